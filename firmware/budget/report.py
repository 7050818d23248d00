#!/usr/bin/env python3
"""Turns the size listing, the instruction counts, the stack analysis and the handler facts into
firmware/BUDGET.md.

Usage: report.py DIR PROFILE... > BUDGET.md
DIR/<profile>/ holds what run.sh gathered for that image: size.txt (arm-none-eabi-size -A),
counts.json (count.py), stack.md (stack.py), handlers.json (handlers.py) and qemu.log (QEMU's output,
the serial images' trace). `amr-spi` gets the sections it always had; `cdc` and `teensy` a section
each (report.py's SERIAL says what each runs and sends); `pi-spi` its own (PI_TASKS).
"""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import serial_frames  # noqa: E402

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


def inclusive(incl, name):
    """A function's figure in an `inclusive` profile, whatever its generic arguments
    (`mcu::safety::Safety<2>::step<2>` for `mcu::safety::Safety::step`)."""
    return sum(k for fn, k in incl.items() if short(fn) == name)


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


class Image:
    """What run.sh gathered for one image in DIR/<profile>/: sizes, counts, handler facts, the
    stack section and QEMU's output."""

    def __init__(self, d):
        self.sec, self.flash, self.ram = sizes(os.path.join(d, "size.txt"))
        self.counts = json.load(open(os.path.join(d, "counts.json")))
        self.failed = self.counts.pop("_failed", None)
        facts = json.load(open(os.path.join(d, "handlers.json")))
        self.board, self.qemu = facts["board"], facts["qemu"]
        self.stack = open(os.path.join(d, "stack.md")).read().rstrip()
        log = os.path.join(d, "qemu.log")
        self.log = open(log, errors="replace").read() if os.path.exists(log) else ""


def memory(out, img, level="##"):
    """The board build's sections, flash and static RAM."""
    sec, flash, ram = img.sec, img.flash, img.ram
    out.append(f"{level} Memory (board build, `cargo fw`)\n")
    out.append("| section | bytes |\n|---|---|")
    for s in (".vector_table", ".text", ".rodata", ".data", ".bss", ".uninit"):
        if s in sec:
            out.append(f"| {s} | {sec[s]} |")
    out.append(f"| **flash** (vector table + text + rodata + data) | **{flash}** of 1 048 576 ({100*flash/1048576:.1f} %) |")
    out.append(f"| **static RAM** (data + bss + uninit: the defmt RTT buffer, the reset record) | **{ram}** of 131 072 ({100*ram/131072:.1f} %) |")
    out.append("\nThe stack is the rest of RAM below the statics (flip-link), far above the bounds below.\n")


def units(out, img, level="##"):
    """Every counted unit: min / max instructions and the deepest stack seen."""
    out.append(f"{level} Executed instructions (min / max over the sampled calls)\n")
    out.append("| unit | symbol | instructions | own stack, bytes |\n|---|---|---|---|")
    for name, r in img.counts.items():
        ins = r["instructions"]
        out.append(f"| {name} | `{r['symbol']}` | {min(ins)} / {max(ins)} | {max(r['stack_bytes'])} |")
    if img.failed:
        out.append(f"\n**Counting stopped early** ({img.failed}); the units after it are not measured.")
    out.append("")


def bodies(out, counts, names, level="###"):
    """The board-application bodies `names` inside the handlers, and the heading of the profiles."""
    out.append(f"{level} Board-application bodies inside their handlers\n")
    out.append("Everything executed while the body was active (its code, code inlined into it, the")
    out.append("functions it called), in the handler's worst sampled call:\n")
    out.append("| body | handler | instructions |\n|---|---|---|")
    for name, r in counts.items():
        if r["symbol"].startswith("mcu::"):
            continue
        for fn, k in r.get("inclusive", {}).items():
            if short(fn) in names:
                out.append(f"| `{short(fn)}` | `{r['symbol']}` | {k} |")
    out.append("")

    out.append(f"{level} Where the instructions go\n")
    out.append("Instructions per function in the worst sampled call (code inlined into a caller is counted")
    out.append("in the inlined function, by the debug info; `?` has no debug info).\n")


