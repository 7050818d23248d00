//! Harnesses for the task bodies, each written once: the same body is a `cargo test` (the twin
//! driver, biased pseudo-random inputs) and, under `cfg(kani)`, a Kani proof.
//!
//! Properties: the current loop never writes compares beyond the timer's auto-reload, never
//! drives both high sides of a bridge, brakes the bridge in the same run on a trip, and never
//! writes compares to a braked bridge; the speed loop asks for no current in BRAKE and never more
//! than the speed controller's limit; an ESTOP press brakes the bridge in its handler; the µs
//! clock never panics and stays within one tick of the tick count; on the serial boards, a seed 001
//! `ESTOP 1` frame latches BRAKE at its last byte, from any ladder state and after any bytes; the
//! seed 004 odometry accepts only configurations within its bounds (a refused one changes nothing
//! but its counter), and its update never panics and never reports a non-finite value.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use crate::current::CurrentLoop;
use crate::estop::EstopInput;
use crate::hw::{Bridge, RecordingBridge};
use crate::speed::SpeedLoop;
use crate::timing::micros;
use crate::tuning::AMR;
use control::{BridgeState, Q};
use statemachine::harness::Source;
use statemachine::{assume, check, cover};

fn amps(src: &mut impl Source) -> Q {
    Q::from_bits(src.i32())
}

/// P-13: Current loop: one run from rest with any readings, references, bridge state and break flag.
pub fn current_loop_safe(src: &mut impl Source) {
    let mut c = CurrentLoop::new(&AMR, [src.u16(), src.u16()]);
    let arr = AMR.pwm_arr().unwrap_or(1);
    let mut b = RecordingBridge::new(arr);
    let running = src.bool();
    if running {
        b.apply(BridgeState::Run);
    }
    b.tripped = src.bool();
    let raw = [src.u16(), src.u16()];
    let s = c.run(&mut b, raw, [amps(src), amps(src)]);
    for k in b.compares {
        check!(
            k.a <= arr && k.b <= arr,
            "P-13: compares stay within the auto-reload"
        );
        check!(
            k.a == 0 || k.b == 0,
            "P-13: never both high sides of one bridge"
        );
    }
    if s.tripped {
        check!(
            b.state == BridgeState::Brake,
            "P-13: a trip brakes the bridge in the same run"
        );
    }
    if b.state == BridgeState::Brake {
        check!(
            b.compares.iter().all(|k| k.a == 0 && k.b == 0),
            "P-13: a braked bridge gets no compares"
        );
    }
    cover!(src, running && s.tripped, "trip while running");
    cover!(
        src,
        b.compares.iter().any(|k| k.a > 0),
        "forward duty written"
    );
    cover!(
        src,
        b.compares.iter().any(|k| k.b > 0),
        "reverse duty written"
    );
}

/// P-14: Speed loop: one run from rest with any counters and any setpoint.
pub fn speed_loop_bounded(src: &mut impl Source) {
    let mut l = SpeedLoop::new(&AMR, [src.u16(), src.u16()]);
    let setpoint = if src.bool() {
        Some([src.speed(), src.speed()])
    } else {
        None
    };
    let s = l.run([src.u16(), src.u16()], setpoint);
    let limit = AMR.speed.out_limit;
    for i in s.refs {
        check!(
            control::within(i, limit),
            "P-14: current reference within the speed loop's limit"
        );
    }
    if setpoint.is_none() {
        check!(
            s.refs == [Q::ZERO; 2],
            "P-14: no current asked for in BRAKE"
        );
    }
    cover!(src, s.refs.contains(&limit), "reference saturated");
}

/// P-15: ESTOP: a press brakes the bridge in the handler, whatever its state, and is reported by the
/// next poll even if released again before it.
pub fn estop_press_brakes_at_once(src: &mut impl Source) {
    let mut b = RecordingBridge::new(src.u16());
    let was_running = src.bool();
    if was_running {
        b.apply(BridgeState::Run);
    }
    let mut e = EstopInput::new();
    let pressed = src.bool();
    e.edge(&mut b, pressed);
    if pressed {
        check!(
            b.state == BridgeState::Brake,
            "P-15: a press brakes the bridge in its handler"
        );
        check!(
            e.poll(src.bool()) == Some(statemachine::Estop::Engage),
            "P-15: a press is reported even if released before the tick"
        );
    }
    cover!(src, pressed && was_running, "press while running");
}

/// P-16: µs clock: never panics; within one tick of the tick count (modulo the u32 wrap).
pub fn micros_bounded(src: &mut impl Source) {
    let ticks = src.u32();
    let period = src.u32();
    assume!(src, period > 0);
    let t = micros(ticks, src.u32(), src.bool(), period, 1000);
    let base = ticks.wrapping_mul(1000);
    let off = t.wrapping_sub(base);
    check!(
        off < 2000,
        "P-16: time stamp within one tick after the counted ticks"
    );
    cover!(src, off >= 1000, "update pending counted");
}

