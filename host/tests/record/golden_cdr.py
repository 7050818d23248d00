#!/usr/bin/env python3
"""Golden CDR bytes for host/src/record/msgs.rs, from an independent serializer (Python rosbags).

Builds one message of each type the recorder writes, with the values the Rust unit tests use,
serializes it with rosbags' ROS 2 (Humble) type store as little-endian CDR, and prints
`<type> <hex>` lines. Regenerate: python3 host/tests/record/golden_cdr.py > host/tests/record/golden_cdr.txt
(needs `pip install rosbags`).
"""

import numpy as np
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
Time = ts.types['builtin_interfaces/msg/Time']
Header = ts.types['std_msgs/msg/Header']
Point = ts.types['geometry_msgs/msg/Point']
Quaternion = ts.types['geometry_msgs/msg/Quaternion']
Pose = ts.types['geometry_msgs/msg/Pose']
PoseWithCovariance = ts.types['geometry_msgs/msg/PoseWithCovariance']
Vector3 = ts.types['geometry_msgs/msg/Vector3']
Twist = ts.types['geometry_msgs/msg/Twist']
TwistWithCovariance = ts.types['geometry_msgs/msg/TwistWithCovariance']
Odometry = ts.types['nav_msgs/msg/Odometry']
JointState = ts.types['sensor_msgs/msg/JointState']
KeyValue = ts.types['diagnostic_msgs/msg/KeyValue']
DiagnosticStatus = ts.types['diagnostic_msgs/msg/DiagnosticStatus']
DiagnosticArray = ts.types['diagnostic_msgs/msg/DiagnosticArray']


def header():
    # 12.345678901 s; a frame id whose length (4 + 5 bytes) leaves the next field unaligned.
    return Header(stamp=Time(sec=12, nanosec=345678901), frame_id='odom')


def cov(first):
    c = np.zeros(36, dtype=np.float64)
    c[0] = first
    c[35] = -first
    return c


messages = [
    ('geometry_msgs/msg/Twist',
     Twist(linear=Vector3(x=0.3, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=-0.5))),
    ('nav_msgs/msg/Odometry',
     Odometry(
         header=header(),
         child_frame_id='base_link',
         pose=PoseWithCovariance(
             pose=Pose(position=Point(x=1.5, y=-0.25, z=0.0),
                       orientation=Quaternion(x=0.0, y=0.0, z=0.2, w=0.9797958971132712)),
             covariance=cov(0.01)),
         twist=TwistWithCovariance(
             twist=Twist(linear=Vector3(x=0.3, y=0.0, z=0.0),
                         angular=Vector3(x=0.0, y=0.0, z=0.125)),
             covariance=cov(0.02)))),
    ('sensor_msgs/msg/JointState',
     JointState(
         header=Header(stamp=Time(sec=1, nanosec=2), frame_id=''),
         name=['left_wheel', 'right_wheel'],
         position=np.array([1.25, -2.5], dtype=np.float64),
         velocity=np.array([3.75, 3.5], dtype=np.float64),
         effort=np.array([0.5, -0.75], dtype=np.float64))),
    ('diagnostic_msgs/msg/DiagnosticArray',
     DiagnosticArray(
         header=Header(stamp=Time(sec=2, nanosec=0), frame_id=''),
         status=[
             DiagnosticStatus(level=b'\x01'[0], name='motorlink: mcu', message='REDUCED',
                              hardware_id='amr_spi',
                              values=[KeyValue(key='mode', value='REDUCED'),
                                      KeyValue(key='faults', value='LINK_DEGRADED')]),
             DiagnosticStatus(level=0, name='motorlink: clock', message='synced',
                              hardware_id='amr_spi', values=[]),
         ])),
]

for name, msg in messages:
    print(name, bytes(ts.serialize_cdr(msg, name)).hex())
