//! Fixed-point motor control for the differential-drive base: speed PID, current PI, rate limiter,
//! kinematics, measurement scaling and the bridge mapping, and the trapezoidal position profile of
//! a position-mode axis. The board application (`mcu`) composes these into the firmware's task
//! bodies.
//!
//! ```text
//!  ladder setpoint ─► RateLimiter ─► SpeedPid ─► current ref ─► CurrentPi ─► duty ─► bridge::bridge_compare ─► PWM
//!  (1 kHz, rad/s)      (10 kHz)      (10 kHz)      (A)           (20 kHz)    [-1, 1]
//!                                        ▲                          ▲
//!                     sense::SpeedEstimator (encoders)    sense::adc_to_amps (shunt ADC)
//!
//!  position axis:  target, cap ─► profile::Trapezoid ─► position ref (rad) + speed ref (rad/s)
//!                  (rad, rad/s)    (1 kHz, within the travel, never past the target, |v| ≤ cap)
//! ```
//!
//! Units and number formats (all Q16.16, [`fixed::types::I16F16`], so one multiply costs one
//! 32×32→64 bit product on the Cortex-M4 and NaN/∞ cannot exist):
//!
//! | alias            | unit  | range used        | resolution     |
//! |------------------|-------|-------------------|----------------|
//! | [`Speed`]        | rad/s | ±v_max (≤ 1000)   | 1.5e-5 rad/s   |
//! | [`Amps`]         | A     | ±current limit    | 1.5e-5 A       |
//! | [`Duty`]         | 1     | [-1, 1]           | 1.5e-5 (the PWM has 2.4e-4 at ARR 4200) |
//! | [`Gain`]         | mixed | ±32768            | 1.5e-5         |
//! | [`Meters`], [`MetersPerSecond`] | m, m/s | ±32768 | 15 µm |
//! | [`Position`]     | rad   | the axis travel   | 1.5e-5 rad (1.5e-8 rad inside the profile) |
//!
//! Every function saturates instead of overflowing and never panics; the bounds are proved by the
//! harnesses in `verification` (Kani) and checked by their `cargo test` twins.
#![no_std]
// No unsafe code in any build of the crate; the exceptions are the Kani-only memories of P-20's
// stand-ins for the stopping distance and the exact position (`verification::stand_in`), which
// exist only under `cfg(kani)` and allow it locally.
#![cfg_attr(not(kani), forbid(unsafe_code))]
#![cfg_attr(kani, deny(unsafe_code))]
#![cfg_attr(
    test,
    allow(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::panic,
        clippy::float_arithmetic,
        clippy::cast_possible_truncation
    )
)]

pub mod bridge;
pub mod kinematics;
pub mod pid;
pub mod profile;
pub mod rate;
pub mod sense;

#[cfg(any(test, kani))]
mod verification;

pub use bridge::{BridgeCompare, BridgeState};
pub use kinematics::{DiffDrive, KinematicsError, Twist};
pub use pid::{AntiWindup, CurrentPi, Pid, PidGains, SpeedPid};
pub use profile::{Position, ProfileLimits, Trapezoid, Travel};
pub use rate::RateLimiter;
pub use sense::SpeedEstimator;
pub use statemachine::Speed;

/// Motor current in amperes, Q16.16.
pub type Amps = fixed::types::I16F16;
/// PWM duty in [-1, 1] (sign = direction), Q16.16.
pub type Duty = fixed::types::I16F16;
/// A controller gain or other dimensioned coefficient, Q16.16.
pub type Gain = fixed::types::I16F16;
/// A length in metres, Q16.16.
pub type Meters = fixed::types::I16F16;
/// A linear speed in metres per second, Q16.16.
pub type MetersPerSecond = fixed::types::I16F16;

/// Q16.16, the one number format of this crate.
pub type Q = fixed::types::I16F16;

/// `x` in Q16.16, rounded to the nearest step; beyond the range saturated, NaN as zero. For the
/// host and the simulator, which hold their numbers as floats (the MCU path has no floats).
pub fn q_from_f64(x: f64) -> Q {
    Q::checked_from_num(x).unwrap_or(if x > 0.0 {
        Q::MAX
    } else if x < 0.0 {
        Q::MIN
    } else {
        Q::ZERO
    })
}

/// Limits `x` to ±`limit`. A negative `limit` counts as zero. Never panics (unlike `Ord::clamp`).
pub const fn clamp_sym(x: Q, limit: Q) -> Q {
    let lim = if limit.to_bits() < 0 { Q::ZERO } else { limit };
    let neg = lim.saturating_neg();
    if x.to_bits() > lim.to_bits() {
        lim
    } else if x.to_bits() < neg.to_bits() {
        neg
    } else {
        x
    }
}

/// True if |x| ≤ limit.
pub const fn within(x: Q, limit: Q) -> bool {
    x.to_bits() <= limit.to_bits() && x.to_bits() >= limit.saturating_neg().to_bits()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64) -> Q {
        Q::from_num(x)
    }

    #[test]
    fn q_from_f64_rounds_saturates_and_maps_nan_to_zero() {
        assert_eq!(q_from_f64(1.5), q(1.5));
        assert_eq!(q_from_f64(-2.25), q(-2.25));
        // Q16.16 ends below 32 768: anything beyond saturates to the end on its side.
        assert_eq!(q_from_f64(1e9), Q::MAX);
        assert_eq!(q_from_f64(f64::INFINITY), Q::MAX);
        assert_eq!(q_from_f64(-1e9), Q::MIN);
        assert_eq!(q_from_f64(f64::NEG_INFINITY), Q::MIN);
        assert_eq!(q_from_f64(f64::NAN), Q::ZERO);
    }

    #[test]
    fn clamp_sym_limits_both_sides_and_treats_a_negative_limit_as_zero() {
        assert_eq!(clamp_sym(q(2.0), q(3.0)), q(2.0));
        assert_eq!(clamp_sym(q(4.0), q(3.0)), q(3.0));
        assert_eq!(clamp_sym(q(-4.0), q(3.0)), q(-3.0));
        // A limit of −1 is a limit of 0: both signs of input end at zero.
        assert_eq!(clamp_sym(q(5.0), q(-1.0)), Q::ZERO);
        assert_eq!(clamp_sym(q(-5.0), q(-1.0)), Q::ZERO);
        // −Q::MAX is one step above Q::MIN: the symmetric range excludes Q::MIN.
        assert_eq!(clamp_sym(Q::MIN, Q::MAX), -Q::MAX);
    }

    #[test]
    fn within_is_the_closed_symmetric_interval() {
        assert!(within(q(3.0), q(3.0)));
        assert!(within(q(-3.0), q(3.0)));
        assert!(within(Q::ZERO, Q::ZERO));
        assert!(!within(q(3.5), q(3.0)));
        assert!(!within(q(-3.5), q(3.0)));
        assert!(!within(Q::MIN, Q::MAX));
    }
}
