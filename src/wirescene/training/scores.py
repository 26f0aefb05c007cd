"""Fitting the confidence model of :mod:`wirescene.fitting.confidence` from the frame
records of an evaluation run on labelled real frames (``wirescene eval ...
--predictions DIR --raw-scores`` writes them to ``DIR/.frames``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable

import numpy as np

from wirescene.core.boxes import box_centers
from wirescene.core.errors import InputError
from wirescene.core.groundplane import rotation_y
from wirescene.core.labels import CAR_TYPES, is_type
from wirescene.core.matching import match_detections
from wirescene.eval.kitti_metrics import iou_3d
from wirescene.eval.metrics import FrameResult
from wirescene.eval.records import RECORDS_DIR
from wirescene.fitting.confidence import (
    FEATURES,
    MODEL_FEATURES,
    STAGES,
    calibrated_confidence,
    confidence_features,
)
from wirescene.fitting.variants import get_variant

#: When the confidence calls an estimate right (its detection matches a ``Car`` at 2D IoU >
#: 0.5, greedy by score, and ...): ``"iou"`` its 3D box overlaps the car's at IoU > 0.7
#: (KITTI's rule for cars; the default, chosen held out by drive: ``benchmarks/RESULTS.md``),
#: ``"1m"`` its 3D centre lies within 1 m of the car's (the paper's).
RIGHT_CRITERIA = {"iou": "detection IoU > 0.5 with a Car and 3D box IoU > 0.7 with it",
                  "1m": "detection IoU > 0.5 with a Car and 3D centre within 1 m"}
DEFAULT_RIGHT = "iou"
_MIN_IOU, _MAX_ERROR_M = 0.7, 1.0


def record_features(result: FrameResult) -> np.ndarray:
    """``(D, 5)`` :func:`~wirescene.fitting.confidence.confidence_features` of a record's
    estimates."""
    if result.image_size is None:
        raise InputError(f"record of frame {result.frame_id} has no image size (written by an older wirescene: "
                         "evaluate again)", path=None)
    return confidence_features(result.det_scores, result.est_cost, result.det_boxes, image_width=result.image_size[0])


def labelled_features(result: FrameResult, *, target: str = "right",
                      right: str = DEFAULT_RIGHT) -> tuple[np.ndarray, np.ndarray]:
    """Features ``(D, 5)`` of a frame's estimates (:func:`record_features`) and whether
    each is right by the criterion ``right`` of :data:`RIGHT_CRITERIA`; with
    ``target="car"``, whether its detection matches a car at all (IoU > 0.5, greedy by
    score)."""
    if result.est_cost is None:
        raise ValueError(f"record of frame {result.frame_id} has no fit objective (est_cost)")
    if right not in RIGHT_CRITERIA:
        raise ValueError(f"unknown criterion {right!r}; known: {sorted(RIGHT_CRITERIA)}")
    feats = record_features(result)
    cars = [g for g in result.gt if is_type(g.type, CAR_TYPES)]
    gt_boxes = np.array([g.box for g in cars]).reshape(-1, 4)
    match, _ = match_detections(result.det_boxes, result.det_scores, gt_boxes)
    if target == "car":
        return feats, match >= 0
    d = np.flatnonzero(match >= 0)
    matched = [cars[m] for m in match[d]]
    location, dims = result.est_location[d], result.est_dims[d]
    rot = np.asarray(result.est_rotation_y, float)[d]
    g_location = np.array([g.location for g in matched], float).reshape(-1, 3)
    g_dims = np.array([g.dims for g in matched], float).reshape(-1, 3)
    g_rot = np.array([g.rotation_y for g in matched], float)
    if right == "iou":
        ok = iou_3d(location, dims, rot, g_location, g_dims, g_rot) > _MIN_IOU
    else:  # the evaluation's localisation error: between the boxes' centroids
        error = box_centers(dims, location, rotation_y(rot)) - box_centers(g_dims, g_location, rotation_y(g_rot))
        ok = np.linalg.norm(error, axis=-1) < _MAX_ERROR_M
    out = np.zeros(len(feats), bool)
    out[d] = ok
    return feats, out


def read_run_sources(predictions_dir, frames: Iterable[str] | None = None) -> dict[str, dict[str, list[FrameResult]]]:
    """``{"labels" | "detections": {variant: [FrameResult, ...]}}`` from
    ``predictions_dir/.frames/*.json``, by whether the run's pre-detections were the label
    boxes or a detector's (ours, or files of another); each file read once."""
    folder = Path(predictions_dir) / RECORDS_DIR
    paths = sorted(folder.glob("*.json"))
    if frames is not None:
        keep = set(frames)
        paths = [p for p in paths if p.stem in keep]
    if not paths:
        raise InputError("no frame records (run `wirescene eval ... --predictions DIR` first)", path=folder)
    out: dict[str, dict[str, list[FrameResult]]] = {"labels": {}, "detections": {}}
    for path in paths:
        try:
            record = json.loads(path.read_text())
            if not isinstance(record, dict):
                raise TypeError(f"a JSON {type(record).__name__}, not an object")
            gt = record.get("config", {}).get("detections", {}).get("spec") == "gt"
            for variant, entry in record["variants"].items():
                out["labels" if gt else "detections"].setdefault(variant, []).append(
                    FrameResult.from_dict(entry["result"]))
        except KeyError as exc:  # its str() is the bare key: "unreadable frame record ('variants')"
            raise InputError(f"unreadable frame record (no {str(exc.args[0])[:40]!r} entry)", path=path) from None
        except (OSError, ValueError, TypeError, AttributeError) as exc:  # AttributeError: a part not an object
            raise InputError(f"unreadable frame record ({' '.join(str(exc).split())[:100]})", path=path) from None
    return out


def read_run_records(predictions_dir, frames: Iterable[str] | None = None) -> dict[str, list[FrameResult]]:
    """``{variant: [FrameResult, ...]}`` from ``predictions_dir/.frames/*.json``
    (:func:`read_run_sources`, both sources)."""
    out: dict[str, list[FrameResult]] = {}
    for by_variant in read_run_sources(predictions_dir, frames).values():
        for variant, results in by_variant.items():
            out.setdefault(variant, []).extend(results)
    return out


def _fit_stages(records: dict[str, list[FrameResult]], *, C: float, stages: tuple[str, ...], target: str,
                right: str = DEFAULT_RIGHT, features: tuple[str, ...] | None = None) -> dict:
    """One logistic model per stage of ``stages`` on the records' estimates, reading
    ``features`` (default: ``MODEL_FEATURES[target]``)."""
    names = tuple(MODEL_FEATURES[target] if features is None else features)
    from sklearn.linear_model import LogisticRegression

    data = {stage: ([], []) for stage in STAGES}
    for variant, results in records.items():
        stage = "fine" if get_variant(variant).fine else "coarse"
        for r in results:
            if r.n_detections:
                x, y = labelled_features(r, target=target, right=right)
                data[stage][0].append(x)
                data[stage][1].append(y)
    out = {}
    for stage in stages:
        xs, ys = data[stage]
        if not xs:
            raise InputError(f"no {stage} variant in the records: evaluate at least one coarse and one fine variant",
                             path=None)
        columns = [FEATURES.index(f) for f in names]
        X, y = np.concatenate(xs)[:, columns], np.concatenate(ys)
        if y.all() or not y.any():
            what = {"right": ("right", "wrong"), "car": ("on a car", "off every car")}[target]
            raise InputError(f"{stage} estimates are all {what[0] if y.all() else what[1]}: nothing to calibrate")
        mean, scale = X.mean(axis=0), X.std(axis=0)
        scale = np.where(scale > 1e-9, scale, 1.0)
        model = LogisticRegression(C=C).fit((X - mean) / scale, y)
        out[stage] = {"features": list(names), "mean": mean.tolist(), "scale": scale.tolist(),
                      "weights": model.coef_[0].tolist(),
                      "bias": float(model.intercept_[0]), "n": int(len(y)), "positive_rate": float(y.mean())}
    return out


def fit_score_calibration(records: dict[str, list[FrameResult]], *, C: float = 1.0,
                          stages: tuple[str, ...] = STAGES,
                          car_records: dict[str, list[FrameResult]] | None = None,
                          right: str = DEFAULT_RIGHT) -> dict:
    """A logistic model per stage (coarse / fine variants) on the records' estimates,
    right by the criterion ``right`` of :data:`RIGHT_CRITERIA`; every stage of ``stages``
    needs records. With ``car_records`` (runs on our own pre-detections: label boxes are
    all cars), also the ``"car"`` models."""
    if right not in RIGHT_CRITERIA:
        raise ValueError(f"unknown criterion {right!r}; known: {sorted(RIGHT_CRITERIA)}")
    out = {"features": list(FEATURES), "criterion": RIGHT_CRITERIA[right], "right": right}
    out.update(_fit_stages(records, C=C, stages=stages, target="right", right=right))
    if car_records is not None:
        out["car"] = {"criterion": "detection IoU > 0.5 with a Car (greedy by score)",
                      **_fit_stages(car_records, C=C, stages=stages, target="car")}
    return out


def cross_validated_confidences(records: dict[str, list[FrameResult]], folds: dict[str, int],
                                variant: str, *, target: str = "right", right: str = DEFAULT_RIGHT,
                                features: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """``{frame: (D,) confidences}`` of ``variant``'s estimates, each fold's from a model
    fitted on the records of the other folds only (``folds``: frame -> fold); ``target``
    as in :func:`wirescene.fitting.confidence.calibrated_confidence`, ``right`` as in
    :func:`labelled_features`, ``features`` the model's (default: the shipped ones,
    ``MODEL_FEATURES[target]``)."""
    fine = get_variant(variant).fine
    out = {}
    for k in sorted(set(folds.values())):
        test = [r for r in records[variant] if folds[r.frame_id] == k]
        if not test:
            continue
        model = _fit_stages({v: [r for r in rs if folds[r.frame_id] != k] for v, rs in records.items()}, C=1.0,
                            stages=("fine",) if fine else ("coarse",), target=target, right=right, features=features)
        calibration = model if target == "right" else {target: model}
        for r in test:
            feats = record_features(r)
            out[r.frame_id] = (calibrated_confidence(feats, fine=fine, calibration=calibration, target=target)
                               if len(feats) else np.zeros(0))
    return out


def cross_validated_car_filter(records: dict[str, list[FrameResult]], folds: dict[str, int], *,
                               min_probability: float) -> dict[str, list[FrameResult]]:
    """The records of a run on our own pre-detections with the fit's verification
    (:func:`wirescene.fitting.confidence.keep_likely_cars`) applied held out: each fold's
    fitted cars scored by a car model fitted on the records of the other folds only
    (``folds``: frame -> fold, :func:`cross_validated_confidences`), those below
    ``min_probability`` left out (0 keeps every car)."""
    if min_probability <= 0:
        return records
    out: dict[str, list[FrameResult]] = {}
    for variant, results in records.items():
        p = cross_validated_confidences(records, folds, variant, target="car")
        out[variant] = [r.subset(p[r.frame_id] >= min_probability) for r in results]
    return out
