//! The operator's verbs of the AMR SPI link (seed 000, the primary link: spidev, 64-byte frames,
//! 1 kHz): `list`, `arm`, `disarm`, `rearm`, `estop`, `drive --v --w`, `teleop` and the live view
//! `top`, on a spidev device or on the simulated board (`--sim`).
//!
//! Every verb runs the host's own [`Bridge`] at 1 kHz, the code the robot runs, and reports what
//! the MCU's feedback showed. The MCU decides: the host asks (an enable 0→1 edge is the ladder's
//! re-arm request; fresh frames keep it armed), the feedback tells what happened.
//!
//! ```text
//!  verb start ── enable 0 frames (the ladder sees enable 0 after any latch) ── arm: enable 0→1
//!     ── cmd_vel frames ── end or Ctrl-C: cmd_vel 0, wheels ramp down ── enable 0 (STOP) ── exit
//!  after the last frame: HOLD at 2 ms, STOP at 5 ms, BRAKE (latched, COMM_LOST) at 10 ms
//! ```
//!
//! On this link the drive is armed only while a process streams frames: when a verb ends, its
//! frames end, and the board latches BRAKE 10 ms later. `arm` and `rearm` therefore show that the
//! latch can be cleared (and why not, if it cannot); `drive` and `teleop` arm, drive, and stop.
//!
//! The link has no ESTOP message. The board's ESTOP is its own input (the ladder's `Local`
//! source); the host's fastest stop is to end its frames (`estop`): the ladder brakes within
//! 10 ms (stop category 0), where enable 0 (`disarm`) stops under control (category 1).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use protocol::amr::{self, McuInfo, MotorFeedback, FRAME_LEN};
use serde::Serialize;
use serde_json::Value;
use statemachine::{FaultFlags, Mode};

use crate::bridge::{ArmState, Bridge, BridgeConfig, Diagnostic};
use crate::cli::exit::{Exit, Failure, OrExit, Run};
use crate::pacing::{Pacer, PeriodStats};
use crate::simlink::{SimClock, SimConfig, SimMcu, LOCKSTEP_RECV_US};
use crate::transport::{LinkError, SpiTransport, Transport};

pub mod list;
pub mod teleop;
pub mod top;

/// The default SPI clock of the AMR link, Hz.
pub const DEFAULT_SPI_HZ: u32 = 2_000_000;

/// The options every AMR-link verb takes besides its device.
#[derive(Args, Clone, Debug, Default)]
pub struct AmrOpts {
    /// Run against the simulated board (the board application on a simulated robot) instead of a
    /// device: no hardware needed. It starts as a board does, BRAKE latched after power-on.
    #[arg(long)]
    pub sim: bool,
    /// The simulated board's clock: paced (one board millisecond per exchange, the exchanges at
    /// 1 kHz: real time, immune to a loaded machine's scheduling), wall (its ticks follow real
    /// time: a host thread starved for 10 ms brakes it, as it would a real board), lockstep (one
    /// board millisecond per exchange, as fast as possible: deterministic, for tests).
    #[arg(long, value_enum, default_value = "paced")]
    pub sim_clock: SimClockArg,
    /// What the simulated board has been through before the verb starts (for tests): power-on,
    /// driving (armed, 0.3 m/s), estop-held (its ESTOP input pressed and held), braked (driven,
    /// then BRAKE latched by a frame gap).
    #[arg(long, value_enum, default_value = "power-on", hide = true)]
    pub sim_setup: SimSetup,
    /// Print one JSON object (the result) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The link of the verbs that only speak the AMR link (arm, disarm, rearm, teleop, top).
#[derive(Args, Clone, Debug)]
pub struct AmrLinkArgs {
    /// spidev device of the AMR link, e.g. /dev/spidev0.0 (omit with --sim).
    #[arg(required_unless_present = "sim")]
    pub device: Option<String>,
    /// SPI clock, Hz.
    #[arg(long, default_value_t = DEFAULT_SPI_HZ)]
    pub speed: u32,
    /// Simulation and output options.
    #[command(flatten)]
    pub opts: AmrOpts,
}

/// `--sim-clock`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum SimClockArg {
    /// The board's ticks follow wall time.
    Wall,
    /// One board millisecond per exchange, exchanges at 1 kHz on the wall clock.
    #[default]
    Paced,
    /// One board millisecond per exchange: deterministic.
    Lockstep,
}

/// `--sim-setup`: the simulated board's history before the verb starts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum SimSetup {
    /// Just powered on: BRAKE latched (POWER_ON).
    #[default]
    PowerOn,
    /// Armed and driving straight at 0.3 m/s (a host drove it until the verb took over).
    Driving,
    /// Its ESTOP input pressed and still held: BRAKE latched (ESTOP).
    EstopHeld,
    /// Driven, then a frame gap: BRAKE latched (COMM_LOST), nothing holding it.
    Braked,
}

/// How a verb ended; the exit status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// The MCU did what was asked.
    Done,
    /// The MCU answered and did not do it (stayed in BRAKE, an ESTOP holds).
    Refused,
    /// No valid feedback came back.
    NoReply,
}

impl Outcome {
    /// Exit status: done 0, refused 1 (a check failed), no reply 69 (the device is unavailable);
    /// errors before or outside the exchange are a [`Failure`] of their own (64 a bad argument,
    /// 69 a device that does not open, 74 a failed exchange).
    pub const fn exit(self) -> Exit {
        match self {
            Self::Done => Exit::Ok,
            Self::Refused => Exit::Failed,
            Self::NoReply => Exit::Unavailable,
        }
    }
}

/// A seed 000 link with its time base: one exchange per cycle, on a device or the simulated board.
pub trait Port {
    /// Waits for the next cycle's start (the 1 ms deadline) and returns the host time then, µs.
    fn begin_cycle(&mut self) -> u64;
    /// One full-duplex exchange started at `t_send`; returns the host time the reply was in, µs.
    fn exchange(
        &mut self,
        t_send: u64,
        tx: &[u8; FRAME_LEN],
        rx: &mut [u8; FRAME_LEN],
    ) -> Result<u64, LinkError>;
    /// Lets `ms` milliseconds pass with no frame at all (a frame gap).
    fn gap(&mut self, ms: u64);
    /// The device's name, for messages.
    fn name(&self) -> &str;
    /// The 1 kHz loop's period statistics (a wall-clock port).
    fn pacing(&self) -> Option<&PeriodStats> {
        None
    }
    /// The simulated board's ground truth as JSON (a simulated port).
    fn truth(&self) -> Option<Value> {
        None
    }
}

