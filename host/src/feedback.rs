//! Feedback validation: the host never trusts what the MCU reports (seed 000, "Jetson rule").
//!
//! # Motor current: signed, bounded by the sensor's full scale
//!
//! Seed 000 says "negative current = sensor failure". That rule was written for a unidirectional
//! current sensor, which cannot read below zero unless it is broken. This board measures each motor
//! with a bidirectional shunt amplifier and the firmware reports the current **signed**: negative
//! means reverse torque (driving backwards) or regenerative braking, both normal. Kept as written,
//! the seed's rule would flag a sensor fault whenever a wheel drives backwards or the robot brakes.
//!
//! What still cannot come from a working sensor chain is a reading beyond the sensor's measurable
//! range: the ADC saturates at full scale, so a larger magnitude means a broken conversion (offset,
//! scale, wiring) or a corrupted value. The rule is therefore `|current| > current_full_scale` ⇒
//! [`FeedbackFault::CurrentOutOfRange`], with the full scale from the board:
//!
//! ```text
//!  5 mΩ shunt × gain 20 = 0.1 V/A;  3.3 V / 4096 counts = 0.806 mV/count  →  8.06 mA per count
//!  mid-scale reference (bidirectional): ±2048 counts × 8.06 mA = ±16.5 A
//! ```
//! A real overcurrent is the MCU's to act on (it braked already); a sensor that reads a constant
//! in-range value is caught by the encoder/speed checks, not here.

/// Why a feedback frame (or its absence) was judged wrong. Codes are fixed and never reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[repr(u8)]
pub enum FeedbackFault {
    /// A wheel speed above 2 × the maximum: the encoder or its decoding is broken.
    SpeedImplausible = 1,
    /// A motor current whose magnitude exceeds the sensor's full scale: the shunt, its amplifier or
    /// the conversion failed. Negative currents are normal (reverse torque, regenerative braking);
    /// this replaces the seed's "negative current" rule, see the module documentation.
    CurrentOutOfRange = 2,
    /// Encoder counts moved against the sign of the reported speed, or far from it.
    EncoderInconsistent = 3,
    /// No new feedback (MCU timestamp not advancing) for longer than the stale limit: MCU frozen.
    Stale = 4,
    /// A number was NaN or infinite.
    NonFinite = 5,
}

/// One decoded feedback sample, independent of the wire format.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FeedbackSample {
    /// MCU timestamp, µs.
    pub mcu_us: u32,
    /// Wheel speeds (left, right), rad/s.
    pub speed: [f32; 2],
    /// Motor currents (left, right), A.
    pub current: [f32; 2],
    /// Cumulative encoder counts (left, right).
    pub encoder: [i32; 2],
    /// Fault flags as reported.
    pub faults: u16,
}

/// The board's current sensor full scale, A: ±2048 counts of a 3.3 V 12-bit ADC around mid-scale,
/// 8.06 mA per count (5 mΩ shunt × gain 20 = 0.1 V/A).
pub const BOARD_CURRENT_FULL_SCALE_A: f64 = 16.5;

/// Thresholds for [`FeedbackMonitor`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeedbackLimits {
    /// Largest wheel speed, rad/s; twice this is implausible.
    pub max_wheel_speed: f64,
    /// The current sensor's measurable full scale, A: a reported motor current whose magnitude
    /// exceeds it is a sensor failure. Currents of either sign within it are normal.
    pub current_full_scale: f64,
    /// Encoder counts per wheel radian.
    pub counts_per_rad: f64,
    /// Speeds below this are not checked against the encoder direction, rad/s.
    pub direction_min_speed: f64,
    /// Allowed error of the count increment against speed × Δt, as a fraction plus a count slack.
    pub count_tolerance: f64,
    /// Slack in counts added to the allowed increment error.
    pub count_slack: f64,
    /// No advancing MCU timestamp for this long (host µs) means the MCU is frozen.
    pub stale_after_us: u64,
}

impl FeedbackLimits {
    /// 20 rad/s MCU limit, ±16.5 A current full scale ([`BOARD_CURRENT_FULL_SCALE_A`]), 4096 counts
    /// per wheel revolution, 5 ms stale limit.
    pub const DEFAULT: Self = Self {
        max_wheel_speed: 20.0,
        current_full_scale: BOARD_CURRENT_FULL_SCALE_A,
        counts_per_rad: 4096.0 / core::f64::consts::TAU,
        direction_min_speed: 0.5,
        count_tolerance: 0.5,
        count_slack: 8.0,
        stale_after_us: 5_000,
    };
}

