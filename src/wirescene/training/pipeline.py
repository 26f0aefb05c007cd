"""``wirescene train all``: every trained artefact of a models directory from one labelled
KITTI root, in order, each step fed by the previous, with a manifest.

Steps (:data:`STEPS`), each writing one file of :data:`wirescene.core.resources.ARTEFACTS`:

1. ``parts``: the part detectors (:func:`wirescene.training.parts.train_part_detector`,
   the shipped recipe :data:`RECIPE`), their per-part calibration held out by the folds below;
2. ``detector``: the detector bank (:func:`wirescene.training.kitti_detector.train_detector_bank_kitti`),
   its Platt calibration fitted on leave-one-fold-out detections
   (:func:`heldout_bank_calibration`);
3. ``viewpoints``: the crop viewpoint classifier
   (:func:`wirescene.predetect.viewpoint_classifier.train_on_kitti`, the recipe of ``train
   viewpoints``), which gives our own boxes and those of other detectors their viewpoints
   with the bank; a directory of an older ``train all`` without it keeps the shipped one,
   and ``--resume`` trains it;
4. ``score_calibration``: not trained. Fitting the confidence honestly needs evaluation
   records of every frame fitted by models that never saw it (fold models of both steps
   above, then ``eval --raw-scores`` per fold and ``train scores``): several times the
   whole training. The directory keeps the shipped calibration, and the manifest says so;
5. ``occlusion``: the occluded-part score ``c`` (:func:`wirescene.training.occlusion.calibrate_occluded_score`)
   with the part detectors of step 1.

Held-out folds (:func:`calibration_folds`): frames are grouped by recording drive where
the drive is known (:func:`wirescene.io.folds.frame_drives`, and the KITTI devkit's mapping
files of a user's whole training split: :func:`wirescene.io.folds.drive_map`), each other
frame is a group of its own, and the groups are dealt to folds balanced by cars
(:func:`wirescene.io.folds.assign_folds`).

``MODELS_DIR/models.json`` (format ``wirescene-models/1``) records the data (root, split
file, frames), the folds, the packages and BLAS kernels it ran with
(:func:`wirescene.core.version.environment`), and per step its options, inputs, artefact
hash, wall time and peak resident memory, and the run's peak (``peak_rss_mb``, at least each
step's, one kept by ``resume`` too: each step's is measured by resetting the process's, which
``/usr/bin/time`` then reports of the last step alone). It is rewritten after every step from
the first one trained on, ``"complete": false`` until the last;
:func:`wirescene.core.resources.resolve_models` refuses an unfinished directory.
With ``resume``, a step whose record matches the current data (the frames, their label,
calibration and image files and their folds), options, inputs and package
version, and whose file is unchanged, is not run again; the earlier run's records stand
until their steps are replaced, so a resumed run that fails before it trains a step
leaves the directory as it was. The frames' cars, images and calibrations are checked
before any step trains, and a first run whose first step fails leaves no directory.
"""

from __future__ import annotations

import hashlib
import inspect
import numbers
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Iterable, Mapping

from wirescene.core.artefacts import load_json, save_json
from wirescene.core.atomic import missing_dirs, remove_empty
from wirescene.core.errors import InputError
from wirescene.core.resources import (
    ARTEFACTS,
    MANIFEST_FILE,
    MANIFEST_KIND,
    MANIFEST_VERSION,
    file_sha256,
    images_sha256,
    shipped_path,
)
from wirescene.core.validate import finite_real
from wirescene.core.version import __version__, environment
from wirescene.io.folds import drive_map
from wirescene.parts import MAX_SMOOTH
from wirescene.predetect.viewpoint_classifier import check_trainable
from wirescene.training.kitti_detector import (
    calibration_folds,
    calibration_record,
    check_calibration,
    heldout_bank_calibration,
)
from wirescene.training.recipe import RECIPE
from wirescene.training.scale import (
    CACHE,
    MAX_AUG,
    MAX_CACHE_MB,
    MAX_CUT_PASTE,
    MAX_DEPTH,
    MAX_FOLDS,
    MAX_MINING_IMAGES,
    MAX_MINING_ROUNDS,
    MAX_NEGATIVES,
    MAX_OCCLUSION_SCENES,
    MAX_PART_SCENES,
    MAX_PARTIAL,
    MAX_PER_OCTAVE,
    MAX_TREES,
    MAX_VIEWS,
)

