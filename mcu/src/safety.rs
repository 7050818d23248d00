//! The safety core as the board runs it: the ladder, the tick count, and the trace of what the
//! ladder did. Both priority-2 tasks (frames and ticks) step the ladder only through
//! [`Safety::step`], so every mode change, latch and re-arm is recorded whichever task caused it.

use crate::trace::{Record, Trace};
use crate::AXES;
use statemachine::{Config, Event, FaultFlags, Ladder, Mode, Output};

/// What the trace compares across one ladder step.
#[derive(Clone, Copy)]
struct Marks {
    mode: Mode,
    rearms: u32,
    rearm_refused: u32,
    brake_entries: u32,
}

impl Marks {
    fn of<const N: usize>(l: &Ladder<N>) -> Self {
        let c = l.counters();
        Self {
            mode: l.mode(),
            rearms: c.rearms,
            rearm_refused: c.rearm_refused,
            brake_entries: c.brake_entries,
        }
    }
}

/// Ladder, tick count and trace, over the board's `N` axes (the seed 000 board's [`AXES`] unless
/// named: 4 for the seed 001 and seed 003 boards).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Safety<const N: usize = AXES> {
    ladder: Ladder<N>,
    ticks: u32,
    trace: Trace,
    /// Under Kani only: the events the stand-in of [`Safety::apply`] recorded in place of the
    /// ladder's steps (`verification::event_log`): the first two, then how many.
    #[cfg(kani)]
    pub(crate) seen: [u8; 3],
}

impl<const N: usize> Safety<N> {
    /// Power-on state: BRAKE latched until the host arms (see [`Ladder::new`]).
    pub const fn new(cfg: Config) -> Self {
        Self {
            ladder: Ladder::new(cfg),
            ticks: 0,
            trace: Trace::new(),
            #[cfg(kani)]
            seen: [0; 3],
        }
    }

    /// The board's safety core around an existing ladder state: for proofs that start from any
    /// state satisfying [`Ladder::is_valid`] (an over-approximation of the reachable states).
    pub const fn from_ladder(ladder: Ladder<N>) -> Self {
        Self {
            ladder,
            ticks: 0,
            trace: Trace::new(),
            #[cfg(kani)]
            seen: [0; 3],
        }
    }

    /// Feeds one event to the ladder and records what changed.
    pub fn step(&mut self, event: Event<N>) -> Output<N> {
        self.apply(event);
        self.ladder.output()
    }

    /// Steps the ladder and records what changed, without building its output: for the events the
    /// tick applies before the tick itself (ESTOP input, board conditions).
    pub fn apply(&mut self, event: Event<N>) {
        // Only what the trace compares is kept from before the step (not a copy of the ladder:
        // this runs for every received frame).
        let before = Marks::of(&self.ladder);
        self.ladder.update(event);
        self.record(&before);
    }

    /// One watchdog tick: counts it, then steps the ladder.
    pub(crate) fn tick(&mut self) -> Output<N> {
        self.ticks = self.ticks.wrapping_add(1);
        self.step(Event::Tick)
    }

    fn record(&mut self, before: &Marks) {
        let t = self.ticks;
        let now = Marks::of(&self.ladder);
        if now.rearms != before.rearms {
            self.trace.push(t, Record::Rearmed);
        }
        if now.rearm_refused != before.rearm_refused {
            self.trace.push(t, Record::RearmRefused);
        }
        if now.mode != before.mode {
            self.trace.push(
                t,
                Record::Mode {
                    from: before.mode,
                    to: now.mode,
                },
            );
        }
        if now.brake_entries != before.brake_entries {
            let causes = self
                .ladder
                .faults()
                .without(FaultFlags::BRAKE_LATCHED)
                .without(FaultFlags::LINK_DEGRADED);
            self.trace.push(t, Record::Latched(causes));
        }
    }

    /// The ladder (read only: events go through [`Safety::step`]).
    pub const fn ladder(&self) -> &Ladder<N> {
        &self.ladder
    }

    /// The ladder's current output.
    pub fn output(&self) -> Output<N> {
        self.ladder.output()
    }

    /// The current rung.
    pub const fn mode(&self) -> Mode {
        self.ladder.mode()
    }

    /// Watchdog ticks since boot (wrapping).
    pub const fn ticks(&self) -> u32 {
        self.ticks
    }

    /// The trace.
    pub const fn trace(&self) -> &Trace {
        &self.trace
    }

    /// Microseconds since boot from the tick timer's counter (see [`crate::timing::micros`]).
    pub const fn micros(
        &self,
        count: u32,
        update_pending: bool,
        counts_per_tick: u32,
        us_per_tick: u32,
    ) -> u32 {
        crate::timing::micros(
            self.ticks,
            count,
            update_pending,
            counts_per_tick,
            us_per_tick,
        )
    }
}
