"""Semi-local part configurations (paper Sec. 3.4): sets of 3-4 wireframe vertices that
are adjacent in :data:`wirescene.core.wireframe.EDGES`, visible from a coarse viewpoint (one of
8 bins of the observation angle) and cover at least ~20% of the car's 2D box, plus one
full-car configuration per viewpoint.

Every configuration stores, learned from training cars, its template shape (HOG cells),
the mean size of its box relative to the full-object box and the mean offsets that map a
configuration box back to the full-object box (poselet-style voting).

Geometry conventions
--------------------
* ``vertex box``: bounding box of the 36 projected vertices (amodal: hidden vertices too).
* ``full box``: the vertex box corrected to the car's silhouette extent (per-bin mean
  correction learned from unoccluded, untruncated training cars, whose label box is the
  silhouette box); this is what detections predict.
* ``configuration box``: bounding box of the configuration's vertices, grown by
  ``MARGIN`` of the full box on every side and to at least ``MIN_SIZE`` of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wirescene.core.boxes import iou_2d
from wirescene.core.groundplane import wrap_angle
from wirescene.core.viewpoints import N_BINS
from wirescene.core.wireframe import EDGES, MIRROR, N_VERTICES, VERTEX_NAMES

MARGIN = 0.08
MIN_SIZE = 0.3
FULL = tuple(range(N_VERTICES))


def mirror_bin(b):
    """Viewpoint bin of the horizontally flipped image (alpha -> pi - alpha).

    Examples
    --------
    >>> mirror_bin(np.arange(8))  # bins 2 and 6 (alpha +-90 deg) are their own mirror images
    array([4, 3, 2, 1, 0, 7, 6, 5])
    """
    return (4 - np.asarray(b)) % N_BINS


def mirror_alpha(alpha):
    """Observation angles ``(...)`` in the horizontally flipped image: ``pi - alpha``, in ``[-pi, pi)``.

    Examples
    --------
    >>> mirror_alpha([0.0, np.pi / 2, 0.5]).round(4)  # pi - alpha, wrapped into [-pi, pi)
    array([-3.1416,  1.5708,  2.6416])
    """
    return wrap_angle(np.pi - np.asarray(alpha, dtype=float))


@dataclass
class Configuration:
    """One part configuration seen from one viewpoint bin.

    Examples
    --------
    >>> c = Configuration(bin=0, vertices=(0, 1, 2), template=(4, 6), offsets=np.array([-0.5, -0.2, 0.5, 0.3]),
    ...                   frac=np.array([0.5, 0.6]), coverage=0.3)
    >>> c.name, c.is_full
    ('bin0:nose_bottom_left+nose_top_left+headlight_left', False)
    >>> c.full_box([[100, 100, 160, 150]])  # cfg box + offsets * (60, 50, 60, 50)
    array([[ 70.,  90., 190., 165.]])
    """

    bin: int
    vertices: tuple  # vertex indices; all 36 for the full-car configuration
    template: tuple  # (th, tw) HOG cells
    offsets: np.ndarray  # (4,) full box = cfg box + offsets * (w, h, w, h)
    frac: np.ndarray  # (2,) mean cfg box (width, height) / full box (width, height)
    coverage: float  # mean cfg box area / full box area
    n_examples: int = 0

    @property
    def is_full(self) -> bool:
        return len(self.vertices) == N_VERTICES

    @property
    def name(self) -> str:
        if self.is_full:
            return f"bin{self.bin}:full"
        return f"bin{self.bin}:" + "+".join(VERTEX_NAMES[v] for v in self.vertices)

    def full_box(self, cfg_boxes: np.ndarray) -> np.ndarray:
        """(N, 4) full-object boxes predicted from (N, 4) configuration boxes."""
        b = np.asarray(cfg_boxes, float).reshape(-1, 4)
        wh = np.stack([b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]], 1)
        return b + self.offsets[None] * np.concatenate([wh, wh], 1)


# --------------------------------------------------------------------------- topology


def _adjacency() -> list[set]:
    adj = [set() for _ in range(N_VERTICES)]
    for a, b in EDGES:
        adj[int(a)].add(int(b))
        adj[int(b)].add(int(a))
    return adj


def connected_subsets(sizes=(3, 4)) -> list[tuple]:
    """All vertex sets of the given sizes that are connected in the wireframe graph.

    Examples
    --------
    >>> subsets = connected_subsets()
    >>> len(subsets), subsets[:2], len(connected_subsets((3,)))
    (374, [(0, 1, 2), (0, 1, 2, 3)], 116)
    """
    adj = _adjacency()
    found: set = set()
    frontier = {frozenset([v]) for v in range(N_VERTICES)}
    for size in range(2, max(sizes) + 1):
        nxt = set()
        for s in frontier:
            for v in s:
                for u in adj[v] - s:
                    nxt.add(s | {u})
        frontier = nxt
        if size in sizes:
            found |= nxt
    return sorted(tuple(sorted(s)) for s in found)


# --------------------------------------------------------------------------- examples


@dataclass
class CarExample:
    """One training car (possibly a horizontally flipped copy) in one training image."""

    image: int  # index of the training image
    flipped: bool
    bin: int
    v2d: np.ndarray  # (36, 2) projected vertices (in the flipped frame if flipped)
    visible: np.ndarray  # (36,) visible (not hidden by anything, inside the image)
    geom_visible: np.ndarray  # (36,) not self-occluded and inside the image
    label_box: np.ndarray  # (4,) visible extent
    occ_frac: float
    truncated: float
    full_box: np.ndarray = field(default=None)
    alpha: float = float("nan")  # KITTI observation angle (in the flipped frame if flipped); nan: unknown

    @property
    def clean(self) -> bool:
        return self.occ_frac < 0.03 and self.truncated <= 0.0

    @property
    def vertex_box(self) -> np.ndarray:
        return np.array([*self.v2d.min(0), *self.v2d.max(0)])


def examples_from_wireframes(wire: dict, labels, image_index: int, width: int, *, flips: bool = True) -> list:
    """Car examples (and their mirror images) of one synthetic scene."""
    from wirescene.core.viewpoints import viewpoint_bin

    out = []
    for lab, car in zip(labels.objects, wire["cars"]):
        v2d = np.asarray(car["vertices_2d"], float)
        reasons = car["visibility"]
        vis = np.array([r == "visible" for r in reasons])
        geom = np.array([r not in ("self", "truncated") for r in reasons])
        b = int(viewpoint_bin(lab.alpha))
        kw = dict(occ_frac=float(car["occluded_fraction"]), truncated=float(lab.truncated))
        out.append(CarExample(image_index, False, b, v2d, vis, geom, lab.box.copy(), alpha=float(lab.alpha), **kw))
        if flips:
            fv = v2d[MIRROR].copy()
            fv[:, 0] = (width - 1) - fv[:, 0]
            box = lab.box.copy()
            box[[0, 2]] = (width - 1) - lab.box[[2, 0]]
            out.append(CarExample(image_index, True, int(mirror_bin(b)), fv, vis[MIRROR], geom[MIRROR], box,
                                  alpha=float(mirror_alpha(lab.alpha)), **kw))
    return out


def learn_full_box_correction(examples) -> np.ndarray:
    """(8, 4) per-bin mean of (label box - vertex box) / vertex (w, h, w, h) over clean cars."""
    corr = np.zeros((N_BINS, 4))
    rel_all, bins = [], []
    for e in examples:
        if e.clean and e.label_box[3] - e.label_box[1] >= 20:
            vb = e.vertex_box
            wh = np.array([vb[2] - vb[0], vb[3] - vb[1]] * 2)
            rel_all.append((e.label_box - vb) / wh)
            bins.append(e.bin)
    rel_all, bins = np.array(rel_all).reshape(-1, 4), np.array(bins, int)
    glob = np.median(rel_all, 0) if len(rel_all) else np.zeros(4)
    for b in range(N_BINS):
        sel = rel_all[bins == b]
        corr[b] = np.median(sel, 0) if len(sel) >= 5 else glob
    return corr


def apply_full_box(examples, corr: np.ndarray) -> None:
    for e in examples:
        vb = e.vertex_box
        wh = np.array([vb[2] - vb[0], vb[3] - vb[1]] * 2)
        e.full_box = vb + corr[e.bin] * wh


def config_box(v2d: np.ndarray, vertices, full_box: np.ndarray) -> np.ndarray:
    """Configuration box of vertex set ``vertices`` (see module docstring).

    Examples
    --------
    >>> v2d = np.array([[x, y] for x in range(6) for y in range(6)], float) * 10  # 36 vertices on a grid
    >>> full = np.array([0.0, 0, 50, 50])
    >>> config_box(v2d, FULL, full)  # the full-car configuration: the full box itself
    array([ 0.,  0., 50., 50.])
    >>> config_box(v2d, (0, 1, 2), full)  # (0, 0)..(0, 20) grown by 4 px, then to 15 px (30%) wide
    array([-7.5, -4. ,  7.5, 24. ])
    """
    fb = np.asarray(full_box, float)
    if len(vertices) == N_VERTICES:
        return fb.copy()
    p = np.asarray(v2d)[list(vertices)]
    fw, fh = fb[2] - fb[0], fb[3] - fb[1]
    x1, y1 = p.min(0) - MARGIN * np.array([fw, fh])
    x2, y2 = p.max(0) + MARGIN * np.array([fw, fh])
    cx, cy = (x1 + x2) / 2, (y1 + y2) / 2
    w, h = max(x2 - x1, MIN_SIZE * fw), max(y2 - y1, MIN_SIZE * fh)
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2])


def _normalised(box, full):
    wh = np.array([full[2] - full[0], full[3] - full[1]] * 2)
    return (np.asarray(box) - np.array([full[0], full[1]] * 2)) / wh


def template_shape(aspect: float, area_cells: float) -> tuple:
    """``(th, tw)`` HOG cells of a template of about ``area_cells`` cells whose width is
    ``aspect`` times its height, at least 3 x 3.

    Examples
    --------
    >>> template_shape(2.0, 60), template_shape(0.5, 42)  # th = round(sqrt(area / aspect)), tw = round(area / th)
    ((5, 12), (9, 5))
    """
    th = max(3, int(round(np.sqrt(area_cells / max(aspect, 1e-3)))))
    tw = max(3, int(round(area_cells / th)))
    return th, tw


def make_configuration(b: int, vertices, examples, *, area_cells: float) -> Configuration:
    """Statistics of one configuration over the examples of its bin."""
    boxes = np.array([config_box(e.v2d, vertices, e.full_box) for e in examples])
    fulls = np.array([e.full_box for e in examples])
    wh = np.stack([boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]], 1)
    fwh = np.stack([fulls[:, 2] - fulls[:, 0], fulls[:, 3] - fulls[:, 1]], 1)
    offsets = np.median((fulls - boxes) / np.concatenate([wh, wh], 1), 0)
    frac = np.median(wh / fwh, 0)
    aspect = float(np.median(wh[:, 0] / wh[:, 1]))
    return Configuration(b, tuple(int(v) for v in vertices), template_shape(aspect, area_cells), offsets, frac,
                         float(np.median(np.prod(wh / fwh, 1))), len(examples))


def select_configurations(examples, *, n_partial: int = 3, min_coverage: float = 0.2,
                          max_coverage: float = 0.6, min_visible_rate: float = 0.9,
                          max_iou: float = 0.3, full_area: float = 60, partial_area: float = 42,
                          min_height: float = 25, bins=range(N_BINS)) -> list[Configuration]:
    """Choose the configurations of every bin.

    Candidates: connected 3-4 vertex sets whose vertices are all geometrically visible
    (not self-occluded, inside the image) in >= ``min_visible_rate`` of the bin's training
    cars and whose box covers ``min_coverage..max_coverage`` of the full box (median).
    Greedy selection by coverage, skipping a candidate whose mean normalised box overlaps
    an already chosen one by IoU > ``max_iou`` (so the chosen ones look at different
    regions of the car: diversity stands in for the paper's validation-set
    discriminativeness). Every bin also gets the full-car configuration, listed first.
    """
    cands = connected_subsets()
    cand_idx = [np.array(c) for c in cands]
    out = []
    for b in bins:
        ex = [e for e in examples if e.bin == b and e.full_box[3] - e.full_box[1] >= min_height
              and e.truncated <= 0.0]
        if not ex:
            continue
        full_ex = [e for e in ex if e.occ_frac < 0.2]
        out.append(make_configuration(b, FULL, full_ex or ex, area_cells=full_area))
        geom = np.array([e.geom_visible for e in ex])  # (n, 36)
        scored = []
        for c, ci in zip(cands, cand_idx):
            rate = geom[:, ci].all(1).mean()
            if rate < min_visible_rate:
                continue
            nb = np.array([_normalised(config_box(e.v2d, c, e.full_box), e.full_box) for e in ex])
            cov = float(np.median((nb[:, 2] - nb[:, 0]) * (nb[:, 3] - nb[:, 1])))
            if min_coverage <= cov <= max_coverage:
                scored.append((cov, c, np.median(nb, 0)))
        scored.sort(key=lambda t: (-t[0], t[1]))
        chosen = []
        for cov, c, nb in scored:
            if len(chosen) >= n_partial:
                break
            if all(iou_2d(nb, o) <= max_iou for _, _, o in chosen):
                chosen.append((cov, c, nb))
        for _, c, _ in chosen:
            out.append(make_configuration(b, c, ex, area_cells=partial_area))
    return out
