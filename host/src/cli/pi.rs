//! The seed 004 verbs of `motorlink` (`--kind pi-spi`): `ping`, `monitor` and `drive` from a
//! Raspberry Pi's spidev to the STM32's SPI2, one JSON line per transfer, a verdict at the end.
//!
//! Every transfer is full duplex, [`pi_spi::TRANSFER_LEN`] bytes: the host sends an `RxBuffer`
//! while it receives a `TxBuffer` (the first [`pi_spi::TX_LEN`] bytes). The board acts on the
//! `RxBuffer` of a transfer at its end; the `TxBuffer` it sends was prepared after the *previous*
//! transfer (double-buffered DMA), so every reply is one transfer late. The verbs run over any
//! [`Transport`] (`exchange` is the full-duplex transfer; the CLI opens a
//! [`crate::transport::SpiTransport`]), so the tests run them against a fake board.
//!
//! # Verbs
//!
//! * `ping`: at least two transfers of an *ignored* buffer, every byte 0 (transferVersion 0 ≠ 15:
//!   the board answers but applies nothing, so a ping never changes what the robot does), 10 ms
//!   apart. Prints each round trip and `TxBuffer`, and whether `update_time` advanced.
//! * `monitor`: the same ignored transfers at `--hz` for `--seconds` (or `--count` transfers), every
//!   decoded `TxBuffer` printed; a reply that does not decode is counted and printed, never fatal.
//! * `drive`: paced command transfers (see the diagram), then a shutdown buffer.
//!
//! # `drive`, transfer by transfer
//!
//! ```text
//!  transfer   0 (arm)               1 … n (commands)          n+1 (shutdown)
//!  MOSI       systemShutdown 0b10   systemShutdown 0          systemShutdown 0b11
//!             motors OFF, servos    the requested modes,      motors OFF, servos
//!             fully disabled,       targets, goals, servos    fully disabled
//!             one-shot flags        no update flags
//!  MISO       prepared before 0     prepared after k-1        prepared after n
//!             |<------ 1/hz ------->|<------ 1/hz ------>| …  |
//! ```
//!
//! Leaving BRAKE needs an explicit re-arm: the board takes the motor shutdown bit's 1→0 edge as
//! one (its ladder sees enable 0→1), followed by fresh valid transfers. So transfer 0 sets the bit
//! with every motor OFF, and transfers 1…n clear it. The one-shot updates (`--odom-reset`,
//! `--kinematics`, `--pid-speed`) ride on transfer 0 only: the board acts on every transfer that
//! carries a flag, so a flag is sent exactly once, and new gains are loaded while the motors are
//! still held off. The PID and kinematics blocks are repeated in every buffer (the board reads them
//! only with their flag). At the end, on SIGINT/SIGTERM/SIGHUP (the `stop` callback) and after any
//! transfer error, one last buffer sets both shutdown bits (the seed: "the Pi sets this bit on
//! process exit"); the board brakes anyway 49 ms after the last valid transfer.
//!
//! # Output and verdicts
//!
//! ```text
//!  {"t_ms":..,"transfer":k,"tx":{..}}                                  a TxBuffer (drive: every --every-th)
//!  {"t_ms":..,"transfer":k,"error":"version","version_byte":0,"hint":..}   a reply that does not decode
//!  {"t_ms":..,"ping":i,"round_trip_us":..,"tx":{..},"advanced":..}     ping, per transfer
//!  {"t_ms":..,"verdict":"done"|"refused"|"no_reply",..}                always the last line
//! ```
//!
//! * `no_reply` (exit 69): `update_time` never advanced between two decoded replies: none decoded
//!   (all 0x00 or 0xFF bytes: no board), only one, or all with the same `update_time` (a stale
//!   board: its SPI callback does not run; `"stale":true`).
//! * `refused` (exit 1, `drive` only): commands were sent for at least [`REFUSED_AFTER`], some motor
//!   was commanded to move (`pwm`/`mav` with a target ≠ 0, `mtp` with a speed cap ≠ 0 and a goal
//!   other than its position in the first reply), feedback came after the first command, and none
//!   of those motors' `motor.position` ever differed from its value in the first reply.
//! * `done` (exit 0): otherwise.
//!
//! An argument error refuses the run before the device is opened (exit 64), an open error (69) or a
//! transfer error (74) ends it (see [`super::exit::Exit`]). A run stopped by a signal ends normally, with
//! `"interrupted":true`.

use std::path::Path;
use std::time::{Duration, Instant};

use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use protocol::pi_spi::assumed::{KinematicsConfig, MotorPidSettings};
use protocol::pi_spi::{
    self, MotorMode, RxBuffer, ServoMode, Shutdown, TxBuffer, UpdateFlags, RX_LEN, TRANSFER_LEN,
    TX_LEN,
};
use serde_json::{json, Value};
use statemachine::RejectReason;

