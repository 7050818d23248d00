#!/usr/bin/env python3
"""Golden vectors for seeds 001 (USB CDC), 003 (Teensy) and 004 (Pi SPI), built with Python `struct`.

    gen_structs.py write        writes structs_python.txt: one line per case, "<kind> <hex> k=v ..."
    gen_structs.py check DIR    reads DIR/structs_rust.txt (the same cases encoded by Rust), decodes each
                                with struct and compares the values and the bytes

Lists are comma-separated; floats are given as their IEEE-754 bit patterns. Layouts follow the seeds;
the Pi SPI sub-structures the seed leaves undefined follow protocol/src/pi_spi/assumed.rs.
"""
import os
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def crc16(data: bytes) -> int:
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


assert crc16(b"123456789") == 0x29B1


def cobs(data: bytes) -> bytes:
    """COBS encoding, written from the algorithm's description, plus the 0x00 terminator."""
    out, block = bytearray(), bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out += bytes([255]) + block
                block = bytearray()
    out += bytes([len(block) + 1]) + block
    return bytes(out) + b"\x00"


def uncobs(frame: bytes) -> bytes:
    assert frame[-1] == 0 and 0 not in frame[:-1]
    data, i, body = bytearray(), 0, frame[:-1]
    while i < len(body):
        code = body[i]
        data += body[i + 1:i + code]
        i += code
        if code < 255 and i < len(body):
            data.append(0)
    return bytes(data)


def fbits(x):
    return struct.unpack("<I", struct.pack("<f", x))[0]


# ---- seed 001 ----
CDC_LAYOUT = {  # msg_id, struct format, field names
    "set_motor_pwm": (0x01, "<4hH", ["pwm", "timeout_ms"]),
    "motor_enable": (0x02, "<B", ["enable"]),
    "estop": (0x03, "<B", ["action"]),
    "ping": (0x10, "<", []),
    "ack": (0x7F, "<BB", ["msg_id", "result"]),
    "imu": (0x81, "<I3h3hh2x", ["t_ms", "accel_mg", "gyro_mdps", "temp_cdeg"]),
    "status": (0x82, "<IHHH", ["t_ms", "vbat_mv", "flags", "err"]),
}
CDC_CASES = [
    ("set_motor_pwm", dict(pwm=[-1000, 1000, 0, 1], timeout_ms=200)),
    ("set_motor_pwm", dict(pwm=[32767, -32768, 0x55AA, -1], timeout_ms=65535)),
    ("motor_enable", dict(enable=1)),
    ("motor_enable", dict(enable=0)),
    ("estop", dict(action=1)),
    ("estop", dict(action=0)),
    ("ping", dict()),
    ("ack", dict(msg_id=0x03, result=0)),
    ("imu", dict(t_ms=123456, accel_mg=[0, -1000, 1000], gyro_mdps=[5, -5, 32767], temp_cdeg=2512)),
    ("status", dict(t_ms=4294967295, vbat_mv=12600, flags=0b1011, err=4)),
]


def flat(values, names):
    out = []
    for n in names:
        v = values[n]
        out += v if isinstance(v, list) else [v]
    return out


def cdc_frame(kind, values):
    msg_id, fmt, names = CDC_LAYOUT[kind]
    payload = struct.pack(fmt, *flat(values, names))
    body = bytes([msg_id, len(payload)]) + payload
    return b"\xAA\x55" + body + struct.pack("<H", crc16(body))


def cdc_unframe(kind, frame):
    msg_id, fmt, names = CDC_LAYOUT[kind]
    assert frame[:2] == b"\xAA\x55" and frame[2] == msg_id and len(frame) == 6 + frame[3]
    assert struct.unpack("<H", frame[-2:])[0] == crc16(frame[2:-2]), "crc"
    vals = list(struct.unpack(fmt, frame[4:-2]))
    out = {}
    for n in names:
        k = len(CDC_CASES_SHAPE[kind][n]) if isinstance(CDC_CASES_SHAPE[kind][n], list) else 1
        out[n] = vals[:k] if k > 1 or isinstance(CDC_CASES_SHAPE[kind][n], list) else vals[0]
        vals = vals[k:]
    return out


CDC_CASES_SHAPE = {k: v for k, v in CDC_CASES}

