#!/usr/bin/env python3
"""Compares two networks on one clip, each run under several int8 calibration draws.

  python3 models/draws_compare.py --ref ref64 ref65 ref66 --cand cand64 cand65 cand66 \
      [--base base [--base-row off/hard]] [--rows full/em,motion/em] [--json out.json]

Every argument is a `semloc ablate --out` folder (or its ablation.json), all of one dataset and
from the same starts (`--first-frames`). A network's int8 blob depends on which calibration images
`quantise.py` saw: on the 51-frame KITTI clips, four draws of the committed float weights (64 to 67
images) move 06's motion + EM from 0.72 to 0.93 of the backbone's ATE (models/README.md,
"Calibration draws"). One draw per network therefore judges its calibration as much as its
weights. This script averages them out: per start, the mean over a network's draws of ln ATE,
then, as `semloc compare` does, the geometric mean over starts of cand / ref with the standard error
of the mean log ratio, the worst start and the starts where cand is better. With --base (the
backbone's run; its row off/hard, or --base-row, e.g. off/em for EM without semantics), it also
gives each network against the backbone, every draw's own geometric mean beside it, and the
spread of those draws (the standard deviation of their log geometric means), which is what one
draw of that network is worth on this clip.

With one draw per side its figures are `semloc compare`'s (same formulas; the smoke test checks
known answers on made-up results).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


class DrawsError(Exception):
    pass


def load(path):
    f = os.path.join(path, "ablation.json") if os.path.isdir(path) else path
    try:
        with open(f) as fh:
            d = json.load(fh)
    except FileNotFoundError:
        raise DrawsError(f"{f}: no such file (a `semloc ablate --out` folder or its ablation.json)")
    except json.JSONDecodeError as e:
        raise DrawsError(f"{f}: not JSON ({e})")
    try:
        rows = {f"{r['semantics']}/{r['association']}": [float(v) for v in r["ate_rmse_m"]]
                for r in d["over_first_frames"]}
        starts = list(d["first_frames"])
        name = d["dataset"]["name"]
    except (KeyError, TypeError) as e:
        raise DrawsError(f"{f}: not a `semloc ablate` result run from several starts (missing {e})")
    for k, v in rows.items():
        if len(v) != len(starts):
            raise DrawsError(f"{f}: row {k} has {len(v)} ATEs for {len(starts)} starts")
        if any(not (x > 0 and math.isfinite(x)) for x in v):
            raise DrawsError(f"{f}: row {k} has an ATE that is not a positive number")
    return {"file": f, "dataset": name, "starts": starts, "rows": rows}


def check_same(runs):
    a = runs[0]
    for r in runs[1:]:
        if r["dataset"] != a["dataset"]:
            raise DrawsError(f"{r['file']}: dataset {r['dataset']}, but {a['file']} is {a['dataset']}")
        if r["starts"] != a["starts"]:
            raise DrawsError(f"{r['file']}: starts {r['starts']}, but {a['file']} has {a['starts']}")


def mean_log(runs, row):
    """Per start, the mean over the draws of ln ATE."""
    for r in runs:
        if row not in r["rows"]:
            raise DrawsError(f"{r['file']}: no row {row} (it has {', '.join(sorted(r['rows']))})")
    n = len(runs[0]["starts"])
    return [sum(math.log(r["rows"][row][i]) for r in runs) / len(runs) for i in range(n)]


def paired(ref_logs, var_logs):
    d = [v - r for r, v in zip(ref_logs, var_logs)]
    n = len(d)
    m = sum(d) / n
    se = math.sqrt(sum((x - m) ** 2 for x in d) / (n - 1) / n) if n > 1 else 0.0
    return {"ate_ratio_geomean": math.exp(m), "ate_ratio_log_se": se, "ate_ratio_worst": math.exp(max(d)),
            "better": sum(1 for x in d if x < 0), "starts": n}


def spread(logs):
    """Standard deviation of a list of log geometric means (n - 1), 0 for one."""
    if len(logs) < 2:
        return 0.0
    m = sum(logs) / len(logs)
    return math.sqrt(sum((x - m) ** 2 for x in logs) / (len(logs) - 1))


def compare(ref_paths, cand_paths, base_path=None, rows=("full/em", "motion/em"), base_row="off/hard"):
    ref = [load(p) for p in ref_paths]
    cand = [load(p) for p in cand_paths]
    base = load(base_path) if base_path else None
    check_same(ref + cand + ([base] if base else []))
    out = {"dataset": ref[0]["dataset"], "starts": ref[0]["starts"],
           "ref": [r["file"] for r in ref], "cand": [r["file"] for r in cand],
           "base": base["file"] if base else None, "base_row": base_row if base else None, "rows": []}
    bl = mean_log([base], base_row) if base else None
    for row in rows:
        rl, cl = mean_log(ref, row), mean_log(cand, row)
        e = {"row": row, "cand_vs_ref": paired(rl, cl)}
        if base:
            for side, runs, logs in (("ref", ref, rl), ("cand", cand, cl)):
                per_draw = [paired(bl, mean_log([r], row)) for r in runs]
                e[f"{side}_vs_base"] = paired(bl, logs)
                e[f"{side}_vs_base_per_draw"] = [p["ate_ratio_geomean"] for p in per_draw]
                e[f"{side}_draw_spread_log"] = spread([math.log(p["ate_ratio_geomean"]) for p in per_draw])
        out["rows"].append(e)
    return out


def fmt(p):
    return (f"{p['ate_ratio_geomean']:.3f} ± {p['ate_ratio_log_se']:.3f}  worst {p['ate_ratio_worst']:.2f}  "
            f"{p['better']}/{p['starts']} better")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ref", nargs="+", required=True, help="the reference network's runs, one per draw")
    p.add_argument("--cand", nargs="+", required=True, help="the candidate's runs, one per draw")
    p.add_argument("--base", help="the backbone's run, for the figures against it")
    p.add_argument("--base-row", default="off/hard", help="its row to pair with (default off/hard)")
    p.add_argument("--rows", default="full/em,motion/em", help="rows to compare (default full/em,motion/em)")
    p.add_argument("--json", help="also write the comparison here")
    a = p.parse_args(argv)
    try:
        out = compare(a.ref, a.cand, a.base, [r for r in a.rows.split(",") if r], a.base_row)
    except DrawsError as e:
        print(f"draws_compare: {e}", file=sys.stderr)
        return 1
    print(f"{out['dataset']}: {len(a.cand)} candidate / {len(a.ref)} reference draws, {len(out['starts'])} starts")
    for e in out["rows"]:
        print(f"  {e['row']:<10} cand / ref      {fmt(e['cand_vs_ref'])}")
        if a.base:
            for side in ("ref", "cand"):
                draws = " ".join(f"{v:.3f}" for v in e[f"{side}_vs_base_per_draw"])
                print(f"  {e['row']:<10} {side:<4} / base    {fmt(e[f'{side}_vs_base'])}   draws {draws}, "
                      f"spread {e[f'{side}_draw_spread_log']:.3f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
