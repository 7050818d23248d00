//! Seed 000: the 1 kHz Jetson ↔ STM32 SPI link, `MotorCommand` / `MotorFeedback` in protobuf wire format.
//!
//! # Transaction
//!
//! The Jetson (master) clocks one [`FRAME_LEN`]-byte full-duplex transaction every millisecond: a
//! command frame goes out on MOSI while the feedback frame the MCU prepared comes back on MISO.
//!
//! ```text
//!  t (µs)   0        256                                   1000
//!  CS       ‾‾\______________________/‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾\___
//!  MOSI        [ command frame n, 64 B ]                          [ n+1
//!  MISO        [ feedback frame (answers n−1), 64 B ]             [
//!  MCU                                   DMA done → decode (CRC, protobuf, version)
//!                                        → Event::Frame / Event::Rejected → ladder
//!                                        → encode feedback for n+1 → re-arm DMA
//! ```
//! 64 bytes at 2 MHz take 256 µs; the seed budgets ≈ 0.2 ms for the transfer within the 1 ms cycle.
//!
//! # Frame (both directions)
//!
//! ```text
//!  offset  0      1 ............................ 1+LEN ........ 61  62       63
//!        ┌─────┬───────────────────────────────┬────────────────┬─────────┬─────────┐
//!        │ LEN │ message, protobuf wire format │ zero padding   │ CRC hi  │ CRC lo  │
//!        └─────┴───────────────────────────────┴────────────────┴─────────┴─────────┘
//!          LEN ≤ 61        CRC-16/CCITT-FALSE over bytes 0..62, stored big-endian
//! ```
//!
//! Why the CRC sits at a fixed offset at the end and covers the whole frame, padding included:
//! - the receiver checks integrity before it trusts any byte, the length included (a corrupted
//!   length can never make it read the wrong bytes as a CRC);
//! - every one of the 512 bits is protected, so every single-bit error, and every burst of up to
//!   16 bits anywhere in the 64 bytes, is detected (`crc16::verification` proves it for every error
//!   pattern; `examples/residual_error.rs` measures the rest);
//! - the CRC is stored most significant byte first, the order its bits leave the shift register, so
//!   the 64 bytes are one codeword of the cyclic code and the burst guarantee holds across the
//!   boundary between body and CRC too. Stored little-endian (as seed 001 does), a burst of 13 bits
//!   that ends in the CRC's low byte can pass the check (the exhaustive test in `crc16::verification`
//!   finds it);
//! - the work is the same for every frame (62 bytes), which keeps the receive path's time constant;
//! - a bus stuck at 0x00 or 0xFF fails the CRC (0x00… would need CRC 0x0000, 0xFF… would need 0xFFFF).
//!
//! The length is one byte before the payload because protobuf has no terminator: the padding
//! cannot be parsed as fields (a zero key is invalid). Padding must be zero, so each message has
//! exactly one valid frame.
//!
//! # Version and sequence
//!
//! Both messages carry `protocol_version` (must equal [`PROTOCOL_VERSION`]; a frame without it,
//! e.g. from the original seed-format sender, is refused with [`RejectReason::Version`]) and `seq`.
//! The Jetson increments the command `seq` for every new command; the MCU passes it to
//! [`statemachine::validate()`], which refuses a repeated or older value (serial-number arithmetic,
//! wrap-around allowed) as [`RejectReason::Stale`], so a frame replayed by a stuck DMA buffer or a
//! retransmitting bridge never feeds the watchdog. The feedback carries its own `seq` (the host
//! detects a frozen MCU that keeps sending the same buffer) and `cmd_seq`, the last command the MCU
//! accepted (the host measures the command round trip and sees rejections).
//!
//! # Identity and reset cause
//!
//! A feedback payload can take all 61 bytes, so the firmware's identity cannot ride in every
//! frame. The host asks for it instead: a command whose `request` is [`REQUEST_IDENTITY`] makes
//! the MCU send an [`McuInfo`] in the next feedback slot in place of a `MotorFeedback`.
//!
//! ```text
//!  MOSI   cmd n (request = 1)    cmd n+1             cmd n+2
//!  MISO   feedback (n−1)         McuInfo (seq k)     feedback (answers n+1, seq k+1)
//! ```
//! `McuInfo` uses field numbers 16 and up only and carries its own `info_version` (field 16)
//! instead of `protocol_version` (field 13), so neither decoder takes the other's frame:
//! [`decode_feedback`] of an info frame and [`decode_info`] of a feedback frame both fail with
//! [`RejectReason::Version`] (the version each expects is missing). [`decode_mcu_frame`] reads
//! whichever it is. The info frame carries the feedback sequence number, so the host's count of
//! feedback frames has no gap. The command's `request` is not part of [`Command`]: the ladder never
//! sees it, and a request this version does not define is ignored, never a reason to refuse the
//! command that carries it.

use crate::crc16;
use crate::pb::{self, DecodeError, Reader, Value, Writer};
use statemachine::{AxisCommand, Command, ControlMode, RejectReason};

/// Bytes per direction per SPI transaction.
pub const FRAME_LEN: usize = 64;

/// The protocol version both sides must send; bump it on any incompatible change.
pub const PROTOCOL_VERSION: u32 = 1;

/// Offset of the length byte.
pub const LEN_OFFSET: usize = 0;
/// Offset of the first payload byte.
pub const PAYLOAD_OFFSET: usize = 1;
/// Offset of the CRC (big-endian: most significant byte first), the last two bytes of the frame.
pub const CRC_OFFSET: usize = FRAME_LEN - 2;
/// Room for the protobuf payload.
pub const MAX_PAYLOAD: usize = CRC_OFFSET - PAYLOAD_OFFSET;

