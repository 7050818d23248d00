//! Real-time settings for the thread that runs a 1 kHz loop: SCHED_FIFO, locked memory, a CPU.
//!
//! Each setting is asked for where permitted and otherwise falls back, with exactly one warning
//! that says what was refused and how to permit it; the loop then runs as it would without it.
//! The settings apply to the calling thread (the scheduling policy and the CPU) and to the process
//! (the memory lock), so [`apply`] is called first thing on the bridge thread.
//!
//! ```text
//!  bridge thread:  apply(RtOptions) ──▶ SCHED_FIFO prio P? ──▶ mlockall(CURRENT|FUTURE)? ──▶ CPU N?
//!                        each refused: one warning, the loop runs on the normal scheduler / unlocked / anywhere
//! ```

use nix::sched::{sched_setaffinity, CpuSet};
use nix::sys::mman::{mlockall, MlockAllFlags};
use nix::unistd::Pid;
use serde::Serialize;

/// Lowest SCHED_FIFO priority on Linux.
pub const FIFO_MIN: i32 = 1;
/// Highest SCHED_FIFO priority on Linux.
pub const FIFO_MAX: i32 = 99;
/// Default priority: above the kernel's threaded interrupt handlers' default of 50 would starve
/// them, so a little below it.
pub const DEFAULT_PRIORITY: i32 = 40;

