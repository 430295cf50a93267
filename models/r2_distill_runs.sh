#!/usr/bin/env bash
# Issue 15 on one lent GPU: the paper's ablation finished (res2net at the full 75-epoch schedule with
# the fixed loader; the bottleneck's three seeds of the same recipe are in
# ablation/distill_fixed_gpu.json) and distillation into the deployed variant (res2net).
# Phase 1, three runs side by side: the held-out teacher (resunet, 150 epochs, bf16) and res2net
# seeds 0 and 1 without a teacher. Phase 2, two runs: res2net seeds 0 and 1 distilled from that
# teacher (--teacher, alpha 0.5, T 2). Every run trains on CamVid train + val without 0006R0 and
# selects on 0006R0 (strong augmentation, scale 0.35-2.0, batch 8, crop 384x384, fp32).
# One lent H200 needs about 300 s for phase 1 and 280 s for phase 2; with the machine's start that
# is close to one command's 600 s, so the phases can run as two calls on the warm machine (phase 2
# reads phase 1's teacher from OUTDIR, which survives between calls while the machine is held).
# Usage: bash models/r2_distill_runs.sh OUTDIR [PHASE (1, 2 or all; default all) [PHASE1_S [PHASE2_S]]]
#        [-- extra train.py args]
# PHASE1_S / PHASE2_S (default 300 / 300): --time-budget of each phase's runs (a run that would not
# finish its schedule in it is shortened; train.py's metrics.json records that as time_budget_fit).
# Env: WORKERS (DataLoader workers per run, default 4), COPY_TO (each phase's logs and metrics, and
# the res2net checkpoints, r2_s0_best.pt ... kd_r2_s1_best.pt: at most 5 files in all).
# After it, on the CPU machine: runs_int8 (runs_lib.sh) on each checkpoint for the int8 figures.
set -uo pipefail
. "$(dirname "$0")/runs_lib.sh"
runs_args 3 all 300 300 "${@:2}"
phase=${RUNS_POS[0]}; b1=${RUNS_POS[1]}; b2=${RUNS_POS[2]}
case $phase in 1 | 2 | all) ;; *) echo "PHASE must be 1, 2 or all, not '$phase'" >&2; exit 2 ;; esac
runs_out "$1"
rec=(--holdout-seq 0006R0 --aug strong --scale 0.35 2.0 --batch 8 --crop 384x384 --eval-every 10
     --workers "${WORKERS:-4}")
t0=$(date +%s)
if [ "$phase" != 2 ]; then
  runs_train t_ho --variant resunet "${rec[@]}" --epochs 150 --amp --time-budget "$b1" &
  runs_train r2_s0 --variant res2net "${rec[@]}" --epochs 75 --seed 0 --time-budget "$b1" &
  runs_train r2_s1 --variant res2net "${rec[@]}" --epochs 75 --seed 1 --time-budget "$b1" &
  wait
  echo "phase 1: $(( $(date +%s) - t0 )) s"
  runs_collect r2_s0/best.pt r2_s1/best.pt
fi
if [ "$phase" != 1 ]; then
  [ -f "$RUNS_OUT/t_ho/best.pt" ] || { echo "no teacher at $RUNS_OUT/t_ho/best.pt: run phase 1 first" >&2; exit 1; }
  for s in 0 1; do
    runs_train kd_r2_s$s --variant res2net "${rec[@]}" --epochs 75 --seed $s --time-budget "$b2" \
      --teacher "$RUNS_OUT/t_ho/best.pt" &
  done
  wait
  echo "phase 2: $(( $(date +%s) - t0 )) s"
  runs_collect r2_s0/best.pt r2_s1/best.pt kd_r2_s0/best.pt kd_r2_s1/best.pt
fi
for r in t_ho r2_s0 r2_s1 kd_r2_s0 kd_r2_s1; do
  [ -f "$RUNS_OUT/$r.log" ] || continue
  printf '%-9s ' "$r"; grep -E "^best val" "$RUNS_OUT/$r.log" || echo "(no result)"
done
