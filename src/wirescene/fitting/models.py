"""The trained artefacts a fit uses, as :class:`~wirescene.fitting.options.FitOptions`
carry them: their loaders (:func:`part_detector`, :func:`detector_bank`,
:func:`viewpoint_classifier`, :func:`load_shape_model`, :func:`shape_model_for`; each file
loaded once per version), a models directory (:func:`wirescene.core.resources.resolve_models`)
applied to the options, which of the files a run reads (:func:`model_files_read`), the files
checked before any fit, and the content fingerprint of those it reads (part of every resume
record, so that a retrained model is never mistaken for the one a record was fitted with, and
a file the run does not read changes nothing)."""

from __future__ import annotations

import dataclasses
from typing import Iterable

from wirescene.core.errors import InputError
from wirescene.core.resources import Models, cached_by_file, file_sha256, shipped_path
from wirescene.core.shape import DEFAULT_MODEL_PATH as SHIPPED_SHAPE_MODEL
from wirescene.core.shape import ShapeModel
from wirescene.core.shape import load_default as load_default_shape_model
from wirescene.fitting.options import FitOptions

__all__ = ["MODEL_FILES", "FINE_OPTIONS", "part_detector", "viewpoint_classifier", "load_shape_model",
           "shape_model_for", "detector_bank", "with_models", "model_files_read", "check_model_files",
           "reads_score_calibration", "models_fingerprint", "options_read"]

#: The artefacts a fit reads from a file that :class:`FitOptions` names (the field of the
#: same name; None: the shipped file): each an explicit option (``--parts-model``, ``--bank``,
#: ``--viewpoint-classifier``, ``--score-calibration``, ``--shape-model``) that wins over
#: a models directory's file. The occluded-part score is a number in the options instead.
MODEL_FILES: tuple[str, ...] = ("parts_model", "detector_bank", "viewpoint_classifier", "score_calibration",
                                "shape_model")

#: The options only the fine variants read, as ``--set`` names them (``STAGE`` for all of a
#: stage's, ``STAGE.FIELD``): the inference stage's (Algorithm 1 and the part evidence it
#: scores, ``inference.flip_evidence``; the coarse variants compute none) and the weight of
#: our own pre-detection's boxes in its objective, which replaces ``inference.box_weight``.
FINE_OPTIONS: tuple[str, ...] = ("inference", "predetect.box_weight")


@cached_by_file(maxsize=4)
def part_detector(path: str | None):
    """The part detectors at ``path`` (None: the shipped model), loaded once per version of the file."""
    from wirescene.parts.detector import PartDetector, load_default

    return load_default() if path is None else PartDetector.load(path)


@cached_by_file(maxsize=4)
def viewpoint_classifier(path: str | None):
    """The crop viewpoint classifier at ``path`` (None: the shipped one), loaded once per version of the file.

    Examples
    --------
    >>> classifier = viewpoint_classifier(None)  # the shipped one
    >>> classifier is viewpoint_classifier(None), classifier.weights.shape  # (features, 8 bins)
    (True, (1957, 8))
    """
    from wirescene.predetect.viewpoint_classifier import ViewpointClassifier, load_default_classifier

    return load_default_classifier() if path is None else ViewpointClassifier.load(path)


@cached_by_file(maxsize=4)
def load_shape_model(path: str | None = None) -> ShapeModel:
    """The shape model at ``path`` (None: the shipped one), loaded once per version of the file.

    Examples
    --------
    >>> import numpy as np
    >>> model = load_shape_model()  # the shipped one, loaded once
    >>> model is load_shape_model(), model.instantiate(np.zeros(5)).shape  # the mean car's 36 vertices (m)
    (True, (36, 3))
    """
    return load_default_shape_model() if path is None else ShapeModel.load(path)


def shape_model_for(options: "FitOptions") -> ShapeModel:
    """The shape model of ``options`` (:attr:`FitOptions.shape_model`), checked to have the
    components the fine stage searches (``inference.n_shape``): an
    :class:`~wirescene.core.errors.InputError` naming the file otherwise.

    Examples
    --------
    >>> shape_model_for(FitOptions()) is load_shape_model()
    True
    >>> from wirescene.infer.inference import InferenceOptions
    >>> shape_model_for(FitOptions(inference=InferenceOptions(n_shape=1000)))
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...components, the fine stage searches 1000 (--set inference.n_shape=N...
    """
    model = load_shape_model(options.shape_model)
    if model.n_components < options.inference.n_shape:
        raise InputError(f"shape model of {model.n_components} components, the fine stage searches "
                         f"{options.inference.n_shape} (--set inference.n_shape=N, N <= {model.n_components})",
                         path=options.shape_model or SHIPPED_SHAPE_MODEL)
    return model


