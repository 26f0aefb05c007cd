"""``wirescene train occlusion``: calibrate the occluded-part score ``c``."""

from __future__ import annotations

import sys
from pathlib import Path

import click


@click.command("occlusion")
@click.option("--seed", default=2000, show_default=True, help="Synthetic stream of the held-out scenes.")
@click.option("--scenes", default=30, show_default=True)
@click.option("--out", type=click.Path(path_type=Path), default=None, help="Default: the packaged data/occlusion.json.")
def occlusion(seed, scenes, out):
    """Choose the likelihood's occluded-part score c on held-out synthetic scenes."""
    from tqdm import tqdm

    from wirescene.infer.occluded_score import DEFAULT_PATH, save_occluded_score
    from wirescene.training.occlusion import calibrate_occluded_score

    result = calibrate_occluded_score(seed=seed, n_scenes=scenes,
                                      progress=lambda it: tqdm(it, desc="scenes", leave=False, file=sys.stderr))
    out = DEFAULT_PATH if out is None else out
    save_occluded_score(out, result)
    for c, a in zip(result["grid"], result["accuracy"]):
        click.echo(f"c = {c:+.2f}  occlusion accuracy {100 * a:.1f}%")
    click.echo(f"chosen c = {result['c']} ({result['n_cars']} cars; all-visible baseline "
               f"{100 * result['accuracy_all_visible']:.1f}%) -> {out}")
