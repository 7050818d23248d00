use super::*;
use crate::estop::EstopInput;
use protocol::pi_spi::{decode_tx, encode_rx, MotorMode, ServoMode};
use statemachine::{Config, FaultFlags, Mode};

/// Full duty on the test board's motor timer (the seed 001/004 boards' TIM8: 8400 + 1).
const FULL: u16 = 8401;

struct Board {
    app: PiSpiApp,
    safety: Safety<MOTORS>,
    estop: EstopInput,
    counts: [i32; MOTORS],
    t_us: u32,
    /// The crude plant's wheel speeds and angles ([`run_plant`]).
    speed: [f64; MOTORS],
    angle: [f64; MOTORS],
}

impl Board {
    fn new() -> Self {
        Self {
            app: PiSpiApp::new(&Config::PI_SPI, &TUNING, 100, FULL),
            safety: Safety::new(Config::PI_SPI),
            estop: EstopInput::new(),
            counts: [0; MOTORS],
            t_us: 0,
            speed: [0.0; MOTORS],
            angle: [0.0; MOTORS],
        }
    }

    fn transfer_bytes(&mut self, rx: &[u8; TRANSFER_LEN]) -> (TransferOutcome, TxBuffer) {
        let mut tx = [0u8; TRANSFER_LEN];
        let o = self
            .app
            .on_transfer(&mut self.safety, rx, self.t_us, 0x0405, &mut tx);
        let fb = decode_tx(tx[..TX_LEN].try_into().unwrap()).expect("the board writes version 15");
        (o, fb)
    }

    fn transfer(&mut self, rx: &RxBuffer) -> TransferOutcome {
        self.transfer_bytes(&bytes(rx)).0
    }

    fn tick(&mut self) -> PiSpiTickOutcome {
        self.t_us = self.t_us.wrapping_add(1000);
        let inputs = PiSpiTickInputs {
            counts: self.counts,
            ..PiSpiTickInputs::default()
        };
        self.app
            .tick(&mut self.safety, self.estop.press_pending(), &inputs)
    }

    /// The session start the module documentation prescribes: a shutdown transfer, then `rx`,
    /// then a tick.
    fn arm(&mut self, rx: &RxBuffer) -> PiSpiTickOutcome {
        let off = RxBuffer {
            system_shutdown: Shutdown {
                servos: false,
                motors: true,
            },
            ..RxBuffer::default()
        };
        assert!(self.transfer(&off).accepted);
        assert!(self.transfer(rx).accepted);
        self.tick()
    }
}

fn bytes(rx: &RxBuffer) -> [u8; TRANSFER_LEN] {
    let mut b = [0u8; TRANSFER_LEN];
    encode_rx(rx, (&mut b[..RX_LEN]).try_into().unwrap());
    b
}

fn modes(m: MotorMode) -> [MotorMode; 4] {
    [m; 4]
}

fn pwm(t: [i32; 4]) -> RxBuffer {
    RxBuffer {
        motor_control_mode: modes(MotorMode::Pwm),
        motor_target: t,
        ..RxBuffer::default()
    }
}

#[test]
fn power_on_is_braked_and_the_shutdown_edge_re_arms() {
    let mut b = Board::new();
    assert_eq!(b.safety.mode(), Mode::Brake);
    // Transfers that merely resume do not leave BRAKE: there was no enable edge.
    assert!(b.transfer(&pwm([100; 4])).accepted);
    assert_eq!(b.tick().out.mode, Mode::Brake);
    let t = b.arm(&pwm([100; 4]));
    assert_ne!(
        t.out.mode,
        Mode::Brake,
        "re-armed by the shutdown bit's 1 → 0 edge"
    );
    // Past the ladder's duty ramp and its clean window after a re-arm (REDUCED for 1 s).
    stream(&mut b, &pwm([100; 4]), 1200);
    let t = b.tick();
    assert_eq!(t.out.mode, Mode::Normal);
    // 100/399 of full scale, forward.
    let ccr = (100.0 / 399.0 * f64::from(FULL)).round() as u16;
    for m in t.motors {
        assert!(m.in1 && !m.in2);
        assert!(m.ccr.abs_diff(ccr) <= 1, "{} vs {ccr}", m.ccr);
    }
}

