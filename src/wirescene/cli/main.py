"""The ``wirescene`` command: every stage composes into one CLI, each owning its options."""

from __future__ import annotations

import errno
import json
import signal
import sys
import threading
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack, contextmanager
from importlib import resources
from pathlib import Path

import click
import numpy as np

from wirescene.cli.options import (
    CALIB_FORMS,
    KEPT_ON_RESUME,
    NON_NEGATIVE,
    NON_NEGATIVE_FLOAT,
    NonEmptyPath,
    ap_draws_option,
    calib_option,
    check_output_dir,
    check_output_file,
    check_picture_file,
    detections_spec,
    drive_map_option,
    interval_drives,
    keeps_on_resume,
    kitti_dataset,
    min_score_option,
    models_option,
    particles_option,
    progress_bar,
    refuse_min_score,
    say_models,
    say_off_centre_image,
    select_frames,
    settings_option,
    split_file_option,
    split_option,
    stage_options,
    stage_settings,
    workers_count,
    workers_option,
)
from wirescene.core.errors import InputError, WiresceneError
from wirescene.core.labels import CAR_TYPES
from wirescene.core.version import __version__
from wirescene.eval.seeds import MAX_SEEDS
from wirescene.fitting.variants import DEFAULT_VARIANT
from wirescene.lift import MAX_PARTICLES


def _usage_message(exc: click.UsageError) -> str:
    """``--option: problem`` for a bad option value, click's message otherwise."""
    if isinstance(exc, click.BadParameter):
        hint = exc.param_hint
        if hint is None and exc.param is not None:
            if isinstance(exc.param, click.Argument):
                hint = exc.param.human_readable_name  # IMAGE, as the usage line spells it
            else:
                hint = "/".join(getattr(exc.param, "opts", None) or [exc.param.name or "?"])
        if isinstance(hint, (list, tuple)):
            hint = "/".join(hint)
        if hint:
            # click leaves a missing parameter's message empty (its text is built in format_message)
            problem = "missing (required)" if isinstance(exc, click.MissingParameter) else exc.message
            return f"{str(hint).strip(chr(39) + chr(34))}: {problem}"
    return " ".join(exc.format_message().split())


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a scheduler's stop) or SIGHUP (the terminal of the session closed, a
    dropped SSH connection), raised in the main thread as Ctrl-C raises ``KeyboardInterrupt``:
    a subclass of it, so that every cleanup Ctrl-C runs (staging folders removed, worker
    processes stopped) runs for it too. ``signum``: the signal."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__()
        self.signum = int(signum)


#: The signals that stop a run: Ctrl-C (SIGINT), SIGTERM and, where the system has it, SIGHUP
#: (ignored under ``nohup``, and then left ignored).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM) + ((signal.SIGHUP,) if hasattr(signal, "SIGHUP") else ())


class _Stopping:
    """Whether the command has reached its end (its result or an exception's exit code in
    hand), after which a stop signal changes nothing; set by :meth:`_Group.invoke`."""

    exiting = False


def _on_stop_signal(signum, frame) -> None:
    """The CLI's handler of :data:`STOP_SIGNALS`: the run stops once. Every later stop
    signal is ignored, so that no second Ctrl-C cuts the cleanup short, lands outside the
    handled region (click's "Aborted!" and exit 1) or in the interpreter's exit (where
    Python has put back the default action and the process dies of it, exit -2); one that
    comes once the command has its exit code in hand raises nothing."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    if not _Stopping.exiting:
        raise KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


@contextmanager
def _stop_signals(*, process: bool):
    """Handle :data:`STOP_SIGNALS` by :func:`_on_stop_signal` while a command runs (those a
    parent ignores, as a shell does for a job in the background, stay ignored). ``process``:
    the command is this process's (the console script), whose interpreter then exits with
    them ignored; otherwise (a call from Python, a test's) the handlers before are put back."""
    if threading.current_thread() is not threading.main_thread():  # only the main thread may set handlers
        yield
        return
    before = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for s, handler in before.items():
        if handler is not signal.SIG_IGN:
            signal.signal(s, _on_stop_signal)
    _Stopping.exiting = False
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, signal.SIG_IGN if process else signal.SIG_DFL if handler is None else handler)
        if not process:
            _Stopping.exiting = False


# What the machine refused a write or a read (a full disk or quota, a read-only or unreadable place, a failing
# device, too many open files, a path longer than the file system takes): one line, exit code 1, as out of memory.
_MACHINE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO,
                             errno.EMFILE, errno.ENFILE, errno.ENAMETOOLONG})


