"""Our own pre-detection (stage 1): the detector bank's passes over a frame
(:func:`own_detections`, the one entry point), the box rule that gives boxes their viewpoints,
ours and any other detector's (:func:`complete_viewpoints`, :func:`with_rule_viewpoints`),
and the boxes kept at a threshold with the fit's viewpoints (:func:`detections_above`)."""

from __future__ import annotations

import time

import numpy as np

from wirescene.core.camera import Camera
from wirescene.core.groundplane import KITTI_MOUNT, Mount
from wirescene.core.types import Detections
from wirescene.fitting.models import detector_bank, viewpoint_classifier
from wirescene.fitting.mount import frame_mount
from wirescene.fitting.options import PredetectOptions
from wirescene.predetect.bank import smallest_car_search
from wirescene.predetect.enlarge import add_enlarged, boxes_back, frame_passes


def complete_viewpoints(camera: Camera, detections: Detections, image: np.ndarray, *, bank=None,
                        classifier=None, pyramid: list | None = None, responses: dict | None = None,
                        mount: Mount = KITTI_MOUNT) -> Detections:
    """Detections whose unknown viewpoints (NaN ``alpha``, e.g. boxes of an external
    detector) are scored inside each box by the detector bank's templates and the crop
    viewpoint classifier, with the camera's road prior
    (:func:`wirescene.predetect.box_viewpoints.box_viewpoints`, all unknown boxes of the frame
    at once: cars of one row agree); known viewpoints are kept.

    Parameters
    ----------
    camera : Camera
    detections : Detections
    image : (H, W, 3) uint8 array
    bank : DetectorBank, optional
        Default: the shipped bank.
    classifier : ViewpointClassifier, optional
        Default: the shipped one.
    pyramid : list of (float, ndarray), optional
        The image's :func:`~wirescene.predetect.bank.bank_pyramid` if already computed.
    responses : dict, optional
        The bank's template response maps on ``pyramid`` (``detect_cars(responses=)``), if
        already computed.
    mount : Mount, optional
        The camera's height above the road and pitch down from it
        (:class:`~wirescene.core.groundplane.Mount`; ``LiftingOptions.mount``), for the road
        prior.

    Returns
    -------
    Detections
        The same boxes and scores, every ``alpha`` finite.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.camera import Camera
    >>> P = np.array([[720.0, 0, 48, 0], [0, 720.0, 20, 0], [0, 0, 1, 0]])
    >>> dets = Detections(np.array([[10.0, 20.0, 70.0, 50.0]]), np.ones(1), np.full(1, np.nan))
    >>> out = complete_viewpoints(Camera(P, (96, 64)), dets, np.zeros((64, 96, 3), np.uint8))
    >>> bool(np.isfinite(out.alpha).all())
    True
    """
    from wirescene.predetect.box_viewpoints import box_viewpoints

    unknown = np.flatnonzero(~np.isfinite(detections.alpha))
    if len(unknown) == 0:
        return detections
    bank = detector_bank(None) if bank is None else bank
    classifier = viewpoint_classifier(None) if classifier is None else classifier
    alpha = detections.alpha.copy()
    alpha[unknown] = box_viewpoints(bank, image, detections.boxes[unknown], camera=camera, classifier=classifier,
                                    pyramid=pyramid, responses=responses, mount=mount)
    return Detections(detections.boxes, detections.scores, alpha, detections.source)