@cached_by_file(maxsize=4)
def detector_bank(path: str | None):
    """The detector bank at ``path`` (None: the shipped one), loaded once per version of the file.

    Examples
    --------
    >>> from wirescene.predetect import load_default_bank
    >>> detector_bank(None) is load_default_bank()  # the shipped bank
    True
    """
    from wirescene.predetect import DetectorBank, load_default_bank

    return load_default_bank() if path is None else DetectorBank.load(path)


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


def model_files_read(options: FitOptions, *, fine: bool = True, own: bool = True,
                     evidence: str = "parts", viewpoints_given: bool = False) -> tuple[str, ...]:
    """The artefacts of :data:`MODEL_FILES` that fitting with ``options`` reads, in that
    order: the files :func:`check_model_files` loads and :func:`models_fingerprint` hashes.

    Parameters
    ----------
    options : FitOptions
        ``calibrate_scores``, ``predetect.min_car_probability`` and ``lifting.estimate_pitch``
        decide on the score calibration and the detector bank.
    fine : bool
        A fine variant is fitted: it reads the shape model and, on the part detectors'
        evidence, the part model. The coarse variants read neither.
    own : bool
        The boxes are our own pre-detection: the detector bank finds them and, with the crop
        viewpoint classifier, gives them their viewpoints; the verification reads the score
        calibration (``predetect.min_car_probability`` above 0). Other boxes (label files,
        detection files, the API's) may come without a viewpoint (no ``alpha``, or KITTI's
        ``-10``), which the fit then finds with the bank and the classifier on the image
        (``evidence="parts"``) or from the given evidence with the shape model (``"oracle"``):
        those files count as read, unless ``viewpoints_given``.
    evidence : {"parts", "oracle"}
        What the fine variants fit to (``wirescene eval --evidence``): the part detectors on
        the image, or given per-vertex evidence (synthetic scenes), which reads no part model.
    viewpoints_given : bool
        Of boxes not our own (``own`` False), every one is known to come with its viewpoint
        (the run's boxes read): neither the classifier nor, unless it reads the pitch off the
        boxes, the bank is read. A fingerprint, made before the boxes are read, counts them.

    Returns
    -------
    tuple of str
        Names of :data:`MODEL_FILES`.

    Examples
    --------
    >>> model_files_read(FitOptions())  # a fine variant on our own pre-detection
    ('parts_model', 'detector_bank', 'viewpoint_classifier', 'score_calibration', 'shape_model')
    >>> model_files_read(FitOptions(), fine=False, own=False)  # coarse variants on label boxes
    ('detector_bank', 'viewpoint_classifier', 'score_calibration')
    >>> model_files_read(FitOptions(calibrate_scores=False), fine=False, own=False, evidence="oracle")
    ('shape_model',)
    >>> model_files_read(FitOptions(), own=False, viewpoints_given=True)  # a fine variant on label boxes
    ('parts_model', 'score_calibration', 'shape_model')
    """
    if evidence not in ("parts", "oracle"):
        raise ValueError(f"evidence must be 'parts' or 'oracle', got {evidence!r}")
    unposed = not own and not viewpoints_given  # boxes that may come without a viewpoint
    # their viewpoints scored on the image by the bank and the classifier, or read off the given evidence
    on_image = own or (unposed and evidence == "parts")
    read = {
        "parts_model": fine and evidence == "parts",
        # the pitch read off each frame's boxes (lifting.estimate_pitch) takes the bank's ground prior
        "detector_bank": on_image or options.lifting.estimate_pitch,
        "viewpoint_classifier": on_image,
        "score_calibration": reads_score_calibration(options, own=own),
        "shape_model": fine or (unposed and evidence == "oracle"),
    }
    return tuple(name for name in MODEL_FILES if read[name])


