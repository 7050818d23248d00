//! The seed 003 board application (`teensy` profile): an arm of [`JOINTS`] stepper joints moved to
//! angles, the robust COBS + CRC frame over a UART, every command echoed with `cmd_success`.
//!
//! ```text
//!  task (priority, rate)          body                          what it does
//!  link_rx       (2, per byte)    TeensyLinkTask::on_byte       byte → frame → ladder event → echo queued
//!  watchdog_tick (2, 1 kHz)       serial::tick, Joints::tick    ESTOP, supply → tick → trapezoid per joint → step targets
//!  step_gen      (3, 10 kHz)      StepGen::run                  at most one STEP pulse per joint toward its target
//! ```
//!
//! # What each command does (the seed's `CmdType`, on the safety core)
//!
//! | `cmd_type`     | ladder event / board action                                                         | `cmd_success` of the echo |
//! |----------------|-------------------------------------------------------------------------------------|---------------------------|
//! | `MTRS`         | a frame of position axes: every joint to its angle (deg → rad) under `mtr_speed_deg_s` as the speed cap | 1 if the ladder accepted it |
//! | `MTRS`, `is_relative` ≠ 0 | refused (`Rejected(Decode)`): a relative move repeated after a lost echo would move twice; the host sends absolute angles | 0 |
//! | `CAL`          | a frame of coasting joints with enable 0, then `Rearm(Primary)`: the explicit re-arm (the seed has no enable message); the arm leaves BRAKE at the tick after the first `MTRS` that follows within the profile's BRAKE threshold (as `MOTOR_ENABLE 1` of seed 001, `mcu::cdc`) | 1 unless the ladder refused the re-arm |
//! | `ENDEFF_ON/OFF`| the end-effector output (kept through BRAKE: dropping a held part is not safer)      | 1                         |
//! | `CONFIG`       | the joints' acceleration (`mtr_accel_deg_s_s`), within (0, the profile's limit]      | 1 if within, else 0 (nothing changed) |
//! | a refused frame| `Rejected(reason)` (counted; nothing else changes); no echo (the bytes are not a command) | — |
//!
//! # Joints
//!
//! Each joint follows a trapezoidal profile ([`control::profile::Trapezoid`], proven to stay within
//! the travel and under the cap) toward its target at the ladder's cap, which falls to 0 in HOLD
//! and STOP: the joint decelerates and holds. In BRAKE every joint stops at once where it stands
//! (no more step pulses; the drivers stay powered and hold). A coasting axis keeps its reference.
//! Step targets are the reference in steps ([`STEPS_PER_RAD`]); the step generator moves the
//! motor at most one step per 10 kHz run toward it.

use crate::safety::Safety;
use crate::serial::TxQueue;
use control::profile::{ProfileLimits, Trapezoid, Travel};
use protocol::teensy::{CmdMsg, CmdType, RobustDecoder};
use statemachine::{
    AxisCommand, AxisDrive, Command, Config, Drive, Event, Output, Position, RejectReason, Source,
    Speed,
};

/// Joints of the seed 003 arm on this board (`MAX_SUPPORTED_MTRS`).
pub const JOINTS: usize = 4;
/// Transmit queue: eight echoes.
pub const TX_CAP: usize = 8 * CmdMsg::<JOINTS>::ROBUST_LEN;
/// Steps per revolution: 200 full steps, 8 microsteps.
pub const STEPS_PER_REV: i32 = 1600;
/// Steps per radian, Q16.16 (1600 / 2π = 254.648).
pub const STEPS_PER_RAD: Speed = Speed::from_bits(16_688_605);
/// Step generator rate, Hz: at most this many steps per second per joint (≥ v_max · STEPS_PER_RAD).
pub const STEP_HZ: u32 = 10_000;

const _: () = assert!(
    // v_max 20 rad/s × 254.65 steps/rad = 5093 steps/s.
    Config::TEENSY.params().v_max.to_bits() as i64 * STEPS_PER_RAD.to_bits() as i64
        <= (STEP_HZ as i64) << 32,
    "the step generator must keep up with the fastest joint"
);

/// The link task's state: the stream decoder, the echoes waiting for the transmitter.
#[derive(Clone, Debug)]
pub struct TeensyLinkTask {
    dec: RobustDecoder<JOINTS>,
    /// Echoes waiting for the transmitter.
    pub tx: TxQueue<TX_CAP>,
}

impl Default for TeensyLinkTask {
    fn default() -> Self {
        Self::new()
    }
}

