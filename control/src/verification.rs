//! Kani harnesses for the control crate, each with a `cargo test` twin driving the same body.
//!
//! Properties: PID and PI outputs and integrators stay within their bounds for every state that
//! satisfies the invariant and every input (an inductive argument: one step from any valid state);
//! the rate limiter never moves more than its step and never overshoots; kinematics, ADC scaling,
//! bridge mapping and speed estimation never panic or overflow, and the bridge never drives both
//! high sides; the position profile keeps the axis within its travel and never past its target,
//! its speed within the cap, and its velocity change within `accel_step` except where the cap or
//! a stop on the target or a limit forces it, and no such stop from a state the profile planned
//! for the same target (with the stopping distance, the move and the velocity chooser by the
//! lemmas `proofs/REPORT.md` proves in writing: `stand_in`).

use crate::bridge::bridge_compare;
use crate::kinematics::{DiffDrive, KinematicsError, Twist};
use crate::pid::{AntiWindup, CurrentPi, Pid, PidGains};
use crate::profile::{
    toward, toward_gives, toward_needs, Position, ProfileLimits, Trapezoid, Travel,
};
use crate::rate::RateLimiter;
use crate::sense::{adc_to_amps, SpeedEstimator};
use crate::{within, Q};
use statemachine::harness::Source;
use statemachine::{assume, check, cover, fail};

fn q(src: &mut impl Source) -> Q {
    Q::from_bits(src.i32())
}

fn gains(src: &mut impl Source) -> PidGains {
    PidGains {
        kp: q(src),
        ki_dt: q(src),
        kd_dt: q(src),
        out_limit: q(src),
        i_limit: q(src),
        anti_windup: if src.bool() {
            AntiWindup::Conditional
        } else {
            AntiWindup::ClampOnly
        },
    }
}

/// P-8: PID: from any valid state, one step keeps |u| ≤ out_limit and |i| ≤ i_limit.
pub fn pid_bounded(src: &mut impl Source) {
    let g = gains(src);
    assume!(src, g.is_valid());
    let integ = q(src);
    assume!(src, within(integ, g.i_limit));
    let prev = q(src);
    let mut pid = Pid::from_parts(g, integ, prev);
    let (r, y) = (q(src), q(src));
    let u = pid.step(r, y);
    check!(
        within(u, g.out_limit),
        "P-8: the PID output stays within its limit"
    );
    check!(
        pid.is_valid(),
        "P-8: the PID state stays valid (integrator within its limit)"
    );
    cover!(
        src,
        u == g.out_limit && u > Q::ZERO,
        "output saturated high"
    );
    cover!(
        src,
        u == g.out_limit.saturating_neg() && u < Q::ZERO,
        "output saturated low"
    );
    cover!(
        src,
        g.anti_windup == AntiWindup::Conditional
            && pid.integrator() == integ
            && g.ki_dt != Q::ZERO
            && r != y,
        "anti-windup held the integrator"
    );
    cover!(
        src,
        pid.integrator() == g.i_limit && g.i_limit > Q::ZERO,
        "integrator at its limit"
    );
}

/// P-9: Current PI: |duty| ≤ min(out_limit, 1) from any valid state.
pub fn current_pi_bounded(src: &mut impl Source) {
    let g = gains(src);
    assume!(src, g.is_valid());
    let mut pi = CurrentPi::new(g);
    let (r, y) = (q(src), q(src));
    let d1 = pi.step(r, y);
    let d2 = pi.step(q(src), q(src));
    let lim = pi.inner().gains().out_limit;
    check!(
        lim <= Q::ONE,
        "P-9: the current PI's duty limit is at most 1"
    );
    check!(
        within(d1, lim) && within(d2, lim),
        "P-9: both duties stay within the limit"
    );
    check!(
        pi.inner().is_valid(),
        "P-9: the current PI's state stays valid"
    );
    cover!(src, d2 == Q::ONE, "full positive duty");
    cover!(src, d2 > Q::ZERO && d2 < lim, "unsaturated duty");
}

/// P-10: Rate limiter: |Δ| ≤ max_step, never past the target, exact when within one step.
pub fn rate_limiter_bounded(src: &mut impl Source) {
    let step = q(src);
    let start = q(src);
    let mut r = RateLimiter::new(step, start);
    let target = q(src);
    let next = r.step(target);
    let d = i64::from(next.to_bits()).wrapping_sub(i64::from(start.to_bits()));
    let lim = i64::from(r.max_step().to_bits());
    check!(
        d <= lim && d >= lim.wrapping_neg(),
        "P-10: the limiter moves by at most its step"
    );
    let (lo, hi) = if start <= target {
        (start, target)
    } else {
        (target, start)
    };
    check!(
        next >= lo && next <= hi,
        "P-10: the limiter never passes the target"
    );
    let gap = i64::from(target.to_bits()).wrapping_sub(i64::from(start.to_bits()));
    if gap.unsigned_abs() <= lim.unsigned_abs() {
        check!(
            next == target,
            "P-10: within one step of the target the limiter lands on it"
        );
    }
    cover!(src, next == target && start != target, "reached the target");
    cover!(src, next != target, "limited by the step");
}