# ---- seed 004 ----
SENSOR = "fffb"
TX_FMT = "<BI4i4iB6hhH" + SENSOR * 5 + "4f" + "ff" + "6f"
RX_FMT = "<BIBH4i4iB4H" + "12f" + "9b9b" + "16f"
assert struct.calcsize(TX_FMT) == 167 and struct.calcsize(RX_FMT) == 179


def parity_word(flags):
    return flags | (0x80 if bin(flags).count("1") % 2 == 0 else 0)


RX_CASE = dict(
    updates=0b010011,  # three flags: odd, parity bit clear
    shutdown=0b10,
    motor_modes=[3, 3, 4, 1],
    motor_target=[100, -100, 399, 0],
    motor_goal=[123456, -1, 0, 2147483647],
    servo_modes=[2, 1, 0, 2],
    servo_pos=[600, 2600, 1500, 0],
    pid=[fbits(x) for x in [1.5, 2.5, 0.25, -1.0, 0.125, 0.0, 3.0, 4.0, 0.5, 0.75, 1e-3, 100.0]],
    gyro_orient=[1, 0, 0, 0, -1, 0, 0, 0, 1],
    compass_orient=[0, 1, 0, 1, 0, 0, 0, 0, -1],
    kinematics=[fbits(x) for x in [0.25, 0.25, 0.25, 0.25, -0.25, 0.25, 0.25, -0.25,
                                   -1.5, 1.5, -1.5, 1.5, 0.001, 0.001, 0.002, 0.002]],
)
TX_CASE = dict(
    update_time=987654321,
    bemf=[1, -2, 3, -4], position=[100000, -100000, 7, 0], done=0b0101,
    analog=[0, 4095, 2048, 1, 2, 3], battery=3000, digital=0b10000000011,
    imu=[fbits(0.5), fbits(-0.5), fbits(9.81), 3] + [fbits(1.0), fbits(2.0), fbits(3.0), 2] +
        [fbits(-40.0), fbits(12.0), fbits(30.0), 1] + [fbits(0.1), fbits(0.2), fbits(0.0), 0] +
        [fbits(0.01), fbits(0.0), fbits(-0.01), -1],
    quat=[fbits(1.0), fbits(0.0), fbits(0.0), fbits(0.0)],
    heading=fbits(359.5), temperature=fbits(36.6),
    odometry=[fbits(x) for x in [1.25, -2.5, 3.0, 0.5, 0.0, -0.75]],
)


def f_from_bits(b):
    return struct.unpack("<f", struct.pack("<I", b))[0]


def rx_bytes(c):
    modes = sum(m << (3 * i) for i, m in enumerate(c["motor_modes"]))
    servos = sum(m << (2 * i) for i, m in enumerate(c["servo_modes"]))
    return struct.pack(RX_FMT, 15, parity_word(c["updates"]), c["shutdown"], modes, *c["motor_target"],
                       *c["motor_goal"], servos, *c["servo_pos"], *map(f_from_bits, c["pid"]),
                       *c["gyro_orient"], *c["compass_orient"], *map(f_from_bits, c["kinematics"]))


def tx_bytes(c):
    imu = []
    for i in range(5):
        x, y, z, acc = c["imu"][4 * i:4 * i + 4]
        imu += [f_from_bits(x), f_from_bits(y), f_from_bits(z), acc]
    return struct.pack(TX_FMT, 15, c["update_time"], *c["bemf"], *c["position"], c["done"], *c["analog"],
                       c["battery"], c["digital"], *imu, *map(f_from_bits, c["quat"]),
                       f_from_bits(c["heading"]), f_from_bits(c["temperature"]),
                       *map(f_from_bits, c["odometry"]))


# ---- seed 003 ----
TEENSY_CASE = dict(cmd_type=0, is_relative=1, angles=[90, -90, 0x0A0A, 2147483647], speed=30, accel=-60, success=1)


def cmdmsg_bytes(c):
    return struct.pack("<ii4iiii", c["cmd_type"], c["is_relative"], *c["angles"], c["speed"], c["accel"], c["success"])


TEENSY_ROBUST_VERSION = 2


def teensy_check_bytes(crc):
    """The three check bytes of a robust frame: the CRC's bits 15..14, 13..7 and 6..0, each byte with
    bit 7 set (so none is 0x00)."""
    return bytes([0x80 | (crc >> 14), 0x80 | ((crc >> 7) & 0x7F), 0x80 | (crc & 0x7F)])


