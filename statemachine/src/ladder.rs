//! The degradation ladder NORMAL → REDUCED → HOLD → STOP → BRAKE as a pure step function.
//!
//! ```text
//!  valid frame ─┐        watchdog tick (1 kHz)
//!               v              v
//!          age = 0         age = age + 1 (saturating), then the rung is chosen
//!
//!   last valid frame
//!        │  tick1 tick2 tick3 ..... tick5 ............ tick10
//!   age: 0    1     2     3           5                  10
//!        NORMAL/REDUCED   HOLD        STOP               BRAKE (latched)
//!                          │           │                  │
//!   setpoint: commanded    └ hold decel ┴ stop decel ─────┴ PWM off, low-side short
//!
//!   With a frame every millisecond the age is 1 at every tick; one lost frame makes it 2 (no effect),
//!   two missed cycles make it 3 (HOLD, seed: "2 missed cycles").
//! ```
//!
//! `age` is the seed's watchdog counter turned around (seed: reload 10 on a valid frame, count down at
//! 1 kHz, brake at 0): BRAKE comes at the 10th tick after the last valid frame, so at most 10 ms after it.
//!
//! Ticks are the only clock: [`Ladder::step`] never reads time, so every transition is a function
//! of the event sequence and can be checked exhaustively (see `proofs/SAFETY.md`).

use crate::config::Config;
use crate::types::{
    Command, Condition, ControlMode, Drive, FaultFlags, Mode, Output, RejectReason, Speed,
};
use crate::validate::{validate, Setpoint};

/// Emergency-stop requests (seed 001 `ESTOP.action`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Estop {
    /// Engage and latch the emergency stop (action = 1).
    Engage,
    /// Release the latch (action = 0); BRAKE stays latched until a re-arm.
    Release,
}

/// Everything that can happen to the ladder.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// The 1 kHz watchdog tick: the only event that moves the setpoint.
    Tick,
    /// A frame that passed CRC and decoding; validated here.
    Frame(Command),
    /// A frame refused below the ladder (CRC, framing, decoding, version, parity).
    Rejected(RejectReason),
    /// A board condition became active or cleared.
    Condition {
        /// Which condition.
        condition: Condition,
        /// True when it became active, false when it cleared.
        active: bool,
    },
    /// Emergency stop engaged or released.
    Estop(Estop),
    /// The host's shutdown bit (seed 004 `SHUTDOWN_MOTOR`), asserted or not.
    Shutdown(bool),
    /// An explicit re-arm request (a clear command from the host).
    Rearm,
}

/// Saturating event counters, reported in diagnostics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Watchdog ticks seen.
    pub ticks: u32,
    /// Frames that passed validation.
    pub valid_frames: u32,
    /// Refused frames, indexed by [`RejectReason::index`].
    pub rejected: [u32; RejectReason::ALL.len()],
    /// Ticks with no valid frame since the previous tick.
    pub missed_ticks: u32,
    /// Entries into HOLD.
    pub hold_entries: u32,
    /// Entries into BRAKE (latches).
    pub brake_entries: u32,
    /// Re-arms that released BRAKE.
    pub rearms: u32,
    /// Re-arm requests refused because a latching cause was still active.
    pub rearm_refused: u32,
}

impl Counters {
    /// How many frames were refused for `reason`.
    pub fn rejected(&self, reason: RejectReason) -> u32 {
        self.rejected.get(reason.index()).copied().unwrap_or(0)
    }

    /// All refused frames.
    pub fn rejected_total(&self) -> u32 {
        self.rejected.iter().fold(0u32, |a, b| a.saturating_add(*b))
    }
}

/// Conditions that keep BRAKE latched while they are active: a re-arm is refused until they clear.
pub const LATCHING: FaultFlags = FaultFlags(
    FaultFlags::OVERCURRENT.0
        | FaultFlags::OVERTEMPERATURE.0
        | FaultFlags::ENCODER.0
        | FaultFlags::UNDERVOLTAGE.0
        | FaultFlags::ESTOP.0
        | FaultFlags::SHUTDOWN.0,
);

/// Conditions that hold the ladder in REDUCED while active.
pub const DEGRADING: FaultFlags =
    FaultFlags(FaultFlags::THERMAL_WARNING.0 | FaultFlags::CLOCK_SYNC_LOST.0);

