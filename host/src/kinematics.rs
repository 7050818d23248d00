//! Differential-drive inverse and forward kinematics between body velocity (v, ω) and wheel speeds.

/// Geometry and limits of a differential-drive base.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DiffDrive {
    /// Distance between the wheel contact points, m.
    pub wheelbase_m: f64,
    /// Wheel radius, m.
    pub wheel_radius_m: f64,
    /// Largest wheel speed the host will ask for, rad/s (the MCU's v_max refuses anything above).
    pub max_wheel_speed: f64,
}

impl DiffDrive {
    /// The simulated robot: 0.40 m wheelbase, 0.08 m wheels, 18 rad/s (a margin under the MCU's 20).
    pub const DEFAULT: Self = Self {
        wheelbase_m: 0.40,
        wheel_radius_m: 0.08,
        max_wheel_speed: 18.0,
    };

    /// Wheel speeds (left, right) in rad/s for body velocity `v` (m/s) and yaw rate `omega` (rad/s).
    ///
    /// Seed 000's formulas `wL = (v − ω b/2) / r`, `wR = (v + ω b/2) / r`. If either wheel would exceed
    /// `max_wheel_speed`, both are scaled by the same factor so that the path curvature is kept.
    /// Non-finite input gives (0, 0).
    pub fn inverse(&self, v: f64, omega: f64) -> (f64, f64) {
        if !(v.is_finite() && omega.is_finite()) || self.wheel_radius_m <= 0.0 {
            return (0.0, 0.0);
        }
        let half = omega * self.wheelbase_m / 2.0;
        let wl = (v - half) / self.wheel_radius_m;
        let wr = (v + half) / self.wheel_radius_m;
        let peak = wl.abs().max(wr.abs());
        if peak > self.max_wheel_speed && peak > 0.0 {
            let k = self.max_wheel_speed / peak;
            (wl * k, wr * k)
        } else {
            (wl, wr)
        }
    }

    /// Body velocity (v m/s, ω rad/s) from wheel speeds (rad/s).
    pub fn forward(&self, wl: f64, wr: f64) -> (f64, f64) {
        let r = self.wheel_radius_m;
        ((wr + wl) * r / 2.0, (wr - wl) * r / self.wheelbase_m)
    }
}

impl Default for DiffDrive {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;

    #[test]
    fn straight_and_spin() {
        let k = DiffDrive::DEFAULT;
        // 0.8 m/s on 0.08 m wheels = 10 rad/s each.
        assert_eq!(k.inverse(0.8, 0.0), (10.0, 10.0));
        // Spin at 1 rad/s: each wheel travels ±0.2 m/s = ±2.5 rad/s.
        let (l, r) = k.inverse(0.0, 1.0);
        assert!((l + 2.5).abs() < 1e-12 && (r - 2.5).abs() < 1e-12);
    }

    #[test]
    fn saturation_keeps_curvature() {
        let k = DiffDrive::DEFAULT;
        let (v, w) = (2.0, 2.0);
        let (l, r) = k.inverse(v, w);
        assert!((r - 18.0).abs() < 1e-9, "{r}");
        let (v2, w2) = k.forward(l, r);
        assert!((v2 / w2 - v / w).abs() < 1e-9);
    }

    #[test]
    fn round_trip_and_non_finite() {
        let k = DiffDrive::DEFAULT;
        let (l, r) = k.inverse(0.3, -0.7);
        let (v, w) = k.forward(l, r);
        assert!((v - 0.3).abs() < 1e-12 && (w + 0.7).abs() < 1e-12);
        assert_eq!(k.inverse(f64::NAN, 0.0), (0.0, 0.0));
        assert_eq!(k.inverse(0.0, f64::INFINITY), (0.0, 0.0));
    }
}
