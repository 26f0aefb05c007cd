"""Ground plane parametrised by pitch and roll relative to the camera, with a known
camera height, and placement of objects (x, z, azimuth) on it.

The plane through the points ``X`` with ``n . X = height`` has the downward unit
normal ``n = R_gp @ (0, 1, 0)`` where ``R_gp = R_x(pitch) @ R_z(roll)``. A level
plane (pitch = roll = 0) is ``y = height``. Objects stand on the plane: an object
point ``X_obj`` (object frame: x forward, y down, z to the car's left, ground at
``y = 0``) lands at ``R_gp @ R_y(azimuth) @ X_obj + location``. On a level plane this
is exactly KITTI's convention with ``rotation_y = azimuth``.

All functions broadcast over leading dimensions, so that one call places a whole batch
of hypotheses (particles x objects).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

KITTI_CAMERA_HEIGHT = 1.65  # metres, the KITTI recording platform


class Mount(NamedTuple):
    """Where a camera sits on its car: ``height`` metres above the road, looking ``pitch``
    degrees down from it (``LiftingOptions.camera_height`` and ``camera_pitch``; KITTI's
    rig, :data:`KITTI_MOUNT`: 1.65 m, level).

    Examples
    --------
    >>> Mount(1.3, pitch=4.0)
    Mount(height=1.3, pitch=4.0)
    """

    height: float = KITTI_CAMERA_HEIGHT
    pitch: float = 0.0


KITTI_MOUNT = Mount()


def rotation_x(angle) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about the camera x axis, for angles ``(...)`` in radians.

    Examples
    --------
    >>> R = rotation_x(np.deg2rad([0.0, 90.0]))
    >>> R.shape
    (2, 3, 3)
    >>> np.round(R[1] @ [0.0, 1.0, 0.0], 6)  # +90 deg turns y (down) into z (forward)
    array([0., 0., 1.])
    """
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rotation_y(angle) -> np.ndarray:
    """KITTI ``rotation_y`` matrices ``(..., 3, 3)`` (about the downward y axis), for angles
    ``(...)`` in radians: the object's x axis (its heading) goes to
    ``(cos a, 0, -sin a)``.

    Examples
    --------
    >>> np.round(rotation_y(0.0) @ [1.0, 0.0, 0.0], 6)  # rotation_y = 0: heading right (+x)
    array([1., 0., 0.])
    >>> np.round(rotation_y(np.pi / 2) @ [1.0, 0.0, 0.0], 6)  # +90 deg: heading towards the camera (-z)
    array([ 0.,  0., -1.])
    >>> rotation_y(np.zeros((4, 2))).shape
    (4, 2, 3, 3)
    """
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rotation_z(angle) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about the optical (z) axis, for angles ``(...)`` in radians.

    Examples
    --------
    >>> np.round(rotation_z(np.pi / 2) @ [1.0, 0.0, 0.0], 6)  # +90 deg turns x (right) into y (down)
    array([0., 1., 0.])
    """
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def plane_rotation(pitch, roll) -> np.ndarray:
    """``R_gp = R_x(pitch) @ R_z(roll)`` ``(..., 3, 3)`` taking a level plane to one with
    this pitch and roll (radians, broadcasting).

    Examples
    --------
    >>> plane_rotation(0.0, 0.0)  # a level plane
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    >>> plane_rotation(np.zeros(5), np.zeros((3, 1))).shape  # a grid of 3 rolls x 5 pitches
    (3, 5, 3, 3)
    """
    return rotation_x(pitch) @ rotation_z(roll)


def plane_normal(pitch, roll) -> np.ndarray:
    """Downward unit normals ``(..., 3)`` of planes with the given pitch and roll (radians):
    ``(-sin roll, cos pitch cos roll, sin pitch cos roll)``.

    Examples
    --------
    >>> plane_normal(0.0, 0.0)  # a level road: straight down
    array([0., 1., 0.])
    >>> np.round(plane_normal(np.deg2rad(5.0), 0.0), 4)  # pitched 5 deg: the road rises ahead
    array([0.    , 0.9962, 0.0872])
    """
    return plane_rotation(pitch, roll)[..., :, 1]


def point_on_plane(x, z, pitch, roll, height=KITTI_CAMERA_HEIGHT) -> np.ndarray:
    """The point ``(..., 3)`` of the plane above/below camera-frame ``(x, z)`` (metres),
    for a plane of ``pitch`` and ``roll`` (radians) ``height`` metres below the camera.

    Examples
    --------
    >>> point_on_plane(2.0, 10.0, 0.0, 0.0)  # a level road is y = 1.65 m below the camera
    array([ 2.  ,  1.65, 10.  ])
    >>> p = point_on_plane(0.0, 10.0, np.deg2rad(5.0), 0.0)  # pitched 5 deg: 10 m ahead it is higher
    >>> round(float(p[1]), 4), round(float((1.65 - 10 * np.sin(np.deg2rad(5.0))) / np.cos(np.deg2rad(5.0))), 4)
    (0.7814, 0.7814)
    """
    n = plane_normal(pitch, roll)
    x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
    y = (np.asarray(height, dtype=float) - n[..., 0] * x - n[..., 2] * z) / n[..., 1]
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def object_pose(x, z, azimuth, pitch=0.0, roll=0.0, height=KITTI_CAMERA_HEIGHT):
    """Pose of objects standing on a plane.

    Returns
    -------
    location : (..., 3) array
        Bottom centre of the object (on the plane), camera frame.
    R : (..., 3, 3) array
        Object-to-camera rotation ``R_gp @ R_y(azimuth)``, of the broadcast shape of
        ``azimuth``, ``pitch`` and ``roll`` only (``x`` and ``z`` do not enlarge it).

    Examples
    --------
    >>> location, R = object_pose(2.0, 10.0, np.pi / 2)  # level plane: KITTI's location and rotation_y
    >>> location.tolist(), bool(np.allclose(R, rotation_y(np.pi / 2)))
    ([2.0, 1.65, 10.0], True)
    >>> x, z, azimuth = np.zeros((250, 3)), np.full((250, 3), 10.0), np.zeros((250, 3))  # particles x cars
    >>> location, R = object_pose(x, z, azimuth, pitch=0.02)
    >>> location.shape, R.shape
    ((250, 3, 3), (250, 3, 3, 3))
    """
    location = point_on_plane(x, z, pitch, roll, height)
    R = plane_rotation(pitch, roll) @ rotation_y(azimuth)
    return location, R


def transform(points_obj: np.ndarray, location: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Object-frame points ``(..., V, 3)`` to the camera frame, ``R @ X + location``, given
    ``location`` ``(..., 3)`` and ``R`` ``(..., 3, 3)`` (arrays; the batch axes broadcast).

    Examples
    --------
    >>> front_and_roof = np.array([[2.0, 0.0, 0.0], [0.0, -1.5, 0.0]])  # object frame: x forward, y down
    >>> np.round(transform(front_and_roof, np.array([0.0, 1.65, 10.0]), rotation_y(np.pi / 2)), 6)
    array([[ 0.  ,  1.65,  8.  ],
           [ 0.  ,  0.15, 10.  ]])
    """
    # matmul, not einsum: 2.5x faster on large batches of small matrices
    X = np.matmul(points_obj, np.swapaxes(R, -1, -2))
    offset = np.asarray(location)[..., None, :]
    if np.broadcast_shapes(X.shape, offset.shape) != X.shape or np.result_type(X, offset) != X.dtype:
        return X + offset
    # In place, a component at a time where the product has the sum's shape and type: the same
    # sums, in long loops over the points rather than short ones of 3.
    for k in range(X.shape[-1]):
        X[..., k] += offset[..., k]
    return X


