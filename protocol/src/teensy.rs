//! Seed 003: the Jetson ↔ Teensy serial packet, the legacy `\n`-delimited `CmdMsg` union and its COBS + CRC successor.
//!
//! # Legacy packet (compatibility)
//!
//! The C union `Packet { CmdMsg msg; char bytes[sizeof(CmdMsg) + 1]; }`, sent as raw bytes with
//! `'\n'` (0x0A) in the last byte. On both ends (Teensy 3.2 Cortex-M4, Jetson aarch64) `int` and
//! the enum are 32-bit little-endian and the struct has no padding:
//!
//! ```text
//!  off       size  field
//!    0         4   i32 cmd_type (0 MTRS, 1 CAL, 2 ENDEFF_ON, 3 ENDEFF_OFF, 4 CONFIG)
//!    4         4   i32 is_relative
//!    8       4·N   i32 mtr_angles[N]          (N = MAX_SUPPORTED_MTRS, a const generic here)
//!    8+4N      4   i32 mtr_speed_deg_s
//!   12+4N      4   i32 mtr_accel_deg_s_s
//!   16+4N      4   i32 cmd_success            (set by the Teensy in its echo)
//!   20+4N      1   '\n'
//! ```
//! [`CmdMsg::decode_legacy`] accepts only a packet of exactly the right length ending in `'\n'`
//! ([`RejectReason::Framing`] otherwise). The delimiter is not an escape: any field may contain
//! 0x0A, and nothing detects corrupted bytes. A receiver that splits the stream after each `'\n'`
//! and decodes each piece therefore mis-splits (N = 4, test
//! `legacy_split_on_newline_loses_and_corrupts_commands`):
//!
//! ```text
//!  A = MTRS, angles [10, 0, 0, 0], speed 30, accel 60, 37 bytes:
//!  00 00 00 00 00 00 00 00 0A | 00 00 00 (00 00 00 00)×3 1E 00 00 00 3C 00 00 00 00 00 00 00 0A
//!  └──── piece 1: 9 bytes ───┘ └──────────────────── piece 2: 28 bytes ─────────────────────────┘
//! ```
//!
//! - *Lost:* both pieces are refused, so A, and every command with a 0x0A in a field (an angle of
//!   10°, 2,560° or −246°, a speed of 10 deg/s, …), never arrives, however often it is sent.
//! - *Forged:* if A's `'\n'` is lost on the line and B (A with angle 2,560: `00 0A 00 00`)
//!   follows, the 37 bytes from A's offset 9 to B's offset 9 end in 0x0A and decode as MTRS with
//!   angles [0, 503316480, 1006632960, 0] (A's speed and acceleration bytes, shifted): a command
//!   neither end sent.
//!
//! So no receiver of this framing can deliver every packet at its delimiter and refuse every
//! piece that is not one: without a CRC, the 37 bytes before a 0x0A in a field can decode as well
//! as a packet. `decode_legacy` stays as it is, for compatibility; the robust successor below has
//! the property.
//!
//! # Robust successor (version 2)
//!
//! The same `CmdMsg` bytes behind a version byte, COBS-encoded, followed by a CRC of the bytes as
//! sent, and ended by 0x00. No other byte of the frame is 0x00, so a receiver always
//! resynchronises at the next 0x00, and [`RobustDecoder`] delivers a valid frame at its 0x00
//! whatever came before it:
//!
//! ```text
//!  frame = S | K0 K1 K2 | 0x00
//!  S     = COBS( ROBUST_VERSION = 2 (1 B) | CmdMsg (20+4N B) )     one COBS block: 22+4N B, no 0x00
//!  crc   = CRC-16/CCITT-FALSE over S, the stuffed bytes exactly as sent (code bytes included)
//!  K0    = 0x80 | crc >> 14                                         (bits 6..2 zero)
//!  K1    = 0x80 | (crc >> 7) & 0x7F
//!  K2    = 0x80 | crc & 0x7F
//! ```
//!
//! The version and message (`21 + 4N` bytes, fewer than 254 for every motor count up to
//! [`MAX_MOTORS`]) always stuff to one COBS block of one code byte more, and the check bytes are
//! never zero, so every frame of `N` motors has the same length, [`CmdMsg::ROBUST_LEN`] =
//! `(22 + 4N) + 3 + 1`. Example, N = 1, the command `MTRS, is_relative −63191, angle 0, speed 32,
//! accel 0, cmd_success 4` (30 bytes):
//!
//! ```text
//!  S:  02 02 01 01 01 05 29 09 ff ff 01 01 01 02 20 01 01 01 01 01 01 02 04 01 01 01
//!  K:  83 9d ce                 (crc 0xcece = 11 | 0011101 | 1001110)
//!  00
//! ```
//!
//! The Teensy echoes the command with `cmd_success` = 1 (done) or 0 (refused) in the same format
//! ([`CmdMsg::reply`]). [`CmdMsg::decode_robust`] checks, in this order:
//!
//! 1. the length and the trailing 0x00 → [`RejectReason::Framing`];
//! 2. the check bytes: bit 7 clear in one of them, or a bit of 6..2 set in `K0` →
//!    [`RejectReason::Crc`];
//! 3. the CRC over `S` against the value the check bytes carry → [`RejectReason::Crc`];
//! 4. COBS undone on `S` (a code chain that does not end exactly at the end of `S`, or a zero
//!    inside) → [`RejectReason::Framing`];
//! 5. the version byte → [`RejectReason::Version`];
//! 6. `cmd_type` → [`RejectReason::Decode`].
//!
//! The crate's own one-block COBS encoder (`stuff_into`) makes `S`, and its decoder
//! (`unstuff`) reads and writes only at fixed positions; Kani proves that the decoder inverts the
//! encoder and is total (`teensy::verification`); the tests cross-check both against the
//! crate `corncobs`.
//!
//! ## Why the CRC covers the bytes as sent
//!
//! Version 1 of this frame was `COBS(1 | CmdMsg | CRC-16 LE over 1 | CmdMsg) | 0x00`: a CRC over
//! the body *before* COBS. Such a CRC does not cover the COBS code bytes. A code byte says where
//! the decoder puts the body's next zero, so one flipped bit in a code byte moves zeros: the frame
//! can still decode to a body of the right length whose error is several bytes at positions that
//! depend on the content, and a 16-bit CRC passes such a multi-byte pattern about once in 2¹⁶.
//! A search over 2·10⁷ random one-motor frames (every single-bit flip of each,
//! 4.5·10⁹ flips) found 8 flips that version 1 accepted, for instance bit 2 of byte 17 of
//!
//! ```text
//!  02 01 01 01 01 05 29 09 ff ff 01 01 01 02 20 01 01 01 01 01 01 02 04 01 01 03 02 32 00
//! ```
//!
//! (the command above; the code byte 0x01 becomes 0x05), which decodes to the same command with
//! `mtr_accel_deg_s_s` 33620225 and `cmd_success` 50397440 (test
//! `a_code_byte_flip_the_body_crc_missed_is_refused`).
//!
//! Version 2 checks the CRC over the stuffed bytes before anything is unstuffed, so a flipped bit
//! is judged on the wire, where it is one bit:
//!
//! - a flip in `S` is a one-bit error of the CRC's codeword, which CRC-16/CCITT-FALSE always
//!   catches (it catches every burst of up to 16 bits within `S`: test
//!   `every_burst_within_the_stuffed_bytes_changes_the_crc`);
//! - a flip in `K` either breaks a fixed bit (bit 7 of each, bits 6..2 of `K0`) or changes the
//!   16-bit value the check bytes carry, which then differs from the CRC of the unchanged `S`;
//! - a flip of the 0x00 leaves no terminator.
//!
//! Whether an error pattern is caught does not depend on the frame's content (the CRC is affine
//! over GF(2), see `crc16::verification`, and the check bytes' fixed bits are checked by place),
//! so checking every single-bit flip of one frame of a
//! length checks every frame of that length: the Kani harness `verify_bit_flip_refused` does that
//! for one motor, and the tests for 1, 4 and 16 motors.
//!
//! The check bytes carry 7 bits each so that none of them is ever 0x00 (COBS framing stays
//! intact) without a second COBS pass over the CRC.
//!
//! # Mapping onto the safety core
//!
//! `CMDTYPE_MTRS` carries motor angles (a position command): [`CmdMsg::to_event`] maps every motor to
//! a position axis (degrees → rad) under the message's speed as the cap, which the seed 003 profile
//! (`statemachine::Config::TEENSY`, joints within ±π rad) accepts; the other command types concern
//! the arm's configuration and calibration and give no ladder event.

