//! Expected values from the geometry of each case, not from the filter: a level board measures
//! +1 g on z, a board turned +90° about x measures +1 g on y, a turn at r °/s for t s moves the
//! heading by r·t.

use super::*;

const HZ: u32 = 100;
/// +1 g in accelerometer counts.
const ONE_G: i16 = 16_384;
/// 10 °/s in gyro counts (131 counts per °/s).
const TEN_DPS: i16 = 1310;
/// 25 °C: (25 − 36.53) · 340.
const TEMP_25C: i16 = -3920;

const LEVEL: [i16; 3] = [0, 0, ONE_G];

/// Feeds `n` identical readings; returns the last output.
fn run(f: &mut ImuFusion, n: u32, accel: [i16; 3], gyro: [i16; 3]) -> ImuData {
    let mut out = ImuData::default();
    for _ in 0..n {
        out = f.update(accel, gyro, TEMP_25C);
    }
    out
}

/// A fusion past its start-up second, level and still.
fn started() -> ImuFusion {
    let mut f = ImuFusion::new(HZ);
    run(&mut f, HZ, LEVEL, [0; 3]);
    assert!(f.bias_ready());
    f
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

/// Gravity's direction in the board frame as the filter sees it: R(q)ᵀ · (0, 0, 1).
fn up_in_board(q: &QuaternionData) -> [f32; 3] {
    let (w, x, y, z) = (q.w, q.x, q.y, q.z);
    [
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        w * w - x * x - y * y + z * z,
    ]
}

fn accuracies(d: &ImuData) -> [i8; 5] {
    [
        d.gyro.accuracy,
        d.accel.accuracy,
        d.compass.accuracy,
        d.linear_accel.accuracy,
        d.accel_velocity.accuracy,
    ]
}

#[test]
fn at_rest_level_converges_to_identity_and_no_linear_accel() {
    let mut f = ImuFusion::new(HZ);
    let d = run(&mut f, 5 * HZ, LEVEL, [0; 3]);
    let q = d.dmp_quat;
    assert!(close(q.w, 1.0, 1e-3), "{q:?}");
    assert!(
        q.x.abs() < 0.01 && q.y.abs() < 0.01 && q.z.abs() < 0.01,
        "{q:?}"
    );
    for v in [d.linear_accel.x, d.linear_accel.y, d.linear_accel.z] {
        assert!(v.abs() < 0.05, "linear accel {:?}", d.linear_accel);
    }
    assert!(close(d.accel.z, G, 0.01), "{:?}", d.accel);
    assert!(
        d.heading < 0.5 || d.heading > 359.5,
        "heading {}",
        d.heading
    );
    assert_eq!(accuracies(&d), [3, 3, 0, 3, 0]);
    assert!(close(d.temperature, 25.0, 0.01), "{}", d.temperature);
    assert_eq!(f.counters().readings, 5 * HZ);
    assert_eq!(f.counters().accel_rejected, 0);
}

#[test]
fn gyro_accuracy_is_zero_until_the_bias_is_known() {
    let mut f = ImuFusion::new(HZ);
    let bias = [50, -30, 20];
    for k in 1..HZ {
        let d = f.update(LEVEL, bias, TEMP_25C);
        assert_eq!(d.gyro.accuracy, 0, "reading {k}");
        assert_eq!(d.linear_accel.accuracy, 0, "reading {k}");
    }
    let d = f.update(LEVEL, bias, TEMP_25C);
    assert!(f.bias_ready());
    assert_eq!(d.gyro.accuracy, 3);
    // The bias is removed: the still board reads no rotation and keeps its heading.
    let d = run(&mut f, 10 * HZ, LEVEL, bias);
    for v in [d.gyro.x, d.gyro.y, d.gyro.z] {
        assert!(v.abs() < 1e-4, "{:?}", d.gyro);
    }
    assert!(
        d.heading < 0.5 || d.heading > 359.5,
        "heading {}",
        d.heading
    );
}

#[test]
fn movement_restarts_the_bias_window() {
    let mut f = ImuFusion::new(HZ);
    run(&mut f, HZ / 2, LEVEL, [0; 3]);
    // A turn at 10 °/s: not still.
    run(&mut f, 10, LEVEL, [0, 0, TEN_DPS]);
    assert!(!f.bias_ready());
    assert!(f.counters().bias_restarts >= 1);
    run(&mut f, HZ - 1, LEVEL, [0; 3]);
    assert!(
        !f.bias_ready(),
        "the window counts only the still readings since the turn"
    );
    run(&mut f, 1, LEVEL, [0; 3]);
    assert!(f.bias_ready());
}

#[test]
fn constant_rate_about_z_moves_heading_clockwise_from_north() {
    // +10 °/s about z (z up): counter-clockwise seen from above, so the clockwise heading falls:
    // 4 s → −40°, i.e. 320°.
    let mut f = started();
    let d = run(&mut f, 4 * HZ, LEVEL, [0, 0, TEN_DPS]);
    assert!(close(d.heading, 320.0, 0.5), "heading {}", d.heading);
    let rate = 10.0f32.to_radians();
    assert!(close(d.gyro.z, rate, 1e-3), "{:?}", d.gyro);
    assert_eq!(d.gyro.accuracy, 3);
    // And back the other way for 8 s: −40° + 80° = 40°.
    let d = run(&mut f, 8 * HZ, LEVEL, [0, 0, -TEN_DPS]);
    assert!(close(d.heading, 40.0, 0.5), "heading {}", d.heading);
}

#[test]
fn tilt_of_90_deg_about_x_is_found_from_gravity_alone() {
    // Board turned +90° about x: its y axis points up, so the accelerometer reads +1 g on y.
    // Expected attitude: q = (cos 45°, sin 45°, 0, 0). No gyro reading says so.
    let tilted = [0, ONE_G, 0];
    let h = core::f32::consts::FRAC_1_SQRT_2;
    // From power-on, within the start-up second and a little more.
    let mut f = ImuFusion::new(HZ);
    let d = run(&mut f, 2 * HZ, tilted, [0; 3]);
    let q = d.dmp_quat;
    assert!(close(q.w, h, 0.02) && close(q.x, h, 0.02), "{q:?}");
    assert!(q.y.abs() < 0.02 && q.z.abs() < 0.02, "{q:?}");
    assert_eq!(d.linear_accel.accuracy, 3);
    // After start-up, level, then tipped over with no gyro reading: found with the slow gain.
    let mut f = started();
    let d = run(&mut f, 1, tilted, [0; 3]);
    assert_eq!(d.linear_accel.accuracy, 1, "gravity 90° off the estimate");
    let d = run(&mut f, 30 * HZ, tilted, [0; 3]);
    let up = up_in_board(&d.dmp_quat);
    assert!(close(up[0], 0.0, 0.01) && close(up[1], 1.0, 0.01) && close(up[2], 0.0, 0.01));
    let q = d.dmp_quat;
    assert!(close(q.w, h, 0.01) && close(q.x, h, 0.01), "{q:?}");
    for v in [d.linear_accel.x, d.linear_accel.y, d.linear_accel.z] {
        assert!(v.abs() < 0.1, "{:?}", d.linear_accel);
    }
    assert_eq!(d.linear_accel.accuracy, 3);
}

/// M · Mᵀ = I and det M = +1, computed here independently of `check_rotation`.
fn is_proper_rotation(m: [i8; 9]) -> bool {
    let e = |r: usize, c: usize| i32::from(m[3 * r + c]);
    for r in 0..3 {
        for s in 0..3 {
            let dot: i32 = (0..3).map(|c| e(r, c) * e(s, c)).sum();
            if dot != i32::from(r == s) {
                return false;
            }
        }
    }
    let det = e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
        - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
        + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0));
    det == 1
}

