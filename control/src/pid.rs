//! Discrete PID with integrator clamp, conditional-integration anti-windup and output clamp.
//!
//! One sample, period `dt` folded into the gains (`ki_dt = Ki·dt`, `kd_dt = Kd/dt`):
//!
//! ```text
//!  e      = r − y
//!  p      = kp · e
//!  d      = −kd_dt · (y − y_prev)          derivative on the measurement: no kick on setpoint steps
//!  i'     = clamp(i + ki_dt · e, ±i_limit)
//!  u_raw  = p + i' + d
//!  anti-windup (Conditional): if u_raw is beyond ±out_limit and e pushes further out, keep i
//!  u      = clamp(p + i + d, ±out_limit)
//! ```
//!
//! Invariant ([`Pid::is_valid`]): |i| ≤ i_limit, and every step keeps it and returns |u| ≤ out_limit,
//! for every input (proved in `verification`).

use crate::{clamp_sym, within, Amps, Duty, Gain, Q};
use statemachine::Speed;

/// How the integrator is kept from winding up while the output is saturated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AntiWindup {
    /// Only the hard integrator clamp ±i_limit (the baseline the tests compare against).
    ClampOnly,
    /// Conditional integration: stop integrating while the output saturates in the error's direction.
    Conditional,
}

/// Gains and limits of one controller, per sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PidGains {
    /// Proportional gain (output units per input unit).
    pub kp: Gain,
    /// Integral gain times the sample period.
    pub ki_dt: Gain,
    /// Derivative gain divided by the sample period (0 for a PI).
    pub kd_dt: Gain,
    /// Output magnitude limit (≥ 0).
    pub out_limit: Q,
    /// Integrator magnitude limit (≥ 0).
    pub i_limit: Q,
    /// Anti-windup strategy.
    pub anti_windup: AntiWindup,
}

impl PidGains {
    /// True if the limits are non-negative (gains may have any sign: a negative gain is a
    /// configuration mistake but still cannot break the bounds).
    pub const fn is_valid(&self) -> bool {
        self.out_limit.to_bits() >= 0 && self.i_limit.to_bits() >= 0
    }
}

/// The controller state: gains, integrator and the previous measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pid {
    gains: PidGains,
    integ: Q,
    prev_meas: Q,
}

impl Pid {
    /// A controller at rest (integrator zero, previous measurement zero).
    /// Negative limits are treated as zero.
    pub const fn new(gains: PidGains) -> Self {
        let mut g = gains;
        if g.out_limit.to_bits() < 0 {
            g.out_limit = Q::ZERO;
        }
        if g.i_limit.to_bits() < 0 {
            g.i_limit = Q::ZERO;
        }
        Self {
            gains: g,
            integ: Q::ZERO,
            prev_meas: Q::ZERO,
        }
    }

    /// A controller in an arbitrary state, for the harnesses (which assume [`Pid::is_valid`]).
    #[cfg(any(test, kani))]
    pub(crate) const fn from_parts(gains: PidGains, integ: Q, prev_meas: Q) -> Self {
        Self {
            gains,
            integ,
            prev_meas,
        }
    }

    /// The gains in force.
    pub const fn gains(&self) -> &PidGains {
        &self.gains
    }

    /// The integrator value.
    pub const fn integrator(&self) -> Q {
        self.integ
    }

    /// The state invariant: limits non-negative and |integrator| ≤ i_limit.
    pub const fn is_valid(&self) -> bool {
        self.gains.is_valid() && within(self.integ, self.gains.i_limit)
    }

    /// Forgets the integrator and restarts the derivative from `meas` (used when BRAKE releases the loop).
    pub fn reset(&mut self, meas: Q) {
        self.integ = Q::ZERO;
        self.prev_meas = meas;
    }

    /// One sample: setpoint `r`, measurement `y`; returns the clamped output.
    pub fn step(&mut self, r: Q, y: Q) -> Q {
        let g = &self.gains;
        let e = r.saturating_sub(y);
        let p = g.kp.saturating_mul(e);
        let d = g
            .kd_dt
            .saturating_mul(y.saturating_sub(self.prev_meas))
            .saturating_neg();
        self.prev_meas = y;
        let candidate = clamp_sym(
            self.integ.saturating_add(g.ki_dt.saturating_mul(e)),
            g.i_limit,
        );
        let pd = p.saturating_add(d);
        let keep_old = match g.anti_windup {
            AntiWindup::ClampOnly => false,
            AntiWindup::Conditional => {
                let raw = pd.saturating_add(candidate);
                (raw > g.out_limit && e > Q::ZERO)
                    || (raw < g.out_limit.saturating_neg() && e < Q::ZERO)
            }
        };
        if !keep_old {
            self.integ = candidate;
        }
        clamp_sym(pd.saturating_add(self.integ), g.out_limit)
    }
}