class _Group(click.Group):
    """Every refused input ends the same way: one line ``wirescene: error: WHAT: problem``
    on standard error and exit code 2, without a traceback (typed errors of the package,
    bad option values and usage errors alike); running out of memory (or a worker process
    stopped by the system), a full disk or a place that refuses a write one line too, exit
    code 1; Ctrl-C ends with exit code 130, SIGTERM with 143 and SIGHUP with 129 (128 + the
    signal), each after the same cleanup, once, whenever it comes (:func:`_on_stop_signal`)."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, *, console: bool = False,
             **extra):
        # console: the process is this command's (:func:`console_main`); a call from Python (a notebook's, a
        # test's) gets its handlers back afterwards
        with _stop_signals(process=console):
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)

    def invoke(self, ctx):
        # Each branch's first statement, before any call (where Python runs signal handlers), marks
        # the exit as decided: a stop signal from there on is ignored rather than raised in it.
        try:
            result = super().invoke(ctx)
            _Stopping.exiting = True
            return result
        except WiresceneError as exc:
            _Stopping.exiting = True
            click.echo(f"wirescene: error: {exc}", err=True)
            sys.exit(2)
        except click.UsageError as exc:
            _Stopping.exiting = True
            click.echo(f"wirescene: error: {_usage_message(exc)}", err=True)
            sys.exit(2)
        except click.ClickException as exc:  # e.g. an unreachable --dask scheduler, a failed write of `synth`
            _Stopping.exiting = True
            click.echo(f"wirescene: error: {' '.join(exc.format_message().split())}", err=True)
            sys.exit(2)
        except (MemoryError, BrokenProcessPool) as exc:  # a request the machine cannot hold: a line, no traceback
            _Stopping.exiting = True
            what = ("a worker process was stopped (by the system, for memory?)" if isinstance(exc, BrokenProcessPool)
                    else f"out of memory ({' '.join(str(exc).split()) or 'MemoryError'})")
            click.echo(f"wirescene: error: {what}; ask for less (fewer --samples or --workers, --upsample 1, a "
                       "larger --smallest-car) or use a larger machine; frames an --out or --predictions folder holds "
                       "stay (remove it to run with other settings)", err=True)
            sys.exit(1)
        except OSError as exc:
            if exc.errno not in _MACHINE_ERRNOS:  # a bug's OSError keeps its traceback
                raise
            _Stopping.exiting = True
            where = f"{exc.filename}: " if exc.filename else ""
            kept = ctx.meta.get(KEPT_ON_RESUME, "")  # set by the command that runs (a nested group's too)
            click.echo(f"wirescene: error: {where}{exc.strerror or exc}{kept}", err=True)
            sys.exit(1)
        except KeyboardInterrupt as exc:  # the shell's convention (128 + the signal), not click's "Aborted!" and 1
            _Stopping.exiting = True
            signum = exc.signum if isinstance(exc, Terminated) else signal.SIGINT
            said = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated"}.get(signum, "hung up")
            # what a run of hours has written stays for its --resume: said, as after a full disk
            click.echo(f"wirescene: {said}{ctx.meta.get(KEPT_ON_RESUME, '')}", err=True)
            sys.exit(128 + signum)


@click.group(cls=_Group)
@click.version_option(__version__, prog_name="wirescene")
def main():
    """Fine-grained 3D street-scene understanding from a single image."""


def sample_root() -> Path:
    """The KITTI-layout sample bundled with the package."""
    return Path(str(resources.files("wirescene") / "data" / "sample" / "kitti"))


def _frame_workers(workers: int | None, device: str) -> int:
    """Processes fitting frames: ``workers`` (None: the usable cores), or one on a CUDA device,
    said on stderr when that reduces them (forked processes cannot share the CUDA state)."""
    n = workers_count(workers)
    if device.startswith("cuda") and n > 1:
        click.echo(f"wirescene: --device {device} fits frames in one process, not {n} (the GPU is the parallelism)",
                   err=True)
        return 1
    return n


def _parallel(workers: int | None, frame_ids: list[str] | None, dask_address: str | None) -> bool:
    """Whether frames will be fitted by several processes (local workers or Dask)."""
    several_frames = frame_ids is None or len(frame_ids) > 1  # None: every frame of the split
    return several_frames and (dask_address is not None or workers_count(workers) > 1)


def _progress(desc: str, total: int | None = None):
    return lambda it: progress_bar(it, desc, unit="frame", total=total)


def _fit_options(particles: int, seed: int, *, parallel: bool = False, casts_rays: bool = True, **inference):
    """The :class:`FitOptions` of a command's options: the stage options and ``--set``
    (one mapping, :meth:`FitOptions.with_settings`), the models and the device
    (``parallel``: frames will be fitted by several processes; ``casts_rays``: a variant to be
    fitted is a fine one, :func:`wirescene.fitting.variants.casts_rays`; see
    :func:`wirescene.infer.torch_backend.choose_device`)."""
    from wirescene.core.resources import resolve_models
    from wirescene.fitting.models import MODEL_FILES, check_model_files, with_models
    from wirescene.fitting.options import FitOptions
    from wirescene.infer.torch_backend import choose_device
    from wirescene.lift import LiftingOptions

    models_dir = inference.pop("models", None)
    # False: the pre-detection scores (`eval --raw-scores`, the data of `train scores`).
    calibrate_scores = inference.pop("calibrate_scores", True)
    # absolute: a resumed run from another folder, or a Dask worker, reads the same files
    models_given = {k: None if inference.get(k) is None else str(Path(inference[k]).resolve()) for k in MODEL_FILES}
    settings = stage_settings(inference, inference.pop("settings", ()))
    device = inference.pop("device", None)
    unknown = set(inference) - set(models_given)
    if unknown:  # a command passed an option no stage owns: a bug, not a user error
        raise TypeError(f"options no stage owns: {', '.join(sorted(unknown))}")
    # --device, else --set inference.device=..., else auto: resolved and checked here, before any fit ("" is no device)
    chosen = settings.get("inference.device", "auto") if device is None else device
    settings["inference.device"] = choose_device(chosen, parallel=parallel,
                                                 casts_rays=casts_rays)
    options = FitOptions(lifting=LiftingOptions(n_particles=particles), seed=seed, calibrate_scores=calibrate_scores,
                         **models_given)
    models = resolve_models(models_dir)
    options = with_models(options, models)  # before --set, which wins over the directory's occluded-part score
    try:
        options = options.with_settings(settings, combined=False)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--set") from None
    problem = options.combined_problem()  # of --particles and --samples as much as of --set
    if problem is not None:
        raise click.UsageError(problem)
    # a missing or malformed model file is refused naming it (the error line alone), before any frame is read
    options = check_model_files(options, fine=casts_rays)
    say_models(models, replaced=[name for name, path in models_given.items() if path is not None])
    return options


def _inference_options(f):
    """Options of the coarse and fine-grained inference stages (generated from the
    stages' own option fields, :func:`stage_options`) and the trained models they use,
    shared by `eval`, `fit` and `predict`."""
    from wirescene.fitting.options import PredetectOptions
    from wirescene.infer.inference import InferenceOptions
    from wirescene.lift import LiftingOptions

    f = settings_option(f)
    f = stage_options(PredetectOptions, "predetect")(f)
    f = stage_options(InferenceOptions, "inference")(f)
    f = stage_options(LiftingOptions, "lifting")(f)
    f = models_option(f)
    f = click.option("--parts-model", type=NonEmptyPath(exists=True, dir_okay=False, path_type=Path), default=None,
                     help="Part detector file (default: --models' or the shipped model), e.g. a cross-validation "
                          "fold's.")(f)
    f = click.option("--bank", "detector_bank", type=NonEmptyPath(exists=True, dir_okay=False, path_type=Path),
                     default=None, help="Detector bank file for our own pre-detection (default: --models' or the "
                                        "shipped bank).")(f)
    f = click.option("--viewpoint-classifier", type=NonEmptyPath(exists=True, dir_okay=False, path_type=Path),
                     default=None, help="Crop viewpoint classifier file (`wirescene train viewpoints`) that gives our "
                                        "own boxes and boxes without a viewpoint theirs (default: --models' or the "
                                        "shipped one).")(f)
    f = click.option("--score-calibration", type=NonEmptyPath(exists=True, dir_okay=False, path_type=Path),
                     default=None, help="Score calibration file (`wirescene train scores`) of the cars' confidences "
                                        "and of the verification of our own boxes (default: --models' or the "
                                        "shipped one).")(f)
    f = click.option("--shape-model", type=NonEmptyPath(exists=True, dir_okay=False, path_type=Path), default=None,
                     help="Shape model file (`wirescene train shape`) of the fine variants' wireframes (default: "
                          "--models' or the shipped one).")(f)
    f = click.option("--device", default=None,
                     help="Where the likelihood's ray casting runs: numpy, or PyTorch on cpu, cuda or cuda:N "
                          "(optional: pip install torch). auto (the default, unless --set inference.device=... "
                          "names one): a CUDA GPU if PyTorch sees one, a fine variant is fitted and the frames are "
                          "fitted in one process (one image, --workers 1 or one core), else numpy.")(f)
    return f


def _variants():
    from wirescene.fitting.variants import VARIANTS

    return list(VARIANTS)


def _write_json_atomic(path: Path, data: dict) -> None:
    from wirescene.core.jsonio import write_json

    write_json(path, data)  # strict JSON: a figure of an empty subset is null, not NaN


def _dask_client(address: str):
    """A client of the Dask scheduler at ``address``; a missing package or an unreachable
    scheduler is a one-line error before any frame is fitted."""
    try:
        from distributed import Client
    except ImportError:
        raise click.ClickException("--dask needs the 'distributed' package: pip install wirescene[dask]") from None
    try:
        return Client(address, set_as_default=False)
    except (OSError, ValueError, TypeError) as exc:
        detail = " ".join(str(exc).split())
        raise click.ClickException(f"--dask: cannot connect to the Dask scheduler at {address} ({detail})") from None


@main.command("eval")
@click.argument("kitti_root", type=NonEmptyPath(directory=True, path_type=Path))
@click.option("--variant", "variants", multiple=True, type=click.Choice(_variants()), help="Model variant(s); default: all available.")
@click.option("--detections", default="gt", show_default=True, callback=detections_spec,
              help="'gt' (label boxes), 'bank' (our pre-detection from raw pixels) or a directory of per-frame detection files.")
@click.option("--viewpoint-noise", type=NON_NEGATIVE_FLOAT, default=0.0, show_default=True,
              help="Std. dev. (deg) of noise on the GT viewpoint before binning.")
@click.option("--frames", default=None, help="Comma-separated frame ids (default: all labelled frames).")
@split_file_option
@particles_option
@click.option("--seed", "seeds", type=NON_NEGATIVE, multiple=True, default=(0,), show_default=True,
              help=f"Seed of the fit. Repeat it (--seed 1 --seed 2 --seed 3; at most {MAX_SEEDS} seeds) to fit every frame "
                   "once per seed: each seed's figures, then their mean and range over the seeds (the fit samples, so the "
                   "seed alone moves the figures by a few cars); --predictions and --report then get a seed-S folder "
                   "per seed, and --report a page of the mean and range over the seeds that links them.")
@split_option()
@calib_option
@click.option("--json", "json_out", type=NonEmptyPath(path_type=Path), default=None,
              help="Write the metrics as JSON: one variant's at the top level (its name under 'variant'), several keyed "
                   "by variant (and by seed under 'seeds' with several --seed).")
@click.option("--predictions", type=NonEmptyPath(directory=True, path_type=Path), default=None,
              help="Write KITTI label files per variant here.")
@click.option("--evidence", type=click.Choice(["parts", "oracle"]), default="parts", show_default=True,
              help="Evidence of the fine-grained variants: part detectors, or true vertices of synthetic scenes (upper bound).")
@click.option("--raw-scores", is_flag=True, default=False,
              help="Write the pre-detection scores instead of calibrated confidences, and keep every box of our own "
                   "pre-detection (the data of `train scores`).")
@ap_draws_option
@click.option("--report", "report_dir", type=NonEmptyPath(directory=True, path_type=Path), default=None,
              help="Write an HTML report with plots and a gallery of the best and worst frames to this directory.")
@workers_option()
@click.option("--allow-missing-detections", is_flag=True, default=False,
              help="With --detections DIR: frames without a detection file count as frames without detections "
                   "(their number is reported) instead of an error.")
@min_score_option
@click.option("--resume/--no-resume", default=False, show_default=True,
              help="Reuse the frames already finished in --predictions DIR (recorded in DIR/.frames/) and fit only the "
                   "rest; a record written with other settings is fitted again. Its frames must be among those chosen "
                   "now (--frames / --split-file: a larger selection continues it; a DIR holding frames outside the "
                   "selection is refused). Without it, a DIR holding an earlier run's records is refused (its frames "
                   "would mix with this run's).")
@click.option("--dask", "dask_address", metavar="ADDRESS", default=None,
              help="Fit frames on this running Dask scheduler (e.g. tcp://host:8786) instead of local processes "
                   "(--workers is then ignored); needs wirescene[dask] and the data at the same path on the workers.")
@_inference_options
def eval_cmd(kitti_root, variants, detections, viewpoint_noise, frames, split_file, particles, seeds, split, calib,
             json_out, predictions, evidence, raw_scores, draws, report_dir, workers, allow_missing_detections,
             min_score, resume, dask_address, **inference):
    """Evaluate model variants on a KITTI directory with the paper's protocol."""
    from wirescene.eval.seeds import format_over_seeds, over_seeds, seed_figures

    refuse_min_score(min_score, detections)
    if len(seeds) > MAX_SEEDS:  # each seed evaluates every frame again
        raise click.BadParameter(f"{len(seeds):,} seeds given, at most {MAX_SEEDS} (each evaluates every frame again)",
                                 param_hint="--seed")
    if resume and predictions is None:
        raise click.UsageError("--resume needs --predictions DIR, where finished frames are recorded")
    if dask_address is not None:  # Dask workers may run elsewhere (another working directory): absolute paths
        if detections not in ("gt", "bank"):
            detections = str(Path(detections).resolve())
    check_output_file(json_out, "--json")
    check_output_dir(predictions, "--predictions")
    check_output_dir(report_dir, "--report")
    if predictions is not None:
        keeps_on_resume("the frames --predictions holds")
    dataset = kitti_dataset(kitti_root, split, calib, absolute=dask_address is not None)
    variants = list(variants) or _variants()
    dataset.require_labels("evaluation")  # before --frames looks among labelled frames (a testing/ split has none)
    frame_ids = select_frames(frames, split_file, dataset.require_frames(), where=dataset.split_dir)
    # read before any fit (a bad devkit mapping is an error now); a plain folder's frames are no KITTI drive's
    drives = {} if dataset.image_dir == dataset.split_dir else interval_drives(dataset.split_dir)
    if raw_scores:
        inference["calibrate_scores"] = False
        # The car model of `train scores` learns from the boxes the verification would drop.
        inference["predetect__min_car_probability"] = 0.0
    if len(set(seeds)) < len(seeds):
        raise click.UsageError(f"--seed: each seed once (given {', '.join(map(str, seeds))})")
    several = len(seeds) > 1
    if predictions is not None:  # every seed's folder, before the first seed's fits
        from wirescene.eval.records import refuse_predictions_dir

        for seed in seeds:
            refuse_predictions_dir(_seed_dir(predictions, seed, several), variants,
                                   dataset.require_frames() if frame_ids is None else frame_ids, resume=resume)
    client = _dask_client(dask_address) if dask_address is not None else None
    figures, data = {}, {}
    with ExitStack() as stack:
        if client is not None:
            stack.callback(client.close)
        pages = report_dir
        if several and report_dir is not None:
            from wirescene.eval.report import staged_report

            # the seeds' pages and the page over them replace an earlier report together, after the last seed
            pages = stack.enter_context(staged_report(report_dir))
        said: set[str] = set()

        def notify(message: str) -> None:  # several seeds: a frame's warning once, not once a seed
            if message not in said:
                said.add(message)
                click.echo(f"wirescene: {message}", err=True)

        for k, seed in enumerate(seeds):
            if several:
                click.echo(("\n" if k else "") + f"=== seed {seed}")
            reports, kitti, data[seed] = _evaluate_seed(
                dataset, variants, frame_ids, drives, seed=seed, detections=detections, viewpoint_noise=viewpoint_noise,
                particles=particles, predictions=_seed_dir(predictions, seed, several), evidence=evidence, draws=draws,
                report_dir=_seed_dir(pages, seed, several), workers=workers,
                allow_missing=allow_missing_detections, min_score=min_score, resume=resume, client=client,
                dask_address=dask_address, say_held_out=not k,
                inference=dict(inference), as_json=json_out is not None, notify=notify)
            figures[seed] = seed_figures({v: r.metrics["all"] for v, r in reports.items()}, kitti)
        summary = over_seeds(figures) if several else None
        if several and report_dir is not None:
            from wirescene.eval.report import write_seeds_page

            write_seeds_page(pages, summary, seeds, title=f"{dataset.split_dir} ({detections} pre-detections)")
    if several:
        click.echo("\n" + format_over_seeds(summary, seeds))
    if report_dir is not None:
        each = f", one page a seed in {', '.join(str(_seed_dir(report_dir, s, True)) for s in seeds)}" if several else ""
        click.echo(f"report written to {Path(report_dir) / 'index.html'}{each}")
    if json_out is not None:
        out = data[seeds[0]] if not several else {"seeds": {str(s): d for s, d in data.items()}, "over_seeds": summary}
        if len(variants) == 1 and not several:  # flat, but saying whose figures they are
            out = {"variant": variants[0], **out[variants[0]]}
        _write_json_atomic(json_out, out)
        click.echo(f"metrics written to {json_out}")


def _seed_dir(path: Path | None, seed: int, several: bool) -> Path | None:
    """Where one seed of ``wirescene eval`` writes under an output folder: ``PATH/seed-S`` when
    several seeds are evaluated, else ``PATH`` itself."""
    from wirescene.eval.seeds import seed_folder

    return None if path is None else (Path(path) / seed_folder(seed) if several else path)


def _evaluate_seed(dataset, variants, frame_ids, drives, *, seed, detections, viewpoint_noise, particles, predictions,
                   evidence, draws, report_dir, workers, allow_missing, min_score, resume, client, dask_address,
                   inference, as_json, notify, say_held_out=False) -> tuple[dict, dict, dict | None]:
    """One seed of ``wirescene eval``: fits, prints its tables and writes its report (its notices
    to ``notify``, with, ``say_held_out``, the frames evaluated that a model read was trained on,
    :func:`~wirescene.eval.held_out.trained_on_frames`); returns ``(reports, kitti figures, JSON
    data)`` by variant, the JSON data (every record serialised) only ``as_json`` (else None)."""
    from wirescene.eval.intervals import format_intervals, localisation_intervals, margin_intervals
    from wirescene.eval.kitti_metrics import format_kitti_summary
    from wirescene.eval.metrics import format_table
    from wirescene.eval.runner import evaluate_dataset
    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.variants import casts_rays

    options = _fit_options(particles, seed, parallel=_parallel(workers, frame_ids, dask_address),
                           casts_rays=casts_rays(variants), **inference)
    source = DetectionSource(detections, viewpoint_noise, allow_missing=allow_missing, min_score=min_score,
                             bank=options.detector_bank, classifier=options.viewpoint_classifier)
    on_gpu = options.inference.device.startswith("cuda")
    if on_gpu and workers is not None and _parallel(workers, frame_ids, None):  # --workers asked for, and usable
        # Forked processes cannot share the parent's CUDA state; the GPU is the parallelism.
        raise click.UsageError("--device cuda fits frames in one process: drop --workers (or use --dask, one worker per GPU)")
    gallery = None
    if report_dir is not None:
        from wirescene.eval.report import Gallery

        gallery = Gallery()
    kitti_rows: dict = {}  # {variant: {frame: label rows}} for the KITTI benchmark figures

    def on_estimate(frame_id, variant, estimate, *rest):
        kitti_rows.setdefault(variant, {})[frame_id] = estimate.to_labels()
        if gallery is not None:
            gallery.add(frame_id, variant, estimate, *rest)

    reports = evaluate_dataset(
        dataset,
        variants,
        frames=frame_ids,
        source=source,
        options=options,
        predictions_dir=predictions,
        resume=resume,
        evidence=evidence,
        workers=_frame_workers(workers, options.inference.device),
        dask_client=client,
        progress=_progress("eval", len(frame_ids) if frame_ids else len(dataset.frame_ids())),
        notify=notify,
        on_estimate=on_estimate,
        check_images=report_dir is not None,  # the gallery draws fitted frames: a corrupt image refused before the fits
        held_out=notify if say_held_out else None,
    )
    # Table 3 needs per-vertex ground truth (synthetic scenes); KITTI has none.
    has_parts = any(np.isfinite(r.metrics["all"].get("occ_pred_acc", np.nan)) for r in reports.values())
    click.echo(format_table(reports, tables=("3d", "viewpoint", "2d") if has_parts else ("3d", "viewpoint")))
    intervals = localisation_intervals(reports, drives, seed=seed)
    # each variant against coarse+gp (the coarse stage with the shared plane, which the fine stage must beat)
    reference = "coarse+gp" if "coarse+gp" in reports else next(iter(reports))
    margins = margin_intervals(reports, drives, reference=reference, seed=seed) if len(reports) > 1 else {}
    click.echo("\n" + format_intervals(intervals, margins=margins))
    kitti, kitti_spread, kitti_margins = _kitti_figures(dataset, frame_ids, reports, kitti_rows, predictions,
                                                        drives=drives, seed=seed, draws=draws,
                                                        reference=reference if margins else None)
    click.echo("\n" + format_kitti_summary(kitti, intervals=kitti_spread, margins=kitti_margins))
    data = None if not as_json else {
        v: {**r.to_json_dict(include_records=True), "kitti": kitti[v], "loc_1m_interval": intervals[v],
            **({"kitti_interval": kitti_spread[v]} if v in kitti_spread else {}),
            **({"kitti_margin": kitti_margins[v]} if v in kitti_margins else {}),
            **({"loc_1m_margin": margins[v]} if v in margins else {})}
        for v, r in reports.items()}
    if report_dir is not None:
        from wirescene.eval.report import run_settings, write_report
        from wirescene.eval.runner import model_files_of_run

        # the files the fits read, as the held-out line names them (label boxes read no bank nor classifier)
        evaluated = dataset.require_frames() if frame_ids is None else frame_ids
        read = model_files_of_run(dataset, source, variants, evaluated, options=options, evidence=evidence)
        write_report(report_dir, reports, gallery=gallery, image_of=dataset.image, intervals=intervals,
                     kitti=kitti, kitti_intervals=kitti_spread, title=f"{dataset.split_dir} ({detections} pre-detections, seed {seed})",
                     run=run_settings(options, detections=detections, evidence=evidence, fine=casts_rays(variants),
                                      min_score=min_score, read=read),
                     raw_scores=not options.calibrate_scores)
    return reports, kitti, data


@main.command("predict")
@click.argument("kitti_root", type=NonEmptyPath(directory=True, path_type=Path))
@split_option("testing")
@calib_option
@click.option("--out", type=NonEmptyPath(directory=True, path_type=Path), required=True,
              help="Directory of KITTI label files, one FRAME.txt per image (the benchmark's submission layout).")
@click.option("--json-dir", type=NonEmptyPath(directory=True, path_type=Path), default=None,
              help="Also write each frame's FRAME.json here, as `wirescene fit` writes it: every car's 3D box and "
                   "ground plane and, of the fine variants (fg...), its 36-vertex wireframe and visible vertices "
                   "(the label files keep the box alone).")
@click.option("--pictures", "pictures_dir", type=NonEmptyPath(directory=True, path_type=Path), default=None,
              help="Also draw each frame's FRAME_overlay.png and FRAME_bev.png here (the cars of a labelled "
                   "split's label files drawn beside the estimates; some 0.3 s a frame more).")
@click.option("--variant", type=click.Choice(_variants()), default=DEFAULT_VARIANT, show_default=True)
@click.option("--detections", default="bank", show_default=True, callback=detections_spec,
              help="'bank' (our pre-detection), 'gt' (label boxes; labelled splits only) or a directory of "
                   "per-frame detection files.")
@click.option("--allow-missing-detections", is_flag=True, default=False,
              help="With --detections DIR: images without a detection file get an empty label file.")
@min_score_option
@click.option("--frames", default=None, help="Comma-separated frame ids (default: every image).")
@split_file_option
@particles_option
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True)
@workers_option()
@click.option("--resume/--no-resume", default=False, show_default=True,
              help="Continue an interrupted run in --out (same settings): fit only the images without a label file. "
                   "Its frames must be among those chosen now (--frames / --split-file: a larger selection "
                   "continues it; a folder holding frames outside the selection is refused).")
