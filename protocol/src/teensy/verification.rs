//! Kani harnesses of the seed 003 packets and their `cargo test` twins.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::*;
use statemachine::harness::Source;
use statemachine::{check, cover};

/// Motor count used by the harnesses (small under Kani).
const N: usize = if cfg!(kani) { 1 } else { 4 };
type Msg = CmdMsg<N>;

fn any_msg(src: &mut impl Source) -> Msg {
    let mut mtr_angles = [0i32; N];
    for a in mtr_angles.iter_mut() {
        *a = src.i32();
    }
    CmdMsg {
        cmd_type: CmdType::from_raw(i32::from(src.below(5))).unwrap_or_default(),
        is_relative: src.i32(),
        mtr_angles,
        mtr_speed_deg_s: src.i32(),
        mtr_accel_deg_s_s: src.i32(),
        cmd_success: src.i32(),
    }
}

/// P-4: Both decoders return a command or a typed error for every input up to the robust frame size.
pub(crate) fn check_decode_total(src: &mut impl Source) {
    let mut buf = [0u8; ROBUST_BUF];
    // Under Kani any bytes of any length (shape 0) already include every frame; the other shapes
    // steer the twin's random inputs to (nearly) valid frames and packets.
    let shape = if cfg!(kani) { 0 } else { src.below(3) };
    let n = if shape == 0 {
        let n = usize::from(src.below(Msg::ROBUST_LEN as u8 + 2));
        for b in buf.iter_mut().take(n) {
            *b = src.u8();
        }
        n
    } else {
        // A valid robust frame or legacy packet with one byte replaced.
        let m = any_msg(src);
        let n = if shape == 1 {
            m.encode_robust(&mut buf)
        } else {
            m.encode_legacy(&mut buf)
        };
        let n = n.unwrap_or(0);
        let i = usize::from(src.u8()) % n.max(1);
        buf[i] = src.u8();
        n
    };
    let legacy = Msg::decode_legacy(&buf[..n]);
    let robust = Msg::decode_robust(&buf[..n]);
    cover!(src, legacy.is_ok(), "legacy decoded");
    cover!(src, robust.is_ok(), "robust decoded");
    cover!(src, robust == Err(RejectReason::Crc), "robust crc error");
    cover!(
        src,
        robust == Err(RejectReason::Framing),
        "robust framing error"
    );
    // Feed the same bytes to a stream decoder.
    let mut dec = RobustDecoder::<N>::new();
    for &b in &buf[..n] {
        let _ = dec.push(b);
    }
}

/// P-6, P-22: encode → decode round-trips in both formats, and the stream decoder delivers the robust
/// frame. A twin only: Kani proves the frame halves (`verify_legacy_round_trip`,
/// `verify_robust_round_trip` and its pieces) and the stream half (`verify_stream_delivers_frame`,
/// and `robust_holds_back_no_frame_after_every_byte` for the sample command with the real decoder).
#[cfg_attr(kani, allow(dead_code))]
pub(crate) fn check_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; ROBUST_BUF];
    let n = m.encode_legacy(&mut buf);
    check!(
        n == Some(Msg::LEGACY_LEN),
        "P-6: the legacy packet has the legacy length"
    );
    check!(
        Msg::decode_legacy(&buf[..Msg::LEGACY_LEN]) == Ok(m),
        "P-6: the legacy packet decodes to the message sent"
    );
    let n = m.encode_robust(&mut buf).unwrap_or(0);
    check!(
        n == Msg::ROBUST_LEN,
        "P-6: the robust frame has the robust length"
    );
    check!(
        Msg::decode_robust(&buf[..n]) == Ok(m),
        "P-6: the robust frame decodes to the message sent"
    );
    let mut dec = RobustDecoder::<N>::new();
    let mut got = None;
    for &b in &buf[..n] {
        if let Some(r) = dec.push(b) {
            got = Some(r);
        }
    }
    check!(
        got == Some(Ok(m)),
        "P-22: the stream decoder delivers the message sent"
    );
    cover!(src, m.cmd_type == CmdType::Mtrs, "motor command");
}

/// P-6: encode → decode of the robust frame gives back the same command, and the frame has the
/// fixed length. Under Kani the CRC is an uninterpreted function of the bytes
/// (`crc16::verification::model::uninterpreted_checksum`: any value, the same for the same bytes):
/// the round trip needs only that the receiver computes over the same stuffed bytes the value the
/// sender computed, so it holds for every pure function and so for the real CRC (no state). The pieces it composes are proven on their own too:
/// [`check_body_round_trip`], [`check_unstuff_inverts_stuff`], [`check_check_bytes`].
pub(crate) fn check_robust_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; FRAME];
    check!(
        m.encode_robust(&mut buf) == Some(FRAME),
        "P-6: the robust frame has the robust length"
    );
    check!(
        Msg::decode_robust(&buf) == Ok(m),
        "P-6: the robust frame decodes to the message sent"
    );
    cover!(
        src,
        buf[..STUFFED].contains(&1),
        "a zero of the body stuffed"
    );
}

