//! The 1 kHz motor bridge (seed 000's `MotorBridge`, done properly), as a pure state machine:
//! every method takes the host time in µs, so the robot and the simulator run the same code.
//!
//! ```text
//!  cmd_vel (20 Hz) ──► target (v, ω) ──► IK ──► slew ≤ 0.04 rad/s per cycle ──► MotorCommand (1 kHz)
//!        older than 200 ms ⇒ target 0                  enable = 0 unless Armed
//!  feedback ──► checks (speed, current, encoder, staleness) ──► diagnostics; clock sync
//!        MCU in BRAKE, or feedback stale ⇒ Latched: enable = 0, zero, wait for an explicit re-arm
//!  McuInfo (in the feedback slot after request_identity) ──► mcu_info(); a reset since the last
//!        one seen (count or cause changed, or a first one not from power-on) ⇒ McuReset
//! ```
//!
//! Arming follows the ladder's rule: a valid frame with enable = 0, then enable = 1 (the rising
//! edge is the re-arm request), then fresh frames. The host never re-arms by itself.

use protocol::amr::{McuFrame, McuInfo, MotorCommand, MotorFeedback, ResetCause, REQUEST_IDENTITY};
use statemachine::{ControlMode, FaultFlags, Mode, RejectReason};

use crate::clocksync::{ClockSync, ClockSyncConfig, SeedClockSync};
use crate::feedback::{FeedbackFault, FeedbackLimits, FeedbackMonitor, FeedbackSample};
use crate::kinematics::DiffDrive;

/// Bridge settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BridgeConfig {
    /// Robot geometry.
    pub kinematics: DiffDrive,
    /// cmd_vel older than this is replaced by zero, µs (seed: 200 ms).
    pub cmd_vel_timeout_us: u64,
    /// Largest change of a wheel command per cycle, rad/s (below the MCU's 0.05 per tick).
    pub slew_per_cycle: f64,
    /// Cycles with enable = 0 before enable = 1 when arming.
    pub arm_cycles: u32,
    /// Cycles to wait for the MCU to leave BRAKE after arming before giving up.
    pub arm_timeout_cycles: u32,
    /// Feedback limits.
    pub limits: FeedbackLimits,
    /// Clock sync tuning.
    pub clock: ClockSyncConfig,
    /// Duration of one SPI transfer, µs (the MCU stamps its feedback at the end of a transfer).
    pub transfer_us: u64,
    /// A gap between two of our own cycles longer than this is reported (HostLate), µs.
    pub late_cycle_us: u64,
}

impl BridgeConfig {
    /// Seed 000's figures on the default robot.
    pub const DEFAULT: Self = Self {
        kinematics: DiffDrive::DEFAULT,
        cmd_vel_timeout_us: 200_000,
        slew_per_cycle: 0.04,
        arm_cycles: 3,
        arm_timeout_cycles: 200,
        limits: FeedbackLimits::DEFAULT,
        clock: ClockSyncConfig::DEFAULT,
        transfer_us: 256,
        late_cycle_us: 2_000,
    };
}

impl Default for BridgeConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Where the bridge is in the arming sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum ArmState {
    /// Sending enable = 0; nothing asked.
    Disarmed,
    /// Sending enable = 0 for this many more cycles, then enable = 1.
    Arming(u32),
    /// Sending enable = 1 with the commanded speeds.
    Armed,
    /// The MCU braked (or froze): sending enable = 0, waiting for an explicit re-arm.
    Latched,
}

