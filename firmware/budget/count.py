"""gdb script: counts executed Cortex-M4 instructions per call of the firmware's units under QEMU.


Loaded by run.sh as `gdb-multiarch -batch -x count.py ELF`. For each unit it stops at its first
instruction, single-steps (`stepi`) until the unit returns, counting the steps (the return instruction included
for functions; for handlers, up to and including the exception return). It also records the
deepest stack pointer seen below the entry SP (the handler's own stack use, excluding the
hardware-stacked exception frame).

Units are the board application's task bodies (`mcu::…`, kept out of line for this count) and the
RTIC handlers, named by their interrupt symbols; a profile's list (AMR_SPI, CDC, TEENSY, PI_SPI)
is chosen by BUDGET_PROFILE. Per call it also records:
- `own`: instructions inside the unit's symbol itself (the rest ran in functions it called), so
  report.py can replace a handler's own code by the board build's, which differs from the `qemu`
  build's;
- `emulator` (`emulator_own`: of those, inside the symbol): instructions of the emulator's
  stand-ins (`firmware::board::emu`, semihosting), by the debug info of the code that executed
  (inlined code included); the board does not run them;
- `skipped`: calls run through without counting because they only print the emulator's trace
  (`core::fmt`, semihosting output); their instructions are in no figure;
- `traced`: instructions spent recording a trace entry (`mcu::trace::Trace::push`), 0 for a call
  that recorded nothing.
And for the sampled call with the most instructions:
- `by_function`: instructions per function, inlined code counted in the inlined function;
- `inclusive`: per `mcu::` function, every instruction executed while it was active (its own code,
  code inlined into it, and the functions it called), so a body inlined into its handler, such as
  `mcu::speed::SpeedLoop::run`, still gets its own figure. Calls are followed by the return
  address they leave in `lr`.

Symbols are looked up in the ELF's symbol table (`arm-none-eabi-nm`), not by gdb's expression
scope: stopped inside an RTIC task, `ADC` names the app module's `firmware::app::ADC` type.
"""
import gdb  # noqa: F401  (provided by gdb)
import json
import os
import re
import socket
import subprocess
import sys
import time

# Run by gdb from the repository root (run.sh); serial_frames.py sits beside this script.
sys.path.insert(0, os.path.join("firmware", "budget"))
import serial_frames  # noqa: E402

OUT = os.environ["BUDGET_JSON"]
SAMPLES = int(os.environ.get("BUDGET_SAMPLES", "5"))

# GPIOD input data register and the ESTOP input's bit (PD4, high = pressed).
GPIOD_IDR = 0x4002_0C10
ESTOP_BIT = 1 << 4
# NVIC interrupt set-pending registers; interrupt numbers of the handlers QEMU never triggers.
NVIC_ISPR = 0xE000_E200
IRQ_EXTI4 = 10
IRQ_USART1 = 37
IRQ_UART4 = 52
# SCB interrupt control and state register and its SysTick pending-clear bit.
SCB_ICSR = 0xE000_ED04
PENDSTCLR = 1 << 25
# ADC1 status register and its end-of-conversion bit: QEMU's ADC never sets it (the `cdc` image's
# battery reading would poll until its timeout); it reads set at the first poll.
ADC1_SR = 0x4001_2000
ADC_EOC = 1 << 1
# Scratch word for `pend`: the far end of the stack (flip-link puts the stack below the statics,
# growing down towards the start of RAM; no run comes near it).
STUB = 0x2000_0000

