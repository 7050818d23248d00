//! Tests of the frame tools: round trips through the CLI functions, the committed golden vectors
//! (values written by Python `struct`, not by this code), and every error path.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use super::*;
use serde_json::{json, Value};

const GOLDEN_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../protocol/golden");

/// The documented example of every kind (each must appear verbatim in [`SHAPES`] and the README).
fn examples() -> Vec<(FrameKind, &'static str)> {
    vec![
        (
            FrameKind::AmrCommand,
            r#"{"timestamp_us":1000,"left_speed_cmd":1.5,"right_speed_cmd":-1.5,"control_mode":1,"enable":true,"seq":1,"request":0}"#,
        ),
        (
            FrameKind::AmrFeedback,
            r#"{"timestamp_us":5,"left_speed":0.5,"right_speed":-0.5,"left_current":1.25,"right_current":0.75,"left_encoder":-3,"right_encoder":7,"fault_flags":2,"seq":9,"mode":1,"cmd_seq":8}"#,
        ),
        (
            FrameKind::AmrInfo,
            r#"{"fw_version":66051,"git_hash":439041101,"board":"amr_spi","build_date":20261130,"reset_cause":"independent_watchdog","reset_count":2,"panic_line":0,"seq":1234,"dirty":false}"#,
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"set_motor_pwm","pwm":[-1000,1000,0,1],"timeout_ms":200}"#,
        ),
        (FrameKind::Cdc, r#"{"type":"motor_enable","enable":true}"#),
        (FrameKind::Cdc, r#"{"type":"estop","action":"engage"}"#),
        (FrameKind::Cdc, r#"{"type":"ping"}"#),
        (FrameKind::Cdc, r#"{"type":"ack","msg_id":3,"result":0}"#),
        (
            FrameKind::Cdc,
            r#"{"type":"imu","t_ms":123456,"accel_mg":[0,-1000,1000],"gyro_mdps":[5,-5,32767],"temp_cdeg":2512}"#,
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"status","t_ms":4294967295,"vbat_mv":12600,"flags":11,"err":4}"#,
        ),
        (
            FrameKind::PiRx,
            r#"{"updates":19,"system_shutdown":{"servos":false,"motors":true},"motor_control_mode":["mav","mav","mtp","passive_brake"],"motor_target":[100,-100,399,0],"motor_goal_position":[123456,-1,0,2147483647],"servo_mode":["enabled","disabled","fully_disabled","enabled"],"servo_pos":[600,2600,1500,0],"motor_pid_settings":{"kp":[1.5,2.5,0.25,-1.0],"ki":[0.125,0.0,3.0,4.0],"kd":[0.5,0.75,0.001,100.0]},"imu_gyro_orientation":[1,0,0,0,-1,0,0,0,1],"imu_compass_orientation":[0,1,0,1,0,0,0,0,-1],"kinematics":{"inverse":[[0.25,0.25,0.25,0.25],[-0.25,0.25,0.25,-0.25],[-1.5,1.5,-1.5,1.5]],"ticks_to_rad":[0.001,0.001,0.002,0.002]}}"#,
        ),
        (
            FrameKind::PiTx,
            r#"{"update_time":987654321,"motor":{"bemf":[1,-2,3,-4],"position":[100000,-100000,7,0],"done":5},"analog_sensor":[0,4095,2048,1,2,3],"battery_voltage":3000,"digital_sensors":1027,"imu":{"gyro":{"x":0.5,"y":-0.5,"z":9.81,"accuracy":3},"accel":{"x":1.0,"y":2.0,"z":3.0,"accuracy":2},"compass":{"x":-40.0,"y":12.0,"z":30.0,"accuracy":1},"linear_accel":{"x":0.1,"y":0.2,"z":0.0,"accuracy":0},"accel_velocity":{"x":0.01,"y":0.0,"z":-0.01,"accuracy":-1},"dmp_quat":{"w":1.0,"x":0.0,"y":0.0,"z":0.0},"heading":359.5,"temperature":36.6},"odometry":{"pos_x":1.25,"pos_y":-2.5,"heading":3.0,"vx":0.5,"vy":0.0,"wz":-0.75}}"#,
        ),
        (
            FrameKind::TeensyLegacy,
            r#"{"cmd_type":"mtrs","is_relative":1,"mtr_angles":[90,-90,2570,2147483647],"mtr_speed_deg_s":30,"mtr_accel_deg_s_s":-60,"cmd_success":1}"#,
        ),
        (
            FrameKind::TeensyRobust,
            r#"{"cmd_type":"mtrs","is_relative":1,"mtr_angles":[90,-90,2570,2147483647],"mtr_speed_deg_s":30,"mtr_accel_deg_s_s":-60,"cmd_success":1}"#,
        ),
    ]
}

/// Numbers equal as f32 when either is fractional (decode prints the shortest f32 decimal), exactly otherwise.
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            if x.is_f64() || y.is_f64() {
                let (x, y) = (x.as_f64().unwrap() as f32, y.as_f64().unwrap() as f32);
                x.to_bits() == y.to_bits() || x == y
            } else {
                x == y
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(a, b)| same(a, b))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
        }
        _ => a == b,
    }
}

fn assert_same(got: &Value, want: &Value, what: &str) {
    assert!(same(got, want), "{what}:\n got  {got}\n want {want}");
}

#[test]
fn every_example_round_trips_json_hex_json() {
    for (kind, text) in examples() {
        let hex = encode(kind, text, DEFAULT_MOTORS).unwrap();
        let back: Value =
            serde_json::from_str(&decode(kind, &hex, DEFAULT_MOTORS).unwrap()).unwrap();
        let want: Value = serde_json::from_str(text).unwrap();
        assert_same(&back, &want, &format!("{kind:?}"));
        // and the hex is stable through a second pass
        assert_eq!(
            encode(kind, &back.to_string(), DEFAULT_MOTORS).unwrap(),
            hex
        );
    }
}

