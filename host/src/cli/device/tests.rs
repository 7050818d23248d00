//! The verbs' argument checks, and their frame order and verdicts against a scripted stream.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use super::*;
use crate::transport::ScriptedStream;

fn frame(m: &cdc::Message) -> Vec<u8> {
    let mut out = [0u8; cdc::MAX_FRAME_LEN];
    let n = m.encode(&mut out);
    out[..n].to_vec()
}

fn robust<const N: usize>(m: &teensy::CmdMsg<N>) -> Vec<u8> {
    let mut out = [0u8; teensy::ROBUST_BUF];
    let n = m.encode_robust(&mut out).unwrap();
    out[..n].to_vec()
}

fn ack(id: cdc::MsgId, result: u8) -> Vec<u8> {
    frame(&cdc::Message::Ack(cdc::Ack {
        msg_id: id as u8,
        result,
    }))
}

/// Runs `run` with a sink that keeps the lines.
fn collect(
    run: impl FnOnce(&mut dyn FnMut(Value)) -> Result<Verdict, String>,
) -> (Verdict, Vec<Value>) {
    let mut lines = Vec::new();
    let v = run(&mut |l| lines.push(l)).unwrap();
    (v, lines)
}

const WAIT: Duration = Duration::from_millis(300);

#[test]
fn exit_codes() {
    assert_eq!(Verdict::Done.exit_code(), 0);
    assert_eq!(Verdict::Refused.exit_code(), 1);
    assert_eq!(Verdict::NoReply.exit_code(), 69);
    assert_eq!(Verdict::NoReply.as_str(), "no_reply");
}

#[test]
fn drive_arguments_are_checked_before_anything_is_sent() {
    let ok = DrivePlan::new(&[1000, -1000, 0, 1], 200, 50.0, 1.0, false).unwrap();
    assert_eq!(ok.frame.pwm, [1000, -1000, 0, 1]);
    assert_eq!(ok.frame.timeout_ms, 200);
    assert_eq!(ok.frames, 50, "1 s at 50 Hz, the first at once");
    assert_eq!(ok.period, Duration::from_millis(20));
    assert_eq!(
        DrivePlan::new(&[0; 4], 20, 50.0, 0.01, false)
            .unwrap()
            .frames,
        1
    );
    for (pwm, timeout, hz, seconds, what) in [
        (&[1001, 0, 0, 0][..], 200, 50.0, 1.0, "outside"),
        (&[0, 0, 0, -1001], 200, 50.0, 1.0, "motor 4"),
        (&[0, 0, 0], 200, 50.0, 1.0, "4 duties"),
        (&[0; 5], 200, 50.0, 1.0, "4 duties"),
        (&[0; 4], 0, 50.0, 1.0, "--timeout-ms 0"),
        (&[0; 4], 19, 50.0, 1.0, "shorter than the frame period"),
        (&[0; 4], 65_536, 50.0, 1.0, "65535"),
        (&[0; 4], 200, 0.0, 1.0, "--hz"),
        (&[0; 4], 200, f64::NAN, 1.0, "--hz"),
        (&[0; 4], 200, 1001.0, 1.0, "--hz"),
        (&[0; 4], 200, 50.0, 0.0, "--seconds"),
        (&[0; 4], 200, 50.0, f64::INFINITY, "--seconds"),
    ] {
        let e = DrivePlan::new(pwm, timeout, hz, seconds, false).unwrap_err();
        assert!(e.contains(what), "{pwm:?} {timeout} {hz} {seconds}: {e}");
    }
}

#[test]
fn move_arguments_are_checked() {
    let p = MovePlan::new(&[1, 2, 3, 4], 4, 90, false, 50.0, 0.5, false, true).unwrap();
    assert_eq!(p.frames, 25);
    assert!(p.cal);
    assert_eq!(
        MovePlan::new(&[0; 4], 4, 90, false, 50.0, 9.0, true, false)
            .unwrap()
            .frames,
        1
    );
    assert_eq!(
        MovePlan::new(&[0; 4], 4, 90, false, 50.0, 9.0, true, true)
            .unwrap()
            .frames,
        2,
        "--once --cal: one MTRS before the CAL, one after"
    );
    let e = MovePlan::new(&[0; 3], 4, 90, false, 50.0, 1.0, false, false).unwrap_err();
    assert!(
        e.contains("3 values") && e.contains("--angles 0,0,0,0"),
        "{e}"
    );
    let e = MovePlan::new(&[0; 4], 4, -1, false, 50.0, 1.0, false, false).unwrap_err();
    assert!(e.contains("--speed"), "{e}");
}

