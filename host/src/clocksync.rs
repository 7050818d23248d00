//! Host ↔ MCU clock synchronisation from link round trips: filtered offset plus skew, with
//! round-trip-time and deviation outlier rejection.
//!
//! Each exchange gives a triple (host send time t1, MCU timestamp t2, host receive time t3).
//! Assuming the MCU stamp lies in the middle of the exchange, one sample of the offset is
//! `t2 − (t1 + t3) / 2`. The seed filters these samples with a fixed EMA and no skew term, so a
//! 50 ppm crystal (50 µs/s) leaves a steady lag of `drift / alpha` (5 ms at alpha = 0.01) and one
//! preempted read moves the estimate by 1 % of its error. Here, as in PX4's timesync:
//! - samples whose round trip is much longer than the best recent one are dropped (a preempted
//!   read makes the midpoint wrong by half of the extra delay);
//! - the offset and its rate (skew) are tracked by a double-exponential (Holt) filter, so a
//!   constant drift leaves no steady error and the estimate extrapolates across gaps;
//! - the filter gains start high and shrink as samples converge;
//! - once converged, samples deviating by more than a bound are dropped; many in a row mean the
//!   MCU clock jumped (reset) and the filter restarts.
//!
//! ```text
//!  host   t1 ──────────────────────── t3        offset sample = t2 − (t1 + t3)/2
//!            \  SPI exchange        /           rtt = t3 − t1
//!  MCU        ─────── t2 ──────────
//! ```

/// Tuning of [`ClockSync`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockSyncConfig {
    /// Offset gain for the first samples.
    pub alpha_initial: f64,
    /// Offset gain once converged.
    pub alpha_final: f64,
    /// Skew gain (relative to alpha) for the first samples.
    pub beta_initial: f64,
    /// Skew gain once converged.
    pub beta_final: f64,
    /// Accepted samples over which the gains move from initial to final.
    pub converge_samples: u32,
    /// Round trips longer than this are always refused, µs.
    pub rtt_max_us: f64,
    /// A round trip more than this above the best recent one is refused, µs.
    pub rtt_margin_us: f64,
    /// Once converged, residuals larger than this are refused, µs.
    pub max_deviation_us: f64,
    /// Consecutive refused residuals after which the filter restarts (clock jump).
    pub reset_after: u32,
    /// No accepted sample for this long (host µs) means sync is lost.
    pub lost_after_us: f64,
}

impl ClockSyncConfig {
    /// Figures for a 1 kHz link: gains 0.05 → 0.002, skew gain 0.05 → 0.01 over 5000 samples;
    /// round trips more than 150 µs above the best are dropped; 2 ms deviation bound.
    pub const DEFAULT: Self = Self {
        alpha_initial: 0.05,
        alpha_final: 0.002,
        beta_initial: 0.05,
        beta_final: 0.01,
        converge_samples: 5000,
        rtt_max_us: 5000.0,
        rtt_margin_us: 150.0,
        max_deviation_us: 2000.0,
        reset_after: 50,
        lost_after_us: 500_000.0,
    };
}

impl Default for ClockSyncConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What happened to one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum SampleOutcome {
    /// The first sample: offset initialised.
    Initialised = 0,
    /// Used to update the filter.
    Accepted = 1,
    /// Refused: round trip too long (preempted or delayed read).
    RttOutlier = 2,
    /// Refused: residual beyond the deviation bound.
    DeviationOutlier = 3,
    /// Too many deviations in a row: the filter restarted from this sample.
    Reset = 4,
    /// Refused: timestamps out of order (t3 < t1).
    Invalid = 5,
}

/// Offset and skew estimator between the host clock and the MCU clock (both in µs).
#[derive(Clone, Debug)]
pub struct ClockSync {
    cfg: ClockSyncConfig,
    /// Host time of the filter state, µs.
    ref_host: f64,
    /// MCU − host at `ref_host`, µs.
    offset: f64,
    /// d(offset)/d(host time), dimensionless (µs per µs).
    skew: f64,
    initialised: bool,
    accepted: u32,
    deviations_in_row: u32,
    /// Best recent round trip, µs; decays upward slowly so a lucky sample does not pin it.
    rtt_floor: f64,
    /// Counts per outcome, indexed by the outcome's value.
    pub counts: [u64; 6],
}

impl ClockSync {
    /// An estimator with no samples yet.
    pub fn new(cfg: ClockSyncConfig) -> Self {
        Self {
            cfg,
            ref_host: 0.0,
            offset: 0.0,
            skew: 0.0,
            initialised: false,
            accepted: 0,
            deviations_in_row: 0,
            rtt_floor: f64::INFINITY,
            counts: [0; 6],
        }
    }