#[test]
fn every_example_is_documented_in_help_and_readme() {
    let readme = include_str!("../../README.md");
    for (kind, text) in examples() {
        assert!(
            SHAPES.contains(text),
            "{kind:?} example missing from SHAPES"
        );
        assert!(
            readme.contains(text),
            "{kind:?} example missing from host/README.md"
        );
    }
}

#[test]
fn teensy_round_trips_for_every_supported_motor_count() {
    for n in [1usize, 2, 3, 4, 6, 8, 16] {
        let angles: Vec<i32> = (0..n as i32).map(|i| i * 1000 - 7).collect();
        let want = json!({"cmd_type": "config", "is_relative": 0, "mtr_angles": angles,
            "mtr_speed_deg_s": -5, "mtr_accel_deg_s_s": 9, "cmd_success": 0});
        for kind in [FrameKind::TeensyLegacy, FrameKind::TeensyRobust] {
            let hex = encode(kind, &want.to_string(), n).unwrap();
            let bytes = parse_hex(&hex).unwrap();
            if kind == FrameKind::TeensyLegacy {
                // sizeof(CmdMsg) + '\n' = 4·(5 + n) + 1, from the seed's struct.
                assert_eq!(
                    bytes.len(),
                    4 * (5 + n) + 1,
                    "legacy length with {n} motors"
                );
            } else {
                assert_eq!(bytes.last(), Some(&0));
                assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1);
            }
            let back: Value = serde_json::from_str(&decode(kind, &hex, n).unwrap()).unwrap();
            assert_eq!(back, want, "{kind:?} with {n} motors");
        }
    }
}

#[test]
fn a_wrong_motor_count_is_named_with_the_count_that_fits() {
    let hex = encode(
        FrameKind::TeensyLegacy,
        r#"{"mtr_angles":[1,2,3,4,5,6]}"#,
        6,
    )
    .unwrap();
    let e = decode(FrameKind::TeensyLegacy, &hex, 4).unwrap_err();
    assert!(e.contains("Framing") && e.contains("--motors 6"), "{e}");
    let hex = encode(
        FrameKind::TeensyRobust,
        r#"{"mtr_angles":[1,2,3,4,5,6]}"#,
        6,
    )
    .unwrap();
    let e = decode(FrameKind::TeensyRobust, &hex, 4).unwrap_err();
    assert!(e.contains("Framing") && e.contains("--motors 6"), "{e}");
    let e = encode(FrameKind::TeensyRobust, r#"{"mtr_angles":[1,2,3]}"#, 4).unwrap_err();
    assert!(e.contains("mtr_angles") && e.contains("--motors 3"), "{e}");
    let e = encode(FrameKind::TeensyLegacy, "{}", 17).unwrap_err();
    assert!(e.contains("--motors 17") && e.contains("1 to 16"), "{e}");
}

// ---- golden vectors: structs_python.txt (seed 001, 003, 004), amr_python.txt (seed 000) ----

fn kv(fields: &[&str]) -> std::collections::HashMap<String, String> {
    fields
        .iter()
        .filter_map(|f| f.split_once('='))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

fn ints(s: &str) -> Vec<i64> {
    s.split(',').map(|x| x.parse().unwrap()).collect()
}

/// An f32 given as its IEEE-754 bits (as the Python script writes floats), `null` if not finite.
fn fbits(bits: i64) -> Value {
    let f = f32::from_bits(u32::try_from(bits).unwrap());
    if f.is_finite() {
        json!(f)
    } else {
        Value::Null
    }
}

fn floats(s: &str) -> Vec<Value> {
    ints(s).into_iter().map(fbits).collect()
}

const MOTOR_MODES: [&str; 5] = ["off", "passive_brake", "pwm", "mav", "mtp"];
const SERVO_MODES: [&str; 3] = ["fully_disabled", "disabled", "enabled"];
const CMD_TYPES: [&str; 5] = ["mtrs", "cal", "endeff_on", "endeff_off", "config"];

fn names(s: &str, table: &[&str]) -> Vec<&'static str> {
    ints(s)
        .into_iter()
        .map(|i| match table.get(i as usize) {
            Some(n) => Box::leak(n.to_string().into_boxed_str()) as &'static str,
            None => panic!("undefined enum value {i}"),
        })
        .collect()
}

fn sensor(v: &[i64]) -> Value {
    json!({"x": fbits(v[0]), "y": fbits(v[1]), "z": fbits(v[2]), "accuracy": v[3]})
}

/// The JSON this tool must print for a golden line, built from the Python script's values.
fn expected_struct_json(
    kind: &str,
    f: &std::collections::HashMap<String, String>,
) -> (FrameKind, Value) {
    let g = |k: &str| {
        f.get(k)
            .map(String::as_str)
            .unwrap_or_else(|| panic!("{kind}: no {k}"))
    };
    let n = |k: &str| g(k).parse::<i64>().unwrap();
    match kind {
        "cdc_set_motor_pwm" => (
            FrameKind::Cdc,
            json!({"type": "set_motor_pwm", "pwm": ints(g("pwm")), "timeout_ms": n("timeout_ms")}),
        ),
        "cdc_motor_enable" => (
            FrameKind::Cdc,
            json!({"type": "motor_enable", "enable": n("enable") == 1}),
        ),
        "cdc_estop" => (
            FrameKind::Cdc,
            json!({"type": "estop", "action": if n("action") == 1 { "engage" } else { "release" }}),
        ),
        "cdc_ping" => (FrameKind::Cdc, json!({"type": "ping"})),
        "cdc_ack" => (
            FrameKind::Cdc,
            json!({"type": "ack", "msg_id": n("msg_id"), "result": n("result")}),
        ),
        "cdc_imu" => (
            FrameKind::Cdc,
            json!({"type": "imu", "t_ms": n("t_ms"), "accel_mg": ints(g("accel_mg")),
            "gyro_mdps": ints(g("gyro_mdps")), "temp_cdeg": n("temp_cdeg")}),
        ),
        "cdc_status" => (
            FrameKind::Cdc,
            json!({"type": "status", "t_ms": n("t_ms"), "vbat_mv": n("vbat_mv"),
            "flags": n("flags"), "err": n("err")}),
        ),
        "pi_rx" => {
            let pid = floats(g("pid"));
            let k = floats(g("kinematics"));
            (
                FrameKind::PiRx,
                json!({
                    "updates": n("updates"),
                    "system_shutdown": {"servos": n("shutdown") & 1 != 0, "motors": n("shutdown") & 2 != 0},
                    "motor_control_mode": names(g("motor_modes"), &MOTOR_MODES),
                    "motor_target": ints(g("motor_target")),
                    "motor_goal_position": ints(g("motor_goal")),
                    "servo_mode": names(g("servo_modes"), &SERVO_MODES),
                    "servo_pos": ints(g("servo_pos")),
                    "motor_pid_settings": {"kp": &pid[0..4], "ki": &pid[4..8], "kd": &pid[8..12]},
                    "imu_gyro_orientation": ints(g("gyro_orient")),
                    "imu_compass_orientation": ints(g("compass_orient")),
                    "kinematics": {"inverse": [&k[0..4], &k[4..8], &k[8..12]], "ticks_to_rad": &k[12..16]},
                }),
            )
        }
        "pi_tx" => {
            let imu = ints(g("imu"));
            let q = floats(g("quat"));
            let o = floats(g("odometry"));
            (
                FrameKind::PiTx,
                json!({
                    "update_time": n("update_time"),
                    "motor": {"bemf": ints(g("bemf")), "position": ints(g("position")), "done": n("done")},
                    "analog_sensor": ints(g("analog")),
                    "battery_voltage": n("battery"),
                    "digital_sensors": n("digital"),
                    "imu": {
                        "gyro": sensor(&imu[0..4]), "accel": sensor(&imu[4..8]), "compass": sensor(&imu[8..12]),
                        "linear_accel": sensor(&imu[12..16]), "accel_velocity": sensor(&imu[16..20]),
                        "dmp_quat": {"w": q[0], "x": q[1], "y": q[2], "z": q[3]},
                        "heading": fbits(n("heading")), "temperature": fbits(n("temperature")),
                    },
                    "odometry": {"pos_x": o[0], "pos_y": o[1], "heading": o[2], "vx": o[3], "vy": o[4], "wz": o[5]},
                }),
            )
        }
        "teensy_legacy" | "teensy_robust" => {
            let v = json!({
                "cmd_type": CMD_TYPES[n("cmd_type") as usize], "is_relative": n("is_relative"),
                "mtr_angles": ints(g("angles")), "mtr_speed_deg_s": n("speed"),
                "mtr_accel_deg_s_s": n("accel"), "cmd_success": n("success"),
            });
            let k = if kind == "teensy_legacy" {
                FrameKind::TeensyLegacy
            } else {
                FrameKind::TeensyRobust
            };
            (k, v)
        }
        other => panic!("golden kind {other} not handled"),
    }
}

#[test]
fn golden_structs_decode_to_the_python_values_and_encode_to_the_python_bytes() {
    let text = std::fs::read_to_string(format!("{GOLDEN_DIR}/structs_python.txt")).unwrap();
    let mut seen = std::collections::BTreeSet::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let parts: Vec<&str> = line.split_whitespace().collect();
        let (kind, hex) = (parts[0], parts[1]);
        let (fk, want) = expected_struct_json(kind, &kv(&parts[2..]));
        seen.insert(fk as u8);
        let got: Value = serde_json::from_str(&decode(fk, hex, 4).unwrap()).unwrap();
        assert_same(&got, &want, line);
        assert_eq!(encode(fk, &want.to_string(), 4).unwrap(), hex, "{line}");
    }
    // cdc, pi-rx, pi-tx, teensy-legacy, teensy-robust
    assert_eq!(seen.len(), 5);
}

