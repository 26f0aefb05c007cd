"""Box refinement from the image: a linear regression from the HOG cells around a
detection to the offsets of its four sides (R-CNN's bounding-box regression on HOG).

The bank's boxes average the votes of part configurations, each placed on an 8-pixel
cell grid of some pyramid level, so a side is typically 5-8% of the box off (held-out
median on the real frames) -- too much for KITTI's IoU 0.7. The cells around the box
show where the car's sides are. The window is the box grown by ``CONTEXT`` of its size
on every side, warped to ``GRID`` cells (:func:`wirescene.predetect.hog.crop_features`);
with the viewpoint bin and the box's geometry (:func:`wirescene.predetect.bank.regression_features`)
that gives ``n_features`` numbers, standardised, and a ridge regression maps them to the
offsets ``(dx1, dy1, dx2, dy2)`` in units of the box's width / height.

Training (:func:`wirescene.training.kitti_detector.fit_box_refinement`) needs many more
examples than the ~200 detections a bank makes of its training cars, so it adds jittered
copies of the labelled boxes, the offsets drawn as the bank's own errors are spread
(normal, 12% of the size per side).
"""

from __future__ import annotations

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.predetect.hog import N_FEAT, crops_features

CONTEXT = 0.25
GRID = (8, 12)  # (rows, cols) of HOG cells of the grown window


def window_boxes(boxes) -> np.ndarray:
    """Boxes ``(D, 4)`` grown by ``CONTEXT`` of their width / height on every side.

    Examples
    --------
    >>> window_boxes([[0, 0, 100, 40]])  # a quarter of the width / height on every side
    array([[-25., -10., 125.,  50.]])
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    w, h = b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]
    return b + CONTEXT * np.column_stack([-w, -h, w, h])


def refinement_features(gray: np.ndarray, boxes, geometry: np.ndarray) -> np.ndarray:
    """``(D, F)`` features of detection ``boxes`` ``(D, 4)`` in a grey ``(H, W)`` float
    image: the HOG cells of each grown window, then ``geometry`` ``(D, G)`` (the box
    regression's features of the same boxes).

    Examples
    --------
    >>> from wirescene.predetect.bank import regression_features
    >>> from wirescene.predetect.hog import to_gray
    >>> gray = to_gray(np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8))
    >>> boxes = np.array([[10.0, 10, 70, 40], [20, 5, 90, 60]])
    >>> geometry = regression_features(boxes, [0, 2], (96, 64))  # (2, 14)
    >>> refinement_features(gray, boxes, geometry).shape  # 8 x 12 cells x 31, then the 14 geometry features
    (2, 2990)
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    geometry = np.asarray(geometry, float)
    geometry = geometry.reshape(len(b), geometry.shape[-1])  # (the last axis named: no boxes, no rows to infer it)
    th, tw = GRID
    cells = crops_features(gray, window_boxes(b), th, tw).reshape(len(b), th * tw * N_FEAT)
    return np.concatenate([cells, geometry], 1)


def apply_box_refinement(refinement: dict, gray: np.ndarray, boxes, geometry) -> np.ndarray:
    """Boxes ``(D, 4)`` moved by a fitted refinement (``mean`` ``(F,)``, ``scale`` ``(F,)``,
    ``weights`` ``(F + 1, 4)``, the last row the constant).

    Examples
    --------
    >>> from wirescene.predetect.bank import regression_features
    >>> from wirescene.predetect.hog import to_gray
    >>> gray = to_gray(np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8))
    >>> boxes = np.array([[10.0, 10, 70, 40], [20, 5, 90, 60]])
    >>> geometry = regression_features(boxes, [0, 2], (96, 64))  # (2, 14)
    >>> F = 2990
    >>> weights = np.zeros((F + 1, 4))
    >>> weights[-1] = [0.1, 0.0, -0.1, 0.0]  # the constant alone: both sides 10% of the width inwards
    >>> refinement = {"mean": np.zeros(F), "scale": np.ones(F), "weights": weights}
    >>> apply_box_refinement(refinement, gray, boxes, geometry)
    array([[16., 10., 64., 40.],
           [27.,  5., 83., 60.]])
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    if not len(b):
        return b
    X = refinement_features(gray, b, geometry)
    mean, scale, weights = (np.asarray(refinement[k], float) for k in ("mean", "scale", "weights"))
    check_shape("refinement weights", weights, (X.shape[1] + 1, 4))
    t = ((X - mean) / scale) @ weights[:-1] + weights[-1]
    w, h = b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]
    return b + t * np.column_stack([w, h, w, h])


def fit_ridge(X, T, reg: float, *, chunk: int = 2048) -> dict:
    """The refinement ``dict`` of a ridge regression ``T (N, 4) ~ X (N, F)`` on
    standardised features (constant features keep scale 1), the constant unpenalised.
    The normal equations are accumulated ``chunk`` rows at a time in float64, so memory
    is that of ``X`` itself plus ``F x F`` floats, whatever ``N``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> X = rng.normal(size=(200, 3))
    >>> T = np.column_stack([X @ [1.0, 2.0, 0.0], 0.5 * X[:, 0], np.zeros(200), np.full(200, 0.1)])
    >>> fit = fit_ridge(X, T, reg=0.0)
    >>> {k: v.shape for k, v in fit.items()}  # the last row of the weights: the constant
    {'mean': (3,), 'scale': (3,), 'weights': (4, 4)}
    >>> predicted = (X - fit["mean"]) / fit["scale"] @ fit["weights"][:-1] + fit["weights"][-1]
    >>> bool(np.abs(predicted - T).max() < 1e-4)  # a linear target, found exactly (to float32)
    True
    """
    X, T = np.asarray(X), np.asarray(T, float)
    n, F = X.shape

    def blocks():  # (first row, float64 rows)
        return ((i, np.asarray(X[i:i + chunk], float)) for i in range(0, n, chunk))

    mean = sum(b.sum(0) for _, b in blocks()) / n
    sd = np.sqrt(sum(((b - mean) ** 2).sum(0) for _, b in blocks()) / n)
    flat = sd < 1e-9
    mean[flat], sd[flat] = 0.0, 1.0
    ZZ, ZT = np.zeros((F + 1, F + 1)), np.zeros((F + 1, T.shape[1]))
    for i, b in blocks():
        Z = np.column_stack([(b - mean) / sd, np.ones(len(b))])
        ZZ += Z.T @ Z
        ZT += Z.T @ T[i:i + chunk]
    penalty = np.full(F + 1, float(reg))
    penalty[-1] = 0.0
    weights = np.linalg.solve(ZZ + np.diag(penalty), ZT)
    return {"mean": mean.astype(np.float32), "scale": sd.astype(np.float32), "weights": weights.astype(np.float32)}
