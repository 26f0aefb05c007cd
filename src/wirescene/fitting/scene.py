"""Fit a scene model to one image: the stages of the data flow composed by variant."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wirescene.core.camera import Camera
from wirescene.core.types import Detections, SceneEstimate
from wirescene.infer.inference import InferenceOptions, estimate_from_refined, refine_particles
from wirescene.lift import LiftingOptions, LiftingTable, lift_table, select_particles
from wirescene.infer.likelihood import PartEvidence
from wirescene.fitting.variants import Variant, get_variant


@dataclass(frozen=True)
class FitOptions:
    """Options of every stage of :func:`fit_scene`."""

    lifting: LiftingOptions = field(default_factory=LiftingOptions)
    inference: InferenceOptions = field(default_factory=InferenceOptions)
    seed: int = 0


def fit_scene(
    camera: Camera,
    detections: Detections,
    *,
    variant: str | Variant = "coarse+gp",
    options: FitOptions = FitOptions(),
    lifted: LiftingTable | None = None,
    image: np.ndarray | None = None,
    evidence: PartEvidence | None = None,
) -> SceneEstimate:
    """Estimate the 3D scene behind ``detections``.

    Parameters
    ----------
    camera : Camera
        Calibrated camera with ``image_size`` set.
    detections : Detections
        2D pre-detections (at least one).
    variant : str or Variant
        One of :data:`wirescene.fitting.variants.VARIANTS`.
    lifted : LiftingTable, optional
        The coarse grid search of these detections, if already computed (it does not
        depend on the variant, so callers fitting several variants compute it once).

    Returns
    -------
    SceneEstimate
        The best scene particle, one :class:`ObjectEstimate` per detection.
    """
    v = get_variant(variant) if isinstance(variant, str) else variant
    if len(detections) == 0:
        return SceneEstimate(variant=v.name, objects=[], shared_plane=v.shared_plane)
    if lifted is None and not np.all(np.isfinite(detections.alpha)):
        # Boxes without a viewpoint (external detectors): take it from the part evidence,
        # for every variant, so that all variants start from the same pre-detections.
        from wirescene.core.shape import load_default
        from wirescene.infer.evidence import part_evidence, viewpoint_from_evidence

        if evidence is None and image is not None:
            evidence = part_evidence(image, detections)
        if evidence is not None:
            detections = viewpoint_from_evidence(camera, detections, evidence, load_default())
    if lifted is None:
        lifted = lift_table(camera, detections, options=options.lifting)
    particles = select_particles(
        lifted, shared_plane=v.shared_plane, n_particles=options.lifting.n_particles,
        robust_cost=options.lifting.robust_cost,
    )
    if not v.fine:
        best = int(np.argmin(particles.cost))
        return SceneEstimate.from_particle(particles, best, detections, variant=v.name)
    if evidence is None:
        if image is None:
            raise ValueError(f"variant {v.name!r} needs the image (or precomputed evidence)")
        from wirescene.infer.evidence import part_evidence

        evidence = part_evidence(image, detections)
    from wirescene.core.shape import load_default

    shape_model = load_default()
    rng = np.random.default_rng([options.seed, len(detections)])
    refined = refine_particles(
        camera, particles, evidence, shape_model, options=options.inference, rng=rng, boxes=detections.boxes,
        searched_occluder=v.searched_occluder, deterministic_occlusion=v.deterministic_occlusion,
    )
    return estimate_from_refined(camera, refined, detections, shape_model, variant=v.name)
