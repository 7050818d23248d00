//! `estop_input` (priority 5, the highest: EXTI on both edges of the local ESTOP input): the
//! bridge is braked inside the edge handler itself, and the press is latched until the next tick
//! reports it to the ladder, so a press shorter than a tick is never missed.
//!
//! ```text
//!  input   ‾‾‾‾‾\_____/‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾          (pressed = low)
//!  EXTI         ↓ edge(): bridge Brake, latch
//!  tick            │ poll(): Estop::Engage → ladder BRAKE latched (ESTOP)
//!  tick                  │ poll(): released, nothing latched → Estop::Release (BRAKE stays
//!                                  latched until the host re-arms)
//! ```

use crate::hw::Bridge;
use control::BridgeState;
use statemachine::Estop;

/// The local ESTOP input's state between its edge handler and the tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EstopInput {
    pressed_since_poll: bool,
    engaged: bool,
}

impl EstopInput {
    /// Released, nothing latched.
    pub const fn new() -> Self {
        Self {
            pressed_since_poll: false,
            engaged: false,
        }
    }

    /// The edge handler: `pressed` is the input's level after the edge. A press brakes the bridge
    /// at once, before any other task runs. Returns true for a press.
    pub fn edge(&mut self, bridge: &mut impl Bridge, pressed: bool) -> bool {
        self.edge_then(pressed, || bridge.apply(BridgeState::Brake))
    }

    /// [`EstopInput::edge`] for a board whose outputs are not the two H-bridges: `stop` is what
    /// takes them to their safe state at once (the seed 001 motors shorted, the seed 003 steppers
    /// halted); it runs only on a press.
    pub fn edge_then(&mut self, pressed: bool, stop: impl FnOnce()) -> bool {
        if pressed {
            stop();
            self.pressed_since_poll = true;
        }
        pressed
    }

    /// Called once per tick with the input's level: the ladder event to feed, if the engaged
    /// state changed. Engaged = pressed now or pressed at any time since the last poll.
    pub fn poll(&mut self, pressed_now: bool) -> Option<Estop> {
        let engaged = pressed_now || self.pressed_since_poll;
        self.pressed_since_poll = false;
        let event = match (self.engaged, engaged) {
            (false, true) => Some(Estop::Engage),
            (true, false) => Some(Estop::Release),
            _ => None,
        };
        self.engaged = engaged;
        event
    }

    /// True if a press came after the last poll (the bridge was braked by [`EstopInput::edge`]).
    pub const fn press_pending(&self) -> bool {
        self.pressed_since_poll
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hw::RecordingBridge;

    #[test]
    fn a_press_brakes_at_once_and_each_change_is_reported_once() {
        let mut e = EstopInput::new();
        let mut b = RecordingBridge::new(4200);
        b.apply(BridgeState::Run);
        assert!(e.edge(&mut b, true));
        assert_eq!(b.state, BridgeState::Brake);
        assert!(e.press_pending());
        // Released again before the tick: the press is still reported, then cleared.
        assert!(!e.edge(&mut b, false));
        assert_eq!(e.poll(false), Some(Estop::Engage));
        assert!(!e.press_pending());
        // No press since the last poll and the input released: the release, once.
        assert_eq!(e.poll(false), Some(Estop::Release));
        assert_eq!(e.poll(false), None);
        // Held across polls: one engage, then nothing until it is let go.
        assert_eq!(e.poll(true), Some(Estop::Engage));
        assert_eq!(e.poll(true), None);
        assert_eq!(e.poll(false), Some(Estop::Release));
    }
}
