#!/usr/bin/env python3
"""Worst-case stack per task of the firmware ELF, from the compiler's frame sizes and the call graph.

Usage: stack.py ELF [PROFILE] > stack.md   (ELF built with `-Z emit-stack-sizes`, see stack.sh; PROFILE
names the image's tasks: amr-spi (the default), cdc, teensy or pi-spi)

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

# Per image: (vector / symbol, task, priority); thread mode first. Priorities are RTIC's (higher
# preempts lower); the fault handlers' negative numbers only order them above every task.
THREAD = [("main", "init + idle (thread mode)", 0)]
FAULTS = [
    ("NonMaskableInt", "NMI handler (clock security system)", -2),
    ("HardFault", "HardFault handler", -1),
]
ROOTS_BY_PROFILE = {
    "amr-spi": THREAD + [
        ("TIM2", "watchdog_tick", 2),
        ("DMA1_STREAM3", "spi_dma_done", 2),
        ("EXTI15_10", "spi_nss_rise", 2),
        ("TIM5", "speed_pid", 3),
        ("ADC", "current_loop", 4),
        ("EXTI4", "estop_input", 5),
    ] + FAULTS,
    "cdc": THREAD + [
        ("TIM3", "imu_read", 1),
        ("TIM2", "watchdog_tick", 2),
        ("USART1", "link_usart", 2),
        ("EXTI4", "estop_input", 5),
    ] + FAULTS,
    "teensy": THREAD + [
        ("TIM2", "watchdog_tick", 2),
        ("USART1", "link_usart", 2),
        ("TIM5", "step_gen", 3),
        ("EXTI4", "estop_input", 5),
    ] + FAULTS,
    # Seed 004. The emulator-only emu_tick (SysTick) is not in the board build.
    "pi-spi": THREAD + [
        ("UART4", "imu_read", 1),
        ("DMA1_STREAM3", "spi_dma_done", 2),
        ("EXTI15_10", "spi_nss_rise", 2),
        ("TIM7", "watchdog_tick", 2),
        ("EXTI4", "estop_input", 5),
    ] + FAULTS,
}
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
    """address → (mangled name, size) of every function symbol, and name → address of every alias."""
    fns, names = {}, {}
    for line in run("arm-none-eabi-nm", "-S", "--defined-only", elf).splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "Tt":
            addr = int(parts[0], 16) & ~1
            fns.setdefault(addr, (parts[3], int(parts[1], 16)))
            names.setdefault(parts[3], addr)
        elif len(parts) == 3 and parts[1] in "Tt":  # an alias without a size (HardFault)
            names.setdefault(parts[2], int(parts[0], 16) & ~1)
    return fns, names


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


def main(elf, profile="amr-spi"):
    roots = ROOTS_BY_PROFILE[profile]
    # RTIC task priorities (the rest are thread mode and the fault handlers).
    task_priorities = {p for _, _, p in roots if p > 0}
    sizes = stack_sizes(elf)
    fns, by_name = functions(elf)
    code = disassemble(elf)
    starts = sorted(fns)

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

    frame, source, callees, indirect, resolved = {}, {}, {}, {}, {}
    for addr, insns in code.items():
        if addr not in fns:
            continue
        if addr in sizes:
            frame[addr], source[addr] = sizes[addr], "compiler"
        else:
            frame[addr], source[addr] = prologue_bytes(insns), "prologue"
        out, ind, taken, movw = set(), False, set(), {}
        for mnem, ops in insns:
            base = mnem.split(".")[0]
            # Function addresses built in a register (movw/movt, Thumb bit set): the targets of
            # this function's indirect calls when it picks one of a few functions (defmt-rtt does).
            m = re.match(r"(r\d+|ip|lr|sl|fp), #(\d+)", ops)
            if m and base == "movw":
                movw[m.group(1)] = int(m.group(2))
            elif m and base == "movt" and m.group(1) in movw:
                value = (int(m.group(2)) << 16) | movw[m.group(1)]
                if value & 1 and (value & ~1) in fns:
                    taken.add(value & ~1)
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
        if ind and taken:
            out |= taken
            resolved[addr] = taken
        callees[addr], indirect[addr] = out, ind

    demangled = {}
    names = [fns[a][0] for a in fns]
    for a, d in zip(names, run("arm-none-eabi-c++filt", *names).splitlines() if names else []):
        demangled[a] = d

    def pretty(addr):
        d = demangled.get(fns[addr][0], fns[addr][0])
        d = re.sub(r"::h[0-9a-f]{16}$", "", d)
        d = re.sub(r"\[[0-9a-f]{16}\]", "", d)
        # `<Type>::method` (an inherent method) → `Type::method`.
        return re.sub(r"^<([^<> ]*)>::", r"\1::", d)

    def brief(addr):
        """The last two path segments of the name, without generic arguments."""
        depth, flat = 0, []
        for ch in pretty(addr):
            depth += ch == "<"
            if depth == 0:
                flat.append(ch)
            depth -= ch == ">" and depth > 0
        parts = [p for p in "".join(flat).split("::") if p]
        return "::".join(parts[-2:])

    panics = {a for a in fns if pretty(a).startswith("core::panicking::")}

    class Graph:
        """Worst-case stack from each function down, optionally without the panic paths (calls
        into `core::panicking`)."""

        def __init__(self, cut=frozenset()):
            self.cut, self.memo, self.cycles = cut, {}, set()

        def worst(self, addr, path=()):
            """(bytes, deepest call chain, indirect-call sites met) from `addr` down."""
            if addr in path:
                self.cycles.add(pretty(addr))
                return 0, [], set()
            if addr in self.memo:
                return self.memo[addr]
            best, chain, ind = 0, [], set()
            for c in callees.get(addr, ()):
                if c in self.cut:
                    continue
                b, ch, i = self.worst(c, path + (addr,))
                ind |= i
                if b > best:
                    best, chain = b, ch
            if indirect.get(addr):
                ind.add(addr)
            res = (frame.get(addr, 0) + best, [addr] + chain, ind)
            self.memo[addr] = res
            return res

        def reach(self, root):
            seen, todo = set(), [root]
            while todo:
                a = todo.pop()
                if a not in seen and a not in self.cut:
                    seen.add(a)
                    todo.extend(callees.get(a, ()))
            return seen

    full, safe = Graph(), Graph(frozenset(panics))

    def chain_text(chain):
        return " → ".join(
            f"`{brief(a)}` {frame[a]}" + ("*" if source[a] == "prologue" else "") for a in chain)

    if profile == "amr-spi":
        out = ["## Worst-case stack per task\n"]
        out.append("Computed by `firmware/budget/stack.sh` from the board build (the pinned compiler, `cargo fw`'s")
        out.append("profile, plus `-Z emit-stack-sizes` allowed by `RUSTC_BOOTSTRAP=1`): per-function frame sizes")
        out.append("from the `.stack_sizes` section (or, marked *prologue*, read from the function's prologue), call")
        out.append("graph from the disassembly (direct calls and tail calls; a tail call counted as nested, an")
        out.append("over-estimate). *Without panics* leaves out every call into `core::panicking` (a panic resets")
        out.append("the MCU; see below); *with panics* follows them once around the panic handler.\n")
    else:
        out = ["### Worst-case stack per task\n"]
        out.append(f"Computed as for `amr-spi` above, from the `{profile}` board image.\n")
    out.append("| task | priority | worst-case bytes without panics | deepest chain (bytes per frame) | "
               "with panics | indirect calls met |")
    out.append("|---|---|---|---|---|---|")
    per_level = {}
    rows_ind = set()
    missing = []
    for sym, task, prio in roots:
        addr = by_name.get(sym)
        if addr is None:
            missing.append(sym)
            continue
        total, chain, ind = safe.worst(addr)
        total_p, chain_p, ind_p = full.worst(addr)
        rows_ind |= ind_p
        per_level[prio] = max(per_level.get(prio, 0), total)
        with_p = "same" if total_p == total else f"{total_p}: {chain_text(chain_p)}"
        out.append(f"| {task} (`{sym}`) | {prio} | **{total}** | {chain_text(chain)} | {with_p} | "
                   f"{len(ind_p) or 'none'} |")
    out.append("")
    out.append("\\* frame read from the prologue (no `.stack_sizes` entry).")
    levels = sorted(per_level)
    nested = sum(per_level[p] for p in levels) + EXC_FRAME * (len(levels) - 1)
    out.append("")
    out.append(f"All priority levels nested, without panics (thread mode + the worst task of each of the "
               f"{len(levels) - 1} exception levels, each preemption adding a {EXC_FRAME}-byte exception "
               f"frame with FPU context and alignment): **{nested} bytes**. Tasks of one priority do not "
               f"preempt each other.")
    out.append("")
    if full.cycles:
        out.append("Recursion found (no bound computed through it): " + ", ".join(f"`{c}`" for c in sorted(full.cycles)))
    else:
        out.append("Recursion: none in the call graph.")
    if rows_ind:
        out.append("")
        out.append("Functions with indirect calls (`blx rN`) reached from a root:")
        for a in sorted(rows_ind, key=pretty):
            if a in resolved:
                targets = ", ".join(f"`{brief(t)}`" for t in sorted(resolved[a], key=pretty))
                out.append(f"- `{pretty(a)}`: targets taken as the function addresses it builds "
                           f"(movw/movt): {targets} (included above)")
            else:
                out.append(f"- `{pretty(a)}`: targets not followed, bounded by hand")

    def unresolved(r):
        return any(indirect.get(a) and a not in resolved for a in r)

    out.append("")
    out.append("| root | reaches a panic | reaches a cycle | reaches an unresolved indirect call | "
               "same without panics: cycle / unresolved call |")
    out.append("|---|---|---|---|---|")
    cycle_addrs = {a for a in fns if pretty(a) in full.cycles}
    safe_cycles = {a for a in fns if pretty(a) in safe.cycles}
    clean_tasks = True
    panicking_tasks = []
    for sym, task, prio in roots:
        if sym not in by_name:
            continue
        r, rs = full.reach(by_name[sym]), safe.reach(by_name[sym])
        flags = [bool(r & panics), bool(r & cycle_addrs), unresolved(r)]
        safe_flags = [bool(rs & safe_cycles), unresolved(rs)]
        if prio in task_priorities:
            clean_tasks &= not any(safe_flags)
            if flags[0]:
                panicking_tasks.append(sym)
        out.append(f"| `{sym}` | " + " | ".join("yes" if f else "no" for f in flags) + " | "
                   + " / ".join("yes" if f else "no" for f in safe_flags) + " |")
    # Where the tasks' paths reach a panic: the callers of `core::panicking` reached from a task.
    task_reach = set()
    for sym, _, prio in roots:
        if prio in task_priorities and sym in by_name:
            task_reach |= safe.reach(by_name[sym])
    sites = sorted({brief(a) for a in task_reach if callees.get(a, set()) & panics})
    out.append("")
    if full.cycles and not safe.cycles:
        out.append("Every recursion found passes through the panic handler (none is left without the")
        out.append("calls into `core::panicking`). The handler brakes the bridges, then logs with")
        out.append("`defmt::error!`: a panic raised while the defmt logger is held (inside a `defmt` call)")
        out.append("makes that log panic again (`_defmt_acquire`: logger taken re-entrantly), so the")
        out.append("handler recurses until the stack runs out (flip-link: a fault at the bottom of RAM,")
        out.append("then the IWDG reset); the bridges are braked from the first pass. The *with panics*")
        out.append("figures count one pass and are not bounds.")
    elif safe.cycles:
        out.append("CHECK: a recursion outside the panic path: " + ", ".join(f"`{c}`" for c in sorted(safe.cycles))
                   + "; bound it by hand.")
    if panicking_tasks:
        out.append("Tasks that reach a panic: " + ", ".join(f"`{t}`" for t in panicking_tasks)
                   + "; the calls into `core::panicking` on their paths are in " + ", ".join(f"`{s}`" for s in sites)
                   + ".")
    if clean_tasks:
        out.append(f"Without panics the {len([r for r in roots if r[2] in task_priorities])} tasks reach no cycle "
                   "and no unresolved indirect call (table above), so those figures are complete bounds.")
    else:
        out.append("A TASK REACHES A CYCLE OR AN UNRESOLVED INDIRECT CALL WITHOUT PANICS (table above): its "
                   "figure is not a complete bound.")
    if missing:
        out.append("")
        out.append("Roots not found in the ELF: " + ", ".join(missing))
    on_chains = set()
    for g in (safe, full):
        for sym, _, _ in roots:
            if sym in by_name and by_name[sym] in g.memo:
                on_chains |= set(g.memo[by_name[sym]][1])
    no_entry = sorted(pretty(a) for a in on_chains if source.get(a) == "prologue")
    if no_entry:
        out.append("")
        out.append("On a deepest chain without a `.stack_sizes` entry: " + ", ".join(f"`{n}`" for n in no_entry))
    print("\n".join(out))


if __name__ == "__main__":
    main(*sys.argv[1:3])
