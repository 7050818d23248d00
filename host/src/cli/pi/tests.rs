//! The seed 004 verbs against a fake board: what each transfer carried (decoded back with
//! `decode_rx`, compared with the values given as arguments), and the verdicts. The board's
//! replies are written here byte by byte at the seed's offsets, not with `encode_tx`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic,
    clippy::float_cmp
)]

use super::*;
use protocol::pi_spi::decode_rx;

/// A fake board: records every buffer the host sent, answers transfer n with `reply(n)`, and fails
/// the transfer numbered `fail_at` (that one is not recorded: its bytes never left).
struct FakeBoard {
    sent: Vec<[u8; TRANSFER_LEN]>,
    reply: Box<dyn FnMut(usize) -> Vec<u8>>,
    fail_at: Option<usize>,
    attempts: usize,
}

impl FakeBoard {
    fn new(reply: impl FnMut(usize) -> Vec<u8> + 'static) -> Self {
        Self {
            sent: Vec::new(),
            reply: Box::new(reply),
            fail_at: None,
            attempts: 0,
        }
    }

    fn decoded(&self) -> Vec<RxBuffer> {
        self.sent
            .iter()
            .map(|b| decode_rx(b[..RX_LEN].try_into().unwrap()).unwrap())
            .collect()
    }
}

impl Transport for FakeBoard {
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        let n = self.attempts;
        self.attempts += 1;
        assert_eq!(tx.len(), 179, "every transfer is TRANSFER_LEN = 179 bytes");
        assert_eq!(rx.len(), 179);
        if self.fail_at == Some(n) {
            return Err(LinkError::Io(
                "fake".into(),
                std::io::Error::other("cable pulled"),
            ));
        }
        self.sent.push(tx.try_into().unwrap());
        let r = (self.reply)(n);
        rx.copy_from_slice(&r);
        Ok(())
    }

    fn name(&self) -> &str {
        "fake"
    }
}

/// A TxBuffer at the seed's offsets: version 15 at 0, updateTime at 1, motor.position[4] at 21,
/// batteryVoltage at 50; padded to the 179-byte transfer.
fn tx_bytes(update_time: u32, position: [i32; 4]) -> Vec<u8> {
    let mut b = vec![0u8; 179];
    b[0] = 15;
    b[1..5].copy_from_slice(&update_time.to_le_bytes());
    for (i, p) in position.iter().enumerate() {
        b[21 + 4 * i..25 + 4 * i].copy_from_slice(&p.to_le_bytes());
    }
    b[50..52].copy_from_slice(&3000i16.to_le_bytes());
    b
}

/// A board whose clock advances 10 ms per transfer and whose motors do not move.
fn live_board() -> FakeBoard {
    FakeBoard::new(|n| tx_bytes(1_000 + 10_000 * n as u32, [7, -7, 0, 0]))
}

fn collect(
    run: impl FnOnce(&mut dyn FnMut(Value)) -> Result<Verdict, String>,
) -> (Result<Verdict, String>, Vec<Value>) {
    let mut lines = Vec::new();
    let v = run(&mut |l| lines.push(l));
    (v, lines)
}

fn never() -> impl FnMut() -> bool {
    || false
}

fn last(lines: &[Value]) -> &Value {
    lines.last().expect("a last line")
}

