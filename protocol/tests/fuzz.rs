//! Fuzz targets, one per decoder (bolero). Under `cargo test` each runs a bounded number of random
//! inputs; for a longer run set `BOLERO_RANDOM_ITERATIONS` (see protocol/README.md), e.g.
//! `BOLERO_RANDOM_ITERATIONS=2000000 cargo test --release -p protocol --test fuzz -- --nocapture`.
//! Every target also checks that whatever decodes re-encodes to the same message.
//!
//! The two `*_stream_holds_back_no_frame` targets check the stream decoders' property (a frame
//! with a good CRC is delivered at its last byte, whatever came before it; see
//! `cdc::StreamDecoder` and `teensy::RobustDecoder`) at every byte of a stream built from the
//! input, with valid, truncated and raw frames spliced in, against a naive reference written
//! here (independent of the one in the crate's harnesses). Coverage-guided runs (libFuzzer, nightly:
//! `cargo xtask fuzz`) and their figures are in protocol/README.md; `cargo test` also replays each
//! target's committed corpus (`tests/__fuzz__/<target>/corpus/`).
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    missing_docs
)]

use protocol::{amr, cdc, crc16, pi_spi, teensy};
use statemachine::RejectReason;
use std::sync::atomic::{AtomicU64, Ordering};

fn report(name: &str, n: &AtomicU64) {
    eprintln!(
        "fuzz {name}: {} executions, no finding",
        n.load(Ordering::Relaxed)
    );
}

fn frame64(input: &[u8], fix_crc: bool) -> [u8; amr::FRAME_LEN] {
    let mut f = [0u8; amr::FRAME_LEN];
    let n = input.len().min(amr::FRAME_LEN);
    f[..n].copy_from_slice(&input[..n]);
    if fix_crc {
        let crc = crc16::checksum(&f[..amr::CRC_OFFSET]);
        f[amr::CRC_OFFSET..].copy_from_slice(&crc.to_be_bytes());
    }
    f
}

#[test]
fn fuzz_amr_command() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(amr::FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            for fix in [false, true] {
                let f = frame64(input, fix);
                if let Ok(c) = amr::decode_command(&f) {
                    let mut g = [0u8; amr::FRAME_LEN];
                    amr::encode_command(&c, &mut g);
                    let d = amr::decode_command(&g).unwrap();
                    assert_eq!(format!("{c:?}"), format!("{d:?}"));
                }
            }
        });
    report("amr_command", &N);
}

#[test]
fn fuzz_amr_feedback() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(amr::FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            for fix in [false, true] {
                let f = frame64(input, fix);
                if let Ok(fb) = amr::decode_feedback(&f) {
                    let mut g = [0u8; amr::FRAME_LEN];
                    amr::encode_feedback(&fb, &mut g);
                    assert_eq!(
                        format!("{fb:?}"),
                        format!("{:?}", amr::decode_feedback(&g).unwrap())
                    );
                }
            }
        });
    report("amr_feedback", &N);
}

/// Every 64-byte input through `decode_info` and `decode_mcu_frame`: no panic, whatever decodes
/// re-encodes to the same message, and the two decoders agree on which frames are info frames.
#[test]
fn fuzz_amr_info() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(amr::FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            for fix in [false, true] {
                let f = frame64(input, fix);
                let info = amr::decode_info(&f);
                let any = amr::decode_mcu_frame(&f);
                match any {
                    Ok(amr::McuFrame::Info(i)) => {
                        assert_eq!(info, Ok(i));
                        assert_eq!(amr::decode_feedback(&f), Err(RejectReason::Version));
                    }
                    Ok(amr::McuFrame::Feedback(fb)) => {
                        let direct = amr::decode_feedback(&f).unwrap();
                        assert_eq!(format!("{fb:?}"), format!("{direct:?}"));
                    }
                    // A frame refused as feedback for its version is refused for what the info
                    // decoder found; any other refusal is the feedback decoder's.
                    Err(e) => match amr::decode_feedback(&f).map(|_| ()) {
                        Err(RejectReason::Version) => assert_eq!(info.map(|_| ()), Err(e)),
                        other => assert_eq!(other, Err(e)),
                    },
                }
                if let Ok(i) = info {
                    let mut g = [0u8; amr::FRAME_LEN];
                    amr::encode_info(&i, &mut g);
                    assert_eq!(amr::decode_info(&g), Ok(i));
                }
            }
        });
    report("amr_info", &N);
}

