//! Wheel odometry of the seed 004 board: the robot's pose and body velocity from the four wheel
//! encoders' cumulative counts and the Pi's `KinematicsConfig`, for `TxBuffer.odometry`.
//!
//! # Frames and units (seed 004, `OdometryData`)
//!
//! ```text
//!   world frame (ENU, fixed at the last reset)     body frame (moves with the robot)
//!
//!        y (north)                                      y_b (left)
//!        ^                                              ^
//!        |    heading θ: CCW from +x, rad,              |
//!        |    in (−π, π]                                +----> x_b (forward)
//!        +------> x (east)                             wz: CCW positive, rad/s
//!
//!   pos_x, pos_y  m, world frame        vx, vy  m/s, body frame        wz  rad/s
//! ```
//!
//! # The configuration (our assumption, see [`protocol::pi_spi::assumed`])
//!
//! `KinematicsConfig { inverse: [[f32; 4]; 3], ticks_to_rad: [f32; 4] }`: `inverse` is row-major,
//! rows vx, vy, wz, columns wheels 0–3, and maps wheel angular speeds (rad/s) to the body twist
//! (the "inverse" of the wheel-speed kinematics); `ticks_to_rad[n]` is wheel n's angle per encoder
//! count. Seed 004 names the struct but does not define it: the layout is ours, in one place
//! (`assumed.rs`), to be aligned with the real `pi_buffer.h`. A wheel the robot does not have gets
//! a zero column and any accepted `ticks_to_rad`.
//!
//! [`Odometry::configure`] accepts a configuration only if every number is finite, every
//! `ticks_to_rad` has a magnitude in [[`MIN_TICKS_TO_RAD`], [`MAX_TICKS_TO_RAD`]] (nonzero; at least
//! one count per revolution), every entry of the vx and vy rows is at most [`MAX_LINEAR_GAIN`] m/rad
//! (a share of a wheel radius) and every entry of the wz row at most [`MAX_YAW_GAIN`] rad/rad (a
//! share of radius over track) in magnitude, and the matrix is not all zero.
//!
//! # Equations (one [`Odometry::update`], period `dt`)
//!
//! ```text
//!   Δφ_n = (c_n ⊖ c_n,prev) · ticks_to_rad[n]          rad; ⊖ is the wrapping i32 difference,
//!                                                      so a counter wrap is no jump
//!   (Δx, Δy, Δθ) = inverse · Δφ                        body-frame displacement over the period
//!   (vx, vy, wz) = (Δx, Δy, Δθ) / dt                   the twist, constant over the period
//!
//!   exact for a constant twist (the SE(2) exponential), θ₀ the heading at the period's start:
//!   a = sin Δθ / Δθ,   b = (1 − cos Δθ) / Δθ           (series for |Δθ| < 10⁻², both → 1, 0)
//!   x += cos θ₀ · (a Δx − b Δy) − sin θ₀ · (b Δx + a Δy)
//!   y += sin θ₀ · (a Δx − b Δy) + cos θ₀ · (b Δx + a Δy)
//!   θ  = wrap(θ₀ + Δθ) into (−π, π]
//! ```
//!
//! The pose depends on the displacement only, not on `dt`: a coarse or jittery period changes the
//! reported velocity, never the pose, and an arc driven at constant curvature lands on the circle
//! however few updates cover it. `b` is computed as `2 sin²(Δθ/2) / Δθ`, which loses no precision
//! to the cancellation in `1 − cos Δθ`.
//!
//! Position and heading are accumulated in f32 with compensated summation: the exact rounding
//! error of each addition is kept in a second f32 and folded back (renormalised) every time, so the
//! error of a long path does not grow with the number of updates. Measured in the tests: a 10 m
//! straight run ends 0.94 µm off in 10 030 updates of 13 counts and 0.01 µm off in 130 390 updates
//! of 1 count (a plain f32 sum of the same steps is 0.76 mm and 5.5 mm off); a 1 m-radius quarter
//! circle in 1000 updates ends (0.12, −0.06) µm off. The 2π of the heading wrap is applied in two
//! parts (the f32 `TAU` and its remainder), so whole turns leave no residue: after 1554 turns the
//! heading is within 1.2·10⁻⁷ rad (the f32 output's rounding) of the exact one, where `TAU` alone
//! would leave 2.7·10⁻⁴ rad.
//!
//! # When outputs are zero
//!
//! - Until a configuration is accepted, every field is zero, whatever the counts do (seed 004:
//!   "Until then, all odometry fields are zero").
//! - The update that takes a new encoder baseline (the first after a configuration or a reset)
//!   reports zero velocities: there is no previous count to difference.
//!
//! # Reset and configure
//!
//! - [`Odometry::reset`] (update flag `ODOM_RESET`): pose and velocities zero; the next update takes
//!   the counts as the new baseline. The configuration stays.
//! - [`Odometry::configure`] (update flag `KINEMATICS`), accepted: the pose is **kept** (a new
//!   geometry re-interprets future motion, it does not move the robot; the Pi sends `ODOM_RESET`
//!   with it to start from zero), the velocities are zeroed, and the next update takes the new
//!   baseline, so counts that moved while unconfigured, or under the old geometry, cause no jump.
//!   The motion of at most that one period is not integrated. Refused: nothing changes but
//!   [`OdometryCounters::refused_configs`].
//!
//! # Nothing saturates silently
//!
//! A refused period (`dt` not finite or below [`MIN_DT_S`]) changes nothing, is counted, and its
//! motion is integrated by the next accepted update (the baseline stays). A rotation of more than
//! half a turn in one period is reduced modulo 2π and counted; a position beyond
//! ±[`MAX_POSITION_M`] is clamped and counted. With the bounds above no arithmetic can overflow to
//! ±∞ or make NaN (|Δφ| ≤ 2³¹·2π, so |Δx|, |Δy| ≤ 5.4·10¹¹ m, |Δθ| ≤ 5.4·10¹³ rad, every twist
//! ≤ 5.4·10¹⁹ after the division by dt ≥ 10⁻⁶ s); a non-finite result would still be dropped and
//! counted in [`OdometryCounters::non_finite`], which the harness checks stays zero.

