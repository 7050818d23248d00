#!/usr/bin/env bash
# Boots the real firmware images amr-spi and pi-spi (feature `qemu`) in QEMU's netduinoplus2 (STM32F405, Cortex-M4), feeds it
# link frames from a host file through semihosting, and checks its own per-tick trace:
# frames applied, a corrupted frame rejected without effect, BRAKE at the 9th tick after the link stops (strictly within 10 ms);
# and the feedback frames it wrote (feedback.bin): CRC, µs time stamps, sequence, mode and fault flags.
# Needs qemu-system-arm (Debian: apt-get install qemu-system-arm) and python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo xtask fw-variant qemu
elf="$PWD/target/qemu/thumbv7em-none-eabihf/firmware/amr-spi"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
python3 firmware/qemu/make_frames.py "$work/frames.bin"
# Semihosting paths are relative to QEMU's working directory. The firmware exits QEMU itself
# 15 ticks after the frames end and BRAKE holds; the timeout only catches a hang.
(cd "$work" && timeout 120 qemu-system-arm -machine netduinoplus2 -cpu cortex-m4 -nographic \
  -monitor none -serial none -semihosting-config enable=on,target=native -kernel "$elf") > "$work/trace.txt"
cp "$work/trace.txt" target/qemu/trace.txt
cp "$work/feedback.bin" target/qemu/feedback.bin
python3 firmware/qemu/check_trace.py "$work/trace.txt" "$work/feedback.bin" "$work/frames.bin" "$(git rev-parse HEAD 2>/dev/null || true)"
# The host tool decodes the identity and reset cause from the bytes the firmware wrote (the binary
# named by MOTORLINK if set, as .ci/run sets it to the one `cargo test` built; else cargo builds it).
if [ -n "${MOTORLINK:-}" ]; then
  "$MOTORLINK" info --capture "$work/feedback.bin"
else
  cargo run -q -p motorlink -- info --capture "$work/feedback.bin"
fi

# The seed 004 image (`pi-spi`): its transfers from pi_spi_transfers.bin (packed with Python's struct
# from the seed's declarations), its trace and the TxBuffers it queued checked by pi_spi.py.
elf="$PWD/target/qemu/thumbv7em-none-eabihf/firmware/pi-spi"
python3 firmware/qemu/pi_spi.py make "$work/pi_spi_transfers.bin"
(cd "$work" && timeout 120 qemu-system-arm -machine netduinoplus2 -cpu cortex-m4 -nographic \
  -monitor none -serial none -semihosting-config enable=on,target=native -kernel "$elf") > "$work/pi_spi_trace.txt"
cp "$work/pi_spi_trace.txt" target/qemu/pi_spi_trace.txt
python3 firmware/qemu/pi_spi.py check "$work/pi_spi_trace.txt" "$work/pi_spi_feedback.bin"
