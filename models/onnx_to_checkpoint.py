#!/usr/bin/env python3
"""Rebuild a train.py checkpoint from a BN-folded ONNX export (export.py's output).

The deployed network's training checkpoint is not committed (models/.gitignore: *.pt); its
artefacts are. To export it at another input size, or quantise it again, rebuild the checkpoint
from the committed ONNX:

  python3 models/onnx_to_checkpoint.py models/artefacts/fastscnn_r2_192x640.onnx --variant res2net \
      --out /tmp/deployed.pt
  bash models/make_artefacts.sh /tmp/deployed.pt res2net

Exact, not approximate: every folded conv's weight goes back into its conv, and the BatchNorm
after it becomes the identity carrying the folded bias (weight 1, mean 0, variance 1 - eps, bias
= the folded bias), so export.py's folding gives back the same weights. The ONNX Conv nodes are
paired with the model's convs in the order the model runs them, shapes checked, and the rebuilt
model is compared with onnxruntime (export.py's check) at the ONNX's own size before anything is
written (a wrong --variant or a graph export.py did not write fails there, by name).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np
import torch
from torch import nn

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from export import check_against_ort  # noqa: E402
from semloc_models import FASTSCNN_VARIANTS, build  # noqa: E402
from semloc_models.fastscnn import ConvBN  # noqa: E402


class RebuildError(Exception):
    pass


def conv_run_order(model, h, w):
    """The model's Conv2d modules in the order a forward pass calls them."""
    order = []
    hooks = [m.register_forward_hook(lambda m, i, o: order.append(m))
             for m in model.modules() if isinstance(m, nn.Conv2d)]
    try:
        with torch.no_grad():
            model(torch.zeros(1, 1, h, w))
    finally:
        for hk in hooks:
            hk.remove()
    return order


def rebuild(onnx_path, variant):
    """Returns the model with the ONNX's weights and the ONNX's input size (h, w)."""
    import onnx
    from onnx import numpy_helper

    try:
        proto = onnx.load(onnx_path)
    except Exception as e:  # noqa: BLE001 - onnx raises several types for a bad file
        raise RebuildError(f"{onnx_path}: not a readable ONNX model ({e})") from e
    inp = proto.graph.input[0]
    dims = [d.dim_value for d in inp.type.tensor_type.shape.dim]
    if inp.name != "luma" or len(dims) != 4 or dims[:2] != [1, 1] or min(dims) <= 0:
        raise RebuildError(f"{onnx_path}: input '{inp.name}' {dims}, expected export.py's static "
                           "1x1xHxW 'luma' input")
    h, w = dims[2], dims[3]
    init = {i.name: numpy_helper.to_array(i) for i in proto.graph.initializer}
    nodes = [n for n in proto.graph.node if n.op_type == "Conv"]
    model = build(variant).eval()
    convs = conv_run_order(model, h, w)
    if len(convs) != len(nodes):
        raise RebuildError(f"{onnx_path}: {len(nodes)} Conv nodes, but the {variant} model has "
                           f"{len(convs)} convs (wrong --variant?)")
    bn_of = {id(m[0]): m[1] for m in model.modules()
             if isinstance(m, ConvBN) and isinstance(m[1], nn.BatchNorm2d)}
    with torch.no_grad():
        for k, (conv, node) in enumerate(zip(convs, nodes)):
            if len(node.input) < 3 or node.input[1] not in init or node.input[2] not in init:
                raise RebuildError(f"{onnx_path}: Conv node {k} ({node.name}) has no constant "
                                   "weight and bias (not a BN-folded export.py graph)")
            wt = torch.from_numpy(np.array(init[node.input[1]], dtype=np.float32))
            b = torch.from_numpy(np.array(init[node.input[2]], dtype=np.float32))
            if tuple(wt.shape) != tuple(conv.weight.shape):
                raise RebuildError(f"{onnx_path}: Conv node {k} ({node.name}) weight "
                                   f"{tuple(wt.shape)}, the {variant} model's conv "
                                   f"{tuple(conv.weight.shape)} (wrong --variant?)")
            conv.weight.copy_(wt)
            bn = bn_of.get(id(conv))
            if bn is not None:
                bn.weight.fill_(1.0)
                bn.running_mean.zero_()
                bn.running_var.fill_(1.0 - bn.eps)
                bn.bias.copy_(b)
            elif conv.bias is not None:
                conv.bias.copy_(b)
            else:
                raise RebuildError(f"{onnx_path}: conv {k} has neither a BatchNorm nor a bias")
    return model, (h, w)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("onnx", help="a BN-folded export.py ONNX (e.g. models/artefacts/fastscnn_r2_192x640.onnx)")
    p.add_argument("--variant", required=True, choices=FASTSCNN_VARIANTS)
    p.add_argument("--out", required=True, help="checkpoint to write (train.py's format)")
    p.add_argument("--tol", type=float, default=1e-4, help="largest |logit difference| accepted")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    try:
        model, (h, w) = rebuild(a.onnx, a.variant)
    except RebuildError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    chk = check_against_ort(a.onnx, model, (h, w))
    if chk is None:
        print("error: onnxruntime is needed to check the rebuilt model", file=sys.stderr)
        return 2
    diff, agree = chk["max_abs_diff"], chk["argmax_agreement"]
    print(f"{a.onnx}: {a.variant} at {h}x{w}, rebuilt model vs onnxruntime: max|diff| {diff:.2e}, "
          f"argmax agreement {agree:.4f}")
    if not diff <= a.tol or agree < 1.0:
        print(f"error: {a.onnx}: the rebuilt model does not reproduce the ONNX (max|diff| {diff:.2e} "
              f"> {a.tol:g} or argmax agreement {agree:.4f} < 1)", file=sys.stderr)
        return 2
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    torch.save({"variant": a.variant, "model": model.state_dict(),
                "rebuilt_from": os.path.basename(a.onnx)}, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
