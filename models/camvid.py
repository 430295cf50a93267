"""CamVid (SegNet split) as luma images for semloc's segmentation net.

Reads ../shared/data/camvid/{train,val}/*.jpg with labels {train,val}annot/*.png (ids 0..10,
11 = void, ignored). Luma is Pillow's Image.convert('L') (ITU-R BT.601, fixed point
L = (R*19595 + G*38470 + B*7471 + 0x8000) >> 16), the same conversion the Rust side uses, so the
net sees the same numbers on KITTI colour (converted) and grey frames. The net's input is
luma / 255 in [0, 1].
"""

from __future__ import annotations

import math
import os
import random

import numpy as np
import torch
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
# SEMLOC_CAMVID overrides it where ../shared is not beside the checkout (the lent GPU machine).
DEFAULT_ROOT = os.environ.get("SEMLOC_CAMVID") or os.path.normpath(
    os.path.join(HERE, "..", "..", "shared", "data", "camvid"))

CLASSES = ["sky", "building", "pole", "road", "pavement", "tree", "sign-symbol", "fence", "car",
           "pedestrian", "bicyclist"]
VOID = 11
# The paper's categories (dynamic: human, vehicle; static: construction, object, flat, nature; sky).
CATEGORIES = {
    "human": [9, 10],
    "vehicle": [8],
    "construction": [1, 7],
    "object": [2, 6],
    "flat": [3, 4],
    "nature": [5],
    "sky": [0],
}
DYNAMIC = [8, 9, 10]


def list_split(root, split):
    img_dir = os.path.join(root, split)
    ann_dir = os.path.join(root, split + "annot")
    names = sorted(f for f in os.listdir(img_dir) if f.endswith(".jpg"))
    return [(os.path.join(img_dir, n), os.path.join(ann_dir, n[:-4] + ".png")) for n in names]


def sequence_of(path):
    """CamVid sequence of an image path: the file-name prefix before '_' (0001TP, 0006R0,
    0016E5, Seq05VD)."""
    return os.path.basename(path).split("_", 1)[0]


def list_sequences(root, splits, include=None, exclude=None):
    """Items of `splits` whose sequence is in `include` (all when None) and not in `exclude`."""
    items = []
    for sp in splits:
        for it in list_split(root, sp):
            seq = sequence_of(it[0])
            if include is not None and seq not in include:
                continue
            if exclude is not None and seq in exclude:
                continue
            items.append(it)
    return items


def list_synth(root, every=1):
    """(image, label) pairs of a `semloc synth` output root: every `every`-th frame of each
    `sequences/XX`, its left image (`image_0`, grey, or `image_2`, colour; both become luma)
    with `semantic/` (CamVid ids, the generator's exact labels). Raises on a root without
    any such sequence, so a mistyped path is not trained on as nothing."""
    seq_root = os.path.join(root, "sequences")
    items = []
    if os.path.isdir(seq_root):
        for seq in sorted(os.listdir(seq_root)):
            d = os.path.join(seq_root, seq)
            sem = os.path.join(d, "semantic")
            img = next((os.path.join(d, c) for c in ("image_0", "image_2")
                        if os.path.isdir(os.path.join(d, c))), None)
            if img is None or not os.path.isdir(sem):
                continue
            names = sorted(f for f in os.listdir(sem) if f.endswith(".png"))
            for n in names[::max(1, every)]:
                if os.path.exists(os.path.join(img, n)):
                    items.append((os.path.join(img, n), os.path.join(sem, n)))
    if not items:
        raise ValueError(f"{root}: no `semloc synth` sequence (sequences/XX/image_0|image_2 + semantic/)")
    return items


def load_luma(path):
    """u8 luma, H x W (Pillow BT.601 fixed point, as the Rust side)."""
    return np.asarray(Image.open(path).convert("L"), dtype=np.uint8)


def load_label(path):
    lab = np.asarray(Image.open(path), dtype=np.uint8).copy()
    lab[lab > VOID] = VOID
    return lab


def pad_to_multiple(img, lab, m=32, img_fill="edge"):
    """Pad bottom/right so both sides are multiples of m (image edge-replicated, label void)."""
    h, w = img.shape
    H, W = math.ceil(h / m) * m, math.ceil(w / m) * m
    if (H, W) == (h, w):
        return img, lab
    img = np.pad(img, ((0, H - h), (0, W - w)), mode=img_fill)
    if lab is not None:
        lab = np.pad(lab, ((0, H - h), (0, W - w)), mode="constant", constant_values=VOID)
    return img, lab