#[test]
fn golden_amr_frames_decode_to_the_python_values() {
    let cases = std::fs::read_to_string(format!("{GOLDEN_DIR}/amr_cases.txt")).unwrap();
    let frames = std::fs::read_to_string(format!("{GOLDEN_DIR}/amr_python.txt")).unwrap();
    let float_fields = [
        "left_speed_cmd",
        "right_speed_cmd",
        "left_speed",
        "right_speed",
        "left_current",
        "right_current",
    ];
    // The wire values of McuInfo's enumerations, as the .proto comments list them.
    let boards = ["amr_spi", "cdc", "teensy", "pi_spi"];
    let causes = [
        "unknown",
        "power_on",
        "pin",
        "independent_watchdog",
        "panic",
        "software",
        "brownout",
        "window_watchdog",
        "low_power",
    ];
    let mut n = 0;
    for (case, frame) in cases.lines().zip(frames.lines()) {
        let c: Vec<&str> = case.split_whitespace().collect();
        let f: Vec<&str> = frame.split_whitespace().collect();
        assert_eq!(c[0], f[0]);
        let kind = match c[0] {
            "command" => FrameKind::AmrCommand,
            "feedback" => FrameKind::AmrFeedback,
            "info" => FrameKind::AmrInfo,
            other => panic!("unknown kind {other}"),
        };
        let mut want = serde_json::Map::new();
        for (k, v) in kv(&c[1..]) {
            let v: i64 = v.parse().unwrap();
            let val = if float_fields.contains(&k.as_str()) {
                fbits(v)
            } else if k == "enable" || k == "dirty" {
                json!(v == 1)
            } else if k == "board" {
                json!(boards[v as usize])
            } else if k == "reset_cause" {
                json!(causes[v as usize])
            } else {
                json!(v)
            };
            want.insert(k, val);
        }
        let want = Value::Object(want);
        let got: Value = serde_json::from_str(&decode(kind, f[1], 4).unwrap()).unwrap();
        assert_same(&got, &want, case);
        if !want.as_object().unwrap().values().any(Value::is_null) {
            assert_eq!(encode(kind, &want.to_string(), 4).unwrap(), f[1], "{case}");
        }
        n += 1;
    }
    assert_eq!(n, 17);
}

