"""A second detector family as a source of candidates: aggregated channel features.

Question (issue 27): the detector bank's held-out detections reach 80% of the real cars at any
score (70% above 0.05), and its verifier scores two thirds of the missed cars' label boxes like
background (``bench_missed_cars.py``). Does a detector of another family, with its own appearance
model, find the cars the bank misses at a precision the fit can use?

The detector is aggregated channel features (Dollar, Appel, Belongie and Perona, "Fast feature
pyramids for object detection", PAMI 2014) in its plain form: ten channels (CIE L*u*v*, gradient
magnitude and six orientation channels of the magnitude) summed over 4 x 4 pixel blocks and
smoothed; windows 8 blocks tall (32 pixels of car) plus one block of context, one model per box
aspect (cars seen from the front, obliquely, from the side); gradient-boosted trees of depth 2
(scikit-learn's histogram gradient boosting) on the window's blocks, trained on the labelled cars
and their mirror images against random and twice mined hard background windows. Windows are
searched only where a car of their height may stand on the road (the bottom row against the
horizon, :mod:`wirescene.predetect.geometry`), at 4 scales an octave from twice the image's
size down.

Protocol: 4 folds by drive (:mod:`wirescene.io.folds`); each fold's model is trained on the other
folds' frames and detects on its own. The held-out detections are scored with the bank's
(``bench_predetect.py --fold-models DIR --save-dets D.npz``) by the devkit's 2D AP and by the cars
each source reaches (a detection at IoU >= 0.5 at any score), alone and together, and by the cars
found at a given precision; the two sources are fused by a logistic model per source fitted on one
fold group and read on the other (:func:`fused_detections`).

    python benchmarks/bench_acf.py --root ../shared/data/kitti --out DIR --fold 0 --fold 2   # and --fold 1 --fold 3
    python benchmarks/bench_acf.py --root ../shared/data/kitti --out DIR --bank-dets D.npz   # score
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import read_saved_detections  # noqa: E402
from wirescene.core.boxes import iou_2d  # noqa: E402
from wirescene.core.image import to_rgb_uint8  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.bank import nms  # noqa: E402
from wirescene.predetect.geometry import horizon_row  # noqa: E402
from wirescene.predetect.hog import resize  # noqa: E402
from wirescene.training.kitti_detector import kitti_gt_boxes  # noqa: E402

SHRINK = 4  # pixels a block
N_ORIENT = 6
N_CH = 4 + N_ORIENT
CAR_CELLS = 8  # blocks of car height in a window
PAD = 1  # blocks of context on each side
ASPECTS = (1.2, 1.7, 2.5)  # width / height of each model's car box
RATIO_BAND = (0.75, 1.9)  # (bottom - horizon) / height a window may have
PER_OCTAVE = 4
MAX_SCALE = 2.0
MIN_HEIGHT = 16.0  # px of car, the smallest searched
TOP_K = 200  # detections kept a frame
N_TREES = 256
PRECISIONS = (0.8, 0.71, 0.6, 0.5)  # 0.71: the bank's at the fit's threshold
NEG_IOU = 0.3  # windows overlapping a car, van or truck less than this are background
BACKGROUND_TYPES = ("Car", "Van", "Truck", "DontCare")


def model_cells(aspect: float) -> tuple[int, int]:
    """(rows, columns) of blocks of a model's window, context included."""
    return CAR_CELLS + 2 * PAD, int(round(CAR_CELLS * aspect)) + 2 * PAD


def luv(image) -> np.ndarray:
    from skimage.color import rgb2luv

    return rgb2luv(to_rgb_uint8(image)).astype(np.float32) / 100.0