@click.option("--dask", "dask_address", metavar="ADDRESS", default=None,
              help="Fit frames on this running Dask scheduler instead of local processes.")
@_inference_options
def predict_cmd(kitti_root, split, calib, out, json_dir, pictures_dir, variant, detections, allow_missing_detections,
                min_score, frames, split_file, particles, seed, workers, resume, dask_address, **inference):
    """Write KITTI label files (with scores) for every image of a split, labelled or not (or of a folder of
    frames of one camera, with --calib)."""
    from wirescene.eval.predict import predict_dataset
    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.variants import casts_rays

    refuse_min_score(min_score, detections)
    # predict_dataset's refusals of a folder name its option, as these checks do
    options_named = {"out_dir": "--out", "json_dir": "--json-dir", "pictures_dir": "--pictures", "resume": "--resume"}
    check_output_dir(out, options_named["out_dir"])
    check_output_dir(json_dir, options_named["json_dir"])
    check_output_dir(pictures_dir, options_named["pictures_dir"])
    keeps_on_resume("the frames --out holds")
    if dask_address is not None:  # Dask workers may run elsewhere (another working directory): absolute paths
        if detections not in ("gt", "bank"):
            detections = str(Path(detections).resolve())
    dataset = kitti_dataset(kitti_root, split, calib, absolute=dask_address is not None)
    images = dataset.require_frames(images=True)
    frame_ids = select_frames(frames, split_file, images, where=dataset.split_dir, what="image")
    options = _fit_options(particles, seed, parallel=_parallel(workers, frame_ids, dask_address),
                           casts_rays=casts_rays([variant]), **inference)
    client = _dask_client(dask_address) if dask_address is not None else None
    total = len(frame_ids) if frame_ids else len(images)
    try:
        fitted = predict_dataset(dataset, out, variant=variant, options=options, frames=frame_ids, resume=resume,
                                 source=DetectionSource(detections, allow_missing=allow_missing_detections,
                                                        min_score=min_score, bank=options.detector_bank,
                                                        classifier=options.viewpoint_classifier),
                                 workers=_frame_workers(workers, options.inference.device), dask_client=client,
                                 progress=_progress("predict", total), json_dir=json_dir, pictures_dir=pictures_dir,
                                 names=options_named,
                                 notify=lambda message: click.echo(f"wirescene: {message}", err=True))
    finally:
        if client is not None:
            client.close()
    also = "".join(f", {what} in {folder}" for what, folder in (("scenes", json_dir), ("pictures", pictures_dir))
                   if folder)
    click.echo(f"{len(fitted)} frames fitted, {total - len(fitted)} kept from an earlier run; labels in {out}{also}")


