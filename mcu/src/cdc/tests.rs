use super::*;
use protocol::cdc::{Message, SetMotorPwm, StreamDecoder};
use statemachine::{Config, Estop, FaultFlags, Mode};
use std::vec::Vec;

const ST: BoardStatus = BoardStatus {
    t_ms: 1234,
    vbat_mv: 12_000,
    imu_ok: true,
};

fn board() -> (CdcLinkTask, Safety<MOTORS>) {
    (CdcLinkTask::new(), Safety::new(Config::CDC))
}

fn send(link: &mut CdcLinkTask, s: &mut Safety<MOTORS>, m: &Message) -> Option<Output<MOTORS>> {
    let mut buf = [0u8; cdc::MAX_FRAME_LEN];
    let n = m.encode(&mut buf);
    let mut last = None;
    for &b in &buf[..n] {
        if let Some(o) = link.on_byte(s, b, &ST) {
            last = Some(o);
        }
    }
    last
}

/// Everything the board queued, decoded by an independent decoder.
fn replies(link: &mut CdcLinkTask) -> Vec<Message> {
    let mut dec = StreamDecoder::new();
    let mut out = Vec::new();
    while let Some(b) = link.tx.pop() {
        if let Some(r) = dec.push(b) {
            out.push(r.expect("the board sends valid frames"));
        }
    }
    out
}

fn pwm(p: [i16; 4], timeout_ms: u16) -> Message {
    Message::SetMotorPwm(SetMotorPwm { pwm: p, timeout_ms })
}

fn ack(id: MsgId, result: u8) -> Message {
    Message::Ack(Ack {
        msg_id: id as u8,
        result,
    })
}

#[test]
fn ping_is_answered_with_a_status_at_once() {
    let (mut l, mut s) = board();
    assert!(
        send(&mut l, &mut s, &Message::Ping).is_none(),
        "PING is no ladder event"
    );
    let r = replies(&mut l);
    let [Message::Status(st)] = r.as_slice() else {
        std::panic!("expected one STATUS, got {r:?}");
    };
    assert_eq!((st.t_ms, st.vbat_mv), (1234, 12_000));
    // Power-on: braked, not enabled, no ESTOP, IMU fine.
    assert_eq!(st.flags.0, StatusFlags::IMU_OK);
    assert_eq!(st.err, 0);
}

#[test]
fn enable_then_frames_drive_the_motors_and_only_low_rate_commands_are_acked() {
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_OK)]);
    send(&mut l, &mut s, &pwm([500, -250, 0, 1000], 200));
    assert!(
        replies(&mut l).is_empty(),
        "no ACK for SET_MOTOR_PWM (the seed's advice)"
    );
    let mut out = s.output();
    let mut run = |s: &mut Safety<MOTORS>, l: &mut CdcLinkTask, ticks: u32| {
        for _ in 0..ticks {
            out = crate::serial::tick(s, &Default::default());
            if s.ticks().is_multiple_of(20) {
                send(l, s, &pwm([500, -250, 0, 1000], 200));
            }
        }
        out
    };
    // Just re-armed: REDUCED (half duty) until a clean 1 s window has passed.
    let out = run(&mut s, &mut l, 300);
    assert_eq!(out.mode, Mode::Reduced);
    let m = motor_outputs(&out.drive, 1000);
    assert_eq!(
        m[3],
        MotorOutput {
            ccr: 500,
            in1: true,
            in2: false
        },
        "full duty limited to half"
    );
    let out = run(&mut s, &mut l, 1000);
    assert_eq!(out.mode, Mode::Normal);
    // Ramped at 0.005 per tick: every duty has long reached its command.
    let m = motor_outputs(&out.drive, 1000);
    assert_eq!(
        m,
        [
            MotorOutput {
                ccr: 500,
                in1: true,
                in2: false
            },
            MotorOutput {
                ccr: 250,
                in1: false,
                in2: true
            },
            MotorOutput::COAST,
            MotorOutput {
                ccr: 1000,
                in1: true,
                in2: false
            },
        ]
    );
}

