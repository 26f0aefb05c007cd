"""Atomic file writes: a file appears complete or not at all, so a failed run never
leaves a partial output behind."""

from __future__ import annotations

import os
import secrets
import shutil
from contextlib import contextmanager
from pathlib import Path

from wirescene.core.errors import InputError


@contextmanager
def atomic_path(path: str | Path, *, suffix: str = ".tmp"):
    """Yield a temporary path beside ``path``; it replaces ``path`` when the block
    succeeds and is removed when it raises. A symbolic link stays: its target is replaced; a
    device or a pipe (``--json /dev/stdout``) is yielded itself and written to.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = Path(d) / "labels.txt"
    ...     with atomic_path(path) as tmp:
    ...         _ = tmp.write_text("Car ...")
    ...     try:
    ...         with atomic_path(path) as tmp:
    ...             _ = tmp.write_text("half a file")
    ...             raise RuntimeError("disk full")
    ...     except RuntimeError:
    ...         pass
    ...     path.read_text(), sorted(p.name for p in Path(d).iterdir())  # the first file, no leftovers
    ('Car ...', ['labels.txt'])
    """
    path = Path(path)
    if path.is_dir():  # a folder, or a link to one: no file takes its place
        raise InputError("a folder where a file is written", path=path)
    if path.exists() and not path.is_file():  # a device or a pipe (/dev/stdout, a FIFO): written to, never replaced
        yield path
        return
    if path.is_symlink():  # the link kept: its target is the file written, beside which the temporary one is made
        path = path.resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    with _named_as(path):  # a full disk or a refused place told of the file asked for, not its temporary
        tmp = _new_file(path.parent, prefix=f".{path.name}.", suffix=suffix)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        # a full disk told of the file asked for, not its temporary; an errno-less OSError keeps message and type
        if exc.errno is not None and exc.filename in (None, str(tmp)):
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def _named_as(path: Path):
    """An OSError of the block with an errno is told of ``path`` (the file or set asked for),
    not of the temporary name the block was making beside it."""
    try:
        yield
    except OSError as exc:
        if exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror, str(path)) from exc


def _new_entry(directory: Path, create, *, prefix: str, suffix: str) -> Path:
    """``create(name)`` at a new name in ``directory`` (``prefix``, random letters,
    ``suffix``), another name where one exists already."""
    for _ in range(100):
        name = directory / f"{prefix}{secrets.token_hex(6)}{suffix}"
        try:
            create(name)
        except FileExistsError:
            continue
        return name
    raise FileExistsError(f"{directory}: no free temporary name for {prefix}*{suffix}")


def _new_file(directory: Path, *, prefix: str, suffix: str) -> Path:
    """Create an empty file of a new name in ``directory`` with the permissions any new file
    gets there (``0o666`` less the umask: ``tempfile.mkstemp``'s ``0o600`` would make every
    output unreadable to others)."""
    return _new_entry(directory, lambda name: os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)),
                      prefix=prefix, suffix=suffix)


