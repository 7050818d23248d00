//! A reference model of the ladder written from the rules of `proofs/SAFETY.md` (§1 the rungs,
//! §3 SR-1 … SR-15, §4 INV-0 … INV-19, §8 the decisions), not from `Ladder`'s code. It tracks what
//! the rules make observable: the rung, whether BRAKE is latched and why, the age and the comm-loss
//! threshold in force, the last valid command, the re-arm that is pending, the ESTOP holders and the
//! source whose release ended an ESTOP, the counters SR-14 and SR-8 name (refused ESTOP releases,
//! refused re-arms, re-arms that released BRAKE), the link-quality strikes and the REDUCED state they
//! give, and per axis its drive mode, its applied value and its position target.
//!
//! The model decides everything itself: it validates each frame by SR-3, SR-4 and §8 ([`validate`]
//! below, its own code), keeps its own strike window (§1 REDUCED), changes each axis's mode by
//! SR-15 and INV-19, and recomputes each applied value by §1's table "What each drive mode does on
//! each rung" and SR-5. The ladder's public API is used for the types and the profile's numbers
//! only. Every value is Q16.16 fixed point, so the model's ramps are exact and the comparison is
//! exact: the applied values, the axis modes and the drive output must equal the model's, bit for
//! bit. Where the document leaves a choice open, the model states the reading it takes next to the
//! code, citing the rule.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic,
    dead_code,
    missing_docs
)]

use statemachine::{
    AxisDrive, AxisMode, AxisSetpoint, Command, Condition, Config, Drive, Estop, Event, FaultFlags,
    Ladder, Mode, Position, Setpoint, Source, Speed,
};
use std::collections::VecDeque;

/// The conditions that latch BRAKE and keep a re-arm refused while active (SR-6, SR-8).
fn brakes(c: Condition) -> bool {
    matches!(
        c,
        Condition::Overcurrent
            | Condition::Overtemperature
            | Condition::EncoderFailure
            | Condition::Undervoltage
    )
}

/// Why the model refuses a frame (SR-3, SR-4; the names of `RejectReason`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    UnsupportedMode,
    NonFinite,
    OutOfRange,
    Stale,
    Acceleration,
}

/// A finite `f32` as Q16.16 (SR-4: numbers are held as `Speed`, `Duty`, `Position`), or `None` if it
/// does not fit. INV-5: the held value equals the sent one "to within half a Q16.16 LSB", that is
/// rounded to the nearest step. Reading for the ties, which the rule leaves open (both neighbours are
/// half an LSB away): to even, IEEE 754's default rounding. The product by 2¹⁶ is exact in f64.
fn q16(x: f32) -> Option<Speed> {
    let r = (f64::from(x) * 65536.0).round_ties_even();
    if (-2_147_483_648.0..=2_147_483_647.0).contains(&r) {
        Some(Speed::from_bits(r as i32))
    } else {
        None
    }
}

