"""Image arrays: one conversion to RGB uint8 and one to grey, used by every stage.

Integer images are scaled by their type's range (uint8 /255, uint16 /65535: a 16-bit
PNG is not all white), signed and 32/64-bit ones holding values up to 255 by 255; float
images are taken as [0, 1] when their maximum is at most 1 (give or take half a level: a
resampling's 1.001), else as [0, 255] (where images enter, values fitting neither are refused:
:func:`range_problem`).
"""

from __future__ import annotations

import numpy as np

from wirescene.core.errors import ShapeError

_LUMA = np.array([0.299, 0.587, 0.114], np.float32)


def _values_and_range(img: np.ndarray) -> tuple[np.ndarray, float]:
    """``img`` as float32 and the value that maps to 1 (its dtype's range)."""
    if img.dtype == bool:
        return img.astype(np.float32), 1.0
    if np.issubdtype(img.dtype, np.integer):
        top = 255.0 if img.dtype.itemsize == 1 else float(np.iinfo(img.dtype).max)
        if (img.dtype.itemsize > 2 or img.dtype.kind == "i") and (img.size == 0 or img.max() <= 255):
            top = 255.0  # signed or 32/64-bit arrays holding 8-bit values (e.g. from arithmetic)
        return img.astype(np.float32), top
    if not np.issubdtype(img.dtype, np.floating):
        raise ShapeError(f"image must have a numeric dtype, got {img.dtype}")
    img = img.astype(np.float32)
    if img.size and not np.all(np.isfinite(img)):
        nan = int(np.isnan(img).sum())
        raise ShapeError(f"image has non-finite values ({nan} NaN, {int(np.isinf(img).sum())} infinite of {img.size})")
    # [0, 1] while the maximum rounds to level 255 (a resampling's 1.001, as its -1e-4 rounds to 0)
    return img, (255.0 if img.size and np.rint(img.max() * np.float32(255.0)) > 255 else 1.0)


def integer_range_problem(image) -> str | None:
    """Why an integer image array would be read as another image than it holds, as a phrase, or
    None: one of a type other than uint8 and uint16 (signed, or wider) holding a value outside
    0..255 is scaled by its type's range (:func:`_values_and_range`), so that an int32 array of a
    16-bit image's values reads black and negative values are cut to 0. Read where images enter
    (:func:`wirescene.api.as_image`), not on the arrays a stage passes on.

    Examples
    --------
    >>> integer_range_problem(np.array([[0, 255]], np.int32)) is None  # 8-bit values, e.g. after arithmetic
    True
    >>> integer_range_problem(np.array([[0, 65535]], np.uint16)) is None  # a 16-bit PNG's range
    True
    >>> integer_range_problem(np.array([[0, 65535]], ">u2")) is None  # big-endian (a raw PGM's bytes) alike
    True
    >>> integer_range_problem(np.array([[0, 4095]], np.int32))
    'integer values outside 0..255 (dtype int32, 0..4095) would be read by the range of int32: cast a 16-bit image to uint16, scale others to 0..255'
    >>> integer_range_problem(np.array([[-1, 254]], np.int16))  # 8-bit values but one: not the range of int16
    'integer values outside 0..255 (dtype int16, -1..254): the negative ones would be read as 0: clip or scale the image to 0..255 (cast a 16-bit image to uint16)'
    """
    img = _colour(np.asarray(image))
    if img.dtype.kind not in "iu" or (img.dtype.kind == "u" and img.dtype.itemsize <= 2) or img.size == 0:
        return None
    lo, hi = img.min(), img.max()
    if lo >= 0 and hi <= 255:
        return None
    if hi <= 255:  # read as 8-bit values (_values_and_range), the negative ones as 0
        return (f"integer values outside 0..255 (dtype {img.dtype}, {lo}..{hi}): the negative ones would be read "
                f"as 0: clip or scale the image to 0..255 (cast a 16-bit image to uint16)")
    return (f"integer values outside 0..255 (dtype {img.dtype}, {lo}..{hi}) would be read by the range of "
            f"{img.dtype}: cast a 16-bit image to uint16, scale others to 0..255")


