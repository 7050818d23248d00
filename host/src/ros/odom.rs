//! Wheel odometry from the MCU's cumulative encoder counts: pose by integrating the wheel arcs
//! between two feedbacks (midpoint rule), velocity from the measured wheel speeds.
//!
//! ```text
//!  Δθ = Δcounts · 2π / counts_per_rev      (per wheel, wrapping i32 difference)
//!  Δs = r (Δθl + Δθr) / 2     Δψ = r (Δθr − Δθl) / L
//!  x += Δs cos(ψ + Δψ/2)      y += Δs sin(ψ + Δψ/2)      ψ += Δψ
//! ```
//!
//! The counts are cumulative, so the pose does not depend on how often it is updated. A jump no
//! wheel could make in the MCU time between the two feedbacks (an MCU reset zeroes its counts) is
//! not integrated: the counts are taken as the new reference and the jump is counted.

use core::f64::consts::TAU;

use protocol::amr::MotorFeedback;

use crate::kinematics::DiffDrive;

/// Pose, velocity and wheel angles of the robot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OdomState {
    /// x in the odometry frame, m.
    pub x: f64,
    /// y in the odometry frame, m.
    pub y: f64,
    /// Heading, rad, wrapped to (−π, π].
    pub yaw: f64,
    /// Forward velocity, m/s.
    pub v: f64,
    /// Yaw rate, rad/s.
    pub w: f64,
    /// Wheel angles (left, right) since the first feedback, rad.
    pub wheel_angle: [f64; 2],
    /// Measured wheel speeds (left, right), rad/s.
    pub wheel_speed: [f64; 2],
}

/// The integrator.
#[derive(Clone, Debug)]
pub struct Odometer {
    drive: DiffDrive,
    rad_per_count: f64,
    reference: Option<([i32; 2], u32)>,
    state: OdomState,
    /// Encoder jumps not integrated.
    pub jumps: u64,
}

/// The wrapped difference `a − b` of two cumulative i32 counters.
fn delta(a: i32, b: i32) -> f64 {
    f64::from(a.wrapping_sub(b))
}

/// `a` wrapped to (−π, π].
fn wrap(a: f64) -> f64 {
    let r = a.rem_euclid(TAU);
    if r > core::f64::consts::PI {
        r - TAU
    } else {
        r
    }
}

impl Odometer {
    /// An odometer at the origin for `drive` and `counts_per_rev` (at least 1).
    pub fn new(drive: DiffDrive, counts_per_rev: u32) -> Self {
        Self {
            drive,
            rad_per_count: TAU / f64::from(counts_per_rev.max(1)),
            reference: None,
            state: OdomState::default(),
            jumps: 0,
        }
    }

    /// The current estimate.
    pub fn state(&self) -> OdomState {
        self.state
    }

    /// Takes one feedback into account.
    pub fn update(&mut self, fb: &MotorFeedback) {
        let enc = [fb.left_encoder, fb.right_encoder];
        let speed = [f64::from(fb.left_speed), f64::from(fb.right_speed)];
        if speed.iter().all(|s| s.is_finite()) {
            let (v, w) = self.drive.forward(speed[0], speed[1]);
            self.state.v = v;
            self.state.w = w;
            self.state.wheel_speed = speed;
        }
        let Some((prev, prev_t)) = self.reference.replace((enc, fb.timestamp_us)) else {
            return;
        };
        let dl = delta(enc[0], prev[0]) * self.rad_per_count;
        let dr = delta(enc[1], prev[1]) * self.rad_per_count;
        // The most any wheel can turn in the MCU time between the two (twice the limit, plus one
        // count of slack): more is no motion but a reset.
        let dt = f64::from(fb.timestamp_us.wrapping_sub(prev_t)) * 1e-6;
        let bound = 2.0 * self.drive.max_wheel_speed() * dt + self.rad_per_count;
        if dl.abs() > bound || dr.abs() > bound {
            self.jumps = self.jumps.saturating_add(1);
            return;
        }
        let k = self.drive.config();
        let ds = k.wheel_radius_m * (dl + dr) / 2.0;
        let dyaw = k.wheel_radius_m * (dr - dl) / k.wheelbase_m;
        let mid = self.state.yaw + dyaw / 2.0;
        self.state.x += ds * mid.cos();
        self.state.y += ds * mid.sin();
        self.state.yaw = wrap(self.state.yaw + dyaw);
        self.state.wheel_angle[0] += dl;
        self.state.wheel_angle[1] += dr;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::float_cmp)]
