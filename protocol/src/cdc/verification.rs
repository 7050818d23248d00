//! Kani harnesses of the seed 001 framing and stream decoder, and their `cargo test` twins.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::*;
use statemachine::harness::Source;
use statemachine::{check, cover};

/// Longest input the stream twin feeds: two full frames and more.
const MAX_INPUT: usize = 2 * MAX_FRAME_LEN + 8;

pub(crate) fn any_message(src: &mut impl Source) -> Message {
    let kind = src.below(KINDS);
    any_message_of(src, kind)
}

/// How many message kinds seed 001 has.
const KINDS: u8 = 7;

/// Any message of kind `kind` (0 ..= 6 in the order SET_MOTOR_PWM, MOTOR_ENABLE, ESTOP, PING, ACK,
/// IMU, STATUS; anything above is STATUS).
fn any_message_of(src: &mut impl Source, kind: u8) -> Message {
    match kind {
        0 => Message::SetMotorPwm(SetMotorPwm {
            pwm: [
                src.u16() as i16,
                src.u16() as i16,
                src.u16() as i16,
                src.u16() as i16,
            ],
            timeout_ms: src.u16(),
        }),
        1 => Message::MotorEnable(src.bool()),
        2 => Message::Estop(if src.bool() {
            Estop::Engage
        } else {
            Estop::Release
        }),
        3 => Message::Ping,
        4 => Message::Ack(Ack {
            msg_id: src.u8(),
            result: src.u8(),
        }),
        5 => Message::Imu(Imu {
            t_ms: src.u32(),
            accel_mg: [src.u16() as i16, src.u16() as i16, src.u16() as i16],
            gyro_mdps: [src.u16() as i16, src.u16() as i16, src.u16() as i16],
            temp_cdeg: src.u16() as i16,
        }),
        _ => Message::Status(Status {
            t_ms: src.u32(),
            vbat_mv: src.u16(),
            flags: StatusFlags(src.u16()),
            err: src.u16(),
        }),
    }
}

/// P-4: `decode_frame` returns a message or a typed error for every input of every length up to
/// [`MAX_FRAME_LEN`] (a longer slice cannot match `6 + LEN` and is refused at the length check).
pub(crate) fn check_decode_frame_total(src: &mut impl Source) {
    let mut buf: [u8; MAX_FRAME_LEN] = src.bytes();
    // Under Kani, any bytes of any length (shape 0) already include every frame; the other shapes
    // steer the twin's random inputs to (nearly) valid frames, which it would not draw otherwise.
    let shape = if cfg!(kani) { 0 } else { src.below(3) };
    let n = match shape {
        // Arbitrary bytes of arbitrary length.
        0 => usize::from(src.u16()) % (MAX_FRAME_LEN + 1),
        1 => {
            // A real frame with one byte replaced.
            let n = any_message(src).encode(&mut buf);
            let i = usize::from(src.u8()) % n;
            buf[i] = src.u8();
            n
        }
        _ => {
            // A real frame with one byte after the SOF replaced and the CRC made good again.
            let n = any_message(src).encode(&mut buf);
            let i = 2 + usize::from(src.u8()) % (n - 4);
            buf[i] = src.u8();
            let len = usize::from(buf[3]).min(n - 6);
            let crc = crate::crc16::checksum(&buf[2..4 + len]);
            buf[4 + len..6 + len].copy_from_slice(&crc.to_le_bytes());
            6 + len
        }
    };
    let r = decode_frame(&buf[..n]);
    cover!(src, r.is_ok(), "frame decoded");
    cover!(src, r == Err(Error::Framing), "framing error");
    cover!(src, r == Err(Error::Crc), "crc error");
    cover!(src, r == Err(Error::Length), "length error");
    cover!(src, r == Err(Error::UnknownMsg), "unknown msg");
    cover!(src, r == Err(Error::Value), "value error");
}

