//! What the byte-stream link profiles (seed 001 `cdc`, seed 003 `teensy`) share: the transmit
//! queue the board's UART or USB endpoint drains, and the watchdog tick of a board without
//! control loops of its own to monitor.
//!
//! ```text
//!  link_rx  (priority 2, per received byte)   cdc::CdcLinkTask / teensy::TeensyLinkTask::on_byte
//!      byte → stream decoder → ladder event (Safety::step) → reply frame queued in TxQueue
//!  link_tx  (priority 1, transmitter empty)   TxQueue::pop → data register
//!  watchdog_tick (priority 2, 1 kHz)          serial::tick → outputs of the profile's drive stage
//! ```
//!
//! A reply that does not fit the queue is dropped whole (never a partial frame, which would cost
//! the host the next frame too) and counted in [`TxQueue::dropped`].

use crate::safety::Safety;
use statemachine::{Estop, Event, Output, Source};

/// Bytes waiting for the transmitter, in frames pushed whole.
#[derive(Clone, Debug)]
pub struct TxQueue<const CAP: usize> {
    q: heapless::Deque<u8, CAP>,
    dropped: u32,
}

impl<const CAP: usize> Default for TxQueue<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> TxQueue<CAP> {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            q: heapless::Deque::new(),
            dropped: 0,
        }
    }

    /// Queues `frame` whole, or not at all (counted) if it does not fit. Returns whether it was
    /// queued.
    pub fn push_frame(&mut self, frame: &[u8]) -> bool {
        if frame.len() > CAP.saturating_sub(self.q.len()) {
            self.dropped = self.dropped.saturating_add(1);
            return false;
        }
        for &b in frame {
            // Cannot fail: the room was checked above.
            let _ = self.q.push_back(b);
        }
        true
    }

    /// Puts `bytes` back at the front, in order: for a transmitter that took fewer of the bytes
    /// just popped than it was offered. Returns false (and puts back nothing) if they do not fit.
    pub fn push_front_all(&mut self, bytes: &[u8]) -> bool {
        if bytes.len() > CAP.saturating_sub(self.q.len()) {
            return false;
        }
        for &b in bytes.iter().rev() {
            // Cannot fail: the room was checked above.
            let _ = self.q.push_front(b);
        }
        true
    }

    /// The next byte to send.
    pub fn pop(&mut self) -> Option<u8> {
        self.q.pop_front()
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.q.len()
    }

    /// True if nothing waits.
    pub fn is_empty(&self) -> bool {
        self.q.is_empty()
    }

    /// Frames dropped because the queue was full (saturating).
    pub const fn dropped(&self) -> u32 {
        self.dropped
    }
}

/// What the tick of a serial-link board reads from the board.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SerialTickInputs {
    /// The local ESTOP input's change since the last tick ([`crate::EstopInput::poll`]).
    pub estop: Option<Estop>,
    /// The supply is below the board's minimum (battery voltage from the ADC).
    pub undervoltage: bool,
}

/// `watchdog_tick` of a serial-link board (priority 2, 1 kHz): the local ESTOP input and the
/// supply as ladder events, then the tick. The caller applies the output through its profile's
/// drive stage ([`crate::cdc::motor_outputs`], [`crate::teensy::Joints::tick`]). Not inlined,
/// so the budget report can count it as one unit.
#[inline(never)]
pub fn tick<const N: usize>(safety: &mut Safety<N>, inputs: &SerialTickInputs) -> Output<N> {
    if let Some(action) = inputs.estop {
        safety.apply(Event::Estop {
            source: Source::Local,
            action,
        });
    }
    safety.apply(Event::Condition {
        condition: statemachine::Condition::Undervoltage,
        active: inputs.undervoltage,
    });
    safety.tick()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_is_queued_whole_or_dropped_and_counted() {
        let mut q = TxQueue::<8>::new();
        assert_eq!(q.dropped(), 0);
        assert!(q.push_frame(&[1, 2, 3, 4, 5]));
        assert!(!q.is_empty());
        assert!(
            !q.push_frame(&[6, 7, 8, 9]),
            "4 bytes do not fit in the 3 left"
        );
        assert_eq!(q.dropped(), 1);
        assert!(!q.push_frame(&[6, 7, 8, 9]));
        assert_eq!(q.dropped(), 2);
        assert!(q.push_frame(&[6, 7, 8]));
        let (a, b) = (q.pop(), q.pop());
        assert!(
            q.push_front_all(&[1, 2]),
            "the two bytes a transmitter did not take"
        );
        assert_eq!((a, b), (Some(1), Some(2)));
        let out: std::vec::Vec<u8> = core::iter::from_fn(|| q.pop()).collect();
        assert_eq!(out, [1, 2, 3, 4, 5, 6, 7, 8]);
        assert!(q.is_empty());
    }

    #[test]
    fn bytes_are_put_back_only_if_they_all_fit() {
        let mut q = TxQueue::<4>::new();
        assert!(q.push_frame(&[3, 4]));
        // Room for 2: one byte back leaves room to spare, then two more do not fit.
        assert!(q.push_front_all(&[2]));
        assert!(!q.push_front_all(&[0, 1]));
        assert_eq!(q.len(), 3);
        assert!(q.push_front_all(&[1]));
        assert!(!q.push_front_all(&[0]), "full");
        let out: std::vec::Vec<u8> = core::iter::from_fn(|| q.pop()).collect();
        assert_eq!(out, [1, 2, 3, 4]);
    }

    #[test]
    fn tick_latches_a_local_estop_and_an_undervoltage() {
        let mut s = Safety::<4>::new(statemachine::Config::CDC);
        let out = tick(
            &mut s,
            &SerialTickInputs {
                estop: Some(Estop::Engage),
                undervoltage: true,
            },
        );
        assert_eq!(out.mode, statemachine::Mode::Brake);
        let f = s.ladder().faults();
        assert!(f.contains(statemachine::FaultFlags::ESTOP));
        assert!(f.contains(statemachine::FaultFlags::UNDERVOLTAGE));
        assert_eq!(s.ticks(), 1);
    }
}
