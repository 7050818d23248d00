//! The frame tools behind `motorlink decode` and `motorlink encode`: every seed's frames to and from JSON
//! (and, in [`info`], `motorlink info`: the MCU's identity from a capture or a live link; in
//! [`device`], the verbs that talk to a serial board; in [`pi`], the seed 004 verbs over spidev).
//!
//! Each function returns the text to print or an error message that names the problem and the fix;
//! none panics, whatever the input. The JSON shapes are listed in [`SHAPES`] (printed by
//! `motorlink decode --help`) and in `host/README.md`; `decode` prints exactly the JSON that
//! `encode` takes, so `encode(decode(x)) == x` for every valid frame.

use protocol::{amr, cdc, pi_spi, teensy};
use serde::{Deserialize, Serialize};
use statemachine::{Estop, RejectReason};

pub mod amr_link;
pub mod device;
pub mod exit;
pub mod info;
pub mod pi;

/// The frame kinds of every link.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FrameKind {
    /// AMR SPI link command frame (Jetson → MCU), 64 bytes.
    AmrCommand,
    /// AMR SPI link feedback frame (MCU → Jetson), 64 bytes.
    AmrFeedback,
    /// AMR SPI link identity frame `McuInfo` (MCU → Jetson, in the feedback slot after a command
    /// with request 1), 64 bytes.
    AmrInfo,
    /// USB CDC four-motor link frame (USB CDC / UART) `AA 55 | id | len | payload | crc` (decode also takes a capture).
    Cdc,
    /// Raspberry Pi SPI link, Pi → STM32 `RxBuffer`, 179 bytes.
    PiRx,
    /// Raspberry Pi SPI link, STM32 → Pi `TxBuffer`, 167 bytes (or a whole 179-byte transfer).
    PiTx,
    /// Teensy serial link legacy `CmdMsg` packet ending in `\n`, 21 + 4·motors bytes.
    TeensyLegacy,
    /// Teensy serial link robust `CmdMsg` frame: COBS(version 2 | CmdMsg), 3 check bytes of the CRC over those bytes, 00 (decode also takes a capture).
    TeensyRobust,
}

/// Default `--motors` (the seed's `MAX_SUPPORTED_MTRS`).
pub const DEFAULT_MOTORS: usize = 4;

/// The JSON shape of every frame kind, one example each (also in `host/README.md`).
pub const SHAPES: &str = r#"JSON shapes (decode prints them, encode takes them; in encode a missing field is 0 / false /
the first enum value, an unknown field or a wrong type is an error naming the field):

amr-command   {"timestamp_us":1000,"left_speed_cmd":1.5,"right_speed_cmd":-1.5,"control_mode":1,"enable":true,"seq":1,"request":0}
amr-feedback  {"timestamp_us":5,"left_speed":0.5,"right_speed":-0.5,"left_current":1.25,"right_current":0.75,"left_encoder":-3,"right_encoder":7,"fault_flags":2,"seq":9,"mode":1,"cmd_seq":8}
amr-info      {"fw_version":66051,"git_hash":439041101,"board":"amr_spi","build_date":20261130,"reset_cause":"independent_watchdog","reset_count":2,"panic_line":0,"seq":1234,"dirty":false}
cdc           {"type":"set_motor_pwm","pwm":[-1000,1000,0,1],"timeout_ms":200}
              {"type":"motor_enable","enable":true}        (required field)
              {"type":"estop","action":"engage"}           (required field; "engage" | "release")
              {"type":"ping"}
              {"type":"ack","msg_id":3,"result":0}
              {"type":"imu","t_ms":123456,"accel_mg":[0,-1000,1000],"gyro_mdps":[5,-5,32767],"temp_cdeg":2512}
              {"type":"status","t_ms":4294967295,"vbat_mv":12600,"flags":11,"err":4}
pi-rx         {"updates":19,"system_shutdown":{"servos":false,"motors":true},"motor_control_mode":["mav","mav","mtp","passive_brake"],"motor_target":[100,-100,399,0],"motor_goal_position":[123456,-1,0,2147483647],"servo_mode":["enabled","disabled","fully_disabled","enabled"],"servo_pos":[600,2600,1500,0],"motor_pid_settings":{"kp":[1.5,2.5,0.25,-1.0],"ki":[0.125,0.0,3.0,4.0],"kd":[0.5,0.75,0.001,100.0]},"imu_gyro_orientation":[1,0,0,0,-1,0,0,0,1],"imu_compass_orientation":[0,1,0,1,0,0,0,0,-1],"kinematics":{"inverse":[[0.25,0.25,0.25,0.25],[-0.25,0.25,0.25,-0.25],[-1.5,1.5,-1.5,1.5]],"ticks_to_rad":[0.001,0.001,0.002,0.002]}}
pi-tx         {"update_time":987654321,"motor":{"bemf":[1,-2,3,-4],"position":[100000,-100000,7,0],"done":5},"analog_sensor":[0,4095,2048,1,2,3],"battery_voltage":3000,"digital_sensors":1027,"imu":{"gyro":{"x":0.5,"y":-0.5,"z":9.81,"accuracy":3},"accel":{"x":1.0,"y":2.0,"z":3.0,"accuracy":2},"compass":{"x":-40.0,"y":12.0,"z":30.0,"accuracy":1},"linear_accel":{"x":0.1,"y":0.2,"z":0.0,"accuracy":0},"accel_velocity":{"x":0.01,"y":0.0,"z":-0.01,"accuracy":-1},"dmp_quat":{"w":1.0,"x":0.0,"y":0.0,"z":0.0},"heading":359.5,"temperature":36.6},"odometry":{"pos_x":1.25,"pos_y":-2.5,"heading":3.0,"vx":0.5,"vy":0.0,"wz":-0.75}}
teensy-legacy {"cmd_type":"mtrs","is_relative":1,"mtr_angles":[90,-90,2570,2147483647],"mtr_speed_deg_s":30,"mtr_accel_deg_s_s":-60,"cmd_success":1}
teensy-robust (the same shape as teensy-legacy)

