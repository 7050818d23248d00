//! The seed 004 board application (`pi-spi` profile): four DC motors with quadrature encoders in
//! the seed's five modes, four servos with the 6 V rail, the IMU and odometry, behind the Raspberry
//! Pi's packed `RxBuffer` / `TxBuffer` exchanged over SPI2.
//!
//! ```text
//!  task (priority, rate)            body                          what it does
//!  estop_input   (5, EXTI edge)     estop::EstopInput::edge_then  every motor shorted in the handler
//!  spi_dma_done  (2, per transfer)  PiSpiApp::on_transfer         shutdown bits first (motors shorted, servos
//!                                                                 off in this handler), then version, parity,
//!                                                                 decode → ladder; one-shot updates; the next TxBuffer
//!  watchdog_tick (2, 1 kHz)         PiSpiApp::tick                ESTOP, supply → ladder tick → per-motor loop
//!                                                                 (PWM / MAV / MTP) → compares and IN1/IN2;
//!                                                                 servos; odometry
//!  imu_read      (1, 100 Hz)        PiSpiApp::imu_sample          MPU6050 → fusion → the TxBuffer's ImuData
//! ```
//!
//! The two priority-2 tasks never preempt each other, so the shutdown bit is acted on at most one
//! tick body after the transfer completes (BUDGET.md gives that body's length), far inside the
//! seed's "within one SPI cycle".
//!
//! # One transfer ([`PiSpiApp::on_transfer`]), the seed's §"SPI Interrupt Handling" in order
//!
//! | step | the seed                                        | here |
//! |------|-------------------------------------------------|------|
//! | 0    | (the shutdown bit is the "primary hardware safety interlock") | [`protocol::pi_spi::shutdown_raw`] read from the raw bytes before any check: `motors` → `Event::Shutdown(true)`, BRAKE latched in this step, and the caller shorts the motors before it returns; `servos` → every servo off, rail cut, in this handler. A bit from a corrupted buffer can only stop things. |
//! | 1, 2 | timestamp, digital inputs into the TxBuffer     | the caller's `now_us` and `digital` go into the TxBuffer written for the next transfer |
//! | 3    | wrong `transferVersion`: commands ignored        | `Rejected(Version)`: nothing but counters changes; no update flag is taken |
//! | 4    | parity wrong: update flags not trusted          | `Rejected(Parity)`: the update flags **and the commands** are ignored (see below) |
//! | 5    | `sanitizeMotorCommandsForShutdown()`             | the decoded command carries `enable = !motors`; a shutdown buffer's motor fields never drive |
//!
//! **What a bad parity invalidates.** The seed drops only the update flags. On this link the parity
//! bit is the only sign of a corrupted transfer (no CRC): a buffer whose flags word is corrupted
//! may have corrupted targets too, and this board does not apply a command it cannot trust. It is
//! refused whole (as a missed transfer: the ladder holds the last valid command and starts HOLD
//! after two periods). The shutdown bits are still honoured (step 0).
//!
//! **Refused as a whole** (nothing applied, counted by reason in the ladder): a wrong version, a
//! wrong parity, an undefined mode or reserved bit (`Decode`), a target outside the profile
//! (`OutOfRange`, by the ladder's validation: `|motorTarget| > 399` in PWM, beyond ±v_max in MAV,
//! a goal beyond the travel in MTP), an enabled servo outside 600–2600 ticks (`OutOfRange`).
//! One-shot updates of a refused buffer are not taken. Of a valid buffer, each update is checked
//! by its owner and refused on its own (counted in [`UpdateCounters`]): gains outside
//! [`GainBounds`], an orientation that is not a rotation, a kinematics block that is not finite or
//! maps no wheel to motion.
//!
//! # Motors (the seed's modes on the ladder's drive modes)
//!
//! | `motorControlMode` | ladder axis          | tick (1 kHz)                                                        |
//! |--------------------|----------------------|---------------------------------------------------------------------|
//! | `OFF`              | coast                | outputs open                                                        |
//! | `PASSIV_BRAKE`     | short                | both inputs high                                                    |
//! | `PWM`              | duty `t / 399`       | the duty as it is (sign = direction)                                |
//! | `MAV`              | velocity `t · rad/count` (t in counts/s) | speed PI(D) on the encoder speed → duty                   |
//! | `MTP`              | position `g · rad/count` under cap `\|t\| · rad/count` | trapezoid profile → position PID + feed-forward → speed PID → duty |
//!
//! In HOLD and STOP the ladder ramps velocity setpoints down and sets position caps to zero (the
//! profile decelerates and holds); in BRAKE every motor is shorted and every loop reset. The
//! comm-loss guarantee is the ladder's, whatever the modes: BRAKE at the profile's 49th tick after
//! the last valid transfer (`Config::PI_SPI`, SAFETY.md §4).
//!
//! # Servos ([`servo_outputs`])
//!
//! | condition                                   | pulses                 | 6 V rail |
//! |---------------------------------------------|------------------------|----------|
//! | shutdown bit `servos` in the last transfer  | none                   | off      |
//! | BRAKE (comm loss, ESTOP, motor shutdown)     | none (the servos' disabled state) | as the modes say |
//! | otherwise: `ENABLED`                         | `servoPos` µs          | on       |
//! | otherwise: `DISABLED` / `FULLY_DISABLED`     | none                   | off only if all four are `FULLY_DISABLED` |
//!
//! On comm loss a servo keeps its last valid position through HOLD and STOP (a position actuator
//! that holds is the least surprising thing while the wheels decelerate) and goes to its disabled
//! state at BRAKE, with the drive. Before the first valid transfer every servo is fully disabled.
//!
//! # Leaving BRAKE
//!
//! The seed has no enable message: the motor shutdown bit is it. A transfer with `motors` set is
//! enable 0 (BRAKE latched by `Shutdown`), and the first valid transfer with the bit clear after it
//! is the enable 0 → 1 edge, the ladder's explicit re-arm (SR-8); the board leaves BRAKE at the tick
//! after it. The Pi therefore starts every session with one shutdown transfer, and after a comm
//! loss sends one again: BRAKE is never left by transfers that merely resume.

