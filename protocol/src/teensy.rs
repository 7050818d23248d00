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
//! # Robust successor
//!
//! The same `CmdMsg` bytes behind a version byte and followed by a CRC, COBS-encoded, and ended by
//! 0x00 (COBS leaves no other zero in the frame, so a receiver always resynchronises at the next
//! 0x00, and [`RobustDecoder`] delivers a valid frame at its 0x00 whatever came before it):
//!
//! ```text
//!  COBS( ROBUST_VERSION (1 B) | CmdMsg (20+4N B) | CRC-16/CCITT-FALSE LE over the previous bytes (2 B) ) | 0x00
//! ```
//! The Teensy echoes the command with `cmd_success` = 1 (done) or 0 (refused) in the same format
//! ([`CmdMsg::reply`]). Checks on receipt: COBS structure and length → [`RejectReason::Framing`],
//! CRC → [`RejectReason::Crc`], version → [`RejectReason::Version`], `cmd_type` → [`RejectReason::Decode`].
//!
//! The body is shorter than 254 bytes for every motor count up to [`MAX_MOTORS`], so COBS encodes
//! it as one block and every frame of `N` motors has the same length, [`CmdMsg::ROBUST_LEN`]. The
//! crate `corncobs` encodes; the receiver checks that length first and undoes the one-block COBS
//! at fixed positions (a Kani-proven decoder, cross-checked against corncobs' own in the tests).
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
/// Version byte of the robust successor frame.
pub const ROBUST_VERSION: u8 = 1;
/// The legacy delimiter.
pub const DELIMITER: u8 = b'\n';

/// Bytes of `CmdMsg` with `n` motors (`sizeof(CmdMsg)`).
pub const fn msg_len(n: usize) -> usize {
    4usize.saturating_mul(5usize.saturating_add(n))
}

/// Bytes of a legacy packet with `n` motors (`sizeof(Packet)`).
pub const fn legacy_len(n: usize) -> usize {
    msg_len(n).saturating_add(1)
}

/// Bytes before COBS of a robust frame with `n` motors: version, message, CRC.
pub const fn robust_body_len(n: usize) -> usize {
    msg_len(n).saturating_add(3)
}

/// Bytes of every robust frame with `n` motors, COBS code bytes and the 0x00 terminator included.
///
/// COBS adds one code byte per started run of 254 bytes, so a body shorter than 254 bytes (as it
/// is up to [`MAX_MOTORS`], checked below) always encodes to exactly its length + 2: the largest
/// encoding is the only one.
pub const fn robust_len(n: usize) -> usize {
    corncobs::max_encoded_len(robust_body_len(n))
}

const _: () = assert!(
    robust_body_len(MAX_MOTORS) < 254
        && robust_len(MAX_MOTORS) == robust_body_len(MAX_MOTORS).saturating_add(2),
    "robust frames must stay one COBS run long, so that their length is fixed"
);

/// Room for the body of a robust frame of any motor count.
const ROBUST_BODY_BUF: usize = robust_body_len(MAX_MOTORS);