pub use super::device::Verdict;

use super::device::{self, Lines};
use crate::pacing::{Pacer, PeriodStats};
use crate::transport::{LinkError, Transport};

/// Default `--hz`: the seed's 10 ms frame period.
pub const DEFAULT_HZ: f64 = 100.0;
/// The board brakes this long after the last valid transfer; a period this long or longer is refused.
pub const BOARD_BRAKE_AFTER: Duration = Duration::from_millis(49);
/// Transfers with the motor shutdown bit set before the commands (the re-arm edge follows them).
pub const ARM_TRANSFERS: u64 = 1;
/// Fewest transfers of `ping` (two are needed to see `update_time` advance).
pub const MIN_PINGS: u32 = 2;
/// Smallest `servoPos` of an enabled servo, timer ticks.
pub const SERVO_POS_MIN: u16 = 600;
/// Largest `servoPos` of an enabled servo, timer ticks.
pub const SERVO_POS_MAX: u16 = 2600;
/// A drive must have sent commands for this long before "the motors did not move" means `refused`.
pub const REFUSED_AFTER: Duration = Duration::from_millis(200);

/// The buffer `ping` and `monitor` send: every byte 0, so transferVersion 0 ≠ 15 and the board
/// ignores it (it answers, applies nothing).
pub const IGNORED: [u8; TRANSFER_LEN] = [0; TRANSFER_LEN];

/// The seed 004 options of `drive` (`--kind pi-spi`), as given on the command line.
#[derive(Clone, Debug, Default, clap::Args)]
#[command(next_help_heading = "Raspberry Pi SPI link (drive --kind pi-spi)")]
pub struct PiDriveArgs {
    /// Motor modes, one for all four or four (motors 0-3): off, passive_brake (or brake), pwm, mav,
    /// mtp. Default off.
    #[arg(long, value_name = "MODES")]
    pub modes: Option<String>,
    /// motorTarget, one or four: pwm duty -399..=399, mav velocity setpoint (ticks), mtp speed cap.
    #[arg(long, value_name = "T", allow_hyphen_values = true)]
    pub targets: Option<String>,
    /// motorGoalPosition (mtp), one or four, ticks.
    #[arg(long, value_name = "G", allow_hyphen_values = true)]
    pub goals: Option<String>,
    /// Servo modes, one or four: fully_disabled (or off), disabled, enabled. Default fully_disabled.
    #[arg(long, value_name = "MODES")]
    pub servo_modes: Option<String>,
    /// servoPos, one or four, timer ticks; 600..=2600 for an enabled servo (required for one).
    #[arg(long, value_name = "P")]
    pub servo_pos: Option<String>,
    /// Reset the odometry once (update flag ODOM_RESET, first transfer only).
    #[arg(long)]
    pub odom_reset: bool,
    /// Load a KinematicsConfig once (.toml, else JSON: {"inverse":[[..4],[..4],[..4]],"ticks_to_rad":[..4]}).
    #[arg(long, value_name = "FILE")]
    pub kinematics: Option<std::path::PathBuf>,
    /// Velocity PID gains, sent once (MOTOR_PID_SPEED): kp,ki,kd for all four motors, or twelve
    /// values kp,ki,kd of motor 0, then motor 1, 2, 3.
    #[arg(long, value_name = "GAINS", allow_hyphen_values = true)]
    pub pid_speed: Option<String>,
    /// Print every Nth TxBuffer received (default 1: all).
    #[arg(long, value_name = "N")]
    pub every: Option<u64>,
    /// SPI clock, Hz (default 2000000).
    #[arg(long)]
    pub speed: Option<u32>,
}

impl PiDriveArgs {
    /// The first seed 004 option given, to refuse it on another link kind.
    pub fn first_given(&self) -> Option<&'static str> {
        let given = [
            (self.modes.is_some(), "--modes"),
            (self.targets.is_some(), "--targets"),
            (self.goals.is_some(), "--goals"),
            (self.servo_modes.is_some(), "--servo-modes"),
            (self.servo_pos.is_some(), "--servo-pos"),
            (self.odom_reset, "--odom-reset"),
            (self.kinematics.is_some(), "--kinematics"),
            (self.pid_speed.is_some(), "--pid-speed"),
            (self.every.is_some(), "--every"),
            (self.speed.is_some(), "--speed"),
        ];
        given.iter().find(|(g, _)| *g).map(|(_, n)| *n)
    }
}

/// A value for all four, or four values.
fn one_or_four<T: Copy>(v: &[T], what: &str, example: &str) -> Result<[T; 4], String> {
    match v {
        [a] => Ok([*a; 4]),
        [a, b, c, d] => Ok([*a, *b, *c, *d]),
        _ => Err(format!(
            "{what} takes one value (for all four) or four (0 to 3), got {}; e.g. {what} {example}; nothing was sent",
            v.len()
        )),
    }
}

