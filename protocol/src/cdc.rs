//! Seed 001: the USB CDC / UART framing `AA 55 | MSG_ID | LEN | payload | CRC16 LE`, every message, and a resynchronising stream decoder.
//!
//! # Frame
//!
//! ```text
//!  offset 0     1     2        3     4 ........ 4+LEN−1   4+LEN     4+LEN+1
//!       ┌─────┬─────┬────────┬─────┬─────────────────────┬─────────┬─────────┐
//!       │ AA  │ 55  │ MSG_ID │ LEN │ payload (LEN bytes) │ CRC lo  │ CRC hi  │
//!       └─────┴─────┴────────┴─────┴─────────────────────┴─────────┴─────────┘
//!                    └──────── CRC-16/CCITT-FALSE over MSG_ID, LEN, payload ─┘
//! ```
//! All multi-byte fields little-endian, signed fields two's complement. LEN is 0..=255, so a frame
//! is 6..=[`MAX_FRAME_LEN`] bytes.
//!
//! The seed gives IMU_MPU6050 a 20-byte payload but lists 18 bytes of fields: 20 is `sizeof` of the
//! naturally aligned C struct (4-byte alignment pads 18 to 20). LEN is 20 as the seed says; the last
//! two bytes are reserved, sent as zero and ignored on receipt.
//!
//! # Payloads
//!
//! ```text
//!  0x01 SET_MOTOR_PWM  Jetson→MCU 10 B  i16 pwm_m1 | i16 pwm_m2 | i16 pwm_m3 | i16 pwm_m4 | u16 timeout_ms
//!  0x02 MOTOR_ENABLE   Jetson→MCU  1 B  u8 enable (0 off, 1 on)
//!  0x03 ESTOP          Jetson→MCU  1 B  u8 action (1 engage and latch, 0 release)
//!  0x10 PING           Jetson→MCU  0 B
//!  0x81 IMU_MPU6050    MCU→Jetson 20 B  u32 t_ms | i16 ax ay az (mg) | i16 gx gy gz (mdps) | i16 temp_cdeg | 2 B reserved
//!  0x82 STATUS         MCU→Jetson 10 B  u32 t_ms | u16 vbat_mV | u16 flags | u16 err
//!  0x7F ACK            MCU→Jetson  2 B  u8 ack_msg_id | u8 result (0 OK)
//! ```
//!
//! # Mapping onto the safety core
//!
//! | message              | ladder event                                                             |
//! |----------------------|--------------------------------------------------------------------------|
//! | `MOTOR_ENABLE` 1     | [`Event::Rearm`] from the primary link (the explicit re-arm; BRAKE is left only if no latching cause is active) |
//! | `MOTOR_ENABLE` 0     | [`Event::Frame`] with `enable = false`, every motor coasting (the seed: outputs forced to 0) |
//! | `ESTOP` 1 / 0        | [`Event::Estop`] `Engage` / `Release` from the primary link (it releases only its own ESTOP) |
//! | `SET_MOTOR_PWM`      | [`Event::Frame`] of four duty axes, `pwm / 1000` of full scale, `pwm = 0` coasting, `timeout_ms` as the frame's comm-loss threshold (see [`SetMotorPwm::to_command`]); the seed 001 profile (`statemachine::Config::CDC`) accepts duty and coast |
//! | `PING`, MCU→Jetson   | none                                                                     |
//!
//! Protocol failures: bad CRC → [`RejectReason::Crc`]; bad SOF → [`RejectReason::Framing`]; wrong
//! payload length, unknown MSG_ID or an out-of-range value → [`RejectReason::Decode`]
//! (see [`Error::reason`]; [`Error::error_code`] gives the seed's STATUS `err` code).

use crate::crc16;
use crate::le;
use statemachine::config::brake_age_for_timeout_ms;
use statemachine::{AxisCommand, Command, Estop, Event, RejectReason, Source};

/// Start-of-frame bytes.
pub const SOF: [u8; 2] = [0xAA, 0x55];
/// SOF, MSG_ID, LEN.
pub const HEADER_LEN: usize = 4;
/// CRC trailer.
pub const CRC_LEN: usize = 2;
/// Largest payload LEN can announce.
pub const MAX_PAYLOAD: usize = 255;
/// Largest frame: header, 255 payload bytes, CRC.
pub const MAX_FRAME_LEN: usize = HEADER_LEN + MAX_PAYLOAD + CRC_LEN;

