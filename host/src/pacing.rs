//! Absolute-deadline 1 kHz pacing and its own measurement of period and deadline misses.
//!
//! ```text
//!  deadline k        deadline k+1       deadline k+2
//!      |<---- 1 ms ---->|<---- 1 ms ---->|
//!      | work | sleep   |spin| work | ... |
//!                 ^ wake at deadline - spin, then busy-wait to the deadline
//! ```
//!
//! The next deadline is always `previous deadline + period`, never `now + period`, so lateness in
//! one cycle does not accumulate (the seed's `sleep(0.001)` loop drifts by its own overhead every
//! cycle). A cycle that wakes more than one period late skips the deadlines it missed instead of
//! bursting to catch up; the skipped ones are counted.

use std::time::{Duration, Instant};

/// The contract of seed 000: a new command every 1 ms ± 0.2 ms.
pub const CONTRACT_PERIOD: Duration = Duration::from_micros(1000);
/// Allowed deviation of one period from [`CONTRACT_PERIOD`].
pub const CONTRACT_TOLERANCE: Duration = Duration::from_micros(200);

/// Width of one histogram bin, µs.
pub const BIN_US: u64 = 50;
/// Number of histogram bins (the last one collects everything longer).
pub const BINS: usize = 100;

/// Statistics of measured periods against a nominal period and tolerance.
#[derive(Clone, Debug)]
pub struct PeriodStats {
    nominal_us: f64,
    tolerance_us: f64,
    /// Periods measured.
    pub count: u64,
    /// Periods outside nominal ± tolerance.
    pub misses: u64,
    /// Periods longer than nominal + tolerance.
    pub late: u64,
    /// Periods shorter than nominal − tolerance.
    pub early: u64,
    /// Deadlines skipped because a cycle overran by more than a whole period.
    pub skipped: u64,
    /// Shortest period, µs.
    pub min_us: f64,
    /// Longest period, µs.
    pub max_us: f64,
    sum_us: f64,
    sum_sq_us: f64,
    /// Period histogram, [`BIN_US`] µs per bin.
    pub histogram: Vec<u64>,
}

impl PeriodStats {
    /// Empty statistics for `nominal` ± `tolerance`.
    pub fn new(nominal: Duration, tolerance: Duration) -> Self {
        Self {
            nominal_us: nominal.as_secs_f64() * 1e6,
            tolerance_us: tolerance.as_secs_f64() * 1e6,
            count: 0,
            misses: 0,
            late: 0,
            early: 0,
            skipped: 0,
            min_us: f64::INFINITY,
            max_us: 0.0,
            sum_us: 0.0,
            sum_sq_us: 0.0,
            histogram: vec![0; BINS],
        }
    }

    /// Records one measured period in µs.
    pub fn record_us(&mut self, period_us: f64) {
        self.count = self.count.saturating_add(1);
        self.min_us = self.min_us.min(period_us);
        self.max_us = self.max_us.max(period_us);
        self.sum_us += period_us;
        self.sum_sq_us += period_us * period_us;
        if period_us > self.nominal_us + self.tolerance_us {
            self.late = self.late.saturating_add(1);
            self.misses = self.misses.saturating_add(1);
        } else if period_us < self.nominal_us - self.tolerance_us {
            self.early = self.early.saturating_add(1);
            self.misses = self.misses.saturating_add(1);
        }
        let bin = (period_us.max(0.0) / BIN_US as f64) as usize;
        let last = BINS.saturating_sub(1);
        if let Some(b) = self.histogram.get_mut(bin.min(last)) {
            *b = b.saturating_add(1);
        }
    }

    /// Mean period, µs (NaN before the first period).
    pub fn mean_us(&self) -> f64 {
        self.sum_us / self.count as f64
    }

    /// Standard deviation of the period, µs.
    pub fn std_us(&self) -> f64 {
        let n = self.count as f64;
        let m = self.mean_us();
        (self.sum_sq_us / n - m * m).max(0.0).sqrt()
    }

    /// Fraction of periods outside the tolerance.
    pub fn miss_rate(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.misses as f64 / self.count as f64
        }
    }

    /// One-line human summary.
    pub fn summary(&self) -> String {
        format!(
            "periods {} | mean {:.1} us | std {:.1} us | min {:.1} us | max {:.1} us | outside {:.0}±{:.0} us: {} ({:.4} %), late {}, early {}, skipped deadlines {}",
            self.count,
            self.mean_us(),
            self.std_us(),
            self.min_us,
            self.max_us,
            self.nominal_us,
            self.tolerance_us,
            self.misses,
            100.0 * self.miss_rate(),
            self.late,
            self.early,
            self.skipped
        )
    }
}