/// Something the bridge reports (the fault/diagnostic stream).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "diag", rename_all = "snake_case")]
pub enum Diagnostic {
    /// No cmd_vel for longer than the timeout: commanding zero.
    CmdVelStale,
    /// cmd_vel is fresh again.
    CmdVelResumed,
    /// A feedback frame failed to decode.
    FeedbackRejected {
        /// Why (ladder reject code).
        reason: u8,
    },
    /// A feedback frame failed a plausibility check.
    Feedback {
        /// Which check.
        fault: FeedbackFault,
    },
    /// MCU timestamps stopped advancing: MCU frozen. Commanding stop; re-arm needed.
    McuFrozen,
    /// The MCU is in BRAKE with these fault flags; re-arm needed.
    BrakeLatched {
        /// Fault flags reported.
        faults: u16,
    },
    /// The MCU left BRAKE after an explicit re-arm.
    Rearmed,
    /// The MCU did not leave BRAKE after arming (a latching cause is still active).
    ArmRefused {
        /// Fault flags reported.
        faults: u16,
    },
    /// The MCU's ladder changed rung.
    Mode {
        /// New rung (0 NORMAL … 4 BRAKE).
        mode: u8,
    },
    /// Clock sync acquired.
    ClockSynced,
    /// The MCU did not accept the last command (its cmd_seq lags).
    CommandNotAccepted,
    /// Our own cycle came late (scheduling, GC pause): the MCU missed commands.
    HostLate {
        /// Time since the previous cycle, µs.
        gap_us: u64,
    },
    /// The MCU reset (its `McuInfo` shows a reset count or cause other than the last one seen, or,
    /// in the first one seen, a reset that was not a power-on): whatever it was doing was lost.
    McuReset {
        /// Why it last started.
        cause: ResetCause,
        /// Resets since power-on.
        reset_count: u32,
        /// Source line of the last panic, 0 if none.
        panic_line: u32,
    },
}

impl Diagnostic {
    /// Short stable name (used in traces and scenario expectations).
    pub fn name(&self) -> &'static str {
        match self {
            Self::CmdVelStale => "cmd_vel_stale",
            Self::CmdVelResumed => "cmd_vel_resumed",
            Self::FeedbackRejected { .. } => "feedback_rejected",
            Self::Feedback { fault } => match fault {
                FeedbackFault::SpeedImplausible => "speed_implausible",
                FeedbackFault::CurrentOutOfRange => "current_out_of_range",
                FeedbackFault::EncoderInconsistent => "encoder_inconsistent",
                FeedbackFault::Stale => "feedback_stale",
                FeedbackFault::NonFinite => "feedback_non_finite",
            },
            Self::McuFrozen => "mcu_frozen",
            Self::BrakeLatched { .. } => "brake_latched",
            Self::Rearmed => "rearmed",
            Self::ArmRefused { .. } => "arm_refused",
            Self::Mode { .. } => "mode",
            Self::ClockSynced => "clock_synced",
            Self::CommandNotAccepted => "command_not_accepted",
            Self::HostLate { .. } => "host_late",
            Self::McuReset { .. } => "mcu_reset",
        }
    }
}

/// Counters of the bridge.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct BridgeStats {
    /// Commands built.
    pub commands: u64,
    /// Feedback frames decoded.
    pub feedback_ok: u64,
    /// Feedback frames refused by decoding.
    pub feedback_rejected: u64,
    /// Exchanges where the MCU had not accepted the previous command.
    pub not_accepted: u64,
    /// `McuInfo` frames received in the feedback slot (neither feedback nor refused).
    pub info_frames: u64,
}

/// The bridge state.
#[derive(Clone, Debug)]
pub struct Bridge {
    cfg: BridgeConfig,
    state: ArmState,
    cmd_vel: Option<(f64, f64, u64)>,
    stale: bool,
    out: [f64; 2],
    seq: u32,
    monitor: FeedbackMonitor,
    /// Offset and skew estimator.
    pub clock: ClockSync,
    /// The seed's estimator, for comparison.
    pub seed_clock: SeedClockSync,
    /// (t_send, t_recv, seq) of the previous exchange.
    prev_exchange: Option<(u64, u64, u32)>,
    mcu_mode: Option<u8>,
    seen_running: bool,
    rearm_requested: bool,
    arm_wait: u32,
    frozen: bool,
    synced: bool,
    failed_in_row: u32,
    last_command_us: Option<u64>,
    diags: Vec<(u64, Diagnostic)>,
    /// The next command asks for an `McuInfo`.
    identity_requested: bool,
    /// Last `McuInfo` received.
    info: Option<McuInfo>,
    /// Last feedback decoded.
    pub last_feedback: Option<MotorFeedback>,
    /// Counters.
    pub stats: BridgeStats,
}

fn approach(cur: f64, target: f64, step: f64) -> f64 {
    if (target - cur).abs() <= step {
        target
    } else if target > cur {
        cur + step
    } else {
        cur - step
    }
}

