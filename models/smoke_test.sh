#!/usr/bin/env bash
# Smoke test of the whole Python path on one CPU thread (~1 minute): a few training iterations on
# 8 images, export at 192x624, int8 PTQ with 4 calibration images, onnxruntime cross-check;
# KITTI pseudo-labels and a fine-tune with them.
# Run from anywhere: bash models/smoke_test.sh   (needs: pip install -r models/requirements.txt)
set -euo pipefail
cd "$(dirname "$0")"
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
out=runs/smoke
for v in res2net bottleneck; do
  python3 train.py --variant $v --epochs 3 --batch 4 --crop 128x192 --limit-images 8 --limit-val 4 \
    --eval-every 1 --threads 1 --out $out/$v
  python3 export.py --checkpoint $out/$v/best.pt --size 192x624 --out $out/$v/fastscnn_${v}_192x624.onnx
  python3 quantise.py --checkpoint $out/$v/best.pt --onnx $out/$v/fastscnn_${v}_192x624.onnx \
    --calib 4 --limit-val 4
done
# Self-training path: pseudo-labels on the 06 clip (no poses: stereo and confidence filters
# only), read back through the training set's augmentation.
python3 pseudo_label.py --checkpoint $out/bottleneck/best.pt --out $out/pseudo --every 25 --threads 1 \
  --odometry ../../shared/data/kitti-odometry:06
python3 -c "
import camvid
ds = camvid.CamVid('train', crop=(128, 192), items=camvid.list_synth('$out/pseudo'))
x, y = ds[0]
assert len(ds) == 3 and tuple(x.shape[-2:]) == (128, 192), (len(ds), x.shape)
print('pseudo-labelled frames load through the training augmentation:', len(ds))"
echo "smoke test OK"
