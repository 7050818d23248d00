//! The seed 001 board application (`cdc` profile): four open-loop PWM motors, the `AA 55` link
//! over USB CDC or a UART, STATUS, ACK and the MPU6050's raw readings.
//!
//! ```text
//!  task (priority, rate)          body                          what it does
//!  link_rx       (2, per byte)    CdcLinkTask::on_byte          byte → frame → ladder event → ACK / STATUS queued
//!                                 outputs_after_frame           a frame that braked: every motor shorted at once
//!  watchdog_tick (2, 1 kHz)       serial::tick, motor_outputs   ESTOP, supply → tick → CCR and IN1/IN2 per motor
//!                                 CdcLinkTask::periodic         STATUS every STATUS_PERIOD_TICKS
//!  imu_read      (1, 100 Hz)      imu_from_raw, send_imu        MPU6050 registers → IMU_MPU6050 frame
//! ```
//!
//! # What each message does (the seed's §3, on the safety core)
//!
//! | received        | ladder event ([`protocol::cdc::Message::to_event`])   | reply                     |
//! |-----------------|--------------------------------------------------------|---------------------------|
//! | `SET_MOTOR_PWM` | four duty/coast axes, `timeout_ms` as the comm-loss threshold | none (the seed: no ACK for the 50 Hz frame) |
//! | `MOTOR_ENABLE 1`| a frame of four coasting axes with enable 0, then `Rearm(Primary)`; the following `SET_MOTOR_PWM` frames drive | `ACK(0x02, 0)` if the re-arm was taken, else `ACK(0x02, 1)` |
//! | `MOTOR_ENABLE 0`| a frame of four coasting axes with enable 0 (STOP); until `MOTOR_ENABLE 1`, `SET_MOTOR_PWM` frames keep the link alive with every motor at 0 (the seed: outputs forced to 0) | `ACK(0x02, 0)` / `(0x02, 1)` |
//! | `ESTOP 1`       | `Estop(Primary, Engage)`: BRAKE latched at once          | `ACK(0x03, 0)`            |
//! | `ESTOP 0`       | `Estop(Primary, Release)`: releases the link's own ESTOP; the drive stays braked until `MOTOR_ENABLE 1` | `ACK(0x03, 0)`, or `(0x03, 1)` if refused |
//! | `PING`          | none                                                   | a `STATUS` at once        |
//! | a refused frame, or a message only the MCU sends | `Rejected(reason)` (counted; nothing else changes) | reported in the next STATUS `err` |
//!
//! The seed's `MOTOR_ENABLE`: "0 = disabled (outputs forced to 0), 1 = enabled (lets
//! `SET_MOTOR_PWM` take effect)". The disable therefore lasts until the next `MOTOR_ENABLE 1`,
//! not until the next 50 Hz frame. Power-on counts as disabled; the drive is braked then anyway.
//!
//! Why `MOTOR_ENABLE 1` carries a coasting frame: the ladder leaves BRAKE at a tick after the
//! re-arm only with a valid enabled frame since the previous tick, and while no frame arrives its
//! comm-loss check re-latches BRAKE every tick, which withdraws a pending re-arm. The host sends
//! `MOTOR_ENABLE 1`, waits for the ACK, then starts its 50 Hz frames: the coasting frame (a valid
//! frame, every motor at 0) restarts the link's age, so the re-arm waits for the first
//! `SET_MOTOR_PWM` for up to the profile's BRAKE threshold (249 ms), and no longer: a re-arm is
//! never kept for a later session. The enable 0 → 1 edge between that frame and the first
//! `SET_MOTOR_PWM` is the ladder's explicit re-arm as well (SR-8).
//!
//! ACK `result`: [`ACK_OK`] when the event took effect, [`ACK_REFUSED`] when the safety core
//! refused it (a latching cause still active, an ESTOP owned by another source, an invalid frame).
//!
//! # Motor outputs (TB6612-style driver: IN1, IN2 and a PWM input per motor)
//!
//! | drive of the axis          | CCR                         | IN1 | IN2 | bridge            |
//! |----------------------------|-----------------------------|-----|-----|-------------------|
//! | duty d > 0                 | round(d · ARR)              | 1   | 0   | forward           |
//! | duty d < 0                 | round(\|d\| · ARR)          | 0   | 1   | reverse           |
//! | coast, or duty 0           | 0                           | 0   | 0   | outputs open (the seed's pwm = 0) |
//! | short, and every axis in BRAKE | ARR                     | 1   | 1   | short brake       |

