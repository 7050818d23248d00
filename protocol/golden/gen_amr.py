#!/usr/bin/env python3
"""Golden vectors for the seed 000 AMR SPI frame, built with the Python `protobuf` library.

Three kinds of frame: `command` (MotorCommand), `feedback` (MotorFeedback) and `info` (McuInfo, sent in
the feedback slot after an identity request; it carries info_version instead of protocol_version).

    gen_amr.py write            writes amr_cases.txt (the values) and amr_python.txt (frames encoded here)
    gen_amr.py check FRAMES     decodes FRAMES (e.g. written by the Rust encoder) and compares with amr_cases.txt

The message classes come from the shipped proto/amr.proto, compiled by `protoc` into a descriptor set
(no generated code, so any protobuf runtime version works). The frame (length byte, payload, zero
padding, CRC-16/CCITT-FALSE over bytes 0..62, stored big-endian) is built here independently of the Rust code.
"""
import math
import os
import struct
import subprocess
import sys
import tempfile

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

HERE = os.path.dirname(os.path.abspath(__file__))
PROTO_DIR = os.path.join(HERE, "..", "proto")
FRAME_LEN = 64
CRC_OFFSET = FRAME_LEN - 2
PROTOCOL_VERSION = 1
INFO_VERSION = 1


def crc16_ccitt_false(data: bytes) -> int:
    """The seed's bitwise loop: poly 0x1021, init 0xFFFF."""
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


assert crc16_ccitt_false(b"123456789") == 0x29B1


def load_classes():
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "amr.desc")
        subprocess.run(["protoc", "-I", PROTO_DIR, "--descriptor_set_out=" + out, "amr.proto"], check=True)
        with open(out, "rb") as f:
            fds = descriptor_pb2.FileDescriptorSet.FromString(f.read())
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return {kind: message_factory.GetMessageClass(pool.FindMessageTypeByName("amr." + name))
            for kind, name in (("command", "MotorCommand"), ("feedback", "MotorFeedback"), ("info", "McuInfo"))}


def f32_bits(x: float) -> int:
    return struct.unpack("<I", struct.pack("<f", x))[0]


def bits_f32(b: int) -> float:
    return struct.unpack("<f", struct.pack("<I", b))[0]


COMMAND_FIELDS = ["timestamp_us", "left_speed_cmd", "right_speed_cmd", "control_mode", "enable", "seq", "request"]
FEEDBACK_FIELDS = ["timestamp_us", "left_speed", "right_speed", "left_current", "right_current",
                   "left_encoder", "right_encoder", "fault_flags", "seq", "mode", "cmd_seq"]
INFO_FIELDS = ["fw_version", "git_hash", "board", "build_date", "reset_cause", "reset_count", "panic_line", "seq",
               "dirty"]
FIELDS = {"command": COMMAND_FIELDS, "feedback": FEEDBACK_FIELDS, "info": INFO_FIELDS}
# The field that must equal the version, per kind (the info message has no protocol_version).
VERSION_FIELD = {"command": ("protocol_version", PROTOCOL_VERSION), "feedback": ("protocol_version", PROTOCOL_VERSION),
                 "info": ("info_version", INFO_VERSION)}
FLOATS = {"left_speed_cmd", "right_speed_cmd", "left_speed", "right_speed", "left_current", "right_current"}

# Values chosen to exercise every field: zero (omitted), small and large varints, negative zigzag,
# NaN (passes the wire, the ladder refuses it), extremes of every type.
COMMANDS = [
    dict(timestamp_us=0, left_speed_cmd=0.0, right_speed_cmd=0.0, control_mode=0, enable=0, seq=0, request=0),
    dict(timestamp_us=1000, left_speed_cmd=1.5, right_speed_cmd=-1.5, control_mode=1, enable=1, seq=1, request=0),
    dict(timestamp_us=4294967295, left_speed_cmd=20.0, right_speed_cmd=-20.0, control_mode=1, enable=1, seq=4294967295,
         request=0),
    dict(timestamp_us=123456789, left_speed_cmd=0.1, right_speed_cmd=3.25, control_mode=3, enable=0, seq=305419896,
         request=0),
    dict(timestamp_us=7, left_speed_cmd=float("nan"), right_speed_cmd=float("inf"), control_mode=255, enable=1, seq=2,
         request=0),
    dict(timestamp_us=268435456, left_speed_cmd=-3.4028234663852886e38, right_speed_cmd=1e-45, control_mode=2, enable=0,
         seq=128, request=0),
    # The identity request (enable 0, speeds 0, as `motorlink info` sends it), and a request this
    # version does not define (still a valid command: the MCU ignores it).
    dict(timestamp_us=5000, left_speed_cmd=0.0, right_speed_cmd=0.0, control_mode=0, enable=0, seq=77, request=1),
    dict(timestamp_us=1, left_speed_cmd=0.5, right_speed_cmd=0.5, control_mode=1, enable=1, seq=3, request=4294967295),
]
FEEDBACKS = [
    dict(timestamp_us=0, left_speed=0.0, right_speed=0.0, left_current=0.0, right_current=0.0, left_encoder=0,
         right_encoder=0, fault_flags=0, seq=0, mode=0, cmd_seq=0),
    dict(timestamp_us=1001, left_speed=1.25, right_speed=-1.25, left_current=0.5, right_current=0.75,
         left_encoder=-1, right_encoder=1, fault_flags=0x0210, seq=1, mode=4, cmd_seq=1),
    dict(timestamp_us=4294967295, left_speed=40.0, right_speed=-40.0, left_current=-2.0, right_current=12.5,
         left_encoder=-2147483648, right_encoder=2147483647, fault_flags=0xFFFF, seq=4294967295, mode=255,
         cmd_seq=4294967295),
    dict(timestamp_us=99999, left_speed=float("-inf"), right_speed=0.333, left_current=1e-3, right_current=0.0,
         left_encoder=123456, right_encoder=-654321, fault_flags=0x0001, seq=77, mode=1, cmd_seq=76),
]
# board: 0 AMR SPI, 1 CDC, 2 Teensy, 3 Pi SPI; reset_cause: 0 unknown .. 8 low-power.
INFOS = [
    dict(fw_version=0, git_hash=0, board=0, build_date=0, reset_cause=0, reset_count=0, panic_line=0, seq=0, dirty=0),
    dict(fw_version=0x010203, git_hash=0x1A2B3C4D, board=0, build_date=20261130, reset_cause=1, reset_count=0,
         panic_line=0, seq=1234, dirty=0),
    dict(fw_version=0x00000A, git_hash=0xDEADBEEF, board=3, build_date=20250101, reset_cause=4, reset_count=3,
         panic_line=417, seq=4294967295, dirty=1),
    dict(fw_version=4294967295, git_hash=4294967295, board=2, build_date=4294967295, reset_cause=8,
         reset_count=4294967295, panic_line=4294967295, seq=2, dirty=1),
    dict(fw_version=0x020000, git_hash=0x00000001, board=1, build_date=19991231, reset_cause=3, reset_count=1,
         panic_line=0, seq=65536, dirty=0),
]


