"""Operating points of a checkpoint's dynamic-class mask on a held-out CamVid sequence.

The mask culling uses is argmax in {car, pedestrian, bicyclist}. This scores, in f32 on the
sequence kept out of training, the pixel precision and recall of that mask and of two
post-processings that could trade one for the other without retraining:
  - thresholds on p(dynamic) = the softmax mass of the three classes (instead of the argmax);
  - dropping connected dynamic regions smaller than N pixels (at CamVid's 360x480);
and says which pixels the mask gets wrong (false positives by true class, misses by label).

    python3 models/dyn_mask_points.py CKPT [CKPT ...] [--holdout-seq 0006R0] [--json OUT]

Needs opencv-python-headless (connected components), as pseudo_label.py does.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import camvid  # noqa: E402
from export import load_model  # noqa: E402

THRESHOLDS = (0.3, 0.4, 0.5, 0.6, 0.7)
MIN_AREAS = (50, 200, 500, 1000, 2000)


def load(path):
    """export.py's loader (which refuses a teacher checkpoint by name), with a missing or foreign
    file named rather than a traceback."""
    try:
        return load_model(path)
    except (OSError, KeyError, RuntimeError, pickle.UnpicklingError) as e:
        raise SystemExit(f"{path}: not a train.py checkpoint ({e})")


def pr(masks, gts):
    tp = fp = fn = 0
    for m, g in zip(masks, gts):
        valid = g < len(camvid.CLASSES)
        gd = np.isin(g, camvid.DYNAMIC) & valid
        m = m & valid
        tp += int((m & gd).sum())
        fp += int((m & ~gd).sum())
        fn += int((~m & gd).sum())
    return {"precision": tp / max(tp + fp, 1), "recall": tp / max(tp + fn, 1)}


def drop_small(mask, min_area):
    import cv2
    _, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area
    keep[0] = False
    return keep[lab]


@torch.no_grad()
def score(path, items):
    model, variant = load(path)
    ds = camvid.CamVid("val", items=items, augment=False)
    preds, pdyn, gts = [], [], []
    for i in range(len(ds)):
        x, y = ds[i]
        logits = model(x[None])[0]
        preds.append(logits.argmax(0).numpy())
        pdyn.append(logits.softmax(0)[camvid.DYNAMIC].sum(0).numpy())
        gts.append(y.numpy())
    argmax = [np.isin(p, camvid.DYNAMIC) for p in preds]
    n = len(camvid.CLASSES)
    fp_by = np.zeros(n, np.int64)  # void pixels are scored neither way, as in pr()
    miss_as = np.zeros(n, np.int64)
    for m, p, g in zip(argmax, preds, gts):
        gd = np.isin(g, camvid.DYNAMIC)
        fp_by += np.bincount(g[m & ~gd & (g < n)], minlength=n)
        miss_as += np.bincount(p[gd & ~m], minlength=n)
    names = list(camvid.CLASSES)
    return {
        "checkpoint": path,
        "variant": variant,
        "images": len(ds),
        "argmax": pr(argmax, gts),
        "p_dynamic_above": {str(t): pr([q > t for q in pdyn], gts) for t in THRESHOLDS},
        "regions_at_least": {str(a): pr([drop_small(m, a) for m in argmax], gts) for a in MIN_AREAS},
        "false_positives_by_true_class": dict(zip(names, (fp_by / max(fp_by.sum(), 1)).round(3).tolist())),
        "misses_labelled_as": dict(zip(names, (miss_as / max(miss_as.sum(), 1)).round(3).tolist())),
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("checkpoints", nargs="+")
    p.add_argument("--data", default=camvid.DEFAULT_ROOT)
    p.add_argument("--holdout-seq", default="0006R0")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--json", default="", help="write the figures here as well")
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    items = camvid.list_sequences(a.data, ["train", "val"], include={a.holdout_seq})
    if not items:
        raise SystemExit(f"--holdout-seq {a.holdout_seq}: no such sequence in {a.data}")
    out = []
    for ck in a.checkpoints:
        r = score(ck, items)
        out.append(r)
        f = lambda d: f"{100 * d['precision']:.1f} / {100 * d['recall']:.1f} %"  # noqa: E731
        print(f"{ck} ({r['variant']}, {r['images']} images of {a.holdout_seq}), dynamic mask P / R:")
        print(f"  argmax               {f(r['argmax'])}")
        for t, d in r["p_dynamic_above"].items():
            print(f"  p(dynamic) > {t:<7} {f(d)}")
        for s, d in r["regions_at_least"].items():
            print(f"  regions >= {s:>5} px {f(d)}")
        top = lambda d: ", ".join(f"{k} {100 * v:.0f} %" for k, v in sorted(d.items(), key=lambda kv: -kv[1])[:4])  # noqa: E731
        print(f"  false positives are: {top(r['false_positives_by_true_class'])}")
        print(f"  misses are labelled: {top(r['misses_labelled_as'])}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"holdout_seq": a.holdout_seq, "runs": out}, fh, indent=1)


if __name__ == "__main__":
    main()