/// SR-4: one axis, its mode accepted by the profile, its numbers finite and in the mode's range.
/// Reading: the range is checked on the Q16.16 value the ladder would hold (the limits are the
/// profile's Q16.16 numbers, and INV-5 states the ranges of the held values); a number too large
/// for Q16.16 is beyond every limit (`Config` keeps v_max ≤ 1000, the travel within ±10 000 and
/// duty_max ≤ 1), so out of range. Non-finite numbers are refused before any range (§8 "NaN").
fn validate_axis(a: &statemachine::AxisCommand, cfg: &Config) -> Result<AxisSetpoint, Refusal> {
    let p = cfg.params();
    if !p.modes.contains(a.mode) {
        return Err(Refusal::UnsupportedMode);
    }
    let within = |x: Speed, lo: Speed, hi: Speed| lo <= x && x <= hi;
    match a.mode {
        // SR-4: "the passive modes ignore their numbers"; INV-5: passive axes carry zeros.
        AxisMode::Coast | AxisMode::Short => Ok(AxisSetpoint {
            target: Speed::ZERO,
            cap: Speed::ZERO,
            mode: a.mode,
        }),
        AxisMode::Duty | AxisMode::Velocity => {
            if !a.target.is_finite() {
                return Err(Refusal::NonFinite);
            }
            let limit = if a.mode == AxisMode::Duty {
                p.duty_max
            } else {
                p.v_max
            };
            match q16(a.target) {
                Some(t) if within(t, -limit, limit) => Ok(AxisSetpoint {
                    target: t,
                    cap: Speed::ZERO,
                    mode: a.mode,
                }),
                _ => Err(Refusal::OutOfRange),
            }
        }
        AxisMode::Position => {
            if !a.target.is_finite() || !a.cap.is_finite() {
                return Err(Refusal::NonFinite);
            }
            let target = q16(a.target).filter(|&t| within(t, p.travel_lo, p.travel_hi));
            let cap = q16(a.cap).filter(|&c| within(c, Speed::ZERO, p.v_max));
            match (target, cap) {
                (Some(target), Some(cap)) => Ok(AxisSetpoint {
                    target,
                    cap,
                    mode: a.mode,
                }),
                _ => Err(Refusal::OutOfRange),
            }
        }
    }
}

/// SR-3: `seq` is newer than `prev`. Reading: the number is a 32-bit counter that wraps (after
/// 49.7 days at 1 kHz), and "newer" must survive the wrap, so it means ahead by 1 ..= 2³¹ − 1
/// modulo 2³²; a repeat or anything up to 2³¹ behind is not newer.
fn newer(seq: u32, prev: u32) -> bool {
    let d = seq.wrapping_sub(prev);
    d != 0 && d < 1 << 31
}

/// SR-3, SR-4 and §8's decisions: the setpoint a frame gives, or why it is refused. `last` is the
/// last valid command (none after a latch) and `age` the ticks since it arrived.
///
/// - SR-4 per axis ([`validate_axis`]); "a `timeout` of 0 is refused" (as out of range, the reason
///   `RejectReason::OutOfRange` names); SR-1: the threshold a frame leaves in force is its own
///   `timeout` capped by the profile's `brake_after`, the profile's without one.
/// - SR-3 where both the frame and the last valid command carry a sequence number. Reading: a frame
///   without one, or the first one after a command without one, has nothing to be compared with.
/// - SR-4's acceleration rule with §8 "Acceleration check after lost frames": only a velocity
///   target on an axis that the last valid command and this one both drive in velocity mode, not a
///   zero target, and not in a frame that disables (§8: "Frames that stop (disable, a zero target,
///   a passive mode) are never refused"). Reading of "both drive": a command drives its axes only
///   while enabled (a disabled one puts the ladder in STOP, §1, and every axis ramps to zero), so
///   after a disabled command there is no driven target to be within the allowance of. The allowance is `max_cmd_step` times the ticks since the
///   last valid frame. Reading: a second frame before the next tick (age 0) is allowed one tick's
///   worth, so a frame that slips ahead of its tick does not lock the host out. Compared on the
///   Q16.16 values (integers: no rounding at the boundary).
pub fn validate<const N: usize>(
    cmd: &Command<N>,
    last: Option<&Setpoint<N>>,
    age: u16,
    cfg: &Config,
) -> Result<Setpoint<N>, Refusal> {
    let p = cfg.params();
    let mut axes = [AxisSetpoint {
        target: Speed::ZERO,
        cap: Speed::ZERO,
        mode: AxisMode::Coast,
    }; N];
    for (out, a) in axes.iter_mut().zip(cmd.axes.iter()) {
        *out = validate_axis(a, cfg)?;
    }
    let brake_after = match cmd.timeout {
        Some(0) => return Err(Refusal::OutOfRange),
        Some(t) => t.min(p.brake_after),
        None => p.brake_after,
    };
    if let (Some(seq), Some(prev)) = (cmd.seq, last.and_then(|l| l.seq())) {
        if !newer(seq, prev) {
            return Err(Refusal::Stale);
        }
    }
    if let Some(last) = last.filter(|l| l.enable && cmd.enable) {
        let ticks = i64::from(age.max(1));
        let allowance = i64::from(p.max_cmd_step.to_bits()) * ticks;
        for (new, old) in axes.iter().zip(last.axes.iter()) {
            if new.mode == AxisMode::Velocity
                && old.mode == AxisMode::Velocity
                && new.target != Speed::ZERO
                && (i64::from(new.target.to_bits()) - i64::from(old.target.to_bits())).abs()
                    > allowance
            {
                return Err(Refusal::Acceleration);
            }
        }
    }
    Ok(Setpoint {
        axes,
        seq_value: cmd.seq.unwrap_or(0),
        brake_after,
        has_seq: cmd.seq.is_some(),
        enable: cmd.enable,
    })
}

