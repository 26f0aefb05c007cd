"""Fit model variants over a dataset and evaluate them with the paper's protocol:
where each frame's pre-detections come from, the per-frame job (one call of
:func:`wirescene.fitting.pipeline.fit_frame`), serial / process-pool / Dask
scheduling, and resuming from the records of :mod:`wirescene.eval.records`."""

from __future__ import annotations

import itertools
import os
import signal
import sys
import threading
import time
import uuid
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator, Mapping

import numpy as np

from wirescene.core.camera import Camera
from wirescene.core.errors import ArgumentError, InputError
from wirescene.core.types import Detections, SceneEstimate, fitted_detections  # not io.outputs: it imports matplotlib
from wirescene.core.validate import output_dir_problem
from wirescene.core.workers import end_on_stop_signals, usable_cores
from wirescene.eval.held_out import trained_on_frames
from wirescene.eval.metrics import EvaluationReport, FrameResult, evaluate
from wirescene.eval.records import (
    FrameRecords,
    StaleRecord,
    refuse_predictions_dir,
    run_config,
)
from wirescene.eval.sources import DetectionSource, frame_seed
from wirescene.fitting.models import model_files_read
from wirescene.fitting.options import FitOptions
from wirescene.fitting.pipeline import fit_frame, needs_evidence
from wirescene.fitting.variants import get_variant
from wirescene.infer.evidence import oracle_evidence
from wirescene.infer.torch_backend import TORCH_THREADS_ENV
from wirescene.io.detections import detections_from_labels
from wirescene.io.kitti import FrameLabels, KittiDataset, as_frame_ids
from wirescene.io.wireframes import WireframeGT, read_wireframe_gt, wireframe_gt_path

if TYPE_CHECKING:  # an optional dependency, imported where dask mode runs
    from distributed import Client


def frame_result(
    frame_id: str,
    gt: FrameLabels,
    detections: Detections,
    estimate: SceneEstimate,
    vertex_gt: WireframeGT | None = None,
    camera: Camera | None = None,
) -> FrameResult:
    """Evaluation record of one frame: the estimates with the detections they were fitted
    to (those the fit's verification dropped are left out, as from its output); with
    ``vertex_gt`` (synthetic data) the occlusion subsets use true part counts.

    Examples
    --------
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import ObjectEstimate
    >>> dets = Detections([[300, 180, 520, 300], [600, 170, 680, 230]], scores=[0.9, 0.4], alpha=0.0)
    >>> car = ObjectEstimate(detection_index=0, box2d=dets.boxes[0], score=0.8, location=np.array([-2.0, 1.65, 12.0]),
    ...                      R=rotation_y(0.3), dims=np.array([1.5, 1.6, 3.9]), cost=0.1)
    >>> record = frame_result("000001", FrameLabels(), dets, SceneEstimate(variant="coarse", objects=[car]))
    >>> record.n_detections, record.det_boxes.tolist(), record.est_score.tolist()  # detection 1 was dropped
    (1, [[300.0, 180.0, 520.0, 300.0]], [0.8])
    """
    objs = sorted(estimate.objects, key=lambda o: o.detection_index)
    kept = np.array([o.detection_index for o in objs], dtype=int)
    if len(np.unique(kept)) != len(kept) or (len(kept) and (kept.min() < 0 or kept.max() >= len(detections))):
        raise ValueError("estimate must hold at most one object per detection")
    detections = fitted_detections(detections, estimate)
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
        est_cost=np.array([o.cost for o in objs]),
        est_score=np.array([o.score for o in objs]),
        image_size=None if camera is None or camera.image_size is None else tuple(int(v) for v in camera.image_size),
    )


