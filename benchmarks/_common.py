"""Helpers shared by the benchmark scripts, so that no script imports another. Run the
scripts as ``python benchmarks/NAME.py``: Python puts this directory on ``sys.path``.

Importing this module loads no part of wirescene (scripts set thread counts first);
the helpers that need it import it when called.
"""

from __future__ import annotations

import contextlib
import copy
import importlib
import sys
import time
from pathlib import Path


def best_of(fn, repeat: int = 3, *, warmup: bool = False):
    """``(seconds, result)``: the fastest of ``repeat`` calls of ``fn`` (after one
    untimed call with ``warmup``: lazy imports, allocators, CUDA kernels)."""
    out = fn() if warmup else None
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def _is_wirescene(name: str) -> bool:
    return name == "wirescene" or name.startswith("wirescene.")


class Checkout:
    """The ``wirescene`` package of a checkout's ``src`` directory, imported beside the one
    this process runs (``src=None``: that one), so that a benchmark can time two revisions
    side by side in one run, alternating: ``with other.active(): other.module("wirescene").fit(...)``.

    The other revision's modules stay out of ``sys.modules`` except inside :meth:`active`,
    where they stand in for this process's and its ``src`` leads ``sys.path``, so that the
    imports its functions make when called resolve to the same revision. Give both
    revisions plain arrays: an object one of them made is of a class the other does not
    know. Each revision keeps its own caches (models load once per revision).
    """

    def __init__(self, src=None, modules=("wirescene",)):
        self.src = None if src is None else str(Path(src).resolve())
        self._modules: dict = {}
        with self.active():
            for name in modules:
                importlib.import_module(name)
            where = Path(sys.modules["wirescene"].__file__).resolve()
        if self.src is not None and Path(self.src) not in where.parents:
            raise SystemExit(f"{src}: wirescene imported from {where}, not from this directory")
        self.path = where.parent

    @contextlib.contextmanager
    def active(self):
        if self.src is None:
            yield self
            return
        own = {k: sys.modules.pop(k) for k in list(sys.modules) if _is_wirescene(k)}
        sys.modules.update(self._modules)
        sys.path.insert(0, self.src)
        try:
            yield self
        finally:
            sys.path.remove(self.src)
            self._modules = {k: sys.modules.pop(k) for k in list(sys.modules) if _is_wirescene(k)}
            sys.modules.update(own)

    def module(self, name: str):
        """The revision's module ``name`` (imported if need be)."""
        with self.active():
            return importlib.import_module(name)


def parse_config(text: str) -> tuple[str, dict]:
    """``NAME:key=value,key=value`` (keys of :class:`~wirescene.infer.inference.InferenceOptions`,
    or ``bilinear`` for the part maps' lookup) as ``(NAME, {key: value})``."""
    from wirescene.core.settings import replace_fields
    from wirescene.infer.inference import InferenceOptions

    name, _, body = text.partition(":")
    out = {}
    for item in filter(None, body.split(",")):
        key, _, value = item.partition("=")
        if key == "bilinear":  # evidence lookup (parts only), not an inference option
            out[key] = bool(int(value))
            continue
        try:  # the package's one mapping of option names (wirescene.core.settings)
            out[key] = getattr(replace_fields(InferenceOptions(), {key: value}), key)
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
    return name, out