use core::f32::consts::{PI, TAU};
use protocol::pi_spi::assumed::KinematicsConfig;
use protocol::pi_spi::OdometryData;

/// Smallest accepted |`ticks_to_rad`|, rad per count: 10⁹ counts per radian is beyond any
/// encoder (an i32 counter would wrap within 4.3 rad); refuses zero and subnormal scales.
pub const MIN_TICKS_TO_RAD: f32 = 1e-9;
/// Largest accepted |`ticks_to_rad`|, rad per count: at least one count per wheel revolution.
pub const MAX_TICKS_TO_RAD: f32 = TAU;
/// Largest accepted |entry| of the vx and vy rows, m/rad: a share of a wheel radius, and a wheel
/// radius is at most 10 m (the bound of the differential-drive geometry in `control`).
pub const MAX_LINEAR_GAIN: f32 = 10.0;
/// Largest accepted |entry| of the wz row, rad/rad: a share of wheel radius over track, at most
/// 10 m / 1 cm (the bounds of the differential-drive geometry in `control`).
pub const MAX_YAW_GAIN: f32 = 1000.0;
/// Shortest accepted period, s: the resolution of the board's µs time stamps. Also what keeps
/// every velocity finite.
pub const MIN_DT_S: f32 = 1e-6;
/// Largest reported |pos_x|, |pos_y|, m (100 km: f32 still resolves 8 mm there). Beyond it a
/// coordinate is clamped and counted; odometry alone is meaningless that far from its reset.
pub const MAX_POSITION_M: f32 = 1e5;

/// Below this |Δθ| (rad) the arc factors come from their series.
const SMALL_ANGLE: f32 = 1e-2;
/// 2π − `TAU` (the part of 2π that the f32 `TAU` misses): 2π = `TAU` + `TAU_LO`.
const TAU_LO: f32 = -1.748_455_6e-7;