def with_rule_viewpoints(camera: Camera | None, image: np.ndarray, detections: Detections, *, bank=None,
                         classifier=None, pyramid: list | None = None, responses: dict | None = None,
                         mount: Mount = KITTI_MOUNT) -> Detections:
    """The bank's ``detections`` of ``image`` with the box rule's viewpoints in place of the
    detector's own: each box's viewpoint chosen as for the boxes of any other detector
    (:func:`complete_viewpoints` on every box, none known), as our own pre-detection gives its
    boxes theirs (:func:`own_detections`). Without a camera (``None``) the detector's own
    viewpoints stay. ``image``, ``bank``, ``classifier``, ``pyramid`` and ``mount`` as in
    :func:`complete_viewpoints`; ``responses``: the response maps (``detect_cars(responses=)``)
    ``detections`` were made from, if kept, for the rule to read.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> P = np.array([[720.0, 0, 48, 0], [0, 720.0, 20, 0], [0, 0, 1, 0]])
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> dets = Detections(np.array([[10.0, 20.0, 70.0, 50.0]]), np.ones(1), np.zeros(1))  # the detector's alpha 0
    >>> bool(np.isfinite(with_rule_viewpoints(Camera(P, (96, 64)), image, dets).alpha).all())
    True
    >>> with_rule_viewpoints(None, image, dets) is dets  # no camera: the detector's own viewpoints
    True
    """
    if camera is None or not len(detections):
        return detections
    unknown = Detections(detections.boxes, detections.scores, np.full(len(detections), np.nan), detections.source)
    return complete_viewpoints(camera, unknown, image, bank=bank, classifier=classifier, pyramid=pyramid,
                               responses=responses, mount=mount)


def detections_above(camera: Camera | None, image: np.ndarray, found: Detections, threshold: float, *, bank,
                     classifier=None, pyramid: list | None = None, responses: dict | None = None,
                     mount: Mount = KITTI_MOUNT) -> Detections:
    """The bank's detections ``found`` of ``image`` (every score down to ``threshold`` at least)
    above ``threshold``, each box that the fit's own pre-detection also keeps (above
    ``PredetectOptions.threshold``, for a calibrated bank) with the viewpoint the fit gives it:
    cars of one row agree, so a box's viewpoint depends on the boxes the rule reads beside it
    (:func:`with_rule_viewpoints`; ``classifier``, ``pyramid``, ``responses`` and ``mount`` as there)."""
    keep = found.subset(found.scores > threshold)
    if camera is None:
        return keep
    fit_threshold = PredetectOptions().threshold
    if bank.calibration is None:  # margins, not probabilities: no common scale with the fit's threshold
        return with_rule_viewpoints(camera, image, keep, bank=bank, classifier=classifier, pyramid=pyramid,
                                    responses=responses, mount=mount)
    read = with_rule_viewpoints(camera, image, found.subset(found.scores > min(threshold, fit_threshold)), bank=bank,
                                classifier=classifier, pyramid=pyramid, responses=responses, mount=mount)
    out = read.subset(read.scores > threshold)
    if threshold < fit_threshold:  # the rule read more boxes than the fit's: the fit's set decides its own boxes
        fit = with_rule_viewpoints(camera, image, found.subset(found.scores > fit_threshold), bank=bank,
                                   classifier=classifier, pyramid=pyramid, responses=responses, mount=mount)
        alpha = out.alpha.copy()
        alpha[out.scores > fit_threshold] = fit.alpha
        out = Detections(out.boxes, out.scores, alpha, out.source)
    return out


