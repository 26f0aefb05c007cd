"""Fine-grained scene inference (paper Sec. 4.3, Algorithm 1).

Every scene particle of the coarse stage is refined by smoothing-based optimisation
(Leordeanu & Hebert, CVPR 2008): per iteration, every object of every particle draws
Gaussian samples of its pose (x, z, azimuth on the particle's fixed ground plane) and
shape coefficients around its current value, keeps the best (the current value is
always among the candidates, so the objective never decreases), and re-estimates its
sampling spread from the samples weighted by their objective values: where the
objective is flat or wiggly the weights are even and the spread grows (by
:data:`GROWTH`), near a distinct peak they concentrate and the spread shrinks. Pose and
shape are sampled in alternate iterations, so each step searches a 3- or K-dimensional
space rather than both at once. Particles, objects and samples form one batch, so one
likelihood call per iteration scores all of them.

The search is a :class:`SearchState` (the per-particle arrays) refined in place by its
named steps -- :meth:`~SearchState.pose_step` (step 1 for the pose or the shape, with
step 3), :meth:`~SearchState.plane_step` (the same for the ground plane),
:meth:`~SearchState.occlusion_step` (step 2), :meth:`~SearchState.prune` and
:func:`polish` -- against a :class:`FineObjective`, which holds what stays fixed.

The current value's geometry and evidence are kept between iterations, so only new
samples are placed and ray cast, and the occlusion update and re-scoring reuse the
chosen samples' geometry. After ``prune_after`` iterations only the best
``keep_fraction`` of the particles continue (successive halving).

Additions to the paper's objective and search (see :class:`InferenceOptions`, and
``benchmarks/RESULTS.md`` for how their defaults were chosen): a detection-box term in
KITTI's convention (``box_weight``: the coarse stage's lifting cost of the wireframe's
3D box, so that the fine objective contains what placed the car and picked its
particle, and weak part evidence cannot slide a car along its viewing ray), and a third
sampling block for the ground plane (``plane_refinement``: the paper's scene-level
inference samples the plane too, instead of keeping the coarse grid's plane; objects
follow a sampled plane along their viewing rays), priors on the shape and on the car's
size (``shape_prior``, ``size_prior``: boxes and parts cannot tell a small car near
from a large one far, the priors can), a road-alignment prior (``road_prior``) and a
viewpoint window (``viewpoint_window_deg``), and a polish (``polish_iterations``: more
iterations of the same search on the MAP rows alone).

Positions are sampled in viewing coordinates -- the bearing ``phi = atan2(x, z)``, the
log range and the observation angle ``alpha = azimuth - phi`` -- rather than in
``(x, z, azimuth)``: an image pins the bearing and the observation angle tightly and
the range loosely, so these coordinates are nearly uncorrelated under the likelihood
and an axis-aligned Gaussian samples them efficiently.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wirescene.core.boxes import KITTI_CAR_SIZE
from wirescene.core.camera import NEAR_PLANE, Camera
from wirescene.core.errors import check_shape
from wirescene.core.groundplane import plane_normal, point_on_plane, wrap_angle
from wirescene.core.settings import bounded, option
from wirescene.core.shape import ShapeModel
from wirescene.core.types import ObjectEstimate, SceneEstimate, SceneParticles
from wirescene.core.wireframe import FACES, N_VERTICES
from wirescene.infer.likelihood import PartEvidence, instantiate_wireframes, object_likelihood, outside_image
from wirescene.infer.masks import best_mask, fit_mask, mask_hidden
from wirescene.infer.occluded_score import load_occluded_score
from wirescene.infer.occlusion import hidden_reasons, inter_object_occlusion
from wirescene.lift import ROAD_PRIOR_WIDTH, box_residual, project_boxes, road_alignment_cost, road_angle

_SIZE_MEAN, _SIZE_STD = np.array(KITTI_CAR_SIZE["mean"]), np.array(KITTI_CAR_SIZE["std"])  # l, w, h


#: Factor on the weighted spread of the samples in the variance update (step 3 of
#: Algorithm 1): above 1, so that evenly weighted samples (a flat objective) widen the search.
GROWTH = 1.3
#: Bounds of every sampling spread relative to its initial value, so the search neither
#: freezes nor leaves the neighbourhood of its start.
MIN_SIGMA_RATIO, MAX_SIGMA_RATIO = 0.05, 3.0
#: Shape coefficients stay within this many standard deviations of the shape model.
SHAPE_LIMIT = 3.0
#: Scale ``b`` of the box term's robust loss ``b log(1 + cost / b)``: the coarse stage's
#: vote cap, so that a false detection cannot dominate a shared plane.
BOX_ROBUST = 0.01


#: Most iterations of the fine stage (``iterations``, default 12, and ``polish_iterations``, default 24):
#: memory does not grow with them, time does, some 0.3 s an iteration of Algorithm 1 and 0.02 s a
#: polish iteration for an 8-car KITTI frame (5 s in all at the defaults), so 1,000 of Algorithm 1
#: make some 5 minutes a frame, two weeks of a 3,769-frame split on one core.
MAX_ITERATIONS = 1000


@dataclass(frozen=True)
class InferenceOptions:
    """Options of :func:`refine_particles`.

    ``sigma_*`` are the initial sampling spreads: bearing in degrees, range as a
    fraction (log range), observation angle in degrees, shape in units of the PCA
    standard deviations, plane pitch and roll in degrees. How each default was chosen
    (the study, its command and figures): ``benchmarks/RESULTS.md``.

    Examples
    --------
    >>> options = InferenceOptions()
    >>> options.iterations, options.samples, options.n_shape, options.device
    (12, 12, 5, 'numpy')
    >>> from dataclasses import replace
    >>> replace(options, iterations=4, polish_iterations=0).iterations
    4
    >>> InferenceOptions(known_occluded_score=float("nan"))
    Traceback (most recent call last):
    ...
    ValueError: known_occluded_score must be a finite number or None, got nan
    """

    iterations: int = option(12, maximum=MAX_ITERATIONS, help="Inference iterations (Algorithm 1; at most 1,000).")
    # Memory grows with it (some 11 MB a sample for a 5-car frame): 200 keeps a 20-car frame under 8 GB.
    samples: int = option(12, minimum=2, maximum=200,
                          help="Samples per object and iteration (the current value among them; at most 200).")
    n_shape: int = bounded(5, minimum=1)  # 3 or 8 place no more cars (RESULTS, "`n_shape` = 5")
    sigma_bearing_deg: float = bounded(0.5, minimum=0)  # the image pins the bearing tightly ...
    sigma_range_frac: float = bounded(0.05, minimum=0)  # ... and the range loosely
    sigma_azimuth_deg: float = bounded(8.0, minimum=0)
    sigma_shape: float = bounded(0.6, minimum=0)
    # Successive halving: particles far behind after ``prune_after`` iterations practically never win.
    prune_after: int = option(4, help="Keep only the best quarter of the particles after this many iterations "
                                       "(0: never).")
    keep_fraction: float = bounded(0.25, minimum=0, maximum=1)
    # The polish: more iterations on the MAP rows alone, spent where the answer is.
    polish_iterations: int = option(24, maximum=MAX_ITERATIONS,
                                    help="Extra iterations on the MAP scene after Algorithm 1 (0: none; at most 1,000).")
    polish_samples: int = bounded(24, minimum=2, maximum=1000)
    # The paper's c, the log ratio charged to occluded parts (`wirescene train occlusion`).
    occluded_score: float = field(default_factory=load_occluded_score)
    # The score of parts hidden by the scene's other cars or the image border, occluders the fit
    # does not choose (None: occluded_score).
    known_occluded_score: float | None = None
    # The coarse stage's box cost in the fine objective, so weak evidence cannot slide a car along its ray.
    box_weight: float = option(100.0, help="Weight of the detection box (KITTI convention) in the fine objective "
                                           "(0: the paper's part likelihood only; our own pre-detection's boxes: "
                                           "--own-box-weight).")
    # Sample the ground plane too (the paper's scene-level inference) instead of keeping the coarse grid's.
    plane_refinement: bool = option(True, help="Sample the ground plane in the fine stage.")
    # The shape model's Gaussian, weak: the size prior carries the size, the evidence the details.
    shape_prior: float = option(1.0, help="Weight of the shape model's Gaussian prior in the fine objective (0: none).")
    # KITTI's car sizes pin what the image cannot: size against range, hence the shared plane.
    size_prior: float = option(1.0, help="Weight of the car-size prior (KITTI's size statistics) in the fine "
                                        "objective (0: none).")
    # Cars head along the road where the part evidence is weak (the coarse stage's prior, fine scale).
    road_prior: float = option(1.0, cli="fine-road-prior",
                               help="Weight of the prior that cars head along the road in the fine objective (0: none).")
    # Only for cars whose coarse start heads within ROAD_PRIOR_WIDTH of the road: the rest stand across it.
    road_prior_gated: bool = True
    # A part projected outside the image scores c like any occluded part, not the detectors' floor.
    border_occludes: bool = option(True, help="Count the parts a hypothesis projects outside the image as occluded "
                                              "by the image border.")
    # Test-time mirroring of the part evidence (parts.detector.response_maps(flip=)): the forest is not mirror-symmetric.
    flip_evidence: bool = option(True, help="Also read the part evidence off each box's mirror image and average "
                                            "the two (the part detection takes twice as long).")
    # The paper's tolerance for a correct coarse viewpoint, around each pre-detection's (0: no window).
    viewpoint_window_deg: float = option(45.0, cli="viewpoint-window", maximum=180.0,
                                         help="Degrees the fine stage may turn a car's observation angle away from "
                                              "its pre-detection's viewpoint (0 or 180: unlimited).")
    # Starting spreads of the plane block: 0.1 deg of pitch moves a car at 30 m by about 1 m (0.1-0.4 read alike).
    sigma_pitch_deg: float = bounded(0.2, minimum=0)
    sigma_roll_deg: float = bounded(0.2, minimum=0)
    # Where the likelihood's ray casting runs: "numpy" or a PyTorch device; the CLI and the API take "auto"
    # too and resolve it before a fit (infer.torch_backend.choose_device).
    device: str = "numpy"

    def __post_init__(self):
        c = self.known_occluded_score
        if c is not None and not (isinstance(c, (int, float)) and np.isfinite(c)):
            raise ValueError(f"known_occluded_score must be a finite number or None, got {c!r}")


@dataclass
class RefinedParticles:
    """Result of :func:`refine_particles`: the particles' final parameters (``x``, ``z``,
    ``azimuth`` ``(P, N)``, ``shape`` ``(P, N, K)``), likelihoods ``score`` ``(P, N)``
    (higher is better), occluder ``mask`` indices ``(P, N)`` and deterministic
    inter-object occlusion ``gamma`` ``(P, N, 36)``, with the coarse particles' planes.
    ``coupled`` says whether objects depend on each other (shared plane or
    deterministic occlusion), so that only whole particles can be compared, by the
    scene objective: the object likelihoods summed with ``weights`` ``(N,)``.

    Examples
    --------
    >>> P, N = 2, 2
    >>> zeros = np.zeros((P, N))
    >>> particles = SceneParticles(zeros, zeros, zeros, zeros + 10, zeros, zeros, np.ones((P, N, 3)))
    >>> refined = RefinedParticles(particles, np.zeros((P, N, 5)), score=np.array([[1.0, 0.2], [0.5, 0.9]]),
    ...                            history=np.zeros(1), mask=np.zeros((P, N), int),
    ...                            gamma=np.zeros((P, N, 36), bool), coupled=False)
    >>> refined.scene_score(), refined.best_scene(), refined.best_per_object()
    (array([1.2, 1.4]), 1, array([0, 1]))
    >>> refined.best_rows()  # independent objects: each its own best particle
    array([0, 1])
    >>> from dataclasses import replace
    >>> replace(refined, coupled=True).best_rows()  # coupled (a shared plane): the best scene's row
    array([1, 1])
    """

    particles: SceneParticles
    shape: np.ndarray
    score: np.ndarray
    history: np.ndarray  # (iterations + 1,) best scene objective per iteration
    mask: np.ndarray
    gamma: np.ndarray
    coupled: bool
    # (P, N, D) final sampling spreads of (bearing, log range, observation angle,
    # shape...) and (P, N, 2) of (pitch, roll); see the module docstring.
    spread: np.ndarray | None = None
    plane_spread: np.ndarray | None = None
    weights: np.ndarray | None = None  # (N,); None: all 1
    started: int | None = None  # scene particles the search began with (None: those refined to the end)

    def scene_score(self) -> np.ndarray:
        """(P,) scene objective of every particle."""
        return _scene(self.score, self.weights)

    def best_per_object(self) -> np.ndarray:
        """(N,) particle index with the highest likelihood for each object."""
        return np.argmax(self.score, axis=0)

    def best_scene(self) -> int:
        """Particle with the highest scene objective (sum of object likelihoods)."""
        return int(np.argmax(self.scene_score()))

    def best_rows(self) -> np.ndarray:
        """(N,) particle of each object in the MAP estimate."""
        N = self.score.shape[1]
        return np.full(N, self.best_scene()) if self.coupled else self.best_per_object()


def _to_viewing(x, z, azimuth):
    phi = np.arctan2(x, z)
    return phi, np.log(np.hypot(x, z)), wrap_angle(azimuth - phi)


def _from_viewing(theta):
    phi, rng_, alpha = theta[..., 0], np.exp(theta[..., 1]), theta[..., 2]
    return rng_ * np.sin(phi), rng_ * np.cos(phi), wrap_angle(alpha + phi)


def _geometry(camera, shape_model, plane, height, theta, n_shape, device="numpy"):
    """Placed wireframes of viewing parameters ``theta`` ``(P, N, M, 3 + K)`` on planes
    ``plane = (pitch, roll)``, each ``(P, N)`` or ``(P, N, M)``."""
    expand = lambda a: np.asarray(a) if np.ndim(a) == theta.ndim - 1 else np.asarray(a)[:, :, None]  # noqa: E731
    x, z, az = _from_viewing(theta)
    return instantiate_wireframes(
        camera, shape_model, x=x, z=z, azimuth=az,
        pitch=expand(plane[0]), roll=expand(plane[1]),
        shape=theta[..., 3:3 + n_shape], height=height, device=device,
    )


def box_cost(camera, extent, location, R, boxes) -> np.ndarray:
    """The coarse stage's lifting cost of placed wireframes against detection ``boxes``
    (broadcast to ``location.shape[:-1] + (4,)``): squared side differences, over the
    detection diagonal, between the detection and the projected 3D box of each
    wireframe's object-frame ``extent`` (``lo, hi``, see :class:`~wirescene.infer.likelihood.WireframeBatch`)
    clipped to the image -- KITTI's label convention, the one the coarse stage fits
    with mean-size boxes."""
    projected, min_depth = project_boxes(camera, *extent, location, R)
    return np.sum(box_residual(projected, boxes, min_depth) ** 2, axis=-1)


def size_cost(lo, hi) -> np.ndarray:
    """Half the squared distance ``(...)`` of the box size of extents ``lo, hi``
    ``(..., 3)`` (object frame: x length, y height, z width) from KITTI's mean car, in
    KITTI's standard deviations per dimension: the negative log density of car sizes.

    Examples
    --------
    >>> from wirescene.core.boxes import KITTI_CAR_SIZE
    >>> l, w, h = KITTI_CAR_SIZE["mean"]
    >>> float(size_cost(np.zeros(3), np.array([l, h, w])))  # object frame: x length, y height, z width
    0.0
    >>> round(float(size_cost(np.zeros(3), np.array([l + 0.43, h, w]))), 6)  # one standard deviation longer
    0.5
    """
    ext = hi - lo
    size = np.stack([ext[..., 0], ext[..., 2], ext[..., 1]], axis=-1)  # l, w, h
    return 0.5 * np.sum(((size - _SIZE_MEAN) / _SIZE_STD) ** 2, axis=-1)


@dataclass
class _Terms:
    """The mask-independent parts of the objective for a batch ``(P, N, M)`` of
    hypotheses: projected vertices, their self-occlusion (or being behind the camera),
    which fall outside the image (occluded by its border), the part evidence at them and
    the box penalty. Kept so that the occlusion update
    and the re-scoring after it reuse the geometry of the chosen samples instead of
    placing and ray casting them again."""

    uv: np.ndarray  # (P, N, M, 36, 2)
    vertices: np.ndarray  # (P, N, M, 36, 3)
    self_hidden: np.ndarray  # (P, N, M, 36)
    border: np.ndarray  # (P, N, M, 36) visible but outside the image
    evidence: np.ndarray  # (P, N, M, 36)
    penalty: np.ndarray  # (P, N, M)

    def take(self, index: np.ndarray) -> "_Terms":
        """Sample ``index`` ``(P, N)`` of every object -> a batch ``(P, N, 1)``."""
        def pick(a):
            i = index.reshape(index.shape + (1,) * (a.ndim - 2))
            return np.take_along_axis(a, i, axis=2)

        return _Terms(*(pick(getattr(self, f)) for f in self.__dataclass_fields__))

    def value(self, c: float, mask=None, gamma=None, *, known_c: float | None = None) -> np.ndarray:
        """Objective ``(P, N, M)`` with vertices hidden by each object's occluder
        ``mask`` ``(P, N)``, by ``gamma`` ``(P, N, 36)`` and by the image border; those
        hidden by ``gamma`` or the border score ``known_c`` (None: ``c``) instead of ``c``."""
        known = self.border if gamma is None else self.border | np.asarray(gamma)[:, :, None, :]
        hidden = known if mask is None else known | mask_hidden(self.uv, np.asarray(mask)[:, :, None])
        value = object_likelihood(self.evidence, self.self_hidden, hidden, c=c) - self.penalty
        if known_c is None or known_c == c:
            return value
        visible = ~self.self_hidden
        return value + (known_c - c) * (known & visible).sum(-1) / np.maximum(visible.sum(-1), 1)


def _terms(camera, shape_model, evidence, particles, theta, n_shape, boxes=None, box_weight=0.0,
           device="numpy", plane=None, shape_prior=0.0, size_prior=0.0, road_prior=0.0,
           border_occludes=False) -> _Terms:
    """:class:`_Terms` of viewing parameters ``theta`` ``(P, N, M, 3 + K)`` on the
    particles' planes (or ``plane = (pitch, roll)``, see :func:`_geometry`); the
    penalty is ``box_weight`` times :func:`box_cost` against the detection ``boxes``
    ``(N, 4)`` under the robust loss of scale :data:`BOX_ROBUST`, plus ``shape_prior``
    times half the squared norm of the shape coefficients, plus the size and
    road-alignment priors. With ``border_occludes`` the visible vertices projected outside
    the image are occluded by its border."""
    N = particles.x.shape[1]
    plane = (particles.pitch, particles.roll) if plane is None else plane
    batch = _geometry(camera, shape_model, plane, particles.height, theta, n_shape, device)
    obj = np.broadcast_to(np.arange(N)[None, :, None], theta.shape[:-1])
    e = evidence.log_ratio(batch.uv, obj, batch.scale)
    penalty = np.zeros(theta.shape[:-1])
    box = box_weight and boxes is not None
    if box:
        cost = box_cost(camera, batch.extent, batch.location, batch.R, boxes[None, :, None, :])
        penalty = box_weight * (BOX_ROBUST * np.log1p(cost / BOX_ROBUST))
    if size_prior:
        penalty = penalty + size_prior * size_cost(*batch.extent)
    if shape_prior:
        penalty = penalty + 0.5 * shape_prior * np.sum(theta[..., 3:3 + n_shape] ** 2, axis=-1)
    if np.any(road_prior):  # a weight, or (P, N, 1) weights per car
        azimuth = _from_viewing(theta)[2]
        penalty = penalty + road_alignment_cost(azimuth, weight=road_prior, width=ROAD_PRIOR_WIDTH)
    self_hidden = batch.self_hidden | (batch.depth <= NEAR_PLANE)
    border = (outside_image(camera, batch.uv) & ~self_hidden if border_occludes
              else np.zeros_like(self_hidden))
    return _Terms(batch.uv, batch.vertices, self_hidden, border, e, penalty)


def _evaluate(camera, shape_model, evidence, particles, theta, n_shape, c, boxes=None, box_weight=0.0,
              mask=None, gamma=None, *, border_occludes=False):
    """Objective of viewing parameters ``theta`` ``(P, N, M, 3 + K)`` -> ``(P, N, M)``
    (see :class:`_Terms`)."""
    return _terms(camera, shape_model, evidence, particles, theta, n_shape, boxes, box_weight,
                  border_occludes=border_occludes).value(c, mask, gamma)


def _onto_plane(camera, theta, plane_from, plane_to, height):
    """Viewing parameters ``theta`` ``(..., D)`` of objects on planes ``plane_from``
    moved along the ray through their bottom centre onto planes ``plane_to`` (pitch,
    roll pairs broadcasting with ``theta[..., 0]``); observation angle and shape kept.
    The image pins the ray, not the range, so this is how a plane change moves a car."""
    x, z, _ = _from_viewing(theta)
    L = point_on_plane(x, z, *plane_from, height)
    c = camera.center
    d = L - c
    n = plane_normal(*plane_to)
    denom = np.sum(n * d, axis=-1)
    t = (height - n @ c) / np.where(np.abs(denom) < 1e-9, 1e-9, denom)
    t = np.where(t > 0, t, 1.0)  # a ray missing the new plane keeps its point
    L2 = c + t[..., None] * d
    out = np.array(theta, dtype=float, copy=True)
    out[..., 0] = np.arctan2(L2[..., 0], L2[..., 2])
    out[..., 1] = np.log(np.maximum(np.hypot(L2[..., 0], L2[..., 2]), 1.0))
    return out


def update_occlusion(camera, shape_model, evidence, particles, theta, n_shape, c, *, searched: bool, deterministic: bool,
                     border_occludes: bool = False):
    """Step 2 of Algorithm 1 for the current parameters ``theta`` ``(P, N, D)``.

    * deterministic only (``fg+do``): ``gamma`` by ray casting against the other
      objects, and the mask that best represents it (occluded vertices weigh double);
      the mask alone then defines the occlusion;
    * searched only (``fg+so``): exhaustive search of the mask maximising the
      likelihood, occluded parts scoring ``c``;
    * both (``full``): the searched mask is combined with ``gamma``, so every
      deterministically occluded vertex stays occluded whatever the mask (the paper's
      domain restriction).

    With ``border_occludes`` the vertices outside the image stay occluded whatever the
    mask. Returns ``mask`` ``(P, N)`` and ``gamma`` ``(P, N, 36)`` (None where unused).
    """
    terms = _terms(camera, shape_model, evidence, particles, theta[:, :, None], n_shape,
                   border_occludes=border_occludes)
    return _occlusion_of(camera, terms, c, searched=searched, deterministic=deterministic)


def _occlusion_of(camera, terms: _Terms, c, *, searched: bool, deterministic: bool, device: str = "numpy"):
    """:func:`update_occlusion` for the geometry ``terms`` ``(P, N, 1)`` of the current parameters."""
    uv = terms.uv[:, :, 0]
    self_hidden = terms.self_hidden[:, :, 0]
    border = terms.border[:, :, 0]
    gamma = None
    if deterministic:
        gamma = inter_object_occlusion(terms.vertices[:, :, 0], FACES, camera.center, device=device) & ~self_hidden
    if searched:
        hidden = border if gamma is None else gamma | border
        return best_mask(uv, terms.evidence[:, :, 0], self_hidden, c=c, hidden=hidden), gamma
    if deterministic:
        return fit_mask(uv, gamma, ~self_hidden), None
    return None, None


def _scene(score: np.ndarray, weights: np.ndarray | None, axis: int = 1) -> np.ndarray:
    """Scene objective: object scores summed over ``axis`` with ``weights`` (None: 1)."""
    if weights is None:
        return score.sum(axis=axis)
    w = np.asarray(weights, float).reshape((-1,) + (1,) * (score.ndim - axis - 1))
    return np.sum(score * w, axis=axis)


def _best_rows(score: np.ndarray, k: int, *, coupled: bool, weights: np.ndarray | None = None) -> np.ndarray:
    """``(k, N)`` particle rows to keep for each object: the ``k`` best scenes (sum over
    objects) when objects are coupled, else each object's own ``k`` best particles
    (independent objects may be regrouped into new rows)."""
    N = score.shape[1]
    if coupled:
        rows = np.argsort(-_scene(score, weights), kind="stable")[:k]
        return np.repeat(rows[:, None], N, axis=1)
    return np.argsort(-score, axis=0, kind="stable")[:k]


@dataclass(frozen=True)
class FineObjective:
    """What the fine search maximises for one image, fixed during the search: the
    objective's terms (:func:`_terms`), the occlusion update (step 2 of Algorithm 1) and
    the scene objective that compares coupled particles.

    Build it with :meth:`create`; ``window`` is ``(centre, known, half)`` of the
    viewpoint window (``(1, N, 1)`` arrays and radians) or None.
    """

    camera: Camera
    shape_model: ShapeModel
    evidence: PartEvidence
    options: InferenceOptions
    boxes: np.ndarray | None = None
    weights: np.ndarray | None = None
    window: tuple | None = None
    searched_occluder: bool = False
    deterministic_occlusion: bool = False

    @classmethod
    def create(cls, camera, shape_model, evidence, options, *, n_objects, boxes=None, weights=None, alpha=None,
               searched_occluder=False, deterministic_occlusion=False) -> "FineObjective":
        """The objective of :func:`refine_particles` (same arguments); ``alpha`` ``(N,)``
        becomes the viewpoint window."""
        window = None
        if alpha is not None and options.viewpoint_window_deg > 0:
            alpha = np.asarray(alpha, dtype=float)
            check_shape("alpha", alpha, (n_objects,))
            known = np.isfinite(alpha)
            window = (np.where(known, alpha, 0.0)[None, :, None], known[None, :, None],
                      np.deg2rad(options.viewpoint_window_deg))
        return cls(camera, shape_model, evidence, options, boxes, weights, window, searched_occluder,
                   deterministic_occlusion)

    @property
    def occlusion(self) -> bool:
        """Whether step 2 of Algorithm 1 (the occlusion update) runs."""
        return self.searched_occluder or self.deterministic_occlusion

    def coupled(self, particles: SceneParticles) -> bool:
        """Whether objects depend on each other, so that only whole particles compare."""
        return particles.shared_plane or self.deterministic_occlusion

    def road_weight(self, particles: SceneParticles):
        """Weight of the road prior per car of ``particles`` (``(P, N, 1)``, or a scalar
        ungated): only cars whose coarse start heads along the road are pulled onto it."""
        o = self.options
        if not o.road_prior_gated:
            return o.road_prior
        along = road_angle(particles.azimuth) <= np.deg2rad(ROAD_PRIOR_WIDTH)
        return o.road_prior * along[:, :, None]

    def terms(self, particles: SceneParticles, theta: np.ndarray, plane: np.ndarray) -> "_Terms":
        """:class:`_Terms` of viewing parameters ``theta`` ``(P, N, M, D)`` on planes
        ``plane`` ``(P, N, 2)`` or ``(P, N, M, 2)`` (pitch, roll)."""
        o = self.options
        return _terms(self.camera, self.shape_model, self.evidence, particles, theta, o.n_shape, self.boxes,
                      o.box_weight, o.device, plane=(plane[..., 0], plane[..., 1]), shape_prior=o.shape_prior,
                      size_prior=o.size_prior, road_prior=o.road_prior and self.road_weight(particles),
                      border_occludes=o.border_occludes)

    def value(self, terms: "_Terms", mask, gamma) -> np.ndarray:
        """Objective ``(P, N, M)`` of ``terms`` under the occlusion ``mask``, ``gamma``."""
        return terms.value(self.options.occluded_score, mask, gamma, known_c=self.options.known_occluded_score)

    def update_occlusion(self, current: "_Terms"):
        """Step 2 of Algorithm 1 on the current geometry: ``mask``, ``gamma``."""
        return _occlusion_of(self.camera, current, self.options.occluded_score, searched=self.searched_occluder,
                             deterministic=self.deterministic_occlusion, device=self.options.device)

    def scene(self, score: np.ndarray) -> np.ndarray:
        """Scene objective: object scores summed over axis 1 with the objects' weights."""
        return _scene(score, self.weights)


