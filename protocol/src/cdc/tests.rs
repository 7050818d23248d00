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
    let got = collect(&mut StreamDecoder::new(), &bytes);
    // The broken frame's CRC is checked once its 26 announced bytes are in (7 + 7 + 6 + 6 of them),
    // then the rescan finds the swallowed ESTOP and PINGs.
    let ping = Ok(Message::Ping);
    assert_eq!(
        got,
        [
            Err(Error::Crc),
            Ok(Message::Estop(Estop::Engage)),
            ping,
            ping,
            ping
        ]
    );
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
