"""Option types and output checks shared by every command: numbers are checked for
range and finiteness as they are parsed, and outputs for writability before any work
starts, so that a long run never fails at its end on a bad path."""

from __future__ import annotations

import functools
import math
import os
import sys
from pathlib import Path
from typing import Mapping

import click

from wirescene.core.validate import creatable_problem, empty_path_problem, output_dir_problem

#: Counts that must be at least 1 (particles, samples, workers, scenes).
POSITIVE = click.IntRange(min=1)
#: Counts and seeds that may be 0 (iterations, prune-after, seeds).
NON_NEGATIVE = click.IntRange(min=0)


class FiniteFloat(click.ParamType):
    """A finite float, at least ``min`` (above it with ``strict``; 0 too with ``zero``, what 0
    means) and at most ``max`` (NaN and infinities refused)."""

    name = "float"

    def __init__(self, min: float | None = None, *, strict: bool = False, max: float | None = None,
                 zero: str | None = None):
        self.min = min
        self.strict = strict
        self.max = max
        self.zero = zero

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not finite", param, ctx)
        if self.zero and number == 0:
            return number
        if self.min is not None and (number <= self.min if self.strict else number < self.min):
            self.fail(f"{number:g} is {'not above' if self.strict else 'below the minimum'} {self.min:g}"
                      + (f" (0: {self.zero})" if self.zero else ""), param, ctx)
        if self.max is not None and number > self.max:
            self.fail(f"{number:g} is above the maximum {self.max:g}", param, ctx)
        return number


NON_NEGATIVE_FLOAT = FiniteFloat(min=0.0)
POSITIVE_FLOAT = FiniteFloat(min=0.0, strict=True)


class NonEmptyPath(click.Path):
    """``click.Path`` that refuses an empty (or blank) value, the type of every path option
    and argument of the CLI: click reads ``""`` as ``Path(".")``, so that an unset shell
    variable (``--out "$OUT"``) would write into the current directory (or read it), exit 0
    (:func:`wirescene.core.validate.empty_path_problem`). ``directory``: the path names a
    directory (the hint of the message; default: where ``file_okay`` is false).

    Examples
    --------
    >>> NonEmptyPath(file_okay=False).convert("", None, None)
    Traceback (most recent call last):
    ...
    click.exceptions.BadParameter: empty path (give a directory, e.g. '.')
    >>> NonEmptyPath(path_type=Path).convert("out.json", None, None) == Path("out.json")
    True
    """

    def __init__(self, *, directory: bool | None = None, **kwargs):
        super().__init__(**kwargs)
        self.directory = not self.file_okay if directory is None else directory

    def convert(self, value, param, ctx):
        problem = empty_path_problem(value, directory=self.directory)
        if problem:
            self.fail(problem, param, ctx)
        return super().convert(value, param, ctx)


def detections_spec(ctx, param, value: str) -> str:
    """``--detections``' callback: ``gt``, ``bank`` or a directory, never an empty value (an
    unset variable, ``--detections "$DETS"``, would read the current directory).

    Examples
    --------
    >>> detections_spec(None, None, "bank")
    'bank'
    >>> detections_spec(None, None, "")
    Traceback (most recent call last):
    ...
    click.exceptions.BadParameter: empty path (give a directory, e.g. '.')
    """
    problem = empty_path_problem(value)
    if problem:
        raise click.BadParameter(problem, ctx=ctx, param=param)
    return value


def min_score_option(f):
    """``--min-score FLOAT``: the score floor of boxes read from files (``--detections FILE``
    of ``fit``, ``--detections DIR`` of ``eval`` and ``predict``; :func:`refuse_min_score`
    refuses it with other boxes)."""
    return click.option("--min-score", type=FiniteFloat(), default=None,
                        help="With --detections FILE/DIR: fit only the boxes scoring at or above this (score >= "
                             "FLOAT; default: every box); a file with none left is an image without cars. A "
                             "detector's raw output (COCO-style result files keep ~100 boxes an image, most at low "
                             "scores) costs the fit some 3.5 s a frame of 50 boxes with coarse and 38 s with full, "
                             "and each low-score box fitted is a false 3D car.")(f)


