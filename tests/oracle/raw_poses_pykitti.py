#!/usr/bin/env python3
"""Reference camera-2 ground truth of a KITTI raw drive, computed by pykitti.

usage: raw_poses_pykitti.py DATE_DIR DRIVE OUT.txt

DATE_DIR  the date folder, e.g. ../shared/data/kitti-raw/2011_09_26
DRIVE     0005, 2011_09_26_0005 or 2011_09_26_drive_0005_sync
OUT.txt   written in KITTI format: 12 numbers a line, row-major 3x4 camera-to-world

Poses are pykitti's own: oxts T_w_imu (Mercator, Rz·Ry·Rx) and calib.T_cam2_imu
(= T2 · R_rect_00 · T_cam0unrect_velo · T_velo_imu), giving
T_w_cam2(i) = T_w_imu(i) · inv(T_cam2_imu), made relative to the first frame:
G_i = inv(T_w_cam2(0)) · T_w_cam2(i).

Exit status 3 means pykitti (or numpy) is not installed, so callers can skip rather than fail.
"""
import os
import re
import sys
import types


def import_pykitti():
    try:
        import cv2  # noqa: F401  (pykitti's tracking module imports it; raw does not use it)
    except ImportError:
        sys.modules["cv2"] = types.ModuleType("cv2")
    import numpy as np
    import pykitti
    return np, pykitti


def main(argv):
    if len(argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    date_dir, drive, out = argv[1], argv[2], argv[3]
    try:
        np, pykitti = import_pykitti()
    except ImportError as e:
        print(f"pykitti unavailable: {e}", file=sys.stderr)
        return 3
    date_dir = os.path.normpath(date_dir)
    base, date = os.path.split(date_dir)
    m = re.search(r"(?:drive_)?(\d{4})(?:_sync)?$", drive)
    if not m:
        print(f"bad drive name {drive!r}", file=sys.stderr)
        return 2
    data = pykitti.raw(base, date, m.group(1))
    inv_cam2_imu = np.linalg.inv(data.calib.T_cam2_imu)
    w_cam = [o.T_w_imu.dot(inv_cam2_imu) for o in data.oxts]
    first_inv = np.linalg.inv(w_cam[0])
    with open(out, "w") as f:
        for t in w_cam:
            g = first_inv.dot(t)
            f.write(" ".join("%.17e" % v for v in g[:3, :].reshape(-1)) + "\n")
    print(f"{len(w_cam)} poses of {data.drive} written to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
