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
    """(H, W) float32 luminance in [0, 1] (:func:`wirescene.core.image.to_grey`)."""
    return to_grey(image)


def hog_cells(gray: np.ndarray, cell: int = CELL) -> np.ndarray:
    """(H // cell, W // cell, 31) float32 FHOG features of a grey image."""
    g = np.asarray(gray, dtype=np.float32)
    hc, wc = g.shape[0] // cell, g.shape[1] // cell
    if hc < 1 or wc < 1:
        return np.zeros((max(hc, 0), max(wc, 0), N_FEAT), np.float32)
    g = g[: hc * cell, : wc * cell]
    p = np.pad(g, 1, mode="edge")
    gx = p[1:-1, 2:] - p[1:-1, :-2]
    gy = p[2:, 1:-1] - p[:-2, 1:-1]
    mag = np.sqrt(gx * gx + gy * gy)
    ang = np.arctan2(gy, gx)  # [-pi, pi]
    pos = (ang + np.pi) * (_N_ORIENT / (2 * np.pi))
    b0 = np.floor(pos).astype(np.int64)
    f = (pos - b0).astype(np.float32)
    b0 %= _N_ORIENT
    b1 = (b0 + 1) % _N_ORIENT
    rows = np.arange(hc * cell) // cell
    cols = np.arange(wc * cell) // cell
    cidx = (rows[:, None] * wc + cols[None, :]) * _N_ORIENT
    n = hc * wc * _N_ORIENT
    h18 = np.bincount((cidx + b0).ravel(), weights=(mag * (1 - f)).ravel(), minlength=n)
    h18 += np.bincount((cidx + b1).ravel(), weights=(mag * f).ravel(), minlength=n)
    h18 = h18.reshape(hc, wc, _N_ORIENT).astype(np.float32)
    h9 = h18[..., :9] + h18[..., 9:]
    energy = np.pad((h9 * h9).sum(-1), 1, mode="edge")
    # block energies: block (i, j) covers cells (i..i+1, j..j+1) of the padded grid
    blk = energy[:-1, :-1] + energy[1:, :-1] + energy[:-1, 1:] + energy[1:, 1:]  # (hc+1, wc+1)
    eps = 1e-4
    norms = [1.0 / np.sqrt(blk[dy:dy + hc, dx:dx + wc] + eps) for dy in (0, 1) for dx in (0, 1)]
    out = np.empty((hc, wc, N_FEAT), np.float32)
    s18 = np.zeros((hc, wc, 18), np.float32)
    s9 = np.zeros((hc, wc, 9), np.float32)
    for k, nk in enumerate(norms):
        a = np.minimum(h18 * nk[..., None], 0.2)
        s18 += a
        s9 += np.minimum(h9 * nk[..., None], 0.2)
        out[..., 27 + k] = 0.2357 * a.sum(-1)
    out[..., :18] = 0.5 * s18
    out[..., 18:27] = 0.5 * s9
    return out


def resize(gray: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear (antialiased when shrinking) resize of a float grey image."""
    return np.asarray(Image.fromarray(np.asarray(gray, np.float32), mode="F").resize(
        (int(width), int(height)), Image.BILINEAR), dtype=np.float32)


def pyramid_scales(width: int, height: int, *, max_scale: float = 2.0, min_scale: float = 0.1,
                   per_octave: int = 4, min_cells: int = 4) -> list[float]:
    """Image scales ``max_scale * 2**(-k / per_octave)`` down to ``min_scale`` (or too small)."""
    scales, k = [], 0
    while True:
        s = max_scale * 2.0 ** (-k / per_octave)
        if s < min_scale or min(width, height) * s < min_cells * CELL:
            break
        scales.append(s)
        k += 1
    return scales


def level_size(W: int, H: int, scale: float) -> tuple[int, int]:
    """``(w, h)`` in pixels of a ``W x H`` image at pyramid ``scale``."""
    return max(int(round(W * scale)), 1), max(int(round(H * scale)), 1)


def level_image(gray: np.ndarray, scale: float) -> np.ndarray:
    """The grey image resized to pyramid ``scale`` (itself at scale 1)."""
    H, W = gray.shape
    w, h = level_size(W, H, scale)
    return gray if (w == W and h == H) else resize(gray, w, h)


def feature_pyramid(image: np.ndarray, scales) -> list[tuple[float, np.ndarray]]:
    """``[(scale, (Hc, Wc, 31) features)]`` of the image resized by each scale."""
    gray = to_gray(image)
    return [(float(s), hog_cells(level_image(gray, s))) for s in scales]


def crop_features(gray: np.ndarray, box, th: int, tw: int) -> np.ndarray:
    """(th, tw, 31) features of ``box`` (x1 y1 x2 y2) warped to a ``th x tw``-cell template.

    The crop includes one cell of context on every side (edge-replicated outside the
    image) so that gradients and block normalisation at the template border match those
    of the sliding-window features."""
    x1, y1, x2, y2 = [float(v) for v in box]
    cw, ch = (x2 - x1) / tw, (y2 - y1) / th
    X1, Y1, X2, Y2 = x1 - cw, y1 - ch, x2 + cw, y2 + ch
    H, W = gray.shape
    ix1, iy1 = int(np.floor(X1)), int(np.floor(Y1))
    # only the crop's own pixels, edge-replicated where it leaves the image (padding the
    # whole image per crop cost more than the crop's features)
    rows = np.clip(np.arange(iy1, int(np.ceil(Y2))), 0, H - 1)
    cols = np.clip(np.arange(ix1, int(np.ceil(X2))), 0, W - 1)
    patch = np.asarray(gray)[np.ix_(rows, cols)]
    # map the exact (sub-pixel) crop to the template grid
    im = Image.fromarray(np.ascontiguousarray(patch, np.float32), mode="F")
    ox, oy = X1 - ix1, Y1 - iy1
    im = im.resize(((tw + 2) * CELL, (th + 2) * CELL), Image.BILINEAR,
                   box=(ox, oy, ox + (X2 - X1), oy + (Y2 - Y1)))
    f = hog_cells(np.asarray(im, np.float32))
    return f[1:-1, 1:-1]
