//! The seed 001 board (`cdc` profile) in the loop: the board application's `cdc` task bodies on a
//! simulated STM32F407 with two TB6612 drivers, a four-wheel robot ([`crate::skid`]), and a
//! scripted host on the other end of a serial line ([`crate::wire`]).
//!
//! ```text
//!  task (rate)                  body (crate mcu)                        simulated peripheral
//!  link_rx       (per byte)     CdcLinkTask::on_byte, outputs_after_frame  the host → board line
//!  watchdog_tick (1 kHz)        serial::tick, cdc::motor_outputs        TIM8 CCR1..4, IN1/IN2 pins
//!                               CdcLinkTask::periodic                   STATUS every 100 ticks
//!  imu_read      (100 Hz)       cdc::imu_from_raw, send_imu             the MPU6050's registers
//!  link_tx       (line free)    TxQueue::pop                            the board → host line
//! ```
//! The step is 100 µs. Within a step: the bytes that arrived, then the tick (every 10th step),
//! then the transmitter, then the plant. `link_rx` writes the motor outputs itself when the frame
//! braked the ladder (an `ESTOP`: "电机立刻 0", the motors at once); any other frame leaves them
//! to the next tick, as the board application says (a frame never moves the drive).
//!
//! The host streams `SET_MOTOR_PWM` at `frame_hz` with the scenario's `timeout_ms`, sends its
//! low-rate messages at their times, and decodes everything the board sends with the protocol
//! crate's [`StreamDecoder`]. A second decoder reads the host → board line as the board does (a
//! logic analyser on the wire), so the run knows what message the board took from which frame.

use std::collections::VecDeque;
use std::io::Write;
use std::time::Instant;

use mcu::cdc::{
    imu_from_raw, motor_outputs, outputs_after_frame, BoardStatus, CdcLinkTask, MotorOutput,
    IMU_SCALE, MOTORS,
};
use mcu::serial::SerialTickInputs;
use mcu::Safety;
use protocol::cdc::{self, Message, MsgId, SetMotorPwm, StatusFlags, StreamDecoder};
use statemachine::{Config, Estop, FaultFlags, Mode, Output};

use crate::rng::Rng;
use crate::runner::{corrupt, mode_name, Panel, RunOptions, RunResult, Series, Summary};
use crate::scenario::{CdcMessage, Fault, Scenario};
use crate::skid::{MotorDrive, Skid, G, SMALL_4WD};
use crate::wire::Wire;

/// Simulation step: 100 µs.
pub const STEP_S: f64 = 100e-6;
/// Steps per 1 ms tick.
const STEPS_PER_TICK: u64 = 10;
/// Ticks between two MPU6050 reads (100 Hz).
const IMU_PERIOD_TICKS: u32 = 10;
/// Battery voltage the board reports, mV (the plant's supply).
const VBAT_MV: u16 = 12_000;

/// TIM8's auto-reload: the same 20 kHz centre-aligned PWM from the 168 MHz timer clock as the
/// seed 000 board's timers.
pub fn pwm_arr() -> u16 {
    mcu::tuning::AMR.pwm_arr().unwrap_or(1)
}

/// What one received byte did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ByteReport {
    /// The byte completed a frame that decoded.
    pub decoded: bool,
    /// The ladder accepted a command frame (`SET_MOTOR_PWM`, `MOTOR_ENABLE 0`).
    pub valid: bool,
}

/// The seed 001 board: task state as the firmware would hold it, and its outputs.
#[derive(Clone, Debug)]
pub struct SimCdcBoard {
    safety: Safety<MOTORS>,
    link: CdcLinkTask,
    arr: u16,
    /// Last ladder output.
    pub out: Output<MOTORS>,
    /// The driver inputs: CCR and IN1/IN2 per motor.
    pub motors: [MotorOutput; MOTORS],
    /// IMU frames whose values saturated.
    pub imu_saturated: u64,
}

