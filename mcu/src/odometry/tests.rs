//! Expected values come from the geometry (distance = r·φ, a circle of radius v/ω, the robot's own
//! axes rotated by its heading), computed in f64 from the configuration's numbers; never from the
//! code's own output.

use super::*;
use core::f64::consts::{FRAC_PI_2 as HALF_PI_64, PI as PI_64, TAU as TAU_64};
use std::println;
use std::vec::Vec;

/// Wheel radius, m, and track width (left to right wheel contact), m.
const R: f64 = 0.05;
const TRACK: f64 = 0.3;
/// Half the sum of the mecanum base's half-length and half-width, m.
const LXY: f64 = 0.35;
const DT: f32 = 0.001;

/// A differential drive on four wheels: 0 and 2 left, 1 and 3 right.
/// vx = r/2·(ω_L + ω_R) with ω_L = (ω₀ + ω₂)/2, ω_R = (ω₁ + ω₃)/2; wz = r/track·(ω_R − ω_L).
fn diff_drive(ticks_to_rad: f64) -> KinematicsConfig {
    let (a, w) = ((R / 4.0) as f32, (R / (2.0 * TRACK)) as f32);
    KinematicsConfig {
        inverse: [[a, a, a, a], [0.0; 4], [-w, w, -w, w]],
        ticks_to_rad: [ticks_to_rad as f32; 4],
    }
}

/// A mecanum base, wheels front-left, front-right, rear-left, rear-right (rollers in an X seen from
/// above): vx = r/4·(ω₀+ω₁+ω₂+ω₃), vy = r/4·(−ω₀+ω₁+ω₂−ω₃), wz = r/(4·(lx+ly))·(−ω₀+ω₁−ω₂+ω₃).
fn mecanum(ticks_to_rad: f64) -> KinematicsConfig {
    let (a, w) = ((R / 4.0) as f32, (R / (4.0 * LXY)) as f32);
    KinematicsConfig {
        inverse: [[a, a, a, a], [-a, a, a, -a], [-w, w, -w, w]],
        ticks_to_rad: [ticks_to_rad as f32; 4],
    }
}

/// An odometry and the encoders it reads.
struct Rig {
    o: Odometry,
    counts: [i32; 4],
}

impl Rig {
    /// Configured, baseline taken at `counts`.
    fn new(k: KinematicsConfig, counts: [i32; 4]) -> Self {
        let mut o = Odometry::new();
        o.configure(&k).unwrap();
        let d = o.update(counts, DT);
        assert_eq!(d, OdometryData::default());
        Self { o, counts }
    }

    fn step(&mut self, delta: [i32; 4]) -> OdometryData {
        for (c, d) in self.counts.iter_mut().zip(delta) {
            *c = c.wrapping_add(d);
        }
        self.o.update(self.counts, DT)
    }

    fn steps(&mut self, n: u32, delta: [i32; 4]) -> OdometryData {
        let mut d = self.o.data();
        for _ in 0..n {
            d = self.step(delta);
            assert_finite_and_wrapped(&d);
        }
        d
    }
}

fn assert_finite_and_wrapped(d: &OdometryData) {
    for v in [d.pos_x, d.pos_y, d.heading, d.vx, d.vy, d.wz] {
        assert!(v.is_finite(), "{d:?}");
    }
    assert!(d.heading > -PI && d.heading <= PI, "{d:?}");
}

#[track_caller]
fn near(got: f32, want: f64, tol: f64) {
    let err = (f64::from(got) - want).abs();
    assert!(
        err <= tol,
        "got {got}, want {want}, error {err:e} > {tol:e}"
    );
}

/// The heading difference, wrapped, for comparing angles near ±π.
fn angle_err(got: f32, want: f64) -> f64 {
    let d = (f64::from(got) - want).rem_euclid(TAU_64);
    d.min(TAU_64 - d)
}

#[test]
fn unconfigured_outputs_zero_even_when_counts_move() {
    let mut o = Odometry::new();
    assert!(!o.configured());
    for i in 0..100i32 {
        let c = i.wrapping_mul(1_000_003);
        assert_eq!(o.update([c, -c, c, 7], DT), OdometryData::default());
    }
    o.reset();
    assert_eq!(o.data(), OdometryData::default());
    assert_eq!(Odometry::default(), Odometry::new());
}