/// SR-5: moves `cur` toward `target` by at most `step`, never past it.
fn approach(cur: Speed, target: Speed, step: Speed) -> Speed {
    if cur < target {
        (cur + step).min(target)
    } else {
        (cur - step).max(target)
    }
}

/// `x` limited to ±`limit`.
fn clamp_sym(x: Speed, limit: Speed) -> Speed {
    x.max(-limit).min(limit)
}

/// One axis as the rules describe it: its drive mode, its applied value (speed setpoint, duty or
/// position cap; zero for the passive modes) and, in position mode, the target it is driven to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Axis {
    pub mode: AxisMode,
    pub value: Speed,
    pub target: Position,
}

/// The observable state the rules speak of.
#[derive(Clone, Debug)]
pub struct Model<const N: usize> {
    pub cfg: Config,
    pub mode: Mode,
    pub latched: bool,
    /// Why BRAKE latched (§1 table "entered when"); cleared when BRAKE is released.
    pub causes: FaultFlags,
    /// Board conditions active now (SR-6, SR-12).
    pub conditions: FaultFlags,
    pub shutdown: bool,
    /// SR-14: the sources holding ESTOP, as `Source::bit`s.
    pub estop_owners: u8,
    /// SR-14: the source whose release ended the last ESTOP.
    pub released_by: Option<Source>,
    /// The last valid command (SR-8: none after a latch until the next valid frame).
    pub last: Option<Setpoint<N>>,
    /// §1: ticks since the last valid frame, saturating at 65535.
    pub age: u16,
    /// SR-1: the threshold in force.
    pub threshold: u16,
    /// SR-8: enable of the last valid frame, for the 0 → 1 edge.
    pub prev_enable: bool,
    pub rearm_pending: bool,
    /// SR-8: a valid frame arrived since the previous tick.
    pub fresh: bool,
    pub estop_release_refused: u32,
    pub rearm_refused: u32,
    pub rearms: u32,
    /// Ticks so far: events between two ticks are dated by the count of the earlier one.
    pub ticks: u64,
    /// The dates of the strikes (refused frames, HOLD entries; §1 REDUCED) of the current window.
    pub strikes: VecDeque<u64>,
    /// Strikes since the previous tick.
    pub strikes_since_tick: u32,
    /// §1 REDUCED: the link is degraded (the feedback's LINK_DEGRADED).
    pub degraded: bool,
    /// Clean ticks in a row while degraded (§1 "back to NORMAL after a clean window").
    pub clean: u64,
    /// Each axis (§1 "What each drive mode does on each rung", SR-15).
    pub axes: [Axis; N],
}

/// The ladder's state before an event, for the checks that compare before and after.
pub struct Before<const N: usize> {
    pub mode: Mode,
    pub applied: [Speed; N],
    pub axis_modes: [AxisMode; N],
    pub ladder: Ladder<N>,
}