/// Geometries (wheelbase, wheel radius), m: four real ones, from a small AMR to a pallet mover, and
/// the two extreme corners of the accepted range, where the ratios 1/r, L/(2r) and r/L are largest.
/// The conversions are checked for each of them with fully symbolic speeds; [`geometry_checked`]
/// covers every other geometry's construction. (With a symbolic geometry every conversion would
/// carry 64-bit division and multiplication circuits of two unknowns, which the solver does not
/// finish.)
const GEOMETRIES: [(Q, Q); 6] = [
    (Q::lit("0.42"), Q::lit("0.075")),
    (Q::lit("0.3"), Q::lit("0.05")),
    (Q::lit("0.6"), Q::lit("0.1")),
    (Q::lit("1.2"), Q::lit("0.2")),
    (Q::const_from_int(64), Q::lit("0.001")),
    (Q::lit("0.01"), Q::const_from_int(10)),
];

/// P-12: Kinematics conversions never panic or overflow for any twist and any wheel speeds; zero maps to
/// zero, a straight twist gives equal wheel speeds, equal wheel speeds give no yaw.
pub fn kinematics_total(src: &mut impl Source) {
    for &(base, radius) in &GEOMETRIES {
        let Ok(k) = DiffDrive::new(base, radius) else {
            fail!("P-12: a listed geometry was refused");
        };
        let t = Twist {
            v: q(src),
            omega: q(src),
        };
        let [l, r] = k.inverse(t);
        let _ = k.forward(l, r);
        let _ = k.forward(q(src), q(src));
        let [zl, zr] = k.inverse(Twist {
            v: Q::ZERO,
            omega: Q::ZERO,
        });
        check!(
            zl == Q::ZERO,
            "P-12: zero twist gives a zero left wheel speed"
        );
        check!(
            zr == Q::ZERO,
            "P-12: zero twist gives a zero right wheel speed"
        );
        let [sl, sr] = k.inverse(Twist {
            v: t.v,
            omega: Q::ZERO,
        });
        check!(sl == sr, "P-12: a straight twist gives equal wheel speeds");
        check!(
            k.forward(l, l).omega == Q::ZERO,
            "P-12: equal wheel speeds give no yaw"
        );
        cover!(src, l != r, "turning twist");
        cover!(src, l == Q::MAX, "a wheel speed saturated");
    }
}

/// P-12: Construction of any geometry never panics, refuses a radius outside 1 mm ..= 10 m or a wheelbase
/// outside 1 cm ..= 64 m, and accepts every geometry inside both ranges.
pub fn geometry_checked(src: &mut impl Source) {
    // Any value, or (for the twin's sake: random bits rarely land in range) one near the ranges.
    fn geometry(src: &mut impl Source) -> Q {
        if src.bool() {
            q(src)
        } else {
            src.speed_within(Q::const_from_int(120))
        }
    }
    let base = geometry(src);
    let radius = geometry(src);
    const RADIUS: (Q, Q) = (Q::lit("0.001"), Q::const_from_int(10));
    const BASE: (Q, Q) = (Q::lit("0.01"), Q::const_from_int(64));
    let radius_ok = radius >= RADIUS.0 && radius <= RADIUS.1;
    let base_ok = base >= BASE.0 && base <= BASE.1;
    let k = DiffDrive::new(base, radius);
    match k {
        Ok(k) => {
            check!(
                radius_ok && base_ok,
                "P-12: only a geometry within the ranges is accepted"
            );
            check!(
                k.wheelbase() == base,
                "P-12: an accepted geometry keeps its wheelbase"
            );
            check!(
                k.wheel_radius() == radius,
                "P-12: an accepted geometry keeps its wheel radius"
            );
        }
        Err(KinematicsError::WheelRadius) => check!(
            !radius_ok,
            "P-12: a wheel radius refused only outside its range"
        ),
        Err(KinematicsError::Wheelbase) => check!(
            radius_ok && !base_ok,
            "P-12: a wheelbase refused only outside its range, after a good radius"
        ),
    }
    if radius_ok && base_ok {
        check!(k.is_ok(), "P-12: a geometry within the ranges is accepted");
    }
    cover!(src, k.is_ok(), "geometry accepted");
    cover!(
        src,
        k == Err(KinematicsError::WheelRadius),
        "radius refused"
    );
    cover!(
        src,
        k == Err(KinematicsError::Wheelbase),
        "wheelbase refused"
    );
}

