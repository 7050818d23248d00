#!/usr/bin/env python3
"""End-to-end check of `motorlink ros --sim` against an independent DDS implementation.

Eclipse Cyclone DDS (Python binding) plays the ROS 2 side: a child process publishes
geometry_msgs/Twist on rt/cmd_vel, this process reads rt/odom and rt/diagnostics. Run by
`cargo xtask ros-e2e` inside a network namespace of its own (RustDDS needs a multicast-capable,
non-loopback interface); it can also run on any network where multicast works:

    python3 host/tests/ros/cmd_vel_odom.py --motorlink target/release/motorlink

Checks, in order (every wait is generous: the machine may be busy):
  1. the node is discovered and odom arrives;
  2. armed, +v commanded: the odom twist reaches about v and x grows at about v;
  3. the publisher process is killed: the bridge's 200 ms rule commands zero, the odom twist
     goes to 0 and the position stops changing; diagnostics say cmd_vel is stale;
  4. the ~/estop service (std_srvs/SetBool true, rmw_cyclonedds's request header) stops the
     node's exchanges, SIGUSR2 resumes them: the MCU reports BRAKE with comm_lost and
     brake_latched (its watchdog braked while no frame came) and stays there until the ~/arm
     service asks for the re-arm, whose reply says the MCU left BRAKE;
  5. SIGINT: the node exits with status 0.
Exit status 0 if every check holds; 1 with the failed check otherwise.
"""

import argparse
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