#[test]
fn pwm_mode_covers_the_seeds_range_and_refuses_beyond_it() {
    let mut b = Board::new();
    b.arm(&pwm([399, -399, 0, -200]));
    stream(&mut b, &pwm([399, -399, 0, -200]), 1200);
    let t = b.tick();
    assert_eq!(t.motors[0].ccr, FULL);
    assert!(t.motors[0].in1 && !t.motors[0].in2);
    assert_eq!(t.motors[1].ccr, FULL);
    assert!(
        !t.motors[1].in1 && t.motors[1].in2,
        "negative duty reverses"
    );
    assert_eq!(t.motors[2], MotorOutput::COAST, "duty 0: outputs open");
    assert!(b.transfer(&pwm([399, 399, 399, 399])).accepted);
    let before = *b.safety.ladder().counters();
    assert!(
        !b.transfer(&pwm([400, 0, 0, 0])).accepted,
        "400 is beyond 0–399"
    );
    let after = b.safety.ladder().counters();
    assert_eq!(after.valid_frames, before.valid_frames);
    assert_eq!(
        after.rejected[RejectReason::OutOfRange.index()],
        before.rejected[RejectReason::OutOfRange.index()] + 1
    );
}

#[test]
fn off_and_passive_brake_map_to_coast_and_short() {
    let mut b = Board::new();
    let rx = RxBuffer {
        motor_control_mode: [
            MotorMode::Off,
            MotorMode::PassiveBrake,
            MotorMode::Off,
            MotorMode::PassiveBrake,
        ],
        ..RxBuffer::default()
    };
    let t = b.arm(&rx);
    assert_eq!(t.motors[0], MotorOutput::COAST);
    assert_eq!(t.motors[1], MotorOutput::short(FULL));
}

#[test]
fn the_motor_shutdown_bit_brakes_in_the_transfer_even_from_a_refused_buffer() {
    let mut b = Board::new();
    b.arm(&pwm([200; 4]));
    assert_ne!(b.safety.mode(), Mode::Brake);
    // Wrong version, wrong parity, undefined modes: the shutdown bit still acts.
    for corrupt in [0usize, 1, 6] {
        let mut b2 = Board::new();
        b2.arm(&pwm([200; 4]));
        let mut raw = bytes(&RxBuffer {
            system_shutdown: Shutdown {
                servos: false,
                motors: true,
            },
            ..pwm([200; 4])
        });
        raw[corrupt] ^= 0xFF;
        let (o, _) = b2.transfer_bytes(&raw);
        assert!(!o.accepted, "byte {corrupt} corrupted");
        assert!(o.motors_off, "motors off in the same transfer");
        assert_eq!(o.out.drive, Drive::Brake);
        assert!(b2.safety.ladder().faults().contains(FaultFlags::SHUTDOWN));
    }
}

#[test]
fn a_wrong_version_or_parity_ignores_the_commands_and_the_updates() {
    for (byte, mask) in [(0usize, 0x01u8), (1, 0x80)] {
        let mut b = Board::new();
        b.arm(&pwm([100; 4]));
        stream(&mut b, &pwm([100; 4]), 1200);
        let rx = RxBuffer {
            updates: UpdateFlags(UpdateFlags::ODOM_RESET | UpdateFlags::MOTOR_PID_SPEED),
            motor_pid_settings: MotorPidSettings {
                kp: [1.0; 4],
                ki: [10.0; 4],
                kd: [0.0; 4],
            },
            servo_mode: [ServoMode::Enabled; 4],
            servo_pos: [1500; 4],
            ..pwm([300; 4])
        };
        let mut raw = bytes(&rx);
        raw[byte] ^= mask;
        let gains = b.app.loops()[0].gains();
        let frames = b.safety.ladder().counters().valid_frames;
        let (o, _) = b.transfer_bytes(&raw);
        assert!(!o.accepted);
        assert_eq!(b.safety.ladder().counters().valid_frames, frames);
        assert_eq!(b.app.loops()[0].gains(), gains, "no gain taken");
        assert_eq!(b.app.updates().odom_resets, 0, "no reset taken");
        assert_eq!(b.app.servo().modes, [ServoMode::FullyDisabled; 4]);
        let reason = if byte == 0 {
            RejectReason::Version
        } else {
            RejectReason::Parity
        };
        assert_eq!(b.safety.ladder().counters().rejected[reason.index()], 1);
        // The last valid duty stays.
        let ccr = (100.0 / 399.0 * f64::from(FULL)).round() as u16;
        assert!(b.tick().motors[0].ccr.abs_diff(ccr) <= 1);
    }
}

