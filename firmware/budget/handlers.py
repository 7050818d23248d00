#!/usr/bin/env python3
"""Static facts about the RTIC handlers of firmware ELFs, for the load estimate in BUDGET.md.

Usage: handlers.py LABEL=ELF [LABEL=ELF ...] > handlers.json

Per handler symbol: its instructions (in the `arm-none-eabi-objdump -d` listing), whether it is
loop-free (no branch back inside its own code: then every instruction runs at most once per call,
so the count bounds the handler's own code), and the functions it calls directly. The `qemu` build's
handlers hold the emulator's link and hooks instead of the board's registers; report.py uses these
facts to put the board build's handler code in place of the emulator's.
"""
import json
import re
import subprocess
import sys

# Every image's (those an image lacks are left out of its facts).
HANDLERS = ("ADC", "TIM5", "TIM2", "DMA1_STREAM3", "EXTI15_10", "EXTI4", "USART1", "TIM3", "TIM7", "UART4")
HEADER = re.compile(r"^([0-9a-f]+) <(.+)>:$")
INSN = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
TARGET = re.compile(r"^([0-9a-f]+) <([^>+]+)(\+0x[0-9a-f]+)?>")
BRANCH = re.compile(r"^(b|bl|cbn?z)(eq|ne|cs|cc|hs|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le|al)?(\.[nw])?$")


def facts(elf):
    listing = subprocess.run(["arm-none-eabi-objdump", "-d", "-C", "--no-show-raw-insn", elf],
                             check=True, capture_output=True, text=True).stdout
    out, cur = {}, None
    for line in listing.splitlines():
        m = HEADER.match(line)
        if m:
            cur = m.group(2) if m.group(2) in HANDLERS else None
            if cur:
                out[cur] = {"start": int(m.group(1), 16), "insns": []}
            continue
        m = INSN.match(line)
        if m and cur:
            out[cur]["insns"].append((int(m.group(1), 16), m.group(2), m.group(3)))
    res = {}
    for name, f in out.items():
        insns = f["insns"]
        back, calls = [], set()
        for addr, mnem, ops in insns:
            b = BRANCH.match(mnem)
            t = TARGET.match(ops.split(", ")[-1]) if b else None
            if not t:
                continue
            target = int(t.group(1), 16)
            inside = t.group(2) == name
            if b.group(1) == "bl" or not inside:
                calls.add(re.sub(r"::h[0-9a-f]{16}$", "", t.group(2)))
            elif target <= addr:
                back.append(hex(addr))
        res[name] = {"instructions": len(insns), "loop_free": not back, "calls": sorted(calls)}
    return res


def main(args):
    print(json.dumps({label: facts(elf) for label, elf in (a.split("=", 1) for a in args)}, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
