//! `motorlink`'s AMR SPI link verbs run as a binary against the simulated board (`--sim`) on its
//! lockstep clock, so each run is deterministic on a loaded machine: what the MCU's feedback and
//! the simulated robot's ground truth show after `drive`, `rearm`, `disarm`, `estop`, and `list`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use std::process::Command;

use serde_json::Value;

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

/// Runs a verb on the lockstep simulated board with `--json`: exit status and the report.
fn sim(args: &[&str]) -> (i32, Value) {
    let mut all = args.to_vec();
    all.extend(["--sim", "--sim-clock", "lockstep", "--json"]);
    let (code, out, err) = motorlink(&all);
    let report: Value = serde_json::from_str(out.trim())
        .unwrap_or_else(|e| panic!("{args:?}: {e}: stdout {out:?} stderr {err:?}"));
    (code, report)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn faults(v: &Value) -> Vec<String> {
    v["faults"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn drive_forward_moves_the_robot_forward_and_ends_stopped() {
    let (code, r) = sim(&["drive", "--v", "0.3", "--seconds", "1"]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["verdict"], "done");
    let d = &r["drive"];
    // 0.3 m/s for 1 s: 0.3 m, less the acceleration ramp, plus the ramp down after it.
    assert!((0.2..0.4).contains(&f(&d["distance_m"])), "{d}");
    assert!((f(&d["mean_v_mps"]) - 0.3).abs() < 0.03, "{d}");
    assert!(f(&d["heading_rad"]).abs() < 0.01, "{d}");
    // The simulated robot's own pose agrees with what the feedback integrated to.
    let t = &r["sim_truth"];
    assert!((f(&t["x_m"]) - f(&d["distance_m"])).abs() < 0.02, "{t}");
    assert!(f(&t["y_m"]).abs() < 0.01);
    // Ended commanded to zero and disarmed: STOP, wheels standing.
    assert_eq!(r["after"]["mode"], "STOP");
    assert!(f(&t["v_mps"]).abs() < 0.01, "{t}");
    assert_eq!(r["before"]["mode"], "BRAKE");
    // The identity asked on the first frame: the simulated board runs the AMR-SPI profile.
    assert_eq!(r["mcu_info"]["board"], "amr_spi", "{r}");
    assert_eq!(r["mcu_info"]["reset_cause"], "power_on");
}

#[test]
fn a_drive_longer_than_the_kept_history_still_counts_its_ramp_down() {
    // 3 s at 0.6 m/s: 1.8 m less the ramp up, plus the ramp down (7.5 rad/s at the bridge's
    // 0.04 rad/s per ms: 0.19 s, some 0.06 m). A session keeps 2 s of feedback, less than the
    // run, so the ramp down must be taken from the newest samples to be counted.
    let (code, r) = sim(&["drive", "--v", "0.6", "--seconds", "3"]);
    assert_eq!(code, 0, "{r}");
    let d = f(&r["drive"]["distance_m"]);
    let x = f(&r["sim_truth"]["x_m"]);
    assert!((d - x).abs() < 0.02, "feedback {d} m, robot {x} m");
    assert!((1.6..1.9).contains(&x), "{x}");
}

#[test]
fn drive_backward_turning_left_goes_backward_and_turns_left() {
    let (code, r) = sim(&["drive", "--v", "-0.2", "--w", "0.5", "--seconds", "1"]);
    assert_eq!(code, 0, "{r}");
    let t = &r["sim_truth"];
    assert!(f(&t["x_m"]) < -0.1, "{t}");
    // 0.5 rad/s for about a second: about 0.5 rad counter-clockwise.
    assert!((0.35..0.65).contains(&f(&t["theta_rad"])), "{t}");
    assert!(f(&r["drive"]["distance_m"]) < -0.1);
}

#[test]
fn rearm_clears_a_comm_loss_brake_latch() {
    let (code, r) = sim(&["rearm", "--sim-setup", "braked"]);
    assert_eq!(code, 0, "{r}");
    let before = &r["before"];
    assert_eq!(before["mode"], "BRAKE");
    assert!(
        faults(before).contains(&"COMM_LOST".to_string()),
        "{before}"
    );
    let modes: Vec<&str> = r["modes_seen"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap())
        .collect();
    assert_eq!(modes[0], "BRAKE");
    assert!(modes[1..].iter().any(|m| *m != "BRAKE"), "{modes:?}");
    assert!(r["message"].as_str().unwrap().contains("left BRAKE"));
}

#[test]
fn rearm_is_refused_while_the_board_estop_holds() {
    let (code, r) = sim(&["rearm", "--sim-setup", "estop-held"]);
    assert_eq!(code, 1, "{r}");
    assert_eq!(r["verdict"], "refused");
    assert_eq!(r["after"]["mode"], "BRAKE");
    assert!(faults(&r["after"]).contains(&"ESTOP".to_string()));
    assert_eq!(r["modes_seen"], serde_json::json!(["BRAKE"]));
    assert!(r["message"].as_str().unwrap().contains("ESTOP input"));
    assert_eq!(r["sim_truth"]["braked"], true);
}

#[test]
fn estop_brakes_a_driving_robot_by_a_frame_gap() {
    let (code, r) = sim(&["estop", "--sim-setup", "driving"]);
    assert_eq!(code, 0, "{r}");
    assert_ne!(r["before"]["mode"], "BRAKE");
    assert_eq!(r["after"]["mode"], "BRAKE");
    assert!(faults(&r["after"]).contains(&"COMM_LOST".to_string()));
    assert_eq!(r["counters"]["gaps"], 1);
    assert_eq!(r["sim_truth"]["braked"], true);
}

#[test]
fn estop_release_reports_whether_the_board_estop_holds() {
    let (code, r) = sim(&["estop", "--release", "--sim-setup", "estop-held"]);
    assert_eq!(code, 1, "{r}");
    assert!(r["message"].as_str().unwrap().contains("still engaged"));
    // Nothing holds on a board just powered on; the action word works as well as --release.
    let (code, r) = sim(&["estop", "release"]);
    assert_eq!(code, 0, "{r}");
    assert!(r["message"].as_str().unwrap().contains("rearm"));
}

#[test]
fn disarm_stops_a_driving_robot_under_control() {
    let (code, r) = sim(&["disarm", "--sim-setup", "driving"]);
    assert_eq!(code, 0, "{r}");
    let before = &r["before"];
    // Driving at 0.3 m/s: 3.75 rad/s on 0.08 m wheels.
    assert!(f(&before["wheel_radps"][0]) > 3.0, "{before}");
    // enable 0 is the ladder's STOP (not BRAKE): the speed loop holds zero.
    assert_eq!(r["after"]["mode"], "STOP");
    assert!(f(&r["after"]["wheel_radps"][0]).abs() < 0.05);
    assert!(f(&r["sim_truth"]["v_mps"]).abs() < 0.01);
    assert_eq!(r["sim_truth"]["braked"], false);
}

#[test]
fn list_json_parses_and_names_the_kinds() {
    let (code, out, err) = motorlink(&["list", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(out.trim()).unwrap();
    let devices = v["devices"].as_array().unwrap();
    for d in devices {
        assert!(d["path"].as_str().unwrap().starts_with("/dev/"), "{d}");
        assert!(!d["kinds"].as_array().unwrap().is_empty(), "{d}");
    }
}

#[test]
fn bad_twists_and_mixed_options_are_refused_before_anything_is_sent() {
    let (code, _, err) = motorlink(&["drive", "--sim", "--v", "2"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("1.44"), "{err}");
    let (code, _, err) = motorlink(&["drive", "/dev/ttyACM0", "--kind", "serial", "--v", "0.3"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("nothing was sent"), "{err}");
    let (code, _, err) = motorlink(&["drive", "--sim", "--v", "0.3", "--pwm", "1,1,1,1"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("--pwm"), "{err}");
    let (code, _, err) = motorlink(&["drive", "--sim", "--v", "0.3", "--modes", "pwm"]);
    assert_eq!(code, 64, "a usage error");
    assert!(
        err.contains("--modes is an option of drive --kind pi-spi"),
        "{err}"
    );
    let (code, _, err) = motorlink(&["drive", "--sim"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("--v"), "{err}");
    let (code, _, err) = motorlink(&["top", "--sim", "--sim-clock", "lockstep"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("real time"), "{err}");
    let (code, _, err) = motorlink(&["teleop", "--sim", "--max-v", "3"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("--max-v"), "{err}");
}

#[test]
fn estop_takes_the_device_first_and_keeps_the_serial_words() {
    // The device in the action's place: the AMR link (no such device here: an open error).
    let (code, _, err) = motorlink(&["estop", "/dev/spidev-none", "--kind", "spi"]);
    assert_eq!(code, 69, "a device that does not open is unavailable");
    assert!(err.contains("cannot open /dev/spidev-none"), "{err}");
    // A word that is neither action nor device path: refused before anything is opened.
    let (code, _, err) = motorlink(&["estop", "stop", "/dev/ttyACM0"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("neither engage nor release"), "{err}");
    // Seed 001 still needs its action.
    let (code, _, err) = motorlink(&["estop", "/dev/ttyACM-none"]);
    assert_eq!(code, 64, "a usage error");
    assert!(err.contains("engage or release"), "{err}");
}

#[test]
fn text_output_names_mode_and_verdict() {
    let (code, out, _) = motorlink(&["rearm", "--sim", "--sim-clock", "lockstep"]);
    assert_eq!(code, 0);
    assert!(out.starts_with("rearm: done (sim)"), "{out}");
    assert!(out.contains("mode BRAKE"), "{out}");
    assert!(out.contains("POWER_ON"), "{out}");
    assert!(out.contains("board AmrSpi, reset cause PowerOn"), "{out}");
}

#[test]
fn help_documents_the_amr_verbs() {
    for (verb, words) in [
        ("arm", &["BRAKE", "--sim", "--json"][..]),
        ("rearm", &["latch", "ESTOP"][..]),
        ("disarm", &["STOP"][..]),
        ("estop", &["frame gap", "--release", "engage"][..]),
        ("drive", &["--v", "--w", "--sim", "--pwm"][..]),
        ("list", &["spidev", "--json"][..]),
    ] {
        let (code, help, _) = motorlink(&[verb, "--help"]);
        assert_eq!(code, 0, "{verb}");
        for w in words {
            assert!(help.contains(w), "{verb} --help lacks {w}: {help}");
        }
    }
}

/// `motorlink` on a pseudo-terminal of 32 x 120 (the test is its keyboard and screen).
struct OnPty {
    child: std::process::Child,
    keyboard: std::fs::File,
    screen: std::sync::Arc<std::sync::Mutex<Vec<u8>>>,
    reader: std::thread::JoinHandle<()>,
}

impl OnPty {
    fn start(args: &[&str]) -> Self {
        use std::io::Read;
        use std::process::Stdio;
        let size = nix::pty::Winsize {
            ws_row: 32,
            ws_col: 120,
            ws_xpixel: 0,
            ws_ypixel: 0,
        };
        let pty = nix::pty::openpty(Some(&size), None).unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_motorlink"))
            .args(args)
            .stdin(Stdio::from(pty.slave.try_clone().unwrap()))
            .stdout(Stdio::from(pty.slave.try_clone().unwrap()))
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(pty.slave);
        let keyboard = std::fs::File::from(pty.master);
        let mut from = keyboard.try_clone().unwrap();
        let screen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let sink = std::sync::Arc::clone(&screen);
        // Read until the child closes the terminal (EIO on the master).
        let reader = std::thread::spawn(move || {
            let mut buf = [0u8; 65536];
            while let Ok(n) = from.read(&mut buf) {
                if n == 0 {
                    break;
                }
                sink.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        });
        Self {
            child,
            keyboard,
            screen,
            reader,
        }
    }

    fn shows(&self, word: &str) -> bool {
        String::from_utf8_lossy(&self.screen.lock().unwrap()).contains(word)
    }

    /// Waits (a minute at most) until the screen shows `word`, however slow the start.
    fn wait_for(&self, word: &str) {
        for _ in 0..600 {
            if self.shows(word) {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        panic!("the screen never showed {word}");
    }

    fn keys(&mut self, keys: &[u8], every_ms: u64) {
        use std::io::Write;
        for k in keys {
            self.keyboard.write_all(&[*k]).unwrap();
            std::thread::sleep(std::time::Duration::from_millis(every_ms));
        }
    }

    /// Waits for the exit: the screen while it ran, and the report printed after the terminal was
    /// given back (the alternate screen left and the cursor shown, or the test fails).
    fn finish(self) -> (String, Value) {
        let out = self.child.wait_with_output().unwrap();
        drop(self.keyboard);
        self.reader.join().unwrap();
        let screen = String::from_utf8_lossy(&self.screen.lock().unwrap()).into_owned();
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let restored = screen
            .rfind("\u{1b}[?1049l")
            .expect("the alternate screen was left");
        let report = &screen[restored..];
        assert!(report.contains("\u{1b}[?25h"), "the cursor is shown again");
        let r: Value = serde_json::from_str(report[report.find('{').unwrap()..].trim()).unwrap();
        (screen[..restored].to_string(), r)
    }
}

/// `teleop` on the paced simulated board: keys tapped and then held drive the robot forward, `q`
/// stops it, and the terminal is given back before the report is printed.
#[test]
fn teleop_drives_while_keys_come_and_q_stops_and_restores_the_terminal() {
    let mut t = OnPty::start(&["teleop", "--sim", "--json", "--seconds", "60"]);
    // Keys only once the view says the drive is armed (the help line's note).
    t.wait_for("armed");
    // Two taps, then the key held (a terminal repeats it every 40 ms) for 1.5 s, then q.
    t.keys(b"ww", 250);
    t.keys(&[b'w'; 38], 40);
    t.keys(b"q", 0);
    let (drawn, r) = t.finish();
    assert_eq!(r["verb"], "teleop");
    // Drawn while it ran: the view's mode line.
    assert!(drawn.contains("mode"), "nothing drawn");
    // It moved forward (0.1 m/s or more for over a second), and q left it standing, disarmed.
    let t = &r["sim_truth"];
    assert!(f(&t["x_m"]) > 0.05, "{t}");
    assert!(f(&t["v_mps"]).abs() < 0.01, "{t}");
    assert_eq!(r["after"]["mode"], "STOP", "{r}");
    assert_eq!(r["interrupted"], false);
}

/// A terminal that goes quiet: the twist stops being sent, the bridge's staleness rule takes the
/// target to zero while teleop still runs, and the robot stands before teleop ends on its own.
#[test]
fn teleop_with_a_quiet_keyboard_lets_the_command_go_stale() {
    let mut t = OnPty::start(&["teleop", "--sim", "--json", "--seconds", "4"]);
    t.wait_for("armed");
    t.keys(b"www", 150);
    // No key after these: 0.75 s of hold and 0.2 s of staleness are long gone by the end.
    let (drawn, r) = t.finish();
    // The command line said the twist was being sent (SENDING), and later, while teleop still
    // ran, that it no longer was (IDLE).
    let sent = drawn
        .rfind("SENDING")
        .expect("the twist was never shown as sent");
    assert!(
        drawn[sent..].contains("IDLE"),
        "never shown as no longer sent"
    );
    assert!(
        f(&r["counters"]["diagnostics"]["cmd_vel_stale"]) >= 1.0,
        "{r}"
    );
    let t = &r["sim_truth"];
    assert!(f(&t["x_m"]) > 0.02, "it moved: {t}");
    assert!(f(&t["v_mps"]).abs() < 0.01, "{t}");
}

#[test]
fn drive_interrupted_by_sigint_stops_and_disarms() {
    use nix::sys::signal::{kill, Signal};
    use nix::unistd::Pid;
    use std::process::Stdio;

    let child = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .args([
            "drive",
            "--sim",
            "--sim-clock",
            "paced",
            "--v",
            "0.3",
            "--seconds",
            "60",
            "--json",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    kill(
        Pid::from_raw(i32::try_from(child.id()).unwrap()),
        Signal::SIGINT,
    )
    .unwrap();
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let r: Value = serde_json::from_str(text.trim())
        .unwrap_or_else(|e| panic!("{e}: {text} {}", String::from_utf8_lossy(&out.stderr)));
    assert_eq!(out.status.code(), Some(0), "{r}");
    assert_eq!(r["interrupted"], true);
    // Stopped long before the 60 s asked for.
    assert!(f(&r["drive"]["seconds"]) < 59.0, "{r}");
    assert_eq!(r["after"]["mode"], "STOP");
    assert!(f(&r["sim_truth"]["v_mps"]).abs() < 0.01, "{r}");
}

/// `top` on a pseudo-terminal against the simulated board with its ESTOP input held: the view
/// shows the mode, the fault names and the link counters while it runs, and the terminal is given
/// back before the report is printed.
#[test]
fn top_on_a_terminal_shows_the_board_and_gives_the_terminal_back() {
    let t = OnPty::start(&[
        "top",
        "--sim",
        "--sim-setup",
        "estop-held",
        "--seconds",
        "1",
        "--json",
    ]);
    let (drawn, r) = t.finish();
    // Words, not phrases: the first frame skips the blank cells between them (cursor moves).
    for word in [
        "motorlink",
        "top:",
        "BRAKE",
        "ESTOP",
        "BRAKE_LATCHED",
        "exchanges",
        "diagnostics",
    ] {
        assert!(drawn.contains(word), "{word} not drawn");
    }
    assert_eq!(r["verb"], "top");
    // It watched: the board never left BRAKE, and no frame armed it.
    assert_eq!(r["modes_seen"], serde_json::json!(["BRAKE"]));
    assert!(f(&r["counters"]["exchanges"]) >= 1000.0, "{r}");
}
