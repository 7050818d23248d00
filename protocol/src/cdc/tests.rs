//! Unit tests of the seed 001 framing and stream decoder.

use super::*;
use std::vec::Vec;

/// The seed's CRC loop, kept here as an independent reference.
fn crc_ref(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// A frame built by hand from the seed's description.
fn frame(id: u8, payload: &[u8]) -> Vec<u8> {
    let mut f = vec![0xAA, 0x55, id, payload.len() as u8];
    f.extend_from_slice(payload);
    let crc = crc_ref(&f[2..]);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

fn encoded(m: &Message) -> Vec<u8> {
    let mut out = [0u8; MAX_FRAME_LEN];
    let n = m.encode(&mut out);
    out[..n].to_vec()
}

#[test]
fn set_motor_pwm_layout_from_the_seed() {
    // pwm -1000, 1000, 0, 1; timeout 200 ms: little-endian two's complement.
    let payload = [0x18, 0xFC, 0xE8, 0x03, 0x00, 0x00, 0x01, 0x00, 0xC8, 0x00];
    let m = Message::SetMotorPwm(SetMotorPwm {
        pwm: [-1000, 1000, 0, 1],
        timeout_ms: 200,
    });
    assert_eq!(encoded(&m), frame(0x01, &payload));
    assert_eq!(decode_frame(&frame(0x01, &payload)), Ok(m));
}

#[test]
fn every_message_round_trips() {
    let msgs = [
        Message::SetMotorPwm(SetMotorPwm {
            pwm: [1, -2, 3, -4],
            timeout_ms: 500,
        }),
        Message::MotorEnable(true),
        Message::MotorEnable(false),
        Message::Estop(Estop::Engage),
        Message::Estop(Estop::Release),
        Message::Ping,
        Message::Ack(Ack {
            msg_id: 0x03,
            result: 0,
        }),
        Message::Imu(Imu {
            t_ms: 123_456,
            accel_mg: [0, -1000, 1000],
            gyro_mdps: [5, -5, 32767],
            temp_cdeg: 2512,
        }),
        Message::Status(Status {
            t_ms: 9,
            vbat_mv: 12_600,
            flags: StatusFlags(0b1011),
            err: 4,
        }),
    ];
    for m in msgs {
        let f = encoded(&m);
        assert_eq!(f.len(), 6 + m.id().payload_len());
        assert_eq!(f[2], m.id() as u8);
        assert_eq!(decode_frame(&f), Ok(m));
    }
    assert_eq!(frame(0x10, &[]), encoded(&Message::Ping));
}

#[test]
fn payload_errors() {
    assert_eq!(decode_frame(&frame(0x02, &[2])), Err(Error::Value));
    assert_eq!(decode_frame(&frame(0x03, &[0xFF])), Err(Error::Value));
    assert_eq!(decode_frame(&frame(0x02, &[1, 0])), Err(Error::Length));
    assert_eq!(decode_frame(&frame(0x01, &[0; 9])), Err(Error::Length));
    assert_eq!(decode_frame(&frame(0x55, &[])), Err(Error::UnknownMsg));
    assert_eq!(Error::UnknownMsg.reason(), RejectReason::Decode);
    assert_eq!(Error::Crc.error_code(), ErrorCode::CrcError);
    let mut f = frame(0x10, &[]);
    f[4] ^= 0x01;
    assert_eq!(decode_frame(&f), Err(Error::Crc));
    assert_eq!(decode_frame(&f[..5]), Err(Error::Framing));
    assert_eq!(
        decode_frame(&[0xAB, 0x55, 0x10, 0x00, 0, 0]),
        Err(Error::Framing)
    );
}

fn collect(dec: &mut StreamDecoder, bytes: &[u8]) -> Vec<Result<Message, Error>> {
    dec.feed(bytes).collect()
}

#[test]
fn stream_skips_garbage() {
    let mut dec = StreamDecoder::new();
    let mut bytes = vec![0x00, 0x13, 0xAA, 0xAA, 0x77];
    bytes.extend(frame(0x02, &[1]));
    assert_eq!(collect(&mut dec, &bytes), [Ok(Message::MotorEnable(true))]);
    assert_eq!(dec.stats().dropped_bytes, 5);
    assert_eq!(dec.stats().frames, 1);
    assert_eq!(dec.buffered(), 0);
}

#[test]
fn stream_recovers_from_a_truncated_frame() {
    // An IMU frame cut after 7 bytes, then a complete ESTOP frame that the truncated one swallows.
    let imu = encoded(&Message::Imu(Imu::default()));
    let estop = frame(0x03, &[1]);
    let mut bytes = imu[..7].to_vec();
    bytes.extend(&estop);
    for _ in 0..3 {
        bytes.extend(frame(0x10, &[]));
    }
    // The ESTOP is delivered at its own last byte (the 14th), not after the 26 bytes the broken
    // IMU frame announced; the IMU candidate, which started before it, goes with it.
    let mut dec = StreamDecoder::new();
    let at: Vec<_> = bytes
        .iter()
        .enumerate()
        .filter_map(|(i, &b)| dec.push(b).map(|r| (i, r)))
        .collect();
    let ping = Ok(Message::Ping);
    assert_eq!(
        at,
        [
            (13, Ok(Message::Estop(Estop::Engage))),
            (19, ping),
            (25, ping),
            (31, ping)
        ]
    );
    assert_eq!(dec.stats().dropped_bytes, 7);
    assert_eq!(dec.stats().crc_errors, 0);
}

#[test]
fn stream_recovers_from_a_false_sof_inside_a_payload() {
    // Garbage that looks like a header announcing 4 payload bytes, right before a real frame.
    let mut bytes = vec![0xAA, 0x55, 0x01, 0x04];
    bytes.extend(frame(0x02, &[0]));
    let got = collect(&mut StreamDecoder::new(), &bytes);
    assert_eq!(got, [Err(Error::Crc), Ok(Message::MotorEnable(false))]);
}

#[test]
fn stream_after_bad_crc_and_reset() {
    let mut dec = StreamDecoder::new();
    let mut bad = frame(0x10, &[]);
    bad[5] ^= 0x80;
    let mut bytes = bad.clone();
    bytes.extend(frame(0x10, &[]));
    assert_eq!(
        collect(&mut dec, &bytes),
        [Err(Error::Crc), Ok(Message::Ping)]
    );
    assert_eq!(dec.stats().crc_errors, 1);
    assert_eq!(dec.stats().dropped_bytes, 6);
    // A partial frame then a reset.
    assert!(collect(&mut dec, &[0xAA, 0x55, 0x01]).is_empty());
    assert_eq!(dec.buffered(), 3);
    dec.reset();
    assert_eq!(dec.buffered(), 0);
    assert_eq!(dec.stats().dropped_bytes, 9);
}

#[test]
fn push_one_byte_at_a_time() {
    let mut dec = StreamDecoder::new();
    let mut results = Vec::new();
    for b in frame(0x03, &[0]) {
        if let Some(r) = dec.push(b) {
            results.push(r);
        }
    }
    assert_eq!(results, [Ok(Message::Estop(Estop::Release))]);
}

#[test]
fn events_for_the_ladder() {
    use statemachine::{AxisCommand, AxisMode, Config, Source, Speed};
    assert_eq!(
        Message::MotorEnable(true).to_event(),
        Some(Event::Rearm(Source::Primary))
    );
    assert!(matches!(
        Message::MotorEnable(false).to_event(),
        Some(Event::Frame(Command { enable: false, axes, .. })) if axes == [AxisCommand::COAST; 4]
    ));
    assert_eq!(
        Message::Estop(Estop::Engage).to_event(),
        Some(Event::Estop {
            source: Source::Primary,
            action: Estop::Engage
        })
    );
    assert_eq!(Message::Ping.to_event(), None);
    // The seed: pwm / 1000 of full scale, 0 coasts; timeout_ms = 200 brakes at the 199th tick.
    let pwm = SetMotorPwm {
        pwm: [500, -1000, 0, 250],
        timeout_ms: 200,
    };
    let c = pwm.to_command();
    assert_eq!(
        c.axes,
        [
            AxisCommand::duty(0.5),
            AxisCommand::duty(-1.0),
            AxisCommand::COAST,
            AxisCommand::duty(0.25)
        ]
    );
    assert_eq!(c.timeout, Some(199));
    let sp = statemachine::validate(&c, None, Speed::ONE, &Config::CDC).unwrap();
    assert_eq!(sp.brake_after, 199);
    assert_eq!(sp.axes[2].mode, AxisMode::Coast);
    // Beyond full scale and a zero timeout are refused (and counted by the ladder), never clamped.
    for bad in [
        SetMotorPwm {
            pwm: [1001, 0, 0, 0],
            timeout_ms: 200,
        },
        SetMotorPwm {
            pwm: [0; 4],
            timeout_ms: 0,
        },
    ] {
        let r = statemachine::validate(&bad.to_command(), None, Speed::ONE, &Config::CDC);
        assert_eq!(r, Err(RejectReason::OutOfRange), "{bad:?}");
    }
    // The seed 000 profile refuses duty.
    let r = statemachine::validate(&c, None, Speed::ONE, &Config::AMR_SPI);
    assert_eq!(r, Err(RejectReason::UnsupportedMode));
}

/// The bytes from the alphabet of [`stream_holds_back_no_frame_exhaustively`]: each makes or
/// breaks a candidate (zero, SOF, a LEN reaching past everything, the MSG_IDs, LEN and action of
/// ESTOP, PING's MSG_ID, the first CRC byte of the ESTOP frame).
const DANGEROUS: [u8; 8] = [0x00, 0xAA, 0x55, 0xFF, 0x03, 0x01, 0x10, 0xDC];

/// Longest garbage prefix [`stream_holds_back_no_frame_exhaustively`] tries.
const PREFIX: usize = 6;

/// Every garbage prefix of up to [`PREFIX`] bytes from [`DANGEROUS`], then frames: an ESTOP, alone
/// or behind a PING, a truncated copy of itself, a truncated IMU frame (LEN 20), or a STATUS
/// whose payload holds a false SOF with LEN 255. At every byte the decoder answers as the naive
/// reference (`verification::Reference`, which tries every start), its counters agree, and the
/// ESTOP is delivered at its last byte unless the garbage began a frame with a good CRC.
#[test]
fn stream_holds_back_no_frame_exhaustively() {
    let estop = encoded(&Message::Estop(Estop::Engage));
    assert_eq!(estop, [0xAA, 0x55, 0x03, 0x01, 0x01, 0xDC, 0xB6]);
    let imu = encoded(&Message::Imu(Imu::default()));
    // t_ms little-endian: AA 55 03 FF, a false SOF of LEN 255 inside the payload.
    let status = encoded(&Message::Status(Status {
        t_ms: 0xFF03_55AA,
        ..Status::default()
    }));
    assert_eq!(status[4..8], [0xAA, 0x55, 0x03, 0xFF]);
    let tails: [Vec<u8>; 6] = [
        estop.clone(),
        [encoded(&Message::Ping), estop.clone()].concat(),
        [&estop[..4], &estop].concat(),
        [&estop[..6], &estop].concat(),
        [&imu[..7], &estop].concat(),
        [status, estop.clone()].concat(),
    ];
    let mut streams = 0u32;
    let mut taken = 0u32;
    for len in 0..=PREFIX {
        for code in 0..DANGEROUS.len().pow(len as u32) {
            let mut prefix = Vec::with_capacity(len);
            let mut c = code;
            for _ in 0..len {
                prefix.push(DANGEROUS[c % DANGEROUS.len()]);
                c /= DANGEROUS.len();
            }
            for tail in &tails {
                let stream = [prefix.as_slice(), tail].concat();
                let mut dec = StreamDecoder::new();
                let mut reference = verification::Reference::new();
                let mut last = None;
                for end in 1..=stream.len() {
                    let got = dec.push(stream[end - 1]);
                    reference.check(&stream[..end], &dec, got);
                    last = got;
                }
                let garbage_frame = reference.first_start.is_some_and(|s| s < len);
                assert!(
                    garbage_frame || last == Some(Ok(Message::Estop(Estop::Engage))),
                    "ESTOP held back after {prefix:02X?}, tail {tail:02X?}"
                );
                streams += 1;
                taken += u32::from(garbage_frame);
            }
        }
    }
    // 299,593 prefixes, 6 tails. A garbage frame needs a good CRC over bytes the prefix chose:
    // none of these prefixes makes one.
    assert_eq!(streams, 1_797_558);
    assert_eq!(taken, 0);
}

/// The worst case of the decoder's CRC work at one byte, which its documentation states: at most
/// 64 candidates end at the same byte, their CRCs covering at most 8,384 bytes in all; and a
/// window that reaches it makes the decoder check all 64.
#[test]
fn crc_work_per_byte_is_bounded() {
    // The bytes a candidate fixes, in a window of `w` bytes whose last byte it ends at.
    let fixed = |w: usize, s: usize| [(s, 0xAA), (s + 1, 0x55), (s + 3, w - 6 - s)];
    let compatible = |w: usize, t: usize, s: usize| {
        fixed(w, t)
            .iter()
            .all(|&(p, v)| fixed(w, s).iter().all(|&(q, u)| p != q || v == u))
    };
    // Every window length, every set of starts, by dynamic programming over the starts from left to
    // right: only the starts chosen among the last three can share a byte with the next one
    // (a candidate fixes its bytes 0, 1 and 3). Each state keeps the most candidates and,
    // separately, the most bytes covered.
    let mut most = (0usize, 0usize);
    for w in MIN_FRAME_LEN..=MAX_FRAME_LEN {
        let mut states: [Option<(usize, usize)>; 8] = [None; 8];
        states[0] = Some((0, 0));
        for s in 0..=w - MIN_FRAME_LEN {
            let covered = w - 6 - s + 2;
            let mut next: [Option<(usize, usize)>; 8] = [None; 8];
            for (mask, state) in states.iter().enumerate() {
                let Some((count, bytes)) = *state else {
                    continue;
                };
                let mut keep = |m: usize, c: usize, b: usize| {
                    let e = next[m].get_or_insert((c, b));
                    *e = (e.0.max(c), e.1.max(b));
                };
                keep((mask << 1) & 7, count, bytes);
                let fits = (1..=3).all(|d| mask & (1 << (d - 1)) == 0 || compatible(w, s - d, s));
                if fits {
                    keep(((mask << 1) | 1) & 7, count + 1, bytes + covered);
                }
            }
            states = next;
        }
        for (c, b) in states.into_iter().flatten() {
            most = (most.0.max(c), most.1.max(b));
        }
    }
    assert_eq!(most, (64, 8384));
    // A window reaching 64: a false SOF every 4 bytes, LEN 255, 251, …, 3, all ending at byte 260.
    let mut window = [0x00; MAX_FRAME_LEN];
    for s in (0..=252).step_by(4) {
        window[s] = 0xAA;
        window[s + 1] = 0x55;
        window[s + 3] = (MAX_FRAME_LEN - 6 - s) as u8;
    }
    let mut dec = StreamDecoder::new();
    for &b in &window[..MAX_FRAME_LEN - 1] {
        assert_eq!(dec.push(b), None);
    }
    assert_eq!(dec.buffered(), MAX_FRAME_LEN - 1);
    assert_eq!(dec.push(window[MAX_FRAME_LEN - 1]), Some(Err(Error::Crc)));
    assert_eq!(dec.stats().crc_errors, 64);
}

/// The seed's framing has no escaping, so a payload can carry a whole valid frame. The stream
/// decoder delivers a valid frame at its last byte (P-5), which then is the inner one: an IMU
/// frame sent 1070.506 s after power-on (`t_ms` = 0x0010_55AA, little-endian `AA 55 10 00`, the
/// head of a PING frame) whose x acceleration equals a PING frame's CRC is received as a PING, and
/// the IMU frame itself is lost (its start was consumed with the PING). The stream round trip (P-6) therefore holds for
/// frames in which no valid frame ends before the last byte; `decode_frame` of the frame itself
/// is unaffected.
#[test]
fn a_payload_that_carries_a_whole_frame_is_received_as_that_frame() {
    let ping = frame(0x10, &[]);
    assert_eq!(
        ping,
        encoded(&Message::Ping),
        "0x10 is PING, with no payload"
    );
    let ping_crc = i16::from_le_bytes([ping[4], ping[5]]);
    let imu = Imu {
        t_ms: 0x0010_55AA,
        accel_mg: [ping_crc, 0, 1000],
        gyro_mdps: [0; 3],
        temp_cdeg: 2500,
    };
    let bytes = encoded(&Message::Imu(imu));
    assert_eq!(
        &bytes[4..10],
        &ping[..],
        "the IMU payload begins with a PING frame"
    );
    assert_eq!(
        decode_frame(&bytes),
        Ok(Message::Imu(imu)),
        "the frame itself decodes"
    );
    let mut dec = StreamDecoder::new();
    let got: Vec<_> = bytes.iter().filter_map(|&b| dec.push(b)).collect();
    assert_eq!(
        got,
        [Ok(Message::Ping)],
        "the stream yields the PING and not the IMU frame"
    );
}

/// P-4, the half of `append` that `verify_append` leaves to this test: from every state with a full
/// buffer (every `first`, so every number of bytes moved) and every state without (every `len`),
/// each byte kept ends up where the bytes held before it say. `append` copies bytes without
/// reading them (its only data-dependent statement is the store of the byte pushed), so what it
/// does to the buffer is one fixed selection of positions per `(len, first)`; two passes, tagged
/// with the low and the high byte of each position, name that selection exactly, whatever the
/// bytes are.
#[test]
fn append_keeps_the_bytes_in_order() {
    let mut states = 0u32;
    for len in 0..=MAX_FRAME_LEN {
        for first in 0..=len {
            for tag in [|i: usize| i as u8, |i: usize| (i >> 8) as u8] {
                let mut dec = StreamDecoder::new();
                for (i, b) in dec.buf.iter_mut().enumerate() {
                    *b = tag(i);
                }
                dec.len = len;
                dec.first = first;
                dec.append(0xEE);
                // The position each byte now held came from: moved down by `gone` when full.
                let gone = if len == MAX_FRAME_LEN {
                    first.max(1)
                } else {
                    0
                };
                assert_eq!(dec.len, len - gone + 1, "len={len} first={first}");
                assert_eq!(dec.buf[dec.len - 1], 0xEE, "len={len} first={first}");
                for j in 0..dec.len - 1 {
                    assert_eq!(dec.buf[j], tag(j + gone), "len={len} first={first} j={j}");
                }
            }
            states += 1;
        }
    }
    // Every (len, first) with first <= len <= MAX_FRAME_LEN: (n + 1)(n + 2) / 2 for n = MAX_FRAME_LEN.
    assert_eq!(
        states as usize,
        (MAX_FRAME_LEN + 1) * (MAX_FRAME_LEN + 2) / 2
    );
}

/// The seed's STATUS `err` list (0 OK, 1 CRC_ERROR, 2 LEN_ERROR, 3 UNKNOWN_MSG, 4 IMU_FAIL), read
/// back from the raw value, and the code and the safety core's reason of every failure as the
/// module documentation maps them.
#[test]
fn error_codes_and_reasons_follow_the_seed() {
    let seed = [
        (0, ErrorCode::Ok),
        (1, ErrorCode::CrcError),
        (2, ErrorCode::LenError),
        (3, ErrorCode::UnknownMsg),
        (4, ErrorCode::ImuFail),
    ];
    for (raw, code) in seed {
        assert_eq!(ErrorCode::from_raw(raw), Some(code), "err {raw}");
    }
    for raw in [5, 0x0100, u16::MAX] {
        assert_eq!(ErrorCode::from_raw(raw), None, "err {raw}");
    }
    let failures = [
        (Error::Crc, RejectReason::Crc, ErrorCode::CrcError),
        (Error::Framing, RejectReason::Framing, ErrorCode::LenError),
        (Error::Length, RejectReason::Decode, ErrorCode::LenError),
        (
            Error::UnknownMsg,
            RejectReason::Decode,
            ErrorCode::UnknownMsg,
        ),
        (Error::Value, RejectReason::Decode, ErrorCode::UnknownMsg),
    ];
    for (e, reason, code) in failures {
        assert_eq!(e.reason(), reason, "{e:?}");
        assert_eq!(e.error_code(), code, "{e:?}");
    }
}

/// `duty` is the seed's `min(|pwm|·ARR/1000, ARR)` with the sign kept: within ±1000 a duty is
/// itself, beyond it full scale on its own side.
#[test]
fn duty_saturates_at_full_scale_on_each_side() {
    let p = SetMotorPwm {
        pwm: [1001, -1001, i16::MIN, -7],
        timeout_ms: 200,
    };
    assert_eq!(p.duty(), [1000, -1000, -1000, -7]);
    let p = SetMotorPwm {
        pwm: [i16::MAX, 1000, -1000, 999],
        timeout_ms: 200,
    };
    assert_eq!(p.duty(), [1000, 1000, -1000, 999]);
}

/// STATUS `flags` as the seed numbers them (bit 0 motor_enabled, bit 1 estop_latched, bit 2
/// cmd_timeout, bit 3 imu_ok), read from a received payload: flags 0x000A is ESTOP latched with the
/// IMU healthy, motors disabled and no command timeout.
#[test]
fn status_flags_are_the_seeds_bits() {
    assert_eq!(StatusFlags::MOTOR_ENABLED, 0x0001);
    assert_eq!(StatusFlags::ESTOP_LATCHED, 0x0002);
    assert_eq!(StatusFlags::CMD_TIMEOUT, 0x0004);
    assert_eq!(StatusFlags::IMU_OK, 0x0008);
    // t_ms 1, vbat 0, flags 0x000A, err 0.
    let payload = [0x01, 0, 0, 0, 0, 0, 0x0A, 0x00, 0, 0];
    let Ok(Message::Status(s)) = decode_frame(&frame(0x82, &payload)) else {
        panic!("STATUS refused");
    };
    assert!(s.flags.has(StatusFlags::ESTOP_LATCHED));
    assert!(s.flags.has(StatusFlags::IMU_OK));
    assert!(s
        .flags
        .has(StatusFlags::ESTOP_LATCHED | StatusFlags::IMU_OK));
    assert!(!s.flags.has(StatusFlags::MOTOR_ENABLED));
    assert!(!s.flags.has(StatusFlags::CMD_TIMEOUT));
    assert!(!s
        .flags
        .has(StatusFlags::ESTOP_LATCHED | StatusFlags::MOTOR_ENABLED));
}

/// A candidate that has ended cannot end again: at the byte where its CRC fails, the decoder lets
/// go of it (no byte of it can start another frame: no `AA` after its SOF) and counts its bytes
/// as dropped at once, not at the next byte.
#[test]
fn a_frame_with_a_bad_crc_is_let_go_at_its_last_byte() {
    // PING: AA 55 10 00, then the seed's CRC over 10 00, 0x1E7C, low byte first.
    let ping = [0xAA, 0x55, 0x10, 0x00, 0x7C, 0x1E];
    assert_eq!(frame(0x10, &[]), ping);
    let mut bad = ping;
    bad[5] ^= 0x80;
    let mut dec = StreamDecoder::new();
    for &b in &bad[..5] {
        assert_eq!(dec.push(b), None);
    }
    assert_eq!(dec.buffered(), 5);
    assert_eq!(dec.push(bad[5]), Some(Err(Error::Crc)));
    assert_eq!(dec.buffered(), 0);
    assert_eq!(
        dec.stats(),
        Stats {
            frames: 0,
            crc_errors: 1,
            message_errors: 0,
            dropped_bytes: 6,
        }
    );
}