/// Parses `--modes`.
pub fn parse_motor_modes(s: &str) -> Result<[MotorMode; 4], String> {
    let modes = s
        .split(',')
        .map(|m| match m.trim() {
            "off" => Ok(MotorMode::Off),
            "passive_brake" | "brake" => Ok(MotorMode::PassiveBrake),
            "pwm" => Ok(MotorMode::Pwm),
            "mav" => Ok(MotorMode::Mav),
            "mtp" => Ok(MotorMode::Mtp),
            other => Err(format!(
                "--modes: '{other}' is not a motor mode; give off, passive_brake (brake), pwm, mav or mtp; nothing was sent"
            )),
        })
        .collect::<Result<Vec<_>, _>>()?;
    one_or_four(&modes, "--modes", "pwm,pwm,off,off")
}

/// Parses `--servo-modes`.
pub fn parse_servo_modes(s: &str) -> Result<[ServoMode; 4], String> {
    let modes = s
        .split(',')
        .map(|m| match m.trim() {
            "fully_disabled" | "off" => Ok(ServoMode::FullyDisabled),
            "disabled" => Ok(ServoMode::Disabled),
            "enabled" => Ok(ServoMode::Enabled),
            other => Err(format!(
                "--servo-modes: '{other}' is not a servo mode; give fully_disabled (off), disabled or enabled; nothing was sent"
            )),
        })
        .collect::<Result<Vec<_>, _>>()?;
    one_or_four(&modes, "--servo-modes", "enabled,off,off,off")
}

/// Parses `--pid-speed`: three gains for all motors or twelve (kp,ki,kd per motor); all finite.
pub fn parse_pid(s: &str) -> Result<MotorPidSettings, String> {
    let v = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f32>()
                .ok()
                .filter(|g| g.is_finite())
                .ok_or_else(|| {
                    format!(
                        "--pid-speed: '{}' is not a finite number; e.g. --pid-speed 0.5,0.1,0; nothing was sent",
                        x.trim()
                    )
                })
        })
        .collect::<Result<Vec<f32>, _>>()?;
    let triple = |m: usize| -> [f32; 3] {
        let at = |i: usize| {
            m.checked_mul(3)
                .and_then(|b| b.checked_add(i))
                .and_then(|j| v.get(j))
                .copied()
                .unwrap_or(0.0)
        };
        [at(0), at(1), at(2)]
    };
    let per_motor: [[f32; 3]; 4] = match v.len() {
        3 => [triple(0); 4],
        12 => [triple(0), triple(1), triple(2), triple(3)],
        n => {
            return Err(format!(
                "--pid-speed takes kp,ki,kd (for all four motors) or twelve values (kp,ki,kd of motor 0, 1, 2, 3), got {n}; nothing was sent"
            ))
        }
    };
    Ok(MotorPidSettings {
        kp: per_motor.map(|g| g[0]),
        ki: per_motor.map(|g| g[1]),
        kd: per_motor.map(|g| g[2]),
    })
}

/// Reads `--kinematics`: TOML if the name ends in `.toml`, JSON otherwise; every number finite.
pub fn load_kinematics(path: &Path) -> Result<KinematicsConfig, String> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        format!(
            "--kinematics {}: cannot read it: {e}; nothing was sent",
            path.display()
        )
    })?;
    let k: KinematicsConfig = if path.extension().is_some_and(|e| e == "toml") {
        toml::from_str(&text).map_err(|e| e.to_string())
    } else {
        super::from_json(&text)
    }
    .map_err(|e| {
        format!(
            "--kinematics {}: {e}; the fields are inverse (3 rows of 4) and ticks_to_rad (4); nothing was sent",
            path.display()
        )
    })?;
    if !k
        .inverse
        .iter()
        .flatten()
        .chain(k.ticks_to_rad.iter())
        .all(|x| x.is_finite())
    {
        return Err(format!(
            "--kinematics {}: every number must be finite; nothing was sent",
            path.display()
        ));
    }
    Ok(k)
}

/// A checked `drive --kind pi-spi`: built only from arguments the board could take.
#[derive(Clone, Debug, PartialEq)]
pub struct PiDrivePlan {
    /// The command buffer repeated (shutdown bits clear, no update flags).
    pub command: RxBuffer,
    /// The one-shot update flags, sent with the first transfer only.
    pub oneshot: UpdateFlags,
    /// Time between transfers.
    pub period: Duration,
    /// Command transfers (after the arm transfer, before the shutdown one).
    pub frames: u64,
    /// Print every this many TxBuffers (by transfer number).
    pub every: u64,
}

