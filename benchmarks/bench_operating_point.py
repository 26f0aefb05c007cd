"""The pre-detection threshold as the fit sees it: the paper's protocol and the false 3D cars as it moves.

Reads ``bench_real_folds.py --detections bank`` runs made with fold banks whose stored
threshold differs (e.g. copies of the fold banks with ``DetectorBank.threshold`` set to
0.2, 0.3, 0.5), and reports per fold group and pooled, per variant: the true-positive
initialisations (the paper's TP/GT: box on a car and viewpoint within 45 deg), the share of
them and the number of cars placed within 1 m, the cars fitted and the false ones (whose
pre-detection overlaps no labelled car at IoU 0.5, or one already taken: each is a 3D car
in the output that is not there).

With ``--funnel``, where the cars are lost on their way to a true positive, per fold group and
pooled: the cars a fitted car's pre-detection matches (IoU > 0.5, first come by score, as the
paper's test) before the fit verifies its cars, those still matched after it, those whose
pre-detection's viewpoint then lies within 45 deg (the true positives) and of them the cars
within 1 m. The run must hold every fitted car (a ``--detections bank`` run with its
``verification.json``).

With ``--paired``, every run after the first is also compared with the first on the cars
that are true positives in both (the same label matched), per fold group: their median and
mean localisation error (each clipped at :data:`CLIP` m, so that a lost car counts as one
far off), how many lie within 1 m and 1.5 m, and on how many cars the run is nearer the
label than the first run or farther from it. A change that moves few cars across 1 m can
still move the errors of all of them.

    python benchmarks/bench_operating_point.py NAME=RUN [NAME=RUN ...] [--paired] [--funnel] [--json OUT.json]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.jsonio import write_json
from wirescene.eval.metrics import evaluate
from wirescene.io.folds import FOLD_GROUPS, fold_of


def on_car(result) -> np.ndarray:
    """``(D,)`` bool: which fitted cars of a frame have the first pre-detection, in score
    order, to overlap a ``Car`` label at IoU >= 0.5."""
    from wirescene.training.kitti_detector import detection_labels

    order = np.argsort(-np.asarray(result.det_scores, float), kind="stable")
    cars = np.array([g.box for g in result.gt if g.type == "Car"], float).reshape(-1, 4)
    out = np.zeros(len(order), bool)
    if len(order):
        out[order] = detection_labels(np.asarray(result.det_boxes)[order], cars)
    return out


def false_cars(result) -> int:
    """Fitted cars of a frame that are not :func:`on_car` (a second box on a car counts too)."""
    return int((~on_car(result)).sum())


def figures(results) -> dict:
    """Paper-protocol figures of a list of FrameResult, with the cars a pre-detection matches
    (before the viewpoint test) and the false cars."""
    ev = evaluate(results)
    m = ev.metrics["all"]
    n_tp, n_gt = int(m["n_tp"]), int(m["n_gt"])
    within = 0 if m["loc_1m"] is None else round(m["loc_1m"] * n_tp / 100)
    return {"tp": n_tp, "gt": n_gt, "loc_1m": m["loc_1m"], "cars_within_1m": within, "matched": int(ev.counts["matched"]),
            "fitted": int(sum(len(r.det_boxes) for r in results)), "false_cars": sum(map(false_cars, results))}


def funnel(unverified, verified: dict) -> dict:
    """Cars matched by a fitted car before the fit's verification (``unverified``, a list of
    FrameResult) and after it, of those the true positives (viewpoint within 45 deg) and the
    cars within 1 m (``verified``: :func:`figures` of the verified records of the same frames):
    ``{"cars", "matched", "verified", "tp", "within_1m"}``."""
    return {"cars": verified["gt"], "matched": int(evaluate(unverified).counts["matched"]),
            "verified": verified["matched"], "tp": verified["tp"], "within_1m": verified["cars_within_1m"]}


#: Localisation errors are clipped here (m) before averaging in ``--paired``.
CLIP = 5.0


def errors_by_car(results) -> dict:
    """``{(frame, label index): localisation error (m)}`` of the true positives."""
    return {(tp.frame_id, tp.gt_index): tp.loc_error for tp in evaluate(results).records}


def paired(first: dict, other: dict) -> dict:
    """Per fold group with any, the cars true positives in both ``{car: error}``: count, median
    and mean clipped error of each, within 1 m and 1.5 m of each, and cars nearer / farther."""
    out = {}
    for g in FOLD_GROUPS:
        cars = [c for c in first if c in other and fold_of(c[0]) in g]
        if not cars:
            continue
        a = np.array([first[c] for c in cars], float)
        b = np.array([other[c] for c in cars], float)
        out[str(g)] = {"cars": len(cars), "median": [float(np.median(a)), float(np.median(b))],
                       "mean_clipped": [float(np.minimum(a, CLIP).mean()), float(np.minimum(b, CLIP).mean())],
                       "within_1m": [int((a < 1).sum()), int((b < 1).sum())],
                       "within_1.5m": [int((a < 1.5).sum()), int((b < 1.5).sum())],
                       "nearer": int((b < a).sum()), "farther": int((b > a).sum())}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="NAME=RUN_DIR (bench_real_folds.py --out, --detections bank)")
    ap.add_argument("--paired", action="store_true", help="compare every run with the first, car by car")
    ap.add_argument("--funnel", action="store_true",
                    help="where the cars are lost: matched before / after the fit's verification, true positives, within 1 m")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    out, errors = {}, {}
    for item in args.runs:
        name, _, run = item.partition("=")
        records, _ = read_run(Path(run))
        errors[name] = {variant: errors_by_car(results) for variant, results in records.items()}
        out[name] = {}
        for variant, results in records.items():
            row = {str(g): figures([r for r in results if fold_of(r.frame_id) in g]) for g in FOLD_GROUPS}
            row["pooled"] = figures(results)
            out[name][variant] = row
            print(f"{name:6s} {variant:10s} " + " | ".join(
                f"{k}: TP {v['tp']}/{v['gt']}, {v['loc_1m']:.1f}% <1 m = {v['cars_within_1m']} cars, "
                f"{v['false_cars']} false of {v['fitted']} fitted" for k, v in row.items()))
        if args.funnel:
            unverified, _ = read_run(Path(run), verified=False)
            for variant in records:
                rows = {str(g): funnel([r for r in unverified[variant] if fold_of(r.frame_id) in g],
                                       out[name][variant][str(g)]) for g in FOLD_GROUPS}
                rows["pooled"] = funnel(unverified[variant], out[name][variant]["pooled"])
                out[name][variant]["funnel"] = rows
                print(f"{name:6s} {variant:10s} cars -> matched -> verified -> viewpoint (TP) -> within 1 m: "
                      + " | ".join(f"{g}: {r['cars']} -> {r['matched']} -> {r['verified']} -> {r['tp']} -> "
                                   f"{r['within_1m']}" for g, r in rows.items()))
    if args.paired and len(errors) > 1:
        first, *others = errors
        print(f"\ncars true positives in both runs, against {first}: median / mean of errors clipped at {CLIP:g} m, "
              "within 1 m, within 1.5 m, nearer / farther than there")
        for name in others:
            for variant in errors[name]:
                if variant not in errors[first]:
                    continue
                rows = paired(errors[first][variant], errors[name][variant])
                out[name][variant]["paired"] = rows
                print(f"{name:6s} {variant:10s} " + " | ".join(
                    f"{g}: {r['cars']} cars, {r['median'][0]:.2f} -> {r['median'][1]:.2f} / {r['mean_clipped'][0]:.2f} "
                    f"-> {r['mean_clipped'][1]:.2f} m, {r['within_1m'][0]} -> {r['within_1m'][1]}, "
                    f"{r['within_1.5m'][0]} -> {r['within_1.5m'][1]}, {r['nearer']} / {r['farther']}"
                    for g, r in rows.items()))
    if args.json:
        write_json(args.json, out)


if __name__ == "__main__":
    main()
