#!/usr/bin/env python3
"""Turns the size listing, the instruction counts, the stack analysis and the handler facts into
firmware/BUDGET.md.

Usage: report.py SIZE_TXT COUNTS_JSON STACK_MD HANDLERS_JSON > BUDGET.md
(arm-none-eabi-size -A output, count.py's JSON, stack.py's Markdown, handlers.py's JSON).
"""
import json
import sys

F_CPU = 168e6
# Cycles per instruction assumed for the load estimate: Cortex-M4 executes most instructions in
# one cycle; loads/stores, branches and multiplies take 2-3, flash wait states (5 at 168 MHz) are
# mostly hidden by the ART accelerator. 2.0 is a deliberately pessimistic average.
CPI = 2.0

RECEIVE = "frame: receive (CRC + decode + validate + ladder step)"
FEEDBACK = "frame: feedback (encode feedback frame)"
TICK = "tick: run (conditions + ladder step)"
TRACE = "trace: one record (ring entry + defmt log line)"
RECEIVE_TARGET = 1000

# The RTIC tasks: task, interrupt symbol, priority, rate in Hz (None: on an event, not periodic),
# what triggers it. Rates are the board's (firmware/src/board/mod.rs).
TASKS = [
    ("estop_input", "EXTI4", 5, None, "ESTOP input edge (PD4)"),
    ("current_loop", "ADC", 4, 20_000, "ADC injected conversion, TIM1_CC4"),
    ("speed_pid", "TIM5", 3, 10_000, "TIM5 update"),
    ("watchdog_tick", "TIM2", 2, 1_000, "TIM2 update"),
    ("spi_dma_done", "DMA1_STREAM3", 2, 1_000, "SPI2 RX DMA transfer complete, one per host transaction"),
    ("spi_nss_rise", "EXTI15_10", 2, 1_000, "NSS rising edge (PB12), one per host transaction"),
]
# Board-application bodies to show inside their handlers (inclusive counts: code inlined into them
# and the functions they call).
BODIES = [
    "mcu::estop::EstopInput::edge",
    "mcu::current::CurrentLoop::run",
    "mcu::speed::SpeedLoop::run",
    "mcu::tick::TickTask::run",
    "mcu::tick::TickOutcome::drive",
    "mcu::estop::EstopInput::poll",
    "mcu::link::LinkTask::on_frame",
    "mcu::link::LinkTask::receive",
    "mcu::link::LinkTask::feedback",
]


def short(name):
    """A function name without its generic arguments (`any<u8, …>` → `any`)."""
    out, depth = [], 0
    for ch in name:
        if ch == "<":
            depth += 1
        elif ch == ">" and depth > 0:
            depth -= 1
        elif depth == 0:
            out.append(ch)
    return "".join(out)


def sizes(path):
    sec = {}
    for line in open(path):
        parts = line.split()
        if len(parts) >= 3 and parts[0].startswith("."):
            sec[parts[0]] = int(parts[1])
    flash = sum(sec.get(s, 0) for s in (".vector_table", ".text", ".rodata", ".data"))
    ram = sum(sec.get(s, 0) for s in (".data", ".bss", ".uninit"))
    return sec, flash, ram


# Per-frame instruction counts before and after the receive-path work (same frames, same method),
# each step measured with this script's counting.
HISTORY = [
    "Per-frame history (max over the same sampled frames): 1,896 (crc crate `Table<1>`, generic",
    "varint loop, bytewise padding check) → 1,339 (crc `Table<16>`, padding a word at a time) →",
    "1,153 (one-byte varints inlined) → 1,073 (own slice-by-16 tables, remainder in 8/4/2-byte",
    "blocks) → 1,027 (long varints out of line, reader kept in registers) → 1,032 (counted from the",
    "unit's first instruction, see below) → 1,062 (the task bodies moved into the `mcu` crate, see",
    "below). Measured and set aside: entering a well-framed frame's zero padding into the CRC by an",
    "exact zero-extension step instead of reading it gave 957, but makes the CRC length",
    "data-dependent; the protocol's Kani bit-flip harness had not finished after 18 minutes with it",
    "(its time without it was not measured), so it stays out until that is checked.",
    "",
    "Counting starts at a unit's first instruction (it used to start where gdb puts a breakpoint on a",
    "name, after the prologue, and the old `firmware::glue::feedback`'s prologue used `lr` as a",
    "scratch register, so the return address read there was wrong and the count ran to its cap),",
    "and the own stack includes the unit's own frame: on the unchanged receive path that added 5",
    "instructions (1,027 → 1,032) and 104 bytes (136 → 240). Writing the feedback fields in a loop",
    "over `feedback_field::ALL` cost 887 instructions per feedback frame; one call per field with the",
    "numbers taken from `ALL` (759 then) is the same code as the old straight-line writer.",
    "",
    "The move of the task bodies from `firmware::glue` into the `mcu` crate, measured with this",
    "script on both (`glue::on_frame` of commit 8624b25 counts 1,033 on that commit's frames):",
    "`glue::on_frame` (33 instructions of its own) became `LinkTask::receive`, `LinkTask::apply`",
    "and `protocol::event_from` (43 with the `Result` adapters: valid-frame count before and after,",
    "sequence number, identity request) and `Safety::step` + `Safety::record` (35: the ladder",
    "copied before the step, its counters compared for the trace), +45 in all; the ladder's own",
    "functions came out 18 shorter (inlined differently), the decoder +2: 1,033 → 1,062. Per",
    "feedback frame 759 → the figure above, mostly the µs time stamp, now written (it was 0, a field",
    "left out), and the identity-request check. Per tick 549 → the figure above: each of the tick's",
    "five ladder steps goes through `Safety::step` (copy + trace comparison), and the IWDG liveness",
    "check (`TickTask::alive`) is part of the unit now.",
]