/// Wheel speed controller: speed error (rad/s) in, motor current reference (A) out, run at 10 kHz.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpeedPid(Pid);

impl SpeedPid {
    /// A controller at rest; `gains.out_limit` is the current limit in amperes.
    pub const fn new(gains: PidGains) -> Self {
        Self(Pid::new(gains))
    }
    /// One sample: returns the current reference, |i_ref| ≤ out_limit.
    pub fn step(&mut self, setpoint: Speed, measured: Speed) -> Amps {
        self.0.step(setpoint, measured)
    }
    /// Clears the integrator.
    pub fn reset(&mut self, measured: Speed) {
        self.0.reset(measured);
    }
    /// The underlying controller.
    pub const fn inner(&self) -> &Pid {
        &self.0
    }
}

/// Motor current controller: current error (A) in, PWM duty out, run at 20 kHz in step with the PWM.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CurrentPi(Pid);

impl CurrentPi {
    /// A PI (the derivative gain is forced to zero); `gains.out_limit` is the duty limit, at most 1.
    pub const fn new(gains: PidGains) -> Self {
        let mut g = gains;
        g.kd_dt = Q::ZERO;
        if g.out_limit.to_bits() > Q::ONE.to_bits() {
            g.out_limit = Q::ONE;
        }
        Self(Pid::new(g))
    }
    /// One sample: returns the duty, |duty| ≤ out_limit ≤ 1.
    pub fn step(&mut self, reference: Amps, measured: Amps) -> Duty {
        self.0.step(reference, measured)
    }
    /// Clears the integrator.
    pub fn reset(&mut self, measured: Amps) {
        self.0.reset(measured);
    }
    /// The underlying controller.
    pub const fn inner(&self) -> &Pid {
        &self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64) -> Q {
        Q::from_num(x)
    }

    /// First-order speed plant dω/dt = (K·i − ω)/τ, integrated with exact discretisation in f64.
    struct Plant {
        w: f64,
        a: f64,
        b: f64,
    }
    impl Plant {
        fn new(k: f64, tau: f64, dt: f64) -> Self {
            let a = (-dt / tau).exp();
            Self {
                w: 0.0,
                a,
                b: k * (1.0 - a),
            }
        }
        fn step(&mut self, u: f64) -> f64 {
            self.w = self.a * self.w + self.b * u;
            self.w
        }
    }

    fn gains(kp: f64, ki_dt: f64, out: f64, ilim: f64, aw: AntiWindup) -> PidGains {
        PidGains {
            kp: q(kp),
            ki_dt: q(ki_dt),
            kd_dt: Q::ZERO,
            out_limit: q(out),
            i_limit: q(ilim),
            anti_windup: aw,
        }
    }

    /// Runs a step from 0 to `r` for `n` samples; returns the trajectory.
    fn run(pid: &mut Pid, plant: &mut Plant, r: f64, n: usize) -> std::vec::Vec<f64> {
        extern crate std;
        let mut y = 0.0;
        let mut out = std::vec::Vec::new();
        for _ in 0..n {
            let u = pid.step(q(r), q(y)).to_num::<f64>();
            y = plant.step(u);
            out.push(y);
        }
        out
    }

    extern crate std;

    #[test]
    fn closed_loop_step_settles_on_first_order_plant() {
        // Plant: K = 2 (rad/s)/A, τ = 50 ms, sampled at 10 kHz. PI designed for a ~10 ms closed loop:
        // pole-zero cancellation Ki/Kp = 1/τ, Kp·K/τ = 1/τ_cl → Kp = τ/(K·τ_cl) = 2.5.
        let dt = 1e-4;
        let (k, tau, tau_cl) = (2.0, 0.05, 0.01);
        let kp = tau / (k * tau_cl);
        let ki_dt = kp / tau * dt;
        let mut pid = Pid::new(gains(kp, ki_dt, 20.0, 20.0, AntiWindup::Conditional));
        let mut plant = Plant::new(k, tau, dt);
        let y = run(&mut pid, &mut plant, 5.0, 1000); // 100 ms
                                                      // First-order closed loop: 63 % at τ_cl, within 2 % after 4·τ_cl (400 samples); allow quantisation slack.
        let at_tau = y[99];
        assert!(
            (at_tau - 5.0 * (1.0 - (-1.0f64).exp())).abs() < 0.15,
            "y(τ_cl) = {at_tau}"
        );
        for (n, v) in y.iter().enumerate().skip(450) {
            assert!((v - 5.0).abs() < 0.1, "sample {n}: {v}");
        }
        let overshoot = y.iter().cloned().fold(0.0, f64::max);
        assert!(overshoot < 5.1, "overshoot {overshoot}");
        assert!(pid.is_valid());
    }

