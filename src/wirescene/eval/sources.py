"""Where each frame's pre-detections come from in an evaluation, and the per-frame
random stream that makes runs independent of scheduling."""

from __future__ import annotations

import itertools
import os
import stat
import zlib
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wirescene.core.errors import InputError
from wirescene.core.types import Detections
from wirescene.core.validate import finite_real
from wirescene.io.detections import detections_from_labels, format_classes, read_boxes_and_classes
from wirescene.io.kitti import KittiDataset

if TYPE_CHECKING:  # imported where the bank runs
    from wirescene.fitting.options import PredetectOptions
    from wirescene.lift import LiftingOptions


#: The extensions of a detections directory's files.
DETECTION_SUFFIXES = (".json", ".csv", ".txt")


def _spellings(suffix: str) -> list[str]:
    """Every spelling of ``suffix`` in upper and lower case, the lower-case one first.

    Examples
    --------
    >>> _spellings(".csv")
    ['.csv', '.csV', '.cSv', '.cSV', '.Csv', '.CsV', '.CSv', '.CSV']
    """
    return list(dict.fromkeys("".join(chars) for chars in itertools.product(*((c, c.upper()) for c in suffix))))


# probed by name (32 a frame), not by listing the directory: a look-up costs the same in KITTI's 7481 files
_SPELLINGS = [spelling for suffix in DETECTION_SUFFIXES for spelling in _spellings(suffix)]


