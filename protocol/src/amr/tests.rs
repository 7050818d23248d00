//! Unit tests of the seed 000 frame: hand-derived encodings, protobuf rules, framing errors.

use super::*;

/// Builds a frame around `payload` with a correct CRC, the way an independent sender would.
fn frame_with(payload: &[u8]) -> [u8; FRAME_LEN] {
    let mut f = [0u8; FRAME_LEN];
    f[0] = payload.len() as u8;
    f[1..1 + payload.len()].copy_from_slice(payload);
    let crc = crc16::checksum(&f[..62]);
    f[62..].copy_from_slice(&crc.to_be_bytes());
    f
}

/// The version field (8, varint 1) that every valid command carries.
const V1: [u8; 2] = [0x40, 0x01];

#[test]
fn command_bytes_derived_by_hand_from_the_protobuf_spec() {
    let cmd = MotorCommand {
        timestamp_us: 0x0102_0304,
        left_speed_cmd: 1.0,   // 0x3F800000
        right_speed_cmd: -2.5, // 0xC0200000
        control_mode: 1,
        enable: true,
        seq: 7,
        request: 0,
    };
    let mut f = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut f);
    let want: [u8; 28] = [
        0x0D, 0x04, 0x03, 0x02, 0x01, // field 1, I32
        0x15, 0x00, 0x00, 0x80, 0x3F, // field 2, I32
        0x1D, 0x00, 0x00, 0x20, 0xC0, // field 3, I32
        0x20, 0x01, // field 4, varint 1
        0x28, 0x01, // field 5, varint 1
        0x3D, 0x07, 0x00, 0x00, 0x00, // field 7, I32
        0x40, 0x01, // field 8, varint 1
        0x00, 0x00, // padding starts
    ];
    assert_eq!(f[0], 26);
    assert_eq!(f[1..29], want);
    assert!(f[27..62].iter().all(|&b| b == 0));
    assert_eq!(f, frame_with(&want[..26]));
    assert_eq!(decode_command(&f), Ok(cmd));
}

#[test]
fn an_identity_request_is_field_9_after_the_version() {
    let cmd = MotorCommand {
        request: REQUEST_IDENTITY,
        ..Default::default()
    };
    let mut f = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut f);
    // field 8 varint 1, then field 9 (key 9 << 3 = 0x48) varint 1.
    assert_eq!(f, frame_with(&[0x40, 0x01, 0x48, 0x01]));
    assert_eq!(decode_command(&f), Ok(cmd));
    // The ladder's command does not carry it.
    assert_eq!(cmd.to_command(), MotorCommand::default().to_command());
    // A request this version does not define is still a valid command (the MCU ignores it).
    let cmd = MotorCommand {
        request: 0x1234_5678,
        enable: true,
        ..Default::default()
    };
    encode_command(&cmd, &mut f);
    assert_eq!(decode_command(&f), Ok(cmd));
}

#[test]
fn zero_fields_are_omitted_and_an_empty_command_is_just_the_version() {
    let mut f = [0u8; FRAME_LEN];
    encode_command(&MotorCommand::default(), &mut f);
    assert_eq!(f, frame_with(&V1));
}

#[test]
fn negative_encoder_counts_use_zigzag() {
    let fb = MotorFeedback {
        left_encoder: -1,
        right_encoder: 1,
        ..Default::default()
    };
    let mut f = [0u8; FRAME_LEN];
    encode_feedback(&fb, &mut f);
    assert_eq!(f, frame_with(&[0x30, 0x01, 0x38, 0x02, 0x68, 0x01]));
    assert_eq!(decode_feedback(&f), Ok(fb));
}

#[test]
fn stuck_bus_frames_fail_the_crc() {
    assert_eq!(decode_command(&[0x00; FRAME_LEN]), Err(RejectReason::Crc));
    assert_eq!(decode_command(&[0xFF; FRAME_LEN]), Err(RejectReason::Crc));
    assert_eq!(decode_feedback(&[0x00; FRAME_LEN]), Err(RejectReason::Crc));
    assert_eq!(decode_feedback(&[0xFF; FRAME_LEN]), Err(RejectReason::Crc));
}

