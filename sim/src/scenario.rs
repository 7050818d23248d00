//! Scenario files: what the host is asked to do when, which faults happen when, and what must hold.
//!
//! A scenario is TOML (see `sim/scenarios/*.toml`); every time is in seconds of true time.
//!
//! ```toml
//! name = "gc-pause-50ms"
//! duration_s = 2.0
//! [[cmd_vel]]            # what Nav2 publishes (piecewise constant), at nav2_rate_hz
//! from_s = 0.2
//! to_s = 2.0
//! v = 1.0
//! w = 0.0
//! [[faults]]
//! kind = "gc_pause"      # the host process stops: no frames, no cmd_vel handling
//! at_s = 1.0
//! duration_s = 0.05
//! [expect]
//! brake_after_last_frame_ms = [9.0, 10.0]
//! ```
//!
//! `profile` chooses the board: `"amr-spi"` (the default: seed 000, the SPI host and the
//! differential-drive robot), `"cdc"` (seed 001: four PWM motors, settings in `[cdc]`) or
//! `"teensy"` (seed 003: a four-joint stepper arm, settings in `[teensy]`) or `"pi-spi"` (seed 004:
//! the Raspberry Pi's packed buffers over SPI2, four encoder motors of a skid-steer robot and four
//! servos, settings in `[pi_spi]`). The serial profiles share the line settings of `[serial]`; they
//! and `pi-spi` accept the faults `link_cut`, `gc_pause` and `corruption` (of the host's frames or
//! transfers); see `cdc-4wd-timeout.toml`, `teensy-arm-angles.toml` and
//! `pi-spi-odometry-servos.toml`.

use crate::plant::PlantParams;
use serde::{Deserialize, Serialize};

/// One piece of Nav2's velocity command profile.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CmdVelSegment {
    /// Start, s.
    pub from_s: f64,
    /// End (exclusive), s.
    pub to_s: f64,
    /// Forward speed, m/s.
    pub v: f64,
    /// Yaw rate, rad/s.
    pub w: f64,
}

/// Something the operator or the host software asks for at a given time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// Arm the drive (sends enable 0 then 1).
    Arm {
        /// When, s.
        at_s: f64,
    },
    /// Explicit re-arm after BRAKE (operator action).
    Rearm {
        /// When, s.
        at_s: f64,
    },
    /// Disable the drive.
    Disarm {
        /// When, s.
        at_s: f64,
    },
}

impl Request {
    /// When the request is made, s.
    pub fn at(&self) -> f64 {
        match *self {
            Self::Arm { at_s } | Self::Rearm { at_s } | Self::Disarm { at_s } => at_s,
        }
    }
}

/// Which wheel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wheel {
    /// Left wheel (index 0).
    Left,
    /// Right wheel (index 1).
    Right,
}

impl Wheel {
    /// Index into (left, right) arrays.
    pub fn index(self) -> usize {
        match self {
            Self::Left => 0,
            Self::Right => 1,
        }
    }
}

/// An injected fault.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Fault {
    /// EMI on the link: each command frame in the window is corrupted with probability `rate`
    /// (random bit flips or a burst of random bytes, as EMI would).
    Corruption {
        /// Probability per frame.
        rate: f64,
        /// Window start, s (default 0).
        #[serde(default)]
        from_s: f64,
        /// Window end, s (default: the whole run).
        #[serde(default = "forever")]
        to_s: f64,
        /// Also corrupt feedback frames at the same rate.
        #[serde(default)]
        feedback: bool,
    },
    /// A host stall: the host process pauses (garbage collection): no SPI transfers, no cmd_vel.
    GcPause {
        /// Start, s.
        at_s: f64,
        /// Length, s.
        duration_s: f64,
    },
    /// Nav2 misses cycles: no cmd_vel published for the duration (the bridge keeps sending).
    Nav2Gap {
        /// Start, s.
        at_s: f64,
        /// Length, s.
        duration_s: f64,
    },
    /// The SPI link is cut (cable, connector): transfers return garbage-free silence.
    LinkCut {
        /// Start, s.
        at_s: f64,
        /// Length, s.
        duration_s: f64,
    },
    /// Clock rates: the MCU crystal and the host clock deviate from true time.
    ClockDrift {
        /// MCU clock error, ppm (positive: fast).
        mcu_ppm: f64,
        /// Host clock error, ppm.
        #[serde(default)]
        host_ppm: f64,
    },
    /// The MCU firmware hangs: no interrupt runs, the bridge keeps its last PWM, the SPI DMA keeps
    /// replaying the last feedback; the hardware watchdog resets the MCU after `iwdg_ms`.
    McuFreeze {
        /// Start, s.
        at_s: f64,
        /// Independent watchdog timeout, ms.
        #[serde(default = "default_iwdg_ms")]
        iwdg_ms: f64,
    },
    /// A wheel encoder glitches: its counter jumps by `counts` (EMI on the A/B lines).
    EncoderGlitch {
        /// When, s.
        at_s: f64,
        /// Which wheel.
        wheel: Wheel,
        /// Counter jump.
        #[serde(default = "default_glitch")]
        counts: i32,
    },
    /// A motor lead shorts to ground through the shunt: `amps` of extra current that the bridge
    /// cannot control, seen by the current sensor.
    Overcurrent {
        /// Start, s.
        at_s: f64,
        /// Length, s.
        duration_s: f64,
        /// Which wheel.
        wheel: Wheel,
        /// Fault current, A.
        amps: f64,
    },
    /// The emergency-stop button is pressed at `at_s` and released at `release_s`.
    Estop {
        /// Press, s.
        at_s: f64,
        /// Release, s.
        release_s: f64,
    },
}

