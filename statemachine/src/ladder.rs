//! The degradation ladder NORMAL → REDUCED → HOLD → STOP → BRAKE as a pure step function over `N` axes.
//!
//! ```text
//!  valid frame ─┐        watchdog tick (1 kHz)
//!               v              v
//!          age = 0         age = age + 1 (saturating), then the rung is chosen
//!
//!   last valid frame (seed 000 profile)
//!        │  tick1 tick2 tick3 ..... tick5 ........ tick9
//!   age: 0    1     2     3           5              9
//!        NORMAL/REDUCED   HOLD        STOP           BRAKE (latched)
//!                          │           │              │
//!   setpoint: commanded    └ hold decel ┴ stop decel ─┴ PWM off, low-side short
//!
//!   With a frame every millisecond the age is 1 at every tick; one lost frame makes it 2 (no effect),
//!   two missed cycles make it 3 (HOLD, seed: "2 missed cycles").
//! ```
//!
//! The thresholds are the link profile's ([`Config`]): a 50 Hz link holds after 41 ticks, not 3. The
//! profile's `brake_after` is the latest BRAKE; a frame's own `timeout` may bring it earlier. BRAKE at
//! the 9th tick after seed 000's last valid frame is strictly within 10 ms of that frame's arrival
//! (`config` module diagram).
//!
//! Every axis is driven in its own [`AxisMode`]; what each rung does to each mode:
//!
//! | mode     | NORMAL / REDUCED                      | HOLD, STOP                       | BRAKE |
//! |----------|---------------------------------------|----------------------------------|-------|
//! | coast    | no torque                             | no torque                        | short |
//! | short    | short brake                           | short brake                      | short |
//! | duty     | ramps to the target (≤ duty limit)    | ramps to zero (`duty_step`)      | short |
//! | velocity | ramps to the target (≤ speed limit)   | decelerates (hold / stop step)   | short |
//! | position | profile under a cap ramped to the command's cap (≤ speed limit) | cap falls to zero (hold / stop step): the axis comes to rest and holds there | short |
//!
//! An axis changes mode only from rest: a new drive mode first brings the old one to zero at its
//! ramp, then takes over; a passive mode (coast, short) takes over at once.
//!
//! Ticks are the only clock: [`Ladder::step`] never reads time, so every transition is a function
//! of the event sequence and can be checked exhaustively (see `proofs/SAFETY.md`).

use crate::config::Config;
use crate::types::{
    AxisDrive, AxisMode, Command, Condition, Drive, FaultFlags, Mode, Output, Position,
    RejectReason, Speed,
};
use crate::validate::{validate_into, AxisSetpoint, Setpoint};

/// Emergency-stop requests (seed 001 `ESTOP.action`, the board's ESTOP input).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Estop {
    /// Engage and latch the emergency stop (action = 1).
    Engage,
    /// Release this source's hold on the latch (action = 0); BRAKE stays latched until a re-arm.
    Release,
}

/// Where a command comes from. ESTOP is owned by the sources that engaged it (INV-14).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Source {
    /// The board's own ESTOP input: engages for itself, releases every source's ESTOP.
    Local = 0,
    /// The link that drives the axes (its frames are [`Event::Frame`]s).
    Primary = 1,
    /// A second link, e.g. a service port: may engage and release its own ESTOP and request re-arms.
    Service = 2,
}

impl Source {
    /// Every source.
    pub const ALL: [Self; 3] = [Self::Local, Self::Primary, Self::Service];

    /// This source's bit in an owner set.
    pub const fn bit(self) -> u8 {
        1 << self as u8
    }
}

/// Everything that can happen to the ladder.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event<const N: usize> {
    /// The 1 kHz watchdog tick: the only event that moves the setpoints.
    Tick,
    /// A frame of the primary link that passed CRC and decoding; validated here.
    Frame(Command<N>),
    /// A frame refused below the ladder (CRC, framing, decoding, version, parity, unknown mode).
    Rejected(RejectReason),
    /// A board condition became active or cleared.
    Condition {
        /// Which condition.
        condition: Condition,
        /// True when it became active, false when it cleared.
        active: bool,
    },
    /// Emergency stop engaged or released by a source.
    Estop {
        /// Who asks.
        source: Source,
        /// Engage or release.
        action: Estop,
    },
    /// The host's shutdown bit (seed 004 `SHUTDOWN_MOTOR`), asserted or not.
    Shutdown(bool),
    /// An explicit re-arm request (a clear command) from a source.
    Rearm(Source),
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
    /// Re-arm requests refused: a latching cause still active, or not the source that released ESTOP.
    pub rearm_refused: u32,
    /// ESTOP releases refused: the source did not hold the ESTOP it tried to release.
    pub estop_release_refused: u32,
}

impl Counters {
    /// How many frames were refused for `reason`.
    pub fn rejected(&self, reason: RejectReason) -> u32 {
        self.rejected.get(reason.index()).copied().unwrap_or(0)
    }

