//! A reference model of the ladder written from the rules of `proofs/SAFETY.md` (§1 the rungs,
//! §3 SR-1 … SR-15, §4 INV-0 … INV-19), not from `Ladder`'s code. It tracks what the rules make
//! observable: the rung, whether BRAKE is latched and why, the age and the comm-loss threshold in
//! force, the last valid command, the re-arm that is pending, the ESTOP holders and the source whose
//! release ended an ESTOP, and the counters SR-14 and SR-8 name (refused ESTOP releases, refused
//! re-arms, re-arms that released BRAKE). The applied values are not recomputed:
//! the model checks them against the envelope the rules allow (limits, ramps, modes).
//!
//! Frame validation is `statemachine::validate`, whose contract INV-5 proves on its own; the model
//! only decides what the ladder does with its answer. Where the document leaves a choice open, the
//! model states the reading it takes next to the code, citing the rule.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic,
    dead_code,
    missing_docs
)]

use statemachine::{
    validate, AxisDrive, AxisMode, Condition, Config, Estop, Event, FaultFlags, Ladder, Mode,
    Setpoint, Source, Speed,
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
    /// Ticks so far, to date strikes.
    pub ticks: u64,
    /// The tick count at each strike of the last window (refused frames, HOLD entries; §1 REDUCED).
    pub strikes: VecDeque<u64>,
    /// Strikes since the previous tick.
    pub strikes_since_tick: u32,
    /// The tick count of the last event that degrades the link (strike, degrading condition,
    /// re-arm, link loss reaching STOP).
    pub last_dirty: u64,
}

/// The ladder's state before an event, for the checks that compare before and after.
pub struct Before<const N: usize> {
    pub mode: Mode,
    pub applied: [Speed; N],
    pub axis_modes: [AxisMode; N],
    pub degraded: bool,
    pub ladder: Ladder<N>,
}