impl Fault {
    /// The time window the fault acts in, `[start, end)` in s: a corruption's `from_s..to_s`, an
    /// ESTOP's press to release, `at_s` plus `duration_s` for a pause, a gap, a cut or an
    /// overcurrent. `None` for the faults that have no window.
    pub fn window(&self) -> Option<(f64, f64)> {
        match *self {
            Self::Corruption { from_s, to_s, .. } => Some((from_s, to_s)),
            Self::GcPause { at_s, duration_s }
            | Self::Nav2Gap { at_s, duration_s }
            | Self::LinkCut { at_s, duration_s }
            | Self::Overcurrent {
                at_s, duration_s, ..
            } => Some((at_s, at_s + duration_s)),
            Self::Estop { at_s, release_s } => Some((at_s, release_s)),
            Self::ClockDrift { .. } | Self::McuFreeze { .. } | Self::EncoderGlitch { .. } => None,
        }
    }

    /// True if `t` (s) falls in the fault's [`Fault::window`].
    pub fn active_at(&self, t: f64) -> bool {
        self.window()
            .is_some_and(|(start, end)| t >= start && t < end)
    }
}

fn forever() -> f64 {
    f64::INFINITY
}
fn default_iwdg_ms() -> f64 {
    20.0
}
fn default_glitch() -> i32 {
    3000
}

/// Which board and link a scenario runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Profile {
    /// Seed 000: the SPI link at 1 kHz, two velocity-controlled wheels.
    #[default]
    AmrSpi,
    /// Seed 001: `AA 55` frames over USB CDC or a UART, four open-loop PWM motors.
    Cdc,
    /// Seed 003: robust COBS frames over a UART, four stepper joints.
    Teensy,
    /// Seed 004: the Raspberry Pi's packed `RxBuffer` / `TxBuffer` over SPI2 at 100 Hz, four
    /// encoder motors in the seed's five modes, four servos, odometry.
    PiSpi,
}

impl Profile {
    /// The name scenarios use.
    pub fn name(self) -> &'static str {
        match self {
            Self::AmrSpi => "amr-spi",
            Self::Cdc => "cdc",
            Self::Teensy => "teensy",
            Self::PiSpi => "pi-spi",
        }
    }

    /// The board's ladder configuration.
    pub fn config(self) -> statemachine::Config {
        match self {
            Self::AmrSpi => mcu::tuning::AMR.ladder,
            Self::Cdc => statemachine::Config::CDC,
            Self::Teensy => statemachine::Config::TEENSY,
            Self::PiSpi => statemachine::Config::PI_SPI,
        }
    }
}

/// The serial line of the seed 001 and seed 003 profiles (both directions).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SerialSettings {
    /// Line rate, bit/s (8N1: ten bits per byte).
    pub baud: f64,
    /// Latency added to every byte, ms (a USB host stack's; 0 for a bare UART).
    pub latency_ms: f64,
    /// Probability per bit of a flip on the host → board direction.
    pub bit_error_rate: f64,
}

impl Default for SerialSettings {
    fn default() -> Self {
        Self {
            baud: 115_200.0,
            latency_ms: 0.0,
            bit_error_rate: 0.0,
        }
    }
}

/// A piece of the seed 001 host's drive: the `SET_MOTOR_PWM` values it streams.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PwmSegment {
    /// Start, s.
    pub from_s: f64,
    /// End (exclusive), s.
    pub to_s: f64,
    /// pwm_m1 … pwm_m4, −1000 ..= 1000 (m1, m3 left; m2, m4 right).
    pub pwm: [i16; 4],
}

/// A low-rate seed 001 message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CdcMessage {
    /// `MOTOR_ENABLE 1`.
    Enable,
    /// `MOTOR_ENABLE 0`.
    Disable,
    /// `ESTOP 1`.
    Estop,
    /// `ESTOP 0`.
    Release,
    /// `PING`.
    Ping,
}

/// A low-rate message the seed 001 host sends at a given time, and the ACK it must get.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CdcCommand {
    /// When, s.
    pub at_s: f64,
    /// What.
    pub message: CdcMessage,
    /// The ACK `result` the board must answer (0 OK, 1 refused); none expected for `ping`.
    #[serde(default)]
    pub ack: Option<u8>,
}

/// The seed 001 host and board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CdcSettings {
    /// `SET_MOTOR_PWM` rate, Hz (streamed for the whole run, zeros outside the drive segments).
    pub frame_hz: f64,
    /// Every frame's `timeout_ms`.
    pub timeout_ms: u16,
    /// What the host drives.
    pub drive: Vec<PwmSegment>,
    /// Low-rate messages.
    pub commands: Vec<CdcCommand>,
}

impl Default for CdcSettings {
    fn default() -> Self {
        Self {
            frame_hz: 50.0,
            timeout_ms: 200,
            drive: Vec::new(),
            commands: vec![CdcCommand {
                at_s: 0.01,
                message: CdcMessage::Enable,
                ack: Some(0),
            }],
        }
    }
}

impl CdcSettings {
    /// The pwm values the host streams at `t`.
    pub fn pwm_at(&self, t: f64) -> [i16; 4] {
        self.drive
            .iter()
            .find(|s| t >= s.from_s && t < s.to_s)
            .map_or([0; 4], |s| s.pwm)
    }
}

/// A piece of the seed 003 host's motion: the `MTRS` it streams.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointMove {
    /// Start, s.
    pub from_s: f64,
    /// End (exclusive), s: the joints must be there by then.
    pub to_s: f64,
    /// Joint angles, degrees.
    pub deg: [i32; 4],
    /// Speed cap, degrees per second.
    pub speed_deg_s: i32,
    /// The `cmd_success` every echo must carry (false: the board must refuse the move).
    #[serde(default = "yes")]
    pub success: bool,
}

/// A seed 003 command besides the `MTRS` stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TeensyCmd {
    /// `CAL`: the re-arm.
    Cal,
    /// One `MTRS` to `deg` at `speed_deg_s` (e.g. one out of the travel, which the board refuses).
    Mtrs,
    /// `MTRS` with `is_relative` = 1.
    Relative,
    /// `ENDEFF_ON`.
    EndeffOn,
    /// `ENDEFF_OFF`.
    EndeffOff,
    /// `CONFIG` with `accel_deg_s2`.
    Config,
}

