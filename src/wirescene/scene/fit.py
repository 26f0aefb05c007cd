"""Fit a scene model to one image: the stages of the data flow composed by variant."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera
from .hypotheses import Detections, SceneEstimate
from .lifting import LiftingOptions, LiftingTable, lift_table, select_particles
from .variants import Variant, get_variant


@dataclass(frozen=True)
class FitOptions:
    """Options of every stage of :func:`fit_scene`."""

    lifting: LiftingOptions = field(default_factory=LiftingOptions)
    seed: int = 0


def fit_scene(
    camera: Camera,
    detections: Detections,
    *,
    variant: str | Variant = "coarse+gp",
    options: FitOptions = FitOptions(),
    lifted: LiftingTable | None = None,
) -> SceneEstimate:
    """Estimate the 3D scene behind ``detections``.

    Parameters
    ----------
    camera : Camera
        Calibrated camera with ``image_size`` set.
    detections : Detections
        2D pre-detections (at least one).
    variant : str or Variant
        One of :data:`wirescene.scene.variants.VARIANTS`.
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
    if lifted is None:
        lifted = lift_table(camera, detections, options=options.lifting)
    particles = select_particles(
        lifted, shared_plane=v.shared_plane, n_particles=options.lifting.n_particles,
        robust_cost=options.lifting.robust_cost,
    )
    best = int(np.argmin(particles.cost))
    estimate = SceneEstimate.from_particle(particles, best, detections, variant=v.name)
    return estimate
