"""Resume records of an evaluation run: one JSON file per finished frame under the
predictions directory, holding the run's configuration and each variant's result; and the
settings' record of a run writing one file a frame (``predict``'s ``.predict.json``,
``detect --out``'s ``.detect.json``), which a resumed run compares with its own."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Mapping

from wirescene.core.artefacts import format_tag
from wirescene.core.atomic import write_text
from wirescene.core.errors import InputError
from wirescene.core.version import __version__
from wirescene.eval.metrics import FrameResult
from wirescene.io.kitti import KittiDataset

if TYPE_CHECKING:
    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.options import FitOptions


#: Where :func:`evaluate_dataset` keeps the record of each finished frame, under the
#: predictions directory (hidden, so KITTI tools that list ``VARIANT/*.txt`` ignore it).
RECORDS_DIR = ".frames"
RECORD_FORMAT = format_tag("frame-record", 1)


def run_config(
    dataset: KittiDataset, variants: Iterable[str], source: DetectionSource, options: FitOptions, evidence: str
) -> dict:
    """Everything that determines a frame's fits, as stored in its resume record.

    Two runs with equal configurations give equal per-frame results (every frame draws
    its random numbers from the seed and its id alone), so a record is reused only when
    its configuration equals the current one. The package version stands in for the
    code; the content of a detections directory is not included, the one calibration of
    every frame is (:meth:`~wirescene.io.kitti.KittiDataset.record`). Of the trained files
    (:data:`~wirescene.fitting.models.MODEL_FILES`) it holds those the fit reads
    (:func:`~wirescene.fitting.models.model_files_read`): their paths among the options and
    their content hashes under ``models`` (:func:`~wirescene.fitting.models.models_fingerprint`),
    so that a model retrained in place refits and a file the run does not read (the part and
    shape models of coarse variants, say) changes nothing. Of the options it holds those the
    fit reads too (:func:`~wirescene.fitting.models.options_read`: not the fine stage's for
    coarse variants, nor our own pre-detection's for other boxes); a record written before an
    option was left out differs in it, and its frame is fitted again.
    """
    from wirescene.fitting.models import models_fingerprint, options_read
    from wirescene.fitting.variants import casts_rays

    read = {"fine": casts_rays(variants), "own": source.own, "evidence": evidence}
    spec = source.spec if source.spec in ("gt", "bank") else str(Path(source.spec).resolve())
    config = {
        "wirescene": __version__,
        # the split folder, and the one calibration of its frames where it has one (KittiDataset.record)
        **dataset.record(),
        # Per-variant fits do not depend on the order of the variants (fit_scene seeds
        # itself per call), but the set decides whether part evidence is computed.
        "variants": sorted(variants),
        "detections": {"spec": spec, "viewpoint_noise_deg": float(source.viewpoint_noise_deg),
                       "allow_missing": bool(source.allow_missing),
                       # the bank that finds our own boxes (another source's are found without it)
                       "bank": None if source.bank is None or not source.own else str(Path(source.bank).resolve()),
                       **source.floor_record()},
        "evidence": evidence,
        "options": options_read(options, **read),
        # the artefacts' content, not only their paths: a model retrained in place refits
        "models": models_fingerprint(options, **read),
    }
    # Normalised through JSON (tuples become lists; anything else JSON cannot hold, as
    # its str) so that it compares equal to a stored one.
    return json.loads(json.dumps(config, default=str))


def config_difference(stored, current, prefix: str = "") -> list[str]:
    """Dotted names of the settings in which two configurations differ.

    Examples
    --------
    >>> config_difference({"seed": 1, "options": {"a": 1, "b": 2}}, {"seed": 1, "options": {"a": 1, "b": 3}})
    ['options.b']
    """
    if isinstance(stored, dict) and isinstance(current, dict):
        out = []
        for key in sorted(set(stored) | set(current), key=str):
            out += config_difference(stored.get(key), current.get(key), f"{prefix}{key}.")
        return out
    return [] if stored == current else [prefix.rstrip(".")]


def settings_record(folder: Path, name: str, *, command: str) -> Path:
    """``folder / name``, where ``command`` keeps its run's settings' record; an
    :class:`InputError` naming it where a folder is in its place (found before any frame, not
    when the first frame's file is written)."""
    path = Path(folder) / name
    if path.is_dir():
        raise InputError(f"a folder where {command} writes its settings' record", path=path)
    return path


def stored_config(path: Path) -> dict | None:
    """The settings' record of an earlier run at ``path`` (None where there is none), for a
    resumed run to compare with its own; an :class:`InputError` naming it where it cannot be
    read as one, not taken for no record and written over: a resumed run refuses it, with or
    without the files it describes (as ``eval --resume`` names a frame's unreadable record)."""
    if not path.exists():
        return None
    try:
        stored = json.loads(path.read_text())
        if not isinstance(stored, dict):
            raise TypeError(f"a JSON {type(stored).__name__}, not an object")
    except (OSError, ValueError, TypeError) as exc:  # ValueError: UnicodeDecodeError and JSONDecodeError too
        why = exc if isinstance(exc, TypeError) else exc.__class__.__name__
        raise InputError(f"unreadable settings record ({why}): cannot resume from it (remove it to start afresh, "
                         "or choose another directory)", path=path) from None
    return stored


def settings_changed(stored: dict | None, config: dict, *, record: str,
                     said: Mapping[str, str] | None = None) -> str | None:
    """The settings in which an earlier run's record ``stored`` differs from ``config``, as a
    refusal names them (``said``: a setting's name in the command's words, e.g. its option);
    ``"RECORD missing"`` where there is no record; None where they are the same.

    Examples
    --------
    >>> settings_changed({"threshold": 0.5, "upsample": 1.5}, {"threshold": 0.3, "upsample": 1.5}, record=".r.json")
    'threshold'
    >>> settings_changed(None, {"threshold": 0.3}, record=".r.json"), settings_changed({}, {}, record=".r.json")
    ('.r.json missing', None)
    """
    if stored == config:
        return None
    if stored is None:
        return f"{record} missing"
    return ", ".join((said or {}).get(name, name) for name in config_difference(stored, config))


def resumed_settings(folder: Path, files: list[Path], config: dict, record: Path, frame_ids, *, would: str,
                     what: str = "label files", said: Mapping[str, str] | None = None) -> dict | None:
    """The refusals of a run resumed in ``folder``, before any frame: where it holds ``files``
    (one a frame, ``FRAME.*``) written with settings other than ``config`` (or without the
    record ``record``), or of frames outside ``frame_ids`` (:func:`refuse_frames_outside`,
    ``would`` and ``what`` its words); returns the earlier run's record (None: none).

    Raises
    ------
    InputError
        Naming ``folder``, or ``record`` where it cannot be read (:func:`stored_config`).
    """
    stored = stored_config(record)
    if files:
        changed = settings_changed(stored, config, record=record.name, said=said)
        if changed is not None:
            raise InputError(f"{what} were written with other settings ({changed}): cannot resume into this "
                             "directory", path=folder)
        refuse_frames_outside(folder, files, frame_ids, would=would, what=what)
    return stored


class StaleRecord(Exception):
    """A frame record that cannot be reused (the message says why).

    Examples
    --------
    >>> import tempfile
    >>> empty = FrameResult("000001", [], [], [], [], [], [], [], [])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     FrameRecords(Path(tmp), {"variants": ["coarse"], "seed": 0}).save("000001", {"coarse": ("", empty)})
    ...     FrameRecords(Path(tmp), {"variants": ["coarse"], "seed": 1}).load("000001")
    Traceback (most recent call last):
    ...
    wirescene.eval.records.StaleRecord: written with a different configuration (seed)
    """


class FrameRecords:
    """The resume records of one predictions directory: ``DIR/.frames/FRAME.json`` holds
    the configuration and, per variant, the frame's :class:`FrameResult` and its KITTI
    label text. A record is written (atomically) only after the frame's label files, so
    its presence means the frame is complete.

    Examples
    --------
    >>> import tempfile
    >>> empty = FrameResult("000001", [], [], [], [], [], [], [], [])  # a frame without detections
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     records = FrameRecords(Path(tmp), {"variants": ["coarse"], "seed": 0})
    ...     records.save("000001", {"coarse": ("", empty)})  # coarse/000001.txt, then .frames/000001.json
    ...     labels, result = records.load("000001")["coarse"]
    ...     missing = records.load("000002")
    >>> labels, result.n_detections, missing
    ('', 0, None)
    """

    def __init__(self, predictions_dir: Path, config: dict):
        self.root = Path(predictions_dir)
        self.config = config

    def path(self, frame_id: str) -> Path:
        return self.root / RECORDS_DIR / f"{frame_id}.json"

    def labels_path(self, variant: str, frame_id: str) -> Path:
        return self.root / variant / f"{frame_id}.txt"

    def save(self, frame_id: str, fits: dict[str, tuple[str, FrameResult]]) -> None:
        """Write the label files of every variant, then the record."""
        for v, (labels, _) in fits.items():
            write_text(self.labels_path(v, frame_id), labels)
        record = {
            "format": RECORD_FORMAT,
            "frame": frame_id,
            "config": self.config,
            "variants": {v: {"labels": labels, "result": result.to_dict()} for v, (labels, result) in fits.items()},
        }
        write_text(self.path(frame_id), json.dumps(record))

    def load(self, frame_id: str) -> dict[str, tuple[str, FrameResult]] | None:
        """The frame's label text and result per variant; ``None`` without a record.

        Raises
        ------
        StaleRecord
            If the record is unreadable, of another frame or format, or was written with
            a different configuration.
        """
        path = self.path(frame_id)
        if not path.is_file():
            return None
        try:
            record = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise StaleRecord(f"unreadable ({exc.__class__.__name__})") from None
        if not isinstance(record, dict) or record.get("format") != RECORD_FORMAT or record.get("frame") != frame_id:
            raise StaleRecord("not a record of this frame")
        if record.get("config") != self.config:
            changed = config_difference(record.get("config"), self.config)
            raise StaleRecord(f"written with a different configuration ({', '.join(changed) or 'config'})")
        try:
            variants = record["variants"]
            fits = {v: (str(variants[v]["labels"]), FrameResult.from_dict(variants[v]["result"]))
                    for v in self.config["variants"]}
        except (KeyError, TypeError, ValueError) as exc:
            raise StaleRecord(f"malformed ({' '.join(str(exc).split())})") from None
        return fits

    def restore_labels(self, frame_id: str, fits: dict[str, tuple[str, FrameResult]]) -> None:
        """Rewrite label files of a reused frame that have gone missing or differ from its
        record since (a run of other settings stopped between a frame's labels and its
        record)."""
        for v, (labels, _) in fits.items():
            path = self.labels_path(v, frame_id)
            try:
                same = path.read_text() == labels
            except (OSError, UnicodeDecodeError):
                same = False
            if not same:
                write_text(path, labels)


def recorded_frames(predictions_dir) -> list[str]:
    """The frames a predictions directory holds records of (whatever their settings).

    Examples
    --------
    >>> import tempfile
    >>> empty = FrameResult("000001", [], [], [], [], [], [], [], [])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     before = recorded_frames(tmp)
    ...     FrameRecords(Path(tmp), {"variants": ["coarse"]}).save("000001", {"coarse": ("", empty)})
    ...     before, recorded_frames(tmp)
    ([], ['000001'])
    """
    return sorted(p.stem for p in (Path(predictions_dir) / RECORDS_DIR).glob("*.json"))


def refuse_earlier_run(predictions_dir) -> None:
    """An :class:`InputError` if ``predictions_dir`` holds an earlier run's records: a run
    that does not resume it would leave its frames beside the other's, to pass for one run.

    Examples
    --------
    >>> import tempfile
    >>> empty = FrameResult("000001", [], [], [], [], [], [], [], [])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     refuse_earlier_run(tmp)  # an empty directory: nothing to refuse
    ...     FrameRecords(Path(tmp), {"variants": ["coarse"]}).save("000001", {"coarse": ("", empty)})
    ...     refuse_earlier_run(tmp)
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...holds the records of an earlier run (1 frames)...
    """
    earlier = recorded_frames(predictions_dir)
    if earlier:
        raise InputError(f"holds the records of an earlier run ({len(earlier)} frames): resume it (--resume reuses "
                         "the frames of the same settings and fits the rest) or choose another directory",
                         path=predictions_dir)


def refuse_frames_outside(folder, files, frame_ids, *, would: str, what: str = "label files") -> None:
    """An :class:`InputError` if ``files`` (paths under ``folder``, each named after its frame,
    ``FRAME.txt``) hold frames outside ``frame_ids``: a run resumed with a narrower selection
    (``--frames``, ``--split-file``) than the one it continues would leave them in ``folder``
    beside its own; the message names the first, calls them ``what``, and says what they
    ``would`` then do. Nothing when every file is of a chosen frame.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     files = [Path(tmp) / "000002.txt", Path(tmp) / "000010.txt"]
    ...     refuse_frames_outside(tmp, files, ["000002", "000010", "001545"], would="...")  # a larger selection
    ...     refuse_frames_outside(tmp, files, ["000010"], would="which would pass for this run's")
    Traceback (most recent call last):
    ...
    wirescene.core.errors.InputError: ...holds the label files of 1 frame outside this run's selection (e.g. 000002.txt), which would pass for this run's: resume with a selection that includes them, or choose another directory
    """
    chosen = set(frame_ids)
    outside = [Path(f) for f in files if Path(f).stem not in chosen]
    if outside:
        n = len({f.stem for f in outside})
        example = outside[0].relative_to(folder).as_posix()
        raise InputError(f"holds the {what} of {n} frame{'s' if n > 1 else ''} outside this run's selection "
                         f"(e.g. {example}), {would}: resume with a selection that includes them, or choose another "
                         "directory", path=folder)


def refuse_records_outside(predictions_dir, variants: Iterable[str], frame_ids) -> None:
    """:func:`refuse_frames_outside` of a resumed evaluation's ``predictions_dir``: its label
    files of ``variants`` (``VARIANT/FRAME.txt``) and its records (``.frames/FRAME.json``) must
    all be of ``frame_ids``, else the label files of frames this run does not evaluate would
    stay beside its own, to be scored with them by ``kitti-eval`` of its folders."""
    root = Path(predictions_dir)
    files = [p for v in variants for p in sorted((root / v).glob("*.txt"))]
    files += sorted((root / RECORDS_DIR).glob("*.json"))
    refuse_frames_outside(root, files, frame_ids, what="label files or records",
                          would="which `kitti-eval` of its folders would score with this run's")


def refuse_predictions_dir(predictions_dir, variants: Iterable[str], frame_ids, *, resume: bool) -> None:
    """The refusals of an evaluation's ``predictions_dir``, before any fit: without ``resume``,
    one holding an earlier run's records (:func:`refuse_earlier_run`); resumed, one holding
    files of frames outside ``frame_ids`` (:func:`refuse_records_outside`).

    Parameters
    ----------
    predictions_dir : path
        The folder of one run's label files and records.
    variants : iterable of str
        The run's model variants (their folders).
    frame_ids : iterable of str
        The run's frames.
    resume : bool
        Whether the run continues the one recorded in ``predictions_dir``.

    Raises
    ------
    InputError
        Naming ``predictions_dir``.
    """
    if resume:  # a narrower selection would leave the other frames' label files beside this run's
        refuse_records_outside(predictions_dir, variants, frame_ids)
    else:
        refuse_earlier_run(predictions_dir)