def worst(r):
    """Index of the sampled call with the most instructions."""
    ins = r["instructions"]
    return ins.index(max(ins))


def board_estimate(r, board, qemu):
    """Instructions the board build's handler runs, from the `qemu` build's measured call, and how.

    A loop-free board handler runs each of its own instructions at most once: its instruction
    count replaces the measured own code. Otherwise the emulator's instructions are taken out and
    the board's extra handler code (if any) is assumed to run once."""
    i = worst(r)
    n, own = r["instructions"][i], r["own"][i]
    emu, emu_own = r["emulator"][i], r["emulator_own"][i]
    if board["loop_free"]:
        est = n - own - (emu - emu_own) + board["instructions"]
        how = (f"{n - own - (emu - emu_own)} measured in the functions it calls + the board handler's "
               f"{board['instructions']} instructions (loop-free: each runs at most once) in place of "
               f"the `qemu` handler's {own}")
    else:
        extra = max(0, board["instructions"] - qemu["instructions"])
        est = n - emu + extra
        how = f"{n} measured"
        if emu:
            how += f" − {emu} of the emulator's stand-ins"
        if extra:
            how += f" + {extra} (the board handler is {extra} instructions longer, counted once)"
    return est, how


def profile_table(out, prof, limit=14):
    out.append("| function | instructions |\n|---|---|")
    merged = {}
    for fn, k in prof.items():
        merged[short(fn)] = merged.get(short(fn), 0) + k
    shown = rest = 0
    for fn, k in sorted(merged.items(), key=lambda x: -x[1]):
        if shown < limit and k > 0:
            out.append(f"| `{fn}` | {k} |")
            shown += 1
        else:
            rest += k
    if rest:
        out.append(f"| (others) | {rest} |")
    out.append("")