#[test]
fn fuzz_cdc() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(2 * cdc::MAX_FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            if let Ok(m) = cdc::decode_frame(input) {
                let mut out = [0u8; cdc::MAX_FRAME_LEN];
                let n = m.encode(&mut out);
                assert_eq!(cdc::decode_frame(&out[..n]), Ok(m));
            }
            // Too short, or no SOF: a framing error, whatever follows.
            if input.len() < cdc::MIN_FRAME_LEN || input[..2] != cdc::SOF {
                assert_eq!(cdc::decode_frame(input), Err(cdc::Error::Framing));
            }
            // Any MSG_ID and payload in a frame with a good length and CRC: the frame layer
            // accepts it, so the answer is a message or a message-level error, never Framing or
            // Crc; a message re-encodes to one that decodes the same.
            if let Some((&id, payload)) = input.split_first() {
                let payload = &payload[..payload.len().min(cdc::MAX_PAYLOAD)];
                let mut frame = [0u8; cdc::MAX_FRAME_LEN];
                let n = cdc::encode_raw(id, payload, &mut frame);
                match cdc::decode_frame(&frame[..n]) {
                    Ok(m) => {
                        let mut out = [0u8; cdc::MAX_FRAME_LEN];
                        let k = m.encode(&mut out);
                        assert_eq!(cdc::decode_frame(&out[..k]), Ok(m));
                    }
                    Err(e) => assert!(
                        !matches!(e, cdc::Error::Framing | cdc::Error::Crc),
                        "{e:?} for a well-framed {:02X?}",
                        &frame[..n]
                    ),
                }
            }
            let mut dec = cdc::StreamDecoder::new();
            let mut seen = 0u32;
            for r in dec.feed(input) {
                if r.is_ok() {
                    seen += 1;
                }
            }
            assert!(dec.buffered() <= cdc::MAX_FRAME_LEN);
            assert_eq!(dec.stats().frames, seen);
        });
    report("cdc", &N);
}

#[test]
fn fuzz_pi_spi() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(pi_spi::RX_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            let mut rx = [0u8; pi_spi::RX_LEN];
            let n = input.len().min(pi_spi::RX_LEN);
            rx[..n].copy_from_slice(&input[..n]);
            rx[0] = pi_spi::TRANSFER_VERSION; // get past the version check most of the time
            if let Ok(d) = pi_spi::decode_rx(&rx) {
                let mut g = [0u8; pi_spi::RX_LEN];
                pi_spi::encode_rx(&d, &mut g);
                assert_eq!(g, rx);
            }
            let _ = pi_spi::shutdown_raw(&rx);
            let mut tx = [0u8; pi_spi::TX_LEN];
            let n = input.len().min(pi_spi::TX_LEN);
            tx[..n].copy_from_slice(&input[..n]);
            if let Ok(d) = pi_spi::decode_tx(&tx) {
                let mut g = [0u8; pi_spi::TX_LEN];
                pi_spi::encode_tx(&d, &mut g);
                assert_eq!(g, tx);
            }
        });
    report("pi_spi", &N);
}

