#!/usr/bin/env bash
# Four sequence-held-out runs side by side on one lent GPU (CamVid train + val without 0006R0,
# selected on 0006R0, strong augmentation, scale 0.35-2.0, batch 8, crop 384x384, fp32, seed 0):
#   bn75   bottleneck, 75 epochs        (the recipe that scored 35.6 +- 0.3 % int8 on CPU)
#   bn200  bottleneck, 200 epochs       (cut by --time-budget to what fits)
#   r2_75  res2net, 75 epochs           (the paper's variant, the same recipe: the ablation)
#   t_ho   resunet, 150 epochs, bf16    (the distillation teacher; cut by --time-budget)
# Written after the DataLoader fix of 2026-12-04 (camvid.EpochSampler): every earlier lent-GPU run
# repeated its first epoch's augmentation, so this re-measures what those runs concluded.
# Usage: bash models/holdout_compare.sh OUTDIR [BUDGET_S (default 200)] [-- extra train.py args]
# Env: WORKERS (per run, default 3), COPY_TO (logs, metrics and the Fast-SCNN checkpoints go there,
# as bn75_best.pt, bn200_best.pt, r2_75_best.pt).
set -uo pipefail
. "$(dirname "$0")/runs_lib.sh"
runs_args 1 200 "${@:2}"
runs_out "$1"
rec=(--holdout-seq 0006R0 --aug strong --scale 0.35 2.0 --batch 8 --crop 384x384 --eval-every 10
     --workers "${WORKERS:-3}" --time-budget "${RUNS_POS[0]}")
runs_train bn75 "${rec[@]}" --variant bottleneck --epochs 75 &
runs_train bn200 "${rec[@]}" --variant bottleneck --epochs 200 &
runs_train r2_75 "${rec[@]}" --variant res2net --epochs 75 &
runs_train t_ho "${rec[@]}" --variant resunet --epochs 150 --amp &
wait
runs_collect bn75/best.pt bn200/best.pt r2_75/best.pt
exit 0
