//! Kani harnesses of the seed 000 codec and their `cargo test` twins: total decoders, round trips,
//! single-bit errors always detected; for `MotorCommand`, `MotorFeedback` and `McuInfo`.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::*;
use statemachine::harness::Source;
use statemachine::{assume, check, cover, fail};

pub(crate) fn any_command(src: &mut impl Source) -> MotorCommand {
    MotorCommand {
        timestamp_us: src.u32(),
        left_speed_cmd: src.f32(),
        right_speed_cmd: src.f32(),
        control_mode: src.u32(),
        enable: src.bool(),
        seq: src.u32(),
        request: src.u32(),
    }
}

pub(crate) fn any_feedback(src: &mut impl Source) -> MotorFeedback {
    MotorFeedback {
        timestamp_us: src.u32(),
        left_speed: src.f32(),
        right_speed: src.f32(),
        left_current: src.f32(),
        right_current: src.f32(),
        left_encoder: src.i32(),
        right_encoder: src.i32(),
        fault_flags: src.u32(),
        seq: src.u32(),
        mode: src.u32(),
        cmd_seq: src.u32(),
    }
}

/// Any info message: every field any value its type holds (the enums: every variant).
pub(crate) fn any_info(src: &mut impl Source) -> McuInfo {
    McuInfo {
        fw_version: src.u32(),
        git_hash: src.u32(),
        board: any_board(src),
        build_date: src.u32(),
        reset_cause: any_reset_cause(src),
        reset_count: src.u32(),
        panic_line: src.u32(),
        seq: src.u32(),
        dirty: src.bool(),
    }
}

fn any_board(src: &mut impl Source) -> BoardProfile {
    match src.below(BoardProfile::MAX + 1) {
        0 => BoardProfile::AmrSpi,
        1 => BoardProfile::Cdc,
        2 => BoardProfile::Teensy,
        _ => BoardProfile::PiSpi,
    }
}

fn any_reset_cause(src: &mut impl Source) -> ResetCause {
    match src.below(ResetCause::MAX + 1) {
        0 => ResetCause::Unknown,
        1 => ResetCause::PowerOn,
        2 => ResetCause::Pin,
        3 => ResetCause::IndependentWatchdog,
        4 => ResetCause::Panic,
        5 => ResetCause::Software,
        6 => ResetCause::Brownout,
        7 => ResetCause::WindowWatchdog,
        _ => ResetCause::LowPower,
    }
}

/// Bitwise equality (NaN payloads and the sign of zero must survive the wire).
fn same_command(a: &MotorCommand, b: &MotorCommand) -> bool {
    a.timestamp_us == b.timestamp_us
        && a.left_speed_cmd.to_bits() == b.left_speed_cmd.to_bits()
        && a.right_speed_cmd.to_bits() == b.right_speed_cmd.to_bits()
        && a.control_mode == b.control_mode
        && a.enable == b.enable
        && a.seq == b.seq
        && a.request == b.request
}

fn same_feedback(a: &MotorFeedback, b: &MotorFeedback) -> bool {
    a.timestamp_us == b.timestamp_us
        && a.left_speed.to_bits() == b.left_speed.to_bits()
        && a.right_speed.to_bits() == b.right_speed.to_bits()
        && a.left_current.to_bits() == b.left_current.to_bits()
        && a.right_current.to_bits() == b.right_current.to_bits()
        && a.left_encoder == b.left_encoder
        && a.right_encoder == b.right_encoder
        && a.fault_flags == b.fault_flags
        && a.seq == b.seq
        && a.mode == b.mode
        && a.cmd_seq == b.cmd_seq
}

/// An input frame of one of three shapes: any 64 bytes; any payload in a well-formed frame with a
/// correct CRC; a valid frame with one byte before the CRC replaced and the CRC fixed.
fn shaped_frame<S: Source>(
    src: &mut S,
    encode_valid: impl FnOnce(&mut S, &mut [u8; FRAME_LEN]),
) -> [u8; FRAME_LEN] {
    let mut f = [0u8; FRAME_LEN];
    match src.below(3) {
        0 => {
            for b in f.iter_mut() {
                *b = src.u8();
            }
        }
        1 => {
            let len = usize::from(src.below(MAX_PAYLOAD as u8 + 1));
            for b in f.iter_mut().skip(PAYLOAD_OFFSET).take(len) {
                *b = src.u8();
            }
            seal(&mut f, len);
        }
        _ => {
            // A valid frame with any byte before the CRC replaced (length, payload or padding), CRC fixed.
            encode_valid(src, &mut f);
            let i = usize::from(src.below(CRC_OFFSET as u8));
            f[i] = src.u8();
            let stated = usize::from(f[LEN_OFFSET]);
            seal(&mut f, stated);
        }
    }
    f
}

