"""Vectorised Felzenszwalb-style HOG ("FHOG", 31 dims per cell) and a feature pyramid.

Per 8x8-pixel cell: 18 contrast-sensitive orientation bins, 9 contrast-insensitive ones
and 4 texture (gradient energy) features, each histogram normalised by the 4 surrounding
2x2-cell blocks and clipped at 0.2, as in Felzenszwalb et al. (PAMI 2010). Hard spatial
binning, linear interpolation between orientation bins; two ``np.bincount`` passes per
image, no Python loops over pixels.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

from wirescene.core.image import to_grey

CELL = 8
N_FEAT = 31
_N_ORIENT = 18


def to_gray(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 luminance in [0, 1] (:func:`wirescene.core.image.to_grey`).

    Examples
    --------
    >>> g = to_gray(np.full((2, 3, 3), 255, np.uint8))
    >>> g.shape, g.dtype.name, float(g.max())
    ((2, 3), 'float32', 1.0)
    """
    return to_grey(image)


def _edge_pad(x: np.ndarray) -> np.ndarray:
    """``x`` ``(..., h, w)`` with one edge-replicated row / column on every side of its last
    two axes (``np.pad``'s ``mode="edge"``, without its per-call cost, which dominated small
    crops)."""
    h, w = x.shape[-2:]
    out = np.empty(x.shape[:-2] + (h + 2, w + 2), x.dtype)
    out[..., 1:-1, 1:-1] = x
    out[..., 0, 1:-1], out[..., -1, 1:-1] = x[..., 0, :], x[..., -1, :]
    out[..., :, 0], out[..., :, -1] = out[..., :, 1], out[..., :, -2]
    return out


# atan(t) * 9 / pi = t * P(t^2) on [0, 1], 20-degree bins: a weighted least-squares (near-minimax) fit,
# off by at most 1.1e-7 bins (float64); tests/test_predetect.py checks the whole circle against arctan2
_ATAN_BINS = np.array([2.86478707, -0.95483018, 0.57142702, -0.39845288, 0.27622858, -0.16017695, 0.0626327,
                       -0.01161546], np.float32)


