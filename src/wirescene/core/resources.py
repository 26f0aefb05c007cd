"""Where the package's trained artefacts and bundled data live, and the one resolver of
a models directory (``--models MODELS_DIR``, ``models=``) that replaces them.

A models directory (written by ``wirescene train all --out MODELS_DIR``, or put together
by hand) holds any of the replaceable artefacts of :data:`ARTEFACTS`. Each one it holds
replaces the shipped file everywhere that file is loaded; each one it lacks is the
shipped one. Its manifest ``models.json`` (format ``wirescene-models/1``) lists what it
holds (``"artefacts"``) and whether its training finished (``"complete"``); the directory
must agree with it. A directory with neither a manifest nor any known artefact is an
error, as is an unfinished training or a listed file that is missing.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from wirescene.core.artefacts import MISSING_ARTEFACT, load_json
from wirescene.core.errors import InputError
from wirescene.core.validate import path_problem

#: ``src/wirescene/data``: trained models (npz / JSON) and the bundled sample frames.
DATA_DIR = Path(__file__).resolve().parent.parent / "data"

#: The artefacts a models directory can replace: ``{name: file name}`` (the same name in
#: the models directory as in :data:`DATA_DIR`).
ARTEFACTS: dict[str, str] = {
    "parts_model": "parts_model.npz",
    "detector_bank": "detector_bank.npz",
    "viewpoint_classifier": "viewpoint_classifier.npz",
    "score_calibration": "score_calibration.json",
    "occlusion": "occlusion.json",
    "shape_model": "shape_model.npz",
}
MANIFEST_FILE = "models.json"
MANIFEST_KIND = "models"
MANIFEST_VERSION = 1


def shipped_path(name: str) -> Path:
    """The package's own file of artefact ``name`` (a key of :data:`ARTEFACTS`).

    Examples
    --------
    >>> path = shipped_path("shape_model")
    >>> path.name, path.parent == DATA_DIR, path.is_file()
    ('shape_model.npz', True, True)
    """
    return DATA_DIR / ARTEFACTS[name]


@dataclass(frozen=True)
class Models:
    """The artefacts a run uses: those of a models directory, the shipped ones otherwise.

    Attributes
    ----------
    root : Path or None
        The models directory (None: every artefact is the shipped one).
    own : tuple of str
        Names of the artefacts ``root`` holds (keys of :data:`ARTEFACTS`).

    Examples
    --------
    >>> SHIPPED.describe()  # Models(): every artefact the package's own
    'shipped models'
    >>> SHIPPED.path("occlusion") == shipped_path("occlusion")
    True
    """

    root: Path | None = None
    own: tuple[str, ...] = ()

    def path(self, name: str) -> Path:
        """The file of artefact ``name``: the directory's if it holds one, else the shipped one."""
        if name not in ARTEFACTS:
            raise KeyError(f"unknown artefact {name!r}; known: {', '.join(ARTEFACTS)}")
        return self.root / ARTEFACTS[name] if name in self.own else shipped_path(name)

    def file(self, name: str, *, given=None):
        """What the loader of artefact ``name`` reads (the fit's file options, ``detect``'s
        ``--bank`` and ``--viewpoint-classifier``): ``given``, a file named in its place, which
        wins; else the directory's own file (a string); else None, which the loaders read as
        the shipped file.

        Examples
        --------
        >>> mine = Models(Path("m"), ("viewpoint_classifier",))
        >>> Path(mine.file("viewpoint_classifier")) == Path("m") / "viewpoint_classifier.npz"
        True
        >>> mine.file("viewpoint_classifier", given="v.npz"), mine.file("detector_bank"), SHIPPED.file("detector_bank")
        ('v.npz', None, None)
        """
        path = self.path(name)  # an unknown name: the KeyError that lists the known ones
        if given is not None:
            return given
        return str(path) if name in self.own else None

    def describe(self, *, replaced=()) -> str:
        """One line: which artefacts come from the directory, which from a file given in
        their place (``replaced``, names of :data:`ARTEFACTS`) and which are shipped.

        Examples
        --------
        >>> Models(Path("m"), ("parts_model", "shape_model")).describe(replaced=["shape_model", "detector_bank"])
        'models from m: parts_model; given as files: detector_bank, shape_model; shipped: viewpoint_classifier, \
score_calibration, occlusion'
        """
        if self.root is None:
            return "shipped models"
        replaced = set(replaced)
        own = [n for n in self.own if n not in replaced]
        given = [n for n in ARTEFACTS if n in replaced]
        shipped = [n for n in ARTEFACTS if n not in self.own and n not in replaced]
        return (f"models from {self.root}: {', '.join(own) or 'none used'}"
                + (f"; given as files: {', '.join(given)}" if given else "")
                + (f"; shipped: {', '.join(shipped)}" if shipped else ""))