// ---- errors: each names the problem ----

fn err(kind: FrameKind, hex: &str) -> String {
    decode(kind, hex, DEFAULT_MOTORS).unwrap_err()
}

fn flip(hex: &str, byte: usize, mask: u8) -> String {
    let mut b = parse_hex(hex).unwrap();
    b[byte] ^= mask;
    to_hex(&b)
}

fn example(kind: FrameKind) -> String {
    let (_, j) = examples().into_iter().find(|(k, _)| *k == kind).unwrap();
    encode(kind, j, DEFAULT_MOTORS).unwrap()
}

#[test]
fn bad_hex_is_refused_with_the_reason() {
    for kind in [
        FrameKind::AmrCommand,
        FrameKind::Cdc,
        FrameKind::PiRx,
        FrameKind::TeensyRobust,
    ] {
        assert!(err(kind, "abc").contains("odd number of digits (3)"));
        assert!(err(kind, "zz00").contains("'zz' at digit 0 is not a hex byte"));
        assert!(err(kind, "0é").contains("non-ASCII"));
    }
    assert_eq!(parse_hex("0xAA 55:01,02").unwrap(), vec![0xAA, 0x55, 1, 2]);
}

#[test]
fn wrong_lengths_name_the_expected_length() {
    assert!(err(FrameKind::AmrCommand, "00").contains("exactly 64 bytes, got 1"));
    assert!(err(FrameKind::AmrFeedback, &"00".repeat(65)).contains("exactly 64 bytes, got 65"));
    assert!(err(FrameKind::PiRx, &"0f".repeat(178)).contains("exactly 179 bytes, got 178"));
    assert!(err(FrameKind::PiTx, &"0f".repeat(170)).contains("exactly 167 bytes, got 170"));
    assert!(err(FrameKind::TeensyLegacy, "0a").contains("is 37 bytes"));
    assert!(err(FrameKind::TeensyRobust, "0101").contains("no 0x00 terminator"));
    let e = err(FrameKind::Cdc, "aa5510");
    assert!(
        e.contains("Framing") && e.contains("code 2") && e.contains("no USB CDC frame"),
        "{e}"
    );
}

#[test]
fn crc_errors_report_reason_code_and_both_crcs() {
    // AMR: flip a payload bit; the frame's CRC field stays, the computed one changes.
    let hex = example(FrameKind::AmrCommand);
    let bad = flip(&hex, 3, 0x01);
    let e = err(FrameKind::AmrCommand, &bad);
    let b = parse_hex(&hex).unwrap();
    let carried = u16::from_be_bytes([b[62], b[63]]);
    assert!(
        e.contains("Crc") && e.contains("RejectReason wire code 1"),
        "{e}"
    );
    assert!(e.contains(&format!("carries {carried:#06x}")), "{e}");
    let computed = protocol::crc16::checksum(&parse_hex(&bad).unwrap()[..62]);
    assert!(e.contains(&format!("computed {computed:#06x}")), "{e}");
    // CDC: the golden ESTOP frame with its CRC high byte changed (dc b6 → dc b7).
    let e = err(FrameKind::Cdc, "aa55030101dcb7");
    assert!(
        e.contains("computed 0xb6dc") && e.contains("carries 0xb7dc"),
        "{e}"
    );
    assert!(
        e.contains("cdc error Crc (code 1)") && e.contains("STATUS err CrcError (1)"),
        "{e}"
    );
    // Robust Teensy: the golden frame (protocol/golden/structs_python.txt) with its last check byte
    // changed (0xf0 → 0xf1). The check bytes 83 ff f0 carry 0b11 | 1111111 | 1110000 = 0xfff0, the
    // CRC of the unchanged stuffed bytes; f1 carries 0xfff1.
    let golden =
        "020201010102010101025a010107a6ffffff0a0a0106ffffff7f1e010106c4ffffff0101010183fff000";
    let e = err(
        FrameKind::TeensyRobust,
        &golden.replace("83fff000", "83fff100"),
    );
    assert!(
        e.contains("Crc") && e.contains("computed 0xfff0") && e.contains("carries 0xfff1"),
        "{e}"
    );
    // A check byte with bit 7 clear carries no CRC at all.
    let e = err(
        FrameKind::TeensyRobust,
        &golden.replace("83fff000", "03fff000"),
    );
    assert!(
        e.contains("Crc") && e.contains("check bytes 03fff0 carry no CRC"),
        "{e}"
    );
}

