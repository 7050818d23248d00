//! The odometry update's finiteness (P-19), proven in pieces. One Kani harness over the whole
//! update does not finish (the matrix product, the arc factors and the compensated sums of 16
//! symbolic f32: `proofs/REPORT.md`), so the argument is split where it is cheap to split:
//!
//! - **Magnitudes, by the monotonicity of rounding.** IEEE 754 rounding to nearest is monotone and
//!   odd, so for finite operands |a ⊗ b| ≤ A ⊗ B, |a ⊕ b| and |a ⊖ b| ≤ A ⊕ B and
//!   |a ⊘ b| ≤ A ⊘ B' whenever |a| ≤ A, |b| ≤ B and |b| ≥ B' > 0. The update's matrix product,
//!   twist and rotation into the world frame (no branches) are therefore bounded by the same
//!   operations on the largest magnitudes the accepted configuration allows, all positive. The
//!   test `update_magnitudes_are_finite_at_the_bounds` computes that chain with the real
//!   `body_displacement` and checks that every bound is finite and below the bound the next piece
//!   assumes. A finite result of finite operands with a non-zero divisor is never NaN.
//! - **The branching pieces, by Kani** (each a handful of symbolic f32, `libm`'s `sinf` replaced by
//!   its range as in the other odometry harnesses): [`arc_factors_bounded`] (both branches of the
//!   arc factors), [`position_step_stays_bounded`] (the clamped compensated sum),
//!   [`heading_turn_stays_bounded`] and [`heading_wrap_stays_bounded`] (the heading sum: a turn,
//!   then its wrap). They are inductive: the bounds they assume of a sum are the bounds they prove
//!   of it after the step, and `Sum::ZERO` (`new`, `reset`) is within them.
//! - **The refused period**, by Kani: [`refused_period_changes_nothing`] from any state.
//!
//! The turn added to the heading is `dtheta` when |Δθ| ≤ π, else `remainderf(Δθ, 2π)`, within
//! [−π, π] by `mcu/tests/libm_ranges.rs` (every f32 argument). `data` reports the position sums'
//! values and maps a heading value outside (−π, π] (or NaN) to π.

// Under Kani the bodies that only twins call are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::*;
use statemachine::harness::Source;
use statemachine::{assume, check, cover};

/// Largest |a| of the arc factors: |sin Δθ| ≤ 1 over |Δθ| ≥ [`SMALL_ANGLE`] (0.01); the series
/// stays near 1 below it.
pub(crate) const ARC_A_MAX: f32 = 100.0;
/// Largest |b| of the arc factors: 2 sin²(Δθ/2) ≤ 2 over |Δθ| ≥ 0.01.
pub(crate) const ARC_B_MAX: f32 = 200.0;
/// Largest |step| added to a position sum (the world-frame displacement of one update): the
/// magnitude chain's bound is 3.2·10¹⁴ m.
pub(crate) const STEP_MAX: f32 = 1e15;
/// Bounds of a position sum's parts: the value is clamped at ±`MAX_POSITION_M`, `hi` rounds
/// within one ulp of it and `lo` is at most half an ulp of `hi` (0.004 m at 10⁵ m).
pub(crate) const POSITION_HI_MAX: f32 = 2.0 * MAX_POSITION_M;
pub(crate) const POSITION_LO_MAX: f32 = 0.01;
/// Bounds of the heading sum's parts: (−π, π] after a wrap, plus the rounding; `lo` at most half
/// an ulp of `hi` (2.4·10⁻⁷ below 4).
pub(crate) const HEADING_HI_MAX: f32 = 4.0;
pub(crate) const HEADING_LO_MAX: f32 = 1e-6;
/// Bound of the heading sum's `hi` after a turn, before the wrap: 4 + π and the rounding.
pub(crate) const HEADING_TURNED_MAX: f32 = 8.0;

/// A finite value within ±`bound`. Under Kani any f32, which the caller narrows with `assume!`;
/// the twin, which would draw few such values from random bit patterns, also spreads values
/// over the whole range.
fn within(src: &mut impl Source, bound: f32) -> f32 {
    let v = src.f32();
    if cfg!(kani) || (v.is_finite() && v.abs() <= bound) {
        return v;
    }
    let unit = f32::from(src.u16()) / f32::from(u16::MAX);
    (unit * 2.0 - 1.0) * bound
}

fn finite_within(v: f32, bound: f32) -> bool {
    v.is_finite() && v.abs() <= bound
}

