"""Split files: the frames of a run listed in KITTI's ``ImageSets`` format (``train.txt``,
``val.txt``: one frame id a line, e.g. ``000123``), read by every command that chooses
frames (``--split-file``) and by :func:`wirescene.evaluate`."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterable

from wirescene.core.errors import InputError
from wirescene.core.validate import path_problem

__all__ = ["read_split_file"]

# KITTI's ids are six digits; our own frames of tracking drives (trk0001_000005) are ids too.
_FRAME_ID = re.compile(r"[A-Za-z0-9_-]+")


def read_split_file(path: str | Path, *, known: Iterable[str] | None = None, what: str = "frame",
                    where: str | Path | None = None) -> list[str]:
    """Frame ids of a split file, in the file's order.

    Parameters
    ----------
    path : path
        One frame id a line; blank lines (and surrounding white space) are ignored.
    known : iterable of str, optional
        The frames the ids must name (e.g. the labelled frames of a KITTI root).
    what, where : str
        How an unknown id is reported: ``"line 7: no {what} 000123 in {where}"``.

    Returns
    -------
    list of str
        The ids, each once.

    Raises
    ------
    InputError
        Naming the file (and the line): missing or unreadable file, a line that is not
        one frame id, an id listed twice, an id not in ``known``, or no id at all.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "val.txt").write_text("000010\\n\\n  001545  \\n")
    ...     ids = read_split_file(Path(d) / "val.txt", known=["000010", "001545"])
    ...     read_split_file(Path(d) / "val.txt", known=["000010"], where="the sample")
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...val.txt: line 3: no frame 001545 in the sample
    >>> ids
    ['000010', '001545']
    """
    path = Path(path)
    problem = path_problem(path, "split")
    if problem:
        raise InputError(problem, path=path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"unreadable split file ({exc.__class__.__name__})", path=path) from None
    known = None if known is None else set(known)
    first_line: dict[str, int] = {}
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text:
            continue
        if not _FRAME_ID.fullmatch(text):
            shown = text if len(text) <= 40 else text[:37] + "..."
            raise InputError(f"line {number}: {shown!r} is not a frame id (one id a line, e.g. 000123)", path=path)
        if text in first_line:
            raise InputError(f"line {number}: frame {text} is listed twice (first on line {first_line[text]})",
                             path=path)
        if known is not None and text not in known:
            place = f" in {where}" if where is not None else ""
            raise InputError(f"line {number}: no {what} {text}{place}", path=path)
        first_line[text] = number
    if not first_line:
        raise InputError("split file lists no frame id", path=path)
    return list(first_line)