use crate::cdc::{motor_outputs, MotorOutput};
use crate::imu::ImuFusion;
use crate::odometry::Odometry;
use crate::safety::Safety;
use crate::serial::{tick as serial_tick, SerialTickInputs};
use control::profile::{ProfileLimits, Trapezoid, Travel};
use control::{AntiWindup, Pid, PidGains, Q};
use protocol::pi_spi::{
    self as wire, assumed::MotorPidSettings, ImuData, RxBuffer, ServoMode, Shutdown, TxBuffer,
    UpdateFlags, RX_LEN, TRANSFER_LEN, TX_LEN,
};
use statemachine::{AxisDrive, Config, Drive, Duty, Event, Output, Position, RejectReason, Speed};

/// Motors of the seed 004 board.
pub const MOTORS: usize = 4;
/// Servos of the seed 004 board.
pub const SERVOS: usize = 4;
/// Watchdog tick and motor-loop rate, Hz.
pub const TICK_HZ: u32 = 1_000;
/// Encoder counts per wheel revolution (after ×4 decoding).
pub const COUNTS_PER_REV: u32 = 1_440;
/// Radians per encoder count, `2π / COUNTS_PER_REV`: the unit of `motorTarget` (counts/s in MAV,
/// counts in MTP) on the ladder's side.
pub const RAD_PER_COUNT: f32 = core::f32::consts::TAU / COUNTS_PER_REV as f32;
/// Ticks over which the speed is measured: 10 ms, 0.436 rad/s per count of difference.
pub const SPEED_WINDOW: usize = 10;
/// Shortest servo pulse the seed allows, timer ticks (µs).
pub const SERVO_MIN_US: u16 = 600;
/// Longest servo pulse the seed allows, timer ticks (µs).
pub const SERVO_MAX_US: u16 = 2_600;
/// An MTP motor is `done` within this many counts of its goal, at rest.
pub const DONE_TOLERANCE_COUNTS: i32 = 4;
/// The closed loops' duty limit: the full scale of the seed's PWM mode.
pub const DUTY_LIMIT: Q = Q::ONE;
/// Ticks between odometry updates (100 Hz).
pub const ODOMETRY_DIVIDER: u32 = 10;