def _kitti_figures(dataset, frame_ids, variants, rows, predictions, *, drives, seed, draws,
                   reference) -> tuple[dict, dict, dict]:
    """KITTI benchmark figures (:func:`wirescene.eval.kitti_metrics.kitti_metrics`) of each
    variant, the moderate ones' bootstrap intervals over ``drives`` with ``draws`` draws
    (:func:`wirescene.eval.intervals.kitti_intervals`; none for 0) and those of each variant's
    margins over ``reference`` (None: none): of its label files in ``predictions`` if given (so
    that fitted and resumed frames give the same figures, and ``kitti-eval`` on those files
    agrees), else of the label rows it predicted (``rows[variant][frame]``)."""
    from wirescene.eval.intervals import kitti_variant_intervals
    from wirescene.eval.kitti_metrics import kitti_metrics
    from wirescene.io.kitti import read_labels

    frame_ids = list(frame_ids) if frame_ids else dataset.frame_ids()
    gts = [dataset.labels(f) for f in frame_ids]
    preds = {}
    for v in variants:
        if predictions is not None:
            preds[v] = [read_labels(Path(predictions) / v / f"{f}.txt") for f in frame_ids]
        else:
            preds[v] = [rows[v][f] for f in frame_ids]
    out = {v: kitti_metrics(gts, p) for v, p in preds.items()}
    if not draws:
        return out, {}, {}
    spread, margins = kitti_variant_intervals(gts, preds, frame_ids, drives, reference=reference, n_boot=draws,
                                              seed=seed)
    return out, spread, margins


