//! Trapezoidal position profile for one axis: the position and speed reference of a position-mode
//! axis (a joint moving to an angle, a wheel moving to a position), one step per 1 kHz tick.
//!
//! ```text
//!   v (toward the target)
//!   ^
//!   |        accelerate      cruise       decelerate
//!  cap - - - - +-------------------------+
//!   |         /:                         :\       v rises by accel_step per tick up to cap,
//!   |        / :                         : \      holds at cap, and falls once the stopping
//!   |       /  :                         :  \     distance v + (v - a) + (v - 2a) + ... (one
//!   |      /   :                         :   \    term per tick) reaches the distance left
//!   |     /    :                         :    \
//!   0 ---+-----+-------------------------+-----+------> t
//!      start                                 target: pos = target, v = 0
//! ```
//!
//! A short move has no cruise (a triangle, the peak below `cap`). Time of a move of length d with
//! a = accel_step / dt: d/cap + cap/a when the cap is reached, 2·sqrt(d/a) when it is not.
//!
//! One [`Trapezoid::step`]:
//! 1. **move**: the position advances by the velocity of the tick that just ended, v·dt (the
//!    velocity the speed loop followed during that tick). It never goes past the target: reaching
//!    or passing it puts the axis on it at rest. Nor past a travel limit: passing one puts the axis
//!    on it at rest (step 2 then starts it back toward the target).
//! 2. **velocity** for the next tick: toward the target, the largest speed whose stopping distance
//!    fits the distance left, moved at most `accel_step` from the current velocity; then limited
//!    to ±`cap` — the one change that may exceed `accel_step`, and it only lowers |v| (the ladder
//!    lowers the cap when the link degrades). `cap` = 0 stops the axis and holds it.
//!
//! The stops of step 1 are abrupt (|Δv| > `accel_step`) only when the target was moved inside the
//! stopping distance, which no deceleration within the limit can honour: the profile then keeps
//! the target and the travel over the acceleration limit. From a state it planned for the same
//! target the axis arrives with |v| ≤ `accel_step` and never meets a limit.
//!
//! Units and number formats: positions in rad and speeds in rad/s, Q16.16 like the rest of the
//! crate; the acceleration as `accel_step`, the largest velocity change per tick (rad/s per tick,
//! = a·dt). The position keeps 1/1000 of a Q16.16 step more (a *sub-step*, 1.5e-8 rad) as a
//! remainder next to it: a speed of v Q16.16 steps per second moves exactly v sub-steps in one
//! 1 ms tick, so slow speeds (0.05 rad/s moves 3.3 Q16.16 steps per tick) accumulate without
//! rounding. Everything is integer arithmetic in `i64`/`u64` (distances in sub-steps below 2⁴³,
//! stopping distances below 2⁶³), written wrapping with a stated bound, saturating or checked,
//! never panicking; no square root, two divisions by a variable per tick.
//!
//! Proved by Kani for every valid state and every target and cap (`verification`): the position
//! stays within the travel and never passes the target; |v| ≤ cap; |Δv| ≤ `accel_step` except
//! for the cap and the two stops above. That a planned state never meets those stops (P-20) is
//! proved by Kani with the stopping distance, the move and the velocity chooser by their lemmas,
//! which `proofs/REPORT.md` ("P-20 by decomposition") proves in writing and the tests below check
//! (the stopping distances multiply unknowns, which the solver does not finish).

use crate::Q;
use statemachine::Speed;

/// A position along the axis, rad, Q16.16 (±32 768 rad).
pub type Position = Q;

/// Profile steps per second: one per 1 kHz watchdog tick, dt = 1 ms.
pub const TICK_HZ: u16 = 1000;

/// Sub-steps per Q16.16 step of position ([`TICK_HZ`]): a speed of v steps per second moves v
/// sub-steps per tick.
const SUB: i64 = TICK_HZ as i64;

/// The exact position `f` sub-steps above the Q16.16 step `p`, in sub-steps: |p| ≤ 2³¹ and
/// `f` < 2¹⁶, so |result| < 2⁴² and neither operation can wrap. Every exact position is computed
/// by this one expression (the step, the state's [`Trapezoid::exact`] and the harnesses), so the
/// solver sees one term where two computations meet.
pub(crate) const fn sub_steps(p: i32, f: u16) -> i64 {
    (p as i64).wrapping_mul(SUB).wrapping_add(f as i64)
}

/// `x` in sub-steps.
#[cfg(any(test, kani))]
const fn sub(x: Position) -> i64 {
    sub_steps(x.to_bits(), 0)
}

/// The travel limits of an axis, rad.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Travel {
    /// Lowest allowed position.
    pub lo: Position,
    /// Highest allowed position.
    pub hi: Position,
}

impl Travel {
    /// True if `lo < hi`.
    pub const fn is_valid(&self) -> bool {
        self.lo.to_bits() < self.hi.to_bits()
    }

    /// `x` limited to `lo ..= hi` (never panics, unlike `Ord::clamp`; for a travel that is not
    /// valid the result is `hi` or `lo`).
    pub const fn clamp(&self, x: Position) -> Position {
        if x.to_bits() > self.hi.to_bits() {
            self.hi
        } else if x.to_bits() < self.lo.to_bits() {
            self.lo
        } else {
            x
        }
    }
}

/// The limits an axis's profile keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProfileLimits {
    /// Where the axis may go.
    pub travel: Travel,
    /// Largest velocity change per tick, rad/s per tick (> 0): the acceleration times dt, e.g.
    /// 10 rad/s² → 0.01.
    pub accel_step: Speed,
}

impl ProfileLimits {
    /// True if the travel is valid and `accel_step > 0`.
    pub const fn is_valid(&self) -> bool {
        self.travel.is_valid() && self.accel_step.to_bits() > 0
    }
}

/// The profile state of one axis: the position, its sub-step remainder and the velocity for the
/// next tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Trapezoid {
    /// The exact position rounded down to Q16.16.
    pos: Position,
    /// Sub-steps above `pos`, `0 .. TICK_HZ`.
    frac: u16,
    vel: Speed,
}

