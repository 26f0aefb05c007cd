"""Search or objective: would restarts kept by the fit's own objective place more cars?

The fine stage samples, and the same boxes fitted with another seed land elsewhere
(``bench_seeds.py``). Restarts (fit K times, keep the fit with the lowest objective) turn
compute into accuracy only if the objective ranks its own fits the way the labels do. This
reads K runs of ``bench_real_folds.py`` that differ in the seed alone and, per fold group,
reports for K = 1..n the cars within 1 m, the cars passing 3D IoU > 0.7 and the mean 3D IoU
when each frame keeps the run whose fitted scene has the lowest objective (the sum of its
cars' ``cost``, as recorded by the fit), averaged over every K-subset of the runs (K = 1 is
the mean run). Beside it, two bounds of the same subsets: each frame keeping its best run by
the labels (``oracle``, what a perfect ranking would buy) and its worst (``worst``); and each
car's K fitted boxes averaged (``average``: what the mean of K fits would place). And the
objective's agreement with the labels: over the pairs of runs whose scenes differ, how often
the lower objective also has the higher mean 3D IoU (0.5: no better than chance).

    python benchmarks/bench_restarts.py --root KITTI RUN1,RUN2,...,RUNn [--variant full] [--json OUT]

Only runs with label boxes are meaningful (every car a true positive in every run); the runs'
frames and cars must agree.
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Mapping, Sequence

import numpy as np

from bench_error_budget import KITTI_CAMERA_HEIGHT, Boxes, passes, run_tables  # noqa: E402  (benchmarks/ is on the path)
from bench_seeds import GROUPS, chosen_variants, seed_run_parser, seed_runs
from wirescene.core.jsonio import write_json
from wirescene.eval.kitti_metrics import iou_3d
from wirescene.io.folds import DRIVE_FOLDS, frame_drives
from wirescene.io.kitti import KittiDataset

#: What a frame keeps of its K runs: by the fit's objective, by the labels (best, worst); and
#: each car's K fitted boxes averaged.
SELECTIONS = ("objective", "oracle", "worst", "average")


def frame_arrays(tables: Sequence[Mapping], records: Sequence[Sequence], variant: str):
    """``(frames, cars)``: the frame ids and, per frame, ``(cost (R,), loc (R, n), iou_ok (R, n),
    iou (R, n), fitted (R, n, 7), labels (n, 7))`` over the R runs and the frame's n true
    positives (the same cars in every run); a box's 7 numbers are its bottom centre, ``h w l``
    and ``rotation_y``."""
    keys = None
    for t in tables:
        k = sorted(zip(map(str, t[variant]["frame"]), map(int, t[variant]["gt_index"])))
        if keys is not None and k != keys:
            raise ValueError("the runs' true positives differ: only runs on the same label boxes compare")
        keys = k
    frames = sorted({f for f, _ in keys})
    held = set(frames)
    cost = np.array([[float(np.sum(r.est_cost)) for r in sorted(rs, key=lambda r: r.frame_id) if r.frame_id in held]
                     for rs in records])  # (R, frames)
    out = {}
    for i, f in enumerate(frames):
        rows = []
        for t in tables:
            tab = t[variant]
            sel = np.flatnonzero(np.asarray(tab["frame"]).astype(str) == f)
            sel = sel[np.argsort(np.asarray(tab["gt_index"])[sel])]
            rows.append((np.asarray(tab["pass_loc"])[sel], np.asarray(tab["pass_iou"])[sel], np.asarray(tab["iou"])[sel],
                         _box_rows(tab["fitted"], sel), _box_rows(tab["labels"], sel)))
        loc, ok, iou, fitted = (np.array([r[j] for r in rows]) for j in range(4))
        out[f] = (cost[:, i], loc.astype(bool), ok.astype(bool), iou.astype(float), fitted, rows[0][4])
    return frames, out


def _box_rows(boxes: Boxes, sel) -> np.ndarray:
    """``(len(sel), 7)``: bottom centre, ``h w l`` and ``rotation_y`` of ``boxes[sel]``."""
    return np.concatenate([boxes.location[sel], boxes.dims[sel], boxes.rotation_y[sel, None]], axis=1)


def mean_boxes(boxes: np.ndarray) -> Boxes:
    """The mean of ``(K, n, 7)`` boxes over K: bottom centre and size averaged, the heading
    by the mean of the doubled angle (a box is the same turned by pi), on the side of the
    first box's heading."""
    theta = boxes[..., 6]
    mean = 0.5 * np.arctan2(np.sin(2 * theta).mean(axis=0), np.cos(2 * theta).mean(axis=0))
    mean = np.where(np.cos(mean - theta[0]) < 0, mean + np.pi, mean)
    return Boxes.of(boxes[..., :3].mean(axis=0), boxes[..., 3:6].mean(axis=0), mean)