#[test]
fn orientation_accepts_exactly_the_24_rotations() {
    let mut accepted = 0;
    for code in 0..3u32.pow(9) {
        let mut m = [0i8; 9];
        let mut c = code;
        for v in &mut m {
            *v = (c % 3) as i8 - 1;
            c /= 3;
        }
        let mut f = ImuFusion::new(HZ);
        let ok = f.set_orientation(m, IDENTITY).is_ok();
        assert_eq!(ok, is_proper_rotation(m), "{m:?}");
        assert_eq!(f.set_orientation(IDENTITY, m).is_ok(), ok, "compass {m:?}");
        accepted += u32::from(ok);
    }
    assert_eq!(accepted, 24);
}

#[test]
fn orientation_refuses_a_reflection_a_zero_row_and_a_2() {
    let mut f = started();
    let swap_xy = [0, 1, 0, -1, 0, 0, 0, 0, 1];
    f.set_orientation(swap_xy, IDENTITY).unwrap();
    let before = f.clone();
    let reflection = [1, 0, 0, 0, 1, 0, 0, 0, -1];
    let zero_row = [1, 0, 0, 0, 0, 0, 0, 0, 1];
    let two = [2, 0, 0, 0, 1, 0, 0, 0, 1];
    assert_eq!(
        f.set_orientation(reflection, IDENTITY),
        Err(OrientationError::GyroReflection)
    );
    assert_eq!(
        f.set_orientation(zero_row, IDENTITY),
        Err(OrientationError::GyroNotPermutation)
    );
    assert_eq!(
        f.set_orientation(two, IDENTITY),
        Err(OrientationError::GyroEntry)
    );
    assert_eq!(
        f.set_orientation(IDENTITY, reflection),
        Err(OrientationError::CompassReflection)
    );
    assert_eq!(
        f.set_orientation(IDENTITY, zero_row),
        Err(OrientationError::CompassNotPermutation)
    );
    assert_eq!(
        f.set_orientation(IDENTITY, two),
        Err(OrientationError::CompassEntry)
    );
    assert_eq!(f.counters().orientation_refused, 6);
    assert_eq!(f.orientation(), (swap_xy, IDENTITY));
    assert_eq!(f.filter.quat, before.filter.quat);
}

