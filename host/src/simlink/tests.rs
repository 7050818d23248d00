//! The host's real bridge and link over the simulated board: driving, comm loss, ESTOP, re-arm.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use super::*;
use crate::bridge::{ArmState, Bridge, BridgeConfig};
use protocol::amr::{self, McuFrame, MotorCommand, MotorFeedback};
use statemachine::{ControlMode, FaultFlags};

/// The default robot's wheel radius, m (`PlantParams::default`, the host's `DiffDrive::DEFAULT`).
const WHEEL_R: f64 = 0.08;

fn link() -> Link<SimMcu> {
    Link::new(SimMcu::lockstep(), Bridge::new(BridgeConfig::DEFAULT))
}

/// `n` lockstep cycles with cmd_vel (v, w) fresh in each.
fn drive(l: &mut Link<SimMcu>, n: u32, v: f64, w: f64) -> Vec<Diagnostic> {
    let mut diags = Vec::new();
    for _ in 0..n {
        let now = l.transport.now_us();
        l.bridge.cmd_vel(now, v, w);
        diags.extend(l.sim_cycle().unwrap().into_iter().map(|(_, d)| d));
    }
    diags
}

/// Armed and driving at (v, w) for `n` cycles.
fn armed(v: f64, n: u32) -> Link<SimMcu> {
    let mut l = link();
    l.bridge.arm(l.transport.now_us());
    drive(&mut l, n, v, 0.0);
    assert_eq!(l.bridge.state(), ArmState::Armed);
    l
}

fn feedback(l: &Link<SimMcu>) -> MotorFeedback {
    l.bridge.last_feedback.unwrap()
}

/// A command frame as the bridge would build it, `seq` fresh.
fn command(seq: u32, enable: bool, speed: f32) -> [u8; FRAME_LEN] {
    let mut tx = [0u8; FRAME_LEN];
    amr::encode_command(
        &MotorCommand {
            timestamp_us: seq,
            left_speed_cmd: speed,
            right_speed_cmd: speed,
            control_mode: ControlMode::Speed as u32,
            enable,
            seq,
            request: 0,
        },
        &mut tx,
    );
    tx
}

/// A frame the board refuses (its CRC broken): it changes nothing but counters, and the board
/// still answers it with a feedback frame in the next slot.
fn broken(seq: u32) -> [u8; FRAME_LEN] {
    let mut tx = command(seq, true, 0.0);
    tx[3] ^= 0x5a;
    tx
}

/// One raw exchange; the feedback that came back.
fn raw(sim: &mut SimMcu, tx: &[u8; FRAME_LEN]) -> MotorFeedback {
    let mut rx = [0u8; FRAME_LEN];
    sim.exchange(tx, &mut rx).unwrap();
    match amr::decode_mcu_frame(&rx).unwrap() {
        McuFrame::Feedback(fb) => fb,
        McuFrame::Info(i) => panic!("info frame {i:?}"),
    }
}

#[test]
fn the_bridge_drives_the_simulated_robot_at_the_commanded_speed() {
    for v in [0.3, -0.2] {
        let l = armed(v, 2000);
        let t = l.transport.truth();
        // 2 s, of which the ramp (0.04 rad/s per cycle: under 100 cycles) and the speed loop's
        // settling take a small part: the robot moves at the commanded speed, in its direction.
        assert!((t.v_mps - v).abs() < 0.05 * v.abs(), "v {v}: {t:?}");
        assert!(t.w_radps.abs() < 0.01, "{t:?}");
        for w in t.wheel_radps {
            assert!(
                (w - v / WHEEL_R).abs() < 0.05 * (v / WHEEL_R).abs(),
                "{t:?}"
            );
        }
        // Travelled: at most v for 2 s, at least v for the last 1.5 s.
        assert!(t.x_m.signum() == v.signum(), "{t:?}");
        assert!(
            t.x_m.abs() > 1.5 * v.abs() && t.x_m.abs() < 2.0 * v.abs() * 1.05,
            "{t:?}"
        );
        // The board's own view: NORMAL, its measured speeds near the truth.
        let fb = feedback(&l);
        assert_eq!(fb.mode, Mode::Normal as u32);
        // Its estimate moves in steps of one encoder count per estimator window (0.96 rad/s).
        for s in [fb.left_speed, fb.right_speed] {
            assert!((f64::from(s) - v / WHEEL_R).abs() < 1.0, "{fb:?}");
        }
        // Lockstep: one board millisecond per exchange.
        assert_eq!(l.transport.now_us(), 2_000_000);
        assert_eq!(l.transport.exchanges(), 2000);
        assert_eq!(l.bridge.stats.feedback_rejected, 0);
    }
}