/// A one-off seed 003 command and the `cmd_success` its echo must carry.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TeensyCommand {
    /// When, s.
    pub at_s: f64,
    /// What.
    pub cmd: TeensyCmd,
    /// Angles of an `mtrs` or `relative` command, degrees.
    #[serde(default)]
    pub deg: [i32; 4],
    /// Speed of an `mtrs` or `relative` command, degrees per second.
    #[serde(default)]
    pub speed_deg_s: i32,
    /// Acceleration of a `CONFIG`, degrees per second².
    #[serde(default)]
    pub accel_deg_s2: i32,
    /// The `cmd_success` the echo must carry.
    #[serde(default = "yes")]
    pub success: bool,
}

/// The seed 003 host and board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TeensySettings {
    /// `MTRS` rate while a move is in force, Hz.
    pub frame_hz: f64,
    /// The moves, in time order.
    pub moves: Vec<JointMove>,
    /// Other commands.
    pub commands: Vec<TeensyCommand>,
}

impl Default for TeensySettings {
    fn default() -> Self {
        Self {
            frame_hz: 50.0,
            moves: Vec::new(),
            commands: vec![TeensyCommand {
                at_s: 0.01,
                cmd: TeensyCmd::Cal,
                deg: [0; 4],
                speed_deg_s: 0,
                accel_deg_s2: 0,
                success: true,
            }],
        }
    }
}

impl TeensySettings {
    /// The move in force at `t`.
    pub fn move_at(&self, t: f64) -> Option<&JointMove> {
        self.moves.iter().find(|m| t >= m.from_s && t < m.to_s)
    }
}

fn yes() -> bool {
    true
}

/// A seed 004 motor mode (`motorControlMode`), as scenarios name it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PiMotorMode {
    /// `MOT_MODE_OFF`: coast.
    #[default]
    Off,
    /// `MOT_MODE_PASSIV_BRAKE`: short brake.
    PassiveBrake,
    /// `MOT_MODE_PWM`: `targets` is the duty, −399 ..= 399.
    Pwm,
    /// `MOT_MODE_MAV`: `targets` is the velocity, encoder counts per second.
    Mav,
    /// `MOT_MODE_MTP`: `goals` is the position, counts; `targets` caps the speed, counts/s.
    Mtp,
}

/// A seed 004 servo mode (`servoMode`), as scenarios name it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PiServoMode {
    /// `SERVO_FULLY_DISABLED`: no pulse; the 6 V rail is cut when all four are.
    #[default]
    FullyDisabled,
    /// `SERVO_DISABLED`: no pulse, the rail stays on.
    Disabled,
    /// `SERVO_ENABLED`: a pulse of `positions` µs.
    Enabled,
}

/// A time window of the seed 004 host's motor command, as the wire carries it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiSegment {
    /// Start, s.
    pub from_s: f64,
    /// End (exclusive), s.
    pub to_s: f64,
    /// Mode of motors 1–4 (m1, m3 left; m2, m4 right).
    pub modes: [PiMotorMode; 4],
    /// `motorTarget`: duty (PWM), counts/s (MAV), speed cap in counts/s (MTP).
    #[serde(default)]
    pub targets: [i32; 4],
    /// `motorGoalPosition` (MTP), counts.
    #[serde(default)]
    pub goals: [i32; 4],
}

/// A servo command of the seed 004 host, in force from `at_s` until the next.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiServoCommand {
    /// From, s.
    pub at_s: f64,
    /// Mode of servos 1–4.
    pub modes: [PiServoMode; 4],
    /// `servoPos`, timer ticks (µs), 600–2600 for an enabled servo.
    #[serde(default)]
    pub positions: [u16; 4],
}

/// Shutdown bits the seed 004 host sets (`systemShutdown`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiShutdown {
    /// From, s: the first transfer at or after it carries the bits.
    pub at_s: f64,
    /// How long every transfer carries them, s; 0 (the default): that one transfer only.
    #[serde(default)]
    pub for_s: f64,
    /// Bit 1, `SHUTDOWN_MOTOR`. The first valid transfer without it afterwards is the re-arm.
    #[serde(default)]
    pub motors: bool,
    /// Bit 0, `SHUTDOWN_SERVO`.
    #[serde(default)]
    pub servos: bool,
}

/// A `KinematicsConfig` as the host sends it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiKinematics {
    /// Rows vx, vy, wz; columns wheels 1–4: body twist = inverse × wheel speeds (rad/s).
    pub inverse: [[f32; 4]; 3],
    /// Radians per encoder count, wheels 1–4.
    pub ticks_to_rad: [f32; 4],
}

/// The seed 004 host and board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PiSpiSettings {
    /// Transfers per second (the seed's 10 ms: 100).
    pub frame_hz: f64,
    /// The motor command over time; outside every segment all four motors are `off`.
    pub segments: Vec<PiSegment>,
    /// The host ramps each MAV target by at most this many counts/s per transfer (the ladder
    /// refuses a velocity step beyond 50 rad/s² × the time since the last valid transfer: 114
    /// counts/s at 100 Hz).
    pub mav_step_cps: i32,
    /// Servo commands; before the first, all four fully disabled.
    pub servos: Vec<PiServoCommand>,
    /// Shutdown bits.
    pub shutdown: Vec<PiShutdown>,
    /// The `KinematicsConfig` sent once, with the `KINEMATICS` flag, at `kinematics_at_s`; none
    /// (the default): the plant's skid steer (wheel radius r, track b, 1440 counts per
    /// revolution): vx = r/4 · Σω, wz = r/(2b) · (ω2 + ω4 − ω1 − ω3).
    pub kinematics: Option<PiKinematics>,
    /// When the kinematics are sent, s (the first transfer at or after).
    pub kinematics_at_s: f64,
    /// When the `ODOM_RESET` flag is sent, s (the first transfer at or after), if ever; the
    /// odometry is then compared with the plant's pose at that transfer (send it at rest).
    pub odom_reset_at_s: Option<f64>,
    /// When the odometry is compared with the plant's pose, s; none: at the end of the run.
    pub odometry_at_s: Option<f64>,
    /// The bytes of the `RxBuffer` a `corruption` fault may change, `[start, end)`: the default
    /// is the whole buffer. The link has no CRC: a change in a target field passes every check.
    pub corrupt_bytes: [usize; 2],
}