/// P-17's three properties after the ESTOP frame: the ladder latched in BRAKE, the link holding
/// the ESTOP it engaged, and one more reply queued than `queued` (the ACK).
fn estop_latched_and_acknowledged(
    safety: &crate::Safety<{ crate::cdc::MOTORS }>,
    link: &crate::cdc::CdcLinkTask,
    queued: usize,
) {
    use statemachine::{check, Mode, Source as Origin};
    check!(
        safety.mode() == Mode::Brake,
        "P-17: the ladder is latched in BRAKE after the ESTOP frame"
    );
    check!(
        safety.ladder().estop_owners() & Origin::Primary.bit() != 0,
        "P-17: the link holds the ESTOP it engaged"
    );
    check!(link.tx.len() > queued, "P-17: the ESTOP is acknowledged");
}

/// P-17: Seed 001 board, the link body's half: from any ladder state, the decoded `ESTOP 1` that
/// the stream decoder delivers at the frame's last byte latches BRAKE (mode and drive) in that
/// same call, leaves the link holding the ESTOP, and queues its ACK. That the decoder delivers the
/// frame at its last byte whatever came before it is the protocol crate's half (P-5);
/// [`serial_estop_brakes_at_its_last_byte`] tests the two together, byte by byte.
pub fn serial_estop_message_brakes(src: &mut impl Source) {
    use crate::cdc::{BoardStatus, CdcLinkTask, MOTORS};
    use protocol::cdc::Message;
    use statemachine::{check, Config, Drive, Estop, Mode};
    let ladder = statemachine::harness::arbitrary::ladder::<MOTORS>(src, Config::CDC);
    let mut safety = crate::Safety::from_ladder(ladder);
    let mut link = CdcLinkTask::new();
    let st = BoardStatus::default();
    let was_running = safety.mode() != Mode::Brake;
    let queued = link.tx.len();
    let out = link.on_decoded(&mut safety, Ok(Message::Estop(Estop::Engage)), &st);
    check!(
        matches!(out, Some(o) if o.mode == Mode::Brake && o.drive == Drive::Brake),
        "P-17: a decoded ESTOP frame brakes in the call that applies it"
    );
    estop_latched_and_acknowledged(&safety, &link, queued);
    cover!(src, was_running, "ESTOP while running");
    cover!(src, !was_running, "ESTOP while already braked");
}

/// P-17: Seed 001 board, bytes to BRAKE (a test: the two halves are proven separately, see
/// [`serial_estop_message_brakes`]): whatever the ladder's state and whatever bytes came before it
/// (a false start-of-frame, a truncated frame), an `ESTOP 1` frame latches BRAKE in the link task's
/// step for its last byte, and is acknowledged.
pub fn serial_estop_brakes_at_its_last_byte(src: &mut impl Source) {
    use crate::cdc::{BoardStatus, CdcLinkTask, MOTORS};
    use protocol::cdc::{Message, MAX_FRAME_LEN};
    use statemachine::{Config, Estop, Mode};
    let ladder = statemachine::harness::arbitrary::ladder::<MOTORS>(src, Config::CDC);
    let mut safety = crate::Safety::from_ladder(ladder);
    let mut link = CdcLinkTask::new();
    let st = BoardStatus::default();
    // Any bytes, drawn often from the dangerous ones: start-of-frame bytes and a long LEN.
    let mut garbage = [0u8; 2];
    for g in &mut garbage {
        *g = if src.bool() {
            src.u8()
        } else {
            match src.below(4) {
                0 => 0xAA,
                1 => 0x55,
                2 => 0xFF,
                _ => 0x03,
            }
        };
    }
    let used = usize::from(src.below(3));
    for &b in garbage.iter().take(used) {
        link.on_byte(&mut safety, b, &st);
    }
    let mut frame = [0u8; MAX_FRAME_LEN];
    let n = Message::Estop(Estop::Engage).encode(&mut frame);
    let was_running = safety.mode() != Mode::Brake;
    let queued = link.tx.len();
    for (i, &b) in frame.iter().take(n).enumerate() {
        link.on_byte(&mut safety, b, &st);
        if i.saturating_add(1) < n {
            continue;
        }
        estop_latched_and_acknowledged(&safety, &link, queued);
    }
    cover!(src, was_running, "ESTOP while running");
    cover!(
        src,
        used == 2 && garbage == [0xAA, 0x55],
        "after a false start of frame"
    );
}

