"""Side-view depth image of a canonical car mesh: the geometric evidence from which the
road-car rule (:mod:`wirescene.cad.mesh`) and the automatic landmarks
(:mod:`wirescene.cad.landmarks`) are read.

Rays are cast from the car's left (+z) towards the mid-plane on a regular (x, height)
grid; each pixel keeps the z of the first surface hit. From that image:

- the *silhouette* is the set of hit pixels, opened with a 3 cm disk (removes antennas
  and thin mounts) and reduced to its largest connected component;
- the *skin* is the part of the silhouette whose depth is within 10 cm of the body side
  (the 90 % quantile of z in the lower 60 % of the height); pixels behind it -- wheel
  houses, open arches -- are not skin, which is what makes the arches visible;
- per column, ``top`` is the upper end of the lowest contiguous run of silhouette pixels
  (gaps up to 3 cm are bridged), so that a rear wing above a gap is not taken for the
  boot lid, and ``low_skin`` is the lowest skin pixel. Behind the highest point of
  ``top`` between the wheel arches the profile is then made non-increasing towards the rear (and in front of it
  towards the front): a car's roof line only falls towards its ends, so whatever rises
  again -- rear wings, spoiler mounts -- is not body;
- the body's front and rear ends are the extreme silhouette columns below 55 % of the
  height (a wing may overhang the tail higher up);
- the approach clearance (:func:`approach_clearance`) is the lowest silhouette pixel
  between the front end of the car and its front wheel arch;
- wheel arches (:func:`find_arches`) are the runs of columns whose lowest skin pixel is
  more than 15 cm above the sill (median lowest skin in the middle 20 % of the length),
  the longest run in each half of the car.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from wirescene.core.raycast import require_ray_tracer

SKIN_DEPTH = 0.10
GAP = 0.03
ARCH_RISE = 0.15
END_ROWS = 0.55


@dataclass
class SideView:
    """Side depth image (rows: height above ground increasing; columns: x increasing).

    Attributes
    ----------
    res : float
        Pixel size in metres.
    xs : (nx,) array
        Object-frame x of the pixel centres.
    hs : (nh,) array
        Heights above ground (``-y``) of the pixel centres.
    depth : (nh, nx) array
        z of the first hit from the left, NaN where the ray missed.
    silhouette, skin : (nh, nx) bool arrays
    z_side : float
        Half-width of the body side used for the skin test.
    top, low_skin : (nx,) arrays
        Per-column heights (NaN for empty columns).
    front_col, rear_col : int
        Columns of the body's front and rear ends.
    """

    res: float
    xs: np.ndarray
    hs: np.ndarray
    depth: np.ndarray
    silhouette: np.ndarray
    skin: np.ndarray
    z_side: float
    top: np.ndarray
    low_skin: np.ndarray
    front_col: int
    rear_col: int

    def col(self, x) -> int:
        return int(np.clip(np.round((x - self.xs[0]) / self.res), 0, len(self.xs) - 1))

    def row(self, h) -> int:
        return int(np.clip(np.round((h - self.hs[0]) / self.res), 0, len(self.hs) - 1))

    def z_near(self, x, h, toward=(0.0, None), *, max_dist=0.15) -> float:
        """Depth of the silhouette at (x, h) or, if that pixel is empty, at the first
        silhouette pixel on the way toward ``toward`` (default: the car's centre)."""
        tx = toward[0]
        th = toward[1] if toward[1] is not None else 0.5 * self.hs[-1]
        direction = np.array([tx - x, th - h])
        norm = np.linalg.norm(direction)
        direction = direction / norm if norm > 0 else direction
        for step in np.arange(0.0, max_dist + 1e-9, self.res):
            c, r = self.col(x + step * direction[0]), self.row(h + step * direction[1])
            if self.silhouette[r, c] and np.isfinite(self.depth[r, c]):
                return float(self.depth[r, c])
        return float("nan")


def _disk(radius: int) -> np.ndarray:
    yy, xx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    return xx**2 + yy**2 <= radius**2


def side_view(vertices, faces, *, res: float = 0.01) -> SideView:
    """Build the :class:`SideView` of an object-frame mesh (see the module docstring)."""
    import trimesh

    v = np.asarray(vertices, dtype=float)
    mesh = trimesh.Trimesh(v, np.asarray(faces), process=False)
    lo, hi = v.min(axis=0), v.max(axis=0)
    xs = np.arange(lo[0], hi[0], res) + res / 2
    hs = np.arange(0.0, -lo[1], res) + res / 2
    X, H = np.meshgrid(xs, hs)
    origins = np.stack([X.ravel(), -H.ravel(), np.full(X.size, hi[2] + 1.0)], axis=1)
    dirs = np.tile([0.0, 0.0, -1.0], (X.size, 1))
    require_ray_tracer()
    loc, ray_idx, _ = mesh.ray.intersects_location(origins, dirs, multiple_hits=False)
    depth = np.full(X.size, np.nan)
    depth[ray_idx] = loc[:, 2]
    depth = depth.reshape(X.shape)

    hit = np.isfinite(depth)
    opened = ndimage.binary_opening(hit, structure=_disk(max(1, int(round(0.03 / res)))))
    labels, n = ndimage.label(opened)
    if n > 1:
        sizes = ndimage.sum(opened, labels, index=np.arange(1, n + 1))
        opened = labels == (1 + int(np.argmax(sizes)))
    silhouette = opened

    lower = hs < 0.6 * hs[-1]
    z_side = float(np.nanquantile(np.where(silhouette[lower], depth[lower], np.nan), 0.9))
    skin = silhouette & (depth > z_side - SKIN_DEPTH)

    gap = int(round(GAP / res))
    bridged = ndimage.binary_closing(silhouette, structure=np.ones((2 * gap + 1, 1)), border_value=0) | silhouette
    top = np.full(len(xs), np.nan)
    low_skin = np.full(len(xs), np.nan)
    for j in range(len(xs)):
        col = bridged[:, j]
        if col.any():
            first = int(np.argmax(col))
            run_end = first + int(np.argmin(col[first:])) if not col[first:].all() else len(col)
            top[j] = hs[run_end - 1]
        s = skin[:, j]
        if s.any():
            low_skin[j] = hs[int(np.argmax(s))]
    # The roof peak lies between the axles (a rear wing may be as high as the roof).
    front_arch, rear_arch, _ = _arch_runs(xs, low_skin)
    lo_c = rear_arch[1] if rear_arch is not None else int(0.2 * len(xs))
    hi_c = front_arch[0] if front_arch is not None else int(0.8 * len(xs))
    peak = lo_c + int(np.nanargmax(top[lo_c:hi_c]))
    # Roof line falls monotonically towards both ends (removes wings; see docstring).
    rear = top[:peak + 1][::-1]
    top[:peak + 1] = np.fmin.accumulate(np.where(np.isnan(rear), np.inf, rear))[::-1]
    top[peak:] = np.fmin.accumulate(np.where(np.isnan(top[peak:]), np.inf, top[peak:]))
    top[~np.isfinite(top)] = np.nan
    body_cols = np.flatnonzero(silhouette[hs < END_ROWS * hs[-1]].any(axis=0))
    return SideView(res, xs, hs, depth, silhouette, skin, z_side, top, low_skin,
                    int(body_cols[-1]), int(body_cols[0]))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the True runs of a 1-D mask."""
    padded = np.concatenate([[False], mask, [False]]).astype(int)
    d = np.diff(padded)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def find_arches(sv: SideView):
    """Wheel arches of a side view.

    Returns
    -------
    front, rear : (start, stop) column runs, or None where no arch was found
    sill : float
        Sill height (m).
    """
    return _arch_runs(sv.xs, sv.low_skin)


def _arch_runs(xs, low):
    n = len(xs)
    sill = float(np.nanmedian(low[int(0.4 * n):int(0.6 * n)]))
    high = np.nan_to_num(low, nan=-1.0) > sill + ARCH_RISE
    runs = _runs(high)
    front = [r for r in runs if xs[(r[0] + r[1] - 1) // 2] > 0]
    rear = [r for r in runs if xs[(r[0] + r[1] - 1) // 2] <= 0]
    pick = lambda rs: max(rs, key=lambda r: r[1] - r[0]) if rs else None  # noqa: E731
    return pick(front), pick(rear), sill


def approach_clearance(sv: SideView) -> float:
    """Front overhang (approach) clearance: the lowest silhouette pixel between the
    front end of the car and its front wheel arch, in metres; NaN without a front arch.

    Only the front is used: race cars' rear diffusers lift the rear overhang as much as
    an off-road body does."""
    front, _, _ = find_arches(sv)
    if front is None:
        return float("nan")
    cols = slice(front[1], sv.front_col + 1)
    sil = sv.silhouette[:, cols]
    if not sil.any():
        return float("nan")
    return float(np.min(sv.hs[np.argmax(sil, axis=0)][sil.any(axis=0)]))
