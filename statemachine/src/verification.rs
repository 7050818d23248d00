//! Kani harnesses of the ladder invariants (INV-n, `proofs/SAFETY.md`) and their `cargo test` twins.
//!
//! Each property is one body generic over [`Source`] and the axis count `N`: `verify_<property>_<N>`
//! runs it under Kani with symbolic inputs for N = 2 and N = 4; the `#[test]` of the same name runs it
//! on biased pseudo-random inputs and checks that every `cover!` fired, so the twin is not vacuous either.
//! Configurations are any that [`Config::new`] accepts, the four shipped profiles half the time.

// Under Kani the one-step bodies and their event generators are proven together by
// `one_step_properties`; as far as rustc can see, only their twins call them (the test build
// still reports dead code).
#![cfg_attr(kani, allow(dead_code))]

use crate::harness::{arbitrary, Source};
use crate::ladder::{Estop, Event, Ladder, Source as Origin, LATCHING};
use crate::types::{AxisDrive, AxisMode, Drive, FaultFlags, Mode, RejectReason, Speed};
use crate::validate::validate_into;
use crate::{assume, check, cover, Config};

fn magnitude(s: Speed) -> Speed {
    s.saturating_abs()
}

/// One step from a valid state: the state before, the event, the state after and the output.
#[derive(Clone, Copy)]
struct Step<const N: usize> {
    l0: Ladder<N>,
    e: Event<N>,
    l: Ladder<N>,
    out: crate::Output<N>,
}

impl<const N: usize> Step<N> {
    /// A one-step body: draws a configuration and a ladder (states that are not valid assumed
    /// away), steps it with the event `event` draws and runs `checks` on the step. The parts are
    /// built in place, not passed through `Option`s: under Kani each copy of a ladder is a
    /// whole-state assignment in every cover's trace (about two fifths of a one-step harness's
    /// trace, whose building and printing is a third of its time: `proofs/REPORT.md`).
    fn run<S: Source>(
        src: &mut S,
        event: impl FnOnce(&mut S) -> Event<N>,
        checks: impl FnOnce(&mut S, &Self),
    ) {
        let cfg = arbitrary::config(src);
        assume!(src, cfg.is_some());
        let Some(cfg) = cfg else { return };
        let l0 = arbitrary::ladder::<N>(src, cfg);
        assume!(src, l0.is_valid());
        let e = event(src);
        let mut l = l0;
        let out = l.step(e);
        checks(src, &Self { l0, e, l, out });
    }
}

/// A tick half the time, otherwise any event (the twins meet ticks often; under Kani every event).
fn tick_or_any<const N: usize>(src: &mut impl Source) -> Event<N> {
    if src.bool() {
        Event::Tick
    } else {
        arbitrary::event(src)
    }
}

/// INV-18's events: a tick half the time, otherwise any event with frames made unvalidatable (a
/// zero timeout).
fn tick_or_no_valid_frame<const N: usize>(src: &mut impl Source) -> Event<N> {
    if src.bool() {
        Event::Tick
    } else {
        arbitrary::event_without_valid_frame(src)
    }
}

/// Whether `e` is one of [`tick_or_no_valid_frame`]'s events: no frame that could validate.
fn no_valid_frame<const N: usize>(e: &Event<N>) -> bool {
    match e {
        Event::Frame(c) => c.timeout == Some(0),
        _ => true,
    }
}

/// INV-4's events: a refusal below the ladder (any reason) or a frame (any command bits).
fn refusal_or_frame<const N: usize>(src: &mut impl Source) -> Event<N> {
    if src.bool() {
        Event::Rejected(arbitrary::reason(src))
    } else {
        Event::Frame(arbitrary::command(src))
    }
}

/// INV-7's events: a braking condition becoming active, the shutdown bit, ESTOP from any source.
fn latching_event<const N: usize>(src: &mut impl Source) -> Event<N> {
    match src.below(3) {
        // A condition that does not brake stands in for the shutdown bit (already one of these events).
        0 => match arbitrary::condition(src) {
            c if c.brakes() => Event::Condition {
                condition: c,
                active: true,
            },
            _ => Event::Shutdown(true),
        },
        1 => Event::Shutdown(true),
        _ => Event::Estop {
            source: arbitrary::origin(src),
            action: Estop::Engage,
        },
    }
}

/// Whether `e` is one of [`latching_event`]'s events.
fn is_latching_event<const N: usize>(e: &Event<N>) -> bool {
    match e {
        Event::Condition {
            condition,
            active: true,
        } => condition.brakes(),
        Event::Shutdown(true) => true,
        Event::Estop { action, .. } => *action == Estop::Engage,
        _ => false,
    }
}

