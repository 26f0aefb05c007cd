"""Whether an evaluation's figures are held out: the frames evaluated that a model the run's
fits read was trained on.

The frame-trained models are the part model (read by the fine variants fitted to part
evidence), the detector bank and the crop viewpoint classifier (read for our own detections,
for boxes given without a viewpoint, and the bank for a pitch read off the boxes) and the
score calibration (the confidences the APs rank, unless the scores are raw): which of them a
run reads is :func:`wirescene.fitting.models.model_files_read`'s answer. A file of a ``train
all`` directory is told by its manifest's frames (:func:`wirescene.core.resources.trained_on`),
another trained on real frames (``train parts --kitti-root``, ``train detector --kitti-root``,
``train viewpoints``) by the record of their images it carries
(:func:`wirescene.core.artefacts.read_trained_images`), a shipped one (or a copy of it) by the
images' content (:mod:`wirescene.io.shipped_frames`): a user's KITTI root holds 65 of the
shipped models' 72 frames under the same ids.
"""

from __future__ import annotations

import os
from collections.abc import Iterable

from wirescene.core.artefacts import read_trained_images
from wirescene.core.resources import file_sha256, frames_of_content, shipped_path, trained_on
from wirescene.fitting.options import FitOptions
from wirescene.io.kitti import KittiDataset
from wirescene.io.shipped_frames import among_shipped_training_frames, shipped_training_frames

__all__ = ["FRAME_TRAINED", "trained_on_frames"]

#: The artefacts trained on real frames, as a message names them.
FRAME_TRAINED = {"parts_model": "part model", "detector_bank": "detector bank",
                 "viewpoint_classifier": "viewpoint classifier", "score_calibration": "score calibration"}


def trained_on_frames(dataset: KittiDataset, frame_ids: list[str] | None, *, options: FitOptions,
                      read: Iterable[str]) -> list[str]:
    """What to say of the frames evaluated that a model the run reads was trained on (their
    figures are not held out): a sentence for the files of each ``train all`` directory (by its
    manifest), one for the other files that record the frames they were trained on (a
    standalone training's, the files alike trained on the same frames evaluated together) and
    one for the shipped files (by the images' content); none where no model read was trained
    on them. A file of the user's own that records no frames says nothing.

    Parameters
    ----------
    dataset : KittiDataset
        The split evaluated.
    frame_ids : list of str or None
        The frames evaluated (None: every labelled frame).
    options : FitOptions
        The run's options, its models directory applied
        (:func:`~wirescene.fitting.models.with_models`): each artefact's file (None: the
        shipped one).
    read : iterable of str
        The artefacts the run's fits read (:func:`~wirescene.fitting.models.model_files_read`);
        those of :data:`FRAME_TRAINED` are looked up.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> sample = KittiDataset(DATA_DIR / "sample" / "kitti")  # two of the shipped models' 72 frames
    >>> read = ["parts_model", "score_calibration", "shape_model"]  # a fine variant on label boxes
    >>> print(*trained_on_frames(sample, None, options=FitOptions(), read=read))
    2 of the 2 frames evaluated are among the 72 the shipped part model and score calibration were trained on ...
    >>> print(*trained_on_frames(sample, ["000010"], options=FitOptions(), read=["score_calibration"]))
    1 of the 1 frames evaluated is among the 72 the shipped score calibration was trained on (e.g. 000010): its ...
    >>> trained_on_frames(sample, ["000010"], options=FitOptions(), read=[])
    []
    """
    frame_ids = dataset.require_frames() if frame_ids is None else list(frame_ids)
    read = set(read)
    said, shipped, by_manifest, by_record = [], [], {}, {}
    for name in (n for n in FRAME_TRAINED if n in read):
        file = getattr(options, name)
        if file is None or _same_bytes(file, shipped_path(name)):
            shipped.append(name)
            continue
        seen = trained_on(file, dataset.image_path, frame_ids, split_dir=dataset.split_dir)
        if seen:
            names, frames = by_manifest.setdefault(os.path.dirname(os.path.abspath(file)), ([], set()))
            names.append(name)
            frames.update(seen)
            continue
        # the file's own record (a train all file's agrees with its manifest, which has said it)
        seen = frames_of_content(dataset.image_path, frame_ids, read_trained_images(file))
        if seen:
            by_record.setdefault(tuple(seen), []).append((name, file))
    for folder, (names, frames) in by_manifest.items():
        seen = [f for f in frame_ids if f in frames]
        said.append(f"{_share(seen, frame_ids)} those the {_which(names)} of {folder} {_were(names)} trained on "
                    f"(e.g. {seen[0]}): {_figures(seen)} not held out")
    for seen, files in by_record.items():
        names = [name for name, _ in files]
        which = _which(names, files=[file for _, file in files])
        said.append(f"{_share(seen, frame_ids)} those the {which} {_were(names)} trained on (e.g. {seen[0]}): "
                    f"{_figures(seen)} not held out")
    seen = among_shipped_training_frames(dataset.image_path, frame_ids) if shipped else []
    if seen:
        said.append(f"{_share(seen, frame_ids)} the {len(shipped_training_frames())} the shipped {_which(shipped)} "
                    f"{_were(shipped)} trained on (e.g. {seen[0]}): {_figures(seen)} not held out")
    return said


def _which(names: list[str], *, files=None) -> str:
    """The artefacts ``names`` as a message names them: ``"part model and detector bank"``, each
    followed by its file of ``files`` where given (``"part model p.npz and detector bank b.npz"``)."""
    words = [FRAME_TRAINED[n] for n in names] if files is None else \
        [f"{FRAME_TRAINED[n]} {f}" for n, f in zip(names, files)]
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def _were(names: list[str]) -> str:
    """``"was"``, or ``"were"`` of several artefacts."""
    return "were" if len(names) > 1 else "was"


def _same_bytes(file, shipped) -> bool:
    """Whether ``file`` holds the shipped file's bytes (a copy of it counts as the shipped model)."""
    try:
        if os.path.getsize(file) != os.path.getsize(shipped):
            return False
    except OSError:
        return False
    return file_sha256(file) == file_sha256(shipped)


def _share(seen: list[str], frame_ids: list[str]) -> str:
    """``"N of the M frames evaluated are among"``, the verb agreeing with N."""
    return f"{len(seen)} of the {len(frame_ids)} frames evaluated {'is' if len(seen) == 1 else 'are'} among"


def _figures(seen: list[str]) -> str:
    """``"their figures are"``, or ``"its figures are"`` of one frame."""
    return f"{'its' if len(seen) == 1 else 'their'} figures are"