def channels(luv_img: np.ndarray) -> np.ndarray:
    """``(N_CH, H // 4, W // 4)`` aggregated, smoothed channels of an L*u*v* image ``(H, W, 3)``."""
    H, W = luv_img.shape[0] // SHRINK * SHRINK, luv_img.shape[1] // SHRINK * SHRINK
    Hb, Wb = H // SHRINK, W // SHRINK
    L = luv_img[..., 0]
    gy, gx = np.gradient(L)
    gy, gx = gy[:H, :W], gx[:H, :W]
    mag = np.hypot(gx, gy)
    o = (np.mod(np.arctan2(gy, gx), np.pi) * (N_ORIENT / np.pi)).astype(np.int64)
    np.minimum(o, N_ORIENT - 1, out=o)
    block = (np.arange(H)[:, None] // SHRINK) * Wb + np.arange(W)[None] // SHRINK
    agg = np.empty((N_CH, Hb, Wb), np.float32)
    agg[:3] = np.moveaxis(luv_img[:H, :W].reshape(Hb, SHRINK, Wb, SHRINK, 3).mean((1, 3)), -1, 0)
    agg[3] = mag.reshape(Hb, SHRINK, Wb, SHRINK).mean((1, 3))
    agg[4:] = np.bincount((o * (Hb * Wb) + block).ravel(), weights=mag.ravel(),
                          minlength=N_ORIENT * Hb * Wb).reshape(N_ORIENT, Hb, Wb) / SHRINK**2
    p = np.pad(agg, ((0, 0), (1, 1), (1, 1)), mode="edge")
    agg = (p[:, :-2] + 2 * p[:, 1:-1] + p[:, 2:]) / 4
    return ((agg[:, :, :-2] + 2 * agg[:, :, 1:-1] + agg[:, :, 2:]) / 4).astype(np.float32)


def resize_luv(luv_img: np.ndarray, w: int, h: int) -> np.ndarray:
    return np.stack([resize(luv_img[..., c], w, h) for c in range(3)], axis=-1)


def pyramid(image, *, per_octave: int = PER_OCTAVE) -> list[tuple[float, np.ndarray]]:
    """``[(scale, channels)]`` from twice the image's size down to cars of 320 px."""
    L = luv(image)
    H, W = L.shape[:2]
    out, k = [], 0
    while True:
        s = MAX_SCALE * 2.0 ** (-k / per_octave)
        if CAR_CELLS * SHRINK / s > 320 or H * s < (CAR_CELLS + 2 * PAD) * SHRINK:
            break
        out.append((s, channels(resize_luv(L, int(round(W * s)), int(round(H * s))))))
        k += 1
    return out


def window_positions(s: float, shape, aspect: float, horizon: float):
    """Block rows and columns of the windows at scale ``s`` where a car may stand, and their car boxes."""
    th, tw = model_cells(aspect)
    Hc, Wc = shape
    if Hc < th or Wc < tw:
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4))
    ys = np.arange(Hc - th + 1)
    height = CAR_CELLS * SHRINK / s
    bottom = (ys + PAD + CAR_CELLS) * SHRINK / s
    r = (bottom - horizon) / height
    ys = ys[(r >= RATIO_BAND[0]) & (r <= RATIO_BAND[1])]
    xs = np.arange(Wc - tw + 1)
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    yy, xx = yy.ravel(), xx.ravel()
    boxes = np.stack([(xx + PAD) * SHRINK / s, (yy + PAD) * SHRINK / s, (xx + tw - PAD) * SHRINK / s,
                      (yy + th - PAD) * SHRINK / s], axis=1)
    return yy, xx, boxes


def gather(ch: np.ndarray, yy, xx, aspect: float) -> np.ndarray:
    """``(N, F)`` float32 features of the windows at block rows ``yy`` and columns ``xx``."""
    th, tw = model_cells(aspect)
    view = np.lib.stride_tricks.sliding_window_view(ch, (th, tw), axis=(1, 2))  # (C, Hc', Wc', th, tw)
    return np.ascontiguousarray(np.moveaxis(view[:, yy, xx], 0, 1)).reshape(len(yy), -1)


def aspect_model(box) -> int:
    w, h = box[2] - box[0], box[3] - box[1]
    return int(np.argmin(np.abs(np.log(w / max(h, 1.0)) - np.log(ASPECTS))))