impl PiDrivePlan {
    /// Checks the arguments: modes and servo modes by name, one or four of each value, a `pwm`
    /// target within ±399, an enabled servo's position within 600..=2600, finite gains and
    /// kinematics, `hz` in (1000/49, 1000] (a longer period would let the board brake between
    /// transfers), `seconds` in (0, one day].
    pub fn new(a: &PiDriveArgs, hz: f64, seconds: f64) -> Result<Self, String> {
        let modes = a
            .modes
            .as_deref()
            .map_or(Ok([MotorMode::Off; 4]), parse_motor_modes)?;
        let ints = |s: &Option<String>, what: &str, example: &str| -> Result<[i32; 4], String> {
            match s {
                None => Ok([0; 4]),
                Some(s) => one_or_four(
                    &device::parse_list(s, what).map_err(|e| format!("{e}; nothing was sent"))?,
                    what,
                    example,
                ),
            }
        };
        let targets = ints(&a.targets, "--targets", "200,-200,0,0")?;
        let goals = ints(&a.goals, "--goals", "1000,1000,0,0")?;
        let pwm_max = i32::from(pi_spi::PWM_MAX);
        for (i, (m, t)) in modes.iter().zip(targets).enumerate() {
            if *m == MotorMode::Pwm && t.unsigned_abs() > pwm_max.unsigned_abs() {
                return Err(format!(
                    "--targets: motor {i} is in pwm mode and its duty {t} is outside -{pwm_max}..={pwm_max}; nothing was sent"
                ));
            }
        }
        let servo_mode = a
            .servo_modes
            .as_deref()
            .map_or(Ok([ServoMode::FullyDisabled; 4]), parse_servo_modes)?;
        let servo_raw = ints(&a.servo_pos, "--servo-pos", "1500")?;
        let mut servo_pos = [0u16; 4];
        for (i, ((p, raw), m)) in servo_pos
            .iter_mut()
            .zip(servo_raw)
            .zip(servo_mode)
            .enumerate()
        {
            let enabled = m == ServoMode::Enabled;
            let in_range = (i32::from(SERVO_POS_MIN)..=i32::from(SERVO_POS_MAX)).contains(&raw);
            if enabled && !in_range {
                return Err(format!(
                    "--servo-pos: servo {i} is enabled and its position {raw} is outside {SERVO_POS_MIN}..={SERVO_POS_MAX} timer ticks{}; nothing was sent",
                    if a.servo_pos.is_none() { " (give --servo-pos)" } else { "" }
                ));
            }
            *p = u16::try_from(raw).map_err(|_| {
                format!("--servo-pos: servo {i} position {raw} does not fit 0..=65535; nothing was sent")
            })?;
        }
        let mut flags = 0u8;
        if a.odom_reset {
            flags |= UpdateFlags::ODOM_RESET;
        }
        let kinematics = match &a.kinematics {
            Some(p) => {
                flags |= UpdateFlags::KINEMATICS;
                load_kinematics(p)?
            }
            None => KinematicsConfig::default(),
        };
        let pid = match &a.pid_speed {
            Some(s) => {
                flags |= UpdateFlags::MOTOR_PID_SPEED;
                parse_pid(s)?
            }
            None => MotorPidSettings::default(),
        };
        let (period, frames, _) =
            device::paced_frames(hz, seconds).map_err(|e| format!("{e}; nothing was sent"))?;
        if period >= BOARD_BRAKE_AFTER {
            return Err(format!(
                "--hz {hz}: the board brakes {} ms after the last valid transfer, so transfers must come more often; give --hz above {:.1} (default {DEFAULT_HZ}); nothing was sent",
                BOARD_BRAKE_AFTER.as_millis(),
                1.0 / BOARD_BRAKE_AFTER.as_secs_f64()
            ));
        }
        let every = a.every.unwrap_or(1);
        if every == 0 {
            return Err("--every 0: give 1 to print every TxBuffer, N for every Nth".into());
        }
        Ok(Self {
            command: RxBuffer {
                motor_control_mode: modes,
                motor_target: targets,
                motor_goal_position: goals,
                servo_mode,
                servo_pos,
                motor_pid_settings: pid,
                kinematics,
                ..RxBuffer::default()
            },
            oneshot: UpdateFlags(flags),
            period,
            frames,
            every,
        })
    }

    /// Transfer 0: the motor shutdown bit set, every motor OFF, servos fully disabled, nothing
    /// commanded; the one-shot flags with their PID and kinematics blocks.
    pub fn arm_buffer(&self) -> RxBuffer {
        RxBuffer {
            updates: self.oneshot,
            system_shutdown: Shutdown {
                servos: false,
                motors: true,
            },
            motor_pid_settings: self.command.motor_pid_settings,
            kinematics: self.command.kinematics,
            ..RxBuffer::default()
        }
    }

