//! The host's differential-drive policy around `control::DiffDrive`: cmd_vel (v, ω) → wheel speeds
//! limited with the path's curvature kept, and wheel speeds → body velocity.
//!
//! The formulas themselves are `control::kinematics`, the fixed-point code the MCU crates use and
//! the Kani harnesses cover; this module only converts at the boundary and applies the limits:
//!
//! ```text
//!  (v, ω) f64 ──► non-finite? ⇒ (0, 0) ──► Q16.16 (v to 15 µm/s, ω to 1.5e-5 rad/s)
//!        ──► control::DiffDrive::inverse_unrounded (exact, Q32.32) ──► f64 ──► scale both to max
//! ```
//!
//! Resolution that costs, against the same formulas in f64: the geometry is held to the nearest
//! 2⁻¹⁶ m (15 µm steps, so within 7.6 µm: 0.08 m is held as 0.0800018 m, a scale error of 2.3e-5;
//! at worst 7.6 µm / r, 1e-4 on an 8 cm wheel, far under a tyre's tolerance); v and ω are rounded
//! to 2⁻¹⁶ (1.5e-5 m/s, 1.5e-5 rad/s), which moves the default robot's wheel speeds by at most
//! 1.2e-4 rad/s, plus 7.6e-6 rad/s per m/s and per rad/s from the ratios' own rounding; the wheel speeds themselves are not rounded (Q32.32, exact); a body velocity from
//! [`DiffDrive::forward`] is rounded to 2⁻¹⁶ (1.5e-5 m/s, 1.5e-5 rad/s).

use control::kinematics::{KinematicsError, Twist};
use control::Q;

/// Largest value Q16.16 holds, as f64 (exact).
const Q_MAX: f64 = 32_768.0 - 1.0 / 65_536.0;

/// Geometry and wheel-speed limit of a differential-drive base, checked: only built from a
/// geometry `control::DiffDrive` accepts (wheelbase 1 cm ..= 64 m, wheel radius 1 mm ..= 10 m) and
/// a limit in (0, 32 767] rad/s. (De)serialised as a [`DiffDriveConfig`], so a configuration out
/// of range is refused when it is read.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "DiffDriveConfig", into = "DiffDriveConfig")]
pub struct DiffDrive {
    geometry: control::DiffDrive,
    max_wheel_speed: f64,
}

/// The configuration of a [`DiffDrive`], in SI units.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DiffDriveConfig {
    /// Distance between the wheel contact points, m.
    pub wheelbase_m: f64,
    /// Wheel radius, m.
    pub wheel_radius_m: f64,
    /// Largest wheel speed the host will ask for, rad/s (the MCU's v_max refuses anything above).
    pub max_wheel_speed: f64,
}

/// Why a [`DiffDriveConfig`] was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeometryError {
    /// The wheelbase (m) is not a number in 0.01 ..= 64.
    Wheelbase(f64),
    /// The wheel radius (m) is not a number in 0.001 ..= 10.
    WheelRadius(f64),
    /// The wheel-speed limit (rad/s) is not a number in (0, 32 767].
    MaxWheelSpeed(f64),
}

impl core::fmt::Display for GeometryError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Wheelbase(x) => write!(f, "wheelbase {x} m is outside 0.01 ..= 64 m"),
            Self::WheelRadius(x) => write!(f, "wheel radius {x} m is outside 0.001 ..= 10 m"),
            Self::MaxWheelSpeed(x) => {
                write!(f, "max wheel speed {x} rad/s is outside (0, 32767] rad/s")
            }
        }
    }
}

impl std::error::Error for GeometryError {}

impl DiffDrive {
    /// The simulated robot: 0.40 m wheelbase, 0.08 m wheels, 18 rad/s (a margin under the MCU's 20).
    pub const DEFAULT: Self = match control::DiffDrive::new(Q::lit("0.40"), Q::lit("0.08")) {
        Ok(geometry) => Self {
            geometry,
            max_wheel_speed: 18.0,
        },
        // Evaluated at compile time: an out-of-range default does not build.
        Err(_) => panic!("the default geometry is out of range"),
    };

