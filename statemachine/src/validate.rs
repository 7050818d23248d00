//! Command validation: the MCU never trusts a host command (seed 000, "MCU rule").
//!
//! The seed's `fabsf(x) > MAX_WHEEL_SPEED` lets NaN through (every comparison with NaN is false);
//! here a float becomes a fixed-point target only after it is known to be finite and in its mode's range.

use crate::config::Config;
use crate::types::{AxisCommand, AxisMode, Command, RejectReason, Speed};

/// One axis of a command that passed validation.
///
/// `repr(C)`, words first: setpoints are copied on every received frame, and with the byte-sized
/// fields last a copy is whole words (the default layout led the compiler to copy them byte-wise
/// from an odd offset, a fifth of a frame's instructions on the Cortex-M4; `firmware/BUDGET.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct AxisSetpoint {
    /// |duty| ≤ duty_max, |speed| ≤ v_max, or a position within the travel; zero for the passive modes.
    pub target: Speed,
    /// Position speed cap in 0 ..= v_max; zero for the other modes.
    pub cap: Speed,
    /// A mode the profile accepts.
    pub mode: AxisMode,
}

impl AxisSetpoint {
    /// A passive axis (coast or short brake).
    pub const fn passive(mode: AxisMode) -> Self {
        Self {
            mode,
            target: Speed::ZERO,
            cap: Speed::ZERO,
        }
    }
}

/// A command that passed validation: finite, in range, modes the profile accepts. `repr(C)`, words
/// first, for the reason given at [`AxisSetpoint`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct Setpoint<const N: usize> {
    /// One validated request per axis.
    pub axes: [AxisSetpoint; N],
    /// Sequence number, meaningful if `has_seq` (see [`Setpoint::seq`]). Not an `Option<u32>`: its
    /// tag word is one meaningful byte and three undefined ones, which the compiler copies apart from
    /// the rest, byte-wise.
    pub seq_value: u32,
    /// The comm-loss threshold this frame leaves in force: its `timeout` capped by the profile's
    /// `brake_after`, at least 1.
    pub brake_after: u16,
    /// True if the link carries a sequence number.
    pub has_seq: bool,
    /// Drive enabled.
    pub enable: bool,
}

impl<const N: usize> Setpoint<N> {
    /// A placeholder for "no command": every axis coasting, disabled, the given threshold.
    pub const fn none(brake_after: u16) -> Self {
        Self {
            axes: [AxisSetpoint::passive(AxisMode::Coast); N],
            seq_value: 0,
            brake_after,
            has_seq: false,
            enable: false,
        }
    }

    /// The sequence number, where the link carries one.
    pub const fn seq(&self) -> Option<u32> {
        if self.has_seq {
            Some(self.seq_value)
        } else {
            None
        }
    }
}

/// Sequence numbers are compared in serial-number arithmetic (RFC 1982 style): `seq` is newer than
/// `prev` if it lies 1 ..= 2³¹ ahead, so a counter may wrap but a repeat or an older frame is refused.
pub const fn seq_is_newer(seq: u32, prev: u32) -> bool {
    let d = seq.wrapping_sub(prev);
    d != 0 && d <= 0x8000_0000
}

/// SR-4 / INV-5: NaN and infinities are refused before any comparison; the range check is done on the
/// converted fixed-point value, so rounding cannot carry a value past a limit.
fn to_q(x: f32, lo: Speed, hi: Speed) -> Result<Speed, RejectReason> {
    if !x.is_finite() {
        return Err(RejectReason::NonFinite);
    }
    match q16_from_f32(x) {
        Some(s) if s <= hi && s >= lo => Ok(s),
        _ => Err(RejectReason::OutOfRange),
    }
}

/// One axis: its mode accepted by the profile, its numbers finite and within the mode's range.
fn validate_axis(a: &AxisCommand, cfg: &Config) -> Result<AxisSetpoint, RejectReason> {
    let p = cfg.params();
    if !p.modes.contains(a.mode) {
        return Err(RejectReason::UnsupportedMode);
    }
    let sym = |limit: Speed| (limit.saturating_neg(), limit);
    let (target, cap) = match a.mode {
        AxisMode::Coast | AxisMode::Short => (Speed::ZERO, Speed::ZERO),
        AxisMode::Duty => {
            let (lo, hi) = sym(p.duty_max);
            (to_q(a.target, lo, hi)?, Speed::ZERO)
        }
        AxisMode::Velocity => {
            let (lo, hi) = sym(p.v_max);
            (to_q(a.target, lo, hi)?, Speed::ZERO)
        }
        // SR-15 / INV-15: a position target outside the travel is refused, so none is ever applied.
        AxisMode::Position => (
            to_q(a.target, p.travel_lo, p.travel_hi)?,
            to_q(a.cap, Speed::ZERO, p.v_max)?,
        ),
    };
    Ok(AxisSetpoint {
        mode: a.mode,
        target,
        cap,
    })
}

