"""KITTI APs of one setting fitted with several seeds: each seed's, their mean, and an interval over seeds and drives.

A run's AP interval (``bench_real_folds.py``, ``wirescene eval``) resamples the drives of
that run alone, but the fine stage samples, and the seed moves its 3D AP@0.7 by as much as
the drives do (seven seeds of the README's label-box run: 10.5 to 17.9). This reads runs
of ``bench_real_folds.py`` that differ in the seed alone and reports, per variant, the
moderate KITTI APs (R40; the confidences cross-validated within each run, as
``bench_real_folds.py`` makes them) of every run, their mean, and a 90% interval whose every
draw resamples the drives and takes one of the runs at random
(:func:`wirescene.eval.intervals.kitti_run_intervals`): what one more run on other drives
like these could show. ``wirescene kitti-eval GT_DIR RUN1_DIR RUN2_DIR ...`` does the same for
label files; this reads the runs' records, whose confidences it cross-validates first.

    python benchmarks/bench_seed_aps.py --root KITTI RUN1,RUN2,...,RUNn [--variant full] [--draws 1000] [--json OUT]
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from _common import read_run  # noqa: E402  (benchmarks/ is on the path)
from bench_real_folds import cv_predictions
from bench_seeds import chosen_variants, same_frames, seed_run_parser, seed_runs
from wirescene.core.jsonio import write_json
from wirescene.eval.intervals import N_BOOT_AP, kitti_run_intervals
from wirescene.eval.kitti_metrics import kitti_figure, kitti_metrics, mean_kitti_metrics
from wirescene.io.folds import drive_map, fold_of
from wirescene.io.kitti import KittiDataset

#: The figures reported: (name, block, metric) as :func:`kitti_figure` reads them.
FIGURES = (("3D AP@0.7", "car", "3d"), ("BEV AP@0.7", "car", "bev"), ("3D AP@0.5", "iou_0.5", "3d"))


def seed_aps(preds_by_run: Sequence[dict], gts: Sequence, frames: Sequence[str], drives: dict, *, variants,
             n_boot: int = N_BOOT_AP, seed: int = 0) -> dict:
    """``{variant: {figure: {"runs": [AP of each run], "mean", "interval": [lo, hi] or None}}}``
    of moderate KITTI APs, the interval over drives and runs."""
    out = {}
    for v in variants:
        runs = [p[v] for p in preds_by_run]
        metrics = [kitti_metrics(gts, r) for r in runs]
        mean = mean_kitti_metrics(metrics)
        spread = kitti_run_intervals(gts, runs, frames, drives, n_boot=n_boot, seed=seed)
        out[v] = {name: {"runs": [kitti_figure(m, block, metric)["moderate"] for m in metrics],
                         "mean": kitti_figure(mean, block, metric)["moderate"],
                         "interval": kitti_figure(spread, block, metric)}
                  for name, block, metric in FIGURES}
    return out


def format_report(report: dict, seeds: Sequence) -> str:
    lines = [f"KITTI AP (R40, moderate), runs of seeds {', '.join(map(str, seeds))}; mean and 90% interval over "
             "drives and runs"]
    for v, figures in report.items():
        lines.append(f"-- {v}")
        for name, f in figures.items():
            runs = " ".join("   -" if x is None else f"{x:4.1f}" for x in f["runs"])
            span = "" if f["interval"] is None else " [{:.1f}, {:.1f}]".format(*f["interval"])
            mean = "-" if f["mean"] is None else f"{f['mean']:.1f}"
            lines.append(f"  {name:10s} {runs}   mean {mean}{span}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (module docstring); ``argv`` as for :meth:`argparse.ArgumentParser.parse_args`."""
    ap = seed_run_parser(__doc__)
    ap.add_argument("--draws", type=int, default=N_BOOT_AP, help="bootstrap draws of the interval")
    args = ap.parse_args(argv)
    runs, seeds = seed_runs(ap, args.runs)
    dataset = KittiDataset(args.root)
    records = [read_run(r)[0] for r in runs]
    frames = same_frames(ap, {r: {x.frame_id for rs in rec.values() for x in rs} for r, rec in zip(runs, records)})
    variants = chosen_variants(ap, records, args.variant)
    folds = {f: fold_of(f) for f in frames}
    # each run's confidences come from its own variants' records, as its summary made them
    preds = [cv_predictions(rec, frames, folds) for rec in records]
    gts = [dataset.labels(f) for f in frames]
    report = seed_aps(preds, gts, frames, drive_map(dataset.base_dir)[0], variants=variants, n_boot=args.draws)
    print(format_report(report, [s if s is not None else "?" for s in seeds]))
    if args.json:
        write_json(args.json, {"runs": [str(r) for r in runs], "seeds": seeds, "variants": report})
        print(f"json: {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
