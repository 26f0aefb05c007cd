"""``wirescene info``: what a run here depends on beside the code (packages, BLAS kernels,
the ray tracer, every model and data file with its hash), for bug reports and for
comparing a machine with the one whose figures the README gives."""

from __future__ import annotations

import os
from pathlib import Path

import click

from wirescene.cli.options import NonEmptyPath, check_output_file, models_option, say_models


def info_record(models) -> dict:
    """The environment (:func:`wirescene.core.version.environment`), the optional packages,
    ``OPENBLAS_CORETYPE``, the ray tracer and the files of ``models``
    (:func:`wirescene.core.resources.artefact_files`)."""
    from wirescene.core.raycast import has_embree
    from wirescene.core.resources import artefact_files
    from wirescene.core.version import environment, package_versions

    return {"environment": environment(), "optional": package_versions(("torch", "dask", "distributed")),
            "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE"),
            "ray_tracer": "embree" if has_embree() else None,
            "models": models.describe(), "files": artefact_files(models)}


def _size(n: int) -> str:
    return f"{n / 1e6:.2f} MB" if n >= 1e6 else f"{n / 1e3:.1f} kB"


def _lines(record: dict) -> list[str]:
    env = record["environment"]
    packages = ", ".join(f"{k} {v or '-'}" for k, v in env.items() if k not in ("wirescene", "python", "blas"))
    optional = ", ".join(f"{k} {v or 'not installed'}" for k, v in record["optional"].items())
    blas = "; ".join(f"{b['library']} {b['version']}, kernels {b['kernels']}" for b in env["blas"] or []) or "unknown"
    coretype = record["openblas_coretype"]
    lines = [f"wirescene {env['wirescene']} (Python {env['python']})", f"packages: {packages}",
             f"optional: {optional}",
             f"BLAS: {blas}" + (f" (OPENBLAS_CORETYPE={coretype})" if coretype else ""),
             f"ray tracer: {record['ray_tracer'] or 'none (rendering and training parts need embreex)'}",
             f"models: {record['models']}"]
    width = max(len(f["file"]) for f in record["files"])
    for f in record["files"]:
        lines.append(f"  {f['file']:<{width}}  {f['source']:<7}  {_size(f['bytes']):>8}  sha256 {f['sha256'][:16]}  "
                     f"{f['format'] or '(no format tag)'}")
    return lines


@click.command("info")
@models_option
@click.option("--json", "json_out", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="Also write the record as JSON (full hashes and paths).")
def info(models, json_out):
    """Print the versions, BLAS kernels and model files a run here uses.

    The trained files and the figures of the README depend on them (another CPU's BLAS
    kernels train other models in their last digits): attach this to a bug report, or
    compare it with the environment a run or a training recorded."""
    from wirescene.core.resources import resolve_models

    check_output_file(json_out, "--json")
    models = resolve_models(models)
    record = info_record(models)  # reads every file: a corrupt one is the only line, said before any other
    say_models(models)
    click.echo("\n".join(_lines(record)))
    if json_out is not None:
        from wirescene.core.jsonio import write_json

        write_json(json_out, record)
        click.echo(f"written: {json_out}")
