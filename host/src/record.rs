//! `motorlink record`: every exchange of the 1 kHz bridge to an MCAP file (ROS 2 messages in CDR,
//! readable by ROS 2 tools, Foxglove and Python `rosbags` / `mcap`) or a CSV file.
//!
//! MCAP (profile `ros2`, no compression), one message per exchange on each of:
//!
//! ```text
//!  topic               type                                   what
//!  /cmd_vel            geometry_msgs/msg/Twist                the cmd_vel the bridge was given
//!  /odom               nav_msgs/msg/Odometry                  pose integrated from the encoders, twist from the
//!                                                             measured wheel speeds (feedback frames only)
//!  /joint_states       sensor_msgs/msg/JointState             wheel angle (encoders), speed, motor current as
//!                                                             effort, A (feedback frames only)
//!  /motorlink/frames   JSON, no schema                        both raw frames in hex, host times
//! ```
//! and every [`RecordConfig::diagnostics_every`] exchanges (default 100: 10 Hz) `/diagnostics`
//! (`diagnostic_msgs/msg/DiagnosticArray`): the MCU's mode, fault flags by name and the age of its
//! feedback; the link counters and the bridge's diagnostics since the last one; the clock sync.
//! Message encoding `cdr`, schema encoding `ros2msg`. Log and publish times are the host times
//! the feedback came in (in lockstep simulation the board's clock from 0, so a simulated recording
//! is the same file every time).
//!
//! CSV: one row per exchange, the columns of [`CSV_HEADER`].

pub mod cdr;
pub mod msgs;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use protocol::amr::{self, McuFrame, MotorCommand, MotorFeedback, FRAME_LEN};
use statemachine::Mode;

use crate::bridge::{ArmState, Bridge, BridgeStats, Diagnostic};
use crate::kinematics::DiffDrive;
use crate::link::{ExchangeRecord, Link};
use crate::simlink::{SimMcu, Truth};
use crate::transport::{LinkError, Transport};
use msgs::{
    DiagnosticArray, DiagnosticStatus, Header, JointState, KeyValue, Odometry, RosMessage, Time,
    Twist,
};

/// The file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// MCAP with ROS 2 messages.
    Mcap,
    /// Comma-separated values, one row per exchange.
    Csv,
}

impl Format {
    /// The format a file name asks for: `.mcap` or `.csv`.
    pub fn from_path(path: &Path) -> Result<Self, RecordError> {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("mcap") => Ok(Self::Mcap),
            Some(e) if e.eq_ignore_ascii_case("csv") => Ok(Self::Csv),
            _ => Err(RecordError::Format(path.to_path_buf())),
        }
    }
}

/// Why a recording failed.
#[derive(Debug)]
pub enum RecordError {
    /// The output file name ends in neither `.mcap` nor `.csv`.
    Format(PathBuf),
    /// The output file could not be created or written.
    Io(PathBuf, std::io::Error),
    /// The MCAP writer refused.
    Mcap(PathBuf, String),
    /// An exchange failed.
    Link(LinkError),
    /// A bad plan (seconds, speeds).
    Plan(String),
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Format(p) => write!(
                f,
                "{}: the output file must end in .mcap (ROS 2 messages) or .csv (one row per exchange)",
                p.display()
            ),
            Self::Io(p, e) => write!(f, "cannot write {}: {e}", p.display()),
            Self::Mcap(p, e) => write!(f, "MCAP writer failed on {}: {e}", p.display()),
            Self::Link(e) => write!(f, "{e}"),
            Self::Plan(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for RecordError {}

/// What a recording needs to know besides the exchanges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordConfig {
    /// Robot geometry (odometry from the wheels).
    pub kinematics: DiffDrive,
    /// Encoder counts per wheel revolution (the AMR board: 4096).
    pub counts_per_rev: u32,
    /// A `/diagnostics` message after every this many exchanges (0: none).
    pub diagnostics_every: u64,
    /// Added to the host times (µs) to make log times, ns: the UNIX time of the link's start on a
    /// device, 0 in simulation.
    pub time_origin_ns: u64,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            kinematics: DiffDrive::DEFAULT,
            counts_per_rev: 4096,
            diagnostics_every: 100,
            time_origin_ns: 0,
        }
    }
}

