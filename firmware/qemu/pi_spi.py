#!/usr/bin/env python3
"""The emulator test of the `pi-spi` image (seed 004), from the seed's struct description.

  pi_spi.py make TRANSFERS       writes the host's transfers: one record per watchdog tick,
                                 tag byte (1 = a transfer in this tick, 0 = none) + 179 bytes
  pi_spi.py check TRACE FEEDBACK checks the firmware's own trace and the TxBuffers it queued
  pi_spi.py make-budget TRANSFERS  writes the run firmware/budget/run.sh counts instructions on
                                 (worst-case-ish transfers: mixed modes, every costly update flag)

The buffers are packed here with Python's `struct` from the seed's C declarations (little-endian,
packed), independently of the Rust codec, so the test also checks that the firmware reads what a
Pi written from the seed sends.
"""
import math
import re
import struct
import sys

TRANSFER_LEN = 179
VERSION = 15
PERIOD = 10  # ticks between transfers: the seed's 100 Hz
OFF, PASSIV_BRAKE, PWM, MAV, MTP = range(5)
SHUTDOWN_SERVO, SHUTDOWN_MOTOR = 1, 2
ODOM_RESET = 1 << 5

# The script of the run: (first tick, what the host sends from then on, every PERIOD ticks).
#   ("shutdown", pwm)  motors shut down (the enable 0 of the re-arm edge)
#   ("pwm", duty)      all four motors PWM at `duty` (0–399)
#   ("bad_parity"|"bad_version", duty, shutdown)   one corrupted transfer
#   ("silent",)        nothing more: the link is lost
# The ladder ramps a duty at duty_step per tick and holds REDUCED (half duty) for its 1 s clean
# window after a re-arm: PWM 100 of 399 (a quarter) is reached by about tick 560.
SHUTDOWN_AT = 1100
LAST_VALID = 1300
SCRIPT = [
    (10, ("shutdown", 0)),
    (20, ("pwm", 100)),
    (1000, ("bad_parity", 399, False)),
    (1010, ("pwm", 100)),
    (1020, ("bad_version", 399, False)),
    (1030, ("pwm", 100)),
    (SHUTDOWN_AT, ("bad_version", 399, True)),
    (1110, ("shutdown", 0)),
    (1120, ("pwm", -100)),
    (LAST_VALID + 1, ("silent",)),
]
END_TICK = 1420


def rx_buffer(modes, targets, updates=0, shutdown=0, version=VERSION, parity_ok=True,
              goals=(0, 0, 0, 0), servo_modes=(0, 0, 0, 0), servo_pos=(0, 0, 0, 0),
              pid=((0.0,) * 4, (0.0,) * 4, (0.0,) * 4), gyro=(0,) * 9, compass=(0,) * 9,
              inverse=((0.0,) * 4,) * 3, ticks_to_rad=(0.0,) * 4):
    """An RxBuffer as the seed declares it: version, updates (bit 7 parity), systemShutdown,
    motorControlMode (3 bits per motor), motorTarget[4], motorGoalPosition[4], servoMode (2 bits
    per servo), servoPos[4], MotorPidSettings (f32 kp[4], ki[4], kd[4]), two i8[9] orientations,
    KinematicsConfig (f32 inverse[3][4], ticks_to_rad[4])."""
    if bin(updates & 0x7F).count("1") % 2 == 0:
        updates |= 0x80
    if not parity_ok:
        updates ^= 0x80
    mode_word = sum(m << (3 * n) for n, m in enumerate(modes))
    servo_word = sum(m << (2 * n) for n, m in enumerate(servo_modes))
    b = struct.pack("<BIBH4i4iB4H", version, updates, shutdown, mode_word, *targets, *goals,
                    servo_word, *servo_pos)
    b += struct.pack("<12f", *pid[0], *pid[1], *pid[2])
    b += struct.pack("<9b9b", *gyro, *compass)
    b += struct.pack("<16f", *(v for row in inverse for v in row), *ticks_to_rad)
    assert len(b) == TRANSFER_LEN
    return b


def transfer_at(tick):
    """The host's transfer in this tick, or None."""
    if tick % PERIOD:
        return None
    step = None
    for start, what in SCRIPT:
        if tick >= start:
            step = (start, what)
    if step is None:
        return None
    start, what = step
    kind = what[0]
    if kind == "silent":
        return None
    if kind == "shutdown":
        return rx_buffer([PWM] * 4, [what[1]] * 4, shutdown=SHUTDOWN_MOTOR)
    if kind == "pwm":
        return rx_buffer([PWM] * 4, [what[1]] * 4)
    if tick != start:
        return None  # a corrupted transfer is sent once
    shutdown = SHUTDOWN_MOTOR if what[2] else 0
    if kind == "bad_parity":
        return rx_buffer([PWM] * 4, [what[1]] * 4, updates=ODOM_RESET, shutdown=shutdown, parity_ok=False)
    return rx_buffer([PWM] * 4, [what[1]] * 4, shutdown=shutdown, version=VERSION - 1)