/// P-6: The robust frame's body before COBS (version, message) round-trips: `encode_body` →
/// `decode_body` gives back the same command. With [`check_unstuff_inverts_stuff`] and
/// [`check_check_bytes`] this is [`check_robust_round_trip`] in pieces.
pub(crate) fn check_body_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut body = [0u8; ROBUST_BODY_BUF];
    check!(
        m.encode_body(&mut body) == Some(BODY),
        "P-6: the robust body has the body length"
    );
    check!(
        body[0] == ROBUST_VERSION,
        "P-6: the robust body starts with the version"
    );
    check!(
        Msg::decode_body(&body[..BODY]) == Ok(m),
        "P-6: the robust body decodes to the message sent"
    );
    cover!(src, body[..BODY].contains(&0), "body with a zero");
}

/// P-22: A frame's bytes fed to a fresh `RobustDecoder` give nothing until the terminator, and then
/// exactly what `decode_robust` says of the frame: any non-zero bytes of a frame's length, then 0x00.
/// Under Kani from the state those bytes leave (see the body) and with `decode_robust` an
/// uninterpreted function of the bytes.
pub(crate) fn check_stream_delivers_frame(src: &mut impl Source) {
    let mut frame: [u8; FRAME] = src.bytes();
    if !cfg!(kani) && src.bool() {
        // A valid frame (the twin would not draw one at random).
        check!(
            any_msg(src).encode_robust(&mut frame) == Some(FRAME),
            "P-22: a robust frame fills exactly one frame"
        );
    }
    for b in frame.iter_mut().take(FRAME - 1) {
        if *b == 0 {
            *b = 1;
        }
    }
    frame[FRAME - 1] = 0;
    let mut dec = RobustDecoder::<N>::new();
    if cfg!(kani) {
        // What pushing the frame's non-zero bytes into a fresh decoder leaves, by induction on
        // `verify_robust_push_step` (a non-zero byte answers nothing and is kept last, the bytes
        // held before it kept in order; none is dropped below the limit, `ROBUST_LEN − 1`): those
        // bytes, held from the front. The bytes after them are any. Pushed one by one, the
        // solver's symbolic execution cannot rule out a 0x00 among them and follows the
        // terminator's path at every byte (still running after 12 min at 8.1 GB).
        dec.buf = src.bytes();
        dec.buf[..FRAME - 1].copy_from_slice(&frame[..FRAME - 1]);
        dec.len = FRAME - 1;
    } else {
        for &b in &frame[..FRAME - 1] {
            check!(
                dec.push(b).is_none(),
                "P-22: nothing is delivered before the terminator"
            );
        }
        check!(
            dec.len == FRAME - 1 && dec.buf[..FRAME - 1] == frame[..FRAME - 1],
            "P-22: the frame's bytes are held from the front before its terminator"
        );
    }
    let got = dec.push(0);
    check!(
        got == Some(Msg::decode_robust(&frame)),
        "P-22: the stream answers as decode_robust of the frame"
    );
    cover!(src, got.is_some_and(|r| r.is_ok()), "command delivered");
    cover!(
        src,
        got == Some(Err(RejectReason::Crc)),
        "frame refused by its CRC"
    );
}

/// P-7: Flipping any one bit of the valid robust frame `f` of `M` motors makes `decode_robust` refuse
/// it: as `Crc` for a bit of the stuffed bytes `S` (a one-bit error of the CRC's codeword) or of the
/// check bytes (a fixed bit broken, or another 16-bit value), as `Framing` for a bit of the 0x00
/// terminator. Real CRC. Whether an error pattern passes the CRC does not depend on the bytes it
/// hits (the checksum is affine, see `crc16::verification`), and every other step looks only at
/// the flipped byte's place, so one frame of a length, every bit of it, stands for every frame of
/// that length. The test `bit_flip_refused_for_every_bit` runs it for every bit `bit` of frames of
/// 1, 4 and 16 motors (an enumeration of the whole input, so no Kani harness: one over a symbolic
/// bit of a one-motor frame took 40 s).
pub(crate) fn check_bit_flip_refused<const M: usize>(src: &mut impl Source, f: &[u8], bit: usize) {
    let n = CmdMsg::<M>::ROBUST_LEN;
    check!(
        f.len() == n && CmdMsg::<M>::decode_robust(f).is_ok(),
        "P-7: the frame flipped is a valid robust frame"
    );
    let bit = bit % (n * 8);
    let mut g = [0u8; ROBUST_BUF];
    g[..n].copy_from_slice(f);
    g[bit / 8] ^= 1 << (bit % 8);
    let r = CmdMsg::<M>::decode_robust(&g[..n]).map(|_| ());
    let terminator = bit / 8 == n - 1;
    check!(
        r == Err(if terminator {
            RejectReason::Framing
        } else {
            RejectReason::Crc
        }),
        "P-7: a robust frame with one bit flipped is refused (Crc, or Framing for the terminator)"
    );
    cover!(src, bit / 8 < stuffed_len(M), "flip in the stuffed bytes");
    cover!(
        src,
        (stuffed_len(M)..n - 1).contains(&(bit / 8)),
        "flip in the check bytes"
    );
    cover!(src, terminator, "flip in the terminator");
}

/// P-6, P-7: The check bytes carry every CRC value and nothing else: for `crc`, none of
/// `check_bytes(crc)` is 0x00 and `check_value` gives `crc` back; with bit `bit` (0..24) of the
/// three bytes flipped, `check_value` refuses them or gives another value.
pub(crate) fn check_check_bytes_of(crc: u16, bit: usize) {
    let k = check_bytes(crc);
    check!(k.iter().all(|&b| b != 0), "P-6: no check byte is 0x00");
    check!(
        check_value(k) == Some(crc),
        "P-6: the check bytes give back the CRC"
    );
    let mut g = k;
    g[bit / 8] ^= 1 << (bit % 8);
    check!(
        check_value(g) != Some(crc),
        "P-7: check bytes with one bit flipped are refused or give another value"
    );
}

