//! Measurements as the control loops see them: shunt ADC counts → amperes and the overcurrent
//! check, encoder counts → wheel speed and distance, and the plausibility rule for a speed estimate.

use crate::{Amps, Q};
use statemachine::Speed;

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

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64) -> Q {
        Q::from_num(x)
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
    fn speed_scale_refuses_a_zero_argument() {
        // Zero counts per revolution divides by zero; a zero rate has no sample period.
        assert_eq!(speed_scale(0, 10_000), None);
        assert_eq!(speed_scale(4096, 0), None);
        assert_eq!(speed_scale(0, 0), None);
    }

    #[test]
    fn plausibility() {
        assert!(speed_plausible(q(40.0), q(20.0)));
        assert!(!speed_plausible(q(-40.1), q(20.0)));
    }
}