use crate::crc16;
use crate::le;
use statemachine::{AxisCommand, Command, Event, RejectReason};

/// The largest motor count supported by the robust stream decoder's buffer.
pub const MAX_MOTORS: usize = 16;
/// Version byte of the robust successor frame (2: the CRC covers the stuffed bytes; see the module
/// documentation for why version 1's layout was replaced).
pub const ROBUST_VERSION: u8 = 2;
/// The legacy delimiter.
pub const DELIMITER: u8 = b'\n';
/// Check bytes of a robust frame: the CRC's 16 bits, 7 per byte, bit 7 of each set.
pub const CHECK_LEN: usize = 3;

/// Bytes of `CmdMsg` with `n` motors (`sizeof(CmdMsg)`).
pub const fn msg_len(n: usize) -> usize {
    4usize.saturating_mul(5usize.saturating_add(n))
}

/// Bytes of a legacy packet with `n` motors (`sizeof(Packet)`).
pub const fn legacy_len(n: usize) -> usize {
    msg_len(n).saturating_add(1)
}

/// Bytes before COBS of a robust frame with `n` motors: the version and the message.
pub const fn robust_body_len(n: usize) -> usize {
    msg_len(n).saturating_add(1)
}

/// Bytes of the stuffed part `S` of a robust frame with `n` motors: the body and one COBS code
/// byte (the body is one COBS block, fewer than 254 bytes, checked below). The CRC covers these.
pub const fn stuffed_len(n: usize) -> usize {
    robust_body_len(n).saturating_add(1)
}

