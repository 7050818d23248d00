//! The ranges of `libm`'s `sinf`, `cosf` and `remainderf(·, 2π)` for every one of the 2³² f32
//! arguments: the premise of the Kani stand-in for `sinf` in `mcu/src/verification.rs`
//! (`libm_models`), which lets `verify_arc_factors_bounded` prove the arc factors without
//! bit-blasting the function, and of the odometry update's decomposition (`proofs/REPORT.md`, "P-19
//! by decomposition"), which takes the ranges of `cosf` and `remainderf` from here. Exhaustive, so ignored in the test run: `cargo test --profile ranges -p mcu
//! --test libm_ranges -- --ignored` runs them (5 min 46 s on 2 cores, 11 min of CPU time).
//!
//! What they check is a property of `libm`'s source alone, and `Cargo.lock` pins that source by its
//! registry checksum. [`CHECKED_LIBM`] names the source they last passed on, and the plain test
//! [`libm_is_the_one_the_ranges_were_checked_for`] fails as soon as the lock file names another:
//! then the three checks are run on the new one and [`CHECKED_LIBM`] updated. So `cargo test` (and
//! `.ci/run`) keeps the premise without repeating 11 min of CPU time on every run.

#![allow(clippy::expect_used)]

use core::f32::consts::{PI, TAU};

/// The `libm` the exhaustive checks below last passed on (`cargo test --profile ranges -p mcu --test
/// libm_ranges -- --ignored`, 1 December 2026): its version and the checksum `Cargo.lock` records
/// for its source.
const CHECKED_LIBM: (&str, &str) = (
    "0.2.16",
    "b6d2cec3eae94f9f509c767b45932f1ada8350c4bdb85af2fcab4a3c14807981",
);

/// Every `libm` that `Cargo.lock` pins, as (version, checksum).
fn locked_libm() -> Vec<(String, String)> {
    let lock = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.lock"))
        .expect("the workspace's Cargo.lock is readable");
    let field = |block: &str, key: &str| {
        block
            .lines()
            .find_map(|l| {
                l.strip_prefix(key)?
                    .strip_prefix(" = \"")?
                    .strip_suffix('"')
            })
            .unwrap_or("")
            .to_string()
    };
    lock.split("[[package]]")
        .filter(|block| field(block, "name") == "libm")
        .map(|block| (field(block, "version"), field(block, "checksum")))
        .collect()
}

/// The premise of the stand-ins holds for the `libm` the build uses: the lock file pins exactly
/// the source the exhaustive checks passed on.
#[test]
fn libm_is_the_one_the_ranges_were_checked_for() {
    let locked = locked_libm();
    assert!(!locked.is_empty(), "Cargo.lock pins no libm");
    for (version, checksum) in &locked {
        assert!(
            (version.as_str(), checksum.as_str()) == CHECKED_LIBM,
            "Cargo.lock pins libm {version} ({checksum}), not the one the ranges were checked on \
             ({CHECKED_LIBM:?}): run `cargo test --profile ranges -p mcu --test libm_ranges -- \
             --ignored` and update CHECKED_LIBM"
        );
    }
}

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
#[ignore = "exhaustive over every f32: run with --profile ranges --ignored (see the module docs)"]
fn sinf_is_within_its_range_for_every_f32() {
    assert_eq!(
        every_f32(libm::sinf, unit_range),
        None,
        "first failing bits"
    );
}

#[test]
#[ignore = "exhaustive over every f32: run with --profile ranges --ignored (see the module docs)"]
fn cosf_is_within_its_range_for_every_f32() {
    assert_eq!(
        every_f32(libm::cosf, unit_range),
        None,
        "first failing bits"
    );
}

#[test]
#[ignore = "exhaustive over every f32: run with --profile ranges --ignored (see the module docs)"]
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