#[test]
fn framing_errors() {
    // Length beyond the payload area, CRC valid.
    let mut f = frame_with(&V1);
    f[0] = 62;
    let crc = crc16::checksum(&f[..62]);
    f[62..].copy_from_slice(&crc.to_be_bytes());
    assert_eq!(decode_command(&f), Err(RejectReason::Framing));
    // Non-zero padding, CRC valid.
    let mut f = frame_with(&V1);
    f[40] = 1;
    let crc = crc16::checksum(&f[..62]);
    f[62..].copy_from_slice(&crc.to_be_bytes());
    assert_eq!(decode_command(&f), Err(RejectReason::Framing));
    // Two equal non-zero padding bytes, whose XOR would be zero: the padding after the 2-byte
    // payload is bytes 3..62, fourteen 4-byte words and a 3-byte tail. One pair in the same lane
    // of two words, one pair in the tail.
    for (a, b) in [(3, 7), (60, 61)] {
        let mut f = frame_with(&V1);
        f[a] = 0x5A;
        f[b] = 0x5A;
        let crc = crc16::checksum(&f[..62]);
        f[62..].copy_from_slice(&crc.to_be_bytes());
        assert_eq!(
            decode_command(&f),
            Err(RejectReason::Framing),
            "padding bytes {a} and {b}"
        );
    }
}

#[test]
fn version_missing_or_wrong() {
    // A seed-era sender: no version field.
    assert_eq!(
        decode_command(&frame_with(&[0x20, 0x01])),
        Err(RejectReason::Version)
    );
    assert_eq!(decode_command(&frame_with(&[])), Err(RejectReason::Version));
    assert_eq!(
        decode_command(&frame_with(&[0x40, 0x02])),
        Err(RejectReason::Version)
    );
    assert_eq!(
        decode_feedback(&frame_with(&[0x68, 0x02])),
        Err(RejectReason::Version)
    );
    // Version 300 is a version error, not a decode error (the field is a full uint32).
    assert_eq!(
        decode_command(&frame_with(&[0x40, 0xAC, 0x02])),
        Err(RejectReason::Version)
    );
}

#[test]
fn unknown_fields_of_every_wire_type_are_skipped() {
    let payload = [
        0x30, 0x05, // field 6 (reserved, was crc16), varint
        0x79, 1, 2, 3, 4, 5, 6, 7, 8, // field 15, I64
        0x52, 0x03, 0xAA, 0xBB, 0xCC, // field 10, LEN 3
        0x5D, 1, 2, 3, 4, // field 11, I32
        0xF8, 0xFF, 0xFF, 0xFF, 0x0F, 0x00, // field 2^29-1, varint
        0x20, 0x01, 0x40, 0x01,
    ];
    let cmd = decode_command(&frame_with(&payload)).unwrap();
    assert_eq!(cmd.control_mode, 1);
}

#[test]
fn duplicate_fields_last_one_wins() {
    let payload = [
        0x20, 0x00, 0x3D, 1, 0, 0, 0, 0x20, 0x01, 0x3D, 9, 0, 0, 0, 0x40, 0x01,
    ];
    let cmd = decode_command(&frame_with(&payload)).unwrap();
    assert_eq!(cmd.control_mode, 1);
    assert_eq!(cmd.seq, 9);
}

