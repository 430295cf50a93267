#!/usr/bin/env bash
# Guest instructions of one frame of the int8 network on aarch64, per op kind and whole, with
# the NEON kernels and with the portable ones: `benches/nn.rs` cross-built for
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
printf '%-12s %14s %14s %7s\n' kind portable neon ratio
for k in pw dw conv Resize Concat Add AveragePool; do
  p=$(( ($(count $k 3 SEMLOC_NN_ISA=portable) - $(count $k 1 SEMLOC_NN_ISA=portable)) / 2 ))
  n=$(( ($(count $k 3) - $(count $k 1)) / 2 ))
  printf '%-12s %14d %14d %7.2f\n' "$k" "$p" "$n" "$(awk -v p="$p" -v n="$n" 'BEGIN { print p / n }')"
done
p=$(frame SEMLOC_NN_ISA=portable); n=$(frame SEMLOC_NN_ISA=neon)
printf '%-12s %14d %14d %7.2f\n' "graph" "$p" "$n" "$(awk -v p="$p" -v n="$n" 'BEGIN { print p / n }')"