/// INV-0 (base): the power-on state satisfies the invariant and is braked.
pub fn initial_state_is_valid<const N: usize>(src: &mut impl Source) {
    let cfg = arbitrary::config(src);
    assume!(src, cfg.is_some());
    let Some(cfg) = cfg else { return };
    let mut l = Ladder::<N>::new(cfg);
    check!(l.is_valid(), "INV-0: the power-on state is valid");
    check!(
        l.output().drive == Drive::Brake,
        "INV-0: the power-on state is BRAKE"
    );
    check!(
        l.output().faults.contains(FaultFlags::POWER_ON),
        "INV-0: the power-on state reports POWER_ON"
    );
    cover!(src, !cfg.is_1khz(), "a profile slower than 1 kHz");
    let out = l.step(Event::Tick);
    check!(out.drive == Drive::Brake, "INV-0: ticks alone never arm");
}

/// INV-0 (step), INV-2, INV-9: every event from every valid state keeps the invariant, never panics
/// or overflows, and a late link is never NORMAL or REDUCED.
pub fn step_preserves_invariant<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(src, |s| arbitrary::event(s), |s, st| invariant_kept(s, st));
}

fn invariant_kept<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l0 = &s.l0;
    let l = &s.l;
    check!(l.is_valid(), "INV-0: step preserves the invariant");
    check!(out == l.output(), "INV-0: step returns the state's output");
    let p = l.config().params();
    if out.age >= p.hold_after {
        check!(
            !matches!(out.mode, Mode::Normal | Mode::Reduced),
            "INV-2: a late link is never NORMAL or REDUCED"
        );
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
    cover!(
        src,
        l.axis_modes() != l0.axis_modes() && out.mode != Mode::Brake,
        "an axis changes mode"
    );
}

/// INV-1 (unrolled, thresholds ≤ 9): with no valid frame, BRAKE is reached at the threshold in force
/// from any valid state, whatever else happens between the ticks. Under Kani on the 1 kHz profile
/// (seed 000's, the one whose whole horizon is ≤ 9 ticks; every profile's bound is INV-18's
/// induction), in the twins on any configuration.
pub fn comm_loss_brakes_within_brake_after_ticks<const N: usize>(src: &mut impl Source) {
    let cfg = if cfg!(kani) {
        Some(crate::Config::AMR_SPI)
    } else {
        arbitrary::config(src)
    };
    assume!(src, cfg.is_some());
    let Some(cfg) = cfg else { return };
    let l0 = arbitrary::ladder::<N>(src, cfg);
    assume!(src, l0.is_valid());
    let mut l = l0;
    let start = l.mode();
    let brake_after = l.brake_after();
    assume!(src, brake_after <= crate::config::MAX_BRAKE_AFTER_1KHZ);
    let mut braked_at = None;
    for k in 1..=crate::config::MAX_BRAKE_AFTER_1KHZ {
        if k > brake_after {
            break;
        }
        // The twins put any non-frame event between the ticks; under Kani the ticks run back to
        // back, since what the other events may do between them is INV-18's (one step, any event),
        // and unrolled nine times over every event the proof took ten minutes.
        if !cfg!(kani) && src.bool() {
            l.step(arbitrary::event_without_valid_frame(src));
        }
        let out = l.step(Event::Tick);
        if out.mode == Mode::Brake && braked_at.is_none() {
            braked_at = Some(k);
        }
        if k == brake_after {
            check!(
                out.mode == Mode::Brake && out.drive == Drive::Brake,
                "INV-1: comm loss brakes at the threshold"
            );
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

/// INV-18 (the induction step of INV-1 for every profile): an event that is not a valid frame never
/// lowers the age, never raises the threshold in force, and a tick adds exactly one to the age; at
/// the threshold the drive is BRAKE. With INV-0's clause "unlatched ⇒ age < threshold ≤ the
/// profile's `brake_after`", BRAKE comes at the latest at the `brake_after`-th tick after the last
/// valid frame, for every profile (SAFETY.md §4, the induction argument).
pub fn comm_loss_age_advances<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(
        src,
        |s| tick_or_no_valid_frame(s),
        |s, st| age_advances(s, st),
    );
}

fn age_advances<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l0 = &s.l0;
    let l = &s.l;
    if !no_valid_frame(&e) {
        return;
    }
    check!(
        l.brake_after() <= l0.brake_after()
            || l.counters().valid_frames != l0.counters().valid_frames,
        "INV-18: only a valid frame changes the threshold"
    );
    check!(
        l.brake_after() <= l.config().params().brake_after,
        "INV-18: the threshold never exceeds the profile's brake_after"
    );
    check!(
        l.counters().valid_frames == l0.counters().valid_frames,
        "INV-18: an event without a valid frame validates nothing"
    );
    if e == Event::Tick {
        check!(
            l.age() == l0.age().saturating_add(1),
            "INV-18: a tick adds one to the age"
        );
        if l.age() >= l.brake_after() {
            check!(
                out.drive == Drive::Brake,
                "INV-18: at the threshold the drive is BRAKE"
            );
        }
    } else {
        check!(l.age() == l0.age(), "INV-18: only ticks move the age");
    }
    cover!(
        src,
        e == Event::Tick && l0.mode != Mode::Brake && out.mode == Mode::Brake,
        "a tick reaches the threshold"
    );
    cover!(
        src,
        l0.brake_after() > crate::config::MAX_BRAKE_AFTER_1KHZ && l0.mode != Mode::Brake,
        "a long threshold (50 Hz profile)"
    );
    cover!(
        src,
        l0.brake_after() < l.config().params().brake_after && l0.mode != Mode::Brake,
        "a frame's own timeout in force"
    );
}

/// INV-3, INV-16: velocity and position caps stay within v_max, duties within duty_max; above the
/// rung's limit only while falling; in HOLD and STOP every value falls toward zero without changing
/// sign; in BRAKE every value is zero.
pub fn applied_within_mode_limit<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(src, |s| tick_or_any(s), |s, st| within_mode_limit(s, st));
}

