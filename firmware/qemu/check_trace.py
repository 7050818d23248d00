#!/usr/bin/env python3
"""Checks the emulator trace (one line per watchdog tick, printed by the firmware itself)."""
import re
import sys

from make_frames import crc16_ccitt_false  # the same wire description, written once

LINE = re.compile(
    r"tick=(\d+) mode=(\w+) age=(\d+) drive=(\w+) left=(\S+) right=(\S+) valid=(\d+) rejected=(\d+) "
    r"faults=0x([0-9a-fA-F]+)"
)


MODES = ["Normal", "Reduced", "Hold", "Stop", "Brake"]


def decode_feedback(frame: bytes) -> dict:
    """Decodes a MotorFeedback frame from the wire description (protobuf wire types), not the Rust code."""
    assert len(frame) == 64
    if crc16_ccitt_false(frame[:62]) != int.from_bytes(frame[62:], "big"):
        raise ValueError("CRC")
    n = frame[0]
    p, i, out = frame[1:1 + n], 0, {}
    names = {1: "timestamp_us", 8: "fault_flags", 10: "seq", 11: "mode", 12: "cmd_seq", 13: "version",
             16: "info_version", 17: "fw_version", 18: "git_hash", 19: "board", 20: "build_date",
             21: "reset_cause", 22: "reset_count", 23: "panic_line", 24: "info_seq", 25: "dirty"}
    while i < len(p):
        key, i = varint(p, i)
        field, wt = key >> 3, key & 7
        if wt == 0:
            v, i = varint(p, i)
        elif wt == 5:
            v, i = int.from_bytes(p[i:i + 4], "little"), i + 4
        else:
            raise ValueError(f"wire type {wt}")
        if field in names:
            out[names[field]] = v
    for k in names.values():
        out.setdefault(k, 0)
    return out


def varint(b: bytes, i: int):
    v, shift = 0, 0
    while True:
        c = b[i]
        i += 1
        v |= (c & 0x7F) << shift
        shift += 7
        if not c & 0x80:
            return v, i


def check_feedback(path: str, rows: list, git_hash: str, tags: list) -> list:
    fails = []
    data = open(path, "rb").read()
    frames = [data[k:k + 64] for k in range(0, len(data) - 63, 64)]
    fbs, infos = [], []
    for k, f in enumerate(frames):
        try:
            d = decode_feedback(f)
        except (ValueError, IndexError) as e:
            fails.append(f"feedback frame {k} does not decode: {e}")
            continue
        if d["info_version"]:
            infos.append((k, d))
        else:
            fbs.append(d)
    # The identity answers the first command (which asked for it) in the very next slot: frame 0
    # is the one written after the first transaction. It takes that slot's sequence number.
    if [k for k, _ in infos] != [0]:
        fails.append(f"identity frames at slots {[k for k, _ in infos]}, expected exactly slot 0")
    else:
        info = infos[0][1]
        want = {"info_version": 1, "fw_version": 0x000100, "board": 0, "info_seq": 1}
        for k, v in want.items():
            if info[k] != v:
                fails.append(f"identity {k} = {info[k]}, expected {v}")
        if git_hash and info["git_hash"] != int(git_hash[:8], 16):
            fails.append(f"identity git hash {info['git_hash']:08x}, expected {git_hash[:8]}")
        if not 20200101 <= info["build_date"] <= 29991231:
            fails.append(f"identity build date {info['build_date']}")
        # QEMU does not model the RCC: no reset flag is set, so the cause is Unknown (0).
        if info["reset_cause"] != 0 or info["reset_count"] != 0:
            fails.append(f"reset cause {info['reset_cause']} count {info['reset_count']}, expected 0/0")
        if fbs and fbs[0]["seq"] != 2:
            fails.append(f"first feedback after the identity has seq {fbs[0]['seq']}, expected 2")
    if len(fbs) < 40:
        return fails + [f"only {len(fbs)} feedback frames"]
    for a, b in zip(fbs, fbs[1:]):
        if b["seq"] != a["seq"] + 1:
            fails.append(f"feedback seq {a['seq']} then {b['seq']}")
            break
        # One transaction per tick: the MCU's own clock advances by one tick, 1000 µs.
        if b["timestamp_us"] - a["timestamp_us"] != 1000:
            fails.append(f"timestamps {a['timestamp_us']} then {b['timestamp_us']} µs")
            break
    if any(f["version"] != 1 for f in fbs):
        fails.append("feedback without protocol_version 1")
    # Each feedback frame is written by the link task the tick pends, right after that tick's trace
    # line, and reports the ladder after the frame it answers. Transactions happen only at ticks
    # whose frames.bin record has tag 1, so slot j belongs to the j-th such tick. A frame changes
    # the rung or the flags only when the ladder refuses or accepts it (a refused frame can degrade
    # the link, an accepted one can arm), so the two agree except at most at the one corrupted frame.
    by_tick = {r["tick"]: r for r in rows}
    slots = [k + 1 for k, tag in enumerate(tags) if tag == 1]
    frames_fb = [None] + fbs  # slot 0 is the identity
    compared, mismatched = 0, []
    for slot, tick in enumerate(slots):
        if slot == 0 or slot >= len(frames_fb) or tick not in by_tick:
            continue
        fb, row = frames_fb[slot], by_tick[tick]
        compared += 1
        if MODES[fb["mode"]] != row["mode"] or fb["fault_flags"] != row["faults"]:
            mismatched.append((tick, MODES[fb["mode"]], row["mode"], hex(fb["fault_flags"]), hex(row["faults"])))
    if compared < 40:
        fails.append(f"only {compared} feedback frames matched to trace lines")
    if len(mismatched) > 1:
        fails.append(f"feedback mode/flags differ from the trace at {len(mismatched)} ticks: {mismatched[:5]}")
    if not any(MODES[f["mode"]] == "Brake" and f["fault_flags"] & 0x0200 for f in fbs):
        fails.append("feedback never reported BRAKE latched")
    if not any(MODES[f["mode"]] in ("Normal", "Reduced") for f in fbs):
        fails.append("feedback never reported a driving mode")
    return fails


