"""Whether an evaluation's figures are held out: the frames evaluated that a model the run
reads was trained on.

The frame-trained models are the part model (read by the fine variants fitted to part
evidence), the detector bank and the crop viewpoint classifier (read for our own detections
and for boxes given without a viewpoint) and the score calibration (the confidences the APs
rank, unless the scores are raw). A model of a models directory is told by its manifest's
frames (:func:`wirescene.core.resources.trained_on`), a shipped one by the images' content
(:mod:`wirescene.io.shipped_frames`): a user's KITTI root holds 65 of the shipped models' 72
frames under the same ids.
"""

from __future__ import annotations

from pathlib import Path

from wirescene.core.resources import resolve_models, trained_on
from wirescene.fitting.variants import get_variant
from wirescene.io.kitti import KittiDataset
from wirescene.io.shipped_frames import among_shipped_training_frames, shipped_training_frames

__all__ = ["FRAME_TRAINED", "trained_on_frames"]

#: The artefacts trained on real frames, as a message names them.
FRAME_TRAINED = {"parts_model": "part model", "detector_bank": "detector bank",
                 "viewpoint_classifier": "viewpoint classifier", "score_calibration": "score calibration"}


def trained_on_frames(models_dir: str | Path | None, dataset: KittiDataset, frame_ids: list[str] | None, *,
                      variants, detections: str, replaced=(), calibrated: bool = True,
                      evidence: str = "parts") -> list[str]:
    """What to say of the frames evaluated that a model the run reads was trained on (their
    figures are not held out): a sentence for ``models_dir``'s own models (by its manifest) and
    one for the shipped ones it lacks; none where no model read was trained on them.

    Parameters
    ----------
    models_dir : path or None
        The run's models directory (None: every artefact the shipped one).
    dataset : KittiDataset
        The split evaluated.
    frame_ids : list of str or None
        The frames evaluated (None: every labelled frame).
    variants : iterable of str
        The variants fitted (a fine one reads the part model).
    detections : str
        ``"gt"`` (label boxes, with their viewpoints: neither the bank nor the classifier is
        read), ``"bank"`` or a directory of detection files.
    replaced : iterable of str
        Artefacts (keys of :data:`FRAME_TRAINED`) given as files of their own in the run
        (``--parts-model``, ``--bank``, ``--viewpoint-classifier``, ``--score-calibration``).
    calibrated : bool
        Whether the confidences are calibrated (the score calibration read).
    evidence : {"parts", "oracle"}
        What the fine variants fit to (``eval --evidence``): the part model's evidence, or
        true vertices, which read no part model.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> sample = KittiDataset(DATA_DIR / "sample" / "kitti")  # two of the shipped models' 72 frames
    >>> print(*trained_on_frames(None, sample, None, variants=["full"], detections="gt"))
    2 of the 2 frames evaluated are among the 72 the shipped part model and score calibration were trained on ...
    >>> print(*trained_on_frames(None, sample, ["000010"], variants=["coarse"], detections="gt"))
    1 of the 1 frames evaluated is among the 72 the shipped score calibration was trained on (e.g. 000010): its ...
    >>> trained_on_frames(None, sample, ["000010"], variants=["coarse"], detections="gt", calibrated=False)
    []
    """
    models = resolve_models(models_dir)
    frame_ids = dataset.require_frames() if frame_ids is None else list(frame_ids)
    read = {"parts_model"} if evidence == "parts" and any(get_variant(v).fine for v in variants) else set()
    if detections != "gt":  # label boxes carry their viewpoints: neither the bank nor the classifier is read
        read |= {"detector_bank", "viewpoint_classifier"}
    if calibrated:
        read.add("score_calibration")
    read -= set(replaced)
    said = []
    if read & set(models.own) - {"score_calibration"}:  # a manifest lists what `train all` trained
        seen = trained_on(models, dataset.split_dir, frame_ids)
        if seen:
            said.append(f"{_share(seen, frame_ids)} those {models_dir} was trained on (e.g. {seen[0]}): "
                        f"{_figures(seen)} not held out")
    shipped = [name for name in FRAME_TRAINED if name in read and name not in models.own]
    seen = among_shipped_training_frames(dataset.image_path, frame_ids) if shipped else []
    if seen:
        names = [FRAME_TRAINED[n] for n in shipped]
        which = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
        said.append(f"{_share(seen, frame_ids)} the {len(shipped_training_frames())} the shipped {which} "
                    f"{'were' if len(names) > 1 else 'was'} trained on (e.g. {seen[0]}): {_figures(seen)} not held out")
    return said


def _share(seen: list[str], frame_ids: list[str]) -> str:
    """``"N of the M frames evaluated are among"``, the verb agreeing with N."""
    return f"{len(seen)} of the {len(frame_ids)} frames evaluated {'is' if len(seen) == 1 else 'are'} among"


def _figures(seen: list[str]) -> str:
    """``"their figures are"``, or ``"its figures are"`` of one frame."""
    return f"{'its' if len(seen) == 1 else 'their'} figures are"