impl Bridge {
    /// A disarmed bridge.
    pub fn new(cfg: BridgeConfig) -> Self {
        Self {
            cfg,
            state: ArmState::Disarmed,
            cmd_vel: None,
            stale: false,
            out: [0.0; 2],
            seq: 0,
            monitor: FeedbackMonitor::new(cfg.limits),
            clock: ClockSync::new(cfg.clock),
            seed_clock: SeedClockSync::default(),
            prev_exchange: None,
            mcu_mode: None,
            seen_running: false,
            rearm_requested: false,
            arm_wait: 0,
            frozen: false,
            synced: false,
            failed_in_row: 0,
            last_command_us: None,
            diags: Vec::new(),
            identity_requested: false,
            info: None,
            last_feedback: None,
            stats: BridgeStats::default(),
        }
    }

    /// The arming state.
    pub fn state(&self) -> ArmState {
        self.state
    }

    /// The wheel speeds last commanded, rad/s.
    pub fn output(&self) -> [f64; 2] {
        self.out
    }

    fn report(&mut self, now: u64, d: Diagnostic) {
        self.diags.push((now, d));
    }

    /// Takes the diagnostics raised since the last call.
    pub fn drain(&mut self) -> Vec<(u64, Diagnostic)> {
        core::mem::take(&mut self.diags)
    }

    /// A cmd_vel message (v m/s, ω rad/s) arrived at `now`.
    pub fn cmd_vel(&mut self, now: u64, v: f64, w: f64) {
        self.cmd_vel = Some((v, w, now));
    }

    /// Starts the arming sequence (from Disarmed or Latched).
    pub fn arm(&mut self, now: u64) {
        if matches!(self.state, ArmState::Disarmed | ArmState::Latched) {
            self.rearm_requested = self.state == ArmState::Latched;
            self.state = ArmState::Arming(self.cfg.arm_cycles);
            self.out = [0.0; 2];
            self.seen_running = false;
            self.arm_wait = 0;
            self.frozen = false;
            self.monitor.reset(now);
        }
    }

    /// Explicit re-arm after BRAKE (operator action); the same sequence as [`Bridge::arm`].
    pub fn rearm(&mut self, now: u64) {
        self.arm(now);
    }

    /// Asks the MCU who it is: the next command carries `request` = [`REQUEST_IDENTITY`], and the
    /// MCU answers with an `McuInfo` in the feedback slot after it (read it with
    /// [`Bridge::mcu_info`]). One command carries the request; if that frame is lost, ask again.
    pub fn request_identity(&mut self) {
        self.identity_requested = true;
    }

    /// The last `McuInfo` the MCU sent (firmware version, board, reset cause), if any.
    pub fn mcu_info(&self) -> Option<McuInfo> {
        self.info
    }

    /// Disables the drive.
    pub fn disarm(&mut self) {
        self.state = ArmState::Disarmed;
        self.out = [0.0; 2];
    }

    /// The command to send at `now`.
    pub fn next_command(&mut self, now: u64) -> MotorCommand {
        self.stats.commands = self.stats.commands.saturating_add(1);
        self.monitor.start(now);
        // Staleness is judged on feedback (a paused host must not blame the MCU); a late cycle
        // of our own is reported as such.
        if let Some(prev) = self.last_command_us {
            let gap = now.saturating_sub(prev);
            if gap > self.cfg.late_cycle_us {
                self.report(now, Diagnostic::HostLate { gap_us: gap });
            }
        }
        self.last_command_us = Some(now);
        let fresh = self
            .cmd_vel
            .filter(|&(_, _, t)| now.saturating_sub(t) <= self.cfg.cmd_vel_timeout_us);
        if fresh.is_none() && self.cmd_vel.is_some() && !self.stale {
            self.stale = true;
            self.report(now, Diagnostic::CmdVelStale);
        } else if fresh.is_some() && self.stale {
            self.stale = false;
            self.report(now, Diagnostic::CmdVelResumed);
        }
        let enable = match self.state {
            ArmState::Armed => true,
            ArmState::Arming(0) => {
                self.state = ArmState::Armed;
                true
            }
            ArmState::Arming(n) => {
                self.state = ArmState::Arming(n.saturating_sub(1));
                false
            }
            ArmState::Disarmed | ArmState::Latched => false,
        };
        let target = match (enable, fresh) {
            (true, Some((v, w, _))) => {
                let (l, r) = self.cfg.kinematics.inverse(v, w);
                [l, r]
            }
            _ => [0.0; 2],
        };
        if enable {
            for (o, t) in self.out.iter_mut().zip(target) {
                *o = approach(*o, t, self.cfg.slew_per_cycle);
            }
        } else {
            self.out = [0.0; 2];
        }
        self.seq = self.seq.wrapping_add(1);
        let request = if core::mem::take(&mut self.identity_requested) {
            REQUEST_IDENTITY
        } else {
            0
        };
        MotorCommand {
            timestamp_us: now as u32,
            left_speed_cmd: self.out[0] as f32,
            right_speed_cmd: self.out[1] as f32,
            control_mode: ControlMode::Speed as u32,
            enable,
            seq: self.seq,
            request,
        }
    }