#[test]
fn first_update_after_configure_takes_the_baseline() {
    let t2r = TAU_64 / 4096.0;
    let mut o = Odometry::new();
    o.update([5_000, 6_000, 7_000, 8_000], DT);
    o.configure(&diff_drive(t2r)).unwrap();
    assert!(o.configured());
    // The counts moved a lot while unconfigured: the first update only takes them.
    assert_eq!(
        o.update([9_000_000, 9_000_000, -9_000_000, 9], DT),
        OdometryData::default()
    );
    let d = o.update([9_000_013, 9_000_013, -8_999_987, 22], DT);
    near(d.pos_x, R * 13.0 * t2r, 1e-9);
    near(d.vx, R * 13.0 * t2r / f64::from(DT), 1e-5);
    assert_eq!((d.pos_y, d.heading, d.wz), (0.0, 0.0, 0.0));
}

/// The measured error of a 10 m straight run, for the report in the module documentation.
fn straight_run(per_step: i32, steps: u32) -> (f64, f32) {
    let t2r = TAU_64 / 4096.0;
    let mut rig = Rig::new(diff_drive(t2r), [0; 4]);
    let d = rig.steps(steps, [per_step; 4]);
    let want = R * f64::from(per_step) * f64::from(steps) * t2r; // distance = r·φ
    assert!((want - 10.0).abs() < 1e-3);
    let err = f64::from(d.pos_x) - want;
    println!("straight {per_step} counts × {steps}: want {want} m, error {err:e} m");
    assert!(err.abs() <= 1e-3 * want, "within 1e-3 relative");
    assert!(err.abs() <= 1e-5, "compensated sum: within 10 µm");
    assert_eq!((d.pos_y, d.heading, d.vy, d.wz), (0.0, 0.0, 0.0, 0.0));
    (err, d.vx)
}

#[test]
fn straight_10_m_run() {
    // 1 m/s at 1 kHz: 13 counts of a 4096-count encoder per period, 10 030 periods.
    let (_, vx) = straight_run(13, 10_030);
    near(vx, R * 13.0 * TAU_64 / 4096.0 / f64::from(DT), 1e-5);
}

#[test]
fn straight_10_m_creep_one_count_per_update() {
    // 130 390 updates of 77 µm: an uncompensated f32 sum would round every one of them at 10 m.
    let (_, vx) = straight_run(1, 130_390);
    near(vx, R * TAU_64 / 4096.0 / f64::from(DT), 1e-6);
}

#[test]
fn straight_backwards() {
    let t2r = TAU_64 / 4096.0;
    let mut rig = Rig::new(diff_drive(t2r), [0; 4]);
    let d = rig.steps(1000, [-13; 4]);
    near(d.pos_x, -R * 13_000.0 * t2r, 1e-6);
    assert!(d.vx < 0.0);
}

#[test]
fn spin_in_place_whole_turns_return_to_start() {
    // Left wheels back, right wheels forward, 3 counts each: wz·dt = r/(2·track)·12·t2r = t2r,
    // so 4096 periods are one turn.
    let t2r = TAU_64 / 4096.0;
    let mut rig = Rig::new(diff_drive(t2r), [0; 4]);
    let spin = [-3, 3, -3, 3];
    let mut worst: f64 = 0.0;
    for turn in 0..5u32 {
        for quarter in 1..=4u32 {
            let d = rig.steps(1024, spin);
            let err = angle_err(d.heading, f64::from(quarter) * HALF_PI_64);
            worst = worst.max(err);
            assert!(err < 1e-5, "turn {turn} quarter {quarter}: {d:?}");
            assert_eq!((d.pos_x, d.pos_y), (0.0, 0.0), "no translation");
        }
    }
    let d = rig.o.data();
    println!("5 turns: heading {:e} rad, worst {worst:e}", d.heading);
    // What is left is the configuration's own rounding: its f32 numbers are not exactly
    // r/(2·track) and 2π/4096 (4096 of its periods turn 2π + 1.7·10⁻⁷ rad).
    assert!(d.heading.abs() < 1e-5);
    near(d.wz, t2r / f64::from(DT), 1e-4);
    // And back the other way, through −π.
    let d = rig.steps(5 * 4096, [3, -3, 3, -3]);
    assert!(d.heading.abs() < 1e-7, "{d:?}");
}