/// P-6, P-7: [`check_check_bytes_of`] for any CRC value and any bit of the check bytes.
pub(crate) fn check_check_bytes(src: &mut impl Source) {
    let crc = src.u16();
    let bit = usize::from(src.below(CHECK_LEN as u8 * 8));
    check_check_bytes_of(crc, bit);
    let flipped = {
        let mut g = check_bytes(crc);
        g[bit / 8] ^= 1 << (bit % 8);
        check_value(g)
    };
    cover!(src, flipped.is_none(), "flip breaks a fixed bit");
    cover!(src, flipped.is_some(), "flip changes the value");
}

/// P-4: `decode_legacy` returns a command, `Framing` or `Decode` for every input of every length up to
/// one byte past a legacy packet.
pub(crate) fn check_legacy_total(src: &mut impl Source) {
    let mut buf: [u8; Msg::LEGACY_LEN + 1] = src.bytes();
    let n = usize::from(src.below(Msg::LEGACY_LEN as u8 + 2));
    if src.bool() {
        // A valid packet with at most one byte replaced (the twin would not draw one at random).
        let _ = any_msg(src).encode_legacy(&mut buf);
        let i = usize::from(src.below(Msg::LEGACY_LEN as u8));
        if src.bool() {
            buf[i] = src.u8();
        }
    }
    let r = Msg::decode_legacy(&buf[..n]);
    check!(
        matches!(r, Ok(_) | Err(RejectReason::Framing | RejectReason::Decode)),
        "P-4: decode_legacy returns a message or one of its typed errors"
    );
    cover!(src, r.is_ok(), "legacy decoded");
    cover!(src, r == Err(RejectReason::Decode), "unknown cmd_type");
    cover!(
        src,
        r == Err(RejectReason::Framing),
        "wrong length or delimiter"
    );
}

/// P-4: `decode_robust` returns a command or a typed error for every input of every length up to one
/// byte past the largest robust frame of any motor count. Under Kani the CRC is replaced by any
/// value (`crc16::verification::model::any_checksum`; `crc16::verify_checksum_total` proves the real
/// one returns for every input).
pub(crate) fn check_robust_total(src: &mut impl Source) {
    let mut buf: [u8; ROBUST_BUF + 1] = src.bytes();
    let mut n = usize::from(src.below(ROBUST_BUF as u8 + 2));
    // Under Kani any bytes of any length already include every frame; the twin would not draw a
    // valid one at random, so it also takes valid frames with at most one byte replaced.
    if !cfg!(kani) && src.bool() {
        n = any_msg(src).encode_robust(&mut buf).unwrap_or(0);
        if src.bool() {
            buf[usize::from(src.u8()) % n.max(1)] = src.u8();
        }
    }
    let r = Msg::decode_robust(&buf[..n]);
    check!(
        matches!(
            r,
            Ok(_)
                | Err(RejectReason::Framing
                    | RejectReason::Crc
                    | RejectReason::Version
                    | RejectReason::Decode)
        ),
        "P-4: decode_robust returns a message or one of its typed errors"
    );
    if n != Msg::ROBUST_LEN || buf[..n].last() != Some(&0) {
        check!(
            r == Err(RejectReason::Framing),
            "P-4: bytes of another length or not ending in 0x00 are a framing error"
        );
    }
    cover!(src, r.is_ok(), "robust decoded");
    cover!(src, r == Err(RejectReason::Crc), "robust crc error");
    cover!(src, r == Err(RejectReason::Framing), "robust framing error");
}

/// P-4: One `RobustDecoder::push` from any state (any bytes, any number held up to its limit, any
/// counters) never panics, keeps the bytes held within the limit, never lowers a counter, answers
/// only at a 0x00, and keeps exactly the last non-zero bytes of the run: after a non-zero byte the
/// bytes held are the ones held before, the oldest dropped if the limit was reached, then the new
/// byte. So, by induction over the bytes fed, the decoder holds the last `min(run, ROBUST_LEN − 1)`
/// bytes of the current run, whatever came before them.
pub(crate) fn check_robust_push_step(src: &mut impl Source) {
    let bytes: [u8; ROBUST_BUF] = src.bytes();
    let limit = Msg::ROBUST_LEN - 1;
    let held = usize::from(src.below(limit as u8 + 1));
    let mut dec = RobustDecoder::<N>::new();
    dec.buf = bytes;
    dec.len = held;
    dec.stats = RobustStats {
        frames: src.u32(),
        errors: src.u32(),
        dropped_bytes: src.u32(),
    };
    let before = dec.stats;
    let byte = src.u8();
    let r = dec.push(byte);
    let after = dec.stats;
    check!(dec.len <= limit, "P-4: at most a frame's bytes are held");
    check!(
        after.frames >= before.frames && after.errors >= before.errors,
        "P-4: counters never go down"
    );
    check!(
        after.dropped_bytes >= before.dropped_bytes,
        "P-4: counters never go down"
    );
    check!(r.is_none() || byte == 0, "P-4: an answer only at a 0x00");
    if byte == 0 {
        check!(dec.len == 0, "P-4: a 0x00 ends the run");
        check!(
            r.is_some() == (held > 0),
            "P-4: every non-empty run is answered"
        );
    } else {
        let dropped = usize::from(held == limit);
        check!(dec.len == held + 1 - dropped, "P-4: the new byte is kept");
        check!(
            dec.buf[dec.len - 1] == byte,
            "P-4: the new byte is kept last"
        );
        // One byte kept before it, anywhere: the byte held before, one place further on if the
        // oldest was dropped.
        let i = usize::from(src.below(limit as u8));
        if i + 1 < dec.len {
            check!(
                dec.buf[i] == bytes[i + dropped],
                "P-4: the bytes kept are the last ones of the run, in order"
            );
        }
        check!(
            after.dropped_bytes == before.dropped_bytes.saturating_add(dropped as u32),
            "P-4: each byte dropped is counted"
        );
    }
    cover!(src, byte != 0 && held == limit, "byte dropped at the limit");
    cover!(src, r.is_some_and(|r| r.is_err()), "frame refused");
    cover!(src, byte == 0 && held == 0, "0x00 after 0x00");
}

