#!/usr/bin/env python3
"""Checks the emulator trace (one line per watchdog tick, printed by the firmware itself)."""
import re
import sys

LINE = re.compile(
    r"tick=(\d+) mode=(\w+) age=(\d+) drive=(\w+) left=(\S+) right=(\S+) valid=(\d+) rejected=(\d+)"
)


def main(path: str) -> int:
    rows = []
    for line in open(path, encoding="utf-8", errors="replace"):
        m = LINE.search(line)
        if m:
            t, mode, age, drive, left, right, valid, rej = m.groups()
            rows.append(dict(tick=int(t), mode=mode, age=int(age), drive=drive,
                             left=float(left), right=float(right), valid=int(valid), rejected=int(rej)))
    fails = []
    if len(rows) < 30:
        fails.append(f"only {len(rows)} trace lines")
    # 1. Frames are applied: the setpoints reach the commanded 1.0 / -0.5 rad/s while running.
    if not any(r["drive"] == "RUN" and r["left"] == 1.0 and r["right"] == -0.5 for r in rows):
        fails.append("commanded speeds 1.0/-0.5 never applied")
    # 2. The corrupted frame is counted and changes nothing.
    for prev, cur in zip(rows, rows[1:]):
        if cur["rejected"] > prev["rejected"]:
            if (cur["left"], cur["right"], cur["drive"]) != (prev["left"], prev["right"], prev["drive"]):
                fails.append(f"rejected frame changed the output at tick {cur['tick']}")
            break
    else:
        fails.append("the corrupted frame was not rejected")
    # 3. Comm loss: BRAKE exactly at the 10th tick after the last valid frame, not before.
    #    t1 is the first tick after that frame (age 1), so the 10th is t1 + 9, with age 10.
    last_valid = max((r for r in rows if r["valid"] == rows[-1]["valid"]), key=lambda r: -r["tick"])
    t1 = last_valid["tick"]  # first tick that saw the final valid count
    after = [r for r in rows if r["tick"] >= t1]
    brake_at = next((r for r in after if r["mode"] == "Brake"), None)
    if brake_at is None:
        fails.append("no BRAKE after the link stopped")
    else:
        if brake_at["tick"] - t1 != 9 or brake_at["age"] != 10 or brake_at["drive"] != "BRAKE":
            fails.append(f"BRAKE at tick {brake_at['tick']} (age {brake_at['age']}), "
                         f"expected tick {t1 + 9} with age 10")
        modes = [r["mode"] for r in after if r["tick"] < brake_at["tick"]]
        if "Hold" not in modes or "Stop" not in modes:
            fails.append(f"ladder skipped HOLD/STOP on the way down: {modes}")
    for f in fails:
        print("FAIL:", f)
    if fails:
        return 1
    print(f"qemu: {len(rows)} ticks traced; frames applied; corrupted frame rejected without effect; "
          f"BRAKE at tick {brake_at['tick']}, the 10th tick after the last valid frame")
    print("3 passed, 0 failed")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