/// Paces a loop at a fixed period with absolute deadlines: sleep until shortly before the deadline,
/// then spin until it.
#[derive(Debug)]
pub struct Pacer {
    period: Duration,
    spin: Duration,
    next: Instant,
    last_wake: Option<Instant>,
    /// Measured periods between consecutive wake-ups.
    pub stats: PeriodStats,
    /// Every measured period, µs, in order, once [`Pacer::keep_periods`] asked for them.
    pub periods: Vec<f64>,
    keep: bool,
}

impl Pacer {
    /// A pacer whose first deadline is one period from now. `spin` is how long before each deadline
    /// the thread stops sleeping and busy-waits (100–200 µs absorbs typical Linux wake-up latency).
    pub fn new(period: Duration, spin: Duration) -> Self {
        Self {
            period,
            spin,
            next: Instant::now()
                .checked_add(period)
                .unwrap_or_else(Instant::now),
            last_wake: None,
            stats: PeriodStats::new(CONTRACT_PERIOD, CONTRACT_TOLERANCE),
            periods: Vec::new(),
            keep: false,
        }
    }

    /// Keeps every period from now on in [`Pacer::periods`], with room for `capacity` of them
    /// reserved now (so a run of known length does not allocate in the loop).
    pub fn keep_periods(&mut self, capacity: usize) {
        self.keep = true;
        self.periods.reserve(capacity);
    }

    /// The seed's contract: 1 ms, with a 150 µs spin.
    pub fn contract() -> Self {
        Self::new(CONTRACT_PERIOD, Duration::from_micros(150))
    }

    /// The deadline the next [`Pacer::wait`] returns at.
    pub fn next_deadline(&self) -> Instant {
        self.next
    }

    fn advance(&mut self) {
        self.next = self.next.checked_add(self.period).unwrap_or(self.next);
    }

    /// Blocks until the next deadline, records the period since the previous wake-up and returns
    /// the wake-up instant.
    pub fn wait(&mut self) -> Instant {
        let now = Instant::now();
        let wake_sleep = self.next.checked_sub(self.spin).unwrap_or(self.next);
        if let Some(d) = wake_sleep.checked_duration_since(now) {
            std::thread::sleep(d);
        }
        while Instant::now() < self.next {
            std::hint::spin_loop();
        }
        let woke = Instant::now();
        if let Some(prev) = self.last_wake {
            let period_us = woke.duration_since(prev).as_secs_f64() * 1e6;
            self.stats.record_us(period_us);
            if self.keep {
                self.periods.push(period_us);
            }
        }
        self.last_wake = Some(woke);
        self.advance();
        // Overran by more than a period: skip the missed deadlines rather than burst.
        while self.next <= woke {
            self.advance();
            self.stats.skipped = self.stats.skipped.saturating_add(1);
        }
        woke
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::float_cmp,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
mod tests {
    use super::*;

    #[test]
    fn classifies_against_the_contract() {
        let mut s = PeriodStats::new(CONTRACT_PERIOD, CONTRACT_TOLERANCE);
        for p in [1000.0, 800.0, 1200.0, 799.0, 1201.0, 5000.0] {
            s.record_us(p);
        }
        assert_eq!(s.count, 6);
        assert_eq!(s.misses, 3);
        assert_eq!(s.late, 2);
        assert_eq!(s.early, 1);
        assert_eq!(s.min_us, 799.0);
        assert_eq!(s.max_us, 5000.0);
        assert_eq!(s.histogram[20], 1); // 1000 us
        assert_eq!(s.histogram[BINS - 1], 1); // 5000 us overflows into the last bin
    }

    #[test]
    fn deadlines_are_absolute() {
        // Work of 300 us per 2 ms cycle: deadlines advance by exactly one period per cycle (plus
        // any skipped ones), independent of how long the work or the wake-up took.
        let period = Duration::from_millis(2);
        let mut p = Pacer::new(period, Duration::from_micros(200));
        let first = p.next_deadline();
        let woke = p.wait();
        assert!(woke >= first);
        for _ in 0..20 {
            let t = Instant::now();
            while t.elapsed() < Duration::from_micros(300) {}
            let w = p.wait();
            assert!(w >= first);
        }
        let cycles = 21 + u32::try_from(p.stats.skipped).unwrap();
        assert_eq!(p.next_deadline(), first + period * cycles);
        assert_eq!(p.stats.count, 20);
    }

    #[test]
    fn kept_periods_are_the_recorded_ones() {
        let mut p = Pacer::new(Duration::from_millis(1), Duration::from_micros(150));
        p.wait();
        p.wait();
        assert!(p.periods.is_empty(), "nothing kept before it is asked for");
        p.keep_periods(8);
        for _ in 0..5 {
            p.wait();
        }
        assert_eq!(p.periods.len(), 5);
        assert_eq!(p.stats.count, 6);
        let max = p.periods.iter().copied().fold(0.0, f64::max);
        assert_eq!(max.max(p.stats.max_us), p.stats.max_us);
    }
}
