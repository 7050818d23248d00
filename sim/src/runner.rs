//! The simulation loop: true time advances in steps of the MCU's 20 kHz current loop; the host's
//! link cycles, Nav2's messages, SPI transfers and faults happen at their own (continuous) times
//! and are applied at the first step at or after them.
//!
//! ```text
//!  host clock  ─ cycle k ─┬─ t_send ────────────────── t_recv ─┬─ cycle k+1 ─     (1 ms ± jitter, drift)
//!  SPI                    └ CS↓ ─ 64 B @ 2 MHz (256 µs) ─ CS↑ ┘
//!  MCU clock   ── step (50 µs) ── … ── spi_dma_done at CS↑: decode → ladder → feedback stamped ──
//! ```

use std::io::Write;
use std::time::Instant;

use protocol::amr::{ResetCause, FRAME_LEN};
use statemachine::{FaultFlags, Mode};

use crate::board::SimBoard;
use crate::host::HostModel;
use crate::measure::{add_report, Trace, Watch};
use crate::plant::{BridgeDrive, Plant};
use crate::rng::Rng;
use crate::scenario::{Fault, Profile, Request, Scenario};

/// MCU step: the 20 kHz current loop.
pub const STEP_S: f64 = 50e-6;
/// SPI transfer time of one frame: 64 bytes at 2 MHz.
pub const TRANSFER_S: f64 = FRAME_LEN as f64 * 8.0 / 2.0e6;
/// Host clock at the start of a run, µs.
pub const HOST_EPOCH_US: f64 = 50_000_000.0;

/// How to run.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunOptions {
    /// Print progress to stderr for long runs.
    pub progress: bool,
    /// Keep per-tick series for plots.
    pub keep_series: bool,
}

/// Mode as a short name.
pub fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Normal => "NORMAL",
        Mode::Reduced => "REDUCED",
        Mode::Hold => "HOLD",
        Mode::Stop => "STOP",
        Mode::Brake => "BRAKE",
    }
}

/// A plot panel of named signals over the series' time.
#[derive(Clone, Debug, Default)]
pub struct Panel {
    /// Caption.
    pub caption: String,
    /// (name, one value per time of the series).
    pub signals: Vec<(String, Vec<f64>)>,
}

/// Per-tick series for plots. The seed 000 run fills the wheel, command and setpoint series; the
/// serial profiles put their own signals in `lines` instead.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// The first panel, when not the wheel speeds.
    pub lines: Option<Panel>,
    /// The profile's HOLD, STOP and BRAKE ages, ticks (seed 000's when `None`).
    pub thresholds: Option<[u16; 3]>,
    /// Time, s.
    pub t: Vec<f64>,
    /// True wheel speeds, rad/s.
    pub wheel: [Vec<f64>; 2],
    /// Host command, rad/s.
    pub host_cmd: [Vec<f64>; 2],
    /// Ladder-applied setpoint, rad/s.
    pub applied: [Vec<f64>; 2],
    /// Mode as 0..=4.
    pub mode: Vec<u8>,
    /// Watchdog age: ticks since the last valid frame.
    pub age: Vec<u16>,
    /// Robot speed, m/s.
    pub v: Vec<f64>,
}

