"""Choose among configurations by leaving one fold out, from runs of bench_real_folds.py.

Each configuration is one or more run directories of ``benchmarks/bench_real_folds.py``
(e.g. one with label boxes and one with our pre-detections, same options). For every fold
k, the configuration with the most true-positive cars within 1 m on the *other* folds
(pooled over the given variants and runs; ties: the first given) is chosen, and fold k's
cars are scored with it. The pooled held-out figures therefore come from choices that
never saw the frames they score, unlike picking the best row of a table of runs.

    python benchmarks/choose_by_fold.py --variant coarse --variant coarse+gp \\
        --config off=RUNS/gt_off,RUNS/bank_off --config w20=RUNS/gt_w20,RUNS/bank_w20 ...

The road prior of the coarse stage (``LiftingOptions.road_prior``) was chosen this way.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import read_run
from wirescene.eval.metrics import evaluate
from wirescene.io.folds import N_FOLDS, fold_of


def fold_records(run: Path, variant: str) -> list[list]:
    """True-positive records of ``variant`` per fold of one run, ``[fold][car]``; a run on our
    own pre-detections verified as its summary does (``_common.read_run``)."""
    records = evaluate(read_run(run)[0][variant]).records
    return [[t for t in records if fold_of(t.frame_id) == k] for k in range(N_FOLDS)]


def other_folds_total(counts: dict[str, list[int]], k: int) -> dict[str, int]:
    """Each configuration's sum of ``counts`` over every fold but ``k``."""
    return {c: sum(n for j, n in enumerate(per_fold) if j != k) for c, per_fold in counts.items()}


def choose_leaving_one_out(counts: dict[str, list[int]]) -> dict[int, str]:
    """For every fold ``k`` the configuration with the largest sum of ``counts[config]``
    over the other folds (ties: the first configuration given).

    ``counts`` maps each configuration to one count per fold (e.g. cars within 1 m).
    """
    n_folds = len(next(iter(counts.values())))
    chosen = {}
    for k in range(n_folds):
        others = other_folds_total(counts, k)
        chosen[k] = max(counts, key=lambda c: others[c])  # max keeps the first of equals
    return chosen


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", action="append", required=True, metavar="NAME=RUN[,RUN...]")
    ap.add_argument("--variant", dest="variants", action="append", required=True)
    args = ap.parse_args()
    configs = {}
    for item in args.config:
        name, _, runs = item.partition("=")
        configs[name] = [Path(r) for r in runs.split(",")]
    n_runs = {len(r) for r in configs.values()}
    if len(n_runs) != 1:
        ap.error("every configuration needs the same number of runs (e.g. label boxes, then pre-detections)")
    tps = {(c, i, v): fold_records(run, v) for c, runs in configs.items() for i, run in enumerate(runs)
           for v in args.variants}

    def within_1m(records) -> int:
        return sum(t.loc_error < 1.0 for t in records)

    counts = {c: [sum(within_1m(tps[(c, i, v)][k]) for i in range(len(configs[c])) for v in args.variants)
                  for k in range(N_FOLDS)] for c in configs}
    chosen = choose_leaving_one_out(counts)
    for k in range(N_FOLDS):
        others = other_folds_total(counts, k)
        ranked = ", ".join(f"{c} {others[c]}" for c in sorted(configs, key=lambda c: -others[c]))
        print(f"fold {k}: chooses {chosen[k]} (cars within 1 m on the other folds: {ranked})")
    first = next(iter(configs))
    for i in range(len(configs[first])):
        for v in args.variants:
            for label, pick in ((first, lambda k: first), ("chosen by fold", lambda k: chosen[k])):
                records = [t for k in range(N_FOLDS) for t in tps[(pick(k), i, v)][k]]
                if not records:
                    continue
                near = within_1m(records)
                az = np.median([t.az3d_error for t in records])
                print(f"run {i + 1} {v:10s} {label:15s} within 1 m {near}/{len(records)} = "
                      f"{100 * near / len(records):.0f}%, median 3D azimuth error {az:.1f} deg")


if __name__ == "__main__":
    main()
