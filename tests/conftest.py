"""Shared test fixtures and helpers (data lives in tests/data so the project stands alone)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
KITTI_ROOT = DATA / "kitti"
# a detector bank trained in seconds on two frames (train_bank_on_frames options)
TINY_BANK = dict(n_partial=0, mining_rounds=1, neg_per_image=10, min_pos=20, min_height=40.0, max_scale=1.0,
                 per_octave=2)


def kitti_copy(dest: Path, frames, *, subdirs=("image_2", "calib", "label_2"), split="training",
               rename=None) -> Path:
    """A KITTI root at ``dest`` whose ``split`` holds copies of the test frames ``frames`` (only the
    ``subdirs`` given); ``rename`` maps a frame to the id its copy takes. Returns ``dest``."""
    rename = rename or {}
    for sub in subdirs:
        (dest / split / sub).mkdir(parents=True, exist_ok=True)
        ext = "png" if sub == "image_2" else "txt"
        for frame in frames:
            shutil.copy(KITTI_ROOT / "training" / sub / f"{frame}.{ext}",
                        dest / split / sub / f"{rename.get(frame, frame)}.{ext}")
    return dest


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
