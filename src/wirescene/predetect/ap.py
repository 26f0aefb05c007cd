"""2D car detection average precision with the paper's pre-detection protocol (Sec. 5.2).

PASCAL VOC AP (all-point interpolation) at IoU >= 0.5 over cars more than ``min_height``
(50) px high and at least ``min_visible`` (20%) visible. As in the KITTI devkit, the other
ground truth is "ignore": cars too small or too occluded, vans (the neighbouring class),
and DontCare regions; a detection matching an ignored object (IoU >= 0.5), lying at least
half inside a DontCare region, or itself lower than ``min_height`` is neither a true nor a
false positive.

Visibility: KITTI labels only carry coarse occlusion levels, so ">= 20% visible" is
approximated by ``occluded <= 2 and truncated <= 0.8`` (occluded 3 = unknown is
ignored). Synthetic scenes (``wireframes/FRAME.json`` present) give it exactly:
``(1 - occluded_fraction) * (1 - truncated) >= 0.2``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wirescene.core.boxes import iou_2d
from wirescene.core.viewpoints import angle_difference, viewpoint_bin

NEIGHBOUR_TYPES = ("Van",)


@dataclass
class FrameGT:
    boxes: np.ndarray  # (K, 4) cars that count
    alpha: np.ndarray  # (K,)
    ignore: np.ndarray  # (M, 4) objects whose matches are ignored
    dontcare: np.ndarray  # (N, 4)


def _arr(boxes) -> np.ndarray:
    return np.asarray(boxes, float).reshape(-1, 4)


def frame_gt(labels, *, wireframes: dict | None = None, min_height: float = 50.0,
             min_visible: float = 0.2) -> FrameGT:
    """Split a frame's labels into counted cars, ignored objects and DontCare regions.

    ``wireframes``: the synthetic scene's ``wireframes/FRAME.json`` content (cars aligned
    with ``labels.objects``) for the exact visible fraction; else the KITTI rule."""
    keep, alpha, ignore = [], [], []
    cars = wireframes.get("cars") if wireframes else None
    for k, o in enumerate(labels.objects):
        if o.type == "Car":
            if cars is not None and k < len(cars):
                vis = (1.0 - float(cars[k]["occluded_fraction"])) * (1.0 - float(cars[k]["truncated"]))
                visible_ok = vis >= min_visible
            else:
                visible_ok = o.occluded <= 2 and o.truncated <= 0.8
            if visible_ok and o.height_px > min_height:
                keep.append(o.box)
                alpha.append(o.alpha)
            else:
                ignore.append(o.box)
        elif o.type in NEIGHBOUR_TYPES:
            ignore.append(o.box)
    return FrameGT(_arr(keep), np.asarray(alpha, float), _arr(ignore), _arr([d.box for d in labels.dontcare]))


def _inside_fraction(det: np.ndarray, regions: np.ndarray) -> np.ndarray:
    iw = np.clip(np.minimum(det[2], regions[:, 2]) - np.maximum(det[0], regions[:, 0]), 0, None)
    ih = np.clip(np.minimum(det[3], regions[:, 3]) - np.maximum(det[1], regions[:, 1]), 0, None)
    area = max((det[2] - det[0]) * (det[3] - det[1]), 1e-9)
    return iw * ih / area


def match_frame(boxes, scores, alpha, gt: FrameGT, *, iou: float = 0.5, min_height: float = 50.0):
    """Label one frame's detections: returns ``(status (D,), gt_index (D,))`` with status
    1 = true positive, 0 = false positive, -1 = ignored; detections in descending score."""
    boxes, scores = _arr(boxes), np.asarray(scores, float)
    order = np.argsort(-scores, kind="stable")
    status = np.full(len(boxes), -1, int)
    gidx = np.full(len(boxes), -1, int)
    used = np.zeros(len(gt.boxes), bool)
    for d in order:
        b = boxes[d]
        if len(gt.boxes):
            ov = iou_2d(b[None], gt.boxes)
            ov[used] = -1
            j = int(np.argmax(ov))
            if ov[j] >= iou:
                used[j] = True
                status[d], gidx[d] = 1, j
                continue
        if len(gt.ignore) and np.any(iou_2d(b[None], gt.ignore) >= iou):
            continue
        if b[3] - b[1] < min_height:
            continue
        if len(gt.dontcare) and np.any(_inside_fraction(b, gt.dontcare) >= 0.5):
            continue
        status[d] = 0
    return status, gidx


def average_precision(recall: np.ndarray, precision: np.ndarray) -> float:
    """PASCAL VOC (2010+) all-point interpolated AP."""
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[0.0], precision, [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    i = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[i + 1] - mrec[i]) * mpre[i + 1]))


def evaluate_detections(detections, gts, *, iou: float = 0.5, min_height: float = 50.0) -> dict:
    """AP, PR curve and viewpoint accuracy over frames.

    ``detections``: per frame a :class:`~wirescene.core.types.Detections` (or any
    object with ``boxes``, ``scores``, ``alpha``); ``gts``: per frame a :class:`FrameGT`."""
    all_s, all_t, vp_err = [], [], []
    n_gt = 0
    for det, gt in zip(detections, gts):
        n_gt += len(gt.boxes)
        status, gidx = match_frame(det.boxes, det.scores, det.alpha, gt, iou=iou, min_height=min_height)
        sel = status >= 0
        all_s.append(np.asarray(det.scores, float)[sel])
        all_t.append(status[sel])
        for d in np.flatnonzero(status == 1):
            vp_err.append((float(det.alpha[d]), float(gt.alpha[gidx[d]])))
    s = np.concatenate(all_s) if all_s else np.zeros(0)
    t = np.concatenate(all_t) if all_t else np.zeros(0, int)
    order = np.argsort(-s, kind="stable")
    tp = np.cumsum(t[order] == 1)
    fp = np.cumsum(t[order] == 0)
    recall = tp / max(n_gt, 1)
    precision = tp / np.maximum(tp + fp, 1)
    ap = average_precision(recall, precision) if n_gt else float("nan")
    res = {"ap": ap, "n_gt": int(n_gt), "n_det": int(len(s)), "n_tp": int(tp[-1]) if len(tp) else 0,
           "max_recall": float(recall[-1]) if len(recall) else 0.0,
           "recall": recall, "precision": precision, "scores": s[order]}
    if vp_err:
        a = np.array(vp_err)
        ok = np.isfinite(a[:, 0])
        res["viewpoint_bin_acc"] = float(np.mean(viewpoint_bin(a[ok, 0]) == viewpoint_bin(a[ok, 1]))) if ok.any() else float("nan")
        res["viewpoint_within_45"] = float(np.mean(angle_difference(a[ok, 0], a[ok, 1]) <= np.deg2rad(45) + 1e-9)) if ok.any() else float("nan")
    else:
        res["viewpoint_bin_acc"] = res["viewpoint_within_45"] = float("nan")
    return res


def summary(res: dict) -> dict:
    """JSON-friendly subset of :func:`evaluate_detections`'s result."""
    return {k: v for k, v in res.items() if not isinstance(v, np.ndarray)}