/// What to ask for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RtOptions {
    /// SCHED_FIFO at this priority ([`FIFO_MIN`]..=[`FIFO_MAX`]); `None`: the normal scheduler.
    pub fifo_priority: Option<i32>,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`: no page fault stalls the loop.
    pub lock_memory: bool,
    /// Pin the thread to this CPU.
    pub cpu: Option<usize>,
}

impl RtOptions {
    /// The options of `--rt` (SCHED_FIFO at `priority` and locked memory) and `--cpu`, checked:
    /// a priority outside 1..=99 or a CPU this machine does not have is refused with a message.
    pub fn new(rt: bool, priority: i32, cpu: Option<usize>) -> Result<Self, String> {
        if !(FIFO_MIN..=FIFO_MAX).contains(&priority) {
            return Err(format!(
                "--rt-priority {priority}: give a SCHED_FIFO priority from {FIFO_MIN} to {FIFO_MAX}"
            ));
        }
        if let Some(c) = cpu {
            let allowed = allowed_cpus();
            if !allowed.contains(&c) {
                let list: Vec<String> = allowed.iter().map(ToString::to_string).collect();
                return Err(format!(
                    "--cpu {c}: this process may run on CPUs {}",
                    list.join(", ")
                ));
            }
        }
        Ok(Self {
            fifo_priority: rt.then_some(priority),
            lock_memory: rt,
            cpu,
        })
    }
}

/// The CPUs the calling thread may run on (its affinity mask; CPU 0 if it cannot be read).
pub fn allowed_cpus() -> Vec<usize> {
    match nix::sched::sched_getaffinity(Pid::from_raw(0)) {
        Ok(set) => (0..CpuSet::count())
            .filter(|&c| set.is_set(c).unwrap_or(false))
            .collect(),
        Err(_) => vec![0],
    }
}

/// What one setting came to.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Not asked for.
    NotAsked,
    /// In force.
    Applied,
    /// Refused by the system; the loop runs without it.
    Refused(String),
}

/// What [`apply`] achieved, setting by setting, and the warnings to print (one per refusal).
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct RtReport {
    /// SCHED_FIFO.
    pub fifo: Outcome,
    /// The memory lock.
    pub memory_locked: Outcome,
    /// The CPU affinity.
    pub cpu: Outcome,
    /// One line per refused setting, for standard error.
    #[serde(skip)]
    pub warnings: Vec<String>,
}

/// The warning for a refused setting: what was refused, why, and what permits it.
pub fn warning(what: &str, errno: nix::errno::Errno, fix: &str) -> String {
    format!(
        "warning: {what} not permitted ({errno}: {}); {fix}; the loop runs without it",
        errno.desc()
    )
}

/// Asks for each setting of `opts` on the calling thread and reports what came of it.
pub fn apply(opts: &RtOptions) -> RtReport {
    let mut warnings = Vec::new();
    let mut refused = |what: &str, e: nix::errno::Errno, fix: &str| {
        warnings.push(warning(what, e, fix));
        Outcome::Refused(e.to_string())
    };
    let fifo = match opts.fifo_priority {
        None => Outcome::NotAsked,
        Some(p) => match set_fifo(p) {
            Ok(()) => Outcome::Applied,
            Err(e) => refused(
                &format!("SCHED_FIFO priority {p}"),
                e,
                "run as root, or give CAP_SYS_NICE or an rtprio limit (ulimit -r, /etc/security/limits.conf)",
            ),
        },
    };
    let memory_locked = if opts.lock_memory {
        match mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE) {
            Ok(()) => Outcome::Applied,
            Err(e) => refused(
                "mlockall(MCL_CURRENT|MCL_FUTURE)",
                e,
                "give CAP_IPC_LOCK or raise the memlock limit (ulimit -l); a page fault may delay a period",
            ),
        }
    } else {
        Outcome::NotAsked
    };
    let cpu = match opts.cpu {
        None => Outcome::NotAsked,
        Some(c) => {
            let mut set = CpuSet::new();
            match set
                .set(c)
                .and_then(|()| sched_setaffinity(Pid::from_raw(0), &set))
            {
                Ok(()) => Outcome::Applied,
                Err(e) => refused(
                    &format!("CPU affinity to CPU {c}"),
                    e,
                    "give a CPU this process may use (see taskset -p $$, the cgroup's cpuset)",
                ),
            }
        }
    };
    RtReport {
        fifo,
        memory_locked,
        cpu,
        warnings,
    }
}

/// SCHED_FIFO at `priority` for the calling thread.
fn set_fifo(priority: i32) -> Result<(), nix::errno::Errno> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: pthread_self() is the calling thread, always valid; `param` is a live, initialised
    // sched_param on this stack frame for the whole call, and the call only reads it.
    let r = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if r == 0 {
        Ok(())
    } else {
        Err(nix::errno::Errno::from_raw(r))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn options_are_checked() {
        assert_eq!(
            RtOptions::new(true, 40, None).unwrap(),
            RtOptions {
                fifo_priority: Some(40),
                lock_memory: true,
                cpu: None
            }
        );
        let cpu = allowed_cpus()[0];
        assert_eq!(
            RtOptions::new(false, 40, Some(cpu)).unwrap(),
            RtOptions {
                fifo_priority: None,
                lock_memory: false,
                cpu: Some(cpu)
            }
        );
        for p in [0, 100, -1] {
            assert!(RtOptions::new(true, p, None)
                .unwrap_err()
                .contains("1 to 99"));
        }
        assert!(RtOptions::new(false, 40, Some(100_000))
            .unwrap_err()
            .contains("--cpu"));
    }

    #[test]
    fn nothing_asked_is_nothing_done() {
        let r = apply(&RtOptions::default());
        assert_eq!(r.fifo, Outcome::NotAsked);
        assert_eq!(r.memory_locked, Outcome::NotAsked);
        assert_eq!(r.cpu, Outcome::NotAsked);
        assert!(r.warnings.is_empty());
    }

    #[test]
    fn each_refused_setting_warns_exactly_once() {
        // Whether this machine permits them is not known here; what must hold either way: a
        // setting is applied or refused, and there is one warning per refusal, none otherwise.
        // The thread is the test's own and ends with it (SCHED_FIFO at the lowest priority).
        let cpu = allowed_cpus()[0];
        let opts = RtOptions::new(false, FIFO_MIN, Some(cpu)).unwrap();
        let opts = RtOptions {
            fifo_priority: Some(FIFO_MIN),
            ..opts
        };
        let r = std::thread::spawn(move || apply(&opts)).join().unwrap();
        let refusals = [&r.fifo, &r.cpu]
            .iter()
            .filter(|o| matches!(o, Outcome::Refused(_)))
            .count();
        assert_eq!(r.warnings.len(), refusals, "{r:?}");
        assert_ne!(r.fifo, Outcome::NotAsked);
        assert_ne!(r.cpu, Outcome::NotAsked);
        assert_eq!(r.memory_locked, Outcome::NotAsked);
    }

    #[test]
    fn the_warning_names_the_refusal_and_the_fix() {
        let w = warning(
            "SCHED_FIFO priority 40",
            nix::errno::Errno::EPERM,
            "run as root",
        );
        assert!(
            w.starts_with("warning: SCHED_FIFO priority 40 not permitted (EPERM"),
            "{w}"
        );
        assert!(w.contains("run as root"), "{w}");
        assert!(w.ends_with("the loop runs without it"), "{w}");
    }
}