def run_configs(root, variants, configs, *, evidence="parts", frames=None, seed=1, models=None, log=print):
    """Fit ``variants`` under every configuration ``{name: options}`` on the frames of
    ``root`` (label boxes as pre-detections; evidence once per frame and mirroring setting, the coarse
    grid once per frame).

    Returns ``{(name, variant): [FrameResult]}``, ``{name: seconds}`` (CPU seconds of
    fitting, i.e. one core's time on a shared machine) and the number of frames.
    """
    import numpy as np

    from wirescene.eval.runner import frame_result
    from wirescene.eval.sources import DetectionSource, frame_seed
    from wirescene.fitting.options import FitOptions
    from wirescene.fitting.pipeline import fit_scene
    from wirescene.infer.evidence import oracle_evidence, part_evidence
    from wirescene.infer.inference import InferenceOptions
    from wirescene.io.folds import fold_of
    from wirescene.io.kitti import KittiDataset
    from wirescene.io.wireframes import read_wireframe_gt, wireframe_gt_path
    from wirescene.lift import lift_table
    from wirescene.parts.detector import PartDetector

    ds = KittiDataset(root)
    frame_ids = ds.frame_ids()[:frames]
    source = DetectionSource("gt")
    results = {(c, v): [] for c in configs for v in variants}
    default_flip = InferenceOptions().flip_evidence
    flips = sorted({kw.get("flip_evidence", default_flip) for kw in configs.values()})
    seconds = dict.fromkeys(configs, 0.0)
    t0 = time.perf_counter()
    for fid in frame_ids:
        gt = ds.labels(fid)
        detections = source.for_frame(ds, fid, frame_seed(seed, fid))
        camera = ds.camera(fid)
        gt_path = wireframe_gt_path(ds.split_dir, fid)
        vertex_gt = read_wireframe_gt(gt_path) if gt_path.is_file() else None
        if not len(detections):
            continue
        if evidence == "oracle":
            box_gt = np.array([o.box for o in gt.objects]).reshape(-1, 4)
            frame_evidence = dict.fromkeys(flips, oracle_evidence(detections, box_gt, vertex_gt))
        else:
            detector = None if models is None else PartDetector.load(models / f"parts_fold{fold_of(fid)}.npz")
            # one reading per mirroring setting the configurations ask for
            frame_evidence = {f: part_evidence(ds.image(fid), detections, detector=detector, flip=f) for f in flips}
        lifted = lift_table(camera, detections)
        for name, kw in configs.items():
            kw = dict(kw)
            ev = frame_evidence[kw.get("flip_evidence", default_flip)]
            if "bilinear" in kw:
                ev = copy.copy(ev)
                ev.bilinear = kw.pop("bilinear")
            options = FitOptions(inference=InferenceOptions(**kw), seed=seed)
            for v in variants:
                t = time.process_time()
                est = fit_scene(camera, detections, variant=v, options=options, lifted=lifted, evidence=ev)
                seconds[name] += time.process_time() - t
                results[(name, v)].append(frame_result(fid, gt, detections, est, vertex_gt, camera))
        log(f"{fid} done ({time.perf_counter() - t0:.0f} s)")
    return results, seconds, len(frame_ids)


def prediction_dirs(run):
    """The predictions directories of a run: the run itself if it holds frame records,
    else its ``fold*`` subdirectories that do (as ``bench_real_folds.py`` writes them)."""
    from pathlib import Path

    from wirescene.core.errors import InputError
    from wirescene.eval.records import RECORDS_DIR

    run = Path(run)
    if (run / RECORDS_DIR).is_dir():
        return [run]
    folds = sorted(p for p in run.glob("fold*") if (p / RECORDS_DIR).is_dir())
    if not folds:
        raise InputError(f"no frame records: expected {RECORDS_DIR}/ or fold*/{RECORDS_DIR}/", path=run)
    return folds


def read_run(run, *, verified: bool = True) -> tuple[dict, str]:
    """``({variant: [FrameResult, ...]}, detections)`` of a run's folds, pooled; the
    detections spec as recorded (``gt``, ``bank`` or a directory). A ``bench_real_folds.py``
    run on our own pre-detections holds every fitted car; with ``verified`` its fit's
    verification is applied held out, as its summary does (``verification.json``)."""
    import json
    from pathlib import Path

    from wirescene.core.errors import InputError
    from wirescene.eval.records import RECORDS_DIR
    from wirescene.training.scores import read_run_records

    records: dict[str, list] = {}
    specs, seen = set(), set()
    for folder in prediction_dirs(run):
        for variant, results in read_run_records(folder).items():
            records.setdefault(variant, []).extend(results)
        frames = sorted(p.stem for p in (folder / RECORDS_DIR).glob("*.json"))
        # Pooling folds must not count a frame twice (e.g. a fold fitted into two dirs).
        twice = seen.intersection(frames)
        if twice:
            raise InputError(f"frame {sorted(twice)[0]} recorded in more than one fold directory", path=folder)
        seen.update(frames)
        first = json.loads((folder / RECORDS_DIR / f"{frames[0]}.json").read_text())
        specs.add(str(first.get("config", {}).get("detections", {}).get("spec", "?")))
    verification = Path(run) / VERIFICATION_FILE
    if verified and verification.is_file():
        records = verified_records(records, json.loads(verification.read_text())["min_car_probability"])
    return records, ", ".join(sorted(specs))


#: Written into a ``bench_real_folds.py`` run on our own pre-detections: the verification its summary applied.
VERIFICATION_FILE = "verification.json"