def orientation_bins(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Float32 ``(arctan2(gy, gx) + pi) * 18 / (2 pi)``, the gradient's direction in 20-degree bins
    in ``[0, 18]``, for float32 arrays of one shape.

    Within 4e-6 bins of float32 ``np.arctan2`` (within 1.5e-6 of the exact value, which float32
    ``arctan2`` misses by up to 2.6e-6) at 2.4x its speed: numpy's ``arctan2`` has no vectorised
    loop without AVX-512 and was half of :func:`hog_cells`. Octant reduction, an odd polynomial, and
    the quadrant restored by ``copysign`` (``np.where`` costs 20 multiplications); signed zeros
    give ``arctan2``'s angles.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.predetect.hog import orientation_bins
    >>> gx = np.array([1, 0, -1, 0, 1], np.float32)
    >>> gy = np.array([0, 1, 0, -1, 1], np.float32)
    >>> np.round(orientation_bins(gx, gy), 5).tolist()  # 0, 90, 180, -90 and 45 degrees
    [9.0, 13.5, 18.0, 4.5, 11.25]
    """
    ax, ay = np.abs(gx), np.abs(gy)
    t = np.minimum(ax, ay)
    m = np.maximum(ax, ay)
    t /= np.maximum(m, np.float32(1e-30), out=m)
    t2 = np.multiply(t, t, out=m)  # (m's buffer, no longer read)
    p = np.multiply(t2, _ATAN_BINS[-1])  # the first Horner step: (c * 1) * t^2, without an array of c
    p += _ATAN_BINS[-2]
    for c in _ATAN_BINS[-3::-1]:  # Horner in t^2
        p *= t2
        p += c
    p *= t  # atan(min / max) in bins: [0, 2.25]
    ax -= ay
    for half, sign in ((np.float32(2.25), ax), (np.float32(4.5), gx)):  # unfold the octant, then the quadrant
        np.subtract(half, p, out=p)
        np.copysign(p, sign, out=p)
        np.subtract(half, p, out=p)
    np.copysign(p, gy, out=p)
    p += np.float32(9)
    return p


# each pixel's two bins from the floor of its direction in [0, 18]: the floor and the next, 18 wrapped to 0
_BIN0 = np.array([*range(_N_ORIENT), 0], np.intp)
_BIN1 = np.array([*range(1, _N_ORIENT), 0, 1], np.intp)


def _cell_offsets(lead: tuple, hc: int, wc: int, cell: int) -> np.ndarray:
    """(..., hc * cell, wc * cell) index of each pixel's histogram in :func:`_cell_histograms`:
    ``((image * hc + cell row) * wc + cell column) * 18``."""
    offset = (np.arange(hc * cell) // cell * (wc * _N_ORIENT))[:, None] + np.arange(wc * cell) // cell * _N_ORIENT
    if lead:
        offset = offset + (np.arange(int(np.prod(lead))) * (hc * wc * _N_ORIENT)).reshape(lead + (1, 1))
    return offset


def _cell_histograms(p: np.ndarray, hc: int, wc: int, cell: int, offset: np.ndarray | None = None) -> np.ndarray:
    """(..., hc, wc, 18) float64 orientation histograms of the cells of edge-padded grey
    images ``p`` ``(..., hc * cell + 2, wc * cell + 2)``: each pixel's gradient magnitude shared
    linearly between its two nearest of 18 orientation bins, summed over its cell. ``offset``:
    :func:`_cell_offsets` of these images and cells, if already computed."""
    lead = p.shape[:-2]
    gx = p[..., 1:-1, 2:] - p[..., 1:-1, :-2]
    gy = p[..., 2:, 1:-1] - p[..., :-2, 1:-1]
    mag = np.multiply(gx, gx)
    mag += np.multiply(gy, gy)
    np.sqrt(mag, out=mag)
    f = orientation_bins(gx, gy)  # [0, 18]
    lower = np.floor(f)
    b = lower.astype(np.intp)
    f -= lower  # exact in float32: a fractional part
    offset = _cell_offsets(lead, hc, wc, cell) if offset is None else offset
    # histogram index of each pixel's bins: ((image * hc + cell row) * wc + cell column) * 18 + bin
    b0 = _BIN0.take(b)  # (tables: a modulo costs more than the whole histogram)
    b0 += offset
    b1 = _BIN1.take(b)
    b1 += offset
    n = hc * wc * _N_ORIENT * int(np.prod(lead))
    np.subtract(1, f, out=lower)
    lower *= mag  # mag * (1 - f)
    h = np.bincount(b0.ravel(), weights=lower.ravel(), minlength=n)
    f *= mag
    h += np.bincount(b1.ravel(), weights=f.ravel(), minlength=n)
    return h.reshape(lead + (hc, wc, _N_ORIENT))


def hog_cells(gray: np.ndarray, cell: int = CELL, *, strip_pixels: int = 1 << 16) -> np.ndarray:
    """(..., H // cell, W // cell, 31) float32 FHOG features of grey images ``(..., H, W)``
    (a stack of equal crops in one call: the same numbers as one call each, for far fewer
    numpy calls). The pixels are read in strips of whole cell rows, some ``strip_pixels`` at
    a time: the same sums in the same order, with the temporaries in the CPU's cache (1.4-1.8x
    faster on a 750 x 2484 pyramid level; ``benchmarks/bench_hog.py``).

    Examples
    --------
    >>> step = np.zeros((32, 48), np.float32)
    >>> step[:, 24:] = 1.0  # dark left, bright right: a vertical edge between cell columns 2 and 3
    >>> F = hog_cells(step)
    >>> F.shape, F.dtype.name  # 4 x 6 cells of 8 px, 31 features each
    ((4, 6, 31), 'float32')
    >>> int(F[1, 2, :18].argmax()), int(F[1, 2, 18:27].argmax())  # gradient along +x: bin 9 of 18, bin 0 of 9
    (9, 0)
    >>> float(hog_cells(np.zeros((32, 48))).max())  # no gradient, no feature
    0.0
    >>> hog_cells(np.zeros((5, 32, 48))).shape  # a stack of equal crops at once
    (5, 4, 6, 31)
    """
    g = np.asarray(gray, dtype=np.float32)
    lead = g.shape[:-2]
    hc, wc = g.shape[-2] // cell, g.shape[-1] // cell
    if hc < 1 or wc < 1:
        return np.zeros(lead + (max(hc, 0), max(wc, 0), N_FEAT), np.float32)
    p = _edge_pad(g[..., : hc * cell, : wc * cell])
    rows = max(1, strip_pixels // (int(np.prod(lead)) * wc * cell * cell))  # cell rows a strip
    # the 18 contrast-sensitive bins, then the 9 insensitive ones, side by side: each block's normalisation in one pass
    h27 = np.empty(lead + (hc, wc, 27), np.float32)
    offsets = {}  # {cell rows: their pixels' histogram indices}: the strips of one height share them
    for r in range(0, hc, rows):
        k = min(rows, hc - r)
        if k not in offsets:
            offsets[k] = _cell_offsets(lead, k, wc, cell)
        h27[..., r:r + k, :, :_N_ORIENT] = _cell_histograms(p[..., r * cell:(r + k) * cell + 2, :], k, wc, cell,
                                                              offsets[k])
    h9 = np.add(h27[..., :9], h27[..., 9:_N_ORIENT], out=h27[..., _N_ORIENT:])
    energy = _edge_pad((h9 * h9).sum(-1))
    # block energies: block (i, j) covers cells (i..i+1, j..j+1) of the padded grid
    blk = energy[..., :-1, :-1] + energy[..., 1:, :-1] + energy[..., :-1, 1:] + energy[..., 1:, 1:]  # (hc+1, wc+1)
    inv = 1.0 / np.sqrt(blk + 1e-4)
    out = np.empty(lead + (hc, wc, N_FEAT), np.float32)
    # one block's normalisation at a time, added to the first in the order of the four blocks (no stack of four)
    s27 = None
    for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        a = np.multiply(h27, inv[..., dy:dy + hc, dx:dx + wc, None])
        np.minimum(a, 0.2, out=a)
        np.multiply(a[..., :_N_ORIENT].sum(-1), 0.2357, out=out[..., 27 + k])
        if s27 is None:
            s27 = a
        else:
            s27 += a
    np.multiply(s27, 0.5, out=out[..., :27])
    return out


def resize(gray: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear (antialiased when shrinking) resize of a float grey image.

    Examples
    --------
    >>> resize(np.ones((4, 6)), 3, 2).shape  # width, height in; (height, width) out
    (2, 3)
    """
    return np.asarray(Image.fromarray(np.asarray(gray, np.float32), mode="F").resize(
        (int(width), int(height)), Image.BILINEAR), dtype=np.float32)


def pyramid_scales(width: int, height: int, *, max_scale: float = 2.0, min_scale: float = 0.1,
                   per_octave: int = 4, min_cells: int = 4) -> list[float]:
    """Image scales ``max_scale * 2**(-k / per_octave)`` down to ``min_scale`` (or too small).

    Examples
    --------
    >>> np.round(pyramid_scales(64, 64, max_scale=1.0, min_scale=0.5), 3)  # 4 levels an octave
    array([1.   , 0.841, 0.707, 0.595, 0.5  ])
    >>> len(pyramid_scales(1242, 375))  # a KITTI frame from 2x down to 0.1x, 4 levels an octave
    18
    """
    scales, k = [], 0
    while True:
        s = max_scale * 2.0 ** (-k / per_octave)
        if s < min_scale or min(width, height) * s < min_cells * CELL:
            break
        scales.append(s)
        k += 1
    return scales


def level_size(W: int, H: int, scale: float) -> tuple[int, int]:
    """``(w, h)`` in pixels of a ``W x H`` image at pyramid ``scale``.

    Examples
    --------
    >>> level_size(1242, 375, 0.5)  # (w, h), rounded
    (621, 188)
    """
    return max(int(round(W * scale)), 1), max(int(round(H * scale)), 1)


def level_image(gray: np.ndarray, scale: float) -> np.ndarray:
    """The grey image resized to pyramid ``scale`` (itself at scale 1).

    Examples
    --------
    >>> level_image(np.zeros((375, 1242), np.float32), 0.5).shape
    (188, 621)
    """
    H, W = gray.shape
    w, h = level_size(W, H, scale)
    return gray if (w == W and h == H) else resize(gray, w, h)


def feature_pyramid(image: np.ndarray, scales) -> list[tuple[float, np.ndarray]]:
    """``[(scale, (Hc, Wc, 31) features)]`` of the image resized by each scale.

    Examples
    --------
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> [(s, F.shape) for s, F in feature_pyramid(image, [1.0, 0.5])]
    [(1.0, (8, 12, 31)), (0.5, (4, 6, 31))]
    """
    gray = to_gray(image)
    return [(float(s), hog_cells(level_image(gray, s))) for s in scales]


def _warped_crop(gray: np.ndarray, box, th: int, tw: int) -> np.ndarray:
    """``((th + 2) * CELL, (tw + 2) * CELL)`` float32 pixels of ``box`` with one cell of context."""
    x1, y1, x2, y2 = [float(v) for v in box]
    cw, ch = (x2 - x1) / tw, (y2 - y1) / th
    X1, Y1, X2, Y2 = x1 - cw, y1 - ch, x2 + cw, y2 + ch
    H, W = gray.shape
    ix1, iy1, ix2, iy2 = int(np.floor(X1)), int(np.floor(Y1)), int(np.ceil(X2)), int(np.ceil(Y2))
    # only the crop's own pixels, edge-replicated where it leaves the image (padding the
    # whole image per crop cost more than the crop's features)
    if 0 <= ix1 and 0 <= iy1 and ix2 <= W and iy2 <= H:
        patch = np.ascontiguousarray(gray[iy1:iy2, ix1:ix2], np.float32)
    else:
        rows = np.clip(np.arange(iy1, iy2), 0, H - 1)
        cols = np.clip(np.arange(ix1, ix2), 0, W - 1)
        patch = np.ascontiguousarray(np.asarray(gray).take(rows, 0).take(cols, 1), np.float32)  # (two takes: half np.ix_'s time)
    # map the exact (sub-pixel) crop to the template grid; PIL images made from and read into
    # the arrays' buffers directly (fromarray / asarray cost half as much again as the resize)
    im = Image.frombuffer("F", (patch.shape[1], patch.shape[0]), patch, "raw", "F", 0, 1)
    ox, oy = X1 - ix1, Y1 - iy1
    out_w, out_h = (tw + 2) * CELL, (th + 2) * CELL
    im = im.resize((out_w, out_h), Image.BILINEAR, box=(ox, oy, ox + (X2 - X1), oy + (Y2 - Y1)))
    return np.frombuffer(im.tobytes(), np.float32).reshape(out_h, out_w)


def crop_features(gray: np.ndarray, box, th: int, tw: int) -> np.ndarray:
    """(th, tw, 31) features of ``box`` (x1 y1 x2 y2) warped to a ``th x tw``-cell template.

    The crop includes one cell of context on every side (edge-replicated outside the
    image) so that gradients and block normalisation at the template border match those
    of the sliding-window features.

    Examples
    --------
    >>> gray = to_gray(np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8))
    >>> crop_features(gray, [10, 10, 70, 40], 4, 8).shape  # a 60 x 30 px box on a 4 x 8-cell template
    (4, 8, 31)
    """
    return hog_cells(_warped_crop(gray, box, th, tw))[1:-1, 1:-1]


def crops_features(gray: np.ndarray, boxes, th: int, tw: int, *, chunk: int = 16) -> np.ndarray:
    """(D, th, tw, 31) :func:`crop_features` of ``boxes`` ``(D, 4)``, the same numbers, the
    features of ``chunk`` crops at a time (some 60 kB per crop and array: 16 keep the
    temporaries in the CPU's cache, 1.9x faster than 256; ``benchmarks/bench_hog.py``).

    Examples
    --------
    >>> gray = to_gray(np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8))
    >>> boxes = [[10, 10, 70, 40], [-5, 0, 30, 30]]  # the second reaches past the image's left side
    >>> F = crops_features(gray, boxes, 4, 8)
    >>> F.shape, bool(np.array_equal(F[0], crop_features(gray, boxes[0], 4, 8)))
    ((2, 4, 8, 31), True)
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    out = np.zeros((len(b), th, tw, N_FEAT), np.float32)
    for start in range(0, len(b), chunk):
        stack = np.stack([_warped_crop(gray, box, th, tw) for box in b[start:start + chunk]])
        out[start:start + len(stack)] = hog_cells(stack)[:, 1:-1, 1:-1]
    return out
