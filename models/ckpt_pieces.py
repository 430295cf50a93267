#!/usr/bin/env python3
"""Split a checkpoint into half-precision pieces small enough to come back from a lent machine
(its file limit is 16 MB; the 13.7 M-parameter resunet teacher is 55 MB in float32), and join them.

  python3 models/ckpt_pieces.py split runs/t_all/best.pt OUT/t_all   # OUT/t_all.part0.pt, .part1.pt, ...
  python3 models/ckpt_pieces.py join OUT/t_all.part*.pt --out t_all.pt

Floating weight tensors (2-D and more: the convolutions, nearly all the bytes) are stored in float16
(relative rounding at most 2^-11 above 6e-5 in magnitude, an absolute error under 6e-8 below) and
joined back as float32; vectors (BatchNorm statistics and affine terms, biases) stay float32, exact;
integer tensors and the checkpoint's other entries (variant, epoch, metrics, args) are kept as
they are. Only the weights travel: an optimiser state does not (a joined checkpoint starts or
distils, it does not --resume).
"""

from __future__ import annotations

import argparse
import os
import sys
import uuid

import torch


def fail(msg):
    print(f"ckpt_pieces.py: {msg}", file=sys.stderr)
    raise SystemExit(2)


def split(path, prefix, max_mb):
    try:
        ck = torch.load(path, map_location="cpu")
    except Exception as e:  # noqa: BLE001 - any unreadable file is the same error to the user
        fail(f"{path}: not a readable checkpoint ({e})")
    if not isinstance(ck, dict) or "model" not in ck:
        fail(f"{path}: no 'model' state in the checkpoint")
    limit = int(max_mb * 1e6) - 100_000  # room for pickling overhead and the metadata
    meta = {k: v for k, v in ck.items() if k not in ("model", "opt", "ema")}
    pieces, cur, size = [], {}, 0
    for k, v in ck["model"].items():
        t = v.half() if v.dtype.is_floating_point and v.ndim >= 2 else v
        n = t.numel() * t.element_size()
        if n > limit:
            fail(f"{path}: tensor {k} alone is {n / 1e6:.1f} MB, over the {max_mb} MB limit")
        if cur and size + n > limit:
            pieces.append(cur)
            cur, size = {}, 0
        cur[k], size = t, size + n
    pieces.append(cur)
    os.makedirs(os.path.dirname(prefix) or ".", exist_ok=True)
    split_id = uuid.uuid4().hex  # pieces of different splits must not be joined
    names = []
    for i, part in enumerate(pieces):
        name = f"{prefix}.part{i}.pt"
        torch.save({"part": i, "parts": len(pieces), "split_id": split_id, "model": part, "meta": meta if i == 0 else None}, name)
        names.append(name)
    print(f"{path}: {len(ck['model'])} tensors in {len(pieces)} pieces: {' '.join(names)}")


def join(paths, out):
    parts = {}
    for p in paths:
        try:
            d = torch.load(p, map_location="cpu")
        except Exception as e:  # noqa: BLE001
            fail(f"{p}: not a readable piece ({e})")
        if not isinstance(d, dict) or "part" not in d:
            fail(f"{p}: not a piece written by ckpt_pieces.py split")
        if d["part"] in parts:
            fail(f"{p}: piece {d['part']} given twice")
        first = next(iter(parts.values()), d)
        if (d.get("split_id"), d["parts"]) != (first.get("split_id"), first["parts"]):
            fail(f"{p}: a piece of another split than {paths[0]}")
        parts[d["part"]] = d
    n = next(iter(parts.values()))["parts"]
    missing = sorted(set(range(n)) - set(parts))
    if missing:
        fail(f"pieces {missing} of {n} are missing")
    ck = dict(parts[0]["meta"] or {})
    ck["model"] = {}
    for i in range(n):
        for k, v in parts[i]["model"].items():
            ck["model"][k] = v.float() if v.dtype == torch.float16 else v
    torch.save(ck, out)
    print(f"{out}: {len(ck['model'])} tensors from {n} pieces (variant {ck.get('variant')})")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("split")
    s.add_argument("checkpoint")
    s.add_argument("prefix")
    s.add_argument("--max-mb", type=float, default=15.0)
    j = sub.add_parser("join")
    j.add_argument("pieces", nargs="+")
    j.add_argument("--out", required=True)
    a = p.parse_args(argv)
    if a.cmd == "split":
        split(a.checkpoint, a.prefix, a.max_mb)
    else:
        join(a.pieces, a.out)


if __name__ == "__main__":
    main()