def verified_records(records: dict, min_probability: float) -> dict:
    """The records of a run on our own pre-detections with the fit's verification applied
    held out by drive (each fold by a car model of the other folds' records)."""
    from wirescene.io.folds import fold_of
    from wirescene.training.scores import cross_validated_car_filter

    folds = {r.frame_id: fold_of(r.frame_id) for rs in records.values() for r in rs}
    return cross_validated_car_filter(records, folds, min_probability=min_probability)


def frame_result_2d(labels, vgt, camera, uv):
    """A frame record whose estimates are the true cars with vertices ``uv`` ``(N, 36, 2)``."""
    import numpy as np

    from wirescene.core.groundplane import object_pose
    from wirescene.core.types import ObjectEstimate, SceneEstimate
    from wirescene.eval.runner import frame_result
    from wirescene.io.detections import detections_from_labels

    dets = detections_from_labels(labels)
    objects = [ObjectEstimate(detection_index=j, box2d=o.box, score=1.0, location=np.asarray(o.location, float),
                              R=object_pose(0.0, 1.0, o.rotation_y)[1], dims=np.asarray(o.dims, float), cost=0.0)
               for j, o in enumerate(labels.objects)]
    res = frame_result("x", labels, dets, SceneEstimate(variant="truth", objects=objects), vgt, camera)
    res.est_vertices_2d = uv
    return res


def approximated_wireframes(model, cars, camera, n_shape: int):
    """``(uv (N, 36, 2), vertex errors (N, 36) in metres)``: the true wireframes of the
    wireframes-JSON ``cars`` approximated by the first ``n_shape`` components of ``model``
    (least squares in the object frame; 0: the mean shape), placed with their true poses."""
    import numpy as np

    uv, err = [], []
    for car in cars:
        X, R, t = np.array(car["vertices_3d"]), np.array(car["R"]), np.array(car["location"])
        obj = (X - t) @ R
        approx = model.reconstruct(obj, n_shape) if n_shape else model.mean
        uv.append(camera.project(approx @ R.T + t))
        err.append(np.linalg.norm(approx - obj, axis=1))
    return np.array(uv), np.array(err)


#: Each side of a jittered box moves by Gaussian noise of this share of the box's width / height.
JITTER = 0.05


def jittered(boxes, image_size, rng):
    """Boxes ``(N, 4)`` with each side moved by N(0, JITTER) of the box's width / height,
    clipped to the image and kept at least 2 px wide and high: a good external detector's
    boxes, made from label boxes."""
    import numpy as np

    W, H = image_size
    wh = np.column_stack([boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]])
    out = boxes + rng.normal(0.0, JITTER, boxes.shape) * np.tile(wh, 2)
    out = np.column_stack([np.clip(out[:, 0], 0, W - 3), np.clip(out[:, 1], 0, H - 3),
                           np.clip(out[:, 2], 0, W - 1), np.clip(out[:, 3], 0, H - 1)])
    out[:, 2] = np.maximum(out[:, 2], out[:, 0] + 2)
    out[:, 3] = np.maximum(out[:, 3], out[:, 1] + 2)
    return out


def jitter_rng(seed: int, frame_id: str):
    """The jitter's random stream for one frame: the same boxes whatever else runs."""
    import zlib

    import numpy as np

    return np.random.default_rng([seed, zlib.crc32(frame_id.encode())])


#: Box heights (px) by which :func:`operating_point` splits the cars found.
HEIGHT_BANDS = (0.0, 25.0, 40.0, 60.0, float("inf"))


