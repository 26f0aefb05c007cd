"""What the pre-detection's early cut costs and saves (plain script, not a test).

The bank's box refinement and verifier cost two HOG crops per cluster, and a frame holds
hundreds of clusters, most far below any threshold. ``verify_within`` (margin units) drops,
when a threshold is given, the clusters more than that below it before those two steps.
Every frame is detected by its fold's bank (held out by drive) at the given calibrated
thresholds, once without the cut and once per ``--within`` value, side by side: the CPU
seconds of each call, the clusters the steps saw, and what changed at each threshold (the
detections kept, those on a car at IoU >= 0.5, frames whose detections differ), per fold
group and pooled.

Usage:
  python benchmarks/bench_verify_within.py --root ../shared/data/kitti --fold-models DIR --within 1 2 3 4
  [--folds 0 1 --json A.json]   (one fold group a process, the other beside it)
  (DIR holds fold{k}.npz, each trained without fold k's drives; or a path pattern with {k})
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import wirescene.predetect.bank as bank_module  # noqa: E402
from wirescene.core.boxes import iou_2d  # noqa: E402
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.fitting.options import PredetectOptions  # noqa: E402
from wirescene.io.folds import N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.bank import DetectorBank, bank_pyramid, detect_cars  # noqa: E402

GROUPS = ((0, 1), (2, 3))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", required=True)
    ap.add_argument("--fold-models", required=True,
                    help="fold banks DIR/fold{k}.npz (or a path pattern with {k}), each trained without fold k")
    ap.add_argument("--within", type=float, nargs="+", default=[1.0, 2.0, 3.0, 4.0])
    ap.add_argument("--thresholds", type=float, nargs="+", default=None,
                    help="calibrated thresholds (default: the fit's and each bank's own)")
    ap.add_argument("--frames", type=int, default=None, help="every n-th frame only")
    ap.add_argument("--folds", type=int, nargs="+", default=None, help="only the frames of these folds")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    ds = KittiDataset(args.root)
    pattern = args.fold_models if "{k}" in args.fold_models else str(Path(args.fold_models) / "fold{k}.npz")
    banks = {k: DetectorBank.load(pattern.format(k=k)) for k in range(N_FOLDS)}
    thresholds = args.thresholds or sorted({PredetectOptions().threshold, float(banks[0].threshold)})
    ids = [f for f in ds.frame_ids()[:: args.frames or 1] if args.folds is None or fold_of(f) in args.folds]
    settings = [None, *args.within]
    verified = {}  # clusters the verifier saw, per setting

    original = bank_module.verification_logits

    def counting(bank, gray, boxes, bins, **kw):
        verified[current] = verified.get(current, 0) + len(boxes)
        return original(bank, gray, boxes, bins, **kw)

    bank_module.verification_logits = counting
    rows = {t: {str(s): [] for s in settings} for t in thresholds}  # per frame: (group, kept, on car, same)
    cpu = {str(s): 0.0 for s in settings}
    for f in ids:
        image, camera, bank = ds.image(f), ds.camera(f), banks[fold_of(f)]
        gt = np.array([o.box for o in ds.labels(f).objects if o.type == "Car"], float).reshape(-1, 4)
        group = next(g for g, folds in enumerate(GROUPS) if fold_of(f) in folds)
        pyramid = bank_pyramid(bank, image)  # shared: the cut acts after the templates
        for t in thresholds:
            reference = None
            for s in settings:  # side by side, frame by frame: load falls on all alike
                current = str(s)
                c = time.process_time()
                d = detect_cars(image, bank=bank, camera=camera, threshold=t, pyramid=pyramid, verify_within=s)
                cpu[current] += time.process_time() - c
                on = int((iou_2d(d.boxes[:, None], gt[None]).max(1) >= 0.5).sum()) if len(d) and len(gt) else 0
                if reference is None:
                    reference = d
                same = len(d) == len(reference) and np.array_equal(d.boxes, reference.boxes) and np.array_equal(
                    d.scores, reference.scores)
                rows[t][current].append((group, len(d), on, same))
    report = {"frames": len(ids), "thresholds": thresholds, "cpu_seconds_per_call": {}, "verified_per_call": {},
              "by_threshold": {}}
    calls = len(ids) * len(thresholds)
    for s in settings:
        report["cpu_seconds_per_call"][str(s)] = cpu[str(s)] / calls
        report["verified_per_call"][str(s)] = verified.get(str(s), 0) / calls
        print(f"verify_within {s}: {cpu[str(s)] / calls:.3f} s of CPU a call, {verified.get(str(s), 0) / calls:.0f} "
              f"clusters verified a call")
    for t in thresholds:
        report["by_threshold"][str(t)] = {}
        for s in settings:
            r = np.array(rows[t][str(s)], int).reshape(-1, 4)
            entry = {}
            for name, mask in (("{0, 1}", r[:, 0] == 0), ("{2, 3}", r[:, 0] == 1), ("pooled", np.ones(len(r), bool))):
                entry[name] = {"detections": int(r[mask, 1].sum()), "on_car": int(r[mask, 2].sum()),
                               "frames_differing": int((r[mask, 3] == 0).sum())}
            report["by_threshold"][str(t)][str(s)] = entry
            print(f"threshold {t}, verify_within {s}: " + "; ".join(
                f"{g} {e['detections']} detections, {e['on_car']} on a car, {e['frames_differing']} frames differ"
                for g, e in entry.items()))
    if args.json:
        write_json(args.json, report)


if __name__ == "__main__":
    main()
