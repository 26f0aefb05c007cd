"""Pictures of what the model did: image overlays and bird's-eye views.

Estimates are drawn in red, ground truth in cyan (not the paper's green: red and green
look alike to one reader in twelve, red and cyan differ for every common colour-vision
deficiency), pre-detections dashed yellow; the edges between two hidden vertices of a wireframe
are dashed, and each hidden vertex is marked, by shape rather than colour, by what hides it
(:data:`HIDDEN_MARKS`: a ring the car itself, an x another car, an open square the
occluder mask the fit chose, whose region is hatched, a triangle at the image's edge the
border). Each estimated car carries
its number (its line in the KITTI label file) in both views, and its confidence in the
overlay. Where ground truth is drawn beside a fitted estimate, the evaluation's own
matching (:func:`wirescene.core.matching.match_estimate`) marks the false cars (violet,
tagged ``false``, or ``false view`` on a labelled car whose viewpoint its pre-detection's
is over 45 deg off) and the labelled cars missed (dashed, tagged ``missed``: of no true
positive); the bird's-eye view joins each car matched to a labelled car to it (dash-dotted
for a ``false view``). The overlay draws the shared ground plane of the ``+gp`` variants
and ``full`` as a grid (:func:`ground_grid`). All functions draw into a new
:class:`matplotlib.figure.Figure` (:func:`new_figure`) and return it; :func:`save_figure`
writes it atomically. No pyplot: the figures belong to
no window manager, need no display, and the caller's matplotlib backend (a notebook's,
say) is left as it was.
"""

from __future__ import annotations

import functools
import io
import sys
from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib import patheffects, rc_context, transforms
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from wirescene.core.atomic import write_bytes
from wirescene.core.boxes import box_corners
from wirescene.core.camera import NEAR_PLANE, Camera
from wirescene.core.groundplane import point_on_plane, rotation_y
from wirescene.core.matching import FrameMatches, match_estimate
from wirescene.core.occluders import mask_box

EST_COLOR = "#e8302a"
GT_COLOR = "#33bbee"
DET_COLOR = "#f5d90a"
#: Pre-detections the fit's verification dropped (not cars, by the fit).
DROPPED_COLOR = "#d9d9d9"
#: Dark rim of each dot of a dropped pre-detection's light grey line: it stays visible on a bright
#: sky or wall, and on the key's light background (a grey of 1.4:1 contrast there alone).
DROPPED_RIM = "#404040"
#: A false car (no true positive: on no labelled car, or of a wrong viewpoint): violet, over 40 CIELAB
#: units from the estimates' red, the ground truth's cyan and the pre-detections' yellow for every
#: common colour-vision deficiency, as bright as the red (seen on a dark road and a bright sky alike).
FALSE_COLOR = "#9933ff"
#: The line joining a true positive to its labelled car in the bird's-eye view.
LINK_COLOR = "#404040"
#: Dashes of a missed labelled car's box (the hidden edges' are (3, 2), of the estimates' colour only).
MISSED_DASHES = (0, (5, 3))
#: The shared ground plane's grid (``+gp`` variants, ``full``): thin white lines, half transparent, under the cars.
GROUND_COLOR = "#ffffff8c"
#: Where the grid's lines lie on the plane (m): across the road every 10 m ahead, along it every 5 m aside.
GROUND_AHEAD = np.arange(10.0, 81.0, 10.0)
GROUND_ASIDE = np.arange(-10.0, 10.1, 5.0)
#: Face of a hidden vertex's dot (an open dot, edged in the estimate's colour).
HIDDEN_FACE = "white"
#: How the overlay marks a fitted car's hidden vertex, by what hides it (``ObjectEstimate.hidden_by``):
#: ``(marker, face (None: the car's colour), area (the visible dot's times), key text)``, told apart by
#: shape; a vertex outside the image is drawn at the edge it left by, a triangle pointing out.
HIDDEN_MARKS = {
    "self": ("o", "none", 1.5, "hidden by the car itself"),  # a ring: the far side, the most hidden vertices
    "other-car": ("x", None, 2.5, "hidden by another car"),
    "occluder": ("s", HIDDEN_FACE, 1.5, "hidden by the occluder mask (hatched)"),
    "truncated": (">", None, 2.5, "outside the image (at its edge)"),
}
#: The occluder mask the fit chose for a car: the region it covers hatched in the car's colour, half
#: transparent (``OCCLUDER_HATCH_ALPHA``), over a light veil (``OCCLUDER_VEIL``), under the cars.
OCCLUDER_HATCH = "//"
OCCLUDER_HATCH_ALPHA = 0.6
OCCLUDER_VEIL = "#ffffff26"
#: Font size (points) of the cars' numbers.
NUMBER_FONTSIZE = 7
# A dropped pre-detection's line on its dark rim (each dot of the dotted line rimmed, the dots kept).
_DROPPED_EFFECTS = [patheffects.Stroke(linewidth=2.5, foreground=DROPPED_RIM), patheffects.Normal()]
# Box edges as corner index pairs for the corner order of boxes.box_corners_object.
_BOX_EDGES = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
_FRONT_FACE = [(0, 3), (1, 2)]  # cross on the front face marks the heading


#: Most pixels of an overlay's canvas (a 4K UHD frame's): matplotlib takes some 115 bytes a pixel
#: to draw one (about 1 GB here; a 9,000 x 9,000 image took 9.3 GB), so a larger image is drawn
#: reduced by the least whole factor that fits (:func:`drawn_image`).
MAX_OVERLAY_PIXELS = 3840 * 2160


def drawn_image(image: np.ndarray) -> np.ndarray:
    """``image`` ``(H, W, 3)`` as an overlay draws it: itself when it has at most
    :data:`MAX_OVERLAY_PIXELS` pixels, else reduced by the least whole factor that fits (each
    pixel the mean of a square of them), so that drawing a huge image takes bounded memory.

    Examples
    --------
    >>> drawn_image(np.zeros((375, 1242, 3), np.uint8)).shape
    (375, 1242, 3)
    >>> drawn_image(np.zeros((9000, 9000, 3), np.uint8)).shape
    (2250, 2250, 3)
    """
    h, w = image.shape[:2]
    k = 1
    while -(-w // k) * -(-h // k) > MAX_OVERLAY_PIXELS:
        k += 1
    if k == 1:
        return image
    from PIL import Image

    return np.asarray(Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).reduce(k))