/// Bytes of every robust frame with `n` motors: `S`, the three check bytes and the 0x00 terminator.
pub const fn robust_len(n: usize) -> usize {
    stuffed_len(n).saturating_add(CHECK_LEN).saturating_add(1)
}

const _: () = assert!(
    robust_body_len(MAX_MOTORS) < 254,
    "robust frame bodies must stay one COBS block long, so that their length is fixed"
);

/// Room for the body of a robust frame of any motor count.
const ROBUST_BODY_BUF: usize = robust_body_len(MAX_MOTORS);

/// The stream decoder's buffer: the largest robust frame of [`MAX_MOTORS`] motors.
pub const ROBUST_BUF: usize = robust_len(MAX_MOTORS);

/// The check bytes of a robust frame for the CRC `crc`: `[0x80 | crc >> 14, 0x80 | (crc >> 7) &
/// 0x7F, 0x80 | crc & 0x7F]`. None is 0x00, and in the first only bits 7, 1 and 0 can be set.
pub const fn check_bytes(crc: u16) -> [u8; CHECK_LEN] {
    let [hi, lo] = crc.to_be_bytes();
    [
        0x80 | (hi >> 6),
        0x80 | ((hi << 1) & 0x7E) | (lo >> 7),
        0x80 | (lo & 0x7F),
    ]
}

/// The CRC that check bytes carry, or `None` if they are not check bytes: bit 7 clear in one of
/// them, or one of bits 6..2 set in the first. The inverse of [`check_bytes`].
pub const fn check_value(k: [u8; CHECK_LEN]) -> Option<u16> {
    let [k0, k1, k2] = k;
    if k0 & 0xFC != 0x80 || k1 & 0x80 == 0 || k2 & 0x80 == 0 {
        return None;
    }
    let hi = ((k0 & 0x03) << 6) | ((k1 & 0x7F) >> 1);
    let lo = ((k1 & 0x01) << 7) | (k2 & 0x7F);
    Some(u16::from_be_bytes([hi, lo]))
}

/// Command types (`enum CmdType`, 32-bit on the wire). Values fixed by the seed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(i32)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum CmdType {
    /// Actuate the motors.
    #[default]
    Mtrs = 0,
    /// Calibrate the motors.
    Cal = 1,
    /// End effector on.
    EndeffOn = 2,
    /// End effector off.
    EndeffOff = 3,
    /// Set speed / acceleration.
    Config = 4,
}

impl CmdType {
    /// Maps a raw value, `None` if undefined.
    pub const fn from_raw(raw: i32) -> Option<Self> {
        match raw {
            0 => Some(Self::Mtrs),
            1 => Some(Self::Cal),
            2 => Some(Self::EndeffOn),
            3 => Some(Self::EndeffOff),
            4 => Some(Self::Config),
            _ => None,
        }
    }
}

