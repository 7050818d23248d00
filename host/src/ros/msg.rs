//! The ROS 2 messages and services the node speaks, as serde structs in the field order of their
//! ROS 2 IDL (`ros2 interface show ...`), so the CDR encoding RustDDS applies is the one every ROS 2
//! RMW expects. ros2-client adds the DDS type names (`geometry_msgs::msg::dds_::Twist_`) and the
//! topic prefixes (`rt/cmd_vel`); [`MessageType`] names each type for it.
//!
//! IDL fixed arrays (`float64[36]`) are encoded as CDR arrays (no length); sequences (`string[]`,
//! `float64[]`) carry a length. An empty request (`std_srvs/Trigger`) has the one `uint8` member
//! `structure_needs_at_least_one_member` that ROS 2's IDL generator adds to empty structures.

use serde::de::{Error as _, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A ROS 2 interface type: its package and name (`geometry_msgs`, `Twist`).
pub trait MessageType {
    /// Package, e.g. `geometry_msgs`.
    const PACKAGE: &'static str;
    /// Type name within the package, e.g. `Twist`.
    const NAME: &'static str;
}

macro_rules! message_type {
    ($t:ty, $pkg:literal, $name:literal) => {
        impl MessageType for $t {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
        }
        impl ros2_client::Message for $t {}
    };
}

/// `builtin_interfaces/Time`: seconds and nanoseconds since the Unix epoch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds, 0 ..= 999 999 999.
    pub nanosec: u32,
}

impl Time {
    /// The time `t`, truncated to the nanosecond; times outside the `i32` seconds range saturate.
    pub fn from_system(t: std::time::SystemTime) -> Self {
        match t.duration_since(std::time::UNIX_EPOCH) {
            Ok(d) => Self {
                sec: i32::try_from(d.as_secs()).unwrap_or(i32::MAX),
                nanosec: d.subsec_nanos(),
            },
            Err(_) => Self::default(),
        }
    }

    /// The system clock now (ROS time without simulated time).
    pub fn now() -> Self {
        Self::from_system(std::time::SystemTime::now())
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// When the data was measured.
    pub stamp: Time,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Twist`: linear (m/s) and angular (rad/s) velocity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: Vector3,
    /// Angular velocity, rad/s.
    pub angular: Vector3,
}
message_type!(Twist, "geometry_msgs", "Twist");

/// `geometry_msgs/TwistStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The velocity.
    pub twist: Twist,
}
message_type!(TwistStamped, "geometry_msgs", "TwistStamped");

/// `geometry_msgs/Point`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// z, m.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    /// The identity rotation (the IDL's default `w = 1`).
    fn default() -> Self {
        Self::from_yaw(0.0)
    }
}

