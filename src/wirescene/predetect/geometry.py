"""Ground-plane consistency of 2D car boxes: where a box stands says how tall it may be.

A car of height ``Hc`` standing on the road at depth ``Z`` in front of a camera mounted
``Hcam`` above the road projects to a box of height ``h = f Hc / Z`` whose bottom edge
lies ``f Hcam / Z`` below the horizon row. Their ratio

    r = (bottom - horizon) / h  =  Hcam / Hc

is the same for every car of the scene, whatever its distance (about 1.1-1.2 for KITTI's
1.65 m camera and 1.4-1.6 m cars; road slope, pitch and occlusion of the bottom spread
it). Background windows that fire the HOG templates -- facades, trees, road texture --
have no reason to obey it: on the real KITTI frames 95% of true cars have r in
0.95..1.5, against 14% of the detector's top-scoring background windows. This is the
geometric context of Hoiem, Efros and Hebert ("Putting objects in perspective", CVPR
2006) in its simplest form, the 2D face of the paper's shared ground plane.

The prior is two densities of ``r`` learned from training frames -- cars (the labelled
boxes) and background (the bank's own detections that overlap no labelled object) --
and a detection's score gains their log ratio (naive Bayes: the SVM margin and the
box's position are taken as independent given car / not car). The horizon is the row
of the camera's principal point: the KITTI camera frame's y axis is the road normal up
to the small pitch of the rig, and the horizon of a plane with normal y is ``v = K[1, 2]``;
a camera pitched down by ``theta`` sees it ``K[1, 1] tan(theta)`` pixels higher.
Both priors were learned at KITTI's camera height; for a camera ``Hcam`` above the road a
box's distance below the horizon is taken times ``1.65 / Hcam`` (:class:`Horizon`), the
distance at which KITTI's camera would see that car.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, KITTI_MOUNT, Mount


class Horizon(NamedTuple):
    """The horizon's image ``row`` and the camera's height above the road as the priors
    read it: ``scale`` = KITTI's camera height over the camera's (1 for KITTI's rig).

    Examples
    --------
    >>> Horizon(170.0)  # KITTI's rig
    Horizon(row=170.0, scale=1.0)
    >>> below_horizon([230.0], Horizon(170.0, scale=0.5))  # a camera 3.3 m up: 60 px read as KITTI's 30
    array([30.])
    """

    row: float
    scale: float = 1.0

#: Share of real cars allowed to follow the background density of ``r`` (cars on steep
#: slopes, boxes cut by the image's bottom edge), so no car's score collapses.
OUTLIER_SHARE = 0.02
MIN_SIGMA = 0.05


def horizon_row(camera) -> float:
    """Image row of the horizon of the KITTI camera frame's ground plane (``K[1, 2]``).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> horizon_row(camera)  # K[1, 2]
    170.0
    """
    return float(np.asarray(camera.K, float)[1, 2])


def road_horizon(camera, mount: Mount = KITTI_MOUNT) -> Horizon:
    """The :class:`Horizon` of ``camera`` on its ``mount``
    (:class:`~wirescene.core.groundplane.Mount`: metres above the road, degrees down from it).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> from wirescene.core.groundplane import Mount
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> road_horizon(camera, Mount(3.3))  # twice KITTI's height: boxes read as half as far below the horizon
    Horizon(row=170.0, scale=0.5)
    >>> round(road_horizon(camera, Mount(pitch=4.0)).row, 1)  # looking down 4 deg: the horizon 50 px higher
    119.7
    """
    height, pitch = mount
    if not np.isfinite(height) or height <= 0:
        raise ValueError(f"camera_height must be a positive number of metres, got {height!r}")
    if not np.isfinite(pitch) or abs(pitch) >= 90:
        raise ValueError(f"camera_pitch must be a number of degrees within +-90, got {pitch!r}")
    row = horizon_row(camera) - float(np.asarray(camera.K, float)[1, 1]) * np.tan(np.deg2rad(pitch))
    return Horizon(float(row), float(KITTI_CAMERA_HEIGHT / height))


def below_horizon(rows, horizon) -> np.ndarray:
    """How far image ``rows`` lie below the ``horizon`` (a :class:`Horizon`, or a row for
    KITTI's rig), in pixels of KITTI's camera height.

    Examples
    --------
    >>> below_horizon([200.0, 230.0], 170.0)  # a row: KITTI's camera height
    array([30., 60.])
    """
    if isinstance(horizon, Horizon):
        return (np.asarray(rows, float) - horizon.row) * horizon.scale
    return np.asarray(rows, float) - float(horizon)


def bottom_ratio(boxes, horizon) -> np.ndarray:
    """``(D,)`` ratio ``(bottom - horizon) / height`` of boxes ``(D, 4)`` (x1 y1 x2 y2);
    ``horizon`` as in :func:`below_horizon`.

    Examples
    --------
    >>> bottom_ratio([[500, 180, 600, 230], [500, 100, 600, 150]], 170.0)  # 60 / 50; a box above the horizon
    array([ 1.2, -0.4])
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    return below_horizon(b[:, 3], horizon) / np.maximum(b[:, 3] - b[:, 1], 1.0)


def _log_normal(x, mean: float, sigma: float) -> np.ndarray:
    s = max(float(sigma), MIN_SIGMA)
    return -0.5 * ((x - float(mean)) / s) ** 2 - np.log(s * np.sqrt(2 * np.pi))


def fit_ground_prior(car_ratios, background_ratios) -> dict:
    """The prior (a JSON-able dict) from the ratios of training cars and of background
    detections: a robust normal for cars (median, 1.4826 MAD) and a normal for the
    background (mean, standard deviation).

    Examples
    --------
    >>> prior = fit_ground_prior([1.0, 1.1, 1.2, 1.3, 1.4], [-1.0, 0.0, 0.5, 1.0, 2.5])
    >>> prior["car"][0], round(prior["car"][1], 4), prior["background"][0]  # median, 1.4826 MAD; mean
    (1.2, 0.1483, 0.6)
    """
    rc = np.asarray(car_ratios, float)
    rb = np.asarray(background_ratios, float)
    rc, rb = rc[np.isfinite(rc)], rb[np.isfinite(rb)]
    if len(rc) < 5 or len(rb) < 5:
        raise ValueError(f"a ground prior needs >= 5 cars and >= 5 background boxes, got {len(rc)} and {len(rb)}")
    med = float(np.median(rc))
    return {"car": [med, max(1.4826 * float(np.median(np.abs(rc - med))), MIN_SIGMA)],
            "background": [float(np.mean(rb)), max(float(np.std(rb)), MIN_SIGMA)],
            "outlier_share": OUTLIER_SHARE, "n_car": int(len(rc)), "n_background": int(len(rb))}


def _log_densities(prior: dict, r) -> tuple[np.ndarray, np.ndarray]:
    """``(log p(r | car), log p(r | background))`` of ratios ``r``: the car density mixed with
    ``outlier_share`` of the background density (no car's ratio is impossible)."""
    bg = _log_normal(r, *prior["background"])
    eps = float(prior.get("outlier_share", OUTLIER_SHARE))
    return np.logaddexp(np.log1p(-eps) + _log_normal(r, *prior["car"]), np.log(eps) + bg), bg


def ground_log_ratio(prior: dict, boxes, horizon: float | Horizon) -> np.ndarray:
    """``(D,)`` log p(r | car) - log p(r | background) of boxes ``(D, 4)``; the car density
    is mixed with ``outlier_share`` of the background density, so the ratio is bounded
    below by ``log(outlier_share)``.

    Examples
    --------
    >>> prior = fit_ground_prior([1.0, 1.1, 1.2, 1.3, 1.4], [-1.0, 0.0, 0.5, 1.0, 2.5])
    >>> boxes = [[500, 180, 600, 230], [500, 100, 600, 150]]  # ratios 1.2 (a car's) and -0.4
    >>> ground_log_ratio(prior, boxes, 170.0).round(2)  # bounded below by log(outlier_share) = log(0.02)
    array([ 2.17, -3.91])
    """
    car, bg = _log_densities(prior, bottom_ratio(boxes, horizon))
    return car - bg


#: Spread (degrees) of the pitch's prior about the one told (``LiftingOptions.camera_pitch``):
#: a dashcam's tilt, not a free search.
PITCH_SPREAD = 5.0


#: Half-width (degrees) of the pitch searched about the one told, on a grid of 0.1 deg.
PITCH_SEARCH = 15.0


def pitch_grid(*, told: Mount = KITTI_MOUNT) -> np.ndarray:
    """``(301,)`` pitches (degrees down from the road) the boxes are read at: 0.1 deg apart,
    within :data:`PITCH_SEARCH` (15 deg) of ``told.pitch``.

    Examples
    --------
    >>> grid = pitch_grid(told=Mount(1.65, 2.0))
    >>> grid.shape, float(grid[0]), float(grid[-1])
    ((301,), -13.0, 17.0)
    """
    steps = round(PITCH_SEARCH * 10)
    return float(told.pitch) + np.arange(-steps, steps + 1) / 10.0


def pitch_log_likelihood(prior: dict, camera, boxes, *, weights=None, told: Mount = KITTI_MOUNT) -> np.ndarray:
    """``(301,)`` log-likelihood of ``boxes`` standing on the road as cars do, at each pitch
    of :func:`pitch_grid`, the camera's height told: the ground ``prior``'s car density
    (mixed with the background's, for boxes that are no car's) of every box's ratio of its
    distance below the horizon to its height (:func:`bottom_ratio`), ``weights`` per box
    (e.g. their probability of a car, default 1). Boxes cut by the image's bottom edge say
    nothing of where their car stands and are left out; without a box, zeros. Frames of
    one rig add their log-likelihoods (:func:`pitch_of`).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> prior = {"car": [1.1, 0.08], "background": [0.5, 1.0]}
    >>> bool(pitch_log_likelihood(prior, camera, np.zeros((0, 4))).any())  # no box: no evidence
    False
    >>> z = np.array([8.0, 20.0])  # two frames of one car each, the horizon 50 px up: 4 deg down
    >>> frames = [[[500.0, 120 + 720 * 0.15 / d, 600.0, 120 + 720 * 1.65 / d]] for d in z]
    >>> pitch_of(sum(pitch_log_likelihood(prior, camera, b) for b in frames))
    4.0
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    w = np.ones(len(b)) if weights is None else np.asarray(weights, float).reshape(-1)
    if len(w) != len(b):
        raise ValueError(f"weights must have one value per box ({len(b)}), got {len(w)}")
    size = getattr(camera, "image_size", None)
    keep = np.isfinite(b).all(1) & np.isfinite(w) & (w > 0) & (b[:, 3] - b[:, 1] >= 1)
    if size is not None:
        keep &= b[:, 3] < size[1] - 2  # cut by the bottom edge: its bottom is not the car's
    grid = pitch_grid(told=told)
    if not keep.any():
        return np.zeros(len(grid))
    ratios = np.stack([bottom_ratio(b[keep], road_horizon(camera, Mount(told.height, p))) for p in grid])  # (G, D)
    density, _ = _log_densities(prior, ratios)
    return density @ w[keep]


def pitch_of(log_likelihood, *, told: Mount = KITTI_MOUNT) -> float:
    """The pitch (degrees) of :func:`pitch_grid` that a log-likelihood ``(301,)`` of
    :func:`pitch_log_likelihood` (one frame's, or the sum of a rig's frames') and a normal
    prior about ``told.pitch`` (:data:`PITCH_SPREAD`) make most likely; ``told.pitch`` for
    no evidence.

    Examples
    --------
    >>> import numpy as np
    >>> pitch_of(np.zeros(301), told=Mount(1.65, 2.5))
    2.5
    """
    grid = pitch_grid(told=told)
    score = np.asarray(log_likelihood, float) - 0.5 * ((grid - told.pitch) / PITCH_SPREAD) ** 2
    return float(grid[np.argmax(score)])


def pitch_from_boxes(prior: dict, camera, boxes, *, weights=None, told: Mount = KITTI_MOUNT) -> float:
    """The camera's pitch (degrees down from the road) under which ``boxes`` stand on the
    road as cars do, its height above the road told.

    A car's box lies ``f Hcam / Z`` below the horizon and is ``f Hc / Z`` high: the ratio of
    the two is the same for every car (:func:`bottom_ratio`), and the horizon that gives the
    frame's boxes the ratios the ground ``prior`` expects of cars
    (:func:`pitch_log_likelihood`) is the camera's pitch, searched on a grid of 0.1 deg
    within 15 deg of ``told.pitch`` under a normal prior about it (:func:`pitch_of`).
    Without a box the told pitch is returned. The height is not estimated: the boxes fix
    the ratio of the camera's height to the cars' only, and a car's height varies by 10%.

    Parameters
    ----------
    prior : dict
        A ground prior (:func:`fit_ground_prior`; a bank's ``meta["ground_prior"]``).
    camera : Camera
    boxes : (D, 4) array
        ``x1 y1 x2 y2`` in pixels.
    weights : (D,) array, optional
    told : Mount, optional
        The camera's height, and the pitch the prior is centred on.

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> prior = {"car": [1.1, 0.08], "background": [0.5, 1.0]}
    >>> z = np.array([8.0, 12.0, 20.0, 30.0])  # cars 1.5 m high seen from 1.65 m, the horizon 50 px up
    >>> bottom, top = 120 + 720 * 1.65 / z, 120 + 720 * (1.65 - 1.5) / z
    >>> boxes = np.stack([np.full(4, 500.0), top, np.full(4, 600.0), bottom], axis=1)
    >>> round(pitch_from_boxes(prior, camera, boxes), 1)
    4.0
    """
    return pitch_of(pitch_log_likelihood(prior, camera, boxes, weights=weights, told=told), told=told)