impl<const N: usize> Model<N> {
    /// Power-on (SR-8: "Power-on starts in BRAKE"). SAFETY.md does not say what the age is before
    /// the first frame; the model starts from the ladder's (it only has to be ≥ 0), and the
    /// threshold in force is the profile's `brake_after` (SR-1: no frame has lowered it).
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
            last_dirty: 0,
        }
    }

    /// A latching cause is active (SR-8: "no latching cause active").
    fn cause_active(&self) -> bool {
        self.estop_owners != 0 || self.shutdown || self.conditions.0 & latching_conditions().0 != 0
    }

    fn degrading_active(&self) -> bool {
        self.conditions.intersects(FaultFlags::THERMAL_WARNING)
            || self.conditions.intersects(FaultFlags::CLOCK_SYNC_LOST)
    }

    /// Latches BRAKE for `cause` (SR-6, SR-9, SR-10, SR-1). Reading of SR-8 ("the primary link's
    /// enable 0 → 1 edge observed after the latch", H-8): every latch forgets the held command and
    /// any pending re-arm, and takes the enable as 1, so only an enable 0 frame and then an enable 1
    /// frame after this latch make an edge.
    fn latch(&mut self, cause: FaultFlags) {
        self.latched = true;
        self.mode = Mode::Brake;
        self.causes = self.causes.union(cause);
        self.last = None;
        self.prev_enable = true;
        self.rearm_pending = false;
    }

    fn strike(&mut self) {
        self.strikes.push_back(self.ticks);
        self.strikes_since_tick += 1;
        self.last_dirty = self.ticks;
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
            // SR-14: refused re-arms are counted. Reading (SR-8 is silent): a refused request also
            // withdraws a pending one, the conservative choice (H-8, H-13): the last word of the
            // sources on re-arming is a refusal, so BRAKE stays until a request that counts.
            self.rearm_refused += 1;
            self.rearm_pending = false;
        }
    }

    /// Feeds one event. `degraded` is the ladder's LINK_DEGRADED flag before and after it: the
    /// model does not fix how the strike window is laid out (§1 says only "`strike_limit` strikes in
    /// a window", "back to NORMAL after a clean window"), so it takes the ladder's flag for the
    /// REDUCED / NORMAL choice (`degraded` is the flag before and after the event) and checks the
    /// flag against the rules in [`check`].
    pub fn step(&mut self, event: &Event<N>, degraded: (bool, bool)) {
        match *event {
            Event::Tick => self.tick(degraded),
            Event::Frame(cmd) => {
                // SR-4: what `validate` accepts, against the last valid command (none after a latch).
                // §8 "Acceleration check after lost frames": the allowance scales with the ticks
                // since the last valid frame. Reading: `max_cmd_step` per tick, and one tick's worth
                // for a second frame within the same tick.
                let ticks = i32::from(self.age.max(1));
                let allowance = self.cfg.params().max_cmd_step.saturating_mul_int(ticks);
                match validate(&cmd, self.last.as_ref(), allowance, &self.cfg) {
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
                }
            }
            Event::Rejected(_) => self.strike(),
            Event::Condition { condition, active } => {
                let flag = condition.flag();
                if active {
                    self.conditions = self.conditions.union(flag);
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
    /// test, then the rung (§1 table, SR-7).
    fn tick(&mut self, (degraded_before, degraded_after): (bool, bool)) {
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
            // §1: a re-arm enters REDUCED.
            self.last_dirty = self.ticks;
        }
        if self.age >= self.threshold {
            // SR-1: comm loss "from every state". Reading: it is a latch cause of its own also when
            // BRAKE is already latched (the feedback names it; §1 lists it among BRAKE's entries),
            // and like every latch it forgets a pending re-arm.
            self.latch(FaultFlags::COMM_LOST);
        }
        let before = self.mode;
        if !self.latched {
            self.mode = if self.age >= p.stop_after || !enabled {
                Mode::Stop
            } else if self.age >= p.hold_after {
                Mode::Hold
            } else if degraded_before || degraded_after {
                // Reading of §1 ("back to NORMAL after a clean window"): the flag may clear at
                // the tick that completes the window while that tick's rung is still REDUCED;
                // NORMAL needs the flag clear before and after the tick.
                Mode::Reduced
            } else {
                Mode::Normal
            };
        }
        // §1: an entry into HOLD is a strike; a link loss that reached STOP degrades.
        if self.mode == Mode::Hold && before != Mode::Hold {
            self.strike();
        }
        if self.mode == Mode::Stop && self.age >= p.stop_after {
            self.last_dirty = self.ticks;
        }
        if self.degrading_active() {
            self.last_dirty = self.ticks;
        }
        self.fresh = false;
        self.strikes_since_tick = 0;
        while self
            .strikes
            .front()
            .is_some_and(|&t| t + u64::from(p.window) < self.ticks)
        {
            self.strikes.pop_front();
        }
    }

    /// The flags the feedback frame must carry, except LINK_DEGRADED (checked apart).
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
        f
    }
}

fn latching_conditions() -> FaultFlags {
    FaultFlags::OVERCURRENT
        .union(FaultFlags::OVERTEMPERATURE)
        .union(FaultFlags::ENCODER)
        .union(FaultFlags::UNDERVOLTAGE)
}

fn abs(x: Speed) -> i64 {
    i64::from(x.to_bits()).abs()
}

/// Feeds `event` to both, then checks that they agree on everything observable, and that the
/// ladder's applied values stay in the envelope of SR-5, SR-15, INV-3, INV-8, INV-16, INV-17, INV-19.
pub fn step_both<const N: usize>(ladder: &mut Ladder<N>, model: &mut Model<N>, event: Event<N>) {
    let before = Before {
        mode: ladder.mode(),
        applied: ladder.applied(),
        axis_modes: ladder.axis_modes(),
        degraded: ladder.faults().contains(FaultFlags::LINK_DEGRADED),
        ladder: *ladder,
    };
    let model_before = model.clone();
    let out = ladder.step(event);
    let degraded = out.faults.contains(FaultFlags::LINK_DEGRADED);
    model.step(&event, (before.degraded, degraded));
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
    let is_tick = matches!(event, Event::Tick);

    // The rung, BRAKE and its drive (§1, SR-6, SR-8, SR-9, SR-10, INV-7).
    assert_eq!(ladder.mode(), model.mode, "rung {}", ctx());
    assert_eq!(out.mode, model.mode, "output rung {}", ctx());
    assert_eq!(ladder.brake_latched(), model.latched, "latch {}", ctx());
    assert_eq!(
        matches!(out.drive, statemachine::Drive::Brake),
        model.mode == Mode::Brake,
        "drive {}",
        ctx()
    );
    // Why it latched, and what is active (the feedback flags).
    assert_eq!(
        out.faults.without(FaultFlags::LINK_DEGRADED),
        model.faults(),
        "faults {}",
        ctx()
    );
    // SR-1: age and threshold.
    assert_eq!(ladder.age(), model.age, "age {}", ctx());
    assert_eq!(out.age, model.age, "output age {}", ctx());
    assert_eq!(ladder.brake_after(), model.threshold, "threshold {}", ctx());
    assert!(model.threshold >= 1 && model.threshold <= p.brake_after);
    // SR-8: the command held.
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

    // LINK_DEGRADED against §1's REDUCED rules (the flag is meaningful outside BRAKE).
    if is_tick && !model.latched {
        if model.degrading_active()
            || mb.latched
            || model.strikes.len() >= usize::from(p.strike_limit)
                && mb.strikes_since_tick >= u32::from(p.strike_limit)
        {
            assert!(
                degraded_of(out),
                "REDUCED cause without LINK_DEGRADED {}",
                ctx()
            );
        }
        if before.degraded && !degraded_of(out) && !mb.latched {
            // Back to NORMAL only after a clean window.
            assert!(
                !model.degrading_active()
                    && model.ticks - model.last_dirty >= u64::from(p.window).saturating_sub(1),
                "LINK_DEGRADED cleared before a clean window {}",
                ctx()
            );
        }
    }
    if !is_tick {
        // Reading of §1: the rung is chosen at ticks; only a latch changes it between ticks.
        if model.mode != Mode::Brake {
            assert_eq!(ladder.mode(), before.mode, "{}", ctx());
        }
    }

    // The applied values (SR-5, SR-15, INV-3, INV-8, INV-16, INV-17, INV-19).
    let applied = ladder.applied();
    let modes = ladder.axis_modes();
    for i in 0..N {
        let a = abs(applied[i]);
        let was = abs(before.applied[i]);
        if model.mode == Mode::Brake {
            assert_eq!(a, 0, "applied in BRAKE {}", ctx());
            continue;
        }
        if !is_tick {
            assert_eq!(
                applied[i],
                before.applied[i],
                "moved between ticks {}",
                ctx()
            );
            assert_eq!(
                modes[i],
                before.axis_modes[i],
                "mode changed between ticks {}",
                ctx()
            );
            continue;
        }
        let (max, reduced, step) = match modes[i] {
            AxisMode::Coast | AxisMode::Short => (0, 0, 0),
            AxisMode::Duty => (abs(p.duty_max), abs(p.duty_reduced), abs(p.duty_step)),
            AxisMode::Velocity | AxisMode::Position => (
                abs(p.v_max),
                abs(p.reduced_limit),
                abs(model.cfg.max_tick_step()),
            ),
        };
        assert!(a <= max, "axis {i} beyond its mode's limit {}", ctx());
        if modes[i] != before.axis_modes[i] {
            // INV-19: only from rest, or into a passive mode.
            assert!(
                modes[i].is_passive()
                    || before.applied[i] == Speed::ZERO
                    || before.mode == Mode::Brake,
                "axis {i} changed mode while moving {}",
                ctx()
            );
            assert!(a <= step, "axis {i} jumped on a mode change {}", ctx());
            continue;
        }
        if before.mode != Mode::Brake {
            assert!(
                abs(applied[i] - before.applied[i]) <= step,
                "axis {i} stepped too far {}",
                ctx()
            );
        } else {
            assert!(a <= step, "axis {i} jumped out of BRAKE {}", ctx());
        }
        match model.mode {
            Mode::Reduced => assert!(
                a <= reduced || a < was || applied[i] == before.applied[i],
                "axis {i} above REDUCED's limit and not falling {}",
                ctx()
            ),
            Mode::Hold | Mode::Stop => {
                assert!(
                    a <= was || before.mode == Mode::Brake,
                    "axis {i} grew in {:?} {}",
                    model.mode,
                    ctx()
                );
                assert!(
                    applied[i].to_bits().signum() * before.applied[i].to_bits().signum() >= 0,
                    "axis {i} changed sign in {:?} {}",
                    model.mode,
                    ctx()
                );
            }
            _ => {}
        }
    }
    // INV-15, INV-17: outside BRAKE each axis is driven in its own mode with its applied value;
    // a position target lies within the travel and its cap is ≥ 0.
    if let statemachine::Drive::Run(axes) = out.drive {
        for ((d, mode), value) in axes.iter().zip(modes.iter()).zip(applied.iter()) {
            match (d, mode) {
                (AxisDrive::Coast, AxisMode::Coast) | (AxisDrive::Short, AxisMode::Short) => {}
                (AxisDrive::Duty(x), AxisMode::Duty)
                | (AxisDrive::Velocity(x), AxisMode::Velocity) => {
                    assert_eq!(x, value, "drive and applied value differ {}", ctx());
                }
                (AxisDrive::Position { target, cap }, AxisMode::Position) => {
                    assert_eq!(
                        cap,
                        value,
                        "position cap and applied value differ {}",
                        ctx()
                    );
                    assert!(*cap >= Speed::ZERO, "negative cap {}", ctx());
                    assert!(
                        p.travel_lo <= *target && *target <= p.travel_hi,
                        "position target outside the travel {}",
                        ctx()
                    );
                }
                _ => panic!("axis driven in another mode than its own {}", ctx()),
            }
        }
    }
    // INV-17: after a tick outside BRAKE, an axis whose last valid command is passive is passive.
    if is_tick && model.mode != Mode::Brake {
        if let Some(last) = model.last {
            for (mode, asked) in modes.iter().zip(last.axes.iter()) {
                if asked.mode.is_passive() {
                    assert_eq!(*mode, asked.mode, "passive request driven {}", ctx());
                }
            }
        }
    }
}

fn degraded_of<const N: usize>(out: &statemachine::Output<N>) -> bool {
    out.faults.contains(FaultFlags::LINK_DEGRADED)
}