#[test]
fn timeout_ms_brakes_strictly_within_it_and_status_says_so() {
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    send(&mut l, &mut s, &pwm([300; 4], 100));
    crate::serial::tick(&mut s, &Default::default());
    send(&mut l, &mut s, &pwm([300; 4], 100));
    let last_frame_tick = s.ticks();
    let mut braked_at = None;
    for _ in 0..200 {
        let out = crate::serial::tick(&mut s, &Default::default());
        if out.mode == Mode::Brake && braked_at.is_none() {
            braked_at = Some(s.ticks());
        }
    }
    let after = braked_at.expect("BRAKE after the timeout") - last_frame_tick;
    assert!(
        after < 100,
        "BRAKE {after} ticks after the last frame, timeout 100 ms"
    );
    assert!(after >= 61, "not before STOP's own threshold: {after}");
    replies(&mut l);
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert!(st.flags.has(StatusFlags::CMD_TIMEOUT));
    assert!(!st.flags.has(StatusFlags::MOTOR_ENABLED));
}

#[test]
fn estop_latches_and_only_its_release_then_an_enable_rearm() {
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    send(&mut l, &mut s, &pwm([300; 4], 200));
    crate::serial::tick(&mut s, &Default::default());
    replies(&mut l);
    let driving = send(&mut l, &mut s, &pwm([300; 4], 200)).unwrap();
    assert_eq!(
        outputs_after_frame(&driving, 1000),
        None,
        "a frame that does not brake leaves the outputs to the tick"
    );
    let braked = send(&mut l, &mut s, &Message::Estop(Estop::Engage)).unwrap();
    assert_eq!(
        s.mode(),
        Mode::Brake,
        "ESTOP brakes in the step that received it"
    );
    assert_eq!(
        outputs_after_frame(&braked, 1000),
        Some([MotorOutput::short(1000); MOTORS]),
        "and the motors are shorted in the same step"
    );
    assert_eq!(replies(&mut l), [ack(MsgId::Estop, ACK_OK)]);
    // Enable while the ESTOP is engaged: refused.
    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_REFUSED)]);
    // Frames still arrive but the drive stays braked.
    send(&mut l, &mut s, &pwm([300; 4], 200));
    let out = crate::serial::tick(&mut s, &Default::default());
    assert_eq!(out.drive, Drive::Brake);
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert!(st.flags.has(StatusFlags::ESTOP_LATCHED));
    // Release: accepted, still braked until re-armed.
    send(&mut l, &mut s, &Message::Estop(Estop::Release));
    assert_eq!(replies(&mut l), [ack(MsgId::Estop, ACK_OK)]);
    send(&mut l, &mut s, &pwm([300; 4], 200));
    assert_eq!(
        crate::serial::tick(&mut s, &Default::default()).drive,
        Drive::Brake
    );
    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_OK)]);
    send(&mut l, &mut s, &pwm([300; 4], 200));
    let out = crate::serial::tick(&mut s, &Default::default());
    assert_ne!(
        out.mode,
        Mode::Brake,
        "re-armed by enable after the release"
    );
}

/// The seed: `MOTOR_ENABLE 0` forces the outputs to 0, `MOTOR_ENABLE 1` lets `SET_MOTOR_PWM`
/// take effect. A host that disables the motors and keeps its 50 Hz stream running must not have
/// them driven again by the next frame; the stream keeps the link alive (no comm-loss BRAKE).
#[test]
fn motor_enable_0_holds_the_motors_off_under_the_stream_until_motor_enable_1() {
    let (mut l, mut s) = board();
    assert!(!l.motors_enabled(), "power-on: not enabled");
    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert!(l.motors_enabled());
    let run = |s: &mut Safety<MOTORS>, l: &mut CdcLinkTask, ticks: u32| {
        let mut outs = Vec::new();
        for _ in 0..ticks {
            let out = crate::serial::tick(s, &Default::default());
            if s.ticks().is_multiple_of(20) {
                send(l, s, &pwm([500; 4], 200));
            }
            outs.push(out);
        }
        outs
    };
    send(&mut l, &mut s, &pwm([500; 4], 200));
    let driving = run(&mut s, &mut l, 300);
    assert!(motor_outputs(&driving[299].drive, 1000)[0].ccr > 0);
    replies(&mut l);
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert!(
        st.flags.has(StatusFlags::MOTOR_ENABLED),
        "enabled and driving"
    );

    send(&mut l, &mut s, &Message::MotorEnable(false));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_OK)]);
    assert!(!l.motors_enabled());
    for (i, out) in run(&mut s, &mut l, 500).iter().enumerate() {
        assert_eq!(out.mode, Mode::Stop, "tick {i} after MOTOR_ENABLE 0");
        assert_eq!(
            motor_outputs(&out.drive, 1000),
            [MotorOutput::COAST; MOTORS],
            "tick {i} after MOTOR_ENABLE 0: the frames must not drive the motors"
        );
    }
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert!(!st.flags.has(StatusFlags::MOTOR_ENABLED));

    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_OK)]);
    let again = run(&mut s, &mut l, 100);
    assert!(
        motor_outputs(&again[99].drive, 1000)[0].ccr > 0,
        "MOTOR_ENABLE 1 lets the frames drive again"
    );
    assert_eq!(
        s.ladder().counters().brake_entries,
        0,
        "no BRAKE on the way"
    );
}

