//! Kani harnesses of the ladder invariants (INV-n, `proofs/SAFETY.md`) and their `cargo test` twins.
//!
//! Each property is one body generic over [`Source`]: `verify_<property>` runs it under Kani with
//! symbolic inputs; the `#[test]` of the same name runs it on biased pseudo-random inputs and checks
//! that every `cover!` fired, so the twin is not vacuous either.

use crate::harness::{arbitrary, Source};
use crate::ladder::{Estop, Event, Ladder, LATCHING};
use crate::types::{Drive, FaultFlags, Mode, RejectReason, Speed};
use crate::validate::validate;
use crate::{assume, cover, Config};

fn magnitude(s: Speed) -> Speed {
    s.saturating_abs()
}

fn valid_ladder(src: &mut impl Source) -> Option<Ladder> {
    let cfg = arbitrary::config(src)?;
    let l = arbitrary::ladder(src, cfg);
    if l.is_valid() {
        Some(l)
    } else {
        None
    }
}

/// INV-0 (base): the power-on state satisfies the invariant and is braked.
pub fn initial_state_is_valid(src: &mut impl Source) {
    let cfg = arbitrary::config(src);
    assume!(src, cfg.is_some());
    let Some(cfg) = cfg else { return };
    let mut l = Ladder::new(cfg);
    assert!(l.is_valid());
    assert_eq!(l.output().drive, Drive::Brake);
    assert!(l.output().faults.contains(FaultFlags::POWER_ON));
    cover!(src, cfg != Config::DEFAULT, "a non-default configuration");
    let out = l.step(Event::Tick);
    assert_eq!(out.drive, Drive::Brake);
}

/// INV-0 (step), INV-2, INV-9: every event from every valid state keeps the invariant, never panics
/// or overflows, and a late link is never NORMAL or REDUCED.
pub fn step_preserves_invariant(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let e = arbitrary::event(src);
    let mut l = l0;
    let out = l.step(e);
    assert!(l.is_valid());
    assert_eq!(out, l.output());
    let p = l.config().params();
    if out.age >= p.hold_after {
        assert!(!matches!(out.mode, Mode::Normal | Mode::Reduced));
    }
    cover!(
        src,
        l0.mode == Mode::Normal && out.mode == Mode::Hold,
        "NORMAL -> HOLD"
    );
    cover!(
        src,
        l0.mode == Mode::Hold && out.mode == Mode::Stop,
        "HOLD -> STOP"
    );
    cover!(
        src,
        l0.mode == Mode::Stop && out.mode == Mode::Brake,
        "STOP -> BRAKE"
    );
    cover!(
        src,
        l0.mode == Mode::Normal && out.mode == Mode::Reduced,
        "NORMAL -> REDUCED"
    );
    cover!(
        src,
        l0.mode == Mode::Reduced && out.mode == Mode::Normal,
        "REDUCED -> NORMAL"
    );
    cover!(
        src,
        l0.mode == Mode::Brake && out.mode != Mode::Brake,
        "BRAKE released"
    );
    cover!(
        src,
        matches!(e, Event::Frame(_)) && l.counters().valid_frames != l0.counters().valid_frames,
        "valid frame"
    );
}

/// INV-1: with no valid frame, BRAKE is reached at the `brake_after`-th tick (≤ 10) from any valid
/// state, whatever else happens between the ticks.
pub fn comm_loss_brakes_within_brake_after_ticks(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(mut l) = l0 else { return };
    let start = l.mode();
    let brake_after = l.config().params().brake_after;
    assert!(brake_after <= crate::config::MAX_BRAKE_AFTER);
    let mut braked_at = None;
    for k in 1..=crate::config::MAX_BRAKE_AFTER {
        if k > brake_after {
            break;
        }
        if src.bool() {
            l.step(arbitrary::event_without_valid_frame(src));
        }
        let out = l.step(Event::Tick);
        if out.mode == Mode::Brake && braked_at.is_none() {
            braked_at = Some(k);
        }
        if k == brake_after {
            assert_eq!(out.mode, Mode::Brake);
            assert_eq!(out.drive, Drive::Brake);
        }
    }
    cover!(src, start == Mode::Normal, "from NORMAL");
    cover!(src, start == Mode::Reduced, "from REDUCED");
    cover!(src, start == Mode::Hold, "from HOLD");
    cover!(src, start == Mode::Stop, "from STOP");
    cover!(
        src,
        start != Mode::Brake && braked_at == Some(brake_after),
        "brakes exactly at the threshold"
    );
}