/// True if the exact position `(p, f)` (Q16.16 bits, sub-steps above them, `0 ≤ f < SUB`) is at or
/// below the step `t`. Exact positions compare like pairs: no multiplication is needed.
const fn at_or_below(p: i64, f: i64, t: i64) -> bool {
    p < t || (p == t && f == 0)
}

impl Trapezoid {
    /// An axis at rest at `start`, clamped into `travel`.
    pub const fn new(start: Position, travel: &Travel) -> Self {
        Self {
            pos: travel.clamp(start),
            frac: 0,
            vel: Speed::ZERO,
        }
    }

    /// A profile in an arbitrary state, `frac` sub-steps above `pos`, for the harnesses (which
    /// assume [`Trapezoid::is_valid`]).
    #[cfg(any(test, kani))]
    pub(crate) const fn from_parts(pos: Position, frac: u16, vel: Speed) -> Self {
        Self { pos, frac, vel }
    }

    /// The position reference, rad: the exact position rounded down to Q16.16.
    pub const fn position(&self) -> Position {
        self.pos
    }

    /// The sub-steps (1/[`TICK_HZ`] of a Q16.16 step) the exact position lies above
    /// [`Trapezoid::position`], `0 .. TICK_HZ`.
    pub const fn remainder(&self) -> u16 {
        self.frac
    }

    /// The velocity reference for the coming tick, rad/s.
    pub const fn velocity(&self) -> Speed {
        self.vel
    }

    /// The exact position in sub-steps (< 2⁴¹ in magnitude: no wrap).
    #[cfg(any(test, kani))]
    pub(crate) const fn exact(&self) -> i64 {
        sub_steps(self.pos.to_bits(), self.frac)
    }

    /// The state invariant: the limits are valid, the remainder is below [`TICK_HZ`] and the
    /// exact position is within the travel.
    pub const fn is_valid(&self, lim: &ProfileLimits) -> bool {
        let (p, f) = (self.pos.to_bits() as i64, self.frac as i64);
        lim.is_valid()
            && f < SUB
            && p >= lim.travel.lo.to_bits() as i64
            && at_or_below(p, f, lim.travel.hi.to_bits() as i64)
    }

    /// One tick toward `target` (clamped into the travel) at no more than `cap` (a negative cap
    /// counts as 0): moves by the velocity of the tick that ended, chooses the velocity for the
    /// next one ([`Trapezoid::velocity`]) and returns the new position. See the module
    /// documentation for the rule.
    ///
    /// With limits that are not valid the axis stops at once and holds its position. A state
    /// outside the travel (the limits were narrowed) does not jump into it: moving outward it
    /// stops where it is, then it moves back toward the target like any other.
    pub fn step(&mut self, target: Position, cap: Speed, lim: &ProfileLimits) -> Position {
        if !lim.is_valid() {
            self.vel = Speed::ZERO;
            return self.pos;
        }
        let a = i64::from(lim.accel_step.to_bits());
        let t = lim.travel.clamp(target).to_bits();
        let v = self.vel.to_bits();

        // 1. Move by the velocity of the tick that just ended.
        let (p2, f2, moving) = advance(
            self.pos.to_bits(),
            self.frac,
            v,
            t,
            lim.travel.lo.to_bits(),
            lim.travel.hi.to_bits(),
        );

        // 2. The velocity for the next tick, in the frame where the target is ahead:
        // |left| < 2³³·SUB < 2⁴³.
        let left = sub_steps(t, 0).wrapping_sub(sub_steps(p2, f2));
        let w = if left >= 0 {
            toward(moving, left.unsigned_abs(), a)
        } else {
            toward(moving.wrapping_neg(), left.unsigned_abs(), a).wrapping_neg()
        };
        // |w| ≤ |moving| + a ≤ 2³², so the negation above cannot wrap; the cap brings it into i32.
        let c = i64::from(cap.to_bits().max(0));
        let w = if w > c {
            c
        } else if w < c.wrapping_neg() {
            c.wrapping_neg()
        } else {
            w
        };

        // |w| ≤ cap ≤ i32::MAX: the fallback is never taken.
        self.pos = Position::from_bits(p2);
        self.frac = f2;
        self.vel = Speed::from_bits(i32::try_from(w).unwrap_or(0));
        self.pos
    }

    /// True if the axis can stop, decelerating by `accel_step` per tick, before it would pass the
    /// target (clamped into the travel) or a travel limit: the states [`Trapezoid::step`] plans
    /// for a fixed target, in which no stop is abrupt. For the harnesses.
    #[cfg(any(test, kani))]
    pub(crate) fn can_stop(&self, target: Position, lim: &ProfileLimits) -> bool {
        let a = i64::from(lim.accel_step.to_bits()).unsigned_abs();
        let goal = sub(lim.travel.clamp(target));
        let here = self.exact();
        let v = i64::from(self.vel.to_bits());
        // The distance to the goal, as the step computes it (its `left`): on the goal's side the
        // room is its magnitude, beyond it the distance to the travel limit ahead.
        let ahead = goal.wrapping_sub(here);
        let (fits, room) = if v > 0 {
            if ahead >= 0 {
                (true, ahead.unsigned_abs())
            } else {
                let r = sub(lim.travel.hi).wrapping_sub(here);
                (r >= 0, r.unsigned_abs())
            }
        } else if v < 0 {
            if ahead <= 0 {
                (true, ahead.unsigned_abs())
            } else {
                let r = here.wrapping_sub(sub(lim.travel.lo));
                (r >= 0, r.unsigned_abs())
            }
        } else {
            return true;
        };
        fits && stop_distance(v.unsigned_abs(), a) <= room
    }
}

