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
no fold in :func:`fold_of`. A user's whole KITTI training split is grouped by drive through
the devkit's own mapping files (:func:`read_devkit_mapping`, found next to the data by
:func:`find_devkit_mapping`; :func:`drive_map` joins both).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Iterable, Mapping

from wirescene.core.artefacts import load_json
from wirescene.core.errors import InputError
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
    """``{frame id: drive}`` of the labelled real frames the project knows.

    Examples
    --------
    >>> frame_drives()["000010"]  # drive names without KITTI's ``_sync``
    '2011_09_26_drive_0036'
    """
    record = load_json(DATA_DIR / "kitti_drives.json", kind="kitti-drives", version=1)
    return {f: d.removesuffix("_sync") for f, d in record["drives"].items()}


def drive_groups(frames: Iterable[str], drives: Mapping[str, str] | None = None) -> dict[str, str]:
    """``{frame: group}``: each frame's recording drive (``drives``, default :func:`frame_drives`),
    a frame of unknown drive a group of its own; no held-out fold splits a group.

    Examples
    --------
    >>> drive_groups(["000010", "900001"])
    {'000010': '2011_09_26_drive_0036', '900001': '900001'}
    """
    drives = frame_drives() if drives is None else drives
    return {f: drives.get(f, f) for f in frames}


#: The devkit's files: a random permutation of the object frames' 1-based indices into the
#: lines of the mapping (``date drive raw_frame``), one line each.
DEVKIT_RAND, DEVKIT_MAPPING = "train_rand.txt", "train_mapping.txt"
#: Where :func:`find_devkit_mapping` looks, relative to a KITTI root (the object devkit
#: unpacks as ``devkit_object/`` or ``devkit/``, its mapping files in ``mapping/``).
DEVKIT_PLACES = ("mapping", "devkit/mapping", "devkit_object/mapping")


def read_devkit_mapping(directory) -> dict[str, str]:
    r"""``{frame id: drive}`` of KITTI's object training frames from the devkit's mapping files.

    Parameters
    ----------
    directory : path
        Holds :data:`DEVKIT_RAND` (one line of comma-separated 1-based indices, the i-th for
        frame ``i``, written ``%06d``) and :data:`DEVKIT_MAPPING` (``2011_09_26
        2011_09_26_drive_0005_sync 0000000109`` a line).

    Returns
    -------
    dict
        Drive names as :func:`frame_drives` gives them (``2011_09_26_drive_0005``).

    Raises
    ------
    InputError
        A missing file, an index that is not a positive integer or has no mapping line, a
        malformed mapping line; the message names the file.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "train_rand.txt").write_text("2,1\n")
    ...     _ = (Path(d) / "train_mapping.txt").write_text(
    ...         "2011_09_26 2011_09_26_drive_0005_sync 0000000109\n2011_09_26 2011_09_26_drive_0009_sync 0000000003\n")
    ...     read_devkit_mapping(d)
    {'000000': '2011_09_26_drive_0009', '000001': '2011_09_26_drive_0005'}
    """
    directory = Path(directory)
    rand_path, mapping_path = directory / DEVKIT_RAND, directory / DEVKIT_MAPPING
    for path in (rand_path, mapping_path):
        if not path.is_file():
            raise InputError(f"no {path.name} here: not a KITTI devkit mapping directory", path=directory)
    drives = []
    for number, line in enumerate(mapping_path.read_text().splitlines(), 1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != 3 or "_drive_" not in fields[1]:
            raise InputError(f"line {number} is not 'date drive frame': {line.strip()[:60]!r}", path=mapping_path)
        drives.append(fields[1].removesuffix("_sync"))
    out = {}
    for i, item in enumerate(t for t in rand_path.read_text().replace("\n", ",").split(",") if t.strip()):
        if not item.strip().isdigit() or not 1 <= int(item) <= len(drives):
            raise InputError(f"entry {i + 1} ({item.strip()[:20]!r}) is not a line of {DEVKIT_MAPPING} "
                             f"(1..{len(drives)})", path=rand_path)
        out[f"{i:06d}"] = drives[int(item) - 1]
    return out


def find_devkit_mapping(kitti_root) -> Path | None:
    """The devkit mapping directory at one of :data:`DEVKIT_PLACES` under ``kitti_root``
    (both files present), or None.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as root:
    ...     before = find_devkit_mapping(root)
    ...     (Path(root) / "devkit" / "mapping").mkdir(parents=True)
    ...     for name in (DEVKIT_RAND, DEVKIT_MAPPING):
    ...         _ = (Path(root) / "devkit" / "mapping" / name).write_text("")
    ...     before, find_devkit_mapping(root).relative_to(root).as_posix()
    (None, 'devkit/mapping')
    """
    for place in DEVKIT_PLACES:
        directory = Path(kitti_root) / place
        if (directory / DEVKIT_RAND).is_file() and (directory / DEVKIT_MAPPING).is_file():
            return directory
    return None


def drive_map(kitti_root=None, *, mapping=None) -> tuple[dict[str, str], Path | None]:
    """``({frame id: drive}, mapping directory or None)``: the drives of the frames the
    project knows (:func:`frame_drives`) and, over them, those of the devkit mapping files
    in ``mapping`` or else found under ``kitti_root`` (:func:`find_devkit_mapping`)."""
    directory = Path(mapping) if mapping is not None else (
        None if kitti_root is None else find_devkit_mapping(kitti_root))
    drives = dict(frame_drives())
    if directory is not None:
        drives.update(read_devkit_mapping(directory))
    return drives, directory


def fold_of(frame_id: str) -> int:
    """Fold (0 to :data:`N_FOLDS` - 1) of a frame id; ``KeyError`` for a frame of an unknown drive.

    Examples
    --------
    >>> fold_of("000010")  # drive 2011_09_26_drive_0036
    3
    >>> fold_of("999999")
    Traceback (most recent call last):
    ...
    KeyError: "frame '999999' has no known recording drive"
    """
    drive = frame_drives().get(frame_id)
    if drive is None:
        raise KeyError(f"frame {frame_id!r} has no known recording drive")
    return DRIVE_FOLDS[drive]
