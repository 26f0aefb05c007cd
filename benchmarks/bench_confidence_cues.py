"""Cues the confidence could read beyond its five features (issue 29): does any of them rank
the fine variants' estimates better for KITTI's IoU 0.7?

``bench_scores.py`` shows the same estimates ranked perfectly would reach about twice the 3D
AP@0.7 of the shipped confidence, so the ranking, not the boxes, holds most of the gap. Range
along the viewing ray decides IoU 0.7 (``bench_error_budget.py``), and what sets it wrong is
mostly each car's own ground (``bench_plane_height.py``). Each cue below is read from a run's
frame records alone and added to the shipped features
(:data:`wirescene.fitting.confidence.FEATURES`):

* ``box fit``: how far the fitted wireframe's projected extent lies from the 2D box it was
  fitted to, the log of the summed side offsets over the box height (sides at the image's border
  left out);
* ``frame scale``: per frame, the median log ratio of each car's fitted depth to the depth a car
  of KITTI's mean height would have at its box's height: a frame whose plane disagrees with the
  size of all its cars (the plane's height, which no estimate here sees, moves them all);
* ``own scale``: that log ratio of the car itself minus the frame's median;
* ``pitch``: the slope of the frame's fitted bottom heights against their depth;
* ``cars``: the log number of cars the frame holds.

For each fold, a logistic model on each feature set (the shipped five plus a cue, or plus all
of them) is fitted on the other three folds' records of the run's fine variants (``fg+gp`` and
``full`` pooled, as ``wirescene train scores`` pools a stage's variants) and scores this fold's
estimates; KITTI's 3D and BEV AP@0.7 (moderate, R40) per fold group and pooled. With a run on
our own pre-detections the model is fitted on that run's records (its verified cars) and a
last row ranks them by the product of the probability of a car (the fit's verification model,
three features) and the probability of IoU > 0.7 learned from the label-box run's records
(more right estimates to learn from; label boxes all score 1, so the detection score is left
out of it). The cue is chosen on one fold group by the fine variants' 3D AP@0.7 summed over the
runs and read on the other. ::

    python benchmarks/bench_confidence_cues.py RUN_GT [RUN_BANK] --root ../shared/data/kitti

RUN_GT and RUN_BANK are ``bench_real_folds.py`` runs with label boxes and our own
pre-detections (``--detections gt`` / ``bank``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from bench_scores import COLUMNS, group_aps
from wirescene.core.boxes import KITTI_CAR_SIZE
from wirescene.fitting.confidence import FEATURES
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.training.scores import labelled_features

#: The cues of the module docstring, by column of :func:`cue_features`.
CUES = ("box fit", "frame scale", "own scale", "pitch", "cars")
#: Fine variants whose estimates are ranked (and pooled to fit the models).
VARIANTS = ("fg+gp", "full")
#: The feature sets compared: columns of ``record_features`` (the shipped five) plus cue columns.
N_SHIPPED = len(FEATURES)
SETS = {"shipped": []} | {f"+ {c}": [N_SHIPPED + i] for i, c in enumerate(CUES)} | {
    "+ all cues": [N_SHIPPED + i for i in range(len(CUES))]}
PRODUCT = "p(car) x p(right | label-box model)"
#: Names of the columns of :func:`frame_rows`' features.
FEATURE_NAMES = FEATURES + CUES
_MEAN_HEIGHT = KITTI_CAR_SIZE["mean"][2]


def cue_features(result, focal: float) -> np.ndarray:
    """``(D, 5)`` cues of :data:`CUES` for a record's ``D`` fine estimates (``focal``: the
    camera's vertical focal length in pixels)."""
    boxes = np.asarray(result.det_boxes, float).reshape(-1, 4)
    height = np.maximum(boxes[:, 3] - boxes[:, 1], 1.0)
    uv = np.asarray(result.est_vertices_2d, float)
    extent = np.column_stack([uv[..., 0].min(1), uv[..., 1].min(1), uv[..., 0].max(1), uv[..., 1].max(1)])
    W, H = result.image_size
    at_border = np.column_stack([boxes[:, 0] <= 1, np.zeros(len(boxes), bool), boxes[:, 2] >= W - 2,
                                 boxes[:, 3] >= H - 2])
    offset = np.where(at_border, 0.0, np.abs(extent - boxes) / height[:, None])
    depth = np.asarray(result.est_location, float)[:, 2]
    scale = np.log(depth * height / (focal * _MEAN_HEIGHT))
    frame = np.median(scale) if len(scale) else 0.0
    bottom = np.asarray(result.est_location, float)[:, 1]
    pitch = np.polyfit(depth, bottom, 1)[0] if len(depth) > 1 and np.ptp(depth) > 1.0 else 0.0
    ones = np.ones(len(depth))
    return np.column_stack([np.log(offset.sum(1) + 1e-3), frame * ones, scale - frame, pitch * ones,
                            np.log(len(depth)) * ones])


def frame_rows(records: dict, dataset: KittiDataset) -> dict[str, list[tuple]]:
    """``{variant: [(record, (D, 10) features, (D,) right, (D,) on a car), ...]}`` of the
    records' frames with estimates: the shipped features, then :func:`cue_features`; right by
    IoU > 0.7 (the shipped criterion)."""
    out = {}
    for v in VARIANTS:
        rows = []
        for r in records[v]:
            if r.n_detections:
                shipped, right = labelled_features(r, right="iou")
                x = np.column_stack([shipped, cue_features(r, dataset.camera(r.frame_id).P[1, 1])])
                rows.append((r, x, right, labelled_features(r, target="car")[1]))
        out[v] = rows
    return out


