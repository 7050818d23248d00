//! Seed 004: the Raspberry Pi ↔ STM32 SPI2 packed buffers `TxBuffer` / `RxBuffer` at TRANSFER_VERSION 15.
//!
//! Every transaction is a full-duplex exchange of [`TRANSFER_LEN`] bytes (the larger of the two
//! buffers): the Pi sends an [`RxBuffer`] while it receives a [`TxBuffer`] (the first [`TX_LEN`]
//! bytes). Both are packed little-endian C structs with no framing and no checksum: the only
//! integrity checks are the version byte and the parity bit of `updates`. Encoding and decoding
//! are explicit byte offsets (no transmutes).
//!
//! # TxBuffer (STM32 → Pi), 167 bytes
//!
//! ```text
//!  off  size  field
//!    0    1   u8   transferVersion (= 15)
//!    1    4   u32  updateTime (µs, TIM6)
//!    5   16   i32  motor.bemf[4]
//!   21   16   i32  motor.position[4]
//!   37    1   u8   motor.done (bit n: motor n reached its goal)
//!   38   12   i16  analogSensor[6]
//!   50    2   i16  batteryVoltage
//!   52    2   u16  digitalSensors (bits 0–9 DIN0–9, bit 10 button)
//!   54   13   SensorData imu.gyro             ┐
//!   67   13   SensorData imu.accel            │
//!   80   13   SensorData imu.compass          │ layouts of SensorData and
//!   93   13   SensorData imu.linearAccel      │ QuaternionData: see `assumed`
//!  106   13   SensorData imu.accelVelocity    │
//!  119   16   QuaternionData imu.dmpQuat      ┘
//!  135    4   f32  imu.heading (deg)
//!  139    4   f32  imu.temperature (°C)
//!  143   24   f32  odometry pos_x, pos_y, heading, vx, vy, wz
//! ```
//!
//! # RxBuffer (Pi → STM32), 179 bytes
//!
//! ```text
//!  off  size  field
//!    0    1   u8   transferVersion (= 15)
//!    1    4   u32  updates: bits 0–5 one-shot flags, bit 7 parity, others zero
//!    5    1   u8   systemShutdown: bit 0 servos off, bit 1 motors off
//!    6    2   u16  motorControlMode: 3 bits per motor, motor n in bits 3n+2..3n
//!    8   16   i32  motorTarget[4]
//!   24   16   i32  motorGoalPosition[4]
//!   40    1   u8   servoMode: 2 bits per servo, servo n in bits 2n+1..2n
//!   41    8   u16  servoPos[4] (timer ticks, 600–2600)
//!   49   48   MotorPidSettings     (layout: see `assumed`)
//!   97    9   i8   imuGyroOrientation[9] (row-major 3×3)
//!  106    9   i8   imuCompassOrientation[9]
//!  115   64   KinematicsConfig     (layout: see `assumed`)
//! ```
//!
//! # Checks, in order ([`decode_rx`])
//!
//! 1. `transferVersion` ≠ 15 → [`RejectReason::Version`] (the seed ignores the commands).
//! 2. Parity: the number of set bits in the 32-bit `updates` word must be odd (bit 7 is set exactly
//!    when bits 0–6 hold an even number of ones) → [`RejectReason::Parity`]. The seed only drops the
//!    update flags on a parity error; with no CRC on this link a wrong parity is the only sign of a
//!    corrupted transfer, so this decoder refuses the whole buffer.
//! 3. Undefined values (motor mode 5–7, servo mode 3, reserved bits in `updates`, `systemShutdown`
//!    or `motorControlMode`) → [`RejectReason::Decode`].
//!
//! The shutdown bits are the seed's "primary hardware safety interlock", acted on in the SPI
//! interrupt. [`shutdown_raw`] reads them from any buffer, valid or not: acting on a possibly
//! corrupted shutdown bit can only stop the motors, so the fail-safe path does not wait for the checks.

pub mod assumed;

use crate::le;
use assumed::{KinematicsConfig, MotorPidSettings, Packed, QuaternionData, SensorData};
use statemachine::{AxisCommand, Command, Event, RejectReason};

