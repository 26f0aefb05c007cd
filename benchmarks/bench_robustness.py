"""Robustness of the 3D lifting to imperfect pre-detections, on the real KITTI frames.

The label boxes of every Car serve as pre-detections, as in ``wirescene eval --detections
gt``, but each box edge is moved by Gaussian noise of ``level`` x the box width (left and
right edges) or height (top and bottom edges), and the observation angle by Gaussian noise
of ``--viewpoint-noise`` degrees before it is binned into the 8 coarse viewpoints. The
detection files hold only the 2D box, the angle and a score of 1 (no 3D ground truth).
Reported per setting: TP/GT (a detection is a TP initialisation if it overlaps its car
by IoU > 0.5, the paper's rule), the % of TPs within 1 m / 1.5 m of the true position,
and the KITTI 3D AP R40 at IoU 0.5 (moderate) of the written predictions (raw scores:
all 1, so that AP is about precision x recall of one operating point).

Nothing here is trained on real frames (the coarse variants use the CAD shape model
only), so every labelled frame of ``--root`` is scored. Fine variants (``--variant fg+gp`` ...) use part
detectors and occluder statistics; check what they were trained on before reading their
figures as held-out ones.

Usage: python benchmarks/bench_robustness.py --root KITTI_ROOT
       [--levels 0,0.05,0.1,0.2] [--viewpoint-noise 0,20] [--variant coarse --variant coarse+gp]
       [--seed 0] [--json out.json]
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

from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.eval.kitti_metrics import kitti_metrics  # noqa: E402
from wirescene.eval.runner import evaluate_dataset  # noqa: E402
from wirescene.eval.sources import DetectionSource, frame_seed  # noqa: E402
from wirescene.fitting.options import FitOptions  # noqa: E402
from wirescene.io.kitti import KittiDataset, Label, read_labels, write_labels  # noqa: E402


def write_perturbed_detections(dataset: KittiDataset, out_dir: Path, *, level: float, viewpoint_noise_deg: float,
                               seed: int) -> int:
    """One KITTI ``.txt`` of perturbed Car boxes per frame; returns the number of cars."""
    out_dir.mkdir(parents=True, exist_ok=True)
    n = 0
    for f in dataset.frame_ids():
        rng = frame_seed(seed, f)  # the same draws at every level: differences come from the level alone
        width, height = dataset.image_size(f)
        rows = []
        for car in dataset.labels(f).of_type("Car"):
            w, h = car.box[2] - car.box[0], car.box[3] - car.box[1]
            box = car.box + level * rng.standard_normal(4) * [w, h, w, h]
            box = np.clip(box, 0, [width - 1, height - 1, width - 1, height - 1])
            x1, x2 = sorted(box[[0, 2]])
            y1, y2 = sorted(box[[1, 3]])
            box = [x1, y1, max(x2, x1 + 2), max(y2, y1 + 2)]
            alpha = car.alpha + np.deg2rad(viewpoint_noise_deg) * rng.standard_normal()
            alpha = (alpha + np.pi) % (2 * np.pi) - np.pi
            # 3D columns are the devkit's "not given" values: no ground truth leaks.
            rows.append(Label("Car", -1, -1, alpha, box, [-1, -1, -1], [-1000, -1000, -1000], -10, 1.0))
            n += 1
        write_labels(out_dir / f"{f}.txt", rows)
    return n


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames")
    ap.add_argument("--levels", default="0,0.05,0.1,0.2", help="Box jitter, fractions of the box size.")
    ap.add_argument("--viewpoint-noise", default="0,20", help="Std. dev. of the angle noise, degrees.")
    ap.add_argument("--variant", dest="variants", action="append", default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    variants = args.variants or ["coarse", "coarse+gp"]
    dataset = KittiDataset(args.root)
    frames = dataset.frame_ids()
    gts = [dataset.labels(f) for f in frames]
    rows = []
    print(f"{len(frames)} frames; variants {', '.join(variants)}; seed {args.seed}")
    print(f"{'jitter':>6} {'vp noise':>8} {'variant':<10} {'TP/GT':>8} {'<1m':>5} {'<1.5m':>6} {'3D AP@.5 mod':>13}")
    for level in (float(x) for x in args.levels.split(",")):
        for vp in (float(x) for x in args.viewpoint_noise.split(",")):
            with tempfile.TemporaryDirectory() as tmp:
                det_dir, pred_dir = Path(tmp, "dets"), Path(tmp, "pred")
                n_cars = write_perturbed_detections(dataset, det_dir, level=level, viewpoint_noise_deg=vp,
                                                    seed=args.seed)
                t0 = time.perf_counter()
                reports = evaluate_dataset(dataset, variants, source=DetectionSource(str(det_dir)),
                                           options=FitOptions(seed=args.seed, calibrate_scores=False), predictions_dir=pred_dir, workers=1,
                                           notify=lambda m: None)
                seconds = time.perf_counter() - t0
                for v, rep in reports.items():
                    m = rep["all"]
                    preds = [read_labels(pred_dir / v / f"{f}.txt") for f in frames]
                    ap3d = kitti_metrics(gts, preds)["iou_0.5"]["car"]["3d"]["moderate"]
                    rows.append({"jitter": level, "viewpoint_noise_deg": vp, "variant": v, "n_cars": n_cars,
                                 "n_tp": m["n_tp"], "n_gt": m["n_gt"], "loc_1m": m["loc_1m"],
                                 "loc_1_5m": m["loc_1_5m"], "kitti_3d_ap_r40_iou05_moderate": ap3d,
                                 "seconds": seconds})
                    print(f"{level:>6.2f} {vp:>8.0f} {v:<10} {m['n_tp']:>4}/{m['n_gt']:<3} {m['loc_1m']:>4.0f}% "
                          f"{m['loc_1_5m']:>5.0f}% {ap3d if ap3d is not None else float('nan'):>13.2f}", flush=True)
    if args.json:
        write_json(args.json, {"frames": len(frames), "seed": args.seed, "rows": rows})


if __name__ == "__main__":
    main()
