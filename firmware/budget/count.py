"""gdb script: counts executed Cortex-M4 instructions per call of the firmware's units under QEMU.


Loaded by run.sh as `gdb-multiarch -batch -x count.py ELF`. For each unit it stops at the entry,
single-steps (`stepi`) until the unit returns, counting the steps (the return instruction included
for functions; for handlers, up to and including the exception return). It also records the
deepest stack pointer seen below the entry SP (the handler's own stack use, excluding the
hardware-stacked exception frame).
"""
import gdb  # noqa: F401  (provided by gdb)
import json
import os

OUT = os.environ["BUDGET_JSON"]
SAMPLES = int(os.environ.get("BUDGET_SAMPLES", "5"))

# name, symbol, kind: "fn" returns to its caller; "isr" returns from the exception.
UNITS = [
    ("frame: on_frame (CRC + decode + validate + ladder step)", "firmware::glue::on_frame", "fn"),
    ("frame: feedback (encode feedback frame)", "firmware::glue::feedback", "fn"),
    ("tick: on_tick (conditions + ladder step)", "firmware::glue::on_tick", "fn"),
    ("current_loop handler (ADC)", "ADC", "isr"),
    ("speed_pid handler (TIM5)", "TIM5", "isr"),
]


def reg(name):
    return int(gdb.parse_and_eval("$" + name)) & 0xFFFFFFFF


def count_call(kind):
    ipsr0 = reg("xpsr") & 0x1FF
    sp0 = reg("sp")
    lr0 = reg("lr") & ~1
    n = 0
    min_sp = sp0
    # QEMU's gdb stub single-steps with interrupts masked, so nothing preempts the unit: a
    # function ends when it returns to its caller, a handler when the core leaves its exception.
    while n < 50000:
        gdb.execute("stepi", to_string=True)
        ipsr = reg("xpsr") & 0x1FF
        if kind == "isr" and ipsr != ipsr0:
            break
        n += 1
        pc = reg("pc")
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
    for title, sym, kind in UNITS:
        bp = gdb.Breakpoint(sym, internal=True)
        counts = []
        stacks = []
        for _ in range(SAMPLES):
            gdb.execute("continue", to_string=True)
            bp.enabled = False
            n, st = count_call(kind)
            bp.enabled = True
            counts.append(n)
            stacks.append(st)
        bp.delete()
        results[title] = {"instructions": counts, "stack_bytes": stacks}
    with open(OUT, "w") as f:
        json.dump(results, f, indent=1)
    gdb.execute("kill")


main()
