//! The serial verbs against the real board application behind a real pseudo-terminal pair.
//!
//! A thread plays the board: it reads what the host writes to the pty, feeds every byte to the
//! board application of crate `mcu` (`CdcLinkTask::on_byte` / `TeensyLinkTask::on_byte` with a
//! `Safety<4>`), runs the 1 kHz `mcu::serial::tick` paced by wall time, and writes the board's
//! transmit queue back. The host side is exactly what `motorlink` runs: the library verbs over a
//! `SerialTransport` opened on the pty's device path, or the binary itself as a separate process
//! per verb (as the QEMU end-to-end test calls it), which also checks the exit status.
//!
//! ```text
//!  motorlink ──▶ /dev/pts/N ══ pty ══ master ──▶ on_byte ─▶ Safety<4> ◀── tick (1 kHz, wall time)
//!            ◀──────────────────────────────── tx queue ◀──┘ (ACK, STATUS, IMU / echoes)
//! ```
//!
//! When its thread is starved on a loaded machine the board's clock slips (it never bursts more than
//! a few ticks), so a stall cannot fake a comm loss; the ticks that are due run before the bytes
//! that came meanwhile, so a stall cannot make a frame look earlier than it was either. The reply
//! timeouts are generous.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic,
    missing_docs
)]

use std::collections::VecDeque;
use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mcu::cdc::{self, BoardStatus, CdcLinkTask, MotorOutput};
use mcu::serial::{tick, SerialTickInputs};
use mcu::teensy::{BoardAction, Joints, TeensyLinkTask};
use mcu::Safety;
use motorlink::cli::device::{self, CdcVerb, DrivePlan, MovePlan, SendHex, TeensyVerb, Verdict};
use motorlink::transport::SerialTransport;
use serde_json::Value;
use statemachine::{Config, Estop, FaultFlags, Mode, Position, RejectReason};

/// The timer's auto-reload of the fake seed 001 board: a duty of 0.3 is CCR 300.
const ARR: u16 = 1000;
/// Reply wait of every verb here: generous for a loaded machine.
const WAIT: Duration = Duration::from_secs(2);
/// Most ticks run at once when the board thread was starved.
const MAX_CATCH_UP: u64 = 20;

/// A board application the fake device runs.
trait App: Send + 'static {
    fn on_byte(&mut self, b: u8);
    fn tick(&mut self);
    fn pop(&mut self) -> Option<u8>;
}

/// A pty whose far end runs `B`; the host opens `path`.
struct FakeBoard<B: App> {
    path: String,
    state: Arc<Mutex<B>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Held open so the master never sees a hang-up between two host processes.
    _slave: OwnedFd,
}

/// A pty pair: the master end (non-blocking) and the device path, with its slave fd.
fn pty() -> (File, String, OwnedFd) {
    let p = nix::pty::openpty(None, None).unwrap();
    let path = nix::unistd::ttyname(p.slave.as_fd()).unwrap();
    let master = File::from(p.master);
    let flags = nix::fcntl::fcntl(master.as_raw_fd(), nix::fcntl::FcntlArg::F_GETFL).unwrap();
    let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
    nix::fcntl::fcntl(master.as_raw_fd(), nix::fcntl::FcntlArg::F_SETFL(flags)).unwrap();
    (master, path.to_string_lossy().into_owned(), p.slave)
}

