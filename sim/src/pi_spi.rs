//! The seed 004 board (`pi-spi` profile) in the loop: the board application's `pi_spi` task
//! bodies on a simulated STM32F407 with four encoder gearmotors on the skid-steer robot of
//! [`crate::skid`], four servos and the 6 V servo rail, and a scripted Raspberry Pi on the other
//! end of SPI2 exchanging packed `RxBuffer` / `TxBuffer`s.
//!
//! ```text
//!  task (rate)                     body (crate mcu)          simulated peripheral
//!  spi_dma_done  (per transfer)    PiSpiApp::on_transfer     the Pi's RxBuffer in, the TxBuffer out;
//!                                                            motors shorted at once on motors_off,
//!                                                            servo timer and rail at once
//!  watchdog_tick (1 kHz)           PiSpiApp::tick            encoder counters in; TIM8 CCR1..4,
//!                                                            IN1/IN2, servo pulses and rail out
//!  imu_read      (100 Hz)          PiSpiApp::imu_sample      the MPU6050's registers
//! ```
//!
//! The step is 100 µs. Within a step: the host's transfer when one is due (every 1/`frame_hz`
//! s), then the tick (every 10th step; `imu_read` every 10th tick), then the plant. A transfer is
//! full duplex: the Pi receives the `TxBuffer` the board wrote at the previous transfer while the
//! board receives the `RxBuffer`, so the host's odometry is one transfer old.
//!
//! What the run checks beside the ladder's comm-loss BRAKE (49th tick after the last valid
//! transfer, `Config::PI_SPI`):
//! - the odometry the host decodes against the plant's true pose ([`Summary::odometry_err_pct`]);
//! - the servo outputs, after every transfer and every tick, against the module's rules
//!   recomputed here from what reached the board and the ladder's mode ([`ServoRules`]);
//! - every motor shorted in the step of a transfer carrying the motor shutdown bit;
//! - BRAKE left only after the shutdown bit's 1 → 0 edge in valid transfers (the re-arm);
//! - no corrupted transfer whose effective content differs from what the host sent is taken.

use std::io::Write;
use std::time::Instant;

use mcu::cdc::{motor_outputs, MotorOutput};
use mcu::estop::EstopInput;
use mcu::pi_spi::{
    PiSpiApp, PiSpiTickInputs, ServoOutputs, TransferOutcome, COUNTS_PER_REV, MOTORS, SERVOS,
    TUNING,
};
use mcu::Safety;
use protocol::pi_spi::{
    assumed::KinematicsConfig, decode_rx, decode_tx, encode_rx, encode_tx, MotorMode, RxBuffer,
    ServoMode, Shutdown, TxBuffer, UpdateFlags, RX_LEN, RX_SHUTDOWN_OFFSET, TRANSFER_LEN, TX_LEN,
};
use statemachine::{Config, Drive, Mode, Output};

use crate::cdc::pwm_arr;
use crate::measure::{Trace, Watch};
use crate::plant::PlantParams;
use crate::rng::Rng;
use crate::runner::{corrupt, Panel, RunOptions, RunResult, Series, Summary};
use crate::scenario::{Fault, PiMotorMode, PiServoMode, PiSpiSettings, Scenario};
use crate::serial::{Rearm, Schedule};
use crate::skid::{MotorDrive, Skid, SIDE, SMALL_4WD};

/// Simulation step: 100 µs.
pub const STEP_S: f64 = 100e-6;
/// Steps per 1 ms tick.
const STEPS_PER_TICK: u64 = 10;
/// Ticks between two MPU6050 reads (100 Hz).
const IMU_PERIOD_TICKS: u32 = 10;

/// The robot of the seed 004 runs: the seed 001 robot's motors and body with the seed 004
/// board's 1440-count encoders.
pub const PI_SPI_ROBOT: PlantParams = PlantParams {
    counts_per_rev: COUNTS_PER_REV,
    ..SMALL_4WD
};

/// The seed 004 board: task state as the firmware would hold it, and its outputs.
#[derive(Clone, Debug)]
pub struct SimPiSpiBoard {
    safety: Safety<MOTORS>,
    app: PiSpiApp,
    estop: EstopInput,
    arr: u16,
    /// The buffer the next transfer sends (the SPI DMA's transmit buffer).
    tx: [u8; TRANSFER_LEN],
    /// Last ladder output.
    pub out: Output<MOTORS>,
    /// The driver inputs: CCR and IN1/IN2 per motor.
    pub motors: [MotorOutput; MOTORS],
    /// Servo pulses and the 6 V rail.
    pub servos: ServoOutputs,
}

