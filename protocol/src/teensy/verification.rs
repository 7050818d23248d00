//! Kani harnesses of the seed 003 packets and their `cargo test` twins.

use super::*;
use statemachine::cover;
use statemachine::harness::Source;

/// Motor count used by the harnesses (small under Kani).
const N: usize = if cfg!(kani) { 1 } else { 4 };
type Msg = CmdMsg<N>;

fn any_msg(src: &mut impl Source) -> Msg {
    let mut mtr_angles = [0i32; N];
    for a in mtr_angles.iter_mut() {
        *a = src.i32();
    }
    CmdMsg {
        cmd_type: CmdType::from_raw(i32::from(src.below(5))).unwrap_or_default(),
        is_relative: src.i32(),
        mtr_angles,
        mtr_speed_deg_s: src.i32(),
        mtr_accel_deg_s_s: src.i32(),
        cmd_success: src.i32(),
    }
}

/// Both decoders return a command or a typed error for every input up to the robust frame size.
pub(crate) fn check_decode_total(src: &mut impl Source) {
    let mut buf = [0u8; ROBUST_BUF];
    let shape = src.below(3);
    let n = if shape == 0 {
        let n = usize::from(src.below(Msg::ROBUST_MAX_LEN as u8 + 2));
        for b in buf.iter_mut().take(n) {
            *b = src.u8();
        }
        n
    } else {
        // A valid robust frame or legacy packet with one byte replaced.
        let m = any_msg(src);
        let n = if shape == 1 {
            m.encode_robust(&mut buf)
        } else {
            m.encode_legacy(&mut buf)
        };
        let n = n.unwrap_or(0);
        let i = usize::from(src.u8()) % n.max(1);
        buf[i] = src.u8();
        n
    };
    let legacy = Msg::decode_legacy(&buf[..n]);
    let robust = Msg::decode_robust(&buf[..n]);
    cover!(src, legacy.is_ok(), "legacy decoded");
    cover!(src, robust.is_ok(), "robust decoded");
    cover!(src, robust == Err(RejectReason::Crc), "robust crc error");
    cover!(
        src,
        robust == Err(RejectReason::Framing),
        "robust framing error"
    );
    // Feed the same bytes to a stream decoder.
    let mut dec = RobustDecoder::<N>::new();
    for &b in &buf[..n] {
        let _ = dec.push(b);
    }
}

/// encode → decode round-trips in both formats.
pub(crate) fn check_round_trip(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; ROBUST_BUF];
    let n = m.encode_legacy(&mut buf);
    assert_eq!(n, Some(Msg::LEGACY_LEN));
    assert_eq!(Msg::decode_legacy(&buf[..Msg::LEGACY_LEN]), Ok(m));
    let n = m.encode_robust(&mut buf).unwrap_or(0);
    assert!(n > 0 && n <= Msg::ROBUST_MAX_LEN);
    assert_eq!(Msg::decode_robust(&buf[..n]), Ok(m));
    let mut dec = RobustDecoder::<N>::new();
    let mut got = None;
    for &b in &buf[..n] {
        if let Some(r) = dec.push(b) {
            got = Some(r);
        }
    }
    assert_eq!(got, Some(Ok(m)));
    cover!(src, m.cmd_type == CmdType::Mtrs, "motor command");
}

/// A flipped bit anywhere in a robust frame is refused.
pub(crate) fn check_bit_flip_detected(src: &mut impl Source) {
    let m = any_msg(src);
    let mut buf = [0u8; ROBUST_BUF];
    let n = m.encode_robust(&mut buf).unwrap_or(0);
    let bit = usize::from(src.u16()) % (n * 8).max(1);
    buf[bit / 8] ^= 1 << (bit % 8);
    assert!(Msg::decode_robust(&buf[..n]).is_err());
    cover!(src, bit / 8 == n - 1, "flip in terminator");
    cover!(src, bit / 8 < n - 1, "flip in body");
}

/// Kani harnesses, pending: they do not finish on today's solvers (symbolic-length slices through
/// the decoders); they run only with `RUSTFLAGS="--cfg kani_pending" cargo kani`, and always as
/// `cargo test` twins. See `proofs/REPORT.md`.
#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use super::*;
    use statemachine::harness::KaniSource;

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(90))]
    fn verify_decode_total() {
        check_decode_total(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(90))]
    fn verify_round_trip() {
        check_round_trip(&mut KaniSource);
    }

    #[cfg_attr(kani_pending, kani::proof)]
    #[cfg_attr(kani_pending, kani::unwind(90))]
    fn verify_bit_flip_detected() {
        check_bit_flip_detected(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use super::*;
    use statemachine::harness::Twin;

    #[test]
    fn decode_total() {
        Twin::run(0x7E_0001, 20_000, check_decode_total).assert_covered(4);
    }

    #[test]
    fn round_trip() {
        Twin::run(0x7E_0002, 10_000, check_round_trip).assert_covered(1);
    }

    #[test]
    fn bit_flip_detected() {
        Twin::run(0x7E_0003, 20_000, check_bit_flip_detected).assert_covered(2);
    }
}