/// The stream decoder never holds more than one frame, never panics, and finds frames again after
/// garbage, truncations and corrupted frames.
pub(crate) fn check_stream_total(src: &mut impl Source) {
    let mut dec = StreamDecoder::new();
    let mut ok = 0u32;
    let mut crc_results = 0u32;
    let mut message_errors = 0u32;
    let mut fed = 0usize;
    while fed < MAX_INPUT {
        let mut chunk = [0u8; MAX_FRAME_LEN];
        let n = match src.below(4) {
            0 => {
                chunk[0] = src.u8();
                1
            }
            1 => {
                // A frame cut short.
                let n = any_message(src).encode(&mut chunk);
                1 + usize::from(src.u8()) % n
            }
            2 => {
                // A frame with one bit flipped.
                let n = any_message(src).encode(&mut chunk);
                let bit = usize::from(src.u16()) % (n * 8);
                chunk[bit / 8] ^= 1 << (bit % 8);
                n
            }
            _ => any_message(src).encode(&mut chunk),
        };
        let n = n.min(MAX_INPUT - fed);
        fed += n;
        for &b in &chunk[..n] {
            let r = dec.push(b);
            check!(
                dec.buffered() <= MAX_FRAME_LEN,
                "P-4: the stream decoder holds at most one frame"
            );
            match r {
                Some(Ok(_)) => ok += 1,
                Some(Err(Error::Crc)) => crc_results += 1,
                Some(Err(_)) => message_errors += 1,
                None => {}
            }
        }
    }
    let s = dec.stats();
    check!(
        s.frames == ok,
        "P-4: the stream counts every frame it delivers"
    );
    check!(
        s.message_errors == message_errors,
        "P-4: the stream counts every message error it reports"
    );
    // One `Err(Crc)` reports every candidate that failed at that byte.
    check!(
        crc_results <= s.crc_errors,
        "P-4: every CRC error reported is counted"
    );
    cover!(
        src,
        ok > 0 && s.dropped_bytes > 0,
        "frame found after dropped bytes"
    );
    cover!(
        src,
        ok > 0 && s.crc_errors > 0,
        "frame found after a crc error"
    );
    cover!(src, ok > 1, "several frames");
}

/// P-4: `candidate_at` from any state (any bytes, any length held, any start): never panics, and
/// gives a verdict only where the bytes held from `start` on are a candidate: `AA 55`, then a LEN
/// that makes the frame end exactly at the last byte held. A good CRC is never a framing error.
pub(crate) fn check_candidate_at(src: &mut impl Source) {
    let mut dec = StreamDecoder::new();
    dec.buf = src.bytes();
    dec.len = usize::from(src.u16_below(MAX_FRAME_LEN as u16 + 1));
    let mut start = usize::from(src.u16());
    if !cfg!(kani) && src.bool() {
        // A frame of any MSG_ID and up to 16 payload bytes ending at the last byte held (the twin
        // would not draw one at random), possibly with one byte replaced.
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = usize::from(src.below(17));
        let n = encode_raw(src.u8(), &dec.buf[..len], &mut frame);
        if src.bool() {
            frame[usize::from(src.u8()) % n] = src.u8();
        }
        dec.len = dec.len.max(n);
        start = dec.len - n;
        dec.buf[start..dec.len].copy_from_slice(&frame[..n]);
    }
    let verdict = dec.candidate_at(start);
    let rest = if start < dec.len {
        &dec.buf[start..dec.len]
    } else {
        &[]
    };
    let is_candidate =
        rest.len() >= MIN_FRAME_LEN && rest[..2] == SOF && rest.len() == usize::from(rest[3]) + 6;
    match verdict {
        Candidate::NotHere => check!(!is_candidate, "P-4: every candidate is checked"),
        Candidate::BadCrc => check!(is_candidate, "P-4: a CRC is checked only for a candidate"),
        Candidate::Good(r) => {
            check!(
                is_candidate,
                "P-4: a frame is delivered only from a candidate"
            );
            check!(
                r != Err(Error::Framing),
                "P-4: a candidate is never a framing error"
            );
            cover!(src, r.is_ok(), "message");
        }
    }
    cover!(
        src,
        matches!(verdict, Candidate::BadCrc),
        "candidate with a bad CRC"
    );
    cover!(
        src,
        is_candidate && start > 0,
        "candidate after other bytes"
    );
}

/// P-4: `append` from any state (any bytes, any count held and dropped, any counters): the byte goes
/// last; when the buffer is full the bytes held first move to its front (the oldest byte goes,
/// counted, if none was dropped), in order; nothing else changes. [`model::append`] stands in for
/// it with the counts alone. Where the bytes go (the byte appended and the bytes moved) is the
/// exhaustive test's (`append_keeps_the_bytes_in_order`, every count held and first byte held);
/// Kani proves the rest, for any bytes.
pub(crate) fn check_append(src: &mut impl Source) {
    let mut dec = StreamDecoder::new();
    dec.buf = src.bytes();
    dec.len = usize::from(src.u16_below(MAX_FRAME_LEN as u16 + 1));
    if !cfg!(kani) && src.bool() {
        dec.len = MAX_FRAME_LEN;
    }
    dec.first = usize::from(src.u16_below(dec.len as u16 + 1));
    dec.stats.dropped_bytes = src.u32();
    let before = dec.clone();
    let byte = src.u8();
    dec.append(byte);
    let full = before.len == MAX_FRAME_LEN;
    let gone = if full { before.first.max(1) } else { 0 };
    check!(
        dec.len == before.len - gone + 1 && dec.first == before.first.saturating_sub(gone),
        "P-4: append keeps the bytes held and adds one"
    );
    // Where the bytes go is checked here by the twin, and for every state by the exhaustive test
    // `append_keeps_the_bytes_in_order` (`append` moves and writes bytes without reading them, so
    // position-tagged bytes stand for any). Under Kani a symbolic index into a buffer moved by a
    // symbolic offset is the costly part of the formula: the order of the bytes kept took 200 s of
    // the harness's 227 s, and the byte appended most of what was left (92 s against 14 s).
    if !cfg!(kani) {
        check!(dec.buf[dec.len - 1] == byte, "P-4: the byte goes last");
        let j = usize::from(src.u16_below(MAX_FRAME_LEN as u16));
        if j + 1 < dec.len {
            check!(
                dec.buf[j] == before.buf[j + gone],
                "P-4: the bytes kept stay in order"
            );
        }
    }
    let counted = u32::from(full && before.first == 0);
    check!(
        dec.stats.dropped_bytes == before.stats.dropped_bytes.saturating_add(counted),
        "P-4: a byte that leaves the buffer held is counted"
    );
    cover!(src, full && before.first > 1, "full buffer moved");
    cover!(src, !full, "byte added");
}