#[test]
fn a_local_estop_is_not_released_by_the_link() {
    let (mut l, mut s) = board();
    crate::serial::tick(
        &mut s,
        &crate::serial::SerialTickInputs {
            estop: Some(Estop::Engage),
            undervoltage: false,
        },
    );
    send(&mut l, &mut s, &Message::Estop(Estop::Release));
    assert_eq!(
        replies(&mut l),
        [ack(MsgId::Estop, ACK_OK)],
        "the link held no ESTOP of its own: nothing of its own is left engaged"
    );
    assert!(
        s.ladder().faults().contains(FaultFlags::ESTOP),
        "the button's ESTOP stays"
    );
    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_REFUSED)]);
}

#[test]
fn a_corrupted_frame_changes_nothing_but_counters_and_the_next_status_error() {
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    send(&mut l, &mut s, &pwm([300; 4], 200));
    crate::serial::tick(&mut s, &Default::default());
    replies(&mut l);
    let before = s.ladder().last_valid();
    let mut buf = [0u8; cdc::MAX_FRAME_LEN];
    let n = pwm([-900; 4], 200).encode(&mut buf);
    buf[6] ^= 0x40; // a payload bit
    for &b in &buf[..n] {
        l.on_byte(&mut s, b, &ST);
    }
    assert_eq!(s.ladder().last_valid(), before);
    assert_eq!(
        s.ladder()
            .counters()
            .rejected(statemachine::RejectReason::Crc),
        1
    );
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert_eq!(st.err, ErrorCode::CrcError as u16);
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert_eq!(st.err, 0, "reported once");
}

#[test]
fn imu_fail_is_reported_when_the_sensor_does_not_answer() {
    let (mut l, s) = board();
    let st = BoardStatus {
        imu_ok: false,
        ..ST
    };
    l.send_status(&s, &st);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert!(!st.flags.has(StatusFlags::IMU_OK));
    assert_eq!(st.err, ErrorCode::ImuFail as u16);
}

#[test]
fn status_every_100_ticks() {
    let (mut l, s) = board();
    for _ in 0..250 {
        l.periodic(&s, &ST);
    }
    assert_eq!(replies(&mut l).len(), 2);
}

#[test]
fn brake_shorts_every_motor_and_duty_maps_to_ccr_and_direction() {
    assert_eq!(
        motor_outputs(&Drive::Brake, 4199),
        [MotorOutput::short(4199); 4]
    );
    let d = |x: f32| AxisDrive::Duty(statemachine::Duty::from_num(x));
    let out = motor_outputs(
        &Drive::Run([d(0.25), d(-1.0), AxisDrive::Coast, AxisDrive::Short]),
        4200,
    );
    // 0.25 × 4200 = 1050; full reverse = ARR.
    assert_eq!(
        out[0],
        MotorOutput {
            ccr: 1050,
            in1: true,
            in2: false
        }
    );
    assert_eq!(
        out[1],
        MotorOutput {
            ccr: 4200,
            in1: false,
            in2: true
        }
    );
    assert_eq!(out[2], MotorOutput::COAST);
    assert_eq!(out[3], MotorOutput::short(4200));
    assert!((out[0].duty(4200) - 0.25).abs() < 1e-6);
    assert!((out[1].duty(4200) + 1.0).abs() < 1e-6);
}

#[test]
fn imu_units_follow_the_datasheet_and_saturation_is_flagged() {
    // 1 g at ±2 g = 16384 LSB → 1000 mg; 131 LSB = 1 dps → 1000 mdps; raw temperature 0 → 36.53 °C.
    let (imu, sat) = imu_from_raw(7, [16_384, -8192, 0], 0, [131, -1310, 0], &IMU_SCALE);
    assert!(!sat);
    assert_eq!(imu.accel_mg, [1000, -500, 0]);
    assert_eq!(imu.gyro_mdps, [1000, -10_000, 0]);
    assert_eq!(imu.temp_cdeg, 3653);
    // 40 dps = 40 000 mdps does not fit an i16: reported at the limit, flagged.
    let (imu, sat) = imu_from_raw(7, [0; 3], 0, [5240, 0, 0], &IMU_SCALE);
    assert!(sat);
    assert_eq!(imu.gyro_mdps[0], i16::MAX);
}

