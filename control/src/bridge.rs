//! The H-bridge as the control loops see it: a duty becomes two compare values, a ladder drive
//! command becomes run or brake.

use crate::{clamp_sym, Duty, Q};
use statemachine::Drive;

/// Compare values for the two half-bridges of one H-bridge (timer counts, 0 ..= ARR).
///
/// Unipolar switching: forward drives half-bridge A with the duty and holds B's low side on;
/// reverse swaps them. At most one of `a`, `b` is non-zero, so the bridge never shorts the supply
/// through both high sides, and zero duty is both low sides on (a dynamic brake at rest).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BridgeCompare {
    /// Half-bridge A compare value.
    pub a: u16,
    /// Half-bridge B compare value.
    pub b: u16,
}

/// Maps a duty in [-1, 1] (clamped) to compare values for a timer with auto-reload `arr`.
pub fn bridge_compare(duty: Duty, arr: u16) -> BridgeCompare {
    let d = clamp_sym(duty, Q::ONE);
    let mag = d.unsigned_abs();
    // |d| ≤ 1, so |d|·arr ≤ arr: the product fits and the cast cannot truncate.
    let counts = mag
        .saturating_mul_int(fixed::types::U16F16::from_num(arr).to_num::<u32>())
        .round()
        .to_num::<u32>()
        .min(u32::from(arr));
    let c = u16::try_from(counts).unwrap_or(arr);
    if d.is_negative() {
        BridgeCompare { a: 0, b: c }
    } else {
        BridgeCompare { a: c, b: 0 }
    }
}

/// What the bridge hardware must do for a ladder output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BridgeState {
    /// PWM outputs active, the current loop sets the duty.
    Run,
    /// High sides off, low sides on (motor shorted): dynamic brake, no control loop.
    Brake,
}

/// The bridge state a ladder drive command needs (all axes of one board share the bridge enable).
pub const fn bridge_state<const N: usize>(drive: &Drive<N>) -> BridgeState {
    match drive {
        Drive::Run(_) => BridgeState::Run,
        Drive::Brake => BridgeState::Brake,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64) -> Q {
        Q::from_num(x)
    }

    #[test]
    fn compare_values_by_hand() {
        assert_eq!(
            bridge_compare(q(0.5), 4200),
            BridgeCompare { a: 2100, b: 0 }
        );
        assert_eq!(
            bridge_compare(q(-0.25), 4200),
            BridgeCompare { a: 0, b: 1050 }
        );
        assert_eq!(
            bridge_compare(q(1.0), 4200),
            BridgeCompare { a: 4200, b: 0 }
        );
        assert_eq!(
            bridge_compare(q(-7.0), 4200),
            BridgeCompare { a: 0, b: 4200 }
        );
        assert_eq!(bridge_compare(Q::ZERO, 4200), BridgeCompare { a: 0, b: 0 });
        assert_eq!(
            bridge_compare(Q::MIN, u16::MAX),
            BridgeCompare { a: 0, b: u16::MAX }
        );
    }
}