#[test]
fn ping_sends_only_ignored_version_0_buffers_and_an_advancing_board_is_done() {
    let mut dev = live_board();
    let (v, lines) = collect(|s| run_ping(&mut dev, 3, s));
    assert_eq!(v.unwrap(), Verdict::Done);
    assert_eq!(dev.sent.len(), 3);
    for b in &dev.sent {
        assert!(b.iter().all(|x| *x == 0), "a ping sends zeros only");
        let head: &[u8; RX_LEN] = b[..RX_LEN].try_into().unwrap();
        assert_eq!(decode_rx(head), Err(RejectReason::Version));
    }
    let pings: Vec<&Value> = lines.iter().filter(|l| l.get("ping").is_some()).collect();
    assert_eq!(pings.len(), 3);
    for (i, p) in pings.iter().enumerate() {
        assert_eq!(p["ping"], i);
        assert_eq!(p["tx"]["update_time"], 1_000 + 10_000 * i as u64);
        assert_eq!(p["tx"]["motor"]["position"], json!([7, -7, 0, 0]));
        assert_eq!(p["tx"]["battery_voltage"], 3000);
        assert!(p["round_trip_us"].is_u64());
        assert!(p["t_ms"].is_u64());
    }
    assert_eq!(pings[0]["advanced"], Value::Null, "nothing to compare with");
    assert_eq!(pings[1]["advanced"], true);
    let end = last(&lines);
    assert_eq!(end["verdict"], "done");
    assert_eq!(end["stale"], false);
    assert_eq!(end["update_time"]["advanced"], true);
    assert_eq!(end["update_time"]["first"], 1_000);
    assert_eq!(end["update_time"]["last"], 21_000);
}

#[test]
fn ping_makes_at_least_two_transfers() {
    let mut dev = live_board();
    let (v, _) = collect(|s| run_ping(&mut dev, 1, s));
    assert_eq!(v.unwrap(), Verdict::Done);
    assert_eq!(dev.sent.len(), 2);
}

#[test]
fn ping_reports_a_frozen_timestamp_as_stale() {
    let mut dev = FakeBoard::new(|_| tx_bytes(555, [0; 4]));
    let (v, lines) = collect(|s| run_ping(&mut dev, 4, s));
    assert_eq!(v.unwrap(), Verdict::NoReply);
    let end = last(&lines);
    assert_eq!(end["stale"], true);
    assert_eq!(end["decoded"], 4);
    assert_eq!(end["update_time"]["advanced"], false);
    assert!(end["why"].as_str().unwrap().contains("frozen"));
    assert_eq!(Verdict::NoReply.exit_code(), 69);
}

#[test]
fn ping_of_an_absent_board_names_the_all_zero_or_all_ff_bytes() {
    for (byte, words) in [(0x00u8, "0x00"), (0xFF, "0xFF")] {
        let mut dev = FakeBoard::new(move |_| vec![byte; 179]);
        let (v, lines) = collect(|s| run_ping(&mut dev, 2, s));
        assert_eq!(v.unwrap(), Verdict::NoReply);
        let first = &lines[0];
        assert_eq!(first["error"], "version");
        assert_eq!(first["version_byte"], byte);
        assert!(first["hint"].as_str().unwrap().contains(words));
        let end = last(&lines);
        assert_eq!(end["decoded"], 0);
        assert_eq!(end["errors"], 2);
        assert!(end["why"].as_str().unwrap().contains(words));
    }
}

#[test]
fn monitor_prints_every_reply_and_counts_errors_without_stopping() {
    // Odd transfers answer garbage whose version byte is 14.
    let mut dev = FakeBoard::new(|n| {
        if n % 2 == 1 {
            let mut g: Vec<u8> = (0..179u32).map(|i| (i * 37 + 11) as u8).collect();
            g[0] = 14;
            g
        } else {
            tx_bytes(100 * n as u32, [0; 4])
        }
    });
    let plan = MonitorPlan::new(200.0, 10.0, Some(6)).unwrap();
    let (v, lines) = collect(|s| run_monitor(&mut dev, &plan, &mut never(), s));
    assert_eq!(v.unwrap(), Verdict::Done);
    assert_eq!(dev.sent.len(), 6);
    assert!(dev.sent.iter().flatten().all(|x| *x == 0));
    let transfers: Vec<&Value> = lines
        .iter()
        .filter(|l| l.get("transfer").is_some())
        .collect();
    assert_eq!(transfers.len(), 6);
    for (k, l) in transfers.iter().enumerate() {
        assert_eq!(l["transfer"], k);
        if k % 2 == 1 {
            assert_eq!(l["error"], "version");
            assert_eq!(l["version_byte"], 14);
        } else {
            assert_eq!(l["tx"]["update_time"], 100 * k as u64);
        }
    }
    let end = last(&lines);
    assert_eq!(end["decoded"], 3);
    assert_eq!(end["errors"], 3);
    assert_eq!(end["interrupted"], false);
}