#[test]
fn gains_are_converted_per_sample_and_refused_outside_their_bounds() {
    let s = |kp: f32, ki: f32, kd: f32| MotorPidSettings {
        kp: [kp, 0.1, 0.1, 0.1],
        ki: [ki, 1.0, 1.0, 1.0],
        kd: [kd, 0.0, 0.0, 0.0],
    };
    let g = gains_from_wire(&s(0.5, 100.0, 0.01), &SPEED_BOUNDS).unwrap();
    // ki·dt = 100 / 1000, kd/dt = 0.01 · 1000.
    assert_eq!(g[0].kp, Q::from_num(0.5));
    assert!((g[0].ki_dt.to_num::<f64>() - 0.1).abs() < 2e-5);
    assert!((g[0].kd_dt.to_num::<f64>() - 10.0).abs() < 2e-5);
    assert_eq!(g[0].out_limit, DUTY_LIMIT);
    // Each maximum is allowed: the bounds are the largest gains, not the first refused ones.
    let at_max = s(
        SPEED_BOUNDS.kp_max,
        SPEED_BOUNDS.ki_max,
        SPEED_BOUNDS.kd_max,
    );
    let g = gains_from_wire(&at_max, &SPEED_BOUNDS).unwrap();
    assert_eq!(g[0].kp, Q::from_num(SPEED_BOUNDS.kp_max));
    for (set, e) in [
        (s(f32::NAN, 1.0, 0.0), GainError::NonFinite),
        (s(1.0, f32::INFINITY, 0.0), GainError::NonFinite),
        (s(-0.1, 1.0, 0.0), GainError::Negative),
        (s(10.5, 1.0, 0.0), GainError::TooLarge),
        (s(1.0, 1000.5, 0.0), GainError::TooLarge),
        // 0.001 /s · 1 ms = 1e-6 per sample: below Q16.16's 1.5e-5.
        (s(1.0, 0.001, 0.0), GainError::BelowResolution),
    ] {
        assert_eq!(gains_from_wire(&set, &SPEED_BOUNDS), Err(e));
    }
}

#[test]
fn a_gain_update_is_applied_whole_or_refused_and_counted() {
    let mut b = Board::new();
    b.arm(&pwm([0; 4]));
    let mut rx = RxBuffer {
        updates: UpdateFlags(UpdateFlags::MOTOR_PID_SPEED),
        motor_pid_settings: MotorPidSettings {
            kp: [0.2; 4],
            ki: [50.0; 4],
            kd: [0.0; 4],
        },
        ..pwm([0; 4])
    };
    assert!(b.transfer(&rx).accepted);
    assert_eq!(b.app.updates().gains_applied, 1);
    let applied = b.app.loops()[3].gains()[0];
    assert_eq!(applied.kp, Q::from_num(0.2));
    rx.motor_pid_settings.kp[2] = -1.0;
    assert!(b.transfer(&rx).accepted, "the command itself is valid");
    assert_eq!(b.app.updates().gains_refused, 1);
    assert_eq!(b.app.updates().last_gain_error, Some(GainError::Negative));
    for l in b.app.loops() {
        assert_eq!(l.gains()[0], applied, "no motor took part of a refused set");
    }
}

#[test]
fn servos_follow_the_rail_rule_and_stop_on_brake_and_on_their_shutdown_bit() {
    let cmd = |m: [ServoMode; 4]| ServoCommand {
        modes: m,
        pulses_us: [1500, 600, 2600, 1000],
        shutdown: false,
    };
    use ServoMode::{Disabled as D, Enabled as E, FullyDisabled as F};
    assert_eq!(servo_outputs(false, &cmd([F; 4])), ServoOutputs::OFF);
    assert_eq!(
        servo_outputs(false, &cmd([F, D, F, F])),
        ServoOutputs {
            rail_on: true,
            pulses_us: [0; 4]
        }
    );
    assert_eq!(
        servo_outputs(false, &cmd([E, F, E, D])),
        ServoOutputs {
            rail_on: true,
            pulses_us: [1500, 0, 2600, 0]
        }
    );
    assert_eq!(
        servo_outputs(true, &cmd([E; 4])),
        ServoOutputs {
            rail_on: true,
            pulses_us: [0; 4]
        },
        "BRAKE: the disabled state"
    );
    let mut s = cmd([E; 4]);
    s.shutdown = true;
    assert_eq!(servo_outputs(false, &s), ServoOutputs::OFF);
}

