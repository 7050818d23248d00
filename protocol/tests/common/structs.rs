//! Builds the typed values of the `structs_python.txt` golden cases (seeds 001, 003, 004) and encodes
//! them with this crate; shared by `tests/golden.rs` and `examples/golden_emit.rs`.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::panic,
    clippy::arithmetic_side_effects,
    dead_code
)]

use protocol::{cdc, pi_spi, teensy};
use std::collections::HashMap;

/// One case line: kind, frame bytes, values.
pub struct Case {
    pub kind: String,
    pub frame: Vec<u8>,
    pub values: HashMap<String, Vec<i64>>,
}

pub fn parse(text: &str) -> Vec<Case> {
    text.lines()
        .map(|l| {
            let mut it = l.split_whitespace();
            let kind = it.next().unwrap().to_string();
            let hex = it.next().unwrap();
            let frame = (0..hex.len() / 2)
                .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                .collect();
            let values = it
                .map(|p| {
                    let (k, v) = p.split_once('=').unwrap();
                    (
                        k.to_string(),
                        v.split(',').map(|x| x.parse().unwrap()).collect(),
                    )
                })
                .collect();
            Case {
                kind,
                frame,
                values,
            }
        })
        .collect()
}

/// The typed value of a case.
#[derive(Debug, PartialEq)]
pub enum Value {
    Cdc(cdc::Message),
    PiRx(pi_spi::RxBuffer),
    PiTx(pi_spi::TxBuffer),
    Teensy(teensy::CmdMsg<4>),
}

fn arr<const N: usize, T: TryFrom<i64>>(v: &[i64]) -> [T; N]
where
    T::Error: std::fmt::Debug,
{
    let items: Vec<T> = v.iter().map(|&x| T::try_from(x).unwrap()).collect();
    match items.try_into() {
        Ok(a) => a,
        Err(_) => panic!("wrong length"),
    }
}

fn f32s<const N: usize>(v: &[i64]) -> [f32; N] {
    arr::<N, u32>(v).map(f32::from_bits)
}