/// Counts per second of one count of difference over the speed window.
const CPS_PER_DIFF: i32 = (TICK_HZ / SPEED_WINDOW as u32) as i32;

/// `2π · 65536`, rounded: Q16.16 bits of one revolution.
const REV_BITS: i64 = 411_775;

/// Encoder counts as a wheel angle, rad (Q16.16, saturating at the format's range).
pub fn rad_of_counts(counts: i32) -> Position {
    let bits = i64::from(counts)
        .saturating_mul(REV_BITS)
        .checked_div(i64::from(COUNTS_PER_REV))
        .unwrap_or(0);
    Position::from_bits(i32::try_from(bits).unwrap_or(if bits < 0 { i32::MIN } else { i32::MAX }))
}

/// The allowed ranges of gains received at run time, in the wire's units (per second, not per
/// sample). A set outside them is refused whole, counted, and never applied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GainBounds {
    /// Largest proportional gain.
    pub kp_max: f32,
    /// Largest integral gain, per second.
    pub ki_max: f32,
    /// Largest derivative gain, seconds.
    pub kd_max: f32,
    /// Output limit of the controller built from them.
    pub out_limit: Q,
    /// Integrator limit of the controller built from them.
    pub i_limit: Q,
}

/// Speed controller: error in rad/s → duty. Its output limit is the full duty scale.
pub const SPEED_BOUNDS: GainBounds = GainBounds {
    kp_max: 10.0,
    ki_max: 1_000.0,
    kd_max: 0.1,
    out_limit: DUTY_LIMIT,
    i_limit: DUTY_LIMIT,
};

/// Position controller: error in rad → speed correction in rad/s, at most 5 rad/s on top of the
/// profile's feed-forward (and never beyond the ladder's cap).
pub const POSITION_BOUNDS: GainBounds = GainBounds {
    kp_max: 100.0,
    ki_max: 1_000.0,
    kd_max: 1.0,
    out_limit: Q::lit("5"),
    i_limit: Q::lit("5"),
};

/// Why a gain set received at run time was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum GainError {
    /// A gain was NaN or infinite.
    NonFinite = 1,
    /// A gain was negative (positive feedback).
    Negative = 2,
    /// A gain was above its [`GainBounds`] maximum.
    TooLarge = 3,
    /// A nonzero gain is below the resolution of the per-sample fixed-point gain (it would be
    /// applied as zero).
    BelowResolution = 4,
}

/// One wire gain (`k` per `scale` seconds: 1 for kp, dt for ki, 1/dt for kd) as a per-sample
/// fixed-point gain, or why not.
fn gain(k: f32, max: f32, scale: f32) -> Result<Q, GainError> {
    if !k.is_finite() {
        return Err(GainError::NonFinite);
    }
    if k < 0.0 {
        return Err(GainError::Negative);
    }
    if k > max {
        return Err(GainError::TooLarge);
    }
    let q = Q::checked_from_num(k * scale).ok_or(GainError::TooLarge)?;
    if k > 0.0 && q == Q::ZERO {
        return Err(GainError::BelowResolution);
    }
    Ok(q)
}

/// A received gain set for all four motors as per-sample controller gains at [`TICK_HZ`], every
/// motor's checked against `b`; the set is taken whole or refused whole.
pub fn gains_from_wire(
    s: &MotorPidSettings,
    b: &GainBounds,
) -> Result<[PidGains; MOTORS], GainError> {
    const DT: f32 = 1.0 / TICK_HZ as f32;
    let mut out = [PidGains {
        kp: Q::ZERO,
        ki_dt: Q::ZERO,
        kd_dt: Q::ZERO,
        out_limit: b.out_limit,
        i_limit: b.i_limit,
        anti_windup: AntiWindup::Conditional,
    }; MOTORS];
    // By index (every `i` is below `MOTORS`): Kani models each step of a slice iterator as a
    // checked pointer offset, which a plain loop over the arrays does not need.
    #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
    for i in 0..MOTORS {
        out[i].kp = gain(s.kp[i], b.kp_max, 1.0)?;
        out[i].ki_dt = gain(s.ki[i], b.ki_max, DT)?;
        out[i].kd_dt = gain(s.kd[i], b.kd_max, 1.0 / DT)?;
    }
    Ok(out)
}