#[test]
fn lists_parse_with_negative_numbers_and_name_the_bad_item() {
    assert_eq!(
        parse_list("300,-300, 0,0", "--pwm").unwrap(),
        [300, -300, 0, 0]
    );
    let e = parse_list("1,x,3", "--pwm").unwrap_err();
    assert!(e.contains("'x'") && e.contains("--pwm"), "{e}");
}

#[test]
fn drive_enable_sends_a_frame_first_then_the_enable_then_keeps_the_frames_coming() {
    // The ACK comes back after the second write (the enable).
    let stream = ScriptedStream::new(vec![vec![], ack(cdc::MsgId::MotorEnable, 0)], 3);
    let plan = DrivePlan::new(&[100, 0, 0, -100], 50, 100.0, 0.03, true).unwrap();
    let mut written = Vec::new();
    let (v, lines) = collect(|sink| {
        let mut s = Session::new(CdcLink::new(stream), sink);
        let v = cdc_drive(&mut s, &plan, WAIT);
        written = s.link.stream.written.clone();
        v
    });
    assert_eq!(v, Verdict::Done);
    let pwm = frame(&cdc::Message::SetMotorPwm(plan.frame));
    let enable = frame(&cdc::Message::MotorEnable(true));
    // 0.03 s at 100 Hz plans 3 frames: the first, the enable after it, then the others. A loaded
    // machine may skip a deadline (counted), never send more or change the order.
    let end = lines.last().unwrap();
    let sent = end["frames_sent"].as_u64().unwrap();
    let skipped = end["pacing"]["skipped"].as_u64().unwrap();
    assert!(
        (1..=3).contains(&sent),
        "between 1 and the 3 planned frames: {sent}"
    );
    assert!(
        sent + skipped >= 3,
        "every planned frame sent or its deadline counted skipped"
    );
    let mut want = [&pwm[..], &enable].concat();
    for _ in 1..sent {
        want.extend_from_slice(&pwm);
    }
    assert_eq!(
        written, want,
        "the first frame, the enable, then the frames"
    );
    assert_eq!(end["enable"]["reply"]["result"], 0);
    assert_eq!(lines[0]["sending"]["type"], "set_motor_pwm");
}

#[test]
fn a_refused_enable_stops_the_drive_at_once() {
    let stream = ScriptedStream::new(vec![vec![], ack(cdc::MsgId::MotorEnable, 1)], 64);
    let plan = DrivePlan::new(&[100; 4], 200, 50.0, 1.0, true).unwrap();
    let (v, lines) = collect(|sink| run_cdc(stream, &CdcVerb::Drive(plan), WAIT, sink));
    assert_eq!(v, Verdict::Refused);
    let end = lines.last().unwrap();
    assert_eq!(end["frames_sent"], 1, "only the frame before the enable");
    assert_eq!(end["stopped_early"], true);
    assert_eq!(end["verdict"], "refused");
}

#[test]
fn a_drive_without_any_reply_is_no_reply() {
    let plan = DrivePlan::new(&[100; 4], 200, 50.0, 0.2, false).unwrap();
    let (v, lines) =
        collect(|sink| run_cdc(ScriptedStream::default(), &CdcVerb::Drive(plan), WAIT, sink));
    assert_eq!(v, Verdict::NoReply);
    // 0.2 s at 50 Hz plans 10 frames; a loaded machine may skip a deadline (counted), never send more.
    let end = lines.last().unwrap();
    let sent = end["frames_sent"].as_u64().unwrap();
    let skipped = end["pacing"]["skipped"].as_u64().unwrap();
    assert!(sent <= 10, "at most the planned frames: {sent}");
    assert!(
        sent + skipped >= 10,
        "every planned frame sent or its deadline counted skipped"
    );
}

