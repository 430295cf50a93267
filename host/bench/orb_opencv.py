#!/usr/bin/env python3
"""Reference timing for `semloc bench`: OpenCV's ORB on the same luma frames semloc used.

Usage: orb_opencv.py REPEAT FRAME.pgm [FRAME.pgm ...]
Prints one JSON object: per-frame milliseconds (median, p99), features per frame, versions.
OpenCV runs single-threaded (cv2.setNumThreads(1)) with ORB-SLAM2's settings: 2000
features, scale 1.2, 8 levels, FAST threshold 20, edge threshold 19, patch 31, Harris score.
Exit 3 if cv2 is missing, so the caller can say so instead of failing.
"""
import json
import sys
import time

try:
    import cv2
    import numpy as np
except ImportError as e:  # pragma: no cover
    print(f"opencv unavailable: {e}", file=sys.stderr)
    sys.exit(3)


def main():
    repeat = int(sys.argv[1])
    paths = sys.argv[2:]
    if not paths:
        print("no frames given", file=sys.stderr)
        sys.exit(2)
    cv2.setNumThreads(1)
    frames = []
    for p in paths:
        img = cv2.imread(p, cv2.IMREAD_UNCHANGED)
        if img is None:
            print(f"{p}: cannot read", file=sys.stderr)
            sys.exit(2)
        frames.append(img)
    orb = cv2.ORB_create(nfeatures=2000, scaleFactor=1.2, nlevels=8, edgeThreshold=19,
                         firstLevel=0, WTA_K=2, scoreType=cv2.ORB_HARRIS_SCORE,
                         patchSize=31, fastThreshold=20)
    orb.detectAndCompute(frames[0], None)  # warm-up
    times, counts = [], []
    for _ in range(repeat):
        for img in frames:
            t = time.perf_counter()
            kps, _ = orb.detectAndCompute(img, None)
            times.append((time.perf_counter() - t) * 1e3)
            counts.append(len(kps))
    times.sort()
    n = len(times)
    p99 = times[min(n - 1, max(0, int(np.ceil(0.99 * n)) - 1))]
    print(json.dumps({
        "median_ms": times[n // 2] if n % 2 else 0.5 * (times[n // 2 - 1] + times[n // 2]),
        "p99_ms": p99,
        "features_median": sorted(counts)[len(counts) // 2],
        "frames": len(frames),
        "repeat": repeat,
        "opencv": cv2.__version__,
    }))


if __name__ == "__main__":
    main()