/// A transport on the wall clock: 1 ms absolute deadlines ([`Pacer`]).
pub struct Paced<T> {
    /// The byte link.
    pub transport: T,
    pacer: Pacer,
    epoch: Instant,
}

impl<T: Transport> Paced<T> {
    /// `transport` paced at the seed's 1 ms contract.
    pub fn new(transport: T) -> Self {
        Self {
            transport,
            pacer: Pacer::contract(),
            epoch: Instant::now(),
        }
    }

    fn now(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
    }
}

impl<T: Transport> Port for Paced<T> {
    fn begin_cycle(&mut self) -> u64 {
        self.pacer.wait();
        self.now()
    }

    fn exchange(
        &mut self,
        _t_send: u64,
        tx: &[u8; FRAME_LEN],
        rx: &mut [u8; FRAME_LEN],
    ) -> Result<u64, LinkError> {
        self.transport.exchange(tx, rx)?;
        Ok(self.now())
    }

    fn gap(&mut self, ms: u64) {
        std::thread::sleep(Duration::from_millis(ms));
        // Deadlines start again after the gap (the gap is no late period of the loop).
        let stats = std::mem::replace(&mut self.pacer, Pacer::contract()).stats;
        self.pacer.stats = stats;
    }

    fn name(&self) -> &str {
        self.transport.name()
    }

    fn pacing(&self) -> Option<&PeriodStats> {
        Some(&self.pacer.stats)
    }
}

pub use crate::names::{fault_names, mode_name, FAULT_NAMES};

/// One feedback as the verbs show it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FeedbackView {
    /// Ladder rung name.
    pub mode: &'static str,
    /// Fault flags by name.
    pub faults: Vec<String>,
    /// Wheel speeds (left, right), rad/s.
    pub wheel_radps: [f32; 2],
    /// Motor currents (left, right), A.
    pub current_a: [f32; 2],
    /// Encoder counts (left, right).
    pub encoder: [i32; 2],
    /// The MCU's clock, µs.
    pub mcu_us: u32,
}

impl From<&MotorFeedback> for FeedbackView {
    fn from(f: &MotorFeedback) -> Self {
        Self {
            mode: mode_name(f.mode),
            faults: fault_names(f.fault_flags),
            wheel_radps: [f.left_speed, f.right_speed],
            current_a: [f.left_current, f.right_current],
            encoder: [f.left_encoder, f.right_encoder],
            mcu_us: f.timestamp_us,
        }
    }
}

/// One feedback sample kept for the plots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Host time it arrived, µs.
    pub t_us: u64,
    /// The feedback.
    pub fb: MotorFeedback,
}

/// The last feedback samples (a bounded ring, oldest first).
#[derive(Clone, Debug, Default)]
pub struct History {
    samples: std::collections::VecDeque<Sample>,
    cap: usize,
}

impl History {
    /// Keeps at most `cap` samples.
    pub fn new(cap: usize) -> Self {
        Self {
            samples: std::collections::VecDeque::with_capacity(cap.min(1 << 16)),
            cap,
        }
    }

    /// Adds one sample, dropping the oldest beyond the capacity.
    pub fn push(&mut self, s: Sample) {
        if self.cap == 0 {
            return;
        }
        while self.samples.len() >= self.cap {
            self.samples.pop_front();
        }
        self.samples.push_back(s);
    }

    /// The samples, oldest first.
    pub fn iter(&self) -> impl DoubleEndedIterator<Item = &Sample> + '_ {
        self.samples.iter()
    }

    /// How many samples are kept.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True if none is kept.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

/// Counters of a session.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct LinkCounters {
    /// Exchanges made.
    pub exchanges: u64,
    /// Exchanges that failed at the transport.
    pub transport_errors: u64,
    /// Feedback frames decoded.
    pub feedback_ok: u64,
    /// Feedback-slot frames refused (CRC, decoding).
    pub feedback_rejected: u64,
    /// Exchanges where the MCU had not accepted the previous command.
    pub not_accepted: u64,
    /// Frame gaps made on purpose (`estop`, teleop's stop key).
    pub gaps: u64,
    /// Diagnostics raised, by name.
    pub diagnostics: BTreeMap<&'static str, u64>,
    /// The longest gap between two of the host's own cycles that was reported late, µs.
    pub host_late_max_us: u64,
}

/// The bridge bound to a port: one exchange per [`Session::cycle`].
pub struct Session<P: Port> {
    /// The link.
    pub port: P,
    /// The bridge state machine.
    pub bridge: Bridge,
    /// Counters.
    pub counters: LinkCounters,
    /// The last feedback samples (2 s at 1 kHz).
    pub history: History,
    /// Recent diagnostics (at most 64), host time µs.
    pub recent: std::collections::VecDeque<(u64, Diagnostic)>,
    /// Host time of the current cycle, µs.
    pub now_us: u64,
    /// Host time of the last decoded feedback, µs.
    pub last_feedback_us: Option<u64>,
    /// Modes seen, in order, each change once.
    pub modes_seen: Vec<&'static str>,
}

/// How many diagnostics [`Session::recent`] keeps.
const RECENT: usize = 64;

impl<P: Port> Session<P> {
    /// A disarmed bridge on `port` that asks the MCU who it is on its first command.
    pub fn new(port: P) -> Self {
        let mut bridge = Bridge::new(BridgeConfig::DEFAULT);
        bridge.request_identity();
        Self {
            port,
            bridge,
            counters: LinkCounters::default(),
            history: History::new(2_000),
            recent: std::collections::VecDeque::new(),
            now_us: 0,
            last_feedback_us: None,
            modes_seen: Vec::new(),
        }
    }

    /// The last feedback decoded.
    pub fn feedback(&self) -> Option<MotorFeedback> {
        self.bridge.last_feedback
    }

    /// The last feedback's age now, µs.
    pub fn feedback_age_us(&self) -> Option<u64> {
        self.last_feedback_us.map(|t| self.now_us.saturating_sub(t))
    }

    /// True if the last feedback shows the ladder in BRAKE.
    pub fn mcu_braked(&self) -> bool {
        self.feedback()
            .is_some_and(|f| f.mode == Mode::Brake as u32)
    }

