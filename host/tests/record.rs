//! `motorlink record --sim` as a separate process: the MCAP file read back with the `mcap` crate's
//! reader (topics, encodings, schemas, counts, the raw frames decoded), the CSV file's rows, a
//! recording's determinism, and the arguments refused before anything runs.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;

use protocol::amr::{self, McuFrame};

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("motorlink-record-{}-{name}", std::process::id()))
}

/// Runs `motorlink record` with `args`; (exit code, stdout, stderr).
fn record(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .arg("record")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_simulated_recording_reads_back_as_ros2_mcap() {
    let path = tmp("sim.mcap");
    let p = path.to_str().unwrap();
    let (code, stdout, stderr) = record(&["--sim", "--seconds", "2", "--v", "0.3", "--out", p]);
    assert_eq!(code, 0, "{stderr}");
    let last: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(last["exchanges"], 2000);
    let bytes = std::fs::read(&path).unwrap();

    // 2 s at one exchange per board millisecond, a feedback in each: 2000 on every per-exchange
    // topic, and a /diagnostics every 100 exchanges.
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let mut last_frame = None;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let ch = &m.channel;
        *counts.entry(ch.topic.clone()).or_default() += 1;
        if ch.topic == "/motorlink/frames" {
            assert!(ch.schema.is_none());
            assert_eq!(ch.message_encoding, "json");
            last_frame = Some(m.data.into_owned());
        } else {
            let s = ch.schema.as_ref().unwrap();
            assert_eq!(s.encoding, "ros2msg");
            assert_eq!(ch.message_encoding, "cdr");
            let want = match ch.topic.as_str() {
                "/cmd_vel" => "geometry_msgs/msg/Twist",
                "/odom" => "nav_msgs/msg/Odometry",
                "/joint_states" => "sensor_msgs/msg/JointState",
                "/diagnostics" => "diagnostic_msgs/msg/DiagnosticArray",
                t => panic!("unexpected topic {t}"),
            };
            assert_eq!(s.name, want);
            // Every message starts with the little-endian CDR encapsulation header.
            assert_eq!(m.data[..4], [0, 1, 0, 0]);
        }
    }
    let want: BTreeMap<String, u64> = [
        ("/cmd_vel", 2000),
        ("/diagnostics", 20),
        ("/joint_states", 2000),
        ("/motorlink/frames", 2000),
        ("/odom", 2000),
    ]
    .into_iter()
    .map(|(t, n)| (t.to_string(), n))
    .collect();
    assert_eq!(counts, want);
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.unwrap().message_count, 8020);

    // The last raw frames: the MCU's feedback decodes, NORMAL, the robot's wheels turning forward
    // at about 0.3 / 0.08 = 3.75 rad/s (the estimate moves in steps of 0.96 rad/s).
    let f: serde_json::Value = serde_json::from_slice(&last_frame.unwrap()).unwrap();
    assert_eq!(f["index"], 1999);
    let rx: Vec<u8> = (0..64)
        .map(|k| u8::from_str_radix(&f["rx"].as_str().unwrap()[2 * k..2 * k + 2], 16).unwrap())
        .collect();
    let Ok(McuFrame::Feedback(fb)) = amr::decode_mcu_frame(rx.as_slice().try_into().unwrap())
    else {
        panic!("no feedback in {f}");
    };
    assert_eq!(fb.mode, 0);
    assert!((f64::from(fb.left_speed) - 3.75).abs() < 1.0, "{fb:?}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn simulated_recordings_are_identical() {
    let (a, b) = (tmp("a.mcap"), tmp("b.mcap"));
    for p in [&a, &b] {
        let args = ["--sim", "--seconds", "0.5", "--v", "-0.2", "--w", "0.4"];
        let (code, _, e) = record(&[&args[..], &["--out", p.to_str().unwrap()]].concat());
        assert_eq!(code, 0, "{e}");
    }
    let (x, y) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert!(x.len() > 100_000);
    assert!(x == y, "two lockstep recordings differ");
    std::fs::remove_file(&a).ok();
    std::fs::remove_file(&b).ok();
}

#[test]
fn a_csv_recording_has_one_row_per_exchange() {
    let path = tmp("sim.csv");
    let p = path.to_str().unwrap();
    let (code, _, stderr) = record(&["--sim", "--seconds", "2", "--v", "0.3", "--out", p]);
    assert_eq!(code, 0, "{stderr}");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2000);
    assert!(rows.iter().all(|r| r.len() == header.len()));
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let num = |r: &Vec<&str>, name: &str| r[col(name)].parse::<f64>().unwrap();
    // One board millisecond between exchanges.
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(num(r, "index"), k as f64);
        assert_eq!(num(r, "t_send_us"), 1000.0 * k as f64);
    }
    // Starts braked (power-on latch), ends armed and NORMAL.
    assert_eq!(rows[0][col("mode_name")], "BRAKE");
    assert!(rows[0][col("faults")].contains("POWER_ON"));
    let last = rows.last().unwrap();
    assert_eq!(last[col("mode_name")], "NORMAL");
    assert_eq!(last[col("arm_state")], "Armed");
    // The host's odometry follows the plant's ground truth: within 1 cm after 0.58 m.
    let (x, truth) = (num(last, "odom_x"), num(last, "truth_x"));
    assert!(x > 0.45 && (x - truth).abs() < 0.01, "{x} vs {truth}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn bad_arguments_are_refused_before_anything_runs() {
    let bag = tmp("x.bag");
    for (args, says) in [
        (
            vec!["--sim", "--out", bag.to_str().unwrap()],
            ".mcap (ROS 2 messages) or .csv",
        ),
        (vec!["--out", "x.csv"], "or --sim"),
        (
            vec!["/dev/spidev9.9", "--sim", "--out", "x.csv"],
            "not both",
        ),
        (
            vec!["--sim", "--seconds", "-1", "--out", "x.csv"],
            "--seconds -1",
        ),
    ] {
        let (code, _, stderr) = record(&args);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    assert!(!bag.exists());
    assert!(!std::path::Path::new("x.csv").exists());
}

#[test]
fn ctrl_c_ends_a_recording_with_a_complete_file() {
    use nix::sys::signal::{kill, Signal};
    use nix::unistd::Pid;
    let path = tmp("interrupted.mcap");
    let child = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .args([
            "record",
            "--sim",
            "--seconds",
            "3600",
            "--v",
            "0.2",
            "--out",
        ])
        .arg(&path)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The file is created after the signals are taken over: from then on SIGINT is a request.
    while !path.exists() {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{out:?}");
    let last: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap();
    let n = last["exchanges"].as_u64().unwrap();
    assert!(n < 3_600_000, "{last}");
    // A complete file: its summary section counts what the process said it wrote.
    let bytes = std::fs::read(&path).unwrap();
    let stats = mcap::Summary::read(&bytes).unwrap().unwrap().stats.unwrap();
    let per_exchange = 4 * n + n / 100;
    assert_eq!(stats.message_count, per_exchange, "{last}");
    std::fs::remove_file(&path).ok();
}