def to_input(img):
    """A luma image (H x W, 0..255) as the network's 1 x H x W input, luma / 255."""
    return torch.from_numpy(np.ascontiguousarray(img, dtype=np.float32) / 255.0)[None]


class CamVid(torch.utils.data.Dataset):
    """split 'train' (augmented random crops) or 'val' (whole images, padded to a multiple of 32).

    Augmentation (train): random scale 0.5..2.0 (bilinear image, nearest label), random crop of
    `crop` (h, w) (padding with void / edge where the scaled image is smaller; a list of shapes takes
    them in turn by epoch, so a batch's crops share one shape), horizontal flip,
    brightness/contrast/gamma jitter, Gaussian noise. All randomness comes from a per-sample
    generator seeded with (seed, epoch, index), so runs are reproducible for any worker count.
    The epoch must reach the DataLoader's worker processes, which hold copies of the dataset made
    when they started: train with `EpochSampler`, whose indices carry it.
    """

    def __init__(self, split, root=DEFAULT_ROOT, crop=(384, 384), augment=None, limit=None,
                 scale=(0.5, 2.0), seed=0, cache=True, items=None, strong=False, pad_random=False):
        self.split = split
        self.pad_random = pad_random
        self.items = list_split(root, split) if items is None else list(items)
        self.strong = strong
        if limit:
            self.items = self.items[:limit]
        self.crops = [tuple(crop)] if isinstance(crop[0], int) else [tuple(c) for c in crop]
        self.augment = (split == "train") if augment is None else augment
        self.scale = scale
        self.seed = seed
        self.epoch = 0
        self._cache = {} if cache else None

    def __len__(self):
        return len(self.items)

    def set_epoch(self, e):
        self.epoch = e

    def _load(self, i):
        if self._cache is not None and i in self._cache:
            return self._cache[i]
        ip, lp = self.items[i]
        pair = (load_luma(ip), load_label(lp))
        if self._cache is not None:
            self._cache[i] = pair
        return pair

    def __getitem__(self, i):
        epoch = self.epoch
        if isinstance(i, tuple):  # from EpochSampler: (epoch, index)
            epoch, i = i
        img, lab = self._load(i)
        if self.augment:
            rng = random.Random((self.seed * 1_000_003 + epoch) * 10_007 + i)
            img, lab = self._augment(img, lab, rng, self.crops[epoch % len(self.crops)])
        else:
            img, lab = pad_to_multiple(img, lab)
        x = to_input(img)
        y = torch.from_numpy(np.ascontiguousarray(lab).astype(np.int64))
        return x, y

    def _augment(self, img, lab, rng, crop):
        h, w = img.shape
        s = rng.uniform(*self.scale)
        nh, nw = max(1, round(h * s)), max(1, round(w * s))
        img = np.asarray(Image.fromarray(img).resize((nw, nh), Image.BILINEAR), dtype=np.float32)
        lab = np.asarray(Image.fromarray(lab).resize((nw, nh), Image.NEAREST))
        ch, cw = crop
        # pad (image with its mean-free edge, label void) when smaller than the crop
        ph, pw = max(0, ch - nh), max(0, cw - nw)
        if ph or pw:
            # by default the image sits at the crop's top left; `pad_random` places it anywhere in
            # it (a wide crop otherwise always has the image on its left and edge streaks right)
            t = rng.randint(0, ph) if self.pad_random and ph else 0
            l = rng.randint(0, pw) if self.pad_random and pw else 0
            img = np.pad(img, ((t, ph - t), (l, pw - l)), mode="edge")
            lab = np.pad(lab, ((t, ph - t), (l, pw - l)), mode="constant", constant_values=VOID)
        H, W = img.shape
        y0, x0 = rng.randint(0, H - ch), rng.randint(0, W - cw)
        img = img[y0:y0 + ch, x0:x0 + cw]
        lab = lab[y0:y0 + ch, x0:x0 + cw]
        if rng.random() < 0.5:
            img, lab = img[:, ::-1], lab[:, ::-1]
        # photometric: contrast, brightness, gamma, noise (in 0..255)
        f = img / 255.0
        c = rng.uniform(0.7, 1.3)
        b = rng.uniform(-0.15, 0.15)
        f = (f - 0.5) * c + 0.5 + b
        f = np.clip(f, 0.0, 1.0)
        g = math.exp(rng.uniform(math.log(0.7), math.log(1.4)))
        f = f ** g
        if self.strong:
            # KITTI-like appearance: a stronger exposure range, defocus / motion blur and
            # sensor noise, so the net does not learn CamVid's one camera.
            f = np.clip(f * rng.uniform(0.6, 1.5), 0.0, 1.0)
            if rng.random() < 0.4:
                f = _blur(f, rng)
        if rng.random() < (0.7 if self.strong else 0.5):
            sigma = rng.uniform(0.0, 0.05 if self.strong else 0.03)
            nrng = np.random.default_rng(rng.randrange(1 << 31))
            f = f + nrng.normal(0.0, sigma, f.shape)
        # back to u8 levels, as the engine only ever sees u8 luma
        img = np.clip(np.round(f * 255.0), 0, 255)
        return img, lab