def refuse_min_score(min_score: float | None, detections, *, needs: str = "--detections DIR") -> None:
    """A ``click.UsageError`` where ``--min-score`` is given without boxes from files
    (:func:`wirescene.eval.sources.min_score_problem`: with ``detections`` ``"gt"``, or
    ``"bank"`` / None, our own pre-detection); ``needs``: the option that reads files.

    Examples
    --------
    >>> refuse_min_score(None, "gt"), refuse_min_score(0.5, "dets")  # no floor, or boxes from files: nothing
    (None, None)
    >>> refuse_min_score(0.5, "gt")
    Traceback (most recent call last):
    ...
    click.exceptions.UsageError: --min-score needs --detections DIR: label boxes ('gt') are all fitted
    >>> refuse_min_score(0.0, None, needs="--detections FILE")
    Traceback (most recent call last):
    ...
    click.exceptions.UsageError: --min-score needs --detections FILE: our own pre-detection's floor is its detection \
threshold (--detection-threshold)
    """
    from wirescene.eval.sources import min_score_problem

    problem = min_score_problem(min_score, detections if detections is None else str(detections))
    if problem:
        hint = " (--detection-threshold)" if problem.startswith("our own") else ""
        raise click.UsageError(f"--min-score needs {needs}: {problem}{hint}")


def _check_creatable(path: Path, option: str) -> None:
    """The directories above ``path`` exist or can be created and written."""
    problem = creatable_problem(path)
    if problem:
        raise click.BadParameter(problem, param_hint=option)


def check_output_file(path: Path | None, option: str) -> None:
    """``path`` can be written as a file (checked before any work starts)."""
    if path is None:
        return
    path = Path(path)
    if path.is_dir():
        raise click.BadParameter(f"{path} is a directory, expected a file path", param_hint=option)
    if path.exists() and not os.access(path, os.W_OK):
        raise click.BadParameter(f"{path} is not writable", param_hint=option)
    _check_creatable(path, option)


def check_picture_file(path: Path | None, option: str) -> None:
    """``path`` can be written as a file (:func:`check_output_file`) and its suffix, if it has
    one, names a format matplotlib writes (``.png``, ``.pdf``, ``.svg``, ...): the picture of
    a ``.txt`` or ``.json`` path would be a PNG under a name that says otherwise."""
    if path is None:
        return
    from matplotlib.backend_bases import FigureCanvasBase

    suffix = Path(path).suffix
    if suffix and suffix[1:].lower() not in FigureCanvasBase.get_supported_filetypes():
        raise click.BadParameter(f"{path}: {suffix} is not a picture format (.png, .pdf, .svg, ...)", param_hint=option)
    check_output_file(path, option)


#: ``click.Context.meta`` key (shared by nested contexts): what the running command keeps for its --resume.
KEPT_ON_RESUME = "wirescene.kept_on_resume"


def keeps_on_resume(what: str) -> None:
    """Say, after a refusal of the machine that stops the running command, that ``what`` stays
    for its ``--resume`` (the command group's one line)."""
    click.get_current_context().meta[KEPT_ON_RESUME] = f"; {what} stay (--resume goes on from them)"


def check_output_dir(path: Path | str | None, option: str) -> None:
    """``path`` is (or can be created as) a writable directory."""
    if path is None:
        return
    problem = output_dir_problem(path)
    if problem:
        raise click.BadParameter(problem, param_hint=option)


def parse_frames(value: str | None, known: list[str], option: str = "--frames", *, where,
                 what: str = "frame") -> list[str] | None:
    """Comma-separated frame ids, each known and listed once; None keeps all frames. An unknown
    id is ``no {what} ID in {where}``, the words of ``--split-file``'s
    (:func:`wirescene.io.splits.read_split_file`): which frames count (labelled ones, images,
    records) and the folder they were looked for in.

    Examples
    --------
    >>> parse_frames("000010, 000002", ["000002", "000010"], where="kitti/training")
    ['000010', '000002']
    >>> parse_frames("000099", ["000002", "000010"], where="kitti/training", what="labelled frame")
    Traceback (most recent call last):
    ...
    click.exceptions.BadParameter: no labelled frame 000099 in kitti/training
    """
    if value is None:
        return None
    frames = [f.strip() for f in value.split(",") if f.strip()]
    if not frames:
        raise click.BadParameter("no frame id given", param_hint=option)
    seen = set()
    for f in frames:
        if f in seen:
            raise click.BadParameter(f"frame {f} is listed twice", param_hint=option)
        seen.add(f)
    unknown = [f for f in frames if f not in set(known)]
    if unknown:
        more = f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else ""
        raise click.BadParameter(f"no {what} {unknown[0]}{more} in {where}", param_hint=option)
    return frames


