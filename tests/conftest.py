"""Shared test fixtures and helpers (data lives in tests/data so the project stands alone)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
KITTI_ROOT = DATA / "kitti"
# a detector bank trained in seconds on two frames (train_bank_on_frames options)
TINY_BANK = dict(n_partial=0, mining_rounds=1, neg_per_image=10, min_pos=20, min_height=40.0, max_scale=1.0,
                 per_octave=2)


def assert_close(actual, expected, *, atol=1e-6, rtol=1e-6, msg=""):
    """pytorch3d-style closeness check that reports the worst offender."""
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape or expected.ndim == 0, f"{msg} shape {actual.shape} != {expected.shape}"
    diff = np.abs(actual - expected)
    tol = atol + rtol * np.abs(expected)
    if not np.all(diff <= tol):
        idx = np.unravel_index(np.argmax(diff - tol), diff.shape) if diff.ndim else ()
        raise AssertionError(
            f"{msg} not close: max |diff| {diff.max():.3g} at {idx} "
            f"(actual {actual[idx] if diff.ndim else actual}, expected {np.broadcast_to(expected, diff.shape)[idx] if diff.ndim else expected})"
        )


@pytest.fixture(scope="session")
def kitti_root() -> Path:
    return KITTI_ROOT
