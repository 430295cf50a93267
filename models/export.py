#!/usr/bin/env python3
"""Export a trained checkpoint to ONNX with BatchNorm folded, at a static input size.

  python3 models/export.py --checkpoint models/runs/r2/best.pt --size 384x1248 --out models/artefacts/fastscnn_r2_384x1248.onnx

Input 'luma': 1 x 1 x H x W float, u8 luma / 255. Output 'logits': 1 x 11 x H x W
(or H/8 x W/8 with --no-final-upsample). Ops: Conv, Relu, Add, AveragePool, Resize, Concat
(see --help output of the op list printed at the end). Uses the TorchScript exporter
(dynamo=False) so the PPM pooling's custom symbolic applies.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import time
import warnings

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from semloc_models import FASTSCNN_VARIANTS, build, count_params_folded, fold_bn  # noqa: E402

ALLOWED_OPS = {"Conv", "Relu", "Add", "AveragePool", "ReduceMean", "Resize", "Concat"}


def parse_hw(s):
    h, w = s.lower().split("x")
    return int(h), int(w)


def load_model(checkpoint=None, variant=None, final_upsample=True):
    if checkpoint:
        ck = torch.load(checkpoint, map_location="cpu")
        variant = ck["variant"]
        if variant not in FASTSCNN_VARIANTS:
            raise SystemExit(f"{checkpoint}: a {variant} checkpoint (training only, no int8 ops for it); "
                             f"only the Fast-SCNN variants ({', '.join(FASTSCNN_VARIANTS)}) export")
        model = build(variant, final_upsample=final_upsample)
        model.load_state_dict(ck["model"])
    else:
        model = build(variant or "res2net", final_upsample=final_upsample)
    model.eval()
    return model, variant


def export_onnx(model, size, path, opset=17):
    """Fold BN (in place, on a copy) and write ONNX. Returns the folded model."""
    import copy

    import onnx

    m = fold_bn(copy.deepcopy(model)).eval()
    x = torch.rand(1, 1, *size)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(m, (x,), path, input_names=["luma"], output_names=["logits"],
                          opset_version=opset, do_constant_folding=True, dynamo=False)
    model_proto = static_resize_sizes(onnx.load(path))
    onnx.checker.check_model(model_proto, full_check=True)
    onnx.save(model_proto, path)
    return m, model_proto


def static_resize_sizes(model_proto):
    """Give every Resize a constant 'sizes' initializer and drop the Shape/Slice/Concat chains the
    exporter builds for it, and remove Identity nodes, so the graph holds only compute ops (the
    input size is static anyway)."""
    import onnx
    from onnx import numpy_helper, shape_inference

    inferred = shape_inference.infer_shapes(model_proto, data_prop=True)
    shapes = {}
    for vi in list(inferred.graph.value_info) + list(inferred.graph.output):
        dims = [d.dim_value if d.HasField("dim_value") else None for d in vi.type.tensor_type.shape.dim]
        shapes[vi.name] = dims
    g = model_proto.graph
    # Identity nodes (the exporter adds them when parameters are equal, e.g. untrained zero
    # biases): rewire their consumers to the source tensor
    outputs = {o.name for o in g.output}
    for n in [n for n in g.node if n.op_type == "Identity" and n.output[0] not in outputs]:
        src, dst = n.input[0], n.output[0]
        for m in g.node:
            for k, i in enumerate(m.input):
                if i == dst:
                    m.input[k] = src
        g.node.remove(n)
    for n in g.node:
        if n.op_type != "Resize":
            continue
        dims = shapes.get(n.output[0])
        if not dims or any(d is None for d in dims):
            raise RuntimeError(f"cannot infer the static output shape of Resize {n.name}")
        name = n.name.strip("/").replace("/", "_") + "_sizes"
        g.initializer.append(numpy_helper.from_array(np.array(dims, np.int64), name))
        x = n.input[0]
        del n.input[:]
        n.input.extend([x, "", "", name])
    # dead-code elimination
    while True:
        used = {i for n in g.node for i in n.input} | {o.name for o in g.output}
        dead = [n for n in g.node if not any(o in used for o in n.output)]
        if not dead:
            break
        for n in dead:
            g.node.remove(n)
    used = {i for n in g.node for i in n.input}
    for init in [i for i in g.initializer if i.name not in used]:
        g.initializer.remove(init)
    del g.value_info[:]
    return shape_inference.infer_shapes(model_proto)



def op_summary(model_proto):
    ops = collections.Counter(n.op_type for n in model_proto.graph.node)
    resize_modes = collections.Counter()
    pool_attrs = []
    for n in model_proto.graph.node:
        at = {a.name: a for a in n.attribute}
        if n.op_type == "Resize":
            import onnx
            resize_modes[(onnx.helper.get_attribute_value(at["mode"]).decode(),
                          onnx.helper.get_attribute_value(at["coordinate_transformation_mode"]).decode())] += 1
        if n.op_type == "AveragePool":
            import onnx
            pool_attrs.append({k: onnx.helper.get_attribute_value(v) for k, v in at.items()})
    return ops, resize_modes, pool_attrs


def check_against_ort(path, folded, size, image=None):
    try:
        import onnxruntime as ort
    except ImportError:
        print("onnxruntime not installed: torch-vs-onnx check skipped")
        return None
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    sess = ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])
    x = torch.rand(1, 1, *size) if image is None else image
    with torch.no_grad():
        ref = folded(x).numpy()
    out = sess.run(None, {"luma": x.numpy()})[0]
    diff = float(np.abs(out - ref).max())
    agree = float((out.argmax(1) == ref.argmax(1)).mean())
    t0 = time.time()
    for _ in range(3):
        sess.run(None, {"luma": x.numpy()})
    ms = (time.time() - t0) / 3 * 1000
    return {"max_abs_diff": diff, "argmax_agreement": agree, "ort_ms_1thread": ms}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default="", help="train.py checkpoint (omit: random weights, for tests)")
    p.add_argument("--variant", choices=FASTSCNN_VARIANTS, default="res2net",
                   help="only used without --checkpoint")
    p.add_argument("--size", type=parse_hw, default=(384, 1248), help="HxW static input size")
    p.add_argument("--opset", type=int, default=17)
    p.add_argument("--no-final-upsample", action="store_true", help="output logits at H/8 x W/8")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    model, variant = load_model(a.checkpoint, a.variant, final_upsample=not a.no_final_upsample)
    folded, proto = export_onnx(model, a.size, a.out, a.opset)
    ops, modes, pools = op_summary(proto)
    print(f"{a.out}: variant={variant} size={a.size[0]}x{a.size[1]} opset={a.opset} "
          f"params(folded)={count_params_folded(folded):,} bytes={os.path.getsize(a.out):,}")
    print("ops:", dict(sorted(ops.items())))
    print("resize (mode, coordinate_transformation_mode):", dict(modes))
    for pa in pools:
        print("AveragePool", pa)
    extra = set(ops) - ALLOWED_OPS
    if extra:
        print("WARNING: ops outside the int8 engine's set:", sorted(extra))
    chk = check_against_ort(a.out, folded, a.size)
    if chk:
        print("onnxruntime vs torch (BN folded): max|diff| {max_abs_diff:.2e}, argmax agreement "
              "{argmax_agreement:.4f}, ORT {ort_ms_1thread:.1f} ms/frame (1 thread)".format(**chk))
    info = {"onnx": os.path.basename(a.out), "variant": variant, "input": [1, 1, *a.size],
            "input_scale": "luma u8 / 255", "final_upsample": not a.no_final_upsample,
            "opset": a.opset, "ops": dict(ops), "resize": {f"{k[0]}/{k[1]}": v for k, v in modes.items()},
            "check": chk, "checkpoint": os.path.basename(a.checkpoint) if a.checkpoint else None}
    with open(os.path.splitext(a.out)[0] + ".export.json", "w") as f:
        json.dump(info, f, indent=1)
    return info


if __name__ == "__main__":
    main()
