//! What the CRC catches, for every link that stores it after the bytes it covers: Kani harnesses
//! over error patterns and their `cargo test` twins.
//!
//! | link | CRC stored | caught: every burst of up to |
//! |---|---|---|
//! | seed 000 SPI frame | big-endian (codeword order) | 16 bits, anywhere in the frame |
//! | seed 001 CDC frame | little-endian (seed 001's rule) | 12 bits, anywhere |
//!
//! With the CRC stored little-endian its two bytes are swapped against the codeword order, and a
//! 13-bit burst that ends in the low CRC byte can pass (`every_burst_by_byte_order` finds the
//! shortest one at every checked length). Every single-bit error is caught in both orders.
//!
//! The Teensy robust frame (version 2) stores its CRC in neither order: 7 bits per check byte, each
//! with bit 7 set, after the stuffed bytes it covers. An error confined to those stuffed bytes
//! leaves the stored value alone, so it passes only if its pattern is a multiple of the generator
//! polynomial, which no burst of up to 16 bits is (whatever the length; the test
//! `every_burst_within_the_stuffed_bytes_changes_the_crc` enumerates every motor count's). A flip in the
//! check bytes is refused by their own encoding (`teensy::verification`, `check_check_bytes`).
//!
//! # Why checking error patterns alone is enough
//!
//! For a fixed length `n` the checksum is affine over GF(2): `C(x ⊕ e) = C(x) ⊕ C(e) ⊕ C(0ⁿ)`. Each
//! slice table is linear (`T[a ⊕ b] = T[a] ⊕ T[b]`, checked for every entry by the test
//! `tables_are_linear`), and [`checksum`] only XORs table entries indexed by data bytes XORed with
//! register bytes, starting from the constant `INIT`. A sender puts `x` and `s = C(x)` on the wire;
//! the receiver gets `x ⊕ e_x` and `s ⊕ e_s` and accepts iff `C(x ⊕ e_x) = s ⊕ e_s`, that is iff
//! `C(e_x) ⊕ C(0ⁿ) = e_s` — whatever `x` was. So proving `C(e_x) ⊕ C(0ⁿ) ≠ e_s` for an error pattern
//! proves that pattern is caught in *every* frame of that length.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::checksum;
use statemachine::harness::Source;
use statemachine::{assume, check, cover};

/// Longest run of covered bytes checked: the seed 000 frame body (62 bytes), which is longer than
/// every seed 001 frame of the seed's messages and the Teensy robust frame's stuffed bytes up to 10
/// motors (22 + 4·N bytes).
pub(crate) const MAX_COVERED: usize = 62;

/// The error in a codeword of `n` covered bytes followed by the CRC: a burst of at most `max_bits`
/// bits (≤ 16) in transmission order (most significant bit of each byte first) starting anywhere, so
/// every single-bit error too. `None` for a start past the codeword (assumed away).
fn any_burst(src: &mut impl Source, n: usize, max_bits: u32) -> Option<[u8; MAX_COVERED + 2]> {
    let total_bits = (n + 2) * 8;
    let start = usize::from(src.u16());
    if start >= total_bits {
        return None;
    }
    // Bit 0 is the first wrong bit; any of the next 15 may be wrong too.
    let pattern = (src.u16() | 1) & (u16::MAX >> 16u32.saturating_sub(max_bits));
    let mut e = [0u8; MAX_COVERED + 2];
    for i in 0..16 {
        let bit = start + i;
        if (pattern >> i) & 1 == 1 && bit < total_bits {
            set_bit(&mut e, bit);
        }
    }
    Some(e)
}

/// Sets bit `bit` of `e` in transmission order (most significant bit of each byte first).
fn set_bit(e: &mut [u8; MAX_COVERED + 2], bit: usize) {
    e[bit / 8] |= 0x80 >> (bit % 8);
}

/// What error `e` in a codeword of `n` covered bytes plus CRC does to the receiver's check: the
/// change of the computed CRC XOR the change of the stored one (`zeros_crc` is the CRC of `n` zero
/// bytes). By the affine identity the error passes iff this is zero, whatever the frame.
fn syndrome(e: &[u8; MAX_COVERED + 2], n: usize, order: Order, zeros_crc: u16) -> u16 {
    checksum(&e[..n]) ^ zeros_crc ^ order.read([e[n], e[n + 1]])
}

/// Whether the CRC is stored most significant byte first (codeword order).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Order {
    /// Most significant byte first: seed 000.
    Big,
    /// Least significant byte first: seed 001.
    Little,
}

impl Order {
    /// The longest burst this storage order is proven to catch.
    pub(crate) const fn max_burst(self) -> u32 {
        match self {
            Order::Big => 16,
            Order::Little => 12,
        }
    }