#[test]
fn enable_and_estop_verdicts_follow_the_ack() {
    for (verb, reply, want) in [
        (
            CdcVerb::Enable(true),
            ack(cdc::MsgId::MotorEnable, 0),
            Verdict::Done,
        ),
        (
            CdcVerb::Enable(true),
            ack(cdc::MsgId::MotorEnable, 1),
            Verdict::Refused,
        ),
        (
            CdcVerb::Estop(Estop::Engage),
            ack(cdc::MsgId::Estop, 0),
            Verdict::Done,
        ),
        // An ACK of another message is no answer.
        (
            CdcVerb::Estop(Estop::Release),
            ack(cdc::MsgId::MotorEnable, 0),
            Verdict::NoReply,
        ),
    ] {
        let stream = ScriptedStream::new(vec![reply], 5);
        let (v, lines) = collect(|sink| run_cdc(stream, &verb, Duration::from_millis(50), sink));
        assert_eq!(v, want, "{verb:?}");
        assert_eq!(lines.last().unwrap()["verdict"], want.as_str());
    }
}

#[test]
fn send_hex_writes_the_bytes_as_given_and_prints_what_comes_back() {
    let garbage = vec![0xAA, 0x55, 0x7F, 0x02, 0x03, 0x00, 0x00, 0x00];
    let status = frame(&cdc::Message::Status(cdc::Status::default()));
    let stream = ScriptedStream::new(vec![status], 4);
    let h = SendHex {
        bytes: garbage,
        listen: Duration::from_millis(30),
    };
    let (v, lines) = collect(|sink| run_cdc(stream, &CdcVerb::SendHex(h), WAIT, sink));
    assert_eq!(v, Verdict::Done);
    assert_eq!(lines[0]["sent_hex"], "aa557f0203000000");
    assert_eq!(lines[1]["message"]["type"], "status");
    assert_eq!(lines.last().unwrap()["received"]["status"], 1);
}

#[test]
fn move_with_cal_sends_mtrs_then_cal_and_counts_every_echo() {
    let mtrs = teensy::CmdMsg::<2> {
        cmd_type: teensy::CmdType::Mtrs,
        mtr_angles: [10, -10],
        mtr_speed_deg_s: 90,
        ..teensy::CmdMsg::default()
    };
    let cal = cmd::<2>(teensy::CmdType::Cal);
    let echo = |m: &teensy::CmdMsg<2>, ok| robust(&m.reply(ok));
    let stream = ScriptedStream::new(
        vec![
            echo(&mtrs, true),
            echo(&cal, true),
            echo(&mtrs, true),
            echo(&mtrs, true),
        ],
        7,
    );
    let plan = MovePlan::new(&[10, -10], 2, 90, false, 100.0, 0.03, false, true).unwrap();
    let (v, lines) = collect(|sink| run_teensy(stream, 2, &TeensyVerb::Move(plan), WAIT, sink));
    let end = lines.last().unwrap();
    assert_eq!(v, Verdict::Done, "{end}");
    assert_eq!(end["mtrs_sent"], 3);
    assert_eq!(end["echoes_ok"], 3);
    assert_eq!(end["cal"]["reply"]["cmd_success"], 1);

    // A refused MTRS stops the sending.
    let rel = teensy::CmdMsg {
        is_relative: 1,
        ..mtrs
    };
    let stream = ScriptedStream::new(vec![echo(&rel, false)], 7);
    let plan = MovePlan::new(&[10, -10], 2, 90, true, 50.0, 1.0, false, false).unwrap();
    let (v, lines) = collect(|sink| run_teensy(stream, 2, &TeensyVerb::Move(plan), WAIT, sink));
    assert_eq!(v, Verdict::Refused);
    assert_eq!(lines.last().unwrap()["mtrs_sent"], 1);
}

