use super::*;
use protocol::teensy::CmdMsg;
use statemachine::{Config, Mode};
use std::vec::Vec;

type Msg = CmdMsg<JOINTS>;

fn board() -> (TeensyLinkTask, Safety<JOINTS>, Joints) {
    let cfg = Config::TEENSY;
    (
        TeensyLinkTask::new(),
        Safety::new(cfg),
        Joints::new([Position::ZERO; JOINTS], &cfg),
    )
}

fn send(l: &mut TeensyLinkTask, s: &mut Safety<JOINTS>, m: &Msg) -> Option<BoardAction> {
    let mut buf = [0u8; Msg::ROBUST_LEN];
    let n = m.encode_robust(&mut buf).expect("fits");
    let mut act = None;
    for &b in &buf[..n] {
        if let Some((_, a)) = l.on_byte(s, b) {
            act = Some(a);
        }
    }
    act
}

fn echoes(l: &mut TeensyLinkTask) -> Vec<Msg> {
    let mut dec = RobustDecoder::<JOINTS>::new();
    let mut out = Vec::new();
    while let Some(b) = l.tx.pop() {
        if let Some(r) = dec.push(b) {
            out.push(r.expect("the board sends valid frames"));
        }
    }
    out
}

fn mtrs(deg: [i32; JOINTS], speed: i32) -> Msg {
    Msg {
        cmd_type: CmdType::Mtrs,
        mtr_angles: deg,
        mtr_speed_deg_s: speed,
        ..Msg::default()
    }
}

fn cmd(t: CmdType) -> Msg {
    Msg {
        cmd_type: t,
        ..Msg::default()
    }
}

fn deg(p: Position) -> f64 {
    p.to_num::<f64>().to_degrees()
}

#[test]
fn every_command_is_echoed_with_its_success() {
    let (mut l, mut s, _) = board();
    // Not calibrated: the ladder takes the frame (valid) but stays braked.
    send(&mut l, &mut s, &mtrs([10, 20, 30, 40], 90));
    send(&mut l, &mut s, &cmd(CmdType::Cal));
    assert_eq!(
        send(&mut l, &mut s, &cmd(CmdType::EndeffOn)),
        Some(BoardAction::EndEffector(true))
    );
    let rel = Msg {
        is_relative: 1,
        ..mtrs([5; JOINTS], 90)
    };
    send(&mut l, &mut s, &rel);
    let too_fast = Msg {
        mtr_accel_deg_s_s: 1_000_000,
        ..cmd(CmdType::Config)
    };
    send(&mut l, &mut s, &too_fast);
    let e = echoes(&mut l);
    assert_eq!(e.len(), 5);
    assert_eq!(e[0], mtrs([10, 20, 30, 40], 90).reply(true));
    assert_eq!(e[1], cmd(CmdType::Cal).reply(true));
    assert_eq!(e[2], cmd(CmdType::EndeffOn).reply(true));
    assert_eq!(e[3], rel.reply(false), "relative moves are refused");
    assert_eq!(
        e[4],
        too_fast.reply(false),
        "an acceleration above the profile's is refused"
    );
}

#[test]
fn the_arm_moves_to_its_angles_and_brakes_on_comm_loss() {
    let (mut l, mut s, mut j) = board();
    send(&mut l, &mut s, &cmd(CmdType::Cal));
    let target = [45, -90, 10, 0];
    let mut out = s.output();
    let mut last_frame = 0;
    let mut braked_at = None;
    for t in 1..=3000u32 {
        if t % 20 == 0 && t <= 2000 {
            send(&mut l, &mut s, &mtrs(target, 180));
            last_frame = s.ticks();
        }
        out = crate::serial::tick(&mut s, &Default::default());
        j.tick(&out.drive);
        if out.mode == Mode::Brake && braked_at.is_none() && t > 2000 {
            braked_at = Some(s.ticks());
        }
        if t == 1990 {
            assert_eq!(out.mode, Mode::Normal);
            // 90° at 180 °/s takes 0.5 s plus the ramps: long arrived.
            for (p, want) in j.positions().iter().zip(target) {
                assert!(
                    (deg(*p) - f64::from(want)).abs() < 0.01,
                    "{} vs {want}",
                    deg(*p)
                );
            }
        }
    }
    assert_eq!(out.mode, Mode::Brake);
    let c = s.ladder().counters();
    assert!(c.brake_entries >= 1);
    // Seed 003's bound: BRAKE strictly within 250 ms of the last frame (the frame came before
    // tick last_frame + 1; BRAKE at its 249th tick); the joints stopped.
    let after = braked_at.expect("BRAKE after the link stopped") - last_frame;
    assert_eq!(
        after, 249,
        "BRAKE at the profile's threshold, not earlier, not later"
    );
    assert_eq!(j.velocities(), [Speed::ZERO; JOINTS]);
}

