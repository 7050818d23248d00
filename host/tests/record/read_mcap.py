#!/usr/bin/env python3
"""Reads an MCAP file written by `motorlink record --sim --seconds S --v V` with two independent
readers (the `mcap` package for the container, `rosbags` for the ROS 2 messages, typed from the
schemas in the file) and checks topics, counts and values. Exit status 0 if every check passes.

    python3 host/tests/record/read_mcap.py FILE.mcap --seconds 2 --v 0.3 [--w W]
(at least 2 s: the board reports a degraded link for its first quality window after power-on,
and the last /diagnostics must show NORMAL)
(needs `pip install mcap rosbags`)
"""

import argparse
import json
import math
import sys
from pathlib import Path

from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

ROS_TOPICS = {
    '/cmd_vel': 'geometry_msgs/msg/Twist',
    '/odom': 'nav_msgs/msg/Odometry',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
}
FRAMES = '/motorlink/frames'
FAILED = []


def check(ok, what):
    print(('ok   ' if ok else 'FAIL ') + what)
    if not ok:
        FAILED.append(what)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('file', type=Path)
    ap.add_argument('--seconds', type=float, required=True)
    ap.add_argument('--v', type=float, required=True)
    ap.add_argument('--w', type=float, default=0.0)
    a = ap.parse_args()
    # One exchange per board millisecond; every exchange carries a valid feedback in simulation,
    # so /cmd_vel, /odom, /joint_states and the frames have one message each; /diagnostics one per
    # 100 exchanges.
    n = round(a.seconds * 1000)
    want = {'/cmd_vel': n, '/odom': n, '/joint_states': n, FRAMES: n, '/diagnostics': n // 100}

    # The container, with the mcap package.
    with a.file.open('rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        check(header.profile == 'ros2', f'profile {header.profile!r} is ros2')
        summary = reader.get_summary()
        counts = {}
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == FRAMES:
                check_frame(schema, channel, message, counts[channel.topic] - 1)
            else:
                if counts[channel.topic] == 1:
                    check(schema.encoding == 'ros2msg' and channel.message_encoding == 'cdr',
                          f'{channel.topic}: ros2msg schema {schema.name}, cdr messages')
                    check(schema.name == ROS_TOPICS[channel.topic],
                          f'{channel.topic}: type {schema.name}')
        check(counts == want, f'message counts {counts} == {want}')
        stats = summary.statistics
        check(stats.message_count == sum(want.values()),
              f'summary statistics: {stats.message_count} messages')

    # The ROS 2 messages, with rosbags typed from the file's own schemas.
    with AnyReader([a.file]) as r:
        # The file's schemas define each type exactly as ROS 2 does (fields, types, constants).
        humble = get_typestore(Stores.ROS2_HUMBLE).fielddefs
        defined = r.typestore.fielddefs
        differ = [k for k in defined if defined[k] != humble.get(k)]
        check(not differ and all(t in defined for t in ROS_TOPICS.values()),
              f'schemas define {len(defined)} types as ROS 2 Humble does (differ: {differ})')
        typed = {c.topic: c.msgtype for c in r.connections}
        check(all(typed.get(t) == ty for t, ty in ROS_TOPICS.items()), f'rosbags types {typed}')
        msgs = {t: [] for t in ROS_TOPICS}
        conns = [c for c in r.connections if c.topic in ROS_TOPICS]
        for conn, t_ns, raw in r.messages(connections=conns):
            msgs[conn.topic].append((t_ns, r.deserialize(raw, conn.msgtype)))
    check(all(len(msgs[t]) == want[t] for t in ROS_TOPICS),
          'rosbags deserialized every message: ' + str({t: len(m) for t, m in msgs.items()}))

    cmd = [m for _, m in msgs['/cmd_vel']]
    check(all(m.linear.x == a.v and m.angular.z == a.w for m in cmd), f'/cmd_vel is ({a.v}, {a.w})')

    odom = msgs['/odom']
    xs = [m.pose.pose.position.x for _, m in odom]
    check(all(m.header.frame_id == 'odom' and m.child_frame_id == 'base_link' for _, m in odom),
          '/odom frames odom -> base_link')
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in odom]
    check(stamps == [t for t, _ in odom], '/odom header stamps are the log times')
    check(all(b - a_ == 1_000_000 for a_, b in zip(stamps, stamps[1:])),
          '/odom one per millisecond of board time')
    # The robot moves the way it is told: x grows (never back by more than an encoder count) and
    # ends within 25 % of v over the run less its first half second (start-up and ramp).
    step = 2 * math.pi * 0.08 / 4096
    sign = 1 if a.v >= 0 else -1
    check(all(sign * (b - a_) >= -step for a_, b in zip(xs, xs[1:])), 'odom x never goes back')
    expect = a.v * (a.seconds - 0.5)
    check(sign * xs[-1] > 0.75 * abs(expect) and sign * xs[-1] < abs(a.v) * a.seconds,
          f'odom x at the end {xs[-1]:.4f} m for v {a.v} over {a.seconds} s')
    v_end = odom[-1][1].twist.twist.linear.x
    check(abs(v_end - a.v) < 0.1 * abs(a.v) + 0.01, f'odom twist at the end {v_end:.4f} m/s')
    q = odom[-1][1].pose.pose.orientation
    check(abs(q.x**2 + q.y**2 + q.z**2 + q.w**2 - 1) < 1e-9, 'odom orientation is a unit quaternion')

    js = [m for _, m in msgs['/joint_states']]
    check(all(list(m.name) == ['left_wheel_joint', 'right_wheel_joint'] for m in js),
          '/joint_states names')
    check(all(len(m.position) == len(m.velocity) == len(m.effort) == 2 for m in js),
          '/joint_states two of each')
    check(sign * js[-1].position[0] > 0, 'left wheel turned the commanded way')

    diags = [m for _, m in msgs['/diagnostics']]
    names = [[s.name for s in d.status] for d in diags]
    check(all(n_ == ['motorlink: mcu', 'motorlink: link', 'motorlink: clock'] for n_ in names),
          '/diagnostics: mcu, link, clock')
    last = diags[-1].status[0]
    values = {kv.key: kv.value for kv in last.values}
    check(last.message == 'NORMAL' and values.get('mode') == 'NORMAL' and last.level == 0,
          f'/diagnostics at the end: {last.message}, level {last.level}')
    check(diags[-1].status[2].message == 'synced', 'clock synced at the end')

    print('FAILED: ' + '; '.join(FAILED) if FAILED else 'all checks passed')
    return 1 if FAILED else 0


def check_frame(schema, channel, message, k):
    if k == 0:
        check(schema is None and channel.message_encoding == 'json',
              f'{FRAMES}: schemaless JSON')
    if k < 3 or k % 500 == 0:
        f = json.loads(message.data)
        check(f['index'] == k and len(f['tx']) == 128 and len(f['rx']) == 128
              and f['t_recv_us'] > f['t_send_us'],
              f'{FRAMES} #{k}: both 64-byte frames, times in order')


if __name__ == '__main__':
    sys.exit(main())
