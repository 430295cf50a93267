#!/usr/bin/env python3
"""Checks that the firmware library reproduces the host pipeline bit for bit.

Usage: host_pipeline_check.py SEMLOC_BIN REPORT.txt

REPORT.txt is the output of `host_poses` (or the QEMU image). This script writes the
embedded frames (firmware-sim/data) as a KITTI odometry layout with the crop's calibration,
runs `semloc run --threads 1` on it twice (geometric; `--semantics full --assoc em --model
models/artefacts/fastscnn_r2_192x640.slm`), and requires every pose number of the host's
trajectory.txt (written in shortest round-trip form) to equal the report's bit patterns.
Exit 0 only if all 2 x 12 x frames numbers are equal.
"""
import os
import shutil
import struct
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DATA = os.path.join(HERE, "data")
MODEL = os.path.join(ROOT, "models", "artefacts", "fastscnn_r2_192x640.slm")


def manifest():
    kv, frames = {}, []
    with open(os.path.join(DATA, "manifest.txt")) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            key, _, rest = line.partition(" ")
            if key == "frame":
                frames.append(rest.split())
            else:
                kv[key] = rest
    return kv, frames


def layout(tmp):
    kv, frames = manifest()
    seq = os.path.join(tmp, "sequences", "00")
    for d in ("image_0", "image_1"):
        os.makedirs(os.path.join(seq, d))
    os.makedirs(os.path.join(tmp, "poses"))
    for i in range(len(frames)):
        shutil.copy(os.path.join(DATA, f"left_{i:02}.png"), os.path.join(seq, "image_0", f"{i:06}.png"))
        shutil.copy(os.path.join(DATA, f"right_{i:02}.png"), os.path.join(seq, "image_1", f"{i:06}.png"))
    fx, cx, cy, b = (float(kv[k]) for k in ("fx_px", "cx_px", "cy_px", "baseline_m"))

    def p(tx):
        return " ".join("%.12e" % v for v in (fx, 0, cx, -fx * tx, 0, fx, cy, 0, 0, 0, 1, 0))

    with open(os.path.join(seq, "calib.txt"), "w") as f:
        f.write(f"P0: {p(0)}\nP1: {p(b)}\nP2: {p(0)}\nP3: {p(b)}\n")
    with open(os.path.join(seq, "times.txt"), "w") as f:
        f.writelines(fr[1] + "\n" for fr in frames)
    with open(os.path.join(tmp, "poses", "00.txt"), "w") as f:
        f.writelines(" ".join(fr[2:]) + "\n" for fr in frames)


def report_runs(path):
    runs = []
    with open(path) as f:
        for line in f:
            if line.startswith("# semloc firmware-sim"):
                runs.append([])
            elif not line.startswith(("#", "@", "fnv")) and len(line.split()) == 12:
                runs[-1].append([struct.unpack("<d", struct.pack("<Q", int(t, 16)))[0] for t in line.split()])
    return runs


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    semloc, report = sys.argv[1], sys.argv[2]
    runs = report_runs(report)
    if len(runs) != 2:
        raise SystemExit(f"{report}: want 2 runs (geometric, semantic), found {len(runs)}")
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        layout(tmp)
        variants = [("geometric", []),
                    ("semantic", ["--semantics", "full", "--assoc", "em", "--model", MODEL])]
        for (name, extra), run in zip(variants, runs):
            out = os.path.join(tmp, "out-" + name)
            subprocess.run([semloc, "run", tmp, "--seq", "00", "--threads", "1", "--out", out] + extra,
                           check=True, stdout=subprocess.DEVNULL)
            with open(os.path.join(out, "trajectory.txt")) as f:
                traj = [[float(t) for t in line.split()] for line in f if line.strip()]
            pairs = [(a, b) for r, q in zip(run, traj) for a, b in zip(r, q)]
            equal = sum(struct.pack("<d", a) == struct.pack("<d", b) for a, b in pairs)
            total = 12 * len(run)
            good = len(traj) == len(run) and equal == total
            ok &= good
            print(f"{name}: {equal} of {total} pose numbers bit-equal to `semloc run --threads 1`"
                  f" ({'OK' if good else 'DIFFERENT'})")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