    fn gains(&self) -> (f64, f64) {
        let n = f64::from(self.cfg.converge_samples.max(1));
        let k = (f64::from(self.accepted) / n).min(1.0);
        let a = self.cfg.alpha_initial + (self.cfg.alpha_final - self.cfg.alpha_initial) * k;
        let b = self.cfg.beta_initial + (self.cfg.beta_final - self.cfg.beta_initial) * k;
        (a, b)
    }

    fn count(&mut self, o: SampleOutcome) -> SampleOutcome {
        if let Some(c) = self.counts.get_mut(o as usize) {
            *c = c.saturating_add(1);
        }
        o
    }

    /// Feeds one exchange: host send time, MCU timestamp, host receive time (µs).
    pub fn update(&mut self, t1_host: u64, t2_mcu: u64, t3_host: u64) -> SampleOutcome {
        if t3_host < t1_host {
            return self.count(SampleOutcome::Invalid);
        }
        let rtt = t3_host.saturating_sub(t1_host) as f64;
        let mid = t1_host as f64 + rtt / 2.0;
        let sample = t2_mcu as f64 - mid;
        if !self.initialised {
            self.restart(mid, sample, rtt);
            return self.count(SampleOutcome::Initialised);
        }
        // The floor creeps up by 1 µs per sample so that it follows a slower link.
        self.rtt_floor = (self.rtt_floor + 1.0).min(rtt);
        if rtt > self.cfg.rtt_max_us || rtt > self.rtt_floor + self.cfg.rtt_margin_us {
            return self.count(SampleOutcome::RttOutlier);
        }
        let dt = mid - self.ref_host;
        let predicted = self.offset + self.skew * dt;
        let residual = sample - predicted;
        let converged = self.accepted >= self.cfg.converge_samples / 10;
        if converged && residual.abs() > self.cfg.max_deviation_us {
            self.deviations_in_row = self.deviations_in_row.saturating_add(1);
            if self.deviations_in_row >= self.cfg.reset_after {
                self.restart(mid, sample, rtt);
                return self.count(SampleOutcome::Reset);
            }
            return self.count(SampleOutcome::DeviationOutlier);
        }
        self.deviations_in_row = 0;
        let (alpha, beta) = self.gains();
        self.offset = predicted + alpha * residual;
        if dt > 0.0 {
            self.skew += alpha * beta * residual / dt;
        }
        self.ref_host = mid;
        self.accepted = self.accepted.saturating_add(1);
        self.count(SampleOutcome::Accepted)
    }

    fn restart(&mut self, mid: f64, sample: f64, rtt: f64) {
        self.initialised = true;
        self.ref_host = mid;
        self.offset = sample;
        self.skew = 0.0;
        self.accepted = 0;
        self.deviations_in_row = 0;
        self.rtt_floor = rtt;
    }

    /// True once at least one sample was taken and the last accepted one is recent.
    pub fn is_synced(&self, host_now: u64) -> bool {
        self.initialised && (host_now as f64 - self.ref_host) < self.cfg.lost_after_us
    }

    /// Estimated MCU − host offset at host time `host`, µs.
    pub fn offset_at(&self, host: f64) -> Option<f64> {
        self.initialised
            .then_some(self.offset + self.skew * (host - self.ref_host))
    }

    /// Estimated skew of the MCU clock against the host's, parts per million.
    pub fn skew_ppm(&self) -> f64 {
        self.skew * 1e6
    }

    /// Host time at which the MCU clock read `mcu`, µs.
    pub fn mcu_to_host(&self, mcu: u64) -> Option<f64> {
        if !self.initialised {
            return None;
        }
        // mcu = host + offset + skew (host − ref)  ⇒  host = (mcu − offset + skew ref) / (1 + skew)
        let m = mcu as f64;
        Some((m - self.offset + self.skew * self.ref_host) / (1.0 + self.skew))
    }

    /// MCU clock reading at host time `host`, µs.
    pub fn host_to_mcu(&self, host: u64) -> Option<f64> {
        let h = host as f64;
        self.offset_at(h).map(|o| h + o)
    }
}

/// The seed's estimator, kept for comparison: EMA with alpha = 0.01, integer µs, no skew, no outlier rejection.
#[derive(Clone, Debug, Default)]
pub struct SeedClockSync {
    /// Host − MCU, µs (the seed's sign).
    pub offset_us: i64,
}

