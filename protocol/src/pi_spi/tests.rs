//! Unit tests of the seed 004 buffers: offsets, parity, mode packing, shutdown.

use super::*;

#[test]
fn sizes_and_offsets_from_the_seed() {
    assert_eq!(TX_LEN, 167);
    assert_eq!(RX_LEN, 179);
    assert_eq!(TRANSFER_LEN, 179);
    let rx = RxBuffer {
        system_shutdown: Shutdown {
            servos: false,
            motors: true,
        },
        motor_target: [0x0102_0304, 0, 0, -1],
        kinematics: assumed::KinematicsConfig {
            ticks_to_rad: [0.0, 0.0, 0.0, 1.0],
            ..Default::default()
        },
        ..Default::default()
    };
    let mut b = [0u8; RX_LEN];
    encode_rx(&rx, &mut b);
    assert_eq!(b[0], 15);
    assert_eq!(b[1..5], [0x80, 0, 0, 0]); // no flags: the parity bit alone
    assert_eq!(b[5], 0b10);
    assert_eq!(b[8..12], [0x04, 0x03, 0x02, 0x01]);
    assert_eq!(b[20..24], [0xFF; 4]);
    assert_eq!(b[175..179], 1.0f32.to_le_bytes());
    assert_eq!(decode_rx(&b), Ok(rx));
}

#[test]
fn parity_rule() {
    // bit 7 set exactly when bits 0-6 hold an even number of ones.
    assert_eq!(updates_word(UpdateFlags(0)), 0x80);
    assert_eq!(
        updates_word(UpdateFlags(UpdateFlags::MOTOR_PID_SPEED)),
        0x01
    );
    assert_eq!(updates_word(UpdateFlags(0b11)), 0x83);
    assert_eq!(updates_word(UpdateFlags(0x3F)), 0xBF);
    assert!(parity_ok(0x80) && parity_ok(0x01) && parity_ok(0x83));
    assert!(!parity_ok(0) && !parity_ok(0x81) && !parity_ok(0x03));
    let mut b = [0u8; RX_LEN];
    encode_rx(&RxBuffer::default(), &mut b);
    b[1] = 0x00; // parity bit dropped
    assert_eq!(decode_rx(&b), Err(RejectReason::Parity));
    b[1] = 0x40 | 0x01 | 0x80; // odd count, but bit 6 is reserved
    assert_eq!(decode_rx(&b), Err(RejectReason::Decode));
}

#[test]
fn mode_packing() {
    use MotorMode::*;
    assert_eq!(
        pack_motor_modes([Mtp, Mav, Pwm, PassiveBrake]),
        0b001_010_011_100
    );
    assert_eq!(
        unpack_motor_modes(0b001_010_011_100),
        Some([Mtp, Mav, Pwm, PassiveBrake])
    );
    assert_eq!(unpack_motor_modes(0b101), None); // mode 5
    assert_eq!(unpack_motor_modes(1 << 12), None); // reserved bit
    use ServoMode::*;
    assert_eq!(
        pack_servo_modes([Enabled, Disabled, FullyDisabled, Enabled]),
        0b10_00_01_10
    );
    assert_eq!(
        unpack_servo_modes(0b10_00_01_10),
        Some([Enabled, Disabled, FullyDisabled, Enabled])
    );
    assert_eq!(unpack_servo_modes(0b11 << 4), None);
}

#[test]
fn version_and_shutdown() {
    let mut b = [0u8; RX_LEN];
    encode_rx(&RxBuffer::default(), &mut b);
    b[5] = 0b10;
    assert!(shutdown_raw(&b).motors);
    b[0] = 14;
    assert_eq!(decode_rx(&b), Err(RejectReason::Version));
    // The fail-safe reader still sees the shutdown bit of a buffer that does not decode.
    assert!(shutdown_raw(&b).motors);
    b[0] = 15;
    b[5] = 0b100;
    assert_eq!(decode_rx(&b), Err(RejectReason::Decode));
    let mut t = [0u8; TX_LEN];
    encode_tx(&TxBuffer::default(), &mut t);
    t[0] = 16;
    assert_eq!(decode_tx(&t), Err(RejectReason::Version));
}

