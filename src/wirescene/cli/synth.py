"""``wirescene synth``: write synthetic street scenes with full ground truth."""

from __future__ import annotations

import re
from pathlib import Path

import click

from wirescene.cli.options import NonEmptyPath, check_output_dir, progress_bar
from wirescene.core.atomic import replaced_dir
from wirescene.core.errors import WiresceneError

MAX_CARS = 1000
#: Most scenes of one set: some 0.8 s and 0.9 MB of disk a scene (memory does not grow), so the cap
#: is about 22 hours and 90 GB; KITTI's six-digit frame ids would end at 1,000,000.
MAX_SCENES = 100_000


def _parse_range(value: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", value or "")
    if not m:
        raise click.BadParameter(f"expected A-B or N (e.g. 2-8), got {value!r}", param_hint="--cars-per-scene")
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    if not 1 <= a <= b <= MAX_CARS:  # a street holds some 20 cars: more only asks the layout in vain
        raise click.BadParameter(f"need 1 <= A <= B <= {MAX_CARS}, got {value!r}", param_hint="--cars-per-scene")
    return a, b


@click.command("synth")
@click.argument("out_dir", type=NonEmptyPath(file_okay=False))
@click.option("--scenes", default=10, show_default=True, type=click.IntRange(min=1, max=MAX_SCENES),
              help=f"Number of scenes (at most {MAX_SCENES:,}: about 0.8 s and 0.9 MB each).")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
              help="Random seed; scene i is drawn from (seed, i).")
@click.option("--cars-per-scene", "cars", default="2-8", show_default=True,
              help="Number of cars per scene, A-B (fewer only if the street has no room).")
@click.option("--occluders/--no-occluders", default=True, show_default=True,
              help="Add 0-3 unmodelled occluders (poles, boxes, bushes) per scene.")
@click.option("--overwrite", is_flag=True, default=False,
              help="Replace the scenes already in OUT_DIR/training (otherwise a non-empty one is an error); "
                   "they are removed only once the new set is complete.")
def synth(out_dir, scenes, seed, cars, occluders, overwrite):
    """Generate synthetic KITTI-layout scenes in OUT_DIR/training: image_2, label_2,
    calib, edges_2 (edge renderings) and wireframes (per-car 36-vertex ground truth with
    per-vertex visibility). The set appears whole or not at all: an interrupted or failed
    run leaves OUT_DIR as it was."""
    from wirescene.synth.generate import generate_dataset

    rng_cars = _parse_range(cars)
    check_output_dir(Path(out_dir), "OUT_DIR")
    split = Path(out_dir) / "training"
    if split.exists() and not split.is_dir():  # not scenes: --overwrite would remove it
        raise click.BadParameter(f"{split} is a file, not a folder of scenes (move it or give another directory)",
                                 param_hint="OUT_DIR")
    if split.is_dir() and any(split.iterdir()):
        if not overwrite:
            raise click.BadParameter(f"{split} already holds scenes; stale ones would mix with new ones "
                                     "(use --overwrite or another directory)", param_hint="OUT_DIR")
    try:
        with replaced_dir(split) as staging:
            ids = generate_dataset(
                staging.parent, scenes, seed, cars=rng_cars, occluders=occluders, split=staging.name,
                progress=lambda it: progress_bar(it, "synth", unit="scene"),
            )
    except WiresceneError as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(f"wrote {len(ids)} scenes to {split}")