/// P-4: `may_start` from any state and any position: never panics, and says yes only for a position
/// held whose candidate can still end after the last byte held, that is fewer than
/// `MAX_FRAME_LEN` bytes before the end (so a full buffer's first byte held is never its first
/// byte after `advance`). [`model::may_start`] stands in for it with exactly this.
pub(crate) fn check_may_start(src: &mut impl Source) {
    let mut bytes: [u8; MAX_FRAME_LEN] = src.bytes();
    let len = usize::from(src.u16_below(MAX_FRAME_LEN as u16 + 1));
    let mut i = usize::from(src.u16());
    if !cfg!(kani) && len > 0 && src.bool() {
        // A header at a position held (the twin would seldom draw one).
        i = usize::from(src.u16()) % len;
        let header = [0xAA, 0x55, src.u8(), src.u8()];
        for (b, &h) in bytes[i..].iter_mut().zip(&header) {
            *b = h;
        }
    }
    let held = &bytes[..len];
    let yes = may_start(held, i);
    if yes {
        check!(i < len, "P-4: only a position held may start a frame");
        check!(
            len - i < MAX_FRAME_LEN,
            "P-4: a candidate that can still end started fewer than MAX_FRAME_LEN bytes ago"
        );
    }
    cover!(src, yes && len - i >= 4, "a header whose frame ends later");
    cover!(src, yes && len - i == 1, "a lone AA");
}

/// P-4: One `push` from *any* state (up to a full buffer of any bytes, any of them already dropped,
/// any counters) never panics, never overfills, never lowers a counter; a delivered frame leaves
/// nothing held, and otherwise fewer than `MAX_FRAME_LEN` bytes stay held (so when the next byte
/// finds the buffer full, the byte it moves out is a dropped one). `push` has no other loops than
/// its two scans over the buffer, so it terminates.
pub(crate) fn check_stream_step(src: &mut impl Source) {
    let mut bytes: [u8; MAX_FRAME_LEN] = src.bytes();
    let mut held = usize::from(src.u16_below(MAX_FRAME_LEN as u16 + 1));
    // Under Kani any bytes held already include every state; the twin, which would rarely draw a
    // frame, also takes a frame of any MSG_ID and any payload of up to 16 bytes, possibly with
    // one byte replaced, that the byte pushed completes.
    let mut byte = src.u8();
    let mut frame_start = MAX_FRAME_LEN;
    if !cfg!(kani) && src.bool() {
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = usize::from(src.below(17));
        let n = encode_raw(src.u8(), &bytes[..len], &mut frame);
        if src.bool() {
            frame[usize::from(src.u8()) % n] = src.u8();
        }
        // All but its last byte held, the last one pushed.
        held = held.clamp(n - 1, MAX_FRAME_LEN - 1);
        frame_start = held + 1 - n;
        bytes[frame_start..held].copy_from_slice(&frame[..n - 1]);
        byte = frame[n - 1];
    }
    let mut dec = StreamDecoder::new();
    dec.buf = bytes;
    dec.len = held;
    dec.first = usize::from(src.u16_below(held as u16 + 1)).min(frame_start);
    dec.stats = Stats {
        frames: src.u32(),
        crc_errors: src.u32(),
        message_errors: src.u32(),
        dropped_bytes: src.u32(),
    };
    let before = dec.stats;
    let r = dec.push(byte);
    let after = dec.stats;
    check!(
        dec.first <= dec.len && dec.len <= MAX_FRAME_LEN,
        "P-4: the decoder never holds more than a frame"
    );
    check!(
        after.frames >= before.frames && after.crc_errors >= before.crc_errors,
        "P-4: counters never go down"
    );
    check!(
        after.message_errors >= before.message_errors
            && after.dropped_bytes >= before.dropped_bytes,
        "P-4: counters never go down"
    );
    match r {
        Some(Ok(_)) | Some(Err(Error::Length | Error::UnknownMsg | Error::Value)) => {
            check!(
                dec.buffered() == 0,
                "P-4: nothing is held after a delivered frame"
            );
            cover!(src, r.is_some_and(|r| r.is_ok()), "frame delivered");
        }
        _ => {
            check!(
                dec.buffered() < MAX_FRAME_LEN,
                "P-4: the next byte fits without dropping one"
            );
            check!(r != Some(Err(Error::Framing)), "P-4: never a framing error");
            cover!(src, r == Some(Err(Error::Crc)), "crc error");
            cover!(src, r.is_none() && dec.buffered() > 0, "bytes kept");
        }
    }
    cover!(src, held == MAX_FRAME_LEN, "push into a full buffer");
}

