"""Cross-validation folds of the real KITTI frames, split by recording drive.

Frames of one drive share cars and streets, so a model scored on a frame must not have
been trained on any frame of the same drive. The 33 labelled frames at hand (141 cars,
8 drives) are split into four folds of whole drives; every real figure is reported on
frames whose fold was held out of training, and the shipped models are trained on all
folds (the set the project is finally judged on comes from other drives).

=====  =============================================  =====
fold   drives                                          cars
=====  =============================================  =====
0      2011_09_26_drive_0009                            64
1      2011_09_26_drive_0022                            34
2      2011_09_26_drive_0036, 2011_09_26_drive_0057     33
3      2011_09_26_drive_0101, _0086, 2011_09_29_0071,   10
       2011_09_28_drive_0106
=====  =============================================  =====

The frame -> drive map (``data/kitti_drives.json``) is copied from the KITTI devkit's
mapping files as listed in ``shared/data/kitti/SOURCES.md``; frames of other drives
(e.g. a user's full KITTI root) have no fold.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Iterable

from wirescene.core.artefacts import load_json
from wirescene.core.resources import DATA_DIR

N_FOLDS = 4

#: Fold of each drive (short names: date_drive_NNNN without ``_sync``).
DRIVE_FOLDS: dict[str, int] = {
    "2011_09_26_drive_0009": 0,
    "2011_09_26_drive_0022": 1,
    "2011_09_26_drive_0036": 2,
    "2011_09_26_drive_0057": 2,
    "2011_09_26_drive_0101": 3,
    "2011_09_26_drive_0086": 3,
    "2011_09_29_drive_0071": 3,
    "2011_09_28_drive_0106": 3,
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


def split_frames(frame_ids: Iterable[str], held_out: int) -> tuple[list[str], list[str]]:
    """``(train, test)``: the frames of the other folds, and those of fold ``held_out``.

    Frames of unknown drives raise ``KeyError`` (they cannot be assigned safely).
    """
    if not 0 <= held_out < N_FOLDS:
        raise ValueError(f"held_out must be in 0..{N_FOLDS - 1}, got {held_out}")
    train, test = [], []
    for f in frame_ids:
        (test if fold_of(f) == held_out else train).append(f)
    return train, test