#[test]
fn orientation_maps_sensor_axes_and_keeps_the_world_frame() {
    // The sensor is mounted turned: its x axis points up. Board z = sensor x.
    let sensor_x_up = [0, 0, -1, 0, 1, 0, 1, 0, 0];
    assert!(is_proper_rotation(sensor_x_up));
    let mut f = ImuFusion::new(HZ);
    f.set_orientation(sensor_x_up, IDENTITY).unwrap();
    let d = run(&mut f, 3 * HZ, [ONE_G, 0, 0], [0; 3]);
    let q = d.dmp_quat;
    assert!(close(q.w, 1.0, 1e-3), "the board is level: {q:?}");
    // A turn of the sensor about its x axis is a turn of the board about z.
    let d = run(&mut f, 2 * HZ, [ONE_G, 0, 0], [TEN_DPS, 0, 0]);
    assert!(close(d.heading, 340.0, 0.5), "heading {}", d.heading);

    // At rest, a new orientation: world vectors go on unchanged, the heading jumps with the axes.
    let mut f = started();
    run(&mut f, HZ, LEVEL, [0; 3]);
    let before = f.update(LEVEL, [0; 3], TEMP_25C);
    // Board x = sensor y, board y = −sensor x: a quarter turn about z.
    f.set_orientation([0, 1, 0, -1, 0, 0, 0, 0, 1], IDENTITY)
        .unwrap();
    let after = f.update(LEVEL, [0; 3], TEMP_25C);
    assert!(close(after.accel.z, before.accel.z, 0.01));
    assert!(after.linear_accel.x.abs() < 0.05 && after.linear_accel.y.abs() < 0.05);
    assert_eq!(after.linear_accel.accuracy, 3);
    let turned = (after.heading - before.heading).rem_euclid(360.0);
    // The new board x is the old board y: a quarter turn counter-clockwise, so the clockwise
    // heading falls by 90°.
    assert!(
        close(turned, 270.0, 0.5),
        "heading {} → {}",
        before.heading,
        after.heading
    );
    // Sensor y is board x: a sensor +x reading now reads as board −y. Turning the sensor +10 °/s
    // about its z (= board z) still turns the board counter-clockwise.
    let d = run(&mut f, 2 * HZ, LEVEL, [0, 0, TEN_DPS]);
    let moved = (after.heading - d.heading).rem_euclid(360.0);
    assert!(close(moved, 20.0, 0.5), "moved {moved}");
}