impl<const N: usize> Model<N> {
    /// Power-on (SR-8: "Power-on starts in BRAKE"). SAFETY.md does not say what the age is before
    /// the first frame; the model starts from the ladder's (it only has to be ≥ 0), and the
    /// threshold in force is the profile's `brake_after` (SR-1: no frame has lowered it). Reading:
    /// each axis powers on at rest, coasting (§1: BRAKE applies nothing; the mode an axis has in
    /// BRAKE is not observable in the drive, and the first tick out of BRAKE finds it at rest).
    pub fn new(cfg: Config, initial_age: u16) -> Self {
        Self {
            cfg,
            mode: Mode::Brake,
            latched: true,
            causes: FaultFlags::POWER_ON,
            conditions: FaultFlags::NONE,
            shutdown: false,
            estop_owners: 0,
            released_by: None,
            last: None,
            age: initial_age,
            threshold: cfg.params().brake_after,
            prev_enable: true,
            rearm_pending: false,
            fresh: false,
            estop_release_refused: 0,
            rearm_refused: 0,
            rearms: 0,
            ticks: 0,
            strikes: VecDeque::new(),
            strikes_since_tick: 0,
            degraded: false,
            clean: 0,
            // §1: before its first position command an axis holds the travel's lower limit as its
            // target; only a NORMAL or REDUCED tick gives it the command's, and until then its
            // cap is zero.
            axes: [Axis {
                mode: AxisMode::Coast,
                value: Speed::ZERO,
                target: cfg.params().travel_lo,
            }; N],
        }
    }

    /// A latching cause is active (SR-8: "no latching cause active").
    fn cause_active(&self) -> bool {
        self.estop_owners != 0 || self.shutdown || self.conditions.0 & latching_conditions().0 != 0
    }

    /// SR-12 and §1: a thermal warning or a lost clock sync degrades the link while active.
    fn degrading_active(&self) -> bool {
        self.conditions.intersects(FaultFlags::THERMAL_WARNING)
            || self.conditions.intersects(FaultFlags::CLOCK_SYNC_LOST)
    }

    /// Latches BRAKE for `cause` (SR-6, SR-9, SR-10, SR-1). Reading of SR-8 ("the primary link's
    /// enable 0 → 1 edge observed after the latch", H-8): every latch forgets the held command and
    /// any pending re-arm, and takes the enable as 1, so only an enable 0 frame and then an enable 1
    /// frame after this latch make an edge. §1: in BRAKE every applied value is zero (INV-0).
    fn latch(&mut self, cause: FaultFlags) {
        self.latched = true;
        self.mode = Mode::Brake;
        self.causes = self.causes.union(cause);
        self.last = None;
        self.prev_enable = true;
        self.rearm_pending = false;
        for a in &mut self.axes {
            a.value = Speed::ZERO;
        }
    }

    /// §1 REDUCED: a strike (a refused frame, an entry into HOLD). The link is degraded once
    /// `strike_limit` strikes fall within one window, and once degraded any strike is a tick that
    /// is not clean. Reading of "in a window" (§1, §8 "in a 1 s window"; `ConfigParams::window`:
    /// "within one window"): the windows are consecutive spans of `window` ticks from power-on, the
    /// k-th holding the events dated k·window ..= (k + 1)·window − 1. SAFETY.md does not say
    /// whether the window slides; the fixed one is the reading its "one window" names.
    fn strike(&mut self) {
        self.strikes.push_back(self.ticks);
        self.strikes_since_tick += 1;
        self.forget_old_strikes();
        if self.degraded || self.strikes.len() >= usize::from(self.cfg.params().strike_limit) {
            self.dirty();
        }
    }

    /// Keeps the strikes of the current window only.
    fn forget_old_strikes(&mut self) {
        let window = u64::from(self.cfg.params().window);
        let now = self.ticks / window;
        while self.strikes.front().is_some_and(|&t| t / window < now) {
            self.strikes.pop_front();
        }
    }

    /// An event that degrades the link (§1: `strike_limit` strikes, a link loss that reached STOP,
    /// a thermal warning, clock sync lost, a re-arm): the clean window starts again.
    fn dirty(&mut self) {
        self.degraded = true;
        self.clean = 0;
    }