def sampling_blocks(options: InferenceOptions) -> list:
    """Parameter blocks sampled in turn, so each step searches a 3- or K-dimensional
    space: indices into the viewing parameters (pose, then shape), and None for the
    ground plane.

    Examples
    --------
    >>> sampling_blocks(InferenceOptions())  # pose, shape, ground plane
    [array([0, 1, 2]), array([3, 4, 5, 6, 7]), None]
    >>> sampling_blocks(InferenceOptions(n_shape=2, plane_refinement=False))
    [array([0, 1, 2]), array([3, 4])]
    """
    blocks = [np.arange(3), np.arange(3, 3 + options.n_shape)] if options.n_shape else [np.arange(3)]
    if options.plane_refinement:
        blocks.append(None)  # the ground plane
    return blocks


def smoothed_spread(values: np.ndarray, delta: np.ndarray, sigma0: np.ndarray) -> np.ndarray:
    """Step 3 of Algorithm 1, the smoothing-based variance update around the previous
    value: the spread of the sample offsets ``delta`` ``(..., M, d)`` weighted by their
    objective ``values`` ``(..., M)`` relative to its spread, times :data:`GROWTH`,
    within :data:`MIN_SIGMA_RATIO` and :data:`MAX_SIGMA_RATIO` of the initial spread
    ``sigma0``. Even weights (a flat objective) widen the search, weights concentrated
    on a peak narrow it.

    Examples
    --------
    >>> delta = np.array([[-1.0], [1.0]])  # (M, d): two samples one unit either side
    >>> smoothed_spread(np.zeros(2), delta, np.array([1.0]))  # a flat objective: the spread grows by GROWTH
    array([1.3])
    >>> values, delta = np.array([10.0, 0.0, 0.0]), np.array([[0.0], [1.0], [-1.0]])  # a peak at offset 0
    >>> smoothed_spread(values, delta, np.array([1.0])).round(3)  # the weights concentrate: it narrows
    array([0.572])
    """
    spread = values.std(axis=-1, keepdims=True) + 1e-9
    w = np.exp((values - values.max(axis=-1, keepdims=True)) / spread)
    w /= w.sum(axis=-1, keepdims=True)
    wstd = np.sqrt(np.sum(w[..., None] * delta**2, axis=-2))
    return np.clip(GROWTH * wstd, MIN_SIGMA_RATIO * sigma0, MAX_SIGMA_RATIO * sigma0)


