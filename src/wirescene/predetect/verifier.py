"""A second look at every detection: does the box, with what surrounds it, show a car?

The bank's templates score a cluster by its best vote, one part configuration at a time,
so a box across two parked cars, on half of one or on a car-like patch of background
scores as high as a car. The verifier looks at the whole final box at once, with its
surroundings: the HOG cells of the box grown by :data:`wirescene.predetect.refine.CONTEXT`
on every side (:func:`wirescene.predetect.refine.refinement_features`, the features the box
refinement reads, with the box's geometry) and, in banks trained since December 2026, the
mean colour and gradient magnitude of the same window's cells
(:mod:`wirescene.predetect.channels`; :data:`CHANNELS`), standardised, and an
L2-regularised logistic regression fitted on the bank's own detections of its training
images (a detection is a car when it overlaps one at IoU >= 0.5) and the labelled cars'
boxes, each with a copy jittered as the bank's boxes are. Banks of format 5 and later may
hold one such regression per group of viewpoints instead (:data:`VIEW_GROUPS`: side,
diagonal, front or back; a mixture of linear models, as DPM's components), all stored on
one standardisation; a study, not adopted (``benchmarks/RESULTS.md``).

Its logit enters the bank's score through the Platt calibration, whose third coefficient
(``c`` in ``P(car) = sigmoid(a * margin + b + c * logit + ground)``) is fitted on held-out
detections; :meth:`wirescene.predetect.bank.DetectorBank.confidence` then needs no change,
as :func:`wirescene.predetect.bank.merge_activations` adds ``c / a * logit`` to the margin.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.predetect.channels import window_channel_features
from wirescene.predetect.refine import refinement_features

#: Inverse L2 regularisation of the logistic regression.
C = 1e-3
#: Whether newly trained verifiers also read the boxes' colour channels (:mod:`wirescene.predetect.channels`).
CHANNELS = True
#: Group of each of the 8 viewpoint bins: 0 side (bins 0, 4), 1 diagonal, 2 front or back (bins 2, 6).
VIEW_GROUPS = np.array([0, 1, 2, 1, 0, 1, 2, 1])
N_VIEW_GROUPS = 3


def verifier_features(gray: np.ndarray, boxes, geometry, *, channels: np.ndarray | None = None) -> np.ndarray:
    """``(D, F)`` features of ``boxes`` ``(D, 4)`` in a grey ``(H, W)`` float image, with the
    boxes' ``geometry`` ``(D, G)`` (:func:`wirescene.predetect.bank.regression_features`):
    the HOG cells of each box's window, then, given the image's ``channels``
    (:func:`wirescene.predetect.channels.integral_channels`), its colour and gradient-magnitude
    channel features (:func:`wirescene.predetect.channels.window_channel_features`), then the
    geometry.

    Examples
    --------
    >>> from wirescene.predetect.bank import regression_features
    >>> from wirescene.predetect.channels import integral_channels
    >>> from wirescene.predetect.hog import to_gray
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> boxes = np.array([[10.0, 10, 70, 40], [20, 5, 90, 60]])
    >>> geometry = regression_features(boxes, [0, 2], (96, 64))
    >>> verifier_features(to_gray(image), boxes, geometry).shape  # HOG of the grown window, geometry
    (2, 2990)
    >>> verifier_features(to_gray(image), boxes, geometry, channels=integral_channels(image)).shape  # + channels
    (2, 3382)
    """
    if channels is None:
        return refinement_features(gray, boxes, geometry)
    b = np.asarray(boxes, float).reshape(-1, 4)
    geometry = np.asarray(geometry, float)
    geometry = geometry.reshape(len(b), geometry.shape[-1])  # as refinement_features reads it
    return refinement_features(gray, b, np.concatenate([window_channel_features(channels, b), geometry], axis=1))


def fit_verifier(features, labels, *, C: float = C, groups=None) -> dict:
    """The verifier (``mean`` ``(F,)``, ``scale`` ``(F,)``, ``weights``) of training
    ``features`` ``(N, F)`` with 0/1 ``labels`` ``(N,)``; the classes are weighted to balance,
    so the logit's zero sits between them. ``weights`` is ``(F + 1,)`` (the last entry the
    constant), or with ``groups`` (``(N,)`` ints below :data:`N_VIEW_GROUPS`, e.g.
    ``VIEW_GROUPS[bins]``) ``(N_VIEW_GROUPS, F + 1)``: one regression per group, each on its
    own rows and standardisation, re-expressed on the standardisation of all rows (a group
    without both classes takes the regression of all rows).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> y = np.arange(200) % 2
    >>> x = rng.normal(size=(200, 5)) + y[:, None]
    >>> v = fit_verifier(x, y, C=1.0)
    >>> bool(np.mean((verifier_logits(v, x) > 0) == y) > 0.8)
    True
    >>> g = np.arange(200) // 100  # two groups
    >>> v = fit_verifier(x, y, C=1.0, groups=g)
    >>> v["weights"].shape
    (3, 6)
    >>> bool(np.mean((verifier_logits(v, x, groups=g) > 0) == y) > 0.8)
    True
    """
    x = np.asarray(features, float)
    y = np.asarray(labels, int)
    check_shape("labels", y, (len(x),))
    if len(np.unique(y)) < 2:
        raise ValueError("the verifier needs both cars and non-cars to train on")
    mean, scale = _standardisation(x)
    stored = {"mean": mean.astype(np.float32), "scale": scale.astype(np.float32)}
    if groups is None:
        return {**stored, "weights": _logistic((x - mean) / scale, y, C).astype(np.float32)}
    g = np.asarray(groups)
    check_shape("groups", g, (len(x),))
    if len(g) and not (np.issubdtype(g.dtype, np.integer) and 0 <= g.min() and g.max() < N_VIEW_GROUPS):
        raise ValueError(f"groups must be integers in [0, {N_VIEW_GROUPS})")
    weights = np.zeros((N_VIEW_GROUPS, x.shape[1] + 1))
    shared = None  # the regression of all rows, fitted only for a group that lacks a class
    for j in range(N_VIEW_GROUPS):
        xj, yj = x[g == j], y[g == j]
        if len(np.unique(yj)) < 2:
            shared = _logistic((x - mean) / scale, y, C) if shared is None else shared
            weights[j] = shared
            continue
        m, s = _standardisation(xj)
        wj = _logistic((xj - m) / s, yj, C)
        # (x - m) / s . w + c  ==  (x - mean) / scale . (scale / s * w) + (mean - m) / s . w + c
        weights[j, :-1] = scale / s * wj[:-1]
        weights[j, -1] = wj[-1] + ((mean - m) / s) @ wj[:-1]
    return {**stored, "weights": weights.astype(np.float32)}


def _standardisation(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(mean, scale)`` of the columns of ``x``; constant columns keep scale 1."""
    mean, scale = x.mean(0), x.std(0)
    scale[scale < 1e-9] = 1.0
    return mean, scale


