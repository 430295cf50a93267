#!/usr/bin/env python3
"""How well can any odometry score against a KITTI raw drive's position-based ground truth?

usage: oxts_scale_floor.py DRIVE_DIR

DRIVE_DIR  e.g. ../shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0005_sync

The ground truth of a raw drive is built from the OXTS *positions* (lat/lon/alt, Mercator with
the first frame's scale, as pykitti and the KITTI odometry poses do). The same unit also records
its *velocities* (vn, ve, vu). This script integrates the velocities (trapezoid, over the real
timestamps) into a dead-reckoned track and scores it against the positions the way `semloc
eval` scores a tracker (RMSE after Umeyama SE(3), and Sim(3)). Where positions and velocities
disagree in scale, no metric-scale odometry can beat that SE(3) figure by much: it is the
ground truth's own floor. On drive 0005 (91 frames): GPS path 33.49 m, velocity path 34.90 m
(scale 0.957), SE(3) ATE 0.524 m, Sim(3) 0.290 m.

Needs numpy only.
"""
import glob
import math
import os
import sys

import numpy as np


def stamp(s):
    hms = s.strip().split(" ")[1].split(":")
    return int(hms[0]) * 3600 + int(hms[1]) * 60 + float(hms[2])


def ate(gt, est, scale=False):
    mg, me = gt.mean(0), est.mean(0)
    g, e = gt - mg, est - me
    u, s, vt = np.linalg.svd(g.T @ e / len(gt))
    d = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[2, 2] = -1
    r = u @ d @ vt
    c = np.trace(np.diag(s) @ d) / (e**2).sum(1).mean() if scale else 1.0
    aligned = (c * (r @ e.T)).T + mg
    return math.sqrt(((aligned - gt) ** 2).sum(1).mean()), c


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    drive = sys.argv[1]
    files = sorted(glob.glob(os.path.join(drive, "oxts", "data", "*.txt")))
    with open(os.path.join(drive, "oxts", "timestamps.txt")) as f:
        t = np.array([stamp(line) for line in f if line.strip()])
    rec = np.array([[float(v) for v in open(p).read().split()] for p in files])
    if len(rec) != len(t) or len(rec) < 3:
        sys.exit(f"{drive}: {len(rec)} oxts records, {len(t)} timestamps")
    er = 6378137.0
    sc = math.cos(math.radians(rec[0, 0]))
    pos = np.stack([sc * np.radians(rec[:, 1]) * er,
                    sc * er * np.log(np.tan(np.radians(90 + rec[:, 0]) / 2)),
                    rec[:, 2]], 1)
    vel = np.stack([rec[:, 7], rec[:, 6], rec[:, 10]], 1)  # ve, vn, vu: east, north, up
    dr = np.zeros_like(pos)
    dr[0] = pos[0]
    for i in range(len(pos) - 1):
        dr[i + 1] = dr[i] + 0.5 * (vel[i] + vel[i + 1]) * (t[i + 1] - t[i])
    path = lambda p: float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())  # noqa: E731
    se3, _ = ate(pos, dr)
    sim3, s = ate(pos, dr, scale=True)
    print(f"frames {len(pos)}  GPS path {path(pos):.2f} m  velocity path {path(dr):.2f} m")
    print(f"velocity track vs GPS ground truth: SE(3) ATE {se3:.3f} m, "
          f"Sim(3) ATE {sim3:.3f} m (scale {s:.4f})")


if __name__ == "__main__":
    main()
