//! Harnesses of the IMU fusion, each one body for the `cargo test` twin and (where CBMC can
//! finish) a Kani proof.
//!
//! - `orientation_check_is_the_definition`: [`check_rotation`] accepts a matrix exactly when it is
//!   orthogonal with determinant +1 (computed here from the definition). Integer-only: a proof.
//! - `update_output_finite_and_bounded`: for any raw readings, sample rate, orientation and lost
//!   periods, every `ImuData` field is finite, every accuracy is in 0..=3, the heading is in
//!   [0, 360) and the quaternion has unit norm. Twin only: a Madgwick step is some hundred float
//!   operations with `sqrt` and `atan2` from `libm`, which CBMC bit-blasts; a handful of steps
//!   would not finish on this machine, and one step from a symbolic quaternion would prove little.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::*;
use statemachine::harness::Source;
use statemachine::{assume, check, cover};

fn i8x9(src: &mut impl Source) -> [i8; 9] {
    let mut out = [0i8; 9];
    if src.bool() {
        // A signed permutation (half of them reflections): the matrices near the boundary.
        const PERMS: [[usize; 3]; 6] = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let perm = PERMS
            .get(usize::from(src.below(6)))
            .copied()
            .unwrap_or([0, 1, 2]);
        for (r, c) in perm.into_iter().enumerate() {
            if let Some(v) = out.get_mut(r.saturating_mul(3).saturating_add(c)) {
                *v = if src.bool() { 1 } else { -1 };
            }
        }
        return out;
    }
    for v in out.iter_mut() {
        // Mostly −1, 0, +1, sometimes any byte.
        *v = if src.bool() {
            (src.below(3) as i8).wrapping_sub(1)
        } else {
            src.u8() as i8
        };
    }
    out
}

fn i16x3(src: &mut impl Source) -> [i16; 3] {
    [src.u16() as i16, src.u16() as i16, src.u16() as i16]
}

/// Row `r`, column `c` as i32 (entries of any i8: products stay far from overflow).
fn at(m: &[i8; 9], r: usize, c: usize) -> i32 {
    // Indexed (r, c < 3 at every call, so 3·r + c < 9, which the harness proves): `get` on a
    // slice is a pointer offset to Kani.
    #[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
    i32::from(m[3 * r + c])
}

/// P-18: Orientation check: accepted ⇔ M · Mᵀ = I and det M = +1.
pub fn orientation_check_is_the_definition(src: &mut impl Source) {
    let m = i8x9(src);
    let mut orthogonal = true;
    for r in 0..3 {
        for s in 0..3 {
            let dot = (0..3).fold(0i32, |acc, c| {
                acc.saturating_add(at(&m, r, c).saturating_mul(at(&m, s, c)))
            });
            orthogonal &= dot == i32::from(r == s);
        }
    }
    let minor = |r1: usize, c1: usize, r2: usize, c2: usize| {
        at(&m, r1, c1)
            .saturating_mul(at(&m, r2, c2))
            .saturating_sub(at(&m, r1, c2).saturating_mul(at(&m, r2, c1)))
    };
    let det = at(&m, 0, 0)
        .saturating_mul(minor(1, 1, 2, 2))
        .saturating_sub(at(&m, 0, 1).saturating_mul(minor(1, 0, 2, 2)))
        .saturating_add(at(&m, 0, 2).saturating_mul(minor(1, 0, 2, 1)));
    let rotation = orthogonal && det == 1;
    let result = check_rotation(m);
    check!(
        result.is_ok() == rotation,
        "P-18: accepted exactly the proper rotations"
    );
    if orthogonal && det == -1 {
        check!(
            result == Err(MatrixDefect::Reflection),
            "P-18: a reflection is named as one"
        );
    }
    cover!(src, rotation, "a rotation accepted");
    cover!(src, orthogonal && det == -1, "a reflection refused");
}

/// P-23: Every field of an output is finite, accuracies are 0..=3, the heading in [0, 360), the
/// quaternion of unit norm.
pub(super) fn check_output(d: &ImuData) {
    for s in [
        &d.gyro,
        &d.accel,
        &d.compass,
        &d.linear_accel,
        &d.accel_velocity,
    ] {
        check!(
            s.x.is_finite() && s.y.is_finite() && s.z.is_finite(),
            "P-23: every vector finite"
        );
        check!((0..=3).contains(&s.accuracy), "P-23: accuracy within 0..=3");
    }
    check!(
        d.compass.accuracy == 0 && d.accel_velocity.accuracy == 0,
        "P-23: no magnetometer, no velocity: accuracy 0"
    );
    let q = d.dmp_quat;
    let n = q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z;
    check!(
        n.is_finite() && (n - 1.0).abs() < 1e-3,
        "P-23: unit quaternion"
    );
    check!(q.w >= 0.0, "P-23: quaternion sent with w ≥ 0");
    check!(
        d.heading.is_finite() && (0.0..360.0).contains(&d.heading),
        "P-23: heading within [0, 360)"
    );
    check!(d.temperature.is_finite(), "P-23: temperature finite");
}

/// P-23: The fusion's outputs stay finite and within their ranges (`check_output`) for any sample
/// rate, orientation and raw readings, with lost periods among them (a lost reading has accuracy 0).
pub fn update_output_finite_and_bounded(src: &mut impl Source) {
    // Small rates reach the end of the start-up window within the few readings of a case.
    let hz = if src.bool() {
        u32::from(src.below(4))
    } else {
        src.u32()
    };
    let mut f = ImuFusion::new(hz);
    let orientation = f.set_orientation(i8x9(src), i8x9(src)).is_ok();
    let steps = src.below(8).saturating_add(1);
    let mut lost = false;
    let mut saturated = false;
    for _ in 0..steps {
        let d = if src.below(8) == 0 {
            lost = true;
            let d = f.sensor_lost();
            check!(
                d.gyro.accuracy == 0 && d.accel.accuracy == 0 && d.linear_accel.accuracy == 0,
                "P-23: a lost reading has accuracy 0"
            );
            d
        } else {
            // Often a still, level board, so the start-up window closes.
            let (accel, gyro) = if src.bool() {
                ([0, 0, 16_384], [0, 0, 0])
            } else {
                (i16x3(src), i16x3(src))
            };
            saturated |= accel.contains(&i16::MAX) || accel.contains(&i16::MIN);
            f.update(accel, gyro, src.u16() as i16)
        };
        check_output(&d);
    }
    assume!(src, f.counters().readings > 0);
    cover!(src, orientation, "an orientation accepted");
    cover!(src, f.bias_ready(), "bias estimated");
    cover!(src, lost, "sensor lost");
    cover!(src, saturated, "accelerometer saturated");
}

#[cfg(kani)]
mod proofs {
    use statemachine::harness::KaniSource;

    // MiniSat (CBMC's default) rather than CaDiCaL: 3.0 s against 14.2 s on one build, 4.2 s
    // against 12.6 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(10)]
    #[kani::solver(minisat)]
    fn verify_orientation_check_is_the_definition() {
        super::orientation_check_is_the_definition(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use statemachine::harness::Twin;

    #[test]
    fn orientation_check_is_the_definition() {
        Twin::run(0x1A_01, 200_000, super::orientation_check_is_the_definition).assert_covered(2);
    }

    #[test]
    fn update_output_finite_and_bounded() {
        Twin::run(0x1A_02, 20_000, super::update_output_finite_and_bounded).assert_covered(4);
    }
}
