//! The seed 003 board (`teensy` profile) in the loop: the board application's `teensy` task
//! bodies driving four stepper joints, and a scripted host on the other end of a serial line
//! ([`crate::wire`]).
//!
//! ```text
//!  task (rate)                  body (crate mcu)                        simulated peripheral
//!  link_rx       (per byte)     TeensyLinkTask::on_byte                 the host → board line
//!  watchdog_tick (1 kHz)        serial::tick, drive_joints              step targets of the generator
//!  step_gen      (10 kHz)       StepGen::run                            STEP/DIR pins: the motors
//!  link_tx       (line free)    TxQueue::pop                            the board → host line
//! ```
//! The step is 100 µs, one `step_gen` run. Within a step: the bytes that arrived, `step_gen`
//! (priority 3, with the targets of the last tick), the tick every 10th step, the transmitter.
//! The arm is the motors themselves: a stepper that gets a pulse moves one step, so a joint's
//! angle is its step count over [`STEPS_PER_RAD`].
//!
//! The host sends its commands (`CAL` first: the re-arm), streams `MTRS` at `frame_hz` while a
//! move is in force, and decodes every echo with the protocol crate's [`RobustDecoder`]; each
//! echo must repeat its command with the expected `cmd_success`. A second decoder reads the
//! host → board line as the board does, so the run knows what the board took from which frame.

use std::collections::VecDeque;
use std::io::Write;
use std::time::Instant;

use mcu::serial::SerialTickInputs;
use mcu::teensy::{
    drive_joints, BoardAction, Joints, StepGen, StepPulse, TeensyLinkTask, JOINTS, STEPS_PER_RAD,
};
use mcu::Safety;
use protocol::teensy::{CmdMsg, CmdType, RobustDecoder};
use statemachine::{Config, Output, Position, RejectReason};

use crate::measure::{Trace, Watch};
use crate::rng::Rng;
use crate::runner::{Panel, RunOptions, RunResult, Series, Summary};
use crate::scenario::{Scenario, TeensyCmd};
use crate::serial::{Decode, HostRx, Link, Rearm, Schedule, Sent, SerialBoard};

/// Simulation step: one `step_gen` run at 10 kHz.
pub const STEP_S: f64 = 1.0 / mcu::teensy::STEP_HZ as f64;
/// Steps per 1 ms tick.
const STEPS_PER_TICK: u64 = (mcu::teensy::STEP_HZ / 1000) as u64;

type Msg = CmdMsg<JOINTS>;

/// The seed 003 board: task state as the firmware would hold it, and the motors.
#[derive(Clone, Debug)]
pub struct SimTeensyBoard {
    safety: Safety<JOINTS>,
    link: TeensyLinkTask,
    joints: Joints,
    stepgen: StepGen,
    targets: [i32; JOINTS],
    /// Last ladder output.
    pub out: Output<JOINTS>,
    /// The end-effector output.
    pub end_effector: bool,
}

impl Default for SimTeensyBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimTeensyBoard {
    /// Just out of reset, the joints at 0 (BRAKE latched until `CAL`).
    pub fn new() -> Self {
        let cfg = Config::TEENSY;
        let safety = Safety::new(cfg);
        let joints = Joints::new([Position::ZERO; JOINTS], &cfg);
        Self {
            out: safety.output(),
            safety,
            link: TeensyLinkTask::new(),
            targets: joints.step_targets(),
            stepgen: StepGen::new(joints.step_targets()),
            joints,
            end_effector: false,
        }
    }

    /// The link task (decoder counters, transmit queue).
    pub fn link(&self) -> &TeensyLinkTask {
        &self.link
    }

    /// The joints' profiles.
    pub fn joints(&self) -> &Joints {
        &self.joints
    }

    /// The motors' step counts.
    pub fn steps(&self) -> [i32; JOINTS] {
        self.stepgen.position()
    }

    /// `watchdog_tick`: the ladder's tick, the joints' profiles, the new step targets.
    pub fn tick(&mut self) {
        self.out = mcu::serial::tick(&mut self.safety, &SerialTickInputs::default());
        self.targets = drive_joints(&mut self.joints, &mut self.stepgen, &self.out.drive, false);
    }

    /// `step_gen`: one run of the step generator.
    pub fn step_gen(&mut self) -> [StepPulse; JOINTS] {
        self.stepgen.run()
    }
}

