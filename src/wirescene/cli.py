"""The ``wirescene`` command: every stage composes into one CLI, each owning its options."""

from __future__ import annotations

import json
import os
import sys
from importlib import resources
from pathlib import Path

import click
import numpy as np

from . import __version__
from .errors import InputError, WiresceneError


class _Group(click.Group):
    """Turns our typed errors into one clean line and exit code 2."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except WiresceneError as exc:
            click.echo(f"wirescene: error: {exc}", err=True)
            sys.exit(2)


@click.group(cls=_Group)
@click.version_option(__version__, prog_name="wirescene")
def main():
    """Fine-grained 3D street-scene understanding from a single image."""


def sample_root() -> Path:
    """The KITTI-layout sample bundled with the package."""
    return Path(str(resources.files("wirescene") / "data" / "sample" / "kitti"))


def _progress(desc: str, total: int | None = None):
    from tqdm import tqdm

    return lambda it: tqdm(it, desc=desc, unit="frame", total=total, leave=False, file=sys.stderr)


def _fit_options(particles: int, seed: int, **inference):
    from .scene.fit import FitOptions
    from .scene.inference import InferenceOptions
    from .scene.lifting import LiftingOptions

    inference = {k: v for k, v in inference.items() if v is not None}
    if "device" in inference:
        inference["device"] = _resolve_device(inference["device"])
    return FitOptions(lifting=LiftingOptions(n_particles=particles), inference=InferenceOptions(**inference), seed=seed)


def _resolve_device(name: str) -> str:
    """The inference device for ``--device``: ``numpy``, or a PyTorch device name.
    ``auto`` takes a CUDA GPU when PyTorch and one are there, else numpy (PyTorch is
    imported only to look for the GPU, and only if it is installed)."""
    from . import torch_backend

    key = name.strip().lower()
    if key == "numpy":
        return "numpy"
    if key == "auto":
        if not torch_backend.available():
            return "numpy"
        return "cuda" if torch_backend.resolve_device("auto").type == "cuda" else "numpy"
    return str(torch_backend.resolve_device(key))


def _inference_options(f):
    """Options of the fine-grained inference stage, shared by `eval` and `fit`."""
    f = click.option("--device", default="auto", show_default=True,
                     help="Where the likelihood's ray casting runs: numpy, or PyTorch on cpu, cuda or cuda:N "
                          "(optional: pip install torch). auto: a CUDA GPU if PyTorch sees one, else numpy.")(f)
    f = click.option("--iterations", type=int, default=None, help="Inference iterations (Algorithm 1).")(f)
    f = click.option("--samples", type=int, default=None, help="Samples per object and iteration.")(f)
    f = click.option("--prune-after", type=int, default=None,
                     help="Keep only the best quarter of the particles after this many iterations (default 4; 0: never).")(f)
    f = click.option("--box-weight", type=float, default=None,
                     help="Weight of the detection box (KITTI convention) in the fine objective "
                          "(0: the paper's part likelihood only; default: InferenceOptions).")(f)
    f = click.option("--plane-refinement/--no-plane-refinement", default=None,
                     help="Sample the ground plane in the fine stage (default: InferenceOptions).")(f)
    return f


def _variants():
    from .scene.variants import VARIANTS

    return list(VARIANTS)


def _write_json_atomic(path: Path, data: dict) -> None:
    from .atomic import write_text

    write_text(path, json.dumps(data, indent=1))


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
@click.argument("kitti_root", type=click.Path(path_type=Path))
@click.option("--variant", "variants", multiple=True, type=click.Choice(_variants()), help="Model variant(s); default: all available.")
@click.option("--detections", default="gt", show_default=True,
              help="'gt' (label boxes), 'bank' (our pre-detection from raw pixels) or a directory of per-frame detection files.")
@click.option("--viewpoint-noise", default=0.0, show_default=True, help="Std. dev. (deg) of noise on the GT viewpoint before binning.")
@click.option("--frames", default=None, help="Comma-separated frame ids (default: all labelled frames).")
@click.option("--particles", default=250, show_default=True, help="Scene particles kept by the coarse stage.")
@click.option("--seed", default=0, show_default=True)
@click.option("--split", default="training", show_default=True)
@click.option("--json", "json_out", type=click.Path(path_type=Path), default=None, help="Write the metrics as JSON.")
@click.option("--predictions", type=click.Path(path_type=Path), default=None, help="Write KITTI label files per variant here.")
@click.option("--evidence", type=click.Choice(["parts", "oracle"]), default="parts", show_default=True,
              help="Evidence of the fine-grained variants: part detectors, or true vertices of synthetic scenes (upper bound).")
@click.option("--workers", type=int, default=None, help="Processes fitting frames in parallel (default: all cores).")
@click.option("--resume/--no-resume", default=False, show_default=True,
              help="Reuse the frames already finished in --predictions DIR (recorded in DIR/.frames/) and fit only the "
                   "rest; a record written with other settings is fitted again.")
@click.option("--dask", "dask_address", metavar="ADDRESS", default=None,
              help="Fit frames on this running Dask scheduler (e.g. tcp://host:8786) instead of local processes "
                   "(--workers is then ignored); needs wirescene[dask] and the data at the same path on the workers.")
@_inference_options
def eval_cmd(kitti_root, variants, detections, viewpoint_noise, frames, particles, seed, split, json_out, predictions, evidence,
             workers, resume, dask_address, iterations, samples, prune_after, box_weight, plane_refinement, device):
    """Evaluate model variants on a KITTI directory with the paper's protocol."""
    from .datasets.kitti import KittiDataset
    from .evaluate import format_table
    from .pipeline import DetectionSource, evaluate_dataset

    if resume and predictions is None:
        raise click.UsageError("--resume needs --predictions DIR, where finished frames are recorded")
    if dask_address is not None:
        # Dask workers may run elsewhere (another working directory): give them absolute paths.
        kitti_root = kitti_root.resolve()
        if detections not in ("gt", "bank"):
            detections = str(Path(detections).resolve())
    dataset = KittiDataset(kitti_root, split=split)
    variants = list(variants) or _variants()
    frame_ids = [f.strip() for f in frames.split(",")] if frames else None
    options = _fit_options(particles, seed, iterations=iterations, samples=samples, prune_after=prune_after,
                           box_weight=box_weight, plane_refinement=plane_refinement, device=device)
    on_gpu = options.inference.device.startswith("cuda")
    if on_gpu and (workers or 1) > 1:
        # Forked processes cannot share the parent's CUDA state; the GPU is the parallelism.
        raise click.UsageError("--device cuda fits frames in one process: drop --workers (or use --dask, one worker per GPU)")
    client = _dask_client(dask_address) if dask_address is not None else None
    try:
        reports = evaluate_dataset(
            dataset,
            variants,
            frames=frame_ids,
            source=DetectionSource(detections, viewpoint_noise),
            options=options,
            predictions_dir=predictions,
            resume=resume,
            evidence=evidence,
            workers=1 if on_gpu else workers or os.cpu_count() or 1,
            dask_client=client,
            progress=_progress("eval", len(frame_ids) if frame_ids else len(dataset.frame_ids())),
            notify=lambda message: click.echo(f"wirescene: {message}", err=True),
        )
    finally:
        if client is not None:
            client.close()
    # Table 3 needs per-vertex ground truth (synthetic scenes); KITTI has none.
    has_parts = any(np.isfinite(r.metrics["all"].get("occ_pred_acc", np.nan)) for r in reports.values())
    click.echo(format_table(reports, tables=("3d", "viewpoint", "2d") if has_parts else ("3d", "viewpoint")))
    if json_out is not None:
        data = {v: r.to_json_dict(include_records=True) for v, r in reports.items()}
        if len(variants) == 1:
            data = data[variants[0]]
        _write_json_atomic(json_out, data)
        click.echo(f"metrics written to {json_out}")


