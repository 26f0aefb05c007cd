"""Which learner should the detector's verifier be? A study on held-out candidates, plain script.

The verifier (:mod:`wirescene.predetect.verifier`) is an L2 logistic regression on the HOG
cells around each box. This script asks whether another learner on the same rows orders
the candidates of drives it never saw better. Two phases:

``--dump``: for each fold k, the rows the fold bank's verifier trains on
(:func:`wirescene.training.kitti_detector.verifier_training_rows`, its training frames and
their mirror images) and the candidates of its held-out frames before the cross-view
suppression (clustered, regressed and refined boxes, their margins, the ground prior's log
ratio, the verifier's features, the best IoU with a ``Car`` label), into ``CACHE/fold{k}.npz``.
Run one process per fold pair, as the bank training does. The features hold the colour
channels (:mod:`wirescene.predetect.channels`) unless ``--grey``.

Scoring (default): for every learner, each fold's verifier is fitted on its training rows,
its logits on the held-out candidates enter the score as the bank's do
(``a * margin + b + c * logit + ground``; ``a, b, c`` fitted on the other three folds'
candidates), the cross-view suppression (IoU 0.3) runs on that score, and the pooled
detections are scored by KITTI's rules (2D AP, devkit) and at the fit's threshold (0.3): the
detections, the share on a car, the cars found. A proxy of the full recipe (the calibration
is fitted on the candidates before the suppression, the viewpoint prior is left out), so its
baseline is printed beside the learners.

Usage:
  python benchmarks/bench_verifier.py --root ../shared/data/kitti --raw DIR --cache CACHE --dump --fold 0 --fold 2
  python benchmarks/bench_verifier.py --root ../shared/data/kitti --cache CACHE [--learner NAME ...]
DIR holds the fold banks ``fold{k}_raw.npz`` of ``bench_predetect.py --cv --fold`` (uncalibrated).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.core.boxes import iou_2d  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.core.viewpoints import bin_center, viewpoint_bin  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.bank import (  # noqa: E402
    DetectorBank,
    cluster_options,
    merge_activations,
    nms,
    regression_features,
    score_pyramid,
)
from wirescene.predetect.hog import pyramid_scales  # noqa: E402
from wirescene.predetect.verifier import VIEW_GROUPS, fit_verifier, verifier_features, verifier_logits  # noqa: E402
from wirescene.predetect.verifier import C as VERIFIER_C  # noqa: E402
from wirescene.training.kitti_detector import (  # noqa: E402
    detection_labels,
    fit_platt,
    kitti_gt_boxes,
    load_training_frames,
    verifier_training_rows,
)

N_GEOMETRY = 14  # regression_features' columns at the end of every row


def candidates(bank: DetectorBank, image, dataset, *, channels: bool) -> dict:
    """The candidates of one held-out image before the cross-view suppression (their
    verifier features with the colour channels where ``channels``)."""
    W, H = image.size
    pyramid = image.hog_pyramid(pyramid_scales(W, H, max_scale=float(bank.meta.get("max_scale", 2.0)),
                                               per_octave=int(bank.meta.get("per_octave", 4))))
    act = score_pyramid(bank, pyramid, threshold=-1.0, min_height=float(bank.meta.get("min_height", 30.0)),
                        max_height=3.0 * H)
    gray = image.gray.astype(np.float32) / 255.0
    plain = replace(bank, verifier=None)
    # merge_activations without suppression, threshold or ground term: the boxes the verifier sees
    det = merge_activations(act, plain, (W, H), threshold=None, cross_view_nms=None, cluster_kw=cluster_options(bank),
                            gray=gray)
    boxes = det.boxes
    bins = viewpoint_bin(det.alpha) if len(boxes) else np.zeros(0, int)
    cars = kitti_gt_boxes(dataset.labels(image.frame))
    best = iou_2d(boxes[:, None], cars[None]).max(1) if len(boxes) and len(cars) else np.zeros(len(boxes))
    return {"boxes": boxes, "margins": det.scores, "bins": bins, "best_iou": best,
            "ground": bank.ground_log_ratio(boxes, image.horizon),
            "features": verifier_features(gray, boxes, regression_features(boxes, bins, (W, H)),
                                          channels=image.channels if channels else None).astype(np.float16)}


def dump(args) -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    ds = KittiDataset(args.root)
    ids = ds.frame_ids()
    Path(args.cache).mkdir(parents=True, exist_ok=True)
    for k in sorted(set(args.fold or range(N_FOLDS))):
        t0 = time.time()
        bank = DetectorBank.load(Path(args.raw) / f"fold{k}_raw.npz")
        train, _ = load_training_frames(ds, [f for f in ids if fold_of(f) != k])
        X, y, _, _ = verifier_training_rows(bank, train, ds, channels=not args.grey)
        print(f"fold {k}: {len(y)} training rows ({int(y.sum())} cars) [{time.time() - t0:.0f}s]", flush=True)
        held, _ = load_training_frames(ds, [f for f in ids if fold_of(f) == k], flips=False)
        out = {"train_X": X.astype(np.float16), "train_y": y}
        for im in held:
            for key, v in candidates(bank, im, ds, channels=not args.grey).items():
                out[f"{im.frame}__{key}"] = v
        np.savez(Path(args.cache) / f"fold{k}.npz", **out)
        print(f"fold {k}: {len(held)} held-out frames [{time.time() - t0:.0f}s]", flush=True)


# ----------------------------------------------------------------------------- learners

def _logistic(C):
    def fit(X, y):
        v = fit_verifier(X, y, C=C)
        return lambda Z: verifier_logits(v, Z)
    return fit


def _groups(X) -> np.ndarray:
    """Viewpoint group (:data:`~wirescene.predetect.verifier.VIEW_GROUPS`) of every row, from its one-hot bin."""
    return VIEW_GROUPS[np.argmax(X[:, -N_GEOMETRY + 1:-N_GEOMETRY + 9], 1)]


def _per_group(C):
    """One logistic regression per viewpoint group (a mixture of linear verifiers, ``fit_verifier(groups=)``)."""
    def fit(X, y):
        v = fit_verifier(X, y, C=C, groups=_groups(X))
        return lambda Z: verifier_logits(v, Z, groups=_groups(Z))
    return fit


def _mlp(hidden, alpha):
    def fit(X, y):
        from sklearn.neural_network import MLPClassifier

        mean, sd = X.mean(0), X.std(0)
        sd[sd < 1e-9] = 1.0
        w = np.where(y > 0, 0.5 / y.mean(), 0.5 / (1 - y.mean()))
        rng = np.random.default_rng(0)
        idx = rng.choice(len(y), size=len(y), p=w / w.sum())  # balanced by resampling (MLP takes no weights)
        clf = MLPClassifier(hidden_layer_sizes=(hidden,), alpha=alpha, max_iter=200, early_stopping=True,
                            random_state=0).fit((X[idx] - mean) / sd, y[idx])

        def logits(Z):
            p = np.clip(clf.predict_proba((Z - mean) / sd)[:, 1], 1e-6, 1 - 1e-6)
            return np.log(p / (1 - p))
        return logits
    return fit


def _boosted(n_pcs, iters):
    def fit(X, y):
        from sklearn.decomposition import PCA
        from sklearn.ensemble import HistGradientBoostingClassifier

        mean, sd = X.mean(0), X.std(0)
        sd[sd < 1e-9] = 1.0
        hog = slice(0, X.shape[1] - N_GEOMETRY)
        pca = PCA(n_pcs, random_state=0).fit(((X - mean) / sd)[:, hog])

        def feats(Z):
            return np.column_stack([pca.transform(((Z - mean) / sd)[:, hog]), Z[:, -N_GEOMETRY + 1:]])
        clf = HistGradientBoostingClassifier(max_iter=iters, learning_rate=0.1, max_leaf_nodes=15,
                                             class_weight="balanced", random_state=0).fit(feats(X), y)

        def logits(Z):
            p = np.clip(clf.predict_proba(feats(Z))[:, 1], 1e-6, 1 - 1e-6)
            return np.log(p / (1 - p))
        return logits
    return fit


LEARNERS = {
    "logistic": _logistic(VERIFIER_C),  # the verifier of banks before December 2026
    "logistic-C3e-4": _logistic(3e-4),
    "logistic-C1e-2": _logistic(1e-2),
    "per-view-group": _per_group(VERIFIER_C),
    "mlp-64": _mlp(64, 1.0),
    "mlp-64-a10": _mlp(64, 10.0),
    "boosted-pca64": _boosted(64, 300),
}


def suppress(boxes, scores, *, iou: float, behind_iou: float | None, bottom_gap: float) -> np.ndarray:
    """Greedy suppression, indices kept best first: a box goes when a better one overlaps it
    by IoU > ``iou``, or, where their bottoms differ by more than ``bottom_gap`` of the taller
    box's height (one car behind the other), by IoU > ``behind_iou`` (None: ``iou``)."""
    if behind_iou is None:
        return nms(boxes, scores, iou)
    order = np.argsort(-np.asarray(scores), kind="stable")
    keep = []
    while len(order):
        i, rest = order[0], order[1:]
        keep.append(i)
        ov = iou_2d(boxes[i][None], boxes[rest])
        h = np.maximum(boxes[i, 3] - boxes[i, 1], boxes[rest, 3] - boxes[rest, 1])
        behind = np.abs(boxes[rest, 3] - boxes[i, 3]) > bottom_gap * h
        order = rest[ov <= np.where(behind, behind_iou, iou)]
    return np.array(keep, int)