    /// Waits for the next deadline and makes one exchange.
    pub fn cycle(&mut self) -> Result<(), LinkError> {
        let t_send = self.port.begin_cycle();
        self.now_us = t_send;
        let cmd = self.bridge.next_command(t_send);
        let mut tx = [0u8; FRAME_LEN];
        let mut rx = [0u8; FRAME_LEN];
        amr::encode_command(&cmd, &mut tx);
        self.counters.exchanges = self.counters.exchanges.saturating_add(1);
        let t_recv = match self.port.exchange(t_send, &tx, &mut rx) {
            Ok(t) => t,
            Err(e) => {
                self.counters.transport_errors = self.counters.transport_errors.saturating_add(1);
                return Err(e);
            }
        };
        let b = self.bridge.stats;
        self.bridge
            .on_frame(t_send, t_recv, cmd.seq, amr::decode_mcu_frame(&rx));
        let s = self.bridge.stats;
        let c = &mut self.counters;
        c.feedback_ok = c
            .feedback_ok
            .saturating_add(s.feedback_ok.saturating_sub(b.feedback_ok));
        c.feedback_rejected = c
            .feedback_rejected
            .saturating_add(s.feedback_rejected.saturating_sub(b.feedback_rejected));
        c.not_accepted = c
            .not_accepted
            .saturating_add(s.not_accepted.saturating_sub(b.not_accepted));
        if s.feedback_ok != b.feedback_ok {
            self.last_feedback_us = Some(t_recv);
            if let Some(fb) = self.bridge.last_feedback {
                self.history.push(Sample { t_us: t_recv, fb });
                let m = mode_name(fb.mode);
                if self.modes_seen.last() != Some(&m) {
                    self.modes_seen.push(m);
                }
            }
        }
        for (t, d) in self.bridge.drain() {
            if let Diagnostic::HostLate { gap_us } = d {
                self.counters.host_late_max_us = self.counters.host_late_max_us.max(gap_us);
            }
            let c = self.counters.diagnostics.entry(d.name()).or_insert(0);
            *c = c.saturating_add(1);
            while self.recent.len() >= RECENT {
                self.recent.pop_front();
            }
            self.recent.push_back((t, d));
        }
        Ok(())
    }

    /// Runs `n` cycles, or fewer if `stop` says so; true if stopped.
    pub fn run(&mut self, n: u64, stop: &mut dyn FnMut() -> bool) -> Result<bool, LinkError> {
        for _ in 0..n {
            if stop() {
                return Ok(true);
            }
            self.cycle()?;
        }
        Ok(false)
    }

    /// Lets `ms` pass with no frame (the ladder: HOLD at 2 ms, STOP at 5, BRAKE at 10).
    pub fn gap(&mut self, ms: u64) {
        self.counters.gaps = self.counters.gaps.saturating_add(1);
        self.port.gap(ms);
    }

    /// The arming sequence (from Disarmed or Latched): enable 0, then the 0→1 edge, cmd_vel 0,
    /// until the MCU's feedback shows it out of BRAKE with the bridge armed, the bridge gives up
    /// (the MCU stayed in BRAKE: `arm_refused`), `timeout_ms` passes or `stop` says so.
    pub fn arm_and_wait(
        &mut self,
        timeout_ms: u64,
        stop: &mut dyn FnMut() -> bool,
    ) -> Result<ArmResult, LinkError> {
        // Enable 0 first, so the ladder sees enable 0 after its latch whatever came before.
        self.bridge.disarm();
        self.run(SETTLE_CYCLES, stop)?;
        self.bridge.arm(self.now_us);
        let mut armed_cycles = 0u64;
        for _ in 0..timeout_ms {
            if stop() {
                return Ok(ArmResult::Stopped);
            }
            self.bridge.cmd_vel(self.now_us, 0.0, 0.0);
            self.cycle()?;
            match self.bridge.state() {
                ArmState::Armed => armed_cycles = armed_cycles.saturating_add(1),
                ArmState::Latched => return Ok(ArmResult::Refused),
                ArmState::Disarmed | ArmState::Arming(_) => {}
            }
            // Two exchanges after the edge the feedback reflects it (it is prepared one frame late).
            if armed_cycles > 2 && self.feedback().is_some() && !self.mcu_braked() {
                return Ok(ArmResult::Armed);
            }
        }
        if self.feedback().is_none() {
            return Ok(ArmResult::NoFeedback);
        }
        self.bridge.disarm();
        Ok(ArmResult::Refused)
    }

    /// Commands zero until both wheels have been below [`STILL_RADPS`] for [`STILL_CYCLES`]
    /// feedbacks in a row (at most `max_ms`), then enable 0 for [`SETTLE_CYCLES`]: the MCU ends in
    /// STOP with the speed loop holding zero.
    pub fn stop_and_disarm(&mut self, max_ms: u64) -> Result<(), LinkError> {
        if self.bridge.state() == ArmState::Armed {
            let mut still_for = 0u64;
            for _ in 0..max_ms {
                self.bridge.cmd_vel(self.now_us, 0.0, 0.0);
                self.cycle()?;
                let still = self.feedback().is_none_or(|f| {
                    f.left_speed.abs() < STILL_RADPS && f.right_speed.abs() < STILL_RADPS
                });
                let zero = self.bridge.output().iter().all(|o| o.abs() < 1e-9);
                still_for = if still && zero {
                    still_for.saturating_add(1)
                } else {
                    0
                };
                if still_for >= STILL_CYCLES {
                    break;
                }
            }
        }
        self.bridge.disarm();
        let mut never = || false;
        self.run(SETTLE_CYCLES, &mut never)?;
        Ok(())
    }
}

/// Cycles of enable 0 before an arming edge and after a stop.
pub const SETTLE_CYCLES: u64 = 20;

/// Feedbacks in a row with both wheels standing before the drive is disabled.
pub const STILL_CYCLES: u64 = 50;

/// A wheel slower than this counts as standing, rad/s.
pub const STILL_RADPS: f32 = 0.05;

/// What the arming sequence ended with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArmResult {
    /// The MCU left BRAKE and the bridge is armed.
    Armed,
    /// The MCU stayed in BRAKE (a latching cause, such as a held ESTOP, is active).
    Refused,
    /// No valid feedback at all.
    NoFeedback,
    /// Stopped by the operator (Ctrl-C).
    Stopped,
}

/// The result of a verb: what it printed as JSON, and its exit status.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The verb.
    pub verb: &'static str,
    /// How it ended.
    pub verdict: Outcome,
    /// The device (or "sim").
    pub device: String,
    /// What the MCU did, in words.
    pub message: String,
    /// The first feedback of the run.
    pub before: Option<FeedbackView>,
    /// The last feedback of the run.
    pub after: Option<FeedbackView>,
    /// Modes seen, in order.
    pub modes_seen: Vec<&'static str>,
    /// The drive's summary (`drive`, `teleop`).
    pub drive: Option<DriveSummary>,
    /// Counters, diagnostics by name.
    pub counters: LinkCounters,
    /// The 1 kHz loop's periods (wall clock).
    pub pacing: Option<Value>,
    /// Ended by Ctrl-C (or another stop signal).
    pub interrupted: bool,
    /// The simulated board's ground truth at the end (`--sim`).
    pub sim_truth: Option<Value>,
    /// The MCU's identity (firmware version, board, reset cause), asked on the first frame.
    pub mcu_info: Option<McuInfo>,
}