    /// A re-arm request from `source` (SR-8, SR-14). Reading: a request counts only while BRAKE is
    /// latched (INV-6: a re-arm is pending only in BRAKE); it is refused while a latching cause is
    /// active, and after an ESTOP latch from any source but the one whose release ended the ESTOP
    /// (any source if that was the board's input, `Source::Local`).
    fn request_rearm(&mut self, source: Source) {
        if !self.latched {
            return;
        }
        let estop_ok = !self.causes.intersects(FaultFlags::ESTOP)
            || match self.released_by {
                Some(Source::Local) => true,
                Some(s) => s == source,
                None => false,
            };
        if !self.cause_active() && estop_ok {
            self.rearm_pending = true;
        } else {
            // SR-14: refused re-arms are counted. SR-8: a refused request also withdraws a pending
            // one, so a second link can delay the owner's re-arm, never hasten it.
            self.rearm_refused += 1;
            self.rearm_pending = false;
        }
    }

    /// Feeds one event.
    pub fn step(&mut self, event: &Event<N>) {
        match *event {
            Event::Tick => self.tick(),
            Event::Frame(cmd) => match validate(&cmd, self.last.as_ref(), self.age, &self.cfg) {
                Ok(sp) => {
                    // SR-1: a valid frame restarts the age and sets its own threshold.
                    self.age = 0;
                    self.threshold = sp.brake_after;
                    self.fresh = true;
                    let edge = !self.prev_enable && sp.enable;
                    self.prev_enable = sp.enable;
                    self.last = Some(sp);
                    // SR-14: the enable 0 → 1 edge is the primary link's re-arm request.
                    if edge {
                        self.request_rearm(Source::Primary);
                    }
                }
                // SR-2: counters and strikes only.
                Err(_) => self.strike(),
            },
            Event::Rejected(_) => self.strike(),
            Event::Condition { condition, active } => {
                let flag = condition.flag();
                if active {
                    self.conditions = self.conditions.union(flag);
                    // SR-12, §1: a thermal warning or a lost clock sync degrades. Reading: the
                    // rung is chosen at ticks (§1), so a warning degrades at the ticks that find
                    // it active; one that comes and goes between two ticks changes no rung.
                    if brakes(condition) {
                        self.latch(flag);
                    }
                } else {
                    self.conditions = self.conditions.without(flag);
                }
            }
            Event::Estop {
                source,
                action: Estop::Engage,
            } => {
                self.estop_owners |= source.bit();
                // SR-14: a new ESTOP has not been ended by anyone yet.
                self.released_by = None;
                self.latch(FaultFlags::ESTOP);
            }
            Event::Estop {
                source,
                action: Estop::Release,
            } => {
                let held = self.estop_owners != 0;
                if source == Source::Local {
                    // SR-14: the board's input releases every source's hold.
                    self.estop_owners = 0;
                } else if self.estop_owners & source.bit() == 0 {
                    // SR-14: a link's release of an ESTOP it does not hold is refused and counted.
                    // Reading: only while some source holds one; with no ESTOP engaged there is no
                    // hold to take from anyone, and the release is a no-op.
                    if held {
                        self.estop_release_refused += 1;
                    }
                } else {
                    self.estop_owners &= !source.bit();
                }
                // SR-14 "the source whose release ended the ESTOP": reading, a release that finds
                // no ESTOP held ends nothing and leaves the record as it was.
                if held && self.estop_owners == 0 {
                    self.released_by = Some(source);
                }
            }
            Event::Shutdown(on) => {
                self.shutdown = on;
                if on {
                    self.latch(FaultFlags::SHUTDOWN);
                }
            }
            Event::Rearm(source) => self.request_rearm(source),
        }
    }