/// Any `RxBuffer` the decoder can return. Under Kani every field is symbolic; the twin keeps
/// targets small so that the ladder accepts some (random bit patterns it almost never does).
fn any_pi_rx(src: &mut impl Source) -> protocol::pi_spi::RxBuffer {
    use protocol::pi_spi::assumed::{KinematicsConfig, MotorPidSettings};
    use protocol::pi_spi::{MotorMode, RxBuffer, ServoMode, Shutdown, UpdateFlags};
    fn target(src: &mut impl Source) -> i32 {
        let x = src.i32();
        if cfg!(kani) {
            x
        } else {
            x % 400
        }
    }
    fn motor(src: &mut impl Source) -> MotorMode {
        MotorMode::from_raw(src.below(5)).unwrap_or_default()
    }
    fn servo(src: &mut impl Source) -> ServoMode {
        ServoMode::from_raw(src.below(3)).unwrap_or_default()
    }
    fn f4(src: &mut impl Source) -> [f32; 4] {
        [src.f32(), src.f32(), src.f32(), src.f32()]
    }
    RxBuffer {
        updates: UpdateFlags(src.u8() & UpdateFlags::ALL),
        system_shutdown: Shutdown {
            servos: src.bool(),
            motors: src.bool(),
        },
        motor_control_mode: [motor(src), motor(src), motor(src), motor(src)],
        motor_target: [target(src), target(src), target(src), target(src)],
        motor_goal_position: [target(src), target(src), target(src), target(src)],
        servo_mode: [servo(src), servo(src), servo(src), servo(src)],
        servo_pos: [src.u16(), src.u16(), src.u16(), src.u16()],
        motor_pid_settings: MotorPidSettings {
            kp: f4(src),
            ki: f4(src),
            kd: f4(src),
        },
        imu_gyro_orientation: src.bytes::<9>().map(|b| b as i8),
        imu_compass_orientation: src.bytes::<9>().map(|b| b as i8),
        kinematics: KinematicsConfig {
            inverse: [f4(src), f4(src), f4(src)],
            ticks_to_rad: f4(src),
        },
    }
}

/// Seed 004 board, INV-21: a transfer whose motor shutdown bit is set — whatever the rest of its
/// bytes, so whatever the decoder made of them: any refusal, or any buffer — leaves the ladder in
/// BRAKE and tells the handler to turn the motors off before it returns, from any valid ladder
/// state (the seed's "motors stop within one SPI cycle"; INV-7 at the board's level); its servo
/// bit stops every servo and cuts the rail there. The bytes half: `shutdown_raw` reads the bits of
/// byte 5 of any buffer.
pub fn pi_spi_shutdown_bit_brakes_in_its_transfer(src: &mut impl Source) {
    use crate::pi_spi::{PiSpiApp, ServoOutputs, MOTORS, TUNING};
    use protocol::pi_spi::{RxBuffer, Shutdown};
    use statemachine::{check, Config, Drive, Mode};
    let ladder = statemachine::harness::arbitrary::ladder::<MOTORS>(src, Config::PI_SPI);
    let mut safety = crate::Safety::from_ladder(ladder);
    let was_running = safety.mode() != Mode::Brake;
    let mut app = PiSpiApp::new(&Config::PI_SPI, &TUNING, 100, 8401);
    let raw = Shutdown {
        servos: src.bool(),
        motors: true,
    };
    let decoded: Result<RxBuffer, _> = if src.bool() {
        Ok(any_pi_rx(src))
    } else {
        Err(statemachine::harness::arbitrary::reason(src))
    };
    let o = app.apply(&mut safety, raw, decoded);
    check!(
        o.out.mode == Mode::Brake && o.out.drive == Drive::Brake,
        "INV-21: the motor shutdown bit latches BRAKE in its own transfer"
    );
    check!(
        o.motors_off,
        "INV-21: the handler is told to turn the motors off"
    );
    if raw.servos {
        check!(
            o.servos == ServoOutputs::OFF,
            "INV-21: the servo shutdown bit stops every servo and cuts the rail in its own transfer"
        );
    }
    cover!(src, was_running, "shutdown while running");
    cover!(
        src,
        o.accepted,
        "shutdown in a buffer that passed every check"
    );
    cover!(src, !o.accepted, "shutdown in a refused buffer");
}