mod tests {
    use super::*;

    fn fb(t_us: u32, l: i32, r: i32) -> MotorFeedback {
        MotorFeedback {
            timestamp_us: t_us,
            left_encoder: l,
            right_encoder: r,
            ..MotorFeedback::default()
        }
    }

    /// The default robot (r = 0.08 m, L = 0.40 m held to 15 µm) with 4096 counts per turn.
    fn odo() -> Odometer {
        Odometer::new(DiffDrive::DEFAULT, 4096)
    }

    #[test]
    fn one_wheel_turn_forward_is_one_circumference() {
        let mut o = odo();
        o.update(&fb(0, 100, -50));
        // One full turn of both wheels in 1 s (6.28 rad/s, under the limit): 2π·0.08 m.
        o.update(&fb(1_000_000, 100 + 4096, -50 + 4096));
        let s = o.state();
        assert!((s.x - TAU * 0.08).abs() < 1e-4, "{s:?}");
        assert!(s.y.abs() < 1e-9 && s.yaw.abs() < 1e-9, "{s:?}");
        assert!((s.wheel_angle[0] - TAU).abs() < 1e-12);
    }

    #[test]
    fn the_pose_does_not_depend_on_the_update_rate() {
        let mut coarse = odo();
        let mut fine = odo();
        coarse.update(&fb(0, 0, 0));
        fine.update(&fb(0, 0, 0));
        // An arc: the right wheel twice as fast as the left, 1000 steps of 1 ms.
        for k in 1..=1000i32 {
            fine.update(&fb(k as u32 * 1000, k * 2, k * 4));
        }
        coarse.update(&fb(1_000_000, 2000, 4000));
        // Same wheel angles and heading (both linear in the counts, up to float rounding); x
        // differs only by the midpoint rule's error on one 0.61 rad step: (ψ/2)/sin(ψ/2) = 1.016
        // of 0.35 m, 6 mm.
        for (c, f) in coarse
            .state()
            .wheel_angle
            .iter()
            .zip(fine.state().wheel_angle)
        {
            assert!((c - f).abs() < 1e-9, "{c} {f}");
        }
        assert!((coarse.state().yaw - fine.state().yaw).abs() < 1e-9);
        let dx = (coarse.state().x - fine.state().x).abs();
        assert!(dx > 1e-3 && dx < 1e-2, "{dx}");
    }

    #[test]
    fn spinning_in_place_turns_by_r_over_half_l() {
        let mut o = odo();
        o.update(&fb(0, 0, 0));
        // Left −1024 counts (−π/2 rad), right +1024: Δψ = 0.08·π / 0.40 = 0.2π rad.
        o.update(&fb(1_000_000, -1024, 1024));
        let s = o.state();
        assert!((s.yaw - 0.2 * core::f64::consts::PI).abs() < 1e-4, "{s:?}");
        assert!(s.x.abs() < 1e-12 && s.y.abs() < 1e-12);
    }

    #[test]
    fn a_counter_wrap_is_a_small_step() {
        let mut o = odo();
        o.update(&fb(0, i32::MAX - 10, i32::MAX - 10));
        o.update(&fb(10_000, i32::MIN + 9, i32::MIN + 9));
        // 20 counts each: 20·2π/4096·0.08 m.
        let want = 20.0 * TAU / 4096.0 * 0.08;
        assert!((o.state().x - want).abs() < 1e-6, "{:?}", o.state());
        assert_eq!(o.jumps, 0);
    }

    #[test]
    fn a_reset_of_the_counts_is_not_motion() {
        let mut o = odo();
        o.update(&fb(0, 500_000, 500_000));
        o.update(&fb(1000, 0, 0));
        assert_eq!(o.state().x, 0.0);
        assert_eq!(o.jumps, 1);
        // Counting resumes from the new reference.
        o.update(&fb(1_001_000, 4096, 4096));
        assert!((o.state().x - TAU * 0.08).abs() < 1e-4);
    }

    #[test]
    fn velocity_comes_from_the_measured_wheel_speeds() {
        let mut o = odo();
        let mut f = fb(0, 0, 0);
        // 10 rad/s each on 0.08 m wheels: 0.8 m/s, no turn.
        f.left_speed = 10.0;
        f.right_speed = 10.0;
        o.update(&f);
        assert!((o.state().v - 0.8).abs() < 1e-3);
        assert!(o.state().w.abs() < 1e-4);
    }
}
