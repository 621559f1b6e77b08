#!/usr/bin/env python3
"""occmask `process` against OpenCV's RGB odometry on the same frames: frames per second (as a
ratio measured in one run) and ATE against the motion capture.

For each of --rounds rounds, in this order:
  1. OpenCV 5 `cv2.Odometry` (OdometryType.RGB, default settings) over every colour/depth pair,
     frames decoded beforehand (only `prepareFrame` + `compute` are timed);
  2. `occmask process IN.mcap -o OUT.mcap` for each --mode (offline, causal), the whole command
     timed (decoding, DVO, detector, encoding and writing the annotated copy).
The ratio of each round's occmask frames/s to that round's OpenCV frames/s is printed, then
the median over rounds. Speed drifts on a shared machine; the ratio within a round does not
(both run in the same minute).

Setup:
    python3 -m venv /tmp/venv-cv && /tmp/venv-cv/bin/pip install numpy scipy opencv-python-headless
Run (DIR: a TUM-layout folder with groundtruth.txt; IN.mcap: `occmask convert tum DIR -o IN.mcap`):
    cargo build --release
    /tmp/venv-cv/bin/python tools/opencv_compare.py DIR IN.mcap --camera FX,FY,CX,CY [--bonn] [--rounds 3]
--bonn converts the Bonn dataset's marker poses to the camera's before the ATE (the conversion
of occmask::dataset::bonn); ATE is the RMSE after a rigid alignment, as `occmask eval` reports it.
"""
import argparse
import os
import statistics
import subprocess
import tempfile
import time

import cv2
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

# occmask::dataset::bonn: marker_from_camera (translation, quaternion x y z w) and the scale of
# the motion capture's translations.
BONN_MARKER_FROM_CAMERA_T = np.array([-0.0113, 0.0111, -0.0098])
BONN_MARKER_FROM_CAMERA_Q = np.array([-0.12874689, 0.88664202, -0.4396311, 0.06336138])
BONN_SCALE = 1.059290452


def read_list(path):
    out = []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            t, name = line.split()[:2]
            out.append((float(t), name))
    return out


def pairs(root, max_gap_s=0.02):
    rgb, depth = read_list(os.path.join(root, "rgb.txt")), read_list(os.path.join(root, "depth.txt"))
    dt = np.array([t for t, _ in depth])
    out = []
    for t, name in rgb:
        j = int(np.argmin(np.abs(dt - t)))
        if abs(dt[j] - t) <= max_gap_s:
            out.append((t, name, depth[j][1]))
    return out


def ground_truth(root, bonn):
    gt = np.loadtxt(os.path.join(root, "groundtruth.txt"))
    if bonn:
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(BONN_MARKER_FROM_CAMERA_Q).as_matrix()
        m[:3, 3] = BONN_MARKER_FROM_CAMERA_T
        for row in gt:
            t = np.eye(4)
            t[:3, :3] = Rotation.from_quat(row[4:8]).as_matrix()
            t[:3, 3] = row[1:4]
            c = t @ m
            row[1:4] = c[:3, 3] / BONN_SCALE
            row[4:8] = Rotation.from_matrix(c[:3, :3]).as_quat()
    return gt


def positions_at(gt, times):
    out = []
    for t in times:
        i = int(np.clip(np.searchsorted(gt[:, 0], t), 1, len(gt) - 1))
        a = (t - gt[i - 1, 0]) / (gt[i, 0] - gt[i - 1, 0])
        out.append(gt[i - 1, 1:4] * (1 - a) + gt[i, 1:4] * a)
    return np.array(out)


def ate(estimated, truth):
    """RMSE after the rigid (no scale) least-squares alignment of estimated onto truth."""
    me, mt = estimated.mean(0), truth.mean(0)
    u, _, vt = np.linalg.svd((truth - mt).T @ (estimated - me))
    d = np.diag([1, 1, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    aligned = (r @ (estimated - me).T).T + mt
    return float(np.sqrt(((aligned - truth) ** 2).sum(1).mean()))


def opencv_run(root, frames, k):
    grays = [cv2.imread(os.path.join(root, c), cv2.IMREAD_GRAYSCALE) for _, c, _ in frames]
    depths = [cv2.imread(os.path.join(root, d), cv2.IMREAD_UNCHANGED).astype(np.float32) / 5000.0 for _, _, d in frames]
    settings = cv2.OdometrySettings()
    settings.setCameraMatrix(k)
    odometry = cv2.Odometry(cv2.OdometryType_RGB, settings, cv2.OdometryAlgoType_COMMON)
    pose, positions = np.eye(4), [np.zeros(3)]
    started = time.perf_counter()
    previous = cv2.OdometryFrame(depths[0], grays[0])
    odometry.prepareFrame(previous)
    for gray, depth in zip(grays[1:], depths[1:]):
        current = cv2.OdometryFrame(depth, gray)
        odometry.prepareFrame(current)
        ok, rt = odometry.compute(previous, current)
        if ok:
            pose = pose @ rt
        positions.append(pose[:3, 3].copy())
        previous = current
    elapsed = time.perf_counter() - started
    return (len(frames) - 1) / elapsed, np.array(positions)


def occmask_run(binary, mcap, mode, out_dir):
    out = os.path.join(out_dir, f"{mode}.mcap")
    trajectory = os.path.join(out_dir, f"{mode}.txt")
    command = [binary, "process", mcap, "-o", out, "--force", "--quiet", "--export-trajectory", trajectory]
    if mode == "causal":
        command.append("--causal")
    started = time.perf_counter()
    subprocess.run(command, check=True)
    elapsed = time.perf_counter() - started
    traj = np.loadtxt(trajectory)
    return len(traj) / elapsed, traj


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dir")
    p.add_argument("mcap")
    p.add_argument("--camera", required=True, help="FX,FY,CX,CY")
    p.add_argument("--bonn", action="store_true")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--modes", default="offline,causal")
    p.add_argument("--bin", default="target/release/occmask")
    a = p.parse_args()
    fx, fy, cx, cy = (float(v) for v in a.camera.split(","))
    k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], np.float32)
    frames = pairs(a.dir)
    gt = ground_truth(a.dir, a.bonn)
    modes = a.modes.split(",")
    ratios = {m: [] for m in modes}
    with tempfile.TemporaryDirectory() as work:
        for r in range(a.rounds):
            cv_fps, cv_positions = opencv_run(a.dir, frames, k)
            line = f"round {r + 1}: OpenCV RGB {cv_fps:.1f} frames/s"
            if r == 0:
                cv_ate = ate(cv_positions, positions_at(gt, [t for t, _, _ in frames]))
            for m in modes:
                fps, traj = occmask_run(a.bin, a.mcap, m, work)
                ratios[m].append(fps / cv_fps)
                line += f" | occmask {m} {fps:.1f} frames/s ({fps / cv_fps:.2f}x)"
                if r == 0:
                    ours = ate(traj[:, 1:4], positions_at(gt, traj[:, 0]))
                    line += f" ATE {ours:.4f} m"
            print(line, flush=True)
    print(f"OpenCV RGB odometry ATE {cv_ate:.4f} m")
    for m in modes:
        print(f"occmask {m}: median {statistics.median(ratios[m]):.2f}x OpenCV's frames/s over {a.rounds} rounds")


if __name__ == "__main__":
    main()
