"""Glue between the stages: run a variant over a dataset, turn estimates into KITTI
labels and evaluation records, and write the outputs of one fit."""

from __future__ import annotations

import itertools
import json
import sys
import uuid
from contextlib import ExitStack
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator

import numpy as np

from wirescene import __version__
from wirescene.core.artefacts import format_tag
from wirescene.core.atomic import write_text
from wirescene.core.camera import Camera
from wirescene.io.kitti import FrameLabels, KittiDataset, Label, format_labels, write_labels
from wirescene.io.wireframes import WireframeGT, read_wireframe_gt, wireframe_gt_path
from wirescene.io.detections import detections_from_labels, read_detections
from wirescene.core.errors import InputError
from wirescene.eval.metrics import EvaluationReport, FrameResult, evaluate
from wirescene.fitting.scene import FitOptions, fit_scene
from wirescene.infer.evidence import oracle_evidence, part_evidence, viewpoint_from_evidence
from wirescene.lift import lift_table
from wirescene.fitting.variants import get_variant
from wirescene.core.shape import load_default as load_shape_model
from wirescene.core.types import Detections, SceneEstimate
from wirescene.io.pictures import birds_eye, overlay, save_figure
from wirescene.core.wireframe import EDGES

if TYPE_CHECKING:  # an optional dependency, imported where dask mode runs
    from distributed import Client


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
            from wirescene.predetect import detect_cars

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


#: Where :func:`evaluate_dataset` keeps the record of each finished frame, under the
#: predictions directory (hidden, so KITTI tools that list ``VARIANT/*.txt`` ignore it).
RECORDS_DIR = ".frames"
_RECORD_FORMAT = format_tag("frame-record", 1)


def run_config(
    dataset: KittiDataset, variants: Iterable[str], source: DetectionSource, options: FitOptions, evidence: str
) -> dict:
    """Everything that determines a frame's fits, as stored in its resume record.

    Two runs with equal configurations give equal per-frame results (every frame draws
    its random numbers from the seed and its id alone), so a record is reused only when
    its configuration equals the current one. The package version stands in for the
    code; the content of a detections directory is not included.
    """
    spec = source.spec if source.spec in ("gt", "bank") else str(Path(source.spec).resolve())
    config = {
        "wirescene": __version__,
        "dataset": str(Path(dataset.split_dir).resolve()),
        # Per-variant fits do not depend on the order of the variants (fit_scene seeds
        # itself per call), but the set decides whether part evidence is computed.
        "variants": sorted(variants),
        "detections": {"spec": spec, "viewpoint_noise_deg": float(source.viewpoint_noise_deg)},
        "evidence": evidence,
        "options": asdict(options),
    }
    # Normalised through JSON (tuples become lists; anything else JSON cannot hold, as
    # its str) so that it compares equal to a stored one.
    return json.loads(json.dumps(config, default=str))


def _config_difference(stored, current, prefix: str = "") -> list[str]:
    """Dotted names of the settings in which two configurations differ."""
    if isinstance(stored, dict) and isinstance(current, dict):
        out = []
        for key in sorted(set(stored) | set(current), key=str):
            out += _config_difference(stored.get(key), current.get(key), f"{prefix}{key}.")
        return out
    return [] if stored == current else [prefix.rstrip(".")]


class _StaleRecord(Exception):
    """A frame record that cannot be reused (the message says why)."""