Fields:
  amr-command request: 0 none, 1 identity (the MCU answers with an amr-info frame in the next
    feedback slot; `motorlink info` does this for you).
  amr-info fw_version: major << 16 | minor << 8 | patch (66051 = 1.2.3); git_hash: the first 8 hex
    digits of the commit as a number (439041101 = 1a2b3c4d, 0 unknown); build_date: YYYYMMDD;
    board: "amr_spi" | "cdc" | "teensy" | "pi_spi";
    reset_cause: "unknown" | "power_on" | "pin" | "independent_watchdog" | "panic" | "software" |
    "brownout" | "window_watchdog" | "low_power"; panic_line: 0 if none.
  pi-rx updates: flags bits 0-5 (the parity bit 7 is added by encode, checked by decode);
    motor_control_mode: "off" | "passive_brake" | "pwm" | "mav" | "mtp";
    servo_mode: "fully_disabled" | "disabled" | "enabled"; transferVersion (15) is implicit.
  teensy cmd_type: "mtrs" | "cal" | "endeff_on" | "endeff_off" | "config"; mtr_angles has exactly
    --motors entries (missing: all zero).
  cdc: decode of a capture (several frames, garbage) prints
    {"results":[{"message":{..}} | {"error":{..}}, ..],"stats":{"frames":..,"crc_errors":..,"message_errors":..,"dropped_bytes":..},"incomplete_bytes":..}
  teensy-robust: decode of a capture prints the same with "stats":{"frames":..,"errors":..,"dropped_bytes":..}.
  Floats print as the shortest decimal that reads back to the same f32; NaN and infinities print as
  null and cannot be encoded.
"#;

/// A seed 001 message as JSON: `{"type": "<message>", <fields>}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum CdcJson {
    /// 0x01.
    SetMotorPwm(cdc::SetMotorPwm),
    /// 0x02.
    MotorEnable {
        /// true = enable.
        enable: bool,
    },
    /// 0x03.
    Estop {
        /// engage (1) or release (0).
        action: EstopAction,
    },
    /// 0x10.
    Ping,
    /// 0x7F.
    Ack(cdc::Ack),
    /// 0x81.
    Imu(cdc::Imu),
    /// 0x82.
    Status(cdc::Status),
}

/// `ESTOP.action` in JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EstopAction {
    /// action = 1: engage and latch.
    Engage,
    /// action = 0: release.
    Release,
}

impl From<cdc::Message> for CdcJson {
    fn from(m: cdc::Message) -> Self {
        match m {
            cdc::Message::SetMotorPwm(p) => Self::SetMotorPwm(p),
            cdc::Message::MotorEnable(enable) => Self::MotorEnable { enable },
            cdc::Message::Estop(Estop::Engage) => Self::Estop {
                action: EstopAction::Engage,
            },
            cdc::Message::Estop(Estop::Release) => Self::Estop {
                action: EstopAction::Release,
            },
            cdc::Message::Ping => Self::Ping,
            cdc::Message::Ack(a) => Self::Ack(a),
            cdc::Message::Imu(i) => Self::Imu(i),
            cdc::Message::Status(s) => Self::Status(s),
        }
    }
}