def own_detections(camera: Camera | None, image: np.ndarray, *, bank=None, classifier=None,
                   threshold: float | None = None, fit_viewpoints: bool = False, return_all: bool = False,
                   viewpoints: bool = True, upsample: float = 1.0, smallest_car: float | None = None,
                   pyramid: list | None = None, mount: Mount = KITTI_MOUNT, estimate_pitch: bool = False,
                   cross_view_nms: float | None = 0.3, source: str = "bank", seconds: list | None = None):
    """Our own pre-detection (stage 1) of a frame, for the fit
    (:func:`~wirescene.fitting.pipeline.fit_frame`), the evaluation, :func:`wirescene.detect`
    and the ``detect`` command: the detector bank's cars (:func:`wirescene.predetect.detect_cars`,
    with the camera), each box's viewpoint then chosen as for the boxes of any other detector
    (:func:`with_rule_viewpoints`: the bank's templates inside the box, the crop classifier and
    the road prior, every box of the frame at once so that cars of one row agree). Held out by
    drive, that rule puts 84.7% of the 189 cars the bank finds at 0.3 within 45 deg, the
    detector's own choice 83.1% (``benchmarks/RESULTS.md``).

    The passes over the frame are chained here once: one camera mount for every pass
    (:func:`~wirescene.fitting.mount.frame_mount`), the passes of
    :func:`~wirescene.predetect.enlarge.frame_passes` (the image as it is and, with
    ``upsample``, enlarged), on each the detector bank (:func:`bank_pass`) and the box rule's
    viewpoints, the enlarged image's boxes brought back to the image's pixels
    (:func:`~wirescene.predetect.enlarge.boxes_back`) and the cars it adds
    (:func:`~wirescene.predetect.enlarge.add_enlarged`).

    Parameters
    ----------
    camera : Camera or None
        For the bank's priors and the box rule (None: neither, the detector's own viewpoints).
    image : (H, W, 3) uint8 array
    bank, classifier : DetectorBank, ViewpointClassifier, optional
        As in :func:`complete_viewpoints`.
    threshold : float, optional
        Keep the boxes scoring above it (None: the bank's own, its 2D operating point).
    fit_viewpoints : bool
        Keep the boxes above ``threshold`` of the fit's own pre-detection, whatever the
        threshold, for a calibrated bank: the passes read down to the lower of ``threshold``
        and the fit's (``PredetectOptions.threshold``), each box the fit keeps takes the fit's
        viewpoint (:func:`detections_above`) and the enlarged image's cars are added at the
        fit's threshold. False: the passes read at ``threshold`` and the rule reads every box
        found (the fit's own pre-detection, at its threshold).
    return_all : bool
        The passes keep every score (:func:`bank_pass`), returned too with the detector's own
        viewpoints (e.g. for AP); with ``fit_viewpoints`` only.
    viewpoints : bool
        The boxes kept take the box rule's viewpoints (False: the detector's own; no response
        maps kept).
    upsample : float
        The detection and the rule also run on the image enlarged by this factor, at its
        pyramid's levels finer than the image's (``PredetectOptions.upsample``), whose cars that
        no box of ``image`` covers are added, their boxes brought back to ``image``'s pixels
        (1: the image alone).
    smallest_car : float, optional
        The smallest car height searched (px; None or 0: the bank's own), the pyramid's
        largest scale moved so that the bank's smallest templates reach it.
    pyramid : list of (float, ndarray), optional
        The image's :func:`~wirescene.predetect.bank.bank_pyramid` if already computed (read by
        the detection and the rule).
    mount : Mount
        The camera's height above the road and pitch down from it
        (:class:`~wirescene.core.groundplane.Mount`; ``LiftingOptions.mount``), for the ground
        and traffic priors learned at KITTI's level rig.
    estimate_pitch : bool
        The priors read the camera's pitch off the boxes the templates find without them
        (:func:`~wirescene.fitting.mount.image_mount` about ``mount``'s, once for every pass;
        ``LiftingOptions.estimate_pitch``).
    cross_view_nms : float or None
        As in :func:`~wirescene.predetect.detect_cars`.
    source : str
        The detections' ``source``.
    seconds : list, optional
        Receives the seconds the detection took: the mount, the passes' images and the bank's
        passes, not the box rule's viewpoints.

    Returns
    -------
    Detections or tuple of Detections
        The boxes kept, in the image's pixels; with ``return_all``, ``(every, kept)``.

    Examples
    --------
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> own_detections(None, image, upsample=1.5).boxes.shape
    (0, 4)
    >>> every, kept = own_detections(None, image, fit_viewpoints=True, return_all=True, viewpoints=False)
    >>> len(every) >= len(kept), bool((kept.scores > detector_bank(None).threshold).all())
    (True, True)
    """
    if return_all and not fit_viewpoints:  # every box would take the box rule's viewpoint: seconds for nothing
        raise ValueError("return_all needs fit_viewpoints (the boxes kept above the threshold)")
    bank = detector_bank(None) if bank is None else bank
    keep = read = threshold
    add_at = None  # every pass cut at one threshold: every box counts
    if fit_viewpoints:
        keep = bank.threshold if threshold is None else float(threshold)
        fit = PredetectOptions().threshold if bank.calibration is not None else keep  # margins: no common scale
        read, add_at = min(keep, fit), fit
    clock = time.perf_counter()
    pyramid, mount = frame_mount(camera, image, bank=bank, told=mount, estimate_pitch=estimate_pitch,
                                 smallest_car=smallest_car, pyramid=pyramid)  # one mount for every pass
    passes = list(frame_passes(bank, camera, image, upsample, smallest_car, pyramid=pyramid))
    spent = time.perf_counter() - clock
    merged = None  # (every, viewed) in the image's pixels
    for p in passes:
        clock = time.perf_counter()
        found, levels, responses = bank_pass(p.camera, p.image, bank=bank, threshold=read, return_all=return_all,
                                             smallest_car=p.smallest_car, min_scale=p.min_scale, pyramid=p.pyramid,
                                             mount=mount, keep_responses=viewpoints, cross_view_nms=cross_view_nms,
                                             source=source)
        spent += time.perf_counter() - clock
        viewed = None
        if viewpoints and fit_viewpoints:
            viewed = detections_above(p.camera, p.image, found, read, bank=bank, classifier=classifier,
                                      pyramid=levels, responses=responses, mount=mount)
        elif viewpoints:
            viewed = with_rule_viewpoints(p.camera, p.image, found, bank=bank, classifier=classifier, pyramid=levels,
                                          responses=responses, mount=mount)
        del levels, responses  # this pass's features and maps, freed before the next pass's
        if viewed is not None and not return_all:  # every box found is neither returned nor shown
            found = None
        here = [None if d is None else boxes_back(d, p.factors, image.shape[1::-1]) for d in (found, viewed)]
        merged = here if merged is None else [None if d is None else add_enlarged(d, more, threshold=add_at)
                                              for d, more in zip(merged, here)]
    if seconds is not None:
        seconds.append(spent)
    every, viewed = merged
    shown = every if viewed is None else viewed
    kept = shown.subset(shown.scores > keep) if fit_viewpoints else shown
    return (every, kept) if return_all else kept


