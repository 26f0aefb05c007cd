"""Held-out detections of several detector runs side by side, by fold group, with their mean and range.

Each run is the ``--save-dets`` file of ``bench_predetect.py --from-raw DIR`` (every frame
detected by the fold bank trained without its drive): typically the same recipe trained
with several ``--train-seed`` values, so that a detector change is read against the
training's own noise. Per run: moderate 2D AP on each fold group
(:data:`wirescene.io.folds.FOLD_GROUPS`), pooled easy / moderate / hard and moderate at IoU
0.5 (devkit rules), and at the fit's threshold the detections, the cars found at IoU 0.5 per
fold group, and the cars any detection reaches at IoU 0.5 (``_common.operating_point``);
then the mean and range of each figure over the runs.

    python benchmarks/bench_detector_seeds.py --root ../shared/data/kitti s0=DETS0.npz s1=DETS1.npz [--json OUT]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import operating_point, read_saved_detections  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.eval.kitti_metrics import detection_ap_2d  # noqa: E402
from wirescene.fitting.options import PredetectOptions  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402

FIT_THRESHOLD = PredetectOptions().threshold  # the fit's own threshold on our pre-detections


def run_figures(dets: dict, gts: dict, frames: list[str], *, threshold: float) -> dict:
    groups = {"".join(map(str, g)): [f for f in frames if fold_of(f) in g] for g in FOLD_GROUPS}
    pooled = detection_ap_2d([dets[f] for f in frames], [gts[f] for f in frames])
    out = {f"moderate {{{','.join(g)}}}": detection_ap_2d([dets[f] for f in fr], [gts[f] for f in fr])["2d"]["moderate"]
           for g, fr in groups.items()}
    out.update({f"pooled {k}": pooled["2d"][k] for k in ("easy", "moderate", "hard")})
    out["pooled moderate IoU 0.5"] = pooled["2d_iou_0.5"]["moderate"]
    at = {g: operating_point([dets[f] for f in fr], [gts[f] for f in fr], threshold) for g, fr in groups.items()}
    out[f"detections at {threshold:g}"] = sum(o["n_detections"] for o in at.values())
    for g, o in at.items():  # the cars found lie among those a detection reaches at any score
        missed = o["missed_without_candidate"] + o["missed_below_threshold"]
        out[f"found at {threshold:g} {{{','.join(g)}}}"] = o["n_cars"] - missed
    out["reached"] = sum(o["n_cars"] - o["missed_without_candidate"] for o in at.values())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", help="NAME=DETS.npz (bench_predetect.py --save-dets), two or more")
    ap.add_argument("--root", required=True, help="the KITTI root the detections were scored on")
    ap.add_argument("--threshold", type=float, default=FIT_THRESHOLD, help="the operating point of the counts")
    ap.add_argument("--json", default=None, help="write every run's figures and their summary here")
    args = ap.parse_args()
    runs = {}
    for spec in args.runs:
        name, sep, path = spec.partition("=")
        if not sep or not name or not path:
            raise SystemExit(f"{spec}: expected NAME=DETS.npz")
        if not Path(path).is_file():
            raise SystemExit(f"{path}: no such detections file")
        runs[name] = Path(path)
    ds = KittiDataset(args.root)
    frames = ds.frame_ids()
    gts = {f: ds.labels(f) for f in frames}
    cars = {"".join(map(str, g)): sum(len(gts[f].of_type("Car")) for f in frames if fold_of(f) in g) for g in FOLD_GROUPS}
    figures = {name: run_figures(read_saved_detections(p, frames), gts, frames, threshold=args.threshold)
               for name, p in runs.items()}
    first = next(iter(figures.values()))
    keys = list(first)
    width = max(len(n) for n in list(runs) + ["range"])
    print(f"{len(frames)} frames; cars per fold group: " + ", ".join(f"{{{','.join(g)}}} {n}" for g, n in cars.items())
          + "; found / reached: cars at IoU 0.5 (reached: by a detection at any score)")
    print(" " * width + " | " + " | ".join(keys))
    for name, fig in figures.items():
        print(f"{name:<{width}} | " + " | ".join(f"{fig[k]:.1f}" if isinstance(fig[k], float) else str(fig[k])
                                                 for k in keys))
    summary = {}
    for k in keys:
        v = np.array([fig[k] for fig in figures.values()], float)
        summary[k] = {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())}
    print(f"{'mean':<{width}} | " + " | ".join(f"{summary[k]['mean']:.1f}" for k in keys))
    print(f"{'range':<{width}} | " + " | ".join(f"{summary[k]['min']:.{d}f}-{summary[k]['max']:.{d}f}"
                                                for k in keys for d in [1 if isinstance(first[k], float) else 0]))
    if args.json:
        write_json(args.json, {"runs": figures, "summary": summary, "threshold": args.threshold})


if __name__ == "__main__":
    main()
