"""The confidence written with every car: a calibrated probability that the estimate is
right, from the pre-detection's score and the fit itself, so that ranking metrics (KITTI
AP) mean something.

A logistic model per stage (``coarse`` variants, whose objective is the lifting cost, and
``fine`` ones, whose objective is the negative part likelihood) on the features of
:data:`FEATURES`:

* the detection score as a logit (scores are read as probabilities, as our bank's
  are; scores outside (0, 1) saturate),
* the fit's objective for the car (``ObjectEstimate.cost``, lower is better),
* the log height of the 2D box (far, small cars are harder to place in depth), and its
  square (the nearest cars are not the best placed either),
* whether the box touches the image's left or right side (a car the image cuts).

Each stored model names the features it reads (older calibrations: the first three).

"Right" means the pre-detection matches a ground-truth car (IoU > 0.5) and the estimated
3D box overlaps the car's at IoU > 0.7, KITTI's rule for cars (the calibration records its
criterion; ``wirescene train scores --right 1m`` fits the paper's, the 3D centre within 1 m,
instead). A second model per stage, on the first three features, gives the
probability that the fitted car stands on a car at all (its
pre-detection matches one): the fit's verification of our own pre-detections
(:func:`keep_likely_cars`), since a box that is not a car fits the part evidence badly.
The weights are fitted by ``wirescene train scores`` (:mod:`wirescene.training.scores`) on
evaluation records of labelled real frames and stored in ``data/score_calibration.json``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wirescene.core.artefacts import load_json, save_json
from wirescene.core.errors import InputError
from wirescene.core.resources import DATA_DIR, cached_by_file
from wirescene.core.types import SceneEstimate

DEFAULT_PATH = DATA_DIR / "score_calibration.json"
ARTEFACT_KIND = "score-calibration"
FORMAT_VERSION = 2
FEATURES = ("detection_logit", "objective", "log_box_height", "log_box_height_sq", "at_image_side")
STAGES = ("coarse", "fine")
#: What the models predict: ``right`` (the confidence; stored per stage at the top level)
#: and ``car`` (stored per stage under ``"car"``).
TARGETS = ("right", "car")
#: The features each target's models read: the confidence all; the car model (the fit's
#: verification, chosen on three) the first three.
MODEL_FEATURES = {"right": FEATURES, "car": FEATURES[:3]}


def confidence_features(detection_scores, costs, boxes, *, image_width: float | None = None) -> np.ndarray:
    """``(N, 5)`` features of :data:`FEATURES` for ``N`` cars; ``image_width`` (pixels)
    tells which boxes touch the image's right side (None: only its left side counts).

    Examples
    --------
    >>> f = confidence_features([0.5, 0.9], [0.1, 2.0], [[0, 100, 50, 150], [600, 100, 1241, 300]], image_width=1242)
    >>> f.shape, f[:, 0].round(3), f[:, 2].round(3), f[:, 4]  # logit of the score, log height, at a side
    ((2, 5), array([0.   , 2.197]), array([3.912, 5.298]), array([1., 1.]))
    """
    s = np.clip(np.asarray(detection_scores, float), 1e-3, 1 - 1e-3)
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    log_height = np.log(np.maximum(boxes[:, 3] - boxes[:, 1], 1.0))
    side = boxes[:, 0] <= 1.0
    if image_width is not None:
        side |= boxes[:, 2] >= float(image_width) - 2.0
    return np.stack([np.log(s / (1 - s)), np.asarray(costs, float), log_height, log_height**2,
                     side.astype(float)], axis=1)


def save_score_calibration(path: str | Path, record: dict) -> Path:
    """Write a calibration (``{"coarse": {...}, "fine": {...}, ...}``) as loaded below.

    Examples
    --------
    >>> def model(weights):  # standardisation by (0, 1), then a logistic model on the first three features
    ...     return {"mean": [0.0] * 3, "scale": [1.0] * 3, "weights": weights, "bias": 0.0}
    >>> calibration = {stage: model([1.0, -1.0, 0.0]) for stage in STAGES}  # sigmoid(logit(score) - cost)
    >>> calibration["car"] = {stage: model([1.0, 0.0, 0.0]) for stage in STAGES}  # the detection score itself
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = save_score_calibration(Path(tmp) / "score_calibration.json", calibration)
    ...     load_score_calibration(path)["fine"]["weights"]
    [1.0, -1.0, 0.0]
    """
    return save_json(path, record, kind=ARTEFACT_KIND, version=FORMAT_VERSION)


@cached_by_file(maxsize=8)
def load_score_calibration(path: str | Path | None = None) -> dict:
    """The calibration: per stage ``mean`` and ``scale`` (feature standardisation),
    ``weights`` and ``bias`` of the logistic model, for each of :data:`TARGETS`.

    Examples
    --------
    >>> calibration = load_score_calibration()  # the shipped one
    >>> [sorted(calibration[stage]) == sorted(calibration["car"][stage]) for stage in STAGES]  # each target, stage
    [True, True]
    >>> {"mean", "scale", "weights", "bias"} <= set(calibration["fine"])
    True
    """
    path = DEFAULT_PATH if path is None else Path(path)
    record = load_json(path, kind=ARTEFACT_KIND, version=FORMAT_VERSION)
    try:
        for target in TARGETS:
            for stage in STAGES:
                _check_model(_model(record, stage, target), record)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed score calibration ({exc})", path=path) from None
    return record


def _model(calibration: dict, stage: str, target: str) -> dict:
    return calibration[stage] if target == "right" else calibration[target][stage]


def _model_columns(m: dict, calibration: dict) -> list[int]:
    """Columns of :data:`FEATURES` a model reads (its ``features``; older files name
    them once, at the top level)."""
    names = m.get("features", calibration.get("features", FEATURES[:3]))
    unknown = set(names) - set(FEATURES)
    if unknown:
        raise ValueError(f"unknown features {sorted(unknown)}")
    return [FEATURES.index(n) for n in names]


def _check_model(m: dict, calibration: dict) -> None:
    n = len(_model_columns(m, calibration))
    for key in ("mean", "scale", "weights"):
        if len(m[key]) != n or not np.all(np.isfinite(m[key])):
            raise ValueError(key)
    if not np.isfinite(float(m["bias"])) or min(m["scale"]) <= 0:
        raise ValueError("bias/scale")


def calibrated_confidence(features: np.ndarray, *, fine: bool, calibration: dict | None = None,
                          target: str = "right") -> np.ndarray:
    """``(N,)`` probabilities that the ``N`` estimates of ``features`` ``(N, 5)``
    (:func:`confidence_features`) are right (``target="right"``) or stand on a car
    (``"car"``).

    Examples
    --------
    >>> def model(weights):  # standardisation by (0, 1), then a logistic model on the first three features
    ...     return {"mean": [0.0] * 3, "scale": [1.0] * 3, "weights": weights, "bias": 0.0}
    >>> calibration = {stage: model([1.0, -1.0, 0.0]) for stage in STAGES}  # sigmoid(logit(score) - cost)
    >>> calibration["car"] = {stage: model([1.0, 0.0, 0.0]) for stage in STAGES}  # the detection score itself
    >>> features = confidence_features([0.8, 0.8], [0.0, 1.0], [[0, 0, 10, 10]] * 2)
    >>> calibrated_confidence(features, fine=True, calibration=calibration).round(4)  # sigmoid(logit(0.8) - cost)
    array([0.8   , 0.5954])
    >>> calibrated_confidence(features, fine=True, calibration=calibration, target="car").round(4)
    array([0.8, 0.8])
    """
    cal = load_score_calibration() if calibration is None else calibration
    m = _model(cal, "fine" if fine else "coarse", target)
    x = np.asarray(features, float).reshape(-1, len(FEATURES))[:, _model_columns(m, cal)]
    z = (x - np.asarray(m["mean"])) / np.asarray(m["scale"])
    logit = np.clip(z @ np.asarray(m["weights"]) + float(m["bias"]), -30, 30)
    return 1.0 / (1.0 + np.exp(-logit))


def _car_features(cars, image_width: float | None) -> np.ndarray:
    """:func:`confidence_features` of fitted cars, from their pre-detection's score
    (``detection_score`` once :func:`apply_confidence` has set it)."""
    scores = [o.score if o.detection_score is None else o.detection_score for o in cars]
    return confidence_features(scores, [o.cost for o in cars], [o.box2d for o in cars], image_width=image_width)


def apply_confidence(estimate: SceneEstimate, *, fine: bool, calibration: dict | None = None,
                     image_width: float | None = None) -> SceneEstimate:
    """Set every car's ``score`` to its calibrated confidence, keeping the pre-detection's
    score as ``detection_score``; ``image_width`` as in :func:`confidence_features`.

    Examples
    --------
    >>> def model(weights):  # standardisation by (0, 1), then a logistic model on the first three features
    ...     return {"mean": [0.0] * 3, "scale": [1.0] * 3, "weights": weights, "bias": 0.0}
    >>> calibration = {stage: model([1.0, -1.0, 0.0]) for stage in STAGES}  # sigmoid(logit(score) - cost)
    >>> calibration["car"] = {stage: model([1.0, 0.0, 0.0]) for stage in STAGES}  # the detection score itself
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import ObjectEstimate
    >>> def car(i, score, cost, box):
    ...     return ObjectEstimate(detection_index=i, box2d=np.array(box, float), score=score, cost=cost,
    ...                           location=np.array([0.0, 1.65, 12.0]), R=rotation_y(0.0), dims=np.array([1.5, 1.6, 3.9]))
    >>> scene = SceneEstimate(variant="coarse", objects=[car(0, 0.9, 0.0, [300, 180, 520, 300]),
    ...                                                  car(1, 0.2, 0.5, [600, 170, 640, 200])])
    >>> scene = apply_confidence(scene, fine=False, calibration=calibration)
    >>> [(round(o.score, 4), o.detection_score) for o in scene.cars]  # calibrated; the detection's kept
    [(0.9, 0.9), (0.1317, 0.2)]
    """
    cars = estimate.objects
    if not cars:
        return estimate
    for o in cars:
        if o.detection_score is None:
            o.detection_score = o.score
    p = calibrated_confidence(_car_features(cars, image_width), fine=fine, calibration=calibration)
    for o, q in zip(cars, p):
        o.score = float(q)
    return estimate


def car_probabilities(estimate: SceneEstimate, *, fine: bool, calibration: dict | None = None,
                      image_width: float | None = None) -> np.ndarray:
    """``(N,)`` probabilities that the ``N`` fitted cars of ``estimate`` stand on a car,
    from their pre-detection's score (``detection_score`` once :func:`apply_confidence`
    has run), their objective and their box height.

    Examples
    --------
    >>> def model(weights):  # standardisation by (0, 1), then a logistic model on the first three features
    ...     return {"mean": [0.0] * 3, "scale": [1.0] * 3, "weights": weights, "bias": 0.0}
    >>> calibration = {stage: model([1.0, -1.0, 0.0]) for stage in STAGES}  # sigmoid(logit(score) - cost)
    >>> calibration["car"] = {stage: model([1.0, 0.0, 0.0]) for stage in STAGES}  # the detection score itself
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import ObjectEstimate
    >>> def car(i, score, cost, box):
    ...     return ObjectEstimate(detection_index=i, box2d=np.array(box, float), score=score, cost=cost,
    ...                           location=np.array([0.0, 1.65, 12.0]), R=rotation_y(0.0), dims=np.array([1.5, 1.6, 3.9]))
    >>> scene = SceneEstimate(variant="coarse", objects=[car(0, 0.9, 0.0, [300, 180, 520, 300]),
    ...                                                  car(1, 0.2, 0.5, [600, 170, 640, 200])])
    >>> car_probabilities(scene, fine=False, calibration=calibration).round(4)
    array([0.9, 0.2])
    """
    if not estimate.objects:
        return np.zeros(0)
    return calibrated_confidence(_car_features(estimate.objects, image_width), fine=fine, calibration=calibration,
                                 target="car")


def keep_likely_cars(estimate: SceneEstimate, *, fine: bool, min_probability: float,
                     calibration: dict | None = None, image_width: float | None = None) -> SceneEstimate:
    """``estimate`` without the cars whose :func:`car_probabilities` fall below
    ``min_probability`` (0 keeps every car): the fit's verification of our own
    pre-detections. The kept cars keep their ``detection_index``.

    Examples
    --------
    >>> def model(weights):  # standardisation by (0, 1), then a logistic model on the first three features
    ...     return {"mean": [0.0] * 3, "scale": [1.0] * 3, "weights": weights, "bias": 0.0}
    >>> calibration = {stage: model([1.0, -1.0, 0.0]) for stage in STAGES}  # sigmoid(logit(score) - cost)
    >>> calibration["car"] = {stage: model([1.0, 0.0, 0.0]) for stage in STAGES}  # the detection score itself
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import ObjectEstimate
    >>> def car(i, score, cost, box):
    ...     return ObjectEstimate(detection_index=i, box2d=np.array(box, float), score=score, cost=cost,
    ...                           location=np.array([0.0, 1.65, 12.0]), R=rotation_y(0.0), dims=np.array([1.5, 1.6, 3.9]))
    >>> scene = SceneEstimate(variant="coarse", objects=[car(0, 0.9, 0.0, [300, 180, 520, 300]),
    ...                                                  car(1, 0.2, 0.5, [600, 170, 640, 200])])
    >>> kept = keep_likely_cars(scene, fine=False, min_probability=0.5, calibration=calibration)
    >>> [o.detection_index for o in kept.cars]
    [0]
    """
    if min_probability <= 0 or not estimate.objects:
        return estimate
    p = car_probabilities(estimate, fine=fine, calibration=calibration, image_width=image_width)
    estimate.objects = [o for o, q in zip(estimate.objects, p) if q >= min_probability]
    return estimate
