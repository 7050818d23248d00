#!/usr/bin/env python3
"""The seed's bridge timing: a loop paced by time.sleep(0.001), measured like `motorlink loop-bench`.

Each cycle does comparable work (inverse kinematics, pack a 64-byte frame, CRC-16/CCITT over it)
and then sleeps 1 ms, as a rclpy timer callback followed by a relative sleep would. Periods outside
1 ms +- 0.2 ms are deadline misses.

    python3 host/scripts/seed_loop.py [seconds]
"""
import json
import struct
import sys
import time


def crc16_ccitt(data):
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 60.0
    wheelbase, radius = 0.40, 0.08
    v, omega = 1.0, 0.2
    periods = []
    end = time.monotonic() + seconds
    prev = None
    while True:
        now = time.monotonic()
        if now >= end:
            break
        if prev is not None:
            periods.append((now - prev) * 1e6)
        prev = now
        wl = (v - omega * wheelbase / 2) / radius
        wr = (v + omega * wheelbase / 2) / radius
        body = struct.pack("<Iffbb", int(now * 1e6) & 0xFFFFFFFF, wl, wr, 1, 1).ljust(62, b"\0")
        frame = body + struct.pack(">H", crc16_ccitt(body))
        assert len(frame) == 64
        time.sleep(0.001)
    n = len(periods)
    misses = sum(1 for p in periods if p < 800.0 or p > 1200.0)
    mean = sum(periods) / n
    std = (sum((p - mean) ** 2 for p in periods) / n) ** 0.5
    print(f"periods {n} | mean {mean:.1f} us | std {std:.1f} us | min {min(periods):.1f} us | "
          f"max {max(periods):.1f} us | outside 1000+-200 us: {misses} ({100.0 * misses / n:.4f} %)")
    print(json.dumps({"impl": "python-sleep-0.001", "seconds": seconds, "periods": n, "misses": misses,
                      "miss_rate": misses / n, "mean_us": mean, "std_us": std,
                      "min_us": min(periods), "max_us": max(periods)}))


if __name__ == "__main__":
    main()
