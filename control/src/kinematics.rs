//! Differential-drive kinematics: body twist (v, ω) ↔ wheel speeds (ω_L, ω_R).
//!
//! ```text
//!   inverse:  ω_L = v/r − ω·L/(2r)        forward:  v = (ω_L + ω_R)·r/2
//!             ω_R = v/r + ω·L/(2r)                  ω = (ω_R − ω_L)·r/L
//! ```
//!
//! L is the wheelbase (track width, wheel contact to wheel contact), r the wheel radius. The ratios
//! 1/r and L/(2r) (in Q16.16) and r/L (in Q12.20, as it is small: 0.2 on a typical base) are
//! computed once in [`DiffDrive::new`], each rounded to the nearest step from the exact geometry,
//! so a conversion is multiplies, adds and shifts only (no division on the control path); r/2 is
//! not a ratio at all but r with one more bit of shift.
//!
//! Each conversion sums exact 64-bit products of the inputs' Q16.16 bit patterns with the ratios'
//! bit patterns and rounds once, to the nearest Q16.16 value, at the end: nothing saturates on the way, and only a result outside the
//! Q16.16 range (beyond ±32 767 rad/s or m/s, far past any motor) is clamped to it. The geometry
//! limits keep every precomputed ratio inside Q16.16 and every sum inside `i64`; the bounds are
//! spelled out at [`DiffDrive::new`]. The `i64` operations are written saturating so that no
//! arithmetic can wrap or panic even if those bounds were wrong; with them, none saturates.
//!
//! These are the only copies of the formulas in the workspace: the host's 1 kHz bridge computes
//! its wheel commands from cmd_vel with [`DiffDrive::inverse_unrounded`] (and applies its own
//! limit policy in f64), and the simulator's plant relates its body velocity and its wheel speeds
//! with [`DiffDrive::inverse_unrounded`] and [`DiffDrive::forward`].

use crate::{Meters, MetersPerSecond, Q};
use statemachine::Speed;

/// A sum of products of Q16.16 values before its rounding: Q32.32, exact.
pub type Q32 = fixed::types::I32F32;

/// The ratio r/L, with the 20 fraction bits its smallness needs (≤ 1000 for any accepted
/// geometry, so Q12.20's ±2048 holds it).
type Q20 = fixed::types::I12F20;

const MIN_RADIUS: Q = Q::lit("0.001");
const MAX_RADIUS: Q = Q::const_from_int(10);
const MIN_BASE: Q = Q::lit("0.01");
const MAX_BASE: Q = Q::const_from_int(64);

/// Body velocity: forward speed and yaw rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Twist {
    /// Forward speed, m/s.
    pub v: MetersPerSecond,
    /// Yaw rate, rad/s, counter-clockwise positive.
    pub omega: Q,
}

/// Why a geometry was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum KinematicsError {
    /// Wheel radius must be between 1 mm and 10 m.
    WheelRadius = 1,
    /// Wheelbase must be between 1 cm and 64 m.
    Wheelbase = 2,
}

/// A validated differential-drive geometry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiffDrive {
    wheelbase: Meters,
    radius: Meters,
    inv_radius: Q,
    half_base_over_radius: Q,
    radius_over_base: Q20,
}

/// A sum of products `x` in units of 2^-(16 + SHIFT) rounded to the nearest Q16.16, ties upward,
/// and clamped to the Q16.16 range: SHIFT = 16 for Q16.16 × Q16.16 (a Q32.32 value), 17 for the
/// same halved, 20 for Q16.16 × Q12.20.
fn round_q<const SHIFT: u32>(x: i64) -> Q {
    // Callers keep |x| < 2⁶³ − 2¹⁹ (see `DiffDrive::new`), so the saturating add of the rounding
    // bias is a guard that never triggers.
    let bits = x.saturating_add((1 << SHIFT) >> 1) >> SHIFT;
    Q::from_bits(i32::try_from(bits).unwrap_or(if bits < 0 { i32::MIN } else { i32::MAX }))
}

/// `n / d` rounded to the nearest integer, ties upward, as `i32`; `None` unless 0 ≤ n < 2⁶¹,
/// 0 < d < 2⁶¹ and the quotient fits. For the ratios in [`DiffDrive::new`].
const fn div_round(n: i64, d: i64) -> Option<i32> {
    const LIMIT: i64 = 1 << 61;
    if n < 0 || n >= LIMIT || d <= 0 || d >= LIMIT {
        return None;
    }
    // (2n + d) / 2d with both doublings below 2⁶³: nothing saturates.
    match n
        .saturating_mul(2)
        .saturating_add(d)
        .checked_div(d.saturating_mul(2))
    {
        Some(q) if q <= i32::MAX as i64 => Some(q as i32),
        _ => None,
    }
}

