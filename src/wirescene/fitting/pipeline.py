"""The per-frame pipeline, written once: detect -> parts -> lift -> infer -> estimate.

:func:`fit_frame` is the only place where the stages are composed. The Python API
(:func:`wirescene.fit`), ``wirescene fit``, ``wirescene demo`` and ``wirescene eval``
(every frame, in any process) all call it, so they cannot drift apart. It does no file
I/O: inputs are arrays and typed objects, outputs a :class:`FrameFit`. Its options are in
:mod:`wirescene.fitting.options`, the trained artefacts it loads in
:mod:`wirescene.fitting.models`, our own pre-detection in :mod:`wirescene.fitting.own_boxes`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable

import numpy as np

from wirescene.core.boxes import clip_boxes
from wirescene.core.camera import Camera
from wirescene.core.errors import ArgumentError, check_shape
from wirescene.core.types import Detections, SceneEstimate
from wirescene.fitting.confidence import apply_confidence, keep_likely_cars, load_score_calibration
from wirescene.fitting.models import (
    detector_bank,
    load_shape_model,
    part_detector,
    shape_model_for,
    viewpoint_classifier,
)
from wirescene.fitting.mount import frame_pitch
from wirescene.fitting.options import FitOptions
from wirescene.fitting.own_boxes import complete_viewpoints, own_detections
from wirescene.fitting.variants import DEFAULT_VARIANT, Variant, get_variant
from wirescene.infer.evidence import part_evidence, viewpoint_from_evidence
from wirescene.infer.inference import estimate_from_refined, refine_particles
from wirescene.infer.likelihood import PartEvidence
from wirescene.lift import LiftingTable, lift_table, plane_vote_weights, select_particles

# The fit's own names: the options, loaders and pre-detection it imports live in their modules.
__all__ = ["FrameFit", "needs_evidence", "inside_image", "fit_frame", "fit_scene"]


@dataclass
class FrameFit:
    """What :func:`fit_frame` produced for one image.

    Attributes
    ----------
    detections : Detections
        The pre-detections the variants were fitted to, with unknown viewpoints
        completed by the detector bank
        (:func:`~wirescene.fitting.own_boxes.complete_viewpoints`; from the part evidence
        when no image is given).
    estimates : dict of str to SceneEstimate
        One estimate per requested variant, in the requested order.
    evidence : PartEvidence or None
        The part evidence the fine variants used (None if no variant needed it).

    Examples
    --------
    >>> from wirescene.lift import LiftingOptions
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
        :func:`~wirescene.fitting.own_boxes.own_detections`).
    variants : iterable of str or Variant
        See :data:`wirescene.fitting.variants.VARIANTS`.
    image : (H, W, 3) uint8 array, optional
        Needed for pre-detection, for the viewpoints of detections without one (scored by
        the detector bank, :func:`~wirescene.fitting.own_boxes.complete_viewpoints`) and for
        the part evidence, unless ``evidence`` is given (viewpoints then come from the part
        evidence).
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
    >>> from wirescene.lift import LiftingOptions
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
        detections = own_detections(camera, image, bank=detector_bank(options.detector_bank),
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
    variant: str | Variant = DEFAULT_VARIANT,
    options: FitOptions | None = None,
    image: np.ndarray | None = None,
    evidence: PartEvidence | None = None,
    lifted: LiftingTable | None = None,
) -> SceneEstimate:
    """One variant of :func:`fit_frame` (same arguments): the estimate alone.

    Examples
    --------
    >>> from wirescene.lift import LiftingOptions
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