/// The board's tuning of the four motors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotorTuning {
    /// Speed controller at [`TICK_HZ`] (rad/s → duty).
    pub speed: PidGains,
    /// Position controller at [`TICK_HZ`] (rad → rad/s).
    pub position: PidGains,
}

/// The default gains of the seed 004 board's gearmotors (12 V, 1440 counts per wheel revolution,
/// no-load 30 rad/s at full duty): speed PI 0.03 duty per rad/s, 1.0 duty per rad (Ki·dt 0.001);
/// position P 8 rad/s per rad.
pub const TUNING: MotorTuning = MotorTuning {
    speed: PidGains {
        kp: Q::lit("0.03"),
        ki_dt: Q::lit("0.001"),
        kd_dt: Q::ZERO,
        out_limit: DUTY_LIMIT,
        i_limit: DUTY_LIMIT,
        anti_windup: AntiWindup::Conditional,
    },
    position: PidGains {
        kp: Q::lit("8"),
        ki_dt: Q::ZERO,
        kd_dt: Q::ZERO,
        out_limit: POSITION_BOUNDS.out_limit,
        i_limit: POSITION_BOUNDS.i_limit,
        anti_windup: AntiWindup::Conditional,
    },
};

/// One motor's loops: the speed estimate over [`SPEED_WINDOW`], the speed and position
/// controllers, and the MTP profile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotorLoop {
    history: [i32; SPEED_WINDOW],
    head: usize,
    speed_pid: Pid,
    pos_pid: Pid,
    profile: Trapezoid,
    closed: bool,
}

impl MotorLoop {
    fn new(t: &MotorTuning, travel: &Travel) -> Self {
        Self {
            history: [0; SPEED_WINDOW],
            head: 0,
            speed_pid: Pid::new(t.speed),
            pos_pid: Pid::new(t.position),
            profile: Trapezoid::new(Position::ZERO, travel),
            closed: false,
        }
    }

    /// Records this tick's count; returns the count difference over the window.
    fn sample(&mut self, count: i32) -> i32 {
        let slot = self.head % SPEED_WINDOW;
        let old = self.history.get(slot).copied().unwrap_or(count);
        if let Some(h) = self.history.get_mut(slot) {
            *h = count;
        }
        self.head = slot.wrapping_add(1) % SPEED_WINDOW;
        count.wrapping_sub(old)
    }

    /// The gains in force: [speed, position].
    pub const fn gains(&self) -> [PidGains; 2] {
        [*self.speed_pid.gains(), *self.pos_pid.gains()]
    }

    /// The controllers' state invariant (limits non-negative, integrators within them).
    pub const fn is_valid(&self) -> bool {
        self.speed_pid.is_valid() && self.pos_pid.is_valid()
    }

    /// One tick: the duty for a closed-loop axis (`None` for an open-loop one), from the measured
    /// speed and position. A loop entered anew starts from rest at the measurement.
    fn run(
        &mut self,
        axis: &AxisDrive,
        speed: Speed,
        pos: Position,
        lim: &ProfileLimits,
    ) -> Option<Duty> {
        let setpoint = match axis {
            AxisDrive::Velocity(v) => {
                self.enter(speed, pos, lim);
                *v
            }
            AxisDrive::Position { target, cap } => {
                self.enter(speed, pos, lim);
                let reference = self.profile.step(*target, *cap, lim);
                let correction = self.pos_pid.step(reference, pos);
                let limit = if *cap < Speed::ZERO {
                    Speed::ZERO
                } else {
                    *cap
                };
                let v = self.profile.velocity().saturating_add(correction);
                if v > limit {
                    limit
                } else if v < limit.saturating_neg() {
                    limit.saturating_neg()
                } else {
                    v
                }
            }
            AxisDrive::Coast | AxisDrive::Short | AxisDrive::Duty(_) => {
                self.closed = false;
                return None;
            }
        };
        Some(self.speed_pid.step(setpoint, speed))
    }

