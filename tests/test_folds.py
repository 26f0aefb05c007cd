"""Drive folds: deterministic, balanced, and the shipped table is what assign_folds makes."""

from __future__ import annotations

import collections
import re
from pathlib import Path

import pytest

from wirescene.io.folds import DRIVE_FOLDS, FOLD_GROUPS, N_FOLDS, assign_folds, fold_of, frame_drives

SHARED_KITTI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti" / "training"
# The label files of the 72 shared frames, copied: the folds are checked wherever the tests run.
SHARED_LABELS = Path(__file__).resolve().parent / "data" / "shared_labels"


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
def test_the_copied_labels_are_the_shared_frames_labels():
    copies = sorted(SHARED_LABELS.glob("*.txt"))
    assert [p.name for p in copies] == sorted(p.name for p in (SHARED_KITTI / "label_2").iterdir())
    for copy in copies:
        assert copy.read_bytes() == (SHARED_KITTI / "label_2" / copy.name).read_bytes(), copy.name


def test_shipped_drive_folds_are_assign_folds_of_the_shared_frames():
    cars = collections.Counter()
    for frame, drive in frame_drives().items():
        rows = (SHARED_LABELS / f"{frame}.txt").read_text().splitlines()
        cars[drive] += sum(1 for r in rows if r.split()[:1] == ["Car"])
    assert sum(cars.values()) == 294
    assert assign_folds(cars) == DRIVE_FOLDS
    per_fold = collections.Counter()
    for drive, n in cars.items():
        per_fold[DRIVE_FOLDS[drive]] += n
    assert max(per_fold.values()) - min(per_fold.values()) <= 2


def _devkit(directory, rand: str, mapping: list[str]):
    directory.mkdir(parents=True)
    (directory / "train_rand.txt").write_text(rand)
    (directory / "train_mapping.txt").write_text("".join(line + "\n" for line in mapping))
    return directory


def test_devkit_mapping_gives_each_frame_its_drive(tmp_path):
    from wirescene.io.folds import drive_map, find_devkit_mapping, read_devkit_mapping

    lines = ["2011_09_26 2011_09_26_drive_0005_sync 0000000109", "2011_09_26 2011_09_26_drive_0009_sync 0000000003",
             "2011_10_03 2011_10_03_drive_0047_sync 0000000723"]
    mapping = _devkit(tmp_path / "kitti" / "devkit_object" / "mapping", "3,1,2,1\n", lines)
    assert read_devkit_mapping(mapping) == {"000000": "2011_10_03_drive_0047", "000001": "2011_09_26_drive_0005",
                                            "000002": "2011_09_26_drive_0009", "000003": "2011_09_26_drive_0005"}
    assert find_devkit_mapping(tmp_path / "kitti") == mapping
    assert find_devkit_mapping(tmp_path) is None
    drives, where = drive_map(tmp_path / "kitti")
    assert where == mapping and drives["000002"] == "2011_09_26_drive_0009"  # the devkit's over the project's
    assert drives["trk0001_000000"] == frame_drives()["trk0001_000000"]  # frames it does not list keep theirs
    assert drive_map(tmp_path) == (frame_drives(), None)


@pytest.mark.parametrize("rand, mapping, problem", [
    ("1,4\n", ["2011_09_26 2011_09_26_drive_0005_sync 0000000109"], "entry 2 ('4') is not a line"),
    ("1,x\n", ["2011_09_26 2011_09_26_drive_0005_sync 0000000109"], "entry 2 ('x')"),
    ("1\n", ["2011_09_26 0000000109"], "line 1 is not 'date drive frame'"),
])
def test_bad_devkit_mapping_names_the_file(tmp_path, rand, mapping, problem):
    from wirescene.core.errors import InputError
    from wirescene.io.folds import read_devkit_mapping

    directory = _devkit(tmp_path / "mapping", rand, mapping)
    with pytest.raises(InputError, match=re.escape(problem)) as info:
        read_devkit_mapping(directory)
    assert "train_" in str(info.value) and "\n" not in str(info.value)
    (directory / "train_rand.txt").unlink()
    with pytest.raises(InputError, match="no train_rand.txt here"):
        read_devkit_mapping(directory)
