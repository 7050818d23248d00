//! The DDS side of the node: subscriptions, publishers and services over ros2-client/RustDDS,
//! polled every [`POLL`] on a thread of its own; it talks to the bridge only through [`Shared`].
//!
//! ```text
//!  cmd_vel (Twist | TwistStamped) ─► Shared::put_cmd_vel
//!  services arm/disarm/rearm/estop ─► Shared::request ─► reply once the MCU's feedback shows what it did
//!  Shared::snapshot ─► odometer ─► odom + /tf (odom_hz), joint_states (joint_states_hz)
//!                   └► /diagnostics (diagnostics_hz, and at once when mode, arming or ESTOP change)
//! ```

use std::time::{Duration, Instant};

use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, QosProfile,
    ServiceTypeName,
};
use statemachine::Mode;

use super::diag;
use super::msg::{
    DiagnosticArray, Header, JointState, MessageType, Odometry, Point, Pose, PoseWithCovariance,
    Quaternion, ServiceResponse, SetBoolRequest, TfMessage, Time, Transform, TransformStamped,
    TriggerRequest, Twist, TwistStamped, TwistWithCovariance, Vector3,
};
use super::odom::Odometer;
use super::params::{self, Params, TopicQos};
use super::shared::{Request, Shared, Snapshot};
use crate::bridge::{ArmState, Diagnostic};

/// How often the DDS thread polls its readers and the shared state.
pub const POLL: Duration = Duration::from_millis(2);

/// How long a service call waits for the MCU's answer before replying that none came.
pub const SERVICE_TIMEOUT: Duration = Duration::from_secs(2);

fn err(what: &str, e: impl core::fmt::Display) -> String {
    format!("ROS 2 node: cannot create {what}: {e}")
}

fn qos(q: &TopicQos) -> QosProfile {
    use ros2_client::qos::{Durability, History, WhenFull};
    let base = QosProfile::subscription_default().history(History::KeepLast {
        depth: usize::try_from(q.depth).unwrap_or(1),
    });
    let base = match q.reliability {
        // A full send window never holds the DDS thread: the sample is dropped and counted.
        params::Reliability::Reliable => base.reliability_reliable(WhenFull::Fail),
        params::Reliability::BestEffort => base.reliability_best_effort(),
    };
    base.durability(match q.durability {
        params::Durability::Volatile => Durability::Volatile,
        params::Durability::TransientLocal => Durability::TransientLocal,
    })
}

/// The absolute name of `name` for a node in the root namespace: `~/x` is `/<node>/x`, a relative
/// `x` is `/x` (resolved here: ros2-client would join the namespace `/` and `x` with a second
/// slash, `rt//x`).
fn resolve(name: &str, node: &str) -> Result<Name, String> {
    let full = match name.strip_prefix("~/") {
        Some(rest) => format!("/{node}/{rest}"),
        None if name.starts_with('/') => name.to_string(),
        None => format!("/{name}"),
    };
    Name::parse(&full).map_err(|e| format!("`{name}` is not a valid ROS 2 name: {e}"))
}

fn topic<M: MessageType>(
    node: &Node,
    name: &str,
    node_name: &str,
    q: &QosProfile,
) -> Result<ros2_client::dds::rustdds::Topic, String> {
    let n = resolve(name, node_name)?;
    node.create_topic(&n, MessageTypeName::new(M::PACKAGE, M::NAME), q)
        .map_err(|e| err(&format!("topic {name}"), e))
}

/// Which service a request came in on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Svc {
    Arm,
    Disarm,
    Rearm,
    Estop,
}

/// A service call waiting for the MCU's answer.
#[derive(Debug)]
struct Pending {
    svc: Svc,
    id: ros2_client::RmwRequestId,
    /// What was asked.
    request: Request,
    since: Instant,
    /// `feedback_ok` when it was asked: the answer must come from a later feedback.
    feedback_at: u64,
}

