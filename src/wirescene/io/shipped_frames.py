"""The real frames the shipped models were trained on, known by their images' content.

The shipped part model, detector bank, crop viewpoint classifier and score calibration are
trained on the 72 labelled frames of ``shared/data/kitti`` (65 of KITTI's object training
set, 7 of tracking sequence 0001). A user's KITTI root holds the 65 under the same ids, so
figures of the shipped models on them are not held out. The record
``data/training_frames.json`` (format ``wirescene-training-frames/1``) holds each frame's
image digest (SHA-256 of ``image_2/FRAME.png``,
:func:`wirescene.core.resources.file_sha256`), so that a frame is told by its content, not
by its id alone (a synthetic scene ``000010`` is no KITTI frame). It is written by ``python
benchmarks/record_training_frames.py ../shared/data/kitti --out
src/wirescene/data/training_frames.json``.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Iterable

from wirescene.core.artefacts import load_json, save_json
from wirescene.core.resources import DATA_DIR, frames_of_content, images_sha256

__all__ = ["RECORD", "training_frames_record", "write_training_frames", "shipped_training_frames",
           "among_shipped_training_frames"]

#: The record of the frames the shipped models were trained on.
RECORD = DATA_DIR / "training_frames.json"
KIND = "training-frames"
VERSION = 1


def training_frames_record(image_paths: dict[str, Path], *, source: str) -> dict:
    """The record of frames ``{frame id: image path}``: ``{"source": source, "sha256": {frame id:
    digest}}``, frames in order of their ids.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "000010.png").write_bytes(b"")
    ...     record = training_frames_record({"000010": Path(d) / "000010.png"}, source="a test")
    >>> record["source"], {f: h[:6] for f, h in record["sha256"].items()}
    ('a test', {'000010': 'e3b0c4'})
    """
    return {"source": source, "sha256": images_sha256(image_paths.__getitem__, sorted(image_paths))}


def write_training_frames(path: str | Path, record: dict) -> Path:
    """Write ``record`` (:func:`training_frames_record`) to ``path`` with its format tag."""
    return save_json(path, record, kind=KIND, version=VERSION)


@lru_cache(maxsize=4)
def shipped_training_frames(path: Path = RECORD) -> dict[str, str]:
    """``{frame id: image digest}`` of the frames the shipped models were trained on.

    Examples
    --------
    >>> frames = shipped_training_frames()
    >>> len(frames), "000010" in frames, len(frames["000010"])
    (72, True, 64)
    """
    return dict(load_json(path, kind=KIND, version=VERSION)["sha256"])


def among_shipped_training_frames(image_path, frame_ids: Iterable[str], *, record: Path = RECORD) -> list[str]:
    """The frames of ``frame_ids`` whose image (``image_path(frame id)``) is one the shipped
    models were trained on: an id of the record whose image has the recorded content (only
    those ids are read, at most 72 images; one that cannot be read is not told).

    Examples
    --------
    >>> from wirescene.io.kitti import KittiDataset
    >>> sample = KittiDataset(DATA_DIR / "sample" / "kitti")  # the package's two of the 72 frames
    >>> among_shipped_training_frames(sample.image_path, sample.frame_ids())
    ['000010', '001545']
    >>> among_shipped_training_frames(lambda f: Path("elsewhere") / f"{f}.png", ["000010"])  # no such image
    []
    """
    return frames_of_content(image_path, frame_ids, shipped_training_frames(Path(record)))