/// The naive reference of [`RobustDecoder`]'s property: what `push` of the last byte of `stream`
/// (the whole stream so far) must return, found by trying [`CmdMsg::decode_robust`] on every slice
/// that ends there, earliest first. `None` if no slice holds a frame with a good COBS structure
/// and CRC; the caller then accepts `None` or a framing or CRC error.
pub(crate) fn reference(stream: &[u8]) -> Option<Result<Msg, RejectReason>> {
    (0..stream.len())
        .map(|start| Msg::decode_robust(&stream[start..]))
        .find(|r| !matches!(r, Err(RejectReason::Framing | RejectReason::Crc)))
}

/// Checks one answer of the decoder against [`reference`]: a frame with a good CRC ending at the
/// last byte is delivered there; otherwise at most a framing or CRC error, and only at a 0x00 that
/// ends a non-empty run.
pub(crate) fn check_against_reference(stream: &[u8], got: Option<Result<Msg, RejectReason>>) {
    match reference(stream) {
        Some(want) => check!(
            got == Some(want),
            "P-5: no frame held back: a frame with a good CRC is delivered at its 0x00"
        ),
        None => {
            check!(
                matches!(
                    got,
                    None | Some(Err(RejectReason::Framing | RejectReason::Crc))
                ),
                "P-5: nothing but a framing or CRC error where no frame ends"
            );
            let answers = matches!(stream, [.., b, 0] if *b != 0);
            check!(
                got.is_some() == answers,
                "P-5: an answer exactly at each 0x00 ending a non-empty run"
            );
        }
    }
}

/// Garbage bytes before the frame in the twin: up to 3 frames' worth, biased toward zeros and the
/// frame's own bytes.
const GARBAGE: usize = 3 * FRAME;

/// P-5: No valid frame is held back by the bytes before it: any garbage, then a frame, fed byte by
/// byte, gives at every byte what the [`reference`] says, and the frame is delivered at its 0x00.
/// A twin. Proven for any garbage by enumeration and induction: the test
/// `robust_holds_back_no_frame_after_every_byte` runs [`holds_back_no_frame_in`] on every byte
/// value before the sample frame (zero or not: the frame then follows a 0x00 or merges with a
/// run), and `verify_robust_push_step` proves from any state that the decoder keeps exactly the
/// last non-zero bytes of a run, so longer garbage leaves the decoder in a state one byte of
/// garbage already reaches. (That one symbolic byte was a Kani harness: 132 s for 256 inputs.)
pub(crate) fn check_robust_holds_back_no_frame(src: &mut impl Source) {
    let m = any_msg(src);
    let mut frame = [0u8; ROBUST_BUF];
    check!(
        m.encode_robust(&mut frame) == Some(FRAME),
        "P-5: every frame has the fixed length"
    );
    let mut stream = [0u8; GARBAGE + FRAME];
    let n = usize::from(src.u16_below(GARBAGE as u16 + 1));
    let garbage: [u8; GARBAGE] = src.bytes();
    stream[..GARBAGE].copy_from_slice(&garbage);
    for (i, b) in stream[..n].iter_mut().enumerate() {
        *b = match src.below(8) {
            0 => 0,
            1 | 2 => frame[i % FRAME],
            _ => *b,
        };
    }
    stream[n..n + FRAME].copy_from_slice(&frame[..FRAME]);
    holds_back_no_frame_in(src, &stream[..n + FRAME], n, &m);
}

/// P-5 for one stream: `stream` is `n` bytes of garbage, then the frame of `m`. Fed byte by byte,
/// it gives at every byte what the [`reference`] says, and `m` at its last byte.
pub(crate) fn holds_back_no_frame_in(src: &mut impl Source, stream: &[u8], n: usize, m: &Msg) {
    let mut dec = RobustDecoder::<N>::new();
    let mut last = None;
    for end in 1..=stream.len() {
        let got = dec.push(stream[end - 1]);
        check_against_reference(&stream[..end], got);
        last = got;
    }
    check!(
        last == Some(Ok(*m)),
        "P-5: a valid frame after any garbage is delivered at its 0x00"
    );
    let run = stream[..n].iter().rev().take_while(|&&b| b != 0).count();
    cover!(src, run > 0, "non-zero garbage right before the frame");
    cover!(src, n > 0 && run == n, "garbage without a zero");
    cover!(src, run < n, "a zero in the garbage");
}