/// `decode` returns `Ok` or a frame-level error for every 64-byte input ([`shaped_frame`] shapes,
/// `encode_valid` supplying the valid frames).
fn decode_total<S: Source, M>(
    src: &mut S,
    encode_valid: impl FnOnce(&mut S, &mut [u8; FRAME_LEN]),
    decode: impl Fn(&[u8; FRAME_LEN]) -> Result<M, RejectReason>,
) {
    let f = shaped_frame(src, encode_valid);
    let r = decode(&f).map(|_| ());
    check!(
        matches!(
            r,
            Ok(())
                | Err(RejectReason::Crc
                    | RejectReason::Framing
                    | RejectReason::Decode
                    | RejectReason::Version)
        ),
        "P-3: the decoder returns a message or one of its typed errors"
    );
    cover!(src, r.is_ok(), "decoded");
    cover!(src, r == Err(RejectReason::Crc), "crc error");
    cover!(src, r == Err(RejectReason::Framing), "framing error");
    cover!(src, r == Err(RejectReason::Decode), "decode error");
    cover!(src, r == Err(RejectReason::Version), "version error");
}

/// P-3: [`decode_total`] for `decode_command`.
pub(crate) fn check_decode_command_total(src: &mut impl Source) {
    decode_total(
        src,
        |s, f| encode_command(&any_command(s), f),
        decode_command,
    );
}

/// P-3: [`decode_total`] for `decode_feedback`.
pub(crate) fn check_decode_feedback_total(src: &mut impl Source) {
    decode_total(
        src,
        |s, f| encode_feedback(&any_feedback(s), f),
        decode_feedback,
    );
}

/// P-3: [`decode_total`] for `decode_info`.
pub(crate) fn check_decode_info_total(src: &mut impl Source) {
    decode_total(src, |s, f| encode_info(&any_info(s), f), decode_info);
}

/// P-3: [`decode_total`] for `decode_mcu_frame`, with valid frames of both kinds.
pub(crate) fn check_decode_mcu_frame_total(src: &mut impl Source) {
    decode_total(
        src,
        |s, f| {
            if s.bool() {
                encode_info(&any_info(s), f);
            } else {
                encode_feedback(&any_feedback(s), f);
            }
        },
        decode_mcu_frame,
    );
}

/// P-6: encode → decode gives back the same command, bit for bit; out-of-range modes are refused, never truncated.
pub(crate) fn check_command_round_trip(src: &mut impl Source) {
    let cmd = any_command(src);
    let mut f = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut f);
    let r = decode_command(&f);
    if cmd.control_mode <= 0xFF {
        check!(
            matches!(r, Ok(d) if same_command(&d, &cmd)),
            "P-6: a command with an in-range mode decodes to itself"
        );
    } else {
        check!(
            r == Err(RejectReason::Decode),
            "P-6: a command with an out-of-range mode is refused as Decode"
        );
    }
    cover!(src, cmd.left_speed_cmd.is_nan(), "NaN speed round-trips");
    cover!(src, cmd.request == REQUEST_IDENTITY, "identity requested");
    cover!(src, cmd.control_mode > 0xFF, "out-of-range mode refused");
    cover!(src, usize::from(f[0]) == MAX_COMMAND_LEN, "longest command");
}

/// P-6: encode → decode gives back the same feedback, bit for bit.
pub(crate) fn check_feedback_round_trip(src: &mut impl Source) {
    let fb = any_feedback(src);
    let mut f = [0u8; FRAME_LEN];
    encode_feedback(&fb, &mut f);
    let r = decode_feedback(&f);
    if fb.fault_flags <= 0xFFFF && fb.mode <= 0xFF {
        check!(
            matches!(r, Ok(d) if same_feedback(&d, &fb)),
            "P-6: feedback with an in-range mode decodes to itself"
        );
    } else {
        check!(
            r == Err(RejectReason::Decode),
            "P-6: feedback with an out-of-range mode is refused as Decode"
        );
    }
    cover!(src, fb.left_encoder < 0, "negative encoder count");
    cover!(
        src,
        fb.fault_flags <= 0xFFFF && fb.mode <= 0xFF && fb.fault_flags > 0,
        "faults reported"
    );
    cover!(src, fb.mode > 0xFF, "out-of-range mode refused");
}

/// P-6: encode → decode gives back the same info message, through `decode_info` and through
/// `decode_mcu_frame`; `decode_feedback` refuses the frame as `Version` (no `protocol_version`), and
/// `decode_info` refuses the feedback frame of any feedback the same way (no `info_version`).
pub(crate) fn check_info_round_trip(src: &mut impl Source) {
    let info = any_info(src);
    let mut f = [0u8; FRAME_LEN];
    encode_info(&info, &mut f);
    check!(
        decode_info(&f) == Ok(info),
        "P-6: an identity frame decodes to the identity sent"
    );
    check!(
        decode_mcu_frame(&f) == Ok(McuFrame::Info(info)),
        "P-6: an identity frame decodes as McuFrame::Info of the identity sent"
    );
    check!(
        decode_feedback(&f) == Err(RejectReason::Version),
        "P-6: the feedback decoder refuses an identity frame as Version"
    );
    check!(
        decode_command(&f) == Err(RejectReason::Version),
        "P-6: the command decoder refuses an identity frame as Version"
    );
    let mut g = [0u8; FRAME_LEN];
    encode_feedback(&any_feedback(src), &mut g);
    check!(
        decode_info(&g) == Err(RejectReason::Version),
        "P-6: the identity decoder refuses a feedback frame as Version"
    );
    cover!(src, usize::from(f[0]) == MAX_INFO_LEN, "longest info");
    cover!(
        src,
        info.reset_cause == ResetCause::Panic && info.panic_line > 0,
        "panic recorded"
    );
    cover!(src, info.board == BoardProfile::PiSpi, "last board profile");
}

