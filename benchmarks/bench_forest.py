"""Speed of the part model's forest traversal (plain script, not a test).

The fit's part maps classify every grid point of every box at three scales, twice with
the mirrored reading: some 80,000 descriptors on a frame with 5 cars, each through the
30 trees of depth 13. This times :meth:`wirescene.parts.detector.PartDetector.predict_proba`
on the descriptors the part maps of a real frame classify, side by side in one run with
the straightforward traversal kept here as the reference (three table gathers a step:
feature, threshold and child; 16,384 rows at a time), at several chunk sizes, and checks
that every probability is the same to the bit.

Usage: python benchmarks/bench_forest.py [--root tests/data/kitti] [--frame 000010] [--cars 5] [--model PATH]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import best_of  # noqa: E402
from wirescene.infer.evidence import part_evidence  # noqa: E402
from wirescene.io.detections import detections_from_labels  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.parts.detector import N_CLASSES, PartDetector  # noqa: E402


def reference_proba(det: PartDetector, X, chunk: int = 16384) -> np.ndarray:
    """The traversal before the renumbered records: child, feature and threshold gathered
    from three tables at every step."""
    idx = np.arange(len(det.left), dtype=np.int32)
    leaf = det.left < 0
    child = np.stack([np.where(leaf, idx, det.left), np.where(leaf, idx, det.right)], 1).astype(np.int32).ravel()
    thr = det.threshold.astype(np.float32)
    over = thr.astype(np.float64) > det.threshold
    thr[over] = np.nextafter(thr[over], np.float32(-np.inf))
    feature = np.maximum(det.feature, 0).astype(np.intp)
    vals = det.values.astype(np.float32) / np.float32(det.value_scale * det.n_trees)
    out = np.empty((len(X), N_CLASSES))
    for s in range(0, len(X), chunk):
        x = X[s:s + chunk]
        n = len(x)
        node = np.broadcast_to(det.roots[None, :], (n, det.n_trees)).copy()
        flat = x.ravel()
        rows = (np.arange(n) * x.shape[1])[:, None]
        for _ in range(det.max_depth):
            node = child[2 * node + (flat[rows + feature[node]] > thr[node])]
        leaves = det.leaf[node]
        p = np.zeros((n, N_CLASSES), np.float32)
        for t in range(det.n_trees):
            p += vals[leaves[:, t]]
        p = p.astype(np.float64)
        if det.value_scale != 1.0:
            p /= np.maximum(p.sum(axis=1, keepdims=True), 1e-12)
        out[s:s + n] = p
    return out


def frame_descriptors(det: PartDetector, root, frame: str, cars: int | None) -> np.ndarray:
    """The descriptors the part maps of ``frame`` classify (both readings), as the fit computes them."""
    ds = KittiDataset(root)
    dets = detections_from_labels(ds.labels(frame))
    if cars is not None:
        dets = dets.subset(np.arange(min(cars, len(dets))))
    seen = []
    predict = det.predict_proba
    det.predict_proba = lambda X, **kw: (seen.append(np.array(X, np.float32)), predict(X, **kw))[1]
    try:
        part_evidence(ds.image(frame), dets, detector=det, flip=True)
    finally:
        del det.predict_proba
    return np.concatenate(seen)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", default=str(Path(__file__).resolve().parents[1] / "tests" / "data" / "kitti"))
    ap.add_argument("--frame", default="000010")
    ap.add_argument("--cars", type=int, default=5, help="the first N labelled cars of the frame")
    ap.add_argument("--model", default=None, help="part model (default: the shipped one)")
    args = ap.parse_args()
    det = PartDetector.load(args.model)
    X = frame_descriptors(det, args.root, args.frame, args.cars)
    print(f"{args.frame}: {len(X):,} descriptors x {X.shape[1]} features, {det.n_trees} trees of depth {det.max_depth}")
    t_ref, ref = best_of(lambda: reference_proba(det, X))
    print(f"  reference (three tables, 16,384 rows)  {t_ref:.3f} s")
    for chunk in (16384, 4096, 1024, 256):
        t, p = best_of(lambda chunk=chunk: det.predict_proba(X, chunk=chunk))
        same = np.array_equal(p, ref)
        print(f"  records, {chunk:6,d} rows a chunk        {t:.3f} s  {t_ref / t:.2f}x  "
              f"{'same to the bit' if same else 'DIFFERENT'}")
        assert same


if __name__ == "__main__":
    main()
