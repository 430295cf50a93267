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
# Env: WORKERS (per run, default 3), COPY_TO (logs, metrics and the Fast-SCNN checkpoints go there).
set -uo pipefail
out=$1; shift
b=200
[ $# -gt 0 ] && [ "$1" != -- ] && { b=$1; shift; }
[ $# -gt 0 ] && [ "$1" = -- ] && shift
extra=("$@")
here=$(cd "$(dirname "$0")" && pwd)
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
rec=(--holdout-seq 0006R0 --aug strong --scale 0.35 2.0 --batch 8 --crop 384x384 --eval-every 10
     --workers "${WORKERS:-3}" --time-budget "$b")
mkdir -p "$out"
train() { # name, train.py args...
  local name=$1; shift
  python3 "$here/train.py" "${rec[@]}" "$@" --out "$out/$name" ${extra[@]+"${extra[@]}"} > "$out/$name.log" 2>&1
  echo "$name: exit $? $(tail -n 1 "$out/$name.log")"
}
train bn75 --variant bottleneck --epochs 75 &
train bn200 --variant bottleneck --epochs 200 &
train r2_75 --variant res2net --epochs 75 &
train t_ho --variant resunet --epochs 150 --amp &
wait
if [ -n "${COPY_TO:-}" ]; then
  mkdir -p "$COPY_TO"
  tar -C "$out" -cf "$COPY_TO/logs.tar" $(cd "$out" && ls *.log */metrics.json 2>/dev/null)
  for r in bn75 bn200 r2_75; do [ -f "$out/$r/best.pt" ] && cp "$out/$r/best.pt" "$COPY_TO/$r.pt"; done
fi
exit 0
