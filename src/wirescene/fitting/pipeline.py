"""The per-frame pipeline, written once: detect -> parts -> lift -> infer -> estimate.

:func:`fit_frame` is the only place where the stages are composed. The Python API
(:func:`wirescene.fit`), ``wirescene fit``, ``wirescene demo`` and ``wirescene eval``
(every frame, in any process) all call it, so they cannot drift apart. It does no file
I/O: inputs are arrays and typed objects, outputs a :class:`FrameFit`.
"""

from __future__ import annotations

import numbers
import time
from dataclasses import dataclass, field, replace
from typing import Iterable, Mapping

import numpy as np

from wirescene.core.boxes import clip_boxes
from wirescene.core.camera import Camera
from wirescene.core.errors import ArgumentError, InputError, check_shape
from wirescene.core.groundplane import KITTI_MOUNT, Mount
from wirescene.core.resources import cached_by_file
from wirescene.core.settings import option, stage_field
from wirescene.core.shape import DEFAULT_MODEL_PATH as SHIPPED_SHAPE_MODEL
from wirescene.core.shape import ShapeModel
from wirescene.core.shape import load_default as load_default_shape_model
from wirescene.core.types import Detections, SceneEstimate
from wirescene.fitting.confidence import apply_confidence, keep_likely_cars, load_score_calibration
from wirescene.fitting.variants import Variant, get_variant
from wirescene.infer.evidence import part_evidence, viewpoint_from_evidence
from wirescene.infer.inference import InferenceOptions, estimate_from_refined, refine_particles
from wirescene.infer.likelihood import PartEvidence
from wirescene.lift import (
    MAX_HYPOTHESES,
    LiftingOptions,
    LiftingTable,
    lift_table,
    plane_vote_weights,
    select_particles,
)
from wirescene.predetect.bank import MIN_SMALLEST_CAR, smallest_car_search
from wirescene.predetect.enlarge import add_enlarged, boxes_back, frame_passes

#: Largest enlargement of ``PredetectOptions.upsample``: 3 makes a KITTI frame 9 times the pixels.
MAX_UPSAMPLE = 3.0


@dataclass(frozen=True)
class PredetectOptions:
    """Options of our own pre-detection as the fit uses it (stage 1), and of how the fit
    treats its boxes: their weight in the fine objective and their verification. How each
    default was chosen: ``benchmarks/RESULTS.md``.

    Examples
    --------
    >>> PredetectOptions()
    PredetectOptions(threshold=0.3, min_car_probability=0.5, box_weight=30.0, smallest_car=0.0, upsample=1.5)
    >>> FitOptions().with_settings({"predetect.threshold": "0.5"}).predetect.threshold
    0.5
    """

    # Below the bank's own 2D operating point (0.5): the fit verifies every box it is given.
    threshold: float = option(0.3, cli="detection-threshold",
                              help="Score threshold of our own pre-detection for the fit (the bank's calibrated "
                                   "probability of a car).")
    # The score calibration's car model on the detection score, the fit's objective and the box height.
    min_car_probability: float = option(0.5, maximum=1.0,
                                        help="Drop the fitted cars of our own pre-detection whose probability "
                                             "of standing on a car is below this (0: keep all).")
    # The bank's boxes miss the car's outline by more than labelled ones: the fine stage leans on them less.
    box_weight: float = option(30.0, cli="own-box-weight",
                               help="Weight of our own pre-detection's boxes in the fine objective (boxes from files "
                                    "or the API take the inference stage's --box-weight).")
    # Off: held out (upsample 1), 16.7 px gave 7 more true positives, 8 fewer cars within 1 m, 1.7x the time (RESULTS).
    smallest_car: float = option(0.0, minimum=MIN_SMALLEST_CAR, zero="the bank's own",
                                 help="Smallest car height (px) our own pre-detection searches, its pyramid "
                                      "upsampled to reach it, the enlarged image's too (--upsample; 0: the bank's "
                                      "own, 25 px, and the enlarged image's below it; at least 10).")
    # Held out on {0, 1}, where it was chosen: `full` 7 more true positives, 8 more within 1 m, 2 more false (RESULTS).
    upsample: float = option(1.5, minimum=1.0, maximum=MAX_UPSAMPLE,
                             help="Also detect our own cars on the image enlarged by this factor, 1 to 3 (Lanczos; "
                                  "up to a 4K frame's pixels), at its pyramid levels finer than the image's, adding "
                                  "the small, far cars the image as it is misses (2.3x the pre-detection's time at "
                                  "1.5; 1: none).")