/// Full scale of `motorTarget` in `PWM` mode (the seed: duty 0–399).
pub const PWM_MAX: u16 = 399;

/// The shared header's `TRANSFER_VERSION`.
pub const TRANSFER_VERSION: u8 = 15;

/// Packed size of `MotorData`.
pub const MOTOR_DATA_LEN: usize = 16 + 16 + 1;
/// Packed size of `ImuData`.
pub const IMU_DATA_LEN: usize = 5 * SensorData::LEN + QuaternionData::LEN + 4 + 4;
/// Packed size of `OdometryData`.
pub const ODOMETRY_LEN: usize = 6 * 4;
/// Packed size of `TxBuffer`.
pub const TX_LEN: usize = 1 + 4 + MOTOR_DATA_LEN + 12 + 2 + 2 + IMU_DATA_LEN + ODOMETRY_LEN;
/// Packed size of `RxBuffer`.
pub const RX_LEN: usize =
    1 + 4 + 1 + 2 + 16 + 16 + 1 + 8 + MotorPidSettings::LEN + 9 + 9 + KinematicsConfig::LEN;
/// Bytes per SPI transaction (`BUFFER_LENGTH_DUPLEX_COMMUNICATION`): the larger buffer.
pub const TRANSFER_LEN: usize = if TX_LEN > RX_LEN { TX_LEN } else { RX_LEN };

/// Offset of `RxBuffer.updates`.
pub const RX_UPDATES_OFFSET: usize = 1;
/// Offset of `RxBuffer.systemShutdown`.
pub const RX_SHUTDOWN_OFFSET: usize = 5;
/// Offset of `RxBuffer.motorPidSettings`.
pub const RX_PID_OFFSET: usize = 49;
/// Offset of `RxBuffer.kinematics`.
pub const RX_KINEMATICS_OFFSET: usize = 115;
/// Offset of `TxBuffer.imu`.
pub const TX_IMU_OFFSET: usize = 54;
/// Offset of `TxBuffer.odometry`.
pub const TX_ODOMETRY_OFFSET: usize = 143;

// The offsets drawn in the module documentation, checked against the field sizes.
const _: () = assert!(TX_LEN == 167 && RX_LEN == 179 && TRANSFER_LEN == 179);
const _: () = assert!(TX_IMU_OFFSET == 1 + 4 + MOTOR_DATA_LEN + 12 + 2 + 2);
const _: () = assert!(TX_ODOMETRY_OFFSET == TX_IMU_OFFSET + IMU_DATA_LEN);
const _: () = assert!(RX_PID_OFFSET == 1 + 4 + 1 + 2 + 16 + 16 + 1 + 8);
const _: () = assert!(RX_KINEMATICS_OFFSET == RX_PID_OFFSET + MotorPidSettings::LEN + 9 + 9);

/// One-shot update flags of `RxBuffer.updates` (bits 0–5; the parity bit 7 is added by the encoder).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(transparent)
)]
pub struct UpdateFlags(pub u8);

impl UpdateFlags {
    /// Copy `motorPidSettings` into the velocity PID controllers.
    pub const MOTOR_PID_SPEED: u8 = 1 << 0;
    /// Copy `motorPidSettings` into the position PID controllers.
    pub const MOTOR_PID_POS: u8 = 1 << 1;
    /// Apply new gyro/compass orientation matrices.
    pub const IMU_ORIENTATION: u8 = 1 << 2;
    /// Save the IMU calibration (reserved by the seed).
    pub const SAVE_IMU_CAL: u8 = 1 << 3;
    /// Load a new `KinematicsConfig`.
    pub const KINEMATICS: u8 = 1 << 4;
    /// Reset the odometry accumulators.
    pub const ODOM_RESET: u8 = 1 << 5;
    /// Every defined flag.
    pub const ALL: u8 = 0x3F;
    /// The parity bit of the `updates` word.
    pub const PARITY_BIT: u32 = 1 << 7;
}

/// True if `updates` has odd parity (an odd number of set bits), the seed's validity rule.
pub const fn parity_ok(updates: u32) -> bool {
    updates.count_ones() & 1 == 1
}