#[test]
fn heading_wraps_without_drift_over_many_turns() {
    // Numbers exact in f32 (1 rad per rad, 2⁻¹⁰ rad per count, 1000 counts a period), so every
    // period turns exactly 0.9765625 rad and the expected heading is that times n, wrapped with
    // the true π. A 2π applied as the f32 `TAU` alone would leave 1.7·10⁻⁷ rad per turn:
    // 2.7·10⁻⁴ rad after these 1554 turns.
    let k = KinematicsConfig {
        inverse: [[0.0; 4], [0.0; 4], [1.0, 0.0, 0.0, 0.0]],
        ticks_to_rad: [1.0 / 1024.0; 4],
    };
    for sign in [1, -1] {
        let mut rig = Rig::new(k, [0; 4]);
        let mut worst: f64 = 0.0;
        for n in 1..=10_000u32 {
            let d = rig.step([sign * 1000, 0, 0, 0]);
            assert!(d.heading > -PI && d.heading <= PI);
            let err = angle_err(d.heading, f64::from(sign) * f64::from(n) * 0.976_562_5);
            worst = worst.max(err);
        }
        println!("1554 turns ({sign}): worst heading error {worst:e} rad");
        assert!(worst < 2e-7, "{worst:e}");
        assert_eq!(rig.o.counters().large_rotations, 0);
    }
}

/// Left wheels 17 counts, right 23, t2r = π/2000: v·dt = r/4·80·t2r = t2r and
/// wz·dt = r/(2·track)·12·t2r = t2r, so the radius is v/ω = 1 m and 1000 periods are a quarter turn.
const ARC_T2R: f64 = PI_64 / 2000.0;

#[test]
fn quarter_circle_ends_at_r_r() {
    let mut rig = Rig::new(diff_drive(ARC_T2R), [0; 4]);
    let d = rig.steps(1000, [17, 23, 17, 23]);
    let (ex, ey) = (f64::from(d.pos_x) - 1.0, f64::from(d.pos_y) - 1.0);
    println!("quarter circle R = 1 m in 1000 steps: error ({ex:e}, {ey:e}) m");
    near(d.pos_x, 1.0, 1e-5);
    near(d.pos_y, 1.0, 1e-5);
    near(d.heading, HALF_PI_64, 1e-6);
    near(d.vx, ARC_T2R / f64::from(DT), 1e-4);
    near(d.wz, ARC_T2R / f64::from(DT), 1e-4);
}

#[test]
fn quarter_circle_exact_however_few_updates() {
    // The pose integrates the arc exactly for a constant twist: 10 updates or a single one land on
    // (R, R) as well. (Euler steps would put the single update at (π/2, 0).)
    for (n, per) in [(10u32, 100i32), (1, 1000)] {
        let mut rig = Rig::new(diff_drive(ARC_T2R), [0; 4]);
        let d = rig.steps(n, [17 * per, 23 * per, 17 * per, 23 * per]);
        near(d.pos_x, 1.0, 1e-6);
        near(d.pos_y, 1.0, 1e-6);
        near(d.heading, HALF_PI_64, 1e-6);
    }
}

#[test]
fn clockwise_arc_and_full_circle() {
    // Right wheels slower: a clockwise quarter circle ends at (R, −R), heading −π/2.
    let mut rig = Rig::new(diff_drive(ARC_T2R), [0; 4]);
    let d = rig.steps(1000, [23, 17, 23, 17]);
    near(d.pos_x, 1.0, 1e-5);
    near(d.pos_y, -1.0, 1e-5);
    near(d.heading, -HALF_PI_64, 1e-6);
    assert!(d.wz < 0.0);
    // Three more quarters close the circle.
    let d = rig.steps(3000, [23, 17, 23, 17]);
    near(d.pos_x, 0.0, 2e-5);
    near(d.pos_y, 0.0, 2e-5);
    assert!(d.heading.abs() < 1e-5, "{d:?}");
}

#[test]
fn mecanum_strafe_turn_strafe_drive() {
    // t2r = π/2000: strafing (−20, 20, 20, −20) moves r/4·80·t2r = t2r per period to the left;
    // turning (−7, 7, −7, 7) turns r/(4·lxy)·28·t2r = t2r; driving (20, 20, 20, 20) moves t2r ahead.
    let t2r = PI_64 / 2000.0;
    let q = HALF_PI_64; // 1000 periods of each: π/2 m, or π/2 rad
    let mut rig = Rig::new(mecanum(t2r), [0; 4]);
    let d = rig.steps(1000, [-20, 20, 20, -20]);
    near(d.pos_x, 0.0, 1e-6);
    near(d.pos_y, q, 1e-5);
    assert_eq!((d.heading, d.vx, d.wz), (0.0, 0.0, 0.0));
    near(d.vy, t2r / f64::from(DT), 1e-4);
    let d = rig.steps(1000, [-7, 7, -7, 7]);
    near(d.pos_x, 0.0, 1e-6);
    near(d.pos_y, q, 1e-5);
    near(d.heading, q, 1e-6);
    // Facing north, the robot's left is west.
    let d = rig.steps(1000, [-20, 20, 20, -20]);
    near(d.pos_x, -q, 1e-5);
    near(d.pos_y, q, 1e-5);
    near(d.vy, t2r / f64::from(DT), 1e-4);
    let d = rig.steps(1000, [20, 20, 20, 20]);
    near(d.pos_x, -q, 1e-5);
    near(d.pos_y, 2.0 * q, 1e-5);
    near(d.vx, t2r / f64::from(DT), 1e-4);
    assert_eq!(d.vy, 0.0);
}