@dataclass(frozen=True)
class DetectionSource:
    """Where pre-detections come from: ``"gt"`` (label boxes, noisy viewpoint bins),
    ``"bank"`` (our part-configuration detector bank on the raw image) or a directory of
    per-frame detection files (``FRAME.json``, ``.csv`` or ``.txt``, the extension in any case).

    A frame without a detection file in the directory is an error, unless
    ``allow_missing`` (then it has no detections, and :meth:`missing_frames` counts it).
    ``min_score``: of a directory's files, only the boxes scoring at or above it are kept
    (``read_detections(min_score=...)``; a file with none left is a frame without
    detections); None keeps every box. It does not apply to ``gt`` or ``bank``.

    Examples
    --------
    >>> import tempfile
    >>> DetectionSource().folder is None, DetectionSource("bank").own  # label boxes; our own detector bank
    (True, True)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = Path(tmp, "000001.json").write_text("{}")
    ...     source = DetectionSource(tmp, allow_missing=True)
    ...     source.detection_file("000001").name, source.missing_frames(["000001", "000002"])
    ('000001.json', ['000002'])
    >>> import pickle  # sent to worker processes and Dask workers as it is
    >>> pickle.loads(pickle.dumps(DetectionSource("dets", min_score=0.5))).min_score
    0.5
    """

    spec: str = "gt"
    viewpoint_noise_deg: float = 0.0
    allow_missing: bool = False
    bank: str | None = None  # detector bank file for "bank" (None: the shipped one)
    classifier: str | None = None  # crop viewpoint classifier file for "bank" (None: the shipped one)
    min_score: float | None = None  # score floor of the boxes of a directory's files (None: every box)

    @property
    def folder(self) -> Path | None:
        """The detections directory, or None for ``gt`` / ``bank``."""
        if self.spec in ("gt", "bank"):
            return None
        folder = Path(self.spec)
        if not folder.is_dir():
            raise InputError("detections must be 'gt', 'bank' or a directory of per-frame files", path=folder)
        return folder

    def detection_file(self, frame_id: str) -> Path | None:
        """The frame's file in the detections directory (None if it has none), its extension in
        any case (``000010.JSON``, as Windows tools write it); an :class:`InputError` if it has two
        (which one holds the detections meant is unknown)."""
        stem = os.path.join(self.folder, frame_id)
        found, seen = [], set()
        for ext in _SPELLINGS:
            path = stem + ext
            try:  # os.access first: a miss (31 of the 32 spellings) without the cost of an exception
                st = os.stat(path) if os.access(path, os.F_OK) else None
            except (OSError, ValueError):  # gone since, unreadable, or a frame id no path can hold
                st = None
            # a case-insensitive file system finds one file under every spelling: counted once
            key = None if st is None else (ext.lower(), st.st_dev, st.st_ino)
            if key is not None and stat.S_ISREG(st.st_mode) and key not in seen:
                seen.add(key)
                found.append(Path(path))
        if len(found) > 1:
            raise InputError(f"frame {frame_id} has {len(found)} detection files ({', '.join(p.name for p in found)}): "
                             "keep one", path=self.folder)
        return found[0] if found else None

    def missing_frames(self, frame_ids: list[str]) -> list[str]:
        """Frames without a detection file; an :class:`InputError` naming the directory
        if there are any and ``allow_missing`` is off."""
        if self.folder is None:
            return []
        missing = [f for f in frame_ids if self.detection_file(f) is None]
        if missing and not self.allow_missing:
            what = ("none of the frames have a detection file" if len(missing) == len(frame_ids)
                    else f"{len(missing)} of {len(frame_ids)} frames have no detection file")
            raise InputError(f"{what} (e.g. no {missing[0]}.json, .csv or .txt); "
                             "--allow-missing-detections treats such frames as having none", path=self.folder)
        return missing

    def floor_record(self) -> dict:
        """The score floor as a run's settings record holds it: ``{"min_score": S}``, or ``{}``
        without one (as in records written before the floor existed, which so still match).

        Examples
        --------
        >>> DetectionSource("dets", min_score=0.5).floor_record(), DetectionSource("dets").floor_record()
        ({'min_score': 0.5}, {})
        """
        return {} if self.min_score is None else {"min_score": float(self.min_score)}

    def check_files(self, dataset: KittiDataset, frame_ids: list[str],
                    notify: Callable[[str], None] | None = None) -> dict[str, Detections]:
        """Read every frame's file of the detections directory once (nothing for ``gt`` / ``bank``):
        an :class:`InputError` naming the first malformed one before a run fits any frame, as
        :meth:`~wirescene.io.kitti.KittiDataset.check_frames` for the calibrations and labels (a
        bad file found at frame N would leave the N - 1 frames fitted before it).

        ``notify`` is told, in one line, when no file holds a car (of any score) and some hold boxes
        of other classes alone (a detector that numbers its classes otherwise than COCO, whose every
        box would be skipped: a run without a car, read as streets without cars), naming the most
        common of those classes over all the files, with their counts.

        Returns ``{frame: its detections}`` as :meth:`for_frame` gives them (``{}`` for ``gt`` /
        ``bank``), for the checks before the first fit that look at the boxes
        (:func:`~wirescene.eval.runner.check_images_read`, :func:`~wirescene.eval.runner.boxes_lack_viewpoints`):
        each file read once a run, not once a check."""
        if self.folder is None:
            return {}
        boxes, others, files = {}, Counter(), 0  # others: the boxes of files of other classes alone, while no car
        for frame_id in frame_ids:
            boxes[frame_id], classes = self._file_boxes(dataset, frame_id)
            if classes is None:  # cars (all under the floor, maybe): the classes are read as they should be
                others = None
            elif others is not None and classes:  # a file of boxes of other classes alone
                others.update(classes)
                files += 1
        if notify is not None and others:
            n = others.total()
            notify(f"warning: no detection file in {self.folder} holds a car: {files} of the {len(frame_ids)} "
                   f"frames' files hold boxes of other classes alone ({n:,} {'box' if n == 1 else 'boxes'}: "
                   f"{format_classes(others)}), fitted as frames without cars; a car is 'car' (category, "
                   "category_name, label, class or type) or COCO's category_id 3")
        return boxes

    @property
    def own(self) -> bool:
        """Whether these are our own pre-detections (the fit verifies them)."""
        return self.spec == "bank"

    def for_frame(self, dataset: KittiDataset, frame_id: str, rng: np.random.Generator, *,
                  predetect: PredetectOptions | None = None, lifting: LiftingOptions | None = None) -> Detections:
        """The detections of one frame; ``predetect``: the threshold, smallest car and
        enlargement of our own pre-detection (:func:`~wirescene.fitting.own_boxes.own_detections`;
        None: the bank's own);
        ``lifting``: the camera's mount (``LiftingOptions.mount``), for its priors (None: KITTI's)."""
        if self.spec == "gt":
            return detections_from_labels(dataset.labels(frame_id), viewpoint_noise_deg=self.viewpoint_noise_deg, rng=rng)
        if self.spec == "bank":
            from wirescene.fitting.models import detector_bank, viewpoint_classifier
            from wirescene.fitting.own_boxes import own_detections
            from wirescene.lift import LiftingOptions

            rig = LiftingOptions() if lifting is None else lifting
            return own_detections(dataset.camera(frame_id), dataset.image(frame_id), bank=detector_bank(self.bank),
                                  classifier=viewpoint_classifier(self.classifier),
                                  threshold=None if predetect is None else predetect.threshold,
                                  smallest_car=None if predetect is None else predetect.smallest_car,
                                  upsample=1.0 if predetect is None else predetect.upsample,
                                  mount=rig.mount, estimate_pitch=rig.estimate_pitch)
        return self._file_boxes(dataset, frame_id)[0]

    def _file_boxes(self, dataset: KittiDataset, frame_id: str) -> tuple[Detections, Counter | None]:
        """The detections of the frame's file, its boxes scoring ``min_score`` or more, and, where
        the file holds no car (before the floor: a file of cars all under it holds cars), how many
        boxes of each other class it holds (none where it is missing), else None."""
        path = self.detection_file(frame_id)
        if path is None:
            if not self.allow_missing:
                raise InputError(f"no detection file for frame {frame_id}", path=self.folder)
            return Detections.empty(str(self.folder)), Counter()
        dets, classes = read_boxes_and_classes(path, image_size=dataset.image_size(frame_id))
        if len(dets) == 0:
            return Detections.empty(str(path)), classes
        if self.min_score is not None:  # the floor, as read_detections applies it
            dets = dets.subset(dets.scores >= self.min_score)
        return (dets if len(dets) else Detections.empty(str(path))), None


