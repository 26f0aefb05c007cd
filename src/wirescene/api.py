"""The Python API: plain functions on arrays (or paths), inputs checked at this boundary.

Every wrong argument raises :class:`~wirescene.core.errors.ArgumentError` (a
``ValueError``) whose message starts with the argument's name; unreadable files raise
:class:`~wirescene.core.errors.InputError` naming the file. The work itself is done by
:func:`wirescene.fitting.pipeline.fit_frame`, the same orchestration the CLI runs.
"""

from __future__ import annotations

import numbers
import sys
import warnings
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from wirescene.core.camera import Camera, KittiCalib, read_projection
from wirescene.core.errors import ArgumentError, CalibrationWarning, HeldOutWarning, InputError, ShapeError
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, Mount
from wirescene.core.image import range_problem, to_rgb_uint8
from wirescene.core.settings import check_value, stage_field
from wirescene.core.types import Detections, SceneEstimate, car_fitted
from wirescene.core.validate import (
    MAX_WORKERS,
    boxes_problem,
    empty_path_problem,
    finite_real,
    image_size_problem,
    normalised_boxes_problem,
    off_centre_problem,
    output_dir_problem,
    projection_problem,
    real_dtype_problem,
)
from wirescene.fitting.options import FitOptions
from wirescene.fitting.pipeline import fit_frame
from wirescene.fitting.variants import DEFAULT_VARIANT, VARIANTS, casts_rays
from wirescene.infer.inference import InferenceOptions
from wirescene.lift import MAX_PARTICLES, LiftingOptions

__all__ = ["fit", "detect", "draw", "evaluate", "as_image", "as_camera", "as_detections"]


def _is_pil_image(image) -> bool:
    """Whether ``image`` is a PIL image (without importing PIL for other inputs)."""
    pil = sys.modules.get("PIL.Image")
    return pil is not None and isinstance(image, pil.Image)


def as_image(image, *, name: str = "image") -> np.ndarray:
    """The image every entry point reads: ``(H, W, 3)`` uint8 RGB.

    Parameters
    ----------
    image : path, ndarray or PIL image
        An image file, a PIL image (read as its file would be), or an ``(H, W)`` /
        ``(H, W, 1|3|4)`` array: uint8, uint16 (a 16-bit PNG's range), other integers
        holding 8-bit values (others refused: :func:`wirescene.core.image.integer_range_problem`),
        bool, or float in [0, 1] (or [0, 255] when larger; others refused:
        :func:`wirescene.core.image.float_range_problem`); an alpha channel is dropped.
    name : str
        The argument's name in error messages.

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Raises
    ------
    ArgumentError
        Not an image array or PIL image (shape, dtype, non-finite values, integers beyond 8-bit
        values but uint16's, floats outside both [0, 1] and [0, 255], under 16 px a side).
    InputError
        An image file that is missing, unreadable, under 16 px a side or of such values.

    Examples
    --------
    >>> import numpy as np
    >>> rgb = as_image(np.ones((20, 30)))  # grey, float in [0, 1]
    >>> rgb.shape, rgb.dtype.name, int(rgb.max())
    ((20, 30, 3), 'uint8', 255)
    """
    if isinstance(image, (str, Path)):
        from wirescene.io.kitti import read_image

        return read_image(image)
    pil = _is_pil_image(image)
    if not pil and not isinstance(image, np.ndarray):
        raise ArgumentError(name, f"expected a path, a numpy array or a PIL image, got {type(image).__name__}")
    try:
        if pil:
            from wirescene.io.kitti import rgb_of_pil

            rgb = rgb_of_pil(image)
        else:
            rgb = to_rgb_uint8(image)
    except ShapeError as exc:
        raise ArgumentError(name, exc.problem) from None
    except (OSError, ValueError) as exc:  # a PIL image that cannot be converted
        raise ArgumentError(name, f"unreadable PIL image ({' '.join(str(exc).split())})") from None
    # after the shape's check: an int32 array of 16-bit values read black (a PIL image's checked by rgb_of_pil)
    problem = (None if pil else range_problem(image)) or image_size_problem((rgb.shape[1], rgb.shape[0]))
    if problem:
        raise ArgumentError(name, problem)
    return rgb


