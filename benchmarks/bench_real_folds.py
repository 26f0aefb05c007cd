"""The model variants on the real KITTI frames, cross-validated by drive.

Every frame of fold k (:mod:`wirescene.io.folds`) is fitted with the part detectors and
the detector bank and crop viewpoint classifier trained on the other folds
(``MODELS/parts_fold{k}.npz``, ``MODELS/bank_fold{k}.npz``,
``MODELS/viewpoint_classifier_fold{k}.npz``; the last two only with ``--detections bank`` or ``DIR``;
made by ``wirescene train parts|detector --kitti-root ROOT`` and ``wirescene train
viewpoints ROOT`` with ``--split-file`` of the other folds' frames), so no figure comes
from a model that saw the frame's drive. The folds'
records are pooled and reported with the paper's tables and the KITTI metrics, whose
scores are the calibrated confidences cross-validated the same way (the confidence model
of fold k is fitted on the other folds' records).

    python benchmarks/bench_real_folds.py --root ../shared/data/kitti --models MODELS \\
        --detections gt --out RUN_DIR [--variant full ...] [--workers 2]

``--detections bank`` is the paper's protocol end to end (our own pre-detections);
``--detections DIR`` fits another detector's per-frame files (``FRAME.json``, ``.csv``, ``.txt``),
whose boxes without a viewpoint take one from the fold's bank and crop classifier.
``--shipped`` uses the shipped models for every fold instead: fair only for models that
were not trained on these frames (e.g. wirescene 0.1's synthetic-only models).
Interrupted runs resume (``RUN_DIR/fold{k}`` are ordinary ``eval --predictions`` dirs).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from _common import VERIFICATION_FILE, read_run, verified_records  # noqa: E402  (benchmarks/ is on the path)
from wirescene.core.atomic import write_text
from wirescene.core.jsonio import dumps, write_json
from wirescene.core.version import environment
from wirescene.eval.intervals import format_intervals, kitti_variant_intervals, localisation_intervals, margin_intervals
from wirescene.eval.kitti_metrics import format_kitti_intervals, kitti_figure, kitti_metrics
from wirescene.eval.metrics import evaluate, format_table
from wirescene.eval.runner import evaluate_dataset
from wirescene.eval.sources import DetectionSource
from wirescene.fitting.options import FitOptions
from wirescene.fitting.variants import VARIANTS, get_variant
from wirescene.io.folds import N_FOLDS, drive_map, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.lift import LiftingOptions
from wirescene.training.scores import cross_validated_confidences


def cv_predictions(records, frames, folds) -> dict:
    """``{variant: [labels of each of frames]}``: a run's estimates with each fold's confidences
    from a model of the other folds' records."""
    preds = {}
    for variant, results in records.items():
        by_frame = {r.frame_id: r for r in results}
        scores = cross_validated_confidences(records, folds, variant)
        preds[variant] = [by_frame[f].estimate_labels(scores[f]) for f in frames]
    return preds