/// P-11: Bridge mapping: both compares ≤ ARR and at most one non-zero (never both high sides on).
pub fn bridge_compare_safe(src: &mut impl Source) {
    let duty = q(src);
    let arr = src.u16();
    let c = bridge_compare(duty, arr);
    check!(
        c.a <= arr && c.b <= arr,
        "P-11: both compares stay within ARR"
    );
    check!(c.a == 0 || c.b == 0, "P-11: never both high sides on");
    if duty > Q::ZERO {
        check!(
            c.b == 0,
            "P-11: a positive duty leaves the reverse compare at zero"
        );
    }
    if duty < Q::ZERO {
        check!(
            c.a == 0,
            "P-11: a negative duty leaves the forward compare at zero"
        );
    }
    cover!(src, c.a == arr && arr > 0, "full forward");
    cover!(src, c.b > 0, "reverse");
}

/// P-12: ADC scaling never panics and |i| ≤ 4095·|gain| (saturating at the Q16.16 range).
pub fn adc_scaling_bounded(src: &mut impl Source) {
    let counts = src.u16();
    let offset = src.u16();
    let gain = q(src);
    assume!(
        src,
        gain.unsigned_abs() <= fixed::types::U16F16::from_num(8)
    );
    let i = adc_to_amps(counts, offset, gain);
    let bound = gain.unsigned_abs().saturating_mul_int(4095);
    check!(
        i.unsigned_abs() <= bound,
        "P-12: the scaled ADC current stays within its bound"
    );
    cover!(src, i > Q::ZERO, "positive current");
    cover!(src, i < Q::ZERO, "negative current");
}

/// P-12: Speed estimator: any counter sequence, no panic, estimate = scale × window delta.
pub fn speed_estimator_total(src: &mut impl Source) {
    let scale = q(src);
    let mut e = SpeedEstimator::new(src.u16(), scale);
    for _ in 0..3 {
        let s = e.update(src.u16());
        check!(
            s.unsigned_abs() <= scale.unsigned_abs().saturating_mul_int(32_768),
            "P-12: the estimated speed stays within its bound"
        );
    }
    cover!(src, e.total() != 0, "wheel moved");
}

/// Any value, `base` itself, or (for the twins: random bits rarely land close to each other) a
/// value up to 128 Q16.16 steps from it. Under Kani the first choice alone is every value.
fn near(src: &mut impl Source, base: Q) -> Q {
    // Under Kani the other two choices are values the first already takes, and they would give
    // the solver a selector and a saturating addition to carry through every formula.
    if cfg!(kani) {
        return q(src);
    }
    match src.below(3) {
        0 => q(src),
        1 => base,
        _ => base.saturating_add(Q::from_bits(i32::from(src.u8() as i8))),
    }
}

/// True if the profile's exact position is at or below `x` (exact positions compare as (step,
/// sub-step) pairs, which spares the solver the multiplication by 1000).
fn at_or_below(p: &Trapezoid, x: Position) -> bool {
    p.position() < x || (p.position() == x && p.remainder() == 0)
}

/// True if the profile's exact position is `x`.
fn on(p: &Trapezoid, x: Position) -> bool {
    p.position() == x && p.remainder() == 0
}

/// Profile limits: any bits, with (for the twins) a travel often only a few steps wide and an
/// `accel_step` often a few bits; callers assume [`ProfileLimits::is_valid`].
fn profile_limits(src: &mut impl Source) -> ProfileLimits {
    let lo = q(src);
    let hi = near(src, lo);
    // Under Kani any bits, which include the twins' small steps.
    let accel_step = if cfg!(kani) || src.bool() {
        q(src)
    } else {
        Q::from_bits(i32::from(src.u16()))
    };
    ProfileLimits {
        travel: Travel { lo, hi },
        accel_step,
    }
}

/// A profile state and a target: any bits, with (for the twins) the position often near a travel
/// limit, the target near the position, and the velocity often small or exactly the distance to
/// the target; callers assume [`Trapezoid::is_valid`].
fn profile_case(src: &mut impl Source, lim: &ProfileLimits) -> (Trapezoid, Position) {
    // Under Kani any bits for each part (the callers assume the state valid, which bounds the
    // remainder): the twins' choices below are values among these, and as choices they would
    // put a selector, a remainder by 1000 and two multiplications into every formula.
    if cfg!(kani) {
        return (Trapezoid::from_parts(q(src), src.u16(), q(src)), q(src));
    }
    let edge = if src.bool() {
        lim.travel.lo
    } else {
        lim.travel.hi
    };
    let pos = near(src, edge);
    let frac = if src.bool() {
        0
    } else {
        src.u16().checked_rem(1000).unwrap_or(0)
    };
    let target = near(src, pos);
    // The distance to the target in sub-steps, from the (step, sub-step) pairs rather than
    // `sub_steps`, which P-20's harness stands in for: it only picks a velocity.
    let to_target = i64::from(lim.travel.clamp(target).to_bits())
        .wrapping_sub(i64::from(pos.to_bits()))
        .wrapping_mul(1000)
        .wrapping_sub(i64::from(frac));
    let vel = match src.below(3) {
        0 => q(src),
        1 => Q::from_bits(i32::try_from(to_target).unwrap_or(0)),
        _ => Q::from_bits(
            i32::from(src.u8() as i8).wrapping_mul(lim.accel_step.to_bits().clamp(1, 1 << 16)),
        ),
    };
    (Trapezoid::from_parts(pos, frac, vel), target)
}