__all__ = ["STEPS", "STEP_OPTIONS", "RECIPE", "step_options", "option_default", "check_options", "calibration_folds",
           "heldout_bank_calibration", "train_all"]

#: The steps in order; each makes one artefact (``_ARTEFACT``).
STEPS: tuple[str, ...] = ("parts", "detector", "viewpoints", "score_calibration", "occlusion")
#: The steps that take options (``score_calibration`` is the shipped file).
STEP_OPTIONS: tuple[str, ...] = ("parts", "detector", "viewpoints", "occlusion")
_ARTEFACT = {"parts": "parts_model", "detector": "detector_bank", "viewpoints": "viewpoint_classifier",
             "score_calibration": "score_calibration", "occlusion": "occlusion"}


def _parameters(fn, exclude: Iterable[str]) -> dict[str, object]:
    """``{name: default}`` of the keyword parameters of ``fn`` a step may set."""
    skip = set(exclude)
    return {n: p.default for n, p in inspect.signature(fn).parameters.items()
            if n not in skip and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is not p.empty}


def step_options() -> dict[str, dict[str, object]]:
    """``{step: {option: default}}``: what each trained step accepts (``--set STEP.KEY=VALUE``)."""
    from wirescene.predetect.viewpoint_classifier import train_on_kitti
    from wirescene.training.kitti_detector import train_bank_on_frames, train_detector_bank_kitti
    from wirescene.training.occlusion import calibrate_occluded_score
    from wirescene.training.parts import train_part_detector

    # workers change how fast, not what is trained: a run argument, not a recipe option; synthetic
    # takes loaded frames, which no --set value can name (a study's option: benchmarks/bench_predetect.py)
    bank = _parameters(train_bank_on_frames, ("images", "examples", "progress", "workers", "synthetic"))
    bank.update(_parameters(train_detector_bank_kitti, ("out_path", "kitti_root", "frames", "folds", "split", "progress",
                                                         "calibration_folds", "workers", "drives")))
    return {
        "parts": _parameters(train_part_detector, ("out_path", "kitti_root", "frames", "progress", "calibration_folds")),
        "detector": bank,
        "viewpoints": _parameters(train_on_kitti, ("dataset", "frames")),
        "occlusion": _parameters(calibrate_occluded_score, ("detector", "progress")),
    }


def _reset_peak_memory() -> bool:
    """Reset the process's peak resident memory (Linux ``/proc/self/clear_refs``), so
    that ``ru_maxrss`` measures the next step alone; False where that is not possible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


@dataclass
class _RunPeak:
    """The process's peak resident memory over a run whose steps each reset it to measure their
    own (:func:`_reset_peak_memory`): the peak before every reset is kept (``mb``), so that the
    run's is not lost with it."""

    mb: float | None = None

    def reset(self) -> bool:
        """Keep the peak so far, then reset the process's (:func:`_reset_peak_memory`)."""
        self.mb = self.total()
        return _reset_peak_memory()

    def total(self) -> float | None:
        """The run's peak resident memory so far in MB (None where the OS does not say)."""
        now = _peak_memory_mb()
        return now if self.mb is None else self.mb if now is None else max(self.mb, now)


def step_cost(record: dict) -> str:
    """A finished step's time and peak memory as the manifest records them, in words
    (``"412 s, peak 2048 MB"``; no peak where the OS did not say)."""
    peak = record.get("peak_rss_mb")
    return f"{record['seconds']:.0f} s" + ("" if peak is None else f", peak {peak:.0f} MB")


def _peak_memory_mb() -> float | None:
    """The process's peak resident memory in MB; None where the OS does not say (Windows)."""
    try:
        import resource  # Unix only
    except ImportError:
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(peak / (1 << 20 if sys.platform == "darwin" else 1 << 10), 1)  # bytes on macOS, KiB on Linux