/// Seed 004 board, INV-22: a transfer the decoder refused (a wrong version or parity — the
/// protocol crate's `verify_version_and_parity_first` — or any other reason) changes nothing but
/// counters: no valid frame, no gain, no servo command, no update counter, and the drive stays
/// what it was unless its shutdown bit stops the motors.
///
/// Under Kani by composition: `Safety::apply` records the events the application applies
/// ([`event_log`]) instead of stepping the ladder, and the harness checks that a refused transfer
/// applies exactly `Shutdown(true)` when its bit is set, then `Rejected` of its reason, and nothing
/// else. What those events do to any valid ladder of four axes is the ladder's own proof
/// (`verify_one_step_properties_4`, every profile): a refusal changes nothing applied, keeps the
/// drive and validates nothing (INV-4), the shutdown bit brakes in its step (INV-7), an event
/// without a frame validates nothing (INV-18), and the state after each stays valid (INV-0). The
/// twin runs the whole body on the real ladder.
pub fn pi_spi_refusal_changes_nothing(src: &mut impl Source) {
    use crate::pi_spi::{PiSpiApp, MOTORS, TUNING};
    use protocol::pi_spi::Shutdown;
    use statemachine::{check, Config, Drive, Mode, RejectReason};
    let ladder = statemachine::harness::arbitrary::ladder::<MOTORS>(src, Config::PI_SPI);
    let mut safety = crate::Safety::from_ladder(ladder);
    let mut app = PiSpiApp::new(&Config::PI_SPI, &TUNING, 100, 8401);
    let raw = Shutdown {
        servos: src.bool(),
        motors: src.bool(),
    };
    let reason = statemachine::harness::arbitrary::reason(src);
    let before = safety.output();
    let frames = safety.ladder().counters().valid_frames;
    let gains = app.loops().map(|l| l.gains());
    let servo = *app.servo();
    let updates_before = *app.updates();
    let o = app.apply(&mut safety, raw, Err(reason));
    check!(!o.accepted, "INV-22: a refused buffer is not accepted");
    // (Under Kani the ladder is not stepped: this one and the drive's are the ladder's proofs.)
    check!(
        safety.ladder().counters().valid_frames == frames,
        "INV-22: a refused buffer is no valid frame"
    );
    check!(
        app.loops().map(|l| l.gains()) == gains,
        "INV-22: a refused buffer changes no gain"
    );
    check!(
        app.servo().modes == servo.modes && app.servo().pulses_us == servo.pulses_us,
        "INV-22: a refused buffer changes no servo command"
    );
    check!(
        *app.updates() == updates_before,
        "INV-22: a refused buffer takes no update flag"
    );
    check!(
        o.out == safety.output() && o.motors_off == (o.out.drive == Drive::Brake),
        "INV-22: the outcome reports the ladder's output"
    );
    #[cfg(kani)]
    {
        let refusal = event_log::code(&statemachine::Event::<MOTORS>::Rejected(reason));
        let [first, second, count] = safety.seen;
        check!(
            count == 1 + u8::from(raw.motors),
            "INV-22: a refused buffer applies one event, two with its shutdown bit"
        );
        check!(
            if raw.motors {
                first == event_log::code(&statemachine::Event::<MOTORS>::Shutdown(true))
                    && second == refusal
            } else {
                first == refusal
            },
            "INV-22: a refused buffer applies its shutdown bit if set, then the refusal of its reason"
        );
    }
    #[cfg(not(kani))]
    {
        if raw.motors {
            check!(
                o.out.drive == Drive::Brake,
                "INV-22: its shutdown bit still brakes"
            );
        } else {
            check!(
                o.out.drive == before.drive,
                "INV-22: without the shutdown bit a refused buffer leaves the drive as it was"
            );
        }
    }
    cover!(src, before.mode != Mode::Brake, "refused while running");
    cover!(src, reason == RejectReason::Version, "wrong version");
    cover!(src, reason == RejectReason::Parity, "wrong parity");
    cover!(src, raw.motors, "refused buffer with the shutdown bit");
}

/// INV-23: Seed 004 board: gains received at run time either are refused whole, or every controller built
/// from them keeps the limits of its bounds (non-negative, the board's) and so stays inside the
/// PID's proven bounds: one sample from rest, with any setpoint and measurement, returns
/// |u| ≤ the bounds' output limit (control's `verify_pid_bounded` covers every later sample).
pub fn pi_spi_gain_updates_stay_bounded(src: &mut impl Source) {
    use crate::pi_spi::{gains_from_wire, GainError, POSITION_BOUNDS, SPEED_BOUNDS};
    use control::Pid;
    use protocol::pi_spi::assumed::MotorPidSettings;
    use statemachine::check;
    // Under Kani any bit patterns; the twin draws mostly from the interesting ranges.
    let gain = |src: &mut _| {
        if cfg!(kani) {
            Source::f32(src)
        } else {
            match Source::below(src, 6) {
                0 => 0.0,
                1 => f32::from(Source::u16(src)) / 1000.0,
                2 => f32::from(Source::u16(src)) / 100_000.0,
                3 => -f32::from(Source::u16(src)),
                4 => f32::from(Source::u16(src)),
                _ => Source::f32(src),
            }
        }
    };
    let mut f4 = || [gain(src), gain(src), gain(src), gain(src)];
    let s = MotorPidSettings {
        kp: f4(),
        ki: f4(),
        kd: f4(),
    };
    let b = if src.bool() {
        SPEED_BOUNDS
    } else {
        POSITION_BOUNDS
    };
    let r = gains_from_wire(&s, &b);
    if let Ok(set) = &r {
        #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
        for i in 0..crate::pi_spi::MOTORS {
            let g = &set[i];
            check!(g.is_valid(), "INV-23: accepted gains have valid limits");
            check!(
                g.out_limit == b.out_limit && g.i_limit == b.i_limit,
                "INV-23: accepted gains keep the board's limits"
            );
            check!(
                g.kp >= Q::ZERO && g.ki_dt >= Q::ZERO && g.kd_dt >= Q::ZERO,
                "INV-23: accepted gains are never negative"
            );
            let mut pid = Pid::new(*g);
            let u = pid.step(Q::from_bits(src.i32()), Q::from_bits(src.i32()));
            check!(
                u <= b.out_limit && u >= b.out_limit.saturating_neg(),
                "INV-23: a controller from accepted gains stays within its output limit"
            );
            check!(pid.is_valid(), "INV-23: and within its integrator limit");
        }
    }
    cover!(src, r.is_ok(), "gains accepted");
    cover!(
        src,
        r == Err(GainError::NonFinite),
        "NaN or infinite gain refused"
    );
    cover!(
        src,
        r == Err(GainError::TooLarge),
        "gain beyond its bound refused"
    );
    #[cfg(not(kani))]
    cover!(src, r == Err(GainError::Negative), "negative gain refused");
}