    /// A watchdog tick: the age advances (SR-1), BRAKE is released if SR-8 allows it, the comm-loss
    /// test, the rung (§1 table, SR-7), the link quality, then each axis (§1, SR-5, SR-15).
    fn tick(&mut self) {
        let p = *self.cfg.params();
        self.ticks += 1;
        self.age = self.age.saturating_add(1);
        let enabled = self.last.is_some_and(|l| l.enable);
        // SR-8 / INV-6: released only at a tick, with a re-arm pending, a valid frame since the
        // previous tick, enable = 1, no latching cause active. Reading: the release is decided on
        // the age this tick gives; a frame whose own threshold that age already reaches brakes
        // again (SR-1 wins).
        if self.latched
            && self.rearm_pending
            && self.fresh
            && enabled
            && !self.cause_active()
            && self.age < self.threshold
        {
            self.latched = false;
            self.causes = FaultFlags::NONE;
            self.rearm_pending = false;
            self.rearms += 1;
            // §1: a re-arm enters REDUCED. Reading of "after a clean window": the re-arm is how
            // the ladder comes back, not a fault of this tick, so its tick is the first of the
            // clean window; REDUCED then lasts `window` ticks, as after a strike between ticks.
            self.dirty();
        }
        if self.age >= self.threshold {
            // SR-1: comm loss "from every state". Reading: it is a latch cause of its own also when
            // BRAKE is already latched (the feedback names it; §1 lists it among BRAKE's entries),
            // and like every latch it forgets a pending re-arm.
            self.latch(FaultFlags::COMM_LOST);
        }
        if self.degrading_active() {
            self.dirty();
        }
        let before = self.mode;
        if !self.latched {
            self.mode = if self.age >= p.stop_after || !enabled {
                Mode::Stop
            } else if self.age >= p.hold_after {
                Mode::Hold
            } else if self.degraded {
                Mode::Reduced
            } else {
                Mode::Normal
            };
        }
        // §1: an entry into HOLD is a strike.
        if self.mode == Mode::Hold && before != Mode::Hold {
            self.strike();
        }
        self.forget_old_strikes();
        // §1 "back to NORMAL after a clean window": `window` clean ticks in a row. Readings: a
        // tick is not clean when the link loss has reached STOP's age (which degrades: "a link
        // loss that reached STOP"; in BRAKE this is moot, the re-arm degrades again) or while
        // frames are late (age ≥ hold_after: HOLD is not a clean link, though only its entry is a
        // strike); the flag clears at the tick that completes the window, after that tick's rung
        // was chosen, so NORMAL comes at the next tick.
        if self.age >= p.stop_after {
            self.dirty();
        } else if self.age >= p.hold_after {
            self.clean = 0;
        } else if self.degraded && !self.degrading_active() {
            self.clean += 1;
            if self.clean >= u64::from(p.window) {
                self.degraded = false;
                self.clean = 0;
            }
        }
        if !self.latched {
            let cmd = self.last.unwrap();
            for i in 0..N {
                self.axis_tick(i, cmd.axes[i]);
            }
        }
        self.fresh = false;
        self.strikes_since_tick = 0;
    }