def _frames_sha256(frames: list[str]) -> str:
    return hashlib.sha256("\n".join(frames).encode()).hexdigest()


def option_default(step: str, key: str):
    """The default of option ``key`` of ``step``; a ``ValueError`` naming what exists if
    there is no such step or option."""
    known = step_options()
    if step not in known:
        raise ValueError(f"no step {step!r} takes options; steps: {', '.join(STEP_OPTIONS)}")
    if key not in known[step]:
        raise ValueError(f"step {step} has no option {key!r}; options: {', '.join(sorted(known[step]))}")
    return known[step][key]


#: ``{step: {option: (minimum, maximum)}}`` of the numeric options that a value of 0 (the
#: least any number of a step takes) would break; ``maximum`` None: none.
OPTION_LIMITS: dict[str, dict[str, tuple]] = {
    "parts": {"n_trees": (1, MAX_TREES), "max_depth": (1, MAX_DEPTH), "min_samples_leaf": (1, None),
              "max_real_patches": (1, None), "n_jobs": (-1, None), "synth_seed": (1000, None),
              "smooth": (0, MAX_SMOOTH), "n_views": (0, MAX_VIEWS), "n_aug": (1, MAX_AUG),
              "synth_scenes": (0, MAX_PART_SCENES)},
    "detector": {"C": (1e-9, None), "max_pos": (1, None), "min_pos": (1, None), "neg_per_image": (1, None),
                 "min_height": (1, None), "max_scale": (0.01, None), "full_area": (1, None), "partial_area": (1, None),
                 "per_octave": (1, MAX_PER_OCTAVE), "cluster_radius": (0.01, None), "max_negatives": (1, MAX_NEGATIVES),
                 "max_truncated": (0, 1), "mining_images": (1, MAX_MINING_IMAGES), "threshold": (0, 1),
                 "mining_rounds": (0, MAX_MINING_ROUNDS), "cut_paste": (0, MAX_CUT_PASTE),
                 "pyramid_cache_mb": (0, MAX_CACHE_MB), "n_partial": (0, MAX_PARTIAL)},
    "viewpoints": {"C": (1e-9, None)},
    "occlusion": {"n_scenes": (1, MAX_OCCLUSION_SCENES)},
}
#: The options that take one of a few words.
OPTION_CHOICES: dict[str, dict[str, tuple]] = {"parts": {"class_weight": ("balanced", "balanced_subsample", None)}}
#: The numeric options that None also sets (all: no cap).
OPTION_NONE: dict[str, tuple] = {"parts": ("max_real_patches",), "detector": ("mining_images",)}
#: ``{step: options}`` that name a file or directory (None: none): a path's text, never a number or "".
OPTION_PATHS: dict[str, tuple] = {"parts": ("synth_cache", "kitti_background")}
#: ``{step: options}`` that a ``--set`` text cannot give (an array a command reads from a file), with that command.
OPTION_UNSET: dict[str, dict] = {"parts": {"label_shapes": "wirescene train parts --label-shapes FILE"}}


