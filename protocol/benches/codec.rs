//! Criterion benchmarks: encode, decode and CRC per frame for every link.
//! `cargo bench -p protocol --bench codec` (host figures; on the MCU measure with the cycle counter).
#![allow(clippy::unwrap_used, clippy::indexing_slicing, missing_docs)]

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use protocol::{amr, cdc, crc16, pi_spi, teensy};

fn benches(c: &mut Criterion) {
    let cmd = amr::MotorCommand {
        timestamp_us: 123_456_789,
        left_speed_cmd: 1.25,
        right_speed_cmd: -3.5,
        control_mode: 1,
        enable: true,
        seq: 4242,
        request: 0,
    };
    let fb = amr::MotorFeedback {
        timestamp_us: 987_654_321,
        left_speed: 1.2,
        right_speed: -3.4,
        left_current: 0.8,
        right_current: 1.1,
        left_encoder: -123_456,
        right_encoder: 654_321,
        fault_flags: 0x0200,
        seq: 99,
        mode: 0,
        cmd_seq: 4241,
    };
    let mut cf = [0u8; amr::FRAME_LEN];
    amr::encode_command(&cmd, &mut cf);
    let mut ff = [0u8; amr::FRAME_LEN];
    amr::encode_feedback(&fb, &mut ff);

    c.bench_function("crc16 62 bytes (amr frame body)", |b| {
        b.iter(|| crc16::checksum(black_box(&cf[..amr::CRC_OFFSET])))
    });
    c.bench_function("amr encode_command", |b| {
        let mut out = [0u8; amr::FRAME_LEN];
        b.iter(|| amr::encode_command(black_box(&cmd), &mut out))
    });
    c.bench_function("amr decode_command", |b| {
        b.iter(|| amr::decode_command(black_box(&cf)))
    });
    c.bench_function("amr encode_feedback", |b| {
        let mut out = [0u8; amr::FRAME_LEN];
        b.iter(|| amr::encode_feedback(black_box(&fb), &mut out))
    });
    c.bench_function("amr decode_feedback", |b| {
        b.iter(|| amr::decode_feedback(black_box(&ff)))
    });

    let pwm = cdc::Message::SetMotorPwm(cdc::SetMotorPwm {
        pwm: [100, -200, 300, -400],
        timeout_ms: 200,
    });
    let mut pf = [0u8; cdc::MAX_FRAME_LEN];
    let n = pwm.encode(&mut pf);
    c.bench_function("cdc encode SET_MOTOR_PWM", |b| {
        let mut out = [0u8; cdc::MAX_FRAME_LEN];
        b.iter(|| black_box(&pwm).encode(&mut out))
    });
    c.bench_function("cdc decode_frame SET_MOTOR_PWM", |b| {
        b.iter(|| cdc::decode_frame(black_box(&pf[..n])))
    });
    c.bench_function("cdc stream 16 bytes (one frame)", |b| {
        b.iter(|| {
            let mut d = cdc::StreamDecoder::new();
            d.feed(black_box(&pf[..n])).count()
        })
    });

    let rx = pi_spi::RxBuffer::default();
    let mut rb = [0u8; pi_spi::RX_LEN];
    pi_spi::encode_rx(&rx, &mut rb);
    c.bench_function("pi_spi encode_rx", |b| {
        let mut out = [0u8; pi_spi::RX_LEN];
        b.iter(|| pi_spi::encode_rx(black_box(&rx), &mut out))
    });
    c.bench_function("pi_spi decode_rx", |b| {
        b.iter(|| pi_spi::decode_rx(black_box(&rb)))
    });

    let m = teensy::CmdMsg::<4> {
        mtr_angles: [10, 20, 30, 40],
        ..Default::default()
    };
    let mut tf = [0u8; teensy::ROBUST_BUF];
    let tn = m.encode_robust(&mut tf).unwrap();
    c.bench_function("teensy encode_robust (4 motors)", |b| {
        let mut out = [0u8; teensy::ROBUST_BUF];
        b.iter(|| black_box(&m).encode_robust(&mut out))
    });
    c.bench_function("teensy decode_robust (4 motors)", |b| {
        b.iter(|| teensy::CmdMsg::<4>::decode_robust(black_box(&tf[..tn])))
    });
}

criterion_group!(codec, benches);
criterion_main!(codec);
