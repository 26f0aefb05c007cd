"""Small array helpers for the hot paths."""

from __future__ import annotations

import numpy as np


def point_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Componentwise minimum and maximum ``(..., D)`` of point sets ``(..., V, D)``.

    Same as ``points.min(axis=-2), points.max(axis=-2)``; for the short point axes of
    boxes and wireframes (8 or 36 points) a loop of elementwise minima over the points
    is about 4x faster than numpy's reduction along a short, strided axis.
    """
    points = np.asarray(points)
    if points.shape[-2] == 0:
        raise ValueError("point_bounds needs at least one point")
    lo = points[..., 0, :].copy()
    hi = lo.copy()
    for k in range(1, points.shape[-2]):
        np.minimum(lo, points[..., k, :], out=lo)
        np.maximum(hi, points[..., k, :], out=hi)
    return lo, hi
