//! Differential-drive kinematics: body twist (v, ω) ↔ wheel speeds (ω_L, ω_R).
//!
//! ```text
//!   inverse:  ω_L = (v − ω·L/2) / r        forward:  v = r·(ω_L + ω_R) / 2
//!             ω_R = (v + ω·L/2) / r                  ω = r·(ω_R − ω_L) / L
//! ```
//!
//! L is the wheelbase (track width, wheel contact to wheel contact), r the wheel radius. The ratios
//! 1/r, L/2, r/2 and r/L are computed once in [`DiffDrive::new`], so a conversion is multiplies and
//! adds only (no division on the control path).

use crate::{Meters, MetersPerSecond, Q};
use statemachine::Speed;

const MIN_RADIUS: Q = Q::lit("0.001");
const MIN_BASE: Q = Q::lit("0.01");

/// Body velocity: forward speed and yaw rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Twist {
    /// Forward speed, m/s.
    pub v: MetersPerSecond,
    /// Yaw rate, rad/s, counter-clockwise positive.
    pub omega: Q,
}

/// Why a geometry was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum KinematicsError {
    /// Wheel radius must be between 1 mm and 10 m.
    WheelRadius = 1,
    /// Wheelbase must be between 1 cm and 100 m.
    Wheelbase = 2,
}

/// A validated differential-drive geometry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiffDrive {
    wheelbase: Meters,
    radius: Meters,
    inv_radius: Q,
    half_base: Q,
    half_radius: Q,
    radius_over_base: Q,
}

impl DiffDrive {
    /// Checks the geometry and precomputes the ratios.
    pub fn new(wheelbase: Meters, wheel_radius: Meters) -> Result<Self, KinematicsError> {
        if wheel_radius < MIN_RADIUS || wheel_radius > Q::const_from_int(10) {
            return Err(KinematicsError::WheelRadius);
        }
        if wheelbase < MIN_BASE || wheelbase > Q::const_from_int(100) {
            return Err(KinematicsError::Wheelbase);
        }
        // Both divisors are checked non-zero above and the quotients (≤ 1000, ≤ 1000) fit Q16.16.
        let inv_radius = Q::ONE
            .checked_div(wheel_radius)
            .ok_or(KinematicsError::WheelRadius)?;
        let radius_over_base = wheel_radius
            .checked_div(wheelbase)
            .ok_or(KinematicsError::Wheelbase)?;
        Ok(Self {
            wheelbase,
            radius: wheel_radius,
            inv_radius,
            half_base: Q::from_bits(wheelbase.to_bits() >> 1),
            half_radius: Q::from_bits(wheel_radius.to_bits() >> 1),
            radius_over_base,
        })
    }

    /// Wheelbase, m.
    pub const fn wheelbase(&self) -> Meters {
        self.wheelbase
    }

    /// Wheel radius, m.
    pub const fn wheel_radius(&self) -> Meters {
        self.radius
    }

    /// Wheel speeds `[left, right]` (rad/s) for a body twist; saturates at the Q16.16 range.
    pub fn inverse(&self, t: Twist) -> [Speed; 2] {
        let turn = t.omega.saturating_mul(self.half_base);
        let left = t.v.saturating_sub(turn).saturating_mul(self.inv_radius);
        let right = t.v.saturating_add(turn).saturating_mul(self.inv_radius);
        [left, right]
    }

    /// Body twist from wheel speeds (rad/s); saturates at the Q16.16 range.
    pub fn forward(&self, left: Speed, right: Speed) -> Twist {
        // (ωL + ωR)·r/2 computed as ωL·r/2 + ωR·r/2 so the sum cannot saturate first.
        let v = left
            .saturating_mul(self.half_radius)
            .saturating_add(right.saturating_mul(self.half_radius));
        let omega = right
            .saturating_mul(self.radius_over_base)
            .saturating_sub(left.saturating_mul(self.radius_over_base));
        Twist { v, omega }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64) -> Q {
        Q::from_num(x)
    }
    fn close(a: Q, b: f64, tol: f64) -> bool {
        (a.to_num::<f64>() - b).abs() <= tol
    }

    #[test]
    fn straight_and_spin_by_hand() {
        // r = 0.1 m, L = 0.5 m.
        let k = DiffDrive::new(q(0.5), q(0.1)).unwrap();
        // 1 m/s straight: both wheels 1/0.1 = 10 rad/s.
        let [l, r] = k.inverse(Twist {
            v: q(1.0),
            omega: Q::ZERO,
        });
        assert!(close(l, 10.0, 1e-3) && close(r, 10.0, 1e-3), "{l} {r}");
        // Spin 1 rad/s: wheels ∓ 1·0.25/0.1 = ∓2.5 rad/s.
        let [l, r] = k.inverse(Twist {
            v: Q::ZERO,
            omega: q(1.0),
        });
        assert!(close(l, -2.5, 1e-3) && close(r, 2.5, 1e-3), "{l} {r}");
        // Forward of (4, 6) rad/s: v = 0.1·10/2 = 0.5 m/s, ω = 0.1·2/0.5 = 0.4 rad/s.
        let t = k.forward(q(4.0), q(6.0));
        assert!(close(t.v, 0.5, 1e-3) && close(t.omega, 0.4, 1e-3), "{t:?}");
    }

    #[test]
    fn seed_bridge_formula_matches() {
        // The seed's Python bridge: wL = (v − ω·WB/2)/R, wR = (v + ω·WB/2)/R, with WB = 0.42, R = 0.075.
        let k = DiffDrive::new(q(0.42), q(0.075)).unwrap();
        for (v, w) in [(0.5, 0.3), (-0.2, 1.1), (0.0, -0.7), (1.2, 0.0)] {
            let wl = (v - w * 0.42 / 2.0) / 0.075;
            let wr = (v + w * 0.42 / 2.0) / 0.075;
            let [l, r] = k.inverse(Twist {
                v: q(v),
                omega: q(w),
            });
            assert!(
                close(l, wl, 2e-3) && close(r, wr, 2e-3),
                "{v} {w}: {l} {r} vs {wl} {wr}"
            );
        }
    }

    #[test]
    fn round_trip_within_resolution() {
        let k = DiffDrive::new(q(0.42), q(0.075)).unwrap();
        for (v, w) in [(0.5, 0.3), (-1.0, 2.0), (0.01, -0.01)] {
            let [l, r] = k.inverse(Twist {
                v: q(v),
                omega: q(w),
            });
            let t = k.forward(l, r);
            assert!(close(t.v, v, 1e-3) && close(t.omega, w, 1e-3), "{t:?}");
        }
    }

    #[test]
    fn bad_geometry_refused() {
        assert_eq!(
            DiffDrive::new(q(0.5), Q::ZERO),
            Err(KinematicsError::WheelRadius)
        );
        assert_eq!(
            DiffDrive::new(q(0.5), q(-0.1)),
            Err(KinematicsError::WheelRadius)
        );
        assert_eq!(
            DiffDrive::new(Q::ZERO, q(0.1)),
            Err(KinematicsError::Wheelbase)
        );
        assert_eq!(
            DiffDrive::new(q(1000.0), q(0.1)),
            Err(KinematicsError::Wheelbase)
        );
    }
}