#[test]
fn an_enabled_servo_outside_600_to_2600_refuses_the_transfer() {
    let mut b = Board::new();
    b.arm(&pwm([0; 4]));
    let ok = RxBuffer {
        servo_mode: [ServoMode::Enabled; 4],
        servo_pos: [600, 2600, 1500, 1500],
        ..pwm([0; 4])
    };
    assert!(b.transfer(&ok).accepted);
    assert_eq!(b.tick().servos.pulses_us, [600, 2600, 1500, 1500]);
    for bad in [599u16, 2601, 0] {
        let rx = RxBuffer {
            servo_pos: [1500, bad, 1500, 1500],
            ..ok
        };
        assert!(!b.transfer(&rx).accepted, "{bad} µs");
    }
    // A disabled servo's position is not looked at.
    let rx = RxBuffer {
        servo_mode: [
            ServoMode::Enabled,
            ServoMode::Disabled,
            ServoMode::Enabled,
            ServoMode::Enabled,
        ],
        servo_pos: [1500, 0, 1500, 1500],
        ..ok
    };
    assert!(b.transfer(&rx).accepted);
}

#[test]
fn the_servo_shutdown_bit_of_a_corrupted_buffer_stops_but_never_restarts_them() {
    let mut b = Board::new();
    let run = RxBuffer {
        servo_mode: [ServoMode::Enabled; 4],
        servo_pos: [1500; 4],
        ..pwm([0; 4])
    };
    b.arm(&run);
    let mut off = bytes(&RxBuffer {
        system_shutdown: Shutdown {
            servos: true,
            motors: false,
        },
        ..run
    });
    off[0] = 14;
    let (o, _) = b.transfer_bytes(&off);
    assert_eq!(o.servos, ServoOutputs::OFF, "off in the handler");
    let mut on = bytes(&run);
    on[0] = 14;
    assert_eq!(
        b.transfer_bytes(&on).0.servos,
        ServoOutputs::OFF,
        "a refused buffer does not restart them"
    );
    assert_eq!(
        b.transfer(&run).servos.pulses_us,
        [1500; 4],
        "a valid one does"
    );
}

#[test]
fn comm_loss_brakes_at_the_49th_tick_whatever_the_modes() {
    let mut b = Board::new();
    let rx = RxBuffer {
        motor_control_mode: [
            MotorMode::Pwm,
            MotorMode::Mav,
            MotorMode::Mtp,
            MotorMode::Off,
        ],
        motor_target: [200, 720, 720, 0],
        motor_goal_position: [0, 0, 1440, 0],
        servo_mode: [ServoMode::Enabled; 4],
        servo_pos: [1500; 4],
        ..RxBuffer::default()
    };
    b.arm(&rx);
    for k in 2..=60u32 {
        let t = b.tick();
        if k < 49 {
            assert_ne!(t.out.mode, Mode::Brake, "tick {k}");
            if k < 21 {
                assert_eq!(
                    t.servos.pulses_us, [1500; 4],
                    "servos hold through HOLD and STOP"
                );
            }
        } else {
            assert_eq!(t.out.mode, Mode::Brake, "tick {k}");
            assert!(t.motors.iter().all(|m| *m == MotorOutput::short(FULL)));
            assert_eq!(t.servos.pulses_us, [0; 4], "servos disabled at BRAKE");
        }
    }
}

/// A crude motor for the loops: speed follows 30 rad/s × duty with a 20 ms time constant.
fn run_plant(b: &mut Board, ticks: u32) -> [f64; MOTORS] {
    for _ in 0..ticks {
        let t = b.tick();
        for n in 0..MOTORS {
            let m = t.motors[n];
            let duty = match (m.in1, m.in2) {
                (true, false) => f64::from(m.ccr) / f64::from(FULL),
                (false, true) => -f64::from(m.ccr) / f64::from(FULL),
                _ => 0.0,
            };
            b.speed[n] += (30.0 * duty - b.speed[n]) * (0.001 / 0.02);
            b.angle[n] += b.speed[n] * 0.001;
            b.counts[n] = (b.angle[n] / f64::from(RAD_PER_COUNT)).floor() as i32;
        }
    }
    b.speed
}