@dataclass(frozen=True)
class FitOptions:
    """Options of every stage of :func:`fit_frame`, with the run's seed.

    Examples
    --------
    >>> options = FitOptions()
    >>> options.seed, options.calibrate_scores, options.inference.iterations, options.parts_model  # None: shipped
    (0, True, 12, None)
    >>> from dataclasses import replace
    >>> replace(options, seed=3, lifting=replace(options.lifting, n_particles=20)).lifting.n_particles
    20
    """

    lifting: LiftingOptions = field(default_factory=LiftingOptions)
    inference: InferenceOptions = field(default_factory=InferenceOptions)
    predetect: PredetectOptions = field(default_factory=PredetectOptions)
    seed: int = 0
    # Write calibrated confidences (wirescene.fitting.confidence) as the cars' scores;
    # False keeps the pre-detection scores (used to collect the calibration's own data).
    calibrate_scores: bool = True
    # Part detector file (None: the shipped model), e.g. a cross-validation fold's model
    # so that real frames are scored by a model that never saw their drive.
    parts_model: str | None = None
    # Detector bank file for our own pre-detection (None: the shipped bank).
    detector_bank: str | None = None
    # Crop viewpoint classifier file for boxes given without a viewpoint (None: the shipped one).
    viewpoint_classifier: str | None = None
    # Score calibration file of the confidences and of the verification of our own boxes
    # (None: the shipped one), e.g. one of `wirescene train scores` on the user's own runs.
    score_calibration: str | None = None
    # Shape model file of the fine variants' wireframes (None: the shipped one), e.g. one of
    # `wirescene train shape` on other CAD cars.
    shape_model: str | None = None

    def with_settings(self, settings: Mapping[str, object] | None, *, combined: bool = True) -> "FitOptions":
        """These options with ``{"STAGE.FIELD": value}`` changed, ``STAGE`` one of
        :data:`STAGES` (``lifting``, ``inference``, ``predetect``): the mapping ``--set`` and the named
        options of ``eval`` / ``predict`` / ``fit`` and the API's ``settings`` share.
        String values are parsed as the field's type; an unknown stage or field is a
        ``ValueError`` naming what exists, and so are options that break a limit together
        (:meth:`combined_problem`; ``combined=False``: left to the caller).

        Examples
        --------
        >>> FitOptions().with_settings({"inference.box_weight": "50", "lifting.road_prior": 0}).inference.box_weight
        50.0
        """
        from wirescene.core.settings import replace_fields

        by_stage: dict[str, dict[str, object]] = {}
        for name, value in (settings or {}).items():
            stage, dot, key = name.partition(".") if isinstance(name, str) else ("", "", "")
            if not dot or stage not in STAGES:
                raise ValueError(f"{name!r}: settings are STAGE.FIELD, STAGE one of {', '.join(STAGES)}")
            by_stage.setdefault(stage, {})[key] = value
        changed = {stage: replace_fields(getattr(self, stage), values, scope=stage) for stage, values in by_stage.items()}
        out = replace(self, **changed)
        problem = out.combined_problem() if combined else None
        if problem is not None:
            raise ValueError(problem)
        return out

    def combined_problem(self) -> str | None:
        """What the stages' options break together, or None: more scene particles (those the
        plane grid holds) times fine-stage samples than :data:`~wirescene.lift.MAX_HYPOTHESES`,
        whose memory grows with both (some 9 kB a particle, car and sample).

        Examples
        --------
        >>> FitOptions().combined_problem() is None
        True
        >>> FitOptions(lifting=LiftingOptions(n_particles=1000, pitch_step=0.05),
        ...            inference=InferenceOptions(samples=60)).combined_problem()
        'lifting.n_particles x inference.samples = 1,000 x 60 = 60,000 hypotheses a car and iteration, at most 50,000 (memory grows with them): fewer particles or samples'
        """
        lifting, inference = self.lifting, self.inference
        if not all(isinstance(v, numbers.Integral) for v in (lifting.n_particles, inference.samples)):
            return None  # the fields' own checks name what is wrong
        try:
            particles = min(lifting.n_particles, lifting.grid_planes())  # the coarse stage keeps one a plane at most
        except (TypeError, ValueError, ZeroDivisionError, OverflowError):
            return None
        n = particles * inference.samples
        if n <= MAX_HYPOTHESES:
            return None
        planes = " (one a plane of the grid)" if particles < lifting.n_particles else ""
        return (f"lifting.n_particles x inference.samples = {particles:,}{planes} x {inference.samples:,} = {n:,} "
                f"hypotheses a car and iteration, at most {MAX_HYPOTHESES:,} (memory grows with them): fewer "
                "particles or samples")

    def checked(self) -> "FitOptions":
        """These options, once every stage's numbers are checked against their fields'
        kinds and limits (:func:`wirescene.core.settings.check_fields`) and the seed is a
        non-negative integer; an :class:`~wirescene.core.errors.ArgumentError` naming the
        field otherwise (options built directly bypass :meth:`with_settings`' checks).

        Examples
        --------
        >>> FitOptions(lifting=LiftingOptions(n_particles=0)).checked()
        Traceback (most recent call last):
        ...
        wirescene.core.errors.ArgumentError: options: lifting.n_particles must be at least 1, got 0
        """
        from wirescene.core.settings import check_fields

        try:
            for stage in STAGES:
                check_fields(getattr(self, stage), scope=stage)
        except ValueError as exc:
            raise ArgumentError("options", str(exc)) from None
        problem = self.combined_problem()
        if problem is not None:
            raise ArgumentError("options", problem)
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral) or self.seed < 0:
            raise ArgumentError("options", f"seed must be a non-negative integer, got {self.seed!r}")
        return self


#: The stages whose options :meth:`FitOptions.with_settings` reaches, by attribute of :class:`FitOptions`.
STAGES: tuple[str, ...] = ("lifting", "inference", "predetect")


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


@dataclass
class FrameFit:
    """What :func:`fit_frame` produced for one image.

    Attributes
    ----------
    detections : Detections
        The pre-detections the variants were fitted to, with unknown viewpoints
        completed by the detector bank (:func:`complete_viewpoints`; from the part evidence
        when no image is given).
    estimates : dict of str to SceneEstimate
        One estimate per requested variant, in the requested order.
    evidence : PartEvidence or None
        The part evidence the fine variants used (None if no variant needed it).

    Examples
    --------
    >>> P = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> camera = Camera(P, (1242, 375))
    >>> dets = Detections([[300, 180, 520, 300]], 0.9, 0.0)  # a box and its viewpoint (alpha 0)
    >>> options = FitOptions(lifting=LiftingOptions(n_particles=20))
    >>> fit = fit_frame(camera, dets, ["coarse", "coarse+gp"], options=options)
    >>> list(fit.estimates), fit.evidence is None  # coarse variants need no part evidence
    (['coarse', 'coarse+gp'], True)
    """

    detections: Detections
    estimates: dict[str, SceneEstimate]
    evidence: PartEvidence | None = None


