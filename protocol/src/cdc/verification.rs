//! Kani harnesses of the seed 001 framing and stream decoder, and their `cargo test` twins.

use super::*;
use statemachine::cover;
use statemachine::harness::Source;

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

/// `decode_frame` returns a message or a typed error for every input of every length up to
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
    let mut errors = 0u32;
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
            assert!(dec.buffered() <= MAX_FRAME_LEN);
            match r {
                Some(Ok(_)) => ok += 1,
                Some(Err(_)) => errors += 1,
                None => {}
            }
        }
    }
    while let Some(r) = dec.poll() {
        if r.is_ok() {
            ok += 1;
        } else {
            errors += 1;
        }
        assert!(dec.buffered() <= MAX_FRAME_LEN);
    }
    let s = dec.stats();
    assert_eq!(s.frames, ok);
    assert_eq!(s.crc_errors + s.message_errors, errors);
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

/// One step of the stream decoder from *any* state it can be in (up to a full buffer of any
/// bytes, any counters) never panics and never overfills, and every step of `poll`'s loop that
/// does not finish drops a byte: so `push`, `poll` and `feed` are total and terminate, by
/// induction over the bytes buffered.
pub(crate) fn check_stream_step(src: &mut impl Source) {
    let mut bytes: [u8; MAX_FRAME_LEN] = src.bytes();
    let mut held = usize::from(src.u16()) % (MAX_FRAME_LEN + 1);
    // Under Kani any bytes held already include every state; the twin, which would rarely draw a
    // frame, also takes a frame of any MSG_ID and any payload of up to 16 bytes at the front,
    // possibly with one byte replaced.
    if !cfg!(kani) && src.bool() {
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = usize::from(src.below(17));
        let n = encode_raw(src.u8(), &bytes[..len], &mut frame);
        if src.bool() {
            frame[usize::from(src.u8()) % n] = src.u8();
        }
        bytes[..n].copy_from_slice(&frame[..n]);
        held = held.max(n);
    }
    let mut dec = StreamDecoder::new();
    dec.buf = bytes;
    dec.len = held;
    dec.stats = Stats {
        frames: src.u32(),
        crc_errors: src.u32(),
        message_errors: src.u32(),
        dropped_bytes: src.u32(),
    };
    let before = dec.stats;
    if src.bool() {
        dec.append(src.u8());
        assert!(dec.buffered() == (held + 1).min(MAX_FRAME_LEN));
        cover!(src, held == MAX_FRAME_LEN, "append to a full buffer");
        return;
    }
    let step = dec.poll_step();
    let after = dec.stats;
    assert!(dec.buffered() <= held);
    assert!(after.frames >= before.frames && after.crc_errors >= before.crc_errors);
    assert!(after.message_errors >= before.message_errors);
    assert!(after.dropped_bytes >= before.dropped_bytes);
    match step {
        Scan::Again => {
            assert!(dec.buffered() + 1 == held);
            cover!(
                src,
                held == MAX_FRAME_LEN,
                "byte dropped from a full buffer"
            );
        }
        Scan::Done(None) => assert!(dec.buffered() == held),
        Scan::Done(Some(r)) => {
            assert!(dec.buffered() < held);
            cover!(src, r.is_ok(), "frame delivered");
            cover!(src, r == Err(Error::Crc), "crc error");
            cover!(src, r == Err(Error::UnknownMsg), "unknown msg");
        }
    }
}

/// `drop_front(n)` from any state keeps exactly the bytes after the first `n` (none if fewer are
/// held), in order: the specification that [`model::drop_front`] stands in for.
pub(crate) fn check_drop_front(src: &mut impl Source) {
    let mut dec = StreamDecoder::new();
    dec.buf = src.bytes();
    dec.len = usize::from(src.u16()) % (MAX_FRAME_LEN + 1);
    let before = dec.clone();
    let n = usize::from(src.u16());
    dec.drop_front(n);
    let keep = before.len.saturating_sub(n);
    assert_eq!(dec.buffered(), keep);
    assert!(dec.stats() == before.stats());
    // One byte kept, anywhere: it is the byte `n` places further on.
    let i = usize::from(src.u16()) % MAX_FRAME_LEN;
    if i < keep {
        assert_eq!(dec.buf[i], before.buf[i + n]);
    }
    cover!(
        src,
        n > 0 && keep > 1 && i == keep - 1,
        "last kept byte moved"
    );
    cover!(
        src,
        n > before.len && before.len > 0,
        "more dropped than held"
    );
}