/// Message identifiers (MSG_ID). Values fixed by the seed, never reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum MsgId {
    /// Four motor PWM commands.
    SetMotorPwm = 0x01,
    /// Enable or disable the motors.
    MotorEnable = 0x02,
    /// Engage or release the emergency stop.
    Estop = 0x03,
    /// Link probe.
    Ping = 0x10,
    /// Acknowledgement of a low-rate command.
    Ack = 0x7F,
    /// MPU6050 raw data.
    Imu = 0x81,
    /// Low-rate status.
    Status = 0x82,
}

impl MsgId {
    /// Maps a raw MSG_ID, `None` if the seed does not define it.
    pub const fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            0x01 => Some(Self::SetMotorPwm),
            0x02 => Some(Self::MotorEnable),
            0x03 => Some(Self::Estop),
            0x10 => Some(Self::Ping),
            0x7F => Some(Self::Ack),
            0x81 => Some(Self::Imu),
            0x82 => Some(Self::Status),
            _ => None,
        }
    }

    /// The payload length the seed fixes for this message.
    pub const fn payload_len(self) -> usize {
        match self {
            Self::SetMotorPwm | Self::Status => 10,
            Self::MotorEnable | Self::Estop => 1,
            Self::Ping => 0,
            Self::Ack => 2,
            // 18 bytes of fields + 2 reserved (see the module documentation).
            Self::Imu => 20,
        }
    }
}

/// The seed's STATUS `err` codes. Values fixed, never reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u16)]
pub enum ErrorCode {
    /// No error.
    Ok = 0,
    /// A frame failed its CRC.
    CrcError = 1,
    /// A payload had the wrong length for its MSG_ID.
    LenError = 2,
    /// MSG_ID not defined.
    UnknownMsg = 3,
    /// The IMU does not answer.
    ImuFail = 4,
}

impl ErrorCode {
    /// Maps a raw `err` value, `None` if undefined.
    pub const fn from_raw(raw: u16) -> Option<Self> {
        match raw {
            0 => Some(Self::Ok),
            1 => Some(Self::CrcError),
            2 => Some(Self::LenError),
            3 => Some(Self::UnknownMsg),
            4 => Some(Self::ImuFail),
            _ => None,
        }
    }
}

/// Why a frame or payload was refused. Wire codes fixed, never reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Error {
    /// The CRC did not match.
    Crc = 1,
    /// The payload length is not the one fixed for the MSG_ID.
    Length = 2,
    /// The MSG_ID is not defined.
    UnknownMsg = 3,
    /// A field holds a value the seed does not define (e.g. `enable` = 2).
    Value = 4,
    /// Not a frame: bad SOF, or the bytes do not hold exactly one frame.
    Framing = 5,
}

impl Error {
    /// The safety core's view of this failure.
    pub const fn reason(self) -> RejectReason {
        match self {
            Self::Crc => RejectReason::Crc,
            Self::Framing => RejectReason::Framing,
            Self::Length | Self::UnknownMsg | Self::Value => RejectReason::Decode,
        }
    }

    /// The seed's STATUS `err` code that reports this failure.
    pub const fn error_code(self) -> ErrorCode {
        match self {
            Self::Crc => ErrorCode::CrcError,
            Self::Length | Self::Framing => ErrorCode::LenError,
            Self::UnknownMsg | Self::Value => ErrorCode::UnknownMsg,
        }
    }
}

/// `SET_MOTOR_PWM` payload: four signed duties in [-1000, 1000] and a command timeout.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct SetMotorPwm {
    /// pwm_m1 … pwm_m4 (TIM8 CH1 … CH4); the seed recommends [-1000, 1000].
    pub pwm: [i16; 4],
    /// Outputs go to zero if no new control frame arrives within this many milliseconds.
    pub timeout_ms: u16,
}

/// Largest duty magnitude of `SET_MOTOR_PWM` (full scale).
pub const PWM_FULL_SCALE: i16 = 1000;

