"""KITTI object benchmark I/O: labels (ground truth and detections), images, calibration
and a dataset wrapper that discovers frames under a KITTI root directory.

A KITTI label line has 15 columns (ground truth) or 16 (detections, with a score)::

    type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]

``x y z`` is the bottom centre of the 3D box in the rectified camera frame of ``P2``
(x right, y down, z forward, metres); ``rotation_y`` is the azimuth about the camera's
y axis and ``alpha`` the observation angle, both in radians. ``DontCare`` regions are
kept apart from the objects, since every evaluation ignores them.
"""

from __future__ import annotations

import numbers
import os
import warnings
from pathlib import Path
from typing import Iterable

import numpy as np
from PIL import Image, UnidentifiedImageError

from wirescene.core.atomic import write_text
from wirescene.core.camera import Camera, KittiCalib, read_calibration, read_kitti_calib
from wirescene.core.errors import ArgumentError, InputError, ShapeError
from wirescene.core.image import range_problem, to_rgb_uint8
from wirescene.core.labels import (  # noqa: F401  (re-exported: the KITTI label types live in core)
    ALPHA_NOT_ESTIMATED,
    CAR_TYPES,
    COLUMNS,
    DONTCARE,
    FrameLabels,
    Label,
    angle_problem,
    car_indices,
    format_label,
    format_labels,
    is_type,
    no_3d_box,
    select_cars,
)
from wirescene.core.validate import (
    MAX_PIXEL,
    image_size_problem,
    off_centre_problem,
    outside_image,
    path_problem,
)

# --------------------------------------------------------------------------- labels


def _object_problem(values: list[float]) -> str | None:
    """What is impossible in the numbers of a (non-DontCare) label row, if anything.
    ``-1`` marks a quantity that is not estimated (truncation and occlusion of
    predictions, all three dimensions of a 2D-only detector), as in KITTI files, and
    ``-10`` an angle that is not (``alpha``, ``rotation_y``); any other angle beyond one
    turn is one in degrees."""
    truncated, occluded, _alpha = values[0:3]
    x1, y1, x2, y2 = values[3:7]
    dims = values[7:10]
    if not (truncated == -1 or 0.0 <= truncated <= 1.0):
        return f"truncation {truncated:g} is outside [0, 1] (or -1 for unknown)"
    if occluded not in (-1, 0, 1, 2, 3):
        return f"occlusion state {occluded:g} is not one of 0, 1, 2, 3 (or -1 for unknown)"
    if not (x1 < x2 and y1 < y2):
        return f"2D box is empty or inverted (x1 y1 x2 y2 = {x1:g} {y1:g} {x2:g} {y2:g})"
    if not no_3d_box(dims) and min(dims) <= 0:
        return f"dimensions must be positive (h w l = {' '.join(f'{d:g}' for d in dims)})"
    return angle_problem("alpha", values[2]) or angle_problem("rotation_y", values[13])


def _box_problem(box: list[float], image_size: tuple[int, int] | None) -> str | None:
    """What cannot be about the 2D box of a row of any class (DontCare included): a
    coordinate no image reaches or, with the image's ``(width, height)``, a box with no
    pixel in the image (KITTI clips boxes to the image, so truncated cars touch its border)."""
    far = [v for v in box if abs(v) > MAX_PIXEL]
    if far:
        return f"2D box coordinate {far[0]:g} is absurdly far from any image (beyond {MAX_PIXEL:g} px)"
    if image_size is not None and outside_image(box, image_size)[0]:
        return (f"2D box (x1 y1 x2 y2 = {' '.join(f'{v:g}' for v in box)}) lies entirely outside the "
                f"{image_size[0]}x{image_size[1]} image")
    return None


def _parse_label_line(tokens: list[str], lineno: int, path: Path,
                      image_size: tuple[int, int] | None = None) -> Label:
    if len(tokens) not in (15, 16):
        raise InputError(
            f"line {lineno}: expected 15 columns (ground truth) or 16 (with score), got {len(tokens)}",
            path=path,
        )
    values = []
    for col, tok in enumerate(tokens[1:], 1):
        try:
            v = float(tok)
        except ValueError:
            raise InputError(
                f"line {lineno}: column {col + 1} ({COLUMNS[col]}) is not a number: {tok!r}", path=path
            ) from None
        if not np.isfinite(v):
            raise InputError(f"line {lineno}: column {col + 1} ({COLUMNS[col]}) is not finite: {tok!r}", path=path)
        values.append(v)
    occluded = values[1]
    if occluded != int(occluded):
        raise InputError(f"line {lineno}: column 3 (occluded) must be an integer, got {tokens[2]!r}", path=path)
    problem = _object_problem(values) if not is_type(tokens[0], DONTCARE) else None
    problem = problem or _box_problem(values[3:7], image_size)
    if problem:
        raise InputError(f"line {lineno}: {problem}", path=path)
    return Label(
        type=tokens[0],
        truncated=values[0],
        occluded=int(occluded),
        alpha=values[2],
        box=values[3:7],
        dims=values[7:10],
        location=values[10:13],
        rotation_y=values[13],
        score=values[14] if len(values) == 15 else None,
    )