    fn enter(&mut self, speed: Speed, pos: Position, lim: &ProfileLimits) {
        if !self.closed {
            self.closed = true;
            self.speed_pid.reset(speed);
            self.pos_pid.reset(pos);
            self.profile = Trapezoid::new(pos, &lim.travel);
        }
    }

    /// True once an MTP axis's profile has reached `target` and the motor is within
    /// [`DONE_TOLERANCE_COUNTS`] of it.
    fn done(&self, target: Position, pos: Position, lim: &ProfileLimits) -> bool {
        let goal = lim.travel.clamp(target);
        let tol = rad_of_counts(DONE_TOLERANCE_COUNTS);
        self.closed
            && self.profile.position() == goal
            && self.profile.velocity() == Speed::ZERO
            && pos.saturating_sub(goal).abs() <= tol
    }
}

/// The last valid servo command and the servo shutdown bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServoCommand {
    /// Mode of each servo.
    pub modes: [ServoMode; SERVOS],
    /// Pulse of each servo, µs (600–2600 for an enabled servo).
    pub pulses_us: [u16; SERVOS],
    /// The last transfer's servo shutdown bit (from the raw bytes).
    pub shutdown: bool,
}

/// What the servo timer and the rail pin are told.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServoOutputs {
    /// The 6 V servo rail.
    pub rail_on: bool,
    /// Pulse per servo, µs; 0 = no pulse (the line held low).
    pub pulses_us: [u16; SERVOS],
}

impl ServoOutputs {
    /// Every servo off, rail cut.
    pub const OFF: Self = Self {
        rail_on: false,
        pulses_us: [0; SERVOS],
    };
}

/// The servo rules of the module documentation's table.
pub fn servo_outputs(braked: bool, cmd: &ServoCommand) -> ServoOutputs {
    if cmd.shutdown {
        return ServoOutputs::OFF;
    }
    let rail_on = cmd.modes.iter().any(|m| *m != ServoMode::FullyDisabled);
    let mut pulses_us = [0; SERVOS];
    if !braked {
        for ((p, m), pos) in pulses_us.iter_mut().zip(cmd.modes).zip(cmd.pulses_us) {
            if m == ServoMode::Enabled {
                *p = pos;
            }
        }
    }
    ServoOutputs { rail_on, pulses_us }
}

/// Counters of the one-shot updates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UpdateCounters {
    /// Gain sets applied (speed or position).
    pub gains_applied: u32,
    /// Gain sets refused ([`GainError`]).
    pub gains_refused: u32,
    /// The last refusal's reason.
    pub last_gain_error: Option<GainError>,
    /// Orientation updates refused.
    pub orientation_refused: u32,
    /// Kinematics updates refused.
    pub kinematics_refused: u32,
    /// `SAVE_IMU_CAL` requests (reserved by the seed: counted, nothing else).
    pub save_imu_cal: u32,
    /// Odometry resets.
    pub odom_resets: u32,
}

/// What one transfer decided; the caller carries it out before the handler returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TransferOutcome {
    /// The ladder's output after the transfer.
    pub out: Output<MOTORS>,
    /// Short every motor now (the ladder is in BRAKE: the shutdown bit, or a latch it confirmed).
    pub motors_off: bool,
    /// The servo outputs now (every servo off and the rail cut on the servo shutdown bit).
    pub servos: ServoOutputs,
    /// The buffer's checks passed and its command reached the ladder.
    pub accepted: bool,
}

/// What the tick reads from the board.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PiSpiTickInputs {
    /// ESTOP input change and supply.
    pub serial: SerialTickInputs,
    /// Cumulative encoder counts.
    pub counts: [i32; MOTORS],
    /// 12-bit ADC readings of the analog ports 0–5.
    pub analog: [i16; 6],
    /// 12-bit ADC reading of the battery.
    pub battery: i16,
}