#[test]
fn mecanum_diagonal_while_turning_is_exact_arc() {
    // Constant twist (vx, vy, wz) for one period: the start frame sees the robot at
    // (vx·sin θ + vy·(cos θ − 1), vx·(1 − cos θ) + vy·sin θ) / wz (θ = wz·t). Forward 20 + strafe 20
    // + turn 7 counts-pattern, scaled by 100, in one update and in 100.
    let t2r = PI_64 / 2000.0;
    let (ahead, left, turn) = ([20, 20, 20, 20], [-20, 20, 20, -20], [-7, 7, -7, 7]);
    let mut delta = [0i32; 4];
    for (i, d) in delta.iter_mut().enumerate() {
        *d = ahead[i] + left[i] + turn[i];
    }
    let (dx, dy, th) = (100.0 * t2r, 100.0 * t2r, 100.0 * t2r);
    let want_x = (dx * th.sin() + dy * (th.cos() - 1.0)) / th;
    let want_y = (dx * (1.0 - th.cos()) + dy * th.sin()) / th;
    for n in [1u32, 100] {
        let mut rig = Rig::new(mecanum(t2r), [0; 4]);
        let per = delta.map(|d| d * 100 / n as i32);
        let d = rig.steps(n, per);
        near(d.pos_x, want_x, 1e-6);
        near(d.pos_y, want_y, 1e-6);
        near(d.heading, th, 1e-6);
    }
}

/// A configured rig that has moved, and a copy of it.
fn moved() -> Rig {
    let mut rig = Rig::new(diff_drive(ARC_T2R), [100, 200, 300, 400]);
    rig.steps(300, [17, 23, 17, 23]);
    rig
}

#[test]
fn refused_configs_change_nothing() {
    let good = diff_drive(ARC_T2R);
    let with = |f: &dyn Fn(&mut KinematicsConfig)| {
        let mut k = good;
        f(&mut k);
        k
    };
    let cases: Vec<(KinematicsConfig, KinematicsError)> = std::vec![
        (
            with(&|k| k.inverse[1][2] = f32::NAN),
            KinematicsError::NotFinite
        ),
        (
            with(&|k| k.inverse[2][3] = f32::INFINITY),
            KinematicsError::NotFinite
        ),
        (
            with(&|k| k.ticks_to_rad[3] = f32::NEG_INFINITY),
            KinematicsError::NotFinite
        ),
        (
            with(&|k| k.ticks_to_rad[0] = f32::NAN),
            KinematicsError::NotFinite
        ),
        (
            with(&|k| k.ticks_to_rad[1] = 0.0),
            KinematicsError::TicksToRad
        ),
        (
            with(&|k| k.ticks_to_rad[1] = -0.0),
            KinematicsError::TicksToRad
        ),
        (
            with(&|k| k.ticks_to_rad[2] = 1e-10),
            KinematicsError::TicksToRad
        ),
        (
            with(&|k| k.ticks_to_rad[2] = f32::from_bits(1)),
            KinematicsError::TicksToRad
        ),
        (
            with(&|k| k.ticks_to_rad[3] = -6.3),
            KinematicsError::TicksToRad
        ),
        (
            with(&|k| k.inverse[0][0] = 10.001),
            KinematicsError::InverseEntry
        ),
        (
            with(&|k| k.inverse[1][3] = -10.5),
            KinematicsError::InverseEntry
        ),
        (
            with(&|k| k.inverse[2][1] = 1000.1),
            KinematicsError::InverseEntry
        ),
        (
            with(&|k| k.inverse = [[0.0; 4]; 3]),
            KinematicsError::ZeroMatrix
        ),
        (
            with(&|k| k.inverse = [[-0.0; 4]; 3]),
            KinematicsError::ZeroMatrix
        ),
        (KinematicsConfig::default(), KinematicsError::TicksToRad),
    ];
    for (i, (k, e)) in cases.iter().enumerate() {
        let mut rig = moved();
        let before = rig.o;
        assert_eq!(rig.o.configure(k), Err(*e), "case {i}");
        assert_eq!(rig.o.config(), Some(&good));
        assert_eq!(rig.o.data(), before.data());
        assert_eq!(
            rig.o.counters(),
            OdometryCounters {
                refused_configs: 1,
                ..before.counters()
            }
        );
        // The old geometry and baseline go on as if nothing had come.
        let mut twin = Rig {
            o: before,
            counts: rig.counts,
        };
        assert_eq!(
            rig.steps(10, [17, 23, 17, 23]),
            twin.steps(10, [17, 23, 17, 23])
        );
    }
    // Refused while unconfigured: still unconfigured, still zero.
    let mut o = Odometry::new();
    assert_eq!(o.configure(&cases[0].0), Err(KinematicsError::NotFinite));
    assert!(!o.configured());
    assert_eq!(o.update([1, 2, 3, 4], DT), OdometryData::default());
    assert_eq!(o.update([5, 6, 7, 8], DT), OdometryData::default());
}

