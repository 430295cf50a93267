#!/usr/bin/env bash
# Guest instructions of one frame of the int8 network on aarch64, per op kind and whole, with
# the portable kernels, the NEON ones and NEON with the `sdot` 1×1 GEMM: `benches/nn.rs` cross-built for
# aarch64-unknown-linux-gnu and run under qemu-aarch64 with a counting plugin (insn.c).
# QEMU's timings mean nothing, and instructions are not cycles; with no Arm board here this is
# the measure the kernels' changes were judged by (README, "The int8 network on aarch64").
#
# Needs (Debian 12): apt-get install qemu-user gcc-aarch64-linux-gnu gcc;
# rustup target add aarch64-unknown-linux-gnu. Run from anywhere; prints a table.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
gcc -shared -fPIC -O2 -o "$WORK/libinsn.so" firmware-sim/insns/insn.c
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
BENCH=$(cargo bench -p semloc-core --bench nn --target aarch64-unknown-linux-gnu --no-run \
  --message-format=json 2>/dev/null | grep -o '"executable":"[^"]*"' | tail -1 | cut -d'"' -f4)
MODEL="$ROOT/models/artefacts/fastscnn_r2_192x640.slm"
# count KINDS REPS [env...]: guest instructions of the bench table (only whole frames repeat)
count() {
  env SEMLOC_NN_SEQ_ONLY=1 SEMLOC_NN_NOREF=1 SEMLOC_NN_KINDS="$1" SEMLOC_NN_REPS="$2" "${@:3}" \
    qemu-aarch64 -L /usr/aarch64-linux-gnu -plugin "$WORK/libinsn.so" -d plugin "$BENCH" \
    --bench --list 2>&1 | awk '/^insns/ {print $2}'
}
# the whole graph: each repetition runs it twice (timed, then per op)
frame() {
  local a b
  a=$(count none 1 SEMLOC_SLM="$MODEL" "$@"); b=$(count none 3 SEMLOC_SLM="$MODEL" "$@")
  echo $(( (b - a) / 4 ))
}
# three levels: the portable kernels, baseline NEON, NEON with the `sdot` 1×1 GEMM (qemu-aarch64's
# default CPU, `max`, has the dot products; ratios against portable and against NEON)
printf '%-12s %14s %14s %14s %9s %9s\n' kind portable neon dotprod "p/neon" "neon/dot"
row() {
  printf '%-12s %14d %14d %14d %9.2f %9.2f\n' "$1" "$2" "$3" "$4" \
    "$(awk -v p="$2" -v n="$3" 'BEGIN { print p / n }')" "$(awk -v n="$3" -v d="$4" 'BEGIN { print n / d }')"
}
for k in pw dw conv Resize Concat Add AveragePool; do
  p=$(( ($(count $k 3 SEMLOC_NN_ISA=portable) - $(count $k 1 SEMLOC_NN_ISA=portable)) / 2 ))
  n=$(( ($(count $k 3 SEMLOC_NN_ISA=neon) - $(count $k 1 SEMLOC_NN_ISA=neon)) / 2 ))
  d=$(( ($(count $k 3) - $(count $k 1)) / 2 ))
  row "$k" "$p" "$n" "$d"
done
row graph "$(frame SEMLOC_NN_ISA=portable)" "$(frame SEMLOC_NN_ISA=neon)" "$(frame)"