/// The sample command of the harnesses and of `robust_holds_back_no_frame_after_every_byte`: a
/// motor command with bytes of every kind (zeros, which COBS replaces, and a 0x0A).
fn sample() -> Msg {
    CmdMsg {
        cmd_type: CmdType::Mtrs,
        is_relative: 0,
        mtr_angles: [0x0A; N],
        mtr_speed_deg_s: 30,
        mtr_accel_deg_s_s: -1,
        cmd_success: 0,
    }
}

/// The robust frame of [`sample`] (the Kani bit-flip harness's frame).
pub(crate) fn sample_frame() -> [u8; FRAME] {
    let mut f = [0u8; FRAME];
    check!(
        sample().encode_robust(&mut f) == Some(FRAME),
        "P-7: the sample frame has the robust length"
    );
    f
}

/// Bytes of a robust frame's body (version, message) of the harnesses' motor count.
const BODY: usize = robust_body_len(N);
/// Bytes of its stuffed form `S`: the body and one COBS code byte.
const STUFFED: usize = stuffed_len(N);
/// Bytes of that frame.
const FRAME: usize = robust_len(N);

/// [`stuff_into`] for a body of the harnesses' motor count.
fn stuff(body: &[u8; BODY]) -> [u8; STUFFED] {
    let mut stuffed = [0u8; STUFFED];
    check!(
        stuff_into(body, &mut stuffed) == Some(STUFFED),
        "P-6: a stuffed body fills exactly one block"
    );
    stuffed
}

/// Random bytes seldom hold zeros, which are what COBS replaces: sets each byte to zero with a
/// chance of 0, ¼, ½ or ¾, drawn once per body.
fn with_zeros(src: &mut impl Source, body: &mut [u8]) {
    let density = src.below(4);
    for b in body.iter_mut() {
        if src.below(4) < density {
            *b = 0;
        }
    }
}

/// P-6: `unstuff` inverts [`stuff_into`] for every body, and `stuff_into`'s block has no zero byte;
/// the twin checks that corncobs writes the same block before its terminator (the crate's encoder
/// is the COBS of the literature). Together, the stuffed bytes of every robust frame sent decode to
/// the body they were made of.
pub(crate) fn check_unstuff_inverts_stuff(src: &mut impl Source) {
    let mut body: [u8; BODY] = src.bytes();
    if !cfg!(kani) {
        with_zeros(src, &mut body);
    }
    let stuffed = stuff(&body);
    check!(
        stuffed.iter().all(|&b| b != 0),
        "P-6: a stuffed block holds no zero byte"
    );
    let mut out = [0u8; BODY];
    check!(
        unstuff(&stuffed, &mut out) == Some(BODY),
        "P-6: unstuffing a stuffed body gives a body of the body length"
    );
    check!(out == body, "P-6: unstuff gives back the body stuffed");
    // corncobs is a dev-dependency: the Kani build, which has none, leaves the cross-check out.
    #[cfg(not(kani))]
    {
        let mut reference = [0u8; STUFFED + 1];
        check!(
            corncobs::encode_buf(&body, &mut reference) == STUFFED + 1,
            "P-6: corncobs' encoder writes one block and a terminator"
        );
        check!(
            reference[..STUFFED] == stuffed && reference[STUFFED] == 0,
            "P-6: corncobs' encoder writes the block stuff_into writes"
        );
    }
    cover!(src, body.iter().all(|&b| b != 0), "no zero in the body");
    cover!(
        src,
        body[0] == 0 && body[BODY - 1] == 0,
        "zeros at both ends"
    );
}

/// P-4: `unstuff` never panics on any input of any length up to one byte past a stuffed block,
/// decodes a block of `n` bytes to `n − 1`, accepts only the blocks of that length that
/// [`stuff_into`] makes (so each body has exactly one block, and a changed block either decodes to
/// a changed body or is refused), and, in the twin, agrees with corncobs' decoder.
pub(crate) fn check_unstuff_total(src: &mut impl Source) {
    let mut buf: [u8; STUFFED + 1] = src.bytes();
    let mut n = usize::from(src.below(STUFFED as u8 + 2));
    if !cfg!(kani) && src.bool() {
        // A valid block with at most one byte replaced (the twin would not draw one at random).
        let mut body: [u8; BODY] = src.bytes();
        with_zeros(src, &mut body);
        buf[..STUFFED].copy_from_slice(&stuff(&body));
        n = STUFFED;
        if src.bool() {
            buf[usize::from(src.below(STUFFED as u8))] = src.u8();
        }
    }
    let block = &buf[..n];
    let mut out = [0u8; BODY + 1];
    let r = unstuff(block, &mut out);
    if let Some(len) = r {
        check!(
            len + 1 == n,
            "P-4: an accepted block of n bytes decodes to n - 1 bytes"
        );
        if n == STUFFED {
            let mut body = [0u8; BODY];
            body.copy_from_slice(&out[..BODY]);
            check!(
                stuff(&body)[..] == *block,
                "P-4: unstuff accepts only blocks stuff_into makes"
            );
        }
    }
    #[cfg(not(kani))]
    {
        // corncobs' decoder on the block and a terminator, behind the no-zero check: the same
        // blocks accepted, the same bodies.
        let mut framed = [0u8; STUFFED + 2];
        framed[..n].copy_from_slice(block);
        let mut reference = [0u8; STUFFED + 2];
        let no_zero = !block.contains(&0);
        let accepted = match corncobs::decode_buf(&framed[..=n], &mut reference) {
            Ok(len) if no_zero && len + 1 == n => Some(len),
            _ => None,
        };
        check!(
            accepted == r,
            "P-4: unstuff accepts exactly the blocks corncobs' decoder accepts"
        );
        if let Some(len) = r {
            check!(
                reference[..len] == out[..len],
                "P-4: unstuff decodes as corncobs' decoder does"
            );
        }
    }
    cover!(src, r.is_some(), "block accepted");
    cover!(
        src,
        r.is_none() && n == STUFFED,
        "block of the right length refused"
    );
    cover!(
        src,
        r.is_some() && out[..n.saturating_sub(1)].contains(&0),
        "body with zeros decoded"
    );
}