def separation(rows: list[tuple]) -> np.ndarray:
    """ROC AUC of each feature column of :func:`frame_rows`' rows (of one variant) for telling
    the estimates that pass IoU 0.7 from the others (0.5: no signal; below: inverted)."""
    from sklearn.metrics import roc_auc_score

    X = np.concatenate([row[1] for row in rows])
    y = np.concatenate([row[2] for row in rows])
    return np.array([roc_auc_score(y, X[:, j]) for j in range(X.shape[1])])


def _logistic(X: np.ndarray, y: np.ndarray):
    """A standardised L2 logistic model (C = 1, as the shipped confidence's) as a function."""
    from sklearn.linear_model import LogisticRegression

    mean, scale = X.mean(axis=0), X.std(axis=0)
    scale = np.where(scale > 1e-9, scale, 1.0)
    model = LogisticRegression(C=1.0).fit((X - mean) / scale, y)
    return lambda Z: model.predict_proba((Z - mean) / scale)[:, 1]


def held_out_scores(rows: dict, columns: list[int], *, target: int = 2, fit_rows: dict | None = None) -> dict:
    """``{variant: {frame: (D,) probabilities}}``: each fold's estimates scored by a model of
    ``columns`` fitted on the other folds of ``fit_rows`` (default ``rows``), all its
    variants pooled; ``target`` 2: right, 3: on a car (tuple fields of :func:`frame_rows`)."""
    fit_rows = rows if fit_rows is None else fit_rows
    out = {v: {} for v in rows}
    for k in range(N_FOLDS):
        train = [row for rs in fit_rows.values() for row in rs if fold_of(row[0].frame_id) != k]
        model = _logistic(np.concatenate([row[1][:, columns] for row in train]),
                          np.concatenate([row[target] for row in train]))
        for v, rs in rows.items():
            for row in rs:
                if fold_of(row[0].frame_id) == k:
                    out[v][row[0].frame_id] = model(row[1][:, columns])
    return out


def product_scores(rows: dict, label_rows: dict) -> dict:
    """:data:`PRODUCT` held out: the car model on the first three shipped features from
    ``rows``, the right model on the shipped features but the detection score from
    ``label_rows`` (each fold's from the other folds)."""
    car = held_out_scores(rows, [0, 1, 2], target=3)
    right = held_out_scores(rows, list(range(1, N_SHIPPED)), fit_rows=label_rows)
    return {v: {f: car[v][f] * right[v][f] for f in car[v]} for v in rows}


def ap_table(rows: dict, scores: dict, gt: dict, groups: dict) -> dict:
    """``{variant: {group: {column: AP}}}`` (moderate, IoU 0.7) of the fine estimates ranked by ``scores``."""
    return {v: group_aps({row[0].frame_id: row[0] for row in rs}, scores[v], gt, groups, COLUMNS[:2])
            for v, rs in rows.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, metavar="RUN", help="label-box run first, then own boxes' if any")
    ap.add_argument("--root", default=str(Path(__file__).resolve().parents[1] / "tests" / "data" / "kitti"))
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    names = [str(g) for g in FOLD_GROUPS]
    chosen_by = {g: {s: 0.0 for s in SETS} for g in names}
    label_rows = None
    for run in args.runs:
        records, detections = read_run(run)
        rows = frame_rows(records, dataset)
        frames = sorted({r.frame_id for rs in records.values() for r in rs})
        gt = {f: dataset.labels(f) for f in frames}
        groups = {str(g): [f for f in frames if fold_of(f) in g] for g in FOLD_GROUPS} | {"pooled": frames}
        n_right = {v: int(sum(row[2].sum() for row in rs)) for v, rs in rows.items()}
        n_est = {v: int(sum(len(row[2]) for row in rs)) for v, rs in rows.items()}
        print(f"\n## {run.name} (detections {detections}): {len(frames)} frames, "
              f"{sum(len(gt[f].of_type('Car')) for f in frames)} cars; estimates passing IoU 0.7: "
              + ", ".join(f"{v} {n_right[v]} of {n_est[v]}" for v in rows) + "\n")
        for v, rs in rows.items():
            print(f"{v}: ROC AUC for passing IoU 0.7, " + ", ".join(
                f"{name} {auc:.2f}" for name, auc in zip(FEATURE_NAMES, separation(rs))))
        print()
        print("| variant | features | " + " | ".join(f"{g}: 3D, BEV @0.7" for g in groups) + " |")
        print("|---|---|" + "---|" * len(groups))
        tables = {name: ap_table(rows, held_out_scores(rows, list(range(N_SHIPPED)) + cols), gt, groups)
                  for name, cols in SETS.items()}
        if label_rows is not None and detections != "gt":
            tables[PRODUCT] = ap_table(rows, product_scores(rows, label_rows), gt, groups)
        for v in rows:
            for name, table in tables.items():
                cells = " | ".join(", ".join("-" if table[v][g][c] is None else f"{table[v][g][c]:.1f}"
                                             for c, _ in COLUMNS[:2]) for g in groups)
                print(f"| {v} | {name} | {cells} |")
                if name in SETS:
                    for g in names:
                        chosen_by[g][name] += table[v][g]["3D 0.7"] or 0.0
        if detections == "gt":
            label_rows = rows
    print()
    for choose, report in (names, names[::-1]):
        best = max(chosen_by[choose], key=chosen_by[choose].get)
        print(f"chosen on {choose} (fine variants' 3D AP@0.7 summed over the runs): {best} "
              f"({chosen_by[choose][best]:.1f}; shipped {chosen_by[choose]['shipped']:.1f}); on {report}: "
              f"{chosen_by[report][best]:.1f} (shipped {chosen_by[report]['shipped']:.1f})")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