def check_model_files(options: FitOptions, *, fine: bool = True, own: bool = True,
                      evidence: str = "parts") -> FitOptions:
    """``options``, once the model files a fit with them reads (:func:`model_files_read`, of
    ``fine``, ``own`` and ``evidence``) have been loaded (once per version of each file, so
    the fits reuse them; the shipped ones too, which are read anyway) and, for a ``fine``
    variant to be fitted, the shape model found to have the components the fine stage
    searches: a broken file is refused before any frame is fitted, not in the first frame's
    fit. A shape model named in ``options`` is checked even where it is not read.

    Raises
    ------
    InputError
        Naming the file: missing, corrupt, of another kind or format version, of arrays of
        other shapes, or (``fine``) a shape model of fewer components than
        ``options.inference.n_shape``.
    """
    from wirescene.fitting.confidence import load_score_calibration

    load = {
        "detector_bank": lambda: detector_bank(options.detector_bank),
        "viewpoint_classifier": lambda: viewpoint_classifier(options.viewpoint_classifier),
        "score_calibration": lambda: load_score_calibration(options.score_calibration),
        "parts_model": lambda: part_detector(options.parts_model),
        "shape_model": lambda: shape_model_for(options) if fine else load_shape_model(options.shape_model),
    }
    read = model_files_read(options, fine=fine, own=own, evidence=evidence)
    for name in load:  # the bank first, the shape model last, as a fit reads them
        if name in read:
            load[name]()
    if "shape_model" not in read and options.shape_model is not None:
        load_shape_model(options.shape_model)
    return options


def reads_score_calibration(options: FitOptions, *, own: bool = True) -> bool:
    """Whether a fit with ``options`` reads the score calibration: for the confidences
    (``calibrate_scores``) or for the verification of our own boxes (``own``, with
    ``predetect.min_car_probability`` above 0).

    Examples
    --------
    >>> from wirescene.fitting.options import PredetectOptions
    >>> reads_score_calibration(FitOptions())
    True
    >>> reads_score_calibration(FitOptions(calibrate_scores=False)), reads_score_calibration(
    ...     FitOptions(calibrate_scores=False), own=False)  # only our own boxes are verified
    (True, False)
    >>> reads_score_calibration(FitOptions(calibrate_scores=False, predetect=PredetectOptions(min_car_probability=0)))
    False
    """
    return options.calibrate_scores or (own and options.predetect.min_car_probability > 0)


def models_fingerprint(options: FitOptions, *, fine: bool = True, own: bool = True,
                       evidence: str = "parts", read: Iterable[str] | None = None) -> dict[str, str]:
    """``{artefact: SHA-256}`` of the files a fit with ``options`` reads
    (:func:`model_files_read`, of ``fine``, ``own`` and ``evidence``; ``read``: those names,
    where the run's boxes told them): a file it does not read is left out, so that replacing
    it changes nothing. The occluded-part score is a number in the options themselves.

    Examples
    --------
    >>> sorted(models_fingerprint(FitOptions()))
    ['detector_bank', 'parts_model', 'score_calibration', 'shape_model', 'viewpoint_classifier']
    >>> sorted(models_fingerprint(FitOptions(), fine=False, own=False))  # coarse variants on label boxes
    ['detector_bank', 'score_calibration', 'viewpoint_classifier']
    """
    read = model_files_read(options, fine=fine, own=own, evidence=evidence) if read is None else read
    return {name: file_sha256(getattr(options, name) or shipped_path(name)) for name in read}


def options_read(options: FitOptions, *, fine: bool = True, own: bool = True, evidence: str = "parts") -> dict:
    """``dataclasses.asdict(options)`` without the fields of the model files a fit with them
    does not read (:func:`model_files_read`), nor, unless it fits our own pre-detections
    (``own``), the options of that pre-detection (``predetect``), nor, unless it fits a fine
    variant (``fine``), the options only those read (:data:`FINE_OPTIONS`): the options as a
    resume record holds them, so that naming another such file or option changes nothing.

    Examples
    --------
    >>> sorted(set(MODEL_FILES) & set(options_read(FitOptions(shape_model="mine.npz"), fine=False, own=False)))
    ['detector_bank', 'score_calibration', 'viewpoint_classifier']
    >>> "predetect" in options_read(FitOptions(), own=False), "predetect" in options_read(FitOptions())
    (False, True)
    >>> coarse = options_read(FitOptions(), fine=False)  # coarse variants on our own pre-detection
    >>> "inference" in coarse, sorted(coarse["predetect"])
    (False, ['min_car_probability', 'smallest_car', 'threshold', 'upsample'])
    """
    read = model_files_read(options, fine=fine, own=own, evidence=evidence)
    unread = {name for name in MODEL_FILES if name not in read}
    unread |= set() if own else {"predetect"}
    unread |= set() if fine else set(FINE_OPTIONS)
    # a stage's fields are one level down (predetect.box_weight); the others sit at the top (seed)
    return {k: {f: x for f, x in v.items() if f"{k}.{f}" not in unread} if isinstance(v, dict) else v
            for k, v in dataclasses.asdict(options).items() if k not in unread}
