"""2D car detection average precision with the paper's pre-detection protocol (Sec. 5.2).

This is not KITTI's AP: the one KITTI evaluation is :mod:`wirescene.eval.kitti_metrics`
(:func:`~wirescene.eval.kitti_metrics.detection_ap_2d` for 2D detections). Here:
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
from wirescene.core.labels import CAR_TYPES, is_type
from wirescene.core.viewpoints import angle_difference, viewpoint_bin
from wirescene.io.wireframes import wireframe_gt_path

NEIGHBOUR_TYPES = ("Van",)


@dataclass
class FrameGT:
    """A frame's ground truth as the pre-detection AP reads it (:func:`frame_gt`): the cars
    that count ``boxes`` ``(K, 4)`` with their observation angles ``alpha`` ``(K,)``, the
    objects whose matches are ignored ``ignore`` ``(M, 4)`` and the DontCare regions
    ``dontcare`` ``(N, 4)``.

    Examples
    --------
    >>> from wirescene.core.labels import FrameLabels, Label
    >>> def label(kind, box):
    ...     return Label(kind, 0.0, 0, 1.6, box, [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> labels = FrameLabels([label("Car", [100, 100, 200, 160]),  # counts: 60 px high
    ...                       label("Car", [300, 100, 340, 130]),  # 30 px high: ignored
    ...                       label("Van", [500, 100, 600, 170])],  # the neighbouring class: ignored
    ...                      [label("DontCare", [700, 100, 800, 200])])
    >>> gt = frame_gt(labels)
    >>> gt.boxes, gt.alpha, gt.ignore.shape, gt.dontcare.shape
    (array([[100., 100., 200., 160.]]), array([1.6]), (2, 4), (1, 4))
    """

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
    with ``labels.objects``) for the exact visible fraction; else the KITTI rule.

    Examples
    --------
    >>> from wirescene.core.labels import FrameLabels, Label
    >>> def label(kind, box):
    ...     return Label(kind, 0.0, 0, 1.6, box, [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> labels = FrameLabels([label("Car", [100, 100, 200, 160]),  # counts: 60 px high
    ...                       label("Car", [300, 100, 340, 130]),  # 30 px high: ignored
    ...                       label("Van", [500, 100, 600, 170])],  # the neighbouring class: ignored
    ...                      [label("DontCare", [700, 100, 800, 200])])
    >>> gt = frame_gt(labels)
    >>> len(gt.boxes), len(frame_gt(labels, min_height=25).boxes)  # the small car counts from 25 px up
    (1, 2)
    """
    keep, alpha, ignore = [], [], []
    cars = wireframes.get("cars") if wireframes else None
    for k, o in enumerate(labels.objects):
        if is_type(o.type, CAR_TYPES):
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
        elif is_type(o.type, NEIGHBOUR_TYPES):
            ignore.append(o.box)
    return FrameGT(_arr(keep), np.asarray(alpha, float), _arr(ignore), _arr([d.box for d in labels.dontcare]))


def _inside_fraction(det: np.ndarray, regions: np.ndarray) -> np.ndarray:
    iw = np.clip(np.minimum(det[2], regions[:, 2]) - np.maximum(det[0], regions[:, 0]), 0, None)
    ih = np.clip(np.minimum(det[3], regions[:, 3]) - np.maximum(det[1], regions[:, 1]), 0, None)
    area = max((det[2] - det[0]) * (det[3] - det[1]), 1e-9)
    return iw * ih / area


def match_frame(boxes, scores, alpha, gt: FrameGT, *, iou: float = 0.5, min_height: float = 50.0):
    """Label one frame's detections: returns ``(status (D,), gt_index (D,))`` with status
    1 = true positive, 0 = false positive, -1 = ignored; detections in descending score.

    Examples
    --------
    >>> from wirescene.core.labels import FrameLabels, Label
    >>> def label(kind, box):
    ...     return Label(kind, 0.0, 0, 1.6, box, [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> labels = FrameLabels([label("Car", [100, 100, 200, 160]),  # counts: 60 px high
    ...                       label("Car", [300, 100, 340, 130]),  # 30 px high: ignored
    ...                       label("Van", [500, 100, 600, 170])],  # the neighbouring class: ignored
    ...                      [label("DontCare", [700, 100, 800, 200])])
    >>> boxes = [[100, 100, 200, 160], [300, 100, 340, 130], [500, 100, 600, 170], [710, 110, 790, 190],
    ...          [900, 100, 1000, 170]]
    >>> status, gt_index = match_frame(boxes, [0.9, 0.8, 0.7, 0.6, 0.5], None, frame_gt(labels))
    >>> status  # the car; the small car, the van and the DontCare region ignored; a false positive
    array([ 1, -1, -1, -1,  0])
    >>> gt_index
    array([ 0, -1, -1, -1, -1])
    """
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


def voc_average_precision(recall: np.ndarray, precision: np.ndarray) -> float:
    """PASCAL VOC (2010+) all-point interpolated AP.

    Examples
    --------
    >>> voc_average_precision(np.array([0.5, 1.0]), np.array([1.0, 0.5]))  # 0.5 x 1 + 0.5 x 0.5
    0.75
    """
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[0.0], precision, [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    i = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[i + 1] - mrec[i]) * mpre[i + 1]))


