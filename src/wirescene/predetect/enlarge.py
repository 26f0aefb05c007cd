"""An image enlarged for the pre-detection, and its detections brought back to the image's pixels.

The detector bank's smallest templates fit cars some 25 px high; a camera of KITTI's
resolution sees many cars smaller than that. Detecting on the image enlarged (Lanczos) and
dividing the boxes back finds many of them (``PredetectOptions.upsample``; held-out figures
in ``benchmarks/RESULTS.md``). A pixel centre ``u`` of the image lies at ``s (u + 0.5) - 0.5``
in the image enlarged by ``s``, on each axis with its own factor (the enlarged size is
rounded to whole pixels).
"""

from __future__ import annotations

import numpy as np
from PIL import Image

from wirescene.core.camera import Camera
from wirescene.core.types import Detections

#: Most pixels of an enlarged image (a 4K frame's): a larger image is enlarged less, one of as
#: many pixels not at all (its cars are large enough; the pre-detection's time and memory grow
#: with the pixels).
MAX_ENLARGED_PIXELS = 3840 * 2160


def enlarged_size(width: int, height: int, factor: float) -> tuple[int, int]:
    """``(width, height)`` of an image enlarged by ``factor``, within :data:`MAX_ENLARGED_PIXELS`.

    Examples
    --------
    >>> enlarged_size(1242, 375, 1.5)  # a KITTI frame
    (1863, 562)
    >>> enlarged_size(3840, 2160, 1.5)  # a 4K frame: as it is
    (3840, 2160)
    >>> enlarged_size(1242, 375, 1.0)
    (1242, 375)
    """
    factor = min(float(factor), float(np.sqrt(MAX_ENLARGED_PIXELS / (width * height))))
    if factor <= 1.0:
        return int(width), int(height)
    return round(width * factor), round(height * factor)


def scaled_projection(P, sx: float, sy: float | None = None) -> np.ndarray:
    """``P`` ``(3, 4)`` of the same camera whose image is resized by ``sx`` across and ``sy``
    down (default ``sx``): a pixel centre ``u`` moves to ``s (u + 0.5) - 0.5``.

    Examples
    --------
    >>> P = np.array([[700.0, 0, 600, 0], [0, 700, 180, 0], [0, 0, 1, 0]])
    >>> scaled_projection(P, 2.0)[:2, :3]
    array([[1400. ,    0. , 1200.5],
           [   0. , 1400. ,  360.5]])
    """
    sy = sx if sy is None else sy
    out = np.array(P, dtype=float)
    out[0] = sx * out[0] + 0.5 * (sx - 1.0) * out[2]
    out[1] = sy * out[1] + 0.5 * (sy - 1.0) * out[2]
    return out


def enlarge_frame(camera: Camera | None, image: np.ndarray, factor: float):
    """``(camera, image, (sx, sy))``: ``image`` ``(H, W, 3)`` uint8 enlarged by ``factor``
    (Lanczos; :func:`enlarged_size`) and the ``camera`` (or None) that sees it, with the
    factors each axis took; ``(camera, image, (1, 1))`` as they are where it is not enlarged.

    Examples
    --------
    >>> cam = Camera(np.array([[700.0, 0, 48, 0], [0, 700, 32, 0], [0, 0, 1, 0]]), (96, 64))
    >>> big_cam, big, factors = enlarge_frame(cam, np.zeros((64, 96, 3), np.uint8), 1.5)
    >>> big.shape, big_cam.image_size, factors
    ((96, 144, 3), (144, 96), (1.5, 1.5))
    """
    H, W = image.shape[:2]
    w, h = enlarged_size(W, H, factor)
    if (w, h) == (W, H):
        return camera, image, (1.0, 1.0)
    big = np.asarray(Image.fromarray(image).resize((w, h), Image.LANCZOS))
    sx, sy = w / W, h / H
    if camera is not None:
        camera = Camera(scaled_projection(camera.P, sx, sy), (w, h))
    return camera, big, (sx, sy)


def boxes_back(detections: Detections, factors: tuple[float, float]) -> Detections:
    """``detections`` of an image enlarged by ``factors`` ``(sx, sy)``
    (:func:`enlarge_frame`), their boxes in the original image's pixels; the scores and
    viewpoints as they are (a viewpoint does not change with the image's size).

    Examples
    --------
    >>> dets = Detections(np.array([[29.5, 14.5, 89.5, 44.5]]), np.ones(1), np.zeros(1))
    >>> boxes_back(dets, (1.5, 1.5)).boxes
    array([[19.5,  9.5, 59.5, 29.5]])
    """
    sx, sy = factors
    if (sx, sy) == (1.0, 1.0):
        return detections
    scale = np.array([sx, sy, sx, sy])
    return Detections((detections.boxes + 0.5) / scale - 0.5, detections.scores, detections.alpha, detections.source)
