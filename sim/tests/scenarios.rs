//! Every built-in scenario as a test: its own expectations plus physics and ladder checks whose
//! bounds come from the plant parameters, not from the simulator's output.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use motorlink::SimHost;
use sim::runner::STEP_S;
use sim::scenario::{builtin, Scenario};
use sim::Summary;

fn run(name: &str) -> (Scenario, Summary, SimHost) {
    let sc = builtin()
        .unwrap()
        .into_iter()
        .find(|s| s.name == name)
        .unwrap_or_else(|| panic!("no built-in {name}"));
    let mut host = SimHost::new();
    let r = sim::run(&sc, &mut host, sim::RunOptions::default(), None).unwrap();
    let fails = r.summary.check(&sc);
    assert!(fails.is_empty(), "{name}: {fails:#?}\n{:#?}", r.summary);
    (sc, r.summary, host)
}

/// Upper bound of the distance after a comm-loss or fault BRAKE from speed v0: `lag` s at v0,
/// then dynamic braking, whose exponential decay covers v0 · m_eff / k_short (rolling
/// resistance and drag only shorten it).
fn brake_bound(sc: &Scenario, v0: f64, lag: f64) -> f64 {
    let p = sc.plant;
    v0 * (lag + p.m_eff() / p.short_brake_damping())
}

fn first_report(s: &Summary, name: &str) -> f64 {
    s.host_reports
        .iter()
        .find(|(_, n, _)| n == name)
        .map(|(t, _, _)| *t)
        .unwrap_or_else(|| panic!("{name} not reported: {:?}", s.host_reports))
}

#[test]
fn every_scenario_file_parses() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            Scenario::load(&p).unwrap();
            n += 1;
        }
    }
    assert!(n >= builtin().unwrap().len());
}

#[test]
fn nominal_never_brakes_and_tracks() {
    let (_, s, _) = run("nominal");
    assert_eq!(s.brake_entries, 0);
    // 1.0 m/s commanded; the REDUCED limit (10 rad/s · 0.08 m = 0.8 m/s) applies for the first
    // second, then NORMAL: the peak is the commanded speed, not more.
    assert!(
        s.peak_speed > 0.95 && s.peak_speed < 1.05,
        "{}",
        s.peak_speed
    );
}

#[test]
fn gc_pause_brakes_strictly_within_ten_ms_of_the_last_frame() {
    let (sc, s, _) = run("gc-pause-50ms");
    let b = s.brake_after_last_frame_ms.unwrap();
    // BRAKE at the 9th tick after the last valid frame: the first tick comes within 1 ms of the
    // frame (one 50 µs step of granularity), the 9th 8 ms after the first.
    assert!((8.0 - STEP_S * 1e3..=9.0).contains(&b), "{b}");
    // The seed's headline, at the outputs: both bridges braked strictly within 10 ms of the frame.
    let bridge = s.bridge_brake_after_last_frame_ms.unwrap();
    assert!(bridge >= b && bridge < 10.0, "{bridge}");
    // From the pause start, whose last frame came up to 1 ms before it: HOLD at the 3rd tick after that
    // frame (age 3), STOP at the 5th, BRAKE at the 9th, each up to 1 ms earlier as seen from the pause.
    let (h, st, br) = (s.hold_ms.unwrap(), s.stop_ms.unwrap(), s.brake_ms.unwrap());
    assert!((1.0..=3.0).contains(&h), "{h}");
    assert!((3.0..=5.0).contains(&st), "{st}");
    assert!((7.0..=9.0).contains(&br), "{br}");
    let v0 = s.speed_at_onset.unwrap();
    assert!((v0 - 1.0).abs() < 0.05, "{v0}");
    let d = s.stop_distance_m.unwrap();
    let bound = brake_bound(&sc, v0, 0.010);
    assert!(d <= bound, "{d} > {bound}");
    // And not absurdly short: the 8 ms at speed before BRAKE alone cover 8 mm.
    assert!(d > 0.008 * v0 * 0.9, "{d}");
    assert_eq!(s.final_mode, "BRAKE");
}

#[test]
fn corruption_is_never_applied() {
    for name in ["corruption-1e-4", "corruption-1e-3", "corruption-1e-2"] {
        let (_, s, _) = run(name);
        assert!(s.corrupted_sent > 0, "{name}: nothing corrupted");
        assert_eq!(s.corrupted_applied, 0, "{name}");
        assert_eq!(s.corrupted_rejected, s.corrupted_sent, "{name}");
        assert_eq!(s.brake_entries, 0, "{name}");
    }
}

