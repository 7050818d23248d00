//! The serialisation against bytes from an independent serializer (Python `rosbags`, see
//! `host/tests/record/golden_cdr.py`), and the schemas' structure.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use super::*;

const GOLDEN: &str = include_str!("../../../tests/record/golden_cdr.txt");

fn golden(name: &str) -> String {
    GOLDEN
        .lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .unwrap()
        .trim()
        .to_string()
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn header() -> Header {
    Header {
        stamp: Time {
            sec: 12,
            nanosec: 345_678_901,
        },
        frame_id: "odom".into(),
    }
}

fn cov(first: f64) -> [f64; 36] {
    let mut c = [0.0; 36];
    c[0] = first;
    c[35] = -first;
    c
}

#[test]
fn twist_matches_rosbags() {
    let m = Twist {
        linear: [0.3, 0.0, 0.0],
        angular: [0.0, 0.0, -0.5],
    };
    assert_eq!(hex(&m.to_cdr()), golden(Twist::NAME));
}

#[test]
fn odometry_matches_rosbags() {
    let m = Odometry {
        header: header(),
        child_frame_id: "base_link".into(),
        position: [1.5, -0.25, 0.0],
        orientation: [0.0, 0.0, 0.2, 0.979_795_897_113_271_2],
        pose_covariance: cov(0.01),
        twist: Twist {
            linear: [0.3, 0.0, 0.0],
            angular: [0.0, 0.0, 0.125],
        },
        twist_covariance: cov(0.02),
    };
    assert_eq!(hex(&m.to_cdr()), golden(Odometry::NAME));
}

#[test]
fn joint_state_matches_rosbags() {
    let m = JointState {
        header: Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: String::new(),
        },
        name: vec!["left_wheel".into(), "right_wheel".into()],
        position: vec![1.25, -2.5],
        velocity: vec![3.75, 3.5],
        effort: vec![0.5, -0.75],
    };
    assert_eq!(hex(&m.to_cdr()), golden(JointState::NAME));
}

#[test]
fn diagnostic_array_matches_rosbags() {
    let kv = |k: &str, v: &str| KeyValue {
        key: k.into(),
        value: v.into(),
    };
    let m = DiagnosticArray {
        header: Header {
            stamp: Time { sec: 2, nanosec: 0 },
            frame_id: String::new(),
        },
        status: vec![
            DiagnosticStatus {
                level: LEVEL_WARN,
                name: "motorlink: mcu".into(),
                message: "REDUCED".into(),
                hardware_id: "amr_spi".into(),
                values: vec![kv("mode", "REDUCED"), kv("faults", "LINK_DEGRADED")],
            },
            DiagnosticStatus {
                level: LEVEL_OK,
                name: "motorlink: clock".into(),
                message: "synced".into(),
                hardware_id: "amr_spi".into(),
                values: vec![],
            },
        ],
    };
    assert_eq!(hex(&m.to_cdr()), golden(DiagnosticArray::NAME));
}

#[test]
fn time_from_nanoseconds() {
    assert_eq!(
        Time::from_ns(12_345_678_901),
        Time {
            sec: 12,
            nanosec: 345_678_901
        }
    );
}

/// The `MSG:` lines of a schema, in order.
fn deps(schema: &str) -> Vec<&str> {
    schema
        .lines()
        .filter_map(|l| l.strip_prefix("MSG: "))
        .collect()
}

#[test]
fn each_schema_carries_every_dependency_once() {
    let odom = Odometry::schema();
    assert!(odom.starts_with("std_msgs/Header header\n"), "{odom}");
    let mut d = deps(&odom);
    assert_eq!(d.len(), 9, "{odom}");
    d.sort_unstable();
    assert_eq!(
        d,
        [
            "builtin_interfaces/Time",
            "geometry_msgs/Point",
            "geometry_msgs/Pose",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Quaternion",
            "geometry_msgs/Twist",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Vector3",
            "std_msgs/Header",
        ]
    );
    // Every MSG line follows a separator line of 80 '='.
    let lines: Vec<&str> = odom.lines().collect();
    for (k, l) in lines.iter().enumerate() {
        if l.starts_with("MSG: ") {
            assert_eq!(lines[k - 1], "=".repeat(80));
        }
    }
    assert_eq!(deps(&Twist::schema()), ["geometry_msgs/Vector3"]);
    assert_eq!(
        deps(&JointState::schema()),
        ["std_msgs/Header", "builtin_interfaces/Time"]
    );
    assert_eq!(
        deps(&DiagnosticArray::schema()),
        [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "diagnostic_msgs/DiagnosticStatus",
            "diagnostic_msgs/KeyValue"
        ]
    );
}