/// Stand-ins for the Kani harnesses, each over-approximating a function proven separately.
#[cfg(kani)]
pub(crate) mod model {
    use super::*;

    /// [`StreamDecoder::append`] as `verify_append` proves it for the counts, with any bytes:
    /// for the step harness, whose properties do not read them.
    pub(crate) fn append(dec: &mut StreamDecoder, _byte: u8) {
        if dec.len >= MAX_FRAME_LEN {
            let gone = dec.first.clamp(1, MAX_FRAME_LEN);
            if dec.first == 0 {
                dec.count_dropped(1);
            }
            dec.len = MAX_FRAME_LEN - gone;
            dec.first = dec.first.saturating_sub(gone);
        }
        dec.buf = kani::any();
        dec.len += 1;
    }

    /// [`may_start`] as `verify_may_start` proves it: any answer, but yes only for a position held
    /// fewer than `MAX_FRAME_LEN` bytes before the end.
    pub(crate) fn may_start(held: &[u8], i: usize) -> bool {
        let yes: bool = kani::any();
        kani::assume(!yes || (i < held.len() && held.len() - i < MAX_FRAME_LEN));
        yes
    }

    /// [`StreamDecoder::candidate_at`] as any verdict at all, for the step harness, whose
    /// properties hold whatever the candidates say (`verify_candidate_at` proves the real one).
    pub(crate) fn candidate_at(_dec: &StreamDecoder, _start: usize) -> Candidate {
        match kani::any::<u8>() {
            0 => Candidate::NotHere,
            1 => Candidate::BadCrc,
            2 => Candidate::Good(Ok(Message::Ping)),
            _ => Candidate::Good(Err(Error::UnknownMsg)),
        }
    }
}

/// The naive reference of [`StreamDecoder`]'s property: after each byte it tries
/// [`decode_frame`] on every suffix of the stream that starts at or after the boundary, earliest
/// first. It keeps no bytes of its own and knows nothing of how the decoder holds them.
pub(crate) struct Reference {
    /// Position just after the last frame delivered.
    pub(crate) boundary: usize,
    /// Start of the first frame delivered.
    pub(crate) first_start: Option<usize>,
    /// Candidates whose CRC failed, each counted once (at the byte where it ends).
    pub(crate) crc_errors: u32,
    /// Bytes before the frames delivered.
    pub(crate) dropped: usize,
}

impl Reference {
    /// Nothing seen yet.
    pub(crate) const fn new() -> Self {
        Self {
            boundary: 0,
            first_start: None,
            crc_errors: 0,
            dropped: 0,
        }
    }

    /// What `push` of the last byte of `stream` (the whole stream so far) must return.
    pub(crate) fn step(&mut self, stream: &[u8]) -> Option<Result<Message, Error>> {
        let end = stream.len();
        let mut bad_crc = false;
        // Only a start within the longest frame of the end can make a frame; the others are
        // refused as framing errors anyway (the twins run long streams).
        let mut start = self.boundary.max(end.saturating_sub(MAX_FRAME_LEN));
        while start < end {
            match decode_frame(&stream[start..]) {
                Err(Error::Framing) => {}
                Err(Error::Crc) => {
                    self.crc_errors += 1;
                    bad_crc = true;
                }
                r => {
                    self.dropped += start - self.boundary;
                    self.boundary = end;
                    self.first_start = self.first_start.or(Some(start));
                    return Some(r);
                }
            }
            start += 1;
        }
        if bad_crc {
            Some(Err(Error::Crc))
        } else {
            None
        }
    }

    /// Checks, after the decoder took the last byte of `stream` and answered `got`, that it
    /// answered as the reference and that its counters agree.
    pub(crate) fn check(
        &mut self,
        stream: &[u8],
        dec: &StreamDecoder,
        got: Option<Result<Message, Error>>,
    ) {
        let want = self.step(stream);
        check!(
            got == want,
            "P-5: no frame held back: push answers with the earliest frame with a good CRC ending at this byte"
        );
        let s = dec.stats();
        check!(
            s.crc_errors == self.crc_errors,
            "P-5: each candidate with a bad CRC is counted once"
        );
        check!(
            s.dropped_bytes as usize + dec.buffered()
                == self.dropped + (stream.len() - self.boundary),
            "P-5: every byte is delivered in a frame, dropped or held"
        );
    }
}