/// The drive of the test `drive_arms_then_sends_the_commands_then_shuts_down`.
fn drive_args() -> PiDriveArgs {
    PiDriveArgs {
        modes: Some("pwm,mav,mtp,brake".into()),
        targets: Some("200,-150,80,0".into()),
        goals: Some("0,0,5000,-3".into()),
        servo_modes: Some("enabled,off,disabled,enabled".into()),
        servo_pos: Some("1500,0,0,2600".into()),
        ..PiDriveArgs::default()
    }
}

#[test]
fn drive_arms_then_sends_the_commands_then_shuts_down() {
    let plan = PiDrivePlan::new(&drive_args(), 100.0, 0.05).unwrap();
    assert_eq!(plan.frames, 5);
    let mut dev = FakeBoard::new(|n| tx_bytes(10 * n as u32, [n as i32; 4]));
    let (v, lines) = collect(|s| run_drive(&mut dev, &plan, &mut never(), s));
    assert_eq!(v.unwrap(), Verdict::Done);
    let rx = dev.decoded();
    assert_eq!(rx.len(), 7, "arm, five commands, shutdown");

    let arm = &rx[0];
    assert!(
        arm.system_shutdown.motors,
        "the first transfer sets the motor shutdown bit"
    );
    assert!(!arm.system_shutdown.servos);
    assert_eq!(arm.motor_control_mode, [MotorMode::Off; 4]);
    assert_eq!(arm.motor_target, [0; 4]);
    assert_eq!(arm.servo_mode, [ServoMode::FullyDisabled; 4]);
    assert_eq!(arm.updates, UpdateFlags(0));

    for c in &rx[1..6] {
        assert_eq!(
            c.system_shutdown,
            Shutdown::default(),
            "bit clear: the re-arm edge"
        );
        assert_eq!(
            c.motor_control_mode,
            [
                MotorMode::Pwm,
                MotorMode::Mav,
                MotorMode::Mtp,
                MotorMode::PassiveBrake
            ]
        );
        assert_eq!(c.motor_target, [200, -150, 80, 0]);
        assert_eq!(c.motor_goal_position, [0, 0, 5000, -3]);
        assert_eq!(
            c.servo_mode,
            [
                ServoMode::Enabled,
                ServoMode::FullyDisabled,
                ServoMode::Disabled,
                ServoMode::Enabled
            ]
        );
        assert_eq!(c.servo_pos, [1500, 0, 0, 2600]);
        assert_eq!(c.updates, UpdateFlags(0));
    }

    let down = &rx[6];
    assert!(down.system_shutdown.motors && down.system_shutdown.servos);
    assert_eq!(down.motor_control_mode, [MotorMode::Off; 4]);
    assert_eq!(down.motor_target, [0; 4]);

    // Every reply printed (--every 1), the shutdown transfer's too.
    let printed: Vec<u64> = lines
        .iter()
        .filter_map(|l| l.get("tx").map(|t| t["update_time"].as_u64().unwrap()))
        .collect();
    assert_eq!(printed, vec![0, 10, 20, 30, 40, 50, 60]);
    let end = last(&lines);
    assert_eq!(
        end["transfers"],
        json!({"arm": 1, "command": 5, "shutdown": true})
    );
    assert_eq!(end["interrupted"], false);
    assert_eq!(end["commanded"], json!([true, true, true, false]));
}

#[test]
fn drive_prints_every_nth_reply() {
    let args = PiDriveArgs {
        every: Some(3),
        ..drive_args()
    };
    let plan = PiDrivePlan::new(&args, 100.0, 0.05).unwrap();
    let mut dev = live_board();
    let (_, lines) = collect(|s| run_drive(&mut dev, &plan, &mut never(), s));
    let printed: Vec<u64> = lines
        .iter()
        .filter(|l| l.get("tx").is_some())
        .map(|l| l["transfer"].as_u64().unwrap())
        .collect();
    assert_eq!(printed, vec![0, 3, 6]);
}