/// The `updates` word for `flags`: bit 7 set exactly when the flags hold an even number of ones.
pub const fn updates_word(flags: UpdateFlags) -> u32 {
    let bits = (flags.0 & UpdateFlags::ALL) as u32;
    if bits.count_ones() & 1 == 0 {
        bits | UpdateFlags::PARITY_BIT
    } else {
        bits
    }
}

/// `RxBuffer.systemShutdown`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Shutdown {
    /// Bit 0 (`SHUTDOWN_SERVO`): disable the servos.
    pub servos: bool,
    /// Bit 1 (`SHUTDOWN_MOTOR`): force the motors off.
    pub motors: bool,
}

impl Shutdown {
    /// The byte on the wire.
    pub const fn to_byte(self) -> u8 {
        (self.servos as u8) | ((self.motors as u8) << 1)
    }
}

/// Reads the shutdown bits of a received buffer without any other check (see the module docs):
/// the fail-safe path for the SPI interrupt.
pub const fn shutdown_raw(buf: &[u8; RX_LEN]) -> Shutdown {
    let b = buf[RX_SHUTDOWN_OFFSET];
    Shutdown {
        servos: b & 1 != 0,
        motors: b & 2 != 0,
    }
}

/// Motor control modes (3 bits per motor). Values fixed by the seed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum MotorMode {
    /// PWM off, H-bridge low (coast).
    #[default]
    Off = 0,
    /// Both H-bridge pins high (short brake).
    PassiveBrake = 1,
    /// Direct duty cycle, `motorTarget` 0–399.
    Pwm = 2,
    /// Velocity PID, `motorTarget` is the BEMF-tick velocity setpoint.
    Mav = 3,
    /// Position PID to `motorGoalPosition`, `motorTarget` caps the speed.
    Mtp = 4,
}

impl MotorMode {
    /// Maps a 3-bit value, `None` for 5–7.
    pub const fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            0 => Some(Self::Off),
            1 => Some(Self::PassiveBrake),
            2 => Some(Self::Pwm),
            3 => Some(Self::Mav),
            4 => Some(Self::Mtp),
            _ => None,
        }
    }
}

/// Servo modes (2 bits per servo). Values fixed by the seed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum ServoMode {
    /// PWM stopped; the 6 V rail is cut if all four servos are fully disabled.
    #[default]
    FullyDisabled = 0,
    /// PWM stopped, 6 V rail on.
    Disabled = 1,
    /// PWM active at `servoPos`.
    Enabled = 2,
}

impl ServoMode {
    /// Maps a 2-bit value, `None` for 3.
    pub const fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            0 => Some(Self::FullyDisabled),
            1 => Some(Self::Disabled),
            2 => Some(Self::Enabled),
            _ => None,
        }
    }
}

/// Packs four motor modes: motor n in bits 3n+2..3n.
pub const fn pack_motor_modes(modes: [MotorMode; 4]) -> u16 {
    (modes[0] as u16)
        | ((modes[1] as u16) << 3)
        | ((modes[2] as u16) << 6)
        | ((modes[3] as u16) << 9)
}

/// Unpacks `motorControlMode`; `None` if a mode is 5–7 or a reserved bit (12–15) is set.
pub const fn unpack_motor_modes(word: u16) -> Option<[MotorMode; 4]> {
    if word >> 12 != 0 {
        return None;
    }
    match (
        MotorMode::from_raw((word & 0b111) as u8),
        MotorMode::from_raw(((word >> 3) & 0b111) as u8),
        MotorMode::from_raw(((word >> 6) & 0b111) as u8),
        MotorMode::from_raw(((word >> 9) & 0b111) as u8),
    ) {
        (Some(a), Some(b), Some(c), Some(d)) => Some([a, b, c, d]),
        _ => None,
    }
}

/// Packs four servo modes: servo n in bits 2n+1..2n.
pub const fn pack_servo_modes(modes: [ServoMode; 4]) -> u8 {
    (modes[0] as u8) | ((modes[1] as u8) << 2) | ((modes[2] as u8) << 4) | ((modes[3] as u8) << 6)
}