def _variant(v: str | Variant) -> Variant:
    return get_variant(v) if isinstance(v, str) else v


def needs_evidence(detections: Detections, variants: Iterable[str | Variant]) -> bool:
    """Whether :func:`fit_frame` needs part evidence or the image for these detections:
    a fine variant, or a detection without a viewpoint (scored by the detector bank on the
    image, or taken from the part evidence when only that is given).

    Examples
    --------
    >>> dets = Detections([[300, 180, 520, 300]], 0.9, 0.0)
    >>> needs_evidence(dets, ["coarse", "coarse+gp"]), needs_evidence(dets, ["fg"])
    (False, True)
    >>> needs_evidence(Detections([[300, 180, 520, 300]], 0.9, np.nan), ["coarse"])  # a viewpoint to find
    True
    """
    if len(detections) == 0:
        return False
    return any(_variant(v).fine for v in variants) or not np.all(np.isfinite(detections.alpha))


def complete_viewpoints(camera: Camera, detections: Detections, image: np.ndarray, *, bank=None,
                        classifier=None, pyramid: list | None = None, responses: dict | None = None,
                        mount: Mount = KITTI_MOUNT) -> Detections:
    """Detections whose unknown viewpoints (NaN ``alpha``, e.g. boxes of an external
    detector) are scored inside each box by the detector bank's templates and the crop
    viewpoint classifier, with the camera's road prior
    (:func:`wirescene.predetect.box_viewpoints.box_viewpoints`, all unknown boxes of the frame
    at once: cars of one row agree); known viewpoints are kept.

    Parameters
    ----------
    camera : Camera
    detections : Detections
    image : (H, W, 3) uint8 array
    bank : DetectorBank, optional
        Default: the shipped bank.
    classifier : ViewpointClassifier, optional
        Default: the shipped one.
    pyramid : list of (float, ndarray), optional
        The image's :func:`~wirescene.predetect.bank.bank_pyramid` if already computed.
    responses : dict, optional
        The bank's template response maps on ``pyramid`` (``detect_cars(responses=)``), if
        already computed.
    mount : Mount, optional
        The camera's height above the road and pitch down from it
        (:class:`~wirescene.core.groundplane.Mount`; ``LiftingOptions.mount``), for the road
        prior.

    Returns
    -------
    Detections
        The same boxes and scores, every ``alpha`` finite.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> P = np.array([[720.0, 0, 48, 0], [0, 720.0, 20, 0], [0, 0, 1, 0]])
    >>> dets = Detections(np.array([[10.0, 20.0, 70.0, 50.0]]), np.ones(1), np.full(1, np.nan))
    >>> out = complete_viewpoints(Camera(P, (96, 64)), dets, np.zeros((64, 96, 3), np.uint8))
    >>> bool(np.isfinite(out.alpha).all())
    True
    """
    from wirescene.predetect.box_viewpoints import box_viewpoints

    unknown = np.flatnonzero(~np.isfinite(detections.alpha))
    if len(unknown) == 0:
        return detections
    bank = detector_bank(None) if bank is None else bank
    classifier = viewpoint_classifier(None) if classifier is None else classifier
    alpha = detections.alpha.copy()
    alpha[unknown] = box_viewpoints(bank, image, detections.boxes[unknown], camera=camera, classifier=classifier,
                                    pyramid=pyramid, responses=responses, mount=mount)
    return Detections(detections.boxes, detections.scores, alpha, detections.source)


def detections_above(camera: Camera | None, image: np.ndarray, found: Detections, threshold: float, *, bank,
                     classifier=None, pyramid: list | None = None, responses: dict | None = None,
                     mount: Mount = KITTI_MOUNT) -> Detections:
    """The bank's detections ``found`` of ``image`` (every score down to ``threshold`` at least)
    above ``threshold``, each box that the fit's own pre-detection also keeps (above
    ``PredetectOptions.threshold``, for a calibrated bank) with the viewpoint the fit gives it:
    cars of one row agree, so a box's viewpoint depends on the boxes the rule reads beside it
    (:func:`detect_own`; ``classifier``, ``pyramid``, ``responses`` and ``mount`` as there)."""
    keep = found.subset(found.scores > threshold)
    if camera is None:
        return keep
    fit_threshold = PredetectOptions().threshold
    if bank.calibration is None:  # margins, not probabilities: no common scale with the fit's threshold
        return detect_own(camera, image, bank=bank, classifier=classifier, detections=keep, pyramid=pyramid,
                          responses=responses, mount=mount)
    read = detect_own(camera, image, bank=bank, classifier=classifier,
                      detections=found.subset(found.scores > min(threshold, fit_threshold)), pyramid=pyramid,
                      responses=responses, mount=mount)
    out = read.subset(read.scores > threshold)
    if threshold < fit_threshold:  # the rule read more boxes than the fit's: the fit's set decides its own boxes
        fit = detect_own(camera, image, bank=bank, classifier=classifier,
                         detections=found.subset(found.scores > fit_threshold), pyramid=pyramid, responses=responses,
                         mount=mount)
        alpha = out.alpha.copy()
        alpha[out.scores > fit_threshold] = fit.alpha
        out = Detections(out.boxes, out.scores, alpha, out.source)
    return out


#: Score down to which the templates' boxes, found without the priors, tell a frame's pitch
#: (:func:`detect_own` with ``estimate_pitch``): below the fit's threshold, as the ground
#: term the priors would add is missing; each box weighs its score.
PITCH_THRESHOLD = 0.1