impl SetMotorPwm {
    /// Duties clamped to ±[`PWM_FULL_SCALE`] (the seed's `min(|pwm|·ARR/1000, ARR)`).
    pub fn duty(&self) -> [i16; 4] {
        self.pwm
            .map(|p| p.clamp(PWM_FULL_SCALE.saturating_neg(), PWM_FULL_SCALE))
    }

    /// The ladder's view: four duty axes as fractions of full scale (`pwm / 1000`), `pwm = 0` as coast
    /// (the seed's IN1 = IN2 = 0), and `timeout_ms` as the frame's comm-loss threshold
    /// ([`brake_age_for_timeout_ms`]: strictly within `timeout_ms`). Nothing is clamped here: a
    /// `|pwm|` above 1000 reaches the ladder, which refuses the frame as out of range and counts it
    /// (the seed's `min(…, ARR)` would saturate silently); `timeout_ms = 0` is refused the same way.
    pub fn to_command(&self) -> Command<4> {
        let axes = self.pwm.map(|p| {
            if p == 0 {
                AxisCommand::COAST
            } else {
                AxisCommand::duty(f32::from(p) / f32::from(PWM_FULL_SCALE))
            }
        });
        Command {
            axes,
            enable: true,
            seq: None,
            timeout: Some(brake_age_for_timeout_ms(self.timeout_ms).unwrap_or(0)),
        }
    }
}

/// `IMU_MPU6050` payload: raw MPU6050 readings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Imu {
    /// MCU milliseconds since power-on.
    pub t_ms: u32,
    /// Acceleration x, y, z in mg.
    pub accel_mg: [i16; 3],
    /// Angular rate x, y, z in mdps.
    pub gyro_mdps: [i16; 3],
    /// Temperature in 0.01 °C (0 if not measured).
    pub temp_cdeg: i16,
}

/// `STATUS.flags` bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(transparent)
)]
pub struct StatusFlags(pub u16);

impl StatusFlags {
    /// bit 0: motors enabled.
    pub const MOTOR_ENABLED: u16 = 1 << 0;
    /// bit 1: emergency stop latched.
    pub const ESTOP_LATCHED: u16 = 1 << 1;
    /// bit 2: command timeout protection active.
    pub const CMD_TIMEOUT: u16 = 1 << 2;
    /// bit 3: IMU healthy.
    pub const IMU_OK: u16 = 1 << 3;

    /// True if every bit of `mask` is set.
    pub const fn has(self, mask: u16) -> bool {
        self.0 & mask == mask
    }
}

/// `STATUS` payload.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Status {
    /// MCU milliseconds since power-on.
    pub t_ms: u32,
    /// Battery voltage in mV (0 if not measured).
    pub vbat_mv: u16,
    /// Status bits.
    pub flags: StatusFlags,
    /// Error code, raw (see [`ErrorCode::from_raw`]).
    pub err: u16,
}

/// `ACK` payload.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Ack {
    /// The MSG_ID acknowledged.
    pub msg_id: u8,
    /// 0 OK, otherwise an error.
    pub result: u8,
}

/// Every message of the seed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Message {
    /// 0x01.
    SetMotorPwm(SetMotorPwm),
    /// 0x02: true = enable.
    MotorEnable(bool),
    /// 0x03.
    Estop(Estop),
    /// 0x10.
    Ping,
    /// 0x7F.
    Ack(Ack),
    /// 0x81.
    Imu(Imu),
    /// 0x82.
    Status(Status),
}

impl Message {
    /// This message's MSG_ID.
    pub const fn id(&self) -> MsgId {
        match self {
            Self::SetMotorPwm(_) => MsgId::SetMotorPwm,
            Self::MotorEnable(_) => MsgId::MotorEnable,
            Self::Estop(_) => MsgId::Estop,
            Self::Ping => MsgId::Ping,
            Self::Ack(_) => MsgId::Ack,
            Self::Imu(_) => MsgId::Imu,
            Self::Status(_) => MsgId::Status,
        }
    }