def read_labels(path: str | Path, *, image_size: tuple[int, int] | None = None) -> FrameLabels:
    """Read a KITTI label file (15 columns) or detection file (16 columns, with score).

    Blank lines are skipped; an empty file is a frame without objects. With the image's
    ``image_size`` ``(width, height)``, every row's 2D box must have a pixel in the image.

    Raises
    ------
    InputError
        If the file is missing or unreadable, or a line has the wrong number of columns,
        a non-numeric or non-finite number, a non-integer occlusion state, impossible
        values (an empty or inverted box, a truncation outside [0, 1], an angle in
        degrees, ...) or a 2D box coordinate beyond :data:`~wirescene.core.validate.MAX_PIXEL`
        or (with ``image_size``) a box wholly outside the image; the message gives the line
        number.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> labels = read_labels(DATA_DIR / "sample" / "kitti" / "training" / "label_2" / "000010.txt")
    >>> len(labels.objects), len(labels.dontcare)  # DontCare regions are kept apart
    (9, 4)
    >>> car = labels.objects[1]
    >>> car.type, car.box.tolist(), car.dims.tolist(), car.location.tolist(), car.rotation_y
    ('Car', [354.43, 185.52, 549.52, 294.49], [1.43, 1.7, 3.95], [-2.39, 1.66, 11.8], 1.76)
    >>> car.score is None  # 15 columns: ground truth
    True
    """
    path = Path(path)
    problem = path_problem(path, "label")
    if problem:
        raise InputError(problem, path=path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark (editors write one) is no part of a type
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read label file ({exc.__class__.__name__})", path=path) from exc
    out = FrameLabels()
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split()
        if not tokens:
            continue
        label = _parse_label_line(tokens, lineno, path, image_size)
        (out.dontcare if label.is_dontcare else out.objects).append(label)
    return out


def write_labels(
    path: str | Path, labels: FrameLabels | Iterable[Label], *, with_score: bool = True
) -> None:
    """Write labels in KITTI format (16 columns with ``with_score``, else 15).

    ``labels`` is a :class:`FrameLabels` (objects then DontCare regions) or a list of
    :class:`Label`. The file is written to a temporary file in the same directory and
    moved into place with :func:`os.replace`, so an error never leaves a partial file.
    See :func:`format_label` for the number formats.

    Examples
    --------
    >>> import tempfile
    >>> from wirescene.core.resources import DATA_DIR
    >>> labels = read_labels(DATA_DIR / "sample" / "kitti" / "training" / "label_2" / "000010.txt")
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_labels(Path(d) / "000010.txt", labels, with_score=False)  # ground truth: 15 columns
    ...     first = (Path(d) / "000010.txt").read_text().splitlines()[0]
    ...     again = read_labels(Path(d) / "000010.txt")
    >>> first
    'Car 0.80 0 -2.090000 1013.39 182.46 1241.00 374.00 1.570000 1.650000 3.350000 4.430000 1.650000 5.200000 -1.420000'
    >>> len(again), len(again.dontcare), again.objects[1].location.tolist()  # the same labels back
    (9, 4, [-2.39, 1.66, 11.8])
    """
    write_text(Path(path), format_labels(labels, with_score=with_score))  # formatting fails before touching disk


# --------------------------------------------------------------------------- images


def _open_image(path: Path) -> Image.Image:
    problem = path_problem(path, "image")
    if problem:
        raise InputError(problem, path=path)
    try:
        with warnings.catch_warnings():
            # Pillow only warns between 1x and 2x its pixel limit: refuse those too.
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            img = Image.open(path)
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise InputError(f"image is too large (more than {Image.MAX_IMAGE_PIXELS} pixels: a decompression bomb?)",
                         path=path) from None
    except UnidentifiedImageError:
        raise InputError("not an image file (unrecognised format)", path=path) from None
    except OSError as exc:
        raise InputError(f"cannot open image ({exc})", path=path) from None
    problem = image_size_problem(img.size)  # from the header: every frame's is read before a run's first fit
    if problem:
        img.close()
        raise InputError(problem, path=path)
    return img


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as an ``(H, W, 3)`` uint8 RGB array.

    16-bit and float images are scaled by their range (:func:`wirescene.core.image.to_rgb_uint8`),
    not clipped; palette, grey and alpha images are converted to RGB (:func:`rgb_of_pil`).

    Raises
    ------
    InputError
        If the file is missing, not an image, too large or too small (under
        :data:`~wirescene.core.validate.MIN_IMAGE_SIDE` px a side), corrupt / truncated, or of
        values its conversion would misread (a float image outside both 0..1 and 0..255, a 32-bit
        integer one outside 0..65535: :func:`rgb_of_pil`).

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> image = read_image(DATA_DIR / "sample" / "kitti" / "training" / "image_2" / "000010.png")
    >>> image.shape, image.dtype.name  # rows, columns, RGB
    ((375, 1242, 3), 'uint8')
    """
    path = Path(path)
    img = _open_image(path)
    try:
        with img:
            img.load()
            return rgb_of_pil(img)
    except ShapeError as exc:  # values read, but not as an image (a float TIFF of -3..400, NaN pixels)
        raise InputError(exc.problem, path=path) from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputError(f"corrupt or truncated image ({' '.join(str(exc).split())})", path=path) from None


def rgb_of_pil(img) -> np.ndarray:
    """A loaded PIL image as an ``(H, W, 3)`` uint8 RGB array: 16-bit and float images
    scaled by their range (:func:`wirescene.core.image.to_rgb_uint8`), palette, grey and
    alpha images converted to RGB. Its values are checked as an array's are where images
    enter (:func:`wirescene.core.image.range_problem`); a 32-bit integer image (mode ``I``)
    of values in 0..65535 is read as a 16-bit one (Pillow before 10.3 opens a 16-bit PNG so), one
    beyond refused in those words.

    Raises
    ------
    ShapeError
        Values it would misread (a float image outside both 0..1 and 0..255, a 32-bit integer
        one outside 0..65535), or non-finite ones.

    Examples
    --------
    >>> white16 = Image.fromarray(np.full((2, 3), 65535, np.uint16))  # a 16-bit grey image
    >>> rgb = rgb_of_pil(white16)
    >>> rgb.shape, rgb[0, 0].tolist()  # white, not clipped to 255 of 65535
    ((2, 3, 3), [255, 255, 255])
    >>> rgb_of_pil(Image.fromarray(np.array([[-3.0, 400.0]], np.float32)))  # mode F
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ShapeError: float values outside both 0..1 and 0..255 (dtype float32, -3..400) would be ...
    """
    values = _pil_values(img)
    if img.mode == "I" and values.dtype != np.uint16:  # read by 0..65535: an int32 array's words (0..255) would mislead
        raise ShapeError(f"integer values outside 0..65535 (mode I, {values.min()}..{values.max()}) would be clipped: "
                         "scale to 0..65535, the range a 32-bit integer image is read by")
    rgb = to_rgb_uint8(values)  # first: non-finite values said as such, with their count
    problem = range_problem(values)
    if problem:
        raise ShapeError(problem)
    return rgb


def _pil_values(img) -> np.ndarray:
    """The values of a loaded PIL image as the array :func:`rgb_of_pil` reads: uint16 (modes
    ``I;16*``, and ``I`` within 0..65535), int32 (``I`` beyond), float32 (``F``) or RGB uint8."""
    if img.mode.startswith("I;16"):  # I;16B is big-endian: read in the machine's order
        return np.asarray(img).astype(np.uint16)
    if img.mode == "I":
        values = np.asarray(img)
        fits = values.size == 0 or (values.min() >= 0 and values.max() <= 65535)
        return values.astype(np.uint16) if fits else values  # beyond: refused by rgb_of_pil
    if img.mode == "F":
        return np.asarray(img, dtype=np.float32)
    return np.asarray(img.convert("RGB"), dtype=np.uint8)


def image_size(path: str | Path) -> tuple[int, int]:
    """``(width, height)`` of an image read from its header only (no decoding): note the
    order, that of :class:`~wirescene.core.camera.Camera` ``image_size``, not of
    ``array.shape``.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> image_size(DATA_DIR / "sample" / "kitti" / "training" / "image_2" / "000010.png")
    (1242, 375)
    """
    path = Path(path)
    with _open_image(path) as img:
        return int(img.size[0]), int(img.size[1])


# --------------------------------------------------------------------------- dataset


#: The image files of a folder read with one calibration (``KittiDataset(calib=)``): a dashcam's
#: or a nuScenes camera's frames are JPEG; KITTI's own layout without it reads ``.png`` only.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
def _frame_image(path: Path) -> bool:
    """Whether ``path`` is a frame's image in a folder read with one calibration: a file of
    :data:`IMAGE_SUFFIXES`, not hidden (macOS writes ``._NAME.jpg`` beside each file it copies to
    an exFAT card, where a dashcam's frames lie)."""
    return path.suffix.lower() in IMAGE_SUFFIXES and not path.name.startswith(".") and path.is_file()


# Where a folder lacks KITTI's calib/: the commands that read one calibration for every frame.
ONE_CALIB_HINT = "; predict, detect, pitch and eval take one calibration for every frame (--calib FILE)"

#: The split :class:`KittiDataset` reads where none is given (``ROOT/training``).
DEFAULT_SPLIT = "training"


def folder_names(path: Path) -> set[str]:
    """The names the folder ``path`` goes by: its own as given (a relative path read from the shell's
    working directory, ``$PWD``, as the links it was entered by left it) and its target's, where a
    link leads elsewhere (``KITTI/training -> /data/kitti_train``).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     (Path(d) / "kitti_train").mkdir()
    ...     (Path(d) / "training").symlink_to(Path(d) / "kitti_train")
    ...     sorted(folder_names(Path(d) / "training"))
    ['kitti_train', 'training']
    """
    path = Path(path)
    names = {path.resolve().name, Path(os.path.abspath(path)).name}
    pwd = os.environ.get("PWD")
    if pwd and not path.is_absolute():
        try:
            if os.path.samefile(pwd, os.curdir):  # the shell's logical directory, links kept
                names.add(Path(os.path.normpath(os.path.join(pwd, path))).name)
        except OSError:
            pass
    return names


def given_split_problem(dataset: KittiDataset, split: str, *, root: str | Path | None = None,
                        names: tuple[str, str] = ("split", "calib")) -> str | None:
    """Why ``split``, given by the caller for ``dataset`` (read from ``root`` as given, default
    ``dataset.root``), would be ignored there, or None: a plain folder of frames (read with one
    calibration, no ``image_2/``) has no split folder, and a split folder given as the root
    (``ROOT/training``, its own ``image_2/`` read) is no split of another name (as given, or as
    its link's target, :func:`folder_names`). ``names``: how the split and the calibration are
    named, the keywords of :class:`KittiDataset` or the options of the commands
    (``("--split", "--calib")``, :func:`wirescene.cli.options.kitti_dataset`).

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> split = KittiDataset(DATA_DIR / "sample" / "kitti" / "training")
    >>> given_split_problem(split, "training") is None  # its own name
    True
    >>> given_split_problem(split, "testing", names=("--split", "--calib"))[:58]
    '--split testing names no folder here: this is itself a spl'
    """
    option, calib = names
    said = f"{option} {split}" if option.startswith("-") else f"{option}={split!r}"
    if dataset.image_dir == dataset.split_dir and dataset.image_ids():
        # a folder of no images is a KITTI root lacking the split: require_frames says so, naming what it holds
        return (f"{said} has no meaning for a plain folder of frames (its own images are read with {calib}; "
                f"no {split}/image_2 here): drop {option}")
    if dataset.split_dir == dataset.root != dataset.image_dir and split not in folder_names(
            dataset.root if root is None else root):
        return (f"{said} names no folder here: this is itself a split folder (its image_2/ is read, no "
                f"{split}/image_2): give the KITTI root above it, or drop {option}")
    return None


def as_frame_id(frame_id, *, name: str = "frame_id") -> str:
    """A frame's id as its files are named: a str as given, an int (or numpy integer) written
    ``%06d`` (KITTI's frame ``10`` is ``000010``); what :class:`KittiDataset` reads every id
    with, and the API its ``frames``.

    Parameters
    ----------
    frame_id : str or int
        The id.
    name : str
        The argument's name in error messages.

    Returns
    -------
    str

    Raises
    ------
    ArgumentError
        Naming ``name``: a bool, a negative int, or neither a str nor an int (a float, ``10.0`` too).

    Examples
    --------
    >>> as_frame_id(10), as_frame_id("000010"), as_frame_id("frame_a")
    ('000010', '000010', 'frame_a')
    >>> as_frame_id(-10, name="frames")
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ArgumentError: frames: an int frame id (written %06d) must be non-negative, got -10
    """
    if isinstance(frame_id, str):
        return str(frame_id)  # a numpy str as a str: ids are written to JSON records
    if isinstance(frame_id, numbers.Integral) and not isinstance(frame_id, bool):  # True is no frame 000001
        if frame_id < 0:  # -10 would be the file -00010.png
            raise ArgumentError(name, f"an int frame id (written %06d) must be non-negative, got {frame_id!r}")
        return f"{int(frame_id):06d}"
    raise ArgumentError(name, f"expected a frame id (a str, or an int written %06d), got "
                              f"{type(frame_id).__name__} {frame_id!r}")


def as_frame_ids(frames, *, name: str = "frames", some: bool = False) -> list[str]:
    """Frame ids as :func:`as_frame_id` writes each, in the order given, each once (``10`` and
    ``"000010"`` are one frame): what the functions of a set of frames read their ``frames`` with.

    Parameters
    ----------
    frames : str, int or iterable of them
        One id (a numpy scalar or 0-d array too), or several (a list, a numpy array, a
        generator; a set's or a frozenset's in sorted order: theirs changes from one Python
        process to the next, and the reports list the frames in this order).
    name : str
        The argument's name in error messages.
    some : bool
        Refuse an empty selection (an empty list, an exhausted generator): for a caller whose
        run of no frame would be no run (a submission of no file); else an empty list is returned.

    Returns
    -------
    list of str

    Raises
    ------
    ArgumentError
        Naming ``name``: an id that :func:`as_frame_id` refuses, or (``some``) no id at all.

    Examples
    --------
    >>> as_frame_ids(10), as_frame_ids([2, "000010", 10]), as_frame_ids({"000010", "000002"})
    (['000010'], ['000002', '000010'], ['000002', '000010'])
    """
    if isinstance(frames, np.ndarray) and frames.ndim == 0:  # np.array(10): one id (iterating it is a TypeError)
        frames = frames.item()
    one = isinstance(frames, (str, bytes, numbers.Integral)) or not isinstance(frames, Iterable)  # not its characters
    ids = list(dict.fromkeys(as_frame_id(f, name=name) for f in ([frames] if one else frames)))
    if isinstance(frames, (set, frozenset)):
        ids.sort()
    if some and not ids:
        raise ArgumentError(name, "no frame given")
    return ids


class KittiDataset:
    """Frames of a KITTI object split on disk (``image_2``, ``calib``, optional ``label_2``),
    or of a folder of frames of one camera with one calibration (``calib``). Its methods take a
    frame's id as a str or an int written ``%06d`` (:func:`as_frame_id`: an
    :class:`~wirescene.core.errors.ArgumentError` naming ``frame_id`` for a bool, a negative int or a float).

    Parameters
    ----------
    root : path
        Either the KITTI root (containing ``<split>/``) or the split directory itself; with
        ``calib``, also a plain folder holding the images themselves.
    split : str, optional
        Split directory name under ``root``, ``"training"`` or ``"testing"`` (None:
        :data:`DEFAULT_SPLIT`, ``"training"``). A split given where it would be ignored is
        refused (:func:`given_split_problem`): a plain folder of frames read with ``calib``,
        or a split folder given as ``root`` (``ROOT/training``) that goes by no such name.
    calib : path, optional
        One calibration for every frame (a camera other than KITTI's whose frames share it),
        in any form :func:`~wirescene.core.camera.read_calibration` reads: a KITTI calibration
        file (its ``P2``) or a text file of the 9 numbers of ``K`` or the 12 of ``P``. No
        ``calib/`` directory is then read (nor needed), the images may be ``.png``, ``.jpg`` or
        ``.jpeg`` (:data:`IMAGE_SUFFIXES`), and a folder without ``image_2/`` is read as the
        folder of the images; frame ids are the images' stems.

    Raises
    ------
    InputError
        If ``root`` does not exist or the split lacks ``image_2/`` or ``calib/`` (without
        ``calib``), or ``calib`` is missing or malformed (naming it), or ``split`` is given
        where it has no meaning (naming ``root``).

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> dataset = KittiDataset(DATA_DIR / "sample" / "kitti")  # the bundled sample: two frames
    >>> dataset.split_dir.name, dataset.frame_ids(), dataset.has_labels
    ('training', ['000010', '001545'], True)
    >>> camera = dataset.camera(10)  # an int id is written %06d: frame 000010
    >>> camera.image_size, camera.focal
    ((1242, 375), 721.5377)
    >>> dataset.image(10).shape, len(dataset.labels(10).of_type("Car"))
    ((375, 1242, 3), 8)
    >>> dataset.car_counts(["000010", "001545"])
    {'000010': 8, '001545': 6}

    A folder of frames of one camera, read with one calibration:

    >>> import shutil, tempfile
    >>> split = DATA_DIR / "sample" / "kitti" / "training"
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = shutil.copy(split / "image_2" / "000010.png", Path(d) / "frame_a.png")
    ...     _ = Path(d, "K.txt").write_text("721.5 0 609.6  0 721.5 172.9  0 0 1")
    ...     frames = KittiDataset(d, calib=Path(d) / "K.txt")
    ...     frames.image_dir == Path(d), frames.frame_ids(), frames.camera("frame_a").image_size
    (True, ['frame_a'], (1242, 375))
    >>> KittiDataset(split, split="testing")  # a split folder: no other split below it
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...: split='testing' names no folder here: ...
    """

    def __init__(self, root: str | Path, *, split: str | None = None, calib: str | Path | None = None):
        if split is not None and (not isinstance(split, str) or split != Path(split).name or split in ("", "..")):
            raise ArgumentError("split", f"expected the name of a split folder (e.g. 'training'), got {split!r}")
        self._read(root, DEFAULT_SPLIT if split is None else split, calib)
        if split is not None:
            problem = given_split_problem(self, split, root=root)
            if problem:
                raise InputError(problem, path=root)

    @classmethod
    def of_default_split(cls, root: str | Path, split: str, *, calib: str | Path | None = None) -> KittiDataset:
        """``KittiDataset(root, split=split, calib=calib)`` without the check of a split given
        (:func:`given_split_problem`): for a split named by a default (a command's ``--split`` not
        given), never refused where it has no meaning, as no split given is; a command checks the
        one given itself, against the root as typed and with its options' names
        (:func:`wirescene.cli.options.kitti_dataset`).

        Examples
        --------
        >>> from wirescene.core.resources import DATA_DIR
        >>> KittiDataset.of_default_split(DATA_DIR / "sample" / "kitti" / "training", "testing").split_dir.name
        'training'
        """
        dataset = cls.__new__(cls)
        dataset._read(root, split, calib)
        return dataset

    def _read(self, root: str | Path, split: str, calib: str | Path | None) -> None:
        """Find the split's folders under ``root`` (the constructor's work, but the check of a split given)."""
        root = Path(root)
        problem = path_problem(root, "KITTI root", directory=True)
        if problem:
            raise InputError(problem, path=root)
        # one calibration is read now: a bad file is refused before any frame, naming it
        self._calib = None if calib is None else read_calibration(calib)
        if self._calib is not None:  # no calib/ is read: image_2/ where there is one, else the folder's own images
            split_dir = next((d for d in (root / split, root) if (d / "image_2").is_dir()), root)
            image_dir = split_dir / "image_2" if (split_dir / "image_2").is_dir() else split_dir
        elif (root / split / "image_2").is_dir() or (root / split / "calib").is_dir():
            split_dir = root / split
        elif (root / "image_2").is_dir() or (root / "calib").is_dir():
            split_dir = root
        else:
            images = any(_frame_image(p) for p in root.iterdir())
            # predict's split is testing: a root of the training split alone (the shared frames) said as such
            other = next((s for s in ("training", "testing") if s != split and (root / s / "image_2").is_dir()), None)
            raise InputError(
                f"not a KITTI object directory: expected {split}/image_2 and {split}/calib (or image_2 and calib)"
                + (f"{ONE_CALIB_HINT} for a folder of one camera's frames" if images else "")
                + (f"; it holds {other}/image_2: --split {other}" if other else ""),
                path=root,
            )
        if self._calib is None:
            for sub in ("image_2", "calib"):
                if not (split_dir / sub).is_dir():
                    hint = ONE_CALIB_HINT if sub == "calib" else ""
                    raise InputError(f"KITTI split has no {sub}/ directory{hint}", path=split_dir)
            image_dir = split_dir / "image_2"
        self.root = root
        self._split = split
        self.split_dir = split_dir
        #: Where the images lie: ``image_2/`` of the split, or (with one calibration) a plain folder of them.
        self.image_dir = image_dir
        self._ids: list[str] | None = None
        self._images: dict[str, Path] | None = None

    @property
    def base_dir(self) -> Path:
        """The directory above the split (the KITTI root, whether ``ROOT`` or ``ROOT/training``
        was given), where the devkit's files lie."""
        return self.split_dir.parent

    @property
    def has_labels(self) -> bool:
        """Whether the split has a ``label_2/`` directory (training split)."""
        return (self.split_dir / "label_2").is_dir()

    def require_labels(self, use: str) -> None:
        """Refuse a split without ``label_2/`` (KITTI's ``testing/``) for ``use`` (``"training"``,
        ``"evaluation"``), checked before any frame is chosen or image read (a refusal after
        decoding thousands of images would cost minutes).

        Raises
        ------
        InputError
            Naming the split folder: ``"{use} needs label_2/ ground truth"``.

        Examples
        --------
        >>> from wirescene.core.resources import DATA_DIR
        >>> KittiDataset(DATA_DIR / "sample" / "kitti").require_labels("training")  # labelled: nothing
        """
        if not self.has_labels:
            raise InputError(f"{use} needs label_2/ ground truth", path=self.split_dir)

    def frame_ids(self) -> list[str]:
        """Sorted frame ids (file stems), from ``label_2`` if present, else the images'."""
        if self._ids is None:
            if self.has_labels:
                ids = [p.stem for p in (self.split_dir / "label_2").glob("*.txt")]
            else:
                ids = self.image_ids()
            self._ids = sorted(ids)
        return list(self._ids)

    def image_ids(self) -> list[str]:
        """Sorted ids of every image in :attr:`image_dir` (labelled or not)."""
        if self._calib is None:
            return sorted(p.stem for p in self.image_dir.glob("*.png"))
        return sorted(self._image_files())

    def __getstate__(self) -> dict:
        # a worker's copy is sent with every frame's task: not the folder's listing, which it makes once if needed
        return {**self.__dict__, "_images": None}

    def _image_files(self) -> dict[str, Path]:
        """``{frame: image}`` of a folder read with one calibration, listed once (a folder of
        thousands is not listed again for each frame); an :class:`InputError` where two images
        share a stem (which is the frame is unknown)."""
        if self._images is None:
            found: dict[str, Path] = {}
            for path in sorted(self.image_dir.iterdir()):
                if not _frame_image(path):
                    continue
                if path.stem in found:
                    raise InputError(f"frame {path.stem} has two images ({found[path.stem].name}, {path.name}): "
                                     "keep one", path=self.image_dir)
                found[path.stem] = path
            self._images = found
        return self._images

    def require_frames(self, *, images: bool = False) -> list[str]:
        """:meth:`frame_ids` (``images``: :meth:`image_ids`), refusing a split without any.

        Raises
        ------
        InputError
            Naming the folder read (``label_2/`` or the images') and what it holds instead,
            so that a run over no frame stops here rather than reporting nothing.
        """
        ids = self.image_ids() if images else self.frame_ids()
        if not ids:
            labels = self.has_labels and not images
            folder = self.split_dir / "label_2" if labels else self.image_dir
            kind = ".txt" if labels else ".png" if self._calib is None else ".png, .jpg or .jpeg"
            others = sorted({p.suffix or p.name for p in folder.iterdir() if p.is_file()})
            held = f"it holds {', '.join(others)} files" if others else "it is empty"
            folders = sorted(p.name for p in folder.iterdir() if p.is_dir()) if not labels else []
            if self._calib is not None and folders:  # a KITTI root given for a split that has no image_2/
                files = f"{', '.join(others)} files and " if others else "only "
                held = f"it holds {files}the folders {', '.join(folders[:3])}, no {self._split}/image_2"
            hint = "; KITTI's images are .png" if others and not labels and self._calib is None else ""
            raise InputError(f"no {kind} file ({held}{hint})", path=folder)
        return ids

    def __len__(self) -> int:
        return len(self.frame_ids())

    def __iter__(self):
        return iter(self.frame_ids())

    @staticmethod
    def _id(frame_id: str | int) -> str:
        return as_frame_id(frame_id)

    def image_path(self, frame_id: str | int) -> Path:
        """``image_2/FRAME.png`` of the split (an int id written ``%06d``); with one calibration,
        the frame's image in :attr:`image_dir` of any of :data:`IMAGE_SUFFIXES` (``FRAME.png``
        where it has none, the path its error names)."""
        frame = self._id(frame_id)
        if self._calib is None:
            return self.image_dir / f"{frame}.png"
        if self._images is None:  # a worker's copy: the usual spellings before a listing of the folder
            for suffix in IMAGE_SUFFIXES + tuple(s.upper() for s in IMAGE_SUFFIXES):
                if (self.image_dir / f"{frame}{suffix}").is_file():
                    return self.image_dir / f"{frame}{suffix}"
        found = self._image_files().get(frame)
        return found if found is not None else self.image_dir / f"{frame}.png"

    def calib_path(self, frame_id: str | int) -> Path:
        """``calib/FRAME.txt`` of the split; the one calibration's file where the dataset has one."""
        if self._calib is not None:
            return Path(self._calib.source)
        return self.split_dir / "calib" / f"{self._id(frame_id)}.txt"

    def label_path(self, frame_id: str | int) -> Path:
        """``label_2/FRAME.txt`` of the split."""
        return self.split_dir / "label_2" / f"{self._id(frame_id)}.txt"

    def image(self, frame_id: str | int) -> np.ndarray:
        """``(H, W, 3)`` uint8 left colour image."""
        return read_image(self.image_path(frame_id))

    def image_size(self, frame_id: str | int) -> tuple[int, int]:
        """``(width, height)`` of the image, from its header."""
        return image_size(self.image_path(frame_id))

    def calib(self, frame_id: str | int) -> KittiCalib:
        """The frame's calibration (:func:`~wirescene.core.camera.read_kitti_calib`): the one
        calibration of every frame where the dataset has one."""
        if self._calib is not None:
            return self._calib
        return read_kitti_calib(self.calib_path(frame_id))

    def record(self) -> dict:
        """What a run's settings record holds of the dataset, for a resumed run to compare:
        the split folder and, with one calibration, the projection every frame takes (a run
        resumed with another camera would mix two cameras' fits).

        Examples
        --------
        >>> from wirescene.core.resources import DATA_DIR
        >>> root = DATA_DIR / "sample" / "kitti"
        >>> sorted(KittiDataset(root).record())
        ['dataset']
        >>> KittiDataset(root, calib=root / "training" / "calib" / "000010.txt").record()["calib"][0]
        [721.5377, 0.0, 609.5593, 44.85728]
        """
        out: dict = {"dataset": str(Path(self.split_dir).resolve())}
        if self._calib is not None:
            out["calib"] = self._calib.P2.tolist()
        return out

    def camera(self, frame_id: str | int) -> Camera:
        """The ``P2`` camera with the frame's image size."""
        return self.calib(frame_id).camera(self.image_size(frame_id))

    def labels(self, frame_id: str | int) -> FrameLabels:
        """The frame's ground truth; every box is checked against the image's size when
        the frame has an image (:func:`read_labels`)."""
        if not self.has_labels:
            raise InputError("split has no label_2/ directory (no ground truth)", path=self.split_dir)
        image = self.image_path(frame_id)
        size = self.image_size(frame_id) if image.is_file() else None  # no image: checked where it is read
        return read_labels(self.label_path(frame_id), image_size=size)

    def check_frames(self, frame_ids, *, labels: bool = False, images: bool = False) -> list[tuple[str, str]]:
        """Read every frame's calibration, image header, (``labels``) label file and (``images``)
        image: an :class:`InputError` naming the first missing or malformed one, before a run
        fits any frame (a hole found at frame N of thousands would cost N fits and leave their
        outputs). Without ``images`` the images are not decoded (their headers are read): a
        truncated image is found where it is read; with it each is decoded as :meth:`image`
        reads it (some 12 ms a KITTI frame), for a run that reads them (after its fits: a report).
        Returns ``[(frame, warning)]`` of the frames whose calibration looks made for another
        image size (:func:`~wirescene.core.validate.off_centre_problem`), for the caller to say."""
        odd = []
        for f in frame_ids:
            camera = self.camera(f)
            problem = off_centre_problem(camera.P, camera.image_size)
            if problem is not None:
                odd.append((f, problem))
            if labels:
                self.labels(f)
            if images:
                self.image(f)
        return odd

    def car_counts(self, frame_ids) -> dict[str | int, int]:
        """``{frame: number of its Car labels}`` for ``frame_ids`` (keyed as given): what the
        training commands check before they learn (a bank or a part model needs labelled cars)."""
        return {f: len(self.labels(f).of_type(*CAR_TYPES)) for f in frame_ids}
