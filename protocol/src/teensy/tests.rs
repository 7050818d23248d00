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