impl Default for FeedbackLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Checks each feedback sample against physics and the previous sample.
#[derive(Clone, Debug)]
pub struct FeedbackMonitor {
    limits: FeedbackLimits,
    last: Option<FeedbackSample>,
    /// Host time at which the MCU timestamp last advanced, µs.
    last_advance_host: Option<u64>,
    /// Samples checked.
    pub checked: u64,
    /// Faults found, by code − 1.
    pub fault_counts: [u64; 5],
}

impl FeedbackMonitor {
    /// A monitor with no history.
    pub fn new(limits: FeedbackLimits) -> Self {
        Self {
            limits,
            last: None,
            last_advance_host: None,
            checked: 0,
            fault_counts: [0; 5],
        }
    }

    /// The limits in force.
    pub fn limits(&self) -> &FeedbackLimits {
        &self.limits
    }

    fn note(&mut self, out: &mut Vec<FeedbackFault>, f: FeedbackFault) {
        if !out.contains(&f) {
            out.push(f);
            let i = (f as usize).saturating_sub(1);
            if let Some(c) = self.fault_counts.get_mut(i) {
                *c = c.saturating_add(1);
            }
        }
    }

    /// Checks one sample received at host time `host_us`; returns the faults found (empty if sane).
    pub fn check(&mut self, host_us: u64, s: &FeedbackSample) -> Vec<FeedbackFault> {
        let mut out = Vec::new();
        self.checked = self.checked.saturating_add(1);
        let l = self.limits;
        let finite = s
            .speed
            .iter()
            .chain(s.current.iter())
            .all(|x| x.is_finite());
        if !finite {
            self.note(&mut out, FeedbackFault::NonFinite);
        }
        for &w in &s.speed {
            if f64::from(w).abs() > 2.0 * l.max_wheel_speed {
                self.note(&mut out, FeedbackFault::SpeedImplausible);
            }
        }
        for &i in &s.current {
            if f64::from(i).abs() > l.current_full_scale {
                self.note(&mut out, FeedbackFault::CurrentOutOfRange);
            }
        }
        match self.last {
            Some(prev) if s.mcu_us != prev.mcu_us => {
                self.last_advance_host = Some(host_us);
                let dt = f64::from(s.mcu_us.wrapping_sub(prev.mcu_us)) * 1e-6;
                if finite && dt > 0.0 && dt < 0.1 {
                    for k in 0..2 {
                        let (Some(&w0), Some(&w1), Some(&c0), Some(&c1)) = (
                            prev.speed.get(k),
                            s.speed.get(k),
                            prev.encoder.get(k),
                            s.encoder.get(k),
                        ) else {
                            continue;
                        };
                        let w = (f64::from(w0) + f64::from(w1)) / 2.0;
                        let dc = f64::from(c1.wrapping_sub(c0));
                        let expected = w * dt * l.counts_per_rad;
                        let wrong_sign = w.abs() > l.direction_min_speed
                            && f64::from(w0).signum() == f64::from(w1).signum()
                            && dc * w.signum() < -l.count_slack;
                        let wrong_size = (dc - expected).abs()
                            > l.count_tolerance * expected.abs() + l.count_slack;
                        if wrong_sign || wrong_size {
                            self.note(&mut out, FeedbackFault::EncoderInconsistent);
                        }
                    }
                }
            }
            Some(_) => {}
            None => self.last_advance_host = Some(host_us),
        }
        self.last = Some(*s);
        if self.is_stale(host_us) {
            self.note(&mut out, FeedbackFault::Stale);
        }
        out
    }

    /// True if the MCU timestamp has not advanced for longer than the stale limit at `host_us`
    /// (also when no feedback has ever come since `since_us`).
    pub fn is_stale(&self, host_us: u64) -> bool {
        match self.last_advance_host {
            Some(t) => host_us.saturating_sub(t) > self.limits.stale_after_us,
            None => false,
        }
    }

    /// Forgets the history (after an MCU reset or re-arm).
    pub fn reset(&mut self, host_us: u64) {
        self.last = None;
        self.last_advance_host = Some(host_us);
    }