/// What a command asks of the board besides the ladder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardAction {
    /// Nothing.
    None,
    /// End effector on (`true`) or off.
    EndEffector(bool),
    /// New joint acceleration, rad/s per tick (already checked against the profile's limit).
    Accel(Speed),
}

impl TeensyLinkTask {
    /// Before the first byte.
    pub const fn new() -> Self {
        Self {
            dec: RobustDecoder::new(),
            tx: TxQueue::new(),
        }
    }

    /// The stream decoder's counters.
    pub const fn stats(&self) -> protocol::teensy::RobustStats {
        self.dec.stats()
    }

    /// One received byte (the body of `link_rx`): the ladder's output if a frame reached the
    /// ladder, and what the board must do. Not inlined, for the budget report.
    #[inline(never)]
    pub fn on_byte(
        &mut self,
        safety: &mut Safety<JOINTS>,
        byte: u8,
    ) -> Option<(Output<JOINTS>, BoardAction)> {
        let cmd = match self.dec.push(byte)? {
            Ok(c) => c,
            Err(reason) => return Some((safety.step(Event::Rejected(reason)), BoardAction::None)),
        };
        let before = *safety.ladder().counters();
        let (out, ok, action) = match cmd.cmd_type {
            CmdType::Mtrs if cmd.is_relative != 0 => (
                safety.step(Event::Rejected(RejectReason::Decode)),
                false,
                BoardAction::None,
            ),
            CmdType::Mtrs => {
                let out = match cmd.to_event() {
                    Some(e) => safety.step(e),
                    None => safety.output(),
                };
                let ok = safety.ladder().counters().valid_frames != before.valid_frames;
                (out, ok, BoardAction::None)
            }
            CmdType::Cal => {
                let coast = Command::uniform(AxisCommand::COAST, false, None);
                safety.step(Event::Frame(coast));
                let out = safety.step(Event::Rearm(Source::Primary));
                let ok = safety.ladder().counters().rearm_refused == before.rearm_refused;
                (out, ok, BoardAction::None)
            }
            CmdType::EndeffOn => (safety.output(), true, BoardAction::EndEffector(true)),
            CmdType::EndeffOff => (safety.output(), true, BoardAction::EndEffector(false)),
            CmdType::Config => match accel_step(cmd.mtr_accel_deg_s_s, safety.ladder().config()) {
                Some(a) => (safety.output(), true, BoardAction::Accel(a)),
                None => (safety.output(), false, BoardAction::None),
            },
        };
        let mut buf = [0u8; CmdMsg::<JOINTS>::ROBUST_LEN];
        if let Some(n) = cmd.reply(ok).encode_robust(&mut buf) {
            self.tx.push_frame(buf.get(..n).unwrap_or(&[]));
        }
        Some((out, action))
    }
}

/// A `CONFIG` acceleration (deg/s²) as the profile's step per tick, if it is within
/// (0, the profile's command acceleration]: `None` refuses it.
pub fn accel_step(deg_s2: i32, cfg: &Config) -> Option<Speed> {
    // deg/s² → rad/s per 1 ms tick: × π/180 / 1000.
    const PER_DEG: f32 = core::f32::consts::PI / 180.0 / 1000.0;
    let step = Speed::checked_from_num(deg_s2 as f32 * PER_DEG)?;
    (step > Speed::ZERO && step <= cfg.params().max_cmd_step).then_some(step)
}

/// The joints' profiles: the position reference of every joint, stepped once per tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Joints {
    prof: [Trapezoid; JOINTS],
    lim: ProfileLimits,
}

impl Joints {
    /// Joints at rest at `start` (rad) within `cfg`'s travel, accelerating at its command
    /// acceleration until a `CONFIG` changes it.
    pub fn new(start: [Position; JOINTS], cfg: &Config) -> Self {
        let p = cfg.params();
        let travel = Travel {
            lo: p.travel_lo,
            hi: p.travel_hi,
        };
        Self {
            prof: start.map(|s| Trapezoid::new(s, &travel)),
            lim: ProfileLimits {
                travel,
                accel_step: p.max_cmd_step,
            },
        }
    }

    /// Sets the acceleration (from [`accel_step`], which keeps it within the profile's).
    pub fn set_accel(&mut self, step: Speed) {
        if step > Speed::ZERO {
            self.lim.accel_step = step;
        }
    }

    /// The acceleration in force, rad/s per tick.
    pub const fn accel(&self) -> Speed {
        self.lim.accel_step
    }