/// The exact product of two Q16.16 bit patterns as Q32.32: |a·b| ≤ 2⁶² for any two `i32`, so the
/// saturating multiply never saturates (it only keeps the arithmetic visibly overflow-free).
fn wide(a: Q, b: Q) -> i64 {
    i64::from(a.to_bits()).saturating_mul(i64::from(b.to_bits()))
}

impl DiffDrive {
    /// Checks the geometry and precomputes the ratios, each the exact one rounded to the nearest
    /// step (at most half a step off: 2⁻¹⁷ for 1/r and L/(2r), 2⁻²¹ for r/L). A `const fn`, so a
    /// fixed geometry can be a constant that is checked at compile time.
    ///
    /// With 1 mm ≤ r ≤ 10 m and 1 cm ≤ L ≤ 64 m (r ≥ 66 and L ≥ 655 in Q16.16 steps): 1/r ≤ 1000
    /// and L/(2r) ≤ 32 000 fit Q16.16 (< 32 768), r/L ≤ 1000 fits Q12.20 (< 2048). The conversions
    /// then stay inside `i64`:
    /// - inverse: |v·(1/r)| < 2³¹·2²⁶ = 2⁵⁷ and |ω·L/(2r)| < 2³¹·2³¹ = 2⁶², sum < 2⁶³ − 2¹⁹;
    /// - forward: |ω_L + ω_R| ≤ 2³², times r < 2²⁰ stays below 2⁵²; |ω_R − ω_L| ≤ 2³², times
    ///   r/L < 2³⁰ (Q12.20) stays below 2⁶².
    pub const fn new(wheelbase: Meters, wheel_radius: Meters) -> Result<Self, KinematicsError> {
        let (base, radius) = (wheelbase.to_bits() as i64, wheel_radius.to_bits() as i64);
        if radius < MIN_RADIUS.to_bits() as i64 || radius > MAX_RADIUS.to_bits() as i64 {
            return Err(KinematicsError::WheelRadius);
        }
        if base < MIN_BASE.to_bits() as i64 || base > MAX_BASE.to_bits() as i64 {
            return Err(KinematicsError::Wheelbase);
        }
        // In Q16.16 steps: 1/r = 2³²/r, L/(2r) = 2¹⁵·L/r; in Q12.20 steps: r/L = 2²⁰·r/L. The
        // divisors are checked positive above and every quotient fits (bounds above).
        let Some(inv_radius) = div_round(1 << 32, radius) else {
            return Err(KinematicsError::WheelRadius);
        };
        let Some(half_base_over_radius) = div_round(base.saturating_mul(1 << 15), radius) else {
            return Err(KinematicsError::Wheelbase);
        };
        let Some(radius_over_base) = div_round(radius.saturating_mul(1 << 20), base) else {
            return Err(KinematicsError::Wheelbase);
        };
        Ok(Self {
            wheelbase,
            radius: wheel_radius,
            inv_radius: Q::from_bits(inv_radius),
            half_base_over_radius: Q::from_bits(half_base_over_radius),
            radius_over_base: Q20::from_bits(radius_over_base),
        })
    }

    /// Wheelbase, m.
    pub const fn wheelbase(&self) -> Meters {
        self.wheelbase
    }

    /// Wheel radius, m.
    pub const fn wheel_radius(&self) -> Meters {
        self.radius
    }

    /// Wheel speeds `[left, right]` (rad/s) for a body twist, each rounded once to the nearest
    /// Q16.16 value and clamped to the Q16.16 range.
    pub fn inverse(&self, t: Twist) -> [Speed; 2] {
        let [l, r] = self.inverse_unrounded(t);
        [round_q::<16>(l.to_bits()), round_q::<16>(r.to_bits())]
    }

    /// Wheel speeds `[left, right]` (rad/s) for a body twist before [`DiffDrive::inverse`] rounds
    /// and clamps them: the exact value of the formula with the twist and the precomputed ratios,
    /// as Q32.32. Never clamped: |ω| < 2³¹ rad/s for every twist and geometry (bounds at
    /// [`DiffDrive::new`]). For a caller that limits the wheel speeds by its own policy and must
    /// not see a clamp first (a clamp of one wheel would change the path's curvature).
    pub fn inverse_unrounded(&self, t: Twist) -> [Q32; 2] {
        let straight = wide(t.v, self.inv_radius);
        let turn = wide(t.omega, self.half_base_over_radius);
        [
            Q32::from_bits(straight.saturating_sub(turn)),
            Q32::from_bits(straight.saturating_add(turn)),
        ]
    }