/// INV-20: Profile, property 1 (and no panic or overflow for any input): from any valid state, toward any
/// target at any cap, the new position is within the travel and never passes the target clamped
/// into it — a position at or below it stays at or below it, and symmetrically.
pub fn profile_stays_within_travel(src: &mut impl Source) {
    let lim = profile_limits(src);
    assume!(src, lim.is_valid());
    let (before, target) = profile_case(src, &lim);
    assume!(src, before.is_valid(&lim));
    let cap = near(src, before.velocity().saturating_abs());
    let mut p = before;
    let pos = p.step(target, cap, &lim);
    let (lo, hi) = (lim.travel.lo, lim.travel.hi);
    let t = lim.travel.clamp(target);
    check!(
        pos == p.position(),
        "INV-20: profile step returns the new position"
    );
    check!(
        pos >= lo && pos <= hi,
        "INV-20: profile position stays within travel"
    );
    check!(
        p.is_valid(&lim),
        "INV-20: profile position stays within travel"
    );
    // At or below the target before → at or below after; at or above (position ≥ t, as t has no
    // sub-steps) → at or above.
    if at_or_below(&before, t) {
        check!(
            at_or_below(&p, t) && pos <= t,
            "INV-20: profile never passes the target from below"
        );
    }
    if before.position() >= t {
        check!(
            pos >= t,
            "INV-20: profile never passes the target from above"
        );
    }
    let moved = p.position() != before.position() || p.remainder() != before.remainder();
    cover!(src, on(&p, t) && !on(&before, t), "arrived at the target");
    cover!(
        src,
        (on(&p, lo) || on(&p, hi)) && !on(&p, t) && moved,
        "stopped at a travel limit"
    );
    cover!(
        src,
        t != target && moved,
        "moving toward a target outside the travel"
    );
}

/// INV-20: Profile, property 2: from any valid state, toward any target at any cap, |v| ≤ max(cap, 0)
/// after the step, and the velocity changes by at most `accel_step` unless
/// - the cap forced it: then |v_new| = cap < |v_old|, same sign (the cap only ever slows the axis);
/// - the axis stopped on the target (reaching or passing it): on it, v_new = 0;
/// - the axis stopped on a travel limit (passing it): on it and restarting from rest,
///   |v_new| ≤ `accel_step`.
///
/// The stops happen only when the target was moved inside the stopping distance (or a state was
/// made up): [`profile_smooth_for_fixed_target`] checks that a planned state never meets them.
pub fn profile_speed_within_cap(src: &mut impl Source) {
    let lim = profile_limits(src);
    assume!(src, lim.is_valid());
    let (before, target) = profile_case(src, &lim);
    assume!(src, before.is_valid(&lim));
    let cap = near(src, before.velocity().saturating_abs());
    let mut p = before;
    p.step(target, cap, &lim);
    let (v0, v1) = (before.velocity(), p.velocity());
    let c = cap.max(Q::ZERO);
    check!(within(v1, c), "INV-20: profile speed stays within the cap");
    let a = lim.accel_step;
    let dv = i64::from(v1.to_bits()).wrapping_sub(i64::from(v0.to_bits()));
    let smooth = dv.unsigned_abs() <= u64::from(a.unsigned_abs().to_bits());
    let forced = v1.unsigned_abs() == c.unsigned_abs()
        && v1.unsigned_abs() < v0.unsigned_abs()
        && (v1 == Q::ZERO || (v1 > Q::ZERO) == (v0 > Q::ZERO));
    let t = lim.travel.clamp(target);
    let (lo, hi) = (lim.travel.lo, lim.travel.hi);
    let stopped_on_target = on(&p, t) && v1 == Q::ZERO;
    let stopped_at_limit = (on(&p, lo) || on(&p, hi)) && within(v1, a);
    check!(
        smooth || forced || stopped_on_target || stopped_at_limit,
        "INV-20: profile velocity changes by at most accel_step unless the cap or a stop forces it"
    );
    let toward = (at_or_below(&before, t) && !on(&before, t) && v0 > Q::ZERO)
        || (before.position() >= t && !on(&before, t) && v0 < Q::ZERO);
    cover!(
        src,
        v1.unsigned_abs() > v0.unsigned_abs() && (v1 > Q::ZERO) == (v0 > Q::ZERO),
        "accelerating"
    );
    cover!(
        src,
        v1 == v0 && v1.unsigned_abs() == c.unsigned_abs() && c > Q::ZERO,
        "cruising at the cap"
    );
    cover!(src, forced && !smooth, "cap forced a deceleration");
    cover!(
        src,
        toward && !on(&p, t) && v1.unsigned_abs() < v0.unsigned_abs() && within(v0, c),
        "decelerating near the target"
    );
    cover!(
        src,
        stopped_on_target && !smooth,
        "stopped on a target moved too close"
    );
}

