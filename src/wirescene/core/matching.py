"""The protocol's matching of one frame's pre-detections to its labelled cars (Zia et al., the
paper's Sec. 5.1; :mod:`wirescene.eval.metrics`, step 1): greedy one-to-one by score at 2D IoU
above 0.5, a match a true-positive initialisation where its coarse viewpoint is within 45 deg
of the car's. The evaluation counts with it, and the pictures mark with it the cars it counts
false and the labelled cars it counts missed (:func:`match_estimate`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from wirescene.core.boxes import iou_2d
from wirescene.core.errors import shaped_array
from wirescene.core.labels import CAR_TYPES, Label, is_type
from wirescene.core.types import Detections, SceneEstimate, fitted_detections
from wirescene.core.viewpoints import angle_difference

__all__ = ["FrameMatches", "match_detections", "match_frame", "match_estimate"]


def match_detections(
    det_boxes: np.ndarray, det_scores: np.ndarray, gt_boxes: np.ndarray, *, iou_threshold: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """Greedy one-to-one matching of detections to ground-truth boxes.

    Detections are visited by descending score (ties: input order); each takes the
    unmatched ground-truth box of highest IoU if that IoU is ``> iou_threshold``.

    Parameters
    ----------
    det_boxes : (D, 4) array
    det_scores : (D,) array
    gt_boxes : (G, 4) array
    iou_threshold : float, optional
        A match needs an IoU above it (the paper's 0.5).

    Returns
    -------
    match : (D,) int array
        Index of the matched ground-truth box, -1 for none.
    iou : (D,) array
        IoU with the matched box (0 where unmatched).

    Examples
    --------
    >>> gt = np.array([[0, 0, 10, 10], [20, 0, 30, 10]])
    >>> det = np.array([[1, 0, 11, 10], [0, 0, 10, 10], [50, 50, 60, 60]])
    >>> match, iou = match_detections(det, [0.9, 0.5, 0.8], gt)
    >>> match  # the best-scored box takes car 0 first; the exact box then finds it taken
    array([ 0, -1, -1])
    >>> iou.round(3)  # 90 / 110
    array([0.818, 0.   , 0.   ])
    """
    det_boxes = shaped_array("det_boxes", det_boxes, (0, 4) if np.size(det_boxes) == 0 else (None, 4))
    gt_boxes = shaped_array("gt_boxes", gt_boxes, (0, 4) if np.size(gt_boxes) == 0 else (None, 4))
    D, G = len(det_boxes), len(gt_boxes)
    det_scores = shaped_array("det_scores", det_scores, (D,))
    match = np.full(D, -1, dtype=int)
    best = np.zeros(D)
    if D == 0 or G == 0:
        return match, best
    ious = iou_2d(det_boxes[:, None, :], gt_boxes[None, :, :])
    taken = np.zeros(G, dtype=bool)
    for d in np.argsort(-det_scores, kind="stable"):
        cand = np.where(taken, -np.inf, ious[d])
        g = int(np.argmax(cand))
        if cand[g] > iou_threshold:
            match[d], best[d] = g, ious[d, g]
            taken[g] = True
    return match, best


@dataclass(frozen=True)
class FrameMatches:
    """How one frame's pre-detections (and the cars estimated from them) meet its labels under
    the protocol (:mod:`wirescene.eval.metrics`, step 1): :func:`match_frame`'s result.

    Attributes
    ----------
    cars : (C,) int array
        Indices into the frame's labels of the labelled cars evaluated (type one of
        ``car_types``); DontCare regions and other classes are none of them.
    match : (D,) int array
        Per detection, the index into the labels of the car it matched (2D IoU above the
        threshold, one-to-one, greedy by score), -1 for none.
    iou : (D,) array
        IoU with the matched car (0 where unmatched).
    viewpoint_checked : (D,) bool array
        Whether the detection had a coarse viewpoint to test (else the test is skipped).
    true_positive : (D,) bool array
        Matched, and its coarse viewpoint within the tolerance of the car's ``alpha`` (or
        untested): a true-positive initialisation, one
        :class:`~wirescene.eval.metrics.TPRecord` of :func:`~wirescene.eval.metrics.evaluate`.

    Examples
    --------
    >>> m = FrameMatches(cars=np.array([0, 2]), match=np.array([2, -1]), iou=np.array([0.8, 0.0]),
    ...                  viewpoint_checked=np.array([True, True]), true_positive=np.array([True, False]))
    >>> m.false.tolist(), m.missed.tolist()  # detection 1 on no car; the label line 0, a car, missed
    ([1], [0])
    """

    cars: np.ndarray
    match: np.ndarray
    iou: np.ndarray
    viewpoint_checked: np.ndarray
    true_positive: np.ndarray

    @property
    def false(self) -> np.ndarray:
        """(F,) int: the detections that are no true positive, on no labelled car or matched to
        one with a viewpoint out of the tolerance (the report's "false" cars)."""
        return np.flatnonzero(~self.true_positive)

    @property
    def wrong_viewpoint(self) -> np.ndarray:
        """(W,) int: of :attr:`false`, those matched to a labelled car whose viewpoint test failed."""
        return np.flatnonzero((self.match >= 0) & ~self.true_positive)

    @property
    def missed(self) -> np.ndarray:
        """(M,) int: indices into the labels of the cars of no true positive (not matched, or
        consumed by a detection of a wrong viewpoint)."""
        return self.cars[~np.isin(self.cars, self.match[self.true_positive])]


def match_frame(
    det_boxes: np.ndarray,
    det_scores: np.ndarray,
    det_alpha: np.ndarray,
    labels: Sequence[Label],
    *,
    iou_threshold: float = 0.5,
    viewpoint_tolerance_deg: float = 45.0,
    car_types: Sequence[str] = CAR_TYPES,
) -> FrameMatches:
    """The true-positive initialisations of one frame (:mod:`wirescene.eval.metrics`, step 1), the one
    matching :func:`~wirescene.eval.metrics.evaluate` and the pictures' marks (:func:`match_estimate`) share.

    Parameters
    ----------
    det_boxes : (D, 4) array
        Pre-detection boxes ``x1 y1 x2 y2``.
    det_scores : (D,) array
        Their scores, the greedy matching's order.
    det_alpha : (D,) array
        Their coarse viewpoints (radians; NaN: unknown, the test skipped).
    labels : sequence of Label
        The frame's labels, any class (only ``car_types`` are matched); the indices returned
        are into this sequence, whether it holds every label line or the cars only.
    iou_threshold, viewpoint_tolerance_deg, car_types
        As of :func:`~wirescene.eval.metrics.evaluate`.

    Returns
    -------
    FrameMatches

    Examples
    --------
    >>> from wirescene.io.kitti import Label
    >>> car = Label("Car", 0.0, 0, 0.3, [100, 100, 200, 160], [1.5, 1.6, 4.0], [2.0, 1.6, 20.0], 0.4)
    >>> ignored = Label("DontCare", -1, -1, -10, [300, 100, 360, 140], [-1, -1, -1], [-1000, -1000, -1000], -10)
    >>> other = Label("Car", 0.0, 0, -1.2, [500, 100, 600, 160], [1.5, 1.6, 4.0], [9.0, 1.6, 20.0], -0.8)
    >>> m = match_frame([[102, 100, 200, 160], [300, 100, 360, 140], [500, 100, 600, 160]], [0.9, 0.8, 0.7],
    ...                 [0.3, np.nan, 1.6], [car, ignored, other])  # the third 160 deg off its car's viewpoint
    >>> m.match.tolist(), m.true_positive.tolist()  # the DontCare region matches nothing
    ([0, -1, 2], [True, False, False])
    >>> m.false.tolist(), m.wrong_viewpoint.tolist(), m.missed.tolist()
    ([1, 2], [2], [2])
    """
    det_boxes = shaped_array("det_boxes", det_boxes, (0, 4) if np.size(det_boxes) == 0 else (None, 4))
    D = len(det_boxes)
    det_alpha = shaped_array("det_alpha", det_alpha, (D,))
    labels = list(labels)
    cars = np.array([i for i, o in enumerate(labels) if is_type(o.type, car_types)], dtype=int)
    gt_boxes = np.array([labels[g].box for g in cars]).reshape(-1, 4)
    match, iou = match_detections(det_boxes, det_scores, gt_boxes, iou_threshold=iou_threshold)
    match = np.append(cars, -1)[match]  # indices into the labels (-1, unmatched, picks the -1 appended)
    checked = np.isfinite(det_alpha)
    tol = np.deg2rad(viewpoint_tolerance_deg) + 1e-9
    # rejected only where the difference exceeds the tolerance: a label's NaN alpha fails no test, as in evaluate
    positive = np.array([g >= 0 and not (checked[d] and angle_difference(det_alpha[d], labels[g].alpha) > tol)
                         for d, g in enumerate(match)], dtype=bool).reshape(D)
    return FrameMatches(cars, match, iou, checked, positive)


def match_estimate(
    estimate: SceneEstimate,
    labels: Sequence[Label],
    *,
    detections: Detections | None = None,
    iou_threshold: float = 0.5,
    viewpoint_tolerance_deg: float = 45.0,
    car_types: Sequence[str] = CAR_TYPES,
) -> FrameMatches:
    """Which cars of a fitted ``estimate`` are true positives, which false, and which labelled
    cars were missed: :func:`match_frame` on the pre-detections of its cars, exactly as
    :func:`~wirescene.eval.metrics.evaluate` judges the record :func:`wirescene.eval.runner.frame_result` makes of
    the same fit (the pre-detections the fit's verification dropped are no car output).

    Parameters
    ----------
    estimate : SceneEstimate
        What :func:`wirescene.fit` returned; detection ``d`` of the result is its car
        ``estimate.cars[d]``, numbered ``#d+1`` in the label file and the pictures.
    labels : sequence of Label
        The frame's labels: every line, or the cars only (as the pictures draw them); the
        indices of :attr:`FrameMatches.missed` and ``match`` are into this sequence.
    detections : Detections, optional
        The pre-detections the estimate was fitted to; default ``estimate.detections``.
    iou_threshold, viewpoint_tolerance_deg, car_types
        As of :func:`~wirescene.eval.metrics.evaluate`.

    Returns
    -------
    FrameMatches

    Raises
    ------
    ValueError
        Where the pre-detections are unknown or the cars are not one per pre-detection.

    Examples
    --------
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate
    >>> from wirescene.io.kitti import Label
    >>> dets = Detections([[100, 100, 200, 160], [700, 120, 760, 150]], scores=[0.9, 0.8], alpha=np.nan)
    >>> cars = [ObjectEstimate(detection_index=i, box2d=dets.boxes[i], score=0.5, location=np.array([2.0, 1.6, 20.0]),
    ...                        R=rotation_y(0.4), dims=np.array([1.5, 1.6, 4.0]), cost=0.0) for i in (0, 1)]
    >>> labels = [Label("Car", 0.0, 0, 0.3, [100, 100, 200, 160], [1.5, 1.6, 4.0], [2.0, 1.6, 20.0], 0.4),
    ...           Label("Car", 0.0, 0, 0.3, [900, 110, 1000, 170], [1.5, 1.6, 4.0], [12.0, 1.6, 20.0], 0.9)]
    >>> m = match_estimate(SceneEstimate("coarse", cars, detections=dets), labels)
    >>> m.false.tolist(), m.missed.tolist()  # car #2 on no labelled car; the second label missed
    ([1], [1])
    """
    detections = estimate.detections if detections is None else detections
    if detections is None:
        raise ValueError("the estimate carries no pre-detections (estimate.detections): pass detections")
    index = [o.detection_index for o in estimate.cars]
    if len(set(index)) != len(index) or any(not 0 <= i < len(detections) for i in index):
        raise ValueError("estimate must hold at most one car per pre-detection, each of the detections given")
    fitted = fitted_detections(detections, estimate)  # in the cars' order, as the evaluation's record
    return match_frame(fitted.boxes, fitted.scores, fitted.alpha, labels, iou_threshold=iou_threshold,
                       viewpoint_tolerance_deg=viewpoint_tolerance_deg, car_types=car_types)
