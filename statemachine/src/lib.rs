//! Pure fail-safe core of the motor controller: the NORMAL → REDUCED → HOLD → STOP → BRAKE ladder,
//! the link watchdog and host-command validation.
//!
//! No clock, no peripheral, no allocation, no `unsafe`: the firmware and the simulator feed the same
//! [`Event`]s to [`Ladder::step`] and apply the returned [`Output`]. The safety case that this crate
//! implements is `proofs/SAFETY.md`; its invariants are checked by the harnesses in `verification`
//! (Kani) and by their `cargo test` twins.
#![no_std]
#![forbid(unsafe_code)]
// Per-axis loops index `[_; N]` arrays with `for i in 0..N`: no index can be out of range, and
// unlike slice iterators and their zips they leave a Kani harness no pointer arithmetic to
// execute (Kani models each step of a slice iterator as a checked pointer offset). The ladder's
// one-step harnesses took about half the time (proofs/REPORT.md, "Kani suite time"). Each such
// loop allows `clippy::indexing_slicing` where it stands.
#![allow(clippy::needless_range_loop)]
#![cfg_attr(
    test,
    allow(
        clippy::unwrap_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::panic
    )
)]

pub mod config;
pub mod harness;
pub mod ladder;
pub mod types;
pub mod validate;

#[cfg(any(test, kani))]
mod verification;

/// Proven contracts as Kani stubs, for the harnesses of the crates above the ladder: a harness
/// that drives the ladder with frames can put `any_validation` (INV-5's contract, proven by
/// `validated_setpoints_are_finite_and_in_range`) in place of `validate::validate_into` with
/// `#[kani::stub]` and `-Z stubbing`.
#[cfg(kani)]
pub mod kani_models {
    pub use crate::verification::model::any_validation;
}

pub use config::{Config, ConfigError, ConfigParams};
pub use ladder::{Counters, Estop, Event, Ladder, Source};
pub use types::{
    AxisCommand, AxisDrive, AxisMode, Command, Condition, ControlMode, Drive, Duty, FaultFlags,
    Mode, ModeSet, Output, Position, RejectReason, Speed, MAX_AXES,
};
pub use validate::{validate, AxisSetpoint, Setpoint};
