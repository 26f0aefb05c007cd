"""The camera's mount as our own pre-detection reads it: its pitch read off the boxes the
detector bank's templates find without the priors, which need it (:func:`image_mount`, one
frame; :func:`rig_pitch`, the frames of one rig together), and the mount every detection
pass of a frame takes (:func:`frame_mount`)."""

from __future__ import annotations

import numpy as np

from wirescene.core.camera import Camera
from wirescene.core.groundplane import KITTI_MOUNT, Mount
from wirescene.core.settings import stage_field
from wirescene.core.types import Detections
from wirescene.lift import LiftingOptions
from wirescene.predetect.bank import smallest_car_search

#: Score down to which the templates' boxes, found without the priors, tell a frame's pitch
#: (:func:`~wirescene.fitting.own_boxes.own_detections` with ``estimate_pitch``): below the
#: fit's threshold, as the ground term the priors would add is missing; each box weighs its score.
PITCH_THRESHOLD = 0.1


def bounded_pitch(pitch: float) -> float:
    """``pitch`` (degrees) within ``LiftingOptions.camera_pitch``'s bounds, which a pitch read
    off boxes may pass (the grid reaches 15 deg past the one told).

    Examples
    --------
    >>> bounded_pitch(50.0), bounded_pitch(-0.1)
    (45.0, -0.1)
    """
    bounds = stage_field(LiftingOptions, "camera_pitch").metadata
    return min(max(float(pitch), bounds["minimum"]), bounds["maximum"])


def frame_pitch(camera: Camera, detections: Detections, *, bank, told: Mount = KITTI_MOUNT,
                weighted: bool = False) -> float:
    """The camera's pitch read off a frame's boxes
    (:func:`~wirescene.predetect.geometry.pitch_from_boxes` with ``bank``'s ground prior,
    about ``told``; ``weighted``: each box by its score, a probability of a car), within
    ``LiftingOptions.camera_pitch``'s bounds; ``told.pitch`` for a bank without a ground prior.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> from wirescene.fitting.models import detector_bank
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> frame_pitch(camera, Detections.empty("none"), bank=detector_bank(None))  # no box: the pitch told
    0.0
    """
    from wirescene.predetect.geometry import pitch_from_boxes

    prior = bank.meta.get("ground_prior")
    if not prior:
        return float(told.pitch)
    weights = np.clip(detections.scores, 0.0, 1.0) if weighted else None
    return bounded_pitch(pitch_from_boxes(prior, camera, detections.boxes, weights=weights, told=told))


def image_pitch_likelihood(camera: Camera, image: np.ndarray, *, bank, told: Mount = KITTI_MOUNT,
                           pyramid: list | None = None, min_height: float | None = None) -> tuple[np.ndarray, int]:
    """``((301,) log-likelihood, boxes)`` of the camera's pitch
    (:func:`~wirescene.predetect.geometry.pitch_log_likelihood` on the grid about ``told``) by
    the boxes ``bank``'s templates find in ``image`` without the priors, which need the pitch,
    down to :data:`PITCH_THRESHOLD`, each weighed by its score, and how many boxes it read;
    zeros and 0 for a bank without a ground prior. Frames of one rig add their
    log-likelihoods (:func:`rig_pitch`, ``wirescene pitch``); ``pyramid`` and ``min_height`` as in
    :func:`~wirescene.predetect.bank.detect_cars`.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> from wirescene.fitting.models import detector_bank
    >>> camera = Camera(np.array([[720.0, 0, 48, 0], [0, 720.0, 32, 0], [0, 0, 1, 0]]), (96, 64))
    >>> likelihood, boxes = image_pitch_likelihood(camera, np.zeros((64, 96, 3), np.uint8), bank=detector_bank(None))
    >>> likelihood.shape, boxes  # a blank image: no box, no evidence
    ((301,), 0)
    """
    from wirescene.predetect import detect_cars
    from wirescene.predetect.geometry import pitch_grid, pitch_log_likelihood

    prior = bank.meta.get("ground_prior")
    if not prior:  # no prior to read the pitch with: no detection pass spent on it
        return np.zeros(len(pitch_grid(told=told))), 0
    raw = detect_cars(image, bank=bank, threshold=PITCH_THRESHOLD, pyramid=pyramid, min_height=min_height)
    weights = np.clip(raw.scores, 0.0, 1.0)
    return pitch_log_likelihood(prior, camera, raw.boxes, weights=weights, told=told), len(raw)


def rig_pitch(likelihoods, *, told: Mount = KITTI_MOUNT) -> float:
    """The pitch (degrees) that the frames of one rig tell together: the sum of their
    :func:`image_pitch_likelihood` (read about ``told``, at its height) under the prior about
    ``told.pitch`` (:func:`~wirescene.predetect.geometry.pitch_of`), within
    ``LiftingOptions.camera_pitch``'s bounds; ``told.pitch`` without evidence.

    Examples
    --------
    >>> rig_pitch([np.zeros(301), np.zeros(301)], told=Mount(1.65, 2.5))
    2.5
    """
    from wirescene.predetect.geometry import pitch_of

    return bounded_pitch(pitch_of(np.sum(np.asarray(likelihoods, float), axis=0), told=told))


def image_mount(camera: Camera, image: np.ndarray, *, bank, told: Mount = KITTI_MOUNT, pyramid: list | None = None,
                min_height: float | None = None) -> Mount:
    """``told`` with the pitch read off the boxes ``bank``'s templates find in ``image``
    without the priors, which need the pitch (:func:`image_pitch_likelihood`, within
    ``LiftingOptions.camera_pitch``'s bounds; ``told`` for a bank without a ground prior);
    ``pyramid`` and ``min_height`` as in :func:`~wirescene.predetect.bank.detect_cars`."""
    if not bank.meta.get("ground_prior"):  # no prior to read the pitch with: the mount told, as it is
        return told
    likelihood, _ = image_pitch_likelihood(camera, image, bank=bank, told=told, pyramid=pyramid, min_height=min_height)
    return Mount(told.height, rig_pitch([likelihood], told=told))


def frame_mount(camera: Camera | None, image: np.ndarray, *, bank, told: Mount = KITTI_MOUNT,
                estimate_pitch: bool = False, smallest_car: float | None = None,
                pyramid: list | None = None) -> tuple[list | None, Mount]:
    """``(pyramid, mount)`` of a frame before its detection passes: with ``estimate_pitch`` and
    a camera, the image's feature pyramid for its ``smallest_car`` (or ``pyramid``, given) and
    ``told`` with the pitch read off its boxes (:func:`image_mount`); else ``(pyramid, told)``
    as given. Every pass of the frame then takes that mount (the enlarged image's too, whose
    pyramid holds its finest levels only: :func:`~wirescene.predetect.enlarge.frame_passes`).

    Examples
    --------
    >>> from wirescene.fitting.models import detector_bank
    >>> frame_mount(None, np.zeros((64, 96, 3), np.uint8), bank=detector_bank(None), estimate_pitch=True)
    (None, Mount(height=1.65, pitch=0.0))
    """
    if not estimate_pitch or camera is None:
        return pyramid, told
    from wirescene.predetect.bank import bank_pyramid

    min_height, max_scale = smallest_car_search(bank, smallest_car)
    pyramid = bank_pyramid(bank, image, max_scale=max_scale) if pyramid is None else pyramid
    return pyramid, image_mount(camera, image, bank=bank, told=told, pyramid=pyramid, min_height=min_height)
