#!/usr/bin/env python3
"""Reference figures for semloc's trajectory evaluator (tests/tests/system/eval_reference.rs).

For each KITTI odometry sequence 00..10 this prints, for the published ORB-SLAM2 stereo run
(shared/data/trajectories/orbslam2-stereo/XX.txt) against the KITTI ground truth
(shared/data/trajectories/kitti-gt/XX.txt):

* t_rel (%) and r_rel (deg/100 m) from a direct numpy transcription of the KITTI odometry
  devkit's evaluate_odometry.cpp (trajectoryDistances, lastFrameFromSegmentLength,
  calcSequenceErrors, rotationError, translationError; segment lengths 100..800 m, first frame
  every 10 frames; dist kept in float32 like the devkit's vector<float>);
* ATE RMSE (m) computed with evo's own API: SE(3) Umeyama alignment (no scale, like
  `evo_ape kitti -a`) and APE on the translation part.

Usage: python3 tests/oracle/eval_reference.py [DATA_DIR]   (default: ../shared/data)
"""
import os
import sys

import numpy as np
import evo
from evo.core import metrics
from evo.tools import file_interface

LENGTHS = [100, 200, 300, 400, 500, 600, 700, 800]
STEP_SIZE = 10


def load_poses(path):
    """KITTI pose file -> list of 4x4 matrices (devkit loadPoses)."""
    data = np.loadtxt(path, dtype=np.float64).reshape(-1, 12)
    out = []
    for row in data:
        m = np.eye(4)
        m[:3, :] = row.reshape(3, 4)
        out.append(m)
    return out


def trajectory_distances(poses):
    dist = [np.float32(0.0)]
    for i in range(1, len(poses)):
        d = poses[i - 1][:3, 3] - poses[i][:3, 3]
        # float dist[i-1] + double sqrt -> double, stored as float
        dist.append(np.float32(float(dist[i - 1]) + float(np.sqrt(d @ d))))
    return dist


def last_frame_from_segment_length(dist, first_frame, length):
    target = np.float32(dist[first_frame] + np.float32(length))
    for i in range(first_frame, len(dist)):
        if dist[i] > target:
            return i
    return -1


def rotation_error(e):
    d = 0.5 * (e[0, 0] + e[1, 1] + e[2, 2] - 1.0)
    return np.arccos(max(min(d, 1.0), -1.0))


def translation_error(e):
    return np.linalg.norm(e[:3, 3])


def calc_sequence_errors(poses_gt, poses_result):
    err = []
    dist = trajectory_distances(poses_gt)
    for first_frame in range(0, len(poses_gt), STEP_SIZE):
        for length in LENGTHS:
            last_frame = last_frame_from_segment_length(dist, first_frame, length)
            if last_frame == -1:
                continue
            pose_delta_gt = np.linalg.inv(poses_gt[first_frame]) @ poses_gt[last_frame]
            pose_delta_result = np.linalg.inv(poses_result[first_frame]) @ poses_result[last_frame]
            pose_error = np.linalg.inv(pose_delta_result) @ pose_delta_gt
            r_err = rotation_error(pose_error)
            t_err = translation_error(pose_error)
            num_frames = last_frame - first_frame + 1
            speed = length / (0.1 * num_frames)
            err.append((first_frame, r_err / length, t_err / length, length, speed))
    return err


def devkit(gt_path, est_path):
    gt = load_poses(gt_path)
    est = load_poses(est_path)
    assert len(gt) == len(est), (gt_path, est_path)
    err = calc_sequence_errors(gt, est)
    t_rel = np.mean([e[2] for e in err]) * 100.0
    r_rel = np.mean([e[1] for e in err]) * 180.0 / np.pi * 100.0
    return t_rel, r_rel, len(err)


def evo_ate(gt_path, est_path):
    ref = file_interface.read_kitti_poses_file(gt_path)
    est = file_interface.read_kitti_poses_file(est_path)
    est.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return ape.get_statistic(metrics.StatisticsType.rmse)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    data = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "..", "..", "shared", "data")
    traj = os.path.join(data, "trajectories")
    print(f"# evo {evo.__version__}, numpy {np.__version__}")
    print("# seq  n_poses  segments  t_rel_pct  r_rel_deg_per_100m  ate_rmse_m")
    for seq in range(11):
        gt_path = os.path.join(traj, "kitti-gt", f"{seq:02d}.txt")
        est_path = os.path.join(traj, "orbslam2-stereo", f"{seq:02d}.txt")
        t_rel, r_rel, nseg = devkit(gt_path, est_path)
        ate = evo_ate(gt_path, est_path)
        n = len(load_poses(gt_path))
        print(f"{seq:02d}  {n:5d}  {nseg:5d}  {t_rel:.6f}  {r_rel:.6f}  {ate:.6f}")


if __name__ == "__main__":
    main()