#[test]
fn sensor_lost_has_accuracy_zero_everywhere() {
    let mut f = started();
    let d = run(&mut f, 2 * HZ, LEVEL, [0, 0, TEN_DPS]);
    let lost = f.sensor_lost();
    assert_eq!(accuracies(&lost), [0; 5]);
    assert_eq!(lost.gyro, SensorData::default());
    assert_eq!(lost.accel, SensorData::default());
    assert_eq!(lost.linear_accel, SensorData::default());
    assert_eq!(lost.dmp_quat, d.dmp_quat);
    assert_eq!(lost.heading, d.heading);
    assert_eq!(lost.temperature, d.temperature);
    assert_eq!(f.counters().lost, 1);
    assert_eq!(f.attitude_level(), 0);
    // Lost before any reading: identity, zeros.
    let lost = ImuFusion::new(HZ).sensor_lost();
    assert_eq!(accuracies(&lost), [0; 5]);
    assert_eq!(lost.dmp_quat.w, 1.0);
    // The next quasi-static reading judges the attitude again.
    let d = f.update(LEVEL, [0, 0, 0], TEMP_25C);
    assert_eq!(d.linear_accel.accuracy, 3);
}

#[test]
fn saturation_lowers_accuracy_and_is_counted() {
    let mut f = started();
    let d = f.update([i16::MAX, 0, ONE_G], [0; 3], TEMP_25C);
    assert_eq!(d.accel.accuracy, 1);
    assert_eq!(d.linear_accel.accuracy, 1);
    assert_eq!(d.gyro.accuracy, 3);
    // About z: the clipped rate turns the heading only, so the attitude stays judged settled.
    let d = f.update(LEVEL, [0, 0, i16::MIN], TEMP_25C);
    assert_eq!(d.gyro.accuracy, 1);
    assert_eq!(d.accel.accuracy, 3);
    let c = f.counters();
    assert_eq!((c.accel_saturated, c.gyro_saturated), (1, 1));
    assert_eq!(
        c.accel_rejected, 1,
        "a saturated acceleration is not gravity"
    );
}

#[test]
fn temperature_follows_the_datasheet_formula() {
    let mut f = ImuFusion::new(HZ);
    for (raw, c) in [
        (0, 36.53),
        (340, 37.53),
        (-12_410, 0.03),
        (i16::MIN, -59.846_47),
    ] {
        let d = f.update(LEVEL, [0; 3], raw);
        assert!(close(d.temperature, c, 1e-3), "{raw}: {}", d.temperature);
    }
}

#[test]
fn no_non_finite_field_for_random_raw_inputs() {
    // xorshift64*: many random readings, half of them from the extremes.
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        s.wrapping_mul(0x2545_F491_4F6C_DD1D)
    };
    for hz in [0, 1, 100, 1000, u32::MAX] {
        let mut f = ImuFusion::new(hz);
        for _ in 0..20_000 {
            let mut v = [0i16; 7];
            for x in &mut v {
                let r = next();
                *x = match r % 4 {
                    0 => [i16::MIN, i16::MAX, 0, -1, 1][(r >> 8) as usize % 5],
                    _ => (r >> 16) as i16,
                };
            }
            let d = if next() % 50 == 0 {
                f.sensor_lost()
            } else {
                f.update([v[0], v[1], v[2]], [v[3], v[4], v[5]], v[6])
            };
            super::verification::check_output(&d);
        }
    }
}