def _checked_value(step: str, key: str, value):
    """``value`` of option ``key`` of ``step`` if it is of its default's kind (an integer, a
    finite number, true or false) and within :data:`OPTION_LIMITS` (at least 0 otherwise);
    a ``ValueError`` naming the option before any step trains."""
    import dataclasses

    from wirescene.core.settings import check_value

    default = option_default(step, key)
    choices = dict(OPTION_CHOICES.get(step, {}))
    if step == "parts":
        from wirescene.parts.features import KINDS

        choices["kind"] = KINDS
    if key in choices:
        if value not in choices[key]:
            raise ValueError(f"{step}.{key} must be one of {', '.join(map(str, choices[key]))}, got {value!r}")
        return value
    if value is None and key in OPTION_NONE.get(step, ()):
        return None
    if key in OPTION_PATHS.get(step, ()):
        if value is not None and (not isinstance(value, str) or not value.strip()):
            hint = f" (a name of digits or a JSON word: ./{value})" if isinstance(value, (int, float)) else ""
            raise ValueError(f"{step}.{key} must be a path, got {value!r}{hint}")
        return value
    if key in OPTION_UNSET.get(step, {}) and value is not None:
        raise ValueError(f"{step}.{key} is not an option of train all (it is `{OPTION_UNSET[step][key]}`'s)")
    if (step, key) == ("occlusion", "grid") and value is not None:  # the c values the calibration tries
        if not isinstance(value, (list, tuple)) or not value or not all(finite_real(v) for v in value):
            raise ValueError(f"occlusion.grid must be a list of numbers, got {value!r}")
        return value
    low, high = OPTION_LIMITS.get(step, {}).get(key, (0, None))
    if default is None and value is not None and key in OPTION_LIMITS.get(step, {}):  # a number or none
        default = 0
    if default is None:
        return value
    field = dataclasses.field(default=default, metadata={"minimum": low, "maximum": high})
    field.name = key
    value = check_value(field, value, scope=step)
    if (step, key) == ("parts", "n_jobs") and value == 0:  # scikit-learn's: -1 all cores, 0 none
        raise ValueError("parts.n_jobs must not be 0 (-1: all cores)")
    return value


def check_options(overrides: Mapping[str, Mapping[str, object]]) -> dict[str, dict]:
    """The recipe with ``overrides`` (``{step: {option: value}}``), every name and value
    checked (and a given ``detector.calibration``); a ``ValueError`` says what is wrong."""
    out = {step: dict(RECIPE.get(step, {})) for step in STEP_OPTIONS}
    for step, values in overrides.items():
        for key, value in values.items():
            out[step][key] = _checked_value(step, key, value)
    given = out["detector"].get("calibration")
    if given is not None:  # checked here, not after the parts step has trained
        try:
            check_calibration(given, size=3)
        except ValueError as exc:
            raise ValueError(f"detector.calibration: {exc}") from None
    return out