def float_range_problem(image) -> str | None:
    """Why a float image array would be read as another image than it holds, as a phrase, or None:
    one whose values fit neither [0, 1] nor [0, 255] (a negative value, or one above 255: a
    normalised network input, a sum of images), so that :func:`to_rgb_uint8` would clip some
    pixel. A value that rounds into the range (a resampling's -1e-4 or 1.001) is no clipped pixel. Read
    where images enter (:func:`wirescene.api.as_image`), as :func:`integer_range_problem`;
    non-finite values are refused by the conversion itself.

    Examples
    --------
    >>> float_range_problem(np.array([[0.0, 0.5, 1.0]])) is None  # [0, 1]
    True
    >>> float_range_problem(np.array([[0.0, 128.0, 255.0]], np.float32)) is None  # [0, 255]
    True
    >>> float_range_problem(np.array([[-1e-4, 0.5, 1.001]])) is None  # [0, 1], a resampling's overshoot
    True
    >>> float_range_problem(np.array([[-3.0, 400.0]]))
    'float values outside both 0..1 and 0..255 (dtype float64, -3..400) would be clipped: scale to 0..1 or 0..255'
    """
    img = _colour(np.asarray(image))
    if img.dtype.kind != "f" or img.size == 0:
        return None
    ends = np.array([img.min(), img.max()])
    if not np.all(np.isfinite(ends)):  # refused by _values_and_range, saying how many
        return None
    values, top = _values_and_range(ends)  # the top the whole image is read by: its maximum's
    levels = np.rint(values / np.float32(top) * 255.0)  # to_rgb_uint8's arithmetic, before its clip
    if levels[0] >= 0 and levels[1] <= 255:
        return None
    return (f"float values outside both 0..1 and 0..255 (dtype {img.dtype}, {ends[0]:g}..{ends[1]:g}) would be "
            "clipped: scale to 0..1 or 0..255")


def range_problem(image) -> str | None:
    """Why an image array would be read as another image than it holds, as a phrase, or None:
    :func:`integer_range_problem` or :func:`float_range_problem`, the one check of an image's
    values where images enter (arrays, PIL images and image files alike).

    Examples
    --------
    >>> range_problem(np.array([[0, 200]], np.int32)) is None, range_problem(np.array([[0.0, 1.0]])) is None
    (True, True)
    >>> range_problem(np.array([[-3.0, 400.0]]))
    'float values outside both 0..1 and 0..255 (dtype float64, -3..400) would be clipped: scale to 0..1 or 0..255'
    """
    return integer_range_problem(image) or float_range_problem(image)


def _colour(img: np.ndarray) -> np.ndarray:
    """The colour channels of an image array: an ``(H, W, 4)`` array's alpha left out, as
    :func:`to_rgb_uint8` leaves it out before it reads the values' range.

    Examples
    --------
    >>> _colour(np.zeros((2, 3, 4))).shape, _colour(np.zeros((2, 3))).shape
    ((2, 3, 3), (2, 3))
    """
    return img[..., :3] if img.ndim == 3 and img.shape[-1] == 4 else img


def _channels(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return img[..., None]
    if img.ndim == 3 and img.shape[-1] in (1, 3, 4):
        return _colour(img)  # alpha dropped
    raise ShapeError(f"image must be (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got {img.shape}")


def to_grey(image) -> np.ndarray:
    """Grey ``(H, W)`` float32 in [0, 1] (ITU-R 601 luma of RGB) of an image ``(H, W)``,
    ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)`` (alpha dropped) of any numeric dtype.

    Examples
    --------
    >>> import numpy as np
    >>> grey = to_grey(np.array([[[255, 0, 0], [0, 255, 0]]], np.uint8))  # pure red, pure green
    >>> grey.shape, grey.dtype.name, np.round(grey.astype(float), 3).tolist()
    ((1, 2), 'float32', [[0.299, 0.587]])
    >>> float(to_grey(np.full((2, 2), 65535, np.uint16)).max())  # 16-bit: scaled by its own range
    1.0
    """
    values, top = _values_and_range(_channels(np.asarray(image)))
    grey = values[..., 0] if values.shape[-1] == 1 else values @ _LUMA
    # Luma first, then the scaling: the float32 rounding of every stage's features
    # depends on this order.
    return grey / np.float32(top) if top != 1.0 else grey


def to_rgb_uint8(image) -> np.ndarray:
    """``(H, W, 3)`` uint8 RGB of any supported image array (grey is replicated; see
    :func:`to_grey` for the shapes and the module docstring for the value ranges). An
    ``(H, W, 3)`` uint8 array is returned as it is, not copied.

    Examples
    --------
    >>> import numpy as np
    >>> rgb = to_rgb_uint8(np.array([[0.0, 0.5, 1.0]]))  # float grey in [0, 1]
    >>> rgb.shape, rgb.dtype.name, rgb[0, :, 0].tolist()
    ((1, 3, 3), 'uint8', [0, 128, 255])
    """
    img = np.asarray(image)
    if img.dtype == np.uint8 and img.ndim == 3 and img.shape[-1] == 3:
        return img
    values, top = _values_and_range(_channels(img))
    rgb = np.broadcast_to(values / np.float32(top), values.shape[:2] + (3,))
    return np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)