def compile_trees(clf, aspect: float) -> dict:
    """The boosted trees of ``clf`` as arrays ``(T, K)`` over each tree's ``K`` nodes, features
    as (channel, row, column) of the window, so that windows are scored straight from a
    channel map (:func:`score_windows`) without copying their features out. Reads scikit-learn's
    private tree arrays (``_predictors``, ``_baseline_prediction``); the tests check the scores
    against ``decision_function``, so a change there fails them."""
    trees = [p[0].nodes for p in clf._predictors]
    K = max(len(t) for t in trees)
    th, tw = model_cells(aspect)

    def field(name, dtype, fill):
        out = np.full((len(trees), K), fill, dtype)
        for i, t in enumerate(trees):
            out[i, :len(t)] = t[name]
        return out

    f = field("feature_idx", np.int64, 0)
    c, rest = np.divmod(f, th * tw)
    dy, dx = np.divmod(rest, tw)
    return {"c": c, "dy": dy, "dx": dx, "threshold": field("num_threshold", np.float64, 0.0),
            "left": field("left", np.int64, 0), "right": field("right", np.int64, 0),
            "leaf": field("is_leaf", bool, True), "value": field("value", np.float64, 0.0),
            "baseline": float(np.ravel(clf._baseline_prediction)[0]),
            "depth": int(max(t["depth"].max() for t in trees))}


def score_windows(trees: dict, ch: np.ndarray, yy, xx, *, chunk: int = 8192) -> np.ndarray:
    """``(N,)`` boosted-tree scores of the windows at block rows ``yy``, columns ``xx`` of ``ch``."""
    _, Hc, Wc = ch.shape
    flat = ch.reshape(-1)
    off = trees["c"] * (Hc * Wc) + trees["dy"] * Wc + trees["dx"]  # (T, K)
    T = off.shape[0]
    rows = np.arange(T)[:, None]
    out = np.empty(len(yy))
    for i in range(0, len(yy), chunk):
        base = (np.asarray(yy[i:i + chunk]) * Wc + np.asarray(xx[i:i + chunk]))[None]  # (1, n)
        node = np.zeros((T, base.shape[1]), np.int64)
        for _ in range(trees["depth"]):
            v = flat[off[rows, node] + base]
            nxt = np.where(v <= trees["threshold"][rows, node], trees["left"][rows, node], trees["right"][rows, node])
            node = np.where(trees["leaf"][rows, node], node, nxt)
        out[i:i + chunk] = trees["value"][rows, node].sum(0) + trees["baseline"]
    return out


class ACF:
    """One boosted-tree model per aspect (:func:`compile_trees`); ``detect`` gives boxes and scores."""

    def __init__(self, models):
        self.models = models

    def detect(self, image, camera, *, top_k: int = TOP_K):
        horizon = horizon_row(camera)
        pyr = pyramid(image)
        boxes, scores = [], []
        for aspect, trees in zip(ASPECTS, self.models):
            for s, ch in pyr:
                if CAR_CELLS * SHRINK / s < MIN_HEIGHT:
                    continue
                yy, xx, b = window_positions(s, ch.shape[1:], aspect, horizon)
                boxes.append(b)
                scores.append(score_windows(trees, ch, yy, xx))
        boxes = np.concatenate(boxes) if boxes else np.zeros((0, 4))
        scores = np.concatenate(scores) if scores else np.zeros(0)
        order = np.argsort(-scores)[:20 * top_k]
        boxes, scores = boxes[order], scores[order]
        keep = nms(boxes, scores, 0.5, max_keep=top_k)
        return boxes[keep], scores[keep]