/// Any `KinematicsConfig` the odometry accepts: drawn numbers within the bounds are kept, the others
/// are folded onto accepted constants, so every accepted configuration is reachable (under Kani,
/// all) and the solver meets no arithmetic on the drawn numbers.
fn accepted_kinematics(src: &mut impl Source) -> protocol::pi_spi::assumed::KinematicsConfig {
    use crate::odometry::{MAX_LINEAR_GAIN, MAX_TICKS_TO_RAD, MAX_YAW_GAIN, MIN_TICKS_TO_RAD};
    let mut k = protocol::pi_spi::assumed::KinematicsConfig::default();
    // Indexed, not iterated (as `odometry::validate`): Kani executes no pointer offsets.
    let bounds = [MAX_LINEAR_GAIN, MAX_LINEAR_GAIN, MAX_YAW_GAIN];
    #[allow(clippy::needless_range_loop)]
    for i in 0..3 {
        let max = bounds[i];
        for j in 0..4 {
            let v = src.f32();
            k.inverse[i][j] = if v.is_finite() && v.abs() <= max {
                v
            } else if src.bool() {
                0.5
            } else {
                -0.25
            };
        }
    }
    for j in 0..4 {
        let v = src.f32();
        k.ticks_to_rad[j] =
            if v.is_finite() && v.abs() >= MIN_TICKS_TO_RAD && v.abs() <= MAX_TICKS_TO_RAD {
                v
            } else if src.bool() {
                0.01
            } else {
                -1.5
            };
    }
    if k.inverse == [[0.0; 4]; 3] {
        k.inverse[0][0] = 0.0125;
    }
    k
}