def main(path: str, feedback: str, frames: str, git_hash: str) -> int:
    raw = open(frames, "rb").read()
    tags = [raw[k] for k in range(0, len(raw), 65)]
    rows = []
    for line in open(path, encoding="utf-8", errors="replace"):
        m = LINE.search(line)
        if m:
            t, mode, age, drive, left, right, valid, rej, faults = m.groups()
            rows.append(dict(tick=int(t), mode=mode, age=int(age), drive=drive, faults=int(faults, 16),
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
    # 3. Comm loss: BRAKE exactly at the 9th tick after the last valid frame, not before (seed 000's
    #    profile, SAFETY.md SR-16). t1 is the first tick after that frame (age 1), so the 9th is
    #    t1 + 8, with age 9: the frame arrived less than one tick before t1, so BRAKE is strictly
    #    within 9 + 1 = 10 ticks (10 ms) of its arrival.
    last_valid = max((r for r in rows if r["valid"] == rows[-1]["valid"]), key=lambda r: -r["tick"])
    t1 = last_valid["tick"]  # first tick that saw the final valid count
    after = [r for r in rows if r["tick"] >= t1]
    brake_at = next((r for r in after if r["mode"] == "Brake"), None)
    if brake_at is None:
        fails.append("no BRAKE after the link stopped")
    else:
        if brake_at["tick"] - t1 != 8 or brake_at["age"] != 9 or brake_at["drive"] != "BRAKE":
            fails.append(f"BRAKE at tick {brake_at['tick']} (age {brake_at['age']}), "
                         f"expected tick {t1 + 8} with age 9")
        if brake_at["tick"] - t1 + 1 >= 10:
            fails.append(f"BRAKE {brake_at['tick'] - t1 + 1} ticks after the last frame: not within 10 ms")
        modes = [r["mode"] for r in after if r["tick"] < brake_at["tick"]]
        if "Hold" not in modes or "Stop" not in modes:
            fails.append(f"ladder skipped HOLD/STOP on the way down: {modes}")
    fails += check_feedback(feedback, rows, git_hash, tags)
    for f in fails:
        print("FAIL:", f)
    if fails:
        return 1
    print(f"qemu: {len(rows)} ticks traced; frames applied; corrupted frame rejected without effect; "
          f"BRAKE at tick {brake_at['tick']}, the 9th tick after the last valid frame (within 10 ms of it); "
          f"feedback frames decode with µs time stamps 1000 apart and consecutive sequence numbers; "
          f"mode and fault flags as traced; the identity answers the request in the next slot")
    print("5 passed, 0 failed")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4] if len(sys.argv) > 4 else ""))