/// `MotorCommand.request`: send an [`McuInfo`] in the next feedback slot.
pub const REQUEST_IDENTITY: u32 = 1;

/// Largest `request` the encoder writes and the decoder takes: any `uint32`. The MCU must ignore a
/// request it does not define and still apply the command, so a newer host's request costs an
/// older MCU nothing but the answer; refusing the frame would cost a command (and count against
/// the link's quality).
pub const REQUEST_MAX: u32 = u32::MAX;

/// The `info_version` every [`McuInfo`] carries; bump it on any incompatible change of the message.
pub const INFO_VERSION: u32 = 1;

/// Field numbers of `MotorCommand` (they must match `proto/amr.proto`; a test checks).
pub mod command_field {
    /// `fixed32 timestamp_us`.
    pub const TIMESTAMP_US: u32 = 1;
    /// `float left_speed_cmd`.
    pub const LEFT_SPEED_CMD: u32 = 2;
    /// `float right_speed_cmd`.
    pub const RIGHT_SPEED_CMD: u32 = 3;
    /// `uint32 control_mode` (uint8 on the MCU).
    pub const CONTROL_MODE: u32 = 4;
    /// `uint32 enable` (uint8 on the MCU, 0 or 1).
    pub const ENABLE: u32 = 5;
    /// `fixed32 seq`.
    pub const SEQ: u32 = 7;
    /// `uint32 protocol_version`.
    pub const PROTOCOL_VERSION: u32 = 8;
    /// `uint32 request` (0 none, [`super::REQUEST_IDENTITY`]).
    pub const REQUEST: u32 = 9;
    /// Every field, in the order the encoder writes them.
    pub const ALL: [u32; 8] = [
        TIMESTAMP_US,
        LEFT_SPEED_CMD,
        RIGHT_SPEED_CMD,
        CONTROL_MODE,
        ENABLE,
        SEQ,
        PROTOCOL_VERSION,
        REQUEST,
    ];
}

/// Field numbers of `MotorFeedback` (they must match `proto/amr.proto`; a test checks).
pub mod feedback_field {
    /// `fixed32 timestamp_us`.
    pub const TIMESTAMP_US: u32 = 1;
    /// `float left_speed`.
    pub const LEFT_SPEED: u32 = 2;
    /// `float right_speed`.
    pub const RIGHT_SPEED: u32 = 3;
    /// `float left_current`.
    pub const LEFT_CURRENT: u32 = 4;
    /// `float right_current`.
    pub const RIGHT_CURRENT: u32 = 5;
    /// `sint32 left_encoder`.
    pub const LEFT_ENCODER: u32 = 6;
    /// `sint32 right_encoder`.
    pub const RIGHT_ENCODER: u32 = 7;
    /// `uint32 fault_flags` (uint16 on the MCU).
    pub const FAULT_FLAGS: u32 = 8;
    /// `fixed32 seq`.
    pub const SEQ: u32 = 10;
    /// `uint32 mode` (uint8 on the MCU).
    pub const MODE: u32 = 11;
    /// `fixed32 cmd_seq`.
    pub const CMD_SEQ: u32 = 12;
    /// `uint32 protocol_version`.
    pub const PROTOCOL_VERSION: u32 = 13;
    /// Every field, in the order the encoder writes them.
    pub const ALL: [u32; 12] = [
        TIMESTAMP_US,
        LEFT_SPEED,
        RIGHT_SPEED,
        LEFT_CURRENT,
        RIGHT_CURRENT,
        LEFT_ENCODER,
        RIGHT_ENCODER,
        FAULT_FLAGS,
        SEQ,
        MODE,
        CMD_SEQ,
        PROTOCOL_VERSION,
    ];
}

/// Field numbers of `McuInfo` (they must match `proto/amr.proto`; a test checks). All are 16 or
/// above, so none is a `MotorCommand` or `MotorFeedback` field; each key takes two bytes.
pub mod info_field {
    /// `uint32 info_version`, must equal [`super::INFO_VERSION`].
    pub const INFO_VERSION: u32 = 16;
    /// `uint32 fw_version`: major << 16 | minor << 8 | patch.
    pub const FW_VERSION: u32 = 17;
    /// `fixed32 git_hash`: the first 8 hex digits of the commit, 0 when unknown.
    pub const GIT_HASH: u32 = 18;
    /// `uint32 board`: [`super::BoardProfile`].
    pub const BOARD: u32 = 19;
    /// `uint32 build_date`: YYYYMMDD.
    pub const BUILD_DATE: u32 = 20;
    /// `uint32 reset_cause`: [`super::ResetCause`].
    pub const RESET_CAUSE: u32 = 21;
    /// `uint32 reset_count`: resets since power-on.
    pub const RESET_COUNT: u32 = 22;
    /// `uint32 panic_line`: source line of the last panic, 0 if none.
    pub const PANIC_LINE: u32 = 23;
    /// `fixed32 seq`: the feedback sequence number this frame took.
    pub const SEQ: u32 = 24;
    /// `bool dirty`: the build tree had uncommitted changes.
    pub const DIRTY: u32 = 25;
    /// Every field, in the order the encoder writes them.
    pub const ALL: [u32; 10] = [
        INFO_VERSION,
        FW_VERSION,
        GIT_HASH,
        BOARD,
        BUILD_DATE,
        RESET_CAUSE,
        RESET_COUNT,
        PANIC_LINE,
        SEQ,
        DIRTY,
    ];
}