def plot_pr(results: dict, path, *, title: str = "Car pre-detection") -> Path:
    """Precision-recall curves ``{name: result}`` to a PNG (matplotlib Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4.5))
    for name, r in results.items():
        ax.plot(r["recall"], r["precision"], label=f"{name} (AP {100 * r['ap']:.1f}%)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def load_frame_gt(split_dir, frame_id: str, **kw) -> FrameGT:
    """GT of one frame of a KITTI-layout split (uses ``wireframes/`` when present)."""
    from wirescene.io.kitti import read_labels

    split_dir = Path(split_dir)
    labels = read_labels(split_dir / "label_2" / f"{frame_id}.txt")
    wpath = split_dir / "wireframes" / f"{frame_id}.json"
    wire = json.loads(wpath.read_text()) if wpath.is_file() else None
    return frame_gt(labels, wireframes=wire, **kw)


# --------------------------------------------------------------------------- KITTI 2D AP (devkit rules)

#: KITTI difficulty definitions (devkit ``evaluate_object.cpp``): minimum box height (px),
#: maximum occlusion level, maximum truncation.
KITTI_DIFFICULTIES = {"easy": (40.0, 0, 0.15), "moderate": (25.0, 1, 0.30), "hard": (25.0, 2, 0.50)}
N_SAMPLE_PTS = 41


@dataclass
class KittiFrameGT:
    """A frame's ground truth as the KITTI devkit sees it for class Car."""

    boxes: np.ndarray  # (K, 4) Car and Van boxes
    is_car: np.ndarray  # (K,) True: Car, False: Van (the neighbouring class, always ignored)
    occluded: np.ndarray  # (K,)
    truncated: np.ndarray  # (K,)
    alpha: np.ndarray  # (K,)
    dontcare: np.ndarray  # (N, 4)


def kitti_frame_gt(labels) -> KittiFrameGT:
    """:class:`KittiFrameGT` of a :class:`~wirescene.io.kitti.FrameLabels`."""
    objs = [o for o in labels.objects if o.type in ("Car",) + NEIGHBOUR_TYPES]
    return KittiFrameGT(_arr([o.box for o in objs]), np.array([o.type == "Car" for o in objs], bool),
                        np.array([o.occluded for o in objs], int), np.array([o.truncated for o in objs], float),
                        np.array([o.alpha for o in objs], float), _arr([d.box for d in labels.dontcare]))


