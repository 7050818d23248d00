//! Kani harnesses for the control crate, each with a `cargo test` twin driving the same body.
//!
//! Properties: PID and PI outputs and integrators stay within their bounds for every state that
//! satisfies the invariant and every input (an inductive argument: one step from any valid state);
//! the rate limiter never moves more than its step and never overshoots; kinematics, ADC scaling,
//! bridge mapping and speed estimation never panic or overflow, and the bridge never drives both
//! high sides.

use crate::bridge::bridge_compare;
use crate::kinematics::{DiffDrive, KinematicsError, Twist};
use crate::pid::{AntiWindup, CurrentPi, Pid, PidGains};
use crate::rate::RateLimiter;
use crate::sense::{adc_to_amps, SpeedEstimator};
use crate::{within, Q};
use statemachine::harness::Source;
use statemachine::{assume, cover};

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

/// PID: from any valid state, one step keeps |u| ≤ out_limit and |i| ≤ i_limit.
pub fn pid_bounded(src: &mut impl Source) {
    let g = gains(src);
    assume!(src, g.is_valid());
    let integ = q(src);
    assume!(src, within(integ, g.i_limit));
    let prev = q(src);
    let mut pid = Pid::from_parts(g, integ, prev);
    let (r, y) = (q(src), q(src));
    let u = pid.step(r, y);
    assert!(within(u, g.out_limit));
    assert!(pid.is_valid());
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

/// Current PI: |duty| ≤ min(out_limit, 1) from any valid state.
pub fn current_pi_bounded(src: &mut impl Source) {
    let g = gains(src);
    assume!(src, g.is_valid());
    let mut pi = CurrentPi::new(g);
    let (r, y) = (q(src), q(src));
    let d1 = pi.step(r, y);
    let d2 = pi.step(q(src), q(src));
    let lim = pi.inner().gains().out_limit;
    assert!(lim <= Q::ONE);
    assert!(within(d1, lim) && within(d2, lim));
    assert!(pi.inner().is_valid());
    cover!(src, d2 == Q::ONE, "full positive duty");
    cover!(src, d2 > Q::ZERO && d2 < lim, "unsaturated duty");
}

/// Rate limiter: |Δ| ≤ max_step, never past the target, exact when within one step.
pub fn rate_limiter_bounded(src: &mut impl Source) {
    let step = q(src);
    let start = q(src);
    let mut r = RateLimiter::new(step, start);
    let target = q(src);
    let next = r.step(target);
    let d = i64::from(next.to_bits()).wrapping_sub(i64::from(start.to_bits()));
    let lim = i64::from(r.max_step().to_bits());
    assert!(d <= lim && d >= lim.wrapping_neg());
    let (lo, hi) = if start <= target {
        (start, target)
    } else {
        (target, start)
    };
    assert!(next >= lo && next <= hi);
    let gap = i64::from(target.to_bits()).wrapping_sub(i64::from(start.to_bits()));
    if gap.unsigned_abs() <= lim.unsigned_abs() {
        assert_eq!(next, target);
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

/// Kinematics conversions never panic or overflow for any twist and any wheel speeds; zero maps to
/// zero, a straight twist gives equal wheel speeds, equal wheel speeds give no yaw.
pub fn kinematics_total(src: &mut impl Source) {
    for &(base, radius) in &GEOMETRIES {
        let Ok(k) = DiffDrive::new(base, radius) else {
            panic!("a listed geometry was refused");
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
        assert_eq!(zl, Q::ZERO);
        assert_eq!(zr, Q::ZERO);
        let [sl, sr] = k.inverse(Twist {
            v: t.v,
            omega: Q::ZERO,
        });
        assert_eq!(sl, sr);
        assert_eq!(k.forward(l, l).omega, Q::ZERO);
        cover!(src, l != r, "turning twist");
        cover!(src, l == Q::MAX, "a wheel speed saturated");
    }
}

/// Construction of any geometry never panics, refuses a radius outside 1 mm ..= 10 m or a wheelbase
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
            assert!(radius_ok && base_ok);
            assert_eq!(k.wheelbase(), base);
            assert_eq!(k.wheel_radius(), radius);
        }
        Err(KinematicsError::WheelRadius) => assert!(!radius_ok),
        Err(KinematicsError::Wheelbase) => assert!(radius_ok && !base_ok),
    }
    if radius_ok && base_ok {
        assert!(k.is_ok());
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

/// Bridge mapping: both compares ≤ ARR and at most one non-zero (never both high sides on).
pub fn bridge_compare_safe(src: &mut impl Source) {
    let duty = q(src);
    let arr = src.u16();
    let c = bridge_compare(duty, arr);
    assert!(c.a <= arr && c.b <= arr);
    assert!(c.a == 0 || c.b == 0);
    if duty > Q::ZERO {
        assert_eq!(c.b, 0);
    }
    if duty < Q::ZERO {
        assert_eq!(c.a, 0);
    }
    cover!(src, c.a == arr && arr > 0, "full forward");
    cover!(src, c.b > 0, "reverse");
}

/// ADC scaling never panics and |i| ≤ 4095·|gain| (saturating at the Q16.16 range).
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
    assert!(i.unsigned_abs() <= bound);
    cover!(src, i > Q::ZERO, "positive current");
    cover!(src, i < Q::ZERO, "negative current");
}

/// Speed estimator: any counter sequence, no panic, estimate = scale × window delta.
pub fn speed_estimator_total(src: &mut impl Source) {
    let scale = q(src);
    let mut e = SpeedEstimator::new(src.u16(), scale);
    for _ in 0..3 {
        let s = e.update(src.u16());
        assert!(s.unsigned_abs() <= scale.unsigned_abs().saturating_mul_int(32_768));
    }
    cover!(src, e.total() != 0, "wheel moved");
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
    #[kani::proof]
    #[kani::unwind(7)]
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
    #[kani::proof]
    #[kani::unwind(2)]
    fn verify_adc_scaling_bounded() {
        super::adc_scaling_bounded(&mut KaniSource);
    }
    #[kani::proof]
    #[kani::unwind(17)]
    fn verify_speed_estimator_total() {
        super::speed_estimator_total(&mut KaniSource);
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
}