    /// The last transfer: both shutdown bits, every motor OFF, servos fully disabled.
    pub fn shutdown_buffer(&self) -> RxBuffer {
        RxBuffer {
            system_shutdown: Shutdown {
                servos: true,
                motors: true,
            },
            motor_pid_settings: self.command.motor_pid_settings,
            kinematics: self.command.kinematics,
            ..RxBuffer::default()
        }
    }

    /// Motors commanded to move, given their positions in the first reply (if any).
    fn commanded(&self, baseline: Option<[i32; 4]>) -> [bool; 4] {
        let c = &self.command;
        let mut out = [false; 4];
        for (i, o) in out.iter_mut().enumerate() {
            let at = |a: &[i32; 4]| a.get(i).copied().unwrap_or(0);
            let target = at(&c.motor_target);
            *o = match c.motor_control_mode.get(i) {
                Some(MotorMode::Pwm | MotorMode::Mav) => target != 0,
                Some(MotorMode::Mtp) => {
                    target != 0 && baseline.is_none_or(|b| at(&b) != at(&c.motor_goal_position))
                }
                _ => false,
            };
        }
        out
    }
}

/// An `RxBuffer` as the bytes of one transfer (zero padding after it).
pub fn transfer_bytes(rx: &RxBuffer) -> [u8; TRANSFER_LEN] {
    let mut buf = [0u8; RX_LEN];
    pi_spi::encode_rx(rx, &mut buf);
    let mut out = [0u8; TRANSFER_LEN];
    for (d, s) in out.iter_mut().zip(buf) {
        *d = s;
    }
    out
}

/// What one transfer brought back.
#[derive(Clone, Debug)]
enum Reply {
    /// A TxBuffer.
    Tx(Box<TxBuffer>),
    /// Bytes that do not decode: why, and the version byte.
    Bad(RejectReason, u8),
}

/// One full-duplex transfer of `out`: the reply and the time the transfer took.
fn transfer<D: Transport>(
    dev: &mut D,
    out: &[u8; TRANSFER_LEN],
) -> Result<(Reply, Duration, [u8; TRANSFER_LEN]), LinkError> {
    let mut rx = [0u8; TRANSFER_LEN];
    let t = Instant::now();
    dev.exchange(out, &mut rx)?;
    let took = t.elapsed();
    let head = rx.first_chunk::<TX_LEN>().copied().unwrap_or([0; TX_LEN]);
    let reply = match pi_spi::decode_tx(&head) {
        Ok(tx) => Reply::Tx(Box::new(tx)),
        Err(r) => Reply::Bad(r, rx.first().copied().unwrap_or(0)),
    };
    Ok((reply, took, rx))
}

/// A reply of 0x00 bytes only.
const HINT_ZERO: &str = "every byte 0x00: no board is driving MISO (absent, unpowered, or its SPI2 DMA not running); check the wiring, the power, and that the Raspberry Pi SPI link's firmware runs";
/// A reply of 0xFF bytes only.
const HINT_FF: &str = "every byte 0xFF: MISO is floating high, no board is answering; check the wiring, the chip select (PB12) and that the Raspberry Pi SPI link's firmware runs";
/// Any other reply that does not decode.
const HINT_VERSION: &str = "transferVersion is not 15: the firmware speaks another pi_buffer.h version, or the transfers are misaligned (reset the board)";

/// Why a reply did not decode, and what to check.
fn hint(rx: &[u8]) -> &'static str {
    if rx.iter().all(|b| *b == 0x00) {
        HINT_ZERO
    } else if rx.iter().all(|b| *b == 0xFF) {
        HINT_FF
    } else {
        HINT_VERSION
    }
}

/// A TxBuffer as JSON, floats as their shortest f32 decimal (as `motorlink decode` prints them).
fn tx_json(tx: &TxBuffer) -> Value {
    serde_json::to_string(tx)
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or(Value::Null)
}

/// What a run received.
#[derive(Clone, Debug, Default)]
struct Received {
    decoded: u64,
    errors: u64,
    all_zero: u64,
    all_ff: u64,
    first_time: Option<u32>,
    last_time: Option<u32>,
    /// Consecutive decoded replies whose `update_time` differed.
    advanced: u64,
    first_position: Option<[i32; 4]>,
}