def train_all(
    out_dir,
    kitti_root,
    *,
    frames: list[str] | None = None,
    split_file=None,
    options: Mapping[str, Mapping[str, object]] | None = None,
    n_folds: int = 4,
    drive_mapping=None,
    resume: bool = False,
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
    iterate: Callable[[Iterable, str], Iterable] | None = None,
    notify: Callable[[str], None] | None = None,
) -> dict:
    """Train every artefact of a models directory (see the module docstring).

    Parameters
    ----------
    out_dir : path
        The models directory; must be empty of models unless ``resume``.
    kitti_root : path
        A labelled KITTI root (``training/`` with ``label_2/``) or split directory.
    frames : list of str, optional
        The training frames (default: every labelled frame); checked against the root.
    split_file : path, optional
        Instead of ``frames``: a KITTI ``ImageSets`` file (:func:`wirescene.io.splits.read_split_file`).
    options : dict, optional
        ``{step: {option: value}}`` over :data:`RECIPE` (names of :func:`step_options`).
    n_folds : int
        Folds of the held-out calibrations, 2 to :data:`~wirescene.training.scale.MAX_FOLDS`
        (fewer if there are fewer groups).
    drive_mapping : path, optional
        A KITTI devkit mapping directory (``train_rand.txt``, ``train_mapping.txt``) that
        groups the frames by drive; default: one found under ``kitti_root``
        (:func:`wirescene.io.folds.find_devkit_mapping`), else the drives the project knows.
    resume : bool
        Keep the steps already done in ``out_dir`` with the same data, options and inputs.
    workers : int
        Processes of the detector step's per-image passes (0 or 1: serial); the
        artefacts are the same, so a resumed run may use another number.
    progress : callable, optional
        Receives one line per event.
    iterate : callable, optional
        ``iterate(items, name)`` wraps the steps and a step's inner loops (progress bars).
    notify : callable, optional
        Receives one-line warnings (frames whose calibration looks made for another image
        size, said once before any step); default: standard error.

    Returns
    -------
    dict
        The manifest as written to ``out_dir/models.json``.

    Raises
    ------
    InputError
        A bad root, frame selection, split file or models directory, before any training.
    ValueError
        An unknown step option, ``workers`` beyond :data:`~wirescene.core.validate.MAX_WORKERS`,
        or ``n_folds`` outside 2 to :data:`~wirescene.training.scale.MAX_FOLDS`.
    """
    from wirescene.core.validate import MAX_WORKERS
    from wirescene.io.kitti import KittiDataset

    out = Path(out_dir)
    if frames is not None and split_file is not None:
        raise ValueError("frames and split_file both choose the frames: give one")
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or not 0 <= workers <= MAX_WORKERS:
        raise ValueError(f"workers must be an integer from 0 to {MAX_WORKERS:,}, got {workers!r}")
    if isinstance(n_folds, bool) or not isinstance(n_folds, numbers.Integral) or not 2 <= n_folds <= MAX_FOLDS:
        raise ValueError(f"n_folds must be an integer from 2 to {MAX_FOLDS}, got {n_folds!r}")
    opts = check_options(options or {})
    dataset = KittiDataset(kitti_root)
    dataset.require_labels("training")
    ids = _training_frames(dataset, frames, split_file)
    data_sha256, cars, images = _check_frames(dataset, ids, notify=notify)  # before anything is trained or written
    check_trainable(dataset, ids)  # the viewpoint step's bins, before the steps ahead of it train
    drives, mapping_dir = drive_map(dataset.base_dir, mapping=drive_mapping)
    # held-out folds serve the part calibration and the bank's, unless both are off or given (one drive is then enough)
    held_out = bool(opts["parts"].get("calibrate_real")) or opts["detector"].get("calibration") is None
    folds = calibration_folds(dataset, ids, n_folds=n_folds, drives=drives) if held_out else {}
    previous = _previous_steps(out, resume)
    manifest = _new_manifest(dataset, ids, cars, folds, split_file, drives=drives, mapping_dir=mapping_dir,
                             images=images)
    # what a step learns from: the frames' labels, calibrations and images, and the folds they are dealt to
    # (not the root's path: the same files under another, a copy of the root, train the same)
    key_data = {"frames_sha256": manifest["data"]["frames_sha256"],
                "n_folds": n_folds, "files_sha256": data_sha256,
                "folds_sha256": hashlib.sha256(str(sorted(folds.items())).encode()).hexdigest()}
    run = _Run(out, kitti_root, ids, folds, opts, workers, progress or (lambda message: None),
               iterate or (lambda items, name: items))
    # the earlier run's records stand until a step replaces them, so that a run that fails keeps them
    manifest["steps"] = {s: r for s, r in previous.items() if s in STEPS}
    made = missing_dirs(out)
    out.mkdir(parents=True, exist_ok=True)
    changed = False  # the directory is rewritten from the first step trained on: until then it is as it was
    try:
        for step in run.wrap(STEPS, "train all"):
            if step == "score_calibration":
                manifest["shipped"].append(_ARTEFACT[step])
                manifest["steps"][step] = {
                    "done": True, "source": "shipped", "sha256": file_sha256(shipped_path(_ARTEFACT[step])),
                    "why": "an honest calibration needs evaluation records of fold models on every frame "
                           "(eval --raw-scores per fold, then train scores): not trained by train all"}
            else:
                key = _normalised({"data": key_data, "options": opts[step], "wirescene": __version__,
                                   "inputs": {s: manifest["steps"][s]["sha256"] for s in _INPUTS[step]}})
                record = run.step(step, key, previous.get(step))
                changed |= record is not previous.get(step)
                manifest["steps"][step] = record
                manifest["artefacts"].append(_ARTEFACT[step])
            if changed:
                run.write(manifest)
    except BaseException:
        remove_empty(made)  # a first step that failed leaves no directory behind, nor those made for it
        raise
    manifest["complete"] = True
    run.write(manifest)
    return manifest