    /// The exchange that sent command `seq` at `t_send` completed at `t_recv` with whatever the
    /// MCU sent in the feedback slot (`protocol::amr::decode_mcu_frame`): a feedback goes to
    /// [`Bridge::on_feedback`]; an `McuInfo` is neither a feedback nor a refused frame.
    pub fn on_frame(
        &mut self,
        t_send: u64,
        t_recv: u64,
        seq: u32,
        frame: Result<McuFrame, RejectReason>,
    ) {
        match frame {
            Ok(McuFrame::Info(info)) => self.on_info(t_send, t_recv, seq, info),
            Ok(McuFrame::Feedback(fb)) => self.on_feedback(t_send, t_recv, seq, Ok(fb)),
            Err(reason) => self.on_feedback(t_send, t_recv, seq, Err(reason)),
        }
    }

    /// An `McuInfo` in the feedback slot: kept for [`Bridge::mcu_info`], checked for a reset.
    ///
    /// It carries no measurements, so the feedback checks and the clock do not see it; but it
    /// does not advance the MCU's timestamp either, so an MCU stuck sending the same info frame
    /// goes stale and is reported frozen like one stuck sending the same feedback.
    fn on_info(&mut self, t_send: u64, t_recv: u64, seq: u32, info: McuInfo) {
        // The next feedback answers this exchange's command: pair the clock with it.
        self.prev_exchange = Some((t_send, t_recv, seq));
        self.stats.info_frames = self.stats.info_frames.saturating_add(1);
        self.failed_in_row = 0;
        // What the MCU reported before, or what a fresh power-on would report.
        let (count, cause) = self
            .info
            .map_or((0, ResetCause::PowerOn), |i| (i.reset_count, i.reset_cause));
        if (info.reset_count, info.reset_cause) != (count, cause) {
            self.report(
                t_recv,
                Diagnostic::McuReset {
                    cause: info.reset_cause,
                    reset_count: info.reset_count,
                    panic_line: info.panic_line,
                },
            );
        }
        self.info = Some(info);
        if self.monitor.is_stale(t_recv) {
            self.mcu_frozen(t_recv);
        }
    }

    /// No new feedback for longer than the stale limit: report it once and latch (stop, and wait
    /// for an explicit re-arm).
    fn mcu_frozen(&mut self, t_recv: u64) {
        if !self.frozen {
            self.frozen = true;
            self.report(t_recv, Diagnostic::McuFrozen);
            if self.state != ArmState::Disarmed {
                self.state = ArmState::Latched;
            }
        }
    }