class Load:
    """The CPU load table: a row per task (or per part of one), the total of the periodic rows."""

    def __init__(self, out, level="##"):
        self.out, self.total, self.sporadic = out, 0.0, []
        out.append(f"{level} CPU load at 168 MHz\n")
        out.append(f"Board build, assuming {CPI} cycles per instruction on average (pessimistic for this code):\n")
        out.append("| task (interrupt) | priority | trigger | rate, Hz | instructions per run | µs per run | "
                   "cycles/s | share | estimated as |")
        out.append("|---|---|---|---|---|---|---|---|---|")

    def row(self, task, prio, trigger, rate, n, how, cycles=0):
        """`n` instructions per run (None: not measured, or only `cycles`), plus `cycles` spent waiting;
        `rate` None for a task run per event."""
        if n is None and not cycles:
            self.out.append(f"| {task} | {prio} | {trigger} | {rate or 'event'} | ? | | | | not measured |")
            return
        per_run = (n or 0) * CPI + cycles
        shown = "–" if n is None else n
        us = per_run / F_CPU * 1e6
        if rate:
            c = rate * per_run
            self.total += c
            self.out.append(f"| {task} | {prio} | {trigger} | {rate} | {shown} | {us:.1f} | {c:,.0f} | "
                            f"{100*c/F_CPU:.1f} % | {how} |")
        else:
            self.sporadic.append(task.split(" ")[0])
            self.out.append(f"| {task} | {prio} | {trigger} | per event | {shown} | {us:.1f} | – | – | {how} |")

    def end(self):
        """The total row; returns the periodic cycles per second and the tasks run per event."""
        self.out.append(f"| **total (periodic tasks)** | | | | | | {self.total:,.0f} | "
                        f"**{100*self.total/F_CPU:.1f} %** | |")
        self.out.append("")
        return self.total, self.sporadic


