//! Cross-crate safety harnesses over the very functions the firmware's tasks call (crate `mcu`):
//! bytes from the SPI link through `protocol` into the ladder (`LinkTask::receive` / `apply`, the
//! body of `spi_dma_done`), and a tick through the ladder to the bridge (`TickTask::run` and
//! `TickOutcome::drive`, the body of `watchdog_tick`). The invariants are INV-10 to INV-13 of
//! `SAFETY.md`.
//!
//! The frame proof is split where the two crates meet, the decode result that
//! `LinkTask::apply` turns into a ladder event:
//! - bytes → result: `protocol`'s harnesses (`open` accepts only frames whose CRC matches; every
//!   burst of up to 16 bits changes the CRC; every decode-loop step is total and makes progress);
//! - result → ladder: from *any* valid ladder state, for *any* refusal and any command a decoder
//!   can return: a refusal is exactly one ladder refusal ([`link_refusal_is_one_ladder_refusal`],
//!   with the ladder's INV-4 giving [`refusals_never_move_the_drive`]), a command reaches the
//!   ladder as sent ([`decoded_commands_reach_the_ladder_as_sent`]), verified by Kani;
//! - tick → bridge: [`tick_drives_the_bridge_as_the_ladder_says`], from any valid ladder state,
//!   any board inputs and any bridge and ESTOP-latch state, verified by Kani.
//!
//! The end-to-end bodies (64 bytes → decoder → ladder in one harness) stay as `cargo test` twins:
//! under Kani the protobuf decoder over a symbolic 64-byte frame does not finish.
#![no_std]
#![forbid(unsafe_code)]
#![cfg_attr(
    test,
    allow(
        clippy::unwrap_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::panic
    )
)]

use mcu::hw::RecordingBridge;
use mcu::tick::{Runs, TickInputs};
use mcu::{Bridge, BridgeState, EstopInput, LinkTask, Measurements, Safety, TickTask};
use protocol::amr::{decode_command, encode_command, MotorCommand, FRAME_LEN};
use statemachine::harness::{arbitrary, Source};
use statemachine::{assume, check, cover, Drive, Estop, Mode, RejectReason, Speed};

/// The seed 000 board's ladder: two velocity-driven wheels.
type Ladder = statemachine::Ladder<{ mcu::AXES }>;

fn valid_ladder(src: &mut impl Source) -> Option<Ladder> {
    let cfg = arbitrary::config(src)?;
    let l = arbitrary::ladder(src, cfg);
    l.is_valid().then_some(l)
}

/// The link task as the firmware builds it (the identity it answers with is irrelevant here).
fn link() -> LinkTask {
    LinkTask::new(protocol::amr::McuInfo::default())
}

/// Steps a copy of `l0` through the link task with `decoded`; returns the ladder after it.
fn through_link(l0: &Ladder, decoded: Result<MotorCommand, RejectReason>) -> Ladder {
    let mut safety = Safety::from_ladder(*l0);
    link().apply(&mut safety, decoded);
    *safety.ladder()
}

/// Feeds `frame` through the link task's receive path; returns the ladder after it and whether the
/// frame decoded.
fn receive(l0: &Ladder, frame: &[u8; FRAME_LEN]) -> (Ladder, bool) {
    let mut safety = Safety::from_ladder(*l0);
    link().receive(&mut safety, frame);
    (*safety.ladder(), decode_command(frame).is_ok())
}

/// A command whose speeds the default configuration accepts, in speed mode.
fn plausible_command(src: &mut impl Source) -> MotorCommand {
    let v = statemachine::Config::DEFAULT.params().v_max;
    MotorCommand {
        timestamp_us: src.u32(),
        left_speed_cmd: src.speed_within(v).to_num(),
        right_speed_cmd: src.speed_within(v).to_num(),
        control_mode: 1,
        enable: src.bool(),
        seq: src.u32(),
        // Any request: the ladder never sees it (an identity request changes only the reply).
        request: src.u32(),
    }
}

/// A refusal moved nothing but the counters: `l` is `l0` after one refused event.
fn assert_only_counted(l0: &Ladder, l: &Ladder) {
    check!(
        unchanged(l0, l),
        "INV-10: a refusal leaves the ladder unchanged but for its counters"
    );
    check!(
        l.counters().rejected_total() == l0.counters().rejected_total().saturating_add(1),
        "INV-10: a refusal adds exactly one to the refusal count"
    );
}