impl Default for PiSpiSettings {
    fn default() -> Self {
        Self {
            frame_hz: 100.0,
            segments: Vec::new(),
            mav_step_cps: 100,
            servos: Vec::new(),
            shutdown: vec![PiShutdown {
                at_s: 0.02,
                for_s: 0.0,
                motors: true,
                servos: false,
            }],
            kinematics: None,
            kinematics_at_s: 0.03,
            odom_reset_at_s: None,
            odometry_at_s: None,
            corrupt_bytes: [0, protocol::pi_spi::RX_LEN],
        }
    }
}

impl PiSpiSettings {
    /// The segment in force at `t`.
    pub fn segment_at(&self, t: f64) -> Option<&PiSegment> {
        self.segments.iter().find(|s| t >= s.from_s && t < s.to_s)
    }

    /// The servo command in force at `t`.
    pub fn servo_at(&self, t: f64) -> Option<&PiServoCommand> {
        self.servos
            .iter()
            .filter(|c| c.at_s <= t)
            .max_by(|a, b| a.at_s.total_cmp(&b.at_s))
    }
}

/// Limits the run must respect; checked by [`crate::runner::Summary::check`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Expect {
    /// BRAKE must latch between these times after the last valid frame before it, ms.
    pub brake_after_last_frame_ms: Option<[f64; 2]>,
    /// BRAKE must never latch.
    pub never_brake: bool,
    /// Distance travelled from the fault onset until standstill, at most, m.
    pub max_stop_distance_m: Option<f64>,
    /// Corrupted frames that changed the applied command: at most.
    pub max_corrupted_applied: Option<u64>,
    /// The robot must be moving (|v| > 0.1 m/s) at the end.
    pub moving_at_end: Option<bool>,
    /// The host must have reported these diagnostics (names as in the trace).
    pub host_reports: Vec<String>,
    /// Clock-sync error at the end, at most, µs.
    pub max_clock_error_us: Option<f64>,
    /// Mode at the end (NORMAL, REDUCED, HOLD, STOP, BRAKE).
    pub final_mode: Option<String>,
    /// Serial profiles: BRAKE must latch between these many ticks of the board after the last
    /// valid frame.
    pub brake_after_last_frame_ticks: Option<[u32; 2]>,
    /// Robot speed at the fault onset, at most, m/s.
    pub max_speed_at_onset_mps: Option<f64>,
    /// Seed 001: an `ESTOP 1` must short every motor in the simulation step its last byte arrived.
    pub estop_brakes_at_once: bool,
    /// Seed 003: at the end of each move the board accepted, every joint within this many steps of
    /// its commanded angle.
    pub max_joint_error_steps: Option<f64>,
    /// Seed 003: step pulses issued after the comm-loss BRAKE, at most.
    pub max_steps_after_brake: Option<u64>,
    /// Seed 004: distance between the board's odometry and the plant's pose at the measuring
    /// time, at most, % of the distance travelled.
    pub max_odometry_error_pct: Option<f64>,
    /// Seed 004: servo outputs (per transfer and per tick) that differ from the rules recomputed
    /// by the simulator, at most.
    pub max_servo_violations: Option<u64>,
    /// Seed 004: every transfer with the motor shutdown bit shorts every motor in its own step.
    pub shutdown_brakes_in_its_transfer: bool,
}

/// Host-side settings of a scenario.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HostSettings {
    /// Nav2 cmd_vel rate, Hz.
    pub nav2_rate_hz: f64,
    /// Link period, ms.
    pub link_period_ms: f64,
    /// Send-side scheduling latency, uniform 0..this, µs.
    pub send_jitter_us: f64,
    /// Receive-side latency, 5 µs + uniform 0..this, µs.
    pub recv_jitter_us: f64,
    /// Probability that a cycle is preempted (late by 0.3–3 ms).
    pub preempt_rate: f64,
}

impl Default for HostSettings {
    fn default() -> Self {
        Self {
            nav2_rate_hz: 20.0,
            link_period_ms: 1.0,
            send_jitter_us: 30.0,
            recv_jitter_us: 40.0,
            preempt_rate: 0.0,
        }
    }
}

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name (file stem), used for output files.
    pub name: String,
    /// What it shows.
    #[serde(default)]
    pub description: String,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Random seed.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Write one trace row every this many ms (1 = every watchdog tick).
    #[serde(default = "default_trace_every")]
    pub trace_every_ms: u32,
    /// Host settings.
    #[serde(default)]
    pub host: HostSettings,
    /// Plant parameters.
    #[serde(default)]
    pub plant: PlantParams,
    /// Operator / host requests. Default: arm at 10 ms.
    #[serde(default = "default_requests")]
    pub requests: Vec<Request>,
    /// Nav2's velocity profile.
    #[serde(default)]
    pub cmd_vel: Vec<CmdVelSegment>,
    /// Injected faults.
    #[serde(default)]
    pub faults: Vec<Fault>,
    /// What must hold.
    #[serde(default)]
    pub expect: Expect,
    /// The board and link.
    #[serde(default)]
    pub profile: Profile,
    /// The serial line (profiles `cdc` and `teensy`).
    #[serde(default)]
    pub serial: SerialSettings,
    /// The seed 001 host (profile `cdc`).
    #[serde(default)]
    pub cdc: CdcSettings,
    /// The seed 003 host (profile `teensy`).
    #[serde(default)]
    pub teensy: TeensySettings,
    /// The seed 004 host (profile `pi-spi`).
    #[serde(default)]
    pub pi_spi: PiSpiSettings,
}

fn default_seed() -> u64 {
    1
}
fn default_trace_every() -> u32 {
    1
}
fn default_requests() -> Vec<Request> {
    vec![Request::Arm { at_s: 0.01 }]
}

/// Why a scenario could not be loaded.
#[derive(Debug)]
pub enum ScenarioError {
    /// The file could not be read.
    Io(String, std::io::Error),
    /// The TOML did not parse or did not match the format.
    Parse(String, String),
    /// The values are inconsistent.
    Invalid(String, String),
}

