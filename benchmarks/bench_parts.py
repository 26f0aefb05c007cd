"""Benchmark of the part detector: speed and LOCALISATION on held-out synthetic shaded
scenes and on the real KITTI frames (plain script).

1. Time: response maps of one KITTI frame restricted to its GT car boxes, one thread.
2. Localisation (:func:`wirescene.training.parts.localisation`): for every visible vertex
   of a car (inside its box), is the top-scoring grid location of its log-ratio map inside
   the box within 4% / 10% of the car's projected length (max extent of the projected
   wireframe) of the vertex? Chance = a uniformly random grid location of the box. Also
   the mean percentile rank of the vertex location's score among the box's locations
   (chance 0.5). "clean" cars: occluded 0, truncated 0, box height >= 40 px.

   (a) synthetic: ``wirescene synth ROOT --scenes 20 --seed 1`` (seed < 1000: never used
       for training; generated into ``--synth-root`` if missing), exact GT vertices and
       ray-cast visibility;
   (b) real KITTI: the mean wireframe (``wirescene.core.shape.load_default().mean``) placed at
       the label pose (``groundplane.rotation_y``, location = the label's bottom centre),
       self-occlusion by ``occlusion.self_occlusion``. The "GT" vertices come from the
       *mean* shape, so they are themselves off by a few percent of the car length. These
       frames are the evaluation set: the shipped model never saw them.

Usage: python benchmarks/bench_parts.py --root KITTI_ROOT [--frame 000010]
       [--synth-root DIR] [--model PATH] [--fold K] [--flip] [--smooth SIGMA] [--real-only]

``--fold K`` scores only the frames of fold K of the shared frames' drive folds
(:mod:`wirescene.io.folds`): a fold model (``wirescene train parts --split-file`` of the
other folds' frames) held out by drive.

``--root`` holds the labelled KITTI frames scored (``tests/data/kitti``, three frames, is
a quick check of the script); without ``--synth-root`` the synthetic scenes are generated
into a temporary directory and removed afterwards.
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

from wirescene.io.folds import DRIVE_FOLDS, frame_drives  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.parts.detector import PartDetector, response_maps  # noqa: E402
from wirescene.training.parts import kitti_eval_frames, localisation, synth_eval_frames  # noqa: E402


def _line(name, r, radii):
    parts = [f"{name:<22s} {r['n_cars']:3d} cars {r['n_vertices']:4d} vertices:"]
    for rad in radii:
        parts.append(f"within {rad:.0%} {r['hits'][rad]:.3f} (chance {r['chance'][rad]:.3f})")
    parts.append(f"rank {r['rank']:.3f} (chance 0.5)")
    return "  ".join(parts)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames")
    ap.add_argument("--frame", default="000010")
    ap.add_argument("--synth-root", default=None,
                    help="synthetic held-out scenes, generated here if missing (default: a temporary directory)")
    ap.add_argument("--synth-scenes", type=int, default=20)
    ap.add_argument("--synth-seed", type=int, default=1)
    ap.add_argument("--model", default=None)
    ap.add_argument("--radius", type=float, nargs="+", default=[0.04, 0.10])
    ap.add_argument("--fold", type=int, default=None, help="score only this drive fold's frames")
    ap.add_argument("--flip", action="store_true", help="also score each box's mirror image (response_maps(flip=))")
    ap.add_argument("--smooth", type=float, default=None,
                    help="smoothing of the maps in box heights (response_maps(smooth=); default: the model's)")
    ap.add_argument("--real-only", action="store_true", help="score the real frames only (no synthetic scenes)")
    args = ap.parse_args()
    if args.synth_seed >= 1000:
        ap.error("synthetic seeds >= 1000 are training data")

    det = PartDetector.load(args.model)
    print(f"model: kind {det.kind}, {det.n_trees} trees, depth {det.max_depth}, "
          f"{det.n_features} features; meta {det.meta}")
    ds = KittiDataset(args.root)
    scored = None
    if args.fold is not None:
        drives = frame_drives()  # frames of no known drive belong to no fold
        scored = [f for f in ds.frame_ids() if DRIVE_FOLDS.get(drives.get(f)) == args.fold]
        print(f"fold {args.fold}: {len(scored)} frames")
    img = ds.image(args.frame)
    boxes = np.array([o.box for o in ds.labels(args.frame).of_type("Car")])
    response_maps(img[:50, :50], np.array([[5, 5, 40, 30]]), detector=det)  # warm-up
    t = time.perf_counter()
    R = response_maps(img, boxes, detector=det)
    dt = time.perf_counter() - t
    n_grid = sum(b.probs.shape[0] * b.probs.shape[1] * b.probs.shape[2] for b in R.boxes)
    print(f"frame {args.frame}: {len(boxes)} car boxes, {n_grid} grid points x scales, "
          f"response maps in {dt:.2f} s (1 thread)")

    with tempfile.TemporaryDirectory() as tmp:
        synth = Path(args.synth_root or tmp)
        if not args.real_only and not (synth / "training" / "wireframes").is_dir():
            from wirescene.synth.generate import generate_dataset

            print(f"generating {args.synth_scenes} synthetic scenes (seed {args.synth_seed}) into {synth}")
            generate_dataset(synth, args.synth_scenes, seed=args.synth_seed)
        radii = tuple(args.radius)
        rows = [] if args.real_only else [("synthetic held-out", lambda: synth_eval_frames(synth))]
        rows += [
            ("real KITTI clean", lambda: kitti_eval_frames(args.root, frames=scored)),
            ("real KITTI all cars", lambda: kitti_eval_frames(args.root, clean=False, min_box_h=0.0, frames=scored)),
        ]
        for name, frames in rows:
            r = localisation(det, frames(), radii=radii, flip=args.flip, smooth=args.smooth)
            print(_line(name, r, radii) + f"  [maps {r['t_maps_s']:.1f} s]")


if __name__ == "__main__":
    main()