def bounded_pitch(pitch: float) -> float:
    """``pitch`` (degrees) within ``LiftingOptions.camera_pitch``'s bounds, which a pitch read
    off boxes may pass (the grid reaches 15 deg past the one told).

    Examples
    --------
    >>> bounded_pitch(50.0), bounded_pitch(-0.1)
    (45.0, -0.1)
    """
    bounds = stage_field(LiftingOptions, "camera_pitch").metadata
    return min(max(float(pitch), bounds["minimum"]), bounds["maximum"])


def frame_pitch(camera: Camera, detections: Detections, *, bank, told: Mount = KITTI_MOUNT,
                weighted: bool = False) -> float:
    """The camera's pitch read off a frame's boxes
    (:func:`~wirescene.predetect.geometry.pitch_from_boxes` with ``bank``'s ground prior,
    about ``told``; ``weighted``: each box by its score, a probability of a car), within
    ``LiftingOptions.camera_pitch``'s bounds; ``told.pitch`` for a bank without a ground prior.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> frame_pitch(camera, Detections.empty("none"), bank=detector_bank(None))  # no box: the pitch told
    0.0
    """
    from wirescene.predetect.geometry import pitch_from_boxes

    prior = bank.meta.get("ground_prior")
    if not prior:
        return float(told.pitch)
    weights = np.clip(detections.scores, 0.0, 1.0) if weighted else None
    return bounded_pitch(pitch_from_boxes(prior, camera, detections.boxes, weights=weights, told=told))


def image_pitch_likelihood(camera: Camera, image: np.ndarray, *, bank, told: Mount = KITTI_MOUNT,
                           pyramid: list | None = None, min_height: float | None = None) -> tuple[np.ndarray, int]:
    """``((301,) log-likelihood, boxes)`` of the camera's pitch
    (:func:`~wirescene.predetect.geometry.pitch_log_likelihood` on the grid about ``told``) by
    the boxes ``bank``'s templates find in ``image`` without the priors, which need the pitch,
    down to :data:`PITCH_THRESHOLD`, each weighed by its score, and how many boxes it read;
    zeros and 0 for a bank without a ground prior. Frames of one rig add their
    log-likelihoods (:func:`rig_pitch`, ``wirescene pitch``); ``pyramid`` and ``min_height`` as in
    :func:`~wirescene.predetect.bank.detect_cars`.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 48, 0], [0, 720.0, 32, 0], [0, 0, 1, 0]]), (96, 64))
    >>> likelihood, boxes = image_pitch_likelihood(camera, np.zeros((64, 96, 3), np.uint8), bank=detector_bank(None))
    >>> likelihood.shape, boxes  # a blank image: no box, no evidence
    ((301,), 0)
    """
    from wirescene.predetect import detect_cars
    from wirescene.predetect.geometry import pitch_grid, pitch_log_likelihood

    prior = bank.meta.get("ground_prior")
    if not prior:  # no prior to read the pitch with: no detection pass spent on it
        return np.zeros(len(pitch_grid(told=told))), 0
    raw = detect_cars(image, bank=bank, threshold=PITCH_THRESHOLD, pyramid=pyramid, min_height=min_height)
    weights = np.clip(raw.scores, 0.0, 1.0)
    return pitch_log_likelihood(prior, camera, raw.boxes, weights=weights, told=told), len(raw)


def rig_pitch(likelihoods, *, told: Mount = KITTI_MOUNT) -> float:
    """The pitch (degrees) that the frames of one rig tell together: the sum of their
    :func:`image_pitch_likelihood` (read about ``told``, at its height) under the prior about
    ``told.pitch`` (:func:`~wirescene.predetect.geometry.pitch_of`), within
    ``LiftingOptions.camera_pitch``'s bounds; ``told.pitch`` without evidence.

    Examples
    --------
    >>> rig_pitch([np.zeros(301), np.zeros(301)], told=Mount(1.65, 2.5))
    2.5
    """
    from wirescene.predetect.geometry import pitch_of

    return bounded_pitch(pitch_of(np.sum(np.asarray(likelihoods, float), axis=0), told=told))


def image_mount(camera: Camera, image: np.ndarray, *, bank, told: Mount = KITTI_MOUNT, pyramid: list | None = None,
                min_height: float | None = None) -> Mount:
    """``told`` with the pitch read off the boxes ``bank``'s templates find in ``image``
    without the priors, which need the pitch (:func:`image_pitch_likelihood`, within
    ``LiftingOptions.camera_pitch``'s bounds; ``told`` for a bank without a ground prior);
    ``pyramid`` and ``min_height`` as in :func:`~wirescene.predetect.bank.detect_cars`."""
    if not bank.meta.get("ground_prior"):  # no prior to read the pitch with: the mount told, as it is
        return told
    likelihood, _ = image_pitch_likelihood(camera, image, bank=bank, told=told, pyramid=pyramid, min_height=min_height)
    return Mount(told.height, rig_pitch([likelihood], told=told))


