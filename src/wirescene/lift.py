"""Coarse 3D geometry (paper Sec. 4.3): lift 2D pre-detections to 3D boxes of mean car
size standing on a ground plane, by a grid search over ground-plane pitch and roll and
object azimuth, with the object's position on the plane solved for each grid cell so
that the projected box matches the detected 2D box.

The search is vectorised over (detections x planes x azimuths), a block of cells at a time
(:data:`LIFT_BLOCK_CELLS`: the memory does not grow with the grid): for every
cell a few damped Gauss-Newton steps on (x, log z) minimise the squared difference of the
projected and detected box sides, normalised by the detection's diagonal, and each
(detection, plane) keeps the azimuth that best fits its box under a prior that cars head
along the road (:func:`road_alignment_cost`). Two variants:

* ``shared_plane=False`` (``coarse``): every object chooses its own plane, i.e. objects
  are lifted independently;
* ``shared_plane=True`` (``coarse+gp``): one plane for the whole image, chosen by the
  consensus of all objects (sum of robustified per-object costs).

In both cases many scene particles are kept (default 250), ranked by cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wirescene.core.boxes import MEAN_CAR_DIMS, box_extent_object
from wirescene.core.camera import Camera
from wirescene.core.groundplane import (
    KITTI_CAMERA_HEIGHT,
    Mount,
    plane_rotation,
    wrap_angle,
)
from wirescene.core.settings import bounded, option
from wirescene.core.types import Detections, SceneParticles
from wirescene.core.validate import finite_real

#: Width (degrees) of the road-alignment prior (:func:`road_alignment_cost`), one for
#: both stages: the fine stage's prior and its gate act on what the coarse prior settled.
ROAD_PRIOR_WIDTH = 20.0

#: (detection, plane, azimuth) cells the grid search solves at once (:func:`lift_table`): about
#: 930 bytes of temporaries a cell, 120 MB whatever the grid and the detections. The default grid
#: of a frame of up to 21 cars is one block: smaller ones made a fresh process slower, its
#: allocator returning and faulting the blocks' memory again and again.
LIFT_BLOCK_CELLS = 1 << 17

#: Most ground planes (pitches x rolls) the coarse grid may hold: its table keeps some 40 bytes
#: a (detection, plane), so 100 detections take 1 GB at most; 0.01 deg steps over the default
#: ranges make 180,901 planes, the defaults 325.
MAX_GRID_PLANES = 250_000

#: Most azimuths the coarse grid tries a detection (``2 * azimuth_halfwidth / azimuth_step + 1``
#: for a known viewpoint, ``360 / unknown_viewpoint_step`` for none): 0.1 deg steps round the
#: circle, 50x the default 72. Each costs time, not memory (some 17 us a (detection, plane,
#: azimuth) cell: 5.5 ms a detection on the default 325 planes).
MAX_AZIMUTH_STEPS = 3_600

#: Most (plane, azimuth) cells of one detection: what :data:`MAX_GRID_PLANES` allows at the default
#: 72 azimuths of an unknown viewpoint (the defaults: 6,175 and 23,400), about 5 minutes of
#: lifting a detection.
MAX_GRID_CELLS = MAX_GRID_PLANES * 72

#: Most scene particles (``n_particles``): 100x the default. What a particle costs grows with the
#: fine stage's samples, which :data:`MAX_HYPOTHESES` caps together with it.
MAX_PARTICLES = 25_000

#: Most particles x fine-stage samples (:meth:`wirescene.fitting.options.FitOptions.combined_problem`):
#: 250 x 200, the memory the ``samples`` cap was sized for (some 9 kB a (particle, car, sample): 9 GB
#: for 20 cars).
MAX_HYPOTHESES = 50_000


#: Most Levenberg-Marquardt steps of the coarse stage's box fit (``iterations``, default 8): each
#: costs some 0.07 s of an 8-car frame on the default grid (its 6,175 cells a detection; 3,000x that
#: on the largest grid :data:`MAX_GRID_CELLS` allows) and no memory; beyond some 150 steps a cell
#: whose step is rejected again and again overflows its damping (200 steps: overflow warnings, NaN).
MAX_LIFT_ITERATIONS = 100


@dataclass(frozen=True)
class LiftingOptions:
    """Options of the coarse lifting stage (all angles in degrees). How the defaults
    were chosen (the study, its command and figures): ``benchmarks/RESULTS.md``.

    Examples
    --------
    >>> options = LiftingOptions(pitch_range=1.0, pitch_step=0.5, roll_range=0.0, camera_pitch=2.0)
    >>> pitch, roll = options.plane_grid()  # radians, one entry a plane
    >>> np.rad2deg(pitch).round(6).tolist(), np.rad2deg(roll).tolist()  # about the camera's own pitch
    ([1.0, 1.5, 2.0, 2.5, 3.0], [0.0, 0.0, 0.0, 0.0, 0.0])
    >>> options.mount
    Mount(height=1.65, pitch=2.0)
    >>> len(options.alpha_offsets(True)), len(options.alpha_offsets(False))  # +-22.5 deg by 2.5; a full turn by 5
    (19, 72)
    """

    # KITTI's camera is rigidly mounted: roads tilt by a few degrees in pitch, much less in roll.
    pitch_range: float = bounded(3.0, minimum=0)  # searched about camera_pitch
    pitch_step: float = bounded(0.25, minimum=0.01)
    roll_range: float = bounded(1.5, minimum=0)
    roll_step: float = bounded(0.25, minimum=0.01)
    azimuth_halfwidth: float = bounded(22.5, minimum=0, maximum=180)  # search +- this around the detection's viewpoint
    azimuth_step: float = bounded(2.5, minimum=0.01)
    unknown_viewpoint_step: float = bounded(5.0, minimum=0.01)  # full circle when the detector gives none
    iterations: int = bounded(8, minimum=0, maximum=MAX_LIFT_ITERATIONS)  # Levenberg-Marquardt steps a cell
    # Cap of each object's shared-plane vote, near a fitting car's cost: a box no car explains is an outlier.
    robust_cost: float = bounded(0.01, minimum=0)
    # Metres above the road: a car's, a truck's, a pole's at some 10-15 m; 165 or 1650 would be cm or mm.
    camera_height: float = bounded(KITTI_CAMERA_HEIGHT, minimum=0.1, maximum=50.0)
    # Degrees the camera looks down from the road (a dashcam's tilt; KITTI's rig is level to +-1 deg).
    camera_pitch: float = bounded(0.0, minimum=-45.0, maximum=45.0)
    # Off: on KITTI's level rig reading it costs `coarse` 9 of 148 cars within 1 m (benchmarks/RESULTS.md,
    # "A camera's pitch read off its boxes").
    estimate_pitch: bool = option(False, help="Read the camera's pitch off each frame's boxes, within 15 deg of "
                                              "lifting.camera_pitch (a camera whose tilt is not known; our own "
                                              "pre-detection then takes 1.3x as long).")
    n_particles: int = bounded(250, minimum=1, maximum=MAX_PARTICLES)
    # Weight of the prior that cars head along the road (:func:`road_alignment_cost`), which a box leaves open; 0: off.
    road_prior: float = option(0.03, help="Weight of the coarse stage's prior that cars head along the road "
                                          "(0: none).")

    @property
    def mount(self) -> Mount:
        """The camera's :class:`~wirescene.core.groundplane.Mount` (``camera_height``, ``camera_pitch``)."""
        return Mount(self.camera_height, self.camera_pitch)

    def plane_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Flattened pitch and roll grids (radians), shape ``(G,)`` each: the pitch about the
        camera's (a camera looking down sees the road pitched by as much)."""
        pitch = np.deg2rad(self.camera_pitch + _symmetric_range(self.pitch_range, self.pitch_step))
        roll = np.deg2rad(_symmetric_range(self.roll_range, self.roll_step))
        pp, rr = np.meshgrid(pitch, roll, indexing="ij")
        return pp.ravel(), rr.ravel()

    def combined_problem(self) -> tuple[tuple[str, ...], str] | None:
        """The fields whose values together break a limit and the problem, or None: a plane
        grid of more than :data:`MAX_GRID_PLANES` planes, more than :data:`MAX_AZIMUTH_STEPS`
        azimuths a detection or more than :data:`MAX_GRID_CELLS` (plane, azimuth) cells (read
        by :func:`wirescene.core.settings.check_combined`).

        Examples
        --------
        >>> LiftingOptions().combined_problem() is None
        True
        >>> LiftingOptions(pitch_range=10, pitch_step=0.01, roll_step=0.01).combined_problem()[1]
        'give 2,001 pitches x 301 rolls = 602,301 ground planes, at most 250,000: take coarser steps or narrower ranges'
        >>> LiftingOptions(unknown_viewpoint_step=0.01).combined_problem()[1]
        'gives 36,000 azimuths a detection, at most 3,600: take a coarser step'
        """
        sides = ((self.pitch_range, self.pitch_step), (self.roll_range, self.roll_step))
        if not all(finite_real(half) and finite_real(step) and half >= 0 and step > 0 for half, step in sides):
            return None  # the fields' own checks name what is wrong
        n_pitch, n_roll = (_symmetric_count(half, step) for half, step in sides)
        if n_pitch * n_roll > MAX_GRID_PLANES:
            return (("pitch_range", "pitch_step", "roll_range", "roll_step"),
                    f"give {_count(n_pitch)} pitches x {_count(n_roll)} rolls = {_count(n_pitch * n_roll)} ground "
                    f"planes, at most {MAX_GRID_PLANES:,}: take coarser steps or narrower ranges")
        azimuths = {("azimuth_halfwidth", "azimuth_step"): (self.azimuth_halfwidth, self.azimuth_step),
                    ("unknown_viewpoint_step",): (180.0, self.unknown_viewpoint_step)}
        if not all(finite_real(half) and finite_real(step) and half >= 0 and step > 0
                   for half, step in azimuths.values()):
            return None
        counts = {names: _symmetric_count(half, step) if len(names) == 2 else _circle_count(step)
                  for names, (half, step) in azimuths.items()}
        for names, n in counts.items():
            if n > MAX_AZIMUTH_STEPS:
                return (names, f"give{'s' if len(names) == 1 else ''} {_count(n)} azimuths a detection, at most "
                               f"{MAX_AZIMUTH_STEPS:,}: take a coarser step")
        names, n_az = max(counts.items(), key=lambda item: item[1])  # the grid pads every detection to the longer
        if n_pitch * n_roll * n_az > MAX_GRID_CELLS:
            return (("pitch_step", "roll_step") + names,
                    f"give {_count(n_pitch * n_roll)} ground planes x {_count(n_az)} azimuths = "
                    f"{_count(n_pitch * n_roll * n_az)} cells a detection, at most {MAX_GRID_CELLS:,}: take coarser "
                    "steps or narrower ranges")
        return None

    def grid_planes(self) -> int:
        """The number of ground planes of :meth:`plane_grid`, counted without building it."""
        pitches = _symmetric_count(self.pitch_range, self.pitch_step)
        return int(pitches * _symmetric_count(self.roll_range, self.roll_step))

    def alpha_offsets(self, known: bool) -> np.ndarray:
        """Offsets (radians) of the observation angles searched about a detection's
        viewpoint: ``+- azimuth_halfwidth`` by ``azimuth_step`` where it is ``known``, a
        full turn by ``unknown_viewpoint_step`` where it is not."""
        if known:
            return np.deg2rad(_symmetric_range(self.azimuth_halfwidth, self.azimuth_step))
        return np.deg2rad(_circle(self.unknown_viewpoint_step))


