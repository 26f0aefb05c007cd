"""Typed errors. Every user-facing failure is one of these, with a one-line message
that names the offending file (if any) and the problem."""

from __future__ import annotations

from pathlib import Path


class WiresceneError(Exception):
    """Base class of all errors raised on purpose by wirescene; ``path`` (a
    :class:`~pathlib.Path` or None) is the file it names, ``problem`` the message without it.

    Examples
    --------
    >>> err = InputError("calibration has no P2 matrix", path="000010.txt")
    >>> str(err), err.problem, isinstance(err, WiresceneError)
    ('000010.txt: calibration has no P2 matrix', 'calibration has no P2 matrix', True)
    >>> isinstance(ShapeError("..."), ValueError)  # shape and argument errors are ValueErrors too
    True
    """

    def __init__(self, message: str, *, path: str | Path | None = None):
        self.path = None if path is None else Path(path)
        self.problem = message
        super().__init__(f"{self.path}: {message}" if self.path is not None else message)


class InputError(WiresceneError):
    """A file given by the user is missing, unreadable or malformed."""


class DependencyError(WiresceneError, ImportError):
    """An optional package that a command needs is not installed; the message says what to
    install."""


class ShapeError(WiresceneError, ValueError):
    """An array does not satisfy the documented shape contract of a function."""


class ArgumentError(WiresceneError, ValueError):
    """An argument of the Python API (or an option of the CLI) has a wrong type, shape
    or value; the message starts with the argument's name.

    Examples
    --------
    >>> err = ArgumentError("particles", "must be at least 1, got 0")
    >>> err.name, str(err)
    ('particles', 'particles: must be at least 1, got 0')
    """

    def __init__(self, name: str, problem: str):
        self.name = name
        super().__init__(f"{name}: {problem}")


class CalibrationWarning(UserWarning):
    """A calibration accepted for an image that it looks made for another image size (its
    principal point in the image's outer quarter: a larger or smaller image's, or a crop's;
    :func:`~wirescene.core.validate.off_centre_problem`): said, not refused, by
    :func:`wirescene.fit` and :func:`wirescene.detect`. Filter it as any warning, e.g.
    ``warnings.simplefilter("error", CalibrationWarning)`` to refuse such a calibration."""


class HeldOutWarning(UserWarning):
    """Some frames :func:`wirescene.evaluate` evaluates are frames a model it reads was
    trained on (the shipped models' 72, a models directory's own, or those a trained file
    records): their figures are not held out (:func:`wirescene.eval.held_out.trained_on_frames`;
    ``wirescene eval`` says it on standard error)."""


def check_shape(name: str, array, shape: tuple) -> None:
    """Check ``array.shape`` against ``shape``; ``None`` entries match any size.

    A leading ``...`` in ``shape`` matches any number of leading dimensions.

    Raises
    ------
    ShapeError
        Naming ``name``, the expected and the actual shape.

    Examples
    --------
    >>> import numpy as np
    >>> check_shape("points", np.zeros((250, 36, 3)), (..., 3))  # passes: returns None
    >>> check_shape("P", np.zeros((3, 3)), (3, 4))
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ShapeError: P must have shape (3, 4), got (3, 3)
    >>> check_shape("boxes", np.zeros((5, 4)), (None, 4))  # None: any size
    >>> check_shape("location", np.zeros(2), (3,))
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ShapeError: location must have shape (3,), got (2,)
    """
    actual = tuple(getattr(array, "shape", ()))
    want = tuple(shape)
    if want and want[0] is Ellipsis:
        tail = want[1:]
        ok = len(actual) >= len(tail) and all(
            w is None or w == a for w, a in zip(tail, actual[len(actual) - len(tail):])
        )
    else:
        ok = len(actual) == len(want) and all(w is None or w == a for w, a in zip(want, actual))
    if not ok:
        pretty = ", ".join("..." if w is Ellipsis else ("*" if w is None else str(w)) for w in want)
        pretty = f"({pretty},)" if len(want) == 1 else f"({pretty})"  # (3,) as Python writes the shape it got
        raise ShapeError(f"{name} must have shape {pretty}, got {actual}")


def shaped_array(name: str, value, shape: tuple, dtype=float):
    """``value`` as an array of ``dtype``, checked against ``shape`` (:func:`check_shape`); an
    empty ``value`` (``[]``: no detections) is taken as an array of that shape where its first
    size is 0 and the others are fixed.

    Examples
    --------
    >>> shaped_array("det_boxes", [], (0, 4)).shape
    (0, 4)
    >>> shaped_array("det_scores", [0.9, 0.5], (2,)).tolist()
    [0.9, 0.5]
    """
    import numpy as np

    arr = np.asarray(value, dtype=dtype)
    if arr.size == 0 and shape[0] == 0 and None not in shape:  # allow [] for empty detections
        arr = arr.reshape(shape)
    check_shape(name, arr, shape)
    return arr
