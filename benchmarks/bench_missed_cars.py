"""Would a second source of candidates find the cars the detector bank misses?

Reads held-out detections of every frame (``bench_predetect.py --fold-models DIR --save-dets
D.npz``: each frame detected by the fold bank that never saw its drive, ``return_all``) and
the fold banks themselves. The missed cars are the ``Car`` labels no detection overlaps at
IoU >= 0.5. Each one's *label box* is shown to its fold bank's verifier (the second look at
every box, :func:`wirescene.predetect.bank.verification_logits`) with the label's viewpoint
bin and with the best of the 8 bins; the logits are compared with those of the detections
the fit keeps (``--threshold``), on a car and off every car. A missed car that the verifier
scores like the kept true detections needs only a proposal; one it scores like background
needs a better appearance model too.

    python benchmarks/bench_missed_cars.py --root ../shared/data/kitti --fold-models DIR --dets D.npz
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import read_saved_detections  # noqa: E402
from wirescene.core.boxes import iou_2d  # noqa: E402
from wirescene.core.viewpoints import N_BINS, viewpoint_bin  # noqa: E402
from wirescene.io.folds import N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.bank import DetectorBank, verification_logits  # noqa: E402
from wirescene.predetect.channels import integral_channels  # noqa: E402
from wirescene.predetect.hog import to_gray  # noqa: E402

HEIGHT_BANDS = ((0, 25), (25, 60), (60, np.inf))  # px, of the label box


def frame_logits(bank: DetectorBank, image, boxes, scores, alpha, cars, *, threshold: float, iou: float = 0.5):
    """``(kept on a car (K1,), kept off every car (K2,), missed (M, 3))``: the verifier's logits of
    the detections above ``threshold``, split by whether one overlaps a ``Car`` label box at
    ``iou``, and for each label no detection overlaps at ``iou``: its logit with the label's
    viewpoint bin, the best over the 8 bins, and the box's height."""
    gray, channels = to_gray(image), integral_channels(image)
    gt = np.array([o.box for o in cars], float).reshape(-1, 4)
    keep = scores > threshold
    kept = (verification_logits(bank, gray, boxes[keep], viewpoint_bin(alpha[keep]), channels=channels)
            if keep.any() else np.zeros(0))
    on = iou_2d(boxes[keep][:, None], gt[None]).max(1) >= iou if len(gt) and keep.any() else np.zeros(len(kept), bool)
    best = iou_2d(gt[:, None], boxes[None]).max(1) if len(gt) and len(boxes) else np.zeros(len(gt))
    m = np.flatnonzero(best < iou)
    if not len(m):
        return kept[on], kept[~on], np.zeros((0, 3))
    mb = gt[m]
    per_bin = np.column_stack([verification_logits(bank, gray, mb, np.full(len(m), b), channels=channels)
                               for b in range(N_BINS)])  # (M, 8)
    true_bin = per_bin[np.arange(len(m)), viewpoint_bin(np.array([cars[i].alpha for i in m]))]
    return kept[on], kept[~on], np.column_stack([true_bin, per_bin.max(1), mb[:, 3] - mb[:, 1]])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames (e.g. ../shared/data/kitti)")
    ap.add_argument("--fold-models", required=True, help="directory of the fold banks fold{k}.npz")
    ap.add_argument("--dets", required=True, help="their held-out detections (bench_predetect.py --save-dets)")
    ap.add_argument("--threshold", type=float, default=0.3, help="the detections the fit keeps (default: its 0.3)")
    args = ap.parse_args()
    ds = KittiDataset(args.root)
    banks = {k: DetectorBank.load(Path(args.fold_models) / f"fold{k}.npz") for k in range(N_FOLDS)}
    saved = read_saved_detections(args.dets, ds.frame_ids())
    tp, fp, missed = [], [], []
    for f in ds.frame_ids():
        cars = [o for o in ds.labels(f).objects if o.type == "Car"]
        a, b, c = frame_logits(banks[fold_of(f)], ds.image(f), saved[f].boxes, saved[f].scores,
                               saved[f].alpha, cars, threshold=args.threshold)
        tp.append(a)
        fp.append(b)
        missed.append(c)
    tp, fp, missed = np.concatenate(tp), np.concatenate(fp), np.concatenate(missed)
    q25, fp_median = np.quantile(tp, 0.25), np.median(fp)
    print(f"verifier logits of the detections above {args.threshold}: {len(tp)} on a car (median {np.median(tp):.2f}, "
          f"lower quartile {q25:.2f}), {len(fp)} off every car (median {fp_median:.2f})")
    print(f"{len(missed)} cars without a detection at IoU 0.5; their label boxes:")
    for name, col in (("label's bin", 0), ("best of 8 bins", 1)):
        v = missed[:, col]
        print(f"  {name}: median {np.median(v):.2f}; above the false detections' median {np.mean(v > fp_median):.0%}, "
              f"above the true ones' lower quartile {np.mean(v > q25):.0%} ({int(np.sum(v > q25))} cars)")
    for lo, hi in HEIGHT_BANDS:
        sel = (missed[:, 2] >= lo) & (missed[:, 2] < hi)
        if sel.any():
            print(f"  {lo}-{hi} px ({int(sel.sum())} cars), label's bin: above the true detections' lower quartile "
                  f"{np.mean(missed[sel, 0] > q25):.0%}, median {np.median(missed[sel, 0]):.2f}")


if __name__ == "__main__":
    main()
