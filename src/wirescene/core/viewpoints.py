"""Coarse viewpoints: the 8 bins of the observation angle (KITTI ``alpha``) used by
pre-detection, as in the paper (8 equally spaced viewpoints, 45 degrees apart).

Bin ``b`` is centred on ``alpha = b * 45 deg`` (wrapped to ``[-pi, pi)``) and covers
``+-22.5 deg`` around it.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.groundplane import wrap_angle

N_BINS = 8
BIN_WIDTH = 2 * np.pi / N_BINS


def viewpoint_bin(alpha) -> np.ndarray:
    """Bin index ``(...)`` (int, 0..7) of observation angles ``alpha`` (radians, any range).

    Examples
    --------
    >>> viewpoint_bin(np.deg2rad([0.0, 22.0, 23.0, 90.0, -90.0, 180.0])).tolist()
    [0, 0, 1, 2, 6, 4]
    >>> viewpoint_bin(np.nan)
    Traceback (most recent call last):
    ...
    ValueError: viewpoint_bin: an unknown (non-finite) viewpoint has no bin
    """
    alpha = np.asarray(alpha, dtype=float)
    if not np.isfinite(alpha).all():  # NaN would be cast to bin 0: an unknown viewpoint made a known one
        raise ValueError("viewpoint_bin: an unknown (non-finite) viewpoint has no bin")
    return (np.round(alpha / BIN_WIDTH).astype(int)) % N_BINS


def bin_center(bin_index) -> np.ndarray:
    """Observation angle (radians, in ``[-pi, pi)``) at the centre of each bin ``(...)``.

    Examples
    --------
    >>> np.rad2deg(bin_center([0, 1, 4, 7])).round(1).tolist()  # bin 4 is -180 deg, not +180
    [0.0, 45.0, -180.0, -45.0]
    >>> viewpoint_bin(bin_center(np.arange(8))).tolist()
    [0, 1, 2, 3, 4, 5, 6, 7]
    """
    return wrap_angle(np.asarray(bin_index, dtype=float) * BIN_WIDTH)


def angle_difference(a, b) -> np.ndarray:
    """Absolute angular difference ``|a - b|`` (radians, broadcasting) wrapped to ``[0, pi]``.

    Examples
    --------
    >>> round(float(np.rad2deg(angle_difference(np.deg2rad(170.0), np.deg2rad(-170.0)))), 6)  # across +-180
    20.0
    """
    return np.abs(wrap_angle(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))