/// P-6: encode → decode of the legacy packet gives back the same command (no CRC on this path).
pub(crate) fn check_legacy_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; Msg::LEGACY_LEN];
    check!(
        m.encode_legacy(&mut buf) == Some(Msg::LEGACY_LEN),
        "P-6: the legacy packet has the legacy length"
    );
    check!(
        Msg::decode_legacy(&buf) == Ok(m),
        "P-6: the legacy packet decodes to the message sent"
    );
    cover!(src, m.cmd_type == CmdType::Mtrs, "motor command");
}

/// Stand-ins under Kani (with `#[kani::stub(…)]`, which needs `cargo kani -Z stubbing`).
#[cfg(kani)]
pub(crate) mod model {
    use super::*;
    use statemachine::harness::{arbitrary, KaniSource};

    /// The most motors an answer of [`uninterpreted_decode_robust`] carries angles for.
    const ANGLES: usize = 4;
    /// How many distinct frames it remembers: more than any harness decodes.
    const REMEMBERED: usize = 2;

    /// One answer, kept apart from the motor count (a static cannot be generic): a refusal or
    /// the fields of a command.
    #[derive(Clone, Copy)]
    struct Answer {
        refused: Option<RejectReason>,
        cmd_type: CmdType,
        words: [i32; 4],
        angles: [i32; ANGLES],
    }

    /// The one body [`remembered_stuff_into`] has stuffed and the block it wrote for it.
    static mut STUFFED_BODY: Option<([u8; BODY], [u8; STUFFED])> = None;

    /// Stands for [`stuff_into`] on the one body of [`BODY`] bytes a round-trip harness stuffs: any
    /// block of [`STUFFED`] non-zero bytes, remembered with the body. For that length this is what
    /// `verify_unstuff_inverts_stuff` proves of the real encoder, whose block is one of these: it
    /// returns `Some(STUFFED)`, writes `STUFFED` non-zero bytes and nothing past them, and
    /// [`unstuff`] gives the body back from them. A harness that stuffs another length or a second
    /// body fails the assumption, and its covers show it.
    #[allow(unsafe_code)]
    pub(crate) fn remembered_stuff_into(body: &[u8], out: &mut [u8]) -> Option<usize> {
        // SAFETY: Kani runs a harness on one thread, from a fresh program state each time; no
        // reference to the static outlives this call.
        let slot = unsafe { &mut *core::ptr::addr_of_mut!(STUFFED_BODY) };
        kani::assume(slot.is_none() && body.len() == BODY);
        let body: &[u8; BODY] = body.try_into().ok()?;
        let block = out.get_mut(..STUFFED)?;
        let stuffed: [u8; STUFFED] = kani::any();
        for (o, &s) in block.iter_mut().zip(&stuffed) {
            kani::assume(s != 0);
            *o = s;
        }
        *slot = Some((*body, stuffed));
        Some(STUFFED)
    }

    /// Stands for [`unstuff`] beside [`remembered_stuff_into`]: the block it wrote gives back the
    /// body it was given (`verify_unstuff_inverts_stuff`); any other bytes give anything the real
    /// decoder could (`None`, or the block's data length with any bytes written).
    #[allow(unsafe_code)]
    pub(crate) fn remembered_unstuff(stuffed: &[u8], out: &mut [u8]) -> Option<usize> {
        // SAFETY: as in `remembered_stuff_into`.
        let slot = unsafe { &*core::ptr::addr_of!(STUFFED_BODY) };
        if let Some((body, block)) = slot {
            if stuffed == block.as_slice() && out.len() >= BODY {
                for (o, &b) in out.iter_mut().zip(body) {
                    *o = b;
                }
                return Some(BODY);
            }
        }
        let data = stuffed.len().checked_sub(1)?;
        for o in out.iter_mut().take(data) {
            *o = kani::any();
        }
        if kani::any() || out.len() < data {
            return None;
        }
        Some(data)
    }

    /// What it has answered: (frame length, frame bytes, answer).
    static mut ANSWERS: [Option<(usize, [u8; ROBUST_BUF], Answer)>; REMEMBERED] =
        [None; REMEMBERED];

