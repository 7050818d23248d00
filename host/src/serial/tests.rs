//! The serial links against a scripted in-memory stream; frames written are compared with the
//! Python-built golden frames of protocol/golden/structs_python.txt.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use super::*;
use crate::cli::parse_hex;
use crate::transport::ScriptedStream;
use statemachine::{AxisCommand, Command, Source};

const T: Duration = Duration::from_millis(50);

// Golden frames (Python `struct`).
const PING: &str = "aa5510007c1e";
const ENABLE_1: &str = "aa55020101ec81";
const ENABLE_0: &str = "aa55020100cd91";
const ESTOP_1: &str = "aa55030101dcb6";
const ACK_ESTOP: &str = "aa557f0203006829";
const STATUS: &str = "aa55820affffffff38310b00040022ac";
const IMU: &str = "aa55811440e20100000018fce8030500fbffff7fd00900006e18";

fn h(s: &str) -> Vec<u8> {
    parse_hex(s).unwrap()
}

fn ack(id: u8, result: u8) -> Vec<u8> {
    let mut out = [0u8; cdc::MAX_FRAME_LEN];
    let n = cdc::Message::Ack(cdc::Ack { msg_id: id, result }).encode(&mut out);
    out[..n].to_vec()
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

#[test]
fn ping_is_answered_by_an_ack_through_garbage_and_split_reads() {
    let reply = cat(&[&[0x13, 0xAA, 0x00], &h(IMU), &ack(0x10, 0)]);
    let mut link = CdcLink::new(ScriptedStream::new(vec![reply], 3));
    let r = link.ping(T).unwrap();
    assert_eq!(link.stream.written, h(PING));
    assert_eq!(
        r.reply,
        cdc::Message::Ack(cdc::Ack {
            msg_id: 0x10,
            result: 0
        })
    );
    assert_eq!(r.other.len(), 1);
    assert!(matches!(r.other[0], cdc::Message::Imu(i) if i.t_ms == 123_456 && i.temp_cdeg == 2512));
    assert_eq!(link.stats().frames, 2);
    assert_eq!(link.stats().dropped_bytes, 3);
}

#[test]
fn ping_is_answered_by_a_status() {
    let mut link = CdcLink::new(ScriptedStream::new(vec![h(STATUS)], 64));
    let r = link.ping(T).unwrap();
    match r.reply {
        cdc::Message::Status(s) => {
            assert_eq!(
                (s.t_ms, s.vbat_mv, s.flags.0, s.err),
                (u32::MAX, 12600, 0b1011, 4)
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_ack_of_another_message_does_not_answer_a_ping() {
    let mut link = CdcLink::new(ScriptedStream::new(vec![h(ACK_ESTOP)], 64));
    let e = link.ping(Duration::from_millis(5)).unwrap_err();
    assert!(
        matches!(e, LinkError::NoReply(_, ref w) if w == "ACK or STATUS"),
        "{e}"
    );
    assert!(e
        .to_string()
        .contains("no ACK or STATUS before the timeout"));
}

#[test]
fn a_silent_device_times_out() {
    let mut link = CdcLink::new(ScriptedStream::new(vec![], 64));
    let t0 = Instant::now();
    assert!(matches!(
        link.ping(Duration::from_millis(5)),
        Err(LinkError::NoReply(..))
    ));
    assert!(t0.elapsed() >= Duration::from_millis(5));
}

#[test]
fn a_corrupted_reply_is_counted_and_the_next_good_one_taken() {
    let mut broken = ack(0x10, 0);
    broken[5] ^= 0x40; // result byte: CRC no longer matches
    let reply = cat(&[&broken, &ack(0x10, 0)]);
    let mut link = CdcLink::new(ScriptedStream::new(vec![reply], 5));
    let r = link.ping(T).unwrap();
    assert_eq!(
        r.reply,
        cdc::Message::Ack(cdc::Ack {
            msg_id: 0x10,
            result: 0
        })
    );
    assert_eq!(link.errors, vec![cdc::Error::Crc]);
    assert_eq!(link.stats().crc_errors, 1);
}

#[test]
fn enable_and_estop_send_the_seed_frames_and_map_to_ladder_events() {
    let mut link = CdcLink::new(ScriptedStream::new(
        vec![ack(0x02, 0), ack(0x02, 0), h(ACK_ESTOP)],
        4,
    ));
    let (r, ev) = link.enable(true, T).unwrap();
    assert_eq!(
        r.reply,
        cdc::Message::Ack(cdc::Ack {
            msg_id: 2,
            result: 0
        })
    );
    assert_eq!(ev, Some(Event::Rearm(Source::Primary)));
    let (_, ev) = link.enable(false, T).unwrap();
    assert_eq!(
        ev,
        Some(Event::Frame(Command::uniform(
            AxisCommand::COAST,
            false,
            None
        )))
    );
    let (r, ev) = link.estop(Estop::Engage, T).unwrap();
    assert_eq!(
        r.reply,
        cdc::Message::Ack(cdc::Ack {
            msg_id: 3,
            result: 0
        })
    );
    assert_eq!(
        ev,
        Some(Event::Estop {
            source: Source::Primary,
            action: Estop::Engage
        })
    );
    assert_eq!(
        link.stream.written,
        cat(&[&h(ENABLE_1), &h(ENABLE_0), &h(ESTOP_1)])
    );
}

#[test]
fn a_command_waits_for_its_own_ack() {
    // The device first acknowledges something else, then refuses the enable (result 1).
    let reply = cat(&[&h(ACK_ESTOP), &ack(0x02, 1)]);
    let mut link = CdcLink::new(ScriptedStream::new(vec![reply], 7));
    let (r, _) = link.enable(true, T).unwrap();
    assert_eq!(
        r.reply,
        cdc::Message::Ack(cdc::Ack {
            msg_id: 2,
            result: 1
        })
    );
    assert_eq!(
        r.other,
        vec![cdc::Message::Ack(cdc::Ack {
            msg_id: 3,
            result: 0
        })]
    );
}

// ---- seed 003 ----

const ROBUST: &str =
    "020201010102010101025a010107a6ffffff0a0a0106ffffff7f1e010106c4ffffff0101010183fff000";

fn golden_cmd() -> teensy::CmdMsg<4> {
    teensy::CmdMsg {
        cmd_type: teensy::CmdType::Mtrs,
        is_relative: 1,
        mtr_angles: [90, -90, 2570, i32::MAX],
        mtr_speed_deg_s: 30,
        mtr_accel_deg_s_s: -60,
        cmd_success: 1,
    }
}

#[test]
fn teensy_command_writes_the_golden_frame_and_takes_the_echo() {
    let cmd = golden_cmd().reply(false);
    let mut echo = [0u8; teensy::ROBUST_BUF];
    let n = cmd.reply(true).encode_robust(&mut echo).unwrap();
    // a broken frame and a stray zero first
    let reply = cat(&[&[0x05, 0x01, 0x02, 0x00, 0x00], &echo[..n]]);
    let mut link = TeensyLink::<_, 4>::new(ScriptedStream::new(vec![reply], 6));
    let r = link.command(&cmd, T).unwrap();
    assert_eq!(r.reply.cmd_success, 1);
    assert_eq!(r.reply.mtr_angles, [90, -90, 2570, i32::MAX]);
    assert_eq!(link.errors, vec![statemachine::RejectReason::Framing]);
    assert_eq!(link.stats().frames, 1);
    // The bytes a send puts on the wire are the Python-built frame (which has cmd_success = 1).
    let mut sent_golden = TeensyLink::<_, 4>::new(ScriptedStream::new(vec![], 1));
    sent_golden.send(&golden_cmd()).unwrap();
    assert_eq!(sent_golden.stream.written, h(ROBUST));
}

#[test]
fn teensy_without_echo_times_out() {
    let mut link = TeensyLink::<_, 4>::new(ScriptedStream::new(vec![h(ROBUST)], 64));
    // The reply is for another command (different angles), so it is not the echo.
    let mut other = golden_cmd();
    other.mtr_angles[0] = 1;
    let e = link.command(&other, Duration::from_millis(5)).unwrap_err();
    assert!(e.to_string().contains("echo of the command"), "{e}");
}
