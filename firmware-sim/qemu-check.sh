#!/usr/bin/env bash
# Bare-metal check of semloc-firmware-sim (see firmware-sim/README.md):
#  1. builds the aarch64-unknown-none image, the thumbv7em size probe and the host runner;
#  2. runs the embedded frames on the host (x86-64, std) and under
#     qemu-system-aarch64 -M virt (semihosting), with a timeout, on a Cortex-A72 (baseline NEON
#     kernels) and on a Cortex-A76 (the `sdot` 1×1 GEMM), twice each run: geometric (ORB +
#     stereo + tracker) and semantic (int8 network + semantic ORB + EM);
#  3. requires all to exit 0 (tracked in both runs), the output to be non-empty and, after
#     dropping the target-specific `@` lines, byte-identical: the same f64 pose bits, label
#     hashes and pose hashes;
#  4. prints the section sizes of both bare-metal builds;
#  5. with SEMLOC_BIN=path/to/semloc, also requires the poses to be bit-identical to the host
#     pipeline's (`semloc run --threads 1`, see host_pipeline_check.py).
# Exit 0 only if all of that holds. Environment: CARGO_TARGET_DIR (default: target/),
# QEMU (default: qemu-system-aarch64), QEMU_TIMEOUT_S (default: 300), SEMLOC_BIN (optional).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
QEMU="${QEMU:-qemu-system-aarch64}"
TIMEOUT_S="${QEMU_TIMEOUT_S:-300}"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

command -v "$QEMU" >/dev/null || {
  echo "qemu-check: $QEMU not found (Debian/Ubuntu: apt-get install qemu-system-arm)" >&2
  exit 1
}

echo "== build"
cargo build --release -p semloc-firmware-sim --target aarch64-unknown-none --bin qemu_aarch64
cargo build --release -p semloc-firmware-sim --target thumbv7em-none-eabihf --bin thumbv7em_size
cargo build --release -p semloc-firmware-sim --bin host_poses
IMG="$CARGO_TARGET_DIR/aarch64-unknown-none/release/qemu_aarch64"
PROBE="$CARGO_TARGET_DIR/thumbv7em-none-eabihf/release/thumbv7em_size"
HOST="$CARGO_TARGET_DIR/release/host_poses"

echo "== host (x86-64, std)"
host_rc=0
"$HOST" >"$WORK/host.txt" || host_rc=$?
echo "host_poses exit status $host_rc"

# run_qemu CPU: the image on that CPU; its semihosting output in $WORK/qemu-CPU.txt, the exit
# status in $WORK/qemu-CPU.rc
run_qemu() {
  local cpu=$1 rc=0 t0 t1
  echo "== qemu ($QEMU -M virt -cpu $cpu, timeout ${TIMEOUT_S}s)"
  t0=$(date +%s%N)
  # Semihosting output goes to a file chardev: without one QEMU picks stdout or stderr
  # depending on how its own stdio is set up.
  : >"$WORK/qemu-$cpu.txt"
  timeout "$TIMEOUT_S" "$QEMU" -M virt -cpu "$cpu" -m 512M -nographic -monitor none \
    -chardev "file,id=semihost,path=$WORK/qemu-$cpu.txt" \
    -semihosting-config enable=on,target=native,chardev=semihost -kernel "$IMG" \
    </dev/null >"$WORK/qemu-$cpu.log" 2>&1 || rc=$?
  t1=$(date +%s%N)
  echo "qemu exit status $rc, wall $(( (t1 - t0) / 1000000 )) ms"
  echo "$rc" >"$WORK/qemu-$cpu.rc"
  cat "$WORK/qemu-$cpu.log" >&2
  grep '^@' "$WORK/qemu-$cpu.txt" || true
  # Semihosting writes the bytes as they are; drop CRs a terminal layer might add.
  tr -d '\r' <"$WORK/qemu-$cpu.txt" | grep -v '^@' >"$WORK/qemu-$cpu.cmp" || true
}
# The Cortex-A72 (ARMv8.0) runs the baseline NEON kernels; the Cortex-A76 (ARMv8.2) has the dot
# products, so its 1×1 convs take the `sdot` GEMM (the image's `@ kernels` line says which).
CPUS=(cortex-a72 cortex-a76)
for cpu in "${CPUS[@]}"; do run_qemu "$cpu"; done
grep -v '^@' "$WORK/host.txt" >"$WORK/host.cmp" || true

echo "== sizes (bytes; aarch64 'other' is the 320 MiB NOLOAD stack)"
python3 firmware-sim/elf_sizes.py "$PROBE" "$IMG"

