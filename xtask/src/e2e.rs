//! `cargo xtask qemu-e2e <cdc|teensy>`: the real host against the real firmware. Boots the
//! profile's emulator image (`--features qemu`) in QEMU `netduinoplus2` with USART1 on a pty, drives
//! it with the `motorlink` binary (the dev build) over that pty (one process per step, as a user would),
//! and checks every step against the firmware's own trace (`firmware/src/board/trace.rs`: one
//! line per tick on which something but the age changed, ticks in emulated milliseconds).
//!
//! The last check is the safety one: after the host stops, BRAKE comes within the profile's bound
//! of the last valid frame, counted in the firmware's ticks.

// A host-side test driver: an index out of range or an overflow here is a failed test run, never
// a board's behaviour.
#![allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One trace line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Line {
    /// Emulated 1 ms ticks since boot.
    pub tick: u32,
    /// The rung (`Normal`, `Reduced`, `Hold`, `Stop`, `Brake`).
    pub mode: String,
    /// Ticks since the last valid frame.
    pub age: u32,
    /// The drive is BRAKE.
    pub brake: bool,
    /// Valid frames so far.
    pub valid: u32,
    /// Refused frames so far.
    pub rejected: u32,
    /// Refused re-arms and ESTOP releases so far.
    pub refusals: u32,
    /// ESTOP owners (bit 0 the board's input, bit 1 the link).
    pub owners: u8,
    /// One token per motor: `+n`/`-n`, `C`, `S`.
    pub out: Vec<String>,
}

/// Parses a trace line; `None` for anything else QEMU prints.
pub fn parse(line: &str) -> Option<Line> {
    let rest = line.trim().strip_prefix("tick=")?;
    let (head, out) = rest.split_once(" out=")?;
    let mut fields = head.split(' ');
    let tick = fields.next()?.parse().ok()?;
    let mut get = |key: &str| -> Option<String> {
        let f = fields.next()?;
        f.strip_prefix(key)?.strip_prefix('=').map(str::to_string)
    };
    Some(Line {
        tick,
        mode: get("mode")?,
        age: get("age")?.parse().ok()?,
        brake: get("drive")? == "BRAKE",
        valid: get("valid")?.parse().ok()?,
        rejected: get("rejected")?.parse().ok()?,
        refusals: get("refusals")?.parse().ok()?,
        owners: get("owners")?.parse().ok()?,
        out: out.split(' ').map(str::to_string).collect(),
    })
}

/// The BRAKE after the host stopped: the tick of the last line whose valid-frame count rose
/// (the frame arrived in the tick before it, when its age restarted at 0) and the first BRAKE
/// line after it. Returns (last valid frame's line tick, BRAKE line tick, BRAKE line's age).
pub fn brake_after_last_frame(trace: &[Line]) -> Option<(u32, u32, u32)> {
    let last_frame = trace
        .windows(2)
        .filter(|w| w[1].valid > w[0].valid)
        .map(|w| &w[1])
        .next_back()?;
    let brake = trace.iter().find(|l| l.tick > last_frame.tick && l.brake)?;
    Some((last_frame.tick, brake.tick, brake.age))
}

/// The corrupted frame was the last thing the host sent: from the line where the refusal count
/// reached `rejected` on, no valid frame was counted, no other refusal, and no line shows
/// `applied` (what the corrupted frame would have put on the outputs). Lines before it may still
/// show the last valid frames arriving: the pty delivers a backlog at the emulator's pace.
pub fn refused_changed_nothing(
    trace: &[Line],
    rejected: u32,
    applied: impl Fn(&Line) -> bool,
) -> bool {
    let Some(i) = trace.iter().position(|l| l.rejected == rejected) else {
        return false;
    };
    let valid = trace[i].valid;
    trace[i..]
        .iter()
        .all(|l| l.valid == valid && l.rejected == rejected && !applied(l))
}

/// The emulator with the image booted.
struct Qemu {
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
    pty: String,
    /// The pty held open for the whole session (never read): QEMU's pty backend drops what the
    /// guest sends, and stops reading, while no process has the pty open, and notices a new opener
    /// only at its next once-a-second poll. Without this, every `motorlink` run would lose up to a
    /// second of its exchange.
    _hold: std::fs::File,
}

