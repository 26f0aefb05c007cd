"""Choose the fine stage's extra weights on training folds of the real KITTI frames.

Every configuration (``--config NAME:key=value,key=value``, keys of
:class:`wirescene.infer.inference.InferenceOptions`) fits the given variants on every
frame with label boxes as pre-detections (as ``wirescene eval --detections gt``; the
part evidence and the coarse grid search are computed once per frame and shared by all
configurations). Frames are grouped by fold (``wirescene.io.folds``): group A =
folds {0, 1}, group B = folds {2, 3}. The configuration chosen on group A (highest
share of cars within 1 m, pooled over the fine variants; ties: lower median 3D azimuth
error) is reported on group B and vice versa, so no reported figure comes from the
frames its configuration was chosen on. ``--json`` keeps every figure.

Usage: python benchmarks/tune_fine.py ROOT --models MODELS --variant fg+gp --variant full \\
           --config paper: --config box100:box_weight=100 --config box100gp:box_weight=100,plane_refinement=1
On real frames the part evidence of a frame of fold k comes from ``MODELS/parts_fold{k}.npz``
(``benchmarks/bench_real.py --save-dir MODELS``), a model that never saw the frame's drive;
``--shipped`` uses the shipped part model (only fair on frames it was not trained on, e.g.
synthetic scenes of an unused seed).
(``bilinear=0`` in a configuration looks the part maps up at the nearest grid point.)
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.io.folds import fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.io.wireframes import read_wireframe_gt, wireframe_gt_path  # noqa: E402
from wirescene.eval.metrics import evaluate  # noqa: E402
from wirescene.eval.runner import frame_result  # noqa: E402
from wirescene.eval.sources import DetectionSource, frame_seed  # noqa: E402
from wirescene.infer.evidence import oracle_evidence, part_evidence  # noqa: E402
from wirescene.fitting.pipeline import FitOptions, fit_scene  # noqa: E402
from wirescene.parts.detector import PartDetector  # noqa: E402
from wirescene.infer.inference import InferenceOptions  # noqa: E402
from wirescene.lift import lift_table  # noqa: E402

GROUPS = {"A": (0, 1), "B": (2, 3)}


def option_value(options, key: str, text: str):
    """``text`` as a value of field ``key`` of the options dataclass ``options`` (an
    instance), of its default's type; booleans are written 0 / 1. Raises ``KeyError``
    for a key that is not a field."""
    if key not in {f.name for f in dataclasses.fields(options)}:
        raise KeyError(key)
    default = getattr(options, key)
    return bool(int(text)) if isinstance(default, bool) else type(default)(text)


def parse_config(text: str) -> tuple[str, dict]:
    name, _, body = text.partition(":")
    out = {}
    for item in filter(None, body.split(",")):
        key, _, value = item.partition("=")
        if key == "bilinear":  # evidence lookup (parts only), not an inference option
            out[key] = bool(int(value))
            continue
        try:
            out[key] = option_value(InferenceOptions(), key, value)
        except KeyError:
            raise SystemExit(f"unknown option {key!r}") from None
    return name, out


def figures(records, n_gt):
    loc = np.array([r.loc_error for r in records])
    az = np.array([r.az3d_error for r in records])
    return {"n_gt": n_gt, "n_tp": len(records), "loc_1m": float(100 * np.mean(loc < 1.0)) if len(loc) else np.nan,
            "loc_1_5m": float(100 * np.mean(loc < 1.5)) if len(loc) else np.nan,
            "median_az3d": float(np.median(az)) if len(az) else np.nan,
            "median_loc": float(np.median(loc)) if len(loc) else np.nan}


def group_of(frame_id: str, synthetic: bool) -> str:
    if synthetic:  # synthetic scenes: alternate frames
        return "A" if int(frame_id) % 2 == 0 else "B"
    f = fold_of(frame_id)
    return next(g for g, folds in GROUPS.items() if f in folds)


def run_configs(root, variants, configs, *, evidence="parts", frames=None, seed=1, models=None, log=print):
    """Fit ``variants`` under every configuration ``{name: options}`` on the frames of
    ``root`` (label boxes as pre-detections; evidence and coarse grid once per frame).

    Returns ``{(name, variant): [FrameResult]}``, ``{name: seconds}`` (CPU seconds of
    fitting, i.e. one core's time on a shared machine) and the number of frames.
    """
    ds = KittiDataset(root)
    frame_ids = ds.frame_ids()[:frames]
    source = DetectionSource("gt")
    results = {(c, v): [] for c in configs for v in variants}
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
            frame_evidence = oracle_evidence(detections, np.array([o.box for o in gt.objects]).reshape(-1, 4), vertex_gt)
        else:
            detector = None if models is None else PartDetector.load(models / f"parts_fold{fold_of(fid)}.npz")
            frame_evidence = part_evidence(ds.image(fid), detections, detector=detector)
        lifted = lift_table(camera, detections)
        for name, kw in configs.items():
            kw = dict(kw)
            ev = frame_evidence
            if "bilinear" in kw:
                ev = copy.copy(frame_evidence)
                ev.bilinear = kw.pop("bilinear")
            options = FitOptions(inference=InferenceOptions(**kw), seed=seed)
            for v in variants:
                t = time.process_time()
                est = fit_scene(camera, detections, variant=v, options=options, lifted=lifted, evidence=ev)
                seconds[name] += time.process_time() - t
                results[(name, v)].append(frame_result(fid, gt, detections, est, vertex_gt, camera))
        log(f"{fid} done ({time.perf_counter() - t0:.0f} s)")
    return results, seconds, len(frame_ids)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root")
    ap.add_argument("--variant", action="append", required=True)
    ap.add_argument("--config", action="append", required=True)
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--evidence", choices=["parts", "oracle"], default="parts")
    ap.add_argument("--synthetic", action="store_true", help="group frames by parity instead of fold")
    ap.add_argument("--json", default=None)
    ap.add_argument("--models", type=Path, default=None, help="fold models (parts_fold{k}.npz)")
    ap.add_argument("--shipped", action="store_true", help="use the shipped part model")
    args = ap.parse_args()
    if args.evidence == "parts" and not args.synthetic and not args.shipped and args.models is None:
        ap.error("real frames need --models DIR (fold part models) or --shipped")
    configs = dict(parse_config(c) for c in args.config)
    results, seconds, n_frames = run_configs(args.root, args.variant, configs, evidence=args.evidence,
                                             frames=args.frames, seed=args.seed, models=args.models,
                                             log=lambda m: print(m, flush=True))
    table = {}
    for (name, v), frames in results.items():
        rep = evaluate(frames)
        n_gt = {g: 0 for g in GROUPS}
        for fr in frames:
            n_gt[group_of(fr.frame_id, args.synthetic)] += sum(o.type in ("Car",) for o in fr.gt)
        for g in GROUPS:
            recs = [r for r in rep.records if group_of(r.frame_id, args.synthetic) == g]
            table[(name, v, g)] = figures(recs, n_gt[g])
        table[(name, v, "all")] = figures(rep.records, sum(n_gt.values())) | {
            "parts_70": rep.metrics["all"]["parts_70"]}
    print(f"\n{'config':14s} {'variant':7s} {'grp':3s} {'cars':>4s} {'<1m':>6s} {'<1.5m':>6s} {'az':>5s} {'loc':>5s}")
    for (name, v, g), f in table.items():
        extra = f"  parts70 {f['parts_70']:.0f}%" if "parts_70" in f and f["parts_70"] == f["parts_70"] else ""
        print(f"{name:14s} {v:7s} {g:3s} {f['n_tp']:4d} {f['loc_1m']:6.1f} {f['loc_1_5m']:6.1f} "
              f"{f['median_az3d']:5.1f} {f['median_loc']:5.2f}{extra}")
    print("\nseconds per frame (all variants): " + ", ".join(
        f"{n} {s / max(n_frames, 1):.2f}" for n, s in seconds.items()))

    def criterion(name, g):
        rows = [table[(name, v, g)] for v in args.variant]
        return (np.mean([r["loc_1m"] for r in rows]), -np.mean([r["median_az3d"] for r in rows]))

    print("\ncross-group choice (chosen on one group, reported on the other):")
    chosen = {}
    for choose, report in (("A", "B"), ("B", "A")):
        best = max(configs, key=lambda n: criterion(n, choose))
        chosen[report] = best
        for v in args.variant:
            f = table[(best, v, report)]
            print(f"  chosen on {choose}: {best:14s} -> on {report}: {v:7s} {f['n_tp']} cars  <1m {f['loc_1m']:.1f}%  "
                  f"<1.5m {f['loc_1_5m']:.1f}%  az {f['median_az3d']:.1f}  loc {f['median_loc']:.2f} m")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"configs": configs, "seconds": seconds, "chosen": chosen,
                       "table": {"|".join(k): v for k, v in table.items()}}, fh, indent=1)


if __name__ == "__main__":
    main()