def _gt_flags(gt: KittiFrameGT, difficulty: str) -> np.ndarray:
    """Devkit ``ignored_gt``: 0 counted, 1 ignored (Van, or Car outside the difficulty)."""
    min_h, max_occ, max_trunc = KITTI_DIFFICULTIES[difficulty]
    h = gt.boxes[:, 3] - gt.boxes[:, 1]
    hard = (gt.occluded > max_occ) | (gt.truncated > max_trunc) | (h < min_h)
    return np.where(gt.is_car & ~hard, 0, 1).astype(int)


def _kitti_frame_stats(det_boxes, det_scores, gt: KittiFrameGT, flags, min_h, iou, thresh, compute_fp):
    """One frame of devkit ``computeStatistics``: ``(tp, fp, fn, tp_scores, tp_gt_index)``."""
    D = len(det_boxes)
    ignored_det = (det_boxes[:, 3] - det_boxes[:, 1] < min_h).astype(int) if D else np.zeros(0, int)
    below = det_scores < thresh
    assigned = np.zeros(D, bool)
    ov = iou_2d(gt.boxes[:, None], det_boxes[None]) if (len(gt.boxes) and D) else np.zeros((len(gt.boxes), D))
    tp = fp = fn = 0
    tp_scores, tp_gt = [], []
    for i in range(len(gt.boxes)):
        det_idx, valid, max_ov, assigned_ignored = -1, -np.inf, 0.0, False
        for j in np.flatnonzero(ov[i] > iou):
            if assigned[j] or below[j]:
                continue
            o = ov[i, j]
            if not o > iou:
                continue
            if not compute_fp:
                if det_scores[j] > valid:
                    det_idx, valid = j, det_scores[j]
            elif (o > max_ov or assigned_ignored) and ignored_det[j] == 0:
                max_ov, det_idx, valid, assigned_ignored = o, j, 1.0, False
            elif valid == -np.inf and ignored_det[j] == 1:
                det_idx, valid, assigned_ignored = j, 1.0, True
        if valid == -np.inf:
            fn += flags[i] == 0
        elif flags[i] == 1 or ignored_det[det_idx] == 1:
            assigned[det_idx] = True
        else:
            tp += 1
            assigned[det_idx] = True
            tp_scores.append(det_scores[det_idx])
            tp_gt.append((i, det_idx))
    if compute_fp:
        free = ~assigned & ~below & (ignored_det == 0)
        for j in np.flatnonzero(free):
            if len(gt.dontcare) and np.any(_inside_fraction(det_boxes[j], gt.dontcare) > iou):
                free[j] = False  # inside a DontCare region: neither true nor false positive
        fp = int(free.sum())
    return tp, fp, fn, tp_scores, tp_gt


