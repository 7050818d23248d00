//! `motorlink ros`: a ROS 2 node on the pure-Rust DDS stack (ros2-client over RustDDS; no ROS
//! installation needed) bridging `cmd_vel` to the MCU at 1 kHz and publishing `odom`, the
//! `odom → base_link` TF, `joint_states` and `/diagnostics`, with arm / disarm / re-arm / ESTOP
//! services.
//!
//! ```text
//!   main thread: signals ── SIGINT/SIGTERM/SIGHUP ⇒ stop;  SIGUSR1 ⇒ ESTOP (exchanges stop);  SIGUSR2 ⇒ release
//!   bridge thread (SCHED_FIFO where permitted): runner::run, 1 kHz, never waits for DDS
//!   DDS thread: node::run, polls every 2 ms        (+ ros2-client's spinner thread)
//!                         └──── shared::Shared (try-lock hand-off) ────┘
//! ```
//!
//! Not published on the AMR SPI link: `battery_state` (`sensor_msgs/BatteryState`) and `imu/data_raw`
//! (`sensor_msgs/Imu`). Its feedback frame carries wheel speeds, currents, encoder counts, fault
//! flags and the ladder's rung, and nothing else: no pack voltage, no charge, no IMU sample. The
//! node publishes only what the MCU measured; values it would have to invent are left out.

pub mod diag;
pub mod msg;
pub mod node;
pub mod odom;
pub mod params;
pub mod runner;
pub mod shared;

use std::sync::Arc;
use std::time::Duration;

use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};

use crate::bridge::BridgeConfig;

pub use runner::NodeTransport;

pub use params::{ParamFile, Params};
pub use shared::{Request, Shared};

/// The signals the node handles, blocked in every thread and read from a signalfd.
struct Signals {
    fd: SignalFd,
}

impl Signals {
    /// Blocks the signals in the calling thread (before any other thread starts, so all inherit
    /// the mask).
    fn block() -> Result<Self, String> {
        let mut set = SigSet::empty();
        for s in [
            Signal::SIGINT,
            Signal::SIGTERM,
            Signal::SIGHUP,
            Signal::SIGUSR1,
            Signal::SIGUSR2,
        ] {
            set.add(s);
        }
        set.thread_block()
            .map_err(|e| format!("cannot block the node's signals: {e}"))?;
        let fd = SignalFd::with_flags(&set, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)
            .map_err(|e| format!("cannot open a signalfd: {e}"))?;
        Ok(Self { fd })
    }

    /// The next pending signal, if any.
    fn next(&mut self) -> Option<i32> {
        match self.fd.read_signal() {
            Ok(Some(s)) => i32::try_from(s.ssi_signo).ok(),
            _ => None,
        }
    }
}

/// How the node runs.
pub struct NodeSetup {
    /// The node's name.
    pub node_name: String,
    /// Its parameters (checked).
    pub params: Params,
    /// Names the hardware in the diagnostics (the device, or `sim`).
    pub hardware_id: String,
    /// Arm at start (`--arm` or `arm_on_start`).
    pub arm: bool,
    /// Ask for SCHED_FIFO on the bridge thread.
    pub realtime: bool,
}

/// SCHED_FIFO priority of the node's 1 kHz bridge thread, where the system permits it.
pub const BRIDGE_FIFO_PRIORITY: i32 = 80;

/// Runs the node over `transport` until SIGINT, SIGTERM or SIGHUP (or the DDS side fails).
/// [`block_signals`] must be called before anything that starts a thread; pass its result here.
pub fn run(
    setup: &NodeSetup,
    transport: Box<dyn NodeTransport + Send>,
    signals: SignalGuard,
) -> Result<(), String> {
    let mut signals = signals.0;
    let shared = Arc::new(Shared::new());
    let drive = setup.params.drive().map_err(|e| e.to_string())?;
    let cfg = BridgeConfig {
        kinematics: drive,
        ..BridgeConfig::DEFAULT
    };
    let bridge = {
        let shared = shared.clone();
        let arm = setup.arm;
        let realtime = setup.realtime;
        std::thread::Builder::new()
            .name("bridge-1khz".into())
            .spawn(move || {
                if realtime {
                    // The same settings as `loop-bench --rt` (host/src/rt.rs): SCHED_FIFO above
                    // the DDS threads and the memory locked; one warning per refusal.
                    let report = crate::rt::apply(&crate::rt::RtOptions {
                        fifo_priority: Some(BRIDGE_FIFO_PRIORITY),
                        lock_memory: true,
                        cpu: None,
                    });
                    for w in &report.warnings {
                        eprintln!("motorlink ros: {w}");
                    }
                    if report.fifo == crate::rt::Outcome::Applied {
                        eprintln!(
                            "motorlink ros: bridge thread on SCHED_FIFO {BRIDGE_FIFO_PRIORITY}"
                        );
                    }
                }
                runner::run(transport, cfg, arm, &shared);
            })
            .map_err(|e| format!("cannot start the bridge thread: {e}"))?
    };
    let dds = {
        let shared = shared.clone();
        let name = setup.node_name.clone();
        let params = setup.params.clone();
        let hw = setup.hardware_id.clone();
        std::thread::Builder::new()
            .name("ros-dds".into())
            .spawn(move || {
                let r = node::run(&name, &params, &hw, &shared);
                // Whatever ended the DDS side ends the bridge too (it disarms first).
                shared.stop();
                r
            })
            .map_err(|e| format!("cannot start the DDS thread: {e}"))?
    };
    eprintln!(
        "motorlink ros: node /{} running (SIGUSR1 ESTOP, SIGUSR2 release, Ctrl-C to stop)",
        setup.node_name
    );
    while !shared.stopping() {
        while let Some(sig) = signals.next() {
            if sig == Signal::SIGUSR1 as i32 {
                shared.request(Request::Estop(true));
            } else if sig == Signal::SIGUSR2 as i32 {
                shared.request(Request::Estop(false));
            } else {
                shared.stop();
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let b = bridge.join();
    let d = dds
        .join()
        .map_err(|_| "the DDS thread panicked".to_string())?;
    b.map_err(|_| "the bridge thread panicked".to_string())?;
    let s = shared.snapshot();
    eprintln!(
        "motorlink ros: stopped after {} cycles: {} feedback ok, {} refused, {} not accepted, {} transport errors; pacing: {} periods outside 1 ms +- 0.2 ms, {} deadlines skipped",
        s.cycles,
        s.stats.feedback_ok,
        s.stats.feedback_rejected,
        s.stats.not_accepted,
        s.transport_errors,
        s.period_misses,
        s.skipped_deadlines
    );
    d
}

/// The node's signals, blocked: take it first thing in `main`, before any thread starts.
pub struct SignalGuard(Signals);

/// Blocks SIGINT, SIGTERM, SIGHUP, SIGUSR1 and SIGUSR2 in the calling thread (inherited by every
/// thread started after) and returns the handle that reads them.
pub fn block_signals() -> Result<SignalGuard, String> {
    Signals::block().map(SignalGuard)
}

/// The setup of a run: `arm` if asked on the command line or by `arm_on_start`.
pub fn node_setup(
    node_name: String,
    params: Params,
    hardware_id: String,
    arm: bool,
    realtime: bool,
) -> NodeSetup {
    let arm = arm || params.arm_on_start;
    NodeSetup {
        node_name,
        params,
        hardware_id,
        arm,
        realtime,
    }
}
