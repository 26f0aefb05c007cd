"""Where a car stands on the road says which way it faces: a viewpoint prior from traffic.

The HOG templates of a car's front and of its back look alike (a symmetric box with two
lamps and a plate): a quarter of the bank's true detections on held-out KITTI frames came
out facing the wrong way. Traffic breaks the tie. In the lane of the ego car and to its
right, cars drive the way the camera looks and show their backs; to its left, oncoming
cars show their fronts (on the labelled KITTI frames 79-86% of the cars 1-6 m to the right
are seen from behind, 67-100% of those to the left from the front). This is the scene-level
context the paper's shared ground plane stands for, learned rather than assumed: a country
that drives on the left yields the mirrored prior when the bank is trained on its frames.

A box's lateral position on the road, in units of the camera's height above it, is

    s = X / Hcam = (centre column - principal column) / (bottom row - horizon row)

(both offsets scale with 1 / Z). The prior ``P(bin | s)`` is a kernel density estimate per
viewpoint bin over the training cars (Gaussian kernel, robust Silverman bandwidth, one
pseudo-count per bin so no viewpoint is ruled out). At detection, the clusters of all
viewpoints that a kept detection suppressed in the cross-view NMS are its candidates; its
viewpoint is the bin maximising the calibrated log-odds of the bin's best cluster plus the
log prior (naive Bayes). Boxes and scores stay those of the kept cluster, so the ranking --
and the AP -- are unchanged.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.boxes import iou_2d
from wirescene.core.viewpoints import N_BINS
from wirescene.predetect.geometry import below_horizon

PSEUDO_COUNT = 1.0
MIN_CARS = 5


def lateral_position(boxes, horizon, center_column: float) -> np.ndarray:
    """``(D,)`` lateral position ``s`` (in KITTI's camera heights, 1.65 m; right positive) of
    boxes ``(D, 4)`` standing on the road below the horizon (a row, or a
    :class:`~wirescene.predetect.geometry.Horizon` for another camera height), seen by a
    camera whose principal point lies in column ``center_column``. Boxes whose bottom is less
    than half their height below the horizon (no car on the road) are measured as if it
    were half their height.

    Examples
    --------
    >>> lateral_position([[700, 180, 800, 230], [400, 180, 500, 230]], 170.0, 600.0)  # (750 - 600) / 60
    array([ 2.5, -2.5])
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    below = np.maximum(below_horizon(b[:, 3], horizon), 0.5 * np.maximum(b[:, 3] - b[:, 1], 1.0))
    return ((b[:, 0] + b[:, 2]) / 2 - float(center_column)) / below


def fit_viewpoint_prior(lateral, bins) -> dict:
    """The prior (a JSON-able dict) from the lateral positions ``(N,)`` and viewpoint bins
    ``(N,)`` of training cars (never mirrored copies: mirroring swaps the sides of traffic).

    Examples
    --------
    >>> lateral = np.r_[np.linspace(1, 3, 10), np.linspace(-3, -1, 10)]  # 10 cars right of the camera, 10 left
    >>> bins = np.r_[np.full(10, 6), np.full(10, 2)]  # seen in bin 6 on the right, bin 2 on the left
    >>> prior = fit_viewpoint_prior(lateral, bins)
    >>> sorted(prior), prior["n"], round(prior["bandwidth"], 3)
    (['bandwidth', 'bins', 'lateral', 'n', 'pseudo_count'], 20, 1.038)
    """
    s = np.asarray(lateral, float).reshape(-1)
    b = np.asarray(bins, int).reshape(-1)
    if s.shape != b.shape:
        raise ValueError(f"lateral positions {s.shape} and bins {b.shape} differ in length")
    ok = np.isfinite(s)
    s, b = s[ok], b[ok]
    if len(s) < MIN_CARS:
        raise ValueError(f"a viewpoint prior needs >= {MIN_CARS} cars, got {len(s)}")
    q75, q25 = np.percentile(s, [75, 25])
    spread = min(float(np.std(s)), float(q75 - q25) / 1.34) or float(np.std(s)) or 1.0
    return {"lateral": np.round(s, 4).tolist(), "bins": b.tolist(), "bandwidth": 0.9 * spread * len(s) ** -0.2,
            "pseudo_count": PSEUDO_COUNT, "n": int(len(s))}


def viewpoint_log_prior(prior: dict, lateral) -> np.ndarray:
    """``(D, 8)`` log P(bin | s) of lateral positions ``(D,)``.

    Examples
    --------
    >>> lateral = np.r_[np.linspace(1, 3, 10), np.linspace(-3, -1, 10)]  # 10 cars right of the camera, 10 left
    >>> bins = np.r_[np.full(10, 6), np.full(10, 2)]  # seen in bin 6 on the right, bin 2 on the left
    >>> prior = fit_viewpoint_prior(lateral, bins)
    >>> log_prior = viewpoint_log_prior(prior, [2.0, -2.0])
    >>> log_prior.shape, log_prior.argmax(1), bool(np.allclose(np.exp(log_prior).sum(1), 1.0))
    ((2, 8), array([6, 2]), True)
    """
    q = np.asarray(lateral, float).reshape(-1)
    s = np.asarray(prior["lateral"], float)
    b = np.asarray(prior["bins"], int)
    k = np.exp(-0.5 * ((q[:, None] - s[None]) / float(prior["bandwidth"])) ** 2)
    counts = np.stack([k[:, b == i].sum(1) for i in range(N_BINS)], axis=1) + float(prior["pseudo_count"])
    return np.log(counts / counts.sum(1, keepdims=True))


def choose_viewpoints(kept, candidates, candidate_log_odds, candidate_bins, log_prior, *, iou: float) -> np.ndarray:
    """``(D,)`` viewpoint bin of each kept detection ``kept`` ``(D, 4)``: among the
    ``candidates`` ``(C, 4)`` overlapping it by IoU >= ``iou`` (the clusters of every
    viewpoint it suppressed; it is one of them), the bin maximising the best candidate's
    calibrated log-odds ``candidate_log_odds`` ``(C,)`` plus ``log_prior`` ``(D, 8)``.

    Examples
    --------
    >>> lateral = np.r_[np.linspace(1, 3, 10), np.linspace(-3, -1, 10)]  # 10 cars right of the camera, 10 left
    >>> bins = np.r_[np.full(10, 6), np.full(10, 2)]  # seen in bin 6 on the right, bin 2 on the left
    >>> prior = fit_viewpoint_prior(lateral, bins)
    >>> kept = np.array([[100.0, 100, 200, 150]])
    >>> candidates = np.array([[100.0, 100, 200, 150], [102, 101, 201, 151]])  # bins 2 and 6, log-odds 1.0, 0.8
    >>> choose_viewpoints(kept, candidates, [1.0, 0.8], [2, 6], np.zeros((1, 8)), iou=0.5)  # no prior: the best
    array([2])
    >>> choose_viewpoints(kept, candidates, [1.0, 0.8], [2, 6], viewpoint_log_prior(prior, [2.0]), iou=0.5)
    array([6])
    """
    kept = np.asarray(kept, float).reshape(-1, 4)
    candidates = np.asarray(candidates, float).reshape(-1, 4)
    bins = np.asarray(candidate_bins, int)
    if not len(kept):
        return np.zeros(0, int)
    ov = iou_2d(kept[:, None], candidates[None]) >= iou  # (D, C)
    scored = np.where(ov, np.asarray(candidate_log_odds, float)[None], -np.inf)
    best = np.full((len(kept), N_BINS), -np.inf)
    for b in np.unique(bins):
        best[:, b] = scored[:, bins == b].max(1)
    return np.argmax(best + log_prior, axis=1)