def _prediction_dir_warnings(pred_dir: Path, gt_dir: Path, ids: list[str], *, chosen: bool) -> list[str]:
    """What a user scoring ``pred_dir`` against ``gt_dir`` should know: label files of frames
    that ``gt_dir`` has not (not scored, unless ``chosen``: frames were selected), and a
    ``wirescene predict`` folder (its ``.predict.json``) made of another split than ``gt_dir``'s
    (``testing`` scored against ``training/label_2``)."""
    from wirescene.eval.predict import CONFIG_FILE

    warnings = []
    extra = [] if chosen else sorted({p.stem for p in pred_dir.glob("*.txt")} - set(ids))
    if extra:
        warnings.append(f"{len(extra)} prediction files have no label file in {gt_dir} and are not scored "
                        f"(e.g. {extra[0]}.txt)")
    try:
        record = json.loads((pred_dir / CONFIG_FILE).read_text(encoding="utf-8"))
        made_of = record["dataset"]
    except (OSError, ValueError, TypeError, KeyError):  # not a predict folder, or a record this check cannot read
        return warnings
    if "calib" in record:  # a folder of one camera's frames: no KITTI split whose name to compare
        return warnings
    # by the split's folder name: a KITTI folder moved since the prediction is no mistake
    if isinstance(made_of, str) and Path(made_of).name != gt_dir.resolve().parent.name:
        warnings.append(f"predicted from the images of {made_of}, scored against the labels of {gt_dir}")
    return warnings