#[test]
fn nav2_gap_is_bridged_and_a_stall_stops_softly() {
    let (_, s, _) = run("nav2-gap-100ms");
    assert_eq!(s.brake_entries, 0);
    assert!(s.final_v > 0.9);
    let (_, s, _) = run("nav2-stall-300ms");
    assert_eq!(s.brake_entries, 0);
    // Last cmd_vel before the stall at 1.95 s (20 Hz); stale 200 ms later.
    let t = first_report(&s, "cmd_vel_stale");
    assert!((2.149..=2.153).contains(&t), "{t}");
}

#[test]
fn clock_sync_beats_the_seed_under_drift() {
    let (_, s, _) = run("clock-drift-50ppm");
    let ours = s.clock_err_final_us.unwrap();
    let seed = s.seed_clock_err_final_us.unwrap();
    assert!(ours < 50.0, "{ours}");
    // The seed's EMA lags a 50 ppm ramp and its int() stalls it: at least several µs.
    assert!(seed > 2.0 * ours, "seed {seed} ours {ours}");
}

#[test]
fn mcu_freeze_is_detected_by_the_host_and_ends_in_brake() {
    let (sc, s, host) = run("mcu-freeze");
    let t = first_report(&s, "mcu_frozen");
    // 5 ms stale limit after the last advancing feedback, within a couple of cycles.
    assert!((2.004..=2.008).contains(&t), "{t}");
    // The independent watchdog (20 ms) counts from its last refresh, the last tick before the
    // freeze (at most one tick earlier): the MCU resets and restarts in BRAKE (POWER_ON).
    let b = s.brake_ms.unwrap();
    assert!((18.95..=20.05).contains(&b), "{b}");
    // When feedback resumes the host asks the restarted MCU why: the IWDG, the first reset.
    let r = first_report(&s, "mcu_reset");
    assert!(r > 2.0 + b / 1e3 && r < 2.05, "{r}");
    let info = host.bridge.mcu_info().unwrap();
    assert_eq!(
        info.reset_cause,
        protocol::amr::ResetCause::IndependentWatchdog
    );
    assert_eq!(info.reset_count, 1);
    let d = s.stop_distance_m.unwrap();
    assert!(
        d <= brake_bound(&sc, s.speed_at_onset.unwrap(), 0.021),
        "{d}"
    );
}

#[test]
fn encoder_failure_and_overcurrent_brake_at_once() {
    // Overcurrent: the comparator and the current loop brake the bridge in the same 50 µs step.
    // Encoder failure: the tick checks the speed estimates, so the bridge brakes at the next tick.
    // Either way the ladder latches BRAKE at the next tick (≤ 1 ms + one step).
    for (name, bridge_within_ms) in [("encoder-failure", 1.05), ("overcurrent", 0.05)] {
        let (sc, s, _) = run(name);
        let b = s.bridge_brake_ms.unwrap();
        assert!(
            b <= bridge_within_ms + 1e-9,
            "{name}: bridge braked after {b} ms"
        );
        let l = s.brake_ms.unwrap();
        assert!(l <= 1.05 + 1e-9, "{name}: ladder BRAKE after {l} ms");
        let d = s.stop_distance_m.unwrap();
        assert!(
            d <= brake_bound(&sc, s.speed_at_onset.unwrap(), 0.001),
            "{name}: {d}"
        );
        assert!(s.host_reports.iter().any(|(_, n, _)| n == "brake_latched"));
    }
}

#[test]
fn estop_needs_the_rearm() {
    let (_, s, host) = run("estop-rearm");
    // The input's own handler brakes the bridge in the step of the press; the ladder latches at
    // the next tick.
    assert!(s.bridge_brake_ms.unwrap() <= 0.05);
    assert!(s.brake_ms.unwrap() <= 1.05);
    // The power-on arm and the operator's re-arm: nothing else released BRAKE.
    assert_eq!(s.rearms, 2);
    // Re-armed only after the operator's request at 3.5 s, never at the release (3.0 s).
    let t = first_report(&s, "rearmed");
    assert!((3.5..3.52).contains(&t), "{t}");
    assert!(host.log.iter().all(|(_, d)| d.name() != "arm_refused"));
}