/// `l` is `l0` after the event of `cmd`: if the ladder accepted it, its new command is the sent
/// speeds to within half a Q16.16 step, with the sent enable and sequence number, and the watchdog
/// age restarts.
fn check_delivered_as_sent(src: &mut impl Source, l0: &Ladder, l: &Ladder, cmd: &MotorCommand) {
    let accepted = l.counters().valid_frames != l0.counters().valid_frames;
    if accepted {
        let sp = l.last_valid();
        check!(
            sp.is_some(),
            "INV-12: an accepted frame leaves a valid command held"
        );
        if let Some(sp) = sp {
            let half = Speed::from_bits(1);
            let sent_l: Speed = Speed::from_num(cmd.left_speed_cmd);
            let sent_r: Speed = Speed::from_num(cmd.right_speed_cmd);
            let [left, right] = sp.axes.map(|a| a.target);
            check!(
                left.saturating_sub(sent_l).saturating_abs() <= half,
                "INV-12: the left speed is the sent one within one Q16.16 step"
            );
            check!(
                right.saturating_sub(sent_r).saturating_abs() <= half,
                "INV-12: the right speed is the sent one within one Q16.16 step"
            );
            check!(
                sp.enable == cmd.enable,
                "INV-12: the ladder holds the sent enable"
            );
            check!(
                sp.seq() == Some(cmd.seq),
                "INV-12: the ladder holds the sent sequence number"
            );
        }
        check!(l.age() == 0, "INV-12: a valid frame resets the age");
    }
    cover!(src, accepted, "accepted");
    cover!(
        src,
        l.counters().rejected(RejectReason::Stale) != l0.counters().rejected(RejectReason::Stale),
        "refused as stale"
    );
}

fn unchanged(a: &Ladder, b: &Ladder) -> bool {
    a.applied() == b.applied()
        && a.last_valid() == b.last_valid()
        && a.age() == b.age()
        && a.mode() == b.mode()
        && a.output().drive == b.output().drive
}

/// INV-10: whatever 64 bytes arrive, a frame that does not decode changes neither the command, nor the
/// watchdog age, nor the rung, nor the setpoint: corrupted bytes only ever add to the counters.
pub fn undecodable_bytes_never_move_the_drive(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let mut frame = [0u8; FRAME_LEN];
    if src.bool() {
        for b in frame.iter_mut() {
            *b = src.u8();
        }
    } else {
        // A real frame with up to three bytes overwritten: corruption that keeps the frame's shape
        // (none overwritten: the frame as sent).
        encode_command(&plausible_command(src), &mut frame);
        let n = src.below(4);
        for _ in 0..n {
            let i = usize::from(src.below(FRAME_LEN as u8));
            if let Some(b) = frame.get_mut(i) {
                *b = src.u8();
            }
        }
    }
    let (l, decoded) = receive(&l0, &frame);
    if !decoded {
        assert_only_counted(&l0, &l);
    }
    cover!(
        src,
        l.counters().rejected(RejectReason::Crc) != l0.counters().rejected(RejectReason::Crc),
        "refused by the CRC"
    );
    cover!(src, decoded, "bytes that form a frame");
}

/// Bits in a frame.
const FRAME_BITS: u16 = 512;
const _: () = assert!(FRAME_BITS as usize == FRAME_LEN * 8);

/// INV-11 (Incident-A): one flipped bit anywhere in a valid command frame never reaches the ladder as a
/// command, from any state.
pub fn single_bit_flip_never_reaches_the_ladder(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let cmd = plausible_command(src);
    let mut frame = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut frame);
    let clean_frame = frame;
    let bit = src.u16_below(FRAME_BITS);
    if let Some(b) = frame.get_mut(usize::from(bit / 8)) {
        *b ^= 1u8 << (bit % 8);
    }
    let (l, decoded) = receive(&l0, &frame);
    check!(!decoded, "INV-11: a single bit flip never decodes");
    check!(
        unchanged(&l0, &l),
        "INV-11: a flipped frame leaves the ladder unchanged but for its counters"
    );
    let (clean, _) = receive(&l0, &clean_frame);
    cover!(
        src,
        clean.last_valid() != l0.last_valid(),
        "the unflipped frame would have been applied"
    );
    cover!(src, bit < 8 * 2, "flip in the length or first payload byte");
    cover!(
        src,
        usize::from(bit) >= 8 * (FRAME_LEN - 2),
        "flip in the CRC"
    );
}

