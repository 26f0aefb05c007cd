"""The confidence written with every car: a calibrated probability that the estimate is
right, from the pre-detection's score and the fit itself, so that ranking metrics (KITTI
AP) mean something.

A logistic model per stage (``coarse`` variants, whose objective is the lifting cost, and
``fine`` ones, whose objective is the negative part likelihood) on three features:

* the detection score as a logit (scores are read as probabilities, as our bank's
  are; scores outside (0, 1) saturate),
* the fit's objective for the car (``ObjectEstimate.cost``, lower is better),
* the log height of the 2D box (far, small cars are harder to place in depth).

"Right" is the paper's criterion: the pre-detection matches a ground-truth car (IoU >
0.5) and the estimated 3D centre lies within 1 m of it. A second model per stage, on the
same features, gives the probability that the fitted car stands on a car at all (its
pre-detection matches one): the fit's verification of our own pre-detections
(:func:`keep_likely_cars`), since a box that is not a car fits the part evidence badly.
The weights are fitted by ``wirescene train scores`` (:mod:`wirescene.training.scores`) on
evaluation records of labelled real frames and stored in ``data/score_calibration.json``.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from wirescene.core.artefacts import load_json, save_json
from wirescene.core.errors import InputError
from wirescene.core.resources import DATA_DIR
from wirescene.core.types import SceneEstimate

DEFAULT_PATH = DATA_DIR / "score_calibration.json"
ARTEFACT_KIND = "score-calibration"
FORMAT_VERSION = 2
FEATURES = ("detection_logit", "objective", "log_box_height")
STAGES = ("coarse", "fine")
#: What the models predict: ``right`` (the confidence; stored per stage at the top level)
#: and ``car`` (stored per stage under ``"car"``).
TARGETS = ("right", "car")


def confidence_features(detection_scores, costs, boxes) -> np.ndarray:
    """``(N, 3)`` features of :data:`FEATURES` for ``N`` cars."""
    s = np.clip(np.asarray(detection_scores, float), 1e-3, 1 - 1e-3)
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    height = np.maximum(boxes[:, 3] - boxes[:, 1], 1.0)
    return np.stack([np.log(s / (1 - s)), np.asarray(costs, float), np.log(height)], axis=1)


def save_score_calibration(path: str | Path, record: dict) -> Path:
    """Write a calibration (``{"coarse": {...}, "fine": {...}, ...}``) as loaded below."""
    return save_json(path, record, kind=ARTEFACT_KIND, version=FORMAT_VERSION)


@lru_cache(maxsize=8)
def load_score_calibration(path: str | Path | None = None) -> dict:
    """The calibration: per stage ``mean`` and ``scale`` (feature standardisation),
    ``weights`` and ``bias`` of the logistic model, for each of :data:`TARGETS`."""
    path = DEFAULT_PATH if path is None else Path(path)
    record = load_json(path, kind=ARTEFACT_KIND, version=FORMAT_VERSION)
    try:
        for target in TARGETS:
            for stage in STAGES:
                _check_model(_model(record, stage, target))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed score calibration ({exc})", path=path) from None
    return record


def _model(calibration: dict, stage: str, target: str) -> dict:
    return calibration[stage] if target == "right" else calibration[target][stage]


def _check_model(m: dict) -> None:
    for key in ("mean", "scale", "weights"):
        if len(m[key]) != len(FEATURES) or not np.all(np.isfinite(m[key])):
            raise ValueError(key)
    if not np.isfinite(float(m["bias"])) or min(m["scale"]) <= 0:
        raise ValueError("bias/scale")


def calibrated_confidence(features: np.ndarray, *, fine: bool, calibration: dict | None = None,
                          target: str = "right") -> np.ndarray:
    """``(N,)`` probabilities that the ``N`` estimates are right (``target="right"``) or
    stand on a car (``"car"``)."""
    cal = load_score_calibration() if calibration is None else calibration
    m = _model(cal, "fine" if fine else "coarse", target)
    z = (np.asarray(features, float) - np.asarray(m["mean"])) / np.asarray(m["scale"])
    logit = np.clip(z @ np.asarray(m["weights"]) + float(m["bias"]), -30, 30)
    return 1.0 / (1.0 + np.exp(-logit))


def _car_features(cars) -> np.ndarray:
    """:func:`confidence_features` of fitted cars, from their pre-detection's score
    (``detection_score`` once :func:`apply_confidence` has set it)."""
    scores = [o.score if o.detection_score is None else o.detection_score for o in cars]
    return confidence_features(scores, [o.cost for o in cars], [o.box2d for o in cars])


def apply_confidence(estimate: SceneEstimate, *, fine: bool, calibration: dict | None = None) -> SceneEstimate:
    """Set every car's ``score`` to its calibrated confidence, keeping the pre-detection's
    score as ``detection_score``."""
    cars = estimate.objects
    if not cars:
        return estimate
    for o in cars:
        if o.detection_score is None:
            o.detection_score = o.score
    for o, p in zip(cars, calibrated_confidence(_car_features(cars), fine=fine, calibration=calibration)):
        o.score = float(p)
    return estimate


def car_probabilities(estimate: SceneEstimate, *, fine: bool, calibration: dict | None = None) -> np.ndarray:
    """``(N,)`` probabilities that the ``N`` fitted cars of ``estimate`` stand on a car,
    from their pre-detection's score (``detection_score`` once :func:`apply_confidence`
    has run), their objective and their box height."""
    if not estimate.objects:
        return np.zeros(0)
    return calibrated_confidence(_car_features(estimate.objects), fine=fine, calibration=calibration, target="car")


def keep_likely_cars(estimate: SceneEstimate, *, fine: bool, min_probability: float,
                     calibration: dict | None = None) -> SceneEstimate:
    """``estimate`` without the cars whose :func:`car_probabilities` fall below
    ``min_probability`` (0 keeps every car): the fit's verification of our own
    pre-detections. The kept cars keep their ``detection_index``."""
    if min_probability <= 0 or not estimate.objects:
        return estimate
    p = car_probabilities(estimate, fine=fine, calibration=calibration)
    estimate.objects = [o for o, q in zip(estimate.objects, p) if q >= min_probability]
    return estimate