    /// Body twist from wheel speeds (rad/s), each component rounded once to the nearest Q16.16
    /// value and clamped to the Q16.16 range: v = (ω_L + ω_R)·r/2 exactly from r, ω from r/L.
    pub fn forward(&self, left: Speed, right: Speed) -> Twist {
        let (l, r) = (i64::from(left.to_bits()), i64::from(right.to_bits()));
        let v = l
            .saturating_add(r)
            .saturating_mul(i64::from(self.radius.to_bits()));
        let omega = r
            .saturating_sub(l)
            .saturating_mul(i64::from(self.radius_over_base.to_bits()));
        Twist {
            v: round_q::<17>(v),
            omega: round_q::<20>(omega),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64) -> Q {
        Q::from_num(x)
    }
    fn close(a: Q, b: f64, tol: f64) -> bool {
        (a.to_num::<f64>() - b).abs() <= tol
    }

    #[test]
    fn straight_and_spin_by_hand() {
        // r = 0.1 m, L = 0.5 m.
        let k = DiffDrive::new(q(0.5), q(0.1)).unwrap();
        // 1 m/s straight: both wheels 1/0.1 = 10 rad/s.
        let [l, r] = k.inverse(Twist {
            v: q(1.0),
            omega: Q::ZERO,
        });
        assert!(close(l, 10.0, 1e-3) && close(r, 10.0, 1e-3), "{l} {r}");
        // Spin 1 rad/s: wheels ∓ 1·0.25/0.1 = ∓2.5 rad/s.
        let [l, r] = k.inverse(Twist {
            v: Q::ZERO,
            omega: q(1.0),
        });
        assert!(close(l, -2.5, 1e-3) && close(r, 2.5, 1e-3), "{l} {r}");
        // Forward of (4, 6) rad/s: v = 0.1·10/2 = 0.5 m/s, ω = 0.1·2/0.5 = 0.4 rad/s.
        let t = k.forward(q(4.0), q(6.0));
        assert!(close(t.v, 0.5, 1e-3) && close(t.omega, 0.4, 1e-3), "{t:?}");
    }

    #[test]
    fn seed_bridge_formula_matches() {
        // The seed's Python bridge: wL = (v − ω·WB/2)/R, wR = (v + ω·WB/2)/R, with WB = 0.42, R = 0.075.
        let k = DiffDrive::new(q(0.42), q(0.075)).unwrap();
        for (v, w) in [(0.5, 0.3), (-0.2, 1.1), (0.0, -0.7), (1.2, 0.0)] {
            let wl = (v - w * 0.42 / 2.0) / 0.075;
            let wr = (v + w * 0.42 / 2.0) / 0.075;
            let [l, r] = k.inverse(Twist {
                v: q(v),
                omega: q(w),
            });
            assert!(
                close(l, wl, 2e-3) && close(r, wr, 2e-3),
                "{v} {w}: {l} {r} vs {wl} {wr}"
            );
        }
    }

    #[test]
    fn round_trip_within_resolution() {
        let k = DiffDrive::new(q(0.42), q(0.075)).unwrap();
        for (v, w) in [(0.5, 0.3), (-1.0, 2.0), (0.01, -0.01)] {
            let [l, r] = k.inverse(Twist {
                v: q(v),
                omega: q(w),
            });
            let t = k.forward(l, r);
            assert!(close(t.v, v, 1e-3) && close(t.omega, w, 1e-3), "{t:?}");
        }
    }

    #[test]
    fn bad_geometry_refused() {
        assert_eq!(
            DiffDrive::new(q(0.5), Q::ZERO),
            Err(KinematicsError::WheelRadius)
        );
        assert_eq!(
            DiffDrive::new(q(0.5), q(-0.1)),
            Err(KinematicsError::WheelRadius)
        );
        assert_eq!(
            DiffDrive::new(Q::ZERO, q(0.1)),
            Err(KinematicsError::Wheelbase)
        );
        assert_eq!(
            DiffDrive::new(q(1000.0), q(0.1)),
            Err(KinematicsError::Wheelbase)
        );
        assert!(DiffDrive::new(q(64.0), q(0.001)).is_ok());
        assert_eq!(
            DiffDrive::new(q(64.001), q(0.1)),
            Err(KinematicsError::Wheelbase)
        );
    }

    /// The extreme geometries with the extreme inputs: every result is the rounded exact value with
    /// the precomputed ratios, or the clamp on the exact value's side, so nothing saturated on the
    /// way (the bounds argued at `DiffDrive::new`).
    #[test]
    fn extreme_corners_round_or_clamp_to_the_exact_side() {
        let edges = [Q::MIN, Q::from_bits(-1), Q::ZERO, Q::DELTA, Q::MAX];
        let check = |got: Q, want: f64| {
            if want >= 32768.0 {
                assert_eq!(got, Q::MAX, "{want}");
            } else if want < -32768.0 {
                assert_eq!(got, Q::MIN, "{want}");
            } else {
                assert!(
                    (got.to_num::<f64>() - want).abs() <= 1.0 / 65536.0,
                    "{got} {want}"
                );
            }
        };
        for (base, radius) in [(64.0, 0.001), (0.01, 10.0), (0.01, 0.001), (64.0, 10.0)] {
            let k = DiffDrive::new(q(base), q(radius)).unwrap();
            let f = |x: Q| x.to_num::<f64>();
            for a in edges {
                for b in edges {
                    let [l, r] = k.inverse(Twist { v: a, omega: b });
                    check(
                        l,
                        f(a) * f(k.inv_radius) - f(b) * f(k.half_base_over_radius),
                    );
                    check(
                        r,
                        f(a) * f(k.inv_radius) + f(b) * f(k.half_base_over_radius),
                    );
                    let t = k.forward(a, b);
                    check(t.v, (f(a) + f(b)) * f(k.radius) / 2.0);
                    check(t.omega, (f(b) - f(a)) * k.radius_over_base.to_num::<f64>());
                }
            }
        }
    }

    /// The unrounded wheel speeds are the exact sums, also where the rounded ones clamp, and
    /// rounding them gives `inverse`.
    #[test]
    fn unrounded_is_exact_and_rounds_to_inverse() {
        let edges = [Q::MIN, Q::from_bits(-1), Q::ZERO, Q::DELTA, Q::MAX];
        for (base, radius) in [(64.0, 0.001), (0.01, 10.0), (0.42, 0.075)] {
            let k = DiffDrive::new(q(base), q(radius)).unwrap();
            let ratio = |x: Q| i128::from(x.to_bits());
            for v in edges {
                for w in edges {
                    let t = Twist { v, omega: w };
                    let [l, r] = k.inverse_unrounded(t);
                    let straight = ratio(v) * ratio(k.inv_radius);
                    let turn = ratio(w) * ratio(k.half_base_over_radius);
                    assert_eq!(i128::from(l.to_bits()), straight - turn);
                    assert_eq!(i128::from(r.to_bits()), straight + turn);
                    assert_eq!(
                        k.inverse(t),
                        [round_q::<16>(l.to_bits()), round_q::<16>(r.to_bits())]
                    );
                }
            }
        }
    }

    /// `div_round`'s contract, each refusal on its own: the divisions of `DiffDrive::new` never
    /// reach the refusals (the geometry checks come first), so only a direct call shows them.
    #[test]
    fn div_round_rounds_half_up_and_refuses_out_of_range() {
        assert_eq!(div_round(7, 2), Some(4)); // 3.5, a tie: upward
        assert_eq!(div_round(4, 3), Some(1)); // 1.33
        assert_eq!(div_round(5, 3), Some(2)); // 1.67
        assert_eq!(div_round(0, 5), Some(0));
        let limit = 1_i64 << 61;
        assert_eq!(div_round(limit - 1, limit - 1), Some(1));
        assert_eq!(div_round(-1, 2), None);
        assert_eq!(div_round(limit, 1 << 40), None);
        assert_eq!(div_round(1, 0), None);
        assert_eq!(div_round(1, -3), None);
        assert_eq!(div_round(1, limit), None);
        // The quotient must fit i32: 2³¹ − 1 does, 2³¹ does not.
        assert_eq!(div_round(i64::from(i32::MAX), 1), Some(i32::MAX));
        assert_eq!(div_round(1 << 31, 1), None);
    }

    #[test]
    fn a_fixed_geometry_is_a_constant() {
        const AMR: Result<DiffDrive, KinematicsError> =
            DiffDrive::new(Q::lit("0.40"), Q::lit("0.08"));
        assert_eq!(AMR, DiffDrive::new(q(0.40), q(0.08)));
        const TOO_SMALL: Result<DiffDrive, KinematicsError> =
            DiffDrive::new(Q::lit("0.40"), Q::lit("0.0005"));
        assert_eq!(TOO_SMALL, Err(KinematicsError::WheelRadius));
    }

    /// Each ratio is the exact one (from the geometry as held) rounded to the nearest step: the
    /// error is at most half a step, 2⁻¹⁷ for 1/r and L/(2r), 2⁻²¹ for r/L.
    #[test]
    fn ratios_are_the_nearest_steps() {
        let geometries = [
            (0.40, 0.08),
            (0.42, 0.075),
            (0.3, 0.05),
            (1.2, 0.2),
            (64.0, 0.001),
            (0.01, 10.0),
            (0.01, 0.001),
            (64.0, 10.0),
        ];
        for (base, radius) in geometries {
            let k = DiffDrive::new(q(base), q(radius)).unwrap();
            let (b, r) = (k.wheelbase().to_num::<f64>(), k.radius.to_num::<f64>());
            let q16 = 1.0 / 65536.0;
            assert!((k.inv_radius.to_num::<f64>() - 1.0 / r).abs() <= q16 / 2.0);
            assert!((k.half_base_over_radius.to_num::<f64>() - b / (2.0 * r)).abs() <= q16 / 2.0);
            let q20 = 1.0 / 1_048_576.0;
            assert!((k.radius_over_base.to_num::<f64>() - r / b).abs() <= q20 / 2.0);
        }
    }

    /// The default simulated robot (L = 0.40 m, r = 0.08 m, held as 26 214 and 5 243 steps: r/2 is
    /// not a whole step) against the formula by hand: v = 0.08·(12 + 18)/2 = 1.2 m/s,
    /// ω = 0.08·(18 − 12)/0.40 = 1.2 rad/s; both within the geometry's own rounding (relative
    /// 2.3e-5 for r, 1.5e-5 for L) plus half an output step.
    #[test]
    fn forward_on_an_odd_radius_by_hand() {
        let k = DiffDrive::new(q(0.40), q(0.08)).unwrap();
        let t = k.forward(q(12.0), q(18.0));
        assert!(close(t.v, 1.2, 1.2 * 2.3e-5 + 7.7e-6), "{}", t.v);
        assert!(close(t.omega, 1.2, 1.2 * 3.8e-5 + 7.7e-6), "{}", t.omega);
    }

    /// One rounding per output: against the exact real-number formula with the precomputed ratios,
    /// the error is at most half a Q16.16 step; against the true geometry it adds the ratios' own
    /// rounding (≤ 2⁻¹⁷ for 1/r and L/(2r), ≤ 2⁻²¹ for r/L, none for r/2) times the input.
    #[test]
    fn rounds_once_to_nearest() {
        let k = DiffDrive::new(q(0.42), q(0.075)).unwrap();
        let ratio = |x: Q| x.to_num::<f64>();
        let mut seed = 0x1234_5678_9abc_def0_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            Q::from_bits((seed >> 40) as i32 - (1 << 23)) // ±128
        };
        let step = 1.0 / 65536.0;
        for _ in 0..100_000 {
            let (v, w) = (next(), next());
            let [l, r] = k.inverse(Twist { v, omega: w });
            let want_l = v.to_num::<f64>() * ratio(k.inv_radius)
                - w.to_num::<f64>() * ratio(k.half_base_over_radius);
            let want_r = v.to_num::<f64>() * ratio(k.inv_radius)
                + w.to_num::<f64>() * ratio(k.half_base_over_radius);
            assert!((l.to_num::<f64>() - want_l).abs() <= step / 2.0, "{v} {w}");
            assert!((r.to_num::<f64>() - want_r).abs() <= step / 2.0, "{v} {w}");
            let t = k.forward(v, w);
            let want_v = (v.to_num::<f64>() + w.to_num::<f64>()) * ratio(k.radius) / 2.0;
            let want_w =
                (w.to_num::<f64>() - v.to_num::<f64>()) * k.radius_over_base.to_num::<f64>();
            assert!((t.v.to_num::<f64>() - want_v).abs() <= step / 2.0);
            assert!((t.omega.to_num::<f64>() - want_w).abs() <= step / 2.0);
        }
    }
}
