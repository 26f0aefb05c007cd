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
detections; made geometric, it knows that a car on the road is aligned with it
(:func:`box_log_prior`). A crop classifier
(:mod:`wirescene.predetect.viewpoint_classifier`) may add what the templates miss (front
against back). Given the camera, the boxes of a frame then choose their bins together, so
that cars of one row face the same way (:func:`row_coherent_bins`), and each viewpoint is
its bin's centre.

Held out by drive on the 72 shared KITTI frames (``benchmarks/bench_box_viewpoints.py``:
each fold's bank and classifier trained without its drives; settings chosen on fold group
(0, 1), 148 cars, reported on (2, 3), 146 cars), label boxes given without a viewpoint come
out within 45 deg for 80.8% of the cars of (2, 3) (81.8% on (0, 1); 77.4% with the boxes
jittered by 5% of their size) with the README's fold banks, 83.6% (84.5%) with the banks the
rule's weights were chosen with; there each box alone 77.4% (81.1%; 74.7%), the templates
alone 63.0%, the classifier alone 72.6%, the part evidence
(:func:`~wirescene.infer.evidence.viewpoint_from_evidence`) 55%, and adding it to the
rule gains nothing on (0, 1). On the 169 cars the README's fold banks find at the fit's
threshold, the rule gets 84.6% right, the bank's own detections 82.8% (benchmarks/RESULTS.md).
"""

from __future__ import annotations

import numpy as np

from wirescene.core.boxes import clip_boxes, iou_2d
from wirescene.core.errors import ArgumentError, InputError, check_shape
from wirescene.core.groundplane import KITTI_MOUNT, Mount, rotation_y_from_alpha
from wirescene.core.validate import MIN_IMAGE_SIDE, boxes_problem
from wirescene.core.viewpoints import N_BINS, bin_center
from wirescene.predetect.bank import (
    DetectorBank,
    apply_box_regression,
    bank_scales,
    template_responses,
    traffic_log_prior,
)
from wirescene.predetect.geometry import road_horizon
from wirescene.predetect.hog import CELL, hog_cells, level_image, level_size, to_gray

#: Overlap (IoU of a window's predicted car box with the given box) for a window to vote.
IOU = 0.5
#: Margin a bin scores at least (the lowest activation :func:`~wirescene.predetect.bank.detect_pyramid`
#: keeps at the shipped threshold), so that one bin's missing window does not rule it out.
FLOOR_MARGIN = -1.0
#: Weight of the log prior against the templates' log-odds (1 would be naive Bayes, as
#: :func:`~wirescene.predetect.bank.traffic_viewpoints`; 2 chosen on fold group (0, 1): the
#: templates' log-odds are calibrated for car against background, not for one bin against another).
PRIOR_WEIGHT = 2.0
#: Width (radians) of the road-aligned prior's kernel around the two headings along the road
#: (:func:`box_log_prior`; None: the traffic prior alone).
ROAD_SPREAD: float | None = 0.2
#: Share of the road-aligned prior spread evenly over the bins: cars not aligned with the road.
UNALIGNED = 0.05
#: Weight of the agreement of cars in one row (:func:`row_coherent_bins`) against the bins'
#: summed log scores (0: each box alone); with :data:`ROW_WIDTH`, chosen on fold group (0, 1).
ROW_WEIGHT = 2.0
#: Lateral distance (m) at which two cars' agreement counts ``exp(-1/2)`` of a row's: the
#: width of a Gaussian of their lateral offset (a lane or a parked row is about 2-3.5 m wide).
ROW_WIDTH = 3.0
#: Cars further apart along the camera's axis (m) are not counted as one row.
ROW_DEPTH = 30.0
# Car height (m) that places a box from its pixel height alone, for the rows.
_CAR_HEIGHT = 1.5
# Most sweeps of iterated conditional modes (it stops earlier once no bin changes).
_SWEEPS = 5
# Factor by which the box regression may change a vote's height, at most (the shipped bank's
# moves it by 0.84-1.23x), so windows beyond it cannot reach the IoU and are not scored.
_REGRESSION_SLACK = 1.5


def _check_image(image) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim not in (2, 3) or min(image.shape[:2]) < MIN_IMAGE_SIDE:
        raise InputError(f"expected an (H, W, 3) image, got shape {image.shape}")
    return image


def _check_boxes(boxes, image_size=None) -> np.ndarray:
    b = np.asarray(boxes)
    if b.size == 0:
        b = b.reshape(0, 4)
    check_shape("boxes", b, (None, 4))
    problem = boxes_problem(b, image_size)
    if problem:
        raise ArgumentError("boxes", problem)
    return b.astype(float)


def _window_ranges(bank: DetectorBank, templates, scale: float, boxes: np.ndarray, iou: float):
    """Windows (top-left cells) of the bank's ``templates`` ``(T,)`` at pyramid ``scale`` whose
    vote may overlap each of ``boxes`` ``(N, 4)`` by IoU >= ``iou``: ``(near (T, N) bool, r0, r1,
    q0, q1, votes)``, the half-open row and column ranges ``(T, N)`` (unclipped; meaningless
    where not ``near``) and the votes ``(T, 4)`` of window ``(0, 0)``, which window ``(r, q)``'s
    shift by ``CELL / scale * (q, r)``. All templates at once, each number as one at a time."""
    configs = [bank.configs[t] for t in templates]
    th = np.array([c.template[0] for c in configs], float)[:, None]
    tw = np.array([c.template[1] for c in configs], float)[:, None]
    step = CELL / scale
    wh = np.column_stack([tw * step, th * step])  # the window (0, 0): (0, 0, tw * step, th * step)
    offsets = np.array([c.offsets for c in configs], float).reshape(-1, 4)
    # Configuration.full_box of each template's window (0, 0), operation for operation
    votes = np.column_stack([np.zeros((len(configs), 2)), wh]) + offsets * np.concatenate([wh, wh], 1)
    v0, v1, v2, v3 = (votes[:, i, None] for i in range(4))
    vw, vh = v2 - v0, v3 - v1
    gw, gh = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    # the regression moves a height by < 25% and clipping only shrinks it: no IoU >= iou beyond these ratios
    near = (vh >= iou / _REGRESSION_SLACK * gh) & (vh <= _REGRESSION_SLACK / iou * gh)
    # the vote of window (r, q) is that of (0, 0) shifted by step * (q, r): votes that intersect the
    # box, with room for the regression's shift
    rx, ry = 0.5 * (gw + vw) + 0.25 * vw, 0.5 * (gh + vh) + 0.25 * vh
    cx = (boxes[:, 0] + boxes[:, 2] - v0 - v2) / 2
    cy = (boxes[:, 1] + boxes[:, 3] - v1 - v3) / 2
    q0, q1 = np.ceil((cx - rx) / step).astype(int), np.floor((cx + rx) / step).astype(int) + 1
    r0, r1 = np.ceil((cy - ry) / step).astype(int), np.floor((cy + ry) / step).astype(int) + 1
    return near, r0, r1, q0, q1, votes


def _plan(bank: DetectorBank, levels, boxes: np.ndarray, iou: float) -> list:
    """Per pyramid level ``(index, scale, (Hc, Wc) cells)`` of ``levels``, the templates that can
    vote for some box (in bank order) with their :func:`_window_ranges`, and the cell rectangle
    ``(R0, R1, C0, C1)`` their windows cover: ``[(index, scale, rectangle, {t: ranges})]``; levels
    no template can use are left out."""
    out = []
    shapes = np.array([c.template for c in bank.configs], int).reshape(-1, 2)
    for li, scale, (Hc, Wc) in levels:
        fits = np.flatnonzero((shapes[:, 0] <= Hc) & (shapes[:, 1] <= Wc))
        if not len(fits):
            continue
        ranges = _window_ranges(bank, fits, scale, boxes, iou)
        near, r0, r1, q0, q1, _ = ranges
        th, tw = shapes[fits, 0, None], shapes[fits, 1, None]
        r0, r1 = np.maximum(r0, 0), np.minimum(r1, Hc - th + 1)
        q0, q1 = np.maximum(q0, 0), np.minimum(q1, Wc - tw + 1)
        ok = near & (r1 > r0) & (q1 > q0)
        use = np.flatnonzero(ok.any(1))
        if not len(use):
            continue
        rect = (int(r0[ok].min()), int((r1 + th - 1)[ok].max()), int(q0[ok].min()), int((q1 + tw - 1)[ok].max()))
        out.append((li, scale, rect, {int(fits[i]): tuple(a[i] for a in ranges) for i in use}))
    return out


def _region_features(gray: np.ndarray, scale: float, rect) -> np.ndarray:
    """The cells ``rect`` ``(R0, R1, C0, C1)`` of the image's pyramid level ``scale``, exactly as
    :func:`~wirescene.predetect.hog.feature_pyramid` computes them, from that rectangle alone."""
    H, W = gray.shape
    w, h = level_size(W, H, scale)
    im = level_image(gray, scale)
    R0, R1, C0, C1 = rect
    # two cells of margin: a cell's features depend on its neighbours' gradients and energies only
    y0, y1 = max(R0 - 2, 0), min(R1 + 2, h // CELL)
    x0, x1 = max(C0 - 2, 0), min(C1 + 2, w // CELL)
    f = hog_cells(im[y0 * CELL:y1 * CELL, x0 * CELL:x1 * CELL])
    return f[R0 - y0:R1 - y0, C0 - x0:C1 - x0]


def _best_votes(bank: DetectorBank, scale: float, responses, ranges, origin, boxes: np.ndarray, image_size,
                iou: float, floor: float) -> np.ndarray:
    """``(N, 8)`` best response per box and viewpoint bin among the windows of the response
    maps ``responses`` ``[(t, R)]`` of templates ``t`` at pyramid ``scale`` (entry ``(r, q)``
    of ``R`` scores the window whose top-left cell is ``origin + (r, q)``; ``ranges``: their
    :func:`_window_ranges` by template, as :func:`_plan` gives them) whose vote
    overlaps each of ``boxes`` ``(N, 4)`` by IoU >= ``iou``; ``floor`` where none above
    ``floor`` does (windows at or below it are not placed: what they would give, the floor
    replaces). All templates of a level at once: one box regression and one overlap test
    for their windows."""
    W, H = image_size
    step = CELL / scale
    o_r, o_q = origin
    out = np.full((len(boxes), N_BINS), float(floor))
    idx, rows, cols, vote0, bins, values = [], [], [], [], [], []
    for t, R in responses:
        config = bank.configs[t]
        near, r0, r1, q0, q1, vote = ranges[t]
        r0, r1 = np.maximum(r0, o_r), np.minimum(r1, o_r + R.shape[0])
        q0, q1 = np.maximum(q0, o_q), np.minimum(q1, o_q + R.shape[1])
        sel = np.flatnonzero(near & (r1 > r0) & (q1 > q0))
        if not len(sel):
            continue
        # each selected box's rectangle of windows, row by row
        nq, counts = (q1 - q0)[sel], (r1 - r0)[sel] * (q1 - q0)[sel]
        k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        nq_w = np.repeat(nq, counts)
        r, q = np.repeat(r0[sel], counts) + k // nq_w, np.repeat(q0[sel], counts) + k % nq_w
        value = R[r - o_r, q - o_q].astype(float)
        above = value > floor
        idx.append(np.repeat(sel, counts)[above])
        rows.append(r[above])
        cols.append(q[above])
        vote0.append(np.broadcast_to(vote, (int(above.sum()), 4)))
        bins.append(np.full(len(rows[-1]), config.bin))
        values.append(value[above])
    if not idx:
        return out
    idx, rows, cols, bins = (np.concatenate(a) for a in (idx, rows, cols, bins))
    if not len(idx):
        return out
    votes = clip_boxes(np.concatenate(vote0) + step * np.column_stack([cols, rows, cols, rows]), W, H)
    regression = bank.meta.get("box_regression")
    if regression is not None:
        votes = clip_boxes(apply_box_regression(regression, votes, bins, (W, H)), W, H)
    ok = iou_2d(votes, boxes[idx]) >= iou
    np.maximum.at(out, (idx[ok], bins[ok]), np.concatenate(values)[ok])
    return out


def box_bin_log_odds(bank: DetectorBank, image: np.ndarray, boxes, *, pyramid=None, iou: float = IOU,
                     floor_margin: float = FLOOR_MARGIN, responses: dict | None = None) -> np.ndarray:
    """Score the 8 viewpoint bins inside given boxes with the bank's templates.

    Parameters
    ----------
    bank : DetectorBank
    image : (H, W, 3) uint8 array
    boxes : (N, 4) array
        ``x1 y1 x2 y2`` in pixels.
    pyramid : list of (float, ndarray), optional
        :func:`wirescene.predetect.hog.feature_pyramid` of the image if already computed;
        without it only the cells of the bank's pyramid levels (``meta["max_scale"]``,
        ``meta["per_octave"]``) that some box's windows cover are computed, to the same values.
    iou : float, optional
        Overlap of a window's predicted car box with a box for the window to vote.
    floor_margin : float, optional
        Margin each bin scores at least.
    responses : dict, optional
        The templates' response maps on ``pyramid`` by ``(template, level)``, as the bank's
        detection left them (:func:`~wirescene.predetect.bank.detect_cars`'s ``responses``):
        read where they hold a level's template, computed where they do not (all computed
        without ``pyramid``).

    Returns
    -------
    (N, 8) ndarray
        Per box and bin the calibrated log-odds of the bin's best vote (raw margins for an
        uncalibrated bank).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.predetect import load_default_bank
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> box_bin_log_odds(load_default_bank(), image, np.array([[10.0, 10.0, 70.0, 40.0]])).shape
    (1, 8)
    """
    image = _check_image(image)
    H, W = image.shape[:2]
    b = _check_boxes(boxes)
    best = np.full((len(b), N_BINS), -np.inf)
    if len(b):
        if pyramid is None:
            scales = bank_scales(bank, W, H)
            gray = to_gray(image)
            levels = [(li, s, tuple(n // CELL for n in level_size(W, H, s)[::-1])) for li, s in enumerate(scales)]
        else:
            levels = [(li, s, F.shape[:2]) for li, (s, F) in enumerate(pyramid)]
        for li, scale, rect, ranges in _plan(bank, levels, b, iou):
            R0, R1, C0, C1 = rect
            known = [] if pyramid is None or responses is None else [t for t in ranges if (t, li) in responses]
            maps = [(t, responses[(t, li)][R0:R1 - bank.configs[t].template[0] + 1,
                                           C0:C1 - bank.configs[t].template[1] + 1]) for t in known]
            rest = [t for t in ranges if t not in known]
            if rest:
                F = _region_features(gray, scale, rect) if pyramid is None else pyramid[li][1][R0:R1, C0:C1]
                maps += [(t, R) for t, _, _, R in template_responses(bank, [(scale, F)], min_height=0.0,
                                                                     max_height=np.inf, detectors=rest)]
            best = np.maximum(best, _best_votes(bank, scale, maps, ranges, (R0, C0), b, (W, H), iou, floor_margin))
    best = np.maximum(best, floor_margin)
    if bank.calibration is not None:
        a, c = (float(v) for v in bank.calibration)
        best = a * best + c
    return best


def box_log_prior(bank: DetectorBank, boxes, camera, *, road_spread: float | None = ROAD_SPREAD,
                  mount: Mount = KITTI_MOUNT) -> np.ndarray | None:
    """Log prior of the 8 viewpoint bins of boxes from where they stand on the road.

    The bank's traffic prior (:func:`~wirescene.predetect.bank.traffic_log_prior`) gives
    P(bin | lateral position). With ``road_spread``, the prior also knows that a car on
    the road is aligned with it: seen along the ray at angle ``theta`` (right positive) from
    the optical axis, a car facing the camera has ``alpha = pi/2 - theta`` and one facing
    away ``alpha = -pi/2 - theta`` (KITTI's ``alpha = rotation_y - theta``). The traffic
    prior's mass of the front bins (1-3) goes to the first, that of the back bins (5-7) to
    the second, each spread over the bins by a von Mises kernel of width ``road_spread``
    (radians; roads bend), the side bins (0, 4: crossing cars) keep theirs, and a share
    :data:`UNALIGNED` is spread evenly (cars parked askew, turning).

    Parameters
    ----------
    bank : DetectorBank
    boxes : (N, 4) array
    camera : Camera
    road_spread : float or None, optional
        None: the traffic prior alone, as for the bank's own detections.
    mount : Mount, optional
        The camera's height above the road (m) and pitch down from it (deg;
        :class:`~wirescene.core.groundplane.Mount`), which place the horizon
        (:func:`~wirescene.predetect.geometry.road_horizon`); the traffic prior was learned
        on KITTI's level rig.

    Returns
    -------
    (N, 8) ndarray or None
        None for a bank without a viewpoint prior or a calibration.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> from wirescene.predetect import load_default_bank
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> prior = box_log_prior(load_default_bank(), [[900.0, 180, 1000, 250]], camera)
    >>> prior.shape, bool(np.allclose(np.exp(prior).sum(1), 1.0))
    ((1, 8), True)
    """
    b = _check_boxes(boxes)
    K = np.asarray(camera.K, float)
    log_prior = traffic_log_prior(bank, b, road_horizon(camera, mount), float(K[0, 2])) if len(b) else None
    if log_prior is None or road_spread is None:
        return log_prior
    p = np.exp(log_prior)
    theta = np.arctan2((b[:, 0] + b[:, 2]) / 2 - K[0, 2], K[0, 0])
    centres = bin_center(np.arange(N_BINS))

    def kernel(mu):
        k = np.exp((np.cos(centres[None] - mu[:, None]) - 1.0) / road_spread ** 2)
        return k / k.sum(1, keepdims=True)

    road = (p[:, [1, 2, 3]].sum(1, keepdims=True) * kernel(np.pi / 2 - theta)
            + p[:, [5, 6, 7]].sum(1, keepdims=True) * kernel(-np.pi / 2 - theta))
    road[:, [0, 4]] += p[:, [0, 4]]
    return np.log((1.0 - UNALIGNED) * road + UNALIGNED / N_BINS)


def box_viewpoints(bank: DetectorBank, image: np.ndarray, boxes, *, camera=None, classifier=None, iou: float = IOU,
                   floor_margin: float = FLOOR_MARGIN, prior_weight: float = PRIOR_WEIGHT,
                   road_spread: float | None = ROAD_SPREAD, pyramid=None, row_weight: float = ROW_WEIGHT,
                   responses: dict | None = None, mount: Mount = KITTI_MOUNT) -> np.ndarray:
    """The viewpoint of each given box, scored by the bank's configuration detectors (and a
    crop classifier): the bin maximising the templates' log-odds, plus the classifier's
    log-probability, plus ``prior_weight`` times the road prior; given the camera, the boxes
    of one row of cars agree (:func:`row_coherent_bins`).

    Parameters
    ----------
    bank : DetectorBank
    image : (H, W, 3) uint8 array
    boxes : (N, 4) array
        ``x1 y1 x2 y2`` in pixels, e.g. another detector's boxes.
    camera : Camera, optional
        With it, the prior of where each box stands on the road (:func:`box_log_prior`)
        weighs the bins, front against back above all.
    classifier : ViewpointClassifier, optional
        A crop classifier (:mod:`wirescene.predetect.viewpoint_classifier`) whose
        log-probabilities are added (None: the templates alone).
    iou, floor_margin : float, optional
        See :func:`box_bin_log_odds`.
    prior_weight : float, optional
        Weight of the log prior against the templates' log-odds (:data:`PRIOR_WEIGHT`).
    road_spread : float or None, optional
        See :func:`box_log_prior`.
    pyramid : list of (float, ndarray), optional
        The image's feature pyramid if already computed (see :func:`box_bin_log_odds`).
    responses : dict, optional
        The templates' response maps on ``pyramid`` (see :func:`box_bin_log_odds`).
    row_weight : float, optional
        Weight of the rows' agreement (:data:`ROW_WEIGHT`; 0: each box alone). Pass every box
        of the frame at once: the rows are made of the boxes given.
    mount : Mount, optional
        The camera's height above the road and pitch down from it, for the road prior
        (:func:`box_log_prior`).

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
    image = _check_image(image)
    H, W = image.shape[:2]
    b = _check_boxes(boxes, (W, H))
    if not len(b):
        return np.zeros(0)
    scores = box_bin_log_odds(bank, image, b, pyramid=pyramid, iou=iou, floor_margin=floor_margin, responses=responses)
    if classifier is not None:
        scores = scores + classifier.log_probs(image, b)
    prior = None if camera is None else box_log_prior(bank, b, camera, road_spread=road_spread,
                                                       mount=mount)
    if prior is not None:
        scores = scores + prior_weight * prior
    if camera is None:
        return bin_center(np.argmax(scores, axis=1))
    return bin_center(row_coherent_bins(scores, b, camera, weight=row_weight))


