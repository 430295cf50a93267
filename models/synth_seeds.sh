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
. "$(dirname "$0")/runs_lib.sh"
semloc=$2
runs_out "$1"
runs_args 0 "${@:3}"
out=$RUNS_OUT
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
  runs_train "b$s" "${common[@]}" --eval-every 10 --seed "$s" &
  runs+=("b$s")
done
for s in ${SYN_SEEDS:-0 1}; do
  runs_train "s$s" "${common[@]}" --eval-every 5 --seed "$s" --synth "${syn[@]}" &
  runs+=("s$s")
done
wait
for r in "${runs[@]}"; do runs_int8 "$r" bottleneck & done
wait
for r in "${runs[@]}"; do echo "$r: $(grep -h 'held-out sequence' "$out/$r.quant.log")"; done