/// What the tick decided; the caller writes it to the timers and pins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PiSpiTickOutcome {
    /// The ladder's output after the tick.
    pub out: Output<MOTORS>,
    /// Compare and IN1/IN2 of each motor (shorted in BRAKE or with an ESTOP press pending).
    pub motors: [MotorOutput; MOTORS],
    /// Servo pulses and rail.
    pub servos: ServoOutputs,
}

/// The seed 004 board application's state, shared by the SPI completion and the tick (both
/// priority 2) and written by the IMU task.
#[derive(Clone, Debug)]
pub struct PiSpiApp {
    loops: [MotorLoop; MOTORS],
    lim: ProfileLimits,
    servo: ServoCommand,
    odometry: Odometry,
    imu: ImuFusion,
    imu_data: ImuData,
    feedback: TxBuffer,
    updates: UpdateCounters,
    odom_div: u32,
    pending_odom_reset: bool,
    pwm_full: u16,
}

impl PiSpiApp {
    /// Power-on: every loop at rest, servos fully disabled, odometry unconfigured. `pwm_full` is
    /// the compare value of full duty on the board's motor timer.
    pub fn new(cfg: &Config, t: &MotorTuning, imu_hz: u32, pwm_full: u16) -> Self {
        let p = cfg.params();
        let travel = Travel {
            lo: p.travel_lo,
            hi: p.travel_hi,
        };
        let lim = ProfileLimits {
            travel,
            accel_step: p.max_cmd_step,
        };
        Self {
            loops: [MotorLoop::new(t, &travel); MOTORS],
            lim,
            servo: ServoCommand::default(),
            odometry: Odometry::new(),
            imu: ImuFusion::new(imu_hz),
            imu_data: ImuData::default(),
            feedback: TxBuffer::default(),
            updates: UpdateCounters::default(),
            odom_div: 0,
            pending_odom_reset: false,
            pwm_full,
        }
    }

    /// The motor loops.
    pub const fn loops(&self) -> &[MotorLoop; MOTORS] {
        &self.loops
    }

    /// The servo command in force.
    pub const fn servo(&self) -> &ServoCommand {
        &self.servo
    }

    /// The update counters.
    pub const fn updates(&self) -> &UpdateCounters {
        &self.updates
    }

    /// The odometry.
    pub const fn odometry(&self) -> &Odometry {
        &self.odometry
    }

    /// The IMU fusion.
    pub const fn imu(&self) -> &ImuFusion {
        &self.imu
    }

    /// The feedback the next transfer sends (without its time stamp and digital inputs).
    pub const fn feedback(&self) -> &TxBuffer {
        &self.feedback
    }

    /// One completed SPI transfer (the body of `spi_dma_done`): `rx` as received, `tx` the buffer
    /// the next transfer sends. Not inlined, for the budget report.
    #[inline(never)]
    pub fn on_transfer(
        &mut self,
        safety: &mut Safety<MOTORS>,
        rx: &[u8; TRANSFER_LEN],
        now_us: u32,
        digital: u16,
        tx: &mut [u8; TRANSFER_LEN],
    ) -> TransferOutcome {
        let (rx_bytes, _) = rx
            .split_first_chunk::<RX_LEN>()
            .unwrap_or((&[0; RX_LEN], &[]));
        let o = self.apply(
            safety,
            wire::shutdown_raw(rx_bytes),
            wire::decode_rx(rx_bytes),
        );
        self.write_feedback(now_us, digital, tx);
        o
    }

    /// What the task decides from one transfer, given the raw shutdown bits and the decode result:
    /// the shutdown bits first, then a refusal becomes `Event::Rejected`, a decoded buffer goes
    /// through the servo check and the ladder, then its one-shot updates. ([`Self::on_transfer`]
    /// then writes the next TxBuffer, which reads the board's state and changes none of it.) The
    /// proofs split `on_transfer` here: bytes → (bits, result) in the protocol crate, (bits,
    /// result) → board and ladder here.
    pub fn apply(
        &mut self,
        safety: &mut Safety<MOTORS>,
        raw: Shutdown,
        decoded: Result<RxBuffer, RejectReason>,
    ) -> TransferOutcome {
        // Step 0. A bit from any buffer can only stop things: it is set from the raw bytes, and
        // cleared only by a buffer that passed every check.
        self.servo.shutdown |= raw.servos;
        if raw.motors {
            safety.apply(Event::Shutdown(true));
        }
        let accepted = match decoded {
            Err(reason) => {
                safety.apply(Event::Rejected(reason));
                false
            }
            Ok(cmd) => self.take(safety, &cmd),
        };
        // (From the same bytes the decoded bit equals the raw one; held here whatever `decoded` is.)
        self.servo.shutdown |= raw.servos;
        let out = safety.output();
        TransferOutcome {
            out,
            motors_off: out.drive == Drive::Brake,
            servos: servo_outputs(out.drive == Drive::Brake, &self.servo),
            accepted,
        }
    }

