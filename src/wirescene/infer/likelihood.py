"""The object likelihood of the paper (Sec. 4.2, Eqs. 2-4), vectorised over any batch
of hypotheses (particles x objects x samples).

For one object hypothesis with vertex evidence ``e_j = log(S_j / S_b)`` at the projected
vertices (maximised over detector scale by the evidence provider):

    L = ( sum_j o_j(a) e_j + (o_j(a0) - o_j(a)) c ) / sum_j o_j(a0)

where ``o_j(a0)`` is 1 for vertices that are not self-occluded and ``o_j(a)`` is 1 for
those also not covered by the object's occluder mask ``a``; occluded parts score the
constant ``c``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wirescene.core.arrays import point_bounds
from wirescene.core.camera import NEAR_PLANE, Camera
from wirescene.core.errors import check_shape
from wirescene.core.groundplane import object_pose, transform
from wirescene.core.shape import ShapeModel
from wirescene.core.wireframe import FACES, N_VERTICES
from wirescene.infer.occlusion import self_occlusion


class PartEvidence(Protocol):
    """Per-vertex image evidence of one image, e.g. part-detector response maps."""

    def log_ratio(self, uv: np.ndarray, obj: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """``log(S_j / S_b)`` ``(..., 36)`` at pixels ``uv`` ``(..., 36, 2)`` for the
        detection ``obj`` ``(...)`` of each hypothesis, whose projected car length in
        pixels is ``scale`` ``(...)``."""


def object_likelihood(evidence: np.ndarray, self_hidden: np.ndarray, mask_hidden: np.ndarray | None, *, c: float) -> np.ndarray:
    """Paper Eq. 2 for a batch: ``evidence``, ``self_hidden``, ``mask_hidden`` are
    ``(..., V)``; returns ``(...)``.

    Examples
    --------
    >>> evidence = np.array([2.0, 2.0, -1.0, -1.0])
    >>> self_hidden = np.array([False, False, False, True])  # vertex 3 does not count
    >>> mask_hidden = np.array([False, False, True, False])  # vertex 2 occluded: scores c
    >>> float(object_likelihood(evidence, self_hidden, mask_hidden, c=0.5))  # (2 + 2 + 0.5) / 3
    1.5
    >>> float(object_likelihood(evidence, self_hidden, None, c=0.5))  # (2 + 2 - 1) / 3
    1.0
    """
    evidence = np.asarray(evidence, dtype=float)
    visible0 = ~np.asarray(self_hidden, dtype=bool)
    if mask_hidden is None:
        masked = np.zeros_like(visible0)
    else:
        masked = visible0 & np.asarray(mask_hidden, dtype=bool)
    visible = visible0 & ~masked
    num = np.where(visible, evidence, 0.0).sum(axis=-1) + c * masked.sum(axis=-1)
    return num / np.maximum(visible0.sum(axis=-1), 1)


def outside_image(camera: Camera, uv: np.ndarray) -> np.ndarray:
    """``(...)`` bool: which pixels ``uv`` ``(..., 2)`` fall outside the camera's image
    (all False when its ``image_size`` is unknown). A part projected there is hidden by
    the image border, an occluder known without search (the paper's truncation mode).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> cam = Camera(np.hstack([np.eye(3), np.zeros((3, 1))]), (100, 50))
    >>> outside_image(cam, np.array([[10.0, 10.0], [-1.0, 10.0], [10.0, 60.0]])).tolist()
    [False, True, True]
    """
    uv = np.asarray(uv, dtype=float)
    check_shape("uv", uv, (..., 2))
    if camera.image_size is None:
        return np.zeros(uv.shape[:-1], dtype=bool)
    width, height = camera.image_size
    return (uv[..., 0] < 0) | (uv[..., 0] > width - 1) | (uv[..., 1] < 0) | (uv[..., 1] > height - 1)


@dataclass
class WireframeBatch:
    """Geometry of a batch of wireframe hypotheses, everything ``(..., 36, ...)``.

    Examples
    --------
    >>> from wirescene.fitting.models import load_shape_model
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> def place(x):  # two cars, at (x, 12 m) and (3 m, 20 m), the mean shape (5 coefficients 0)
    ...     return instantiate_wireframes(camera, load_shape_model(), x=np.array([[x, 3.0]]), z=np.array([[12.0, 20.0]]),
    ...                                   azimuth=np.array([[0.3, 1.5]]), pitch=np.zeros((1, 2)), roll=np.zeros((1, 2)),
    ...                                   shape=np.zeros((1, 2, 5)), height=1.65)
    >>> batch = place(-2.0)
    >>> batch.vertices.shape, batch.uv.shape, batch.self_hidden.shape, batch.scale.shape
    ((1, 2, 36, 3), (1, 2, 36, 2), (1, 2, 36), (1, 2))
    >>> batch.location  # bottom centres on the road, 1.65 m below the camera
    array([[[-2.  ,  1.65, 12.  ],
            [ 3.  ,  1.65, 20.  ]]])
    """

    vertices: np.ndarray  # (..., 36, 3) camera frame
    location: np.ndarray  # (..., 3) bottom centre of the shape model origin
    R: np.ndarray  # (..., 3, 3)
    uv: np.ndarray  # (..., 36, 2)
    depth: np.ndarray  # (..., 36)
    self_hidden: np.ndarray  # (..., 36) bool
    scale: np.ndarray  # (...) projected length in pixels
    extent: tuple[np.ndarray, np.ndarray]  # object-frame lo, hi (..., 3): the 3D box KITTI would label


def instantiate_wireframes(
    camera: Camera,
    shape_model: ShapeModel,
    *,
    x, z, azimuth, pitch, roll, shape, height: float,
    device: str = "numpy",
) -> WireframeBatch:
    """Place shape-model wireframes with coefficients ``shape`` ``(..., K)`` at
    ``(x, z, azimuth)`` on planes ``(pitch, roll)`` (all ``(...)``), project them and
    compute self-occlusion by ray casting against the wireframe's own faces (on
    ``device``, see :func:`wirescene.infer.occlusion.self_occlusion`).

    Examples
    --------
    >>> from wirescene.fitting.models import load_shape_model
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> def place(x):  # two cars, at (x, 12 m) and (3 m, 20 m), the mean shape (5 coefficients 0)
    ...     return instantiate_wireframes(camera, load_shape_model(), x=np.array([[x, 3.0]]), z=np.array([[12.0, 20.0]]),
    ...                                   azimuth=np.array([[0.3, 1.5]]), pitch=np.zeros((1, 2)), roll=np.zeros((1, 2)),
    ...                                   shape=np.zeros((1, 2, 5)), height=1.65)
    >>> batch = place(-2.0)
    >>> batch.uv.shape, batch.self_hidden.dtype.name  # (...) = (1, 2): one particle, two cars
    ((1, 2, 36, 2), 'bool')
    >>> lo, hi = batch.extent  # the object-frame box of each wireframe: x length, y height, z width
    >>> size = hi - lo
    >>> size.shape, bool(np.all(size[..., 0] > size[..., 2]))  # longer than wide
    ((1, 2, 3), True)
    """
    shape = np.asarray(shape, dtype=float)
    check_shape("shape", shape, (..., None))
    X_obj = shape_model.instantiate(shape)
    location, R = object_pose(x, z, azimuth, pitch, roll, height)
    vertices = transform(X_obj, location, R)
    uv, depth = camera.project_with_depth(vertices)
    hidden = self_occlusion(vertices, FACES, camera.center, device=device)
    # The projected car length sets the part-detector scale.
    lo, hi = point_bounds(X_obj)
    length = hi[..., 0] - lo[..., 0]
    scale = camera.focal * length / np.maximum(np.linalg.norm(location - camera.center, axis=-1), 0.5)
    return WireframeBatch(vertices, location, R, uv, depth, hidden, scale, (lo, hi))


def wireframe_likelihood(
    batch: WireframeBatch,
    evidence: PartEvidence,
    obj: np.ndarray,
    *,
    c: float,
    mask_hidden: np.ndarray | None = None,
) -> np.ndarray:
    """Object likelihood ``(...)`` of placed wireframes against image evidence.
    Vertices behind the camera count as hidden.

    Examples
    --------
    >>> from wirescene.fitting.models import load_shape_model
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> def place(x):  # two cars, at (x, 12 m) and (3 m, 20 m), the mean shape (5 coefficients 0)
    ...     return instantiate_wireframes(camera, load_shape_model(), x=np.array([[x, 3.0]]), z=np.array([[12.0, 20.0]]),
    ...                                   azimuth=np.array([[0.3, 1.5]]), pitch=np.zeros((1, 2)), roll=np.zeros((1, 2)),
    ...                                   shape=np.zeros((1, 2, 5)), height=1.65)
    >>> batch = place(-2.0)
    >>> evidence = GaussianVertexEvidence(batch.uv[0], np.ones((2, 36), bool))  # peaks at these wireframes
    >>> wireframe_likelihood(batch, evidence, np.array([0, 1]), c=0.5)  # every counted vertex at its peak
    array([[2., 2.]])
    >>> wireframe_likelihood(place(-1.0), evidence, np.array([0, 1]), c=0.5).round(3)  # car 0 a metre aside
    array([[-1.,  2.]])
    """
    check_shape("uv", batch.uv, (..., N_VERTICES, 2))
    self_hidden = batch.self_hidden | (batch.depth <= NEAR_PLANE)
    e = evidence.log_ratio(batch.uv, np.broadcast_to(obj, batch.scale.shape), batch.scale)
    return object_likelihood(e, self_hidden, mask_hidden, c=c)


class GaussianVertexEvidence:
    """Evidence that peaks at known 2D vertex positions: ``peak`` at the true position,
    falling off as a Gaussian of ``sigma_frac`` times the car's projected length to
    ``floor``. Used to test inference and as an oracle upper bound of what perfect part
    detectors would give.

    Parameters
    ----------
    uv_true : (N, 36, 2) array
        True vertex positions of each detection's car.
    visible : (N, 36) bool array
        Which true vertices have evidence (occluded ones have none).
    sigma_frac : float, optional
        The Gaussian's width, a fraction of the car's projected length.
    peak, floor : float, optional
        The log ratio at the true position and far from it (and at vertices without
        evidence).

    Examples
    --------
    >>> uv_true = np.zeros((1, 36, 2))  # one detection, every true vertex at (0, 0)
    >>> evidence = GaussianVertexEvidence(uv_true, [np.arange(36) < 18], sigma_frac=0.1)  # 18 vertices seen
    >>> e = evidence.log_ratio(np.zeros((36, 2)), 0, 100.0)  # at the true positions, a car 100 px long
    >>> float(e[0]), float(e[35])  # the peak where seen, the floor where not
    (2.0, -1.0)
    >>> round(float(evidence.log_ratio(np.full((36, 2), [10.0, 0.0]), 0, 100.0)[0]), 4)  # one sigma off
    0.8196
    """

    def __init__(self, uv_true, visible, *, sigma_frac: float = 0.03, peak: float = 2.0, floor: float = -1.0):
        self.uv_true = np.asarray(uv_true, dtype=float)
        self.visible = np.asarray(visible, dtype=bool)
        check_shape("uv_true", self.uv_true, (None, N_VERTICES, 2))
        # a (36,) mask would be read as one vertex's flag for every vertex of a car
        check_shape("visible", self.visible, self.uv_true.shape[:2])
        self.sigma_frac, self.peak, self.floor = sigma_frac, peak, floor

    def log_ratio(self, uv, obj, scale):
        uv = np.asarray(uv, dtype=float)
        obj = np.asarray(obj, dtype=int)
        d2 = np.sum((uv - self.uv_true[obj]) ** 2, axis=-1)
        sigma = self.sigma_frac * np.maximum(np.asarray(scale, float), 1.0)[..., None]
        g = np.exp(-0.5 * d2 / sigma**2)
        return np.where(self.visible[obj], self.floor + (self.peak - self.floor) * g, self.floor)