#[test]
fn an_enable_acked_before_the_first_frame_still_rearms() {
    // The host's order: MOTOR_ENABLE 1, wait for the ACK, then the 50 Hz frames. Ticks pass in
    // between, during which the ladder's comm-loss check keeps re-latching BRAKE.
    let (mut l, mut s) = board();
    for _ in 0..300 {
        crate::serial::tick(&mut s, &Default::default());
    }
    send(&mut l, &mut s, &Message::MotorEnable(true));
    assert_eq!(replies(&mut l), [ack(MsgId::MotorEnable, ACK_OK)]);
    for _ in 0..30 {
        crate::serial::tick(&mut s, &Default::default());
    }
    send(&mut l, &mut s, &pwm([300; 4], 200));
    let out = crate::serial::tick(&mut s, &Default::default());
    assert_eq!(
        out.mode,
        Mode::Reduced,
        "armed by the enable 30 ms before the first frame"
    );
    // But not for ever: an enable not followed by a frame within the BRAKE threshold lapses.
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    for _ in 0..400 {
        crate::serial::tick(&mut s, &Default::default());
    }
    send(&mut l, &mut s, &pwm([300; 4], 200));
    let out = crate::serial::tick(&mut s, &Default::default());
    assert_eq!(out.mode, Mode::Brake, "a re-arm 400 ms old has lapsed");
}

#[test]
fn disabled_frames_keep_the_link_alive_with_every_motor_at_zero() {
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    send(&mut l, &mut s, &pwm([300; 4], 200));
    crate::serial::tick(&mut s, &Default::default());
    send(&mut l, &mut s, &Message::MotorEnable(false));
    let mut out = s.output();
    for t in 0..500 {
        if t % 20 == 0 {
            send(&mut l, &mut s, &pwm([800; 4], 200));
        }
        out = crate::serial::tick(&mut s, &Default::default());
    }
    assert_eq!(
        out.mode,
        Mode::Stop,
        "disabled: STOP, not BRAKE (the frames keep coming)"
    );
    assert_eq!(motor_outputs(&out.drive, 1000), [MotorOutput::COAST; 4]);
    replies(&mut l);
    l.send_status(&s, &ST);
    let [Message::Status(st)] = replies(&mut l)[..] else {
        std::panic!("one STATUS");
    };
    assert!(!st.flags.has(StatusFlags::MOTOR_ENABLED));
    // Enabled again: the frames drive.
    send(&mut l, &mut s, &Message::MotorEnable(true));
    for t in 0..100 {
        if t % 20 == 0 {
            send(&mut l, &mut s, &pwm([800; 4], 200));
        }
        out = crate::serial::tick(&mut s, &Default::default());
    }
    assert_ne!(motor_outputs(&out.drive, 1000)[0], MotorOutput::COAST);
}

#[test]
fn a_disabled_frame_still_carries_its_timeout_to_the_ladder() {
    let (mut l, mut s) = board();
    send(&mut l, &mut s, &Message::MotorEnable(true));
    send(&mut l, &mut s, &pwm([300; 4], 100));
    crate::serial::tick(&mut s, &Default::default());
    send(&mut l, &mut s, &Message::MotorEnable(false));
    send(&mut l, &mut s, &pwm([300; 4], 100));
    let last_frame_tick = s.ticks();
    let mut braked_at = None;
    for _ in 0..300 {
        let out = crate::serial::tick(&mut s, &Default::default());
        if out.mode == Mode::Brake && braked_at.is_none() {
            braked_at = Some(s.ticks());
        }
    }
    // The frame's 100 ms, not the profile's 249-tick maximum.
    let after = braked_at.expect("BRAKE after the timeout") - last_frame_tick;
    assert!(after < 100, "BRAKE {after} ticks after the last frame");
}

#[test]
fn send_imu_queues_one_imu_frame() {
    let (mut l, _) = board();
    let imu = Imu {
        t_ms: 5,
        accel_mg: [1, -2, 1000],
        gyro_mdps: [3, 0, -4],
        temp_cdeg: 2500,
    };
    l.send_imu(&imu);
    assert_eq!(replies(&mut l), [Message::Imu(imu)]);
}