impl Default for SimPiSpiBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimPiSpiBoard {
    /// Just out of reset: BRAKE latched, every motor shorted, servos off, a `TxBuffer` with the
    /// version and nothing else ready for the first transfer.
    pub fn new() -> Self {
        let cfg = Config::PI_SPI;
        let safety = Safety::new(cfg);
        let arr = pwm_arr();
        let out = safety.output();
        let mut tx = [0u8; TRANSFER_LEN];
        if let Ok(head) = <&mut [u8; TX_LEN]>::try_from(&mut tx[..TX_LEN]) {
            encode_tx(&TxBuffer::default(), head);
        }
        Self {
            app: PiSpiApp::new(&cfg, &TUNING, 1000 / IMU_PERIOD_TICKS, arr),
            estop: EstopInput::new(),
            motors: motor_outputs(&out.drive, arr),
            servos: ServoOutputs::OFF,
            out,
            safety,
            arr,
            tx,
        }
    }

    /// The safety core.
    pub fn safety(&self) -> &Safety<MOTORS> {
        &self.safety
    }

    /// The board application.
    pub fn app(&self) -> &PiSpiApp {
        &self.app
    }

    /// The timer's auto-reload.
    pub fn arr(&self) -> u16 {
        self.arr
    }

    /// True if every motor is shorted.
    pub fn all_shorted(&self) -> bool {
        self.motors.iter().all(|m| m.in1 && m.in2)
    }

    /// `spi_dma_done`: one full-duplex transfer at the board's time `now_us`. Returns what the
    /// board decided and the buffer the Pi received meanwhile (written at the previous transfer).
    pub fn transfer(
        &mut self,
        rx: &[u8; TRANSFER_LEN],
        now_us: u32,
    ) -> (TransferOutcome, [u8; TRANSFER_LEN]) {
        let sent = self.tx;
        let o = self
            .app
            .on_transfer(&mut self.safety, rx, now_us, 0, &mut self.tx);
        self.out = o.out;
        if o.motors_off {
            self.motors = motor_outputs(&Drive::Brake, self.arr);
        }
        self.servos = o.servos;
        (o, sent)
    }

    /// `watchdog_tick` with the encoder `counts`, and `imu_read` every tenth tick with the
    /// MPU6050's registers from `imu` (accelerometer, temperature, gyroscope).
    pub fn tick(&mut self, counts: [i32; MOTORS], imu: impl FnOnce() -> ([i16; 3], i16, [i16; 3])) {
        let inputs = PiSpiTickInputs {
            counts,
            ..PiSpiTickInputs::default()
        };
        let o = self
            .app
            .tick(&mut self.safety, self.estop.press_pending(), &inputs);
        self.out = o.out;
        self.motors = o.motors;
        self.servos = o.servos;
        if self.safety.ticks() % IMU_PERIOD_TICKS == 0 {
            let (accel, temp, gyro) = imu();
            self.app.imu_sample(Some((accel, gyro, temp)));
        }
    }
}

/// The plant's skid steer as a `KinematicsConfig`: wheel radius `r`, track `b`, wheels 1, 3 left
/// and 2, 4 right ([`SIDE`]), 1440 counts per revolution: vx = r/4 · Σω,
/// wz = r/(2b) · (ω2 + ω4 − ω1 − ω3), vy = 0.
pub fn skid_kinematics(p: &PlantParams) -> KinematicsConfig {
    let r = p.wheel_radius_m;
    let b = p.wheelbase_m;
    let mut inverse = [[0.0f32; 4]; 3];
    for k in 0..MOTORS {
        inverse[0][k] = (r / 4.0) as f32;
        let side = if SIDE[k] == 1 { 1.0 } else { -1.0 };
        inverse[2][k] = (side * r / (2.0 * b)) as f32;
    }
    KinematicsConfig {
        inverse,
        ticks_to_rad: [(core::f64::consts::TAU / f64::from(p.counts_per_rev)) as f32; 4],
    }
}

fn motor_mode(m: PiMotorMode) -> MotorMode {
    match m {
        PiMotorMode::Off => MotorMode::Off,
        PiMotorMode::PassiveBrake => MotorMode::PassiveBrake,
        PiMotorMode::Pwm => MotorMode::Pwm,
        PiMotorMode::Mav => MotorMode::Mav,
        PiMotorMode::Mtp => MotorMode::Mtp,
    }
}

