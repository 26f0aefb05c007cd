"""``wirescene train scores``: fit the calibrated confidence written with every car."""

from __future__ import annotations

from pathlib import Path

import click

from wirescene.cli.options import NonEmptyPath, check_output_file, select_frames, split_file_option


@click.command("scores")
@click.argument("predictions_dirs", nargs=-1, required=True, type=NonEmptyPath(directory=True, path_type=Path))
@click.option("--frames", default=None, help="Comma-separated frame ids to train on (default: every record).")
@split_file_option
@click.option("--out", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="Calibration to write (the shipped one is src/wirescene/data/score_calibration.json).")
@click.option("--right", type=click.Choice(["iou", "1m"]), default="iou", show_default=True,
              help="When the confidence calls a car right: its 3D box overlaps the labelled car's at IoU > 0.7 "
                   "(KITTI's rule for cars) or its centre lies within 1 m (the paper's).")
def scores(predictions_dirs, frames, split_file, out, right):
    """Fit the confidence model on the frame records of evaluation runs on labelled
    real frames (`wirescene eval ROOT --variant coarse+gp --variant full --raw-scores
    --predictions DIR`; e.g. one run with label boxes and one with `--detections bank`),
    and the model of which fitted cars stand on a car on the runs with our own
    pre-detections (`--detections bank`, at least one needed)."""
    from wirescene.core.errors import InputError
    from wirescene.eval.records import RECORDS_DIR
    from wirescene.fitting.confidence import save_score_calibration
    from wirescene.training.scores import fit_score_calibration, read_run_sources

    check_output_file(out, "--out")
    seen: dict = {}
    for folder in predictions_dirs:  # a run given twice would count every record twice
        first = seen.setdefault(Path(folder).resolve(), folder)
        if first is not folder:
            raise InputError(f"evaluation run given twice (as {first} and {folder})", path=folder)
    recorded = sorted({p.stem for folder in predictions_dirs for p in (Path(folder) / RECORDS_DIR).glob("*.json")})
    where = ", ".join(str(d) for d in predictions_dirs)
    frame_ids = select_frames(frames, split_file, recorded, where=where, what="frame record") if recorded else None
    records: dict = {}
    own: dict = {}
    for folder in predictions_dirs:
        sources = read_run_sources(folder, frame_ids)
        for source, by_variant in sources.items():
            for variant, results in by_variant.items():
                old = next((r for r in results if r.image_size is None), None)
                if old is not None:  # the confidence's features need it
                    raise InputError("frame record without the image size (written by an older wirescene): evaluate "
                                     "again", path=Path(folder) / RECORDS_DIR / f"{old.frame_id}.json")
                records.setdefault(variant, []).extend(results)
                if source == "detections":
                    own.setdefault(variant, []).extend(results)
    if not own:
        raise InputError("no run on our own pre-detections (`--detections bank`): the car model needs one",
                         path=Path(predictions_dirs[0]))
    result = fit_score_calibration(records, car_records=own, right=right)
    result["trained_on"] = {"runs": [f"{Path(d).parent.name}/{Path(d).name}" for d in predictions_dirs],
                            "frames": sorted({r.frame_id for rs in records.values() for r in rs})}
    save_score_calibration(out, result)
    for stage in ("coarse", "fine"):
        for m, what in ((result[stage], "right"), (result["car"][stage], "on a car")):
            click.echo(f"{stage}: {m['n']} estimates, {100 * m['positive_rate']:.0f}% {what}; weights "
                       + ", ".join(f"{f} {w:+.2f}" for f, w in zip(m["features"], m["weights"])))
    click.echo(f"-> {out}")