    /// Starts the stale clock without a sample (link opened, nothing heard yet).
    pub fn start(&mut self, host_us: u64) {
        if self.last_advance_host.is_none() {
            self.last_advance_host = Some(host_us);
        }
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
mod tests {
    use super::*;

    fn sample(t_ms: u32, w: f32, enc: i32) -> FeedbackSample {
        FeedbackSample {
            mcu_us: t_ms * 1000,
            speed: [w, w],
            current: [1.0, 1.0],
            encoder: [enc, enc],
            faults: 0,
        }
    }

    // 4096 counts/rev: 10 rad/s for 1 ms = 0.01 rad = 6.52 counts.
    #[test]
    fn consistent_motion_passes() {
        let mut m = FeedbackMonitor::new(FeedbackLimits::DEFAULT);
        let mut enc = 0i32;
        for k in 0..100u32 {
            enc += if k % 2 == 0 { 6 } else { 7 };
            assert!(
                m.check(u64::from(k) * 1000, &sample(k, 10.0, enc))
                    .is_empty(),
                "{k}"
            );
        }
    }

    #[test]
    fn each_rule_fires() {
        let mut m = FeedbackMonitor::new(FeedbackLimits::DEFAULT);
        assert!(m.check(0, &sample(0, 10.0, 0)).is_empty());
        // 41 rad/s > 2 × 20.
        assert!(m
            .check(1000, &sample(1, 41.0, 20))
            .contains(&FeedbackFault::SpeedImplausible));
        let mut over = sample(2, 10.0, 27);
        over.current[1] = 17.0;
        assert!(m
            .check(2000, &over)
            .contains(&FeedbackFault::CurrentOutOfRange));
        // Forward speed but counts going backwards by 50.
        assert!(m
            .check(3000, &sample(3, 10.0, -23))
            .contains(&FeedbackFault::EncoderInconsistent));
        let mut nan = sample(4, 10.0, -17);
        nan.speed[0] = f32::NAN;
        assert!(m.check(4000, &nan).contains(&FeedbackFault::NonFinite));
    }

    #[test]
    fn board_full_scale_is_2048_counts_of_8_06_ma() {
        let amps_per_count: f64 = (3.3 / 4096.0) / (0.005 * 20.0);
        assert!((amps_per_count - 0.00806).abs() < 1e-5);
        assert!((2048.0 * amps_per_count - BOARD_CURRENT_FULL_SCALE_A).abs() < 1e-9);
    }

    /// Signed currents: reverse and regenerative currents within the full scale are normal; beyond
    /// it, in either direction, the sensor has failed.
    #[test]
    fn current_is_checked_by_magnitude_against_the_full_scale() {
        let verdict = |current: [f32; 2]| {
            let mut m = FeedbackMonitor::new(FeedbackLimits::DEFAULT);
            let mut s = sample(0, 0.0, 0);
            s.current = current;
            m.check(0, &s).contains(&FeedbackFault::CurrentOutOfRange)
        };
        // Driving backwards (−10 A) and regenerative braking (−0.5 A) are accepted.
        assert!(!verdict([-10.0, -10.0]));
        assert!(!verdict([-0.5, 3.0]));
        // Exactly at full scale (a saturated reading) is still a reading.
        assert!(!verdict([16.5, -16.5]));
        // Beyond full scale, either sign, either wheel: flagged.
        assert!(verdict([17.0, 0.0]));
        assert!(verdict([0.0, -17.0]));
        // The limit is configurable.
        let mut m = FeedbackMonitor::new(FeedbackLimits {
            current_full_scale: 5.0,
            ..FeedbackLimits::DEFAULT
        });
        let mut s = sample(0, 0.0, 0);
        s.current = [-6.0, 0.0];
        assert_eq!(m.check(0, &s), vec![FeedbackFault::CurrentOutOfRange]);
    }

    #[test]
    fn frozen_timestamp_is_stale_after_the_limit() {
        let mut m = FeedbackMonitor::new(FeedbackLimits::DEFAULT);
        assert!(m.check(0, &sample(7, 0.0, 0)).is_empty());
        for t in 1..=5u64 {
            assert!(m.check(t * 1000, &sample(7, 0.0, 0)).is_empty(), "{t}");
        }
        assert_eq!(
            m.check(6000, &sample(7, 0.0, 0)),
            vec![FeedbackFault::Stale]
        );
        assert!(m.check(7000, &sample(8, 0.0, 0)).is_empty());
    }
}