#[test]
fn brake_stops_every_joint_where_it_stands() {
    let cfg = Config::TEENSY;
    let mut j = Joints::new([Position::ZERO; JOINTS], &cfg);
    let run = Drive::Run(
        [AxisDrive::Position {
            target: Position::from_num(3),
            cap: Speed::from_num(5),
        }; JOINTS],
    );
    for _ in 0..100 {
        j.tick(&run);
    }
    let moving = j.positions();
    assert!(j.velocities()[0] > Speed::ZERO);
    let braked = j.tick(&Drive::Brake);
    assert_eq!(braked, moving, "no step further");
    assert_eq!(j.velocities(), [Speed::ZERO; JOINTS]);
}

#[test]
fn steps_follow_the_reference_one_per_run() {
    // π/2 rad = 400 steps at 1600 steps per revolution.
    assert_eq!(
        steps_of(Position::from_num(core::f64::consts::FRAC_PI_2)),
        400
    );
    assert_eq!(steps_of(Position::from_num(-core::f64::consts::PI)), -800);
    let mut g = StepGen::new([0, 0, 5, 0]);
    g.set_target([2, -1, 5, 0]);
    let p = g.run();
    assert_eq!(
        p,
        [
            StepPulse::Forward,
            StepPulse::Backward,
            StepPulse::Idle,
            StepPulse::Idle
        ]
    );
    g.run();
    assert_eq!(g.position(), [2, -1, 5, 0]);
    assert_eq!(
        g.run(),
        [StepPulse::Idle; JOINTS],
        "at the target: no pulse"
    );
    g.set_target([100; JOINTS]);
    g.run();
    g.halt();
    assert_eq!(g.run(), [StepPulse::Idle; JOINTS], "halted: no pulse");
    assert_eq!(g.position(), [3, 0, 6, 1]);
}

#[test]
fn config_sets_the_acceleration_within_the_profile() {
    let cfg = Config::TEENSY;
    // 1000 °/s² = 17.45 rad/s² → 0.01745 rad/s per tick.
    let a = accel_step(1000, &cfg).expect("within 50 rad/s²");
    assert!((a.to_num::<f64>() - 0.017_453).abs() < 1e-4);
    assert_eq!(accel_step(0, &cfg), None);
    assert_eq!(accel_step(-10, &cfg), None);
    assert_eq!(
        accel_step(3000, &cfg),
        None,
        "52 rad/s² is above the profile's 50"
    );
    // The joints take a new acceleration; a zero or negative one is ignored.
    let mut j = Joints::new([Position::ZERO; JOINTS], &cfg);
    assert_eq!(j.accel(), cfg.params().max_cmd_step);
    j.set_accel(a);
    assert_eq!(j.accel(), a);
    j.set_accel(Speed::ZERO);
    j.set_accel(-a);
    assert_eq!(j.accel(), a);
}

#[test]
fn a_cal_before_the_first_move_still_rearms_within_the_threshold() {
    let (mut l, mut s, _) = board();
    for _ in 0..300 {
        crate::serial::tick(&mut s, &Default::default());
    }
    send(&mut l, &mut s, &cmd(CmdType::Cal));
    for _ in 0..40 {
        crate::serial::tick(&mut s, &Default::default());
    }
    send(&mut l, &mut s, &mtrs([10; JOINTS], 90));
    let out = crate::serial::tick(&mut s, &Default::default());
    assert_ne!(
        out.mode,
        Mode::Brake,
        "armed by the CAL 40 ms before the first MTRS"
    );
    // Without CAL a comm-loss BRAKE stays.
    for _ in 0..300 {
        crate::serial::tick(&mut s, &Default::default());
    }
    send(&mut l, &mut s, &mtrs([10; JOINTS], 90));
    assert_eq!(
        crate::serial::tick(&mut s, &Default::default()).mode,
        Mode::Brake
    );
}

#[test]
fn brake_halts_the_motors_and_the_profiles_restart_from_them() {
    let cfg = Config::TEENSY;
    let mut j = Joints::new([Position::ZERO; JOINTS], &cfg);
    let mut g = StepGen::new([0; JOINTS]);
    let run = Drive::Run(
        [AxisDrive::Position {
            target: Position::from_num(3),
            cap: Speed::from_num(10),
        }; JOINTS],
    );
    for _ in 0..200 {
        drive_joints(&mut j, &mut g, &run, false);
        // Ten step-generator runs per tick.
        for _ in 0..10 {
            g.run();
        }
    }
    // Moving: the next tick's target is ahead of the motors, and it is the references in steps.
    let t = drive_joints(&mut j, &mut g, &run, false);
    assert_eq!(t, j.positions().map(steps_of));
    assert!(t.iter().all(|&s| s > 0), "moving toward +3 rad: {t:?}");
    let at = g.position();
    let t = drive_joints(&mut j, &mut g, &Drive::Brake, false);
    assert_eq!(t, at, "halted where the motors stand");
    assert_eq!(g.run(), [StepPulse::Idle; JOINTS]);
    assert_eq!(
        j.step_targets(),
        at,
        "the references restart from the motors"
    );
    // An ESTOP press not yet latched halts the same way.
    let mut g2 = StepGen::new([0; JOINTS]);
    let t = drive_joints(&mut j, &mut g2, &run, true);
    assert_eq!(t, [0; JOINTS]);
    // 1 rad = 254.6 steps; back and forth within one step.
    assert_eq!(steps_of(rad_of(255)), 255);
}
