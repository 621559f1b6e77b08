#!/usr/bin/env python3
"""Side-by-side DVO comparison: occmask vs Open3D RGB-D odometry on the same frame pairs.

Reads the per-pair CSV written by `cargo run --release --example dvo_tum -- DIR --csv OURS.csv`
(which also carries the interpolated ground-truth motion of every pair), runs Open3D's
`compute_rgbd_odometry` (hybrid Jacobian, default OdometryOption) on the same pairs with the same
intrinsics, and prints a markdown table: RPE RMSE (translation mm, rotation deg) and mean
milliseconds per pair for both.

Setup (a virtual environment of your choice; `apt-get install libusb-1.0-0` if `import open3d`
complains):
    python3 -m venv /tmp/venv-o3d && /tmp/venv-o3d/bin/pip install open3d numpy
Run (DIR: a TUM folder, e.g. fixtures/tum_fr2_desk_10 or $OCCMASK_DATA/tum_fr2_desk_50):
    cargo run --release --example dvo_tum -- DIR --csv /tmp/ours.csv
    /tmp/venv-o3d/bin/python tools/open3d_compare.py DIR /tmp/ours.csv \
        --ours-cpu-ms <CPU ms/pair printed by dvo_tum>

CPU ms counts all threads of the process (robust when other jobs load the machine).
Open3D's timing covers `compute_rgbd_odometry` only (RGBDImage objects are built beforehand);
ours covers pyramid construction + estimation. Error convention (TUM evaluate_rpe, docs/method.md
"Evaluation"): E = a^-1 b, a = estimated current_from_reference, b = ground truth.
"""
import argparse
import csv
import math
import os
import time

import numpy as np
import open3d as o3d

FX, FY, CX, CY = 520.9, 521.0, 325.1, 249.7  # TUM fr2
DEPTH_SCALE = 5000.0


def read_list(path):
    out = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            t, name = line.split()[:2]
            out.append((t, name))
    return out


def ns(t):
    whole, _, frac = t.partition(".")
    return int(whole) * 10**9 + int((frac + "000000000")[:9])


def quat_to_matrix(tx, ty, tz, qx, qy, qz, qw):
    x, y, z, w = qx, qy, qz, qw
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = [tx, ty, tz]
    return m


def rpe(est, gt):
    e = np.linalg.inv(est) @ gt
    trans_mm = np.linalg.norm(e[:3, 3]) * 1000.0
    c = max(-1.0, min(1.0, (np.trace(e[:3, :3]) - 1.0) / 2.0))
    return trans_mm, math.degrees(math.acos(c))


def rms(v):
    return math.sqrt(sum(x * x for x in v) / len(v)) if v else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", help="TUM folder (rgb.txt, depth.txt)")
    ap.add_argument("ours_csv", help="CSV from the dvo_tum example")
    ap.add_argument("--label", default="occmask DVO (default config)")
    ap.add_argument("--per-pair", action="store_true", help="also print every pair")
    ap.add_argument("--ours-cpu-ms", type=float, default=float("nan"),
                    help="our CPU ms per pair (all threads), from the dvo_tum summary line")
    args = ap.parse_args()

    rgb = read_list(os.path.join(args.dataset, "rgb.txt"))
    depth = read_list(os.path.join(args.dataset, "depth.txt"))
    depth_ns = [(ns(t), n) for t, n in depth]

    def rgbd(i):
        t, name = rgb[i]
        dn = min(depth_ns, key=lambda d: abs(d[0] - ns(t)))[1]
        color = o3d.io.read_image(os.path.join(args.dataset, name))
        dep = o3d.io.read_image(os.path.join(args.dataset, dn))
        return o3d.geometry.RGBDImage.create_from_color_and_depth(
            color, dep, depth_scale=DEPTH_SCALE, depth_trunc=1000.0, convert_rgb_to_intensity=True)

    intr = o3d.camera.PinholeCameraIntrinsic(640, 480, FX, FY, CX, CY)
    images = [rgbd(i) for i in range(len(rgb))]
    option = o3d.pipelines.odometry.OdometryOption()
    jac = o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm()

    with open(args.ours_csv) as f:
        rows = list(csv.DictReader(f))
    ours_t, ours_r, ours_ms, o3d_t, o3d_r, o3d_ms, o3d_cpu_ms, o3d_fail = [], [], [], [], [], [], [], 0
    per_pair = []
    for row in rows:
        if not row["gt_tx"]:
            continue
        i = int(row["pair"])
        gt = quat_to_matrix(*(float(row[k]) for k in ("gt_tx", "gt_ty", "gt_tz", "gt_qx", "gt_qy", "gt_qz", "gt_qw")))
        est = quat_to_matrix(*(float(row[k]) for k in ("est_tx", "est_ty", "est_tz", "est_qx", "est_qy", "est_qz", "est_qw")))
        et, er = rpe(est, gt)
        ours_t.append(et)
        ours_r.append(er)
        ours_ms.append(float(row["ms"]))
        start, cpu_start = time.perf_counter(), time.process_time()
        ok, trans, _ = o3d.pipelines.odometry.compute_rgbd_odometry(
            images[i], images[i + 1], intr, np.eye(4), jac, option)
        o3d_ms.append((time.perf_counter() - start) * 1e3)
        o3d_cpu_ms.append((time.process_time() - cpu_start) * 1e3)
        if not ok:
            o3d_fail += 1
        # Open3D returns the transform taking source (frame i) points into the target (frame i+1)
        # camera: the same current_from_reference convention as ours.
        ot, orr = rpe(np.asarray(trans), gt)
        o3d_t.append(ot)
        o3d_r.append(orr)
        per_pair.append((i, et, er, float(row["ms"]), ot, orr, o3d_ms[-1]))

    if args.per_pair:
        print("| pair | ours mm | ours deg | ours ms | Open3D mm | Open3D deg | Open3D ms |")
        print("|---:|---:|---:|---:|---:|---:|---:|")
        for p in per_pair:
            print("| %d | %.2f | %.3f | %.1f | %.2f | %.3f | %.1f |" % p)
        print()
    print(f"{len(ours_t)} frame pairs of {os.path.basename(os.path.normpath(args.dataset))}, "
          f"Open3D {o3d.__version__} (hybrid Jacobian, default OdometryOption; {o3d_fail} pairs reported failure)")
    print()
    print("| method | RPE trans RMSE (mm) | RPE rot RMSE (deg) | max trans (mm) | wall ms / pair | CPU ms / pair |")
    print("|---|---:|---:|---:|---:|---:|")
    print(f"| {args.label} | {rms(ours_t):.2f} | {rms(ours_r):.3f} | {max(ours_t):.2f} | "
          f"{np.mean(ours_ms):.1f} | {args.ours_cpu_ms:.1f} |")
    print(f"| Open3D compute_rgbd_odometry | {rms(o3d_t):.2f} | {rms(o3d_r):.3f} | {max(o3d_t):.2f} | "
          f"{np.mean(o3d_ms):.1f} | {np.mean(o3d_cpu_ms):.1f} |")


if __name__ == "__main__":
    main()
