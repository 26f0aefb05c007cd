"""Is the ground plane's height worth estimating per frame, and can the fit estimate it?

The fit stands every car on a plane through the point ``camera_height`` (1.65 m, KITTI's
mount) below the camera, tilted by the searched pitch and roll. Near cars sit 4-5x their
one-pixel range limit off, and their range error follows their height error along the ray
(``bench_error_budget.py``). Issue 29 asks for the plane's height to be checked against the
camera's. Three checks, each optional:

1. ``--oracle RUN``: the bound. The true positives of each variant of a
   ``bench_real_folds.py`` run, as fitted; with every car of a frame moved along its ray by
   the frame's one factor that puts the frame's cars at their labels' height below the
   camera (median over its cars: the best single plane height per frame the labels allow);
   onto the labels' least-squares plane (height, pitch and roll) in frames with
   :data:`PLANE_MIN_CARS` cars or more; and with each car moved by its own factor (its height
   error removed along the ray).
2. ``--boxes``: the coarse stage's choice. Label boxes lifted at every height of a grid;
   per frame the height whose shared-plane consensus cost (as ``coarse+gp`` ranks planes)
   plus ``weight * ((h - 1.65) / sd)**2`` is least; ``coarse+gp``'s bottom centres (mean car
   size) within 1 m, per fold group, against 1.65 m fixed and the labels' best height.
3. ``--fine H=RUN ...``: the fine stage's choice. Runs of one fine variant, each fitted
   with ``--set lifting.camera_height=H`` (label boxes, same seed); per frame the run whose
   summed objective plus the same prior is least.

A setting is chosen on one fold group and read on the other (``io.folds.FOLD_GROUPS``).

    python benchmarks/bench_plane_height.py --root ../shared/data/kitti --oracle RUN_GT --boxes \\
        --fine 1.55=R155 1.60=R160 1.65=R165 1.70=R170 1.75=R175
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import read_run  # noqa: E402
from bench_error_budget import Boxes, error_components, passes, true_positive_cars  # noqa: E402
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402

#: The row of the fit as shipped, against which the choices are read.
REFERENCE = f"{KITTI_CAMERA_HEIGHT:.2f} fixed"
#: (sd in m, weight) pairs of the prior on the plane height the choices are read with.
PRIORS = tuple((sd, w) for sd in (0.03, 0.08) for w in (0.001, 0.01, 0.1))
#: Label depth (m) below which a car is near.
NEAR = 15.0
#: Frames with at least this many true positives get the labels' own plane in the bound (3 parameters).
PLANE_MIN_CARS = 7
#: Plane heights of the coarse stage's grid (m).
BOX_HEIGHTS = tuple(np.round(np.arange(1.45, 1.851, 0.05), 3))


def _groups(frames) -> dict[str, np.ndarray]:
    folds = np.array([fold_of(f) for f in frames])
    return {str(g): np.isin(folds, g) for g in FOLD_GROUPS}


def moved_along_rays(cars: dict, factor: np.ndarray) -> Boxes:
    """The fitted boxes of :func:`true_positive_cars` ``cars`` with each bottom centre moved
    along its ray from the camera centre by ``factor`` (N,)."""
    c, f = cars["camera_centre"], cars["fitted"]
    return Boxes(c + (f.location - c) * factor[:, None], f.dims, f.rotation_y)


def oracle_bounds(records: dict, cameras: dict) -> dict:
    """Per variant and fold group: the true positives, and the shares within 1 m and at IoU
    > 0.7 as fitted, with the best plane height per frame and with each car's own height."""
    out = {}
    for variant, results in records.items():
        cars = true_positive_cars(results, cameras)
        c, fitted, labels = cars["camera_centre"], cars["fitted"], cars["labels"]
        per_car = (labels.location[:, 1] - c[:, 1]) / (fitted.location[:, 1] - c[:, 1])
        per_frame, plane = np.ones(len(per_car)), np.ones(len(per_car))
        for f in set(cars["frame"]):
            m = cars["frame"] == f
            per_frame[m] = plane[m] = np.median(per_car[m])
            if m.sum() >= PLANE_MIN_CARS:
                # the labels' least-squares plane y = a + b z + d x; each fitted car moved onto it along its ray
                # (to first order: the plane's height at the fitted car)
                A = np.column_stack([np.ones(m.sum()), fitted.location[m, 2], fitted.location[m, 0]])
                coef = np.linalg.lstsq(np.column_stack([np.ones(m.sum()), labels.location[m, 2],
                                                        labels.location[m, 0]]), labels.location[m, 1], rcond=None)[0]
                plane[m] = (A @ coef - c[m, 1]) / (fitted.location[m, 1] - c[m, 1])
        tests = {"as fitted": passes(fitted, labels),
                 "height per frame": passes(moved_along_rays(cars, per_frame), labels),
                 "plane per frame": passes(moved_along_rays(cars, plane), labels),
                 "height per car": passes(moved_along_rays(cars, per_car), labels)}
        out[variant] = {g: {"cars": int(m.sum()), **{k: (100 * t["loc"][m].mean(), 100 * t["iou"][m].mean())
                                                      for k, t in tests.items()}}
                        for g, m in _groups(cars["frame"]).items()}
        # near whole cars: how far their bottoms stand above the plane, and how their range error follows it
        errors = error_components(fitted, labels, c)
        drop = fitted.location[:, 1] - labels.location[:, 1]  # +: the fitted car stands lower than its label
        near = (labels.location[:, 2] < NEAR) & (cars["truncated"] <= 0)
        for g, m in _groups(cars["frame"]).items():
            out[variant][g]["near"] = (int((m & near).sum()), float(np.median(drop[m & near])) if (m & near).any()
                                       else float("nan"))
        out[variant]["near correlation"] = {k: float(np.corrcoef(errors["range"][near], x[near])[0, 1])
                                            for k, x in (("height", drop), ("length", errors["dl"]))}
    return out


