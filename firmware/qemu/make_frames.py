#!/usr/bin/env python3
"""Writes frames.bin for the emulator test: one record per watchdog tick, tag byte + 64-byte frame.

The frames are built here from the wire format description (protobuf wire types, CRC-16/CCITT-FALSE),
independently of the Rust encoder, so the test also checks that the firmware decodes what a host
written from the specification sends.
"""
import struct
import sys

FRAME_LEN = 64
VERSION = 1


def crc16_ccitt_false(data: bytes) -> int:
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def varint(v: int) -> bytes:
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def key(field: int, wire_type: int) -> bytes:
    return varint((field << 3) | wire_type)


def command(ts: int, left: float, right: float, mode: int, enable: int, seq: int, request: int = 0) -> bytes:
    p = bytearray()
    # Fields with their default value are omitted (proto3).
    if ts:
        p += key(1, 5) + struct.pack("<I", ts)
    if left != 0.0:
        p += key(2, 5) + struct.pack("<f", left)
    if right != 0.0:
        p += key(3, 5) + struct.pack("<f", right)
    if mode:
        p += key(4, 0) + varint(mode)
    if enable:
        p += key(5, 0) + varint(enable)
    if seq:
        p += key(7, 5) + struct.pack("<I", seq)
    p += key(8, 0) + varint(VERSION)
    if request:
        p += key(9, 0) + varint(request)
    body = bytes([len(p)]) + bytes(p)
    body += bytes(FRAME_LEN - 2 - len(body))
    return body + struct.pack(">H", crc16_ccitt_false(body))


def main(path: str) -> None:
    recs = []
    # Three ticks with no transaction: the ladder stays latched in BRAKE (power-on).
    recs += [b"\x00" + bytes(FRAME_LEN)] * 3
    seq = 1
    # Arm: a valid frame with enable = 0, then enable = 1 frames ramping up (0.04 rad/s per frame,
    # inside the 0.05 rad/s-per-tick acceleration limit) to left 1.0, right -0.5 rad/s.
    # The first frame also asks for the MCU's identity (request = 1): the next feedback slot
    # carries an McuInfo frame instead of a MotorFeedback.
    recs.append(b"\x01" + command(1000, 0.0, 0.0, 1, 0, seq, request=1))
    for k in range(1, 46):
        seq += 1
        left = min(0.04 * k, 1.0)
        frame = command(1000 + 1000 * k, left, -left / 2, 1, 1, seq)
        if k == 35:
            # One corrupted frame (a bit flipped in the left speed): must be rejected, change nothing.
            bad = bytearray(frame)
            bad[8] ^= 0x10
            frame = bytes(bad)
        recs.append(b"\x01" + frame)
    # End of file: the host stops sending.
    with open(path, "wb") as f:
        f.write(b"".join(recs))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "frames.bin")