    /// All refused frames.
    pub fn rejected_total(&self) -> u32 {
        let mut total = 0u32;
        #[allow(clippy::indexing_slicing)]
        for i in 0..self.rejected.len() {
            total = total.saturating_add(self.rejected[i]);
        }
        total
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

/// Every [`Source`]'s bit.
const ALL_SOURCES: u8 = 0b111;

/// The whole fail-safe state of `N` axes. Every field is plain data; [`Ladder::step`] is the only way it changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ladder<const N: usize> {
    pub(crate) cfg: Config,
    pub(crate) mode: Mode,
    /// Per axis, after the last tick: the speed setpoint (velocity), the duty (duty), the speed cap
    /// (position), zero (passive modes, and every axis in BRAKE).
    pub(crate) applied: [Speed; N],
    /// The mode each `applied` value is expressed in.
    pub(crate) axis_modes: [AxisMode; N],
    /// The position target in force per axis (used while the axis is in position mode); within the travel.
    pub(crate) held: [Position; N],
    /// Last valid command, meaningful while `has_last` (cleared when BRAKE latches). Kept beside a
    /// flag rather than in an `Option`: it is stored on every valid frame, and the compiler copies a
    /// plain struct of words as words (`firmware/BUDGET.md`).
    pub(crate) last: Setpoint<N>,
    /// True once a valid command is held; false at power-on and after BRAKE latched.
    pub(crate) has_last: bool,
    /// The comm-loss threshold in force: the last valid frame's, 1 ..= the profile's `brake_after`.
    pub(crate) brake_after: u16,
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
    /// The sources holding ESTOP engaged ([`Source::bit`]s); ESTOP is active exactly while non-empty.
    pub(crate) estop_owners: u8,
    /// The source whose release ended the last ESTOP; after an ESTOP latch only its re-arm counts
    /// (any link's if it was the local input).
    pub(crate) estop_released_by: Option<Source>,
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

const fn min_q(a: Speed, b: Speed) -> Speed {
    if a.to_bits() < b.to_bits() {
        a
    } else {
        b
    }
}

/// True if `x` lies in `lo ..= hi`. Compared as bits, like the functions above: within one
/// fixed-point type the bits order as the values do, while `fixed`'s operators go through its
/// comparison of two fraction widths, whose type-level calls a Kani harness executes and writes
/// into every cover's trace (this check runs for every axis of every state a harness checks).
const fn in_range(x: Speed, lo: Speed, hi: Speed) -> bool {
    let x = x.to_bits();
    x >= lo.to_bits() && x <= hi.to_bits()
}

impl<const N: usize> Ladder<N> {
    /// Power-on state: BRAKE latched with `POWER_ON`, so the drive starts only after an explicit arm
    /// (ISO 3691-4: no automatic start) and fresh valid frames.
    pub const fn new(cfg: Config) -> Self {
        Self {
            mode: Mode::Brake,
            applied: [Speed::ZERO; N],
            axis_modes: [AxisMode::Coast; N],
            held: [cfg.params().travel_lo; N],
            last: Setpoint::none(cfg.params().brake_after),
            has_last: false,
            brake_after: cfg.params().brake_after,
            prev_enable: true,
            age: 0,
            brake_latched: true,
            latch_causes: FaultFlags::POWER_ON,
            active: FaultFlags::NONE,
            estop_owners: 0,
            estop_released_by: None,
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
                estop_release_refused: 0,
            },
            cfg,
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

    /// Per-axis values applied after the last tick (zero in BRAKE): speed, duty or position cap, by
    /// each axis's mode ([`Self::axis_modes`]).
    pub const fn applied(&self) -> [Speed; N] {
        self.applied
    }

    /// The mode each axis is driven in.
    pub const fn axis_modes(&self) -> [AxisMode; N] {
        self.axis_modes
    }

    /// The last valid command (None after BRAKE latched, until a new valid frame).
    pub const fn last_valid(&self) -> Option<Setpoint<N>> {
        if self.has_last {
            Some(self.last)
        } else {
            None
        }
    }

    /// Watchdog ticks since the last valid frame.
    pub const fn age(&self) -> u16 {
        self.age
    }

    /// The comm-loss threshold in force (ticks since the last valid frame): BRAKE when the age reaches it.
    pub const fn brake_after(&self) -> u16 {
        self.brake_after
    }

    /// The sources holding ESTOP engaged, as [`Source::bit`]s.
    pub const fn estop_owners(&self) -> u8 {
        self.estop_owners
    }

    /// Event counters.
    pub const fn counters(&self) -> &Counters {
        &self.counters
    }

    /// True while BRAKE is latched.
    pub const fn brake_latched(&self) -> bool {
        self.brake_latched
    }

    /// True if `sp` is what [`validate`] can return under this configuration.
    fn setpoint_ok(&self, sp: &Setpoint<N>) -> bool {
        let p = self.cfg.params();
        let mut axes_ok = true;
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            let a = &sp.axes[i];
            axes_ok &= p.modes.contains(a.mode)
                && match a.mode {
                    AxisMode::Coast | AxisMode::Short => {
                        a.target == Speed::ZERO && a.cap == Speed::ZERO
                    }
                    AxisMode::Duty => {
                        in_range(a.target, p.duty_max.saturating_neg(), p.duty_max)
                            && a.cap == Speed::ZERO
                    }
                    AxisMode::Velocity => {
                        in_range(a.target, p.v_max.saturating_neg(), p.v_max)
                            && a.cap == Speed::ZERO
                    }
                    AxisMode::Position => {
                        in_range(a.target, p.travel_lo, p.travel_hi)
                            && in_range(a.cap, Speed::ZERO, p.v_max)
                    }
                };
        }
        sp.brake_after >= 1 && sp.brake_after <= p.brake_after && axes_ok
    }

    /// True if `a` is a value an axis in mode `m` may hold.
    fn applied_ok(&self, m: AxisMode, a: Speed) -> bool {
        let p = self.cfg.params();
        match m {
            AxisMode::Coast | AxisMode::Short => a == Speed::ZERO,
            AxisMode::Duty => in_range(a, p.duty_max.saturating_neg(), p.duty_max),
            AxisMode::Velocity => in_range(a, p.v_max.saturating_neg(), p.v_max),
            AxisMode::Position => in_range(a, Speed::ZERO, p.v_max),
        }
    }

    /// The invariant every reachable state satisfies (INV-0 in `proofs/SAFETY.md`).
    ///
    /// `Ladder::new` satisfies it and every [`Ladder::step`] preserves it (`verify_step_preserves_invariant`),
    /// so harnesses may start from any state that satisfies it: an over-approximation of the reachable set.
    pub fn is_valid(&self) -> bool {
        let p = self.cfg.params();
        let mut axes_ok = true;
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            axes_ok &= self.applied_ok(self.axis_modes[i], self.applied[i])
                && in_range(self.held[i], p.travel_lo, p.travel_hi);
        }
        let last_ok = !self.has_last || self.setpoint_ok(&self.last);
        let mode_ok = match self.mode {
            Mode::Normal | Mode::Reduced => self.age < p.hold_after,
            Mode::Hold => self.age < p.stop_after,
            // STOP's bound (age < brake_after) is the unlatched clause below.
            Mode::Stop => true,
            Mode::Brake => self.applied == [Speed::ZERO; N],
        };
        let estop_ok = self.estop_owners & !ALL_SOURCES == 0
            && self.active.contains(FaultFlags::ESTOP) == (self.estop_owners != 0);
        axes_ok
            && last_ok
            && mode_ok
            && estop_ok
            && self.brake_after >= 1
            && self.brake_after <= p.brake_after
            && (self.mode == Mode::Brake) == self.brake_latched
            && self.brake_latched != self.latch_causes.is_empty()
            && (self.brake_latched || (self.age < self.brake_after && self.has_last))
            && (!self.active.intersects(LATCHING) || self.brake_latched)
            && (!self.rearm_pending || self.brake_latched)
            && self.window_pos < p.window
            && self.clean_ticks < p.window
    }

    /// Feeds one event and returns what to apply. Never panics; all arithmetic saturates.
    pub fn step(&mut self, event: Event<N>) -> Output<N> {
        self.update(event);
        self.output()
    }

    /// Feeds one event without building the output ([`Self::step`] is this plus [`Self::output`]):
    /// for a board that applies several events before it drives its outputs.
    pub fn update(&mut self, event: Event<N>) {
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
            // SR-9 / INV-6, INV-7: ESTOP latches at once, owned by the source that engaged it.
            Event::Estop {
                source,
                action: Estop::Engage,
            } => {
                self.estop_owners |= source.bit();
                self.estop_released_by = None;
                self.active = self.active.union(FaultFlags::ESTOP);
                self.latch(FaultFlags::ESTOP);
            }
            Event::Estop {
                source,
                action: Estop::Release,
            } => self.release_estop(source),
            // SR-10 / INV-7: the host's shutdown bit turns the PWM off in this very step.
            Event::Shutdown(true) => {
                self.active = self.active.union(FaultFlags::SHUTDOWN);
                self.latch(FaultFlags::SHUTDOWN);
            }
            Event::Shutdown(false) => {
                self.active = self.active.without(FaultFlags::SHUTDOWN);
            }
            Event::Rearm(source) => self.request_rearm(source),
        }
    }