def lifted_heights(dataset: KittiDataset, heights) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Per frame with a car: ``(frame, is_car (N,), label bottoms (N, 3), [(cost, bottoms (N, 3))
    per height])`` of the label boxes lifted with the shared plane of ``coarse+gp``."""
    from wirescene.core.groundplane import point_on_plane
    from wirescene.io.detections import detections_from_labels
    from wirescene.io.kitti import CAR_TYPES
    from wirescene.lift import LiftingOptions, lift_table, plane_vote_weights

    rows = []
    for f in dataset.frame_ids():
        labels = dataset.labels(f)
        objs = labels.of_type(*CAR_TYPES)
        if not any(o.type == "Car" for o in objs):
            continue
        det, camera = detections_from_labels(labels), dataset.camera(f)
        w = plane_vote_weights(det.scores)
        costs, bottoms = [], []
        for h in heights:
            opts = LiftingOptions(camera_height=float(h))
            t = lift_table(camera, det, options=opts)
            total = w @ np.minimum(t.cost, opts.robust_cost) + 1e-3 * (w @ t.cost)  # select_particles' ranking
            g = int(np.argmin(total))
            costs.append(total[g])
            bottoms.append(point_on_plane(t.x[:, g], t.z[:, g], t.pitch[g], t.roll[g], float(h)))
        rows.append((f, np.array([o.type == "Car" for o in objs]), np.array([o.location for o in objs], float),
                     np.array(costs), np.array(bottoms)))
    return rows


def box_choice_table(rows, heights) -> dict:
    """Within 1 m of the lifted cars per fold group: 1.65 m fixed, each prior of
    :data:`PRIORS`, and the labels' best height per frame."""
    heights = np.asarray(heights, float)

    def within(pick):
        dist, frames = [], []
        for f, is_car, label, cost, bottoms in rows:
            k = pick(cost, bottoms, label)
            dist.extend(np.linalg.norm(bottoms[k][is_car] - label[is_car], axis=1))
            frames.extend([f] * int(is_car.sum()))
        d = np.array(dist)
        return {g: (int(m.sum()), 100 * float(np.mean(d[m] < 1))) for g, m in _groups(frames).items()}

    fixed = int(np.argmin(abs(heights - KITTI_CAMERA_HEIGHT)))
    table = {REFERENCE: within(lambda c, b, label: fixed)}
    for sd, w in PRIORS:
        prior = w * ((heights - KITTI_CAMERA_HEIGHT) / sd) ** 2
        table[f"sd {sd}, weight {w}"] = within(lambda c, b, label, p=prior: int(np.argmin(c + p)))
    table["labels' best per frame"] = within(
        lambda c, b, label: int(np.argmin([np.median(np.linalg.norm(x - label, axis=1)) for x in b])))
    return table