class EpochSampler(torch.utils.data.RandomSampler):
    """The DataLoader's shuffle (torch's RandomSampler, the same order from the same generator)
    with the dataset's current epoch in every index: it yields (epoch, i).

    `CamVid.set_epoch` changes the main process's copy of the dataset only. DataLoader workers,
    persistent ones above all, keep the copy they were started with, so with `--workers` > 0 every
    epoch used to get epoch 0's augmentation: the same crop, scale, flip and noise of each image,
    every epoch. The sampler runs in the main process, so its indices carry the right epoch."""

    def __iter__(self):
        epoch = self.data_source.epoch
        for i in super().__iter__():
            yield (epoch, i)


def _blur(f, rng):
    """Separable box blur of radius 1-2 along x (motion) or both axes (defocus)."""
    r = rng.choice([1, 1, 2])
    k = 2 * r + 1
    g = np.pad(f, r, mode="edge")
    c = np.cumsum(np.cumsum(g, 0), 1)
    c = np.pad(c, ((1, 0), (1, 0)))
    if rng.random() < 0.5:  # defocus: k x k box
        out = (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)
    else:  # horizontal motion: 1 x k
        row = np.pad(np.cumsum(g[r:-r], 1), ((0, 0), (1, 0)))
        out = (row[:, k:] - row[:, :-k]) / k
    return out


def confusion(pred, target, n=len(CLASSES)):
    """n x n confusion matrix (rows: truth, cols: prediction) over pixels whose truth < n."""
    pred = pred.reshape(-1).long()
    target = target.reshape(-1).long()
    k = target < n
    idx = target[k] * n + pred[k].clamp(0, n - 1)
    return torch.bincount(idx, minlength=n * n).reshape(n, n)


def iou_from_confusion(cm):
    cm = cm.double()
    tp = cm.diag()
    denom = cm.sum(0) + cm.sum(1) - tp
    return torch.where(denom > 0, tp / denom.clamp(min=1), torch.full_like(tp, float("nan")))


def category_confusion(cm):
    cats = list(CATEGORIES.values())
    m = torch.zeros(len(cats), cm.shape[0], dtype=cm.dtype)
    for ci, ids in enumerate(cats):
        m[ci, ids] = 1
    return m @ cm @ m.T


def metrics(cm):
    iou = iou_from_confusion(cm)
    ccm = category_confusion(cm)
    ciou = iou_from_confusion(ccm)
    acc = (cm.diag().sum() / cm.sum().clamp(min=1)).item()
    # The dynamic mask culling uses (car, pedestrian, bicyclist): pixel precision and recall.
    d = torch.tensor(DYNAMIC)
    tp = cm[d][:, d].sum().item()
    pred_dyn = cm[:, d].sum().item()
    gt_dyn = cm[d].sum().item()
    return {
        "dyn_precision": tp / pred_dyn if pred_dyn else float("nan"),
        "dyn_recall": tp / gt_dyn if gt_dyn else float("nan"),
        "miou": float(np.nanmean(iou.numpy())),
        "iou": {c: float(v) for c, v in zip(CLASSES, iou.tolist())},
        "cat_miou": float(np.nanmean(ciou.numpy())),
        "cat_iou": {c: float(v) for c, v in zip(CATEGORIES, ciou.tolist())},
        "pixel_acc": acc,
    }


def class_frequencies(ds):
    cnt = np.zeros(len(CLASSES), np.float64)
    for i in range(len(ds)):
        _, lab = ds._load(i)
        cnt += np.bincount(lab.reshape(-1), minlength=VOID + 1)[: len(CLASSES)]
    return cnt / cnt.sum()
