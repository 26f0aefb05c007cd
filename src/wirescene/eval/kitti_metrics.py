"""The KITTI object benchmark's evaluation (2D AP, AOS, bird's-eye-view AP, 3D AP) in numpy.

This re-implements the rules of the official KITTI object development kit
(``devkit_object/readme.txt`` and ``cpp/evaluate_object.cpp`` of the 3D object benchmark,
http://www.cvlibs.net/datasets/kitti/eval_object.php), vectorised over all frames so that a
3,769-frame validation split takes seconds on one core. The rules, per class (here: Car),
difficulty and metric:

Difficulty (:data:`MIN_HEIGHT`, :data:`MAX_OCCLUSION`, :data:`MAX_TRUNCATION`)
    easy / moderate / hard admit ground truth with 2D box height ``y2 - y1 >= 40 / 25 / 25``
    px, occlusion flag ``<= 0 / 1 / 2`` and truncation ``<= 0.15 / 0.30 / 0.50``; the
    levels are nested (moderate contains easy).
Ground truth
    A ``Car`` inside the difficulty counts (recall denominator). A ``Car`` outside it and
    every ``Van`` (the neighbouring class) is *ignored*: it may absorb a detection, which
    then is neither TP nor FP, and missing it is no FN. Other classes play no part.
    Type names compare case-insensitively.
Detections
    Only ``Car`` detections are evaluated, except that *any* detection whose 2D box is lower
    than the difficulty's minimum height (``|y2 - y1| < MIN_HEIGHT``) is an ignored
    detection: it may be assigned to a ground truth (which then is neither TP nor FN) and
    is never an FP. (That this also holds for detections of other classes is a quirk of
    the devkit, kept.)
Matching (per frame, ground truth in file order)
    A pair is a candidate if its overlap is strictly greater than the minimum overlap
    (Car: 0.7 for 2D, BEV and 3D). To collect score thresholds every ground truth takes
    the unassigned candidate with the highest score (ties: first in the file); for the
    precision/recall points it takes, among unassigned candidates scoring at least the
    threshold, the non-ignored one of largest overlap (ties: first), else the first
    ignored one.
DontCare
    Unassigned detections overlapping a ``DontCare`` region by more than the minimum
    overlap, measured as intersection over the *detection's* area, are not FPs. The
    devkit tests this with the metric's own overlap function; KITTI's DontCare rows have
    no 3D box (location -1000 m, size -1), so it only ever acts in the 2D/AOS evaluation,
    which is where it is applied here.
Thresholds (41 sample points)
    The scores of the TPs of the first pass are sorted (descending) and, walking along
    them, a score is kept whenever its recall ``(i + 1) / n_gt`` is the closest to the next
    of the recall steps 0, 1/40, 2/40, ... (the devkit's ``getThresholds``), giving at most
    41 thresholds. At each threshold TP, FP and FN are counted over all frames;
    precision ``TP / (TP + FP)`` and orientation similarity ``sum_TP (1 + cos(dalpha)) / 2
    / (TP + FP)`` (FPs contribute 0) are made monotone by taking the maximum over this and
    all later thresholds; missing points are 0.
AP
    R40 (KITTI's rule since 2019): the mean of the 40 points 1..40 (recall 0 excluded);
    R11 (before 2019): the mean of the 11 points 0, 4, ..., 40. In percent.
Overlaps
    2D: box intersection over union (no +1 pixel). BEV: area IoU of the rotated
    ``l x w`` footprints in the camera's x-z plane (exact convex-polygon intersection).
    3D: footprint intersection times the overlap of the vertical extents ``[y - h, y]``
    (y points down, ``y`` is the bottom), over the union of the volumes.
AOS
    Computed with the 2D evaluation, and only if no detection row has ``alpha == -10``
    (the devkit's "no orientation" marker).

Where the devkit prints no figure this module gives ``None``: a metric is evaluated for a
class only if at least one detection of the class has a valid 2D box (``x1 >= 0``, for 2D
and AOS) or location (``!= -1000``, for BEV and 3D), and an AP needs ground truth of the
difficulty (the devkit would print 0 there, a division by zero in its recall).

Resampled sets of frames (a bootstrap over drives, :func:`wirescene.eval.intervals.kitti_intervals`)
are evaluated at once: :func:`kitti_curves` with ``frame_weights`` gives the curves of each
set, frames counted as often as drawn, the same as the devkit on the repeated frames. The
matching is per frame, so it runs once (the second pass at every level of each frame's own
scores); each set picks its own thresholds and sums the frames' counts.

Two things go beyond the official devkit, which evaluates Car at IoU 0.7 only: the
``"iou_0.5"`` block evaluates all four metrics at 0.5 (the common secondary setting of
monocular 3D papers; note that OpenPCDet's "AP@0.70, 0.50, 0.50" keeps 2D and AOS at 0.7,
which equal our top-level (``"car"``, IoU 0.7) figures), and a frame without a prediction file counts as a
frame without detections (the official devkit refuses to evaluate then).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from wirescene.core.errors import InputError, check_shape
from wirescene.core.labels import ALPHA_NOT_ESTIMATED, CAR_TYPES, FrameLabels, Label, is_type
from wirescene.core.validate import path_problem
from wirescene.io.kitti import read_labels

DIFFICULTIES = ("easy", "moderate", "hard")
#: Minimum 2D box height (pixels) per difficulty, of ground truth and detections.
MIN_HEIGHT = (40.0, 25.0, 25.0)
#: Maximum occlusion flag of counted ground truth per difficulty.
MAX_OCCLUSION = (0, 1, 2)
#: Maximum truncation of counted ground truth per difficulty.
MAX_TRUNCATION = (0.15, 0.3, 0.5)
#: Sampled recall steps of the precision curve (the devkit's ``N_SAMPLE_PTS``).
N_SAMPLE_PTS = 41
#: Neighbouring classes: ignored ground truth, neither FN nor FP when matched.
NEIGHBOURS = {"car": ("van",), "pedestrian": ("person_sitting",), "cyclist": ()}
#: The devkit's minimum overlap per class (2D, BEV and 3D alike).
MIN_OVERLAP = {"car": 0.7, "pedestrian": 0.5, "cyclist": 0.5}
METRICS = ("2d", "bev", "3d")

# The devkit's placeholders for "not given".
_NO_ALPHA = ALPHA_NOT_ESTIMATED
_NO_LOCATION = -1000.0


# --------------------------------------------------------------------------- overlaps


def box_overlap_2d(a: np.ndarray, b: np.ndarray, *, criterion: str = "union") -> np.ndarray:
    """Overlap of 2D boxes ``(..., 4)`` (``x1 y1 x2 y2``, broadcasting), the devkit's way.

    ``criterion="union"`` gives intersection over union, ``"a"`` intersection over the
    area of ``a`` (the DontCare test, ``a`` the detection). Boxes that do not intersect
    (zero or negative width or height of the intersection) give 0.

    Examples
    --------
    >>> round(float(box_overlap_2d([0, 0, 10, 10], [5, 0, 15, 10])), 4)  # 50 / 150
    0.3333
    >>> float(box_overlap_2d([0, 0, 10, 10], [5, 0, 15, 10], criterion="a"))  # 50 / 100
    0.5
    >>> a, b = np.array([[0.0, 0, 10, 10]]), np.array([[5.0, 0, 15, 10], [20, 20, 30, 30]])
    >>> box_overlap_2d(a[:, None], b[None]).round(3)  # (1, 2): every pair by broadcasting
    array([[0.333, 0.   ]])
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    check_shape("a", a, (..., 4))
    check_shape("b", b, (..., 4))
    w = np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0])
    h = np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1])
    hit = (w > 0) & (h > 0)
    inter = np.where(hit, w * h, 0.0)
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    if criterion == "union":
        denom = area_a + (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1]) - inter
    elif criterion == "a":
        denom = area_a
    else:
        raise ValueError(f"criterion must be 'union' or 'a', got {criterion!r}")
    return np.where(hit, inter / np.where(hit & (denom != 0), denom, 1.0), 0.0)