def _logistic(z: np.ndarray, y: np.ndarray, C: float) -> np.ndarray:
    """``(F + 1,)`` weights (the last the constant) of a class-balanced L2 logistic
    regression on standardised rows ``z``."""
    from sklearn.linear_model import LogisticRegression

    clf = LogisticRegression(C=C, max_iter=5000, class_weight="balanced").fit(z, y)
    return np.concatenate([clf.coef_.ravel(), clf.intercept_])


def verifier_logits(verifier: dict, features, *, groups=None) -> np.ndarray:
    """``(D,)`` log-odds of the verifier for ``features`` ``(D, F)``; a verifier with one
    regression per viewpoint group needs each row's ``groups`` ``(D,)``.

    Examples
    --------
    >>> verifier = {"mean": np.zeros(2), "scale": np.ones(2), "weights": np.array([1.0, -1.0, 0.5])}
    >>> verifier_logits(verifier, [[2.0, 1.0], [0.0, 3.0]])  # x . w + constant
    array([ 1.5, -2.5])
    """
    mean, scale, weights = (np.asarray(verifier[k], float) for k in ("mean", "scale", "weights"))
    x = np.asarray(features, float).reshape(-1, len(mean))
    z = (x - mean) / scale
    if weights.ndim == 1:
        check_shape("verifier weights", weights, (len(mean) + 1,))
        return z @ weights[:-1] + weights[-1]
    check_shape("verifier weights", weights, (N_VIEW_GROUPS, len(mean) + 1))
    if groups is None:
        raise ValueError("a verifier with one regression per viewpoint group needs the rows' groups")
    w = weights[np.asarray(groups, int).reshape(len(x))]
    return np.einsum("df,df->d", z, w[:, :-1]) + w[:, -1]
