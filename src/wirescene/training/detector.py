"""Train the configuration detector bank on synthetic street scenes (deterministic).

1. Generate ``n_scenes`` scenes with :func:`wirescene.synth.generate.generate_scene`
   (stream ``seed``); every car and its horizontal mirror image is an example (mirroring
   maps viewpoint bin b to 4 - b and swaps left/right vertices).
2. Choose the configurations (:func:`.configurations.select_configurations`).
3. Per configuration: positives = its box warped to the template, in cars where all its
   vertices are visible (full-car: < 20% occluded, untruncated); negatives = random
   windows of the scenes' feature pyramids overlapping no car by more than 30% of the
   window; configurations with fewer than ``min_pos`` positives get jittered copies
   (shift +-5%, scale +-7%, at most 4 per example); a linear SVM; then ``mining_rounds`` rounds of hard-negative mining (windows
   scoring above -1 that overlap no car; each round on ``mining_images`` scenes, :func:`mining_subsets`), retraining on
   all negatives.
4. The default threshold maximises F1 on ``n_val`` held-out scenes (stream ``seed + 1``).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wirescene.core.viewpoints import N_BINS
from wirescene.predetect.ap import summary
from wirescene.predetect.bank import DetectorBank, detect_cars, half_inside, pad_pyramid, score_pyramid
from wirescene.predetect.configurations import (
    FULL,
    apply_full_box,
    config_box,
    examples_from_wireframes,
    learn_full_box_correction,
    select_configurations,
)
from wirescene.predetect.hog import CELL, N_FEAT, crops_features, feature_pyramid, pyramid_scales, to_gray
from wirescene.training.scale import single_threaded


def _overlap_frac(windows: np.ndarray, cars: np.ndarray) -> np.ndarray:
    """(W,) max over cars of intersection / window area."""
    if not len(cars) or not len(windows):
        return np.zeros(len(windows))
    iw = np.clip(np.minimum(windows[:, None, 2], cars[None, :, 2]) - np.maximum(windows[:, None, 0], cars[None, :, 0]), 0, None)
    ih = np.clip(np.minimum(windows[:, None, 3], cars[None, :, 3]) - np.maximum(windows[:, None, 1], cars[None, :, 1]), 0, None)
    area = np.maximum((windows[:, 2] - windows[:, 0]) * (windows[:, 3] - windows[:, 1]), 1e-9)
    return (iw * ih).max(1) / area


def mining_subsets(n_images: int, rounds: int, per_round: int | None, *, seed: int = 0) -> list[np.ndarray]:
    """Indices of the images each of ``rounds`` mining rounds searches, in image order: all
    ``n_images`` where ``per_round`` is None or not below it; else round ``r`` takes the
    ``r``-th stretch of ``per_round`` images of one random order (wrapping round), so that the
    rounds search ``min(n_images, rounds * per_round)`` different images.

    Examples
    --------
    >>> [s.tolist() for s in mining_subsets(5, 2, None)]
    [[0, 1, 2, 3, 4], [0, 1, 2, 3, 4]]
    >>> subsets = mining_subsets(6, 3, 2)
    >>> sorted(i for s in subsets for i in s.tolist())
    [0, 1, 2, 3, 4, 5]
    """
    if per_round is not None and per_round < 1:
        raise ValueError(f"mining_images must be at least 1, got {per_round}")
    if per_round is None or per_round >= n_images:
        return [np.arange(n_images) for _ in range(rounds)]
    order = np.random.default_rng([seed, 2]).permutation(n_images)  # its own stream: the other draws stay
    return [np.sort(order[np.arange(r * per_round, (r + 1) * per_round) % n_images]) for r in range(rounds)]


def _valid_levels(cfg, pyr, H, min_height):
    th, tw = cfg.template
    out = []
    for li, (s, F) in enumerate(pyr):
        full_h = th * CELL / s / max(float(cfg.frac[1]), 1e-3)
        if th <= F.shape[0] and tw <= F.shape[1] and min_height <= full_h <= 3.0 * H:
            out.append(li)
    return out


def _fit_svm(pos, neg, C, seed):
    from sklearn.svm import LinearSVC

    X = np.concatenate([pos, neg]).astype(np.float32)
    y = np.concatenate([np.ones(len(pos)), -np.ones(len(neg))])
    clf = LinearSVC(C=C, class_weight={1: 2.0, -1: 1.0}, max_iter=4000, random_state=seed, dual=True)
    clf.fit(X, y)
    return clf.coef_.ravel().astype(np.float32), float(clf.intercept_[0])




def sample_random_negatives(neg, pyr, configs, blocked, *, H, min_height, per_image, rng, pad_cells: int = 0) -> None:
    """Append to ``neg[t]`` (a list or a :class:`~wirescene.training.scale.NegativePool`) up
    to ``per_image`` random windows of pyramid ``pyr`` for each configuration ``t``, skipping windows that overlap a ``blocked`` box (cars) by more than 30%.
    ``pad_cells``: windows may reach that many empty cells past the image's sides, as
    :func:`~wirescene.predetect.bank.score_pyramid` scores them."""
    padded = pad_pyramid(pyr, pad_cells)
    for t, c in enumerate(configs):
        th, tw = c.template
        levels = _valid_levels(c, pyr, H, min_height)
        if not levels:
            continue
        got = 0
        for _ in range(4 * per_image):
            li = levels[rng.integers(len(levels))]
            s, F = padded[li]
            r, q = rng.integers(F.shape[0] - th + 1), rng.integers(F.shape[1] - tw + 1)
            if not half_inside(q, tw, F.shape[1] - 2 * pad_cells, pad_cells):
                continue
            win = np.array([[q - pad_cells, r, q - pad_cells + tw, r + th]]) * CELL / s
            if _overlap_frac(win, blocked)[0] > 0.3:
                continue
            neg[t].append(F[r:r + th, q:q + tw].flatten())  # a copy: a view would hold the whole level
            got += 1
            if got >= per_image:
                break

def fit_svms(configs, pos, neg, *, C: float, seed: int, whiteners=None):
    """One linear SVM per configuration on its positive and negative descriptors (lists
    per configuration); a configuration without positives gets zero weights and a bias of
    -10, so it never fires. Returns ``(weights, biases)`` as :class:`DetectorBank` takes them.
    ``whiteners``: one :func:`~wirescene.training.whitening.whitening_matrix` per
    configuration to train in whitened features, None for raw HOG."""
    weights, biases = [], np.zeros(len(configs), np.float32)
    for t, c in enumerate(configs):
        th, tw = c.template
        if not len(pos[t]):
            weights.append(np.zeros((th, tw, N_FEAT), np.float32))
            biases[t] = -10.0
            continue
        P, N = pos[t], np.array(neg[t], np.float32).reshape(-1, th * tw * N_FEAT)
        if whiteners is None:
            w, b = _fit_svm(P, N, C, seed)
        else:
            M = whiteners[t]
            w, b = _fit_svm(P @ M, N @ M, C, seed)
            w = M @ w
        weights.append(w.reshape(th, tw, N_FEAT))
        biases[t] = b
    return weights, biases

def calibrate_threshold(bank: DetectorBank, *, seed: int, n_val: int, cars=(2, 8), max_scale: float = 2.0,
                        min_height: float = 30.0, camera=None, library=None):
    """Threshold maximising F1 on ``n_val`` synthetic scenes of stream ``seed`` (with
    :func:`detect_cars`'s default merging); returns ``(threshold, evaluation or None)``."""
    from wirescene.predetect.ap import evaluate_detections, frame_gt
    from wirescene.synth.generate import default_camera, generate_scene, load_car_library

    if not n_val:
        return 0.0, None
    camera = default_camera() if camera is None else camera
    library = load_car_library() if library is None else library
    dets, gts = [], []
    for i in range(n_val):
        sc = generate_scene(seed, i, camera=camera, library=library, cars=cars)
        dets.append(detect_cars(sc.image, bank=bank, return_all=True, max_scale=max_scale, min_height=min_height))
        gts.append(frame_gt(sc.labels, wireframes=sc.wireframes))
    val = evaluate_detections(dets, gts)
    p, r, s = val["precision"], val["recall"], val["scores"]
    thr = 0.0
    if len(s):
        f1 = 2 * p * r / np.maximum(p + r, 1e-9)
        thr = float(s[int(np.argmax(f1))]) - 1e-6
    return thr, val


def outside_cells_zeroed(f: np.ndarray, box, width: int) -> np.ndarray:
    """Template features ``f`` ``(th, tw, 31)`` of ``box`` with the columns whose centres lie
    outside an image ``width`` px wide set to zero, as a padded pyramid
    (:func:`~wirescene.predetect.bank.pad_pyramid`) shows a window past the image's sides."""
    tw = f.shape[1]
    centres = box[0] + (np.arange(tw) + 0.5) * (box[2] - box[0]) / tw
    f[:, (centres < 0) | (centres > width)] = 0.0
    return f


def _window_features(gray, box, th: int, tw: int, truncated_windows: bool, offsets=None) -> np.ndarray:
    """``(D,)`` template features of ``box``; with ``offsets`` ``(K, 3)`` those of the window moved by
    each, ``(K, D)``, as latent placement searches it."""
    boxes = [box] if offsets is None else [moved_box(box, o, th, tw) for o in offsets]
    f = crops_features(gray, boxes, th, tw)
    if truncated_windows:
        f = np.stack([outside_cells_zeroed(fk, bk, gray.shape[1]) for fk, bk in zip(f, boxes)])
    f = f.reshape(len(boxes), -1)
    return f[0] if offsets is None else f


def alignment_offsets(*, shift: float = 0.5, scale_steps: float = 1 / 6) -> np.ndarray:
    """``(27, 3)`` offsets ``(dx, dy, ds)`` of a positive window searched by latent placement:
    ``dx, dy`` in template cells (``-shift, 0, shift``), ``ds`` in octaves (``-scale_steps, 0,
    scale_steps``: one pyramid level at 6 per octave); the unmoved window first."""
    return np.array([(dx, dy, ds) for dx in (0.0, -shift, shift) for dy in (0.0, -shift, shift)
                     for ds in (0.0, -scale_steps, scale_steps)])


def moved_box(box, offset, th: int, tw: int) -> np.ndarray:
    """``box`` (x1 y1 x2 y2) of a ``th x tw``-cell window shifted by ``offset[:2]`` cells and
    scaled about its centre by ``2 ** offset[2]``."""
    x1, y1, x2, y2 = (float(v) for v in box)
    cw, ch = (x2 - x1) / tw, (y2 - y1) / th
    cx, cy = (x1 + x2) / 2 + offset[0] * cw, (y1 + y2) / 2 + offset[1] * ch
    f = 2.0 ** offset[2]
    return np.array([cx - f * (x2 - x1) / 2, cy - f * (y2 - y1) / 2, cx + f * (x2 - x1) / 2, cy + f * (y2 - y1) / 2])


def align_positives(candidates, weights) -> list:
    """Latent placement of the positives (as DPM relabels its root windows): per configuration,
    each positive's ``(K, D)`` candidate windows (:func:`positive_features` with ``offsets``)
    reduced to the one the current template ``weights[t]`` scores highest. Returns the
    ``(n, D)`` positives :func:`fit_svms` takes."""
    out = []
    for C, w in zip(candidates, weights):
        if not len(C):
            out.append(C.reshape(0, C.shape[-1]))
            continue
        best = np.argmax(C @ np.asarray(w, np.float32).ravel(), axis=1)
        out.append(C[np.arange(len(C)), best])
    return out


def positive_features(configs, examples, gray_of, rng, *, min_height, max_pos, min_pos, max_jitter,
                      max_occluded, max_truncated, min_box_cells=None, truncated_windows: bool = False,
                      offsets=None):
    """HOG features of every configuration's positive examples.

    A car example is a positive of configuration ``c`` when it is in ``c``'s viewpoint
    bin, at least ``min_height`` px tall and, for a full-car configuration, occluded by
    less than ``max_occluded`` and truncated by at most ``max_truncated`` (a partial
    configuration needs all its vertices visible); with ``min_box_cells`` the
    configuration's box must also span ``min_box_cells`` px per template cell. At most
    ``max_pos`` are drawn at random; rare viewpoints get up to ``max_jitter`` jittered
    copies each (shift +-5%, scale +-7%) to reach about ``min_pos``. ``gray_of(example)``
    is its float grey image in [0, 1].

    ``truncated_windows``: cells of a window past the image's sides are zero
    (:func:`outside_cells_zeroed`), as detection with padded levels sees them; else they
    show the edge-replicated image.

    ``offsets``: ``(K, 3)`` moves of every window (:func:`alignment_offsets`) for latent
    placement; each positive then holds the ``(K, th * tw * N_FEAT)`` features of its moved
    windows (:func:`align_positives` picks one).

    Returns the ``(n, th * tw * N_FEAT)`` feature arrays (``(n, K, ...)`` with ``offsets``)
    and the number of examples (before jitter), one per configuration.
    """
    pos, counts = [], []
    for c in configs:
        th, tw = c.template
        cand = []
        for e in examples:
            if e.bin != c.bin or e.full_box[3] - e.full_box[1] < min_height:
                continue
            if c.vertices == FULL:
                if e.occ_frac >= max_occluded or e.truncated > max_truncated:
                    continue
            elif not e.visible[list(c.vertices)].all():
                continue
            box = config_box(e.v2d, c.vertices, e.full_box)
            if min_box_cells is not None and box[3] - box[1] < th * min_box_cells:
                continue
            cand.append((e, box))
        if len(cand) > max_pos:
            cand = [cand[k] for k in np.sort(rng.choice(len(cand), max_pos, replace=False))]
        n_jit = min(max_jitter, int(np.ceil(min_pos / len(cand))) - 1) if cand else 0
        feats, cache = [], {}
        for e, box in cand:
            key = (e.image, e.flipped)
            if key not in cache:  # examples come grouped by image: keep one image at a time
                cache.clear()
                cache[key] = gray_of(e)
            g = cache[key]
            feats.append(_window_features(g, box, th, tw, truncated_windows, offsets))
            w, h = box[2] - box[0], box[3] - box[1]
            for _ in range(max(n_jit, 0)):
                cx = (box[0] + box[2]) / 2 + rng.uniform(-0.05, 0.05) * w
                cy = (box[1] + box[3]) / 2 + rng.uniform(-0.05, 0.05) * h
                f = np.exp(rng.uniform(-0.07, 0.07))
                feats.append(_window_features(g, [cx - f * w / 2, cy - f * h / 2, cx + f * w / 2, cy + f * h / 2],
                                              th, tw, truncated_windows, offsets))
        shape = (-1, th * tw * N_FEAT) if offsets is None else (-1, len(offsets), th * tw * N_FEAT)
        pos.append(np.array(feats, np.float32).reshape(shape))
        counts.append(len(cand))
    return pos, counts


@single_threaded
def train_detector_bank(out_path, *, seed: int = 0, n_scenes: int = 200, n_partial: int = 3, bins=range(N_BINS),
                        C: float = 0.01, max_pos: int = 800, min_pos: int = 150, neg_per_image: int = 15, mining_rounds: int = 1,
                        mining_images: int = 80, hard_per_image: int = 10, n_val: int = 20,
                        min_height: float = 30.0, max_scale: float = 2.0, cars=(2, 8),
                        progress=None) -> tuple[DetectorBank, dict]:
    """Train and save the bank (``out_path``; None: do not save). Returns ``(bank, report)``."""
    from wirescene.synth.generate import default_camera, generate_scene, load_car_library

    say = progress or (lambda msg: None)
    t0 = time.time()
    rng = np.random.default_rng(seed)
    camera, library = default_camera(), load_car_library()
    W, H = camera.image_size
    bins = list(bins)

    # ---- 1. scenes and examples
    grays, car_boxes, examples = [], [], []
    for i in range(n_scenes):
        sc = generate_scene(seed, i, camera=camera, library=library, cars=cars)
        grays.append(np.round(to_gray(sc.image) * 255).astype(np.uint8))
        car_boxes.append(np.array([o.box for o in sc.labels.objects]).reshape(-1, 4))
        examples += examples_from_wireframes(sc.wireframes, sc.labels, i, W)
    say(f"{n_scenes} scenes, {len(examples)} car examples (with mirror images) [{time.time() - t0:.0f}s]")
    corr = learn_full_box_correction(examples)
    apply_full_box(examples, corr)

    # ---- 2. configurations
    configs = select_configurations(examples, n_partial=n_partial, bins=bins, min_height=min_height)
    say(f"{len(configs)} configurations: " + ", ".join(f"bin{b}:{sum(c.bin == b for c in configs)}" for b in bins))

    # ---- 3. positives
    def gray_of(e):
        g = grays[e.image].astype(np.float32) / 255.0
        return g[:, ::-1] if e.flipped else g

    pos, _ = positive_features(configs, examples, gray_of, rng, min_height=min_height, max_pos=max_pos,
                               min_pos=min_pos, max_jitter=4, max_occluded=0.2, max_truncated=0.0,
                               min_box_cells=CELL / max_scale)
    say("positives per detector: " + " ".join(str(len(p)) for p in pos) + f" [{time.time() - t0:.0f}s]")

    # ---- negatives: random windows, then hard negatives
    neg = [[] for _ in configs]
    order = rng.permutation(n_scenes)
    scales = pyramid_scales(W, H, max_scale=max_scale)
    rand_imgs = order[: min(n_scenes, mining_images)]
    for i in rand_imgs:
        pyr = feature_pyramid(grays[i], scales)
        sample_random_negatives(neg, pyr, configs, car_boxes[i], H=H, min_height=min_height,
                                per_image=neg_per_image, rng=rng)
    say("random negatives per detector: " + " ".join(str(len(n)) for n in neg) + f" [{time.time() - t0:.0f}s]")

    weights, biases = fit_svms(configs, pos, neg, C=C, seed=seed)
    say(f"initial SVMs trained [{time.time() - t0:.0f}s]")
    bank = DetectorBank(configs, weights, biases)
    for rnd, imgs in enumerate(mining_subsets(n_scenes, mining_rounds, mining_images, seed=seed)):
        n_new = np.zeros(len(configs), int)
        for i in imgs:
            pyr = feature_pyramid(grays[i], scales)
            act = score_pyramid(bank, pyr, threshold=-1.0, top_k=30, min_height=min_height, max_height=3.0 * H)
            if not len(act.det):
                continue
            ok = _overlap_frac(act.boxes, car_boxes[i]) <= 0.3
            for t in np.unique(act.det[ok]):
                sel = np.flatnonzero(ok & (act.det == t))
                sel = sel[np.argsort(-act.scores[sel])[:hard_per_image]]
                th, tw = configs[t].template
                for k in sel:
                    r, q = act.cell[k]
                    neg[t].append(pyr[act.level[k]][1][r:r + th, q:q + tw].ravel())
                n_new[t] += len(sel)
        weights, biases = fit_svms(configs, pos, neg, C=C, seed=seed)
        bank = DetectorBank(configs, weights, biases)
        say(f"mining round {rnd + 1}: {int(n_new.sum())} hard negatives (per detector {n_new.min()}..{n_new.max()}) "
            f"[{time.time() - t0:.0f}s]")
    t_train = time.time() - t0

    # ---- 4. threshold on held-out scenes
    thr, val = calibrate_threshold(bank, seed=seed + 1, n_val=n_val, cars=cars, max_scale=max_scale,
                                   min_height=min_height, camera=camera, library=library)
    if val is not None:
        say(f"validation ({n_val} scenes, seed {seed + 1}): AP {val['ap']:.3f}, threshold {thr:.3f}")
    bank.threshold = thr
    bank.meta = {
        "trained_on": "synthetic scenes (wirescene.synth.generate_scene)",
        "seed": int(seed), "n_scenes": int(n_scenes), "n_partial": int(n_partial), "bins": bins, "C": C,
        "mining_rounds": int(mining_rounds), "mining_images": int(mining_images),
        "n_positives": [int(len(p)) for p in pos], "n_negatives": [int(len(n)) for n in neg],
        "full_box_correction": np.round(corr, 5).tolist(), "train_seconds": round(t_train, 1),
        "validation": None if val is None else {"n_scenes": n_val, "seed": seed + 1, **summary(val)},
    }
    if out_path is not None:
        bank.save(out_path)
        say(f"saved {len(bank)} detectors to {out_path} ({Path(out_path).stat().st_size / 1e6:.2f} MB)")
    report = dict(bank.meta, n_detectors=len(bank), names=[c.name for c in configs],
                  total_seconds=round(time.time() - t0, 1))
    return bank, report