/// What a run measured.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Scenario name.
    pub name: String,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Wall-clock time, s.
    pub wall_s: f64,
    /// Fault onset, s.
    pub onset_s: Option<f64>,
    /// First HOLD after the onset, ms after it.
    pub hold_ms: Option<f64>,
    /// First STOP after the onset, ms after it.
    pub stop_ms: Option<f64>,
    /// First BRAKE of the ladder after the onset, ms after it.
    pub brake_ms: Option<f64>,
    /// First step after the onset with both bridges braked (low sides on), ms after it: the
    /// current loop and the ESTOP handler brake the bridge before the ladder's next tick.
    pub bridge_brake_ms: Option<f64>,
    /// First comm-loss BRAKE: time since the last valid frame, ms.
    pub brake_after_last_frame_ms: Option<f64>,
    /// First comm-loss BRAKE at the bridge: time from the last valid frame's arrival to both
    /// bridges braked (low sides on), ms; checked against the profile's bound in every scenario.
    pub bridge_brake_after_last_frame_ms: Option<f64>,
    /// Distance from the onset until standstill, m.
    pub stop_distance_m: Option<f64>,
    /// Robot speed at the onset, m/s.
    pub speed_at_onset: Option<f64>,
    /// Highest robot speed, m/s.
    pub peak_speed: f64,
    /// Highest |motor current|, A.
    pub peak_current: f64,
    /// Command frames the host sent.
    pub frames_sent: u64,
    /// Command frames corrupted on the wire.
    pub corrupted_sent: u64,
    /// Corrupted frames refused by decoding or validation.
    pub corrupted_rejected: u64,
    /// Corrupted frames the ladder accepted as valid (applied).
    pub corrupted_applied: u64,
    /// Frames refused by the ladder (all reasons).
    pub rejected_total: u64,
    /// BRAKE latches.
    pub brake_entries: u64,
    /// Re-arms.
    pub rearms: u64,
    /// Mode at the end.
    pub final_mode: String,
    /// Robot speed at the end, m/s.
    pub final_v: f64,
    /// Host diagnostics: (first time s, name, count).
    pub host_reports: Vec<(f64, String, u64)>,
    /// Clock-sync error at the end (mean |error| over the last second), µs.
    pub clock_err_final_us: Option<f64>,
    /// Largest |clock error| after the first 10 s, µs.
    pub clock_err_max_us: Option<f64>,
    /// The seed estimator's error at the end, µs.
    pub seed_clock_err_final_us: Option<f64>,
    /// The board and link (`amr-spi`, `cdc`, `teensy`).
    pub profile: String,
    /// Serial profiles: first comm-loss BRAKE, in the board's ticks since the tick count at the
    /// last valid frame.
    pub brake_after_last_frame_ticks: Option<u32>,
    /// Serial profiles: replies the host decoded and frames it could not decode.
    pub replies: Option<[u64; 2]>,
    /// Serial profiles: replies that were not what the host expected (ACK results, echoes), and
    /// expected replies that never came.
    pub reply_failures: Vec<String>,
    /// Serial profiles: ticks at which BRAKE was left without a re-arm message delivered since
    /// the latch.
    pub rearm_violations: u64,
    /// Serial profiles: replies dropped by the board because its transmit queue was full.
    pub tx_dropped: u64,
    /// Seed 001: time from the last byte of each `ESTOP 1` to every motor shorted, the largest, ms.
    pub estop_brake_ms: Option<f64>,
    /// Seed 001: largest |duty| applied from the first tick after a `MOTOR_ENABLE 0` reached the
    /// board until the next `MOTOR_ENABLE 1` (must be 0: the seed's "outputs forced to 0").
    pub duty_while_disabled: Option<f64>,
    /// Seed 001: IMU frames whose values saturated (the seed's i16 mdps ends at ±32.767 dps).
    pub imu_saturated: u64,
    /// Seed 001: largest difference between a decoded IMU frame and the true motion at its time
    /// (mg, mdps), unsaturated frames.
    pub imu_max_err: Option<[f64; 2]>,
    /// Seed 003: largest distance of a joint from its commanded angle at the end of an accepted
    /// move, steps.
    pub joint_err_steps: Option<f64>,
    /// Seed 003: largest joint speed above the command's cap (ramped down at the profile's
    /// acceleration after a lower cap), steps per tick.
    pub joint_speed_excess_steps: Option<f64>,
    /// Seed 003: largest |joint angle|, rad.
    pub joint_max_abs_rad: Option<f64>,
    /// Seed 003: step pulses issued after the first comm-loss BRAKE.
    pub steps_after_brake: Option<u64>,
    /// Seed 004: distance between the board's odometry (`pos_x`, `pos_y` of the last `TxBuffer`
    /// the host decoded) and the plant's true position at the measuring time, % of the distance
    /// the robot travelled (the plant's odometer) until then.
    pub odometry_err_pct: Option<f64>,
    /// Seed 004: the same distance, m.
    pub odometry_err_m: Option<f64>,
    /// Seed 004: |board heading − true heading| at the measuring time, degrees.
    pub odometry_heading_err_deg: Option<f64>,
    /// Seed 004: the distance the robot travelled until the measuring time, m.
    pub odometry_travel_m: Option<f64>,
    /// Seed 004: servo outputs (after every transfer and every tick) that differ from the rules
    /// recomputed by the simulator from what reached the board and the ladder's mode.
    pub servo_violations: Option<u64>,
    /// Seed 004: servo outputs compared.
    pub servo_checks: u64,
    /// Seed 004: for each transfer carrying the motor shutdown bit, the time from the transfer to
    /// every motor shorted; the largest, ms (0: in the transfer's own step).
    pub shutdown_brake_ms: Option<f64>,
    /// Seed 004: transfers with the motor shutdown bit that reached the board.
    pub shutdown_transfers: u64,
}

