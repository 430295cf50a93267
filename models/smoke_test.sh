#!/usr/bin/env bash
# Smoke test of the whole Python path on one CPU thread (~1 minute): a few training iterations on
# 8 images (ClassMix and the weight average on one variant, the auxiliary losses on the other, and
# a resume), a checkpoint split into pieces and joined, export at 192x624, int8 PTQ with 4
# calibration images, onnxruntime cross-check; the dynamic mask's operating points on the held-out
# sequence; crops that take turns by epoch and the KITTI-shape evaluation; the training-only IBN
# variant; KITTI pseudo-labels and a fine-tune with them; the deployed network rebuilt from its committed
# ONNX (onnx_to_checkpoint.py) and exported again, with the same outputs, and fine-tuned from; a
# class boost applied and an unknown class refused.
# Run from anywhere: bash models/smoke_test.sh [SEMLOC_BINARY]   (needs: pip install -r
# models/requirements.txt). With a semloc binary it also quantises the rebuilt network again
# (64 calibration images) and checks that the .slm is byte for byte the committed one.
set -euo pipefail
semloc=${1:+$(realpath "$1")}
cd "$(dirname "$0")"
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
out=runs/smoke
for v in res2net bottleneck; do
  mix=$([ $v = bottleneck ] && echo "--classmix 0.5 --ema 0.9" || echo "--aux-weight 0.4")
  python3 train.py --variant $v --epochs 3 --batch 4 --crop 128x192 --limit-images 8 --limit-val 4 $mix \
    --eval-every 1 --threads 1 --out $out/$v
  python3 export.py --checkpoint $out/$v/best.pt --size 192x624 --out $out/$v/fastscnn_${v}_192x624.onnx
  python3 quantise.py --checkpoint $out/$v/best.pt --onnx $out/$v/fastscnn_${v}_192x624.onnx \
    --calib 4 --limit-val 4
done
# The auxiliary heads (res2net run above) are training only: best.pt exported without them; the
# run resumes with its heads, and refuses to resume without them.
python3 train.py --variant res2net --epochs 4 --batch 4 --crop 128x192 --limit-images 8 --limit-val 4 \
  --aux-weight 0.4 --eval-every 1 --threads 1 --resume $out/res2net/last.pt --out $out/res2net | tee $out/aux.log
grep -q "auxiliary losses on the LDS and GFE outputs, weight 0.4" $out/aux.log
grep -q "resumed at epoch 3" $out/aux.log
if python3 train.py --variant res2net --epochs 5 --batch 4 --crop 128x192 --limit-images 8 --limit-val 4 \
    --threads 1 --resume $out/res2net/last.pt --out $out/res2net 2> $out/aux.err; then
  echo "train.py resumed a run with auxiliary heads without them" >&2; exit 1
fi
grep -q "had auxiliary heads" $out/aux.err
echo "auxiliary heads: exported without, resumed with, refused without"
# --class-boost multiplies chosen classes' loss weights; a class that does not exist is refused.
python3 train.py --variant res2net --epochs 1 --max-iters 1 --batch 2 --crop 128x192 --limit-images 2 \
  --limit-val 2 --class-boost car=2 pedestrian=1.5 --threads 1 --out $out/boost | tee $out/boost.log
grep -qF "class weights [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 1.5, 1.0]" $out/boost.log
if python3 train.py --class-boost lorry=2 --out $out/boost 2> $out/boost.err; then
  echo "train.py accepted --class-boost for a class that does not exist" >&2; exit 1