/// Transfers of `rx` every 10 ticks (the seed's 100 Hz) for `ms`, the plant running.
fn stream(b: &mut Board, rx: &RxBuffer, ms: u32) -> [f64; MOTORS] {
    let mut s = b.speed;
    for _ in 0..ms / 10 {
        b.transfer(rx);
        s = run_plant(b, 10);
    }
    s
}

#[test]
fn mav_holds_the_commanded_speed() {
    let mut b = Board::new();
    // 1440 counts/s = 2π rad/s forward; −720 = −π.
    let rx = RxBuffer {
        motor_control_mode: modes(MotorMode::Mav),
        motor_target: [1440, -720, 0, 300],
        ..RxBuffer::default()
    };
    b.arm(&rx);
    let s = stream(&mut b, &rx, 3000);
    let want = [
        std::f64::consts::TAU,
        -std::f64::consts::PI,
        0.0,
        300.0 * f64::from(RAD_PER_COUNT),
    ];
    for n in 0..MOTORS {
        assert!(
            (s[n] - want[n]).abs() < 0.3,
            "motor {n}: {} vs {}",
            s[n],
            want[n]
        );
    }
    let fb = b.transfer_bytes(&bytes(&rx)).1;
    assert!(
        (fb.motor.bemf[0] - 1440).abs() <= 100,
        "bemf {}",
        fb.motor.bemf[0]
    );
    // 3000 closed-loop ticks later every controller still satisfies its invariant.
    assert!(b.app.loops().iter().all(MotorLoop::is_valid));
}

#[test]
fn mtp_reaches_its_goal_under_the_cap_and_reports_done() {
    let mut b = Board::new();
    // Goal 2880 counts (two revolutions) at 720 counts/s (π rad/s): 4 s.
    let rx = RxBuffer {
        motor_control_mode: modes(MotorMode::Mtp),
        motor_target: [720; 4],
        motor_goal_position: [2880, -1440, 0, 100],
        ..RxBuffer::default()
    };
    b.arm(&rx);
    let mut fastest = 0.0f64;
    for k in 0..600 {
        let s = stream(&mut b, &rx, 10);
        fastest = fastest.max(s[0].abs());
        if k == 100 {
            // 1 s into the 4 s move of motors 0 and 1: not done yet.
            let fb = b.transfer_bytes(&bytes(&rx)).1;
            assert_eq!(
                fb.motor.done & 0b0011,
                0,
                "done early: {:#06b}",
                fb.motor.done
            );
        }
    }
    assert!(
        fastest <= std::f64::consts::PI * 1.1,
        "cap respected: {fastest}"
    );
    let fb = b.transfer_bytes(&bytes(&rx)).1;
    for (n, goal) in [2880, -1440, 0, 100].into_iter().enumerate() {
        assert!(
            (b.counts[n] - goal).abs() <= DONE_TOLERANCE_COUNTS,
            "motor {n}: {}",
            b.counts[n]
        );
    }
    assert_eq!(fb.motor.done, 0b1111);
    assert_eq!(fb.motor.position, b.counts);
}

#[test]
fn feedback_carries_time_inputs_and_counts() {
    let mut b = Board::new();
    b.counts = [10, -20, 30, -40];
    b.arm(&pwm([0; 4]));
    b.t_us = 123_456;
    let (_, fb) = b.transfer_bytes(&bytes(&pwm([0; 4])));
    assert_eq!(fb.update_time, 123_456);
    assert_eq!(fb.digital_sensors, 0x0405);
    assert_eq!(fb.motor.position, [10, -20, 30, -40]);
}