def teensy_check_value(check):
    """The CRC that three check bytes carry, or None if bit 7 of one is clear or bits 6..2 of the
    first are not all zero."""
    k0, k1, k2 = check
    if k0 & 0xFC != 0x80 or not (k1 & 0x80 and k2 & 0x80):
        return None
    return ((k0 & 0x03) << 14) | ((k1 & 0x7F) << 7) | (k2 & 0x7F)


def teensy_robust(c):
    """Seed 003 robust frame, version 2: S = COBS(version | CmdMsg) without COBS's terminator, then
    the check bytes of the CRC-16 over S (the bytes as sent), then 0x00."""
    s = cobs(bytes([TEENSY_ROBUST_VERSION]) + cmdmsg_bytes(c))[:-1]
    return s + teensy_check_bytes(crc16(s)) + b"\x00"


def teensy_robust_body(frame):
    """The version and CmdMsg bytes of a robust frame, or None if its terminator, check bytes, CRC or
    COBS are wrong."""
    if len(frame) < 5 or frame[-1] != 0:
        return None
    s, check = frame[:-4], frame[-4:-1]
    if 0 in s or teensy_check_value(check) != crc16(s):
        return None
    try:
        return uncobs(s + b"\x00")
    except (AssertionError, IndexError):
        return None


def fmt_values(values):
    return " ".join(f"{k}=" + (",".join(map(str, v)) if isinstance(v, list) else str(v)) for k, v in values.items())


def all_cases():
    cases = [(f"cdc_{kind}", cdc_frame(kind, v), v) for kind, v in CDC_CASES]
    cases.append(("pi_rx", rx_bytes(RX_CASE), RX_CASE))
    cases.append(("pi_tx", tx_bytes(TX_CASE), TX_CASE))
    cases.append(("teensy_legacy", cmdmsg_bytes(TEENSY_CASE) + b"\n", TEENSY_CASE))
    cases.append(("teensy_robust", teensy_robust(TEENSY_CASE), TEENSY_CASE))
    return cases


def main():
    cases = all_cases()
    if sys.argv[1:2] == ["write"]:
        with open(os.path.join(HERE, "structs_python.txt"), "w") as f:
            for kind, frame, values in cases:
                f.write(f"{kind} {frame.hex()} {fmt_values(values)}\n")
        print(f"structs: wrote {len(cases)} cases")
    elif sys.argv[1:2] == ["check"]:
        with open(os.path.join(sys.argv[2], "structs_rust.txt")) as f:
            rust = [l.split() for l in f if l.strip()]
        assert len(rust) == len(cases), "case count differs"
        bad = 0
        for (kind, frame, values), (rkind, rhex) in zip(cases, rust):
            got = bytes.fromhex(rhex)
            ok = rkind == kind and got == frame
            # Decode the Rust bytes with struct / the hand-written COBS, independently of the comparison above.
            if kind.startswith("cdc_"):
                ok = ok and cdc_unframe(kind[4:], got) == values
            elif kind == "pi_rx":
                ok = ok and struct.unpack(RX_FMT, got)[:2] == (15, parity_word(values["updates"]))
            elif kind == "pi_tx":
                ok = ok and struct.unpack(TX_FMT, got)[:2] == (15, values["update_time"])
            elif kind == "teensy_robust":
                body = teensy_robust_body(got)
                ok = ok and body is not None and body[0] == TEENSY_ROBUST_VERSION and body[1:] == cmdmsg_bytes(values)
                # Every single-bit flip of the frame is refused here too (the CRC covers the stuffed
                # bytes as sent, so a flipped COBS code byte cannot pass it).
                for bit in range(len(got) * 8):
                    flipped = bytearray(got)
                    flipped[bit // 8] ^= 1 << (bit % 8)
                    if teensy_robust_body(bytes(flipped)) is not None:
                        print("ACCEPTED FLIP", kind, bit)
                        ok = False
            if not ok:
                bad += 1
                print("MISMATCH", kind, got.hex(), frame.hex())
        print(f"structs: python checked {len(rust)} Rust-encoded frames, {bad} mismatches")
        sys.exit(1 if bad else 0)
    else:
        print(__doc__)
        sys.exit(2)


if __name__ == "__main__":
    main()
