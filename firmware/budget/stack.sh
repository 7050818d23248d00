#!/usr/bin/env bash
# Worst-case stack per RTIC task: builds the board firmware with `-Z emit-stack-sizes` (LLVM writes
# every function's frame size into a `.stack_sizes` section) and walks the call graph of its
# disassembly (firmware/budget/stack.py). Prints a Markdown section; run.sh puts it in BUDGET.md.
# Usage: stack.sh [PROFILE]   (the image: amr-spi, the default, cdc, teensy or pi-spi)
#
# The flag is unstable. RUSTC_BOOTSTRAP=1 lets the pinned stable compiler accept it, so the analysed
# code is what that compiler generates for `cargo fw` (same version, same profile; the flag only adds
# the section). A separate target dir keeps the board build untouched. (A nightly toolchain would
# need its own thumbv7em rust-std or `-Z build-std`, and would analyse another compiler's code.)
# Needs binutils-arm-none-eabi (objdump, nm, objcopy, c++filt) and python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
RUSTC_BOOTSTRAP=1 RUSTFLAGS="-Z emit-stack-sizes" \
  cargo build -q -p firmware --profile firmware --target thumbv7em-none-eabihf --target-dir target/stack >&2
profile="${1:-amr-spi}"
python3 firmware/budget/stack.py "target/stack/thumbv7em-none-eabihf/firmware/$profile" "$profile"
