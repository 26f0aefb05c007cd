"""Checks of values that cross a boundary (files, CLI options, API arguments), written
once: each returns the problem as a short phrase, or None, and the caller names the
file, option or argument it came from (``InputError`` with a path, ``ArgumentError``
with a name, a click ``BadParameter``)."""

from __future__ import annotations

import math
import numbers
import os
import tempfile
from pathlib import Path

import numpy as np

from wirescene.core.workers import usable_cores

# Focal lengths outside this range (pixels) are not a street camera: KITTI's is ~720.
FOCAL_RANGE = (10.0, 1e5)
# No image is this large (pixels): a box coordinate beyond it is a corrupted number.
MAX_PIXEL = 1e5
# No image is smaller (pixels a side): the detector's and the crop classifier's least window.
MIN_IMAGE_SIDE = 16
# A camera centre farther than this (m) from the rectified frame's origin is a corrupt translation
# column: KITTI's cameras lie within 0.6 m of it, and a fit would place every car that far off.
MAX_CAMERA_OFFSET = 100.0

#: Most worker processes of one run (``--workers``, the API's ``workers``): each fitting worker holds
#: some 440 MB (README, "Evaluating needs little memory"), so 64 of them take 28 GB (55 fit 24 GB); a
#: machine with more cores than that may use them all (beyond the cores a worker adds no speed, only memory).
MAX_WORKERS = max(64, usable_cores())