/// The names of the flags set in `bits`, joined by `|` (`""` for none; an unknown bit as `BIT<n>`).
pub fn fault_names(bits: u32) -> String {
    crate::names::fault_names(bits).join("|")
}

pub use crate::names::mode_name;

/// Pose from the encoder counts of successive feedback frames (midpoint integration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Odometer {
    radius_m: f64,
    wheelbase_m: f64,
    rad_per_count: f64,
    last: Option<[i32; 2]>,
    /// Position x, m.
    pub x: f64,
    /// Position y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
}

impl Odometer {
    /// At the origin, facing +x.
    pub fn new(kinematics: &DiffDrive, counts_per_rev: u32) -> Self {
        let c = kinematics.config();
        Self {
            radius_m: c.wheel_radius_m,
            wheelbase_m: c.wheelbase_m,
            rad_per_count: core::f64::consts::TAU / f64::from(counts_per_rev.max(1)),
            last: None,
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        }
    }

    /// Wheel angle of an encoder count, rad.
    pub fn angle(&self, counts: i32) -> f64 {
        f64::from(counts) * self.rad_per_count
    }

    /// Moves by what the encoders travelled since the previous feedback (the first only sets the
    /// reference; counters wrap).
    pub fn update(&mut self, encoders: [i32; 2]) {
        if let Some(prev) = self.last {
            let d = [0, 1].map(|k| {
                let (now, before) = (
                    encoders.get(k).copied().unwrap_or(0),
                    prev.get(k).copied().unwrap_or(0),
                );
                f64::from(now.wrapping_sub(before)) * self.rad_per_count * self.radius_m
            });
            let [dl, dr] = d;
            let ds = (dl + dr) / 2.0;
            let dtheta = (dr - dl) / self.wheelbase_m;
            let mid = self.theta + dtheta / 2.0;
            self.x += ds * mid.cos();
            self.y += ds * mid.sin();
            self.theta += dtheta;
        }
        self.last = Some(encoders);
    }
}

/// Everything about one exchange that is recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Exchange number from 0.
    pub index: u64,
    /// The exchange (host times, both frames).
    pub exchange: ExchangeRecord,
    /// The cmd_vel the bridge was given (v m/s, ω rad/s).
    pub cmd_vel: (f64, f64),
    /// The command sent (decoded back from the frame).
    pub command: Option<MotorCommand>,
    /// The feedback, if the feedback slot held a valid one.
    pub feedback: Option<MotorFeedback>,
    /// What else the slot held: `"info"` (an `McuInfo`) or the decoder's refusal.
    pub other: Option<String>,
    /// Odometry after this exchange: x, y, θ.
    pub pose: [f64; 3],
    /// Body velocity from the measured wheel speeds: v, ω.
    pub twist: [f64; 2],
    /// Host time since the last valid feedback, µs (0 for this one).
    pub feedback_age_us: Option<u64>,
    /// The bridge's arming state after the exchange.
    pub arm_state: ArmState,
    /// The bridge's counters after the exchange.
    pub stats: BridgeStats,
    /// Exchanges that failed at the transport so far.
    pub transport_errors: u64,
    /// Clock sync acquired.
    pub clock_synced: bool,
    /// MCU − host clock offset, µs, if known.
    pub clock_offset_us: Option<f64>,
    /// The bridge's diagnostics of this exchange, by name.
    pub diagnostics: Vec<&'static str>,
    /// The simulator's ground truth, if the other end is simulated.
    pub truth: Option<Truth>,
}

/// The CSV columns.
pub const CSV_HEADER: &str = "index,t_send_us,t_recv_us,cmd_v,cmd_w,seq,enable,left_cmd,right_cmd,slot,mcu_timestamp_us,feedback_seq,cmd_seq,mode,mode_name,fault_flags,faults,left_speed,right_speed,left_current,right_current,left_encoder,right_encoder,odom_x,odom_y,odom_theta,odom_v,odom_w,feedback_age_us,arm_state,clock_synced,clock_offset_us,diagnostics,truth_v,truth_w,truth_x,truth_y,truth_theta,truth_left_radps,truth_right_radps";