/// What a pending call's answer is, given the latest snapshot and the events since the last one;
/// None while undecided.
fn answer(p: &Pending, s: &Snapshot, events: &[Diagnostic]) -> Option<ServiceResponse> {
    let mode = s.feedback.map(|f| f.mode);
    let faults = diag::fault_names(s.feedback.map_or(0, |f| f.fault_flags));
    let rung = mode.map_or("unknown", diag::mode_name);
    let newer = s.stats.feedback_ok > p.feedback_at.saturating_add(5);
    let ok = |m: String| {
        Some(ServiceResponse {
            success: true,
            message: m,
        })
    };
    let no = |m: String| {
        Some(ServiceResponse {
            success: false,
            message: m,
        })
    };
    let brake = u32::from(Mode::Brake as u8);
    match p.request {
        Request::Arm | Request::Rearm => {
            if let Some(Diagnostic::ArmRefused { .. }) = events
                .iter()
                .find(|d| matches!(d, Diagnostic::ArmRefused { .. }))
            {
                return no(format!("the MCU stayed in BRAKE (faults: {faults}); clear the cause, then re-arm"));
            }
            if s.silent {
                return no("ESTOP engaged: exchanges are stopped; release it first".into());
            }
            if s.arm == Some(ArmState::Armed) && newer && mode.is_some_and(|m| m != brake) {
                return ok(format!("armed: the MCU is in {rung} (faults: {faults})"));
            }
            if s.arm == Some(ArmState::Latched) && newer {
                return no(format!(
                    "the MCU is in {rung} (faults: {faults}); latched, re-arm needed"
                ));
            }
            None
        }
        Request::Disarm => {
            if s.silent || (newer && mode.is_some_and(|m| m >= u32::from(Mode::Stop as u8))) {
                ok(format!("disarmed: the MCU is in {rung} (faults: {faults})"))
            } else {
                None
            }
        }
        Request::Estop(true) => s.silent.then(|| ServiceResponse {
            success: true,
            message: "ESTOP: exchanges stopped; the MCU brakes on comm loss (its 10 ms watchdog)"
                .into(),
        }),
        Request::Estop(false) => (!s.silent && newer).then(|| ServiceResponse {
            success: true,
            message: format!(
                "exchanges resumed: the MCU is in {rung} (faults: {faults}); disarmed, arm or re-arm to drive"
            ),
        }),
    }
}

