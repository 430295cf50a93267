#!/usr/bin/env bash
# Issue 15 on one lent GPU: the paper's ablation finished (res2net at the full 75-epoch schedule with
# the fixed loader; the bottleneck's three seeds of the same recipe are in
# ablation/distill_fixed_gpu.json), distillation tried on the deployed variant (res2net), and a
# deployable distilled res2net.
# Phase 1, four runs side by side: the held-out teacher t_ho (resunet, 150 epochs, bf16; CamVid
# train + val without 0006R0, selected on 0006R0), res2net seeds 0 and 1 with the same data and no
# teacher, and the all-data teacher t_all (resunet, CamVid train, selected on val: the deployed
# network's data). Phase 2, three runs: res2net seeds 0 and 1 distilled from t_ho (--teacher,
# alpha 0.5, T 2), and dep_kd, res2net on the deployed network's data distilled from t_all, 75
# epochs: the deployable candidate (export it at 192x640, convert, and judge it on the real clips
# against a null swap, models/README.md "Again, with the stronger teacher").
# Every run: strong augmentation, scale 0.35-2.0, batch 8, crop 384x384, fp32 for the students.
# One lent H200 needs about 340 s for phase 1 and 330 s for phase 2; with the machine's start that
# is more than one command's 600 s, so the phases run as two calls on the warm machine (phase 2
# reads phase 1's teachers from OUTDIR, which survives between calls while the machine is held).
# Usage: bash models/r2_distill_runs.sh OUTDIR [PHASE (1, 2 or all; default all) [PHASE1_S [PHASE2_S]]]
#        [-- extra train.py args]
# PHASE1_S / PHASE2_S (default 330 / 320): --time-budget of each phase's runs (a run that would not
# finish its schedule in it is shortened; train.py's metrics.json records that as time_budget_fit).
# Env: R2_ARGS (extra train.py arguments for the five res2net runs only, e.g.
# --zero-init-residual; the -- arguments reach every run, the teachers included), WORKERS
# (DataLoader workers per run, default 3), COPY_TO (each phase's logs and metrics, and
# the res2net checkpoints r2_s0_best.pt, r2_s1_best.pt, kd_r2_s0_best.pt, kd_r2_s1_best.pt and
# dep_kd_best.pt: 6 files in all).
# After it, on the CPU machine: runs_int8 (runs_lib.sh) on each held-out checkpoint for the int8
# figures.
set -uo pipefail
. "$(dirname "$0")/runs_lib.sh"
runs_args 3 all 330 320 "${@:2}"
phase=${RUNS_POS[0]}; b1=${RUNS_POS[1]}; b2=${RUNS_POS[2]}
case $phase in 1 | 2 | all) ;; *) echo "PHASE must be 1, 2 or all, not '$phase'" >&2; exit 2 ;; esac
runs_out "$1"
rec=(--aug strong --scale 0.35 2.0 --batch 8 --crop 384x384 --eval-every 10 --workers "${WORKERS:-3}")
ho=(--holdout-seq 0006R0 "${rec[@]}")
read -ra r2 <<< "${R2_ARGS:-}"
t0=$(date +%s)
if [ "$phase" != 2 ]; then
  runs_train t_ho --variant resunet "${ho[@]}" --epochs 150 --amp --time-budget "$b1" &
  runs_train t_all --variant resunet "${rec[@]}" --epochs 150 --amp --time-budget "$b1" &
  runs_train r2_s0 --variant res2net "${ho[@]}" --epochs 75 --seed 0 --time-budget "$b1" ${r2[@]+"${r2[@]}"} &
  runs_train r2_s1 --variant res2net "${ho[@]}" --epochs 75 --seed 1 --time-budget "$b1" ${r2[@]+"${r2[@]}"} &
  wait
  echo "phase 1: $(( $(date +%s) - t0 )) s"
  runs_collect r2_s0/best.pt r2_s1/best.pt
fi
if [ "$phase" != 1 ]; then
  for t in t_ho t_all; do
    [ -f "$RUNS_OUT/$t/best.pt" ] || { echo "no teacher at $RUNS_OUT/$t/best.pt: run phase 1 first" >&2; exit 1; }
  done
  for s in 0 1; do
    runs_train kd_r2_s$s --variant res2net "${ho[@]}" --epochs 75 --seed $s --time-budget "$b2" ${r2[@]+"${r2[@]}"} \
      --teacher "$RUNS_OUT/t_ho/best.pt" &
  done
  runs_train dep_kd --variant res2net "${rec[@]}" --epochs 75 --time-budget "$b2" ${r2[@]+"${r2[@]}"} \
    --teacher "$RUNS_OUT/t_all/best.pt" &
  wait
  echo "phase 2: $(( $(date +%s) - t0 )) s"
  runs_collect r2_s0/best.pt r2_s1/best.pt kd_r2_s0/best.pt kd_r2_s1/best.pt dep_kd/best.pt
fi
for r in t_ho t_all r2_s0 r2_s1 kd_r2_s0 kd_r2_s1 dep_kd; do
  [ -f "$RUNS_OUT/$r.log" ] || continue
  printf '%-9s ' "$r"; grep -E "^best val" "$RUNS_OUT/$r.log" || echo "(no result)"
done