/// Garbage bytes before the frame. Under Kani 3 bytes of any values: a shorter garbage is the same
/// stream with 0x00 bytes in front, which the decoder drops at once (they start nothing, and
/// nothing started before them), so only the counters differ. Three bytes reach a false SOF whose
/// LEN reaches past the frame (`AA 55 id` then the frame's `AA` as LEN); a candidate from the
/// garbage that ends inside the frame needs four, which made the proof run for many minutes (the
/// twin and the exhaustive test cover it). The twin draws up to 24, biased toward the bytes that
/// make candidates.
const GARBAGE: usize = if cfg!(kani) { 3 } else { 24 };

/// P-5: No valid frame is held back by the bytes before it: any garbage, then the frame of `m`, fed
/// byte by byte, gives at every byte what the naive [`Reference`] says, and the frame is
/// delivered at its last byte unless the garbage began a frame with a good CRC that took some
/// of its bytes.
pub(crate) fn check_stream_holds_back_no_frame(src: &mut impl Source, m: &Message) {
    let mut frame = [0u8; MAX_FRAME_LEN];
    let f = m.encode(&mut frame);
    let mut stream = [0u8; GARBAGE + MAX_FRAME_LEN];
    let n = if cfg!(kani) {
        GARBAGE
    } else {
        usize::from(src.below(GARBAGE as u8 + 1))
    };
    let garbage: [u8; GARBAGE] = src.bytes();
    stream[..GARBAGE].copy_from_slice(&garbage);
    if !cfg!(kani) {
        // Random bytes seldom make a candidate: the twin takes some from the frame's own bytes
        // and from SOF and LEN values.
        for (i, b) in stream[..n].iter_mut().enumerate() {
            *b = match src.below(6) {
                0 => 0xAA,
                1 => 0x55,
                2 => frame[i % f],
                _ => *b,
            };
        }
    }
    stream[n..n + f].copy_from_slice(&frame[..f]);
    let total = n + f;
    let mut dec = StreamDecoder::new();
    let mut reference = Reference::new();
    let mut last = None;
    for end in 1..=total {
        let got = dec.push(stream[end - 1]);
        reference.check(&stream[..end], &dec, got);
        last = got;
    }
    let taken = reference.first_start.is_some_and(|s| s < n);
    check!(
        taken || last == Some(Ok(*m)),
        "P-5: a valid frame after any garbage is delivered at its last byte"
    );
    let sof_at = |i: usize| stream[i] == 0xAA && stream[i + 1] == 0x55;
    cover!(src, (0..n).any(sof_at), "false SOF in the garbage");
    cover!(
        src,
        (0..n).any(|i| sof_at(i) && i + 3 < total && i + 6 + usize::from(stream[i + 3]) > total),
        "a false SOF whose LEN reaches past the frame"
    );
    cover!(
        src,
        !taken && reference.crc_errors > 0,
        "frame delivered after a crc error"
    );
    cover!(src, taken, "the garbage began a valid frame");
}

/// encode → decode_frame, and encode → stream, give back the same message.
pub(crate) fn check_round_trip(src: &mut impl Source) {
    let kind = src.below(KINDS);
    let m = check_round_trip_of(src, kind);
    cover!(src, matches!(m, Message::Imu(_)), "imu");
    cover!(src, matches!(m, Message::SetMotorPwm(_)), "pwm");
}

/// [`check_round_trip`] for one message kind: [`check_frame_round_trip_of`], then the same frame
/// fed to a stream decoder byte by byte. Returns the message sent.
pub(crate) fn check_round_trip_of(src: &mut impl Source, kind: u8) -> Message {
    let (m, buf, n) = check_frame_round_trip_of(src, kind);
    stream_delivers(&m, &buf, n);
    m
}

/// P-6, P-22: The stream half of [`check_round_trip_of`] on its own (one CRC computation fewer under Kani).
pub(crate) fn check_stream_round_trip_of(src: &mut impl Source, kind: u8) {
    let m = any_message_of(src, kind);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    stream_delivers(&m, &buf, n);
    cover!(src, buf[n - 2..n] != [0, 0], "frame with a non-zero CRC");
}

/// Feeding the frame `buf[..n]` of `m` byte by byte to a fresh stream decoder delivers `m` at the
/// frame's last byte, and nothing before.
fn stream_delivers(m: &Message, buf: &[u8; MAX_FRAME_LEN], n: usize) {
    let mut dec = StreamDecoder::new();
    let mut got = None;
    for (i, &b) in buf[..n].iter().enumerate() {
        if let Some(r) = dec.push(b) {
            // Delivered at the frame's last byte, not before.
            check!(
                i + 1 == n,
                "P-6: a frame is delivered at its last byte, not before"
            );
            got = Some(r);
        }
    }
    check!(
        got == Some(Ok(*m)),
        "P-6: the stream delivers the message sent"
    );
}