/// INV-20: Profile, the velocity chooser (`profile::toward`, its contract): from any speed |u| ≤ 2³¹
/// toward a target any distance ahead, with any `accel_step` 1 ≤ a < 2³¹, the speed chosen for the
/// next tick is within u ± a, and 0 for an axis at rest on its target. The two harnesses of the
/// step above use this contract in place of the function (`kani::stub_verified`): their properties
/// hold for every speed within u ± a, so they need not solve the stopping distances.
pub fn toward_within_a_step(src: &mut impl Source) {
    let a = i64::from(src.i32());
    let v = i64::from(src.i32());
    let u = if src.bool() { v } else { v.wrapping_neg() };
    let d = if src.bool() {
        u64::from(src.u32()) << 32 | u64::from(src.u32())
    } else {
        u64::from(src.u16())
    };
    assume!(src, toward_needs(u, a));
    let w = toward(u, d, a);
    check!(
        toward_gives(u, d, a, w),
        "INV-20: profile velocity chooser stays within accel_step of the speed, at rest on the target"
    );
    cover!(src, w == u + a && u > 0, "accelerating toward the target");
    cover!(src, w == u - a && u > 0, "braking by a full step");
    cover!(
        src,
        w > u - a && w < u + a && u > 0,
        "a speed between the two"
    );
    cover!(src, u == 0 && d == 0, "at rest on the target");
}

/// P-20: Profile, nominal operation: from a valid state that can stop before the target and the travel
/// limits ([`Trapezoid::can_stop`], the states the profile plans), a step toward the same target at
/// any cap changes the velocity by at most `accel_step` unless the cap forces it (no abrupt stop on
/// the target or a limit, arrival included), and the new state can again stop: by induction a
/// profile started at rest meets neither stop until its target moves inside the stopping distance.
///
/// One run takes the states moving down (`backward`: velocity below 0) or the others (at rest or
/// moving up): the two Kani harnesses take one half each, which together are every state (two
/// smaller formulas, and no single harness of over two minutes to end the suite on:
/// `proofs/REPORT.md`, "Kani suite time"); the twin runs both. Each half meets every cover: an
/// axis of either direction can arrive, decelerate toward its target or brake away from it.
pub fn profile_smooth_for_fixed_target(src: &mut impl Source, backward: bool) {
    let lim = profile_limits(src);
    assume!(src, lim.is_valid());
    let (before, target) = profile_case(src, &lim);
    assume!(src, before.is_valid(&lim));
    assume!(src, before.can_stop(target, &lim));
    assume!(src, (before.velocity() < Q::ZERO) == backward);
    let cap = near(src, before.velocity().saturating_abs());
    let mut p = before;
    p.step(target, cap, &lim);
    let (v0, v1) = (before.velocity(), p.velocity());
    let c = cap.max(Q::ZERO);
    let dv = i64::from(v1.to_bits()).wrapping_sub(i64::from(v0.to_bits()));
    let a = i64::from(lim.accel_step.to_bits());
    let forced = v1.unsigned_abs() == c.unsigned_abs() && v1.unsigned_abs() < v0.unsigned_abs();
    check!(
        dv.unsigned_abs() <= a.unsigned_abs() || forced,
        "P-20: profile velocity changes by at most accel_step unless the cap forces it"
    );
    check!(
        p.can_stop(target, &lim),
        "P-20: profile can still stop before the target and the limits"
    );
    let t = lim.travel.clamp(target);
    let (below, above) = (before.position() < t, !at_or_below(&before, t));
    cover!(
        src,
        on(&p, t) && !on(&before, t) && v1 == Q::ZERO,
        "arrived at the target"
    );
    cover!(
        src,
        ((below && v0 > Q::ZERO) || (above && v0 < Q::ZERO))
            && v1.unsigned_abs() < v0.unsigned_abs()
            && !forced,
        "decelerating near the target"
    );
    cover!(
        src,
        ((below && v0 < Q::ZERO) || (above && v0 > Q::ZERO)) && !forced,
        "braking away from the target"
    );
}

/// The stand-ins of P-20's harness: the stopping distance S as an uninterpreted function that keeps
/// the facts `proofs/REPORT.md` ("P-20") proves of the real one, `toward_ahead` by its lemma T,
/// the move `advance` by its lemma A, and the exact position `sub_steps` as an uninterpreted
/// function of its pair. A property proven with them holds for every function with those facts, so
/// for the real ones.
///
/// The facts of S, for speeds v, v' (sub-steps per tick) and one `accel_step` a ≥ 1:
/// - L1: S(v) = v for v ≤ a;
/// - L2: S(v) = v + S(v − a) for v ≥ a;
/// - L3: S is monotone;
/// - L4: S(v) ≥ 2v − a for v ≥ a (from L2 and S(v − a) ≥ v − a);
/// - L5: S(v) ≥ v + S(v') for v' + a ≤ v (from L2 and L3): the stopping distance left after one
///   tick at v covers any speed a full step or more below it.
///
/// The stand-in checks the domain of each use: the real `stop_distance` is exact for v ≤ 2³¹, the
/// facts are proven for v ≤ 2³², `toward_ahead`'s lemma needs S(max(u − a, 0)) ≤ d.
// Reached only through `#[kani::stub]` paths, which rustc does not count as uses.
#[cfg(kani)]
#[allow(dead_code)]
pub(crate) mod stand_in {
    use crate::profile::{moved, toward_needs};
    use statemachine::check;