/// The stream decoder's buffer: the largest robust frame of [`MAX_MOTORS`] motors.
pub const ROBUST_BUF: usize = robust_len(MAX_MOTORS);

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

    /// Writes the robust frame (COBS, 0x00 terminator included); `None` if `out` is shorter than
    /// [`Self::ROBUST_LEN`].
    pub fn encode_robust(&self, out: &mut [u8]) -> Option<usize> {
        let mut body = [0u8; ROBUST_BODY_BUF];
        let n = self.encode_body(&mut body)?;
        let out = out.get_mut(..Self::ROBUST_LEN)?;
        Some(corncobs::encode_buf(body.get(..n)?, out))
    }

    /// Writes the robust frame's body before COBS (version, message, CRC); returns its length
    /// ([`robust_body_len`]`(N)`).
    pub(crate) fn encode_body(&self, body: &mut [u8; ROBUST_BODY_BUF]) -> Option<usize> {
        let () = Self::FITS;
        let body = body.get_mut(..robust_body_len(N))?;
        let (version, rest) = body.split_first_mut()?;
        *version = ROBUST_VERSION;
        let n = self.encode_raw(rest)?;
        let covered = n.saturating_add(1);
        let crc = crc16::checksum(body.get(..covered)?);
        body.get_mut(covered..)?.copy_from_slice(&crc.to_le_bytes());
        Some(body.len())
    }

    /// Reads one robust frame: COBS bytes ending with the 0x00 terminator and containing no other zero.
    pub fn decode_robust(frame: &[u8]) -> Result<Self, RejectReason> {
        let () = Self::FITS;
        // Every frame of ours has the same length (see `robust_len`); checked first, so that
        // COBS only ever decodes that many bytes.
        if frame.len() != Self::ROBUST_LEN || frame.last() != Some(&0) {
            return Err(RejectReason::Framing);
        }
        let mut body = [0u8; ROBUST_BODY_BUF];
        let n = unstuff(frame, &mut body).ok_or(RejectReason::Framing)?;
        // `n` is the fixed body length here (the frame's was checked); slicing by the constant
        // keeps every length below known to Kani's solver, which does not carry `n`'s value over
        // from the check.
        if n != robust_body_len(N) {
            return Err(RejectReason::Framing);
        }
        Self::decode_body(
            body.get(..robust_body_len(N))
                .ok_or(RejectReason::Framing)?,
        )
    }

    /// Reads a robust frame's body after COBS: length → `Framing`, CRC → `Crc`, version →
    /// `Version`, then the message.
    pub(crate) fn decode_body(body: &[u8]) -> Result<Self, RejectReason> {
        let n = body.len();
        if n != robust_body_len(N) {
            return Err(RejectReason::Framing);
        }
        // Split at the constant rather than at `n` (equal here), as in `decode_robust`.
        let (covered, crc) = body
            .split_at_checked(robust_body_len(N).saturating_sub(2))
            .ok_or(RejectReason::Framing)?;
        let stored = <[u8; 2]>::try_from(crc).map_err(|_| RejectReason::Framing)?;
        if crc16::checksum(covered) != u16::from_le_bytes(stored) {
            return Err(RejectReason::Crc);
        }
        match covered.split_first() {
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

/// Undoes COBS for a frame of a single block (`code, data…, 0x00`, fewer than 254 data bytes, as
/// every robust frame is): writes the body into `out` and returns its length (`frame.len() − 2`).
///
/// In such a frame every code byte stands where the body has a zero, so byte `p` of the frame
/// (1 ≤ p ≤ len − 2) decodes to body byte `p − 1`: a zero where a code stands, the frame byte
/// elsewhere. The first code is byte 0; each code `c` at `p` puts the next one at `p + c`, and the
/// chain must end exactly on the terminator. `None` for anything else: no terminator, a zero
/// before it, a chain that overshoots or stops short, 254 or more data bytes (which would need
/// the 0xFF code), or `out` too short.
///
/// corncobs, which encodes these frames, also decodes them, but by copying each run with a
/// length read from the frame; this byte-by-byte form reads and writes only at fixed positions,
/// which is what lets Kani prove the decoder total over every input. The tests check that both
/// decoders agree.
pub(crate) fn unstuff(frame: &[u8], out: &mut [u8]) -> Option<usize> {
    let (&first, rest) = frame.split_first()?;
    let (&0, data) = rest.split_last()? else {
        return None;
    };
    if data.len() >= 254 || out.len() < data.len() {
        return None;
    }
    let mut next = usize::from(first);
    for (i, (o, &d)) in out.iter_mut().zip(data).enumerate() {
        if d == 0 {
            return None;
        }
        let p = i.saturating_add(1);
        if p == next {
            *o = 0;
            next = p.saturating_add(usize::from(d));
        } else {
            *o = d;
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
///    `Some(CmdMsg::decode_robust(b[k+1−L ..= k]))`. A frame whose COBS structure and CRC are
///    good is thus delivered at its 0x00, as `Ok(command)` or the message's error
///    ([`RejectReason::Version`], [`RejectReason::Decode`]), whatever non-zero bytes came
///    before it: those are dropped and counted in [`RobustStats::dropped_bytes`];
/// 2. if `b[k]` is 0x00 after 1 to `L − 2` non-zero bytes, it returns
///    `Some(Err(RejectReason::Framing))`: too short for a frame;
/// 3. otherwise (a non-zero byte, or a 0x00 right after another or at the start) it returns `None`.
///
/// Checked against a naive reference that tries `decode_robust` on every slice ending at the
/// byte, by the exhaustive test `robust_stream_holds_back_no_frame_exhaustively`, the Kani
/// harness `verify_robust_holds_back_no_frame` with its twin, and the fuzz target
/// `fuzz_teensy_stream_holds_back_no_frame`.
///
/// ```text
///  bytes:  13 37 02 5A … 3B 00 02 5A … 3B 00
///          └───┘ └───────────┘ └───────────┘
///          dropped  a frame     the next one
/// ```
///
/// Each frame (`L` bytes) is delivered by the `push` of its 0x00; the non-zero bytes before it
/// without a 0x00 between (13 37) are dropped and counted.
///
/// Per byte: a non-zero byte is stored, moving the `L − 2` bytes kept when the run is longer
/// than `L − 1`; a 0x00 decodes at most one frame (one COBS pass and one CRC over `L − 3`
/// bytes).
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