/// Unpacks `servoMode`; `None` if a servo mode is 3.
pub const fn unpack_servo_modes(byte: u8) -> Option<[ServoMode; 4]> {
    match (
        ServoMode::from_raw(byte & 0b11),
        ServoMode::from_raw((byte >> 2) & 0b11),
        ServoMode::from_raw((byte >> 4) & 0b11),
        ServoMode::from_raw((byte >> 6) & 0b11),
    ) {
        (Some(a), Some(b), Some(c), Some(d)) => Some([a, b, c, d]),
        _ => None,
    }
}

/// `MotorData`: BEMF readings, positions, done flags.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct MotorData {
    /// Filtered instantaneous BEMF.
    pub bemf: [i32; 4],
    /// Accumulated BEMF ticks.
    pub position: [i32; 4],
    /// Bit n: motor n reached its position goal.
    pub done: u8,
}

/// `ImuData`: the IMU fusion output.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct ImuData {
    /// World-frame angular velocity.
    pub gyro: SensorData,
    /// World-frame acceleration (m/s²).
    pub accel: SensorData,
    /// Raw magnetometer counts.
    pub compass: SensorData,
    /// Linear acceleration, gravity removed.
    pub linear_accel: SensorData,
    /// Integrated linear velocity (experimental).
    pub accel_velocity: SensorData,
    /// DMP quaternion.
    pub dmp_quat: QuaternionData,
    /// Heading in degrees, 0–360 clockwise from north.
    pub heading: f32,
    /// IMU die temperature, °C.
    pub temperature: f32,
}

/// `OdometryData`: world-frame pose and body-frame velocity.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct OdometryData {
    /// m, world frame.
    pub pos_x: f32,
    /// m, world frame.
    pub pos_y: f32,
    /// rad, CCW positive (ENU).
    pub heading: f32,
    /// m/s, body frame.
    pub vx: f32,
    /// m/s, body frame.
    pub vy: f32,
    /// rad/s, body frame.
    pub wz: f32,
}

/// STM32 → Pi sensor buffer (`transferVersion` is implicit: written as 15, checked on decode).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct TxBuffer {
    /// µs timestamp of the transfer.
    pub update_time: u32,
    /// Motor readings.
    pub motor: MotorData,
    /// 12-bit ADC readings, ports 0–5.
    pub analog_sensor: [i16; 6],
    /// 12-bit ADC reading of the battery.
    pub battery_voltage: i16,
    /// Bits 0–9 DIN0–9, bit 10 the onboard button.
    pub digital_sensors: u16,
    /// IMU output.
    pub imu: ImuData,
    /// Odometry.
    pub odometry: OdometryData,
}

/// Pi → STM32 command buffer (`transferVersion` implicit; the parity bit is computed by the encoder).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct RxBuffer {
    /// One-shot update flags.
    pub updates: UpdateFlags,
    /// Shutdown bits.
    pub system_shutdown: Shutdown,
    /// Mode of motors 0–3.
    pub motor_control_mode: [MotorMode; 4],
    /// PWM duty / velocity setpoint / speed cap, per mode.
    pub motor_target: [i32; 4],
    /// Absolute target position (MTP mode).
    pub motor_goal_position: [i32; 4],
    /// Mode of servos 0–3.
    pub servo_mode: [ServoMode; 4],
    /// Servo PWM in timer ticks (600–2600).
    pub servo_pos: [u16; 4],
    /// PID configuration block.
    pub motor_pid_settings: MotorPidSettings,
    /// Row-major 3×3 gyro orientation.
    pub imu_gyro_orientation: [i8; 9],
    /// Row-major 3×3 compass orientation.
    pub imu_compass_orientation: [i8; 9],
    /// Wheel geometry.
    pub kinematics: KinematicsConfig,
}

