"""Pseudo-labels for self-training on unlabelled KITTI stereo sequences (issue 15).

A trained checkpoint (the teacher) labels KITTI frames at the deployed input scale (box-downscaled
by 2, as the Rust side feeds the net), and only the pixels that several independent views agree
on are kept; the rest become void (11, ignored by training):

- **confidence**: the teacher's softmax (mean of the frame and its mirror image) is at least a
  per-class threshold: the class's median confidence over the sequence, capped at `--conf`, so
  rare classes (pole, sign, people) are not wiped out by a single global threshold;
- **stereo**: the right image, labelled on its own, agrees at the pixel the disparity (OpenCV
  SGBM on the same half-resolution pair) points to. Pixels without a valid disparity (sky, bare
  road) are kept only at `--conf-no-depth`;
- **temporal**: for static classes, the next frame's labels agree where the pixel lands under the
  relative pose (a `semloc run` trajectory, KITTI format, camera to world: no ground truth) and
  its stereo depth. Dynamic classes are exempt: a moving car lands elsewhere.

Writes ROOT/sequences/<name>/{image_0,semantic}/NNNNNN.png (half-resolution luma and labels), the
layout `train.py --synth ROOT` reads, and ROOT/pseudo_stats.json (kept share per class and
filter). Usage:

    python3 models/pseudo_label.py --checkpoint bn_best.pt --variant bottleneck --out /tmp/pl \
        --raw ../shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0005_sync:/tmp/t0005/trajectory.txt \
        --odometry ../shared/data/kitti-odometry:06:/tmp/t06/trajectory.txt
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import camvid  # noqa: E402
from semloc_models import NUM_CLASSES, VARIANTS, build  # noqa: E402

VOID = camvid.VOID
DYNAMIC = set(camvid.DYNAMIC)


def fail(msg):
    raise SystemExit(f"pseudo_label.py: {msg}")


def read_calib(path, left, right):
    """fx, cx, cy and baseline*fx of a rectified pair from a KITTI calibration file."""
    rows = {}
    try:
        with open(path) as f:
            for line in f:
                if ":" in line:
                    k, v = line.split(":", 1)
                    rows[k.strip()] = v
    except OSError as e:
        fail(f"{path}: {e}")
    try:
        pl = np.array(rows[left].split(), dtype=np.float64).reshape(3, 4)
        pr = np.array(rows[right].split(), dtype=np.float64).reshape(3, 4)
    except (KeyError, ValueError) as e:
        fail(f"{path}: no usable {left} / {right} projection rows ({e})")
    return pl[0, 0], pl[0, 2], pl[1, 2], pl[0, 3] - pr[0, 3]


def read_poses(path, n):
    if path is None:
        return None
    try:
        m = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as e:
        fail(f"{path}: {e}")
    if m.shape[1] != 12 or m.shape[0] < n:
        fail(f"{path}: expected {n} KITTI poses (12 numbers a line), found {m.shape[0]} x {m.shape[1]}")
    out = np.tile(np.eye(4), (m.shape[0], 1, 1))
    out[:, :3, :] = m.reshape(-1, 3, 4)
    return out


def sources(a):
    """(name, left paths, right paths, calib, poses) for each --raw / --odometry source."""
    out = []
    for spec in a.raw:
        drive, _, poses = spec.partition(":")
        l_dir, r_dir = os.path.join(drive, "image_02", "data"), os.path.join(drive, "image_03", "data")
        calib = read_calib(os.path.join(os.path.dirname(os.path.normpath(drive)), "calib_cam_to_cam.txt"),
                           "P_rect_02", "P_rect_03")
        out.append((os.path.basename(os.path.normpath(drive)), l_dir, r_dir, calib, poses or None))
    for spec in a.odometry:
        parts = spec.split(":")
        if len(parts) < 2:
            fail(f"--odometry {spec}: expected ROOT:SEQ[:POSES]")
        root, seq = parts[0], parts[1]
        d = os.path.join(root, "sequences", seq)
        calib = read_calib(os.path.join(d, "calib.txt"), "P0", "P1")
        out.append((f"odometry_{seq}", os.path.join(d, "image_0"), os.path.join(d, "image_1"), calib,
                    parts[2] if len(parts) > 2 else None))
    resolved = []
    for name, l_dir, r_dir, calib, poses in out:
        for d in (l_dir, r_dir):
            if not os.path.isdir(d):
                fail(f"{d}: no such image folder")
        names = sorted(f for f in os.listdir(l_dir) if f.endswith(".png"))
        names = [n for n in names if os.path.exists(os.path.join(r_dir, n))]
        if not names:
            fail(f"{l_dir}: no stereo pairs (same-named png in {r_dir})")
        resolved.append((name, [os.path.join(l_dir, n) for n in names],
                         [os.path.join(r_dir, n) for n in names], calib, read_poses(poses, len(names))))
    return resolved


def half(luma):
    """Box downscale by 2 (floor of odd sizes), rounded to u8: what the Rust side feeds the net."""
    h, w = luma.shape[0] // 2 * 2, luma.shape[1] // 2 * 2
    x = luma[:h, :w].astype(np.uint16)
    s = x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2]
    return ((s + 2) // 4).astype(np.uint8)


@torch.no_grad()
def probs(model, img):
    """Softmax (11 x h x w) of a u8 luma image, edge-padded to multiples of 32, mean with the
    mirror image."""
    h, w = img.shape
    H, W = -(-h // 32) * 32, -(-w // 32) * 32
    x = np.pad(img, ((0, H - h), (0, W - w)), mode="edge").astype(np.float32) / 255.0
    t = torch.from_numpy(x)[None, None]
    p = F.softmax(model(t), 1) + F.softmax(model(torch.flip(t, [3])), 1).flip(3)
    return (p[0, :, :h, :w] / 2).numpy()


def disparity(left, right):
    import cv2  # opencv-python-headless; only this script needs it

    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=64, blockSize=5, P1=8 * 25,
                                 P2=32 * 25, uniquenessRatio=10, speckleWindowSize=50,
                                 speckleRange=2, disp12MaxDiff=1,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    d = sgbm.compute(left, right).astype(np.float32) / 16.0
    d[d <= 0.5] = np.nan
    return d


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--variant", choices=VARIANTS, default=None,
                   help="default: the checkpoint's (the resunet teacher labels too)")
    p.add_argument("--out", required=True)
    p.add_argument("--raw", nargs="*", default=[], metavar="DRIVE_DIR[:POSES]")
    p.add_argument("--odometry", nargs="*", default=[], metavar="ROOT:SEQ[:POSES]")
    p.add_argument("--conf", type=float, default=0.7, help="per-class confidence cap")
    p.add_argument("--conf-no-depth", type=float, default=0.9)
    p.add_argument("--every", type=int, default=1, help="label every K-th frame")
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    if not a.raw and not a.odometry:
        fail("give at least one --raw or --odometry source")
    torch.set_num_threads(a.threads)
    try:
        ck = torch.load(a.checkpoint, map_location="cpu", weights_only=False)
    except (OSError, RuntimeError) as e:
        fail(f"{a.checkpoint}: {e}")
    variant = a.variant or ck.get("variant")
    if variant is None:
        fail(f"{a.checkpoint}: no variant recorded; pass --variant")
    model = build(variant, num_classes=NUM_CLASSES)
    model.load_state_dict(ck["model"])
    model.eval()

    stats = {"checkpoint": os.path.abspath(a.checkpoint), "sources": {}}
    for name, lefts, rights, (fx, cx, cy, bf), poses in sources(a):
        # Half resolution: pixel centres map as x' = (x + 0.5) / 2 - 0.5.
        fx2, cx2, cy2, bf2 = fx / 2, (cx + 0.5) / 2 - 0.5, (cy + 0.5) / 2 - 0.5, bf / 2
        imgs, labs, confs, disps = [], [], [], []
        for lp, rp in zip(lefts, rights):
            li, ri = half(camvid.load_luma(lp)), half(camvid.load_luma(rp))
            pl, pr = probs(model, li), probs(model, ri)
            imgs.append(li)
            labs.append((pl.argmax(0).astype(np.uint8), pr.argmax(0).astype(np.uint8)))
            confs.append(pl.max(0))
            disps.append(disparity(li, ri))
        n = len(imgs)
        # Per-class thresholds: the class's median confidence, capped.
        allc = np.concatenate([c.ravel() for c in confs])
        alll = np.concatenate([l[0].ravel() for l in labs])
        thr = np.full(NUM_CLASSES, a.conf, dtype=np.float32)
        for k in range(NUM_CLASSES):
            sel = allc[alll == k]
            if sel.size:
                thr[k] = min(a.conf, float(np.median(sel)))
        seq_dir = os.path.join(a.out, "sequences", name)
        os.makedirs(os.path.join(seq_dir, "image_0"), exist_ok=True)
        os.makedirs(os.path.join(seq_dir, "semantic"), exist_ok=True)
        tot = np.zeros(NUM_CLASSES, np.int64)
        kept = np.zeros(NUM_CLASSES, np.int64)
        fails = {"confidence": 0, "stereo": 0, "no_depth": 0, "temporal": 0}
        for i in range(0, n, max(1, a.every)):
            lab, lab_r = labs[i]
            conf, d = confs[i], disps[i]
            h, w = lab.shape
            ys, xs = np.mgrid[0:h, 0:w]
            ok = conf >= thr[lab]
            fails["confidence"] += int((~ok).sum())
            valid = np.isfinite(d)
            # Stereo: the right image's label at the matched pixel.
            xr = np.where(valid, np.rint(xs - np.nan_to_num(d)), -1).astype(np.int64)
            inside = valid & (xr >= 0) & (xr < w)
            st = np.zeros_like(ok)
            st[inside] = lab_r[ys[inside], xr[inside]] == lab[inside]
            bad = ok & valid & ~st
            fails["stereo"] += int(bad.sum())
            ok &= ~(valid & ~st)
            nd = ok & ~valid & (conf < a.conf_no_depth)
            fails["no_depth"] += int(nd.sum())
            ok &= ~nd
            # Temporal: static classes land on the same label in the neighbouring frame.
            if poses is not None and n > 1:
                j = i + 1 if i + 1 < n else i - 1
                t_rel = np.linalg.inv(poses[j]) @ poses[i]
                z = bf2 / np.where(valid, d, np.nan)
                pc = np.stack([(xs - cx2) / fx2 * z, (ys - cy2) / fx2 * z, z], -1)
                q = pc @ t_rel[:3, :3].T + t_rel[:3, 3]
                with np.errstate(invalid="ignore", divide="ignore"):
                    u = np.rint(fx2 * q[..., 0] / q[..., 2] + cx2)
                    v = np.rint(fx2 * q[..., 1] / q[..., 2] + cy2)
                land = valid & (q[..., 2] > 0.5) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
                tl = np.ones_like(ok)
                ui, vi = u[land].astype(np.int64), v[land].astype(np.int64)
                tl[land] = labs[j][0][vi, ui] == lab[land]
                static = ~np.isin(lab, list(DYNAMIC))
                tb = ok & static & land & ~tl
                fails["temporal"] += int(tb.sum())
                ok &= ~tb
            out = np.where(ok, lab, VOID).astype(np.uint8)
            for k in range(NUM_CLASSES):
                tot[k] += int((lab == k).sum())
                kept[k] += int((out == k).sum())
            stem = f"{i:06d}.png"
            Image.fromarray(imgs[i]).save(os.path.join(seq_dir, "image_0", stem))
            Image.fromarray(out).save(os.path.join(seq_dir, "semantic", stem))
        stats["sources"][name] = {
            "frames": len(range(0, n, max(1, a.every))),
            "thresholds": {camvid.CLASSES[k]: round(float(thr[k]), 3) for k in range(NUM_CLASSES)},
            "kept_share": round(float(kept.sum() / max(1, tot.sum())), 4),
            "kept_by_class": {camvid.CLASSES[k]: round(float(kept[k] / tot[k]), 3) if tot[k] else None
                              for k in range(NUM_CLASSES)},
            "predicted_share": {camvid.CLASSES[k]: round(float(tot[k] / tot.sum()), 4)
                                for k in range(NUM_CLASSES)},
            "removed_by": {k: round(v / max(1, tot.sum()), 4) for k, v in fails.items()},
        }
        print(name, json.dumps(stats["sources"][name]), flush=True)
    with open(os.path.join(a.out, "pseudo_stats.json"), "w") as f:
        json.dump(stats, f, indent=1)


if __name__ == "__main__":
    main()