# --- ROS 2 message types, by their IDL (ros2 interface show ...) -----------------------------


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0
    w: t.float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose = field(default_factory=Pose)
    covariance: t.array[t.float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist = field(default_factory=Twist)
    covariance: t.array[t.float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: t.uint8 = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: t.sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: t.sequence[DiagnosticStatus] = field(default_factory=list)


# std_srvs/SetBool as rmw_cyclonedds puts it on the wire: a 16-byte header (the low half of the
# client's GUID, the request's sequence number as high/low words) before the request or reply.
@dataclass
class SetBoolRequest(IdlStruct, typename="std_srvs::srv::dds_::SetBool_Request_"):
    client: t.array[t.uint8, 8] = field(default_factory=lambda: [0] * 8)
    seq_high: t.int32 = 0
    seq_low: t.uint32 = 0
    data: bool = False


@dataclass
class SetBoolResponse(IdlStruct, typename="std_srvs::srv::dds_::SetBool_Response_"):
    client: t.array[t.uint8, 8] = field(default_factory=lambda: [0] * 8)
    seq_high: t.int32 = 0
    seq_low: t.uint32 = 0
    success: bool = False
    message: str = ""


def qos(depth):
    return Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.History.KeepLast(depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )


# --- the publisher child process -------------------------------------------------------------


def publish_forever(v, w, hz):
    """Publishes Twist(v, w) on rt/cmd_vel at `hz` until killed."""
    dp = DomainParticipant(0)
    writer = DataWriter(dp, Topic(dp, "rt/cmd_vel", Twist), qos=qos(10))
    msg = Twist(linear=Vector3(x=v), angular=Vector3(z=w))
    period = 1.0 / hz
    nxt = time.monotonic()
    while True:
        writer.write(msg)
        nxt += period
        time.sleep(max(0.0, nxt - time.monotonic()))


# --- the checks ------------------------------------------------------------------------------


class Failed(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Failed(what)
    print(f"ok: {what}", flush=True)


class Watch:
    """Reads odom and diagnostics; keeps every odom sample with its receive time."""

    def __init__(self, dp):
        self.odom_reader = DataReader(dp, Topic(dp, "rt/odom", Odometry), qos=qos(200))
        self.diag_reader = DataReader(dp, Topic(dp, "rt/diagnostics", DiagnosticArray), qos=qos(50))
        self.odom = []  # (monotonic receive time, x, y, v)
        self.diag = {}  # latest key -> value
        self.diag_history = []

    def poll(self):
        for s in self.odom_reader.take(N=500):
            if isinstance(s, Odometry):
                p = s.pose.pose.position
                self.odom.append((time.monotonic(), p.x, p.y, s.twist.twist.linear.x))
        for s in self.diag_reader.take(N=100):
            if isinstance(s, DiagnosticArray):
                for st in s.status:
                    d = {kv.key: kv.value for kv in st.values}
                    d["_level"] = st.level
                    d["_message"] = st.message
                    self.diag = d
                    self.diag_history.append(d)

    def wait(self, cond, timeout, what):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.poll()
            if cond():
                return
            time.sleep(0.02)
        raise Failed(f"{what} (waited {timeout} s; last diagnostics: {self.diag})")

    def window(self, seconds):
        """Odom samples of the last `seconds`."""
        now = time.monotonic()
        return [o for o in self.odom if o[0] >= now - seconds]

    def collect(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.poll()
            time.sleep(0.02)


class SetBoolClient:
    """A std_srvs/SetBool client of the node's service `name` (e.g. /motorlink/estop)."""

    CLIENT = [0x6D, 0x6C, 0x72, 0x6F, 0x73, 0x74, 0x73, 0x74]

    def __init__(self, dp, name):
        base = name.lstrip("/")
        self.writer = DataWriter(dp, Topic(dp, f"rq/{base}Request", SetBoolRequest), qos=qos(10))
        self.reader = DataReader(dp, Topic(dp, f"rr/{base}Reply", SetBoolResponse), qos=qos(10))
        self.seq = 0
        self.name = name

    def call(self, data, timeout):
        """The reply (success, message) to SetBool(data), waiting for discovery first."""
        end = time.monotonic() + timeout
        while not (self.writer.get_matched_subscriptions() and self.reader.get_matched_publications()):
            if time.monotonic() > end:
                raise Failed(f"service {self.name} not discovered within {timeout} s")
            time.sleep(0.05)
        self.seq += 1
        self.writer.write(SetBoolRequest(client=self.CLIENT, seq_high=0, seq_low=self.seq, data=data))
        while time.monotonic() < end:
            for r in self.reader.take(N=10):
                if isinstance(r, SetBoolResponse) and list(r.client) == self.CLIENT and r.seq_low == self.seq:
                    return r.success, r.message
            time.sleep(0.02)
        raise Failed(f"no reply from {self.name} within {timeout} s")


def run(args):
    v_cmd = args.speed
    params = os.path.join(tempfile.mkdtemp(prefix="mlros-"), "params.yaml")
    with open(params, "w") as f:
        f.write(
            "motorlink:\n  ros__parameters:\n"
            "    rates: {odom_hz: 50.0, joint_states_hz: 10.0, diagnostics_hz: 10.0}\n"
            "    services: {mapping: cyclone}\n"
        )
    log = open(args.log, "w") if args.log else subprocess.DEVNULL
    node = subprocess.Popen(
        [args.motorlink, "ros", "--sim", "--arm", "--params", params] + (["--no-realtime"] if args.no_realtime else []),
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    pub = None
    try:
        dp = DomainParticipant(0)
        w = Watch(dp)
        w.wait(lambda: node.poll() is not None or len(w.odom) > 0, args.discovery_timeout,
               "odom arrives from the node")
        check(node.poll() is None, "the node runs")
        w.wait(lambda: w.diag.get("arm_state") == "armed" and w.diag.get("mode") == "NORMAL",
               20, "the node reports armed, MCU NORMAL")
        check(True, f"odom discovered; diagnostics: mode {w.diag.get('mode')}, clock {w.diag.get('clock_sync')}")

        # 2. Drive: a separate process publishes +v (it is killed below, as a crashed planner).
        pub = subprocess.Popen([sys.executable, __file__, "--publish", str(v_cmd)])
        w.wait(lambda: any(o[3] > 0.5 * v_cmd for o in w.window(0.5)), args.discovery_timeout,
               "the odom twist rises under +v")
        w.collect(2.0)
        win = w.window(1.5)
        check(len(win) >= 10, f"odom keeps coming ({len(win)} samples in 1.5 s)")
        speeds = [o[3] for o in win]
        mean_v = sum(speeds) / len(speeds)
        check(0.7 * v_cmd <= mean_v <= 1.3 * v_cmd,
              f"odom twist {mean_v:.3f} m/s is about the commanded {v_cmd} m/s")
        dt = win[-1][0] - win[0][0]
        dx = win[-1][1] - win[0][1]
        rate = dx / dt if dt > 0 else 0.0
        # Receive times carry DDS and scheduling jitter; the sign and rough size are what count.
        check(dx > 0 and 0.4 * v_cmd <= rate <= 1.6 * v_cmd,
              f"x grows at {rate:.3f} m/s over {dt:.2f} s (+{dx:.3f} m)")
        check(abs(win[-1][2]) < 0.05 * max(abs(win[-1][1]), 0.1) + 0.01,
              f"straight ahead: y = {win[-1][2]:.4f} m")

        # 3. The publisher dies: the host's cmd_vel goes stale after 200 ms, the bridge commands zero.
        pub.kill()
        pub.wait()
        pub = None
        killed = time.monotonic()
        w.wait(lambda: w.diag.get("cmd_vel_stale") == "true", 10, "diagnostics report cmd_vel stale")
        w.wait(lambda: bool(w.window(0.3)) and all(abs(o[3]) < 1e-3 for o in w.window(0.3)), 10,
               "the odom twist goes to 0")
        stop_s = time.monotonic() - killed
        check(True, f"stopped {stop_s:.2f} s after the publisher died (diagnostics at 10 Hz, odom at 50 Hz)")
        # Half a second for the speed loop to settle at zero, then a second of odom.
        w.collect(1.5)
        still = w.window(1.0)
        moved = math.hypot(still[-1][1] - still[0][1], still[-1][2] - still[0][2])
        check(len(still) >= 5 and moved < 1e-3, f"the position stops changing ({moved * 1e3:.3f} mm in 1 s)")
        check(w.diag.get("arm_state") == "armed" and w.diag.get("mode") in ("NORMAL", "REDUCED"),
              f"the bridge stays armed commanding zero; MCU {w.diag.get('mode')}")

        # 4. ESTOP (the service, std_srvs/SetBool): the node stops exchanging frames; the MCU's
        # watchdog brakes and latches. Released by a signal (SIGUSR2), the same request.
        estop = SetBoolClient(dp, "/motorlink/estop")
        ok, msg = estop.call(True, args.discovery_timeout)
        check(ok, f"~/estop true answered: {msg}")
        w.wait(lambda: w.diag.get("exchanges") == "stopped", 10, "diagnostics report exchanges stopped")
        time.sleep(0.5)
        node.send_signal(signal.SIGUSR2)
        w.wait(lambda: w.diag.get("exchanges") == "running" and w.diag.get("mode") == "BRAKE", 10,
               "after the silence the MCU reports BRAKE")
        faults = w.diag.get("faults", "")
        check("comm_lost" in faults and "brake_latched" in faults,
              f"BRAKE with faults {faults} (its comm-loss watchdog)")
        check(w.diag.get("arm_state") == "disarmed", "the bridge is disarmed and does not re-arm by itself")
        w.collect(0.5)
        check(w.diag.get("mode") == "BRAKE", "still BRAKE: leaving it needs an explicit re-arm")

        # The explicit re-arm (~/arm true): a request; the reply says what the MCU did.
        arm = SetBoolClient(dp, "/motorlink/arm")
        ok, msg = arm.call(True, args.discovery_timeout)
        check(ok and "BRAKE" not in msg.split("(")[0], f"~/arm true answered: {msg}")
        # After a comm loss the ladder may hold REDUCED for its clean window before NORMAL.
        w.wait(lambda: w.diag.get("arm_state") == "armed" and w.diag.get("mode") in ("NORMAL", "REDUCED"),
               10, "diagnostics report armed, the MCU out of BRAKE")

        # 5. A clean exit.
        node.send_signal(signal.SIGINT)
        try:
            code = node.wait(timeout=15)
        except subprocess.TimeoutExpired:
            raise Failed("the node did not exit within 15 s of SIGINT")
        check(code == 0, f"the node exits with status {code}")
        return 0
    finally:
        if pub is not None:
            pub.kill()
        if node.poll() is None:
            node.kill()
            node.wait()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--motorlink", default="target/release/motorlink")
    ap.add_argument("--speed", type=float, default=0.3, help="commanded v, m/s")
    ap.add_argument("--discovery-timeout", type=float, default=60.0)
    ap.add_argument("--log", help="write the node's output here")
    ap.add_argument("--no-realtime", action="store_true",
                    help="run the node's bridge thread at normal priority (as a user without RLIMIT_RTPRIO)")
    ap.add_argument("--publish", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.publish is not None:
        publish_forever(args.publish, 0.0, 20.0)
        return 0
    try:
        return run(args)
    except Failed as e:
        print(f"FAILED: {e}", flush=True)
        return 1


if __name__ == "__main__":
    sys.exit(main())