impl From<CdcJson> for cdc::Message {
    fn from(m: CdcJson) -> Self {
        match m {
            CdcJson::SetMotorPwm(p) => Self::SetMotorPwm(p),
            CdcJson::MotorEnable { enable } => Self::MotorEnable(enable),
            CdcJson::Estop {
                action: EstopAction::Engage,
            } => Self::Estop(Estop::Engage),
            CdcJson::Estop {
                action: EstopAction::Release,
            } => Self::Estop(Estop::Release),
            CdcJson::Ping => Self::Ping,
            CdcJson::Ack(a) => Self::Ack(a),
            CdcJson::Imu(i) => Self::Imu(i),
            CdcJson::Status(s) => Self::Status(s),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnableFields {
    enable: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EstopFields {
    action: EstopAction,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoFields {}

fn fields<T: serde::de::DeserializeOwned>(ty: &str, rest: serde_json::Value) -> Result<T, String> {
    serde_path_to_error::deserialize(rest).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let at = if path == "." || path.is_empty() {
            String::new()
        } else {
            format!("field `{path}`: ")
        };
        format!("\"{ty}\": {at}{inner}; see `motorlink decode --help` for every field and its type")
    })
}

/// Parses a seed 001 message from JSON, naming the field of any error (the derived
/// `Deserialize` of [`CdcJson`] loses the field path inside the tagged enum).
pub fn parse_cdc(json: &str) -> Result<CdcJson, String> {
    const TYPES: &str = "set_motor_pwm, motor_enable, estop, ping, ack, imu, status";
    let v: serde_json::Value = from_json(json)?;
    let serde_json::Value::Object(mut map) = v else {
        return Err(format!(
            "give a JSON object with a \"type\" ({TYPES}), e.g. '{{\"type\":\"ping\"}}'"
        ));
    };
    let ty = match map.remove("type") {
        Some(serde_json::Value::String(t)) => t,
        Some(other) => {
            return Err(format!(
                "field `type`: {other} is not a string; give one of {TYPES}"
            ))
        }
        None => return Err(format!("field `type` is missing; give one of {TYPES}")),
    };
    let rest = serde_json::Value::Object(map);
    Ok(match ty.as_str() {
        "set_motor_pwm" => CdcJson::SetMotorPwm(fields(&ty, rest)?),
        "motor_enable" => CdcJson::MotorEnable {
            enable: fields::<EnableFields>(&ty, rest)?.enable,
        },
        "estop" => CdcJson::Estop {
            action: fields::<EstopFields>(&ty, rest)?.action,
        },
        "ping" => {
            let NoFields {} = fields(&ty, rest)?;
            CdcJson::Ping
        }
        "ack" => CdcJson::Ack(fields(&ty, rest)?),
        "imu" => CdcJson::Imu(fields(&ty, rest)?),
        "status" => CdcJson::Status(fields(&ty, rest)?),
        other => {
            return Err(format!(
                "field `type`: unknown message \"{other}\"; give one of {TYPES}"
            ))
        }
    })
}

/// A seed 003 `CmdMsg` as JSON (any motor count; checked against `--motors` on conversion).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CmdMsgJson {
    /// Command type.
    pub cmd_type: teensy::CmdType,
    /// Non-zero: relative angles.
    pub is_relative: i32,
    /// One angle per motor (degrees); missing = all zero.
    pub mtr_angles: Option<Vec<i32>>,
    /// deg/s.
    pub mtr_speed_deg_s: i32,
    /// deg/s².
    pub mtr_accel_deg_s_s: i32,
    /// 1 done, 0 not (set in the Teensy's echo).
    pub cmd_success: i32,
}

impl<const N: usize> From<&teensy::CmdMsg<N>> for CmdMsgJson {
    fn from(m: &teensy::CmdMsg<N>) -> Self {
        Self {
            cmd_type: m.cmd_type,
            is_relative: m.is_relative,
            mtr_angles: Some(m.mtr_angles.to_vec()),
            mtr_speed_deg_s: m.mtr_speed_deg_s,
            mtr_accel_deg_s_s: m.mtr_accel_deg_s_s,
            cmd_success: m.cmd_success,
        }
    }
}

impl CmdMsgJson {
    /// The message with `N` motors; an error if `mtr_angles` has another length.
    pub fn to_msg<const N: usize>(&self) -> Result<teensy::CmdMsg<N>, String> {
        let mtr_angles = match &self.mtr_angles {
            None => [0; N],
            Some(v) => <[i32; N]>::try_from(v.as_slice()).map_err(|_| {
                format!(
                    "field `mtr_angles` has {} entries but --motors is {N}; give {N} angles or pass --motors {}",
                    v.len(),
                    v.len()
                )
            })?,
        };
        Ok(teensy::CmdMsg {
            cmd_type: self.cmd_type,
            is_relative: self.is_relative,
            mtr_angles,
            mtr_speed_deg_s: self.mtr_speed_deg_s,
            mtr_accel_deg_s_s: self.mtr_accel_deg_s_s,
            cmd_success: self.cmd_success,
        })
    }
}

/// Calls `$f::<N>(args)` for the runtime motor count `$n` (1 ..= [`teensy::MAX_MOTORS`]); any other
/// count is an `Err` naming the range, returned before `$f` runs.
#[macro_export]
macro_rules! with_motors {
    ($n:expr, $f:ident ( $($arg:expr),* )) => {
        match $n {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            5 => $f::<5>($($arg),*),
            6 => $f::<6>($($arg),*),
            7 => $f::<7>($($arg),*),
            8 => $f::<8>($($arg),*),
            9 => $f::<9>($($arg),*),
            10 => $f::<10>($($arg),*),
            11 => $f::<11>($($arg),*),
            12 => $f::<12>($($arg),*),
            13 => $f::<13>($($arg),*),
            14 => $f::<14>($($arg),*),
            15 => $f::<15>($($arg),*),
            16 => $f::<16>($($arg),*),
            other => Err(format!(
                "--motors {other} is not supported; give 1 to {} (protocol::teensy::MAX_MOTORS)",
                ::protocol::teensy::MAX_MOTORS
            )),
        }
    };
}
pub(crate) use with_motors;

/// Parses hex (whitespace, `:`, `,` and a leading `0x` allowed).
pub fn parse_hex(s: &str) -> Result<Vec<u8>, String> {
    let clean: String = s
        .chars()
        .filter(|c| !c.is_whitespace() && *c != ':' && *c != ',')
        .collect();
    let clean = clean
        .strip_prefix("0x")
        .or_else(|| clean.strip_prefix("0X"))
        .unwrap_or(&clean);
    if !clean.is_ascii() {
        return Err("hex input contains non-ASCII characters; give digits 0-9 a-f only".into());
    }
    if !clean.len().is_multiple_of(2) {
        return Err(format!(
            "hex input has an odd number of digits ({}); give two digits per byte",
            clean.len()
        ));
    }
    (0..clean.len())
        .step_by(2)
        .map(|i| {
            let pair = clean.get(i..i.saturating_add(2)).unwrap_or("");
            u8::from_str_radix(pair, 16).map_err(|_| {
                format!("'{pair}' at digit {i} is not a hex byte; give digits 0-9 a-f")
            })
        })
        .collect()
}

/// Lower-case hex, no separators.
pub fn to_hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// Deserialises `json`, naming the field of any error (`motor_pid_settings.kp[1]`).
pub fn from_json<T: serde::de::DeserializeOwned>(json: &str) -> Result<T, String> {
    let mut de = serde_json::Deserializer::from_str(json);
    let v: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let hint = "see `motorlink decode --help` for every field and its type";
        if inner.is_syntax() || inner.is_eof() {
            format!("not valid JSON: {inner}; check quotes, commas and braces")
        } else if path == "." || path.is_empty() {
            format!("{inner}; {hint}")
        } else {
            format!("field `{path}`: {inner}; {hint}")
        }
    })?;
    de.end()
        .map_err(|e| format!("trailing characters after the JSON value: {e}"))?;
    Ok(v)
}

