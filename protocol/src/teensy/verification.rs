//! Kani harnesses of the seed 003 packets and their `cargo test` twins.

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

/// P-21: Both decoders return a command or a typed error for every input up to the robust frame size.
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

/// P-21: encode → decode round-trips in both formats.
pub(crate) fn check_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; ROBUST_BUF];
    let n = m.encode_legacy(&mut buf);
    assert!(
        n == Some(Msg::LEGACY_LEN),
        "P-21: the legacy packet has the legacy length"
    );
    assert!(
        Msg::decode_legacy(&buf[..Msg::LEGACY_LEN]) == Ok(m),
        "P-21: the legacy packet decodes to the message sent"
    );
    let n = m.encode_robust(&mut buf).unwrap_or(0);
    assert!(
        n == Msg::ROBUST_LEN,
        "P-21: the robust frame has the robust length"
    );
    assert!(
        Msg::decode_robust(&buf[..n]) == Ok(m),
        "P-21: the robust frame decodes to the message sent"
    );
    let mut dec = RobustDecoder::<N>::new();
    let mut got = None;
    for &b in &buf[..n] {
        if let Some(r) = dec.push(b) {
            got = Some(r);
        }
    }
    assert!(
        got == Some(Ok(m)),
        "P-21: the stream decoder delivers the message sent"
    );
    cover!(src, m.cmd_type == CmdType::Mtrs, "motor command");
}

/// P-6: The robust frame's body, before COBS, round-trips: `encode_body` → `decode_body` gives back
/// the same command (real CRC). With [`check_unstuff_inverts_stuff`] and
/// [`check_stream_delivers_frame`] this is the robust half of [`check_round_trip`] in pieces Kani
/// can prove.
pub(crate) fn check_body_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut body = [0u8; ROBUST_BODY_BUF];
    assert!(
        m.encode_body(&mut body) == Some(BODY),
        "P-6: the robust body has the body length"
    );
    assert!(
        Msg::decode_body(&body[..BODY]) == Ok(m),
        "P-6: the robust body decodes to the message sent"
    );
    cover!(
        src,
        body[BODY - 2..BODY] != [0, 0],
        "body with a non-zero CRC"
    );
}

/// P-21: A frame's bytes fed to a fresh `RobustDecoder` give nothing until the terminator, and then
/// exactly what `decode_robust` says of the frame: any non-zero bytes of a frame's length, then 0x00.
pub(crate) fn check_stream_delivers_frame(src: &mut impl Source) {
    let mut frame: [u8; FRAME] = src.bytes();
    if !cfg!(kani) && src.bool() {
        // A valid frame (the twin would not draw one at random).
        let mut body = [0u8; ROBUST_BODY_BUF];
        let _ = any_msg(src).encode_body(&mut body);
        assert!(
            stuff_into(&body[..BODY], &mut frame) == FRAME,
            "P-21: a stuffed body fills exactly one frame"
        );
    }
    for b in frame.iter_mut().take(FRAME - 1) {
        if *b == 0 {
            *b = 1;
        }
    }
    frame[FRAME - 1] = 0;
    let mut dec = RobustDecoder::<N>::new();
    for &b in &frame[..FRAME - 1] {
        assert!(
            dec.push(b).is_none(),
            "P-21: nothing is delivered before the terminator"
        );
    }
    let got = dec.push(0);
    assert!(
        got == Some(Msg::decode_robust(&frame)),
        "P-21: the stream answers as decode_robust of the frame"
    );
    cover!(src, got.is_some_and(|r| r.is_ok()), "command delivered");
    cover!(
        src,
        got == Some(Err(RejectReason::Crc)),
        "frame refused by its CRC"
    );
}

