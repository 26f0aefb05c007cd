"""Pictures of what the model did: image overlays and bird's-eye views.

Estimates are drawn in red, ground truth in green, as in the paper's figures. All
functions draw into a new :class:`matplotlib.figure.Figure` (:func:`new_figure`) and
return it; :func:`save_figure` writes it atomically. No pyplot: the figures belong to
no window manager, need no display, and the caller's matplotlib backend (a notebook's,
say) is left as it was.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib import rc_context
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from wirescene.core.atomic import atomic_path
from wirescene.core.boxes import box_corners
from wirescene.core.camera import NEAR_PLANE, Camera
from wirescene.core.groundplane import rotation_y

EST_COLOR = "#e8302a"
GT_COLOR = "#2fbf40"
DET_COLOR = "#f5d90a"
# Box edges as corner index pairs for the corner order of boxes.box_corners_object.
_BOX_EDGES = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
_FRONT_FACE = [(0, 3), (1, 2)]  # cross on the front face marks the heading


HIDDEN_COLOR = "#2f6fe8"


def _draw_edges(ax, camera: Camera, points: np.ndarray, edges, color: str, lw: float) -> None:
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
    ax.add_collection(LineCollection(np.stack([uv[:len(a)], uv[len(a):]], axis=1), colors=color, linewidths=lw))


def _draw_box3d(ax, camera: Camera, corners: np.ndarray, color: str, lw: float = 1.5):
    _draw_edges(ax, camera, corners, _BOX_EDGES, color, lw)
    _draw_edges(ax, camera, corners, _FRONT_FACE, color, lw * 0.6)


def draw_wireframe(ax, camera: Camera, vertices: np.ndarray, edges: np.ndarray, *, visible=None, color=EST_COLOR):
    """Draw a wireframe ``(V, 3)`` with ``edges`` ``(E, 2)``; hidden vertices in blue, dots
    sized by the car's height in the image (a far car's dots would hide it)."""
    vertices = np.asarray(vertices, float)
    _draw_edges(ax, camera, vertices, edges, color, 1.0)
    uv, depth = camera.project_with_depth(vertices)
    front = depth > NEAR_PLANE
    if not front.any():
        return
    size = float(np.clip(np.ptp(uv[front, 1]) / 8.0, 1.0, 10.0))
    vis = np.ones(len(uv), bool) if visible is None else np.asarray(visible, bool)
    ax.scatter(uv[vis & front, 0], uv[vis & front, 1], s=size, c=color, zorder=3)
    ax.scatter(uv[~vis & front, 0], uv[~vis & front, 1], s=size, c=HIDDEN_COLOR, zorder=3)


def overlay(
    image: np.ndarray,
    camera: Camera,
    estimate=None,
    *,
    gt: Sequence = (),
    detections=None,
    title: str | None = None,
    edges: np.ndarray | None = None,
    estimate_name: str = "estimate",
):
    """Image with detections (yellow), estimated 3D boxes or wireframes (red) and
    ground-truth 3D boxes (green).

    Parameters
    ----------
    image : (H, W, 3) uint8 array
    camera : Camera
        The image's camera (``P2``).
    estimate : SceneEstimate, optional
    gt : sequence of kitti ``Label``
    detections : Detections, optional
    title : str, optional
        A line written at the top left.
    edges : (E, 2) int array, optional
        Wireframe edges, used for objects that carry ``vertices``.
    estimate_name : str, optional
        What the key calls the red objects (``wirescene gt`` draws no estimate).
    """
    h, w = image.shape[:2]
    fig = new_figure(figsize=(w / 100, h / 100), dpi=100)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.imshow(image)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.axis("off")
    if detections is not None:
        for b in detections.boxes:
            ax.add_patch(Rectangle((b[0], b[1]), b[2] - b[0], b[3] - b[1], fill=False, ec=DET_COLOR, lw=1, ls="--"))
    for g in sorted(gt, key=lambda g: -g.location[2]):  # far to near: a near car is drawn over a far one
        _draw_box3d(ax, camera, box_corners(g.dims, g.location, rotation_y(g.rotation_y)), GT_COLOR, 1.0)
    objects = [] if estimate is None else sorted(estimate.objects, key=lambda o: -o.location[2])
    wireframes = edges is not None and any(o.vertices is not None for o in objects)
    for o in objects:
        if o.vertices is not None and edges is not None:
            draw_wireframe(ax, camera, o.vertices, edges, visible=o.visibility)
        else:
            _draw_box3d(ax, camera, box_corners(o.dims, o.location, o.R), EST_COLOR)
    if title:
        ax.text(5, 15, title, color="white", fontsize=10, bbox=dict(facecolor="black", alpha=0.5, lw=0))
    key = []  # what each colour means, for the parts drawn
    if objects:
        key.append(("-", EST_COLOR, estimate_name + (" (a cross marks the front)" if not wireframes else "")))
        if wireframes and any(o.visibility is not None and not np.all(o.visibility) for o in objects):
            key.append(("o", HIDDEN_COLOR, "hidden part"))
    if len(gt):
        key.append(("-", GT_COLOR, "ground truth"))
    if detections is not None and len(detections.boxes):
        key.append(("--", DET_COLOR, "pre-detection"))
    if key:
        from matplotlib.lines import Line2D

        handles = [Line2D([], [], color=c, ls="none" if s == "o" else s, marker="o" if s == "o" else None, ms=4)
                   for s, c, _ in key]
        ax.legend(handles, [k[2] for k in key], loc="upper right", fontsize=7, framealpha=0.6, borderpad=0.4)
    return fig


def _footprint(dims, location, R):
    c = box_corners(dims, location, R)
    return c[[0, 1, 5, 4, 0]][:, [0, 2]]  # bottom face outline in x-z (corner order of boxes.py)


def birds_eye(
    estimate=None,
    *,
    gt: Sequence = (),
    camera: Camera | None = None,
    extent: tuple[float, float, float, float] | None = None,
    title: str | None = None,
):
    """Top-down view (x right, z up the page) of estimated (red) and GT (green) cars,
    with the camera's field of view."""
    fig = new_figure(figsize=(5, 6), dpi=100)
    ax = fig.subplots()
    pts = [np.zeros(2)]

    def draw(dims, location, R, color):
        fp = _footprint(dims, location, R)
        ax.plot(fp[:, 0], fp[:, 1], color=color, lw=1.5)
        front = fp[[0, 1]].mean(axis=0)  # corners 0 and 1 are the front face
        ax.plot([location[0], front[0]], [location[2], front[1]], color=color, lw=1.0)
        pts.append(fp)

    for g in gt:
        draw(g.dims, g.location, rotation_y(g.rotation_y), GT_COLOR)
    if estimate is not None:
        for o in estimate.objects:
            draw(o.dims, o.location, o.R, EST_COLOR)
    allp = np.vstack([np.atleast_2d(p) for p in pts])
    if extent is None:
        xmin, zmax = allp[:, 0].min() - 3, max(allp[:, 1].max() + 3, 10)
        xmax = allp[:, 0].max() + 3
        half = max(abs(xmin), abs(xmax), 8, 0.4 * (zmax + 2))  # a deep scene widens x rather than becoming a strip
        extent = (-half, half, -2, zmax)
    if camera is not None and camera.image_size is not None:
        w = camera.image_size[0]
        for u in (0, w - 1):
            d = camera.rays(np.array([u, camera.K[1, 2]], float))
            t = extent[3] / max(d[2], 1e-3)
            ax.plot([0, d[0] * t], [0, d[2] * t], color="0.6", lw=0.8, ls=":")
    ax.plot([0], [0], marker="^", color="black")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.grid(alpha=0.3)
    ax.plot([], [], color=EST_COLOR, label="estimate (a line marks the front)")
    ax.plot([], [], color=GT_COLOR, label="ground truth")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8, frameon=False)  # off the cars
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


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


def save_figure(fig, path: str | Path, **savefig_kw) -> Path:
    """Save ``fig`` atomically (temporary file, then rename) in the format its suffix names
    (``.pdf``, ``.svg``, ...), PNG where matplotlib knows no such format; a figure pyplot
    manages (the caller's) is closed too. PNG, SVG and PDF files are the same bytes run to
    run (no creation date). ``savefig_kw``: further options of
    :meth:`~matplotlib.figure.Figure.savefig` (``dpi``, ``bbox_inches``, ``metadata``)."""
    path = Path(path)
    fmt = path.suffix[1:].lower()
    if fmt not in fig.canvas.get_supported_filetypes():
        fmt = "png"
    if fmt in _UNDATED:
        savefig_kw.setdefault("metadata", _UNDATED[fmt])
    try:
        with atomic_path(path, suffix=f".{fmt}") as tmp, rc_context({"svg.hashsalt": "wirescene"}):
            fig.savefig(tmp, format=fmt, **savefig_kw)
    finally:
        pyplot = sys.modules.get("matplotlib.pyplot")
        if pyplot is not None:
            pyplot.close(fig)
    return path
