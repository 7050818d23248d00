#!/usr/bin/env bash
# Regenerates firmware/BUDGET.md for every image (amr-spi, cdc, teensy, pi-spi): flash/RAM of the board build,
# executed instructions of the board application's task bodies (`mcu::…`) and of each RTIC handler
# (Cortex-M4 code of the `qemu` build under QEMU, counted by gdb single-stepping: count.py), measured
# stack use per unit, the board build's handler code (handlers.py), the worst-case stack per task from
# the call graph (stack.sh), and the resulting CPU load at 168 MHz. A report, not a test: it takes
# several minutes (about a quarter of an hour on a loaded 2-core machine).
# amr-spi reads its link frames from a host file (firmware/qemu/make_frames.py), pi-spi its transfers
# (firmware/qemu/pi_spi.py make-budget); the serial images get their bytes on USART1, which QEMU
# serves on a local TCP port that count.py writes to.
# Needs qemu-system-arm, gdb-multiarch, binutils-arm-none-eabi (Debian packages; iproute2's `ss` if present) and python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo fw
cargo xtask fw-variant qemu
profiles=(amr-spi cdc teensy pi-spi)
work="$(mktemp -d)"
qpid=""
stop_qemu() {
  # gdb's `kill` normally ends QEMU already; only a QEMU still running is stopped here.
  if [ -n "$qpid" ] && kill -0 "$qpid" 2>/dev/null; then kill "$qpid" || true; fi
  qpid=""
}
cleanup() {
  stop_qemu
  rm -rf "$work"
}
trap cleanup EXIT
# Semihosting paths are relative to QEMU's working directory ($work): each image opens its own file.
python3 firmware/qemu/make_frames.py "$work/frames.bin"
python3 firmware/qemu/pi_spi.py make-budget "$work/pi_spi_transfers.bin"
for profile in "${profiles[@]}"; do
  out="$work/$profile"
  mkdir -p "$out"
  board="$PWD/target/thumbv7em-none-eabihf/firmware/$profile"
  emu="$PWD/target/qemu/thumbv7em-none-eabihf/firmware/$profile"
  port=$((20000 + RANDOM % 20000))
  link=(-serial none)
  serial_env=()
  if [ "$profile" != amr-spi ] && [ "$profile" != pi-spi ]; then
    link=(-chardev "socket,id=link,host=127.0.0.1,port=$((port + 1)),server=on,wait=off" -serial chardev:link)
    serial_env=(BUDGET_SERIAL_PORT=$((port + 1)))
  fi
  (cd "$work" && exec qemu-system-arm -machine netduinoplus2 -cpu cortex-m4 -nographic -monitor none \
    "${link[@]}" -semihosting-config enable=on,target=native -S -gdb "tcp::$port" -kernel "$emu" \
    > "$out/qemu.log" 2>&1) &
  qpid=$!
  # QEMU starts halted (-S) and listens for gdb; on a loaded machine that can take a while.
  for _ in $(seq 60); do
    # (checked without connecting: a probe connection could let the halted core run on)
    if ! command -v ss > /dev/null; then sleep 2; break; fi
    if ss -ltn "sport = :$port" | grep -q LISTEN; then break; fi
    sleep 0.5
  done
  env GDB_PORT=$port BUDGET_PROFILE="$profile" BUDGET_JSON="$out/counts.json" BUDGET_SAMPLES=3 \
    "${serial_env[@]}" timeout 1200 gdb-multiarch -batch -x firmware/budget/count.py "$emu" \
    > "$out/gdb.log" 2>&1 || true
  stop_qemu
  if [ ! -s "$out/counts.json" ]; then
    echo "instruction counting failed for $profile; gdb said:" >&2
    tail -n 30 "$out/gdb.log" >&2
    exit 1
  fi
  arm-none-eabi-size -A "$board" > "$out/size.txt"
  python3 firmware/budget/handlers.py board="$board" qemu="$emu" > "$out/handlers.json"
  bash firmware/budget/stack.sh "$profile" > "$out/stack.md"
  echo "counted $profile"
done
python3 firmware/budget/report.py "$work" "${profiles[@]}" > "$work/BUDGET.md"
mv "$work/BUDGET.md" firmware/BUDGET.md
echo "wrote firmware/BUDGET.md"