def bank_pass(camera: Camera | None, image: np.ndarray, *, bank, threshold: float | None = None,
              return_all: bool = False, pyramid: list | None = None, smallest_car: float | None = None,
              min_scale: float | None = None, mount: Mount = KITTI_MOUNT, keep_responses: bool = True,
              cross_view_nms: float | None = 0.3, source: str = "bank"):
    """One pass of the detector ``bank`` over ``image``: the feature pyramid its smallest car
    needs (``smallest_car``, :func:`~wirescene.predetect.bank.smallest_car_search`), down to
    ``min_scale`` (None: the bank's own; or ``pyramid``, given), then
    :func:`~wirescene.predetect.detect_cars` at ``threshold`` (None: the bank's own), or every
    score with ``return_all``, with the camera's ``mount``
    (:func:`~wirescene.fitting.mount.frame_mount`) and its ``cross_view_nms``. Returns
    ``(detections, pyramid, responses)``: what the box rule reads after it (``responses`` None
    unless ``keep_responses``); each pass of :func:`own_detections`.

    Examples
    --------
    >>> found, pyramid, responses = bank_pass(None, np.zeros((64, 96, 3), np.uint8), bank=detector_bank(None))
    >>> found.boxes.shape, len(responses) > 0
    ((0, 4), True)
    """
    from wirescene.predetect import detect_cars
    from wirescene.predetect.bank import bank_pyramid

    min_height, max_scale = smallest_car_search(bank, smallest_car)
    pyramid = bank_pyramid(bank, image, max_scale=max_scale, min_scale=min_scale) if pyramid is None else pyramid
    responses = {} if keep_responses else None
    found = detect_cars(image, bank=bank, camera=camera, threshold=threshold, return_all=return_all, pyramid=pyramid,
                        responses=responses, min_height=min_height, mount=mount, cross_view_nms=cross_view_nms,
                        source=source)
    return found, pyramid, responses
