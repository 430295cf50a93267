#!/usr/bin/env bash
# Issue 15: distillation from a larger network we runs_train ourselves, in one call on one lent GPU.
# Phase 1, three runs side by side: the teacher (resunet, semloc_models/teacher.py) on the
# sequence-held-out split (CamVid runs_train + val without 0006R0, selected on 0006R0); the student
# without a teacher, the same recipe (the control: bottleneck, 75 epochs, batch 8, fp32 - the
# recipe of models/README.md that scored 35.6 +- 0.3 % int8 on 0006R0); and the teacher on the
# deployed network's data (CamVid train, selected on val).
# Phase 2, three runs: the student distilled from the held-out teacher (same recipe plus
# --teacher); the deployed res2net fine-tuned with the distillation from the all-data teacher
# (--init, 20 epochs, lr 0.003: the fine-tune of models/README.md plus --teacher); and that
# fine-tune without a teacher, its control in the same call.
# Usage: bash models/distill_runs.sh OUTDIR DEPLOYED_CKPT [PHASE1_S [PHASE2_S]] [-- extra train.py args]
# DEPLOYED_CKPT: onnx_to_checkpoint.py's rebuild of models/artefacts/fastscnn_r2_192x640.onnx.
# PHASE1_S / PHASE2_S (default 240 / 200): --time-budget of each phase's runs.
# Env: WORKERS (DataLoader workers per run, default 4), COPY_TO (a folder: each phase's logs,
# metrics and student checkpoints are copied there as soon as the phase ends, and at the end the
# all-data teacher in float16 pieces: join them with ckpt_pieces.py join).
set -uo pipefail
. "$(dirname "$0")/runs_lib.sh"
deployed=$2
runs_args 2 240 200 "${@:3}"
b1=${RUNS_POS[0]}; b2=${RUNS_POS[1]}
runs_out "$1"
W=${WORKERS:-4}
ho=(--holdout-seq 0006R0)
rec=(--aug strong --scale 0.35 2.0 --batch 8 --crop 384x384 --eval-every 10 --workers "$W")
t0=$(date +%s)
runs_train t_ho --variant resunet "${ho[@]}" "${rec[@]}" --epochs 150 --amp --time-budget "$b1" &
runs_train ctrl_ho --variant bottleneck "${ho[@]}" "${rec[@]}" --epochs 75 --time-budget "$b1" &
runs_train t_all --variant resunet "${rec[@]}" --epochs 150 --amp --time-budget "$b1" &
wait
echo "phase 1: $(( $(date +%s) - t0 )) s"
runs_collect ctrl_ho/best.pt
[ -f "$RUNS_OUT/t_ho/best.pt" ] && [ -f "$RUNS_OUT/t_all/best.pt" ] || { echo "a teacher is missing"; exit 1; }
ft=(--variant res2net --init "$deployed" "${rec[@]}" --epochs 20 --warmup-iters 100 --lr 0.003)
runs_train kd_ho --variant bottleneck "${ho[@]}" "${rec[@]}" --epochs 75 --time-budget "$b2" \
  --teacher "$RUNS_OUT/t_ho/best.pt" &
runs_train kd_all "${ft[@]}" --time-budget "$b2" --teacher "$RUNS_OUT/t_all/best.pt" &
runs_train ft_all "${ft[@]}" --time-budget "$b2" &
wait
echo "phase 2: $(( $(date +%s) - t0 )) s"
runs_collect ctrl_ho/best.pt kd_ho/best.pt kd_all/last.pt ft_all/last.pt
# The all-data teacher comes back too, in float16 pieces under the 16 MB file limit (7 files in
# all): on CPU it can label KITTI frames (pseudo_label.py) and distil again.
if [ -n "${COPY_TO:-}" ] && [ -f "$RUNS_OUT/t_all/best.pt" ]; then
  python3 "$RUNS_HERE/ckpt_pieces.py" split "$RUNS_OUT/t_all/best.pt" "$COPY_TO/t_all"
fi
for r in t_ho ctrl_ho t_all kd_ho kd_all ft_all; do
  printf '%-8s ' "$r"; grep -E "^best val" "$RUNS_OUT/$r.log" || echo "(no result)"
done