#: How a message names the KITTI root of a ``train`` command, which takes it in either form (:func:`kitti_root_params`).
KITTI_ROOT_FORMS = "a KITTI root (KITTI_ROOT or --kitti-root)"


def same_path(a, b) -> bool:
    """Whether paths ``a`` and ``b`` name one file or folder: through a symbolic link or ``./``
    too (``os.path.samefile``), else (one missing) by their resolved paths.

    Examples
    --------
    >>> same_path("./x", "x"), same_path("x", "y")
    (True, False)
    """
    try:
        return os.path.samefile(a, b)
    except OSError:  # one missing (or unreadable): its own check names it
        return os.path.realpath(a) == os.path.realpath(b)


def kitti_root_params(help: str, *, type: click.ParamType, required: bool = False):
    """The labelled KITTI root of a ``train`` command, taken in either form: the ``KITTI_ROOT``
    argument (``train all ROOT``) or ``--kitti-root DIR`` (``train parts --kitti-root ROOT``), so
    that no command refuses the other's spelling. The command receives it as ``kitti_root``.

    Parameters
    ----------
    help : str
        The help of ``--kitti-root``.
    type : click.ParamType
        The type of both forms (the command's checks of the root).
    required : bool
        The command needs a root: neither form given is a usage error naming both, and the usage
        line shows ``KITTI_ROOT`` without the brackets of an optional argument.

    Returns
    -------
    callable
        A decorator of a click command function taking ``kitti_root``; both forms naming two
        different roots (not one through a link, :func:`same_path`) is a usage error.
    """
    def decorate(f):
        @functools.wraps(f)
        def command(*args, kitti_root=None, kitti_root_option=None, **kwargs):
            if kitti_root is not None and kitti_root_option is not None and not same_path(kitti_root,
                                                                                            kitti_root_option):
                raise click.UsageError(f"KITTI_ROOT ({kitti_root}) and --kitti-root ({kitti_root_option}) name two "
                                       "roots: give one")
            root = kitti_root if kitti_root is not None else kitti_root_option
            if root is None and required:
                raise click.UsageError("the KITTI root is missing: give it as KITTI_ROOT or --kitti-root DIR")
            return f(*args, kitti_root=root, **kwargs)

        command = click.option("--kitti-root", "kitti_root_option", type=type, default=None,
                               help=f"{help} The KITTI_ROOT argument gives it too.")(command)
        # click brackets an argument it may go without; one of the two forms is needed (checked above)
        return click.argument("kitti_root", type=type, required=False,
                              metavar="KITTI_ROOT" if required else None)(command)

    return decorate


def split_file_option(f):
    """``--split-file FILE``: the frames of a run from a KITTI ``ImageSets`` file."""
    return click.option("--split-file", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
                        help="Frames listed in this file, one id a line (KITTI's ImageSets format, e.g. "
                             "ImageSets/val.txt); instead of --frames.")(f)


def split_option(default: str = "training", *, calib: bool = True):
    """``--split NAME``: the split folder of ``KITTI_ROOT`` a command reads (:func:`kitti_dataset`);
    ``calib``: the command takes :func:`calib_option` too."""
    plain = ", as is any --split with a plain folder of frames read with --calib" if calib else ""
    return click.option("--split", default=default, show_default=True,
                        help="The split folder under KITTI_ROOT (a split folder given as KITTI_ROOT is read as it "
                             f"is: a --split naming another is refused there{plain}).")


#: The forms of a calibration file the commands read (:func:`wirescene.core.camera.read_calibration`).
CALIB_FORMS = ("a KITTI calibration file (P2 is used), or a text file of the 9 numbers of the intrinsics K or the 12 "
               "of the projection P")