    /// Decodes a payload for a raw MSG_ID (the CRC already checked).
    pub fn decode(msg_id: u8, payload: &[u8]) -> Result<Self, Error> {
        let id = MsgId::from_raw(msg_id).ok_or(Error::UnknownMsg)?;
        if payload.len() != id.payload_len() {
            return Err(Error::Length);
        }
        let mut r = le::Reader::new(payload);
        let short = |_| Error::Length;
        let msg = match id {
            MsgId::SetMotorPwm => Self::SetMotorPwm(SetMotorPwm {
                pwm: [
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                ],
                timeout_ms: r.u16().map_err(short)?,
            }),
            MsgId::MotorEnable => match r.u8().map_err(short)? {
                0 => Self::MotorEnable(false),
                1 => Self::MotorEnable(true),
                _ => return Err(Error::Value),
            },
            MsgId::Estop => match r.u8().map_err(short)? {
                0 => Self::Estop(Estop::Release),
                1 => Self::Estop(Estop::Engage),
                _ => return Err(Error::Value),
            },
            MsgId::Ping => Self::Ping,
            MsgId::Ack => Self::Ack(Ack {
                msg_id: r.u8().map_err(short)?,
                result: r.u8().map_err(short)?,
            }),
            MsgId::Imu => Self::Imu(Imu {
                t_ms: r.u32().map_err(short)?,
                accel_mg: [
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                ],
                gyro_mdps: [
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                    r.i16().map_err(short)?,
                ],
                temp_cdeg: r.i16().map_err(short)?,
            }),
            MsgId::Status => Self::Status(Status {
                t_ms: r.u32().map_err(short)?,
                vbat_mv: r.u16().map_err(short)?,
                flags: StatusFlags(r.u16().map_err(short)?),
                err: r.u16().map_err(short)?,
            }),
        };
        Ok(msg)
    }

    /// Writes the payload; returns its length.
    pub fn encode_payload(&self, out: &mut [u8; MAX_PAYLOAD]) -> usize {
        let mut w = le::Writer::new(out);
        match self {
            Self::SetMotorPwm(p) => {
                w.each(&p.pwm, le::Writer::i16);
                w.u16(p.timeout_ms);
            }
            Self::MotorEnable(on) => w.u8(u8::from(*on)),
            Self::Estop(Estop::Engage) => w.u8(1),
            Self::Estop(Estop::Release) => w.u8(0),
            Self::Ping => {}
            Self::Ack(a) => {
                w.u8(a.msg_id);
                w.u8(a.result);
            }
            Self::Imu(i) => {
                w.u32(i.t_ms);
                w.each(&i.accel_mg, le::Writer::i16);
                w.each(&i.gyro_mdps, le::Writer::i16);
                w.i16(i.temp_cdeg);
                w.u16(0); // reserved
            }
            Self::Status(s) => {
                w.u32(s.t_ms);
                w.u16(s.vbat_mv);
                w.u16(s.flags.0);
                w.u16(s.err);
            }
        }
        w.len()
    }

    /// Writes the complete frame (SOF, MSG_ID, LEN, payload, CRC); returns its length (6..=26).
    pub fn encode(&self, out: &mut [u8; MAX_FRAME_LEN]) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD];
        let n = self.encode_payload(&mut payload);
        let body = payload.get(..n).unwrap_or(&[]);
        encode_raw(self.id() as u8, body, out)
    }

    /// The ladder event this message asks for (see the module documentation), `None` for messages
    /// that do not concern the ladder.
    pub fn to_event(&self) -> Option<Event<4>> {
        match self {
            Self::MotorEnable(true) => Some(Event::Rearm(Source::Primary)),
            Self::MotorEnable(false) => Some(Event::Frame(Command::uniform(
                AxisCommand::COAST,
                false,
                None,
            ))),
            Self::Estop(e) => Some(Event::Estop {
                source: Source::Primary,
                action: *e,
            }),
            Self::SetMotorPwm(p) => Some(Event::Frame(p.to_command())),
            Self::Ping | Self::Ack(_) | Self::Imu(_) | Self::Status(_) => None,
        }
    }
}