@main.command("kitti-eval")
@click.argument("gt_dir", type=NonEmptyPath(directory=True, path_type=Path))
@click.argument("pred_dirs", metavar="PRED_DIR...", nargs=-1, required=True,
                type=NonEmptyPath(directory=True, path_type=Path))
@click.option("--json", "json_out", type=NonEmptyPath(path_type=Path), default=None, help="Write the figures as JSON.")
@click.option("--frames", default=None, help="Comma-separated frame ids (default: every GT_DIR/*.txt).")
@split_file_option
@ap_draws_option
@drive_map_option("the interval draws whole drives")
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True, help="Seed of the bootstrap draws.")
def kitti_eval_cmd(gt_dir, pred_dirs, json_out, frames, split_file, draws, drive_mapping, seed):
    """KITTI object-benchmark AP of Car (2D, AOS, BEV, 3D; easy / moderate / hard; R40 and
    R11; IoU 0.7 and 0.5) of the label files in PRED_DIR against GT_DIR, by the devkit's
    rules, and the moderate APs' bootstrap interval over drives. A frame without a
    prediction file is scored as a frame without detections, its cars missed (said: KITTI's
    server refuses such a submission); a prediction file of a frame GT_DIR lacks is not
    scored (said). Several PRED_DIRs are runs of one method (other
    seeds, say): each run's moderate APs, their mean, and an interval whose every draw
    resamples the drives and takes one of the runs."""
    from wirescene.core.labels import no_3d_box
    from wirescene.eval.intervals import kitti_intervals, kitti_run_intervals
    from wirescene.eval.kitti_metrics import (
        format_kitti_intervals,
        format_kitti_summary,
        format_kitti_table,
        kitti_metrics,
        mean_kitti_metrics,
        read_label_dirs,
    )

    check_output_file(json_out, "--json")
    known = sorted(p.stem for p in gt_dir.glob("*.txt")) if gt_dir.is_dir() else []
    frame_ids = select_frames(frames, split_file, known, where=gt_dir, what="label file of frame") if known else None
    drives = interval_drives(gt_dir.resolve().parent, drive_mapping)  # GT_DIR: ROOT/training/label_2
    names = [d.name or str(d) for d in pred_dirs]
    if len(set(names)) < len(names):  # e.g. seed1/full and seed2/full
        names = [str(d) for d in pred_dirs]
    twice = [d for i, (d, n) in enumerate(zip(pred_dirs, names)) if n in names[:i]]
    if twice:
        raise InputError("prediction directory given twice", path=twice[0])
    runs = [read_label_dirs(gt_dir, d, frames=frame_ids) for d in pred_dirs]
    ids, gts = runs[0][0], runs[0][1]
    for d, (_, _, preds) in zip(pred_dirs, runs):
        missing = [f for f in ids if not (d / f"{f}.txt").exists()]
        if missing:  # scored (an interrupted run's frames so far, say), said in full: the server refuses it
            click.echo(f"wirescene: {d}: {len(missing)} of {len(ids)} frames have no prediction file (e.g. "
                       f"{missing[0]}.txt): scored as frames without detections, their cars missed; KITTI's server "
                       "refuses a submission lacking a frame (an empty FRAME.txt is a frame without cars; --frames or "
                       "--split-file scores a selection)", err=True)
        cars = [o for frame in preds for o in frame.of_type(*CAR_TYPES)]
        flat = sum(no_3d_box(o.dims) for o in cars)  # a 2D detector's rows: scored as 3D boxes of size -1
        if flat:
            click.echo(f"wirescene: {d}: {flat} of {len(cars)} Car rows have no 3D box (dimensions -1 -1 -1): "
                       "BEV and 3D AP count them as misses", err=True)
        for warning in _prediction_dir_warnings(d, gt_dir, ids, chosen=frame_ids is not None):
            click.echo(f"wirescene: {d}: {warning}", err=True)
    preds = [r[2] for r in runs]
    if len(preds) == 1:
        result = kitti_metrics(gts, preds[0])
        click.echo(format_kitti_table(result))
        if draws:
            result["kitti_interval"] = kitti_intervals(gts, preds[0], ids, drives, n_boot=draws, seed=seed)
            click.echo("\n" + format_kitti_intervals({names[0]: result["kitti_interval"]}))
    else:
        each = {n: kitti_metrics(gts, p) for n, p in zip(names, preds)}
        mean = f"mean of {len(preds)}"
        result = {"runs": each, "mean": mean_kitti_metrics(list(each.values()))}
        click.echo(format_kitti_summary({**each, mean: result["mean"]}))
        if draws:
            result["kitti_interval"] = kitti_run_intervals(gts, preds, ids, drives, n_boot=draws, seed=seed)
            click.echo(f"\nEach draw takes one of the {len(preds)} runs at random:")
            click.echo(format_kitti_intervals({f"{len(preds)} runs": result["kitti_interval"]}))
    if json_out is not None:
        _write_json_atomic(json_out, result)
        click.echo(f"metrics written to {json_out}")