def bev_corners(location: np.ndarray, dims: np.ndarray, rotation_y: np.ndarray) -> np.ndarray:
    """Footprints ``(N, 4, 2)`` (camera ``x``, ``z``) of KITTI boxes, clockwise in ``(x, z)``
    coordinates (a negative shoelace area; either order suits :func:`convex_intersection_area`):
    the object's length ``l`` along ``(cos ry, -sin ry)``, its width ``w`` across, as in the
    devkit (and :func:`wirescene.core.boxes.box_corners`).

    Examples
    --------
    >>> bev_corners([0.0, 1.6, 10.0], [1.5, 1.6, 4.0], 0.0)  # 4 m long along x, 1.6 m wide along z
    array([[[ 2. , 10.8],
            [ 2. ,  9.2],
            [-2. ,  9.2],
            [-2. , 10.8]]])
    """
    location = np.asarray(location, dtype=float).reshape(-1, 3)
    dims = np.asarray(dims, dtype=float).reshape(-1, 3)
    ry = np.asarray(rotation_y, dtype=float).reshape(-1)
    c, s = np.cos(ry), np.sin(ry)
    half_l, half_w = dims[:, 2] / 2, dims[:, 1] / 2
    # object-frame (x, z) corners, then rotated by R_y: x' = c x + s z, z' = -s x + c z
    ox = np.stack([half_l, half_l, -half_l, -half_l], axis=1)
    oz = np.stack([half_w, -half_w, -half_w, half_w], axis=1)
    x = location[:, 0:1] + c[:, None] * ox + s[:, None] * oz
    z = location[:, 2:3] - s[:, None] * ox + c[:, None] * oz
    return np.stack([x, z], axis=-1)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _signed_area(poly: np.ndarray) -> np.ndarray:
    return 0.5 * _cross(poly, np.roll(poly, -1, axis=-2)).sum(axis=-1)