#[test]
fn odometry_is_zero_until_configured_then_follows_the_wheels_and_resets() {
    use protocol::pi_spi::assumed::KinematicsConfig;
    let mut b = Board::new();
    let mav = RxBuffer {
        motor_control_mode: modes(MotorMode::Mav),
        motor_target: [720; 4],
        ..RxBuffer::default()
    };
    b.arm(&mav);
    stream(&mut b, &mav, 500);
    let fb = b.transfer_bytes(&bytes(&mav)).1;
    assert_eq!(
        fb.odometry,
        protocol::pi_spi::OdometryData::default(),
        "zero until configured"
    );
    // Four wheels of radius 0.05 m all forward: vx = r/4 · Σω; no lateral motion or turn.
    let k = KinematicsConfig {
        inverse: [[0.0125; 4], [0.0; 4], [0.0; 4]],
        ticks_to_rad: [RAD_PER_COUNT; 4],
    };
    let cfg = RxBuffer {
        updates: UpdateFlags(UpdateFlags::KINEMATICS),
        kinematics: k,
        ..mav
    };
    assert!(b.transfer(&cfg).accepted);
    let start = b.counts[0];
    stream(&mut b, &mav, 2000);
    let fb = b.transfer_bytes(&bytes(&mav)).1;
    // Odometry runs at 100 Hz: up to 10 ticks of travel may not be integrated yet.
    let wheel_m = f64::from(b.counts[0] - start) * f64::from(RAD_PER_COUNT) * 0.05;
    assert!(wheel_m > 0.2, "the wheels turned: {wheel_m} m");
    assert!(
        (f64::from(fb.odometry.pos_x) - wheel_m).abs() < 0.01,
        "{} vs {wheel_m}",
        fb.odometry.pos_x
    );
    assert!(fb.odometry.pos_y.abs() < 1e-6 && fb.odometry.heading.abs() < 1e-6);
    // 720 counts/s is π rad/s per wheel: vx = 0.0125 m · 4π rad/s = 0.157 m/s, over the
    // odometry's own 10 ms period.
    assert!(
        (f64::from(fb.odometry.vx) - 0.05 * std::f64::consts::PI).abs() < 0.02,
        "vx {}",
        fb.odometry.vx
    );
    let reset = RxBuffer {
        updates: UpdateFlags(UpdateFlags::ODOM_RESET),
        ..mav
    };
    assert!(b.transfer(&reset).accepted);
    run_plant(&mut b, 10);
    let fb = b.transfer_bytes(&bytes(&mav)).1;
    assert!(
        fb.odometry.pos_x.abs() < 0.01,
        "reset: {}",
        fb.odometry.pos_x
    );
    // A refused kinematics block is counted and changes nothing.
    let bad = RxBuffer {
        updates: UpdateFlags(UpdateFlags::KINEMATICS),
        kinematics: KinematicsConfig {
            ticks_to_rad: [f32::NAN; 4],
            ..k
        },
        ..mav
    };
    assert!(b.transfer(&bad).accepted);
    assert_eq!(b.app.updates().kinematics_refused, 1);
}

#[test]
fn counts_become_radians_and_saturate_at_the_format_range() {
    // One revolution is 2π rad, to within a Q16.16 step.
    let rev = rad_of_counts(COUNTS_PER_REV as i32).to_num::<f64>();
    assert!(
        (rev - core::f64::consts::TAU).abs() < 2.0 / 65536.0,
        "{rev}"
    );
    assert_eq!(rad_of_counts(0), Position::ZERO);
    // 2³¹ counts are about 1.5 million revolutions, far beyond Q16.16's ±32 768 rad.
    assert_eq!(rad_of_counts(i32::MAX), Position::MAX);
    assert_eq!(rad_of_counts(i32::MIN), Position::MIN);
}

/// An MTP axis far behind its profile: the position controller's correction (here its full
/// 5 rad/s) is added to the profile's speed, and the sum is held to the ladder's cap before the
/// speed controller sees it, in either direction.
#[test]
fn the_position_correction_never_lifts_the_speed_setpoint_above_the_cap() {
    let travel = Travel {
        lo: Position::from_num(-10),
        hi: Position::from_num(10),
    };
    let lim = ProfileLimits {
        travel,
        accel_step: Speed::from_num(0.01),
    };
    let cap = Speed::from_num(1);
    for sign in [1, -1] {
        let goal = Position::from_num(sign);
        let mut l = MotorLoop::new(&TUNING, &travel);
        // Already closed, the profile resting on the goal, the motor 1 rad short of it.
        l.closed = true;
        l.profile = Trapezoid::new(goal, &travel);
        let duty = l.run(
            &AxisDrive::Position { target: goal, cap },
            Speed::ZERO,
            Position::ZERO,
            &lim,
        );
        let mut speed_pid = Pid::new(TUNING.speed);
        let want = speed_pid.step(cap * sign, Speed::ZERO);
        assert_eq!(duty, Some(want), "goal {goal}");
    }
}