fn servo_mode(m: PiServoMode) -> ServoMode {
    match m {
        PiServoMode::FullyDisabled => ServoMode::FullyDisabled,
        PiServoMode::Disabled => ServoMode::Disabled,
        PiServoMode::Enabled => ServoMode::Enabled,
    }
}

/// What of a buffer can act on the board: the fields its modes and flags use. Two buffers with
/// the same effective content command the same thing (a change in, e.g., the PID block of a
/// buffer without a PID flag is ignored by the board and is not an applied corruption).
fn effective(rx: &RxBuffer) -> RxBuffer {
    let mut e = *rx;
    let f = rx.updates.0;
    if f & (UpdateFlags::MOTOR_PID_SPEED | UpdateFlags::MOTOR_PID_POS) == 0 {
        e.motor_pid_settings = Default::default();
    }
    if f & UpdateFlags::IMU_ORIENTATION == 0 {
        e.imu_gyro_orientation = [0; 9];
        e.imu_compass_orientation = [0; 9];
    }
    if f & UpdateFlags::KINEMATICS == 0 {
        e.kinematics = KinematicsConfig::default();
    }
    for k in 0..MOTORS {
        match e.motor_control_mode[k] {
            MotorMode::Off | MotorMode::PassiveBrake => {
                e.motor_target[k] = 0;
                e.motor_goal_position[k] = 0;
            }
            MotorMode::Pwm | MotorMode::Mav => e.motor_goal_position[k] = 0,
            MotorMode::Mtp => e.motor_target[k] = e.motor_target[k].saturating_abs(),
        }
    }
    for k in 0..SERVOS {
        if e.servo_mode[k] != ServoMode::Enabled {
            e.servo_pos[k] = 0;
        }
    }
    e
}

/// The servo rules of `mcu::pi_spi`'s module documentation, recomputed from what reached the
/// board: the last valid transfer's servo modes and positions, the servo shutdown bit (set by
/// any transfer's raw bits, cleared only by a valid transfer without it), and the ladder's mode.
#[derive(Clone, Copy, Debug, Default)]
pub struct ServoRules {
    /// Modes and positions of the last valid transfer (none before the first).
    cmd: Option<([ServoMode; SERVOS], [u16; SERVOS])>,
    shutdown: bool,
}

impl ServoRules {
    /// A transfer reached the board: its raw bytes, and its content if the board took it.
    pub fn transfer(&mut self, raw: &[u8; TRANSFER_LEN], taken: Option<&RxBuffer>) {
        // The servo bit is bit 0 of systemShutdown.
        self.shutdown |= raw[RX_SHUTDOWN_OFFSET] & 1 != 0;
        if let Some(rx) = taken {
            self.cmd = Some((rx.servo_mode, rx.servo_pos));
            self.shutdown = rx.system_shutdown.servos;
        }
    }

    /// The outputs the rules give with the ladder in `mode`.
    pub fn expected(&self, mode: Mode) -> ServoOutputs {
        let Some((modes, pos)) = self.cmd else {
            return ServoOutputs::OFF;
        };
        if self.shutdown {
            return ServoOutputs::OFF;
        }
        let mut pulses_us = [0u16; SERVOS];
        if mode != Mode::Brake {
            for k in 0..SERVOS {
                if modes[k] == ServoMode::Enabled {
                    pulses_us[k] = pos[k];
                }
            }
        }
        ServoOutputs {
            rail_on: modes.iter().any(|m| *m != ServoMode::FullyDisabled),
            pulses_us,
        }
    }
}

/// The scripted Raspberry Pi.
struct Host {
    /// The MAV target sent last per motor (none: the motor was not in MAV).
    ramp: [Option<i32>; MOTORS],
    shutdown_done: Vec<bool>,
    kinematics_sent: bool,
    reset_sent: bool,
    kinematics: KinematicsConfig,
    /// The last `TxBuffer` decoded, and when.
    feedback: Option<(f64, TxBuffer)>,
    decoded: u64,
    broken: u64,
    failures: Vec<String>,
}

