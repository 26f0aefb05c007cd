"""Is the range bias of the fitted cars a correctable constant, or a 2D-box convention?

Two checks behind issue 29's "range is biased long":

1. ``--budget B.json`` (the ``--json`` of ``bench_error_budget.py``): per run and variant,
   the median relative range error (fitted minus label over the label's range) of the true
   positives of one fold group is divided out of the other group's fitted ranges, both
   ways; the share within 1 m before and after, per group.
2. ``--root KITTI``: KITTI's labelled 2D box against the projection of the label's own 3D
   box (unoccluded, untruncated cars): if the projection were larger than the labelled box,
   fitting 3D boxes to 2D ones would push cars away.

    python benchmarks/bench_range_bias.py --budget B.json --root KITTI
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from wirescene.core.jsonio import write_json
from wirescene.io.folds import FOLD_GROUPS, fold_of


def corrected_within_1m(cars: dict) -> list[dict]:
    """Per held-out fold group: the bias fitted on the other, the share within 1 m before and after."""
    x = {k: np.asarray(v) for k, v in cars.items() if k != "frame"}
    folds = np.array([fold_of(f) for f in cars["frame"]])
    fitted = x["label_range"] + x["range"]
    out = []
    for train, test in (FOLD_GROUPS, FOLD_GROUPS[::-1]):
        bias = float(np.median((x["range"] / x["label_range"])[np.isin(folds, train)]))
        m = np.isin(folds, test)
        before = np.sqrt(x["lateral"][m] ** 2 + x["range"][m] ** 2 + x["height"][m] ** 2)
        new_range = fitted[m] / (1 + bias) - x["label_range"][m]
        after = np.sqrt(x["lateral"][m] ** 2 + new_range ** 2 + x["height"][m] ** 2)
        out.append({"test": list(test), "bias_fitted_on_other": 100 * bias, "cars": int(m.sum()),
                    "bias_here": 100 * float(np.median((x["range"] / x["label_range"])[m])),
                    "within_1m_before": 100 * float(np.mean(before < 1)), "within_1m_after": 100 * float(np.mean(after < 1))})
    return out


def projected_label_boxes(root: Path) -> dict:
    """Median ratios of the projected 3D label box to the labelled 2D box, by depth band."""
    from wirescene.core.boxes import box_extent_object
    from wirescene.core.groundplane import rotation_y
    from wirescene.io.kitti import KittiDataset
    from wirescene.lift import project_boxes

    ds = KittiDataset(root)
    rows = []
    for f in ds.frame_ids():
        camera = ds.camera(f)
        for o in ds.labels(f).objects:
            if o.type != "Car" or o.truncated > 0.05 or o.occluded > 0:
                continue
            p, _ = project_boxes(camera, *box_extent_object(np.asarray(o.dims, float)), np.asarray(o.location, float),
                                 rotation_y(o.rotation_y))
            g = o.box
            rows.append([(p[2] - p[0]) / (g[2] - g[0]), (p[3] - p[1]) / (g[3] - g[1]), p[3] - g[3], o.location[2]])
    r = np.array(rows)
    bands = {}
    for lo, hi in ((0, 15), (15, 25), (25, 35), (35, 200)):
        m = (r[:, 3] >= lo) & (r[:, 3] < hi)
        bands[f"{lo}-{hi} m"] = {"cars": int(m.sum()), "width_ratio": float(np.median(r[m, 0])),
                                 "height_ratio": float(np.median(r[m, 1]))}
    return {"cars": len(r), "width_ratio": float(np.median(r[:, 0])), "height_ratio": float(np.median(r[:, 1])),
            "bottom_px": float(np.median(r[:, 2])), "bands": bands}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=Path, required=True, help="bench_error_budget.py --json output")
    ap.add_argument("--root", type=Path, default=None, help="KITTI root for the projection check")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    runs = json.loads(args.budget.read_text())["runs"]
    out = {"correction": {}}
    for body in runs.values():
        for variant, cars in body["cars"].items():
            rows = out["correction"].setdefault(f"{body['detections']}:{variant}", corrected_within_1m(cars))
            print(f"{body['detections']:4s} {variant:9s} " + " | ".join(
                f"{r['test']} ({r['cars']} cars) bias here {r['bias_here']:+.1f}%, other group's {r['bias_fitted_on_other']:+.1f}%:"
                f" within 1 m {r['within_1m_before']:.1f} -> {r['within_1m_after']:.1f}" for r in rows))
    if args.root is not None:
        out["projection"] = p = projected_label_boxes(args.root)
        print(f"projected 3D label box / labelled 2D box ({p['cars']} unoccluded untruncated cars): width "
              f"{p['width_ratio']:.3f}, height {p['height_ratio']:.3f}, bottom {p['bottom_px']:+.2f} px")
        for band, b in p["bands"].items():
            print(f"  {band}: {b['cars']} cars, width {b['width_ratio']:.3f}, height {b['height_ratio']:.3f}")
    if args.json:
        write_json(args.json, out)


if __name__ == "__main__":
    main()