# name, symbol, kind ("fn" returns to its caller; "isr" returns from the exception), options.
# The ESTOP press comes last: it latches ESTOP, so every later tick would run braked.
AMR_SPI = [
    ("frame: receive (CRC + decode + validate + ladder step)", "mcu::link::LinkTask::receive", "fn", {}),
    ("frame: feedback (encode feedback frame)", "mcu::link::LinkTask::feedback", "fn", {}),
    ("tick: run (conditions + ladder step)", "mcu::tick::TickTask::run", "fn", {}),
    ("current_loop handler (ADC)", "ADC", "isr", {}),
    ("speed_pid handler (TIM5)", "TIM5", "isr", {}),
    ("watchdog_tick handler (TIM2)", "TIM2", "isr", {}),
    ("spi_dma_done handler (DMA1_STREAM3)", "DMA1_STREAM3", "isr", {}),
    # A mode change, latch or re-arm: one trace entry and its defmt log line (in a critical section;
    # with no host attached, the RTT write does not block). The first ones after the units above
    # come when the frames stop: four (HOLD, STOP, BRAKE, the latch), so at most three are sampled.
    ("trace: one record (ring entry + defmt log line)", "mcu::trace::Trace::push", "fn",
     {"samples": min(SAMPLES, 3)}),
    # QEMU models no GPIO and no EXTI line: the interrupt is pended through the NVIC, and the pin
    # reads pressed (the bit is set in the register the handler loaded the input data into).
    ("estop_input handler (EXTI4), press edge", "EXTI4", "isr",
     {"pend": IRQ_EXTI4, "force_load": {GPIOD_IDR: ESTOP_BIT}, "samples": 1}),
]
# The serial images (seed 001 `cdc`, seed 003 `teensy`): USART1 bytes fed by this script through
# QEMU's `-serial` (option "feed": one byte per sample from serial_frames.FEEDS, the link task's body
# or handler counted for each); ticks sampled with the link alive (option "keepalive": a whole frame
# sent every 20 ticks, as the host's 50 Hz). The ESTOP frames and the press come last (latches).
LINK_BYTE = "link: one received byte"
# The link tasks' bodies: one call per received byte.
CDC_BYTE = "mcu::cdc::CdcLinkTask::on_byte"
TEENSY_BYTE = "mcu::teensy::TeensyLinkTask::on_byte"
USART1 = "link_usart handler (USART1), one received byte"
SERIAL_TICK = ("tick: run (ESTOP input, supply, ladder tick)", "mcu::serial::tick", "fn",
               {"keepalive": True})
# What one transmit interrupt costs on the board (QEMU's USART takes every byte at once, so the
# emulator never raises one): the interrupt pended with nothing received and nothing queued.
USART1_IDLE = ("link_usart handler (USART1), nothing received or queued", "USART1", "isr",
               {"pend": IRQ_USART1, "samples": 1})
# The ladder enters REDUCED when it leaves the power-on BRAKE (a recent HOLD episode) and returns
# to NORMAL after a clean window of 1000 ticks: frames are counted in NORMAL after this many ticks.
SETTLE = 1000
# Once the units above are counted the link stops: HOLD, STOP and BRAKE each record a trace entry.
# The commands then start from BRAKE.
TRACE_UNIT = ("trace: one record (ring entry + defmt log line)", "mcu::trace::Trace::push", "fn",
              {"samples": min(SAMPLES, 3)})
ESTOP_PRESS = ("estop_input handler (EXTI4), press edge", "EXTI4", "isr",
               {"pend": IRQ_EXTI4, "force_load": {GPIOD_IDR: ESTOP_BIT}, "samples": 1})