@main.command("fit")
@click.argument("image", type=NonEmptyPath(path_type=Path))
@click.option("--calib", type=NonEmptyPath(path_type=Path), required=True, help=f"Camera calibration: {CALIB_FORMS}.")
@click.option("--detections", type=NonEmptyPath(path_type=Path), default=None,
              help="2D car detections: .json, .csv or KITTI label .txt (see `wirescene.io.detections.read_detections`); "
                   "default: our own pre-detection from raw pixels.")
@min_score_option
@click.option("--gt", type=NonEmptyPath(path_type=Path), default=None,
              help="KITTI label file drawn in cyan for comparison; the cars the evaluation counts false are "
                   "marked violet, the labelled cars it counts missed dashed.")
@click.option("--variant", type=click.Choice(_variants()), default=DEFAULT_VARIANT, show_default=True,
              help="Model variant (the default as `predict`'s and `wirescene.fit`'s).")
@particles_option
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True)
@click.option("--out", type=NonEmptyPath(directory=True, path_type=Path), required=True, help="Output directory.")
@_inference_options
def fit_cmd(image, calib, detections, min_score, gt, variant, particles, seed, out, **inference):
    """Fit the scene model to one image; write KITTI labels, JSON, overlay and bird's-eye view."""
    import warnings

    from wirescene.api import as_camera, fit
    from wirescene.core.errors import CalibrationWarning
    from wirescene.core.types import Detections
    from wirescene.fitting.variants import casts_rays
    from wirescene.io.detections import NO_CARS, read_detections
    from wirescene.io.kitti import read_image, read_labels
    from wirescene.io.outputs import fit_output_paths, fit_outputs_problem, write_fit_outputs

    refuse_min_score(min_score, detections, needs="--detections FILE")
    check_output_dir(out, "--out")
    problem = fit_outputs_problem(fit_output_paths(out, Path(image).stem))
    if problem:  # before the fit, not at its end
        raise click.BadParameter(f"{problem[0]}: {problem[1]}", param_hint="--out")
    # a bad --set fails before any file is read
    options = _fit_options(particles, seed, casts_rays=casts_rays([variant]), **inference)
    img = read_image(image)
    camera = as_camera(calib, (img.shape[1], img.shape[0]))
    say_off_centre_image(image, camera)  # a calibration carries no image size: said, not refused
    dets, others = None, ""
    if detections is not None:
        try:
            dets = read_detections(detections, image_size=(img.shape[1], img.shape[0]), min_score=min_score)
        except InputError as exc:  # a frame without cars (or none at --min-score) is a frame, as in eval and predict
            if not exc.problem.startswith(NO_CARS):
                raise
            dets = Detections.empty(str(detections))
            others = exc.problem[len(NO_CARS):]  # the classes of the file's boxes, where it has some
    gt_objs = read_labels(gt, image_size=(img.shape[1], img.shape[0])).of_type(*CAR_TYPES) if gt is not None else None
    with warnings.catch_warnings():  # said above, in the command's one line, not again by the API
        warnings.simplefilter("ignore", CalibrationWarning)
        estimate = fit(img, camera, dets, variant=variant, options=options)
    if not estimate.cars:
        # the floor said where it left the file no box
        floor = f" scoring at least {min_score:g}" if min_score is not None and dets is not None and not len(dets) else ""
        said = f"no car detections{floor}{others}" if dets is not None else "no car found"
        click.echo(f"wirescene: {detections if dets is not None else image}: {said}; writing an empty scene", err=True)
    paths = write_fit_outputs(out, Path(image).stem, image=img, camera=camera, estimate=estimate,
                              detections=estimate.detections, gt=gt_objs)
    for kind, p in paths.items():
        click.echo(f"{kind:8s} {p}")


@main.command("demo")
@click.option("--out", type=NonEmptyPath(directory=True, path_type=Path), default=Path("wirescene_demo"),
              show_default=True)
@click.option("--particles", type=click.IntRange(min=1, max=MAX_PARTICLES), default=50, show_default=True,
              help="Scene particles (the paper used 250; fewer keep the demo short).")
@click.option("--variant", "variants", multiple=True, type=click.Choice(_variants()),
              default=("coarse", "coarse+gp", "fg+gp", "full"), show_default=True)
