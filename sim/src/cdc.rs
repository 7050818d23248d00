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
use statemachine::{Config, Estop, Output};

use crate::measure::{add_report, Trace, Watch};
use crate::rng::Rng;
use crate::runner::{Panel, RunOptions, RunResult, Series, Summary};
use crate::scenario::{CdcMessage, Scenario};
use crate::serial::{Decode, HostRx, Link, Rearm, Schedule, SerialBoard};
use crate::skid::{MotorDrive, Skid, G, SMALL_4WD};

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
}

impl SerialBoard<MOTORS> for SimCdcBoard {
    fn safety(&self) -> &Safety<MOTORS> {
        &self.safety
    }

    fn on_byte(&mut self, byte: u8) {
        let st = self.board_status();
        if let Some(out) = self.link.on_byte(&mut self.safety, byte, &st) {
            self.out = out;
            if let Some(m) = outputs_after_frame(&out, self.arr) {
                self.motors = m;
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

impl Decode for StreamDecoder {
    type Msg = Message;
    type Error = cdc::Error;

    fn decode(&mut self, byte: u8) -> Option<Result<Message, cdc::Error>> {
        self.push(byte)
    }
}

/// What the host received in reply to one low-rate message.
#[derive(Clone, Copy, Debug, Default)]
struct Reply {
    sent: bool,
    ack: Option<u8>,
}

/// The scripted seed 001 host's receiving side.
struct Host {
    rx: HostRx<StreamDecoder>,
    /// Low-rate messages waiting for their ACK: (command index, MSG_ID).
    pending: VecDeque<(usize, MsgId)>,
    replies: Vec<Reply>,
    reports: Vec<(f64, String, u64)>,
    failures: Vec<String>,
    imus: VecDeque<(u32, [f64; 3], [f64; 3])>,
    imu_err: Option<[f64; 2]>,
}

impl Host {
    fn report(&mut self, t: f64, name: &str) {
        add_report(&mut self.reports, t, name, 1);
    }

    fn receive(&mut self, t: f64, byte: u8) {
        let m = match self.rx.byte(t, byte, "a reply") {
            Ok(Some(m)) => m,
            Ok(None) => return,
            Err(failure) => return self.failures.push(failure),
        };
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

/// Runs a `cdc` scenario; writes the CSV trace to `trace` if given.
pub fn run(
    sc: &Scenario,
    opts: RunOptions,
    trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    let wall = Instant::now();
    let cfg = &sc.cdc;
    let mut rng = Rng::new(sc.seed);
    let mut board = SimCdcBoard::new();
    let arr = board.arr();
    let mut plant = Skid::new(SMALL_4WD);
    // Each frame's expected reply: the index of its low-rate message in `commands`.
    let mut link: Link<Message, Option<usize>, _> = Link::new(sc, StreamDecoder::new());
    let mut schedule = Schedule::new(cfg.frame_hz, &cfg.commands, |c| c.at_s);
    let mut host = Host {
        rx: HostRx::default(),
        pending: VecDeque::new(),
        replies: vec![Reply::default(); schedule.commands.len()],
        reports: Vec::new(),
        failures: Vec::new(),
        imus: VecDeque::new(),
        imu_err: None,
    };
    let brake_age = statemachine::config::brake_age_for_timeout_ms(cfg.timeout_ms)
        .unwrap_or(u16::MAX)
        .min(Config::CDC.params().brake_after);
    let p = Config::CDC.params();

    let mut s = Summary::new(sc);
    let names = [
        "host pwm m1 (left)",
        "host pwm m2 (right)",
        "duty m1 (applied)",
        "duty m2 (applied)",
        "robot speed (m/s)",
    ];
    let caption = "duty (fraction of full scale) and robot speed";
    let mut series = Series {
        lines: opts
            .keep_series
            .then(|| Panel::new(caption, names.map(String::from))),
        thresholds: Some([p.hold_after, p.stop_after, brake_age]),
        ..Series::default()
    };
    let mut watch = Watch::new(board.out.mode);
    let mut rearm = Rearm::new(board.safety().ladder().counters());
    let mut disabled = Disabled::No;
    let mut host_estop = false;
    let mut estop_at: Option<f64> = None;
    let mut onset_braked_ticks: Option<u32> = None;

    let mut trace = Trace::new(sc, trace, "pwm_cmd_1,pwm_cmd_2,pwm_cmd_3,pwm_cmd_4,duty_1,duty_2,duty_3,duty_4,shorted,current_1,current_2,current_3,current_4,wheel_l,wheel_r,v_mps,w_radps,x_m,y_m,odometer_m,frames_sent,corrupted_sent,corrupted_applied,rejected,replies,reply_errors")?;

    for (n, t) in sc.steps(STEP_S) {
        let paused = sc.host_paused(t);

        // The host writes: the 50 Hz stream, then any low-rate message due.
        let mut outgoing: Vec<(Message, Option<usize>)> = Vec::new();
        schedule.frames_due(t, paused, |at| {
            let pwm = cfg.pwm_at(at);
            outgoing.push((
                Message::SetMotorPwm(SetMotorPwm {
                    pwm,
                    timeout_ms: cfg.timeout_ms,
                }),
                None,
            ));
        });
        schedule.commands_due(t, paused, |k, c| {
            outgoing.push((message(c.message), Some(k)));
        });
        for (msg, command) in outgoing {
            let mut buf = [0u8; cdc::MAX_FRAME_LEN];
            let len = msg.encode(&mut buf);
            if let Some(k) = command {
                host.replies[k].sent = true;
                if matches!(msg, Message::MotorEnable(_) | Message::Estop(_)) {
                    host.pending.push_back((k, msg.id()));
                }
            }
            link.write(sc, t, msg, &mut buf[..len], command, &mut rng);
        }

        // link_rx: every byte that arrived.
        while let Some((_, m)) = link.link_rx(sc, t, &mut board, &mut s) {
            if let Some(m) = m {
                match m {
                    // Only an enable after the host's own ESTOP was released re-arms (the link
                    // is the only ESTOP source here).
                    Message::MotorEnable(true) => {
                        if !host_estop {
                            rearm.deliver();
                        }
                        disabled = Disabled::No;
                    }
                    Message::MotorEnable(false) => disabled = Disabled::FromNextTick,
                    Message::Estop(Estop::Engage) => {
                        estop_at = Some(t);
                        host_estop = true;
                        rearm.cancel();
                    }
                    Message::Estop(Estop::Release) => host_estop = false,
                    _ => {}
                }
            }
            rearm.latches(board.safety().ladder().counters());
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
            let c = board.safety().ladder().counters();
            rearm.tick(c, watch.mode, board.out.mode, &mut s);
        }

        // link_tx: the transmitter sends whatever is queued while the line is free.
        link.link_tx(sc, t, STEP_S, &mut board, &mut rng, |b, _| {
            host.receive(t, b)
        });

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
        if link.watch_mode(&mut watch, &mut s, t, &out, board.safety().ticks()) {
            onset_braked_ticks = Some(board.safety().ticks());
        }
        if s.bridge_brake_after_last_frame_ms.is_none()
            && onset_braked_ticks.is_some()
            && board.all_shorted()
        {
            if let Some((lt, _)) = link.last_valid {
                s.bridge_brake_after_last_frame_ms = Some((t - lt) * 1e3);
            }
        }
        watch.motion(&mut s, t, &plant.body, &plant.current, board.all_shorted());

        if n % STEPS_PER_TICK == 0 && n > 0 && trace.due(n / STEPS_PER_TICK) {
            let cmd = cfg.pwm_at(t).map(|p| f64::from(p) / 1000.0);
            let duty = board.motors.map(|m| f64::from(m.duty(arr)));
            if opts.keep_series {
                let v = plant.body.v;
                series.push_tick(t, out.mode, out.age, [cmd[0], cmd[1], duty[0], duty[1], v]);
                series.v.push(v);
            }
            if let Some(w) = trace.row(t, out.mode, out.age, out.faults)? {
                let ws = plant.body.wheel_speeds();
                let b = &plant.body;
                write!(
                    w,
                    "{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4},{:.4},{},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},",
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
                )?;
                link.trace_tail(w, &s, &board, host.rx.counts())?;
            }
        }
    }

    // Replies: every low-rate message that reached the board whole must have its ACK as expected.
    for (k, c) in schedule.commands.iter().enumerate() {
        let r = host.replies[k];
        let delivered = link
            .sent
            .iter()
            .any(|f| f.expect == Some(k) && f.decoded && !f.lost);
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

    link.tally(&mut s);
    s.final_v = plant.body.v;
    s.replies = Some(host.rx.counts());
    s.reply_failures = host.failures;
    s.tx_dropped = u64::from(board.link().tx.dropped());
    s.imu_saturated = board.imu_saturated;
    s.imu_max_err = host.imu_err;
    for (t0, name, count) in host.reports {
        add_report(&mut s.host_reports, t0, &name, count);
    }
    s.host_reports.sort_by(|a, b| a.0.total_cmp(&b.0));
    s.finish(sc, wall, board.safety().ladder().counters(), board.out.mode);
    Ok(RunResult { summary: s, series })
}