    fn settle_time(y: &[f64], r: f64, band: f64) -> usize {
        y.iter()
            .rposition(|v| (v - r).abs() > band)
            .map_or(0, |i| i + 1)
    }

    #[test]
    fn anti_windup_recovers_faster_than_clamp_only() {
        // Output limit 2 A with K = 2 → the plant can reach 4 rad/s at most; a step to 3.8 rad/s
        // saturates for a long time. Without anti-windup the integrator charges up to i_limit and
        // the response overshoots and settles late.
        let dt = 1e-4;
        let (k, tau) = (2.0, 0.05);
        let (kp, ki_dt) = (2.5, 50.0 * dt);
        let mut with = Pid::new(gains(kp, ki_dt, 2.0, 50.0, AntiWindup::Conditional));
        let mut without = Pid::new(gains(kp, ki_dt, 2.0, 50.0, AntiWindup::ClampOnly));
        let y_with = run(&mut with, &mut Plant::new(k, tau, dt), 3.8, 20_000);
        let y_without = run(&mut without, &mut Plant::new(k, tau, dt), 3.8, 20_000);
        let t_with = settle_time(&y_with, 3.8, 0.05);
        let t_without = settle_time(&y_without, 3.8, 0.05);
        let os_with = y_with.iter().cloned().fold(0.0, f64::max);
        let os_without = y_without.iter().cloned().fold(0.0, f64::max);
        assert!(
            t_with < t_without,
            "settle with {t_with}, without {t_without}"
        );
        assert!(
            os_with <= os_without,
            "overshoot with {os_with}, without {os_without}"
        );
        assert!(t_with < 19_000, "with anti-windup it must settle: {t_with}");
    }

    #[test]
    fn output_and_integrator_clamped() {
        let mut pid = Pid::new(gains(100.0, 10.0, 3.0, 1.5, AntiWindup::ClampOnly));
        for _ in 0..100 {
            let u = pid.step(q(1000.0), q(-1000.0));
            assert_eq!(u, q(3.0));
            assert!(pid.integrator() <= q(1.5));
        }
        assert_eq!(pid.integrator(), q(1.5));
        let u = pid.step(q(-1000.0), q(1000.0));
        assert_eq!(u, q(-3.0));
    }

    #[test]
    fn derivative_acts_on_measurement_only() {
        let mut g = gains(0.0, 0.0, 100.0, 0.0, AntiWindup::Conditional);
        g.kd_dt = q(2.0);
        let mut pid = Pid::new(g);
        // A setpoint step produces no derivative kick.
        assert_eq!(pid.step(q(10.0), q(0.0)), Q::ZERO);
        // Measurement rising by 1.5 → −2·1.5.
        assert_eq!(pid.step(q(10.0), q(1.5)), q(-3.0));
    }

    #[test]
    fn current_pi_settles_on_rl_load() {
        // RL load: L = 1 mH, R = 0.5 Ω, bus 24 V (duty 1 → 24 V), sampled at 20 kHz.
        let dt = 5e-5;
        let (l, r, vbus) = (1e-3, 0.5, 24.0);
        // Cancellation design for a 0.5 ms closed loop: Kp = L/(Vbus·τ_cl), Ki = R/(Vbus·τ_cl).
        let tau_cl = 5e-4;
        let kp = l / (vbus * tau_cl);
        let ki_dt = r / (vbus * tau_cl) * dt;
        let mut pi = CurrentPi::new(gains(kp, ki_dt, 0.95, 0.95, AntiWindup::Conditional));
        let a = (-dt * r / l).exp();
        let mut i = 0.0f64;
        let mut trace = std::vec::Vec::new();
        for _ in 0..400 {
            let d = pi.step(q(4.0), q(i)).to_num::<f64>();
            assert!(d.abs() <= 0.95 + 1e-9);
            i = a * i + (1.0 - a) * vbus * d / r;
            trace.push(i);
        }
        // After 10 τ_cl (100 samples) within 2 %.
        for v in trace.iter().skip(100) {
            assert!((v - 4.0).abs() < 0.08, "{v}");
        }
    }

    #[test]
    fn current_pi_limit_never_exceeds_one() {
        let pi = CurrentPi::new(gains(1.0, 1.0, 7.0, 7.0, AntiWindup::Conditional));
        assert_eq!(pi.inner().gains().out_limit, Q::ONE);
        assert_eq!(pi.inner().gains().kd_dt, Q::ZERO);
    }

