"""The crop viewpoint classifier held out by drive: its training copies and regularisation,
and how well the crop tells a car's front from its back (issue 27; ``benchmarks/RESULTS.md``,
"The crop classifier's training copies and its front or back").

Each fold's classifier is trained on the other folds' frames (:mod:`wirescene.io.folds`) and
scores the held-out label boxes and copies of them moved by 5% of their size
(``_common.jittered``, seed 0), by the classifier alone: the share within 45 deg and the
front/back swaps (> 135 deg), per fold group.

* ``--study copies``: the shipped recipe (one jittered copy a box and its mirror image, C =
  0.01) against three jittered copies, a brightness / contrast copy of each box, C x 0.3 and
  x 3;
* ``--study front-back``: cars not seen from the side (|sin alpha| > 0.5), front against back,
  by logistic regressions (all features, the colour cells alone), gradient-boosted trees and
  an RBF SVM on the classifier's features.

    python benchmarks/bench_viewpoint_classifier.py --root KITTI_ROOT [--study copies front-back]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import wirescene.predetect.viewpoint_classifier as vc  # noqa: E402
from _common import jitter_rng, jittered  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.viewpoints import angle_difference, bin_center  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402

#: ``{name: (training options, C)}`` of ``--study copies``.
COPIES = {"shipped recipe": ({}, vc.C), "three jittered copies": ({"copies": 3}, vc.C),
          "a brightness / contrast copy": ({"photometric": True}, vc.C), "C = 0.003": ({}, 0.003),
          "C = 0.03": ({}, 0.03)}


def held_out_boxes(ds, frames):
    """Per frame ``(label-box features, jittered-box features, alpha)`` of its cars."""
    out = []
    for f in frames:
        cars = ds.labels(f).of_type("Car")
        if not cars:
            continue
        image = ds.image(f)
        boxes = np.array([o.box for o in cars], float)
        moved = jittered(boxes, (image.shape[1], image.shape[0]), jitter_rng(0, f))
        out.append((vc.crop_viewpoint_features(image, boxes), vc.crop_viewpoint_features(image, moved),
                    np.array([o.alpha for o in cars])))
    return out


def study_copies(ds, frames, tests) -> None:
    for name, (options, C) in COPIES.items():
        t0 = time.time()
        errors: dict = {}
        for k in range(N_FOLDS):
            x, y = vc.kitti_examples(ds, [f for f in frames if fold_of(f) != k], **options)
            model = vc.fit_viewpoint_classifier(x, y, C=C)
            for which in (0, 1):
                for boxes in tests[k]:
                    pick = bin_center(model.log_probs_of_features(boxes[which]).argmax(1))
                    errors.setdefault((k, which), []).append(np.degrees(np.abs(angle_difference(pick, boxes[2]))))
        cells = []
        for g in FOLD_GROUPS:
            for which, kind in ((0, "label"), (1, "jittered")):
                d = np.concatenate([np.concatenate(errors[(k, which)]) for k in g])
                cells.append(f"{g} {kind} {np.mean(d <= 45):.1%} within 45 deg / {np.mean(d > 135):.1%} swapped "
                             f"({len(d)} cars)")
        print(f"{name} [{time.time() - t0:.0f} s]: " + "; ".join(cells), flush=True)


def study_front_back(ds, frames, tests) -> None:
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.linear_model import LogisticRegression
    from sklearn.svm import SVC

    n_hog = vc.HOG_GRID[0] * vc.HOG_GRID[1] * 31
    learners = {
        "logistic regression": (lambda: LogisticRegression(C=0.01, max_iter=5000), slice(None)),
        "logistic regression, colour cells": (lambda: LogisticRegression(C=1.0, max_iter=5000), slice(n_hog, None)),
        "boosted trees": (lambda: HistGradientBoostingClassifier(max_iter=200, learning_rate=0.05, max_depth=3,
                                                                 random_state=0), slice(None)),
        "RBF SVM": (lambda: SVC(C=1.0, gamma="scale"), slice(None)),
    }
    train = {k: vc.kitti_examples(ds, [f for f in frames if fold_of(f) != k]) for k in range(N_FOLDS)}
    for g in FOLD_GROUPS:
        alpha = np.concatenate([b[2] for k in g for b in tests[k]])
        seen = np.abs(np.sin(alpha)) > 0.5
        print(f"{g}: {seen.sum()} cars not seen from the side, {np.mean(np.sin(alpha[seen]) < 0):.1%} from behind")
    for name, (make, cols) in learners.items():
        right: dict = {}
        for k in range(N_FOLDS):
            x, y = train[k]
            front = np.sin(bin_center(y))
            keep = np.abs(front) > 0.5
            mean, scale = x.mean(0), x.std(0) + 1e-6
            model = make().fit(((x - mean) / scale)[keep][:, cols], front[keep] > 0)
            for boxes in tests[k]:
                s = np.sin(boxes[2])
                side = np.abs(s) > 0.5
                if side.any():
                    guess = model.predict(((boxes[0] - mean) / scale)[side][:, cols])
                    right.setdefault(k, []).append(guess == (s[side] > 0))
        cells = [f"{g} {np.concatenate([np.concatenate(right[k]) for k in g]).mean():.1%}" for g in FOLD_GROUPS]
        print(f"front or back, {name}: " + ", ".join(cells) + " of the label boxes", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames (e.g. ../shared/data/kitti)")
    ap.add_argument("--study", nargs="+", choices=("copies", "front-back"), default=["copies", "front-back"])
    args = ap.parse_args()
    ds = KittiDataset(args.root)
    frames = list(ds.frame_ids())
    tests = {k: held_out_boxes(ds, [f for f in frames if fold_of(f) == k]) for k in range(N_FOLDS)}
    if "copies" in args.study:
        study_copies(ds, frames, tests)
    if "front-back" in args.study:
        study_front_back(ds, frames, tests)


if __name__ == "__main__":
    main()