/// INV-3: the applied speed stays within ±v_max, and above the rung's limit only while falling.
pub fn applied_speed_within_mode_limit(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let mut l = l0;
    let e = if src.bool() {
        Event::Tick
    } else {
        arbitrary::event(src)
    };
    let out = l.step(e);
    let p = *l.config().params();
    let ticked = e == Event::Tick;
    for (a0, a1) in l0.applied().into_iter().zip(l.applied()) {
        let (m0, m1) = (magnitude(a0), magnitude(a1));
        assert!(m1 <= p.v_max);
        match out.mode {
            Mode::Normal => {}
            // Ramping down toward the reduced limit; between ticks the setpoint does not move.
            Mode::Reduced => assert!(m1 <= p.reduced_limit || m1 < m0 || (!ticked && m1 == m0)),
            Mode::Hold | Mode::Stop => {
                assert!(m1 <= m0);
                assert!(a1 == Speed::ZERO || (a1 > Speed::ZERO) == (a0 > Speed::ZERO));
            }
            Mode::Brake => assert_eq!(a1, Speed::ZERO),
        }
    }
    cover!(
        src,
        out.mode == Mode::Reduced && magnitude(l.applied()[0]) > p.reduced_limit,
        "REDUCED while ramping down"
    );
    cover!(
        src,
        out.mode == Mode::Stop && l.applied()[0] != Speed::ZERO,
        "STOP while moving"
    );
    cover!(
        src,
        out.mode == Mode::Normal && magnitude(l.applied()[0]) > p.reduced_limit,
        "NORMAL above the reduced limit"
    );
}

/// INV-4: a refused frame (below the ladder or by validation) leaves the command, the watchdog and the
/// applied setpoint untouched.
pub fn rejected_frames_change_nothing_applied(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let e = if src.bool() {
        Event::Rejected(arbitrary::reason(src))
    } else {
        Event::Frame(arbitrary::command(src))
    };
    let mut l = l0;
    let out = l.step(e);
    let refused = l.counters().rejected_total() != l0.counters().rejected_total()
        || matches!(e, Event::Rejected(_));
    if refused {
        assert_eq!(l.applied(), l0.applied());
        assert_eq!(l.last_valid(), l0.last_valid());
        assert_eq!(l.age(), l0.age());
        assert_eq!(l.prev_enable, l0.prev_enable);
        assert_eq!(l.mode(), l0.mode());
        assert_eq!(out.drive, l0.output().drive);
        assert_eq!(l.counters().valid_frames, l0.counters().valid_frames);
    }
    let grew = |r: RejectReason| l.counters().rejected(r) != l0.counters().rejected(r);
    cover!(src, grew(RejectReason::NonFinite), "refused: non-finite");
    cover!(src, grew(RejectReason::OutOfRange), "refused: out of range");
    cover!(
        src,
        grew(RejectReason::UnknownMode),
        "refused: unknown mode"
    );
    cover!(
        src,
        grew(RejectReason::Acceleration),
        "refused: acceleration"
    );
    cover!(src, grew(RejectReason::Stale), "refused: stale");
    cover!(src, grew(RejectReason::Crc), "refused: CRC");
    cover!(
        src,
        !refused && l.last_valid() != l0.last_valid(),
        "accepted frame changes the command"
    );
}

/// INV-5: validation never lets a NaN or infinity through, and what it accepts is in range and equals
/// the sent value to within the Q16.16 rounding.
pub fn validated_setpoints_are_finite_and_in_range(src: &mut impl Source) {
    let cfg = arbitrary::config(src);
    assume!(src, cfg.is_some());
    let Some(cfg) = cfg else { return };
    let cmd = arbitrary::command(src);
    let last = if src.bool() {
        Some(arbitrary::setpoint(src, &cfg))
    } else {
        None
    };
    let allowance = src.speed_within(cfg.params().v_max);
    let r = validate(&cmd, last.as_ref(), allowance, &cfg);
    let v = cfg.params().v_max;
    let half_lsb = 1.0 / 131_072.0;
    if let Ok(sp) = r {
        assert!(cmd.left.is_finite() && cmd.right.is_finite());
        for (s, x) in [(sp.left, cmd.left), (sp.right, cmd.right)] {
            assert!(s <= v && s >= -v);
            let err = s.to_num::<f64>() - f64::from(x);
            assert!((-half_lsb..=half_lsb).contains(&err));
        }
    }
    if cmd.left.is_nan() || cmd.right.is_infinite() {
        assert!(r.is_err());
    }
    cover!(
        src,
        r.is_ok() && cmd.left < 0.0,
        "accepted a negative speed"
    );
    cover!(
        src,
        r.is_ok() && sp_at_limit(&r, v),
        "accepted exactly v_max"
    );
    cover!(
        src,
        cmd.left.is_nan() && r == Err(RejectReason::NonFinite),
        "refused NaN"
    );
}