def calib_option(f):
    """``--calib FILE``: one calibration for every frame of ``KITTI_ROOT``
    (:class:`~wirescene.io.kitti.KittiDataset` ``calib``), which may then be a plain folder of images."""
    return click.option("--calib", type=NonEmptyPath(path_type=Path), default=None,
                        help="One calibration for every image (a camera other than KITTI's whose frames share it): "
                             f"{CALIB_FORMS}. No calib/ folder is then read, and KITTI_ROOT may be a plain folder of "
                             "the images (.png, .jpg or .jpeg; frame ids are their names without the suffix).")(f)


def kitti_dataset(kitti_root: Path, split: str, calib: Path | None, *, absolute: bool = False):
    """``KittiDataset(kitti_root, split=split, calib=calib)`` of a command of :func:`split_option` and
    :func:`calib_option`: an ``InputError`` naming a plain folder of frames (read with ``--calib``, no
    ``image_2/``), or a split folder itself (``ROOT/training``, its ``image_2/`` read) of another name
    (as given, or as its link's target), where ``--split`` was given on the command line, which would be
    ignored there (:func:`wirescene.io.kitti.given_split_problem`, the check of ``KittiDataset``'s own
    ``split``); at its default it is no error. ``absolute``: the dataset reads the root's absolute path
    (for workers elsewhere), the checks and messages the path given."""
    from click.core import ParameterSource

    from wirescene.core.errors import InputError
    from wirescene.io.kitti import KittiDataset, given_split_problem

    root = Path(kitti_root)
    dataset = KittiDataset.of_default_split(root.resolve() if absolute else root, split, calib=calib)
    source = click.get_current_context().get_parameter_source("split")
    if source in (ParameterSource.COMMANDLINE, ParameterSource.ENVIRONMENT):
        problem = given_split_problem(dataset, split, root=root, names=("--split", "--calib"))
        if problem:
            raise InputError(problem, path=kitti_root)
    return dataset


def ap_draws_option(f):
    """``--draws N``: bootstrap draws of the KITTI APs' intervals over drives (0: none)."""
    from wirescene.eval.intervals import MAX_BOOT_AP, N_BOOT_AP

    return click.option("--draws", type=click.IntRange(min=0, max=MAX_BOOT_AP), default=N_BOOT_AP, show_default=True,
                        help=f"Bootstrap draws of the moderate KITTI APs' 90% interval over drives (0: none; each "
                             f"draw evaluates the drawn frames again; at most {MAX_BOOT_AP:,}).")(f)


def drive_map_option(purpose: str = "the held-out calibrations' folds group the frames by recording drive"):
    """``--drive-map DIR``: the KITTI devkit's mapping files, grouping frames by drive for ``purpose``."""
    return click.option("--drive-map", "drive_mapping", type=NonEmptyPath(file_okay=False, path_type=Path),
                        default=None,
                        help=f"KITTI devkit mapping directory (train_rand.txt, train_mapping.txt): {purpose} "
                             "(default: mapping/, devkit/mapping/ or devkit_object/mapping/ under the KITTI root when "
                             "there, else the drives of the shared frames only; other frames are each their own "
                             "group).")


def interval_drives(split_dir: Path, mapping: Path | None = None) -> dict[str, str]:
    """``{frame: drive}`` the bootstrap intervals over drives draw by: the shared frames' drives and
    a devkit mapping (``mapping``, or found under the KITTI root above ``split_dir``); none for
    synthetic scenes unless a mapping is given (their ids are KITTI's too: each is drawn alone)."""
    from wirescene.io.folds import drive_map
    from wirescene.io.wireframes import wireframe_gt_dir

    if mapping is None and wireframe_gt_dir(split_dir).is_dir():
        return {}
    return drive_map(Path(split_dir).parent, mapping=mapping)[0]


def read_drive_map(dataset, mapping: Path | None) -> tuple[dict[str, str], Path | None]:
    """``({frame: drive}, mapping directory or None)`` for the held-out calibrations of a training
    on ``dataset`` (a :class:`~wirescene.io.kitti.KittiDataset`, given as ROOT or ROOT/training):
    ``--drive-map`` or the devkit mapping found under the root; says which directory groups the frames."""
    from wirescene.io.folds import drive_map

    drives, mapping_dir = drive_map(dataset.base_dir, mapping=mapping)
    if mapping_dir is not None:
        click.echo(f"frames grouped by drive with {mapping_dir}")
    return drives, mapping_dir


