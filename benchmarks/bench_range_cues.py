"""Cues to the range of a fitted car beyond the one the fit uses (issue 29): would any of them place
cars better?

The fit puts each car on the ground plane: its range along the viewing ray follows from where
the box's bottom meets the plane, and its size is what the box then needs (held near KITTI's mean
by the size prior). ``bench_error_budget.py`` shows range deciding both the 1 m test and IoU 0.7.
Three checks on the true positives of one or more runs of ``bench_real_folds.py``, per fold group:

1. **Size against plane.** A car that the plane places too far must look too large to fill its
   box. Each car is moved along its ray by ``(h_mean / h) ** k`` (its dimensions scaled alike, so
   its image stays), ``h`` the fitted height and ``h_mean`` KITTI's mean car height: ``k = 0`` is
   the fit, ``k = 1`` trusts the mean height alone. If size told the range better than the plane,
   some ``k > 0`` would gain in both fold groups. The row ``k(z)`` weighs the two cues by their
   variances at each car's range (:func:`error_model_power`, no parameter chosen on the figures):
   the size prior's strength against distance (issue 29).
2. **Two fits of the same boxes** (``--pair RUN_B``, another seed of the same detections): each
   alone, their average (positions and sizes; azimuths within 90 deg averaged) and the one of
   lower objective. How much of the error is the sampler's, not the model's?
3. **The plane's pitch.** Per frame with ``--min-cars`` or more true positives, least-squares
   planes through the fitted and the labelled bottom centres: the median pitch difference is
   what a cue from the image itself (the horizon, the road's vanishing point) would have to
   beat, at the focal length's pixels per degree.

    python benchmarks/bench_range_cues.py RUN [--pair RUN_B] --root ../shared/data/kitti
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.eval.kitti_metrics import iou_3d
from wirescene.eval.metrics import evaluate
from wirescene.io.folds import FOLD_GROUPS, fold_of
from wirescene.io.kitti import KittiDataset

#: KITTI's mean car height (m), the size prior's.
MEAN_HEIGHT = 1.526
#: KITTI's spread of car heights (m, sd: ``core.boxes.KITTI_CAR_SIZE``), the size cue's own error.
HEIGHT_SD = 0.14
#: Spread (m, sd) of the labelled cars' bottoms about their frame's least-squares plane (RESULTS.md, "Fine stage:
#: other cues to a car's range": 283 cars): each car's own ground, which no plane tells.
GROUND_SD = 0.056
#: The camera's height above the road (m, KITTI's mount).
CAMERA_HEIGHT = 1.65
SIZE_POWERS = (0.0, 0.25, 0.5, 0.75, 1.0)
VARIANTS = ("coarse+gp", "fg+gp", "full")


def true_positives(results) -> list[tuple]:
    """``(frame, record, det_index, label)`` of every true positive of the paper's protocol."""
    by_frame = {r.frame_id: r for r in results}
    return [(tp.frame_id, by_frame[tp.frame_id], tp.det_index, by_frame[tp.frame_id].gt[tp.gt_index])
            for tp in evaluate(results).records]


def scores(location, dims, rotation_y, labels) -> tuple[np.ndarray, np.ndarray]:
    """``(within 1 m, IoU > 0.7)`` per car, bottom centres compared, ``(N, 3)`` arrays."""
    g_loc = np.array([lab.location for lab in labels], float).reshape(-1, 3)
    g_dims = np.array([lab.dims for lab in labels], float).reshape(-1, 3)
    g_rot = np.array([lab.rotation_y for lab in labels], float)
    near = np.linalg.norm(location - g_loc, axis=1) < 1.0
    return near, iou_3d(location, dims, rotation_y, g_loc, g_dims, g_rot) > 0.7


def _arrays(tps, cameras) -> dict:
    return {"group": np.array([next(i for i, g in enumerate(FOLD_GROUPS) if fold_of(f) in g) for f, *_ in tps]),
            "centre": np.array([cameras[f].center for f, *_ in tps], float).reshape(-1, 3),
            "focal": np.array([cameras[f].P[0, 0] for f, *_ in tps], float),
            "location": np.array([r.est_location[d] for _, r, d, _ in tps], float).reshape(-1, 3),
            "dims": np.array([r.est_dims[d] for _, r, d, _ in tps], float).reshape(-1, 3),
            "rotation_y": np.array([r.est_rotation_y[d] for _, r, d, _ in tps], float),
            "cost": np.array([r.est_cost[d] for _, r, d, _ in tps], float),
            "labels": [lab for *_, lab in tps]}


def _row(name: str, group: np.ndarray, near: np.ndarray, iou: np.ndarray) -> str:
    cells = [f"{int(near[group == g].sum())} / {int(iou[group == g].sum())} of {int(np.sum(group == g))}"
             for g in range(len(FOLD_GROUPS))]
    return f"| {name} | " + " | ".join(cells) + f" | {int(near.sum())} / {int(iou.sum())} |"


