//! What the safety core did, kept on the board: a ring of the last [`TRACE_LEN`] records (mode
//! changes, latch causes, re-arms) with the tick they happened at, and a running count, so a
//! debugger or a crash dump shows the history that led to a stop. Each record is also logged with
//! defmt when the `defmt` feature is on.

use statemachine::{FaultFlags, Mode};

/// Records kept.
pub const TRACE_LEN: usize = 32;

/// One thing the safety core did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Record {
    /// Nothing recorded in this slot yet.
    None,
    /// The ladder changed rung.
    Mode {
        /// Rung before.
        from: Mode,
        /// Rung after.
        to: Mode,
    },
    /// BRAKE latched, for these causes.
    Latched(FaultFlags),
    /// A re-arm released BRAKE.
    Rearmed,
    /// A re-arm was refused (a latching cause still active).
    RearmRefused,
}

/// A record with its time stamp.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    /// Watchdog ticks since boot when it happened.
    pub tick: u32,
    /// What happened.
    pub record: Record,
}

/// The ring buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Trace {
    entries: [Entry; TRACE_LEN],
    next: usize,
    total: u32,
}

impl Default for Trace {
    fn default() -> Self {
        Self::new()
    }
}

impl Trace {
    /// An empty trace.
    pub const fn new() -> Self {
        Self {
            entries: [Entry {
                tick: 0,
                record: Record::None,
            }; TRACE_LEN],
            next: 0,
            total: 0,
        }
    }

    /// Adds a record, overwriting the oldest once full.
    pub fn push(&mut self, tick: u32, record: Record) {
        #[cfg(feature = "defmt")]
        log(tick, &record);
        let i = self.next % TRACE_LEN;
        if let Some(slot) = self.entries.get_mut(i) {
            *slot = Entry { tick, record };
        }
        self.next = i.wrapping_add(1) % TRACE_LEN;
        self.total = self.total.saturating_add(1);
    }

    /// Records ever pushed (saturating).
    pub const fn total(&self) -> u32 {
        self.total
    }

    /// The records still held, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &Entry> {
        let (newer, older) = self.entries.split_at(self.next % TRACE_LEN);
        older
            .iter()
            .chain(newer.iter())
            .filter(|e| e.record != Record::None)
    }
}

#[cfg(feature = "defmt")]
fn log(tick: u32, record: &Record) {
    match record {
        Record::None => {}
        Record::Mode { from, to } => defmt::info!("t={=u32} mode {} -> {}", tick, from, to),
        Record::Latched(c) => defmt::warn!("t={=u32} BRAKE latched, causes {=u16:#x}", tick, c.0),
        Record::Rearmed => defmt::info!("t={=u32} re-armed", tick),
        Record::RearmRefused => defmt::warn!("t={=u32} re-arm refused", tick),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_newest_in_order() {
        let mut t = Trace::new();
        assert_eq!(t.iter().count(), 0);
        for k in 0..(TRACE_LEN as u32 + 5) {
            t.push(k, Record::Rearmed);
        }
        let ticks: [u32; TRACE_LEN] = core::array::from_fn(|i| i as u32 + 5);
        assert!(t.iter().map(|e| e.tick).eq(ticks.iter().copied()));
        assert_eq!(t.total(), TRACE_LEN as u32 + 5);
    }
}