impl Summary {
    /// Simulated seconds per wall-clock second.
    pub fn speedup(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.sim_s / self.wall_s
        } else {
            f64::INFINITY
        }
    }

    /// Checks the scenario's expectations; returns one line per violation.
    pub fn check(&self, sc: &Scenario) -> Vec<String> {
        let e = &sc.expect;
        let mut bad = Vec::new();
        // SR-16: every comm-loss BRAKE reaches the bridge strictly within the profile's bound of the
        // last valid frame (10 ms for seed 000), whatever the scenario expects besides.
        let bound = sc.comm_loss_bound_ms();
        if let Some(x) = self.bridge_brake_after_last_frame_ms {
            if x >= bound {
                bad.push(format!(
                    "bridge braked {x:.3} ms after the last valid frame: the profile's bound is < {bound} ms"
                ));
            }
        }
        // The same in the board's own ticks: BRAKE at tick n after the frame is within n ms.
        if let Some(n) = self.brake_after_last_frame_ticks {
            if f64::from(n) >= bound {
                bad.push(format!(
                    "BRAKE {n} ticks after the last valid frame: the profile's bound is < {bound} ms"
                ));
            }
            if let Some([lo, hi]) = e.brake_after_last_frame_ticks {
                if n < lo || n > hi {
                    bad.push(format!(
                        "BRAKE after last frame: expected {lo}..{hi} ticks, got {n}"
                    ));
                }
            }
        } else if e.brake_after_last_frame_ticks.is_some() {
            bad.push("no comm-loss BRAKE measured in ticks".into());
        }
        if let Some([ok, broken]) = self.replies {
            if broken > 0 {
                bad.push(format!(
                    "the host could not decode {broken} of {} replies",
                    ok + broken
                ));
            }
        }
        bad.extend(self.reply_failures.iter().cloned());
        if self.rearm_violations > 0 {
            bad.push(format!(
                "BRAKE left {} times without a re-arm since the latch",
                self.rearm_violations
            ));
        }
        if self.tx_dropped > 0 {
            bad.push(format!("{} replies dropped by the board", self.tx_dropped));
        }
        if let Some(d) = self.duty_while_disabled {
            if d > 0.0 {
                bad.push(format!(
                    "motors driven at duty {d} after MOTOR_ENABLE 0, before MOTOR_ENABLE 1"
                ));
            }
        }
        if let Some(max) = e.max_speed_at_onset_mps {
            match self.speed_at_onset {
                Some(v) if v.abs() <= max => {}
                other => bad.push(format!(
                    "speed at the onset: expected ≤ {max} m/s, got {other:?}"
                )),
            }
        }
        if e.estop_brakes_at_once && self.estop_brake_ms != Some(0.0) {
            bad.push(format!(
                "ESTOP must short every motor in the step it arrived: {:?} ms",
                self.estop_brake_ms
            ));
        }
        if let Some(x) = self.joint_speed_excess_steps {
            if x > 1.0 {
                bad.push(format!(
                    "a joint exceeded its cap by {x} steps per tick (tolerance 1)"
                ));
            }
        }
        if let Some(x) = self.joint_max_abs_rad {
            if x > core::f64::consts::PI {
                bad.push(format!("a joint reached {x} rad, beyond ±π"));
            }
        }
        if let Some(max) = e.max_joint_error_steps {
            match self.joint_err_steps {
                Some(x) if x <= max => {}
                other => bad.push(format!(
                    "joint error at the end of a move: expected ≤ {max} steps, got {other:?}"
                )),
            }
        }
        if let Some(max) = e.max_steps_after_brake {
            match self.steps_after_brake {
                Some(x) if x <= max => {}
                other => bad.push(format!(
                    "steps after BRAKE: expected ≤ {max}, got {other:?}"
                )),
            }
        }
        if let Some(max) = e.max_odometry_error_pct {
            match self.odometry_err_pct {
                Some(x) if x <= max => {}
                other => bad.push(format!(
                    "odometry error: expected ≤ {max} % of the distance travelled, got {} (board vs plant: {} m over {} m, heading {} deg)",
                    other.map_or("none".into(), |x| format!("{x:.3} %")),
                    self.odometry_err_m.map_or("-".into(), |x| format!("{x:.4}")),
                    self.odometry_travel_m.map_or("-".into(), |x| format!("{x:.3}")),
                    self.odometry_heading_err_deg.map_or("-".into(), |x| format!("{x:.2}")),
                )),
            }
        }
        if let Some(max) = e.max_servo_violations {
            match self.servo_violations {
                Some(n) if n <= max => {}
                other => bad.push(format!(
                    "servo outputs differing from the rules: expected ≤ {max}, got {other:?} of {} checks",
                    self.servo_checks
                )),
            }
        }
        if e.shutdown_brakes_in_its_transfer && self.shutdown_brake_ms != Some(0.0) {
            bad.push(format!(
                "a motor shutdown transfer must short every motor in its own step: largest {:?} ms over {} shutdown transfers",
                self.shutdown_brake_ms, self.shutdown_transfers
            ));
        }
        if let Some([lo, hi]) = e.brake_after_last_frame_ms {
            match self.brake_after_last_frame_ms {
                Some(x) if x >= lo && x <= hi => {}
                other => bad.push(format!(
                    "BRAKE after last frame: expected {lo}..{hi} ms, got {other:?}"
                )),
            }
        }
        if e.never_brake && self.brake_entries > 0 {
            bad.push(format!("expected no BRAKE, got {}", self.brake_entries));
        }
        if let Some(max) = e.max_stop_distance_m {
            match self.stop_distance_m {
                Some(d) if d <= max => {}
                other => bad.push(format!("stop distance: expected ≤ {max} m, got {other:?}")),
            }
        }
        if let Some(max) = e.max_corrupted_applied {
            if self.corrupted_applied > max {
                bad.push(format!(
                    "corrupted frames applied: expected ≤ {max}, got {}",
                    self.corrupted_applied
                ));
            }
        }
        if let Some(m) = e.moving_at_end {
            if (self.final_v.abs() > 0.1) != m {
                bad.push(format!(
                    "moving at end: expected {m}, v = {:.3}",
                    self.final_v
                ));
            }
        }
        for r in &e.host_reports {
            if !self.host_reports.iter().any(|(_, n, _)| n == r) {
                bad.push(format!("host did not report {r}"));
            }
        }
        if let Some(max) = e.max_clock_error_us {
            match self.clock_err_final_us {
                Some(x) if x <= max => {}
                other => bad.push(format!("clock error: expected ≤ {max} us, got {other:?}")),
            }
        }
        if let Some(m) = &e.final_mode {
            if &self.final_mode != m {
                bad.push(format!("final mode: expected {m}, got {}", self.final_mode));
            }
        }
        bad
    }
}