fn within_mode_limit<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l0 = &s.l0;
    let l = &s.l;
    let p = *l.config().params();
    let ticked = e == Event::Tick;
    let modes = l.axis_modes();
    let (applied0, applied) = (l0.applied(), l.applied());
    for i in 0..N {
        let (a0, a1, m) = (applied0[i], applied[i], modes[i]);
        let (m0, m1) = (magnitude(a0), magnitude(a1));
        let (full, reduced) = if m == AxisMode::Duty {
            (p.duty_max, p.duty_reduced)
        } else {
            (p.v_max, p.reduced_limit)
        };
        check!(
            m1 <= full,
            "INV-3/INV-16: |applied| within the mode's limit"
        );
        match out.mode {
            Mode::Normal => {}
            // Ramping down toward the reduced limit; between ticks the setpoint does not move.
            Mode::Reduced => check!(
                m1 <= reduced || m1 < m0 || (!ticked && m1 == m0),
                "INV-3/INV-16: REDUCED above its limit only while falling"
            ),
            Mode::Hold | Mode::Stop => {
                check!(m1 <= m0, "INV-3: HOLD and STOP never speed up");
                check!(
                    a1 == Speed::ZERO || (a1 > Speed::ZERO) == (a0 > Speed::ZERO),
                    "INV-3: HOLD and STOP never reverse"
                );
            }
            Mode::Brake => check!(a1 == Speed::ZERO, "INV-3: BRAKE applies nothing"),
        }
    }
    let any = |f: &dyn Fn(AxisMode, Speed) -> bool| (0..N).any(|i| f(modes[i], applied[i]));
    cover!(
        src,
        out.mode == Mode::Reduced
            && any(&|m, a| m == AxisMode::Velocity && magnitude(a) > p.reduced_limit),
        "REDUCED while ramping a speed down"
    );
    cover!(
        src,
        out.mode == Mode::Stop && any(&|m, a| m == AxisMode::Velocity && a != Speed::ZERO),
        "STOP while moving"
    );
    cover!(
        src,
        out.mode == Mode::Normal
            && any(&|m, a| m == AxisMode::Duty && magnitude(a) > p.duty_reduced),
        "NORMAL duty above the reduced duty"
    );
    cover!(
        src,
        out.mode == Mode::Hold && any(&|m, a| m == AxisMode::Position && a != Speed::ZERO),
        "HOLD while a position cap falls"
    );
}

/// INV-4: a refused frame (below the ladder or by validation) leaves the command, the watchdog and the
/// applied setpoints untouched.
pub fn rejected_frames_change_nothing_applied<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(
        src,
        |s| refusal_or_frame(s),
        |s, st| refusal_changes_nothing(s, st),
    );
}