def rotation_y_of(R: np.ndarray) -> np.ndarray:
    """KITTI ``rotation_y`` ``(...)`` of object rotations ``(..., 3, 3)``: the heading
    (object x axis) angle about the camera's y axis, radians in ``[-pi, pi]``.

    Examples
    --------
    >>> round(float(rotation_y_of(rotation_y(2.5))), 6)
    2.5
    >>> rotation_y_of(rotation_y(np.zeros((4, 2)))).shape
    (4, 2)
    """
    heading = R[..., :, 0]
    return np.arctan2(-heading[..., 2], heading[..., 0])


def wrap_angle(a):
    """Angles (radians) wrapped to ``[-pi, pi)``.

    Examples
    --------
    >>> np.round(wrap_angle([np.pi, 1.5 * np.pi, -0.5]), 4)  # pi itself becomes -pi
    array([-3.1416, -1.5708, -0.5   ])
    """
    return (np.asarray(a, dtype=float) + np.pi) % (2 * np.pi) - np.pi


def alpha_from_rotation_y(rotation_y, x, z):
    """KITTI observation angle ``alpha = rotation_y - atan2(x, z)`` (radians, wrapped to
    ``[-pi, pi)``) from ``rotation_y`` and the camera-frame location ``(x, z)``.

    Examples
    --------
    >>> round(float(alpha_from_rotation_y(0.3, 0.0, 10.0)), 6)  # straight ahead: alpha = rotation_y
    0.3
    >>> round(float(alpha_from_rotation_y(0.0, 10.0, 10.0)), 4)  # 45 deg to the right: -pi / 4
    -0.7854
    >>> # a car of the sample frame 000010's labels: alpha 1.95, rotation_y 1.76 at x = -2.39, z = 11.80
    >>> round(float(alpha_from_rotation_y(1.76, -2.39, 11.80)), 2)
    1.96
    """
    return wrap_angle(np.asarray(rotation_y) - np.arctan2(x, z))