    /// The fault and status flags of the feedback frame: active conditions, latch causes, and
    /// BRAKE_LATCHED and LINK_DEGRADED while they hold.
    pub fn faults(&self) -> FaultFlags {
        let mut faults = self.active.union(self.latch_causes);
        if self.brake_latched {
            faults = faults.union(FaultFlags::BRAKE_LATCHED);
        }
        if self.degraded {
            faults = faults.union(FaultFlags::LINK_DEGRADED);
        }
        faults
    }

    /// What the current state tells the bridge, without changing anything.
    pub fn output(&self) -> Output<N> {
        let p = self.cfg.params();
        let limit = match self.mode {
            Mode::Normal => p.v_max,
            Mode::Reduced => p.reduced_limit,
            Mode::Hold | Mode::Stop | Mode::Brake => Speed::ZERO,
        };
        let drive = if self.mode == Mode::Brake {
            Drive::Brake
        } else {
            let mut axes = [AxisDrive::Coast; N];
            #[allow(clippy::indexing_slicing)]
            for i in 0..N {
                let a = self.applied[i];
                axes[i] = match self.axis_modes[i] {
                    AxisMode::Coast => AxisDrive::Coast,
                    AxisMode::Short => AxisDrive::Short,
                    AxisMode::Duty => AxisDrive::Duty(a),
                    AxisMode::Velocity => AxisDrive::Velocity(a),
                    AxisMode::Position => AxisDrive::Position {
                        target: self.held[i],
                        cap: a,
                    },
                };
            }
            Drive::Run(axes)
        };
        Output {
            mode: self.mode,
            drive,
            limit,
            faults: self.faults(),
            age: self.age,
        }
    }