/// The cosine the attitude judgement compares with its thresholds, for a reading of the sensor in
/// its power-on orientation: the filter's gravity against the measured one.
fn judged_cos(f: &ImuFusion, accel: [i16; 3]) -> f32 {
    let measured = ops::rotate(IDENTITY, &Vector3::from(accel.map(f32::from)), MS2_PER_LSB);
    let expected = f.filter.quat.inverse_transform_vector(&Vector3::z());
    expected.dot(&measured) / measured.norm()
}

#[test]
fn attitude_level_follows_the_angle_between_measured_and_estimated_gravity() {
    // Level and settled; then one reading of 1 g tilted θ about x: (0, sin θ, cos θ) g. The step
    // turns the estimate at most 2·β·dt = 0.001 rad (0.06°) towards it, so it stays ≈ θ off.
    for (deg, accel, level) in [
        (1, [0, 286, 16_382], 3),
        (5, [0, 1428, 16_322], 2),
        (15, [0, 4240, 15_826], 1),
        (90, [0, ONE_G, 0], 1),
        (180, [0, 0, -ONE_G], 1),
    ] {
        let mut f = started();
        assert_eq!(f.attitude_level(), 3, "level and still");
        let d = f.update(accel, [0; 3], TEMP_25C);
        assert_eq!(f.attitude_level(), level, "{deg}° off");
        assert_eq!(d.gyro.accuracy, level, "{deg}° off");
        assert_eq!(d.accel.accuracy, level, "{deg}° off");
        assert_eq!(d.linear_accel.accuracy, level, "{deg}° off");
    }
}

#[test]
fn attitude_level_exactly_at_a_threshold_is_the_lower_one() {
    // "< 2° off" is level 3, "2° … 10°" level 2, "≥ 10°" level 1: a reading whose cosine with the
    // estimate is exactly the threshold's is level 2 at 2° and level 1 at 10°. Each reading (about
    // 2.06° and 10.06° tilted about x, the step taking 0.06° off) lands there to the last bit.
    for (accel, threshold, level) in [
        ([0, 586, 16_311], COS_2_DEG, 2),
        ([0, 2903, 16_368], COS_10_DEG, 1),
    ] {
        let mut f = started();
        f.update(accel, [0; 3], TEMP_25C);
        assert_eq!(
            judged_cos(&f, accel),
            threshold,
            "{accel:?} is not on the threshold"
        );
        assert_eq!(f.attitude_level(), level, "{accel:?}");
    }
}

#[test]
fn acceleration_that_cannot_be_gravity_steps_the_filter_on_the_gyro_alone() {
    // 0.3 g along x and 1.8 g along y, neither saturated: outside 0.5 g … 1.5 g. With no rotation
    // measured the estimate stays level, and the level judged before stays (not quasi-static).
    let mut f = started();
    run(&mut f, HZ, [4915, 0, 0], [0; 3]);
    let d = run(&mut f, HZ, [0, 29_491, 0], [0; 3]);
    assert_eq!(f.counters().accel_rejected, 2 * HZ);
    let q = d.dmp_quat;
    assert!(close(q.w, 1.0, 1e-6), "{q:?}");
    assert_eq!(f.attitude_level(), 3);
    assert_eq!(d.linear_accel.accuracy, 3);
}

#[test]
fn a_usable_reading_that_is_not_quasi_static_leaves_the_level_as_judged() {
    // 1.2 g along y: within 0.5 g … 1.5 g, so the filter steps with it, but outside 1 g ± 10 %,
    // so the level is not judged on it although it is 90° off the level estimate.
    let mut f = started();
    let d = f.update([0, 19_661, 0], [0; 3], TEMP_25C);
    assert_eq!(f.counters().accel_rejected, 0);
    assert_eq!(f.attitude_level(), 3);
    assert_eq!(d.linear_accel.accuracy, 3);
    // The same direction at 1 g is judged.
    f.update([0, ONE_G, 0], [0; 3], TEMP_25C);
    assert_eq!(f.attitude_level(), 1);
}

