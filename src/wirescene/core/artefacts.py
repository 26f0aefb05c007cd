"""One convention for every trained artefact and record file: a ``format`` tag
``"wirescene-KIND/VERSION"`` stored with the data (a 0-d string array in ``.npz``, a
top-level key in JSON), checked on load. A missing, unreadable, corrupt or mismatched
file is an :class:`~wirescene.core.errors.InputError` naming the file; nothing falls
back silently. Arrays are loaded without pickle.
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from wirescene.core.atomic import write_bytes, write_text
from wirescene.core.errors import InputError
from wirescene.core.validate import path_problem

#: What a missing trained file's error says (the fix, not only the fact).
MISSING_ARTEFACT = "artefact file is missing (run the training command that makes it)"


def format_tag(kind: str, version: int) -> str:
    """``"wirescene-KIND/VERSION"``.

    Examples
    --------
    >>> format_tag("shape-model", 1)
    'wirescene-shape-model/1'
    """
    return f"wirescene-{kind}/{int(version)}"


def _check(found, kind: str, version: int, path: Path, older=()) -> None:
    want = format_tag(kind, version)
    if found != want and found not in {format_tag(kind, v) for v in older}:
        raise InputError(f"format {found!r}, expected {want!r} (retrain or reinstall it)", path=path)


def save_npz(path: str | Path, arrays: dict, *, kind: str, version: int) -> Path:
    """Write ``arrays`` (``{name: array}``, no object arrays) with their format tag, atomically,
    compressed; returns ``path``. Read it back with :func:`load_npz`.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = save_npz(Path(d) / "weights.npz", {"w": np.arange(3.0)}, kind="demo", version=2)
    ...     arrays = load_npz(path, kind="demo", version=2)
    ...     load_npz(path, kind="demo", version=3)
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...weights.npz: format 'wirescene-demo/2', expected 'wirescene-demo/3' (...)
    >>> arrays
    {'w': array([0., 1., 2.])}
    """
    buf = io.BytesIO()
    np.savez_compressed(buf, format=np.array(format_tag(kind, version)), **arrays)
    write_bytes(Path(path), buf.getvalue())
    return Path(path)


def load_npz(path: str | Path, *, kind: str, version: int, older=()) -> dict[str, np.ndarray]:
    """Arrays of an artefact written by :func:`save_npz` (format checked: ``version``, or one
    of the ``older`` versions its reader still understands; an error names ``version``),
    as ``{name: array}`` without the tag; see :func:`save_npz` for an example.

    Raises
    ------
    InputError
        Naming the file: missing, corrupt, or of another kind or version.
    """
    path = Path(path)
    problem = path_problem(path, "artefact", missing=MISSING_ARTEFACT)
    if problem:
        raise InputError(problem, path=path)
    arrays = npz_arrays(path)
    found = arrays.pop("format", None)
    _check(None if found is None else str(found), kind, version, path, older)
    return arrays


#: The arrays of an artefact's record of the real frames it was trained on (:func:`trained_arrays`).
TRAINED_FRAMES, TRAINED_IMAGES = "trained_frames", "trained_images_sha256"


def trained_arrays(images: dict[str, str]) -> dict[str, np.ndarray]:
    """The arrays by which an artefact's ``.npz`` records the real frames it was trained on,
    ``images`` ``{frame id: SHA-256 (hex) of its image}``: the ids (fixed-width strings) and the
    digests as 32 raw bytes each (240 kB for KITTI's 7,481 training frames, half their hex);
    none for no frame. Read back by :func:`trained_images`.

    Examples
    --------
    >>> arrays = trained_arrays({"000010": "ab" * 32})
    >>> arrays[TRAINED_FRAMES], arrays[TRAINED_IMAGES].shape, trained_images(arrays, path="m.npz")["000010"][:6]
    (array(['000010'], dtype='<U6'), (1, 32), 'ababab')
    >>> trained_arrays({})
    {}
    """
    if not images:
        return {}
    digests = bytes.fromhex("".join(images.values()))
    return {TRAINED_FRAMES: np.array(list(images), dtype=str),
            TRAINED_IMAGES: np.frombuffer(digests, np.uint8).reshape(len(images), 32)}


def trained_images(arrays: dict, *, path) -> dict[str, str]:
    """``{frame id: image SHA-256}`` of the record :func:`trained_arrays` made among an artefact's
    ``arrays``; ``{}`` where it has none (a file trained on no real frame, or written before the
    record was).

    Raises
    ------
    InputError
        Naming ``path``: a record whose ids and digests do not match.
    """
    if TRAINED_FRAMES not in arrays and TRAINED_IMAGES not in arrays:
        return {}
    frames, digests = np.asarray(arrays.get(TRAINED_FRAMES)), np.asarray(arrays.get(TRAINED_IMAGES))
    if frames.dtype.kind != "U" or frames.ndim != 1 or digests.dtype != np.uint8 or digests.shape != (len(frames), 32):
        raise InputError(f"malformed record of its training frames ({TRAINED_FRAMES}, {TRAINED_IMAGES})", path=path)
    hexes = digests.tobytes().hex()
    return {f: hexes[64 * i:64 * (i + 1)] for i, f in enumerate(frames.tolist())}


def read_trained_images(path: str | Path) -> dict[str, str]:
    """The record of the real frames the artefact ``.npz`` at ``path`` was trained on
    (:func:`trained_images`), its two arrays read alone; ``{}`` for a file without one or that
    cannot be read (its loader names the problem).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = save_npz(Path(d) / "m.npz", {"w": np.zeros(2), **trained_arrays({"000010": "00" * 32})},
    ...                     kind="demo", version=1)
    ...     read_trained_images(path) == {"000010": "0" * 64}, read_trained_images(Path(d) / "missing.npz")
    (True, {})
    """
    try:
        return trained_images(npz_arrays(path, (TRAINED_FRAMES, TRAINED_IMAGES)), path=path)
    except InputError:
        return {}


def npz_arrays(path: Path, names=None) -> dict[str, np.ndarray]:
    """``{name: array}`` of the ``.npz`` at ``path``, of ``names`` alone where given (those it
    holds), read without pickle; an :class:`InputError` naming a file that cannot be read as one."""
    try:
        loaded = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"corrupt artefact file ({exc.__class__.__name__})", path=path) from None
    if not isinstance(loaded, np.lib.npyio.NpzFile):  # np.load gives an .npy file's one array, no archive
        raise InputError("corrupt artefact file (a single .npy array, not an .npz archive)", path=path)
    try:
        with loaded as z:
            return {k: z[k] for k in z.files if names is None or k in names}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"corrupt artefact file ({exc.__class__.__name__})", path=path) from None
    except zlib.error:  # a member's compressed bytes damaged
        raise InputError("corrupt artefact file (compressed data that does not inflate)", path=path) from None


def save_json(path: str | Path, record: dict, *, kind: str, version: int, indent: int | None = 1) -> Path:
    """Write a JSON record (a dict of JSON-ready values) with its format tag first,
    atomically; returns ``path``.

    Examples
    --------
    >>> import json, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = save_json(Path(d) / "run.json", {"frames": 2}, kind="run", version=1)
    ...     json.loads(path.read_text()), load_json(path, kind="run", version=1)
    ({'format': 'wirescene-run/1', 'frames': 2}, {'frames': 2})
    """
    write_text(Path(path), json.dumps({"format": format_tag(kind, version), **record}, indent=indent))
    return Path(path)


def load_json(path: str | Path, *, kind: str, version: int) -> dict:
    """A JSON record written by :func:`save_json` (format checked), without the tag."""
    path = Path(path)
    problem = path_problem(path, "artefact", missing=MISSING_ARTEFACT)
    if problem:
        raise InputError(problem, path=path)
    try:
        record = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"corrupt JSON file ({exc.__class__.__name__})", path=path) from None
    if not isinstance(record, dict):
        raise InputError("corrupt JSON file (not an object)", path=path)
    record = dict(record)
    _check(record.pop("format", None), kind, version, path)
    return record