use crate::safety::Safety;
use crate::serial::TxQueue;
use protocol::cdc::{
    self, Ack, ErrorCode, Imu, Message, MsgId, Status, StatusFlags, StreamDecoder,
};
use statemachine::{
    AxisCommand, AxisDrive, Command, Drive, Event, FaultFlags, Mode, Output, Source,
};

/// Motors of the seed 001 board (TIM8 CH1 … CH4).
pub const MOTORS: usize = 4;
/// Transmit queue: a STATUS (16 B) and ten IMU frames (26 B) with room to spare.
pub const TX_CAP: usize = 512;
/// STATUS period, ticks (10 Hz: the seed's "low rate").
pub const STATUS_PERIOD_TICKS: u32 = 100;
/// ACK result: the command took effect.
pub const ACK_OK: u8 = 0;
/// ACK result: the safety core refused the command (see the module documentation).
pub const ACK_REFUSED: u8 = 1;

/// What the board measured, for STATUS.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BoardStatus {
    /// Milliseconds since power-on.
    pub t_ms: u32,
    /// Battery voltage, mV (0 if not measured).
    pub vbat_mv: u16,
    /// The MPU6050 answered its last read.
    pub imu_ok: bool,
}

/// The link task's state: the stream decoder, the replies waiting for the transmitter, and the
/// error the next STATUS reports.
#[derive(Clone, Debug)]
pub struct CdcLinkTask {
    dec: StreamDecoder,
    /// Replies waiting for the transmitter.
    pub tx: TxQueue<TX_CAP>,
    last_error: Option<ErrorCode>,
    status_due: u32,
    /// The host's last `MOTOR_ENABLE` (false from power-on until the first `MOTOR_ENABLE 1`).
    enabled: bool,
}

impl Default for CdcLinkTask {
    fn default() -> Self {
        Self::new()
    }
}

impl CdcLinkTask {
    /// Before the first byte.
    pub const fn new() -> Self {
        Self {
            dec: StreamDecoder::new(),
            tx: TxQueue::new(),
            last_error: None,
            status_due: 0,
            enabled: false,
        }
    }

    /// The stream decoder's counters.
    pub const fn stats(&self) -> cdc::Stats {
        self.dec.stats()
    }

    /// True between a `MOTOR_ENABLE 1` and the next `MOTOR_ENABLE 0`: `SET_MOTOR_PWM` drives.
    pub const fn motors_enabled(&self) -> bool {
        self.enabled
    }

    /// One received byte (the body of `link_rx`). Returns the ladder's output if the byte
    /// completed a frame that reached the ladder. Not inlined, for the budget report.
    #[inline(never)]
    pub fn on_byte(
        &mut self,
        safety: &mut Safety<MOTORS>,
        byte: u8,
        st: &BoardStatus,
    ) -> Option<Output<MOTORS>> {
        let decoded = self.dec.push(byte)?;
        self.on_decoded(safety, decoded, st)
    }

    /// What the stream decoder delivered at a frame's last byte, applied: a message to the ladder
    /// (and its ACK or STATUS to the queue), a refusal counted. The second half of
    /// [`Self::on_byte`], split off so that the board's half of an ESTOP frame is proven on its own
    /// (P-17); the decoder's half is the protocol crate's.
    pub fn on_decoded(
        &mut self,
        safety: &mut Safety<MOTORS>,
        decoded: Result<Message, cdc::Error>,
        st: &BoardStatus,
    ) -> Option<Output<MOTORS>> {
        match decoded {
            Err(e) => Some(self.refuse(safety, e)),
            Ok(Message::Ping) => {
                self.send_status(safety, st);
                None
            }
            Ok(m @ Message::MotorEnable(on)) => {
                self.enabled = on;
                let before = *safety.ladder().counters();
                let mut out = safety.step(Event::Frame(coasting(None)));
                if on {
                    out = safety.step(Event::Rearm(Source::Primary));
                }
                let ok = took_effect(&m, safety, &before);
                self.ack(m.id(), ok);
                Some(out)
            }
            Ok(m @ Message::Estop(_)) => {
                let event = m.to_event()?;
                let before = *safety.ladder().counters();
                let out = safety.step(event);
                let ok = took_effect(&m, safety, &before);
                self.ack(m.id(), ok);
                Some(out)
            }
            Ok(Message::SetMotorPwm(p)) => {
                let cmd = p.to_command();
                let cmd = if self.enabled {
                    cmd
                } else {
                    coasting(cmd.timeout)
                };
                Some(safety.step(Event::Frame(cmd)))
            }
            // Messages only the MCU sends: a host that sends them is confused.
            Ok(Message::Ack(_) | Message::Imu(_) | Message::Status(_)) => {
                Some(self.refuse(safety, cdc::Error::UnknownMsg))
            }
        }
    }

