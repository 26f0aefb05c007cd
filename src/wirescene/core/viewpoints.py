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
    """Bin index ``(...)`` (int, 0..7) of observation angles ``alpha`` (radians)."""
    return (np.round(np.asarray(alpha, dtype=float) / BIN_WIDTH).astype(int)) % N_BINS


def bin_center(bin_index) -> np.ndarray:
    """Observation angle (radians, in ``[-pi, pi)``) at the centre of each bin."""
    return wrap_angle(np.asarray(bin_index, dtype=float) * BIN_WIDTH)


def angle_difference(a, b) -> np.ndarray:
    """Absolute angular difference ``|a - b|`` wrapped to ``[0, pi]``."""
    return np.abs(wrap_angle(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))
