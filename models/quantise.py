#!/usr/bin/env python3
"""int8 post-training quantisation of the exported graph + a reference int8 simulation.

  python3 models/quantise.py --checkpoint models/runs/r2/best.pt \
      --onnx models/artefacts/fastscnn_r2_384x1248.onnx --calib 64

1. Exports the checkpoint (BN folded) at --eval-size (CamVid, default 384x480 = 360x480 padded)
   and checks its tensor names are those of --onnx (same graph, other static size).
2. Calibrates per-tensor activation ranges on --calib CamVid *train* images (whole images, padded
   like val; min/max, or the mean over images of a low/high percentile with --method percentile).
3. Writes the parameters as a JSON sidecar `<onnx without .onnx>.quant.json` (no QDQ graph: the Rust
   converter reads the float ONNX + this file). Scheme, also written into the JSON:
   - activations: per-tensor asymmetric int8, scale = (max - min) / 255 with min <= 0 <= max,
     zero_point = round(-128 - min / scale) in [-128, 127]; q = clamp(round(x / s) + zp, -128, 127).
     The graph input 'luma' (u8 / 255) is fixed at scale 1/255, zero_point -128 (q = luma - 128).
   - weights: per-output-channel symmetric int8, scale_c = max|W_c| / 127, zero_point 0.
   - bias: int32, scale = s_input * scale_c, zero_point 0.
   - a Conv or Add whose only consumer is a Relu is fused with it: only the Relu output is
     quantised (the engine applies the ReLU before requantising).
4. Runs the graph (a small torch interpreter over the ONNX nodes: Conv, Relu, Add, Concat,
   AveragePool, Resize) on CamVid val in f32 and in simulated int8 (fake-quant of every
   materialised tensor, quantised weights and biases) and reports mIoU f32 -> int8.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import camvid  # noqa: E402
import export  # noqa: E402
from semloc_models import FASTSCNN_VARIANTS, NUM_CLASSES  # noqa: E402

INPUT_SCALE, INPUT_ZP = 1.0 / 255.0, -128


# ---------------------------------------------------------------------------------------------
# graph interpreter
# ---------------------------------------------------------------------------------------------


class Graph:
    def __init__(self, proto):
        from onnx import helper, numpy_helper

        self.proto = proto
        self.init = {i.name: torch.from_numpy(numpy_helper.to_array(i).copy()) for i in proto.graph.initializer}
        self.nodes = []
        for n in proto.graph.node:
            attrs = {a.name: helper.get_attribute_value(a) for a in n.attribute}
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in attrs.items()}
            self.nodes.append((n.op_type, n.name, list(n.input), list(n.output), attrs))
        self.input = proto.graph.input[0].name
        self.output = proto.graph.output[0].name
        consumers = {}
        for op, _, ins, _, _ in self.nodes:
            for i in ins:
                consumers.setdefault(i, []).append(op)
        self.consumers = consumers
        # tensors the int8 engine materialises (quantised): every node output except a Conv/Add
        # output whose only consumer is a Relu (fused)
        self.quant_tensors = []
        self.fused = []
        for op, name, ins, outs, _ in self.nodes:
            o = outs[0]
            if op in ("Conv", "Add") and consumers.get(o) == ["Relu"]:
                self.fused.append(o)
            else:
                self.quant_tensors.append(o)

    def activation_names(self):
        return [outs[0] for _, _, _, outs, _ in self.nodes]

    def run(self, x, qparams=None, wq=None, observe=None):
        """x: N x 1 x H x W float. qparams: {tensor: (scale, zp)} -> fake-quant; wq: quantised
        conv weights {node: (w, b)}; observe(name, tensor) is called on every node output."""
        env = {self.input: x}
        if qparams is not None:
            env[self.input] = fake_quant(x, INPUT_SCALE, INPUT_ZP)
        for op, name, ins, outs, at in self.nodes:
            a = [env[i] if i in env else self.init.get(i) for i in ins]
            if op == "Conv":
                if wq is not None:
                    w, b = wq[name]
                else:
                    w, b = a[1], (a[2] if len(a) > 2 else None)
                pads = at.get("pads", [0, 0, 0, 0])
                assert pads[0] == pads[2] and pads[1] == pads[3], "asymmetric conv pads"
                y = F.conv2d(a[0], w, b, stride=at.get("strides", [1, 1]), padding=(pads[0], pads[1]),
                             dilation=at.get("dilations", [1, 1]), groups=at.get("group", 1))
            elif op == "Relu":
                y = F.relu(a[0])
            elif op == "Add":
                y = a[0] + a[1]
            elif op == "Concat":
                y = torch.cat(a, dim=at["axis"])
            elif op == "AveragePool":
                y = avgpool(a[0], at)
            elif op == "Resize":
                assert at.get("mode") == "linear" and at.get("coordinate_transformation_mode") in (
                    "half_pixel", "pytorch_half_pixel"), at
                size = [int(v) for v in a[3].tolist()[2:]]
                y = F.interpolate(a[0], size=size, mode="bilinear", align_corners=False)
            else:
                raise NotImplementedError(op)
            o = outs[0]
            if observe is not None:
                observe(o, y)
            if qparams is not None and o in qparams:
                s, zp = qparams[o]
                y = fake_quant(y, s, zp)
            env[o] = y
        return env[self.output]


def avgpool(x, at):
    kh, kw = at["kernel_shape"]
    sh, sw = at.get("strides", [kh, kw])
    t, l, b, r = at.get("pads", [0, 0, 0, 0])
    assert at.get("count_include_pad", 0) == 0 and (sh, sw) == (kh, kw)
    xp = F.pad(x, (l, r, t, b))
    s = F.avg_pool2d(xp, (kh, kw), (sh, sw)) * (kh * kw)
    ones = F.pad(torch.ones(1, 1, x.shape[2], x.shape[3]), (l, r, t, b))
    cnt = F.avg_pool2d(ones, (kh, kw), (sh, sw)) * (kh * kw)
    return s / cnt


def fake_quant(x, scale, zp):
    q = torch.clamp(torch.round(x / scale) + zp, -128, 127)
    return (q - zp) * scale


def act_qparams(lo, hi):
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    if hi - lo < 1e-8:
        hi = lo + 1e-8
    scale = (hi - lo) / 255.0
    zp = int(np.clip(round(-128 - lo / scale), -128, 127))
    return scale, zp


def quantise_weights(graph, qparams):
    """Per-output-channel symmetric int8 weights and int32 biases (returned dequantised for the sim)."""
    wq, meta = {}, {}
    producer_scale = dict(qparams)
    producer_scale[graph.input] = (INPUT_SCALE, INPUT_ZP)
    for op, name, ins, outs, at in graph.nodes:
        if op != "Conv":
            continue
        w = graph.init[ins[1]]
        b = graph.init[ins[2]] if len(ins) > 2 else torch.zeros(w.shape[0])
        amax = w.abs().reshape(w.shape[0], -1).amax(1).clamp(min=1e-12)
        sw = amax / 127.0
        qw = torch.clamp(torch.round(w / sw.reshape(-1, 1, 1, 1)), -127, 127)
        s_in = producer_scale[ins[0]][0]
        sb = s_in * sw
        qb = torch.round(b / sb).clamp(-(2 ** 31), 2 ** 31 - 1)
        wq[name] = (qw * sw.reshape(-1, 1, 1, 1), qb * sb)
        meta[name] = {"input": ins[0], "weight": ins[1], "bias": ins[2] if len(ins) > 2 else None,
                      "output": outs[0], "weight_scales": [float(v) for v in sw],
                      "bias_scales": [float(v) for v in sb]}
    return wq, meta


# ---------------------------------------------------------------------------------------------


def padded_images(split, n, limit_offset=None, holdout=""):
    items = (camvid.list_sequences(camvid.DEFAULT_ROOT, ["train", "val"], exclude={holdout})
             if holdout else None)
    ds = camvid.CamVid(split, augment=False, items=items)
    idx = list(range(len(ds)))
    if n and n < len(idx):  # evenly spread over the split (sequences differ along it)
        idx = [idx[int(i * len(idx) / n)] for i in range(n)]
    return ds, idx


@torch.no_grad()
def calibrate(graph, n, method="minmax", pct=99.99, holdout=""):
    ds, idx = padded_images("train", n, holdout=holdout)
    stats = {}

    def obs(name, y):
        if method == "minmax":
            lo, hi = float(y.min()), float(y.max())
        else:
            v = y.reshape(-1)
            if v.numel() > 1_000_000:
                v = v[torch.randperm(v.numel(), generator=torch.Generator().manual_seed(0))[:1_000_000]]
            lo = float(torch.quantile(v, 1 - pct / 100))
            hi = float(torch.quantile(v, pct / 100))
        st = stats.setdefault(name, [])
        st.append((lo, hi))

    for i in idx:
        x, _ = ds[i]
        graph.run(x[None], observe=obs)
    ranges = {}
    for k, v in stats.items():
        lo = np.array([a for a, _ in v])
        hi = np.array([b for _, b in v])
        ranges[k] = (float(lo.min()), float(hi.max())) if method == "minmax" else (float(lo.mean()), float(hi.mean()))
    return ranges, [ds.items[i][0] for i in idx]


@torch.no_grad()
def eval_val(graph, qparams=None, wq=None, limit=0, holdout=""):
    items = (camvid.list_sequences(camvid.DEFAULT_ROOT, ["train", "val"], include={holdout})
             if holdout else None)
    ds = camvid.CamVid("val", augment=False, limit=limit or None, items=items)
    cm = torch.zeros(NUM_CLASSES, NUM_CLASSES, dtype=torch.int64)
    for i in range(len(ds)):
        x, y = ds[i]
        out = graph.run(x[None], qparams, wq)
        cm += camvid.confusion(out.argmax(1)[0], y)
    return camvid.metrics(cm)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default="", help="train.py checkpoint (omit: random weights, for tests)")
    p.add_argument("--variant", choices=FASTSCNN_VARIANTS, default="res2net")
    p.add_argument("--onnx", required=True, help="deployed ONNX (from export.py); the JSON goes beside it")
    p.add_argument("--calib", type=int, default=64, help="number of CamVid train images to calibrate on")
    p.add_argument("--method", choices=["minmax", "percentile"], default="minmax")
    p.add_argument("--percentile", type=float, default=99.99)
    p.add_argument("--eval-size", type=export.parse_hw, default=(384, 480))
    p.add_argument("--limit-val", type=int, default=0, help="evaluate on the first N val images only")
    p.add_argument("--no-eval", action="store_true")
    p.add_argument("--holdout-seq", default="",
                   help="the checkpoint's held-out CamVid sequence (train.py --holdout-seq): "
                   "calibrate without it and evaluate on it instead of val")
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    import onnx

    t0 = time.time()
    model, variant = export.load_model(a.checkpoint, a.variant,
                                       final_upsample=not _no_final_upsample(a.onnx))
    with tempfile.TemporaryDirectory() as td:
        ep = os.path.join(td, "eval.onnx")
        export.export_onnx(model, a.eval_size, ep)
        g = Graph(onnx.load(ep))
    deploy = Graph(onnx.load(a.onnx))
    if deploy.activation_names() != g.activation_names():
        raise SystemExit("the eval-size graph and --onnx differ in structure/tensor names: "
                         "export --onnx from the same checkpoint/variant")
    ranges, calib_files = calibrate(g, a.calib, a.method, a.percentile, a.holdout_seq)
    qparams = {t: act_qparams(*ranges[t]) for t in g.quant_tensors}
    wq, wmeta = quantise_weights(g, qparams)
    side = {
        "onnx": os.path.basename(a.onnx),
        "variant": variant,
        "scheme": {
            "activations": "per-tensor asymmetric int8: q = clamp(round(x/scale) + zero_point, -128, 127)",
            "weights": "per-output-channel symmetric int8 (zero_point 0), scale_c = max|W_c|/127, q in [-127, 127]",
            "bias": "int32, scale = input_scale * weight_scale_c",
            "fused_relu": "Conv/Add outputs listed in 'fused' feed only a Relu; only the Relu output is quantised",
            "calibration": f"{a.method}" + (f" p={a.percentile}" if a.method == "percentile" else "")
                           + f" over {len(calib_files)} CamVid train images (whole, padded to {a.eval_size[0]}x{a.eval_size[1]})",
        },
        "input": {"name": deploy.input, "scale": INPUT_SCALE, "zero_point": INPUT_ZP,
                  "note": "q = luma_u8 - 128"},
        "activations": {t: {"min": ranges[t][0], "max": ranges[t][1], "scale": qparams[t][0],
                            "zero_point": qparams[t][1]} for t in g.quant_tensors},
        "fused": g.fused,
        "convs": wmeta,
        "calibration_images": [os.path.basename(f) for f in calib_files],
    }
    out_json = os.path.splitext(a.onnx)[0] + ".quant.json"
    print(f"calibrated {len(calib_files)} images, {len(qparams)} activation tensors, "
          f"{len(wmeta)} convs in {time.time() - t0:.0f}s")
    if not a.no_eval:
        t1 = time.time()
        m32 = eval_val(g, limit=a.limit_val, holdout=a.holdout_seq)
        m8 = eval_val(g, qparams, wq, limit=a.limit_val, holdout=a.holdout_seq)
        side["eval"] = {
            "split": f"held-out sequence {a.holdout_seq}" if a.holdout_seq else "val",
            "images": a.limit_val or 101, "size": list(a.eval_size),
            "int8_dyn_precision": m8["dyn_precision"], "int8_dyn_recall": m8["dyn_recall"],
            "f32": {"miou": m32["miou"], "cat_miou": m32["cat_miou"], "iou": m32["iou"]},
            "int8_sim": {"miou": m8["miou"], "cat_miou": m8["cat_miou"], "iou": m8["iou"]},
            "miou_drop": m32["miou"] - m8["miou"], "cat_miou_drop": m32["cat_miou"] - m8["cat_miou"],
        }
        print(f"{side['eval']['split']} mIoU f32 {m32['miou'] * 100:.2f} -> int8 {m8['miou'] * 100:.2f} "
              f"(drop {(m32['miou'] - m8['miou']) * 100:.2f}); category mIoU f32 {m32['cat_miou'] * 100:.2f} "
              f"-> int8 {m8['cat_miou'] * 100:.2f}  [{time.time() - t1:.0f}s]")
    with open(out_json, "w") as f:
        json.dump(side, f, indent=1)
    print("wrote", out_json)
    return side


def _no_final_upsample(onnx_path):
    import onnx

    m = onnx.load(onnx_path, load_external_data=False)
    dims = [d.dim_value for d in m.graph.output[0].type.tensor_type.shape.dim]
    idims = [d.dim_value for d in m.graph.input[0].type.tensor_type.shape.dim]
    return dims[2] != idims[2]


if __name__ == "__main__":
    main()