    /// One axis at a tick outside BRAKE, by §1's table "What each drive mode does on each rung",
    /// SR-5 (one step per tick, toward the rung's limit only while falling), SR-15 and INV-19.
    fn axis_tick(&mut self, i: usize, cmd: AxisSetpoint) {
        let p = *self.cfg.params();
        let rung = self.mode;
        let ax = &mut self.axes[i];
        // SR-15: a passive request becomes coast or short at the next tick, in every rung; passive
        // axes apply nothing.
        if cmd.mode.is_passive() {
            *ax = Axis {
                mode: cmd.mode,
                value: Speed::ZERO,
                target: ax.target,
            };
            return;
        }
        // The step of the axis's own mode on this rung (§1 table): speeds and caps by `accel_step`
        // toward the target, `hold_decel_step` or `stop_decel_step` toward zero; duties by
        // `duty_step` on every rung.
        let step = |mode: AxisMode| match (mode, rung) {
            (AxisMode::Duty, _) => p.duty_step,
            (_, Mode::Hold) => p.hold_decel_step,
            (_, Mode::Stop) => p.stop_decel_step,
            _ => p.accel_step,
        };
        if ax.mode != cmd.mode {
            if ax.value != Speed::ZERO {
                // §1, INV-19: the old mode's value ramps to zero first, at its rung's step; a
                // position axis keeps its target meanwhile (the ladder never moves it on its own).
                ax.value = approach(ax.value, Speed::ZERO, step(ax.mode));
                return;
            }
            // From rest the new mode takes over. Reading of "then the new mode takes over": at the
            // tick that finds the axis at rest, which applies the new mode's rule at once (one
            // step from zero), on every rung.
            ax.mode = cmd.mode;
        }
        let toward_target = matches!(rung, Mode::Normal | Mode::Reduced);
        // Position (§1 table): "target: the command's" in NORMAL and REDUCED, "target held" in HOLD
        // and STOP: the axis keeps the target it had while its cap falls to zero, whatever targets
        // the frames that still arrive carry (in STOP from enable = 0 the host keeps sending them).
        if ax.mode == AxisMode::Position && toward_target {
            ax.target = cmd.target;
        }
        let (limit, duty_limit) = match rung {
            Mode::Reduced => (p.reduced_limit, p.duty_reduced),
            _ => (p.v_max, p.duty_max),
        };
        ax.value = match ax.mode {
            AxisMode::Coast | AxisMode::Short => Speed::ZERO,
            // NORMAL and REDUCED: toward the target clamped to the rung's limit (REDUCED:
            // "commanded, clamped, ramped"; above the limit only while falling, SR-5).
            AxisMode::Duty if toward_target => {
                approach(ax.value, clamp_sym(cmd.target, duty_limit), p.duty_step)
            }
            AxisMode::Velocity if toward_target => {
                approach(ax.value, clamp_sym(cmd.target, limit), p.accel_step)
            }
            // Position: the cap ramps toward min(command's cap, the rung's limit).
            AxisMode::Position if toward_target => {
                approach(ax.value, cmd.cap.min(limit), p.accel_step)
            }
            // HOLD and STOP: toward zero at the rung's step.
            m => approach(ax.value, Speed::ZERO, step(m)),
        };
    }

    /// The flags the feedback frame must carry.
    fn faults(&self) -> FaultFlags {
        let mut f = self.conditions.union(self.causes);
        if self.estop_owners != 0 {
            f = f.union(FaultFlags::ESTOP);
        }
        if self.shutdown {
            f = f.union(FaultFlags::SHUTDOWN);
        }
        if self.latched {
            f = f.union(FaultFlags::BRAKE_LATCHED);
        }
        if self.degraded {
            f = f.union(FaultFlags::LINK_DEGRADED);
        }
        f
    }

    /// Each axis's applied value (§1: zero for the passive modes and in BRAKE).
    pub fn applied(&self) -> [Speed; N] {
        self.axes.map(|a| a.value)
    }

    /// The drive the rules ask for: BRAKE, or each axis in its own mode with its applied value
    /// (INV-7, INV-17).
    pub fn drive(&self) -> Drive<N> {
        if self.mode == Mode::Brake {
            return Drive::Brake;
        }
        Drive::Run(self.axes.map(|a| match a.mode {
            AxisMode::Coast => AxisDrive::Coast,
            AxisMode::Short => AxisDrive::Short,
            AxisMode::Duty => AxisDrive::Duty(a.value),
            AxisMode::Velocity => AxisDrive::Velocity(a.value),
            AxisMode::Position => AxisDrive::Position {
                target: a.target,
                cap: a.value,
            },
        }))
    }
}

fn latching_conditions() -> FaultFlags {
    FaultFlags::OVERCURRENT
        .union(FaultFlags::OVERTEMPERATURE)
        .union(FaultFlags::ENCODER)
        .union(FaultFlags::UNDERVOLTAGE)
}

/// Feeds `event` to both, then checks that they agree on everything observable.
pub fn step_both<const N: usize>(ladder: &mut Ladder<N>, model: &mut Model<N>, event: Event<N>) {
    let before = Before {
        mode: ladder.mode(),
        applied: ladder.applied(),
        axis_modes: ladder.axis_modes(),
        ladder: *ladder,
    };
    let model_before = model.clone();
    let out = ladder.step(event);
    model.step(&event);
    check(ladder, model, &model_before, &before, &event, &out);
}