def min_score_problem(min_score, spec) -> str | None:
    """Why ``min_score`` cannot floor the boxes of the detections ``spec`` (``DetectionSource.spec``;
    None: our own pre-detection), or None: it must be a finite number, and only boxes read
    from files have such a floor (label boxes are all fitted, our own pre-detection has its
    detection threshold). The command line and the API each name their own option.

    Examples
    --------
    >>> min_score_problem(None, "gt"), min_score_problem(0.5, "dets")
    (None, None)
    >>> min_score_problem(float("nan"), "dets"), min_score_problem(0.5, "gt")
    ('must be a finite number, got nan', "label boxes ('gt') are all fitted")
    """
    if min_score is None:
        return None
    if not finite_real(min_score):
        return f"must be a finite number, got {min_score!r}"
    if spec is None or str(spec) == "bank":
        return "our own pre-detection's floor is its detection threshold"
    if str(spec) == "gt":
        return "label boxes ('gt') are all fitted"
    return None


def frame_seed(seed: int, frame_id: str) -> np.random.Generator:
    """A generator that depends only on the run seed and the frame, so results do not depend
    on the order (or the process) in which frames are processed. A numeric id below 2^32 seeds by its
    number (``"000007"`` and ``"7"`` share a stream), any other by its bytes' CRC-32 in a
    stream of its own (``"a1"`` and ``"b1"`` differ).

    Examples
    --------
    >>> a, b = frame_seed(0, "000007").random(), frame_seed(0, "000007").random()
    >>> a == b, a == frame_seed(1, "000007").random(), a == frame_seed(0, "7").random()
    (True, False, True)
    >>> frame_seed(0, "a1").random() == frame_seed(0, "b1").random()
    False
    """
    if frame_id.isascii() and frame_id.isdigit() and int(frame_id) < 2**32:  # KITTI's: every earlier run's streams
        return np.random.default_rng([seed, int(frame_id)])
    # a spawn key of its own: one 32-bit word of id, so no id's entropy equals a numeric id's (zero-padded) one
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(frame_id.encode("utf-8"))], spawn_key=(1,)))