def select_frames(frames: str | None, split_file: Path | None, known: list[str], *, where, what: str = "labelled frame",
                  option: str = "--frames") -> list[str] | None:
    """The frames chosen by ``--frames`` (comma-separated) or ``--split-file`` (not both),
    each one of ``known``, an unknown one refused in the same words by either (``no {what}
    ID in {where}``); None: neither was given (all frames)."""
    if frames is not None and split_file is not None:
        raise click.UsageError(f"{option} and --split-file both choose the frames: give one")
    if split_file is not None:
        from wirescene.io.splits import read_split_file

        return read_split_file(split_file, known=known, what=what, where=where)
    return parse_frames(frames, known, option, where=where, what=what)


def refuse_given(options: Mapping[str, object], *, needs: str | None = None, why: str | None = None) -> None:
    """A ``click.UsageError`` naming every option of ``{"--name": given}`` given (a true value)
    where it would be ignored: ``--a / --b need NEEDS`` (``needs``), or ``--a / --b: WHY``;
    nothing when none is given.

    Examples
    --------
    >>> refuse_given({"--n-aug": False, "--heldout": 0}, needs="--n-views")  # none given: nothing
    >>> refuse_given({"--n-aug": True}, needs="--n-views")
    Traceback (most recent call last):
    ...
    click.exceptions.UsageError: --n-aug needs --n-views
    """
    given = [name for name, value in options.items() if value]
    if given:
        listed = " / ".join(given)
        raise click.UsageError(f"{listed} need{'s' if len(given) == 1 else ''} {needs}" if needs is not None
                               else f"{listed}: {why}")


def workers_option(what: str = "fitting frames"):
    """``--workers N``: processes doing ``what`` in parallel (None: every core this process may
    use, :func:`workers_count`)."""
    from wirescene.core.validate import MAX_WORKERS

    return click.option("--workers", type=click.IntRange(min=1, max=MAX_WORKERS), default=None,
                        help=f"Processes {what} in parallel (default: the cores this process may use; at most "
                             f"{MAX_WORKERS}, the larger of 64 and those cores: each takes some 440 MB).")


def particles_option(f):
    """``--particles N``: scene particles the coarse stage hands the fine one (``LiftingOptions.n_particles``)."""
    from wirescene.core.settings import stage_field
    from wirescene.lift import MAX_HYPOTHESES, LiftingOptions

    options = LiftingOptions()
    planes = len(options.plane_grid()[0])
    return click.option("--particles", type=field_type(stage_field(LiftingOptions, "n_particles")),
                        default=options.n_particles, show_default=True,
                        help=f"Scene particles kept by the coarse stage: at most one per plane of its grid "
                             f"({planes} planes with the default steps), their number times --samples at most "
                             f"{MAX_HYPOTHESES:,}.")(f)


def workers_count(workers: int | None) -> int:
    """The processes of ``--workers`` (None: every core this process may use,
    :func:`~wirescene.core.workers.usable_cores`)."""
    from wirescene.core.workers import usable_cores

    return workers or usable_cores()


def models_option(f):
    """``--models MODELS_DIR``: trained artefacts that replace the shipped ones."""
    return click.option("--models", "models", type=NonEmptyPath(directory=True, path_type=Path), default=None,
                        help="Models directory (`wirescene train all --out`): its parts_model.npz, detector_bank.npz, "
                             "viewpoint_classifier.npz, score_calibration.json, shape_model.npz and occlusion.json "
                             "replace the shipped ones; what it lacks stays shipped.")(f)


def say_models(models, *, replaced=()):
    """``models`` (a :class:`~wirescene.core.resources.Models`), said on standard error unless
    they are the shipped ones; ``replaced``: the artefacts a file option gave instead."""
    if models.root is not None:
        click.echo(f"wirescene: {models.describe(replaced=replaced)}", err=True)
    return models


def progress_bar(items, desc: str, *, unit: str = "it", total: int | None = None):
    """``items`` under a tqdm bar on standard error, gone once done; none where standard error is
    no terminal (``2> log``: its redrawn lines would fill the file with carriage returns) or where
    ``TQDM_DISABLE`` is set (tqdm's own switch)."""
    from tqdm import tqdm

    # tqdm reads TQDM_DISABLE as a default, which the argument overrides (and before 4.66 not at all): read here
    disable = True if os.environ.get("TQDM_DISABLE") else None
    return tqdm(items, desc=desc, unit=unit, total=total, leave=False, file=sys.stderr, disable=disable)