impl core::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "cannot read scenario {p}: {e}"),
            Self::Parse(p, e) => write!(
                f,
                "scenario {p} is not valid TOML for this format: {e}(see sim/scenarios/*.toml for examples)"
            ),
            Self::Invalid(p, e) => write!(f, "scenario {p}: {e}"),
        }
    }
}

impl std::error::Error for ScenarioError {}

impl Scenario {
    /// Parses a scenario from TOML text; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, ScenarioError> {
        let s: Self =
            toml::from_str(text).map_err(|e| ScenarioError::Parse(origin.into(), e.to_string()))?;
        s.validate(origin)?;
        Ok(s)
    }

    /// Reads and parses a scenario file.
    pub fn load(path: &std::path::Path) -> Result<Self, ScenarioError> {
        let origin = path.display().to_string();
        let text =
            std::fs::read_to_string(path).map_err(|e| ScenarioError::Io(origin.clone(), e))?;
        Self::from_toml(&text, &origin)
    }

    fn validate(&self, origin: &str) -> Result<(), ScenarioError> {
        let bad = |m: &str| Err(ScenarioError::Invalid(origin.into(), m.into()));
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 86_400.0) {
            return bad("duration_s must be in (0, 86400]");
        }
        if self.trace_every_ms == 0 {
            return bad("trace_every_ms must be at least 1");
        }
        if !(self.host.link_period_ms > 0.05 && self.host.link_period_ms < 1000.0) {
            return bad("host.link_period_ms must be in (0.05, 1000)");
        }
        if !(self.host.nav2_rate_hz > 0.0 && self.host.nav2_rate_hz <= 1000.0) {
            return bad("host.nav2_rate_hz must be in (0, 1000]");
        }
        match self.plant.kinematics() {
            Ok(_) => {}
            Err(control::KinematicsError::WheelRadius) => {
                return bad("plant.wheel_radius_m must be in [0.001, 10]")
            }
            Err(control::KinematicsError::Wheelbase) => {
                return bad("plant.wheelbase_m must be in [0.01, 64]")
            }
        }
        for f in &self.faults {
            if let Fault::Corruption { rate, .. } = f {
                if !(0.0..=1.0).contains(rate) {
                    return bad("corruption rate must be in [0, 1]");
                }
            }
        }
        match self.profile {
            Profile::AmrSpi => {}
            Profile::PiSpi => self.validate_pi_spi(origin)?,
            Profile::Cdc | Profile::Teensy => self.validate_serial(origin)?,
        }
        Ok(())
    }

    /// The faults a scripted-host profile takes: `link_cut`, `gc_pause`, `corruption` of the
    /// host's frames.
    fn host_faults_only(&self, origin: &str, profiles: &str) -> Result<(), ScenarioError> {
        for f in &self.faults {
            match f {
                Fault::LinkCut { .. } | Fault::GcPause { .. } => {}
                Fault::Corruption { feedback, .. } if !feedback => {}
                _ => {
                    return Err(ScenarioError::Invalid(
                        origin.into(),
                        format!("{profiles} take only link_cut, gc_pause and corruption (of the host's frames) faults"),
                    ))
                }
            }
        }
        Ok(())
    }

    fn validate_pi_spi(&self, origin: &str) -> Result<(), ScenarioError> {
        let bad = |m: &str| Err(ScenarioError::Invalid(origin.into(), format!("pi_spi.{m}")));
        self.host_faults_only(origin, "the pi-spi profile")?;
        let p = &self.pi_spi;
        let time = |t: f64| t.is_finite() && t >= 0.0;
        if !(1.0..=1000.0).contains(&p.frame_hz) {
            return bad("frame_hz must be in [1, 1000]");
        }
        if p.segments.iter().any(|s| {
            !time(s.from_s) || s.to_s.partial_cmp(&s.from_s) != Some(core::cmp::Ordering::Greater)
        }) {
            return bad("segments need 0 <= from_s < to_s");
        }
        if !(1..=100_000).contains(&p.mav_step_cps) {
            return bad("mav_step_cps must be in [1, 100000]");
        }
        if p.servos.iter().any(|c| !time(c.at_s)) {
            return bad("servos[].at_s must be a time >= 0");
        }
        if p.shutdown
            .iter()
            .any(|e| !time(e.at_s) || !time(e.for_s) || !(e.motors || e.servos))
        {
            return bad("shutdown events need at_s >= 0, for_s >= 0 and motors or servos set");
        }
        if p.kinematics.is_some_and(|k| {
            k.inverse
                .iter()
                .flatten()
                .chain(&k.ticks_to_rad)
                .any(|x| !x.is_finite())
        }) {
            return bad("kinematics must be finite");
        }
        if !time(p.kinematics_at_s) || p.odom_reset_at_s.is_some_and(|t| !time(t)) {
            return bad("kinematics_at_s and odom_reset_at_s must be times >= 0");
        }
        if p.odometry_at_s
            .is_some_and(|t| !(time(t) && t <= self.duration_s))
        {
            return bad("odometry_at_s must be within the run");
        }
        let [a, b] = p.corrupt_bytes;
        if !(a < b && b <= protocol::pi_spi::RX_LEN) {
            return bad(&format!(
                "corrupt_bytes must be [start, end) with start < end <= {}",
                protocol::pi_spi::RX_LEN
            ));
        }
        Ok(())
    }

    fn validate_serial(&self, origin: &str) -> Result<(), ScenarioError> {
        let bad = |m: &str| Err(ScenarioError::Invalid(origin.into(), m.into()));
        let l = &self.serial;
        if !(l.baud >= 1200.0 && l.baud <= 20e6) {
            return bad("serial.baud must be in [1200, 2e7]");
        }
        if !(l.latency_ms >= 0.0 && l.latency_ms <= 1000.0) {
            return bad("serial.latency_ms must be in [0, 1000]");
        }
        if !(0.0..=0.1).contains(&l.bit_error_rate) {
            return bad("serial.bit_error_rate must be in [0, 0.1]");
        }
        self.host_faults_only(origin, "the serial profiles")?;
        let hz = match self.profile {
            Profile::Cdc => {
                let c = &self.cdc;
                if !(2..=u16::MAX).contains(&c.timeout_ms) {
                    return bad("cdc.timeout_ms must be at least 2");
                }
                if c.drive
                    .iter()
                    .flat_map(|s| s.pwm)
                    .any(|p| p.unsigned_abs() > 1000)
                {
                    return bad("cdc.drive pwm values must be within ±1000");
                }
                c.frame_hz
            }
            Profile::Teensy => {
                let t = &self.teensy;
                if t.moves
                    .iter()
                    .any(|m| m.speed_deg_s <= 0 || m.to_s <= m.from_s)
                {
                    return bad("teensy.moves need a positive speed and to_s > from_s");
                }
                t.frame_hz
            }
            Profile::AmrSpi | Profile::PiSpi => 1000.0,
        };
        if !(1.0..=1000.0).contains(&hz) {
            return bad("frame_hz must be in [1, 1000]");
        }
        Ok(())
    }

    /// The comm-loss bound the run is checked against, ms after the last valid frame (strict):
    /// the profile's ([`statemachine::Config::comm_loss_bound_ms`]), or for seed 001 the frames'
    /// `timeout_ms` if that is earlier.
    pub fn comm_loss_bound_ms(&self) -> f64 {
        let board = f64::from(self.profile.config().comm_loss_bound_ms());
        match self.profile {
            Profile::Cdc => board.min(f64::from(self.cdc.timeout_ms)),
            Profile::AmrSpi | Profile::Teensy | Profile::PiSpi => board,
        }
    }

    /// Nav2's command at time `t`, if a segment covers it.
    pub fn cmd_vel_at(&self, t: f64) -> Option<(f64, f64)> {
        self.cmd_vel
            .iter()
            .find(|s| t >= s.from_s && t < s.to_s)
            .map(|s| (s.v, s.w))
    }

    /// True if a fault of the kind `kind` picks is active at `t`.
    fn any_active(&self, t: f64, kind: impl Fn(&Fault) -> bool) -> bool {
        self.faults.iter().any(|f| kind(f) && f.active_at(t))
    }

    /// True if a `gc_pause` holds the host process at `t`.
    pub fn host_paused(&self, t: f64) -> bool {
        self.any_active(t, |f| matches!(f, Fault::GcPause { .. }))
    }

    /// True if a `link_cut` cuts the link at `t`.
    pub fn link_cut(&self, t: f64) -> bool {
        self.any_active(t, |f| matches!(f, Fault::LinkCut { .. }))
    }

    /// True if Nav2 publishes nothing at `t` (`nav2_gap`).
    pub fn nav2_gap(&self, t: f64) -> bool {
        self.any_active(t, |f| matches!(f, Fault::Nav2Gap { .. }))
    }

    /// The simulation steps of `dt` s that cover the run: (index, time s).
    pub fn steps(&self, dt: f64) -> impl Iterator<Item = (u64, f64)> {
        let n = (self.duration_s / dt).ceil() as u64;
        (0..n).map(move |k| (k, k as f64 * dt))
    }

    /// The MCU and host clock errors, ppm.
    pub fn drift_ppm(&self) -> (f64, f64) {
        self.faults
            .iter()
            .find_map(|f| match *f {
                Fault::ClockDrift { mcu_ppm, host_ppm } => Some((mcu_ppm, host_ppm)),
                _ => None,
            })
            .unwrap_or((0.0, 0.0))
    }

    /// Time of the first fault that disturbs the link or the drive (for stopping distances), s.
    pub fn fault_onset(&self) -> Option<f64> {
        self.faults
            .iter()
            .filter_map(|f| match *f {
                Fault::GcPause { at_s, .. }
                | Fault::LinkCut { at_s, .. }
                | Fault::McuFreeze { at_s, .. }
                | Fault::EncoderGlitch { at_s, .. }
                | Fault::Overcurrent { at_s, .. }
                | Fault::Estop { at_s, .. }
                | Fault::Nav2Gap { at_s, .. } => Some(at_s),
                Fault::Corruption { .. } | Fault::ClockDrift { .. } => None,
            })
            .fold(None, |acc: Option<f64>, t| {
                Some(acc.map_or(t, |a| a.min(t)))
            })
    }
}