/// INV-12: a valid frame delivers exactly the command that was sent: the ladder's new command is the
/// sent speeds to within half a Q16.16 step, with the sent enable and sequence number.
pub fn valid_frame_delivers_the_sent_command(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let cmd = plausible_command(src);
    let mut frame = [0u8; FRAME_LEN];
    encode_command(&cmd, &mut frame);
    check!(
        decode_command(&frame) == Ok(cmd),
        "INV-12: a freshly encoded frame decodes to itself"
    );
    let (l, _) = receive(&l0, &frame);
    check_delivered_as_sent(src, &l0, &l, &cmd);
}

/// INV-10 / INV-11, ladder side: whatever a link decoder refuses, for whatever reason, the event it
/// becomes changes neither the command, nor the watchdog age, nor the rung, nor the drive; only the
/// refusal counters move. A twin only: under Kani it is [`link_refusal_is_one_ladder_refusal`]
/// composed with the ladder's INV-4.
pub fn refusals_never_move_the_drive(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let reason = arbitrary::reason(src);
    let l = through_link(&l0, Err(reason));
    assert_only_counted(&l0, &l);
    cover!(src, reason == RejectReason::Crc, "refused by the CRC");
    cover!(
        src,
        l0.last_valid().is_some() && l0.mode() != statemachine::Mode::Brake,
        "refused while driving"
    );
}

/// INV-10 / INV-11, the link task's half: whatever a decoder refuses, `LinkTask::apply` turns it into
/// exactly one ladder refusal: the ladder after it equals, field for field, the ladder after
/// `Event::Rejected(reason)`, from any valid state. With INV-4 (the ladder's refusal changes nothing
/// applied and adds one to its reason's refusal count, verified for every valid state) this gives
/// [`refusals_never_move_the_drive`], whose own Kani proof took 216 to 430 s against this one's 48 s.
pub fn link_refusal_is_one_ladder_refusal(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let reason = arbitrary::reason(src);
    let l = through_link(&l0, Err(reason));
    let mut want = l0;
    want.update(statemachine::Event::Rejected(reason));
    check!(
        l == want,
        "INV-10: the link task turns a refusal into exactly one ladder refusal"
    );
    cover!(src, reason == RejectReason::Crc, "refused by the CRC");
    cover!(
        src,
        l0.last_valid().is_some() && l0.mode() != statemachine::Mode::Brake,
        "refused while driving"
    );
}

/// INV-12, ladder side: a command a decoder returns reaches the ladder as sent: if accepted, the
/// ladder's new command is the sent speeds to within half a Q16.16 step, with the sent enable and
/// sequence number, and the watchdog age restarts.
pub fn decoded_commands_reach_the_ladder_as_sent(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let cmd = plausible_command(src);
    let l = through_link(&l0, Ok(cmd));
    check_delivered_as_sent(src, &l0, &l, &cmd);
}