/// [`from_json`] for a message with floating-point fields: a number that is not finite once
/// converted to the field's type (1e40 in an `f32` becomes +Inf) is refused, naming the field, since
/// a frame must never carry an infinity (the decoders and the board's validation refuse them).
pub fn from_json_finite<T: serde::de::DeserializeOwned + Serialize>(
    json: &str,
) -> Result<T, String> {
    let v: T = from_json(json)?;
    let given: serde_json::Value = from_json(json)?;
    // The value printed back: a non-finite float prints as null where the input held a number.
    let back = serde_json::to_value(&v).map_err(|e| format!("cannot check the numbers: {e}"))?;
    match lost_number(&given, &back, String::new()) {
        None => Ok(v),
        Some((path, n)) => Err(format!(
            "field `{path}`: {n} is not finite as a 32-bit float (the largest magnitude is {:e}); a frame cannot carry an infinity, give a finite value",
            f32::MAX
        )),
    }
}

/// The first path where `given` holds a number and `back` holds null, with that number.
fn lost_number(
    given: &serde_json::Value,
    back: &serde_json::Value,
    path: String,
) -> Option<(String, String)> {
    use serde_json::Value;
    let join = |key: &str| {
        if path.is_empty() {
            key.to_string()
        } else {
            format!("{path}.{key}")
        }
    };
    match (given, back) {
        (Value::Number(n), Value::Null) => Some((path.clone(), n.to_string())),
        (Value::Object(g), Value::Object(b)) => g.iter().find_map(|(k, gv)| {
            b.get(k)
                .and_then(|bv| lost_number(gv, bv, join(k.as_str())))
        }),
        (Value::Array(g), Value::Array(b)) => g
            .iter()
            .zip(b)
            .enumerate()
            .find_map(|(i, (gv, bv))| lost_number(gv, bv, format!("{path}[{i}]"))),
        _ => None,
    }
}

fn pretty<T: Serialize>(v: &T) -> Result<String, String> {
    serde_json::to_string_pretty(v).map_err(|e| format!("cannot print JSON: {e}"))
}

/// "refused: Crc (RejectReason code 1)".
fn refused(reason: RejectReason, detail: &str) -> String {
    format!(
        "frame refused: {reason:?} (RejectReason wire code {}): {detail}",
        reason as u8
    )
}

fn crc_detail(expected: u16, found: u16) -> String {
    format!(
        "CRC mismatch: computed {expected:#06x} over the frame, the frame carries {found:#06x}; the capture is corrupted or misaligned"
    )
}

fn le16(bytes: &[u8], at: usize) -> u16 {
    let lo = bytes.get(at).copied().unwrap_or(0);
    let hi = bytes.get(at.saturating_add(1)).copied().unwrap_or(0);
    u16::from_le_bytes([lo, hi])
}

fn exact<const L: usize>(bytes: &[u8], what: &str, hint: &str) -> Result<[u8; L], String> {
    <[u8; L]>::try_from(bytes)
        .map_err(|_| format!("{what} is exactly {L} bytes, got {}; {hint}", bytes.len()))
}

