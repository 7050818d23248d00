//! The board application: the body of every firmware task as plain functions over a small board
//! trait, and the board's tuning. The RTIC firmware binds interrupts to these functions; the
//! simulator calls the very same functions against a motor and robot model; the cross-crate proofs
//! prove them.
//!
//! ```text
//!  task (priority, rate)            body                        what it does
//!  estop_input   (5, EXTI edge)     estop::EstopInput::edge     bridge braked in the handler, press latched
//!  current_loop  (4, 20 kHz)        current::CurrentLoop::run   shunt ADC → amps → trip check → PI → compares
//!  speed_pid     (3, 10 kHz)        speed::SpeedLoop::run       encoders → speed → rate limiter → PID → current refs
//!  spi_dma_done  (2, per frame)     link::LinkTask::on_frame    frame → event → ladder → feedback frame
//!  watchdog_tick (2, 1 kHz)         tick::TickTask::run         conditions → ladder tick → bridge state → IWDG
//! ```
//!
//! Data between the tasks is plain values ([`Measurements`], setpoints, current references); the
//! only hardware a body touches itself is the bridge ([`hw::Bridge`]), because braking must happen
//! inside the task that decided it. Everything else a body decides it returns, and the caller
//! (firmware shell or simulated board) carries it out.
#![no_std]
#![forbid(unsafe_code)]
#![cfg_attr(
    test,
    allow(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::panic
    )
)]

#[cfg(test)]
extern crate std;

pub mod boot;
pub mod cdc;
pub mod current;
pub mod estop;
pub mod hw;
pub mod imu;
pub mod link;
pub mod safety;
pub mod serial;
pub mod speed;
pub mod teensy;
pub mod tick;
pub mod timing;
pub mod trace;
pub mod tuning;

#[cfg(any(test, kani))]
mod verification;

pub use control::{Amps, BridgeCompare, BridgeState};
pub use current::{Calibration, CalibrationError, CurrentLoop, CurrentSample};
pub use estop::EstopInput;
pub use hw::Bridge;
pub use link::LinkTask;
pub use safety::Safety;
pub use speed::{SpeedLoop, SpeedSample};
pub use statemachine::Speed;
pub use tick::{Runs, TickInputs, TickOutcome, TickTask};
pub use tuning::Tuning;

/// The axes of the seed 000 board: two velocity-driven wheels (left, right).
pub const AXES: usize = 2;

/// Everything the control loops measured, for the feedback frame and the tick's plausibility checks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Measurements {
    /// Wheel speeds, rad/s [left, right].
    pub speeds: [Speed; 2],
    /// Motor currents, A, signed (positive = forward torque).
    pub currents: [Amps; 2],
    /// Cumulative encoder counts.
    pub encoders: [i32; 2],
    /// An overcurrent (software trip or hardware break) was seen since the tick last looked.
    pub overcurrent: bool,
}

impl Measurements {
    /// Records a current-loop sample; an overcurrent stays set until the tick takes it.
    pub fn record_current(&mut self, s: &CurrentSample) {
        self.currents = s.amps;
        self.overcurrent |= s.tripped;
    }

    /// Records a speed-loop sample.
    pub fn record_speed(&mut self, s: &SpeedSample) {
        self.speeds = s.speeds;
        self.encoders = s.totals;
    }

    /// A copy for the tick, clearing the overcurrent it now reports.
    pub fn take_for_tick(&mut self) -> Self {
        let snapshot = *self;
        self.overcurrent = false;
        snapshot
    }
}