def frame_mount(camera: Camera | None, image: np.ndarray, *, bank, told: Mount = KITTI_MOUNT,
                estimate_pitch: bool = False, smallest_car: float | None = None,
                pyramid: list | None = None) -> tuple[list | None, Mount]:
    """``(pyramid, mount)`` of a frame before its detection passes: with ``estimate_pitch`` and
    a camera, the image's feature pyramid for its ``smallest_car`` (or ``pyramid``, given) and
    ``told`` with the pitch read off its boxes (:func:`image_mount`); else ``(pyramid, told)``
    as given. Every pass of the frame then takes that mount (the enlarged image's too, whose
    pyramid holds its finest levels only: :func:`~wirescene.predetect.enlarge.frame_passes`).

    Examples
    --------
    >>> frame_mount(None, np.zeros((64, 96, 3), np.uint8), bank=detector_bank(None), estimate_pitch=True)
    (None, Mount(height=1.65, pitch=0.0))
    """
    if not estimate_pitch or camera is None:
        return pyramid, told
    from wirescene.predetect.bank import bank_pyramid

    min_height, max_scale = smallest_car_search(bank, smallest_car)
    pyramid = bank_pyramid(bank, image, max_scale=max_scale) if pyramid is None else pyramid
    return pyramid, image_mount(camera, image, bank=bank, told=told, pyramid=pyramid, min_height=min_height)


def detect_own(camera: Camera | None, image: np.ndarray, *, bank=None, classifier=None,
               detections: Detections | None = None, threshold: float | None = None, pyramid: list | None = None,
               responses: dict | None = None, smallest_car: float | None = None, mount: Mount = KITTI_MOUNT,
               estimate_pitch: bool = False, upsample: float = 1.0) -> Detections:
    """Our own pre-detection (stage 1): the detector bank's cars at its threshold
    (:func:`wirescene.predetect.detect_cars`, with the camera), each box's viewpoint then
    chosen as for the boxes of any other detector (:func:`complete_viewpoints`: the bank's
    templates inside the box, the crop classifier and the road prior, every box of the frame
    at once so that cars of one row agree). Held out by drive, that rule puts 84.7% of the 189
    cars the bank finds at 0.3 within 45 deg, the detector's own choice 83.1%
    (``benchmarks/RESULTS.md``). Without a camera (``None``) the detector's own
    viewpoints stay. ``image``, ``bank`` and ``classifier`` as in :func:`complete_viewpoints`;
    ``detections``: the bank's detections of ``image`` if already made (e.g. at another
    threshold), with ``responses``, the response maps (``detect_cars(responses=)``) they were
    made from, if kept, for the viewpoint rule to read; ``pyramid``: the image's
    :func:`~wirescene.predetect.bank.bank_pyramid` if already computed (read by the detection
    and the rule); ``threshold``: the bank's score threshold (None: its own, the 2D
    operating point); ``smallest_car``: the smallest car height searched (px; None or 0: the
    bank's own), the pyramid's largest scale moved so that the bank's smallest templates reach
    it; ``mount``: the camera's height above the road and pitch down from it
    (:class:`~wirescene.core.groundplane.Mount`; ``LiftingOptions.mount``), for the ground and
    traffic priors learned at KITTI's level rig; ``estimate_pitch``: the priors read the
    camera's pitch off the boxes the templates find without them (:func:`frame_pitch` about
    ``mount``'s; ``LiftingOptions.estimate_pitch``; :func:`frame_mount`); ``upsample``: the
    detection and the rule also run on the image enlarged by this factor, at its pyramid's
    levels finer than the image's (:func:`~wirescene.predetect.enlarge.frame_passes`;
    ``PredetectOptions.upsample``), whose cars that no box of ``image`` covers are added, their
    boxes brought back to ``image``'s pixels (:func:`~wirescene.predetect.enlarge.add_enlarged`;
    with ``detections`` given, nothing is detected and it is not read; the passes:
    :func:`own_detections`). Returns the bank's boxes and calibrated scores with the rule's
    viewpoints.

    Examples
    --------
    >>> import numpy as np
    >>> detect_own(None, np.zeros((64, 96, 3), np.uint8)).boxes.shape
    (0, 4)
    """
    bank = detector_bank(None) if bank is None else bank
    if detections is None:
        return own_detections(camera, image, bank=bank, classifier=classifier, threshold=threshold, upsample=upsample,
                              smallest_car=smallest_car, pyramid=pyramid, mount=mount, estimate_pitch=estimate_pitch)
    if camera is None or not len(detections):
        return detections
    unknown = Detections(detections.boxes, detections.scores, np.full(len(detections), np.nan), detections.source)
    return complete_viewpoints(camera, unknown, image, bank=bank, classifier=classifier, pyramid=pyramid,
                               responses=responses, mount=mount)