/// The whole fail-safe state. Every field is plain data; [`Ladder::step`] is the only way it changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ladder {
    pub(crate) cfg: Config,
    pub(crate) mode: Mode,
    /// Setpoints applied after the last tick, [left, right].
    pub(crate) applied: [Speed; 2],
    /// Last valid command; cleared when BRAKE latches.
    pub(crate) last: Option<Setpoint>,
    /// Enable bit of the last valid frame, for the 0→1 re-arm edge. Set to true whenever BRAKE latches,
    /// so only an enable = 0 frame seen after the latch, then an enable = 1 frame, makes an edge: a host that
    /// keeps sending enable = 1 across an MCU reset or a link loss never restarts the drive by itself.
    pub(crate) prev_enable: bool,
    /// Watchdog ticks since the last valid frame (saturating); 0 right after a valid frame.
    pub(crate) age: u16,
    pub(crate) brake_latched: bool,
    /// Why BRAKE latched (COMM_LOST, ESTOP, SHUTDOWN, conditions, POWER_ON).
    pub(crate) latch_causes: FaultFlags,
    /// Conditions active now, plus ESTOP and SHUTDOWN while set.
    pub(crate) active: FaultFlags,
    pub(crate) rearm_pending: bool,
    pub(crate) degraded: bool,
    /// Consecutive clean ticks while degraded.
    pub(crate) clean_ticks: u16,
    /// Position in the reject-counting window, < window.
    pub(crate) window_pos: u16,
    /// Strikes (refused frames, HOLD entries) in the current window (saturating).
    pub(crate) window_strikes: u16,
    pub(crate) counters: Counters,
}

/// Moves `cur` toward `target` by at most `step` (step ≥ 0).
pub const fn approach(cur: Speed, target: Speed, step: Speed) -> Speed {
    if target.to_bits() > cur.to_bits() {
        let gap = target.saturating_sub(cur);
        if gap.to_bits() > step.to_bits() {
            cur.saturating_add(step)
        } else {
            target
        }
    } else {
        let gap = cur.saturating_sub(target);
        if gap.to_bits() > step.to_bits() {
            cur.saturating_sub(step)
        } else {
            target
        }
    }
}

/// Limits `x` to ±`limit` (limit ≥ 0), without the panic of `Ord::clamp`.
pub const fn clamp_sym(x: Speed, limit: Speed) -> Speed {
    let neg = limit.saturating_neg();
    if x.to_bits() > limit.to_bits() {
        limit
    } else if x.to_bits() < neg.to_bits() {
        neg
    } else {
        x
    }
}

impl Ladder {
    /// Power-on state: BRAKE latched with `POWER_ON`, so the drive starts only after an explicit arm
    /// (ISO 3691-4: no automatic start) and fresh valid frames.
    pub const fn new(cfg: Config) -> Self {
        Self {
            cfg,
            mode: Mode::Brake,
            applied: [Speed::ZERO; 2],
            last: None,
            prev_enable: true,
            age: 0,
            brake_latched: true,
            latch_causes: FaultFlags::POWER_ON,
            active: FaultFlags::NONE,
            rearm_pending: false,
            degraded: true,
            clean_ticks: 0,
            window_pos: 0,
            window_strikes: 0,
            counters: Counters {
                ticks: 0,
                valid_frames: 0,
                rejected: [0; RejectReason::ALL.len()],
                missed_ticks: 0,
                hold_entries: 0,
                brake_entries: 0,
                rearms: 0,
                rearm_refused: 0,
            },
        }
    }

    /// The configuration in force.
    pub const fn config(&self) -> &Config {
        &self.cfg
    }

    /// The current rung.
    pub const fn mode(&self) -> Mode {
        self.mode
    }

    /// Setpoints applied after the last tick, [left, right] (zero in BRAKE).
    pub const fn applied(&self) -> [Speed; 2] {
        self.applied
    }

    /// The last valid command (None after BRAKE latched, until a new valid frame).
    pub const fn last_valid(&self) -> Option<Setpoint> {
        self.last
    }

    /// Watchdog ticks since the last valid frame.
    pub const fn age(&self) -> u16 {
        self.age
    }

    /// Event counters.
    pub const fn counters(&self) -> &Counters {
        &self.counters
    }

    /// True while BRAKE is latched.
    pub const fn brake_latched(&self) -> bool {
        self.brake_latched
    }