def _draw_edges(ax, camera: Camera, points: np.ndarray, edges, color: str, lw: float, ls="-",
                zorder: float = 2.0) -> None:
    """The segments ``edges`` ``(E, 2)`` between 3D ``points`` ``(P, 3)``, each cut at the
    camera's near plane (a car next to or beside the camera keeps the part in front of it)."""
    from matplotlib.collections import LineCollection

    e = np.asarray(edges, int).reshape(-1, 2)
    _, depth = camera.project_with_depth(points)
    a, b = points[e[:, 0]], points[e[:, 1]]
    da, db = depth[e[:, 0]], depth[e[:, 1]]
    keep = (da > NEAR_PLANE) | (db > NEAR_PLANE)
    a, b, da, db = a[keep], b[keep], da[keep], db[keep]
    with np.errstate(divide="ignore", invalid="ignore"):  # depth is affine along a segment: cut where it is NEAR_PLANE
        s = np.clip((NEAR_PLANE * 1.001 - da) / (db - da), 0.0, 1.0)[:, None]
    cut = a + s * (b - a)
    a, b = np.where((da <= NEAR_PLANE)[:, None], cut, a), np.where((db <= NEAR_PLANE)[:, None], cut, b)
    uv = camera.project(np.concatenate([a, b]))
    ax.add_collection(LineCollection(np.stack([uv[:len(a)], uv[len(a):]], axis=1), colors=color, linewidths=lw,
                                     linestyles=ls, zorder=zorder))


def _draw_box3d(ax, camera: Camera, corners: np.ndarray, color: str, lw: float = 1.5, ls="-"):
    _draw_edges(ax, camera, corners, _BOX_EDGES, color, lw, ls=ls)
    _draw_edges(ax, camera, corners, _FRONT_FACE, color, lw * 0.6, ls=ls)


def ground_grid(plane) -> tuple[np.ndarray, np.ndarray]:
    """The grid drawn on a ground ``plane`` (a :class:`~wirescene.core.groundplane.GroundPlane`):
    ``(points (P, 3), edges (E, 2))`` in the camera frame, lines across the road at
    :data:`GROUND_AHEAD` and along it at :data:`GROUND_ASIDE`, each lying on the plane.

    Examples
    --------
    >>> from wirescene.core.groundplane import GroundPlane
    >>> points, edges = ground_grid(GroundPlane())  # KITTI's level road, 1.65 m below the camera
    >>> points.shape, edges.shape, bool(np.allclose(points[:, 1], 1.65))
    ((26, 3), (13, 2), True)
    """
    near, far = 5.0, float(GROUND_AHEAD[-1])
    ends = [(GROUND_ASIDE[0], z, GROUND_ASIDE[-1], z) for z in GROUND_AHEAD]
    ends += [(x, near, x, far) for x in GROUND_ASIDE]
    x0, z0, x1, z1 = np.array(ends, float).T
    points = point_on_plane(np.concatenate([x0, x1]), np.concatenate([z0, z1]), plane.pitch, plane.roll,
                            plane.height)
    return points, np.stack([np.arange(len(ends)), np.arange(len(ends)) + len(ends)], axis=1)


def judged(estimate, gt: Sequence | None) -> FrameMatches | None:
    """The evaluation's verdict on ``estimate`` against the drawn labels ``gt``
    (:func:`wirescene.core.matching.match_estimate`: indices into ``gt``, cars in
    :attr:`SceneEstimate.cars` order), or None where nothing is judged: no estimate, no labels
    (``gt`` None; an empty ``gt`` is a frame labelled without cars, where every car is false),
    or an estimate that carries no pre-detections (one put together by hand, or
    ``wirescene gt``'s mean wireframes) or not one car per pre-detection.

    Examples
    --------
    >>> from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate
    >>> from wirescene.core.labels import Label
    >>> dets = Detections([[100, 100, 200, 160]], scores=0.9, alpha=np.nan)
    >>> car = ObjectEstimate(detection_index=0, box2d=dets.boxes[0], score=0.5, location=np.array([2.0, 1.6, 20.0]),
    ...                      R=np.eye(3), dims=np.array([1.5, 1.6, 4.0]), cost=0.0)
    >>> far = Label("Car", 0.0, 0, 0.3, [900, 110, 1000, 170], [1.5, 1.6, 4.0], [12.0, 1.6, 20.0], 0.9)
    >>> m = judged(SceneEstimate("coarse", [car], detections=dets), [far])
    >>> m.false.tolist(), m.missed.tolist()  # car #1 on no labelled car, the label missed
    ([0], [0])
    >>> judged(SceneEstimate("coarse", [car]), [far]) is None  # no pre-detections: not judged
    True
    >>> judged(SceneEstimate("coarse", [car], detections=dets), []).false.tolist()  # labelled: no car
    [0]
    >>> judged(SceneEstimate("coarse", [car], detections=dets), None) is None  # no labels
    True
    """
    if estimate is None or gt is None or estimate.detections is None:
        return None
    try:
        return match_estimate(estimate, list(gt))
    except ValueError:  # cars not one per pre-detection (a scene made by hand): drawn as before, unjudged
        return None


def _verdicts(estimate, gt: Sequence | None) -> tuple[list, FrameMatches | None, dict[int, str], set[int]]:
    """``(labels drawn, matches, {id(car): "false" | "false view"}, {id(label) missed})``:
    :func:`judged`'s verdict on ``estimate`` against ``gt`` (None: no labels, none drawn)."""
    matches = judged(estimate, gt)
    gt = [] if gt is None else list(gt)
    if matches is None:
        return gt, None, {}, set()
    cars = estimate.cars
    false = {id(cars[d]): "false" for d in matches.false}
    false.update({id(cars[d]): "false view" for d in matches.wrong_viewpoint})
    return gt, matches, false, {id(gt[g]) for g in matches.missed}