@main.command("fit")
@click.argument("image", type=click.Path(path_type=Path))
@click.option("--calib", type=click.Path(path_type=Path), required=True, help="KITTI calibration file (P2 is used).")
@click.option("--detections", type=click.Path(path_type=Path), default=None,
              help="2D car detections: .json, .csv or KITTI label .txt (see `wirescene.detect.read_detections`); "
                   "default: our own pre-detection from raw pixels.")
@click.option("--gt", type=click.Path(path_type=Path), default=None, help="KITTI label file drawn in green for comparison.")
@click.option("--variant", type=click.Choice(_variants()), default="coarse+gp", show_default=True)
@click.option("--particles", default=250, show_default=True)
@click.option("--seed", default=0, show_default=True)
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Output directory.")
@_inference_options
def fit_cmd(image, calib, detections, gt, variant, particles, seed, out, iterations, samples, prune_after, box_weight,
            plane_refinement, device):
    """Fit the scene model to one image; write KITTI labels, JSON, overlay and bird's-eye view."""
    from .camera import read_kitti_calib
    from .datasets.kitti import read_image, read_labels
    from .detect import read_detections
    from .pipeline import write_fit_outputs
    from .scene.fit import fit_scene

    img = read_image(image)
    camera = read_kitti_calib(calib).camera((img.shape[1], img.shape[0]))
    if detections is not None:
        dets = read_detections(detections)
    else:
        from .predetect import detect_cars

        dets = detect_cars(img)
        if len(dets) == 0:
            raise InputError("pre-detection found no car in the image", path=image)
    gt_objs = read_labels(gt).of_type("Car") if gt is not None else []
    options = _fit_options(particles, seed, iterations=iterations, samples=samples, prune_after=prune_after,
                           box_weight=box_weight, plane_refinement=plane_refinement, device=device)
    estimate = fit_scene(camera, dets, variant=variant, options=options, image=img)
    paths = write_fit_outputs(out, Path(image).stem, image=img, camera=camera, estimate=estimate, detections=dets, gt=gt_objs)
    for kind, p in paths.items():
        click.echo(f"{kind:8s} {p}")