impl Host {
    /// The buffer for the transfer at `t`.
    fn buffer(&mut self, cfg: &PiSpiSettings, t: f64) -> RxBuffer {
        let mut rx = RxBuffer {
            kinematics: self.kinematics,
            ..RxBuffer::default()
        };
        let mut sd = Shutdown::default();
        for (e, done) in cfg.shutdown.iter().zip(self.shutdown_done.iter_mut()) {
            if t >= e.at_s && (!*done || t < e.at_s + e.for_s) {
                *done = true;
                sd.motors |= e.motors;
                sd.servos |= e.servos;
            }
        }
        rx.system_shutdown = sd;
        let seg = cfg.segment_at(t);
        let bemf = self.feedback.map_or([0; MOTORS], |(_, f)| f.motor.bemf);
        for k in 0..MOTORS {
            let (mode, target, goal) = seg.map_or((PiMotorMode::Off, 0, 0), |s| {
                (s.modes[k], s.targets[k], s.goals[k])
            });
            rx.motor_control_mode[k] = motor_mode(mode);
            rx.motor_goal_position[k] = goal;
            rx.motor_target[k] = target;
            if mode == PiMotorMode::Mav {
                // Entering MAV: from the wheel's speed the board reports; then ramped.
                let from = self.ramp[k].unwrap_or(bemf[k]);
                let step = cfg.mav_step_cps;
                let next = from + (target - from).clamp(-step, step);
                rx.motor_target[k] = next;
                self.ramp[k] = Some(next);
            } else {
                self.ramp[k] = None;
            }
        }
        if let Some(c) = cfg.servo_at(t) {
            rx.servo_mode = c.modes.map(servo_mode);
            rx.servo_pos = c.positions;
        }
        let mut flags = 0u8;
        if !self.kinematics_sent && t >= cfg.kinematics_at_s {
            self.kinematics_sent = true;
            flags |= UpdateFlags::KINEMATICS;
        }
        if !self.reset_sent && cfg.odom_reset_at_s.is_some_and(|at| t >= at) {
            self.reset_sent = true;
            flags |= UpdateFlags::ODOM_RESET;
        }
        rx.updates = UpdateFlags(flags);
        rx
    }

    /// The `TxBuffer` received in the transfer at `t`.
    fn receive(&mut self, t: f64, tx: &[u8; TRANSFER_LEN]) {
        let Ok(head) = <&[u8; TX_LEN]>::try_from(&tx[..TX_LEN]) else {
            return;
        };
        match decode_tx(head) {
            Ok(fb) => {
                self.decoded += 1;
                self.feedback = Some((t, fb));
            }
            Err(e) => {
                self.broken += 1;
                if self.failures.len() < 8 {
                    self.failures
                        .push(format!("{t:.4} s: host could not decode a TxBuffer: {e:?}"));
                }
            }
        }
    }
}

/// The plant's pose when the board's odometry started from zero: x, y, heading, odometer.
#[derive(Clone, Copy, Debug, Default)]
struct Origin {
    x: f64,
    y: f64,
    theta: f64,
    odometer: f64,
}

/// The board's odometry against the plant: position error (m), travel (m), heading error (rad).
fn odometry_error(fb: &TxBuffer, plant: &Skid, o: &Origin) -> (f64, f64, f64) {
    let b = &plant.body;
    let (dx, dy) = (b.x - o.x, b.y - o.y);
    let (s, c) = o.theta.sin_cos();
    let (xr, yr) = (c * dx + s * dy, -s * dx + c * dy);
    let od = &fb.odometry;
    let err = (f64::from(od.pos_x) - xr).hypot(f64::from(od.pos_y) - yr);
    let dh = f64::from(od.heading) - (b.theta - o.theta);
    let dh = dh.sin().atan2(dh.cos()).abs();
    (err, b.odometer - o.odometer, dh)
}

/// The encoder counts of the four motors: each wheel's angle in counts, rounded down.
fn counts_of(plant: &Skid) -> [i32; MOTORS] {
    let per_rad = f64::from(COUNTS_PER_REV) / core::f64::consts::TAU;
    SIDE.map(|k| (plant.body.wheel_angle[k] * per_rad).floor() as i32)
}