fn sp_at_limit(r: &Result<crate::Setpoint, RejectReason>, v: Speed) -> bool {
    matches!(r, Ok(sp) if sp.left == v || sp.left == -v)
}

/// INV-6: BRAKE is left only at a tick, after an explicit re-arm (a `Rearm` event or an enable 0→1
/// edge), with a fresh valid frame and no latching cause active; ESTOP is cleared only by `Release`.
pub fn brake_left_only_by_rearm_and_fresh_frames(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let e = arbitrary::event(src);
    let mut l = l0;
    l.step(e);
    if l0.brake_latched() && !l.brake_latched() {
        assert_eq!(e, Event::Tick);
        // The re-arm was pending and a valid frame came after the previous tick.
        assert!(l0.rearm_pending && l0.age() == 0);
        assert!(!l0.active.intersects(LATCHING));
        assert!(matches!(l.last_valid(), Some(sp) if sp.enable));
    }
    if !l0.rearm_pending && l.rearm_pending {
        let edge = matches!(e, Event::Frame(c) if c.enable) && !l0.prev_enable;
        assert!(e == Event::Rearm || edge);
    }
    if l0.active.contains(FaultFlags::ESTOP) && e != Event::Estop(Estop::Release) {
        assert!(l.active.contains(FaultFlags::ESTOP));
        assert!(l.brake_latched());
    }
    cover!(
        src,
        l0.brake_latched() && !l.brake_latched(),
        "BRAKE released by a re-arm"
    );
    cover!(
        src,
        !l0.rearm_pending && l.rearm_pending && e != Event::Rearm,
        "re-arm by enable edge"
    );
    cover!(
        src,
        l0.active.contains(FaultFlags::ESTOP) && !l.active.contains(FaultFlags::ESTOP),
        "ESTOP released"
    );
}

/// INV-7: overcurrent, overtemperature, encoder failure, undervoltage, the shutdown bit and ESTOP turn
/// the PWM off in the same step, from any state.
pub fn latching_faults_cut_pwm_in_same_step(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(mut l) = l0 else { return };
    let e = match src.below(3) {
        0 => {
            let c = arbitrary::condition(src);
            assume!(src, c.brakes());
            Event::Condition {
                condition: c,
                active: true,
            }
        }
        1 => Event::Shutdown(true),
        _ => Event::Estop(Estop::Engage),
    };
    let was_running = matches!(l.output().drive, Drive::Run { .. });
    let out = l.step(e);
    assert_eq!(out.drive, Drive::Brake);
    assert_eq!(out.mode, Mode::Brake);
    cover!(
        src,
        was_running && matches!(e, Event::Condition { .. }),
        "condition stops a running drive"
    );
    cover!(
        src,
        was_running && e == Event::Shutdown(true),
        "shutdown stops a running drive"
    );
    cover!(
        src,
        was_running && e == Event::Estop(Estop::Engage),
        "ESTOP stops a running drive"
    );
}

/// INV-8: outside BRAKE the setpoint moves at most `max_tick_step` per tick, and only at a tick.
pub fn setpoint_step_is_bounded(src: &mut impl Source) {
    let l0 = valid_ladder(src);
    assume!(src, l0.is_some());
    let Some(l0) = l0 else { return };
    let e = if src.bool() {
        Event::Tick
    } else {
        arbitrary::event(src)
    };
    let mut l = l0;
    let out = l.step(e);
    let bound = l.config().max_tick_step();
    if e != Event::Tick {
        assert!(l.applied() == l0.applied() || out.mode == Mode::Brake);
    }
    if l0.mode() != Mode::Brake && out.mode != Mode::Brake {
        for (a0, a1) in l0.applied().into_iter().zip(l.applied()) {
            let d = a1.saturating_sub(a0);
            assert!(d <= bound && d >= -bound);
        }
    }
    cover!(
        src,
        e == Event::Tick && out.mode != Mode::Brake && l.applied() != l0.applied(),
        "setpoint moved"
    );
    cover!(
        src,
        out.mode == Mode::Normal
            && l.applied()[0].saturating_sub(l0.applied()[0]) == l.config().params().accel_step,
        "full acceleration step"
    );
}