#: Why a frame without per-vertex ground truth cannot be fitted to the oracle's evidence.
ORACLE_NEEDS = "oracle evidence needs wireframes/ ground truth (synthetic scenes)"


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
        detections = self.source.for_frame(dataset, frame_id, frame_seed(self.options.seed, frame_id),
                                           predetect=self.options.predetect, lifting=self.options.lifting)
        camera = dataset.camera(frame_id)
        image = evidence = None
        if needs_evidence(detections, self.variants):
            if self.evidence == "oracle":
                if vertex_gt is None:
                    raise InputError(ORACLE_NEEDS, path=gt_path)
                evidence = oracle_evidence(detections, np.array([o.box for o in gt.objects]).reshape(-1, 4), vertex_gt)
            else:
                image = dataset.image(frame_id)
        fitted = fit_frame(camera, detections, self.variants, image=image, evidence=evidence, options=self.options,
                           own=self.source.own)
        fits = {v: (estimate, frame_result(frame_id, gt, fitted.detections, estimate, vertex_gt, camera))
                for v, estimate in fitted.estimates.items()}
        return frame_id, camera, fitted.detections, gt, fits


def _worker_init(parent: int, threads: int) -> None:
    """Worker initializer: end with the parent (:func:`_die_with_parent`), leave Ctrl-C to
    the parent (which stops the pool: a worker interrupted in its queue's read hung a
    second Ctrl-C), end at once on SIGTERM, and let a PyTorch the parent imported use the
    worker's share of the cores (each worker taking them all made ``--device cpu`` 3-4x
    slower)."""
    _die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    end_on_stop_signals()
    os.environ[TORCH_THREADS_ENV] = str(threads)  # read where PyTorch is imported later (spawned workers)
    torch = sys.modules.get("torch")
    if torch is not None:  # imported before the fork
        torch.set_num_threads(threads)


def _die_with_parent(parent: int) -> None:
    """Worker initializer: end this worker when the process that started it is gone,
    even if it was killed (SIGKILL leaves no chance to shut the pool down). Linux gets
    the kernel's parent-death signal; elsewhere a daemon thread polls the parent id."""
    if sys.platform.startswith("linux"):  # elsewhere there is no prctl (and on Windows no CDLL(None))
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            PR_SET_PDEATHSIG = 1
            if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0 and os.getppid() == parent:
                return
        except (OSError, AttributeError, TypeError):
            pass

    def watch():
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="wirescene-parent-watch").start()