/// Driving backwards and braking regeneratively makes the motor currents negative: the board
/// reports them signed, and the host must not take that for a failed current sensor.
#[test]
fn reverse_driving_raises_no_sensor_fault_end_to_end() {
    let sc = Scenario::from_toml(
        r#"
name = "reverse"
duration_s = 4.0
[[cmd_vel]]
from_s = 0.2
to_s = 2.0
v = -1.0
w = 0.0
[[cmd_vel]]
from_s = 2.0
to_s = 4.0
v = 0.0
w = 0.0
[expect]
never_brake = true
moving_at_end = false
"#,
        "test",
    )
    .unwrap();
    let mut host = SimHost::new();
    let mut trace = Vec::new();
    let r = sim::run(&sc, &mut host, sim::RunOptions::default(), Some(&mut trace)).unwrap();
    assert!(r.summary.check(&sc).is_empty(), "{:#?}", r.summary);
    // The run really drove backwards with negative currents (columns of the per-tick trace).
    let text = String::from_utf8(trace).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (v, il) = (col("v_mps"), col("current_l"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    assert!(rows.iter().any(|r| r[v] < -0.9), "never reached -0.9 m/s");
    assert!(
        rows.iter().any(|r| r[il] < -1.0),
        "no negative current seen"
    );
    let sensor_faults: Vec<_> = host
        .log
        .iter()
        .filter(|(_, d)| d.name().contains("current"))
        .collect();
    assert!(sensor_faults.is_empty(), "{sensor_faults:?}");
}

/// Seed 001: the frames' `timeout_ms` bounds the comm-loss BRAKE, in the board's own ticks.
#[test]
fn cdc_timeout_brakes_strictly_within_timeout_ms_and_the_robot_stops() {
    let (sc, s, _) = run("cdc-4wd-timeout");
    assert_eq!(s.profile, "cdc");
    // timeout_ms = 200: BRAKE at the 199th tick after the tick count of the last valid frame,
    // which arrived up to 1 ms before the next tick: within (198, 199] ms of it, under 200.
    assert_eq!(s.brake_after_last_frame_ticks, Some(199));
    let ms = s.brake_after_last_frame_ms.unwrap();
    assert!(ms > 198.0 && ms <= 199.0 + 1e-9, "{ms}");
    assert_eq!(
        s.bridge_brake_after_last_frame_ms,
        Some(ms),
        "shorted in the BRAKE tick"
    );
    // The last frame came up to 20 ms (one period) before the host stalled: HOLD at age 41 and
    // STOP at 61 are 21..41 and 41..61 ms after the stall.
    let (h, st) = (s.hold_ms.unwrap(), s.stop_ms.unwrap());
    assert!(
        (21.0..=41.0).contains(&h) && (41.0..=61.0).contains(&st),
        "{h} {st}"
    );
    // Distance after the stall: at most the speed at the stall for the 200 ms to BRAKE (the
    // duty only ramps down meanwhile), then four shorted motors' exponential decay.
    let v0 = s.speed_at_onset.unwrap();
    assert!(v0 > 0.5, "{v0}");
    let p = sim::skid::SMALL_4WD;
    let tau = p.m_eff_with(4.0) / (2.0 * p.short_brake_damping());
    let d = s.stop_distance_m.unwrap();
    assert!(d <= v0 * (0.2 + tau), "{d} > {v0} × (0.2 + {tau})");
    assert!(
        d > v0 * 0.02,
        "{d}: at speed for at least the 20 ms before HOLD"
    );
    // Everything the host received decoded; STATUS at 10 Hz, IMU at 100 Hz; each IMU frame
    // matches the true motion within the sensor's rounding (half an LSB: 0.031 mg, 3.82 mdps)
    // plus the integer division to the seed's units (under 1 mg, 1 mdps).
    let [ok, bad] = s.replies.unwrap();
    assert_eq!(bad, 0);
    let count = |name: &str| {
        s.host_reports
            .iter()
            .find(|(_, n, _)| n == name)
            .map_or(0, |r| r.2)
    };
    let secs = sc.duration_s;
    assert!(
        (count("imu") as f64 - 100.0 * secs).abs() <= 2.0,
        "{}",
        count("imu")
    );
    assert!(
        (count("status") as f64 - 10.0 * secs).abs() <= 1.0,
        "{}",
        count("status")
    );
    assert_eq!(ok, count("imu") + count("status") + count("ack_ok"));
    let [mg, mdps] = s.imu_max_err.unwrap();
    assert!(mg < 1.031 && mdps < 4.82, "{mg} mg, {mdps} mdps");
    // The turn (about 0.6 rad/s) is beyond the seed's i16 mdps (±32.767 dps): those frames are
    // sent at the limit and counted, never wrapped.
    assert!(s.imu_saturated > 0);
    // The host sees cmd_timeout in the first STATUS after the BRAKE.
    let t = first_report(&s, "status_cmd_timeout");
    assert!(t > 3.5 + 0.178 && t < 3.5 + 0.2 + 0.1 + 0.01, "{t}");
}

/// Seed 001's ESTOP, its release and MOTOR_ENABLE, through the board's byte stream.
#[test]
fn cdc_estop_brakes_at_once_and_only_enable_after_the_release_rearms() {
    let (_, s, _) = run("cdc-estop-release");
    // ESTOP 1 shorts every motor in the 100 µs step its last byte arrived.
    assert_eq!(s.estop_brake_ms, Some(0.0));
    // Re-arms: the power-on MOTOR_ENABLE 1 and the one after the release; the one sent while
    // the ESTOP held was refused (ACK 1, checked with the others by the scenario).
    assert_eq!(s.rearms, 2);
    assert_eq!(s.rearm_violations, 0);
    // ESTOP, then the comm loss.
    assert_eq!(s.brake_entries, 2);
    // MOTOR_ENABLE 0 held the motors off under the 50 Hz frames until the link was cut.
    assert_eq!(s.duty_while_disabled, Some(0.0));
    assert!(s.speed_at_onset.unwrap() < 0.3, "coasting since 3.0 s");
    assert_eq!(s.brake_after_last_frame_ticks, Some(99));
    assert!(s
        .host_reports
        .iter()
        .any(|(_, n, _)| n == "status_estop_latched"));
}

#[test]
fn cdc_bit_errors_are_refused_never_applied() {
    let (_, s, _) = run("cdc-bit-errors");
    assert!(s.corrupted_sent >= 10, "{}", s.corrupted_sent);
    assert_eq!(s.corrupted_applied, 0);
    assert_eq!(s.corrupted_rejected, s.corrupted_sent);
    assert!(s.rejected_total > 0);
    assert_eq!(s.brake_after_last_frame_ticks, Some(149));
    // Every refusal is reported once in the next STATUS's err.
    assert!(s.host_reports.iter().any(|(_, n, _)| n == "status_err"));
}

/// Seed 003: the arm moves to its angles under its caps and stops on comm loss.
#[test]
fn teensy_joints_reach_their_angles_within_a_step_and_brake_within_250_ms() {
    let (_, s, _) = run("teensy-arm-angles");
    assert_eq!(s.profile, "teensy");
    assert!(s.joint_err_steps.unwrap() <= 1.0, "{:?}", s.joint_err_steps);
    assert!(s.joint_speed_excess_steps.unwrap() <= 1.0);
    // The third move's ±179° were reached (steps / STEPS_PER_RAD), never more than π.
    let top = s.joint_max_abs_rad.unwrap();
    assert!(top <= std::f64::consts::PI, "{top}");
    assert!(top >= 179f64.to_radians() - 1.0 / 254.6, "{top}");
    // No MTRS carries timeout_ms: BRAKE at the profile's 249th tick, strictly within 250 ms.
    assert_eq!(s.brake_after_last_frame_ticks, Some(249));
    let ms = s.brake_after_last_frame_ms.unwrap();
    assert!(ms > 248.0 && ms < 250.0, "{ms}");
    // The steppers stop in the BRAKE tick (they were already braking in STOP).
    assert_eq!(s.steps_after_brake, Some(0));
    // Every frame the board took whole was echoed as expected (the scenario's check), and the
    // corrupted ones were refused.
    let [ok, bad] = s.replies.unwrap();
    assert_eq!(bad, 0);
    assert!(ok > 200);
    assert!(s.corrupted_sent > 0);
    assert_eq!(s.corrupted_applied, 0);
    assert_eq!(s.corrupted_rejected, s.corrupted_sent);
    assert_eq!(s.rearms, 1);
    assert_eq!(s.final_mode, "BRAKE");
}

/// Seed 004: the Pi's buffers drive a 10 m path; the board's odometry, servos, shutdown bits and
/// comm-loss BRAKE are checked against the plant and the rules.
#[test]
fn pi_spi_odometry_servos_shutdown_and_comm_loss() {
    let sc = builtin()
        .unwrap()
        .into_iter()
        .find(|s| s.name == "pi-spi-odometry-servos")
        .unwrap();
    let s = sim::run(&sc, &mut SimHost::new(), sim::RunOptions::default(), None)
        .unwrap()
        .summary;
    // Every expectation but the odometry's first, so that a wrong odometry module shows as that
    // one failure at the end.
    let (odometry, others): (Vec<String>, Vec<String>) = s
        .check(&sc)
        .into_iter()
        .partition(|f| f.starts_with("odometry error"));
    assert!(others.is_empty(), "{others:#?}\n{s:#?}");
    assert_eq!(s.profile, "pi-spi");
    // Config::PI_SPI: BRAKE at the 49th tick after the last valid transfer, which came up to one
    // period (10 ms) before the cut; shorted in that tick, strictly within the 50 ms bound.
    assert_eq!(s.brake_after_last_frame_ticks, Some(49));
    let ms = s.brake_after_last_frame_ms.unwrap();
    assert!(ms > 48.0 && ms <= 49.0 + 1e-9, "{ms}");
    assert_eq!(s.bridge_brake_after_last_frame_ms, Some(ms));
    // The path is at least the 10 m of the issue.
    assert!(
        s.odometry_travel_m.unwrap() >= 10.0,
        "{:?}",
        s.odometry_travel_m
    );
    // Every shutdown transfer shorted every motor in its own step: the session start, the one
    // while driving.
    assert_eq!(s.shutdown_brake_ms, Some(0.0));
    assert_eq!(s.shutdown_transfers, 2);
    // Re-arms: the session start and after the shutdown at 24 s; nothing else left BRAKE.
    assert_eq!(s.rearms, 2);
    assert_eq!(s.rearm_violations, 0);
    // Servo outputs checked after every transfer and tick, all as the rules give.
    assert_eq!(s.servo_violations, Some(0));
    assert!(s.servo_checks as f64 >= 1000.0 * sc.duration_s);
    // Corruption happened, all of it refused.
    assert!(s.corrupted_sent >= 20, "{}", s.corrupted_sent);
    assert_eq!(s.corrupted_applied, 0);
    assert_eq!(s.corrupted_rejected, s.corrupted_sent);
    // Every TxBuffer the host received decoded (version 15).
    let [ok, bad] = s.replies.unwrap();
    assert_eq!(bad, 0);
    assert!(ok as f64 >= 100.0 * 28.9, "{ok}");
    assert_eq!(s.final_mode, "BRAKE");
    // The board's odometry at rest after the path: within 1 % of the distance travelled (the
    // scenario's expectation), and the heading after the 90° arc within a degree.
    assert!(odometry.is_empty(), "{odometry:#?}");
    assert!(s.odometry_heading_err_deg.unwrap() < 1.0, "{s:#?}");
}

/// Seed 004's link has no CRC: only the version byte and the parity of the updates word guard a
/// transfer. Corruption anywhere in the RxBuffer (the default `corrupt_bytes`) therefore gets
/// through: most of it into fields the board ignores, some into the command (a low bit of a MAV
/// target within the ladder's acceleration check, a servo position within 600–2600), which the
/// run counts as applied. (The built-in scenario corrupts only the guarded header.)
#[test]
fn pi_spi_corruption_of_unguarded_fields_is_applied_and_counted() {
    let sc = Scenario::from_toml(
        r#"
name = "pi-spi-whole-buffer-corruption"
duration_s = 5.0
profile = "pi-spi"
[[pi_spi.segments]]
from_s = 0.1
to_s = 5.0
modes = ["mav", "mav", "mav", "mav"]
targets = [2000, 2000, 2000, 2000]
[[pi_spi.servos]]
at_s = 0.1
modes = ["enabled", "enabled", "enabled", "enabled"]
positions = [1500, 1500, 1500, 1500]
[[faults]]
kind = "corruption"
rate = 0.3
from_s = 1.0
to_s = 5.0
"#,
        "test",
    )
    .unwrap();
    let s = sim::run(&sc, &mut SimHost::new(), sim::RunOptions::default(), None)
        .unwrap()
        .summary;
    assert!(s.corrupted_sent > 80, "{}", s.corrupted_sent);
    assert!(s.corrupted_applied > 0, "{s:#?}");
    assert!(s.corrupted_rejected < s.corrupted_sent);
    // The servo rules and the re-arm still hold whatever was taken.
    assert_eq!(s.servo_violations, Some(0));
    assert_eq!(s.rearm_violations, 0);
}