#[test]
fn teensy_commands_take_their_echo_and_a_motor_count_outside_the_range_is_an_error() {
    let on = cmd::<4>(teensy::CmdType::EndeffOn);
    let stream = ScriptedStream::new(vec![robust(&on.reply(true))], 9);
    let (v, lines) = collect(|sink| run_teensy(stream, 4, &TeensyVerb::Endeff(true), WAIT, sink));
    assert_eq!(v, Verdict::Done);
    assert_eq!(lines.last().unwrap()["reply"]["cmd_type"], "endeff_on");

    let cfg = teensy::CmdMsg::<4> {
        mtr_accel_deg_s_s: 9999,
        ..cmd(teensy::CmdType::Config)
    };
    let stream = ScriptedStream::new(vec![robust(&cfg.reply(false))], 9);
    let verb = TeensyVerb::Config { accel_deg_s2: 9999 };
    let (v, _) = collect(|sink| run_teensy(stream, 4, &verb, WAIT, sink));
    assert_eq!(v, Verdict::Refused);

    let e = run_teensy(
        ScriptedStream::default(),
        17,
        &TeensyVerb::Cal,
        WAIT,
        &mut |_| {},
    )
    .unwrap_err();
    assert!(e.contains("--motors 17"), "{e}");
}

fn status(t_ms: u32) -> Vec<u8> {
    frame(&cdc::Message::Status(cdc::Status {
        t_ms,
        ..cdc::Status::default()
    }))
}

#[test]
fn ping_does_not_take_a_status_that_was_already_waiting_for_the_reply() {
    // A STATUS sits in the input before the first PING (a periodic one, or a late reply); the
    // board does not answer the first PING and answers the second.
    let mut stream = ScriptedStream::new(vec![Vec::new(), status(200)], 3);
    stream.pending.extend(status(100));
    let (v, lines) = collect(|sink| {
        run_cdc(
            stream,
            &CdcVerb::Ping { count: 2 },
            Duration::from_millis(30),
            sink,
        )
    });
    assert_eq!(v, Verdict::Done);
    let pings: Vec<&Value> = lines.iter().filter(|l| l.get("ping").is_some()).collect();
    assert_eq!(pings.len(), 2, "{lines:?}");
    assert!(pings[0].get("no_reply_ms").is_some(), "{:?}", pings[0]);
    assert_eq!(pings[1]["reply"]["t_ms"], 200, "{:?}", pings[1]);
    let last = lines.last().unwrap();
    assert_eq!(last["replies"], 1);
}

#[test]
fn ping_with_only_stale_input_is_no_reply() {
    let mut stream = ScriptedStream::new(vec![Vec::new()], 64);
    stream.pending.extend(status(100));
    let (v, lines) = collect(|sink| {
        run_cdc(
            stream,
            &CdcVerb::Ping { count: 1 },
            Duration::from_millis(30),
            sink,
        )
    });
    assert_eq!(v, Verdict::NoReply, "{lines:?}");
}

#[test]
fn ping_matches_its_reply_and_reports_min_avg_max() {
    // Each PING is answered by an ACK of another message and an IMU (no reply to a PING), then the
    // reply: a STATUS, or an ACK of the PING itself.
    let other = ack(cdc::MsgId::MotorEnable, 0);
    let imu = frame(&cdc::Message::Imu(cdc::Imu::default()));
    let replies = vec![
        [other.clone(), imu.clone(), status(1)].concat(),
        [imu.clone(), ack(cdc::MsgId::Ping, 0)].concat(),
        [other, imu, status(3)].concat(),
    ];
    let stream = ScriptedStream::new(replies, 7);
    let (v, lines) = collect(|sink| {
        run_cdc(
            stream,
            &CdcVerb::Ping { count: 3 },
            Duration::from_millis(50),
            sink,
        )
    });
    assert_eq!(v, Verdict::Done);
    let replies: Vec<&Value> = lines.iter().filter_map(|l| l.get("reply")).collect();
    assert_eq!(replies.len(), 3, "{lines:?}");
    assert_eq!(replies[0]["type"], "status");
    assert_eq!(replies[1]["type"], "ack");
    assert_eq!(replies[1]["msg_id"], cdc::MsgId::Ping as u8);
    assert_eq!(replies[2]["t_ms"], 3);
    let last = lines.last().unwrap();
    assert_eq!(last["replies"], 3);
    let rtt = &last["round_trip_us"];
    let (min, avg, max) = (
        rtt["min"].as_f64().unwrap(),
        rtt["avg"].as_f64().unwrap(),
        rtt["max"].as_f64().unwrap(),
    );
    assert!(min <= avg && avg <= max, "{rtt}");
}