    /// A refused frame: counted by the ladder, reported by the next STATUS.
    fn refuse(&mut self, safety: &mut Safety<MOTORS>, e: cdc::Error) -> Output<MOTORS> {
        self.last_error = Some(e.error_code());
        safety.step(Event::Rejected(e.reason()))
    }

    fn ack(&mut self, id: MsgId, ok: bool) {
        let a = Ack {
            msg_id: id as u8,
            result: if ok { ACK_OK } else { ACK_REFUSED },
        };
        self.send(&Message::Ack(a));
    }

    fn send(&mut self, m: &Message) {
        let mut buf = [0u8; cdc::MAX_FRAME_LEN];
        let n = m.encode(&mut buf);
        self.tx.push_frame(buf.get(..n).unwrap_or(&[]));
    }

    /// The STATUS the board reports now (the seed's §3.2 flags and error codes).
    pub fn status(&self, safety: &Safety<MOTORS>, st: &BoardStatus) -> Status {
        let l = safety.ladder();
        let faults = l.faults();
        let mut flags = 0;
        if self.enabled && l.mode() != Mode::Brake {
            flags |= StatusFlags::MOTOR_ENABLED;
        }
        if faults.contains(FaultFlags::ESTOP) {
            flags |= StatusFlags::ESTOP_LATCHED;
        }
        if faults.contains(FaultFlags::COMM_LOST) {
            flags |= StatusFlags::CMD_TIMEOUT;
        }
        if st.imu_ok {
            flags |= StatusFlags::IMU_OK;
        }
        let err = if st.imu_ok {
            self.last_error.unwrap_or(ErrorCode::Ok)
        } else {
            ErrorCode::ImuFail
        };
        Status {
            t_ms: st.t_ms,
            vbat_mv: st.vbat_mv,
            flags: StatusFlags(flags),
            err: err as u16,
        }
    }

    /// Queues a STATUS; the protocol error it reports is then cleared.
    pub fn send_status(&mut self, safety: &Safety<MOTORS>, st: &BoardStatus) {
        let s = self.status(safety, st);
        self.send(&Message::Status(s));
        self.last_error = None;
    }

    /// Called every tick: queues a STATUS every [`STATUS_PERIOD_TICKS`].
    pub fn periodic(&mut self, safety: &Safety<MOTORS>, st: &BoardStatus) {
        self.status_due = self.status_due.saturating_add(1);
        if self.status_due >= STATUS_PERIOD_TICKS {
            self.status_due = 0;
            self.send_status(safety, st);
        }
    }

    /// Queues an `IMU_MPU6050` frame.
    pub fn send_imu(&mut self, imu: &Imu) {
        self.send(&Message::Imu(*imu));
    }
}

/// Every motor coasting, enable 0: what the board applies while disabled (the seed's outputs
/// forced to 0), with the frame's comm-loss threshold.
fn coasting(timeout: Option<u16>) -> Command<MOTORS> {
    Command {
        timeout,
        ..Command::uniform(AxisCommand::COAST, false, None)
    }
}

/// Whether `MOTOR_ENABLE` or `ESTOP` took effect, from the ladder after the step.
fn took_effect(m: &Message, safety: &Safety<MOTORS>, before: &statemachine::Counters) -> bool {
    let l = safety.ladder();
    let primary = Source::Primary.bit();
    match m {
        // The re-arm is pending (BRAKE is left at the next tick after a fresh enabled frame) or
        // there was nothing to re-arm: refused only when the ladder counted a refusal.
        Message::MotorEnable(true) => l.counters().rearm_refused == before.rearm_refused,
        Message::MotorEnable(false) => l.counters().valid_frames != before.valid_frames,
        // (`MOTOR_ENABLE 1` also needs its coasting frame taken, which the ladder always does:
        // it is valid in every state.)
        Message::Estop(statemachine::Estop::Engage) => l.estop_owners() & primary != 0,
        Message::Estop(statemachine::Estop::Release) => l.estop_owners() & primary == 0,
        _ => false,
    }
}

/// One motor's driver inputs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MotorOutput {
    /// Compare value of its TIM8 channel, 0 ..= ARR.
    pub ccr: u16,
    /// IN1.
    pub in1: bool,
    /// IN2.
    pub in2: bool,
}