#[test]
fn wrong_wire_type_or_range_is_a_decode_error() {
    for bad in [
        &[0x08, 0x01, 0x40, 0x01][..],   // timestamp as varint (it is fixed32)
        &[0x25, 0, 0, 0, 0, 0x40, 0x01], // control_mode as I32
        &[0x45, 1, 0, 0, 0],             // version as I32
        &[0x28, 0x02, 0x40, 0x01],       // enable = 2
        &[0x20, 0x80, 0x02, 0x40, 0x01], // control_mode = 256 (uint8 on the MCU)
        &[0x40],                         // truncated
        &[0x40, 0x80],                   // truncated varint
        &[0x00, 0x40, 0x01],             // field 0
        &[0x12, 0x05, 0x40, 0x01],       // LEN past the end
        &[0x0B, 0x0C, 0x40, 0x01],       // group
        &[0x40, 0x01, 0x4D, 1, 0, 0, 0], // request as I32
    ] {
        assert_eq!(
            decode_command(&frame_with(bad)),
            Err(RejectReason::Decode),
            "{bad:02x?}"
        );
    }
    // Feedback: fault_flags above 16 bits, mode above 8 bits.
    assert_eq!(
        decode_feedback(&frame_with(&[0x40, 0x80, 0x80, 0x04, 0x68, 0x01])),
        Err(RejectReason::Decode)
    );
    assert_eq!(
        decode_feedback(&frame_with(&[0x58, 0x80, 0x02, 0x68, 0x01])),
        Err(RejectReason::Decode)
    );
}

#[test]
fn size_bounds() {
    assert_eq!(MAX_COMMAND_LEN, 36);
    assert_eq!(MAX_FEEDBACK_LEN, 61);
    assert_eq!(MAX_INFO_LEN, 52);
    assert_eq!(NANOPB_COMMAND_SIZE, 38);
    assert_eq!(NANOPB_FEEDBACK_SIZE, 60);
    assert_eq!(NANOPB_INFO_SIZE, 58);
    // The longest messages really are that long.
    let cmd = MotorCommand {
        timestamp_us: u32::MAX,
        left_speed_cmd: f32::MIN,
        right_speed_cmd: f32::MAX,
        control_mode: u32::MAX,
        enable: true,
        seq: u32::MAX,
        request: u32::MAX,
    };
    let mut f = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut f);
    assert_eq!(usize::from(f[0]), MAX_COMMAND_LEN);
    let fb = MotorFeedback {
        timestamp_us: 1,
        left_speed: 1.0,
        right_speed: 1.0,
        left_current: 1.0,
        right_current: 1.0,
        left_encoder: i32::MIN,
        right_encoder: i32::MIN,
        fault_flags: u32::MAX,
        seq: 1,
        mode: u32::MAX,
        cmd_seq: 1,
    };
    encode_feedback(&fb, &mut f);
    assert_eq!(usize::from(f[0]), MAX_FEEDBACK_LEN);
    // Out-of-range narrow fields are written but refused, as nanopb refuses them.
    assert_eq!(decode_feedback(&f), Err(RejectReason::Decode));
    encode_info(&longest_info(), &mut f);
    assert_eq!(usize::from(f[0]), MAX_INFO_LEN);
    assert_eq!(decode_info(&f), Ok(longest_info()));
}

/// Every field of an info message at its longest encoding.
fn longest_info() -> McuInfo {
    McuInfo {
        fw_version: u32::MAX,
        git_hash: 1,
        board: BoardProfile::PiSpi,
        build_date: u32::MAX,
        reset_cause: ResetCause::LowPower,
        reset_count: u32::MAX,
        panic_line: u32::MAX,
        seq: 1,
        dirty: true,
    }
}

