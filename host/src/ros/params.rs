//! The node's parameters, read from a file in the ROS 2 parameter-file format
//! (`ros2 run ... --ros-args --params-file FILE`):
//!
//! ```yaml
//! motorlink:              # the node's name (or /** for any node)
//!   ros__parameters:
//!     device: /dev/spidev0.0
//!     geometry: { wheelbase_m: 0.40, wheel_radius_m: 0.08 }
//! ```
//!
//! Every key is optional (the defaults are [`Params::default`]); an unknown key anywhere is
//! refused, and a value out of range is reported with its dotted name (`rates.odom_hz`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::kinematics::{DiffDrive, DiffDriveConfig};

/// The node name a parameter file addresses when it names none of its own.
pub const DEFAULT_NODE_NAME: &str = "motorlink";

/// The byte link to the MCU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinkKind {
    /// Seed 000's Jetson ↔ STM32 SPI frames over Linux spidev (the only link this node drives).
    #[default]
    Spi,
}

/// Wheel geometry and encoder resolution.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Geometry {
    /// Distance between the wheel contact points, m.
    pub wheelbase_m: f64,
    /// Wheel radius, m.
    pub wheel_radius_m: f64,
    /// Largest wheel speed the bridge asks for, rad/s.
    pub max_wheel_speed: f64,
    /// Encoder counts per wheel revolution (odometry and joint positions).
    pub encoder_counts_per_rev: u32,
}

impl Default for Geometry {
    /// The simulated robot (`DiffDrive::DEFAULT`, 4096 counts per revolution).
    fn default() -> Self {
        let k = DiffDrive::DEFAULT.config();
        Self {
            wheelbase_m: 0.40,
            wheel_radius_m: 0.08,
            max_wheel_speed: k.max_wheel_speed,
            encoder_counts_per_rev: 4096,
        }
    }
}

/// Frame and joint names.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Frames {
    /// The odometry frame (`header.frame_id` of `odom`, parent of the TF).
    pub odom: String,
    /// The robot's base frame (`child_frame_id`).
    pub base: String,
    /// The left wheel's joint in `joint_states`.
    pub left_wheel_joint: String,
    /// The right wheel's joint.
    pub right_wheel_joint: String,
}

impl Default for Frames {
    fn default() -> Self {
        Self {
            odom: "odom".into(),
            base: "base_link".into(),
            left_wheel_joint: "left_wheel_joint".into(),
            right_wheel_joint: "right_wheel_joint".into(),
        }
    }
}

/// Topic names (relative names resolve in the node's namespace, `/` by default).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Topics {
    /// Velocity commands in.
    pub cmd_vel: String,
    /// `cmd_vel` carries `geometry_msgs/TwistStamped` instead of `Twist`.
    pub cmd_vel_stamped: bool,
    /// Odometry out.
    pub odom: String,
    /// Transforms out.
    pub tf: String,
    /// Wheel joint states out.
    pub joint_states: String,
    /// Diagnostics out.
    pub diagnostics: String,
}

impl Default for Topics {
    fn default() -> Self {
        Self {
            cmd_vel: "cmd_vel".into(),
            cmd_vel_stamped: false,
            odom: "odom".into(),
            tf: "/tf".into(),
            joint_states: "joint_states".into(),
            diagnostics: "/diagnostics".into(),
        }
    }
}

/// How request and reply samples carry their identity (the RMW of the callers).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ServiceMapping {
    /// rmw_fastrtps (the ROS 2 default) and rmw_connextdds: the identity in the inline QoS.
    #[default]
    Enhanced,
    /// rmw_cyclonedds: the identity in front of the data.
    Cyclone,
    /// The basic mapping of the DDS-RPC specification.
    Basic,
}

/// Service names.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Services {
    /// `std_srvs/SetBool`: true arms (or re-arms), false disarms.
    pub arm: String,
    /// `std_srvs/Trigger`: disarm.
    pub disarm: String,
    /// `std_srvs/Trigger`: re-arm after BRAKE.
    pub rearm: String,
    /// `std_srvs/SetBool`: true stops every exchange (the MCU brakes on comm loss), false resumes.
    pub estop: String,
    /// The callers' service mapping.
    pub mapping: ServiceMapping,
}

impl Default for Services {
    fn default() -> Self {
        Self {
            arm: "~/arm".into(),
            disarm: "~/disarm".into(),
            rearm: "~/rearm".into(),
            estop: "~/estop".into(),
            mapping: ServiceMapping::Enhanced,
        }
    }
}

/// DDS reliability.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// Lost samples are resent.
    Reliable,
    /// Lost samples are lost.
    BestEffort,
}

/// DDS durability.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Durability {
    /// Only samples published while a reader is there.
    Volatile,
    /// Late readers get the last `depth` samples.
    TransientLocal,
}