def training_windows(ds, frames, rng, *, models=None, per_frame: int = 40, hard: bool = False, cache=None):
    """Background windows of the training frames (and their mirrors): random ones, or the
    highest-scoring ones of the current ``models``; ``cache`` keeps the pyramids between rounds."""
    cache = {} if cache is None else cache
    X = [[] for _ in ASPECTS]
    for f in frames:
        img = ds.image(f)
        cam = ds.camera(f)
        others = np.array([o.box for o in ds.labels(f).objects if o.type in BACKGROUND_TYPES], float).reshape(-1, 4)
        W = img.shape[1]
        for flip in (False, True):
            im = img[:, ::-1] if flip else img
            occ = others.copy()
            if flip:
                occ[:, [0, 2]] = W - others[:, [2, 0]]
            if (f, flip) not in cache:
                cache[f, flip] = pyramid(im)
            pyr = cache[f, flip]
            horizon = horizon_row(cam)
            for m, aspect in enumerate(ASPECTS):
                cand = []
                for li, (s, ch) in enumerate(pyr):
                    if CAR_CELLS * SHRINK / s < MIN_HEIGHT:
                        continue
                    yy, xx, b = window_positions(s, ch.shape[1:], aspect, horizon)
                    if not len(yy):
                        continue
                    free = iou_2d(b[:, None], occ[None]).max(1) < NEG_IOU if len(occ) else np.ones(len(b), bool)
                    yy, xx, b = yy[free], xx[free], b[free]
                    if hard:
                        sc = score_windows(models[m], ch, yy, xx)
                        top = np.argsort(-sc)[:per_frame]
                        cand += [(sc[t], li, yy[t], xx[t], b[t]) for t in top]
                    else:
                        pick = rng.choice(len(yy), size=min(len(yy), max(per_frame // len(pyr), 2)), replace=False)
                        cand += [(0.0, li, yy[t], xx[t], b[t]) for t in pick]
                if hard:  # the highest-scoring windows, one per place
                    cand.sort(key=lambda c: -c[0])
                    cb = np.array([c[4] for c in cand]).reshape(-1, 4)
                    keep = nms(cb, np.array([c[0] for c in cand]), 0.5, max_keep=per_frame) if len(cand) else []
                    cand = [cand[i] for i in keep]
                for _, li, y, x, _b in cand:
                    X[m].append(gather(pyr[li][1], np.array([y]), np.array([x]), aspect)[0])
    return [np.array(x, np.float32).reshape(-1, N_CH * np.prod(model_cells(a))) for x, a in zip(X, ASPECTS)]


def positives(ds, frames, *, cache=None):
    """Features of the labelled cars and their mirror images: the window of the model whose
    aspect is nearest the box's, centred on the box, at the level of a pyramid of 8 scales an
    octave where the car is nearest ``CAR_CELLS`` blocks tall (so each positive is computed
    as the windows searched at detection time are). ``cache`` receives every other level: the
    detection pyramid of 4 scales an octave, for :func:`training_windows`."""
    cache = {} if cache is None else cache
    X = [[] for _ in ASPECTS]
    for f in frames:
        img = ds.image(f)
        W = img.shape[1]
        cars = [o.box for o in ds.labels(f).objects if o.type == "Car" and o.box[3] - o.box[1] >= MIN_HEIGHT * 0.9]
        for flip in (False, True):
            if not cars:
                break
            pyr = pyramid(img[:, ::-1] if flip else img, per_octave=2 * PER_OCTAVE)
            cache[f, flip] = pyr[::2]  # 2 ** (-2k / 8) is 2 ** (-k / 4) exactly
            scales = np.array([s for s, _ in pyr])
            for box in cars:
                box = np.array([W - box[2], box[1], W - box[0], box[3]]) if flip else np.asarray(box, float)
                m = aspect_model(box)
                th, tw = model_cells(ASPECTS[m])
                li = int(np.argmin(np.abs(np.log(scales * (box[3] - box[1]) / (CAR_CELLS * SHRINK)))))
                s, ch = pyr[li]
                y = int(np.clip(round(box[1] * s / SHRINK - PAD), 0, ch.shape[1] - th))
                x = int(np.clip(round((box[0] + box[2]) / 2 * s / SHRINK - tw / 2), 0, ch.shape[2] - tw))
                X[m].append(gather(ch, np.array([y]), np.array([x]), ASPECTS[m])[0])
    return [np.array(x, np.float32) for x in X]


def fit(Xp, Xn, aspect: float, *, seed: int = 0, n_trees: int = N_TREES) -> dict:
    """Boosted trees of depth 2 on cars ``Xp`` against background ``Xn`` (classes weighted
    equally), compiled for the windows of the model of ``aspect``."""
    from sklearn.ensemble import HistGradientBoostingClassifier

    X = np.concatenate([Xp, Xn])
    y = np.r_[np.ones(len(Xp)), np.zeros(len(Xn))]
    w = np.where(y == 1, len(Xn) / max(len(Xp), 1), 1.0)
    clf = HistGradientBoostingClassifier(max_iter=n_trees, max_depth=2, learning_rate=0.1, max_bins=64,
                                         l2_regularization=1.0, early_stopping=False, random_state=seed,
                                         max_features=0.25)
    clf.fit(X, y, sample_weight=w)
    return compile_trees(clf, aspect)


def train(ds, frames, *, seed: int = 0, rounds: int = 2, log=print) -> ACF:
    """The three aspect models on ``frames``: random background, then ``rounds`` of mined hard background."""
    rng = np.random.default_rng(seed)
    t = time.time()
    cache = {}
    Xp = positives(ds, frames, cache=cache)
    Xn = training_windows(ds, frames, rng, per_frame=120, cache=cache)
    log(f"  positives {[len(x) for x in Xp]}, random background {[len(x) for x in Xn]} ({time.time() - t:.0f} s)")
    models = [fit(p, n, a, seed=seed) for p, n, a in zip(Xp, Xn, ASPECTS)]
    for r in range(rounds):
        t = time.time()
        Xh = training_windows(ds, frames, rng, models=models, per_frame=25, hard=True, cache=cache)
        Xn = [np.concatenate([n, h]) for n, h in zip(Xn, Xh)]
        models = [fit(p, n, a, seed=seed) for p, n, a in zip(Xp, Xn, ASPECTS)]
        log(f"  round {r + 1}: background {[len(x) for x in Xn]} ({time.time() - t:.0f} s)")
    return ACF(models)


def reach(dets: dict, frames, labels) -> np.ndarray:
    """``(n_cars,)`` best IoU of any detection with each ``Car`` label, frames in order."""
    out = []
    for f, lab in zip(frames, labels):
        gt = kitti_gt_boxes(lab)
        b = dets[f][0]
        out.append(iou_2d(b[:, None], gt[None]).max(0) if len(b) and len(gt) else np.zeros(len(gt)))
    return np.concatenate(out)


def fusion_features(bank, acf, *, iou: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Features of each source's detections: the bank's ``(B, 3)`` (its logit, the best ACF
    score among ACF's detections that overlap it at ``iou``, floor -10 where none does, and
    whether any does), ACF's ``(A, 5)`` (its score, the box's log height, their product, the
    best bank logit overlapping it and whether any does)."""
    bb, bs, _ = bank
    ab, a_s = acf
    p = np.clip(bs, 1e-4, 1 - 1e-4)
    lb = np.log(p / (1 - p))
    ov = iou_2d(bb[:, None], ab[None]) >= iou if len(bb) and len(ab) else np.zeros((len(bb), len(ab)), bool)
    fa = np.where(ov, a_s[None], -np.inf).max(1, initial=-np.inf)
    fb = np.where(ov.T, lb[None], -np.inf).max(1, initial=-np.inf)
    log_h = np.log(np.maximum(ab[:, 3] - ab[:, 1], 1.0))
    return (np.column_stack([lb, np.where(np.isfinite(fa), fa, -10.0), np.isfinite(fa)]),
            np.column_stack([a_s, log_h, a_s * log_h, np.where(np.isfinite(fb), fb, -10.0), np.isfinite(fb)]))


def fused_detections(frames, bank, acf, labels, weights_from, *, bank_first: bool, iou: float = 0.5,
                     top_k: int = TOP_K):
    """Both sources' detections, each scored by a logistic model of its
    :func:`fusion_features` fitted on the frames of ``weights_from`` (a car: IoU >= ``iou``
    with a ``Car`` label), suppressed together at IoU 0.5. ``bank_first``: ACF's detections
    count only where no bank detection overlaps them (ACF adds places, the bank's boxes and
    viewpoints stay)."""
    from sklearn.linear_model import LogisticRegression

    def car(f, boxes):
        gt = kitti_gt_boxes(labels[f])
        return iou_2d(boxes[:, None], gt[None]).max(1) >= iou if len(gt) and len(boxes) else np.zeros(len(boxes), bool)

    x = {f: fusion_features(bank[f], acf[f], iou=iou) for f in frames}
    fit_on = [f for f in frames if f in weights_from]
    models = [LogisticRegression(C=1.0, max_iter=1000).fit(np.concatenate([x[f][i] for f in fit_on]),
                                                           np.concatenate([car(f, src[f][0]) for f in fit_on]))
              for i, src in enumerate((bank, acf))]
    out = []
    for f in frames:
        pb, pa = (m.predict_proba(v)[:, 1] if len(v) else np.zeros(0) for m, v in zip(models, x[f]))
        if bank_first:
            pa = np.where(x[f][1][:, 4] > 0, 0.0, pa)
        boxes = np.concatenate([bank[f][0], acf[f][0]]).reshape(-1, 4)
        p = np.concatenate([pb, pa])
        alpha = np.concatenate([bank[f][2], np.full(len(pa), np.nan)])
        keep = nms(boxes, p, 0.5, max_keep=top_k)
        out.append(Detections(boxes[keep], p[keep], alpha[keep]))
    return out


def found_at_precision(dets, labels, precisions, *, iou: float = 0.5) -> list[tuple[float, int, float]]:
    """For each precision: the most cars found (share of the ``Car`` labels with a detection at
    ``iou``) by any threshold whose detections are at least that share on a car, and the fewest
    detections (and the threshold) that find as many."""
    scores, on, car_id, n_cars = [], [], [], 0
    for d, lab in zip(dets, labels):
        gt = kitti_gt_boxes(lab)
        b = np.asarray(d.boxes, float).reshape(-1, 4)
        ov = iou_2d(b[:, None], gt[None]) if len(gt) and len(b) else np.zeros((len(b), len(gt)))
        scores.append(np.asarray(d.scores, float))
        on.append(ov.max(1) >= iou if len(gt) else np.zeros(len(b), bool))
        car_id.append(np.where(ov.max(1) >= iou, ov.argmax(1) + n_cars, -1) if len(gt) else np.full(len(b), -1))
        n_cars += len(gt)
    scores, on, car_id = np.concatenate(scores), np.concatenate(on), np.concatenate(car_id)
    order = np.argsort(-scores, kind="stable")
    on, car_id = on[order], car_id[order]
    prec = np.cumsum(on) / np.arange(1, len(on) + 1)
    seen = np.zeros(n_cars + 1, bool)
    new = np.zeros(len(on), bool)
    for i, c in enumerate(car_id):
        if c >= 0 and not seen[c]:
            seen[c] = new[i] = True
    found = np.cumsum(new) / max(n_cars, 1)
    out = []
    for p in precisions:
        ok = np.flatnonzero(prec >= p)
        k = ok[np.argmax(found[ok])] if len(ok) else -1
        out.append((float(found[k]) if k >= 0 else 0.0, int(k + 1), float(scores[order][k]) if k >= 0 else np.nan))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames (e.g. ../shared/data/kitti)")
    ap.add_argument("--out", required=True, help="directory of the held-out detections acf{k}.npz")
    ap.add_argument("--fold", type=int, action="append", help="train and detect these folds (default: score)")
    ap.add_argument("--bank-dets", help="the bank's held-out detections (bench_predetect.py --save-dets)")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of hard background windows")
    args = ap.parse_args()
    ds = KittiDataset(args.root)
    frames = ds.frame_ids()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.fold:
        for k in args.fold:
            t = time.time()
            train_frames = [f for f in frames if fold_of(f) != k]
            print(f"fold {k}: training on {len(train_frames)} frames", flush=True)
            model = train(ds, train_frames, rounds=args.rounds, log=lambda s: print(s, flush=True))
            rec, t_det = {}, time.time()
            test = [f for f in frames if fold_of(f) == k]
            for f in test:
                b, s = model.detect(ds.image(f), ds.camera(f))
                rec[f"{f}__boxes"], rec[f"{f}__scores"] = b, s
            np.savez_compressed(out / f"acf{k}.npz", **rec)
            print(f"fold {k}: {time.time() - t:.0f} s, detection {(time.time() - t_det) / len(test):.2f} s a frame",
                  flush=True)
        return
    from bench_predetect import fmt, metrics

    acf = {}
    for k in range(N_FOLDS):
        d = np.load(out / f"acf{k}.npz")
        for f in frames:
            if fold_of(f) == k:
                acf[f] = (d[f"{f}__boxes"], d[f"{f}__scores"])
    labels = [ds.labels(f) for f in frames]
    # the logistic of each fold model's boosted score (the pooled AP ranks the four models' scores together)
    dets = [Detections(acf[f][0], 1 / (1 + np.exp(-acf[f][1])), np.full(len(acf[f][1]), np.nan)) for f in frames]
    print(fmt("ACF (held out)", metrics(dets, labels)))
    r_acf = reach(acf, frames, labels)
    print(f"ACF reaches {np.mean(r_acf >= 0.5):.1%} of {len(r_acf)} cars at IoU 0.5, {np.mean(r_acf >= 0.7):.1%} at 0.7")
    if args.bank_dets:
        saved = read_saved_detections(args.bank_dets, frames)
        bank = {f: (saved[f].boxes, saved[f].scores) for f in frames}
        r_bank = reach(bank, frames, labels)
        both = np.maximum(r_acf, r_bank)
        h = np.concatenate([[o.box[3] - o.box[1] for o in lab.objects if o.type == "Car"] for lab in labels])
        print(f"the bank reaches {np.mean(r_bank >= 0.5):.1%}, both {np.mean(both >= 0.5):.1%}; "
              f"of the {int(np.sum(r_bank < 0.5))} cars the bank misses ACF reaches {int(np.sum((r_bank < 0.5) & (r_acf >= 0.5)))}")
        for lo, hi in ((0, 25), (25, 60), (60, np.inf)):
            sel = (h >= lo) & (h < hi)
            print(f"  {lo}-{hi} px ({int(sel.sum())} cars): bank {np.mean(r_bank[sel] >= 0.5):.0%}, ACF "
                  f"{np.mean(r_acf[sel] >= 0.5):.0%}, both {np.mean(both[sel] >= 0.5):.0%}")
        bank_alpha = {f: (bank[f][0], bank[f][1], saved[f].alpha) for f in frames}
        label_of = dict(zip(frames, labels))
        runs = {"the bank alone": [Detections(*bank_alpha[f]) for f in frames]}
        for name, first in (("both, fused", False), ("both, ACF only where no bank box is", True)):
            fused = {}
            for group in FOLD_GROUPS:  # the fusion's weights fitted on one fold group, read on the other
                other = {f for f in frames if fold_of(f) not in group}
                d = fused_detections(frames, bank_alpha, acf, label_of, other, bank_first=first)
                fused.update({f: x for f, x in zip(frames, d) if fold_of(f) in group})
            runs[name] = [fused[f] for f in frames]
        for name, dd in runs.items():
            print(fmt(name, metrics(dd, labels)))
            for g in FOLD_GROUPS:
                sel = [i for i, f in enumerate(frames) if fold_of(f) in g]
                m = metrics([dd[i] for i in sel], [labels[i] for i in sel])
                n_cars = sum(o.type == "Car" for i in sel for o in labels[i].objects)
                found = found_at_precision([dd[i] for i in sel], [labels[i] for i in sel], PRECISIONS)
                print(f"  folds {g}: moderate 2D AP {m['2d']['moderate']:.1f} ({m['n_gt']['moderate']} cars); cars found "
                      f"at precision {' / '.join(f'{p:.2f}' for p in PRECISIONS)}: "
                      f"{' / '.join(str(round(r * n_cars)) for r, _, _ in found)} of {n_cars}")
            print("  most cars found at precision " + "; ".join(
                f">= {p:.2f}: {r:.1%} ({k} detections)"
                for p, (r, k, _) in zip(PRECISIONS, found_at_precision(dd, labels, PRECISIONS))))
        # the cars the bank misses: does ACF score them above its own false detections?
        acf_dets = [Detections(acf[f][0], acf[f][1], np.zeros(len(acf[f][1]))) for f in frames]
        best = []  # each car's best ACF score among ACF's boxes at IoU >= 0.5
        for f, lab in zip(frames, labels):
            gt = kitti_gt_boxes(lab)
            b, sc = acf[f]
            ov = iou_2d(b[:, None], gt[None]) >= 0.5 if len(gt) and len(b) else np.zeros((len(b), len(gt)), bool)
            best.append(np.where(ov, sc[:, None], -np.inf).max(0, initial=-np.inf))
        best, missed = np.concatenate(best), r_bank < 0.5
        for p, (_, _, t) in zip(PRECISIONS, found_at_precision(acf_dets, labels, PRECISIONS)):
            print(f"  ACF at precision >= {p:.2f} (score >= {t:.2f}) finds {int(np.sum(missed & (best >= t)))} of the "
                  f"{int(missed.sum())} cars no bank box reaches")


if __name__ == "__main__":
    main()