def fit_frames(
    job: Callable, frame_ids: list[str], *, workers: int, dask_client: str | Client | None, stack: ExitStack
) -> Iterator:
    """Outputs of ``job`` on ``frame_ids`` as the frames finish: serially, in ``workers``
    processes, or on a Dask cluster (``dask_client``: its address or a
    ``distributed.Client``). Pools and futures are released when ``stack`` closes.

    Examples
    --------
    >>> from contextlib import ExitStack
    >>> with ExitStack() as stack:  # one worker: the frames in order, in this process
    ...     list(fit_frames(str.upper, ["000001", "00000a"], workers=1, dask_client=None, stack=stack))
    ['000001', '00000A']
    """
    if not frame_ids:
        return iter(())
    if dask_client is not None:
        return _fit_frames_dask(job, frame_ids, dask_client, stack)
    if workers > 1 and len(frame_ids) > 1:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        n = min(workers, len(frame_ids))
        pool = ProcessPoolExecutor(max_workers=n, initializer=_worker_init,
                                   initargs=(os.getpid(), max(1, usable_cores() // n)))
        stack.push(_pool_closer(pool))
        # As completed rather than in order: a finished frame is recorded at once, so an
        # interrupted run loses only the frames still being fitted.
        return (future.result() for future in as_completed([pool.submit(job, f) for f in frame_ids]))
    return map(job, frame_ids)


def _pool_closer(pool):
    """An exit callback of ``pool``: shut down when the frames are done; on an error or
    Ctrl-C its workers end at once, the frames they are fitting not waited for."""

    def close(exc_type, exc, tb) -> bool:
        if exc_type is None:
            pool.shutdown(cancel_futures=True)
            return False
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.kill()  # workers write no file (results come back through the pool); SIGTERM may be handled
        pool.shutdown(wait=False, cancel_futures=True)
        return False

    return close


def _fit_frames_dask(job, frame_ids: list[str], dask_client: str | Client, stack: ExitStack) -> Iterator:
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
    frames: Iterable[str | int] | str | int | None = None,
    source: DetectionSource | None = None,
    options: FitOptions | None = None,
    predictions_dir: str | Path | None = None,
    resume: bool = False,
    evidence: str = "parts",
    workers: int = 1,
    dask_client: str | Client | None = None,
    progress: Callable[[Iterable], Iterable] = lambda it: it,
    on_estimate: Callable[..., None] | None = None,
    notify: Callable[[str], None] | None = None,
    check_images: bool = False,
    held_out: Callable[[str], None] | None = None,
) -> dict[str, EvaluationReport]:
    """Fit every variant on every frame and evaluate with the paper's protocol.

    Parameters
    ----------
    dataset : KittiDataset
        A split with ``label_2/`` ground truth.
    variants : iterable of str
        Model variants, see :data:`wirescene.fitting.variants.VARIANTS`.
    frames : str, int or iterable of them, optional
        Frame ids, an int written ``%06d`` as :class:`~wirescene.io.kitti.KittiDataset` reads it
        (:func:`~wirescene.io.kitti.as_frame_ids`; each frame once); default all labelled frames.
    source : DetectionSource
        Where the pre-detections come from.
    options : FitOptions
        Options of every stage, with the run's seed.
    predictions_dir : path, optional
        Write KITTI label files of each variant to ``predictions_dir/VARIANT/FRAME.txt``
        and, once a frame is complete, its resume record to
        ``predictions_dir/.frames/FRAME.json`` (configuration, per-variant
        :class:`FrameResult` and label text; see :func:`run_config`, with the content hashes
        of the trained artefacts the fit reads, :func:`~wirescene.fitting.models.models_fingerprint`).
    resume : bool
        Reuse the records in ``predictions_dir`` instead of fitting those frames again;
        needs ``predictions_dir``. A record written with a different configuration, or
        unreadable, is not reused: its frame is fitted again (and ``notify`` told).
        Reused frames give exactly the results of fitting them again. The earlier run's
        frames must be among ``frames`` (a larger selection continues it; a smaller one is
        refused, :func:`~wirescene.eval.records.refuse_records_outside`).
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
    check_images : bool
        Decode every frame to fit's image before the first fit, as a caller that reads them
        after the fits asks (a report's gallery, drawn from the fitted frames); the images the
        fits read are decoded anyway (:func:`check_images_read`).
    held_out : callable, optional
        Told, once every check above has passed and before the first fit (a run refused says
        nothing of its figures), each sentence of
        :func:`~wirescene.eval.held_out.trained_on_frames`: the frames evaluated that a model
        the fits read was trained on (of the frames reused too), so that their figures are not
        held out. None: not looked up.

    Returns
    -------
    dict
        ``{variant: EvaluationReport}``. Every frame draws its random numbers from (seed,
        frame id) alone and the reports list frames in the order of ``frames``, so
        serial, process, Dask and resumed runs give identical reports.

    Raises
    ------
    ArgumentError
        Before any fit: ``predictions_dir`` is no path, a file, an empty path, or a directory
        that cannot be written or created (:func:`wirescene.core.validate.output_dir_problem`,
        as :func:`wirescene.evaluate` checks ``predictions``), or a frame id is a bool, a
        negative int or a float (:func:`~wirescene.io.kitti.as_frame_id`).
    InputError
        Before any fit: a frame's missing or malformed file (an image corrupt or truncated, where
        ``check_images`` or the fits read it), or ``predictions_dir`` holding
        an earlier run's records (without ``resume``) or, resumed, files of frames outside
        ``frames``; with ``evidence="oracle"``, a frame without ``wireframes/`` ground truth
        whose fit needs the evidence (a fine variant, or a box without a viewpoint).
    """
    source = DetectionSource() if source is None else source
    options = FitOptions() if options is None else options
    if evidence not in ("parts", "oracle"):
        raise ValueError(f"evidence must be 'parts' or 'oracle', got {evidence!r}")
    if resume and predictions_dir is None:
        raise ValueError("resume needs predictions_dir, where finished frames are recorded")
    problem = None if predictions_dir is None else output_dir_problem(predictions_dir)
    if problem:  # before any fit: "" would write into the working directory, a file fail after the first frame
        raise ArgumentError("predictions_dir", problem)
    dataset.require_labels("evaluation")
    if notify is None:
        notify = notify_stderr
    variants = [get_variant(v).name for v in variants]
    frame_ids = as_frame_ids(frames) if frames is not None else dataset.require_frames()
    missing = source.missing_frames(frame_ids)
    if missing:
        notify(f"{len(missing)} of {len(frame_ids)} frames have no detection file in {source.folder} "
               f"and are evaluated without detections (e.g. {missing[0]})")
    job = _FrameJob(dataset, tuple(variants), source, options, evidence)
    records = None
    if predictions_dir is not None:
        records = FrameRecords(Path(predictions_dir), run_config(dataset, variants, source, options, evidence))
        refuse_predictions_dir(predictions_dir, variants, frame_ids, resume=resume)
    reused = _reusable_records(records, frame_ids, notify) if resume else {}
    todo = [f for f in frame_ids if f not in reused]
    odd, boxes = check_frames_boxes(dataset, source, todo, labels=True)
    say_off_centre(odd, len(todo), notify)
    boxes.update(source.check_files(dataset, todo, notify))  # each frame's boxes, read once for every check below
    if evidence == "oracle":  # refused now, not at the first fit: a fine variant's, or a box's viewpoint's evidence
        fine = any(get_variant(v).fine for v in variants)
        lacking = next((f for f in todo if not wireframe_gt_path(dataset.split_dir, f).is_file()
                        and (fine or not source.own and boxes_lack_viewpoints(dataset, source, [f], boxes=boxes))),
                       None)
        if lacking is not None:
            raise InputError(ORACLE_NEEDS, path=wireframe_gt_path(dataset.split_dir, lacking))
    # a corrupt image refused now, not at its frame's fit or in the report after every fit
    check_images_read(dataset, source, variants, todo, evidence=evidence, every=check_images, notify=notify,
                      boxes=boxes)
    if held_out is not None:  # of every frame evaluated: a reused frame's figures are its earlier fit's
        read = model_files_of_run(dataset, source, variants, frame_ids, options=options, evidence=evidence, boxes=boxes)
        for sentence in trained_on_frames(dataset, frame_ids, options=options, read=read):
            held_out(sentence)
    with ExitStack() as stack:
        fitted = fit_frames(job, todo, workers=workers, dask_client=dask_client, stack=stack)
        by_frame = _collect_frames(fitted, reused, records, progress, on_estimate)
    # Frames finish in any order; the reports list them in the given order.
    return {v: evaluate([by_frame[f][v] for f in frame_ids]) for v in variants}


#: From how many images :func:`check_images_read` says that it decodes them (some 12 ms each: a pause).
SAY_DECODING = 200


def check_frames_boxes(dataset: KittiDataset, source: DetectionSource, frame_ids: list[str], *,
                       labels: bool = False) -> tuple[list[tuple[str, str]], dict[str, Detections]]:
    """:meth:`~wirescene.io.kitti.KittiDataset.check_frames` of ``frame_ids`` (with ``labels``: their
    label files read too), and of label boxes (``source`` "gt", with ``labels``) each frame's boxes from
    the labels read then (their viewpoints without noise, which moves a viewpoint, never makes one
    unknown), for the checks before the first fit that look at the boxes (:func:`check_images_read`,
    :func:`boxes_lack_viewpoints`), which so read no label file again: ``(odd, {frame: boxes})``, ``odd``
    as ``check_frames`` returns it; ``{}`` of any other source (its files read by
    :meth:`~wirescene.eval.sources.DetectionSource.check_files`).

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> sample = KittiDataset(DATA_DIR / "sample" / "kitti")
    >>> odd, boxes = check_frames_boxes(sample, DetectionSource("gt"), ["000010"], labels=True)
    >>> odd, len(boxes["000010"])  # the 8 cars
    ([], 8)
    """
    if not labels or source.spec != "gt":
        return dataset.check_frames(frame_ids, labels=labels), {}
    odd, boxes = [], {}
    for f in frame_ids:  # frame by frame, as check_frames checks them: the same first error
        odd += dataset.check_frames([f])
        boxes[f] = detections_from_labels(dataset.labels(f))
    return odd, boxes


def check_images_read(dataset: KittiDataset, source: DetectionSource, variants: Iterable[str],
                      frame_ids: list[str], *, evidence: str = "parts", every: bool = False,
                      notify: Callable[[str], None] | None = None,
                      boxes: Mapping[str, Detections] | None = None) -> None:
    """Decode, before the first fit, the image of each frame of ``frame_ids`` whose fit reads it
    (:meth:`~wirescene.io.kitti.KittiDataset.check_frames` with ``images``): a corrupt or
    truncated one is an :class:`InputError` then, not at its frame's fit (the frames fitted
    before it left behind). Every frame's for our own pre-detection; else, with ``evidence``
    "parts", those whose detections :func:`~wirescene.fitting.pipeline.needs_evidence` (a fine
    variant, or a box without a viewpoint, as detection files give them), as the fits decide;
    ``every``: each frame's, for a caller that reads them after the fits (a report, pictures).
    Call it after :meth:`~wirescene.eval.sources.DetectionSource.check_files`; ``notify`` is told
    of :data:`SAY_DECODING` images or more (a KITTI split's take half a minute or more); ``boxes``:
    the frames' detections already read (:func:`check_frames_boxes`, ``check_files``), a frame
    missing from it read here."""
    if every or source.own:
        read = list(frame_ids)
    elif evidence != "parts":  # the oracle's evidence (and the viewpoints told by it): no image
        read = []
    else:  # a label's viewpoint noise moves a viewpoint, never makes one unknown: any generator tells
        read = [f for f in frame_ids if needs_evidence(_boxes(dataset, source, f, boxes), variants)]
    if notify is not None and len(read) >= SAY_DECODING:
        notify(f"decoding the {len(read)} images the fits read before the first fit (a corrupt one refused now)")
    dataset.check_frames(read, images=True)


def boxes_lack_viewpoints(dataset: KittiDataset, source: DetectionSource, frame_ids: Iterable[str], *,
                          boxes: Mapping[str, Detections] | None = None) -> bool:
    """Whether a box of ``source`` (label boxes or files, not our own: a ``ValueError``) in the
    frames ``frame_ids`` comes without a viewpoint, which a fit on the image finds with the
    detector bank and the crop classifier (:func:`~wirescene.fitting.models.model_files_read`'s
    ``viewpoints_given`` is its negation). A frame whose boxes no longer read (a reused frame's
    file changed since its fit) counts: what it held is unknown. ``boxes``: the frames' detections
    already read (:func:`check_frames_boxes`', :meth:`~wirescene.eval.sources.DetectionSource.check_files`'), a
    frame missing from it read here.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> sample = KittiDataset(DATA_DIR / "sample" / "kitti")
    >>> boxes_lack_viewpoints(sample, DetectionSource("gt"), sample.frame_ids())  # label boxes carry theirs
    False
    """
    if source.own:
        raise ValueError("our own pre-detection's boxes are found with their viewpoints")
    for frame_id in frame_ids:
        try:
            dets = _boxes(dataset, source, frame_id, boxes)
        except InputError:
            return True
        if not np.all(np.isfinite(dets.alpha)):
            return True
    return False


def model_files_of_run(dataset: KittiDataset, source: DetectionSource, variants: Iterable[str],
                       frame_ids: Iterable[str], *, options: FitOptions, evidence: str = "parts",
                       boxes: Mapping[str, Detections] | None = None) -> tuple[str, ...]:
    """The trained files the fits of ``variants`` on ``frame_ids`` read
    (:func:`~wirescene.fitting.models.model_files_read`), their boxes read (``boxes``: those
    already read, :func:`check_frames_boxes`): the bank and the classifier give our own boxes
    their viewpoints, and label or file boxes theirs only where one lacks it. What the
    held-out line and a report's "How this run was made" name (a resume record counts them
    before the boxes are read: :func:`~wirescene.fitting.models.models_fingerprint`).

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> sample = KittiDataset(DATA_DIR / "sample" / "kitti")
    >>> model_files_of_run(sample, DetectionSource("gt"), ["full"], ["000010"], options=FitOptions())
    ('parts_model', 'score_calibration', 'shape_model')
    """
    given = not source.own and not boxes_lack_viewpoints(dataset, source, frame_ids, boxes=boxes)
    return model_files_read(options, fine=any(get_variant(v).fine for v in variants), own=source.own,
                            evidence=evidence, viewpoints_given=given)


def _boxes(dataset: KittiDataset, source: DetectionSource, frame_id: str,
           boxes: Mapping[str, Detections] | None) -> Detections:
    """The frame's detections of ``boxes``, or read where it has none (label boxes' viewpoint noise
    moves a viewpoint, never makes one unknown: any generator tells what the checks ask)."""
    if boxes is not None and frame_id in boxes:
        return boxes[frame_id]
    return source.for_frame(dataset, frame_id, np.random.default_rng(0))


def _reusable_records(records: FrameRecords, frame_ids: list[str], notify) -> dict[str, dict]:
    """``{frame: {variant: (label text, FrameResult)}}`` of the frames whose records can
    be reused; those that cannot (stale or unreadable) are refitted, and ``notify`` told."""
    reused, stale = {}, []
    for frame_id in frame_ids:
        try:
            fits = records.load(frame_id)
        except StaleRecord as exc:
            stale.append((records.path(frame_id), str(exc)))
            continue
        if fits is not None:
            reused[frame_id] = fits
    if stale:
        more = f" (and {len(stale) - 1} more)" if len(stale) > 1 else ""
        notify(f"refitting {len(stale)} frame(s) whose record cannot be reused: {stale[0][0]} {stale[0][1]}{more}")
    if reused:
        notify(f"resuming: {len(reused)} of {len(frame_ids)} frames already done in {records.root}")
    return reused


def _collect_frames(fitted, reused: dict, records: FrameRecords | None, progress, on_estimate):
    """``{frame: {variant: FrameResult}}`` of the reused frames and the fitted ones as
    they finish; each fitted frame's labels and record are written as it arrives."""
    by_frame: dict[str, dict[str, FrameResult]] = {}
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
            records.save(frame_id, {v: (estimate.to_kitti(), result) for v, (estimate, result) in fits.items()})
    return by_frame


def say_off_centre(odd: list[tuple[str, str]], total: int, notify: Callable[[str], None]) -> None:
    """Tell ``notify`` in one line of the frames whose calibration looks made for another image
    size (``odd``, of :meth:`~wirescene.io.kitti.KittiDataset.check_frames`; of ``total`` checked)."""
    if odd:
        frame, problem = odd[0]
        notify(f"warning: {len(odd)} of {total} frames: {problem} (e.g. frame {frame})")


def notify_stderr(message: str) -> None:
    """``wirescene: MESSAGE`` on standard error, one line."""
    print(f"wirescene: {message}", file=sys.stderr)