fn check<const N: usize>(
    ladder: &Ladder<N>,
    model: &Model<N>,
    mb: &Model<N>,
    before: &Before<N>,
    event: &Event<N>,
    out: &statemachine::Output<N>,
) {
    let p = *model.cfg.params();
    let ctx = || {
        format!(
            "after {event:?}\nmodel {model:?}\nladder before {:?}\nladder {ladder:?}",
            before.ladder
        )
    };

    // The rung, BRAKE and its drive (§1, SR-6, SR-8, SR-9, SR-10, INV-7).
    assert_eq!(ladder.mode(), model.mode, "rung {}", ctx());
    assert_eq!(out.mode, model.mode, "output rung {}", ctx());
    assert_eq!(ladder.brake_latched(), model.latched, "latch {}", ctx());
    // Why it latched, what is active, and the link quality (the feedback flags; §1 REDUCED).
    // LINK_DEGRADED is compared outside BRAKE, where §1 gives it a meaning (the rung it selects).
    let mask = if model.latched {
        FaultFlags::LINK_DEGRADED
    } else {
        FaultFlags::NONE
    };
    assert_eq!(
        out.faults.without(mask),
        model.faults().without(mask),
        "faults {}",
        ctx()
    );
    // SR-1: age and threshold.
    assert_eq!(ladder.age(), model.age, "age {}", ctx());
    assert_eq!(out.age, model.age, "output age {}", ctx());
    assert_eq!(ladder.brake_after(), model.threshold, "threshold {}", ctx());
    assert!(model.threshold >= 1 && model.threshold <= p.brake_after);
    // SR-3, SR-4, SR-8: the command held, as the model validated it.
    assert_eq!(ladder.last_valid(), model.last, "last valid {}", ctx());
    // SR-14: the ESTOP holders and refused releases.
    assert_eq!(
        ladder.estop_owners(),
        model.estop_owners,
        "owners {}",
        ctx()
    );
    assert_eq!(
        ladder.counters().estop_release_refused,
        model.estop_release_refused,
        "refused releases {}",
        ctx()
    );
    assert_eq!(ladder.counters().rearms, model.rearms, "re-arms {}", ctx());
    assert_eq!(
        ladder.counters().rearm_refused,
        model.rearm_refused,
        "refused re-arms {}",
        ctx()
    );

    // Each axis: its applied value (SR-5, INV-3, INV-8, INV-16), its mode outside BRAKE (SR-15,
    // INV-17, INV-19) and the drive (INV-7, INV-15, INV-17), exactly as the model computed them.
    assert_eq!(
        ladder.applied(),
        model.applied(),
        "applied values {}",
        ctx()
    );
    if !model.latched {
        assert_eq!(
            ladder.axis_modes(),
            model.axes.map(|a| a.mode),
            "axis modes {}",
            ctx()
        );
    }
    assert_eq!(out.drive, model.drive(), "drive {}", ctx());

    // SR-2 / INV-4: a refused frame changes nothing but counters and strikes.
    let refused = match event {
        Event::Rejected(_) => true,
        Event::Frame(_) => mb.strikes_since_tick != model.strikes_since_tick,
        _ => false,
    };
    if refused {
        assert_eq!(
            ladder.mode(),
            before.mode,
            "refused frame moved the rung {}",
            ctx()
        );
        assert_eq!(
            ladder.applied(),
            before.applied,
            "refused frame moved a value {}",
            ctx()
        );
        assert_eq!(ladder.axis_modes(), before.axis_modes, "{}", ctx());
        assert_eq!(ladder.age(), before.ladder.age(), "{}", ctx());
        assert_eq!(
            ladder.brake_after(),
            before.ladder.brake_after(),
            "{}",
            ctx()
        );
        assert_eq!(ladder.last_valid(), before.ladder.last_valid(), "{}", ctx());
        assert_eq!(
            ladder.output().drive,
            before.ladder.output().drive,
            "{}",
            ctx()
        );
    }
}
