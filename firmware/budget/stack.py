#!/usr/bin/env python3
"""Worst-case stack per task of the firmware ELF, from the compiler's frame sizes and the call graph.

Usage: stack.py ELF > stack.md   (ELF built with `-Z emit-stack-sizes`; see stack.sh)

- Frame sizes: the `.stack_sizes` section (LLVM writes, per function, its address and the bytes its
  prologue reserves). Functions without an entry (assembly, and `compiler_builtins`, which is not
  compiled with the flag) get their size from their prologue in the disassembly (`push`, `stmdb sp!`,
  `vpush`, `sub sp`), marked "prologue".
- Call graph: direct calls (`bl`) and branches into another function (tail calls) in the
  `arm-none-eabi-objdump -d` listing. A tail call is counted as a nested call (an over-estimate).
- Indirect calls (`blx rN`, `bx rN` other than `bx lr`) cannot be followed: they are listed per root
  and must be bounded by hand. Recursion is reported (a cycle has no bound).
"""
import re
import subprocess
import sys
import tempfile
import os

ROOTS = [
    # (vector / symbol, task, priority); thread mode first.
    ("main", "init + idle (thread mode)", 0),
    ("TIM2", "watchdog_tick", 2),
    ("DMA1_STREAM3", "spi_dma_done", 2),
    ("TIM5", "speed_pid", 3),
    ("ADC", "current_loop", 4),
    ("HardFault", "HardFault (ends in a breakpoint/reset)", 5),
]
# Hardware exception frame per preemption: 8 words, 26 with the FPU context (lazy stacking reserves
# it when the interrupted code used the FPU), plus 4 bytes of alignment padding.
EXC_FRAME = 26 * 4 + 4


def run(*args):
    return subprocess.run(args, check=True, capture_output=True, text=True).stdout


def uleb(data, i):
    value = shift = 0
    while True:
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if b & 0x80 == 0:
            return value, i


def stack_sizes(elf):
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "ss.bin")
        run("arm-none-eabi-objcopy", "-O", "binary", "--only-section=.stack_sizes",
            "--set-section-flags", ".stack_sizes=alloc", elf, out)
        data = open(out, "rb").read()
    sizes = {}
    i = 0
    while i + 4 <= len(data):
        addr = int.from_bytes(data[i:i + 4], "little") & ~1
        size, i = uleb(data, i + 4)
        sizes[addr] = size
    return sizes


def functions(elf):
    """address → (mangled name, size) of every function symbol."""
    fns = {}
    for line in run("arm-none-eabi-nm", "-S", "--defined-only", elf).splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "Tt":
            addr = int(parts[0], 16) & ~1
            fns.setdefault(addr, (parts[3], int(parts[1], 16)))
    return fns


HEADER = re.compile(r"^([0-9a-f]+) <(.+)>:$")
INSN = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
REGLIST = re.compile(r"\{([^}]*)\}")


def reg_count(regs):
    n = 0
    for part in regs.split(","):
        part = part.strip()
        if "-" in part:
            a, b = part.split("-")
            n += int(b.strip()[1:]) - int(a.strip()[1:]) + 1
        elif part:
            n += 1
    return n


