"""Drive folds: deterministic, balanced, and the shipped table is what assign_folds makes."""

from __future__ import annotations

import collections
from pathlib import Path

import pytest

from wirescene.io.folds import DRIVE_FOLDS, FOLD_GROUPS, N_FOLDS, assign_folds, fold_of, frame_drives

SHARED_KITTI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti" / "training"


def test_assign_folds_deals_the_largest_drive_first_to_the_lightest_fold():
    folds = assign_folds({"a": 10, "b": 6, "c": 5, "d": 1}, n_folds=2)
    assert folds == {"a": 0, "b": 1, "c": 1, "d": 0}
    # the order of the mapping does not matter
    assert assign_folds({"d": 1, "c": 5, "b": 6, "a": 10}, n_folds=2) == folds
    with pytest.raises(ValueError, match="n_folds"):
        assign_folds({"a": 1}, n_folds=0)


def test_every_known_frame_has_a_fold_and_the_groups_split_the_folds():
    drives = frame_drives()
    assert len(drives) == 72 and len(set(drives.values())) == 25
    assert {fold_of(f) for f in drives} == set(range(N_FOLDS))
    assert sorted(k for g in FOLD_GROUPS for k in g) == list(range(N_FOLDS))
    with pytest.raises(KeyError):
        fold_of("999999")


@pytest.mark.skipif(not SHARED_KITTI.is_dir(), reason="the shared KITTI frames are not beside the checkout")
def test_shipped_drive_folds_are_assign_folds_of_the_shared_frames():
    cars = collections.Counter()
    for frame, drive in frame_drives().items():
        rows = (SHARED_KITTI / "label_2" / f"{frame}.txt").read_text().splitlines()
        cars[drive] += sum(1 for r in rows if r.split()[:1] == ["Car"])
    assert sum(cars.values()) == 294
    assert assign_folds(cars) == DRIVE_FOLDS
    per_fold = collections.Counter()
    for drive, n in cars.items():
        per_fold[DRIVE_FOLDS[drive]] += n
    assert max(per_fold.values()) - min(per_fold.values()) <= 2
