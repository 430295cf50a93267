# Sourced by the run scripts of models/ (distill_runs.sh, holdout_compare.sh, holdout_runs.sh,
# synth_seeds.sh): one-thread PyTorch per run, parsing a script's optional values and its extra
# train.py arguments, training one named run, the int8 check on the held-out sequence, and
# copying results to where a lent machine sends them back.
# shellcheck shell=bash
RUNS_HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1

# runs_args K DEFAULT_1 .. DEFAULT_K ARGS...: up to K leading ARGS that are not `--` replace the
# defaults in RUNS_POS; after an optional `--`, the rest goes to RUNS_EXTRA (train.py arguments
# added to every run, after the script's own, so they win).
runs_args() {
  local k=$1 i
  shift
  RUNS_POS=("${@:1:k}")
  shift "$k"
  for ((i = 0; i < k; i++)); do
    if [ $# -gt 0 ] && [ "$1" != -- ]; then RUNS_POS[i]=$1; shift; fi
  done
  if [ $# -gt 0 ] && [ "$1" = -- ]; then shift; fi
  RUNS_EXTRA=("$@")
}

# runs_out DIR: where runs_train writes (DIR/NAME/ and DIR/NAME.log).
runs_out() { RUNS_OUT=$1; mkdir -p "$RUNS_OUT"; }

# runs_train NAME ARGS...: python3 train.py ARGS... RUNS_EXTRA... into $RUNS_OUT/NAME, the log
# in $RUNS_OUT/NAME.log; prints the run's exit status and last line, returns its status.
runs_train() {
  local name=$1 rc
  shift
  python3 "$RUNS_HERE/train.py" "$@" --out "$RUNS_OUT/$name" ${RUNS_EXTRA[@]+"${RUNS_EXTRA[@]}"} \
    > "$RUNS_OUT/$name.log" 2>&1
  rc=$?
  echo "$name: exit $rc $(tail -n 1 "$RUNS_OUT/$name.log")"
  return $rc
}

# runs_quant CKPT VARIANT SIZE STEM LOG [quantise.py args...]: exports CKPT at SIZE (HxW) to
# STEM.onnx and quantises it with 64 calibration images drawn without the held-out sequence 0006R0
# (quantise.py writes STEM.quant.json); both tools' output goes to LOG.
runs_quant() {
  local ckpt=$1 v=$2 size=$3 stem=$4 log=$5
  shift 5
  { python3 "$RUNS_HERE/export.py" --checkpoint "$ckpt" --variant "$v" --size "$size" --out "$stem.onnx" &&
    python3 "$RUNS_HERE/quantise.py" --checkpoint "$ckpt" --variant "$v" --holdout-seq 0006R0 \
      --onnx "$stem.onnx" --calib 64 "$@"; } > "$log" 2>&1
}

# runs_int8 NAME VARIANT: runs_quant of $RUNS_OUT/NAME/best.pt at 384x480, scored in f32 and int8
# on the held-out sequence 0006R0; the log is $RUNS_OUT/NAME.quant.log, the figures
# $RUNS_OUT/NAME/fastscnn_384x480.quant.json.
runs_int8() {
  local d=$RUNS_OUT/$1
  runs_quant "$d/best.pt" "$2" 384x480 "$d/fastscnn_384x480" "$RUNS_OUT/$1.quant.log" --threads 4
}

# runs_collect FILE...: with COPY_TO set, tars every log and metrics.json of $RUNS_OUT into
# $COPY_TO/logs.tar and copies each FILE (a path under $RUNS_OUT, e.g. bn75/best.pt) that exists to
# $COPY_TO with its slashes made underscores (bn75_best.pt). Without COPY_TO it does nothing.
runs_collect() {
  [ -n "${COPY_TO:-}" ] || return 0
  mkdir -p "$COPY_TO"
  tar -C "$RUNS_OUT" -cf "$COPY_TO/logs.tar" $(cd "$RUNS_OUT" && ls ./*.log ./*/metrics.json 2>/dev/null)
  local f
  for f in "$@"; do
    if [ -f "$RUNS_OUT/$f" ]; then cp "$RUNS_OUT/$f" "$COPY_TO/${f//\//_}"; fi
  done
  return 0
}
