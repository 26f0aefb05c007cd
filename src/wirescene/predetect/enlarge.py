"""An image enlarged for the pre-detection, its detections brought back to the image's pixels
and added to those of the image as it is.

The detector bank's smallest templates fit cars some 25 px high; a camera of KITTI's
resolution sees many cars smaller than that. Detecting on the image enlarged (Lanczos) too,
at the pyramid levels finer than the image's finest, and adding the cars found there that no
detection of the image covers, finds many of them (``PredetectOptions.upsample``); the cars
both find keep the boxes of the image as it is, which sit better (held-out figures in
``benchmarks/RESULTS.md``). A pixel centre ``u`` of the image lies at ``s (u + 0.5) - 0.5``
in the image enlarged by ``s``, on each axis with its own factor (the enlarged size is
rounded down to whole pixels).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from PIL import Image

from wirescene.core.boxes import clip_boxes, iou_2d
from wirescene.core.camera import Camera
from wirescene.core.types import Detections
from wirescene.predetect.bank import smallest_car_search

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
    return int(width * factor + 1e-9), int(height * factor + 1e-9)  # whole pixels, down: within the limit


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


def boxes_back(detections: Detections, factors: tuple[float, float], image_size: tuple[int, int]) -> Detections:
    """``detections`` of an image enlarged by ``factors`` ``(sx, sy)``
    (:func:`enlarge_frame`), their boxes in the pixels of the original ``image_size``
    ``(W, H)``, clipped to them as the bank clips its boxes to its image (the enlarged image's
    border lies half an enlarged pixel beyond the original's); the scores and viewpoints as
    they are (a viewpoint does not change with the image's size).

    Examples
    --------
    >>> dets = Detections(np.array([[29.5, 14.5, 89.5, 44.5], [0.0, 0.0, 30.0, 95.0]]), np.ones(2), np.zeros(2))
    >>> boxes_back(dets, (1.5, 1.5), (96, 64)).boxes  # the second from the enlarged image's corner
    array([[19.5       ,  9.5       , 59.5       , 29.5       ],
           [ 0.        ,  0.        , 19.83333333, 63.        ]])
    """
    if tuple(factors) == (1.0, 1.0):
        return detections
    sx, sy = factors
    boxes = (detections.boxes + 0.5) / np.array([sx, sy, sx, sy]) - 0.5
    return Detections(clip_boxes(boxes, *image_size), detections.scores, detections.alpha, detections.source)


def smallest_car_enlarged(bank, smallest_car: float | None, factors: tuple[float, float]) -> float | None:
    """The smallest car height the detector ``bank`` searches in the image enlarged by
    ``factors`` (:func:`enlarge_frame`) for ``smallest_car`` pixels of the image as it is
    (``PredetectOptions.smallest_car``, in the caller's pixels): the same cars, except that a
    smallest car asked below the bank's own (to search farther than it) is searched at least
    as far down as the enlarged image's default, the bank's own (0) there.

    Examples
    --------
    >>> bank = type("Bank", (), {"meta": {"min_height": 25.0}})()
    >>> round(smallest_car_enlarged(bank, 12.0, (1.5, 1.4986)), 2)  # 18 px of the enlarged image
    17.98
    >>> smallest_car_enlarged(bank, 20.0, (1.5, 1.5))  # 16.7 px of the image by default: farther than asked
    0.0
    >>> smallest_car_enlarged(bank, 50.0, (1.5, 1.5)), smallest_car_enlarged(bank, None, (1.5, 1.5))  # no car < 50
    (75.0, None)
    """
    if not smallest_car:
        return smallest_car
    own = float(bank.meta.get("min_height", 30.0))
    enlarged = float(smallest_car) * min(factors)
    return enlarged if smallest_car >= own or enlarged < own else 0.0


class Pass(NamedTuple):
    """One pass of the pre-detection over a frame (:func:`frame_passes`): its ``camera`` (or
    None) and ``image``, the ``smallest_car`` it searches (``PredetectOptions.smallest_car``,
    in its pixels), the coarsest level of its pyramid ``min_scale`` (None: the bank's own),
    the ``factors`` by which ``image`` enlarges the frame's (:func:`boxes_back`) and its
    feature ``pyramid`` if already computed (None: to compute)."""

    camera: Camera | None
    image: np.ndarray
    smallest_car: float | None
    min_scale: float | None
    factors: tuple[float, float]
    pyramid: list | None = None


def _finest_scale(bank, smallest_car: float | None) -> float:
    """The finest pyramid level (scale) the ``bank`` searches for ``smallest_car`` px
    (:func:`~wirescene.predetect.bank.smallest_car_search`; None or 0: its own)."""
    return smallest_car_search(bank, smallest_car)[1] or float(bank.meta.get("max_scale", 2.0))


def frame_passes(bank, camera: Camera | None, image: np.ndarray, factor: float, smallest_car: float | None = None,
                 *, pyramid: list | None = None):
    """The passes (:class:`Pass`) of the pre-detection over ``image`` with the enlargement
    ``factor`` (``PredetectOptions.upsample``): the image as it is (with its feature
    ``pyramid`` if already computed, e.g. to read the camera's pitch), then, where
    :func:`enlarge_frame` enlarges it, the enlarged image at the levels of its pyramid finer
    than the image's finest by a quarter of a level at least: the small, far cars the image's
    own levels cannot hold (the cars they hold keep the image's boxes). Its smallest car is
    :func:`smallest_car_enlarged`. There is no second pass where none of its levels is that
    much finer: with a ``smallest_car`` the image's own levels reach (16.7 px or less at 1.5,
    the bank's own smallest car over ``factor``), or one at or above the bank's own (no car
    smaller is searched, in either image).

    Examples
    --------
    >>> bank = type("Bank", (), {"meta": {"min_height": 25.0, "max_scale": 2.0, "per_octave": 6}})()
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> [(p.image.shape, round(p.min_scale or 0, 3), p.factors) for p in frame_passes(bank, None, image, 1.5)]
    [((64, 96, 3), 0, (1.0, 1.0)), ((96, 144, 3), 1.372, (1.5, 1.5))]
    >>> len(list(frame_passes(bank, None, image, 1.0)))  # as it is only
    1
    >>> [len(list(frame_passes(bank, None, image, 1.5, smallest_car=c))) for c in (12.5, 16.7, 18, 24, 25)]
    [1, 1, 2, 2, 1]
    """
    yield Pass(camera, image, smallest_car, None, (1.0, 1.0), pyramid)
    H, W = image.shape[:2]
    w, h = enlarged_size(W, H, factor)
    if (w, h) == (W, H):
        return
    factors = (w / W, h / H)  # as enlarge_frame's, known before the image is enlarged
    smallest = smallest_car_enlarged(bank, smallest_car, factors)
    quarter = 2.0 ** (1.0 / (4 * int(bank.meta.get("per_octave", 4))))  # a level nearer is the image's own again
    min_scale = _finest_scale(bank, smallest_car) / min(factors) * quarter
    if _finest_scale(bank, smallest) >= min_scale:
        big_camera, big, factors = enlarge_frame(camera, image, factor)
        yield Pass(big_camera, big, smallest, min_scale, factors)


#: IoU with a detection of the image as it is above which an enlarged image's detection is the
#: same car (:func:`add_enlarged`): the IoU at which a detection counts as a car's.
SAME_CAR_IOU = 0.5


def add_enlarged(detections: Detections, enlarged: Detections, *, threshold: float | None = None) -> Detections:
    """``detections`` of an image with the cars ``enlarged`` adds (the same image's, enlarged
    and brought back: :func:`boxes_back`): its boxes scoring above ``threshold`` that overlap
    none of ``detections`` above it at IoU :data:`SAME_CAR_IOU` or more; a box of
    ``detections`` at or below ``threshold`` that overlaps an added one is the same car and
    goes. ``threshold`` None: every box counts (both lists already cut at one threshold). The
    cars both find above ``threshold`` keep the image's box and score; a car the image finds
    only at or below it takes the enlarged image's.

    Examples
    --------
    >>> mine = Detections(np.array([[0.0, 0, 40, 20], [59, 0, 70, 6]]), np.array([0.9, 0.1]), np.zeros(2))
    >>> more = Detections(np.array([[1.0, 0, 40, 20], [60, 0, 70, 6]]), np.array([0.8, 0.6]), np.ones(2))
    >>> add_enlarged(mine, more, threshold=0.3).boxes  # the first car found both ways; the second's low box goes
    array([[ 0.,  0., 40., 20.],
           [60.,  0., 70.,  6.]])
    >>> add_enlarged(mine, more).scores  # every box counts: the second car found both ways too
    array([0.9, 0.1])
    """
    floor = -np.inf if threshold is None else float(threshold)
    enlarged = enlarged.subset(enlarged.scores > floor)
    above = detections.boxes[detections.scores > floor]
    if len(enlarged) and len(above):
        enlarged = enlarged.subset(iou_2d(enlarged.boxes[:, None, :], above[None, :, :]).max(axis=1) < SAME_CAR_IOU)
    if not len(enlarged):
        return detections
    if threshold is not None and len(detections):
        twin = iou_2d(detections.boxes[:, None, :], enlarged.boxes[None, :, :]).max(axis=1) >= SAME_CAR_IOU
        detections = detections.subset((detections.scores > floor) | ~twin)
    return _joined(detections, enlarged)


def _joined(first: Detections, second: Detections) -> Detections:
    """The detections of ``first``, then those of ``second``, with ``first``'s source.

    Examples
    --------
    >>> one = Detections(np.array([[0.0, 0, 40, 20]]), np.array([0.9]), np.zeros(1))
    >>> len(_joined(one, one)), len(_joined(one, Detections.empty()))
    (2, 1)
    """
    return Detections(np.concatenate([first.boxes, second.boxes]).reshape(-1, 4),
                      np.concatenate([first.scores, second.scores]), np.concatenate([first.alpha, second.alpha]),
                      first.source)