#[test]
fn fuzz_teensy() {
    static N: AtomicU64 = AtomicU64::new(0);
    type Msg = teensy::CmdMsg<4>;
    bolero::check!()
        .with_max_len(3 * teensy::ROBUST_BUF)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            if let Ok(m) = Msg::decode_legacy(input) {
                let mut out = [0u8; Msg::LEGACY_LEN];
                m.encode_legacy(&mut out).unwrap();
                assert_eq!(&out[..], input);
            }
            if let Ok(m) = Msg::decode_robust(input) {
                let mut out = [0u8; teensy::ROBUST_BUF];
                let n = m.encode_robust(&mut out).unwrap();
                assert_eq!(Msg::decode_robust(&out[..n]), Ok(m));
            }
            // Any version and message bytes in a body, COBS-stuffed, with the check bytes of a good
            // CRC over the stuffed bytes: the frame layer accepts it, so the answer is a command or
            // a version or message error, never Framing or Crc; a command re-encodes to one that
            // decodes the same.
            const BODY: usize = teensy::robust_body_len(4);
            const S: usize = teensy::stuffed_len(4);
            let mut body = [0u8; BODY];
            let n = input.len().min(BODY);
            body[..n].copy_from_slice(&input[..n]);
            let mut frame = [0u8; Msg::ROBUST_LEN];
            // corncobs writes S and a terminator; the check bytes go over that terminator.
            assert_eq!(corncobs::encode_buf(&body, &mut frame), S + 1);
            let crc = crc16::checksum(&frame[..S]);
            frame[S..S + 3].copy_from_slice(&teensy::check_bytes(crc));
            frame[S + 3] = 0;
            let len = Msg::ROBUST_LEN;
            match Msg::decode_robust(&frame[..len]) {
                Ok(m) => {
                    let mut out = [0u8; teensy::ROBUST_BUF];
                    let k = m.encode_robust(&mut out).unwrap();
                    assert_eq!(Msg::decode_robust(&out[..k]), Ok(m));
                }
                Err(e) => assert!(
                    !matches!(e, RejectReason::Framing | RejectReason::Crc),
                    "{e:?} for a well-framed {:02X?}",
                    &frame[..len]
                ),
            }
            let mut dec = teensy::RobustDecoder::<4>::new();
            for &b in input {
                let _ = dec.push(b);
            }
            for &b in &frame[..len] {
                let _ = dec.push(b);
            }
            // After arbitrary bytes the decoder may still be resynchronising (the stream target
            // checks when it must deliver), so here only a clean decoder must deliver the frame.
            let mut clean = teensy::RobustDecoder::<4>::new();
            let mut got = None;
            for &b in &frame[..len] {
                got = clean.push(b);
            }
            assert_eq!(got, Some(Msg::decode_robust(&frame[..len])));
        });
    report("teensy", &N);
}

/// Reads the fuzzer's bytes, 0 once they run out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let (&b, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        b
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }
}

/// A seed 001 message of kind `kind % 7`, its fields read from `b`.
fn cdc_message(kind: u8, b: &mut Bytes) -> cdc::Message {
    use cdc::Message as M;
    match kind % 7 {
        0 => M::SetMotorPwm(cdc::SetMotorPwm {
            pwm: [
                b.u16() as i16,
                b.u16() as i16,
                b.u16() as i16,
                b.u16() as i16,
            ],
            timeout_ms: b.u16(),
        }),
        1 => M::MotorEnable(b.u8() & 1 == 1),
        2 => M::Estop(if b.u8() & 1 == 1 {
            statemachine::Estop::Engage
        } else {
            statemachine::Estop::Release
        }),
        3 => M::Ping,
        4 => M::Ack(cdc::Ack {
            msg_id: b.u8(),
            result: b.u8(),
        }),
        5 => M::Imu(cdc::Imu {
            t_ms: b.u32(),
            accel_mg: [b.u16() as i16, b.u16() as i16, b.u16() as i16],
            gyro_mdps: [b.u16() as i16, b.u16() as i16, b.u16() as i16],
            temp_cdeg: b.u16() as i16,
        }),
        _ => M::Status(cdc::Status {
            t_ms: b.u32(),
            vbat_mv: b.u16(),
            flags: cdc::StatusFlags(b.u16()),
            err: b.u16(),
        }),
    }
}