/// P-7: Flipping any one of the 512 bits of a valid command frame makes it rejected.
pub(crate) fn check_command_bit_flip_detected(src: &mut impl Source) {
    let cmd = any_command(src);
    assume!(src, cmd.control_mode <= 0xFF);
    let mut f = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut f);
    let bit = usize::from(src.u16() % (FRAME_LEN as u16 * 8));
    f[bit / 8] ^= 1 << (bit % 8);
    check!(
        decode_command(&f).is_err(),
        "P-7: a command frame with one bit flipped is refused"
    );
    let byte = bit / 8;
    let len = usize::from(f[0]);
    cover!(src, byte == LEN_OFFSET, "flip in length");
    cover!(
        src,
        byte >= PAYLOAD_OFFSET && byte < PAYLOAD_OFFSET + len,
        "flip in payload"
    );
    cover!(
        src,
        byte >= PAYLOAD_OFFSET + len && byte < CRC_OFFSET,
        "flip in padding"
    );
    cover!(src, byte >= CRC_OFFSET, "flip in crc");
}

/// P-7: Flipping any one of the 512 bits of a valid feedback frame makes it rejected.
pub(crate) fn check_feedback_bit_flip_detected(src: &mut impl Source) {
    let fb = any_feedback(src);
    let mut f = [0u8; FRAME_LEN];
    encode_feedback(&fb, &mut f);
    let bit = usize::from(src.u16() % (FRAME_LEN as u16 * 8));
    f[bit / 8] ^= 1 << (bit % 8);
    check!(
        decode_feedback(&f).is_err(),
        "P-7: a feedback frame with one bit flipped is refused"
    );
    cover!(src, bit / 8 >= CRC_OFFSET, "flip in crc");
    cover!(src, bit / 8 < CRC_OFFSET, "flip before crc");
}

/// P-3: `open` (CRC, length, padding) returns a payload or `Crc` / `Framing` for every 64-byte input, and
/// returns a payload only when the stored CRC (big-endian) matches the bytes before it and the
/// payload is the `LEN` bytes after the length byte.
///
/// With [`check_command_field_step`] and [`check_feedback_field_step`] this makes both decoders
/// total for every input: `decode_*` is `open`, then a loop whose every iteration is total and
/// either ends the loop or consumes at least two bytes of the at most 61-byte payload (so at most 30
/// iterations), then a version compare.
pub(crate) fn check_open_total(src: &mut impl Source) {
    let mut f: [u8; FRAME_LEN] = src.bytes();
    let crc = crc16::checksum(&f[..CRC_OFFSET]);
    if src.bool() {
        // Make the CRC good so that the length and padding checks are reached.
        f[CRC_OFFSET..].copy_from_slice(&crc.to_be_bytes());
    }
    let crc_good = u16::from_be_bytes([f[CRC_OFFSET], f[CRC_OFFSET + 1]]) == crc;
    let r = open(&f);
    match r {
        Ok(p) => {
            check!(crc_good, "P-3: a frame opens only with a matching CRC");
            check!(
                p.len() == usize::from(f[LEN_OFFSET]),
                "P-3: an opened payload has the length byte's length"
            );
            check!(
                p.len() <= MAX_PAYLOAD,
                "P-3: an opened payload fits the frame"
            );
        }
        Err(RejectReason::Crc) => check!(!crc_good, "P-3: a Crc refusal only for a wrong CRC"),
        Err(RejectReason::Framing) => {
            check!(crc_good, "P-3: a Framing refusal only with a good CRC")
        }
        Err(_) => fail!("P-3: open refused for a reason it does not check"),
    }
    cover!(src, r.is_ok(), "frame opened");
    cover!(src, r == Err(RejectReason::Crc), "crc refused");
    cover!(
        src,
        r == Err(RejectReason::Framing) && usize::from(f[LEN_OFFSET]) > MAX_PAYLOAD,
        "length refused"
    );
    cover!(
        src,
        r == Err(RejectReason::Framing) && usize::from(f[LEN_OFFSET]) <= MAX_PAYLOAD,
        "padding refused"
    );
}

/// P-3: The shape half of [`check_open_total`], for the Kani harness that replaces the CRC by any
/// value (`crc16::verification::model::any_checksum`): for every 64-byte input and whatever the
/// CRC says, `open` returns a payload of exactly `LEN` ≤ [`MAX_PAYLOAD`] bytes, or `Crc` or
/// `Framing`, and never panics. The twin of [`check_open_total`] checks the CRC half with the
/// real CRC; `crc16::verify_checksum_total` proves the real CRC returns for every input.
pub(crate) fn check_open_shape(src: &mut impl Source) {
    let mut f: [u8; FRAME_LEN] = src.bytes();
    if src.bool() {
        // Well formed (the twin would not draw one at random): zero padding, length, CRC sealed.
        let len = usize::from(src.below(MAX_PAYLOAD as u8 + 1));
        f[PAYLOAD_OFFSET + len..CRC_OFFSET].fill(0);
        // Or any length byte with the CRC made good: too long, or padding that is not zero.
        let stated = if src.bool() {
            usize::from(src.u8())
        } else {
            len
        };
        seal(&mut f, stated);
    }
    let r = open(&f);
    match r {
        Ok(p) => {
            check!(
                p.len() == usize::from(f[LEN_OFFSET]),
                "P-3: an opened payload has the length byte's length"
            );
            check!(
                p.len() <= MAX_PAYLOAD,
                "P-3: an opened payload fits the frame"
            );
        }
        Err(RejectReason::Crc | RejectReason::Framing) => {}
        Err(_) => fail!("P-3: open refused for a reason it does not check"),
    }
    cover!(src, r.is_ok(), "frame opened");
    cover!(src, r == Err(RejectReason::Crc), "crc refused");
    cover!(
        src,
        r == Err(RejectReason::Framing),
        "length or padding refused"
    );
}

