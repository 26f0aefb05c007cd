"""Cross-validation folds of labelled KITTI frames, split by recording drive.

Frames of one drive share cars and streets, so a model scored on a frame must not have
been trained on any frame of the same drive. :func:`assign_folds` splits any set of
frames into folds of whole drives, balanced by their number of cars (a frame whose drive
is unknown -- a user's KITTI root without the devkit's mapping files -- is a group of its
own). The 72 labelled frames at hand (294 cars, 25 drives) are split this way into the
four folds of :data:`DRIVE_FOLDS`; every real figure is reported on frames whose fold was
held out of training, and the shipped models are trained on all folds (the set the
project is finally judged on comes from other drives). Settings are chosen on one fold
group (:data:`FOLD_GROUPS`) and reported on the other.

=====  ==========================================================================  =====
fold   drives (2011_MM_DD_drive_NNNN)                                                frames/cars
=====  ==========================================================================  =====
0      09_26_0009 (trk0001 included), 09_26_0011, 09_26_0086, 09_26_0091             15 / 74
1      09_26_0022, 09_26_0051, 09_26_0084, 09_26_0001, 09_28_0016, 09_29_0071         21 / 74
2      09_26_0059, 10_03_0047, 09_26_0093, 09_26_0032, 09_26_0046, 09_26_0019,        18 / 73
       09_26_0087, 09_28_0106
3      09_26_0036, 09_26_0106, 09_26_0057, 09_26_0015, 09_26_0101, 09_29_0004,        18 / 73
       09_26_0027
=====  ==========================================================================  =====

The frame -> drive map (``data/kitti_drives.json``) is copied from the KITTI devkit's
mapping files as listed in ``shared/data/kitti/SOURCES.md``; frames of other drives have
no fold in :func:`fold_of`.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Mapping

from wirescene.core.artefacts import load_json
from wirescene.core.resources import DATA_DIR

N_FOLDS = 4

#: The two fold groups: a setting is chosen on one and reported on the other.
FOLD_GROUPS: tuple[tuple[int, ...], tuple[int, ...]] = ((0, 1), (2, 3))


def assign_folds(cars: Mapping[str, int], *, n_folds: int = N_FOLDS) -> dict[str, int]:
    """``{group: fold}``: groups (drives) of ``cars`` (``{group: number of cars}``) dealt to
    ``n_folds`` folds, the largest group first, each to the fold with the fewest cars so far
    (ties: the lowest fold, then the fewest groups); deterministic for a given mapping.

    Examples
    --------
    >>> assign_folds({"a": 10, "b": 6, "c": 5, "d": 1}, n_folds=2)
    {'a': 0, 'b': 1, 'c': 1, 'd': 0}
    """
    if n_folds < 1:
        raise ValueError(f"n_folds must be at least 1, got {n_folds}")
    load, size, out = [0] * n_folds, [0] * n_folds, {}
    for group, n in sorted(cars.items(), key=lambda kv: (-int(kv[1]), str(kv[0]))):
        k = min(range(n_folds), key=lambda i: (load[i], size[i], i))
        out[group] = k
        load[k] += int(n)
        size[k] += 1
    return out


#: Fold of each drive of the shared frames (short names: date_drive_NNNN without ``_sync``):
#: :func:`assign_folds` of their car counts (checked by ``tests/test_folds.py``).
DRIVE_FOLDS: dict[str, int] = {
    "2011_09_26_drive_0009": 0, "2011_09_26_drive_0011": 0, "2011_09_26_drive_0086": 0,
    "2011_09_26_drive_0091": 0,
    "2011_09_26_drive_0022": 1, "2011_09_26_drive_0051": 1, "2011_09_26_drive_0084": 1,
    "2011_09_26_drive_0001": 1, "2011_09_28_drive_0016": 1, "2011_09_29_drive_0071": 1,
    "2011_09_26_drive_0059": 2, "2011_10_03_drive_0047": 2, "2011_09_26_drive_0093": 2,
    "2011_09_26_drive_0032": 2, "2011_09_26_drive_0046": 2, "2011_09_26_drive_0019": 2,
    "2011_09_26_drive_0087": 2, "2011_09_28_drive_0106": 2,
    "2011_09_26_drive_0036": 3, "2011_09_26_drive_0106": 3, "2011_09_26_drive_0057": 3,
    "2011_09_26_drive_0015": 3, "2011_09_26_drive_0101": 3, "2011_09_29_drive_0004": 3,
    "2011_09_26_drive_0027": 3,
}


@lru_cache(maxsize=1)
def frame_drives() -> dict[str, str]:
    """``{frame id: drive}`` of the labelled real frames the project knows."""
    record = load_json(DATA_DIR / "kitti_drives.json", kind="kitti-drives", version=1)
    return {f: d.removesuffix("_sync") for f, d in record["drives"].items()}


def fold_of(frame_id: str) -> int:
    """Fold of a frame; ``KeyError`` for a frame of an unknown drive."""
    drive = frame_drives().get(frame_id)
    if drive is None:
        raise KeyError(f"frame {frame_id!r} has no known recording drive")
    return DRIVE_FOLDS[drive]