def _check_frames(dataset, ids: list[str], *,
                  notify: Callable[[str], None] | None = None) -> tuple[str, int, dict[str, str]]:
    """Check the training frames' calibrations, images (decoded, some 12 ms a KITTI frame: a
    truncated one found here, not in a step hours on) and labels (read to count the cars)
    (:meth:`~wirescene.io.kitti.KittiDataset.check_frames`): an :class:`InputError` naming the
    first missing or malformed file, or saying that they hold no labelled car, before any step
    trains; tell ``notify`` (default: standard error) in one
    line of those whose calibration looks made for another image size
    (:func:`wirescene.eval.runner.say_off_centre`); return a SHA-256 of their label, calibration
    and image files (a resumed step whose frames changed is trained again; an image replaced by
    another of the same size too), their number of cars and ``{frame: its image's SHA-256}`` (the
    manifest's, by which an evaluation tells its frames, :func:`wirescene.core.resources.trained_on`)."""
    from wirescene.eval.runner import SAY_DECODING, notify_stderr, say_off_centre

    notify = notify or notify_stderr
    if len(ids) >= SAY_DECODING:
        notify(f"decoding the {len(ids)} training images before any step trains (a corrupt one refused now)")
    say_off_centre(dataset.check_frames(ids, images=True), len(ids), notify)
    counts = dataset.car_counts(ids)
    if not any(counts.values()):
        raise InputError(f"none of the {len(ids)} training frames has a labelled Car", path=dataset.split_dir)
    digest = hashlib.sha256()
    images = images_sha256(dataset.image_path, ids)  # some 6 s for KITTI's 7,481 images
    for f in ids:
        digest.update(f"{f}\n".encode())
        digest.update(dataset.label_path(f).read_bytes())
        digest.update(dataset.calib_path(f).read_bytes())
        digest.update(images[f].encode())
    return digest.hexdigest(), sum(counts.values()), images


#: Steps whose artefacts another step trains from (part of the resume key).
_INPUTS = {"parts": (), "detector": (), "viewpoints": (), "occlusion": ("parts",)}


def _training_frames(dataset, frames, split_file) -> list[str]:
    """The frames to train on: of ``split_file``, ``frames`` (checked) or all labelled ones."""
    known = dataset.frame_ids()
    if split_file is not None:
        from wirescene.io.splits import read_split_file

        ids = read_split_file(split_file, known=known, what="labelled frame", where=dataset.split_dir)
    elif frames is not None:
        ids = list(dict.fromkeys(frames))
        unknown = [f for f in ids if f not in set(known)]
        if unknown:
            raise InputError(f"no labelled frame {unknown[0]}", path=dataset.split_dir)
    else:
        ids = known
    if not ids:
        raise InputError("no labelled frame to train on", path=dataset.split_dir)
    return ids


def _previous_steps(out: Path, resume: bool) -> dict:
    """The step records of an earlier run in ``out`` to resume from (empty: none); an
    :class:`InputError` for a directory that holds models but may not be written over."""
    manifest_path = out / MANIFEST_FILE
    if out.exists() and not out.is_dir():
        raise InputError("is a file, expected a models directory", path=out)
    held = [f for f in (MANIFEST_FILE, *ARTEFACTS.values()) if (out / f).exists()]
    if held and not resume:
        raise InputError(f"already holds models ({', '.join(held)}): continue with --resume or choose an empty "
                         "directory", path=out)
    if resume and held and not manifest_path.is_file():
        raise InputError(f"holds {held[0]} but no {MANIFEST_FILE}: not a directory of `train all`, nothing to resume",
                         path=out)
    return manifest_steps(out) if resume else {}


def manifest_steps(out: str | Path) -> dict:
    """``{step: record}`` of the manifest of the models directory ``out`` (``{}`` where it has
    none); an :class:`InputError` naming a manifest that cannot be read."""
    path = Path(out) / MANIFEST_FILE
    if not path.is_file():
        return {}
    steps = load_json(path, kind=MANIFEST_KIND, version=MANIFEST_VERSION).get("steps")
    return steps if isinstance(steps, dict) else {}