#[test]
fn bounds_themselves_are_accepted() {
    let mut o = Odometry::new();
    let edge = KinematicsConfig {
        inverse: [
            [10.0, -10.0, 0.0, 0.0],
            [0.0, 0.0, -10.0, 10.0],
            [1000.0, -1000.0, 0.0, 0.0],
        ],
        ticks_to_rad: [TAU, -TAU, 1e-9, -1e-9],
    };
    assert_eq!(o.configure(&edge), Ok(()));
    // A single nonzero entry (one wheel, yaw only) is a valid, if odd, geometry.
    let mut one = KinematicsConfig {
        ticks_to_rad: [1e-3; 4],
        ..KinematicsConfig::default()
    };
    one.inverse[2][3] = 1e-30;
    assert_eq!(o.configure(&one), Ok(()));
    assert_eq!(o.counters().refused_configs, 0);
}

#[test]
fn reconfigure_keeps_the_pose_and_takes_a_new_baseline() {
    let mut rig = moved();
    let pose = rig.o.data();
    // Twice the encoder resolution.
    rig.o.configure(&diff_drive(ARC_T2R / 2.0)).unwrap();
    let d = rig.o.data();
    assert_eq!(
        (d.pos_x, d.pos_y, d.heading),
        (pose.pos_x, pose.pos_y, pose.heading)
    );
    assert_eq!((d.vx, d.vy, d.wz), (0.0, 0.0, 0.0));
    // Counts jump (say the Pi reconfigured after a pause): no jump in the pose.
    rig.counts = [1 << 30, -(1 << 30), 12, -12];
    let d = rig.o.update(rig.counts, DT);
    assert_eq!(
        (d.pos_x, d.pos_y, d.heading),
        (pose.pos_x, pose.pos_y, pose.heading)
    );
    assert_eq!((d.vx, d.vy, d.wz), (0.0, 0.0, 0.0));
    // Straight ahead under the new scale: 2000 counts of π/4000 rad, r·φ = r·π/2.
    let d = rig.steps(1000, [2; 4]);
    let h = f64::from(pose.heading);
    let run = R * PI_64 / 2.0;
    near(d.pos_x, f64::from(pose.pos_x) + run * h.cos(), 1e-6);
    near(d.pos_y, f64::from(pose.pos_y) + run * h.sin(), 1e-6);
    near(d.heading, h, 1e-7);
}

#[test]
fn odom_reset_zeroes_and_takes_a_new_baseline() {
    let mut rig = moved();
    assert_ne!(rig.o.data(), OdometryData::default());
    rig.o.reset();
    assert_eq!(rig.o.data(), OdometryData::default());
    assert!(rig.o.configured());
    rig.counts = [-5, 1 << 20, 77, i32::MIN];
    assert_eq!(rig.o.update(rig.counts, DT), OdometryData::default());
    // From the origin, heading 0, the same arc as from the start.
    let d = rig.steps(1000, [17, 23, 17, 23]);
    near(d.pos_x, 1.0, 1e-5);
    near(d.pos_y, 1.0, 1e-5);
}

