//! `motorlink` itself for seed 004 (`--kind pi-spi`): the help text documents the verbs, bad
//! arguments are refused (exit 64) before the device is opened, and a missing device exits 69.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::process::Command;

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

#[test]
fn help_documents_the_pi_spi_verbs() {
    let (code, top, _) = motorlink(&["--help"]);
    assert_eq!(code, 0);
    assert!(top.contains("Raspberry Pi SPI link"), "{top}");
    for verb in ["ping", "monitor", "drive"] {
        let (code, help, _) = motorlink(&[verb, "--help"]);
        assert_eq!(code, 0);
        assert!(help.contains("pi-spi"), "{verb} --help: {help}");
    }
    let (_, drive, _) = motorlink(&["drive", "--help"]);
    for flag in [
        "--modes",
        "--targets",
        "--goals",
        "--servo-modes",
        "--servo-pos",
        "--odom-reset",
        "--kinematics",
        "--pid-speed",
        "--every",
        "--duration",
        "600..=2600",
        "both shutdown bits",
        "no_reply",
        "refused",
    ] {
        assert!(drive.contains(flag), "drive --help lacks {flag}");
    }
    let (_, ping, _) = motorlink(&["ping", "--help"]);
    assert!(ping.contains("stale"));
    let (_, monitor, _) = motorlink(&["monitor", "--help"]);
    assert!(monitor.contains("--count") && monitor.contains("--hz"));
}

#[test]
fn bad_pi_spi_arguments_exit_64_before_the_device_is_opened() {
    // The device does not exist: the argument error comes first, so nothing was opened.
    let dev = "/nonexistent/spidev9.9";
    for (args, want) in [
        (
            vec!["--servo-modes", "enabled", "--servo-pos", "2601"],
            "600..=2600",
        ),
        (vec!["--modes", "pwm", "--targets", "400"], "-399..=399"),
        (vec!["--pwm", "1,2,3,4"], "--modes pwm --targets"),
        (vec!["--hz", "10"], "above 20.4"),
    ] {
        let mut all = vec!["drive", dev, "--kind", "pi-spi"];
        all.extend(args);
        let (code, out, err) = motorlink(&all);
        assert_eq!(code, 64, "{all:?}: {err}");
        assert!(out.is_empty(), "nothing printed: {out}");
        assert!(err.contains(want), "{all:?}: {err}");
        assert!(!err.contains("cannot open"), "{err}");
    }
    // A missing device is an open error, exit 69.
    let (code, _, err) = motorlink(&["drive", dev, "--kind", "pi-spi", "--modes", "off"]);
    assert_eq!(code, 69);
    assert!(err.contains("cannot open"), "{err}");
    let (code, _, err) = motorlink(&["ping", dev, "--kind", "pi-spi"]);
    assert_eq!(code, 69);
    assert!(err.contains("cannot open"), "{err}");
}

#[test]
fn the_other_kinds_keep_their_arguments() {
    let dev = "/nonexistent/ttyACM9";
    // Seed 004 options on a seed 001 drive, and a seed 001 drive without --pwm, are refused.
    let (code, _, err) = motorlink(&["drive", dev, "--pwm", "0,0,0,0", "--modes", "pwm"]);
    assert_eq!(code, 64);
    assert!(
        err.contains("--modes is an option of drive --kind pi-spi"),
        "{err}"
    );
    let (code, _, err) = motorlink(&["drive", dev]);
    assert_eq!(code, 64);
    assert!(err.contains("needs --pwm"), "{err}");
    // Verbs seed 004 does not have name the ones it has.
    let (code, _, err) = motorlink(&["enable", "on", dev, "--kind", "pi-spi"]);
    assert_eq!(code, 64);
    assert!(err.contains("ping, monitor and drive"), "{err}");
    let (code, _, err) = motorlink(&["monitor", dev, "--kind", "serial", "--hz", "10"]);
    assert_eq!(code, 64);
    assert!(err.contains("--kind pi-spi"), "{err}");
}