#[test]
fn info_and_feedback_frames_point_to_each_other() {
    let info = example(FrameKind::AmrInfo);
    let e = err(FrameKind::AmrFeedback, &info);
    assert!(
        e.contains("Version") && e.contains("McuInfo") && e.contains("--frame amr-info"),
        "{e}"
    );
    let fb = example(FrameKind::AmrFeedback);
    let e = err(FrameKind::AmrInfo, &fb);
    assert!(
        e.contains("info_version") && e.contains("--frame amr-feedback"),
        "{e}"
    );
    let e = err(FrameKind::AmrInfo, &example(FrameKind::AmrCommand));
    assert!(e.contains("info_version") && e.contains("missing"), "{e}");
    // An undefined reset cause (9) in an otherwise valid frame.
    let mut f = [0u8; 64];
    let payload = [0x80, 0x01, 0x01, 0xA8, 0x01, 0x09];
    f[0] = payload.len() as u8;
    f[1..1 + payload.len()].copy_from_slice(&payload);
    let crc = protocol::crc16::checksum(&f[..62]);
    f[62..].copy_from_slice(&crc.to_be_bytes());
    let e = err(FrameKind::AmrInfo, &to_hex(&f));
    assert!(e.contains("Decode") && e.contains("reset_cause"), "{e}");
    let e = encode(FrameKind::AmrInfo, r#"{"board":"vax"}"#, 4).unwrap_err();
    assert!(e.contains("board") && e.contains("pi_spi"), "{e}");
}

#[test]
fn cdc_payload_errors_name_the_message() {
    let mut out = [0u8; cdc::MAX_FRAME_LEN];
    let n = cdc::encode_raw(0x42, &[1, 2], &mut out);
    let e = err(FrameKind::Cdc, &to_hex(&out[..n]));
    assert!(
        e.contains("MSG_ID 0x42 is not defined") && e.contains("Decode") && e.contains("code 3"),
        "{e}"
    );
    assert!(e.contains("cdc error UnknownMsg (code 3)"), "{e}");
    let n = cdc::encode_raw(0x01, &[0; 9], &mut out);
    let e = err(FrameKind::Cdc, &to_hex(&out[..n]));
    assert!(
        e.contains("10-byte payload, LEN says 9") && e.contains("Length"),
        "{e}"
    );
    let n = cdc::encode_raw(0x02, &[2], &mut out);
    let e = err(FrameKind::Cdc, &to_hex(&out[..n]));
    assert!(
        e.contains("value 2 is not defined") && e.contains("cdc error Value (code 4)"),
        "{e}"
    );
}

#[test]
fn cdc_capture_lists_every_frame_and_the_drop_statistics() {
    // garbage, ENABLE 1, ENABLE 0 (golden), a truncated ESTOP, PING (golden)
    let cap = "13 37 aa55020101ec81 aa55020100cd91 aa550301 aa5510007c1e aa55";
    let v: Value = serde_json::from_str(&decode(FrameKind::Cdc, cap, 4).unwrap()).unwrap();
    let r = v["results"].as_array().unwrap();
    assert_eq!(r.len(), 4, "{v}");
    assert_eq!(
        r[0],
        json!({"message": {"type": "motor_enable", "enable": true}})
    );
    assert_eq!(
        r[1],
        json!({"message": {"type": "motor_enable", "enable": false}})
    );
    // The truncated ESTOP swallows the PING's first bytes into a bad CRC; the PING is then found again.
    assert_eq!(r[2]["error"]["reason"], "Crc");
    assert_eq!(r[2]["error"]["reason_code"], 1);
    assert_eq!(r[3], json!({"message": {"type": "ping"}}));
    assert_eq!(v["stats"]["frames"], 3);
    assert_eq!(v["stats"]["crc_errors"], 1);
    // 2 garbage bytes + the broken ESTOP's 4 bytes; the trailing AA 55 waits for more.
    assert_eq!(v["stats"]["dropped_bytes"], 6);
    assert_eq!(v["incomplete_bytes"], 2);
}

#[test]
fn teensy_robust_capture_lists_every_frame() {
    let one = encode(FrameKind::TeensyRobust, r#"{"cmd_type":"cal"}"#, 2).unwrap();
    let two = encode(
        FrameKind::TeensyRobust,
        r#"{"cmd_type":"endeff_on","cmd_success":1}"#,
        2,
    )
    .unwrap();
    let bad = flip(&two, 3, 0x10);
    let cap = format!("{one}{bad}{two}0505");
    let v: Value =
        serde_json::from_str(&decode(FrameKind::TeensyRobust, &cap, 2).unwrap()).unwrap();
    let r = v["results"].as_array().unwrap();
    assert_eq!(r.len(), 3, "{v}");
    assert_eq!(r[0]["message"]["cmd_type"], "cal");
    assert!(r[1]["error"]["reason"].is_string());
    assert_eq!(r[2]["message"]["cmd_type"], "endeff_on");
    assert_eq!(v["stats"]["frames"], 2);
    assert_eq!(v["stats"]["errors"], 1);
    assert_eq!(v["incomplete_bytes"], 2);
}

#[test]
fn pi_errors_name_version_parity_and_the_undefined_field() {
    let rx = example(FrameKind::PiRx);
    let e = err(FrameKind::PiRx, &flip(&rx, 0, 0x01));
    assert!(
        e.contains("Version") && e.contains("code 4") && e.contains("transferVersion is 14"),
        "{e}"
    );
    let e = err(FrameKind::PiRx, &flip(&rx, 1, 0x02));
    assert!(
        e.contains("Parity") && e.contains("code 11") && e.contains("set bits"),
        "{e}"
    );
    // motor 0 mode 3 → 7 (undefined): bits 0..2 of offset 6
    let e = err(FrameKind::PiRx, &flip(&rx, 6, 0x04));
    assert!(
        e.contains("Decode") && e.contains("motorControlMode"),
        "{e}"
    );
    // servo 0 mode 2 → 3
    let e = err(FrameKind::PiRx, &flip(&rx, 40, 0x01));
    assert!(e.contains("servoMode") && e.contains("mode 3"), "{e}");
    let e = err(FrameKind::PiRx, &flip(&rx, 5, 0x80));
    assert!(e.contains("systemShutdown"), "{e}");
    let tx = example(FrameKind::PiTx);
    let e = err(FrameKind::PiTx, &flip(&tx, 0, 0xFF));
    assert!(
        e.contains("Version") && e.contains("transferVersion is 240"),
        "{e}"
    );
    // a whole 179-byte transfer decodes as its first 167 bytes
    assert!(decode(FrameKind::PiTx, &format!("{tx}{}", "00".repeat(12)), 4).is_ok());
}

#[test]
fn teensy_errors_name_cmd_type_version_and_delimiter() {
    let legacy = example(FrameKind::TeensyLegacy);
    let e = err(FrameKind::TeensyLegacy, &flip(&legacy, 0, 0x09));
    assert!(
        e.contains("Decode") && e.contains("cmd_type 9 is not defined"),
        "{e}"
    );
    let e = err(FrameKind::TeensyLegacy, &flip(&legacy, 36, 0x01));
    assert!(
        e.contains("Framing") && e.contains("0x0b") && e.contains("ends in 0x0a"),
        "{e}"
    );
    // Robust frame with version 3 and a correct CRC, built here from the layout: COBS of the
    // version and CmdMsg without its terminator, the CRC of those bytes in 2 + 7 + 7 bits with bit
    // 7 set, then 00.
    let msg = &parse_hex(&legacy).unwrap()[..36];
    let mut body = vec![3u8];
    body.extend_from_slice(msg);
    let mut frame = vec![0u8; corncobs::max_encoded_len(body.len())];
    let n = corncobs::encode_buf(&body, &mut frame);
    frame.truncate(n - 1);
    let crc = protocol::crc16::checksum(&frame);
    frame.extend_from_slice(&[
        0x80 | (crc >> 14) as u8,
        0x80 | ((crc >> 7) & 0x7F) as u8,
        0x80 | (crc & 0x7F) as u8,
        0,
    ]);
    let e = err(FrameKind::TeensyRobust, &to_hex(&frame));
    assert!(
        e.contains("Version") && e.contains("version byte is 3, this build speaks 2"),
        "{e}"
    );
}

#[test]
fn encode_errors_name_the_field_and_the_fix() {
    let cases: &[(FrameKind, &str, &[&str])] = &[
        (
            FrameKind::AmrCommand,
            r#"{"enable":true,"speed":1}"#,
            &["unknown field `speed`", "left_speed_cmd"],
        ),
        (
            FrameKind::AmrCommand,
            r#"{"enable":1}"#,
            &["field `enable`", "expected a boolean"],
        ),
        (
            FrameKind::AmrFeedback,
            r#"{"mode":-1}"#,
            &["field `mode`", "expected u32"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"set_motor_pwm","pwm":[1,2,"x",4]}"#,
            &["field `pwm[2]`", "expected i16"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"set_motor_pwm","pwm":[1,2,3]}"#,
            &["field `pwm`", "length 3"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"status","vbat":1}"#,
            &["unknown field `vbat`", "vbat_mv"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"estop","action":"on"}"#,
            &["field `action`", "`engage` or `release`"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"motor_enable"}"#,
            &["missing field `enable`"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"ping","x":0}"#,
            &["unknown field `x`"],
        ),
        (
            FrameKind::Cdc,
            r#"{"type":"pong"}"#,
            &["unknown message \"pong\"", "set_motor_pwm"],
        ),
        (
            FrameKind::Cdc,
            r#"{"pwm":[0,0,0,0]}"#,
            &["field `type` is missing"],
        ),
        (FrameKind::Cdc, "[1]", &["JSON object"]),
        (
            FrameKind::PiRx,
            r#"{"motor_pid_settings":{"kp":[1,"x",0,0]}}"#,
            &["field `motor_pid_settings.kp[1]`", "expected f32"],
        ),
        (
            FrameKind::PiRx,
            r#"{"servo_mode":["on","off","off","off"]}"#,
            &["field `servo_mode[0]`", "fully_disabled"],
        ),
        (
            FrameKind::PiTx,
            r#"{"imu":{"gyro":{"w":1}}}"#,
            &["unknown field `w`", "accuracy"],
        ),
        (
            FrameKind::TeensyLegacy,
            r#"{"cmd_type":"move"}"#,
            &["field `cmd_type`", "mtrs"],
        ),
        (
            FrameKind::TeensyRobust,
            r#"{"angles":[1]}"#,
            &["unknown field `angles`", "mtr_angles"],
        ),
        (
            FrameKind::AmrCommand,
            r#"{"enable":true"#,
            &["not valid JSON"],
        ),
        (FrameKind::AmrCommand, r#"{} {}"#, &["trailing characters"]),
    ];
    for (kind, json, needles) in cases {
        let e = encode(*kind, json, DEFAULT_MOTORS).unwrap_err();
        for n in *needles {
            assert!(e.contains(n), "{kind:?} {json}: `{e}` lacks `{n}`");
        }
    }
}

#[test]
fn missing_fields_encode_as_zero() {
    let full = r#"{"timestamp_us":0,"left_speed_cmd":0.0,"right_speed_cmd":0.0,"control_mode":0,"enable":false,"seq":0}"#;
    assert_eq!(
        encode(FrameKind::AmrCommand, "{}", 4).unwrap(),
        encode(FrameKind::AmrCommand, full, 4).unwrap()
    );
}

#[test]
fn no_input_makes_any_decoder_panic() {
    // A small xorshift generator: lengths around every kind's size, random and mutated content.
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let kinds = [
        FrameKind::AmrCommand,
        FrameKind::AmrFeedback,
        FrameKind::AmrInfo,
        FrameKind::Cdc,
        FrameKind::PiRx,
        FrameKind::PiTx,
        FrameKind::TeensyLegacy,
        FrameKind::TeensyRobust,
    ];
    let seeds: Vec<Vec<u8>> = examples()
        .into_iter()
        .map(|(k, j)| parse_hex(&encode(k, j, 4).unwrap()).unwrap())
        .collect();
    for i in 0..3000 {
        let mut bytes = if i % 2 == 0 {
            seeds[(next() % seeds.len() as u64) as usize].clone()
        } else {
            (0..next() % 200).map(|_| next() as u8).collect()
        };
        if !bytes.is_empty() {
            let at = (next() % bytes.len() as u64) as usize;
            bytes[at] ^= 1 << (next() % 8);
        }
        if next() % 4 == 0 {
            bytes.truncate((next() % (bytes.len() as u64 + 1)) as usize);
        }
        let hex = to_hex(&bytes);
        for kind in kinds {
            let motors = [1usize, 4, 8, 0, 17][(next() % 5) as usize];
            let _ = decode(kind, &hex, motors);
        }
    }
}

// ---- motorlink info: McuInfo from a capture and from a (simulated) live link ----

mod info_cmd {
    use super::*;
    use crate::cli::info::{info_capture_file, info_live, query_info, scan_capture, QueryError};
    use crate::transport::{LinkError, Transport};
    use protocol::amr::{
        BoardProfile, McuInfo, MotorFeedback, ResetCause, FRAME_LEN, REQUEST_IDENTITY,
    };
    use statemachine::validate::seq_is_newer;

    fn identity() -> McuInfo {
        McuInfo {
            fw_version: amr::pack_fw_version(1, 4, 2),
            git_hash: 0x8624_B25F,
            board: BoardProfile::AmrSpi,
            build_date: 20_261_130,
            reset_cause: ResetCause::IndependentWatchdog,
            reset_count: 3,
            panic_line: 0,
            seq: 1042,
            dirty: true,
        }
    }

    fn feedback_frame(seq: u32) -> [u8; FRAME_LEN] {
        let mut f = [0u8; FRAME_LEN];
        let fb = MotorFeedback {
            timestamp_us: seq * 1000,
            left_speed: -2.0,
            left_current: -3.25,
            seq,
            cmd_seq: seq - 1,
            ..MotorFeedback::default()
        };
        amr::encode_feedback(&fb, &mut f);
        f
    }

    /// Feedback 1040, 1041, the info frame (seq 1042), a corrupted feedback, feedback 1044, and
    /// 10 stray bytes: what a logic analyser gives while the host asks once.
    fn capture() -> Vec<u8> {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&feedback_frame(1040));
        bytes.extend_from_slice(&feedback_frame(1041));
        let mut info = [0u8; FRAME_LEN];
        amr::encode_info(&identity(), &mut info);
        bytes.extend_from_slice(&info);
        let mut bad = feedback_frame(1043);
        bad[9] ^= 0x04;
        bytes.extend_from_slice(&bad);
        bytes.extend_from_slice(&feedback_frame(1044));
        bytes.extend_from_slice(&[0xAB; 10]);
        bytes
    }

    fn write_temp(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let path =
            std::env::temp_dir().join(format!("motorlink-info-{}-{name}.bin", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn a_capture_file_prints_the_identity_in_human_form() {
        let path = write_temp("human", &capture());
        let text = info_capture_file(&path, false).unwrap();
        std::fs::remove_file(&path).unwrap();
        for needle in [
            "McuInfo at frame 2",
            "firmware     1.4.2 (git 8624b25f, built from a tree with uncommitted changes)",
            "board        AmrSpi (AMR SPI link, Jetson)",
            "built        2026-11-30",
            "reset cause  IndependentWatchdog (code 3)",
            "resets       3 since power-on",
            "last panic   none recorded",
            "seq          1042",
            "capture: 5 frames of 64 bytes: 3 feedback, 1 McuInfo, refused: 1 Crc, 10 bytes after the last whole frame",
        ] {
            assert!(text.contains(needle), "`{needle}` missing from:\n{text}");
        }
    }

    #[test]
    fn a_capture_file_prints_the_identity_as_json() {
        let path = write_temp("json", &capture());
        let text = info_capture_file(&path, true).unwrap();
        std::fs::remove_file(&path).unwrap();
        let v: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["frames"], 5);
        assert_eq!(v["feedback"], 3);
        assert_eq!(v["info"], 1);
        assert_eq!(v["refused"], json!({"Crc": 1}));
        assert_eq!(v["trailing_bytes"], 10);
        let ids = v["identities"].as_array().unwrap();
        assert_eq!(ids.len(), 1);
        let id = &ids[0];
        assert_eq!(id["frame"], 2);
        assert_eq!(id["fw_version"], "1.4.2");
        assert_eq!(id["fw_version_raw"], 0x0001_0402);
        assert_eq!(id["git_hash"], "8624b25f");
        assert_eq!(id["dirty"], true);
        assert_eq!(id["board"], "amr_spi");
        assert_eq!(id["build_date"], "2026-11-30");
        assert_eq!(id["reset_cause"], "independent_watchdog");
        assert_eq!(id["reset_cause_code"], 3);
        assert_eq!(id["reset_count"], 3);
        assert_eq!(id["panic_line"], Value::Null);
        assert_eq!(id["seq"], 1042);
    }

    #[test]
    fn a_reset_during_the_capture_shows_as_a_second_identity() {
        let mut bytes = capture();
        bytes.truncate(5 * FRAME_LEN);
        let mut f = [0u8; FRAME_LEN];
        amr::encode_info(
            &McuInfo {
                seq: 1045,
                ..identity()
            },
            &mut f,
        );
        bytes.extend_from_slice(&f); // the same identity again: counted, not repeated
        let panic = McuInfo {
            reset_cause: ResetCause::Panic,
            reset_count: 4,
            panic_line: 212,
            seq: 1,
            git_hash: 0,
            ..identity()
        };
        amr::encode_info(&panic, &mut f);
        bytes.extend_from_slice(&f);
        let scan = scan_capture(&bytes);
        assert_eq!(scan.info, 3);
        assert_eq!(scan.identities.len(), 2);
        assert_eq!(scan.identities[0].frames, 2);
        assert_eq!(scan.identities[1].frame, 6);
        assert_eq!(scan.identities[1].panic_line, Some(212));
        assert_eq!(scan.identities[1].git_hash, None);
        let path = write_temp("reset", &bytes);
        let text = info_capture_file(&path, false).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert!(
            text.contains("McuInfo at frame 2, and 1 more like it"),
            "{text}"
        );
        assert!(text.contains("reset cause  Panic (code 4)"), "{text}");
        assert!(text.contains("last panic   at line 212"), "{text}");
        assert!(text.contains("git hash unknown"), "{text}");
        assert!(text.contains("the MCU reset or was reflashed"), "{text}");
    }

    #[test]
    fn a_capture_without_an_info_frame_is_an_error_that_says_what_it_held() {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&feedback_frame(7));
        bytes.extend_from_slice(&[0u8; FRAME_LEN]);
        let path = write_temp("none", &bytes);
        let e = info_capture_file(&path, false).unwrap_err();
        std::fs::remove_file(&path).unwrap();
        assert!(e.contains("no McuInfo frame in"), "{e}");
        assert!(
            e.contains("2 frames of 64 bytes: 1 feedback, 0 McuInfo, refused: 1 Crc"),
            "{e}"
        );
        assert!(e.contains("request = 1"), "{e}");
        // Too short for a frame.
        let e = crate::cli::info::info_capture("tiny.bin", &[1, 2, 3], false).unwrap_err();
        assert!(e.contains("no whole 64-byte frame (3 bytes)"), "{e}");
        // A missing file.
        let e =
            info_capture_file(std::path::Path::new("/nonexistent/capture.bin"), false).unwrap_err();
        assert!(e.contains("cannot read /nonexistent/capture.bin"), "{e}");
    }

    #[test]
    fn a_misaligned_capture_names_the_offset_to_drop() {
        let mut bytes = vec![0x55; 7];
        bytes.extend_from_slice(&capture());
        let e = crate::cli::info::info_capture("shifted.bin", &bytes, false).unwrap_err();
        assert!(e.contains("drop its first 7 bytes"), "{e}");
    }

    /// An MCU as the firmware behaves on the link: the frame it returns was prepared after the
    /// previous exchange; a command is accepted only with a newer `seq`, and an accepted command
    /// with `request` = 1 makes the next frame an `McuInfo` (if the firmware knows the request).
    struct FakeMcu {
        accepted: u32,
        fb_seq: u32,
        info_next: bool,
        knows_identity: bool,
        commands: Vec<amr::MotorCommand>,
    }

    impl FakeMcu {
        fn new(accepted: u32, knows_identity: bool) -> Self {
            Self {
                accepted,
                fb_seq: 1040,
                info_next: false,
                knows_identity,
                commands: Vec::new(),
            }
        }
    }

    impl Transport for FakeMcu {
        fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
            self.fb_seq += 1;
            let mut out = [0u8; FRAME_LEN];
            if self.info_next {
                let info = McuInfo {
                    seq: self.fb_seq,
                    ..identity()
                };
                amr::encode_info(&info, &mut out);
            } else {
                let mut f = feedback_frame(self.fb_seq);
                let mut fb = amr::decode_feedback(&f).unwrap();
                fb.cmd_seq = self.accepted;
                amr::encode_feedback(&fb, &mut f);
                out = f;
            }
            rx.copy_from_slice(&out);
            self.info_next = false;
            let cmd = amr::decode_command(tx.try_into().unwrap()).unwrap();
            self.commands.push(cmd);
            if seq_is_newer(cmd.seq, self.accepted) {
                self.accepted = cmd.seq;
                self.info_next = self.knows_identity && cmd.request == REQUEST_IDENTITY;
            }
            Ok(())
        }

        fn name(&self) -> &str {
            "fake-mcu"
        }
    }

    #[test]
    fn live_query_moves_past_a_stale_seq_and_reads_the_answer() {
        // The MCU last accepted seq 5000; the query starts at 10, which it refuses as stale.
        let mut mcu = FakeMcu::new(5000, true);
        let mut paced = 0;
        let (id, log) = query_info(&mut mcu, 10, 50, || {
            paced += 1;
            paced * 1000
        })
        .unwrap();
        assert_eq!(id.fw_version, "1.4.2");
        assert_eq!(id.reset_cause, ResetCause::IndependentWatchdog);
        assert_eq!(id.seq, 1043);
        // 10 refused as stale, 5001 accepted with the request, the answer on the next exchange.
        assert_eq!(log.exchanges, 3);
        assert_eq!(paced, 3);
        assert_eq!(log.feedback, 2);
        let seqs: Vec<u32> = mcu.commands.iter().map(|c| c.seq).collect();
        assert_eq!(seqs, [10, 5001, 5002]);
        // Every command asks, with the drive disabled.
        for c in &mcu.commands {
            assert_eq!(c.request, REQUEST_IDENTITY);
            assert!(!c.enable);
            assert_eq!(
                (c.left_speed_cmd, c.right_speed_cmd, c.control_mode),
                (0.0, 0.0, 0)
            );
        }
        let mut mcu = FakeMcu::new(0, true);
        let text = info_live(&mut mcu, 1, 50, true, || 0).unwrap();
        let v: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["device"], "fake-mcu");
        assert_eq!(v["identity"]["git_hash"], "8624b25f");
        assert_eq!(v["query"]["exchanges"], 2);
    }

    #[test]
    fn live_query_times_out_with_what_came_back() {
        let mut old_firmware = FakeMcu::new(0, false);
        let e = info_live(&mut old_firmware, 1, 20, false, || 0).unwrap_err();
        assert!(
            e.contains("no McuInfo from fake-mcu in 20 exchanges: 20 feedback")
                && e.contains("does not know the identity request"),
            "{e}"
        );
        let mut silent = crate::transport::NullTransport {
            reply: vec![0; FRAME_LEN],
        };
        let e = info_live(&mut silent, 1, 20, false, || 0).unwrap_err();
        assert!(
            e.contains("0 feedback, refused: 20 Crc") && e.contains("check the wiring"),
            "{e}"
        );
        struct Broken;
        impl Transport for Broken {
            fn exchange(&mut self, _: &[u8], _: &mut [u8]) -> Result<(), LinkError> {
                Err(LinkError::Timeout("broken".into(), 0))
            }
            fn name(&self) -> &str {
                "broken"
            }
        }
        assert!(matches!(
            query_info(&mut Broken, 1, 5, || 0),
            Err(QueryError::Transport(m)) if m.contains("broken")
        ));
    }
}