def own_detections(camera: Camera | None, image: np.ndarray, *, bank=None, classifier=None,
                   threshold: float | None = None, fit_viewpoints: bool = False, return_all: bool = False,
                   viewpoints: bool = True, upsample: float = 1.0, smallest_car: float | None = None,
                   pyramid: list | None = None, mount: Mount = KITTI_MOUNT, estimate_pitch: bool = False,
                   cross_view_nms: float | None = 0.3, source: str = "bank", seconds: list | None = None):
    """Our own pre-detection's passes over a frame, chained once for :func:`detect_own` (the
    fit's and the evaluation's), :func:`wirescene.detect` and the ``detect`` command: one
    camera mount for every pass (:func:`frame_mount`), the passes of
    :func:`~wirescene.predetect.enlarge.frame_passes` (the image as it is and, with
    ``upsample``, enlarged), on each the detector bank (:func:`bank_pass`) and the box rule's
    viewpoints, the enlarged image's boxes brought back to the image's pixels
    (:func:`~wirescene.predetect.enlarge.boxes_back`) and the cars it adds
    (:func:`~wirescene.predetect.enlarge.add_enlarged`).

    Parameters
    ----------
    camera : Camera or None
        For the bank's priors and the box rule (None: neither, the detector's own viewpoints).
    image : (H, W, 3) uint8 array
    bank, classifier : DetectorBank, ViewpointClassifier, optional
        As in :func:`complete_viewpoints`.
    threshold : float, optional
        Keep the boxes scoring above it (None: the bank's own, its 2D operating point).
    fit_viewpoints : bool
        Keep the boxes above ``threshold`` of the fit's own pre-detection, whatever the
        threshold, for a calibrated bank: the passes read down to the lower of ``threshold``
        and the fit's (``PredetectOptions.threshold``), each box the fit keeps takes the fit's
        viewpoint (:func:`detections_above`) and the enlarged image's cars are added at the
        fit's threshold. False: the passes read at ``threshold`` and the rule reads every box
        found (:func:`detect_own`'s: the fit's own at its threshold).
    return_all : bool
        The passes keep every score (:func:`bank_pass`), returned too with the detector's own
        viewpoints (e.g. for AP); with ``fit_viewpoints`` only.
    viewpoints : bool
        The boxes kept take the box rule's viewpoints (False: the detector's own; no response
        maps kept).
    upsample, smallest_car, pyramid, mount, estimate_pitch
        As in :func:`detect_own`.
    cross_view_nms : float or None
        As in :func:`~wirescene.predetect.detect_cars`.
    source : str
        The detections' ``source``.
    seconds : list, optional
        Receives the seconds the detection took: the mount, the passes' images and the bank's
        passes, not the box rule's viewpoints.

    Returns
    -------
    Detections or tuple of Detections
        The boxes kept, in the image's pixels; with ``return_all``, ``(every, kept)``.

    Examples
    --------
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> own_detections(None, image, upsample=1.5).boxes.shape
    (0, 4)
    >>> every, kept = own_detections(None, image, fit_viewpoints=True, return_all=True, viewpoints=False)
    >>> len(every) >= len(kept), bool((kept.scores > detector_bank(None).threshold).all())
    (True, True)
    """
    if return_all and not fit_viewpoints:  # every box would take the box rule's viewpoint: seconds for nothing
        raise ValueError("return_all needs fit_viewpoints (the boxes kept above the threshold)")
    bank = detector_bank(None) if bank is None else bank
    keep = read = threshold
    add_at = None  # every pass cut at one threshold: every box counts
    if fit_viewpoints:
        keep = bank.threshold if threshold is None else float(threshold)
        fit = PredetectOptions().threshold if bank.calibration is not None else keep  # margins: no common scale
        read, add_at = min(keep, fit), fit
    clock = time.perf_counter()
    pyramid, mount = frame_mount(camera, image, bank=bank, told=mount, estimate_pitch=estimate_pitch,
                                 smallest_car=smallest_car, pyramid=pyramid)  # one mount for every pass
    passes = list(frame_passes(bank, camera, image, upsample, smallest_car, pyramid=pyramid))
    spent = time.perf_counter() - clock
    merged = None  # (every, viewed) in the image's pixels
    for p in passes:
        clock = time.perf_counter()
        found, levels, responses = bank_pass(p.camera, p.image, bank=bank, threshold=read, return_all=return_all,
                                             smallest_car=p.smallest_car, min_scale=p.min_scale, pyramid=p.pyramid,
                                             mount=mount, keep_responses=viewpoints, cross_view_nms=cross_view_nms,
                                             source=source)
        spent += time.perf_counter() - clock
        viewed = None
        if viewpoints and fit_viewpoints:
            viewed = detections_above(p.camera, p.image, found, read, bank=bank, classifier=classifier,
                                      pyramid=levels, responses=responses, mount=mount)
        elif viewpoints:
            viewed = detect_own(p.camera, p.image, bank=bank, classifier=classifier, detections=found,
                                pyramid=levels, responses=responses, mount=mount)
        del levels, responses  # this pass's features and maps, freed before the next pass's
        if viewed is not None and not return_all:  # every box found is neither returned nor shown
            found = None
        here = [None if d is None else boxes_back(d, p.factors, image.shape[1::-1]) for d in (found, viewed)]
        merged = here if merged is None else [None if d is None else add_enlarged(d, more, threshold=add_at)
                                              for d, more in zip(merged, here)]
    if seconds is not None:
        seconds.append(spent)
    every, viewed = merged
    shown = every if viewed is None else viewed
    kept = shown.subset(shown.scores > keep) if fit_viewpoints else shown
    return (every, kept) if return_all else kept


def bank_pass(camera: Camera | None, image: np.ndarray, *, bank, threshold: float | None = None,
              return_all: bool = False, pyramid: list | None = None, smallest_car: float | None = None,
              min_scale: float | None = None, mount: Mount = KITTI_MOUNT, keep_responses: bool = True,
              cross_view_nms: float | None = 0.3, source: str = "bank"):
    """One pass of the detector ``bank`` over ``image``: the feature pyramid its smallest car
    needs (``smallest_car``, :func:`~wirescene.predetect.bank.smallest_car_search`), down to
    ``min_scale`` (None: the bank's own; or ``pyramid``, given), then
    :func:`~wirescene.predetect.detect_cars` at ``threshold`` (None: the bank's own), or every
    score with ``return_all``, with the camera's ``mount`` (:func:`frame_mount`) and its
    ``cross_view_nms``. Returns ``(detections, pyramid, responses)``: what the box rule reads
    after it (``responses`` None unless ``keep_responses``); each pass of
    :func:`own_detections`.

    Examples
    --------
    >>> found, pyramid, responses = bank_pass(None, np.zeros((64, 96, 3), np.uint8), bank=detector_bank(None))
    >>> found.boxes.shape, len(responses) > 0
    ((0, 4), True)
    """
    from wirescene.predetect import detect_cars
    from wirescene.predetect.bank import bank_pyramid

    min_height, max_scale = smallest_car_search(bank, smallest_car)
    pyramid = bank_pyramid(bank, image, max_scale=max_scale, min_scale=min_scale) if pyramid is None else pyramid
    responses = {} if keep_responses else None
    found = detect_cars(image, bank=bank, camera=camera, threshold=threshold, return_all=return_all, pyramid=pyramid,
                        responses=responses, min_height=min_height, mount=mount, cross_view_nms=cross_view_nms,
                        source=source)
    return found, pyramid, responses