    /// The invariant every reachable state satisfies (INV-0 in `proofs/SAFETY.md`).
    ///
    /// `Ladder::new` satisfies it and every [`Ladder::step`] preserves it (`verify_step_preserves_invariant`),
    /// so harnesses may start from any state that satisfies it: an over-approximation of the reachable set.
    pub fn is_valid(&self) -> bool {
        let p = self.cfg.params();
        let within = |s: Speed| s <= p.v_max && s >= p.v_max.saturating_neg();
        let applied_ok = self.applied.iter().all(|a| within(*a));
        let last_ok = match self.last {
            None => true,
            Some(sp) => {
                within(sp.left)
                    && within(sp.right)
                    && !matches!(sp.mode, ControlMode::Position | ControlMode::RawDuty)
            }
        };
        let mode_ok = match self.mode {
            Mode::Normal | Mode::Reduced => self.age < p.hold_after,
            Mode::Hold => self.age < p.stop_after,
            // STOP's bound (age < brake_after) is the unlatched clause below.
            Mode::Stop => true,
            Mode::Brake => self.applied == [Speed::ZERO; 2],
        };
        applied_ok
            && last_ok
            && mode_ok
            && (self.mode == Mode::Brake) == self.brake_latched
            && self.brake_latched != self.latch_causes.is_empty()
            && (self.brake_latched || (self.age < p.brake_after && self.last.is_some()))
            && (!self.active.intersects(LATCHING) || self.brake_latched)
            && (!self.rearm_pending || self.brake_latched)
            && self.window_pos < p.window
            && self.clean_ticks < p.window
    }

    /// Feeds one event and returns what to apply. Never panics; all arithmetic saturates.
    pub fn step(&mut self, event: Event) -> Output {
        match event {
            Event::Tick => self.tick(),
            Event::Frame(cmd) => self.frame(&cmd),
            Event::Rejected(reason) => self.reject(reason),
            Event::Condition { condition, active } => {
                let flag = condition.flag();
                if active {
                    self.active = self.active.union(flag);
                    // SR-6 / INV-7: a braking condition turns the PWM off in this very step.
                    if condition.brakes() {
                        self.latch(flag);
                    }
                } else {
                    self.active = self.active.without(flag);
                }
            }
            // SR-9 / INV-6, INV-7: ESTOP latches at once; only `Release` clears the flag (INV-6).
            Event::Estop(Estop::Engage) => {
                self.active = self.active.union(FaultFlags::ESTOP);
                self.latch(FaultFlags::ESTOP);
            }
            Event::Estop(Estop::Release) => {
                self.active = self.active.without(FaultFlags::ESTOP);
            }
            // SR-10 / INV-7: the host's shutdown bit turns the PWM off in this very step.
            Event::Shutdown(true) => {
                self.active = self.active.union(FaultFlags::SHUTDOWN);
                self.latch(FaultFlags::SHUTDOWN);
            }
            Event::Shutdown(false) => {
                self.active = self.active.without(FaultFlags::SHUTDOWN);
            }
            Event::Rearm => self.request_rearm(),
        }
        self.output()
    }

    /// What the current state tells the bridge, without changing anything.
    pub fn output(&self) -> Output {
        let p = self.cfg.params();
        let limit = match self.mode {
            Mode::Normal => p.v_max,
            Mode::Reduced => p.reduced_limit,
            Mode::Hold | Mode::Stop | Mode::Brake => Speed::ZERO,
        };
        let drive = if self.mode == Mode::Brake {
            Drive::Brake
        } else {
            Drive::Run {
                left: self.applied[0],
                right: self.applied[1],
            }
        };
        let mut faults = self.active.union(self.latch_causes);
        if self.brake_latched {
            faults = faults.union(FaultFlags::BRAKE_LATCHED);
        }
        if self.degraded {
            faults = faults.union(FaultFlags::LINK_DEGRADED);
        }
        Output {
            mode: self.mode,
            drive,
            limit,
            faults,
            age: self.age,
        }
    }

    /// SR-1, SR-6, SR-9, SR-10: enter BRAKE, zero the setpoint, forget the command, withdraw any re-arm.
    fn latch(&mut self, cause: FaultFlags) {
        if !self.brake_latched {
            self.counters.brake_entries = self.counters.brake_entries.saturating_add(1);
        }
        self.brake_latched = true;
        self.latch_causes = self.latch_causes.union(cause);
        self.mode = Mode::Brake;
        self.applied = [Speed::ZERO; 2];
        self.last = None;
        self.prev_enable = true;
        self.rearm_pending = false;
    }

    /// SR-8 / INV-6: a re-arm is accepted only while no latching cause is active.
    fn request_rearm(&mut self) {
        if !self.brake_latched {
            return;
        }
        if self.active.intersects(LATCHING) {
            self.counters.rearm_refused = self.counters.rearm_refused.saturating_add(1);
            self.rearm_pending = false;
        } else {
            self.rearm_pending = true;
        }
    }