/// P-6: encode → `decode_frame` gives back the same message, for one message kind (under Kani each
/// kind a constant, the seven one after the other: with the kind symbolic every field sits at a
/// symbolic offset). Returns the message and its frame.
pub(crate) fn check_frame_round_trip_of(
    src: &mut impl Source,
    kind: u8,
) -> (Message, [u8; MAX_FRAME_LEN], usize) {
    let m = any_message_of(src, kind);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    check!(
        n == HEADER_LEN + m.id().payload_len() + CRC_LEN,
        "P-6: a frame has its kind's length"
    );
    check!(
        decode_frame(&buf[..n]) == Ok(m),
        "P-6: a frame decodes to the message sent"
    );
    cover!(src, buf[n - 2..n] != [0, 0], "frame with a non-zero CRC");
    (m, buf, n)
}

/// Flipping any one bit of a frame makes `decode_frame` refuse it.
pub(crate) fn check_bit_flip_detected(src: &mut impl Source) {
    let m = any_message(src);
    let region = if src.bool() {
        Flip::LenByte
    } else {
        Flip::OtherBytes
    };
    let at = src.u16();
    check_bit_flip_detected_in(src, &m, region, at);
}

/// Index of the LEN byte in a frame.
const LEN_INDEX: usize = 3;

/// Where [`check_bit_flip_detected_in`] flips a bit.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Flip {
    /// A bit of the LEN byte: refused at the length check, before the CRC is looked at.
    LenByte,
    /// A bit of any other byte (SOF, MSG_ID, payload, CRC): the LEN byte, and so every slice
    /// length, stays as sent.
    OtherBytes,
}

/// P-7: [`check_bit_flip_detected`] for the frame of `m`. With the checksum affine over GF(2) (see
/// `crc16::verification`), whether a flip in the covered bytes or the CRC is caught depends only
/// on the flip and the frame length, not on the frame's content; a flip in the SOF or LEN is a
/// framing error whatever the content. So one frame per length, every bit, covers every frame of
/// that length: one message of each kind (each kind has its own length).
///
/// The flipped bit is bit `at % 8` of the LEN byte, or of byte `at / 8` (modulo the frame's other
/// bytes) of the bytes without it. The test `bit_flip_in_every_sample_for_every_bit` runs every
/// `at` of each kind's sample frame outside the LEN byte, real CRC: an enumeration of the whole
/// input, so no Kani harness for those (over a symbolic bit they took 81 s for the seven kinds).
/// The LEN byte's flips are Kani harnesses with any CRC value, which shows the refusal does not
/// depend on the CRC and so on the content.
pub(crate) fn check_bit_flip_detected_in(
    src: &mut impl Source,
    m: &Message,
    region: Flip,
    at: u16,
) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    let byte = match region {
        Flip::LenByte => LEN_INDEX,
        Flip::OtherBytes => {
            let b = usize::from(at / 8) % (n - 1);
            if b >= LEN_INDEX {
                b + 1
            } else {
                b
            }
        }
    };
    let mask = 1u8 << (at % 8);
    // Written byte by byte at known indices, the LEN byte never touched for `OtherBytes`: under
    // Kani a write at a symbolic index would make LEN, and so every slice length, symbolic.
    for (i, v) in buf[..n].iter_mut().enumerate() {
        let at_len = i == LEN_INDEX;
        if at_len == (region == Flip::LenByte) && i == byte {
            *v ^= mask;
        }
    }
    let r = decode_frame(&buf[..n]);
    check!(r.is_err(), "P-7: a frame with one bit flipped is refused");
    if region == Flip::LenByte {
        check!(
            r == Err(Error::Framing),
            "P-7: a flip of the LEN byte is refused as Framing"
        );
        cover!(src, buf[LEN_INDEX] > 4, "LEN made longer");
    } else {
        cover!(src, byte < 2, "flip in SOF");
        cover!(src, byte == LEN_INDEX - 1, "flip in MSG_ID");
        cover!(src, byte >= n - 2, "flip in CRC");
    }
}

/// One message of each kind, drawn by the twin driver from a fixed seed (the bit-flip harnesses'
/// frames; their content does not matter, see [`check_bit_flip_detected_in`]).
#[cfg(any(kani, test))]
fn sample_of(kind: u8) -> Message {
    any_message_of(&mut statemachine::harness::Twin::new(0x5A3_0001), kind)
}