/// Largest encoding of each `MotorCommand` field this encoder writes (key + value at its longest).
pub(crate) const fn command_field_max(field: u32) -> usize {
    use command_field as f;
    match field {
        f::CONTROL_MODE => pb::max_uint32(field),
        f::ENABLE => pb::max_uint32_upto(field, 1),
        f::PROTOCOL_VERSION => pb::max_uint32_upto(field, PROTOCOL_VERSION),
        f::REQUEST => pb::max_uint32_upto(field, REQUEST_MAX),
        _ => pb::max_fixed32(field),
    }
}

/// Largest encoding of each `MotorFeedback` field this encoder writes.
pub(crate) const fn feedback_field_max(field: u32) -> usize {
    use feedback_field as f;
    match field {
        f::LEFT_ENCODER | f::RIGHT_ENCODER => pb::max_sint32(field),
        f::FAULT_FLAGS | f::MODE => pb::max_uint32(field),
        f::PROTOCOL_VERSION => pb::max_uint32_upto(field, PROTOCOL_VERSION),
        _ => pb::max_fixed32(field),
    }
}

/// Largest encoding of each `McuInfo` field this encoder writes.
pub(crate) const fn info_field_max(field: u32) -> usize {
    use info_field as f;
    match field {
        f::INFO_VERSION => pb::max_uint32_upto(field, INFO_VERSION),
        f::BOARD => pb::max_uint32_upto(field, BoardProfile::MAX as u32),
        f::RESET_CAUSE => pb::max_uint32_upto(field, ResetCause::MAX as u32),
        f::DIRTY => pb::max_uint32_upto(field, 1),
        f::GIT_HASH | f::SEQ => pb::max_fixed32(field),
        _ => pb::max_uint32(field),
    }
}

/// Largest `MotorCommand` payload this encoder writes (every field at its longest).
pub const MAX_COMMAND_LEN: usize = {
    let mut total = 0;
    let mut rest: &[u32] = &command_field::ALL;
    while let [field, tail @ ..] = rest {
        total += command_field_max(*field);
        rest = tail;
    }
    total
};

/// Largest `MotorFeedback` payload this encoder writes (every field at its longest).
pub const MAX_FEEDBACK_LEN: usize = {
    let mut total = 0;
    let mut rest: &[u32] = &feedback_field::ALL;
    while let [field, tail @ ..] = rest {
        total += feedback_field_max(*field);
        rest = tail;
    }
    total
};

/// Largest `McuInfo` payload this encoder writes (every field at its longest).
pub const MAX_INFO_LEN: usize = {
    let mut total = 0;
    let mut rest: &[u32] = &info_field::ALL;
    while let [field, tail @ ..] = rest {
        total += info_field_max(*field);
        rest = tail;
    }
    total
};

/// nanopb's `amr_MotorCommand_size` for our `.options` (narrow fields at their declared size).
pub const NANOPB_COMMAND_SIZE: usize = {
    use command_field as f;
    MAX_COMMAND_LEN - pb::max_uint32(f::CONTROL_MODE) + pb::max_uint32_upto(f::CONTROL_MODE, 0xFF)
        - pb::max_uint32_upto(f::ENABLE, 1)
        + pb::max_uint32_upto(f::ENABLE, 0xFF)
        - pb::max_uint32_upto(f::PROTOCOL_VERSION, PROTOCOL_VERSION)
        + pb::max_uint32(f::PROTOCOL_VERSION)
};

/// nanopb's `amr_MotorFeedback_size` for our `.options`.
pub const NANOPB_FEEDBACK_SIZE: usize = {
    use feedback_field as f;
    MAX_FEEDBACK_LEN - pb::max_uint32(f::FAULT_FLAGS) + pb::max_uint32_upto(f::FAULT_FLAGS, 0xFFFF)
        - pb::max_uint32(f::MODE)
        + pb::max_uint32_upto(f::MODE, 0xFF)
        - pb::max_uint32_upto(f::PROTOCOL_VERSION, PROTOCOL_VERSION)
        + pb::max_uint32(f::PROTOCOL_VERSION)
};

/// nanopb's `amr_McuInfo_size` for our `.options` (`board` and `reset_cause` as `uint8`).
pub const NANOPB_INFO_SIZE: usize = {
    use info_field as f;
    MAX_INFO_LEN - pb::max_uint32_upto(f::INFO_VERSION, INFO_VERSION)
        + pb::max_uint32(f::INFO_VERSION)
        - pb::max_uint32_upto(f::BOARD, BoardProfile::MAX as u32)
        + pb::max_uint32_upto(f::BOARD, 0xFF)
        - pb::max_uint32_upto(f::RESET_CAUSE, ResetCause::MAX as u32)
        + pb::max_uint32_upto(f::RESET_CAUSE, 0xFF)
};

// The proof that every message fits its frame, checked by the compiler.
const _: () = assert!(MAX_COMMAND_LEN <= MAX_PAYLOAD);
const _: () = assert!(MAX_FEEDBACK_LEN <= MAX_PAYLOAD);
const _: () = assert!(MAX_INFO_LEN <= MAX_PAYLOAD);
const _: () = assert!(NANOPB_COMMAND_SIZE <= MAX_PAYLOAD);
const _: () = assert!(NANOPB_FEEDBACK_SIZE <= MAX_PAYLOAD);
const _: () = assert!(NANOPB_INFO_SIZE <= MAX_PAYLOAD);
// The length byte can hold every payload length.
const _: () = assert!(MAX_PAYLOAD <= u8::MAX as usize);
// The versions are one-byte varints, as the size bounds above assume.
const _: () = assert!(PROTOCOL_VERSION >= 1 && PROTOCOL_VERSION < 0x80);
const _: () = assert!(INFO_VERSION >= 1 && INFO_VERSION < 0x80);
// Every info field number needs a two-byte key and lies above every feedback field number, so an
// info frame never carries a field the feedback decoder reads (and the reverse).
const _: () = assert!(info_field::INFO_VERSION > feedback_field::PROTOCOL_VERSION);
const _: () =
    assert!(pb::key_len(info_field::INFO_VERSION) == 2 && pb::key_len(info_field::DIRTY) == 2);

