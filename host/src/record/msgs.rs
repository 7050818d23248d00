//! The ROS 2 messages `motorlink record` writes: their CDR serialisation and their `ros2msg`
//! schemas (the type's `.msg` text, then each type it depends on after a line of 80 `=` and a
//! `MSG: package/Type` line, as rosbag2's MCAP storage writes them).

use super::cdr::CdrWriter;

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch (seconds saturate at `i32::MAX`).
    pub fn from_ns(ns: u64) -> Self {
        let sec = ns.checked_div(1_000_000_000).unwrap_or(0);
        let nanosec = ns.checked_rem(1_000_000_000).unwrap_or(0);
        Self {
            sec: i32::try_from(sec).unwrap_or(i32::MAX),
            nanosec: u32::try_from(nanosec).unwrap_or(0),
        }
    }

    fn write(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Header {
    /// Time stamp.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

impl Header {
    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
}

/// `geometry_msgs/msg/Twist` (linear and angular as `Vector3` x, y, z).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: [f64; 3],
    /// Angular velocity, rad/s.
    pub angular: [f64; 3],
}

impl Twist {
    fn write(&self, w: &mut CdrWriter) {
        w.f64_array(&self.linear);
        w.f64_array(&self.angular);
    }
}

/// `nav_msgs/msg/Odometry`.
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    /// Stamp and the frame of the pose (`odom`).
    pub header: Header,
    /// The frame of the twist (`base_link`).
    pub child_frame_id: String,
    /// Position x, y, z, m.
    pub position: [f64; 3],
    /// Orientation quaternion x, y, z, w.
    pub orientation: [f64; 4],
    /// Pose covariance, row-major 6×6 (x, y, z, rot x, rot y, rot z).
    pub pose_covariance: [f64; 36],
    /// Velocity in the child frame.
    pub twist: Twist,
    /// Twist covariance, row-major 6×6.
    pub twist_covariance: [f64; 36],
}