def say_off_centre_image(image, camera) -> None:
    """``wirescene: warning: IMAGE: problem`` on standard error where ``camera`` looks made for
    another size than its image's (:func:`wirescene.api.off_centre_message`, what the API
    warns): the commands of one image (``fit``, ``gt``) say it, not refuse it (a calibration
    carries no image size); ``image``: the image file."""
    from wirescene.api import off_centre_message
    from wirescene.eval.runner import notify_stderr

    message = off_centre_message(camera, image)
    if message is not None:
        notify_stderr(f"warning: {message}")


def say_off_centre_frames(dataset, frame_ids, *, images: bool = False, before: str = "any training") -> None:
    """Check the calibrations and image headers (``images``: the images, decoded, as a command
    that reads them all asks) of ``frame_ids`` of ``dataset``
    (:meth:`~wirescene.io.kitti.KittiDataset.check_frames`: an ``InputError`` naming the first
    missing or malformed one, before any work) and say in one line on standard error, once for
    the run, those whose calibration looks made for another image size, as ``eval`` and
    ``predict`` do (:func:`wirescene.eval.runner.say_off_centre`); ``before``: the work the
    decoding goes before, as a long one says it."""
    from wirescene.eval.runner import SAY_DECODING, notify_stderr, say_off_centre

    if images and len(frame_ids) >= SAY_DECODING:
        notify_stderr(f"decoding the {len(frame_ids)} images before {before} (a corrupt one refused now)")
    say_off_centre(dataset.check_frames(frame_ids, images=images), len(frame_ids), notify_stderr)


def field_type(field) -> click.ParamType:
    """The click type of a number field of stage options (:func:`wirescene.core.settings.option`,
    :func:`~wirescene.core.settings.bounded`): its kind and bounds, as ``--set`` checks them."""
    low, high = field.metadata.get("minimum"), field.metadata.get("maximum")
    if isinstance(field.default, int) and not isinstance(field.default, bool):
        return click.IntRange(min=None if low is None else int(low), max=None if high is None else int(high))
    return FiniteFloat(min=low, max=high, zero=field.metadata.get("zero"))


def stage_options(cls, scope: str):
    """Click options for the fields of stage options ``cls`` declared with
    :func:`wirescene.core.settings.option`: ``--NAME`` (booleans ``--NAME/--no-NAME``),
    each parsed into the parameter ``SCOPE__FIELD`` with default None (the dataclass's
    default, shown in the help). :func:`stage_settings` turns them into settings."""
    from wirescene.core.settings import exposed_fields, field_default

    def decorate(f):
        for field, name, text in reversed(exposed_fields(cls)):
            default = field_default(field)
            param = f"{scope}__{field.name}"
            if isinstance(default, bool):
                flag, kind = f"--{name}/--no-{name}", None
            else:
                flag, kind = f"--{name}", field_type(field)
            f = click.option(flag, param, type=kind, default=None, help=f"{text} Default: {default}.")(f)
        return f

    return decorate


def settings_option(f):
    """``--set STAGE.FIELD=VALUE``: any option of a fitting stage, by the same names as the API's ``settings``."""
    return click.option("--set", "settings", multiple=True, metavar="STAGE.FIELD=VALUE",
                        help="Set any field of the stage options (stages lifting, inference, predetect; e.g. "
                             "inference.polish_samples=12); repeatable; the named options above win.")(f)


def stage_settings(kwargs: dict, assignments: tuple[str, ...] = ()) -> dict[str, object]:
    """``{"STAGE.FIELD": value}`` of ``--set`` items and of the :func:`stage_options`
    parameters in ``kwargs`` that were given (popped from ``kwargs``)."""
    from wirescene.core.settings import parse_assignment

    out: dict[str, object] = {}
    for item in assignments:
        try:
            stage, key, text = parse_assignment(item)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--set") from None
        out[f"{stage}.{key}"] = text
    for param in [k for k in kwargs if "__" in k]:
        value = kwargs.pop(param)
        if value is not None:
            stage, _, key = param.partition("__")
            out[f"{stage}.{key}"] = value
    return out
