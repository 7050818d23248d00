//! CRC-16/CCITT-FALSE, the checksum of seeds 000, 001 and of the Teensy successor frame.
//!
//! Polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR (the catalogue calls it
//! CRC-16/IBM-3740; the seeds' bitwise C loop computes the same). Check value: `"123456789"` → 0x29B1.

use crc::{Crc, CRC_16_IBM_3740};

/// The CRC engine (table driven, 512 bytes of table in flash).
pub const CCITT_FALSE: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

/// The catalogue check value: the CRC of the ASCII bytes `"123456789"`.
pub const CHECK: u16 = 0x29B1;

/// CRC-16/CCITT-FALSE of `bytes`.
pub const fn checksum(bytes: &[u8]) -> u16 {
    CCITT_FALSE.checksum(bytes)
}

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