@models_option
def demo_cmd(out, particles, variants, models):
    """Fit model variants to the bundled real KITTI frames, evaluate, write pictures."""
    import time

    from wirescene.api import fit
    from wirescene.core.atomic import atomic_dir
    from wirescene.eval.metrics import format_table
    from wirescene.eval.runner import evaluate_dataset
    from wirescene.eval.sources import DetectionSource
    from wirescene.io.kitti import KittiDataset
    from wirescene.io.outputs import fit_output_paths, write_fit_outputs

    check_output_dir(out, "--out")
    options = _fit_options(particles, 0, models=models, device="numpy")  # the README's demo figures, to the bit
    t0 = time.perf_counter()
    dataset = KittiDataset(sample_root())
    first = dataset.frame_ids()[0]
    written = []
    # the demo's files as one set: a run of other variants leaves no earlier run's folder beside its eval.json
    stale = tuple(str(p) for folder in (*_variants(), "raw-pixels")
                  for p in fit_output_paths(Path(folder), first).values())
    with atomic_dir(out, stale=stale) as staging:

        def draw(frame_id, variant, estimate, camera, detections, gt):
            if frame_id == first:
                paths = write_fit_outputs(staging / variant, frame_id, image=dataset.image(frame_id), camera=camera,
                                          estimate=estimate, detections=detections, gt=gt.of_type(*CAR_TYPES))
                written.extend(paths.values())

        trained: list[str] = []  # a models directory keeps the shipped files it lacks (the score calibration)
        reports = evaluate_dataset(dataset, list(variants), source=DetectionSource("gt"), options=options,
                                   progress=_progress("demo"), on_estimate=draw, held_out=trained.append)
        # Raw-pixel mode: our own pre-detection instead of label boxes, then the full model.
        image = dataset.image(first)
        estimate = fit(image, dataset.camera(first), None, variant="full", options=options)
        raw = estimate.detections
        gt = dataset.labels(first).of_type(*CAR_TYPES)
        if len(raw):
            written.extend(write_fit_outputs(staging / "raw-pixels", first, image=image, camera=dataset.camera(first),
                                             estimate=estimate, detections=raw, gt=gt).values())
        click.echo(f"raw-pixel mode on {first}: the detector bank proposed {len(raw)} boxes, the fit kept "
                   f"{len(estimate.objects)} cars ({len(gt)} labelled)\n")
        click.echo(f"wirescene {__version__} demo on bundled KITTI frames {', '.join(dataset.frame_ids())} "
                   f"(GT boxes as pre-detections, {particles} particles"
                   f"{'; frames the models it reads were trained on, so not held out' if trained else ''})\n")
        click.echo(format_table(reports))
        figures = {v: r.to_json_dict(include_records=False) for v, r in reports.items()}
        _write_json_atomic(staging / "eval.json", figures)
        written.append(staging / "eval.json")
    click.echo("\nwritten:")
    for p in written:
        click.echo(f"  {out / p.relative_to(staging)}")
    click.echo(f"\ndone in {time.perf_counter() - t0:.1f} s")


@main.command("gt")
@click.argument("kitti_root", type=NonEmptyPath(directory=True, path_type=Path))
@click.argument("frame")
@click.option("--out", type=NonEmptyPath(path_type=Path), required=True,
              help="Picture to write, in the format its suffix names (.png, .pdf, .svg; PNG without a suffix).")
@split_option(calib=False)
def gt_cmd(kitti_root, frame, out, split):
    """Draw a frame's ground truth with the mean wireframe at every GT car pose
    (the vertices the car itself hides as rings): a check of geometry, shape model and labels."""
    from wirescene.core.groundplane import rotation_y, transform
    from wirescene.core.labels import no_3d_box
    from wirescene.core.shape import load_default
    from wirescene.core.types import ObjectEstimate, SceneEstimate
    from wirescene.core.wireframe import EDGES, FACES
    from wirescene.infer.occlusion import self_occlusion
    from wirescene.io.pictures import overlay, save_figure

    check_picture_file(out, "--out")
    dataset = kitti_dataset(kitti_root, split, None)  # a split folder given: --split naming another refused
    ids = dataset.image_ids()
    if frame not in ids:  # said as such, not as its missing calibration file
        held = f"its image_2 holds {len(ids)} frames, e.g. {ids[0]}" if ids else "its image_2 holds no .png image"
        raise click.BadParameter(f"no frame {frame} in {dataset.split_dir} ({held})", param_hint="FRAME")
    camera = dataset.camera(frame)
    say_off_centre_image(dataset.image_path(frame), camera)
    cars = dataset.labels(frame).of_type(*CAR_TYPES)
    mean = load_default().mean
    objects = []
    for i, g in enumerate(cars):
        if no_3d_box(g.dims):  # a 2D detector's row (-1 -1 -1): no pose to draw a wireframe at, its box drawn
            continue
        R = rotation_y(g.rotation_y)
        vertices = transform(mean, g.location, R)
        hidden = self_occlusion(vertices, FACES, camera.center)
        objects.append(ObjectEstimate(i, g.box, 1.0, g.location, R, g.dims, 0.0, vertices=vertices,
                                      hidden_by=np.where(hidden, "self", "visible")))
    fig = overlay(dataset.image(frame), camera, SceneEstimate("gt", objects), gt=cars, edges=EDGES,
                  title=f"{frame}: mean wireframe at GT poses", estimate_name="mean wireframe at the label's pose",
                  scores=False)
    click.echo(save_figure(fig, out))


def _register_commands():
    """Attach the command groups that live in their own modules. Their imports are
    plain: a broken module fails ``wirescene --help`` (and the CLI tests) loudly instead
    of silently dropping commands."""
    from wirescene.cli.cad import cad, shape
    from wirescene.cli.detect import detect, detector, split_coco, viewpoints
    from wirescene.cli.info import info
    from wirescene.cli.occlusion import occlusion
    from wirescene.cli.parts import parts
    from wirescene.cli.pitch import pitch
    from wirescene.cli.scores import scores
    from wirescene.cli.synth import synth
    from wirescene.cli.train_all import train_all_cmd

    main.add_command(synth)
    main.add_command(cad)
    main.add_command(detect)
    main.add_command(split_coco)
    main.add_command(pitch)
    main.add_command(info)
    train = click.Group("train", help="Train the model's artefacts from documented data.")
    for command in (shape, parts, detector, viewpoints, occlusion, scores, train_all_cmd):
        train.add_command(command)
    main.add_command(train)


_register_commands()


def console_main() -> None:
    """The ``wirescene`` console script (and ``python -m wirescene.cli.main``): :func:`main` on
    this process's command line, the process being the command's, so that it exits with
    the stop signals ignored (:func:`_stop_signals`). Calling ``main()`` from Python instead
    leaves the caller's handlers as they were."""
    main.main(console=True)


if __name__ == "__main__":  # pragma: no cover
    console_main()