def convex_intersection_area(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Exact area of the intersection of convex quadrilaterals ``p``, ``q`` ``(N, 4, 2)``
    (either orientation).

    The intersection polygon is the convex hull of the vertices of each polygon inside
    the other and of the crossings of their edges; these points are ordered by angle
    about their mean and their area summed with the shoelace formula, all as array
    operations over the ``N`` pairs.

    Examples
    --------
    >>> square = np.array([[[0.0, 0], [2, 0], [2, 2], [0, 2]]])
    >>> convex_intersection_area(square, square + 1)  # two 2 x 2 squares sharing a 1 x 1 corner
    array([1.])
    """
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    check_shape("p", p, (None, 4, 2))
    check_shape("q", q, (None, 4, 2))
    n = p.shape[0]
    if n == 0:
        return np.zeros(0)
    # A relative tolerance lets shared corners and collinear edges count as inside.
    scale = np.maximum(np.abs(p).max(axis=(1, 2)), np.abs(q).max(axis=(1, 2))) + 1.0
    eps = 1e-9 * scale[:, None, None]
    sp = np.sign(_signed_area(p))[:, None, None]
    sq = np.sign(_signed_area(q))[:, None, None]

    def inside(points, poly, sign):
        # points (N, K, 2) inside poly (N, 4, 2): on the inner side of every edge
        edges = np.roll(poly, -1, axis=1) - poly  # (N, 4, 2)
        rel = points[:, :, None, :] - poly[:, None, :, :]  # (N, K, 4, 2)
        return (sign * _cross(edges[:, None, :, :], rel) >= -eps).all(axis=2)

    p_in_q = inside(p, q, sq)
    q_in_p = inside(q, p, sp)
    # edge i of p against edge j of q: p_i + t r_i = q_j + u s_j
    r = np.roll(p, -1, axis=1) - p
    s = np.roll(q, -1, axis=1) - q
    rr, ss = r[:, :, None, :], s[:, None, :, :]
    qp = q[:, None, :, :] - p[:, :, None, :]
    denom = _cross(rr, ss)
    parallel = np.abs(denom) <= 1e-12 * scale[:, None, None] ** 2
    safe = np.where(parallel, 1.0, denom)
    t = _cross(qp, ss) / safe
    u = _cross(qp, rr) / safe
    tol = 1e-9
    crossing = ~parallel & (t >= -tol) & (t <= 1 + tol) & (u >= -tol) & (u <= 1 + tol)
    cross_pts = p[:, :, None, :] + t[..., None] * rr  # (N, 4, 4, 2)
    points = np.concatenate([p, q, cross_pts.reshape(n, 16, 2)], axis=1)  # (N, 24, 2)
    valid = np.concatenate([p_in_q, q_in_p, crossing.reshape(n, 16)], axis=1)
    count = valid.sum(axis=1)
    centre = (points * valid[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None]
    angle = np.arctan2(points[..., 1] - centre[:, None, 1], points[..., 0] - centre[:, None, 0])
    order = np.argsort(np.where(valid, angle, np.inf), axis=1, kind="stable")
    ring = np.take_along_axis(points, order[..., None], axis=1)
    ring_valid = np.take_along_axis(valid, order, axis=1)
    # Unused slots repeat the first point: zero-length edges add nothing to the shoelace sum.
    ring = np.where(ring_valid[..., None], ring, ring[:, :1, :])
    area = np.abs(_signed_area(ring))
    return np.where(count >= 3, area, 0.0)


def _footprint_intersection(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry) -> np.ndarray:
    """Intersection areas of the BEV footprints of paired boxes; pairs whose bounding
    circles are apart are not clipped (area 0)."""
    a_loc, b_loc = np.asarray(a_loc, float).reshape(-1, 3), np.asarray(b_loc, float).reshape(-1, 3)
    a_dims, b_dims = np.asarray(a_dims, float).reshape(-1, 3), np.asarray(b_dims, float).reshape(-1, 3)
    radius_a = 0.5 * np.hypot(a_dims[:, 1], a_dims[:, 2])
    radius_b = 0.5 * np.hypot(b_dims[:, 1], b_dims[:, 2])
    dist = np.hypot(a_loc[:, 0] - b_loc[:, 0], a_loc[:, 2] - b_loc[:, 2])
    near = np.flatnonzero(dist < radius_a + radius_b)
    inter = np.zeros(len(a_loc))
    if len(near):
        a_ry, b_ry = np.asarray(a_ry, float).reshape(-1), np.asarray(b_ry, float).reshape(-1)
        inter[near] = convex_intersection_area(
            bev_corners(a_loc[near], a_dims[near], a_ry[near]), bev_corners(b_loc[near], b_dims[near], b_ry[near])
        )
    return inter


def _bev_from_intersection(inter, a_dims, b_dims) -> np.ndarray:
    union = a_dims[:, 1] * a_dims[:, 2] + b_dims[:, 1] * b_dims[:, 2] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _3d_from_intersection(inter, a_loc, a_dims, b_loc, b_dims) -> np.ndarray:
    top = np.maximum(a_loc[:, 1] - a_dims[:, 0], b_loc[:, 1] - b_dims[:, 0])
    bottom = np.minimum(a_loc[:, 1], b_loc[:, 1])
    inter_vol = inter * np.maximum(0.0, bottom - top)
    union = a_dims.prod(axis=1) + b_dims.prod(axis=1) - inter_vol
    return np.where(union > 0, inter_vol / np.where(union > 0, union, 1.0), 0.0)


def _paired(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry):
    a_loc, b_loc = np.asarray(a_loc, float), np.asarray(b_loc, float)
    a_dims, b_dims = np.asarray(a_dims, float), np.asarray(b_dims, float)
    a_ry, b_ry = np.asarray(a_ry, float), np.asarray(b_ry, float)
    n = a_ry.reshape(-1).shape[0]
    for name, arr, shape in (("a_loc", a_loc, (n, 3)), ("a_dims", a_dims, (n, 3)), ("b_loc", b_loc, (n, 3)),
                             ("b_dims", b_dims, (n, 3)), ("b_ry", b_ry.reshape(-1), (n,))):
        check_shape(name, arr, shape)
    return a_loc, a_dims, a_ry.reshape(-1), b_loc, b_dims, b_ry.reshape(-1)


def iou_bev(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry) -> np.ndarray:
    """Bird's-eye-view IoU of paired KITTI boxes: ``location (N, 3)``, ``dims (N, 3)`` =
    ``h w l``, ``rotation_y (N,)`` each; the rotated ``l x w`` footprints in the x-z plane.

    Examples
    --------
    >>> loc, dims = np.array([[0.0, 1.6, 20.0]]), np.array([[1.5, 1.6, 4.0]])  # h w l
    >>> iou_bev(loc, dims, [0.0], loc + [2.0, 0, 0], dims, [0.0]).round(4)  # half a length along x: 1 / 3
    array([0.3333])
    >>> iou_bev(loc, dims, [0.0], loc, dims, [np.pi / 2]).round(4)  # turned 90 deg: 1.6 x 1.6 of 10.24 m^2
    array([0.25])
    """
    a_loc, a_dims, a_ry, b_loc, b_dims, b_ry = _paired(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry)
    return _bev_from_intersection(_footprint_intersection(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry), a_dims, b_dims)


def iou_3d(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry) -> np.ndarray:
    """3D IoU of paired KITTI boxes (arguments as :func:`iou_bev`): footprint intersection
    times the overlap of the vertical extents ``[y - h, y]`` (y down, the location is the
    bottom centre), over the union of the volumes.

    Examples
    --------
    >>> loc, dims = np.array([[0.0, 1.6, 20.0]]), np.array([[1.5, 1.6, 4.0]])
    >>> iou_3d(loc, dims, [0.0], loc, dims, [0.0])
    array([1.])
    >>> iou_3d(loc, dims, [0.0], loc + [0, 0.75, 0], dims, [0.0]).round(4)  # half its height lower: 1 / 3
    array([0.3333])
    """
    a_loc, a_dims, a_ry, b_loc, b_dims, b_ry = _paired(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry)
    inter = _footprint_intersection(a_loc, a_dims, a_ry, b_loc, b_dims, b_ry)
    return _3d_from_intersection(inter, a_loc, a_dims, b_loc, b_dims)


# --------------------------------------------------------------------------- label arrays


@dataclass
class _Rows:
    """Label rows of all frames as flat arrays, frame by frame in file order."""

    frame: np.ndarray  # (N,) int
    type: np.ndarray  # (N,) lower-case str
    truncated: np.ndarray
    occluded: np.ndarray
    alpha: np.ndarray
    box: np.ndarray  # (N, 4)
    dims: np.ndarray  # (N, 3) h w l
    location: np.ndarray  # (N, 3)
    rotation_y: np.ndarray
    score: np.ndarray

    @classmethod
    def of(cls, frames: Sequence[Sequence[Label]]) -> "_Rows":
        rows = [lab for f in frames for lab in f]
        n = len(rows)
        scalars = np.array(
            [(lab.truncated, lab.occluded, lab.alpha, lab.rotation_y, np.nan if lab.score is None else lab.score)
             for lab in rows], dtype=float,
        ).reshape(n, 5)
        vectors = np.array([np.concatenate([lab.box, lab.dims, lab.location]) for lab in rows]).reshape(n, 10)
        num = np.concatenate([scalars[:, :3], vectors, scalars[:, 3:]], axis=1)
        return cls(
            frame=np.repeat(np.arange(len(frames)), [len(f) for f in frames]),
            type=np.array([lab.type.lower() for lab in rows], dtype=object),  # core.labels.is_type's rule
            truncated=num[:, 0],
            occluded=num[:, 1],
            alpha=num[:, 2],
            box=num[:, 3:7],
            dims=num[:, 7:10],
            location=num[:, 10:13],
            rotation_y=num[:, 13],
            score=num[:, 14],
        )

    def take(self, index: np.ndarray) -> "_Rows":
        return _Rows(**{k: v[index] for k, v in vars(self).items()})

    def __len__(self) -> int:
        return len(self.frame)


def _rows_of(frame: FrameLabels | Sequence[Label]) -> list[Label]:
    """All rows of a frame, DontCare regions included, in file order as far as known."""
    if isinstance(frame, FrameLabels):
        return list(frame.objects) + list(frame.dontcare)
    return list(frame)


def _pairs(frame_a: np.ndarray, frame_b: np.ndarray, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """All index pairs ``(i, j)`` with ``frame_a[i] == frame_b[j]`` (both sorted by frame),
    grouped by ``i`` and in order of ``j``."""
    b_count = np.bincount(frame_b, minlength=n_frames)
    b_start = np.concatenate([[0], np.cumsum(b_count)[:-1]])
    per_a = b_count[frame_a]
    ia = np.repeat(np.arange(len(frame_a)), per_a)
    offset = np.arange(len(ia)) - np.repeat(np.cumsum(per_a) - per_a, per_a)
    return ia, b_start[frame_a[ia]] + offset


# --------------------------------------------------------------------------- matching


def _greedy(pg, pd, rank, priority_keys, available):
    """The devkit's greedy assignment for every threshold at once.

    Parameters
    ----------
    pg, pd : (P,) int
        Candidate pairs (ground truth, detection), overlap above the minimum.
    rank : (G,) int
        Position of each ground truth in its frame (the devkit visits them in order).
    priority_keys : list of (P,) arrays
        ``np.lexsort`` keys (last = primary) ordering each ground truth's candidates by
        preference; the first available one is taken.
    available : (D, T) bool
        Whether a detection takes part at threshold ``t`` (score high enough).

    Returns
    -------
    chosen : (G, T) int
        The detection assigned to each ground truth (-1: none).
    assigned : (D, T) bool
        Detections assigned to some ground truth.
    """
    n_gt, n_t = len(rank), available.shape[1]
    chosen = np.full((n_gt, n_t), -1)
    assigned = np.zeros_like(available)
    if len(pg) == 0:
        return chosen, assigned
    order = np.lexsort([*priority_keys, pg, rank[pg]])
    pg, pd = pg[order], pd[order]
    pr = rank[pg]
    bounds = np.flatnonzero(np.diff(pr)) + 1
    # One step per rank: the ground truth of one rank lie in different frames, so they
    # never compete for a detection; earlier ranks' assignments are already made.
    for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [len(pr)]])):
        g, d = pg[lo:hi], pd[lo:hi]
        free = available[d] & ~assigned[d]  # (p, T)
        starts = np.concatenate([[0], np.flatnonzero(np.diff(g)) + 1])
        m = len(g)
        pos = np.where(free, np.arange(m)[:, None], m)
        first = np.minimum.reduceat(pos, starts, axis=0)  # (groups, T)
        hit = first < m
        det = d[np.where(hit, first, 0)]
        chosen[g[starts]] = np.where(hit, det, -1)
        rows, cols = np.nonzero(hit)
        assigned[det[rows, cols], cols] = True
    return chosen, assigned


def _threshold_columns(counts: np.ndarray, n_gt) -> np.ndarray:
    """The devkit's score thresholds for evenly spaced recall (``getThresholds``).

    ``counts`` (U,) says how often each distinct TP score occurs, scores in descending
    order. Walking along the scores, one is kept whenever its recall ``(i + 1) / n_gt`` is
    the closest to the next recall step 0, 1/40, 2/40, ...; the last is always kept.
    Returns the positions in ``counts`` of the kept scores, ascending. Counts ``(B, U)``
    with ``n_gt`` ``(B,)`` (B weighted sets of frames at once) give ``(B, 41)`` positions,
    each row's kept ones first and -1 after them."""
    counts = np.asarray(counts, dtype=float)
    rows = np.atleast_2d(counts)
    n_gt = np.broadcast_to(np.asarray(n_gt, dtype=float), (len(rows),))[:, None]
    n = np.round(rows.sum(axis=1))[:, None]
    last = n - 1
    # The recall steps as the devkit accumulates them (cumsum adds in sequence, as its loop does).
    current = np.concatenate([[0.0], np.cumsum(np.full(N_SAMPLE_PTS - 1, 1.0 / (N_SAMPLE_PTS - 1.0)))])
    # The devkit keeps score i at step c once (i + 2) / n_gt - c >= c - (i + 1) / n_gt, i.e. from about
    # i = c n_gt - 1.5 on: its own float test decides among the few integers around that.
    start = np.maximum(np.floor(current[None, :] * n_gt - 1.5) - 1, 0)  # (B, K), below the first kept
    i = start[:, :, None] + np.arange(5)  # (B, K, 5)
    c = current[None, :, None]
    with np.errstate(divide="ignore", invalid="ignore"):  # a set without ground truth keeps nothing (n = 0)
        keep = (i < last[:, :, None]) & (((i + 2) / n_gt[:, :, None] - c) >= (c - (i + 1) / n_gt[:, :, None]))
    first = np.where(keep.any(axis=2), np.take_along_axis(i, keep.argmax(axis=2)[:, :, None], 2)[:, :, 0], last)
    steps = np.arange(len(current))
    taken = np.maximum.accumulate(first - steps, axis=1) + steps  # a step's score lies past the previous step's
    kept = taken < last
    # the kept ones, then the last (-1 marks the rest)
    taken = np.where(kept, taken, -1.0)
    taken[np.arange(len(rows)), kept.sum(axis=1)] = last[:, 0]
    # every row's positions by one search: row b's counts shifted past all of row b - 1's
    shift = np.arange(len(rows))[:, None] * (n.max(initial=0) + 2)
    flat = (np.cumsum(rows, axis=1) + shift).ravel()
    columns = np.searchsorted(flat, (taken + shift).ravel(), side="right").reshape(taken.shape)
    columns = np.where((taken >= 0) & (n > 0), columns - np.arange(len(rows))[:, None] * rows.shape[1], -1)
    return columns if counts.ndim == 2 else columns[0][columns[0] >= 0]


@dataclass
class _Curve:
    precision: np.ndarray  # (41,), or (B, 41) with frame weights
    orientation: np.ndarray  # (41,) or (B, 41) orientation similarity
    n_gt: int | np.ndarray  # or (B,) float


@dataclass
class _Levels:
    """Where each detection stands in its frame, for curves of weighted frames (:func:`_levels`)."""

    level: np.ndarray  # (D,) the frame's detections scoring strictly higher
    top: np.ndarray  # (D,) the frame's detections scoring at least as high (itself and its ties)
    leader: np.ndarray  # (D,) bool: one detection of each run of equal scores in a frame
    order: np.ndarray  # (D,) the detections by descending score
    ascending: np.ndarray  # (D,) the scores, ascending

    def admitted(self, thresholds: np.ndarray) -> np.ndarray:
        """How many detections score at least each threshold ``(K,)``: a prefix of :attr:`order`."""
        return len(self.ascending) - np.searchsorted(self.ascending, thresholds, side="left")


def _levels(frame: np.ndarray, score: np.ndarray, n_frames: int) -> _Levels:
    """Each detection's place in its frame (a threshold admitting ``j`` of a frame's
    detections admits those of ``level < j``; one at a detection's score admits ``top``)."""
    order = np.lexsort((score, frame))  # by frame, scores ascending
    s, f = score[order], frame[order]
    frame_end = np.searchsorted(f, np.arange(n_frames), side="right")
    positions = np.arange(len(s))
    # Ties share their run's place: none of them scores higher than another.
    ends_run = np.ones(len(s), dtype=bool)
    ends_run[:-1] = (f[1:] != f[:-1]) | (s[1:] != s[:-1])
    starts_run = np.roll(ends_run, 1)
    run_last = np.minimum.accumulate(np.where(ends_run, positions, len(s))[::-1])[::-1] if len(s) else positions
    run_first = np.maximum.accumulate(np.where(starts_run, positions, 0)) if len(s) else positions
    level, top, leader = np.empty(len(s), dtype=int), np.empty(len(s), dtype=int), np.empty(len(s), dtype=bool)
    level[order] = frame_end[f] - 1 - run_last
    top[order] = frame_end[f] - run_first
    leader[order] = ends_run
    return _Levels(level, top, leader, np.argsort(-score, kind="stable"), np.sort(score))


def _per_frame(frame: np.ndarray, values: np.ndarray, n_frames: int) -> np.ndarray:
    """Sums ``(F, L)`` of the rows of ``values`` ``(N, L)`` per frame (``frame`` sorted)."""
    ends = np.searchsorted(frame, np.arange(n_frames), side="right")
    total = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0, dtype=float)])
    return total[ends] - total[np.concatenate([[0], ends[:-1]])]