/// P-7, INV-11 (bytes side): Flipping bit `bit` (below 512) of the frame `f` (sealed: CRC good)
/// makes `open`, and so both decoders, refuse it as `Crc`: every bit before the CRC is covered by
/// it, and the CRC is stored big-endian, so a flip anywhere is a one-bit error pattern of the
/// 64-byte codeword. Whether a pattern is caught does not depend on the frame's content (the
/// checksum is affine, see `crc16::verification`), so checking one frame for every bit checks
/// every frame. The test `bit_flip_refused_by_open_for_every_bit` runs it for each of the 512 bits
/// (an enumeration of the whole input, so no Kani harness: one over a symbolic bit took 100 s).
pub(crate) fn check_bit_flip_refused_by_open(
    src: &mut impl Source,
    f: &[u8; FRAME_LEN],
    bit: usize,
) {
    let bit = bit % (FRAME_LEN * 8);
    let mut g = *f;
    g[bit / 8] ^= 1 << (bit % 8);
    check!(
        open(&g).map(|_| ()) == Err(RejectReason::Crc),
        "P-7: a single-bit flip of a sealed command frame is refused as Crc"
    );
    cover!(src, bit / 8 == LEN_OFFSET, "flip in length");
    cover!(src, bit / 8 >= CRC_OFFSET, "flip in crc");
    cover!(
        src,
        bit / 8 == CRC_OFFSET - 1,
        "flip in the last padding byte"
    );
}

/// A sealed command frame with every field set (the bit-flip harness's frame).
pub(crate) fn sample_command_frame() -> [u8; FRAME_LEN] {
    let cmd = MotorCommand {
        timestamp_us: 0x1234_5678,
        left_speed_cmd: 1.25,
        right_speed_cmd: -0.5,
        control_mode: 1,
        enable: true,
        seq: 0xDEAD_BEEF,
        request: REQUEST_IDENTITY,
    };
    let mut f = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut f);
    f
}

/// Any payload of up to [`MAX_PAYLOAD`] bytes, and a reader over it (a reader part-way through a
/// payload is a reader over the bytes still to read, so this is every reader state).
fn any_payload(src: &mut impl Source) -> ([u8; MAX_PAYLOAD], usize) {
    (src.bytes(), usize::from(src.below(MAX_PAYLOAD as u8 + 1)))
}

/// One iteration of a decode loop (`next_field`, then `apply` into `msg`), from any reader state:
/// never panics, and either ends the loop (end of payload or an error) or consumes at least two
/// bytes. Returns the field read and what applying it gave, for the caller's covers.
fn field_step<S: Source, M>(
    src: &mut S,
    mut msg: (M, u32),
    apply: impl Fn(&mut (M, u32), u32, Value) -> Result<(), DecodeError>,
) -> Option<(u32, Result<(), DecodeError>)> {
    let (buf, len) = any_payload(src);
    let mut r = Reader::new(&buf[..len]);
    match r.next_field() {
        Ok(Some((field, v))) => {
            check!(
                r.remaining() + 2 <= len,
                "P-3: each decode-loop step consumes at least 2 bytes"
            );
            let applied = apply(&mut msg, field, v);
            cover!(src, applied.is_err(), "field refused");
            Some((field, applied))
        }
        Ok(None) => {
            check!(
                len == 0,
                "P-3: the decode loop ends only when the payload is used up"
            );
            None
        }
        Err(_) => {
            cover!(src, len > 0, "malformed key or value");
            None
        }
    }
}

/// P-3: [`field_step`] of the command decode loop, from any command decoded so far.
pub(crate) fn check_command_field_step(src: &mut impl Source) {
    let msg = (any_command(src), src.u32());
    if let Some((field, applied)) = field_step(src, msg, apply_command_field) {
        cover!(
            src,
            applied.is_ok() && field == command_field::ENABLE,
            "enable read"
        );
        cover!(
            src,
            applied.is_ok() && field == command_field::LEFT_SPEED_CMD,
            "speed read"
        );
        cover!(
            src,
            applied.is_ok() && field == command_field::REQUEST,
            "request read"
        );
        cover!(src, field > command_field::REQUEST, "unknown field skipped");
    }
}

/// P-3: [`field_step`] of the feedback decode loop, from any feedback decoded so far.
pub(crate) fn check_feedback_field_step(src: &mut impl Source) {
    let msg = (any_feedback(src), src.u32());
    if let Some((field, applied)) = field_step(src, msg, apply_feedback_field) {
        cover!(
            src,
            applied.is_ok() && field == feedback_field::LEFT_ENCODER,
            "encoder read"
        );
    }
}

