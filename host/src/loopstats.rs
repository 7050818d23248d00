//! Statistics of a paced loop's measured periods against the AMR SPI link's contract (a new
//! command every 1 ms ± 0.2 ms), and the verdict of `motorlink loop-bench`, which compares the
//! Python loop of the original Jetson bridge with the Rust bridge loop on the same machine.
//!
//! Everything here is computed from a list of periods in µs, so the same code judges both loops
//! and the tests feed it lists whose answers are known.
//!
//! ```text
//!  deadline:   0      1      2      3      4      5   (ms)
//!  command:    x      x       x            x      x
//!  period:      1.00   1.05   |--- 2.10 ---| 0.95      2.10 ms: outside the window, and the
//!                                                      deadline at 3 ms passed with no command
//! ```

use serde::Serialize;

/// Nominal period, µs: the AMR SPI link's contract ([`crate::pacing::CONTRACT_PERIOD`]).
pub const NOMINAL_US: f64 = crate::pacing::CONTRACT_PERIOD.as_micros() as f64;
/// Allowed deviation of one period, µs ([`crate::pacing::CONTRACT_TOLERANCE`]).
pub const TOLERANCE_US: f64 = crate::pacing::CONTRACT_TOLERANCE.as_micros() as f64;
/// The goal: the Rust loop has at least this many times fewer periods outside the window.
pub const GOAL_FACTOR: f64 = 10.0;

/// What one loop's periods show.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LoopStats {
    /// Periods measured.
    pub periods: usize,
    /// Periods outside `NOMINAL_US` ± `TOLERANCE_US` (the bounds are inside).
    pub outside: usize,
    /// `outside / periods` (0 without periods).
    pub outside_share: f64,
    /// Deadlines that passed without a command: a period of p µs leaves ⌊p / 1000⌋ − 1 of them
    /// (2 ms or more: one, 3 ms or more: two).
    pub skipped_deadlines: u64,
    /// Median period, µs (nearest rank).
    pub p50_us: f64,
    /// 90th percentile, µs.
    pub p90_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// 99.9th percentile, µs.
    pub p999_us: f64,
    /// Longest period, µs.
    pub max_us: f64,
    /// Mean period, µs.
    pub mean_us: f64,
}

/// The `q`-quantile (0 < q ≤ 1) of `sorted` by nearest rank: the smallest value with at least
/// `q · n` values at or below it. `None` for an empty list.
pub fn nearest_rank(sorted: &[f64], q: f64) -> Option<f64> {
    let n = sorted.len();
    if n == 0 {
        return None;
    }
    let rank = (q * n as f64).ceil().max(1.0) as usize;
    sorted.get(rank.min(n).saturating_sub(1)).copied()
}

impl LoopStats {
    /// The statistics of `periods_us`; non-finite or negative entries are dropped as not
    /// measurements. `None` if no period is left.
    pub fn from_periods(periods_us: &[f64]) -> Option<Self> {
        let mut sorted: Vec<f64> = periods_us
            .iter()
            .copied()
            .filter(|p| p.is_finite() && *p >= 0.0)
            .collect();
        if sorted.is_empty() {
            return None;
        }
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let outside = sorted
            .iter()
            .filter(|&&p| (p - NOMINAL_US).abs() > TOLERANCE_US)
            .count();
        let skipped_deadlines = sorted
            .iter()
            .map(|&p| ((p / NOMINAL_US).floor() as u64).saturating_sub(1))
            .fold(0u64, u64::saturating_add);
        let q = |x: f64| nearest_rank(&sorted, x).unwrap_or(f64::NAN);
        Some(Self {
            periods: n,
            outside,
            outside_share: outside as f64 / n as f64,
            skipped_deadlines,
            p50_us: q(0.5),
            p90_us: q(0.9),
            p99_us: q(0.99),
            p999_us: q(0.999),
            max_us: sorted.last().copied().unwrap_or(f64::NAN),
            mean_us: sorted.iter().sum::<f64>() / n as f64,
        })
    }

    /// Whether every period kept the contract's window and no deadline passed without a command.
    pub fn keeps_window(&self) -> bool {
        self.outside == 0 && self.skipped_deadlines == 0
    }
}

/// The comparison's verdict on the goal (Rust ≥ [`GOAL_FACTOR`]× fewer periods outside the
/// window than Python), on the shares, since the loops complete different numbers of periods in
/// the same time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "goal", rename_all = "snake_case")]
pub enum Goal {
    /// Met: Python's share outside is at least the factor times Rust's (Rust's may be 0).
    Met {
        /// Python's share / Rust's share (`None`: Rust had none outside).
        factor: Option<f64>,
    },
    /// Not met.
    NotMet {
        /// Python's share / Rust's share (`None`: Rust had none outside).
        factor: Option<f64>,
    },
    /// Neither loop left the window: no factor can be measured in this run.
    NotMeasurable,
}

