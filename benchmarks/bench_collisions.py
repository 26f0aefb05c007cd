"""Two fitted cars cannot stand in one place: a suppression on the ground plane, read off the records.

Reads ``bench_real_folds.py --detections bank`` runs (our own pre-detections, each frame fitted
by models trained without its drive; the fit's verification applied held out, as the runs'
summaries do) and, per variant, takes each frame's fitted cars by decreasing held-out
confidence (each fold's from a model of the other folds' records), dropping a car whose
bird's-eye footprint overlaps a kept one's at IoU >= ``--iou``. Reported per fold group and
pooled, before and after: the paper's true-positive initialisations, the cars within 1 m
and the false 3D cars (``bench_operating_point.py``'s), and KITTI's moderate APs (R40) with
the same held-out confidences, refitted on the suppressed records. Also: how many fitted
cars overlap another at all, by how much.

    python benchmarks/bench_collisions.py RUN [RUN ...] --root ../shared/data/kitti [--iou 0.25] [--variant full]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from bench_operating_point import figures
from bench_real_folds import cv_predictions
from wirescene.eval.kitti_metrics import iou_bev, kitti_figure, kitti_metrics
from wirescene.io.folds import FOLD_GROUPS, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.training.scores import cross_validated_confidences

APS = (("car", "3d", "3D@0.7"), ("car", "bev", "BEV@0.7"), ("car", "2d", "2D@0.7"), ("iou_0.5", "3d", "3D@0.5"))


def footprint_overlaps(result) -> np.ndarray:
    """``(D, D)`` bird's-eye IoU of a frame's fitted cars with each other (0 on the diagonal)."""
    n = len(result.det_boxes)
    i, j = np.triu_indices(n, 1)
    out = np.zeros((n, n))
    if len(i):
        loc, dims, ry = (np.asarray(a, float) for a in (result.est_location, result.est_dims, result.est_rotation_y))
        out[i, j] = out[j, i] = iou_bev(loc[i], dims[i], ry[i], loc[j], dims[j], ry[j])
    return out


def kept_apart(overlaps: np.ndarray, scores: np.ndarray, *, iou: float) -> np.ndarray:
    """``(D,)`` bool: greedy by decreasing ``scores``, a car is kept unless its footprint
    overlaps an already kept car's at ``iou`` or more."""
    keep = np.zeros(len(scores), bool)
    for d in np.argsort(-np.asarray(scores, float), kind="stable"):
        keep[d] = not (overlaps[d, keep] >= iou).any()
    return keep


def suppressed(records: dict, folds: dict, *, iou: float) -> tuple[dict, dict]:
    """``(records without the suppressed cars, {variant: [overlap of every car with its most overlapping
    neighbour]})``."""
    out, worst = {}, {}
    for variant, results in records.items():
        scores = cross_validated_confidences(records, folds, variant)
        out[variant], worst[variant] = [], []
        for r in results:
            ov = footprint_overlaps(r)
            worst[variant].extend(ov.max(1) if len(ov) else [])
            out[variant].append(r.subset(kept_apart(ov, scores[r.frame_id], iou=iou)))
    return out, worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, help="bench_real_folds.py --detections bank runs")
    ap.add_argument("--root", required=True)
    ap.add_argument("--iou", type=float, default=0.25, help="footprint IoU at which the less confident car goes")
    ap.add_argument("--variant", dest="variants", action="append", help="default: every variant of the runs")
    args = ap.parse_args()
    ds = KittiDataset(args.root)
    for run in args.runs:
        records, spec = read_run(run)  # every variant: the confidences pool the run's fine variants
        folds = {r.frame_id: fold_of(r.frame_id) for rs in records.values() for r in rs}
        after, worst = suppressed(records, folds, iou=args.iou)
        frames = sorted(folds)
        gts = [ds.labels(f) for f in frames]
        preds = {"before": cv_predictions(records, frames, folds), "after": cv_predictions(after, frames, folds)}
        print(f"{run} (detections: {spec}), footprint IoU >= {args.iou:g} suppressed")
        for variant in args.variants or records:
            w = np.asarray(worst[variant])
            print(f"  {variant}: {len(w)} fitted cars, overlapping another at IoU > 0: {int((w > 0).sum())}, "
                  f">= 0.1: {int((w >= 0.1).sum())}, >= 0.25: {int((w >= 0.25).sum())}, >= 0.5: {int((w >= 0.5).sum())}")
            for name, recs in (("before", records), ("after", after)):
                rows = {str(g): figures([r for r in recs[variant] if fold_of(r.frame_id) in g]) for g in FOLD_GROUPS}
                rows["pooled"] = figures(recs[variant])
                metrics = kitti_metrics(gts, preds[name][variant])
                aps = ", ".join(f"{label} {kitti_figure(metrics, block, metric)['moderate']:.1f}"
                                for block, metric, label in APS)
                print(f"    {name:6s} " + " | ".join(
                    f"{k}: TP {v['tp']}, {v['cars_within_1m']} <1 m, {v['false_cars']} false of {v['fitted']}"
                    for k, v in rows.items()) + f" | AP {aps}")


if __name__ == "__main__":
    main()