def _within_window(alpha: np.ndarray, window) -> np.ndarray:
    """Observation angles ``alpha`` ``(P, N, M)`` clipped to the viewpoint window of
    each car (unknown viewpoints unchanged)."""
    centre, known, half = window
    inside = wrap_angle(centre + np.clip(wrap_angle(alpha - centre), -half, half))
    return np.where(known, inside, alpha)


@dataclass
class SearchState:
    """The state of Algorithm 1 over all particles, refined in place by its steps.

    Per particle and object: viewing parameters ``theta`` ``(P, N, D)`` (bearing, log
    range, observation angle, shape), their sampling spreads ``sigma`` and initial
    spreads ``sigma0``; the ground plane ``plane`` ``(P, N, 2)`` (pitch, roll) with
    ``plane_sigma`` and ``plane_sigma0``; the kept geometry and evidence ``current``
    ``(P, N, 1)`` of the current value, its objective ``score`` ``(P, N)`` and occlusion
    (``mask`` ``(P, N)``, ``gamma`` ``(P, N, 36)``, None where unused); ``particles``,
    the coarse particles of the rows still refined; ``history``, the best scene
    objective after each iteration; ``started``, the particles the search began with.
    """

    particles: SceneParticles
    theta: np.ndarray
    sigma: np.ndarray
    sigma0: np.ndarray
    plane: np.ndarray
    plane_sigma: np.ndarray
    plane_sigma0: np.ndarray
    current: "_Terms"
    score: np.ndarray
    mask: np.ndarray | None
    gamma: np.ndarray | None
    history: list
    started: int = 0

    @classmethod
    def start(cls, objective: FineObjective, particles: SceneParticles) -> "SearchState":
        """The coarse particles as a start: their poses, the mean shape, their planes,
        the initial spreads and no occluder (``a0``)."""
        o = objective.options
        P, N = particles.x.shape
        D = 3 + o.n_shape
        theta = np.zeros((P, N, D))
        theta[..., 0], theta[..., 1], theta[..., 2] = _to_viewing(particles.x, particles.z, particles.azimuth)
        sigma0 = np.empty((P, N, D))
        sigma0[..., 0] = np.deg2rad(o.sigma_bearing_deg)
        sigma0[..., 1] = o.sigma_range_frac
        sigma0[..., 2] = np.deg2rad(o.sigma_azimuth_deg)
        sigma0[..., 3:] = o.sigma_shape
        plane = np.stack([particles.pitch, particles.roll], axis=-1).astype(float)  # (P, N, 2)
        plane_sigma0 = np.empty((P, N, 2))
        plane_sigma0[..., 0] = np.deg2rad(o.sigma_pitch_deg)
        plane_sigma0[..., 1] = np.deg2rad(o.sigma_roll_deg)
        mask = np.zeros((P, N), dtype=int) if objective.occlusion else None
        current = objective.terms(particles, theta[:, :, None], plane)
        score = objective.value(current, mask, None)[..., 0]
        return cls(particles, theta, sigma0.copy(), sigma0, plane, plane_sigma0.copy(), plane_sigma0, current,
                   score, mask, None, [objective.scene(score).max()], P)

    def iterate(self, objective: FineObjective, rng: np.random.Generator, block, samples: int) -> None:
        """One iteration of Algorithm 1: sample ``block`` (see :func:`sampling_blocks`)
        with ``samples`` candidates per object, the current value among them, then
        update the occlusion."""
        if block is None:
            self.plane_step(objective, rng, samples)
        else:
            self.pose_step(objective, rng, block, samples)
        if objective.occlusion:
            self.occlusion_step(objective)
        self.history.append(objective.scene(self.score).max())

    def pose_step(self, objective: FineObjective, rng: np.random.Generator, block: np.ndarray, samples: int) -> None:
        """Steps 1 and 3 of Algorithm 1 for the parameters ``block`` (pose or shape) of
        every object with its occlusion fixed: Gaussian samples around the current value,
        the best kept, the spread re-estimated."""
        P, N, D = self.theta.shape
        noise = np.zeros((P, N, samples, D))
        noise[..., block] = rng.standard_normal((P, N, samples, len(block)))
        noise[:, :, 0] = 0.0  # the current value competes too
        cand = self.theta[:, :, None] + self.sigma[:, :, None] * noise
        cand[..., 1] = np.maximum(cand[..., 1], 0.0)  # at least 1 m away
        cand[..., 2] = wrap_angle(cand[..., 2])
        if objective.window is not None:
            cand[..., 2] = _within_window(cand[..., 2], objective.window)
        cand[..., 3:] = np.clip(cand[..., 3:], -SHAPE_LIMIT, SHAPE_LIMIT)
        # The current value's objective (under the current occlusion) is known: only the
        # new samples are placed and scored.
        sampled = objective.terms(self.particles, cand[:, :, 1:], self.plane)
        values = np.concatenate([self.score[:, :, None], objective.value(sampled, self.mask, self.gamma)], axis=2)
        best = np.argmax(values, axis=2)
        delta = cand - self.theta[:, :, None]
        delta[..., 2] = wrap_angle(delta[..., 2])
        updated = smoothed_spread(values, delta, self.sigma0)
        self.sigma[..., block] = updated[..., block]
        self._accept(cand, values, best, sampled)

    def plane_step(self, objective: FineObjective, rng: np.random.Generator, samples: int) -> None:
        """Steps 1 and 3 for the ground plane: sample the plane of every particle (of
        every object without ``+gp``) and move its objects along their viewing rays onto
        it; a shared plane is judged by the scene objective."""
        P, N, D = self.theta.shape
        shared = self.particles.shared_plane
        noise = rng.standard_normal((P, 1 if shared else N, samples, 2))
        noise[:, :, 0] = 0.0
        cand_plane = self.plane[:, :, None] + self.plane_sigma[:, :, None] * noise  # (P, N, M, 2)
        cand = _onto_plane(objective.camera, np.broadcast_to(self.theta[:, :, None], (P, N, samples, D)),
                           (self.plane[:, :, None, 0], self.plane[:, :, None, 1]),
                           (cand_plane[..., 0], cand_plane[..., 1]), self.particles.height)
        sampled = objective.terms(self.particles, cand[:, :, 1:], cand_plane[:, :, 1:])
        values = np.concatenate([self.score[:, :, None], objective.value(sampled, self.mask, self.gamma)], axis=2)
        judged = objective.scene(values)[:, None] if shared else values
        best = np.broadcast_to(np.argmax(judged, axis=2), (P, N))
        delta = cand_plane - self.plane[:, :, None]
        spread = smoothed_spread(judged, delta, self.plane_sigma0)
        self.plane_sigma = np.broadcast_to(spread, (P, N, 2)).copy()
        self.plane = np.take_along_axis(cand_plane, best[..., None, None], axis=2)[:, :, 0]
        self._accept(cand, values, best, sampled)

    def _accept(self, cand: np.ndarray, values: np.ndarray, best: np.ndarray, sampled: "_Terms") -> None:
        """Take candidate ``best`` ``(P, N)`` of every object (0: the current value) with
        its objective and kept geometry."""
        self.theta = np.take_along_axis(cand, best[..., None, None], axis=2)[:, :, 0]
        moved = best > 0
        chosen = sampled.take(np.maximum(best - 1, 0))
        for f in self.current.__dataclass_fields__:
            a, b = getattr(self.current, f), getattr(chosen, f)
            a[moved] = b[moved]
        self.score = np.take_along_axis(values, best[..., None], axis=2)[..., 0]

    def occlusion_step(self, objective: FineObjective) -> None:
        """Step 2 of Algorithm 1: the occlusion of the new shapes and poses, on their
        kept geometry, and their objective under it."""
        self.mask, self.gamma = objective.update_occlusion(self.current)
        self.score = objective.value(self.current, self.mask, self.gamma)[..., 0]

    def prune(self, objective: FineObjective, k: int) -> None:
        """Keep the ``k`` best rows (:func:`_best_rows`): the best scenes when objects are
        coupled, else each object's own best particles."""
        self.keep_rows(_best_rows(self.score, k, coupled=objective.coupled(self.particles),
                                  weights=objective.weights))

    def keep_rows(self, keep: np.ndarray) -> None:
        """Keep particle rows ``keep`` ``(k, N)`` of every object."""
        cols = np.arange(keep.shape[1])
        for name in ("theta", "sigma", "sigma0", "score", "plane", "plane_sigma", "plane_sigma0"):
            setattr(self, name, getattr(self, name)[keep, cols])
        self.current = _Terms(*(getattr(self.current, f)[keep, cols] for f in self.current.__dataclass_fields__))
        self.mask = None if self.mask is None else self.mask[keep, cols]
        self.gamma = None if self.gamma is None else self.gamma[keep, cols]
        self.particles = self.particles.take(keep)

    def result(self, objective: FineObjective) -> RefinedParticles:
        """The refined particles of the rows still kept."""
        P, N = self.score.shape
        x, z, azimuth = _from_viewing(self.theta)
        p = self.particles
        refined = SceneParticles(
            pitch=self.plane[..., 0], roll=self.plane[..., 1], x=x, z=z, azimuth=azimuth,
            object_cost=-self.score, dims=p.dims, height=p.height, shared_plane=p.shared_plane,
        )
        return RefinedParticles(
            refined, self.theta[..., 3:], self.score, np.array(self.history),
            mask=np.zeros((P, N), dtype=int) if self.mask is None else self.mask,
            gamma=np.zeros((P, N, N_VERTICES), dtype=bool) if self.gamma is None else self.gamma,
            coupled=objective.coupled(p),
            spread=self.sigma, plane_spread=self.plane_sigma, weights=objective.weights, started=self.started,
        )


