"""A viewpoint for every box, whoever detected it: the bank's configuration detectors
score the 8 viewpoint bins inside given boxes (issue 27, item 2).

Boxes read from another detector's files (:mod:`wirescene.io.detections`) carry no
viewpoint. The bank's templates already say which viewpoint a window looks like, and
every window predicts the full car box it belongs to -- the vote of
:func:`~wirescene.predetect.bank.merge_activations`: the configuration box grown by the
configuration's offsets, clipped to the image and moved by the bank's box regression
onto the labelled boxes' convention. For each given box, the windows of every template
on the HOG pyramid whose vote overlaps it by IoU >= :data:`IOU` are its candidates; a
bin scores the calibrated log-odds of its best candidate (the rule of the bank's own
clusters, whose score is their best member's), a bin without any candidate, or with
only weaker ones, scores as :data:`FLOOR_MARGIN`. Given the camera, the bank's traffic
prior (:mod:`wirescene.predetect.viewpoint_prior`) adds log P(bin | lateral position),
as :func:`~wirescene.predetect.bank.traffic_viewpoints` does for the bank's own
detections, and the viewpoint is the best bin's centre.

The settings were chosen held out by drive on fold group (0, 1) and reported on (2, 3)
(``benchmarks/bench_box_viewpoints.py``).
"""

from __future__ import annotations

import numpy as np

from wirescene.core.boxes import iou_2d
from wirescene.core.errors import ArgumentError, InputError, check_shape
from wirescene.core.validate import boxes_problem
from wirescene.core.viewpoints import N_BINS, bin_center
from wirescene.predetect.bank import (
    DetectorBank,
    _clip,
    apply_box_regression,
    template_responses,
    traffic_log_prior,
)
from wirescene.predetect.geometry import horizon_row
from wirescene.predetect.hog import CELL, feature_pyramid, pyramid_scales

#: Overlap (IoU of a window's predicted car box with the given box) for a window to vote.
IOU = 0.5
#: Margin a bin scores at least (the lowest activation :func:`~wirescene.predetect.bank.detect_pyramid`
#: keeps at the shipped threshold), so that one bin's missing window does not rule it out.
FLOOR_MARGIN = -1.0
# Factor by which the box regression may change a vote's height, at most (the shipped bank's
# moves it by 0.84-1.23x), so windows beyond it cannot reach the IoU and are not scored.
_REGRESSION_SLACK = 1.5


def _check_boxes(boxes, image_size=None) -> np.ndarray:
    b = np.asarray(boxes)
    if b.size == 0:
        b = b.reshape(0, 4)
    check_shape("boxes", b, (None, 4))
    problem = boxes_problem(b, image_size)
    if problem:
        raise ArgumentError("boxes", problem)
    return b.astype(float)


def _best_votes(bank: DetectorBank, t: int, scale: float, R: np.ndarray, boxes: np.ndarray, image_size,
                iou: float) -> np.ndarray:
    """``(N,)`` best response in ``R`` (template ``t`` at pyramid ``scale``) among the windows
    whose vote overlaps each of ``boxes`` ``(N, 4)`` by IoU >= ``iou``; -inf where none does."""
    W, H = image_size
    config = bank.configs[t]
    th, tw = config.template
    Hr, Wr = R.shape
    step = CELL / scale
    # the vote of window (r, q) is this box shifted by step * (q, r): each box's windows are a grid range
    vote = config.full_box(np.array([[0.0, 0.0, tw * step, th * step]]))[0]
    vw, vh = vote[2] - vote[0], vote[3] - vote[1]
    out = np.full(len(boxes), -np.inf)
    gw, gh = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    # the regression moves a height by < 25% and clipping only shrinks it: no IoU >= iou beyond these ratios
    near = np.flatnonzero((vh >= iou / _REGRESSION_SLACK * gh) & (vh <= _REGRESSION_SLACK / iou * gh))
    idx, rows, cols = [], [], []
    for i in near:
        # windows whose vote intersects the box (with room for the regression's shift)
        rx, ry = 0.5 * (gw[i] + vw) + 0.25 * vw, 0.5 * (gh[i] + vh) + 0.25 * vh
        cx = (boxes[i, 0] + boxes[i, 2] - vote[0] - vote[2]) / 2
        cy = (boxes[i, 1] + boxes[i, 3] - vote[1] - vote[3]) / 2
        q = np.arange(max(int(np.ceil((cx - rx) / step)), 0), min(int(np.floor((cx + rx) / step)), Wr - 1) + 1)
        r = np.arange(max(int(np.ceil((cy - ry) / step)), 0), min(int(np.floor((cy + ry) / step)), Hr - 1) + 1)
        if len(q) and len(r):
            rows.append(np.repeat(r, len(q)))
            cols.append(np.tile(q, len(r)))
            idx.append(np.full(len(r) * len(q), i))
    if not idx:
        return out
    idx, rows, cols = np.concatenate(idx), np.concatenate(rows), np.concatenate(cols)
    votes = _clip(vote[None] + step * np.column_stack([cols, rows, cols, rows]), W, H)
    regression = bank.meta.get("box_regression")
    if regression is not None:
        votes = _clip(apply_box_regression(regression, votes, np.full(len(votes), config.bin), (W, H)), W, H)
    ok = iou_2d(votes, boxes[idx]) >= iou
    np.maximum.at(out, idx[ok], R[rows[ok], cols[ok]].astype(float))
    return out