    /// SR-2 / INV-4: a refused frame only counts; it never touches the command, the age or the setpoint.
    fn reject(&mut self, reason: RejectReason) {
        if let Some(c) = self.counters.rejected.get_mut(reason.index()) {
            *c = c.saturating_add(1);
        }
        self.strike();
    }

    /// A sign of a poor link (a refused frame, an entry into HOLD): degrade at the window's strike
    /// limit; once degraded, any strike restarts the clean window.
    fn strike(&mut self) {
        self.window_strikes = self.window_strikes.saturating_add(1);
        if self.degraded || self.window_strikes >= self.cfg.params().strike_limit {
            self.degraded = true;
            self.clean_ticks = 0;
        }
    }

    /// SR-3, SR-4: validate, then (and only then) take the command and reset the age.
    fn frame(&mut self, cmd: &Command) {
        let p = self.cfg.params();
        let allowance = p
            .max_cmd_step
            .saturating_mul_int(i32::from(self.age.max(1)));
        match validate(cmd, self.last.as_ref(), allowance, &self.cfg) {
            Err(reason) => self.reject(reason),
            Ok(sp) => {
                self.counters.valid_frames = self.counters.valid_frames.saturating_add(1);
                let rising = sp.enable && !self.prev_enable;
                self.prev_enable = sp.enable;
                self.last = Some(sp);
                self.age = 0;
                if rising {
                    self.request_rearm();
                }
            }
        }
    }