impl Report {
    /// The report of a session so far.
    pub fn new<P: Port>(
        verb: &'static str,
        s: &Session<P>,
        before: Option<MotorFeedback>,
        verdict: Outcome,
        message: String,
    ) -> Self {
        Self {
            verb,
            verdict,
            device: s.port.name().to_string(),
            message,
            before: before.as_ref().map(FeedbackView::from),
            after: s.feedback().as_ref().map(FeedbackView::from),
            modes_seen: s.modes_seen.clone(),
            drive: None,
            counters: s.counters.clone(),
            pacing: s.port.pacing().map(pacing_json),
            interrupted: false,
            sim_truth: s.port.truth(),
            mcu_info: s.bridge.mcu_info(),
        }
    }

    /// The report as text for an operator.
    pub fn text(&self) -> String {
        let mut t = format!(
            "{}: {} ({})\n  {}\n",
            self.verb,
            match self.verdict {
                Outcome::Done => "done",
                Outcome::Refused => "REFUSED",
                Outcome::NoReply => "NO REPLY",
            },
            self.device,
            self.message
        );
        let fb_line = |label: &str, f: &FeedbackView| {
            format!(
                "  {label:7} mode {:7} wheels {:+7.2} {:+7.2} rad/s  currents {:+6.2} {:+6.2} A  faults {}\n",
                f.mode,
                f.wheel_radps[0],
                f.wheel_radps[1],
                f.current_a[0],
                f.current_a[1],
                if f.faults.is_empty() {
                    "none".to_string()
                } else {
                    f.faults.join(",")
                }
            )
        };
        if let Some(f) = &self.before {
            t.push_str(&fb_line("before", f));
        }
        if let Some(f) = &self.after {
            t.push_str(&fb_line("after", f));
        }
        if !self.modes_seen.is_empty() {
            t.push_str(&format!("  modes   {}\n", self.modes_seen.join(" -> ")));
        }
        if let Some(d) = &self.drive {
            t.push_str(&d.text());
        }
        let c = &self.counters;
        t.push_str(&format!(
            "  link    {} exchanges, {} feedback ok, {} refused, {} not accepted, {} transport errors\n",
            c.exchanges, c.feedback_ok, c.feedback_rejected, c.not_accepted, c.transport_errors
        ));
        if !c.diagnostics.is_empty() {
            let d: Vec<String> = c
                .diagnostics
                .iter()
                .map(|(k, v)| format!("{k} x{v}"))
                .collect();
            t.push_str(&format!("  diags   {}\n", d.join(", ")));
        }
        if let Some(i) = &self.mcu_info {
            let (ma, mi, pa) = i.fw_version_parts();
            t.push_str(&format!(
                "  mcu     firmware {ma}.{mi}.{pa}, board {:?}, reset cause {:?}, {} resets\n",
                i.board, i.reset_cause, i.reset_count
            ));
        }
        if self.interrupted {
            t.push_str("  interrupted (Ctrl-C): stopped and disarmed\n");
        }
        t
    }

    /// The report as one JSON object.
    pub fn json(&self) -> Value {
        serde_json::to_value(self).unwrap_or(Value::Null)
    }
}

/// Period statistics as JSON.
fn pacing_json(s: &PeriodStats) -> Value {
    serde_json::json!({"periods": s.count, "misses": s.misses, "skipped": s.skipped,
        "mean_us": s.mean_us(), "max_us": s.max_us})
}

/// What `drive` (and `teleop`) did, from the MCU's feedback.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DriveSummary {
    /// Commanded forward speed, m/s.
    pub v_cmd: f64,
    /// Commanded yaw rate, rad/s.
    pub w_cmd: f64,
    /// How long the twist was commanded, s.
    pub seconds: f64,
    /// Distance the feedback's wheel speeds integrate to (forward kinematics), m.
    pub distance_m: f64,
    /// Heading change they integrate to, rad.
    pub heading_rad: f64,
    /// Mean forward speed over the second half of the command, m/s.
    pub mean_v_mps: f64,
    /// Mean yaw rate over the second half of the command, rad/s.
    pub mean_w_radps: f64,
    /// Largest |wheel speed| seen (left, right), rad/s.
    pub peak_wheel_radps: [f32; 2],
    /// Largest |current| seen (left, right), A.
    pub peak_current_a: [f32; 2],
}

impl DriveSummary {
    fn text(&self) -> String {
        format!(
            "  drive   v {:+.3} m/s, w {:+.3} rad/s for {:.2} s: travelled {:.3} m, turned {:+.3} rad; second half mean v {:+.3} m/s, w {:+.3} rad/s\n  peaks   wheels {:.2} {:.2} rad/s, currents {:.2} {:.2} A\n",
            self.v_cmd,
            self.w_cmd,
            self.seconds,
            self.distance_m,
            self.heading_rad,
            self.mean_v_mps,
            self.mean_w_radps,
            self.peak_wheel_radps[0],
            self.peak_wheel_radps[1],
            self.peak_current_a[0],
            self.peak_current_a[1]
        )
    }
}

/// Accumulates a [`DriveSummary`] from the feedback of each cycle.
#[derive(Clone, Debug, Default)]
pub struct DriveMeter {
    /// The summary so far.
    pub summary: DriveSummary,
    last_t: Option<u64>,
    half: (f64, f64, u64),
}

impl DriveMeter {
    /// Adds the feedback received at `t_us`; `second_half` marks the samples the means are over.
    pub fn add(
        &mut self,
        kin: &crate::DiffDrive,
        t_us: u64,
        fb: &MotorFeedback,
        second_half: bool,
    ) {
        let (v, w) = kin.forward(f64::from(fb.left_speed), f64::from(fb.right_speed));
        if let Some(prev) = self.last_t {
            let dt = t_us.saturating_sub(prev) as f64 * 1e-6;
            self.summary.distance_m += v * dt;
            self.summary.heading_rad += w * dt;
        }
        self.last_t = Some(t_us);
        if second_half {
            self.half.0 += v;
            self.half.1 += w;
            self.half.2 = self.half.2.saturating_add(1);
            let n = self.half.2 as f64;
            self.summary.mean_v_mps = self.half.0 / n;
            self.summary.mean_w_radps = self.half.1 / n;
        }
        let s = &mut self.summary;
        for (p, x) in s
            .peak_wheel_radps
            .iter_mut()
            .zip([fb.left_speed, fb.right_speed])
        {
            *p = p.max(x.abs());
        }
        for (p, x) in s
            .peak_current_a
            .iter_mut()
            .zip([fb.left_current, fb.right_current])
        {
            *p = p.max(x.abs());
        }
    }
}