impl<B: App> FakeBoard<B> {
    fn start(app: B) -> Self {
        let (mut master, path, slave) = pty();
        let state = Arc::new(Mutex::new(app));
        let stop = Arc::new(AtomicBool::new(false));
        let (st, sp) = (state.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let t0 = Instant::now();
            let mut ticks = 0u64;
            let mut out = VecDeque::<u8>::new();
            let mut buf = [0u8; 512];
            while !sp.load(Ordering::Relaxed) {
                // The ticks due first, then the bytes that came meanwhile: after a stall the bytes
                // look late to the board, never early (a frame never lands before ticks that had
                // passed when it was sent).
                let due = t0.elapsed().as_millis() as u64;
                ticks = ticks.max(due.saturating_sub(MAX_CATCH_UP));
                {
                    let mut app = st.lock().unwrap();
                    while ticks < due {
                        app.tick();
                        ticks += 1;
                    }
                }
                loop {
                    match master.read(&mut buf) {
                        Ok(0) => break,
                        Ok(n) => {
                            let mut app = st.lock().unwrap();
                            for &b in &buf[..n] {
                                app.on_byte(b);
                                // The transmitter drains the queue while bytes come in: a burst
                                // read after a stall must not overflow it.
                                while let Some(x) = app.pop() {
                                    out.push_back(x);
                                }
                            }
                        }
                        // Nothing waiting (EAGAIN), or no host holds the device (EIO).
                        Err(_) => break,
                    }
                }
                {
                    let mut app = st.lock().unwrap();
                    while let Some(x) = app.pop() {
                        out.push_back(x);
                    }
                }
                while !out.is_empty() {
                    let (front, _) = out.as_slices();
                    match master.write(front) {
                        Ok(n) => {
                            out.drain(..n);
                        }
                        Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                        Err(_) => out.clear(),
                    }
                }
                // Nobody reads: a UART would send into the void.
                if out.len() > 1 << 16 {
                    out.clear();
                }
                std::thread::sleep(Duration::from_micros(300));
            }
        });
        Self {
            path,
            state,
            stop,
            thread: Some(thread),
            _slave: slave,
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut B) -> R) -> R {
        f(&mut self.state.lock().unwrap())
    }

    /// Polls the board until `pred` holds or `within` has passed.
    fn wait_until(&self, within: Duration, pred: impl Fn(&B) -> bool) -> bool {
        let end = Instant::now() + within;
        loop {
            if self.with(|b| pred(b)) {
                return true;
            }
            if Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    fn open(&self) -> SerialTransport {
        SerialTransport::open(&self.path, 115_200, Duration::from_millis(20)).unwrap()
    }
}

impl<B: App> Drop for FakeBoard<B> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The seed 001 board: link task, safety core, the motors' driver inputs.
struct CdcBoard {
    link: CdcLinkTask,
    safety: Safety<4>,
    ticks: u32,
    outputs: [MotorOutput; 4],
    /// Every distinct (mode, outputs) the tick produced, in order.
    seen: Vec<(Mode, [MotorOutput; 4])>,
}

impl CdcBoard {
    fn new() -> Self {
        Self {
            link: CdcLinkTask::new(),
            safety: Safety::new(Config::CDC),
            ticks: 0,
            outputs: [MotorOutput::COAST; 4],
            seen: Vec::new(),
        }
    }

    fn status(&self) -> BoardStatus {
        BoardStatus {
            t_ms: self.ticks,
            vbat_mv: 12_000,
            imu_ok: true,
        }
    }

    /// An ESTOP is engaged (its owners: this link, the local input). The latch it caused stays in
    /// the faults until the re-arm.
    fn estop(&self) -> bool {
        self.safety.ladder().estop_owners() != 0
    }
}

impl App for CdcBoard {
    fn on_byte(&mut self, b: u8) {
        let st = self.status();
        if let Some(out) = self.link.on_byte(&mut self.safety, b, &st) {
            self.outputs = cdc::motor_outputs(&out.drive, ARR);
        }
    }

    fn tick(&mut self) {
        self.ticks += 1;
        let out = tick(&mut self.safety, &SerialTickInputs::default());
        self.outputs = cdc::motor_outputs(&out.drive, ARR);
        if self.seen.last() != Some(&(out.mode, self.outputs)) {
            self.seen.push((out.mode, self.outputs));
        }
        let st = self.status();
        self.link.periodic(&self.safety, &st);
        if self.ticks.is_multiple_of(10) {
            let (imu, _) =
                cdc::imu_from_raw(self.ticks, [0, 0, 16_384], 0, [0; 3], &cdc::IMU_SCALE);
            self.link.send_imu(&imu);
        }
    }

    fn pop(&mut self) -> Option<u8> {
        self.link.tx.pop()
    }
}

/// The seed 003 arm: link task, safety core, joints, end effector.
struct TeensyBoard {
    link: TeensyLinkTask,
    safety: Safety<4>,
    joints: Joints,
    endeff: bool,
    modes: Vec<Mode>,
}

impl TeensyBoard {
    fn new() -> Self {
        let cfg = Config::TEENSY;
        Self {
            link: TeensyLinkTask::new(),
            safety: Safety::new(cfg),
            joints: Joints::new([Position::ZERO; 4], &cfg),
            endeff: false,
            modes: Vec::new(),
        }
    }

    fn degrees(&self) -> [f64; 4] {
        self.joints
            .positions()
            .map(|p| p.to_num::<f64>().to_degrees())
    }
}

impl App for TeensyBoard {
    fn on_byte(&mut self, b: u8) {
        match self.link.on_byte(&mut self.safety, b) {
            Some((_, BoardAction::EndEffector(on))) => self.endeff = on,
            Some((_, BoardAction::Accel(a))) => self.joints.set_accel(a),
            _ => {}
        }
    }

    fn tick(&mut self) {
        let out = tick(&mut self.safety, &SerialTickInputs::default());
        self.joints.tick(&out.drive);
        if self.modes.last() != Some(&out.mode) {
            self.modes.push(out.mode);
        }
    }

    fn pop(&mut self) -> Option<u8> {
        self.link.tx.pop()
    }
}

/// Runs a library verb, collecting its lines.
fn lines_of(
    run: impl FnOnce(&mut dyn FnMut(Value)) -> Result<Verdict, String>,
) -> (Verdict, Vec<Value>) {
    let mut lines = Vec::new();
    let v = run(&mut |l| lines.push(l)).unwrap();
    (v, lines)
}

/// The binary as a separate process: exit status and stdout's JSON lines.
fn motorlink(args: &[&str]) -> (i32, Vec<Value>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    (
        out.status.code().unwrap_or(-1),
        lines,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The binary with `args` and the generous reply wait.
fn waiting(args: &[&str]) -> (i32, Vec<Value>, String) {
    let mut a = args.to_vec();
    a.extend_from_slice(&["--wait-ms", WAIT_MS]);
    motorlink(&a)
}

fn last(lines: &[Value]) -> &Value {
    lines.last().expect("at least the verdict line")
}

/// The messages (`{"message": ..}` lines) of a given type.
fn messages<'a>(lines: &'a [Value], ty: &str) -> Vec<&'a Value> {
    lines
        .iter()
        .filter_map(|l| l.get("message"))
        .filter(|m| m["type"] == ty)
        .collect()
}

const WAIT_MS: &str = "2000";

#[test]
fn serial_ping_is_answered_by_the_boards_status() {
    let board = FakeBoard::start(CdcBoard::new());
    let (v, lines) =
        lines_of(|sink| device::run_cdc(board.open(), &CdcVerb::Ping { count: 3 }, WAIT, sink));
    assert_eq!(v, Verdict::Done, "{lines:?}");
    let pings: Vec<&Value> = lines.iter().filter(|l| l.get("ping").is_some()).collect();
    assert_eq!(pings.len(), 3);
    for p in pings {
        assert_eq!(p["reply"]["type"], "status", "{p}");
        assert_eq!(p["reply"]["vbat_mv"], 12_000);
    }
    let end = last(&lines);
    assert_eq!(end["verdict"], "done");
    assert_eq!(end["replies"], 3);

    // The same from the binary, which opens the pty anew.
    let dev = board.path.as_str();
    let (code, lines, err) = waiting(&["ping", "--kind", "serial", dev, "--count", "2"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(last(&lines)["replies"], 2);
}

#[test]
fn drive_with_enable_runs_the_motors_at_the_commanded_duties_and_the_board_brakes_after() {
    let board = FakeBoard::start(CdcBoard::new());
    // timeout_ms 250: the board's longest, so a host stalled by a loaded machine is no comm loss.
    let plan = DrivePlan::new(&[300, -200, 0, 100], 250, 50.0, 0.6, true).unwrap();
    assert_eq!(plan.frames, 30);
    let (v, lines) =
        lines_of(|sink| device::run_cdc(board.open(), &CdcVerb::Drive(plan), WAIT, sink));
    assert_eq!(v, Verdict::Done, "{:?}", last(&lines));
    let end = last(&lines);
    // Every planned frame is sent on its deadline, or its deadline is counted as skipped (a
    // loaded machine stalled the host for more than a period; the frames then stop on time rather
    // than run late), never more than planned.
    let sent = end["frames_sent"].as_u64().unwrap();
    let skipped = end["pacing"]["skipped"].as_u64().unwrap();
    assert!(sent <= 30 && sent + skipped >= 30, "{end}");
    assert_eq!(end["enable"]["reply"]["type"], "ack");
    assert_eq!(end["enable"]["reply"]["msg_id"], 2);
    assert_eq!(end["enable"]["reply"]["result"], 0);
    assert_eq!(end["stopped_early"], false);
    // 0.6 s of a board sending STATUS at 10 Hz and IMU at 100 Hz: how many depends on how much
    // of the machine the board's thread got; at least one of each, one STATUS while enabled.
    assert!(end["received"]["status"].as_u64().unwrap() >= 1, "{end}");
    assert!(end["received"]["imu"].as_u64().unwrap() >= 1, "{end}");
    assert!(
        end["received"]["status_motor_enabled"].as_u64().unwrap() >= 1,
        "{end}"
    );
    assert_eq!(end["received"]["errors"], 0);
    assert_eq!(end["decoder"]["crc_errors"], 0);
    assert_eq!(
        messages(&lines, "ack").len(),
        1,
        "the ACK is printed as it arrives"
    );

    // The board ran the motors at the commanded duties: 0.3 forward, 0.2 reverse, coast, 0.1 forward.
    let want = [
        MotorOutput {
            ccr: 300,
            in1: true,
            in2: false,
        },
        MotorOutput {
            ccr: 200,
            in1: false,
            in2: true,
        },
        MotorOutput::COAST,
        MotorOutput {
            ccr: 100,
            in1: true,
            in2: false,
        },
    ];
    board.with(|b| {
        assert!(
            b.seen
                .iter()
                .any(|(m, o)| matches!(m, Mode::Reduced | Mode::Normal) && *o == want),
            "{:?}",
            b.seen.last()
        );
    });
    // Then nothing more is sent: the board brakes on its own (within timeout_ms).
    assert!(board.wait_until(Duration::from_secs(2), |b| b.safety.mode() == Mode::Brake));
    board.with(|b| {
        assert_eq!(b.outputs, [MotorOutput::short(ARR); 4]);
        assert!(b.safety.ladder().faults().contains(FaultFlags::COMM_LOST));
    });
}

#[test]
fn estop_brakes_enable_is_then_refused_a_corrupted_release_changes_nothing_and_release_is_acked() {
    let board = FakeBoard::start(CdcBoard::new());
    let dev = board.path.as_str();
    let (code, lines, err) = waiting(&[
        "drive",
        dev,
        "--pwm",
        "-250,250,0,0",
        "--seconds",
        "0.3",
        "--enable",
    ]);
    assert_eq!(code, 0, "{err} {lines:?}");
    assert!(
        board.with(|b| b.seen.iter().any(|(m, _)| *m != Mode::Brake)),
        "it drove"
    );

    let (code, lines, err) = waiting(&["estop", "engage", "--kind", "serial", dev]);
    assert_eq!(code, 0, "{err}");
    let end = last(&lines);
    assert_eq!(end["verdict"], "done");
    assert_eq!(end["reply"]["msg_id"], 3);
    assert_eq!(end["reply"]["result"], 0);
    board.with(|b| {
        assert_eq!(b.safety.mode(), Mode::Brake);
        assert!(b.estop());
        assert_eq!(b.outputs, [MotorOutput::short(ARR); 4]);
    });

    // The safety core refuses to re-arm while the ESTOP is engaged: ACK result 1, exit status 1.
    let (code, lines, err) = waiting(&["enable", "on", "--kind", "serial", dev]);
    assert_eq!(code, 1, "{err} {lines:?}");
    let end = last(&lines);
    assert_eq!(end["verdict"], "refused");
    assert_eq!(
        end["reply"],
        serde_json::json!({"type": "ack", "msg_id": 2, "result": 1})
    );

    // An ESTOP release whose CRC is broken: no ACK, the ESTOP stays, the next STATUS says CRC_ERROR.
    let good = {
        let mut f = [0u8; protocol::cdc::MAX_FRAME_LEN];
        let n = protocol::cdc::Message::Estop(Estop::Release).encode(&mut f);
        f[..n].to_vec()
    };
    let mut bad = good.clone();
    *bad.last_mut().unwrap() ^= 0x01;
    let hex = motorlink::cli::to_hex(&bad);
    let (code, lines, err) = motorlink(&["send-hex", dev, &hex, "--listen-ms", "400"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(lines[0]["sent_hex"], hex.as_str());
    assert!(messages(&lines, "ack").is_empty(), "{lines:?}");
    assert!(
        messages(&lines, "status").iter().any(|s| s["err"] == 1),
        "STATUS err CRC_ERROR (1) within 400 ms: {lines:?}"
    );
    board.with(|b| {
        assert!(b.estop(), "a corrupted frame changes nothing");
        assert_eq!(b.safety.ladder().counters().rejected(RejectReason::Crc), 1);
        assert_eq!(b.link.stats().crc_errors, 1);
    });

    let (code, lines, err) = waiting(&["estop", "release", dev]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(last(&lines)["reply"]["result"], 0);
    board.with(|b| {
        assert!(!b.estop());
        assert_eq!(
            b.safety.mode(),
            Mode::Brake,
            "released, still braked until re-armed"
        );
    });

    // Re-armed and driven again.
    let from = board.with(|b| b.seen.len());
    let (code, lines, err) = waiting(&[
        "drive",
        dev,
        "--pwm",
        "100,100,100,100",
        "--seconds",
        "0.3",
        "--enable",
    ]);
    assert_eq!(code, 0, "{err} {lines:?}");
    assert_eq!(last(&lines)["enable"]["reply"]["result"], 0);
    board.with(|b| assert!(b.seen[from..].iter().any(|(m, _)| *m != Mode::Brake)));
}

#[test]
fn an_enable_waits_for_the_first_frame_within_the_threshold_and_no_longer() {
    // MOTOR_ENABLE 1 carries a coasting frame, so the re-arm waits for the host's first
    // SET_MOTOR_PWM for up to the profile's BRAKE threshold (249 ms): `enable on` then `drive`
    // (two processes) drives; an enable followed by half a second of silence has lapsed.
    let board = FakeBoard::start(CdcBoard::new());
    let dev = board.path.as_str();
    assert!(
        board.wait_until(Duration::from_secs(5), |b| b.ticks > 300),
        "past the power-on age"
    );
    let (code, lines, err) = waiting(&["enable", "on", dev]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(last(&lines)["reply"]["result"], 0, "accepted, pending");
    let from = board.with(|b| b.seen.len());
    let (code, _, err) = motorlink(&["drive", dev, "--pwm", "200,200,200,200", "--seconds", "0.3"]);
    assert_eq!(code, 0, "{err}");
    board.with(|b| {
        assert!(
            b.seen[from..].iter().any(|(m, _)| *m != Mode::Brake),
            "the enable re-armed at the first frame: {:?}",
            &b.seen[from..]
        )
    });
    // Let the drive brake on comm loss, then enable and stay silent past the threshold.
    assert!(board.wait_until(Duration::from_secs(5), |b| b.safety.mode() == Mode::Brake));
    let (code, _, err) = waiting(&["enable", "on", dev]);
    assert_eq!(code, 0, "{err}");
    std::thread::sleep(Duration::from_millis(600));
    let from = board.with(|b| b.seen.len());
    let (code, lines, err) =
        motorlink(&["drive", dev, "--pwm", "200,200,200,200", "--seconds", "0.3"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(last(&lines)["received"]["status_motor_enabled"], 0);
    board.with(|b| {
        assert!(
            b.seen[from..].iter().all(|(m, _)| *m == Mode::Brake),
            "a lapsed enable does not re-arm: {:?}",
            &b.seen[from..]
        )
    });
}

#[test]
fn a_silent_device_is_no_reply_and_bad_drive_arguments_send_nothing() {
    let (mut master, path, _slave) = pty();
    let path = path.as_str();
    let mut drain = || {
        let mut got = Vec::new();
        let mut buf = [0u8; 256];
        while let Ok(n) = master.read(&mut buf) {
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        got
    };
    for bad in [
        &["drive", path, "--pwm", "1001,0,0,0"][..],
        &["drive", path, "--pwm", "0,0,0,-1001"],
        &["drive", path, "--pwm", "0,0,0,0", "--timeout-ms", "0"],
        &["drive", path, "--pwm", "0,0,0"],
        &["move", path, "--angles", "1,2,3", "--speed", "10"],
    ] {
        let (code, lines, err) = motorlink(bad);
        assert_eq!(code, 64, "{bad:?}");
        assert!(lines.is_empty());
        assert!(err.contains("error:"), "{err}");
        assert!(drain().is_empty(), "nothing sent for {bad:?}");
    }

    let (code, lines, _) = motorlink(&["enable", "on", path, "--wait-ms", "100"]);
    assert_eq!(code, 69);
    assert_eq!(last(&lines)["verdict"], "no_reply");
    assert_eq!(
        drain(),
        [0xAA, 0x55, 0x02, 0x01, 0x01, 0xEC, 0x81],
        "MOTOR_ENABLE 1 went out"
    );

    let (code, lines, _) = motorlink(&["drive", path, "--pwm", "10,0,0,0", "--seconds", "0.25"]);
    assert_eq!(code, 69, "a drive that hears nothing");
    assert_eq!(last(&lines)["verdict"], "no_reply");
    let sent = drain();
    // SET_MOTOR_PWM: 4 header + 10 payload + 2 CRC bytes; 0.25 s at 50 Hz.
    assert_eq!(sent.len() % 16, 0);
    assert!(sent.len() / 16 >= 12, "{} frames", sent.len() / 16);

    let (code, lines, _) = motorlink(&[
        "ping",
        "--kind",
        "teensy",
        path,
        "--count",
        "1",
        "--wait-ms",
        "100",
    ]);
    assert_eq!(code, 69);
    assert_eq!(last(&lines)["verdict"], "no_reply");
}

#[test]
fn teensy_cal_and_move_are_echoed_with_success_and_the_arm_moves() {
    let board = FakeBoard::start(TeensyBoard::new());
    let plan = MovePlan::new(&[10, 20, -30, 0], 4, 180, false, 50.0, 0.6, false, true).unwrap();
    let (v, lines) =
        lines_of(|sink| device::run_teensy(board.open(), 4, &TeensyVerb::Move(plan), WAIT, sink));
    let end = last(&lines);
    assert_eq!(v, Verdict::Done, "{end}");
    assert_eq!(end["cal"]["reply"]["cmd_type"], "cal");
    assert_eq!(end["cal"]["reply"]["cmd_success"], 1);
    // As in the drive test: every planned frame sent or its deadline counted as skipped; every
    // frame sent is echoed with success.
    let sent = end["mtrs_sent"].as_u64().unwrap();
    let skipped = end["pacing"]["skipped"].as_u64().unwrap();
    assert!(sent <= 30 && sent + skipped >= 30, "{end}");
    assert_eq!(end["echoes_ok"], sent);
    assert_eq!(end["echoes_missing"], 0);
    let mtrs: Vec<&Value> = lines
        .iter()
        .filter_map(|l| l.get("message"))
        .filter(|m| m["cmd_type"] == "mtrs")
        .collect();
    assert_eq!(mtrs.len() as u64, sent, "every echo printed");
    assert!(mtrs
        .iter()
        .all(|m| m["cmd_success"] == 1 && m["mtr_angles"] == serde_json::json!([10, 20, -30, 0])));
    board.with(|b| {
        assert!(
            b.modes
                .iter()
                .any(|m| matches!(m, Mode::Reduced | Mode::Normal)),
            "{:?}",
            b.modes
        );
        let d = b.degrees();
        // 30° at 180°/s takes about 0.2 s: the arm has moved well toward every target.
        assert!(
            d[0] > 5.0 && d[1] > 10.0 && d[2] < -15.0 && d[3].abs() < 0.01,
            "{d:?}"
        );
    });

    // A relative move is refused: exit status 1, and sending stops at the refusal.
    let dev = board.path.as_str();
    let (code, lines, err) = waiting(&[
        "move",
        dev,
        "--angles",
        "5,5,5,5",
        "--speed",
        "90",
        "--relative",
        "--seconds",
        "0.5",
    ]);
    assert_eq!(code, 1, "{err}");
    let end = last(&lines);
    assert_eq!(end["verdict"], "refused");
    assert!(end["echoes_refused"].as_u64().unwrap() >= 1, "{end}");
    assert_eq!(end["stopped_early"], true);
    assert!(end["mtrs_sent"].as_u64().unwrap() < 25, "{end}");
}

#[test]
fn teensy_cal_endeff_config_ping_and_a_corrupted_frame() {
    let board = FakeBoard::start(TeensyBoard::new());
    let dev = board.path.as_str();
    let run = |args: &[&str]| {
        let mut a = args.to_vec();
        a.extend_from_slice(&[dev, "--kind", "teensy"]);
        waiting(&a)
    };

    let (code, lines, err) = run(&["cal"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(last(&lines)["reply"]["cmd_success"], 1);

    let (code, lines, _) = run(&["endeff", "on"]);
    assert_eq!(code, 0);
    assert_eq!(last(&lines)["reply"]["cmd_type"], "endeff_on");
    assert!(board.with(|b| b.endeff));

    let before = board.with(|b| b.joints.accel());
    let (code, lines, _) = run(&["config", "--accel", "1000"]);
    assert_eq!(code, 0, "{lines:?}");
    assert_eq!(last(&lines)["reply"]["mtr_accel_deg_s_s"], 1000);
    assert!(
        board.with(|b| b.joints.accel()) < before,
        "1000 °/s² is below the profile's limit"
    );
    let (code, lines, _) = run(&["config", "--accel", "3000"]);
    assert_eq!(code, 1, "above the profile's 50 rad/s²");
    assert_eq!(last(&lines)["reply"]["cmd_success"], 0);

    let (v, lines) = lines_of(|sink| {
        device::run_teensy(board.open(), 4, &TeensyVerb::Ping { count: 3 }, WAIT, sink)
    });
    assert_eq!(v, Verdict::Done);
    assert_eq!(last(&lines)["replies"], 3);
    assert!(
        !board.with(|b| b.endeff),
        "the probe switches the end effector off"
    );

    // ENDEFF_ON whose cmd_type bit 0 flipped on the line (2 → 3, not a zero byte): a frame of the
    // right length whose CRC no longer matches its stuffed bytes. No echo, nothing switched, one
    // CRC refusal counted.
    let mut f = [0u8; protocol::teensy::ROBUST_BUF];
    let on = protocol::teensy::CmdMsg::<4> {
        cmd_type: protocol::teensy::CmdType::EndeffOn,
        ..Default::default()
    };
    let n = on.encode_robust(&mut f).unwrap();
    let mut bad = f[..n].to_vec();
    // The body is 02 (version) 02 00 00 00 (cmd_type) …: COBS puts a code byte first, so S
    // starts 03 02 02.
    assert_eq!(
        bad[..3],
        [3, 2, 2],
        "code byte, version, then cmd_type little-endian"
    );
    bad[2] ^= 0x01;
    let (v, lines) = lines_of(|sink| {
        device::run_teensy(
            board.open(),
            4,
            &TeensyVerb::SendHex(SendHex {
                bytes: bad,
                listen: Duration::from_millis(200),
            }),
            WAIT,
            sink,
        )
    });
    assert_eq!(v, Verdict::Done);
    assert_eq!(last(&lines)["received"]["messages"], 0, "{lines:?}");
    board.with(|b| {
        assert!(!b.endeff);
        assert_eq!(b.link.stats().errors, 1);
        assert_eq!(b.safety.ladder().counters().rejected(RejectReason::Crc), 1);
        assert_eq!(b.safety.ladder().counters().rejected_total(), 1);
    });
}