/// Why a `KinematicsConfig` was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum KinematicsError {
    /// A number is NaN or infinite.
    NotFinite = 1,
    /// A `ticks_to_rad` is zero or its magnitude is outside [`MIN_TICKS_TO_RAD`]..=[`MAX_TICKS_TO_RAD`].
    TicksToRad = 2,
    /// An `inverse` entry exceeds its row's bound ([`MAX_LINEAR_GAIN`] for vx, vy; [`MAX_YAW_GAIN`] for wz).
    InverseEntry = 3,
    /// Every `inverse` entry is zero: no wheel would move the robot.
    ZeroMatrix = 4,
}

/// What the odometry refused, reduced or clamped since boot (saturating counts).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OdometryCounters {
    /// `KINEMATICS` updates refused; the configuration in force stayed.
    pub refused_configs: u32,
    /// Updates refused for their period (not finite, or below [`MIN_DT_S`]); nothing changed.
    pub refused_dt: u32,
    /// Periods that turned more than half a revolution: the heading step was reduced modulo 2π.
    pub large_rotations: u32,
    /// Updates that clamped a coordinate at ±[`MAX_POSITION_M`].
    pub position_clamped: u32,
    /// Updates dropped because a result was not finite (the bounds rule this out: expected zero).
    pub non_finite: u32,
}

/// `a + b` rounded, and the rounding error, exactly (Dekker's Fast2Sum on the larger magnitude
/// first; exact in round-to-nearest binary floating point while nothing overflows).
fn two_sum(a: f32, b: f32) -> (f32, f32) {
    let s = a + b;
    let err = if a.abs() >= b.abs() {
        b - (s - a)
    } else {
        a - (s - b)
    };
    (s, err)
}

/// An f32 sum with its rounding error carried in a second f32 and folded back after every
/// addition (compensated summation, renormalised: |lo| ≤ half an ulp of hi, so the carried error
/// never grows and never loses its own precision).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sum {
    hi: f32,
    lo: f32,
}

impl Sum {
    const ZERO: Self = Self { hi: 0.0, lo: 0.0 };

    fn add(&mut self, x: f32) {
        let (t, err) = two_sum(self.hi, x);
        (self.hi, self.lo) = two_sum(t, self.lo + err);
    }

    fn value(self) -> f32 {
        self.hi + self.lo
    }
}

/// The board's odometry: the configuration in force, the encoder baseline, the pose and the last
/// twist. Updated by the link task once per SPI transfer, read into every `TxBuffer`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Odometry {
    /// The accepted configuration; `None` until the Pi sent one.
    config: Option<KinematicsConfig>,
    /// Counts at the last accepted update; `None`: the next update takes them.
    baseline: Option<[i32; 4]>,
    x: Sum,
    y: Sum,
    /// Kept in (−π, π] (up to the last rounding, see [`Odometry::data`]).
    heading: Sum,
    /// Body twist of the last accepted period: vx, vy (m/s), wz (rad/s).
    twist: [f32; 3],
    counters: OdometryCounters,
}

impl Default for Odometry {
    fn default() -> Self {
        Self::new()
    }
}

/// `inverse` · `phi`, row by row.
fn body_displacement(inverse: &[[f32; 4]; 3], phi: &[f32; 4]) -> [f32; 3] {
    let mut out = [0.0f32; 3];
    for (o, row) in out.iter_mut().zip(inverse) {
        *o = row.iter().zip(phi).map(|(a, p)| a * p).sum();
    }
    out
}

/// The arc factors (sin Δθ / Δθ, (1 − cos Δθ) / Δθ) of the SE(2) exponential.
fn arc_factors(dtheta: f32) -> (f32, f32) {
    if dtheta.abs() < SMALL_ANGLE {
        // Truncation below 3·10⁻¹⁶ relative at the threshold: far under f32's 6·10⁻⁸.
        let sq = dtheta * dtheta;
        let a = 1.0 - sq / 6.0 * (1.0 - sq / 20.0);
        let b = dtheta / 2.0 * (1.0 - sq / 12.0 * (1.0 - sq / 30.0));
        (a, b)
    } else {
        let half = libm::sinf(dtheta / 2.0);
        (libm::sinf(dtheta) / dtheta, 2.0 * half * half / dtheta)
    }
}