/// Jetson → MCU, every 1 ms (seed 000 `MotorCommand`, plus sequence and version).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct MotorCommand {
    /// Jetson's microsecond clock when the command was built.
    pub timestamp_us: u32,
    /// Left wheel speed, rad/s at the wheel (unchecked: validation is the ladder's job).
    pub left_speed_cmd: f32,
    /// Right wheel speed, rad/s at the wheel.
    pub right_speed_cmd: f32,
    /// 0 idle, 1 speed, 2 position, 3 raw duty. Values above 255 cannot be sent (nanopb `uint8`):
    /// the encoder writes them, every decoder refuses them.
    pub control_mode: u32,
    /// Drive enable.
    pub enable: bool,
    /// Command sequence number: +1 for every new command, wrapping.
    pub seq: u32,
    /// What the host asks of the MCU besides the command: 0 nothing, [`REQUEST_IDENTITY`] an
    /// [`McuInfo`] in the next feedback slot. Not part of [`Command`]: the ladder never sees it.
    pub request: u32,
}

/// MCU → Jetson, in the same transaction (seed 000 `MotorFeedback`, plus sequence, mode and version).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct MotorFeedback {
    /// MCU's microsecond clock when the frame was prepared.
    pub timestamp_us: u32,
    /// Measured left wheel speed, rad/s.
    pub left_speed: f32,
    /// Measured right wheel speed, rad/s.
    pub right_speed: f32,
    /// Measured left motor current, A.
    pub left_current: f32,
    /// Measured right motor current, A.
    pub right_current: f32,
    /// Cumulative left encoder count.
    pub left_encoder: i32,
    /// Cumulative right encoder count.
    pub right_encoder: i32,
    /// [`statemachine::FaultFlags`] bits; values above 0xFFFF cannot be sent (nanopb `uint16`).
    pub fault_flags: u32,
    /// Feedback sequence number: +1 per frame, wrapping.
    pub seq: u32,
    /// Ladder rung ([`statemachine::Mode`] as u8: 0 NORMAL … 4 BRAKE); values above 255 cannot be sent.
    pub mode: u32,
    /// `seq` of the last command the MCU accepted (0 before the first).
    pub cmd_seq: u32,
}

/// The link profile a firmware image was built for (`McuInfo.board`). Wire values are fixed and
/// never reused; a value this version does not define is refused ([`RejectReason::Decode`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
#[repr(u8)]
pub enum BoardProfile {
    /// Seed 000: Jetson ↔ STM32 SPI, this module's frames.
    #[default]
    AmrSpi = 0,
    /// Seed 001: USB CDC / UART.
    Cdc = 1,
    /// Seed 003: Teensy serial.
    Teensy = 2,
    /// Seed 004: Raspberry Pi SPI.
    PiSpi = 3,
}

impl BoardProfile {
    /// Every profile, in wire-value order.
    pub const ALL: [Self; 4] = [Self::AmrSpi, Self::Cdc, Self::Teensy, Self::PiSpi];
    /// The largest wire value.
    pub const MAX: u8 = Self::PiSpi as u8;

    /// The profile with wire value `v`, `None` if this version does not define it.
    pub const fn from_wire(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::AmrSpi,
            1 => Self::Cdc,
            2 => Self::Teensy,
            3 => Self::PiSpi,
            _ => return None,
        })
    }
}

/// Why the MCU last started (`McuInfo.reset_cause`), from the reset controller's flags (and the
/// firmware's own record of a panic or a software reset). Wire values are fixed and never reused;
/// a value this version does not define is refused ([`RejectReason::Decode`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
#[repr(u8)]
pub enum ResetCause {
    /// No flag set, or a combination the firmware cannot attribute.
    #[default]
    Unknown = 0,
    /// Power-on / power-down reset: the supply came up.
    PowerOn = 1,
    /// The NRST pin was pulled low (reset button, debugger).
    Pin = 2,
    /// The independent watchdog expired: the firmware stopped feeding it.
    IndependentWatchdog = 3,
    /// The firmware panicked and reset itself (`McuInfo.panic_line` says where).
    Panic = 4,
    /// A deliberate software reset (`SYSRESETREQ`), e.g. after a firmware update.
    Software = 5,
    /// The supply dipped below the brown-out threshold.
    Brownout = 6,
    /// The window watchdog was fed too early or too late.
    WindowWatchdog = 7,
    /// Reset on entering Standby or Stop with the low-power reset option set.
    LowPower = 8,
}

impl ResetCause {
    /// Every cause, in wire-value order.
    pub const ALL: [Self; 9] = [
        Self::Unknown,
        Self::PowerOn,
        Self::Pin,
        Self::IndependentWatchdog,
        Self::Panic,
        Self::Software,
        Self::Brownout,
        Self::WindowWatchdog,
        Self::LowPower,
    ];
    /// The largest wire value.
    pub const MAX: u8 = Self::LowPower as u8;

    /// The cause with wire value `v`, `None` if this version does not define it.
    pub const fn from_wire(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Unknown,
            1 => Self::PowerOn,
            2 => Self::Pin,
            3 => Self::IndependentWatchdog,
            4 => Self::Panic,
            5 => Self::Software,
            6 => Self::Brownout,
            7 => Self::WindowWatchdog,
            8 => Self::LowPower,
            _ => return None,
        })
    }
}

