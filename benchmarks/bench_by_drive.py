"""A variant's margin drive by drive: how much of it one drive carries, and how far other drives would move it.

The 72 shared frames come from 25 drives of very unequal size (one holds 64 of the 294
cars), and every figure of the real folds pools cars. This splits each run's true
positives (as :mod:`bench_error_budget` counts them) by the drive of their frame
(:func:`wirescene.io.folds.frame_drives`) and reports, for each variant against a
reference (default each run's ``coarse+gp``; ``NAME:VARIANT`` names one cell of one run
for all):

* the pooled margin (points of the true positives within 1 m, or passing KITTI's IoU
  0.7 with ``--metric iou``) and the margin on each fold group, with the same bootstrap
  over the group's own drives;
* a drive-clustered bootstrap interval of the pooled margin (drives resampled with
  replacement, ``--bootstrap`` draws, 5th and 95th percentiles): the spread a set of
  other drives like these would show;
* the margin with each drive left out: its smallest and largest value and the drive
  whose absence moves it most;
* each variant's own shares with the same bootstrap: its true positives of the labelled
  cars, and the true positives that pass;
* a table of the counts by drive.

    python benchmarks/bench_by_drive.py RUN [NAME=RUN ...] --root KITTI \\
        [--reference coarse+gp | NAME:VARIANT] [--metric loc|iou] [--bootstrap 10000] [--json OUT]

A RUN given without a name is named by its directory.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bench_error_budget import KITTI_CAMERA_HEIGHT, run_tables  # noqa: E402  (benchmarks/ is on the path)
from wirescene.core.jsonio import write_json
from wirescene.eval.intervals import clustered_margin, clustered_share
from wirescene.io.folds import DRIVE_FOLDS, FOLD_GROUPS, frame_drives
from wirescene.io.kitti import CAR_TYPES, KittiDataset

#: The columns of a car table (:func:`bench_error_budget.car_table`) each ``--metric`` counts.
METRICS = {"loc": "pass_loc", "iou": "pass_iou"}
#: The fold groups: choices are made on one and read on the other.
GROUPS = FOLD_GROUPS


def drive_counts(table: dict, drives: Sequence[str], drive_of: dict[str, str], *, column: str) -> tuple:
    """``(true positives, passing)``, each ``(D,)`` int, of a car table by drive."""
    index = {d: i for i, d in enumerate(drives)}
    rows = np.array([index[drive_of[f]] for f in table["frame"]], int)
    n = np.bincount(rows, minlength=len(drives))
    k = np.bincount(rows, weights=np.asarray(table[column], float), minlength=len(drives)).astype(int)
    return n, k


def margin_by_drive(k, n, k_ref, n_ref, *, n_boot: int = 10000, seed: int = 0) -> dict:
    """A margin in points, ``100 (sum k / sum n - sum k_ref / sum n_ref)``, and how it rests on drives.

    Parameters
    ----------
    k, n : (D,) array_like of int
        Per drive, the cars that pass and the true positives of the variant.
    k_ref, n_ref : (D,) array_like of int
        The same of the reference.
    n_boot : int, keyword-only
        Drive-clustered bootstrap draws (0: none).
    seed : int, keyword-only

    Returns
    -------
    dict
        ``margin``; ``interval`` (5th, 95th percentile of the bootstrap, ``None`` without
        draws); ``leave_one_out`` (D,) the margin without each drive; ``net`` (D,) the cars
        each drive adds to the margin (``k - k_ref``).

    Examples
    --------
    >>> out = margin_by_drive([10, 1], [20, 10], [5, 2], [20, 10], n_boot=0)
    >>> round(out["margin"], 1), out["net"].tolist()
    (13.3, [5, -1])
    >>> out["leave_one_out"].round(1).tolist()
    [-10.0, 25.0]
    """
    margin, interval = clustered_margin(k, n, k_ref, n_ref, n_boot=n_boot, seed=seed)
    k, n, k_ref, n_ref = (np.asarray(a, float) for a in (k, n, k_ref, n_ref))
    keep = ~np.eye(len(k), dtype=bool)
    loo = np.array([clustered_margin(k[m], n[m], k_ref[m], n_ref[m], n_boot=0)[0] for m in keep])
    return {"margin": margin, "interval": interval, "leave_one_out": loo, "net": (k - k_ref).astype(int)}


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (module docstring); ``argv`` as for :meth:`argparse.ArgumentParser.parse_args`."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", metavar="[NAME=]RUN", help="bench_real_folds.py --out directories")
    ap.add_argument("--root", required=True, help="the KITTI root the runs were fitted on (calibrations)")
    ap.add_argument("--reference", default="coarse+gp",
                    help="a variant (each run's own) or NAME:VARIANT (one cell for every run)")
    ap.add_argument("--metric", choices=sorted(METRICS), default="loc",
                    help="loc: centre within 1 m; iou: KITTI 3D IoU > 0.7")
    ap.add_argument("--bootstrap", type=int, default=10000, help="drive-clustered bootstrap draws (0: none)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    if args.bootstrap < 0:
        ap.error("--bootstrap must be >= 0")
    runs = {}
    for item in args.runs:
        name, _, path = item.rpartition("=") if "=" in item else (Path(item).name, "", item)
        if name in runs:
            ap.error(f"run name {name!r} given twice")
        runs[name] = Path(path)
    dataset = KittiDataset(args.root)
    column = METRICS[args.metric]
    tables, labelled = {}, {}
    for name, run in runs.items():
        records, _, by_variant = run_tables(run, dataset, camera_height=KITTI_CAMERA_HEIGHT)
        tables.update({(name, v): t for v, t in by_variant.items()})
        for r in next(iter(records.values())):
            labelled[r.frame_id] = sum(o.type in CAR_TYPES for o in r.gt)
    if ":" in args.reference:
        ref_run, _, ref_variant = args.reference.partition(":")
        if (ref_run, ref_variant) not in tables:
            ap.error(f"--reference {args.reference}: no such run and variant")
    drive_of = frame_drives()
    frames = {f for t in tables.values() for f in t["frame"]} | set(labelled)
    missing = sorted(f for f in frames if f not in drive_of)
    if missing:
        ap.error(f"frame {missing[0]} has no drive in wirescene's drive map")
    # a drive enters the bootstrap through its cars: one without any is no draw
    drives = sorted({drive_of[f] for f in frames if labelled.get(f, 1) > 0})
    counts = {cell: drive_counts(t, drives, drive_of, column=column) for cell, t in tables.items()}
    drive_fold = np.array([DRIVE_FOLDS[d] for d in drives])
    report = {}
    what = "within 1 m" if args.metric == "loc" else "3D IoU > 0.7"
    print(f"margins over {args.reference} in points of the true positives {what}; {len(drives)} drives")
    for (name, variant), (n, k) in counts.items():
        ref = (ref_run, ref_variant) if ":" in args.reference else (name, args.reference)
        if ref not in counts or ref == (name, variant):
            continue
        n_ref, k_ref = counts[ref]
        out = margin_by_drive(k, n, k_ref, n_ref, n_boot=args.bootstrap, seed=args.seed)
        groups, group_intervals = {}, {}
        for g in GROUPS:  # each group's margin with its own drives' bootstrap
            m = np.isin(drive_fold, g)
            groups[str(g)], group_intervals[str(g)] = clustered_margin(k[m], n[m], k_ref[m], n_ref[m],
                                                                       n_boot=args.bootstrap, seed=args.seed)
        in_group = {g: "" if i is None else " [{:+.1f}, {:+.1f}]".format(*i) for g, i in group_intervals.items()}
        loo = out["leave_one_out"]
        most = int(np.argmax(np.abs(loo - out["margin"])))
        spread = "no bootstrap" if out["interval"] is None else "drive bootstrap 90% [{:+.1f}, {:+.1f}]".format(
            *out["interval"])
        print(f"{name}:{variant}: {out['margin']:+.1f} ({int(k.sum())}/{int(n.sum())} against "
              f"{int(k_ref.sum())}/{int(n_ref.sum())}); {{0, 1}} {groups[str(GROUPS[0])]:+.1f}"
              f"{in_group[str(GROUPS[0])]}, {{2, 3}} {groups[str(GROUPS[1])]:+.1f}{in_group[str(GROUPS[1])]}; "
              f"{spread}; one drive left out "
              f"{loo.min():+.1f} .. {loo.max():+.1f} (without {drives[most]} ({int(n[most])} cars, net "
              f"{int(out['net'][most]):+d}): {loo[most]:+.1f})")
        report[f"{name}:{variant}"] = {"reference": f"{ref[0]}:{ref[1]}", "margin": out["margin"],
                                       "groups": groups, "group_intervals": group_intervals,
                                       "interval": out["interval"],
                                       "leave_one_out": dict(zip(drives, loo.tolist())),
                                       "net": dict(zip(drives, out["net"].tolist()))}
    if not report:
        print(f"no run holds both {args.reference} and another variant: no margins")
    cars = np.zeros(len(drives))
    for f, c in labelled.items():
        if c:
            cars[drives.index(drive_of[f])] += c
    print(f"\nshares, drive bootstrap 90% ({int(cars.sum())} labelled cars):")
    shares = {}
    for (name, variant), (n, k) in counts.items():
        tp, tp_interval = clustered_share(n, cars, n_boot=args.bootstrap, seed=args.seed)
        ok, ok_interval = clustered_share(k, n, n_boot=args.bootstrap, seed=args.seed)
        shares[f"{name}:{variant}"] = {"true_positives": tp, "true_positives_interval": tp_interval,
                                       "passing": ok, "passing_interval": ok_interval}
        spans = ["" if i is None else " [{:.1f}, {:.1f}]".format(*i) for i in (tp_interval, ok_interval)]
        print(f"{name}:{variant}: true positives {int(n.sum())}/{int(cars.sum())} = {tp:.1f}%{spans[0]}; {what} "
              f"{int(k.sum())}/{int(n.sum())} = {ok:.1f}%{spans[1]}")
    cells = list(counts)
    print("\n| drive | fold | " + " | ".join(f"{a}:{b}" for a, b in cells) + " |")
    print("|---|---|" + "---|" * len(cells))
    for i in np.argsort([-counts[cells[0]][0][j] for j in range(len(drives))], kind="stable"):
        print(f"| {drives[i]} | {drive_fold[i]} | "
              + " | ".join(f"{counts[c][1][i]}/{counts[c][0][i]}" for c in cells) + " |")
    if args.json:
        write_json(args.json, {"metric": args.metric, "drives": drives, "margins": report, "shares": shares,
                               "counts": {f"{a}:{b}": {"n": n.tolist(), "k": k.tolist()}
                                          for (a, b), (n, k) in counts.items()}})
        print(f"json: {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