/// INV-13: the tick drives the bridge as the ladder says, from any valid ladder state, any board
/// inputs and any bridge and ESTOP-latch state: after `TickTask::run` and `TickOutcome::drive`
/// the bridge runs only if the ladder drives and no ESTOP press is pending; the tick at which the
/// watchdog age reaches `brake_after` leaves the bridge braked; a braked bridge keeps the holding
/// brake applied.
pub fn tick_drives_the_bridge_as_the_ladder_says(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let brake_after = l0.brake_after();
    let mut safety = Safety::from_ladder(l0);
    let mut tick = TickTask::new(&mcu::tuning::AMR);
    let mut bridge = RecordingBridge::new(src.u16());
    if src.bool() {
        bridge.apply(BridgeState::Run);
    }
    bridge.tripped = src.bool();
    let mut estop = EstopInput::new();
    if src.bool() {
        estop.edge(&mut bridge, true);
    }
    let inputs = TickInputs {
        meas: Measurements {
            speeds: [src.speed(), src.speed()],
            overcurrent: src.bool(),
            ..Measurements::default()
        },
        driver_fault: src.bool(),
        thermal_warning: src.bool(),
        estop: match src.below(3) {
            0 => None,
            1 => Some(Estop::Engage),
            _ => Some(Estop::Release),
        },
        runs: Runs {
            current: src.u32(),
            speed: src.u32(),
        },
    };
    let pending = estop.press_pending();
    let o = tick.run(&mut safety, &inputs);
    o.drive(&mut bridge, &estop);
    let braked = bridge.state == BridgeState::Brake;
    check!(
        braked == (o.out.drive == Drive::Brake || pending),
        "INV-13: the bridge runs exactly when the ladder drives and no ESTOP press is pending"
    );
    if safety.ladder().age() >= brake_after {
        check!(
            braked,
            "INV-13: the tick at age >= brake_after leaves the bridge braked"
        );
    }
    if braked {
        check!(
            !bridge.tripped,
            "INV-13: a braked tick clears the break flag"
        );
    }
    check!(
        o.brake_release == (o.out.mode != Mode::Brake),
        "INV-13: the holding brake is released only while the ladder drives"
    );
    cover!(
        src,
        l0.mode() != Mode::Brake && safety.ladder().age() >= brake_after,
        "comm loss brakes at this tick"
    );
    cover!(src, !braked, "the bridge runs");
    cover!(
        src,
        pending && o.out.drive != Drive::Brake,
        "a pending press keeps it braked"
    );
}

#[cfg(kani)]
mod verification {
    use super::*;
    use statemachine::harness::KaniSource;

    /// Unwinding 100: the derived `==` of two ladders is a `memcmp` over their bytes. MiniSat
    /// rather than CaDiCaL: 17.7 s against 21.4 s on one build, 14.9 s against 20.6 s on another
    /// (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(100)]
    #[kani::solver(minisat)]
    fn verify_link_refusal_is_one_ladder_refusal() {
        link_refusal_is_one_ladder_refusal(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL: 13.8 s against 21.7 s on one build, 12.2 s
    // against 19.3 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(13)]
    #[kani::solver(minisat)]
    fn verify_decoded_commands_reach_the_ladder_as_sent() {
        decoded_commands_reach_the_ladder_as_sent(&mut KaniSource);
    }

    // MiniSat (CBMC's default) rather than CaDiCaL: 20 s against 30 s on one build, 20 s against
    // 27 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::unwind(13)]
    #[kani::solver(minisat)]
    fn verify_tick_drives_the_bridge_as_the_ladder_says() {
        tick_drives_the_bridge_as_the_ladder_says(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use statemachine::harness::Twin;

    #[test]
    fn refusals_never_move_the_drive() {
        Twin::run(24, 200_000, super::refusals_never_move_the_drive).assert_covered(2);
    }

    #[test]
    fn link_refusal_is_one_ladder_refusal() {
        Twin::run(27, 200_000, super::link_refusal_is_one_ladder_refusal).assert_covered(2);
    }

    #[test]
    fn decoded_commands_reach_the_ladder_as_sent() {
        Twin::run(
            25,
            200_000,
            super::decoded_commands_reach_the_ladder_as_sent,
        )
        .assert_covered(2);
    }

    #[test]
    fn tick_drives_the_bridge_as_the_ladder_says() {
        Twin::run(
            26,
            200_000,
            super::tick_drives_the_bridge_as_the_ladder_says,
        )
        .assert_covered(3);
    }

    #[test]
    fn undecodable_bytes_never_move_the_drive() {
        Twin::run(21, 200_000, super::undecodable_bytes_never_move_the_drive).assert_covered(2);
    }

    #[test]
    fn single_bit_flip_never_reaches_the_ladder() {
        Twin::run(22, 200_000, super::single_bit_flip_never_reaches_the_ladder).assert_covered(3);
    }

    #[test]
    fn valid_frame_delivers_the_sent_command() {
        Twin::run(23, 200_000, super::valid_frame_delivers_the_sent_command).assert_covered(2);
    }
}
