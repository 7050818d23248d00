"""gdb script: counts executed Cortex-M4 instructions per call of the firmware's units under QEMU.


Loaded by run.sh as `gdb-multiarch -batch -x count.py ELF`. For each unit it stops at its first
instruction, single-steps (`stepi`) until the unit returns, counting the steps (the return instruction included
for functions; for handlers, up to and including the exception return). It also records the
deepest stack pointer seen below the entry SP (the handler's own stack use, excluding the
hardware-stacked exception frame).
"""
import gdb  # noqa: F401  (provided by gdb)
import json
import os
import re

OUT = os.environ["BUDGET_JSON"]
SAMPLES = int(os.environ.get("BUDGET_SAMPLES", "5"))

# name, symbol, kind: "fn" returns to its caller; "isr" returns from the exception.
UNITS = [
    ("frame: receive (CRC + decode + validate + ladder step)", "mcu::link::LinkTask::receive", "fn"),
    ("frame: feedback (encode feedback frame)", "mcu::link::LinkTask::feedback", "fn"),
    ("tick: run (conditions + ladder step)", "mcu::tick::TickTask::run", "fn"),
    ("current_loop handler (ADC)", "ADC", "isr"),
    ("speed_pid handler (TIM5)", "TIM5", "isr"),
]


def reg(name):
    return int(gdb.parse_and_eval("$" + name)) & 0xFFFFFFFF


def function_at(pc, cache={}):
    """The innermost function (inlined ones included) whose code holds `pc`, by the debug info."""
    if pc not in cache:
        name = "?"
        try:
            block = gdb.block_for_pc(pc)
            while block is not None and block.function is None:
                block = block.superblock
            if block is not None:
                name = block.function.print_name
        except RuntimeError:
            pass
        cache[pc] = name
    return cache[pc]


def count_call(kind, profile=None):
    ipsr0 = reg("xpsr") & 0x1FF
    sp0 = reg("sp")
    lr0 = reg("lr") & ~1
    n = 0
    min_sp = sp0
    executed = reg("pc")  # the instruction the next step executes
    # QEMU's gdb stub single-steps with interrupts masked, so nothing preempts the unit: a
    # function ends when it returns to its caller, a handler when the core leaves its exception.
    while n < 50000:
        gdb.execute("stepi", to_string=True)
        ipsr = reg("xpsr") & 0x1FF
        if kind == "isr" and ipsr != ipsr0:
            break
        n += 1
        if profile is not None:
            profile[executed] = profile.get(executed, 0) + 1
        pc = reg("pc")
        executed = pc
        sp = reg("sp")
        min_sp = min(min_sp, sp)
        if kind == "fn" and pc == lr0 and sp >= sp0:
            break
    return n, sp0 - min_sp


def main():
    gdb.execute("set pagination off")
    gdb.execute("set confirm off")
    gdb.execute("target remote :" + os.environ.get("GDB_PORT", "3333"))
    results = {}
    # BUDGET_ONLY=on_frame counts only the units whose symbol contains that text (for quick looks).
    only = os.environ.get("BUDGET_ONLY", "")
    for title, sym, kind in UNITS:
        if only not in sym:
            continue
        # At the unit's first instruction (`*address`), not after the prologue where gdb puts a
        # breakpoint on a name: the prologue may already use `lr` as a scratch register, and the
        # return address is read from `lr` at the stop.
        info = gdb.execute("info address " + sym, to_string=True)
        address = int(re.search(r"at (?:address )?(0x[0-9a-fA-F]+)", info).group(1), 16) & ~1
        bp = gdb.Breakpoint("*" + hex(address), internal=True)
        counts = []
        stacks = []
        pcs = {}
        for _ in range(SAMPLES):
            gdb.execute("continue", to_string=True)
            bp.enabled = False
            n, st = count_call(kind, pcs)
            bp.enabled = True
            counts.append(n)
            stacks.append(st)
        bp.delete()
        # Instructions per function (inlined code counted in the inlined function), per call on average.
        by_fn = {}
        for pc, k in pcs.items():
            f = function_at(pc)
            by_fn[f] = by_fn.get(f, 0) + k
        profile = {f: round(k / SAMPLES) for f, k in sorted(by_fn.items(), key=lambda x: -x[1])}
        results[title] = {"instructions": counts, "stack_bytes": stacks, "by_function": profile}
    with open(OUT, "w") as f:
        json.dump(results, f, indent=1)
    gdb.execute("kill")


main()