impl MotorOutput {
    /// Outputs open: no torque.
    pub const COAST: Self = Self {
        ccr: 0,
        in1: false,
        in2: false,
    };

    /// Both inputs high: short brake.
    pub const fn short(arr: u16) -> Self {
        Self {
            ccr: arr,
            in1: true,
            in2: true,
        }
    }

    /// The signed duty the motor sees, −1 ..= 1 (0 when coasting or shorted).
    pub fn duty(&self, arr: u16) -> f32 {
        let mag = f32::from(self.ccr) / f32::from(arr.max(1));
        match (self.in1, self.in2) {
            (true, false) => mag,
            (false, true) => -mag,
            _ => 0.0,
        }
    }
}

/// The drive stage of the seed 001 board: the ladder's drive as each motor's CCR and IN1/IN2
/// (see the module documentation's table). Every axis is shorted in BRAKE. A duty's magnitude
/// is at most 1 (the ladder's duty limit), so the CCR never exceeds ARR; it is limited to ARR
/// anyway.
pub fn motor_outputs(drive: &Drive<MOTORS>, arr: u16) -> [MotorOutput; MOTORS] {
    match drive {
        Drive::Brake => [MotorOutput::short(arr); MOTORS],
        Drive::Run(axes) => axes.map(|a| match a {
            AxisDrive::Duty(d) => {
                let scaled = d.saturating_mul_int(i32::from(arr));
                let ccr = u16::try_from(scaled.unsigned_abs().round().to_num::<u32>())
                    .unwrap_or(arr)
                    .min(arr);
                if ccr == 0 {
                    MotorOutput::COAST
                } else {
                    MotorOutput {
                        ccr,
                        in1: d.is_positive(),
                        in2: d.is_negative(),
                    }
                }
            }
            AxisDrive::Short => MotorOutput::short(arr),
            AxisDrive::Coast | AxisDrive::Velocity(_) | AxisDrive::Position { .. } => {
                MotorOutput::COAST
            }
        }),
    }
}

/// What `link_rx` writes to the motors after a frame reached the ladder: every motor shorted if
/// the frame braked it (an `ESTOP 1`: "电机立刻 0", the motors at once, not at the next tick),
/// nothing otherwise (a frame never moves the drive; the tick applies the rest).
pub fn outputs_after_frame(out: &Output<MOTORS>, arr: u16) -> Option<[MotorOutput; MOTORS]> {
    matches!(out.drive, Drive::Brake).then_some([MotorOutput::short(arr); MOTORS])
}

/// Full-scale settings of the MPU6050 as the board programs them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImuScale {
    /// Accelerometer LSB per g (±2 g: 16 384).
    pub accel_lsb_per_g: i32,
    /// Gyroscope LSB per 10 dps (±250 dps: 1310, i.e. 131 LSB/dps).
    pub gyro_lsb_per_10dps: i32,
}

/// The board's setting: ±2 g, ±250 dps (the MPU6050's reset values).
pub const IMU_SCALE: ImuScale = ImuScale {
    accel_lsb_per_g: 16_384,
    gyro_lsb_per_10dps: 1310,
};

/// The MPU6050's raw registers (ACCEL_XOUT_H … GYRO_ZOUT_L) in the seed's units. Returns the
/// message and whether any field saturated: the seed's i16 mdps covers only ±32.767 dps, so a
/// faster rotation is reported at the limit and flagged (the caller counts it), never wrapped.
pub fn imu_from_raw(
    t_ms: u32,
    accel: [i16; 3],
    temp: i16,
    gyro: [i16; 3],
    s: &ImuScale,
) -> (Imu, bool) {
    let mut saturated = false;
    let mut conv = |raw: i16, num: i32, den: i32| -> i16 {
        let v = i32::from(raw)
            .saturating_mul(num)
            .checked_div(den)
            .unwrap_or(0);
        let c = v.clamp(i32::from(i16::MIN), i32::from(i16::MAX));
        saturated |= c != v;
        i16::try_from(c).unwrap_or(0)
    };
    let accel_mg = accel.map(|a| conv(a, 1000, s.accel_lsb_per_g));
    let gyro_mdps = gyro.map(|g| conv(g, 10_000, s.gyro_lsb_per_10dps));
    // Datasheet: T (°C) = raw / 340 + 36.53, so 0.01 °C = raw · 100 / 340 + 3653.
    let temp_cdeg = conv(temp, 100, 340).saturating_add(3653);
    (
        Imu {
            t_ms,
            accel_mg,
            gyro_mdps,
            temp_cdeg,
        },
        saturated,
    )
}

#[cfg(test)]
mod tests;