impl Default for SimCdcBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimCdcBoard {
    /// Just out of reset: BRAKE latched, every motor shorted.
    pub fn new() -> Self {
        let safety = Safety::new(Config::CDC);
        let arr = pwm_arr();
        let out = safety.output();
        Self {
            motors: motor_outputs(&out.drive, arr),
            out,
            safety,
            link: CdcLinkTask::new(),
            arr,
            imu_saturated: 0,
        }
    }

    /// The safety core.
    pub fn safety(&self) -> &Safety<MOTORS> {
        &self.safety
    }

    /// The link task (decoder counters, transmit queue).
    pub fn link(&self) -> &CdcLinkTask {
        &self.link
    }

    /// The timer's auto-reload.
    pub fn arr(&self) -> u16 {
        self.arr
    }

    /// True if every motor is shorted.
    pub fn all_shorted(&self) -> bool {
        self.motors.iter().all(|m| m.in1 && m.in2)
    }

    fn board_status(&self) -> BoardStatus {
        BoardStatus {
            t_ms: self.safety.ticks(),
            vbat_mv: VBAT_MV,
            imu_ok: true,
        }
    }

    /// `link_rx`: one received byte.
    pub fn on_byte(&mut self, byte: u8) -> ByteReport {
        let frames = self.link.stats().frames;
        let valid = self.safety.ladder().counters().valid_frames;
        let st = self.board_status();
        if let Some(out) = self.link.on_byte(&mut self.safety, byte, &st) {
            self.out = out;
            if let Some(m) = outputs_after_frame(&out, self.arr) {
                self.motors = m;
            }
        }
        ByteReport {
            decoded: self.link.stats().frames != frames,
            valid: self.safety.ladder().counters().valid_frames != valid,
        }
    }

    /// `watchdog_tick`, and `imu_read` every tenth tick with the MPU6050's registers from `imu`
    /// (accelerometer, temperature, gyroscope). Returns the IMU frame's `t_ms` if one was queued.
    pub fn tick(&mut self, imu: impl FnOnce() -> ([i16; 3], i16, [i16; 3])) -> Option<u32> {
        self.out = mcu::serial::tick(&mut self.safety, &SerialTickInputs::default());
        self.motors = motor_outputs(&self.out.drive, self.arr);
        let st = self.board_status();
        self.link.periodic(&self.safety, &st);
        if self.safety.ticks() % IMU_PERIOD_TICKS != 0 {
            return None;
        }
        let (accel, temp, gyro) = imu();
        let (frame, saturated) = imu_from_raw(st.t_ms, accel, temp, gyro, &IMU_SCALE);
        if saturated {
            self.imu_saturated += 1;
        }
        self.link.send_imu(&frame);
        Some(st.t_ms)
    }

    /// `link_tx`: the next byte for the transmitter.
    pub fn tx_pop(&mut self) -> Option<u8> {
        self.link.tx.pop()
    }
}

/// A frame the host wrote.
struct Sent {
    msg: Message,
    /// Bytes changed on the way (corruption fault or a bit error on the line).
    corrupted: bool,
    /// A byte of it fell into a link cut.
    lost: bool,
    /// The board decoded it.
    decoded: bool,
    /// Index into the scenario's commands, for low-rate messages.
    command: Option<usize>,
}

/// What the host received in reply to one low-rate message.
#[derive(Clone, Copy, Debug, Default)]
struct Reply {
    sent: bool,
    ack: Option<u8>,
}

/// The scripted seed 001 host's receiving side.
struct Host {
    dec: StreamDecoder,
    /// Low-rate messages waiting for their ACK: (command index, MSG_ID).
    pending: VecDeque<(usize, MsgId)>,
    replies: Vec<Reply>,
    decoded: u64,
    broken: u64,
    reports: Vec<(f64, String, u64)>,
    failures: Vec<String>,
    imus: VecDeque<(u32, [f64; 3], [f64; 3])>,
    imu_err: Option<[f64; 2]>,
}