def _new_manifest(dataset, ids: list[str], cars: int, folds: dict[str, int], split_file, *,
                  drives: Mapping[str, str], mapping_dir: Path | None, images: dict[str, str]) -> dict:
    """The manifest of a run before its steps: data (``cars``: their labelled cars; ``images``:
    each frame's image SHA-256), split file and folds (grouped by ``drives``)."""
    data = {"kitti_root": str(Path(dataset.split_dir).resolve()), "frames": len(ids), "cars": cars,
            "frames_sha256": _frames_sha256(ids), "frame_ids": ids, "images_sha256": images}
    if split_file is not None:
        data["split_file"] = str(Path(split_file).resolve())
        data["split_file_sha256"] = file_sha256(split_file, what="split")
    fold_ids = sorted(set(folds.values()))
    fold_record = {"n_folds": len(fold_ids), "frames_with_known_drive": sum(f in drives for f in ids),
                   "devkit_mapping": None if mapping_dir is None else str(Path(mapping_dir).resolve()),
                   "frames_per_fold": {str(k): sum(1 for j in folds.values() if j == k) for k in fold_ids},
                   "fold_of": folds}
    # the packages and BLAS kernels: another CPU's kernels train files that differ in their last digits
    return {"wirescene": __version__, "environment": environment(), "complete": False, "data": data,
            "calibration_folds": fold_record, "artefacts": [], "shipped": [], "steps": {}}


@dataclass
class _Run:
    """One ``train all`` run: where it writes, what it trains on, and its steps."""

    out: Path
    kitti_root: object
    ids: list
    folds: dict
    opts: dict
    workers: int
    say: Callable[[str], None]
    wrap: Callable
    peak: _RunPeak = field(default_factory=_RunPeak)

    def write(self, manifest: dict) -> None:
        # this process's (MB), and at least each step's: a resumed run's steps kept were an earlier process's
        peaks = [self.peak.total(), *(record.get("peak_rss_mb") for record in manifest["steps"].values())]
        manifest["peak_rss_mb"] = max((mb for mb in peaks if mb is not None), default=None)
        save_json(self.out / MANIFEST_FILE, manifest, kind=MANIFEST_KIND, version=MANIFEST_VERSION)

    def path_of(self, step: str) -> Path:
        return self.out / ARTEFACTS[_ARTEFACT[step]]

    def step(self, step: str, key: dict, old: dict | None) -> dict:
        """The record of ``step``: the earlier run's where its key and file match, else trained now."""
        path = self.path_of(step)
        why = _why_not_kept(step, old, key, path) if old else None
        if old and not why:
            self.say(f"{step}: done in an earlier run, kept ({path.name})")
            return old
        if old:  # hours on a whole KITTI: say what changed
            self.say(f"{step}: the earlier run's record does not match ({why}): training again")
        self.say(f"{step}: training -> {path}")
        exact = self.peak.reset()
        t0 = time.perf_counter()
        record = {"done": False, "key": key, "artefact": path.name}
        getattr(self, f"run_{step}")(record)
        record.update(done=True, sha256=file_sha256(path), seconds=round(time.perf_counter() - t0, 1),
                      peak_rss_mb=_peak_memory_mb(), peak_rss_of="step" if exact else "process so far",
                      finished=datetime.now(timezone.utc).isoformat(timespec="seconds"))
        self.say(f"{step}: {step_cost(record)}")
        return record

    def run_parts(self, record: dict) -> None:
        from wirescene.training.parts import train_part_detector

        _, report = train_part_detector(self.path_of("parts"), kitti_root=self.kitti_root, frames=self.ids,
                                        calibration_folds=self.folds, progress=self.say, **self.opts["parts"])
        record["train_accuracy"] = float(report["train_acc"])
        if "calibration" in report:  # a held-out loss is None where no fold holds parts to score
            record["calibration"] = {k: None if v is None else float(v) for k, v in report["calibration"].items()}

    def run_detector(self, record: dict) -> None:
        from wirescene.training.kitti_detector import train_detector_bank_kitti

        bank_opts = dict(self.opts["detector"])
        threshold = bank_opts.pop("threshold", 0.5)
        seed = bank_opts.pop("seed", 0)
        given = bank_opts.pop("calibration", None)
        if given is None:
            calib = heldout_bank_calibration(self.kitti_root, self.folds, seed=seed, workers=self.workers,
                                             progress=self.say, **bank_opts)
        else:  # a Platt fit of the same recipe's fold banks made elsewhere: saves their trainings
            calib = calibration_record(given, source="given")
        record["calibration"] = calib
        bank, _ = train_detector_bank_kitti(self.path_of("detector"), self.kitti_root, frames=self.ids, seed=seed,
                                            calibration=[calib[k] for k in "abc" if k in calib], threshold=threshold,
                                            workers=self.workers, progress=self.say, **bank_opts)
        record["detectors"] = len(bank)
        CACHE.clear()  # the frames' images and pyramids are not needed by the steps after

    def run_viewpoints(self, record: dict) -> None:
        from wirescene.io.kitti import KittiDataset
        from wirescene.predetect.viewpoint_classifier import train_on_kitti

        classifier = train_on_kitti(KittiDataset(self.kitti_root), self.ids, **self.opts["viewpoints"])
        classifier.save(self.path_of("viewpoints"))
        record["crops"] = int(classifier.meta["n"])

    def run_occlusion(self, record: dict) -> None:
        from wirescene.infer.occluded_score import save_occluded_score
        from wirescene.parts.detector import PartDetector
        from wirescene.training.occlusion import calibrate_occluded_score

        detector = PartDetector.load(self.path_of("parts"))
        result = calibrate_occluded_score(detector=detector, progress=lambda it: self.wrap(it, "occlusion scenes"),
                                          **self.opts["occlusion"])
        save_occluded_score(self.path_of("occlusion"), result)
        record["c"] = result["c"]
        self.say(f"occlusion: c = {result['c']} ({result['n_cars']} cars)")