def found_at_precision(dets, labels, precision: float) -> tuple[int, int]:
    """``(cars found, detections)`` of the longest prefix of the pooled detections, best
    first, of which at least ``precision`` lie on a car (first match at IoU 0.5, greedy per
    frame by score, as :func:`~wirescene.training.kitti_detector.detection_labels`)."""
    s = np.concatenate([d.scores for d in dets])
    y = np.concatenate([detection_labels(d.boxes, kitti_gt_boxes(lab)) for d, lab in zip(dets, labels)])
    order = np.argsort(-s, kind="stable")
    hits = np.cumsum(y[order])
    ok = np.flatnonzero(hits >= precision * np.arange(1, len(s) + 1))
    return (int(hits[ok[-1]]), int(ok[-1] + 1)) if len(ok) else (0, 0)


def score(args) -> None:
    from _common import operating_point
    from bench_predetect import fmt, fmt_operating_point, metrics  # benchmarks/ is on the path

    ds = KittiDataset(args.root)
    ids = ds.frame_ids()
    caches = {k: np.load(Path(args.cache) / f"fold{k}.npz") for k in range(N_FOLDS)}
    frames = {k: [f for f in ids if fold_of(f) == k] for k in range(N_FOLDS)}
    labels = {f: ds.labels(f) for f in ids}
    for name in args.learner or list(LEARNERS):
        t0 = time.time()
        rows = {}
        for k, z in caches.items():
            X, y = z["train_X"].astype(np.float32), z["train_y"]
            logits = LEARNERS[name](X, y)
            for f in frames[k]:
                rows[f] = {key: z[f"{f}__{key}"] for key in ("boxes", "margins", "bins", "best_iou", "ground")}
                F = z[f"{f}__features"].astype(np.float32)
                rows[f]["logit"] = logits(F) if len(F) else np.zeros(0)
        dets = {}
        for k in range(N_FOLDS):
            other = [f for f in ids if fold_of(f) != k]
            a, b, c = fit_platt(np.concatenate([rows[f]["margins"] for f in other]),
                                np.concatenate([rows[f]["best_iou"] >= 0.5 for f in other]),
                                offset=np.concatenate([rows[f]["ground"] for f in other]),
                                verifier=np.concatenate([rows[f]["logit"] for f in other]))
            for f in frames[k]:
                r = rows[f]
                s = a * r["margins"] + b + c * r["logit"] + r["ground"]
                keep = (suppress(r["boxes"], s, iou=args.nms, behind_iou=args.behind_nms, bottom_gap=args.bottom_gap)
                        if len(s) else np.zeros(0, int))  # best first
                dets[f] = Detections(r["boxes"][keep], 1 / (1 + np.exp(-s[keep])), bin_center(r["bins"][keep]),
                                     "bank")
        print(f"== {name} [{time.time() - t0:.0f}s]")
        for group in FOLD_GROUPS:
            fg = [f for f in ids if fold_of(f) in group]
            print(fmt(f"  folds {group}", metrics([dets[f] for f in fg], [labels[f] for f in fg])))
        print(fmt("  pooled", metrics([dets[f] for f in ids], [labels[f] for f in ids])))
        for group in FOLD_GROUPS + ((0, 1, 2, 3),):
            fg = [f for f in ids if fold_of(f) in group]
            n_cars = sum(len(kitti_gt_boxes(labels[f])) for f in fg)
            found = [found_at_precision([dets[f] for f in fg], [labels[f] for f in fg], p) for p in args.precision]
            print(f"    cars found of {n_cars} in folds {group} at precision "
                  + ", ".join(f"{p:g}: {c} ({n} dets)" for p, (c, n) in zip(args.precision, found)))
        if args.operating_point:
            print("   ", fmt_operating_point(operating_point([dets[f] for f in ids], [labels[f] for f in ids], 0.3)),
                  flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames (e.g. ../shared/data/kitti)")
    ap.add_argument("--cache", required=True, help="folder of the dumped rows (fold{k}.npz)")
    ap.add_argument("--raw", help="--dump: folder of the uncalibrated fold banks fold{k}_raw.npz")
    ap.add_argument("--dump", action="store_true", help="write the rows of --fold (default all) to --cache")
    ap.add_argument("--fold", type=int, action="append", default=None)
    ap.add_argument("--grey", action="store_true",
                    help="--dump: the verifier's features without the colour channels (HOG cells and geometry, as "
                         "the verifiers of banks before December 2026)")
    ap.add_argument("--nms", type=float, default=0.3, help="cross-view suppression IoU")
    ap.add_argument("--behind-nms", type=float, default=None,
                    help="suppression IoU between boxes whose bottoms differ by more than --bottom-gap of the "
                         "height (one car behind another; default: --nms)")
    ap.add_argument("--bottom-gap", type=float, default=0.1)
    ap.add_argument("--precision", type=float, nargs="+", default=[0.8, 0.7, 0.5],
                    help="report the cars found by the best-scoring detections of which this share is on a car")
    ap.add_argument("--operating-point", action="store_true",
                    help="also the operating point at 0.3 (of the proxy's calibration, fitted before the suppression)")
    ap.add_argument("--learner", action="append", choices=list(LEARNERS), help="score these (default all)")
    args = ap.parse_args()
    if args.dump:
        if not args.raw:
            ap.error("--dump needs --raw")
        return dump(args)
    return score(args)


if __name__ == "__main__":
    main()