    /// A transaction cut short (the chip select rose before the last byte; the link re-armed at a
    /// transfer boundary): counted as a framing refusal, nothing else changes. The body of
    /// `spi_nss_rise`.
    pub fn transfer_cut(&mut self, safety: &mut Safety<MOTORS>) -> Output<MOTORS> {
        safety.step(Event::Rejected(RejectReason::Framing))
    }

    /// A buffer that passed version, parity and decoding: the servo check, the ladder, then the
    /// one-shot updates. Returns whether the ladder took the command.
    fn take(&mut self, safety: &mut Safety<MOTORS>, cmd: &RxBuffer) -> bool {
        let servo_ok =
            cmd.servo_mode.iter().zip(cmd.servo_pos).all(|(m, p)| {
                *m != ServoMode::Enabled || (SERVO_MIN_US..=SERVO_MAX_US).contains(&p)
            });
        if !servo_ok {
            safety.apply(Event::Rejected(RejectReason::OutOfRange));
            return false;
        }
        let before = safety.ladder().counters().valid_frames;
        for e in cmd.to_events(RAD_PER_COUNT) {
            safety.apply(e);
        }
        if safety.ladder().counters().valid_frames == before {
            return false;
        }
        self.servo = ServoCommand {
            modes: cmd.servo_mode,
            pulses_us: cmd.servo_pos,
            shutdown: cmd.system_shutdown.servos,
        };
        self.apply_updates(cmd);
        true
    }

    fn apply_updates(&mut self, cmd: &RxBuffer) {
        let f = cmd.updates.0;
        for (flag, bounds, which) in [
            (UpdateFlags::MOTOR_PID_SPEED, &SPEED_BOUNDS, 0usize),
            (UpdateFlags::MOTOR_PID_POS, &POSITION_BOUNDS, 1),
        ] {
            if f & flag == 0 {
                continue;
            }
            match gains_from_wire(&cmd.motor_pid_settings, bounds) {
                Ok(g) => {
                    for (l, g) in self.loops.iter_mut().zip(g) {
                        let pid = if which == 0 {
                            &mut l.speed_pid
                        } else {
                            &mut l.pos_pid
                        };
                        *pid = Pid::new(g);
                    }
                    self.updates.gains_applied = self.updates.gains_applied.saturating_add(1);
                }
                Err(e) => {
                    self.updates.gains_refused = self.updates.gains_refused.saturating_add(1);
                    self.updates.last_gain_error = Some(e);
                }
            }
        }
        if f & UpdateFlags::IMU_ORIENTATION != 0
            && self
                .imu
                .set_orientation(cmd.imu_gyro_orientation, cmd.imu_compass_orientation)
                .is_err()
        {
            self.updates.orientation_refused = self.updates.orientation_refused.saturating_add(1);
        }
        if f & UpdateFlags::SAVE_IMU_CAL != 0 {
            self.updates.save_imu_cal = self.updates.save_imu_cal.saturating_add(1);
        }
        if f & UpdateFlags::KINEMATICS != 0 && self.odometry.configure(&cmd.kinematics).is_err() {
            self.updates.kinematics_refused = self.updates.kinematics_refused.saturating_add(1);
        }
        if f & UpdateFlags::ODOM_RESET != 0 {
            self.pending_odom_reset = true;
            self.updates.odom_resets = self.updates.odom_resets.saturating_add(1);
        }
    }

