//! Unit tests of the seed 003 packets.

use super::*;

type Msg = CmdMsg<4>;

fn sample() -> Msg {
    CmdMsg {
        cmd_type: CmdType::Config,
        is_relative: 1,
        mtr_angles: [90, -90, 0x0A0A, 0],
        mtr_speed_deg_s: 30,
        mtr_accel_deg_s_s: 60,
        cmd_success: 0,
    }
}

#[test]
fn legacy_layout_is_the_c_union() {
    assert_eq!(Msg::LEN, 36);
    assert_eq!(Msg::LEGACY_LEN, 37);
    let mut b = [0u8; 37];
    assert_eq!(sample().encode_legacy(&mut b), Some(37));
    assert_eq!(b[..4], [4, 0, 0, 0]);
    assert_eq!(b[12..16], (-90i32).to_le_bytes());
    assert_eq!(b[16..20], [0x0A, 0x0A, 0, 0]); // a '\n' inside the data: why the legacy framing is fragile
    assert_eq!(b[36], b'\n');
    assert_eq!(Msg::decode_legacy(&b), Ok(sample()));
    assert_eq!(Msg::decode_legacy(&b[..36]), Err(RejectReason::Framing));
    let mut bad = b;
    bad[36] = 0;
    assert_eq!(Msg::decode_legacy(&bad), Err(RejectReason::Framing));
    bad = b;
    bad[0] = 5;
    assert_eq!(Msg::decode_legacy(&bad), Err(RejectReason::Decode));
    assert_eq!(sample().encode_legacy(&mut [0u8; 36]), None);
}

#[test]
fn robust_frame_round_trip_and_errors() {
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = sample().encode_robust(&mut f).unwrap();
    // Version 1 + CmdMsg 36 + CRC 2, then one COBS code byte and the terminator.
    assert_eq!(n, 41);
    assert_eq!(Msg::ROBUST_LEN, 41);
    assert_eq!(f[n - 1], 0);
    assert!(f[..n - 1].iter().all(|&b| b != 0));
    assert_eq!(Msg::decode_robust(&f[..n]), Ok(sample()));
    // Corrupt a byte: CRC (or COBS structure) catches it.
    let mut g = f;
    g[10] ^= 0x01;
    assert!(Msg::decode_robust(&g[..n]).is_err());
    assert_eq!(Msg::decode_robust(&f[..n - 1]), Err(RejectReason::Framing));
    // Another motor count: the length differs.
    assert_eq!(
        CmdMsg::<3>::decode_robust(&f[..n]),
        Err(RejectReason::Framing)
    );
}

#[test]
fn echo_carries_cmd_success() {
    let mut dec = RobustDecoder::<4>::new();
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = sample().reply(true).encode_robust(&mut f).unwrap();
    let mut got = None;
    for &b in [0u8, 0x13, 0x37, 0x00].iter().chain(&f[..n]) {
        if let Some(r) = dec.push(b) {
            got = Some(r);
        }
    }
    assert_eq!(got, Some(Ok(sample().reply(true))));
    assert_eq!(got.unwrap().unwrap().cmd_success, 1);
    assert_eq!(dec.stats().frames, 1);
    assert_eq!(dec.stats().errors, 1); // the garbage 13 37 before it
}

#[test]
fn decoder_survives_an_endless_frame() {
    let mut dec = RobustDecoder::<4>::new();
    for _ in 0..1000 {
        assert_eq!(dec.push(0x55), None);
    }
    assert_eq!(dec.push(0), Some(Err(RejectReason::Framing)));
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = sample().encode_robust(&mut f).unwrap();
    let results: std::vec::Vec<_> = f[..n].iter().filter_map(|&b| dec.push(b)).collect();
    assert_eq!(results, [Ok(sample())]);
}

#[test]
fn ladder_mapping() {
    let mut m = sample();
    assert_eq!(m.to_event(), None);
    m.cmd_type = CmdType::Mtrs;
    match m.to_event() {
        Some(Event::Frame(c)) => {
            // Degrees to rad, each motor to its angle under the message's 30 deg/s.
            let [a, b, ..] = c.axes;
            let cap = 30.0f32.to_radians();
            assert_eq!(
                a,
                statemachine::AxisCommand::position(core::f32::consts::FRAC_PI_2, cap)
            );
            assert_eq!(
                b,
                statemachine::AxisCommand::position(-core::f32::consts::FRAC_PI_2, cap)
            );
        }
        other => panic!("{other:?}"),
    }
}

fn robust(m: &Msg) -> std::vec::Vec<u8> {
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = m.encode_robust(&mut f).unwrap();
    f[..n].to_vec()
}

#[test]
fn a_frame_right_after_garbage_is_delivered_at_its_terminator() {
    // Non-zero garbage with no 0x00 before the frame: the frame is still the last 40 bytes before
    // its terminator.
    let f = robust(&sample());
    let mut dec = RobustDecoder::<4>::new();
    let stream = [&[0x13, 0x37, 0x0A][..], &f, &f].concat();
    let at: std::vec::Vec<_> = stream
        .iter()
        .enumerate()
        .filter_map(|(i, &b)| dec.push(b).map(|r| (i, r)))
        .collect();
    assert_eq!(at, [(43, Ok(sample())), (84, Ok(sample()))]);
    assert_eq!(dec.stats().dropped_bytes, 3);
    assert_eq!(dec.stats().errors, 0);
    // A frame cut short, then a whole frame with no 0x00 between: the same.
    let stream = [&f[..25], &f].concat();
    let got: std::vec::Vec<_> = stream.iter().filter_map(|&b| dec.push(b)).collect();
    assert_eq!(got, [Ok(sample())]);
    assert_eq!(dec.stats().dropped_bytes, 3 + 25);
}