/// Adds `x` to the position coordinate `s`, clamping at ±[`MAX_POSITION_M`]; true if it clamped.
fn add_clamped(s: &mut Sum, x: f32) -> bool {
    s.add(x);
    let v = s.value();
    if v.abs() > MAX_POSITION_M {
        *s = Sum {
            hi: MAX_POSITION_M.copysign(v),
            lo: 0.0,
        };
        true
    } else {
        false
    }
}

/// Brings the heading sum back into (−π, π] after a step of at most π: one 2π, in two parts, and
/// a second if the first left it outside (the rounding's margin).
fn wrap_heading(h: &mut Sum) {
    for _ in 0..2 {
        if !wrap_once(h) {
            return;
        }
    }
}

/// Moves the heading sum by one 2π (in two parts) toward (−π, π] if its value is outside; whether
/// it was.
fn wrap_once(h: &mut Sum) -> bool {
    let v = h.value();
    if v > PI {
        h.add(-TAU);
        h.add(-TAU_LO);
        true
    } else if v <= -PI {
        h.add(TAU);
        h.add(TAU_LO);
        true
    } else {
        false
    }
}

/// Checks a configuration against the bounds in the module documentation.
pub fn validate(k: &KinematicsConfig) -> Result<(), KinematicsError> {
    let bounds = [MAX_LINEAR_GAIN, MAX_LINEAR_GAIN, MAX_YAW_GAIN];
    // One pass by index over the 16 numbers (under Kani, no iterator's pointer offsets: the
    // configuration harness took a third of its time); the refusal is the first rule broken.
    let (mut finite, mut ticks_ok, mut within, mut zero) = (true, true, true, true);
    #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
    for j in 0..4 {
        let t = k.ticks_to_rad[j];
        finite &= t.is_finite();
        ticks_ok &= (MIN_TICKS_TO_RAD..=MAX_TICKS_TO_RAD).contains(&t.abs());
        for i in 0..3 {
            let a = k.inverse[i][j];
            finite &= a.is_finite();
            within &= a.abs() <= bounds[i];
            zero &= a == 0.0;
        }
    }
    if !finite {
        return Err(KinematicsError::NotFinite);
    }
    if !ticks_ok {
        return Err(KinematicsError::TicksToRad);
    }
    if !within {
        return Err(KinematicsError::InverseEntry);
    }
    if zero {
        return Err(KinematicsError::ZeroMatrix);
    }
    Ok(())
}

impl Odometry {
    /// Unconfigured: every output zero until [`Odometry::configure`] accepts a configuration.
    pub const fn new() -> Self {
        Self {
            config: None,
            baseline: None,
            x: Sum::ZERO,
            y: Sum::ZERO,
            heading: Sum::ZERO,
            twist: [0.0; 3],
            counters: OdometryCounters {
                refused_configs: 0,
                refused_dt: 0,
                large_rotations: 0,
                position_clamped: 0,
                non_finite: 0,
            },
        }
    }

    /// Update flag `KINEMATICS`: validates `k` ([`validate`]) and puts it in force. On `Err` nothing
    /// changes but [`OdometryCounters::refused_configs`]. On `Ok` the pose is kept, the velocities
    /// are zeroed, and the next update takes the encoder baseline, so there is no jump.
    pub fn configure(&mut self, k: &KinematicsConfig) -> Result<(), KinematicsError> {
        if let Err(e) = validate(k) {
            self.counters.refused_configs = self.counters.refused_configs.saturating_add(1);
            return Err(e);
        }
        self.config = Some(*k);
        self.baseline = None;
        self.twist = [0.0; 3];
        Ok(())
    }