def as_camera(calib, image_size: tuple[int, int], *, name: str = "calib") -> Camera:
    """The camera every entry point reads, checked for sanity
    (:func:`wirescene.core.validate.projection_problem`).

    Parameters
    ----------
    calib : path, (3, 4) or (3, 3) array, KittiCalib or Camera
        A calibration path (:func:`wirescene.core.camera.read_projection`: a KITTI file's
        ``P2``, or the numbers of ``K`` or ``P``), a projection matrix ``P``, an intrinsic
        matrix ``K`` (``P = K [I | 0]``), a :class:`KittiCalib` (its ``P2``) or a
        :class:`Camera`.
    image_size : (int, int)
        ``(width, height)`` of the image it is used with.
    name : str
        The argument's name in error messages.

    Returns
    -------
    Camera
        With ``image_size`` set.

    Raises
    ------
    ArgumentError
        Naming ``name``: not a matrix of real numbers, of another shape, non-finite, or no
        plausible street camera.
    InputError
        A calibration file that is missing, malformed or no plausible camera, naming it.

    Examples
    --------
    >>> import numpy as np
    >>> K = [[721.5, 0, 609.6], [0, 721.5, 172.9], [0, 0, 1]]
    >>> camera = as_camera(K, (1242, 375))
    >>> camera.P.shape, camera.image_size
    ((3, 4), (1242, 375))
    >>> as_camera(np.eye(3), (1242, 375))
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ArgumentError: calib: ...
    """
    if isinstance(calib, (str, Path)):
        P = read_projection(calib)  # InputError naming the file
        problem = projection_problem(P, image_size)
        if problem:
            raise InputError(problem, path=calib)
        return Camera(P, image_size)
    if isinstance(calib, Camera):
        P = calib.P
    elif isinstance(calib, KittiCalib):
        P = calib.P2
    elif isinstance(calib, (np.ndarray, list, tuple)):
        try:
            P = np.asarray(calib)
            P = P if real_dtype_problem(P) else P.astype(float)  # complex, bool, text: refused below, not cast
        except (TypeError, ValueError):
            raise ArgumentError(name, "expected a matrix of numbers (rows of equal length)") from None
        if P.shape == (3, 3):
            P = np.hstack([P, np.zeros((3, 1), dtype=P.dtype)])
    else:
        raise ArgumentError(name, f"expected a calibration path, a (3, 4) matrix P, a (3, 3) matrix K or a Camera, "
                                  f"got {type(calib).__name__}")
    problem = real_dtype_problem(P) or projection_problem(P, image_size)
    if problem:
        raise ArgumentError(name, problem)
    return Camera(P.astype(float), image_size)


def off_centre_message(camera: Camera, image) -> str | None:
    """What is said where ``camera`` looks made for another size than its image's
    (:func:`wirescene.core.validate.off_centre_problem`), or None: the problem, after
    ``IMAGE: `` if ``image`` is a path; the API warns it (:func:`fit`, :func:`detect`), the
    commands of one image (``fit``, ``gt``) print it.

    Parameters
    ----------
    camera : Camera
        The calibration and the size of the image it is used with.
    image : path or image
        The image, named in the message if it is a path.

    Returns
    -------
    str or None

    Examples
    --------
    >>> P = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> off_centre_message(Camera(P, (1242, 375)), "000010.png") is None
    True
    >>> off_centre_message(Camera(P, (621, 187)), "small.png")
    'small.png: the principal point (609.6, 172.9) lies in the outer quarter of the 621x187 image: the calibration of a larger image, or of a crop?'
    """
    problem = off_centre_problem(camera.P, camera.image_size)
    if problem is None:
        return None
    return f"{image}: {problem}" if isinstance(image, (str, Path)) else problem


def _warn_off_centre(camera: Camera, image) -> None:
    """A :class:`~wirescene.core.errors.CalibrationWarning` of :func:`off_centre_message`, if
    any, attributed to the caller of the API function that calls this."""
    message = off_centre_message(camera, image)
    if message is not None:
        warnings.warn(message, CalibrationWarning, stacklevel=3)


def as_detections(boxes, image_size: tuple[int, int], *, name: str = "boxes") -> Detections:
    """The boxes every entry point reads.

    Parameters
    ----------
    boxes : (N, 4) array or Detections
        ``x1 y1 x2 y2`` in pixels (score 1, unknown viewpoint), or :class:`Detections`.
    image_size : (int, int)
        ``(width, height)`` of the image the boxes lie in.
    name : str
        The argument's name in error messages.

    Returns
    -------
    Detections

    Raises
    ------
    ArgumentError
        Naming ``name``: not ``(N, 4)`` real numbers, a box non-finite, empty or inverted,
        entirely outside the image or absurdly far beyond it, every box under a pixel
        (normalised coordinates), non-finite scores or infinite viewpoints.

    Examples
    --------
    >>> dets = as_detections([[300, 180, 520, 300]], (1242, 375))
    >>> dets.boxes.shape, dets.scores.tolist(), bool(np.isnan(dets.alpha[0]))
    ((1, 4), [1.0], True)
    """
    if isinstance(boxes, Detections):
        dets = boxes
    else:
        if not isinstance(boxes, (np.ndarray, list, tuple)):
            raise ArgumentError(name, f"expected an (N, 4) array or Detections, got {type(boxes).__name__}")
        try:
            b = np.asarray(boxes)
        except ValueError:
            raise ArgumentError(name, "expected an (N, 4) array: rows of 4 numbers, all of one length") from None
        if b.size == 0:
            b = b.reshape(0, 4)
        problem = boxes_problem(b)
        if problem:
            raise ArgumentError(name, problem)
        dets = Detections(b.astype(float), np.ones(len(b)), np.full(len(b), np.nan), source="api")
    problem = boxes_problem(dets.boxes, image_size) or normalised_boxes_problem(dets.boxes)
    if problem:
        raise ArgumentError(name, problem)
    if not np.all(np.isfinite(dets.scores)):
        raise ArgumentError(name, "detection scores must be finite")
    if np.any(np.isinf(dets.alpha)):
        raise ArgumentError(name, "viewpoints (alpha) must be finite or NaN (unknown)")
    return dets


