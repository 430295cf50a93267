"""How much a network loses when a frame reaches it in KITTI's input shape.

The core gives the network a KITTI frame box-downscaled by 2 (620x188) and edge-padded to 192x640:
a wide band with no context above or below it. CamVid frames are 4:3 and the training crops
square, so the held-out CamVid figures never see that shape. This scores a held-out CamVid
sequence (float, per checkpoint) three ways:

  whole      the frame (360x480, padded to 384x480), as train.py and quantise.py score it;
  ctx@S      the frame scaled by S, whole, scored on its middle CANVAS_H rows only;
  kitti@S    those rows alone, centred in a CANVAS_H x CANVAS_W canvas (edge-padded, as the core
             pads a KITTI frame), scored on the same pixels as ctx@S.

  tallH@S    (with --tall H) the kitti@S canvas edge-padded above and below to H rows: the same
             band given the network a taller input, at H/CANVAS_H its time (the core pads at the
             bottom only; centred is the kinder case).

kitti@S against ctx@S is the cost of the shape alone: same pixels, same scale, the context above
and below taken away and the rest of the width padded. At S = 4/3 the scaled frame is 640 wide
and the band needs no padding.

    python3 models/shape_eval.py CKPT [CKPT ...] [--holdout-seq 0006R0] [--scales 0.72 1 1.3333]
        [--canvas 192x640] [--tall 256 384] [--json OUT.json]
"""
import argparse
import json
import os
import sys

import numpy as np
import torch
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import camvid  # noqa: E402
from export import load_model, parse_hw  # noqa: E402


def predict(model, img):
    with torch.no_grad():
        return model(camvid.to_input(img)[None]).argmax(1)[0]


def evaluate(model, items, scales, canvas, tall=()):
    ch, cw = canvas
    n = len(camvid.CLASSES)
    cms = {"whole": torch.zeros(n, n, dtype=torch.int64)}
    for s in scales:
        cms[f"ctx@{s:g}"] = torch.zeros(n, n, dtype=torch.int64)
        cms[f"kitti@{s:g}"] = torch.zeros(n, n, dtype=torch.int64)
        for H in tall:
            cms[f"tall{H}@{s:g}"] = torch.zeros(n, n, dtype=torch.int64)
    for ip, lp in items:
        img, lab = camvid.load_luma(ip), camvid.load_label(lp)
        pi, pl = camvid.pad_to_multiple(img, lab)
        cms["whole"] += camvid.confusion(predict(model, pi), torch.from_numpy(pl.astype(np.int64)))
        for s in scales:
            h, w = round(img.shape[0] * s), round(img.shape[1] * s)
            if h < ch or w > cw:
                raise SystemExit(f"--scales {s:g}: the scaled frame ({h}x{w}) must be at least "
                                 f"{ch} rows high and at most {cw} wide for a {ch}x{cw} canvas")
            si = np.asarray(Image.fromarray(img).resize((w, h), Image.BILINEAR))
            sl = np.asarray(Image.fromarray(lab).resize((w, h), Image.NEAREST))
            r0 = (h - ch) // 2
            gt = torch.from_numpy(sl[r0:r0 + ch].astype(np.int64))
            ps, _ = camvid.pad_to_multiple(si, None)
            cms[f"ctx@{s:g}"] += camvid.confusion(predict(model, ps)[r0:r0 + ch, :w], gt)
            left = (cw - w) // 2
            band = np.pad(si[r0:r0 + ch], ((0, 0), (left, cw - w - left)), mode="edge")
            cms[f"kitti@{s:g}"] += camvid.confusion(predict(model, band)[:, left:left + w], gt)
            for H in tall:
                t = (H - ch) // 2
                tb = np.pad(band, ((t, H - ch - t), (0, 0)), mode="edge")
                cms[f"tall{H}@{s:g}"] += camvid.confusion(predict(model, tb)[t:t + ch, left:left + w], gt)
    return {k: camvid.metrics(cm) for k, cm in cms.items()}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoints", nargs="+")
    p.add_argument("--holdout-seq", default="0006R0", help="the CamVid sequence scored (train + val frames)")
    p.add_argument("--scales", type=float, nargs="+", default=[0.72, 1.0, 4 / 3])
    p.add_argument("--canvas", type=parse_hw, default=(192, 640), help="HxW network input (the deployed 192x640)")
    p.add_argument("--tall", type=int, nargs="*", default=[],
                   help="also score the band padded to these heights (multiples of 32, above CANVAS_H)")
    p.add_argument("--json", default="", help="write every figure here")
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    for H in a.tall:
        if H <= a.canvas[0] or H % 32:
            raise SystemExit(f"--tall {H}: must be a multiple of 32 above the canvas height {a.canvas[0]}")
    if a.canvas[0] % 32 or a.canvas[1] % 32:
        raise SystemExit(f"--canvas {a.canvas[0]}x{a.canvas[1]}: both sides must be multiples of 32")
    items = camvid.list_sequences(camvid.DEFAULT_ROOT, ["train", "val"], include={a.holdout_seq})
    if not items:
        raise SystemExit(f"--holdout-seq {a.holdout_seq}: no CamVid frames of that sequence in {camvid.DEFAULT_ROOT}")
    out = {"holdout_seq": a.holdout_seq, "frames": len(items), "canvas": list(a.canvas), "runs": {}}
    for ck in a.checkpoints:
        if not os.path.isfile(ck):
            raise SystemExit(f"{ck}: no such checkpoint")
        model, variant = load_model(ck)
        res = evaluate(model, items, a.scales, a.canvas, a.tall)
        out["runs"][ck] = {"variant": variant, "eval": res}
        print(f"== {ck} ({variant}, f32, {a.holdout_seq}, {len(items)} frames)")
        print(f"{'mode':<12} {'mIoU':>6} {'cat':>6} {'dyn P':>6} {'dyn R':>6}")
        for k, m in res.items():
            print(f"{k:<12} {100 * m['miou']:6.2f} {100 * m['cat_miou']:6.2f} "
                  f"{100 * m['dyn_precision']:6.2f} {100 * m['dyn_recall']:6.2f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