/// What [`decode_report`] found: the JSON to print, and for a capture that yielded no frame at all
/// (only refused frames, garbage or an incomplete tail) the reason, which fails the run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decoded {
    /// Pretty JSON (see [`SHAPES`]).
    pub json: String,
    /// `Some(why)` when the bytes were a capture and not one frame in it decoded.
    pub no_frame: Option<String>,
}

/// Decodes `hex` as a frame of `kind` and returns pretty JSON (see [`SHAPES`]). A capture without
/// a single decoded frame still returns its JSON here; [`decode_report`] says it found none.
pub fn decode(kind: FrameKind, hex: &str, motors: usize) -> Result<String, String> {
    decode_report(kind, hex, motors).map(|d| d.json)
}

/// [`decode`], telling a capture that yielded frames from one that yielded none.
pub fn decode_report(kind: FrameKind, hex: &str, motors: usize) -> Result<Decoded, String> {
    let bytes = parse_hex(hex)?;
    let one = |r: Result<String, String>| {
        r.map(|json| Decoded {
            json,
            no_frame: None,
        })
    };
    match kind {
        FrameKind::AmrCommand | FrameKind::AmrFeedback | FrameKind::AmrInfo => {
            one(decode_amr(kind, &bytes))
        }
        FrameKind::Cdc => decode_cdc(&bytes),
        FrameKind::PiRx => one(decode_pi_rx(&bytes)),
        FrameKind::PiTx => one(decode_pi_tx(&bytes)),
        FrameKind::TeensyLegacy => one(with_motors!(motors, decode_teensy_legacy(&bytes))),
        FrameKind::TeensyRobust => with_motors!(motors, decode_teensy_robust(&bytes)),
    }
}

/// The reason a capture of `len` bytes yielded no frame: `refused` frames refused, `incomplete`
/// bytes of an unfinished one at the end.
fn no_frame(what: &str, len: usize, refused: u64, incomplete: usize) -> String {
    format!(
        "no frame decoded: the {len}-byte capture holds no valid {what} frame ({refused} refused, {incomplete} bytes of an incomplete one at the end); check the link kind (--frame), --motors, and that the capture starts at a frame boundary"
    )
}

/// Encodes the JSON message `json` as a frame of `kind` and returns it in hex.
pub fn encode(kind: FrameKind, json: &str, motors: usize) -> Result<String, String> {
    match kind {
        FrameKind::AmrCommand => {
            let c: amr::MotorCommand = from_json_finite(json)?;
            let mut out = [0u8; amr::FRAME_LEN];
            amr::encode_command(&c, &mut out);
            Ok(to_hex(&out))
        }
        FrameKind::AmrFeedback => {
            let f: amr::MotorFeedback = from_json_finite(json)?;
            let mut out = [0u8; amr::FRAME_LEN];
            amr::encode_feedback(&f, &mut out);
            Ok(to_hex(&out))
        }
        FrameKind::AmrInfo => {
            let i: amr::McuInfo = from_json_finite(json)?;
            let mut out = [0u8; amr::FRAME_LEN];
            amr::encode_info(&i, &mut out);
            Ok(to_hex(&out))
        }
        FrameKind::Cdc => {
            let m = parse_cdc(json)?;
            let mut out = [0u8; cdc::MAX_FRAME_LEN];
            let n = cdc::Message::from(m).encode(&mut out);
            Ok(to_hex(out.get(..n).unwrap_or(&[])))
        }
        FrameKind::PiRx => {
            let rx: pi_spi::RxBuffer = from_json_finite(json)?;
            let mut out = [0u8; pi_spi::RX_LEN];
            pi_spi::encode_rx(&rx, &mut out);
            Ok(to_hex(&out))
        }
        FrameKind::PiTx => {
            let tx: pi_spi::TxBuffer = from_json_finite(json)?;
            let mut out = [0u8; pi_spi::TX_LEN];
            pi_spi::encode_tx(&tx, &mut out);
            Ok(to_hex(&out))
        }
        FrameKind::TeensyLegacy | FrameKind::TeensyRobust => {
            let m: CmdMsgJson = from_json(json)?;
            let robust = kind == FrameKind::TeensyRobust;
            with_motors!(motors, encode_teensy(&m, robust))
        }
    }
}