impl Received {
    /// Counts a reply; for a TxBuffer returns whether `update_time` advanced since the last one.
    fn add(&mut self, r: &Reply, raw: &[u8]) -> Option<bool> {
        match r {
            Reply::Tx(tx) => {
                self.decoded = self.decoded.saturating_add(1);
                let advanced = self.last_time.map(|t| t != tx.update_time);
                if advanced == Some(true) {
                    self.advanced = self.advanced.saturating_add(1);
                }
                self.first_time.get_or_insert(tx.update_time);
                self.last_time = Some(tx.update_time);
                self.first_position.get_or_insert(tx.motor.position);
                advanced
            }
            Reply::Bad(..) => {
                let inc = |c: &mut u64| *c = c.saturating_add(1);
                inc(&mut self.errors);
                if raw.iter().all(|b| *b == 0) {
                    inc(&mut self.all_zero);
                } else if raw.iter().all(|b| *b == 0xFF) {
                    inc(&mut self.all_ff);
                }
                None
            }
        }
    }

    /// Why nothing fresh came, if so: no reply decoded (and what the bytes were), or a stale board.
    fn why(&self) -> Option<&'static str> {
        if self.decoded == 0 {
            Some(if self.errors == 0 {
                "no transfer was made"
            } else if self.all_zero == self.errors {
                HINT_ZERO
            } else if self.all_ff == self.errors {
                HINT_FF
            } else {
                HINT_VERSION
            })
        } else if self.stale() {
            Some("update_time never advanced: the board answers with a frozen TxBuffer (its SPI callback does not run)")
        } else {
            None
        }
    }

    /// Decoded replies came, all with the same `update_time`.
    fn stale(&self) -> bool {
        self.decoded >= 2 && self.advanced == 0
    }

    fn json(&self) -> Value {
        json!({"decoded": self.decoded, "errors": self.errors, "errors_all_0x00": self.all_zero,
            "errors_all_0xff": self.all_ff,
            "update_time": {"first": self.first_time, "last": self.last_time,
                "advanced": self.advanced > 0},
            "stale": self.stale()})
    }
}

/// The line of a reply that does not decode.
fn bad_json(reason: RejectReason, version: u8, raw: &[u8]) -> Value {
    json!({"error": format!("{reason:?}").to_lowercase(), "version_byte": version, "hint": hint(raw)})
}

fn merge(mut a: Value, b: Value) -> Value {
    if let (Value::Object(a), Value::Object(b)) = (&mut a, b) {
        a.extend(b);
    }
    a
}

fn lines(sink: &mut dyn FnMut(Value)) -> Lines<'_> {
    Lines {
        t0: Instant::now(),
        sink,
    }
}

fn link_err(e: LinkError) -> String {
    e.to_string()
}

/// `ping --kind pi-spi`: `count` (at least [`MIN_PINGS`]) ignored transfers 10 ms apart; `done` if
/// at least two replies decoded and `update_time` advanced, `no_reply` otherwise.
pub fn run_ping<D: Transport>(
    dev: &mut D,
    count: u32,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    let mut out = lines(sink);
    let count = count.max(MIN_PINGS);
    let period = Duration::from_secs_f64(1.0 / DEFAULT_HZ);
    let mut pacer = Pacer::new(period, device::SPIN);
    let mut rec = Received::default();
    let (mut rtt_min, mut rtt_max, mut rtt_sum) = (u64::MAX, 0u64, 0u64);
    for i in 0..count {
        if i > 0 {
            pacer.wait();
        }
        let (reply, took, raw) = transfer(dev, &IGNORED).map_err(link_err)?;
        let rtt = device::us(took);
        (rtt_min, rtt_max, rtt_sum) = (
            rtt_min.min(rtt),
            rtt_max.max(rtt),
            rtt_sum.saturating_add(rtt),
        );
        let advanced = rec.add(&reply, &raw);
        let head = json!({"ping": i, "round_trip_us": rtt});
        out.put(match &reply {
            Reply::Tx(tx) => merge(head, json!({"tx": tx_json(tx), "advanced": advanced})),
            Reply::Bad(r, v) => merge(head, bad_json(*r, *v, &raw)),
        });
    }
    let verdict = if rec.advanced > 0 {
        Verdict::Done
    } else {
        Verdict::NoReply
    };
    let why = rec.why().map(Value::from).unwrap_or_else(|| {
        if rec.advanced == 0 {
            Value::from("fewer than two replies decoded: cannot tell whether update_time advances")
        } else {
            Value::Null
        }
    });
    out.put(merge(
        json!({"verdict": verdict.as_str(), "transfers": count, "why": why,
            "round_trip_us": {"min": rtt_min, "max": rtt_max,
                "mean": rtt_sum.checked_div(u64::from(count)).unwrap_or(0)}}),
        rec.json(),
    ));
    Ok(verdict)
}

/// A checked `monitor --kind pi-spi`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MonitorPlan {
    /// Time between transfers.
    pub period: Duration,
    /// Transfers to make.
    pub transfers: u64,
}