#[test]
fn lockstep_runs_are_identical() {
    let a = armed(0.25, 700).transport.truth();
    let b = armed(0.25, 700).transport.truth();
    assert_eq!(a, b);
    assert!(a.x_m > 0.0);
}

#[test]
fn silence_brakes_the_board_within_the_ladders_bound() {
    // The last valid frame reaches spi_dma_done at some board time t0 (stamped in the feedback
    // it answers with). After `n` ms of silence a refused frame probes the board: its answer,
    // stamped and carrying the board's mode, comes back in the next slot.
    let mut seen = Vec::new();
    for n in 0..14u64 {
        let mut l = armed(0.3, 600);
        let mut seq = 1_000_000;
        // The feedback to the last valid frame: one more exchange brings it back.
        l.bridge.cmd_vel(l.transport.now_us(), 0.3, 0.0);
        l.sim_cycle().unwrap();
        let sim = &mut l.transport;
        let last_valid = raw(sim, &broken(seq));
        sim.idle(n);
        seq += 1;
        raw(sim, &broken(seq));
        let probe = raw(sim, &broken(seq + 1));
        let after_ms = (probe.timestamp_us - last_valid.timestamp_us) as f64 / 1000.0;
        seen.push((after_ms, probe.mode, probe.fault_flags));
    }
    // The ladder's contract: BRAKE no later than 10 ms after the last valid frame, and it passes
    // through HOLD and STOP on the way (never straight from NORMAL to BRAKE). The refused probes
    // count against the link's quality, so the first probe may already show REDUCED: the rungs
    // only ever descend (0 NORMAL, 1 REDUCED, 2 HOLD, 3 STOP, 4 BRAKE).
    let first_brake = seen
        .iter()
        .find(|s| s.1 == Mode::Brake as u32)
        .expect("braked");
    assert!(first_brake.0 <= 10.0, "{seen:?}");
    assert!(
        FaultFlags(first_brake.2 as u16).contains(FaultFlags::COMM_LOST),
        "{seen:?}"
    );
    let modes: Vec<u32> = seen.iter().map(|s| s.1).collect();
    assert!(modes.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    assert!(modes.contains(&(Mode::Hold as u32)), "{seen:?}");
    assert!(modes.contains(&(Mode::Stop as u32)), "{seen:?}");
    assert!(modes[0] <= Mode::Reduced as u32, "{seen:?}");
    // Once braked, it stays braked for the rest of the silence.
    let at = seen.iter().position(|s| s.1 == Mode::Brake as u32).unwrap();
    assert!(seen[at..].iter().all(|s| s.1 == Mode::Brake as u32));
}

#[test]
fn idle_latches_the_bridge_and_the_robot_stops_until_an_explicit_rearm() {
    let mut l = armed(0.3, 1000);
    l.transport.idle(50);
    // The host resumes with the robot braked: the bridge sees BRAKE and latches (enable 0).
    let d = drive(&mut l, 1000, 0.3, 0.0);
    assert!(
        d.iter()
            .any(|d| matches!(d, Diagnostic::BrakeLatched { .. })),
        "{d:?}"
    );
    assert_eq!(l.bridge.state(), ArmState::Latched);
    assert_eq!(feedback(&l).mode, Mode::Brake as u32);
    let t = l.transport.truth();
    assert!(t.braked && t.v_mps.abs() < 0.01, "{t:?}");
    // An explicit re-arm: the robot moves again.
    l.bridge.rearm(l.transport.now_us());
    let d = drive(&mut l, 1500, 0.3, 0.0);
    assert!(d.contains(&Diagnostic::Rearmed), "{d:?}");
    assert_eq!(feedback(&l).mode, Mode::Normal as u32);
    assert!((l.transport.truth().v_mps - 0.3).abs() < 0.015);
}

#[test]
fn fresh_enabled_frames_alone_never_leave_brake() {
    let mut l = armed(0.3, 500);
    l.transport.idle(50);
    let sim = &mut l.transport;
    let mut seq = 10_000;
    // Valid, fresh, enabled frames for 0.5 s: the board stays in BRAKE (no edge of enable).
    for _ in 0..500 {
        seq += 1;
        raw(sim, &command(seq, true, 2.0));
    }
    seq += 1;
    let fb = raw(sim, &command(seq, true, 2.0));
    assert_eq!(fb.mode, Mode::Brake as u32);
    assert!(sim.truth().braked);
    // The re-arm: a valid frame with enable 0, then enable 1 (the rising edge), then fresh
    // frames. A few at a speed within the acceleration limit from rest.
    seq += 1;
    raw(sim, &command(seq, false, 0.0));
    for _ in 0..20 {
        seq += 1;
        raw(sim, &command(seq, true, 0.0));
    }
    seq += 1;
    let fb = raw(sim, &command(seq, true, 0.0));
    assert_ne!(fb.mode, Mode::Brake as u32, "{fb:?}");
    assert!(!sim.truth().braked);
}

#[test]
fn estop_brakes_and_stays_braked_until_rearmed() {
    let mut l = armed(0.3, 1000);
    l.transport.set_estop(true);
    // The edge handler brakes the bridges at once, before any tick.
    assert!(l.transport.truth().braked);
    let d = drive(&mut l, 1000, 0.3, 0.0);
    let fb = feedback(&l);
    assert_eq!(fb.mode, Mode::Brake as u32);
    assert!(FaultFlags(fb.fault_flags as u16).contains(FaultFlags::ESTOP));
    assert!(d
        .iter()
        .any(|d| matches!(d, Diagnostic::BrakeLatched { .. })));
    let t = l.transport.truth();
    assert!(t.v_mps.abs() < 0.01, "{t:?}");
    // Released: still braked (no automatic restart) until the host re-arms.
    l.transport.set_estop(false);
    drive(&mut l, 500, 0.3, 0.0);
    assert_eq!(feedback(&l).mode, Mode::Brake as u32);
    assert!(l.transport.truth().braked);
    l.bridge.rearm(l.transport.now_us());
    drive(&mut l, 1500, 0.3, 0.0);
    assert_eq!(feedback(&l).mode, Mode::Normal as u32);
    assert!((l.transport.truth().v_mps - 0.3).abs() < 0.015);
}

#[test]
fn wall_clock_silence_brakes_the_board() {
    let mut sim = SimMcu::wall();
    sim.idle(30);
    // At least 30 ms of wall time passed, all of it run by the board: no frame ever, BRAKE.
    assert!(sim.now_us() >= 30_000, "{}", sim.now_us());
    assert_eq!(sim.mode(), Mode::Brake);
}

#[test]
fn frames_of_the_wrong_length_are_refused() {
    let mut sim = SimMcu::lockstep();
    let mut rx = [0u8; FRAME_LEN];
    let e = sim.exchange(&[0u8; 10], &mut rx).unwrap_err();
    assert!(e.to_string().contains("64-byte"), "{e}");
    assert_eq!(sim.exchanges(), 0);
}

#[test]
fn a_plant_with_an_impossible_geometry_is_refused() {
    let mut cfg = SimConfig::new(SimClock::Lockstep);
    cfg.plant.wheel_radius_m = 0.0;
    let e = SimMcu::new(cfg).unwrap_err();
    assert!(e.to_string().contains("WheelRadius"), "{e}");
}