/// Kani harnesses (`cargo kani -p protocol -Z stubbing -Z function-contracts --harness cdc::`,
/// with `-Z unstable-options --cbmc-args --max-field-sensitivity-array-size 512` so that CBMC
/// tracks the 261-byte frame buffers element by element; without it even a concrete frame's
/// decode runs out of memory, see `proofs/REPORT.md`).
///
/// Totality harnesses replace the CRC by `crc16::verification::model::any_checksum` (any value):
/// their properties hold whatever the CRC returns, and `crc16::verify_checksum_total` proves the
/// real one returns for every input. Round trips and bit flips use the real CRC. The stream
/// decoder is total: `verify_stream_step` checks one `push` from any state, its two scans by their
/// loop contracts (built with `--cfg kani_loop_contracts`, `-Z loop-contracts`), with `candidate_at`
/// replaced by [`model::candidate_at`] (any verdict), which `verify_candidate_at` proves, and
/// `may_start` by [`model::may_start`], which `verify_may_start` proves, and `append` by
/// [`model::append`], whose counts `verify_append` proves.
/// `verify_stream_holds_back_no_frame_{ping,estop}` prove the decoder's property for any 3 bytes
/// before a PING or an ESTOP frame, with the CRC computed by the seeds' bitwise loop
/// (`crc16::verification::seed_loop`, the same function as `checksum`, which the test
/// `seed_loop_is_checksum` compares at every frame length; the block folding over slices of
/// many possible lengths multiplied the formula).
#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use super::*;
    use statemachine::harness::KaniSource;

    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    fn verify_decode_frame_total() {
        check_decode_frame_total(&mut KaniSource);
    }

    /// `push`'s two scans run over up to the whole buffer. Each is replaced by its loop contract
    /// (the invariants on the loops of `complete` and `advance`, checked here: they hold on entry
    /// and after every pass), each position by the proven stand-ins of `candidate_at` and
    /// `may_start`, `append` by its proven counts. Loop contracts apply to every harness that
    /// runs the loops, so this one is compiled on its own with `--cfg kani_loop_contracts` and
    /// `-Z loop-contracts` (`.ci/run`); unrolled to the buffer's length it did not finish in
    /// 25 min. `.ci/run` gives CBMC 8 object bits for it: the loop contracts are checked against
    /// sets with one entry per possible object, and at Kani's default of 16 bits those sets made
    /// the formula 130 times larger (`proofs/REPORT.md`, "Kani suite time").
    #[cfg_attr(kani_loop_contracts, kani::proof)]
    #[cfg_attr(
        kani_loop_contracts,
        kani::stub(StreamDecoder::candidate_at, super::model::candidate_at)
    )]
    #[cfg_attr(
        kani_loop_contracts,
        kani::stub(crate::cdc::may_start, super::model::may_start)
    )]
    #[cfg_attr(
        kani_loop_contracts,
        kani::stub(StreamDecoder::append, super::model::append)
    )]
    fn verify_stream_step() {
        check_stream_step(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(8)]
    fn verify_append() {
        check_append(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(8)]
    fn verify_may_start() {
        check_may_start(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL: 24 s against 30 s on one build, 19 s against
    // 28 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::solver(minisat)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    fn verify_candidate_at() {
        check_candidate_at(&mut KaniSource);
    }

    /// The property of [`StreamDecoder`] (no valid frame held back), any 3 bytes before a PING
    /// frame (6 bytes) and before an ESTOP frame (7 bytes), CRC by `seed_loop`.
    #[kani::proof]
    #[kani::unwind(12)]
    #[kani::stub(crate::crc16::checksum, crate::crc16::verification::seed_loop)]
    fn verify_stream_holds_back_no_frame_ping() {
        check_stream_holds_back_no_frame(&mut KaniSource, &Message::Ping);
    }

    #[kani::proof]
    #[kani::unwind(12)]
    #[kani::stub(crate::crc16::checksum, crate::crc16::verification::seed_loop)]
    fn verify_stream_holds_back_no_frame_estop() {
        check_stream_holds_back_no_frame(&mut KaniSource, &Message::Estop(Estop::Engage));
    }

    /// Every message kind with its name, for the harnesses that prove one property of each kind
    /// in turn: `$m!` is given `kind => "NAME"` for each. As many as [`KINDS`] (checked below), so
    /// no kind the twins run is left out of those harnesses.
    macro_rules! every_kind {
        ($m:ident) => {
            $m!(
                0 => "SET_MOTOR_PWM",
                1 => "MOTOR_ENABLE",
                2 => "ESTOP",
                3 => "PING",
                4 => "ACK",
                5 => "IMU",
                6 => "STATUS"
            )
        };
    }
    macro_rules! count_kinds {
        ($($kind:literal => $name:literal),+) => {
            [$($kind),+].len()
        };
    }
    const _: () = assert!(every_kind!(count_kinds) == KINDS as usize);

    /// A flipped bit of the LEN byte in a frame of each kind, one message per kind (see
    /// [`check_bit_flip_detected_in`] for why that covers every frame), with any CRC value: the
    /// flip is refused before the CRC is consulted. (With the real CRC the changed length makes
    /// every slice length symbolic and CBMC runs out of memory. The flips of the other bytes are
    /// enumerated by a test.) The seven kinds one after the other in one harness, each with a
    /// cover of its own; the inner covers are shared, since every kind runs the same code.
    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    fn verify_len_flip_every_kind() {
        let mut src = KaniSource;
        macro_rules! len_flip_of {
            ($($kind:literal => $name:literal),+) => {$(
                let at = src.u16();
                check_bit_flip_detected_in(&mut src, &sample_of($kind), Flip::LenByte, at);
                kani::cover(true, concat!("a LEN flip of ", $name, " checked"));
            )+};
        }
        every_kind!(len_flip_of);
    }

    /// encode → `decode_frame` for every message kind, the seven one after the other in one
    /// harness, with the checksum as an uninterpreted function (`model::uninterpreted_checksum`:
    /// any value, the same for the same bytes; forgotten between kinds, so each kind's round trip
    /// is proven for every such function on its own). The property needs only that `encode` and
    /// `decode_frame` get the same value for the same covered bytes, which holds for every pure
    /// function of the bytes, the real CRC among them; `verify_checksum_total` proves the real one
    /// returns for every input, and the twins run it. With the real CRC the solver had to prove two
    /// copies of the CRC circuit equal over the symbolic payload, and its time depended on the
    /// order of the formula's variables: 60 s in one clone of the repository, over 50 minutes in
    /// another. Each kind has a cover of its own: its frame with a non-zero CRC.
    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::uninterpreted_checksum
    )]
    fn verify_round_trip_every_kind() {
        macro_rules! round_trip_of {
            ($($kind:literal => $name:literal),+) => {$(
                crate::crc16::verification::model::forget_checksums();
                let (_, buf, n) = check_frame_round_trip_of(&mut KaniSource, $kind);
                kani::cover(
                    buf[n - 2..n] != [0, 0],
                    concat!($name, ": a frame with a non-zero CRC"),
                );
            )+};
        }
        every_kind!(round_trip_of);
    }

    /// encode → stream decoder, byte by byte, for PING, whose frame has no payload; the checksum
    /// uninterpreted, as in the frame round trips above.
    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::uninterpreted_checksum
    )]
    fn verify_stream_round_trip_ping() {
        check_stream_round_trip_of(&mut KaniSource, 3);
    }
}