def main(size_path, counts_path, stack_path, handlers_path):
    sec, flash, ram = sizes(size_path)
    counts = json.load(open(counts_path))
    failed = counts.pop("_failed", None)
    facts = json.load(open(handlers_path))
    board, qemu = facts["board"], facts["qemu"]
    by_sym = {r["symbol"]: (name, r) for name, r in counts.items()}
    mx = {name: max(r["instructions"]) for name, r in counts.items()}
    out = []
    out.append("# Firmware budgets\n")
    out.append("Regenerate with `bash firmware/budget/run.sh` (board build sizes; instruction counts of the")
    out.append("`qemu` build's Cortex-M4 code under QEMU netduinoplus2, single-stepped by gdb; the board")
    out.append("build's handlers from its disassembly).\n")
    out.append("## Memory (board build, `cargo fw`)\n")
    out.append("| section | bytes |\n|---|---|")
    for s in (".vector_table", ".text", ".rodata", ".data", ".bss", ".uninit"):
        if s in sec:
            out.append(f"| {s} | {sec[s]} |")
    out.append(f"| **flash** (vector table + text + rodata + data) | **{flash}** of 1 048 576 ({100*flash/1048576:.1f} %) |")
    out.append(f"| **static RAM** (data + bss + uninit: the defmt RTT buffer, the reset record) | **{ram}** of 131 072 ({100*ram/131072:.1f} %) |")
    out.append("\nThe stack is the rest of RAM below the statics (flip-link), far above the bounds below.\n")

    out.append("## Executed instructions (min / max over the sampled calls)\n")
    out.append("| unit | symbol | instructions | own stack, bytes |\n|---|---|---|---|")
    for name, r in counts.items():
        ins = r["instructions"]
        out.append(f"| {name} | `{r['symbol']}` | {min(ins)} / {max(ins)} | {max(r['stack_bytes'])} |")
    if failed:
        out.append(f"\n**Counting stopped early** ({failed}); the units after it are not measured.")
    out.append("")
    out.append("Units named by an interrupt symbol are whole RTIC handlers of the `qemu` build (entry to")
    out.append("exception return, RTIC's lock code included); the others are board-application functions")
    out.append("kept out of line (`#[inline(never)]`) so they can be counted alone. In the handlers, the")
    out.append("emulator's trace printing (`core::fmt`, semihosting output) is run through uncounted;")
    out.append("the emulator's other stand-ins are counted here and taken out for the load estimate below.")
    out.append("The ESTOP handler is counted on a press: QEMU models neither GPIO nor EXTI, so gdb pends")
    out.append("the interrupt through the NVIC and sets the pin's bit in the value the handler loaded.")
    out.append("QEMU's timers follow the host's clock, so which frame meets which tick, and with it a count,")
    out.append("can differ by a few instructions from one run to the next.")
    out.append("")
    # Every measured receive: the unit's own samples and those inside the spi_dma_done handler.
    dma = by_sym.get("DMA1_STREAM3")
    in_dma = dma[1].get("inclusive", {}).get("mcu::link::LinkTask::receive", 0) if dma else 0
    frame, fb = max(mx.get(RECEIVE, 0), in_dma), mx.get(FEEDBACK, 0)
    verdict = "within" if frame <= RECEIVE_TARGET else f"**{frame - RECEIVE_TARGET} above**"
    out.append(f"Per received frame (CRC + decode + validate + ladder step): **{frame} instructions**, "
               f"{verdict} the target of {RECEIVE_TARGET} (seed budget 3360 cycles = 20 µs). With the "
               f"feedback frame: {frame + fb}. (The most over the sampled frames: the receive unit's "
               f"{mx.get(RECEIVE, 0)} and, on later frames, {in_dma} inside the `spi_dma_done` handler.)")
    out.append("")
    out.extend(HISTORY)
    out.append("")
    out.append("The sampled frames are the emulator test's commands: the first has enable 0 and zero speeds")
    out.append("(fields omitted) and asks for the MCU's identity, the others carry all seven fields (26-byte")
    out.append("payload, the longest a conforming sender writes for an accepted command). A frame padded with")
    out.append("unknown or repeated fields up to the 61-byte limit costs more (every field decoded); that")
    out.append("case is not measured.")
    traced = [name for name, r in counts.items()
              if not r["symbol"].startswith("mcu::trace") and any(r.get("traced", []))]
    if traced:
        out.append("Sampled calls that recorded a trace entry (mode change, latch, re-arm): "
                   + ", ".join(traced) + ".")
    else:
        out.append("No sampled call recorded a trace entry (no mode change, latch or re-arm among them):")
        out.append("a call that records one costs the trace unit's figure more per record (see the notes")
        out.append("under the CPU load).")
    out.append("")

    out.append("### Board-application bodies inside their handlers\n")
    out.append("Everything executed while the body was active (its code, code inlined into it, the")
    out.append("functions it called), in the handler's worst sampled call:\n")
    out.append("| body | handler | instructions |\n|---|---|---|")
    for name, r in counts.items():
        if r["symbol"].startswith("mcu::"):
            continue
        for fn, k in r.get("inclusive", {}).items():
            if short(fn) in BODIES:
                out.append(f"| `{short(fn)}` | `{r['symbol']}` | {k} |")
    out.append("")

    out.append("### Where the instructions go\n")
    out.append("Instructions per function in the worst sampled call (code inlined into a caller is counted")
    out.append("in the inlined function, by the debug info; `?` has no debug info).\n")
    rec = counts.get(RECEIVE)
    if rec:
        incl = rec.get("inclusive", {})
        total = max(rec["instructions"])
        apply_ = incl.get("mcu::link::LinkTask::apply", 0)
        step = incl.get("mcu::safety::Safety::step", 0)
        record = incl.get("mcu::safety::Safety::record", 0)
        out.append(f"{RECEIVE}, by stage: {total} = {total - apply_} CRC, protobuf decode and field")
        out.append(f"conversion (`decode_command`, with `receive`'s own entry and exit) + {apply_ - step}")
        out.append(f"`LinkTask::apply` (event, sequence, identity request) + {step - record} `Safety::step`")
        out.append(f"(the ladder: validation, rung, limits; with the marks the trace compares) + {record}")
        out.append("`Safety::record` (trace comparison, nothing recorded).\n")
    for name in (RECEIVE, FEEDBACK, TICK):
        prof = counts.get(name, {}).get("by_function")
        if prof:
            out.append(f"{name}:\n")
            profile_table(out, prof)
    if dma:
        out.append(f"{dma[0]} (the `qemu` build; the board's handler code differs, see the load estimate):\n")
        profile_table(out, dma[1]["by_function"], limit=10)

    out.append("## CPU load at 168 MHz\n")
    out.append(f"Board build, assuming {CPI} cycles per instruction on average (pessimistic for this code):\n")
    out.append("| task (interrupt) | priority | trigger | rate, Hz | instructions per run | µs per run | "
               "cycles/s | share | estimated as |")
    out.append("|---|---|---|---|---|---|---|---|---|")
    total = 0.0
    sporadic = []
    for task, sym, prio, rate, trigger in TASKS:
        b, q = board.get(sym), qemu.get(sym)
        if sym in by_sym and b and q:
            n, how = board_estimate(by_sym[sym][1], b, q)
        elif b and b["loop_free"]:
            n = b["instructions"]
            calls = ", ".join(f"`{c}`" for c in b["calls"])
            how = (f"not run under QEMU (its emulator stand-in does nothing); the board handler's {n} "
                   f"instructions, loop-free: a bound for its own code" + (f", without its calls ({calls})"
                                                                          if calls else ""))
        else:
            out.append(f"| {task} (`{sym}`) | {prio} | {trigger} | {rate or 'event'} | ? | | | | not measured |")
            continue
        us = n * CPI / F_CPU * 1e6
        if rate:
            c = rate * n * CPI
            total += c
            out.append(f"| {task} (`{sym}`) | {prio} | {trigger} | {rate} | {n} | {us:.1f} | {c:,.0f} | "
                       f"{100*c/F_CPU:.1f} % | {how} |")
        else:
            sporadic.append(task)
            out.append(f"| {task} (`{sym}`) | {prio} | {trigger} | per event | {n} | {us:.1f} | – | – | {how} |")
    out.append(f"| **total (periodic tasks)** | | | | | | {total:,.0f} | **{100*total/F_CPU:.1f} %** | |")
    out.append("")
    notes = []
    if sporadic:
        notes.append(f"{', '.join(f'`{t}`' for t in sporadic)} runs once per input edge, not at a rate, "
                     "and is left out of the total.")
    if "EXTI15_10" in board:
        b = board["EXTI15_10"]
        notes.append(f"`spi_nss_rise` ends every transaction: a complete frame finds the receive stream at "
                     f"a frame boundary and returns (the figure bounds that path: all {b['instructions']} "
                     f"instructions of the handler, which is loop-free). A cut transaction also re-arms the "
                     f"link (`SpiLink::arm`: two DMA-stream stops polled up to 1000 times each) and steps the "
                     f"ladder once (`Safety::step`); that path is an error case, not measured.")
    tr = counts.get(TRACE)
    if tr:
        n = max(tr["instructions"])
        log = tr.get("inclusive", {}).get("mcu::trace::log", 0)
        notes.append(f"A ladder step that records a trace entry (mode change, BRAKE latch, re-arm or its "
                     f"refusal; up to four per step) adds {n} instructions per record "
                     f"({n * CPI / F_CPU * 1e6:.1f} µs), {log} of them in the defmt log line. defmt-rtt "
                     f"writes it inside a critical section (interrupts disabled from `acquire` to `release`), "
                     f"so such a step, in `watchdog_tick`, `spi_dma_done` or `spi_nss_rise`, delays "
                     f"`current_loop` and `estop_input` by up to that long per record; and while a host has "
                     f"put the RTT channel in blocking mode, a full buffer makes the write wait for the host "
                     f"with interrupts disabled.")
    if dma:
        mis = dma[1]["by_function"].get(
            "compiler_builtins::mem::impls::copy_forward::copy_forward_misaligned_words", 0)
        notes.append(f"The `spi_dma_done` estimate counts the board handler's own `__aeabi_memcpy` and "
                     f"`__aeabi_memclr4` calls at the `qemu` handler's cost. That includes {mis} instructions "
                     f"in `copy_forward_misaligned_words`: the `qemu` build copies the received frame out of "
                     f"its semihosting record, one byte off word alignment, where the board's memcpy copies "
                     f"the feedback frame into the TX buffer (the board reads the received frame with a "
                     f"volatile copy in the handler's own code instead).")
    notes.append("The `qemu` build reads constant ADC and encoder values (QEMU models neither). The \"own "
                 "stack\" figures above are the deepest SP seen below the entry SP during the sampled calls "
                 "(measured, not a bound); the bound per task follows.")
    for note in notes:
        out.append(note)
        out.append("")
    out.append(open(stack_path).read().rstrip())
    print("\n".join(out))


if __name__ == "__main__":
    main(*sys.argv[1:5])
