//! The exit status of `motorlink`, one per kind of outcome (sysexits-style, see `motorlink --help`
//! and host/README.md): each case here runs the binary as a script would and checks the status.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use std::os::fd::AsFd;
use std::process::Command;

/// The table's values, written out here independently of the code under test.
const OK: i32 = 0;
const FAILED: i32 = 1;
const USAGE: i32 = 64;
const DATA: i32 = 65;
const NO_INPUT: i32 = 66;
const UNAVAILABLE: i32 = 69;
const IO: i32 = 74;
const TEMPORARY: i32 = 75;

fn motorlink(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn code(args: &[&str]) -> i32 {
    motorlink(args).0
}

#[test]
fn help_lists_the_table() {
    let (c, help, _) = motorlink(&["--help"]);
    assert_eq!(c, OK);
    for n in ["64", "65", "66", "69", "74", "75"] {
        assert!(help.contains(n), "--help lacks exit status {n}");
    }
}

#[test]
fn usage_errors_exit_64() {
    assert_eq!(code(&["no-such-verb"]), USAGE);
    assert_eq!(code(&["decode"]), USAGE, "missing arguments (clap)");
    assert_eq!(code(&["decode", "--frame", "nope", "00"]), USAGE);
    assert_eq!(code(&["loop-bench", "--seconds", "0"]), USAGE);
    assert_eq!(
        code(&["decode", "--frame", "teensy-robust", "--motors", "17", "00"]),
        USAGE
    );
    // A bad argument of a board verb: refused before the (missing) device is opened.
    assert_eq!(
        code(&["drive", "/nonexistent/ttyACM9", "--pwm", "2000,0,0,0"]),
        USAGE
    );
    assert_eq!(
        code(&["sim", "nominal", "--duration", "0", "--no-plots"]),
        USAGE
    );
    // Real-time options: a priority SCHED_FIFO does not have, a CPU this machine does not have,
    // and --rt on a link without a 1 kHz loop.
    assert_eq!(
        code(&[
            "loop-bench",
            "--seconds",
            "0.01",
            "--rt",
            "--rt-priority",
            "0"
        ]),
        USAGE
    );
    assert_eq!(
        code(&["loop-bench", "--seconds", "0.01", "--cpu", "100000"]),
        USAGE
    );
    assert_eq!(
        code(&[
            "monitor",
            "/nonexistent/ttyACM9",
            "--kind",
            "serial",
            "--rt"
        ]),
        USAGE
    );
}

#[test]
fn loop_bench_without_python_exits_69() {
    assert_eq!(
        code(&[
            "loop-bench",
            "--seconds",
            "0.01",
            "--python",
            "/nonexistent/python3"
        ]),
        UNAVAILABLE
    );
}

#[test]
fn refused_data_exits_65() {
    // ESTOP engage with its CRC's high byte changed.
    assert_eq!(code(&["decode", "--frame", "cdc", "aa55030101dcb7"]), DATA);
    assert_eq!(code(&["decode", "--frame", "cdc", "zz"]), DATA);
    assert_eq!(
        code(&["encode", "--frame", "cdc", r#"{"type":"nope"}"#]),
        DATA
    );
    assert_eq!(
        code(&[
            "encode",
            "--frame",
            "amr-command",
            r#"{"left_speed_cmd":1e40}"#
        ]),
        DATA
    );
}

#[test]
fn a_missing_input_file_exits_66() {
    assert_eq!(
        code(&["info", "--capture", "/nonexistent/capture.bin"]),
        NO_INPUT
    );
    assert_eq!(
        code(&["sim", "/nonexistent/scenario.toml", "--no-plots"]),
        NO_INPUT
    );
}

#[test]
fn a_missing_device_exits_69() {
    let dev = "/nonexistent/ttyACM9";
    assert_eq!(code(&["ping", dev, "--kind", "serial"]), UNAVAILABLE);
    assert_eq!(code(&["enable", "on", dev]), UNAVAILABLE);
    assert_eq!(
        code(&["monitor", "/nonexistent/spidev9.9", "--seconds", "0.1"]),
        UNAVAILABLE
    );
}

#[test]
fn no_reply_exits_69() {
    let p = nix::pty::openpty(None, None).unwrap();
    let path = nix::unistd::ttyname(p.slave.as_fd()).unwrap();
    let path = path.to_str().unwrap();
    assert_eq!(
        code(&[
            "ping",
            path,
            "--kind",
            "serial",
            "--count",
            "1",
            "--wait-ms",
            "50"
        ]),
        UNAVAILABLE
    );
    drop(p);
}

#[test]
fn a_silent_port_exits_75() {
    let p = nix::pty::openpty(None, None).unwrap();
    let path = nix::unistd::ttyname(p.slave.as_fd()).unwrap();
    let path = path.to_str().unwrap();
    for kind in ["serial", "teensy"] {
        assert_eq!(
            code(&["monitor", path, "--kind", kind, "--seconds", "0.2"]),
            TEMPORARY
        );
    }
    drop(p);
}

#[test]
fn an_output_that_cannot_be_written_exits_74() {
    assert_eq!(
        code(&[
            "sim",
            "nominal",
            "--duration",
            "0.05",
            "--no-plots",
            "--out",
            "/proc/motorlink-out"
        ]),
        IO
    );
}

#[test]
fn a_failed_check_exits_1() {
    let dir = std::env::temp_dir().join(format!("motorlink-exit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("fails.toml");
    // Right after arming the ladder is not NORMAL yet: this expectation fails.
    std::fs::write(
        &file,
        "name = \"fails\"\nduration_s = 0.05\n[expect]\nfinal_mode = \"BRAKE\"\n",
    )
    .unwrap();
    let out = dir.join("out");
    assert_eq!(
        code(&[
            "sim",
            file.to_str().unwrap(),
            "--no-plots",
            "--out",
            out.to_str().unwrap()
        ]),
        FAILED
    );
    let _ = std::fs::remove_dir_all(&dir);
}