/// Judges the goal from the two loops' statistics.
pub fn goal(python: &LoopStats, rust: &LoopStats) -> Goal {
    let (py, rs) = (python.outside_share, rust.outside_share);
    match (python.outside, rust.outside) {
        (0, 0) => Goal::NotMeasurable,
        (_, 0) => Goal::Met { factor: None },
        _ => {
            let factor = py / rs;
            if factor >= GOAL_FACTOR {
                Goal::Met {
                    factor: Some(factor),
                }
            } else {
                Goal::NotMet {
                    factor: Some(factor),
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::float_cmp, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles_of_one_to_a_thousand() {
        // 1, 2, .., 1000: the q-quantile by nearest rank is 1000·q itself.
        let v: Vec<f64> = (1..=1000).map(f64::from).collect();
        let s = LoopStats::from_periods(&v).unwrap();
        assert_eq!(s.periods, 1000);
        assert_eq!(s.p50_us, 500.0);
        assert_eq!(s.p90_us, 900.0);
        assert_eq!(s.p99_us, 990.0);
        assert_eq!(s.p999_us, 999.0);
        assert_eq!(s.max_us, 1000.0);
        assert_eq!(s.mean_us, 500.5);
        // Below 800 µs: 799 periods outside (1..=799); 800..=1000 inside.
        assert_eq!(s.outside, 799);
        assert_eq!(s.skipped_deadlines, 0);
    }

    #[test]
    fn percentiles_do_not_depend_on_the_order() {
        let v = [1300.0, 900.0, 1000.0, 1100.0];
        let s = LoopStats::from_periods(&v).unwrap();
        // Sorted 900, 1000, 1100, 1300: ranks ⌈0.5·4⌉ = 2, ⌈0.9·4⌉ = 4.
        assert_eq!(s.p50_us, 1000.0);
        assert_eq!(s.p90_us, 1300.0);
        assert_eq!(s.p999_us, 1300.0);
        assert_eq!(nearest_rank(&[], 0.5), None);
        assert_eq!(nearest_rank(&[7.0], 0.001), Some(7.0));
    }

    #[test]
    fn the_window_bounds_are_inside() {
        let s = LoopStats::from_periods(&[1000.0, 800.0, 1200.0, 799.9, 1200.1, 5000.0]).unwrap();
        assert_eq!(s.outside, 3);
        assert_eq!(s.outside_share, 0.5);
        assert!(!s.keeps_window());
        assert!(LoopStats::from_periods(&[800.0, 1000.0, 1200.0])
            .unwrap()
            .keeps_window());
    }

    #[test]
    fn skipped_deadlines_count_whole_missed_milliseconds() {
        // 1.999 ms: none passed; 2.0 ms: one; 3.5 ms: two.
        let s = LoopStats::from_periods(&[1000.0, 1999.0, 2000.0, 3500.0]).unwrap();
        assert_eq!(s.skipped_deadlines, 3);
        assert_eq!(s.outside, 3);
    }

    #[test]
    fn non_measurements_are_dropped() {
        assert!(LoopStats::from_periods(&[]).is_none());
        assert!(LoopStats::from_periods(&[f64::NAN, -1.0]).is_none());
        let s = LoopStats::from_periods(&[f64::INFINITY, 1000.0]).unwrap();
        assert_eq!(s.periods, 1);
    }

    fn stats(outside: usize, of: usize) -> LoopStats {
        let mut v = vec![1000.0; of];
        for p in v.iter_mut().take(outside) {
            *p = 1500.0;
        }
        LoopStats::from_periods(&v).unwrap()
    }

    #[test]
    fn the_goal_compares_shares() {
        // Python 10 % outside, Rust 1 %: exactly ten times fewer.
        assert_eq!(
            goal(&stats(100, 1000), &stats(10, 1000)),
            Goal::Met { factor: Some(10.0) }
        );
        // Python 10 %, Rust 2 %: five times.
        assert_eq!(
            goal(&stats(100, 1000), &stats(20, 1000)),
            Goal::NotMet { factor: Some(5.0) }
        );
        // The same count over twice the periods is half the share.
        assert_eq!(
            goal(&stats(100, 1000), &stats(20, 4000)),
            Goal::Met { factor: Some(20.0) }
        );
        assert_eq!(
            goal(&stats(5, 1000), &stats(0, 1000)),
            Goal::Met { factor: None }
        );
        assert_eq!(goal(&stats(0, 1000), &stats(0, 1000)), Goal::NotMeasurable);
        assert_eq!(
            goal(&stats(0, 1000), &stats(3, 1000)),
            Goal::NotMet { factor: Some(0.0) }
        );
    }
}
