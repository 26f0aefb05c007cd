"""Rescoring our own pre-detections by the fit: does the fitted car's objective tell cars from false boxes?

Reads ``bench_real_folds.py --detections bank`` runs (their frame records keep each fitted
car's objective, ``est_cost``) and asks, per variant, how well a logistic model of the
features of the shipped confidence (:func:`wirescene.fitting.confidence.confidence_features`:
the detection's logit, the fit's objective, the log box height) predicts that a fitted car
stands on a labelled car (its box the first in score order to overlap a ``Car`` label at
IoU >= 0.5; the rest are the false 3D cars of ``bench_operating_point.py``). The model,
the car model of ``wirescene train scores`` fitted on the variant's own records, is
fitted on one fold group and applied to the other, both ways (:data:`FOLD_GROUPS`); the
cars it scores below ``tau`` are dropped, and the paper-protocol figures (true-positive
initialisations, cars within 1 m) and the false cars are reported for each ``tau``, with
the ROC AUC of each feature alone.

With ``--calibration FILE`` (e.g. the shipped ``score_calibration.json``), also the share of
each variant's fitted cars on which that file's car model decides as the run's own held-out
verification does (p(car) >= 0.5 both, or below it both; each fold's cars by a car model
fitted on the other folds' records of the run's variants of its stage, as ``bench_real_folds.py``
verifies them): how near a calibration fitted on other runs is to the held-out figures.

    python benchmarks/bench_car_filter.py NAME=RUN [NAME=RUN ...] [--variant full] [--tau 0.3 0.5 0.7]
        [--calibration FILE ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from sklearn.metrics import roc_auc_score

from _common import VERIFICATION_FILE, read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from bench_operating_point import false_cars, figures, on_car
from wirescene.fitting.confidence import FEATURES, MODEL_FEATURES, calibrated_confidence, load_score_calibration
from wirescene.fitting.variants import get_variant
from wirescene.io.folds import FOLD_GROUPS, fold_of
from wirescene.training.scores import cross_validated_confidences, record_features

#: The car model's features (:data:`MODEL_FEATURES`), as columns of the confidence's.
CAR_COLUMNS = [FEATURES.index(f) for f in MODEL_FEATURES["car"]]


def features(results) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per frame, the car model's features ``(D, 3)`` and the on-car labels ``(D,)``."""
    return [record_features(r)[:, CAR_COLUMNS] for r in results], [on_car(r) for r in results]


def cross_group_probabilities(variant: str, results) -> list[np.ndarray]:
    """Per frame, the probability that each fitted car is on a car, from the car model of
    ``wirescene train scores`` fitted on this variant's records of the other fold group."""
    group = {r.frame_id: next(i for i, g in enumerate(FOLD_GROUPS) if fold_of(r.frame_id) in g) for r in results}
    p = cross_validated_confidences({variant: results}, group, variant, target="car")
    return [p[r.frame_id] for r in results]


def agreement(records: dict, calibration: dict, *, min_probability: float = 0.5) -> dict:
    """``{variant: (agreeing, fitted)}``: the fitted cars on which the car model of
    ``calibration`` and the run's held-out car models (each fold's fitted on the other folds'
    records of the run's variants of its stage, coarse or fine) fall on the same side of ``min_probability``."""
    folds = {r.frame_id: fold_of(r.frame_id) for rs in records.values() for r in rs}
    out = {}
    for variant, results in records.items():
        held = cross_validated_confidences(records, folds, variant, target="car")
        fine = get_variant(variant).fine
        same = [(held[r.frame_id] >= min_probability)
                == (calibrated_confidence(record_features(r), fine=fine, calibration=calibration, target="car")
                    >= min_probability) for r in results if len(r.det_boxes)]
        out[variant] = (int(sum(s.sum() for s in same)), sum(len(s) for s in same))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="NAME=RUN_DIR (bench_real_folds.py --out, --detections bank)")
    ap.add_argument("--variant", action="append", default=None, help="variants to report (default: all in the run)")
    ap.add_argument("--tau", type=float, nargs="+", default=[0.3, 0.5, 0.7])
    ap.add_argument("--calibration", type=Path, nargs="+", default=[],
                    help="score calibrations whose car model to compare with the run's held-out verification")
    args = ap.parse_args()
    for item in args.runs:
        name, _, run = item.partition("=")
        records, _ = read_run(Path(run), verified=False)
        verification = Path(run) / VERIFICATION_FILE
        verified_at = json.loads(verification.read_text())["min_car_probability"] if verification.is_file() else 0.5
        for path in args.calibration:
            agree = agreement(records, load_score_calibration(path), min_probability=verified_at)
            print(f"{name}: {path} decides as the held-out car models on " + ", ".join(
                f"{v} {a}/{n} ({100 * a / max(n, 1):.1f}%)" for v, (a, n) in agree.items()))
        for variant, results in records.items():
            if args.variant and variant not in args.variant:
                continue
            if any(r.est_cost is None for r in results):
                raise SystemExit(f"{run}: {variant} records have no fit objective (est_cost)")
            X, y = features(results)
            Xa, ya = np.concatenate(X), np.concatenate(y)
            auc = ", ".join(f"{f} {roc_auc_score(ya, s * Xa[:, j]):.3f}"
                            for j, (f, s) in enumerate(zip(MODEL_FEATURES["car"], (1, -1, 1))))
            prob = cross_group_probabilities(variant, results)
            print(f"{name} {variant}: {len(ya)} fitted cars, {int(ya.sum())} on a car; ROC AUC {auc}, "
                  f"cross-group model {roc_auc_score(ya, np.concatenate(prob)):.3f}")
            for tau in [None] + list(args.tau):
                kept = results if tau is None else [r.subset(p >= tau) for r, p in zip(results, prob)]
                cells = []
                for g in FOLD_GROUPS + ("pooled",):
                    sub = kept if g == "pooled" else [r for r in kept if fold_of(r.frame_id) in g]
                    f = figures(sub)
                    cells.append(f"{g}: TP {f['tp']}/{f['gt']}, {f['cars_within_1m']} <1 m, "
                                 f"{sum(map(false_cars, sub))} false")
                print(f"    {'all' if tau is None else f'p >= {tau:g}':9s} " + " | ".join(cells))


if __name__ == "__main__":
    main()