fn refusal_changes_nothing<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l0 = &s.l0;
    let l = &s.l;
    if !matches!(e, Event::Rejected(_) | Event::Frame(_)) {
        return;
    }
    let refused = l.counters().rejected_total() != l0.counters().rejected_total()
        || matches!(e, Event::Rejected(_));
    if refused {
        check!(
            l.applied() == l0.applied()
                && l.axis_modes() == l0.axis_modes()
                && l.last_valid() == l0.last_valid()
                && l.age() == l0.age()
                && l.brake_after() == l0.brake_after()
                && l.prev_enable == l0.prev_enable
                && l.mode() == l0.mode()
                && out.drive == l0.output().drive
                && l.counters().valid_frames == l0.counters().valid_frames,
            "INV-4: a refused frame changes nothing applied"
        );
    }
    // Per reason, not as a total: the saturating sum of seven counters made the proof 13 times slower.
    if let Event::Rejected(r) = e {
        for q in RejectReason::ALL {
            let before = l0.counters().rejected(q);
            let want = if q == r {
                before.saturating_add(1)
            } else {
                before
            };
            check!(
                l.counters().rejected(q) == want,
                "INV-4: a refusal below the ladder adds exactly one to its reason's count"
            );
        }
    }
    let grew = |r: RejectReason| l.counters().rejected(r) != l0.counters().rejected(r);
    cover!(src, grew(RejectReason::NonFinite), "refused: non-finite");
    cover!(src, grew(RejectReason::OutOfRange), "refused: out of range");
    cover!(
        src,
        grew(RejectReason::UnsupportedMode),
        "refused: mode not in the profile"
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

/// INV-5, INV-15: validation never lets a NaN or infinity through; what it accepts is within its
/// mode's range (±v_max, ±duty_max, a position within the travel, a cap within 0 ..= v_max), in a mode
/// the profile accepts, and equals the sent value to within the Q16.16 rounding.
pub fn validated_setpoints_are_finite_and_in_range<const N: usize>(src: &mut impl Source) {
    let cfg = arbitrary::config(src);
    assume!(src, cfg.is_some());
    let Some(cfg) = cfg else { return };
    let cmd = arbitrary::command::<N>(src);
    let last0 = arbitrary::setpoint::<N>(src, &cfg);
    let has_last = src.bool();
    let p = *cfg.params();
    let allowance = src.speed_within(p.v_max);
    let mut sp = last0;
    let r = validate_into(&cmd, &mut sp, has_last, allowance, &cfg);
    if r.is_err() {
        check!(
            sp == last0,
            "INV-4: a refused command leaves the last setpoint as it was"
        );
    }
    let r = r.map(|()| sp);
    let half_lsb = 1.0 / 131_072.0;
    let close = |s: Speed, x: f32| {
        let err = s.to_num::<f64>() - f64::from(x);
        (-half_lsb..=half_lsb).contains(&err)
    };
    let within = |s: Speed, lo: Speed, hi: Speed| s >= lo && s <= hi;
    if let Ok(sp) = r {
        for i in 0..N {
            let (a, c) = (&sp.axes[i], &cmd.axes[i]);
            check!(a.mode == c.mode, "INV-5: the mode is the one sent");
            check!(
                p.modes.contains(a.mode),
                "INV-5: only the profile's modes are accepted"
            );
            let ok = match a.mode {
                AxisMode::Coast | AxisMode::Short => {
                    a.target == Speed::ZERO && a.cap == Speed::ZERO
                }
                AxisMode::Duty => {
                    c.target.is_finite()
                        && within(a.target, -p.duty_max, p.duty_max)
                        && close(a.target, c.target)
                }
                AxisMode::Velocity => {
                    c.target.is_finite()
                        && within(a.target, -p.v_max, p.v_max)
                        && close(a.target, c.target)
                }
                AxisMode::Position => {
                    c.target.is_finite()
                        && c.cap.is_finite()
                        && within(a.target, p.travel_lo, p.travel_hi)
                        && within(a.cap, Speed::ZERO, p.v_max)
                        && close(a.target, c.target)
                        && close(a.cap, c.cap)
                }
            };
            check!(
                ok,
                "INV-5/INV-15: an accepted target is finite, in its mode's range and as sent"
            );
        }
        check!(
            sp.brake_after >= 1 && sp.brake_after <= p.brake_after,
            "INV-18: a frame's threshold is 1 ..= the profile's brake_after"
        );
        let want = match cmd.timeout {
            Some(t) if t < p.brake_after => t,
            _ => p.brake_after,
        };
        check!(
            sp.brake_after == want && cmd.timeout != Some(0),
            "INV-18: a frame's threshold is its timeout capped by brake_after; zero is refused"
        );
        check!(
            sp.enable == cmd.enable && sp.seq() == cmd.seq,
            "INV-5: enable and sequence number as sent"
        );
    }
    let first = cmd.axes.first().copied();
    let nan_driving = first.is_some_and(|a| !a.mode.is_passive() && a.target.is_nan());
    if nan_driving {
        check!(r.is_err(), "INV-5: a NaN target is always refused");
    }
    cover!(
        src,
        r.is_ok() && first.is_some_and(|a| a.mode == AxisMode::Velocity && a.target < 0.0),
        "accepted a negative speed"
    );
    cover!(
        src,
        matches!(r, Ok(sp) if sp.axes.first().is_some_and(|a| a.mode == AxisMode::Position && a.cap > Speed::ZERO)),
        "accepted a position target under a cap"
    );
    cover!(
        src,
        nan_driving && r == Err(RejectReason::NonFinite),
        "refused NaN"
    );
    cover!(
        src,
        first.is_some_and(|a| a.mode == AxisMode::Position) && r == Err(RejectReason::OutOfRange),
        "refused a position beyond the travel"
    );
}

/// INV-6, INV-14: BRAKE is left only at a tick, after an explicit re-arm (a `Rearm` event or an
/// enable 0→1 edge), with a fresh valid frame and no latching cause active. ESTOP belongs to the
/// sources that engaged it: it is released only by one of them or by the local input, never by
/// another link; after an ESTOP latch a re-arm counts only from the source that released it.
pub fn brake_left_only_by_rearm_and_fresh_frames<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(
        src,
        |s| arbitrary::event(s),
        |s, st| brake_left_only_by_rearm(s, st),
    );
}

