"""Does rescoring detections by their context help on drives it never saw?

The bank scores each cluster of votes alone; most of its false detections overlap a car
badly (across two parked cars, on part of one, beside a better box). The rescorer here
is a small gradient-boosted tree ensemble (scikit-learn) on per-detection context
(:data:`FEATURES`: calibrated score, size, height against the horizon, border contact,
viewpoint, and how much higher-scoring detections overlap, contain or trail it), fitted
to "first detection to find a car at IoU >= 0.5".

Reads held-out detections of every frame (``bench_predetect.py --from-raw ... --save-dets
D.npz``: each frame detected by the fold bank that never saw its drive, calibrated
confidences with the ground prior), fits the rescorer on the frames of one fold group and
scores the other group's, both ways, and reports the devkit's 2D AP (easy / moderate /
hard, IoU 0.7 and 0.5) and the operating point at a threshold, before and after, per
group and pooled over the two held-out halves.

    python benchmarks/bench_rescore.py --root KITTI --dets D.npz [--json OUT.json] [--set n_trees=300 ...]

With ``--fold-banks DIR`` (the ``fold{k}.npz`` of the same run) and ``--extra-refinements N``
it measures instead what applying each frame's fold bank's box refinement N more times to
its detections does (a cascade of the one regression).

With ``--appearance grey|colour`` it measures instead what a look at each box's pixels adds
(the study behind :mod:`wirescene.predetect.verifier`'s settings): a logistic regression
(``--C``) on the appearance of each detection's box -- ``grey``: the verifier's features (HOG
cells of the box grown by 25%, its geometry); ``colour``: the crop viewpoint classifier's
(HOG, colour cells, aspect) -- fitted on the detections and label boxes of one fold group,
stacked with the calibrated score by a two-feature logistic regression fitted on
appearance logits cross-fitted between the group's two folds, and scored on the other group.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import read_saved_detections  # (benchmarks/ is on the path of a script run from it)
from wirescene.core.boxes import iou_2d
from wirescene.core.errors import check_shape
from wirescene.core.jsonio import write_json
from wirescene.core.types import Detections
from wirescene.eval.kitti_metrics import detection_ap_2d
from wirescene.io.folds import FOLD_GROUPS, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.predetect.geometry import horizon_row
from wirescene.training.kitti_detector import detection_labels, kitti_gt_boxes

#: Names of the columns of :func:`rescoring_features`.
FEATURES: tuple[str, ...] = (
    "logit", "log_height", "log_aspect", "bottom_ratio", "lateral", "cos_alpha", "sin_alpha",
    "touches_side", "touches_bottom", "rank", "best_iou_above", "logit_gap", "inside_above", "covers_above",
    "n_above", "best_iou_below",
)

_EPS = 1e-6


def rescoring_features(boxes, scores, alpha, image_size, *, horizon: float, center_column: float) -> np.ndarray:
    """``(D, len(FEATURES))`` context features of one frame's detections.

    Parameters
    ----------
    boxes : (D, 4) array
        Boxes ``x1 y1 x2 y2`` in pixels.
    scores : (D,) array
        Calibrated confidences in (0, 1) (the bank's, ground prior included).
    alpha : (D,) array
        Observation angles (NaN: unknown).
    image_size : (W, H)
    horizon, center_column : float
        Row of the horizon and column of the principal point.

    """
    b, s, a = (np.asarray(v, float) for v in (boxes, scores, alpha))
    D = len(b)
    check_shape("boxes", b, (None, 4))
    check_shape("scores", s, (D,))
    check_shape("alpha", a, (D,))
    W, H = (float(v) for v in image_size)
    w, h = np.maximum(b[:, 2] - b[:, 0], 1.0), np.maximum(b[:, 3] - b[:, 1], 1.0)
    z = np.log(np.clip(s, _EPS, 1 - _EPS) / np.clip(1 - s, _EPS, 1))
    order = np.argsort(-s, kind="stable")
    rank = np.empty(D)
    rank[order] = np.arange(D)
    above = rank[None, :] < rank[:, None]  # [i, j]: j scores above i
    ov = iou_2d(b[:, None], b[None]) if D else np.zeros((0, 0))
    ix = np.clip(np.minimum(b[:, None, 2], b[None, :, 2]) - np.maximum(b[:, None, 0], b[None, :, 0]), 0, None)
    iy = np.clip(np.minimum(b[:, None, 3], b[None, :, 3]) - np.maximum(b[:, None, 1], b[None, :, 1]), 0, None)
    inter = ix * iy
    area = w * h
    inside = inter / area[:, None]  # [i, j]: share of i inside j
    covers = inter / area[None, :]  # [i, j]: share of j inside i
    best_above = np.where(above, ov, 0.0)
    j = np.argmax(best_above, axis=1) if D else np.zeros(0, int)
    has = best_above.max(1, initial=0.0) > 0
    known = np.isfinite(a)
    return np.column_stack([
        z, np.log(h / H), np.log(w / h), (b[:, 3] - horizon) / h, (0.5 * (b[:, 0] + b[:, 2]) - center_column) / h,
        np.where(known, np.cos(a), 0.0), np.where(known, np.sin(a), 0.0),
        ((b[:, 0] <= 1) | (b[:, 2] >= W - 2)).astype(float), (b[:, 3] >= H - 2).astype(float),
        np.log1p(rank), best_above.max(1, initial=0.0), np.where(has, z[j] - z, 0.0) if D else np.zeros(0),
        np.where(above, inside, 0.0).max(1, initial=0.0), np.where(above, covers, 0.0).max(1, initial=0.0),
        (above & (ov > 0.1)).sum(1).astype(float), np.where(above.T, ov, 0.0).max(1, initial=0.0),
    ]).reshape(D, len(FEATURES))


def fit_rescorer(X, y, *, n_trees: int = 150, depth: int = 3, rate: float = 0.05, min_leaf: int = 20, seed: int = 0):
    """Gradient-boosted trees on the log loss (row subsampling 0.8)."""
    from sklearn.ensemble import GradientBoostingClassifier

    return GradientBoostingClassifier(n_estimators=n_trees, max_depth=depth, learning_rate=rate,
                                      min_samples_leaf=min_leaf, subsample=0.8, random_state=seed).fit(X, y)


def load_dets(path: Path) -> dict[str, Detections]:
    """``{frame: Detections}`` of a ``--save-dets`` file, each sorted by descending score."""
    out = {}
    for f, d in read_saved_detections(path).items():
        order = np.argsort(-d.scores, kind="stable")
        out[f] = Detections(d.boxes[order], d.scores[order], d.alpha[order])
    return out


def frame_features(ds, frame: str, d: Detections) -> np.ndarray:
    camera = ds.camera(frame)
    W, H = ds.image_size(frame) if hasattr(ds, "image_size") else camera.image_size
    return rescoring_features(d.boxes, d.scores, d.alpha, (W, H), horizon=horizon_row(camera),
                              center_column=float(camera.K[0, 2]))


def operating_point(dets, labels, threshold: float) -> dict:
    """Detections kept at ``threshold``, the share on a car (IoU >= 0.5) and the share of cars found."""
    kept = hits = cars = 0
    for d, lab in zip(dets, labels):
        gt = kitti_gt_boxes(lab)
        keep = d.scores >= threshold
        kept += int(keep.sum())
        hits += int(detection_labels(d.boxes[keep], gt).sum())  # one hit per car: duplicates count as false
        cars += len(gt)
    return {"threshold": threshold, "detections": kept, "precision": 100 * hits / max(kept, 1),
            "recall": 100 * hits / max(cars, 1), "cars": cars}


def refined_again(ds, dets: dict, banks: dict, times: int) -> dict:
    """``dets`` with each frame's fold bank's box refinement applied ``times`` more times."""
    from wirescene.core.boxes import clip_boxes
    from wirescene.core.viewpoints import viewpoint_bin
    from wirescene.predetect.bank import regression_features
    from wirescene.predetect.hog import to_gray
    from wirescene.predetect.refine import apply_box_refinement

    out = {}
    for f, d in dets.items():
        image = ds.image(f)
        H, W = image.shape[:2]
        gray, boxes, bins = to_gray(image), d.boxes, viewpoint_bin(d.alpha)
        for _ in range(times):
            boxes = clip_boxes(apply_box_refinement(banks[fold_of(f)].refinement, gray, boxes,
                                                    regression_features(boxes, bins, (W, H))), W, H)
        out[f] = Detections(boxes, d.scores, d.alpha)
    return out


def candidate_ceiling(dets: dict, labels: dict) -> dict:
    """Share of the cars (all, by box height, by KITTI occlusion flag) that any candidate
    of the frame overlaps at IoU >= 0.5 and >= 0.7: what no rescoring can exceed."""
    from wirescene.core.boxes import iou_2d

    rows = []
    for f, d in dets.items():
        cars = labels[f].of_type("Car")
        if cars and len(d.boxes):
            best = iou_2d(np.array([o.box for o in cars])[:, None], d.boxes[None]).max(1)
        else:
            best = np.zeros(len(cars))
        rows += [(b, o.box[3] - o.box[1], o.occluded) for o, b in zip(cars, best)]
    r = np.array(rows, float).reshape(-1, 3)
    groups = {"all": np.ones(len(r), bool), "< 25 px": r[:, 1] < 25, "25-40 px": (r[:, 1] >= 25) & (r[:, 1] < 40),
              "40-60 px": (r[:, 1] >= 40) & (r[:, 1] < 60), "> 60 px": r[:, 1] >= 60, "occluded 0": r[:, 2] == 0,
              "occluded 1": r[:, 2] == 1, "occluded 2-3": r[:, 2] >= 2}
    return {k: {"cars": int(m.sum()), "iou_0.5": 100 * float(np.mean(r[m, 0] >= 0.5)),
                "iou_0.7": 100 * float(np.mean(r[m, 0] >= 0.7))} for k, m in groups.items() if m.any()}


def ap_summary(dets, labels) -> dict:
    r = detection_ap_2d(dets, labels)
    return {"2d": r["2d"], "2d_iou_0.5": r["2d_iou_0.5"], "aos": r["aos"], "n_gt": r["n_gt"]}


def fmt(name: str, m: dict, op: dict) -> str:
    d = ("easy", "moderate", "hard")
    ap = " / ".join(f"{m['2d'][k]:.1f}" for k in d)
    ap5 = " / ".join(f"{m['2d_iou_0.5'][k]:.1f}" for k in d)
    return (f"{name}: 2D AP {ap} (IoU 0.5: {ap5}; {' / '.join(str(m['n_gt'][k]) for k in d)} cars); "
            f"at {op['threshold']}: {op['detections']} dets, {op['precision']:.0f}% on a car, "
            f"{op['recall']:.0f}% of {op['cars']} cars found")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, required=True, help="KITTI root of the frames of --dets (labels, calib)")
    ap.add_argument("--dets", type=Path, required=True, help="held-out detections (bench_predetect --save-dets)")
    ap.add_argument("--threshold", type=float, default=0.1)
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                    help="an option of fit_rescorer (n_trees, depth, rate, min_leaf)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--fold-banks", type=Path, default=None, help="DIR of the run's fold{k}.npz (with --extra-refinements)")
    ap.add_argument("--extra-refinements", type=int, default=0)
    ap.add_argument("--appearance", choices=("grey", "colour"), default=None)
    ap.add_argument("--C", type=float, nargs="+", default=[1e-3], help="with --appearance: the inverse regularisations")
    args = ap.parse_args()
    if args.appearance:
        return appearance(args)
    if args.extra_refinements:
        if args.fold_banks is None:
            ap.error("--extra-refinements needs --fold-banks")
        return cascade(args)
    fit_kw = {k: (float(v) if k == "rate" else int(v)) for k, _, v in (s.partition("=") for s in args.settings)}
    ds = KittiDataset(args.root)
    dets = load_dets(args.dets)
    frames = [f for f in ds.frame_ids() if f in dets]
    labels = {f: ds.labels(f) for f in frames}
    X = {f: frame_features(ds, f, dets[f]) for f in frames}
    y = {f: detection_labels(dets[f].boxes, kitti_gt_boxes(labels[f])) for f in frames}
    out = {"options": fit_kw, "groups": {}, "candidate_ceiling": candidate_ceiling(dets, labels)}
    print("cars any candidate overlaps (IoU >= 0.5 / >= 0.7): " + "; ".join(
        f"{k} {v['iou_0.5']:.0f}% / {v['iou_0.7']:.0f}% of {v['cars']}" for k, v in out["candidate_ceiling"].items()))
    rescored = {}
    for train_group, test_group in (FOLD_GROUPS, FOLD_GROUPS[::-1]):
        train = [f for f in frames if fold_of(f) in train_group]
        test = [f for f in frames if fold_of(f) in test_group]
        model = fit_rescorer(np.concatenate([X[f] for f in train]), np.concatenate([y[f] for f in train]), **fit_kw)
        for f in test:
            rescored[f] = Detections(dets[f].boxes, model.predict_proba(X[f])[:, 1], dets[f].alpha)
        before = [dets[f] for f in test], [labels[f] for f in test]
        after = [rescored[f] for f in test], before[1]
        key = f"{test_group} (fitted on {train_group})"
        out["groups"][key] = {"before": ap_summary(*before), "after": ap_summary(*after),
                              "op_before": operating_point(*before, args.threshold),
                              "op_after": operating_point(*after, args.threshold)}
        g = out["groups"][key]
        print(fmt(f"group {test_group} before", g["before"], g["op_before"]))
        print(fmt(f"group {test_group} after ", g["after"], g["op_after"]))
    everything = [labels[f] for f in frames]
    out["pooled"] = {"before": ap_summary([dets[f] for f in frames], everything),
                     "after": ap_summary([rescored[f] for f in frames], everything),
                     "op_before": operating_point([dets[f] for f in frames], everything, args.threshold),
                     "op_after": operating_point([rescored[f] for f in frames], everything, args.threshold)}
    p = out["pooled"]
    print(fmt(f"POOLED before ({len(frames)} frames)", p["before"], p["op_before"]))
    print(fmt(f"POOLED after  ({len(frames)} frames)", p["after"], p["op_after"]))
    if args.json:
        write_json(args.json, out)


def appearance_features(image: np.ndarray, boxes: np.ndarray, alpha: np.ndarray, kind: str) -> np.ndarray:
    """``(D, F)`` appearance features of ``boxes`` in an ``(H, W, 3)`` image (see the module's ``--appearance``)."""
    from wirescene.core.viewpoints import viewpoint_bin
    from wirescene.predetect.bank import regression_features
    from wirescene.predetect.hog import to_gray
    from wirescene.predetect.verifier import verifier_features
    from wirescene.predetect.viewpoint_classifier import crop_viewpoint_features

    if kind == "colour":
        return crop_viewpoint_features(image, boxes)
    gray = to_gray(image)
    bins = viewpoint_bin(np.where(np.isfinite(alpha), alpha, 0.0))
    return verifier_features(gray, boxes, regression_features(boxes, bins, gray.shape[::-1]))


def appearance(args) -> None:
    """The ``--appearance`` study: 2D AP per fold group and pooled, before and after stacking."""
    from sklearn.linear_model import LogisticRegression

    from wirescene.core.boxes import iou_2d
    from wirescene.predetect.verifier import fit_verifier, verifier_logits

    ds = KittiDataset(args.root)
    dets = load_dets(args.dets)
    frames = [f for f in ds.frame_ids() if f in dets]
    labels = {f: ds.labels(f) for f in frames}
    X, Xcar, on_car, first = {}, {}, {}, {}
    for f in frames:
        image, d, gt = ds.image(f), dets[f], kitti_gt_boxes(labels[f])
        X[f] = appearance_features(image, d.boxes, d.alpha, args.appearance)
        Xcar[f] = appearance_features(image, gt, np.full(len(gt), np.nan), args.appearance)
        on_car[f] = (iou_2d(d.boxes[:, None], gt[None]).max(1) >= 0.5).astype(int) if len(gt) and len(d.boxes) \
            else np.zeros(len(d.boxes), int)
        first[f] = detection_labels(d.boxes, gt)

    def fit(fr, C):
        v = fit_verifier(np.concatenate([X[f] for f in fr] + [Xcar[f] for f in fr]),
                         np.concatenate([on_car[f] for f in fr] + [np.ones(len(Xcar[f]), int) for f in fr]), C=C)
        return lambda f: verifier_logits(v, X[f])

    def logit(f):
        return np.log(np.clip(dets[f].scores, 1e-6, 1 - 1e-6) / np.clip(1 - dets[f].scores, 1e-6, 1))

    for C in args.C:
        rescored = {}
        for train_group, test_group in (FOLD_GROUPS, FOLD_GROUPS[::-1]):
            train = [f for f in frames if fold_of(f) in train_group]
            crossed = {}
            for k in train_group:  # appearance logits of each training fold from a model of the group's other fold
                model = fit([f for f in train if fold_of(f) != k], C)
                crossed.update({f: model(f) for f in train if fold_of(f) == k})
            stack = LogisticRegression(max_iter=2000).fit(
                np.concatenate([np.column_stack([logit(f), crossed[f]]) for f in train]),
                np.concatenate([first[f] for f in train]))
            model = fit(train, C)
            for f in (f for f in frames if fold_of(f) in test_group):
                rescored[f] = Detections(dets[f].boxes, stack.predict_proba(np.column_stack([logit(f), model(f)]))[:, 1],
                                         dets[f].alpha)
        for name, group in [*((str(g), [f for f in frames if fold_of(f) in g]) for g in FOLD_GROUPS), ("pooled", frames)]:
            for label, d in (("before", dets), (f"{args.appearance} C={C:g}", rescored)):
                m = ap_summary([d[f] for f in group], [labels[f] for f in group])
                print(f"{name} {label}: 2D AP " + " / ".join(f"{m['2d'][k]:.1f}" for k in ("easy", "moderate", "hard"))
                      + f" (IoU 0.5 moderate {m['2d_iou_0.5']['moderate']:.1f})")


def cascade(args) -> None:
    """The ``--extra-refinements`` study: 2D AP per fold group and pooled, before and after."""
    from wirescene.predetect.bank import DetectorBank

    ds = KittiDataset(args.root)
    dets = load_dets(args.dets)
    frames = [f for f in ds.frame_ids() if f in dets]
    banks = {k: DetectorBank.load(args.fold_banks / f"fold{k}.npz") for k in sorted({fold_of(f) for f in frames})}
    labels = {f: ds.labels(f) for f in frames}
    moved = refined_again(ds, {f: dets[f] for f in frames}, banks, args.extra_refinements)
    for name, group in [*((str(g), [f for f in frames if fold_of(f) in g]) for g in FOLD_GROUPS), ("pooled", frames)]:
        for label, d in (("before", dets), (f"+{args.extra_refinements} refinements", moved)):
            m = ap_summary([d[f] for f in group], [labels[f] for f in group])
            print(f"{name} {label}: 2D AP " + " / ".join(f"{m['2d'][k]:.1f}" for k in ("easy", "moderate", "hard")))


if __name__ == "__main__":
    main()
