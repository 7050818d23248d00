//! The per-tick trace of the serial-link images (`cdc`, `teensy`): under the emulator one line
//! through semihosting whenever the rung, the drive, a ladder counter or an output changed, so a
//! test can check from the firmware's own account what each received frame did and when BRAKE
//! came; on the board, the rung changes through defmt.
//!
//! ```text
//!  tick=1234 mode=Normal age=3 drive=RUN valid=57 rejected=1 refusals=0 owners=0 out=+500 -250 C S
//! ```
//! `tick` counts emulated 1 ms ticks since boot; `owners` is the ESTOP owner set
//! (`statemachine::Source::bit`s); `out` is one token per motor as the profile writes it to the
//! hardware (`cdc`: +CCR forward, −CCR reverse, `C` coast, `S` short brake; `teensy`: the step
//! targets).

use statemachine::{Drive, Mode, Output};

/// What a line is printed for: everything but the age, which changes every tick.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Key {
    mode: Mode,
    brake: bool,
    valid: u32,
    rejected: u32,
    refusals: u32,
    owners: u8,
    outs: [i32; 4],
}

/// The trace's memory of the last line.
pub struct Trace {
    last: Option<Key>,
}

impl Default for Trace {
    fn default() -> Self {
        Self::new()
    }
}

impl Trace {
    /// Nothing printed yet.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// After a tick: prints a line if anything but the age changed. `outs` are the profile's
    /// output codes (see the module documentation), `token` renders one.
    pub fn tick<const N: usize>(
        &mut self,
        tick: u32,
        out: &Output<N>,
        safety: &mcu::Safety<N>,
        outs: [i32; 4],
        token: fn(i32) -> Token,
    ) {
        let l = safety.ladder();
        let c = l.counters();
        let key = Key {
            mode: out.mode,
            brake: matches!(out.drive, Drive::Brake),
            valid: c.valid_frames,
            rejected: c.rejected_total(),
            refusals: c.rearm_refused.saturating_add(c.estop_release_refused),
            owners: l.estop_owners(),
            outs,
        };
        if self.last == Some(key) {
            return;
        }
        if self.last.map(|k| k.mode) != Some(key.mode) {
            defmt::info!("tick {=u32}: {}", tick, out.mode);
        }
        self.last = Some(key);
        emit(tick, out.age, &key, token);
    }
}

/// One output token.
pub enum Token {
    /// A signed number.
    Num(i32),
    /// A letter (`C` coast, `S` short).
    Letter(char),
}

#[cfg(feature = "qemu")]
fn emit(tick: u32, age: u16, k: &Key, token: fn(i32) -> Token) {
    use core::fmt::Write;
    let Ok(mut o) = cortex_m_semihosting::hio::hstdout() else {
        return;
    };
    let _ = write!(
        o,
        "tick={} mode={:?} age={} drive={} valid={} rejected={} refusals={} owners={} out=",
        tick,
        k.mode,
        age,
        if k.brake { "BRAKE" } else { "RUN" },
        k.valid,
        k.rejected,
        k.refusals,
        k.owners,
    );
    for (i, v) in k.outs.iter().enumerate() {
        let sep = if i == 0 { "" } else { " " };
        let _ = match token(*v) {
            Token::Num(n) => write!(o, "{sep}{n:+}"),
            Token::Letter(c) => write!(o, "{sep}{c}"),
        };
    }
    let _ = writeln!(o);
}

#[cfg(not(feature = "qemu"))]
fn emit(_tick: u32, _age: u16, _k: &Key, _token: fn(i32) -> Token) {}