/// P-3: [`field_step`] of the info decode loop, from any info decoded so far.
pub(crate) fn check_info_field_step(src: &mut impl Source) {
    let msg = (any_info(src), src.u32());
    if let Some((field, applied)) = field_step(src, msg, apply_info_field) {
        cover!(
            src,
            applied.is_ok() && field == info_field::RESET_CAUSE,
            "reset cause read"
        );
        cover!(
            src,
            applied.is_err() && field == info_field::BOARD,
            "board refused"
        );
    }
}

/// Room for one field and up to 3 bytes after it: a field of these messages is at most 7 bytes (a
/// key of one byte for field numbers below 16, two for `McuInfo`'s 16 to 25, and a 5-byte varint).
const FIELD_BUF: usize = 10;

/// A message decoded so far, with the `protocol_version` read beside it.
type Decoded<M> = (M, u32);

/// The specification of a decoded command field: `to` with the member numbered `field` taken from
/// `from` (`protocol_version`, kept beside the message, set to [`PROTOCOL_VERSION`]).
fn with_command_field(
    mut to: Decoded<MotorCommand>,
    from: &MotorCommand,
    field: u32,
) -> Decoded<MotorCommand> {
    use command_field as f;
    match field {
        f::TIMESTAMP_US => to.0.timestamp_us = from.timestamp_us,
        f::LEFT_SPEED_CMD => to.0.left_speed_cmd = from.left_speed_cmd,
        f::RIGHT_SPEED_CMD => to.0.right_speed_cmd = from.right_speed_cmd,
        f::CONTROL_MODE => to.0.control_mode = from.control_mode,
        f::ENABLE => to.0.enable = from.enable,
        f::SEQ => to.0.seq = from.seq,
        f::PROTOCOL_VERSION => to.1 = PROTOCOL_VERSION,
        f::REQUEST => to.0.request = from.request,
        _ => {}
    }
    to
}

/// The same for feedback fields.
fn with_feedback_field(
    mut to: Decoded<MotorFeedback>,
    from: &MotorFeedback,
    field: u32,
) -> Decoded<MotorFeedback> {
    use feedback_field as f;
    match field {
        f::TIMESTAMP_US => to.0.timestamp_us = from.timestamp_us,
        f::LEFT_SPEED => to.0.left_speed = from.left_speed,
        f::RIGHT_SPEED => to.0.right_speed = from.right_speed,
        f::LEFT_CURRENT => to.0.left_current = from.left_current,
        f::RIGHT_CURRENT => to.0.right_current = from.right_current,
        f::LEFT_ENCODER => to.0.left_encoder = from.left_encoder,
        f::RIGHT_ENCODER => to.0.right_encoder = from.right_encoder,
        f::FAULT_FLAGS => to.0.fault_flags = from.fault_flags,
        f::SEQ => to.0.seq = from.seq,
        f::MODE => to.0.mode = from.mode,
        f::CMD_SEQ => to.0.cmd_seq = from.cmd_seq,
        f::PROTOCOL_VERSION => to.1 = PROTOCOL_VERSION,
        _ => {}
    }
    to
}

/// The same for info fields (`info_version` kept beside the message, set to [`INFO_VERSION`]).
fn with_info_field(mut to: Decoded<McuInfo>, from: &McuInfo, field: u32) -> Decoded<McuInfo> {
    use info_field as f;
    match field {
        f::INFO_VERSION => to.1 = INFO_VERSION,
        f::FW_VERSION => to.0.fw_version = from.fw_version,
        f::GIT_HASH => to.0.git_hash = from.git_hash,
        f::BOARD => to.0.board = from.board,
        f::BUILD_DATE => to.0.build_date = from.build_date,
        f::RESET_CAUSE => to.0.reset_cause = from.reset_cause,
        f::RESET_COUNT => to.0.reset_count = from.reset_count,
        f::PANIC_LINE => to.0.panic_line = from.panic_line,
        f::SEQ => to.0.seq = from.seq,
        f::DIRTY => to.0.dirty = from.dirty,
        _ => {}
    }
    to
}