    fn read(self, b: [u8; 2]) -> u16 {
        match self {
            Order::Big => u16::from_be_bytes(b),
            Order::Little => u16::from_le_bytes(b),
        }
    }
}

/// Every burst of up to [`Order::max_burst`] bits (every single-bit error among them) in a codeword
/// of `n` (1 ..= 62) covered bytes plus its CRC makes the received CRC disagree with the received
/// bytes. (`n` is fixed per harness: a symbolic length puts every slice at a symbolic offset, which
/// the solver does not finish; the exhaustive test below covers every length.)
pub(crate) fn check_bursts_detected(src: &mut impl Source, order: Order, n: usize) {
    let max_bits = order.max_burst();
    let burst = any_burst(src, n, max_bits);
    assume!(src, burst.is_some());
    let Some(e) = burst else { return };
    let zeros = [0u8; MAX_COVERED];
    check!(
        syndrome(&e, n, order, checksum(&zeros[..n])) != 0,
        "P-1: the burst changes the CRC check (non-zero syndrome)"
    );
    let body_hit = e[..n].iter().any(|&b| b != 0);
    let crc_hit = e[n] != 0 || e[n + 1] != 0;
    let wrong_bits: u32 = e.iter().map(|b| b.count_ones()).sum();
    cover!(src, wrong_bits == 1, "single-bit error");
    cover!(
        src,
        wrong_bits == max_bits,
        "longest burst, every bit wrong"
    );
    cover!(
        src,
        body_hit && crc_hit,
        "burst across the end of the covered bytes"
    );
    cover!(src, !body_hit && crc_hit, "burst in the stored CRC only");
    cover!(src, body_hit && !crc_hit, "burst in the covered bytes only");
}

/// P-1: [`check_bursts_detected`] for the seed 000 frame: 62 covered bytes, CRC big-endian.
pub(crate) fn check_bursts_detected_seed000(src: &mut impl Source) {
    check_bursts_detected(src, Order::Big, MAX_COVERED);
}

/// P-1: [`check_bursts_detected`] for the longest seed 001 frame (IMU: 22 covered bytes), CRC
/// little-endian.
pub(crate) fn check_bursts_detected_seed001_imu(src: &mut impl Source) {
    check_bursts_detected(src, Order::Little, 22);
}

/// Longest input [`check_checksum_total`] feeds: a whole seed 001 frame (the CRC covers at most
/// 257 of its bytes), which is longer than every other covered run.
const TOTAL_MAX: usize = crate::cdc::MAX_FRAME_LEN;

/// P-2: [`checksum`] is total: any bytes of any length up to [`TOTAL_MAX`], never a panic.
pub(crate) fn check_checksum_total(src: &mut impl Source) {
    let buf: [u8; TOTAL_MAX] = src.bytes();
    let n = usize::from(src.u16()) % (TOTAL_MAX + 1);
    let _ = checksum(&buf[..n]);
    cover!(src, n == TOTAL_MAX, "longest input");
    cover!(src, n % 16 == 15, "every block size used");
}