pub fn value(c: &Case) -> Value {
    let v = |k: &str| c.values[k].as_slice();
    let one = |k: &str| c.values[k][0];
    use cdc::Message as M;
    match c.kind.as_str() {
        "cdc_set_motor_pwm" => Value::Cdc(M::SetMotorPwm(cdc::SetMotorPwm {
            pwm: arr(v("pwm")),
            timeout_ms: one("timeout_ms") as u16,
        })),
        "cdc_motor_enable" => Value::Cdc(M::MotorEnable(one("enable") == 1)),
        "cdc_estop" => Value::Cdc(M::Estop(if one("action") == 1 {
            statemachine::Estop::Engage
        } else {
            statemachine::Estop::Release
        })),
        "cdc_ping" => Value::Cdc(M::Ping),
        "cdc_ack" => Value::Cdc(M::Ack(cdc::Ack {
            msg_id: one("msg_id") as u8,
            result: one("result") as u8,
        })),
        "cdc_imu" => Value::Cdc(M::Imu(cdc::Imu {
            t_ms: one("t_ms") as u32,
            accel_mg: arr(v("accel_mg")),
            gyro_mdps: arr(v("gyro_mdps")),
            temp_cdeg: one("temp_cdeg") as i16,
        })),
        "cdc_status" => Value::Cdc(M::Status(cdc::Status {
            t_ms: one("t_ms") as u32,
            vbat_mv: one("vbat_mv") as u16,
            flags: cdc::StatusFlags(one("flags") as u16),
            err: one("err") as u16,
        })),
        "pi_rx" => {
            use pi_spi::assumed::{KinematicsConfig, MotorPidSettings};
            let pid = f32s::<12>(v("pid"));
            let k = f32s::<16>(v("kinematics"));
            let sh = one("shutdown");
            Value::PiRx(pi_spi::RxBuffer {
                updates: pi_spi::UpdateFlags(one("updates") as u8),
                system_shutdown: pi_spi::Shutdown {
                    servos: sh & 1 != 0,
                    motors: sh & 2 != 0,
                },
                motor_control_mode: arr::<4, u8>(v("motor_modes"))
                    .map(|m| pi_spi::MotorMode::from_raw(m).unwrap()),
                motor_target: arr(v("motor_target")),
                motor_goal_position: arr(v("motor_goal")),
                servo_mode: arr::<4, u8>(v("servo_modes"))
                    .map(|m| pi_spi::ServoMode::from_raw(m).unwrap()),
                servo_pos: arr(v("servo_pos")),
                motor_pid_settings: MotorPidSettings {
                    kp: pid[0..4].try_into().unwrap(),
                    ki: pid[4..8].try_into().unwrap(),
                    kd: pid[8..12].try_into().unwrap(),
                },
                imu_gyro_orientation: arr(v("gyro_orient")),
                imu_compass_orientation: arr(v("compass_orient")),
                kinematics: KinematicsConfig {
                    inverse: [
                        k[0..4].try_into().unwrap(),
                        k[4..8].try_into().unwrap(),
                        k[8..12].try_into().unwrap(),
                    ],
                    ticks_to_rad: k[12..16].try_into().unwrap(),
                },
            })
        }
        "pi_tx" => {
            use pi_spi::assumed::{QuaternionData, SensorData};
            let imu = v("imu");
            let s = |i: usize| SensorData {
                x: f32::from_bits(imu[4 * i] as u32),
                y: f32::from_bits(imu[4 * i + 1] as u32),
                z: f32::from_bits(imu[4 * i + 2] as u32),
                accuracy: imu[4 * i + 3] as i8,
            };
            let q = f32s::<4>(v("quat"));
            let o = f32s::<6>(v("odometry"));
            Value::PiTx(pi_spi::TxBuffer {
                update_time: one("update_time") as u32,
                motor: pi_spi::MotorData {
                    bemf: arr(v("bemf")),
                    position: arr(v("position")),
                    done: one("done") as u8,
                },
                analog_sensor: arr(v("analog")),
                battery_voltage: one("battery") as i16,
                digital_sensors: one("digital") as u16,
                imu: pi_spi::ImuData {
                    gyro: s(0),
                    accel: s(1),
                    compass: s(2),
                    linear_accel: s(3),
                    accel_velocity: s(4),
                    dmp_quat: QuaternionData {
                        w: q[0],
                        x: q[1],
                        y: q[2],
                        z: q[3],
                    },
                    heading: f32::from_bits(one("heading") as u32),
                    temperature: f32::from_bits(one("temperature") as u32),
                },
                odometry: pi_spi::OdometryData {
                    pos_x: o[0],
                    pos_y: o[1],
                    heading: o[2],
                    vx: o[3],
                    vy: o[4],
                    wz: o[5],
                },
            })
        }
        "teensy_legacy" | "teensy_robust" => Value::Teensy(teensy::CmdMsg {
            cmd_type: teensy::CmdType::from_raw(one("cmd_type") as i32).unwrap(),
            is_relative: one("is_relative") as i32,
            mtr_angles: arr(v("angles")),
            mtr_speed_deg_s: one("speed") as i32,
            mtr_accel_deg_s_s: one("accel") as i32,
            cmd_success: one("success") as i32,
        }),
        other => panic!("unknown kind {other}"),
    }
}

/// Encodes a case's value with this crate.
pub fn encode(c: &Case) -> Vec<u8> {
    match value(c) {
        Value::Cdc(m) => {
            let mut out = [0u8; cdc::MAX_FRAME_LEN];
            let n = m.encode(&mut out);
            out[..n].to_vec()
        }
        Value::PiRx(rx) => {
            let mut out = [0u8; pi_spi::RX_LEN];
            pi_spi::encode_rx(&rx, &mut out);
            out.to_vec()
        }
        Value::PiTx(tx) => {
            let mut out = [0u8; pi_spi::TX_LEN];
            pi_spi::encode_tx(&tx, &mut out);
            out.to_vec()
        }
        Value::Teensy(m) => {
            let mut out = [0u8; teensy::ROBUST_BUF];
            let n = if c.kind == "teensy_legacy" {
                m.encode_legacy(&mut out)
            } else {
                m.encode_robust(&mut out)
            };
            out[..n.unwrap()].to_vec()
        }
    }
}

/// Decodes a case's frame with this crate.
pub fn decode(c: &Case) -> Result<Value, String> {
    fn e(x: impl std::fmt::Debug) -> String {
        format!("{x:?}")
    }
    Ok(match c.kind.as_str() {
        k if k.starts_with("cdc_") => Value::Cdc(cdc::decode_frame(&c.frame).map_err(e)?),
        "pi_rx" => Value::PiRx(pi_spi::decode_rx(&c.frame.clone().try_into().unwrap()).map_err(e)?),
        "pi_tx" => Value::PiTx(pi_spi::decode_tx(&c.frame.clone().try_into().unwrap()).map_err(e)?),
        "teensy_legacy" => Value::Teensy(teensy::CmdMsg::decode_legacy(&c.frame).map_err(e)?),
        "teensy_robust" => Value::Teensy(teensy::CmdMsg::decode_robust(&c.frame).map_err(e)?),
        other => return Err(format!("unknown kind {other}")),
    })
}