#[test]
fn encoder_wrap_is_no_jump() {
    let delta = [17, 23, -17, 23];
    let mut plain = Rig::new(diff_drive(ARC_T2R), [0; 4]);
    let want = plain.steps(20, delta);
    // Wheels 0, 1, 3 cross i32::MAX → i32::MIN, wheel 2 (backwards) i32::MIN → i32::MAX.
    let start = [i32::MAX - 100, i32::MAX - 5, i32::MIN + 50, i32::MAX];
    let mut wrapping = Rig::new(diff_drive(ARC_T2R), start);
    assert_eq!(wrapping.steps(20, delta), want);
    assert!(wrapping.counts[0] < 0 && wrapping.counts[2] > 0);
}

#[test]
fn bad_periods_are_refused_and_counted() {
    let mut rig = moved();
    let mut reference = Rig {
        o: rig.o,
        counts: rig.counts,
    };
    let bad = [
        0.0,
        -0.0,
        -1e-3,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e-7,
        f32::from_bits(1),
        f32::MIN,
    ];
    for (i, dt) in bad.into_iter().enumerate() {
        let before = rig.o.data();
        rig.counts = rig.counts.map(|c| c.wrapping_add(7));
        assert_eq!(rig.o.update(rig.counts, dt), before, "dt {dt}");
        assert_eq!(rig.o.counters().refused_dt, i as u32 + 1);
    }
    // The motion during the refused periods is integrated by the next accepted one.
    let d = rig.o.update(rig.counts, DT);
    let want = reference.step([7 * bad.len() as i32; 4]);
    assert_eq!(
        (d.pos_x, d.pos_y, d.heading),
        (want.pos_x, want.pos_y, want.heading)
    );
    // Unconfigured, a bad period is counted too.
    let mut o = Odometry::new();
    o.update([0; 4], f32::NAN);
    assert_eq!(o.counters().refused_dt, 1);
    // The shortest accepted period is accepted: the velocity is 10⁶ times the displacement.
    rig.counts = rig.counts.map(|c| c.wrapping_add(1));
    let d = rig.o.update(rig.counts, MIN_DT_S);
    assert_eq!(rig.o.counters().refused_dt, bad.len() as u32);
    near(d.vx, R * ARC_T2R * 1e6, 1e-2);
}

#[test]
fn position_clamp_is_counted() {
    let k = KinematicsConfig {
        inverse: [[10.0; 4], [0.0; 4], [0.0; 4]],
        ticks_to_rad: [TAU; 4],
    };
    let mut rig = Rig::new(k, [0; 4]);
    // 4·10·2³⁰·2π ≈ 2.7·10¹¹ m in one period: a garbage count, clamped at 100 km.
    let d = rig.step([1 << 30; 4]);
    assert_eq!(d.pos_x, MAX_POSITION_M);
    assert!(d.vx.is_finite() && d.vx > 1e13);
    assert_eq!(rig.o.counters().position_clamped, 1);
    let d = rig.step([-(1 << 30); 4]);
    assert_eq!(d.pos_x, -MAX_POSITION_M);
    assert_eq!(rig.o.counters().position_clamped, 2);
    assert_eq!(rig.o.counters().non_finite, 0);
}

#[test]
fn large_rotation_in_one_period_is_reduced_and_counted() {
    let k = KinematicsConfig {
        inverse: [[0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]],
        ticks_to_rad: [1e-3; 4],
    };
    let mut rig = Rig::new(k, [0; 4]);
    // 5000 counts of 1 mrad: 5 rad, i.e. 5 − 2π.
    let d = rig.step([0, 0, 0, 5000]);
    assert!(angle_err(d.heading, 5.0) < 1e-6, "{d:?}");
    near(d.heading, 5.0 - TAU_64, 1e-6);
    assert_eq!(rig.o.counters().large_rotations, 1);
    // Three periods of exactly one radian: none of them is large.
    let d = rig.steps(3, [0, 0, 0, 1000]);
    assert!(angle_err(d.heading, 8.0) < 1e-6, "{d:?}");
    assert_eq!(rig.o.counters().large_rotations, 1);
}

#[test]
fn error_codes_are_stable() {
    assert_eq!(KinematicsError::NotFinite as u8, 1);
    assert_eq!(KinematicsError::TicksToRad as u8, 2);
    assert_eq!(KinematicsError::InverseEntry as u8, 3);
    assert_eq!(KinematicsError::ZeroMatrix as u8, 4);
}

