//! Writes Rust-encoded frames for every golden case, for the Python and nanopb checkers:
//! `cargo run -p protocol --example golden_emit -- OUT_DIR` (see `protocol/golden/run.sh`).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use protocol::amr::{
    self, BoardProfile, McuInfo, MotorCommand, MotorFeedback, ResetCause, FRAME_LEN,
};
use std::collections::HashMap;

#[path = "../tests/common/structs.rs"]
mod structs;
use std::fmt::Write as _;

fn kv(line: &str) -> (&str, HashMap<&str, i64>) {
    let mut it = line.split_whitespace();
    let kind = it.next().unwrap();
    let map = it
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap();
            (k, v.parse().unwrap())
        })
        .collect();
    (kind, map)
}

fn hex(frame: &[u8]) -> String {
    frame.iter().fold(String::new(), |mut s, b| {
        write!(s, "{b:02x}").unwrap();
        s
    })
}

fn amr_frames(cases: &str) -> String {
    let mut out = String::new();
    for line in cases.lines() {
        let (kind, m) = kv(line);
        let u = |k: &str| m[k] as u32;
        let f = |k: &str| f32::from_bits(m[k] as u32);
        let mut frame = [0u8; FRAME_LEN];
        match kind {
            "command" => amr::encode_command(
                &MotorCommand {
                    timestamp_us: u("timestamp_us"),
                    left_speed_cmd: f("left_speed_cmd"),
                    right_speed_cmd: f("right_speed_cmd"),
                    control_mode: u("control_mode"),
                    enable: m["enable"] == 1,
                    seq: u("seq"),
                    request: u("request"),
                },
                &mut frame,
            ),
            "info" => amr::encode_info(
                &McuInfo {
                    fw_version: u("fw_version"),
                    git_hash: u("git_hash"),
                    board: BoardProfile::from_wire(u("board")).expect("a defined board"),
                    build_date: u("build_date"),
                    reset_cause: ResetCause::from_wire(u("reset_cause"))
                        .expect("a defined reset cause"),
                    reset_count: u("reset_count"),
                    panic_line: u("panic_line"),
                    seq: u("seq"),
                    dirty: m["dirty"] == 1,
                },
                &mut frame,
            ),
            _ => amr::encode_feedback(
                &MotorFeedback {
                    timestamp_us: u("timestamp_us"),
                    left_speed: f("left_speed"),
                    right_speed: f("right_speed"),
                    left_current: f("left_current"),
                    right_current: f("right_current"),
                    left_encoder: m["left_encoder"] as i32,
                    right_encoder: m["right_encoder"] as i32,
                    fault_flags: u("fault_flags"),
                    seq: u("seq"),
                    mode: u("mode"),
                    cmd_seq: u("cmd_seq"),
                },
                &mut frame,
            ),
        }
        writeln!(out, "{kind} {}", hex(&frame)).unwrap();
    }
    out
}

fn main() {
    let dir = std::env::args().nth(1).expect("usage: golden_emit OUT_DIR");
    let dir = std::path::Path::new(&dir);
    let cases = include_str!("../golden/amr_cases.txt");
    std::fs::write(dir.join("amr_rust.txt"), amr_frames(cases)).unwrap();
    let mut out = String::new();
    for c in structs::parse(include_str!("../golden/structs_python.txt")) {
        writeln!(out, "{} {}", c.kind, hex(&structs::encode(&c))).unwrap();
    }
    std::fs::write(dir.join("structs_rust.txt"), out).unwrap();
    println!("golden_emit: wrote Rust frames to {}", dir.display());
}
