"""``wirescene train all``: every artefact of a models directory from one labelled KITTI
root (see :mod:`wirescene.training.pipeline`)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from wirescene.cli.options import (
    NonEmptyPath,
    check_output_dir,
    drive_map_option,
    keeps_on_resume,
    kitti_root_params,
    progress_bar,
    split_file_option,
    workers_count,
    workers_option,
)
from wirescene.training.scale import MAX_FOLDS


def parse_settings(values: tuple[str, ...]) -> dict[str, dict]:
    """``{step: {option: value}}`` of ``--set STEP.KEY=VALUE`` (each name checked, each
    value parsed as its default's type by :func:`wirescene.core.settings.parse_value`)."""
    from wirescene.core.settings import parse_assignment, parse_value
    from wirescene.training.pipeline import check_options, option_default

    out: dict[str, dict] = {}
    for item in values:
        try:
            step, key, text = parse_assignment(item)
            out.setdefault(step, {})[key] = parse_value(text, option_default(step, key))
        except ValueError as exc:
            raise click.BadParameter(f"{item.partition('=')[0]}: {exc}", param_hint="--set") from None
    try:
        check_options(out)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--set") from None
    return out


@click.command("all")
@kitti_root_params("Labelled KITTI root to train on.", type=NonEmptyPath(directory=True, path_type=Path),
                   required=True)
@click.option("--out", type=NonEmptyPath(file_okay=False, path_type=Path), required=True,
              help="Models directory to write (parts_model.npz, detector_bank.npz, viewpoint_classifier.npz, "
                   "occlusion.json, models.json); use it with --models of fit, eval, predict and detect.")
@click.option("--frames", default=None, help="Comma-separated training frame ids (default: every labelled frame).")
@split_file_option
@click.option("--folds", "n_folds", type=click.IntRange(min=2, max=MAX_FOLDS), default=4, show_default=True,
              help=f"Folds of the held-out calibrations (by drive where it is known, else by frame; at most {MAX_FOLDS}: "
                   "each trains a bank and a part forest again).")
@drive_map_option()
@click.option("--set", "settings", multiple=True, metavar="STEP.KEY=VALUE",
              help="Change one option of a step's recipe (steps parts, detector, viewpoints, occlusion), e.g. "
                   "parts.synth_scenes=100 or detector.mining_rounds=2; repeatable.")
@click.option("--resume/--no-resume", default=False, show_default=True,
              help="Keep the steps already done in --out with the same data, options and inputs; train the rest.")
@workers_option("of the detector step's per-image passes (mining, detections)")
def train_all_cmd(kitti_root, out, frames, split_file, n_folds, drive_mapping, settings, resume, workers):
    """Train part detectors, detector bank (held-out calibration), crop viewpoint classifier,
    occluded-part score c (the score calibration stays the shipped one) on the labelled
    frames of KITTI_ROOT, in order, into a models directory with a manifest."""
    from tqdm import tqdm

    from wirescene.cli.options import parse_frames
    from wirescene.core.errors import InputError
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.pipeline import manifest_steps, step_cost, train_all

    check_output_dir(out, "--out")
    keeps_on_resume("the steps --out holds")
    options = parse_settings(settings)
    if options.get("parts", {}).get("synth_cache") is not None:
        check_output_dir(options["parts"]["synth_cache"], "--set parts.synth_cache")
    if frames is not None and split_file is not None:
        raise click.UsageError("--frames and --split-file both choose the frames: give one")
    dataset = KittiDataset(kitti_root)
    dataset.require_labels("training")  # before --frames is looked for among its labels
    ids = parse_frames(frames, dataset.frame_ids(), where=dataset.split_dir, what="labelled frame")
    try:  # the steps an earlier run left, to tell those this run keeps (a manifest unread: train_all says why)
        earlier = manifest_steps(out) if resume else {}
    except InputError:
        earlier = {}
    def iterate(items, name):
        return progress_bar(items, name, unit="step" if name == "train all" else "it")

    manifest = train_all(out, kitti_root, frames=ids, split_file=split_file, options=options, n_folds=n_folds,
                         drive_mapping=drive_mapping, resume=resume, workers=workers_count(workers), iterate=iterate,
                         progress=lambda line: tqdm.write(line, file=sys.stderr),
                         notify=lambda message: tqdm.write(f"wirescene: {message}", file=sys.stderr))
    for step, record in manifest["steps"].items():
        if record.get("source") == "shipped":
            click.echo(f"{step:18s} shipped ({record['why']})")
        else:
            kept = " (kept from an earlier run)" if record == earlier.get(step) else ""
            click.echo(f"{step:18s} {record['artefact']}: {step_cost(record)}{kept}")
    folds = manifest["calibration_folds"]
    click.echo(f"models written to {out} ({manifest['data']['frames']} frames, {manifest['data']['cars']} cars; "
               f"{folds['frames_with_known_drive']} frames of known drive"
               + (f" from {folds['devkit_mapping']})" if folds["devkit_mapping"] else ")")
               + ("" if manifest["peak_rss_mb"] is None else f"; peak memory {manifest['peak_rss_mb']:.0f} MB"))