def _new_dir(directory: Path, *, prefix: str, suffix: str) -> Path:
    """Create an empty directory of a new name in ``directory`` with the permissions any new
    directory gets there (``tempfile.mkdtemp``'s ``0o700`` would stay on a set that takes
    a directory's place)."""
    return _new_entry(directory, lambda name: os.mkdir(name, 0o777), prefix=prefix, suffix=suffix)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`), making its directories."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (:func:`atomic_path`), making its directories."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def missing_dirs(path: str | Path) -> list[Path]:
    """``path`` and the directories above it that do not exist yet, deepest first: those
    a ``mkdir(parents=True)`` would make, for :func:`remove_empty` to take back.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     made = missing_dirs(Path(d) / "run" / "plots")
    ...     (Path(d) / "run" / "plots").mkdir(parents=True)
    ...     names = [p.name for p in made]
    ...     remove_empty(made)  # a failed run takes back what it made
    ...     names, (Path(d) / "run").exists()
    (['plots', 'run'], False)
    """
    path = Path(path)
    return [p for p in (path, *path.parents) if not p.exists()]


def remove_empty(made: list[Path]) -> None:
    """Remove the directories of ``made`` (deepest first) up to the first one not empty."""
    for directory in made:
        try:
            directory.rmdir()
        except OSError:
            break


@contextmanager
def _staged(path: Path):
    """A new empty directory beside ``path`` (the directories above it made); when the
    block raises it goes, and so do the directories made for it."""
    made = missing_dirs(path.parent)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with _named_as(path):
            staging = _new_dir(path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except BaseException:
        remove_empty(made)
        raise
    try:
        yield staging
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        remove_empty(made)

        def in_set(name):  # a name in the staging folder (gone by now) as the file's in the set asked for
            if isinstance(name, (str, os.PathLike)) and Path(name).is_relative_to(staging):
                return str(path / Path(name).relative_to(staging))
            return name  # another place's, or no path (bytes, a file descriptor, None)

        if isinstance(exc, OSError) and exc.errno is not None and exc.filename is None:
            # a full disk met by a write() names no file (open() does): told of the set asked for
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        if isinstance(exc, OSError) and exc.errno is not None and (in_set(exc.filename), in_set(exc.filename2)) != (
                exc.filename, exc.filename2):
            # a full disk told of the file in the set asked for, not in its staging folder
            raise OSError(exc.errno, exc.strerror, in_set(exc.filename), None, in_set(exc.filename2)) from exc
        raise


@contextmanager
def atomic_dir(path: str | Path, *, stale: tuple[str, ...] = ()):
    """Yield an empty staging directory beside ``path``; when the block succeeds its files
    move into ``path`` (created if needed), those in folders of the staging directory into
    the same folders of ``path``: files of the same name are replaced, and those of ``path``
    matching a glob pattern of ``stale`` (relative to ``path``, e.g. ``"seed-*/index.html"``)
    that the new set lacks are removed, with the folders they leave empty (never through a
    symbolic link). When the block raises the staging directory goes and so do the
    directories above ``path`` made for it, so that a set of files (a report's pages and
    pictures) appears whole or not at all; a new folder whose place in ``path`` holds a file
    or a symbolic link is an :class:`InputError` before anything moves.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as root:
    ...     report = Path(root) / "set"
    ...     (report / "old").mkdir(parents=True)
    ...     _ = (report / "old" / "a.txt").write_text("old")
    ...     with atomic_dir(report, stale=("*/a.txt",)) as staging:
    ...         (staging / "new").mkdir()
    ...         _ = (staging / "new" / "a.txt").write_text("new")
    ...     sorted(p.relative_to(report).as_posix() for p in report.rglob("*"))
    ['new', 'new/a.txt']
    """
    path = Path(path)
    with _staged(path) as staging:
        yield staging
        problem = _merge_problem(staging, path) if path.is_dir() else None
        if problem is not None:  # before anything moves: a half-merged set would mix two runs
            raise InputError(problem, path=path)
        new = {entry.relative_to(staging) for entry in staging.rglob("*") if not entry.is_dir()}
        _move_into(staging, path)
        for pattern in stale:  # after the new files are in: an interruption leaves no page without its pictures
            for old in path.glob(pattern):
                where = old.relative_to(path)
                through_link = any((path / folder).is_symlink() for folder in list(where.parents)[:-1])
                if where not in new and old.is_file() and not through_link:
                    old.unlink()
                    remove_empty([path / folder for folder in list(where.parents)[:-1]])
    shutil.rmtree(staging, ignore_errors=True)


def _merge_problem(source: Path, target: Path) -> str | None:
    """Why the staged folders of ``source`` cannot be merged into ``target``: a symbolic link
    where one goes (the merge would write outside ``target``) or a file (or a folder where
    a file goes); None when they can."""
    for entry in source.iterdir():
        there = target / entry.name
        if entry.is_dir() and there.is_symlink():
            return f"{entry.name} is a symbolic link where the new set has a folder"
        if there.exists() and entry.is_dir() != there.is_dir():
            new, old = ("folder", "file") if entry.is_dir() else ("file", "folder")
            return f"{entry.name} is a {old} where the new set has a {new}"
        if entry.is_dir() and there.is_dir():
            problem = _merge_problem(entry, there)
            if problem is not None:
                return f"{entry.name}/{problem}"
    return None


def _move_into(source: Path, target: Path) -> None:
    """Move the entries of ``source`` into ``target`` (made if needed), a folder into the folder of
    its name there; folders first and pages (``.html``) last, so that a page comes after what it shows."""
    target.mkdir(exist_ok=True)
    for entry in sorted(source.iterdir(), key=lambda e: (not e.is_dir(), e.suffix == ".html", e.name)):
        if entry.is_dir() and not entry.is_symlink() and (target / entry.name).is_dir():
            _move_into(entry, target / entry.name)
        else:
            os.replace(entry, target / entry.name)


@contextmanager
def replaced_dir(path: str | Path):
    """Yield an empty staging directory beside ``path`` that takes ``path``'s place whole
    when the block succeeds (a directory there before is removed only then); when the
    block raises the staging directory goes, ``path`` is left as it was, and so are the
    directories above it (those made for it are removed). A symbolic link to a directory
    stays: the directory it points to is the one replaced; a link to nothing (or a loop of
    links) is an :class:`InputError` before the block runs (the set could not take its place).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     root = Path(d)
    ...     (root / "set").mkdir()
    ...     _ = (root / "set" / "old.txt").write_text("old")
    ...     with replaced_dir(root / "set") as staging:
    ...         _ = (staging / "a.txt").write_text("new")
    ...     sorted(p.name for p in (root / "set").iterdir())  # the old set is gone whole
    ['a.txt']
    """
    path = Path(path)
    if path.is_symlink() and path.is_dir():  # a set kept on another disk through a link stays there
        path = path.resolve()
    elif path.is_symlink() and not path.exists():  # found after the block's work, as "Not a directory"
        raise InputError(f"a symbolic link to {os.readlink(path)}, which leads to no folder (a disk not mounted, "
                         "a folder not made yet, or a loop of links): make the folder or remove the link", path=path)
    with _staged(path) as staging:
        yield staging
        with _named_as(path):
            old = _new_dir(path.parent, prefix=f".{path.name}.", suffix=".old")
        try:
            if path.exists():
                os.replace(path, old / path.name)
            os.replace(staging, path)
        except BaseException:
            if (old / path.name).exists():  # the swap failed half-way: the old set goes back
                try:
                    os.replace(old / path.name, path)
                except OSError as restore:  # nor could it: the old set stays where it is, and the error says so
                    said = f"the new set could not take its place, and the old one is left in {old / path.name}"
                    raise (OSError(f"{path}: {said}") if restore.errno is None
                           else OSError(restore.errno, said, str(path))) from None
            old.rmdir()
            raise
        shutil.rmtree(old, ignore_errors=True)