/// `sensor_msgs/msg/JointState`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointState {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad.
    pub position: Vec<f64>,
    /// Velocities, rad/s.
    pub velocity: Vec<f64>,
    /// Efforts.
    pub effort: Vec<f64>,
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus` level `OK`.
pub const LEVEL_OK: u8 = 0;
/// Level `WARN`.
pub const LEVEL_WARN: u8 = 1;
/// Level `ERROR`.
pub const LEVEL_ERROR: u8 = 2;
/// Level `STALE`.
pub const LEVEL_STALE: u8 = 3;

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DiagnosticStatus {
    /// [`LEVEL_OK`] … [`LEVEL_STALE`].
    pub level: u8,
    /// What is reported on.
    pub name: String,
    /// Summary.
    pub message: String,
    /// The device.
    pub hardware_id: String,
    /// Details.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// One status per thing reported on.
    pub status: Vec<DiagnosticStatus>,
}

/// A message type the recorder writes.
pub trait RosMessage {
    /// The ROS 2 type name, `package/msg/Type`.
    const NAME: &'static str;
    /// Writes the fields (after the encapsulation header).
    fn write(&self, w: &mut CdrWriter);

    /// The message as little-endian CDR with its encapsulation header.
    fn to_cdr(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        self.write(&mut w);
        w.finish()
    }

    /// The `ros2msg` schema text of the type.
    fn schema() -> String {
        schema(Self::NAME)
    }
}

impl RosMessage for Twist {
    const NAME: &'static str = "geometry_msgs/msg/Twist";
    fn write(&self, w: &mut CdrWriter) {
        Twist::write(self, w);
    }
}

impl RosMessage for Odometry {
    const NAME: &'static str = "nav_msgs/msg/Odometry";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        w.f64_array(&self.position);
        w.f64_array(&self.orientation);
        w.f64_array(&self.pose_covariance);
        self.twist.write(w);
        w.f64_array(&self.twist_covariance);
    }
}

impl RosMessage for JointState {
    const NAME: &'static str = "sensor_msgs/msg/JointState";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string_seq(&self.name);
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
    }
}

impl RosMessage for DiagnosticArray {
    const NAME: &'static str = "diagnostic_msgs/msg/DiagnosticArray";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.len(self.status.len());
        for s in &self.status {
            w.u8(s.level);
            w.string(&s.name);
            w.string(&s.message);
            w.string(&s.hardware_id);
            w.len(s.values.len());
            for kv in &s.values {
                w.string(&kv.key);
                w.string(&kv.value);
            }
        }
    }
}

/// Each type's own `.msg` text (fields, constants, defaults; comments left out) and the types it
/// refers to, `package/msg/Type`.
const DEFINITIONS: &[(&str, &str, &[&str])] = &[
    (
        "builtin_interfaces/msg/Time",
        "int32 sec\nuint32 nanosec\n",
        &[],
    ),
    (
        "std_msgs/msg/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
        &["builtin_interfaces/msg/Time"],
    ),
    (
        "geometry_msgs/msg/Vector3",
        "float64 x\nfloat64 y\nfloat64 z\n",
        &[],
    ),
    (
        "geometry_msgs/msg/Point",
        "float64 x\nfloat64 y\nfloat64 z\n",
        &[],
    ),
    (
        "geometry_msgs/msg/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
        &[],
    ),
    (
        "geometry_msgs/msg/Pose",
        "Point position\nQuaternion orientation\n",
        &["geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"],
    ),
    (
        "geometry_msgs/msg/PoseWithCovariance",
        "Pose pose\nfloat64[36] covariance\n",
        &["geometry_msgs/msg/Pose"],
    ),
    (
        "geometry_msgs/msg/Twist",
        "Vector3 linear\nVector3 angular\n",
        &["geometry_msgs/msg/Vector3"],
    ),
    (
        "geometry_msgs/msg/TwistWithCovariance",
        "Twist twist\nfloat64[36] covariance\n",
        &["geometry_msgs/msg/Twist"],
    ),
    (
        "nav_msgs/msg/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
        &[
            "std_msgs/msg/Header",
            "geometry_msgs/msg/PoseWithCovariance",
            "geometry_msgs/msg/TwistWithCovariance",
        ],
    ),
    (
        "sensor_msgs/msg/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
        &["std_msgs/msg/Header"],
    ),
    (
        "diagnostic_msgs/msg/KeyValue",
        "string key\nstring value\n",
        &[],
    ),
    (
        "diagnostic_msgs/msg/DiagnosticStatus",
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n",
        &["diagnostic_msgs/msg/KeyValue"],
    ),
    (
        "diagnostic_msgs/msg/DiagnosticArray",
        "std_msgs/Header header\nDiagnosticStatus[] status\n",
        &["std_msgs/msg/Header", "diagnostic_msgs/msg/DiagnosticStatus"],
    ),
];

/// The line between the definitions of a schema.
const SEPARATOR: &str =
    "================================================================================";

fn definition(
    name: &str,
) -> Option<&'static (&'static str, &'static str, &'static [&'static str])> {
    DEFINITIONS.iter().find(|(n, _, _)| *n == name)
}

/// The `ros2msg` schema of `name` (`package/msg/Type`): its definition, then every type it depends
/// on, each once, in the order first referred to (depth first). Empty for a type not listed.
pub fn schema(name: &str) -> String {
    let mut order: Vec<&str> = Vec::new();
    let mut stack: Vec<&str> = vec![name];
    // Depth first, each type once: the dependencies of a type right after it.
    while let Some(n) = stack.pop() {
        if order.contains(&n) {
            continue;
        }
        if let Some((_, _, deps)) = definition(n) {
            order.push(n);
            stack.extend(deps.iter().rev());
        }
    }
    let mut out = String::new();
    for (k, n) in order.iter().enumerate() {
        let Some((_, text, _)) = definition(n) else {
            continue;
        };
        if k > 0 {
            // `package/msg/Type` is written `package/Type` on the MSG line.
            let short = n.replacen("/msg/", "/", 1);
            out.push_str(SEPARATOR);
            out.push_str("\nMSG: ");
            out.push_str(&short);
            out.push('\n');
        }
        out.push_str(text);
    }
    out
}

#[cfg(test)]
mod tests;
