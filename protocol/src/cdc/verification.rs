//! Kani harnesses of the seed 001 framing and stream decoder, and their `cargo test` twins.

use super::*;
use statemachine::cover;
use statemachine::harness::Source;

/// Longest arbitrary input the harnesses feed: small under Kani, a full frame and more in the twins.
const MAX_INPUT: usize = if cfg!(kani) {
    12
} else {
    2 * MAX_FRAME_LEN + 8
};

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

/// `decode_frame` returns a message or a typed error for every input up to `MAX_INPUT` bytes.
pub(crate) fn check_decode_frame_total(src: &mut impl Source) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = match src.below(3) {
        0 => {
            // Arbitrary bytes of arbitrary length.
            let n = usize::from(src.u16()) % (MAX_INPUT.min(MAX_FRAME_LEN) + 1);
            for b in buf.iter_mut().take(n) {
                *b = src.u8();
            }
            n
        }
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

/// encode → decode_frame, and encode → stream, give back the same message.
pub(crate) fn check_round_trip(src: &mut impl Source) {
    let kind = src.below(KINDS);
    let m = check_round_trip_of(src, kind);
    cover!(src, matches!(m, Message::Imu(_)), "imu");
    cover!(src, matches!(m, Message::SetMotorPwm(_)), "pwm");
}

/// [`check_round_trip`] for one message kind (under Kani one harness per kind: with the kind
/// symbolic every field sits at a symbolic offset). Returns the message sent.
pub(crate) fn check_round_trip_of(src: &mut impl Source, kind: u8) -> Message {
    let m = any_message_of(src, kind);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    assert_eq!(n, HEADER_LEN + m.id().payload_len() + CRC_LEN);
    assert_eq!(decode_frame(&buf[..n]), Ok(m));
    let mut dec = StreamDecoder::new();
    let mut got = None;
    for (i, &b) in buf[..n].iter().enumerate() {
        if let Some(r) = dec.push(b) {
            // Delivered at the frame's last byte, not before.
            assert_eq!(i + 1, n);
            got = Some(r);
        }
    }
    assert_eq!(got, Some(Ok(m)));
    cover!(src, buf[n - 2..n] != [0, 0], "frame with a non-zero CRC");
    m
}

/// Flipping any one bit of a frame makes `decode_frame` refuse it.
pub(crate) fn check_bit_flip_detected(src: &mut impl Source) {
    let m = any_message(src);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    let bit = usize::from(src.u16()) % (n * 8);
    buf[bit / 8] ^= 1 << (bit % 8);
    let r = decode_frame(&buf[..n]);
    assert!(r.is_err());
    cover!(src, bit < 16, "flip in SOF");
    cover!(src, (24..32).contains(&bit), "flip in LEN");
    cover!(src, bit >= (n - 2) * 8, "flip in CRC");
}

/// Kani harnesses, pending: they do not finish on today's solvers (symbolic-length slices through
/// the decoders); they run only with `RUSTFLAGS="--cfg kani_pending" cargo kani`, and always as
/// `cargo test` twins. See `proofs/REPORT.md`.
#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use super::*;
    use statemachine::harness::KaniSource;

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(30))]
    fn verify_decode_frame_total() {
        check_decode_frame_total(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(30))]
    fn verify_stream_total() {
        check_stream_total(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(30))]
    fn verify_round_trip() {
        check_round_trip(&mut KaniSource);
    }

    /// One round-trip harness per message kind, the CRC replaced by the uninterpreted-function
    /// model (`crc16::verification::model`): the property needs only that sender and receiver
    /// compute the same checksum over the same bytes. Pending too: the IMU one did not finish in
    /// 400 s (`RUSTFLAGS="--cfg kani_pending" cargo kani -p protocol -Z stubbing --harness
    /// verify_round_trip_imu`); with a fixed XOR-fold in place of the model it verified in 24 s.
    macro_rules! round_trip_of {
        ($($name:ident => $kind:literal),+) => {$(
            #[cfg_attr(kani_pending, kani::proof)]
            #[cfg_attr(kani_pending, kani::unwind(30))]
            #[cfg_attr(
                kani_pending,
                kani::stub(crate::crc16::checksum, crate::crc16::verification::model::checksum)
            )]
            fn $name() {
                let _ = check_round_trip_of(&mut KaniSource, $kind);
            }
        )+};
    }
    round_trip_of!(
        verify_round_trip_set_motor_pwm => 0,
        verify_round_trip_motor_enable => 1,
        verify_round_trip_estop => 2,
        verify_round_trip_ping => 3,
        verify_round_trip_ack => 4,
        verify_round_trip_imu => 5,
        verify_round_trip_status => 6
    );

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(30))]
    fn verify_bit_flip_detected() {
        check_bit_flip_detected(&mut KaniSource);
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
        }
    }

    #[test]
    fn bit_flip_detected() {
        Twin::run(0xC0_0004, 20_000, check_bit_flip_detected).assert_covered(3);
    }
}