/// P-19: The arc factors of any finite Δθ are finite, |a| ≤ 100 and |b| ≤ 200, on both
/// branches (the series below 0.01 rad, `sinf` above).
pub fn arc_factors_bounded(src: &mut impl Source) {
    let dtheta = src.f32();
    assume!(src, dtheta.is_finite());
    let (a, b) = arc_factors(dtheta);
    check!(
        finite_within(a, ARC_A_MAX) && finite_within(b, ARC_B_MAX),
        "P-19: arc factors are finite and within their bounds"
    );
    cover!(
        src,
        dtheta != 0.0 && dtheta.abs() < SMALL_ANGLE,
        "series branch"
    );
    cover!(src, dtheta.abs() >= SMALL_ANGLE, "sine branch");
}

/// P-19: One position step keeps the sum bounded: from parts within their bounds, adding any
/// step of at most 10¹⁵ m gives finite parts within the same bounds and a value within
/// ±`MAX_POSITION_M`, clamped (and reported so) exactly when the sum went beyond it.
pub fn position_step_stays_bounded(src: &mut impl Source) {
    let hi = within(src, POSITION_HI_MAX);
    let lo = within(src, POSITION_LO_MAX);
    let step = within(src, STEP_MAX);
    assume!(src, finite_within(hi, POSITION_HI_MAX));
    assume!(src, finite_within(lo, POSITION_LO_MAX));
    assume!(src, finite_within(step, STEP_MAX));
    let mut s = Sum { hi, lo };
    let clamped = add_clamped(&mut s, step);
    check!(
        finite_within(s.hi, POSITION_HI_MAX) && finite_within(s.lo, POSITION_LO_MAX),
        "P-19: position sum parts stay within their bounds"
    );
    check!(
        s.value().abs() <= MAX_POSITION_M,
        "P-19: position within its bound"
    );
    cover!(src, clamped, "position clamped");
    cover!(src, !clamped && step != 0.0, "position moved");
}

/// P-19: Adding a turn keeps the heading sum's parts bounded: from parts within their bounds
/// (|hi| ≤ 4, |lo| ≤ 10⁻⁶), adding any turn within [−π, π] gives finite parts with |hi| ≤ 8 and
/// the same bound on `lo`, which [`heading_wrap_stays_bounded`] takes.
pub fn heading_turn_stays_bounded(src: &mut impl Source) {
    let hi = within(src, HEADING_HI_MAX);
    let lo = within(src, HEADING_LO_MAX);
    let turn = within(src, PI);
    assume!(src, finite_within(hi, HEADING_HI_MAX));
    assume!(src, finite_within(lo, HEADING_LO_MAX));
    assume!(src, finite_within(turn, PI));
    let mut h = Sum { hi, lo };
    h.add(turn);
    check!(
        finite_within(h.hi, HEADING_TURNED_MAX) && finite_within(h.lo, HEADING_LO_MAX),
        "P-19: a turned heading sum stays within the wrap's bounds"
    );
    cover!(src, h.value() > PI, "turned past pi");
    cover!(src, h.value() <= -PI, "turned past minus pi");
}

/// P-19: One wrap brings the heading sum's parts back within their bounds: from finite parts
/// with |hi| ≤ 8 and |lo| ≤ 10⁻⁶, `wrap_once` leaves |hi| ≤ 4 and |lo| ≤ 10⁻⁶. `wrap_heading`
/// is `wrap_once` at most twice, and the second starts within the first's result, so the heading
/// sum after every update is within the bounds [`heading_turn_stays_bounded`] assumes.
///
/// One run takes the sums whose `hi` is negative (`negative`) or the others (`hi ≥ 0`, −0
/// included): the two Kani harnesses take one half each, which together are every finite `hi`
/// (two smaller formulas, faster than one: `proofs/REPORT.md`, "Kani suite time"); the twin runs
/// both. A sum is wrapped toward zero: down from the upper half, up from the lower.
pub fn heading_wrap_stays_bounded(src: &mut impl Source, negative: bool) {
    let hi = within(src, HEADING_TURNED_MAX);
    let lo = within(src, HEADING_LO_MAX);
    assume!(src, finite_within(hi, HEADING_TURNED_MAX));
    assume!(src, finite_within(lo, HEADING_LO_MAX));
    assume!(src, (hi < 0.0) == negative);
    let mut h = Sum { hi, lo };
    let wrapped = wrap_once(&mut h);
    check!(
        finite_within(h.hi, HEADING_HI_MAX) && finite_within(h.lo, HEADING_LO_MAX),
        "P-19: heading sum parts stay within their bounds"
    );
    cover!(src, wrapped, "wrapped toward zero");
    cover!(src, !wrapped, "left within (−π, π]");
}