/// Frames any MSG_ID and payload (payloads longer than 255 bytes are cut at 255); returns the frame length.
pub fn encode_raw(msg_id: u8, payload: &[u8], out: &mut [u8; MAX_FRAME_LEN]) -> usize {
    let payload = payload.get(..MAX_PAYLOAD).unwrap_or(payload);
    let len = u8::try_from(payload.len()).unwrap_or(u8::MAX);
    let mut w = le::Writer::new(out);
    w.bytes(&SOF);
    w.u8(msg_id);
    w.u8(len);
    w.bytes(payload);
    let n = w.len();
    let crc = crc16::checksum(out.get(2..n).unwrap_or(&[]));
    let mut w = le::Writer::new(out.get_mut(n..).unwrap_or(&mut []));
    w.u16(crc);
    n.saturating_add(w.len())
}

/// Decodes exactly one complete frame (`bytes` must be the frame and nothing else).
///
/// Checks: SOF and total length = 6 + LEN ([`Error::Framing`]), CRC ([`Error::Crc`]), then the payload.
pub fn decode_frame(bytes: &[u8]) -> Result<Message, Error> {
    let (header, rest) = bytes.split_at_checked(HEADER_LEN).ok_or(Error::Framing)?;
    let [s0, s1, msg_id, len] = <[u8; HEADER_LEN]>::try_from(header).map_err(|_| Error::Framing)?;
    if [s0, s1] != SOF || rest.len() != usize::from(len).saturating_add(CRC_LEN) {
        return Err(Error::Framing);
    }
    let (payload, crc) = rest.split_at(usize::from(len));
    let covered = bytes
        .get(2..HEADER_LEN.saturating_add(usize::from(len)))
        .ok_or(Error::Framing)?;
    let stored = <[u8; 2]>::try_from(crc).map_err(|_| Error::Framing)?;
    if crc16::checksum(covered) != u16::from_le_bytes(stored) {
        return Err(Error::Crc);
    }
    Message::decode(msg_id, payload)
}

/// What a [`StreamDecoder`] has seen (saturating counters).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Stats {
    /// Frames delivered as messages.
    pub frames: u32,
    /// Candidate frames whose CRC failed (each candidate checked, see [`StreamDecoder`]).
    pub crc_errors: u32,
    /// Frames with a good CRC but a bad payload (length, unknown MSG_ID, value).
    pub message_errors: u32,
    /// Bytes discarded: every byte that is not part of a delivered frame (garbage, false starts,
    /// remains of broken frames, a reset), counted when the decoder lets go of it.
    pub dropped_bytes: u32,
}

/// Shortest frame: SOF, MSG_ID, LEN and CRC, no payload.
pub const MIN_FRAME_LEN: usize = HEADER_LEN + CRC_LEN;