def _circle(step: float) -> np.ndarray:
    """Azimuths (degrees) round the circle from -180 by ``step``."""
    return np.arange(-180.0, 180.0, step)


def _count(n: float) -> str:
    """A count for a message: with thousands separators, or in powers of ten where it has no digits to show."""
    return f"{n:,}" if n < 1e12 else f"{n:.3g}"


def _symmetric_range(half: float, step: float) -> np.ndarray:
    n = int(round(half / step))
    return np.arange(-n, n + 1) * step


def _circle_count(step: float) -> float:
    """``len(_circle(step))`` without building it (a step too fine for any array to hold)."""
    return math.ceil(360.0 / step) if 360.0 / step < 1e15 else 360.0 / step


def _symmetric_count(half: float, step: float) -> float:
    """``len(_symmetric_range(half, step))`` without building it (a float where no array could hold it)."""
    n = half / step
    return 2 * round(n) + 1 if n < 1e15 else 2 * n + 1


def project_boxes(camera: Camera, lo, hi, location, R) -> tuple[np.ndarray, np.ndarray]:
    """2D boxes ``(..., 4)`` of the object-frame boxes spanning ``lo`` to ``hi`` ``(..., 3)``
    (see :func:`wirescene.core.boxes.box_extent_object`) placed at ``location`` ``(..., 3)``
    with rotation ``R`` ``(..., 3, 3)``, clipped to the image when its size is known, and
    the minimum corner depth ``(...)`` (<= 0 means the box reaches behind the camera).

    The same boxes as :func:`wirescene.core.boxes.project_points_to_box` of the eight
    corners, computed without them (the grid search's inner loop).

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]], (1242, 375))
    >>> from wirescene.core.boxes import MEAN_CAR_DIMS, box_corners, box_extent_object, project_points_to_box
    >>> from wirescene.core.groundplane import rotation_y
    >>> lo, hi = box_extent_object(MEAN_CAR_DIMS)
    >>> box, depth = project_boxes(camera, lo, hi, np.array([-3.0, 1.65, 15.0]), rotation_y(-1.5))
    >>> np.round(box, 1).tolist(), round(float(depth), 2)  # x1 y1 x2 y2; the nearest corner 13 m away
    ([395.7, 178.0, 524.5, 264.4], 13.01)
    >>> corners = box_corners(MEAN_CAR_DIMS, [-3.0, 1.65, 15.0], rotation_y(-1.5))
    >>> bool(np.allclose(box, project_points_to_box(camera, corners)))
    True
    """
    lo, hi, location, R = (np.asarray(a, dtype=float) for a in (lo, hi, location, R))
    nd = max(lo.ndim - 1, hi.ndim - 1, location.ndim - 1, R.ndim - 2)  # batch axes
    P3 = camera.P[:, :3]
    M = _components_first(np.matmul(P3, R), nd, 2)  # (3 rows, 3 object axes, batch...)
    offset = _components_first(location @ P3.T + camera.P[:, 3], nd)
    return _projected_extent(camera, lo, hi, (M[:, 0], M[:, 1], M[:, 2]), offset)