fn brake_left_only_by_rearm<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, .. } = *s;
    let l0 = &s.l0;
    let l = &s.l;
    if l0.brake_latched() && !l.brake_latched() {
        check!(e == Event::Tick, "INV-6: BRAKE is left only at a tick");
        check!(
            l0.rearm_pending && l0.age() == 0,
            "INV-6: BRAKE is left only with a re-arm and a fresh frame"
        );
        check!(
            !l0.active.intersects(LATCHING),
            "INV-6: BRAKE is left only with no latching cause"
        );
        check!(
            matches!(l.last_valid(), Some(sp) if sp.enable),
            "INV-6: BRAKE is left only for an enabled command"
        );
    }
    let edge = matches!(e, Event::Frame(c) if c.enable) && !l0.prev_enable;
    let requester = match e {
        Event::Rearm(s) => Some(s),
        _ if edge => Some(Origin::Primary),
        _ => None,
    };
    if !l0.rearm_pending && l.rearm_pending {
        check!(
            requester.is_some(),
            "INV-6: a re-arm is pending only by a request"
        );
        if l0.latch_causes.contains(FaultFlags::ESTOP) {
            check!(
                l0.estop_released_by == Some(Origin::Local) || l0.estop_released_by == requester,
                "INV-14: after ESTOP only the releasing source re-arms"
            );
        }
    }
    // Every source that held ESTOP still holds it, unless it released or the local input did.
    for s in Origin::ALL {
        let released = matches!(e, Event::Estop { source, action: Estop::Release } if source == s || source == Origin::Local);
        if l0.estop_owners() & s.bit() != 0 && !released {
            check!(
                l.estop_owners() & s.bit() != 0,
                "INV-14: ESTOP is released only by its owner or the local input"
            );
        }
    }
    if l0.active.contains(FaultFlags::ESTOP) {
        check!(l.brake_latched(), "INV-6: ESTOP keeps BRAKE latched");
        if !matches!(
            e,
            Event::Estop {
                action: Estop::Release,
                ..
            }
        ) {
            check!(
                l.active.contains(FaultFlags::ESTOP),
                "INV-6: the ESTOP flag is cleared only by a release"
            );
        }
    }
    cover!(
        src,
        l0.brake_latched() && !l.brake_latched(),
        "BRAKE released by a re-arm"
    );
    cover!(
        src,
        !l0.rearm_pending && l.rearm_pending && requester == Some(Origin::Primary) && edge,
        "re-arm by enable edge"
    );
    cover!(
        src,
        l0.active.contains(FaultFlags::ESTOP) && !l.active.contains(FaultFlags::ESTOP),
        "ESTOP released"
    );
    cover!(
        src,
        l.counters().estop_release_refused != l0.counters().estop_release_refused,
        "another link's release refused"
    );
    cover!(
        src,
        l0.latch_causes.contains(FaultFlags::ESTOP)
            && !l0.active.intersects(LATCHING)
            && matches!(e, Event::Rearm(_))
            && !l.rearm_pending,
        "re-arm by a source that did not release refused"
    );
}

/// INV-7: overcurrent, overtemperature, encoder failure, undervoltage, the shutdown bit and ESTOP (from
/// any source) turn the PWM off in the same step, from any state.
pub fn latching_faults_cut_pwm_in_same_step<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(src, |s| latching_event(s), |s, st| latching_cuts_pwm(s, st));
}

fn latching_cuts_pwm<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l0 = &s.l0;
    if !is_latching_event(&e) {
        return;
    }
    let was_running = matches!(l0.output().drive, Drive::Run(_));
    check!(
        out.drive == Drive::Brake && out.mode == Mode::Brake,
        "INV-7: a latching fault brakes in the same step"
    );
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
        was_running && matches!(e, Event::Estop { .. }),
        "ESTOP stops a running drive"
    );
}

/// INV-8, INV-19: outside BRAKE, while an axis keeps its mode, its value moves at most
/// `max_tick_step` (speeds, caps) or `duty_step` (duties) per tick, and only at a tick; an axis
/// changes mode only from rest or into a passive mode.
pub fn setpoint_step_is_bounded<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(
        src,
        |s| tick_or_any(s),
        |s, st| setpoint_step_bounded(s, st),
    );
}

