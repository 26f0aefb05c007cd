"""Glue between the stages: run a variant over a dataset, turn estimates into KITTI
labels and evaluation records, and write the outputs of one fit."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from .atomic import write_text
from .camera import Camera
from .datasets.kitti import FrameLabels, KittiDataset, Label, write_labels
from .datasets.wireframes import WireframeGT, read_wireframe_gt, wireframe_gt_path
from .detect import detections_from_labels, read_detections
from .errors import InputError
from .evaluate import EvaluationReport, FrameResult, evaluate
from .scene.fit import FitOptions, fit_scene
from .scene.evidence import oracle_evidence, part_evidence, viewpoint_from_evidence
from .scene.lifting import lift_table
from .scene.variants import get_variant
from .shape import load_default as load_shape_model
from .scene.hypotheses import Detections, SceneEstimate
from .viz import birds_eye, overlay, save_figure
from .wireframe import EDGES


def estimate_to_labels(estimate: SceneEstimate, *, type_: str = "Car") -> list[Label]:
    """KITTI label rows (with score) for the objects of a scene estimate."""
    return [
        Label(
            type=type_,
            truncated=-1.0,
            occluded=-1,
            alpha=o.alpha,
            box=o.box2d,
            dims=o.dims,
            location=o.location,
            rotation_y=o.rotation_y,
            score=o.score,
        )
        for o in estimate.objects
    ]


def frame_result(
    frame_id: str,
    gt: FrameLabels,
    detections: Detections,
    estimate: SceneEstimate,
    vertex_gt: WireframeGT | None = None,
    camera: Camera | None = None,
) -> FrameResult:
    """Evaluation record of one frame (estimates aligned with detections); with
    ``vertex_gt`` (synthetic data) the occlusion subsets use true part counts."""
    objs = sorted(estimate.objects, key=lambda o: o.detection_index)
    if [o.detection_index for o in objs] != list(range(len(detections))):
        raise ValueError("estimate must hold exactly one object per detection")
    fine = camera is not None and objs and all(o.vertices is not None for o in objs)
    return FrameResult(
        frame_id=frame_id,
        gt=gt.objects,
        det_boxes=detections.boxes,
        det_alpha=detections.alpha,
        det_scores=detections.scores,
        est_location=np.array([o.location for o in objs]).reshape(-1, 3),
        est_dims=np.array([o.dims for o in objs]).reshape(-1, 3),
        est_rotation_y=np.array([o.rotation_y for o in objs]),
        est_alpha=np.array([o.alpha for o in objs]),
        est_occluded=np.array([~o.visibility for o in objs]) if fine else None,
        est_vertices_2d=np.array([camera.project(o.vertices) for o in objs]) if fine else None,
        gt_occluded_parts=None if vertex_gt is None else vertex_gt.occluded_parts,
        gt_vertices_2d=None if vertex_gt is None else vertex_gt.vertices_2d,
        gt_vertex_visible=None if vertex_gt is None else vertex_gt.visible,
        gt_self_occluded=None if vertex_gt is None else vertex_gt.self_occluded,
    )


@dataclass(frozen=True)
class DetectionSource:
    """Where pre-detections come from: ``"gt"`` (label boxes, noisy viewpoint bins),
    ``"bank"`` (our part-configuration detector bank on the raw image) or a directory of
    per-frame detection files (``FRAME.json``, ``.csv`` or ``.txt``)."""

    spec: str = "gt"
    viewpoint_noise_deg: float = 0.0

    def for_frame(self, dataset: KittiDataset, frame_id: str, rng: np.random.Generator) -> Detections:
        if self.spec == "gt":
            return detections_from_labels(dataset.labels(frame_id), viewpoint_noise_deg=self.viewpoint_noise_deg, rng=rng)
        if self.spec == "bank":
            from .predetect import detect_cars

            return detect_cars(dataset.image(frame_id))
        folder = Path(self.spec)
        if not folder.is_dir():
            raise InputError("detections must be 'gt', 'bank' or a directory of per-frame files", path=folder)
        for ext in (".json", ".csv", ".txt"):
            path = folder / f"{frame_id}{ext}"
            if path.is_file():
                try:
                    return read_detections(path)
                except InputError as exc:
                    if exc.problem == "no car detections in file":
                        return Detections.empty(str(path))
                    raise
        return Detections.empty(str(folder))


def frame_seed(seed: int, frame_id: str) -> np.random.Generator:
    """A generator that depends only on the run seed and the frame, so results do not
    depend on the order (or the process) in which frames are processed."""
    digits = int("".join(ch for ch in frame_id if ch.isdigit()) or 0)
    return np.random.default_rng([seed, digits])


@dataclass(frozen=True)
class _FrameJob:
    """Everything a (possibly separate) process needs to fit all variants on one frame."""

    dataset: KittiDataset
    variants: tuple
    source: DetectionSource
    options: FitOptions
    evidence: str

    def __call__(self, frame_id: str):
        dataset = self.dataset
        gt = dataset.labels(frame_id)
        gt_path = wireframe_gt_path(dataset.split_dir, frame_id)
        vertex_gt = read_wireframe_gt(gt_path) if gt_path.is_file() else None
        detections = self.source.for_frame(dataset, frame_id, frame_seed(self.options.seed, frame_id))
        camera = dataset.camera(frame_id)
        unknown_viewpoint = not np.all(np.isfinite(detections.alpha))
        frame_evidence = None
        if (unknown_viewpoint or any(get_variant(v).fine for v in self.variants)) and len(detections):
            if self.evidence == "oracle":
                if vertex_gt is None:
                    raise InputError("oracle evidence needs wireframes/ ground truth (synthetic scenes)", path=gt_path)
                frame_evidence = oracle_evidence(detections, np.array([o.box for o in gt.objects]).reshape(-1, 4), vertex_gt)
            else:
                frame_evidence = part_evidence(dataset.image(frame_id), detections)
        if unknown_viewpoint and frame_evidence is not None:
            detections = viewpoint_from_evidence(camera, detections, frame_evidence, load_shape_model())
        lifted = lift_table(camera, detections, options=self.options.lifting) if len(detections) else None
        fits = {}
        for v in self.variants:
            estimate = fit_scene(camera, detections, variant=v, options=self.options, lifted=lifted, evidence=frame_evidence)
            fits[v] = (estimate, frame_result(frame_id, gt, detections, estimate, vertex_gt, camera))
        return frame_id, camera, detections, gt, fits


def evaluate_dataset(
    dataset: KittiDataset,
    variants: Iterable[str],
    *,
    frames: Iterable[str] | None = None,
    source: DetectionSource = DetectionSource(),
    options: FitOptions = FitOptions(),
    predictions_dir: Path | None = None,
    evidence: str = "parts",
    workers: int = 1,
    progress: Callable[[Iterable], Iterable] = lambda it: it,
    on_estimate: Callable[..., None] | None = None,
) -> dict[str, EvaluationReport]:
    """Fit every variant on every frame and evaluate with the paper's protocol.

    With ``predictions_dir``, KITTI label files of each variant are written to
    ``predictions_dir/VARIANT/FRAME.txt``. ``evidence`` selects what the fine-grained
    variants fit to: ``"parts"`` (the part detectors, the real system) or ``"oracle"``
    (true vertex positions of synthetic scenes; needs ``wireframes/`` ground truth).
    ``workers > 1`` fits frames in that many processes; every frame draws its random
    numbers from (seed, frame id) alone, so the results equal the serial run's.
    ``on_estimate(frame_id, variant, estimate, camera, detections, gt)`` is called for
    every fit, e.g. to draw it.
    """
    if evidence not in ("parts", "oracle"):
        raise ValueError(f"evidence must be 'parts' or 'oracle', got {evidence!r}")
    if not dataset.has_labels:
        raise InputError("evaluation needs label_2/ ground truth", path=dataset.split_dir)
    variants = [get_variant(v).name for v in variants]
    frame_ids = list(frames) if frames is not None else dataset.frame_ids()
    job = _FrameJob(dataset, tuple(variants), source, options, evidence)
    results: dict[str, list[FrameResult]] = {v: [] for v in variants}
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        pool = ProcessPoolExecutor(max_workers=workers)
        outputs = pool.map(job, frame_ids)
    else:
        pool, outputs = None, map(job, frame_ids)
    try:
        for frame_id, camera, detections, gt, fits in progress(outputs):
            for v, (estimate, result) in fits.items():
                results[v].append(result)
                if on_estimate is not None:
                    on_estimate(frame_id, v, estimate, camera, detections, gt)
                if predictions_dir is not None:
                    write_labels(Path(predictions_dir) / v / f"{frame_id}.txt", estimate_to_labels(estimate))
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return {v: evaluate(results[v]) for v in variants}


def write_fit_outputs(
    out_dir: Path,
    stem: str,
    *,
    image: np.ndarray,
    camera: Camera,
    estimate: SceneEstimate,
    detections: Detections,
    gt: list[Label] = (),
) -> dict[str, Path]:
    """Write ``STEM.txt`` (KITTI labels), ``STEM.json``, ``STEM_overlay.png`` and
    ``STEM_bev.png``. Everything is rendered in memory first; if any write fails the
    files already written by this call are removed, so no partial result remains."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    payload = json.dumps({"frame": stem, "detections_source": detections.source, **estimate.to_dict()}, indent=1)
    fig_overlay = overlay(image, camera, estimate, gt=gt, detections=detections, title=f"{stem}  {estimate.variant}", edges=EDGES)
    fig_bev = birds_eye(estimate, gt=gt, camera=camera, title=f"{stem}  {estimate.variant}")
    paths = {
        "labels": out_dir / f"{stem}.txt",
        "json": out_dir / f"{stem}.json",
        "overlay": out_dir / f"{stem}_overlay.png",
        "bev": out_dir / f"{stem}_bev.png",
    }
    written: list[Path] = []
    try:
        write_labels(paths["labels"], estimate_to_labels(estimate))
        written.append(paths["labels"])
        write_text(paths["json"], payload)
        written.append(paths["json"])
        save_figure(fig_overlay, paths["overlay"])
        written.append(paths["overlay"])
        save_figure(fig_bev, paths["bev"])
        written.append(paths["bev"])
    except BaseException:
        for p in written:
            p.unlink(missing_ok=True)
        raise
    return paths
