"""Colour and gradient-magnitude channels around a detection: what HOG cells do not see.

HOG cells hold gradient orientations of the grey image, normalised per block, so two
windows of the same edges but different colours (a dark car on grey asphalt, green hedge
above a kerb) look alike to the verifier. These features, as the channels of aggregated
channel features (Dollar et al. 2014), add per cell of the verifier's window (the box grown
by :data:`wirescene.predetect.refine.CONTEXT`, on the :data:`wirescene.predetect.refine.GRID`
of the HOG cells) the mean CIE L*u*v* colour and gradient magnitude, each channel
standardised over the window (where in the window it is light, red or busy, whatever the
window's overall level), then the window's own mean and log spread of each channel.

Cell means are read from one integral image per image (:func:`integral_channels`), so a
frame's few hundred candidate boxes cost a few array lookups each.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.core.image import to_rgb_uint8
from wirescene.predetect.refine import GRID, window_boxes

N_CHANNELS = 4
"""L*, u*, v* and the gradient magnitude of L*."""
N_CHANNEL_FEATURES = GRID[0] * GRID[1] * N_CHANNELS + 2 * N_CHANNELS
"""Columns of :func:`window_channel_features`: the standardised cells, then each channel's mean and log spread."""
_SPREAD_FLOOR = 1e-3  # of a channel over a window: a flat window's cells stay finite


#: Pixels of the image :func:`integral_channels` converts at once: a larger image is read in strips of rows (the
#: colour conversion's float64 temporaries cost some 80 bytes a pixel, 130 before they were written into one buffer:
#: 4 GB on an 8K frame at once). 2^17 (a KITTI frame in four strips) keeps them in the CPU's cache, without a fresh
#: buffer's page faults; the numbers are those of one strip.
STRIP_PIXELS = 1 << 17

@lru_cache(maxsize=1)
def _luv_constants() -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """``(linear levels (256,), rgb to xyz (3, 3), white (3,), u0, v0)`` of :func:`_luv`: each
    8-bit level's linear light (sRGB's gamma undone), sRGB's primaries in CIE XYZ (transposed,
    as ``rgb2xyz`` multiplies by them) and the D65 white point's terms, computed with
    scikit-image's operations and matrices (``rgb2xyz``, ``xyz2luv``)."""
    from skimage.color import xyz_tristimulus_values
    from skimage.color.colorconv import xyz_from_rgb
    from skimage.util import img_as_float64

    levels = img_as_float64(np.arange(256, dtype=np.uint8))
    curved = levels > 0.04045
    levels[curved] = np.power((levels[curved] + 0.055) / 1.055, 2.4)
    levels[~curved] /= 12.92
    white = xyz_tristimulus_values(illuminant="D65", observer="2", dtype=np.float64)
    uv_weights = np.array([1, 15, 3], dtype=np.float64)
    rgb_to_xyz = xyz_from_rgb.T.astype(np.float64)
    return levels, rgb_to_xyz, white, 4 * white[0] / (uv_weights @ white), 9 * white[1] / (uv_weights @ white)


def _luv(rgb: np.ndarray, out: np.ndarray) -> None:
    """``skimage.color.rgb2luv(rgb)`` of uint8 ``rgb`` ``(..., 3)`` written into the float64
    ``out`` ``(..., 3)``: the same operations, to the bit (``tests/test_channels.py``), with each
    level's linear light read from a table of the 256 levels (a power of every pixel's three
    values was most of ``rgb2xyz``'s time) and no stacked copies."""
    levels, rgb_to_xyz, white, u0, v0 = _luv_constants()
    xyz = levels[rgb] @ rgb_to_xyz
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    L = np.divide(y, white[1], out=out[..., 0])
    bright = L > 0.008856
    L[bright] = 116.0 * np.cbrt(L[bright]) - 16.0
    L[~bright] = 903.3 * L[~bright]
    den = x + 15.0 * y + 3.0 * z + np.finfo(np.float64).eps
    L13 = 13.0 * L
    np.multiply(L13, (4.0 * x) / den - u0, out=out[..., 1])
    np.multiply(L13, (9.0 * y) / den - v0, out=out[..., 2])


