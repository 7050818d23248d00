"""The link traffic count.py feeds the serial images through QEMU's USART1 (`-serial`), one byte at a
time, and the frames report.py names.

Frames are built by the golden-vector generator (protocol/golden/gen_structs.py: Python `struct`, a
bitwise CRC-16/CCITT-FALSE, COBS written from the algorithm's description), independently of the
Rust encoders. A feed is a list of (label, frame bytes, ticks to run after the frame): the gap lets
the link run at its nominal 50 frames/s (a frame every 20 ticks) instead of frames back to back.
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol", "golden"))
from gen_structs import CDC_CASES_SHAPE, cdc_frame, crc16, teensy_robust, teensy_robust_body  # noqa: E402

# Ticks between frames at 50 frames/s (seed 001 and seed 003 both send at 50 Hz).
GAP = 20


def pwm(duties, timeout_ms=200):
    """Seed 001 SET_MOTOR_PWM (16 bytes on the wire)."""
    return cdc_frame("set_motor_pwm", dict(pwm=list(duties), timeout_ms=timeout_ms))


def enable(on):
    """Seed 001 MOTOR_ENABLE (7 bytes)."""
    return cdc_frame("motor_enable", dict(enable=int(on)))


def estop(engage):
    """Seed 001 ESTOP (7 bytes)."""
    return cdc_frame("estop", dict(action=int(engage)))


# Seed 003 `cmd_type` values.
MTRS, CAL = 0, 1


def teensy(cmd_type, angles=(0, 0, 0, 0), speed=0):
    """Seed 003 robust frame (version 2) for four joints: COBS(version, CmdMsg (36 bytes)), the
    three check bytes of the CRC over those stuffed bytes, and 0x00: 42 bytes on the wire (the
    37-byte body, COBS's code byte, the check bytes and the terminator)."""
    return teensy_robust(dict(cmd_type=cmd_type, is_relative=0, angles=list(angles), speed=speed,
                              accel=0, success=0))


def ping():
    """Seed 001 PING (6 bytes): answered by a STATUS at once."""
    return cdc_frame("ping", {})


# The start of a seed 001 STATUS frame (SOF, msg_id 0x82, 10-byte payload).
STATUS_PREFIX = bytes([0xAA, 0x55, 0x82, 10])

# The emulator test's drive (xtask qemu-e2e): duties 300, -300, 0, 500 per mille, timeout 200 ms.
DRIVE = (300, -300, 0, 500)
# The emulator test's arm pose (30°, -45°, 90°, 0° at 90°/s), and a second one to move to.
POSE = (30, -45, 90, 0)
POSE2 = (-30, 45, -90, 20)

FEEDS = {
    # Enable from the power-on latch and start driving (the ladder goes to REDUCED).
    "cdc-enable": [("MOTOR_ENABLE 1 (from the power-on BRAKE)", enable(True), GAP),
                   ("SET_MOTOR_PWM (the first after the enable)", pwm(DRIVE), GAP)],
    # Driving in NORMAL.
    "cdc-drive": [("SET_MOTOR_PWM (NORMAL)", pwm(DRIVE), GAP)] * 3,
    "cdc-usart": [("SET_MOTOR_PWM (NORMAL)", pwm(DRIVE), GAP)],
    # A PING, the link's ESTOP engaged and released, re-armed, disabled.
    "cdc-commands": [("PING", ping(), GAP), ("ESTOP 1", estop(True), GAP), ("ESTOP 0", estop(False), GAP),
                     ("MOTOR_ENABLE 1 (after the ESTOP release)", enable(True), GAP),
                     ("MOTOR_ENABLE 0", enable(False), GAP)],
    # Re-arm (CAL), then move to the pose.
    "teensy-enable": [("CAL (from the power-on BRAKE)", teensy(CAL), GAP),
                      ("MTRS (the first after CAL)", teensy(MTRS, POSE, 90), GAP)],
    # In NORMAL, to the second pose (the keepalive frames send the first one again).
    "teensy-drive": [("MTRS (NORMAL)", teensy(MTRS, POSE2, 90), GAP)] * 3,
    "teensy-usart": [("MTRS (NORMAL)", teensy(MTRS, POSE2, 90), GAP)],
}

# The frame that keeps a link alive while ticks run: (frame, every that many ticks).
KEEPALIVE = {
    "cdc": (pwm(DRIVE), GAP),
    "teensy": (teensy(MTRS, POSE, 90), GAP),
}


def schedule(feed):
    """One entry per byte: (label, frame number, byte's position, byte, ticks to run after it)."""
    out = []
    for k, (label, frame, gap) in enumerate(FEEDS[feed]):
        for i, b in enumerate(frame):
            out.append((label, k, i, b, gap if i == len(frame) - 1 else 0))
    return out


def cdc_len(kind):
    """Bytes on the wire of a seed 001 message (each kind has a fixed payload)."""
    return len(cdc_frame(kind, CDC_CASES_SHAPE[kind]))


CDC_NAMES = {0x7F: "ACK", 0x81: "IMU_MPU6050", 0x82: "STATUS"}
CDC_ACKED = {0x02: "MOTOR_ENABLE", 0x03: "ESTOP"}


def replies(profile, data):
    """What the firmware sent back, one description per frame with a good CRC (seed 001: the
    message, an ACK with the command and its result; seed 003: the echo's `cmd_type` and
    `cmd_success`)."""
    out = []
    if profile == "cdc":
        i = data.find(b"\xAA\x55")
        while 0 <= i and i + 6 <= len(data):
            msg, n = data[i + 2], data[i + 3]
            body, crc = data[i + 2:i + 4 + n], data[i + 4 + n:i + 6 + n]
            if len(crc) == 2 and int.from_bytes(crc, "little") == crc16(body):
                name = CDC_NAMES.get(msg, f"0x{msg:02x}")
                if msg == 0x7F and n == 2:
                    name += f" {CDC_ACKED.get(body[2], hex(body[2]))} result {body[3]}"
                out.append(name)
            i = data.find(b"\xAA\x55", i + 2)
    else:
        for chunk in data.split(b"\x00")[:-1]:
            body = teensy_robust_body(chunk + b"\x00")
            if body is not None and len(body) > 1:
                words = [int.from_bytes(body[1 + 4 * k:5 + 4 * k], "little", signed=True)
                         for k in range((len(body) - 1) // 4)]
                kind = {MTRS: "MTRS", CAL: "CAL"}.get(words[0], f"cmd_type {words[0]}")
                out.append(f"{kind} echo, cmd_success {words[-1]}")
    return out