    /// An uninterpreted function of the frame's bytes in place of `CmdMsg::decode_robust`: any
    /// command or any refusal, but the same answer whenever it is asked again about the same bytes.
    /// A property proven with it holds for every pure function of the bytes, and so for the real
    /// decoder, which is one (no state). Remembers [`REMEMBERED`] frames of up to `ROBUST_BUF`
    /// bytes; a harness that asks about more fails its assumption, and its covers show it.
    #[allow(unsafe_code)]
    pub(crate) fn uninterpreted_decode_robust<const N: usize>(
        frame: &[u8],
    ) -> Result<CmdMsg<N>, RejectReason> {
        kani::assume(frame.len() <= ROBUST_BUF && N <= ANGLES);
        // SAFETY: Kani runs a harness on one thread, from a fresh program state each time; no
        // reference to the static outlives this call.
        let answers = unsafe { &mut *core::ptr::addr_of_mut!(ANSWERS) };
        // Plain loops of fixed lengths (the slots, the frame's bytes), which CBMC unrolls exactly.
        let mut found = None;
        for slot in answers.iter() {
            if let Some((len, seen, answer)) = slot {
                let same = *len == frame.len() && seen.iter().zip(frame).all(|(a, b)| a == b);
                if found.is_none() && same {
                    found = Some(*answer);
                }
            }
        }
        let answer = match found {
            Some(a) => a,
            None => {
                let src = &mut KaniSource;
                let a = Answer {
                    refused: if kani::any() {
                        Some(arbitrary::reason(src))
                    } else {
                        None
                    },
                    cmd_type: CmdType::from_raw(i32::from(src.below(5))).unwrap_or_default(),
                    words: kani::any(),
                    angles: kani::any(),
                };
                let mut bytes = [0u8; ROBUST_BUF];
                for (dst, &b) in bytes.iter_mut().zip(frame) {
                    *dst = b;
                }
                let mut stored = false;
                for slot in answers.iter_mut() {
                    if !stored && slot.is_none() {
                        *slot = Some((frame.len(), bytes, a));
                        stored = true;
                    }
                }
                kani::assume(stored);
                a
            }
        };
        if let Some(reason) = answer.refused {
            return Err(reason);
        }
        let mut mtr_angles = [0i32; N];
        for (dst, &a) in mtr_angles.iter_mut().zip(&answer.angles) {
            *dst = a;
        }
        let [is_relative, mtr_speed_deg_s, mtr_accel_deg_s_s, cmd_success] = answer.words;
        Ok(CmdMsg {
            cmd_type: answer.cmd_type,
            is_relative,
            mtr_angles,
            mtr_speed_deg_s,
            mtr_accel_deg_s_s,
            cmd_success,
        })
    }
}