impl Qemu {
    fn start(elf: &Path) -> Result<Self, String> {
        let mut child = Command::new("qemu-system-arm")
            .args([
                "-machine",
                "netduinoplus2",
                "-cpu",
                "cortex-m4",
                "-nographic",
            ])
            .args(["-monitor", "none", "-serial", "pty"])
            .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
            .arg(elf)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
        let stdout = child.stdout.take().ok_or("no QEMU stdout")?;
        let lines = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&lines);
        std::thread::spawn(move || {
            for l in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Ok(mut v) = sink.lock() {
                    v.push(l);
                }
            }
        });
        let t0 = Instant::now();
        loop {
            let pty = lines.lock().ok().and_then(|v| {
                v.iter().find_map(|l| {
                    l.split_once("redirected to ")
                        .and_then(|(_, r)| r.split_whitespace().next())
                        .map(str::to_string)
                })
            });
            if let Some(pty) = pty {
                use std::os::unix::fs::OpenOptionsExt;
                // O_NOCTTY (Linux): the pty must not become this process's controlling terminal.
                const O_NOCTTY: i32 = 0o400;
                let hold = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .custom_flags(O_NOCTTY)
                    .open(&pty)
                    .map_err(|e| format!("cannot open {pty}: {e}"))?;
                // Let QEMU's poll see the pty connected before the first exchange.
                std::thread::sleep(Duration::from_millis(1500));
                return Ok(Self {
                    child,
                    lines,
                    pty,
                    _hold: hold,
                });
            }
            if t0.elapsed() > Duration::from_secs(20) {
                let _ = child.kill();
                return Err("QEMU did not report its pty within 20 s".into());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn trace(&self) -> Vec<Line> {
        self.lines
            .lock()
            .map(|v| v.iter().filter_map(|l| parse(l)).collect())
            .unwrap_or_default()
    }

    /// Waits until `pred` holds for the trace, or fails after `secs`.
    fn wait_for(
        &self,
        what: &str,
        secs: u64,
        pred: impl Fn(&[Line]) -> bool,
    ) -> Result<(), String> {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(secs) {
            if pred(&self.trace()) {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        Err(format!(
            "{what}: not seen in the firmware's trace within {secs} s"
        ))
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One `motorlink` run: its exit status and standard output.
struct Run {
    ok: bool,
    stdout: String,
}

fn motorlink(bin: &Path, args: &[&str]) -> Result<Run, String> {
    println!("$ motorlink {}", args.join(" "));
    let o = Command::new(bin)
        .args(args)
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot run {}: {e}", bin.display()))?;
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    for l in stdout.lines().take(12) {
        println!("  {l}");
    }
    Ok(Run {
        ok: o.status.success(),
        stdout,
    })
}

fn expect(cond: bool, what: &str) -> Result<(), String> {
    if cond {
        println!("ok: {what}");
        Ok(())
    } else {
        Err(what.to_string())
    }
}

fn build(root: &Path, profile: &str) -> Result<(PathBuf, PathBuf), String> {
    let images = crate::variant::build(root, "qemu")?;
    Ok((images.join(profile), crate::cargo::motorlink(root)?))
}

/// Runs the end-to-end session of `profile` and returns a summary.
pub fn run(root: &Path, profile: &str) -> Result<String, String> {
    let (elf, ml) = build(root, profile)?;
    let q = Qemu::start(&elf)?;
    println!("{profile} image booted, USART1 on {}", q.pty);
    let summary = match profile {
        "cdc" => cdc(&q, &ml),
        "teensy" => teensy(&q, &ml),
        other => Err(format!(
            "no end-to-end session for profile '{other}' (cdc, teensy)"
        )),
    };
    let trace = q.trace();
    let path = root
        .join("target/qemu")
        .join(format!("e2e-{profile}-trace.txt"));
    let text: Vec<String> = q.lines.lock().map(|v| v.clone()).unwrap_or_default();
    let _ = std::fs::write(&path, text.join("\n"));
    println!(
        "firmware trace: {} lines in {}",
        trace.len(),
        path.display()
    );
    summary
}

/// The last line of the trace.
fn last(q: &Qemu) -> Option<Line> {
    q.trace().last().cloned()
}

/// The commanded duties as the trace shows them: PWM full scale under the emulator is 800 counts
/// (16 MHz / 20 kHz), so 300 → +240, -300 → -240, 0 → coast, 500 → +400.
const CDC_PWM: &str = "300,-300,0,500";
const CDC_OUT: [&str; 4] = ["+240", "-240", "C", "+400"];

/// Waits for BRAKE after the host stopped and checks its bound from the trace: BRAKE at age
/// `threshold` (= timeout_ms − 1, or the profile's 249), at most `threshold` ms after the last
/// valid frame's arrival, strictly within `threshold + 1` ms.
fn comm_loss_brake(q: &Qemu, threshold: u32) -> Result<u32, String> {
    q.wait_for("BRAKE after the host stopped", 15, |t| {
        t.last().is_some_and(|l| l.brake)
    })?;
    let (frame, brake, age) =
        brake_after_last_frame(&q.trace()).ok_or("no BRAKE after a valid frame")?;
    let worst_ms = brake - frame + 1;
    expect(
        age == threshold && worst_ms <= threshold,
        &format!(
            "comm loss: BRAKE at age {age}, at most {worst_ms} ms after the last valid frame (bound {} ms)",
            threshold + 1
        ),
    )?;
    Ok(worst_ms)
}

fn cdc(q: &Qemu, ml: &Path) -> Result<String, String> {
    let pty = q.pty.as_str();
    // Power-on: BRAKE latched, every motor shorted.
    q.wait_for("the first tick", 10, |t| !t.is_empty())?;
    let l = last(q).ok_or("no trace line")?;
    expect(
        l.brake && l.out.iter().all(|t| t == "S"),
        "power-on: BRAKE, every motor shorted",
    )?;
    // 1. Ping: PING → STATUS round trip.
    let r = motorlink(ml, &["ping", "--kind", "serial", pty, "--count", "3"])?;
    expect(r.ok, "PING answered by a STATUS (round trip)")?;
    // 2. Enable, then (another process) drive: the re-arm waits for the first frame; the commanded
    // duties reach the traced outputs.
    let r = motorlink(ml, &["enable", "on", pty])?;
    expect(r.ok, "MOTOR_ENABLE 1 acknowledged with result 0")?;
    let r = motorlink(
        ml,
        &[
            "drive",
            pty,
            "--pwm",
            CDC_PWM,
            "--timeout-ms",
            "250",
            "--seconds",
            "2",
        ],
    )?;
    expect(r.ok, "2 s of SET_MOTOR_PWM at 50 Hz sent, STATUS received")?;
    // The trace is read from QEMU by a thread of its own: the line may still be on its way.
    q.wait_for(
        &format!("SET_MOTOR_PWM {CDC_PWM} reached the outputs as {CDC_OUT:?}"),
        10,
        |t| t.iter().any(|l| !l.brake && l.out == CDC_OUT),
    )?;
    // 3. Right after the drive, while the board still runs on its last frame: a corrupted frame
    // (a SET_MOTOR_PWM of -900 on every motor, one payload bit flipped) is refused and changes
    // nothing: no valid frame counted, -900 (−720 counts) never on an output.
    let before = last(q).ok_or("no trace line")?;
    let bad = corrupted_pwm_frame();
    let r = motorlink(ml, &["send-hex", pty, &bad, "--listen-ms", "100"])?;
    expect(r.ok, "corrupted frame written")?;
    q.wait_for("the corrupted frame refused", 10, |t| {
        t.last().is_some_and(|l| l.rejected == before.rejected + 1)
    })?;
    let t = q.trace();
    expect(
        refused_changed_nothing(&t, before.rejected + 1, |l| {
            l.out.iter().any(|o| o == "-720")
        }),
        "the corrupted frame counted as refused, never applied (no valid frame after it, -900 never on an output)",
    )?;
    // The host stopped: BRAKE within the frames' timeout_ms of 250 (threshold 249 ticks).
    let worst_250 = comm_loss_brake(q, 249)?;
    // 4. ESTOP: from a running drive, latched at once by the link; an enable is refused while it
    // holds; its release by the link leaves BRAKE latched; an explicit enable re-arms.
    let r = motorlink(
        ml,
        &[
            "drive",
            pty,
            "--enable",
            "--pwm",
            CDC_PWM,
            "--timeout-ms",
            "250",
            "--seconds",
            "1",
        ],
    )?;
    expect(r.ok, "drive --enable re-armed and drove")?;
    let r = motorlink(ml, &["estop", "engage", pty])?;
    expect(r.ok, "ESTOP 1 acknowledged with result 0")?;
    q.wait_for("ESTOP latched by the link", 10, |t| {
        t.last()
            .is_some_and(|l| l.brake && l.owners == 2 && l.out.iter().all(|o| o == "S"))
    })?;
    let t = q.trace();
    let i = t
        .iter()
        .position(|l| l.owners == 2)
        .ok_or("no ESTOP line")?;
    expect(
        i > 0 && !t[i - 1].brake && t[i].brake,
        &format!(
            "the ESTOP found the drive running (its last line before: tick {}) and braked it (tick {})",
            t[i.saturating_sub(1)].tick,
            t[i].tick
        ),
    )?;
    let r = motorlink(ml, &["enable", "on", pty])?;
    expect(
        !r.ok,
        "MOTOR_ENABLE 1 refused (result 1) while the ESTOP holds",
    )?;
    let r = motorlink(ml, &["estop", "release", pty])?;
    expect(r.ok, "ESTOP 0 from its owner acknowledged")?;
    q.wait_for("ESTOP released, still braked", 10, |t| {
        t.last().is_some_and(|l| l.brake && l.owners == 0)
    })?;
    let from = q.trace().len();
    let r = motorlink(
        ml,
        &[
            "drive",
            pty,
            "--enable",
            "--pwm",
            CDC_PWM,
            "--timeout-ms",
            "100",
            "--seconds",
            "1.5",
        ],
    )?;
    expect(
        r.ok,
        "re-armed by an explicit enable after the release, driving",
    )?;
    expect(
        q.trace()[from..]
            .iter()
            .any(|l| !l.brake && l.out == CDC_OUT),
        "the re-armed drive reached the outputs",
    )?;
    // 5. The host stops: BRAKE within the frames' timeout_ms of 100 (threshold 99 ticks).
    let worst_100 = comm_loss_brake(q, 99)?;
    Ok(format!(
        "cdc end to end: PASS (comm-loss BRAKE at most {worst_250} ms after the last frame with timeout_ms 250, {worst_100} ms with timeout_ms 100)"
    ))
}

/// A SET_MOTOR_PWM frame of -900 on every motor, timeout 200, with one payload bit flipped after
/// the CRC was computed (CRC-16/CCITT-FALSE written out here, independently of the protocol crate).
fn corrupted_pwm_frame() -> String {
    let mut body = vec![0x01u8, 10];
    for _ in 0..4 {
        body.extend_from_slice(&(-900i16).to_le_bytes());
    }
    body.extend_from_slice(&200u16.to_le_bytes());
    let mut crc: u16 = 0xFFFF;
    for b in &body {
        crc ^= u16::from(*b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    let mut frame = vec![0xAA, 0x55];
    frame.extend_from_slice(&body);
    frame.extend_from_slice(&crc.to_le_bytes());
    if let Some(b) = frame.get_mut(5) {
        *b ^= 0x10;
    }
    frame.iter().map(|b| format!("{b:02x}")).collect()
}

/// A robust MTRS frame from the host's own encoder with one data byte changed (kept non-zero, so
/// the frame keeps its length and its place in the stream, and fails its CRC).
fn corrupted_mtrs_frame(ml: &Path) -> Result<String, String> {
    let json = r#"{"cmd_type":"mtrs","is_relative":0,"mtr_angles":[-170,170,-170,170],"mtr_speed_deg_s":90,"mtr_accel_deg_s_s":0,"cmd_success":0}"#;
    let r = motorlink(
        ml,
        &["encode", "--frame", "teensy-robust", json, "--motors", "4"],
    )?;
    let hex = r.stdout.trim().to_string();
    let mut bytes: Vec<u8> = (0..hex.len() / 2)
        .filter_map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok())
        .collect();
    let b = bytes.get_mut(12).ok_or("frame too short")?;
    *b = if *b == 0x01 { 0x02 } else { 0x01 };
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

fn teensy(q: &Qemu, ml: &Path) -> Result<String, String> {
    let pty = q.pty.as_str();
    q.wait_for("the first tick", 10, |t| !t.is_empty())?;
    let r = motorlink(ml, &["ping", "--kind", "teensy", pty, "--count", "3"])?;
    expect(r.ok, "probe (ENDEFF_OFF) echoed (round trip)")?;
    // A relative move is refused (cmd_success 0, exit 1), and so is an acceleration above the
    // profile's; neither moves anything.
    let r = motorlink(
        ml,
        &[
            "move",
            pty,
            "--angles",
            "5,5,5,5",
            "--speed",
            "90",
            "--relative",
            "--once",
        ],
    )?;
    expect(!r.ok, "a relative MTRS echoed with cmd_success 0")?;
    let r = motorlink(ml, &["config", pty, "--accel", "1000000"])?;
    expect(
        !r.ok,
        "CONFIG above the profile's acceleration echoed with cmd_success 0",
    )?;
    // CAL then MTRS: 30°, -45°, 90°, 0° at 1600 steps per revolution are 133.3 → 133, -200, 400
    // and 0 steps. At 90°/s the 90° joint needs 1 s of the board's time; the emulated board runs
    // slower than the host's clock while it traces every step (about a quarter as fast on 2 busy
    // cores), so the host sends for 8 s.
    let want = ["+133", "-200", "+400", "+0"];
    let r = motorlink(
        ml,
        &[
            "move",
            pty,
            "--cal",
            "--angles",
            "30,-45,90,0",
            "--speed",
            "90",
            "--seconds",
            "8",
        ],
    )?;
    expect(r.ok, "CAL and MTRS echoed with cmd_success 1")?;
    // The trace is read from QEMU by a thread of its own: the line may still be on its way.
    q.wait_for(
        &format!("MTRS 30,-45,90,0 reached the step targets as {want:?}"),
        10,
        |t| t.iter().any(|l| !l.brake && l.out == want),
    )?;
    // A corrupted frame right after: refused, never applied (the joints stay where they are).
    let before = last(q).ok_or("no trace line")?;
    let bad = corrupted_mtrs_frame(ml)?;
    let r = motorlink(
        ml,
        &[
            "send-hex",
            "--kind",
            "teensy",
            pty,
            &bad,
            "--listen-ms",
            "100",
        ],
    )?;
    expect(r.ok, "corrupted frame written")?;
    q.wait_for("the corrupted frame refused", 10, |t| {
        t.last().is_some_and(|l| l.rejected == before.rejected + 1)
    })?;
    let worst = comm_loss_brake(q, 249)?;
    let t = q.trace();
    expect(
        refused_changed_nothing(&t, before.rejected + 1, |l| l.out != want),
        "the corrupted frame changed nothing: no valid frame after it, the joints stayed at the last valid angles",
    )?;
    Ok(format!(
        "teensy end to end: PASS (comm-loss BRAKE at most {worst} ms after the last frame, bound 250 ms)"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const LINES: &str = "char device redirected to /dev/pts/3 (label serial0)
tick=1 mode=Brake age=1 drive=BRAKE valid=0 rejected=0 refusals=0 owners=0 out=S S S S
tick=40 mode=Brake age=0 drive=BRAKE valid=1 rejected=0 refusals=0 owners=0 out=S S S S
tick=41 mode=Reduced age=0 drive=RUN valid=2 rejected=0 refusals=0 owners=0 out=+4 -4 C +4
tick=60 mode=Reduced age=1 drive=RUN valid=3 rejected=1 refusals=0 owners=0 out=+240 -240 C +400
tick=259 mode=Brake age=199 drive=BRAKE valid=3 rejected=1 refusals=0 owners=0 out=S S S S";

    #[test]
    fn reads_the_firmware_trace() {
        let t: Vec<Line> = LINES.lines().filter_map(parse).collect();
        assert_eq!(t.len(), 5, "the QEMU banner is not a trace line");
        assert_eq!(t[3].out, ["+240", "-240", "C", "+400"]);
        assert_eq!(
            (t[3].tick, t[3].rejected, t[3].mode.as_str()),
            (60, 1, "Reduced")
        );
        assert!(t[4].brake && !t[3].brake);
        // The last frame was counted at tick 60; BRAKE at 259, age 199.
        assert_eq!(brake_after_last_frame(&t), Some((60, 259, 199)));
        // Refused at tick 60 (rejected 1), nothing valid after it; −720 never on an output.
        assert!(refused_changed_nothing(&t, 1, |l| l
            .out
            .iter()
            .any(|o| o == "-720")));
        // A valid frame after the refusal, or the refused value on an output, fails the check.
        let mut later = t.clone();
        later[4].valid = 4;
        assert!(!refused_changed_nothing(&later, 1, |_| false));
        assert!(!refused_changed_nothing(&t, 1, |l| l
            .out
            .iter()
            .any(|o| o == "+240")));
        assert!(
            !refused_changed_nothing(&t, 2, |_| false),
            "no such refusal"
        );
    }

    #[test]
    fn the_corrupted_frame_fails_its_crc() {
        // The uncorrupted frame's CRC from the seed's algorithm, checked against the protocol
        // crate's encoder would tie the two together; instead the corruption must leave the
        // length and SOF intact and change one payload bit.
        let hex = corrupted_pwm_frame();
        assert_eq!(hex.len(), 32, "16 bytes");
        assert!(hex.starts_with("aa55010a"));
        // -900 = 0xFC7C little endian: 7c fc; byte 5 (0xfc) had bit 4 flipped to 0xec.
        assert_eq!(&hex[8..12], "7cec");
    }
}