/// Runs the DDS side until `shared.stopping()` and the bridge has ended.
pub fn run(node_name: &str, p: &Params, hardware_id: &str, shared: &Shared) -> Result<(), String> {
    let ctx = Context::with_options(ContextOptions::new().domain_id(p.domain_id))
        .map_err(|e| err("the DDS participant", e))?;
    let mut node = ctx
        .new_node(
            NodeName::new("/", node_name).map_err(|e| err("the node", e))?,
            NodeOptions::new().enable_rosout(false),
        )
        .map_err(|e| err("the node", e))?;
    // Discovery info for ROS 2 tools (`ros2 node list`) and the parameter services: the spinner.
    let spinner = node.spinner().map_err(|e| err("the spinner", e))?;
    std::thread::Builder::new()
        .name("ros-spinner".into())
        .spawn(move || {
            if let Err(e) = futures::executor::block_on(spinner.spin()) {
                eprintln!("motorlink ros: spinner ended: {e}");
            }
        })
        .map_err(|e| err("the spinner thread", e))?;

    let t = &p.topics;
    let q = &p.qos;
    let n = node_name;
    let odom_pub = {
        let tp = topic::<Odometry>(&node, &t.odom, n, &qos(&q.odom))?;
        node.create_publisher::<Odometry>(&tp, None)
            .map_err(|e| err("the odom publisher", e))?
    };
    let tf_pub = {
        let tp = topic::<TfMessage>(&node, &t.tf, n, &qos(&q.tf))?;
        node.create_publisher::<TfMessage>(&tp, None)
            .map_err(|e| err("the tf publisher", e))?
    };
    let js_pub = {
        let tp = topic::<JointState>(&node, &t.joint_states, n, &qos(&q.joint_states))?;
        node.create_publisher::<JointState>(&tp, None)
            .map_err(|e| err("the joint_states publisher", e))?
    };
    let diag_pub = {
        let tp = topic::<DiagnosticArray>(&node, &t.diagnostics, n, &qos(&q.diagnostics))?;
        node.create_publisher::<DiagnosticArray>(&tp, None)
            .map_err(|e| err("the diagnostics publisher", e))?
    };
    let cmd_twist = if t.cmd_vel_stamped {
        None
    } else {
        let tp = topic::<Twist>(&node, &t.cmd_vel, n, &qos(&q.cmd_vel))?;
        Some(
            node.create_subscription::<Twist>(&tp, None)
                .map_err(|e| err("the cmd_vel subscription", e))?,
        )
    };
    let cmd_stamped = if t.cmd_vel_stamped {
        let tp = topic::<TwistStamped>(&node, &t.cmd_vel, n, &qos(&q.cmd_vel))?;
        Some(
            node.create_subscription::<TwistStamped>(&tp, None)
                .map_err(|e| err("the cmd_vel subscription", e))?,
        )
    } else {
        None
    };
    let mapping = match p.services.mapping {
        params::ServiceMapping::Enhanced => ros2_client::ServiceMapping::Enhanced,
        params::ServiceMapping::Cyclone => ros2_client::ServiceMapping::Cyclone,
        params::ServiceMapping::Basic => ros2_client::ServiceMapping::Basic,
    };
    let sq =
        QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 10 });
    let set_bool = ServiceTypeName::new("std_srvs", "SetBool");
    let trigger = ServiceTypeName::new("std_srvs", "Trigger");
    let s = &p.services;
    let arm_srv = node
        .create_server::<SetBoolRequest, ServiceResponse>(
            mapping,
            &resolve(&s.arm, n)?,
            &set_bool,
            sq.clone(),
            sq.clone(),
        )
        .map_err(|e| err("the arm service", e))?;
    let estop_srv = node
        .create_server::<SetBoolRequest, ServiceResponse>(
            mapping,
            &resolve(&s.estop, n)?,
            &set_bool,
            sq.clone(),
            sq.clone(),
        )
        .map_err(|e| err("the estop service", e))?;
    let disarm_srv = node
        .create_server::<TriggerRequest, ServiceResponse>(
            mapping,
            &resolve(&s.disarm, n)?,
            &trigger,
            sq.clone(),
            sq.clone(),
        )
        .map_err(|e| err("the disarm service", e))?;
    let rearm_srv = node
        .create_server::<TriggerRequest, ServiceResponse>(
            mapping,
            &resolve(&s.rearm, n)?,
            &trigger,
            sq.clone(),
            sq,
        )
        .map_err(|e| err("the rearm service", e))?;

    let dds_names: Vec<String> = [
        (&t.cmd_vel, "cmd_vel in"),
        (&t.odom, "odom"),
        (&t.tf, "tf"),
        (&t.joint_states, "joint_states"),
        (&t.diagnostics, "diagnostics"),
    ]
    .iter()
    .filter_map(|(name, what)| {
        let node_name = NodeName::new("/", n).ok()?;
        let dds = resolve(name, n).ok()?.to_dds_name("rt", &node_name, "");
        Some(format!("{what} {dds}"))
    })
    .collect();
    eprintln!(
        "motorlink ros: domain {}, topics: {}; services {}, {}, {}, {} ({:?} mapping)",
        p.domain_id,
        dds_names.join(", "),
        s.arm,
        s.disarm,
        s.rearm,
        s.estop,
        p.services.mapping
    );
    let drive = p.drive().map_err(|e| e.to_string())?;
    let mut odo = Odometer::new(drive, p.geometry.encoder_counts_per_rev);
    let period = |hz: f64| Duration::from_secs_f64(1.0 / hz);
    let (odom_every, js_every, diag_every) = (
        period(p.rates.odom_hz),
        period(p.rates.joint_states_hz),
        period(p.rates.diagnostics_hz),
    );
    let start = Instant::now();
    let (mut next_odom, mut next_js, mut next_diag) = (start, start, start);
    let mut last_seq: Option<(u32, u32)> = None;
    let mut pending: Vec<Pending> = Vec::new();
    let mut recent: Vec<&'static str> = Vec::new();
    let mut last_key = None;
    let mut dropped = 0u64;
    let f = &p.frames;
    loop {
        // cmd_vel: every sample in, the newest wins.
        if let Some(sub) = &cmd_twist {
            while let Ok(Some((m, _))) = sub.take() {
                shared.put_cmd_vel(m.linear.x, m.angular.z);
            }
        }
        if let Some(sub) = &cmd_stamped {
            while let Ok(Some((m, _))) = sub.take() {
                shared.put_cmd_vel(m.twist.linear.x, m.twist.angular.z);
            }
        }
        let snap = shared.snapshot();
        let feedback_at = snap.stats.feedback_ok;
        let mut new_calls = Vec::new();
        while let Ok(Some((id, r))) = arm_srv.receive_request() {
            let request = if r.data {
                Request::Arm
            } else {
                Request::Disarm
            };
            new_calls.push((Svc::Arm, id, request));
        }
        while let Ok(Some((id, r))) = estop_srv.receive_request() {
            new_calls.push((Svc::Estop, id, Request::Estop(r.data)));
        }
        while let Ok(Some((id, _))) = disarm_srv.receive_request() {
            new_calls.push((Svc::Disarm, id, Request::Disarm));
        }
        while let Ok(Some((id, _))) = rearm_srv.receive_request() {
            new_calls.push((Svc::Rearm, id, Request::Rearm));
        }
        for (svc, id, request) in new_calls {
            // `arm true` from Latched is the explicit re-arm the ladder asks for.
            let request = match (request, snap.arm) {
                (Request::Arm, Some(ArmState::Latched)) => Request::Rearm,
                (r, _) => r,
            };
            shared.request(request);
            pending.push(Pending {
                svc,
                id,
                request,
                since: Instant::now(),
                feedback_at,
            });
        }
        let events: Vec<Diagnostic> = snap.events.iter().map(|(_, d)| *d).collect();
        for d in &events {
            if !matches!(d, Diagnostic::Mode { .. }) && !recent.contains(&d.name()) {
                recent.push(d.name());
            }
        }
        let mut still = Vec::new();
        for c in pending.drain(..) {
            let reply = answer(&c, &snap, &events).or_else(|| {
                (c.since.elapsed() > SERVICE_TIMEOUT).then(|| ServiceResponse {
                    success: false,
                    message: format!(
                        "no answer from the MCU within {} s ({})",
                        SERVICE_TIMEOUT.as_secs(),
                        snap.last_error.as_deref().unwrap_or("no transport error")
                    ),
                })
            });
            match reply {
                Some(r) => {
                    let sent = match c.svc {
                        Svc::Arm => arm_srv.send_response(c.id, r),
                        Svc::Estop => estop_srv.send_response(c.id, r),
                        Svc::Disarm => disarm_srv.send_response(c.id, r),
                        Svc::Rearm => rearm_srv.send_response(c.id, r),
                    };
                    if let Err(e) = sent {
                        eprintln!("motorlink ros: a service reply was not sent: {e}");
                    }
                }
                None => still.push(c),
            }
        }
        pending = still;

        // Odometry from every new feedback (the counts are cumulative, so none is lost between
        // two snapshots).
        if let Some(fb) = snap.feedback {
            if last_seq != Some((fb.seq, fb.timestamp_us)) {
                last_seq = Some((fb.seq, fb.timestamp_us));
                odo.update(&fb);
            }
        }
        let now = Instant::now();
        let stamp = snap.stamp.map_or_else(Time::now, Time::from_system);
        let o = odo.state();
        if now >= next_odom && snap.feedback.is_some() {
            next_odom = now.checked_add(odom_every).unwrap_or(now);
            let header = Header {
                stamp,
                frame_id: f.odom.clone(),
            };
            let pose = Pose {
                position: Point {
                    x: o.x,
                    y: o.y,
                    z: 0.0,
                },
                orientation: Quaternion::from_yaw(o.yaw),
            };
            let msg = Odometry {
                header: header.clone(),
                child_frame_id: f.base.clone(),
                pose: PoseWithCovariance {
                    pose,
                    covariance: super::msg::Covariance::diagonal([1e-3, 1e-3, 1e6, 1e6, 1e6, 1e-2]),
                },
                twist: TwistWithCovariance {
                    twist: Twist {
                        linear: Vector3 {
                            x: o.v,
                            y: 0.0,
                            z: 0.0,
                        },
                        angular: Vector3 {
                            x: 0.0,
                            y: 0.0,
                            z: o.w,
                        },
                    },
                    covariance: super::msg::Covariance::diagonal([1e-3, 1e6, 1e6, 1e6, 1e6, 1e-2]),
                },
            };
            if odom_pub.publish(msg).is_err() {
                dropped = dropped.saturating_add(1);
            }
            if p.publish_tf {
                let tf = TfMessage {
                    transforms: vec![TransformStamped {
                        header,
                        child_frame_id: f.base.clone(),
                        transform: Transform {
                            translation: Vector3 {
                                x: o.x,
                                y: o.y,
                                z: 0.0,
                            },
                            rotation: pose.orientation,
                        },
                    }],
                };
                if tf_pub.publish(tf).is_err() {
                    dropped = dropped.saturating_add(1);
                }
            }
        }
        if now >= next_js && snap.feedback.is_some() {
            next_js = now.checked_add(js_every).unwrap_or(now);
            let js = JointState {
                header: Header {
                    stamp,
                    frame_id: String::new(),
                },
                name: vec![f.left_wheel_joint.clone(), f.right_wheel_joint.clone()],
                position: o.wheel_angle.to_vec(),
                velocity: o.wheel_speed.to_vec(),
                effort: Vec::new(),
            };
            if js_pub.publish(js).is_err() {
                dropped = dropped.saturating_add(1);
            }
        }
        let key = (
            snap.feedback.map(|f| f.mode),
            snap.arm,
            snap.silent,
            snap.ended,
        );
        if now >= next_diag || last_key != Some(key) {
            last_key = Some(key);
            next_diag = now.checked_add(diag_every).unwrap_or(now);
            let mut st = diag::status(&snap, hardware_id, &recent);
            st.values.push(super::msg::KeyValue {
                key: "samples_dropped".into(),
                value: dropped.to_string(),
            });
            st.values.push(super::msg::KeyValue {
                key: "odom_encoder_jumps".into(),
                value: odo.jumps.to_string(),
            });
            recent.clear();
            let msg = DiagnosticArray {
                header: Header {
                    stamp: Time::now(),
                    frame_id: String::new(),
                },
                status: vec![st],
            };
            if diag_pub.publish(msg).is_err() {
                dropped = dropped.saturating_add(1);
            }
        }
        if snap.ended {
            break;
        }
        std::thread::sleep(POLL);
    }
    drop(node);
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use protocol::amr::MotorFeedback;

    fn pending(request: Request) -> Pending {
        Pending {
            svc: Svc::Arm,
            id: ros2_client::RmwRequestId::default(),
            request,
            since: Instant::now(),
            feedback_at: 100,
        }
    }

    fn snap(mode: u32, arm: ArmState, feedback_ok: u64) -> Snapshot {
        let mut s = Snapshot {
            feedback: Some(MotorFeedback {
                mode,
                ..MotorFeedback::default()
            }),
            arm: Some(arm),
            ..Snapshot::default()
        };
        s.stats.feedback_ok = feedback_ok;
        s
    }

    #[test]
    fn an_arm_call_waits_for_the_mcu_and_says_what_it_did() {
        let p = pending(Request::Arm);
        // Armed on the host but no feedback since: undecided.
        assert_eq!(answer(&p, &snap(3, ArmState::Armed, 101), &[]), None);
        let r = answer(&p, &snap(0, ArmState::Armed, 120), &[]).unwrap();
        assert!(r.success && r.message.contains("NORMAL"), "{r:?}");
        // The MCU kept BRAKE: the bridge latched it after its timeout.
        let r = answer(
            &p,
            &snap(4, ArmState::Latched, 400),
            &[Diagnostic::ArmRefused { faults: 0x200 }],
        )
        .unwrap();
        assert!(!r.success && r.message.contains("BRAKE"), "{r:?}");
    }

    #[test]
    fn a_disarm_call_answers_once_the_mcu_stops() {
        let p = pending(Request::Disarm);
        assert_eq!(answer(&p, &snap(0, ArmState::Disarmed, 120), &[]), None);
        let r = answer(&p, &snap(3, ArmState::Disarmed, 120), &[]).unwrap();
        assert!(r.success && r.message.contains("STOP"), "{r:?}");
    }

    #[test]
    fn releasing_estop_reports_the_mcu_still_braked() {
        let p = pending(Request::Estop(false));
        let mut s = snap(4, ArmState::Disarmed, 120);
        s.feedback.as_mut().unwrap().fault_flags = (1 << 4) | (1 << 9);
        let r = answer(&p, &s, &[]).unwrap();
        assert!(
            r.message.contains("BRAKE") && r.message.contains("comm_lost"),
            "{r:?}"
        );
    }

    /// The DDS topic names ROS 2 uses (design.ros2.org, "Topic and Service name mapping to DDS"):
    /// `rt/` and the absolute name without its leading slash.
    #[test]
    fn names_map_to_the_ros_2_dds_names() {
        let node = NodeName::new("/", "motorlink").unwrap();
        let dds = |n: &str| {
            resolve(n, "motorlink")
                .unwrap()
                .to_dds_name("rt", &node, "")
        };
        assert_eq!(dds("cmd_vel"), "rt/cmd_vel");
        assert_eq!(dds("/tf"), "rt/tf");
        assert_eq!(dds("~/arm"), "rt/motorlink/arm");
        assert_eq!(dds("robot1/odom"), "rt/robot1/odom");
        assert!(resolve("bad//name", "motorlink").is_err());
    }
}
