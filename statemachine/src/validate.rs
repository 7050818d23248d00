//! Command validation: the MCU never trusts a host command (seed 000, "MCU rule").
//!
//! The seed's `fabsf(x) > MAX_WHEEL_SPEED` lets NaN through (every comparison with NaN is false);
//! here a float becomes a [`Speed`] only after it is known to be finite and in range.

use crate::config::Config;
use crate::types::{Command, ControlMode, RejectReason, Speed};

/// A command that passed validation: finite, in range, a mode this firmware drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Setpoint {
    /// Left wheel target, |left| ≤ v_max.
    pub left: Speed,
    /// Right wheel target, |right| ≤ v_max.
    pub right: Speed,
    /// [`ControlMode::Idle`] or [`ControlMode::Speed`].
    pub mode: ControlMode,
    /// Drive enabled.
    pub enable: bool,
    /// Sequence number, where the link carries one.
    pub seq: Option<u32>,
}

impl Setpoint {
    /// True if applying this setpoint would turn the wheels (enabled speed mode).
    pub const fn drives(&self) -> bool {
        self.enable && matches!(self.mode, ControlMode::Speed)
    }
}

/// Sequence numbers are compared in serial-number arithmetic (RFC 1982 style): `seq` is newer than
/// `prev` if it lies 1 ..= 2³¹ ahead, so a counter may wrap but a repeat or an older frame is refused.
pub const fn seq_is_newer(seq: u32, prev: u32) -> bool {
    let d = seq.wrapping_sub(prev);
    d != 0 && d <= 0x8000_0000
}

/// SR-4 / INV-5: NaN and infinities are refused before any comparison; the range check is done on the
/// converted fixed-point value, so rounding cannot carry a value past v_max.
fn to_speed(x: f32, cfg: &Config) -> Result<Speed, RejectReason> {
    if !x.is_finite() {
        return Err(RejectReason::NonFinite);
    }
    let v_max = cfg.params().v_max;
    match q16_from_f32(x) {
        Some(s) if s <= v_max && s >= v_max.saturating_neg() => Ok(s),
        _ => Err(RejectReason::OutOfRange),
    }
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

/// Checks `cmd` against the configuration and the last valid setpoint.
///
/// `allowance` is how far a driving command may move from the last valid driving one
/// (the ladder passes `max_cmd_step` × ticks since that frame, so lost frames do not lock the host out).
/// Checks in order: finite, in range, known mode, driven mode, newer sequence, acceleration.
/// Frames that do not drive (disabled or idle) skip the acceleration check: stopping is always allowed.
pub fn validate(
    cmd: &Command,
    last: Option<&Setpoint>,
    allowance: Speed,
    cfg: &Config,
) -> Result<Setpoint, RejectReason> {
    let left = to_speed(cmd.left, cfg)?;
    let right = to_speed(cmd.right, cfg)?;
    let mode = match ControlMode::from_raw(cmd.mode) {
        None => return Err(RejectReason::UnknownMode),
        Some(ControlMode::Position | ControlMode::RawDuty) => {
            return Err(RejectReason::UnsupportedMode)
        }
        Some(m) => m,
    };
    if let (
        Some(seq),
        Some(Setpoint {
            seq: Some(prev), ..
        }),
    ) = (cmd.seq, last)
    {
        // SR-3: a repeated or older frame is refused.
        if !seq_is_newer(seq, *prev) {
            return Err(RejectReason::Stale);
        }
    }
    let sp = Setpoint {
        left,
        right,
        mode,
        enable: cmd.enable,
        seq: cmd.seq,
    };
    if let Some(prev) = last {
        if sp.drives()
            && prev.drives()
            && !(within(left, prev.left, allowance) && within(right, prev.right, allowance))
        {
            // SR-4: an impossible jump is refused (Incident-A: a corrupted frame that passes the CRC).
            return Err(RejectReason::Acceleration);
        }
    }
    Ok(sp)
}

#[cfg(test)]
mod tests {
    use super::*;

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

    fn cmd(left: f32, right: f32) -> Command {
        Command {
            left,
            right,
            mode: 1,
            enable: true,
            seq: None,
        }
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
    fn modes() {
        let c = Config::DEFAULT;
        for (raw, want) in [
            (0, Ok(ControlMode::Idle)),
            (1, Ok(ControlMode::Speed)),
            (2, Err(RejectReason::UnsupportedMode)),
            (3, Err(RejectReason::UnsupportedMode)),
            (4, Err(RejectReason::UnknownMode)),
            (u32::MAX, Err(RejectReason::UnknownMode)),
        ] {
            let r = validate(
                &Command {
                    mode: raw,
                    ..cmd(0.0, 0.0)
                },
                None,
                STEP,
                &c,
            )
            .map(|s| s.mode);
            assert_eq!(r, want, "mode {raw}");
        }
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
        // Disabling or idling is always allowed.
        let stop = Command {
            enable: false,
            ..cmd(0.0, 0.0)
        };
        assert!(validate(&stop, Some(&last), STEP, &c).is_ok());
        let idle = Command {
            mode: 0,
            ..cmd(0.0, 0.0)
        };
        assert!(validate(&idle, Some(&last), STEP, &c).is_ok());
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