/// The CSV line of a row (no newline).
pub fn csv_line(r: &Row) -> String {
    let mut s = String::with_capacity(256);
    let e = &r.exchange;
    let _ = write!(
        s,
        "{},{},{},{},{},",
        r.index, e.t_send_us, e.t_recv_us, r.cmd_vel.0, r.cmd_vel.1
    );
    match &r.command {
        Some(c) => {
            let _ = write!(
                s,
                "{},{},{},{},",
                c.seq,
                u8::from(c.enable),
                c.left_speed_cmd,
                c.right_speed_cmd
            );
        }
        None => s.push_str(",,,,"),
    }
    match (&r.feedback, &r.other) {
        (Some(f), _) => {
            let _ = write!(
                s,
                "feedback,{},{},{},{},{},{},{},{},{},{},{},{},{},",
                f.timestamp_us,
                f.seq,
                f.cmd_seq,
                f.mode,
                mode_name(f.mode),
                f.fault_flags,
                fault_names(f.fault_flags),
                f.left_speed,
                f.right_speed,
                f.left_current,
                f.right_current,
                f.left_encoder,
                f.right_encoder
            );
        }
        (None, other) => {
            s.push_str(other.as_deref().unwrap_or("none"));
            // The slot, then the 13 feedback columns empty.
            s.push_str(&",".repeat(14));
        }
    }
    let _ = write!(
        s,
        "{},{},{},{},{},",
        r.pose[0], r.pose[1], r.pose[2], r.twist[0], r.twist[1]
    );
    let opt = |v: Option<String>| v.unwrap_or_default();
    let _ = write!(
        s,
        "{},{:?},{},{},{},",
        opt(r.feedback_age_us.map(|a| a.to_string())),
        r.arm_state,
        u8::from(r.clock_synced),
        opt(r.clock_offset_us.map(|o| format!("{o:.1}"))),
        r.diagnostics.join("|")
    );
    match &r.truth {
        Some(t) => {
            let _ = write!(
                s,
                "{},{},{},{},{},{},{}",
                t.v_mps, t.w_radps, t.x_m, t.y_m, t.theta_rad, t.wheel_radps[0], t.wheel_radps[1]
            );
        }
        None => s.push_str(",,,,,,"),
    }
    s
}

/// The topics of an MCAP recording.
pub mod topics {
    /// The cmd_vel the bridge was given.
    pub const CMD_VEL: &str = "/cmd_vel";
    /// Odometry.
    pub const ODOM: &str = "/odom";
    /// Wheel joints.
    pub const JOINT_STATES: &str = "/joint_states";
    /// Diagnostics.
    pub const DIAGNOSTICS: &str = "/diagnostics";
    /// Raw frames (JSON, no schema).
    pub const FRAMES: &str = "/motorlink/frames";
}

struct McapSink {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    cmd_vel: u16,
    odom: u16,
    joints: u16,
    diagnostics: u16,
    frames: u16,
    sequence: u32,
}