def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ArgumentError(name, f"must be a positive integer, got {value!r}")
    return int(value)


def _workers(value) -> int:
    workers = _positive_int(value, "workers")
    if workers > MAX_WORKERS:  # each a process of some 440 MB
        raise ArgumentError("workers", f"must be at most {MAX_WORKERS:,} (the larger of 64 and the cores), "
                                       f"got {workers!r}")
    return workers


def _particles(value) -> int:
    particles = _positive_int(value, "particles")
    if particles > MAX_PARTICLES:  # a typo's hours of fitting, refused here rather than as a field of options
        raise ArgumentError("particles", f"must be at most {MAX_PARTICLES:,}, got {particles!r}")
    return particles


def _seed(value) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        raise ArgumentError("seed", f"must be a non-negative integer, got {value!r}")
    return int(value)


def _variant_names(variant, name: str = "variant") -> list[str]:
    if not isinstance(variant, Iterable):  # a name (str) is iterable too
        raise ArgumentError(name, f"expected a variant name, got {type(variant).__name__}; available: {', '.join(VARIANTS)}")
    names = [variant] if isinstance(variant, str) else list(variant)
    for v in names:
        if v not in VARIANTS:
            raise ArgumentError(name, f"unknown variant {v!r}; available: {', '.join(VARIANTS)}")
    if not names:
        raise ArgumentError(name, "no variant given")
    return names


def _models(models):
    """The :class:`~wirescene.core.resources.Models` of a models directory (None: shipped)."""
    from wirescene.core.resources import resolve_models

    if models is not None and not isinstance(models, (str, Path)):
        raise ArgumentError("models", f"expected a models directory path, got {type(models).__name__}")
    problem = empty_path_problem(models)  # "" (an unset variable) is no name for the current directory
    if problem:
        raise ArgumentError("models", problem)
    return resolve_models(models)  # InputError naming the directory or file


def _options(options: FitOptions | None, particles, seed, models=None, settings=None, *,
             parallel: bool = False, casts_rays: bool = True) -> FitOptions:
    """The fit's options of the API's arguments, the device resolved and checked before
    any work (:func:`wirescene.infer.torch_backend.choose_device`, as the CLI's; ``casts_rays``:
    a variant to be fitted is a fine one, :func:`wirescene.fitting.variants.casts_rays`)."""
    from dataclasses import replace

    from wirescene.fitting.models import check_model_files, with_models
    from wirescene.infer.torch_backend import choose_device

    if options is not None:
        if not isinstance(options, FitOptions):
            raise ArgumentError("options", f"expected FitOptions, got {type(options).__name__}")
    else:
        options = FitOptions(lifting=LiftingOptions(n_particles=_particles(particles)),
                             inference=InferenceOptions(), seed=_seed(seed))
    # the directory's models before the settings: settings={"inference.occluded_score": ...} wins over its c
    options = with_models(options, _models(models))
    if settings is not None:
        if not isinstance(settings, Mapping):
            raise ArgumentError("settings", f"expected a mapping of 'STAGE.FIELD' to values, got {type(settings).__name__}")
        try:
            options = options.with_settings(settings)
        except (ValueError, TypeError) as exc:
            raise ArgumentError("settings", str(exc)) from None
    device = choose_device(options.inference.device, parallel=parallel, casts_rays=casts_rays)
    options = replace(options, inference=replace(options.inference, device=device))
    return check_model_files(options, fine=casts_rays)  # a bad model file: an InputError naming it, before any work