def inside_image(detections: Detections, image_size: tuple[int, int]) -> Detections:
    """``detections`` with their boxes clipped to the image's pixels, as the lifting clips the
    boxes it projects and KITTI clips its labelled ones: another detector's box of a car the
    image cuts may reach past it. A box left under a pixel wide or high (one lying in the
    image's last column or row) keeps one pixel.

    Examples
    --------
    >>> dets = Detections([[-300.0, 200.0, 85.9, 420.0]], 0.9, np.nan)
    >>> inside_image(dets, (1242, 375)).boxes
    array([[  0. , 200. ,  85.9, 374. ]])
    """
    W, H = image_size
    boxes = clip_boxes(detections.boxes, W, H)
    clipped = np.any(boxes != detections.boxes, axis=1)
    if not clipped.any():
        return detections
    for lo, hi, size in ((0, 2, W), (1, 3, H)):  # a box left under a pixel keeps one, inside the image
        boxes[clipped, lo] = np.clip(np.minimum(boxes[clipped, lo], boxes[clipped, hi] - 1.0), 0.0, size - 2.0)
        boxes[clipped, hi] = np.maximum(boxes[clipped, hi], boxes[clipped, lo] + 1.0)
    return Detections(boxes, detections.scores, detections.alpha, detections.source)


def fit_frame(
    camera: Camera,
    detections: Detections | None,
    variants: Iterable[str | Variant],
    *,
    image: np.ndarray | None = None,
    evidence: PartEvidence | None = None,
    options: FitOptions | None = None,
    lifted: LiftingTable | None = None,
    own: bool = False,
) -> FrameFit:
    """Fit model variants to one image.

    Parameters
    ----------
    camera : Camera
        Calibrated camera with ``image_size`` set.
    detections : Detections or None
        2D pre-detections; ``None`` runs our own pre-detection on ``image`` (stage 1,
        :func:`detect_own`).
    variants : iterable of str or Variant
        See :data:`wirescene.fitting.variants.VARIANTS`.
    image : (H, W, 3) uint8 array, optional
        Needed for pre-detection, for the viewpoints of detections without one (scored by
        the detector bank, :func:`complete_viewpoints`) and for the part evidence, unless
        ``evidence`` is given (viewpoints then come from the part evidence).
    evidence : PartEvidence, optional
        Per-vertex evidence to use instead of the part detectors' response maps
        (e.g. the oracle evidence of synthetic scenes).
    options : FitOptions, optional
        Options of every stage; default ``FitOptions()``.
    lifted : LiftingTable, optional
        The coarse lifting of ``detections`` if already computed (benchmarks time the
        stages apart); it must belong to these detections with known viewpoints.
    own : bool
        ``detections`` are our own pre-detection (``detections=None`` makes it at
        ``options.predetect.threshold``): the fine stage then weighs their boxes by
        ``options.predetect.box_weight`` instead of ``options.inference.box_weight``, and each
        variant drops the fitted cars less likely to stand on a car than
        ``options.predetect.min_car_probability`` (:func:`wirescene.fitting.confidence.keep_likely_cars`).

    Returns
    -------
    FrameFit
        The estimates per variant; every variant starts from the same detections and
        the same coarse lifting, which does not depend on the variant.

    Examples
    --------
    >>> P = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> camera = Camera(P, (1242, 375))
    >>> dets = Detections([[300, 180, 520, 300]], 0.9, 0.0)  # a box and its viewpoint (alpha 0)
    >>> options = FitOptions(lifting=LiftingOptions(n_particles=20))
    >>> fit = fit_frame(camera, dets, ["coarse", "coarse+gp"], options=options)
    >>> car = fit.estimates["coarse"].cars[0]
    >>> car.location.shape, car.dims.shape, bool(5 < car.location[2] < 30)  # metres ahead of the camera
    ((3,), (3,), True)
    >>> fit_frame(camera, Detections.empty(), ["full"]).estimates["full"].cars  # no box, no car, no fit
    []
    """
    if options is None:
        options = FitOptions()
    elif not isinstance(options, FitOptions):
        raise ArgumentError("options", f"expected FitOptions, got {type(options).__name__}")
    else:
        options = options.checked()
    if not isinstance(camera, Camera):
        raise ArgumentError("camera", f"expected a Camera, got {type(camera).__name__}")
    if detections is not None and not isinstance(detections, Detections):
        raise ArgumentError("detections", f"expected Detections or None, got {type(detections).__name__}")
    if image is not None:
        size = camera.image_size
        check_shape("image", image, (None, None, 3) if size is None else (size[1], size[0], 3))
        if image.dtype != np.uint8:
            raise ArgumentError("image", f"expected uint8 pixels, got {image.dtype}")
    variants = [_variant(v) for v in ([variants] if isinstance(variants, (str, Variant)) else variants)]
    if detections is None:
        if image is None:
            raise ValueError("image is needed to detect the cars (or pass detections)")
        detections = detect_own(camera, image, bank=detector_bank(options.detector_bank),
                                classifier=viewpoint_classifier(options.viewpoint_classifier),
                                threshold=options.predetect.threshold, smallest_car=options.predetect.smallest_car,
                                upsample=options.predetect.upsample,
                                mount=options.lifting.mount, estimate_pitch=options.lifting.estimate_pitch)
        own = True
    if options.lifting.estimate_pitch and len(detections):
        # the fit's plane and priors about the pitch its boxes tell (our own weighed by their scores)
        pitch = frame_pitch(camera, detections, bank=detector_bank(options.detector_bank), told=options.lifting.mount,
                            weighted=own)
        options = replace(options, lifting=replace(options.lifting, camera_pitch=pitch, estimate_pitch=False))
    if own:
        options = replace(options, inference=replace(options.inference, box_weight=options.predetect.box_weight))
    if len(detections) == 0:
        return FrameFit(detections, {v.name: SceneEstimate(variant=v.name, objects=[], shared_plane=v.shared_plane,
                                                           detections=detections) for v in variants})
    size = camera.image_size if camera.image_size is not None else (None if image is None else image.shape[1::-1])
    if size is not None:
        detections = inside_image(detections, size)
    if image is not None and not np.all(np.isfinite(detections.alpha)):
        # Boxes without a viewpoint (external detectors): the bank's templates and the crop
        # classifier score the 8 bins inside each box, for every variant alike.
        detections = complete_viewpoints(camera, detections, image, bank=detector_bank(options.detector_bank),
                                         classifier=viewpoint_classifier(options.viewpoint_classifier),
                                         mount=options.lifting.mount)
    if evidence is None and needs_evidence(detections, variants):
        if image is None:
            raise ValueError("image is needed for the part evidence of fine variants and unknown viewpoints")
        evidence = part_evidence(image, detections, detector=part_detector(options.parts_model),
                                 flip=options.inference.flip_evidence)
    if not np.all(np.isfinite(detections.alpha)):
        # no image to score (given evidence, e.g. the oracle's): the viewpoint from the part evidence
        detections = viewpoint_from_evidence(camera, detections, evidence, load_shape_model(options.shape_model),
                                             lifting=options.lifting)
    if lifted is None:
        lifted = lift_table(camera, detections, options=options.lifting)
    # the confidence's features ask whether a box touches the image's side
    width = camera.image_size[0] if camera.image_size is not None else (None if image is None else image.shape[1])
    estimates = {v.name: _fit_variant(camera, detections, v, lifted, evidence, options, image_width=width)
                 for v in variants}
    for v in variants:
        estimates[v.name].detections = detections
        if own and options.predetect.min_car_probability > 0:  # the verification reads the calibration's car model
            keep_likely_cars(estimates[v.name], fine=v.fine, min_probability=options.predetect.min_car_probability,
                             calibration=load_score_calibration(options.score_calibration), image_width=width)
    return FrameFit(detections, estimates, evidence)


