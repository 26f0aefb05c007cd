"""The trained artefacts a fit uses, as :class:`~wirescene.fitting.pipeline.FitOptions`
carry them: a models directory (:func:`wirescene.core.resources.resolve_models`) applied
to the options, the files checked before any fit, and the content fingerprint of what the
options load (part of every resume record, so that a retrained model is never mistaken
for the one a record was fitted with)."""

from __future__ import annotations

import dataclasses

from wirescene.core.resources import Models, file_sha256, shipped_path
from wirescene.fitting.pipeline import FitOptions

__all__ = ["MODEL_FILES", "with_models", "check_model_files", "reads_score_calibration", "models_fingerprint"]

#: The artefacts a fit reads from a file that :class:`FitOptions` names (the field of the
#: same name; None: the shipped file): each an explicit option (``--parts-model``, ``--bank``,
#: ``--viewpoint-classifier``, ``--score-calibration``, ``--shape-model``) that wins over
#: a models directory's file. The occluded-part score is a number in the options instead.
MODEL_FILES: tuple[str, ...] = ("parts_model", "detector_bank", "viewpoint_classifier", "score_calibration",
                                "shape_model")


def with_models(options: FitOptions, models: Models) -> FitOptions:
    """``options`` with the artefacts of ``models``.

    Parameters
    ----------
    options : FitOptions
        A file of :data:`MODEL_FILES` set in it (``--parts-model``, ``--bank``, ...) is
        kept: an explicit file wins over the directory's.
    models : Models
        Its part model, detector bank, crop viewpoint classifier, score calibration, shape
        model and occluded-part score ``c`` replace the shipped ones; what it lacks stays
        shipped.

    Examples
    --------
    >>> from wirescene.core.resources import SHIPPED
    >>> with_models(FitOptions(shape_model="mine.npz"), SHIPPED).shape_model
    'mine.npz'
    """
    if models.root is None:
        return options
    changes = {name: models.file(name, given=getattr(options, name)) for name in MODEL_FILES}
    if "occlusion" in models.own:
        from wirescene.infer.occluded_score import load_occluded_score

        c = load_occluded_score(models.path("occlusion"))
        changes["inference"] = dataclasses.replace(options.inference, occluded_score=c)
    return dataclasses.replace(options, **changes)


def check_model_files(options: FitOptions, *, fine: bool = True) -> FitOptions:
    """``options``, once the model files they name have been loaded (once per version of
    each file, so the fits reuse them; the shipped ones too, which are read anyway) and,
    for a ``fine`` variant to be fitted, the part model read and the shape model found to
    have the components the fine stage searches: a broken file is refused before any
    frame is fitted, not in the first frame's fit.

    Raises
    ------
    InputError
        Naming the file: missing, corrupt, of another kind or format version, of arrays of
        other shapes, or (``fine``) a shape model of fewer components than
        ``options.inference.n_shape``.
    """
    from wirescene.fitting.confidence import load_score_calibration
    from wirescene.fitting.pipeline import (
        detector_bank,
        load_shape_model,
        part_detector,
        shape_model_for,
        viewpoint_classifier,
    )

    detector_bank(options.detector_bank)
    viewpoint_classifier(options.viewpoint_classifier)
    if reads_score_calibration(options):
        load_score_calibration(options.score_calibration)
    if fine:
        part_detector(options.parts_model)
        shape_model_for(options)
    elif options.shape_model is not None:
        load_shape_model(options.shape_model)
    return options


def reads_score_calibration(options: FitOptions) -> bool:
    """Whether a fit with ``options`` reads the score calibration: for the confidences
    (``calibrate_scores``) or for the verification of our own boxes
    (``predetect.min_car_probability`` above 0).

    Examples
    --------
    >>> from wirescene.fitting.pipeline import PredetectOptions
    >>> reads_score_calibration(FitOptions())
    True
    >>> reads_score_calibration(FitOptions(calibrate_scores=False, predetect=PredetectOptions(min_car_probability=0)))
    False
    """
    return options.calibrate_scores or options.predetect.min_car_probability > 0


def models_fingerprint(options: FitOptions) -> dict[str, str]:
    """``{artefact: SHA-256}`` of the files a fit with ``options`` reads: part model,
    detector bank, crop viewpoint classifier, shape model and (when it is read,
    :func:`reads_score_calibration`) score calibration. The occluded-part score is a number
    in the options themselves.

    Examples
    --------
    >>> sorted(models_fingerprint(FitOptions()))
    ['detector_bank', 'parts_model', 'score_calibration', 'shape_model', 'viewpoint_classifier']
    """
    return {name: file_sha256(getattr(options, name) or shipped_path(name)) for name in MODEL_FILES
            if name != "score_calibration" or reads_score_calibration(options)}
