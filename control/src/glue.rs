//! Board-agnostic firmware glue, tested on the host: ladder output → bridge, ADC counts → amperes,
//! encoder counts → speed, timer and watchdog arithmetic, task liveness.
//!
//! The firmware's RTIC tasks only move numbers between registers and these functions; the
//! simulator calls the same functions with a plant model in place of the registers.

use crate::pid::{CurrentPi, PidGains, SpeedPid};
use crate::rate::RateLimiter;
use crate::{clamp_sym, Amps, Duty, Q};
use statemachine::{Drive, Speed};

/// Compare values for the two half-bridges of one H-bridge (timer counts, 0 ..= ARR).
///
/// Unipolar switching: forward drives half-bridge A with the duty and holds B's low side on;
/// reverse swaps them. At most one of `a`, `b` is non-zero, so the bridge never shorts the supply
/// through both high sides, and zero duty is both low sides on (a dynamic brake at rest).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BridgeCompare {
    /// Half-bridge A compare value.
    pub a: u16,
    /// Half-bridge B compare value.
    pub b: u16,
}

/// Maps a duty in [-1, 1] (clamped) to compare values for a timer with auto-reload `arr`.
pub fn bridge_compare(duty: Duty, arr: u16) -> BridgeCompare {
    let d = clamp_sym(duty, Q::ONE);
    let mag = d.unsigned_abs();
    // |d| ≤ 1, so |d|·arr ≤ arr: the product fits and the cast cannot truncate.
    let counts = mag
        .saturating_mul_int(fixed::types::U16F16::from_num(arr).to_num::<u32>())
        .round()
        .to_num::<u32>()
        .min(u32::from(arr));
    let c = u16::try_from(counts).unwrap_or(arr);
    if d.is_negative() {
        BridgeCompare { a: 0, b: c }
    } else {
        BridgeCompare { a: c, b: 0 }
    }
}

/// What the bridge hardware must do for a ladder output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BridgeState {
    /// PWM outputs active, the current loop sets the duty.
    Run,
    /// High sides off, low sides on (motor shorted): dynamic brake, no control loop.
    Brake,
}

/// The bridge state a ladder drive command needs.
pub const fn bridge_state(drive: &Drive) -> BridgeState {
    match drive {
        Drive::Run { .. } => BridgeState::Run,
        Drive::Brake => BridgeState::Brake,
    }
}

/// Converts a 12-bit ADC reading of a bidirectional current sensor to amperes.
///
/// `offset` is the reading at zero current (mid-scale, calibrated at start-up), `amps_per_count`
/// the sensor gain: V_ref / 4096 / (shunt Ω × amplifier gain). Bits above 12 are ignored.
pub fn adc_to_amps(counts: u16, offset: u16, amps_per_count: Q) -> Amps {
    let c = i32::from(counts & 0x0FFF);
    let o = i32::from(offset & 0x0FFF);
    amps_per_count.saturating_mul_int(c.wrapping_sub(o))
}

/// True if |i| is at or above the trip level (the software overcurrent check; the hardware one is
/// the comparator on TIM1 BKIN).
pub fn overcurrent(i: Amps, trip: Amps) -> bool {
    i.unsigned_abs() >= trip.unsigned_abs()
}

/// Signed change between two readings of a 16-bit up/down encoder counter (wraps correctly as long
/// as fewer than 32768 counts pass between readings).
pub const fn encoder_delta(prev: u16, now: u16) -> i16 {
    now.wrapping_sub(prev) as i16
}

/// Samples in the speed estimator's window.
pub const SPEED_WINDOW: usize = 16;

/// Wheel speed from encoder counts: the count difference across a window of [`SPEED_WINDOW`]
/// samples (a moving-average FIR), and the cumulative count for the feedback frame.
///
/// At 10 kHz with a 4096-count/rev encoder the resolution is 2π / (4096 · 1.6 ms) ≈ 0.96 rad/s and
/// the group delay 0.8 ms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpeedEstimator {
    ring: [u16; SPEED_WINDOW],
    pos: usize,
    last: u16,
    total: i32,
    scale: Q,
}