impl RxBuffer {
    /// The ladder's view of the four motors, each in its own drive mode: `OFF` → coast,
    /// `PASSIV_BRAKE` → short brake, `PWM` → duty `motorTarget / 399`, `MAV` → velocity
    /// `motorTarget × rad_per_tick` (the target is in encoder ticks per second), `MTP` → position
    /// `motorGoalPosition × rad_per_tick` under the speed cap `|motorTarget| × rad_per_tick`. The motor
    /// shutdown bit disables (and [`Self::to_events`] sends it first, which brakes).
    pub fn to_command(&self, rad_per_tick: f32) -> Command<4> {
        let mut axes = [AxisCommand::COAST; 4];
        for (((a, m), t), g) in axes
            .iter_mut()
            .zip(self.motor_control_mode.iter())
            .zip(self.motor_target.iter())
            .zip(self.motor_goal_position.iter())
        {
            let (t, g) = (*t as f32, *g as f32);
            *a = match m {
                MotorMode::Off => AxisCommand::COAST,
                MotorMode::PassiveBrake => AxisCommand::SHORT,
                MotorMode::Pwm => AxisCommand::duty(t / f32::from(PWM_MAX)),
                MotorMode::Mav => AxisCommand::velocity(t * rad_per_tick),
                MotorMode::Mtp => AxisCommand::position(g * rad_per_tick, t.abs() * rad_per_tick),
            };
        }
        Command {
            axes,
            enable: !self.system_shutdown.motors,
            seq: None,
            timeout: None,
        }
    }

    /// The ladder events of one transfer, in order: the shutdown bit, then the command.
    pub fn to_events(&self, rad_per_tick: f32) -> [Event<4>; 2] {
        [
            Event::Shutdown(self.system_shutdown.motors),
            Event::Frame(self.to_command(rad_per_tick)),
        ]
    }
}

/// Writes `tx` with `transferVersion` = 15.
pub fn encode_tx(tx: &TxBuffer, out: &mut [u8; TX_LEN]) {
    let mut w = le::Writer::new(out);
    w.u8(TRANSFER_VERSION);
    w.u32(tx.update_time);
    w.each(&tx.motor.bemf, le::Writer::i32);
    w.each(&tx.motor.position, le::Writer::i32);
    w.u8(tx.motor.done);
    w.each(&tx.analog_sensor, le::Writer::i16);
    w.i16(tx.battery_voltage);
    w.u16(tx.digital_sensors);
    let imu = &tx.imu;
    for s in [
        &imu.gyro,
        &imu.accel,
        &imu.compass,
        &imu.linear_accel,
        &imu.accel_velocity,
    ] {
        s.write(&mut w);
    }
    imu.dmp_quat.write(&mut w);
    w.f32(imu.heading);
    w.f32(imu.temperature);
    let o = &tx.odometry;
    w.each(
        &[o.pos_x, o.pos_y, o.heading, o.vx, o.vy, o.wz],
        le::Writer::f32,
    );
}

/// Reads a `TxBuffer`; only the version can be wrong ([`RejectReason::Version`]).
pub fn decode_tx(buf: &[u8; TX_LEN]) -> Result<TxBuffer, RejectReason> {
    let mut r = le::Reader::new(buf);
    read_tx(&mut r).map_err(|_| RejectReason::Decode)?
}

fn read_tx(r: &mut le::Reader<'_>) -> Result<Result<TxBuffer, RejectReason>, le::Short> {
    if r.u8()? != TRANSFER_VERSION {
        return Ok(Err(RejectReason::Version));
    }
    let update_time = r.u32()?;
    let bemf = read_i32x4(r)?;
    let position = read_i32x4(r)?;
    let done = r.u8()?;
    let analog_sensor = [r.i16()?, r.i16()?, r.i16()?, r.i16()?, r.i16()?, r.i16()?];
    let battery_voltage = r.i16()?;
    let digital_sensors = r.u16()?;
    let imu = ImuData {
        gyro: SensorData::read(r)?,
        accel: SensorData::read(r)?,
        compass: SensorData::read(r)?,
        linear_accel: SensorData::read(r)?,
        accel_velocity: SensorData::read(r)?,
        dmp_quat: QuaternionData::read(r)?,
        heading: r.f32()?,
        temperature: r.f32()?,
    };
    let odometry = OdometryData {
        pos_x: r.f32()?,
        pos_y: r.f32()?,
        heading: r.f32()?,
        vx: r.f32()?,
        vy: r.f32()?,
        wz: r.f32()?,
    };
    Ok(Ok(TxBuffer {
        update_time,
        motor: MotorData {
            bemf,
            position,
            done,
        },
        analog_sensor,
        battery_voltage,
        digital_sensors,
        imu,
        odometry,
    }))
}