def best_of(cars: Mapping[str, tuple], frames: Sequence[str], k: int, n_runs: int) -> dict[str, dict[str, float]]:
    """Per selection: cars within 1 m, cars passing IoU 0.7 and mean 3D IoU over ``frames``,
    each frame keeping one of K runs, averaged over every K-subset of the ``n_runs`` runs."""
    out = {s: {"within 1 m": [], "IoU > 0.7": [], "mean IoU": []} for s in SELECTIONS}
    for subset in itertools.combinations(range(n_runs), k):
        sub = list(subset)
        tot = {s: [0, 0, []] for s in SELECTIONS}
        fitted = np.concatenate([cars[f][4][sub] for f in frames], axis=1)
        labels = np.concatenate([cars[f][5] for f in frames], axis=0)
        mean, truth = mean_boxes(fitted), Boxes.of(labels[:, :3], labels[:, 3:6], labels[:, 6])
        tests = passes(mean, truth)
        tot["average"] = [int(tests["loc"].sum()), int(tests["iou"].sum()),
                          list(iou_3d(mean.location, mean.dims, mean.rotation_y, truth.location, truth.dims,
                                      truth.rotation_y))]
        for f in frames:
            cost, loc, ok, iou = cars[f][:4]
            pick = {"objective": sub[int(np.argmin(cost[sub]))],
                    "oracle": sub[int(np.argmax(iou[sub].mean(axis=1)))],
                    "worst": sub[int(np.argmin(iou[sub].mean(axis=1)))]}
            for s, r in pick.items():
                tot[s][0] += int(loc[r].sum())
                tot[s][1] += int(ok[r].sum())
                tot[s][2].extend(iou[r])
        for s, (n_loc, n_ok, ious) in tot.items():
            out[s]["within 1 m"].append(n_loc)
            out[s]["IoU > 0.7"].append(n_ok)
            out[s]["mean IoU"].append(float(np.mean(ious)) if ious else float("nan"))
    return {s: {m: float(np.mean(v)) for m, v in ms.items()} for s, ms in out.items()}


def agreement(cars: Mapping[str, tuple], frames: Sequence[str]) -> dict[str, float]:
    """Over the frames' pairs of runs whose mean 3D IoU differs by more than 0.01: how often
    the run with the lower objective has the higher mean 3D IoU."""
    agree = pairs = 0
    for f in frames:
        cost, _, _, iou = cars[f][:4]
        m = iou.mean(axis=1)
        for a, b in itertools.combinations(range(len(cost)), 2):
            if abs(m[a] - m[b]) > 0.01 and cost[a] != cost[b]:
                pairs += 1
                agree += int((cost[a] < cost[b]) == (m[a] > m[b]))
    return {"pairs": pairs, "agree": agree, "share": agree / pairs if pairs else float("nan")}


def report(cars: Mapping[str, tuple], frames_of_group: Mapping[str, Sequence[str]], n_runs: int) -> dict:
    """Per fold group: the car count, best-of-K for K = 1..n and the objective's agreement."""
    out = {}
    for group, frames in frames_of_group.items():
        out[group] = {"cars": int(sum(cars[f][1].shape[1] for f in frames)),
                      "best of": {k: best_of(cars, frames, k, n_runs) for k in range(1, n_runs + 1)},
                      "agreement": agreement(cars, frames)}
    return out


def format_report(variant: str, rep: Mapping) -> str:
    lines = [f"== {variant}: each frame keeps, of K runs, the one with the lowest objective (mean over K-subsets)"]
    for group, g in rep.items():
        a = g["agreement"]
        lines.append(f"-- {group} ({g['cars']} cars); lower objective = higher mean 3D IoU in {a['agree']} of "
                     f"{a['pairs']} pairs of runs ({100 * a['share']:.0f}%)")
        lines.append(f"  {'K':>2}  {'objective: 1 m / IoU0.7 / IoU':>32}" + "".join(f"  {s:>24}" for s in SELECTIONS[1:]))
        for k, sel in g["best of"].items():
            cells = [f"{s['within 1 m']:6.1f} {s['IoU > 0.7']:6.1f} {s['mean IoU']:.4f}" for s in sel.values()]
            lines.append(f"  {k:>2}  {cells[0]:>32}" + "".join(f"  {c:>24}" for c in cells[1:]))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (module docstring); ``argv`` as for :meth:`argparse.ArgumentParser.parse_args`."""
    ap = seed_run_parser(__doc__)
    args = ap.parse_args(argv)
    runs, seeds = seed_runs(ap, args.runs)
    dataset = KittiDataset(args.root)
    tables, records = [], []
    for r in runs:
        recs, _, by_variant = run_tables(r, dataset, camera_height=KITTI_CAMERA_HEIGHT, keep_boxes=True)
        tables.append(by_variant)
        records.append(recs)
    variants = chosen_variants(ap, tables, args.variant)
    drive_of = frame_drives()
    out = {}
    for v in variants:
        try:
            frames, cars = frame_arrays(tables, [rec[v] for rec in records], v)
        except ValueError as exc:
            ap.error(str(exc))
        missing = [f for f in frames if f not in drive_of]
        if missing:
            ap.error(f"frame {missing[0]} has no drive in wirescene's drive map")
        groups = {g: [f for f in frames if DRIVE_FOLDS[drive_of[f]] in folds] for g, folds in GROUPS.items()}
        out[v] = report(cars, groups, len(runs))
        print(format_report(v, out[v]))
    if args.json:
        write_json(args.json, {"runs": [str(r) for r in runs], "seeds": seeds, "variants": out})
        print(f"json: {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
