//! `motorlink` as a separate process: what it refuses, what it says on stderr and that it exits
//! non-zero when it has nothing to show (a capture without a frame, a silent port), numbers the
//! frame formats cannot carry, the range of `--motors`, reading from standard input, and the words
//! its help uses for the links and the faults.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use std::fs::File;
use std::io::Write as _;
use std::os::fd::{AsFd, OwnedFd};
use std::process::{Command, Stdio};

/// Runs the binary with `args` (and `stdin` on its standard input): exit status, stdout, stderr.
fn run(args: &[&str], stdin: Option<&str>) -> (i32, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .args(args)
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    if let Some(text) = stdin {
        child
            .stdin
            .take()
            .unwrap()
            .write_all(text.as_bytes())
            .unwrap();
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn motorlink(args: &[&str]) -> (i32, String, String) {
    run(args, None)
}

/// A seed 001 frame in hex, built by the encoder under test's sibling verb.
fn cdc_hex(json: &str) -> String {
    let (code, out, err) = motorlink(&["encode", "--frame", "cdc", json]);
    assert_eq!(code, 0, "{err}");
    out.trim().to_string()
}

/// Flips the last hex digit (the CRC's high byte): a frame the decoder refuses.
fn broken(hex: &str) -> String {
    let mut s = hex.to_string();
    let last = s.pop().unwrap();
    s.push(if last == '0' { '1' } else { '0' });
    s
}

#[test]
fn a_cdc_capture_without_a_frame_exits_non_zero_and_says_so() {
    // Two frames whose CRC is broken: the decoder resynchronises, refuses both, decodes none.
    let a = broken(&cdc_hex(r#"{"type":"ping"}"#));
    let b = broken(&cdc_hex(r#"{"type":"estop","action":"engage"}"#));
    let (code, _, err) = motorlink(&["decode", "--frame", "cdc", &format!("{a}{b}")]);
    assert_ne!(code, 0, "a capture with no frame must not pass");
    assert!(err.contains("no frame"), "stderr: {err}");
    // One good frame among them: a capture that did yield a frame passes.
    let good = cdc_hex(r#"{"type":"ping"}"#);
    let (code, out, err) = motorlink(&["decode", "--frame", "cdc", &format!("{a}{good}{b}")]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("\"ping\""), "{out}");
}

#[test]
fn a_teensy_capture_without_a_frame_exits_non_zero_and_says_so() {
    // Two delimiters and garbage between them: nothing that decodes as a 4-motor CmdMsg.
    let (code, _, err) = motorlink(&["decode", "--frame", "teensy-robust", "0102030004050600"]);
    assert_ne!(code, 0);
    assert!(err.contains("no frame"), "stderr: {err}");
}

#[test]
fn encode_refuses_numbers_beyond_f32() {
    // 1e40 is finite as f64 but above f32::MAX (3.4e38): it would become +Inf on the wire.
    for (kind, json) in [
        ("amr-command", r#"{"left_speed_cmd":1e40}"#),
        ("amr-feedback", r#"{"right_current":-1e39}"#),
        ("pi-tx", r#"{"imu":{"heading":1e300}}"#),
    ] {
        let (code, out, err) = motorlink(&["encode", "--frame", kind, json]);
        assert_ne!(code, 0, "{kind} {json} encoded to {out}");
        assert!(out.is_empty(), "nothing may be printed: {out}");
        assert!(err.contains("finite"), "{kind}: {err}");
    }
    // The largest f32 itself is fine.
    let (code, _, err) = motorlink(&[
        "encode",
        "--frame",
        "amr-command",
        r#"{"left_speed_cmd":3.4028235e38}"#,
    ]);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn teensy_motor_counts_follow_the_help() {
    let (_, help, _) = motorlink(&["monitor", "--help"]);
    assert!(help.contains("1 to 16"), "{help}");
    // 5 joints is in the range the help gives: refused only because the device does not exist.
    let dev = "/nonexistent/ttyACM9";
    let (code, _, err) = motorlink(&[
        "monitor",
        dev,
        "--kind",
        "teensy",
        "--motors",
        "5",
        "--seconds",
        "0.1",
    ]);
    assert_ne!(code, 0);
    assert!(err.contains(dev), "{err}");
    assert!(!err.contains("monitor supports"), "{err}");
    // 17 is beyond the protocol's limit: refused before the device is opened, naming the range.
    let (code, _, err) = motorlink(&["monitor", dev, "--kind", "teensy", "--motors", "17"]);
    assert_ne!(code, 0);
    assert!(err.contains("1 to 16"), "{err}");
    assert!(!err.contains(dev), "{err}");
}

#[test]
fn loop_bench_refuses_a_zero_or_non_finite_duration() {
    for s in ["0", "-1", "NaN", "inf"] {
        let (code, out, err) = motorlink(&["loop-bench", "--seconds", s]);
        assert_ne!(code, 0, "--seconds {s}: {out}");
        assert!(!out.contains("NaN") && !out.contains("inf"), "{out}");
        assert!(err.contains("--seconds"), "{err}");
    }
}

#[test]
fn decode_dash_reads_standard_input() {
    let hex = cdc_hex(r#"{"type":"estop","action":"engage"}"#);
    let (code, out, err) = run(
        &["decode", "--frame", "cdc", "-"],
        Some(&format!("{hex}\n")),
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("\"engage\""), "{out}");
    // A capture over several lines, as a logic analyser exports it.
    let ping = cdc_hex(r#"{"type":"ping"}"#);
    let text = format!("{hex}\n{ping}\n");
    let (code, out, err) = run(&["decode", "--frame", "cdc", "-"], Some(&text));
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("\"ping\"") && out.contains("\"engage\""),
        "{out}"
    );
}

/// A pty pair: the master end and the slave's device path; the slave fd is held open.
fn pty() -> (File, String, OwnedFd) {
    let p = nix::pty::openpty(None, None).unwrap();
    let path = nix::unistd::ttyname(p.slave.as_fd()).unwrap();
    (
        File::from(p.master),
        path.to_string_lossy().into_owned(),
        p.slave,
    )
}

#[test]
fn monitor_of_a_silent_port_warns_and_exits_non_zero() {
    for kind in ["serial", "teensy"] {
        let (_master, path, _slave) = pty();
        let (code, out, err) = motorlink(&["monitor", &path, "--kind", kind, "--seconds", "0.3"]);
        assert_ne!(code, 0, "{kind}: {out}");
        assert!(err.contains("no frame"), "{kind}: {err}");
        assert!(!out.contains("\"message\""), "{kind}: {out}");
    }
}

#[test]
fn monitor_drops_what_the_port_held_before_it_opened() {
    let (mut master, path, _slave) = pty();
    // A STATUS the board sent before monitor started: stale, it must not be shown as news.
    let stale = cdc_hex(r#"{"type":"status","t_ms":5,"vbat_mv":12000,"flags":8,"err":0}"#);
    let bytes: Vec<u8> = (0..stale.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&stale[i..i + 2], 16).unwrap())
        .collect();
    master.write_all(&bytes).unwrap();
    let (code, out, err) = motorlink(&["monitor", &path, "--kind", "serial", "--seconds", "0.3"]);
    assert!(!out.contains("\"status\""), "stale STATUS replayed: {out}");
    assert_ne!(code, 0, "nothing fresh came: {err}");
}

/// Every verb of the CLI, from its own `--help`.
fn verbs() -> Vec<String> {
    let (_, top, _) = motorlink(&["--help"]);
    top.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|v| *v != "help")
        .map(str::to_string)
        .collect()
}

#[test]
fn help_names_links_and_faults_not_internal_labels() {
    let verbs = verbs();
    assert!(verbs.len() >= 15, "{verbs:?}");
    let (_, top, _) = motorlink(&["--help"]);
    let mut texts = vec![("motorlink".to_string(), top)];
    for v in &verbs {
        let (code, help, _) = motorlink(&[v, "--help"]);
        assert_eq!(code, 0, "{v} --help");
        texts.push((v.clone(), help));
    }
    for (verb, text) in texts {
        let lower = text.to_lowercase();
        for word in ["seed", "incident"] {
            assert!(
                !lower.contains(word),
                "{verb} --help says '{word}': {}",
                text.lines()
                    .find(|l| l.to_lowercase().contains(word))
                    .unwrap_or("")
            );
        }
    }
}

#[test]
fn sim_list_names_links_and_faults_not_internal_labels() {
    let (code, out, _) = motorlink(&["sim", "--list"]);
    assert_eq!(code, 0);
    let lower = out.to_lowercase();
    assert!(
        !lower.contains("seed 0") && !lower.contains("incident"),
        "{out}"
    );
}

#[test]
fn sim_with_a_shorter_duration_does_not_judge_what_needs_the_whole_run() {
    let dir = std::env::temp_dir().join(format!("motorlink-sim-{}", std::process::id()));
    let d = dir.to_string_lossy().into_owned();
    // nominal expects to be moving at its end (2 s); cut to 0.05 s, the robot has barely started.
    let (code, out, err) = motorlink(&[
        "sim",
        "nominal",
        "--duration",
        "0.05",
        "--no-plots",
        "--out",
        &d,
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(out.contains("not judged"), "{out}");
    assert!(out.contains("moving_at_end"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_typo_in_a_scenario_is_refused() {
    let dir = std::env::temp_dir().join(format!("motorlink-typo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("typo.toml");
    std::fs::write(
        &file,
        "name = \"typo\"\nduration_s = 0.05\n[expect]\nnever_brak = true\n",
    )
    .unwrap();
    let out_dir = dir.join("out");
    let (code, out, err) = motorlink(&[
        "sim",
        file.to_str().unwrap(),
        "--no-plots",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_ne!(code, 0, "{out}");
    assert!(err.contains("never_brak"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