/// A finite `f32` as Q16.16, rounded to the nearest step with ties to even (what
/// `Speed::checked_from_num` does), or `None` if |x| ≥ 2¹⁵ (the one in-range value this refuses,
/// −2¹⁵, is beyond every accepted v_max). Works on the bit pattern: on the Cortex-M4 this is a
/// fifth of the generic conversion's instructions, and it runs for both wheels of every frame.
///
/// ```text
///  x = (−1)^sign · m · 2^(e − 150),  m = 1.frac (23 bits) for e ≥ 1, 0.frac for e = 0
///  Q16.16 bits = x · 2^16 = m · 2^(e − 134): shift m left by e − 134, or right with rounding
/// ```
fn q16_from_f32(x: f32) -> Option<Speed> {
    let bits = x.to_bits();
    let e = (bits >> 23) & 0xFF;
    let frac = bits & 0x007F_FFFF;
    // |x| ≥ 2^15 (and infinities, NaN: e = 255).
    if e >= 142 {
        return None;
    }
    let m = if e == 0 { frac } else { frac | 0x0080_0000 };
    let e = if e == 0 { 1 } else { e };
    // Every operation below is on bounds stated beside it; the wrapping forms never wrap.
    let mag: u32 = if e >= 134 {
        // e − 134 ≤ 7 and m < 2^24: the shifted value is < 2^31.
        m.wrapping_shl(e.wrapping_sub(134))
    } else {
        // 1 ≤ s ≤ 133.
        let s = 134u32.wrapping_sub(e);
        if s > 24 {
            // m < 2^24 ≤ half a step: rounds to zero.
            0
        } else {
            let q = m.wrapping_shr(s);
            let rem = m & 1u32.wrapping_shl(s).wrapping_sub(1);
            let half = 1u32.wrapping_shl(s.wrapping_sub(1));
            let up = rem > half || (rem == half && q & 1 == 1);
            // q < 2^24: adding one cannot overflow.
            q.wrapping_add(u32::from(up))
        }
    };
    // mag < 2^31, so it fits i32 and its negation does too.
    let v = mag as i32;
    Some(Speed::from_bits(if bits >> 31 == 1 {
        v.wrapping_neg()
    } else {
        v
    }))
}

fn within(a: Speed, b: Speed, allowance: Speed) -> bool {
    let d = a.saturating_sub(b);
    d <= allowance && d >= allowance.saturating_neg()
}

/// The comm-loss threshold a frame leaves in force: its own `timeout` capped by the profile's
/// `brake_after`, the profile's without one; `None` for a zero timeout, which no frame may ask for.
pub const fn frame_threshold(timeout: Option<u16>, brake_after: u16) -> Option<u16> {
    match timeout {
        None => Some(brake_after),
        Some(0) => None,
        Some(t) if t < brake_after => Some(t),
        Some(_) => Some(brake_after),
    }
}

/// Checks `cmd` against the configuration and the last valid setpoint.
///
/// `allowance` is how far a velocity target may move from the last valid one on the same axis (the
/// ladder passes `max_cmd_step` × ticks since that frame, so lost frames do not lock the host out).
/// Checks in order: each axis (mode accepted, finite, in range), timeout, newer sequence, acceleration.
/// Frames that stop (disabled, or a zero or passive target) skip the acceleration check: stopping is
/// always allowed.
pub fn validate<const N: usize>(
    cmd: &Command<N>,
    last: Option<&Setpoint<N>>,
    allowance: Speed,
    cfg: &Config,
) -> Result<Setpoint<N>, RejectReason> {
    let mut sp = match last {
        Some(l) => *l,
        None => Setpoint::none(cfg.params().brake_after),
    };
    validate_into(cmd, &mut sp, last.is_some(), allowance, cfg)?;
    Ok(sp)
}