fn decode_amr(kind: FrameKind, bytes: &[u8]) -> Result<String, String> {
    let frame: [u8; amr::FRAME_LEN] =
        exact(bytes, "an AMR SPI frame", "capture one whole CS-low period")?;
    let r = match kind {
        FrameKind::AmrCommand => amr::decode_command(&frame).map(|c| pretty(&c)),
        FrameKind::AmrInfo => amr::decode_info(&frame).map(|i| pretty(&i)),
        _ => amr::decode_feedback(&frame).map(|f| pretty(&f)),
    };
    r.map_err(|reason| {
        let detail = match reason {
            RejectReason::Crc => crc_detail(
                protocol::crc16::checksum(frame.get(..amr::CRC_OFFSET).unwrap_or(&[])),
                u16::from_be_bytes([
                    frame.get(amr::CRC_OFFSET).copied().unwrap_or(0),
                    frame.get(amr::CRC_OFFSET + 1).copied().unwrap_or(0),
                ]),
            ),
            RejectReason::Framing => format!(
                "the LEN byte ({}) exceeds {} or the bytes after the payload are not zero",
                frame.first().copied().unwrap_or(0),
                amr::MAX_PAYLOAD
            ),
            RejectReason::Version if kind == FrameKind::AmrInfo => format!(
                "info_version in the payload is not {}{}",
                amr::INFO_VERSION,
                if amr::decode_feedback(&frame).is_ok() {
                    "; this is a MotorFeedback frame: decode it with --frame amr-feedback"
                } else {
                    " (missing: not an McuInfo frame); update the other side"
                }
            ),
            RejectReason::Version if kind == FrameKind::AmrFeedback && amr::decode_info(&frame).is_ok() => {
                "this is an McuInfo frame (the MCU's answer to an identity request, sent in the feedback slot): decode it with --frame amr-info".into()
            }
            RejectReason::Version => format!(
                "protocol_version in the payload is not {}; update the other side",
                amr::PROTOCOL_VERSION
            ),
            _ if kind == FrameKind::AmrInfo => "the protobuf payload does not decode as McuInfo: a board above 3 or a reset_cause above 8 (not defined by this version), dirty not 0/1, a field of the wrong wire type, or truncated".into(),
            _ => "the protobuf payload does not decode (truncated, a field of the wrong wire type, or a value out of range); is this the other direction's frame?".into(),
        };
        refused(reason, &detail)
    })?
}

fn cdc_error_detail(e: cdc::Error, frame: &[u8]) -> String {
    let id = frame.get(2).copied().unwrap_or(0);
    let len = frame.get(3).copied().unwrap_or(0);
    let what = match e {
        cdc::Error::Crc => {
            let end = cdc::HEADER_LEN.saturating_add(usize::from(len));
            crc_detail(
                protocol::crc16::checksum(frame.get(2..end).unwrap_or(&[])),
                le16(frame, end),
            )
        }
        cdc::Error::Length => match cdc::MsgId::from_raw(id) {
            Some(m) => format!(
                "MSG_ID {id:#04x} ({m:?}) has a {}-byte payload, LEN says {len}",
                m.payload_len()
            ),
            None => format!("LEN {len} does not fit MSG_ID {id:#04x}"),
        },
        cdc::Error::UnknownMsg => format!(
            "MSG_ID {id:#04x} is not defined; known: 0x01 set_motor_pwm, 0x02 motor_enable, 0x03 estop, 0x10 ping, 0x7f ack, 0x81 imu, 0x82 status"
        ),
        cdc::Error::Value => format!(
            "MSG_ID {id:#04x}: the value {} is not defined (enable / action must be 0 or 1)",
            frame.get(4).copied().unwrap_or(0)
        ),
        cdc::Error::Framing => {
            "not one frame: SOF must be AA 55 and the length 6 + LEN".to_string()
        }
    };
    format!(
        "{}; cdc error {e:?} (code {}), STATUS err {:?} ({})",
        refused(e.reason(), &what),
        e as u8,
        e.error_code(),
        e.error_code() as u16
    )
}

/// One entry of a capture's results.
#[derive(Serialize)]
#[serde(rename_all = "snake_case")]
enum CaptureItem<M: Serialize> {
    Message(M),
    Error(CaptureError),
}

#[derive(Serialize)]
struct CaptureError {
    reason: String,
    reason_code: u8,
    #[serde(skip_serializing_if = "Option::is_none")]
    cdc_error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cdc_error_code: Option<u8>,
}

#[derive(Serialize)]
struct Capture<M: Serialize, S: Serialize> {
    results: Vec<CaptureItem<M>>,
    stats: S,
    incomplete_bytes: usize,
}

fn decode_cdc(bytes: &[u8]) -> Result<Decoded, String> {
    match cdc::decode_frame(bytes) {
        Ok(m) => {
            return Ok(Decoded {
                json: pretty(&CdcJson::from(m))?,
                no_frame: None,
            })
        }
        Err(cdc::Error::Framing) => {}
        Err(e) => return Err(cdc_error_detail(e, bytes)),
    }
    // Not exactly one frame: treat the bytes as a capture.
    let mut dec = cdc::StreamDecoder::new();
    let results: Vec<CaptureItem<CdcJson>> = dec
        .feed(bytes)
        .map(|r| match r {
            Ok(m) => CaptureItem::Message(CdcJson::from(m)),
            Err(e) => CaptureItem::Error(CaptureError {
                reason: format!("{:?}", e.reason()),
                reason_code: e.reason() as u8,
                cdc_error: Some(format!("{e:?}")),
                cdc_error_code: Some(e as u8),
            }),
        })
        .collect();
    if results.is_empty() {
        return Err(refused(
            RejectReason::Framing,
            &format!(
                "no USB CDC frame in these {} bytes (no AA 55 start, or the last frame is incomplete: {} bytes wait for the rest); capture from a start of frame",
                bytes.len(),
                dec.buffered()
            ),
        ));
    }
    let stats = dec.stats();
    let refused = stats.crc_errors.saturating_add(stats.message_errors);
    Ok(Decoded {
        json: pretty(&Capture {
            results,
            stats,
            incomplete_bytes: dec.buffered(),
        })?,
        no_frame: (stats.frames == 0)
            .then(|| no_frame("USB CDC", bytes.len(), u64::from(refused), dec.buffered())),
    })
}