/// The QoS of one topic.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicQos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    #[serde(default = "volatile")]
    pub durability: Durability,
    /// Keep-last history depth, 1 ..= 1000.
    pub depth: u32,
}

fn volatile() -> Durability {
    Durability::Volatile
}

impl TopicQos {
    /// Reliable, volatile, keep last `depth`.
    pub const fn reliable(depth: u32) -> Self {
        Self {
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            depth,
        }
    }
}

/// QoS per topic (ROS 2's defaults: reliable, volatile, keep last 10; `/tf` keeps 100).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Qos {
    /// `cmd_vel` subscription.
    pub cmd_vel: TopicQos,
    /// `odom`.
    pub odom: TopicQos,
    /// `/tf`.
    pub tf: TopicQos,
    /// `joint_states`.
    pub joint_states: TopicQos,
    /// `/diagnostics`.
    pub diagnostics: TopicQos,
}

impl Default for Qos {
    fn default() -> Self {
        Self {
            cmd_vel: TopicQos::reliable(10),
            odom: TopicQos::reliable(10),
            tf: TopicQos::reliable(100),
            joint_states: TopicQos::reliable(10),
            diagnostics: TopicQos::reliable(10),
        }
    }
}

/// Publication rates, Hz.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Rates {
    /// `odom` and the TF, 0 < hz <= 1000.
    pub odom_hz: f64,
    /// `joint_states`, 0 < hz <= 1000.
    pub joint_states_hz: f64,
    /// `/diagnostics`, 0 < hz <= 1000 (also on every change of mode or arming state).
    pub diagnostics_hz: f64,
}

impl Default for Rates {
    fn default() -> Self {
        Self {
            odom_hz: 50.0,
            joint_states_hz: 50.0,
            diagnostics_hz: 1.0,
        }
    }
}

/// Everything the node is configured with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// spidev device of the MCU (unused with `--sim`).
    pub device: String,
    /// Link kind.
    pub link_kind: LinkKind,
    /// SPI clock, Hz.
    pub spi_hz: u32,
    /// DDS domain (ROS_DOMAIN_ID), 0 ..= 232.
    pub domain_id: u16,
    /// Geometry.
    pub geometry: Geometry,
    /// Frames.
    pub frames: Frames,
    /// Topics.
    pub topics: Topics,
    /// Services.
    pub services: Services,
    /// QoS.
    pub qos: Qos,
    /// Rates.
    pub rates: Rates,
    /// Publish the `odom` → base TF.
    pub publish_tf: bool,
    /// Start the arming sequence at start-up (as the `arm` service would).
    pub arm_on_start: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            device: "/dev/spidev0.0".into(),
            link_kind: LinkKind::Spi,
            spi_hz: 2_000_000,
            domain_id: 0,
            geometry: Geometry::default(),
            frames: Frames::default(),
            topics: Topics::default(),
            services: Services::default(),
            qos: Qos::default(),
            rates: Rates::default(),
            publish_tf: true,
            arm_on_start: false,
        }
    }
}

/// Why a parameter file was refused.
#[derive(Debug, PartialEq, Eq)]
pub enum ParamError {
    /// The file could not be read (path, reason).
    Read(String, String),
    /// The YAML does not parse or does not fit the parameters (where, what).
    Syntax(String, String),
    /// The file's shape is not `node: ros__parameters: {...}`.
    Shape(String),
    /// A value is out of range (dotted name, reason).
    Value(String, String),
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Read(p, e) => write!(f, "cannot read parameter file {p}: {e}"),
            Self::Syntax(at, e) => write!(f, "parameter file: {at}: {e}"),
            Self::Shape(e) => write!(
                f,
                "parameter file: {e} (expected `<node name>: {{ros__parameters: {{...}}}}`, see host/ros/params.yaml)"
            ),
            Self::Value(name, e) => write!(f, "parameter {name}: {e}"),
        }
    }
}

impl std::error::Error for ParamError {}

/// A parameter file: the node's name and its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamFile {
    /// The node name the file addresses ([`DEFAULT_NODE_NAME`] for `/**`).
    pub node_name: String,
    /// The parameters.
    pub params: Params,
}

/// The inner mapping `ros__parameters: {...}`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Section {
    #[serde(rename = "ros__parameters")]
    ros_parameters: serde_yaml_ng::Value,
}

/// Reads and checks a parameter file.
pub fn load(path: &Path) -> Result<ParamFile, ParamError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| ParamError::Read(path.display().to_string(), e.to_string()))?;
    parse(&text)
}