impl SpeedEstimator {
    /// An estimator whose counter reads `initial`; `scale` is rad/s per count across the window,
    /// 2π / (counts_per_rev · SPEED_WINDOW · dt) (see [`speed_scale`]).
    pub const fn new(initial: u16, scale: Q) -> Self {
        Self {
            ring: [initial; SPEED_WINDOW],
            pos: 0,
            last: initial,
            total: 0,
            scale,
        }
    }

    /// Feeds one counter reading, returns the speed estimate (rad/s).
    pub fn update(&mut self, count: u16) -> Speed {
        self.total = self
            .total
            .wrapping_add(i32::from(encoder_delta(self.last, count)));
        self.last = count;
        let idx = self.pos % SPEED_WINDOW;
        let oldest = self.ring.get(idx).copied().unwrap_or(count);
        if let Some(slot) = self.ring.get_mut(idx) {
            *slot = count;
        }
        self.pos = idx.wrapping_add(1) % SPEED_WINDOW;
        self.scale
            .saturating_mul_int(i32::from(encoder_delta(oldest, count)))
    }

    /// Cumulative counts since start (wraps at ±2³¹, as the feedback frame's int32 does).
    pub const fn total(&self) -> i32 {
        self.total
    }
}

/// rad/s per count across the estimator window: 2π / (counts_per_rev · SPEED_WINDOW · dt), with
/// dt = 1 / rate_hz. Returns `None` if the result does not fit Q16.16 or an argument is zero.
pub fn speed_scale(counts_per_rev: u32, rate_hz: u32) -> Option<Q> {
    if counts_per_rev == 0 || rate_hz == 0 {
        return None;
    }
    // 2π · rate / (cpr · window), in Q32.32 first to keep the precision.
    let two_pi = fixed::types::I32F32::TAU;
    let num = two_pi.checked_mul_int(i64::from(rate_hz))?;
    let den = i64::from(counts_per_rev).checked_mul(SPEED_WINDOW as i64)?;
    let q = num.checked_div_int(den)?;
    Q::checked_from_num(q)
}

/// True if a speed estimate is physically possible: seed 000 treats more than twice the maximum
/// speed as an encoder error.
pub fn speed_plausible(speed: Speed, v_max: Speed) -> bool {
    speed.unsigned_abs() <= v_max.unsigned_abs().saturating_mul_int(2)
}

/// Everything one wheel's cascade needs besides the measurements.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AxisParams {
    /// Speed controller gains (output limit = current limit, A).
    pub speed: PidGains,
    /// Current controller gains (output limit = duty limit ≤ 1).
    pub current: PidGains,
    /// Largest setpoint change per speed-loop sample, rad/s (the ladder's accel_step / 10).
    pub ref_step: Speed,
    /// Encoder scale, rad/s per count across the window ([`speed_scale`]).
    pub speed_scale: Q,
}

/// One wheel's cascade: rate limiter → speed PID → current PI, with its speed estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AxisLoop {
    limiter: RateLimiter,
    speed_pid: SpeedPid,
    current_pi: CurrentPi,
    estimator: SpeedEstimator,
    speed: Speed,
    current_ref: Amps,
}

impl AxisLoop {
    /// A loop at rest with the encoder counter reading `count`.
    pub const fn new(p: &AxisParams, count: u16) -> Self {
        Self {
            limiter: RateLimiter::new(p.ref_step, Q::ZERO),
            speed_pid: SpeedPid::new(p.speed),
            current_pi: CurrentPi::new(p.current),
            estimator: SpeedEstimator::new(count, p.speed_scale),
            speed: Q::ZERO,
            current_ref: Q::ZERO,
        }
    }

    /// Speed-loop sample (10 kHz): updates the speed estimate from the counter, then, if the
    /// ladder says `Some(setpoint)`, runs limiter and PID and returns the current reference.
    /// `None` (BRAKE) resets the controllers and returns zero current.
    pub fn speed_step(&mut self, setpoint: Option<Speed>, count: u16) -> Amps {
        self.speed = self.estimator.update(count);
        self.current_ref = match setpoint {
            Some(sp) => {
                let r = self.limiter.step(sp);
                self.speed_pid.step(r, self.speed)
            }
            None => {
                self.limiter.reset(Q::ZERO);
                self.speed_pid.reset(self.speed);
                Q::ZERO
            }
        };
        self.current_ref
    }

    /// Current-loop sample (20 kHz): returns the duty for the measured current.
    pub fn current_step(&mut self, measured: Amps) -> Duty {
        self.current_pi.step(self.current_ref, measured)
    }

