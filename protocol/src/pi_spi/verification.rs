//! Kani harnesses of the seed 004 buffers and their `cargo test` twins.

// Under Kani the bodies that only twins call, and the stand-ins that only `kani::stub` names,
// are unused as far as rustc can see.
#![cfg_attr(kani, allow(dead_code))]

use super::*;
use statemachine::harness::Source;
use statemachine::{check, cover, fail};

fn any_motor_mode(src: &mut impl Source) -> MotorMode {
    MotorMode::from_raw(src.below(5)).unwrap_or_default()
}

fn any_servo_mode(src: &mut impl Source) -> ServoMode {
    ServoMode::from_raw(src.below(3)).unwrap_or_default()
}

fn f32x4(src: &mut impl Source) -> [f32; 4] {
    [src.f32(), src.f32(), src.f32(), src.f32()]
}

fn i8x9(src: &mut impl Source) -> [i8; 9] {
    let mut out = [0i8; 9];
    #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
    for i in 0..9 {
        out[i] = src.u8() as i8;
    }
    out
}

pub(crate) fn any_rx(src: &mut impl Source) -> RxBuffer {
    RxBuffer {
        updates: UpdateFlags(src.u8() & UpdateFlags::ALL),
        system_shutdown: Shutdown {
            servos: src.bool(),
            motors: src.bool(),
        },
        motor_control_mode: [
            any_motor_mode(src),
            any_motor_mode(src),
            any_motor_mode(src),
            any_motor_mode(src),
        ],
        motor_target: [src.i32(), src.i32(), src.i32(), src.i32()],
        motor_goal_position: [src.i32(), src.i32(), src.i32(), src.i32()],
        servo_mode: [
            any_servo_mode(src),
            any_servo_mode(src),
            any_servo_mode(src),
            any_servo_mode(src),
        ],
        servo_pos: [src.u16(), src.u16(), src.u16(), src.u16()],
        motor_pid_settings: MotorPidSettings {
            kp: f32x4(src),
            ki: f32x4(src),
            kd: f32x4(src),
        },
        imu_gyro_orientation: i8x9(src),
        imu_compass_orientation: i8x9(src),
        kinematics: KinematicsConfig {
            inverse: [f32x4(src), f32x4(src), f32x4(src)],
            ticks_to_rad: f32x4(src),
        },
    }
}

/// P-4: `decode_rx` and `decode_tx` return a buffer or a typed error for every input.
pub(crate) fn check_decode_total(src: &mut impl Source) {
    let mut rx = [0u8; RX_LEN];
    // Under Kani any bytes already include every buffer; the twin would not draw a valid one at
    // random, so half its cases are encoded buffers with one checked byte replaced.
    if cfg!(kani) || src.bool() {
        rx = src.bytes();
    } else {
        // A valid buffer with one of its first 41 bytes (the checked fields) replaced.
        encode_rx(&any_rx(src), &mut rx);
        let i = usize::from(src.below(41));
        rx[i] = src.u8();
    }
    let r = decode_rx(&rx);
    check!(
        matches!(
            r,
            Ok(_) | Err(RejectReason::Version | RejectReason::Parity | RejectReason::Decode)
        ),
        "P-4: decode_rx returns a buffer or one of its typed errors"
    );
    let tx: [u8; TX_LEN] = src.bytes();
    let t = decode_tx(&tx);
    check!(
        matches!(t, Ok(_) | Err(RejectReason::Version)),
        "P-4: decode_tx returns a buffer or Version"
    );
    cover!(src, r.is_ok(), "rx decoded");
    cover!(src, r == Err(RejectReason::Version), "rx version error");
    cover!(src, r == Err(RejectReason::Parity), "rx parity error");
    cover!(src, r == Err(RejectReason::Decode), "rx decode error");
}

/// P-6: encode → decode gives back the received buffer (Pi → STM32), bit for bit, every field
/// symbolic.
pub(crate) fn check_rx_round_trip(src: &mut impl Source) {
    let rx = any_rx(src);
    let mut b = [0u8; RX_LEN];
    encode_rx(&rx, &mut b);
    let d = decode_rx(&b);
    // Compare the bytes of a re-encoding: floats then compare bit for bit (NaN included).
    let mut again = [0u8; RX_LEN];
    match d {
        Ok(d) => encode_rx(&d, &mut again),
        Err(_) => fail!("P-6: valid rx refused"),
    }
    check!(
        b == again,
        "P-6: the received buffer re-encodes to the same bytes"
    );
    check!(
        parity_ok(u32::from_le_bytes([b[1], b[2], b[3], b[4]])),
        "P-6: an encoded buffer has a good parity"
    );
    cover!(
        src,
        rx.updates.0.count_ones().is_multiple_of(2),
        "parity bit set"
    );
    cover!(src, rx.updates.0.count_ones() % 2 == 1, "parity bit clear");
}