/// P-19: Odometry, update flag `KINEMATICS`: a configuration is accepted only if every number is finite,
/// every `ticks_to_rad` and every `inverse` entry is within its documented bound and the matrix is
/// not all zero; accepted, it is in force and the pose is kept; refused, the configuration in force
/// and the outputs stay and only the refusal counter moves. From an unconfigured odometry or one
/// configured with any accepted configuration.
pub fn odometry_configure_guarded(src: &mut impl Source) {
    use crate::odometry::{
        KinematicsError, Odometry, MAX_LINEAR_GAIN, MAX_TICKS_TO_RAD, MAX_YAW_GAIN,
        MIN_TICKS_TO_RAD,
    };
    let mut o = Odometry::new();
    if src.bool() {
        let first = accepted_kinematics(src);
        check!(
            o.configure(&first).is_ok(),
            "P-19: a folded configuration is accepted"
        );
    }
    // Under Kani way 3 alone draws every configuration; the others steer the twin to the edges:
    // one number off an accepted configuration, or an all-zero matrix with one number drawn.
    let way = src.below(4);
    let mut k = if way == 3 {
        protocol::pi_spi::assumed::KinematicsConfig::default()
    } else {
        accepted_kinematics(src)
    };
    if way == 2 {
        k.inverse = [[0.0; 4]; 3];
    }
    let raw = if way == 3 {
        16
    } else {
        usize::from(way.min(1))
    };
    let at = usize::from(src.below(16));
    // The 16 numbers in wire order: the matrix by rows, then `ticks_to_rad`.
    for i in 0..16 {
        if raw == 16 || (raw == 1 && i == at) {
            let v = src.f32();
            if i < 12 {
                k.inverse[i / 4][i % 4] = v;
            } else {
                k.ticks_to_rad[i - 12] = v;
            }
        }
    }
    let before = o;
    let result = o.configure(&k);
    if result.is_ok() {
        let entries = || k.inverse.iter().flatten();
        check!(
            entries().chain(&k.ticks_to_rad).all(|v| v.is_finite()),
            "P-19: an accepted configuration is finite"
        );
        check!(
            k.ticks_to_rad
                .iter()
                .all(|t| t.abs() >= MIN_TICKS_TO_RAD && t.abs() <= MAX_TICKS_TO_RAD),
            "P-19: accepted ticks_to_rad within bounds"
        );
        check!(
            k.inverse
                .iter()
                .zip([MAX_LINEAR_GAIN, MAX_LINEAR_GAIN, MAX_YAW_GAIN])
                .all(|(row, max)| row.iter().all(|a| a.abs() <= max)),
            "P-19: accepted inverse entries within bounds"
        );
        check!(
            entries().any(|a| *a != 0.0),
            "P-19: an accepted matrix moves the robot"
        );
        check!(
            o.config() == Some(&k),
            "P-19: the accepted configuration is in force"
        );
        check!(
            o.counters() == before.counters(),
            "P-19: an accepted configuration counts nothing"
        );
    } else {
        check!(
            o.config() == before.config(),
            "P-19: a refused configuration leaves the one in force"
        );
        check!(
            o.counters().refused_configs == before.counters().refused_configs.saturating_add(1),
            "P-19: a refused configuration is counted"
        );
    }
    let (now, then) = (o.data(), before.data());
    check!(
        now.pos_x == then.pos_x && now.pos_y == then.pos_y && now.heading == then.heading,
        "P-19: configure keeps the pose"
    );
    cover!(src, result.is_ok(), "accepted");
    cover!(
        src,
        result == Err(KinematicsError::NotFinite),
        "refused: not finite"
    );
    cover!(
        src,
        result == Err(KinematicsError::TicksToRad),
        "refused: ticks_to_rad"
    );
    cover!(
        src,
        result == Err(KinematicsError::InverseEntry),
        "refused: inverse entry"
    );
    cover!(
        src,
        result == Err(KinematicsError::ZeroMatrix),
        "refused: zero matrix"
    );
}

/// P-19: Odometry: for any accepted configuration, any counts (wrapping), any period and resets between
/// the updates, `update` never panics and reports only finite values, the heading in (−π, π] and
/// the position within ±`MAX_POSITION_M`; no result ever needs the non-finite guard; a refused
/// period changes nothing but its counter.
pub fn odometry_update_finite(src: &mut impl Source) {
    use crate::odometry::{Odometry, MAX_POSITION_M, MIN_DT_S};
    use core::f32::consts::PI;
    let k = accepted_kinematics(src);
    let mut o = Odometry::new();
    check!(
        o.configure(&k).is_ok(),
        "P-19: a folded configuration is accepted"
    );
    let mut counts = [src.i32(), src.i32(), src.i32(), src.i32()];
    let steps = if cfg!(kani) { 2 } else { 6 };
    let (mut refused, mut wrapped, mut clamped, mut half_turn) = (false, false, false, false);
    for _ in 0..steps {
        let prev = counts;
        for c in counts.iter_mut() {
            *c = if src.bool() {
                src.i32()
            } else {
                c.wrapping_add(i32::from(src.u8() as i8))
            };
        }
        wrapped |= counts
            .iter()
            .zip(prev)
            .any(|(now, was)| now.checked_sub(was).is_none());
        let dt = src.f32();
        let (then, seen) = (o.data(), o.counters());
        let d = o.update(counts, dt);
        check!(
            [d.pos_x, d.pos_y, d.heading, d.vx, d.vy, d.wz]
                .iter()
                .all(|v| v.is_finite()),
            "P-19: odometry outputs are finite"
        );
        check!(
            d.heading > -PI && d.heading <= PI,
            "P-19: heading within (-pi, pi]"
        );
        check!(
            d.pos_x.abs() <= MAX_POSITION_M && d.pos_y.abs() <= MAX_POSITION_M,
            "P-19: position within its bound"
        );
        check!(
            o.counters().non_finite == 0,
            "P-19: no result needs the non-finite guard"
        );
        if !(dt.is_finite() && dt >= MIN_DT_S) {
            refused = true;
            check!(d == then, "P-19: a refused period changes nothing");
            check!(
                o.counters().refused_dt == seen.refused_dt.saturating_add(1),
                "P-19: a refused period is counted"
            );
        }
        clamped |= o.counters().position_clamped > seen.position_clamped;
        half_turn |= o.counters().large_rotations > seen.large_rotations;
        if src.below(8) == 0 {
            o.reset();
        }
    }
    cover!(src, refused, "period refused");
    cover!(src, wrapped, "a counter wrapped");
    cover!(src, clamped, "position clamped");
    cover!(src, half_turn, "more than half a turn in one period");
}