    /// How many points the harness asks about: S(v) before the step, S(max(u − a, 0)) and S(w)
    /// in `toward_ahead`, S(v') after it.
    const POINTS: usize = 4;

    /// The points asked so far: (v, a, S(v)).
    static mut ASKED: [Option<(u64, u64, u64)>; POINTS] = [None; POINTS];

    /// Any value for S(v) consistent with the facts L1–L5 and with every point asked before.
    #[allow(unsafe_code)]
    fn uninterpreted(v: u64, a: u64) -> u64 {
        check!(
            a >= 1 && a <= i32::MAX as u64 && v <= 1 << 32,
            "P-20: the stopping distance is asked only where its facts are proven"
        );
        // SAFETY: Kani runs a harness on one thread, from a fresh program state each time; no
        // reference to the static outlives this call.
        let asked = unsafe { &mut *core::ptr::addr_of_mut!(ASKED) };
        let s: u64 = kani::any();
        // L1; L4 (the bounds keep 2v − a within u64).
        if v <= a {
            kani::assume(s == v);
        } else {
            kani::assume(s >= v.wrapping_mul(2).wrapping_sub(a));
        }
        let mut free = None;
        for i in 0..POINTS {
            match asked[i] {
                Some((v2, a2, s2)) if a2 == a => {
                    // The same point, L3, L2 and L5 in both directions.
                    kani::assume(v != v2 || s == s2);
                    kani::assume(v >= v2 || s <= s2);
                    kani::assume(v <= v2 || s >= s2);
                    kani::assume(v != v2.wrapping_add(a) || s == v.wrapping_add(s2));
                    kani::assume(v2 != v.wrapping_add(a) || s2 == v2.wrapping_add(s));
                    kani::assume(v < v2.wrapping_add(a) || s >= v.wrapping_add(s2));
                    kani::assume(v2 < v.wrapping_add(a) || s2 >= v2.wrapping_add(s));
                }
                Some(_) => {}
                None => {
                    if free.is_none() {
                        free = Some(i);
                    }
                }
            }
        }
        match free.and_then(|i| asked.get_mut(i)) {
            Some(slot) => *slot = Some((v, a, s)),
            None => check!(
                false,
                "P-20: the stopping-distance stand-in remembers every point asked"
            ),
        }
        s
    }

    /// Stands for `profile::advance` by lemma A: the move as its statement, in exact sub-steps
    /// (every exact position by `sub_steps`, the one expression the step and the state's `exact`
    /// use). A stop returns the bound's or the start's own (step, sub-steps); a free move returns
    /// `profile::moved`'s pair, which lemma A proves exact (assumed here: the solver cannot link
    /// the division by 1000 with the multiplications).
    pub(crate) fn advance(p: i32, f: u16, v: i32, t: i32, lo: i32, hi: i32) -> (i32, u16, i64) {
        check!(
            u64::from(f) < 1000 && lo <= t && t <= hi,
            "P-20: the move is asked about a remainder below a step and a target within the travel"
        );
        let (e, g) = (sub_steps(p, f), sub_steps(t, 0));
        let (low, high) = (sub_steps(lo, 0), sub_steps(hi, 0));
        let e1 = e.wrapping_add(i64::from(v));
        let (q2, r2) = moved(i64::from(p), i64::from(f), v);
        let free = (
            i32::try_from(q2).unwrap_or(p),
            u16::try_from(r2).unwrap_or(0),
        );
        // Where the move is free lemma A proves the pair exact, in range and below a step.
        let stop = |at: (i32, u16)| (at.0, at.1, 0);
        let go = || {
            let e2 = sub_steps(free.0, free.1);
            kani::assume(i64::from(free.0) == q2 && i64::from(free.1) == r2);
            kani::assume(r2 < 1000 && e2 == e1);
            // Three identities of wrapping arithmetic, true of every value, in the terms the step
            // and `can_stop` compute: the room left after the move is the room before less v.
            let v = i64::from(v);
            kani::assume(g.wrapping_sub(e2) == g.wrapping_sub(e).wrapping_sub(v));
            kani::assume(high.wrapping_sub(e2) == high.wrapping_sub(e).wrapping_sub(v));
            kani::assume(e2.wrapping_sub(low) == e.wrapping_sub(low).wrapping_add(v));
            (free.0, free.1, v)
        };
        if v > 0 {
            if e <= g {
                if e1 >= g {
                    stop((t, 0))
                } else {
                    go()
                }
            } else if e1 > high {
                stop(if e <= high { (hi, 0) } else { (p, f) })
            } else {
                go()
            }
        } else if v < 0 {
            if e >= g {
                if e1 <= g {
                    stop((t, 0))
                } else {
                    go()
                }
            } else if e1 < low {
                stop(if e >= low { (lo, 0) } else { (p, f) })
            } else {
                go()
            }
        } else {
            stop((p, f))
        }
    }