/// A message's per-field functions, for [`field_round_trip`].
struct FieldCodec<M> {
    /// The encoder's writer of one field.
    write: fn(&mut Writer<'_>, &M, u32),
    /// The field's share of the payload bound.
    max: fn(u32) -> usize,
    /// The decoder's step for one field.
    apply: fn(&mut Decoded<M>, u32, Value) -> Result<(), DecodeError>,
    /// The specification of that step.
    with: fn(Decoded<M>, &M, u32) -> Decoded<M>,
    /// Bitwise equality of decoded states.
    same: fn(&Decoded<M>, &Decoded<M>) -> bool,
}

const COMMAND_FIELDS: FieldCodec<MotorCommand> = FieldCodec {
    write: write_command_field,
    max: command_field_max,
    apply: apply_command_field,
    with: with_command_field,
    same: |a, b| same_command(&a.0, &b.0) && a.1 == b.1,
};

const FEEDBACK_FIELDS: FieldCodec<MotorFeedback> = FieldCodec {
    write: write_feedback_field,
    max: feedback_field_max,
    apply: apply_feedback_field,
    with: with_feedback_field,
    same: |a, b| same_feedback(&a.0, &b.0) && a.1 == b.1,
};

const INFO_FIELDS: FieldCodec<McuInfo> = FieldCodec {
    write: write_info_field,
    max: info_field_max,
    apply: apply_info_field,
    with: with_info_field,
    same: |a, b| a == b,
};

/// The round trip of one field, the induction step of the message round trip: one field of `m`,
/// written at the front of any bytes of any length (standing for the fields written after it, if
/// any), then one step of the decode loop from any state decoded so far. The field is written
/// only if `m` does not hold the default there (which is what a decoded message starts from),
/// within its share of the payload's size bound; the step reads that field back, leaves exactly
/// the bytes after it, and sets exactly that member to `m`'s value, or refuses a value out of its
/// range (`in_range` false). Returns the bytes written and what the step gave, for the caller's
/// covers.
fn field_round_trip<S: Source, M: Copy + Default>(
    src: &mut S,
    codec: &FieldCodec<M>,
    m: &M,
    field: u32,
    state: Decoded<M>,
    in_range: bool,
) -> (usize, Result<(), DecodeError>) {
    let FieldCodec {
        write,
        max,
        apply,
        with,
        same,
    } = codec;
    let default = Decoded::<M>::default();
    let mut buf: [u8; FIELD_BUF] = src.bytes();
    let n = {
        let mut w = Writer::new(&mut buf);
        write(&mut w, m, field);
        w.len()
    };
    check!(
        n <= max(field),
        "P-6: a field takes at most its bound's bytes"
    );
    if n == 0 {
        // Omitted: the decoded message keeps the default, which is `m`'s value.
        check!(
            same(&with(default, m, field), &default),
            "P-6: only a default value is omitted"
        );
        return (n, Ok(()));
    }
    // The payload ends anywhere after the field.
    let total = n + usize::from(src.u8()) % (FIELD_BUF - n + 1);
    let mut r = Reader::new(&buf[..total]);
    let Ok(Some((read, v))) = r.next_field() else {
        fail!("P-6: a written field did not read back");
    };
    check!(
        read == field,
        "P-6: the field read back is the field written"
    );
    check!(
        r.remaining() == total - n,
        "P-6: one decode-loop step consumes exactly the field's bytes"
    );
    let mut got = state;
    let applied = apply(&mut got, read, v);
    if in_range {
        check!(applied.is_ok(), "P-6: an in-range field is applied");
        check!(
            same(&got, &with(state, m, field)),
            "P-6: the field read back sets exactly that member"
        );
    } else {
        check!(applied.is_err(), "P-6: an out-of-range field is refused");
    }
    (n, applied)
}

/// P-6: [`field_round_trip`] for every command field.
pub(crate) fn check_command_field_round_trip(src: &mut impl Source) {
    let cmd = any_command(src);
    let field = command_field::ALL[usize::from(src.below(command_field::ALL.len() as u8))];
    let state = (any_command(src), src.u32());
    let in_range = field != command_field::CONTROL_MODE || cmd.control_mode <= 0xFF;
    let (n, applied) = field_round_trip(src, &COMMAND_FIELDS, &cmd, field, state, in_range);
    cover!(src, n == 0, "default value omitted");
    cover!(src, n == 6, "longest field");
    cover!(src, applied.is_err(), "mode out of range refused");
    cover!(
        src,
        n > 0 && field == command_field::LEFT_SPEED_CMD && cmd.left_speed_cmd.is_nan(),
        "NaN speed"
    );
}

/// P-6: [`field_round_trip`] for every feedback field.
pub(crate) fn check_feedback_field_round_trip(src: &mut impl Source) {
    use feedback_field as f;
    let fb = any_feedback(src);
    let field = f::ALL[usize::from(src.below(f::ALL.len() as u8))];
    let state = (any_feedback(src), src.u32());
    let out_of_range = (field == f::FAULT_FLAGS && fb.fault_flags > 0xFFFF)
        || (field == f::MODE && fb.mode > 0xFF);
    let in_range = !out_of_range;
    let (n, applied) = field_round_trip(src, &FEEDBACK_FIELDS, &fb, field, state, in_range);
    cover!(src, n == 0, "default value omitted");
    cover!(src, n == 6, "longest field");
    cover!(src, applied.is_err(), "value out of range refused");
    cover!(
        src,
        n > 0 && field == f::LEFT_ENCODER && fb.left_encoder < 0,
        "negative encoder count"
    );
}

/// P-6: [`field_round_trip`] for every info field (every value of its type is in range: the enums
/// hold only defined values, so the encoder never writes one the decoder refuses).
pub(crate) fn check_info_field_round_trip(src: &mut impl Source) {
    use info_field as f;
    let info = any_info(src);
    let field = f::ALL[usize::from(src.below(f::ALL.len() as u8))];
    let state = (any_info(src), src.u32());
    let (n, applied) = field_round_trip(src, &INFO_FIELDS, &info, field, state, true);
    check!(
        applied.is_ok(),
        "P-6: every identity field read back is applied"
    );
    cover!(src, n == 0, "default value omitted");
    cover!(src, n == 7, "longest field");
    cover!(
        src,
        n > 0 && field == f::RESET_CAUSE && info.reset_cause == ResetCause::LowPower,
        "last reset cause"
    );
}

/// P-6: A frame made as the encoders make it (any payload of any length at the front of the payload
/// region, zeros after it, `seal`) is opened to exactly that payload: the same bytes, in place.
pub(crate) fn check_seal_open(src: &mut impl Source) {
    let mut f: [u8; FRAME_LEN] = src.bytes();
    let len = usize::from(src.below(MAX_PAYLOAD as u8 + 1));
    // The padding zeroed byte by byte, each at a fixed place (a slice from a symbolic start would
    // make every byte's place symbolic for the solver).
    #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
    for i in 0..CRC_OFFSET {
        if i >= PAYLOAD_OFFSET + len {
            f[i] = 0;
        }
    }
    seal(&mut f, len);
    let Ok(opened) = open(&f) else {
        fail!("P-6: a sealed frame was refused");
    };
    check!(
        opened.len() == len,
        "P-6: a sealed frame opens to a payload of the sealed length"
    );
    check!(
        core::ptr::eq(opened.as_ptr(), f[PAYLOAD_OFFSET..].as_ptr()),
        "P-6: the payload is opened in place"
    );
    cover!(src, len == MAX_PAYLOAD, "full payload");
    cover!(src, len == 0, "empty payload");
}

/// The padding rule byte by byte, each byte read at a fixed place: bytes `from..CRC_OFFSET` of
/// `frame` are all zero. [`check_padding_is_zero`] proves `padding_is_zero` (a word at a time)
/// equal to it, and the Kani harnesses `verify_open_total` and `verify_seal_open` use it in its
/// place, with the check below on every start they ask about. (When `padding_is_zero` read its
/// words up from the start, each at a place the frame's length gave, those two harnesses took
/// 75 s and 67 s with it, against 5 s and 7 s with this rule.)
pub(crate) fn padding_by_bytes(frame: &[u8; FRAME_LEN], from: usize) -> bool {
    // The domain on which `check_padding_is_zero` proves the two equal: a harness that uses this
    // rule in `padding_is_zero`'s place fails here if it asks about any other start.
    check!(
        from <= CRC_OFFSET,
        "P-3: the padding is asked about only from a start up to the CRC"
    );
    let mut ored = 0u8;
    #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
    for i in 0..CRC_OFFSET {
        if i >= from {
            ored |= frame[i];
        }
    }
    ored == 0
}

/// P-3, P-6: `padding_is_zero` is [`padding_by_bytes`] for any frame and every start up to the
/// CRC. `open` passes no other (its payload slice ends there or before, or it has refused the
/// frame), and the stand-in checks that of every call in the harnesses that use it.
pub(crate) fn check_padding_is_zero(src: &mut impl Source) {
    let mut frame: [u8; FRAME_LEN] = src.bytes();
    let from = usize::from(src.u16_below(CRC_OFFSET as u16 + 1));
    // Under Kani any bytes include every frame; the twin, whose random bytes would never be zero
    // for long, zeroes every byte from a random place on, possibly but one.
    if !cfg!(kani) {
        let zero_from = usize::from(src.below(FRAME_LEN as u8 + 1));
        for b in frame.iter_mut().skip(zero_from) {
            *b = 0;
        }
        if src.bool() {
            let at = usize::from(src.below(FRAME_LEN as u8));
            if let Some(b) = frame.get_mut(at) {
                *b = src.u8() | 1;
            }
        }
    }
    let zero = padding_by_bytes(&frame, from);
    check!(
        padding_is_zero(&frame, from) == zero,
        "P-3: the padding check is the byte-by-byte rule"
    );
    cover!(src, from < CRC_OFFSET && zero, "zero padding");
    cover!(src, from < CRC_OFFSET && !zero, "non-zero padding");
    cover!(src, from == CRC_OFFSET, "no padding: a full payload");
}

/// Kani harnesses. The whole-message properties (decoder totality, round trips, bit flips) are
/// proven by composition, not by one harness over a symbolic 64-byte frame through the protobuf
/// decoder, which does not finish: `open` ([`check_open_total`]), one step of each decode loop
/// ([`check_command_field_step`] and kin), one field read back ([`check_command_field_round_trip`]
/// and kin), a sealed frame opened ([`check_seal_open`]) and every single-bit flip refused by
/// `open` ([`check_bit_flip_refused_by_open`], enumerated by a test); `proofs/REPORT.md`
/// ("Whole-message properties by composition") puts them together. The whole-message bodies run as
/// `cargo test` twins.
#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use super::*;
    use statemachine::harness::KaniSource;