/// MCU → Jetson, in the feedback slot after a command with `request` = [`REQUEST_IDENTITY`]: which
/// firmware runs, on which link profile, and why it last reset. Field numbers 16 to 25, with
/// `info_version` in place of `protocol_version` (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct McuInfo {
    /// Firmware version, `major << 16 | minor << 8 | patch` (see [`pack_fw_version`]).
    pub fw_version: u32,
    /// The first 8 hex digits of the firmware's commit as a number, 0 when unknown
    /// (see [`git_hash_from_hex`]).
    pub git_hash: u32,
    /// The link profile the image was built for.
    pub board: BoardProfile,
    /// Build date as the decimal number YYYYMMDD (20261130), 0 when unknown.
    pub build_date: u32,
    /// Why the MCU last started.
    pub reset_cause: ResetCause,
    /// Resets since power-on (0 after a power-on reset).
    pub reset_count: u32,
    /// Source line of the last panic, 0 if none is recorded.
    pub panic_line: u32,
    /// The feedback sequence number this frame took (the next feedback carries `seq + 1`).
    pub seq: u32,
    /// The build tree had uncommitted changes.
    pub dirty: bool,
}

/// `major << 16 | minor << 8 | patch`, the layout of [`McuInfo::fw_version`].
pub const fn pack_fw_version(major: u16, minor: u8, patch: u8) -> u32 {
    ((major as u32) << 16) | ((minor as u32) << 8) | patch as u32
}

/// The first 8 hex digits of a commit id (`"1a2b3c4d…"`, either case) as a number, the layout of
/// [`McuInfo::git_hash`]; 0 (unknown) if the text is shorter than 8 digits or not hex. A `const fn`,
/// so a build can turn `env!("GIT_HASH")` into the constant it sends.
pub const fn git_hash_from_hex(hex: &str) -> u32 {
    let mut rest = hex.as_bytes();
    let mut value = 0u32;
    let mut digits = 0u32;
    while digits < 8 {
        let [b, tail @ ..] = rest else {
            return 0;
        };
        let digit = match *b {
            b'0'..=b'9' => b.wrapping_sub(b'0'),
            b'a'..=b'f' => b.wrapping_sub(b'a').wrapping_add(10),
            b'A'..=b'F' => b.wrapping_sub(b'A').wrapping_add(10),
            _ => return 0,
        };
        value = (value << 4) | digit as u32;
        rest = tail;
        digits = digits.wrapping_add(1);
    }
    value
}

impl McuInfo {
    /// `(major, minor, patch)` of [`McuInfo::fw_version`].
    pub const fn fw_version_parts(&self) -> (u16, u8, u8) {
        let v = self.fw_version;
        ((v >> 16) as u16, (v >> 8) as u8, v as u8)
    }

    /// `(year, month, day)` of [`McuInfo::build_date`] (no calendar check: 20261399 gives month 13).
    pub const fn build_date_parts(&self) -> (u32, u32, u32) {
        let d = self.build_date;
        (d / 10_000, (d / 100) % 100, d % 100)
    }
}

/// What the MCU sent in a feedback slot.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum McuFrame {
    /// The usual feedback.
    Feedback(MotorFeedback),
    /// The answer to [`REQUEST_IDENTITY`].
    Info(McuInfo),
}

impl MotorCommand {
    /// The command as the safety core sees it (the ladder validates it); `request` is not part of it.
    ///
    /// `control_mode` maps onto the axes' drive modes: speed → velocity, position → position (no cap:
    /// the seed's message has none), raw duty → duty; the seed 000 profile accepts velocity only and
    /// refuses the others. Idle → zero velocity targets (stopping, always allowed); a non-finite speed
    /// in an idle frame is kept so the ladder still refuses the frame as corrupt. A mode the seed
    /// does not define is refused here as [`RejectReason::UnknownMode`].
    pub fn to_command(&self) -> Result<Command<2>, RejectReason> {
        let mode = ControlMode::from_raw(self.control_mode).ok_or(RejectReason::UnknownMode)?;
        let axis = |x: f32| match mode {
            ControlMode::Idle => AxisCommand::velocity(if x.is_finite() { 0.0 } else { x }),
            ControlMode::Speed => AxisCommand::velocity(x),
            ControlMode::Position => AxisCommand::position(x, 0.0),
            ControlMode::RawDuty => AxisCommand::duty(x),
        };
        Ok(Command {
            axes: [axis(self.left_speed_cmd), axis(self.right_speed_cmd)],
            enable: self.enable,
            seq: Some(self.seq),
            timeout: None,
        })
    }
}

impl MotorFeedback {
    /// Fills the ladder-derived fields from the ladder's output.
    pub fn with_output<const N: usize>(mut self, out: &statemachine::Output<N>) -> Self {
        self.fault_flags = u32::from(out.faults.0);
        self.mode = u32::from(out.mode as u8);
        self
    }
}

fn seal(out: &mut [u8; FRAME_LEN], payload_len: usize) {
    if let Some(len) = out.get_mut(LEN_OFFSET) {
        // payload_len ≤ MAX_PAYLOAD ≤ 255 (const-asserted).
        *len = u8::try_from(payload_len).unwrap_or(u8::MAX);
    }
    let crc = crc16::checksum(out.get(..CRC_OFFSET).unwrap_or(&[]));
    if let Some(slot) = out.get_mut(CRC_OFFSET..) {
        slot.copy_from_slice(&crc.to_be_bytes());
    }
}