#[test]
fn arc_factors_match_the_closed_form_across_the_series_threshold() {
    for th in [
        1e-6f64, 1e-3, 9.99e-3, 1.001e-2, 0.1, 1.0, 3.0, -0.005, -2.0,
    ] {
        let (a, b) = arc_factors(th as f32);
        let (ea, eb) = exact_arc_factors(th as f32);
        near(a, ea, 1e-7);
        near(b, eb, 1e-7);
    }
    assert_eq!(arc_factors(0.0), (1.0, 0.0));
}

#[test]
fn position_reads_as_the_nearest_f32_to_the_exact_sum() {
    // Wheel 0 moves the robot 1 m per count, wheel 1 2⁻²⁶ m per count (both exact in f32).
    let k = KinematicsConfig {
        inverse: [[1.0, 1.0, 0.0, 0.0], [0.0; 4], [0.0; 4]],
        ticks_to_rad: [1.0, 1.0 / (1u64 << 26) as f32, 1.0, 1.0],
    };
    let mut rig = Rig::new(k, [0; 4]);
    let d = rig.step([1, 0, 0, 0]);
    assert_eq!(d.pos_x, 1.0);
    // 1 + 3·2⁻²⁶ m: the f32 below 1 are 2⁻²⁴ apart, above it 2⁻²³, so the nearest f32 is 1 itself
    // (0.75·2⁻²⁴ away), not 1 − 2⁻²⁴ nor 1 + 2⁻²³.
    let d = rig.step([0, 3, 0, 0]);
    assert_eq!(d.pos_x, 1.0);
    // 1 + 6·2⁻²⁶ = 1 + 0.75·2⁻²³ m: nearest 1 + 2⁻²³ (a plain f32 sum would have stayed at 1).
    let d = rig.step([0, 3, 0, 0]);
    assert_eq!(d.pos_x, 1.0 + f32::EPSILON);
    // Back by 3·2⁻²⁶ and then 3·2⁻²⁶ again: 1 + 3·2⁻²⁶, then exactly 1.
    let d = rig.step([0, -3, 0, 0]);
    assert_eq!(d.pos_x, 1.0);
    let d = rig.step([0, -3, 0, 0]);
    assert_eq!(d.pos_x, 1.0);
    assert_eq!((d.pos_y, d.heading), (0.0, 0.0));
}

#[test]
fn position_exactly_at_the_bound_is_not_clamped() {
    // 10 m per count of wheel 0 (exact): 10 000 counts are exactly MAX_POSITION_M.
    let k = KinematicsConfig {
        inverse: [[10.0, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4]],
        ticks_to_rad: [1.0; 4],
    };
    let mut rig = Rig::new(k, [0; 4]);
    let d = rig.step([10_000, 0, 0, 0]);
    assert_eq!(d.pos_x, MAX_POSITION_M);
    assert_eq!(rig.o.counters().position_clamped, 0);
    let d = rig.step([-20_000, 0, 0, 0]);
    assert_eq!(d.pos_x, -MAX_POSITION_M);
    assert_eq!(rig.o.counters().position_clamped, 0);
    // One count (10 m) beyond it is clamped and counted; one back is 10 m inside.
    let d = rig.step([-1, 0, 0, 0]);
    assert_eq!(d.pos_x, -MAX_POSITION_M);
    assert_eq!(rig.o.counters().position_clamped, 1);
    let d = rig.step([1, 0, 0, 0]);
    assert_eq!(d.pos_x, -MAX_POSITION_M + 10.0);
    assert_eq!(rig.o.counters().position_clamped, 1);
}

#[test]
fn half_turn_lands_on_pi_and_minus_half_turn_just_below_it() {
    // Wheel 3 turns the robot by the f32 `PI` per count (π + 8.7·10⁻⁸ rad).
    let k = KinematicsConfig {
        inverse: [[0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]],
        ticks_to_rad: [1.0, 1.0, 1.0, PI],
    };
    let mut rig = Rig::new(k, [0; 4]);
    // Counter-clockwise: the heading is `PI`, the end of (−π, π] that the output keeps.
    let d = rig.step([0, 0, 0, 1]);
    assert_eq!(d.heading, PI);
    assert_eq!((d.pos_x, d.pos_y), (0.0, 0.0));
    // Clockwise back to 0, then once more: −π − 8.7·10⁻⁸ rad is the angle π − 8.7·10⁻⁸, whose
    // nearest f32 is the one below `PI` (π − 1.5·10⁻⁷; `PI` itself is 1.7·10⁻⁷ away).
    let d = rig.step([0, 0, 0, -1]);
    assert_eq!(d.heading, 0.0);
    let d = rig.step([0, 0, 0, -1]);
    assert_eq!(d.heading, f32::from_bits(PI.to_bits() - 1));
    assert_eq!(rig.o.counters().large_rotations, 0);
}