#[test]
fn start_up_bias_is_accepted_up_to_30_dps_per_axis_and_refused_beyond() {
    // 30 °/s is 30 × 131 = 3930 counts. A constant rate over the whole window is taken as the bias.
    for gyro in [[3930, -3930, 0], [0, 0, -3930], [3930, 3930, 3930]] {
        let mut f = ImuFusion::new(HZ);
        run(&mut f, HZ, LEVEL, gyro);
        assert!(f.bias_ready(), "{gyro:?}");
        assert_eq!(f.counters().bias_restarts, 0, "{gyro:?}");
        // That rate now reads as no rotation.
        let d = f.update(LEVEL, gyro, TEMP_25C);
        for v in [d.gyro.x, d.gyro.y, d.gyro.z] {
            assert!(v.abs() < 1e-4, "{gyro:?}: {:?}", d.gyro);
        }
    }
    // One count more, on any axis and either side, or far more: not believed, the window restarts.
    for gyro in [
        [3931, 0, 0],
        [0, -3931, 0],
        [0, 0, 3931],
        [-3931, 3930, 0],
        [0, 0, 20_000],
    ] {
        let mut f = ImuFusion::new(HZ);
        run(&mut f, HZ, LEVEL, gyro);
        assert!(!f.bias_ready(), "{gyro:?}");
        assert_eq!(f.counters().bias_restarts, 1, "{gyro:?}");
        let d = f.update(LEVEL, gyro, TEMP_25C);
        assert_eq!(d.gyro.accuracy, 0, "{gyro:?}");
    }
}

#[test]
fn start_up_takes_1_g_along_any_axis_as_still() {
    // The magnitude counts, not the direction: each axis up or down, and (1, 1, 1)/√3 g.
    for accel in [
        [ONE_G, 0, 0],
        [-ONE_G, 0, 0],
        [0, ONE_G, 0],
        [0, -ONE_G, 0],
        [0, 0, ONE_G],
        [0, 0, -ONE_G],
        [9459, 9459, 9459],
    ] {
        let mut f = ImuFusion::new(HZ);
        run(&mut f, HZ - 1, accel, [0; 3]);
        assert!(!f.bias_ready(), "{accel:?}");
        run(&mut f, 1, accel, [0; 3]);
        assert!(f.bias_ready(), "{accel:?}");
        assert_eq!(f.counters().bias_restarts, 0, "{accel:?}");
    }
}

/// The five vectors of an `ImuData`, in field order.
fn vectors(d: &mut ImuData) -> [&mut SensorData; 5] {
    [
        &mut d.gyro,
        &mut d.accel,
        &mut d.compass,
        &mut d.linear_accel,
        &mut d.accel_velocity,
    ]
}

#[test]
fn a_non_finite_field_goes_as_zeros_or_the_last_value_and_is_counted() {
    // From finite readings the update computes nothing non-finite, so the last check before an
    // `ImuData` leaves is given here one spoilt component at a time.
    let mut f = started();
    let good = f.update(LEVEL, [0, 0, TEN_DPS], TEMP_25C);
    let mut counted = f.counters().non_finite;
    assert_eq!(f.guard(good), good);
    assert_eq!(f.counters().non_finite, counted, "nothing to replace");
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        // A vector: zeros, accuracy 0.
        for v in 0..5 {
            for c in 0..3 {
                let mut d = good;
                let s = vectors(&mut d).into_iter().nth(v).unwrap();
                match c {
                    0 => s.x = bad,
                    1 => s.y = bad,
                    _ => s.z = bad,
                }
                let mut want = good;
                *vectors(&mut want).into_iter().nth(v).unwrap() = SensorData::default();
                assert_eq!(f.guard(d), want, "vector {v}, component {c}: {bad}");
                counted += 1;
                assert_eq!(f.counters().non_finite, counted);
            }
        }
        // The quaternion: the last one sent.
        for c in 0..4 {
            let mut d = good;
            let q = &mut d.dmp_quat;
            match c {
                0 => q.w = bad,
                1 => q.x = bad,
                2 => q.y = bad,
                _ => q.z = bad,
            }
            assert_eq!(f.guard(d), good, "quaternion component {c}: {bad}");
            counted += 1;
            assert_eq!(f.counters().non_finite, counted);
        }
        // The heading and the temperature: 0.
        let (mut d, mut want) = (good, good);
        d.heading = bad;
        want.heading = 0.0;
        assert_eq!(f.guard(d), want, "heading: {bad}");
        let (mut d, mut want) = (good, good);
        d.temperature = bad;
        want.temperature = 0.0;
        assert_eq!(f.guard(d), want, "temperature: {bad}");
        counted += 2;
        assert_eq!(f.counters().non_finite, counted);
    }
}

