#!/usr/bin/env bash
# Regenerates firmware/BUDGET.md: flash/RAM of the board build, executed instructions of the board
# application's task bodies (`mcu::…`) and of each RTIC handler (Cortex-M4 code of the `qemu` build
# under QEMU, counted by gdb single-stepping: count.py), measured stack use per unit, the board
# build's handler code (handlers.py), the worst-case stack per task from the call graph (stack.sh),
# and the resulting CPU load at 168 MHz. A report, not a test: it takes a few minutes.
# Needs qemu-system-arm, gdb-multiarch, binutils-arm-none-eabi (Debian packages; iproute2's `ss` if present) and python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo fw
cargo build -p firmware --release --target thumbv7em-none-eabihf --features qemu --target-dir target/qemu
board="$PWD/target/thumbv7em-none-eabihf/release/amr-spi"
emu="$PWD/target/qemu/thumbv7em-none-eabihf/release/amr-spi"
work="$(mktemp -d)"
qpid=""
cleanup() {
  # gdb's `kill` normally ends QEMU already; only a QEMU still running is stopped here.
  if [ -n "$qpid" ] && kill -0 "$qpid" 2>/dev/null; then kill "$qpid" || true; fi
  rm -rf "$work"
}
trap cleanup EXIT
python3 firmware/qemu/make_frames.py "$work/frames.bin"
port=$((20000 + RANDOM % 20000))
(cd "$work" && exec qemu-system-arm -machine netduinoplus2 -cpu cortex-m4 -nographic -monitor none \
  -serial none -semihosting-config enable=on,target=native -S -gdb "tcp::$port" -kernel "$emu" \
  > "$work/qemu.log" 2>&1) &
qpid=$!
# QEMU starts halted (-S) and listens for gdb; on a loaded machine that can take a while.
for _ in $(seq 60); do
  # (checked without connecting: a probe connection could let the halted core run on)
  if ! command -v ss > /dev/null; then sleep 2; break; fi
  if ss -ltn "sport = :$port" | grep -q LISTEN; then break; fi
  sleep 0.5
done
GDB_PORT=$port BUDGET_JSON="$work/counts.json" BUDGET_SAMPLES=3 \
  timeout 1200 gdb-multiarch -batch -x firmware/budget/count.py "$emu" > "$work/gdb.log" 2>&1 || true
if [ ! -s "$work/counts.json" ]; then
  echo "instruction counting failed; gdb said:" >&2
  tail -n 30 "$work/gdb.log" >&2
  exit 1
fi
arm-none-eabi-size -A "$board" > "$work/size.txt"
python3 firmware/budget/handlers.py board="$board" qemu="$emu" > "$work/handlers.json"
bash firmware/budget/stack.sh > "$work/stack.md"
python3 firmware/budget/report.py "$work/size.txt" "$work/counts.json" "$work/stack.md" \
  "$work/handlers.json" > "$work/BUDGET.md"
mv "$work/BUDGET.md" firmware/BUDGET.md
echo "wrote firmware/BUDGET.md"