def operating_point(dets, labels, threshold: float, *, iou: float = 0.5) -> dict:
    """What the fit receives at the detection ``threshold``: how many detections, the share
    that overlap a ``Car`` label at IoU >= ``iou`` (precision), the share of the cars found
    (recall, also by box height: :data:`HEIGHT_BANDS` px, by truncation and by KITTI's
    occlusion flag), why the others are missed (no detection at any score overlaps them --
    by box height, with how many of those have one at IoU >= 0.3 at least -- or only ones
    below the threshold) and the viewpoint error of the detections on a car (over
    45 deg; over 135 deg: front and back swapped)."""
    import numpy as np

    from wirescene.core.boxes import iou_2d
    from wirescene.core.viewpoints import angle_difference

    n_det = n_on = 0
    found, best, heights, truncated, occluded, dalpha = [], [], [], [], [], []
    for d, lab in zip(dets, labels):
        cars = [o for o in lab.objects if o.type == "Car"]
        gt = np.array([o.box for o in cars], float).reshape(-1, 4)
        every = np.asarray(d.boxes, float).reshape(-1, 4)
        best.append(iou_2d(every[:, None], gt[None]).max(0) if len(every) else np.zeros(len(gt)))  # any score
        keep = np.asarray(d.scores) >= threshold
        boxes, alpha = every[keep], np.asarray(d.alpha, float)[keep]
        n_det += len(boxes)
        heights.append(gt[:, 3] - gt[:, 1])
        truncated.append(np.array([o.truncated > 0 for o in cars], bool))
        occluded.append(np.array([min(int(o.occluded), 2) for o in cars], int))
        if not len(gt):
            continue
        if not len(boxes):
            found.append(np.zeros(len(gt), bool))
            continue
        ov = iou_2d(boxes[:, None], gt[None])
        on = ov.max(1) >= iou
        n_on += int(on.sum())
        found.append(ov.max(0) >= iou)
        truth = np.array([o.alpha for o in cars], float)[ov.argmax(1)[on]]
        dalpha.append(angle_difference(alpha[on], truth))
    found = np.concatenate(found) if found else np.zeros(0, bool)
    best, heights = np.concatenate(best), np.concatenate(heights)
    candidate = best >= iou
    truncated, occluded = np.concatenate(truncated), np.concatenate(occluded)

    def share(mask) -> list:  # [share of the cars found, cars]
        return [float(found[mask].mean()) if mask.any() else None, int(mask.sum())]

    dalpha = np.degrees(np.concatenate(dalpha)) if dalpha else np.zeros(0)
    band = np.digitize(heights, HEIGHT_BANDS[1:-1])
    return {"threshold": float(threshold), "iou": float(iou), "n_detections": int(n_det), "n_on_car": int(n_on),
            "precision": n_on / max(n_det, 1), "n_cars": int(len(found)), "recall": float(found.mean()) if len(found) else 0.0,
            "recall_by_height": {f"{HEIGHT_BANDS[b]:.0f}-{HEIGHT_BANDS[b + 1]:.0f}px": share(band == b)
                                 for b in range(len(HEIGHT_BANDS) - 1)},
            "recall_by_truncation": {"truncated": share(truncated), "whole": share(~truncated)},
            "recall_by_occlusion": {str(k): share(occluded == k) for k in range(3)},
            "missed_without_candidate": int((~found & ~candidate).sum()),
            "missed_below_threshold": int((~found & candidate).sum()),
            "missed_without_candidate_by_height": {  # [cars, of them with a detection at IoU >= 0.3]
                f"{HEIGHT_BANDS[b]:.0f}-{HEIGHT_BANDS[b + 1]:.0f}px": [int((~candidate & (band == b)).sum()),
                                                                      int((~candidate & (band == b) & (best >= 0.3)).sum())]
                for b in range(len(HEIGHT_BANDS) - 1)},
            "viewpoint_over_45": float(np.mean(dalpha > 45)) if len(dalpha) else None,
            "viewpoint_over_135": float(np.mean(dalpha > 135)) if len(dalpha) else None}


def write_saved_detections(path, dets: dict) -> None:
    """Write ``{frame: Detections}`` as a ``--save-dets`` file, the arrays ``{frame}__boxes`` /
    ``__scores`` / ``__alpha`` that :func:`read_saved_detections` reads."""
    import numpy as np

    np.savez(path, **{f"{f}__{k}": getattr(d, k) for f, d in dets.items() for k in ("boxes", "scores", "alpha")})


def read_saved_detections(path, frames=None) -> dict:
    """``{frame: Detections}`` of a ``bench_predetect.py --save-dets`` file (arrays
    ``{frame}__boxes`` / ``__scores`` / ``__alpha``), of ``frames`` (None: every frame it
    holds); a one-line error naming the file where one of ``frames`` is missing."""
    import numpy as np

    from wirescene.core.types import Detections

    with np.load(path, allow_pickle=False) as z:
        held = sorted({k.rsplit("__", 1)[0] for k in z.files})
        frames = held if frames is None else list(frames)
        missing = sorted(set(frames) - set(held))
        if missing:
            raise SystemExit(f"{path}: no detections of frame {missing[0]} ({len(missing)} frames missing)")
        return {f: Detections(z[f"{f}__boxes"].reshape(-1, 4), z[f"{f}__scores"], z[f"{f}__alpha"]) for f in frames}