#[test]
fn a_quaternion_is_finite_only_if_each_coordinate_is() {
    assert!(finite_quat(&UnitQuaternion::identity()));
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for c in 0..4 {
            let mut wxyz = [0.5f32; 4];
            wxyz[c] = bad;
            let [w, x, y, z] = wxyz;
            let q = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, x, y, z));
            assert!(!finite_quat(&q), "component {c}: {bad}");
        }
    }
}

#[test]
fn a_half_turn_goes_with_w_plus_zero() {
    // Sensor mounted turned half about z: board x = −sensor x, board y = −sensor y. The world frame
    // stays, so the board's x axis now points against the power-on one: heading 180°, and the
    // filter holds a half turn about z, whose w is 0. w ≥ 0 down to its sign bit: that quaternion
    // is not negated into one with w = −0.
    let mut f = started();
    f.set_orientation([-1, 0, 0, 0, -1, 0, 0, 0, 1], IDENTITY)
        .unwrap();
    let d = f.update(LEVEL, [0; 3], TEMP_25C);
    let q = d.dmp_quat;
    assert!(q.w == 0.0 && q.w.is_sign_positive(), "{q:?}");
    assert!(close(q.z.abs(), 1.0, 1e-6), "{q:?}");
    assert!(close(d.heading, 180.0, 1e-3), "heading {}", d.heading);
}

#[test]
fn heading_of_a_tilted_board_is_that_of_its_x_axis_seen_from_above() {
    // Rolled +90° about x: the x axis stays along the power-on one. Pitched 30° about y (gravity
    // on the board (−sin 30°, 0, cos 30°)): the x axis points down along the power-on one. Both
    // have heading 0; the tilt is found from gravity, q = (cos 45°, sin 45°, 0, 0) and
    // (cos 15°, 0, sin 15°, 0).
    let s15 = 15.0f32.to_radians().sin();
    let h = core::f32::consts::FRAC_1_SQRT_2;
    for (accel, [x, y]) in [([0, ONE_G, 0], [h, 0.0]), ([-8192, 0, 14_189], [0.0, s15])] {
        let mut f = ImuFusion::new(HZ);
        let d = run(&mut f, 2 * HZ, accel, [0; 3]);
        let q = d.dmp_quat;
        assert!(
            close(q.x, x, 0.02) && close(q.y, y, 0.02),
            "{accel:?}: {q:?}"
        );
        assert!(
            d.heading < 0.5 || d.heading > 359.5,
            "{accel:?}: heading {}",
            d.heading
        );
    }
}

#[test]
fn heading_at_the_power_on_heading_is_plus_zero() {
    // [0, 360) down to the sign bit: the still board at its power-on heading sends +0, not −0.
    let mut f = started();
    let d = f.update(LEVEL, [0; 3], TEMP_25C);
    assert!(
        d.heading == 0.0 && d.heading.is_sign_positive(),
        "heading {:?}",
        d.heading
    );
}