    /// Checks `cfg` and converts the geometry to Q16.16 (the nearest 15 µm step).
    pub fn new(cfg: DiffDriveConfig) -> Result<Self, GeometryError> {
        // Radius first, as `control::DiffDrive::new` checks it.
        let radius = Q::checked_from_num(cfg.wheel_radius_m)
            .ok_or(GeometryError::WheelRadius(cfg.wheel_radius_m))?;
        let base = Q::checked_from_num(cfg.wheelbase_m)
            .ok_or(GeometryError::Wheelbase(cfg.wheelbase_m))?;
        let geometry = control::DiffDrive::new(base, radius).map_err(|e| match e {
            KinematicsError::WheelRadius => GeometryError::WheelRadius(cfg.wheel_radius_m),
            KinematicsError::Wheelbase => GeometryError::Wheelbase(cfg.wheelbase_m),
        })?;
        if !(cfg.max_wheel_speed > 0.0 && cfg.max_wheel_speed <= 32_767.0) {
            return Err(GeometryError::MaxWheelSpeed(cfg.max_wheel_speed));
        }
        Ok(Self {
            geometry,
            max_wheel_speed: cfg.max_wheel_speed,
        })
    }

    /// The configuration this was built from, with the geometry as held (the Q16.16 values).
    pub fn config(&self) -> DiffDriveConfig {
        DiffDriveConfig {
            wheelbase_m: self.geometry.wheelbase().to_num(),
            wheel_radius_m: self.geometry.wheel_radius().to_num(),
            max_wheel_speed: self.max_wheel_speed,
        }
    }

    /// The fixed-point geometry the conversions use.
    pub fn geometry(&self) -> control::DiffDrive {
        self.geometry
    }

    /// Largest wheel speed the host asks for, rad/s.
    pub fn max_wheel_speed(&self) -> f64 {
        self.max_wheel_speed
    }

    /// Wheel speeds (left, right) in rad/s for body velocity `v` (m/s) and yaw rate `omega` (rad/s),
    /// from `control::DiffDrive::inverse_unrounded` (seed 000's `wL = (v − ω b/2) / r`,
    /// `wR = (v + ω b/2) / r`).
    ///
    /// If either wheel would exceed the limit, both are scaled by the same factor, so the path's
    /// curvature ω/v is kept. A v or ω beyond the ±32 767 that Q16.16 holds (no real command) is
    /// first scaled down to it together with the other, so its curvature is kept as well.
    /// Non-finite input gives (0, 0).
    pub fn inverse(&self, v: f64, omega: f64) -> (f64, f64) {
        if !(v.is_finite() && omega.is_finite()) {
            return (0.0, 0.0);
        }
        let big = v.abs().max(omega.abs());
        let (v, omega) = if big > Q_MAX {
            let k = Q_MAX / big;
            (v * k, omega * k)
        } else {
            (v, omega)
        };
        let [l, r] = self.geometry.inverse_unrounded(Twist {
            v: control::q_from_f64(v),
            omega: control::q_from_f64(omega),
        });
        let (wl, wr): (f64, f64) = (l.to_num(), r.to_num());
        let peak = wl.abs().max(wr.abs());
        if peak > self.max_wheel_speed {
            let k = self.max_wheel_speed / peak;
            (wl * k, wr * k)
        } else {
            (wl, wr)
        }
    }

    /// Body velocity (v m/s, ω rad/s) from wheel speeds (rad/s), by `control::DiffDrive::forward`:
    /// each rounded to 2⁻¹⁶; wheel speeds beyond ±32 767 rad/s saturate first. Non-finite input
    /// gives (0, 0).
    pub fn forward(&self, wl: f64, wr: f64) -> (f64, f64) {
        if !(wl.is_finite() && wr.is_finite()) {
            return (0.0, 0.0);
        }
        let t = self
            .geometry
            .forward(control::q_from_f64(wl), control::q_from_f64(wr));
        (t.v.to_num(), t.omega.to_num())
    }
}