def draw_wireframe(ax, camera: Camera, vertices: np.ndarray, edges: np.ndarray, *, visible=None, hidden_by=None,
                   color=EST_COLOR, zorder: float = 2.0, dot_zorder: float | None = None) -> set[str]:
    """Draw a wireframe ``(V, 3)`` with ``edges`` ``(E, 2)``: visible vertices as dots of
    ``color``, hidden ones as open dots (marked otherwise with ``hidden_by``, below) and the edges
    between two hidden vertices dashed; dots sized by the car's height in the image (a far car's
    dots would hide it).
    ``visible`` ``(V,)`` bool defaults to all visible; ``hidden_by`` ``(V,)`` (what hides each
    vertex, :data:`~wirescene.core.wireframe.HIDDEN_BY`; it says which are visible) marks each
    hidden vertex by what hides it, as :data:`HIDDEN_MARKS` (one outside the image at the edge of
    the camera's image, or of the axes' view where it has no size). Edges are cut at the camera's near
    plane. The edges are drawn at ``zorder``, the dots at ``dot_zorder`` (default ``zorder + 1``):
    :func:`overlay` stacks its cars so that a nearer car's edges cover a farther car's dots.
    Returns the kinds of hidden vertices drawn (``"hidden"``: without ``hidden_by``).

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> from wirescene.core.groundplane import transform
    >>> from wirescene.core.shape import load_default
    >>> from wirescene.core.wireframe import EDGES
    >>> camera = Camera([[721.5, 0, 609.6, 0], [0, 721.5, 172.9, 0], [0, 0, 1, 0]], (1242, 375))
    >>> vertices = transform(load_default().mean, np.array([-2.0, 1.65, 12.0]), rotation_y(0.3))  # (36, 3)
    >>> ax = new_figure().subplots()
    >>> draw_wireframe(ax, camera, vertices, EDGES, visible=np.arange(36) >= 18)  # the left side hidden
    {'hidden'}
    >>> [type(c).__name__ for c in ax.collections]  # solid and dashed edges, filled and open dots
    ['LineCollection', 'LineCollection', 'PathCollection', 'PathCollection']
    >>> reasons = ["self"] * 6 + ["other-car"] * 12 + ["visible"] * 18  # what hides each vertex
    >>> sorted(draw_wireframe(ax, camera, vertices, EDGES, hidden_by=reasons))
    ['other-car', 'self']
    """
    vertices = np.asarray(vertices, float)
    edges = np.asarray(edges, int).reshape(-1, 2)
    reasons = None if hidden_by is None else np.asarray(hidden_by, str)
    if reasons is not None:
        vis = reasons == "visible"
    else:
        vis = np.ones(len(vertices), bool) if visible is None else np.asarray(visible, bool)
    behind = ~vis[edges[:, 0]] & ~vis[edges[:, 1]]
    dot_zorder = zorder + 1 if dot_zorder is None else dot_zorder
    _draw_edges(ax, camera, vertices, edges[~behind], color, 1.0, zorder=zorder)
    if behind.any():
        _draw_edges(ax, camera, vertices, edges[behind], color, 0.8, ls=(0, (3, 2)), zorder=zorder)
    uv, depth = camera.project_with_depth(vertices)
    front = depth > NEAR_PLANE
    if not front.any():
        return set()
    size = float(np.clip(np.ptp(uv[front, 1]) / 8.0, 1.0, 10.0))
    _dots(ax, uv[vis & front], "o", size, color, "face", None, dot_zorder)  # as scatter's c=color
    if reasons is None:
        _dots(ax, uv[~vis & front], "o", size * 1.5, HIDDEN_FACE, color, 0.6, dot_zorder)
        return {"hidden"} if (~vis & front).any() else set()
    drawn = set()
    for reason, (marker, face, grow, _) in HIDDEN_MARKS.items():
        at = (reasons == reason) & front
        if not at.any():
            continue
        drawn.add(reason)
        points = uv[at]
        if reason == "truncated":  # off the picture: at the image's edge it left by, pointing out
            points, markers = _at_image_edge(ax, camera, points, np.sqrt(size * grow) / 2)
        else:
            markers = np.full(len(points), marker)
        for m in dict.fromkeys(markers):
            if m == "x":  # all edge
                _dots(ax, points[markers == m], m, size * grow, "none", color, 1.0, dot_zorder)
            else:
                _dots(ax, points[markers == m], m, size * grow, color if face is None else face, color, 0.6, dot_zorder)
    return drawn


def _dots(ax, uv: np.ndarray, marker: str, size: float, face, edge, lw: float | None, zorder: float):
    """Markers at ``uv`` ``(n, 2)``, of area ``size`` (points squared): what :meth:`~matplotlib.axes.Axes.scatter`
    draws (``lw`` None: its default), without its 0.5 ms of parsing a call (a picture of ten cars makes some 40)."""
    from matplotlib.collections import PathCollection

    style = _marker_path(marker)
    dots = PathCollection((style,), [size], facecolors=face, edgecolors=edge, linewidths=lw, offsets=uv,
                          offset_transform=ax.transData, zorder=zorder)
    dots.set_transform(transforms.IdentityTransform())
    ax.add_collection(dots, autolim=False)


@functools.lru_cache(maxsize=None)
def _marker_path(marker: str):
    from matplotlib.markers import MarkerStyle

    style = MarkerStyle(marker)
    return style.get_path().transformed(style.get_transform())