#: How :func:`_why_not_kept` names the parts of a step's resume key that changed.
_KEY_WORDS = {"data.kitti_root": "the KITTI root", "data.frames_sha256": "the frames",
              "data.files_sha256": "the frames' label, calibration or image files", "data.n_folds": "the folds",
              "data.folds_sha256": "the folds", "wirescene": "the wirescene version"}


def _why_not_kept(step: str, old: dict, key: dict, path: Path) -> str | None:
    """Why the earlier run's record ``old`` of ``step`` cannot be kept, in words (None: it can):
    unfinished, its file missing or changed, or its resume key other than ``key``, naming what
    changed. Keys equal but for options that one sets to their default and the other leaves out
    train the same.

    Examples
    --------
    >>> key = {"data": {"frames_sha256": "a"}, "options": {}, "wirescene": "1", "inputs": {}}
    >>> old = {"done": True, "key": {**key, "data": {"frames_sha256": "b"}, "wirescene": "0"}}
    >>> _why_not_kept("viewpoints", old, key, Path("missing.npz"))
    'the frames, the wirescene version'
    """
    from wirescene.eval.records import config_difference

    if not old.get("done"):
        return "unfinished"
    if not isinstance(old.get("key"), dict):
        return "no key"
    defaults = _normalised(step_options()[step])

    def chosen(k: dict) -> dict:
        options = k.get("options") if isinstance(k.get("options"), dict) else {}
        return {**k, "options": {n: v for n, v in options.items() if n not in defaults or v != defaults[n]}}

    changed = config_difference(chosen(old["key"]), chosen(key))
    if changed:
        words = [_KEY_WORDS.get(c) or (f"option {c.split('.', 1)[1]}" if c.startswith("options.")
                                       else f"the {c.split('.', 1)[1]} step's file it trains from"
                                       if c.startswith("inputs.") else c) for c in changed]
        return ", ".join(dict.fromkeys(words))
    if not path.is_file():
        return f"{path.name} missing"
    if file_sha256(path) != old.get("sha256"):
        return f"{path.name} changed since"
    return None


def _normalised(value):
    """``value`` as JSON would give it back (tuples as lists), so that it compares equal
    to the stored record."""
    import json

    return json.loads(json.dumps(value, default=str))