/// The built-in scenarios, embedded so `motorlink sim` works from any directory.
pub const BUILTIN: [(&str, &str); 17] = [
    ("nominal", include_str!("../scenarios/nominal.toml")),
    (
        "corruption-1e-4",
        include_str!("../scenarios/corruption-1e-4.toml"),
    ),
    (
        "corruption-1e-3",
        include_str!("../scenarios/corruption-1e-3.toml"),
    ),
    (
        "corruption-1e-2",
        include_str!("../scenarios/corruption-1e-2.toml"),
    ),
    (
        "gc-pause-50ms",
        include_str!("../scenarios/gc-pause-50ms.toml"),
    ),
    (
        "nav2-gap-100ms",
        include_str!("../scenarios/nav2-gap-100ms.toml"),
    ),
    (
        "nav2-stall-300ms",
        include_str!("../scenarios/nav2-stall-300ms.toml"),
    ),
    (
        "clock-drift-50ppm",
        include_str!("../scenarios/clock-drift-50ppm.toml"),
    ),
    ("mcu-freeze", include_str!("../scenarios/mcu-freeze.toml")),
    (
        "encoder-failure",
        include_str!("../scenarios/encoder-failure.toml"),
    ),
    ("overcurrent", include_str!("../scenarios/overcurrent.toml")),
    ("estop-rearm", include_str!("../scenarios/estop-rearm.toml")),
    (
        "cdc-4wd-timeout",
        include_str!("../scenarios/cdc-4wd-timeout.toml"),
    ),
    (
        "cdc-estop-release",
        include_str!("../scenarios/cdc-estop-release.toml"),
    ),
    (
        "cdc-bit-errors",
        include_str!("../scenarios/cdc-bit-errors.toml"),
    ),
    (
        "teensy-arm-angles",
        include_str!("../scenarios/teensy-arm-angles.toml"),
    ),
    (
        "pi-spi-odometry-servos",
        include_str!("../scenarios/pi-spi-odometry-servos.toml"),
    ),
];