def _prunes_after(options: InferenceOptions, done: int) -> bool:
    """Whether the successive halving happens after ``done`` iterations."""
    return bool(options.prune_after and done == options.prune_after and options.keep_fraction < 1
                and done < options.iterations)


def polish(state: SearchState, objective: FineObjective, rng: np.random.Generator, blocks: list) -> None:
    """The polish: only the MAP rows run ``polish_iterations`` more iterations of the
    same search with ``polish_samples`` samples, from the spreads they reached (the
    block schedule continues where Algorithm 1 stopped)."""
    o = objective.options
    state.prune(objective, 1)
    for it in range(o.iterations, o.iterations + o.polish_iterations):
        state.iterate(objective, rng, blocks[it % len(blocks)], o.polish_samples)


def refine_particles(
    camera: Camera,
    particles: SceneParticles,
    evidence: PartEvidence,
    shape_model: ShapeModel,
    *,
    options: InferenceOptions | None = None,
    rng: np.random.Generator | None = None,
    boxes: np.ndarray | None = None,
    searched_occluder: bool = False,
    deterministic_occlusion: bool = False,
    weights: np.ndarray | None = None,
    alpha: np.ndarray | None = None,
) -> RefinedParticles:
    """Run Algorithm 1 on every particle.

    Parameters
    ----------
    camera : Camera
    particles : SceneParticles
        Coarse-stage particles ``(P, N)``; their ground planes stay fixed unless
        ``options.plane_refinement``.
    evidence : PartEvidence
        Per-vertex image evidence; object ``j`` of the particles is detection ``j``.
    shape_model : ShapeModel
        The cars' shape space (its first ``options.n_shape`` components are searched).
    options : InferenceOptions, optional
        The search's settings (default: ``InferenceOptions()``).
    rng : numpy.random.Generator, optional
        The sampling's generator (default: seeded with 0).
    boxes : (N, 4) array, optional
        Detection boxes, used with ``options.box_weight``.
    searched_occluder, deterministic_occlusion : bool
        The ``+so`` and ``+do`` switches (see :func:`update_occlusion`). Masks start
        empty (``a0``) and are updated after every sampling step.
    weights : (N,) array, optional
        Weights of the objects in the scene objective that compares coupled particles
        and shared planes (default: 1 each); the pipeline passes the detections' plane
        votes (:func:`wirescene.lift.plane_vote_weights`), so that likely false
        detections cannot choose the plane of the cars.
    alpha : (N,) array, optional
        The detections' viewpoints (observation angles, NaN where unknown): each car's
        observation angle stays within ``options.viewpoint_window_deg`` of its own.

    Examples
    --------
    >>> from wirescene.fitting.models import load_shape_model
    >>> from wirescene.infer.likelihood import GaussianVertexEvidence
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> model = load_shape_model()
    >>> truth = instantiate_wireframes(camera, model, x=np.array([-2.0]), z=np.array([12.0]), azimuth=np.array([0.3]),
    ...                                pitch=np.zeros(1), roll=np.zeros(1), shape=np.zeros((1, 5)), height=1.65)
    >>> evidence = GaussianVertexEvidence(truth.uv, np.ones((1, 36), bool))  # peaks at a car's true vertices
    >>> start = SceneParticles(pitch=np.zeros((2, 1)), roll=np.zeros((2, 1)), x=np.array([[-2.3], [-1.5]]),
    ...                        z=np.array([[12.5], [11.0]]), azimuth=np.array([[0.2], [0.5]]),
    ...                        object_cost=np.zeros((2, 1)), dims=np.tile([1.5, 1.6, 3.9], (2, 1, 1)))  # 2 particles
    >>> options = InferenceOptions(iterations=6, samples=8, polish_iterations=0, box_weight=0.0)
    >>> refined = refine_particles(camera, start, evidence, model, options=options)
    >>> refined.score.shape, refined.shape.shape, refined.history.shape  # (P, N), (P, N, K), iterations + 1
    ((1, 1), (1, 1, 5), (7,))
    >>> refined.particles.n_particles  # after prune_after (4) iterations the best quarter went on: 1 of 2
    1
    >>> bool(np.all(np.diff(refined.history) >= 0))  # the current value is always a candidate
    True
    """
    options = InferenceOptions() if options is None else options
    rng = np.random.default_rng(0) if rng is None else rng
    objective = FineObjective.create(
        camera, shape_model, evidence, options, n_objects=particles.n_objects, boxes=boxes, weights=weights,
        alpha=alpha, searched_occluder=searched_occluder, deterministic_occlusion=deterministic_occlusion)
    state = SearchState.start(objective, particles)
    blocks = sampling_blocks(options)
    for it in range(options.iterations):
        state.iterate(objective, rng, blocks[it % len(blocks)], options.samples)
        if _prunes_after(options, it + 1):  # successive halving
            state.prune(objective, max(1, int(np.ceil(options.keep_fraction * state.score.shape[0]))))
    if options.polish_iterations:
        polish(state, objective, rng, blocks)
    return state.result(objective)