/// P-6: encode → decode gives back the transmitted buffer (STM32 → Pi), bit for bit: a field of
/// each width and kind symbolic (the 32-bit time, a motor word, an IMU byte, two floats), the
/// others zero.
pub(crate) fn check_tx_round_trip(src: &mut impl Source) {
    let mut tx = TxBuffer {
        update_time: src.u32(),
        ..Default::default()
    };
    tx.motor.bemf[0] = src.i32();
    tx.imu.gyro.accuracy = src.u8() as i8;
    tx.imu.heading = src.f32();
    tx.odometry.wz = src.f32();
    let mut t = [0u8; TX_LEN];
    encode_tx(&tx, &mut t);
    let mut t2 = [0u8; TX_LEN];
    match decode_tx(&t) {
        Ok(d) => encode_tx(&d, &mut t2),
        Err(_) => fail!("P-6: valid tx refused"),
    }
    check!(t == t2, "P-6: the transmitted buffer decodes to itself");
    cover!(src, tx.imu.heading.is_nan(), "a NaN heading");
}

/// P-7: A single flipped bit in the `updates` word is always caught by the parity check.
pub(crate) fn check_updates_bit_flip_detected(src: &mut impl Source) {
    let rx = any_rx(src);
    let mut b = [0u8; RX_LEN];
    encode_rx(&rx, &mut b);
    let bit = usize::from(src.below(32));
    b[1 + bit / 8] ^= 1 << (bit % 8);
    check!(
        decode_rx(&b) == Err(RejectReason::Parity),
        "P-7: a flip in the updates word is refused as Parity"
    );
    cover!(src, bit == 7, "flip of the parity bit");
    cover!(src, bit < 7, "flip of an update flag");
    cover!(src, bit > 7, "flip of a reserved bit");
}

/// INV-22 (bytes half): The checks come first and in the seed's order, for any bytes: a `transferVersion` other than 15
/// is `Err(Version)` whatever follows it; with version 15, an `updates` word of even parity is
/// `Err(Parity)` whatever follows it. (The bytes half of the `pi-spi` board's INV-22; the board's
/// half, a refusal changes nothing, is `mcu`'s `verify_pi_spi_refusal_changes_nothing`.)
pub(crate) fn check_version_and_parity_first(src: &mut impl Source) {
    let buf: [u8; RX_LEN] = src.bytes();
    version_and_parity_of(src, buf);
}

fn version_and_parity_of(src: &mut impl Source, buf: [u8; RX_LEN]) {
    use statemachine::check;
    let [v, u0, u1, u2, u3, ..] = buf;
    let parity = parity_ok(u32::from_le_bytes([u0, u1, u2, u3]));
    let r = decode_rx(&buf);
    if v != TRANSFER_VERSION {
        check!(
            r == Err(RejectReason::Version),
            "INV-22: a wrong transferVersion is refused as Version"
        );
    } else if !parity {
        check!(
            r == Err(RejectReason::Parity),
            "INV-22: a wrong parity is refused as Parity"
        );
    }
    cover!(src, v != TRANSFER_VERSION, "wrong version");
    cover!(src, v == TRANSFER_VERSION && !parity, "wrong parity");
    #[cfg(not(kani))]
    cover!(src, r.is_ok(), "a buffer that decodes");
}

/// Kani harnesses (`cargo kani -p protocol --harness pi_spi::`). Every field of the buffers is
/// symbolic; the writers use one plain loop per array (`le::Writer::f32s` and kin) so that CBMC
/// unrolls each to its exact length.
#[cfg(kani)]
mod proofs {
    use super::*;
    use statemachine::harness::KaniSource;

    #[kani::proof]
    #[kani::unwind(180)]
    fn verify_decode_total() {
        check_decode_total(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(180)]
    fn verify_rx_round_trip() {
        check_rx_round_trip(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(180)]
    fn verify_tx_round_trip() {
        check_tx_round_trip(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(180)]
    fn verify_updates_bit_flip_detected() {
        check_updates_bit_flip_detected(&mut KaniSource);
    }

    #[kani::proof]
    #[kani::unwind(180)]
    fn verify_version_and_parity_first() {
        check_version_and_parity_first(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    use super::*;
    use statemachine::harness::Twin;

    #[test]
    fn decode_total() {
        Twin::run(0x5B_0001, 20_000, check_decode_total).assert_covered(4);
    }

    #[test]
    fn rx_round_trip() {
        Twin::run(0x5B_0002, 10_000, check_rx_round_trip).assert_covered(2);
    }

    #[test]
    fn tx_round_trip() {
        Twin::run(0x5B_0005, 10_000, check_tx_round_trip).assert_covered(1);
    }

    #[test]
    fn updates_bit_flip_detected() {
        Twin::run(0x5B_0003, 10_000, check_updates_bit_flip_detected).assert_covered(3);
    }

    #[test]
    fn version_and_parity_first() {
        // Random bytes reach version 15 once in 256 and decode almost never: half the cases are
        // encoded buffers with one of the first bytes perhaps broken.
        Twin::run(0x5B_0004, 40_000, |src| {
            if src.bool() {
                check_version_and_parity_first(src);
                return;
            }
            let rx = any_rx(src);
            let mut buf = [0u8; RX_LEN];
            encode_rx(&rx, &mut buf);
            match src.below(3) {
                0 => buf[0] = src.u8(),
                1 => buf[1 + usize::from(src.below(4))] ^= 1 << src.below(8),
                _ => {}
            }
            version_and_parity_of(src, buf);
        })
        .assert_covered(3);
    }
}