/// Runs a `pi-spi` scenario; writes the CSV trace to `trace` if given.
pub fn run(
    sc: &Scenario,
    opts: RunOptions,
    trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    let wall = Instant::now();
    let cfg = &sc.pi_spi;
    let p = *Config::PI_SPI.params();
    let mut rng = Rng::new(sc.seed);
    let mut board = SimPiSpiBoard::new();
    let arr = board.arr();
    let mut plant = Skid::new(PI_SPI_ROBOT);
    let kinematics = cfg.kinematics.map_or_else(
        || skid_kinematics(&plant.body.p),
        |k| KinematicsConfig {
            inverse: k.inverse,
            ticks_to_rad: k.ticks_to_rad,
        },
    );
    let mut host = Host {
        ramp: [None; MOTORS],
        shutdown_done: vec![false; cfg.shutdown.len()],
        kinematics_sent: false,
        reset_sent: false,
        kinematics,
        feedback: None,
        decoded: 0,
        broken: 0,
        failures: Vec::new(),
    };
    let mut schedule: Schedule<()> = Schedule::new(cfg.frame_hz, &[], |_| 0.0);
    let [cb0, cb1] = cfg.corrupt_bytes;

    let mut s = Summary {
        servo_violations: Some(0),
        ..Summary::new(sc)
    };
    let names = [
        "duty m1 (left)",
        "duty m2 (right)",
        "robot speed (m/s)",
        "x true (m)",
        "y true (m)",
        "x odometry (m)",
        "y odometry (m)",
    ];
    let caption = "duty (fraction of full scale), robot speed, position: true and odometry";
    let mut series = Series {
        lines: opts
            .keep_series
            .then(|| Panel::new(caption, names.map(String::from))),
        thresholds: Some([p.hold_after, p.stop_after, p.brake_after]),
        ..Series::default()
    };
    let mut watch = Watch::new(board.out.mode);
    let mut rearm = Rearm::new(board.safety().ladder().counters());
    // The motor shutdown bit of the last valid transfer (the ladder starts as if enabled).
    let mut motors_bit = false;
    let mut last_valid: Option<(f64, u32)> = None;
    let mut onset_braked = false;
    let mut shutdown_pending: Option<f64> = None;
    let mut rules = ServoRules::default();
    let mut origin = Origin::default();
    let mut odometry_done = false;
    let mut sent_frames = 0u64;

    let mut trace = Trace::new(sc, trace, "target_1,target_2,target_3,target_4,duty_1,duty_2,duty_3,duty_4,shorted,wheel_l,wheel_r,v_mps,w_radps,x_m,y_m,heading_rad,odometer_m,odo_x_m,odo_y_m,odo_heading_rad,rail,servo_1,servo_2,servo_3,servo_4,frames_sent,corrupted_sent,corrupted_applied,rejected,feedback_ok,feedback_bad")?;

    let mut last_targets = [0i32; MOTORS];
    let check_servos = |s: &mut Summary, got: ServoOutputs, want: ServoOutputs| {
        s.servo_checks += 1;
        if got != want {
            if let Some(n) = s.servo_violations.as_mut() {
                *n += 1;
            }
        }
    };

    for (n, t) in sc.steps(STEP_S) {
        let paused = sc.host_paused(t);

        // The Pi's transfer, when one is due.
        let mut due = false;
        schedule.frames_due(t, paused, |_| due = true);
        if due {
            let rx = host.buffer(cfg, t);
            last_targets = rx.motor_target;
            let mut bytes = [0u8; TRANSFER_LEN];
            if let Ok(head) = <&mut [u8; RX_LEN]>::try_from(&mut bytes[..RX_LEN]) {
                encode_rx(&rx, head);
            }
            let mut corrupted = false;
            for f in &sc.faults {
                if let Fault::Corruption { rate, .. } = *f {
                    if f.active_at(t) && rng.chance(rate) {
                        corrupted |= corrupt(&mut bytes[cb0..cb1], &mut rng);
                    }
                }
            }
            sent_frames += 1;
            if corrupted {
                s.corrupted_sent += 1;
            }
            // A cut link: the board's DMA sees no clock, the Pi reads nothing.
            if !sc.link_cut(t) {
                let now_us = (t * 1e6).round() as u32;
                let (o, tx) = board.transfer(&bytes, now_us);
                let got = <&[u8; RX_LEN]>::try_from(&bytes[..RX_LEN])
                    .ok()
                    .and_then(|b| decode_rx(b).ok());
                let taken = if o.accepted { got.as_ref() } else { None };
                if o.accepted {
                    last_valid = Some((t, board.safety().ticks()));
                    if let Some(g) = taken {
                        if corrupted && effective(g) != effective(&rx) {
                            s.corrupted_applied += 1;
                        }
                        if g.updates.0 & UpdateFlags::ODOM_RESET != 0 {
                            let b = &plant.body;
                            origin = Origin {
                                x: b.x,
                                y: b.y,
                                theta: b.theta,
                                odometer: b.odometer,
                            };
                        }
                    }
                } else if corrupted {
                    s.corrupted_rejected += 1;
                }
                // The re-arm: the motor shutdown bit's 1 → 0 edge in valid transfers.
                rearm.latches(board.safety().ladder().counters());
                if let Some(g) = taken {
                    if motors_bit && !g.system_shutdown.motors {
                        rearm.deliver();
                    }
                    motors_bit = g.system_shutdown.motors;
                }
                // The motor shutdown bit (bit 1 of systemShutdown) as the handler reads it.
                if bytes[RX_SHUTDOWN_OFFSET] & 2 != 0 {
                    s.shutdown_transfers += 1;
                    shutdown_pending.get_or_insert(t);
                }
                rules.transfer(&bytes, taken);
                check_servos(&mut s, o.servos, rules.expected(o.out.mode));
                host.receive(t, &tx);
            }
        }

        // watchdog_tick (and imu_read).
        if n % STEPS_PER_TICK == 0 && n > 0 {
            let counts = counts_of(&plant);
            board.tick(counts, || plant.mpu6050_raw());
            let c = board.safety().ladder().counters();
            rearm.tick(c, watch.mode, board.out.mode, &mut s);
            check_servos(&mut s, board.servos, rules.expected(board.out.mode));
        }

        // Motor shutdown: every motor shorted, timed from the transfer.
        if let Some(ts) = shutdown_pending {
            if board.all_shorted() {
                let ms = (t - ts) * 1e3;
                s.shutdown_brake_ms = Some(s.shutdown_brake_ms.map_or(ms, |x: f64| x.max(ms)));
                shutdown_pending = None;
            }
        }

        // The plant.
        let drive = board.motors.map(|m| MotorDrive::of(&m, arr));
        plant.step(STEP_S, drive);

        // Measurements.
        let out = board.out;
        if watch.mode(
            &mut s,
            t,
            out.mode,
            out.faults,
            last_valid.map(|(lt, _)| lt),
        ) {
            if let Some((_, lticks)) = last_valid {
                s.brake_after_last_frame_ticks = Some(board.safety().ticks().wrapping_sub(lticks));
            }
            onset_braked = true;
        }
        if s.bridge_brake_after_last_frame_ms.is_none() && onset_braked && board.all_shorted() {
            if let Some((lt, _)) = last_valid {
                s.bridge_brake_after_last_frame_ms = Some((t - lt) * 1e3);
            }
        }
        watch.motion(&mut s, t, &plant.body, &plant.current, board.all_shorted());
        if !odometry_done && cfg.odometry_at_s.is_some_and(|at| t >= at) {
            odometry_done = true;
            measure_odometry(&mut s, &host, &plant, &origin);
        }

        if n % STEPS_PER_TICK == 0 && n > 0 && trace.due(n / STEPS_PER_TICK) {
            let duty = board.motors.map(|m| f64::from(m.duty(arr)));
            let od = host.feedback.map(|(_, f)| f.odometry).unwrap_or_default();
            let b = &plant.body;
            if opts.keep_series {
                series.push_tick(
                    t,
                    out.mode,
                    out.age,
                    [
                        duty[0],
                        duty[1],
                        b.v,
                        b.x,
                        b.y,
                        f64::from(od.pos_x),
                        f64::from(od.pos_y),
                    ],
                );
                series.v.push(b.v);
            }
            if let Some(w) = trace.row(t, out.mode, out.age, out.faults)? {
                let ws = b.wheel_speeds();
                let sv = board.servos;
                writeln!(
                    w,
                    "{},{},{},{},{:.4},{:.4},{:.4},{:.4},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{},{},{},{},{},{},{}",
                    last_targets[0],
                    last_targets[1],
                    last_targets[2],
                    last_targets[3],
                    duty[0],
                    duty[1],
                    duty[2],
                    duty[3],
                    board.motors.iter().filter(|m| m.in1 && m.in2).count(),
                    ws[0],
                    ws[1],
                    b.v,
                    b.w,
                    b.x,
                    b.y,
                    b.theta,
                    b.odometer,
                    od.pos_x,
                    od.pos_y,
                    od.heading,
                    u8::from(sv.rail_on),
                    sv.pulses_us[0],
                    sv.pulses_us[1],
                    sv.pulses_us[2],
                    sv.pulses_us[3],
                    sent_frames,
                    s.corrupted_sent,
                    s.corrupted_applied,
                    board.safety().ladder().counters().rejected_total(),
                    host.decoded,
                    host.broken,
                )?;
            }
        }
    }

    if !odometry_done {
        measure_odometry(&mut s, &host, &plant, &origin);
    }
    if let Some(ts) = shutdown_pending {
        host.failures.push(format!(
            "the motor shutdown transfer at {ts:.4} s never shorted every motor"
        ));
        s.shutdown_brake_ms = Some(f64::INFINITY);
    }
    s.frames_sent = sent_frames;
    s.final_v = plant.body.v;
    s.replies = Some([host.decoded, host.broken]);
    s.reply_failures.extend(host.failures);
    s.finish(sc, wall, board.safety().ladder().counters(), board.out.mode);
    Ok(RunResult { summary: s, series })
}

