"""Do the written confidences rank? KITTI AP of runs' estimates under different scores,
with the confidence model cross-validated by drive.

Input: runs of ``bench_real_folds.py`` (``RUN/fold{k}/``; a run on our own pre-detections is
verified as its summary does) or ``wirescene eval ... --raw-scores --predictions DIR``
directories::

    python benchmarks/bench_scores.py RUN_GT RUN_BANK --root ../shared/data/kitti

For each fold of :mod:`wirescene.io.folds` the confidence model is fitted on the records
of the other folds and applied to this fold's estimates; the predictions are then scored
with the KITTI rules (:mod:`wirescene.eval.kitti_metrics`), per fold group and pooled, by:
the pre-detection scores as they are (label boxes: all 1), the fit's objective alone
(negated cost), the calibrated confidence of each model of :data:`MODELS` (a criterion
of :data:`wirescene.training.scores.RIGHT_CRITERIA`, when an estimate counts as right, and
a feature set), and the ceiling: the estimates that pass IoU 0.7 ranked first (:data:`PERFECT`).
Estimates are the same in all: only their order differs. Per run, a reliability table
says whether the shipped model's held-out confidence is a probability. Last, the model is
chosen on one fold group by the fine variants' 3D AP at IoU 0.7 summed over the runs, and
read on the other.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import read_run  # noqa: E402
from wirescene.eval.kitti_metrics import kitti_metrics  # noqa: E402
from wirescene.fitting.confidence import FEATURES, MODEL_FEATURES  # noqa: E402
from wirescene.fitting.variants import get_variant  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.training.scores import DEFAULT_RIGHT, cross_validated_confidences, labelled_features  # noqa: E402

#: The confidence models compared: name -> (criterion, features). ``3 features`` are those of
#: the confidence before December 2026 (detection logit, objective, log box height).
MODELS = {"1m, 3 features": ("1m", FEATURES[:3]), "iou, 3 features": ("iou", FEATURES[:3]),
          "1m": ("1m", FEATURES), "iou": ("iou", FEATURES)}
#: The model of :data:`MODELS` that ``wirescene train scores`` fits by default.
SHIPPED = next(name for name, model in MODELS.items() if model == (DEFAULT_RIGHT, MODEL_FEATURES["right"]))
#: The scores that rank every estimate passing KITTI's IoU 0.7 above every other: what no confidence can beat.
PERFECT = "perfect ranking (IoU 0.7; ceiling)"
#: (name, KITTI metrics path) of the APs printed, moderate.
COLUMNS = (("3D 0.7", ("car", "3d")), ("BEV 0.7", ("car", "bev")), ("3D 0.5", ("iou_0.5", "car", "3d")))


def _ap(metrics: dict, path) -> float | None:
    for key in path:
        metrics = metrics[key]
    return metrics["moderate"]


def group_aps(by_frame: dict, scores: dict, gt: dict, groups: dict, columns=COLUMNS) -> dict:
    """``{group: {column: AP}}`` (moderate) of the records ``by_frame`` (frame -> record)
    ranked by ``scores`` (frame -> ``(D,)``), for ``groups`` (name -> frames) and the
    ``columns`` of :data:`COLUMNS`; a frame without a record counts its labels alone."""
    return {g: {c: _ap(kitti_metrics([gt[f] for f in fs],
                                     [by_frame[f].estimate_labels(scores[f]) if f in by_frame else [] for f in fs]), p)
                for c, p in columns} for g, fs in groups.items()}


def _calibrated(model: str) -> str:
    """The name of a model of :data:`MODELS` among the scores."""
    return f"calibrated ({model})"


def score_table(records: dict, gt: dict) -> tuple[dict, dict]:
    """``{(variant, scores): {group: {column: AP}}}`` for the groups of
    :data:`FOLD_GROUPS` and ``"pooled"``, and ``{variant: {frame: (D,) confidences}}``
    of the :data:`SHIPPED` model."""
    frames = sorted({r.frame_id for rs in records.values() for r in rs})
    folds = {f: fold_of(f) for f in frames}
    groups = {str(g): [f for f in frames if folds[f] in g] for g in FOLD_GROUPS} | {"pooled": frames}
    table, shipped = {}, {}
    for variant, results in records.items():
        by_frame = {r.frame_id: r for r in results}
        scores = {"detection": {f: by_frame[f].det_scores for f in frames},
                  "objective": {f: -np.asarray(by_frame[f].est_cost, float) for f in frames}}
        for name, (right, features) in MODELS.items():
            scores[_calibrated(name)] = cross_validated_confidences(records, folds, variant, right=right,
                                                                    features=features)
        shipped[variant] = scores[_calibrated(SHIPPED)]
        # the ceiling of any confidence: the estimates that pass IoU 0.7 ranked first
        scores[PERFECT] = {f: labelled_features(by_frame[f], right="iou")[1].astype(float) if by_frame[f].n_detections
                           else np.zeros(0) for f in frames}
        for name, of in scores.items():
            table[(variant, name)] = group_aps(by_frame, of, gt, groups)
    return table, shipped


#: Edges of the confidence bins of the reliability table.
RELIABILITY_BINS = (0.0, 0.1, 0.2, 0.3, 0.5, 0.7, 1.0)


def reliability(records: dict, confidences: dict, *, fine: bool) -> list[tuple[float, float, int, float, float]]:
    """Is the shipped model's confidence a probability? Per bin of :data:`RELIABILITY_BINS`
    ``(low, high, cars, mean confidence, share right)`` of the held-out ``confidences``
    (``{variant: {frame: (D,)}}``, :func:`score_table`) of the fine (or coarse) variants'
    estimates, pooled, right by the shipped criterion."""
    p, y = [], []
    for variant, results in records.items():
        if get_variant(variant).fine != fine:
            continue
        conf = confidences[variant]
        for r in results:
            if r.n_detections:
                p.append(conf[r.frame_id])
                y.append(labelled_features(r)[1])
    p, y = np.concatenate(p), np.concatenate(y)
    edges = np.asarray(RELIABILITY_BINS)
    which = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, len(edges) - 2)
    return [(edges[b], edges[b + 1], int(np.sum(which == b)), float(np.mean(p[which == b])),
             float(np.mean(y[which == b]))) for b in range(len(edges) - 1) if np.any(which == b)]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, metavar="RUN")
    ap.add_argument("--root", default=str(Path(__file__).resolve().parents[1] / "tests" / "data" / "kitti"))
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    groups = [str(g) for g in FOLD_GROUPS]
    chosen_by = {g: {m: 0.0 for m in MODELS} for g in groups}
    for run in args.runs:
        records, detections = read_run(run)
        frames = sorted({r.frame_id for rs in records.values() for r in rs})
        gt = {f: dataset.labels(f) for f in frames}
        n_cars = sum(len(gt[f].of_type("Car")) for f in frames)
        print(f"\n## {run.name} (detections {detections}): {len(frames)} frames, {n_cars} cars; AP moderate, "
              "KITTI rules, R40\n")
        print("| variant | scores | " + " | ".join(f"{g}: {', '.join(c for c, _ in COLUMNS)}"
                                                   for g in groups + ["pooled"]) + " |")
        print("|---|---|" + "---|" * (len(groups) + 1))
        table, shipped = score_table(records, gt)
        for (variant, name), row in table.items():
            cells = " | ".join(", ".join("-" if row[g][c] is None else f"{row[g][c]:.1f}" for c, _ in COLUMNS)
                               for g in groups + ["pooled"])
            print(f"| {variant} | {name} | {cells} |")
        for variant in records:
            if get_variant(variant).fine:
                for model in MODELS:
                    for g in groups:
                        chosen_by[g][model] += table[(variant, _calibrated(model))][g]["3D 0.7"] or 0.0
        for fine in (False, True):
            bins = "; ".join(f"{lo:.1f}-{hi:.1f}: {n} cars, {100 * m:.0f}% predicted, {100 * o:.0f}% right"
                             for lo, hi, n, m, o in reliability(records, shipped, fine=fine))
            print(f"\nreliability of the shipped model, held out, {'fine' if fine else 'coarse'} variants pooled: {bins}")
    print()
    for choose, report in (groups, groups[::-1]):
        best = max(chosen_by[choose], key=chosen_by[choose].get)
        sums = ", ".join(f"{r} {v:.1f}" for r, v in chosen_by[choose].items())
        held = ", ".join(f"{r} {v:.1f}" for r, v in chosen_by[report].items())
        print(f"chosen on {choose} (fine variants' 3D AP@0.7 summed: {sums}): {best}; on {report}: {held}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
