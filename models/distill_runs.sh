#!/usr/bin/env bash
# Issue 15: distillation from a larger network we train ourselves, in one call on one lent GPU.
# Phase 1, three runs side by side: the teacher (resunet, semloc_models/teacher.py) on the
# sequence-held-out split (CamVid train + val without 0006R0, selected on 0006R0); the student
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
# metrics and student checkpoints are copied there as soon as the phase ends).
set -uo pipefail
out=$1; deployed=$2; shift 2
b1=240; b2=200
[ $# -gt 0 ] && [ "$1" != -- ] && { b1=$1; shift; }
[ $# -gt 0 ] && [ "$1" != -- ] && { b2=$1; shift; }
[ $# -gt 0 ] && [ "$1" = -- ] && shift
extra=("$@")
here=$(cd "$(dirname "$0")" && pwd)
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
W=${WORKERS:-4}
ho=(--holdout-seq 0006R0)
rec=(--aug strong --scale 0.35 2.0 --batch 8 --crop 384x384 --eval-every 10 --workers "$W")
mkdir -p "$out"
train() { # name, train.py args...
  local name=$1; shift
  python3 "$here/train.py" "$@" --out "$out/$name" ${extra[@]+"${extra[@]}"} > "$out/$name.log" 2>&1
  echo "$name: exit $? $(tail -n 1 "$out/$name.log")"
}
collect() { # copies logs, metrics and the named checkpoints to $COPY_TO
  [ -n "${COPY_TO:-}" ] || return 0
  mkdir -p "$COPY_TO"
  tar -C "$out" -cf "$COPY_TO/logs.tar" $(cd "$out" && ls *.log */metrics.json 2>/dev/null)
  for f in "$@"; do [ -f "$out/$f" ] && cp "$out/$f" "$COPY_TO/${f//\//_}"; done
  return 0
}
t0=$(date +%s)
train t_ho --variant resunet "${ho[@]}" "${rec[@]}" --epochs 150 --amp --time-budget "$b1" &
train ctrl_ho --variant bottleneck "${ho[@]}" "${rec[@]}" --epochs 75 --time-budget "$b1" &
train t_all --variant resunet "${rec[@]}" --epochs 150 --amp --time-budget "$b1" &
wait
echo "phase 1: $(( $(date +%s) - t0 )) s"
collect ctrl_ho/best.pt
[ -f "$out/t_ho/best.pt" ] && [ -f "$out/t_all/best.pt" ] || { echo "a teacher is missing"; exit 1; }
ft=(--variant res2net --init "$deployed" "${rec[@]}" --epochs 20 --warmup-iters 100 --lr 0.003)
train kd_ho --variant bottleneck "${ho[@]}" "${rec[@]}" --epochs 75 --time-budget "$b2" \
  --teacher "$out/t_ho/best.pt" &
train kd_all "${ft[@]}" --time-budget "$b2" --teacher "$out/t_all/best.pt" &
train ft_all "${ft[@]}" --time-budget "$b2" &
wait
echo "phase 2: $(( $(date +%s) - t0 )) s"
collect ctrl_ho/best.pt kd_ho/best.pt kd_all/last.pt ft_all/last.pt
for r in t_ho ctrl_ho t_all kd_ho kd_all ft_all; do
  printf '%-8s ' "$r"; grep -E "^best val" "$out/$r.log" || echo "(no result)"
done