/// INV-1 cross-check on genuinely reachable states: from power-on, after any short event sequence,
/// ten ticks without a valid frame end in BRAKE.
pub fn comm_loss_brakes_after_any_prefix(src: &mut impl Source) {
    // Speeds from a short table: this harness is about reachable sequences (arming, ramping, refusals),
    // and concrete speeds keep the solver away from symbolic float conversions; INV-5 covers all floats.
    const SPEEDS: [f32; 4] = [0.0, 0.04, -0.04, 0.5];
    let mut l = Ladder::new(Config::DEFAULT);
    let mut seen_running = false;
    for _ in 0..5 {
        let e = match src.below(4) {
            0 => Event::Tick,
            1 => Event::Frame(crate::Command {
                left: SPEEDS
                    .get(usize::from(src.below(4)))
                    .copied()
                    .unwrap_or(0.0),
                right: SPEEDS
                    .get(usize::from(src.below(4)))
                    .copied()
                    .unwrap_or(0.0),
                mode: 1,
                enable: src.bool(),
                seq: None,
            }),
            2 => Event::Rejected(arbitrary::reason(src)),
            _ => Event::Rearm,
        };
        let out = l.step(e);
        seen_running |= matches!(out.mode, Mode::Normal | Mode::Reduced);
    }
    for _ in 0..10 {
        l.step(Event::Tick);
    }
    assert_eq!(l.output().drive, Drive::Brake);
    cover!(
        src,
        seen_running,
        "drive was armed and running before the loss"
    );
}

#[cfg(kani)]
mod kani_entry {
    use super::*;
    use crate::harness::KaniSource;

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_initial_state_is_valid() {
        initial_state_is_valid(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_step_preserves_invariant() {
        step_preserves_invariant(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_comm_loss_brakes_within_brake_after_ticks() {
        comm_loss_brakes_within_brake_after_ticks(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_applied_speed_within_mode_limit() {
        applied_speed_within_mode_limit(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_rejected_frames_change_nothing_applied() {
        rejected_frames_change_nothing_applied(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_validated_setpoints_are_finite_and_in_range() {
        validated_setpoints_are_finite_and_in_range(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_brake_left_only_by_rearm_and_fresh_frames() {
        brake_left_only_by_rearm_and_fresh_frames(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_latching_faults_cut_pwm_in_same_step() {
        latching_faults_cut_pwm_in_same_step(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_setpoint_step_is_bounded() {
        setpoint_step_is_bounded(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(13)]
    fn verify_comm_loss_brakes_after_any_prefix() {
        comm_loss_brakes_after_any_prefix(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use crate::harness::Twin;

    const CASES: u32 = 200_000;

    #[test]
    fn initial_state_is_valid() {
        Twin::run(1, 2_000, super::initial_state_is_valid).assert_covered(1);
    }

    #[test]
    fn step_preserves_invariant() {
        Twin::run(2, CASES * 5, super::step_preserves_invariant).assert_covered(7);
    }

    #[test]
    fn comm_loss_brakes_within_brake_after_ticks() {
        Twin::run(3, CASES, |s| {
            super::comm_loss_brakes_within_brake_after_ticks(s)
        })
        .assert_covered(5);
    }

    #[test]
    fn applied_speed_within_mode_limit() {
        Twin::run(4, CASES, super::applied_speed_within_mode_limit).assert_covered(3);
    }

    #[test]
    fn rejected_frames_change_nothing_applied() {
        Twin::run(5, CASES, |s| {
            super::rejected_frames_change_nothing_applied(s)
        })
        .assert_covered(7);
    }

    #[test]
    fn validated_setpoints_are_finite_and_in_range() {
        Twin::run(6, CASES, |s| {
            super::validated_setpoints_are_finite_and_in_range(s)
        })
        .assert_covered(3);
    }

    #[test]
    fn brake_left_only_by_rearm_and_fresh_frames() {
        Twin::run(7, CASES * 5, |s| {
            super::brake_left_only_by_rearm_and_fresh_frames(s)
        })
        .assert_covered(3);
    }

    #[test]
    fn latching_faults_cut_pwm_in_same_step() {
        Twin::run(8, CASES, super::latching_faults_cut_pwm_in_same_step).assert_covered(3);
    }

    #[test]
    fn setpoint_step_is_bounded() {
        Twin::run(9, CASES, super::setpoint_step_is_bounded).assert_covered(2);
    }

    #[test]
    fn comm_loss_brakes_after_any_prefix() {
        Twin::run(10, CASES, super::comm_loss_brakes_after_any_prefix).assert_covered(1);
    }
}