class _FrameRecords:
    """The resume records of one predictions directory: ``DIR/.frames/FRAME.json`` holds
    the configuration and, per variant, the frame's :class:`FrameResult` and its KITTI
    label text. A record is written (atomically) only after the frame's label files, so
    its presence means the frame is complete."""

    def __init__(self, predictions_dir: Path, config: dict):
        self.root = Path(predictions_dir)
        self.config = config

    def path(self, frame_id: str) -> Path:
        return self.root / RECORDS_DIR / f"{frame_id}.json"

    def labels_path(self, variant: str, frame_id: str) -> Path:
        return self.root / variant / f"{frame_id}.txt"

    def save(self, frame_id: str, fits: dict[str, tuple[str, FrameResult]]) -> None:
        """Write the label files of every variant, then the record."""
        for v, (labels, _) in fits.items():
            write_text(self.labels_path(v, frame_id), labels)
        record = {
            "format": _RECORD_FORMAT,
            "frame": frame_id,
            "config": self.config,
            "variants": {v: {"labels": labels, "result": result.to_dict()} for v, (labels, result) in fits.items()},
        }
        write_text(self.path(frame_id), json.dumps(record))

    def load(self, frame_id: str) -> dict[str, tuple[str, FrameResult]] | None:
        """The frame's label text and result per variant; ``None`` without a record.

        Raises
        ------
        _StaleRecord
            If the record is unreadable, of another frame or format, or was written with
            a different configuration.
        """
        path = self.path(frame_id)
        if not path.is_file():
            return None
        try:
            record = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise _StaleRecord(f"unreadable ({exc.__class__.__name__})") from None
        if not isinstance(record, dict) or record.get("format") != _RECORD_FORMAT or record.get("frame") != frame_id:
            raise _StaleRecord("not a record of this frame")
        if record.get("config") != self.config:
            changed = _config_difference(record.get("config"), self.config)
            raise _StaleRecord(f"written with a different configuration ({', '.join(changed) or 'config'})")
        try:
            variants = record["variants"]
            fits = {v: (str(variants[v]["labels"]), FrameResult.from_dict(variants[v]["result"]))
                    for v in self.config["variants"]}
        except (KeyError, TypeError, ValueError) as exc:
            raise _StaleRecord(f"malformed ({' '.join(str(exc).split())})") from None
        return fits

    def restore_labels(self, frame_id: str, fits: dict[str, tuple[str, FrameResult]]) -> None:
        """Rewrite label files of a reused frame that have gone missing since."""
        for v, (labels, _) in fits.items():
            path = self.labels_path(v, frame_id)
            if not path.is_file():
                write_text(path, labels)


def _fit_frames(
    job: _FrameJob, frame_ids: list[str], *, workers: int, dask_client: str | Client | None, stack: ExitStack
) -> Iterator:
    """Outputs of ``job`` on ``frame_ids`` as the frames finish: serially, in ``workers``
    processes, or on a Dask cluster (``dask_client``: its address or a
    ``distributed.Client``). Pools and futures are released when ``stack`` closes."""
    if not frame_ids:
        return iter(())
    if dask_client is not None:
        return _fit_frames_dask(job, frame_ids, dask_client, stack)
    if workers > 1 and len(frame_ids) > 1:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        pool = ProcessPoolExecutor(max_workers=min(workers, len(frame_ids)))
        stack.callback(pool.shutdown, cancel_futures=True)
        # As completed rather than in order: a finished frame is recorded at once, so an
        # interrupted run loses only the frames still being fitted.
        return (future.result() for future in as_completed([pool.submit(job, f) for f in frame_ids]))
    return map(job, frame_ids)


def _fit_frames_dask(job: _FrameJob, frame_ids: list[str], dask_client: str | Client, stack: ExitStack) -> Iterator:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ImportError("dask mode needs the 'distributed' package: pip install wirescene[dask]") from None
    client = dask_client
    if not isinstance(client, Client):
        client = Client(dask_client, set_as_default=False)
        stack.callback(client.close)
    # Unique keys per run and position (a fit is not a pure function of its arguments'
    # tokens: it reads files), named by frame for the dashboard.
    token = uuid.uuid4().hex[:8]
    futures = client.map(job, frame_ids, key=[f"wirescene-frame-{f}-{token}-{i}" for i, f in enumerate(frame_ids)])
    pending = set(futures)
    # Unfinished tasks must not keep running on a shared cluster after an error.
    stack.callback(lambda: pending and client.cancel(list(pending)))
    del futures

    def results():
        # The client is not the default one (set_as_default=False): name its loop.
        for future in as_completed(pending.copy(), loop=client.loop):
            output = future.result()
            pending.discard(future)  # lets the cluster drop the result
            yield output

    return results()