impl SerialBoard<JOINTS> for SimTeensyBoard {
    fn safety(&self) -> &Safety<JOINTS> {
        &self.safety
    }

    fn on_byte(&mut self, byte: u8) {
        if let Some((out, action)) = self.link.on_byte(&mut self.safety, byte) {
            self.out = out;
            match action {
                BoardAction::None => {}
                BoardAction::EndEffector(on) => self.end_effector = on,
                BoardAction::Accel(a) => self.joints.set_accel(a),
            }
        }
    }

    fn tx_pop(&mut self) -> Option<u8> {
        self.link.tx.pop()
    }

    fn frames(&self) -> u32 {
        self.link.stats().frames
    }
}

impl Decode for RobustDecoder<JOINTS> {
    type Msg = Msg;
    type Error = RejectReason;

    fn decode(&mut self, byte: u8) -> Option<Result<Msg, RejectReason>> {
        self.push(byte)
    }
}

/// The scripted seed 003 host's receiving side.
struct Host {
    rx: HostRx<RobustDecoder<JOINTS>>,
    /// Frames waiting for their echo, by index into the sent frames.
    pending: VecDeque<usize>,
    echoed_ok: u64,
    first_echo: Option<f64>,
    failures: Vec<String>,
    failure_count: u64,
}

impl Host {
    fn fail(&mut self, m: String) {
        self.failure_count += 1;
        if self.failures.len() < 8 {
            self.failures.push(m);
        }
    }

    fn receive(&mut self, t: f64, byte: u8, sent: &[Sent<Msg, bool>]) {
        let echo = match self.rx.byte(t, byte, "an echo") {
            Ok(Some(m)) => m,
            Ok(None) => return,
            Err(failure) => return self.fail(failure),
        };
        self.first_echo.get_or_insert(t);
        // The stream repeats identical frames: the echo is the first the board took whole.
        let same = |k: &usize| sent[*k].decoded && sent[*k].msg == echo.reply(false);
        let Some(i) = self.pending.iter().position(same) else {
            self.fail(format!(
                "{t:.4} s: an echo of nothing the host sent: {echo:?}"
            ));
            return;
        };
        let drained: Vec<usize> = self.pending.drain(..=i).collect();
        let Some((&k, missed)) = drained.split_last() else {
            return;
        };
        for &j in missed {
            let f = &sent[j];
            if f.decoded && !f.lost {
                self.fail(format!(
                    "{t:.4} s: no echo of {:?} {:?}",
                    f.msg.cmd_type, f.msg.mtr_angles
                ));
            }
        }
        let f = &sent[k];
        if (echo.cmd_success != 0) != f.expect {
            self.fail(format!(
                "{t:.4} s: {:?} {:?} echoed with cmd_success {}, expected {}",
                f.msg.cmd_type,
                f.msg.mtr_angles,
                echo.cmd_success,
                u8::from(f.expect)
            ));
        } else {
            self.echoed_ok += 1;
        }
    }
}

fn mtrs(deg: [i32; JOINTS], speed_deg_s: i32) -> Msg {
    Msg {
        cmd_type: CmdType::Mtrs,
        mtr_angles: deg,
        mtr_speed_deg_s: speed_deg_s,
        ..Msg::default()
    }
}