    /// One tick of every joint under the ladder's drive (see the module documentation); returns
    /// the position references, rad.
    pub fn tick(&mut self, drive: &Drive<JOINTS>) -> [Position; JOINTS] {
        match drive {
            Drive::Brake => {
                for p in &mut self.prof {
                    *p = Trapezoid::new(p.position(), &self.lim.travel);
                }
            }
            Drive::Run(axes) => {
                for (p, a) in self.prof.iter_mut().zip(axes) {
                    let (target, cap) = match a {
                        AxisDrive::Position { target, cap } => (*target, *cap),
                        _ => (p.position(), Speed::ZERO),
                    };
                    p.step(target, cap, &self.lim);
                }
            }
        }
        self.positions()
    }

    /// The position references, rad.
    pub fn positions(&self) -> [Position; JOINTS] {
        self.prof.map(|p| p.position())
    }

    /// The velocity references, rad/s.
    pub fn velocities(&self) -> [Speed; JOINTS] {
        self.prof.map(|p| p.velocity())
    }

    /// The step targets of the references.
    pub fn step_targets(&self) -> [i32; JOINTS] {
        self.positions().map(steps_of)
    }

    /// Every joint at rest where its motor stands (`steps`): after a halt, the references restart
    /// from the motors, not from where the profile had already got to.
    pub fn hold_at(&mut self, steps: [i32; JOINTS]) {
        for (p, s) in self.prof.iter_mut().zip(steps) {
            *p = Trapezoid::new(rad_of(s), &self.lim.travel);
        }
    }
}

/// The tick's drive stage of the arm (the body the firmware's tick and the simulator run): the
/// joints' profiles one tick on under the ladder's drive, then the step generator either follows
/// them or, in BRAKE or with an ESTOP press not yet latched, halts where the motors stand, and the
/// profiles are put there too. Returns the step targets in force.
pub fn drive_joints(
    joints: &mut Joints,
    gen: &mut StepGen,
    drive: &Drive<JOINTS>,
    estop_pending: bool,
) -> [i32; JOINTS] {
    joints.tick(drive);
    if matches!(drive, Drive::Brake) || estop_pending {
        gen.halt();
        joints.hold_at(gen.position());
        gen.position()
    } else {
        let t = joints.step_targets();
        gen.set_target(t);
        t
    }
}

/// A step count as a position, rad.
pub fn rad_of(steps: i32) -> Position {
    Position::from_num(steps)
        .checked_div(STEPS_PER_RAD)
        .unwrap_or(Position::ZERO)
}

/// A position in steps, rounded to the nearest (|rad| ≤ π within the travel: no overflow).
pub fn steps_of(rad: Position) -> i32 {
    let s = rad.saturating_mul(STEPS_PER_RAD).round();
    s.to_num::<i32>()
}

/// What the step generator tells one joint's driver in one run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepPulse {
    /// No pulse.
    Idle,
    /// One step forward (DIR high).
    Forward,
    /// One step backward (DIR low).
    Backward,
}

/// `step_gen` (priority 3, [`STEP_HZ`]): the motors' step counts, each moved at most one step per
/// run toward its target (set by the tick from [`Joints::step_targets`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepGen {
    at: [i32; JOINTS],
    target: [i32; JOINTS],
}

impl StepGen {
    /// Motors standing at `at` steps, holding there.
    pub const fn new(at: [i32; JOINTS]) -> Self {
        Self { at, target: at }
    }

    /// The steps issued so far, per joint.
    pub const fn position(&self) -> [i32; JOINTS] {
        self.at
    }

    /// The targets the next runs move toward.
    pub fn set_target(&mut self, target: [i32; JOINTS]) {
        self.target = target;
    }

    /// Stops at once where the motors stand (ESTOP press, BRAKE): no further pulse.
    pub fn halt(&mut self) {
        self.target = self.at;
    }

    /// One run: a pulse per joint that is not at its target. Not inlined, for the budget report.
    #[inline(never)]
    pub fn run(&mut self) -> [StepPulse; JOINTS] {
        let mut out = [StepPulse::Idle; JOINTS];
        for ((o, at), t) in out.iter_mut().zip(self.at.iter_mut()).zip(&self.target) {
            if *t > *at {
                *at = at.saturating_add(1);
                *o = StepPulse::Forward;
            } else if *t < *at {
                *at = at.saturating_sub(1);
                *o = StepPulse::Backward;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;
