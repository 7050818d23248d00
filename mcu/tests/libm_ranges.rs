//! The ranges of `libm`'s `sinf`, `cosf` and `remainderf(·, 2π)` for every one of the 2³² f32
//! arguments: the premise of the Kani stand-ins in `mcu/src/verification.rs` (`libm_models`),
//! which let `verify_odometry_update_finite` prove the odometry update without bit-blasting the
//! functions themselves. Exhaustive, so ignored in the debug test run; `.ci/run` runs them in
//! release: `cargo test --release -p mcu --test libm_ranges -- --ignored`.

#![allow(clippy::expect_used)]

use core::f32::consts::{PI, TAU};

/// Checks `ok(x, f(x))` for every f32 `x`, on two threads; returns the first failing argument.
fn every_f32(f: fn(f32) -> f32, ok: fn(f32, f32) -> bool) -> Option<u32> {
    let halves = [0u32..=0x7FFF_FFFF, 0x8000_0000..=u32::MAX];
    let handles = halves.map(|range| {
        std::thread::spawn(move || {
            range.into_iter().find(|&bits| {
                let x = f32::from_bits(bits);
                !ok(x, f(x))
            })
        })
    });
    handles
        .into_iter()
        .filter_map(|h| h.join().expect("a range thread panicked"))
        .min()
}

/// In [−1, 1] for a finite argument, NaN for ±∞ and NaN: the stand-in's contract.
fn unit_range(x: f32, y: f32) -> bool {
    if x.is_finite() {
        (-1.0..=1.0).contains(&y)
    } else {
        y.is_nan()
    }
}

#[test]
#[ignore = "exhaustive over every f32 (about a minute in release): run by .ci/run with --release --ignored"]
fn sinf_is_within_its_range_for_every_f32() {
    assert_eq!(
        every_f32(libm::sinf, unit_range),
        None,
        "first failing bits"
    );
}

#[test]
#[ignore = "exhaustive over every f32 (about a minute in release): run by .ci/run with --release --ignored"]
fn cosf_is_within_its_range_for_every_f32() {
    assert_eq!(
        every_f32(libm::cosf, unit_range),
        None,
        "first failing bits"
    );
}

#[test]
#[ignore = "exhaustive over every f32 (about a minute in release): run by .ci/run with --release --ignored"]
fn remainderf_by_tau_is_within_pi_for_every_f32() {
    fn by_tau(x: f32) -> f32 {
        libm::remainderf(x, TAU)
    }
    fn within_pi(x: f32, r: f32) -> bool {
        if x.is_finite() {
            (-PI..=PI).contains(&r)
        } else {
            r.is_nan()
        }
    }
    assert_eq!(every_f32(by_tau, within_pi), None, "first failing bits");
}

/// The checker itself: given a range that the smallest subnormal arguments violate (sin x = x
/// there, below 10⁻⁴⁰), it reports the first of them, so the exhaustive tests above can fail.
#[test]
fn the_range_check_finds_a_violation() {
    fn no_subnormal_results(x: f32, y: f32) -> bool {
        !x.is_finite() || y == 0.0 || y.abs() > 1e-40
    }
    assert_eq!(every_f32(libm::sinf, no_subnormal_results), Some(1));
}