    /// SR-1, SR-6, SR-9, SR-10: enter BRAKE, zero the setpoints, forget the command, withdraw any re-arm.
    fn latch(&mut self, cause: FaultFlags) {
        if !self.brake_latched {
            self.counters.brake_entries = self.counters.brake_entries.saturating_add(1);
        }
        self.brake_latched = true;
        self.latch_causes = self.latch_causes.union(cause);
        self.mode = Mode::Brake;
        self.applied = [Speed::ZERO; N];
        self.has_last = false;
        self.prev_enable = true;
        self.rearm_pending = false;
    }

    /// SR-14 / INV-14: a source releases only its own ESTOP; the local input releases every source's.
    fn release_estop(&mut self, source: Source) {
        let owners = self.estop_owners;
        if owners == 0 {
            return;
        }
        let remaining = if source == Source::Local {
            0
        } else if owners & source.bit() == 0 {
            self.counters.estop_release_refused =
                self.counters.estop_release_refused.saturating_add(1);
            return;
        } else {
            owners & !source.bit()
        };
        self.estop_owners = remaining;
        if remaining == 0 {
            self.active = self.active.without(FaultFlags::ESTOP);
            self.estop_released_by = Some(source);
        }
    }

    /// SR-8 / INV-6, SR-14 / INV-14: a re-arm is accepted only while no latching cause is active, and
    /// after an ESTOP latch only from the source that released it (any link after a local release).
    fn request_rearm(&mut self, source: Source) {
        if !self.brake_latched {
            return;
        }
        let estop_ok = !self.latch_causes.contains(FaultFlags::ESTOP)
            || match self.estop_released_by {
                Some(Source::Local) => true,
                Some(s) => s == source,
                None => false,
            };
        if self.active.intersects(LATCHING) || !estop_ok {
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
    fn frame(&mut self, cmd: &Command<N>) {
        let p = self.cfg.params();
        let allowance = p
            .max_cmd_step
            .saturating_mul_int(i32::from(self.age.max(1)));
        match validate_into(cmd, &mut self.last, self.has_last, allowance, &self.cfg) {
            Err(reason) => self.reject(reason),
            Ok(()) => {
                self.counters.valid_frames = self.counters.valid_frames.saturating_add(1);
                let enable = self.last.enable;
                let rising = enable && !self.prev_enable;
                self.prev_enable = enable;
                self.brake_after = self.last.brake_after;
                self.has_last = true;
                self.age = 0;
                if rising {
                    self.request_rearm(Source::Primary);
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

        // SR-1, SR-16 / INV-1, INV-18: BRAKE at the threshold in force (the profile's brake_after or the
        // last frame's timeout, whichever is earlier) after the last valid frame.
        if self.age >= self.brake_after {
            self.latch(FaultFlags::COMM_LOST);
        }

        let enabled = self.has_last && self.last.enable;
        // SR-8 / INV-6: BRAKE is left only here: explicit re-arm + fresh valid frame + no active cause.
        if self.brake_latched
            && self.rearm_pending
            && !self.active.intersects(LATCHING)
            && frame_since_last_tick
            && enabled
        {
            self.brake_latched = false;
            self.latch_causes = FaultFlags::NONE;
            self.estop_released_by = None;
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
        if mode == Mode::Brake {
            self.applied = [Speed::ZERO; N];
            return;
        }
        // Without a command (unreachable outside BRAKE, INV-0) coasting is the answer that drives nothing.
        let wants = if self.has_last {
            self.last.axes
        } else {
            [AxisSetpoint::passive(AxisMode::Coast); N]
        };
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            (self.applied[i], self.axis_modes[i], self.held[i]) = axis_tick(
                &p,
                mode,
                self.applied[i],
                self.axis_modes[i],
                self.held[i],
                &wants[i],
            );
        }
    }
}

/// One axis, one tick outside BRAKE: (applied, mode, held position target) after it.
///
/// SR-5, SR-15 / INV-3, INV-8, INV-16, INV-17, INV-19: every value moves toward the rung's target by at most its
/// step; a passive mode takes over at once and applies nothing; a drive mode takes over from rest only.
fn axis_tick(
    p: &crate::config::ConfigParams,
    mode: Mode,
    applied: Speed,
    m: AxisMode,
    held: Position,
    want: &AxisSetpoint,
) -> (Speed, AxisMode, Position) {
    let m = if want.mode != m && (want.mode.is_passive() || applied == Speed::ZERO) {
        want.mode
    } else {
        m
    };
    // While the old mode still moves, its target is zero: the axis comes to rest before it switches.
    let switching = want.mode != m;
    let running = matches!(mode, Mode::Normal | Mode::Reduced) && !switching;
    // §1: a position axis takes the command's target only while its rung lets it run; in HOLD and
    // STOP (a late link, or frames with enable 0) it keeps the target it had while its cap falls to
    // zero, so no frame redirects an axis that is coming to rest. (`running` implies `want.mode == m`.)
    let held = if running && m == AxisMode::Position {
        want.target
    } else {
        held
    };
    let reduced = mode == Mode::Reduced;
    let speed_limit = if reduced { p.reduced_limit } else { p.v_max };
    let (target, step) = match (m, mode) {
        (AxisMode::Coast | AxisMode::Short, _) => (Speed::ZERO, Speed::MAX),
        (AxisMode::Duty, _) => {
            let limit = if reduced { p.duty_reduced } else { p.duty_max };
            let t = if running {
                clamp_sym(want.target, limit)
            } else {
                Speed::ZERO
            };
            (t, p.duty_step)
        }
        (AxisMode::Velocity | AxisMode::Position, Mode::Hold) => (Speed::ZERO, p.hold_decel_step),
        (AxisMode::Velocity | AxisMode::Position, Mode::Stop | Mode::Brake) => {
            (Speed::ZERO, p.stop_decel_step)
        }
        (AxisMode::Velocity, _) => {
            let t = if running {
                clamp_sym(want.target, speed_limit)
            } else {
                Speed::ZERO
            };
            (t, p.accel_step)
        }
        (AxisMode::Position, _) => {
            let t = if running {
                min_q(want.cap, speed_limit)
            } else {
                Speed::ZERO
            };
            (t, p.accel_step)
        }
    };
    (approach(applied, target, step), m, held)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ConfigParams;

    const P: ConfigParams = ConfigParams::DEFAULT;

    type L = Ladder<2>;

    fn cmd(speed: f32, enable: bool) -> Event<2> {
        Event::Frame(Command::velocity([speed, -speed], enable, None))
    }

    const PRIMARY_ENGAGE: Event<2> = Event::Estop {
        source: Source::Primary,
        action: Estop::Engage,
    };
    const PRIMARY_RELEASE: Event<2> = Event::Estop {
        source: Source::Primary,
        action: Estop::Release,
    };
    const REARM: Event<2> = Event::Rearm(Source::Primary);

    /// A ladder armed the way a host does it: enable 0, then enable 1, frame + tick each millisecond.
    fn armed() -> L {
        let mut l = L::new(Config::DEFAULT);
        l.step(cmd(0.0, false));
        l.step(Event::Tick);
        l.step(cmd(0.0, true));
        let out = l.step(Event::Tick);
        assert_eq!(out.mode, Mode::Reduced, "armed ladder starts in REDUCED");
        l
    }

    /// Frame + tick per millisecond until the ladder runs NORMAL at `speed` (rad/s).
    fn cruising(speed: f32) -> L {
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
        let mut l = L::new(Config::DEFAULT);
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
        // Seed 000: HOLD after 2 missed cycles (age 3), STOP at the seed's WDG_HOLD_LEVEL (5), BRAKE at
        // the 9th tick, so strictly within 10 ms of the last frame's arrival (the seed's "10 ms" counted
        // from the frame, not from the next tick). Index = ticks since the last valid frame.
        let expected = [
            (2, Mode::Normal),
            (3, Mode::Hold),
            (4, Mode::Hold),
            (5, Mode::Stop),
            (6, Mode::Stop),
            (7, Mode::Stop),
            (8, Mode::Stop),
            (9, Mode::Brake),
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
        l.step(Event::Frame(Command::velocity([f32::NAN, 0.0], true, None)));
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
        let out = l.step(PRIMARY_ENGAGE);
        assert_eq!(out.drive, Drive::Brake, "same step");
        // Re-arm while engaged: refused.
        l.step(REARM);
        assert_eq!(l.counters().rearm_refused, 1);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        // Release alone does not restart.
        l.step(PRIMARY_RELEASE);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        // Explicit re-arm, but no fresh frame before the tick: still braked.
        l.step(REARM);
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
            Drive::Run([
                AxisDrive::Velocity(Speed::from_num(2) - P.stop_decel_step),
                AxisDrive::Velocity(-(Speed::from_num(2) - P.stop_decel_step))
            ])
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
            l.step(PRIMARY_ENGAGE);
            l
        };
        assert!(brake.is_valid());
        type Breaker = (&'static str, fn(&mut L));
        let broken: [Breaker; 22] = [
            ("applied beyond v_max", |l| {
                l.applied[0] = P.v_max + Speed::from_bits(1)
            }),
            ("applied below -v_max", |l| {
                l.applied[1] = -P.v_max - Speed::from_bits(1)
            }),
            ("last beyond v_max", |l| {
                l.last.axes[1].target = P.v_max + Speed::from_bits(1);
            }),
            ("last in a mode the profile refuses", |l| {
                l.last.axes[0].mode = AxisMode::Position;
            }),
            ("last with a zero threshold", |l| {
                l.last.brake_after = 0;
            }),
            ("threshold in force beyond the profile's", |l| {
                l.brake_after = P.brake_after + 1
            }),
            ("age at the threshold in force while running", |l| {
                l.brake_after = 4;
                l.age = 4;
                l.mode = Mode::Hold;
            }),
            ("coasting axis with a value", |l| {
                l.axis_modes[0] = AxisMode::Coast;
            }),
            ("position cap below zero", |l| {
                l.axis_modes[0] = AxisMode::Position;
                l.applied[0] = -Speed::from_bits(1);
            }),
            ("held position beyond the travel", |l| {
                l.held[1] = P.travel_hi + Speed::from_bits(1)
            }),
            ("ESTOP owner without the flag", |l| {
                l.estop_owners = Source::Service.bit()
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
            ("running without a command", |l| l.has_last = false),
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
    fn is_valid_checks_each_value_of_the_last_setpoint_against_its_mode() {
        // Seed 004 accepts every mode. The last setpoint of a running ladder is replaced on axis 0
        // by one setpoint at a time: a value at a bound is accepted, one step beyond it is refused,
        // and so is a passive mode's or a duty or velocity axis's non-zero value where only zero
        // belongs.
        let cfg = Config::PI_SPI;
        let p = *cfg.params();
        let c = Command::<2>::uniform(crate::types::AxisCommand::velocity(1.0), true, None);
        let good = armed_with(cfg, c);
        assert!(good.is_valid());
        let bit = Speed::from_bits(1);
        let sp = |mode, target, cap| AxisSetpoint { target, cap, mode };
        let zero = Speed::ZERO;
        let cases = [
            (sp(AxisMode::Coast, zero, zero), true),
            (sp(AxisMode::Coast, bit, zero), false),
            (sp(AxisMode::Coast, zero, bit), false),
            (sp(AxisMode::Short, zero, zero), true),
            (sp(AxisMode::Short, -bit, zero), false),
            (sp(AxisMode::Short, zero, bit), false),
            (sp(AxisMode::Duty, p.duty_max, zero), true),
            (sp(AxisMode::Duty, -p.duty_max, zero), true),
            (sp(AxisMode::Duty, p.duty_max + bit, zero), false),
            (sp(AxisMode::Duty, -p.duty_max - bit, zero), false),
            (sp(AxisMode::Duty, zero, bit), false),
            (sp(AxisMode::Velocity, p.v_max, zero), true),
            (sp(AxisMode::Velocity, -p.v_max, zero), true),
            (sp(AxisMode::Velocity, p.v_max + bit, zero), false),
            (sp(AxisMode::Velocity, -p.v_max - bit, zero), false),
            (sp(AxisMode::Velocity, zero, bit), false),
            (sp(AxisMode::Position, p.travel_hi, p.v_max), true),
            (sp(AxisMode::Position, p.travel_lo, zero), true),
            (sp(AxisMode::Position, p.travel_hi + bit, zero), false),
            (sp(AxisMode::Position, p.travel_lo - bit, zero), false),
            (sp(AxisMode::Position, zero, p.v_max + bit), false),
            (sp(AxisMode::Position, zero, -bit), false),
        ];
        for (axis, valid) in cases {
            let mut l = good;
            l.last.axes[0] = axis;
            assert_eq!(l.is_valid(), valid, "{axis:?}");
        }
    }

    #[test]
    fn every_latching_cause_blocks_rearm_and_warnings_do_not_latch() {
        let latching: [Event<2>; 6] = [
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
            PRIMARY_ENGAGE,
            Event::Shutdown(true),
        ];
        for e in latching {
            let mut l = cruising(1.0);
            assert_eq!(l.step(e).drive, Drive::Brake, "{e:?}");
            l.step(REARM);
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
        l.step(PRIMARY_ENGAGE);
        l.step(Event::Condition {
            condition: Condition::Overcurrent,
            active: true,
        });
        l.step(Event::Shutdown(true));
        assert_eq!(l.counters().brake_entries, c0.brake_entries + 1);
        assert_eq!(l.counters().hold_entries, c0.hold_entries + 1);
    }

    #[test]
    fn a_zero_target_is_never_an_acceleration_fault_and_ramps_down() {
        // Seed 000's idle mode decodes into zero velocity targets: stopping is always allowed, and the
        // setpoint still ramps down at accel_step (5 rad/s at 0.05 rad/s per tick: 100 ticks).
        let mut l = cruising(5.0);
        for k in 0..101 {
            l.step(Event::Frame(Command::velocity([0.0, 0.0], true, None)));
            l.step(Event::Tick);
            if k == 50 {
                assert!(l.applied()[0] > Speed::ZERO, "still ramping at tick {k}");
            }
        }
        assert_eq!(l.counters().rejected_total(), 0);
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

    /// Arms a ladder of `N` axes under `cfg` with `c` the way a host does it: enable 0, then 1.
    fn armed_with<const N: usize>(cfg: Config, c: Command<N>) -> Ladder<N> {
        let mut l = Ladder::<N>::new(cfg);
        l.step(Event::Frame(Command { enable: false, ..c }));
        l.step(Event::Tick);
        l.step(Event::Frame(c));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced, "armed");
        l
    }

    #[test]
    fn estop_belongs_to_the_source_that_engaged_it() {
        let mut l = cruising(2.0);
        let service = |action| Event::Estop {
            source: Source::Service,
            action,
        };
        assert_eq!(l.step(service(Estop::Engage)).drive, Drive::Brake);
        // The driving link cannot release the service port's ESTOP, nor re-arm past it.
        l.step(PRIMARY_RELEASE);
        assert_eq!(l.counters().estop_release_refused, 1);
        assert!(l.output().faults.contains(FaultFlags::ESTOP));
        l.step(REARM);
        assert_eq!(l.counters().rearm_refused, 1);
        // Released by its owner: now only the owner's re-arm counts.
        l.step(service(Estop::Release));
        assert!(!l.active.contains(FaultFlags::ESTOP));
        assert_eq!(l.estop_owners(), 0);
        l.step(cmd(0.0, false));
        l.step(Event::Tick);
        l.step(cmd(0.0, true)); // the driving link's enable edge is its re-arm request: refused
        assert_eq!(l.step(Event::Tick).mode, Mode::Brake);
        assert_eq!(l.counters().rearm_refused, 2);
        l.step(Event::Rearm(Source::Service));
        l.step(cmd(0.0, true));
        assert_eq!(
            l.step(Event::Tick).mode,
            Mode::Reduced,
            "the releasing source re-armed"
        );
    }

    #[test]
    fn the_local_input_releases_every_source_and_any_link_may_rearm() {
        let mut l = cruising(2.0);
        l.step(PRIMARY_ENGAGE);
        l.step(Event::Estop {
            source: Source::Service,
            action: Estop::Engage,
        });
        assert_eq!(
            l.estop_owners(),
            Source::Primary.bit() | Source::Service.bit()
        );
        // Releasing one of two owners keeps ESTOP.
        l.step(PRIMARY_RELEASE);
        assert!(l.output().faults.contains(FaultFlags::ESTOP));
        l.step(Event::Estop {
            source: Source::Local,
            action: Estop::Release,
        });
        assert!(!l.active.contains(FaultFlags::ESTOP));
        l.step(REARM);
        l.step(cmd(0.0, true));
        assert_eq!(l.step(Event::Tick).mode, Mode::Reduced);
    }

    #[test]
    fn a_frame_timeout_brings_brake_earlier_never_later() {
        let duty = |timeout_ms: Option<u16>| Command::<4> {
            timeout: timeout_ms.and_then(crate::config::brake_age_for_timeout_ms),
            ..Command::uniform(crate::types::AxisCommand::duty(0.2), true, None)
        };
        for (timeout_ms, brake_tick) in [
            (Some(200), 199),
            (None, 249),
            (Some(5000), 249),
            (Some(30), 29),
        ] {
            let mut l = armed_with(Config::CDC, duty(timeout_ms));
            // The last valid frame; tick k makes age k.
            l.step(Event::Frame(duty(timeout_ms)));
            for k in 1..=brake_tick {
                let out = l.step(Event::Tick);
                assert_eq!(
                    out.mode == Mode::Brake,
                    k == brake_tick,
                    "timeout {timeout_ms:?}, tick {k}"
                );
            }
        }
    }

    #[test]
    fn duty_axes_ramp_coast_at_once_and_fall_to_zero_when_the_link_is_late() {
        let cfg = Config::CDC;
        let p = *cfg.params();
        let c = Command::<4> {
            axes: [
                crate::types::AxisCommand::duty(0.5),
                crate::types::AxisCommand::duty(-0.5),
                crate::types::AxisCommand::COAST,
                crate::types::AxisCommand::duty(1.0),
            ],
            ..Command::uniform(crate::types::AxisCommand::COAST, true, None)
        };
        let mut l = armed_with(cfg, c);
        // REDUCED after arming: duties ramp by duty_step toward ±duty_reduced.
        assert_eq!(l.applied()[0], p.duty_step);
        assert_eq!(l.applied()[1], -p.duty_step);
        let Drive::Run(axes) = l.output().drive else {
            panic!("running")
        };
        assert_eq!(axes[2], AxisDrive::Coast);
        for _ in 0..400 {
            l.step(Event::Frame(c));
            l.step(Event::Tick);
        }
        assert_eq!(l.applied()[3], p.duty_reduced, "REDUCED caps the duty");
        // Late link: HOLD at age 41, duties fall by duty_step per tick, never reverse. The last tick
        // above made age 1; 40 more make it 41.
        let before = l.applied();
        for _ in 0..40 {
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Hold);
        assert_eq!(l.applied()[3], before[3] - p.duty_step);
        for _ in 0..100 {
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Stop);
        assert_eq!(l.applied(), [Speed::ZERO; 4]);
    }

    #[test]
    fn a_position_axis_runs_under_a_cap_that_falls_to_zero_when_the_link_is_late() {
        let cfg = Config::PI_SPI;
        let p = *cfg.params();
        let c = Command::<2>::uniform(crate::types::AxisCommand::position(1.5, 4.0), true, None);
        let mut l = armed_with(cfg, c);
        let target = Speed::from_num(1.5);
        assert_eq!(
            l.output().drive,
            Drive::Run(
                [AxisDrive::Position {
                    target,
                    cap: p.accel_step
                }; 2]
            )
        );
        for _ in 0..2000 {
            l.step(Event::Frame(c));
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Normal);
        assert_eq!(
            l.applied()[0],
            Speed::from_num(4),
            "the cap reaches the command's"
        );
        // Age 1 after the loop; 20 more ticks: age 21, the first HOLD tick.
        for _ in 0..20 {
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Hold);
        assert_eq!(l.applied()[0], Speed::from_num(4) - p.hold_decel_step);
        assert_eq!(
            l.output().drive,
            Drive::Run(
                [AxisDrive::Position {
                    target,
                    cap: l.applied()[0]
                }; 2]
            ),
            "HOLD keeps the target and lowers the cap"
        );
    }

    #[test]
    fn frames_with_enable_0_do_not_redirect_a_position_axis_that_is_stopping() {
        let cfg = Config::PI_SPI;
        let p = *cfg.params();
        let a = Command::<2>::uniform(crate::types::AxisCommand::position(1.5, 4.0), true, None);
        let mut l = armed_with(cfg, a);
        for _ in 0..2000 {
            l.step(Event::Frame(a));
            l.step(Event::Tick);
        }
        assert_eq!(l.mode(), Mode::Normal);
        let cap = l.applied()[0];
        assert!(
            cap > p.stop_decel_step,
            "the axis is moving: its cap is above one STOP step"
        );
        // The host disables the drive and, in the same frames, asks for another target.
        let b = Command::<2>::uniform(crate::types::AxisCommand::position(-1.0, 4.0), false, None);
        l.step(Event::Frame(b));
        l.step(Event::Tick);
        assert_eq!(l.mode(), Mode::Stop);
        let held = Drive::Run(
            [AxisDrive::Position {
                target: Speed::from_num(1.5),
                cap: cap - p.stop_decel_step,
            }; 2],
        );
        assert_eq!(
            l.output().drive,
            held,
            "STOP keeps the target and lowers the cap"
        );
        // §1: the axis comes to rest toward the target it had, whatever the disabled frames ask.
        while l.applied()[0] > Speed::ZERO {
            l.step(Event::Frame(b));
            l.step(Event::Tick);
            assert_eq!(l.mode(), Mode::Stop);
            let Drive::Run(axes) = l.output().drive else {
                panic!("STOP drives the axes")
            };
            assert!(
                matches!(axes[0], AxisDrive::Position { target, .. } if target == Speed::from_num(1.5)),
                "a disabled frame's target never reaches the drive"
            );
        }
    }

    #[test]
    fn an_axis_changes_drive_mode_only_from_rest() {
        let cfg = Config::PI_SPI;
        let v = Command::<2>::uniform(crate::types::AxisCommand::velocity(1.0), true, None);
        let mut l = armed_with(cfg, v);
        for _ in 0..100 {
            l.step(Event::Frame(v));
            l.step(Event::Tick);
        }
        assert_eq!(l.applied()[0], Speed::from_num(1));
        let d = Command::<2>::uniform(crate::types::AxisCommand::duty(0.5), true, None);
        let mut ticks = 0;
        while l.axis_modes()[0] == AxisMode::Velocity {
            l.step(Event::Frame(d));
            l.step(Event::Tick);
            ticks += 1;
            assert!(ticks < 100, "velocity ramps down first");
        }
        // 1 rad/s at 0.05 rad/s per tick: 20 ticks to rest, the switch at the tick after.
        assert_eq!(ticks, 21);
        assert_eq!(l.axis_modes()[0], AxisMode::Duty);
        // Coasting takes over at once, whatever the axis was doing.
        for _ in 0..50 {
            l.step(Event::Frame(d));
            l.step(Event::Tick);
        }
        assert!(l.applied()[0] > Speed::ZERO);
        l.step(Event::Frame(Command::uniform(
            crate::types::AxisCommand::COAST,
            true,
            None,
        )));
        l.step(Event::Tick);
        assert_eq!(l.output().drive, Drive::Run([AxisDrive::Coast; 2]));
    }
}