/// The bits of every field of `o` but the counters (NaN and −0 compared as bits).
fn state_bits(o: &Odometry) -> [u32; 9] {
    let [x, y, h] = [o.x, o.y, o.heading];
    let [vx, vy, wz] = o.twist;
    [x.hi, x.lo, y.hi, y.lo, h.hi, h.lo, vx, vy, wz].map(f32::to_bits)
}

fn data_bits(d: &OdometryData) -> [u32; 6] {
    [d.pos_x, d.pos_y, d.heading, d.vx, d.vy, d.wz].map(f32::to_bits)
}

/// P-19: A refused period (`dt` not finite or below `MIN_DT_S`) changes nothing but its counter,
/// from any state (configured or not, any baseline, any finite pose and twist, any counters), and
/// reports the data as before.
pub fn refused_period_changes_nothing(src: &mut impl Source) {
    let mut o = Odometry::new();
    if src.bool() {
        // Its content is not read on this path.
        o.config = Some(KinematicsConfig::default());
    }
    if src.bool() {
        o.baseline = Some([src.i32(), src.i32(), src.i32(), src.i32()]);
    }
    // Finite, as every update leaves them (the pieces above); any such values.
    let mut finite = || {
        let v = src.f32();
        if v.is_finite() {
            v
        } else {
            0.5
        }
    };
    o.x = Sum {
        hi: finite(),
        lo: finite(),
    };
    o.y = Sum {
        hi: finite(),
        lo: finite(),
    };
    o.heading = Sum {
        hi: finite(),
        lo: finite(),
    };
    o.twist = [finite(), finite(), finite()];
    o.counters = OdometryCounters {
        refused_configs: src.u32(),
        refused_dt: src.u32(),
        large_rotations: src.u32(),
        position_clamped: src.u32(),
        non_finite: src.u32(),
    };
    let dt = if src.bool() {
        src.f32()
    } else {
        // The twin's random bit patterns are rarely just below the limit.
        MIN_DT_S * f32::from(src.u8()) / 256.0
    };
    assume!(src, !(dt.is_finite() && dt >= MIN_DT_S));
    let (before, shown) = (o, o.data());
    let d = o.update([src.i32(), src.i32(), src.i32(), src.i32()], dt);
    check!(
        state_bits(&o) == state_bits(&before)
            && o.config == before.config
            && o.baseline == before.baseline,
        "P-19: a refused period changes nothing"
    );
    // The data are a function of the state, which the check above finds unchanged; the twin
    // also compares them (under Kani that would ask the solver whether two copies of the same
    // float additions agree, which it cannot see by itself).
    if !cfg!(kani) {
        check!(
            data_bits(&d) == data_bits(&shown),
            "P-19: a refused period reports the data as before"
        );
    }
    let (now, was) = (o.counters, before.counters);
    check!(
        now.refused_dt == was.refused_dt.saturating_add(1)
            && OdometryCounters {
                refused_dt: was.refused_dt,
                ..now
            } == was,
        "P-19: a refused period is counted"
    );
    cover!(src, dt.is_nan(), "period not a number");
    cover!(
        src,
        dt > 0.0 && dt < MIN_DT_S && o.config.is_some(),
        "period too short, configured"
    );
}

/// Stand-ins for the Kani harnesses.
#[cfg(kani)]
mod model {
    use super::*;

    /// [`Odometry::data`] as a read that returns nothing of the state: for the refused-period
    /// harness, whose Kani checks are of the state alone.
    pub(crate) fn data(_o: &Odometry) -> OdometryData {
        OdometryData::default()
    }

    /// [`Odometry::integrate`] where a harness must never reach it.
    pub(crate) fn integrate(_o: &mut Odometry, _counts: [i32; 4], _dt_s: f32) -> OdometryData {
        statemachine::fail!("P-19: a refused period is never integrated")
    }
}

#[cfg(kani)]
mod proofs {
    use statemachine::harness::KaniSource;

    #[kani::proof]
    #[kani::stub(libm::sinf, crate::verification::libm_models::sinf)]
    fn verify_arc_factors_bounded() {
        super::arc_factors_bounded(&mut KaniSource);
    }

    #[kani::proof]
    fn verify_position_step_stays_bounded() {
        super::position_step_stays_bounded(&mut KaniSource);
    }