/// The odometry figures of `s` now: the host's last decoded `TxBuffer` against the plant.
fn measure_odometry(s: &mut Summary, host: &Host, plant: &Skid, origin: &Origin) {
    let Some((_, fb)) = host.feedback else {
        return;
    };
    let (err, travel, dh) = odometry_error(&fb, plant, origin);
    s.odometry_err_m = Some(err);
    s.odometry_travel_m = Some(travel);
    s.odometry_heading_err_deg = Some(dh.to_degrees());
    if travel > 0.0 {
        s.odometry_err_pct = Some(100.0 * err / travel);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The default kinematics by hand for the seed 004 robot (r = 0.0325 m, b = 0.18 m as the
    /// plant holds them): a straight run at ω on every wheel is r·ω forward, no yaw; the right
    /// side alone at ω turns CCW at r·ω/b (half the forward speed of the whole robot's r·ω/2).
    #[test]
    fn default_kinematics_match_the_skid_steer() {
        let plant = Skid::new(PI_SPI_ROBOT);
        let k = skid_kinematics(&plant.body.p);
        let twist = |w: [f32; 4]| {
            k.inverse
                .map(|row| row.iter().zip(w).map(|(a, b)| a * b).sum::<f32>())
        };
        let [vx, vy, wz] = twist([10.0; 4]);
        assert!(
            (vx - 0.325).abs() < 1e-4 && vy == 0.0 && wz.abs() < 1e-6,
            "{vx} {wz}"
        );
        let [vx, _, wz] = twist([0.0, 10.0, 0.0, 10.0]);
        assert!((vx - 0.1625).abs() < 1e-4, "{vx}");
        assert!((wz - 0.325 / 0.18).abs() < 1e-3, "{wz}");
        assert!((k.ticks_to_rad[0] - mcu::pi_spi::RAD_PER_COUNT).abs() < 1e-9);
    }

    /// The rules of the module documentation's table, recomputed.
    #[test]
    fn servo_rules_follow_the_table() {
        let mut r = ServoRules::default();
        assert_eq!(
            r.expected(Mode::Normal),
            ServoOutputs::OFF,
            "before any transfer"
        );
        let mut rx = RxBuffer {
            servo_mode: [
                ServoMode::Enabled,
                ServoMode::Disabled,
                ServoMode::FullyDisabled,
                ServoMode::Enabled,
            ],
            servo_pos: [1500, 700, 800, 2000],
            ..RxBuffer::default()
        };
        let mut raw = [0u8; TRANSFER_LEN];
        r.transfer(&raw, Some(&rx));
        let e = r.expected(Mode::Normal);
        assert!(e.rail_on);
        assert_eq!(e.pulses_us, [1500, 0, 0, 2000]);
        assert_eq!(
            r.expected(Mode::Brake).pulses_us,
            [0; 4],
            "no pulse in BRAKE"
        );
        assert!(r.expected(Mode::Brake).rail_on);
        // A refused buffer with the servo bit still cuts everything; the next valid one without
        // it restores the command.
        raw[RX_SHUTDOWN_OFFSET] = 1;
        r.transfer(&raw, None);
        assert_eq!(r.expected(Mode::Normal), ServoOutputs::OFF);
        raw[RX_SHUTDOWN_OFFSET] = 0;
        rx.servo_mode = [ServoMode::FullyDisabled; 4];
        r.transfer(&raw, Some(&rx));
        assert!(
            !r.expected(Mode::Normal).rail_on,
            "all fully disabled: rail off"
        );
    }
}