def _evaluate(gt: _Rows, det: _Rows, dc_hit: np.ndarray | None, overlap: np.ndarray, pg, pd, *,
              class_name: str, difficulty: int, min_overlap: float, n_frames: int,
              weights: np.ndarray | None = None, levels=None) -> _Curve:
    """Precision and orientation-similarity curves of one class, difficulty and metric.

    ``gt`` holds the rows of the class and its neighbours, ``det`` the detections that
    may take part; ``(pg, pd)`` are all same-frame pairs with their ``overlap``;
    ``dc_hit`` (D,) the largest DontCare overlap of each detection (2D only).
    ``weights`` (B, F): curves of B sets of frames, each frame counted as often as its
    weight says (a bootstrap draw), with ``levels`` the detections' :func:`_levels`; the
    matching is per frame, so only the thresholds and the sums depend on the weights."""
    height = gt.box[:, 3] - gt.box[:, 1]
    hard = (gt.occluded > MAX_OCCLUSION[difficulty]) | (gt.truncated > MAX_TRUNCATION[difficulty]) | (
        height < MIN_HEIGHT[difficulty])
    counted = (gt.type == class_name) & ~hard  # ignored_gt == 0; everything else here is 1
    det_height = np.trunc(np.abs(det.box[:, 1] - det.box[:, 3]))  # an int32 in the devkit
    det_ignored = det_height < MIN_HEIGHT[difficulty]
    det_valid = ~det_ignored & (det.type == class_name)  # ignored_det == 0
    det_active = det_valid | det_ignored  # ignored_det != -1
    cand = (overlap > min_overlap) & det_active[pd]
    cg, cd, cov = pg[cand], pd[cand], overlap[cand]
    rank = np.zeros(len(gt), dtype=int)
    if len(gt):
        starts = np.concatenate([[0], np.flatnonzero(np.diff(gt.frame)) + 1])
        rank = np.arange(len(gt)) - np.repeat(starts, np.diff(np.concatenate([starts, [len(gt)]])))
    score = det.score

    # Pass 1: highest-scoring candidate, no threshold; TP scores define the thresholds.
    chosen, _ = _greedy(cg, cd, rank, [cd, -score[cd]], np.ones((len(det), 1), dtype=bool))
    c = chosen[:, 0]
    tp1 = counted & (c >= 0) & det_valid[np.maximum(c, 0)]
    tp_score, tp_frame = score[c[tp1]], gt.frame[tp1]
    distinct = np.unique(tp_score)[::-1]
    tp_column = len(distinct) - 1 - np.searchsorted(distinct[::-1], tp_score)

    n_gt_frame = np.bincount(gt.frame[counted], minlength=n_frames)
    if weights is None:  # one set of frames: pass 2 at its own thresholds, as the devkit runs it
        n_gt = float(n_gt_frame.sum())
        thresholds = distinct[_threshold_columns(np.bincount(tp_column, minlength=len(distinct)), n_gt)] if n_gt else []
        available = score[:, None] >= np.asarray(thresholds)[None, :]  # (D, K)
    else:  # any threshold leaves each frame at one of the levels its own scores make
        frame_size = np.bincount(det.frame, minlength=n_frames)
        available = levels.level[:, None] < np.arange(int(frame_size.max(initial=0)) + 1)[None, :]  # (D, L)
    # Pass 2: non-ignored candidate of largest overlap, else the first ignored one.
    ignored_key = det_ignored[cd].astype(int)
    chosen, assigned = _greedy(cg, cd, rank, [cd, np.where(det_ignored[cd], 0.0, -cov), ignored_key], available)
    safe = np.maximum(chosen, 0)
    tp_mask = counted[:, None] & (chosen >= 0) & det_valid[safe]
    not_dc = np.ones(len(det), dtype=bool) if dc_hit is None else ~(dc_hit > min_overlap)
    fp_mask = (det_valid & not_dc)[:, None] & available & ~assigned
    similarity = np.where(tp_mask, (1.0 + np.cos(gt.alpha[:, None] - det.alpha[safe])) / 2.0, 0.0)

    if weights is None:
        precision, orientation = _points(tp_mask.sum(axis=0), fp_mask.sum(axis=0), similarity.sum(axis=0))
        return _Curve(precision, orientation, int(n_gt))
    # per frame and level: TP, FP, similarity
    tables = np.stack([_per_frame(gt.frame, tp_mask, n_frames), _per_frame(det.frame, fp_mask, n_frames),
                       _per_frame(gt.frame, similarity, n_frames)])  # (3, F, L)
    # A threshold leaves each frame at the level of its detections scoring at least that much, so a draw's
    # sums there add up the step each run of equal scores makes in its frame's tables, over the detections
    # scoring at least the threshold (a prefix by descending score), each weighted by its frame's weight.
    f = det.frame
    steps = np.where(levels.leader, tables[:, f, levels.top] - tables[:, f, levels.level], 0.0)[:, levels.order]
    step_frame = f[levels.order]
    admitted = levels.admitted(distinct)  # >= 1: a TP score admits its own detection
    n_gt = weights @ n_gt_frame
    precision = np.zeros((len(weights), N_SAMPLE_PTS))
    orientation = np.zeros((len(weights), N_SAMPLE_PTS))
    by_column = np.argsort(tp_column, kind="stable")  # every column holds a TP score: no empty group
    starts = np.searchsorted(tp_column[by_column], np.arange(len(distinct)))
    tp_counts = np.add.reduceat(weights[:, tp_frame[by_column]], starts, axis=1) if len(distinct) else (
        np.zeros((len(weights), 0)))
    all_columns = _threshold_columns(tp_counts, n_gt)
    for b, wb in enumerate(weights):
        columns = all_columns[b][all_columns[b] >= 0]
        if n_gt[b] == 0 or not len(columns):  # no true positive: every point 0
            continue
        reach = admitted[columns]
        sums = np.cumsum(steps[:, : reach[-1]] * wb[step_frame[: reach[-1]]], axis=1)
        precision[b], orientation[b] = _points(*sums[:, reach - 1])
    return _Curve(precision, orientation, n_gt)