impl Host {
    fn report(&mut self, t: f64, name: &str) {
        match self.reports.iter_mut().find(|(_, n, _)| n == name) {
            Some(e) => e.2 += 1,
            None => self.reports.push((t, name.into(), 1)),
        }
    }

    fn receive(&mut self, t: f64, byte: u8) {
        let Some(r) = self.dec.push(byte) else {
            return;
        };
        let m = match r {
            Ok(m) => m,
            Err(e) => {
                self.broken += 1;
                self.failures
                    .push(format!("{t:.4} s: host could not decode a reply: {e:?}"));
                return;
            }
        };
        self.decoded += 1;
        match m {
            Message::Ack(a) => {
                self.report(
                    t,
                    if a.result == 0 {
                        "ack_ok"
                    } else {
                        "ack_refused"
                    },
                );
                match self
                    .pending
                    .iter()
                    .position(|(_, id)| *id as u8 == a.msg_id)
                {
                    Some(i) => {
                        if let Some((k, _)) = self.pending.remove(i) {
                            self.replies[k].ack = Some(a.result);
                        }
                    }
                    None => self
                        .failures
                        .push(format!("{t:.4} s: ACK {a:?} for nothing the host sent")),
                }
            }
            Message::Status(s) => {
                self.report(t, "status");
                for (bit, name) in [
                    (StatusFlags::CMD_TIMEOUT, "status_cmd_timeout"),
                    (StatusFlags::ESTOP_LATCHED, "status_estop_latched"),
                ] {
                    if s.flags.has(bit) {
                        self.report(t, name);
                    }
                }
                if s.err != 0 {
                    self.report(t, "status_err");
                }
            }
            Message::Imu(imu) => {
                self.report(t, "imu");
                while self.imus.front().is_some_and(|(ms, _, _)| *ms < imu.t_ms) {
                    self.imus.pop_front();
                }
                let Some((_, acc, rate)) = self.imus.pop_front() else {
                    return;
                };
                let sat = |x: f64| x.abs() >= f64::from(i16::MAX);
                let acc_mg = acc.map(|a| a / G * 1000.0);
                let rate_mdps = rate.map(|w| w.to_degrees() * 1000.0);
                if acc_mg.iter().chain(&rate_mdps).any(|x| sat(*x)) {
                    return;
                }
                let da = (0..3)
                    .map(|k| (f64::from(imu.accel_mg[k]) - acc_mg[k]).abs())
                    .fold(0.0, f64::max);
                let dg = (0..3)
                    .map(|k| (f64::from(imu.gyro_mdps[k]) - rate_mdps[k]).abs())
                    .fold(0.0, f64::max);
                let e = self.imu_err.get_or_insert([0.0; 2]);
                e[0] = e[0].max(da);
                e[1] = e[1].max(dg);
            }
            other => self.failures.push(format!(
                "{t:.4} s: the board sent a host message: {other:?}"
            )),
        }
    }
}

/// Where the board stands after the host's `MOTOR_ENABLE` messages, as the run checks it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Disabled {
    /// Enabled (or never disabled).
    No,
    /// `MOTOR_ENABLE 0` arrived: the outputs follow at the next tick.
    FromNextTick,
    /// Disabled: no duty may reach a motor.
    Yes,
}

fn message(c: CdcMessage) -> Message {
    match c {
        CdcMessage::Enable => Message::MotorEnable(true),
        CdcMessage::Disable => Message::MotorEnable(false),
        CdcMessage::Estop => Message::Estop(Estop::Engage),
        CdcMessage::Release => Message::Estop(Estop::Release),
        CdcMessage::Ping => Message::Ping,
    }
}

fn in_window(t: f64, at: f64, dur: f64) -> bool {
    t >= at && t < at + dur
}