def amr_spi(out, img):
    """The `amr-spi` image's sections; returns its figures for the overview."""
    counts, board, qemu = img.counts, img.board, img.qemu
    by_sym = {r["symbol"]: (name, r) for name, r in counts.items()}
    mx = {name: max(r["instructions"]) for name, r in counts.items()}
    memory(out, img)
    units(out, img)
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
    # The seed's 10 µs validate + 10 µs apply, in cycles at 168 MHz, against the frame at the two
    # cycles-per-instruction figures in use: this file's load estimate and `cargo xtask rta`'s bound.
    seed_cycles = 3360
    at = {cpi: frame * cpi for cpi in (2, 3)}
    fits = lambda c: "within" if c <= seed_cycles else f"**{c - seed_cycles} cycles over**"
    out.append(f"Per received frame (CRC + decode + validate + ladder step): **{frame} instructions**, "
               f"{verdict} the target of {RECEIVE_TARGET}. Against the seed's 20 µs (10 µs validate + "
               f"10 µs apply: 3360 cycles at 168 MHz): {at[2]} cycles at 2 cycles per instruction (the "
               f"load estimate below), {fits(at[2])}; {at[3]} at 3 (`cargo xtask rta`'s bound, SAFETY.md "
               f"§7 F3), {fits(at[3])}. Only a cycle count on the board settles it (SAFETY.md §7 O5). "
               f"With the feedback frame: {frame + fb}. (The most over the sampled frames: the receive unit's "
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

    bodies(out, counts, BODIES)
    rec = counts.get(RECEIVE)
    if rec:
        incl = rec.get("inclusive", {})
        total = max(rec["instructions"])
        apply_ = inclusive(incl, "mcu::link::LinkTask::apply")
        step = inclusive(incl, "mcu::safety::Safety::step")
        record = inclusive(incl, "mcu::safety::Safety::record")
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

    load = Load(out)
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
            n, how = None, None
        load.row(f"{task} (`{sym}`)", prio, trigger, rate, n, how)
    total, sporadic = load.end()
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
    out.append(img.stack)
    return {"frame": frame, "frame_what": "SPI command frame (receive)", "tick": mx.get(TICK),
            "load": 100 * total / F_CPU}


# The serial images. `frame`: the frame the host sends at `rate` frames/s (its nominal rate);
# `tasks`: the RTIC tasks besides the link (task, interrupt, priority, rate in Hz or None for an
# event, trigger); `sent`: what the board sends (name, bytes, per second), one transmit interrupt
# per byte on the board; `bodies`: board-application bodies to show inside their handlers.
LINK_BAUD_BYTES = 115_200 // 10
SERIAL = {
    "cdc": {
        "title": "Image `cdc` (seed 001: `AA 55` frames on USART1)",
        "frame": "SET_MOTOR_PWM (NORMAL)",
        "rate": 50,
        "tasks": [
            ("estop_input", "EXTI4", 5, None, "ESTOP input edge (PD4)"),
            ("watchdog_tick", "TIM2", 2, 1_000, "TIM2 update"),
            ("imu_read", "TIM3", 1, 100, "TIM3 update"),
        ],
        "sent": [("STATUS", serial_frames.cdc_len("status"), 10),
                 ("IMU_MPU6050", serial_frames.cdc_len("imu"), 100)],
        "bodies": ["mcu::serial::tick", "mcu::cdc::CdcLinkTask::on_byte", "mcu::cdc::CdcLinkTask::periodic",
                   "mcu::cdc::CdcLinkTask::send_status", "mcu::cdc::motor_outputs",
                   "mcu::estop::EstopInput::poll", "mcu::estop::EstopInput::edge_then"],
    },
    "teensy": {
        "title": "Image `teensy` (seed 003: COBS + CRC frames on USART1)",
        "frame": "MTRS (NORMAL)",
        "rate": 50,
        "tasks": [
            ("estop_input", "EXTI4", 5, None, "ESTOP input edge (PD4)"),
            ("step_gen", "TIM5", 3, 10_000, "TIM5 update"),
            ("watchdog_tick", "TIM2", 2, 1_000, "TIM2 update"),
        ],
        "sent": [("MTRS echo", len(serial_frames.teensy(serial_frames.MTRS)), 50)],
        "bodies": ["mcu::serial::tick", "mcu::teensy::TeensyLinkTask::on_byte", "mcu::teensy::Joints::tick",
                   "mcu::teensy::StepGen::run", "mcu::estop::EstopInput::poll",
                   "mcu::estop::EstopInput::edge_then"],
    },
}
LINK_BODY = "link: one received byte"
LINK_HANDLER = "link_usart handler (USART1), one received byte"
LINK_IDLE = "link_usart handler (USART1), nothing received or queued"
SERIAL_TICK = "tick: run (ESTOP input, supply, ladder tick)"
STATUS_TICK = "watchdog_tick handler (TIM2), periodic STATUS"
# The `cdc` battery reading: ADC1 clocked at PCLK2 / 2 = 42 MHz (`board::cdc::Vbat::new` leaves
# ADCPRE at its reset value), 480 sampling + 12 conversion ADC cycles, polled.
ADC_HZ = 42e6
ADC_CYCLES = 480 + 12
# The MPU6050 reading (`board::cdc::Imu::read`: mpu6050-dmp's `motion6`, 14 bytes, then
# `temperature`, 2 bytes): two I2C write-reads at 400 kHz, each START, address + W, register,
# repeated START, address + R, the data bytes and STOP (9 bit times per byte with its acknowledge).
I2C_HZ = 400e3
I2C_BITS = sum(1 + 9 + 9 + 1 + 9 + 9 * n + 1 for n in (14, 2))


def fed_frames(r):
    """The frames a fed unit received, in order: (label, per-byte instructions, per-byte trace
    instructions, per-byte emulator instructions)."""
    frames = {}
    for (label, k, _pos, _byte), n, tr, emu in zip(r["fed"], r["instructions"], r["traced"], r["emulator"]):
        f = frames.setdefault(k, (label, [], [], []))
        f[1].append(n)
        f[2].append(tr)
        f[3].append(emu)
    return list(frames.values())


def span(values):
    """`a` or `a–b`."""
    lo, hi = min(values), max(values)
    return f"{lo}" if lo == hi else f"{lo}–{hi}"


def trace_modes(log):
    """The firmware's trace (QEMU's output): the rung changes `Mode@tick`, and the last line."""
    changes, last, mode = [], None, None
    for line in log.splitlines():
        if line.startswith("tick="):
            f = dict(p.split("=", 1) for p in line.split(" out=")[0].split())
            if f["mode"] != mode:
                mode = f["mode"]
                changes.append(f"{mode}@{f['tick']}")
            last = f
    return changes, last


def serial(out, profile, img):
    """A serial image's section; returns its figures for the overview."""
    cfg = SERIAL[profile]
    counts, board, qemu = img.counts, img.board, img.qemu
    first = {}
    for name, r in counts.items():
        first.setdefault(r["symbol"], r)
    out.append(f"## {cfg['title']}\n")
    memory(out, img, "###")
    units(out, img, "###")
    out.append("Bytes go to the `qemu` build's USART1 through QEMU's `-serial` (a TCP chardev), one at a")
    out.append("time: count.py hands each over while the core is halted and resumes it once the USART holds")
    out.append("it, so each received byte is one interrupt, as at 115 200 baud on the board. Frames follow")
    out.append("each other 20 ticks apart (the host's 50 Hz); the ticks are sampled with a frame every 20")
    out.append("ticks. The frames are built by `protocol/golden/gen_structs.py` (Python `struct`,")
    out.append("independently of the Rust encoders; `firmware/budget/serial_frames.py` lists them).")
    out.append("")

    # Per received frame: the link body's counts, and the handler's.
    rows, per_label = [], {}
    for name, r in counts.items():
        if "fed" not in r:
            continue
        for label, ins, tr, emu in fed_frames(r):
            key = (label, "handler" if r["symbol"] == "USART1" else "body")
            per_label.setdefault(key, []).append((ins, tr, emu))
            if key not in rows:
                rows.append(key)
    out.append("### Per received frame\n")
    out.append("Each frame's bytes counted one by one, in one frame; the last byte completes the frame (CRC,")
    out.append("decode, the ladder step, a reply queued). Min / max over the frames of a kind.\n")
    out.append("| frame | counted | bytes | each byte before the last | the last byte | **per frame** |")
    out.append("|---|---|---|---|---|---|")
    notes = []
    for label, what in rows:
        got = per_label[(label, what)]
        before = [n for ins, _, _ in got for n in ins[:-1]]
        last = [ins[-1] for ins, _, _ in got]
        sums = [sum(ins) for ins, _, _ in got]
        unit = "`link_usart` handler" if what == "handler" else "link body (`on_byte`)"
        out.append(f"| {label} | {unit} | {len(got[0][0])} | {span(before)} | {span(last)} | **{span(sums)}** |")
        traced = max(tr[-1] for _, tr, _ in got)
        if traced:
            notes.append(f"{label}: its last byte records a trace entry ({traced} of its instructions: the "
                         f"ring entry and the defmt log line).")
    out.append("")
    for n in notes:
        out.append(n)
    if notes:
        out.append("")

    frame = cfg["frame"]
    body = per_label.get((frame, "body"))
    handler = per_label.get((frame, "handler"))
    summary = {"frame": None, "frame_what": frame, "tick": None, "load": None}
    if body:
        summary["frame"] = max(sum(ins) for ins, _, _ in body)
    h_sum = max(sum(ins) - sum(emu) for ins, _, emu in handler) if handler else None
    if body and handler:
        b_sum = summary["frame"]
        nbytes = len(handler[0][0])
        rate = cfg["rate"]
        cyc = rate * h_sum * CPI
        period = F_CPU / rate
        most = LINK_BAUD_BYTES // nbytes
        out.append(f"Per received {frame} frame: **{b_sum} instructions** in the link body ({nbytes} calls), "
                   f"**{h_sum}** in the `link_usart` handler ({nbytes} interrupts: RTIC's entry and exit, "
                   f"the UART read, the transmit pump, and the body). The host sends {rate} frames/s: "
                   f"{rate} × {h_sum} = {rate * h_sum:,} instructions/s, {cyc:,.0f} cycles/s at {CPI} cycles "
                   f"per instruction, **{100 * cyc / F_CPU:.2f} %** of 168 MHz; one frame takes "
                   f"{h_sum * CPI / F_CPU * 1e6:.0f} µs of its {1e3 / rate:.0f} ms period ({period:,.0f} cycles). "
                   f"At the most the link carries ({LINK_BAUD_BYTES:,} bytes/s at 115 200 baud, {most} such "
                   f"frames/s) it would be {100 * most * h_sum * CPI / F_CPU:.1f} %.")
        out.append("")

    changes, last = trace_modes(img.log)
    if last:
        out.append(f"The firmware's own trace (QEMU's output) over the run: rung changes "
                   f"{' → '.join(changes)} (`Mode@tick`); at the end {last['valid']} valid frames, "
                   f"{last['rejected']} refused. The ladder leaves the power-on BRAKE for REDUCED and returns to "
                   f"NORMAL after a clean window of 1000 ticks; the frames labelled NORMAL were counted "
                   f"after that change.")
    got = []
    for name, r in counts.items():
        got += serial_frames.replies(profile, bytes.fromhex(r.get("replies", "")))
    if got:
        tally = {}
        for g in got:
            tally[g] = tally.get(g, 0) + 1
        out.append("Replies read back from the link during the counted units: "
                   + ", ".join(f"{k} ×{v}" for k, v in tally.items()) + ".")
    out.append("")

    bodies(out, counts, cfg["bodies"])
    for name in (f"{LINK_BODY}, drive", SERIAL_TICK):
        prof = counts.get(name, {}).get("by_function")
        if prof:
            what = " (its worst byte: the one that completes a frame)" if name.startswith(LINK_BODY) else ""
            out.append(f"{name}{what}:\n")
            profile_table(out, prof)

    # CPU load.
    load = Load(out, "###")
    notes = []
    status, extra = counts.get(STATUS_TICK), None
    for task, sym, prio, rate, trigger in cfg["tasks"]:
        r, b, q = first.get(sym), board.get(sym), qemu.get(sym)
        n, how = board_estimate(r, b, q) if r and b and q else (None, None)
        load.row(f"{task} (`{sym}`)", prio, trigger, rate, n, how)
        if sym == "TIM2" and n is not None:
            summary["tick"] = max(counts.get(SERIAL_TICK, {}).get("instructions", [0]))
            if status:
                extra = max(status["instructions"]) - max(r["instructions"])
                load.row("watchdog_tick's STATUS (`TIM2`)", prio, "every 100th tick", 10, extra,
                         f"the STATUS tick ({max(status['instructions'])} measured) less a plain tick's "
                         f"{max(r['instructions'])}: encoding and queueing the frame, the whole frame "
                         f"written by QEMU's USART at once")
        if sym == "TIM3" and n is not None:
            adc = ADC_CYCLES / ADC_HZ * F_CPU
            load.row("imu_read: battery conversion (`TIM3`)", prio, "each run", rate, None,
                     f"the polled wait for ADC1: {ADC_CYCLES} ADC cycles at {ADC_HZ / 1e6:.0f} MHz "
                     f"(QEMU's ADC never ends a conversion: count.py sets the flag at the first poll)",
                     cycles=adc)
            i2c = I2C_BITS / I2C_HZ * F_CPU
            load.row("imu_read: MPU6050 read (`TIM3`)", prio, "each run", rate, None,
                     f"**not measured** (QEMU has no I2C model; the `qemu` build's sensor is absent): "
                     f"{I2C_BITS} bit times at {I2C_HZ / 1e3:.0f} kHz, the blocking HAL polling throughout",
                     cycles=i2c)
            if extra is not None:
                load.row("imu_read: IMU_MPU6050 frame (`TIM3`)", prio, "each run", rate, extra,
                         "**not measured** (no reading, no frame under QEMU): taken as the STATUS "
                         "frame's cost above (26 bytes against 16)")
    if handler:
        nbytes = len(handler[0][0])
        load.row("link_usart, receive (`USART1`)", 2, f"{cfg['rate']} {frame.split()[0]} frames/s "
                 f"({cfg['rate'] * nbytes} bytes/s)", cfg["rate"], h_sum,
                 f"per frame: the handler over its {nbytes} bytes, measured (one interrupt per byte)")
    idle = counts.get(LINK_IDLE)
    if idle:
        sent = sum(n * per_s for _, n, per_s in cfg["sent"])
        what = " + ".join(f"{name} {n} B × {per_s}/s" for name, n, per_s in cfg["sent"])
        load.row("link_usart, transmit (`USART1`)", 2, f"TXE, one per byte sent ({what})", sent,
                 max(idle["instructions"]),
                 "the handler with nothing received or queued (measured, pended through the NVIC), per "
                 "byte; the byte's own pop and write are counted where QEMU ran them, in the task that "
                 "queued the frame (QEMU's USART takes a whole frame at once, so it never raises TXE)")
    total, sporadic = load.end()
    summary["load"] = 100 * total / F_CPU
    if sporadic:
        notes.append(f"{', '.join(f'`{t}`' for t in sporadic)} runs once per input edge, not at a rate, "
                     "and is left out of the total.")
    notes.append("Handlers: the `qemu` build's, measured, with the board build's handler code put in place "
                 "of the emulator's as for `amr-spi` (the serial images' handlers differ only in the "
                 "trace printing, run through uncounted). A frame that the ladder refuses, or one that "
                 "changes the rung, costs a trace record more (see `amr-spi`'s trace unit).")
    for n in notes:
        out.append(n)
        out.append("")
    out.append(img.stack)
    out.append("")
    return summary


# The seed 004 image (`pi-spi`): the units count.py's PI_SPI list counts, by symbol.
PI_TRANSFER = "mcu::pi_spi::PiSpiApp::on_transfer"
PI_TICK = "mcu::pi_spi::PiSpiApp::tick"
PI_ODOMETRY = "mcu::odometry::Odometry::update"
# Its RTIC tasks: task, interrupt, priority, rate in Hz (None: per event), trigger. The rates are the
# seed's: a transfer every 10 ms (the Pi's 100 Hz), the tick at 1 kHz, the IMU every 10th tick.
PI_TASKS = [
    ("estop_input", "EXTI4", 5, None, "ESTOP input edge (PD4)"),
    ("spi_dma_done", "DMA1_STREAM3", 2, 100, "SPI2 RX DMA transfer complete, one per 179-byte transfer"),
    ("spi_nss_rise", "EXTI15_10", 2, 100, "NSS rising edge (PB12), one per transfer"),
    ("watchdog_tick", "TIM7", 2, 1_000, "TIM7 update"),
    ("imu_read", "UART4", 1, 100, "pended by every 10th tick"),
]
PI_BODIES = [
    "mcu::pi_spi::PiSpiApp::on_transfer", "mcu::pi_spi::PiSpiApp::tick", "mcu::pi_spi::PiSpiApp::imu_sample",
    "mcu::odometry::Odometry::update", "mcu::odometry::Odometry::configure",
    "mcu::imu::ImuFusion::set_orientation", "mcu::imu::ImuFusion::sensor_lost", "mcu::pi_spi::gains_from_wire",
    "mcu::serial::tick", "mcu::estop::EstopInput::poll", "mcu::estop::EstopInput::edge_then",
]
# `board::pi_spi::Analog::scan`: ADC1 at PCLK2 / 4 = 21 MHz, six inputs at 144 + 12 ADC cycles and
# the battery at 480 + 12, polled conversion by conversion.
PI_ADC_HZ = 21e6
PI_ADC_CYCLES = 6 * (144 + 12) + (480 + 12)


def pi_spi(out, img):
    """The `pi-spi` image's section; returns its figures for the overview."""
    counts, board, qemu = img.counts, img.board, img.qemu
    by_sym = {}
    for name, r in counts.items():
        by_sym.setdefault(r["symbol"], (name, r))
    mx = {sym: max(r["instructions"]) for sym, (_, r) in by_sym.items()}
    out.append("## Image `pi-spi` (seed 004: 179-byte SPI transfers from a Raspberry Pi)\n")
    memory(out, img, "###")
    units(out, img, "###")
    out.append("As for `amr-spi`, the transfers come from a host file through semihosting, one record per")
    out.append("tick (`pi_spi_transfers.bin`, written by `firmware/qemu/pi_spi.py make-budget` with Python's")
    out.append("`struct` from the seed's declarations): a shutdown transfer, then one every 10 ticks (the")
    out.append("Pi's 100 Hz), each with the four motors in four different modes (PWM, MAV, MTP,")
    out.append("PASSIV_BRAKE, rotated from one transfer to the next), the four servos enabled, and the")
    out.append("costliest one-shot updates: both gain sets (MOTOR_PID_SPEED and MOTOR_PID_POS, within")
    out.append("`SPEED_BOUNDS` and `POSITION_BOUNDS`), IMU_ORIENTATION (the gyro's alternating between the")
    out.append("identity and a quarter turn about z, so each one turns the fusion's quaternion; the")
    out.append("compass's the identity) and, in every other transfer, KINEMATICS (a mecanum")
    out.append("configuration: wheel radius 0.0325 m, 0.18 m half track + half wheelbase, 2π/1440 rad per")
    out.append("count). Counting starts after the REDUCED window of 1000 ticks that follows the re-arm.")
    out.append("SysTick stands in for TIM7 and the tick pends `spi_dma_done` in every tick (the emulated")
    out.append("link reads one record per call): the handler's calls in a tick without a transfer are its")
    out.append("minimum above; the board raises it only for a transfer. The tick and its handler are")
    out.append("sampled over 20 consecutive ticks: the odometry runs in every 10th, and integrates in")
    out.append("one of 20 (the update right after a kinematics configuration only takes the counts as its")
    out.append("baseline). QEMU models no I2C: the `qemu` build's IMU is absent, so `imu_read` runs")
    out.append("`ImuFusion::sensor_lost`; the fusion itself (`ImuFusion::update`) is **not measured** (see")
    out.append("the load table). Under QEMU the priority-1 `imu_read` does not get to run by itself (the")
    out.append("emulated core is slower than the host clock that drives SysTick, the emulator's tick")
    out.append("source, at priority 1 too, so SysTick is pending again whenever a tick ends): count.py pends")
    out.append("UART4 as the tick does and clears SysTick's pending bit before each sample.")
    out.append("")

    changes, last = trace_modes(img.log)
    if last:
        out.append(f"The firmware's own trace (QEMU's output) over the run: rung changes "
                   f"{' → '.join(changes)} (`Mode@tick`); at the end {last['valid']} valid transfers, "
                   f"{last['rejected']} refused.")
        out.append("")

    tr = by_sym.get(PI_TRANSFER)
    dma = by_sym.get("DMA1_STREAM3")
    in_dma = dma[1].get("inclusive", {}).get(PI_TRANSFER, 0) if dma else 0
    transfer = max(mx.get(PI_TRANSFER, 0), in_dma) or None
    tick = by_sym.get(PI_TICK)
    tim7 = by_sym.get("TIM7")
    summary = {"frame": transfer, "frame_what": "SPI transfer (`on_transfer`)", "tick": None, "load": None}
    if transfer:
        out.append(f"Per transfer: **{transfer} instructions** in `PiSpiApp::on_transfer` (the most over the "
                   f"sampled transfers: the unit's {mx.get(PI_TRANSFER, 0)} and {in_dma} inside the "
                   f"`spi_dma_done` handler), {mx.get('DMA1_STREAM3', 0)} for the whole handler (the "
                   f"`qemu` build, its emulated link included; the board's in the load table).")
    if tr:
        incl = tr[1].get("inclusive", {})
        total = max(tr[1]["instructions"])
        apply_ = incl.get("mcu::pi_spi::PiSpiApp::apply", 0)
        take = incl.get("mcu::pi_spi::PiSpiApp::take", 0)
        upd = incl.get("mcu::pi_spi::PiSpiApp::apply_updates", 0)
        fb = incl.get("mcu::pi_spi::PiSpiApp::write_feedback", 0)
        gains = incl.get("mcu::pi_spi::gains_from_wire", 0)
        orient = incl.get("mcu::imu::ImuFusion::set_orientation", 0)
        kin = incl.get("mcu::odometry::Odometry::configure", 0)
        # `on_transfer` decodes, then calls `apply` (the shutdown bits, `take`, the outcome), then
        # writes the next TxBuffer (`write_feedback`) after it.
        out.append(f"The worst sampled transfer by stage: {total} = {total - apply_ - fb} the version, parity "
                   f"and decode of the 179 bytes (with `on_transfer`'s own entry and exit) + {apply_ - take} "
                   f"the shutdown bits and the outcome (`apply` besides `take`) + {take - upd} the servo "
                   f"check and the ladder's two events + **{upd} the one-shot updates** (both gain sets "
                   f"{gains}, the orientation {orient}, the kinematics {kin}) + {fb} the next TxBuffer "
                   f"(`write_feedback`, after `apply`). A transfer without update flags costs about "
                   f"{total - upd} (not sampled separately).")
    if tick:
        t = tick[1]
        odo = t.get("inclusive", {}).get(PI_ODOMETRY, 0)
        summary["tick"] = max(t["instructions"])
        out.append(f"Per tick: {min(t['instructions'])}–**{max(t['instructions'])} instructions** in "
                   f"`PiSpiApp::tick` over 20 consecutive ticks; the worst one "
                   + (f"ran the odometry's integration ({odo} of its instructions in `Odometry::update`)"
                      if odo else "did not run the odometry (CHECK: the sampled ticks missed it)")
                   + (f"; {min(tim7[1]['instructions'])}–{max(tim7[1]['instructions'])} for the whole "
                      f"`watchdog_tick` handler" if tim7 else "") + ".")
    out.append("")

    bodies(out, counts, PI_BODIES)
    for sym in (PI_TRANSFER, PI_TICK):
        if sym in by_sym:
            name, r = by_sym[sym]
            out.append(f"{name}, its worst sampled call:\n")
            profile_table(out, r["by_function"])

    load = Load(out, "###")
    for task, sym, prio, rate, trigger in PI_TASKS:
        b, q = board.get(sym), qemu.get(sym)
        if sym in by_sym and b and q:
            n, how = board_estimate(by_sym[sym][1], b, q)
            if sym == "DMA1_STREAM3":
                how += " (a call with a transfer)"
            if sym == "TIM7":
                how += ("; the worst of 20 consecutive ticks, the odometry's included, taken for every "
                        "tick (it runs in one of ten)")
            if sym == "UART4":
                how += ("; the sensor absent (`sensor_lost`) and the emulator's ADC, which reads 0 at "
                        "once: the board's waits and the fusion follow")
        elif b and b["loop_free"]:
            n = b["instructions"]
            calls = ", ".join(f"`{c}`" for c in b["calls"])
            how = (f"not run under QEMU (no chip select); the board handler's {n} instructions, loop-free: "
                   f"a bound for its own code" + (f", without its calls ({calls})" if calls else ""))
        else:
            n, how = None, None
        load.row(f"{task} (`{sym}`)", prio, trigger, rate, n, how)
        if sym == "UART4":
            adc = PI_ADC_CYCLES / PI_ADC_HZ * F_CPU
            load.row("imu_read: ADC scan (`UART4`)", prio, "each run", rate, None,
                     f"the polled waits for ADC1 (`Analog::scan`): {PI_ADC_CYCLES} ADC cycles at "
                     f"{PI_ADC_HZ / 1e6:.0f} MHz (QEMU's ADC has no scan: the `qemu` build reads 0)",
                     cycles=adc)
            i2c = I2C_BITS / I2C_HZ * F_CPU
            load.row("imu_read: MPU6050 read (`UART4`)", prio, "each run", rate, None,
                     f"**not measured** (QEMU has no I2C model; the `qemu` build's sensor is absent): "
                     f"{I2C_BITS} bit times at {I2C_HZ / 1e3:.0f} kHz (`board::cdc::Imu`, as on the seed 001 "
                     f"board), the blocking HAL polling throughout", cycles=i2c)
            load.row("imu_read: fusion `ImuFusion::update` (`UART4`)", prio, "each run", rate, None, None)
    total, sporadic = load.end()
    summary["load"] = 100 * total / F_CPU
    notes = []
    notes.append("The IMU fusion (`mcu::imu::ImuFusion::update`: the orientation, bias window and filter in "
                 "`f32`) is **not measured**: QEMU has no I2C, so no reading reaches it under the emulator, "
                 "and its cost is in no figure here; the total leaves it out. It runs in `imu_read` at "
                 "priority 1, like the ADC and I2C waits above, which block only that task: the tick, the "
                 "transfers and the ESTOP input preempt it.")
    if sporadic:
        notes.append(f"{', '.join(f'`{t}`' for t in sporadic)} runs once per input edge, not at a rate, "
                     "and is left out of the total.")
    notes.append("The wheels stand still under QEMU (the `qemu` build's encoders read 0), so the odometry "
                 "integrates zero motion: `sinf`/`cosf` of a zero heading and the arc factors of a zero turn "
                 "take their shortest paths. With the wheels turning they take longer; that case (one tick in "
                 "ten) is not measured.")
    notes.append("The `qemu` build's encoders and ADC read 0 and its µs clock counts whole ticks (QEMU models "
                 "neither TIM2–TIM6 as the board uses them nor the ADC scan); the board handlers' own code "
                 "is put in place of the emulator's as for `amr-spi`. Transfers the ladder refuses, or that "
                 "change the rung, cost a trace record more (the trace unit above).")
    for n in notes:
        out.append(n)
        out.append("")
    out.append(img.stack)
    out.append("")
    return summary


def overview(out, figures):
    """One row per image."""
    out.append("## Every image\n")
    out.append("| image | flash, bytes | static RAM, bytes | per received frame, instructions | "
               "tick body, instructions | CPU load (periodic tasks, 168 MHz) |")
    out.append("|---|---|---|---|---|---|")
    for profile, img, f in figures:
        frame = f"{f['frame']} ({f['frame_what']})" if f["frame"] is not None else "not measured"
        tick = f["tick"] if f["tick"] is not None else "not measured"
        load = f"{f['load']:.1f} %" if f["load"] is not None else "–"
        out.append(f"| `{profile}` | {img.flash} | {img.ram} | {frame} | {tick} | {load} |")
    out.append("")
    out.append("The `amr-spi` image (seed 000, SPI) comes first, in the sections below as before; the")
    out.append("serial images follow, each in its own section, then `pi-spi` (seed 004, SPI). Per received")
    out.append("frame: `amr-spi`'s receive unit; the serial images' link body summed over one frame's bytes;")
    out.append("`pi-spi`'s `on_transfer` per 179-byte transfer. Tick body: `pi-spi`'s is its worst of 20")
    out.append("consecutive ticks, one running the odometry.\n")


def main(d, *profiles):
    out = []
    out.append("# Firmware budgets\n")
    out.append("Regenerate with `bash firmware/budget/run.sh` (board build sizes; instruction counts of the")
    out.append("`qemu` build's Cortex-M4 code under QEMU netduinoplus2, single-stepped by gdb; the board")
    out.append("build's handlers from its disassembly).\n")
    images = [(p, Image(os.path.join(d, p))) for p in profiles]
    sections, figures = [], []
    for p, img in images:
        part = []
        if p == "amr-spi":
            f = amr_spi(part, img)
        elif p == "pi-spi":
            f = pi_spi(part, img)
        else:
            f = serial(part, p, img)
        figures.append((p, img, f))
        sections += part
    overview(out, figures)
    print("\n".join(out + sections))


if __name__ == "__main__":
    main(*sys.argv[1:])