    /// How many exact positions the harness of P-20 computes: three in each `can_stop`, five in
    /// the move, two in the step (the harness of INV-20's property 2, the step alone, asks two).
    /// (`profile_case` and the covers compare (step, sub-step) pairs instead: each position asked
    /// adds a comparison with every one before it, and 18 positions took the harness about 40 %
    /// longer than these 13.)
    const POSITIONS: usize = 13;

    /// The exact positions asked so far: (step, sub-steps, sub-steps in all).
    static mut PLACED: [Option<(i32, u16, i64)>; POSITIONS] = [None; POSITIONS];

    /// Stands for `profile::sub_steps` (1000·p + f): an uninterpreted function of the pair. The
    /// same pair gives the same value, so the step, the state's `exact` and `can_stop` meet on one
    /// value (CaDiCaL could not show two multiplications by 1000 of equal inputs equal, lacking
    /// congruence closure), and every value is below 2⁴² in magnitude. Both hold of 1000·p + f
    /// for `f` < 1000; the step needs nothing else of it. Used by the harnesses of P-20 and of
    /// INV-20's property 2 (`verify_profile_speed_within_cap`).
    #[allow(unsafe_code)]
    pub(crate) fn sub_steps(p: i32, f: u16) -> i64 {
        check!(
            f < 1000,
            "INV-20/P-20: an exact position is asked only for a remainder below a step"
        );
        // SAFETY: as in `uninterpreted`.
        let placed = unsafe { &mut *core::ptr::addr_of_mut!(PLACED) };
        let x: i64 = kani::any();
        kani::assume(x.unsigned_abs() < 1 << 42);
        let mut free = None;
        for i in 0..POSITIONS {
            match placed[i] {
                Some((p2, f2, x2)) => {
                    kani::assume(p != p2 || f != f2 || x == x2);
                }
                None => {
                    if free.is_none() {
                        free = Some(i);
                    }
                }
            }
        }
        match free.and_then(|i| placed.get_mut(i)) {
            Some(slot) => *slot = Some((p, f, x)),
            None => check!(
                false,
                "INV-20/P-20: the exact-position stand-in remembers every position asked"
            ),
        }
        x
    }

    /// Stands for `profile::stop_distance`, which is exact (equal to S) for v ≤ 2³¹.
    pub(crate) fn stop_distance(v: u64, a: u64) -> u64 {
        check!(
            v <= 1 << 31,
            "P-20: the stopping distance is computed only for a speed it is exact for"
        );
        uninterpreted(v, a)
    }

    /// Stands for `profile::toward_ahead` by its lemma: for 0 ≤ u ≤ 2³¹, 1 ≤ a < 2³¹ and
    /// S(max(u − a, 0)) ≤ d, any w in [max(u − a, 0), u + a] with S(w) ≤ d.
    pub(crate) fn toward_ahead(u: i64, d: u64, a: i64) -> i64 {
        check!(
            u >= 0 && toward_needs(u, a),
            "P-20: toward_ahead is asked about a speed toward the target, within its domain"
        );
        let (ua, aa) = (u.unsigned_abs(), a.unsigned_abs());
        let low = ua.saturating_sub(aa);
        check!(
            uninterpreted(low, aa) <= d,
            "P-20: toward_ahead is asked only where braking by accel_step still stops in time"
        );
        let w: u64 = kani::any();
        kani::assume(w >= low && w <= ua.saturating_add(aa));
        kani::assume(uninterpreted(w, aa) <= d);
        i64::try_from(w).unwrap_or(i64::MAX)
    }
}