/// Kani harnesses (`cargo kani -p protocol -Z stubbing -Z function-contracts --harness teensy::`,
/// with `-Z unstable-options --cbmc-args --max-field-sensitivity-array-size 512`).
///
/// The robust decoder is proven total (`verify_robust_total`, with the CRC replaced by any value,
/// `verify_unstuff_total`, and `verify_robust_push_step`, the stream decoder's induction step). The
/// robust round trip is proven whole with the CRC an uninterpreted function
/// (`verify_robust_round_trip`) and in pieces with nothing replaced: the body before COBS
/// (`verify_body_round_trip`), one-block COBS (`verify_unstuff_inverts_stuff`) and the check bytes
/// (`verify_check_bytes`). That a flipped bit is refused is enumerated, not solved: every bit of
/// frames of 1, 4 and 16 motors, real CRC (the test `bit_flip_refused_for_every_bit`; the content
/// does not matter, see [`check_bit_flip_refused`]).
/// The stream decoder delivers what `decode_robust` answers (`verify_stream_delivers_frame`: from
/// the bytes `verify_robust_push_step`'s induction says a frame's non-zero bytes leave held, with
/// `decode_robust` an uninterpreted function of the bytes). `check_decode_total` (both frame
/// decoders and the stream decoder on the same bytes) and `check_round_trip` are twins only: each
/// of their parts is proven above. See `proofs/REPORT.md`.
#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use super::*;
    use statemachine::harness::KaniSource;

    #[kani::proof]
    #[kani::unwind(12)]
    fn verify_legacy_total() {
        check_legacy_total(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(12)]
    fn verify_legacy_round_trip() {
        check_legacy_round_trip(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(31)]
    fn verify_unstuff_inverts_stuff() {
        check_unstuff_inverts_stuff(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(31)]
    fn verify_unstuff_total() {
        check_unstuff_total(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(31)]
    fn verify_body_round_trip() {
        check_body_round_trip(&mut KaniSource);
    }

    #[kani::proof]
    fn verify_check_bytes() {
        check_check_bytes(&mut KaniSource);
    }

    /// The whole robust round trip of one motor, the CRC an uninterpreted function of the bytes
    /// (sound for a round trip: see [`check_robust_round_trip`]) and COBS the pair of stand-ins of
    /// what `verify_unstuff_inverts_stuff` proves of it (`model::remembered_stuff_into`): what is
    /// left to prove is that `encode_robust` and `decode_robust` put the pieces together.
    #[kani::proof]
    #[kani::unwind(31)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::uninterpreted_checksum
    )]
    #[kani::stub(crate::teensy::stuff_into, model::remembered_stuff_into)]
    #[kani::stub(crate::teensy::unstuff, model::remembered_unstuff)]
    fn verify_robust_round_trip() {
        check_robust_round_trip(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(31)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    fn verify_robust_total() {
        check_robust_total(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(31)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    fn verify_robust_push_step() {
        check_robust_push_step(&mut KaniSource);
    }

    /// P-22 by composition: the stream decoder hands `decode_robust` exactly the frame's bytes
    /// and returns its answer, whatever that answer is. `decode_robust` is an uninterpreted
    /// function here ([`model::uninterpreted_decode_robust`]: any command or any refusal, the same
    /// for the same bytes), so the property holds for every pure function of the bytes, the real
    /// decoder among them; what the real one answers is `verify_robust_total`'s,
    /// `verify_robust_round_trip`'s and `verify_bit_flip_refused`'s. (With the real decoder it was
    /// still in symbolic execution after 12 min at 8.1 GB: two COBS passes over symbolic bytes.)
    #[kani::proof]
    #[kani::unwind(31)]
    #[kani::stub(CmdMsg::decode_robust, model::uninterpreted_decode_robust)]
    fn verify_stream_delivers_frame() {
        check_stream_delivers_frame(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use super::*;
    use statemachine::harness::Twin;

    #[test]
    fn legacy_total() {
        Twin::run(0x7E_0004, 20_000, check_legacy_total).assert_covered(3);
    }

    #[test]
    fn legacy_round_trip() {
        Twin::run(0x7E_0005, 10_000, check_legacy_round_trip).assert_covered(1);
    }

    #[test]
    fn robust_total() {
        Twin::run(0x7E_0006, 20_000, check_robust_total).assert_covered(3);
    }

    #[test]
    fn robust_push_step() {
        Twin::run(0x7E_0007, 50_000, check_robust_push_step).assert_covered(3);
    }

    #[test]
    fn robust_holds_back_no_frame() {
        Twin::run(0x7E_000C, 5_000, check_robust_holds_back_no_frame).assert_covered(3);
    }

    /// Every byte value, then the sample frame of one motor (real CRC): the whole input of the
    /// one-byte case, with which `verify_robust_push_step`'s induction covers any garbage.
    #[test]
    fn robust_holds_back_no_frame_after_every_byte() {
        let frame = sample_frame();
        Twin::each(0x7E_000D, 256, |src, g| {
            let mut stream = [g as u8; 1 + FRAME];
            stream[1..].copy_from_slice(&frame);
            holds_back_no_frame_in(src, &stream, 1, &sample());
        })
        .assert_covered(3);
    }

    #[test]
    fn unstuff_inverts_stuff() {
        Twin::run(0x7E_0008, 20_000, check_unstuff_inverts_stuff).assert_covered(2);
    }

    #[test]
    fn body_round_trip() {
        Twin::run(0x7E_000A, 10_000, check_body_round_trip).assert_covered(1);
    }

    #[test]
    fn robust_round_trip() {
        Twin::run(0x7E_000D, 10_000, check_robust_round_trip).assert_covered(1);
    }

    /// Exhaustive: every CRC value, every bit of its check bytes.
    #[test]
    fn check_bytes() {
        for crc in 0..=u16::MAX {
            for bit in 0..CHECK_LEN * 8 {
                check_check_bytes_of(crc, bit);
            }
        }
        Twin::run(0x7E_000E, 10_000, check_check_bytes).assert_covered(2);
    }

    #[test]
    fn stream_delivers_frame() {
        Twin::run(0x7E_000B, 10_000, check_stream_delivers_frame).assert_covered(2);
    }

    #[test]
    fn unstuff_total() {
        Twin::run(0x7E_0009, 50_000, check_unstuff_total).assert_covered(3);
    }

    #[test]
    fn decode_total() {
        Twin::run(0x7E_0001, 20_000, check_decode_total).assert_covered(4);
    }

    #[test]
    fn round_trip() {
        Twin::run(0x7E_0002, 10_000, check_round_trip).assert_covered(1);
    }

    /// Every bit of the sample frame and of 200 frames of random commands (biased toward zeros,
    /// which COBS replaces) for each of 1, 4 and 16 motors, flipped one at a time.
    #[test]
    fn bit_flip_refused_for_every_bit() {
        fn every_bit<const M: usize>(t: &mut Twin, f: &[u8]) {
            Twin::each(u64::from(t.u32()), f.len() as u32 * 8, |src, bit| {
                check_bit_flip_refused::<M>(src, f, bit as usize);
            })
            .assert_covered(3);
        }
        fn frames<const M: usize>(t: &mut Twin) {
            for _ in 0..200 {
                let mut angles = [0i32; M];
                for a in angles.iter_mut() {
                    *a = t.i32();
                }
                let m = CmdMsg::<M> {
                    cmd_type: CmdType::from_raw(i32::from(t.below(5))).unwrap_or_default(),
                    is_relative: t.i32(),
                    mtr_angles: angles,
                    mtr_speed_deg_s: t.i32(),
                    mtr_accel_deg_s_s: t.i32(),
                    cmd_success: t.i32(),
                };
                let mut f = [0u8; ROBUST_BUF];
                let n = m.encode_robust(&mut f).unwrap();
                every_bit::<M>(t, &f[..n]);
            }
        }
        let mut t = Twin::new(0x7E_0003);
        every_bit::<N>(&mut t, &sample_frame());
        frames::<1>(&mut t);
        frames::<4>(&mut t);
        frames::<16>(&mut t);
    }
}