    /// Update flag `ODOM_RESET`: pose and velocities zero; the next update takes the counts as the
    /// baseline. The configuration stays.
    pub fn reset(&mut self) {
        self.x = Sum::ZERO;
        self.y = Sum::ZERO;
        self.heading = Sum::ZERO;
        self.twist = [0.0; 3];
        self.baseline = None;
    }

    /// One period: the four cumulative encoder counts (wrapping) and the period `dt_s` in seconds
    /// since the last update. A `dt_s` that is not finite or is below [`MIN_DT_S`] changes nothing
    /// and is counted (the next accepted update integrates the motion since the last one).
    /// Returns the data for the next `TxBuffer`.
    pub fn update(&mut self, counts: [i32; 4], dt_s: f32) -> OdometryData {
        if !(dt_s.is_finite() && dt_s >= MIN_DT_S) {
            self.counters.refused_dt = self.counters.refused_dt.saturating_add(1);
            return self.data();
        }
        self.integrate(counts, dt_s)
    }

    /// [`Odometry::update`] of an accepted period (`dt_s` finite and at least [`MIN_DT_S`]).
    fn integrate(&mut self, counts: [i32; 4], dt_s: f32) -> OdometryData {
        let Some(k) = self.config else {
            return self.data();
        };
        let Some(prev) = self.baseline.replace(counts) else {
            self.twist = [0.0; 3];
            return self.data();
        };
        let mut phi = [0.0f32; 4];
        for (((p, now), before), scale) in phi.iter_mut().zip(counts).zip(prev).zip(k.ticks_to_rad)
        {
            *p = now.wrapping_sub(before) as f32 * scale;
        }
        let [dx, dy, dtheta] = body_displacement(&k.inverse, &phi);
        let twist = [dx / dt_s, dy / dt_s, dtheta / dt_s];

        let theta0 = self.heading.value();
        let (a, b) = arc_factors(dtheta);
        let (along, across) = (a * dx - b * dy, b * dx + a * dy);
        let (sin0, cos0) = (libm::sinf(theta0), libm::cosf(theta0));
        let (wx, wy) = (cos0 * along - sin0 * across, sin0 * along + cos0 * across);
        let turn = if dtheta.abs() > PI {
            libm::remainderf(dtheta, TAU)
        } else {
            dtheta
        };

        if !twist.iter().chain(&[wx, wy, turn]).all(|v| v.is_finite()) {
            // Unreachable with the accepted bounds; dropped rather than propagated.
            self.baseline = Some(prev);
            self.counters.non_finite = self.counters.non_finite.saturating_add(1);
            return self.data();
        }
        if turn != dtheta {
            self.counters.large_rotations = self.counters.large_rotations.saturating_add(1);
        }
        let clamped_x = add_clamped(&mut self.x, wx);
        let clamped_y = add_clamped(&mut self.y, wy);
        if clamped_x || clamped_y {
            self.counters.position_clamped = self.counters.position_clamped.saturating_add(1);
        }
        self.heading.add(turn);
        wrap_heading(&mut self.heading);
        self.twist = twist;
        self.data()
    }

    /// The odometry as it goes into `TxBuffer.odometry`: all zero until configured. The heading
    /// is in (−π, π] (with π the f32 `PI`); a sum that rounds to −π is reported as π, the same angle.
    pub fn data(&self) -> OdometryData {
        if self.config.is_none() {
            return OdometryData::default();
        }
        let h = self.heading.value();
        let [vx, vy, wz] = self.twist;
        OdometryData {
            pos_x: self.x.value(),
            pos_y: self.y.value(),
            heading: if h > -PI && h <= PI { h } else { PI },
            vx,
            vy,
            wz,
        }
    }

    /// Whether a configuration is in force.
    pub const fn configured(&self) -> bool {
        self.config.is_some()
    }

    /// The configuration in force, if any.
    pub const fn config(&self) -> Option<&KinematicsConfig> {
        self.config.as_ref()
    }

    /// What was refused, reduced or clamped since boot.
    pub const fn counters(&self) -> OdometryCounters {
        self.counters
    }
}

#[cfg(test)]
mod tests;

#[cfg(any(test, kani))]
mod verification;
