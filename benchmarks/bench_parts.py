"""Benchmark of the part detector on real KITTI frames (plain script).

1. Time: response maps of one frame restricted to its GT car boxes, one thread.
2. Localisation: for every GT car of every frame, the mean wireframe
   (``wirescene.shape.load_default().mean``) is placed at the GT pose
   (rotation from ``groundplane.object_pose(x, z, rotation_y)``, location = the label's
   bottom centre: the default plane height misplaces some frames' cars), self-occlusion by ``occlusion.self_occlusion``; for each visible vertex inside
   the box, is the top-scoring grid location of its log-ratio map (inside the box) within
   ``radius`` x the car's projected length (max extent of the projected wireframe) of the
   projected vertex? Chance = a uniformly random grid location in the box. Also the
   percentile rank of the GT location's score among the box's locations (chance 0.5).

Note: these frames are also the evaluation frames; the shipped model never saw them
(no KITTI background by default). The "GT" vertices come from the *mean* shape, so they
are themselves off by a few percent of the car length.

Usage: python benchmarks/bench_parts.py [--root /work/shared/data/kitti] [--frame 000010]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from wirescene import wireframe  # noqa: E402
from wirescene.datasets.kitti import KittiDataset  # noqa: E402
from wirescene.groundplane import object_pose  # noqa: E402
from wirescene.occlusion import self_occlusion  # noqa: E402
from wirescene.parts import PartDetector, response_maps  # noqa: E402
from wirescene.shape import load_default  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", default="/work/shared/data/kitti")
    ap.add_argument("--frame", default="000010")
    ap.add_argument("--model", default=None)
    ap.add_argument("--radius", type=float, nargs="+", default=[0.04, 0.10])
    args = ap.parse_args()

    det = PartDetector.load(args.model)
    ds = KittiDataset(args.root)
    mean = load_default().mean

    img = ds.image(args.frame)
    boxes = np.array([o.box for o in ds.labels(args.frame).of_type("Car")])
    response_maps(img[:50, :50], np.array([[5, 5, 40, 30]]), detector=det)  # warm-up
    t = time.perf_counter()
    R = response_maps(img, boxes, detector=det)
    dt = time.perf_counter() - t
    n_grid = sum(b.probs.shape[0] * b.probs.shape[1] * b.probs.shape[2] for b in R.boxes)
    print(f"frame {args.frame}: {len(boxes)} car boxes, {n_grid} grid points x scales, "
          f"response maps in {dt:.2f} s (1 thread)")

    hits = {r: [] for r in args.radius}
    chance = {r: [] for r in args.radius}
    ranks, n_cars = [], 0
    t_all = 0.0
    for fid in ds.frame_ids():
        img = ds.image(fid)
        cam = ds.camera(fid)
        cars = ds.labels(fid).of_type("Car")
        if not cars:
            continue
        t = time.perf_counter()
        R = response_maps(img, np.array([c.box for c in cars]), detector=det)
        t_all += time.perf_counter() - t
        for bi, car in enumerate(cars):
            # rotation from object_pose; location = the label's own bottom centre (the
            # default ground plane's height puts some KITTI cars ~0.7 m too high)
            _, Rm = object_pose(car.location[0], car.location[2], car.rotation_y)
            X = mean @ Rm.T + car.location
            uv = cam.project(X)
            hidden = self_occlusion(X, wireframe.FACES, cam.center)
            x1, y1, x2, y2 = car.box
            inbox = (uv[:, 0] >= x1) & (uv[:, 0] <= x2) & (uv[:, 1] >= y1) & (uv[:, 1] <= y2)
            vis = ~hidden & inbox
            length = max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1]))
            b = R.boxes[bi]
            g = b.grid_uv().reshape(-1, 2)
            m = (g[:, 0] >= x1) & (g[:, 0] <= x2) & (g[:, 1] >= y1) & (g[:, 1] <= y2)
            g = g[m]
            lr = b.log_ratio.reshape(-1, 36)[m]
            n_cars += 1
            for j in np.nonzero(vis)[0]:
                best = g[np.argmax(lr[:, j])]
                d_all = np.linalg.norm(g - uv[j], axis=1)
                for r in args.radius:
                    hits[r].append(np.linalg.norm(best - uv[j]) <= r * length)
                    chance[r].append(np.mean(d_all <= r * length))
                at = R.log_ratio(np.broadcast_to(uv[j], (36, 2)), bi)[j]
                ranks.append(np.mean(lr[:, j] < at) + 0.5 * np.mean(lr[:, j] == at))
    print(f"{n_cars} GT cars in {len(ds.frame_ids())} frames, {len(ranks)} visible vertices; "
          f"response maps {t_all:.1f} s in all")
    for r in args.radius:
        print(f"  top location within {r:.0%} of projected length: {np.mean(hits[r]):.3f} "
              f"(chance {np.mean(chance[r]):.3f})")
    print(f"  mean percentile rank of the GT location's log ratio in its box: {np.mean(ranks):.3f} (chance 0.5)")


if __name__ == "__main__":
    main()