impl McapSink {
    fn create(path: &Path) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|e| RecordError::Io(path.to_path_buf(), e))?;
        let err = |e: mcap::McapError| RecordError::Mcap(path.to_path_buf(), e.to_string());
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library(concat!("motorlink ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(err)?;
        let no_metadata = BTreeMap::new();
        let channel = |w: &mut mcap::Writer<BufWriter<File>>,
                       topic: &str,
                       name: &str,
                       schema: String|
         -> Result<u16, RecordError> {
            let id = w
                .add_schema(name, "ros2msg", schema.as_bytes())
                .map_err(err)?;
            w.add_channel(id, topic, "cdr", &no_metadata).map_err(err)
        };
        let cmd_vel = channel(&mut writer, topics::CMD_VEL, Twist::NAME, Twist::schema())?;
        let odom = channel(
            &mut writer,
            topics::ODOM,
            Odometry::NAME,
            Odometry::schema(),
        )?;
        let joints = channel(
            &mut writer,
            topics::JOINT_STATES,
            JointState::NAME,
            JointState::schema(),
        )?;
        let diagnostics = channel(
            &mut writer,
            topics::DIAGNOSTICS,
            DiagnosticArray::NAME,
            DiagnosticArray::schema(),
        )?;
        // Schema id 0: no schema (rosbags reads such channels as schemaless and skips them).
        let frames = writer
            .add_channel(0, topics::FRAMES, "json", &no_metadata)
            .map_err(err)?;
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            cmd_vel,
            odom,
            joints,
            diagnostics,
            frames,
            sequence: 0,
        })
    }

    fn put(&mut self, channel_id: u16, time_ns: u64, data: &[u8]) -> Result<(), RecordError> {
        self.sequence = self.sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: self.sequence,
                    log_time: time_ns,
                    publish_time: time_ns,
                },
                data,
            )
            .map_err(|e| RecordError::Mcap(self.path.clone(), e.to_string()))
    }

    fn finish(&mut self) -> Result<(), RecordError> {
        self.writer
            .finish()
            .map(|_| ())
            .map_err(|e| RecordError::Mcap(self.path.clone(), e.to_string()))
    }
}

enum Sink {
    Mcap(Box<McapSink>),
    Csv(PathBuf, BufWriter<File>),
}

/// What a recording wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecordSummary {
    /// Exchanges recorded.
    pub exchanges: u64,
    /// Of those, with a valid feedback frame.
    pub feedback: u64,
    /// `/diagnostics` messages (MCAP).
    pub diagnostics: u64,
}

/// Writes exchanges to a file as they happen.
pub struct Recorder {
    cfg: RecordConfig,
    sink: Sink,
    odometer: Odometer,
    last_feedback_us: Option<u64>,
    summary: RecordSummary,
    pending_diags: Vec<&'static str>,
}