/// Turns a byte stream into messages: every complete frame with a good CRC is delivered at its
/// last byte, whatever came before it (garbage, a false SOF, that is an `AA 55` in garbage or in a
/// payload, announcing a LEN that reaches past the frames after it, a truncated frame, a bad CRC).
///
/// # Property
///
/// Write the stream `b[0] b[1] …` and let the boundary `B` be the position just after the last
/// frame delivered (0 at the start; after [`reset`](Self::reset), the position of the next byte).
/// A *candidate ending at `k`* is `b[s..=k]` with `s ≥ B`, `b[s] b[s+1]` = `AA 55` and
/// `k − s + 1 = 6 + b[s+3]` (its LEN). After `push(b[k])`:
///
/// 1. if a candidate ending at `k` has a good CRC, `push` returns `Some(decode_frame(b[s..=k]))`
///    for the earliest-starting such `s`: `Ok(message)`, or [`Error::Length`],
///    [`Error::UnknownMsg`] or [`Error::Value`] for a frame whose payload is refused. That frame is
///    delivered: `B` becomes `k + 1`, and the `s − B` bytes before it are counted as dropped;
/// 2. otherwise, if candidates end at `k` (each with a bad CRC), it returns `Some(Err(Error::Crc))`;
/// 3. otherwise it returns `None`.
///
/// Each candidate ending at `k` with a bad CRC that starts before `s` (every one in case 2) adds
/// one to [`Stats::crc_errors`]. So no byte before a
/// valid frame can delay it: a valid frame is lost only if it overlaps an earlier-starting frame
/// with a good CRC that ends no later (delivered instead), or starts inside a frame delivered before.
///
/// The property is checked, against a naive reference that tries every start position at every
/// byte, by the exhaustive test `stream_holds_back_no_frame_exhaustively`, the Kani harnesses
/// `verify_stream_holds_back_no_frame_*` with their twin, and the fuzz target
/// `fuzz_cdc_stream_holds_back_no_frame`.
///
/// ```text
///  bytes:  13 AA 55 01 FF AA 55 03 01 01 cc cc AA 55 10 00 cc cc
///          └── dropped ─┘ └────── ESTOP ─────┘ └───── PING ─────┘
/// ```
///
/// `AA 55 01 FF` is a false SOF: its LEN, 255, would end it 261 bytes after its `AA`. The ESTOP
/// and the PING are each delivered at their last byte (`cc cc`: their CRC); the false SOF's
/// bytes and the 13 are dropped when the ESTOP is delivered.
///
/// # Cost
///
/// Memory: one frame ([`MAX_FRAME_LEN`] bytes). The decoder holds the bytes from the oldest
/// candidate that can still end to the last byte: a candidate ends at most `MAX_FRAME_LEN − 1`
/// bytes after its start, and on a stream of frames without false SOFs only the frame being
/// received is held.
///
/// Work per byte, worst case: the held bytes' `MAX_FRAME_LEN − 5` = 256 possible starts compared
/// (`AA`, `55`, then the length); a CRC only for each candidate that ends at this byte, at most 64
/// of them over 8,384 bytes in all; a pass over the bytes held to find the first that may still
/// start a frame; and, when the buffer is full, one move of the bytes held to its front (bytes
/// dropped or delivered stay where they are until then). The 64 need a window crafted for it (false SOFs
/// about four bytes apart whose LENs all end at the same byte: two starts ending together are at
/// least 4 bytes apart, except once 2 for LEN 0x55 and once 3 for LEN 0xAA); the test
/// `crc_work_per_byte_is_bounded` finds the bound by trying every set of LENs and builds such a
/// window. A stream of frames without false SOFs costs one CRC per frame, at its last byte.
#[derive(Clone, Debug)]
pub struct StreamDecoder {
    /// `buf[..len]` are the last bytes pushed, at most [`MAX_FRAME_LEN`]; the bytes held are
    /// `buf[first..len]`, from the oldest candidate that can still end (or a lone `AA` that may
    /// start one) to the last byte pushed. The bytes before `first` are delivered or dropped (and
    /// counted) but not moved: the bytes held move to the front only when the buffer is full.
    /// `first <= len <= MAX_FRAME_LEN` always.
    buf: [u8; MAX_FRAME_LEN],
    len: usize,
    first: usize,
    stats: Stats,
}