    /// The exchange that sent command `seq` at `t_send` completed at `t_recv` with `feedback`.
    pub fn on_feedback(
        &mut self,
        t_send: u64,
        t_recv: u64,
        seq: u32,
        feedback: Result<MotorFeedback, RejectReason>,
    ) {
        let prev = self.prev_exchange.replace((t_send, t_recv, seq));
        let fb = match feedback {
            Ok(fb) => fb,
            Err(reason) => {
                self.stats.feedback_rejected = self.stats.feedback_rejected.saturating_add(1);
                self.report(
                    t_recv,
                    Diagnostic::FeedbackRejected {
                        reason: reason as u8,
                    },
                );
                self.failed_in_row = self.failed_in_row.saturating_add(1);
                if self.failed_in_row >= 5 && self.monitor.is_stale(t_recv) {
                    self.mcu_frozen(t_recv);
                }
                return;
            }
        };
        self.stats.feedback_ok = self.stats.feedback_ok.saturating_add(1);
        self.failed_in_row = 0;
        let repeated = self
            .last_feedback
            .is_some_and(|l| l.seq == fb.seq && l.timestamp_us == fb.timestamp_us);
        self.last_feedback = Some(fb);
        // The feedback was prepared when the previous exchange ended; pair it with that exchange
        // only if the MCU accepted that exchange's command (cmd_seq), so the pairing is certain.
        if let Some((p_send, p_recv, p_seq)) = prev {
            if !repeated && fb.cmd_seq == p_seq {
                let lo = p_send.saturating_add(self.cfg.transfer_us).min(p_recv);
                self.clock.update(lo, u64::from(fb.timestamp_us), p_recv);
                self.seed_clock
                    .update(p_send, u64::from(fb.timestamp_us), p_recv);
                if !self.synced && self.clock.is_synced(t_recv) {
                    self.synced = true;
                    self.report(t_recv, Diagnostic::ClockSynced);
                }
            } else if !repeated && self.state == ArmState::Armed && self.seen_running {
                self.stats.not_accepted = self.stats.not_accepted.saturating_add(1);
            }
        }
        let sample = FeedbackSample {
            mcu_us: fb.timestamp_us,
            speed: [fb.left_speed, fb.right_speed],
            current: [fb.left_current, fb.right_current],
            encoder: [fb.left_encoder, fb.right_encoder],
            faults: u16::try_from(fb.fault_flags).unwrap_or(u16::MAX),
        };
        if self.frozen && !repeated && !self.monitor.is_stale(t_recv) {
            // Timestamps advance again (the MCU restarted): stays Latched until re-armed, and asks
            // the MCU why it restarted (its identity carries the reset cause and count).
            self.frozen = false;
            self.monitor.reset(t_recv);
            self.identity_requested = true;
        }
        for f in self.monitor.check(t_recv, &sample) {
            if f == FeedbackFault::Stale {
                self.mcu_frozen(t_recv);
            } else {
                self.report(t_recv, Diagnostic::Feedback { fault: f });
            }
        }
        if repeated {
            return;
        }
        let mode = u8::try_from(fb.mode).unwrap_or(u8::MAX);
        if self.mcu_mode != Some(mode) {
            self.mcu_mode = Some(mode);
            self.report(t_recv, Diagnostic::Mode { mode });
        }
        let braked = mode == Mode::Brake as u8;
        match self.state {
            ArmState::Armed if !braked => {
                if !self.seen_running && self.rearm_requested {
                    self.report(t_recv, Diagnostic::Rearmed);
                }
                self.seen_running = true;
                self.rearm_requested = false;
            }
            ArmState::Armed if self.seen_running => {
                self.state = ArmState::Latched;
                self.out = [0.0; 2];
                self.report(
                    t_recv,
                    Diagnostic::BrakeLatched {
                        faults: sample.faults,
                    },
                );
            }
            ArmState::Armed => {
                self.arm_wait = self.arm_wait.saturating_add(1);
                if self.arm_wait > self.cfg.arm_timeout_cycles {
                    self.state = ArmState::Latched;
                    self.report(
                        t_recv,
                        Diagnostic::ArmRefused {
                            faults: sample.faults,
                        },
                    );
                }
            }
            _ => {}
        }
    }

