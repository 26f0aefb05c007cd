"""Real-image benchmark (issue 18), part 1: part-detector localisation on real KITTI frames
under 4-fold cross-validation by drive, and on held-out synthetic scenes.

Protocol (:func:`parts_cv`): the real patches of every labelled frame of ``--root`` (the 72 shared
frames) are described once (:func:`wirescene.training.parts_real.make_real_patch_data`: scaled mean
wireframe at the labelled pose, visibility by ray casting, mirrored copies); for each fold ``k`` of
:mod:`wirescene.io.folds` a forest is trained on the patches of the frames of the
other three folds (plus, optionally, the synthetic training patches,
:func:`wirescene.training.parts.make_synth_patch_data`) and scored on the frames of fold
``k`` with :func:`wirescene.training.parts.localisation` (is the arg-max of the vertex's
``log(S_j / S_b)`` map within 4% / 10% of the car's projected length of the labelled
vertex?). Figures are pooled over the four folds (weighted by vertices); car and vertex
counts are printed with every figure. Evaluation cars: "clean" (occlusion 0, truncation 0,
box >= 40 px) and "occ<=1" (occlusion level <= 1, any truncation, box >= 25 px). The
synthetic row scores the model trained on all real frames (+ synthetic, if used) on
``wirescene synth`` scenes of seed 1 (seeds < 1000 are never used for training).

Usage (defaults = the shipped model's recipe: ghog_ms, box position, smoothing 1/16 of the
box height, real + 100 synthetic scenes; the CV models are not calibrated, which does not
change any arg-max)::

    python benchmarks/bench_real.py --root KITTI_ROOT [--kind ghog_ms]
        [--no-position] [--smooth 0.0625] [--synth-scenes 100] [--context] [--n-trees 30]
        [--max-depth 13] [--cache DIR] [--save-dir DIR] [--baseline] [--no-synth-eval]
        [--synth-eval-root DIR]

``--baseline`` additionally scores the shipped model (trained without real frames) on every
fold. ``--cache DIR`` keeps the described patches between runs (npz); ``--synth-eval-root
DIR`` keeps the synthetic held-out scenes (default: generated into a temporary directory).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from wirescene.io.folds import N_FOLDS, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.parts.detector import PartDetector
from wirescene.training.parts import (
    PatchData,
    _merge,
    fit_detector,
    localisation,
    make_synth_patch_data,
    synth_eval_frames,
)
from wirescene.training.parts_real import make_real_patch_data, real_frames

EVAL_SETS = {"clean": dict(clean=True, min_box_h=40.0), "occ<=1": dict(clean=False, min_box_h=25.0, max_occluded=1)}


def _cached(path, make):
    if path is not None and Path(path).is_file():
        with np.load(path) as z:
            return PatchData(X={k[2:]: z[k] for k in z.files if k.startswith("X_")}, y=z["y"], group=z["group"],
                             names=[str(n) for n in z["names"]] if "names" in z.files else [],
                             pos=z["pos"] if "pos" in z.files else None, ctx=z["ctx"] if "ctx" in z.files else None)
    d = make()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        extra = {k: v for k, v in (("pos", d.pos), ("ctx", d.ctx)) if v is not None}
        np.savez(path, y=d.y, group=d.group, names=np.array(d.names), **extra,
                 **{f"X_{k}": v for k, v in d.X.items()})
    return d


def _subset(d: PatchData, m) -> PatchData:
    return PatchData(X={k: v[m] for k, v in d.X.items()}, y=d.y[m], group=d.group[m], names=d.names,
                     pos=None if d.pos is None else d.pos[m], ctx=None if d.ctx is None else d.ctx[m])


def _concat(a: PatchData, b: PatchData, kind: str) -> PatchData:
    return _merge(PatchData(X={kind: a.X[kind]}, y=a.y, group=a.group, names=a.names, pos=a.pos, ctx=a.ctx), b)


def pool(rows) -> dict:
    """Vertex-weighted pool of :func:`localisation` results."""
    n = sum(r["n_vertices"] for r in rows)
    out = {"n_vertices": n, "n_cars": sum(r["n_cars"] for r in rows)}
    for key in ("hits", "chance"):
        out[key] = {rad: sum(r[key][rad] * r["n_vertices"] for r in rows if r["n_vertices"]) / max(n, 1)
                    for rad in rows[0][key]}
    out["rank"] = sum(r["rank"] * r["n_vertices"] for r in rows if r["n_vertices"]) / max(n, 1)
    out["t_maps_s"] = sum(r["t_maps_s"] for r in rows)
    return out


def line(name, r, radii=(0.04, 0.10)) -> str:
    parts = [f"{name:<26s} {r['n_cars']:3d} cars {r['n_vertices']:4d} vertices:"]
    for rad in radii:
        parts.append(f"within {rad:.0%} {r['hits'][rad]:.3f} (chance {r['chance'][rad]:.3f})")
    parts.append(f"rank {r['rank']:.3f}")
    return "  ".join(parts)


def parts_cv(root, *, kind: str = "ghog_ms", position: bool = False, context: bool = False, smooth: float = 0.0,
             real: PatchData | None = None,
             synth: PatchData | None = None,
             n_trees: int = 30, max_depth: int = 13, seed: int = 0, min_samples_leaf: int = 2,
             class_weight="balanced", detector_for_fold=None, save_dir=None, progress=print) -> dict:
    """4-fold cross-validated localisation of part detectors on real frames.

    Parameters
    ----------
    root : KITTI root with the labelled frames
    real : real patches of all frames (``group`` = index into ``real.names``), or None:
        no real training data
    synth : synthetic training patches, or None
    detector_for_fold : callable ``fold -> PartDetector``, optional -- score this
        detector instead of training one (e.g. the shipped synthetic-only model)
    save_dir : path, optional -- write each fold's model as ``parts_fold{k}.npz`` (for
        cross-validated ``wirescene eval --parts-model``)

    Returns
    -------
    dict ``{eval set: {"folds": [result per fold], "pooled": result}}``
    """
    ids = KittiDataset(root).frame_ids()
    out = {name: {"folds": []} for name in EVAL_SETS}
    for k in range(N_FOLDS):
        test = [f for f in ids if fold_of(f) == k]
        if detector_for_fold is not None:
            det = detector_for_fold(k)
        else:
            parts = []
            if real is not None:
                fold = np.array([fold_of(real.names[g]) for g in real.group])
                parts.append(_subset(real, fold != k))
            if synth is not None:
                parts.append(synth)
            data = parts[0] if len(parts) == 1 else _concat(parts[0], parts[1], kind)
            t = time.time()
            det = fit_detector(data, kind=kind, position=position, context=context, smooth=smooth, n_trees=n_trees,
                               max_depth=max_depth, seed=seed,
                               min_samples_leaf=min_samples_leaf, class_weight=class_weight)
            progress(f"fold {k}: trained on {len(data)} patches in {time.time() - t:.0f} s")
            if save_dir is not None:
                det.save(Path(save_dir) / f"parts_fold{k}.npz")
        res = localisation(det, real_frames(root, test, subsets=EVAL_SETS))
        for name in EVAL_SETS:
            r = res["by_tag"].get(name) or {"hits": {0.04: 0.0, 0.10: 0.0}, "chance": {0.04: 0.0, 0.10: 0.0},
                                             "rank": 0.0, "n_vertices": 0, "n_cars": 0, "t_maps_s": 0.0}
            out[name]["folds"].append(r)
            progress(line(f"fold {k} {name}", r))
    for name in EVAL_SETS:
        out[name]["pooled"] = pool(out[name]["folds"])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", required=True, help="KITTI root with the labelled frames of the folds")
    ap.add_argument("--kind", default="ghog_ms")
    ap.add_argument("--smooth", type=float, default=0.0625, help="response-map smoothing (sigma in box heights)")
    ap.add_argument("--context", action="store_true", help="append the box's gradient layout (ghog_ms kinds)")
    ap.add_argument("--position", action=argparse.BooleanOptionalAction, default=True,
                    help="append the box-relative position to the descriptor")
    ap.add_argument("--synth-scenes", type=int, default=100, help="synthetic training scenes added to every fold")
    ap.add_argument("--no-real", action="store_true", help="train on synthetic patches only")
    ap.add_argument("--n-trees", type=int, default=30)
    ap.add_argument("--max-depth", type=int, default=13)
    ap.add_argument("--min-samples-leaf", type=int, default=2)
    ap.add_argument("--save-dir", default=None, help="write the per-fold models here (parts_fold{k}.npz)")
    ap.add_argument("--cache", default=None, help="directory for described patches (npz)")
    ap.add_argument("--baseline", action="store_true", help="also score the shipped model on every fold")
    ap.add_argument("--model", default=None, help="with --baseline: this model instead of the shipped one")
    ap.add_argument("--no-synth-eval", action="store_true",
                    help="skip the synthetic held-out row (score the shipped model with bench_parts.py instead)")
    ap.add_argument("--synth-eval-root", default=None,
                    help="synthetic held-out scenes, generated here if missing (default: a temporary directory)")
    ap.add_argument("--synth-eval-scenes", type=int, default=20)
    args = ap.parse_args()
    cache = Path(args.cache) if args.cache else None
    ids = KittiDataset(args.root).frame_ids()

    if args.baseline:
        det0 = PartDetector.load(args.model)
        print(f"baseline model: kind {det0.kind}, meta {det0.meta}")
        res = parts_cv(args.root, detector_for_fold=lambda k: det0)
        for name in EVAL_SETS:
            print(line(f"BASELINE pooled {name}", res[name]["pooled"]))

    kinds = (args.kind,)
    real = None
    if not args.no_real:
        real = _cached(cache / f"real_{args.kind}.npz" if cache else None,
                       lambda: make_real_patch_data(args.root, ids, kinds=kinds))
    synth = None
    if args.synth_scenes:
        synth = _cached(cache / f"synth_{args.synth_scenes}_{args.kind}.npz" if cache else None,
                        lambda: make_synth_patch_data(n_scenes=args.synth_scenes, kinds=kinds))
    res = parts_cv(args.root, kind=args.kind, position=args.position, context=args.context, smooth=args.smooth,
                   real=real, synth=synth, n_trees=args.n_trees, max_depth=args.max_depth,
                   min_samples_leaf=args.min_samples_leaf, save_dir=args.save_dir)
    tag = (f"{args.kind}{'+ctx' if args.context else ''}{'+pos' if args.position else ''} smooth={args.smooth} "
           f"real={not args.no_real} synth={args.synth_scenes}")
    for name in EVAL_SETS:
        print(line(f"POOLED {name} [{tag}]", res[name]["pooled"]))

    if args.no_synth_eval:
        return
    # synthetic held-out scenes, model trained on all real frames (+ synthetic)
    with tempfile.TemporaryDirectory() as tmp:
        synth_root = Path(args.synth_eval_root or tmp)
        if not (synth_root / "training" / "wireframes").is_dir():
            from wirescene.synth.generate import generate_dataset

            generate_dataset(synth_root, args.synth_eval_scenes, seed=1)
        parts = [p for p in (real, synth) if p is not None]
        data = parts[0] if len(parts) == 1 else _concat(parts[0], parts[1], args.kind)
        det = fit_detector(data, kind=args.kind, position=args.position, context=args.context, smooth=args.smooth,
                           n_trees=args.n_trees, max_depth=args.max_depth, min_samples_leaf=args.min_samples_leaf)
        print(line(f"synthetic held-out [{tag}]", localisation(det, synth_eval_frames(synth_root))))


if __name__ == "__main__":
    main()