/// Parses and checks the text of a parameter file.
pub fn parse(text: &str) -> Result<ParamFile, ParamError> {
    let top: serde_yaml_ng::Mapping = serde_yaml_ng::from_str(text)
        .map_err(|e| ParamError::Syntax(location(&e), e.to_string()))?;
    let mut entries = top.into_iter();
    let (key, section) = match (entries.next(), entries.next()) {
        (Some(one), None) => one,
        (None, _) => return Err(ParamError::Shape("the file is empty".into())),
        (Some(_), Some(_)) => {
            return Err(ParamError::Shape(
                "more than one node in the file; this node reads exactly one".into(),
            ))
        }
    };
    let key = key
        .as_str()
        .ok_or_else(|| ParamError::Shape("the top-level key is not a node name".into()))?;
    let node_name = match key {
        "/**" => DEFAULT_NODE_NAME.to_string(),
        k => {
            let base = k.trim_start_matches('/');
            ros2_client::NodeName::new("/", base)
                .map_err(|e| ParamError::Shape(format!("`{k}` is not a valid node name: {e}")))?;
            base.to_string()
        }
    };
    let section: Section = serde_path_to_error::deserialize(section)
        .map_err(|e| ParamError::Shape(format!("under `{key}`: {}", e.inner())))?;
    let params: Params = serde_path_to_error::deserialize(section.ros_parameters)
        .map_err(|e| ParamError::Syntax(e.path().to_string(), e.inner().to_string()))?;
    params.check()?;
    Ok(ParamFile { node_name, params })
}

fn location(e: &serde_yaml_ng::Error) -> String {
    e.location().map_or_else(
        || "(no position)".to_string(),
        |l| format!("line {} column {}", l.line(), l.column()),
    )
}

fn value(name: &str, why: impl Into<String>) -> ParamError {
    ParamError::Value(name.into(), why.into())
}

fn check_rate(name: &str, hz: f64) -> Result<(), ParamError> {
    if hz > 0.0 && hz <= 1000.0 {
        Ok(())
    } else {
        Err(value(name, format!("{hz} Hz is outside (0, 1000] Hz")))
    }
}

fn check_name(name: &str, topic: &str) -> Result<(), ParamError> {
    let t = topic.strip_prefix("~/").unwrap_or(topic);
    ros2_client::Name::parse(t)
        .map(|_| ())
        .map_err(|e| value(name, format!("`{topic}` is not a valid ROS 2 name: {e}")))
}

fn check_qos(name: &str, q: &TopicQos) -> Result<(), ParamError> {
    if (1..=1000).contains(&q.depth) {
        Ok(())
    } else {
        Err(value(
            &format!("{name}.depth"),
            format!("{} is outside 1 ..= 1000", q.depth),
        ))
    }
}

impl Params {
    /// The wheel geometry, checked.
    pub fn drive(&self) -> Result<DiffDrive, ParamError> {
        let g = &self.geometry;
        DiffDrive::new(DiffDriveConfig {
            wheelbase_m: g.wheelbase_m,
            wheel_radius_m: g.wheel_radius_m,
            max_wheel_speed: g.max_wheel_speed,
        })
        .map_err(|e| value("geometry", e.to_string()))
    }

    /// Checks every value a type alone does not bound.
    pub fn check(&self) -> Result<(), ParamError> {
        self.drive()?;
        if self.geometry.encoder_counts_per_rev == 0 {
            return Err(value(
                "geometry.encoder_counts_per_rev",
                "must be at least 1",
            ));
        }
        if self.spi_hz == 0 || self.spi_hz > 50_000_000 {
            return Err(value(
                "spi_hz",
                format!("{} Hz is outside 1 ..= 50 000 000 Hz", self.spi_hz),
            ));
        }
        if self.domain_id > 232 {
            return Err(value(
                "domain_id",
                format!("{} is outside 0 ..= 232", self.domain_id),
            ));
        }
        check_rate("rates.odom_hz", self.rates.odom_hz)?;
        check_rate("rates.joint_states_hz", self.rates.joint_states_hz)?;
        check_rate("rates.diagnostics_hz", self.rates.diagnostics_hz)?;
        let t = &self.topics;
        for (n, v) in [
            ("topics.cmd_vel", &t.cmd_vel),
            ("topics.odom", &t.odom),
            ("topics.tf", &t.tf),
            ("topics.joint_states", &t.joint_states),
            ("topics.diagnostics", &t.diagnostics),
            ("services.arm", &self.services.arm),
            ("services.disarm", &self.services.disarm),
            ("services.rearm", &self.services.rearm),
            ("services.estop", &self.services.estop),
        ] {
            check_name(n, v)?;
        }
        let f = &self.frames;
        for (n, v) in [
            ("frames.odom", &f.odom),
            ("frames.base", &f.base),
            ("frames.left_wheel_joint", &f.left_wheel_joint),
            ("frames.right_wheel_joint", &f.right_wheel_joint),
        ] {
            if v.is_empty() {
                return Err(value(n, "must not be empty"));
            }
        }
        let q = &self.qos;
        check_qos("qos.cmd_vel", &q.cmd_vel)?;
        check_qos("qos.odom", &q.odom)?;
        check_qos("qos.tf", &q.tf)?;
        check_qos("qos.joint_states", &q.joint_states)?;
        check_qos("qos.diagnostics", &q.diagnostics)?;
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::float_cmp)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_example_file_parses_to_its_values() {
        let text = include_str!("../../ros/params.yaml");
        let f = parse(text).unwrap();
        assert_eq!(f.node_name, "motorlink");
        let p = f.params;
        assert_eq!(p.device, "/dev/spidev0.0");
        assert_eq!(p.geometry.wheelbase_m, 0.40);
        assert_eq!(p.topics.cmd_vel, "cmd_vel");
        assert_eq!(p.qos.cmd_vel.reliability, Reliability::Reliable);
        assert_eq!(p.rates.odom_hz, 50.0);
    }