/// Checks a twist against the robot's limits: finite, |v| and |ω| each reachable with no wheel
/// above its maximum speed.
pub fn check_twist(v: f64, w: f64) -> Result<(), String> {
    let k = BridgeConfig::DEFAULT.kinematics.config();
    let v_max = k.max_wheel_speed * k.wheel_radius_m;
    let w_max = 2.0 * v_max / k.wheelbase_m;
    if !v.is_finite() || v.abs() > v_max {
        return Err(format!(
            "--v {v}: the forward speed must be within +-{v_max:.2} m/s (the wheels' {} rad/s on {} m wheels); nothing was sent",
            k.max_wheel_speed, k.wheel_radius_m
        ));
    }
    if !w.is_finite() || w.abs() > w_max {
        return Err(format!(
            "--w {w}: the yaw rate must be within +-{w_max:.2} rad/s; nothing was sent"
        ));
    }
    Ok(())
}

/// The hint for a MCU that stayed in BRAKE, from its fault flags.
pub fn brake_hint(flags: u32) -> String {
    let f = FaultFlags(u16::try_from(flags).unwrap_or(u16::MAX));
    let mut why = Vec::new();
    if f.contains(FaultFlags::ESTOP) {
        why.push("the board's ESTOP input is engaged: release it at the robot, then rearm");
    }
    if f.contains(FaultFlags::OVERCURRENT) {
        why.push("overcurrent is still active: check the motors and wiring");
    }
    if f.contains(FaultFlags::OVERTEMPERATURE) {
        why.push("the driver is over temperature: let it cool");
    }
    if f.contains(FaultFlags::UNDERVOLTAGE) {
        why.push("the driver reports a fault or undervoltage: check the battery");
    }
    if f.contains(FaultFlags::ENCODER) {
        why.push("an encoder reads implausibly: check its cable");
    }
    if f.contains(FaultFlags::SHUTDOWN) {
        why.push("a shutdown request is asserted");
    }
    if why.is_empty() {
        "no latching cause is flagged; check the link (frames must keep coming) and try again"
            .into()
    } else {
        why.join("; ")
    }
}

/// Why the link may have lapsed: this host's own late cycles, if any.
fn late_hint<P: Port>(s: &Session<P>) -> String {
    let late = s
        .counters
        .diagnostics
        .get("host_late")
        .copied()
        .unwrap_or(0);
    if late == 0 {
        return String::new();
    }
    format!(
        "; this host was late {late} time(s) (the longest gap {:.1} ms; the board brakes 10 ms after a frame): a loaded machine or no real-time priority{}",
        s.counters.host_late_max_us as f64 * 1e-3,
        if s.port.name() == "sim" {
            " (with --sim, --sim-clock paced is immune to it)"
        } else {
            ""
        }
    )
}