/// Stand-ins for `verify_pi_spi_refusal_changes_nothing`: `Safety::apply` records which event the
/// application applied, in order, in the Kani-only field `Safety::seen`, and leaves the ladder as
/// it was; `PiSpiApp::take`, the path of an accepted buffer, fails if it is ever reached.
#[cfg(kani)]
#[allow(dead_code)]
mod event_log {
    use statemachine::Event;

    /// An event as the refusal harness tells them apart: 1 and 2 the shutdown bit set and clear,
    /// 16 + the reason's index a refusal, 255 any other event.
    pub fn code<const N: usize>(e: &Event<N>) -> u8 {
        match e {
            Event::Shutdown(true) => 1,
            Event::Shutdown(false) => 2,
            Event::Rejected(r) => 16u8.saturating_add(r.index() as u8),
            _ => 255,
        }
    }

    pub fn record<const N: usize>(safety: &mut crate::Safety<N>, event: Event<N>) {
        let [first, second, count] = &mut safety.seen;
        match *count {
            0 => *first = code(&event),
            1 => *second = code(&event),
            _ => {}
        }
        *count = count.saturating_add(1);
    }

    /// Stands for `PiSpiApp::take`, the path of a buffer that passed every check, and fails: the
    /// refusal harness so proves that a refused buffer never reaches it. (CBMC's symbolic
    /// execution does not prune a path by the values it can take: with the real `take` the
    /// harness spent about 100 s executing the path of an accepted buffer.)
    pub fn never_taken(
        _app: &mut crate::pi_spi::PiSpiApp,
        _safety: &mut crate::Safety<{ crate::pi_spi::MOTORS }>,
        _cmd: &protocol::pi_spi::RxBuffer,
    ) -> bool {
        statemachine::fail!("INV-22: a refused buffer is never taken")
    }
}

/// Kani models of the one-shot updates' appliers, for the shutdown harness: each is proven on its
/// own (INV-23 `verify_pi_spi_gain_updates_stay_bounded`, `verify_odometry_configure_guarded`,
/// `imu::verify_orientation_check_is_the_definition`), none takes the ladder, and none of their
/// state is read by the property; the models return any result and so over-approximate them.
/// (They also keep `libm`'s x86 inline assembly, which Kani does not model, out of that harness.)
// Referenced only by the `kani::stub` attributes, which rustc does not count as uses.
#[cfg(kani)]
#[allow(dead_code)]
mod update_models {
    use crate::imu::{ImuFusion, OrientationError};
    use crate::odometry::{KinematicsError, Odometry};
    use crate::pi_spi::{GainBounds, GainError, MOTORS};
    use control::{AntiWindup, PidGains, Q};
    use protocol::pi_spi::assumed::{KinematicsConfig, MotorPidSettings};

    pub fn any_gains(
        _s: &MotorPidSettings,
        b: &GainBounds,
    ) -> Result<[PidGains; MOTORS], GainError> {
        if kani::any() {
            return Err(GainError::TooLarge);
        }
        let g = || PidGains {
            kp: Q::from_bits(kani::any()),
            ki_dt: Q::from_bits(kani::any()),
            kd_dt: Q::from_bits(kani::any()),
            out_limit: b.out_limit,
            i_limit: b.i_limit,
            anti_windup: AntiWindup::Conditional,
        };
        Ok([g(), g(), g(), g()])
    }

    pub fn any_orientation(
        _imu: &mut ImuFusion,
        _gyro: [i8; 9],
        _compass: [i8; 9],
    ) -> Result<(), OrientationError> {
        if kani::any() {
            Ok(())
        } else {
            Err(OrientationError::GyroEntry)
        }
    }

    pub fn any_configure(
        _odo: &mut Odometry,
        _k: &KinematicsConfig,
    ) -> Result<(), KinematicsError> {
        if kani::any() {
            Ok(())
        } else {
            Err(KinematicsError::NotFinite)
        }
    }
}

/// Stand-in for `libm::sinf` under Kani (the odometry's arc factors,
/// `odometry::verification::verify_arc_factors_bounded`): any value in the real function's range,
/// NaN where the real one returns NaN; `mcu/tests/libm_ranges.rs` checks that range for every f32
/// argument, so a property proven with it holds for the real function.
#[cfg(kani)]
pub(crate) mod libm_models {
    /// `libm::sinf`: in [−1, 1] for a finite argument, NaN otherwise.
    pub fn sinf(x: f32) -> f32 {
        if x.is_finite() {
            let v: f32 = kani::any();
            kani::assume((-1.0..=1.0).contains(&v));
            v
        } else {
            f32::NAN
        }
    }
}

#[cfg(kani)]
mod proofs {
    use statemachine::harness::KaniSource;