    #[test]
    fn is_valid_needs_both_the_limits_and_the_integrator_in_bounds() {
        let g = gains(1.0, 1.0, 3.0, 1.0, AntiWindup::Conditional);
        assert!(Pid::from_parts(g, q(1.0), Q::ZERO).is_valid());
        assert!(Pid::from_parts(g, q(-1.0), Q::ZERO).is_valid());
        // Integrator beyond ±i_limit with valid limits.
        assert!(!Pid::from_parts(g, q(1.5), Q::ZERO).is_valid());
        assert!(!Pid::from_parts(g, q(-1.5), Q::ZERO).is_valid());
        // A negative limit with the integrator at zero.
        let bad = gains(1.0, 1.0, -3.0, 1.0, AntiWindup::Conditional);
        assert!(!bad.is_valid());
        assert!(!Pid::from_parts(bad, Q::ZERO, Q::ZERO).is_valid());
    }

    #[test]
    fn reset_clears_the_integrator_and_restarts_the_derivative() {
        // I and D only: after one step the integrator holds ki_dt·e = 2.
        let mut g = gains(0.0, 1.0, 100.0, 100.0, AntiWindup::Conditional);
        g.kd_dt = q(2.0);
        let mut pid = Pid::new(g);
        pid.step(q(2.0), Q::ZERO);
        assert_eq!(pid.integrator(), q(2.0));
        pid.reset(q(8.0));
        assert_eq!(pid.integrator(), Q::ZERO);
        // The derivative starts from the measurement given to reset: y = 8 again is no change, so
        // the output is the integrator's one step of ki_dt·(r − y) = 0.
        assert_eq!(pid.step(q(8.0), q(8.0)), Q::ZERO);
    }

    /// Conditional integration holds the integrator only while the unclamped output is strictly
    /// beyond the limit and the error pushes further out: an output exactly at the limit still
    /// integrates; a saturated output with the error pulling back integrates; each side alike.
    #[test]
    fn conditional_integration_at_and_beyond_each_limit() {
        let g = gains(1.0, 1.0, 3.0, 10.0, AntiWindup::Conditional);
        // e = ±1.5: p = ±1.5, candidate ±1.5, raw ±3 = ±out_limit, not beyond: integrate.
        for s in [1.0, -1.0] {
            let mut pid = Pid::new(g);
            assert_eq!(pid.step(q(1.5 * s), Q::ZERO), q(3.0 * s));
            assert_eq!(pid.integrator(), q(1.5 * s));
        }
        // kp = 10, e = ±1: raw = ±11, beyond in the error's direction: the integrator holds.
        let strong = gains(10.0, 1.0, 3.0, 10.0, AntiWindup::Conditional);
        for s in [1.0, -1.0] {
            let mut pid = Pid::new(strong);
            assert_eq!(pid.step(q(s), Q::ZERO), q(3.0 * s));
            assert_eq!(pid.integrator(), Q::ZERO);
        }
        // Unsaturated (raw = ±1): the error's sign alone does not hold the integrator.
        for s in [1.0, -1.0] {
            let mut pid = Pid::new(g);
            assert_eq!(pid.step(q(0.5 * s), Q::ZERO), q(s));
            assert_eq!(pid.integrator(), q(0.5 * s));
        }
    }

    #[test]
    fn speed_and_current_wrappers_step_and_reset_their_controller() {
        let g = gains(2.0, 0.5, 10.0, 10.0, AntiWindup::Conditional);
        let mut speed = SpeedPid::new(g);
        // p = 2·3 = 6 plus the integrator's 0.5·3 = 1.5, then 6 plus 3.
        assert_eq!(speed.step(q(3.0), Q::ZERO), q(7.5));
        assert_eq!(speed.step(q(3.0), Q::ZERO), q(9.0));
        speed.reset(Q::ZERO);
        assert_eq!(speed.inner().integrator(), Q::ZERO);
        let mut current = CurrentPi::new(gains(0.1, 0.05, 1.0, 1.0, AntiWindup::Conditional));
        // 0.1·2 + 0.05·2 = 0.3, in Q16.16 steps.
        let d = current.step(q(2.0), Q::ZERO);
        assert_eq!(d, q(0.1) * q(2.0) + q(0.05) * q(2.0));
        assert_ne!(current.inner().integrator(), Q::ZERO);
        current.reset(Q::ZERO);
        assert_eq!(current.inner().integrator(), Q::ZERO);
    }

    #[test]
    fn negative_limits_become_zero() {
        let mut pid = Pid::new(gains(1.0, 1.0, -1.0, -1.0, AntiWindup::Conditional));
        assert!(pid.is_valid());
        assert_eq!(pid.step(q(5.0), q(0.0)), Q::ZERO);
    }
}