    /// Clears the current controller (BRAKE).
    pub fn current_reset(&mut self, measured: Amps) {
        self.current_pi.reset(measured);
    }

    /// The last current reference.
    pub const fn current_ref(&self) -> Amps {
        self.current_ref
    }

    /// The last speed estimate, rad/s.
    pub const fn speed(&self) -> Speed {
        self.speed
    }

    /// Cumulative encoder counts.
    pub const fn encoder_total(&self) -> i32 {
        self.estimator.total()
    }
}

/// Timer prescaler and auto-reload for an update rate: `clk / ((psc + 1) · (arr + 1)) = rate`.
///
/// Picks the smallest prescaler that makes ARR fit 16 bits. `None` if the rate is zero, above the
/// clock, or not an exact divisor of it (a rate error would break the tick-to-millisecond argument
/// of the safety case, so inexact rates are refused rather than rounded).
// Configuration arithmetic, evaluated in `const` items of the firmware: every divisor is checked
// non-zero and every product bounded in the comments (a violation would fail the build, not the MCU).
#[allow(clippy::arithmetic_side_effects)]
pub const fn timer_divider(clk_hz: u32, rate_hz: u32) -> Option<(u16, u16)> {
    let total = match clk_hz.checked_div(rate_hz) {
        Some(t) if t >= 1 && clk_hz % rate_hz == 0 => t,
        _ => return None,
    };
    let mut psc: u32 = 1;
    while psc <= 65_536 {
        // psc ≥ 1, so the remainder and quotient cannot fail; both results are ≤ 65_536 here.
        if total % psc == 0 && total / psc <= 65_536 {
            return Some((
                psc.saturating_sub(1) as u16,
                (total / psc).saturating_sub(1) as u16,
            ));
        }
        psc = psc.saturating_add(1);
    }
    None
}

/// Auto-reload for a centre-aligned PWM timer: the counter runs up and down, one period is
/// 2·ARR clocks, so ARR = clk / (2 · f_pwm). `None` unless exact and within 16 bits.
// Configuration arithmetic, evaluated in `const` items of the firmware: every divisor is checked
// non-zero and every product bounded in the comments (a violation would fail the build, not the MCU).
#[allow(clippy::arithmetic_side_effects)]
pub const fn center_aligned_arr(clk_hz: u32, pwm_hz: u32) -> Option<u16> {
    let two_f = match pwm_hz.checked_mul(2) {
        Some(v) if v > 0 => v,
        _ => return None,
    };
    match clk_hz.checked_div(two_f) {
        Some(arr) if arr >= 1 && arr <= 65_535 && clk_hz % two_f == 0 => Some(arr as u16),
        _ => None,
    }
}

/// Independent-watchdog setting: prescaler register code (0 → /4 … 6 → /256) and 12-bit reload.
///
/// The timeout is `4·2^code · (reload + 1) / f_LSI`. Chooses the smallest prescaler whose reload
/// fits for the requested timeout at the *nominal* LSI; returns `(code, reload)`.
// Configuration arithmetic, evaluated in `const` items of the firmware: every divisor is checked
// non-zero and every product bounded in the comments (a violation would fail the build, not the MCU).
#[allow(clippy::arithmetic_side_effects)]
pub const fn iwdg_setting(timeout_ms: u32, lsi_hz: u32) -> Option<(u8, u16)> {
    let mut code: u8 = 0;
    while code <= 6 {
        let div = 4u64 << code;
        // ticks = timeout · f_LSI / (1000 · div); the product of two u32 fits u64.
        let ticks = match (timeout_ms as u64 * lsi_hz as u64).checked_div(1000 * div) {
            Some(t) => t,
            None => return None,
        };
        if ticks >= 1 && ticks <= 4096 {
            return Some((code, ticks.saturating_sub(1) as u16));
        }
        code = code.saturating_add(1);
    }
    None
}