@main.command("demo")
@click.option("--out", type=click.Path(path_type=Path), default=Path("wirescene_demo"), show_default=True)
@click.option("--particles", default=50, show_default=True, help="Scene particles (the paper used 250; fewer keep the demo short).")
@click.option("--variant", "variants", multiple=True, type=click.Choice(_variants()),
              default=("coarse", "coarse+gp", "fg+gp", "full"), show_default=True)
def demo_cmd(out, particles, variants):
    """Fit model variants to the bundled real KITTI frames, evaluate, write pictures."""
    import time

    from .datasets.kitti import KittiDataset
    from .evaluate import format_table
    from .pipeline import DetectionSource, evaluate_dataset, write_fit_outputs

    t0 = time.perf_counter()
    dataset = KittiDataset(sample_root())
    first = dataset.frame_ids()[0]
    written = []

    def draw(frame_id, variant, estimate, camera, detections, gt):
        if frame_id == first:
            paths = write_fit_outputs(out / variant, frame_id, image=dataset.image(frame_id), camera=camera,
                                      estimate=estimate, detections=detections, gt=gt.of_type("Car"))
            written.extend(paths.values())

    reports = evaluate_dataset(dataset, list(variants), source=DetectionSource("gt"), options=_fit_options(particles, 0),
                               progress=_progress("demo"), on_estimate=draw)
    # Raw-pixel mode: our own pre-detection instead of label boxes, then the full model.
    from .predetect import detect_cars
    from .scene.fit import fit_scene

    image = dataset.image(first)
    raw = detect_cars(image)
    if len(raw):
        estimate = fit_scene(dataset.camera(first), raw, variant="full", options=_fit_options(particles, 0), image=image)
        written.extend(write_fit_outputs(out / "raw-pixels", first, image=image, camera=dataset.camera(first),
                                         estimate=estimate, detections=raw, gt=dataset.labels(first).of_type("Car")).values())
    click.echo(f"raw-pixel mode on {first}: the detector bank found {len(raw)} cars "
               f"({len(dataset.labels(first).of_type('Car'))} labelled)\n")
    click.echo(f"wirescene {__version__} demo on bundled KITTI frames {', '.join(dataset.frame_ids())} "
               f"(GT boxes as pre-detections, {particles} particles)\n")
    click.echo(format_table(reports))
    _write_json_atomic(out / "eval.json", {v: r.to_json_dict(include_records=False) for v, r in reports.items()})
    click.echo("\nwritten:")
    for p in written + [out / "eval.json"]:
        click.echo(f"  {p}")
    click.echo(f"\ndone in {time.perf_counter() - t0:.1f} s")


@main.command("gt")
@click.argument("kitti_root", type=click.Path(path_type=Path))
@click.argument("frame")
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Output PNG.")
@click.option("--split", default="training", show_default=True)
def gt_cmd(kitti_root, frame, out, split):
    """Draw a frame's ground truth with the mean wireframe at every GT car pose
    (self-occluded vertices in blue): a check of geometry, shape model and labels."""
    from .datasets.kitti import KittiDataset
    from .groundplane import rotation_y, transform
    from .occlusion import self_occlusion
    from .scene.hypotheses import ObjectEstimate, SceneEstimate
    from .shape import load_default
    from .viz import overlay, save_figure
    from .wireframe import EDGES, FACES

    dataset = KittiDataset(kitti_root, split=split)
    camera = dataset.camera(frame)
    cars = dataset.labels(frame).of_type("Car")
    mean = load_default().mean
    objects = []
    for i, g in enumerate(cars):
        R = rotation_y(g.rotation_y)
        vertices = transform(mean, g.location, R)
        hidden = self_occlusion(vertices, FACES, camera.center)
        objects.append(ObjectEstimate(i, g.box, 1.0, g.location, R, g.dims, 0.0, vertices=vertices, visibility=~hidden))
    fig = overlay(dataset.image(frame), camera, SceneEstimate("gt", objects), gt=cars, edges=EDGES,
                  title=f"{frame}: mean wireframe at GT poses")
    click.echo(save_figure(fig, out))


def _register_optional_commands():
    """Attach the sub-commands of stages that define their own CLI pieces."""
    try:
        from .cad.commands import cad, shape
    except ImportError:  # stage not installed in this build
        return
    from .synth.commands import synth

    main.add_command(synth)
    main.add_command(cad)
    train = click.Group("train", help="Train the model's artefacts from documented data.")
    train.add_command(shape)
    from .parts_commands import parts
    from .predetect.commands import detect, detector

    from .occlusion_commands import occlusion

    train.add_command(parts)
    train.add_command(detector)
    train.add_command(occlusion)
    main.add_command(detect)
    main.add_command(train)


_register_optional_commands()

if __name__ == "__main__":  # pragma: no cover
    main()