def fit(
    image,
    calib,
    boxes=None,
    *,
    variant: str = DEFAULT_VARIANT,
    particles: int = 250,
    seed: int = 0,
    options: FitOptions | None = None,
    models=None,
    settings=None,
) -> SceneEstimate:
    """Estimate the 3D cars of one street image.

    Parameters
    ----------
    image : path, ndarray or PIL image
        An image file, a PIL image, or an ``(H, W, 3)`` / ``(H, W)`` array (uint8, uint16
        or float in [0, 1] or [0, 255]; a float image fitting neither is refused); see
        :func:`as_image`.
    calib : path, (3, 4) array, (3, 3) array, KittiCalib or Camera
        A KITTI calibration file (``P2`` is used) or a text file of the 12 numbers of a
        projection matrix or the 9 of the intrinsics ``K``; a projection matrix ``P`` in
        the KITTI rectified camera frame (x right, y down, z forward, metres); ``K``
        (``P = K [I | 0]``); :func:`wirescene.read_kitti_calib`'s result (its ``P2``); or a
        camera.
    boxes : None, (N, 4) array or Detections
        2D car boxes ``x1 y1 x2 y2`` in pixels from any detector (viewpoints are then
        taken from the box rule, :func:`wirescene.fitting.own_boxes.complete_viewpoints`),
        or :class:`Detections` with viewpoints; ``None`` runs wirescene's own
        pre-detection, whose boxes the fit verifies (cars it finds unlikely are dropped:
        ``settings={"predetect.min_car_probability": 0}`` keeps them all) and weighs less than
        given boxes (``predetect.box_weight`` 30 against ``inference.box_weight`` 100: they
        miss the car's outline by more). A box reaching past the image is clipped to it
        (:func:`wirescene.fitting.pipeline.inside_image`).
    variant : str
        Model variant (paper Sec. 5.2): ``coarse``, ``coarse+gp``, ``fg``, ``fg+so``,
        ``fg+do``, ``fg+gp`` or ``full``.
    particles : int
        Scene particles kept by the coarse stage (ignored when ``options`` is given, and
        overridden by ``settings["lifting.n_particles"]``).
    seed : int
        Seed of the inference's random sampling; equal seeds give equal results.
    options : FitOptions, optional
        Every stage's options (overrides ``particles`` and ``seed``), with the trained files
        the fit reads (``parts_model``, ``detector_bank``, ``viewpoint_classifier``,
        ``score_calibration``, ``shape_model``; None: the shipped file).
    models : path, optional
        A models directory (``wirescene train all --out MODELS_DIR``): its part model,
        detector bank, crop viewpoint classifier, score calibration, shape model and
        occluded-part score replace the shipped ones (a file set in ``options`` is kept);
        what it lacks stays shipped.
    settings : mapping, optional
        ``{"STAGE.FIELD": value}`` changes to the stages' options, by the names of the
        command line's ``--set`` (e.g. ``{"inference.box_weight": 50}``; stages
        ``lifting``, ``inference`` and ``predetect``, see :meth:`FitOptions.with_settings`).

    Returns
    -------
    SceneEstimate
        ``.cars`` (each with ``location`` (3,), ``rotation_y``, ``dimensions`` (h, w, l),
        ``vertices`` (36, 3), ``visible`` (36,), ``hidden_by`` (36,) (what hides each vertex),
        ``box``, ``score``, ``cad_model``; the coarse variants fit no wireframe: their
        ``vertices``, ``visible``, ``hidden_by`` and ``cad_model`` are None),
        ``.ground_plane`` (None for a variant without ``+gp``
        or ``full``), ``.to_kitti()`` and ``.to_dict()``.

    Raises
    ------
    ArgumentError
        A ``ValueError`` naming the argument that is wrong (a setting or option out of
        its range included).
    InputError
        A file (image, calibration, a model of ``models``) is missing or malformed.
    DeviceError
        ``settings["inference.device"]`` names a device this machine lacks.

    Warns
    -----
    CalibrationWarning
        The calibration's principal point lies in the outer quarter of the image: it looks
        made for another image size (a larger or smaller image's, or a crop's), which places
        every car wrongly (:func:`wirescene.core.validate.off_centre_problem`).

    Examples
    --------
    >>> import numpy as np, wirescene
    >>> P = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> image = np.full((375, 1242, 3), 128, np.uint8)
    >>> scene = wirescene.fit(image, P, [[300, 180, 520, 300]], variant="coarse+gp", particles=20)
    >>> car = scene.cars[0]
    >>> car.location.shape, car.dimensions.shape
    ((3,), (3,))
    >>> bool(5 < car.location[2] < 30)  # metres in front of the camera
    True
    >>> scene.to_kitti().split()[0]
    'Car'
    """
    rgb = as_image(image)
    size = (rgb.shape[1], rgb.shape[0])
    camera = as_camera(calib, size)
    dets = None if boxes is None else as_detections(boxes, size)
    names = _variant_names(variant)
    if len(names) != 1:
        raise ArgumentError("variant", f"fit takes one variant, got {len(names)}; fit_frame or evaluate fit several")
    (name,) = names
    options = _options(options, particles, seed, models, settings, casts_rays=casts_rays(names))
    _warn_off_centre(camera, image)  # once every argument is accepted, before the fit
    fitted = fit_frame(camera, dets, [name], image=rgb, options=options)
    return fitted.estimates[name]


