#!/usr/bin/env bash
# Exports a trained checkpoint to the artefacts the Rust side loads, at the four input sizes:
#   192x640  KITTI half resolution (1241x376 -> 621x188, edge-padded): the deployed model
#   256x832  KITTI at 2/3 (1241x376 -> 828x251, area mean; measured for comparison)
#   384x1248 KITTI full resolution (measured for comparison)
#   384x480  CamVid val (360x480 edge-padded), for `semloc verify-seg --camvid`
# Each gets <stem>.onnx (f32, BN folded), <stem>.quant.json (int8 PTQ on 64 CamVid train
# images), <stem>.export.json and <stem>.slm (the core's blob, from `semloc convert`).
# Usage: bash models/make_artefacts.sh CHECKPOINT VARIANT [SEMLOC_BINARY]
# Env: SIZES (default "192x640 256x832 384x1248 384x480"), ARTEFACTS (the output folder, default
# models/artefacts), CALIB (calibration images, default 64): judge_on_clips.sh builds a
# candidate's 192x640 blob with them, and its null network with CALIB=65.
set -euo pipefail
ckpt=$1; variant=$2; semloc=${3:-target/release/semloc}
here=$(cd "$(dirname "$0")" && pwd)
short=$([ "$variant" = res2net ] && echo r2 || echo bn)
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "${ARTEFACTS:=$here/artefacts}"
for size in ${SIZES:-192x640 256x832 384x1248 384x480}; do
  stem=$ARTEFACTS/fastscnn_${short}_${size}
  python3 "$here/export.py" --checkpoint "$ckpt" --variant "$variant" --size "$size" --out "$stem.onnx"
  python3 "$here/quantise.py" --checkpoint "$ckpt" --variant "$variant" --onnx "$stem.onnx" --calib "${CALIB:-64}"
  "$semloc" convert --onnx "$stem.onnx" --quant "$stem.quant.json" --out "$stem.slm"
done
