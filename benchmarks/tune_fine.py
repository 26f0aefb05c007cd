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
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import parse_config, run_configs  # noqa: E402
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.eval.metrics import evaluate  # noqa: E402
from wirescene.io.folds import fold_of  # noqa: E402

GROUPS = {"A": (0, 1), "B": (2, 3)}


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
        write_json(args.json, {"configs": configs, "seconds": seconds, "chosen": chosen,
                               "table": {"|".join(k): v for k, v in table.items()}})


if __name__ == "__main__":
    main()