impl MonitorPlan {
    /// `count` transfers if given, else one per period for `seconds`; `hz` in (0, 1000].
    pub fn new(hz: f64, seconds: f64, count: Option<u64>) -> Result<Self, String> {
        let (period, frames, _) = device::paced_frames(hz, seconds)?;
        match count {
            Some(0) => Err("--count 0: give the number of transfers, at least 1".into()),
            Some(n) => Ok(Self {
                period,
                transfers: n,
            }),
            None => Ok(Self {
                period,
                transfers: frames,
            }),
        }
    }
}

/// `monitor --kind pi-spi`: ignored transfers on absolute deadlines, every reply printed, until the
/// plan's count or `stop()`; `done` if `update_time` advanced, `no_reply` otherwise.
pub fn run_monitor<D: Transport>(
    dev: &mut D,
    plan: &MonitorPlan,
    stop: &mut dyn FnMut() -> bool,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    let mut out = lines(sink);
    let mut pacer = paced(plan.period);
    let mut rec = Received::default();
    let mut sent = 0u64;
    let mut interrupted = false;
    while sent < plan.transfers {
        if sent > 0 {
            pacer.wait();
        }
        if stop() {
            interrupted = true;
            break;
        }
        let (reply, _, raw) = transfer(dev, &IGNORED).map_err(link_err)?;
        rec.add(&reply, &raw);
        out.put(reply_json(sent, &reply, &raw));
        sent = sent.saturating_add(1);
    }
    let verdict = if rec.advanced > 0 {
        Verdict::Done
    } else {
        Verdict::NoReply
    };
    out.put(merge(
        json!({"verdict": verdict.as_str(), "transfers": sent, "why": rec.why(),
            "pacing": device::pacing_json(&pacer.stats), "interrupted": interrupted}),
        rec.json(),
    ));
    Ok(verdict)
}

/// A pacer for `period` whose statistics use a tenth of it as the tolerance.
fn paced(period: Duration) -> Pacer {
    let mut p = Pacer::new(period, device::SPIN);
    p.stats = PeriodStats::new(period, period.checked_div(10).unwrap_or(period));
    p
}

/// The line of transfer `k`'s reply.
fn reply_json(k: u64, reply: &Reply, raw: &[u8]) -> Value {
    match reply {
        Reply::Tx(tx) => json!({"transfer": k, "tx": tx_json(tx)}),
        Reply::Bad(r, v) => merge(json!({"transfer": k}), bad_json(*r, *v, raw)),
    }
}

/// `drive --kind pi-spi`: checks the arguments, and only then opens the device (`open`) and runs
/// [`run_drive`]. An argument error returns before `open` is called: nothing is sent.
pub fn drive<D: Transport>(
    args: &PiDriveArgs,
    hz: f64,
    seconds: f64,
    open: impl FnOnce() -> Result<D, String>,
    stop: &mut dyn FnMut() -> bool,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    let plan = PiDrivePlan::new(args, hz, seconds)?;
    let mut dev = open()?;
    run_drive(&mut dev, &plan, stop, sink)
}

/// What a drive saw of the motors.
#[derive(Clone, Copy, Debug, Default)]
struct Motion {
    /// Decoded replies prepared after the first command transfer.
    after_command: u64,
    /// Motors whose position differed from the first reply in any later reply.
    moved: [bool; 4],
}

impl Motion {
    fn add(&mut self, k: u64, tx: &TxBuffer, first: Option<[i32; 4]>) {
        // The reply of transfer k was prepared after transfer k - 1: the first command is transfer
        // ARM_TRANSFERS, so its effect shows from transfer ARM_TRANSFERS + 1 on.
        if k <= ARM_TRANSFERS {
            return;
        }
        self.after_command = self.after_command.saturating_add(1);
        if let Some(first) = first {
            for ((m, p), f) in self.moved.iter_mut().zip(tx.motor.position).zip(first) {
                *m |= p != f;
            }
        }
    }
}

