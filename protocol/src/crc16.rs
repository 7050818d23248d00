//! CRC-16/CCITT-FALSE, the checksum of seeds 000, 001 and of the Teensy successor frame.
//!
//! Polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR (the catalogue calls it
//! CRC-16/IBM-3740; the seeds' bitwise C loop computes the same). Check value: `"123456789"` → 0x29B1.

use crc::{Crc, CRC_16_IBM_3740};

/// The catalogue engine of the `crc` crate (one 512-byte table, a byte per step): the reference
/// [`checksum`] is tested against.
pub const CCITT_FALSE: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

/// The catalogue check value: the CRC of the ASCII bytes `"123456789"`.
pub const CHECK: u16 = 0x29B1;

/// The generator polynomial (x¹⁶ + x¹² + x⁵ + 1, the x¹⁶ term implied).
const POLY: u16 = 0x1021;
/// The register's initial value.
const INIT: u16 = 0xFFFF;

/// Slice-by-16 tables, 8 KiB of flash: `TABLES[k][b]` is the register after feeding byte `b` and
/// then `k` zero bytes into a zero register. Feeding a block of `n` bytes is then one lookup per
/// byte, in table `n − 1 − i` for byte `i`, with the old register XORed into the first two bytes.
static TABLES: [[u16; 256]; 16] = tables();

/// Builds [`TABLES`] at compile time (an out-of-bounds index here is a build error, not a panic).
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
const fn tables() -> [[u16; 256]; 16] {
    let mut t = [[0u16; 256]; 16];
    let mut b = 0;
    while b < 256 {
        let mut reg = (b as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            reg = if reg & 0x8000 != 0 {
                (reg << 1) ^ POLY
            } else {
                reg << 1
            };
            bit += 1;
        }
        t[0][b] = reg;
        b += 1;
    }
    let mut k = 1;
    while k < 16 {
        let mut b = 0;
        while b < 256 {
            let prev = t[k - 1][b];
            t[k][b] = (prev << 8) ^ t[0][(prev >> 8) as usize];
            b += 1;
        }
        k += 1;
    }
    t
}

/// One lookup (`b` < 256, so the `get` never fails and compiles to a plain load).
#[inline(always)]
fn at(table: &[u16; 256], b: u8) -> u16 {
    table.get(usize::from(b)).copied().unwrap_or(0)
}

/// `fn $name(reg, &[u8; $n]) -> reg`: feeds a block of `$n` bytes, byte `i` through table `k`.
///
/// Under Kani each block function carries a contract that says only "returns, for every register
/// and block" (no panic); `crc16::verification` proves it and then lets the proof that
/// [`checksum`] is total use the contract in place of the body (`kani::stub_verified`).
macro_rules! slice_by {
    ($name:ident, $n:literal, [$($i:literal => $k:literal),+]) => {
        #[inline(always)]
        #[cfg_attr(kani, kani::ensures(|_: &u16| true))]
        fn $name(reg: u16, block: &[u8; $n]) -> u16 {
            let [hi, lo] = reg.to_be_bytes();
            let mut bytes = *block;
            bytes[0] ^= hi;
            bytes[1] ^= lo;
            0 $(^ at(&TABLES[$k], bytes[$i]))+
        }
    };
}

slice_by!(fold16, 16, [0 => 15, 1 => 14, 2 => 13, 3 => 12, 4 => 11, 5 => 10, 6 => 9, 7 => 8,
    8 => 7, 9 => 6, 10 => 5, 11 => 4, 12 => 3, 13 => 2, 14 => 1, 15 => 0]);
slice_by!(fold8, 8, [0 => 7, 1 => 6, 2 => 5, 3 => 4, 4 => 3, 5 => 2, 6 => 1, 7 => 0]);
slice_by!(fold4, 4, [0 => 3, 1 => 2, 2 => 1, 3 => 0]);
slice_by!(fold2, 2, [0 => 1, 1 => 0]);

/// CRC-16/CCITT-FALSE of `bytes`: 16 bytes per step, then the rest in blocks of 8, 4, 2 and 1
/// (a 62-byte link frame body is 3 × 16 + 8 + 4 + 2).
pub fn checksum(bytes: &[u8]) -> u16 {
    let mut reg = INIT;
    let mut rest = bytes;
    while let Some((block, tail)) = rest.split_first_chunk::<16>() {
        reg = fold16(reg, block);
        rest = tail;
    }
    if let Some((block, tail)) = rest.split_first_chunk::<8>() {
        reg = fold8(reg, block);
        rest = tail;
    }
    if let Some((block, tail)) = rest.split_first_chunk::<4>() {
        reg = fold4(reg, block);
        rest = tail;
    }
    if let Some((block, tail)) = rest.split_first_chunk::<2>() {
        reg = fold2(reg, block);
        rest = tail;
    }
    if let Some(&b) = rest.first() {
        let [hi, _] = reg.to_be_bytes();
        reg = (reg << 8) ^ at(&TABLES[0], hi ^ b);
    }
    reg
}

#[cfg(any(test, kani))]
pub(crate) mod verification;

#[cfg(test)]
mod tests {
    use super::*;

    /// The seed's C loop, transcribed bit for bit: an independent implementation to compare with.
    fn seed_bitwise(data: &[u8]) -> u16 {
        let mut crc: u16 = 0xFFFF;
        for &b in data {
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

    #[test]
    fn catalogue_check_value() {
        assert_eq!(checksum(b"123456789"), 0x29B1);
        assert_eq!(CHECK, 0x29B1);
    }

    #[test]
    fn tables_are_the_seed_loop_over_zero_extended_bytes() {
        // TABLES[k][b]: the seed loop run from a zero register over b and k zero bytes, for every
        // table entry (the CRC has no final XOR, so a zero initial register gives the raw remainder).
        for k in 0..16 {
            for b in 0..=255u8 {
                let mut reg: u16 = 0;
                let mut msg = [0u8; 16];
                msg[0] = b;
                for &byte in &msg[..=k] {
                    reg ^= u16::from(byte) << 8;
                    for _ in 0..8 {
                        reg = if reg & 0x8000 != 0 {
                            (reg << 1) ^ 0x1021
                        } else {
                            reg << 1
                        };
                    }
                }
                assert_eq!(TABLES[k][usize::from(b)], reg, "k {k} b {b}");
            }
        }
    }

    #[test]
    fn fast_path_matches_the_crc_crate_at_every_length_and_offset() {
        let mut x: u32 = 7;
        let mut buf = [0u8; 200];
        for b in buf.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *b = x as u8;
        }
        for start in 0..17 {
            for end in start..buf.len() {
                let part = &buf[start..end];
                assert_eq!(checksum(part), CCITT_FALSE.checksum(part), "{start}..{end}");
            }
        }
    }

    #[test]
    fn table_engine_matches_the_seed_loop() {
        let mut x: u32 = 1;
        let mut buf = [0u8; 300];
        for len in 0..buf.len() {
            for b in buf.iter_mut() {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *b = x as u8;
            }
            assert_eq!(
                checksum(&buf[..len]),
                seed_bitwise(&buf[..len]),
                "len {len}"
            );
        }
    }
}