#[test]
fn data_reports_a_heading_sum_at_minus_pi_or_outside_as_pi() {
    // `update` keeps the heading sum within (−π, π]; `data` still maps any other value (the
    // finiteness argument in `verification` relies on it) to `PI`, the same angle as −π.
    let mut o = Odometry::new();
    o.configure(&diff_drive(ARC_T2R)).unwrap();
    let inside_below_pi = f32::from_bits(PI.to_bits() - 1);
    for (hi, lo, want) in [
        (-PI, 0.0, PI),
        // −π − 8.7·10⁻⁸ + 10⁻⁷ still rounds to −`PI` (the f32 above it is 2.4·10⁻⁷ away).
        (-PI, 1e-7, PI),
        (4.0, 0.0, PI),
        (-4.0, 0.0, PI),
        (-TAU, 0.0, PI),
        (f32::NAN, 0.0, PI),
        (PI, 0.0, PI),
        (-inside_below_pi, 0.0, -inside_below_pi),
        (1.0, 0.0, 1.0),
    ] {
        o.heading = Sum { hi, lo };
        assert_eq!(o.data().heading, want, "heading sum ({hi}, {lo})");
    }
}

/// The f32 on either side of `x` (both the same if `x` is one).
fn f32_neighbours(x: f64) -> (f32, f32) {
    let r = x as f32;
    let r64 = f64::from(r);
    if r64 == x {
        (r, r)
    } else if r64 < x {
        (r, r.next_up())
    } else {
        (r.next_down(), r)
    }
}

/// sin θ / θ and (1 − cos θ) / θ = 2 sin²(θ/2) / θ in f64, θ the f32 angle.
fn exact_arc_factors(th: f32) -> (f64, f64) {
    let t = f64::from(th);
    let half = (t / 2.0).sin();
    (t.sin() / t, 2.0 * half * half / t)
}

#[test]
fn series_arc_factors_are_faithfully_rounded() {
    // The series' truncation is below 3·10⁻¹⁶ relative, so both factors come out as one of the two
    // f32 next to the exact value, over the series' whole range (every 65 536th f32 below the
    // threshold, and the last 4096, where the dropped terms would be largest), on both signs.
    let top = SMALL_ANGLE.to_bits();
    let angles = (1..top).step_by(1 << 16).chain(top - 4096..top);
    // And at 7.4515·10⁻³ rad, where (1 − cos θ)/θ lies 4 % of an ulp below an f32: the next f32
    // up is already more than an ulp away.
    let angles = angles.chain(0x3bf4_2ba6..=0x3bf4_2baf);
    for bits in angles {
        let th = f32::from_bits(bits);
        assert!(th.abs() < SMALL_ANGLE);
        let (ea, eb) = exact_arc_factors(th);
        for (th, eb) in [(th, eb), (-th, -eb)] {
            let (a, b) = arc_factors(th);
            let (a_lo, a_hi) = f32_neighbours(ea);
            let (b_lo, b_hi) = f32_neighbours(eb);
            assert!(
                a == a_lo || a == a_hi,
                "θ = {th:e}: a = {a:e}, exact {ea:e}"
            );
            assert!(
                b == b_lo || b == b_hi,
                "θ = {th:e}: b = {b:e}, exact {eb:e}"
            );
        }
    }
}

#[test]
fn series_arc_factor_a_is_correctly_rounded_near_rounding_midpoints() {
    // a = 1 − θ²/6·(1 − θ²/20): the roundings before the last subtraction are below 10⁻⁴ of an ulp
    // of a, so a is the f32 nearest to sin θ / θ, even at these angles near the threshold, where
    // sin θ / θ lies 0.3 % to 3 % of an ulp from the midpoint between two f32 (the last two: almost
    // exactly on one).
    for bits in [
        0x3c23_cdea_u32,
        0x3c23_82d5,
        0x3c23_379d,
        0x3c23_d01d,
        0x3c23_8505,
        0x3c22_c6bd,
        0x3c20_ff4e,
    ] {
        let th = f32::from_bits(bits);
        let (ea, _) = exact_arc_factors(th);
        let want = ea as f32;
        assert_eq!(arc_factors(th).0, want, "θ = {th:e}, exact {ea:e}");
        assert_eq!(arc_factors(-th).0, want, "θ = {:e}", -th);
    }
}
