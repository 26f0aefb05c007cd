"""The occluded-part score ``c`` of the likelihood (paper Sec. 4.2), as calibrated by
``wirescene train occlusion`` (:mod:`wirescene.training.occlusion`) into
``data/occlusion.json``. A missing or corrupt file is an error naming it: a silent
fallback value would change every fine-grained fit without a trace."""

from __future__ import annotations

from pathlib import Path

from wirescene.core.artefacts import load_json, save_json
from wirescene.core.errors import InputError
from wirescene.core.resources import DATA_DIR, cached_by_file

DEFAULT_PATH = DATA_DIR / "occlusion.json"
ARTEFACT_KIND = "occlusion"
FORMAT_VERSION = 1


def save_occluded_score(path: str | Path, record: dict) -> Path:
    """Write a calibration record (with its ``c``) as :func:`load_occluded_score` reads it.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = save_occluded_score(Path(tmp) / "occlusion.json", {"c": 0.25, "frames": 72})
    ...     load_occluded_score(path)
    0.25
    """
    return save_json(path, record, kind=ARTEFACT_KIND, version=FORMAT_VERSION)


@cached_by_file(maxsize=8)
def _load(path: Path) -> float:
    record = load_json(path, kind=ARTEFACT_KIND, version=FORMAT_VERSION)
    try:
        c = float(record["c"])
    except (KeyError, TypeError, ValueError):
        raise InputError("calibration record has no numeric 'c'", path=path) from None
    if c != c or abs(c) == float("inf"):
        raise InputError(f"calibrated c is not finite ({c})", path=path)
    return c


def load_occluded_score(path: str | Path | None = None) -> float:
    """The calibrated ``c`` (default: the package's ``data/occlusion.json``).

    Examples
    --------
    >>> c = load_occluded_score()  # the shipped calibration
    >>> isinstance(c, float), c == load_occluded_score(DEFAULT_PATH)
    (True, True)
    """
    return _load(DEFAULT_PATH if path is None else Path(path).resolve())