SHIPPED = Models()


def resolve_models(models_dir: str | Path | None) -> Models:
    """The :class:`Models` of a models directory (None: the shipped models).

    A directory without a manifest (``models.json``) is taken as it is: the known
    artefact files it holds replace the shipped ones.

    Raises
    ------
    InputError
        Naming the directory or file: not a directory; a manifest that is corrupt, of
        another format, lists an unknown or missing artefact, disagrees with the files
        present (or with their hashes), or marks an unfinished training; no manifest and
        no known artefact.

    Examples
    --------
    >>> import shutil, tempfile
    >>> resolve_models(None) is SHIPPED
    True
    >>> with tempfile.TemporaryDirectory() as d:  # a directory put together by hand: one file of its own
    ...     _ = shutil.copy(shipped_path("occlusion"), d)
    ...     models = resolve_models(d)
    ...     own_file, shipped_file = models.path("occlusion"), models.path("parts_model")
    ...     models.own, own_file.parent == Path(d).resolve(), shipped_file.parent == DATA_DIR
    (('occlusion',), True, True)
    """
    if models_dir is None:
        return SHIPPED
    root = Path(models_dir)
    problem = path_problem(root, "models", directory=True)
    if problem:
        raise InputError(problem, path=root)
    present = tuple(n for n, f in ARTEFACTS.items() if (root / f).is_file())
    manifest = root / MANIFEST_FILE
    if not manifest.is_file():
        if not present:
            raise InputError(f"not a models directory: holds no {MANIFEST_FILE} and none of "
                             f"{', '.join(ARTEFACTS.values())}", path=root)
        return Models(root.resolve(), present)
    record = load_json(manifest, kind=MANIFEST_KIND, version=MANIFEST_VERSION)
    listed = record.get("artefacts")
    if not isinstance(listed, list) or not all(isinstance(n, str) for n in listed):
        raise InputError("'artefacts' must be a list of artefact names", path=manifest)
    unknown = [n for n in listed if n not in ARTEFACTS]
    if unknown:
        raise InputError(f"unknown artefact {unknown[0]!r} (known: {', '.join(ARTEFACTS)})", path=manifest)
    if record.get("complete") is not True:
        done = [name for name, step in (record.get("steps") or {}).items() if isinstance(step, dict)
                and step.get("done")]
        raise InputError(f"training not finished (steps done: {', '.join(done) or 'none'}); "
                         "finish it with `wirescene train all ... --resume`", path=manifest)
    missing = [ARTEFACTS[n] for n in listed if n not in present]
    if missing:
        raise InputError(f"{missing[0]} is listed in {MANIFEST_FILE} but missing", path=root)
    extra = [ARTEFACTS[n] for n in present if n not in listed]
    if extra:
        raise InputError(f"{extra[0]} is not listed in {MANIFEST_FILE} (add it to 'artefacts' or remove the file)",
                         path=root)
    written = _written(record)
    for name in listed:  # a file replaced after the training would make the manifest describe another model
        expected = written.get(ARTEFACTS[name])
        if expected and file_sha256(root / ARTEFACTS[name]) != expected:
            raise InputError(f"not the file its training wrote (its SHA-256 differs from {MANIFEST_FILE}'s): retrain "
                             f"it (--resume) or, for a directory put together by hand, remove {MANIFEST_FILE}",
                             path=root / ARTEFACTS[name])
    return Models(root.resolve(), tuple(n for n in ARTEFACTS if n in listed))


