//! `watchdog_tick` (priority 2, 1 kHz timer, the ladder's time base): board conditions as level
//! events → the tick → the bridge state → the brake-release output → the IWDG decision.

use crate::estop::EstopInput;
use crate::hw::Bridge;
use crate::safety::Safety;
use crate::tuning::Tuning;
use crate::Measurements;
use crate::AXES;
use control::bridge::bridge_state;
use control::sense::speed_plausible;
use control::BridgeState;
use statemachine::{Condition, Estop, Event, Output, Source, Speed};

/// How often each control task ran (wrapping counters), for the IWDG liveness check.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Runs {
    /// `current_loop` runs.
    pub current: u32,
    /// `speed_pid` runs.
    pub speed: u32,
}

/// What the tick reads from the board.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TickInputs {
    /// What the loops measured since the last tick ([`Measurements::take_for_tick`]).
    pub meas: Measurements,
    /// Gate-driver fault line active (reported as undervoltage: the driver's UVLO is its most
    /// common cause; either way the bridge cannot be controlled).
    pub driver_fault: bool,
    /// Over-temperature warning line active.
    pub thermal_warning: bool,
    /// The local ESTOP input's change since the last tick ([`crate::EstopInput::poll`]).
    pub estop: Option<Estop>,
    /// The control tasks' run counters.
    pub runs: Runs,
}

/// What the tick decided; the caller carries it out ([`TickOutcome::drive`] for the bridge).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickOutcome {
    /// The ladder's output after the tick.
    pub out: Output<AXES>,
    /// The bridge state the output needs.
    pub bridge: BridgeState,
    /// The holding brake is released only while the speed loop drives.
    pub brake_release: bool,
    /// Refresh the IWDG: both control loops ran at their rates since the last tick.
    pub feed_watchdog: bool,
}

impl TickOutcome {
    /// Applies the bridge state, called with the bridge and the ESTOP input locked together: an
    /// ESTOP press that came after this tick polled the input keeps the bridge braked (its edge
    /// handler braked it; running it again would undo that until the next tick).
    ///
    /// While braked it also clears the break flag: the break input is level sensitive, so the flag
    /// comes straight back (and the current loop reports the overcurrent again) for as long as
    /// the comparator holds it.
    pub fn drive(&self, bridge: &mut impl Bridge, estop: &EstopInput) {
        let state = if estop.press_pending() {
            BridgeState::Brake
        } else {
            self.bridge
        };
        bridge.apply(state);
        if state == BridgeState::Brake {
            bridge.clear_break();
        }
    }

    /// The setpoints for the speed loop: `None` in BRAKE.
    pub fn setpoint(&self) -> Option<[Speed; AXES]> {
        self.out.drive.speeds()
    }
}

/// The tick task's own state: the liveness monitor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickTask {
    seen: [u32; 2],
    min_runs: [u32; 2],
}

impl TickTask {
    /// A tick task for `t`'s loop rates.
    pub const fn new(t: &Tuning) -> Self {
        Self {
            seen: [0; 2],
            min_runs: t.min_runs_per_tick,
        }
    }

    /// One tick. Not inlined, so the budget report can count it as one unit.
    #[inline(never)]
    pub fn run(&mut self, safety: &mut Safety, inputs: &TickInputs) -> TickOutcome {
        if let Some(e) = inputs.estop {
            safety.apply(Event::Estop {
                source: Source::Local,
                action: e,
            });
        }
        let v_max = safety.ladder().config().params().v_max;
        let m = &inputs.meas;
        let encoder_bad = m.speeds.iter().any(|s| !speed_plausible(*s, v_max));
        for (condition, active) in [
            (Condition::Overcurrent, m.overcurrent),
            (Condition::Undervoltage, inputs.driver_fault),
            (Condition::ThermalWarning, inputs.thermal_warning),
            (Condition::EncoderFailure, encoder_bad),
        ] {
            safety.apply(Event::Condition { condition, active });
        }
        let out = safety.tick();
        let bridge = bridge_state(&out.drive);
        TickOutcome {
            out,
            bridge,
            brake_release: bridge == BridgeState::Run,
            feed_watchdog: self.alive([inputs.runs.current, inputs.runs.speed]),
        }
    }

    /// True if every monitored task advanced by at least its minimum since the last call.
    fn alive(&mut self, counters: [u32; 2]) -> bool {
        let mut ok = true;
        for ((seen, now), min) in self.seen.iter_mut().zip(counters).zip(self.min_runs) {
            if now.wrapping_sub(*seen) < min {
                ok = false;
            }
            *seen = now;
        }
        ok
    }
}