def detect(image, calib=None, *, models=None, threshold: float | None = None,
           camera_height: float = KITTI_CAMERA_HEIGHT, camera_pitch: float = 0.0, estimate_pitch: bool = False,
           smallest_car: float | None = None, upsample: float | None = None) -> Detections:
    """wirescene's own 2D pre-detection of cars (paper Sec. 3.4).

    Parameters
    ----------
    image : path, ndarray or PIL image
        As in :func:`fit`.
    calib : path, (3, 4) array or Camera, optional
        The camera; when given, each detection's score also weighs how well its box's
        height fits its position below the horizon (the bank's ground prior,
        :mod:`wirescene.predetect.geometry`), which the shipped bank was calibrated with,
        and each box's viewpoint is chosen by the bank's templates inside it, the crop
        viewpoint classifier and where the car stands on the road
        (:func:`wirescene.fitting.own_boxes.own_detections`); without it the detector's own
        viewpoints stay.
    models : path, optional
        A models directory whose detector bank and crop viewpoint classifier replace the
        shipped ones.
    threshold : float, optional
        Keep the detections scoring above it (default: the bank's own, 0.5 for the shipped
        one, its 2D operating point). The fit's own pre-detection keeps those above 0.3
        (``PredetectOptions.threshold``) and verifies them after the fit; the viewpoints
        are the fit's whatever the threshold (the box rule reads the boxes above 0.3).
    camera_height : float, optional
        The camera's height above the road in metres (KITTI's 1.65 m by default), for the
        ground and traffic priors, which were learned at KITTI's; the fit reads it from
        ``settings={"lifting.camera_height": H}``.
    camera_pitch : float, optional
        Degrees the camera looks down from the road (KITTI's rig: level, 0), which raises the
        horizon those priors read by ``f tan(pitch)`` pixels; the fit reads it from
        ``settings={"lifting.camera_pitch": D}``.
    estimate_pitch : bool, optional
        Read the camera's pitch off the boxes the bank finds without those priors, about
        ``camera_pitch`` (:func:`wirescene.fitting.mount.image_mount`; a camera whose tilt is
        not known; one more pass of the bank over the image, 1.3x the pre-detection's time);
        the fit reads it from ``settings={"lifting.estimate_pitch": True}``.
    smallest_car : float, optional
        The smallest car height searched in pixels, at least 10 (None or 0: the bank's own,
        25 px), the image upsampled to reach it: e.g. scaled by the focal length for a camera
        of longer focal length than KITTI's 721 px; ``upsample``'s enlarged image adds the
        levels finer than those it reaches, none for 25 px or more (no smaller car is searched);
        the fit reads it from ``settings={"predetect.smallest_car": S}``.
    upsample : float, optional
        Also detect on the image enlarged by this factor, 1 to 3 (Lanczos, up to a 4K frame's
        pixels), at its pyramid levels finer than the image's (:mod:`wirescene.predetect.enlarge`),
        adding the cars it finds above the fit's threshold 0.3 that no box of the image above
        it covers (an image box below it over one of them is replaced), their boxes in the
        image's pixels, as the fit adds them: KITTI's small, far cars. None: the fit's, 1.5
        (``settings={"predetect.upsample": F}``), at 2.3x the time of 1 (the image alone).

    Returns
    -------
    Detections
        Boxes ``(D, 4)``, calibrated scores ``(D,)`` and viewpoints ``alpha`` ``(D,)``.

    Warns
    -----
    CalibrationWarning
        As :func:`fit`: ``calib``'s principal point lies in the outer quarter of the image.

    Examples
    --------
    >>> import wirescene
    >>> from wirescene.core.resources import DATA_DIR
    >>> frame = DATA_DIR / "sample" / "kitti" / "training"
    >>> dets = wirescene.detect(frame / "image_2" / "000010.png", frame / "calib" / "000010.txt")
    >>> dets.boxes.shape[1], dets.scores.shape == dets.alpha.shape
    (4, True)
    >>> bool((dets.scores > 0.5).all())  # above the shipped bank's threshold
    True
    """
    from wirescene.fitting.models import detector_bank, viewpoint_classifier
    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.own_boxes import own_detections

    if threshold is not None and not finite_real(threshold):
        raise ArgumentError("threshold", f"expected a finite number or None, got {threshold!r}")
    upsample = PredetectOptions().upsample if upsample is None else upsample
    # the bounds `--set lifting.NAME` / `--set predetect.NAME` and the detect command check
    for stage, name, value in ((LiftingOptions, "camera_height", camera_height),
                               (LiftingOptions, "camera_pitch", camera_pitch),
                               (LiftingOptions, "estimate_pitch", estimate_pitch),
                               (PredetectOptions, "smallest_car", 0.0 if smallest_car is None else smallest_car),
                               (PredetectOptions, "upsample", upsample)):
        try:
            check_value(stage_field(stage, name), value)
        except ValueError as exc:
            raise ArgumentError(name, str(exc).removeprefix(f"{name} ")) from None
    mount = Mount(float(camera_height), float(camera_pitch))
    rgb = as_image(image)
    camera = None if calib is None else as_camera(calib, (rgb.shape[1], rgb.shape[0]))
    given = _models(models)
    bank = detector_bank(given.file("detector_bank"))  # the directory's, else the shipped one (as `detect --models`)
    classifier = viewpoint_classifier(given.file("viewpoint_classifier"))
    if camera is not None:  # once every argument is accepted, before the detection
        _warn_off_centre(camera, image)
    # the fit's boxes and viewpoints above the threshold, the enlarged image's cars added as the fit adds them
    return own_detections(camera, rgb, bank=bank, classifier=classifier, threshold=threshold, fit_viewpoints=True,
                          upsample=upsample, smallest_car=smallest_car, mount=mount, estimate_pitch=estimate_pitch)