/// `struct CmdMsg` with `N` = `MAX_SUPPORTED_MTRS` motors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CmdMsg<const N: usize> {
    /// What to do.
    pub cmd_type: CmdType,
    /// Non-zero: angles are relative to the current position.
    pub is_relative: i32,
    /// Target angle of each motor, degrees.
    pub mtr_angles: [i32; N],
    /// Speed, degrees per second.
    pub mtr_speed_deg_s: i32,
    /// Acceleration, degrees per second².
    pub mtr_accel_deg_s_s: i32,
    /// Set by the Teensy in its echo: 1 done, 0 not.
    pub cmd_success: i32,
}

impl<const N: usize> Default for CmdMsg<N> {
    fn default() -> Self {
        Self {
            cmd_type: CmdType::Mtrs,
            is_relative: 0,
            mtr_angles: [0; N],
            mtr_speed_deg_s: 0,
            mtr_accel_deg_s_s: 0,
            cmd_success: 0,
        }
    }
}

impl<const N: usize> CmdMsg<N> {
    /// `sizeof(CmdMsg)`.
    pub const LEN: usize = msg_len(N);
    /// `sizeof(Packet)`: the message and the `'\n'`.
    pub const LEGACY_LEN: usize = legacy_len(N);
    /// Bytes of a robust frame, terminator included (every frame has this length, see [`robust_len`]).
    pub const ROBUST_LEN: usize = robust_len(N);
    const FITS: () = assert!(N <= MAX_MOTORS, "more motors than MAX_MOTORS");

    /// The echo the Teensy sends back: the same command with `cmd_success` set.
    pub const fn reply(mut self, success: bool) -> Self {
        self.cmd_success = success as i32;
        self
    }

    /// Writes the `CmdMsg` bytes; `None` if `out` is shorter than [`Self::LEN`].
    pub fn encode_raw(&self, out: &mut [u8]) -> Option<usize> {
        let mut w = le::Writer::new(out);
        w.i32(self.cmd_type as i32);
        w.i32(self.is_relative);
        w.each(&self.mtr_angles, le::Writer::i32);
        w.i32(self.mtr_speed_deg_s);
        w.i32(self.mtr_accel_deg_s_s);
        w.i32(self.cmd_success);
        w.finish().ok()
    }

    /// Reads exactly [`Self::LEN`] bytes of `CmdMsg` (length → `Framing`, `cmd_type` → `Decode`).
    pub fn decode_raw(bytes: &[u8]) -> Result<Self, RejectReason> {
        if bytes.len() != Self::LEN {
            return Err(RejectReason::Framing);
        }
        let mut r = le::Reader::new(bytes);
        let short = |_| RejectReason::Framing;
        let cmd_type = CmdType::from_raw(r.i32().map_err(short)?).ok_or(RejectReason::Decode)?;
        let is_relative = r.i32().map_err(short)?;
        let mut mtr_angles = [0i32; N];
        for a in mtr_angles.iter_mut() {
            *a = r.i32().map_err(short)?;
        }
        Ok(Self {
            cmd_type,
            is_relative,
            mtr_angles,
            mtr_speed_deg_s: r.i32().map_err(short)?,
            mtr_accel_deg_s_s: r.i32().map_err(short)?,
            cmd_success: r.i32().map_err(short)?,
        })
    }

    /// Writes the legacy packet (message + `'\n'`); `None` if `out` is shorter than [`Self::LEGACY_LEN`].
    pub fn encode_legacy(&self, out: &mut [u8]) -> Option<usize> {
        let n = self.encode_raw(out)?;
        let slot = out.get_mut(n)?;
        *slot = DELIMITER;
        Some(n.saturating_add(1))
    }

    /// Reads a legacy packet: exactly [`Self::LEGACY_LEN`] bytes ending in `'\n'`.
    pub fn decode_legacy(packet: &[u8]) -> Result<Self, RejectReason> {
        match packet.split_last() {
            Some((&DELIMITER, msg)) => Self::decode_raw(msg),
            _ => Err(RejectReason::Framing),
        }
    }