impl Quaternion {
    /// A rotation by `yaw` rad about z.
    pub fn from_yaw(yaw: f64) -> Self {
        let h = yaw / 2.0;
        Self {
            x: 0.0,
            y: 0.0,
            z: h.sin(),
            w: h.cos(),
        }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position, m.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// A row-major 6×6 covariance (`float64[36]`), encoded as a fixed array.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Covariance(pub [f64; 36]);

impl Default for Covariance {
    fn default() -> Self {
        Self([0.0; 36])
    }
}

impl Covariance {
    /// A diagonal covariance with `d` on the diagonal (x, y, z, roll, pitch, yaw).
    pub fn diagonal(d: [f64; 6]) -> Self {
        let mut c = [0.0; 36];
        for (i, (row, v)) in c.chunks_exact_mut(6).zip(d).enumerate() {
            if let Some(x) = row.get_mut(i) {
                *x = v;
            }
        }
        Self(c)
    }
}

impl Serialize for Covariance {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for x in &self.0 {
            t.serialize_element(x)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Covariance;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<Covariance, A::Error> {
                let mut c = [0.0; 36];
                for (i, x) in c.iter_mut().enumerate() {
                    *x = a
                        .next_element()?
                        .ok_or_else(|| A::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance(c))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Its covariance.
    pub covariance: Covariance,
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The velocity.
    pub twist: Twist,
    /// Its covariance.
    pub covariance: Covariance,
}

/// `nav_msgs/Odometry`: pose in `header.frame_id`, velocity in `child_frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and the pose's frame (`odom`).
    pub header: Header,
    /// The velocity's frame (`base_link`).
    pub child_frame_id: String,
    /// Pose.
    pub pose: PoseWithCovariance,
    /// Velocity.
    pub twist: TwistWithCovariance,
}
message_type!(Odometry, "nav_msgs", "Odometry");

/// `geometry_msgs/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation, m.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// Child frame.
    pub child_frame_id: String,
    /// Child in parent.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage` (the `/tf` topic).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}
message_type!(TfMessage, "tf2_msgs", "TFMessage");

/// `sensor_msgs/JointState`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad.
    pub position: Vec<f64>,
    /// Velocities, rad/s.
    pub velocity: Vec<f64>,
    /// Efforts, N·m (empty: not measured).
    pub effort: Vec<f64>,
}
message_type!(JointState, "sensor_msgs", "JointState");

/// `diagnostic_msgs/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus` levels.
pub mod level {
    /// OK.
    pub const OK: u8 = 0;
    /// WARN.
    pub const WARN: u8 = 1;
    /// ERROR.
    pub const ERROR: u8 = 2;
    /// STALE.
    pub const STALE: u8 = 3;
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// One of [`level`].
    pub level: u8,
    /// Component name.
    pub name: String,
    /// Summary.
    pub message: String,
    /// Hardware identifier.
    pub hardware_id: String,
    /// Details.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/DiagnosticArray`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// One status per component.
    pub status: Vec<DiagnosticStatus>,
}

message_type!(DiagnosticArray, "diagnostic_msgs", "DiagnosticArray");

/// `std_srvs/SetBool` request.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetBoolRequest {
    /// The value asked for.
    pub data: bool,
}
impl ros2_client::Message for SetBoolRequest {}

/// `std_srvs/SetBool` and `std_srvs/Trigger` response (the two have the same fields).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ServiceResponse {
    /// Whether it was done.
    pub success: bool,
    /// What was done, or why not.
    pub message: String,
}
impl ros2_client::Message for ServiceResponse {}

/// `std_srvs/Trigger` request: no field but the one ROS 2 adds to an empty structure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// Always 0.
    pub structure_needs_at_least_one_member: u8,
}
impl ros2_client::Message for TriggerRequest {}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use byteorder::LittleEndian;
    use ros2_client::dds::rustdds::cdr_encoding::{from_bytes, to_vec};

    fn round_trip<T>(m: &T) -> Vec<u8>
    where
        T: Serialize + for<'de> Deserialize<'de> + PartialEq + core::fmt::Debug,
    {
        let bytes = to_vec::<T, LittleEndian>(m).unwrap();
        let (back, used) = from_bytes::<T, LittleEndian>(&bytes).unwrap();
        assert_eq!(&back, m);
        assert_eq!(used, bytes.len());
        bytes
    }

    /// CDR (OMG CDR, little endian): a Twist is six float64 in a row, 48 bytes.
    #[test]
    fn twist_is_six_doubles() {
        let t = Twist {
            linear: Vector3 {
                x: 0.5,
                y: 0.0,
                z: 0.0,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: -1.0,
            },
        };
        let b = round_trip(&t);
        assert_eq!(b.len(), 48);
        assert_eq!(b[..8], 0.5f64.to_le_bytes());
        assert_eq!(b[40..], (-1.0f64).to_le_bytes());
    }

    /// A header: int32 sec, uint32 nanosec, then the string as uint32 length (counting the NUL),
    /// the bytes and the NUL.
    #[test]
    fn header_layout() {
        let h = Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "odom".into(),
        };
        let b = round_trip(&h);
        assert_eq!(
            b,
            [1, 0, 0, 0, 2, 0, 0, 0, 5, 0, 0, 0, b'o', b'd', b'o', b'm', 0]
        );
    }

    /// Odometry: header (17 bytes) and child_frame_id, then the pose aligned to 8; the two
    /// covariances are fixed arrays (36 doubles each, no length).
    #[test]
    fn odometry_round_trip_and_size() {
        let mut o = Odometry {
            header: Header {
                stamp: Time {
                    sec: 1_700_000_000,
                    nanosec: 5,
                },
                frame_id: "odom".into(),
            },
            child_frame_id: "base_link".into(),
            ..Odometry::default()
        };
        o.pose.pose.position.x = 1.25;
        o.pose.pose.orientation = Quaternion::from_yaw(0.3);
        o.pose.covariance = Covariance::diagonal([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        o.twist.twist.linear.x = 0.5;
        let b = round_trip(&o);
        // 17 (header) → pad to 20, 4 + 10 ("base_link\0") = 34 → pad to 40; pose 7 doubles + 36,
        // twist 6 + 36: 85 doubles = 680 bytes.
        assert_eq!(b.len(), 40 + 85 * 8);
        assert_eq!(b[40..48], 1.25f64.to_le_bytes());
    }

    #[test]
    fn the_other_messages_round_trip() {
        round_trip(&TwistStamped::default());
        round_trip(&TfMessage {
            transforms: vec![TransformStamped {
                child_frame_id: "base_link".into(),
                ..TransformStamped::default()
            }],
        });
        round_trip(&JointState {
            name: vec!["l".into(), "r".into()],
            position: vec![1.0, 2.0],
            velocity: vec![0.1, 0.2],
            ..JointState::default()
        });
        round_trip(&DiagnosticArray {
            status: vec![DiagnosticStatus {
                level: level::WARN,
                name: "n".into(),
                values: vec![KeyValue {
                    key: "mode".into(),
                    value: "HOLD".into(),
                }],
                ..DiagnosticStatus::default()
            }],
            ..DiagnosticArray::default()
        });
        assert_eq!(round_trip(&SetBoolRequest { data: true }), [1]);
        assert_eq!(round_trip(&TriggerRequest::default()), [0]);
        round_trip(&ServiceResponse {
            success: true,
            message: "armed".into(),
        });
    }

    #[test]
    fn the_identity_quaternion_is_the_default() {
        let q = Quaternion::default();
        assert_eq!((q.x, q.y, q.z, q.w), (0.0, 0.0, 0.0, 1.0));
        let q = Quaternion::from_yaw(core::f64::consts::PI);
        assert!((q.z - 1.0).abs() < 1e-12 && q.w.abs() < 1e-12);
    }

    #[test]
    fn type_names_are_the_ros_ones() {
        assert_eq!((Twist::PACKAGE, Twist::NAME), ("geometry_msgs", "Twist"));
        assert_eq!(
            (TfMessage::PACKAGE, TfMessage::NAME),
            ("tf2_msgs", "TFMessage")
        );
        let n = ros2_client::MessageTypeName::new(Twist::PACKAGE, Twist::NAME);
        assert_eq!(n.dds_msg_type(), "geometry_msgs::msg::dds_::Twist_");
    }
}