/// Checks CRC, length and padding; returns the payload.
fn open(frame: &[u8; FRAME_LEN]) -> Result<&[u8], RejectReason> {
    let (body, crc) = frame.split_at(CRC_OFFSET);
    let mut stored = [0u8; 2];
    stored.copy_from_slice(crc);
    if crc16::checksum(body) != u16::from_be_bytes(stored) {
        return Err(RejectReason::Crc);
    }
    let len = usize::from(*body.get(LEN_OFFSET).ok_or(RejectReason::Framing)?);
    let end = PAYLOAD_OFFSET.saturating_add(len);
    let payload = body.get(PAYLOAD_OFFSET..end).ok_or(RejectReason::Framing)?;
    if !padding_is_zero(frame, end) {
        return Err(RejectReason::Framing);
    }
    Ok(payload)
}

/// True if bytes `from..CRC_OFFSET` of `frame` are all zero (none when `from ≥ CRC_OFFSET`).
///
/// A word at a time (the padding is most of the frame), down from the CRC: the frame is 16 words
/// (`k`-th: bytes `4k .. 4k + 4`), read from word 15 down to the word that holds `from`, each at a
/// place fixed by the loop's count alone; the first word read loses the CRC's two bytes and the
/// last the payload bytes before `from`. Read up from `from` instead, every word's place would be
/// one the frame's length byte gives, which a model checker has to search.
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
fn padding_is_zero(frame: &[u8; FRAME_LEN], from: usize) -> bool {
    // The CRC takes the last two bytes of word 15: little-endian, those are its upper half.
    const _: () = assert!(CRC_OFFSET == 4 * 15 + 2 && FRAME_LEN == 4 * 16);
    const BEFORE_CRC: u32 = 0x0000_FFFF;
    if from >= CRC_OFFSET {
        return true;
    }
    let (words, _) = frame.as_chunks::<4>();
    // from < 62, so first ≤ 15 and every k below is within the 16 words.
    let first = from / 4;
    let mut k = 15;
    let mut word = u32::from_le_bytes(words[k]) & BEFORE_CRC;
    let mut ored = 0u32;
    while k > first {
        ored |= word;
        k -= 1;
        word = u32::from_le_bytes(words[k]);
    }
    // Word `first` holds `from`, (from % 4) bytes in: the bytes before it are payload.
    ored |= word & (u32::MAX << (8 * (from % 4)));
    ored == 0
}

/// Encodes `cmd` into a complete frame (length, payload, zero padding, CRC); `protocol_version` is
/// written as [`PROTOCOL_VERSION`].
pub fn encode_command(cmd: &MotorCommand, out: &mut [u8; FRAME_LEN]) {
    out.fill(0);
    let len = {
        let mut w = Writer::new(out.get_mut(PAYLOAD_OFFSET..CRC_OFFSET).unwrap_or(&mut []));
        write_command(&mut w, cmd);
        w.len()
    };
    seal(out, len);
}

/// The payload is the fields of [`command_field::ALL`], one after the other, each as
/// [`write_command_field`] writes it (the round-trip proof reads it that way).
///
/// One call per field rather than a loop, so that each field number is a constant and the `match`
/// in the writer folds away (a loop cost about 130 instructions per feedback frame on the MCU);
/// the pattern takes the numbers from `ALL`, in its order, so the two cannot disagree.
fn write_command(w: &mut Writer<'_>, cmd: &MotorCommand) {
    let [f0, f1, f2, f3, f4, f5, f6, f7] = command_field::ALL;
    write_command_field(w, cmd, f0);
    write_command_field(w, cmd, f1);
    write_command_field(w, cmd, f2);
    write_command_field(w, cmd, f3);
    write_command_field(w, cmd, f4);
    write_command_field(w, cmd, f5);
    write_command_field(w, cmd, f6);
    write_command_field(w, cmd, f7);
}

/// One field of `cmd` (nothing if it holds its default value; unknown numbers write nothing).
#[inline(always)]
fn write_command_field(w: &mut Writer<'_>, cmd: &MotorCommand, field: u32) {
    use command_field as f;
    match field {
        f::TIMESTAMP_US => w.fixed32(field, cmd.timestamp_us),
        f::LEFT_SPEED_CMD => w.float(field, cmd.left_speed_cmd),
        f::RIGHT_SPEED_CMD => w.float(field, cmd.right_speed_cmd),
        f::CONTROL_MODE => w.uint32(field, cmd.control_mode),
        f::ENABLE => w.uint32(field, u32::from(cmd.enable)),
        f::SEQ => w.fixed32(field, cmd.seq),
        f::PROTOCOL_VERSION => w.uint32(field, PROTOCOL_VERSION),
        f::REQUEST => w.uint32(field, cmd.request),
        _ => {}
    }
}

/// Encodes `fb` into a complete frame; `protocol_version` is written as [`PROTOCOL_VERSION`].
pub fn encode_feedback(fb: &MotorFeedback, out: &mut [u8; FRAME_LEN]) {
    out.fill(0);
    let len = {
        let mut w = Writer::new(out.get_mut(PAYLOAD_OFFSET..CRC_OFFSET).unwrap_or(&mut []));
        write_feedback(&mut w, fb);
        w.len()
    };
    seal(out, len);
}

/// The payload is the fields of [`feedback_field::ALL`], one after the other, each as
/// [`write_feedback_field`] writes it (one call per field, as in [`write_command`]).
fn write_feedback(w: &mut Writer<'_>, fb: &MotorFeedback) {
    let [f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11] = feedback_field::ALL;
    write_feedback_field(w, fb, f0);
    write_feedback_field(w, fb, f1);
    write_feedback_field(w, fb, f2);
    write_feedback_field(w, fb, f3);
    write_feedback_field(w, fb, f4);
    write_feedback_field(w, fb, f5);
    write_feedback_field(w, fb, f6);
    write_feedback_field(w, fb, f7);
    write_feedback_field(w, fb, f8);
    write_feedback_field(w, fb, f9);
    write_feedback_field(w, fb, f10);
    write_feedback_field(w, fb, f11);
}