    /// True if the MCU reported BRAKE latched in its last feedback.
    pub fn mcu_brake_latched(&self) -> bool {
        self.last_feedback.is_some_and(|f| {
            FaultFlags(u16::try_from(f.fault_flags).unwrap_or(u16::MAX))
                .contains(FaultFlags::BRAKE_LATCHED)
        })
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
mod tests {
    use super::*;
    use statemachine::{Config, Event, Ladder};

    /// Drives a real ladder with the bridge's commands (no plant): one command per tick.
    fn exchange(b: &mut Bridge, l: &mut Ladder<2>, now: u64) -> MotorCommand {
        let c = b.next_command(now);
        l.step(protocol::event_from(c.to_command()));
        let out = l.step(Event::Tick);
        let fb = MotorFeedback {
            timestamp_us: now as u32 + 7,
            seq: (now / 1000) as u32,
            cmd_seq: c.seq,
            ..MotorFeedback::default()
        }
        .with_output(&out);
        b.on_feedback(now, now + 300, c.seq, Ok(fb));
        c
    }

    #[test]
    fn arms_the_real_ladder_and_ramps_within_its_limit() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        b.arm(0);
        let mut last = 0.0f32;
        for k in 0..600u64 {
            b.cmd_vel(k * 1000, 1.0, 0.0);
            let c = exchange(&mut b, &mut l, k * 1000);
            assert!((c.left_speed_cmd - last).abs() <= 0.0401, "slew at {k}");
            last = c.left_speed_cmd;
        }
        assert_eq!(b.state(), ArmState::Armed);
        assert_ne!(l.mode(), Mode::Brake);
        // 1 m/s on 0.08 m wheels = 12.5 rad/s, reached after 12.5 / 0.04 ≈ 313 cycles.
        assert!((last - 12.5).abs() < 1e-3, "{last}");
        // No frame was refused by the ladder's acceleration check.
        assert_eq!(l.counters().rejected_total(), 0);
    }

    /// Arms and holds cmd_vel (v, ω) for `cycles` 1 ms cycles against a real ladder; the last
    /// command's wheel speeds.
    fn settle(
        b: &mut Bridge,
        l: &mut Ladder<2>,
        from: u64,
        cycles: u64,
        v: f64,
        w: f64,
    ) -> [f32; 2] {
        let mut last = [f32::NAN; 2];
        for k in from..from + cycles {
            b.cmd_vel(k * 1000, v, w);
            let c = exchange(b, l, k * 1000);
            last = [c.left_speed_cmd, c.right_speed_cmd];
            assert!(last.iter().all(|x| x.is_finite()), "{last:?} at {k}");
        }
        last
    }

    /// The wheel commands for cmd_vel on the default robot (L = 0.40 m, r = 0.08 m, 18 rad/s),
    /// from wL = (v − ω·0.2)/0.08, wR = (v + ω·0.2)/0.08 worked by hand. Tolerance: the geometry
    /// is held to 15 µm (r = 0.0800018 m, L = 0.3999939 m: a scale error of 2.3e-5, 4e-4 rad/s at
    /// 18 rad/s) and the command is an f32.
    #[test]
    fn wheel_speeds_for_cmd_vel_by_hand() {
        let cases = [
            // 0.8/0.08 = 10 each.
            ((0.8, 0.0), [10.0, 10.0]),
            // (0.5 − 0.2)/0.08 = 3.75, (0.5 + 0.2)/0.08 = 8.75.
            ((0.5, 1.0), [3.75, 8.75]),
            // (0.3 + 0.14)/0.08 = 5.5, (0.3 − 0.14)/0.08 = 2.
            ((0.3, -0.7), [5.5, 2.0]),
            // (−0.4 − 0.1)/0.08 = −6.25, (−0.4 + 0.1)/0.08 = −3.75.
            ((-0.4, 0.5), [-6.25, -3.75]),
            // Spin: ∓0.3/0.08 = ∓3.75.
            ((0.0, 1.5), [-3.75, 3.75]),
            // (2 − 0.4)/0.08 = 20, (2 + 0.4)/0.08 = 30: over 18, both scaled by 18/30 = 0.6 to
            // 12 and 18 (the curvature ω/v = 1 kept).
            ((2.0, 2.0), [12.0, 18.0]),
            // (−1 − 1)/0.08 = −25, (−1 + 1)/0.08 = 0: scaled by 18/25 to −18 and 0.
            ((-1.0, 5.0), [-18.0, 0.0]),
        ];
        for ((v, w), want) in cases {
            let mut b = Bridge::new(BridgeConfig::DEFAULT);
            let mut l = Ladder::new(Config::DEFAULT);
            b.arm(0);
            // 18 rad/s at 0.04 rad/s per cycle: 450 cycles.
            let got = settle(&mut b, &mut l, 0, 600, v, w);
            for (g, w_) in got.iter().zip(want) {
                assert!(
                    (f64::from(*g) - w_).abs() < 5e-4,
                    "({v}, {w}): {got:?} vs {want:?}"
                );
            }
            assert!(got.iter().all(|g| g.abs() <= 18.0), "{got:?}");
            assert_eq!(l.counters().rejected_total(), 0);
        }
    }

    /// A cmd_vel with a NaN or an infinity commands zero, reached at the slew rate.
    #[test]
    fn non_finite_cmd_vel_commands_zero() {
        for (v, w) in [
            (f64::NAN, 0.0),
            (0.5, f64::NAN),
            (f64::INFINITY, 1.0),
            (0.0, f64::NEG_INFINITY),
        ] {
            let mut b = Bridge::new(BridgeConfig::DEFAULT);
            let mut l = Ladder::new(Config::DEFAULT);
            b.arm(0);
            let moving = settle(&mut b, &mut l, 0, 300, 0.5, 1.0);
            assert!(moving[1] > 8.0, "{moving:?}");
            // 8.75 rad/s down at 0.04 per cycle: 219 cycles.
            let got = settle(&mut b, &mut l, 300, 300, v, w);
            assert_eq!(got, [0.0, 0.0], "({v}, {w})");
            assert_eq!(b.state(), ArmState::Armed);
        }
    }

    #[test]
    fn stale_cmd_vel_commands_zero() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        b.arm(0);
        b.cmd_vel(0, 0.5, 0.0);
        for k in 0..400u64 {
            exchange(&mut b, &mut l, k * 1000);
        }
        // cmd_vel is 400 ms old: the target is zero and the output has ramped down.
        assert_eq!(b.output(), [0.0, 0.0]);
        assert!(b.drain().iter().any(|(_, d)| *d == Diagnostic::CmdVelStale));
    }