fn pi_detail_rx(buf: &[u8; pi_spi::RX_LEN], reason: RejectReason) -> String {
    let updates = u32::from_le_bytes([
        buf.get(1).copied().unwrap_or(0),
        buf.get(2).copied().unwrap_or(0),
        buf.get(3).copied().unwrap_or(0),
        buf.get(4).copied().unwrap_or(0),
    ]);
    match reason {
        RejectReason::Version => format!(
            "transferVersion is {}, this build speaks {}",
            buf.first().copied().unwrap_or(0),
            pi_spi::TRANSFER_VERSION
        ),
        RejectReason::Parity => format!(
            "updates word {updates:#010x} has {} set bits; the parity bit 7 must make the count odd",
            updates.count_ones()
        ),
        _ => {
            let shutdown = buf.get(pi_spi::RX_SHUTDOWN_OFFSET).copied().unwrap_or(0);
            let modes = le16(buf.as_slice(), 6);
            let servo = buf.get(40).copied().unwrap_or(0);
            if updates & !(u32::from(pi_spi::UpdateFlags::ALL) | pi_spi::UpdateFlags::PARITY_BIT)
                != 0
            {
                format!("updates word {updates:#010x} sets reserved bits (only 0-5 and 7 exist)")
            } else if shutdown & !0b11 != 0 {
                format!("systemShutdown {shutdown:#04x} sets reserved bits (only 0 and 1 exist)")
            } else if pi_spi::unpack_motor_modes(modes).is_none() {
                format!("motorControlMode {modes:#06x} holds a mode 5-7 or sets bits 12-15")
            } else if pi_spi::unpack_servo_modes(servo).is_none() {
                format!("servoMode {servo:#04x} holds the undefined servo mode 3")
            } else {
                "a field holds an undefined value".into()
            }
        }
    }
}

fn decode_pi_rx(bytes: &[u8]) -> Result<String, String> {
    let buf: [u8; pi_spi::RX_LEN] = exact(
        bytes,
        "a Pi RxBuffer",
        "capture the MOSI bytes of one whole transfer",
    )?;
    let rx = pi_spi::decode_rx(&buf).map_err(|r| refused(r, &pi_detail_rx(&buf, r)))?;
    pretty(&rx)
}

fn decode_pi_tx(bytes: &[u8]) -> Result<String, String> {
    // A whole transfer is TRANSFER_LEN bytes, of which the TxBuffer is the first TX_LEN.
    let bytes = if bytes.len() == pi_spi::TRANSFER_LEN {
        bytes.get(..pi_spi::TX_LEN).unwrap_or(bytes)
    } else {
        bytes
    };
    let buf: [u8; pi_spi::TX_LEN] = exact(
        bytes,
        "a Pi TxBuffer",
        "capture the MISO bytes of one whole transfer (167, or 179 with the padding)",
    )?;
    let tx = pi_spi::decode_tx(&buf).map_err(|r| {
        refused(
            r,
            &format!(
                "transferVersion is {}, this build speaks {}",
                buf.first().copied().unwrap_or(0),
                pi_spi::TRANSFER_VERSION
            ),
        )
    })?;
    pretty(&tx)
}

fn teensy_detail<const N: usize>(reason: RejectReason, msg: &[u8], version: Option<u8>) -> String {
    match reason {
        RejectReason::Decode => format!(
            "cmd_type {} is not defined (0 mtrs, 1 cal, 2 endeff_on, 3 endeff_off, 4 config)",
            i32::from_le_bytes([
                msg.first().copied().unwrap_or(0),
                msg.get(1).copied().unwrap_or(0),
                msg.get(2).copied().unwrap_or(0),
                msg.get(3).copied().unwrap_or(0),
            ])
        ),
        RejectReason::Version => format!(
            "version byte is {}, this build speaks {}",
            version.unwrap_or(0),
            teensy::ROBUST_VERSION
        ),
        _ => format!("not a {N}-motor CmdMsg"),
    }
}

fn motors_hint(len: usize, overhead: usize) -> String {
    match len.checked_sub(overhead) {
        Some(rest) if rest % 4 == 0 && (1..=teensy::MAX_MOTORS).contains(&(rest / 4)) => {
            format!("; {len} bytes fit --motors {}", rest / 4)
        }
        _ => String::new(),
    }
}