def evaluate_detections(detections, gts, *, iou: float = 0.5, min_height: float = 50.0) -> dict:
    """AP, PR curve and viewpoint accuracy over frames.

    ``detections``: per frame a :class:`~wirescene.core.types.Detections` (or any
    object with ``boxes``, ``scores``, ``alpha``); ``gts``: per frame a :class:`FrameGT`.

    Examples
    --------
    >>> from wirescene.core.labels import FrameLabels, Label
    >>> def label(kind, box):
    ...     return Label(kind, 0.0, 0, 1.6, box, [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> labels = FrameLabels([label("Car", [100, 100, 200, 160]),  # counts: 60 px high
    ...                       label("Car", [300, 100, 340, 130]),  # 30 px high: ignored
    ...                       label("Van", [500, 100, 600, 170])],  # the neighbouring class: ignored
    ...                      [label("DontCare", [700, 100, 800, 200])])
    >>> from wirescene.core.types import Detections
    >>> boxes = [[100, 100, 200, 160], [900, 100, 1000, 170]]
    >>> result = evaluate_detections([Detections(boxes, [0.9, 0.5], [1.57, np.nan])], [frame_gt(labels)])
    >>> result["ap"], result["n_tp"], result["precision"], result["viewpoint_bin_acc"]  # the car first: AP 1
    (1.0, 1, array([1. , 0.5]), 1.0)
    >>> evaluate_detections([Detections(boxes, [0.5, 0.9], np.nan)], [frame_gt(labels)])["ap"]  # ranked behind
    0.5
    """
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
    ap = voc_average_precision(recall, precision) if n_gt else float("nan")
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
    """JSON-friendly subset of :func:`evaluate_detections`'s result.

    Examples
    --------
    >>> from wirescene.core.labels import FrameLabels, Label
    >>> def label(kind, box):
    ...     return Label(kind, 0.0, 0, 1.6, box, [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    >>> labels = FrameLabels([label("Car", [100, 100, 200, 160]),  # counts: 60 px high
    ...                       label("Car", [300, 100, 340, 130]),  # 30 px high: ignored
    ...                       label("Van", [500, 100, 600, 170])],  # the neighbouring class: ignored
    ...                      [label("DontCare", [700, 100, 800, 200])])
    >>> from wirescene.core.types import Detections
    >>> result = evaluate_detections([Detections([[100, 100, 200, 160]], 0.9, 1.57)], [frame_gt(labels)])
    >>> summary(result)  # without the curves
    {'ap': 1.0, 'n_gt': 1, 'n_det': 1, 'n_tp': 1, 'max_recall': 1.0, 'viewpoint_bin_acc': 1.0, 'viewpoint_within_45': 1.0}
    """
    return {k: v for k, v in res.items() if not isinstance(v, np.ndarray)}


def plot_pr(results: dict, path, *, title: str = "Car pre-detection") -> Path:
    """Precision-recall curves ``{name: result}`` to a PNG
    (:func:`wirescene.io.pictures.new_figure`); a result's ``n_gt``, where it has one, is
    counted in the key (an AP over a few cars is not one over many). ``title`` says the
    protocol (an AP of this one is not KITTI's)."""
    from wirescene.io.pictures import new_figure, save_figure

    fig = new_figure(figsize=(5, 4.5))
    ax = fig.subplots()
    for name, r in results.items():
        cars = f", {r['n_gt']} cars" if "n_gt" in r else ""
        ax.plot(r["recall"], r["precision"], label=f"{name} (AP {100 * r['ap']:.1f}%{cars})")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left")
    return save_figure(fig, path, dpi=100, bbox_inches="tight")


def load_frame_gt(split_dir, frame_id: str, **kw) -> FrameGT:
    """GT of one frame of a KITTI-layout split (uses ``wireframes/`` when present).

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> gt = load_frame_gt(DATA_DIR / "sample" / "kitti" / "training", "000010")
    >>> gt.boxes.shape, gt.ignore.shape, gt.dontcare.shape  # cars that count, ignored objects, DontCare
    ((5, 4), (3, 4), (4, 4))
    """
    from wirescene.io.kitti import read_labels

    split_dir = Path(split_dir)
    labels = read_labels(split_dir / "label_2" / f"{frame_id}.txt")
    wpath = wireframe_gt_path(split_dir, frame_id)
    wire = json.loads(wpath.read_text()) if wpath.is_file() else None
    return frame_gt(labels, wireframes=wire, **kw)