    #[test]
    fn a_partial_file_keeps_the_defaults_for_the_rest() {
        let f = parse(
            "base_driver:\n  ros__parameters:\n    device: /dev/spidev1.0\n    geometry:\n      wheel_radius_m: 0.1\n    topics:\n      cmd_vel_stamped: true\n",
        )
        .unwrap();
        assert_eq!(f.node_name, "base_driver");
        assert_eq!(f.params.device, "/dev/spidev1.0");
        assert_eq!(f.params.geometry.wheel_radius_m, 0.1);
        assert_eq!(f.params.geometry.wheelbase_m, 0.40);
        assert!(f.params.topics.cmd_vel_stamped);
        assert_eq!(f.params.topics.odom, "odom");
    }

    #[test]
    fn the_wildcard_node_name_means_the_default_one() {
        let f = parse("/**:\n  ros__parameters:\n    spi_hz: 1000000\n").unwrap();
        assert_eq!(f.node_name, DEFAULT_NODE_NAME);
        assert_eq!(f.params.spi_hz, 1_000_000);
    }

    #[test]
    fn an_unknown_key_is_refused_with_its_place() {
        let e = parse("motorlink:\n  ros__parameters:\n    geometry:\n      wheel_base: 0.4\n")
            .unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, ParamError::Syntax(..)), "{e:?}");
        assert!(
            msg.contains("geometry") && msg.contains("wheel_base"),
            "{msg}"
        );
        // Beside ros__parameters too.
        let e = parse("motorlink:\n  ros__parameters: {}\n  extra: 1\n").unwrap_err();
        assert!(e.to_string().contains("extra"), "{e}");
    }

    #[test]
    fn bad_values_are_reported_by_name() {
        let cases = [
            ("rates: {odom_hz: 0}", "rates.odom_hz"),
            ("rates: {diagnostics_hz: 5000}", "rates.diagnostics_hz"),
            ("geometry: {wheel_radius_m: -0.08}", "wheel radius"),
            (
                "geometry: {encoder_counts_per_rev: 0}",
                "encoder_counts_per_rev",
            ),
            (
                "qos: {odom: {reliability: reliable, depth: 0}}",
                "qos.odom.depth",
            ),
            ("topics: {odom: 'two//slashes'}", "topics.odom"),
            ("domain_id: 300", "domain_id"),
            ("frames: {base: ''}", "frames.base"),
        ];
        for (body, want) in cases {
            let text = format!("motorlink:\n  ros__parameters:\n    {body}\n");
            let e = parse(&text).unwrap_err();
            assert!(e.to_string().contains(want), "{body}: {e}");
        }
    }

    #[test]
    fn a_value_of_the_wrong_type_names_its_key() {
        let e = parse("motorlink:\n  ros__parameters:\n    spi_hz: fast\n").unwrap_err();
        assert!(e.to_string().contains("spi_hz"), "{e}");
        let e = parse("motorlink:\n  ros__parameters:\n    qos: {cmd_vel: {reliability: sometimes, depth: 1}}\n")
            .unwrap_err();
        assert!(e.to_string().contains("qos.cmd_vel.reliability"), "{e}");
    }

    #[test]
    fn the_shape_must_be_one_node_with_ros_parameters() {
        for text in [
            "",
            "a:\n  ros__parameters: {}\nb:\n  ros__parameters: {}\n",
            "motorlink:\n  parameters: {}\n",
            "motorlink: [1, 2]\n",
            "'bad name!':\n  ros__parameters: {}\n",
        ] {
            assert!(parse(text).is_err(), "{text:?}");
        }
    }

    #[test]
    fn a_missing_file_says_which() {
        let e = load(Path::new("/nonexistent/params.yaml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/params.yaml"), "{e}");
    }
}