def box_bin_log_odds(bank: DetectorBank, pyramid, image_size, boxes, *, iou: float = IOU,
                     floor_margin: float = FLOOR_MARGIN, horizon: float | None = None,
                     center_column: float | None = None) -> np.ndarray:
    """Score the 8 viewpoint bins inside given boxes on a precomputed feature pyramid.

    Parameters
    ----------
    bank : DetectorBank
    pyramid : list of (float, ndarray)
        :func:`wirescene.predetect.hog.feature_pyramid` of the image.
    image_size : (int, int)
        ``(W, H)`` of the image.
    boxes : (N, 4) array
        ``x1 y1 x2 y2`` in pixels.
    iou : float, optional
        Overlap of a window's predicted car box with a box for the window to vote.
    floor_margin : float, optional
        Margin each bin scores at least.
    horizon, center_column : float, optional
        Image row of the horizon and column of the principal point: both given, the bank's
        traffic viewpoint prior is added (banks with that prior and a calibration).

    Returns
    -------
    (N, 8) ndarray
        Per box and bin the calibrated log-odds of the bin's best vote (raw margins for an
        uncalibrated bank), plus the log prior when the camera's rows are given.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.predetect import load_default_bank
    >>> from wirescene.predetect.hog import feature_pyramid
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> box_bin_log_odds(load_default_bank(), feature_pyramid(image, [1.0]), (96, 64),
    ...                  np.array([[10.0, 10.0, 70.0, 40.0]])).shape
    (1, 8)
    """
    b = _check_boxes(boxes)
    best = np.full((len(b), N_BINS), -np.inf)
    if len(b):
        heights = b[:, 3] - b[:, 1]
        # the levels where a template's full car could match a box (its implied height is the vote's, roughly)
        reach = 2 * _REGRESSION_SLACK / iou
        for t, _, scale, R in template_responses(bank, pyramid, min_height=heights.min() / reach,
                                                 max_height=heights.max() * reach):
            k = bank.configs[t].bin
            best[:, k] = np.maximum(best[:, k], _best_votes(bank, t, scale, R, b, image_size, iou))
    best = np.maximum(best, floor_margin)
    if bank.calibration is not None:
        a, c = (float(v) for v in bank.calibration)
        best = a * best + c
    if horizon is not None and center_column is not None and len(b):
        log_prior = traffic_log_prior(bank, b, horizon, center_column)
        if log_prior is not None:
            best = best + log_prior
    return best


def box_viewpoints(bank: DetectorBank, image: np.ndarray, boxes, *, camera=None, iou: float = IOU,
                   floor_margin: float = FLOOR_MARGIN, pyramid=None) -> np.ndarray:
    """The viewpoint of each given box, scored by the bank's configuration detectors.

    Parameters
    ----------
    bank : DetectorBank
    image : (H, W, 3) uint8 array
    boxes : (N, 4) array
        ``x1 y1 x2 y2`` in pixels, e.g. another detector's boxes.
    camera : Camera, optional
        With it, the bank's traffic viewpoint prior weighs front against back by where each
        box stands on the road.
    iou, floor_margin : float, optional
        See :func:`box_bin_log_odds`.
    pyramid : list of (float, ndarray), optional
        The image's feature pyramid if already computed (default: the bank's scales).

    Returns
    -------
    (N,) ndarray
        Observation angle ``alpha`` (radians): the centre of the best bin of each box.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.predetect import load_default_bank
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> box_viewpoints(load_default_bank(), image, [[10, 10, 70, 40], [20, 5, 90, 60]]).shape
    (2,)
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or image.shape[0] < 16 or image.shape[1] < 16:
        raise InputError(f"expected an (H, W, 3) image, got shape {image.shape}")
    H, W = image.shape[:2]
    b = _check_boxes(boxes, (W, H))
    if not len(b):
        return np.zeros(0)
    if pyramid is None:
        scales = pyramid_scales(W, H, max_scale=float(bank.meta.get("max_scale", 2.0)),
                                per_octave=int(bank.meta.get("per_octave", 4)))
        pyramid = feature_pyramid(image, scales)
    horizon = None if camera is None else horizon_row(camera)
    center_column = None if camera is None else float(np.asarray(camera.K, float)[0, 2])
    scores = box_bin_log_odds(bank, pyramid, (W, H), b, iou=iou, floor_margin=floor_margin, horizon=horizon,
                              center_column=center_column)
    return bin_center(np.argmax(scores, axis=1))