    /// Writes the robust frame (`S`, check bytes, 0x00 terminator); `None` if `out` is shorter than
    /// [`Self::ROBUST_LEN`].
    pub fn encode_robust(&self, out: &mut [u8]) -> Option<usize> {
        let mut body = [0u8; ROBUST_BODY_BUF];
        let n = self.encode_body(&mut body)?;
        let frame = out.get_mut(..Self::ROBUST_LEN)?;
        let (stuffed, rest) = frame.split_at_mut_checked(stuffed_len(N))?;
        stuff_into(body.get(..n)?, stuffed)?;
        let (check, end) = rest.split_first_chunk_mut::<CHECK_LEN>()?;
        *check = check_bytes(crc16::checksum(stuffed));
        *end.first_mut()? = 0;
        Some(Self::ROBUST_LEN)
    }

    /// Writes the robust frame's body before COBS (version, message); returns its length
    /// ([`robust_body_len`]`(N)`).
    pub(crate) fn encode_body(&self, body: &mut [u8; ROBUST_BODY_BUF]) -> Option<usize> {
        let () = Self::FITS;
        let body = body.get_mut(..robust_body_len(N))?;
        let (version, rest) = body.split_first_mut()?;
        *version = ROBUST_VERSION;
        self.encode_raw(rest)?;
        Some(body.len())
    }

    /// Reads one robust frame, in the order of the module documentation: length and terminator →
    /// `Framing`; check bytes, then the CRC over the stuffed bytes → `Crc`; COBS → `Framing`;
    /// version → `Version`; the message → `Decode`.
    pub fn decode_robust(frame: &[u8]) -> Result<Self, RejectReason> {
        let () = Self::FITS;
        // Every frame of ours has the same length (see `robust_len`); checked first, so that
        // the CRC and COBS only ever see that many bytes.
        if frame.len() != Self::ROBUST_LEN || frame.last() != Some(&0) {
            return Err(RejectReason::Framing);
        }
        let (stuffed, rest) = frame
            .split_at_checked(stuffed_len(N))
            .ok_or(RejectReason::Framing)?;
        let check = rest
            .first_chunk::<CHECK_LEN>()
            .ok_or(RejectReason::Framing)?;
        let sent = check_value(*check).ok_or(RejectReason::Crc)?;
        if crc16::checksum(stuffed) != sent {
            return Err(RejectReason::Crc);
        }
        let mut body = [0u8; ROBUST_BODY_BUF];
        // `unstuff` returns the body length, `stuffed.len() − 1` = `robust_body_len(N)` here;
        // slicing by the constant keeps every length below known to Kani's solver, which does not
        // carry `n`'s value over from the check.
        let n = unstuff(stuffed, &mut body).ok_or(RejectReason::Framing)?;
        if n != robust_body_len(N) {
            return Err(RejectReason::Framing);
        }
        Self::decode_body(
            body.get(..robust_body_len(N))
                .ok_or(RejectReason::Framing)?,
        )
    }

    /// Reads a robust frame's body after COBS: length → `Framing`, version → `Version`, then the
    /// message (`cmd_type` → `Decode`).
    pub(crate) fn decode_body(body: &[u8]) -> Result<Self, RejectReason> {
        if body.len() != robust_body_len(N) {
            return Err(RejectReason::Framing);
        }
        match body.split_first() {
            Some((&ROBUST_VERSION, msg)) => Self::decode_raw(msg),
            Some(_) => Err(RejectReason::Version),
            None => Err(RejectReason::Framing),
        }
    }

    /// The ladder event of this command (see the module documentation): `MTRS` moves every motor to
    /// its angle (degrees → rad, position mode) under the message's speed (deg/s → rad/s) as the cap.
    pub fn to_event(&self) -> Option<Event<N>> {
        const RAD_PER_DEG: f32 = core::f32::consts::PI / 180.0;
        let cap = self.mtr_speed_deg_s as f32 * RAD_PER_DEG;
        match self.cmd_type {
            CmdType::Mtrs => Some(Event::Frame(Command {
                axes: self
                    .mtr_angles
                    .map(|deg| AxisCommand::position(deg as f32 * RAD_PER_DEG, cap)),
                enable: true,
                seq: None,
                timeout: None,
            })),
            CmdType::Cal | CmdType::EndeffOn | CmdType::EndeffOff | CmdType::Config => None,
        }
    }
}