def finite_real(value) -> bool:
    """Whether ``value`` is a finite real number (not a bool, not a string, not NaN, not an
    integer too large for a float).

    Examples
    --------
    >>> [finite_real(v) for v in (1, 2.5, float("nan"), True, "3", 10**400)]
    [True, True, False, False, False, False]
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def real_dtype_problem(values) -> str | None:
    """What keeps the array ``values`` from holding real numbers, as a phrase, or None: a dtype
    of complex numbers (whose cast to float drops the imaginary part, numpy only warning), of
    booleans or of text. Integers, floats and objects (which the cast converts one by one,
    refusing a complex number) are fine.

    Examples
    --------
    >>> [real_dtype_problem(np.eye(3, dtype=t)) for t in (int, float, object)]
    [None, None, None]
    >>> real_dtype_problem(np.eye(3) * 1j)
    'complex numbers (dtype complex128), expected real numbers'
    >>> real_dtype_problem([["721.5", "0"]])
    'text (dtype <U5), expected real numbers'
    """
    dtype = np.asarray(values).dtype
    if dtype.kind in "iufO":
        return None
    held = {"c": "complex numbers", "b": "booleans", "U": "text", "S": "text"}.get(dtype.kind, "no numbers")
    return f"{held} (dtype {dtype}), expected real numbers"


def image_size_problem(image_size: tuple[int, int]) -> str | None:
    """Why an image of ``image_size`` ``(width, height)`` is too small to fit, or None: under
    :data:`MIN_IMAGE_SIDE` pixels a side (a thumbnail, a 1x1 placeholder).

    Examples
    --------
    >>> image_size_problem((1242, 375)) is None
    True
    >>> image_size_problem((8, 8))
    'image of 8x8 px is too small (at least 16 px a side)'
    """
    w, h = image_size
    if min(w, h) < MIN_IMAGE_SIDE:
        return f"image of {w}x{h} px is too small (at least {MIN_IMAGE_SIDE} px a side)"
    return None


def projection_problem(P, image_size: tuple[int, int] | None = None) -> str | None:
    """What is wrong with a 3x4 projection matrix as a street camera, if anything.

    It must be finite, with an upper-triangular intrinsic part ``K`` (the camera frame
    is the rectified frame: no rotation), positive ``K[2, 2]``, focal lengths in
    :data:`FOCAL_RANGE`, a camera centre within :data:`MAX_CAMERA_OFFSET` of the origin
    and, when the image size is known, a principal point within the image widened by
    half its size on each side.

    Examples
    --------
    >>> P = [[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]]
    >>> projection_problem(P, (1242, 375)) is None  # KITTI's P2: nothing wrong
    True
    >>> projection_problem(np.eye(3, 4))  # an identity matrix is no street camera
    'implausible focal length (fx=1, fy=1 px; expected 10..100000)'
    >>> projection_problem([[721.5, 0, 5000, 0], [0, 721.5, 172.9, 0], [0, 0, 1, 0]], (1242, 375))
    'principal point (5000, 172.9) is far outside the 1242x375 image'
    >>> projection_problem([[721.5, 0, 609.6, 1e300], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    "camera centre 1.386e+297 m from the frame's origin on an axis (at most 100 m): a corrupt translation column (P's 4th), or one in millimetres?"
    """
    P = np.asarray(P)
    if P.shape != (3, 4):
        return f"projection matrix must be 3x4, got shape {P.shape}"
    if not np.issubdtype(P.dtype, np.number) or not np.all(np.isfinite(P.astype(float))):
        return "projection matrix has non-finite values"
    P = P.astype(float)
    K = P[:, :3]
    if K[2, 2] <= 0 or np.any(np.abs(K[[1, 2, 2], [0, 0, 1]]) > 1e-9 * max(abs(K[2, 2]), 1.0)):
        return "projection matrix is not a rectified pinhole camera (K must be upper triangular with K[2,2] > 0)"
    with np.errstate(over="ignore"):  # a tiny K[2, 2] gives infinite focal lengths, refused below
        K = K / K[2, 2]
    fx, fy = K[0, 0], K[1, 1]
    lo, hi = FOCAL_RANGE
    if not (lo <= fx <= hi and lo <= fy <= hi):
        return f"implausible focal length (fx={fx:g}, fy={fy:g} px; expected {lo:g}..{hi:g})"
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is an offset beyond any bound, refused below
        offset = float(np.abs(np.linalg.solve(P[:, :3], P[:, 3])).max())  # the camera centre's farthest coordinate
    if not offset <= MAX_CAMERA_OFFSET:  # NaN too: an overflow (inf - inf) in the solve
        return (f"camera centre {offset:.4g} m from the frame's origin on an axis (at most {MAX_CAMERA_OFFSET:g} m): a "
                "corrupt translation column (P's 4th), or one in millimetres?")
    if image_size is not None:
        w, h = image_size
        cx, cy = K[0, 2], K[1, 2]
        if not (-0.5 * w <= cx <= 1.5 * w and -0.5 * h <= cy <= 1.5 * h):
            return f"principal point ({cx:g}, {cy:g}) is far outside the {w}x{h} image"
    return None


def off_centre_problem(P, image_size: tuple[int, int]) -> str | None:
    """Why a projection matrix (one :func:`projection_problem` accepts) looks made for
    another image than one of ``image_size`` ``(width, height)``, or None: a warning, not an
    error. A calibration carries no image size, but its principal point lies near the
    image's centre (KITTI's within 4%; the benchmarks' off-centre camera at a third); one in
    the outer quarter of the image on either axis (the image more than twice as large as
    the principal point implies, or cut) is likely another image's calibration (a smaller
    image's where the point lies towards the top left, a larger one's towards the bottom
    right), which places every car wrongly, unless it was adjusted to a crop.

    Examples
    --------
    >>> P = [[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]]
    >>> off_centre_problem(P, (1242, 375)) is None
    True
    >>> off_centre_problem(P, (2484, 750))
    'the principal point (609.6, 172.9) lies in the outer quarter of the 2484x750 image: the calibration of a smaller image, or of a crop?'
    >>> off_centre_problem(P, (621, 187))
    'the principal point (609.6, 172.9) lies in the outer quarter of the 621x187 image: the calibration of a larger image, or of a crop?'
    """
    K = np.asarray(P, dtype=float)[:, :3]
    cx, cy = K[0, 2] / K[2, 2], K[1, 2] / K[2, 2]
    w, h = image_size
    if abs(cx - w / 2) <= w / 4 and abs(cy - h / 2) <= h / 4:
        return None
    low, high = cx < w / 4 or cy < h / 4, cx > 3 * w / 4 or cy > 3 * h / 4
    which = "a smaller image" if low and not high else "a larger image" if high and not low else "another size's image"
    return (f"the principal point ({cx:g}, {cy:g}) lies in the outer quarter of the {w}x{h} image: the calibration "
            f"of {which}, or of a crop?")


def boxes_problem(boxes, image_size: tuple[int, int] | None = None) -> str | None:
    """What is wrong with 2D boxes ``(N, 4)`` ``x1 y1 x2 y2``, if anything: finite,
    ``x1 < x2`` and ``y1 < y2``, and (with the image size) overlapping the image and within
    ten image sizes of it.

    Examples
    --------
    >>> boxes_problem([[300, 180, 520, 300]], (1242, 375)) is None
    True
    >>> boxes_problem([[300, 180, 200, 300]])
    'box 0 is empty or inverted (x1 y1 x2 y2 = 300 180 200 300)'
    >>> boxes_problem([[1300, 180, 1400, 300]], (1242, 375))
    'box 0 lies entirely outside the 1242x375 image'
    """
    b = np.asarray(boxes)
    if b.ndim != 2 or b.shape[1] != 4:
        return f"boxes must have shape (N, 4), got {b.shape}"
    if b.dtype.kind not in "iuf":  # complex numbers too: their cast to float drops the imaginary part
        return f"boxes must be real numbers, got dtype {b.dtype}"
    b = b.astype(float)
    bad = ~np.all(np.isfinite(b), axis=1)
    if bad.any():
        return f"box {int(np.flatnonzero(bad)[0])} has non-finite coordinates"
    bad = (b[:, 2] <= b[:, 0]) | (b[:, 3] <= b[:, 1])
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        return f"box {i} is empty or inverted (x1 y1 x2 y2 = {' '.join(f'{v:g}' for v in b[i])})"
    if image_size is not None and len(b):
        w, h = image_size
        outside = outside_image(b, image_size)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            return f"box {i} lies entirely outside the {w}x{h} image"
        huge = np.any(np.abs(b) > 10 * max(w, h), axis=1)
        if huge.any():
            return f"box {int(np.flatnonzero(huge)[0])} extends absurdly far beyond the {w}x{h} image"
    return None


def normalised_boxes_problem(boxes) -> str | None:
    """Whether the boxes a user gives ``(N, 4)`` ``x1 y1 x2 y2`` are in coordinates normalised
    to the image rather than pixels, as a phrase, or None: every box under a pixel wide and high
    (no car fits one; a sliver clipped at the border among a detector's boxes is no mistake of
    units). Read where boxes enter (files, the API), not on boxes a stage passes on.

    Examples
    --------
    >>> normalised_boxes_problem([[0.24, 0.48, 0.42, 0.8]])
    'every box is under a pixel (box 0: x1 y1 x2 y2 = 0.24 0.48 0.42 0.8): normalised coordinates? boxes are in pixels'
    >>> normalised_boxes_problem([[300, 180, 520, 300], [700.2, 200.1, 700.8, 200.6]]) is None
    True
    """
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    if len(b) and np.all((b[:, 2] - b[:, 0] < 1) & (b[:, 3] - b[:, 1] < 1)):
        return (f"every box is under a pixel (box 0: x1 y1 x2 y2 = {' '.join(f'{v:g}' for v in b[0])}): normalised "
                "coordinates? boxes are in pixels")
    return None


def outside_image(boxes, image_size: tuple[int, int]) -> np.ndarray:
    """``(N,)`` bool: which boxes ``(N, 4)`` ``x1 y1 x2 y2`` have no pixel in the
    ``(width, height)`` image (a truncated box touching the border is inside).

    Examples
    --------
    >>> outside_image([[300, 180, 520, 300], [-50, 100, 0, 200], [-50, 100, 1, 200]], (1242, 375))
    array([False,  True, False])
    """
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    w, h = image_size
    return (b[:, 2] <= 0) | (b[:, 0] >= w) | (b[:, 3] <= 0) | (b[:, 1] >= h)


def path_problem(path, what: str, *, directory: bool = False, missing: str | None = None) -> str | None:
    """Why ``path`` is not the existing file (``directory``: directory) of ``what`` a reader
    needs, or None: ``missing`` (default "WHAT file not found" / "WHAT directory not found")
    where nothing is there, "WHAT path is not a file" (a directory) where something else is.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path_problem(d, "calibration"), path_problem(Path(d) / "x", "calibration"), path_problem(d, "models",
    ...                                                                                            directory=True)
    ('calibration path is not a file', 'calibration file not found', None)
    """
    path = Path(path)
    kind = "directory" if directory else "file"
    if path.is_dir() if directory else path.is_file():
        return None
    if not path.exists():
        return missing or f"{what} {kind} not found"
    return f"{what} path is not a {kind}"


def broken_link_problem(path) -> str | None:
    """Why ``path`` cannot be made a directory because it, or a folder above it, is a symbolic
    link to nothing (``mkdir`` fails on the link itself: FileExistsError), or None.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     (Path(d) / "out").symlink_to(Path(d) / "gone")
    ...     broken_link_problem(Path(d) / "out" / "run").endswith("/out is a broken symbolic link (to " + d + "/gone)")
    True
    """
    for candidate in (Path(path), *Path(path).parents):
        if candidate.is_symlink() and not candidate.exists():
            return f"{candidate} is a broken symbolic link (to {os.readlink(candidate)})"
        if candidate.exists():
            return None
    return None


def _first_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists():
            return candidate
    return Path(".")


def _writable_problem(directory: Path) -> str | None:
    """Why nothing can be created in ``directory``, or None: permission bits first, then a
    real try (a directory made and removed again), since ``os.access`` says yes to root and
    knows nothing of pseudo file systems (``/proc``, ``/sys``)."""
    if not os.access(directory, os.W_OK | os.X_OK):
        return "is not writable"
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".wirescene-check.", dir=directory))
    except OSError as exc:
        return f"is not writable ({exc.strerror or exc.__class__.__name__})"
    return None


def empty_path_problem(path, *, directory: bool = True) -> str | None:
    """``empty path (...)`` where ``path`` is an empty (or blank) string, None otherwise:
    pathlib reads ``""`` as the current directory, so that an unset shell variable
    (``--out "$OUT"``) would write there. Only a string can be empty (``Path("")`` is
    ``Path(".")``, said as such); ``directory``: the path names a directory, else a file.
    Every path option of the CLI (:class:`wirescene.cli.options.NonEmptyPath`) and the API's
    directory arguments are refused by it.

    Examples
    --------
    >>> empty_path_problem("")
    "empty path (give a directory, e.g. '.')"
    >>> empty_path_problem(" ", directory=False), empty_path_problem("."), empty_path_problem(Path(""))
    ('empty path (give a file name)', None, None)
    """
    if isinstance(path, str) and not path.strip():
        return "empty path (give a directory, e.g. '.')" if directory else "empty path (give a file name)"
    return None


def creatable_problem(path) -> str | None:
    """Why the directories above ``path`` cannot be created and written (the first of them
    that exists is a file, or not writable), as a phrase naming ``path``, or None.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.NamedTemporaryFile() as f:
    ...     creatable_problem(Path(f.name) / "out" / "a.json").endswith(f"{f.name} is a file, not a directory")
    True
    """
    path = Path(path)
    try:
        link = broken_link_problem(path.parent)
        if link:
            return f"{path}: {link}"
        base = _first_existing(path.parent)
        if not base.is_dir():
            return f"{path}: {base} is a file, not a directory"
    except OSError as exc:  # a name too long for the file system: refused before any work, not a traceback
        return f"{path}: {exc.strerror or exc}"
    problem = _writable_problem(base)
    return f"{path}: {base} {problem}" if problem else None


def output_dir_problem(path) -> str | None:
    """Why ``path`` is not (and cannot be created as) a writable directory, as a phrase
    naming it, or None: what every output folder of a command (``--out``, ``--predictions``)
    and of the API is checked for before any work (:func:`wirescene.evaluate`'s ``predictions``,
    :func:`~wirescene.eval.runner.evaluate_dataset`'s ``predictions_dir``,
    :func:`~wirescene.eval.predict.predict_dataset`'s ``out_dir``, ``json_dir`` and
    ``pictures_dir``), no path at all (an int, None) included.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     output_dir_problem(Path(d) / "new" / "out") is None  # made when written
    True
    >>> with tempfile.NamedTemporaryFile() as f:
    ...     output_dir_problem(f.name) == f"{f.name} is a file, expected a directory"
    True
    >>> output_dir_problem("")  # an unset shell variable, not the current directory
    "empty path (give a directory, e.g. '.')"
    >>> output_dir_problem(5)
    'expected a directory path, got int'
    """
    if not isinstance(path, (str, os.PathLike)):  # an API's argument: Path(5) would be a TypeError
        return f"expected a directory path, got {type(path).__name__}"
    empty = empty_path_problem(path)
    if empty:  # "" is no name for the current directory
        return empty
    path = Path(path)
    try:
        exists = path.exists()
    except OSError as exc:  # a name too long for the file system: refused before any work, not a traceback
        return f"{path}: {exc.strerror or exc}"
    if exists:
        if not path.is_dir():
            return f"{path} is a file, expected a directory"
        problem = _writable_problem(path)
        return f"{path} {problem}" if problem else None
    return broken_link_problem(path) or creatable_problem(path)