/// Result of one run.
#[derive(Clone, Debug, Default)]
pub struct RunResult {
    /// Figures.
    pub summary: Summary,
    /// Series for plots (empty unless asked for).
    pub series: Series,
}

struct Transfer {
    t_send_host: u64,
    cs_rise: f64,
    recv: f64,
    tx: [u8; FRAME_LEN],
    rx: [u8; FRAME_LEN],
    rx_stamp: Option<(u64, f64)>,
    corrupted: bool,
    mcu_done: bool,
}

/// Flips bits or overwrites a burst of bytes, as EMI does. Returns true if the frame changed.
pub fn corrupt(frame: &mut [u8], rng: &mut Rng) -> bool {
    let before = frame.to_vec();
    let len_total = frame.len();
    if len_total == 0 {
        return false;
    }
    if rng.chance(0.5) {
        let n = 1 + rng.below(4);
        for _ in 0..n {
            let bit = rng.below(len_total as u64 * 8) as usize;
            frame[bit / 8] ^= 1 << (bit % 8);
        }
    } else {
        let len = (1 + rng.below(8) as usize).min(len_total);
        let start = rng.below((len_total - len + 1) as u64) as usize;
        for b in &mut frame[start..start + len] {
            *b = rng.next_u64() as u8;
        }
    }
    *frame != before[..]
}