/// The info frame derived by hand from the protobuf encoding rules (two-byte keys for fields ≥ 16).
#[test]
fn info_bytes_derived_by_hand_from_the_protobuf_spec() {
    let info = McuInfo {
        fw_version: pack_fw_version(1, 2, 3), // 0x010203 = 66051
        git_hash: 0x1A2B_3C4D,
        board: BoardProfile::AmrSpi, // 0: omitted
        build_date: 20_261_130,
        reset_cause: ResetCause::IndependentWatchdog,
        reset_count: 2,
        panic_line: 0, // omitted
        seq: 0x0102_0304,
        dirty: true,
    };
    let want: [u8; 35] = [
        0x80, 0x01, 0x01, // field 16 varint (16 << 3 = 0x80 → 80 01), info_version 1
        0x88, 0x01, 0x83, 0x84, 0x04, // field 17 varint 66051
        0x95, 0x01, 0x4D, 0x3C, 0x2B, 0x1A, // field 18 I32 (0x95 01), little-endian
        0xA0, 0x01, 0x8A, 0xD2, 0xD4, 0x09, // field 20 varint 20261130
        0xA8, 0x01, 0x03, // field 21 varint 3
        0xB0, 0x01, 0x02, // field 22 varint 2
        0xC5, 0x01, 0x04, 0x03, 0x02, 0x01, // field 24 I32
        0xC8, 0x01, 0x01, // field 25 varint 1
    ];
    let mut f = [0u8; FRAME_LEN];
    encode_info(&info, &mut f);
    assert_eq!(f, frame_with(&want));
    assert_eq!(decode_info(&f), Ok(info));
    assert_eq!(info.fw_version_parts(), (1, 2, 3));
    assert_eq!(info.build_date_parts(), (2026, 11, 30));
}

#[test]
fn info_and_feedback_frames_are_never_taken_for_each_other() {
    let mut fi = [0u8; FRAME_LEN];
    encode_info(&longest_info(), &mut fi);
    assert_eq!(decode_feedback(&fi), Err(RejectReason::Version));
    assert_eq!(decode_command(&fi), Err(RejectReason::Version));
    assert_eq!(decode_mcu_frame(&fi), Ok(McuFrame::Info(longest_info())));
    // Even the smallest info frame (every field default: just info_version).
    encode_info(&McuInfo::default(), &mut fi);
    assert_eq!(fi, frame_with(&[0x80, 0x01, 0x01]));
    assert_eq!(decode_feedback(&fi), Err(RejectReason::Version));
    assert_eq!(
        decode_mcu_frame(&fi),
        Ok(McuFrame::Info(McuInfo::default()))
    );
    let fb = MotorFeedback {
        seq: 9,
        left_current: -3.5,
        ..Default::default()
    };
    let mut ff = [0u8; FRAME_LEN];
    encode_feedback(&fb, &mut ff);
    assert_eq!(decode_info(&ff), Err(RejectReason::Version));
    assert_eq!(decode_mcu_frame(&ff), Ok(McuFrame::Feedback(fb)));
    encode_feedback(&MotorFeedback::default(), &mut ff);
    assert_eq!(decode_info(&ff), Err(RejectReason::Version));
    // A command frame is neither.
    let mut fc = [0u8; FRAME_LEN];
    encode_command(&MotorCommand::default(), &mut fc);
    assert_eq!(decode_info(&fc), Err(RejectReason::Version));
    assert_eq!(decode_mcu_frame(&fc), Err(RejectReason::Version));
    // Frame-level errors come first, whichever the kind.
    fi[5] ^= 0x10;
    assert_eq!(decode_mcu_frame(&fi), Err(RejectReason::Crc));
    assert_eq!(decode_info(&fi), Err(RejectReason::Crc));
}