def make(path):
    with open(path, "wb") as f:
        for tick in range(1, END_TICK):
            t = transfer_at(tick)
            f.write(b"\x01" + t if t is not None else b"\x00" + bytes(TRANSFER_LEN))


# The budget run (`make-budget`, for firmware/budget/run.sh): a shutdown transfer, then from tick
# 20 a transfer every PERIOD ticks until BUDGET_LAST, then nothing (the comm-loss BRAKE ends the
# run). count.py lets the REDUCED window of 1000 ticks pass before it counts, then samples about
# 200 ticks; the transfers run on for a few hundred ticks more, so every counted unit meets them.
MOTOR_PID_SPEED, MOTOR_PID_POS, IMU_ORIENTATION, SAVE_IMU_CAL, KINEMATICS = (1 << n for n in range(5))
BUDGET_LAST = 1800
BUDGET_END = BUDGET_LAST + 200
SERVO_ENABLED = 2
# One gain set, within both mcu::pi_spi::SPEED_BOUNDS (kp ≤ 10, ki ≤ 1000, kd ≤ 0.1) and
# POSITION_BOUNDS (kp ≤ 100, ki ≤ 1000, kd ≤ 1), each above the per-sample resolution at 1 kHz
# (ki·0.001 and kd·1000 in Q16.16): the seed sends one block for both flags.
BUDGET_PID = ((0.5,) * 4, (1.0,) * 4, (0.001,) * 4)
IDENTITY = (1, 0, 0, 0, 1, 0, 0, 0, 1)
# A quarter turn about z (a proper rotation): alternating it with the identity makes every
# orientation update change the gyro's axes (the fusion's quaternion is turned), the costlier path;
# an orientation equal to the one in force is only checked.
QUARTER_Z = (0, -1, 0, 1, 0, 0, 0, 0, 1)
# Mecanum-style inverse kinematics: wheel radius R, half track + half wheelbase T; 1440 counts/rev.
R, T = 0.0325, 0.18
INVERSE = ((R / 4,) * 4, (0.0,) * 4, (-R / (2 * T), R / (2 * T), -R / (2 * T), R / (2 * T)))
TICKS_TO_RAD = (2 * math.pi / 1440,) * 4
# Per motor in each mode: PWM duty (of 399), MAV speed (encoder ticks/s, 1 rev/s), MTP goal
# (2 revolutions) under a speed cap of 1 rev/s.
BUDGET_MODES = (PWM, MAV, MTP, PASSIV_BRAKE)


def budget_transfer(k):
    """The k-th transfer after the shutdown one: the four modes rotated by k, servos enabled,
    both gain sets and the orientation in every transfer, the kinematics in every other one
    (a configuration restarts the odometry from a new baseline: the odometry update right after
    one only takes the counts, the next integrates)."""
    modes = [BUDGET_MODES[(n + k) % 4] for n in range(4)]
    targets = [{PWM: 200, MAV: 1440, MTP: 1440}.get(m, 0) for m in modes]
    goals = [2880 if m == MTP else 0 for m in modes]
    updates = MOTOR_PID_SPEED | MOTOR_PID_POS | IMU_ORIENTATION | (KINEMATICS if k % 2 == 0 else 0)
    return rx_buffer(modes, targets, updates=updates, goals=goals,
                     servo_modes=(SERVO_ENABLED,) * 4, servo_pos=(1500, 1200, 1800, 2000),
                     pid=BUDGET_PID, gyro=QUARTER_Z if k % 2 else IDENTITY, compass=IDENTITY,
                     inverse=INVERSE, ticks_to_rad=TICKS_TO_RAD)