/// Every garbage prefix of up to 5 bytes from an alphabet of zeros, COBS codes and the frame's
/// own bytes, then a frame: alone, twice, or behind a truncated copy of itself (no 0x00 between).
/// At every byte the decoder answers as the naive reference (`verification::reference`, which
/// tries `decode_robust` on every slice ending there), and the last frame is delivered at its
/// terminator.
#[test]
fn robust_stream_holds_back_no_frame_exhaustively() {
    let f = robust(&sample());
    let alphabet = [
        0x00,
        0x01,
        0x02,
        0xFF,
        f[0],
        f[1],
        f[5],
        f[Msg::ROBUST_LEN - 2],
    ];
    let tails = [
        f.clone(),
        [&f[..], &f].concat(),
        [&f[..1], &f].concat(),
        [&f[..20], &f].concat(),
        [&f[..Msg::ROBUST_LEN - 1], &f].concat(),
    ];
    let mut streams = 0u32;
    for len in 0..=5u32 {
        for code in 0..alphabet.len().pow(len) {
            let mut prefix = std::vec::Vec::new();
            let mut c = code;
            for _ in 0..len {
                prefix.push(alphabet[c % alphabet.len()]);
                c /= alphabet.len();
            }
            for tail in &tails {
                let stream = [prefix.as_slice(), tail].concat();
                let mut dec = RobustDecoder::<4>::new();
                let mut last = None;
                for end in 1..=stream.len() {
                    let got = dec.push(stream[end - 1]);
                    super::verification::check_against_reference(&stream[..end], got);
                    last = got;
                }
                assert_eq!(last, Some(Ok(sample())), "{prefix:02X?} {tail:02X?}");
                streams += 1;
            }
        }
    }
    assert_eq!(streams, 37_449 * 5);
}

/// What a receiver of the legacy packets that splits the stream after each `'\n'` sees.
fn split_lines(stream: &[u8]) -> std::vec::Vec<&[u8]> {
    stream.split_inclusive(|&b| b == DELIMITER).collect()
}

#[test]
fn legacy_split_on_newline_loses_and_corrupts_commands() {
    // Loss: motor 0 to 10 degrees puts 0x0A at offset 8. Split there, the packet is a 9-byte and a
    // 28-byte piece, both refused: the command never arrives, however often it is sent.
    let a = Msg {
        cmd_type: CmdType::Mtrs,
        is_relative: 0,
        mtr_angles: [10, 0, 0, 0],
        mtr_speed_deg_s: 30,
        mtr_accel_deg_s_s: 60,
        cmd_success: 0,
    };
    let mut pa = [0u8; 37];
    a.encode_legacy(&mut pa).unwrap();
    assert_eq!(pa[..12], [0, 0, 0, 0, 0, 0, 0, 0, 0x0A, 0, 0, 0]);
    let pieces = split_lines(&pa);
    assert_eq!(
        pieces.iter().map(|p| p.len()).collect::<std::vec::Vec<_>>(),
        [9, 28]
    );
    assert!(pieces.iter().all(|p| Msg::decode_legacy(p).is_err()));
    // Corruption: A's '\n' lost on the line (one byte dropped), then B, whose motor 0 angle 2560 is
    // 00 0A 00 00 (0x0A at offset 9). The 37 bytes from A's offset 9 to B's offset 9 end in '\n'
    // and decode as a motor command that neither packet holds: A's speed and acceleration bytes,
    // shifted, become angles of motors 1 and 2 (503,316,480 and 1,006,632,960 degrees).
    let b = Msg {
        mtr_angles: [2560, 0, 0, 0],
        ..a
    };
    let mut pb = [0u8; 37];
    b.encode_legacy(&mut pb).unwrap();
    let stream = [&pa[..36], &pb[..]].concat();
    let pieces = split_lines(&stream);
    assert_eq!(
        pieces.iter().map(|p| p.len()).collect::<std::vec::Vec<_>>(),
        [9, 37, 27]
    );
    let forged = Msg::decode_legacy(pieces[1]).unwrap();
    assert_eq!(forged.cmd_type, CmdType::Mtrs);
    assert_ne!(forged, a);
    assert_ne!(forged, b);
    assert_eq!(forged.mtr_angles, [0, 0x1E00_0000, 0x3C00_0000, 0]);
    // The robust frames of the same commands, the same byte lost: A is refused, B delivered.
    let (fa, fb) = (robust(&a), robust(&b));
    let stream = [&fa[..fa.len() - 1], &fb[..]].concat();
    let mut dec = RobustDecoder::<4>::new();
    let got: std::vec::Vec<_> = stream.iter().filter_map(|&x| dec.push(x)).collect();
    assert_eq!(got, [Ok(b)]);
}