def trained_on(path: str | Path, image_path, frame_ids, *, split_dir: str | Path) -> list[str]:
    """The frames of ``frame_ids`` that the artefact file at ``path`` was trained on, as the
    manifest beside it records them: a file of ``wirescene train all``, the very one its
    training wrote (its SHA-256 the manifest's). A frame is told by its image's content
    (``image_path(frame id)``, :func:`frames_of_content`), as the manifest records each training
    image's SHA-256 (a copy of the KITTI root elsewhere is the same frames); a manifest of an
    earlier version, without them, by the KITTI split directory ``split_dir`` and the ids. No
    frame (``[]``) for a file no readable manifest beside it lists (a shipped file, a file put
    there by hand).

    Examples
    --------
    >>> trained_on(shipped_path("parts_model"), Path, ["000010"], split_dir="kitti/training")  # no manifest
    []
    """
    path = Path(path)
    manifest = path.parent / MANIFEST_FILE
    if not manifest.is_file():
        return []
    try:
        record = load_json(manifest, kind=MANIFEST_KIND, version=MANIFEST_VERSION)
    except InputError:  # a broken manifest is refused where the directory is read as --models
        return []
    written = _written(record)
    data = record.get("data") if isinstance(record.get("data"), dict) else {}
    if path.name not in written or file_sha256(path) != written[path.name]:
        return []
    images = data.get("images_sha256")
    if isinstance(images, dict):
        return frames_of_content(image_path, frame_ids, {str(f): h for f, h in images.items() if isinstance(h, str)})
    if not isinstance(data.get("frame_ids"), list) or data.get("kitti_root") != str(Path(split_dir).resolve()):
        return []
    trained = set(map(str, data["frame_ids"]))
    return [f for f in frame_ids if str(f) in trained]


def images_sha256(image_path, frame_ids) -> dict[str, str]:
    """``{frame id: SHA-256 of its image}`` (``image_path(frame id)``) of ``frame_ids``, in their
    order: the record of a training's real frames (a ``train all`` manifest's ``images_sha256``,
    each frame-trained ``.npz``'s :func:`~wirescene.core.artefacts.trained_arrays`), by which
    :func:`frames_of_content` tells them; about 1 ms a KITTI image, each hashed once per file
    version (:func:`file_sha256`).

    Raises
    ------
    InputError
        Naming the first image that is missing or cannot be read.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "000010.png").write_bytes(b"")
    ...     {f: h[:6] for f, h in images_sha256(lambda f: Path(d) / f"{f}.png", ["000010"]).items()}
    {'000010': 'e3b0c4'}
    """
    return {str(f): file_sha256(image_path(f), what="image") for f in frame_ids}


def frames_of_content(image_path, frame_ids, known: dict[str, str]) -> list[str]:
    """The frames of ``frame_ids`` whose image (``image_path(frame id)``) has the content
    ``known`` records for its id (``{frame id: SHA-256}``): only those ids are read; an image
    that cannot be read is not told (the fits that read it refuse it, naming it).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "000010.png").write_bytes(b"pixels")
    ...     known = {"000010": file_sha256(Path(d) / "000010.png"), "000002": "0" * 64}
    ...     frames_of_content(lambda f: Path(d) / f"{f}.png", ["000002", "000010", "000011"], known)
    ['000010']
    """
    seen = []
    for frame in frame_ids:
        if frame not in known:
            continue
        path = Path(image_path(frame))
        try:
            if path.is_file() and file_sha256(path, what="image") == known[frame]:
                seen.append(frame)
        except InputError:
            continue
    return seen


def _written(record: dict) -> dict[str, object]:
    """``{file name: SHA-256}`` of the artefacts a models manifest's steps say they wrote (a step
    naming no file by a string, as ``train all``'s shipped score calibration, is left out).

    Examples
    --------
    >>> _written({"steps": {"parts": {"artefact": "parts_model.npz", "sha256": "ab"}, "odd": {"artefact": ["x"]}}})
    {'parts_model.npz': 'ab'}
    """
    steps = record.get("steps") if isinstance(record.get("steps"), dict) else {}
    return {s["artefact"]: s.get("sha256") for s in steps.values() if isinstance(s, dict)
            and isinstance(s.get("artefact"), str)}


def file_version(path: str | Path) -> tuple[int, int, int] | None:
    """``(inode, size, mtime in ns)`` of the file at ``path`` (None where it cannot be read):
    a file rewritten or replaced at the same path has another version.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     f = Path(d) / "model.npz"
    ...     missing = file_version(f)
    ...     _ = f.write_bytes(b"12345")
    ...     missing, file_version(f)[1]  # the size is its second entry
    (None, 5)
    """
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return stat.st_ino, stat.st_size, stat.st_mtime_ns