#[test]
fn done_needs_the_loop_closed_the_profile_on_the_goal_and_the_motor_within_tolerance() {
    let travel = Travel {
        lo: Position::from_num(-10),
        hi: Position::from_num(10),
    };
    let lim = ProfileLimits {
        travel,
        accel_step: Speed::from_num(0.01),
    };
    let goal = Position::from_num(1);
    let tol = rad_of_counts(DONE_TOLERANCE_COUNTS);
    let mut l = MotorLoop::new(&TUNING, &travel);
    l.profile = Trapezoid::new(goal, &travel);
    assert!(!l.done(goal, goal, &lim), "open loop");
    l.closed = true;
    assert!(l.done(goal, goal, &lim));
    assert!(l.done(goal, goal + tol, &lim));
    assert!(
        !l.done(goal, goal + tol + tol, &lim),
        "motor short of the goal"
    );
    l.profile = Trapezoid::new(Position::ZERO, &travel);
    assert!(!l.done(goal, goal, &lim), "profile not on the goal");
}

#[test]
fn a_pending_estop_press_shorts_the_motors_in_the_tick_before_the_ladder_knows() {
    let mut b = Board::new();
    b.arm(&pwm([200; 4]));
    let o = b.tick();
    assert_ne!(o.motors, [MotorOutput::short(FULL); MOTORS], "driving");
    // The edge handler ran; the tick has not polled the input, so the ladder still runs.
    b.estop.edge_then(true, || {});
    let o = b.tick();
    assert_ne!(o.out.drive, Drive::Brake);
    assert_eq!(o.motors, [MotorOutput::short(FULL); MOTORS]);
}

#[test]
fn shutdown_of_reads_the_motor_and_servo_bits_of_any_buffer() {
    for (servos, motors) in [(false, true), (true, false), (true, true), (false, false)] {
        let sd = Shutdown { servos, motors };
        let raw = bytes(&RxBuffer {
            system_shutdown: sd,
            ..pwm([200; 4])
        });
        assert_eq!(shutdown_of(&raw), sd);
    }
}

#[test]
fn an_imu_reading_reaches_the_next_feedback() {
    let mut b = Board::new();
    // Level and still, raw temperature 0: 36.53 °C by the MPU6050 register map's raw / 340 + 36.53.
    b.app.imu_sample(Some(([0, 0, 16_384], [0; 3], 0)));
    let fb = b.transfer_bytes(&bytes(&RxBuffer::default())).1;
    assert!(
        (fb.imu.temperature - 36.53).abs() < 1e-4,
        "{}",
        fb.imu.temperature
    );
}

#[test]
fn orientation_and_imu_calibration_updates_count_only_under_their_flags() {
    let mut b = Board::new();
    // The default buffer's orientation matrices are all zeros: not rotations.
    assert!(b.transfer(&RxBuffer::default()).accepted);
    assert_eq!(b.app.updates().orientation_refused, 0, "no flag, no update");
    assert_eq!(b.app.updates().save_imu_cal, 0);
    let bad = RxBuffer {
        updates: UpdateFlags(UpdateFlags::IMU_ORIENTATION),
        ..RxBuffer::default()
    };
    assert!(b.transfer(&bad).accepted);
    assert_eq!(b.app.updates().orientation_refused, 1);
    let identity = [1, 0, 0, 0, 1, 0, 0, 0, 1];
    let good = RxBuffer {
        imu_gyro_orientation: identity,
        imu_compass_orientation: identity,
        ..bad
    };
    assert!(b.transfer(&good).accepted);
    assert_eq!(
        b.app.updates().orientation_refused,
        1,
        "a rotation is taken"
    );
    let save = RxBuffer {
        updates: UpdateFlags(UpdateFlags::SAVE_IMU_CAL),
        ..RxBuffer::default()
    };
    assert!(b.transfer(&save).accepted);
    assert!(b.transfer(&RxBuffer::default()).accepted);
    assert_eq!(b.app.updates().save_imu_cal, 1);
}