fn read_i32x4(r: &mut le::Reader<'_>) -> Result<[i32; 4], le::Short> {
    Ok([r.i32()?, r.i32()?, r.i32()?, r.i32()?])
}

fn read_i8x9(r: &mut le::Reader<'_>) -> Result<[i8; 9], le::Short> {
    let mut out = [0i8; 9];
    #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
    for i in 0..9 {
        out[i] = r.i8()?;
    }
    Ok(out)
}

/// Writes `rx` with `transferVersion` = 15 and the parity bit of `updates` set as the seed requires.
pub fn encode_rx(rx: &RxBuffer, out: &mut [u8; RX_LEN]) {
    let mut w = le::Writer::new(out);
    w.u8(TRANSFER_VERSION);
    w.u32(updates_word(rx.updates));
    w.u8(rx.system_shutdown.to_byte());
    w.u16(pack_motor_modes(rx.motor_control_mode));
    w.each(&rx.motor_target, le::Writer::i32);
    w.each(&rx.motor_goal_position, le::Writer::i32);
    w.u8(pack_servo_modes(rx.servo_mode));
    w.each(&rx.servo_pos, le::Writer::u16);
    rx.motor_pid_settings.write(&mut w);
    w.each(&rx.imu_gyro_orientation, le::Writer::i8);
    w.each(&rx.imu_compass_orientation, le::Writer::i8);
    rx.kinematics.write(&mut w);
}

/// Reads an `RxBuffer`: version, then parity, then every packed field (see the module docs).
pub fn decode_rx(buf: &[u8; RX_LEN]) -> Result<RxBuffer, RejectReason> {
    let mut r = le::Reader::new(buf);
    read_rx(&mut r).map_err(|_| RejectReason::Decode)?
}

fn read_rx(r: &mut le::Reader<'_>) -> Result<Result<RxBuffer, RejectReason>, le::Short> {
    if r.u8()? != TRANSFER_VERSION {
        return Ok(Err(RejectReason::Version));
    }
    let updates = r.u32()?;
    if !parity_ok(updates) {
        return Ok(Err(RejectReason::Parity));
    }
    if updates & !(u32::from(UpdateFlags::ALL) | UpdateFlags::PARITY_BIT) != 0 {
        return Ok(Err(RejectReason::Decode));
    }
    let shutdown = r.u8()?;
    if shutdown & !0b11 != 0 {
        return Ok(Err(RejectReason::Decode));
    }
    let Some(motor_control_mode) = unpack_motor_modes(r.u16()?) else {
        return Ok(Err(RejectReason::Decode));
    };
    let motor_target = read_i32x4(r)?;
    let motor_goal_position = read_i32x4(r)?;
    let Some(servo_mode) = unpack_servo_modes(r.u8()?) else {
        return Ok(Err(RejectReason::Decode));
    };
    let servo_pos = [r.u16()?, r.u16()?, r.u16()?, r.u16()?];
    let motor_pid_settings = MotorPidSettings::read(r)?;
    let imu_gyro_orientation = read_i8x9(r)?;
    let imu_compass_orientation = read_i8x9(r)?;
    let kinematics = KinematicsConfig::read(r)?;
    Ok(Ok(RxBuffer {
        // Bits 0..=5 only (checked above), so the cast keeps every flag.
        updates: UpdateFlags((updates & u32::from(UpdateFlags::ALL)) as u8),
        system_shutdown: Shutdown {
            servos: shutdown & 1 != 0,
            motors: shutdown & 2 != 0,
        },
        motor_control_mode,
        motor_target,
        motor_goal_position,
        servo_mode,
        servo_pos,
        motor_pid_settings,
        imu_gyro_orientation,
        imu_compass_orientation,
        kinematics,
    }))
}

#[cfg(test)]
mod tests;

#[cfg(any(test, kani))]
mod verification;