def kitti_with_cv_scores(records, gt, folds, drives, *, seed, reference="coarse+gp"):
    """({variant: KITTI metrics}, {variant: their moderate figures' intervals over drives}, {variant: the
    intervals of its margins over ``reference``}) with each fold's confidences from a model of the other folds."""
    frames = sorted(gt)
    gts = [gt[f] for f in frames]
    preds = cv_predictions(records, frames, folds)
    out = {v: kitti_metrics(gts, p) for v, p in preds.items()}
    spread, margins = kitti_variant_intervals(gts, preds, frames, drives, seed=seed,
                                              reference=reference if reference in preds else None)
    return out, spread, margins


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", required=True)
    ap.add_argument("--models", type=Path, default=None)
    ap.add_argument("--shipped", action="store_true")
    ap.add_argument("--detections", default="gt",
                    help="gt (label boxes), bank (our pre-detection) or a directory of per-frame detection files "
                         "(boxes without a viewpoint take one from the fold's bank and crop classifier)")
    ap.add_argument("--variant", dest="variants", action="append", choices=list(VARIANTS))
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--fold", type=int, action="append", default=None,
                    help="fit only this fold (repeatable; no summary), e.g. while other folds' models are trained")
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                    help="An InferenceOptions field, e.g. plane_refinement=0 or box_weight=100, or a "
                         "LiftingOptions field with the prefix lifting., e.g. lifting.road_prior=0.01, or a "
                         "PredetectOptions field with the prefix predetect., e.g. predetect.threshold=0.5.")
    args = ap.parse_args()
    if not args.shipped and args.models is None:
        ap.error("give --models DIR (fold models) or --shipped")
    variants = args.variants or list(VARIANTS)
    # STAGE.FIELD as everywhere (FitOptions.with_settings); a bare FIELD is the fine stage's
    settings = {(key if "." in key else f"inference.{key}"): value
                for key, _, value in (item.partition("=") for item in args.settings)}
    try:
        FitOptions().with_settings(settings)
    except ValueError as exc:
        ap.error(f"--set: {exc}")
    dataset = KittiDataset(args.root)
    frames = dataset.frame_ids()
    folds = {f: fold_of(f) for f in frames}
    t0 = time.perf_counter()
    for k in sorted(set(args.fold)) if args.fold else range(N_FOLDS):
        test = [f for f in frames if folds[f] == k]
        models = {}
        if not args.shipped:
            models = {"parts_model": str(args.models / f"parts_fold{k}.npz")}
            if args.detections != "gt":
                models["detector_bank"] = str(args.models / f"bank_fold{k}.npz")
                models["viewpoint_classifier"] = str(args.models / f"viewpoint_classifier_fold{k}.npz")
            for path in models.values():
                if not Path(path).is_file():
                    sys.exit(f"missing fold model {path}")
        # Our own pre-detections are fitted unverified; the summary verifies them held out (each
        # fold by a car model of the other folds), so that no fold is scored by a model that saw it.
        options = FitOptions(lifting=LiftingOptions(n_particles=args.particles), seed=args.seed,
                             calibrate_scores=False, **models).with_settings(
                                 settings | {"predetect.min_car_probability": 0})
        source = DetectionSource(args.detections, bank=models.get("detector_bank"),
                                 classifier=models.get("viewpoint_classifier"))
        print(f"fold {k}: {len(test)} frames, models {models or 'shipped'}", file=sys.stderr)
        evaluate_dataset(dataset, variants, frames=test, source=source, options=options,
                         predictions_dir=args.out / f"fold{k}", resume=True, workers=args.workers)
    elapsed = time.perf_counter() - t0
    if args.fold:
        return
    records, _ = read_run(args.out, verified=False)
    tau = FitOptions().with_settings(settings).predetect.min_car_probability
    if args.detections == "bank":
        fitted = sum(r.n_detections for r in records[variants[0]])
        records = verified_records(records, tau)
        write_json(args.out / VERIFICATION_FILE, {"min_car_probability": tau}, indent=None)
        print(f"verified held out at p(car) >= {tau:g}: {variants[0]} keeps "
              f"{sum(r.n_detections for r in records[variants[0]])} of {fitted} fitted cars", file=sys.stderr)
        pooled = [v for v in variants if get_variant(v).fine]
        # the car models learn from the records of the run's variants of each stage: other variants, other cars kept
        print(f"(the fine variants' car models pool this run's {', '.join(pooled) or 'none'}; a run holding other "
              f"variants verifies other cars)", file=sys.stderr)
    reports = {v: evaluate(records[v]) for v in variants}
    gt = {f: dataset.labels(f) for f in frames}
    n_cars = sum(len(g.of_type("Car")) for g in gt.values())
    print(f"\n{len(frames)} real frames, {n_cars} cars, {N_FOLDS} folds by drive, detections: {args.detections}, "
          f"models: {'shipped' if args.shipped else args.models}, seed {args.seed} ({elapsed:.0f} s)\n")
    print(format_table(reports, tables=("3d", "viewpoint")))
    drives = drive_map(dataset.base_dir)[0]
    within = localisation_intervals(reports, drives, seed=args.seed)
    margins = margin_intervals(reports, drives, reference="coarse+gp", seed=args.seed) if "coarse+gp" in reports else {}
    print("\n" + format_intervals(within, margins=margins))
    kitti, spread, kitti_margins = kitti_with_cv_scores({v: records[v] for v in variants}, gt, folds, drives,
                                                        seed=args.seed)

    def fmt(v):
        return "    -" if v is None else f"{v:5.1f}"

    def fmt_interval(v):
        return "-" if v is None else f"[{v[0]:.1f}, {v[1]:.1f}]"

    print("\nKITTI AP (R40, moderate; scores: cross-validated calibrated confidences), each with its 90% bootstrap "
          "interval over drives")
    print(f"{'variant':10s} {'2D 0.7':>20s} {'AOS':>20s} {'BEV 0.7':>20s} {'3D 0.7':>20s} {'BEV 0.5':>20s} "
          f"{'3D 0.5':>20s}")
    for v, m in kitti.items():
        columns = (("car", "2d"), ("car", "aos"), ("car", "bev"), ("car", "3d"), ("iou_0.5", "bev"), ("iou_0.5", "3d"))
        cells, bounds = ([kitti_figure(r, block, metric) for block, metric in columns] for r in (m, spread[v]))
        print(f"{v:10s} " + " ".join(f"{fmt(c['moderate']) + ' ' + fmt_interval(b):>20s}" for c, b in zip(cells, bounds)))
    if kitti_margins:
        print("\n" + format_kitti_intervals(kitti_margins))
    summary = {v: {"paper": reports[v].to_json_dict(include_records=False), "kitti": kitti[v],
                   "kitti_interval": spread[v], "kitti_margin": kitti_margins.get(v),
                   "loc_1m_interval": within[v]} for v in variants}
    summary["_run"] = {"frames": len(frames), "cars": n_cars, "detections": args.detections, "seed": args.seed,
                       "models": "shipped" if args.shipped else str(args.models), "seconds": elapsed,
                       "settings": args.settings, "environment": environment()}
    write_text(args.out / "summary.json", dumps(summary, default=lambda o: None))
    print(f"\nsummary: {args.out / 'summary.json'}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