CDC = [
    (LINK_BYTE + ", enable", CDC_BYTE, "fn", {"feed": "cdc-enable"}),
    (LINK_BYTE + ", drive", CDC_BYTE, "fn", {"settle": SETTLE, "feed": "cdc-drive"}),
    (USART1, "USART1", "isr", {"feed": "cdc-usart"}),
    USART1_IDLE,
    SERIAL_TICK,
    ("watchdog_tick handler (TIM2)", "TIM2", "isr", {"keepalive": True}),
    # STATUS goes out every 100 ticks: the tick after the one that sent a STATUS, plus 99.
    ("watchdog_tick handler (TIM2), periodic STATUS", "TIM2", "isr",
     {"keepalive": True, "after_reply": (serial_frames.STATUS_PREFIX, 100), "samples": 1}),
    ("imu_read handler (TIM3)", "TIM3", "isr", {"keepalive": True, "force_load": {ADC1_SR: ADC_EOC}}),
    TRACE_UNIT,
    (LINK_BYTE + ", commands", CDC_BYTE, "fn", {"feed": "cdc-commands"}),
    ESTOP_PRESS,
]
TEENSY = [
    (LINK_BYTE + ", enable", TEENSY_BYTE, "fn", {"feed": "teensy-enable"}),
    (LINK_BYTE + ", drive", TEENSY_BYTE, "fn",
     {"settle": SETTLE, "feed": "teensy-drive"}),
    (USART1, "USART1", "isr", {"feed": "teensy-usart"}),
    USART1_IDLE,
    SERIAL_TICK,
    ("watchdog_tick handler (TIM2)", "TIM2", "isr", {"keepalive": True}),
    # The joints move (the frames above changed the pose): every joint steps.
    ("step generator: run", "mcu::teensy::StepGen::run", "fn", {}),
    ("step_gen handler (TIM5)", "TIM5", "isr", {}),
    TRACE_UNIT,
    ESTOP_PRESS,
]
# The seed 004 image (`pi-spi`): like amr-spi, its transfers come from a host file
# (pi_spi_transfers.bin, written by `firmware/qemu/pi_spi.py make-budget`: a shutdown transfer, then
# one every 10 ticks, the seed's 100 Hz, with the four motor modes mixed and every costly update
# flag set), one record per tick; SysTick pends the tick (TIM7), the tick pends the link task
# (DMA1_STREAM3) and, every 10th tick, imu_read (UART4). The ladder re-arms at tick 20 and holds
# REDUCED for 1000 clean ticks: counting starts after that.
PI_TRANSFER = "mcu::pi_spi::PiSpiApp::on_transfer"
PI_TICK = "mcu::pi_spi::PiSpiApp::tick"
# Consecutive calls sampled where one in ten differs: a transfer arrives in one tick of ten (the
# link task runs every tick and finds no record in the other nine), the odometry runs in one tick
# of ten, and its full integration only in one of twenty (the transfers reconfigure the kinematics
# every other time, and the odometry update right after a configuration only takes the counts).
PI_CONSECUTIVE = 20
PI_SPI = [
    ("transfer: on_transfer (shutdown bits, checks, decode, ladder, one-shot updates, next TxBuffer)",
     PI_TRANSFER, "fn", {"settle": SETTLE + 100}),
    ("spi_dma_done handler (DMA1_STREAM3), 20 consecutive ticks (2 with a transfer)", "DMA1_STREAM3", "isr",
     {"samples": PI_CONSECUTIVE}),
    ("tick: run (ladder tick, four motor loops, odometry every 10th tick), 20 consecutive ticks",
     PI_TICK, "fn", {"samples": PI_CONSECUTIVE}),
    ("watchdog_tick handler (TIM7), 20 consecutive ticks", "TIM7", "isr", {"samples": PI_CONSECUTIVE}),
    # QEMU models no I2C: the `qemu` build's sensor is absent, so the body runs the fusion's
    # `sensor_lost`, not `ImuFusion::update`; the ADC scan is the emulator's (every input 0).
    # Under QEMU the priority-1 task never gets to run by itself: the emulated core is slower than
    # the host's clock, which drives SysTick, so the emulator's tick source (SysTick, priority 1
    # too, and taken first at equal priority) is pending again whenever the tick ends. So each
    # sample pends UART4 as the tick does, and clears SysTick's pending bit (one emulated tick is
    # dropped) so the task runs before the next tick.
    ("imu_read handler (UART4), sensor absent (ImuFusion::sensor_lost)", "UART4", "isr",
     {"pend": IRQ_UART4, "store": (SCB_ICSR, PENDSTCLR)}),
    TRACE_UNIT,
    ESTOP_PRESS,
]
PROFILE = os.environ.get("BUDGET_PROFILE", "amr-spi")
UNITS = {"amr-spi": AMR_SPI, "cdc": CDC, "teensy": TEENSY, "pi-spi": PI_SPI}[PROFILE]
# The tick's handler: TIM2 on the seed 000–003 boards, TIM7 on seed 004's.
TICK_HANDLER = {"pi-spi": "TIM7"}.get(PROFILE, "TIM2")
KEEPALIVE = serial_frames.KEEPALIVE.get(PROFILE)
LINK_BODY = {"cdc": CDC_BYTE, "teensy": TEENSY_BYTE}.get(PROFILE)
# Calls run through uncounted: the emulator's trace printing (the board prints nothing per tick).
SKIP = re.compile(r"core::fmt::|cortex_m_semihosting::|fixed::display::|as core::fmt::")
# Code the board does not run: the emulator's link and hooks, semihosting (`pi-spi`'s hooks live
# in its board module: on the board `after_tick` is empty).
EMULATOR = ("firmware::board::emu", "cortex_m_semihosting", "firmware::board::pi_spi::hooks")
# The trace's entry point: a call that records a mode change, latch or re-arm runs it.
TRACE_PUSH = "mcu::trace::Trace::push"
LOAD = re.compile(r"^ldr(?:\.w)?\s+(r\d+|ip|lr),\s*\[(r\d+|ip|lr|sp)(?:,\s*#(-?\d+))?\]")