    #[kani::proof]
    #[kani::unwind(17)]
    fn verify_current_loop_safe() {
        super::current_loop_safe(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(17)]
    fn verify_speed_loop_bounded() {
        super::speed_loop_bounded(&mut KaniSource);
    }

    #[kani::proof]
    fn verify_estop_press_brakes_at_once() {
        super::estop_press_brakes_at_once(&mut KaniSource);
    }

    // Kissat (shipped with Kani) rather than CaDiCaL: 12 s against 34 s on one build, 11 s against
    // 31 s on another (REPORT.md, "Kani suite time").
    #[kani::proof]
    #[kani::solver(kissat)]
    fn verify_micros_bounded() {
        super::micros_bounded(&mut KaniSource);
    }

    /// The link body's half of an ESTOP frame, from any ladder state (the bytes' half is the
    /// protocol crate's P-5). The whole byte path from any ladder state did not finish (8 min,
    /// 6 GB: the symbolic ladder and the decoder's 262-iteration loops in one formula); it runs
    /// as the test `serial_estop_brakes_at_its_last_byte`.
    #[kani::proof]
    #[kani::unwind(17)]
    fn verify_serial_estop_message_brakes() {
        super::serial_estop_message_brakes(&mut KaniSource);
    }

    /// Command validation is INV-5's proven contract here (`statemachine::kani_models`), as in
    /// the ladder's own harnesses, and the one-shot updates' appliers their models
    /// (`update_models`): no symbolic float arithmetic in this one.
    #[kani::proof]
    #[kani::unwind(17)]
    #[kani::stub(
        statemachine::validate::validate_into,
        statemachine::kani_models::any_validation
    )]
    #[kani::stub(crate::pi_spi::gains_from_wire, super::update_models::any_gains)]
    #[kani::stub(
        crate::imu::ImuFusion::set_orientation,
        super::update_models::any_orientation
    )]
    #[kani::stub(
        crate::odometry::Odometry::configure,
        super::update_models::any_configure
    )]
    fn verify_pi_spi_shutdown_bit_brakes_in_its_transfer() {
        super::pi_spi_shutdown_bit_brakes_in_its_transfer(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(17)]
    #[kani::stub(crate::Safety::apply, super::event_log::record)]
    #[kani::stub(crate::pi_spi::PiSpiApp::take, super::event_log::never_taken)]
    fn verify_pi_spi_refusal_changes_nothing() {
        super::pi_spi_refusal_changes_nothing(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL: 11.7 s against 29.5 s on one build, 10.7 s
    // against 27.6 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(5)]
    #[kani::solver(minisat)]
    fn verify_pi_spi_gain_updates_stay_bounded() {
        super::pi_spi_gain_updates_stay_bounded(&mut KaniSource);
    }

    /// Float comparisons and copies only (no arithmetic on the drawn numbers): 16 symbolic f32.
    #[kani::proof]
    #[kani::unwind(17)]
    fn verify_odometry_configure_guarded() {
        super::odometry_configure_guarded(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use statemachine::harness::Twin;

    const CASES: u32 = 100_000;

    #[test]
    fn current_loop_safe() {
        Twin::run(0x3C_01, CASES, super::current_loop_safe).assert_covered(3);
    }

    #[test]
    fn speed_loop_bounded() {
        Twin::run(0x3C_02, CASES, super::speed_loop_bounded).assert_covered(1);
    }

    #[test]
    fn estop_press_brakes_at_once() {
        Twin::run(0x3C_03, CASES, super::estop_press_brakes_at_once).assert_covered(1);
    }

    #[test]
    fn micros_bounded() {
        Twin::run(0x3C_04, CASES, super::micros_bounded).assert_covered(1);
    }

    #[test]
    fn serial_estop_message_brakes() {
        Twin::run(0x3C_0C, 50_000, super::serial_estop_message_brakes).assert_covered(2);
    }

    #[test]
    fn serial_estop_brakes_at_its_last_byte() {
        Twin::run(0x3C_05, 20_000, super::serial_estop_brakes_at_its_last_byte).assert_covered(2);
    }

    #[test]
    fn pi_spi_shutdown_bit_brakes_in_its_transfer() {
        Twin::run(
            0x3C_06,
            50_000,
            super::pi_spi_shutdown_bit_brakes_in_its_transfer,
        )
        .assert_covered(3);
    }

    #[test]
    fn pi_spi_refusal_changes_nothing() {
        Twin::run(0x3C_07, 50_000, super::pi_spi_refusal_changes_nothing).assert_covered(4);
    }

    #[test]
    fn pi_spi_gain_updates_stay_bounded() {
        Twin::run(0x3C_09, 100_000, super::pi_spi_gain_updates_stay_bounded).assert_covered(4);
    }

    #[test]
    fn odometry_configure_guarded() {
        Twin::run(0x3C_0A, CASES, super::odometry_configure_guarded).assert_covered(5);
    }

    #[test]
    fn odometry_update_finite() {
        Twin::run(0x3C_0B, 120_000, super::odometry_update_finite).assert_covered(4);
    }
}