impl Default for DiffDrive {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl TryFrom<DiffDriveConfig> for DiffDrive {
    type Error = GeometryError;
    fn try_from(cfg: DiffDriveConfig) -> Result<Self, GeometryError> {
        Self::new(cfg)
    }
}

impl From<DiffDrive> for DiffDriveConfig {
    fn from(k: DiffDrive) -> Self {
        k.config()
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp, clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The default robot's wheel speeds are within this of the hand-computed ones: the geometry is
    /// held as L = 0.399994 m, r = 0.0800018 m (relative errors 1.5e-5 and 2.3e-5), so below
    /// 20 rad/s the scale error is under 1e-3 rad/s; the input rounding adds under 1e-4.
    const TOL: f64 = 1e-3;

    fn close(got: (f64, f64), want: (f64, f64)) -> bool {
        (got.0 - want.0).abs() <= TOL && (got.1 - want.1).abs() <= TOL
    }

    #[test]
    fn straight_turn_and_spin_by_hand() {
        let k = DiffDrive::DEFAULT;
        // wL = (v − ω·0.2)/0.08, wR = (v + ω·0.2)/0.08.
        // 0.8 m/s straight: 0.8/0.08 = 10 rad/s each.
        assert!(
            close(k.inverse(0.8, 0.0), (10.0, 10.0)),
            "{:?}",
            k.inverse(0.8, 0.0)
        );
        // Spin at 1 rad/s: each wheel travels ∓0.2 m/s = ∓2.5 rad/s.
        assert!(close(k.inverse(0.0, 1.0), (-2.5, 2.5)));
        // (0.5, 1.0): (0.3/0.08, 0.7/0.08) = (3.75, 8.75).
        assert!(close(k.inverse(0.5, 1.0), (3.75, 8.75)));
        // (0.3, −0.7): (0.44/0.08, 0.16/0.08) = (5.5, 2.0).
        assert!(close(k.inverse(0.3, -0.7), (5.5, 2.0)));
        // (−0.4, 0.5): (−0.5/0.08, −0.3/0.08) = (−6.25, −3.75).
        assert!(close(k.inverse(-0.4, 0.5), (-6.25, -3.75)));
        // Forward of (4, 6) rad/s: v = 0.08·10/2 = 0.4 m/s, ω = 0.08·2/0.4 = 0.4 rad/s.
        assert!(close(k.forward(4.0, 6.0), (0.4, 0.4)));
    }

    #[test]
    fn saturation_keeps_curvature() {
        let k = DiffDrive::DEFAULT;
        // (2, 2): (1.6/0.08, 2.4/0.08) = (20, 30); scaled by 18/30 = 0.6 to (12, 18).
        let (l, r) = k.inverse(2.0, 2.0);
        assert!(close((l, r), (12.0, 18.0)), "{l} {r}");
        assert!(r <= 18.0);
        // The curvature ω/v = 1 is kept to the rounding of the body velocity.
        let (v2, w2) = k.forward(l, r);
        assert!((w2 / v2 - 1.0).abs() < 1e-4, "{v2} {w2}");
        // Spin past the limit: (0, 10) gives ∓25, scaled to ∓18.
        assert!(close(k.inverse(0.0, 10.0), (-18.0, 18.0)));
    }

    #[test]
    fn beyond_the_fixed_point_range_the_curvature_is_kept() {
        let k = DiffDrive::DEFAULT;
        // v = 1e9 m/s, ω = 5e8 rad/s: curvature 0.5 /m, wheel ratio (1 − 0.1)/(1 + 0.1) = 9/11.
        let (l, r) = k.inverse(1e9, 5e8);
        assert!(close((l, r), (18.0 * 9.0 / 11.0, 18.0)), "{l} {r}");
        let (l, r) = k.inverse(-1e300, 0.0);
        assert!(close((l, r), (-18.0, -18.0)), "{l} {r}");
    }

    #[test]
    fn non_finite_gives_zero() {
        let k = DiffDrive::DEFAULT;
        assert_eq!(k.inverse(f64::NAN, 0.0), (0.0, 0.0));
        assert_eq!(k.inverse(0.0, f64::INFINITY), (0.0, 0.0));
        assert_eq!(k.inverse(f64::NEG_INFINITY, f64::NAN), (0.0, 0.0));
        assert_eq!(k.forward(f64::NAN, 1.0), (0.0, 0.0));
    }

    #[test]
    fn round_trip_within_resolution() {
        let k = DiffDrive::DEFAULT;
        let (l, r) = k.inverse(0.3, -0.7);
        let (v, w) = k.forward(l, r);
        assert!((v - 0.3).abs() < 1e-4 && (w + 0.7).abs() < 1e-4, "{v} {w}");
    }

    #[test]
    fn default_is_the_checked_configuration() {
        let cfg = DiffDriveConfig {
            wheelbase_m: 0.40,
            wheel_radius_m: 0.08,
            max_wheel_speed: 18.0,
        };
        assert_eq!(DiffDrive::new(cfg), Ok(DiffDrive::DEFAULT));
        let held = DiffDrive::DEFAULT.config();
        assert!((held.wheelbase_m - 0.40).abs() <= 7.7e-6);
        assert!((held.wheel_radius_m - 0.08).abs() <= 7.7e-6);
    }

    #[test]
    fn out_of_range_geometry_is_refused() {
        let ok = DiffDrive::DEFAULT.config();
        let with = |wheelbase_m, wheel_radius_m, max_wheel_speed| {
            DiffDrive::new(DiffDriveConfig {
                wheelbase_m,
                wheel_radius_m,
                max_wheel_speed,
            })
        };
        let (b, r, m) = (ok.wheelbase_m, ok.wheel_radius_m, ok.max_wheel_speed);
        assert_eq!(with(b, 0.0, m), Err(GeometryError::WheelRadius(0.0)));
        assert_eq!(with(b, -0.08, m), Err(GeometryError::WheelRadius(-0.08)));
        // Rounds to 0 in Q16.16: refused, not divided by.
        assert_eq!(with(b, 1e-6, m), Err(GeometryError::WheelRadius(1e-6)));
        assert!(matches!(
            with(b, f64::NAN, m),
            Err(GeometryError::WheelRadius(x)) if x.is_nan()
        ));
        assert_eq!(with(1e6, r, m), Err(GeometryError::Wheelbase(1e6)));
        assert_eq!(with(65.0, r, m), Err(GeometryError::Wheelbase(65.0)));
        assert_eq!(
            with(f64::INFINITY, r, m),
            Err(GeometryError::Wheelbase(f64::INFINITY))
        );
        assert_eq!(with(b, r, 0.0), Err(GeometryError::MaxWheelSpeed(0.0)));
        assert_eq!(with(b, r, 1e9), Err(GeometryError::MaxWheelSpeed(1e9)));
        assert!(with(64.0, 10.0, 1.0).is_ok());
        assert!(with(0.01, 0.001, 32_767.0).is_ok());
    }

    #[test]
    fn serde_refuses_what_new_refuses() {
        let k: DiffDrive = serde_json::from_str(
            r#"{"wheelbase_m": 0.4, "wheel_radius_m": 0.08, "max_wheel_speed": 18.0}"#,
        )
        .unwrap();
        assert_eq!(k, DiffDrive::DEFAULT);
        let back: DiffDrive = serde_json::from_str(&serde_json::to_string(&k).unwrap()).unwrap();
        assert_eq!(back, k);
        let e = serde_json::from_str::<DiffDrive>(
            r#"{"wheelbase_m": 0.4, "wheel_radius_m": 0.0, "max_wheel_speed": 18.0}"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("wheel radius 0 m"), "{e}");
    }
}
