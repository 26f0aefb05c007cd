"""The pre-detection threshold as the fit sees it: the paper's protocol and the false 3D cars as it moves.

Reads ``bench_real_folds.py --detections bank`` runs made with fold banks whose stored
threshold differs (e.g. copies of the fold banks with ``DetectorBank.threshold`` set to
0.2, 0.3, 0.5), and reports per fold group and pooled, per variant: the true-positive
initialisations (the paper's TP/GT: box on a car and viewpoint within 45 deg), the share of
them and the number of cars placed within 1 m, the cars fitted and the false ones (whose
pre-detection overlaps no labelled car at IoU 0.5, or one already taken: each is a 3D car
in the output that is not there).

    python benchmarks/bench_operating_point.py NAME=RUN [NAME=RUN ...] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.eval.metrics import evaluate
from wirescene.io.folds import FOLD_GROUPS, fold_of


def on_car(result) -> np.ndarray:
    """``(D,)`` bool: which fitted cars of a frame have the first pre-detection, in score
    order, to overlap a ``Car`` label at IoU >= 0.5."""
    from wirescene.training.kitti_detector import detection_labels

    order = np.argsort(-np.asarray(result.det_scores, float), kind="stable")
    cars = np.array([g.box for g in result.gt if g.type == "Car"], float).reshape(-1, 4)
    out = np.zeros(len(order), bool)
    if len(order):
        out[order] = detection_labels(np.asarray(result.det_boxes)[order], cars)
    return out


def false_cars(result) -> int:
    """Fitted cars of a frame that are not :func:`on_car` (a second box on a car counts too)."""
    return int((~on_car(result)).sum())


def figures(results) -> dict:
    """Paper-protocol figures of a list of FrameResult, with the false cars."""
    m = evaluate(results).metrics["all"]
    n_tp, n_gt = int(m["n_tp"]), int(m["n_gt"])
    within = 0 if m["loc_1m"] is None else round(m["loc_1m"] * n_tp / 100)
    return {"tp": n_tp, "gt": n_gt, "loc_1m": m["loc_1m"], "cars_within_1m": within,
            "fitted": int(sum(len(r.det_boxes) for r in results)), "false_cars": sum(map(false_cars, results))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="NAME=RUN_DIR (bench_real_folds.py --out, --detections bank)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    out = {}
    for item in args.runs:
        name, _, run = item.partition("=")
        records, _ = read_run(Path(run))
        out[name] = {}
        for variant, results in records.items():
            row = {str(g): figures([r for r in results if fold_of(r.frame_id) in g]) for g in FOLD_GROUPS}
            row["pooled"] = figures(results)
            out[name][variant] = row
            print(f"{name:6s} {variant:10s} " + " | ".join(
                f"{k}: TP {v['tp']}/{v['gt']}, {v['loc_1m']:.1f}% <1 m = {v['cars_within_1m']} cars, "
                f"{v['false_cars']} false of {v['fitted']} fitted" for k, v in row.items()))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