/// [`validate`] in place, as the ladder runs it: checks `cmd` against `last` (meaningful if
/// `has_last`) and, only if every check passes, overwrites `last` with the new setpoint; a refused
/// command leaves `last` as it was. (In place because the setpoint is then stored without a copy:
/// on the Cortex-M4 the compiler copied a returned setpoint byte-wise, `firmware/BUDGET.md`.)
pub fn validate_into<const N: usize>(
    cmd: &Command<N>,
    last: &mut Setpoint<N>,
    has_last: bool,
    allowance: Speed,
    cfg: &Config,
) -> Result<(), RejectReason> {
    let mut axes = [AxisSetpoint::passive(AxisMode::Coast); N];
    #[allow(clippy::indexing_slicing)]
    for i in 0..N {
        axes[i] = validate_axis(&cmd.axes[i], cfg)?;
    }
    let brake_after =
        frame_threshold(cmd.timeout, cfg.params().brake_after).ok_or(RejectReason::OutOfRange)?;
    if let (Some(seq), true, true) = (cmd.seq, has_last, last.has_seq) {
        // SR-3: a repeated or older frame is refused.
        if !seq_is_newer(seq, last.seq_value) {
            return Err(RejectReason::Stale);
        }
    }
    // A velocity axis drives exactly when its command is enabled (velocity is not a passive mode).
    if has_last && last.enable && cmd.enable {
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            let (a, b) = (&axes[i], &last.axes[i]);
            if a.mode == AxisMode::Velocity
                && b.mode == AxisMode::Velocity
                && a.target != Speed::ZERO
                && !within(a.target, b.target, allowance)
            {
                // SR-4: an impossible jump is refused (Incident-A: a corrupted frame that passes the CRC).
                return Err(RejectReason::Acceleration);
            }
        }
    }
    last.axes = axes;
    last.seq_value = cmd.seq.unwrap_or(0);
    last.has_seq = cmd.seq.is_some();
    last.brake_after = brake_after;
    last.enable = cmd.enable;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::AxisCommand;

    /// The bit-level conversion agrees with `fixed`'s `checked_from_num` (limited to |x| < 2^15) for
    /// every exponent, with mantissas at and around every rounding boundary and pseudo-random ones.
    #[test]
    fn q16_conversion_matches_fixed() {
        let reference =
            |x: f32| -> Option<Speed> { Speed::checked_from_num(x).filter(|_| x.abs() < 32768.0) };
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut n = 0u64;
        for sign in [0u32, 1] {
            for e in 0u32..255 {
                let fixed_cases = [0u32, 1, 2, 3, 0x7F_FFFF, 0x7F_FFFE, 0x40_0000].into_iter();
                // Around the rounding boundary of every right shift: half, half ± 1, odd/even q.
                let boundaries = (1u32..=24).flat_map(|s| {
                    let half = 1u32 << (s - 1);
                    [
                        half - 1,
                        half,
                        half + 1,
                        3 * half,
                        3 * half - 1,
                        3 * half + 1,
                    ]
                    .map(|d| d & 0x7F_FFFF)
                });
                let random = (0..2000).map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 41) as u32 & 0x7F_FFFF
                });
                for f in fixed_cases.chain(boundaries).chain(random) {
                    let x = f32::from_bits((sign << 31) | (e << 23) | f);
                    assert_eq!(
                        q16_from_f32(x),
                        reference(x),
                        "{x:e} ({:#010x})",
                        x.to_bits()
                    );
                    n += 1;
                }
            }
        }
        assert!(n > 1_000_000);
    }

    fn cmd(left: f32, right: f32) -> Command<2> {
        Command::velocity([left, right], true, None)
    }

    const STEP: Speed = Speed::from_bits(3277);

    #[test]
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // the seed's comparison, reproduced on purpose
    fn nan_and_infinity_are_refused_even_though_the_seed_check_passes_them() {
        // The seed's check: reject if fabsf(x) > MAX. For NaN that comparison is false.
        let seed_accepts = |x: f32| !(x.abs() > 20.0);
        for bad in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let r = validate(&cmd(bad, 0.0), None, STEP, &Config::DEFAULT);
            assert!(r.is_err(), "{bad} accepted");
            if bad.is_nan() {
                assert!(seed_accepts(bad));
                assert_eq!(r, Err(RejectReason::NonFinite));
            }
        }
    }

    #[test]
    fn range_is_inclusive_of_v_max() {
        let c = Config::DEFAULT;
        assert!(validate(&cmd(20.0, -20.0), None, STEP, &c).is_ok());
        assert_eq!(
            validate(&cmd(20.001, 0.0), None, STEP, &c),
            Err(RejectReason::OutOfRange)
        );
        assert_eq!(
            validate(&cmd(0.0, -1e30), None, STEP, &c),
            Err(RejectReason::OutOfRange)
        );
    }

    #[test]
    fn each_profile_accepts_its_modes_only() {
        let one = |m: AxisMode| {
            Command::<2>::uniform(
                AxisCommand {
                    mode: m,
                    target: 0.5,
                    cap: 1.0,
                },
                true,
                None,
            )
        };
        let table: [(Config, [bool; 5]); 4] = [
            // coast, short, duty, velocity, position
            (Config::AMR_SPI, [false, false, false, true, false]),
            (Config::CDC, [true, false, true, false, false]),
            (Config::TEENSY, [true, false, false, false, true]),
            (Config::PI_SPI, [true, true, true, true, true]),
        ];
        for (cfg, accepts) in table {
            for (m, ok) in AxisMode::ALL.into_iter().zip(accepts) {
                let r = validate(&one(m), None, STEP, &cfg);
                if ok {
                    assert!(r.is_ok(), "{m:?} in {:?}", cfg.params().modes);
                } else {
                    assert_eq!(r, Err(RejectReason::UnsupportedMode), "{m:?}");
                }
            }
        }
    }

    #[test]
    fn duty_position_and_timeout_ranges() {
        let c = Config::PI_SPI;
        let p = c.params();
        let duty = |d: f32| Command::<2>::uniform(AxisCommand::duty(d), true, None);
        assert!(validate(&duty(1.0), None, STEP, &c).is_ok());
        assert!(validate(&duty(-1.0), None, STEP, &c).is_ok());
        assert_eq!(
            validate(&duty(1.0001), None, STEP, &c),
            Err(RejectReason::OutOfRange)
        );
        assert_eq!(
            validate(&duty(f32::NAN), None, STEP, &c),
            Err(RejectReason::NonFinite)
        );
        // Travel ±100 rad, caps 0 ..= v_max (20 rad/s).
        let pos =
            |t: f32, cap: f32| Command::<2>::uniform(AxisCommand::position(t, cap), true, None);
        assert!(validate(&pos(100.0, 20.0), None, STEP, &c).is_ok());
        assert!(validate(&pos(-100.0, 0.0), None, STEP, &c).is_ok());
        assert_eq!(
            validate(&pos(100.01, 1.0), None, STEP, &c),
            Err(RejectReason::OutOfRange)
        );
        assert_eq!(
            validate(&pos(0.0, -0.01), None, STEP, &c),
            Err(RejectReason::OutOfRange)
        );
        assert_eq!(
            validate(&pos(0.0, 20.01), None, STEP, &c),
            Err(RejectReason::OutOfRange)
        );
        assert_eq!(
            validate(&pos(0.0, f32::INFINITY), None, STEP, &c),
            Err(RejectReason::NonFinite)
        );
        // Passive modes ignore their numbers, NaN included.
        let coast = Command::<2>::uniform(
            AxisCommand {
                target: f32::NAN,
                ..AxisCommand::COAST
            },
            true,
            None,
        );
        assert!(validate(&coast, None, STEP, &c).is_ok());
        // A frame's timeout lowers the threshold, never raises it; zero is refused.
        let with = |t: Option<u16>| Command {
            timeout: t,
            ..duty(0.0)
        };
        let th = |t| validate(&with(t), None, STEP, &c).map(|s| s.brake_after);
        assert_eq!(th(None), Ok(p.brake_after));
        assert_eq!(th(Some(5)), Ok(5));
        assert_eq!(th(Some(u16::MAX)), Ok(p.brake_after));
        assert_eq!(th(Some(0)), Err(RejectReason::OutOfRange));
    }

    #[test]
    fn acceleration_limit_against_last_driving_command() {
        let c = Config::DEFAULT;
        let last = validate(&cmd(1.0, 1.0), None, STEP, &c).unwrap();
        assert!(validate(&cmd(1.04, 0.96), Some(&last), STEP, &c).is_ok());
        assert_eq!(
            validate(&cmd(1.2, 1.0), Some(&last), STEP, &c),
            Err(RejectReason::Acceleration)
        );
        // Three ticks since the last valid frame: three steps allowed.
        assert!(validate(&cmd(1.14, 1.0), Some(&last), STEP * 3, &c).is_ok());
        // Disabling or a zero target is always allowed.
        let stop = Command {
            enable: false,
            ..cmd(5.0, 5.0)
        };
        assert!(validate(&stop, Some(&last), STEP, &c).is_ok());
        assert!(validate(&cmd(0.0, 0.0), Some(&last), STEP, &c).is_ok());
        // A zero on one wheel does not excuse a jump on the other.
        assert_eq!(
            validate(&cmd(0.0, 3.0), Some(&last), STEP, &c),
            Err(RejectReason::Acceleration)
        );
    }

    #[test]
    fn sequence_numbers_wrap_but_never_repeat() {
        assert!(seq_is_newer(1, 0));
        assert!(seq_is_newer(0, u32::MAX));
        assert!(!seq_is_newer(5, 5));
        assert!(!seq_is_newer(4, 5));
        assert!(seq_is_newer(0x8000_0000, 0));
        assert!(!seq_is_newer(0x8000_0001, 0));
        let c = Config::DEFAULT;
        let last = validate(
            &Command {
                seq: Some(7),
                ..cmd(0.0, 0.0)
            },
            None,
            STEP,
            &c,
        )
        .unwrap();
        let again = Command {
            seq: Some(7),
            ..cmd(0.0, 0.0)
        };
        assert_eq!(
            validate(&again, Some(&last), STEP, &c),
            Err(RejectReason::Stale)
        );
        let next = Command {
            seq: Some(8),
            ..cmd(0.0, 0.0)
        };
        assert!(validate(&next, Some(&last), STEP, &c).is_ok());
    }
}