/// The exact position `f` sub-steps above the step `p` (`0 ≤ f < SUB`, |p| ≤ 2³¹) moved by `v`
/// sub-steps, as (step, sub-steps): v = q steps and r sub-steps with |r| < SUB (a constant divisor:
/// the division cannot fail), then one carry brings the sub-steps back into `0 .. SUB`. |q| < 2²²:
/// no wrap.
pub(crate) fn moved(p: i64, f: i64, v: i32) -> (i64, i64) {
    let (q, r) = (
        i64::from(v.wrapping_div(1000)),
        i64::from(v.wrapping_rem(1000)),
    );
    let (p2, f2) = (p.wrapping_add(q), f.wrapping_add(r));
    if f2 < 0 {
        (p2.wrapping_sub(1), f2.wrapping_add(SUB))
    } else if f2 >= SUB {
        (p2.wrapping_add(1), f2.wrapping_sub(SUB))
    } else {
        (p2, f2)
    }
}

/// Step 1 of [`Trapezoid::step`], the move: from the exact position `f` sub-steps above the step
/// `p` (`f` < [`TICK_HZ`]), by the velocity `v` of the tick that ended (v sub-steps), toward the
/// target step `t` within the travel `lo ..= hi` (`lo ≤ t ≤ hi`). Returns the new position as
/// (step, sub-steps) and the velocity that carried on: `v`, or 0 where the move stopped the axis.
///
/// In exact sub-steps, with e the position, g = `t`·1000 and the limits likewise: an axis on the
/// near side of the target (or on it) that reaches or passes it stops on it; one beyond the target
/// that passes the travel limit ahead stops on it, or where it is if it was already beyond it;
/// otherwise it moves to e + v. `proofs/REPORT.md` ("P-20", lemma A) proves that statement of this
/// body, the tests `advance_*` check it, and the harness of P-20 uses it in place of the body
/// (`verification::stand_in::advance`).
pub(crate) fn advance(p32: i32, f: u16, v: i32, t: i32, lo: i32, hi: i32) -> (i32, u16, i64) {
    let (p, f) = (i64::from(p32), i64::from(f));
    let (t, lo, hi) = (i64::from(t), i64::from(lo), i64::from(hi));
    let (mut p2, mut f2) = moved(p, f, v);
    // The bound ahead is the target if the axis is on its near side (or on it), else the travel
    // limit. Reaching the target, or passing either, stops the axis there. (A state already
    // beyond the limit, left by a narrower travel, stops where it is: no jump.)
    let mut moving = i64::from(v);
    if v > 0 {
        if at_or_below(p, f, t) {
            if p2 >= t {
                (p2, f2, moving) = (t, 0, 0);
            }
        } else if !at_or_below(p2, f2, hi) {
            (p2, f2, moving) = if at_or_below(p, f, hi) {
                (hi, 0, 0)
            } else {
                (p, f, 0)
            };
        }
    } else if v < 0 {
        if p >= t {
            if at_or_below(p2, f2, t) {
                (p2, f2, moving) = (t, 0, 0);
            }
        } else if p2 < lo {
            (p2, f2, moving) = if p >= lo { (lo, 0, 0) } else { (p, f, 0) };
        }
    }
    // (p2, f2) lies between (p, f) and a bound, so p2 fits i32 and 0 ≤ f2 < SUB: neither
    // fallback is taken.
    (
        i32::try_from(p2).unwrap_or(p32),
        u16::try_from(f2).unwrap_or(0),
        moving,
    )
}

/// What [`toward`] needs: `1 ≤ a < 2³¹` (an `accel_step` of a valid [`ProfileLimits`]) and
/// |u| ≤ 2³¹ (a velocity, or its negation).
#[cfg(any(test, kani))]
pub(crate) const fn toward_needs(u: i64, a: i64) -> bool {
    a >= 1 && a <= i32::MAX as i64 && u.unsigned_abs() <= 1 << 31
}

/// What [`toward`] gives, from what it needs: a speed `w` within `u ± a`, and 0 for an axis at
/// rest on its target (`u` = 0, `d` = 0).
#[cfg(any(test, kani))]
pub(crate) const fn toward_gives(u: i64, d: u64, a: i64, w: i64) -> bool {
    w >= u.wrapping_sub(a) && w <= u.wrapping_add(a) && (u != 0 || d != 0 || w == 0)
}

/// The stopping distance, in sub-steps, of the speed v = k·a + r (0 ≤ r < a, in sub-steps per
/// tick) falling by `a` per tick: v + (v − a) + … + r = (k + 1)(v + r)/2 (the product is even).
/// With v ≤ 2³¹ and a ≥ 1 the product stays below 2⁶³ (`proofs/REPORT.md`, "P-20"), so the
/// saturating operations never saturate.
fn stopping(k: u64, r: u64, a: u64) -> u64 {
    let v = k.saturating_mul(a).saturating_add(r);
    k.saturating_add(1).saturating_mul(v.saturating_add(r)) >> 1
}

/// The stopping distance of the speed `v` (sub-steps per tick) falling by `a` (≥ 1) per tick,
/// S(v) = v + (v − a) + (v − 2a) + … over the terms that are not negative; exact for v ≤ 2³¹.
/// Under Kani the harness of P-20 puts an uninterpreted function in its place
/// (`verification::stand_in::stop_distance`).
#[cfg(any(test, kani))]
pub(crate) fn stop_distance(v: u64, a: u64) -> u64 {
    let (k, r) = (v.checked_div(a).unwrap_or(0), v.checked_rem(a).unwrap_or(0));
    stopping(k, r, a)
}

/// The velocity for the next tick toward a target `d` sub-steps ahead, from `u` (positive =
/// toward it), before the cap: the largest speed whose stopping distance fits `d`, moved at most
/// `a` (≥ 1) from `u`. Needs |u| ≤ 2³¹; the result is within `u ± a`.
///
/// Under Kani it carries that as its contract (`toward_needs`, `toward_gives`, above):
/// `control::verification` proves the contract for every input and the two harnesses of
/// [`Trapezoid::step`] then use it in place of the body (`kani::stub_verified`), which spares them
/// the multiplications and divisions of the stopping distances (their properties hold for any
/// speed within `u ± a`).
#[cfg_attr(kani, kani::requires(toward_needs(u, a)))]
#[cfg_attr(kani, kani::ensures(|w: &i64| toward_gives(u, d, a, *w)))]
pub(crate) fn toward(u: i64, d: u64, a: i64) -> i64 {
    let up = u.saturating_add(a);
    if up <= 0 {
        // Moving away at a or more: brake by a full step.
        return up;
    }
    if u < 0 {
        // 0 < up < a: a speed below a stops within one tick, so its stopping distance is itself.
        return up.min(i64::try_from(d).unwrap_or(i64::MAX));
    }
    toward_ahead(u, d, a)
}