/// Runs a `cdc` scenario; writes the CSV trace to `trace` if given.
pub fn run(
    sc: &Scenario,
    opts: RunOptions,
    mut trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    let wall = Instant::now();
    let cfg = &sc.cdc;
    let mut rng = Rng::new(sc.seed);
    let mut board = SimCdcBoard::new();
    let arr = board.arr();
    let mut plant = Skid::new(SMALL_4WD);
    let mut down = Wire::new(
        sc.serial.baud,
        sc.serial.latency_ms,
        sc.serial.bit_error_rate,
    );
    let mut up = Wire::new(sc.serial.baud, sc.serial.latency_ms, 0.0);
    let mut monitor = StreamDecoder::new();
    let mut sent: Vec<Sent> = Vec::new();
    let mut commands = cfg.commands.clone();
    commands.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
    let mut host = Host {
        dec: StreamDecoder::new(),
        pending: VecDeque::new(),
        replies: vec![Reply::default(); commands.len()],
        decoded: 0,
        broken: 0,
        reports: Vec::new(),
        failures: Vec::new(),
        imus: VecDeque::new(),
        imu_err: None,
    };
    let period = 1.0 / cfg.frame_hz;
    let mut next_frame = 0.0;
    let mut next_command = 0usize;
    let onset = sc.fault_onset();
    let brake_age = statemachine::config::brake_age_for_timeout_ms(cfg.timeout_ms)
        .unwrap_or(u16::MAX)
        .min(Config::CDC.params().brake_after);
    let p = Config::CDC.params();

    let mut s = Summary {
        name: sc.name.clone(),
        profile: sc.profile.name().into(),
        onset_s: onset,
        ..Summary::default()
    };
    let mut series = Series {
        thresholds: Some([p.hold_after, p.stop_after, brake_age]),
        ..Series::default()
    };
    let names = [
        "host pwm m1 (left)",
        "host pwm m2 (right)",
        "duty m1 (applied)",
        "duty m2 (applied)",
        "robot speed (m/s)",
    ];
    let mut lines: Vec<(String, Vec<f64>)> = names
        .iter()
        .map(|n| ((*n).to_string(), Vec::new()))
        .collect();
    let mut last_valid: Option<(f64, u32)> = None;
    let mut prev_mode = board.out.mode;
    let mut brake_entries = board.safety().ladder().counters().brake_entries;
    let mut rearm_delivered = false;
    let mut disabled = Disabled::No;
    let mut host_estop = false;
    let mut estop_at: Option<f64> = None;
    let mut odo_at_onset: Option<f64> = None;
    let mut onset_braked_ticks: Option<u32> = None;

    if let Some(w) = trace.as_deref_mut() {
        writeln!(w, "t_s,mode,age,faults,pwm_cmd_1,pwm_cmd_2,pwm_cmd_3,pwm_cmd_4,duty_1,duty_2,duty_3,duty_4,shorted,current_1,current_2,current_3,current_4,wheel_l,wheel_r,v_mps,w_radps,x_m,y_m,odometer_m,frames_sent,corrupted_sent,corrupted_applied,rejected,replies,reply_errors")?;
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

        // The host writes: the 50 Hz stream, then any low-rate message due.
        let mut outgoing: Vec<(Message, Option<usize>)> = Vec::new();
        while next_frame <= t {
            if !paused {
                let pwm = cfg.pwm_at(next_frame);
                outgoing.push((
                    Message::SetMotorPwm(SetMotorPwm {
                        pwm,
                        timeout_ms: cfg.timeout_ms,
                    }),
                    None,
                ));
            }
            next_frame += period;
        }
        while !paused && next_command < commands.len() && commands[next_command].at_s <= t {
            outgoing.push((message(commands[next_command].message), Some(next_command)));
            next_command += 1;
        }
        for (msg, command) in outgoing {
            let mut buf = [0u8; cdc::MAX_FRAME_LEN];
            let len = msg.encode(&mut buf);
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
            if let Some(k) = command {
                host.replies[k].sent = true;
                if matches!(msg, Message::MotorEnable(_) | Message::Estop(_)) {
                    host.pending.push_back((k, msg.id()));
                }
            }
            sent.push(Sent {
                msg,
                corrupted,
                lost: false,
                decoded: false,
                command,
            });
        }

        // link_rx: every byte that arrived.
        while let Some(b) = down.arrived(t) {
            if cut(b.at) {
                sent[b.tag].lost = true;
                continue;
            }
            let rep = board.on_byte(b.byte);
            let seen = monitor.push(b.byte);
            if let Some(Ok(m)) = seen {
                debug_assert!(rep.decoded);
                if m != sent[b.tag].msg {
                    // A message the host never sent got through the decoder.
                    s.corrupted_applied += 1;
                } else {
                    sent[b.tag].decoded = true;
                }
                match m {
                    // Only an enable after the host's own ESTOP was released re-arms (the link
                    // is the only ESTOP source here).
                    Message::MotorEnable(true) => {
                        rearm_delivered |= !host_estop;
                        disabled = Disabled::No;
                    }
                    Message::MotorEnable(false) => disabled = Disabled::FromNextTick,
                    Message::Estop(Estop::Engage) => {
                        estop_at = Some(t);
                        host_estop = true;
                        rearm_delivered = false;
                    }
                    Message::Estop(Estop::Release) => host_estop = false,
                    _ => {}
                }
            }
            if rep.valid {
                last_valid = Some((t, board.safety().ticks()));
            }
            let e = board.safety().ladder().counters().brake_entries;
            if e != brake_entries {
                brake_entries = e;
                rearm_delivered = false;
            }
        }

        // watchdog_tick (and imu_read).
        if n % STEPS_PER_TICK == 0 && n > 0 {
            let truth = plant.imu_truth();
            if let Some(ms) = board.tick(|| plant.mpu6050_raw()) {
                host.imus.push_back((ms, truth.0, truth.1));
            }
            if disabled == Disabled::FromNextTick {
                disabled = Disabled::Yes;
                s.duty_while_disabled.get_or_insert(0.0);
            }
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
        }

        // link_tx: the transmitter sends whatever is queued while the line is free.
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
                host.receive(t, b.byte);
            }
        }

        // The plant.
        let drive = board.motors.map(|m| MotorDrive::of(&m, arr));
        plant.step(STEP_S, drive);

        // Measurements.
        let out = board.out;
        if disabled == Disabled::Yes {
            let d = board
                .motors
                .iter()
                .map(|m| f64::from(m.duty(arr)).abs())
                .fold(0.0, f64::max);
            if let Some(x) = s.duty_while_disabled.as_mut() {
                *x = x.max(d);
            }
        }
        if let Some(te) = estop_at {
            if board.all_shorted() {
                let x = (t - te) * 1e3;
                s.estop_brake_ms = Some(s.estop_brake_ms.map_or(x, |y: f64| y.max(x)));
                estop_at = None;
            }
        }
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
                            s.brake_after_last_frame_ms = Some((t - lt) * 1e3);
                            s.brake_after_last_frame_ticks =
                                Some(board.safety().ticks().wrapping_sub(lticks));
                            onset_braked_ticks = Some(board.safety().ticks());
                        }
                    }
                }
                _ => {}
            }
            prev_mode = out.mode;
        }
        if s.bridge_brake_after_last_frame_ms.is_none()
            && onset_braked_ticks.is_some()
            && board.all_shorted()
        {
            if let Some((lt, _)) = last_valid {
                s.bridge_brake_after_last_frame_ms = Some((t - lt) * 1e3);
            }
        }
        if let Some(o) = onset {
            if t >= o && odo_at_onset.is_none() {
                odo_at_onset = Some(plant.body.odometer);
                s.speed_at_onset = Some(plant.body.v);
            }
            if t >= o && board.all_shorted() && s.bridge_brake_ms.is_none() {
                s.bridge_brake_ms = Some((t - o) * 1e3);
            }
        }
        if let Some(o0) = odo_at_onset {
            if s.stop_distance_m.is_none()
                && plant.body.v.abs() < 0.002
                && plant.body.w.abs() < 0.01
            {
                s.stop_distance_m = Some(plant.body.odometer - o0);
            }
        }
        s.peak_speed = s.peak_speed.max(plant.body.v.abs());
        s.peak_current = plant
            .current
            .iter()
            .fold(s.peak_current, |m, i| m.max(i.abs()));

        if n % STEPS_PER_TICK == 0 && n > 0 {
            let tick_index = n / STEPS_PER_TICK;
            if tick_index % u64::from(sc.trace_every_ms) == 0 {
                let cmd = cfg.pwm_at(t).map(|p| f64::from(p) / 1000.0);
                let duty = board.motors.map(|m| f64::from(m.duty(arr)));
                if opts.keep_series {
                    series.t.push(t);
                    series.mode.push(out.mode as u8);
                    series.age.push(out.age);
                    series.v.push(plant.body.v);
                    for (k, x) in [cmd[0], cmd[1], duty[0], duty[1], plant.body.v]
                        .into_iter()
                        .enumerate()
                    {
                        lines[k].1.push(x);
                    }
                }
                if let Some(w) = trace.as_deref_mut() {
                    let ws = plant.body.wheel_speeds();
                    let b = &plant.body;
                    writeln!(
                        w,
                        "{:.4},{},{},{:#06x},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4},{:.4},{},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{},{}",
                        t,
                        mode_name(out.mode),
                        out.age,
                        out.faults.0,
                        cmd[0],
                        cmd[1],
                        cmd[2],
                        cmd[3],
                        duty[0],
                        duty[1],
                        duty[2],
                        duty[3],
                        board.motors.iter().filter(|m| m.in1 && m.in2).count(),
                        plant.current[0],
                        plant.current[1],
                        plant.current[2],
                        plant.current[3],
                        ws[0],
                        ws[1],
                        b.v,
                        b.w,
                        b.x,
                        b.y,
                        b.odometer,
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

    // Replies: every low-rate message that reached the board whole must have its ACK as expected.
    for (k, c) in commands.iter().enumerate() {
        let r = host.replies[k];
        let delivered = sent
            .iter()
            .any(|f| f.command == Some(k) && f.decoded && !f.lost);
        match (c.ack, r.ack) {
            (Some(want), Some(got)) if want != got => host.failures.push(format!(
                "{:?} at {} s: ACK result {got}, expected {want}",
                c.message, c.at_s
            )),
            (Some(want), None) if delivered => host.failures.push(format!(
                "{:?} at {} s: no ACK (expected result {want})",
                c.message, c.at_s
            )),
            _ => {}
        }
        if !r.sent {
            host.failures.push(format!(
                "{:?} at {} s was never sent (the run ended first)",
                c.message, c.at_s
            ));
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
    s.final_v = plant.body.v;
    s.replies = Some([host.decoded, host.broken]);
    s.reply_failures = host.failures;
    s.tx_dropped = u64::from(board.link().tx.dropped());
    s.imu_saturated = board.imu_saturated;
    s.imu_max_err = host.imu_err;
    for (t0, name, count) in host.reports {
        match s.host_reports.iter_mut().find(|(_, n, _)| *n == name) {
            Some(e) => e.2 += count,
            None => s.host_reports.push((t0, name, count)),
        }
    }
    s.host_reports.sort_by(|a, b| a.0.total_cmp(&b.0));
    s.sim_s = sc.duration_s;
    s.wall_s = wall.elapsed().as_secs_f64();
    if opts.keep_series {
        series.lines = Some(Panel {
            caption: "duty (fraction of full scale) and robot speed".into(),
            signals: lines,
        });
    }
    Ok(RunResult { summary: s, series })
}