def reg(name):
    return int(gdb.parse_and_eval("$" + name)) & 0xFFFFFFFF


def set_reg(name, value):
    gdb.execute(f"set var ${name} = {value & 0xFFFFFFFF:#x}", to_string=True)


def elf_symbols(elf):
    """Demangled name → (address, size) of every function symbol (first of duplicates)."""
    out = subprocess.run(["arm-none-eabi-nm", "-C", "-S", "--defined-only", elf],
                         check=True, capture_output=True, text=True).stdout
    syms = {}
    for line in out.splitlines():
        parts = line.split(maxsplit=3)
        if len(parts) == 4 and parts[2] in "Tt":
            name = re.sub(r"::h[0-9a-f]{16}$", "", parts[3])
            syms.setdefault(name, (int(parts[0], 16) & ~1, int(parts[1], 16)))
    return syms


def chain_at(pc, cache={}):
    """Functions whose code holds `pc`, innermost first (inlined ones included), by the debug info."""
    if pc not in cache:
        names = []
        try:
            block = gdb.block_for_pc(pc)
            while block is not None:
                if block.function is not None:
                    names.append(block.function.print_name)
                block = block.superblock
        except RuntimeError:
            pass
        cache[pc] = tuple(names) or ("?",)
    return cache[pc]


def pend(irq):
    """Sets an interrupt pending (see `core_store`)."""
    core_store(NVIC_ISPR + 4 * (irq // 32), 1 << (irq % 32))


def core_store(address, value):
    """Writes a system register (the NVIC's, the SCB's). gdb cannot: QEMU's debug writes reach RAM
    and ROM only. So the core itself executes one `str r1, [r0]` placed in RAM, with the registers
    it touches restored after it (single steps run with interrupts masked: an interrupt set
    pending is taken at the next `continue`)."""
    inf = gdb.selected_inferior()
    saved = {r: reg(r) for r in ("pc", "r0", "r1")}
    old = bytes(inf.read_memory(STUB, 2))
    inf.write_memory(STUB, b"\x01\x60")  # str r1, [r0]
    set_reg("r0", address)
    set_reg("r1", value)
    set_reg("pc", STUB)
    gdb.execute("stepi", to_string=True)
    for r, v in saved.items():
        set_reg(r, v)
    inf.write_memory(STUB, old)


def run_through(ret):
    """Runs a call to its return address `ret` without counting (interrupts may run meanwhile)."""
    bp = gdb.Breakpoint("*" + hex(ret), internal=True, temporary=True)
    gdb.execute("continue", to_string=True)
    if bp.is_valid():
        bp.delete()


def count_call(kind, unit_range, skip_entries, force_load, stats):
    ipsr0 = reg("xpsr") & 0x1FF
    sp0 = reg("sp")
    lr0 = reg("lr") & ~1
    n = own = emulator = emulator_own = skipped = traced = 0
    min_sp = sp0
    executed = reg("pc")  # the instruction the next step executes
    arch = gdb.selected_frame().architecture()
    # Calls in progress: (return address, SP at the call, functions active at the call site).
    calls = []
    pcs, inclusive = {}, {}
    # QEMU's gdb stub single-steps with interrupts masked, so nothing preempts the unit: a
    # function ends when it returns to its caller, a handler when the core leaves its exception.
    while n < 50000:
        forced = None
        if force_load:
            m = LOAD.match(arch.disassemble(executed)[0]["asm"])
            if m and m.group(2) != "sp":
                address = (reg(m.group(2)) + int(m.group(3) or 0)) & 0xFFFFFFFF
                if address in force_load:
                    forced = (m.group(1), force_load[address])
        gdb.execute("stepi", to_string=True)
        if forced is not None:
            set_reg(forced[0], reg(forced[0]) | forced[1])
        ipsr = reg("xpsr") & 0x1FF
        if kind == "isr" and ipsr != ipsr0:
            break
        # A handler that returns while its own interrupt is pending again (a timer's next period
        # passed during an uncounted run-through) tail-chains into itself: the exception number
        # stays the same and the core is back at the handler's first instruction.
        if kind == "isr" and n > 0 and reg("pc") == unit_range[0] and reg("sp") >= sp0:
            break
        n += 1
        chain = chain_at(executed)
        active = set(chain).union(*(c[2] for c in calls))
        for f in active:
            if f.startswith("mcu::"):
                inclusive[f] = inclusive.get(f, 0) + 1
        traced += TRACE_PUSH in active
        pcs[executed] = pcs.get(executed, 0) + 1
        mine = unit_range[0] <= executed < unit_range[1]
        own += mine
        if any(f.startswith(EMULATOR) for f in chain):
            emulator += 1
            emulator_own += mine
        pc = reg("pc")
        sp = reg("sp")
        # A call (`bl`, `blx`): `lr` holds the address after the instruction, `pc` went elsewhere.
        ret = reg("lr") & ~1
        if ret in (executed + 2, executed + 4) and pc != ret:
            calls.append((ret, sp, set(chain).union(*(c[2] for c in calls))))
        if pc in skip_entries:
            run_through(ret)
            skipped += 1
            pc = reg("pc")
            sp = reg("sp")
        while calls and pc == calls[-1][0] and sp >= calls[-1][1]:
            calls.pop()
        executed = pc
        min_sp = min(min_sp, sp)
        if kind == "fn" and pc == lr0 and sp >= sp0:
            break
    stats["instructions"].append(n)
    stats["stack_bytes"].append(sp0 - min_sp)
    stats["own"].append(own)
    stats["emulator"].append(emulator)
    stats["emulator_own"].append(emulator_own)
    stats["skipped"].append(skipped)
    stats["traced"].append(traced)
    # The profile of the call with the most instructions (the worst sampled case).
    if n >= max(stats["instructions"]):
        stats["pcs"], stats["inclusive"] = pcs, inclusive


class Link:
    """The guest's USART1 as QEMU serves it on a TCP socket (`-serial` on a server chardev).

    QEMU's USART holds one received byte until the firmware reads it, and QEMU's I/O thread moves
    the next one in at whatever pace the (loaded) host gives it: sent while the firmware ran, a
    byte took several emulated milliseconds to arrive, long enough for a frame to age the ladder
    into HOLD. So each byte is handed over while the core is halted (`put`): sent, then the core
    resumes once the USART's RXNE flag (read by gdb, which QEMU answers without side effects)
    shows QEMU has taken it."""

    # USART1 status register and its receive-not-empty flag.
    SR = 0x4001_1000
    RXNE = 1 << 5

    def __init__(self, port):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=30)

    def put(self, byte):
        self.sock.sendall(bytes([byte]))
        inf = gdb.selected_inferior()
        for _ in range(2000):
            if int.from_bytes(bytes(inf.read_memory(self.SR, 4)), "little") & self.RXNE:
                return
            time.sleep(0.001)
        raise gdb.error("QEMU did not take a byte within 2 s")

    def drain(self):
        """What the guest sent so far (its replies)."""
        got = b""
        self.sock.setblocking(False)
        try:
            while True:
                chunk = self.sock.recv(4096)
                if not chunk:
                    break
                got += chunk
        except BlockingIOError:
            pass
        self.sock.setblocking(True)
        return got


def deliver(syms, link, frame):
    """Hands `frame` to the firmware byte by byte, each taken by its link task (uncounted)."""
    body = gdb.Breakpoint("*" + hex(syms[LINK_BODY][0]), internal=True)
    for b in frame:
        link.put(b)
        gdb.execute("continue", to_string=True)
    body.delete()


def run_ticks(syms, n, link=None):
    """Lets the firmware run uncounted until `n` more ticks (tick handler entries: TIM2, `pi-spi`'s
    TIM7) have begun; with `link`, the keepalive frame goes out every 20 ticks, as the host would
    send it."""
    tim2 = gdb.Breakpoint("*" + hex(syms[TICK_HANDLER][0]), internal=True)
    tim2.enabled = False
    while n > 0:
        chunk = min(n, KEEPALIVE[1]) if link else n
        if link:
            deliver(syms, link, KEEPALIVE[0])
        tim2.enabled = True
        tim2.ignore_count = chunk - 1
        gdb.execute("continue", to_string=True)
        tim2.enabled = False
        n -= chunk
    tim2.delete()


def find_phase(syms, link, prefix, period):
    """Runs tick by tick (the link alive) until a reply starting with `prefix` arrives, then on to
    the tick before the next one (`period` ticks later); returns the replies seen."""
    seen = b""
    for k in range(period + 1):
        if k % KEEPALIVE[1] == 0:
            deliver(syms, link, KEEPALIVE[0])
        run_ticks(syms, 1)
        seen += link.drain()
        if prefix in seen:
            run_ticks(syms, period - 2, link)
            return seen
    raise gdb.error(f"no reply {prefix.hex()} within {period} ticks")


def main():
    gdb.execute("set pagination off")
    gdb.execute("set confirm off")
    syms = elf_symbols(gdb.current_progspace().filename)
    skip_entries = {a for name, (a, _) in syms.items() if SKIP.search(name)}
    gdb.execute("target remote :" + os.environ.get("GDB_PORT", "3333"))
    serial_port = os.environ.get("BUDGET_SERIAL_PORT")
    link = Link(int(serial_port)) if serial_port else None
    if link:
        # QEMU drops what arrives before the firmware has enabled USART1: feed only once it ticks.
        run_ticks(syms, 1)
    results = {}
    # BUDGET_ONLY=receive counts only the units whose symbol contains that text (for quick looks).
    only = os.environ.get("BUDGET_ONLY", "")
    for title, sym, kind, opts in UNITS:
        if only not in sym:
            continue
        # At the unit's first instruction (`*address`), not after the prologue where gdb puts a
        # breakpoint on a name: the prologue may already use `lr` as a scratch register, and the
        # return address is read from `lr` at the stop.
        address, size = syms[sym]
        started = time.time()
        if "settle" in opts:
            run_ticks(syms, opts["settle"], link)
        bp = gdb.Breakpoint("*" + hex(address), internal=True)
        stats = {"instructions": [], "stack_bytes": [], "own": [], "emulator": [],
                 "emulator_own": [], "skipped": [], "traced": [], "pcs": {}, "inclusive": {}}
        feed = serial_frames.schedule(opts["feed"]) if "feed" in opts else None
        samples = len(feed) if feed else opts.get("samples", SAMPLES)
        try:
            for i in range(samples):
                if "pend" in opts:
                    pend(opts["pend"])
                if "store" in opts:
                    core_store(*opts["store"])
                if "after_reply" in opts:
                    bp.enabled = False
                    find_phase(syms, link, *opts["after_reply"])
                    bp.enabled = True
                if feed:
                    link.put(feed[i][3])
                elif opts.get("keepalive") and i % KEEPALIVE[1] == 0:
                    bp.enabled = False
                    deliver(syms, link, KEEPALIVE[0])
                    bp.enabled = True
                gdb.execute("continue", to_string=True)
                bp.enabled = False
                count_call(kind, (address, address + size), skip_entries, opts.get("force_load"), stats)
                if feed:
                    stats.setdefault("fed", []).append(list(feed[i][:4]))
                    if feed[i][4]:
                        run_ticks(syms, feed[i][4])
                bp.enabled = True
                if link:
                    stats["replies"] = stats.get("replies", "") + link.drain().hex()
        except gdb.error as e:
            # Typically the firmware ended (frames.bin exhausted) before the unit ran often enough:
            # the units counted so far are kept, report.py lists this one as not measured.
            results["_failed"] = f"{title}: {e}"
            break
        bp.delete()
        # Instructions per function in the worst sampled call: `by_function` counts inlined code in
        # the inlined function (innermost); `inclusive` counts, for each `mcu::` function,
        # everything executed while it was active (inlined into the code running, or waiting for
        # a call it made).
        by_fn = {}
        for pc, k in stats.pop("pcs").items():
            f = chain_at(pc)[0]
            by_fn[f] = by_fn.get(f, 0) + k
        stats["by_function"] = dict(sorted(by_fn.items(), key=lambda x: -x[1]))
        stats["inclusive"] = dict(sorted(stats["inclusive"].items(), key=lambda x: -x[1]))
        stats["symbol"] = sym
        results[title] = stats
        print(f"counted {title}: {len(stats['instructions'])} calls, {time.time() - started:.0f} s")
    with open(OUT, "w") as f:
        json.dump(results, f, indent=1)
    if "_failed" not in results:
        gdb.execute("kill")


main()