/// Runs a checked drive (see the module docs): the arm transfer, the command transfers on absolute
/// deadlines until the plan's count or `stop()`, then the shutdown transfer, which is also sent
/// after a failed transfer (and that error returned).
pub fn run_drive<D: Transport>(
    dev: &mut D,
    plan: &PiDrivePlan,
    stop: &mut dyn FnMut() -> bool,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    let mut out = lines(sink);
    let hz = 1.0 / plan.period.as_secs_f64();
    out.put(
        json!({"sending": rx_json(&plan.command), "oneshot_updates": plan.oneshot.0,
        "arm_transfers": ARM_TRANSFERS, "frames": plan.frames, "hz": hz}),
    );
    let arm = transfer_bytes(&plan.arm_buffer());
    let command = transfer_bytes(&plan.command);
    let down = transfer_bytes(&plan.shutdown_buffer());
    let total = plan.frames.saturating_add(ARM_TRANSFERS);
    let mut pacer = paced(plan.period);
    let mut rec = Received::default();
    let mut motion = Motion::default();
    let mut k = 0u64;
    let mut interrupted = false;
    let mut take = |k: u64, reply: &Reply, raw: &[u8], out: &mut Lines<'_>| {
        rec.add(reply, raw);
        if let Reply::Tx(tx) = reply {
            motion.add(k, tx, rec.first_position);
        }
        if matches!(reply, Reply::Bad(..)) || k.checked_rem(plan.every) == Some(0) {
            out.put(reply_json(k, reply, raw));
        }
    };
    let failed = loop {
        if k >= total {
            break None;
        }
        if k > 0 {
            pacer.wait();
        }
        if stop() {
            interrupted = true;
            break None;
        }
        let buf = if k < ARM_TRANSFERS { &arm } else { &command };
        match transfer(dev, buf) {
            Ok((reply, _, raw)) => take(k, &reply, &raw, &mut out),
            Err(e) => break Some(e),
        }
        k = k.saturating_add(1);
    };
    // The shutdown buffer: on the next deadline after a complete run, at once otherwise.
    if failed.is_none() && !interrupted {
        pacer.wait();
    }
    let shutdown = transfer(dev, &down);
    let shutdown_sent = shutdown.is_ok();
    if let Ok((reply, _, raw)) = &shutdown {
        take(k, reply, raw, &mut out);
    }
    let commands = k.saturating_sub(ARM_TRANSFERS);
    let transfers = json!({"arm": k.min(ARM_TRANSFERS), "command": commands,
        "shutdown": shutdown_sent});
    if let Some(e) = failed {
        let shutdown_note = match shutdown {
            Ok(_) => "the shutdown buffer (both shutdown bits) was sent after it".to_string(),
            Err(e2) => format!("the shutdown buffer could not be sent either ({e2}); the board brakes on its own 49 ms after the last valid transfer"),
        };
        let msg = format!("transfer {k} failed: {e}; {shutdown_note}");
        out.put(json!({"error": msg, "transfers": transfers, "received": rec.json()}));
        return Err(msg);
    }
    let commanded = plan.commanded(rec.first_position);
    let long_enough = plan
        .period
        .checked_mul(u32::try_from(commands).unwrap_or(u32::MAX))
        .is_none_or(|d| d >= REFUSED_AFTER);
    let refused = long_enough
        && motion.after_command > 0
        && commanded.iter().any(|c| *c)
        && !commanded.iter().zip(motion.moved).any(|(c, m)| *c && m);
    let verdict = if rec.advanced == 0 {
        Verdict::NoReply
    } else if refused {
        Verdict::Refused
    } else {
        Verdict::Done
    };
    let why = match verdict {
        Verdict::NoReply => rec.why(),
        Verdict::Refused => Some("no motor commanded to move changed its position: the board did not leave BRAKE (or the wheels are blocked)"),
        Verdict::Done => None,
    };
    out.put(merge(
        json!({"verdict": verdict.as_str(), "why": why, "transfers": transfers,
            "commanded": commanded, "moved": motion.moved, "pacing": device::pacing_json(&pacer.stats),
            "interrupted": interrupted}),
        rec.json(),
    ));
    Ok(verdict)
}

/// SIGINT, SIGTERM and SIGHUP as a flag: the signals are blocked in the calling thread and read,
/// without waiting, from a signalfd. Blocked signals cannot end the process between two transfers,
/// so a drive always ends with its shutdown buffer; they are checked once per period.
pub struct Signals {
    fd: SignalFd,
    seen: bool,
}

impl Signals {
    /// The signals ending a run.
    fn set() -> SigSet {
        let mut set = SigSet::empty();
        for s in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP] {
            set.add(s);
        }
        set
    }

    /// Blocks the signals in this thread (call it before any other thread starts) and opens the
    /// signalfd that reports them.
    pub fn block() -> Result<Self, String> {
        let set = Self::set();
        set.thread_block()
            .map_err(|e| format!("cannot block SIGINT/SIGTERM: {e}"))?;
        let fd = SignalFd::with_flags(&set, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)
            .map_err(|e| format!("cannot open a signalfd: {e}"))?;
        Ok(Self { fd, seen: false })
    }

    /// True once one of the signals has arrived (it stays true).
    pub fn received(&mut self) -> bool {
        if !self.seen {
            self.seen = matches!(self.fd.read_signal(), Ok(Some(_)));
        }
        self.seen
    }
}

/// An RxBuffer as JSON (the shape `motorlink decode --frame pi-rx` prints).
fn rx_json(rx: &RxBuffer) -> Value {
    serde_json::to_string(rx)
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or(Value::Null)
}

#[cfg(test)]
mod tests;