/// COBS for a body of a single block (fewer than 254 bytes, as every robust frame body is), without
/// a terminator: writes `code, data…` (`body.len() + 1` bytes, none of them zero) into `out` and
/// returns that length.
///
/// Every zero of `body` is replaced by the distance to the next zero (or to the end of the block,
/// one past the last byte), and a code byte giving the distance to the first zero goes in front.
/// Written backwards from the end, at fixed positions only. `None` if the body is too long for one
/// block or `out` too short.
///
/// [`unstuff`] inverts it (proven: `verify_unstuff_inverts_stuff`); the tests check that it writes
/// what `corncobs::encode_buf` writes before the terminator.
pub(crate) fn stuff_into(body: &[u8], out: &mut [u8]) -> Option<usize> {
    let n = body.len();
    if n >= 254 {
        return None;
    }
    let block = out.get_mut(..=n)?;
    let (code, data) = block.split_first_mut()?;
    // Position in the block of the next zero of the body (a code byte), or the block's end.
    let mut next = n.saturating_add(1);
    // By index (`data` and `body` are both `n` long), not zipped: see `crate::le`.
    #[allow(clippy::indexing_slicing)]
    for i in (0..n).rev() {
        let p = i.saturating_add(1);
        let b = body[i];
        data[i] = if b == 0 {
            let code = u8::try_from(next.saturating_sub(p)).ok()?;
            next = p;
            code
        } else {
            b
        };
    }
    *code = u8::try_from(next).ok()?;
    Some(n.saturating_add(1))
}

/// Undoes COBS for a single block without a terminator (`code, data…`, fewer than 254 data bytes,
/// as `S` of every robust frame is): writes the body into `out` and returns its length
/// (`stuffed.len() − 1`).
///
/// In such a block every code byte stands where the body has a zero, so byte `p` of the block
/// (1 ≤ p ≤ len − 1) decodes to body byte `p − 1`: a zero where a code stands, the block byte
/// elsewhere. The first code is byte 0; each code `c` at `p` puts the next one at `p + c`, and the
/// chain must end exactly one past the last byte. `None` for anything else: an empty block, a zero
/// byte, a chain that overshoots or stops short, 254 or more data bytes (which would need the 0xFF
/// code), or `out` too short.
///
/// This byte-by-byte form reads and writes only at fixed positions, which is what lets Kani prove
/// the decoder total over every input. The tests check that it agrees with corncobs' decoder.
pub(crate) fn unstuff(stuffed: &[u8], out: &mut [u8]) -> Option<usize> {
    let (&first, data) = stuffed.split_first()?;
    if data.len() >= 254 || out.len() < data.len() {
        return None;
    }
    let mut next = usize::from(first);
    // By index (`out` is at least as long as `data`), not zipped: see `crate::le`.
    #[allow(clippy::indexing_slicing)]
    for i in 0..data.len() {
        let d = data[i];
        if d == 0 {
            return None;
        }
        let p = i.saturating_add(1);
        if p == next {
            out[i] = 0;
            next = p.saturating_add(usize::from(d));
        } else {
            out[i] = d;
        }
    }
    (next == data.len().saturating_add(1)).then_some(data.len())
}

/// What a [`RobustDecoder`] has seen (saturating counters).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct RobustStats {
    /// Commands delivered.
    pub frames: u32,
    /// Frames refused (framing, CRC, version, decode): one per 0x00 that ends a non-empty run.
    pub errors: u32,
    /// Non-zero bytes discarded because more than `ROBUST_LEN − 1` came without a 0x00: each byte
    /// of a run but its last `ROBUST_LEN − 1` (garbage before a frame, or a run too long for one).
    pub dropped_bytes: u32,
}

