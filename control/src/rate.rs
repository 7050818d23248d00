//! Slew-rate limiter: the output follows the target by at most `max_step` per sample.
//!
//! The ladder updates wheel setpoints at 1 kHz; the speed loop runs at 10 kHz and interpolates
//! between them with `max_step = accel_step / 10`, so the reference has no 1 kHz staircase.

use crate::Q;

/// A slew-rate limiter with a symmetric step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RateLimiter {
    max_step: Q,
    value: Q,
}

impl RateLimiter {
    /// A limiter at `initial` that moves at most `max_step` per call (a negative step counts as zero).
    pub const fn new(max_step: Q, initial: Q) -> Self {
        let s = if max_step.to_bits() < 0 {
            Q::ZERO
        } else {
            max_step
        };
        Self {
            max_step: s,
            value: initial,
        }
    }

    /// The current output.
    pub const fn value(&self) -> Q {
        self.value
    }

    /// The step limit.
    pub const fn max_step(&self) -> Q {
        self.max_step
    }

    /// Jumps to `value` (used when the drive is braked and the wheels are known to stop).
    pub fn reset(&mut self, value: Q) {
        self.value = value;
    }

    /// Moves toward `target` by at most `max_step` and returns the new output. Never overshoots.
    pub fn step(&mut self, target: Q) -> Q {
        let cur = self.value;
        // The gap is computed in i64: in Q16.16 it could saturate and hide a jump larger than the step.
        let gap = i64::from(target.to_bits()).wrapping_sub(i64::from(cur.to_bits()));
        let step = i64::from(self.max_step.to_bits());
        let next = if gap > step {
            cur.saturating_add(self.max_step)
        } else if gap < step.wrapping_neg() {
            cur.saturating_sub(self.max_step)
        } else {
            target
        };
        self.value = next;
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_up_and_down_in_equal_steps() {
        let mut r = RateLimiter::new(Q::from_num(0.25), Q::ZERO);
        let up: [f64; 5] = [0.25, 0.5, 0.75, 1.0, 1.0];
        for want in up {
            assert_eq!(r.step(Q::ONE), Q::from_num(want));
        }
        let down: [f64; 3] = [0.75, 0.5, 0.4];
        for want in down {
            assert_eq!(r.step(Q::from_num(0.4)), Q::from_num(want));
        }
    }

    #[test]
    fn extreme_targets_do_not_overflow() {
        let mut r = RateLimiter::new(Q::MAX, Q::MIN);
        // The true gap (2³² − 1 LSB) exceeds the step (2³¹ − 1 LSB): one step lands at −1 LSB.
        assert_eq!(r.step(Q::MAX), Q::from_bits(-1));
        // Still one LSB more than a step away.
        assert_eq!(r.step(Q::MAX), Q::from_bits(i32::MAX - 1));
        assert_eq!(r.step(Q::MAX), Q::MAX);
        let mut r = RateLimiter::new(Q::from_num(1), Q::MAX);
        assert_eq!(r.step(Q::MIN), Q::MAX - Q::ONE);
    }

    #[test]
    fn reset_jumps_and_the_ramp_continues_from_there() {
        let mut r = RateLimiter::new(Q::from_num(0.25), Q::ZERO);
        r.reset(Q::from_num(2));
        assert_eq!(r.value(), Q::from_num(2));
        // One step from 2 toward 0, not from 0.
        assert_eq!(r.step(Q::ZERO), Q::from_num(1.75));
        assert_eq!(r.max_step(), Q::from_num(0.25));
    }

    #[test]
    fn negative_step_freezes() {
        let mut r = RateLimiter::new(Q::from_num(-1), Q::from_num(3));
        assert_eq!(r.step(Q::ZERO), Q::from_num(3));
    }
}
