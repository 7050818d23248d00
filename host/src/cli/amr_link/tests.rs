//! The AMR-link verbs against a fake port: the statemachine's ladder answering each frame, one
//! tick per exchange, with the applied setpoints as the wheel speeds (no motors, no plant).

#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation
)]

use super::*;
use statemachine::{Config, Estop, Event, Ladder, Source};

/// The ladder behind a port, on a lockstep clock (1 ms per exchange or per gap millisecond).
struct LadderPort {
    ladder: Ladder<2>,
    now: u64,
    fb_seq: u32,
    /// The feedback prepared at the previous exchange (what the next exchange returns).
    next: [u8; FRAME_LEN],
    /// Every command received.
    sent: Vec<amr::MotorCommand>,
}

impl LadderPort {
    fn new() -> Self {
        let mut p = Self {
            ladder: Ladder::new(Config::DEFAULT),
            now: 0,
            fb_seq: 0,
            next: [0; FRAME_LEN],
            sent: Vec::new(),
        };
        p.prepare(0, Event::Tick);
        p
    }

    fn prepare(&mut self, cmd_seq: u32, ev: Event<2>) {
        let out = self.ladder.step(ev);
        let speeds = out
            .drive
            .speeds()
            .map_or([0.0; 2], |s| s.map(|x| x.to_num::<f32>()));
        self.fb_seq += 1;
        let fb = MotorFeedback {
            timestamp_us: self.now as u32,
            left_speed: speeds[0],
            right_speed: speeds[1],
            seq: self.fb_seq,
            cmd_seq,
            ..MotorFeedback::default()
        }
        .with_output(&out);
        amr::encode_feedback(&fb, &mut self.next);
    }

    fn estop_input(&mut self, action: Estop) {
        self.ladder.step(Event::Estop {
            source: Source::Local,
            action,
        });
    }
}

impl Port for LadderPort {
    fn begin_cycle(&mut self) -> u64 {
        self.now
    }

    fn exchange(
        &mut self,
        t_send: u64,
        tx: &[u8; FRAME_LEN],
        rx: &mut [u8; FRAME_LEN],
    ) -> Result<u64, LinkError> {
        *rx = self.next;
        let cmd = amr::decode_command(tx);
        let seq = cmd.as_ref().map_or(0, |c| c.seq);
        if let Ok(c) = cmd {
            self.sent.push(c);
        }
        self.ladder
            .step(protocol::event_from(cmd.and_then(|c| c.to_command())));
        self.now += 1000;
        self.prepare(seq, Event::Tick);
        Ok(t_send + 300)
    }

    fn gap(&mut self, ms: u64) {
        for _ in 0..ms {
            self.now += 1000;
            let seq = self.sent.last().map_or(0, |c| c.seq);
            self.prepare(seq, Event::Tick);
        }
    }

    fn name(&self) -> &str {
        "ladder"
    }
}

fn never() -> impl FnMut() -> bool {
    || false
}