def normalise(kind, values):
    """Floats become their f32 bit patterns, the value the wire carries."""
    out = {}
    for k, v in values.items():
        out[k] = f32_bits(v) if k in FLOATS else int(v)
    return out


def encode(cls, kind, values):
    m = cls()
    for k, v in values.items():
        setattr(m, k, bits_f32(v) if k in FLOATS else bool(v) if k == "dirty" else v)
    name, version = VERSION_FIELD[kind]
    setattr(m, name, version)
    payload = m.SerializeToString()
    assert len(payload) <= CRC_OFFSET - 1, (kind, len(payload))
    body = bytes([len(payload)]) + payload + bytes(CRC_OFFSET - 1 - len(payload))
    return body + struct.pack(">H", crc16_ccitt_false(body))


def decode(cls, kind, frame: bytes):
    if len(frame) != FRAME_LEN:
        raise ValueError("length")
    body, crc = frame[:CRC_OFFSET], struct.unpack(">H", frame[CRC_OFFSET:])[0]
    if crc16_ccitt_false(body) != crc:
        raise ValueError("crc")
    n = body[0]
    if n > CRC_OFFSET - 1 or any(body[1 + n:]):
        raise ValueError("framing")
    m = cls.FromString(body[1:1 + n])
    name, version = VERSION_FIELD[kind]
    if getattr(m, name) != version:
        raise ValueError("version")
    return m


def fmt_case(kind, values):
    fields = FIELDS[kind]
    return kind + " " + " ".join(f"{k}={values[k]}" for k in fields)


def parse_case(line):
    kind, *kv = line.split()
    return kind, {k: int(v) for k, v in (p.split("=") for p in kv)}


def main():
    classes = load_classes()
    cases = [("command", normalise("command", c)) for c in COMMANDS] + \
            [("feedback", normalise("feedback", c)) for c in FEEDBACKS] + \
            [("info", normalise("info", c)) for c in INFOS]
    # An info frame is never taken for a command or a feedback, nor the reverse: each fails the
    # other's version check (command and feedback share protocol_version; they travel in opposite directions).
    for kind, values in cases:
        frame = encode(classes[kind], kind, values)
        for other in (o for o in classes if o != kind and "info" in (o, kind)):
            try:
                decode(classes[other], other, frame)
            except ValueError as e:
                assert str(e) == "version", (kind, other, e)
            else:
                raise AssertionError(f"a {kind} frame decoded as {other}")
    if sys.argv[1:2] == ["write"]:
        with open(os.path.join(HERE, "amr_cases.txt"), "w") as f:
            for kind, values in cases:
                f.write(fmt_case(kind, values) + "\n")
        with open(os.path.join(HERE, "amr_python.txt"), "w") as f:
            for kind, values in cases:
                f.write(f"{kind} {encode(classes[kind], kind, values).hex()}\n")
        print(f"amr: wrote {len(cases)} cases")
    elif sys.argv[1:2] == ["check"]:
        with open(sys.argv[2]) as f:
            frames = [l.split() for l in f if l.strip()]
        assert len(frames) == len(cases), "frame count differs from the case count"
        bad = 0
        for (kind, values), (fkind, hexframe) in zip(cases, frames):
            assert kind == fkind
            m = decode(classes[kind], kind, bytes.fromhex(hexframe))
            got = {k: (f32_bits(getattr(m, k)) if k in FLOATS else int(getattr(m, k))) for k in values}
            if got != values:
                bad += 1
                print("MISMATCH", kind, values, got)
        print(f"amr: python decoded {len(frames)} frames from {sys.argv[2]}, {bad} mismatches")
        sys.exit(1 if bad else 0)
    else:
        print(__doc__)
        sys.exit(2)


if __name__ == "__main__":
    main()