    fn write_feedback(&mut self, now_us: u32, digital: u16, tx: &mut [u8; TRANSFER_LEN]) {
        let fb = TxBuffer {
            update_time: now_us,
            digital_sensors: digital,
            imu: self.imu_data,
            ..self.feedback
        };
        let (head, rest) = tx.split_at_mut(TX_LEN);
        if let Ok(head) = <&mut [u8; TX_LEN]>::try_from(head) {
            wire::encode_tx(&fb, head);
        }
        rest.fill(0);
    }

    /// One watchdog tick (the body of `watchdog_tick`): the ladder's tick, then every motor's loop
    /// under its drive, the servos, and the feedback for the next transfer. `estop_pending`: an
    /// ESTOP press not yet latched ([`crate::EstopInput::press_pending`]) shorts the motors too.
    /// Not inlined, for the budget report.
    #[inline(never)]
    pub fn tick(
        &mut self,
        safety: &mut Safety<MOTORS>,
        estop_pending: bool,
        inputs: &PiSpiTickInputs,
    ) -> PiSpiTickOutcome {
        let out = serial_tick(safety, &inputs.serial);
        let braked = out.drive == Drive::Brake || estop_pending;
        let mut duties = [AxisDrive::Coast; MOTORS];
        let mut speeds_cps = [0i32; MOTORS];
        let mut done = 0u8;
        for (n, ((l, c), d)) in self
            .loops
            .iter_mut()
            .zip(inputs.counts)
            .zip(duties.iter_mut())
            .enumerate()
        {
            let diff = l.sample(c);
            // counts per window → counts per second (× TICK_HZ / SPEED_WINDOW = × 100).
            let cps = diff.saturating_mul(CPS_PER_DIFF);
            if let Some(s) = speeds_cps.get_mut(n) {
                *s = cps;
            }
            let speed = rad_of_counts(cps);
            let pos = rad_of_counts(c);
            let axis = match out.drive {
                Drive::Run(axes) if !braked => axes.get(n).copied().unwrap_or(AxisDrive::Coast),
                _ => AxisDrive::Short,
            };
            *d = match l.run(&axis, speed, pos, &self.lim) {
                Some(duty) => AxisDrive::Duty(duty),
                None => axis,
            };
            if let AxisDrive::Position { target, .. } = axis {
                if l.done(target, pos, &self.lim) {
                    done |= 1 << n;
                }
            }
        }
        let motors = if braked {
            motor_outputs(&Drive::Brake, self.pwm_full)
        } else {
            motor_outputs(&Drive::Run(duties), self.pwm_full)
        };
        self.odom_div = self.odom_div.wrapping_add(1);
        if self.odom_div >= ODOMETRY_DIVIDER {
            self.odom_div = 0;
            if core::mem::take(&mut self.pending_odom_reset) {
                self.odometry.reset();
            }
            const DT: f32 = ODOMETRY_DIVIDER as f32 / TICK_HZ as f32;
            self.feedback.odometry = self.odometry.update(inputs.counts, DT);
        }
        self.feedback.motor = wire::MotorData {
            bemf: speeds_cps,
            position: inputs.counts,
            done,
        };
        self.feedback.analog_sensor = inputs.analog;
        self.feedback.battery_voltage = inputs.battery;
        PiSpiTickOutcome {
            out,
            motors,
            servos: servo_outputs(out.drive == Drive::Brake, &self.servo),
        }
    }

    /// One IMU period (the body of `imu_read`): a reading, or `None` if the sensor did not answer.
    pub fn imu_sample(&mut self, raw: Option<([i16; 3], [i16; 3], i16)>) {
        self.imu_data = match raw {
            Some((accel, gyro, temp)) => self.imu.update(accel, gyro, temp),
            None => self.imu.sensor_lost(),
        };
    }
}

/// The motor shutdown bit of any buffer, as the SPI handler sees it (re-exported for the
/// simulator's checks).
pub fn shutdown_of(rx: &[u8; TRANSFER_LEN]) -> Shutdown {
    match rx.split_first_chunk::<RX_LEN>() {
        Some((b, _)) => wire::shutdown_raw(b),
        None => Shutdown::default(),
    }
}

#[cfg(test)]
mod tests;