echo "== result"
fail=0
if [ "$host_rc" -ne 0 ]; then echo "FAIL: host_poses exited $host_rc"; fail=1; fi
for cpu in "${CPUS[@]}"; do
  rc=$(cat "$WORK/qemu-$cpu.rc")
  if [ "$rc" -ne 0 ]; then echo "FAIL: qemu -cpu $cpu exited $rc (124: timeout)"; fail=1; fi
done
# each CPU ran the 1×1 GEMM it was meant to: otherwise the second run checks nothing new
grep -q '^@ kernels: [0-9]* 1x1 (NEON)' "$WORK/qemu-cortex-a72.txt" || {
  echo "FAIL: the Cortex-A72 run did not report the NEON 1x1 GEMM"; fail=1; }
grep -q '^@ kernels: [0-9]* 1x1 (sdot)' "$WORK/qemu-cortex-a76.txt" || {
  echo "FAIL: the Cortex-A76 run did not report the sdot 1x1 GEMM"; fail=1; }
# the frame stack the ECU simulation reports (`FRAME_STACK_*_BYTES` in firmware-sim/src/sim/mod.rs)
# must cover what the image measures, or its reports would understate the stack an ECU needs
stack_const() {
  sed -n "s/^pub const FRAME_STACK_$1_BYTES: usize = \([0-9_]*\);/\1/p" firmware-sim/src/sim/mod.rs | tr -d _
}
for pass in geometric semantic; do
  budget=$(stack_const "${pass^^}")
  for cpu in "${CPUS[@]}"; do
    peak=$(sed -n "s/^@ $pass pass .*frame stack peak \([0-9]*\) bytes.*/\1/p" "$WORK/qemu-$cpu.txt")
    if [ -z "$budget" ] || [ -z "$peak" ]; then
      echo "FAIL: no $pass frame stack figure (constant '${budget}', $cpu peak '${peak}')"; fail=1
    elif [ "$peak" -gt "$budget" ]; then
      echo "FAIL: the $pass pass used $peak bytes of stack on the $cpu, more than" \
        "FRAME_STACK_${pass^^}_BYTES ($budget) in firmware-sim/src/sim/mod.rs"; fail=1
    else
      echo "$pass frame stack on the $cpu: $peak of $budget bytes"
    fi
  done
done
poses=$(grep -c -E '^([0-9a-f]{16} ){11}[0-9a-f]{16}$' "$WORK/host.cmp" || true)
if [ "$poses" -lt 2 ] || ! grep -q '^fnv1a64 [0-9a-f]\{16\}$' "$WORK/host.cmp"; then
  echo "FAIL: host output has $poses pose lines or no hash line"; fail=1
fi
distinct=$(grep -E '^([0-9a-f]{16} ){11}[0-9a-f]{16}$' "$WORK/host.cmp" | sort -u | wc -l)
if [ "$distinct" -lt 2 ]; then echo "FAIL: the poses do not move"; fail=1; fi
runs=$(grep -c '^# summary' "$WORK/host.cmp" || true)
tracked=$(grep -c '^# summary.* tracked yes$' "$WORK/host.cmp" || true)
if [ "$runs" -lt 2 ] || [ "$tracked" -ne "$runs" ]; then
  echo "FAIL: the tracker tracked in $tracked of $runs runs (want geometric + semantic)"; fail=1
fi
for cpu in "${CPUS[@]}"; do
  if diff -u "$WORK/host.cmp" "$WORK/qemu-$cpu.cmp"; then
    echo "host and qemu -cpu $cpu outputs are identical ($poses poses in $runs runs:" \
      "$(grep '^fnv1a64' "$WORK/host.cmp" | tr '\n' ' '))"
  else
    echo "FAIL: host and qemu -cpu $cpu outputs differ"; fail=1
  fi
done
grep '^# summary' "$WORK/host.cmp"
if [ -n "${SEMLOC_BIN:-}" ]; then
  echo "== the host pipeline (\`$SEMLOC_BIN run --threads 1\`) on the same frames"
  python3 firmware-sim/host_pipeline_check.py "$SEMLOC_BIN" "$WORK/qemu-cortex-a72.cmp" || {
    echo "FAIL: the firmware poses differ from the host pipeline's"; fail=1
  }
else
  echo "(set SEMLOC_BIN=target/release/semloc to also compare with \`semloc run --threads 1\`)"
fi
if [ "$fail" -ne 0 ]; then
  echo "--- host output"; cat "$WORK/host.txt"
  for cpu in "${CPUS[@]}"; do echo "--- qemu -cpu $cpu output"; cat "$WORK/qemu-$cpu.txt"; done
  exit 1
fi
echo "qemu-check: OK"