/// Receives a first feedback (enable 0 frames, at most `ms`): what the MCU shows before the verb
/// acts.
fn first_feedback<P: Port>(
    s: &mut Session<P>,
    ms: u64,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Option<MotorFeedback>, LinkError> {
    for _ in 0..ms {
        if s.feedback().is_some() || stop() {
            break;
        }
        s.cycle()?;
    }
    Ok(s.feedback())
}

/// How long the verbs wait for the MCU, ms.
pub const WAIT_MS: u64 = 500;

/// `arm` and `rearm`: the ladder's re-arm (enable 0, then the 0→1 edge, then fresh frames);
/// report whether the MCU left BRAKE, then command zero and disarm.
pub fn arm<P: Port>(
    s: &mut Session<P>,
    verb: &'static str,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Report, LinkError> {
    let b = match begin(s, verb, stop)? {
        Ok(b) => b,
        Err(r) => return Ok(r),
    };
    let before = Some(b);
    if verb == "rearm" && b.mode != Mode::Brake as u32 {
        let msg = format!(
            "the MCU is in {}, not BRAKE: no latch to clear",
            mode_name(b.mode)
        );
        return Ok(Report::new(verb, s, before, Outcome::Done, msg));
    }
    let result = s.arm_and_wait(WAIT_MS, stop)?;
    let (verdict, msg) = match result {
        ArmResult::Armed => {
            let mode = s.feedback().map_or("?", |f| mode_name(f.mode));
            let what = if b.mode == Mode::Brake as u32 {
                "left BRAKE"
            } else {
                "armed"
            };
            (Outcome::Done, format!(
                "the MCU {what} ({} -> {mode}) after the re-arm edge and fresh frames; it stays armed only while frames keep coming: this verb now commands zero and enable 0 (STOP), and the board brakes (COMM_LOST) 10 ms after its last frame",
                mode_name(b.mode)
            ))
        }
        ArmResult::Refused => {
            let flags = s.feedback().map_or(0, |f| f.fault_flags);
            (
                Outcome::Refused,
                format!(
                    "the MCU stayed in BRAKE (faults {}): {}",
                    fault_names(flags).join(","),
                    brake_hint(flags)
                ),
            )
        }
        ArmResult::NoFeedback => (Outcome::NoReply, no_feedback(s)),
        ArmResult::Stopped => (
            Outcome::Refused,
            "interrupted before the MCU answered".into(),
        ),
    };
    s.stop_and_disarm(1_000)?;
    let mut r = Report::new(verb, s, before, verdict, msg);
    r.interrupted = result == ArmResult::Stopped;
    Ok(r)
}

fn no_feedback<P: Port>(s: &Session<P>) -> String {
    format!(
        "no valid feedback from {} ({} exchanges, {} frames refused): check wiring, SPI mode 0, and that the firmware runs",
        s.port.name(),
        s.counters.exchanges,
        s.counters.feedback_rejected
    )
}

/// The start of `arm`, `rearm`, `disarm` and `drive`: enable 0, then the first valid feedback
/// within [`WAIT_MS`]; without one the verb's report is a no-reply (`Err`).
fn begin<P: Port>(
    s: &mut Session<P>,
    verb: &'static str,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Result<MotorFeedback, Report>, LinkError> {
    s.bridge.disarm();
    Ok(match first_feedback(s, WAIT_MS, stop)? {
        Some(f) => Ok(f),
        None => Err(Report::new(verb, s, None, Outcome::NoReply, no_feedback(s))),
    })
}

/// `disarm`: enable 0 (the ladder's STOP: zero speed under the speed loop, bounded deceleration)
/// for `seconds`, or until the wheels stand; report the MCU's mode and wheel speeds.
pub fn disarm<P: Port>(
    s: &mut Session<P>,
    seconds: f64,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Report, LinkError> {
    let before = match begin(s, "disarm", stop)? {
        Ok(b) => Some(b),
        Err(r) => return Ok(r),
    };
    let cycles = cycles_of(seconds);
    let mut stood = false;
    let mut interrupted = false;
    for _ in 0..cycles {
        if stop() {
            interrupted = true;
            break;
        }
        s.cycle()?;
        let f = s.feedback();
        if f.is_some_and(|f| {
            f.mode != Mode::Normal as u32
                && f.mode != Mode::Reduced as u32
                && f.left_speed.abs() < STILL_RADPS
                && f.right_speed.abs() < STILL_RADPS
        }) {
            stood = true;
            break;
        }
    }
    let mut never = || false;
    s.run(SETTLE_CYCLES, &mut never)?;
    let f = s.feedback().unwrap_or_default();
    let (verdict, msg) = if stood && f.mode == Mode::Brake as u32 {
        (
            Outcome::Done,
            "the MCU is in BRAKE with the wheels standing: nothing to disarm".to_string(),
        )
    } else if stood {
        (
            Outcome::Done,
            format!(
                "the MCU is in {} with the wheels standing (enable 0: zero speed under the speed loop); the board brakes (COMM_LOST) 10 ms after this verb's last frame",
                mode_name(f.mode)
            ),
        )
    } else {
        (
            Outcome::Refused,
            format!(
                "the wheels still turn after {seconds} s of enable 0 ({} {} rad/s, mode {})",
                f.left_speed,
                f.right_speed,
                mode_name(f.mode)
            ),
        )
    };
    let mut r = Report::new("disarm", s, before, verdict, msg);
    r.interrupted = interrupted;
    Ok(r)
}

/// Cycles in `seconds` (1 kHz), at least one.
pub fn cycles_of(seconds: f64) -> u64 {
    let c = (seconds * 1000.0).round();
    if c.is_finite() && c >= 1.0 {
        c.min(1e12) as u64
    } else {
        1
    }
}

/// The frame gap `estop` makes, ms: the ladder brakes at 10 ms; 20 leaves a margin for a tick.
pub const ESTOP_GAP_MS: u64 = 20;

/// `estop`: the host's fastest stop on this link, a frame gap (no frame for [`ESTOP_GAP_MS`]):
/// the ladder goes HOLD at 2 ms, STOP at 5, BRAKE latched (COMM_LOST) at 10. Then enable 0 frames
/// read the feedback back. Done if the MCU shows BRAKE. The latch is cleared by `rearm`.
pub fn estop<P: Port>(
    s: &mut Session<P>,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Report, LinkError> {
    s.bridge.disarm();
    let before = first_feedback(s, WAIT_MS, stop)?;
    s.gap(ESTOP_GAP_MS);
    let mut never = || false;
    s.run(SETTLE_CYCLES, &mut never)?;
    let (verdict, msg) = match s.feedback() {
        None => (Outcome::NoReply, no_feedback(s)),
        Some(f) if f.mode == Mode::Brake as u32 => (
            Outcome::Done,
            format!(
                "the MCU is in BRAKE (faults {}) after a {ESTOP_GAP_MS} ms frame gap: this link has no ESTOP message, a gap of 10 ms brakes; clear the latch with rearm",
                fault_names(f.fault_flags).join(",")
            ),
        ),
        Some(f) => (
            Outcome::Refused,
            format!(
                "the MCU is in {} after a {ESTOP_GAP_MS} ms frame gap, not BRAKE: its comm-loss watchdog did not act; do not drive this board",
                mode_name(f.mode)
            ),
        ),
    };
    Ok(Report::new("estop", s, before, verdict, msg))
}

/// `estop --release`: this link has no ESTOP to release. Reads the feedback (enable 0 frames) and
/// reports whether the board's own ESTOP input still holds: done if not (a BRAKE latch is then
/// cleared by `rearm`), refused if it does (release it at the robot).
pub fn estop_release<P: Port>(
    s: &mut Session<P>,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Report, LinkError> {
    s.bridge.disarm();
    let before = first_feedback(s, WAIT_MS, stop)?;
    let mut never = || false;
    s.run(SETTLE_CYCLES, &mut never)?;
    let (verdict, msg) = match s.feedback() {
        None => (Outcome::NoReply, no_feedback(s)),
        Some(f) if FaultFlags(u16::try_from(f.fault_flags).unwrap_or(u16::MAX)).contains(FaultFlags::ESTOP) => (
            Outcome::Refused,
            "the board's ESTOP input is still engaged; the AMR link cannot release it: release it at the robot, then rearm".to_string(),
        ),
        Some(f) if f.mode == Mode::Brake as u32 => (
            Outcome::Done,
            "no ESTOP holds (the AMR link has none of its own); the MCU is in BRAKE: clear the latch with rearm".to_string(),
        ),
        Some(f) => (
            Outcome::Done,
            format!("no ESTOP holds; the MCU is in {}", mode_name(f.mode)),
        ),
    };
    Ok(Report::new("estop", s, before, verdict, msg))
}

/// `drive --v --w --seconds`: arm, command the twist for `seconds` (cmd_vel refreshed every
/// cycle), then command zero until the wheels stand and disarm; also on `stop` (Ctrl-C).
pub fn drive<P: Port>(
    s: &mut Session<P>,
    v: f64,
    w: f64,
    seconds: f64,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Report, LinkError> {
    let before = match begin(s, "drive", stop)? {
        Ok(b) => Some(b),
        Err(r) => return Ok(r),
    };
    let armed = s.arm_and_wait(WAIT_MS, stop)?;
    if armed != ArmResult::Armed {
        let flags = s.feedback().map_or(0, |f| f.fault_flags);
        let (verdict, msg) = match armed {
            ArmResult::NoFeedback => (Outcome::NoReply, no_feedback(s)),
            ArmResult::Stopped => (Outcome::Refused, "interrupted before arming".into()),
            _ => (
                Outcome::Refused,
                format!(
                    "the MCU stayed in BRAKE (faults {}): {}; nothing was driven",
                    fault_names(flags).join(","),
                    brake_hint(flags)
                ),
            ),
        };
        s.stop_and_disarm(1_000)?;
        let mut r = Report::new("drive", s, before, verdict, msg);
        r.interrupted = armed == ArmResult::Stopped;
        return Ok(r);
    }
    let kin = BridgeConfig::DEFAULT.kinematics;
    let mut meter = DriveMeter {
        summary: DriveSummary {
            v_cmd: v,
            w_cmd: w,
            ..DriveSummary::default()
        },
        ..DriveMeter::default()
    };
    let cycles = cycles_of(seconds);
    let half = cycles / 2;
    let mut interrupted = false;
    let mut latched = false;
    let mut done = 0u64;
    for k in 0..cycles {
        if stop() {
            interrupted = true;
            break;
        }
        s.bridge.cmd_vel(s.now_us, v, w);
        s.cycle()?;
        done = done.saturating_add(1);
        if let (Some(fb), Some(t)) = (s.feedback(), s.last_feedback_us) {
            meter.add(&kin, t, &fb, k >= half);
        }
        if s.bridge.state() == ArmState::Latched {
            latched = true;
            break;
        }
    }
    meter.summary.seconds = done as f64 * 1e-3;
    // The ramp down counts in the distance too: the samples that came during it.
    let ok_before = s.counters.feedback_ok;
    s.stop_and_disarm(3_000)?;
    let ramp = usize::try_from(s.counters.feedback_ok.saturating_sub(ok_before)).unwrap_or(0);
    let tail: Vec<Sample> = s.history.iter().rev().take(ramp).copied().collect();
    for smp in tail.iter().rev() {
        meter.add(&kin, smp.t_us, &smp.fb, false);
    }
    let (verdict, msg) = if latched {
        let flags = s.feedback().map_or(0, |f| f.fault_flags);
        (
            Outcome::Refused,
            format!(
                "the MCU braked while driving (faults {}): {}{}",
                fault_names(flags).join(","),
                brake_hint(flags),
                late_hint(s)
            ),
        )
    } else {
        (
            Outcome::Done,
            "armed, drove, commanded zero until the wheels stood, then enable 0 (STOP)".into(),
        )
    };
    let mut r = Report::new("drive", s, before, verdict, msg);
    r.drive = Some(meter.summary);
    r.interrupted = interrupted;
    Ok(r)
}

/// Opens the port of an AMR-link verb: the spidev device, or the simulated board with its setup.
pub fn open(
    device: Option<&str>,
    speed: u32,
    opts: &AmrOpts,
) -> Result<Box<dyn Port + Send>, String> {
    if opts.sim {
        return open_sim(opts);
    }
    let device =
        device.ok_or("give the spidev device of the AMR link (e.g. /dev/spidev0.0), or --sim")?;
    let t = SpiTransport::open(device, speed).map_err(|e| e.to_string())?;
    Ok(Box::new(Paced::new(t)))
}

fn open_sim(opts: &AmrOpts) -> Result<Box<dyn Port + Send>, String> {
    let clock = match opts.sim_clock {
        SimClockArg::Wall => SimClock::Wall,
        SimClockArg::Paced | SimClockArg::Lockstep => SimClock::Lockstep,
    };
    let mut mcu = SimMcu::new(SimConfig::new(clock)).map_err(|e| e.to_string())?;
    if opts.sim_setup == SimSetup::EstopHeld {
        mcu.set_estop(true);
        mcu.idle(5);
    }
    let mut port = SimPort::new(mcu);
    port.paced = opts.sim_clock == SimClockArg::Paced;
    Ok(Box::new(port))
}

/// The simulated board ([`SimMcu`]) as a port: on its own clock (lockstep: one board millisecond
/// per exchange, the host's time is the board's; `paced`: those exchanges at 1 kHz on the wall
/// clock) or on the wall clock (1 ms absolute deadlines).
pub struct SimPort {
    /// The simulated board.
    pub mcu: SimMcu,
    /// A lockstep board's exchanges wait for 1 kHz deadlines.
    pub paced: bool,
    pacer: Pacer,
    epoch: Instant,
}

impl SimPort {
    /// `mcu` as a port.
    pub fn new(mcu: SimMcu) -> Self {
        Self {
            mcu,
            paced: false,
            pacer: Pacer::contract(),
            epoch: Instant::now(),
        }
    }

    fn lockstep(&self) -> bool {
        self.mcu.config().clock == SimClock::Lockstep
    }

    fn wall_us(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
    }
}

impl Port for SimPort {
    fn begin_cycle(&mut self) -> u64 {
        if self.lockstep() {
            if self.paced {
                self.pacer.wait();
            }
            self.mcu.now_us()
        } else {
            self.pacer.wait();
            self.wall_us()
        }
    }

    fn exchange(
        &mut self,
        t_send: u64,
        tx: &[u8; FRAME_LEN],
        rx: &mut [u8; FRAME_LEN],
    ) -> Result<u64, LinkError> {
        self.mcu.exchange(tx, rx)?;
        Ok(if self.lockstep() {
            t_send.saturating_add(LOCKSTEP_RECV_US)
        } else {
            self.wall_us()
        })
    }

    fn gap(&mut self, ms: u64) {
        self.mcu.idle(ms);
        if self.paced {
            std::thread::sleep(Duration::from_millis(ms));
        }
        if !self.lockstep() || self.paced {
            let stats = std::mem::replace(&mut self.pacer, Pacer::contract()).stats;
            self.pacer.stats = stats;
        }
    }

    fn name(&self) -> &str {
        "sim"
    }

    fn pacing(&self) -> Option<&PeriodStats> {
        (!self.lockstep() || self.paced).then_some(&self.pacer.stats)
    }

    fn truth(&self) -> Option<Value> {
        serde_json::to_value(self.mcu.truth()).ok()
    }
}

/// `--sim-setup driving` and `braked`: the simulated board armed and driving straight at
/// [`SETUP_V`] for 1 s (and, for `braked`, then a frame gap that latches BRAKE), on the verb's
/// own session, so its sequence numbers carry on. The counters start again afterwards.
fn sim_setup<P: Port>(s: &mut Session<P>, setup: SimSetup) -> Result<(), String> {
    if !matches!(setup, SimSetup::Driving | SimSetup::Braked) {
        return Ok(());
    }
    let mut never = || false;
    let armed = s
        .arm_and_wait(WAIT_MS, &mut never)
        .map_err(|e| e.to_string())?;
    if armed != ArmResult::Armed {
        return Err("--sim-setup: the simulated board did not arm".into());
    }
    for _ in 0..1_000 {
        s.bridge.cmd_vel(s.now_us, SETUP_V, 0.0);
        s.cycle().map_err(|e| e.to_string())?;
    }
    if setup == SimSetup::Braked {
        s.gap(ESTOP_GAP_MS);
        s.bridge.disarm();
        s.run(SETTLE_CYCLES, &mut never)
            .map_err(|e| e.to_string())?;
    }
    s.counters = LinkCounters::default();
    s.modes_seen = s
        .feedback()
        .map(|f| mode_name(f.mode))
        .into_iter()
        .collect();
    Ok(())
}

/// The forward speed of `--sim-setup driving`, m/s.
pub const SETUP_V: f64 = 0.3;

impl Port for Box<dyn Port + Send> {
    fn begin_cycle(&mut self) -> u64 {
        (**self).begin_cycle()
    }
    fn exchange(
        &mut self,
        t_send: u64,
        tx: &[u8; FRAME_LEN],
        rx: &mut [u8; FRAME_LEN],
    ) -> Result<u64, LinkError> {
        (**self).exchange(t_send, tx, rx)
    }
    fn gap(&mut self, ms: u64) {
        (**self).gap(ms);
    }
    fn name(&self) -> &str {
        (**self).name()
    }
    fn pacing(&self) -> Option<&PeriodStats> {
        (**self).pacing()
    }
    fn truth(&self) -> Option<Value> {
        (**self).truth()
    }
}

/// Which verb to run on an opened session.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verb {
    /// `arm`.
    Arm,
    /// `rearm`.
    Rearm,
    /// `disarm` for this many seconds at most.
    Disarm(f64),
    /// `estop`.
    Estop,
    /// `estop --release`.
    EstopRelease,
    /// `drive --v --w --seconds`.
    Drive {
        /// m/s.
        v: f64,
        /// rad/s.
        w: f64,
        /// s.
        seconds: f64,
    },
}

/// Runs `verb` on the link, prints its report (text, or JSON with `--json`) and returns the exit
/// status. Arguments are checked before the device is opened.
pub fn run_verb(
    verb: Verb,
    device: Option<&str>,
    speed: u32,
    opts: &AmrOpts,
    stop: &mut dyn FnMut() -> bool,
    print: &mut dyn FnMut(&str),
) -> Run {
    if let Verb::Drive { v, w, seconds } = verb {
        check_twist(v, w).or_exit(Exit::Usage)?;
        if !(seconds.is_finite() && seconds > 0.0 && seconds <= 3600.0) {
            return Err(Failure::usage(format!(
                "--seconds {seconds}: give a duration above 0 and at most 3600 s; nothing was sent"
            )));
        }
    }
    if let Verb::Disarm(sec) = verb {
        if !(sec.is_finite() && sec > 0.0 && sec <= 60.0) {
            return Err(Failure::usage(format!(
                "--seconds {sec}: give 0 < s <= 60; nothing was sent"
            )));
        }
    }
    let port = open(device, speed, opts).or_exit(Exit::Unavailable)?;
    let mut s = Session::new(port);
    if opts.sim {
        sim_setup(&mut s, opts.sim_setup).or_exit(Exit::Io)?;
    }
    let r = match verb {
        Verb::Arm => arm(&mut s, "arm", stop),
        Verb::Rearm => arm(&mut s, "rearm", stop),
        Verb::Disarm(sec) => disarm(&mut s, sec, stop),
        Verb::Estop => estop(&mut s, stop),
        Verb::EstopRelease => estop_release(&mut s, stop),
        Verb::Drive { v, w, seconds } => drive(&mut s, v, w, seconds, stop),
    }
    .or_exit(Exit::Io)?;
    if opts.json {
        print(&r.json().to_string());
    } else {
        print(r.text().trim_end());
    }
    Ok(r.verdict.exit())
}

/// Writes one report to standard output; a closed pipe or a failed write is ignored (the verb
/// has already stopped the robot by then).
pub fn print_stdout(text: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stdout().lock(), "{text}");
}

/// Runs an AMR-link verb as the binary does: SIGINT, SIGTERM and SIGHUP end it early (after the
/// verb has commanded zero and disarmed), the report goes to standard output.
pub fn exec(verb: Verb, device: Option<&str>, speed: u32, opts: &AmrOpts) -> Run {
    let mut signals = super::pi::Signals::block().or_exit(Exit::Io)?;
    let mut stop = || signals.received();
    run_verb(verb, device, speed, opts, &mut stop, &mut print_stdout)
}

/// `top` (watch) and `teleop` (drive with the keyboard, `Some` config): the live view until q,
/// Ctrl-C or `seconds`; the terminal is restored before the report is printed.
pub fn exec_tui(
    teleop: Option<teleop::TeleopConfig>,
    device: Option<&str>,
    speed: u32,
    opts: &AmrOpts,
    seconds: Option<f64>,
) -> Run {
    let verb = if teleop.is_some() { "teleop" } else { "top" };
    if opts.sim && opts.sim_clock == SimClockArg::Lockstep {
        return Err(Failure::usage(format!(
            "{verb} runs in real time: use --sim-clock paced (the default) or wall"
        )));
    }
    if let Some(sec) = seconds {
        if !(sec.is_finite() && sec > 0.0) {
            return Err(Failure::usage(format!(
                "--seconds {sec}: give a duration above 0"
            )));
        }
    }
    if let Some(c) = teleop {
        check_twist(c.max_v, c.max_w)
            .map_err(|e| Failure::usage(format!("--max-v / --max-w: {e}")))?;
        if !(c.max_v > 0.0 && c.max_w > 0.0 && c.hold_us > 0) {
            return Err(Failure::usage(
                "--max-v, --max-w and --hold-ms must be above 0; nothing was sent",
            ));
        }
    }
    let mut signals = super::pi::Signals::block().or_exit(Exit::Io)?;
    let port = open(device, speed, opts).or_exit(Exit::Unavailable)?;
    let mut s = Session::new(port);
    s.history = History::new(6_000);
    if opts.sim {
        sim_setup(&mut s, opts.sim_setup).or_exit(Exit::Io)?;
    }
    let driver = match teleop {
        Some(c) => top::Driver::Teleop(teleop::Teleop::new(c)),
        None => top::Driver::Watch,
    };
    let mut stop = || signals.received();
    let r = top::run(&mut s, verb, driver, seconds, &mut stop).or_exit(Exit::Io)?;
    if opts.json {
        print_stdout(&r.json().to_string());
    } else {
        print_stdout(r.text().trim_end());
    }
    Ok(r.verdict.exit())
}

/// `list`: prints the devices found (text, or JSON with `json`).
pub fn exec_list(json: bool) -> Run {
    let found = list::discover().or_exit(Exit::Io)?;
    if json {
        print_stdout(&list::json(&found).to_string());
    } else {
        print_stdout(list::text(&found).trim_end());
    }
    Ok(Exit::Ok)
}

#[cfg(test)]
mod tests;