impl Recorder {
    /// Creates `path` (`.mcap` or `.csv`). Missing parent directories are created.
    pub fn create(path: &Path, cfg: RecordConfig) -> Result<Self, RecordError> {
        let format = Format::from_path(path)?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| RecordError::Io(dir.to_path_buf(), e))?;
        }
        let sink = match format {
            Format::Mcap => Sink::Mcap(Box::new(McapSink::create(path)?)),
            Format::Csv => {
                let f = File::create(path).map_err(|e| RecordError::Io(path.to_path_buf(), e))?;
                let mut w = BufWriter::new(f);
                writeln!(w, "{CSV_HEADER}").map_err(|e| RecordError::Io(path.to_path_buf(), e))?;
                Sink::Csv(path.to_path_buf(), w)
            }
        };
        Ok(Self {
            odometer: Odometer::new(&cfg.kinematics, cfg.counts_per_rev),
            cfg,
            sink,
            last_feedback_us: None,
            summary: RecordSummary::default(),
            pending_diags: Vec::new(),
        })
    }

    /// What was written so far.
    pub fn summary(&self) -> RecordSummary {
        self.summary
    }

    /// The row of the link's last exchange (`None` if it has none), and the odometry moved on.
    pub fn row<T: Transport>(
        &mut self,
        link: &Link<T>,
        cmd_vel: (f64, f64),
        diags: &[(u64, Diagnostic)],
        truth: Option<Truth>,
    ) -> Option<Row> {
        let e = link.last_exchange?;
        let command = amr::decode_command(&e.tx).ok();
        let (feedback, other) = match amr::decode_mcu_frame(&e.rx) {
            Ok(McuFrame::Feedback(f)) => (Some(f), None),
            Ok(McuFrame::Info(_)) => (None, Some("info".to_string())),
            Err(r) => (None, Some(format!("{r:?}"))),
        };
        let mut twist = [0.0; 2];
        if let Some(f) = &feedback {
            self.odometer.update([f.left_encoder, f.right_encoder]);
            self.last_feedback_us = Some(e.t_recv_us);
            let (v, w) = self
                .cfg
                .kinematics
                .forward(f64::from(f.left_speed), f64::from(f.right_speed));
            twist = [v, w];
        }
        let bridge: &Bridge = &link.bridge;
        Some(Row {
            index: self.summary.exchanges,
            exchange: e,
            cmd_vel,
            command,
            feedback,
            other,
            pose: [self.odometer.x, self.odometer.y, self.odometer.theta],
            twist,
            feedback_age_us: self.last_feedback_us.map(|t| e.t_recv_us.saturating_sub(t)),
            arm_state: bridge.state(),
            stats: bridge.stats,
            transport_errors: link.transport_errors,
            clock_synced: bridge.clock.is_synced(e.t_recv_us),
            clock_offset_us: bridge.clock.offset_at(e.t_recv_us as f64),
            diagnostics: diags.iter().map(|(_, d)| d.name()).collect(),
            truth,
        })
    }

    /// Records the link's last exchange: `cmd_vel` is what the bridge was given, `diags` what the
    /// exchange raised, `truth` the simulator's ground truth (if any).
    pub fn record<T: Transport>(
        &mut self,
        link: &Link<T>,
        cmd_vel: (f64, f64),
        diags: &[(u64, Diagnostic)],
        truth: Option<Truth>,
    ) -> Result<(), RecordError> {
        let Some(row) = self.row(link, cmd_vel, diags, truth) else {
            return Ok(());
        };
        self.summary.exchanges = self.summary.exchanges.saturating_add(1);
        if row.feedback.is_some() {
            self.summary.feedback = self.summary.feedback.saturating_add(1);
        }
        self.pending_diags.extend(row.diagnostics.iter().copied());
        let due = self.cfg.diagnostics_every != 0
            && self
                .summary
                .exchanges
                .checked_rem(self.cfg.diagnostics_every)
                == Some(0);
        match &mut self.sink {
            Sink::Csv(path, w) => {
                writeln!(w, "{}", csv_line(&row)).map_err(|e| RecordError::Io(path.clone(), e))?
            }
            Sink::Mcap(m) => {
                let t_ns = self
                    .cfg
                    .time_origin_ns
                    .saturating_add(row.exchange.t_recv_us.saturating_mul(1000));
                let stamp = Time::from_ns(t_ns);
                let twist = Twist {
                    linear: [row.cmd_vel.0, 0.0, 0.0],
                    angular: [0.0, 0.0, row.cmd_vel.1],
                };
                m.put(m.cmd_vel, t_ns, &twist.to_cdr())?;
                if let Some(f) = &row.feedback {
                    m.put(m.odom, t_ns, &odometry(&row, stamp).to_cdr())?;
                    let joints = JointState {
                        header: Header {
                            stamp,
                            frame_id: "base_link".into(),
                        },
                        name: vec!["left_wheel_joint".into(), "right_wheel_joint".into()],
                        position: vec![
                            self.odometer.angle(f.left_encoder),
                            self.odometer.angle(f.right_encoder),
                        ],
                        velocity: vec![f64::from(f.left_speed), f64::from(f.right_speed)],
                        effort: vec![f64::from(f.left_current), f64::from(f.right_current)],
                    };
                    m.put(m.joints, t_ns, &joints.to_cdr())?;
                }
                m.put(m.frames, t_ns, frames_json(&row).as_bytes())?;
                if due {
                    let d = diagnostics(&row, &self.pending_diags, stamp);
                    m.put(m.diagnostics, t_ns, &d.to_cdr())?;
                    self.summary.diagnostics = self.summary.diagnostics.saturating_add(1);
                }
            }
        }
        if due {
            self.pending_diags.clear();
        }
        Ok(())
    }

    /// Completes the file (MCAP: the summary section and footer).
    pub fn finish(mut self) -> Result<RecordSummary, RecordError> {
        match &mut self.sink {
            Sink::Csv(path, w) => w.flush().map_err(|e| RecordError::Io(path.clone(), e))?,
            Sink::Mcap(m) => m.finish()?,
        }
        Ok(self.summary)
    }
}