#[cfg(test)]
mod twins {
    use super::*;
    use statemachine::harness::Twin;

    #[test]
    fn decode_frame_total() {
        Twin::run(0xC0_0001, 20_000, check_decode_frame_total).assert_covered(6);
    }

    #[test]
    fn stream_total() {
        Twin::run(0xC0_0002, 2_000, check_stream_total).assert_covered(3);
    }

    #[test]
    fn round_trip() {
        Twin::run(0xC0_0003, 20_000, check_round_trip).assert_covered(3);
    }

    #[test]
    fn round_trip_of_every_kind() {
        for kind in 0..KINDS {
            Twin::run(0xC0_0010 + u64::from(kind), 5_000, |src| {
                let _ = check_round_trip_of(src, kind);
            })
            .assert_covered(1);
            Twin::run(0xC0_0030 + u64::from(kind), 2_000, |src| {
                check_stream_round_trip_of(src, kind);
            })
            .assert_covered(1);
        }
    }

    #[test]
    fn stream_step() {
        Twin::run(0xC0_0005, 50_000, check_stream_step).assert_covered(4);
    }

    #[test]
    fn append() {
        Twin::run(0xC0_000A, 50_000, check_append).assert_covered(2);
    }

    #[test]
    fn may_start() {
        Twin::run(0xC0_0009, 50_000, check_may_start).assert_covered(2);
    }

    #[test]
    fn candidate_at() {
        Twin::run(0xC0_0007, 50_000, check_candidate_at).assert_covered(3);
    }

    #[test]
    fn stream_holds_back_no_frame() {
        Twin::run(0xC0_0008, 20_000, |src| {
            let m = any_message(src);
            check_stream_holds_back_no_frame(src, &m);
        })
        .assert_covered(4);
    }

    /// Every bit of each kind's sample frame, the LEN byte's included, each flipped once.
    #[test]
    fn bit_flip_in_every_sample_for_every_bit() {
        for kind in 0..KINDS {
            let seed = 0xC0_0020 + u64::from(kind);
            let m = sample_of(kind);
            let n = m.encode(&mut [0u8; MAX_FRAME_LEN]);
            Twin::each(seed, (n as u32 - 1) * 8, |src, at| {
                check_bit_flip_detected_in(src, &m, Flip::OtherBytes, at as u16);
            })
            .assert_covered(3);
            Twin::each(seed, 8, |src, at| {
                check_bit_flip_detected_in(src, &m, Flip::LenByte, at as u16);
            })
            .assert_covered(1);
        }
    }

    #[test]
    fn bit_flip_detected() {
        Twin::run(0xC0_0004, 20_000, check_bit_flip_detected).assert_covered(4);
    }
}