/// Resets `field` to its default (no expectation) and records `name` if it held one.
fn unjudge<T: Default + PartialEq>(field: &mut T, name: &'static str, out: &mut Vec<&'static str>) {
    if *field != T::default() {
        *field = T::default();
        out.push(name);
    }
}

impl Scenario {
    /// This scenario run for `run_s` seconds instead of its own `duration_s` (`motorlink sim
    /// --duration`): the scenario to run, and the names of the expectations taken out of its
    /// `[expect]` because they depend on its own duration. They are reported as not judged, never
    /// as passed or failed. The simulation is deterministic (same seed, same events), so:
    ///
    /// ```text
    ///  own run   |--------------------------------| duration_s
    ///  shorter   |-------------| run_s              a prefix of the own run
    ///  longer    |--------------------------------|------| run_s   the own run, then more
    /// ```
    ///
    /// - Shorter: only bounds that a prefix cannot break unless the whole run breaks them too are
    ///   judged: `never_brake`, `max_corrupted_applied`, `max_servo_violations`. The others need
    ///   events at or after the cut (a fault's BRAKE, a stop, a move's end, a report) or the end
    ///   state.
    /// - Longer: every event of the scenario happens; what is measured at the end is not judged:
    ///   `moving_at_end`, `final_mode`, `max_clock_error_us` (over the last second), and
    ///   `max_odometry_error_pct` when `pi_spi.odometry_at_s` is not set (then measured at the end).
    /// - The same duration: everything is judged.
    pub fn with_duration(&self, run_s: f64) -> (Self, Vec<&'static str>) {
        let mut sc = self.clone();
        sc.duration_s = run_s;
        let mut not = Vec::new();
        let e = &mut sc.expect;
        if run_s < self.duration_s {
            unjudge(
                &mut e.brake_after_last_frame_ms,
                "brake_after_last_frame_ms",
                &mut not,
            );
            unjudge(&mut e.max_stop_distance_m, "max_stop_distance_m", &mut not);
            unjudge(&mut e.moving_at_end, "moving_at_end", &mut not);
            unjudge(&mut e.host_reports, "host_reports", &mut not);
            unjudge(&mut e.max_clock_error_us, "max_clock_error_us", &mut not);
            unjudge(&mut e.final_mode, "final_mode", &mut not);
            unjudge(
                &mut e.brake_after_last_frame_ticks,
                "brake_after_last_frame_ticks",
                &mut not,
            );
            unjudge(
                &mut e.max_speed_at_onset_mps,
                "max_speed_at_onset_mps",
                &mut not,
            );
            unjudge(
                &mut e.estop_brakes_at_once,
                "estop_brakes_at_once",
                &mut not,
            );
            unjudge(
                &mut e.max_joint_error_steps,
                "max_joint_error_steps",
                &mut not,
            );
            unjudge(
                &mut e.max_steps_after_brake,
                "max_steps_after_brake",
                &mut not,
            );
            unjudge(
                &mut e.max_odometry_error_pct,
                "max_odometry_error_pct",
                &mut not,
            );
            unjudge(
                &mut e.shutdown_brakes_in_its_transfer,
                "shutdown_brakes_in_its_transfer",
                &mut not,
            );
        } else if run_s > self.duration_s {
            unjudge(&mut e.moving_at_end, "moving_at_end", &mut not);
            unjudge(&mut e.final_mode, "final_mode", &mut not);
            unjudge(&mut e.max_clock_error_us, "max_clock_error_us", &mut not);
            if self.pi_spi.odometry_at_s.is_none() {
                unjudge(
                    &mut e.max_odometry_error_pct,
                    "max_odometry_error_pct",
                    &mut not,
                );
            }
        }
        (sc, not)
    }
}

