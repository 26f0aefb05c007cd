"""Training at scale, the crop viewpoint classifier's step: wall time and peak memory of
``wirescene train viewpoints`` (the step ``train all`` runs after the detector) on the
labelled frames of a KITTI root, and a projection to the 3,712-frame KITTI train split,
plain script.

Protocol: the command itself runs on the first N labelled frames for each N of
``--frames`` (a subprocess: wall time and peak resident memory). The step has two parts:
describing each label box's crop (linear in the cars) and one logistic regression on all
the rows (4 a car: the box, its mirror image and a jittered copy of each). The projection
times the first part per car on the largest N, and fits the classifier on a replica of
the projected number of rows (the real rows tiled, each feature moved by 5% of its spread
so that no two rows are equal), whose time and peak memory stand for the last part's. It
is a projection, not a measurement: say so wherever it is quoted.

Usage:
  python benchmarks/bench_viewpoint_scale.py WORK_DIR --root KITTI_ROOT [--frames 24,72] [--json out.json]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train_scale import KITTI_TRAIN_FRAMES, labelled_frames, run_child  # noqa: E402

#: Cars of KITTI's object training split a frame (28,742 'Car' labels in 7,481 frames).
CARS_PER_FRAME = 28742 / 7481


def replica(x: np.ndarray, y: np.ndarray, rows: int, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``rows`` rows of ``(x, y)`` tiled, each feature moved by N(0, 5% of its spread)."""
    rng = np.random.default_rng(seed)
    reps = -(-rows // len(x))
    big = np.tile(x, (reps, 1))[:rows]
    big = big + rng.normal(0.0, 0.05, big.shape).astype(x.dtype) * x.std(0)
    return big, np.tile(y, reps)[:rows]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("work_dir", type=Path)
    ap.add_argument("--root", type=Path, required=True, help="labelled KITTI root")
    ap.add_argument("--frames", default="24,72", help="numbers of frames the command is run on")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    from wirescene.core.jsonio import write_json
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.viewpoint_classifier import fit_viewpoint_classifier, kitti_examples

    args.work_dir.mkdir(parents=True, exist_ok=True)
    ids = labelled_frames(args.root)
    out = {"runs": []}
    for n in (int(s) for s in args.frames.split(",")):
        if n > len(ids):
            raise SystemExit(f"{args.root}: {len(ids)} labelled frames, fewer than the {n} asked for")
        seconds, peak, _ = run_child(["train", "viewpoints", str(args.root), "--frames", ",".join(ids[:n]),
                                      "--out", str(args.work_dir / f"viewpoints_{n}.npz")])
        out["runs"].append({"frames": n, "seconds": round(seconds, 1), "peak_mb": round(peak)})
        print(f"train viewpoints on {n} frames: {seconds:.1f} s, peak {peak:.0f} MB")
    dataset = KittiDataset(args.root)
    n = max(run["frames"] for run in out["runs"])  # the per-car time of the largest run
    t0 = time.perf_counter()
    x, y = kitti_examples(dataset, ids[:n])
    describe = time.perf_counter() - t0
    cars = len(y) / 4
    rows = int(round(KITTI_TRAIN_FRAMES * CARS_PER_FRAME * 4))
    big_x, big_y = replica(x, y, rows)
    t0 = time.perf_counter()
    fit_viewpoint_classifier(big_x, big_y)
    fit = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    per_car = describe / cars
    out["projection"] = {"frames": KITTI_TRAIN_FRAMES, "rows": rows, "describe_s_per_car": per_car,
                         "describe_s": per_car * rows / 4, "fit_s": fit, "fit_peak_mb": round(peak)}
    print(f"projected to {KITTI_TRAIN_FRAMES} frames ({rows} rows, {big_x.nbytes / 1e9:.2f} GB of features): "
          f"crops {per_car * 1e3:.1f} ms a car -> {per_car * rows / 4:.0f} s; the logistic fit on a replica "
          f"{fit:.0f} s, this process's peak {peak:.0f} MB")
    if args.json is not None:
        write_json(args.json, out)


if __name__ == "__main__":
    main()