#[test]
fn undefined_info_values_are_refused_not_mapped() {
    let v1 = [0x80, 0x01, 0x01];
    for bad in [
        &[0x98, 0x01, 0x04][..],   // board 4 (0..=3 defined)
        &[0xA8, 0x01, 0x09],       // reset_cause 9 (0..=8 defined)
        &[0xA8, 0x01, 0xFF, 0x01], // reset_cause 255
        &[0xC8, 0x01, 0x02],       // dirty 2
        &[0x95, 0x01, 0x01],       // git_hash truncated
        &[0x8D, 0x01, 1, 2, 3, 4], // fw_version as I32
        &[0xC0, 0x01, 0x05],       // seq as varint (it is fixed32)
    ] {
        let mut payload = v1.to_vec();
        payload.extend_from_slice(bad);
        let f = frame_with(&payload);
        assert_eq!(decode_info(&f), Err(RejectReason::Decode), "{bad:02x?}");
        assert_eq!(
            decode_mcu_frame(&f),
            Err(RejectReason::Decode),
            "{bad:02x?}"
        );
    }
    // A wrong or missing info_version is a version error.
    assert_eq!(
        decode_info(&frame_with(&[0x80, 0x01, 0x02])),
        Err(RejectReason::Version)
    );
    assert_eq!(
        decode_info(&frame_with(&[0x98, 0x01, 0x01])),
        Err(RejectReason::Version)
    );
    // Every defined value decodes to its variant.
    for b in BoardProfile::ALL {
        let info = McuInfo {
            board: b,
            ..Default::default()
        };
        let mut f = [0u8; FRAME_LEN];
        encode_info(&info, &mut f);
        assert_eq!(decode_info(&f), Ok(info));
        assert_eq!(BoardProfile::from_wire(u32::from(b as u8)), Some(b));
    }
    for (i, c) in ResetCause::ALL.into_iter().enumerate() {
        assert_eq!(c as usize, i);
        assert_eq!(ResetCause::from_wire(i as u32), Some(c));
    }
    assert_eq!(ResetCause::from_wire(9), None);
    assert_eq!(BoardProfile::from_wire(4), None);
}

#[test]
fn version_and_git_hash_helpers() {
    assert_eq!(pack_fw_version(1, 2, 3), 0x0001_0203);
    assert_eq!(pack_fw_version(u16::MAX, 255, 255), u32::MAX);
    assert_eq!(git_hash_from_hex("1a2b3c4d5e6f"), 0x1A2B_3C4D);
    assert_eq!(git_hash_from_hex("DEADBEEF"), 0xDEAD_BEEF);
    assert_eq!(git_hash_from_hex("0000000"), 0); // too short: unknown
    assert_eq!(git_hash_from_hex("1a2b3c4g"), 0); // not hex: unknown
    assert_eq!(git_hash_from_hex(""), 0);
    const BUILT: u32 = git_hash_from_hex("8624b25f");
    assert_eq!(BUILT, 0x8624_B25F);
}

/// The field numbers in Rust agree with the shipped `.proto`.
#[test]
fn field_numbers_match_the_proto_file() {
    let proto = include_str!("../../proto/amr.proto");
    let number = |message: &str, name: &str| -> u32 {
        let body = proto
            .split(&format!("message {message} {{"))
            .nth(1)
            .unwrap();
        let body = body.split('}').next().unwrap();
        let line = body
            .lines()
            .find(|l| l.split_whitespace().nth(1) == Some(name))
            .unwrap_or_else(|| panic!("{message}.{name} not in amr.proto"));
        let n = line.split('=').nth(1).unwrap().split(';').next().unwrap();
        n.trim().parse().unwrap()
    };
    use command_field as c;
    for (name, n) in [
        ("timestamp_us", c::TIMESTAMP_US),
        ("left_speed_cmd", c::LEFT_SPEED_CMD),
        ("right_speed_cmd", c::RIGHT_SPEED_CMD),
        ("control_mode", c::CONTROL_MODE),
        ("enable", c::ENABLE),
        ("seq", c::SEQ),
        ("protocol_version", c::PROTOCOL_VERSION),
        ("request", c::REQUEST),
    ] {
        assert_eq!(number("MotorCommand", name), n, "{name}");
    }
    use info_field as i;
    for (name, n) in [
        ("info_version", i::INFO_VERSION),
        ("fw_version", i::FW_VERSION),
        ("git_hash", i::GIT_HASH),
        ("board", i::BOARD),
        ("build_date", i::BUILD_DATE),
        ("reset_cause", i::RESET_CAUSE),
        ("reset_count", i::RESET_COUNT),
        ("panic_line", i::PANIC_LINE),
        ("seq", i::SEQ),
        ("dirty", i::DIRTY),
    ] {
        assert_eq!(number("McuInfo", name), n, "{name}");
    }
    use feedback_field as b;
    for (name, n) in [
        ("timestamp_us", b::TIMESTAMP_US),
        ("left_speed", b::LEFT_SPEED),
        ("right_speed", b::RIGHT_SPEED),
        ("left_current", b::LEFT_CURRENT),
        ("right_current", b::RIGHT_CURRENT),
        ("left_encoder", b::LEFT_ENCODER),
        ("right_encoder", b::RIGHT_ENCODER),
        ("fault_flags", b::FAULT_FLAGS),
        ("seq", b::SEQ),
        ("mode", b::MODE),
        ("cmd_seq", b::CMD_SEQ),
        ("protocol_version", b::PROTOCOL_VERSION),
    ] {
        assert_eq!(number("MotorFeedback", name), n, "{name}");
    }
}