/// The seed 001 stream the input describes: each byte is itself, except 0xF0..=0xFE, which
/// splice in a valid frame (0xF0..=0xF6, one per kind, fields from the next bytes), a frame of any
/// MSG_ID with up to 31 payload bytes and a good CRC (0xF7..=0xF9), a valid frame cut short or with
/// one byte replaced (0xFA..=0xFD), or the next byte as it is (0xFE).
fn cdc_stream(input: &[u8]) -> Vec<u8> {
    let mut b = Bytes(input);
    let mut out = Vec::new();
    while let Some((&c, rest)) = b.0.split_first() {
        b.0 = rest;
        let mut frame = [0u8; cdc::MAX_FRAME_LEN];
        match c {
            0xF0..=0xF6 => {
                let n = cdc_message(c - 0xF0, &mut b).encode(&mut frame);
                out.extend_from_slice(&frame[..n]);
            }
            0xF7..=0xF9 => {
                let id = b.u8();
                let len = usize::from(b.u8() % 32);
                let payload: Vec<u8> = (0..len).map(|_| b.u8()).collect();
                let n = cdc::encode_raw(id, &payload, &mut frame);
                out.extend_from_slice(&frame[..n]);
            }
            0xFA..=0xFD => {
                let kind = b.u8();
                let n = cdc_message(kind, &mut b).encode(&mut frame);
                let at = usize::from(b.u8()) % n;
                if c < 0xFC {
                    out.extend_from_slice(&frame[..at]);
                } else {
                    frame[at] = b.u8();
                    out.extend_from_slice(&frame[..n]);
                }
            }
            0xFE => out.push(b.u8()),
            _ => out.push(c),
        }
    }
    out
}

/// The property of `cdc::StreamDecoder`, naively: after each byte, `decode_frame` on every slice
/// that ends there and starts at or after the end of the last frame delivered, within a frame's
/// length of the end, earliest first (only at the starts that hold 0xAA: `decode_frame` refuses
/// any other at its first byte, and skipping them keeps the fuzzer fast). Also checks the
/// counters: one CRC error per candidate that failed, and every byte delivered, dropped or held.
fn check_cdc_stream(stream: &[u8]) -> u32 {
    let mut dec = cdc::StreamDecoder::new();
    let (mut boundary, mut dropped, mut crc_errors, mut delivered) = (0usize, 0usize, 0u32, 0u32);
    let aa: Vec<usize> = (0..stream.len()).filter(|&i| stream[i] == 0xAA).collect();
    for end in 1..=stream.len() {
        let got = dec.push(stream[end - 1]);
        let mut want = None;
        let lo = boundary.max(end.saturating_sub(cdc::MAX_FRAME_LEN));
        let from = aa.partition_point(|&i| i < lo);
        for &start in aa[from..].iter().take_while(|&&i| i < end) {
            match cdc::decode_frame(&stream[start..end]) {
                Err(cdc::Error::Framing) => {}
                Err(cdc::Error::Crc) => {
                    crc_errors += 1;
                    want = Some(Err(cdc::Error::Crc));
                }
                r => {
                    want = Some(r);
                    dropped += start - boundary;
                    boundary = end;
                    delivered += 1;
                    break;
                }
            }
        }
        assert_eq!(got, want, "byte {} of {:02X?}", end - 1, stream);
        let s = dec.stats();
        assert_eq!(s.crc_errors, crc_errors);
        assert_eq!(s.frames + s.message_errors, delivered);
        assert_eq!(
            s.dropped_bytes as usize + dec.buffered(),
            dropped + end - boundary
        );
    }
    delivered
}

#[test]
fn fuzz_cdc_stream_holds_back_no_frame() {
    static N: AtomicU64 = AtomicU64::new(0);
    static FRAMES: AtomicU64 = AtomicU64::new(0);
    bolero::check!().with_max_len(64).for_each(|input: &[u8]| {
        N.fetch_add(1, Ordering::Relaxed);
        let delivered = check_cdc_stream(&cdc_stream(input));
        FRAMES.fetch_add(u64::from(delivered), Ordering::Relaxed);
    });
    report("cdc_stream_holds_back_no_frame", &N);
    eprintln!("  frames delivered: {}", FRAMES.load(Ordering::Relaxed));
}

type Robust = teensy::CmdMsg<4>;

/// A seed 003 command of 4 motors, its fields read from `b`.
fn teensy_command(b: &mut Bytes) -> Robust {
    teensy::CmdMsg {
        cmd_type: teensy::CmdType::from_raw(i32::from(b.u8() % 6)).unwrap_or_default(),
        is_relative: b.u32() as i32,
        mtr_angles: [
            b.u32() as i32,
            b.u32() as i32,
            b.u32() as i32,
            b.u32() as i32,
        ],
        mtr_speed_deg_s: b.u32() as i32,
        mtr_accel_deg_s_s: b.u32() as i32,
        cmd_success: b.u32() as i32,
    }
}