DRAW_VIEWS = ("overlay", "bev")


def draw(image, calib, scene: SceneEstimate | None = None, *, view: str = "overlay", gt=None, boxes=None,
         title: str | None = None):
    """A picture of what the model did, as a matplotlib figure.

    Parameters
    ----------
    image : path, ndarray or PIL image
        As in :func:`fit`.
    calib : path, (3, 4) array or Camera
        As in :func:`fit`.
    scene : SceneEstimate, optional
        What :func:`fit` returned: its cars are drawn red, each numbered as in
        :attr:`SceneEstimate.cars` (``#1`` the first), in the ``overlay`` with its confidence
        (the fitted wireframes, each hidden vertex marked by what hides it: the car itself, another
        car, the occluder mask the fit chose, hatched, or the image's border), in the ``bev``
        as footprints and headings; the ``overlay`` draws the shared ground plane of a ``+gp``
        variant or ``full`` as a grid of thin white lines, every 10 m ahead and 5 m aside
        (:func:`wirescene.io.pictures.ground_grid`).
    view : str
        ``"overlay"`` (the image, full size; one of more pixels than a 3840 x 2160 frame
        reduced by a whole factor, :func:`wirescene.io.pictures.drawn_image`) or ``"bev"``
        (bird's-eye view, x right, z up the page, the camera's field of view dotted).
    gt : path or sequence of Label, optional
        A KITTI label file (or its labels): its cars' 3D boxes are drawn cyan; beside a
        fitted ``scene``, the cars the evaluation counts false are violet and tagged
        ``false`` (``false view``: on a labelled car, its pre-detection's viewpoint over 45
        deg off the car's), the labelled cars it counts missed dashed and tagged ``missed``
        (:func:`wirescene.core.matching.match_estimate`), and the ``bev`` joins each car
        matched to a labelled car to it with a thin dark line (dash-dotted for a ``false view``).
    boxes : (N, 4) array or Detections, optional
        2D boxes drawn dashed yellow in the ``overlay`` (e.g. :func:`detect`'s, or
        ``scene.detections``, the boxes the fit started from); checked but not drawn in the
        ``bev``. A box that is one of ``scene.detections`` (compared once clipped to the
        image, as the fit clips them) to which no car was fitted, a box of our own
        pre-detection that the fit's verification dropped, is drawn dotted grey instead, as
        ``wirescene fit``'s overlay draws it.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        Not managed by pyplot: a notebook shows it as a cell's value, ``fig.savefig(path)``
        writes it, and the caller's matplotlib backend is left as it was.

    Examples
    --------
    >>> import numpy as np, wirescene
    >>> P = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> image = np.full((375, 1242, 3), 128, np.uint8)
    >>> scene = wirescene.fit(image, P, [[300, 180, 520, 300]], variant="coarse", particles=20)
    >>> fig = wirescene.draw(image, P, scene, boxes=scene.detections)
    >>> [int(v) for v in fig.get_size_inches() * fig.dpi]  # the image's own size
    [1242, 375]
    >>> type(wirescene.draw(image, P, scene, view="bev")).__name__
    'Figure'
    """
    from wirescene.core.wireframe import EDGES
    from wirescene.io.pictures import birds_eye, overlay

    if view not in DRAW_VIEWS:
        raise ArgumentError("view", f"expected one of {', '.join(DRAW_VIEWS)}, got {view!r}")
    if scene is not None and not isinstance(scene, SceneEstimate):
        raise ArgumentError("scene", f"expected what wirescene.fit returns (SceneEstimate), got {type(scene).__name__}")
    if title is not None and not isinstance(title, str):
        raise ArgumentError("title", f"expected a string, got {type(title).__name__}")
    rgb = as_image(image)
    size = (rgb.shape[1], rgb.shape[0])
    camera = as_camera(calib, size)
    cars = _gt_cars(gt, size)
    dets = None if boxes is None else as_detections(boxes, size)  # checked in either view
    if view == "bev":
        return birds_eye(scene, gt=cars, camera=camera, title=title)
    dropped = None if dets is None else _dropped_boxes(dets, scene, size)
    if dropped is not None:
        dets, dropped = dets.subset(~dropped), dets.subset(dropped)
    return overlay(rgb, camera, scene, gt=cars, detections=dets, dropped=dropped, title=title, edges=EDGES)