/// P-21: A flipped bit anywhere in a robust frame is refused.
pub(crate) fn check_bit_flip_detected(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; ROBUST_BUF];
    let n = m.encode_robust(&mut buf).unwrap_or(0);
    let bit = usize::from(src.u16()) % (n * 8).max(1);
    buf[bit / 8] ^= 1 << (bit % 8);
    assert!(
        Msg::decode_robust(&buf[..n]).is_err(),
        "P-21: a robust frame with one bit flipped is refused"
    );
    cover!(src, bit / 8 == n - 1, "flip in terminator");
    cover!(src, bit / 8 < n - 1, "flip in body");
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
    assert!(
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
    assert!(
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
    check!(dec.len <= limit, "at most a frame's bytes are held");
    check!(
        after.frames >= before.frames && after.errors >= before.errors,
        "counters never go down"
    );
    check!(
        after.dropped_bytes >= before.dropped_bytes,
        "counters never go down"
    );
    check!(r.is_none() || byte == 0, "an answer only at a 0x00");
    if byte == 0 {
        check!(dec.len == 0, "a 0x00 ends the run");
        check!(r.is_some() == (held > 0), "every non-empty run is answered");
    } else {
        let dropped = usize::from(held == limit);
        check!(dec.len == held + 1 - dropped, "the new byte is kept");
        check!(dec.buf[dec.len - 1] == byte, "the new byte is kept last");
        // One byte kept before it, anywhere: the byte held before, one place further on if the
        // oldest was dropped.
        let i = usize::from(src.below(limit as u8));
        if i + 1 < dec.len {
            check!(
                dec.buf[i] == bytes[i + dropped],
                "the bytes kept are the last ones of the run, in order"
            );
        }
        check!(
            after.dropped_bytes == before.dropped_bytes.saturating_add(dropped as u32),
            "each byte dropped is counted"
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
            "no frame held back: a frame with a good CRC is delivered at its 0x00"
        ),
        None => {
            check!(
                matches!(
                    got,
                    None | Some(Err(RejectReason::Framing | RejectReason::Crc))
                ),
                "nothing but a framing or CRC error where no frame ends"
            );
            let answers = matches!(stream, [.., b, 0] if *b != 0);
            check!(
                got.is_some() == answers,
                "an answer exactly at each 0x00 ending a non-empty run"
            );
        }
    }
}

/// Garbage bytes before the frame. Under Kani one byte of any value (zero or not: the frame then
/// follows a 0x00 or merges with a run; more bytes made the proof run for many minutes): garbage
/// of any length is covered by induction, `check_robust_push_step` proving from any state that
/// the decoder keeps exactly the last non-zero bytes of the run. The twin draws up to 3 frames'
/// worth, biased toward zeros and the frame's own bytes.
const GARBAGE: usize = if cfg!(kani) { 1 } else { 3 * FRAME };

/// P-5: No valid frame is held back by the bytes before it: any garbage, then a frame, fed byte by
/// byte, gives at every byte what the [`reference`] says, and the frame is delivered at its 0x00.
/// Under Kani the frame is the harnesses' sample command; the twin takes any command.
pub(crate) fn check_robust_holds_back_no_frame(src: &mut impl Source) {
    let m = if cfg!(kani) { sample() } else { any_msg(src) };
    let mut frame = [0u8; ROBUST_BUF];
    check!(
        m.encode_robust(&mut frame) == Some(FRAME),
        "every frame has the fixed length"
    );
    let mut stream = [0u8; GARBAGE + FRAME];
    let n = if cfg!(kani) {
        GARBAGE
    } else {
        usize::from(src.u16_below(GARBAGE as u16 + 1))
    };
    let garbage: [u8; GARBAGE] = src.bytes();
    stream[..GARBAGE].copy_from_slice(&garbage);
    if !cfg!(kani) {
        for (i, b) in stream[..n].iter_mut().enumerate() {
            *b = match src.below(8) {
                0 => 0,
                1 | 2 => frame[i % FRAME],
                _ => *b,
            };
        }
    }
    stream[n..n + FRAME].copy_from_slice(&frame[..FRAME]);
    let mut dec = RobustDecoder::<N>::new();
    let mut last = None;
    for end in 1..=n + FRAME {
        let got = dec.push(stream[end - 1]);
        check_against_reference(&stream[..end], got);
        last = got;
    }
    check!(
        last == Some(Ok(m)),
        "a valid frame after any garbage is delivered at its 0x00"
    );
    let run = stream[..n].iter().rev().take_while(|&&b| b != 0).count();
    cover!(src, run > 0, "non-zero garbage right before the frame");
    cover!(src, n > 0 && run == n, "garbage without a zero");
    cover!(src, run < n, "a zero in the garbage");
}

/// The command of the Kani harness [`check_robust_holds_back_no_frame`]: a motor command with
/// bytes of every kind (zeros, which COBS replaces, and a 0x0A).
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

/// Data bytes of a robust frame of the harnesses' motor count (the COBS body).
const BODY: usize = robust_body_len(N);
/// Bytes of that frame.
const FRAME: usize = BODY + 2;

/// The specification of one-block COBS (fewer than 254 data bytes): every zero of `body` is
/// replaced by the distance to the next zero (or to the terminator), a code byte giving the
/// distance to the first zero goes in front, and a 0x00 terminator at the end. Written backwards
/// from the terminator, at fixed positions only. Returns the bytes written (`body.len() + 2`), or
/// 0 if the body is too long for one block or `out` too short.
///
/// Also the Kani stand-in for `corncobs::encode_buf` in the harnesses that encode robust frames:
/// the twin of [`check_unstuff_inverts_stuff`] checks that corncobs writes exactly this.
pub(crate) fn stuff_into(body: &[u8], out: &mut [u8]) -> usize {
    let n = body.len();
    if n >= 254 || out.len() < n + 2 {
        return 0;
    }
    // Frame position of the next zero (a code byte or the terminator) after the current byte.
    let mut next = n + 1;
    for p in (1..=n).rev() {
        let b = body[p - 1];
        if b == 0 {
            out[p] = (next - p) as u8;
            next = p;
        } else {
            out[p] = b;
        }
    }
    out[0] = next as u8;
    out[n + 1] = 0;
    n + 2
}

/// [`stuff_into`] for a body of the harnesses' motor count.
fn stuff(body: &[u8; BODY]) -> [u8; FRAME] {
    let mut frame = [0u8; FRAME];
    assert!(
        stuff_into(body, &mut frame) == FRAME,
        "P-6: a stuffed body fills exactly one frame"
    );
    frame
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

/// P-6: `unstuff` inverts [`stuff`] for every body, and the twin checks that corncobs (the encoder of
/// the robust frames) writes exactly [`stuff`]'s frame: together, every robust frame sent decodes
/// to the body it was made of.
pub(crate) fn check_unstuff_inverts_stuff(src: &mut impl Source) {
    let mut body: [u8; BODY] = src.bytes();
    if !cfg!(kani) {
        with_zeros(src, &mut body);
    }
    let frame = stuff(&body);
    let mut out = [0u8; BODY];
    assert!(
        unstuff(&frame, &mut out) == Some(BODY),
        "P-6: unstuffing a stuffed body gives a body of the body length"
    );
    assert!(out == body, "P-6: unstuff gives back the body stuffed");
    if !cfg!(kani) {
        let mut reference = [0u8; FRAME];
        assert!(
            corncobs::encode_buf(&body, &mut reference) == FRAME,
            "P-6: corncobs' encoder writes a frame of the frame length"
        );
        assert!(
            reference == frame,
            "P-6: corncobs' encoder writes the specification's frame"
        );
    }
    cover!(src, body.iter().all(|&b| b != 0), "no zero in the body");
    cover!(
        src,
        body[0] == 0 && body[BODY - 1] == 0,
        "zeros at both ends"
    );
}

/// P-4: `unstuff` never panics on any input of any length up to one byte past a frame, decodes a frame
/// of `n` bytes to `n − 2`, accepts only the frame length's frames that [`stuff`] makes (so each
/// body has exactly one frame, and a changed frame either decodes to a changed body or is
/// refused), and, in the twin, agrees with corncobs' decoder.
pub(crate) fn check_unstuff_total(src: &mut impl Source) {
    let mut buf: [u8; FRAME + 1] = src.bytes();
    let mut n = usize::from(src.below(FRAME as u8 + 2));
    if !cfg!(kani) && src.bool() {
        // A valid frame with at most one byte replaced (the twin would not draw one at random).
        let mut body: [u8; BODY] = src.bytes();
        with_zeros(src, &mut body);
        buf[..FRAME].copy_from_slice(&stuff(&body));
        n = FRAME;
        if src.bool() {
            buf[usize::from(src.below(FRAME as u8))] = src.u8();
        }
    }
    let frame = &buf[..n];
    let mut out = [0u8; BODY];
    let r = unstuff(frame, &mut out);
    if let Some(len) = r {
        assert!(
            len + 2 == n,
            "P-4: an accepted frame of n bytes decodes to n - 2 bytes"
        );
        if n == FRAME {
            assert!(
                stuff(&out)[..] == *frame,
                "P-4: unstuff accepts only frames stuff_into makes"
            );
        }
    }
    if !cfg!(kani) {
        // corncobs' decoder, behind the one-zero check the robust decoder made before: the same
        // frames accepted, the same bodies.
        let mut reference = [0u8; FRAME + 1];
        let one_zero = frame.last() == Some(&0) && frame.iter().filter(|&&b| b == 0).count() == 1;
        let accepted = match corncobs::decode_buf(frame, &mut reference[..n]) {
            Ok(len) if one_zero && len + 2 == n => Some(len),
            _ => None,
        };
        assert!(
            accepted == r,
            "P-4: unstuff accepts exactly the frames corncobs' decoder accepts"
        );
        if let Some(len) = r {
            assert!(
                reference[..len] == out[..len],
                "P-4: unstuff decodes as corncobs' decoder does"
            );
        }
    }
    cover!(src, r.is_some(), "frame accepted");
    cover!(
        src,
        r.is_none() && n == FRAME,
        "frame of the right length refused"
    );
    cover!(
        src,
        r.is_some() && out.contains(&0),
        "body with zeros decoded"
    );
}

/// P-6: encode → decode of the legacy packet gives back the same command (no CRC on this path).
pub(crate) fn check_legacy_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; Msg::LEGACY_LEN];
    assert!(
        m.encode_legacy(&mut buf) == Some(Msg::LEGACY_LEN),
        "P-6: the legacy packet has the legacy length"
    );
    assert!(
        Msg::decode_legacy(&buf) == Ok(m),
        "P-6: the legacy packet decodes to the message sent"
    );
    cover!(src, m.cmd_type == CmdType::Mtrs, "motor command");
}