def _components_first(a: np.ndarray, nd: int, k: int = 1) -> np.ndarray:
    """``a`` ``(batch..., 3)`` (``k = 1``) or ``(batch..., 3, 3)`` (``k = 2``) with its ``k``
    component axes first and its batch axes padded to ``nd``, so the batch broadcasts."""
    moved = np.moveaxis(a, tuple(range(a.ndim - k, a.ndim)), tuple(range(k)))
    return moved.reshape(moved.shape[:k] + (1,) * (nd - (a.ndim - k)) + moved.shape[k:])


def _projected_extent(camera: Camera, lo, hi, axes, offset) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_boxes` from the homogeneous image directions ``axes`` (three
    ``(3, batch...)``, components first) of the object's axes and the image point
    ``offset`` ``(3, batch...)`` of its origin, all with the batch's number of axes."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    # A corner takes lo or hi along each axis, so its image point is the offset plus one of
    # two terms per axis: 2 x 3 products a box instead of an (8 x 3) @ (3 x 3) one.
    t = [np.stack(np.broadcast_arrays(a * lo[..., k], a * hi[..., k])) for k, a in enumerate(axes)]
    uvw = offset + t[0][:, None, None] + t[1][None, :, None] + t[2][None, None, :]
    uvw = uvw.reshape((8,) + uvw.shape[3:])  # corners, then components: elementwise minima
    w = uvw[:, 2]
    safe = np.where(np.abs(w) < 1e-9, 1e-9, w)
    u, v = uvw[:, 0] / safe, uvw[:, 1] / safe
    box = np.stack([u.min(axis=0), v.min(axis=0), u.max(axis=0), v.max(axis=0)], axis=-1)
    if camera.image_size is not None:
        width, height = camera.image_size
        box = np.clip(box, 0.0, [width - 1, height - 1, width - 1, height - 1])
    return box, w.min(axis=0)


def box_residual(projected: np.ndarray, detected: np.ndarray, min_depth: np.ndarray) -> np.ndarray:
    """Side differences ``(..., 4)`` of ``projected`` and ``detected`` boxes ``(..., 4)``,
    normalised by the detection diagonal (at least 1 px); boxes whose ``min_depth``
    ``(...)`` (:func:`project_boxes`) is 0.5 m or less, reaching behind or right up to the
    camera, get a large constant residual of 10.

    Examples
    --------
    >>> detected = np.array([0.0, 0.0, 30.0, 40.0])  # a diagonal of 50 px
    >>> box_residual(detected + [5, 0, 5, 0], detected, np.array(10.0))  # 5 px to the right
    array([0.1, 0. , 0.1, 0. ])
    >>> box_residual(detected, detected, np.array(0.2))  # a corner 0.2 m from the camera: refused
    array([10., 10., 10., 10.])
    """
    diag = np.hypot(detected[..., 2] - detected[..., 0], detected[..., 3] - detected[..., 1])
    r = (projected - detected) / np.maximum(diag, 1.0)[..., None]
    return np.where((min_depth > 0.5)[..., None], r, 10.0)


def _initial_position(camera: Camera, boxes, normal, height, dims):
    """Start each search where the ray through the bottom-centre of the 2D box meets the
    plane, pushed back by a quarter car length (the box bottom is the nearest part of the
    car); above-horizon rays fall back to the depth implied by the box height. ``normal``:
    the planes' downward unit normals ``(..., 3)``."""
    uv = np.stack([(boxes[..., 0] + boxes[..., 2]) / 2, boxes[..., 3]], axis=-1)
    ray = camera.rays(uv)
    c = camera.center
    denom = np.sum(normal * ray, axis=-1)
    t = (height - np.sum(normal * c, axis=-1)) / np.where(np.abs(denom) < 1e-6, 1e-6, denom)
    hit = c + t[..., None] * ray
    box_h = np.maximum(boxes[..., 3] - boxes[..., 1], 1.0)
    z_from_height = camera.focal * dims[..., 0] / box_h
    ok = (t > 0) & (hit[..., 2] > 1.0) & (hit[..., 2] < 150.0)
    z = np.where(ok, hit[..., 2] + 0.25 * dims[..., 2], z_from_height)
    x = np.where(ok, hit[..., 0], (uv[..., 0] - camera.K[0, 2]) * z / camera.focal)
    return x, z


def solve_positions(
    camera: Camera,
    boxes: np.ndarray,
    alpha: np.ndarray,
    pitch: np.ndarray,
    roll: np.ndarray,
    dims: np.ndarray,
    *,
    height: float = KITTI_CAMERA_HEIGHT,
    iterations: int = 8,
):
    """Positions on the plane whose projected boxes best match ``boxes``.

    All inputs broadcast to one batch shape ``B``: ``boxes (B..., 4)``, observation angle
    ``alpha``, plane ``pitch``/``roll``, ``dims (B..., 3)``. The object's azimuth follows
    from its observation angle and position (``rotation_y = alpha + atan2(x, z)``).

    Returns
    -------
    x, z, azimuth, cost : arrays of shape ``B``
        ``cost`` is the squared normalised box residual (0 = perfect fit).

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]], (1242, 375))
    >>> from wirescene.core.boxes import MEAN_CAR_DIMS, box_extent_object
    >>> from wirescene.core.groundplane import alpha_from_rotation_y, rotation_y
    >>> # the box of a mean car 15 m ahead, 3 m to the left, heading away (rotation_y -1.5)
    >>> box, _ = project_boxes(camera, *box_extent_object(MEAN_CAR_DIMS), np.array([-3.0, 1.65, 15.0]),
    ...                        rotation_y(-1.5))
    >>> alpha = alpha_from_rotation_y(-1.5, -3.0, 15.0)
    >>> x, z, azimuth, cost = solve_positions(camera, box, alpha, 0.0, 0.0, MEAN_CAR_DIMS)  # a level plane
    >>> round(float(x), 3), round(float(z), 3), round(float(azimuth), 3), bool(cost < 1e-12)  # found again
    (-3.0, 15.0, -1.5, True)
    >>> # a batch: one box tried on 5 planes x 19 observation angles
    >>> pitch, angles = np.deg2rad(np.linspace(-1, 1, 5))[:, None], alpha + np.deg2rad(np.arange(-9, 10) * 2.5)
    >>> [a.shape for a in solve_positions(camera, box, angles, pitch, 0.0, MEAN_CAR_DIMS)]
    [(5, 19), (5, 19), (5, 19), (5, 19)]
    """
    shape = np.broadcast_shapes(boxes.shape[:-1], np.shape(alpha), np.shape(pitch), np.shape(roll), dims.shape[:-1])
    boxes = np.broadcast_to(boxes, shape + (4,))
    lo, hi = box_extent_object(dims)  # before broadcasting: once per distinct size
    # The plane's rotation and normal once per distinct plane; the azimuth turns the
    # plane's axes in closed form (R = R_gp @ R_y), elementwise over the batch.
    R_gp = plane_rotation(pitch, roll)
    normal = R_gp[..., :, 1]
    P3, p4 = camera.P[:, :3], camera.P[:, 3]
    A = _components_first(np.matmul(P3, R_gp), len(shape), 2)  # (3 rows, 3 plane axes, batch...)
    a0, a1, a2 = A[:, 0], A[:, 1], A[:, 2]
    dims = np.broadcast_to(dims, shape + (3,))
    alpha = np.broadcast_to(alpha, shape)

    def residual(x, logz):
        z = np.exp(logz)
        az = alpha + np.arctan2(x, z)
        c, s = np.cos(az), np.sin(az)
        y = (height - normal[..., 0] * x - normal[..., 2] * z) / normal[..., 1]  # on the plane
        offset = np.stack([P3[i, 0] * x + P3[i, 1] * y + P3[i, 2] * z + p4[i] for i in range(3)])
        proj, min_depth = _projected_extent(camera, lo, hi, (c * a0 - s * a2, a1, s * a0 + c * a2), offset)
        return box_residual(proj, boxes, min_depth)

    x, z = _initial_position(camera, boxes, normal, height, dims)
    logz = np.log(np.maximum(z, 1.0))
    lam = np.full(shape, 1e-2)
    r = residual(x, logz)
    cost = np.sum(r**2, axis=-1)
    hx, hz = 1e-3, 1e-4
    for _ in range(iterations):
        jx = (residual(x + hx, logz) - r) / hx
        jz = (residual(x, logz + hz) - r) / hz
        a11 = np.sum(jx * jx, -1)
        a12 = np.sum(jx * jz, -1)
        a22 = np.sum(jz * jz, -1)
        g1 = np.sum(jx * r, -1)
        g2 = np.sum(jz * r, -1)
        a11d, a22d = a11 * (1 + lam) + 1e-12, a22 * (1 + lam) + 1e-12
        det = a11d * a22d - a12**2
        det = np.where(np.abs(det) < 1e-18, 1e-18, det)
        dx = -(a22d * g1 - a12 * g2) / det
        dz = -(a11d * g2 - a12 * g1) / det
        dz = np.clip(dz, -0.5, 0.5)
        dx = np.clip(dx, -5.0, 5.0)
        r_new = residual(x + dx, logz + dz)
        cost_new = np.sum(r_new**2, axis=-1)
        better = cost_new < cost
        x = np.where(better, x + dx, x)
        logz = np.where(better, logz + dz, logz)
        r = np.where(better[..., None], r_new, r)
        cost = np.where(better, cost_new, cost)
        lam = np.where(better, lam * 0.3, lam * 10.0)
    z = np.exp(logz)
    return x, z, wrap_angle(alpha + np.arctan2(x, z)), cost


@dataclass(frozen=True)
class LiftingTable:
    """Best coarse fit of every detection on every grid plane, arrays ``(N, G)``
    (the azimuth already chosen per cell); shared by the ``coarse`` and ``coarse+gp``
    particle selections so the grid search runs once per image."""

    pitch: np.ndarray  # (G,)
    roll: np.ndarray  # (G,)
    x: np.ndarray
    z: np.ndarray
    azimuth: np.ndarray
    cost: np.ndarray
    dims: np.ndarray  # (N, 3)
    height: float


def lift_table(
    camera: Camera,
    detections: Detections,
    *,
    options: LiftingOptions = LiftingOptions(),
    dims: np.ndarray | None = None,
) -> LiftingTable:
    """Grid search of the coarse stage: for every detection, plane and azimuth solve the
    position, then keep the best azimuth per (detection, plane): the least box cost plus
    :func:`road_alignment_cost` (the table's ``cost`` is the box cost alone).

    ``detections.alpha`` restricts the azimuth search to the viewpoint bin
    (+- ``options.azimuth_halfwidth``); NaN searches the full circle. ``dims`` ``(N, 3)``
    defaults to the mean KITTI car.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]], (1242, 375))
    >>> from wirescene.core.boxes import MEAN_CAR_DIMS, box_extent_object
    >>> from wirescene.core.groundplane import alpha_from_rotation_y, rotation_y
    >>> from wirescene.core.types import Detections
    >>> from wirescene.core.viewpoints import bin_center, viewpoint_bin
    >>> # two mean cars on KITTI's level road, their boxes as a perfect detector would give them
    >>> location, heading = np.array([[-3.0, 1.65, 15.0], [4.0, 1.65, 25.0]]), np.array([-1.5, 1.6])
    >>> boxes, _ = project_boxes(camera, *box_extent_object(MEAN_CAR_DIMS), location, rotation_y(heading))
    >>> alpha = alpha_from_rotation_y(heading, location[:, 0], location[:, 2])
    >>> detections = Detections(boxes, scores=1.0, alpha=bin_center(viewpoint_bin(alpha)))  # 45 deg bins
    >>> table = lift_table(camera, detections, options=LiftingOptions(pitch_range=0.5, roll_range=0.25))
    >>> table.pitch.shape, table.cost.shape  # 5 pitches x 3 rolls: 15 planes, a row of them a detection
    ((15,), (2, 15))
    >>> table.dims.tolist()[0]  # the mean KITTI car (h, w, l)
    [1.53, 1.63, 3.88]
    """
    n = len(detections)
    if n == 0:
        raise ValueError("lifting needs at least one detection")
    dims = np.broadcast_to(MEAN_CAR_DIMS if dims is None else np.asarray(dims, float), (n, 3))
    pitch_g, roll_g = options.plane_grid()  # (G,)
    known = np.isfinite(detections.alpha)
    offsets_known = options.alpha_offsets(True)
    offsets_unknown = options.alpha_offsets(False)
    # Pad the azimuth axis to a common length so all detections are solved in one batch;
    # padded cells repeat the last offset and cannot win over their original.
    n_az = max(len(offsets_known) if known.any() else 0, len(offsets_unknown) if (~known).any() else 0)
    alpha = np.empty((n, n_az))
    for j in range(n):
        off = offsets_known if known[j] else offsets_unknown
        base = detections.alpha[j] if known[j] else 0.0
        alpha[j] = base + np.concatenate([off, np.full(n_az - len(off), off[-1])])
    G = len(pitch_g)
    x, z, az, cost = (np.empty((n, G)) for _ in range(4))
    # A cell's temporaries take about 1 kB: a block of cells at a time, whose bits no other cell changes.
    rows_per, planes_per = _block_shape(n, G, n_az, cells=LIFT_BLOCK_CELLS)
    for d in range(0, n, rows_per):
        for g in range(0, G, planes_per):
            rows, cols = slice(d, d + rows_per), slice(g, g + planes_per)
            block = solve_positions(
                camera,
                detections.boxes[rows, None, None, :],
                alpha[rows, None, :],
                pitch_g[None, cols, None],
                roll_g[None, cols, None],
                dims[rows, None, None, :],
                height=options.camera_height,
                iterations=options.iterations,
            )
            choice = block[3]
            if options.road_prior:
                choice = block[3] + road_alignment_cost(block[2], weight=options.road_prior, width=ROAD_PRIOR_WIDTH)
            best_a = np.argmin(choice, axis=2)[..., None]  # (rows, planes, 1)
            for out, a in zip((x, z, az, cost), block):
                out[rows, cols] = np.take_along_axis(a, best_a, axis=2)[..., 0]
    return LiftingTable(pitch_g, roll_g, x, z, az, cost, np.array(dims), options.camera_height)


def _block_shape(n: int, planes: int, azimuths: int, *, cells: int) -> tuple[int, int]:
    """Detections and planes of one block of the grid search: all detections and as many
    planes as fit ``cells`` (detection, plane, azimuth) cells, or, where one plane of all
    detections does not, one plane of as many detections as fit (at least one)."""
    planes_per = min(planes, max(1, cells // (n * azimuths)))
    rows_per = min(n, max(1, cells // (planes_per * azimuths)))
    return rows_per, planes_per


def road_alignment_cost(azimuth, *, weight: float, width: float) -> np.ndarray:
    """Cost of the prior that cars head along the camera's road, same shape as
    ``azimuth`` (KITTI ``rotation_y`` in the ground plane's frame, radians):
    ``weight * (1 - exp(-sin(d)**2 / (2 sin(width)**2)))``, ``d`` the heading's angle to
    the road (rotation_y = +-90 deg) and ``width`` in degrees. 0 along the road, near
    ``weight`` across it (within 5% of it beyond 60 deg, so a car across the road is
    left to its box); the same front and back. See :class:`LiftingOptions`.

    Examples
    --------
    >>> cost = road_alignment_cost(np.deg2rad([90.0, -90.0, 60.0, 0.0]), weight=0.03, width=20.0)
    >>> np.round(cost, 4)  # along the road (either way), 30 deg off it, across it
    array([0.    , 0.    , 0.0197, 0.0296])
    """
    # cos(rotation_y) is the sine of the heading's angle to the road (the camera's z axis).
    s2 = np.cos(azimuth) ** 2 / (2 * np.sin(np.deg2rad(width)) ** 2)
    return weight * -np.expm1(-s2)


def road_angle(azimuth) -> np.ndarray:
    """Angle (radians, in [0, pi/2]) between a heading of KITTI ``rotation_y``
    ``azimuth`` and the camera's road (rotation_y = +-90 deg), front and back alike.

    Examples
    --------
    >>> np.rad2deg(road_angle(np.deg2rad([-90.0, 90.0, 60.0, -120.0, 0.0]))).round(6)
    array([ 0.,  0., 30., 30., 90.])
    """
    return np.arcsin(np.minimum(np.abs(np.cos(azimuth)), 1.0))


def plane_vote_weights(scores: np.ndarray) -> np.ndarray:
    """Weights ``(N,)`` of the detections' votes for a shared ground plane: their scores
    when all lie in [0, 1] (probabilities that the box is a car, as our calibrated
    pre-detections and label boxes give), else equal weights (scores on another scale,
    e.g. an external detector's margins, say nothing comparable).

    Examples
    --------
    >>> plane_vote_weights([0.9, 0.2]), plane_vote_weights([3.5, -1.0])
    (array([0.9, 0.2]), array([1., 1.]))
    """
    s = np.asarray(scores, dtype=float).reshape(-1)
    if len(s) and np.all((s >= 0) & (s <= 1)) and s.sum() > 0:
        return s
    return np.ones(len(s))


def select_particles(
    table: LiftingTable, *, shared_plane: bool, n_particles: int = 250, robust_cost: float | None = None,
    weights: np.ndarray | None = None,
) -> SceneParticles:
    """Scene particles from a lifting table, best first.

    With ``shared_plane`` (``coarse+gp``) particle ``k`` is the ``k``-th best plane by
    the ``weights``-weighted sum (default: equal; see :func:`plane_vote_weights`) of
    per-object costs, each capped at ``robust_cost`` so one bad detection cannot veto a
    plane, and weighted so that likely false detections, which stand anywhere, do not
    outvote the cars; without (``coarse``) particle ``k`` gives every object its own
    ``k``-th best plane. ``robust_cost`` defaults to ``LiftingOptions().robust_cost``.

    Returns ``min(n_particles, G)`` particles of the table's ``N`` objects.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]], (1242, 375))
    >>> from wirescene.core.boxes import MEAN_CAR_DIMS, box_extent_object
    >>> from wirescene.core.groundplane import alpha_from_rotation_y, rotation_y
    >>> from wirescene.core.types import Detections
    >>> from wirescene.core.viewpoints import bin_center, viewpoint_bin
    >>> # two mean cars on KITTI's level road, their boxes as a perfect detector would give them
    >>> location, heading = np.array([[-3.0, 1.65, 15.0], [4.0, 1.65, 25.0]]), np.array([-1.5, 1.6])
    >>> boxes, _ = project_boxes(camera, *box_extent_object(MEAN_CAR_DIMS), location, rotation_y(heading))
    >>> alpha = alpha_from_rotation_y(heading, location[:, 0], location[:, 2])
    >>> detections = Detections(boxes, scores=1.0, alpha=bin_center(viewpoint_bin(alpha)))  # 45 deg bins
    >>> table = lift_table(camera, detections, options=LiftingOptions(pitch_range=0.5, roll_range=0.25))
    >>> shared = select_particles(table, shared_plane=True, n_particles=4)
    >>> shared.x.shape, bool((shared.pitch[:, 0] == shared.pitch[:, 1]).all())  # one plane for both cars
    ((4, 2), True)
    >>> select_particles(table, shared_plane=False, n_particles=100).n_particles  # no more than the 15 planes
    15
    """
    robust_cost = LiftingOptions().robust_cost if robust_cost is None else robust_cost
    n, G = table.cost.shape
    k = min(n_particles, G)
    if shared_plane:
        w = np.ones(n) if weights is None else np.asarray(weights, dtype=float).reshape(n)
        total = w @ np.minimum(table.cost, robust_cost) + 1e-3 * (w @ table.cost)
        order = np.argsort(total, kind="stable")[:k]
        cols = np.broadcast_to(order[:, None], (k, n))  # (P, N) plane index per object
    else:
        cols = np.argsort(table.cost, axis=1, kind="stable")[:, :k].T
    rows = np.broadcast_to(np.arange(n)[None, :], (k, n))
    return SceneParticles(
        pitch=table.pitch[cols],
        roll=table.roll[cols],
        x=table.x[rows, cols],
        z=table.z[rows, cols],
        azimuth=table.azimuth[rows, cols],
        object_cost=table.cost[rows, cols],
        dims=np.broadcast_to(table.dims, (k, n, 3)).copy(),
        height=table.height,
        shared_plane=shared_plane,
    )


def lift_detections(
    camera: Camera,
    detections: Detections,
    *,
    shared_plane: bool,
    options: LiftingOptions = LiftingOptions(),
    dims: np.ndarray | None = None,
) -> SceneParticles:
    """Coarse 3D scene particles for the detections of one image
    (:func:`lift_table` then :func:`select_particles`).

    ``shared_plane=True`` gives ``coarse+gp`` (one plane for all objects), ``False``
    gives ``coarse``. Returns ``min(options.n_particles, grid planes)`` particles
    sorted by cost.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]], (1242, 375))
    >>> from wirescene.core.boxes import MEAN_CAR_DIMS, box_extent_object
    >>> from wirescene.core.groundplane import alpha_from_rotation_y, rotation_y
    >>> from wirescene.core.types import Detections
    >>> from wirescene.core.viewpoints import bin_center, viewpoint_bin
    >>> # two mean cars on KITTI's level road, their boxes as a perfect detector would give them
    >>> location, heading = np.array([[-3.0, 1.65, 15.0], [4.0, 1.65, 25.0]]), np.array([-1.5, 1.6])
    >>> boxes, _ = project_boxes(camera, *box_extent_object(MEAN_CAR_DIMS), location, rotation_y(heading))
    >>> alpha = alpha_from_rotation_y(heading, location[:, 0], location[:, 2])
    >>> detections = Detections(boxes, scores=1.0, alpha=bin_center(viewpoint_bin(alpha)))  # 45 deg bins
    >>> options = LiftingOptions(pitch_range=0.5, roll_range=0.25, n_particles=10)  # a small grid: fast
    >>> particles = lift_detections(camera, detections, shared_plane=True, options=options)
    >>> particles.n_particles, particles.n_objects
    (10, 2)
    >>> found, R = particles.poses()  # the best particle first
    >>> bool(np.abs(found[0] - location).max() < 0.1)  # both cars within 10 cm, from viewpoint bins alone
    True
    """
    table = lift_table(camera, detections, options=options, dims=dims)
    return select_particles(
        table, shared_plane=shared_plane, n_particles=options.n_particles, robust_cost=options.robust_cost,
        weights=plane_vote_weights(detections.scores),
    )