def integral_channels(image, *, strip_pixels: int = STRIP_PIXELS) -> np.ndarray:
    """``(H + 1, W + 1, 4)`` float64 integral image of the L*u*v* and gradient-magnitude
    channels of an RGB (or grey: no colour then) image ``(H, W[, 3])`` of any dtype
    :func:`wirescene.core.image.to_rgb_uint8` reads. An image of more than ``strip_pixels``
    pixels is converted in strips of rows (one row of context each side for the vertical
    gradient, the column sums carried from strip to strip): the same numbers, the
    temporaries bounded. The colours are ``skimage.color.rgb2luv``'s to the bit (:func:`_luv`),
    and each strip's channels are summed in place, in the order of a ``cumsum`` down the
    columns, then along the rows.

    Examples
    --------
    >>> img = np.zeros((4, 5, 3), np.uint8)
    >>> integral_channels(img).shape
    (5, 6, 4)
    >>> img = np.random.default_rng(0).integers(0, 255, (30, 20, 3), dtype=np.uint8)
    >>> integral_channels(img).tobytes() == integral_channels(img, strip_pixels=1).tobytes()  # strips of one row
    True
    """
    rgb = to_rgb_uint8(image)
    H, W = rgb.shape[:2]
    out = np.zeros((H + 1, W + 1, N_CHANNELS))
    rows = max(1, int(strip_pixels) // max(W, 1))
    carry = None  # the column sums down to the strip's first row
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        a0, a1 = max(0, r0 - 1), min(H, r1 + 1)  # a row of context each side: the gradient's central differences
        ch = np.empty((a1 - a0, W, N_CHANNELS))
        _luv(rgb[a0:a1], ch[..., :3])
        gy, gx = np.gradient(ch[..., 0])
        np.hypot(gx, gy, out=ch[..., 3])
        ch = ch[r0 - a0:r1 - a0]
        if carry is not None:  # (not on the first strip: a zero added would turn its -0.0 sums into 0.0)
            ch[0] += carry
        np.cumsum(ch, axis=0, out=ch)
        carry = ch[-1].copy()
        np.cumsum(ch, axis=1, out=out[r0 + 1:r1 + 1, 1:])
    return out


def window_channel_features(integral: np.ndarray, boxes) -> np.ndarray:
    """``(D, N_CHANNEL_FEATURES)`` float32 channel features of ``boxes`` ``(D, 4)``
    (x1, y1, x2, y2 pixels) from :func:`integral_channels` of their image. Cells past the
    image's edges are clipped to it (at least one pixel).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> ii = integral_channels(rng.integers(0, 255, (60, 80, 3), dtype=np.uint8))
    >>> f = window_channel_features(ii, np.array([[10.0, 10.0, 50.0, 40.0], [-20.0, 0.0, 30.0, 70.0]]))
    >>> f.shape, bool(np.isfinite(f).all())
    ((2, 392), True)
    """
    integral = np.asarray(integral, float)
    if integral.ndim != 3 or integral.shape[-1] != N_CHANNELS:
        raise ValueError(f"integral must be (H + 1, W + 1, {N_CHANNELS}), got {integral.shape}")
    b = np.asarray(boxes, float)
    b = b.reshape(0, 4) if b.size == 0 else b
    check_shape("boxes", b, (None, 4))
    H, W = integral.shape[0] - 1, integral.shape[1] - 1
    th, tw = GRID
    w = window_boxes(b)
    ys = w[:, 1, None] + np.linspace(0.0, 1.0, th + 1)[None] * (w[:, 3] - w[:, 1])[:, None]  # (D, th + 1)
    xs = w[:, 0, None] + np.linspace(0.0, 1.0, tw + 1)[None] * (w[:, 2] - w[:, 0])[:, None]
    y0 = np.clip(np.floor(ys[:, :-1]), 0, H - 1).astype(int)
    y1 = np.clip(np.ceil(ys[:, 1:]), y0 + 1, H).astype(int)
    x0 = np.clip(np.floor(xs[:, :-1]), 0, W - 1).astype(int)
    x1 = np.clip(np.ceil(xs[:, 1:]), x0 + 1, W).astype(int)
    y0, y1, x0, x1 = y0[:, :, None], y1[:, :, None], x0[:, None, :], x1[:, None, :]
    sums = integral[y1, x1] - integral[y0, x1] - integral[y1, x0] + integral[y0, x0]  # (D, th, tw, C)
    cells = sums / ((y1 - y0) * (x1 - x0))[..., None]
    mean = cells.mean((1, 2), keepdims=True)
    spread = cells.std((1, 2), keepdims=True) + _SPREAD_FLOOR
    D = len(b)
    return np.concatenate([((cells - mean) / spread).reshape(D, th * tw * N_CHANNELS), mean.reshape(D, N_CHANNELS),
                           np.log(spread).reshape(D, N_CHANNELS)], axis=1).astype(np.float32)
