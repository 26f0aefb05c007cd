"""Do the written confidences rank? KITTI AP of one evaluation run's estimates under
different scores, with the confidence model cross-validated by drive.

Input: an evaluation run on labelled real frames with raw scores and frame records::

    wirescene eval ../shared/data/kitti --variant coarse+gp --variant full --raw-scores \\
        --seed 1 --predictions RUN_DIR
    python benchmarks/bench_scores.py RUN_DIR --root ../shared/data/kitti

For each fold of :mod:`wirescene.io.folds` the confidence model is fitted on the records
of the other folds and applied to this fold's estimates; the pooled predictions are then
scored with the KITTI rules (:mod:`wirescene.eval.kitti_metrics`) three ways: the
pre-detection scores as they are (label boxes: all 1), the fit's objective alone
(negated cost), and the calibrated confidence. Estimates are the same in all three:
only their order differs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wirescene.eval.kitti_metrics import kitti_metrics
from wirescene.io.folds import N_FOLDS, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.training.scores import cross_validated_confidences, read_run_records


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--root", default=str(Path(__file__).resolve().parents[1] / "tests" / "data" / "kitti"))
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    records = read_run_records(args.run_dir)
    frames = sorted({r.frame_id for rs in records.values() for r in rs})
    folds = {f: fold_of(f) for f in frames}
    gt = {f: dataset.labels(f) for f in frames}
    n_cars = sum(len(gt[f].of_type("Car")) for f in frames)
    print(f"{len(frames)} frames, {n_cars} cars, {N_FOLDS} folds by drive; AP in % (KITTI rules, R40)")
    print(f"{'variant':10s} {'scores':12s} {'3D mod 0.7':>10s} {'3D mod 0.5':>10s} {'BEV mod 0.5':>11s} {'2D mod':>7s}")
    for variant, results in records.items():
        by_frame = {r.frame_id: r for r in results}
        calibrated = cross_validated_confidences(records, folds, variant)
        for name, scores_of in (("detection", lambda f, by_frame=by_frame: by_frame[f].det_scores),
                                ("objective", lambda f, by_frame=by_frame: -by_frame[f].est_cost),
                                ("calibrated", lambda f, calibrated=calibrated: calibrated[f])):
            preds = [by_frame[f].estimate_labels(scores_of(f)) for f in frames]
            m = kitti_metrics([gt[f] for f in frames], preds)

            def fmt(v):
                return "-" if v is None else f"{v:.1f}"

            print(f"{variant:10s} {name:12s} {fmt(m['car']['3d']['moderate']):>10s} "
                  f"{fmt(m['iou_0.5']['car']['3d']['moderate']):>10s} {fmt(m['iou_0.5']['car']['bev']['moderate']):>11s} "
                  f"{fmt(m['car']['2d']['moderate']):>7s}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