#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use statemachine::harness::KaniSource;

    #[kani::proof]
    #[kani::unwind(2)]
    fn verify_pid_bounded() {
        super::pid_bounded(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(2)]
    fn verify_current_pi_bounded() {
        super::current_pi_bounded(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(2)]
    fn verify_rate_limiter_bounded() {
        super::rate_limiter_bounded(&mut KaniSource);
    }
    // MiniSat (CBMC's default) rather than CaDiCaL: 7.8 s against 16.5 s on one build, 6.4 s
    // against 17.9 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(7)]
    #[kani::solver(minisat)]
    fn verify_kinematics_total() {
        super::kinematics_total(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(2)]
    fn verify_geometry_checked() {
        super::geometry_checked(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(2)]
    fn verify_bridge_compare_safe() {
        super::bridge_compare_safe(&mut KaniSource);
    }
    // Kissat (shipped with Kani) rather than CaDiCaL: 29 s against 44 s on one build, 26 s against
    // 40 s on another (REPORT.md, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(2)]
    #[kani::solver(kissat)]
    fn verify_adc_scaling_bounded() {
        super::adc_scaling_bounded(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(17)]
    fn verify_speed_estimator_total() {
        super::speed_estimator_total(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(2)]
    #[kani::stub_verified(crate::profile::toward)]
    fn verify_profile_stays_within_travel() {
        super::profile_stays_within_travel(&mut KaniSource);
    }
    // The step's distance to the target is the difference of two exact positions, each a
    // multiplication by 1000; where the move stopped the axis on its target the two are of equal
    // pairs, which CaDiCaL had to show equal bit by bit: the harness took 27 s to over 400 s
    // depending on the build. The property needs only that equal pairs give equal positions (an
    // axis at rest on its target is 0 away from it), which the uninterpreted stand-in keeps (the
    // stand-in's memory has room for the step's two positions; unwind 14 covers its scan).
    #[kani::proof]
    #[kani::unwind(14)]
    #[kani::stub_verified(crate::profile::toward)]
    #[kani::stub(crate::profile::sub_steps, super::stand_in::sub_steps)]
    fn verify_profile_speed_within_cap() {
        super::profile_speed_within_cap(&mut KaniSource);
    }
    #[kani::proof_for_contract(crate::profile::toward)]
    fn verify_toward_within_a_step() {
        super::toward_within_a_step(&mut KaniSource);
    }
    // The stopping distances multiply unknowns (the speed by the speed over accel_step), which
    // CBMC did not finish in 15 minutes. The harness takes S uninterpreted with the facts the step
    // needs, and `toward_ahead` by its lemma (`stand_in`); REPORT.md ("P-20") proves those of the
    // real functions in writing and the tests `stop_distance_*` and `toward_ahead_*` check them.
    #[kani::proof]
    #[kani::unwind(19)]
    #[kani::stub(crate::profile::stop_distance, super::stand_in::stop_distance)]
    #[kani::stub(crate::profile::toward_ahead, super::stand_in::toward_ahead)]
    #[kani::stub(crate::profile::advance, super::stand_in::advance)]
    #[kani::stub(crate::profile::sub_steps, super::stand_in::sub_steps)]
    fn verify_profile_smooth_for_fixed_target_forward() {
        super::profile_smooth_for_fixed_target(&mut KaniSource, false);
    }
    #[kani::proof]
    #[kani::unwind(19)]
    #[kani::stub(crate::profile::stop_distance, super::stand_in::stop_distance)]
    #[kani::stub(crate::profile::toward_ahead, super::stand_in::toward_ahead)]
    #[kani::stub(crate::profile::advance, super::stand_in::advance)]
    #[kani::stub(crate::profile::sub_steps, super::stand_in::sub_steps)]
    fn verify_profile_smooth_for_fixed_target_backward() {
        super::profile_smooth_for_fixed_target(&mut KaniSource, true);
    }
}

#[cfg(test)]
mod twins {
    use statemachine::harness::Twin;

    const CASES: u32 = 50_000;

    #[test]
    fn pid_bounded() {
        Twin::run(0xC0_01, CASES, super::pid_bounded).assert_covered(4);
    }
    #[test]
    fn current_pi_bounded() {
        Twin::run(0xC0_02, CASES, super::current_pi_bounded).assert_covered(2);
    }
    #[test]
    fn rate_limiter_bounded() {
        Twin::run(0xC0_03, CASES, super::rate_limiter_bounded).assert_covered(2);
    }
    #[test]
    fn kinematics_total() {
        Twin::run(0xC0_04, CASES, super::kinematics_total).assert_covered(2);
    }
    #[test]
    fn geometry_checked() {
        Twin::run(0xC0_0A, CASES, super::geometry_checked).assert_covered(3);
    }
    #[test]
    fn bridge_compare_safe() {
        Twin::run(0xC0_05, CASES, super::bridge_compare_safe).assert_covered(2);
    }
    #[test]
    fn adc_scaling_bounded() {
        Twin::run(0xC0_06, CASES, super::adc_scaling_bounded).assert_covered(2);
    }
    #[test]
    fn speed_estimator_total() {
        Twin::run(0xC0_07, CASES, super::speed_estimator_total).assert_covered(1);
    }
    #[test]
    fn toward_within_a_step() {
        Twin::run(0xC0_0E, CASES, super::toward_within_a_step).assert_covered(4);
    }
    #[test]
    fn profile_stays_within_travel() {
        Twin::run(0xC0_0B, CASES, super::profile_stays_within_travel).assert_covered(3);
    }
    #[test]
    fn profile_speed_within_cap() {
        Twin::run(0xC0_0C, CASES, super::profile_speed_within_cap).assert_covered(5);
    }
    #[test]
    fn profile_smooth_for_fixed_target() {
        // Ten times the cases: the proof rests on lemmas proven in writing, and only one case in
        // twenty passes the assumptions.
        for (seed, backward) in [(0xC0_0D, false), (0xC0_0F, true)] {
            Twin::run(seed, CASES * 10, |s| {
                super::profile_smooth_for_fixed_target(s, backward)
            })
            .assert_covered(3);
        }
    }
}