fn setpoint_step_bounded<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l0 = &s.l0;
    let l = &s.l;
    let p = *l.config().params();
    let bound = l.config().max_tick_step();
    if e != Event::Tick {
        check!(
            l.applied() == l0.applied() || out.mode == Mode::Brake,
            "INV-8: only ticks move the setpoints"
        );
        check!(
            l.axis_modes() == l0.axis_modes(),
            "INV-19: only ticks change an axis's mode"
        );
    }
    if l0.mode() != Mode::Brake && out.mode != Mode::Brake {
        let (applied0, applied, modes0, modes) =
            (l0.applied(), l.applied(), l0.axis_modes(), l.axis_modes());
        for i in 0..N {
            let (a0, a1, m0, m1) = (applied0[i], applied[i], modes0[i], modes[i]);
            if m0 == m1 {
                let step = if m1 == AxisMode::Duty {
                    p.duty_step
                } else {
                    bound
                };
                let d = a1.saturating_sub(a0);
                check!(
                    d <= step && d >= -step,
                    "INV-8: a setpoint moves at most one step per tick"
                );
            } else {
                check!(
                    a0 == Speed::ZERO || m1.is_passive(),
                    "INV-19: an axis changes mode only from rest or into a passive mode"
                );
            }
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
            && l0.axis_modes().first() == Some(&AxisMode::Velocity)
            && l.axis_modes().first() == Some(&AxisMode::Velocity)
            && l.applied()
                .first()
                .copied()
                .unwrap_or(Speed::ZERO)
                .saturating_sub(l0.applied().first().copied().unwrap_or(Speed::ZERO))
                == p.accel_step,
        "full acceleration step"
    );
    cover!(
        src,
        out.mode != Mode::Brake && l.axis_modes() != l0.axis_modes(),
        "an axis changes mode"
    );
}

/// INV-17, INV-15: outside BRAKE the drive each axis gets is its mode's: a passive command (coast,
/// short) never becomes drive, and a position axis's target is within the travel.
pub fn drive_follows_axis_modes<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(src, |s| tick_or_any(s), |s, st| drive_follows_modes(s, st));
}

fn drive_follows_modes<const N: usize>(src: &mut impl Source, s: &Step<N>) {
    let Step { e, out, .. } = *s;
    let l = &s.l;
    let p = *l.config().params();
    if let Drive::Run(axes) = out.drive {
        let wants = l.last_valid().map(|sp| sp.axes);
        let modes = l.axis_modes();
        for i in 0..N {
            let (d, m) = (&axes[i], modes[i]);
            let ok = match (m, d) {
                (AxisMode::Coast, AxisDrive::Coast) | (AxisMode::Short, AxisDrive::Short) => true,
                (AxisMode::Duty, AxisDrive::Duty(_))
                | (AxisMode::Velocity, AxisDrive::Velocity(_)) => true,
                (AxisMode::Position, AxisDrive::Position { target, cap }) => {
                    *target >= p.travel_lo && *target <= p.travel_hi && *cap >= Speed::ZERO
                }
                _ => false,
            };
            check!(
                ok,
                "INV-17/INV-15: each axis is driven in its own mode, positions within the travel"
            );
            // After a tick, an axis whose command is passive is driven passively.
            let want = wants.and_then(|w| w.get(i).copied());
            if e == Event::Tick {
                if let Some(w) = want {
                    if w.mode.is_passive() {
                        check!(
                            matches!(d, AxisDrive::Coast | AxisDrive::Short),
                            "INV-17: a coast or short request never becomes drive"
                        );
                    }
                }
            }
        }
        cover!(
            src,
            (0..N).any(|i| matches!(axes[i], AxisDrive::Coast)),
            "an axis coasts while others run"
        );
        cover!(
            src,
            (0..N).any(|i| matches!(axes[i], AxisDrive::Position { .. })),
            "a position axis runs"
        );
        cover!(
            src,
            (0..N).any(|i| matches!(axes[i], AxisDrive::Duty(_))),
            "a duty axis runs"
        );
    }
}

/// INV-0 (step), INV-2, INV-3, INV-4, INV-6, INV-7, INV-8, INV-9, INV-14, INV-15, INV-16, INV-17,
/// INV-18, INV-19: the checks of the eight one-step bodies above on one shared step, from any valid
/// state with any event. Each check applies where its body's events would (INV-18 to events with no
/// frame that could validate, INV-4 to refusals and frames, INV-7 to the latching events), so this
/// proves what the eight prove; under Kani the step is encoded and solved once instead of eight
/// times.
pub fn one_step_properties<const N: usize>(src: &mut impl Source) {
    Step::<N>::run(
        src,
        |s| tick_or_any(s),
        |s, st| {
            invariant_kept(s, st);
            age_advances(s, st);
            within_mode_limit(s, st);
            refusal_changes_nothing(s, st);
            brake_left_only_by_rearm(s, st);
            latching_cuts_pwm(s, st);
            setpoint_step_bounded(s, st);
            drive_follows_modes(s, st);
        },
    );
}