/// The seed 003 robust stream the input describes: each byte is itself, except 0xF0..=0xFE, which
/// splice in a valid frame (0xF0..=0xF7, fields from the next bytes; small field values are
/// frequent, so frames hold zeros that COBS replaces), a valid frame cut short or with one byte
/// replaced (0xF8..=0xFD), or the next byte as it is (0xFE).
fn teensy_stream(input: &[u8]) -> Vec<u8> {
    let mut b = Bytes(input);
    let mut out = Vec::new();
    while let Some((&c, rest)) = b.0.split_first() {
        b.0 = rest;
        let mut frame = [0u8; Robust::ROBUST_LEN];
        match c {
            0xF0..=0xFD => {
                let n = teensy_command(&mut b).encode_robust(&mut frame).unwrap();
                match c {
                    0xF0..=0xF7 => out.extend_from_slice(&frame[..n]),
                    0xF8..=0xFA => out.extend_from_slice(&frame[..usize::from(b.u8()) % n]),
                    _ => {
                        frame[usize::from(b.u8()) % n] = b.u8();
                        out.extend_from_slice(&frame[..n]);
                    }
                }
            }
            0xFE => out.push(b.u8()),
            _ => out.push(c),
        }
    }
    out
}

/// The property of `teensy::RobustDecoder`, naively: after each byte, `decode_robust` on every
/// slice that ends there (up to a few bytes longer than a frame); a frame whose COBS and CRC are
/// good must be what `push` returns. Where none is, `push` answers only at a 0x00 after a non-zero
/// byte, with a framing or CRC error.
fn check_teensy_stream(stream: &[u8]) -> u32 {
    let mut dec = teensy::RobustDecoder::<4>::new();
    let mut delivered = 0;
    for end in 1..=stream.len() {
        let got = dec.push(stream[end - 1]);
        let want = (end.saturating_sub(Robust::ROBUST_LEN + 4)..end)
            .map(|start| Robust::decode_robust(&stream[start..end]))
            .find(|r| !matches!(r, Err(RejectReason::Framing | RejectReason::Crc)));
        match want {
            Some(w) => {
                assert_eq!(got, Some(w), "byte {} of {:02X?}", end - 1, stream);
                delivered += 1;
            }
            None => {
                let answers = matches!(stream[..end], [.., b, 0] if b != 0);
                assert_eq!(
                    got.is_some(),
                    answers,
                    "byte {} of {:02X?}",
                    end - 1,
                    stream
                );
                assert!(matches!(
                    got,
                    None | Some(Err(RejectReason::Framing | RejectReason::Crc))
                ));
            }
        }
    }
    delivered
}

#[test]
fn fuzz_teensy_stream_holds_back_no_frame() {
    static N: AtomicU64 = AtomicU64::new(0);
    static FRAMES: AtomicU64 = AtomicU64::new(0);
    bolero::check!().with_max_len(64).for_each(|input: &[u8]| {
        N.fetch_add(1, Ordering::Relaxed);
        let delivered = check_teensy_stream(&teensy_stream(input));
        FRAMES.fetch_add(u64::from(delivered), Ordering::Relaxed);
    });
    report("teensy_stream_holds_back_no_frame", &N);
    eprintln!("  frames delivered: {}", FRAMES.load(Ordering::Relaxed));
}

// `cargo xtask fuzz` passes each target's input limit to libFuzzer as `-max_len` (bolero's
// libFuzzer engine does not): the numbers written there (`xtask/src/fuzz.rs`) must still cover what
// the targets read. Checked when this file compiles.
const _: () = assert!(
    amr::FRAME_LEN == 64
        && 2 * cdc::MAX_FRAME_LEN == 522
        && 3 * teensy::ROBUST_BUF == 270
        && pi_spi::RX_LEN <= 512
        && pi_spi::TX_LEN <= 512,
    "update the -max_len of the fuzz targets in xtask/src/fuzz.rs"
);
