#!/usr/bin/env python3
"""The original Jetson bridge's 1 kHz loop, as Python runs it, timed period by period.

The original ROS 2 node ran its SPI callback from a 1 ms timer: take the latest cmd_vel (zero if
older than 200 ms), inverse kinematics for the two wheels, build the 64-byte command frame, the
SPI transfer, parse the feedback. This script does the same work each period with no ROS and no
device: the transfer returns a fixed, valid feedback frame. The loop is paced the way a Python
node without a real-time executor paces it: the work, then time.sleep(0.001).

It prints one JSON object on one line:

    {"impl": "python-sleep-1ms", "python": "3.x.y", "seconds": S,
     "periods_us": [p1, p2, ...]}

where p_k is the time between the starts of two consecutive periods, in microseconds. The
statistics are left to the caller (`motorlink loop-bench` judges both loops with the same code).

    python3 host/scripts/seed_loop.py [seconds]
"""
import json
import platform
import struct
import sys
import time

WHEELBASE_M = 0.40
WHEEL_RADIUS_M = 0.08
CMD_VEL_STALE_S = 0.2
FRAME_LEN = 64


def crc16_ccitt_false(data):
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), bit by bit as a plain Python port would."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            if crc & 0x8000:
                crc = ((crc << 1) ^ 0x1021) & 0xFFFF
            else:
                crc = (crc << 1) & 0xFFFF
    return crc


def build_command(timestamp_us, seq, w_left, w_right):
    """A 64-byte command: length, payload (time, two wheel speeds, mode, enable, seq), CRC."""
    payload = struct.pack("<IffBBI", timestamp_us & 0xFFFFFFFF, w_left, w_right, 1, 1, seq & 0xFFFFFFFF)
    body = bytes([len(payload)]) + payload
    body = body + bytes(FRAME_LEN - 2 - len(body))
    return body + struct.pack(">H", crc16_ccitt_false(body))


def parse_feedback(frame):
    """Checks the CRC and unpacks the feedback payload; None if the frame is refused."""
    body, crc = frame[:-2], struct.unpack(">H", frame[-2:])[0]
    if crc16_ccitt_false(body) != crc:
        return None
    n = body[0]
    return struct.unpack("<IffffiiH", body[1:1 + n])


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 60.0
    if not seconds > 0.0:
        sys.exit("seconds must be above 0")
    # The reply every transfer returns: a valid feedback frame.
    fb_payload = struct.pack("<IffffiiH", 5, 0.5, -0.5, 1.25, 0.75, -3, 7, 0)
    fb_body = bytes([len(fb_payload)]) + fb_payload
    fb_body = fb_body + bytes(FRAME_LEN - 2 - len(fb_body))
    reply = fb_body + struct.pack(">H", crc16_ccitt_false(fb_body))

    cmd_vel = (1.0, 0.2)
    cmd_vel_stamp = time.monotonic()
    starts = []
    seq = 0
    end = time.monotonic() + seconds
    while True:
        now = time.monotonic()
        if now >= end:
            break
        starts.append(now)
        # The timer callback's body.
        if now - cmd_vel_stamp > CMD_VEL_STALE_S:
            cmd_vel_stamp = now  # a subscriber keeps cmd_vel fresh at 20 Hz
        v, omega = cmd_vel
        w_left = (v - omega * WHEELBASE_M / 2.0) / WHEEL_RADIUS_M
        w_right = (v + omega * WHEELBASE_M / 2.0) / WHEEL_RADIUS_M
        seq += 1
        frame = build_command(int(now * 1e6), seq, w_left, w_right)
        if len(frame) != FRAME_LEN or parse_feedback(reply) is None:
            sys.exit("frame building is broken")
        time.sleep(0.001)
    periods = [(b - a) * 1e6 for a, b in zip(starts, starts[1:])]
    print(json.dumps({"impl": "python-sleep-1ms", "python": platform.python_version(),
                      "seconds": seconds, "periods_us": [round(p, 1) for p in periods]}))


if __name__ == "__main__":
    main()