def rotation_y_from_alpha(alpha, x, z):
    """Inverse of :func:`alpha_from_rotation_y`: ``rotation_y = alpha + atan2(x, z)``, wrapped.

    Examples
    --------
    >>> round(float(rotation_y_from_alpha(alpha_from_rotation_y(1.2, -3.0, 15.0), -3.0, 15.0)), 6)
    1.2
    """
    return wrap_angle(np.asarray(alpha) + np.arctan2(x, z))


@dataclass(frozen=True)
class GroundPlane:
    """A ground plane: pitch and roll (radians) and camera height above it (metres).

    Examples
    --------
    >>> GroundPlane().normal  # KITTI's level road, 1.65 m below the camera
    array([0., 1., 0.])
    >>> location, R = GroundPlane().place(2.0, 10.0, 0.0)  # a car standing on it (see object_pose)
    >>> location.tolist()
    [2.0, 1.65, 10.0]
    >>> # recover a plane pitched 2 deg and rolled -1 deg from points on it
    >>> x, z = np.meshgrid([-5.0, 0.0, 5.0], [8.0, 15.0, 30.0])
    >>> points = point_on_plane(x.ravel(), z.ravel(), np.deg2rad(2.0), np.deg2rad(-1.0), height=1.5)
    >>> plane = GroundPlane.fit(points)
    >>> round(float(np.rad2deg(plane.pitch)), 3), round(float(np.rad2deg(plane.roll)), 3), round(plane.height, 3)
    (2.0, -1.0, 1.5)
    """

    pitch: float = 0.0
    roll: float = 0.0
    height: float = KITTI_CAMERA_HEIGHT

    @property
    def normal(self) -> np.ndarray:
        """(3,) downward unit normal."""
        return plane_normal(self.pitch, self.roll)

    def place(self, x, z, azimuth):
        """See :func:`object_pose`."""
        return object_pose(x, z, azimuth, self.pitch, self.roll, self.height)

    def to_dict(self) -> dict:
        """``{"pitch", "roll", "height"}`` as plain floats (JSON-ready)."""
        return {"pitch": float(self.pitch), "roll": float(self.roll), "height": float(self.height)}

    @staticmethod
    def fit(points: np.ndarray, height: float | None = None) -> "GroundPlane":
        """Least-squares plane through ground contact points ``(N, 3)`` (N >= 3, camera frame,
        metres; see the class's example).

        With ``height`` given only pitch and roll are estimated; otherwise the
        camera height is estimated too.
        """
        points = np.asarray(points, dtype=float)
        centroid = points.mean(axis=0)
        _, _, vt = np.linalg.svd(points - centroid)
        n = vt[-1] * np.sign(vt[-1][1] or 1.0)
        # n = R_x(pitch) R_z(roll) e_y = (-sin r, cos p cos r, sin p cos r)
        roll = float(np.arcsin(np.clip(-n[0], -1, 1)))
        pitch = float(np.arctan2(n[2], n[1]))
        h = float(n @ centroid) if height is None else float(height)
        return GroundPlane(pitch, roll, h)
