#!/usr/bin/env python3
"""Train Fast-SCNN / Fast-SCNN-Res2Net on CamVid train, select on CamVid val.

  python3 models/train.py --variant res2net --epochs 200 --batch 8 --crop 384x384 --out models/runs/r2

Writes to --out: best.pt (best val mIoU), last.pt, metrics.json (args, per-eval history, best).
Checkpoints stay out of git (models/.gitignore ignores runs/).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import json
import math
import os
import random
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import camvid  # noqa: E402
from semloc_models import IGNORE_INDEX, NUM_CLASSES, VARIANTS, build, count_params, zero_init_residual  # noqa: E402
from semloc_models.fastscnn import AuxHeads  # noqa: E402


def parse_hw(s):
    h, w = s.lower().split("x")
    return int(h), int(w)


def parse_class_boost(items):
    """["car=2", "pedestrian=1.5"] -> {"car": 2.0, "pedestrian": 1.5}; ValueError naming the bad item."""
    out = {}
    for item in items:
        name, sep, val = item.partition("=")
        if not sep or name not in camvid.CLASSES:
            raise ValueError(f"--class-boost {item!r}: expected CLASS=FACTOR with CLASS one of {', '.join(camvid.CLASSES)}")
        try:
            f = float(val)
        except ValueError:
            f = -1.0
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"--class-boost {item!r}: FACTOR must be a positive finite number")
        if name in out:
            raise ValueError(f"--class-boost {item!r}: {name} is given twice")
        out[name] = f
    return out


def get_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--variant", choices=list(VARIANTS), default="res2net",
                   help="resunet: the larger distillation teacher (semloc_models/teacher.py); bottleneck-ibn: the "
                   "bottleneck with IBN in the LDS (a domain-generalisation experiment); both never exported")
    p.add_argument("--epochs", type=int, default=200)
    p.add_argument("--max-iters", type=int, default=0, help="stop after this many iterations (smoke runs)")
    p.add_argument("--time-budget", type=float, default=0,
                   help="seconds of training to fit the schedule into (a lent GPU's time is fixed): after "
                   "70 iterations the poly schedule is shortened, if need be, to the iterations that fit, "
                   "at the wall time per iteration measured over iterations 20-70 plus a 10 %% margin "
                   "for the evaluations; 0 = the full --epochs")
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--lr", type=float, default=None, help="default 0.045 (sgd) / 2e-3 (adamw)")
    p.add_argument("--optim", choices=["sgd", "adamw"], default="sgd")
    p.add_argument("--wd", type=float, default=None, help="default 4e-5 (sgd) / 1e-2 (adamw)")
    p.add_argument("--poly-power", type=float, default=0.9)
    p.add_argument("--warmup-iters", type=int, default=200)
    p.add_argument("--crop", type=parse_hw, nargs="+", default=[(384, 384)],
                   help="HxW training crop; several shapes (e.g. 384x384 192x640) take turns by epoch")
    p.add_argument("--scale", type=float, nargs=2, default=(0.5, 2.0))
    p.add_argument("--pad-random", action="store_true",
                   help="place a scaled image smaller than the crop anywhere in it (default: top left); "
                        "for wide, KITTI-shaped crops such as 192x640")
    p.add_argument("--class-weights", choices=["none", "enet"], default="none",
                   help="enet: w_c = 1/ln(1.02 + p_c) from train label frequencies")
    p.add_argument("--class-boost", nargs="+", default=[], metavar="CLASS=F",
                   help="multiply the loss weight of CLASS by F (on top of --class-weights), e.g. car=2")
    p.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "runs", "default"))
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--workers", type=int, default=0, help="DataLoader workers")
    p.add_argument("--limit-images", type=int, default=0, help="use only the first N train images")
    p.add_argument("--limit-val", type=int, default=0, help="use only the first N val images")
    p.add_argument("--eval-every", type=int, default=5, help="evaluate on val every K epochs (and at the end)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--amp", action="store_true", help="bf16 autocast on CUDA")
    p.add_argument("--data", default=camvid.DEFAULT_ROOT)
    p.add_argument("--holdout-seq", default="",
                   help="CamVid sequence kept out of training entirely (e.g. 0006R0): train on "
                   "train+val without it, select on it, report val beside it")
    p.add_argument("--synth", nargs="+", default=[], metavar="DIR",
                   help="also train on `semloc synth` output roots (their exact labels): "
                   "every --synth-every-th frame of each sequence joins the training set")
    p.add_argument("--synth-every", type=int, default=1)
    p.add_argument("--aug", choices=["basic", "strong"], default="basic",
                   help="strong: wider exposure range, blur, more noise (KITTI-like appearance)")
    p.add_argument("--classmix", type=float, default=0.0, metavar="P",
                   help="ClassMix (Olsson et al. 2021): with probability P per sample, paste the "
                   "pixels of half the classes of another image of the batch, labels with them "
                   "(new layouts from the same few sequences)")
    p.add_argument("--resume", default="", help="checkpoint to start from: weights, and when it holds "
                   "them (every last.pt does) the optimiser state, epoch and iteration, so the "
                   "schedule continues where an interrupted run stopped")
    p.add_argument("--init", default="",
                   help="fine-tune: start from this checkpoint's weights (a fresh schedule, no optimiser "
                   "state); its BatchNorm statistics are re-estimated on --renorm-batches training "
                   "batches first, so that a BN-folded network (onnx_to_checkpoint.py) trains with "
                   "normalised activations and gives the same outputs in eval mode")
    p.add_argument("--renorm-batches", type=int, default=20)
    p.add_argument("--teacher", nargs="+", default=[], metavar="CKPT",
                   help="distil from these checkpoints (their mean softmax at --kd-temp) on every "
                   "training crop, void pixels included: loss = (1 - a) CE(labels) + a T^2 KL(teacher || student)")
    p.add_argument("--kd-alpha", type=float, default=0.5, metavar="A")
    p.add_argument("--kd-temp", type=float, default=2.0, metavar="T")
    p.add_argument("--zero-init-residual", action="store_true",
                   help="start every residual block as the identity: the BatchNorm scale of its last conv "
                   "(Bottleneck's projection, Res2NetBlock's expand) set to 0 (Goyal et al. 2017)")
    p.add_argument("--ema", type=float, default=0.0, metavar="D",
                   help="keep an exponential moving average of the weights (and BatchNorm statistics) "
                   "with decay D per iteration (e.g. 0.999; 0 = off); evaluations score both, and "
                   "best.pt is selected on and holds the averaged weights")
    p.add_argument("--aux-weight", type=float, default=0.0, metavar="W",
                   help="Fast-SCNN's auxiliary losses: cross-entropy of a small head on the LDS output "
                   "and one on the GFE's (after the PPM), each weighted W (the Fast-SCNN paper: 0.4; "
                   "0 = off); training only, the heads are not part of the exported network")
    a = p.parse_args(argv)
    if a.aux_weight < 0:
        p.error(f"--aux-weight {a.aux_weight}: must be >= 0")
    if not 0.0 <= a.ema < 1.0:
        p.error(f"--ema {a.ema}: the decay must be in [0, 1)")
    try:
        a.class_boost = parse_class_boost(a.class_boost)
    except ValueError as e:
        p.error(str(e))
    return a


@contextlib.contextmanager
def exact_fp32():
    """Full-precision float32 convolutions and matmuls on CUDA for the duration (CUDA's default lets
    cuDNN use TF32, whose 10-bit mantissa moves a deep network's outputs by ~1e-2: too much for a
    check that an exact re-parametrisation left them unchanged). A no-op on CPU."""
    saved = (torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32)
    torch.backends.cudnn.allow_tf32 = False
    torch.backends.cuda.matmul.allow_tf32 = False
    try:
        yield
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = saved


class WeightEma:
    """Exponential moving average of a model's state (parameters and floating buffers, i.e.
    BatchNorm running statistics; integer buffers are copied). The decay ramps up as
    min(D, (1 + n) / (10 + n)) over the first updates, so the average is not dominated by the
    random initialisation of a short run."""

    def __init__(self, model, decay, updates=0):
        self.model = copy.deepcopy(model).eval().requires_grad_(False)
        self.decay, self.updates = decay, updates

    @torch.no_grad()
    def update(self, model):
        self.updates += 1
        d = min(self.decay, (1.0 + self.updates) / (10.0 + self.updates))
        src = model.state_dict()
        for k, v in self.model.state_dict().items():
            if v.dtype.is_floating_point:
                v.mul_(d).add_(src[k].detach(), alpha=1.0 - d)
            else:
                v.copy_(src[k])


@torch.no_grad()
def renormalise_bn(model, loader, device, batches):
    """Re-estimates every BatchNorm2d's statistics from `batches` batches of `loader` without
    changing what the network computes in eval mode: the layer's affine map s*x + c (s =
    weight / sqrt(running_var + eps), c = bias - s * running_mean) is re-expressed around the
    measured mean mu and variance var of its input, weight = s * sqrt(var + eps), bias = c + s * mu.
    A BN-folded network's BatchNorms are identities carrying the conv bias (onnx_to_checkpoint.py);
    in training mode they would normalise by batch statistics the folded weights never saw.
    After this, batch statistics are close to the running ones, so the first training steps
    start from the network as it was. Returns the largest change of an eval-mode output (a check)."""
    bns = [m for m in model.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    sums = {id(m): [0.0, 0.0, 0] for m in bns}

    def hook(m, inp, _out):
        x = inp[0].double()
        acc = sums[id(m)]
        acc[0] = acc[0] + x.sum(dim=(0, 2, 3))
        acc[1] = acc[1] + (x * x).sum(dim=(0, 2, 3))
        acc[2] += x.numel() // x.shape[1]

    model.eval()
    handles = [m.register_forward_hook(hook) for m in bns]
    probe = None
    for k, (x, _y) in enumerate(loader):
        if k >= batches:
            break
        x = x.to(device)
        out = model(x)
        if probe is None:
            probe = (x, out)
    for h in handles:
        h.remove()
    if probe is None:
        raise SystemExit("--init: the training set gave no batch to re-estimate BatchNorm on")
    for m in bns:
        s1, s2, n = sums[id(m)]
        mu = s1 / n
        var = (s2 / n - mu * mu).clamp_min(0.0)
        s = m.weight.double() / torch.sqrt(m.running_var.double() + m.eps)
        c = m.bias.double() - s * m.running_mean.double()
        m.running_mean.copy_(mu.float())
        m.running_var.copy_(var.float())
        m.weight.copy_((s * torch.sqrt(var + m.eps)).float())
        m.bias.copy_((c + s * mu).float())
    err = float((model(probe[0]) - probe[1]).abs().max())
    model.train()
    return err


def classmix(x, y, gen, p):
    """ClassMix on a batch: sample i (with probability p) takes from sample i+1 (cyclic) the
    pixels of a random half of the classes present there, image and labels alike. `gen` is a
    CPU torch.Generator (deterministic for a seed). Returns new tensors."""
    n = x.shape[0]
    if n < 2 or p <= 0:
        return x, y
    x, y = x.clone(), y.clone()
    src_x, src_y = x.roll(1, 0).clone(), y.roll(1, 0).clone()
    for i in range(n):
        if torch.rand((), generator=gen).item() >= p:
            continue
        present = torch.unique(src_y[i].cpu())
        present = present[present != IGNORE_INDEX]
        if len(present) < 2:
            continue
        pick = present[torch.randperm(len(present), generator=gen)[: len(present) // 2]]
        m = torch.isin(src_y[i], pick.to(src_y.device))
        x[i] = torch.where(m.unsqueeze(0), src_x[i], x[i])
        y[i] = torch.where(m, src_y[i], y[i])
    return x, y


def distill_loss(logits, teachers, x, a):
    """T^2 KL(p_teacher || p_student) at temperature T, summed over classes, mean over every pixel
    (void too: the teacher has an opinion where the annotators gave none). Several teachers: the
    mean of their softmaxes."""
    temp = a.kd_temp
    with torch.no_grad(), torch.autocast("cuda", dtype=torch.bfloat16, enabled=x.device.type == "cuda"):
        p = sum(F.softmax(t(x).float() / temp, 1) for t in teachers) / len(teachers)
    logq = F.log_softmax(logits.float() / temp, 1)
    return temp * temp * (p * (torch.log(p.clamp_min(1e-8)) - logq)).sum(1).mean()


def seed_all(seed):
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.cuda.manual_seed_all(seed)


@torch.no_grad()
def evaluate(model, loader, device, amp=False):
    """Confusion matrix of `model` on `loader`, in eval mode; the model is left in the mode it
    was in (the training model in training mode, --ema's averaged copy in eval mode)."""
    was_training = model.training
    model.eval()
    cm = torch.zeros(NUM_CLASSES, NUM_CLASSES, dtype=torch.int64)
    for x, y in loader:
        x = x.to(device)
        with torch.autocast("cuda", dtype=torch.bfloat16, enabled=amp and device.type == "cuda"):
            logits = model(x)
        pred = logits.float().argmax(1).cpu()
        cm += camvid.confusion(pred, y)
    model.train(was_training)
    return cm


def main(argv=None):
    a = get_args(argv)
    torch.set_num_threads(a.threads)
    seed_all(a.seed)
    if a.device == "auto":
        device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    else:
        device = torch.device(a.device)
    if device.type == "cuda":
        torch.backends.cudnn.benchmark = True
    lr = a.lr if a.lr is not None else (0.045 if a.optim == "sgd" else 2e-3)
    wd = a.wd if a.wd is not None else (4e-5 if a.optim == "sgd" else 1e-2)
    os.makedirs(a.out, exist_ok=True)

    train_items = None
    if a.holdout_seq:
        train_items = camvid.list_sequences(a.data, ["train", "val"], exclude={a.holdout_seq})
        sel_items = camvid.list_sequences(a.data, ["train", "val"], include={a.holdout_seq})
        if not sel_items:
            raise SystemExit(f"--holdout-seq {a.holdout_seq}: no such sequence in {a.data}")
    if a.synth:
        if train_items is None:
            train_items = camvid.list_split(a.data, "train")
        n_camvid = len(train_items)
        for root in a.synth:
            try:
                train_items = train_items + camvid.list_synth(root, a.synth_every)
            except ValueError as e:
                raise SystemExit(f"--synth: {e}")
        print(f"training set: {n_camvid} CamVid + {len(train_items) - n_camvid} synthetic frames", flush=True)
    train_ds = camvid.CamVid("train", a.data, crop=a.crop, limit=a.limit_images or None,
                             scale=tuple(a.scale), seed=a.seed, items=train_items,
                             strong=a.aug == "strong", pad_random=a.pad_random)
    # Selection set: the held-out sequence when there is one, else CamVid val.
    val_ds = camvid.CamVid("val", a.data, limit=a.limit_val or None,
                           items=sel_items if a.holdout_seq else None)
    seen_val_ds = camvid.CamVid("val", a.data) if a.holdout_seq else None
    g = torch.Generator()
    g.manual_seed(a.seed)
    # EpochSampler: the shuffle of shuffle=True, with the epoch carried to the workers' copies of
    # the dataset (without it, every epoch after the first repeated the first one's augmentation
    # whenever --workers > 0: every lent-GPU run before 2026-12-04).
    train_dl = torch.utils.data.DataLoader(
        train_ds, batch_size=a.batch, sampler=camvid.EpochSampler(train_ds, generator=g),
        drop_last=len(train_ds) >= a.batch,
        num_workers=a.workers, generator=g, persistent_workers=a.workers > 0,
        pin_memory=device.type == "cuda")
    val_dl = torch.utils.data.DataLoader(val_ds, batch_size=4, num_workers=a.workers)
    seen_val_dl = (torch.utils.data.DataLoader(seen_val_ds, batch_size=4, num_workers=a.workers)
                   if seen_val_ds is not None else None)

    model = build(a.variant).to(device)
    if a.zero_init_residual:
        if a.init or a.resume:
            raise SystemExit("--zero-init-residual initialises a run from scratch; --init and --resume load weights")
        n = zero_init_residual(model)
        if n == 0:
            raise SystemExit(f"--zero-init-residual: the {a.variant} variant has no Bottleneck or Res2Net blocks")
        print(f"zero-initialised residual branches: {n}", flush=True)
    resume = torch.load(a.resume, map_location="cpu") if a.resume else None
    if resume is not None:
        model.load_state_dict(resume["model"])
    if a.init:
        if resume is not None:
            raise SystemExit("--init and --resume: give one (--resume continues a run, --init starts one)")
        init = torch.load(a.init, map_location="cpu")
        if init.get("variant", a.variant) != a.variant:
            raise SystemExit(f"--init {a.init}: a {init['variant']} checkpoint, not {a.variant}")
        model.load_state_dict(init["model"])
        with exact_fp32():
            err = renormalise_bn(model, train_dl, device, a.renorm_batches)
        print(f"initialised from {a.init}; BatchNorm re-estimated on {a.renorm_batches} batches "
              f"(largest eval-mode output change {err:.2e})", flush=True)
        if not err < 1e-2:
            raise SystemExit(f"--init {a.init}: re-estimating BatchNorm changed the outputs by {err:.3g}")
    ema = WeightEma(model, a.ema) if a.ema > 0 else None
    if ema is not None and resume is not None and "ema" in resume:
        ema.model.load_state_dict(resume["ema"])
        ema.updates = resume.get("ema_updates", resume["iter"])
    teachers = []
    for path in a.teacher:
        t = torch.load(path, map_location="cpu")
        tm = build(t.get("variant", a.variant))
        tm.load_state_dict(t["model"])
        teachers.append(tm.to(device).eval().requires_grad_(False))
        print(f"teacher {path}: {t.get('variant')} selected at epoch {t.get('epoch')}, "
              f"mIoU {t.get('metrics', {}).get('miou', float('nan')) * 100:.2f}", flush=True)
    aux = None
    if a.aux_weight > 0:
        if not (hasattr(model, "lds") and hasattr(model, "ppm")):
            raise SystemExit(f"--aux-weight: the {a.variant} variant has no LDS and PPM to put auxiliary heads on")
        # After the EMA copy, so that the copy does not carry the hooks.
        aux = AuxHeads(model).to(device)
        if resume is not None:
            if "aux" not in resume:
                raise SystemExit(f"--resume {a.resume}: the run had no auxiliary heads (--aux-weight)")
            aux.load_state_dict(resume["aux"])
        print(f"auxiliary losses on the LDS and GFE outputs, weight {a.aux_weight} "
              f"({count_params(aux):,} training-only parameters)", flush=True)
    elif resume is not None and "aux" in resume:
        raise SystemExit(f"--resume {a.resume}: the run had auxiliary heads; give its --aux-weight again")
    nparams = count_params(model)
    print(f"variant={a.variant} params={nparams:,} device={device} train={len(train_ds)} val={len(val_ds)}",
          flush=True)

    weight = None
    if a.class_weights == "enet":
        freq = camvid.class_frequencies(train_ds)
        weight = torch.tensor(1.0 / np.log(1.02 + freq), dtype=torch.float32, device=device)
    if a.class_boost:
        if weight is None:
            weight = torch.ones(len(camvid.CLASSES), dtype=torch.float32, device=device)
        for c, f in a.class_boost.items():
            weight[camvid.CLASSES.index(c)] *= f
    if weight is not None:
        print("class weights", [round(float(w), 2) for w in weight], flush=True)

    decay, no_decay = [], []
    for n, p_ in list(model.named_parameters()) + (list(aux.named_parameters()) if aux is not None else []):
        (no_decay if p_.ndim <= 1 else decay).append(p_)
    groups = [{"params": decay, "weight_decay": wd}, {"params": no_decay, "weight_decay": 0.0}]
    if a.optim == "sgd":
        opt = torch.optim.SGD(groups, lr=lr, momentum=0.9, nesterov=True)
    else:
        opt = torch.optim.AdamW(groups, lr=lr)

    iters_per_epoch = max(1, len(train_dl))
    total = a.epochs * iters_per_epoch
    if a.max_iters:
        total = min(total, a.max_iters)

    def lr_at(it):
        w = min(1.0, (it + 1) / a.warmup_iters) if a.warmup_iters else 1.0
        return lr * w * (1 - it / max(1, total)) ** a.poly_power

    history, best = [], {"miou": -1.0}
    it, t_start, start_epoch = 0, time.time(), 0
    if resume is not None and "opt" in resume:
        opt.load_state_dict(resume["opt"])
        start_epoch, it = resume["epoch"], resume["iter"]
        history, best = resume.get("history", []), resume.get("best", best)
        print(f"resumed at epoch {start_epoch}, iteration {it}", flush=True)
    iter_times, data_times = [], []
    mix_gen = torch.Generator()
    mix_gen.manual_seed(a.seed + 7919)
    done = False
    fitted = None  # (iterations the schedule was cut to, s/iter it was measured at)
    for epoch in range(start_epoch, a.epochs):
        train_ds.set_epoch(epoch)
        run_loss, n_b = 0.0, 0
        t_data = time.time()
        for x, y in train_dl:
            t0 = time.time()
            data_times.append(t0 - t_data)
            for gr in opt.param_groups:
                gr["lr"] = lr_at(it)
            x, y = x.to(device, non_blocking=True), y.to(device, non_blocking=True)
            if a.classmix > 0:
                x, y = classmix(x, y, mix_gen, a.classmix)
            with torch.autocast("cuda", dtype=torch.bfloat16, enabled=a.amp and device.type == "cuda"):
                logits = model(x)
                aux_logits = aux(tuple(x.shape[2:])) if aux is not None else []
            labelled = bool((y != IGNORE_INDEX).any())
            if labelled:
                loss = F.cross_entropy(logits.float(), y, weight=weight, ignore_index=IGNORE_INDEX)
            else:  # all-void crop: no gradient (plain CE would be 0/0 = NaN)
                loss = logits.float().sum() * 0.0
            if teachers:
                loss = (1.0 - a.kd_alpha) * loss + a.kd_alpha * distill_loss(logits, teachers, x, a)
            for al in aux_logits:  # on the labels only, beside the distillation term
                loss = loss + (a.aux_weight * F.cross_entropy(al.float(), y, weight=weight, ignore_index=IGNORE_INDEX)
                               if labelled else al.float().sum() * 0.0)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            if ema is not None:
                ema.update(model)
            if device.type == "cuda":
                torch.cuda.synchronize()
            iter_times.append(time.time() - t0)
            t_data = time.time()
            run_loss += loss.item()
            n_b += 1
            it += 1
            if a.time_budget and len(iter_times) == 20:
                t_rate = time.time()  # after start-up and cuDNN's algorithm search
            if a.time_budget and fitted is None and len(iter_times) == 70:
                # Wall time per iteration over iterations 20-70 (data loading and transfers
                # included; no evaluation falls in that window at the usual --eval-every), with a
                # 10 % margin for the evaluations to come; the poly decay is re-aimed at the cut.
                rate = 1.1 * (time.time() - t_rate) / 50
                fit = max(it, it + int((a.time_budget - (time.time() - t_start)) / rate))
                fitted = (min(total, fit), rate)
                if fit < total:
                    print(f"--time-budget {a.time_budget:.0f}s at {rate:.3f} s/iter: schedule cut from "
                          f"{total} to {fit} iterations ({fit / iters_per_epoch:.1f} epochs)", flush=True)
                    total = fit
            if it >= total:
                done = True
                break
        last_epoch = done or epoch == a.epochs - 1
        msg = (f"epoch {epoch + 1}/{a.epochs} it {it} loss {run_loss / max(1, n_b):.4f} "
               f"lr {lr_at(max(0, it - 1)):.5f} s/iter {np.mean(iter_times[-n_b:]):.3f} "
               f"(+data {np.mean(data_times[-n_b:]):.3f}) "
               f"elapsed {time.time() - t_start:.0f}s")
        print(msg, flush=True)
        if (epoch + 1) % a.eval_every == 0 or last_epoch:
            # With --ema the averaged weights are the ones selected, saved and exported; the raw
            # weights' scores are kept beside them for the comparison.
            sel = ema.model if ema is not None else model
            m = camvid.metrics(evaluate(sel, val_dl, device, a.amp))
            m.update(epoch=epoch + 1, iter=it, loss=run_loss / max(1, n_b), elapsed_s=time.time() - t_start)
            if ema is not None:
                mr = camvid.metrics(evaluate(model, val_dl, device, a.amp))
                m.update(raw_miou=mr["miou"], raw_cat_miou=mr["cat_miou"], raw_dyn_precision=mr["dyn_precision"],
                         raw_dyn_recall=mr["dyn_recall"])
            if seen_val_dl is not None:
                mv = camvid.metrics(evaluate(sel, seen_val_dl, device, a.amp))
                m.update(val_seen_miou=mv["miou"], val_seen_cat_miou=mv["cat_miou"])
            history.append(m)
            name = f"held-out {a.holdout_seq}" if a.holdout_seq else "val"
            print(f"  {name} mIoU {m['miou'] * 100:.2f}  category mIoU {m['cat_miou'] * 100:.2f}  "
                  f"pixel acc {m['pixel_acc'] * 100:.2f}"
                  + (f"  (val, seen in training: {m['val_seen_miou'] * 100:.2f})"
                     if seen_val_dl is not None else "")
                  + (f"  (raw weights: {m['raw_miou'] * 100:.2f})" if ema is not None else ""), flush=True)
            if m["miou"] > best["miou"]:
                best = m
                ckpt = {"model": sel.state_dict(), "variant": a.variant, "epoch": epoch + 1,
                        "iter": it, "metrics": m, "args": {k: v for k, v in vars(a).items()}}
                torch.save(ckpt, os.path.join(a.out, "best.pt"))
        # Every epoch: enough to resume an interrupted (e.g. CPU, multi-session) run exactly.
        state = {"model": model.state_dict(), "opt": opt.state_dict(), "variant": a.variant,
                 "epoch": epoch + 1, "iter": it, "history": history, "best": best,
                 "args": {k: v for k, v in vars(a).items()}}
        if ema is not None:
            state.update(ema=ema.model.state_dict(), ema_updates=ema.updates)
        if aux is not None:
            state.update(aux=aux.state_dict())
        torch.save(state, os.path.join(a.out, "last.pt.tmp"))
        os.replace(os.path.join(a.out, "last.pt.tmp"), os.path.join(a.out, "last.pt"))
        summary = {
            "variant": a.variant, "params": nparams, "device": str(device), "threads": a.threads,
            "args": vars(a), "iters": it, "iters_per_epoch": iters_per_epoch,
            "mean_s_per_iter": float(np.mean(iter_times[1:] if len(iter_times) > 1 else iter_times)),
            "mean_data_s_per_iter": float(np.mean(data_times[1:] if len(data_times) > 1 else data_times)),
            "elapsed_s": time.time() - t_start, "history": history, "best": best,
            "scheduled_iters": total, "time_budget_fit": fitted,
        }
        with open(os.path.join(a.out, "metrics.json"), "w") as f:
            json.dump(summary, f, indent=1, default=str)
        if done:
            break
    print(f"best val mIoU {best['miou'] * 100:.2f} (category {best.get('cat_miou', float('nan')) * 100:.2f}) "
          f"in {time.time() - t_start:.0f}s; {a.out}/metrics.json", flush=True)
    return summary


if __name__ == "__main__":
    main()
