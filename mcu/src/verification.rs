//! Harnesses for the task bodies, each written once: the same body is a `cargo test` (the twin
//! driver, biased pseudo-random inputs) and, under `cfg(kani)`, a Kani proof.
//!
//! Properties: the current loop never writes compares beyond the timer's auto-reload, never
//! drives both high sides of a bridge, brakes the bridge in the same run on a trip, and never
//! writes compares to a braked bridge; the speed loop asks for no current in BRAKE and never more
//! than the speed controller's limit; an ESTOP press brakes the bridge in its handler; the µs
//! clock never panics and stays within one tick of the tick count; on the serial boards, a seed 001
//! `ESTOP 1` frame latches BRAKE at its last byte, from any ladder state and after any bytes.

use crate::current::CurrentLoop;
use crate::estop::EstopInput;
use crate::hw::{Bridge, RecordingBridge};
use crate::speed::SpeedLoop;
use crate::timing::micros;
use crate::tuning::AMR;
use control::{BridgeState, Q};
use statemachine::harness::Source;
use statemachine::{assume, cover};

fn amps(src: &mut impl Source) -> Q {
    Q::from_bits(src.i32())
}

/// Current loop: one run from rest with any readings, references, bridge state and break flag.
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
        assert!(
            k.a <= arr && k.b <= arr,
            "compares stay within the auto-reload"
        );
        assert!(k.a == 0 || k.b == 0, "never both high sides of one bridge");
    }
    if s.tripped {
        assert!(
            b.state == BridgeState::Brake,
            "a trip brakes the bridge in the same run"
        );
    }
    if b.state == BridgeState::Brake {
        assert!(
            b.compares.iter().all(|k| k.a == 0 && k.b == 0),
            "a braked bridge gets no compares"
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

/// Speed loop: one run from rest with any counters and any setpoint.
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
        assert!(
            control::within(i, limit),
            "current reference within the speed loop's limit"
        );
    }
    if setpoint.is_none() {
        assert!(s.refs == [Q::ZERO; 2], "no current asked for in BRAKE");
    }
    cover!(src, s.refs.contains(&limit), "reference saturated");
}

/// ESTOP: a press brakes the bridge in the handler, whatever its state, and is reported by the
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
        assert!(
            b.state == BridgeState::Brake,
            "a press brakes the bridge in its handler"
        );
        assert!(
            e.poll(src.bool()) == Some(statemachine::Estop::Engage),
            "a press is reported even if released before the tick"
        );
    }
    cover!(src, pressed && was_running, "press while running");
}

/// µs clock: never panics; within one tick of the tick count (modulo the u32 wrap).
pub fn micros_bounded(src: &mut impl Source) {
    let ticks = src.u32();
    let period = src.u32();
    assume!(src, period > 0);
    let t = micros(ticks, src.u32(), src.bool(), period, 1000);
    let base = ticks.wrapping_mul(1000);
    let off = t.wrapping_sub(base);
    assert!(
        off < 2000,
        "time stamp within one tick after the counted ticks"
    );
    cover!(src, off >= 1000, "update pending counted");
}

/// Seed 001 board: whatever the ladder's state and whatever bytes came before it (a false
/// start-of-frame, a truncated frame), an `ESTOP 1` frame latches BRAKE in the link task's step for
/// its last byte, and is acknowledged.
pub fn serial_estop_brakes_at_its_last_byte(src: &mut impl Source) {
    use crate::cdc::{BoardStatus, CdcLinkTask, MOTORS};
    use protocol::cdc::{Message, MAX_FRAME_LEN};
    use statemachine::{check, Config, Estop, Mode, Source as Origin};
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
    // Under Kani the frame comes first: that any bytes before it do not delay it is the protocol
    // crate's proof (`verify_stream_holds_back_no_frame_*`); this one covers the link body from any
    // ladder state. The twin keeps the bytes before it.
    let used = if cfg!(kani) {
        0
    } else {
        usize::from(src.below(3))
    };
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
        check!(
            safety.mode() == Mode::Brake,
            "an ESTOP frame latches BRAKE at its last byte"
        );
        check!(
            safety.ladder().estop_owners() & Origin::Primary.bit() != 0,
            "the link holds the ESTOP it engaged"
        );
        check!(link.tx.len() > queued, "the ESTOP is acknowledged");
    }
    cover!(src, was_running, "ESTOP while running");
    #[cfg(not(kani))]
    cover!(
        src,
        used == 2 && garbage == [0xAA, 0x55],
        "after a false start of frame"
    );
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

    #[kani::proof]
    fn verify_micros_bounded() {
        super::micros_bounded(&mut KaniSource);
    }

    /// Pending: with the whole ladder state symbolic and the link body's ACK encoding, CBMC had
    /// not finished after 8 minutes (6 GB). The twin runs; the decoder's half is proven in the
    /// protocol crate, the ladder's (ESTOP latches BRAKE in the same step) by INV-7.
    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(262))]
    #[allow(dead_code)]
    fn verify_serial_estop_brakes_at_its_last_byte() {
        super::serial_estop_brakes_at_its_last_byte(&mut KaniSource);
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
    fn serial_estop_brakes_at_its_last_byte() {
        Twin::run(0x3C_05, 20_000, super::serial_estop_brakes_at_its_last_byte).assert_covered(2);
    }
}