/// Runs a `teensy` scenario; writes the CSV trace to `trace` if given.
pub fn run(
    sc: &Scenario,
    opts: RunOptions,
    trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    let wall = Instant::now();
    let cfg = &sc.teensy;
    let params = *Config::TEENSY.params();
    let steps_per_rad: f64 = STEPS_PER_RAD.to_num();
    let mut rng = Rng::new(sc.seed);
    let mut board = SimTeensyBoard::new();
    // Each frame's expected reply: the `cmd_success` its echo must carry.
    let mut link: Link<Msg, bool, _> = Link::new(sc, RobustDecoder::<JOINTS>::new());
    let mut schedule = Schedule::new(cfg.frame_hz, &cfg.commands, |c| c.at_s);
    let mut host = Host {
        rx: HostRx::default(),
        pending: VecDeque::new(),
        echoed_ok: 0,
        first_echo: None,
        failures: Vec::new(),
        failure_count: 0,
    };
    // Moves to check at their end: (index, checked).
    let mut move_checked = vec![false; cfg.moves.len()];

    let mut s = Summary {
        joint_speed_excess_steps: Some(f64::NEG_INFINITY),
        joint_max_abs_rad: Some(0.0),
        ..Summary::new(sc)
    };
    let names = (1..=JOINTS)
        .map(|k| format!("joint {k} (deg)"))
        .chain((1..=JOINTS).map(|k| format!("joint {k} command (deg)")));
    let mut series = Series {
        lines: opts
            .keep_series
            .then(|| Panel::new("joint angles and commands (deg)", names)),
        thresholds: Some([params.hold_after, params.stop_after, params.brake_after]),
        ..Series::default()
    };
    let mut watch = Watch::new(board.out.mode);
    let mut rearm = Rearm::new(board.safety().ladder().counters());
    let mut comm_loss_braked = false;
    let mut steps_after_brake = 0u64;
    // The speed bound: the cap of the last accepted MTRS, and the bound in force, which falls
    // from a higher earlier cap at the ladder's rate (rad/s).
    let mut cap_cmd = 0.0f64;
    let mut cap_bound = 0.0f64;
    let ramp: f64 = params.accel_step.to_num();
    let mut at_last_tick = board.steps();
    let mut commanded: Option<[i32; JOINTS]> = None;

    let mut trace = Trace::new(sc, trace, "cmd_deg_1,cmd_deg_2,cmd_deg_3,cmd_deg_4,ref_deg_1,ref_deg_2,ref_deg_3,ref_deg_4,joint_deg_1,joint_deg_2,joint_deg_3,joint_deg_4,steps_1,steps_2,steps_3,steps_4,end_effector,frames_sent,corrupted_sent,corrupted_applied,rejected,echoes,echo_errors")?;

    for (n, t) in sc.steps(STEP_S) {
        let paused = sc.host_paused(t);

        // The host writes: commands due, then the MTRS stream of the move in force.
        let mut outgoing: Vec<(Msg, bool)> = Vec::new();
        schedule.commands_due(t, paused, |_, c| {
            let msg = match c.cmd {
                TeensyCmd::Cal => Msg {
                    cmd_type: CmdType::Cal,
                    ..Msg::default()
                },
                TeensyCmd::Mtrs => mtrs(c.deg, c.speed_deg_s),
                TeensyCmd::Relative => Msg {
                    is_relative: 1,
                    ..mtrs(c.deg, c.speed_deg_s)
                },
                TeensyCmd::EndeffOn => Msg {
                    cmd_type: CmdType::EndeffOn,
                    ..Msg::default()
                },
                TeensyCmd::EndeffOff => Msg {
                    cmd_type: CmdType::EndeffOff,
                    ..Msg::default()
                },
                TeensyCmd::Config => Msg {
                    cmd_type: CmdType::Config,
                    mtr_accel_deg_s_s: c.accel_deg_s2,
                    ..Msg::default()
                },
            };
            outgoing.push((msg, c.success));
        });
        schedule.frames_due(t, paused, |at| {
            if let Some(m) = cfg.move_at(at) {
                outgoing.push((mtrs(m.deg, m.speed_deg_s), m.success));
            }
        });
        for (msg, want) in outgoing {
            let mut buf = [0u8; Msg::ROBUST_LEN];
            let Some(len) = msg.encode_robust(&mut buf) else {
                continue;
            };
            let tag = link.write(sc, t, msg, &mut buf[..len], want, &mut rng);
            host.pending.push_back(tag);
        }

        // link_rx: every byte that arrived.
        while let Some((rep, m)) = link.link_rx(sc, t, &mut board, &mut s) {
            if let Some(m) = m {
                match m.cmd_type {
                    CmdType::Cal => rearm.deliver(),
                    CmdType::Mtrs if rep.valid => {
                        cap_cmd = f64::from(m.mtr_speed_deg_s).to_radians();
                        commanded = Some(m.mtr_angles);
                    }
                    _ => {}
                }
            }
        }

        // step_gen (priority 3: before the tick due in the same step).
        let pulses = board.step_gen();
        if comm_loss_braked {
            steps_after_brake += pulses.iter().filter(|p| **p != StepPulse::Idle).count() as u64;
        }

        // watchdog_tick.
        let ticked = n % STEPS_PER_TICK == 0 && n > 0;
        if ticked {
            board.tick();
            let c = board.safety().ladder().counters();
            rearm.tick(c, watch.mode, board.out.mode, &mut s);
            // The joints' motion over the tick that ended, against the cap in force during it.
            let now = board.steps();
            let bound = cap_bound * steps_per_rad / 1000.0;
            for k in 0..JOINTS {
                let moved = f64::from((now[k] - at_last_tick[k]).abs());
                let excess = moved - bound;
                if let Some(x) = s.joint_speed_excess_steps.as_mut() {
                    *x = x.max(excess);
                }
                let rad = f64::from(now[k].abs()) / steps_per_rad;
                if let Some(x) = s.joint_max_abs_rad.as_mut() {
                    *x = x.max(rad);
                }
            }
            at_last_tick = now;
            cap_bound = cap_cmd.max(cap_bound - ramp);
            // Moves the board accepted: every joint on its angle by the move's end.
            for (i, m) in cfg.moves.iter().enumerate() {
                if m.success && !move_checked[i] && t >= m.to_s - 1e-3 && m.to_s <= sc.duration_s {
                    move_checked[i] = true;
                    for k in 0..JOINTS {
                        let want =
                            f64::from(m.deg[k]) * f64::from(mcu::teensy::STEPS_PER_REV) / 360.0;
                        let err = (f64::from(now[k]) - want).abs();
                        s.joint_err_steps = Some(s.joint_err_steps.unwrap_or(0.0).max(err));
                    }
                }
            }
        }

        // link_tx, and the host's side.
        link.link_tx(sc, t, STEP_S, &mut board, &mut rng, |b, sent| {
            host.receive(t, b, sent)
        });

        // Measurements.
        let out = board.out;
        if link.watch_mode(&mut watch, &mut s, t, &out, board.safety().ticks()) {
            // The joints stop in this tick: the step targets are frozen.
            s.bridge_brake_after_last_frame_ms = s.brake_after_last_frame_ms;
            comm_loss_braked = true;
        }

        if ticked && trace.due(n / STEPS_PER_TICK) {
            let cmd = commanded.map_or([f64::NAN; JOINTS], |d| d.map(f64::from));
            let refs = board
                .joints()
                .positions()
                .map(|p| p.to_num::<f64>().to_degrees());
            let steps_now = board.steps();
            let deg = steps_now.map(|x| (f64::from(x) / steps_per_rad).to_degrees());
            if opts.keep_series {
                series.push_tick(t, out.mode, out.age, deg.into_iter().chain(cmd));
            }
            if let Some(w) = trace.row(t, out.mode, out.age, out.faults)? {
                write!(
                    w,
                    "{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},",
                    cmd[0],
                    cmd[1],
                    cmd[2],
                    cmd[3],
                    refs[0],
                    refs[1],
                    refs[2],
                    refs[3],
                    deg[0],
                    deg[1],
                    deg[2],
                    deg[3],
                    steps_now[0],
                    steps_now[1],
                    steps_now[2],
                    steps_now[3],
                    u8::from(board.end_effector),
                )?;
                link.trace_tail(w, &s, &board, host.rx.counts())?;
            }
        }
    }

    // Frames the board took at least 50 ms before the end must have been echoed by then.
    for k in std::mem::take(&mut host.pending) {
        let f = &link.sent[k];
        if f.decoded && !f.lost && f.t < sc.duration_s - 0.05 {
            host.fail(format!(
                "no echo of {:?} {:?} by the end",
                f.msg.cmd_type, f.msg.mtr_angles
            ));
        }
    }
    if host.failure_count > host.failures.len() as u64 {
        let more = host.failure_count - host.failures.len() as u64;
        host.failures.push(format!("… and {more} more"));
    }
    // A move that would end after the run is one the run interrupts: not checked.
    for (i, m) in cfg.moves.iter().enumerate() {
        if m.success && !move_checked[i] && m.to_s <= sc.duration_s {
            host.failures
                .push(format!("the move ending at {} s was not checked", m.to_s));
        }
    }

    link.tally(&mut s);
    s.replies = Some(host.rx.counts());
    if let Some(t0) = host.first_echo {
        s.host_reports.push((t0, "echo_ok".into(), host.echoed_ok));
    }
    s.reply_failures = host.failures;
    s.tx_dropped = u64::from(board.link().tx.dropped());
    s.steps_after_brake = comm_loss_braked.then_some(steps_after_brake);
    s.finish(sc, wall, board.safety().ladder().counters(), board.out.mode);
    Ok(RunResult { summary: s, series })
}