/// Kani harnesses (`cargo kani -p protocol -Z stubbing -Z function-contracts --harness teensy::`,
/// with `-Z unstable-options --cbmc-args --max-field-sensitivity-array-size 512`).
///
/// The robust decoder is proven total (`verify_robust_total`, with the CRC replaced by any value,
/// and `verify_robust_push_step`, the stream decoder's induction step). The robust round trip is
/// proven in pieces: the body before COBS (`verify_body_round_trip`, real CRC), one-block COBS
/// (`verify_unstuff_inverts_stuff`: `unstuff` inverts the specification [`stuff_into`]), and
/// corncobs' encoder writing exactly that specification, which the twin checks (a test, not a
/// proof). Those under `cfg_attr(kani_pending, …)` do not finish yet; they run only with
/// `RUSTFLAGS="--cfg kani_pending" cargo kani`, and always as `cargo test` twins. See
/// `proofs/REPORT.md`.
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

    /// The property of [`RobustDecoder`] (no valid frame held back), real CRC, any byte before a
    /// frame of one motor (29 bytes); any longer garbage by induction with
    /// `verify_robust_push_step`.
    #[kani::proof]
    #[kani::unwind(35)]
    fn verify_robust_holds_back_no_frame() {
        check_robust_holds_back_no_frame(&mut KaniSource);
    }

    // Pending, each out of memory (9–10 GB) with the field-sensitivity flag. The stream half
    // and the combined totality decode the same symbolic frame twice (a copy in the decoder's
    // buffer and the original), with the real CRC; the whole round trip and the bit flip also
    // take corncobs' encoder, here replaced by `stuff_into`, which the twin checks it equals.
    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(31))]
    fn verify_stream_delivers_frame() {
        check_stream_delivers_frame(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(31))]
    fn verify_decode_total() {
        check_decode_total(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(31))]
    #[cfg_attr(kani_pending, kani::stub(corncobs::encode_buf, super::stuff_into))]
    fn verify_round_trip() {
        check_round_trip(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(31))]
    #[cfg_attr(kani_pending, kani::stub(corncobs::encode_buf, super::stuff_into))]
    fn verify_bit_flip_detected() {
        check_bit_flip_detected(&mut KaniSource);
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

    #[test]
    fn unstuff_inverts_stuff() {
        Twin::run(0x7E_0008, 20_000, check_unstuff_inverts_stuff).assert_covered(2);
    }

    #[test]
    fn body_round_trip() {
        Twin::run(0x7E_000A, 10_000, check_body_round_trip).assert_covered(1);
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

    #[test]
    fn bit_flip_detected() {
        Twin::run(0x7E_0003, 20_000, check_bit_flip_detected).assert_covered(2);
    }
}
