#!/usr/bin/env bash
# Regenerates the golden vectors with the independent implementations, checks that they equal the
# committed ones, and checks that the Python and nanopb decoders accept the Rust-encoded frames.
# Needs: python3 with `protobuf`, protoc, nanopb (nanopb_generator.py, pb.h, libprotobuf-nanopb), gcc.
set -euo pipefail
cd "$(dirname "$0")"
BUILD=$(mktemp -d)
trap 'rm -rf "$BUILD"' EXIT

# 1. Vectors from Python (protobuf for seed 000, struct for seeds 001/003/004).
python3 gen_amr.py write
if [ -f gen_structs.py ]; then python3 gen_structs.py write; fi

# 2. Vectors from the nanopb C library.
nanopb_generator.py -q -I ../proto -f ../proto/amr.options -D "$BUILD" ../proto/amr.proto
gcc -Wall -Wextra -Werror -O1 -I "$BUILD" -o "$BUILD/nanopb_amr" nanopb_amr.c "$BUILD/amr.pb.c" -lprotobuf-nanopb
"$BUILD/nanopb_amr" encode amr_cases.txt > amr_nanopb.txt 2> amr_nanopb_sizes.txt
python3 gen_amr.py check amr_nanopb.txt
"$BUILD/nanopb_amr" check amr_cases.txt amr_python.txt

# 3. The committed vectors are what the generators produce today.
git diff --exit-code -- . || { echo "golden vectors changed: regenerate and commit them" >&2; exit 1; }

# 4. Rust-encoded frames decode in Python and in nanopb.
cargo run -q -p protocol --example golden_emit -- "$BUILD"
python3 gen_amr.py check "$BUILD/amr_rust.txt"
"$BUILD/nanopb_amr" check amr_cases.txt "$BUILD/amr_rust.txt"
if [ -f gen_structs.py ]; then python3 gen_structs.py check "$BUILD"; fi
echo "golden: all vectors agree"