def disassemble(elf):
    """address of function → list of (mnemonic, operands)."""
    body = {}
    cur = None
    for line in run("arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf).splitlines():
        m = HEADER.match(line)
        if m:
            cur = int(m.group(1), 16)
            body[cur] = []
            continue
        m = INSN.match(line)
        if m and cur is not None:
            body[cur].append((m.group(2), m.group(3).split(";")[0].split("@")[0].strip()))
    return body


def prologue_bytes(insns):
    """Stack a function reserves, read from its first instructions (for functions without an entry)."""
    total = 0
    for mnem, ops in insns[:8]:
        if mnem.startswith("push") or (mnem.startswith("stmdb") and ops.startswith("sp!")):
            total += 4 * reg_count(REGLIST.search(ops).group(1))
        elif mnem.startswith("vpush"):
            regs = REGLIST.search(ops).group(1)
            total += (8 if "d" in regs else 4) * reg_count(regs.replace("d", "r").replace("s", "r"))
        elif mnem.startswith("sub") and ops.startswith("sp, "):
            m = re.search(r"#(\d+)", ops)
            if m:
                total += int(m.group(1))
    return total


def main(elf):
    sizes = stack_sizes(elf)
    fns = functions(elf)
    code = disassemble(elf)
    starts = sorted(fns)
    by_name = {}
    for addr, (name, _) in fns.items():
        by_name.setdefault(name, addr)

    def owner(target):
        """The function whose code holds `target` (None outside every function)."""
        lo, hi = 0, len(starts)
        while lo < hi:
            mid = (lo + hi) // 2
            if starts[mid] <= target:
                lo = mid + 1
            else:
                hi = mid
        if lo == 0:
            return None
        a = starts[lo - 1]
        return a if target < a + max(fns[a][1], 2) else None

    frame, source, callees, indirect = {}, {}, {}, {}
    for addr, insns in code.items():
        if addr not in fns:
            continue
        if addr in sizes:
            frame[addr], source[addr] = sizes[addr], "compiler"
        else:
            frame[addr], source[addr] = prologue_bytes(insns), "prologue"
        out, ind = set(), False
        for mnem, ops in insns:
            base = mnem.split(".")[0]
            if base in ("bl", "b", "blx") or re.fullmatch(r"b(eq|ne|cs|cc|hs|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)", base):
                m = re.match(r"([0-9a-f]+)\b", ops)
                if m:
                    t = owner(int(m.group(1), 16))
                    if t is not None and t != addr:
                        out.add(t)
                elif base == "blx":
                    ind = True
            elif base == "bx" and ops != "lr":
                ind = True
            elif base in ("mov", "ldr") and ops.startswith("pc,"):
                ind = True
        callees[addr], indirect[addr] = out, ind

    demangled = {}
    names = [fns[a][0] for a in fns]
    for a, d in zip(names, run("arm-none-eabi-c++filt", *names).splitlines() if names else []):
        demangled[a] = d

    def pretty(addr):
        d = demangled.get(fns[addr][0], fns[addr][0])
        return re.sub(r"::h[0-9a-f]{16}$", "", d)

    memo, cycles = {}, set()

    def worst(addr, path=()):
        """(bytes, deepest call chain, indirect-call sites met) from `addr` down."""
        if addr in path:
            cycles.add(pretty(addr))
            return 0, [], set()
        if addr in memo:
            return memo[addr]
        best, chain, ind = 0, [], set()
        for c in callees.get(addr, ()):
            b, ch, i = worst(c, path + (addr,))
            ind |= i
            if b > best:
                best, chain = b, ch
        if indirect.get(addr):
            ind.add(pretty(addr))
        res = (frame.get(addr, 0) + best, [addr] + chain, ind)
        memo[addr] = res
        return res

    out = ["## Worst-case stack per task\n"]
    out.append("Computed by `firmware/budget/stack.sh` from the board build: per-function frame sizes from")
    out.append("`-Z emit-stack-sizes` (or, marked *prologue*, read from the function's prologue), call graph from")
    out.append("the disassembly (direct calls and tail calls; a tail call counted as nested, an over-estimate).\n")
    out.append("| task | priority | worst-case bytes | deepest chain (bytes per frame) | indirect calls met |")
    out.append("|---|---|---|---|---|")
    per_level = {}
    rows_ind = set()
    missing = []
    for sym, task, prio in ROOTS:
        addr = by_name.get(sym)
        if addr is None:
            missing.append(sym)
            continue
        total, chain, ind = worst(addr)
        rows_ind |= ind
        per_level[prio] = max(per_level.get(prio, 0), total)
        chain_s = " → ".join(
            f"`{pretty(a).split('::')[-1] if len(pretty(a)) > 40 else pretty(a)}` {frame[a]}"
            + ("*" if source[a] == "prologue" else "") for a in chain)
        out.append(f"| {task} (`{sym}`) | {prio} | **{total}** | {chain_s} | {len(ind) or 'none'} |")
    out.append("")
    out.append("\\* frame read from the prologue (no `.stack_sizes` entry).")
    levels = sorted(per_level)
    nested = sum(per_level[p] for p in levels) + EXC_FRAME * (len(levels) - 1)
    out.append("")
    out.append(f"All priority levels nested (thread mode + the worst task of each of the {len(levels) - 1} "
               f"exception levels, each preemption adding a {EXC_FRAME}-byte exception frame with FPU "
               f"context and alignment): **{nested} bytes**. Priority-2 tasks do not preempt each other.")
    out.append("")
    if cycles:
        out.append("Recursion found (no bound computed through it): " + ", ".join(f"`{c}`" for c in sorted(cycles)))
    else:
        out.append("Recursion: none in the call graph.")
    if rows_ind:
        out.append("")
        out.append("Functions with indirect calls reached from a task (their targets are not followed: "
                   "bounded by hand below):")
        for f in sorted(rows_ind):
            out.append(f"- `{f}`")
    if missing:
        out.append("")
        out.append("Roots not found in the ELF: " + ", ".join(missing))
    no_entry = sorted(pretty(a) for a in frame if source[a] == "prologue" and any(
        a in memo.get(by_name.get(s, -1), (0, [], set()))[1] for s, _, _ in ROOTS))
    if no_entry:
        out.append("")
        out.append("On a deepest chain without a `.stack_sizes` entry: " + ", ".join(f"`{n}`" for n in no_entry))
    print("\n".join(out))


if __name__ == "__main__":
    main(sys.argv[1])