def _dropped_boxes(dets: Detections, scene: SceneEstimate | None, image_size: tuple[int, int]) -> np.ndarray | None:
    """Which of ``dets`` are boxes the fit of ``scene`` dropped: one of its pre-detections
    (``scene.detections``, compared once clipped to the image as the fit clips them) with no
    car fitted to it (:func:`wirescene.core.types.car_fitted`), and no car fitted to an equal one; None when
    ``scene`` does not say which boxes it was fitted to.

    Examples
    --------
    >>> from wirescene.core.types import ObjectEstimate
    >>> fitted = Detections([[0, 0, 10, 10], [20, 0, 30, 10]], 1.0, 0.0)
    >>> car = ObjectEstimate(detection_index=1, box2d=fitted.boxes[1], score=1.0, location=np.array([0.0, 1.65, 9.0]),
    ...                      R=np.eye(3), dims=np.array([1.5, 1.6, 3.9]), cost=0.0)
    >>> scene = SceneEstimate(variant="coarse", objects=[car], detections=fitted)
    >>> drawn = Detections([[20, 0, 30, 10], [-5, 0, 10, 10], [40, 0, 50, 10]], 1.0, 0.0)  # the second one clipped
    >>> _dropped_boxes(drawn, scene, (100, 50)).tolist()
    [False, True, False]
    """
    from wirescene.fitting.pipeline import inside_image

    fitted = None if scene is None else scene.detections
    if fitted is None:
        return None
    drawn = inside_image(dets, image_size).boxes
    same = np.all(np.abs(drawn[:, None, :] - fitted.boxes[None, :, :]) <= 1e-6, axis=2)  # (drawn, fitted)
    return same.any(axis=1) & ~(same & car_fitted(fitted, scene)).any(axis=1)


def _gt_cars(gt, image_size: tuple[int, int]) -> list | None:
    """The ``Car`` labels of a KITTI label file (every row's box checked against the
    ``image_size`` ``(width, height)`` image, as a frame's labels are), or of a sequence of
    labels (None: no labels, as the pictures take it; a file without cars gives ``[]``)."""
    from wirescene.core.labels import CAR_TYPES, FrameLabels, Label, is_type

    if gt is None:
        return None
    if isinstance(gt, (str, Path)):
        from wirescene.io.kitti import read_labels

        return read_labels(gt, image_size=image_size).of_type(*CAR_TYPES)  # InputError naming the file
    if isinstance(gt, FrameLabels):
        return gt.of_type(*CAR_TYPES)
    labels = list(gt) if isinstance(gt, Iterable) else [gt]
    if not all(isinstance(g, Label) for g in labels):
        raise ArgumentError("gt", "expected a KITTI label file or a sequence of wirescene.core.labels.Label")
    return [g for g in labels if is_type(g.type, CAR_TYPES)]  # the cars the evaluation's matching judges