def _fit_variant(camera: Camera, detections: Detections, v: Variant, lifted: LiftingTable,
                 evidence: PartEvidence | None, options: FitOptions, *, image_width: float | None) -> SceneEstimate:
    """Stages 4-5 for one variant: scene particles from the lifting table, then (fine
    variants) Algorithm 1 on every particle and the MAP scene."""
    weights = plane_vote_weights(detections.scores)
    particles = select_particles(
        lifted, shared_plane=v.shared_plane, n_particles=options.lifting.n_particles,
        robust_cost=options.lifting.robust_cost, weights=weights,
    )
    if not v.fine:
        # select_particles ranks the particles best first by its scene cost (capped and
        # weighted by the detections' scores), not by the plain sum ``particles.cost``,
        # which lets badly fitting (false) detections pick the shared plane.
        estimate = SceneEstimate.from_particle(particles, 0, detections, variant=v.name)
        return _confidence(estimate, options, fine=False, image_width=image_width)
    shape_model = shape_model_for(options)
    # Seeded per call from the run seed and the scene size alone, so a variant's fit does
    # not depend on which other variants are fitted with it.
    rng = np.random.default_rng([options.seed, len(detections)])
    refined = refine_particles(
        camera, particles, evidence, shape_model, options=options.inference, rng=rng, boxes=detections.boxes,
        searched_occluder=v.searched_occluder, deterministic_occlusion=v.deterministic_occlusion, weights=weights,
        alpha=detections.alpha,
    )
    estimate = estimate_from_refined(camera, refined, detections, shape_model, variant=v.name)
    return _confidence(estimate, options, fine=True, image_width=image_width)


def _confidence(estimate: SceneEstimate, options: FitOptions, *, fine: bool, image_width: float | None) -> SceneEstimate:
    """``estimate`` with calibrated confidences (``options.score_calibration``'s) as its cars'
    scores, unless ``options.calibrate_scores`` is off."""
    if not options.calibrate_scores:
        return estimate
    return apply_confidence(estimate, fine=fine, calibration=load_score_calibration(options.score_calibration),
                            image_width=image_width)


def fit_scene(
    camera: Camera,
    detections: Detections,
    *,
    variant: str | Variant = "coarse+gp",
    options: FitOptions | None = None,
    image: np.ndarray | None = None,
    evidence: PartEvidence | None = None,
    lifted: LiftingTable | None = None,
) -> SceneEstimate:
    """One variant of :func:`fit_frame` (same arguments): the estimate alone.

    Examples
    --------
    >>> P = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> camera = Camera(P, (1242, 375))
    >>> dets = Detections([[300, 180, 520, 300]], 0.9, 0.0)  # a box and its viewpoint (alpha 0)
    >>> options = FitOptions(lifting=LiftingOptions(n_particles=20))
    >>> scene = fit_scene(camera, dets, variant="coarse", options=options)
    >>> scene.variant, len(scene.cars), scene.cars[0].detection_index
    ('coarse', 1, 0)
    """
    v = _variant(variant)
    return fit_frame(camera, detections, [v], image=image, evidence=evidence, options=options,
                     lifted=lifted).estimates[v.name]