/// The IWDG timeout in microseconds for a setting and an LSI frequency (0 if `lsi_hz` is 0).
// Configuration arithmetic, evaluated in `const` items of the firmware: every divisor is checked
// non-zero and every product bounded in the comments (a violation would fail the build, not the MCU).
#[allow(clippy::arithmetic_side_effects)]
pub const fn iwdg_timeout_us(code: u8, reload: u16, lsi_hz: u32) -> u64 {
    let div = 4u64 << (code & 7);
    // ≤ 512 · 4096 · 10⁶ < 2⁴¹: no overflow.
    match (div * (reload as u64 + 1) * 1_000_000).checked_div(lsi_hz as u64) {
        Some(t) => t,
        None => 0,
    }
}

/// How many runs of each monitored task the watchdog task saw since it last fed the IWDG.
///
/// The 1 kHz watchdog task feeds the independent watchdog only if every monitored task ran at
/// least `min_runs` times since the previous feed; a stalled control loop therefore stops the
/// feeding and the IWDG resets the MCU into its safe (braked) reset state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Liveness<const N: usize> {
    seen: [u32; N],
}

impl<const N: usize> Liveness<N> {
    /// A monitor whose counters start at zero.
    pub const fn new() -> Self {
        Self { seen: [0; N] }
    }

    /// Compares the tasks' run counters with the values seen at the last check; returns true if
    /// every task advanced by at least the matching `min_runs` (wrapping counters are fine).
    pub fn check(&mut self, counters: [u32; N], min_runs: [u32; N]) -> bool {
        let mut ok = true;
        for ((seen, now), min) in self.seen.iter_mut().zip(counters).zip(min_runs) {
            if now.wrapping_sub(*seen) < min {
                ok = false;
            }
            *seen = now;
        }
        ok
    }
}

