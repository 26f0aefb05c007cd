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
#: colour conversion's float64 temporaries cost some 130 bytes a pixel, 4 GB on an 8K frame); a KITTI frame (466,000)
#: is one strip, as before.
STRIP_PIXELS = 1 << 20


def integral_channels(image, *, strip_pixels: int = STRIP_PIXELS) -> np.ndarray:
    """``(H + 1, W + 1, 4)`` float64 integral image of the L*u*v* and gradient-magnitude
    channels of an RGB (or grey: no colour then) image ``(H, W[, 3])`` of any dtype
    :func:`wirescene.core.image.to_rgb_uint8` reads. An image of more than ``strip_pixels``
    pixels is converted in strips of rows (one row of context each side for the vertical
    gradient, the column sums carried from strip to strip): the same numbers, the
    temporaries bounded.

    Examples
    --------
    >>> img = np.zeros((4, 5, 3), np.uint8)
    >>> integral_channels(img).shape
    (5, 6, 4)
    >>> img = np.random.default_rng(0).integers(0, 255, (30, 20, 3), dtype=np.uint8)
    >>> integral_channels(img).tobytes() == integral_channels(img, strip_pixels=1).tobytes()  # strips of one row
    True
    """
    from skimage.color import rgb2luv

    rgb = to_rgb_uint8(image)
    H, W = rgb.shape[:2]
    out = np.zeros((H + 1, W + 1, N_CHANNELS))
    rows = max(1, int(strip_pixels) // max(W, 1))
    carry = None  # the column sums down to the strip's first row
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        a0, a1 = max(0, r0 - 1), min(H, r1 + 1)  # a row of context each side: the gradient's central differences
        luv = rgb2luv(rgb[a0:a1]).astype(np.float64)
        gy, gx = np.gradient(luv[..., 0])
        ch = np.concatenate([luv, np.hypot(gx, gy)[..., None]], axis=-1)[r0 - a0:r1 - a0]
        # (the first strip without a carried row: a zero added would turn its -0.0 sums into 0.0)
        cols = ch.cumsum(0) if carry is None else np.concatenate([carry, ch]).cumsum(0)[1:]
        carry = cols[-1:]
        out[r0 + 1:r1 + 1, 1:] = cols.cumsum(1)
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