def error_model_power(z: np.ndarray, focal: np.ndarray) -> np.ndarray:
    """The weight ``k`` ``(N,)`` of the size cue against the plane at ranges ``z`` ``(N,)`` (m) of
    cameras of ``focal`` lengths (px): the variance of the plane's relative range error (each car's
    own ground, :data:`GROUND_SD`, and one pixel at the ground contact) over the sum of it and the
    size cue's (:data:`HEIGHT_SD`, and one pixel of the box's height). About 0.13 at 10 m and
    0.24 at 60 m for KITTI.

    Examples
    --------
    >>> np.round(error_model_power(np.array([10.0, 60.0]), np.array([721.5, 721.5])), 2)
    array([0.13, 0.24])
    """
    plane = (GROUND_SD / CAMERA_HEIGHT) ** 2 + (z / (focal * CAMERA_HEIGHT)) ** 2
    size = (HEIGHT_SD / MEAN_HEIGHT) ** 2 + (z / (focal * MEAN_HEIGHT)) ** 2
    return plane / (plane + size)


def size_against_plane(cars: dict) -> list[str]:
    powers = {f"k = {k:g}": k for k in SIZE_POWERS}
    powers["k(z), error model"] = error_model_power(cars["location"][:, 2], cars["focal"])
    rows = []
    for name, k in powers.items():
        f = (MEAN_HEIGHT / cars["dims"][:, 0]) ** k
        loc = cars["centre"] + (cars["location"] - cars["centre"]) * f[:, None]
        near, iou = scores(loc, cars["dims"] * f[:, None], cars["rotation_y"], cars["labels"])
        rows.append(_row(name, cars["group"], near, iou))
    return rows


def two_fits(a: dict, b: dict) -> list[str]:
    turn = np.angle(np.exp(1j * (b["rotation_y"] - a["rotation_y"])))
    mean_rot = np.where(np.abs(turn) < np.pi / 2, a["rotation_y"] + turn / 2, a["rotation_y"])
    lower = (a["cost"] <= b["cost"])[:, None]
    cases = {"run A": (a["location"], a["dims"], a["rotation_y"]),
             "run B": (b["location"], b["dims"], b["rotation_y"]),
             "average": ((a["location"] + b["location"]) / 2, (a["dims"] + b["dims"]) / 2, mean_rot),
             "lower objective": (np.where(lower, a["location"], b["location"]), np.where(lower, a["dims"], b["dims"]),
                                 np.where(lower[:, 0], a["rotation_y"], b["rotation_y"]))}
    return [_row(name, a["group"], *scores(*case, a["labels"])) for name, case in cases.items()]


def plane_pitch(tps, *, min_cars: int) -> tuple[int, float, float]:
    """``(frames, median |pitch difference| deg, spread of the labels' pitch deg)``."""
    by_frame: dict[str, list] = {}
    for f, r, d, lab in tps:
        by_frame.setdefault(f, []).append((r.est_location[d], lab.location))
    diffs, label_pitch = [], []
    for pairs in by_frame.values():
        if len(pairs) < min_cars:
            continue
        fitted, labelled = (np.array(p, float) for p in zip(*pairs))
        slopes = []
        for pts in (fitted, labelled):  # y (down) = a + b z + c x
            A = np.c_[np.ones(len(pts)), pts[:, 2], pts[:, 0]]
            slopes.append(np.degrees(np.arctan(np.linalg.lstsq(A, pts[:, 1], rcond=None)[0][1])))
        diffs.append(slopes[0] - slopes[1])
        label_pitch.append(slopes[1])
    if not diffs:
        return 0, float("nan"), float("nan")
    return len(diffs), float(np.median(np.abs(diffs))), float(np.std(label_pitch))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path, metavar="RUN")
    ap.add_argument("--pair", type=Path, default=None, metavar="RUN_B",
                    help="another run of the same detections (another seed)")
    ap.add_argument("--root", type=Path, required=True)
    ap.add_argument("--min-cars", type=int, default=5, help="true positives a frame needs for its plane check")
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    records, detections = read_run(args.run)
    pair = read_run(args.pair)[0] if args.pair else None
    head = "| | " + " | ".join(f"{g}: < 1 m / IoU > 0.7" for g in FOLD_GROUPS) + " | all |\n|---|" + "---|" * (
        len(FOLD_GROUPS) + 1)
    print(f"## {args.run.name} (detections {detections}); cars: true positives of the paper's protocol")
    for variant in VARIANTS:
        if variant not in records:
            continue
        tps = true_positives(records[variant])
        cameras = {f: dataset.camera(f) for f in {f for f, *_ in tps}}
        cars = _arrays(tps, cameras)
        print(f"\n### {variant}: size against plane (cars moved along the ray by (h_mean / h)^k)\n\n{head}")
        print("\n".join(size_against_plane(cars)))
        if pair is not None and variant in pair:
            other = {r.frame_id: r for r in pair[variant]}
            for f, r, d, _ in tps:
                if not np.allclose(other[f].det_boxes[d], r.det_boxes[d]):
                    raise SystemExit(f"{args.pair}: frame {f} has other detections than {args.run}")
            b = _arrays([(f, other[f], d, lab) for f, _, d, lab in tps], cameras)
            print(f"\n### {variant}: two fits of the same boxes ({args.run.name}, {args.pair.name})\n\n{head}")
            print("\n".join(two_fits(cars, b)))
        n, pitch, spread = plane_pitch(tps, min_cars=args.min_cars)
        focal = float(np.median([c.P[1, 1] for c in cameras.values()]))
        print(f"\nplane through the bottoms ({n} frames with >= {args.min_cars} true positives): median |fitted - "
              f"labelled pitch| {pitch:.2f} deg = {np.radians(pitch) * focal:.1f} px; the labels' pitch varies by "
              f"{spread:.2f} deg (sd)")


if __name__ == "__main__":
    main()