/// One field of `fb` (nothing if it holds its default value; unknown numbers write nothing).
#[inline(always)]
fn write_feedback_field(w: &mut Writer<'_>, fb: &MotorFeedback, field: u32) {
    use feedback_field as f;
    match field {
        f::TIMESTAMP_US => w.fixed32(field, fb.timestamp_us),
        f::LEFT_SPEED => w.float(field, fb.left_speed),
        f::RIGHT_SPEED => w.float(field, fb.right_speed),
        f::LEFT_CURRENT => w.float(field, fb.left_current),
        f::RIGHT_CURRENT => w.float(field, fb.right_current),
        f::LEFT_ENCODER => w.sint32(field, fb.left_encoder),
        f::RIGHT_ENCODER => w.sint32(field, fb.right_encoder),
        f::FAULT_FLAGS => w.uint32(field, fb.fault_flags),
        f::SEQ => w.fixed32(field, fb.seq),
        f::MODE => w.uint32(field, fb.mode),
        f::CMD_SEQ => w.fixed32(field, fb.cmd_seq),
        f::PROTOCOL_VERSION => w.uint32(field, PROTOCOL_VERSION),
        _ => {}
    }
}

/// Encodes `info` into a complete frame; `info_version` is written as [`INFO_VERSION`].
pub fn encode_info(info: &McuInfo, out: &mut [u8; FRAME_LEN]) {
    out.fill(0);
    let len = {
        let mut w = Writer::new(out.get_mut(PAYLOAD_OFFSET..CRC_OFFSET).unwrap_or(&mut []));
        write_info(&mut w, info);
        w.len()
    };
    seal(out, len);
}

/// The payload is the fields of [`info_field::ALL`], one after the other, each as
/// [`write_info_field`] writes it (one call per field, as in [`write_command`]).
fn write_info(w: &mut Writer<'_>, info: &McuInfo) {
    let [f0, f1, f2, f3, f4, f5, f6, f7, f8, f9] = info_field::ALL;
    write_info_field(w, info, f0);
    write_info_field(w, info, f1);
    write_info_field(w, info, f2);
    write_info_field(w, info, f3);
    write_info_field(w, info, f4);
    write_info_field(w, info, f5);
    write_info_field(w, info, f6);
    write_info_field(w, info, f7);
    write_info_field(w, info, f8);
    write_info_field(w, info, f9);
}

/// One field of `info` (nothing if it holds its default value; unknown numbers write nothing).
#[inline(always)]
fn write_info_field(w: &mut Writer<'_>, info: &McuInfo, field: u32) {
    use info_field as f;
    match field {
        f::INFO_VERSION => w.uint32(field, INFO_VERSION),
        f::FW_VERSION => w.uint32(field, info.fw_version),
        f::GIT_HASH => w.fixed32(field, info.git_hash),
        f::BOARD => w.uint32(field, u32::from(info.board as u8)),
        f::BUILD_DATE => w.uint32(field, info.build_date),
        f::RESET_CAUSE => w.uint32(field, u32::from(info.reset_cause as u8)),
        f::RESET_COUNT => w.uint32(field, info.reset_count),
        f::PANIC_LINE => w.uint32(field, info.panic_line),
        f::SEQ => w.fixed32(field, info.seq),
        f::DIRTY => w.uint32(field, u32::from(info.dirty)),
        _ => {}
    }
}

/// Decodes a command frame.
///
/// Checks, in order: CRC ([`RejectReason::Crc`]); length ≤ [`MAX_PAYLOAD`] and zero padding
/// ([`RejectReason::Framing`]); protobuf ([`RejectReason::Decode`]: truncated, wrong wire type for a
/// known field, `enable` not 0/1, `control_mode` > 255); version ([`RejectReason::Version`]).
/// Unknown fields are skipped; a repeated field keeps its last value. Any `request` value is taken.
pub fn decode_command(frame: &[u8; FRAME_LEN]) -> Result<MotorCommand, RejectReason> {
    decode_message(frame, PROTOCOL_VERSION, apply_command_field)
}

/// The steps every message shares: `open` the frame, then [`decode_payload`].
#[inline(always)]
fn decode_message<M: Default>(
    frame: &[u8; FRAME_LEN],
    version: u32,
    apply: impl Fn(&mut (M, u32), u32, Value) -> Result<(), DecodeError>,
) -> Result<M, RejectReason> {
    decode_payload(open(frame)?, version, apply)
}

/// Reads the fields of an opened payload into a default message with `apply` (which keeps the
/// message's version field beside it), then checks that the version read equals `version`.
#[inline(always)]
fn decode_payload<M: Default>(
    payload: &[u8],
    version: u32,
    apply: impl Fn(&mut (M, u32), u32, Value) -> Result<(), DecodeError>,
) -> Result<M, RejectReason> {
    let mut msg = (M::default(), 0);
    let mut r = Reader::new(payload);
    let mut read_all = || -> Result<(), DecodeError> {
        while let Some((field, v)) = r.next_field()? {
            apply(&mut msg, field, v)?;
        }
        Ok(())
    };
    read_all().map_err(|_| RejectReason::Decode)?;
    let (m, read) = msg;
    if read != version {
        return Err(RejectReason::Version);
    }
    Ok(m)
}

