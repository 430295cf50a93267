#!/usr/bin/env bash
# Does mixing `semloc synth` frames into training help the sequence-held-out figure, beyond the
# run-to-run spread? Trains the bottleneck with the held-out recipe (holdout_runs.sh) four at a
# time on one GPU: CamVid alone with seeds BASE_SEEDS, and CamVid + 400 synthetic frames
# (high/parked/low/static streets, generator seeds 21-24, 100 frames each) with seeds SYN_SEEDS,
# all on the same 4400-iteration schedule; then the int8 check of each on 0006R0.
# Usage: bash models/synth_seeds.sh OUTDIR SEMLOC_BIN [extra train.py args, e.g. --time-budget 330]
# Env: BASE_SEEDS (default "1 2"), SYN_SEEDS (default "0 1"), WORKERS (default 3).
# Results of 2026-11-27: models/ablation/holdout_seeds_synth_gpu.json, models/README.md.
set -euo pipefail
out=$1; semloc=$2; shift 2
here=$(cd "$(dirname "$0")" && pwd)
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$out"
syn=()
i=21
for d in high parked low static; do
  "$semloc" synth --out "$out/syn_$d" --frames 100 --dynamics "$d" --seed "$i" --force > "$out/syn_$d.log" 2>&1 &
  syn+=("$out/syn_$d"); i=$((i + 1))
done
wait
common=(--variant bottleneck --holdout-seq 0006R0 --aug strong --scale 0.35 2.0 --epochs 1000 --max-iters 4400
        --batch 16 --crop 384x384 --workers "${WORKERS:-3}" --amp)
runs=()
for s in ${BASE_SEEDS:-1 2}; do
  python3 "$here/train.py" "${common[@]}" --eval-every 10 --seed "$s" --out "$out/b$s" "$@" > "$out/b$s.log" 2>&1 &
  runs+=("b$s")
done
for s in ${SYN_SEEDS:-0 1}; do
  python3 "$here/train.py" "${common[@]}" --eval-every 5 --seed "$s" --synth "${syn[@]}" --out "$out/s$s" "$@" \
    > "$out/s$s.log" 2>&1 &
  runs+=("s$s")
done
wait
for r in "${runs[@]}"; do
  ( python3 "$here/export.py" --checkpoint "$out/$r/best.pt" --variant bottleneck --size 384x480 \
      --out "$out/$r/fastscnn_384x480.onnx" > "$out/$r.quant.log" 2>&1 &&
    python3 "$here/quantise.py" --checkpoint "$out/$r/best.pt" --variant bottleneck --holdout-seq 0006R0 \
      --onnx "$out/$r/fastscnn_384x480.onnx" --calib 64 --threads 4 >> "$out/$r.quant.log" 2>&1 ) &
done
wait
for r in "${runs[@]}"; do echo "$r: $(grep -h 'held-out sequence' "$out/$r.quant.log")"; done