/// INV-1 cross-check on genuinely reachable states: from power-on, after any short event sequence,
/// the profile's `brake_after` ticks without a valid frame end in BRAKE (seed 000's profile). A twin
/// only: under Kani it is implied by `comm_loss_brakes_within_brake_after_ticks` (every valid state,
/// and every reachable state is valid by INV-0), and unrolled over 5 events and 9 ticks it took 247 s.
pub fn comm_loss_brakes_after_any_prefix<const N: usize>(src: &mut impl Source) {
    // Speeds from a short table: this harness is about reachable sequences (arming, ramping, refusals),
    // and concrete speeds keep the solver away from symbolic float conversions; INV-5 covers all floats.
    const SPEEDS: [f32; 4] = [0.0, 0.04, -0.04, 0.5];
    let cfg = Config::AMR_SPI;
    let mut l = Ladder::<N>::new(cfg);
    let mut seen_running = false;
    for _ in 0..5 {
        let e = match src.below(4) {
            0 => Event::Tick,
            1 => {
                let mut targets = [0.0f32; N];
                for t in targets.iter_mut() {
                    *t = SPEEDS
                        .get(usize::from(src.below(4)))
                        .copied()
                        .unwrap_or(0.0);
                }
                Event::Frame(crate::Command::velocity(targets, src.bool(), None))
            }
            2 => Event::Rejected(arbitrary::reason(src)),
            _ => Event::Rearm(Origin::Primary),
        };
        let out = l.step(e);
        seen_running |= matches!(out.mode, Mode::Normal | Mode::Reduced);
    }
    for _ in 0..cfg.params().brake_after {
        l.step(Event::Tick);
    }
    check!(
        l.output().drive == Drive::Brake,
        "INV-1: comm loss brakes after any reachable prefix"
    );
    cover!(
        src,
        seen_running,
        "drive was armed and running before the loss"
    );
}

/// The contract of [`validate_into`] that INV-5's harness proves (with INV-4's "a refusal writes
/// nothing", INV-15 and INV-18's clause on a frame's threshold), as a stub: any refusal, leaving the
/// last setpoint as it was, or a new setpoint with the command's modes (all accepted by the profile),
/// enable and sequence number, values anywhere in each mode's range, and exactly the threshold the
/// frame's timeout gives; a zero timeout is always refused. It does everything `validate_into` can do
/// (and more: any refusal at any time), so a ladder harness proven with it in place of
/// `validate_into` holds with the real one, and the ladder harnesses need no symbolic float
/// conversions, which INV-5's harness covers once.
// Referenced only by the `kani::stub` attributes, which rustc does not count as uses.
#[cfg(kani)]
#[allow(dead_code)]
pub mod model {
    use crate::types::{AxisMode, Command, RejectReason, Speed};
    use crate::validate::{AxisSetpoint, Setpoint};
    use crate::Config;

    /// Any value in `lo ..= hi`.
    fn within(lo: Speed, hi: Speed) -> Speed {
        let x: i32 = kani::any();
        // Bits compared (`harness::Source::speed_within`).
        kani::assume(x >= lo.to_bits() && x <= hi.to_bits());
        Speed::from_bits(x)
    }

    /// Stands for [`crate::validate::validate_into`] (same signature): writes `last` only on success.
    pub fn any_validation<const N: usize>(
        cmd: &Command<N>,
        last: &mut Setpoint<N>,
        _has_last: bool,
        _allowance: Speed,
        cfg: &Config,
    ) -> Result<(), RejectReason> {
        let p = cfg.params();
        let refuse = |_: ()| {
            let i: usize = kani::any();
            kani::assume(i < RejectReason::ALL.len());
            Err(RejectReason::ALL
                .get(i)
                .copied()
                .unwrap_or(RejectReason::Crc))
        };
        let mut modes_ok = true;
        for i in 0..N {
            modes_ok &= p.modes.contains(cmd.axes[i].mode);
        }
        if kani::any() || !modes_ok {
            return refuse(());
        }
        let mut axes = [AxisSetpoint::passive(AxisMode::Coast); N];
        for i in 0..N {
            let a = &cmd.axes[i];
            axes[i] = match a.mode {
                AxisMode::Coast | AxisMode::Short => AxisSetpoint::passive(a.mode),
                AxisMode::Duty => AxisSetpoint {
                    mode: a.mode,
                    target: within(p.duty_max.saturating_neg(), p.duty_max),
                    cap: Speed::ZERO,
                },
                AxisMode::Velocity => AxisSetpoint {
                    mode: a.mode,
                    target: within(p.v_max.saturating_neg(), p.v_max),
                    cap: Speed::ZERO,
                },
                AxisMode::Position => AxisSetpoint {
                    mode: a.mode,
                    target: within(p.travel_lo, p.travel_hi),
                    cap: within(Speed::ZERO, p.v_max),
                },
            };
        }
        let Some(brake_after) = crate::validate::frame_threshold(cmd.timeout, p.brake_after) else {
            return refuse(());
        };
        *last = Setpoint {
            axes,
            seq_value: cmd.seq.unwrap_or(0),
            brake_after,
            has_seq: cmd.seq.is_some(),
            enable: cmd.enable,
        };
        Ok(())
    }
}