def estimate_from_refined(
    camera: Camera,
    refined: RefinedParticles,
    detections,
    shape_model: ShapeModel,
    *,
    variant: str,
) -> SceneEstimate:
    """The MAP scene of refined particles: the particle with the best scene objective
    when objects share a plane (the plane couples them), otherwise each object's own
    best particle (independent objects: the per-object maxima form the joint maximum).

    Each object's box size and bottom centre are those of its fitted wireframe's
    axis-aligned extent in the object frame; ``hidden_by`` says what hides each vertex
    (:func:`~wirescene.infer.occlusion.hidden_reasons`: the car itself, the image's border,
    another car, the occluder mask), ``visibility`` where nothing does; ``exemplar`` is the
    nearest CAD exemplar (paper Sec. 5.4).

    Examples
    --------
    >>> from wirescene.fitting.models import load_shape_model
    >>> from wirescene.infer.likelihood import GaussianVertexEvidence
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> model = load_shape_model()
    >>> truth = instantiate_wireframes(camera, model, x=np.array([-2.0]), z=np.array([12.0]), azimuth=np.array([0.3]),
    ...                                pitch=np.zeros(1), roll=np.zeros(1), shape=np.zeros((1, 5)), height=1.65)
    >>> evidence = GaussianVertexEvidence(truth.uv, np.ones((1, 36), bool))  # peaks at a car's true vertices
    >>> start = SceneParticles(pitch=np.zeros((2, 1)), roll=np.zeros((2, 1)), x=np.array([[-2.3], [-1.5]]),
    ...                        z=np.array([[12.5], [11.0]]), azimuth=np.array([[0.2], [0.5]]),
    ...                        object_cost=np.zeros((2, 1)), dims=np.tile([1.5, 1.6, 3.9], (2, 1, 1)))  # 2 particles
    >>> options = InferenceOptions(iterations=6, samples=8, polish_iterations=0, box_weight=0.0)
    >>> from wirescene.core.types import Detections
    >>> refined = refine_particles(camera, start, evidence, model, options=options)
    >>> estimate = estimate_from_refined(camera, refined, Detections([[400, 150, 600, 230]], 0.9, 0.0), model,
    ...                                  variant="fg")
    >>> car = estimate.cars[0]
    >>> len(estimate.cars), car.vertices.shape, car.visibility.shape, car.dims.shape
    (1, (36, 3), (36,), (3,))
    >>> bool(np.array_equal(car.visibility, car.hidden_by == "visible")), "self" in car.hidden_by  # its far side
    (True, True)
    >>> estimate.n_particles  # the search's, not the one row the polish refined to the end
    2
    """

    p = refined.particles
    N = p.n_objects
    rows = refined.best_rows()
    cols = np.arange(N)
    shape = refined.shape[rows, cols]
    batch = instantiate_wireframes(
        camera, shape_model, x=p.x[rows, cols], z=p.z[rows, cols], azimuth=p.azimuth[rows, cols],
        pitch=p.pitch[rows, cols], roll=p.roll[rows, cols], shape=shape, height=p.height,
    )
    X_obj = shape_model.instantiate(shape)  # (N, 36, 3)
    lo, hi = X_obj.min(axis=1), X_obj.max(axis=1)
    dims = np.stack([-lo[:, 1], hi[:, 2] - lo[:, 2], hi[:, 0] - lo[:, 0]], axis=1)  # h, w, l
    bottom_centre = np.stack([(lo[:, 0] + hi[:, 0]) / 2, np.zeros(N), (lo[:, 2] + hi[:, 2]) / 2], axis=1)
    location = batch.location + np.einsum("nij,nj->ni", batch.R, bottom_centre)
    _, names, _ = shape_model.nearest_exemplar(X_obj)
    hidden_by = hidden_reasons(batch.self_hidden, truncated=outside_image(camera, batch.uv),
                               other_car=refined.gamma[rows, cols],
                               occluder=mask_hidden(batch.uv, refined.mask[rows, cols]))
    objects = [
        ObjectEstimate(
            detection_index=j,
            box2d=detections.boxes[j],
            score=float(detections.scores[j]),
            location=location[j],
            R=batch.R[j],
            dims=dims[j],
            cost=float(-refined.score[rows[j], j]),
            pitch=float(p.pitch[rows[j], j]),
            roll=float(p.roll[rows[j], j]),
            shape=shape[j],
            vertices=batch.vertices[j],
            exemplar=str(names[j]),
            occluder_mask=int(refined.mask[rows[j], j]),
            hidden_by=hidden_by[j],  # visibility: where it says visible
        )
        for j in range(N)
    ]
    return SceneEstimate(
        variant=variant, objects=objects, camera_height=p.height, shared_plane=p.shared_plane,
        n_particles=refined.started or p.n_particles,
        extras={"objective_history": [float(v) for v in refined.history]},
    )