def _points(tp: np.ndarray, fp: np.ndarray, similarity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 41-point precision and orientation-similarity curves from TP, FP and summed
    similarity ``(K,)`` at the K thresholds: made monotone, missing points 0."""
    precision, orientation = np.zeros(N_SAMPLE_PTS), np.zeros(N_SAMPLE_PTS)
    denom = tp + fp
    with np.errstate(invalid="ignore", divide="ignore"):
        precision[: len(denom)] = np.where(denom > 0, tp / np.maximum(denom, 1), 0.0)
        orientation[: len(denom)] = np.where(denom > 0, similarity / np.maximum(denom, 1), 0.0)
    return np.maximum.accumulate(precision[::-1])[::-1], np.maximum.accumulate(orientation[::-1])[::-1]


def average_precision(curve: np.ndarray, *, recall_points: int = 40):
    """AP in percent from a 41-point precision (or orientation-similarity) curve: R40
    averages points 1..40, R11 points 0, 4, ..., 40. Curves ``(..., 41)`` give an array
    ``(...)`` of APs.

    Examples
    --------
    >>> average_precision(np.ones(41))  # precision 1 at every recall
    100.0
    >>> half = np.r_[np.ones(21), np.zeros(20)]  # precision 1 up to recall 0.5, then nothing
    >>> average_precision(half), round(average_precision(half, recall_points=11), 2)
    (50.0, 54.55)
    >>> average_precision(np.stack([np.ones(41), half]))  # (2, 41) curves: (2,) APs
    array([100.,  50.])
    """
    curve = np.asarray(curve, dtype=float)
    check_shape("curve", curve, (..., N_SAMPLE_PTS))
    if recall_points == 40:
        ap = curve[..., 1:].sum(axis=-1) / 40.0 * 100.0
    elif recall_points == 11:
        ap = curve[..., ::4].sum(axis=-1) / 11.0 * 100.0
    else:
        raise ValueError(f"recall_points must be 40 or 11, got {recall_points}")
    return float(ap) if ap.ndim == 0 else ap


# --------------------------------------------------------------------------- evaluation


def kitti_curves(
    gt_frames: Sequence[FrameLabels | Sequence[Label]],
    pred_frames: Sequence[FrameLabels | Sequence[Label]],
    *,
    class_name: str = "car",
    min_overlaps: Sequence[float] | None = None,
    difficulties: Sequence[str] = DIFFICULTIES,
    frame_weights: np.ndarray | None = None,
) -> dict:
    """Precision curves of one class at each minimum overlap (default: the devkit's).

    Parameters
    ----------
    gt_frames, pred_frames : sequences of FrameLabels or lists of Label
        As :func:`kitti_metrics` takes them.
    class_name : str, keyword-only
    min_overlaps : sequence of float, keyword-only
    difficulties : sequence of str, keyword-only
        Those of :data:`DIFFICULTIES` to evaluate.
    frame_weights : (B, F) array, keyword-only
        Curves of ``B`` resampled sets at once: frame ``f`` counts ``frame_weights[b, f]``
        times in set ``b`` (whole numbers, as a bootstrap draws them); equal to
        evaluating each set with its frames repeated, at the cost of one matching.

    Returns
    -------
    dict
        ``{min_overlap: {metric: {difficulty: curve or None}, "aos_valid": bool}}`` with
        metrics ``2d`` (whose curve also holds the orientation similarity), ``bev`` and
        ``3d``; a curve has ``precision`` and ``orientation`` (41 points; ``(B, 41)``
        with weights) and ``n_gt`` (``(B,)`` with weights); ``None`` where the devkit
        does not evaluate (see the module docstring).

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> found = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0, 0.9)
    >>> curves = kitti_curves([[car]] * 41, [[found]] * 41)
    >>> sorted(curves), sorted(curves[0.7])
    ([0.7], ['2d', '3d', 'aos_valid', 'bev'])
    >>> curve = curves[0.7]["3d"]["moderate"]
    >>> curve.precision.shape, curve.n_gt, average_precision(curve.precision)
    ((41,), 41, 100.0)
    """
    if len(gt_frames) != len(pred_frames):
        raise ValueError(f"{len(gt_frames)} ground-truth frames but {len(pred_frames)} prediction frames")
    class_name = class_name.lower()
    if class_name not in NEIGHBOURS:
        raise ValueError(f"class must be one of {sorted(NEIGHBOURS)}, got {class_name!r}")
    unknown = sorted(set(difficulties) - set(DIFFICULTIES))
    if unknown:
        raise ValueError(f"difficulties must be among {DIFFICULTIES}, got {unknown}")
    thresholds = [MIN_OVERLAP[class_name]] if min_overlaps is None else [float(t) for t in min_overlaps]
    n_frames = len(gt_frames)
    if frame_weights is not None:
        frame_weights = np.asarray(frame_weights, dtype=float)
        check_shape("frame_weights", frame_weights, (None, n_frames))
        if np.any(frame_weights < 0) or np.any(frame_weights != np.round(frame_weights)):
            raise ValueError("frame_weights must be whole numbers >= 0 (how often each frame is drawn)")
    gt_all = _Rows.of([_rows_of(f) for f in gt_frames])
    det_all = _Rows.of([_rows_of(f) for f in pred_frames])
    gt = gt_all.take(np.isin(gt_all.type, (class_name, *NEIGHBOURS[class_name])))
    dontcare = gt_all.take(gt_all.type == "dontcare")
    is_class = det_all.type == class_name
    # Detections of other classes matter only while lower than a minimum height.
    det = det_all.take(is_class | (np.abs(det_all.box[:, 3] - det_all.box[:, 1]) < max(MIN_HEIGHT)))
    det_is_class = det.type == class_name
    if np.isnan(det.score[det_is_class]).any():
        raise ValueError(f"every {class_name} prediction needs a score (16th column)")
    det.score = np.nan_to_num(det.score, nan=-np.inf)

    pg, pd = _pairs(gt.frame, det.frame, n_frames)
    footprint = _footprint_intersection(det.location[pd], det.dims[pd], det.rotation_y[pd],
                                        gt.location[pg], gt.dims[pg], gt.rotation_y[pg])
    overlaps = {
        "2d": box_overlap_2d(det.box[pd], gt.box[pg]),
        "bev": _bev_from_intersection(footprint, det.dims[pd], gt.dims[pg]),
        "3d": _3d_from_intersection(footprint, det.location[pd], det.dims[pd], gt.location[pg], gt.dims[pg]),
    }
    dj, dk = _pairs(det.frame, dontcare.frame, n_frames)
    dc_hit = np.zeros(len(det))
    if len(dj):
        np.maximum.at(dc_hit, dj, box_overlap_2d(det.box[dj], dontcare.box[dk], criterion="a"))
    evaluated = {
        "2d": bool((det_is_class & (det.box[:, 0] >= 0)).any()),
        "bev": bool((det_is_class & (det.location[:, 0] != _NO_LOCATION)).any()),
        "3d": bool((det_is_class & (det.location[:, 1] != _NO_LOCATION)).any()),
    }
    aos_valid = not bool((det_all.alpha == _NO_ALPHA).any())
    levels = None if frame_weights is None else _levels(det.frame, det.score, n_frames)
    out = {}
    for thr in thresholds:
        curves: dict = {"aos_valid": aos_valid}
        for metric in METRICS:
            curves[metric] = {
                name: _evaluate(gt, det, dc_hit if metric == "2d" else None, overlaps[metric], pg, pd,
                                class_name=class_name, difficulty=d, min_overlap=thr, n_frames=n_frames,
                                weights=frame_weights, levels=levels) if evaluated[metric] else None
                for d, name in enumerate(DIFFICULTIES) if name in difficulties
            }
        out[thr] = curves
    return out


def _aps(curves: dict, recall_points: int) -> dict:
    def ap(curve, field):
        if curve is None or curve.n_gt == 0:
            return None
        return average_precision(getattr(curve, field), recall_points=recall_points)

    return {
        "2d": {d: ap(curves["2d"][d], "precision") for d in DIFFICULTIES},
        "aos": {d: ap(curves["2d"][d], "orientation") if curves["aos_valid"] else None for d in DIFFICULTIES},
        "bev": {d: ap(curves["bev"][d], "precision") for d in DIFFICULTIES},
        "3d": {d: ap(curves["3d"][d], "precision") for d in DIFFICULTIES},
    }


def kitti_metrics(
    gt_frames: Sequence[FrameLabels | Sequence[Label]],
    pred_frames: Sequence[FrameLabels | Sequence[Label]],
) -> dict:
    """KITTI object-benchmark figures for Car.

    Parameters
    ----------
    gt_frames : sequence of FrameLabels or lists of Label
        Ground truth per frame (DontCare rows included, as :func:`read_labels` gives them).
    pred_frames : sequence of FrameLabels or lists of Label
        Predictions of the same frames, in the same order; every ``Car`` row needs a score.

    Returns
    -------
    dict
        ``{"car": {"2d"|"aos"|"bev"|"3d": {"easy", "moderate", "hard"}}, "recall_points":
        40, "r11": {"car": ...}, "iou_0.5": {"car": ...}, "min_overlap": ..., "n_gt":
        {"car": {difficulty: count}}, "n_frames": N}``: APs in percent with KITTI's rules
        (see the module docstring); the top level is R40 at the devkit's IoU 0.7, ``r11``
        the same at 11 recall points, ``iou_0.5`` R40 with every overlap threshold at 0.5.
        ``None`` where the devkit gives no figure.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> exact = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0, 0.9)
    >>> far = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 25], 0.0, 0.9)
    >>> result = kitti_metrics([[car]] * 41, [[exact]] * 41)  # 41 cars, each found exactly
    >>> result["car"]["3d"], result["n_gt"]["car"]["moderate"]
    ({'easy': 100.0, 'moderate': 100.0, 'hard': 100.0}, 41)
    >>> result = kitti_metrics([[car]] * 41, [[far]] * 41)  # the right box, 5 m too far
    >>> result["car"]["2d"]["moderate"], result["car"]["3d"]["moderate"]
    (100.0, 0.0)
    """
    curves = kitti_curves(gt_frames, pred_frames, class_name="car", min_overlaps=(MIN_OVERLAP["car"], 0.5))
    strict, loose = curves[MIN_OVERLAP["car"]], curves[0.5]
    return {
        "car": _aps(strict, 40),
        "recall_points": 40,
        "r11": {"car": _aps(strict, 11)},
        "iou_0.5": {"car": _aps(loose, 40)},
        "min_overlap": {"car": MIN_OVERLAP["car"], "iou_0.5": 0.5},
        "n_gt": {"car": {d: _count_gt(gt_frames, d) for d in DIFFICULTIES}},
        "n_frames": len(gt_frames),
    }


def mean_kitti_metrics(results: Sequence[dict]) -> dict:
    """The mean of several :func:`kitti_metrics` results of the same frames (runs with other
    seeds, say), figure by figure; ``None`` where a run has no figure.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    >>> far = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 25.0], 0.0, 0.9)
    >>> runs = [kitti_metrics([[car]] * 50, [[p]] * 50) for p in (car, far)]
    >>> mean_kitti_metrics(runs)["car"]["3d"]["moderate"], mean_kitti_metrics(runs)["car"]["2d"]["moderate"]
    (50.0, 100.0)
    """
    if not results:
        raise ValueError("no result to average")

    def mean(values):
        if isinstance(values[0], dict):
            return {k: mean([v[k] for v in values]) for k in values[0]}
        if any(v is None for v in values):
            return None
        return float(np.mean(values))

    same = ("recall_points", "min_overlap", "n_gt", "n_frames")
    if any(r[k] != results[0][k] for r in results for k in same):
        raise ValueError("the results are not of the same frames (their car or frame counts differ)")
    out = {k: mean([r[k] for r in results]) for k in results[0] if k not in same}
    out.update({k: results[0][k] for k in same}, runs=len(results))
    return out


def detection_ap_2d(detections, gt_frames: Sequence[FrameLabels | Sequence[Label]]) -> dict:
    """KITTI 2D AP and AOS (R40, Car) of 2D detections, by the devkit's rules.

    Parameters
    ----------
    detections : sequence of Detections
        Per frame, anything with ``boxes`` ``(D, 4)``, ``scores`` ``(D,)`` and ``alpha``
        ``(D,)`` (NaN: no viewpoint, then AOS is not evaluated); every box a ``Car``.
    gt_frames : sequence of FrameLabels or lists of Label
        Ground truth of the same frames.

    Returns
    -------
    dict
        ``{"2d" | "aos" | "2d_iou_0.5": {difficulty: AP in percent or None}, "n_gt":
        {difficulty: count}, "curves": {"2d" | "2d_iou_0.5": {difficulty: (41,) precision}}}``.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> from wirescene.core.types import Detections
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> box = np.array([[100.0, 100, 200, 160]])
    >>> dets = [Detections(box, np.array([0.5 + i / 100]), np.array([0.0])) for i in range(41)]
    >>> detection_ap_2d(dets, [[car]] * 41)["2d"]["moderate"]  # 41 cars, each found (fewer: < 100, the devkit's sampling)
    100.0
    >>> detection_ap_2d([Detections(box + [25, 0, 25, 0], d.scores, d.alpha) for d in dets], [[car]] * 41)["2d"]
    {'easy': 0.0, 'moderate': 0.0, 'hard': 0.0}
    """
    if len(detections) != len(gt_frames):
        raise ValueError(f"{len(detections)} detection frames but {len(gt_frames)} ground-truth frames")
    rows = []
    for d in detections:
        alpha = np.nan_to_num(np.asarray(d.alpha, float), nan=_NO_ALPHA)
        rows.append([Label("Car", -1.0, -1, float(a), b, [-1.0, -1.0, -1.0], [_NO_LOCATION] * 3, _NO_ALPHA, float(c))
                     for b, c, a in zip(np.asarray(d.boxes, float).reshape(-1, 4), np.asarray(d.scores, float), alpha)])
    curves = kitti_curves(gt_frames, rows, class_name="car", min_overlaps=(MIN_OVERLAP["car"], 0.5))
    strict, loose = _aps(curves[MIN_OVERLAP["car"]], 40), _aps(curves[0.5], 40)

    def precision(c):
        return {d: None if c["2d"][d] is None else c["2d"][d].precision for d in DIFFICULTIES}

    return {"2d": strict["2d"], "aos": strict["aos"], "2d_iou_0.5": loose["2d"],
            "n_gt": {d: _count_gt(gt_frames, d) for d in DIFFICULTIES},
            "curves": {"2d": precision(curves[MIN_OVERLAP["car"]]), "2d_iou_0.5": precision(curves[0.5])}}


def difficulty_of(label: Label) -> str | None:
    """The easiest KITTI difficulty whose limits a ground-truth object meets (``None``:
    beyond *hard*, ignored in every evaluation).

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> def car(height, occluded):
    ...     return Label("Car", 0.0, occluded, 0.0, [100, 100, 200, 100 + height], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> difficulty_of(car(60, 0)), difficulty_of(car(30, 1)), difficulty_of(car(60, 3))
    ('easy', 'moderate', None)
    """
    for d, name in enumerate(DIFFICULTIES):
        if (label.occluded <= MAX_OCCLUSION[d] and label.truncated <= MAX_TRUNCATION[d]
                and label.box[3] - label.box[1] >= MIN_HEIGHT[d]):
            return name
    return None


def _count_gt(gt_frames, difficulty: str) -> int:
    order = DIFFICULTIES.index(difficulty)
    return sum(
        1
        for f in gt_frames
        for lab in _rows_of(f)
        if is_type(lab.type, CAR_TYPES) and (lv := difficulty_of(lab)) is not None and DIFFICULTIES.index(lv) <= order
    )


# --------------------------------------------------------------------------- files and table


def read_label_dirs(
    gt_dir: str | Path, pred_dir: str | Path, *, frames: Iterable[str] | None = None
) -> tuple[list[str], list[FrameLabels], list[FrameLabels]]:
    """Ground truth and predictions of KITTI label directories (``FRAME.txt`` each).

    Frames are those given, else every ``*.txt`` of ``gt_dir`` (sorted). A frame without
    a prediction file has no detections.

    Raises
    ------
    InputError
        If a directory is missing, a ground-truth file of a frame is missing, no frame has
        a prediction file, any file is unreadable or malformed (see
        :func:`wirescene.io.kitti.read_labels`), or a prediction row has no score.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> row = "Car 0.00 0 -1.58 587.0 173.3 614.1 200.1 1.65 1.67 3.64 -0.65 1.71 46.70 -1.59"
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     gt, pred = Path(tmp, "label_2"), Path(tmp, "pred")
    ...     gt.mkdir(); pred.mkdir()
    ...     _ = Path(gt, "000001.txt").write_text(row)
    ...     _ = Path(gt, "000002.txt").write_text(row)
    ...     _ = Path(pred, "000001.txt").write_text(row + " 0.9")
    ...     ids, gts, preds = read_label_dirs(gt, pred)
    >>> ids, [len(f) for f in gts], [len(f) for f in preds]  # 000002 has no prediction file: no detections
    (['000001', '000002'], [1, 1], [1, 0])
    """
    gt_dir, pred_dir = Path(gt_dir), Path(pred_dir)
    for path, what in ((gt_dir, "ground-truth label"), (pred_dir, "prediction")):
        problem = path_problem(path, what, directory=True)
        if problem:
            raise InputError(problem, path=path)
    ids = sorted(p.stem for p in gt_dir.glob("*.txt")) if frames is None else [str(f) for f in frames]
    if not ids:
        raise InputError("no ground-truth label files (*.txt)", path=gt_dir)
    gts = [read_labels(gt_dir / f"{f}.txt") for f in ids]
    if not any((pred_dir / f"{f}.txt").exists() for f in ids):  # a wrong folder, not a method that saw nothing
        inner = sorted(d.name for d in pred_dir.iterdir() if d.is_dir() and any(d.glob("*.txt")))
        raise InputError(f"no prediction file of any of the {len(ids)} frames (FRAME.txt)"
                         + (f"; it holds folders of them ({', '.join(inner[:4])}): give one" if inner else ""),
                         path=pred_dir)
    preds = []
    for f in ids:
        path = pred_dir / f"{f}.txt"
        preds.append(read_labels(path) if path.exists() else FrameLabels())
        if any(o.score is None for o in preds[-1].objects):
            raise InputError("predictions need a score (16th column) on every row", path=path)
    return ids, gts, preds


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.2f}"


def format_kitti_table(result: dict, *, title: str = "") -> str:
    """Plain-text table of :func:`kitti_metrics`: rows 2d / aos / bev / 3d at IoU 0.7,
    then at 0.5, columns easy / moderate / hard (R40), and the R11 figures at 0.7.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> found = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0, 0.9)
    >>> print(format_kitti_table(kitti_metrics([[car]] * 41, [[found]] * 41)))  # doctest: +NORMALIZE_WHITESPACE
    KITTI Car AP (%), 41 frames, cars easy/moderate/hard: 41/41/41
    metric   IoU points     easy  moderate     hard
    2d       0.7    R40   100.00    100.00   100.00
    aos      0.7    R40   100.00    100.00   100.00
    bev      0.7    R40   100.00    100.00   100.00
    3d       0.7    R40   100.00    100.00   100.00
    2d       0.5    R40   100.00    100.00   100.00
    ...
    3d       0.7    R11   100.00    100.00   100.00
    """
    n = result["n_gt"]["car"]
    head = (f"KITTI Car AP (%), {result['n_frames']} frames, cars easy/moderate/hard: "
            f"{n['easy']}/{n['moderate']}/{n['hard']}")
    lines = [title, head] if title else [head]
    lines.append(f"{'metric':<7} {'IoU':>4} {'points':>6} {'easy':>8} {'moderate':>9} {'hard':>8}")
    blocks = (("0.7", "R40", result["car"]), ("0.5", "R40", result["iou_0.5"]["car"]), ("0.7", "R11", result["r11"]["car"]))
    for iou, points, figures in blocks:
        for metric in ("2d", "aos", "bev", "3d"):
            row = figures[metric]
            lines.append(f"{metric:<7} {iou:>4} {points:>6} {_fmt(row['easy']):>8} {_fmt(row['moderate']):>9} "
                         f"{_fmt(row['hard']):>8}")
    note = _ceiling_note(n)
    return "\n".join(lines + ([note] if note else []))


def _ceiling_note(n: dict) -> str:
    """A line on the devkit's ceiling of R40 AP where a difficulty of ``n`` (``{difficulty:
    cars}``) has fewer than 40 cars: its thresholds sit at every 40th of the cars, so fewer
    fill fewer of its recall points."""
    few = {d: k for d, k in n.items() if 0 < k < 40}
    return ("note: with fewer than 40 cars the devkit's R40 AP is at most (N - 1) / 40: "
            + ", ".join(f"{d} {100 * (k - 1) / 40:.1f}" for d, k in few.items())) if few else ""


def kitti_figure(result: dict, block: str, metric: str):
    """One metric's figures in the layout of :func:`kitti_metrics` (and of the intervals of
    :func:`wirescene.eval.intervals.kitti_intervals`): ``block`` ``"car"`` (IoU 0.7) or
    ``"iou_0.5"``.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> near = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [1, 1.6, 20], 0.0, 0.9)
    >>> result = kitti_metrics([[car]] * 41, [[near]] * 41)  # 1 m along its length: BEV IoU 0.6
    >>> kitti_figure(result, "car", "bev"), kitti_figure(result, "iou_0.5", "bev")
    ({'easy': 0.0, 'moderate': 0.0, 'hard': 0.0}, {'easy': 100.0, 'moderate': 100.0, 'hard': 100.0})
    """
    return (result[block] if block == "car" else result[block]["car"])[metric]


_SUMMARY_COLUMNS = (("2d@.7", "car", "2d"), ("aos@.7", "car", "aos"), ("bev@.7", "car", "bev"),
                    ("3d@.7", "car", "3d"), ("bev@.5", "iou_0.5", "bev"), ("3d@.5", "iou_0.5", "3d"))


def _summary_cells(result: dict, pick) -> list:
    return [pick(kitti_figure(result, block, metric)) for _, block, metric in _SUMMARY_COLUMNS]


def format_kitti_summary(results: dict[str, dict], *, intervals: dict[str, dict] | None = None,
                         margins: dict[str, dict] | None = None) -> str:
    """One line per variant of :func:`kitti_metrics` results ``{variant: result}``: R40
    AP at moderate difficulty, 2D / AOS / BEV / 3D at IoU 0.7 and BEV / 3D at 0.5; with
    ``intervals`` (``{variant: intervals}`` of :func:`wirescene.eval.intervals.kitti_intervals`)
    the table of :func:`format_kitti_intervals` below, and with ``margins`` (the same of the
    margins over a reference) a table of those.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> near = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [1, 1.6, 20], 0.0, 0.9)
    >>> print(format_kitti_summary({"near": kitti_metrics([[car]] * 41, [[near]] * 41)}))
    KITTI Car AP R40 (%), moderate (41 cars in 41 frames; easy 41, hard 41 cars)
    variant   2d@.7  aos@.7  bev@.7   3d@.7  bev@.5   3d@.5
    near     100.00  100.00    0.00    0.00  100.00  100.00
    """
    if not results:
        return ""
    first = next(iter(results.values()))
    n = first["n_gt"]["car"]
    name_w = max(len("variant"), *(len(v) for v in results))
    frames = first["n_frames"]
    lines = [f"KITTI Car AP R40 (%), moderate ({n['moderate']} cars in {frames} frame{'s' * (frames != 1)}; "
             f"easy {n['easy']}, hard {n['hard']} cars)",
             f"{'variant':<{name_w}} " + " ".join(f"{c[0]:>7}" for c in _SUMMARY_COLUMNS)]
    for v, r in results.items():
        lines.append(f"{v:<{name_w}} " + " ".join(f"{_fmt(c):>7}" for c in _summary_cells(r, lambda f: f["moderate"])))
    note = _ceiling_note(n)
    lines += [note] if note else []
    for table in (intervals, margins):
        text = format_kitti_intervals(table) if table else ""
        if text and text not in lines:  # one drive: said once for the APs and their margins
            lines += ["", text]
    return "\n".join(lines)


#: What :func:`format_kitti_intervals` says of the figures of one drive: every draw is that drive.
ONE_DRIVE = "No interval over drives of the APs or their margins: the frames are of one drive"


def drawn_alike(figures: dict) -> bool:
    """Whether every bootstrap draw of an interval's ``figures`` (their ``drives`` and
    ``frames_alone``, and ``runs`` where a draw also takes one of several runs:
    :mod:`wirescene.eval.intervals`) is the same: one cluster (a drive, or a frame of no known
    drive) and one run, whose [x, x] would read as a figure known exactly, not as none measured.

    Examples
    --------
    >>> drawn_alike({"drives": 1, "frames_alone": 0}), drawn_alike({"drives": 1, "frames_alone": 1})
    (True, False)
    >>> drawn_alike({"drives": 1, "frames_alone": 0, "runs": 2})  # each draw takes a run: the runs' spread
    False
    """
    return figures["drives"] + figures["frames_alone"] < 2 and figures.get("runs", 1) < 2


def format_kitti_intervals(intervals: dict[str, dict]) -> str:
    """A table of :func:`wirescene.eval.intervals.kitti_intervals` figures ``{name:
    intervals}``, a line per name, in the columns of :func:`format_kitti_summary`.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> from wirescene.eval.intervals import kitti_intervals
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    >>> ids = [f"{i:06d}" for i in range(50)]
    >>> spread = kitti_intervals([[car]] * 50, [[car]] * 50, ids, {f: "drive_1" if f < "000025" else "drive_2"
    ...                                                             for f in ids}, n_boot=20)
    >>> print(format_kitti_intervals({"exact": spread}))
    90% bootstrap interval over 2 drives, moderate (20 draws; every draw ranks the estimates again):
    variant          2d@.7         aos@.7         bev@.7          3d@.7         bev@.5          3d@.5
    exact   [100.0, 100.0] [100.0, 100.0] [100.0, 100.0] [100.0, 100.0] [100.0, 100.0] [100.0, 100.0]
    """
    if not intervals:
        return ""
    some = next(iter(intervals.values()))
    alone = some["frames_alone"]
    margin = some.get("margin_over")
    if drawn_alike(some):  # every draw that one drive: [x, x] would read as an AP known exactly
        return ONE_DRIVE
    name_w = max(len("variant"), *(len(v) for v in intervals))
    lines = [(f"AP margins over {margin} in points, " if margin else "")
             + f"{some['level']:g}% bootstrap interval over {some['drives']} drive{'s' * (some['drives'] != 1)}"
             + (f" and {alone} frame{'s' * (alone != 1)} of no known drive" if alone else "")
             + f", {some['difficulty']} ({some['draws']} draws; every draw ranks the estimates again"
             + ("; the same drives for both" if margin else "") + "):",
             f"{'variant':<{name_w}} " + " ".join(f"{c[0]:>14}" for c in _SUMMARY_COLUMNS)]
    shown = "[{:+.1f}, {:+.1f}]" if margin else "[{:.1f}, {:.1f}]"
    for v, r in intervals.items():
        cells = _summary_cells(r, lambda c: "-" if c is None else shown.format(*c))
        lines.append(f"{v:<{name_w}} " + " ".join(f"{c:>14}" for c in cells))
    return "\n".join(lines)
