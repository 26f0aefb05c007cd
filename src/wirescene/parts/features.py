"""Patch descriptors on edge maps for the part detectors (paper Sec. 3.2, 5.1).

Train and test live in one domain: *edge maps at a canonical scale*.

* Training: non-photorealistic renderings (:func:`wirescene.render.render`, 1-pixel
  silhouette/crease lines). Test: Canny edges of the grey image
  (:func:`image_edges`). Both are 1-pixel binary line maps at their native resolution.
* :func:`canonical_edges` resamples such a map by a factor ``z`` so that the object's 2D
  box height becomes :data:`CANONICAL_HEIGHT` pixels, dividing by ``z`` so that the
  map's mass stays "edge length in canonical pixels" whatever ``z`` is (a resampled
  1-pixel line keeps unit mass per unit length).
* A patch is the ``PATCH x PATCH`` window (``PATCH = 2 * RADIUS + 1``) of the canonical
  map around a point, i.e. about half the box height (about 15% of a side-viewed car's
  length, the paper's "~10% of the object width" up to the larger context that the shape
  context needs).

Descriptors (``extract(..., kind=...)``):

``"sc"`` -- shape context (Belongie et al.): a log-polar histogram of edge mass around
    the patch centre, 3 rings (radii 4.5, 9.5, 16.5 px) x 12 angular sectors, L1-normalised, plus
    ``log1p(total mass)``: 37 numbers. Every bin is a fixed linear kernel on the patch, so
    the descriptor of *every* pixel of a map is 36 FFT correlations (:func:`dense_sc`);
    the sparse path (patches @ kernels) gives the same numbers.
``"hog"`` -- :func:`skimage.feature.hog` of the (32 x 32) patch, 8-pixel cells, 2 x 2
    blocks, 9 orientations: 324 numbers. Only patch-wise (dense HOG maps are patch loops).
``"ghog"`` -- gradient-orientation histograms of the *grey image* (not of an edge map),
    resampled to the same canonical scale (:func:`canonical_grey`): unsigned orientation
    in :data:`GHOG_BINS` bins (linear vote split between the two nearest bins, weighted by
    the gradient magnitude), summed over a 4 x 4 grid of 8 x 8-pixel cells covering the
    32 x 32 patch (:func:`orientation_cells`: one box filter per bin, so every pixel's
    cells cost O(1)), L2-Hys normalised, plus ``log1p(total gradient mass)``: 145 numbers.
    Dense and sparse evaluation are the same gather (:func:`ghog_at`). Transfers from
    synthetic shaded scenes to real images much better than Canny-based shape context.
``"ghog_sc"`` -- ``"ghog"`` and ``"sc"`` concatenated (182 numbers).
``"ghog_ms"`` -- two-scale ``"ghog"``: the 4 x 4 grid of 8-pixel cells and a coarse 4 x 4
    grid of 16-pixel cells (:data:`GHOG_COARSE_OFFSETS`, a 64 x 64 window: the whole car
    height, so the descriptor sees where in the car a point lies): 290 numbers.
``"ghog_msc"`` -- ``"ghog_ms"`` plus colour: mean grey and two opponent-colour channels
    over a 3 x 3 grid of 16-pixel cells (:data:`COLOUR_OFFSETS`; tyres are dark, glass
    and lights have distinct hues): 317 numbers.

Grey-image kinds need the canonical grey image as well as (for ``"sc"``) the edge map:
:func:`canonical_inputs` builds what a kind needs from a native image crop, and
:func:`describe` evaluates any kind at points of those inputs (this is what both the
training and :func:`wirescene.parts.detector.response_maps` call).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from wirescene.core.errors import ShapeError
from wirescene.core.image import to_grey

__all__ = [
    "CANONICAL_HEIGHT", "RADIUS", "PATCH", "SC_RING_EDGES", "SC_N_ANGLES", "KINDS",
    "sc_kernels", "canonical_edges", "to_canonical", "image_edges", "extract_patches", "extract", "dense_sc",
    "feature_dim", "GHOG_BINS", "GHOG_CELL", "GHOG_OFFSETS", "image_grey", "canonical_grey",
    "orientation_cells", "ghog_at", "canonical_inputs", "describe", "GREY_KINDS", "EDGE_KINDS", "context_radius",
    "canonical_colour", "colour_at", "box_context", "CONTEXT_DIM", "GHOG_COARSE_CELL", "GHOG_COARSE_OFFSETS", "COLOUR_CELL", "COLOUR_OFFSETS",
]

CANONICAL_HEIGHT = 64
"""2D box height of the object in canonical pixels."""
RADIUS = 16
PATCH = 2 * RADIUS + 1
SC_RING_EDGES = (0.0, 4.5, 9.5, RADIUS + 0.5)
SC_N_ANGLES = 12
KINDS = ("sc", "hog", "ghog", "ghog_sc", "ghog_ms", "ghog_msc")
GREY_KINDS = ("ghog", "ghog_sc", "ghog_ms", "ghog_msc")
"""Kinds that describe the grey (or colour) image, not only an edge map."""
EDGE_KINDS = ("sc", "hog", "ghog_sc")
"""Kinds that need the Canny edge map."""
GHOG_BINS = 9
GHOG_CELL = 8
GHOG_OFFSETS = (-12, -4, 4, 12)
GHOG_COARSE_CELL = 16
GHOG_COARSE_OFFSETS = (-24, -8, 8, 24)
COLOUR_CELL = 16
COLOUR_OFFSETS = (-16, 0, 16)
GHOG_EPS = 1.0
"""L2 normalisation floor (gradient mass units: grey in [0, 1] per canonical pixel): a
low-contrast patch (sensor noise, road) is not blown up to a strong pattern."""

_KERNELS = None


def sc_kernels() -> np.ndarray:
    """``(n_bins, PATCH, PATCH)`` float indicator kernels of the log-polar bins.

    Bin ``ring * SC_N_ANGLES + sector``; angle measured in image coordinates
    (``atan2(dy, dx)``, y down); the centre pixel belongs to ring 0, sector 0.

    Examples
    --------
    >>> k = sc_kernels()
    >>> k.shape, int(k.sum()), bool((k.sum(0) <= 1).all())  # 3 rings x 12 sectors; each pixel in one bin at most
    ((36, 33, 33), 861, True)
    """
    global _KERNELS
    if _KERNELS is None:
        d = np.arange(PATCH, dtype=float) - RADIUS
        dy, dx = np.meshgrid(d, d, indexing="ij")
        r = np.hypot(dx, dy)
        a = np.mod(np.arctan2(dy, dx), 2 * np.pi)
        sector = np.minimum((a / (2 * np.pi) * SC_N_ANGLES).astype(int), SC_N_ANGLES - 1)
        ring = np.searchsorted(np.asarray(SC_RING_EDGES[1:-1]), r, side="right")
        inside = r <= SC_RING_EDGES[-1]
        n_rings = len(SC_RING_EDGES) - 1
        k = np.zeros((n_rings * SC_N_ANGLES, PATCH, PATCH))
        idx = ring * SC_N_ANGLES + sector
        k[idx[inside], np.nonzero(inside)[0], np.nonzero(inside)[1]] = 1.0
        _KERNELS = k
    return _KERNELS


def context_radius(kind: str) -> int:
    """Half-width (canonical px) of the window a descriptor of ``kind`` reads.

    Examples
    --------
    >>> context_radius("ghog"), context_radius("ghog_ms")  # the multi-scale kinds read the whole car height
    (16, 32)
    """
    if kind in ("ghog_ms", "ghog_msc"):
        return GHOG_COARSE_OFFSETS[-1] + GHOG_COARSE_CELL // 2
    return RADIUS


def feature_dim(kind: str) -> int:
    """Length of a descriptor of ``kind`` (one of :data:`KINDS`; a ``ValueError`` otherwise).

    Examples
    --------
    >>> {kind: feature_dim(kind) for kind in KINDS}
    {'sc': 37, 'hog': 324, 'ghog': 145, 'ghog_sc': 182, 'ghog_ms': 290, 'ghog_msc': 317}
    """
    if kind == "sc":
        return sc_kernels().shape[0] + 1
    if kind == "hog":
        return 324
    if kind == "ghog":
        return len(GHOG_OFFSETS) ** 2 * GHOG_BINS + 1
    if kind == "ghog_sc":
        return feature_dim("ghog") + feature_dim("sc")
    if kind == "ghog_ms":
        return 2 * feature_dim("ghog")
    if kind == "ghog_msc":
        return feature_dim("ghog_ms") + 3 * len(COLOUR_OFFSETS) ** 2
    raise ValueError(f"unknown feature kind {kind!r}, expected one of {KINDS}")


def _resample(a: np.ndarray, z: float, *, name: str, filter_mode: str, resize_mode: str) -> np.ndarray:
    """Bilinear resampling of a 2D float32 map by ``z`` to ``round(shape * z)``, after a
    Gaussian of sigma ``0.5 / z`` when downsampling (so a 1-px line keeps its mass
    whatever its phase w.r.t. the new grid). Returns ``a`` itself when the shape stays."""
    from skimage.transform import resize

    if a.ndim != 2:
        raise ShapeError(f"{name} must be (H, W), got {a.shape}")
    if z <= 0:
        raise ValueError(f"z must be positive, got {z}")
    shape = (max(1, int(round(a.shape[0] * z))), max(1, int(round(a.shape[1] * z))))
    if shape == a.shape:
        return a
    if z < 1:
        a = gaussian_filter(a, 0.5 / z, mode=filter_mode)
    return resize(a, shape, order=1, mode=resize_mode, anti_aliasing=False, preserve_range=True).astype(np.float32)


def canonical_edges(edges, z: float, *, blur: float = 0.0) -> np.ndarray:
    """Resample a native-resolution edge map by ``z`` (canonical px per native px).

    Returns a float32 map of shape ``round(shape * z)`` whose mass is edge length in
    canonical pixels (see module docstring); ``blur`` (canonical px) is an optional
    Gaussian (mass-preserving).

    Examples
    --------
    >>> line = np.zeros((20, 20), bool)
    >>> line[10, :] = True  # 20 px of edge
    >>> e = canonical_edges(line, 0.5)
    >>> e.shape, e.dtype.name, round(float(e.sum()), 1)  # about 10 canonical px of edge (less at the map's ends)
    ((10, 10), 'float32', 9.6)
    """
    e = np.asarray(edges, dtype=np.float32)
    # Edge mass is line length: dividing by z keeps it in canonical pixels.
    out = _resample(e, z, name="edges", filter_mode="constant", resize_mode="constant")
    out = e.copy() if out is e else out / np.float32(z)
    if blur > 0:
        out = gaussian_filter(out, blur).astype(np.float32)
    return out


def image_edges(image, *, sigma: float = 1.0, low: float = 0.05, high: float = 0.12) -> np.ndarray:
    """Canny edges (bool ``(H, W)``) of an RGB ``(H, W, 3)`` or grey ``(H, W)`` image.

    ``low``/``high`` are hysteresis thresholds on the gradient magnitude of the grey
    image scaled to [0, 1].

    Examples
    --------
    >>> grey = np.zeros((32, 32), np.float32)
    >>> grey[:, 16:] = 1.0  # a vertical step edge
    >>> edges = image_edges(grey)
    >>> edges.dtype.name, bool(edges[16, 14:18].any()), bool(edges[16, :12].any())  # on the step, not beside it
    ('bool', True, False)
    """
    from skimage.feature import canny

    img = to_grey(image)
    return canny(img, sigma=sigma, low_threshold=low, high_threshold=high, mode="nearest")


def to_canonical(uv, z: float) -> np.ndarray:
    """Native pixel coordinates ``(..., 2) = (u, v)`` to canonical ``(row, col)`` floats
    for a map made by :func:`canonical_edges` with factor ``z`` (pixel centres align as
    in :func:`skimage.transform.resize`).

    Examples
    --------
    >>> to_canonical([[0.0, 0.0], [10.0, 4.0]], 2.0)  # (u, v) -> (row, col), pixel centres aligned
    array([[ 0.5,  0.5],
           [ 8.5, 20.5]])
    """
    uv = np.asarray(uv, dtype=float)
    c = (uv + 0.5) * z - 0.5
    return c[..., ::-1]


def extract_patches(edge_map, points) -> np.ndarray:
    """``(N, PATCH, PATCH)`` windows of a canonical map centred at integer
    ``points (N, 2) = (row, col)``; zero outside the map.

    Examples
    --------
    >>> edge_map = np.zeros((40, 40), np.float32)
    >>> edge_map[20, :] = 1.0  # a horizontal line through row 20
    >>> patches = extract_patches(edge_map, [[20, 20], [0, 0], [-100, 0]])
    >>> patches.shape, [float(p.sum()) for p in patches]  # the line crosses the first; zero outside the map
    ((3, 33, 33), [33.0, 0.0, 0.0])
    """
    e = np.asarray(edge_map, dtype=np.float32)
    p = np.asarray(points).reshape(-1, 2).astype(int)
    padded = np.pad(e, RADIUS)
    d = np.arange(PATCH)
    rows = p[:, 0, None, None] + d[None, :, None]
    cols = p[:, 1, None, None] + d[None, None, :]
    rows = np.clip(rows, 0, padded.shape[0] - 1)
    cols = np.clip(cols, 0, padded.shape[1] - 1)
    out = padded[rows, cols]
    # points far outside the map: clipping would repeat the border; zero those.
    bad = (p[:, 0] < -RADIUS) | (p[:, 1] < -RADIUS) | (p[:, 0] >= e.shape[0] + RADIUS) | (p[:, 1] >= e.shape[1] + RADIUS)
    out[bad] = 0
    return out


def _sc_from_hist(h: np.ndarray) -> np.ndarray:
    total = h.sum(axis=-1, keepdims=True)
    norm = h / np.maximum(total, 1e-6)
    return np.concatenate([norm, np.log1p(np.maximum(total, 0))], axis=-1).astype(np.float32)


def dense_sc(edge_map) -> np.ndarray:
    """Shape context of every pixel of a canonical map: ``(H, W, 37)`` float32.

    Equals ``extract(extract_patches(edge_map, all pixels), "sc")`` up to FFT rounding.

    Examples
    --------
    >>> edge_map = np.zeros((40, 40), np.float32)
    >>> edge_map[20, :] = 1.0  # a horizontal line through row 20
    >>> d = dense_sc(edge_map)
    >>> d.shape, bool(np.allclose(d[20, 20], extract(edge_map, "sc", points=[[20, 20]])[0], atol=1e-5))
    ((40, 40, 37), True)
    """
    e = np.asarray(edge_map, dtype=np.float64)
    if e.ndim != 2:
        raise ShapeError(f"edge_map must be (H, W), got {e.shape}")
    k = sc_kernels()
    H, W = e.shape
    # correlation == convolution with the flipped kernel; crop the 'same' part.
    sh = (H + PATCH - 1, W + PATCH - 1)
    fe = np.fft.rfft2(e, sh)
    fk = np.fft.rfft2(k[:, ::-1, ::-1], sh)
    full = np.fft.irfft2(fk * fe[None], sh)
    h = full[:, RADIUS:RADIUS + H, RADIUS:RADIUS + W]
    h = np.maximum(np.moveaxis(h, 0, -1), 0.0)
    h[h < 1e-9] = 0.0
    return _sc_from_hist(h)


def _hog(patches: np.ndarray) -> np.ndarray:
    from skimage.feature import hog

    out = np.empty((len(patches), 324), dtype=np.float32)
    for i, p in enumerate(patches):
        out[i] = hog(p[:32, :32], orientations=9, pixels_per_cell=(8, 8), cells_per_block=(2, 2),
                     block_norm="L2-Hys", feature_vector=True)
    return out


def image_grey(image) -> np.ndarray:
    """Grey ``(H, W)`` float32 in [0, 1] (:func:`wirescene.core.image.to_grey`).

    Examples
    --------
    >>> g = image_grey(np.full((2, 2, 3), 255, np.uint8))
    >>> g.dtype.name, float(g.max())
    ('float32', 1.0)
    """
    return to_grey(image)


def canonical_grey(grey, z: float) -> np.ndarray:
    """Resample a native grey image by ``z`` (same grid as :func:`canonical_edges`), with
    a Gaussian pre-filter of sigma ``0.5 / z`` when downsampling.

    Examples
    --------
    >>> canonical_grey(np.ones((20, 30)), 0.5).shape  # round(shape * z)
    (10, 15)
    """
    g = np.asarray(grey, dtype=np.float32)
    out = _resample(g, z, name="grey", filter_mode="nearest", resize_mode="edge")
    return g.copy() if out is g else out


def _orientation_votes(grey_map) -> np.ndarray:
    """``(H, W, GHOG_BINS)`` float32 gradient-magnitude-weighted unsigned orientation
    votes of every pixel (linear split between the two nearest bins)."""
    g = np.asarray(grey_map, dtype=np.float32)
    if g.ndim != 2:
        raise ShapeError(f"grey_map must be (H, W), got {g.shape}")
    gx = np.zeros_like(g)
    gy = np.zeros_like(g)
    gx[:, 1:-1] = (g[:, 2:] - g[:, :-2]) * 0.5
    gy[1:-1, :] = (g[2:, :] - g[:-2, :]) * 0.5
    mag = np.hypot(gx, gy)
    pos = np.mod(np.arctan2(gy, gx), np.pi) * (GHOG_BINS / np.pi) - 0.5
    fl = np.floor(pos)
    w1 = (pos - fl).astype(np.float32)
    b0 = np.mod(fl.astype(np.int64), GHOG_BINS)
    b1 = np.mod(b0 + 1, GHOG_BINS)
    # Each pixel votes into its two bins (b1 is b0's neighbour, never b0 itself): two
    # scatters into zeros instead of a pass over the map per bin.
    out = np.zeros((g.size, GHOG_BINS), np.float32)
    pixel = np.arange(g.size)
    out[pixel, b0.ravel()] = (mag * (1 - w1)).ravel()
    out[pixel, b1.ravel()] = (mag * w1).ravel()
    return out.reshape(g.shape + (GHOG_BINS,))


def _cells_of_votes(votes, cell: int) -> np.ndarray:
    from scipy.ndimage import uniform_filter

    area = float(cell * cell)
    out = np.empty_like(votes)
    for b in range(votes.shape[-1]):
        out[..., b] = uniform_filter(votes[..., b], cell, mode="constant") * area
    return out


def _cells_two_sizes(votes) -> tuple[np.ndarray, np.ndarray]:
    """:data:`GHOG_CELL` and twice-as-large cells of ``votes``: the 16-px window
    ``[i - 8, i + 7]`` is the union of the 8-px windows centred at ``i - 4`` and ``i + 4``
    (per axis), so four shifted sums of the small cells (computed on the map padded by 4
    px of zero votes) replace another set of box filters."""
    h = GHOG_CELL // 2
    H, W = votes.shape[:2]
    cp = _cells_of_votes(np.pad(votes, ((h, h), (h, h), (0, 0))), GHOG_CELL)
    coarse = cp[:H, :W] + cp[:H, 2 * h:] + cp[2 * h:, :W] + cp[2 * h:, 2 * h:]
    return np.ascontiguousarray(cp[h:h + H, h:h + W]), coarse


def orientation_cells(grey_map, *, cell: int = GHOG_CELL) -> np.ndarray:
    """``(H, W, GHOG_BINS)`` float32: gradient-magnitude-weighted unsigned orientation
    votes summed over the ``cell``-pixel square window at every pixel (window
    ``[i - cell/2, i + cell/2 - 1]``; zero gradient outside the map).

    Examples
    --------
    >>> grey = np.zeros((32, 32), np.float32)
    >>> grey[:, 16:] = 1.0  # a vertical step edge
    >>> cells = orientation_cells(grey)
    >>> cells.shape, cells.dtype.name
    ((32, 32, 9), 'float32')
    >>> cells[16, 16].round(2)  # a horizontal gradient: split between bins 0 and 8 (centred on 10 and 170 deg)
    array([4., 0., 0., 0., 0., 0., 0., 0., 4.], dtype=float32)
    """
    return _cells_of_votes(_orientation_votes(grey_map), cell)


def ghog_at(cells, points, *, offsets=GHOG_OFFSETS) -> np.ndarray:
    """``"ghog"`` descriptors ``(N, 145)`` at integer canonical ``points (N, 2) = (row,
    col)`` of a map of :func:`orientation_cells` (cells outside the map are empty);
    ``offsets``: cell centres relative to the point (a 4 x 4 grid by default).

    Examples
    --------
    >>> grey = np.zeros((32, 32), np.float32)
    >>> grey[:, 16:] = 1.0  # a vertical step edge
    >>> d = ghog_at(orientation_cells(grey), [[16, 16], [-100, -100]])
    >>> d.shape, float(d[1].max())  # 4 x 4 cells x 9 bins + log1p(mass); nothing far outside the map
    ((2, 145), 0.0)
    """
    c = np.asarray(cells, dtype=np.float32)
    p = np.asarray(points).reshape(-1, 2).astype(np.int64)
    H, W, B = c.shape
    off = np.asarray(offsets)
    rows = p[:, 0, None, None] + off[None, :, None]
    cols = p[:, 1, None, None] + off[None, None, :]
    ok = (rows >= 0) & (cols >= 0) & (rows < H) & (cols < W)
    # one gather of whole cells (float32: this is the response maps' hot path)
    cell = np.clip(rows, 0, H - 1) * W + np.clip(cols, 0, W - 1)
    v = np.take(c.reshape(-1, B), cell, axis=0)  # (N, 4, 4, B)
    if not ok.all():
        v *= ok[..., None]
    v = v.reshape(len(p), -1)
    out = np.empty((len(p), v.shape[1] + 1), np.float32)
    total = v.sum(1, dtype=np.float64)
    ss = np.einsum("ij,ij->i", v, v, dtype=np.float64)
    n = v * (1.0 / np.sqrt(ss + GHOG_EPS ** 2)).astype(np.float32)[:, None]
    np.minimum(n, np.float32(0.2), out=n)
    ss = np.einsum("ij,ij->i", n, n, dtype=np.float64)
    np.multiply(n, (1.0 / np.sqrt(ss + 1e-6)).astype(np.float32)[:, None], out=out[:, :-1])
    out[:, -1] = np.log1p(total)
    return out


CONTEXT_GRID = (4, 8)
"""Samples (rows, columns) of coarse cells over the box for :func:`box_context`, pooled
2 x 2 into a 2 x 4 grid of blocks."""


def box_context(inputs: dict, box_rc) -> np.ndarray:
    """Gradient-orientation layout of the whole box: ``(72,)`` float32.

    The coarse (16-px) orientation cells of ``inputs`` (:func:`canonical_inputs` of a
    multi-scale kind) sampled at a 4 x 8 grid over the canonical box ``box_rc = (r0, c0,
    r1, c1)``, summed 2 x 2 into 2 x 4 blocks of 9 bins, L2-Hys normalised. The same for
    every point of the box: it tells a part detector which way the car faces (where in
    the box its front wheel should be), which local patches cannot (front and rear
    wheels look alike).

    Examples
    --------
    >>> inputs = canonical_inputs(np.zeros((40, 60, 3), np.uint8), 0.5, "ghog_ms")
    >>> context = box_context(inputs, (0, 0, 20, 30))  # 2 x 4 blocks x 9 bins
    >>> context.shape, context.dtype.name, context.shape[0] == CONTEXT_DIM
    ((72,), 'float32', True)
    """
    c = np.asarray(inputs["coarse"], dtype=np.float32)
    H, W, B = c.shape
    r0, c0, r1, c1 = (float(v) for v in box_rc)
    nr, nc = CONTEXT_GRID
    rows = np.rint(r0 + (np.arange(nr) + 0.5) * (r1 - r0) / nr).astype(np.int64)
    cols = np.rint(c0 + (np.arange(nc) + 0.5) * (c1 - c0) / nc).astype(np.int64)
    ok = ((rows >= 0) & (rows < H))[:, None] & ((cols >= 0) & (cols < W))[None, :]
    v = c[np.clip(rows, 0, H - 1)[:, None], np.clip(cols, 0, W - 1)[None, :]]
    v = np.where(ok[..., None], v, 0).astype(np.float64)
    v = v.reshape(nr // 2, 2, nc // 2, 2, B).sum(axis=(1, 3)).ravel()
    n = v / np.sqrt((v * v).sum() + GHOG_EPS ** 2)
    n = np.minimum(n, 0.2)
    n = n / np.sqrt((n * n).sum() + 1e-6)
    return n.astype(np.float32)


CONTEXT_DIM = 72


def canonical_colour(image, z: float) -> np.ndarray:
    """``(H', W', 3)`` float32 canonical colour channels of a native RGB (or grey) image:
    grey in [0, 1] and the opponent channels ``(R - G) / sqrt 2``, ``(R + G - 2B) / sqrt 6``,
    each resampled by ``z`` like :func:`canonical_grey`.

    Examples
    --------
    >>> canonical_colour(np.array([[[255, 0, 0]]], np.uint8), 1.0).round(3)  # red: grey, R - G, R + G - 2B
    array([[[0.299, 0.707, 0.408]]], dtype=float32)
    """
    img = np.asarray(image)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    rgb = img[..., :3].astype(np.float32)
    if np.issubdtype(img.dtype, np.integer) or (rgb.size and rgb.max() > 1.5):
        rgb = rgb / np.float32(255.0)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    chans = (0.299 * r + 0.587 * g + 0.114 * b, (r - g) / np.sqrt(2.0), (r + g - 2 * b) / np.sqrt(6.0))
    return np.stack([canonical_grey(c.astype(np.float32), z) for c in chans], axis=-1)


def colour_at(cmeans, points) -> np.ndarray:
    """Colour descriptors ``(N, 27)``: the ``COLOUR_CELL``-window means of the canonical
    colour channels (``cmeans``, window-averaged :func:`canonical_colour`) at a 3 x 3
    grid of :data:`COLOUR_OFFSETS` around integer canonical ``points``; 0 outside.

    Examples
    --------
    >>> means = np.ones((40, 40, 3), np.float32)
    >>> d = colour_at(means, [[20, 20], [0, 0]])
    >>> d.shape, d[1].reshape(3, 3, 3)[..., 0]  # (N, 3 x 3 cells x 3 channels); cells off the map are 0
    ((2, 27), array([[0., 0., 0.],
           [0., 1., 1.],
           [0., 1., 1.]], dtype=float32))
    """
    c = np.asarray(cmeans, dtype=np.float32)
    p = np.asarray(points).reshape(-1, 2).astype(np.int64)
    H, W, C = c.shape
    off = np.asarray(COLOUR_OFFSETS)
    rows = p[:, 0, None, None] + off[None, :, None]
    cols = p[:, 1, None, None] + off[None, None, :]
    ok = (rows >= 0) & (cols >= 0) & (rows < H) & (cols < W)
    v = c[np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)]
    return np.where(ok[..., None], v, 0).reshape(len(p), -1).astype(np.float32)


def canonical_inputs(image, z: float, kind: str, *, edges=None) -> dict:
    """What :func:`describe` needs for ``kind`` from a native image (crop) resampled by
    ``z``: ``{"edges": canonical edge map}`` and/or ``{"cells": orientation cells}``
    (plus ``"coarse"`` cells and ``"colour"`` means for the multi-scale kinds).
    ``edges``: precomputed :func:`image_edges` of the same crop.

    Examples
    --------
    >>> inputs = canonical_inputs(np.zeros((40, 60, 3), np.uint8), 0.5, "ghog_ms")
    >>> {k: v.shape for k, v in inputs.items()}  # 8-px and 16-px orientation cells of the 20 x 30 canonical crop
    {'cells': (20, 30, 9), 'coarse': (20, 30, 9)}
    >>> sorted(canonical_inputs(np.zeros((40, 60, 3), np.uint8), 0.5, "ghog_msc"))
    ['cells', 'coarse', 'colour']
    """
    from scipy.ndimage import uniform_filter

    if kind not in KINDS:
        raise ValueError(f"unknown feature kind {kind!r}, expected one of {KINDS}")
    out = {}
    if kind in EDGE_KINDS:
        e = image_edges(image) if edges is None else np.asarray(edges)
        out["edges"] = canonical_edges(e, z)
    if kind in GREY_KINDS:
        votes = _orientation_votes(canonical_grey(image_grey(image), z))
        if kind in ("ghog_ms", "ghog_msc"):
            out["cells"], out["coarse"] = _cells_two_sizes(votes)
        else:
            out["cells"] = _cells_of_votes(votes, GHOG_CELL)
    if kind == "ghog_msc":
        col = canonical_colour(image, z)
        out["colour"] = uniform_filter(col, (COLOUR_CELL, COLOUR_CELL, 1), mode="nearest")
    return out


def describe(inputs: dict, points, kind: str) -> np.ndarray:
    """Descriptors ``(N, feature_dim(kind))`` at integer canonical ``points (N, 2)`` of
    :func:`canonical_inputs` (any points: outside the map the input is empty).

    Examples
    --------
    >>> inputs = canonical_inputs(np.zeros((40, 60, 3), np.uint8), 0.5, "ghog_ms")
    >>> describe(inputs, [[10, 15], [0, 0]], "ghog_ms").shape == (2, feature_dim("ghog_ms"))
    True
    """
    p = np.asarray(points).reshape(-1, 2).astype(np.int64)
    if kind == "ghog":
        return ghog_at(inputs["cells"], p)
    if kind == "ghog_ms":
        return np.concatenate([ghog_at(inputs["cells"], p),
                               ghog_at(inputs["coarse"], p, offsets=GHOG_COARSE_OFFSETS)], axis=1)
    if kind == "ghog_msc":
        return np.concatenate([describe(inputs, p, "ghog_ms"), colour_at(inputs["colour"], p)], axis=1)
    if kind == "ghog_sc":
        return np.concatenate([describe(inputs, p, "ghog"), describe(inputs, p, "sc")], axis=1)
    e = inputs["edges"]
    if kind == "sc" and len(p) > 0.05 * e.size:
        d = dense_sc(e)
        inside = (p[:, 0] >= 0) & (p[:, 1] >= 0) & (p[:, 0] < e.shape[0]) & (p[:, 1] < e.shape[1])
        X = np.empty((len(p), d.shape[-1]), dtype=np.float32)
        X[inside] = d[p[inside, 0], p[inside, 1]]
        if (~inside).any():
            X[~inside] = extract(e, "sc", points=p[~inside])
        return X
    return extract(e, kind, points=p)


def extract(x, kind: str = "sc", *, points=None) -> np.ndarray:
    """Descriptors of patches or of a canonical edge map.

    Parameters
    ----------
    x : (N, PATCH, PATCH) patches, or (H, W) canonical edge map
    kind : "sc" or "hog"
    points : (N, 2) int (row, col), optional
        With a map: describe only these pixels (``(N, D)``). Without: every pixel
        (``(H, W, D)``; ``"sc"`` only, via FFT).

    Returns
    -------
    (N, D) or (H, W, D) float32

    Examples
    --------
    >>> edge_map = np.zeros((40, 40), np.float32)
    >>> edge_map[20, :] = 1.0  # a horizontal line through row 20
    >>> d = extract(extract_patches(edge_map, [[20, 20], [0, 0]]), "sc")
    >>> d.shape, round(float(d[0, :36].sum()), 4), d[:, -1].round(3)  # L1-normalised bins, log1p(edge mass)
    ((2, 37), 1.0, array([3.526, 0.   ], dtype=float32))
    >>> extract(edge_map, "sc", points=[[20, 20]]).shape  # a map and points: the same descriptors
    (1, 37)
    """
    if kind not in KINDS:
        raise ValueError(f"unknown feature kind {kind!r}, expected one of {KINDS}")
    if kind in GREY_KINDS:
        raise ValueError(f"kind {kind!r} describes grey images: use canonical_inputs() and describe()")
    x = np.asarray(x)
    if x.ndim == 3:
        if x.shape[1:] != (PATCH, PATCH):
            raise ShapeError(f"patches must be (N, {PATCH}, {PATCH}), got {x.shape}")
        if kind == "sc":
            h = np.einsum("nij,bij->nb", x.astype(np.float64), sc_kernels())
            return _sc_from_hist(h)
        return _hog(x.astype(np.float32))
    if x.ndim != 2:
        raise ShapeError(f"expected patches (N, P, P) or a map (H, W), got {x.shape}")
    if points is not None:
        return extract(extract_patches(x, points), kind)
    if kind != "sc":
        raise ValueError("dense maps are implemented for kind='sc' only; pass points= for HOG")
    return dense_sc(x)