    fn tick(&mut self) {
        let p = *self.cfg.params();
        self.counters.ticks = self.counters.ticks.saturating_add(1);
        self.age = self.age.saturating_add(1);
        let frame_since_last_tick = self.age == 1;
        if !frame_since_last_tick {
            self.counters.missed_ticks = self.counters.missed_ticks.saturating_add(1);
        }

        self.window_pos = self.window_pos.saturating_add(1);
        if self.window_pos >= p.window {
            self.window_pos = 0;
            self.window_strikes = 0;
        }

        // SR-1 / INV-1: BRAKE at the brake_after-th tick (≤ 10) after the last valid frame.
        if self.age >= p.brake_after {
            self.latch(FaultFlags::COMM_LOST);
        }

        let enabled = matches!(self.last, Some(Setpoint { enable: true, .. }));
        // SR-8 / INV-6: BRAKE is left only here: explicit re-arm + fresh valid frame + no active cause.
        if self.brake_latched
            && self.rearm_pending
            && !self.active.intersects(LATCHING)
            && frame_since_last_tick
            && enabled
        {
            self.brake_latched = false;
            self.latch_causes = FaultFlags::NONE;
            self.rearm_pending = false;
            self.degraded = true;
            self.clean_ticks = 0;
            self.counters.rearms = self.counters.rearms.saturating_add(1);
        }

        // SR-1, SR-7 / INV-2: the rung follows the age; a late link is never NORMAL or REDUCED.
        let mode = if self.brake_latched {
            Mode::Brake
        } else if self.age >= p.stop_after || !enabled {
            Mode::Stop
        } else if self.age >= p.hold_after {
            Mode::Hold
        } else if self.degraded || self.active.intersects(DEGRADING) {
            Mode::Reduced
        } else {
            Mode::Normal
        };

        if mode == Mode::Hold && self.mode != Mode::Hold {
            self.counters.hold_entries = self.counters.hold_entries.saturating_add(1);
            self.strike();
        }
        if self.age >= p.stop_after || self.active.intersects(DEGRADING) {
            // The link was lost long enough to stop, or a warning is active: REDUCED afterwards.
            self.degraded = true;
            self.clean_ticks = 0;
        } else if self.age >= p.hold_after {
            // No recovery progress while frames are late.
            self.clean_ticks = 0;
        } else if self.degraded {
            // (In BRAKE this count is moot: the re-arm that ends BRAKE restarts it.)
            self.clean_ticks = self.clean_ticks.saturating_add(1);
            if self.clean_ticks >= p.window {
                self.degraded = false;
                self.clean_ticks = 0;
            }
        }

        self.mode = mode;
        // SR-5 / INV-3, INV-8: the setpoint moves toward the rung's target by at most one step per tick.
        self.applied = match mode {
            Mode::Brake => [Speed::ZERO; 2],
            Mode::Stop => self
                .applied
                .map(|a| approach(a, Speed::ZERO, p.stop_decel_step)),
            Mode::Hold => self
                .applied
                .map(|a| approach(a, Speed::ZERO, p.hold_decel_step)),
            Mode::Normal | Mode::Reduced => {
                let limit = if mode == Mode::Normal {
                    p.v_max
                } else {
                    p.reduced_limit
                };
                let [tl, tr] = match self.last {
                    Some(sp) if sp.drives() => {
                        [clamp_sym(sp.left, limit), clamp_sym(sp.right, limit)]
                    }
                    _ => [Speed::ZERO; 2],
                };
                [
                    approach(self.applied[0], tl, p.accel_step),
                    approach(self.applied[1], tr, p.accel_step),
                ]
            }
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ConfigParams;

    const P: ConfigParams = ConfigParams::DEFAULT;

    fn cmd(speed: f32, enable: bool) -> Event {
        Event::Frame(Command {
            left: speed,
            right: -speed,
            mode: 1,
            enable,
            seq: None,
        })
    }

    /// A ladder armed the way a host does it: enable 0, then enable 1, frame + tick each millisecond.
    fn armed() -> Ladder {
        let mut l = Ladder::new(Config::DEFAULT);
        l.step(cmd(0.0, false));
        l.step(Event::Tick);
        l.step(cmd(0.0, true));
        let out = l.step(Event::Tick);
        assert_eq!(out.mode, Mode::Reduced, "armed ladder starts in REDUCED");
        l
    }

    /// Frame + tick per millisecond until the ladder runs NORMAL at `speed` (rad/s).
    fn cruising(speed: f32) -> Ladder {
        let mut l = armed();
        let mut v = 0.0f32;
        for _ in 0..2000 {
            v = (v + 0.04).min(speed);
            l.step(cmd(v, true));
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Normal);
        assert_eq!(l.applied()[0], Speed::from_num(speed));
        l
    }

    #[test]
    fn power_on_is_braked_and_ticks_alone_never_arm() {
        let mut l = Ladder::new(Config::DEFAULT);
        assert!(l.is_valid());
        for _ in 0..100 {
            assert_eq!(l.step(Event::Tick).drive, Drive::Brake);
        }
        // Frames with enable = 1 but no 0→1 edge do not arm either.
        for _ in 0..100 {
            l.step(cmd(0.0, true));
            assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        }
        assert!(l.step(Event::Tick).faults.contains(FaultFlags::POWER_ON));
    }

    #[test]
    fn comm_loss_walks_the_ladder_at_the_seed_thresholds() {
        // `cruising` ends with frame + tick: the first tick after the last valid frame has passed.
        let mut l = cruising(5.0);
        assert_eq!(l.age(), 1);
        // Seed 000: HOLD after 2 missed cycles (age 3), BRAKE at 10 ms (age 10); STOP at the seed's
        // WDG_HOLD_LEVEL (5). Index = ticks since the last valid frame, from the 2nd to the 10th.
        let expected = [
            (2, Mode::Normal),
            (3, Mode::Hold),
            (4, Mode::Hold),
            (5, Mode::Stop),
            (6, Mode::Stop),
            (7, Mode::Stop),
            (8, Mode::Stop),
            (9, Mode::Stop),
            (10, Mode::Brake),
        ];
        for (age, want) in expected {
            let out = l.step(Event::Tick);
            assert_eq!(out.mode, want, "tick {age} after the last frame");
            assert_eq!(out.age, age);
        }
        let out = l.output();
        assert_eq!(out.drive, Drive::Brake);
        assert!(out
            .faults
            .contains(FaultFlags::COMM_LOST.union(FaultFlags::BRAKE_LATCHED)));
    }

    #[test]
    fn hold_and_stop_decelerate_at_their_configured_rates() {
        let mut l = cruising(5.0);
        let v0 = l.applied()[0];
        l.step(Event::Tick); // age 2: one frame lost, nothing changes
        assert_eq!(l.applied()[0], v0);
        l.step(Event::Tick); // age 3: HOLD, one hold step
        assert_eq!(l.applied()[0], v0 - P.hold_decel_step);
        assert_eq!(
            l.applied()[1],
            -(v0 - P.hold_decel_step),
            "right wheel decelerates toward zero too"
        );
        l.step(Event::Tick); // age 4: second hold step
        l.step(Event::Tick); // age 5: STOP
        assert_eq!(
            l.applied()[0],
            v0 - P.hold_decel_step * 2 - P.stop_decel_step
        );
    }

    #[test]
    fn one_lost_frame_changes_nothing_and_repeated_holds_degrade() {
        let mut l = cruising(3.0);
        // One frame lost (or late past the tick, within the ±0.2 ms contract): no HOLD, no strike.
        assert_eq!(l.step(Event::Tick).mode, Mode::Normal);
        l.step(cmd(3.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Normal);
        // Two missed cycles: one HOLD tick, one strike; NORMAL again when frames return.
        l.step(Event::Tick);
        assert_eq!(l.step(Event::Tick).mode, Mode::Hold);
        l.step(cmd(3.0, true));
        assert_eq!(
            l.step(Event::Tick).mode,
            Mode::Normal,
            "one strike is below the limit"
        );
        // Three HOLD episodes within one window: the link is degraded.
        for _ in 0..2 {
            l.step(Event::Tick);
            l.step(Event::Tick);
            l.step(cmd(3.0, true));
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Reduced);
    }

    #[test]
    fn frames_resuming_after_stop_recover_without_rearm_but_reduced() {
        let mut l = cruising(3.0);
        for _ in 0..6 {
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Stop);
        let slowed = l.applied()[0];
        // The host resumes with the command it was sending; the setpoint ramps back up from where STOP left it.
        l.step(cmd(3.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
        assert_eq!(l.applied()[0], slowed + P.accel_step);
        for _ in 0..1000 {
            l.step(cmd(3.0, true));
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Normal, "clean window restores NORMAL");
    }

    #[test]
    fn rejected_frames_change_only_counters_then_degrade() {
        let mut l = cruising(4.0);
        let before = l;
        l.step(Event::Rejected(RejectReason::Crc));
        assert_eq!(l.applied(), before.applied());
        assert_eq!(l.last_valid(), before.last_valid());
        assert_eq!(l.mode(), Mode::Normal);
        assert_eq!(l.counters().rejected(RejectReason::Crc), 1);
        // An in-range frame that jumps faster than the acceleration limit is refused too.
        l.step(cmd(8.0, true));
        assert_eq!(l.applied(), before.applied());
        assert_eq!(l.counters().rejected(RejectReason::Acceleration), 1);
        l.step(Event::Frame(Command {
            left: f32::NAN,
            right: 0.0,
            mode: 1,
            enable: true,
            seq: None,
        }));
        assert_eq!(l.counters().rejected(RejectReason::NonFinite), 1);
        // Third reject in the window: REDUCED from the next tick, speed ramps down to the reduced limit.
        l.step(cmd(4.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
    }

    #[test]
    fn reduced_ramps_down_instead_of_jumping() {
        let mut l = cruising(15.0);
        for _ in 0..3 {
            l.step(Event::Rejected(RejectReason::Crc));
        }
        l.step(cmd(15.0, true));
        let out = l.step(Event::Tick);
        assert_eq!(out.mode, Mode::Reduced);
        assert_eq!(out.limit, P.reduced_limit);
        assert_eq!(l.applied()[0], Speed::from_num(15) - P.accel_step);
        for _ in 0..200 {
            l.step(cmd(15.0, true));
            l.step(Event::Tick);
        }
        assert_eq!(l.applied()[0], P.reduced_limit);
    }

    #[test]
    fn estop_latches_and_needs_release_then_rearm_then_fresh_frames() {
        let mut l = cruising(2.0);
        let out = l.step(Event::Estop(Estop::Engage));
        assert_eq!(out.drive, Drive::Brake, "same step");
        // Re-arm while engaged: refused.
        l.step(Event::Rearm);
        assert_eq!(l.counters().rearm_refused, 1);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        // Release alone does not restart.
        l.step(Event::Estop(Estop::Release));
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        // Explicit re-arm, but no fresh frame before the tick: still braked.
        l.step(Event::Rearm);
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
        assert_eq!(l.counters().rearms, 2, "power-on arm and this one");
    }

    #[test]
    fn overcurrent_cuts_pwm_in_the_same_step_and_blocks_rearm_while_active() {
        let mut l = cruising(6.0);
        let out = l.step(Event::Condition {
            condition: Condition::Overcurrent,
            active: true,
        });
        assert_eq!(out.drive, Drive::Brake);
        assert!(out.faults.contains(FaultFlags::OVERCURRENT));
        l.step(cmd(0.0, false));
        l.step(Event::Tick);
        l.step(cmd(0.0, true)); // enable edge while the fault is active
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        assert_eq!(l.counters().rearm_refused, 1);
        l.step(Event::Condition {
            condition: Condition::Overcurrent,
            active: false,
        });
        l.step(cmd(0.0, false));
        l.step(Event::Tick);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
    }

    #[test]
    fn shutdown_bit_brakes_immediately() {
        let mut l = cruising(1.0);
        assert_eq!(l.step(Event::Shutdown(true)).drive, Drive::Brake);
        assert!(l.output().faults.contains(FaultFlags::SHUTDOWN));
    }

    #[test]
    fn comm_lost_brake_needs_an_enable_edge() {
        let mut l = cruising(1.0);
        for _ in 0..10 {
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Brake);
        for _ in 0..50 {
            l.step(cmd(0.0, true));
            assert_eq!(
                l.step(Event::Tick).mode,
                Mode::Brake,
                "resumed frames alone never restart"
            );
        }
        l.step(cmd(0.0, false));
        l.step(Event::Tick);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
    }

    #[test]
    fn disable_stops_with_the_loop_active_and_enable_resumes() {
        let mut l = cruising(2.0);
        l.step(cmd(2.0, false));
        let out = l.step(Event::Tick);
        assert_eq!(out.mode, Mode::Stop);
        assert_eq!(
            out.drive,
            Drive::Run {
                left: Speed::from_num(2) - P.stop_decel_step,
                right: -(Speed::from_num(2) - P.stop_decel_step)
            }
        );
        l.step(cmd(0.0, true));
        assert_ne!(l.step(Event::Tick).mode, Mode::Stop);
    }

    #[test]
    fn thermal_warning_holds_reduced_while_active() {
        let mut l = cruising(2.0);
        l.step(Event::Condition {
            condition: Condition::ThermalWarning,
            active: true,
        });
        l.step(cmd(2.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
        l.step(Event::Condition {
            condition: Condition::ThermalWarning,
            active: false,
        });
        // A clean window is 1000 ticks spent in REDUCED; NORMAL from the tick after.
        for _ in 0..1000 {
            l.step(cmd(2.0, true));
            assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
        }
        l.step(cmd(2.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Normal);
    }

    #[test]
    fn approach_and_clamp() {
        let s = |x: f32| Speed::from_num(x);
        assert_eq!(approach(s(1.0), s(2.0), s(0.25)), s(1.25));
        assert_eq!(approach(s(1.0), s(1.1), s(0.25)), s(1.1));
        assert_eq!(approach(s(0.1), s(-1.0), s(0.25)), s(-0.15));
        // Extremes saturate instead of overflowing (configured speeds stay far inside this range).
        assert_eq!(approach(Speed::MIN, Speed::MAX, Speed::MAX), Speed::MAX);
        assert_eq!(
            approach(Speed::MAX, Speed::MIN, Speed::from_bits(1)),
            Speed::MAX - Speed::from_bits(1)
        );
        assert_eq!(clamp_sym(s(-30.0), s(20.0)), s(-20.0));
        assert_eq!(clamp_sym(s(3.0), s(20.0)), s(3.0));
    }

    #[test]
    fn is_valid_refuses_each_broken_clause() {
        let good = cruising(3.0);
        assert!(good.is_valid());
        let v = P.v_max;
        let brake = {
            let mut l = good;
            l.step(Event::Estop(Estop::Engage));
            l
        };
        assert!(brake.is_valid());
        type Breaker = (&'static str, fn(&mut Ladder));
        let broken: [Breaker; 15] = [
            ("applied beyond v_max", |l| {
                l.applied[0] = P.v_max + Speed::from_bits(1)
            }),
            ("applied below -v_max", |l| {
                l.applied[1] = -P.v_max - Speed::from_bits(1)
            }),
            ("last beyond v_max", |l| {
                l.last = l.last.map(|s| Setpoint {
                    right: P.v_max + Speed::from_bits(1),
                    ..s
                })
            }),
            ("last in position mode", |l| {
                l.last = l.last.map(|s| Setpoint {
                    mode: ControlMode::Position,
                    ..s
                })
            }),
            ("NORMAL with a late link", |l| l.age = P.hold_after),
            ("HOLD at the stop age", |l| {
                l.mode = Mode::Hold;
                l.age = P.stop_after;
            }),
            ("STOP at the brake age", |l| {
                l.mode = Mode::Stop;
                l.age = P.brake_after;
            }),
            ("BRAKE without the latch", |l| {
                l.mode = Mode::Brake;
                l.applied = [Speed::ZERO; 2];
            }),
            ("latch without BRAKE", |l| {
                l.brake_latched = true;
                l.latch_causes = FaultFlags::ESTOP;
            }),
            ("running without a command", |l| l.last = None),
            ("latching cause while running", |l| {
                l.active = FaultFlags::UNDERVOLTAGE
            }),
            ("re-arm pending while running", |l| l.rearm_pending = true),
            ("window position past the window", |l| {
                l.window_pos = P.window
            }),
            ("clean count past the window", |l| l.clean_ticks = P.window),
            ("age at the brake threshold while running", |l| {
                l.mode = Mode::Stop;
                l.age = P.brake_after;
            }),
        ];
        for (what, breaks) in broken {
            let mut l = good;
            breaks(&mut l);
            assert!(!l.is_valid(), "accepted: {what}");
        }
        let mut l = brake;
        l.latch_causes = FaultFlags::NONE;
        assert!(!l.is_valid(), "accepted: latched with no cause");
        let mut l = brake;
        l.applied = [v, Speed::ZERO];
        assert!(!l.is_valid(), "accepted: BRAKE with a setpoint");
    }

    #[test]
    fn every_latching_cause_blocks_rearm_and_warnings_do_not_latch() {
        let latching: [Event; 6] = [
            Event::Condition {
                condition: Condition::Overcurrent,
                active: true,
            },
            Event::Condition {
                condition: Condition::Overtemperature,
                active: true,
            },
            Event::Condition {
                condition: Condition::EncoderFailure,
                active: true,
            },
            Event::Condition {
                condition: Condition::Undervoltage,
                active: true,
            },
            Event::Estop(Estop::Engage),
            Event::Shutdown(true),
        ];
        for e in latching {
            let mut l = cruising(1.0);
            assert_eq!(l.step(e).drive, Drive::Brake, "{e:?}");
            l.step(Event::Rearm);
            assert_eq!(l.counters().rearm_refused, 1, "{e:?}");
        }
        for c in [Condition::ThermalWarning, Condition::ClockSyncLost] {
            let mut l = cruising(1.0);
            l.step(Event::Condition {
                condition: c,
                active: true,
            });
            l.step(cmd(1.0, true));
            assert_eq!(l.step(Event::Tick).mode, Mode::Reduced, "{c:?}");
        }
    }

    #[test]
    fn counters_count_what_they_say() {
        let mut l = cruising(1.0);
        let c0 = *l.counters();
        l.step(Event::Rejected(RejectReason::Crc));
        l.step(Event::Rejected(RejectReason::Parity));
        l.step(Event::Rejected(RejectReason::Parity));
        assert_eq!(l.counters().rejected_total(), c0.rejected_total() + 3);
        assert_eq!(l.counters().rejected(RejectReason::Parity), 2);
        // Two ticks with no frame between: two missed ticks.
        l.step(Event::Tick);
        l.step(Event::Tick);
        assert_eq!(l.counters().missed_ticks, c0.missed_ticks + 2);
        // One BRAKE episode with several causes counts once.
        l.step(Event::Estop(Estop::Engage));
        l.step(Event::Condition {
            condition: Condition::Overcurrent,
            active: true,
        });
        l.step(Event::Shutdown(true));
        assert_eq!(l.counters().brake_entries, c0.brake_entries + 1);
        assert_eq!(l.counters().hold_entries, c0.hold_entries + 1);
    }

    #[test]
    fn idle_mode_targets_zero_whatever_speeds_it_carries() {
        let mut l = cruising(2.0);
        for _ in 0..100 {
            l.step(Event::Frame(Command {
                left: 2.0,
                right: -2.0,
                mode: 0,
                enable: true,
                seq: None,
            }));
            l.step(Event::Tick);
        }
        assert_eq!(l.applied(), [Speed::ZERO; 2]);
        assert_eq!(l.mode(), Mode::Normal);
    }

    #[test]
    fn max_tick_step_is_the_largest_of_the_three_steps() {
        let s = |bits| Speed::from_bits(bits);
        for (a, h, st, want) in [
            (9, 5, 7, 9),
            (5, 9, 7, 9),
            (5, 7, 9, 9),
            (9, 9, 9, 9),
            (8, 9, 9, 9),
        ] {
            let p = ConfigParams {
                accel_step: s(a),
                hold_decel_step: s(h),
                stop_decel_step: s(st),
                ..P
            };
            assert_eq!(
                Config::new(p).unwrap().max_tick_step(),
                s(want),
                "{a} {h} {st}"
            );
        }
    }
}