    /// The checksum as an uninterpreted function (`model::uninterpreted_checksum`): the property
    /// needs only that `open` and the harness get the same value for the same 62 bytes, which holds
    /// for every pure function of the bytes, the real CRC among them; `verify_checksum_total`
    /// proves the real one returns for every input.
    #[kani::proof]
    #[kani::unwind(64)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::uninterpreted_checksum
    )]
    #[kani::stub(crate::amr::padding_is_zero, super::padding_by_bytes)]
    fn verify_open_total() {
        check_open_total(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(20)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    fn verify_open_shape() {
        check_open_shape(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(11)]
    fn verify_command_field_round_trip() {
        check_command_field_round_trip(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL: 9.5 s against 13.3 s on one build, 9.7 s
    // against 12.7 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(13)]
    #[kani::solver(minisat)]
    fn verify_feedback_field_round_trip() {
        check_feedback_field_round_trip(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL: 6.2 s against 8.8 s on one build, 6.0 s against
    // 8.9 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(11)]
    #[kani::solver(minisat)]
    fn verify_info_field_round_trip() {
        check_info_field_round_trip(&mut KaniSource);
    }

    /// The checksum as an uninterpreted function (see [`verify_open_total`]): `seal` and `open`
    /// ask it about the same 62 bytes, so the proof holds for the real CRC.
    #[kani::proof]
    #[kani::unwind(64)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::uninterpreted_checksum
    )]
    #[kani::stub(crate::amr::padding_is_zero, super::padding_by_bytes)]
    fn verify_seal_open() {
        check_seal_open(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(64)]
    fn verify_padding_is_zero() {
        check_padding_is_zero(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(11)]
    fn verify_command_field_step() {
        check_command_field_step(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(11)]
    fn verify_feedback_field_step() {
        check_feedback_field_step(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(11)]
    fn verify_info_field_step() {
        check_info_field_step(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use super::*;
    use statemachine::harness::Twin;

    const CASES: u32 = 20_000;

    #[test]
    fn command_field_round_trip() {
        Twin::run(0xA3_0010, CASES, check_command_field_round_trip).assert_covered(4);
    }

    #[test]
    fn feedback_field_round_trip() {
        Twin::run(0xA3_0011, CASES, check_feedback_field_round_trip).assert_covered(4);
    }

    #[test]
    fn info_field_round_trip() {
        Twin::run(0xA3_0013, CASES, check_info_field_round_trip).assert_covered(3);
    }

    #[test]
    fn info_field_step() {
        Twin::run(0xA3_0014, 200_000, check_info_field_step).assert_covered(4);
    }

    #[test]
    fn info_round_trip() {
        Twin::run(0xA3_0015, CASES, check_info_round_trip).assert_covered(3);
    }

    #[test]
    fn decode_info_total() {
        Twin::run(0xA3_0016, CASES, check_decode_info_total).assert_covered(5);
    }

    #[test]
    fn decode_mcu_frame_total() {
        Twin::run(0xA3_0017, CASES, check_decode_mcu_frame_total).assert_covered(5);
    }

    #[test]
    fn seal_open() {
        Twin::run(0xA3_0012, CASES, check_seal_open).assert_covered(2);
    }

    #[test]
    fn open_total() {
        Twin::run(0xA3_0007, CASES, check_open_total).assert_covered(4);
    }

    #[test]
    fn padding_is_zero() {
        Twin::run(0xA3_0018, CASES, check_padding_is_zero).assert_covered(3);
    }

    #[test]
    fn open_shape() {
        Twin::run(0xA3_000A, CASES, check_open_shape).assert_covered(3);
    }

    /// A valid command frame (mode within a byte) drawn by `t`.
    fn valid_command_frame(t: &mut Twin) -> [u8; FRAME_LEN] {
        let mut cmd = any_command(t);
        cmd.control_mode &= 0xFF;
        let mut f = [0u8; FRAME_LEN];
        encode_command(&cmd, &mut f);
        f
    }

    /// Every one of the 512 bits of the sample frame and of 200 drawn frames, each flipped once.
    #[test]
    fn bit_flip_refused_by_open_for_every_bit() {
        let mut t = Twin::new(0xA3_000B);
        let mut frames = [[0u8; FRAME_LEN]; 201];
        frames[0] = sample_command_frame();
        for f in frames.iter_mut().skip(1) {
            *f = valid_command_frame(&mut t);
        }
        for f in &frames {
            Twin::each(0xA3_000C, FRAME_LEN as u32 * 8, |src, bit| {
                check_bit_flip_refused_by_open(src, f, bit as usize);
            })
            .assert_covered(3);
        }
    }

    #[test]
    fn command_field_step() {
        Twin::run(0xA3_0008, 200_000, check_command_field_step).assert_covered(6);
    }

    #[test]
    fn feedback_field_step() {
        Twin::run(0xA3_0009, 200_000, check_feedback_field_step).assert_covered(3);
    }

    #[test]
    fn decode_command_total() {
        Twin::run(0xA3_0001, CASES, check_decode_command_total).assert_covered(5);
    }

    #[test]
    fn decode_feedback_total() {
        Twin::run(0xA3_0002, CASES, check_decode_feedback_total).assert_covered(5);
    }

    #[test]
    fn command_round_trip() {
        Twin::run(0xA3_0003, CASES, check_command_round_trip).assert_covered(4);
    }

    #[test]
    fn feedback_round_trip() {
        Twin::run(0xA3_0004, CASES, check_feedback_round_trip).assert_covered(3);
    }

    #[test]
    fn command_bit_flip_detected() {
        Twin::run(0xA3_0005, CASES, check_command_bit_flip_detected).assert_covered(4);
    }

    #[test]
    fn feedback_bit_flip_detected() {
        Twin::run(0xA3_0006, CASES, check_feedback_bit_flip_detected).assert_covered(2);
    }

    /// Every one of the 512 single-bit errors of a few frames, exhaustively.
    #[test]
    fn every_single_bit_flip_of_sample_frames() {
        let mut t = Twin::new(7);
        for _ in 0..50 {
            let f = valid_command_frame(&mut t);
            for bit in 0..FRAME_LEN * 8 {
                let mut g = f;
                g[bit / 8] ^= 1 << (bit % 8);
                assert!(decode_command(&g).is_err(), "bit {bit}");
            }
        }
    }
}