/// One field of a `MotorCommand` payload into the message and version decoded so far.
#[inline(always)]
fn apply_command_field(
    (cmd, version): &mut (MotorCommand, u32),
    field: u32,
    v: Value,
) -> Result<(), DecodeError> {
    use command_field as f;
    match field {
        f::TIMESTAMP_US => cmd.timestamp_us = v.fixed32()?,
        f::LEFT_SPEED_CMD => cmd.left_speed_cmd = v.float()?,
        f::RIGHT_SPEED_CMD => cmd.right_speed_cmd = v.float()?,
        f::CONTROL_MODE => cmd.control_mode = v.uint32_upto(0xFF)?,
        f::ENABLE => cmd.enable = v.uint32_upto(1)? == 1,
        f::SEQ => cmd.seq = v.fixed32()?,
        f::PROTOCOL_VERSION => *version = v.uint32()?,
        f::REQUEST => cmd.request = v.uint32_upto(REQUEST_MAX)?,
        _ => {}
    }
    Ok(())
}

/// Decodes a feedback frame; the same checks as [`decode_command`] (`fault_flags` > 0xFFFF and
/// `mode` > 255 are [`RejectReason::Decode`]). An [`McuInfo`] frame is refused as
/// [`RejectReason::Version`] (it carries no `protocol_version`); [`decode_mcu_frame`] takes both.
pub fn decode_feedback(frame: &[u8; FRAME_LEN]) -> Result<MotorFeedback, RejectReason> {
    decode_message(frame, PROTOCOL_VERSION, apply_feedback_field)
}

/// One field of a `MotorFeedback` payload into the message and version decoded so far.
#[inline(always)]
fn apply_feedback_field(
    (fb, version): &mut (MotorFeedback, u32),
    field: u32,
    v: Value,
) -> Result<(), DecodeError> {
    use feedback_field as f;
    match field {
        f::TIMESTAMP_US => fb.timestamp_us = v.fixed32()?,
        f::LEFT_SPEED => fb.left_speed = v.float()?,
        f::RIGHT_SPEED => fb.right_speed = v.float()?,
        f::LEFT_CURRENT => fb.left_current = v.float()?,
        f::RIGHT_CURRENT => fb.right_current = v.float()?,
        f::LEFT_ENCODER => fb.left_encoder = v.sint32()?,
        f::RIGHT_ENCODER => fb.right_encoder = v.sint32()?,
        f::FAULT_FLAGS => fb.fault_flags = v.uint32_upto(0xFFFF)?,
        f::SEQ => fb.seq = v.fixed32()?,
        f::MODE => fb.mode = v.uint32_upto(0xFF)?,
        f::CMD_SEQ => fb.cmd_seq = v.fixed32()?,
        f::PROTOCOL_VERSION => *version = v.uint32()?,
        _ => {}
    }
    Ok(())
}

/// Decodes an info frame; the same checks as [`decode_command`], with `info_version` (field 16)
/// in place of `protocol_version`: missing or not [`INFO_VERSION`] is [`RejectReason::Version`]
/// (so a feedback frame is refused that way), a `board` or `reset_cause` this version does not
/// define, or `dirty` not 0/1, is [`RejectReason::Decode`].
pub fn decode_info(frame: &[u8; FRAME_LEN]) -> Result<McuInfo, RejectReason> {
    decode_message(frame, INFO_VERSION, apply_info_field)
}

/// One field of an `McuInfo` payload into the message and `info_version` decoded so far.
#[inline(always)]
fn apply_info_field(
    (info, version): &mut (McuInfo, u32),
    field: u32,
    v: Value,
) -> Result<(), DecodeError> {
    use info_field as f;
    match field {
        f::INFO_VERSION => *version = v.uint32()?,
        f::FW_VERSION => info.fw_version = v.uint32()?,
        f::GIT_HASH => info.git_hash = v.fixed32()?,
        f::BOARD => info.board = BoardProfile::from_wire(v.uint32()?).ok_or(DecodeError)?,
        f::BUILD_DATE => info.build_date = v.uint32()?,
        f::RESET_CAUSE => {
            info.reset_cause = ResetCause::from_wire(v.uint32()?).ok_or(DecodeError)?;
        }
        f::RESET_COUNT => info.reset_count = v.uint32()?,
        f::PANIC_LINE => info.panic_line = v.uint32()?,
        f::SEQ => info.seq = v.fixed32()?,
        f::DIRTY => info.dirty = v.uint32_upto(1)? == 1,
        _ => {}
    }
    Ok(())
}

/// Decodes whatever the MCU sent in a feedback slot: a `MotorFeedback`, or the `McuInfo` it sends
/// in its place after [`REQUEST_IDENTITY`]. The frame is opened once; a payload the feedback decoder
/// refuses as [`RejectReason::Version`] is read again as an info payload, and the result is then the
/// info decoder's (still `Version` for a payload with neither version). A payload carrying both
/// versions is a feedback.
pub fn decode_mcu_frame(frame: &[u8; FRAME_LEN]) -> Result<McuFrame, RejectReason> {
    let payload = open(frame)?;
    match decode_payload(payload, PROTOCOL_VERSION, apply_feedback_field) {
        Err(RejectReason::Version) => {
            decode_payload(payload, INFO_VERSION, apply_info_field).map(McuFrame::Info)
        }
        other => other.map(McuFrame::Feedback),
    }
}

/// The ladder event for a received command frame: `Frame(command)` or `Rejected(reason)`.
pub fn command_event(frame: &[u8; FRAME_LEN]) -> statemachine::Event<2> {
    crate::event_from(decode_command(frame).and_then(|c| c.to_command()))
}

#[cfg(test)]
mod tests;

#[cfg(any(test, kani))]
mod verification;