#[test]
fn arm_from_power_on_leaves_brake_and_ends_in_stop() {
    let mut s = Session::new(LadderPort::new());
    let r = arm(&mut s, "arm", &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
    assert_eq!(r.before.as_ref().unwrap().mode, "BRAKE");
    assert!(r.before.unwrap().faults.contains(&"POWER_ON".to_string()));
    // Left BRAKE (to REDUCED: a latch is a strike against the link, so the ladder starts limited
    // until a clean window has passed), then enable 0: STOP.
    assert_eq!(r.modes_seen, ["BRAKE", "REDUCED", "STOP"]);
    assert_eq!(r.after.unwrap().mode, "STOP");
    // The re-arm edge: some enable 0 command directly followed by an enable 1 one.
    let sent = &s.port.sent;
    assert!(sent.windows(2).any(|w| !w[0].enable && w[1].enable));
    assert!(!sent.last().unwrap().enable);
}

#[test]
fn rearm_is_refused_while_the_board_estop_holds_and_clears_after_release() {
    let mut port = LadderPort::new();
    port.estop_input(Estop::Engage);
    let mut s = Session::new(port);
    let r = arm(&mut s, "rearm", &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Refused, "{}", r.message);
    assert!(
        r.message.contains("ESTOP input is engaged"),
        "{}",
        r.message
    );
    assert_eq!(s.modes_seen, ["BRAKE"]);
    // Released at the board: the same verb now clears the latch.
    s.port.estop_input(Estop::Release);
    let r = arm(&mut s, "rearm", &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
}

#[test]
fn rearm_with_nothing_latched_changes_nothing() {
    let mut s = Session::new(LadderPort::new());
    arm(&mut s, "arm", &mut never()).unwrap();
    // The ladder is in STOP now (enable 0), not BRAKE.
    let r = arm(&mut s, "rearm", &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done);
    assert!(r.message.contains("no latch to clear"), "{}", r.message);
}

#[test]
fn estop_brakes_by_a_frame_gap_and_release_reports_the_board_input() {
    let mut s = Session::new(LadderPort::new());
    arm(&mut s, "arm", &mut never()).unwrap();
    let r = estop(&mut s, &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
    let after = r.after.unwrap();
    assert_eq!(after.mode, "BRAKE");
    assert!(after.faults.contains(&"COMM_LOST".to_string()), "{after:?}");
    assert_eq!(s.counters.gaps, 1);
    // Nothing holds an ESTOP: release says so, rearm clears the latch.
    let r = estop_release(&mut s, &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
    assert!(r.message.contains("rearm"));
    s.port.estop_input(Estop::Engage);
    let r = estop_release(&mut s, &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Refused, "{}", r.message);
}

#[test]
fn drive_commands_the_twist_then_stops_and_disarms() {
    let mut s = Session::new(LadderPort::new());
    let r = drive(&mut s, 0.4, 0.0, 1.0, &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
    let d = r.drive.unwrap();
    // The ladder's setpoints are the wheel speeds here: 0.4 m/s on 0.08 m wheels is 5 rad/s, so
    // the second half's mean forward speed is 0.4 m/s (the acceleration limit reaches 5 rad/s in
    // well under half a second) and the distance is below 0.4 m (the ramp) and above 0.3.
    assert!((d.mean_v_mps - 0.4).abs() < 0.01, "{d:?}");
    assert!(d.distance_m > 0.3 && d.distance_m < 0.45, "{d:?}");
    assert!(d.mean_w_radps.abs() < 0.01);
    let after = r.after.unwrap();
    assert_eq!(after.mode, "STOP");
    assert_eq!(after.wheel_radps, [0.0, 0.0]);
    assert!(!s.port.sent.last().unwrap().enable);
}

#[test]
fn drive_stops_early_on_the_stop_flag_and_still_disarms() {
    let mut s = Session::new(LadderPort::new());
    let mut n = 0u32;
    let mut stop = || {
        n += 1;
        n > 700
    };
    let r = drive(&mut s, 0.4, 0.0, 10.0, &mut stop).unwrap();
    assert!(r.interrupted);
    assert!(r.drive.unwrap().seconds < 1.0);
    assert_eq!(r.after.unwrap().mode, "STOP");
    assert!(!s.port.sent.last().unwrap().enable);
}

#[test]
fn disarm_takes_a_driving_mcu_to_stop() {
    let mut s = Session::new(LadderPort::new());
    s.arm_and_wait(500, &mut never()).unwrap();
    let mut stop = never();
    for _ in 0..300 {
        s.bridge.cmd_vel(s.now_us, 0.3, 0.0);
        s.run(1, &mut stop).unwrap();
    }
    let driving = s.feedback().unwrap();
    assert_eq!(driving.mode, Mode::Reduced as u32);
    assert!(driving.left_speed > 1.0);
    let r = disarm(&mut s, 2.0, &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
    assert_eq!(r.before.unwrap().mode, "REDUCED");
    assert_eq!(r.after.unwrap().mode, "STOP");
}

#[test]
fn a_silent_device_is_no_reply() {
    struct Silent;
    impl Port for Silent {
        fn begin_cycle(&mut self) -> u64 {
            0
        }
        fn exchange(
            &mut self,
            _: u64,
            _: &[u8; FRAME_LEN],
            rx: &mut [u8; FRAME_LEN],
        ) -> Result<u64, LinkError> {
            *rx = [0; FRAME_LEN];
            Ok(1)
        }
        fn gap(&mut self, _: u64) {}
        fn name(&self) -> &str {
            "silent"
        }
    }
    for verb in ["arm", "rearm"] {
        let mut s = Session::new(Silent);
        let r = arm(&mut s, verb, &mut never()).unwrap();
        assert_eq!(r.verdict, Outcome::NoReply);
        assert!(r.message.contains("no valid feedback"));
    }
    let mut s = Session::new(Silent);
    assert_eq!(
        drive(&mut s, 0.1, 0.0, 0.1, &mut never()).unwrap().verdict,
        Outcome::NoReply
    );
}

#[test]
fn twist_limits_come_from_the_geometry() {
    // 18 rad/s on 0.08 m wheels: 1.44 m/s; spinning, 1.44 / 0.2 = 7.2 rad/s.
    assert!(check_twist(1.44, 0.0).is_ok());
    assert!(check_twist(1.45, 0.0).is_err());
    assert!(check_twist(0.0, 7.2).is_ok());
    assert!(check_twist(0.0, -7.3).is_err());
    assert!(check_twist(f64::NAN, 0.0).is_err());
}

#[test]
fn fault_names_follow_the_bits() {
    // BRAKE_LATCHED is bit 9, ESTOP bit 5, POWER_ON bit 10.
    assert_eq!(
        fault_names((1 << 5) | (1 << 9) | (1 << 10) | (1 << 15)),
        ["ESTOP", "BRAKE_LATCHED", "POWER_ON", "BIT15"]
    );
    assert!(fault_names(0).is_empty());
    assert_eq!(mode_name(4), "BRAKE");
    assert_eq!(mode_name(9), "UNKNOWN");
}

#[test]
fn a_late_host_is_counted_and_named_in_the_hint() {
    let mut s = Session::new(LadderPort::new());
    let mut stop = never();
    s.run(10, &mut stop).unwrap();
    assert_eq!(late_hint(&s), "");
    // The host's clock jumps 5 ms between two cycles (the board, here, does not notice).
    s.port.now += 5000;
    s.run(2, &mut stop).unwrap();
    assert_eq!(s.counters.diagnostics.get("host_late"), Some(&1));
    // 1 ms of the usual period plus the 5 ms jump.
    assert_eq!(s.counters.host_late_max_us, 6000);
    let hint = late_hint(&s);
    assert!(hint.contains("late 1 time(s)"), "{hint}");
    assert!(hint.contains("6.0 ms"), "{hint}");
    assert!(
        !hint.contains("--sim-clock"),
        "not a simulated port: {hint}"
    );
}

#[test]
fn arm_from_stop_says_armed_not_left_brake() {
    let mut s = Session::new(LadderPort::new());
    arm(&mut s, "arm", &mut never()).unwrap();
    let r = arm(&mut s, "arm", &mut never()).unwrap();
    assert_eq!(r.verdict, Outcome::Done, "{}", r.message);
    assert!(
        r.message.starts_with("the MCU armed (STOP -> "),
        "{}",
        r.message
    );
}