/// [`toward`] for `u` ≥ 0 (moving toward the target, or at rest): the largest speed x with
/// S(x) ≤ `d`, limited to `u ± a`. Needs `0 ≤ u ≤ 2³¹` and `1 ≤ a < 2³¹`. If S(max(u − a, 0)) ≤ `d`
/// (the axis could stop in time, braking by at most `a`), the result w lies in
/// [max(u − a, 0), u + a] and S(w) ≤ `d`: the lemma `proofs/REPORT.md` ("P-20") proves in writing,
/// the tests `toward_ahead_*` check, and the harness of P-20 uses in place of this body
/// (`verification::stand_in::toward_ahead`).
pub(crate) fn toward_ahead(u: i64, d: u64, a: i64) -> i64 {
    let up = u.saturating_add(a);
    let (ua, aa) = (u.unsigned_abs(), a.unsigned_abs());
    // u = k·a + r; u ± a have the same r and k ± 1. S(x) is the stopping distance of x.
    let (k, r) = (
        ua.checked_div(aa).unwrap_or(0),
        ua.checked_rem(aa).unwrap_or(0),
    );
    let s = stopping(k, r, aa);
    // S(u + a) = (u + a) + S(u): accelerate (or hold at the cap, applied after) if it fits.
    if s.saturating_add(ua).saturating_add(aa) <= d {
        return up;
    }
    // S(u − a) = S(u) − u: if even a full step of braking does not fit, brake by the full step
    // (the target moved inside the stopping distance; the move will stop the axis on it).
    if k >= 1 && s.saturating_sub(ua) > d {
        return u.saturating_sub(a);
    }
    // The largest speed x with S(x) ≤ d lies in [max(u − a, 0), u + a), in the band
    // [j·a, (j + 1)·a) of j = k + 1, k or k − 1: the highest j with S(j·a) ≤ d. With
    // S(k·a) = S(u) − (k + 1)·r and S((j + 1)·a) = S(j·a) + (j + 1)·a:
    let at_k = s.saturating_sub(k.saturating_add(1).saturating_mul(r));
    let k_a = ua.saturating_sub(r);
    let at_k1 = at_k.saturating_add(k_a).saturating_add(aa);
    let (j, at_j) = if at_k1 <= d {
        (k.saturating_add(1), at_k1)
    } else if at_k <= d {
        (k, at_k)
    } else {
        // k ≥ 1 here (S(0) = 0 ≤ d): S((k − 1)·a) = S(k·a) − k·a.
        (k.saturating_sub(1), at_k.saturating_sub(k_a))
    };
    // Within the band S(j·a + x) = S(j·a) + (j + 1)·x, and x < a because S((j + 1)·a) > d.
    let x = d
        .saturating_sub(at_j)
        .checked_div(j.saturating_add(1))
        .unwrap_or(0)
        .min(aa.saturating_sub(1));
    let best = i64::try_from(j.saturating_mul(aa).saturating_add(x)).unwrap_or(i64::MAX);
    // Already within [u − a, u + a) by the choice of the band; the clamp makes it visible.
    let down = u.saturating_sub(a);
    if best < down {
        down
    } else if best > up {
        up
    } else {
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::q_from_f64;

    extern crate std;
    use std::vec::Vec;

    fn q(x: f64) -> Q {
        q_from_f64(x)
    }

    fn lim(lo: f64, hi: f64, accel_step: f64) -> ProfileLimits {
        ProfileLimits {
            travel: Travel {
                lo: q(lo),
                hi: q(hi),
            },
            accel_step: q(accel_step),
        }
    }

    /// Steps toward `target` until the axis rests on it (at most `max` ticks); returns the
    /// (position, velocity) after every tick.
    fn run(
        p: &mut Trapezoid,
        target: f64,
        cap: f64,
        l: &ProfileLimits,
        max: usize,
    ) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        for _ in 0..max {
            let pos = p.step(q(target), q(cap), l);
            assert!(p.is_valid(l));
            out.push((pos.to_num::<f64>(), p.velocity().to_num::<f64>()));
            if pos == l.travel.clamp(q(target)) && p.velocity() == Speed::ZERO {
                break;
            }
        }
        out
    }

    fn peak(trace: &[(f64, f64)]) -> f64 {
        trace.iter().map(|t| t.1.abs()).fold(0.0, f64::max)
    }

    #[test]
    fn one_radian_is_a_trapezoid() {
        // d = 1 rad, cap 2 rad/s, a = 10 rad/s²: t = d/v + v/a = 0.5 s + 0.2 s = 0.7 s = 700 ticks.
        let l = lim(-10.0, 10.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        let tr = run(&mut p, 1.0, 2.0, &l, 2000);
        let n = tr.len();
        assert!((697..=704).contains(&n), "arrived after {n} ticks");
        assert_eq!(p.position(), Q::ONE);
        assert_eq!(p.velocity(), Speed::ZERO);
        assert_eq!(peak(&tr), 2.0);
        // Monotone, no overshoot; the cruise lasts d/v − v/a = 0.3 s (300 ticks).
        for w in tr.windows(2) {
            assert!(w[1].0 >= w[0].0 && w[1].0 <= 1.0);
        }
        let cruise = tr.iter().filter(|t| t.1 == 2.0).count();
        assert!((297..=303).contains(&cruise), "cruise {cruise} ticks");
        // The velocity changes by at most accel_step per tick, arrival included.
        let step = q(0.01).to_num::<f64>();
        let mut prev = 0.0;
        for t in &tr {
            assert!((t.1 - prev).abs() <= step + 1e-12, "{} → {}", prev, t.1);
            prev = t.1;
        }
    }

    #[test]
    fn short_move_is_a_triangle() {
        // d = 0.1 rad, a = 10 rad/s²: the peak sqrt(a·d) = 1 rad/s stays below the cap of 2;
        // t = 2·sqrt(d/a) = 0.2 s = 200 ticks.
        let l = lim(-10.0, 10.0, 0.01);
        let mut p = Trapezoid::new(q(0.5), &l.travel);
        let tr = run(&mut p, 0.6, 2.0, &l, 1000);
        let n = tr.len();
        assert!((198..=204).contains(&n), "arrived after {n} ticks");
        assert_eq!(p.position(), q(0.6));
        let v = peak(&tr);
        assert!((0.98..=1.01).contains(&v), "peak {v}");
        assert!(tr.iter().all(|t| t.0 <= q(0.6).to_num::<f64>()));
    }

    #[test]
    fn negative_move_mirrors_a_positive_one() {
        let l = lim(-10.0, 10.0, 0.01);
        let mut up = Trapezoid::new(Q::ZERO, &l.travel);
        let mut down = Trapezoid::new(Q::ZERO, &l.travel);
        let a = run(&mut up, 1.0, 2.0, &l, 2000);
        let b = run(&mut down, -1.0, 2.0, &l, 2000);
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.1, -y.1);
            // Positions round down, so the mirror image is within one Q16.16 step.
            assert!((x.0 + y.0).abs() <= 1.6e-5, "{x:?} {y:?}");
        }
    }

    #[test]
    fn reversal_decelerates_first() {
        let l = lim(-10.0, 10.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        for _ in 0..300 {
            p.step(q(5.0), q(2.0), &l);
        }
        assert_eq!(p.velocity(), q(2.0));
        let turn = p.position().to_num::<f64>();
        // New target behind: the velocity falls by accel_step per tick through zero, the axis
        // keeps going forward for v²/(2a) = 0.2 rad, then comes back and stops on −1.
        let mut prev = p.velocity();
        let mut furthest = turn;
        for _ in 0..3000 {
            p.step(q(-1.0), q(2.0), &l);
            let v = p.velocity();
            furthest = furthest.max(p.position().to_num::<f64>());
            if v > prev {
                // The deceleration toward −1 started: the rest is an ordinary trapezoid.
                assert_eq!(prev, -q(2.0));
                break;
            }
            assert!(prev - v <= q(0.01), "{prev} → {v}");
            prev = v;
        }
        assert!(
            (furthest - turn - 0.2).abs() < 0.005,
            "went on for {}",
            furthest - turn
        );
        run(&mut p, -1.0, 2.0, &l, 3000);
        assert_eq!(p.position(), q(-1.0));
        assert_eq!(p.velocity(), Speed::ZERO);
    }

    #[test]
    fn cap_drop_stops_at_once_and_holds() {
        let l = lim(-10.0, 10.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        for _ in 0..400 {
            p.step(q(5.0), q(2.0), &l);
        }
        assert_eq!(p.velocity(), q(2.0));
        let before = p.exact();
        p.step(q(5.0), Q::ZERO, &l);
        // The tick that ended ran at 2 rad/s (2 mrad); the next one runs at 0.
        assert_eq!(p.velocity(), Speed::ZERO);
        assert_eq!(p.exact() - before, i64::from(q(2.0).to_bits()));
        let held = p.exact();
        for _ in 0..1000 {
            p.step(q(5.0), Q::ZERO, &l);
            assert_eq!(p.exact(), held);
            assert_eq!(p.velocity(), Speed::ZERO);
        }
        // A negative cap counts as zero.
        p.step(q(5.0), q(-3.0), &l);
        assert_eq!(p.exact(), held);
        // With the cap restored the axis starts again with one accel_step.
        p.step(q(5.0), q(2.0), &l);
        assert_eq!(p.velocity(), q(0.01));
    }

    #[test]
    fn lower_cap_clamps_at_once_then_cruises() {
        let l = lim(-10.0, 10.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        for _ in 0..400 {
            p.step(q(5.0), q(2.0), &l);
        }
        p.step(q(5.0), q(0.5), &l);
        assert_eq!(p.velocity(), q(0.5));
        p.step(q(5.0), q(0.5), &l);
        assert_eq!(p.velocity(), q(0.5));
        run(&mut p, 5.0, 0.5, &l, 20_000);
        assert_eq!(p.position(), q(5.0));
    }

    #[test]
    fn targets_outside_the_travel_stop_at_the_limit() {
        let l = lim(-1.0, 1.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        let tr = run(&mut p, 5.0, 2.0, &l, 5000);
        assert_eq!(p.position(), q(1.0));
        assert_eq!(p.velocity(), Speed::ZERO);
        assert!(tr.iter().all(|t| t.0 <= 1.0));
        let tr = run(&mut p, -100.0, 2.0, &l, 5000);
        assert_eq!(p.position(), q(-1.0));
        assert!(tr.iter().all(|t| t.0 >= -1.0));
        // A start outside is clamped in.
        assert_eq!(Trapezoid::new(q(3.0), &l.travel).position(), q(1.0));
        assert_eq!(Trapezoid::new(q(-3.0), &l.travel).position(), q(-1.0));
    }

    #[test]
    fn slow_speed_still_moves() {
        // 0.05 rad/s is 3.28 Q16.16 steps per tick: after 1 s the axis is at 0.05 rad, not at
        // the 3/65536 or 4/65536 per tick that rounding every tick would give.
        let l = lim(-10.0, 10.0, 1.0);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        for _ in 0..1001 {
            p.step(q(1.0), q(0.05), &l);
        }
        let x = p.position().to_num::<f64>();
        assert!((x - 0.05).abs() <= 2.0 / 65536.0, "{x}");
    }

    #[test]
    fn target_moved_inside_the_stopping_distance_stops_on_it() {
        // At 2 rad/s the stopping distance is 0.2 rad; a target 5 mrad ahead cannot be met by
        // decelerating: the axis brakes by accel_step and stops on the target, never past it.
        let l = lim(-10.0, 10.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        for _ in 0..400 {
            p.step(q(5.0), q(2.0), &l);
        }
        let t = p.position() + q(0.005);
        let v0 = p.velocity();
        p.step(t, q(2.0), &l);
        assert!(p.position() < t);
        assert_eq!(p.velocity(), v0 - q(0.01));
        p.step(t, q(2.0), &l);
        p.step(t, q(2.0), &l);
        assert_eq!(p.position(), t);
        assert_eq!(p.velocity(), Speed::ZERO);
    }

    #[test]
    fn narrowed_travel_does_not_jump() {
        // Cruising up at 1 rad/s at 0.9 rad when the travel shrinks to [−0.5, 0.5]: the axis
        // stops where it is (no jump to 0.5), then comes back into the travel and stops on 0.5.
        let wide = lim(-2.0, 2.0, 0.01);
        let mut p = Trapezoid::new(Q::ZERO, &wide.travel);
        for _ in 0..1000 {
            if p.position() >= q(0.9) {
                break;
            }
            p.step(q(2.0), q(1.0), &wide);
        }
        assert_eq!(p.velocity(), q(1.0));
        let narrow = lim(-0.5, 0.5, 0.01);
        let at = p.position();
        p.step(q(1.0), q(1.0), &narrow);
        assert_eq!(p.position(), at);
        assert_eq!(p.velocity(), -q(0.01));
        let mut prev = p.position();
        for _ in 0..5000 {
            p.step(q(1.0), q(1.0), &narrow);
            assert!(p.position() <= prev);
            prev = p.position();
            if p.velocity() == Speed::ZERO {
                break;
            }
        }
        assert_eq!(p.position(), q(0.5));
        assert!(p.is_valid(&narrow));
    }

    #[test]
    fn random_commands_keep_every_bound() {
        // Long runs under random limits, with the target and the cap changed at random ticks:
        // every step keeps the bounds, and a step from a planned state (one that can stop before
        // the target) is smooth and leads to another planned state.
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut rnd = |n: u64| {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 33) % n
        };
        let (mut arrivals, mut abrupt) = (0, 0);
        for _ in 0..200 {
            let lo = -(rnd(1000) as f64) / 100.0;
            let hi = lo + 0.01 + rnd(2000) as f64 / 100.0;
            let l = lim(lo, hi, (1 + rnd(2000)) as f64 / 10_000.0);
            let a = l.accel_step;
            let pick = |r: u64| lo - 1.0 + (hi - lo + 2.0) * r as f64 / 1e6;
            let mut p = Trapezoid::new(q(pick(rnd(1_000_000))), &l.travel);
            let (mut target, mut cap) = (q(pick(rnd(1_000_000))), q(rnd(500) as f64 / 100.0));
            for _ in 0..3000 {
                if rnd(400) == 0 {
                    target = q(pick(rnd(1_000_000)));
                }
                if rnd(600) == 0 {
                    cap = q(rnd(500) as f64 / 100.0);
                }
                let t = l.travel.clamp(target);
                let before = p;
                let planned = p.can_stop(target, &l);
                p.step(target, cap, &l);
                let (v0, v1) = (before.velocity(), p.velocity());
                assert!(p.is_valid(&l));
                assert!(v1.abs() <= cap);
                let (e0, e1, goal) = (before.exact(), p.exact(), sub(t));
                assert!(e0 > goal || e1 <= goal);
                assert!(e0 < goal || e1 >= goal);
                let forced = v1.abs() == cap && v1.abs() < v0.abs();
                if planned {
                    assert!((v1 - v0).abs() <= a || forced, "{v0} → {v1}");
                    assert!(p.can_stop(target, &l));
                } else if (v1 - v0).abs() > a && !forced {
                    abrupt += 1;
                }
                if e1 == goal && e0 != goal {
                    arrivals += 1;
                }
            }
        }
        // The runs do arrive, and do meet targets moved inside the stopping distance.
        assert!(
            arrivals > 100 && abrupt > 0,
            "{arrivals} arrivals, {abrupt} abrupt stops"
        );
    }

    #[test]
    fn invalid_limits_hold() {
        let mut p = Trapezoid::from_parts(q(0.5), 0, q(1.0));
        let bad = [
            lim(1.0, 1.0, 0.01),
            lim(2.0, -2.0, 0.01),
            lim(-2.0, 2.0, 0.0),
        ];
        for l in &bad {
            assert!(!l.is_valid());
            assert_eq!(p.step(q(1.5), q(2.0), l), q(0.5));
            assert_eq!(p.velocity(), Speed::ZERO);
        }
    }

    /// The state invariant clause by clause: the remainder is below one Q16.16 step (`TICK_HZ`
    /// sub-steps), and the exact position lies in the travel (on `hi` only with no remainder).
    #[test]
    fn is_valid_bounds_the_remainder_and_the_exact_position() {
        let l = lim(-1.0, 1.0, 0.01);
        let v = Speed::ZERO;
        assert!(Trapezoid::from_parts(q(0.5), TICK_HZ - 1, v).is_valid(&l));
        assert!(!Trapezoid::from_parts(q(0.5), TICK_HZ, v).is_valid(&l));
        assert!(Trapezoid::from_parts(q(-1.0), 0, v).is_valid(&l));
        assert!(!Trapezoid::from_parts(q(-1.0) - Q::DELTA, TICK_HZ - 1, v).is_valid(&l));
        assert!(Trapezoid::from_parts(q(1.0), 0, v).is_valid(&l));
        assert!(!Trapezoid::from_parts(q(1.0), 1, v).is_valid(&l));
        assert!(!Trapezoid::from_parts(q(0.5), 0, v).is_valid(&lim(-1.0, 1.0, 0.0)));
    }

    #[test]
    fn extremes_do_not_overflow() {
        let l = ProfileLimits {
            travel: Travel {
                lo: Q::MIN,
                hi: Q::MAX,
            },
            accel_step: Q::MAX,
        };
        let mut p = Trapezoid::new(Q::MIN, &l.travel);
        for _ in 0..5 {
            p.step(Q::MAX, Q::MAX, &l);
            assert!(p.is_valid(&l));
        }
        let tiny = ProfileLimits {
            accel_step: Q::from_bits(1),
            ..l
        };
        let mut p = Trapezoid::from_parts(Q::MIN, 0, Q::MAX);
        for _ in 0..5 {
            p.step(Q::MAX, Q::MAX, &tiny);
            assert!(p.is_valid(&tiny));
        }
        let mut p = Trapezoid::from_parts(Q::MAX, 0, Q::MIN);
        p.step(Q::MIN, Q::MAX, &tiny);
        assert!(p.is_valid(&tiny));
    }

    #[test]
    fn planned_states_can_stop() {
        // Every state of a long run, including a reversal and a cap change, stays one the
        // profile can stop from.
        let l = lim(-3.0, 3.0, 0.007);
        let mut p = Trapezoid::new(Q::ZERO, &l.travel);
        let plan: [(f64, f64, usize); 4] = [
            (2.5, 1.3, 900),
            (-2.0, 1.3, 3000),
            (4.0, 0.3, 800),
            (0.1, 2.0, 3000),
        ];
        for (target, cap, ticks) in plan {
            for _ in 0..ticks {
                assert!(p.can_stop(q(target), &l));
                let v0 = p.velocity();
                p.step(q(target), q(cap), &l);
                let dv = (p.velocity() - v0).abs();
                assert!(dv <= q(0.007) || p.velocity().abs() == q(cap));
            }
        }
    }

    // The lemmas of P-20 (`proofs/REPORT.md`, "P-20"), which the harness of P-20 takes as given
    // (`verification::stand_in`): checked against references written apart from the code.

    /// S(v) by its definition: the sum of v, v − a, v − 2a, … while the terms are not negative.
    fn sum_of_terms(v: u64, a: u64) -> u64 {
        let mut total = 0;
        let mut term = v;
        loop {
            total += term;
            if term < a {
                return total;
            }
            term -= a;
        }
    }

    /// S(v) in exact 128-bit arithmetic by a second closed form: with k = ⌊v/a⌋,
    /// S(v) = (k + 1)·v − a·k·(k + 1)/2.
    fn closed_form(v: u64, a: u64) -> u128 {
        let (v, a) = (u128::from(v), u128::from(a));
        let k = v / a;
        (k + 1) * v - a * k * (k + 1) / 2
    }

    fn lcg(seed: &mut u64) -> u64 {
        *seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        *seed >> 11
    }

    /// A random speed up to 2³¹ and step below 2³¹, the step of a few bits when `i` is even.
    fn speed_and_step(seed: &mut u64, i: u64) -> (u64, u64) {
        let v = lcg(seed) % ((1 << 31) + 1);
        let bits = if i.is_multiple_of(2) {
            1 + lcg(seed) % 31
        } else {
            31
        };
        (v, 1 + lcg(seed) % ((1 << bits) - 1))
    }

    /// Speeds and steps at the ends of the domain: 0, 1, 2, the largest speed 2³¹ and its
    /// neighbours, and steps that divide them or do not.
    const EDGES: [u64; 10] = [
        0,
        1,
        2,
        3,
        (1 << 16) - 1,
        1 << 16,
        (1 << 30) + 1,
        (1 << 31) - 2,
        (1 << 31) - 1,
        1 << 31,
    ];

    #[test]
    fn stop_distance_is_its_sum_on_small_speeds() {
        // Every speed up to 3000 for every step up to 48: the code, the sum and L1–L4; L5 for
        // every pair of speeds up to 400.
        for a in 1..=48u64 {
            for v in 0..=3000u64 {
                let s = stop_distance(v, a);
                assert_eq!(s, sum_of_terms(v, a), "S({v}) for a = {a}");
                if v <= a {
                    assert_eq!(s, v, "L1 at v = {v}, a = {a}");
                } else {
                    assert_eq!(s, v + stop_distance(v - a, a), "L2 at v = {v}, a = {a}");
                    assert!(s + a >= 2 * v, "L4 at v = {v}, a = {a}");
                }
                if v == a {
                    assert_eq!(s, v + stop_distance(0, a), "L2 at v = a = {a}");
                }
                assert!(stop_distance(v + 1, a) >= s, "L3 at v = {v}, a = {a}");
                if v <= 400 {
                    for w in 0..=v.saturating_sub(a) {
                        if w + a <= v {
                            assert!(s >= v + stop_distance(w, a), "L5 at {v}, {w}, a = {a}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn stop_distance_is_exact_up_to_2_31() {
        // The ends of the domain, then a million random pairs, against the 128-bit closed form:
        // no saturation anywhere in v ≤ 2³¹, 1 ≤ a < 2³¹.
        let mut pairs = Vec::new();
        for &v in &EDGES {
            for &a in EDGES.iter().chain(&[v.saturating_sub(1), v + 1]) {
                if (1..1 << 31).contains(&a) {
                    pairs.push((v, a));
                }
            }
        }
        let mut seed = 0x5EED_0020;
        for i in 0..1_000_000u64 {
            pairs.push(speed_and_step(&mut seed, i));
        }
        for (v, a) in pairs {
            let s = stop_distance(v, a);
            assert_eq!(u128::from(s), closed_form(v, a), "S({v}) for a = {a}");
            assert!(s < 1 << 63, "S({v}) for a = {a} stays below 2^63");
        }
        // The largest: a = 1, v = 2³¹.
        assert_eq!(stop_distance(1 << 31, 1), (1 << 61) + (1 << 30));
    }

    /// The lemma of `toward_ahead` at one point, with S computed by `s` (a reference): within
    /// [max(u − a, 0), u + a], S(w) ≤ d, and the largest such speed.
    fn check_toward_ahead(u: u64, d: u64, a: u64, s: impl Fn(u64) -> u128) {
        let w = toward_ahead(u as i64, d, a as i64);
        let low = u.saturating_sub(a);
        assert!(w >= 0, "u = {u}, d = {d}, a = {a}: w = {w}");
        let w = w as u64;
        assert!(w >= low && w <= u + a, "u = {u}, d = {d}, a = {a}: w = {w}");
        assert!(
            s(w) <= u128::from(d),
            "u = {u}, d = {d}, a = {a}: S({w}) > d"
        );
        assert!(
            w == u + a || s(w + 1) > u128::from(d),
            "u = {u}, d = {d}, a = {a}: {w} is not the largest"
        );
    }

    #[test]
    fn toward_ahead_lemma_on_small_axes() {
        // Every step up to 12, every speed up to 150, every distance from the least the lemma
        // allows (S(max(u − a, 0))) to past S(u + a): the whole range where the answer changes.
        for a in 1..=12u64 {
            for u in 0..=150u64 {
                let from = sum_of_terms(u.saturating_sub(a), a);
                for d in from..=sum_of_terms(u + a, a) + a + 2 {
                    check_toward_ahead(u, d, a, |x| u128::from(sum_of_terms(x, a)));
                }
            }
        }
    }

    #[test]
    fn toward_ahead_lemma_at_full_range() {
        // Speeds up to 2³¹ and steps up to 2³¹ − 1, at the ends and at random, with distances at
        // and around S(x) for x across [max(u − a, 0), u + a]: against the 128-bit closed form.
        let mut cases = Vec::new();
        for &u in &EDGES {
            for &a in &EDGES {
                if (1..1 << 31).contains(&a) {
                    cases.push((u, a));
                }
            }
        }
        let mut seed = 0x5EED_7041;
        for i in 0..200_000u64 {
            cases.push(speed_and_step(&mut seed, i));
        }
        for (n, (u, a)) in cases.into_iter().enumerate() {
            let s = |x: u64| closed_form(x, a);
            let low = u.saturating_sub(a);
            let span = u + a - low;
            let picks = [
                low,
                u,
                u + a,
                low + span / 2,
                low + lcg(&mut seed) % (span + 1),
            ];
            for (i, &x) in picks.iter().enumerate() {
                let at = s(x);
                for delta in [-1i128, 0, 1, (n + i) as i128 % 97] {
                    let d = at as i128 + delta;
                    if d >= s(low) as i128 && d <= u64::MAX as i128 {
                        check_toward_ahead(u, d as u64, a, s);
                    }
                }
            }
        }
    }

    /// The move of lemma A by its statement, in exact 128-bit sub-steps: (the new exact
    /// position, the velocity that carried on).
    fn move_by_statement(p: i32, f: u16, v: i32, t: i32, lo: i32, hi: i32) -> (i128, i64) {
        let x = |step: i32| i128::from(step) * 1000;
        let (e, g, low, high) = (x(p) + i128::from(f), x(t), x(lo), x(hi));
        let e1 = e + i128::from(v);
        let v = i64::from(v);
        if v > 0 && e <= g {
            if e1 >= g {
                (g, 0)
            } else {
                (e1, v)
            }
        } else if v > 0 {
            if e1 <= high {
                (e1, v)
            } else if e <= high {
                (high, 0)
            } else {
                (e, 0)
            }
        } else if v < 0 && e >= g {
            if e1 <= g {
                (g, 0)
            } else {
                (e1, v)
            }
        } else if v < 0 {
            if e1 >= low {
                (e1, v)
            } else if e >= low {
                (low, 0)
            } else {
                (e, 0)
            }
        } else {
            (e, 0)
        }
    }

    fn check_advance(p: i32, f: u16, v: i32, t: i32, lo: i32, hi: i32) {
        let (p2, f2, moving) = advance(p, f, v, t, lo, hi);
        let (e2, carried) = move_by_statement(p, f, v, t, lo, hi);
        let case = (p, f, v, t, lo, hi);
        assert!(f2 < 1000, "{case:?}: remainder {f2}");
        assert_eq!(
            i128::from(sub_steps(p2, f2)),
            e2,
            "{case:?}: exact position"
        );
        assert_eq!(moving, carried, "{case:?}: velocity carried on");
    }

    #[test]
    fn advance_is_its_statement_on_small_travels() {
        // Every travel and target within ±3 steps, every start within ±4 steps (outside the
        // travel too) at five remainders, every speed within ±5000 sub-steps per tick.
        for lo in -3..=3 {
            for hi in lo + 1..=3 {
                for t in lo..=hi {
                    for p in -4..=4 {
                        for f in [0, 1, 500, 998, 999] {
                            for v in -5000..=5000 {
                                check_advance(p, f, v, t, lo, hi);
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn advance_is_its_statement_at_full_range() {
        // The ends of i32 for the position, the bounds and the speed, then two million random
        // cases, many of them with the start, the target and the bounds a few steps apart.
        let ends = [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
        for &p in &ends {
            for &v in &ends {
                for &lo in &ends {
                    for &hi in &ends {
                        if lo < hi {
                            for t in [lo, hi, lo / 2 + hi / 2] {
                                for f in [0, 999] {
                                    check_advance(p, f, v, t, lo, hi);
                                }
                            }
                        }
                    }
                }
            }
        }
        let mut seed = 0x5EED_00A0;
        let mut any = |near: i32| {
            let r = lcg(&mut seed);
            if r.is_multiple_of(2) {
                r as i32
            } else {
                near.wrapping_add((r >> 32) as i32 % 8)
            }
        };
        for _ in 0..2_000_000 {
            let lo = any(0);
            let hi = any(lo);
            let t = any(lo);
            let p = any(t);
            let v = any(0);
            let f = (any(0) as u32 % 1000) as u16;
            let (lo, hi) = (lo.min(hi), lo.max(hi));
            if lo < hi {
                check_advance(p, f, v, t.clamp(lo, hi), lo, hi);
            }
        }
    }
}