    // MiniSat rather than CaDiCaL: 23.9 s against 28.6 s on one build, 21.6 s against 28.0 s on
    // another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::solver(minisat)]
    fn verify_heading_turn_stays_bounded() {
        super::heading_turn_stays_bounded(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL for both halves: `_up` 23 s against 34 s and
    // `_down` 23 s against 28 s on one build, `_up` 21 s against 34 s on another
    // (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::solver(minisat)]
    fn verify_heading_wrap_stays_bounded_down() {
        super::heading_wrap_stays_bounded(&mut KaniSource, false);
    }

    #[kani::proof]
    #[kani::solver(minisat)]
    fn verify_heading_wrap_stays_bounded_up() {
        super::heading_wrap_stays_bounded(&mut KaniSource, true);
    }

    /// `data` (a read of the state, compared by the twin only) by a stand-in: its additions of
    /// symbolic sums would only add NaN checks the property does not need. `integrate` (the
    /// accepted period) by a stand-in that fails: symbolic execution does not see that the
    /// assumption rules that path out, and would otherwise run the whole update, `libm` included.
    #[kani::proof]
    #[kani::stub(crate::odometry::Odometry::data, super::model::data)]
    #[kani::stub(crate::odometry::Odometry::integrate, super::model::integrate)]
    fn verify_refused_period_changes_nothing() {
        super::refused_period_changes_nothing(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use statemachine::harness::Twin;

    const CASES: u32 = 200_000;

    #[test]
    fn arc_factors_bounded() {
        Twin::run(0x0D_01, CASES, super::arc_factors_bounded).assert_covered(2);
    }

    #[test]
    fn position_step_stays_bounded() {
        Twin::run(0x0D_02, CASES, super::position_step_stays_bounded).assert_covered(2);
    }

    #[test]
    fn heading_turn_stays_bounded() {
        Twin::run(0x0D_03, CASES, super::heading_turn_stays_bounded).assert_covered(2);
    }

    #[test]
    fn heading_wrap_stays_bounded() {
        for (seed, negative) in [(0x0D_05, false), (0x0D_06, true)] {
            Twin::run(seed, CASES, |s| {
                super::heading_wrap_stays_bounded(s, negative)
            })
            .assert_covered(2);
        }
    }

    #[test]
    fn refused_period_changes_nothing() {
        Twin::run(0x0D_04, CASES, super::refused_period_changes_nothing).assert_covered(2);
    }
}

#[cfg(test)]
mod magnitudes {
    use super::*;

    /// The update's branch-free arithmetic at the largest magnitudes the accepted bounds allow,
    /// all positive, in the update's order of operations: by the monotonicity of rounding (module
    /// documentation) every intermediate of every update is at most these in magnitude.
    #[test]
    fn update_magnitudes_are_finite_at_the_bounds() {
        // Δφ: the largest wrapping count difference, converted exactly, times the largest scale.
        let counts = i32::MIN.unsigned_abs() as f32;
        assert_eq!(counts, 2_147_483_648.0, "i32::MIN converts exactly");
        let phi = counts * MAX_TICKS_TO_RAD;
        let inverse = [
            [MAX_LINEAR_GAIN; 4],
            [MAX_LINEAR_GAIN; 4],
            [MAX_YAW_GAIN; 4],
        ];
        let [dx, dy, dtheta] = body_displacement(&inverse, &[phi; 4]);
        // The bounds the module documentation gives by hand: 5.4·10¹¹ m and 5.4·10¹³ rad.
        assert!(
            dx.is_finite() && dx <= 5.5e11 && dy == dx,
            "|Δx|, |Δy| bound"
        );
        assert!(dtheta.is_finite() && dtheta <= 5.5e13, "|Δθ| bound");
        // The twist: divided by the shortest accepted period.
        for v in [dx, dy, dtheta] {
            let twist = v / MIN_DT_S;
            assert!(twist.is_finite() && twist <= 5.5e19, "twist bound");
        }
        // The body-frame step (a Δx − b Δy, b Δx + a Δy), then the rotation by θ₀ (|sin|, |cos| ≤ 1).
        let along = ARC_A_MAX * dx + ARC_B_MAX * dy;
        let across = ARC_B_MAX * dx + ARC_A_MAX * dy;
        let step = 1.0 * along + 1.0 * across;
        assert!(
            step.is_finite() && step <= STEP_MAX,
            "world-frame step bound"
        );
        // The position sum's additions (Fast2Sum and its renormalisation) stay far below f32::MAX.
        let t = POSITION_HI_MAX + step;
        let err = step + (t + POSITION_HI_MAX);
        let renormalised = t + (POSITION_LO_MAX + err);
        assert!(renormalised.is_finite(), "position sum bound");
    }
}