/// Runs `sc` against `host`; writes the CSV trace to `trace` if given. `host` is the seed 000
/// host; the other profiles run their own scripted hosts ([`crate::cdc`], [`crate::teensy`],
/// [`crate::pi_spi`]).
pub fn run<H: HostModel>(
    sc: &Scenario,
    host: &mut H,
    opts: RunOptions,
    trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    match sc.profile {
        Profile::AmrSpi => run_amr(sc, host, opts, trace),
        Profile::Cdc => crate::cdc::run(sc, opts, trace),
        Profile::Teensy => crate::teensy::run(sc, opts, trace),
        Profile::PiSpi => crate::pi_spi::run(sc, opts, trace),
    }
}

fn run_amr<H: HostModel>(
    sc: &Scenario,
    host: &mut H,
    opts: RunOptions,
    trace: Option<&mut dyn Write>,
) -> std::io::Result<RunResult> {
    let wall = Instant::now();
    let (mcu_ppm, host_ppm) = sc.drift_ppm();
    let mcu_rate = 1.0 + mcu_ppm * 1e-6;
    let host_rate = 1.0 + host_ppm * 1e-6;
    let dt = STEP_S / mcu_rate;
    let host_clock = |t: f64| (HOST_EPOCH_US + t * 1e6 * host_rate).max(0.0) as u64;
    let mut rng = Rng::new(sc.seed);
    let mut plant = Plant::new(sc.plant);
    let tuning = crate::board::amr_tuning(&sc.plant);
    let counters = crate::board::encoder_counters;
    let mut mcu = SimBoard::new(tuning, counters(&plant), (ResetCause::PowerOn, 0));
    let mut last_feed = 0.0f64;
    // The stamp of the feedback in the MCU's tx buffer: (MCU µs, true time).
    let mut stamp: Option<(u64, f64)> = None;
    let mut frozen_since: Option<f64> = None;
    let mut freeze_done = false;

    let mut requests: Vec<Request> = sc.requests.clone();
    requests.sort_by(|a, b| a.at().total_cmp(&b.at()));
    let mut next_request = 0usize;
    let period = sc.host.link_period_ms * 1e-3 / host_rate;
    let mut next_cycle = period;
    let nav2_period = 1.0 / sc.host.nav2_rate_hz;
    let mut next_nav2 = 0.0;
    let mut inflight: Option<Transfer> = None;

    let onset = sc.fault_onset();
    let mut s = Summary::new(sc);
    let mut series = Series::default();
    let mut last_valid_t: Option<f64> = None;
    let mut watch = Watch::new(mcu.out.mode);
    let mut clock_err_sum = 0.0;
    let mut clock_err_n = 0u64;
    let mut seed_err_sum = 0.0;
    let mut seed_err_n = 0u64;
    let mut last_progress = 0.0;

    let mut trace = Trace::new(sc, trace, "host_cmd_l,host_cmd_r,applied_l,applied_r,wheel_l,wheel_r,est_l,est_r,current_l,current_r,duty_l,duty_r,brake,v_mps,w_radps,x_m,y_m,odometer_m,frames_sent,corrupted_sent,corrupted_applied,rejected,clock_err_us")?;

    let mut tick_index = 0u64;
    for (n, t) in sc.steps(dt) {
        let paused = sc.host_paused(t);
        let link_cut = sc.link_cut(t);

        // Nav2 publishes at its rate (nothing while the host process is paused or Nav2 stalls).
        while next_nav2 <= t {
            if !paused && !sc.nav2_gap(next_nav2) {
                if let Some((v, w)) = sc.cmd_vel_at(next_nav2) {
                    host.cmd_vel(host_clock(t), v, w);
                }
            }
            next_nav2 += nav2_period;
        }
        while !paused && next_request < requests.len() && requests[next_request].at() <= t {
            host.request(host_clock(t), requests[next_request]);
            next_request += 1;
        }

        // Faults that act on the MCU side.
        let mut overcurrent = [0.0f64; 2];
        let mut estop = false;
        for f in &sc.faults {
            match *f {
                Fault::McuFreeze { at_s, .. }
                    if frozen_since.is_none() && !freeze_done && t >= at_s =>
                {
                    frozen_since = Some(t);
                }
                Fault::EncoderGlitch {
                    at_s,
                    wheel,
                    counts,
                } if t >= at_s && t < at_s + dt => {
                    let k = wheel.index();
                    mcu.glitch[k] = mcu.glitch[k].wrapping_add(counts);
                }
                Fault::Overcurrent { wheel, amps, .. } if f.active_at(t) => {
                    overcurrent[wheel.index()] += amps;
                }
                Fault::Estop { .. } => {
                    estop |= f.active_at(t);
                }
                _ => {}
            }
        }
        if frozen_since.is_some() {
            let iwdg = sc
                .faults
                .iter()
                .find_map(|f| match *f {
                    Fault::McuFreeze { iwdg_ms, .. } => Some(iwdg_ms * 1e-3),
                    _ => None,
                })
                .unwrap_or(0.02);
            if t >= last_feed + iwdg {
                // The independent watchdog was not refreshed for its timeout: the MCU resets and
                // restarts latched in BRAKE (POWER_ON). One freeze per scenario.
                frozen_since = None;
                freeze_done = true;
                mcu = SimBoard::new(
                    tuning,
                    counters(&plant),
                    (ResetCause::IndependentWatchdog, 1),
                );
                last_feed = t;
                stamp = None;
            }
        }
        let frozen = frozen_since.is_some();

        // SPI: the MCU sees the end of the transfer at CS rise.
        if let Some(tr) = inflight.as_mut() {
            if !tr.mcu_done && tr.cs_rise <= t {
                tr.mcu_done = true;
                if !frozen && !link_cut {
                    let (accepted, stamp_us) = mcu.on_frame(&tr.tx);
                    stamp = Some((u64::from(stamp_us), t));
                    if accepted {
                        last_valid_t = Some(tr.cs_rise);
                        if tr.corrupted {
                            s.corrupted_applied += 1;
                        }
                    } else if tr.corrupted {
                        s.corrupted_rejected += 1;
                    }
                }
            }
        }
        if inflight.as_ref().is_some_and(|tr| tr.recv <= t) {
            if let Some(tr) = inflight.take() {
                let t_recv = host_clock(tr.recv);
                host.end_cycle(tr.t_send_host, t_recv, &tr.rx);
                if let Some((mcu_us, true_t)) = tr.rx_stamp {
                    let truth = HOST_EPOCH_US + true_t * 1e6 * host_rate;
                    let (ours, seed) = host.mcu_to_host_us(mcu_us);
                    if let Some(est) = ours {
                        let err = (est - truth).abs();
                        if t > 10.0 {
                            s.clock_err_max_us = Some(s.clock_err_max_us.unwrap_or(0.0).max(err));
                        }
                        if t > sc.duration_s - 1.0 {
                            clock_err_sum += err;
                            clock_err_n += 1;
                        }
                    }
                    if let Some(est) = seed {
                        if t > sc.duration_s - 1.0 {
                            seed_err_sum += (est - truth).abs();
                            seed_err_n += 1;
                        }
                    }
                }
                for d in host.drain_diagnostics() {
                    add_report(&mut s.host_reports, t, &d, 1);
                }
            }
        }
        // The host starts a cycle when its deadline passed (a paused host starts none).
        if inflight.is_none() && next_cycle <= t {
            let due = next_cycle;
            while next_cycle <= t {
                next_cycle += period;
            }
            if !paused {
                let mut start = due + rng.uniform() * sc.host.send_jitter_us * 1e-6;
                if rng.chance(sc.host.preempt_rate) {
                    start += 0.3e-3 + rng.uniform() * 2.7e-3;
                }
                let start = start.max(t);
                let mut tx = [0u8; FRAME_LEN];
                host.begin_cycle(host_clock(start), &mut tx);
                s.frames_sent += 1;
                let mut corrupted = false;
                let mut corrupt_feedback = false;
                for f in &sc.faults {
                    if let Fault::Corruption { rate, feedback, .. } = *f {
                        if f.active_at(t) && rng.chance(rate) {
                            corrupted |= corrupt(&mut tx, &mut rng);
                        }
                        if feedback && f.active_at(t) && rng.chance(rate) {
                            corrupt_feedback = true;
                        }
                    }
                }
                if corrupted {
                    s.corrupted_sent += 1;
                }
                let cs_fall = start + 5e-6;
                let cs_rise = cs_fall + TRANSFER_S;
                let mut recv = cs_rise + 5e-6 + rng.uniform() * sc.host.recv_jitter_us * 1e-6;
                if rng.chance(sc.host.preempt_rate) {
                    recv += 0.3e-3 + rng.uniform() * 2.7e-3;
                }
                let mut rx = if link_cut {
                    [0u8; FRAME_LEN]
                } else {
                    mcu.tx_buffer
                };
                if corrupt_feedback {
                    corrupt(&mut rx, &mut rng);
                }
                inflight = Some(Transfer {
                    t_send_host: host_clock(start),
                    cs_rise,
                    recv,
                    tx,
                    rx,
                    rx_stamp: if link_cut { None } else { stamp },
                    corrupted,
                    mcu_done: false,
                });
            }
        }

        // MCU tasks.
        let counts = counters(&plant);
        let shunt = [
            plant.current[0] + overcurrent[0],
            plant.current[1] + overcurrent[1],
        ];
        let mut ticked = false;
        if !frozen {
            mcu.set_estop(estop);
            let rep = mcu.step(counts, shunt);
            ticked = rep.ticked;
            if rep.fed_watchdog {
                last_feed = t;
            }
        }
        plant.step(dt, crate::board::bridge_drive(&mcu.bridge), [0.0; 2]);

        // Measurements.
        let out = mcu.out;
        watch.mode(&mut s, t, out.mode, out.faults, last_valid_t);
        let braked = onset.is_some()
            && crate::board::bridge_drive(&mcu.bridge)
                .iter()
                .all(|d| matches!(d, BridgeDrive::Short));
        if let Some(o) = onset {
            if t >= o
                && braked
                && out.faults.contains(FaultFlags::COMM_LOST)
                && s.bridge_brake_after_last_frame_ms.is_none()
            {
                s.bridge_brake_after_last_frame_ms = last_valid_t.map(|lv| (t - lv) * 1e3);
            }
        }
        watch.motion(&mut s, t, &plant, &plant.current, braked);

        if ticked || (frozen && n % 20 == 0) {
            tick_index += 1;
            let ws = plant.wheel_speeds();
            let hc = host.last_command();
            let ap = out
                .drive
                .speeds()
                .map_or([0.0; 2], |s| s.map(|v| v.to_num::<f64>()));
            let due = trace.due(tick_index);
            if opts.keep_series && due {
                series.push_tick(t, out.mode, out.age, []);
                for k in 0..2 {
                    series.wheel[k].push(ws[k]);
                    series.host_cmd[k].push(f64::from(hc[k]));
                    series.applied[k].push(ap[k]);
                }
                series.v.push(plant.v);
            }
            if due {
                if let Some(w) = trace.row(t, out.mode, out.age, out.faults)? {
                    let est = mcu.speed_estimate();
                    let brake = matches!(
                        crate::board::bridge_drive(&mcu.bridge)[0],
                        BridgeDrive::Short
                    );
                    let duty = mcu.duty();
                    writeln!(
                        w,
                        "{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{}",
                        hc[0],
                        hc[1],
                        ap[0],
                        ap[1],
                        ws[0],
                        ws[1],
                        est[0],
                        est[1],
                        mcu.measured[0],
                        mcu.measured[1],
                        duty[0],
                        duty[1],
                        u8::from(brake),
                        plant.v,
                        plant.w,
                        plant.x,
                        plant.y,
                        plant.odometer,
                        s.frames_sent,
                        s.corrupted_sent,
                        s.corrupted_applied,
                        mcu.safety().ladder().counters().rejected_total(),
                        if clock_err_n > 0 { format!("{:.2}", clock_err_sum / clock_err_n as f64) } else { String::new() },
                    )?;
                }
            }
        }
        if opts.progress && sc.duration_s >= 20.0 && t - last_progress >= sc.duration_s / 20.0 {
            last_progress = t;
            let el = wall.elapsed().as_secs_f64();
            eprintln!(
                "  {}: {:>3.0} % ({:.0} of {:.0} s simulated, {:.0}x real time)",
                sc.name,
                100.0 * t / sc.duration_s,
                t,
                sc.duration_s,
                t / el.max(1e-9)
            );
        }
    }

    s.final_v = plant.v;
    if clock_err_n > 0 {
        s.clock_err_final_us = Some(clock_err_sum / clock_err_n as f64);
    }
    if seed_err_n > 0 {
        s.seed_clock_err_final_us = Some(seed_err_sum / seed_err_n as f64);
    }
    s.finish(sc, wall, mcu.safety().ladder().counters(), mcu.out.mode);
    Ok(RunResult { summary: s, series })
}
