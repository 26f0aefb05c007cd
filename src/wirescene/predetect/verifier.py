"""A second look at every detection: does the box, with what surrounds it, show a car?

The bank's templates score a cluster by its best vote, one part configuration at a time,
so a box across two parked cars, on half of one or on a car-like patch of background
scores as high as a car. The verifier looks at the whole final box at once, with its
surroundings: the HOG cells of the box grown by :data:`wirescene.predetect.refine.CONTEXT`
on every side (:func:`wirescene.predetect.refine.refinement_features`, the features the box
refinement reads, with the box's geometry), standardised, and an L2-regularised logistic
regression fitted on the bank's own detections of its training images (a detection is a
car when it overlaps one at IoU >= 0.5) and the labelled cars' boxes, each with a copy
jittered as the bank's boxes are.

Its logit enters the bank's score through the Platt calibration, whose third coefficient
(``c`` in ``P(car) = sigmoid(a * margin + b + c * logit + ground)``) is fitted on held-out
detections; :meth:`wirescene.predetect.bank.DetectorBank.confidence` then needs no change,
as :func:`wirescene.predetect.bank.merge_activations` adds ``c / a * logit`` to the margin.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.predetect.refine import refinement_features

#: Inverse L2 regularisation of the logistic regression.
C = 1e-3


def verifier_features(gray: np.ndarray, boxes, geometry) -> np.ndarray:
    """``(D, F)`` features of ``boxes`` ``(D, 4)`` in a grey ``(H, W)`` float image, with the
    boxes' ``geometry`` ``(D, G)`` (:func:`wirescene.predetect.bank.regression_features`)."""
    return refinement_features(gray, boxes, geometry)


def fit_verifier(features, labels, *, C: float = C) -> dict:
    """The verifier (``mean`` ``(F,)``, ``scale`` ``(F,)``, ``weights`` ``(F + 1,)``, the last
    entry the constant) of training ``features`` ``(N, F)`` with 0/1 ``labels`` ``(N,)``;
    the classes are weighted to balance, so the logit's zero sits between them.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> y = np.arange(200) % 2
    >>> x = rng.normal(size=(200, 5)) + y[:, None]
    >>> v = fit_verifier(x, y, C=1.0)
    >>> bool(np.mean((verifier_logits(v, x) > 0) == y) > 0.8)
    True
    """
    from sklearn.linear_model import LogisticRegression

    x = np.asarray(features, float)
    y = np.asarray(labels, int)
    check_shape("labels", y, (len(x),))
    if len(np.unique(y)) < 2:
        raise ValueError("the verifier needs both cars and non-cars to train on")
    mean, scale = x.mean(0), x.std(0)
    scale[scale < 1e-9] = 1.0  # constant features: left as they are
    clf = LogisticRegression(C=C, max_iter=5000, class_weight="balanced").fit((x - mean) / scale, y)
    weights = np.concatenate([clf.coef_.ravel(), clf.intercept_]).astype(np.float32)
    return {"mean": mean.astype(np.float32), "scale": scale.astype(np.float32), "weights": weights}


def verifier_logits(verifier: dict, features) -> np.ndarray:
    """``(D,)`` log-odds of the verifier for ``features`` ``(D, F)``."""
    mean, scale, weights = (np.asarray(verifier[k], float) for k in ("mean", "scale", "weights"))
    x = np.asarray(features, float).reshape(-1, len(mean))
    check_shape("verifier weights", weights, (len(mean) + 1,))
    return ((x - mean) / scale) @ weights[:-1] + weights[-1]