def evaluate(
    kitti_root,
    *,
    variants: str | Iterable[str] = ("coarse+gp", "full"),
    detections: str = "gt",
    frames: Iterable[str | int] | str | int | None = None,
    split_file=None,
    particles: int = 250,
    seed: int = 0,
    workers: int = 1,
    predictions=None,
    resume: bool = False,
    models=None,
    settings=None,
    min_score: float | None = None,
    calib=None,
):
    """Fit and evaluate variants on a KITTI directory with the paper's protocol.

    Parameters
    ----------
    kitti_root : path
        A KITTI object root (with ``training/``) or a split directory with
        ``image_2/``, ``calib/`` and ``label_2/`` (no ``calib/`` with ``calib``).
    variants : str or iterable of str
        Model variants to fit.
    detections : str
        ``"gt"`` (label boxes), ``"bank"`` (our pre-detection) or a directory with one
        detection file per frame.
    min_score : float, optional
        With a ``detections`` directory: fit only the boxes scoring at or above it (a file
        with none left is a frame without detections); None (default) keeps every box. Not
        with ``"gt"`` or ``"bank"`` (whose floor is ``settings={"predetect.threshold": ...}``).
    frames : str, int or iterable of them, optional
        Frame ids, an int written ``%06d`` as :class:`~wirescene.io.kitti.KittiDataset` reads it
        (``10`` is ``"000010"``; :func:`~wirescene.io.kitti.as_frame_ids`, each frame once; a bool,
        a negative int or a float refused); default: every labelled frame.
    split_file : path, optional
        Instead of ``frames``: a file listing them, one id a line (KITTI's
        ``ImageSets/val.txt`` format; see :func:`wirescene.io.splits.read_split_file`).
    particles, seed : int
        As in :func:`fit`.
    workers : int
        Processes fitting frames in parallel (at most
        :data:`~wirescene.core.validate.MAX_WORKERS`, the larger of 64 and the cores).
    predictions : path, optional
        Also write KITTI label files per variant there, and each finished frame's record
        (``.frames/``); a directory holding an earlier run's records needs ``resume``.
    resume : bool
        Reuse the records in ``predictions`` written with the same settings and fit only
        the other frames (``eval --resume``); the earlier run's frames must be among those
        chosen now (a smaller selection is refused: their label files would stay).
    models : path, optional
        A models directory replacing the shipped artefacts, as in :func:`fit`.
    settings : mapping, optional
        Changes to the stages' options, as in :func:`fit`.
    calib : path, optional
        A calibration file for every frame (a camera other than KITTI's whose frames share it;
        ``eval --calib``): :class:`~wirescene.io.kitti.KittiDataset`'s ``calib``.

    Returns
    -------
    dict of str to EvaluationReport
        Per variant: ``.metrics`` (localisation within 1 m / 1.5 m, azimuth errors, ...).

    Warns
    -----
    HeldOutWarning
        Some frames evaluated are frames a model the run reads was trained on (the shipped
        models' 72, told by their images' content, a models directory's own, or those a
        trained file records): their figures are not held out (:func:`wirescene.eval.held_out.trained_on_frames`).

    Examples
    --------
    >>> import warnings
    >>> import wirescene
    >>> from wirescene.core.resources import DATA_DIR
    >>> with warnings.catch_warnings(record=True) as said:  # the sample's frames: two of the shipped models' 72
    ...     warnings.simplefilter("always")
    ...     reports = wirescene.evaluate(DATA_DIR / "sample" / "kitti", variants="coarse", frames=["000010"],
    ...                                  particles=20)
    >>> [w.category.__name__ for w in said]
    ['HeldOutWarning']
    >>> m = reports["coarse"].metrics["all"]
    >>> m["n_gt"], m["n_tp"]  # the label boxes are the pre-detections: every car is a true positive
    (8, 8)
    >>> bool(0 <= m["loc_1m"] <= 100)
    True
    """
    from wirescene.eval.runner import evaluate_dataset
    from wirescene.eval.sources import DetectionSource, min_score_problem
    from wirescene.io.kitti import KittiDataset, as_frame_ids

    names = _variant_names(variants, "variants")
    if not isinstance(kitti_root, (str, Path)):
        raise ArgumentError("kitti_root", f"expected a directory path, got {type(kitti_root).__name__}")
    problem = empty_path_problem(kitti_root)  # "" (an unset variable) is no name for the current directory
    if problem:
        raise ArgumentError("kitti_root", problem)
    # evaluate_dataset's own check (as predictions_dir), here before the models and the device are read
    problem = None if predictions is None else output_dir_problem(predictions)
    if problem:
        raise ArgumentError("predictions", problem)
    if calib is not None:  # a file, as eval --calib's: a frame's camera comes with its image size
        problem = (f"expected a calibration file's path, got {type(calib).__name__}"
                   if not isinstance(calib, (str, Path)) else empty_path_problem(calib))
        if problem:
            raise ArgumentError("calib", problem)
    dataset = KittiDataset(kitti_root, calib=calib)
    if not isinstance(detections, (str, Path)):
        raise ArgumentError("detections", f"expected 'gt', 'bank' or a directory, got {type(detections).__name__}")
    problem = empty_path_problem(detections)  # "" (an unset variable) is no name for the current directory
    if problem:
        raise ArgumentError("detections", problem)
    problem = min_score_problem(min_score, str(detections))
    if problem:
        raise ArgumentError("min_score", problem if problem.startswith("must") else f"needs detection files: {problem}")
    min_score = None if min_score is None else float(min_score)
    if frames is not None and split_file is not None:
        raise ArgumentError("split_file", "frames and split_file both choose the frames: give one")
    frame_ids = None
    if frames is not None:
        frame_ids = as_frame_ids(frames, name="frames", some=True)
        missing = sorted(set(frame_ids) - set(dataset.frame_ids()))
        if missing:
            raise ArgumentError("frames", f"not in {dataset.split_dir}: {', '.join(missing[:5])}")
    elif split_file is not None:
        from wirescene.io.splits import read_split_file

        if not isinstance(split_file, (str, Path)):
            raise ArgumentError("split_file", f"expected a path, got {type(split_file).__name__}")
        frame_ids = read_split_file(split_file, known=dataset.frame_ids(), what="labelled frame",
                                    where=dataset.split_dir)
    several = frame_ids is None or len(frame_ids) > 1
    if resume and predictions is None:
        raise ArgumentError("resume", "needs predictions, the directory where finished frames are recorded")
    options = _options(None, particles, seed, models, settings, parallel=several and _workers(workers) > 1,
                       casts_rays=casts_rays(names))

    def say_held_out(message: str) -> None:  # once every check has passed, before the first fit
        warnings.warn(message, HeldOutWarning, stacklevel=4)  # the caller's line: evaluate_dataset calls this

    return evaluate_dataset(dataset, names, frames=frame_ids,
                            source=DetectionSource(str(detections), min_score=min_score, bank=options.detector_bank,
                                                   classifier=options.viewpoint_classifier),
                            options=options, workers=_workers(workers),
                            predictions_dir=None if predictions is None else Path(predictions),
                            resume=bool(resume), held_out=say_held_out)