def evaluate_dataset(
    dataset: KittiDataset,
    variants: Iterable[str],
    *,
    frames: Iterable[str] | None = None,
    source: DetectionSource = DetectionSource(),
    options: FitOptions = FitOptions(),
    predictions_dir: Path | None = None,
    resume: bool = False,
    evidence: str = "parts",
    workers: int = 1,
    dask_client: str | Client | None = None,
    progress: Callable[[Iterable], Iterable] = lambda it: it,
    on_estimate: Callable[..., None] | None = None,
    notify: Callable[[str], None] | None = None,
) -> dict[str, EvaluationReport]:
    """Fit every variant on every frame and evaluate with the paper's protocol.

    Parameters
    ----------
    dataset : KittiDataset
        A split with ``label_2/`` ground truth.
    variants : iterable of str
        Model variants, see :data:`wirescene.fitting.variants.VARIANTS`.
    frames : iterable of str, optional
        Frame ids; default all labelled frames.
    source : DetectionSource
        Where the pre-detections come from.
    options : FitOptions
        Options of every stage, with the run's seed.
    predictions_dir : path, optional
        Write KITTI label files of each variant to ``predictions_dir/VARIANT/FRAME.txt``
        and, once a frame is complete, its resume record to
        ``predictions_dir/.frames/FRAME.json`` (configuration, per-variant
        :class:`FrameResult` and label text; see :func:`run_config`).
    resume : bool
        Reuse the records in ``predictions_dir`` instead of fitting those frames again;
        needs ``predictions_dir``. A record written with a different configuration, or
        unreadable, is not reused: its frame is fitted again (and ``notify`` told).
        Reused frames give exactly the results of fitting them again.
    evidence : {"parts", "oracle"}
        What the fine-grained variants fit to: the part detectors (the real system) or
        true vertex positions of synthetic scenes (needs ``wireframes/`` ground truth).
    workers : int
        ``> 1`` fits frames in that many processes.
    dask_client : str or distributed.Client, optional
        Fit frames on this Dask cluster (a scheduler address or a connected client)
        instead; ``workers`` is then ignored. The workers must be able to import
        wirescene and read the dataset at the same path (shared filesystem); outputs
        are written by this process.
    progress : callable
        Wraps an iterable with one item per frame (reused frames first, then fitted
        frames as they finish), e.g. a progress bar.
    on_estimate : callable, optional
        ``on_estimate(frame_id, variant, estimate, camera, detections, gt)``, called
        for every fit (not for reused frames, whose estimates are not stored) as frames
        finish, e.g. to draw it.
    notify : callable, optional
        Receives one-line messages on reused and refitted frames; default: standard error.

    Returns
    -------
    dict
        ``{variant: EvaluationReport}``. Every frame draws its random numbers from (seed,
        frame id) alone and the reports list frames in the order of ``frames``, so
        serial, process, Dask and resumed runs give identical reports.
    """
    if evidence not in ("parts", "oracle"):
        raise ValueError(f"evidence must be 'parts' or 'oracle', got {evidence!r}")
    if resume and predictions_dir is None:
        raise ValueError("resume needs predictions_dir, where finished frames are recorded")
    if not dataset.has_labels:
        raise InputError("evaluation needs label_2/ ground truth", path=dataset.split_dir)
    if notify is None:
        notify = _notify_stderr
    variants = [get_variant(v).name for v in variants]
    frame_ids = list(frames) if frames is not None else dataset.frame_ids()
    job = _FrameJob(dataset, tuple(variants), source, options, evidence)
    records = None
    if predictions_dir is not None:
        records = _FrameRecords(Path(predictions_dir), run_config(dataset, variants, source, options, evidence))
    by_frame: dict[str, dict[str, FrameResult]] = {}
    reused: dict[str, dict[str, tuple[str, FrameResult]]] = {}
    if resume:
        stale = []
        for frame_id in frame_ids:
            try:
                fits = records.load(frame_id)
            except _StaleRecord as exc:
                stale.append((records.path(frame_id), str(exc)))
                continue
            if fits is not None:
                reused[frame_id] = fits
        if stale:
            more = f" (and {len(stale) - 1} more)" if len(stale) > 1 else ""
            notify(f"refitting {len(stale)} frame(s) whose record cannot be reused: {stale[0][0]} {stale[0][1]}{more}")
        if reused:
            notify(f"resuming: {len(reused)} of {len(frame_ids)} frames already done in {records.root}")
    todo = [f for f in frame_ids if f not in reused]

    with ExitStack() as stack:
        fitted = _fit_frames(job, todo, workers=workers, dask_client=dask_client, stack=stack)
        # Reused frames go through `progress` too, so a bar counts every frame.
        items = itertools.chain(((f, None) for f in reused), ((out[0], out) for out in fitted))
        for frame_id, output in progress(items):
            if output is None:
                by_frame[frame_id] = {v: result for v, (_, result) in reused[frame_id].items()}
                records.restore_labels(frame_id, reused[frame_id])
                continue
            _, camera, detections, gt, fits = output
            by_frame[frame_id] = {v: result for v, (_, result) in fits.items()}
            if on_estimate is not None:
                for v, (estimate, _) in fits.items():
                    on_estimate(frame_id, v, estimate, camera, detections, gt)
            if records is not None:
                labels = {v: format_labels(estimate_to_labels(estimate)) for v, (estimate, _) in fits.items()}
                records.save(frame_id, {v: (labels[v], result) for v, (_, result) in fits.items()})
    # Frames finish in any order; the reports list them in the given order.
    return {v: evaluate([by_frame[f][v] for f in frame_ids]) for v in variants}


def _notify_stderr(message: str) -> None:
    print(f"wirescene: {message}", file=sys.stderr)


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