/// Decodes the robust frame that ends at each 0x00 of a byte stream; bounded to [`ROBUST_BUF`]
/// bytes.
///
/// # Property
///
/// Every robust frame of `N` motors is [`CmdMsg::ROBUST_LEN`] bytes long (`L` below), its last
/// byte 0x00 and no other. So the only frame that can end at a 0x00 is the `L − 1` bytes before
/// it, and only if none of them is 0x00: the decoder keeps the last `L − 1` non-zero bytes of the
/// current run and nothing else. After `push(b[k])`:
///
/// 1. if `b[k]` is 0x00 and the `L − 1` bytes before it are non-zero, `push` returns
///    `Some(CmdMsg::decode_robust(b[k+1−L ..= k]))`. A frame whose CRC and COBS structure are
///    good is thus delivered at its 0x00, as `Ok(command)` or the message's error
///    ([`RejectReason::Version`], [`RejectReason::Decode`]), whatever non-zero bytes came
///    before it: those are dropped and counted in [`RobustStats::dropped_bytes`];
/// 2. if `b[k]` is 0x00 after 1 to `L − 2` non-zero bytes, it returns
///    `Some(Err(RejectReason::Framing))`: too short for a frame;
/// 3. otherwise (a non-zero byte, or a 0x00 right after another or at the start) it returns `None`.
///
/// Checked against a naive reference that tries `decode_robust` on every slice ending at the
/// byte, by the exhaustive tests `robust_stream_holds_back_no_frame_exhaustively` and
/// `robust_holds_back_no_frame_after_every_byte`, the twin `robust_holds_back_no_frame`, and the
/// fuzz target `fuzz_teensy_stream_holds_back_no_frame`.
///
/// ```text
///  bytes:  13 37 03 02 … D9 00 03 02 … D9 00
///          └───┘ └───────────┘ └───────────┘
///          dropped  a frame     the next one
/// ```
///
/// Each frame (`L` bytes) is delivered by the `push` of its 0x00; the non-zero bytes before it
/// without a 0x00 between (13 37) are dropped and counted.
///
/// Per byte: a non-zero byte is stored, moving the `L − 2` bytes kept when the run is longer
/// than `L − 1`; a 0x00 decodes at most one frame (one CRC over the `L − 4` stuffed bytes and,
/// if it matches, one COBS pass).
#[derive(Clone, Debug)]
pub struct RobustDecoder<const N: usize> {
    /// The bytes held are `buf[..len]`: the last non-zero bytes since the last 0x00, at most
    /// `ROBUST_LEN − 1` of them (`buf[len]` takes the terminator when a frame is decoded).
    buf: [u8; ROBUST_BUF],
    len: usize,
    stats: RobustStats,
}

impl<const N: usize> Default for RobustDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> RobustDecoder<N> {
    /// Bytes of a frame before its terminator: the most the decoder keeps.
    const WINDOW: usize = CmdMsg::<N>::ROBUST_LEN.saturating_sub(1);

    /// An empty decoder.
    pub const fn new() -> Self {
        let () = CmdMsg::<N>::FITS;
        Self {
            buf: [0; ROBUST_BUF],
            len: 0,
            stats: RobustStats {
                frames: 0,
                errors: 0,
                dropped_bytes: 0,
            },
        }
    }

    /// Counters so far.
    pub const fn stats(&self) -> RobustStats {
        self.stats
    }

    /// Adds one byte; at a 0x00 returns the frame that ends there, or why there is none (empty
    /// runs are ignored). The rules are in the type's documentation.
    pub fn push(&mut self, byte: u8) -> Option<Result<CmdMsg<N>, RejectReason>> {
        if byte != 0 {
            self.keep(byte);
            return None;
        }
        let held = core::mem::replace(&mut self.len, 0);
        if held == 0 {
            return None;
        }
        let result = match self.buf.get_mut(..=Self::WINDOW) {
            Some(frame) if held == Self::WINDOW => {
                if let Some(terminator) = frame.last_mut() {
                    *terminator = 0;
                }
                CmdMsg::<N>::decode_robust(frame)
            }
            _ => Err(RejectReason::Framing),
        };
        if result.is_ok() {
            self.stats.frames = self.stats.frames.saturating_add(1);
        } else {
            self.stats.errors = self.stats.errors.saturating_add(1);
        }
        Some(result)
    }

    /// Keeps a non-zero byte, dropping the oldest byte held if `WINDOW` are held already (the
    /// bytes move by one place: a fixed move, whatever the state).
    fn keep(&mut self, byte: u8) {
        if self.len >= Self::WINDOW {
            if let Some(window) = self.buf.get_mut(..Self::WINDOW) {
                window.copy_within(1.., 0);
            }
            // One byte, unless the state was out of range (more than WINDOW held).
            let drop = self.len.saturating_sub(Self::WINDOW).saturating_add(1);
            self.len = Self::WINDOW.saturating_sub(1);
            let drop = u32::try_from(drop).unwrap_or(u32::MAX);
            self.stats.dropped_bytes = self.stats.dropped_bytes.saturating_add(drop);
        }
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = byte;
            self.len = self.len.saturating_add(1);
        }
    }
}

#[cfg(test)]
mod tests;

#[cfg(any(test, kani))]
mod verification;
