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
use statemachine::{Config, FaultFlags, Mode, Output, Position};

use crate::rng::Rng;
use crate::runner::{corrupt, mode_name, Panel, RunOptions, RunResult, Series, Summary};
use crate::scenario::{Fault, Scenario, TeensyCmd};
use crate::wire::Wire;

/// Simulation step: one `step_gen` run at 10 kHz.
pub const STEP_S: f64 = 1.0 / mcu::teensy::STEP_HZ as f64;
/// Steps per 1 ms tick.
const STEPS_PER_TICK: u64 = (mcu::teensy::STEP_HZ / 1000) as u64;

type Msg = CmdMsg<JOINTS>;

/// What one received byte did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ByteReport {
    /// The byte completed a frame that decoded.
    pub decoded: bool,
    /// The ladder accepted an `MTRS` frame.
    pub valid: bool,
}

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

    /// The safety core.
    pub fn safety(&self) -> &Safety<JOINTS> {
        &self.safety
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

    /// `link_rx`: one received byte.
    pub fn on_byte(&mut self, byte: u8) -> ByteReport {
        let frames = self.link.stats().frames;
        let valid = self.safety.ladder().counters().valid_frames;
        if let Some((out, action)) = self.link.on_byte(&mut self.safety, byte) {
            self.out = out;
            match action {
                BoardAction::None => {}
                BoardAction::EndEffector(on) => self.end_effector = on,
                BoardAction::Accel(a) => self.joints.set_accel(a),
            }
        }
        ByteReport {
            decoded: self.link.stats().frames != frames,
            valid: self.safety.ladder().counters().valid_frames != valid,
        }
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

    /// `link_tx`: the next byte for the transmitter.
    pub fn tx_pop(&mut self) -> Option<u8> {
        self.link.tx.pop()
    }
}

/// A frame the host wrote.
struct Sent {
    msg: Msg,
    /// When the host wrote it, s.
    t: f64,
    /// The `cmd_success` its echo must carry.
    want: bool,
    corrupted: bool,
    lost: bool,
    decoded: bool,
}

/// The scripted seed 003 host's receiving side.
struct Host {
    dec: RobustDecoder<JOINTS>,
    /// Frames waiting for their echo, by index into the sent frames.
    pending: VecDeque<usize>,
    decoded: u64,
    broken: u64,
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

    fn receive(&mut self, t: f64, byte: u8, sent: &[Sent]) {
        let Some(r) = self.dec.push(byte) else {
            return;
        };
        let echo = match r {
            Ok(m) => m,
            Err(e) => {
                self.broken += 1;
                self.fail(format!("{t:.4} s: host could not decode an echo: {e:?}"));
                return;
            }
        };
        self.decoded += 1;
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
        if (echo.cmd_success != 0) != f.want {
            self.fail(format!(
                "{t:.4} s: {:?} {:?} echoed with cmd_success {}, expected {}",
                f.msg.cmd_type,
                f.msg.mtr_angles,
                echo.cmd_success,
                u8::from(f.want)
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

fn in_window(t: f64, at: f64, dur: f64) -> bool {
    t >= at && t < at + dur
}

/// Runs a `teensy` scenario; writes the CSV trace to `trace` if given.
pub fn run(
    sc: &Scenario,
    opts: RunOptions,
    mut trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    let wall = Instant::now();
    let cfg = &sc.teensy;
    let params = *Config::TEENSY.params();
    let steps_per_rad: f64 = STEPS_PER_RAD.to_num();
    let mut rng = Rng::new(sc.seed);
    let mut board = SimTeensyBoard::new();
    let mut down = Wire::new(
        sc.serial.baud,
        sc.serial.latency_ms,
        sc.serial.bit_error_rate,
    );
    let mut up = Wire::new(sc.serial.baud, sc.serial.latency_ms, 0.0);
    let mut monitor = RobustDecoder::<JOINTS>::new();
    let mut sent: Vec<Sent> = Vec::new();
    let mut commands = cfg.commands.clone();
    commands.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
    let mut host = Host {
        dec: RobustDecoder::new(),
        pending: VecDeque::new(),
        decoded: 0,
        broken: 0,
        echoed_ok: 0,
        first_echo: None,
        failures: Vec::new(),
        failure_count: 0,
    };
    let period = 1.0 / cfg.frame_hz;
    let mut next_frame = 0.0;
    let mut next_command = 0usize;
    let onset = sc.fault_onset();
    // Moves to check at their end: (index, checked).
    let mut move_checked = vec![false; cfg.moves.len()];

    let mut s = Summary {
        name: sc.name.clone(),
        profile: sc.profile.name().into(),
        onset_s: onset,
        joint_speed_excess_steps: Some(f64::NEG_INFINITY),
        joint_max_abs_rad: Some(0.0),
        ..Summary::default()
    };
    let mut series = Series {
        thresholds: Some([params.hold_after, params.stop_after, params.brake_after]),
        ..Series::default()
    };
    let mut lines: Vec<(String, Vec<f64>)> = (1..=JOINTS)
        .map(|k| (format!("joint {k} (deg)"), Vec::new()))
        .chain((1..=JOINTS).map(|k| (format!("joint {k} command (deg)"), Vec::new())))
        .collect();
    let mut last_valid: Option<(f64, u32)> = None;
    let mut prev_mode = board.out.mode;
    let mut brake_entries = board.safety().ladder().counters().brake_entries;
    let mut rearm_delivered = false;
    let mut comm_loss_braked = false;
    let mut steps_after_brake = 0u64;
    // The speed bound: the cap of the last accepted MTRS, and the bound in force, which falls
    // from a higher earlier cap at the ladder's rate (rad/s).
    let mut cap_cmd = 0.0f64;
    let mut cap_bound = 0.0f64;
    let ramp: f64 = params.accel_step.to_num();
    let mut at_last_tick = board.steps();
    let mut commanded: Option<[i32; JOINTS]> = None;

    if let Some(w) = trace.as_deref_mut() {
        writeln!(w, "t_s,mode,age,faults,cmd_deg_1,cmd_deg_2,cmd_deg_3,cmd_deg_4,ref_deg_1,ref_deg_2,ref_deg_3,ref_deg_4,joint_deg_1,joint_deg_2,joint_deg_3,joint_deg_4,steps_1,steps_2,steps_3,steps_4,end_effector,frames_sent,corrupted_sent,corrupted_applied,rejected,echoes,echo_errors")?;
    }

    let steps = (sc.duration_s / STEP_S).ceil() as u64;
    for n in 0..steps {
        let t = n as f64 * STEP_S;
        let paused = sc.faults.iter().any(|f| match *f {
            Fault::GcPause { at_s, duration_s } => in_window(t, at_s, duration_s),
            _ => false,
        });
        let cut = |x: f64| {
            sc.faults.iter().any(|f| match *f {
                Fault::LinkCut { at_s, duration_s } => in_window(x, at_s, duration_s),
                _ => false,
            })
        };

        // The host writes: commands due, then the MTRS stream of the move in force.
        let mut outgoing: Vec<(Msg, bool)> = Vec::new();
        while !paused && next_command < commands.len() && commands[next_command].at_s <= t {
            let c = commands[next_command];
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
            next_command += 1;
        }
        while next_frame <= t {
            if !paused {
                if let Some(m) = cfg.move_at(next_frame) {
                    outgoing.push((mtrs(m.deg, m.speed_deg_s), m.success));
                }
            }
            next_frame += period;
        }
        for (msg, want) in outgoing {
            let mut buf = [0u8; Msg::ROBUST_LEN];
            let Some(len) = msg.encode_robust(&mut buf) else {
                continue;
            };
            let bytes = &mut buf[..len];
            let mut corrupted = false;
            for f in &sc.faults {
                if let Fault::Corruption {
                    rate, from_s, to_s, ..
                } = *f
                {
                    if t >= from_s && t < to_s && rng.chance(rate) {
                        corrupted |= corrupt(bytes, &mut rng);
                    }
                }
            }
            let tag = sent.len();
            corrupted |= down.write(t, bytes, tag, &mut rng) > 0;
            host.pending.push_back(tag);
            sent.push(Sent {
                msg,
                t,
                want,
                corrupted,
                lost: false,
                decoded: false,
            });
        }

        // link_rx: every byte that arrived.
        while let Some(b) = down.arrived(t) {
            if cut(b.at) {
                sent[b.tag].lost = true;
                continue;
            }
            let rep = board.on_byte(b.byte);
            if let Some(Ok(m)) = monitor.push(b.byte) {
                debug_assert!(rep.decoded);
                if m != sent[b.tag].msg {
                    s.corrupted_applied += 1;
                } else {
                    sent[b.tag].decoded = true;
                }
                match m.cmd_type {
                    CmdType::Cal => rearm_delivered = true,
                    CmdType::Mtrs if rep.valid => {
                        cap_cmd = f64::from(m.mtr_speed_deg_s).to_radians();
                        commanded = Some(m.mtr_angles);
                    }
                    _ => {}
                }
            }
            if rep.valid {
                last_valid = Some((t, board.safety().ticks()));
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
            let e = board.safety().ladder().counters().brake_entries;
            if e != brake_entries {
                brake_entries = e;
                rearm_delivered = false;
            }
            if prev_mode == Mode::Brake && board.out.mode != Mode::Brake {
                if !rearm_delivered {
                    s.rearm_violations += 1;
                }
                rearm_delivered = false;
            }
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
        while up.idle_before(t + STEP_S) {
            match board.tx_pop() {
                Some(b) => {
                    up.write(t, &[b], 0, &mut rng);
                }
                None => break,
            }
        }
        while let Some(b) = up.arrived(t) {
            if !cut(b.at) {
                host.receive(t, b.byte, &sent);
            }
        }

        // Measurements.
        let out = board.out;
        let since = |x: f64| onset.filter(|&o| x >= o).map(|o| (x - o) * 1e3);
        if out.mode != prev_mode {
            let after = since(t);
            match out.mode {
                Mode::Hold if s.hold_ms.is_none() => s.hold_ms = after,
                Mode::Stop if s.stop_ms.is_none() => s.stop_ms = after,
                Mode::Brake => {
                    if s.brake_ms.is_none() {
                        s.brake_ms = after;
                    }
                    if s.brake_after_last_frame_ms.is_none()
                        && out.faults.contains(FaultFlags::COMM_LOST)
                        && (onset.is_none() || after.is_some())
                    {
                        if let Some((lt, lticks)) = last_valid {
                            let ms = (t - lt) * 1e3;
                            s.brake_after_last_frame_ms = Some(ms);
                            // The joints stop in this tick: the step targets are frozen.
                            s.bridge_brake_after_last_frame_ms = Some(ms);
                            s.brake_after_last_frame_ticks =
                                Some(board.safety().ticks().wrapping_sub(lticks));
                            comm_loss_braked = true;
                        }
                    }
                }
                _ => {}
            }
            prev_mode = out.mode;
        }

        if ticked {
            let tick_index = n / STEPS_PER_TICK;
            if tick_index % u64::from(sc.trace_every_ms) == 0 {
                let cmd = commanded.map_or([f64::NAN; JOINTS], |d| d.map(f64::from));
                let refs = board
                    .joints()
                    .positions()
                    .map(|p| p.to_num::<f64>().to_degrees());
                let steps_now = board.steps();
                let deg = steps_now.map(|x| (f64::from(x) / steps_per_rad).to_degrees());
                if opts.keep_series {
                    series.t.push(t);
                    series.mode.push(out.mode as u8);
                    series.age.push(out.age);
                    for k in 0..JOINTS {
                        lines[k].1.push(deg[k]);
                        lines[JOINTS + k].1.push(cmd[k]);
                    }
                }
                if let Some(w) = trace.as_deref_mut() {
                    writeln!(
                        w,
                        "{:.4},{},{},{:#06x},{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{},{},{},{}",
                        t,
                        mode_name(out.mode),
                        out.age,
                        out.faults.0,
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
                        sent.len(),
                        sent.iter().filter(|f| f.corrupted).count(),
                        s.corrupted_applied,
                        board.safety().ladder().counters().rejected_total(),
                        host.decoded,
                        host.broken,
                    )?;
                }
            }
        }
    }

    // Frames the board took at least 50 ms before the end must have been echoed by then.
    for k in std::mem::take(&mut host.pending) {
        let f = &sent[k];
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

    let c = board.safety().ladder().counters();
    s.frames_sent = sent.len() as u64;
    s.corrupted_sent = sent.iter().filter(|f| f.corrupted).count() as u64;
    s.corrupted_rejected = sent
        .iter()
        .filter(|f| f.corrupted && !f.decoded && !f.lost)
        .count() as u64;
    s.rejected_total = u64::from(c.rejected_total());
    s.brake_entries = u64::from(c.brake_entries);
    s.rearms = u64::from(c.rearms);
    s.final_mode = mode_name(board.out.mode).to_string();
    s.replies = Some([host.decoded, host.broken]);
    if let Some(t0) = host.first_echo {
        s.host_reports.push((t0, "echo_ok".into(), host.echoed_ok));
    }
    s.reply_failures = host.failures;
    s.tx_dropped = u64::from(board.link().tx.dropped());
    s.steps_after_brake = comm_loss_braked.then_some(steps_after_brake);
    s.sim_s = sc.duration_s;
    s.wall_s = wall.elapsed().as_secs_f64();
    if opts.keep_series {
        series.lines = Some(Panel {
            caption: "joint angles and commands (deg)".into(),
            signals: lines,
        });
    }
    Ok(RunResult { summary: s, series })
}