/// Stand-ins for the Kani harnesses, each over-approximating a function proven separately.
#[cfg(kani)]
pub(crate) mod model {
    use super::*;

    /// [`StreamDecoder::drop_front`] as `check_drop_front` proves it for the length, with any
    /// bytes kept: for harnesses whose properties do not read the bytes after a drop.
    pub(crate) fn drop_front(dec: &mut StreamDecoder, n: usize) {
        let keep = dec.len.saturating_sub(n);
        dec.buf = kani::any();
        dec.len = keep;
    }
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

/// The stream half of [`check_round_trip_of`] on its own (one CRC computation fewer under Kani).
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
            assert_eq!(i + 1, n);
            got = Some(r);
        }
    }
    assert_eq!(got, Some(Ok(*m)));
}

/// encode → `decode_frame` gives back the same message, for one message kind (under Kani one
/// harness per kind: with the kind symbolic every field sits at a symbolic offset). Returns the
/// message and its frame.
pub(crate) fn check_frame_round_trip_of(
    src: &mut impl Source,
    kind: u8,
) -> (Message, [u8; MAX_FRAME_LEN], usize) {
    let m = any_message_of(src, kind);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    assert!(n == HEADER_LEN + m.id().payload_len() + CRC_LEN);
    assert!(decode_frame(&buf[..n]) == Ok(m));
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
    check_bit_flip_detected_in(src, &m, region);
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

/// [`check_bit_flip_detected`] for the frame of `m`. With the checksum affine over GF(2) (see
/// `crc16::verification`), whether a flip in the covered bytes or the CRC is caught depends only
/// on the flip and the frame length, not on the frame's content; a flip in the SOF or LEN is a
/// framing error whatever the content. So one frame per length, every bit, covers every frame of
/// that length: the Kani harnesses take one message of each kind (each kind has its own length).
pub(crate) fn check_bit_flip_detected_in(src: &mut impl Source, m: &Message, region: Flip) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    let byte = match region {
        Flip::LenByte => LEN_INDEX,
        Flip::OtherBytes => {
            let b = usize::from(src.u16()) % (n - 1);
            if b >= LEN_INDEX {
                b + 1
            } else {
                b
            }
        }
    };
    let mask = 1u8 << src.below(8);
    // Written byte by byte at known indices, the LEN byte never touched for `OtherBytes`: under
    // Kani a write at a symbolic index would make LEN, and so every slice length, symbolic.
    for (i, v) in buf[..n].iter_mut().enumerate() {
        let at_len = i == LEN_INDEX;
        if at_len == (region == Flip::LenByte) && i == byte {
            *v ^= mask;
        }
    }
    let r = decode_frame(&buf[..n]);
    assert!(r.is_err());
    if region == Flip::LenByte {
        assert_eq!(r, Err(Error::Framing));
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
/// decoder is total and terminates by induction: `verify_stream_step` proves one step from any
/// state, with `drop_front` replaced by [`model::drop_front`], whose length `verify_drop_front`
/// proves. Those under `cfg_attr(kani_pending, …)` do not finish yet and run as `cargo test` twins.
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

    #[kani::proof]
    #[kani::unwind(8)]
    fn verify_drop_front() {
        check_drop_front(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::stub(
        crate::crc16::checksum,
        crate::crc16::verification::model::any_checksum
    )]
    #[kani::stub(StreamDecoder::drop_front, super::model::drop_front)]
    fn verify_stream_step() {
        check_stream_step(&mut KaniSource);
    }

    /// A single flipped bit in a frame of each kind, one message per kind (see
    /// [`check_bit_flip_detected_in`] for why that covers every frame): outside the LEN byte with
    /// the real CRC; in the LEN byte with any CRC value, which shows the flip is refused before
    /// the CRC is consulted (with the real CRC the changed length makes every slice length
    /// symbolic and CBMC runs out of memory).
    macro_rules! bit_flip_of {
        ($($name:ident, $len_name:ident => $kind:literal),+) => {$(
            #[kani::proof]
            #[kani::unwind(30)]
            fn $name() {
                check_bit_flip_detected_in(&mut KaniSource, &sample_of($kind), Flip::OtherBytes);
            }

            #[kani::proof]
            #[kani::unwind(30)]
            #[kani::stub(crate::crc16::checksum, crate::crc16::verification::model::any_checksum)]
            fn $len_name() {
                check_bit_flip_detected_in(&mut KaniSource, &sample_of($kind), Flip::LenByte);
            }
        )+};
    }
    bit_flip_of!(
        verify_bit_flip_set_motor_pwm, verify_len_flip_set_motor_pwm => 0,
        verify_bit_flip_motor_enable, verify_len_flip_motor_enable => 1,
        verify_bit_flip_estop, verify_len_flip_estop => 2,
        verify_bit_flip_ping, verify_len_flip_ping => 3,
        verify_bit_flip_ack, verify_len_flip_ack => 4,
        verify_bit_flip_imu, verify_len_flip_imu => 5,
        verify_bit_flip_status, verify_len_flip_status => 6
    );

    /// encode → `decode_frame` with the real CRC, one harness per message kind.
    macro_rules! frame_round_trip_of {
        ($($name:ident => $kind:literal),+) => {$(
            #[kani::proof]
            #[kani::unwind(30)]
            fn $name() {
                let _ = check_frame_round_trip_of(&mut KaniSource, $kind);
            }
        )+};
    }
    frame_round_trip_of!(
        verify_round_trip_set_motor_pwm => 0,
        verify_round_trip_motor_enable => 1,
        verify_round_trip_estop => 2,
        verify_round_trip_ping => 3,
        verify_round_trip_ack => 4,
        verify_round_trip_imu => 5,
        verify_round_trip_status => 6
    );

    /// encode → stream decoder, byte by byte (real CRC; `drop_front` by its proven length, see
    /// `verify_drop_front`), for PING, whose frame has no payload.
    #[kani::proof]
    #[kani::unwind(30)]
    #[kani::stub(StreamDecoder::drop_front, super::model::drop_front)]
    fn verify_stream_round_trip_ping() {
        check_stream_round_trip_of(&mut KaniSource, 3);
    }

    // Pending: the same for the kinds with a payload. STATUS (12 payload bytes) ran out of memory
    // (9 GB): the decoder's copy of the frame and the encoder's CRC over the original are not
    // seen to be the same bytes. Twins `round_trip_of_every_kind`.
    macro_rules! stream_round_trip_of {
        ($($name:ident => $kind:literal),+) => {$(
            #[cfg_attr(kani_pending, kani::proof)]
            #[cfg_attr(kani_pending, kani::unwind(30))]
            #[cfg_attr(kani_pending, kani::stub(StreamDecoder::drop_front, super::model::drop_front))]
            fn $name() {
                check_stream_round_trip_of(&mut KaniSource, $kind);
            }
        )+};
    }
    stream_round_trip_of!(
        verify_stream_round_trip_set_motor_pwm => 0,
        verify_stream_round_trip_motor_enable => 1,
        verify_stream_round_trip_estop => 2,
        verify_stream_round_trip_ack => 4,
        verify_stream_round_trip_imu => 5,
        verify_stream_round_trip_status => 6
    );
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
    fn drop_front() {
        Twin::run(0xC0_0006, 50_000, check_drop_front).assert_covered(2);
    }

    #[test]
    fn stream_step() {
        Twin::run(0xC0_0005, 50_000, check_stream_step).assert_covered(5);
    }

    #[test]
    fn bit_flip_in_every_sample() {
        for kind in 0..KINDS {
            let seed = 0xC0_0020 + u64::from(kind);
            Twin::run(seed, 2_000, |src| {
                check_bit_flip_detected_in(src, &sample_of(kind), Flip::OtherBytes);
            })
            .assert_covered(3);
            Twin::run(seed, 200, |src| {
                check_bit_flip_detected_in(src, &sample_of(kind), Flip::LenByte);
            })
            .assert_covered(1);
        }
    }

    #[test]
    fn bit_flip_detected() {
        Twin::run(0xC0_0004, 20_000, check_bit_flip_detected).assert_covered(4);
    }
}