/// Parses every built-in scenario.
pub fn builtin() -> Result<Vec<Scenario>, ScenarioError> {
    BUILTIN
        .iter()
        .map(|(name, text)| Scenario::from_toml(text, &format!("built-in {name}")))
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_profile_defaults_to_seed_000_and_names_the_boards() {
        for (name, text) in BUILTIN {
            let sc = Scenario::from_toml(text, name).unwrap();
            let want = if name.starts_with("cdc-") {
                Profile::Cdc
            } else if name.starts_with("teensy-") {
                Profile::Teensy
            } else if name.starts_with("pi-spi-") {
                Profile::PiSpi
            } else {
                Profile::AmrSpi
            };
            assert_eq!(sc.profile, want, "{name}");
        }
        let with = |extra: &str| {
            Scenario::from_toml(
                &format!("name = \"p\"\nduration_s = 1.0\n{extra}\n"),
                "test",
            )
        };
        assert!(matches!(
            with("profile = \"pi-spi-2\""),
            Err(ScenarioError::Parse(..))
        ));
        assert_eq!(
            with("profile = \"pi-spi\"").unwrap().profile.config(),
            statemachine::Config::PI_SPI
        );
        // The seed 004 board's settings are checked on load, with the field named.
        for (extra, field) in [
            ("[pi_spi]\nframe_hz = 0.0", "frame_hz"),
            ("[pi_spi]\ncorrupt_bytes = [5, 500]", "corrupt_bytes"),
            ("[pi_spi]\nodometry_at_s = 2.0", "odometry_at_s"),
            (
                "[[pi_spi.segments]]\nfrom_s = 0.5\nto_s = 0.5\nmodes = [\"mav\", \"mav\", \"mav\", \"mav\"]",
                "segments",
            ),
            ("[[pi_spi.shutdown]]\nat_s = 0.5", "shutdown"),
        ] {
            let r = with(&format!("profile = \"pi-spi\"\n{extra}"));
            assert!(
                matches!(&r, Err(ScenarioError::Invalid(_, m)) if m.contains(field)),
                "{extra}: {r:?}"
            );
        }
        let r = with("profile = \"pi-spi\"\n[[faults]]\nkind = \"mcu_freeze\"\nat_s = 0.5");
        assert!(
            matches!(&r, Err(ScenarioError::Invalid(_, m)) if m.contains("pi-spi")),
            "{r:?}"
        );
        // The serial boards have no ESTOP button, encoder or clock model here: refused on load.
        let r =
            with("profile = \"teensy\"\n[[faults]]\nkind = \"estop\"\nat_s = 1.0\nrelease_s = 2.0");
        assert!(
            matches!(&r, Err(ScenarioError::Invalid(_, m)) if m.contains("serial profiles")),
            "{r:?}"
        );
        let r = with("profile = \"cdc\"\n[cdc]\ntimeout_ms = 1");
        assert!(
            matches!(&r, Err(ScenarioError::Invalid(_, m)) if m.contains("timeout_ms")),
            "{r:?}"
        );
        // The bound each profile is checked against.
        assert_eq!(with("").unwrap().comm_loss_bound_ms(), 10.0);
        assert_eq!(
            with("profile = \"teensy\"").unwrap().comm_loss_bound_ms(),
            250.0
        );
        assert_eq!(
            with("profile = \"cdc\"").unwrap().comm_loss_bound_ms(),
            200.0
        );
        assert_eq!(
            with("profile = \"pi-spi\"").unwrap().comm_loss_bound_ms(),
            50.0
        );
        assert_eq!(
            with("profile = \"cdc\"\n[cdc]\ntimeout_ms = 400")
                .unwrap()
                .comm_loss_bound_ms(),
            250.0
        );
    }

    /// A plant geometry `control::DiffDrive` refuses is refused when the scenario is read, so
    /// `Plant::new` never sees it.
    #[test]
    fn out_of_range_plant_geometry_is_refused_on_load() {
        let with = |plant: &str| {
            Scenario::from_toml(
                &format!("name = \"g\"\nduration_s = 1.0\n[plant]\n{plant}\n"),
                "test",
            )
        };
        assert!(with("wheel_radius_m = 0.08").is_ok());
        for (plant, field) in [
            ("wheel_radius_m = 0.0", "wheel_radius_m"),
            ("wheel_radius_m = 11.0", "wheel_radius_m"),
            ("wheelbase_m = 0.001", "wheelbase_m"),
            ("wheelbase_m = 1e9", "wheelbase_m"),
        ] {
            let r = with(plant);
            assert!(
                matches!(&r, Err(ScenarioError::Invalid(_, m)) if m.contains(field)),
                "{plant}: {r:?}"
            );
        }
    }

    fn nominal() -> Scenario {
        builtin()
            .unwrap()
            .into_iter()
            .find(|s| s.name == "nominal")
            .unwrap()
    }

    #[test]
    fn a_shorter_run_judges_only_what_a_prefix_cannot_break_falsely() {
        let own = nominal();
        // nominal expects: never_brake, max_corrupted_applied 0, final_mode NORMAL, moving_at_end false.
        let (sc, not) = own.with_duration(own.duration_s / 2.0);
        assert_eq!(not, vec!["moving_at_end", "final_mode"]);
        assert!(sc.expect.never_brake);
        assert_eq!(sc.expect.max_corrupted_applied, Some(0));
        assert_eq!(sc.expect.final_mode, None);
        assert_eq!(sc.expect.moving_at_end, None);
    }

    #[test]
    fn a_longer_run_judges_all_but_the_end_state() {
        let own = nominal();
        let (sc, not) = own.with_duration(own.duration_s * 2.0);
        assert_eq!(not, vec!["moving_at_end", "final_mode"]);
        assert!(sc.expect.never_brake);
        let mut with_reports = own.clone();
        with_reports.expect.host_reports = vec!["mcu_frozen".into()];
        let (sc, not) = with_reports.with_duration(own.duration_s * 2.0);
        assert_eq!(sc.expect.host_reports, vec!["mcu_frozen".to_string()]);
        assert!(!not.contains(&"host_reports"));
        let (sc, not) = with_reports.with_duration(own.duration_s / 2.0);
        assert!(sc.expect.host_reports.is_empty());
        assert!(not.contains(&"host_reports"));
    }

    #[test]
    fn the_own_duration_judges_everything() {
        let own = nominal();
        let (sc, not) = own.with_duration(own.duration_s);
        assert!(not.is_empty());
        assert_eq!(sc, own);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod unknown_keys {
    use super::*;

    /// A misspelt key anywhere in the schema is refused with its name, never dropped.
    #[test]
    fn a_misspelt_key_in_any_table_is_refused_with_its_name() {
        let base = "name = \"t\"\nduration_s = 1.0\n";
        for (extra, typo) in [
            ("descripton = \"x\"", "descripton"),
            ("[expect]\nnever_brak = true", "never_brak"),
            ("[host]\nnav2_rate = 20.0", "nav2_rate"),
            ("[plant]\nwheel_radius = 0.1", "wheel_radius"),
            ("[serial]\nbaudrate = 9600.0", "baudrate"),
            ("[cdc]\nframe_rate = 50.0", "frame_rate"),
            ("[teensy]\nhz = 50.0", "hz"),
            ("[pi_spi]\nframehz = 100.0", "framehz"),
            (
                "[[cmd_vel]]\nfrom_s = 0.0\nto_s = 1.0\nv = 1.0\nw = 0.0\nvv = 2.0",
                "vv",
            ),
            (
                "[[faults]]\nkind = \"gc_pause\"\nat_s = 0.5\nduration_s = 0.05\nlength_s = 1.0",
                "length_s",
            ),
            (
                "[[requests]]\nkind = \"arm\"\nat_s = 0.01\nwhen = 1.0",
                "when",
            ),
            (
                "[[cdc.commands]]\nat_s = 0.1\nmessage = \"ping\"\nak = 0",
                "ak",
            ),
        ] {
            match Scenario::from_toml(&format!("{base}{extra}\n"), "test") {
                Err(ScenarioError::Parse(_, e)) => assert!(e.contains(typo), "{typo}: {e}"),
                other => panic!("{typo} was accepted: {other:?}"),
            }
        }
    }
}