fi
grep -q "expected CLASS=FACTOR" $out/boost.err
echo "class boost: applied, unknown class refused"
# A checkpoint split into float16 pieces (how a lent machine sends a large teacher back) joins
# back to the same weights.
python3 ckpt_pieces.py split $out/bottleneck/best.pt $out/pieces/bn --max-mb 2
python3 ckpt_pieces.py join $out/pieces/bn.part*.pt --out $out/pieces/bn.pt
python3 -c "
import torch
a, b = (torch.load(p)['model'] for p in ('$out/bottleneck/best.pt', '$out/pieces/bn.pt'))
assert a.keys() == b.keys()
assert all(torch.equal(a[k], b[k]) for k in a if a[k].ndim < 2)
err = max(float((a[k] - b[k]).abs().max() / a[k].abs().max().clamp_min(1e-6)) for k in a if a[k].ndim >= 2)
assert err < 1e-3, err
print('checkpoint pieces join back: vectors exact, weights within %.1e of their range' % err)"
# The dynamic mask's operating points on the held-out sequence (dyn_mask_points.py): every
# precision and recall is a fraction, and a higher threshold never raises recall.
python3 dyn_mask_points.py $out/bottleneck/best.pt --json $out/dynpts.json > $out/dynpts.log
python3 -c "
import json
r = json.load(open('$out/dynpts.json'))['runs'][0]
pts = [r['argmax']] + list(r['p_dynamic_above'].values()) + list(r['regions_at_least'].values())
assert r['images'] == 101 and all(0 <= v <= 1 for p in pts for v in p.values()), r
rec = [p['recall'] for p in r['p_dynamic_above'].values()]
assert rec == sorted(rec, reverse=True), rec
print('dynamic-mask operating points: %d, on %d held-out images' % (len(pts), r['images']))"
# Judging over calibration draws (draws_compare.py): made-up ablation results with known answers.
python3 -c "
import json, math, os, subprocess
d = '$out/draws'; os.makedirs(d, exist_ok=True)
def run(name, rows, starts=(0, 2, 4), ds='01'):
    ov = [{'semantics': k.split('/')[0], 'association': k.split('/')[1], 'ate_rmse_m': v} for k, v in rows.items()]
    json.dump({'dataset': {'name': ds}, 'first_frames': list(starts), 'over_first_frames': ov}, open(f'{d}/{name}.json', 'w'))
    return f'{d}/{name}.json'
base = run('base', {'off/hard': [1, 1, 1]})
r1 = run('r1', {'full/em': [1, 2, 1]}); r2 = run('r2', {'full/em': [1, 0.5, 2]})
c1 = run('c1', {'full/em': [0.5, 1, 1]})
cmd = ['python3', 'draws_compare.py', '--rows', 'full/em', '--base', base, '--json', f'{d}/out.json']
subprocess.run(cmd + ['--ref', r1, r2, '--cand', c1], check=True, stdout=subprocess.DEVNULL)
e = json.load(open(f'{d}/out.json'))['rows'][0]
# per start, mean log over draws: ref (0, 0, ln 2 / 2), cand (-ln 2, 0, 0): cand / ref (-ln 2, 0, -ln 2 / 2)
assert abs(e['cand_vs_ref']['ate_ratio_geomean'] - 2 ** -0.5) < 1e-12, e
assert e['cand_vs_ref']['better'] == 2 and abs(e['cand_vs_ref']['ate_ratio_worst'] - 1) < 1e-12, e
assert abs(e['ref_vs_base']['ate_ratio_geomean'] - 2 ** (1 / 6)) < 1e-12, e
assert [round(v, 12) for v in e['ref_vs_base_per_draw']] == [round(2 ** (1 / 3), 12), 1.0], e
assert abs(e['ref_draw_spread_log'] - math.log(2) / 3 / math.sqrt(2)) < 1e-12, e
for bad, why in ((run('s', {'full/em': [1, 1]}, starts=(0, 2)), 'starts'), (run('n', {'motion/em': [1, 1, 1]}), 'no row full/em'),
                 (run('q', {'full/em': [1, 1, 1]}, ds='06'), 'dataset 06')):
    p = subprocess.run(cmd + ['--ref', r1, '--cand', bad], capture_output=True, text=True)
    assert p.returncode == 1 and why in p.stderr and bad in p.stderr, (why, p.stderr)
print('draws_compare: averages draws per start, refuses runs that do not pair')"
# Crops that take turns by epoch (square, then KITTI-shaped, the image placed anywhere in a
# larger crop), and the KITTI-shape evaluation (shape_eval.py) on the result.
python3 train.py --variant bottleneck --epochs 2 --max-iters 4 --batch 4 --crop 128x128 64x224 --pad-random \
  --limit-images 8 --limit-val 4 --threads 1 --out $out/mixcrop