impl Default for StreamDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl StreamDecoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME_LEN],
            len: 0,
            first: 0,
            stats: Stats {
                frames: 0,
                crc_errors: 0,
                message_errors: 0,
                dropped_bytes: 0,
            },
        }
    }

    /// Counters so far.
    pub const fn stats(&self) -> Stats {
        self.stats
    }

    /// Bytes held, waiting for the candidates among them to end (at most [`MAX_FRAME_LEN`]).
    pub fn buffered(&self) -> usize {
        self.len.saturating_sub(self.first)
    }

    /// `buf[..len]`: the bytes held and the dropped ones before them (none if the length were ever
    /// out of range).
    fn bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }

    /// Discards the bytes held (e.g. after an inter-byte timeout), counting them as dropped: the
    /// next frame must start at the next byte.
    pub fn reset(&mut self) {
        self.count_dropped(self.buffered());
        self.len = 0;
        self.first = 0;
    }

    /// Adds one byte; returns the frame that ends at it, a CRC failure, or `None` (the rules are
    /// in the type's documentation). Every result is returned by the `push` of the byte that
    /// completes it: nothing waits in the decoder to be collected later.
    pub fn push(&mut self, byte: u8) -> Option<Result<Message, Error>> {
        self.append(byte);
        match self.complete() {
            Completion::Frame { start, result } => {
                self.deliver(start, &result);
                Some(result)
            }
            Completion::BadCrc => {
                self.advance();
                Some(Err(Error::Crc))
            }
            Completion::Nothing => {
                self.advance();
                None
            }
        }
    }

    /// Feeds a slice and iterates over every result it completes, in order.
    pub fn feed<'a>(&'a mut self, bytes: &'a [u8]) -> Feed<'a> {
        Feed { dec: self, bytes }
    }

    fn append(&mut self, byte: u8) {
        if self.len >= MAX_FRAME_LEN {
            // Full: the bytes held move to the front, over the dropped ones. There is at least
            // one: a candidate held ends within MAX_FRAME_LEN bytes of its start, so after the
            // byte that filled the buffer `first` is past its first byte. If there were none all
            // the same, the oldest byte goes, counted, so that no state can make the decoder fail.
            let gone = self.first.clamp(1, MAX_FRAME_LEN);
            if self.first == 0 {
                self.count_dropped(1);
            }
            self.buf.copy_within(gone.., 0);
            self.len = MAX_FRAME_LEN.saturating_sub(gone);
            self.first = self.first.saturating_sub(gone);
        }
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = byte;
            self.len = self.len.saturating_add(1);
        }
    }

    /// Checks the candidates that end at the last byte held and picks the earliest-starting one
    /// with a good CRC. Counts the CRC failures of the candidates that start before it (all of
    /// them if none is good).
    // The loop-contract build reports the loop's variable unused (the contract's rewriting of the
    // loop, not this code).
    #[cfg_attr(kani_loop_contracts, allow(unused_variables))]
    fn complete(&mut self) -> Completion {
        // By length, shortest first: the length and the start it gives (`len − length`) are plain
        // counts from the end, so each byte is read at a fixed place (which is what keeps Kani's
        // formulas small), and only the bytes held are visited. A longer candidate starts earlier.
        // The loop runs to `len` and stops at the bytes held: a bound the solver knows.
        let span = self.len.saturating_sub(self.first);
        let mut best = None;
        let mut bad_before_best = 0u32;
        // Under the loop-contract proof of one `push` (`cdc::verify_stream_step`) this loop stands
        // for any number of its passes, with any `bad_before_best` and any `best` but a framing
        // error (a candidate's CRC and LEN are right): what `push` does next is total and keeps
        // the decoder's bounds for every such value.
        // (A half-open range that is never reversed: Kani's loop contracts take no inclusive
        // range, nor one whose end is below its start.)
        let end = self
            .len
            .min(MAX_FRAME_LEN)
            .saturating_add(1)
            .max(MIN_FRAME_LEN);
        #[cfg_attr(
            kani_loop_contracts,
            kani::loop_invariant(!matches!(best, Some((_, Err(Error::Framing)))))
        )]
        for length in MIN_FRAME_LEN..end {
            if length > span {
                break;
            }
            let start = self.len.saturating_sub(length);
            match self.candidate_at(start) {
                Candidate::NotHere => {}
                Candidate::BadCrc => bad_before_best = bad_before_best.saturating_add(1),
                Candidate::Good(result) => {
                    best = Some((start, result));
                    bad_before_best = 0;
                }
            }
        }
        self.stats.crc_errors = self.stats.crc_errors.saturating_add(bad_before_best);
        match best {
            Some((start, result)) => Completion::Frame { start, result },
            None if bad_before_best > 0 => Completion::BadCrc,
            None => Completion::Nothing,
        }
    }

    /// Whether the bytes from `buf[start]` on are a candidate (SOF, and a LEN that makes it end at
    /// the last byte), and if so what its CRC and payload say. The CRC is computed only here.
    ///
    /// What [`decode_frame`] does, once the SOF and the length are known to be right, with every
    /// slice cut by the frame's own length (the number of bytes from `start` to the last one)
    /// rather than by the LEN byte: the same bytes, but lengths Kani's solver knows.
    fn candidate_at(&self, start: usize) -> Candidate {
        let frame = self.bytes().get(start..).unwrap_or(&[]);
        let [0xAA, 0x55, msg_id, len, ..] = *frame else {
            return Candidate::NotHere;
        };
        if frame.len() != usize::from(len).saturating_add(MIN_FRAME_LEN) {
            return Candidate::NotHere;
        }
        let Some((body, stored)) = frame.split_last_chunk::<CRC_LEN>() else {
            return Candidate::NotHere;
        };
        // MSG_ID, LEN and the payload; then the payload alone.
        let covered = body.get(2..).unwrap_or(&[]);
        if crc16::checksum(covered) != u16::from_le_bytes(*stored) {
            return Candidate::BadCrc;
        }
        Candidate::Good(Message::decode(msg_id, covered.get(2..).unwrap_or(&[])))
    }

    /// Delivers the candidate at `buf[start]`, which ends at the last byte: the bytes held before
    /// it are dropped, and every candidate that started before its end goes with it.
    fn deliver(&mut self, start: usize, result: &Result<Message, Error>) {
        self.count_dropped(start.saturating_sub(self.first));
        self.first = self.len;
        if result.is_ok() {
            self.stats.frames = self.stats.frames.saturating_add(1);
        } else {
            self.stats.message_errors = self.stats.message_errors.saturating_add(1);
        }
    }

    /// Drops the bytes at the front that can no longer start a frame, so that the first byte held
    /// starts a candidate that can still end (or nothing is held).
    // The loop-contract build reports the loop's variable unused (the contract's rewriting of the
    // loop, not this code).
    #[cfg_attr(kani_loop_contracts, allow(unused_variables))]
    fn advance(&mut self) {
        let bytes = self.bytes();
        let span = bytes.len().saturating_sub(self.first);
        // From the end back to `first`, as in `complete`; the last one found is the first.
        let mut live = bytes.len();
        // The first byte kept stays within the bytes held, fewer than a whole buffer before the
        // end (`may_start` says yes only there): the loop contract of `cdc::verify_stream_step`.
        #[cfg_attr(
            kani_loop_contracts,
            kani::loop_invariant(live <= bytes.len() && bytes.len() - live < MAX_FRAME_LEN)
        )]
        for back in 1..bytes.len().saturating_add(1) {
            if back > span {
                break;
            }
            let i = bytes.len().saturating_sub(back);
            if may_start(bytes, i) {
                live = i;
            }
        }
        self.count_dropped(live.saturating_sub(self.first));
        self.first = live;
    }

    fn count_dropped(&mut self, n: usize) {
        let n = u32::try_from(n).unwrap_or(u32::MAX);
        self.stats.dropped_bytes = self.stats.dropped_bytes.saturating_add(n);
    }
}