def kitti_ap_2d(detections, gts, *, difficulty: str = "moderate", iou: float = 0.7) -> dict:
    """KITTI 2D detection AP for class Car, following the devkit's rules.

    Ground truth of class Car counts unless its box is lower than the difficulty's minimum
    height or it is more occluded / truncated than allowed (then it is ignored, as are Vans
    and DontCare regions: a detection matching them, or lying inside a DontCare region, is
    neither a true nor a false positive); detections lower than the minimum height are
    ignored. A detection is a true positive when its IoU with a counted car exceeds ``iou``
    (0.7 for Car). AP is R40: the mean over recall r = 1/40 .. 1 of the best precision at
    recall >= r, with recall and precision counted by the devkit's matching at every
    true-positive score. (The devkit places its 40 thresholds by stepping recall 1/40 per
    true positive, which equals this for >= 40 counted cars but underestimates AP for
    fewer -- e.g. one fold of our 33 frames -- so that quirk is not copied.)

    ``detections``: per frame an object with ``boxes`` ``(D, 4)``, ``scores`` ``(D,)`` and
    ``alpha`` ``(D,)``; ``gts``: per frame a :class:`KittiFrameGT`. Returns ``ap``,
    ``n_gt``, the PR curve (``recall``, ``precision`` over sorted scores) and
    ``tp_alpha`` (``(T, 2)`` detected / true alpha of the true positives at the lowest
    threshold).
    """
    min_h = KITTI_DIFFICULTIES[difficulty][0]
    frames = [(_arr(d.boxes), np.asarray(d.scores, float), np.asarray(d.alpha, float), g, _gt_flags(g, difficulty))
              for d, g in zip(detections, gts)]
    n_gt = int(sum((f[4] == 0).sum() for f in frames))
    v, tp_alpha = [], []
    for b, s, a, g, fl in frames:
        _, _, _, sc, pairs = _kitti_frame_stats(b, s, g, fl, min_h, iou, -np.inf, False)
        v += sc
    v = np.unique(np.asarray(v, float))[::-1]
    # devkit matching (computeStatistics with compute_fp) at every true-positive score
    rec, prec = np.zeros(len(v)), np.zeros(len(v))
    for t, thr in enumerate(v):
        tp = fp = 0
        for b, s, a, g, fl in frames:
            r = _kitti_frame_stats(b, s, g, fl, min_h, iou, thr, True)
            tp, fp = tp + r[0], fp + r[1]
        rec[t], prec[t] = tp / max(n_gt, 1), tp / max(tp + fp, 1)
    # R40: interpolated precision (best precision at recall >= r) at r = 1/40 .. 1
    pts = np.arange(1, N_SAMPLE_PTS) / (N_SAMPLE_PTS - 1.0)
    interp = [prec[rec >= r - 1e-12].max() if np.any(rec >= r - 1e-12) else 0.0 for r in pts]
    ap = float(np.mean(interp)) if n_gt else float("nan")
    # full PR curve and viewpoints of the true positives at the lowest threshold
    all_s, all_t = [], []
    for b, s, a, g, fl in frames:
        tp, fp, fn, sc, pairs = _kitti_frame_stats(b, s, g, fl, min_h, iou, -np.inf, True)
        tp_alpha += [(a[j], g.alpha[i]) for i, j in pairs]
    # PR curve from per-detection status (greedy by score, the same matching at each threshold
    # is approximated by the lowest-threshold assignment; used for plots and recall at FPPI)
    for b, s, a, g, fl in frames:
        st = _det_status(b, s, g, fl, min_h, iou)
        all_s.append(s[st >= 0])
        all_t.append(st[st >= 0])
    s = np.concatenate(all_s) if all_s else np.zeros(0)
    t = np.concatenate(all_t) if all_t else np.zeros(0, int)
    order = np.argsort(-s, kind="stable")
    tpc, fpc = np.cumsum(t[order] == 1), np.cumsum(t[order] == 0)
    return {"ap": ap, "difficulty": difficulty, "iou": iou, "n_gt": n_gt, "n_frames": len(frames),
            "recall": tpc / max(n_gt, 1), "precision": tpc / np.maximum(tpc + fpc, 1), "scores": s[order],
            "fp": fpc, "tp_alpha": np.array(tp_alpha, float).reshape(-1, 2)}


def _det_status(boxes, scores, gt: KittiFrameGT, flags, min_h, iou) -> np.ndarray:
    """Per detection 1 = TP, 0 = FP, -1 = ignored, greedy in descending score (PASCAL
    style) under the devkit's ignore rules."""
    order = np.argsort(-scores, kind="stable")
    st = np.full(len(boxes), -1, int)
    used = np.zeros(len(gt.boxes), bool)
    for d in order:
        b = boxes[d]
        if len(gt.boxes):
            ov = iou_2d(b[None], gt.boxes)
            cnt = np.where((flags == 0) & ~used, ov, -1.0)
            j = int(np.argmax(cnt))
            if cnt[j] > iou:
                used[j] = True
                st[d] = 1
                continue
            if np.any((flags == 1) & (ov > iou)):
                continue
        if b[3] - b[1] < min_h:
            continue
        if len(gt.dontcare) and np.any(_inside_fraction(b, gt.dontcare) > iou):
            continue
        st[d] = 0
    return st


def recall_at_fppi(res: dict, fppi: float = 1.0) -> float:
    """Recall of :func:`kitti_ap_2d`'s PR curve where false positives per image reach ``fppi``."""
    fp, rec = res["fp"], res["recall"]
    ok = fp <= fppi * res["n_frames"]
    return float(rec[ok].max()) if ok.any() else 0.0


def viewpoint_accuracy(tp_alpha: np.ndarray) -> dict:
    """Viewpoint quality of true positives from ``(T, 2)`` (detected, true) alpha.

    ``bin``: same 45-degree bin; ``adjacent``: same or neighbouring bin; ``within_45``:
    ``|detected - true| <= 45 deg`` (wrapped), with the detected alpha the bin centre."""
    a = np.asarray(tp_alpha, float).reshape(-1, 2)
    if not len(a):
        return {"n": 0, "bin": float("nan"), "adjacent": float("nan"), "within_45": float("nan")}
    db = np.abs(viewpoint_bin(a[:, 0]) - viewpoint_bin(a[:, 1])) % 8
    db = np.minimum(db, 8 - db)
    return {"n": int(len(a)), "bin": float(np.mean(db == 0)), "adjacent": float(np.mean(db <= 1)),
            "within_45": float(np.mean(angle_difference(a[:, 0], a[:, 1]) <= np.deg2rad(45) + 1e-9))}