python3 -c "
import sys; sys.path.insert(0, '.')
import camvid
ds = camvid.CamVid('train', crop=[(128, 128), (64, 224)], pad_random=True, limit=2)
shapes = [tuple(ds[(e, 0)][0].shape) for e in range(4)]
assert shapes == [(1, 128, 128), (1, 64, 224)] * 2, shapes
print('crops take turns by epoch:', shapes)"
python3 shape_eval.py $out/mixcrop/last.pt --scales 1 --tall 256 --json $out/shape.json > $out/shape.log
python3 -c "
import json
r = json.load(open('$out/shape.json'))
e = next(iter(r['runs'].values()))['eval']
assert r['frames'] == 101 and set(e) == {'whole', 'ctx@1', 'kitti@1', 'tall256@1'}, e.keys()
assert all(0 <= m['miou'] <= 1 for m in e.values())
print('shape_eval modes:', sorted(e))"
# The IBN experiment's variant (instance normalisation in the LDS) trains, and export.py refuses
# it by name: the int8 core has no instance normalisation.
# --zero-init-residual starts its six residual blocks as the identity.
mkdir -p $out/ibn
python3 train.py --variant bottleneck-ibn --zero-init-residual --epochs 1 --max-iters 2 --batch 4 --crop 128x192 \
  --limit-images 8 --limit-val 4 --threads 1 --out $out/ibn | tee $out/ibn/train.log
grep -q "zero-initialised residual branches: 6" $out/ibn/train.log
if python3 export.py --checkpoint $out/ibn/best.pt --size 192x624 --out $out/ibn/x.onnx 2> $out/ibn/export.err; then
  echo "export.py exported a bottleneck-ibn checkpoint" >&2; exit 1
fi
grep -q "bottleneck-ibn checkpoint (training only" $out/ibn/export.err
echo "bottleneck-ibn trains; export.py refuses it: $(cat $out/ibn/export.err)"
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
# The deployed network's checkpoint is not committed: rebuilt from its ONNX, it exports the same
# network again (and, with a semloc binary, the same int8 blob).
rb=$out/rebuilt
python3 onnx_to_checkpoint.py artefacts/fastscnn_r2_192x640.onnx --variant res2net --out $rb/deployed.pt
python3 export.py --checkpoint $rb/deployed.pt --size 192x640 --out $rb/fastscnn_r2_192x640.onnx
python3 -c "
import numpy as np, onnxruntime as ort
x = np.random.default_rng(1).random((1, 1, 192, 640), dtype=np.float32)
a, b = (ort.InferenceSession(p).run(None, {'luma': x})[0]
        for p in ('artefacts/fastscnn_r2_192x640.onnx', '$rb/fastscnn_r2_192x640.onnx'))
d = float(np.abs(a - b).max())
assert d < 1e-4 and (a.argmax(1) == b.argmax(1)).all(), d
print('re-exported deployed network: max|diff| %.1e, same labels' % d)"
# Fine-tuning it: --init re-estimates the folded network's BatchNorm statistics and stops if that
# changed its eval-mode outputs; two iterations must then train from it.
python3 train.py --variant res2net --init $rb/deployed.pt --renorm-batches 2 --aug strong --scale 0.35 2.0 \
  --epochs 1 --max-iters 2 --batch 4 --crop 128x192 --limit-images 8 --limit-val 4 --lr 0.003 --threads 1 \
  --out $rb/finetune
if [ -n "$semloc" ]; then
  python3 quantise.py --checkpoint $rb/deployed.pt --onnx $rb/fastscnn_r2_192x640.onnx --calib 64 --limit-val 4
  "$semloc" convert --onnx $rb/fastscnn_r2_192x640.onnx --quant $rb/fastscnn_r2_192x640.quant.json \
    --out $rb/fastscnn_r2_192x640.slm
  cmp $rb/fastscnn_r2_192x640.slm artefacts/fastscnn_r2_192x640.slm
  echo "rebuilt deployed network: .slm identical to the committed one"
fi
echo "smoke test OK"