#[test]
fn a_repeated_frame_is_stale_for_the_ladder() {
    use statemachine::{Config, Event, Ladder};
    let mut ladder = Ladder::new(Config::DEFAULT);
    let mut f = [0u8; FRAME_LEN];
    let mut cmd = MotorCommand {
        control_mode: 1,
        seq: 1,
        ..Default::default()
    };
    encode_command(&cmd, &mut f);
    ladder.step(command_event(&f));
    let before = ladder.counters().rejected(RejectReason::Stale);
    ladder.step(command_event(&f)); // the same frame again
    assert_eq!(ladder.counters().rejected(RejectReason::Stale), before + 1);
    cmd.seq = 2;
    encode_command(&cmd, &mut f);
    ladder.step(command_event(&f));
    assert_eq!(ladder.counters().rejected(RejectReason::Stale), before + 1);
    f[10] ^= 1;
    assert_eq!(command_event(&f), Event::Rejected(RejectReason::Crc));
}

#[test]
fn padding_check_covers_exactly_the_bytes_between_payload_and_crc() {
    // For every payload length and every frame byte: a non-zero byte is refused as padding exactly
    // when it lies after the payload and before the CRC (checked against a byte-by-byte rule).
    for len in 0..=MAX_PAYLOAD {
        let end = PAYLOAD_OFFSET + len;
        for j in 0..FRAME_LEN {
            let mut f = [0u8; FRAME_LEN];
            f[j] = 0x40;
            let expect_zero = !(end..CRC_OFFSET).contains(&j);
            assert_eq!(padding_is_zero(&f, end), expect_zero, "len {len} byte {j}");
        }
        assert!(padding_is_zero(&[0u8; FRAME_LEN], end));
    }
    // Beyond the last payload length nothing is padding.
    let mut f = [0xFFu8; FRAME_LEN];
    f[0] = 0;
    assert!(padding_is_zero(&f, CRC_OFFSET));
    assert!(padding_is_zero(&f, usize::MAX));
}

#[test]
fn with_output_fills_mode_and_fault_flags_and_keeps_the_rest() {
    let out = statemachine::Output::<2> {
        mode: statemachine::Mode::Stop,
        drive: statemachine::Drive::Brake,
        limit: statemachine::Speed::ZERO,
        faults: statemachine::FaultFlags::COMM_LOST.union(statemachine::FaultFlags::ESTOP),
        age: 7,
    };
    let fb = MotorFeedback {
        seq: 41,
        left_encoder: -3,
        ..MotorFeedback::default()
    }
    .with_output(&out);
    // STOP is rung 3 on the wire; COMM_LOST is bit 4 and ESTOP bit 5: 0x30.
    assert_eq!(fb.mode, 3);
    assert_eq!(fb.fault_flags, 0x30);
    assert_eq!((fb.seq, fb.left_encoder), (41, -3));
}