impl SeedClockSync {
    /// The seed's `update`.
    pub fn update(&mut self, t1_host: u64, t2_mcu: u64, t3_host: u64) {
        let rtt = (t3_host as i64).saturating_sub(t1_host as i64);
        let mid = (t1_host as i64).saturating_add(rtt / 2);
        let raw = mid.saturating_sub(t2_mcu as i64);
        self.offset_us = (0.01 * raw as f64 + 0.99 * self.offset_us as f64) as i64;
    }

    /// The seed's `mcu_to_jetson_time`.
    pub fn mcu_to_host(&self, mcu: u64) -> f64 {
        mcu as f64 + self.offset_us as f64
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::indexing_slicing
)]
mod tests {
    use super::*;

    /// Deterministic xorshift for jitter.
    fn rng(state: &mut u64) -> f64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// MCU clock: 50 ppm fast and 123456 µs ahead; symmetric 100 µs exchange with jitter and
    /// 1 % preempted reads of 1–3 ms.
    fn run(seconds: u64) -> (ClockSync, f64) {
        let mut cs = ClockSync::new(ClockSyncConfig::DEFAULT);
        let mut s = 0x1234_5678_9abc_def1u64;
        let mut worst_last_second = 0.0f64;
        for k in 0..seconds * 1000 {
            let t1 = k * 1000 + 10;
            let true_mid = t1 as f64 + 50.0;
            let t2 = (true_mid * (1.0 + 50e-6) + 123_456.0).round() as u64;
            let mut back = 50.0 + 20.0 * rng(&mut s);
            if rng(&mut s) < 0.01 {
                back += 1000.0 + 2000.0 * rng(&mut s);
            }
            let t3 = (true_mid + back) as u64;
            cs.update(t1, t2, t3);
            if k >= (seconds - 1) * 1000 {
                let est = cs.mcu_to_host(t2).unwrap();
                worst_last_second = worst_last_second.max((est - true_mid).abs());
            }
        }
        (cs, worst_last_second)
    }

    #[test]
    fn tracks_50_ppm_with_outliers() {
        let (cs, worst) = run(120);
        // Residual error: half the mean return-path jitter (10 µs / 2) plus filter noise.
        assert!(worst < 20.0, "worst error {worst} us");
        assert!((cs.skew_ppm() - 50.0).abs() < 2.0, "skew {}", cs.skew_ppm());
        assert!(cs.counts[SampleOutcome::RttOutlier as usize] > 900);
    }

    #[test]
    fn seed_filter_lags_under_drift() {
        // Independent figures: an EMA with gain a tracking a ramp of r per sample lags by
        // r (1 − a) / a = 0.05 µs × 99 ≈ 5 µs at 50 ppm and 1 kHz; worse, the seed's int()
        // truncation moves the estimate only once 0.01 × error reaches 1 µs, so the error
        // grows to about 100 µs before the estimate follows.
        let mut seed = SeedClockSync::default();
        let mut worst = 0.0f64;
        for k in 0..60_000u64 {
            let t1 = k * 1000;
            let mid = t1 as f64 + 50.0;
            let t2 = (mid * (1.0 + 50e-6)) as u64;
            seed.update(t1, t2, t1 + 100);
            if k > 50_000 {
                worst = worst.max((seed.mcu_to_host(t2) - mid).abs());
            }
        }
        assert!(worst > 90.0, "{worst}");
    }

    #[test]
    fn restarts_after_a_clock_jump() {
        let mut cs = ClockSync::new(ClockSyncConfig::DEFAULT);
        for k in 0..2000u64 {
            cs.update(k * 1000, k * 1000 + 50 + 7000, k * 1000 + 100);
        }
        // MCU reset: its clock restarts near zero.
        let mut last = SampleOutcome::Accepted;
        for k in 2000..2100u64 {
            last = cs.update(k * 1000, (k - 2000) * 1000 + 50, k * 1000 + 100);
            if last == SampleOutcome::Reset {
                break;
            }
        }
        assert_eq!(last, SampleOutcome::Reset);
        let off = cs.offset_at(2_100_000.0).unwrap();
        assert!((off + 2_000_000.0).abs() < 1.0, "{off}");
    }

    #[test]
    fn refuses_reversed_timestamps() {
        let mut cs = ClockSync::new(ClockSyncConfig::DEFAULT);
        assert_eq!(cs.update(100, 5, 50), SampleOutcome::Invalid);
        assert!(cs.mcu_to_host(5).is_none());
    }
}