#[test]
fn one_shot_updates_ride_on_exactly_one_transfer() {
    let dir = std::env::temp_dir().join(format!("motorlink-pi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json_file = dir.join("kin.json");
    std::fs::write(
        &json_file,
        r#"{"inverse":[[0.25,0.25,0.25,0.25],[-0.25,0.25,0.25,-0.25],[-1.5,1.5,-1.5,1.5]],"ticks_to_rad":[0.001,0.001,0.002,0.002]}"#,
    )
    .unwrap();
    let toml_file = dir.join("kin.toml");
    std::fs::write(
        &toml_file,
        "inverse = [[0.25, 0.25, 0.25, 0.25], [-0.25, 0.25, 0.25, -0.25], [-1.5, 1.5, -1.5, 1.5]]\nticks_to_rad = [0.001, 0.001, 0.002, 0.002]\n",
    )
    .unwrap();
    for file in [&json_file, &toml_file] {
        let args = PiDriveArgs {
            odom_reset: true,
            kinematics: Some(file.clone()),
            pid_speed: Some("0.5,0.125,0".into()),
            ..drive_args()
        };
        let plan = PiDrivePlan::new(&args, 100.0, 0.05).unwrap();
        let mut dev = live_board();
        collect(|s| run_drive(&mut dev, &plan, &mut never(), s))
            .0
            .unwrap();
        let rx = dev.decoded();
        let with_flags: Vec<usize> = (0..rx.len()).filter(|i| rx[*i].updates.0 != 0).collect();
        assert_eq!(
            with_flags,
            vec![0],
            "one transfer, the arm transfer, carries the flags"
        );
        assert_eq!(
            rx[0].updates.0,
            UpdateFlags::ODOM_RESET | UpdateFlags::KINEMATICS | UpdateFlags::MOTOR_PID_SPEED
        );
        // Three flags: the parity bit 7 makes the count of set bits odd (bits 0, 4, 5 → already odd).
        let word = u32::from_le_bytes(dev.sent[0][1..5].try_into().unwrap());
        assert_eq!(word, 0b11_0001);
        let pid = rx[0].motor_pid_settings;
        assert_eq!(pid.kp, [0.5; 4]);
        assert_eq!(pid.ki, [0.125; 4]);
        assert_eq!(pid.kd, [0.0; 4]);
        let k = rx[0].kinematics;
        assert_eq!(k.inverse[1], [-0.25, 0.25, 0.25, -0.25]);
        assert_eq!(k.inverse[2], [-1.5, 1.5, -1.5, 1.5]);
        assert_eq!(k.ticks_to_rad, [0.001, 0.001, 0.002, 0.002]);
    }
    // One flag alone (odd count): no parity bit; two (even): parity bit set.
    for (args, want) in [
        (
            PiDriveArgs {
                odom_reset: true,
                ..drive_args()
            },
            0b10_0000u32,
        ),
        (
            PiDriveArgs {
                odom_reset: true,
                pid_speed: Some("1,2,3,4,5,6,7,8,9,10,11,12".into()),
                ..drive_args()
            },
            0b1010_0001,
        ),
    ] {
        let plan = PiDrivePlan::new(&args, 100.0, 0.03).unwrap();
        let mut dev = live_board();
        collect(|s| run_drive(&mut dev, &plan, &mut never(), s))
            .0
            .unwrap();
        let words: Vec<u32> = dev
            .sent
            .iter()
            .map(|b| u32::from_le_bytes(b[1..5].try_into().unwrap()))
            .collect();
        assert_eq!(words[0], want);
        assert!(
            words[1..].iter().all(|w| *w == 0b1000_0000),
            "no flags: parity bit only"
        );
        if args.pid_speed.is_some() {
            let pid = dev.decoded()[0].motor_pid_settings;
            assert_eq!(pid.kp, [1.0, 4.0, 7.0, 10.0]);
            assert_eq!(pid.ki, [2.0, 5.0, 8.0, 11.0]);
            assert_eq!(pid.kd, [3.0, 6.0, 9.0, 12.0]);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn out_of_range_servo_positions_are_refused_before_the_device_is_opened() {
    for (modes, pos) in [
        ("enabled", Some("599")),
        ("enabled", Some("2601")),
        ("off,enabled,off,off", Some("1500,100,1500,1500")),
        ("enabled", None),
        ("enabled", Some("-5")),
    ] {
        let args = PiDriveArgs {
            servo_modes: Some(modes.into()),
            servo_pos: pos.map(String::from),
            ..PiDriveArgs::default()
        };
        let mut opened = false;
        let (v, lines) = collect(|s| {
            drive(
                &args,
                100.0,
                1.0,
                || -> Result<FakeBoard, String> {
                    opened = true;
                    Ok(live_board())
                },
                &mut never(),
                s,
            )
        });
        let e = v.unwrap_err();
        assert!(e.contains("600..=2600"), "{e}");
        assert!(e.contains("nothing was sent"), "{e}");
        assert!(
            !opened,
            "refused before the device is opened ({modes} {pos:?})"
        );
        assert!(lines.is_empty());
    }
    // A servo that is not enabled may carry any position; the edges are accepted.
    let ok = PiDriveArgs {
        servo_modes: Some("enabled,disabled,off,enabled".into()),
        servo_pos: Some("600,0,65535,2600".into()),
        ..PiDriveArgs::default()
    };
    assert_eq!(
        PiDrivePlan::new(&ok, 100.0, 1.0).unwrap().command.servo_pos,
        [600, 0, 65535, 2600]
    );
}

#[test]
fn other_bad_arguments_are_refused_with_the_reason() {
    let bad = |a: PiDriveArgs, hz: f64, want: &str| {
        let e = PiDrivePlan::new(&a, hz, 1.0).unwrap_err();
        assert!(e.contains(want), "{e} should contain {want}");
    };
    let modes = |m: &str, t: &str| PiDriveArgs {
        modes: Some(m.into()),
        targets: Some(t.into()),
        ..PiDriveArgs::default()
    };
    bad(modes("pwm", "400"), 100.0, "-399..=399");
    bad(modes("pwm", "-400"), 100.0, "-399..=399");
    bad(modes("fast", "0"), 100.0, "not a motor mode");
    bad(
        modes("pwm,pwm", "0"),
        100.0,
        "one value (for all four) or four",
    );
    bad(
        modes("pwm", "1,2,3"),
        100.0,
        "one value (for all four) or four",
    );
    bad(modes("pwm", "x"), 100.0, "not an integer");
    bad(modes("pwm", "0"), 20.0, "above 20.4");
    bad(modes("pwm", "0"), 0.0, "--hz");
    let pid = |p: &str| PiDriveArgs {
        pid_speed: Some(p.into()),
        ..PiDriveArgs::default()
    };
    bad(pid("1,2"), 100.0, "kp,ki,kd");
    bad(pid("1,nan,2"), 100.0, "finite");
    bad(
        PiDriveArgs {
            kinematics: Some("/nonexistent/kin.json".into()),
            ..PiDriveArgs::default()
        },
        100.0,
        "cannot read",
    );
    bad(
        PiDriveArgs {
            every: Some(0),
            ..PiDriveArgs::default()
        },
        100.0,
        "--every 0",
    );
    // MAV and MTP targets are not duties: no ±399 limit.
    let ok =
        PiDrivePlan::new(&modes("mav,mtp,off,brake", "5000,-5000,9999,1"), 100.0, 1.0).unwrap();
    assert_eq!(ok.command.motor_target, [5000, -5000, 9999, 1]);
    assert_eq!(ok.frames, 100);
}

#[test]
fn a_failed_transfer_still_sends_the_shutdown_buffer() {
    let plan = PiDrivePlan::new(&drive_args(), 100.0, 0.1).unwrap();
    let mut dev = live_board();
    dev.fail_at = Some(3);
    let (v, lines) = collect(|s| run_drive(&mut dev, &plan, &mut never(), s));
    let e = v.unwrap_err();
    assert!(e.contains("cable pulled"), "{e}");
    assert!(e.contains("shutdown buffer"), "{e}");
    let rx = dev.decoded();
    assert_eq!(rx.len(), 4, "arm, two commands, (the failed one), shutdown");
    let down = rx.last().unwrap();
    assert!(down.system_shutdown.motors && down.system_shutdown.servos);
    assert_eq!(down.motor_control_mode, [MotorMode::Off; 4]);
    assert!(last(&lines)["error"]
        .as_str()
        .unwrap()
        .contains("transfer 3"));
}

#[test]
fn a_stop_request_ends_the_drive_with_the_shutdown_buffer() {
    let plan = PiDrivePlan::new(&drive_args(), 100.0, 10.0).unwrap();
    let mut dev = live_board();
    let mut checks = 0;
    let mut stop = || {
        checks += 1;
        checks > 4
    };
    let (v, lines) = collect(|s| run_drive(&mut dev, &plan, &mut stop, s));
    assert_eq!(v.unwrap(), Verdict::Done);
    let rx = dev.decoded();
    assert_eq!(rx.len(), 5, "arm, three commands, shutdown");
    assert!(rx[1..4].iter().all(|c| !c.system_shutdown.motors));
    let down = &rx[4];
    assert!(down.system_shutdown.motors && down.system_shutdown.servos);
    let end = last(&lines);
    assert_eq!(end["interrupted"], true);
    assert_eq!(end["transfers"]["command"], 3);
}

#[test]
fn a_board_answering_garbage_gives_no_reply() {
    let mut seed = 0x1234_5678u32;
    let mut dev = FakeBoard::new(move |_| {
        let mut g: Vec<u8> = (0..179)
            .map(|_| {
                seed ^= seed << 13;
                seed ^= seed >> 17;
                seed ^= seed << 5;
                seed as u8
            })
            .collect();
        if g[0] == 15 {
            g[0] = 16;
        }
        g
    });
    let plan = PiDrivePlan::new(&drive_args(), 100.0, 0.05).unwrap();
    let (v, lines) = collect(|s| run_drive(&mut dev, &plan, &mut never(), s));
    assert_eq!(v.unwrap(), Verdict::NoReply);
    let end = last(&lines);
    assert_eq!(end["verdict"], "no_reply");
    assert_eq!(end["decoded"], 0);
    assert_eq!(end["errors"], 7);
    let down = dev.decoded().pop().unwrap();
    assert!(down.system_shutdown.motors && down.system_shutdown.servos);
}

#[test]
fn motors_that_never_move_are_refused_and_moving_ones_are_done() {
    // 0.25 s of PWM commands (at least REFUSED_AFTER): a board whose positions stay put refused
    // them; one whose commanded motor 0 counts up after the first command did them.
    let args = PiDriveArgs {
        modes: Some("pwm,off,off,off".into()),
        targets: Some("150".into()),
        ..PiDriveArgs::default()
    };
    let plan = PiDrivePlan::new(&args, 200.0, 0.25).unwrap();
    let mut still = live_board();
    let (v, lines) = collect(|s| run_drive(&mut still, &plan, &mut never(), s));
    assert_eq!(v.unwrap(), Verdict::Refused);
    assert_eq!(Verdict::Refused.exit_code(), 1);
    assert_eq!(last(&lines)["moved"], json!([false, false, false, false]));
    assert_eq!(
        last(&lines)["commanded"],
        json!([true, false, false, false])
    );

    let mut moving = FakeBoard::new(|n| {
        let p = if n >= 2 { 10 * n as i32 } else { 0 };
        tx_bytes(n as u32 * 5_000, [p, 0, 0, 0])
    });
    let (v, lines) = collect(|s| run_drive(&mut moving, &plan, &mut never(), s));
    assert_eq!(v.unwrap(), Verdict::Done);
    assert_eq!(last(&lines)["moved"], json!([true, false, false, false]));
}

#[test]
fn signals_raise_the_stop_flag() {
    let mut s = Signals::block().unwrap();
    assert!(!s.received());
    nix::sys::signal::raise(Signal::SIGTERM).unwrap();
    assert!(s.received());
    assert!(s.received(), "it stays raised");
}