def make_budget(path):
    with open(path, "wb") as f:
        for tick in range(1, BUDGET_END):
            t = None
            if tick == 10:
                t = rx_buffer([PWM] * 4, [0] * 4, shutdown=SHUTDOWN_MOTOR)
            elif 20 <= tick <= BUDGET_LAST and tick % PERIOD == 0:
                t = budget_transfer(tick // PERIOD - 2)
            f.write(b"\x01" + t if t is not None else b"\x00" + bytes(TRANSFER_LEN))


LINE = re.compile(
    r"tick=(\d+) mode=(\w+) age=(\d+) drive=(\w+) valid=(\d+) rejected=(\d+) refusals=(\d+) "
    r"owners=(\d+) out=(.*)$"
)

# TxBuffer (STM32 → Pi): version, updateTime, MotorData (i32 bemf[4], i32 position[4], u8 done),
# i16 analog[6], i16 battery, u16 digital, ImuData (5 × {f32 x, y, z, i8 accuracy}, f32 quaternion[4],
# f32 heading, f32 temperature), OdometryData (6 × f32).
TX = struct.Struct("<BI4i4iB6hhH" + "fffb" * 5 + "4fff" + "6f")


def check(trace_path, feedback_path):
    lines = []
    for raw in open(trace_path, encoding="utf-8", errors="replace"):
        m = LINE.match(raw.strip())
        if m:
            lines.append((int(m[1]), m[2], int(m[3]), m[4], int(m[5]), int(m[6]), m[9].split()))
    fails = []

    def at(tick):
        """The state in force after `tick` (the last line printed at or before it)."""
        best = None
        for line in lines:
            if line[0] <= tick:
                best = line
        return best

    def expect(cond, what):
        print(("ok   " if cond else "FAIL ") + what)
        if not cond:
            fails.append(what)

    # TIM8's compare of full duty in the emulator build, whose clock tree stays at reset (HSI
    # 16 MHz): 16 MHz / 20 kHz = ARR 799 + 1 (the board: 168 MHz, 8401).
    full = 800
    want = 100 / 399 * full  # 200.5: the Q16.16 duty rounds to either neighbour

    def at_duty(outs, sign="+"):
        return all(o[0] == sign and abs(int(o[1:]) - want) <= 1 for o in outs)
    expect(bool(lines) and lines[0][1] == "Brake", "power-on is BRAKE")
    s = at(15)
    expect(s is not None and s[1] == "Brake", "a shutdown transfer alone does not leave BRAKE")
    s = at(30)
    expect(s is not None and s[3] == "RUN", "the clear transfer after it re-arms: running at tick 30")
    s = at(990)
    expect(s is not None and at_duty(s[6]),
           f"PWM 100 of 399 applied as CCR {want:.1f} ± 1 on every motor (got {s and s[6]})")
    valid_before = s[4] if s else 0
    s = at(1028)
    expect(s is not None and s[5] == 2 and s[3] == "RUN" and at_duty(s[6]),
           "a wrong parity and a wrong version are refused and change nothing (duty stays)")
    # The transfer of tick n is taken after tick n's line (the tick pends the link task); the
    # handler shorts the motors on arrival (INV-21), the next tick's line shows it.
    s = at(SHUTDOWN_AT + 1)
    expect(s is not None and s[0] == SHUTDOWN_AT + 1 and s[3] == "BRAKE" and all(o == "S" for o in s[6]),
           "the shutdown bit of a refused transfer: BRAKE and every motor shorted at the next tick")
    s = at(LAST_VALID - 1)
    expect(s is not None and s[3] == "RUN" and all(o.startswith("-") for o in s[6]),
           "re-armed by a shutdown transfer and a clear one: reverse duty")
    brake = next((line for line in lines if line[0] > LAST_VALID and line[3] == "BRAKE"), None)
    expect(brake is not None and brake[0] - LAST_VALID == 49 and brake[2] == 49,
           f"comm loss: BRAKE at the 49th tick after the last valid transfer (tick {LAST_VALID}), "
           f"strictly within 50 ms (got {brake and (brake[0], brake[2])})")
    expect(valid_before > 0, "transfers were accepted")

    data = open(feedback_path, "rb").read()
    n = len(data) // TRANSFER_LEN
    stamps, bad = [], 0
    for k in range(n):
        rec = data[k * TRANSFER_LEN:(k + 1) * TRANSFER_LEN]
        fields = TX.unpack(rec[:TX.size])
        if fields[0] != VERSION or any(rec[TX.size:]):
            bad += 1
        stamps.append(fields[1])
    expect(TX.size == 167, "the TxBuffer is 167 bytes as the seed's struct packs")
    expect(n > 40 and bad == 0, f"{n} TxBuffers queued, each with version 15 and zero padding ({bad} bad)")
    expect(all(b > a for a, b in zip(stamps, stamps[1:])), "updateTime strictly increases")
    print(f"{len(fails)} failed")
    return 1 if fails else 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["make"]:
        make(sys.argv[2])
    elif sys.argv[1:2] == ["make-budget"]:
        make_budget(sys.argv[2])
    elif sys.argv[1:2] == ["check"]:
        sys.exit(check(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