#[test]
fn commands_for_the_ladder() {
    let mut rx = RxBuffer {
        motor_control_mode: [
            MotorMode::Mav,
            MotorMode::Mav,
            MotorMode::Off,
            MotorMode::Off,
        ],
        motor_target: [100, -50, 0, 0],
        ..Default::default()
    };
    use statemachine::AxisCommand;
    let c = rx.to_command(0.01);
    assert_eq!(
        c.axes,
        [
            AxisCommand::velocity(1.0),
            AxisCommand::velocity(-0.5),
            AxisCommand::COAST,
            AxisCommand::COAST
        ]
    );
    assert!(c.enable);
    // Every motor in its own mode: PWM 0–399 as a fraction, MTP to the goal under |target| as the cap.
    rx.motor_control_mode = [
        MotorMode::Pwm,
        MotorMode::PassiveBrake,
        MotorMode::Mtp,
        MotorMode::Off,
    ];
    rx.motor_target = [399, 0, -200, 0];
    rx.motor_goal_position = [0, 0, 300, 0];
    let c = rx.to_command(0.01);
    assert_eq!(
        c.axes,
        [
            AxisCommand::duty(1.0),
            AxisCommand::SHORT,
            AxisCommand::position(3.0, 2.0),
            AxisCommand::COAST
        ]
    );
    rx.system_shutdown.motors = true;
    let [shutdown, frame] = rx.to_events(0.01);
    assert_eq!(shutdown, Event::Shutdown(true));
    assert!(matches!(frame, Event::Frame(Command { enable: false, .. })));
}

#[test]
fn update_flags_are_the_seeds_bits() {
    // The seed's table of `updates`: bits 0 to 5 are the one-shot flags, bit 7 the parity bit.
    assert_eq!(UpdateFlags::MOTOR_PID_SPEED, 0x01);
    assert_eq!(UpdateFlags::MOTOR_PID_POS, 0x02);
    assert_eq!(UpdateFlags::IMU_ORIENTATION, 0x04);
    assert_eq!(UpdateFlags::SAVE_IMU_CAL, 0x08);
    assert_eq!(UpdateFlags::KINEMATICS, 0x10);
    assert_eq!(UpdateFlags::ODOM_RESET, 0x20);
    assert_eq!(UpdateFlags::PARITY_BIT, 0x80);
    // KINEMATICS and ODOM_RESET: 0x30, two ones, so the parity bit is added on the wire.
    let rx = RxBuffer {
        updates: UpdateFlags(UpdateFlags::KINEMATICS | UpdateFlags::ODOM_RESET),
        ..Default::default()
    };
    let mut b = [0u8; RX_LEN];
    encode_rx(&rx, &mut b);
    assert_eq!(b[1..5], [0xB0, 0, 0, 0]);
}

#[test]
fn shutdown_raw_reads_each_bit_on_its_own() {
    // The seed: bit 0 disables the servos, bit 1 the motors; the other bits say nothing.
    let mut b = [0u8; RX_LEN];
    for (byte, servos, motors) in [
        (0x00, false, false),
        (0x01, true, false),
        (0x02, false, true),
        (0x03, true, true),
        (0xFC, false, false),
    ] {
        b[RX_SHUTDOWN_OFFSET] = byte;
        assert_eq!(
            shutdown_raw(&b),
            Shutdown { servos, motors },
            "byte {byte:#04x}"
        );
    }
}

#[test]
fn each_servo_mode_in_its_own_two_bits() {
    // The seed: servo n in bits 2n+1..2n of `servoMode`, ENABLED = 2. One servo enabled at a time.
    use ServoMode::{Enabled, FullyDisabled as Off};
    for (modes, byte) in [
        ([Enabled, Off, Off, Off], 0x02),
        ([Off, Enabled, Off, Off], 0x08),
        ([Off, Off, Enabled, Off], 0x20),
        ([Off, Off, Off, Enabled], 0x80),
    ] {
        assert_eq!(pack_servo_modes(modes), byte);
        assert_eq!(unpack_servo_modes(byte), Some(modes));
        let rx = RxBuffer {
            servo_mode: modes,
            ..Default::default()
        };
        let mut b = [0u8; RX_LEN];
        encode_rx(&rx, &mut b);
        assert_eq!(b[40], byte); // `servoMode` at offset 40
        assert_eq!(decode_rx(&b).map(|d| d.servo_mode), Ok(modes));
    }
}
