"""Small array helpers for the hot paths."""

from __future__ import annotations

import numpy as np


def point_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Componentwise minimum and maximum ``(..., D)`` of point sets ``(..., V, D)``.

    Same as ``points.min(axis=-2), points.max(axis=-2)``; for the short point axes of
    boxes and wireframes (8 or 36 points) a loop of elementwise minima over the points
    is about 4x faster than numpy's reduction along a short, strided axis.

    Examples
    --------
    >>> lo, hi = point_bounds(np.array([[0.0, 1.0, 2.0], [3.0, -1.0, 5.0]]))
    >>> lo.tolist(), hi.tolist()
    ([0.0, -1.0, 2.0], [3.0, 1.0, 5.0])
    >>> [a.shape for a in point_bounds(np.zeros((250, 6, 36, 3)))]  # particles x cars x vertices
    [(250, 6, 3), (250, 6, 3)]
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
