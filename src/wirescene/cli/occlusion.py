"""``wirescene train occlusion``: calibrate the occluded-part score ``c``."""

from __future__ import annotations

from pathlib import Path

import click

from wirescene.cli.options import (
    NON_NEGATIVE,
    NonEmptyPath,
    check_output_file,
    models_option,
    progress_bar,
    say_models,
)
from wirescene.training.scale import MAX_OCCLUSION_SCENES


@click.command("occlusion")
@click.option("--seed", type=NON_NEGATIVE, default=2000, show_default=True, help="Synthetic stream of the held-out scenes.")
@click.option("--scenes", type=click.IntRange(min=1, max=MAX_OCCLUSION_SCENES), default=30, show_default=True,
              help=f"Held-out synthetic scenes scored (at most {MAX_OCCLUSION_SCENES:,}: some 1.6 s each).")
@click.option("--out", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="Record to write (the shipped one is src/wirescene/data/occlusion.json).")
@click.option("--flip-evidence/--no-flip-evidence", default=False, show_default=True,
              help="Also read each box's part evidence off its mirror image, as the fit does by default "
                   "(the shipped c was chosen without; benchmarks/RESULTS.md, 'c = 0.5 with the mirrored evidence').")
@models_option
@click.option("--parts-model", type=NonEmptyPath(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Part detector file whose evidence is scored (default: --models' or the shipped model), e.g. one "
                   "of `wirescene train parts`.")
def occlusion(seed, scenes, out, flip_evidence, models, parts_model):
    """Choose the likelihood's occluded-part score c on held-out synthetic scenes, with
    the part detectors of --parts-model or --models (default: the shipped ones)."""
    from wirescene.core.resources import resolve_models
    from wirescene.infer.occluded_score import save_occluded_score
    from wirescene.parts.detector import PartDetector
    from wirescene.training.occlusion import calibrate_occluded_score

    check_output_file(out, "--out")
    found = resolve_models(models)
    detector = PartDetector.load(parts_model if parts_model is not None else found.path("parts_model"))
    # once its part model is read (a broken one: the error line alone)
    say_models(found, replaced=["parts_model"] if parts_model is not None else [])
    result = calibrate_occluded_score(seed=seed, n_scenes=scenes, detector=detector, flip=flip_evidence,
                                      progress=lambda it: progress_bar(it, "scenes"))
    save_occluded_score(out, result)
    for c, a in zip(result["grid"], result["accuracy"]):
        click.echo(f"c = {c:+.2f}  occlusion accuracy {100 * a:.1f}%")
    click.echo(f"chosen c = {result['c']} ({result['n_cars']} cars; all-visible baseline "
               f"{100 * result['accuracy_all_visible']:.1f}%) -> {out}")