/// The seeds' bitwise CRC loop, one byte at a time: the same function as [`checksum`] (the test
/// `seed_loop_is_checksum` compares them at every length of a seed 001 frame), without the
/// block folding. The stream decoders' property harnesses use it in place of [`checksum`]: there the
/// solver cannot fix the lengths of the slices checked, and the 16-byte blocks multiply the formula.
pub(crate) fn seed_loop(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Stand-ins for [`checksum`] under Kani (used with `#[kani::stub(crate::crc16::checksum, …)]`,
/// which needs `cargo kani -Z stubbing`).
#[cfg(kani)]
pub(crate) mod model {
    /// Any checksum at all, for harnesses whose property must hold whatever the CRC returns
    /// (decoder totality, a LEN flip refused before the CRC is read). Sound in place of
    /// [`super::checksum`] because `verify_checksum_total` proves the real one returns (never
    /// panics) for every input up to a whole frame.
    pub(crate) fn any_checksum(_bytes: &[u8]) -> u16 {
        kani::any()
    }

    /// How many distinct inputs [`uninterpreted_checksum`] remembers: more than any harness calls it.
    const REMEMBERED: usize = 4;
    /// The longest input it remembers: a seed 000 frame's 62 covered bytes, a Teensy robust frame's
    /// stuffed bytes (up to 86).
    const REMEMBERED_LEN: usize = 96;

    /// What [`uninterpreted_checksum`] has answered so far: (input length, input bytes, value).
    static mut ANSWERS: [(usize, [u8; REMEMBERED_LEN], u16); REMEMBERED] =
        [(0, [0; REMEMBERED_LEN], 0); REMEMBERED];
    static mut ANSWERED: usize = 0;

    /// Forgets every answer of [`uninterpreted_checksum`]: from here on it is a new function of
    /// the bytes. For a harness that proves several claims one after the other, each of which must
    /// hold for every pure function on its own (the seed 001 round trip of each message kind).
    #[allow(unsafe_code)]
    pub(crate) fn forget_checksums() {
        // SAFETY: as in `uninterpreted_checksum`: one thread, no reference to the static kept.
        unsafe {
            *core::ptr::addr_of_mut!(ANSWERED) = 0;
        }
    }

    /// An uninterpreted function of the bytes: any value, but the same value whenever it is
    /// asked again about the same bytes. A property proven with it in place of
    /// [`super::checksum`] holds for *every* pure function of the bytes, and so for the real CRC,
    /// which is one (no state, no interior mutability); it proves nothing about error detection,
    /// which is the real CRC's own (P-1, P-7). For harnesses whose property needs only that the
    /// same bytes give the same checksum (a frame sealed, then opened; `open` accepting only a
    /// stored value equal to the checksum the harness computed). Remembers up to [`REMEMBERED`]
    /// inputs of up to [`REMEMBERED_LEN`] bytes; a harness that asks about more fails its
    /// assumption, and Kani reports the harness's covers unsatisfiable rather than a false proof.
    #[allow(unsafe_code)]
    pub(crate) fn uninterpreted_checksum(bytes: &[u8]) -> u16 {
        kani::assume(bytes.len() <= REMEMBERED_LEN);
        // SAFETY: Kani runs a harness on one thread, from a fresh program state each time; no
        // reference to the statics outlives this call.
        let (answers, answered) = unsafe {
            (
                &mut *core::ptr::addr_of_mut!(ANSWERS),
                &mut *core::ptr::addr_of_mut!(ANSWERED),
            )
        };
        for (len, seen, value) in answers.iter().take(*answered) {
            if *len == bytes.len() && seen.get(..*len) == Some(bytes) {
                return *value;
            }
        }
        kani::assume(*answered < REMEMBERED);
        let value: u16 = kani::any();
        if let Some(slot) = answers.get_mut(*answered) {
            slot.0 = bytes.len();
            if let Some(dst) = slot.1.get_mut(..bytes.len()) {
                dst.copy_from_slice(bytes);
            }
            slot.2 = value;
        }
        *answered = answered.saturating_add(1);
        value
    }
}

/// Kani harnesses (`cargo kani -p protocol -Z stubbing -Z function-contracts --harness crc16::`).
/// The burst claims (P-1) are not Kani harnesses: a symbolic burst at a symbolic start bit made the
/// solver refute XOR combinations of up to 16 CRC columns at every start (CBMC ran out of memory on
/// a seed 001 IMU frame and did not finish a seed 000 frame), while the exhaustive test
/// `every_burst_by_byte_order` below enumerates every one of them in about a second; the twins
/// `bursts_detected_*` sample the same bodies.
#[cfg(kani)]
#[allow(dead_code)]
mod proofs {
    use statemachine::harness::KaniSource;

    /// P-2: Each block function returns for every register and every block (its contract).
    macro_rules! block_total {
        ($($harness:ident => $f:ident, $n:literal);+) => {$(
            #[kani::proof_for_contract(crate::crc16::$f)]
            fn $harness() {
                let block: [u8; $n] = kani::any();
                let _ = crate::crc16::$f(kani::any(), &block);
            }
        )+};
    }
    block_total!(
        verify_fold16_total => fold16, 16;
        verify_fold8_total => fold8, 8;
        verify_fold4_total => fold4, 4;
        verify_fold2_total => fold2, 2
    );

    /// [`checksum`]'s contract (returns, never panics) for every length up to `TOTAL_MAX`, with
    /// the block functions replaced by their proven contracts: what is left is the walk over the
    /// slice, which is where a symbolic length costs (with the bodies inlined CBMC ran out of
    /// memory after 3 min).
    // MiniSat (CBMC's default) rather than CaDiCaL: 13.2 s against 25.2 s on one build, 12.7 s
    // against 22.2 s on another (`proofs/REPORT.md`, "Kani suite time").
    #[kani::proof]
    #[kani::stub_verified(crate::crc16::fold16)]
    #[kani::stub_verified(crate::crc16::fold8)]
    #[kani::stub_verified(crate::crc16::fold4)]
    #[kani::stub_verified(crate::crc16::fold2)]
    #[kani::unwind(18)]
    #[kani::solver(minisat)]
    fn verify_checksum_total() {
        super::check_checksum_total(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use super::*;
    use crate::crc16::TABLES;
    use statemachine::harness::Twin;

    #[test]
    fn seed_loop_is_checksum() {
        let mut x: u32 = 0x5EED;
        let mut buf = [0u8; TOTAL_MAX];
        for round in 0..20 {
            for b in buf.iter_mut() {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                // Some rounds all zeros or all ones, the others random.
                *b = match round {
                    0 => 0,
                    1 => 0xFF,
                    _ => x as u8,
                };
            }
            for len in 0..=TOTAL_MAX {
                assert_eq!(
                    seed_loop(&buf[..len]),
                    checksum(&buf[..len]),
                    "{round} {len}"
                );
            }
        }
        assert_eq!(seed_loop(b"123456789"), crate::crc16::CHECK);
    }

    #[test]
    fn checksum_total() {
        Twin::run(0xC8C_0003, 20_000, check_checksum_total).assert_covered(2);
    }

    #[test]
    fn bursts_detected_seed000() {
        Twin::run(0xC8C_0001, 200_000, check_bursts_detected_seed000).assert_covered(5);
    }

    #[test]
    fn bursts_detected_seed001_imu() {
        Twin::run(0xC8C_0002, 200_000, check_bursts_detected_seed001_imu).assert_covered(5);
    }

    /// The premise of the module: every slice table is linear over GF(2), for every pair of entries.
    #[test]
    fn tables_are_linear() {
        for (k, t) in TABLES.iter().enumerate() {
            for a in 0..256usize {
                for b in 0..256usize {
                    assert_eq!(t[a ^ b], t[a] ^ t[b], "table {k}, {a} ^ {b}");
                }
            }
        }
    }

    /// The affine identity itself, on random data of every length up to two blocks past a frame.
    #[test]
    fn checksum_is_affine() {
        let mut t = Twin::new(0xAFF1);
        let zeros = [0u8; 96];
        for n in 0..96 {
            for _ in 0..200 {
                let mut x = [0u8; 96];
                let mut y = [0u8; 96];
                for i in 0..n {
                    x[i] = t.u8();
                    y[i] = t.u8();
                }
                let mut xy = [0u8; 96];
                for i in 0..n {
                    xy[i] = x[i] ^ y[i];
                }
                assert_eq!(
                    checksum(&xy[..n]),
                    checksum(&x[..n]) ^ checksum(&y[..n]) ^ checksum(&zeros[..n]),
                    "n {n}"
                );
            }
        }
    }

    /// The shortest burst each byte order lets through, exhaustively for every covered length from
    /// 1 to 62 bytes, every start bit and every pattern of up to 16 bits: none with the CRC
    /// big-endian; 13 bits with it little-endian. This is where [`Order::max_burst`] comes from.
    ///
    /// By the affine identity a pattern passes iff the XOR of its bits' columns is zero, where the
    /// column of bit `j` is the change it makes to (computed CRC ⊕ stored CRC); patterns are walked
    /// in Gray-code order, one XOR each.
    #[test]
    fn every_burst_by_byte_order() {
        for n in 1..=MAX_COVERED {
            let zeros = [0u8; MAX_COVERED];
            let base = checksum(&zeros[..n]);
            let bits = (n + 2) * 8;
            for order in [Order::Big, Order::Little] {
                let column = |j: usize| -> u16 {
                    let mut e = [0u8; MAX_COVERED + 2];
                    set_bit(&mut e, j);
                    syndrome(&e, n, order, base)
                };
                let columns: std::vec::Vec<u16> = (0..bits).map(column).collect();
                let mut shortest = u32::MAX;
                for start in 0..bits {
                    let width = (bits - start).min(16);
                    // Gray code over the bits after the first (which is always wrong).
                    let mut sum = columns[start];
                    let mut pattern: u32 = 1;
                    for k in 1u32..(1 << (width - 1)) {
                        let flip = k.trailing_zeros() as usize + 1;
                        sum ^= columns[start + flip];
                        pattern ^= 1 << flip;
                        if sum == 0 {
                            shortest = shortest.min(32 - pattern.leading_zeros());
                        }
                    }
                    if sum == 0 && width == 1 {
                        shortest = 1;
                    }
                }
                assert!(
                    columns.iter().all(|&c| c != 0),
                    "n {n}: a single-bit error passed"
                );
                match order {
                    Order::Big => assert_eq!(shortest, u32::MAX, "n {n}: a burst passed"),
                    Order::Little => assert_eq!(shortest, order.max_burst() + 1, "n {n}"),
                }
            }
        }
    }
}
