//! The board trait: the one piece of hardware a task body drives itself.
//!
//! Everything else a body decides (the brake-release output, the IWDG refresh, the feedback frame)
//! it returns as plain values; the firmware's board modules and the simulated board carry it out.

use control::{BridgeCompare, BridgeState};

/// The two H-bridges.
///
/// `apply(Brake)` must take effect at once (high sides off, low sides on); `apply(Run)` starts at
/// zero duty. `set` has no effect unless the state is `Run`.
pub trait Bridge {
    /// Auto-reload of the PWM timers: a duty of 1 is this many counts.
    fn pwm_arr(&self) -> u16;
    /// The state last applied.
    fn state(&self) -> BridgeState;
    /// Applies a state (no effect if it is already in force).
    fn apply(&mut self, state: BridgeState);
    /// Writes the compare values of both bridges [left, right].
    fn set(&mut self, compares: [BridgeCompare; 2]);
    /// True if the hardware break (overcurrent comparator) has tripped since it was last cleared.
    fn break_tripped(&self) -> bool;
    /// Clears the break flag (the comparator sets it again while it still sees the overcurrent).
    fn clear_break(&mut self);
}

/// A bridge that only records what it was told: for tests and proofs of the task bodies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordingBridge {
    /// Auto-reload.
    pub arr: u16,
    /// State in force.
    pub state: BridgeState,
    /// Last compares written while running.
    pub compares: [BridgeCompare; 2],
    /// Break flag.
    pub tripped: bool,
}

impl RecordingBridge {
    /// A braked bridge with auto-reload `arr`.
    pub const fn new(arr: u16) -> Self {
        Self {
            arr,
            state: BridgeState::Brake,
            compares: [BridgeCompare { a: 0, b: 0 }; 2],
            tripped: false,
        }
    }
}

impl Bridge for RecordingBridge {
    fn pwm_arr(&self) -> u16 {
        self.arr
    }
    fn state(&self) -> BridgeState {
        self.state
    }
    fn apply(&mut self, state: BridgeState) {
        if state != self.state {
            self.compares = [BridgeCompare::default(); 2];
            self.state = state;
        }
    }
    fn set(&mut self, compares: [BridgeCompare; 2]) {
        if self.state == BridgeState::Run {
            self.compares = compares;
        }
    }
    fn break_tripped(&self) -> bool {
        self.tripped
    }
    fn clear_break(&mut self) {
        self.tripped = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulator's bridge: the current loop scales its duty by `pwm_arr`, and compares
    /// written while braked are not kept.
    #[test]
    fn recording_bridge_reports_its_reload_and_keeps_compares_only_while_running() {
        let mut b = RecordingBridge::new(4200);
        assert_eq!(b.pwm_arr(), 4200);
        let c = [
            BridgeCompare { a: 2100, b: 0 },
            BridgeCompare { a: 0, b: 7 },
        ];
        b.set(c);
        assert_eq!(b.compares, [BridgeCompare::default(); 2]);
        b.apply(BridgeState::Run);
        b.set(c);
        assert_eq!(b.compares, c);
        b.apply(BridgeState::Brake);
        assert_eq!(b.compares, [BridgeCompare::default(); 2]);
        b.tripped = true;
        assert!(b.break_tripped());
        b.clear_break();
        assert!(!b.break_tripped());
    }
}