def cached_by_file(maxsize: int):
    """Decorate a loader ``load(path=None)`` to load each version of a file once
    (:func:`file_version`): a model retrained in place is loaded anew, in a notebook as in
    a long-lived process. ``None`` (the shipped file) is loaded once; a path that cannot be
    read goes to the loader, which names the problem.

    Examples
    --------
    >>> import tempfile
    >>> @cached_by_file(maxsize=4)
    ... def load(path=None):
    ...     return Path(path).read_text()
    >>> with tempfile.TemporaryDirectory() as d:
    ...     f = Path(d) / "model.txt"
    ...     _ = f.write_text("one")
    ...     first = load(f)
    ...     _ = f.write_text("three")
    ...     first, load(f)
    ('one', 'three')
    """
    def decorate(load):
        @lru_cache(maxsize=maxsize)
        def cached(path, version):
            return load(path)

        @functools.wraps(load)
        def loader(path=None):
            if path is None:
                return cached(None, None)
            version = file_version(path)
            return load(path) if version is None else cached(path, version)

        loader.cache_clear = cached.cache_clear
        return loader

    return decorate


def file_sha256(path: str | Path, *, what: str = "artefact") -> str:
    """SHA-256 (hex) of a file's bytes, computed once per file version (:func:`file_version`).

    Parameters
    ----------
    path : path
        The file.
    what : str
        What the file is, for the error (``"artefact"``, ``"image"``, ``"split"``).

    Raises
    ------
    InputError
        Naming ``path``: missing (an artefact's error says how one is made,
        :data:`~wirescene.core.artefacts.MISSING_ARTEFACT`), not a file, or unreadable.

    Examples
    --------
    >>> import hashlib, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     f = Path(d) / "model.txt"
    ...     _ = f.write_bytes(b"abc")
    ...     file_sha256(f) == hashlib.sha256(b"abc").hexdigest()
    True
    >>> with tempfile.TemporaryDirectory() as d:
    ...     file_sha256(d, what="image")
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...: image path is not a file
    """
    path = Path(path).resolve()
    problem = path_problem(path, what, missing=MISSING_ARTEFACT if what == "artefact" else None)
    version = None if problem else file_version(path)
    if version is None:  # problem None: gone since it was checked
        raise InputError(problem or f"{what} file is unreadable", path=path)
    try:
        return _sha256(path, version)
    except OSError as exc:
        raise InputError(f"cannot read {what} file ({exc.strerror or exc.__class__.__name__})", path=path) from None


# room for KITTI's 7,481 training images: the held-out line hashes a frame's image once, not once per file it reads
@lru_cache(maxsize=8192)
def _sha256(path: Path, version: tuple[int, int, int]) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def artefact_files(models: Models = SHIPPED) -> list[dict]:
    """Every trained or bundled data file a run reads (the ``.npz`` / ``.json`` files of
    :data:`DATA_DIR`, those of ``models`` in place of the shipped ones they replace): one
    ``{"file", "source" ("shipped" or "models"), "path", "bytes", "sha256", "format"}`` each,
    ``format`` the tag stored in the file (None where it has none).

    Examples
    --------
    >>> files = {f["file"]: f for f in artefact_files()}
    >>> files["parts_model.npz"]["source"], files["parts_model.npz"]["format"]
    ('shipped', 'wirescene-parts-forest/2')
    """
    replaced = {ARTEFACTS[name]: models.path(name) for name in models.own}
    out = []
    for shipped in sorted([*DATA_DIR.glob("*.npz"), *DATA_DIR.glob("*.json")]):
        path = replaced.get(shipped.name, shipped)
        out.append({"file": shipped.name, "source": "models" if shipped.name in replaced else "shipped",
                    "path": str(path), "bytes": path.stat().st_size, "sha256": file_sha256(path),
                    "format": _format_tag(path)})
    return out


def _format_tag(path: Path) -> str | None:
    """The format tag a data file stores (``"wirescene-KIND/VERSION"``), None without one."""
    import json

    from wirescene.core.artefacts import npz_arrays

    if path.suffix == ".npz":  # a .npy or damaged compressed data refused in one line, as the loaders refuse them
        found = npz_arrays(path, names=("format",)).get("format")
        return None if found is None else str(found)
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:  # ValueError: JSONDecodeError and UnicodeDecodeError
        raise InputError(f"corrupt data file ({exc.__class__.__name__})", path=path) from None
    return record.get("format") if isinstance(record, dict) else None