def box_ground_positions(boxes, camera) -> tuple[np.ndarray, np.ndarray]:
    """Rough lateral and forward positions ``(x (N,), z (N,))`` (metres, KITTI camera frame)
    of boxes ``(N, 4)``: the distance at which a car :data:`_CAR_HEIGHT` high fills the box's
    height, along the ray through the box's centre column. Enough to tell rows of cars apart,
    nothing finer (a car 10% taller than assumed stands 10% nearer).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> x, z = box_ground_positions([[630.0, 150, 750, 204]], camera)
    >>> float(np.round(x[0], 2)), float(np.round(z[0], 2))
    (2.5, 20.0)
    """
    b = _check_boxes(boxes)
    K = np.asarray(camera.K, float)
    z = K[1, 1] * _CAR_HEIGHT / np.maximum(b[:, 3] - b[:, 1], 1.0)
    x = ((b[:, 0] + b[:, 2]) / 2 - K[0, 2]) * z / K[0, 0]
    return x, z


def row_coherent_bins(scores, boxes, camera, *, weight: float = ROW_WEIGHT, width: float = ROW_WIDTH,
                      depth: float = ROW_DEPTH) -> np.ndarray:
    """The bin of each box, chosen for all boxes of a frame at once: cars in one row share
    their heading.

    Cars of one lane, or parked in one row, nearly always face the same way (in the labels
    of the 72 shared KITTI frames, of the pairs less than 1.5 m apart laterally and 25 m
    along the road, 165 have headings within 45 deg and 6 opposite). The bins maximise

        sum_i scores[i, b_i] + weight * sum_{i<j} n_ij cos(ry_i(b_i) - ry_j(b_j)),

    where ``ry`` is the heading (KITTI ``rotation_y``) of a bin's centre at the box's position
    (:func:`box_ground_positions`) and ``n_ij = exp(-dx^2 / (2 width^2))`` for boxes less than
    ``depth`` apart along the camera's axis (else 0), by iterated conditional modes from each
    box's best bin. A box alone, or far from the others, keeps its best bin; a weak front
    against back decision follows its row's confident ones.

    Parameters
    ----------
    scores : (N, 8) array
        Log scores of the bins of each box (e.g. :func:`box_viewpoints`' sum).
    boxes : (N, 4) array
    camera : Camera
    weight, width, depth : float, optional
        :data:`ROW_WEIGHT`, :data:`ROW_WIDTH` (m), :data:`ROW_DEPTH` (m).

    Returns
    -------
    (N,) int ndarray

    Examples
    --------
    Two cars one behind the other; the far one's back is only slightly less likely than its
    front, the near one is clearly seen from the back (bin 6, ``alpha = -pi/2``):

    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> boxes = np.array([[560.0, 140, 640, 200], [580.0, 160, 620, 190]])
    >>> scores = np.full((2, 8), -5.0)
    >>> scores[0, 6], scores[1, 2], scores[1, 6] = 0.0, -0.2, -0.5
    >>> row_coherent_bins(scores, boxes, camera, weight=0.0).tolist()
    [6, 2]
    >>> row_coherent_bins(scores, boxes, camera).tolist()
    [6, 6]
    """
    s = np.asarray(scores, float)
    b = _check_boxes(boxes)
    check_shape("scores", s, (len(b), N_BINS))
    best = np.argmax(s, axis=1)
    if len(b) < 2 or weight == 0:
        return best
    x, z = box_ground_positions(b, camera)
    near = np.exp(-0.5 * ((x[:, None] - x[None]) / width) ** 2) * (np.abs(z[:, None] - z[None]) < depth)
    np.fill_diagonal(near, 0.0)
    heading = rotation_y_from_alpha(bin_center(np.arange(N_BINS))[None, :], x[:, None], z[:, None])  # (N, 8)
    rows = np.arange(len(b))
    for _ in range(_SWEEPS):
        before = best.copy()
        for i in np.flatnonzero(near.any(1)):
            agree = near[i] @ np.cos(heading[i][None, :] - heading[rows, best][:, None])
            best[i] = int(np.argmax(s[i] + weight * agree))
        if np.array_equal(best, before):
            break
    return best