/// One Kani proof per axis count for each body (N = 2 and 4; INV-1's unrolled check, over the whole
/// horizon, N = 2 only: for N = 4 its conclusion is INV-18's induction; the reachable-prefix
/// cross-check is a twin only). The eight one-step bodies are proven together by
/// [`one_step_properties`] (their checks on one shared step: 126 s for N = 2 and 219 s for N = 4
/// alone, against 292 s and 557 s as eight harnesses each, two at a time); `stubbed` bodies run
/// with [`model::any_validation`] in place of [`validate_into`] (compositional: `validate_into`
/// itself is proven by INV-5's harness).
#[cfg(kani)]
macro_rules! proofs {
    ($($kind:ident $(#[$attr:meta])* $body:ident => $two:ident $(, $four:ident)?;)*) => {
        $( proofs!(@row $kind [$(#[$attr])*] $body $two $(, $four)?); )*
    };
    (@row $kind:ident $attrs:tt $body:ident $two:ident $(, $four:ident)?) => {
        proofs!(@one $kind $attrs $body $two 2);
        $(proofs!(@one $kind $attrs $body $four 4);)?
    };
    (@one plain [$(#[$attr:meta])*] $body:ident $name:ident $n:literal) => {
        #[kani::proof]
        #[kani::unwind(13)]
        $(#[$attr])*
        fn $name() {
            super::$body::<$n>(&mut KaniSource);
        }
    };
    (@one stubbed [$(#[$attr:meta])*] $body:ident $name:ident $n:literal) => {
        #[kani::proof]
        #[kani::unwind(13)]
        #[kani::stub(crate::validate::validate_into, crate::verification::model::any_validation)]
        $(#[$attr])*
        fn $name() {
            super::$body::<$n>(&mut KaniSource);
        }
    };
}

#[cfg(kani)]
mod kani_entry {
    use crate::harness::KaniSource;

    // A row's attributes after its kind go to both of its harnesses. MiniSat (CBMC's default)
    // rather than CaDiCaL for the validation harnesses' float conversions: faster on two builds
    // (`proofs/REPORT.md`, "Kani suite time").
    proofs! {
        plain initial_state_is_valid => verify_initial_state_is_valid_2, verify_initial_state_is_valid_4;
        stubbed one_step_properties => verify_one_step_properties_2, verify_one_step_properties_4;
        stubbed comm_loss_brakes_within_brake_after_ticks => verify_comm_loss_brakes_within_brake_after_ticks_2;
        plain #[kani::solver(minisat)] validated_setpoints_are_finite_and_in_range => verify_validated_setpoints_are_finite_and_in_range_2, verify_validated_setpoints_are_finite_and_in_range_4;
    }
}

/// The `cargo test` twin of each body, for N = 2 and N = 4: (seed, cases, cover points).
#[cfg(test)]
macro_rules! twins {
    ($($body:ident => $seed:expr, $cases:expr, $covers:expr;)*) => {
        $(
            mod $body {
                use crate::harness::Twin;

                #[test]
                fn two_axes() {
                    Twin::run($seed, $cases, super::super::$body::<2>).assert_covered($covers);
                }

                #[test]
                fn four_axes() {
                    Twin::run($seed ^ 0x40, $cases, super::super::$body::<4>).assert_covered($covers);
                }
            }
        )*
    };
}

#[cfg(test)]
mod twins {
    twins! {
        initial_state_is_valid => 1, 2_000, 1;
        step_preserves_invariant => 2, 200_000 * 5, 8;
        comm_loss_brakes_within_brake_after_ticks => 3, 200_000 * 2, 5;
        comm_loss_age_advances => 11, 200_000 * 2, 3;
        applied_within_mode_limit => 4, 200_000 * 2, 4;
        rejected_frames_change_nothing_applied => 5, 200_000, 7;
        validated_setpoints_are_finite_and_in_range => 6, 200_000, 4;
        brake_left_only_by_rearm_and_fresh_frames => 7, 200_000 * 10, 5;
        latching_faults_cut_pwm_in_same_step => 8, 200_000, 3;
        setpoint_step_is_bounded => 9, 200_000 * 2, 3;
        drive_follows_axis_modes => 12, 200_000 * 2, 3;
        // 36 covers, one message shared by two bodies ("an axis changes mode").
        one_step_properties => 13, 200_000 * 5, 35;
        comm_loss_brakes_after_any_prefix => 10, 200_000, 1;
    }
}