fn odometry(row: &Row, stamp: Time) -> Odometry {
    let [x, y, theta] = row.pose;
    Odometry {
        header: Header {
            stamp,
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        position: [x, y, 0.0],
        orientation: [0.0, 0.0, (theta / 2.0).sin(), (theta / 2.0).cos()],
        pose_covariance: [0.0; 36],
        twist: Twist {
            linear: [row.twist[0], 0.0, 0.0],
            angular: [0.0, 0.0, row.twist[1]],
        },
        twist_covariance: [0.0; 36],
    }
}

fn hex(b: &[u8; FRAME_LEN]) -> String {
    let mut s = String::with_capacity(FRAME_LEN.saturating_mul(2));
    for x in b {
        let _ = write!(s, "{x:02x}");
    }
    s
}

fn frames_json(row: &Row) -> String {
    let e = &row.exchange;
    serde_json::json!({
        "index": row.index,
        "t_send_us": e.t_send_us,
        "t_recv_us": e.t_recv_us,
        "tx": hex(&e.tx),
        "rx": hex(&e.rx),
    })
    .to_string()
}

fn kv(key: &str, value: impl ToString) -> KeyValue {
    KeyValue {
        key: key.into(),
        value: value.to_string(),
    }
}

fn diagnostics(row: &Row, raised: &[&'static str], stamp: Time) -> DiagnosticArray {
    let hw = "amr_spi".to_string();
    let mcu = match &row.feedback {
        Some(f) => DiagnosticStatus {
            level: match f.mode {
                m if m == Mode::Normal as u32 => msgs::LEVEL_OK,
                m if m == Mode::Brake as u32 => msgs::LEVEL_ERROR,
                _ => msgs::LEVEL_WARN,
            },
            name: "motorlink: mcu".into(),
            message: mode_name(f.mode).into(),
            hardware_id: hw.clone(),
            values: vec![
                kv("mode", mode_name(f.mode)),
                kv("fault_flags", f.fault_flags),
                kv("faults", fault_names(f.fault_flags)),
                kv("feedback_age_us", row.feedback_age_us.unwrap_or(0)),
                kv("mcu_timestamp_us", f.timestamp_us),
                kv("feedback_seq", f.seq),
                kv("cmd_seq", f.cmd_seq),
                // Commands sent since the last one the MCU accepted, this one included: 1 while
                // every command is accepted (the feedback answers the previous exchange), growing
                // by one per exchange while the MCU refuses or misses them.
                kv(
                    "commands_since_accepted",
                    row.command.map_or(0, |c| c.seq.wrapping_sub(f.cmd_seq)),
                ),
            ],
        },
        None => DiagnosticStatus {
            level: msgs::LEVEL_STALE,
            name: "motorlink: mcu".into(),
            message: format!(
                "no feedback in this exchange ({})",
                row.other.as_deref().unwrap_or("none")
            ),
            hardware_id: hw.clone(),
            values: vec![kv(
                "feedback_age_us",
                row.feedback_age_us
                    .map_or("never".to_string(), |a| a.to_string()),
            )],
        },
    };
    let link = DiagnosticStatus {
        level: if raised.is_empty() {
            msgs::LEVEL_OK
        } else {
            msgs::LEVEL_WARN
        },
        name: "motorlink: link".into(),
        message: format!("{:?}", row.arm_state),
        hardware_id: hw.clone(),
        values: vec![
            kv("exchanges", row.index.saturating_add(1)),
            kv("arm_state", format!("{:?}", row.arm_state)),
            kv("commands", row.stats.commands),
            kv("feedback_ok", row.stats.feedback_ok),
            kv("feedback_rejected", row.stats.feedback_rejected),
            kv("not_accepted", row.stats.not_accepted),
            kv("info_frames", row.stats.info_frames),
            kv("transport_errors", row.transport_errors),
            kv("diagnostics", raised.join("|")),
        ],
    };
    let clock = DiagnosticStatus {
        level: if row.clock_synced {
            msgs::LEVEL_OK
        } else {
            msgs::LEVEL_WARN
        },
        name: "motorlink: clock".into(),
        message: if row.clock_synced {
            "synced".into()
        } else {
            "not synced".into()
        },
        hardware_id: hw,
        values: vec![kv(
            "offset_us",
            row.clock_offset_us
                .map_or(String::new(), |o| format!("{o:.1}")),
        )],
    };
    DiagnosticArray {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        status: vec![mcu, link, clock],
    }
}

/// What `motorlink record` runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordPlan {
    /// Exchanges to record (1 ms each).
    pub exchanges: u64,
    /// cmd_vel forward speed, m/s.
    pub v: f64,
    /// cmd_vel yaw rate, rad/s.
    pub w: f64,
}

impl RecordPlan {
    /// `seconds` of exchanges at 1 kHz with cmd_vel (v, ω); refuses a negative, non-finite or
    /// over-long (a day) duration and non-finite speeds.
    pub fn new(seconds: f64, v: f64, w: f64) -> Result<Self, RecordError> {
        if !(seconds.is_finite() && (0.0..=86_400.0).contains(&seconds)) {
            return Err(RecordError::Plan(format!(
                "--seconds {seconds}: give a duration from 0 to 86400 s"
            )));
        }
        if !(v.is_finite() && w.is_finite()) {
            return Err(RecordError::Plan(format!(
                "--v {v} --w {w}: speeds must be finite numbers"
            )));
        }
        Ok(Self {
            exchanges: (seconds * 1000.0).round() as u64,
            v,
            w,
        })
    }

    /// Whether the bridge is armed: only when the plan moves the robot (a recording with v = ω = 0
    /// leaves the drive disabled and records what the MCU reports).
    pub fn arms(&self) -> bool {
        self.v != 0.0 || self.w != 0.0
    }
}

/// Disarmed exchanges after a recording on a device (not recorded): enable 0 puts the board in STOP
/// with its bounded deceleration before the silence brakes it.
pub const WIND_DOWN_EXCHANGES: u32 = 50;

/// Records `plan` against the simulated board in lockstep (deterministic): the bridge armed at
/// the start if the plan moves, cmd_vel fresh in every exchange. `stop` returning true ends the
/// recording early (the file is completed).
pub fn record_sim(
    out: &Path,
    plan: &RecordPlan,
    cfg: RecordConfig,
    stop: &mut dyn FnMut() -> bool,
) -> Result<RecordSummary, RecordError> {
    let mut rec = Recorder::create(out, cfg)?;
    let mut link = Link::new(SimMcu::lockstep(), Bridge::new(Default::default()));
    if plan.arms() {
        link.bridge.arm(link.transport.now_us());
    }
    for _ in 0..plan.exchanges {
        if stop() {
            break;
        }
        link.bridge.cmd_vel(link.transport.now_us(), plan.v, plan.w);
        let d = link.sim_cycle().map_err(RecordError::Link)?;
        let truth = link.transport.truth();
        rec.record(&link, (plan.v, plan.w), &d, Some(truth))?;
    }
    rec.finish()
}

/// Records `plan` on a device at the link's 1 kHz pacing, then winds down
/// ([`WIND_DOWN_EXCHANGES`] disarmed exchanges). A failed exchange ends the recording (the file is
/// completed first) with the error; `stop` returning true (Ctrl-C) ends it early, wound down and
/// completed.
pub fn record_link<T: Transport>(
    link: &mut Link<T>,
    out: &Path,
    plan: &RecordPlan,
    cfg: RecordConfig,
    stop: &mut dyn FnMut() -> bool,
) -> Result<RecordSummary, RecordError> {
    let mut rec = Recorder::create(out, cfg)?;
    if plan.arms() {
        link.bridge.arm(link.now_us());
    }
    let mut failed = None;
    for _ in 0..plan.exchanges {
        if stop() {
            break;
        }
        link.bridge.cmd_vel(link.now_us(), plan.v, plan.w);
        match link.cycle() {
            Ok(d) => rec.record(link, (plan.v, plan.w), &d, None)?,
            Err(e) => {
                failed = Some(e);
                break;
            }
        }
    }
    link.bridge.disarm();
    for _ in 0..WIND_DOWN_EXCHANGES {
        if failed.is_some() || link.cycle().is_err() {
            break;
        }
    }
    let summary = rec.finish()?;
    match failed {
        Some(e) => Err(RecordError::Link(e)),
        None => Ok(summary),
    }
}

#[cfg(test)]
mod tests;
