//! `speed_pid` (priority 3, 10 kHz timer): encoder counters → speed estimate → reference ramp →
//! speed PID → current references for the current loop.

use crate::tuning::Tuning;
use control::{Amps, RateLimiter, SpeedEstimator, SpeedPid};
use statemachine::Speed;

/// What one speed-loop run produced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SpeedSample {
    /// Current references for the current loop, A [left, right].
    pub refs: [Amps; 2],
    /// Speed estimates, rad/s.
    pub speeds: [Speed; 2],
    /// Cumulative encoder counts.
    pub totals: [i32; 2],
}

/// One wheel's speed cascade.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Axis {
    estimator: SpeedEstimator,
    ramp: RateLimiter,
    pid: SpeedPid,
}

impl Axis {
    const fn new(t: &Tuning, count: u16) -> Self {
        Self {
            estimator: SpeedEstimator::new(count, t.speed_scale),
            ramp: RateLimiter::new(t.ref_step(), Speed::ZERO),
            pid: SpeedPid::new(t.speed),
        }
    }

    fn step(&mut self, count: u16, setpoint: Option<Speed>) -> (Speed, Amps) {
        let w = self.estimator.update(count);
        let i = match setpoint {
            Some(target) => self.pid.step(self.ramp.step(target), w),
            None => {
                self.ramp.reset(Speed::ZERO);
                self.pid.reset(w);
                Amps::ZERO
            }
        };
        (w, i)
    }
}

/// The speed loop's own state: estimators, reference ramps and PIDs of both wheels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpeedLoop {
    axes: [Axis; 2],
}

impl SpeedLoop {
    /// Both wheels at rest, the encoder counters reading `counts`.
    pub const fn new(t: &Tuning, counts: [u16; 2]) -> Self {
        let [cl, cr] = counts;
        Self {
            axes: [Axis::new(t, cl), Axis::new(t, cr)],
        }
    }

    /// One run: `setpoint` is what the ladder last allowed, `None` in BRAKE (the ramps and PIDs
    /// are reset and no current is asked for).
    pub fn run(&mut self, counts: [u16; 2], setpoint: Option<[Speed; 2]>) -> SpeedSample {
        let [al, ar] = &mut self.axes;
        let [cl, cr] = counts;
        let (sl, sr) = match setpoint {
            Some([l, r]) => (Some(l), Some(r)),
            None => (None, None),
        };
        let (wl, il) = al.step(cl, sl);
        let (wr, ir) = ar.step(cr, sr);
        SpeedSample {
            refs: [il, ir],
            speeds: [wl, wr],
            totals: [al.estimator.total(), ar.estimator.total()],
        }
    }

    /// The ramped references the PIDs last followed [left, right].
    pub fn references(&self) -> [Speed; 2] {
        let [al, ar] = &self.axes;
        [al.ramp.value(), ar.ramp.value()]
    }
}
