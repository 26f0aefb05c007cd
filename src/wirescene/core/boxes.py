"""3D boxes of objects on the ground and their 2D image boxes.

A 3D box is given by KITTI dimensions ``(h, w, l)``, the bottom-centre ``location``
and the object-to-camera rotation ``R``; in the object frame it spans
``x in [-l/2, l/2]``, ``y in [-h, 0]``, ``z in [-w/2, w/2]``. 2D boxes are
``(x1, y1, x2, y2)`` in pixels.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.camera import Camera
from wirescene.core.errors import check_shape
from wirescene.core.groundplane import transform

# Mean KITTI car size in metres, from the statistics of the KITTI training split.
#: KITTI 'Car' size statistics in metres, in (l, w, h) order (mean and standard deviation).
KITTI_CAR_SIZE = {"mean": (3.88, 1.63, 1.53), "std": (0.43, 0.10, 0.14)}
#: The mean car as a KITTI box size ``(h, w, l)``, derived from :data:`KITTI_CAR_SIZE`.
MEAN_CAR_DIMS = np.array(KITTI_CAR_SIZE["mean"][::-1])

_UNIT_CORNERS = np.array(
    [[sx, sy, sz] for sx in (0.5, -0.5) for sy in (0.0, -1.0) for sz in (0.5, -0.5)]
)


def box_corners_object(dims) -> np.ndarray:
    """Corners ``(..., 8, 3)`` in the object frame of boxes with ``dims`` ``(..., 3)`` = (h, w, l).

    Corner ``k`` takes ``x = +l/2`` (the front) for ``k < 4``, ``y = 0`` (the ground) for
    even ``k // 2`` and ``z = +w/2`` (the car's left) for even ``k``.

    Examples
    --------
    >>> corners = box_corners_object([1.5, 1.6, 4.0])  # h, w, l in metres
    >>> corners.shape
    (8, 3)
    >>> corners[:4].tolist()  # the front face: x = l / 2, from the ground (y = 0) up to y = -h
    [[2.0, 0.0, 0.8], [2.0, 0.0, -0.8], [2.0, -1.5, 0.8], [2.0, -1.5, -0.8]]
    >>> box_corners_object(np.ones((5, 2, 3))).shape  # any leading batch axes
    (5, 2, 8, 3)
    """
    dims = np.asarray(dims, dtype=float)
    check_shape("dims", dims, (..., 3))
    scale = np.stack([dims[..., 2], dims[..., 0], dims[..., 1]], axis=-1)  # (l, h, w) per axis
    return _UNIT_CORNERS * scale[..., None, :]


def box_extent_object(dims) -> tuple[np.ndarray, np.ndarray]:
    """Object-frame ``lo, hi`` ``(..., 3)`` of boxes with ``dims`` ``(..., 3)`` = (h, w, l):
    the opposite corners of :func:`box_corners_object`.

    Examples
    --------
    >>> lo, hi = box_extent_object(np.array([1.5, 1.6, 4.0]))
    >>> lo.tolist(), hi.tolist()
    ([-2.0, -1.5, -0.8], [2.0, 0.0, 0.8])
    """
    dims = np.asarray(dims, dtype=float)
    check_shape("dims", dims, (..., 3))
    half_l, h, half_w = dims[..., 2] / 2, dims[..., 0], dims[..., 1] / 2
    return np.stack([-half_l, -h, -half_w], axis=-1), np.stack([half_l, np.zeros_like(h), half_w], axis=-1)


def box_corners(dims, location, R) -> np.ndarray:
    """Camera-frame corners ``(..., 8, 3)`` of boxes of ``dims`` ``(..., 3)`` = (h, w, l)
    placed with their bottom centre at ``location`` ``(..., 3)`` and object-to-camera
    rotation ``R`` ``(..., 3, 3)`` (corner order of :func:`box_corners_object`).

    Examples
    --------
    >>> from wirescene.core.groundplane import rotation_y
    >>> # a 4 m car 10 m ahead on the road (y down: the camera is 1.65 m above it), facing the camera
    >>> corners = box_corners([1.5, 1.6, 4.0], [0.0, 1.65, 10.0], rotation_y(np.pi / 2))
    >>> np.round(corners[:4], 3).tolist()  # its front face, 2 m nearer than the centre
    [[0.8, 1.65, 8.0], [-0.8, 1.65, 8.0], [0.8, 0.15, 8.0], [-0.8, 0.15, 8.0]]
    """
    return transform(box_corners_object(dims), np.asarray(location, float), np.asarray(R, float))


def box_centers(dims, location, R) -> np.ndarray:
    """3D centroids ``(..., 3)`` of the boxes (half a height above the bottom centre, along
    the box's own up axis ``-R[:, 1]``), for ``dims`` ``(..., 3)`` = (h, w, l), bottom-centre
    ``location`` ``(..., 3)`` and rotation ``R`` ``(..., 3, 3)``.

    Examples
    --------
    >>> box_centers([1.5, 1.6, 4.0], [0.0, 1.65, 10.0], np.eye(3))  # y points down
    array([ 0. ,  0.9, 10. ])
    """
    dims = np.asarray(dims, dtype=float)
    up = -np.asarray(R, float)[..., :, 1]
    return np.asarray(location, float) + 0.5 * dims[..., 0:1] * up


def project_points_to_box(camera: Camera, points: np.ndarray, *, clip: bool = True) -> np.ndarray:
    """Tight 2D boxes ``(..., 4)`` ``x1 y1 x2 y2`` around the projections of ``points``
    ``(..., V, 3)``, clipped to the image if the camera knows its size and ``clip`` is set.
    Points behind the camera are not treated specially (their projections are meaningless).

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera([[721.5, 0, 609.6, 0], [0, 721.5, 172.9, 0], [0, 0, 1, 0]], image_size=(1242, 375))
    >>> corners = box_corners([1.5, 1.6, 4.0], [0.0, 1.65, 10.0], np.eye(3))  # side on, 10 m ahead
    >>> box = project_points_to_box(camera, corners)
    >>> box.shape, np.round(box, 1).tolist()
    ((4,), [452.8, 182.9, 766.4, 302.3])
    >>> round(172.9 + 721.5 * 1.65 / 9.2, 1)  # y2: the near bottom edge, at z = 10 - w / 2
    302.3
    """
    uv = camera.project(points)
    box = np.concatenate([uv.min(axis=-2), uv.max(axis=-2)], axis=-1)
    if clip and camera.image_size is not None:
        w, h = camera.image_size
        box = np.clip(box, 0.0, [w - 1, h - 1, w - 1, h - 1])
    return box


def clip_boxes(boxes: np.ndarray, W: int, H: int) -> np.ndarray:
    """Boxes ``(D, 4)`` clipped to the pixels of a ``W x H`` image (``[0, W - 1] x [0, H - 1]``,
    as KITTI's labelled boxes and the lifting's projected ones are).

    Examples
    --------
    >>> clip_boxes(np.array([[-20.0, 100.0, 300.0, 400.0]]), 1242, 375)
    array([[  0., 100., 300., 374.]])
    """
    return np.column_stack([np.clip(boxes[:, 0], 0, W - 1), np.clip(boxes[:, 1], 0, H - 1),
                            np.clip(boxes[:, 2], 0, W - 1), np.clip(boxes[:, 3], 0, H - 1)])


def iou_2d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union of 2D boxes ``(..., 4)`` ``x1 y1 x2 y2`` (broadcasting);
    0 where both boxes are empty.

    Examples
    --------
    >>> float(iou_2d([0, 0, 10, 10], [5, 0, 15, 10]))  # 50 shared of 150 px^2
    0.3333333333333333
    >>> iou_2d([[0, 0, 10, 10]], [[0, 0, 10, 10], [20, 20, 30, 30]])  # one box against two
    array([1., 0.])
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = iw * ih
    area = lambda x: np.clip(x[..., 2] - x[..., 0], 0, None) * np.clip(x[..., 3] - x[..., 1], 0, None)  # noqa: E731
    union = area(a) + area(b) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