impl<const N: usize> Default for Liveness<N> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pid::AntiWindup;

    fn q(x: f64) -> Q {
        Q::from_num(x)
    }

    #[test]
    fn compare_values_by_hand() {
        assert_eq!(
            bridge_compare(q(0.5), 4200),
            BridgeCompare { a: 2100, b: 0 }
        );
        assert_eq!(
            bridge_compare(q(-0.25), 4200),
            BridgeCompare { a: 0, b: 1050 }
        );
        assert_eq!(
            bridge_compare(q(1.0), 4200),
            BridgeCompare { a: 4200, b: 0 }
        );
        assert_eq!(
            bridge_compare(q(-7.0), 4200),
            BridgeCompare { a: 0, b: 4200 }
        );
        assert_eq!(bridge_compare(Q::ZERO, 4200), BridgeCompare { a: 0, b: 0 });
        assert_eq!(
            bridge_compare(Q::MIN, u16::MAX),
            BridgeCompare { a: 0, b: u16::MAX }
        );
    }

    #[test]
    fn adc_counts_to_amps() {
        // ACS-style sensor: 100 mV/A around mid-scale, 3.3 V reference, 12 bits.
        let gain = 3.3 / 4096.0 / 0.1;
        let g = q(gain);
        let i = adc_to_amps(2048 + 1241, 2048, g).to_num::<f64>();
        assert!(
            (i - 1241.0 * gain).abs() < 1e-3 && (i - 10.0).abs() < 0.01,
            "{i}"
        );
        let i = adc_to_amps(2048 - 620, 2048, g).to_num::<f64>();
        assert!((i + 5.0).abs() < 0.01, "{i}");
        // Upper bits are ignored: 0xF800 & 0x0FFF = 0x0800 = offset → 0 A.
        assert_eq!(adc_to_amps(0xF800, 2048, g), Q::ZERO);
    }

    #[test]
    fn overcurrent_both_directions() {
        assert!(overcurrent(q(-20.0), q(20.0)));
        assert!(overcurrent(q(20.0), q(20.0)));
        assert!(!overcurrent(q(19.9), q(20.0)));
    }

    #[test]
    fn encoder_wraps() {
        assert_eq!(encoder_delta(65_535, 2), 3);
        assert_eq!(encoder_delta(2, 65_535), -3);
        assert_eq!(encoder_delta(100, 100), 0);
    }

    #[test]
    fn speed_estimate_of_constant_rotation() {
        // 4096 counts/rev at 10 kHz; 2 counts per sample = 2·10_000/4096 rev/s = 30.68 rad/s.
        let scale = speed_scale(4096, 10_000).unwrap();
        let expect_scale = 2.0 * core::f64::consts::PI * 10_000.0 / (4096.0 * 16.0);
        assert!((scale.to_num::<f64>() - expect_scale).abs() < 2e-5);
        let mut est = SpeedEstimator::new(65_000, scale);
        let mut c: u16 = 65_000;
        let mut s = Q::ZERO;
        for _ in 0..40 {
            c = c.wrapping_add(2);
            s = est.update(c);
        }
        let want = 2.0 * 10_000.0 / 4096.0 * 2.0 * core::f64::consts::PI;
        assert!((s.to_num::<f64>() - want).abs() < 0.01, "{s} vs {want}");
        assert_eq!(est.total(), 80);
    }

    #[test]
    fn plausibility() {
        assert!(speed_plausible(q(40.0), q(20.0)));
        assert!(!speed_plausible(q(-40.1), q(20.0)));
    }

    #[test]
    fn timer_dividers() {
        // TIM2 on APB1 at 84 MHz, 1 kHz: 84_000 clocks = (psc+1)(arr+1), smallest psc with arr ≤ 65535 is 2.
        assert_eq!(timer_divider(84_000_000, 1_000), Some((1, 41_999)));
        assert_eq!(timer_divider(84_000_000, 10_000), Some((0, 8_399)));
        assert_eq!(timer_divider(16_000_000, 1_000), Some((0, 15_999)));
        assert_eq!(timer_divider(84_000_000, 9), None);
        assert_eq!(timer_divider(84_000_000, 0), None);
        // 168 MHz centre-aligned at 20 kHz: 168e6 / 40e3 = 4200.
        assert_eq!(center_aligned_arr(168_000_000, 20_000), Some(4200));
        assert_eq!(center_aligned_arr(168_000_000, 1), None);
    }

    #[test]
    fn iwdg_by_hand() {
        // 32 kHz nominal LSI, 50 ms: /4 gives 400 ticks → reload 399, 50 ms.
        assert_eq!(iwdg_setting(50, 32_000), Some((0, 399)));
        assert_eq!(iwdg_timeout_us(0, 399, 32_000), 50_000);
        // LSI is 17..47 kHz over temperature and parts (DS8626): the same setting spans 34..94 ms.
        assert_eq!(iwdg_timeout_us(0, 399, 47_000), 34_042);
        assert_eq!(iwdg_timeout_us(0, 399, 17_000), 94_117);
        // 1 s needs /8: 32000·1/8 = 4000 → reload 3999.
        assert_eq!(iwdg_setting(1000, 32_000), Some((1, 3999)));
    }

    #[test]
    fn liveness_needs_every_task() {
        let mut l = Liveness::<2>::new();
        assert!(l.check([20, 10], [15, 8]));
        assert!(!l.check([40, 10], [15, 8]));
        assert!(l.check([60, 20], [15, 8]));
        // Wrapping counters.
        let mut l = Liveness::<1>::new();
        assert!(l.check([u32::MAX], [1]));
        assert!(l.check([19], [20]));
    }

    #[test]
    fn axis_brake_resets_and_run_drives() {
        let p = AxisParams {
            speed: PidGains {
                kp: q(1.0),
                ki_dt: q(0.01),
                kd_dt: Q::ZERO,
                out_limit: q(10.0),
                i_limit: q(10.0),
                anti_windup: AntiWindup::Conditional,
            },
            current: PidGains {
                kp: q(0.1),
                ki_dt: q(0.01),
                kd_dt: Q::ZERO,
                out_limit: q(0.9),
                i_limit: q(0.9),
                anti_windup: AntiWindup::Conditional,
            },
            ref_step: q(0.5),
            speed_scale: speed_scale(4096, 10_000).unwrap(),
        };
        let mut a = AxisLoop::new(&p, 0);
        // Setpoint 5 rad/s, wheel still: reference ramps 0.5 per sample, P = 1·0.5, I = 0.01·0.5.
        let i1 = a.speed_step(Some(q(5.0)), 0);
        assert!((i1.to_num::<f64>() - 0.505).abs() < 1e-3, "{i1}");
        let d = a.current_step(Q::ZERO);
        assert!(d > Q::ZERO && d <= q(0.9));
        assert_eq!(a.speed_step(None, 0), Q::ZERO);
        // After BRAKE the ramp restarts from zero.
        let i2 = a.speed_step(Some(q(5.0)), 0);
        assert!((i2.to_num::<f64>() - 0.505).abs() < 1e-3, "{i2}");
    }
}