def _at_image_edge(ax, camera: Camera, uv: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Points ``uv`` ``(n, 2)`` outside the camera's image moved onto its edge, a marker of
    ``radius`` points inside it, and each one's triangle marker pointing to where it lies
    (a camera without an image size: the edge of the axes' view)."""
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    if camera.image_size is not None:
        w, h = camera.image_size
        (x0, x1), (y0, y1), edge = (0, w), (0, h), (w - 1, h - 1)
    else:
        (x0, x1), (y0, y1) = sorted(xlim), sorted(ylim)
        edge = (x1, y1)
    box = ax.get_position()  # in the figure's fractions: the axes' size in points
    points = np.array([box.width * ax.figure.get_figwidth(), box.height * ax.figure.get_figheight()]) * 72
    inset = radius * np.abs([xlim[1] - xlim[0], ylim[1] - ylim[0]]) / points  # pixels
    over = np.stack([x0 - uv[:, 0], uv[:, 0] - edge[0], y0 - uv[:, 1], uv[:, 1] - edge[1]], axis=1)
    # each side's triangle as the axes show it ("^": up on the screen; an image's axes grow v down)
    sides = ["<", ">"][::-1 if ax.xaxis_inverted() else 1] + ["^", "v"][::1 if ax.yaxis_inverted() else -1]
    markers = np.array(sides)[np.argmax(over, axis=1)]
    inside = np.clip(uv, [x0, y0] + inset, [x1, y1] - inset)
    return inside, markers


def car_numbers(estimate) -> dict[int, int]:
    """``{id(car): n}``: each car of ``estimate`` numbered as the KITTI label file and the
    JSON file list it (:attr:`SceneEstimate.cars`, detection order), from 1.

    Examples
    --------
    >>> from wirescene.core.types import ObjectEstimate, SceneEstimate
    >>> cars = [ObjectEstimate(detection_index=i, box2d=np.array([0.0, 0.0, 10.0, 10.0]), score=1.0,
    ...                        location=np.array([0.0, 1.65, 10.0]), R=np.eye(3), dims=np.ones(3), cost=0.0)
    ...         for i in (2, 0)]
    >>> numbers = car_numbers(SceneEstimate(variant="coarse", objects=cars))
    >>> numbers[id(cars[0])], numbers[id(cars[1])]  # detection 2 is the second line of the label file
    (2, 1)
    """
    return {} if estimate is None else {id(o): n for n, o in enumerate(estimate.cars, 1)}


def _car_label(n: int, score: float | None) -> str:
    return f"#{n}" if score is None or not np.isfinite(score) else f"#{n} {score:.2f}"


def text_size(text: str, fontsize: float, scale: float, pad: float) -> tuple[float, float]:
    """Width and height (data units, ``scale`` of them a point) of ``text`` in a box padded
    by ``pad`` font sizes, measured from the font's outlines (no renderer needed).

    Examples
    --------
    >>> (w1, h1), (w2, h2) = text_size("#1", 7, 1.0, 0.2), text_size("#1 0.80", 7, 1.0, 0.2)
    >>> bool(w2 > w1), h1 == h2  # longer text, wider box; the height is the font's
    (True, True)
    """
    width = _text_width(text, float(fontsize), FontProperties())  # the font of the rcParams in force
    return (width + 2 * pad * fontsize + 2) * scale, (1.25 * fontsize + 2 * pad * fontsize + 2) * scale


@functools.lru_cache(maxsize=4096)
def _text_width(text: str, fontsize: float, prop: FontProperties) -> float:
    """Points wide of ``text``'s outlines in font ``prop``, remembered: a picture's key and its tags
    (``missed`` on each missed car) are measured again at every picture, at 5-15 ms a text."""
    from matplotlib.textpath import TextPath

    return float(TextPath((0, 0), text, size=fontsize, prop=prop).get_extents().width)


def _overlap(a, b) -> float:
    """The area shared by rectangles ``(x0, y0, x1, y1)``."""
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def place_labels(boxes, sizes, width: float, height: float, *, reserved=(),
                 stacked: bool = True, beside: bool = False) -> list[tuple[float, float]]:
    """Top-left corners (``x``, ``y`` down) of labels of ``sizes`` ``(w, h)``, one by each of
    ``boxes`` ``(x1, y1, x2, y2)``: above the box's top-left corner where there is room,
    else inside its top, below it or (``stacked``) stacked above, always inside the ``width``
    x ``height`` picture, clear of each other and of the ``reserved`` rectangles where
    any candidate place is (else the least covered one). Labels are placed in order.
    ``stacked`` False keeps each label next to its box (a tag that names no car, read by
    where it lies). ``beside`` tries right of the box, then left of it (level with its
    middle) before all those places.

    Examples
    --------
    >>> place_labels([[10, 50, 60, 90], [12, 52, 62, 92]], [(30, 10)] * 2, 100, 100)  # the second inside its box
    [(10.0, 39.0), (12.0, 53.0)]
    >>> place_labels([[-5, 2, 20, 30]], [(30, 10)], 100, 100)  # cut by the image's corner: kept inside
    [(0.0, 0.0)]
    >>> crowded = [(0, 30, 100, 100)]  # every place next to the box taken
    >>> place_labels([[10, 50, 60, 90]], [(30, 10)], 100, 100, reserved=crowded)  # stacked far above it
    [(10.0, 17.0)]
    >>> place_labels([[10, 50, 60, 90]], [(30, 10)], 100, 100, reserved=crowded, stacked=False)  # by it, covered
    [(10.0, 39.0)]
    >>> cars = [[10, 50, 25, 90], [70, 10, 85, 40]]  # right of each, but left of the second: on it by the edge
    >>> place_labels(cars, [(30, 10)] * 2, 100, 100, reserved=cars, beside=True)
    [(26.0, 65.0), (39.0, 20.0)]
    """
    taken = [tuple(map(float, r)) for r in reserved]
    out = []
    for (x1, y1, x2, y2), (tw, th) in zip(np.asarray(boxes, float), sizes):
        above = [(x1, y1 - th - 1 - k * (th + 1)) for k in range(4)]
        candidates = above[:1] + [(x1, y1 + 1), (x2 - tw, y1 - th - 1), (x1, y2 + 1)] + (above[1:] if stacked else [])
        if beside:
            candidates = [(x2 + 1, (y1 + y2 - th) / 2), (x1 - tw - 1, (y1 + y2 - th) / 2)] + candidates
        best = None
        for cx, cy in candidates:
            cx = float(min(max(cx, 0.0), max(width - tw, 0.0)))
            cy = float(min(max(cy, 0.0), max(height - th, 0.0)))
            covered = sum(_overlap(r, (cx, cy, cx + tw, cy + th)) for r in taken)
            if best is None or covered < best[0]:
                best = (covered, cx, cy)
            if covered == 0:
                break
        _, cx, cy = best
        taken.append((cx, cy, cx + tw, cy + th))
        out.append((cx, cy))
    return out


def _image_box(camera: Camera, o, edges) -> np.ndarray | None:
    """The image rectangle of a car: its pre-detection's box, else its projection."""
    box = np.asarray(o.box2d, float) if o.box2d is not None else np.full(4, np.nan)
    if np.isfinite(box).all() and box[2] > box[0]:
        return box
    points = o.vertices if o.vertices is not None else box_corners(o.dims, o.location, o.R)
    uv, depth = camera.project_with_depth(np.asarray(points, float))
    uv = uv[depth > NEAR_PLANE]
    return None if not len(uv) else np.concatenate([uv.min(axis=0), uv.max(axis=0)])


def overlay(
    image: np.ndarray,
    camera: Camera,
    estimate=None,
    *,
    gt: Sequence | None = None,
    detections=None,
    dropped=None,
    title: str | None = None,
    edges: np.ndarray | None = None,
    estimate_name: str = "estimate",
    scores: bool = True,
    score_name: str = "confidence",
):
    """Image with detections (dashed yellow), estimated 3D boxes or wireframes (red, each
    numbered as in the label file, with its confidence) and ground-truth 3D boxes (cyan).
    A fitted wireframe marks each hidden vertex by what hides it (:data:`HIDDEN_MARKS`, from
    ``ObjectEstimate.hidden_by``) and hatches the region of the occluder mask the fit chose
    for the car, where it chose one; the key lists the marks and colours drawn, no others.

    Parameters
    ----------
    image : (H, W, 3) uint8 array
        Drawn pixel for pixel up to :data:`MAX_OVERLAY_PIXELS` pixels, reduced beyond
        (:func:`drawn_image`).
    camera : Camera
        The image's camera (``P2``).
    estimate : SceneEstimate, optional
        Its cars, numbered ``#n`` as :func:`car_numbers` (the label file's order); an
        estimate without cars says so in the key.
    gt : sequence of kitti ``Label``, optional
        Drawn cyan. Beside an estimate that carries its pre-detections (``estimate.detections``,
        as fitted), the evaluation's matching (:func:`judged`) marks its false cars violet,
        tagged ``false`` (on no labelled car) or ``false view`` (on one, from a viewpoint over
        45 deg off), and the labels it counts missed dashed, tagged ``missed``. None: no
        labels, nothing judged; an empty sequence: a frame labelled without cars (every car false).
    detections : Detections, optional
        The pre-detections of the cars drawn.
    dropped : Detections, optional
        Pre-detections the fit's verification dropped, drawn dotted grey.
    title : str, optional
        A line written at the top left.
    edges : (E, 2) int array, optional
        Wireframe edges, used for objects that carry ``vertices``.
    estimate_name : str, optional
        What the key calls the red objects (``wirescene gt`` draws no estimate).
    scores : bool, optional
        Whether each car's number is followed by its confidence (``wirescene gt``'s cars
        have none).
    score_name : str, optional
        What the key calls that number: ``"confidence"`` (calibrated), or what else the
        cars' scores are (``wirescene eval --raw-scores``: ``"pre-detection score"``).
    """
    h, w = image.shape[:2]
    drawn = drawn_image(image)  # the canvas: the image's pixels, or a reduced copy's for a huge image
    fig = new_figure(figsize=(drawn.shape[1] / 100, drawn.shape[0] / 100), dpi=100)
    ax = fig.add_axes([0, 0, 1, 1])
    if drawn is image:
        ax.imshow(image)
    else:  # spread over the image's own pixel coordinates, which everything drawn on it keeps
        ax.imshow(drawn, extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.axis("off")
    scale = w / (fig.get_figwidth() * 72)  # image pixels a point: the axes fill the figure
    if dropped is not None:
        for b in dropped.boxes:
            ax.add_patch(Rectangle((b[0], b[1]), b[2] - b[0], b[3] - b[1], fill=False, ec=DROPPED_COLOR, lw=1,
                                   ls=":", path_effects=_DROPPED_EFFECTS))
    if detections is not None:
        for b in detections.boxes:
            ax.add_patch(Rectangle((b[0], b[1]), b[2] - b[0], b[3] - b[1], fill=False, ec=DET_COLOR, lw=1, ls="--"))
    plane = None if estimate is None else estimate.ground_plane
    if plane is not None:  # the plane every car stands on, under the boxes and the cars, over the image
        _draw_edges(ax, camera, *ground_grid(plane), GROUND_COLOR, 0.6, zorder=0.9)
    gt, _, false, missed = _verdicts(estimate, gt)
    for g in sorted(gt, key=lambda g: -g.location[2]):  # far to near: a near car is drawn over a far one
        _draw_box3d(ax, camera, box_corners(g.dims, g.location, rotation_y(g.rotation_y)), GT_COLOR, 1.0,
                    ls=MISSED_DASHES if id(g) in missed else "-")
    objects = [] if estimate is None else sorted(estimate.objects, key=lambda o: -o.location[2])
    wireframes = edges is not None and any(o.vertices is not None for o in objects)
    step = 1.0 / max(len(objects), 1)
    hidden_kinds = set()
    masked = False
    for k, o in enumerate(objects):
        color = FALSE_COLOR if id(o) in false else EST_COLOR
        if o.vertices is not None and edges is not None:
            masked |= _draw_occluder(ax, camera, o, color)
            # far to near, each car in a layer of its own below the numbers (4): its dots over its own edges,
            # under a nearer car's, as the nearer car hides the farther one
            hidden_kinds |= draw_wireframe(ax, camera, o.vertices, edges, visible=o.visibility, hidden_by=o.hidden_by,
                                           zorder=2 + k * step, dot_zorder=2 + (k + 0.5) * step, color=color)
        else:
            _draw_box3d(ax, camera, box_corners(o.dims, o.location, o.R), color)
    reserved = []
    if title:
        ax.text(4 * scale, 4 * scale, title, color="white", fontsize=10, va="top",
                bbox=dict(facecolor="black", alpha=0.5, lw=0, boxstyle="square,pad=0.25"))
        tw, th = text_size(title, 10, scale, 0.25)
        reserved.append((0, 0, tw + 4 * scale, th + 4 * scale))
    key = []  # what each colour and mark means, for those drawn
    if estimate is not None and not objects:
        key.append(("none", "none", f"no car {'estimated' if estimate_name == 'estimate' else 'drawn'}"))
    est_boxes = bool(objects) and not wireframes  # the estimates' boxes carry the front's cross: the key says so once
    cross = " (a cross marks the front)"
    red = any(id(o) not in false for o in objects)  # the key's red entries only where a red car is drawn
    car_color = EST_COLOR if red else FALSE_COLOR
    if red:
        key.append(("-", EST_COLOR, estimate_name + (cross if est_boxes else "")))
    if "hidden" in hidden_kinds:  # cars that say not what hides them
        key.append(("hidden", car_color, "hidden part"))
    key.extend((kind, car_color, HIDDEN_MARKS[kind][3]) for kind in HIDDEN_MARKS
               if kind in hidden_kinds or (kind == "occluder" and masked))
    if objects:
        key.append(("tag", car_color, f"#n c: car n (line n of the label file), {score_name} c" if scores
                    else "#n: the label file's n-th car"))
        false_key = _false_key(false, "#n c" if scores else "#n")
        if false_key and est_boxes and not red:  # no red entry said it
            false_key[0] = (*false_key[0][:2], false_key[0][2] + cross)
        key.extend(false_key)
    if plane is not None:
        key.append(("ground", GROUND_COLOR, "ground plane: a line every 10 m ahead, 5 m aside"))
    if len(gt):
        key.append(("-", GT_COLOR, "ground truth" + ("" if est_boxes else cross)))
    if missed:
        key.append(("missed", GT_COLOR, "missed: a labelled car without a true positive"))
    if detections is not None and len(detections.boxes):
        key.append(("--", DET_COLOR, "pre-detection"))
    if dropped is not None and len(dropped.boxes):
        key.append((":", DROPPED_COLOR, "pre-detection the fit dropped"))

    if key:
        legend = ax.legend([_key_handle(s, c) for s, c, _ in key], [k[2] for k in key], loc="upper right",
                           fontsize=7, framealpha=0.6, borderpad=0.4)
        # the key's corner, estimated from its rows and longest entry (no renderer needed): no number under it
        longest = max(text_size(k[2], 7, scale, 0)[0] for k in key)
        reserved.append((w - longest - 40 * scale, 0, w, (len(key) * 1.5 * 7 + 12) * scale))
        legend.set_zorder(5)
    missed_gt = sorted((g for g in gt if id(g) in missed), key=lambda g: g.location[2])  # near cars choose first
    _number_cars(ax, estimate, objects, camera, edges, w, h, scale, reserved, scores, false, missed_gt)
    return fig


# The key's line style of each kind of entry that is no plain line style.
_KEY_STYLES = {"hidden": "--", "missed": MISSED_DASHES, "false": "-", "ground": "-"}
#: What the key says a false car's tag means, by the tag's word (the evaluation's rule).
FALSE_KEY = {"false": "no labelled car of its own (IoU > 0.5)", "false view": "viewpoint > 45° off its car"}


def _false_key(false: dict[int, str], tag: str) -> list[tuple[str, str, str]]:
    """The key's entries of the false cars drawn, one a kind, each its ``tag`` (``#n c``) and word."""
    return [("false", FALSE_COLOR, f"{tag} {word}: {text}") for word, text in FALSE_KEY.items()
            if word in false.values()]


def _key_handle(style: str, color: str):
    """The overlay key's sample of an entry of ``style`` (a line style, or a kind of mark) in ``color``."""
    if style == "tag":
        return Patch(facecolor=color, alpha=0.85, lw=0)
    if style == "hidden":  # a hidden vertex of a car that says not what hides it: an open dot on a dashed edge
        return Line2D([], [], color=color, ls="--", marker="o", mfc=HIDDEN_FACE, ms=4)
    if style in HIDDEN_MARKS:
        marker, face, grow, _ = HIDDEN_MARKS[style]
        mark = Line2D([], [], color=color, ls="--" if style == "self" else "none", marker=marker, ms=3 * np.sqrt(grow),
                      mfc=color if face is None else face, mec=color, mew=1.0 if marker == "x" else 0.6)
        if style == "occluder":  # the mask's region behind its vertex
            return (_occluder_patch((0, 0), 1, 1, color, hatch=OCCLUDER_HATCH * 2), mark)  # denser: a few lines in it
        return mark
    return Line2D([], [], color=color, ls=_KEY_STYLES.get(style, style),
                  path_effects=_DROPPED_EFFECTS if color in (DROPPED_COLOR, GROUND_COLOR) else None)


def _draw_occluder(ax, camera: Camera, o, color: str) -> bool:
    """Hatch the image region the occluder mask the fit chose for car ``o`` covers (the rectangle
    of its wireframe's projected box that hides the vertices in it); whether there was one."""
    if not o.occluder_mask or o.vertices is None:  # None or 0: the empty mask, none chosen
        return False
    u0, v0, u1, v1 = mask_box(camera.project(np.asarray(o.vertices, float)), o.occluder_mask)
    ax.add_patch(_occluder_patch((u0, v0), u1 - u0, v1 - v0, color))
    return True


def _occluder_patch(corner, width: float, height: float, color: str, *, hatch: str = OCCLUDER_HATCH) -> Rectangle:
    """An occluder mask's region, hatched in ``color`` (its car's); over the ground's grid (0.9), under the
    pre-detections' boxes (1), the labels' boxes and the cars (2 and over)."""
    from matplotlib.colors import to_rgba

    # the hatch takes the edge's colour (matplotlib < 3.10 has no hatchcolor); no edge is drawn (lw 0)
    patch = Rectangle(corner, width, height, facecolor=OCCLUDER_VEIL, edgecolor=to_rgba(color, OCCLUDER_HATCH_ALPHA),
                      hatch=hatch, lw=0, zorder=0.95)
    if hasattr(patch, "set_hatch_linewidth"):  # matplotlib >= 3.10; before, rcParams["hatch.linewidth"] (1)
        patch.set_hatch_linewidth(0.8)
    return patch


def _number_cars(ax, estimate, objects, camera, edges, w, h, scale, reserved, scores, false, missed_gt) -> None:
    """Write each car's number (and confidence, and ``false`` where it is) by its box, then
    ``missed`` by each of ``missed_gt``'s, inside the picture, clear of the other tags, the
    title and the key where there is room."""
    numbers = car_numbers(estimate)
    placed = [(o, _image_box(camera, o, edges)) for o in reversed(objects)]  # near cars choose first
    placed = [(o, box) for o, box in placed if box is not None]
    texts = [_car_label(numbers[id(o)], o.score if scores else None) + (f" {false[id(o)]}" if id(o) in false else "")
             for o, _ in placed]
    faces = [FALSE_COLOR if id(o) in false else EST_COLOR for o, _ in placed]
    boxes = [box for _, box in placed] + [np.asarray(g.box, float) for g in missed_gt]
    texts += ["missed"] * len(missed_gt)
    faces += [GT_COLOR] * len(missed_gt)
    pad = 0.2
    sizes = [text_size(t, NUMBER_FONTSIZE, scale, pad) for t in texts]
    corners = place_labels(boxes, sizes, w, h, reserved=reserved)
    for text, face, (x, y) in zip(texts, faces, corners):
        ax.text(x + (pad * NUMBER_FONTSIZE + 1) * scale, y + (pad * NUMBER_FONTSIZE + 1) * scale, text,
                fontsize=NUMBER_FONTSIZE, color="black" if face == GT_COLOR else "white", va="top", ha="left",
                zorder=4, bbox=dict(facecolor=face, alpha=0.85, lw=0, boxstyle=f"square,pad={pad}"))


def _footprint(dims, location, R):
    c = box_corners(dims, location, R)
    return c[[0, 1, 5, 4, 0]][:, [0, 2]]  # bottom face outline in x-z (corner order of boxes.py)


def birds_eye(
    estimate=None,
    *,
    gt: Sequence | None = None,
    camera: Camera | None = None,
    extent: tuple[float, float, float, float] | None = None,
    title: str | None = None,
):
    """Top-down view in KITTI's camera frame (x to the camera's right, z ahead of it,
    metres; the camera a triangle at the origin) of estimated (red, numbered as in the
    overlay and the label file) and ground-truth (cyan) cars, with the camera's field of
    view (dotted). Where labels are drawn beside a fitted estimate, its false cars are
    violet and tagged ``false`` (``false view``: on a labelled car, its pre-detection's
    viewpoint over 45 deg off the car's), the labelled cars missed dashed and tagged
    ``missed``, and a thin dark line joins each car matched to a labelled car (2D IoU >
    0.5) to it: solid for a true positive, dash-dotted for a ``false view``, as
    :func:`wirescene.core.matching.match_estimate` judges (``gt`` None: no labels, nothing
    judged; empty: labelled without cars, as :func:`overlay`'s). Each number and tag lies
    beside its own car, clear of the others and of every footprint where there is room."""
    fig = new_figure(figsize=(5, 6), dpi=100)
    ax = fig.subplots()
    pts = [np.zeros(2)]
    numbers = car_numbers(estimate)
    gt, matches, false, missed = _verdicts(estimate, gt)

    def draw(dims, location, R, color, ls="-"):
        fp = _footprint(dims, location, R)
        ax.plot(fp[:, 0], fp[:, 1], color=color, lw=1.5, ls=ls)
        front = fp[[0, 1]].mean(axis=0)  # corners 0 and 1 are the front face
        ax.plot([location[0], front[0]], [location[2], front[1]], color=color, lw=1.0, ls=ls)
        pts.append(fp)
        return fp

    missed_fps = []
    for g in gt:
        fp = draw(g.dims, g.location, rotation_y(g.rotation_y), GT_COLOR, MISSED_DASHES if id(g) in missed else "-")
        if id(g) in missed:
            missed_fps.append(fp)
    labels = []
    if estimate is not None:
        for o in estimate.objects:
            color = FALSE_COLOR if id(o) in false else EST_COLOR
            labels.append((draw(o.dims, o.location, o.R, color),
                           f"#{numbers[id(o)]}" + (f" {false[id(o)]}" if id(o) in false else ""), color))
    links = _links(estimate, gt, matches)
    for (x0, z0, x1, z1), ok in links:  # over the footprints: a short link lies inside them
        ax.plot([x0, x1], [z0, z1], color=LINK_COLOR, lw=0.9, ls="-" if ok else "-.", zorder=2.5)  # not the view's :
    allp = np.vstack([np.atleast_2d(p) for p in pts])
    if extent is None:
        xmin, zmax = allp[:, 0].min() - 3, max(allp[:, 1].max() + 3, 10)
        xmax = allp[:, 0].max() + 3
        half = max(abs(xmin), abs(xmax), 8, 0.4 * (zmax + 2))  # a deep scene widens x rather than becoming a strip
        extent = (-half, half, -2, zmax)
    key = []
    front = " (#n: car n; a line marks the front)"  # said by the first entry of a car
    red = estimate is not None and any(id(o) not in false for o in estimate.objects)  # the red entry only if drawn
    if red:
        key.append((Line2D([], [], color=EST_COLOR), "estimate" + front))
    false_key = [text for *_, text in _false_key(false, "#n")]
    if false_key and not red:  # no red entry said it
        false_key[0] += front
    key.extend((Line2D([], [], color=FALSE_COLOR), text) for text in false_key)
    if len(gt):
        key.append((Line2D([], [], color=GT_COLOR), "ground truth"))
    if missed:
        key.append((Line2D([], [], color=GT_COLOR, ls=MISSED_DASHES), "missed labelled car"))
    if any(ok for _, ok in links):
        key.append((Line2D([], [], color=LINK_COLOR, lw=0.9), "found: estimate to its car"))
    if any(not ok for _, ok in links):
        key.append((Line2D([], [], color=LINK_COLOR, lw=0.9, ls="-."), "view off: estimate to its car"))
    if camera is not None and camera.image_size is not None:
        w = camera.image_size[0]
        for u in (0, w - 1):
            d = camera.rays(np.array([u, camera.K[1, 2]], float))
            t = extent[3] / max(d[2], 1e-3)
            ax.plot([0, d[0] * t], [0, d[2] * t], color="0.6", lw=0.8, ls=":")
        key.append((Line2D([], [], color="0.6", lw=0.8, ls=":"), "field of view"))
    ax.plot([0], [0], marker="^", color="black", ls="none")
    key.append((Line2D([], [], marker="^", color="black", ls="none"), "camera"))
    if estimate is not None and not estimate.objects:
        ax.text(0.5, 0.5, "no car estimated", transform=ax.transAxes, ha="center", va="center", color="0.3")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x: right of the camera (m)")
    ax.set_ylabel("z: ahead of the camera (m)")
    ax.grid(alpha=0.3)
    if title:
        ax.set_title(title, fontsize=10)
    rows = (len(key) + 1) // 2
    fig.tight_layout(rect=(0, (rows * 12 + 8) / (72 * fig.get_figheight()), 1, 1))  # room for the key's rows
    # the key right under the x axis's label, however short the equal-aspect axes are: off the cars and the label
    below = transforms.offset_copy(ax.transAxes, fig=fig, y=-34, units="points")
    # centred on the figure, not on the axes the y label pushes right: the key of every mark drawn fits its width
    below = transforms.blended_transform_factory(fig.transFigure, below)

    def legend(fontsize):
        return fig.legend([k[0] for k in key], [k[1] for k in key], loc="upper center", bbox_to_anchor=(0.5, 0.0),
                          bbox_transform=below, ncol=2, fontsize=fontsize, frameon=False)

    from matplotlib.backends.backend_agg import RendererAgg

    renderer = RendererAgg(*fig.canvas.get_width_height(), fig.dpi)
    for size in (8.0, 7.5, 7.0, 6.5):  # a key of many marks a size smaller where it would be cut
        key_box = legend(size)
        if size == 6.5 or key_box.get_window_extent(renderer).width <= fig.bbox.width:
            break
        key_box.remove()
    _tag_cars(ax, labels, missed_fps, pts[1:], extent)  # every footprint drawn (pts[0]: the camera)
    return fig


def _tag_cars(ax, numbers, missed, footprints, extent) -> None:
    """Write the cars' ``numbers`` ``[(footprint, text, colour)]``, then ``missed`` by each of the
    ``missed`` footprints, in a bird's-eye view laid out over ``extent``: each beside its own car
    (footprints ``(5, 2)`` x, z), inside the axes, clear of each other, of every car's
    ``footprints`` and of the camera where there is room (:func:`place_labels`, in points)."""
    if not numbers and not missed:
        return
    ax.apply_aspect()  # the equal-aspect axes' drawn size: metres a point
    scale = (extent[1] - extent[0]) / (ax.get_position().width * ax.figure.get_figwidth() * 72)

    def down(fp):  # the footprint's bounds in place_labels' frame: points from the axes' top left, y down
        x, z = fp[:, 0], fp[:, 1]
        return ((x.min() - extent[0]) / scale, (extent[3] - z.max()) / scale, (x.max() - extent[0]) / scale,
                (extent[3] - z.min()) / scale)

    u, v = -extent[0] / scale, extent[3] / scale
    camera = (u - 5, v - 5, u + 5, v + 5)  # its triangle (6 points) at the origin
    # (footprint, text, colour, font size, pad, box face): near cars choose first, as in the overlay
    tags = [(*n, NUMBER_FONTSIZE, 0.0, None) for n in sorted(numbers, key=lambda n: n[0][:, 1].mean())]
    tags += [(fp, "missed", "black", 6, 0.2, GT_COLOR) for fp in sorted(missed, key=lambda fp: fp[:, 1].mean())]
    sizes = [text_size(text, size, 1.0, pad) for _, text, _, size, pad, _ in tags]
    corners = place_labels([down(t[0]) for t in tags], sizes, (extent[1] - extent[0]) / scale,
                           (extent[3] - extent[2]) / scale, reserved=[*map(down, footprints), camera], stacked=False,
                           beside=True)
    for (_, text, color, size, pad, face), (_, th), (x, y) in zip(tags, sizes, corners):
        ax.text(extent[0] + (x + pad * size + 1) * scale, extent[3] - (y + th / 2) * scale, text, color=color,
                fontsize=size, va="center", ha="left", clip_on=True,
                bbox=None if face is None else dict(facecolor=face, alpha=0.85, lw=0, boxstyle=f"square,pad={pad}"))


def _links(estimate, gt: Sequence, matches: FrameMatches | None) -> list[tuple[tuple[float, ...], bool]]:
    """``[((x_est, z_est, x_gt, z_gt), true positive), ...]``: each car of ``estimate`` matched
    to a label of ``gt`` (:func:`judged`'s ``matches``), bottom centre to bottom centre."""
    if matches is None:
        return []
    cars, gt = estimate.cars, list(gt)
    return [((float(cars[d].location[0]), float(cars[d].location[2]), float(gt[g].location[0]),
              float(gt[g].location[2])), bool(matches.true_positive[d]))
            for d, g in enumerate(matches.match) if g >= 0]


def new_figure(**kwargs) -> Figure:
    """A :class:`matplotlib.figure.Figure` (``kwargs`` as its constructor's) outside pyplot.

    Examples
    --------
    >>> fig = new_figure(figsize=(2, 1), dpi=50)
    >>> ax = fig.subplots()
    >>> [int(v) for v in fig.get_size_inches() * fig.dpi]
    [100, 50]
    """
    return Figure(**kwargs)


# no date in a vector picture, and SVG ids from a fixed salt: the same figure gives the same bytes
_UNDATED = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}
#: zlib level of the PNG pictures: 1.8x Pillow's default 6 in speed for 13% more bytes, the same pixels
#: (``benchmarks/bench_picture_png.py``)
PNG_COMPRESS_LEVEL = 3


def save_figure(fig, path: str | Path, **savefig_kw) -> Path:
    """Save ``fig`` atomically (temporary file, then rename) in the format its suffix names
    (``.pdf``, ``.svg``, ...), PNG where matplotlib knows no such format; a figure pyplot
    manages (the caller's) is closed too. PNG, SVG and PDF files are the same bytes run to
    run (no creation date). ``savefig_kw``: further options of
    :meth:`~matplotlib.figure.Figure.savefig` (``dpi``, ``bbox_inches``, ``metadata``).
    Returns ``path``.

    Examples
    --------
    >>> import tempfile
    >>> fig = new_figure(figsize=(1, 1), dpi=20)
    >>> _ = fig.subplots().plot([0, 1])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = save_figure(fig, Path(d) / "plot.png")
    ...     path.read_bytes()[:4], sorted(p.name for p in Path(d).iterdir())  # a PNG, no temporary file left
    (b'\\x89PNG', ['plot.png'])
    """
    path = Path(path)
    fmt = path.suffix[1:].lower()
    if fmt not in fig.canvas.get_supported_filetypes():
        fmt = "png"
    write_bytes(path, figure_bytes(fig, fmt, **savefig_kw))
    return path


def figure_bytes(fig, fmt: str = "png", **savefig_kw) -> bytes:
    """The file :func:`save_figure` writes, as bytes (a worker process sends them to the process
    that writes its files); ``fmt`` one of ``fig.canvas.get_supported_filetypes()``. A figure
    pyplot manages is closed.

    Examples
    --------
    >>> fig = new_figure(figsize=(1, 1), dpi=20)
    >>> _ = fig.subplots().plot([0, 1])
    >>> figure_bytes(fig)[:4]
    b'\\x89PNG'
    """
    if fmt in _UNDATED:
        savefig_kw.setdefault("metadata", _UNDATED[fmt])
    if fmt == "png":
        savefig_kw["pil_kwargs"] = {"compress_level": PNG_COMPRESS_LEVEL, **savefig_kw.get("pil_kwargs", {})}
    buffer = io.BytesIO()
    try:
        with rc_context({"svg.hashsalt": "wirescene"}):
            fig.savefig(buffer, format=fmt, **savefig_kw)
    finally:
        pyplot = sys.modules.get("matplotlib.pyplot")
        if pyplot is not None:
            pyplot.close(fig)
    return buffer.getvalue()
