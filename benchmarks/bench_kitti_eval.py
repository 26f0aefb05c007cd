"""Speed of the numpy KITTI evaluation (:mod:`wirescene.eval.kitti_metrics`) on a synthetic
split the size of the usual 3,769-frame val split, on one core.

Ground truth per frame: Poisson(3.8) cars, Poisson(0.4) vans, Poisson(0.6) pedestrians at
random places 5-60 m ahead, their 2D boxes projected with KITTI's P2, random occlusion /
truncation flags, Poisson(2.5) DontCare regions (about KITTI's own mix). Predictions: 85%
of the cars and vans found with noisy boxes and poses, plus Poisson(``--fps``) false
positives with lower scores. Timed: the evaluation of in-memory label rows (all twelve
figures x three difficulties, R40 and R11, IoU 0.7 and 0.5), and separately the same
from label directories on disk (writing excluded, reading included).

Usage: python benchmarks/bench_kitti_eval.py [--frames 3769] [--fps 10] [--repeat 3] [--io]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import best_of  # noqa: E402
from wirescene.core.boxes import box_corners  # noqa: E402
from wirescene.core.groundplane import rotation_y  # noqa: E402
from wirescene.eval.intervals import kitti_intervals  # noqa: E402
from wirescene.eval.kitti_metrics import format_kitti_table, kitti_metrics, read_label_dirs  # noqa: E402
from wirescene.io.kitti import Label, write_labels  # noqa: E402

P2 = np.array([[721.5, 0.0, 609.6, 44.9], [0.0, 721.5, 172.9, 0.2], [0.0, 0.0, 1.0, 0.003]])
SIZES = {"Car": (1.53, 1.63, 3.88), "Van": (2.2, 1.9, 5.1), "Pedestrian": (1.76, 0.66, 0.84)}


def _box2d(dims, location, ry):
    corners = box_corners(np.asarray(dims), np.asarray(location), rotation_y(ry))
    uvw = np.c_[corners, np.ones(8)] @ P2.T
    uv = uvw[:, :2] / uvw[:, 2:]
    box = np.r_[uv.min(axis=0), uv.max(axis=0)]
    return np.clip(box, 0, [1241, 374, 1241, 374])


def synthetic_split(n_frames: int, *, fps: float = 10.0, seed: int = 0):
    """Ground-truth and prediction label rows of ``n_frames`` synthetic frames."""
    rng = np.random.default_rng(seed)
    gts, preds = [], []
    for _ in range(n_frames):
        gt, pred = [], []
        kinds = ["Car"] * rng.poisson(3.8) + ["Van"] * rng.poisson(0.4) + ["Pedestrian"] * rng.poisson(0.6)
        for kind in kinds:
            z, x = rng.uniform(5, 60), rng.uniform(-0.4, 0.4) * 40
            ry = rng.uniform(-np.pi, np.pi)
            dims = np.array(SIZES[kind]) * rng.uniform(0.9, 1.1, 3)
            loc = np.array([x, 1.65, z])
            alpha = ry - np.arctan2(x, z)
            box = _box2d(dims, loc, ry)
            if min(box[2] - box[0], box[3] - box[1]) < 1:  # outside the image
                continue
            gt.append(Label(kind, rng.choice([0.0, 0.0, 0.2, 0.4, 0.6]), int(rng.integers(0, 4)), alpha,
                            box, dims, loc, ry))
            if kind != "Pedestrian" and rng.random() < 0.85:
                e = rng.normal(0, 1, 7)
                dloc = loc + [0.3 * e[0], 0.05 * e[1], 0.03 * z * e[2]]
                dd = dims * (1 + 0.05 * e[3:6])
                dry = ry + 0.1 * e[6]
                dbox = _box2d(dd, dloc, dry)
                if min(dbox[2] - dbox[0], dbox[3] - dbox[1]) >= 1:
                    pred.append(Label("Car", -1, -1, dry - np.arctan2(dloc[0], dloc[2]), dbox, dd, dloc, dry,
                                      float(rng.uniform(0.3, 1.0))))
        for _ in range(rng.poisson(fps)):
            z, x, ry = rng.uniform(5, 60), rng.uniform(-16, 16), rng.uniform(-np.pi, np.pi)
            dims, loc = np.array(SIZES["Car"]), np.array([x, 1.65, z])
            box = _box2d(dims, loc, ry)
            if min(box[2] - box[0], box[3] - box[1]) >= 1:
                pred.append(Label("Car", -1, -1, ry - np.arctan2(x, z), box, dims, loc, ry, float(rng.uniform(0.0, 0.6))))
        for _ in range(rng.poisson(2.5)):
            x1, y1 = rng.uniform(0, 1150), rng.uniform(120, 250)
            gt.append(Label("DontCare", -1, -1, -10, [x1, y1, x1 + rng.uniform(10, 90), y1 + rng.uniform(10, 50)],
                            [-1, -1, -1], [-1000, -1000, -1000], -10))
        gts.append(gt)
        preds.append(pred)
    return gts, preds


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=3769)
    ap.add_argument("--fps", type=float, default=10.0, help="Mean false positives per frame.")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--io", action="store_true", help="Also time the evaluation of label directories on disk.")
    ap.add_argument("--draws", type=int, default=0, help="Also time the APs' bootstrap intervals with this many draws.")
    ap.add_argument("--drives", type=int, default=40, help="Drives the frames are dealt into for --draws.")
    args = ap.parse_args()

    t0 = time.perf_counter()
    gts, preds = synthetic_split(args.frames, fps=args.fps)
    n_gt = sum(len(g) for g in gts)
    n_pred = sum(len(p) for p in preds)
    print(f"synthetic split: {args.frames} frames, {n_gt} ground-truth rows "
          f"({sum(r.type == 'Car' for g in gts for r in g)} cars), {n_pred} predictions "
          f"(made in {time.perf_counter() - t0:.1f} s)")
    seconds, result = best_of(lambda: kitti_metrics(gts, preds), repeat=args.repeat)
    print(f"kitti_metrics on label rows: {seconds:.2f} s (best of {args.repeat}, one core)")
    print(format_kitti_table(result))
    if args.draws:
        ids = [f"{i:06d}" for i in range(args.frames)]
        drives = {f: f"drive{i * args.drives // args.frames}" for i, f in enumerate(ids)}
        spread_s, spread = best_of(lambda: kitti_intervals(gts, preds, ids, drives, n_boot=args.draws), repeat=1)
        print(f"kitti_intervals, {args.draws} draws over {args.drives} drives (moderate; 2D, AOS, BEV, 3D at IoU 0.7 "
              f"and 0.5): {spread_s:.1f} s, {spread_s / seconds:.0f}x kitti_metrics; 3D AP@0.7 "
              f"{result['car']['3d']['moderate']:.2f} [{spread['car']['3d'][0]:.2f}, {spread['car']['3d'][1]:.2f}]")
    if args.io:
        with tempfile.TemporaryDirectory() as tmp:
            gt_dir, pred_dir = Path(tmp, "gt"), Path(tmp, "pred")
            gt_dir.mkdir()
            pred_dir.mkdir()
            for i, (g, p) in enumerate(zip(gts, preds)):
                write_labels(gt_dir / f"{i:06d}.txt", g, with_score=False)
                write_labels(pred_dir / f"{i:06d}.txt", p)

            def from_disk():
                _, g, p = read_label_dirs(gt_dir, pred_dir)
                return kitti_metrics(g, p)

            seconds, _ = best_of(from_disk, repeat=args.repeat)
            print(f"read_label_dirs + kitti_metrics: {seconds:.2f} s (best of {args.repeat})")


if __name__ == "__main__":
    main()