    #[test]
    fn brake_latches_and_needs_explicit_rearm() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        b.arm(0);
        for k in 0..50u64 {
            exchange(&mut b, &mut l, k * 1000);
        }
        l.step(Event::Estop {
            source: statemachine::Source::Primary,
            action: statemachine::Estop::Engage,
        });
        l.step(Event::Estop {
            source: statemachine::Source::Primary,
            action: statemachine::Estop::Release,
        });
        for k in 50..100u64 {
            exchange(&mut b, &mut l, k * 1000);
        }
        assert_eq!(b.state(), ArmState::Latched);
        assert_eq!(l.mode(), Mode::Brake);
        let d = b.drain();
        assert!(d
            .iter()
            .any(|(_, d)| matches!(d, Diagnostic::BrakeLatched { .. })));
        // Still latched 1 s later: the bridge never re-arms by itself.
        for k in 100..1100u64 {
            exchange(&mut b, &mut l, k * 1000);
        }
        assert_eq!(l.mode(), Mode::Brake);
        b.rearm(1_100_000);
        for k in 1100..1120u64 {
            exchange(&mut b, &mut l, k * 1000);
        }
        assert_ne!(l.mode(), Mode::Brake);
        assert!(b.drain().iter().any(|(_, d)| *d == Diagnostic::Rearmed));
    }

    /// The exchange after one that carried an identity request, as the MCU answers it: an
    /// `McuInfo` in the feedback slot, with the feedback sequence number it takes.
    fn exchange_info(b: &mut Bridge, l: &mut Ladder<2>, now: u64, info: McuInfo) -> MotorCommand {
        let c = b.next_command(now);
        l.step(protocol::event_from(c.to_command()));
        l.step(Event::Tick);
        b.on_frame(now, now + 300, c.seq, Ok(McuFrame::Info(info)));
        c
    }

    #[test]
    fn an_identity_request_rides_on_one_command() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        assert_eq!(b.next_command(0).request, 0);
        b.request_identity();
        let c = b.next_command(1000);
        assert_eq!(c.request, REQUEST_IDENTITY);
        assert!(!c.enable);
        assert_eq!(b.next_command(2000).request, 0);
    }

    #[test]
    fn an_info_frame_is_kept_and_is_not_a_bad_feedback_frame() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        b.arm(0);
        for k in 0..50u64 {
            b.cmd_vel(k * 1000, 0.5, 0.0);
            exchange(&mut b, &mut l, k * 1000);
        }
        b.drain();
        let info = McuInfo {
            fw_version: protocol::amr::pack_fw_version(1, 2, 3),
            reset_cause: ResetCause::PowerOn,
            seq: 50,
            ..McuInfo::default()
        };
        b.cmd_vel(50_000, 0.5, 0.0);
        exchange_info(&mut b, &mut l, 50_000, info);
        for k in 51..60u64 {
            b.cmd_vel(k * 1000, 0.5, 0.0);
            exchange(&mut b, &mut l, k * 1000);
        }
        assert_eq!(b.mcu_info(), Some(info));
        assert_eq!(b.stats.info_frames, 1);
        assert_eq!(b.stats.feedback_rejected, 0);
        assert_eq!(b.stats.feedback_ok, 59);
        assert_eq!(b.state(), ArmState::Armed);
        // A power-on reset with no reset since is no news.
        let d = b.drain();
        assert!(d.is_empty(), "{d:?}");
    }

    #[test]
    fn a_reset_seen_in_the_info_is_reported_once() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        let at_power_on = McuInfo {
            reset_cause: ResetCause::PowerOn,
            ..McuInfo::default()
        };
        exchange_info(&mut b, &mut l, 0, at_power_on);
        assert!(b.drain().is_empty());
        // The watchdog bit: reset count up, cause not power-on.
        let watchdog = McuInfo {
            reset_cause: ResetCause::IndependentWatchdog,
            reset_count: 1,
            ..at_power_on
        };
        exchange(&mut b, &mut l, 1000);
        exchange_info(&mut b, &mut l, 2000, watchdog);
        let want = Diagnostic::McuReset {
            cause: ResetCause::IndependentWatchdog,
            reset_count: 1,
            panic_line: 0,
        };
        assert_eq!(
            b.drain().iter().filter(|(_, d)| *d == want).count(),
            1,
            "reported"
        );
        assert_eq!(want.name(), "mcu_reset");
        // Asked again, the same answer: nothing new.
        exchange_info(&mut b, &mut l, 3000, watchdog);
        assert!(!b
            .drain()
            .iter()
            .any(|(_, d)| matches!(d, Diagnostic::McuReset { .. })));
        // A panic next: the count goes up again.
        let panic = McuInfo {
            reset_cause: ResetCause::Panic,
            reset_count: 2,
            panic_line: 417,
            ..at_power_on
        };
        exchange_info(&mut b, &mut l, 4000, panic);
        assert!(b.drain().iter().any(|(_, d)| *d
            == Diagnostic::McuReset {
                cause: ResetCause::Panic,
                reset_count: 2,
                panic_line: 417
            }));
        // The first info a bridge ever sees already shows a reset: reported too.
        let mut fresh = Bridge::new(BridgeConfig::DEFAULT);
        exchange_info(&mut fresh, &mut l, 5000, watchdog);
        assert!(fresh
            .drain()
            .iter()
            .any(|(_, d)| matches!(d, Diagnostic::McuReset { .. })));
        // A power cycle after a reset (count back to 0): the MCU restarted.
        exchange_info(&mut b, &mut l, 6000, at_power_on);
        assert!(b.drain().iter().any(|(_, d)| *d
            == Diagnostic::McuReset {
                cause: ResetCause::PowerOn,
                reset_count: 0,
                panic_line: 0
            }));
    }

    #[test]
    fn an_mcu_stuck_on_an_info_frame_is_frozen() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        b.arm(0);
        for k in 0..50u64 {
            exchange(&mut b, &mut l, k * 1000);
        }
        let info = McuInfo::default();
        for k in 50..60u64 {
            exchange_info(&mut b, &mut l, k * 1000, info);
        }
        assert_eq!(b.state(), ArmState::Latched);
        assert!(b.drain().iter().any(|(_, d)| *d == Diagnostic::McuFrozen));
    }

    #[test]
    fn frozen_feedback_stops_and_reports() {
        let mut b = Bridge::new(BridgeConfig::DEFAULT);
        let mut l = Ladder::new(Config::DEFAULT);
        b.arm(0);
        for k in 0..100u64 {
            b.cmd_vel(k * 1000, 0.5, 0.0);
            exchange(&mut b, &mut l, k * 1000);
        }
        let frozen = b.last_feedback.unwrap();
        for k in 100..110u64 {
            b.cmd_vel(k * 1000, 0.5, 0.0);
            let c = b.next_command(k * 1000);
            b.on_feedback(k * 1000, k * 1000 + 300, c.seq, Ok(frozen));
        }
        assert_eq!(b.state(), ArmState::Latched);
        let c = b.next_command(111_000);
        assert!(!c.enable);
        assert_eq!(c.left_speed_cmd, 0.0);
        assert!(b.drain().iter().any(|(_, d)| *d == Diagnostic::McuFrozen));
    }
}