/// Whether a candidate may still start at `held[i]` and end at a byte not yet pushed: a lone `AA`,
/// `AA 55`, `AA 55 MSG_ID`, or a header whose LEN puts the frame's end after the last byte held.
fn may_start(held: &[u8], i: usize) -> bool {
    match held.get(i..) {
        Some([0xAA] | [0xAA, 0x55] | [0xAA, 0x55, _]) => true,
        Some(rest @ [0xAA, 0x55, _, len, ..]) => {
            usize::from(*len).saturating_add(MIN_FRAME_LEN) > rest.len()
        }
        _ => false,
    }
}

/// What the candidates ending at the last byte gave ([`StreamDecoder::complete`]).
enum Completion {
    /// The earliest-starting candidate with a good CRC, at `start` of the bytes held.
    Frame {
        /// Where it starts in the bytes held.
        start: usize,
        /// Its message, or the payload's error.
        result: Result<Message, Error>,
    },
    /// Candidates ended here, every one with a bad CRC.
    BadCrc,
    /// No candidate ended here.
    Nothing,
}

/// One start position checked by [`StreamDecoder::candidate_at`].
enum Candidate {
    /// No candidate starts there, or it does not end at the last byte held.
    NotHere,
    /// A candidate whose CRC fails.
    BadCrc,
    /// A candidate with a good CRC: its message, or the payload's error.
    Good(Result<Message, Error>),
}

/// Iterator returned by [`StreamDecoder::feed`].
pub struct Feed<'a> {
    dec: &'a mut StreamDecoder,
    bytes: &'a [u8],
}

impl Iterator for Feed<'_> {
    type Item = Result<Message, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        while let Some((&b, rest)) = self.bytes.split_first() {
            self.bytes = rest;
            if let Some(r) = self.dec.push(b) {
                return Some(r);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests;

#[cfg(any(test, kani))]
mod verification;