fn decode_teensy_legacy<const N: usize>(bytes: &[u8]) -> Result<String, String> {
    let want = teensy::CmdMsg::<N>::LEGACY_LEN;
    if bytes.len() != want {
        return Err(refused(
            RejectReason::Framing,
            &format!(
                "a legacy packet with --motors {N} is {want} bytes (20 + 4·{N} + the '\\n'), got {}{}",
                bytes.len(),
                motors_hint(bytes.len(), 21)
            ),
        ));
    }
    let m = teensy::CmdMsg::<N>::decode_legacy(bytes).map_err(|r| {
        let detail = if r == RejectReason::Framing {
            format!(
                "the last byte is {:#04x}, a legacy packet ends in 0x0a ('\\n')",
                bytes.last().copied().unwrap_or(0)
            )
        } else {
            teensy_detail::<N>(r, bytes, None)
        };
        refused(r, &detail)
    })?;
    pretty(&CmdMsgJson::from(&m))
}

/// Why one robust frame failed, with the CRC values and the version where they apply. The frame is
/// `S | K0 K1 K2 | 00` (version 2): the CRC covers the stuffed bytes `S`, the check bytes carry it.
fn robust_error<const N: usize>(frame: &[u8], reason: RejectReason) -> String {
    let want = teensy::CmdMsg::<N>::ROBUST_LEN;
    let split = teensy::stuffed_len(N);
    let stuffed = frame.get(..split).unwrap_or(&[]);
    let check = frame
        .get(split..)
        .and_then(|rest| rest.first_chunk::<{ teensy::CHECK_LEN }>())
        .copied();
    let detail = match reason {
        RejectReason::Crc => match check.map(|k| (k, teensy::check_value(k))) {
            Some((_, Some(carried))) => crc_detail(protocol::crc16::checksum(stuffed), carried),
            Some((k, None)) => format!(
                "the check bytes {} carry no CRC: each has bit 7 set and the first only bits 7, 1 \
                 and 0; the capture is corrupted or misaligned",
                to_hex(&k)
            ),
            None => format!("a {N}-motor robust frame has no check bytes at {split}"),
        },
        RejectReason::Framing if frame.len() != want => format!(
            "a {N}-motor robust frame is {want} bytes (COBS of the {}-byte version and CmdMsg, 3 \
             check bytes, 00), this one {}{}",
            teensy::robust_body_len(N),
            frame.len(),
            motors_hint(frame.len(), teensy::robust_len(0))
        ),
        RejectReason::Framing => format!(
            "the CRC matches, but the {split} stuffed bytes are not one COBS block of the {}-byte \
             version and CmdMsg",
            teensy::robust_body_len(N)
        ),
        _ => {
            // COBS of S (the CRC matched, so it is one block): S and a terminator for corncobs.
            let mut framed = stuffed.to_vec();
            framed.push(0);
            let mut body = vec![0u8; framed.len()];
            let body = corncobs::decode_buf(&framed, &mut body)
                .ok()
                .and_then(|n| body.get(..n))
                .unwrap_or(&[]);
            teensy_detail::<N>(reason, body.get(1..).unwrap_or(&[]), body.first().copied())
        }
    };
    refused(reason, &detail)
}

fn decode_teensy_robust<const N: usize>(bytes: &[u8]) -> Result<Decoded, String> {
    let zeros = bytes.iter().filter(|&&b| b == 0).count();
    if zeros == 0 {
        return Err(refused(
            RejectReason::Framing,
            "no 0x00 terminator: a robust frame ends in 00 and holds no other 00",
        ));
    }
    if zeros == 1 && bytes.last() == Some(&0) {
        let m =
            teensy::CmdMsg::<N>::decode_robust(bytes).map_err(|r| robust_error::<N>(bytes, r))?;
        return Ok(Decoded {
            json: pretty(&CmdMsgJson::from(&m))?,
            no_frame: None,
        });
    }
    // Several frames, or garbage: a capture.
    let mut dec = teensy::RobustDecoder::<N>::new();
    let results: Vec<CaptureItem<CmdMsgJson>> = bytes
        .iter()
        .filter_map(|&b| dec.push(b))
        .map(|r| match r {
            Ok(m) => CaptureItem::Message(CmdMsgJson::from(&m)),
            Err(reason) => CaptureItem::Error(CaptureError {
                reason: format!("{reason:?}"),
                reason_code: reason as u8,
                cdc_error: None,
                cdc_error_code: None,
            }),
        })
        .collect();
    let tail = bytes.iter().rev().take_while(|&&b| b != 0).count();
    let stats = dec.stats();
    Ok(Decoded {
        json: pretty(&Capture {
            results,
            stats,
            incomplete_bytes: tail,
        })?,
        no_frame: (stats.frames == 0)
            .then(|| no_frame("Teensy serial", bytes.len(), u64::from(stats.errors), tail)),
    })
}

fn encode_teensy<const N: usize>(m: &CmdMsgJson, robust: bool) -> Result<String, String> {
    let msg = m.to_msg::<N>()?;
    let mut out = [0u8; teensy::ROBUST_BUF];
    let n = if robust {
        msg.encode_robust(&mut out)
    } else {
        msg.encode_legacy(&mut out)
    }
    .ok_or_else(|| format!("internal: the {N}-motor frame does not fit its buffer"))?;
    Ok(to_hex(out.get(..n).unwrap_or(&[])))
}

#[cfg(test)]
mod tests;