def fine_choice_table(runs: dict[float, dict], cameras: dict) -> dict:
    """Per fine variant the runs hold: within 1 m and IoU > 0.7 per fold group for each
    fixed height and, per prior of :data:`PRIORS`, the per-frame least summed objective."""
    heights = np.array(sorted(runs))
    out = {}
    for variant in sorted(set.intersection(*(set(r) for r in runs.values()))):
        by_height = [{r.frame_id: r for r in runs[h][variant]} for h in heights]
        frames = sorted(set.intersection(*(set(b) for b in by_height)))
        objective = np.array([[np.sum(b[f].est_cost) for b in by_height] for f in frames])  # (F, H)

        def score(choice, by_height=by_height, frames=frames):
            results = [by_height[k][f] for f, k in zip(frames, choice)]
            cars = true_positive_cars(results, cameras)
            t = passes(cars["fitted"], cars["labels"])
            return {g: (int(m.sum()), 100 * t["loc"][m].mean(), 100 * t["iou"][m].mean())
                    for g, m in _groups(cars["frame"]).items()}

        table = {f"{h:.2f} fixed": score(np.full(len(frames), k)) for k, h in enumerate(heights)}
        table["_objective"] = {"least at": np.bincount(objective.argmin(1), minlength=len(heights)).tolist(),
                               "median spread": float(np.median(objective.max(1) - objective.min(1))),
                               "median |frame objective|": float(np.median(np.abs(objective[:, len(heights) // 2]))),
                               "frames": len(frames)}
        for sd, w in PRIORS:
            prior = w * ((heights - KITTI_CAMERA_HEIGHT) / sd) ** 2
            table[f"sd {sd}, weight {w}"] = score(np.argmin(objective + prior, axis=1))
        out[variant] = table
    return out


def _held_out(table: dict, candidates, *, value=lambda v: v[1]) -> list[str]:
    """For each fold group: the candidate row best on it, read on the other group beside
    the :data:`REFERENCE` row."""
    groups = [str(g) for g in FOLD_GROUPS]
    lines = []
    for choose, report in (groups, groups[::-1]):
        best = max(candidates, key=lambda k: value(table[k][choose]))
        lines.append(f"chosen on {choose}: {best}; on {report} {value(table[best][report]):.1f}% "
                     f"({REFERENCE} {value(table[REFERENCE][report]):.1f}%)")
    return lines


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", required=True, type=Path)
    ap.add_argument("--oracle", type=Path, metavar="RUN", help="a bench_real_folds.py run to bound")
    ap.add_argument("--boxes", action="store_true", help="the coarse stage's choice on label boxes")
    ap.add_argument("--fine", nargs="+", default=[], metavar="H=RUN",
                    help="fine runs fitted at camera heights H (same variant, detections and seed)")
    args = ap.parse_args(argv)
    if not (args.oracle or args.boxes or args.fine):
        ap.error("nothing to do: give --oracle, --boxes or --fine")
    dataset = KittiDataset(args.root)
    cameras = {f: dataset.camera(f) for f in dataset.frame_ids()}
    if args.oracle:
        records, detections = read_run(args.oracle)
        print(f"## Bound ({args.oracle.name}, detections {detections}): within 1 m / IoU > 0.7 of the true positives\n")
        print(f"| variant | group | cars | as fitted | best plane height per frame | labels' plane per frame "
              f"({PLANE_MIN_CARS}+ cars) | each car's height |")
        print("|---|---|---|---|---|---|---|")
        bounds = oracle_bounds(records, cameras)
        for v, groups in bounds.items():
            for g, s in groups.items():
                if g == "near correlation":
                    continue
                cells = " | ".join(f"{s[k][0]:.1f}% / {s[k][1]:.1f}%"
                                   for k in ("as fitted", "height per frame", "plane per frame", "height per car"))
                print(f"| {v} | {g} | {s['cars']} | {cells} |")
        print(f"\nNear whole cars (label z < {NEAR:g} m): median fitted minus label bottom y (m, +: the car stands above "
              "the fitted plane) per group; correlation of the signed range error with it and with the length error")
        for v, groups in bounds.items():
            near = "; ".join(f"{g} {s['near'][1]:+.3f} ({s['near'][0]} cars)" for g, s in groups.items()
                             if g != "near correlation")
            r = groups["near correlation"]
            print(f"- {v}: {near}; correlation {r['height']:.2f} (height), {r['length']:.2f} (length)")
        print()
    if args.boxes:
        table = box_choice_table(lifted_heights(dataset, BOX_HEIGHTS), BOX_HEIGHTS)
        print("## The coarse stage's choice (label boxes, coarse+gp bottom centres, mean car size): within 1 m\n")
        groups = [str(g) for g in FOLD_GROUPS]
        print("| height | " + " | ".join(f"{g} (cars)" for g in groups) + " |")
        print("|---|" + "---|" * len(groups))
        for k, row in table.items():
            print(f"| {k} | " + " | ".join(f"{row[g][1]:.1f}% ({row[g][0]})" for g in groups) + " |")
        print("\n" + "\n".join(_held_out(table, [k for k in table if k.startswith("sd")])) + "\n")
    if args.fine:
        runs = {}
        for spec in args.fine:
            h, sep, run = spec.partition("=")
            if not sep:
                ap.error(f"--fine takes H=RUN, got {spec!r}")
            runs[float(h)] = read_run(Path(run))[0]
        for variant, table in fine_choice_table(runs, cameras).items():
            print(f"## The fine stage's choice ({variant}): cars, within 1 m, IoU > 0.7\n")
            groups = [str(g) for g in FOLD_GROUPS]
            print("| height | " + " | ".join(groups) + " |")
            print("|---|" + "---|" * len(groups))
            objective = table.pop("_objective")
            for k, row in table.items():
                print(f"| {k} | " + " | ".join(f"{row[g][0]}, {row[g][1]:.1f}%, {row[g][2]:.1f}%" for g in groups)
                      + " |")
            print(f"\nthe summed objective is least at {dict(zip(sorted(runs), objective['least at']))} "
                  f"(frames of {objective['frames']}); its median spread over the heights "
                  f"{objective['median spread']:.2f} against a median frame objective of "
                  f"{objective['median |frame objective|']:.2f} (absolute)")
            cands = [k for k in table if k.startswith("sd")]
            print("\nwithin 1 m: " + "; ".join(_held_out(table, cands)))
            print("IoU > 0.7: " + "; ".join(_held_out(table, cands, value=lambda v: v[2])) + "\n")


if __name__ == "__main__":
    main()
