"""Training of the part detector (paper Sec. 5.1) and its localisation benchmark.

Three data sources (all deterministic given ``seed``):

* **Real KITTI frames** (``kitti_root``, :func:`wirescene.training.parts_real.make_real_patch_data`):
  the scaled mean wireframe at each labelled pose, ray-cast visibility, mirrored copies.
  The shipped model: real frames + 100 synthetic scenes, descriptor ``"ghog_ms"`` with the
  box-relative position, per-part calibration on held-out real patches
  (:func:`heldout_calibration`), response maps smoothed by 1/16 of the box height
  (``benchmarks/bench_real.py`` measures each choice, 4-fold cross-validated by drive).
* **Synthetic shaded scenes** (:func:`make_synth_patch_data`): patches of
  ``wirescene synth`` scenes of the training stream (seed >= :data:`SYNTH_TRAIN_SEED`),
  described exactly as at test time (:func:`wirescene.parts.detector.box_descriptors`: the full
  image, the car's 2D box, box-relative scale), positives at visible GT vertices,
  background in the padded car boxes away from vertices and outside the cars. With the
  grey-image descriptor ``"ghog"`` this was the first shipped model (synthetic only: on
  real frames 4% / 18% of the vertices within 4% / 10% of the car length).
* **CAD edge renderings** (``n_views > 0``; edge-map descriptors only), as follows.

* **Part patches** -- every road-car CAD model (:func:`wirescene.cad.training.load_cad_meshes`)
  rendered (:func:`wirescene.render.render`, edge images) from ``n_azimuth`` azimuths x
  the paper's 2 elevations (72 x 2 by default); patches around the projected *visible*
  annotated vertices (:func:`wirescene.render.project_landmarks`). The rendering is
  resampled so that the car's 2D box height is ``CANONICAL_HEIGHT`` px
  (:mod:`wirescene.parts.features`). ``n_aug`` augmented copies per view: scale jitter
  (+-15%), rotation (+-6 deg), Gaussian blur, edge dropout and random clutter lines.
* **Background patches** -- (a) rendered non-part patches: points near the car whose
  distance to every visible vertex is at least 0.2 x the car height; (b) real image
  patches from scikit-image's bundled sample photographs (no cars, no download), Canny
  edges at random scales; (c) procedural street-like line drawings (long horizontal /
  vertical lines, rectangles, arcs, specks); (d) optionally car-free regions of KITTI
  frames (``kitti_background``: a KITTI root), outside every labelled box. Off by
  default: the bundled KITTI frames are also the evaluation frames.

Evaluation: leave-models-out (``heldout`` cars, never seen in training), per-part
accuracy of the 37-way classification; and :func:`localisation` (the metric that
matters): does the arg-max of ``log(S_j / S_b)`` in the box land on the vertex, on
held-out synthetic scenes (:func:`synth_eval_frames`) and real KITTI frames
(:func:`kitti_eval_frames`, evaluation only) -- see ``benchmarks/bench_parts.py``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Mapping

import numpy as np
from scipy.ndimage import gaussian_filter

from wirescene.core.errors import ArgumentError
from wirescene.core.labels import CAR_TYPES
from wirescene.io.wireframes import wireframe_gt_path
from wirescene.parts import features as feat
from wirescene.parts.detector import BACKGROUND, N_PARTS, PartDetector
from wirescene.training.patches import PatchCollector, PatchData, _rng

__all__ = ["PatchData", "render_views", "make_patch_data", "make_synth_patch_data", "heldout_accuracy",
           "localisation", "scene_frames", "fit_detector", "design_matrix", "calibrate", "raw_log_ratio", "synth_eval_frames", "kitti_eval_frames", "train_part_detector",
           "SYNTH_TRAIN_SEED"]

RENDER_SIZE = (320, 256)
RENDER_FIELD_WIDTH = 7.25  # metres across the image at 10 m: car height ~ 80 px
ELEVATIONS = (7.5, 15.0)
REAL_BG_IMAGES = ("camera", "astronaut", "coffee", "chelsea", "rocket", "brick", "grass", "gravel",
                  "page", "text", "coins", "moon")


def render_views(names, meshes, landmarks, views, progress=None):
    """Yield ``(car index, view index, edges (H, W) bool, uv (36, 2), visible (36,), bbox)``."""
    from wirescene.render import project_landmarks, render

    for ci, name in enumerate(names):
        V, F = meshes[name]
        t0 = time.time()
        for vi, view in enumerate(views):
            r = render(V, F, view.camera, view.location, view.R)
            if not r.mask.any():
                continue
            uv, _, vis = project_landmarks(landmarks[name], V, F, view.camera, view.location, view.R)
            rows = np.nonzero(r.mask.any(1))[0]
            cols = np.nonzero(r.mask.any(0))[0]
            bbox = np.array([cols[0], rows[0], cols[-1] + 1, rows[-1] + 1], dtype=float)
            yield ci, vi, r.edges, uv, vis, bbox
        if progress:
            progress(f"rendered {name}: {len(views)} views in {time.time() - t0:.1f} s")


def _augment_map(edges, z, rng, *, rotate=True):
    """Canonical map of a native edge image with dropout, clutter, rotation, blur.
    Returns (map, transform uv_native -> (row, col) canonical)."""
    from skimage.draw import line
    from skimage.transform import rotate as sk_rotate

    e = edges.astype(np.float32).copy()
    H, W = e.shape
    # edge dropout
    if rng.random() < 0.5:
        e *= rng.random(e.shape) > rng.uniform(0.0, 0.25)
    # clutter: random short lines
    for _ in range(rng.integers(0, 6)):
        r0, c0 = rng.integers(0, H), rng.integers(0, W)
        ang, ln = rng.uniform(0, np.pi), rng.uniform(5, 40)
        r1 = int(np.clip(r0 + ln * np.sin(ang), 0, H - 1))
        c1 = int(np.clip(c0 + ln * np.cos(ang), 0, W - 1))
        rr, cc = line(r0, c0, r1, c1)
        e[rr, cc] = 1.0
    cmap = feat.canonical_edges(e, z, blur=float(rng.uniform(0.0, 0.8)) if rng.random() < 0.5 else 0.0)
    theta = float(rng.uniform(-6, 6)) if rotate else 0.0
    ch, cw = cmap.shape
    centre = np.array([(ch - 1) / 2, (cw - 1) / 2])
    if theta:
        cmap = sk_rotate(cmap, theta, order=1, mode="constant", preserve_range=True).astype(np.float32)
    # skimage rotates counter-clockwise by theta (in the displayed image, y down)
    t = np.deg2rad(theta)
    # point (row, col) -> rotated: in (x=col, y=row) coordinates a CCW rotation on screen
    rot = np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])  # acting on (x, y - centre)

    def to_map(uv):
        rc = feat.to_canonical(uv, z)
        xy = np.stack([rc[..., 1] - centre[1], rc[..., 0] - centre[0]], -1)
        xy = xy @ rot.T
        return np.stack([xy[..., 1] + centre[0], xy[..., 0] + centre[1]], -1)

    return cmap, to_map


def _describe(cmap, points, kinds):
    pts = np.rint(points).astype(np.int64)
    patches = feat.extract_patches(cmap, pts)
    return {k: feat.extract(patches, k) for k in kinds}


def _real_bg_images():
    import skimage.data as sd

    out = []
    for name in REAL_BG_IMAGES:
        try:
            im = getattr(sd, name)()
        except Exception:  # pragma: no cover - sample missing in this scikit-image
            continue
        out.append(feat.image_edges(im))
    return out


def _procedural_bg(rng, size=(240, 320)):
    from skimage.draw import circle_perimeter_aa, line, rectangle_perimeter

    H, W = size
    e = np.zeros(size, dtype=np.float32)
    for _ in range(rng.integers(2, 12)):
        kind = rng.integers(0, 4)
        if kind == 0:  # long near-horizontal / vertical line
            if rng.random() < 0.5:
                r0 = rng.integers(0, H)
                r1 = int(np.clip(r0 + rng.normal(0, 15), 0, H - 1))
                rr, cc = line(r0, 0, r1, W - 1)
            else:
                c0 = rng.integers(0, W)
                c1 = int(np.clip(c0 + rng.normal(0, 8), 0, W - 1))
                rr, cc = line(0, c0, H - 1, c1)
            e[rr, cc] = 1
        elif kind == 1:  # rectangle
            r0, c0 = rng.integers(0, H - 10), rng.integers(0, W - 10)
            rr, cc = rectangle_perimeter((r0, c0), extent=(rng.integers(5, 80), rng.integers(5, 120)), shape=size)
            e[rr, cc] = 1
        elif kind == 2:  # arc / circle
            rr, cc, _ = circle_perimeter_aa(rng.integers(0, H), rng.integers(0, W), rng.integers(3, 50), shape=size)
            e[rr, cc] = 1
        else:  # random oblique segment
            r0, c0, r1, c1 = rng.integers(0, H), rng.integers(0, W), rng.integers(0, H), rng.integers(0, W)
            rr, cc = line(r0, c0, r1, c1)
            e[rr, cc] = 1
    e[rng.random(size) < rng.uniform(0, 0.02)] = 1  # specks
    return e


def _kitti_bg(root, rng, n, kinds):
    from wirescene.io.kitti import KittiDataset

    ds = KittiDataset(root)
    out = []
    ids = ds.frame_ids()
    per = int(np.ceil(n / max(len(ids), 1)))
    for fid in ids:
        img = ds.image(fid)
        edges = feat.image_edges(img)
        H, W = edges.shape
        blocked = np.zeros((H, W), bool)
        lab = ds.labels(fid)
        for o in list(lab.objects) + list(lab.dontcare):
            x1, y1, x2, y2 = o.box
            blocked[int(max(y1, 0)):int(min(np.ceil(y2), H)), int(max(x1, 0)):int(min(np.ceil(x2), W))] = True
        for _ in range(max(1, per // 20)):
            z = feat.CANONICAL_HEIGHT / rng.uniform(30, 150)
            cmap = feat.canonical_edges(edges, z)
            rad = int(np.ceil(feat.RADIUS / z)) + 1
            from scipy.ndimage import binary_dilation
            bad = binary_dilation(blocked, iterations=rad) if blocked.any() else blocked
            cand = np.argwhere(~bad[rad:H - rad, rad:W - rad]) + rad
            if not len(cand):
                continue
            pick = cand[rng.choice(len(cand), size=min(20, len(cand)), replace=False)]
            pts = feat.to_canonical(pick[:, ::-1].astype(float), z)
            out.append(_describe(cmap, pts, kinds))
    return out


def make_patch_data(*, seed: int = 0, n_azimuth: int = 72, elevations=ELEVATIONS, cars=None, kinds=("sc",),
                    n_aug: int = 2, bg_per_map: int = 6, n_real_bg: int | None = None,
                    kitti_background=None, progress=None) -> PatchData:
    """Generate descriptors of part and background patches (see module docstring)."""
    from wirescene.cad.training import load_cad_landmarks, load_cad_meshes
    from wirescene.render import view_camera

    meshes = load_cad_meshes()
    landmarks = load_cad_landmarks()
    names = sorted(meshes) if cars is None else list(cars)
    views = [view_camera(360.0 * k / n_azimuth, float(el), image_size=RENDER_SIZE, field_width=RENDER_FIELD_WIDTH)
             for el in elevations for k in range(int(n_azimuth))]
    Xs = {k: [] for k in kinds}
    ys, gs = [], []
    min_dist = 0.2 * feat.CANONICAL_HEIGHT

    def add(d, y, g):
        n = len(y)
        if n == 0:
            return
        for k in kinds:
            Xs[k].append(d[k])
        ys.append(np.asarray(y, dtype=np.int16))
        gs.append(np.full(n, g, dtype=np.int16))

    all_names = sorted(meshes)
    for ci, vi, edges, uv, vis, bbox in render_views(names, meshes, landmarks, views, progress):
        gidx = all_names.index(names[ci])
        rng = _rng(seed, 1, gidx, vi)
        h = bbox[3] - bbox[1]
        for a in range(n_aug):
            z = feat.CANONICAL_HEIGHT / h * float(np.exp(rng.uniform(-0.15, 0.15))) if a else feat.CANONICAL_HEIGHT / h
            cmap, to_map = _augment_map(edges, z, rng, rotate=a > 0)
            pts = to_map(uv)
            ok = vis & (pts[:, 0] >= 0) & (pts[:, 1] >= 0) & (pts[:, 0] < cmap.shape[0]) & (pts[:, 1] < cmap.shape[1])
            j = np.nonzero(ok)[0]
            add(_describe(cmap, pts[j], kinds), j, gidx)
            # rendered non-part background near the car
            corners = to_map(np.array([[bbox[0], bbox[1]], [bbox[2], bbox[3]]]))
            lo = np.maximum(corners.min(0) - feat.RADIUS, 0)
            hi = np.minimum(corners.max(0) + feat.RADIUS, np.array(cmap.shape) - 1)
            cand = rng.uniform(lo, hi, size=(bg_per_map * 4, 2))
            if len(j):
                dist = np.linalg.norm(cand[:, None] - pts[None, j], axis=-1).min(1)
                cand = cand[dist >= min_dist]
            cand = cand[:bg_per_map]
            add(_describe(cmap, cand, kinds), np.full(len(cand), BACKGROUND), gidx)
    n_part = int(sum((y < N_PARTS).sum() for y in ys))
    n_real = int(0.5 * n_part) if n_real_bg is None else int(n_real_bg)
    # real photographs (skimage samples) and procedural drawings, half each
    rng = _rng(seed, 2)
    real = _real_bg_images()
    per_map = 30
    n_done = 0
    while n_done < n_real:
        if real and rng.random() < 0.5:
            e = real[rng.integers(len(real))].astype(np.float32)
            z = float(np.exp(rng.uniform(np.log(0.3), np.log(1.5))))
        else:
            e = _procedural_bg(rng)
            z = float(np.exp(rng.uniform(np.log(0.5), np.log(1.5))))
        cmap = feat.canonical_edges(e, z)
        pts = rng.uniform([0, 0], np.array(cmap.shape) - 1, size=(per_map, 2))
        add(_describe(cmap, pts, kinds), np.full(per_map, BACKGROUND), -1)
        n_done += per_map
    if kitti_background is not None:
        for d in _kitti_bg(kitti_background, _rng(seed, 3), max(n_real // 4, 100), kinds):
            add(d, np.full(len(next(iter(d.values()))), BACKGROUND), -1)
    X = {k: np.concatenate(v).astype(np.float32) for k, v in Xs.items()}
    return PatchData(X=X, y=np.concatenate(ys).astype(np.int64), group=np.concatenate(gs).astype(np.int64),
                     names=all_names)


def _fit(X, y, *, n_trees, max_depth, seed, n_jobs=1, class_weight=None, min_samples_leaf=2):
    from sklearn.ensemble import RandomForestClassifier

    rf = RandomForestClassifier(n_estimators=n_trees, max_depth=max_depth, random_state=seed, n_jobs=n_jobs,
                                min_samples_leaf=min_samples_leaf, max_features="sqrt", class_weight=class_weight)
    rf.fit(X, y)
    return rf


def design_matrix(data: PatchData, kind: str, *, position: bool = False, context: bool = False) -> np.ndarray:
    """The forest's inputs: the ``kind`` descriptors, the box context if ``context``, the
    box position if ``position`` (the order of :func:`wirescene.parts.detector.box_descriptors`)."""
    X = data.X[kind]
    if context:
        if data.ctx is None:
            raise ValueError("these patches carry no box context")
        X = np.concatenate([X, data.ctx.astype(np.float32)], axis=1)
    if position:
        if data.pos is None:
            raise ValueError("these patches carry no box positions")
        X = np.concatenate([X, data.pos.astype(np.float32)], axis=1)
    return X


def fit_detector(data: PatchData, *, kind: str, position: bool = False, context: bool = False, smooth: float = 0.0,
                 n_trees: int = 30, max_depth: int = 13,
                 seed: int = 0, min_samples_leaf: int = 2, class_weight: str | None = "balanced", n_jobs: int = 1,
                 meta: dict | None = None) -> PartDetector:
    """Fit the forest on the ``kind`` descriptors of ``data`` (plus the box position if
    ``position``) and export it."""
    rf = _fit(design_matrix(data, kind, position=position, context=context), data.y, n_trees=n_trees, max_depth=max_depth,
              seed=seed, n_jobs=n_jobs, class_weight=class_weight, min_samples_leaf=min_samples_leaf)
    det = PartDetector.from_sklearn(rf, kind=kind, meta=meta, position=position, context=context)
    det.smooth = float(smooth)
    return det


def heldout_accuracy(data: PatchData, heldout_names, *, kind="sc", n_trees=30, max_depth=13, seed=0,
                     n_jobs=1) -> dict:
    """Leave-models-out accuracy: train on all cars but ``heldout_names`` (+ 80% of the
    non-rendered background), test on the held-out cars' patches (+ the other 20%).

    Returns ``{"per_part": (36,), "background": float, "mean_part": float,
    "mean_part_mirror": float (left/right confusions forgiven), "n_test": int}``.
    """
    from wirescene.core.wireframe import MIRROR

    hold = [data.names.index(n) for n in heldout_names]
    rng = _rng(seed, 4)
    other = data.group < 0
    test_other = other & (rng.random(len(data.y)) < 0.2)
    test = np.isin(data.group, hold) | test_other
    train = ~test
    rf = _fit(data.X[kind][train], data.y[train], n_trees=n_trees, max_depth=max_depth, seed=seed, n_jobs=n_jobs)
    det = PartDetector.from_sklearn(rf, kind=kind)
    pred = det.predict(data.X[kind][test])
    yt = data.y[test]
    per_part = np.array([np.mean(pred[yt == j] == j) if (yt == j).any() else np.nan for j in range(N_PARTS)])
    mirror = np.append(np.asarray(MIRROR), BACKGROUND)
    ok_m = (pred == yt) | (pred == mirror[yt])
    per_part_m = np.array([np.mean(ok_m[yt == j]) if (yt == j).any() else np.nan for j in range(N_PARTS)])
    bg = yt == BACKGROUND
    return {"per_part": per_part, "per_part_mirror": per_part_m, "background": float(np.mean(pred[bg] == BACKGROUND)),
            "bg_rendered": float(np.mean(pred[bg & (data.group[test] >= 0)] == BACKGROUND)),
            "part_as_bg": float(np.mean(pred[~bg] == BACKGROUND)),
            "mean_part": float(np.nanmean(per_part)), "mean_part_mirror": float(np.nanmean(per_part_m)),
            "n_test": int(test.sum()), "n_train": int(train.sum())}


SYNTH_TRAIN_SEED = 1000
"""Synthetic scene streams with seed >= 1000 are for training; evaluation uses seeds < 1000."""


def _visible_uv(car):
    uv = np.asarray(car["vertices_2d"], dtype=float)
    vis = np.array([r == "visible" for r in car["visibility"]])
    return uv, vis


def make_synth_patch_data(*, n_scenes: int, seed: int = SYNTH_TRAIN_SEED, kinds=("ghog",), sample_seed: int = 0,
                          scale_samples: int = 2, n_jitter: int = 2, jitter: float = 2.0, bg_per_car: int = 40,
                          bg_boxes: int = 4, bg_per_box: int = 15, min_box_h: float = 20.0, min_dist: float = 6.0,
                          augment: bool = False, cache_dir=None, progress=None) -> PatchData:
    """Patches of synthetic *shaded* scenes (:func:`wirescene.synth.generate.generate_scene`
    ``(seed, i)``, ``i < n_scenes``), described exactly as at test time
    (:func:`wirescene.parts.detector.box_descriptors`: the car's 2D label box, box-relative scale):

    * parts: every visible vertex (``visibility == "visible"``) of every car whose box is
      at least ``min_box_h`` px high, at ``scale_samples`` scales ``s ~ exp(U(-0.2, 0.2))``
      (assumed object height ``s x`` box height, as the test-time scales), plus
      ``n_jitter`` copies displaced by up to ``jitter`` canonical px;
    * background in the box: ``bg_per_car`` points of the padded box at least
      ``min_dist`` canonical px from every visible vertex of every car;
    * background outside cars: ``bg_boxes`` random box-like windows (height 25..150 px,
      aspect 2.5) per scene, ``bg_per_box`` points each outside every padded car box.

    ``augment``: photometric augmentation of each scene image before description (with
    probability 0.7: Gaussian blur sigma 0.3..1.2 px, gamma, contrast, extra sensor noise)
    towards real camera images.

    ``group`` is the scene index. Deterministic given ``seed``, ``sample_seed``.

    ``cache_dir``: keep the patches in an ``.npz`` there, named by every argument above, and
    read them back instead of rendering when present (the same scenes serve every fold).
    """
    from wirescene.synth.generate import generate_scene, load_car_library

    if seed < SYNTH_TRAIN_SEED:
        raise ValueError(f"synthetic training scenes must use seeds >= {SYNTH_TRAIN_SEED} (lower ones are evaluation)")
    args = dict(n_scenes=n_scenes, seed=seed, kinds=list(kinds), sample_seed=sample_seed, scale_samples=scale_samples,
                n_jitter=n_jitter, jitter=jitter, bg_per_car=bg_per_car, bg_boxes=bg_boxes, bg_per_box=bg_per_box,
                min_box_h=min_box_h, min_dist=min_dist, augment=augment)
    cache = None if cache_dir is None else synth_cache_path(cache_dir, args)
    if cache is not None and cache.is_file():
        return load_patch_data(cache)
    library = load_car_library()
    patches = PatchCollector(kinds)
    add = patches.add
    t0 = time.time()

    for i in range(int(n_scenes)):
        sc = generate_scene(seed, i, library=library)
        img = sc.image
        H, W = img.shape[:2]
        rng = _rng(sample_seed, 5, seed, i)
        if augment:
            img = _photometric(img, _rng(sample_seed, 6, seed, i))
        edges = feat.image_edges(img) if any(k in feat.EDGE_KINDS for k in kinds) else None
        cars = sc.wireframes["cars"]
        all_vis = [_visible_uv(c) for c in cars]
        vis_pts = np.concatenate([uv[v] for uv, v in all_vis] + [np.zeros((0, 2))])
        boxes = np.array([c["box"] for c in cars]).reshape(-1, 4)
        for (uv, vis), box in zip(all_vis, boxes):
            bw, bh = box[2] - box[0], box[3] - box[1]
            if bh < min_box_h:
                continue
            j = np.nonzero(vis)[0]
            for _ in range(scale_samples):
                s = float(np.exp(rng.uniform(-0.2, 0.2)))
                z = feat.CANONICAL_HEIGHT / (s * bh)
                if len(j):
                    pts = [uv[j]] + [uv[j] + rng.uniform(-jitter, jitter, (len(j), 2)) / z for _ in range(n_jitter)]
                    add(img, box, np.concatenate(pts), np.tile(j, 1 + n_jitter), s, edges, i)
                lo = box[:2] - 0.1 * np.array([bw, bh])
                hi = box[2:] + 0.1 * np.array([bw, bh])
                cand = rng.uniform(lo, hi, size=(bg_per_car * 3, 2))
                if len(vis_pts):
                    d = np.linalg.norm(cand[:, None] - vis_pts[None], axis=-1).min(1)
                    cand = cand[d * z >= min_dist]
                add(img, box, cand[:bg_per_car], BACKGROUND, s, edges, i)
        # background outside the cars
        grown = np.concatenate([boxes[:, :2] - 0.1 * (boxes[:, 2:] - boxes[:, :2]),
                                boxes[:, 2:] + 0.1 * (boxes[:, 2:] - boxes[:, :2])], axis=1)
        for _ in range(bg_boxes):
            h = float(np.exp(rng.uniform(np.log(25), np.log(150))))
            cx, cy = rng.uniform(0, W), rng.uniform(0, H)
            fake = np.array([cx - 1.25 * h, cy - h / 2, cx + 1.25 * h, cy + h / 2])
            cand = rng.uniform(fake[:2], fake[2:], size=(bg_per_box * 3, 2))
            cand = cand[(cand[:, 0] >= 0) & (cand[:, 1] >= 0) & (cand[:, 0] < W) & (cand[:, 1] < H)]
            if len(grown):
                inside = ((cand[:, None, 0] >= grown[None, :, 0]) & (cand[:, None, 0] <= grown[None, :, 2])
                          & (cand[:, None, 1] >= grown[None, :, 1]) & (cand[:, None, 1] <= grown[None, :, 3])).any(1)
                cand = cand[~inside]
            add(img, fake, cand[:bg_per_box], BACKGROUND, 1.0, edges, i)
        if progress and (i + 1) % 50 == 0:
            progress(f"synthetic scenes: {i + 1}/{n_scenes} in {time.time() - t0:.0f} s")
    data = patches.data([])
    if cache is not None:
        save_patch_data(cache, data)
    return data


def synth_cache_path(cache_dir, args: dict) -> Path:
    """File of the synthetic patches made with ``args`` in ``cache_dir`` (name: a hash of
    the arguments and of the package version, so a new renderer never reads old patches)."""
    import hashlib
    import json

    from wirescene.core.version import __version__

    key = hashlib.sha256(json.dumps({**args, "version": __version__}, sort_keys=True).encode()).hexdigest()[:16]
    return Path(cache_dir) / f"synth_patches_{key}.npz"


def save_patch_data(path, data: PatchData) -> Path:
    """Write :class:`PatchData` as a versioned ``.npz`` (no pickles)."""
    from wirescene.core.artefacts import save_npz

    arrays = {f"X_{k}": v for k, v in data.X.items()}
    arrays.update(y=data.y, group=data.group, names=np.array(list(data.names), dtype=str))
    for name in ("pos", "ctx"):
        if getattr(data, name) is not None:
            arrays[name] = getattr(data, name)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return save_npz(path, arrays, kind="patches", version=1)


def load_patch_data(path) -> PatchData:
    """:class:`PatchData` written by :func:`save_patch_data`."""
    from wirescene.core.artefacts import load_npz

    z = load_npz(path, kind="patches", version=1)
    return PatchData({k[2:]: v for k, v in z.items() if k.startswith("X_")}, z["y"], z["group"],
                     z["names"].tolist(), z.get("pos"), z.get("ctx"))


def _photometric(img, rng):
    if rng.random() >= 0.7:
        return img
    x = img.astype(np.float32) / 255.0
    x = gaussian_filter(x, (rng.uniform(0.3, 1.2),) * 2 + (0,))
    x = np.clip(x, 0, 1) ** float(np.exp(rng.uniform(-0.3, 0.3)))
    x = 0.5 + (x - 0.5) * rng.uniform(0.6, 1.1)
    x = x + rng.normal(0, rng.uniform(0, 4) / 255.0, x.shape)
    return np.clip(np.rint(x * 255), 0, 255).astype(np.uint8)


def _merge(a: PatchData, b: PatchData, *, group_b=None) -> PatchData:
    """``a`` then ``b``; ``b``'s groups become ``group_b`` (default -2: "not a group of a")."""
    kinds = [k for k in a.X if k in b.X]
    pos = None if a.pos is None or b.pos is None else np.concatenate([a.pos, b.pos])
    ctx = None if a.ctx is None or b.ctx is None else np.concatenate([a.ctx, b.ctx])
    gb = np.full(len(b.y), -2) if group_b is None else np.broadcast_to(group_b, (len(b.y),))
    return PatchData(X={k: np.concatenate([a.X[k], b.X[k]]) for k in kinds}, y=np.concatenate([a.y, b.y]),
                     group=np.concatenate([a.group, gb]), names=a.names, pos=pos, ctx=ctx)


def localisation(detector, frames, *, radii=(0.04, 0.10), **response_kwargs) -> dict:
    """Localisation of the part evidence (the metric that matters for the likelihood).

    ``frames``: iterable of ``(image, cars)``, ``cars`` a list of ``(box (4,), uv (36, 2),
    visible (36,) bool)`` or ``(box, uv, visible, tags)`` with ``tags`` a tuple of subset
    names the car belongs to. For every visible vertex inside its box: is the top-scoring
    grid location of ``log(S_j / S_b)`` inside the box within ``r`` x the car's projected
    length (max extent of the 36 projected vertices) of the vertex, for ``r`` in
    ``radii``; chance = a uniformly random grid location of the box; and the percentile
    rank of the vertex location's score among the box's locations (chance 0.5).

    Returns ``{"hits": {r: frac}, "chance": {r: frac}, "rank": float, "n_vertices", "n_cars",
    "t_maps_s", "by_tag": {tag: the same figures over that tag's cars}}``.
    """
    from wirescene.parts.detector import response_maps

    acc = {}

    def bucket(tag):
        return acc.setdefault(tag, {"hits": {r: [] for r in radii}, "chance": {r: [] for r in radii},
                                    "ranks": [], "n_cars": 0})

    t_maps = 0.0
    for image, cars in frames:
        if not cars:
            continue
        t = time.perf_counter()
        R = response_maps(image, np.array([c[0] for c in cars], dtype=float), detector=detector, **response_kwargs)
        t_maps += time.perf_counter() - t
        for bi, car in enumerate(cars):
            box, uv, visible = car[:3]
            buckets = [bucket(None)] + [bucket(tg) for tg in (car[3] if len(car) > 3 else ())]
            x1, y1, x2, y2 = box
            inbox = (uv[:, 0] >= x1) & (uv[:, 0] <= x2) & (uv[:, 1] >= y1) & (uv[:, 1] <= y2)
            vis = np.asarray(visible, bool) & inbox
            length = max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1]))
            b = R.boxes[bi]
            g = b.grid_uv().reshape(-1, 2)
            m = (g[:, 0] >= x1) & (g[:, 0] <= x2) & (g[:, 1] >= y1) & (g[:, 1] <= y2)
            g = g[m]
            lr = b.log_ratio.reshape(-1, N_PARTS)[m]
            for bk in buckets:
                bk["n_cars"] += 1
            at_all = R.log_ratio(uv, bi)
            for j in np.nonzero(vis)[0]:
                best = g[np.argmax(lr[:, j])]
                d_all = np.linalg.norm(g - uv[j], axis=1)
                at = at_all[j]
                rank = np.mean(lr[:, j] < at) + 0.5 * np.mean(lr[:, j] == at)
                for bk in buckets:
                    for r in radii:
                        bk["hits"][r].append(np.linalg.norm(best - uv[j]) <= r * length)
                        bk["chance"][r].append(np.mean(d_all <= r * length))
                    bk["ranks"].append(rank)
    mean = lambda v: float(np.mean(v)) if len(v) else float("nan")  # noqa: E731

    def summary(bk):
        return {"hits": {r: mean(v) for r, v in bk["hits"].items()},
                "chance": {r: mean(v) for r, v in bk["chance"].items()}, "rank": mean(bk["ranks"]),
                "n_vertices": len(bk["ranks"]), "n_cars": bk["n_cars"], "t_maps_s": t_maps}

    out = summary(bucket(None))
    out["by_tag"] = {tg: summary(bk) for tg, bk in acc.items() if tg is not None}
    return out


def _clean_cars(wire_cars, min_box_h, clean):
    cars = []
    for c in wire_cars:
        box = np.asarray(c["box"], float)
        if box[3] - box[1] < min_box_h or (clean and (c["occluded"] != 0 or c["truncated"] > 1e-9)):
            continue
        cars.append((box, np.asarray(c["vertices_2d"], float), np.array([r == "visible" for r in c["visibility"]])))
    return cars


def scene_frames(scenes, *, min_box_h: float = 40.0, clean: bool = True):
    """``(image, cars)`` of in-memory :class:`wirescene.synth.generate.SyntheticScene` s
    for :func:`localisation` (same selection as :func:`synth_eval_frames`)."""
    for sc in scenes:
        yield sc.image, _clean_cars(sc.wireframes["cars"], min_box_h, clean)


def synth_eval_frames(root, *, split: str = "training", min_box_h: float = 40.0, clean: bool = True):
    """``(image, cars)`` of a ``wirescene synth`` output directory for :func:`localisation`:
    cars with ``occluded == 0``, ``truncated == 0`` and box height >= ``min_box_h``
    (``clean``), visible = visibility ``"visible"``."""
    import json

    from PIL import Image

    d = Path(root) / split
    for img_path in sorted((d / "image_2").glob("*.png")):
        fid = img_path.stem
        wf = json.loads(wireframe_gt_path(d, fid).read_text())
        cars = _clean_cars(wf["cars"], min_box_h, clean)
        yield np.asarray(Image.open(img_path).convert("RGB")), cars


def kitti_eval_frames(root, *, min_box_h: float = 40.0, clean: bool = True, frames=None):
    """``(image, cars)`` of real KITTI frames for :func:`localisation`: the mean wireframe
    placed at each ``Car`` label's pose (location = the label's bottom centre), visibility
    by :func:`wirescene.infer.occlusion.self_occlusion`; ``frames``: the ids to read (default
    all of ``root``). EVALUATION ONLY: never train on these."""
    from wirescene.core import wireframe
    from wirescene.core.groundplane import rotation_y, transform
    from wirescene.core.shape import load_default
    from wirescene.infer.occlusion import self_occlusion
    from wirescene.io.kitti import KittiDataset

    ds = KittiDataset(root)
    mean = load_default().mean
    for fid in ds.frame_ids() if frames is None else frames:
        cam = ds.camera(fid)
        cars = []
        for o in ds.labels(fid).of_type(*CAR_TYPES):
            box = np.asarray(o.box, float)
            if box[3] - box[1] < min_box_h or (clean and (o.occluded != 0 or o.truncated > 1e-9)):
                continue
            X = transform(mean, np.asarray(o.location, float), rotation_y(o.rotation_y))
            uv = cam.project(X)
            cars.append((box, uv, ~self_occlusion(X, wireframe.FACES, cam.center)))
        yield ds.image(fid), cars


GREY_KINDS = feat.GREY_KINDS


def real_folds(frame_ids, folds: Mapping[str, int]) -> np.ndarray:
    """Cross-validation fold of each frame, ``folds[frame]``
    (:func:`wirescene.training.kitti_detector.calibration_folds`)."""
    return np.asarray([folds[f] for f in frame_ids], dtype=np.int64)


def heldout_calibration(real: PatchData, other: PatchData | None, *, kind: str, folds: Mapping[str, int],
                        position: bool = False, context: bool = False, progress=None, **fit_kwargs):
    """Per-class calibration (:func:`calibrate`) of a forest trained on ``real`` (+
    ``other``) from held-out scores: for each fold of the real frames
    (:func:`real_folds` of ``folds``), a forest trained without that fold's real patches
    scores them.

    Returns ``(scale, offset, report)``; the report holds the held-out balanced log loss
    of "is vertex j" before (raw ``log(S_j / S_b)`` as logit) and after calibration
    (each fold calibrated on the other folds' scores), over the folds holding a part's 5
    patches at least (a fold without cars has none to score): None where no fold does."""
    say = progress or (lambda m: None)
    folds = real_folds(real.names, folds)[real.group]
    lr = np.zeros((len(real.y), N_PARTS))
    for k in np.unique(folds):
        m = folds != k
        tr = PatchData(X={kind: real.X[kind][m]}, y=real.y[m], group=real.group[m], names=real.names,
                       pos=None if real.pos is None else real.pos[m], ctx=None if real.ctx is None else real.ctx[m])
        if other is not None:
            tr = _merge(tr, other)
        t = time.time()
        det = fit_detector(tr, kind=kind, position=position, context=context, **fit_kwargs)
        te = folds == k
        lr[te] = raw_log_ratio(det, design_matrix(real, kind, position=position, context=context)[te])
        say(f"calibration fold {k}: {int(te.sum())} held-out patches scored [{time.time() - t:.0f} s]")

    def loss(r, y, sc, of):
        """Mean balanced log loss of the parts of 5 patches at least; None where none has 5."""
        z = r * sc + of
        out = []
        for j in range(N_PARTS):
            t = y == j
            if t.sum() < 5:
                continue
            out.append(0.5 * np.mean(np.logaddexp(0, -z[t, j])) + 0.5 * np.mean(np.logaddexp(0, z[~t, j])))
        return float(np.mean(out)) if out else None

    cv = []
    for k in np.unique(folds):
        sc, of = calibrate(lr[folds != k], real.y[folds != k])
        raw = loss(lr[folds == k], real.y[folds == k], 1.0, 0.0)
        if raw is not None:  # a fold without parts to score (no car, or too few) says nothing of either loss
            cv.append((raw, loss(lr[folds == k], real.y[folds == k], sc, of), int((folds == k).sum())))
    n = sum(c[2] for c in cv)
    scale, offset = calibrate(lr, real.y)
    report = {"logloss_raw": sum(c[0] * c[2] for c in cv) / n if cv else None,
              "logloss_calibrated": sum(c[1] * c[2] for c in cv) / n if cv else None,
              "scale_mean": float(scale.mean()), "offset_mean": float(offset.mean())}
    losses = (f"{report['logloss_raw']:.3f} raw -> {report['logloss_calibrated']:.3f} calibrated" if cv else
              "not measured (no fold holds 5 patches of a part)")
    say(f"calibration: held-out balanced log loss {losses} over {len(cv)} of {len(np.unique(folds))} folds; "
        f"mean scale {scale.mean():.2f}, offset {offset.mean():.2f}")
    return scale, offset, report


#: How a training goes without the held-out calibration, said where one cannot be made.
WITHOUT_CALIBRATION = "calibrate_real=False; train parts --no-calibrate, train all --set parts.calibrate_real=false"


def _trained_images(dataset, frames, background) -> dict[str, str]:
    """The record of the real images a part model learnt from
    (:attr:`~wirescene.parts.detector.PartDetector.trained_images`), by which an evaluation on
    them says that its figures are not held out: ``frames`` of the labelled ``dataset`` (None:
    none) and every frame of the KITTI root ``background`` whose backgrounds it learnt (None:
    none); an id of both, the labelled frame's image (an evaluation reads labelled frames)."""
    from wirescene.core.resources import images_sha256
    from wirescene.io.kitti import KittiDataset

    record = {}
    if background is not None:
        other = KittiDataset(background)
        record.update(images_sha256(other.image_path, other.frame_ids()))
    if dataset is not None:
        record.update(images_sha256(dataset.image_path, frames))
    return record


def train_part_detector(out_path, *, seed: int = 0, n_views: int = 0, n_trees: int = 30,
                        max_depth: int = 13, kind: str = "ghog", n_aug: int = 2, cars=None, heldout: int = 0,
                        compare_kinds=(), kitti_background=None, synth_scenes: int = 300,
                        synth_seed: int = SYNTH_TRAIN_SEED, class_weight: str | None = "balanced",
                        min_samples_leaf: int = 2, augment: bool = False, kitti_root=None, frames=None,
                        position: bool = False, context: bool = False, calibrate_real: bool = False,
                        smooth: float = 0.0, calibration_folds: Mapping[str, int] | None = None, n_jobs: int = 1,
                        synth_cache=None, max_real_patches: int | None = 600_000, label_shapes=None,
                        progress=None):
    """Generate training patches, optionally evaluate leave-models-out, fit the forest
    on all data and write the model ``.npz``.

    Parameters
    ----------
    out_path : path or None (do not write); no default, so that a training never overwrites
        the shipped model unless asked
    seed : int -- drives augmentation, background sampling, forest
    n_views : int -- CAD edge renderings: total views per car, split evenly over the 2
        elevations (144: the paper's 72 x 2); 0: none (edge-map kinds, without position or context, only)
    n_trees, max_depth : forest size (paper: 30, 13)
    kind : descriptor of the written model (see :mod:`wirescene.parts.features`)
    n_aug : renderings per view (the first unaugmented)
    cars : list of CAD names, optional (default: all road cars)
    heldout : int -- evaluate with the last ``heldout`` cars (sorted) held out first
    compare_kinds : extra descriptor kinds evaluated held-out as well
    kitti_background : path, optional -- KITTI root for car-free background patches of the CAD
        renderings (``n_views``; every frame of it, which the model records too)
    synth_scenes : int -- synthetic shaded scenes ``generate_scene(synth_seed, i)`` whose
        patches are added (:func:`make_synth_patch_data`)
    synth_seed : int >= 1000 (training stream)
    augment : photometric augmentation of the synthetic scenes (see :func:`make_synth_patch_data`)
    class_weight : "balanced", "balanced_subsample" or None -- forest class weights; a
        balanced forest keeps ``S_j`` well above the clipping floor where part ``j`` is
        plausible, so ``log(S_j / S_b)`` peaks at the part (the background's share of the
        data no longer swamps the parts)
    kitti_root : path, optional -- labelled KITTI frames whose real patches are added
        (:func:`wirescene.training.parts_real.make_real_patch_data`); the model records their
        images' SHA-256 (:attr:`~wirescene.parts.detector.PartDetector.trained_images`)
    frames : list of frame ids, optional -- the real training frames (default: all of
        ``kitti_root``)
    position : bool -- append the box-relative position to the descriptor
    context : bool -- append the box's gradient layout (multi-scale kinds)
    smooth : float -- the model's default smoothing of its response maps (sigma in box
        heights, see :func:`wirescene.parts.detector.response_maps`)
    calibrate_real : bool -- calibrate the log ratio per class on held-out real patches
        (:func:`heldout_calibration`; needs ``kitti_root``)
    calibration_folds : dict, optional -- ``{frame: fold}`` of that calibration (default: the
        frames dealt by the shared frames' drives as ``train all`` deals them,
        :func:`wirescene.training.kitti_detector.calibration_folds`; ``train all`` and ``train
        parts`` give the folds of a devkit mapping they find or are given)
    max_real_patches : int or None -- keep at most that many real patches, a uniform
        sample of all (None: all), so that memory does not grow with the frames beyond
        it (about 0.4 kB a patch: 250 MB); the shipped model's 247,569 patches (real and
        synthetic) are below it
    label_shapes : dict, optional -- ``{frame id: (N, 36, 3)}`` wireframes of the real frames'
        ``Car`` labels (:func:`wirescene.training.parts_real.refit_label_shapes`) in place of
        the mean shape scaled into each label's box
    min_samples_leaf : int -- the forest's smallest leaf (scikit-learn's option)
    n_jobs : int -- processes of the forest's fit (scikit-learn's; -1: all cores)
    synth_cache : path, optional -- a directory where the synthetic scenes' patches are
        kept and read again by a training of the same scenes and options
    progress : callable(str), optional -- called with one line per stage

    Returns
    -------
    (PartDetector, report dict)

    Notes
    -----
    The defaults are the function's own (``kind="ghog"``, 300 synthetic scenes, no position
    or real calibration; the tests pass smaller values); the shipped model's recipe is ``train_part_detector(out, kitti_root=ROOT, **RECIPE["parts"])`` with
    :data:`wirescene.training.recipe.RECIPE`, as ``wirescene train parts`` and
    ``wirescene train all`` call it.
    """
    say = progress or (lambda s: None)
    n_az = max(1, int(n_views) // len(ELEVATIONS)) if n_views else 0
    kinds = tuple(dict.fromkeys((kind,) + tuple(compare_kinds)))
    if n_az and any(k in GREY_KINDS for k in kinds):
        raise ArgumentError("n_views", f"CAD edge renderings (--n-views) have no grey image: use n_views=0 with "
                                       f"kinds {GREY_KINDS}")
    if n_az and (position or context):  # else refused by design_matrix once every patch is made
        raise ArgumentError("n_views", "CAD edge renderings (--n-views) carry no box position or context: train "
                                       "them with position=False (--no-position) and context=False")
    if not n_az and not synth_scenes and kitti_root is None:
        raise ArgumentError("synth_scenes", "no training data: n_views and synth_scenes (--n-views, --synth-scenes) "
                                            "are both 0 and no kitti_root (KITTI_ROOT or --kitti-root) is given")
    if calibrate_real and kitti_root is None:
        raise ArgumentError("calibrate_real", "needs kitti_root (KITTI_ROOT or --kitti-root), the real labelled frames")
    if heldout and n_az:  # the held-out evaluation trains on the other cars: one at least
        from wirescene.cad.training import load_cad_meshes

        n_cars = len(load_cad_meshes()) if cars is None else len(list(cars))
        if int(heldout) >= n_cars:
            raise ArgumentError("heldout", f"holds out {int(heldout):,} of the {n_cars} CAD cars: at most "
                                           f"{n_cars - 1}, so that the evaluation's forest has a car to learn from")
    if kitti_root is not None:  # the real reason, before the folds' checks below and any patch made
        from wirescene.io.kitti import KittiDataset

        ds = KittiDataset(kitti_root)
        ds.require_labels("training")
    real_only = kitti_root is not None and not n_az and not synth_scenes
    if real_only or calibrate_real:  # checked before any patch is made
        from wirescene.training.parts_real import REAL_MAX_OCCLUDED, REAL_MIN_BOX_H, trainable_car_counts

        frames = ds.frame_ids() if frames is None else list(frames)
        car_counts = ds.car_counts(frames) if real_only else {}
        if real_only and not any(car_counts.values()):
            raise ArgumentError("frames", f"none of the {len(frames)} real training frame(s) has a labelled Car, and no "
                                          "synthetic scenes (--synth-scenes) or CAD views (--n-views) add car parts")
        if calibrate_real:  # the calibration holds out folds of the real frames
            if calibration_folds is None:  # dealt as train all deals them: by drive, balanced by their cars
                from wirescene.io.folds import drive_groups
                from wirescene.training.kitti_detector import calibration_folds as dealt_folds

                # frames of one drive: refused below, with what to do instead (a bad label file is its own error)
                one = len(set(drive_groups(frames).values())) < 2
                calibration_folds = dict.fromkeys(frames, 0) if one else dealt_folds(ds, frames)
            fold = real_folds(frames, calibration_folds)
            if len(np.unique(fold)) < 2:
                raise ArgumentError("calibrate_real", f"the held-out calibration needs real frames of 2 or more folds "
                                    f"(drives); the {len(frames)} frame(s) given fall in one: train without it "
                                    f"({WITHOUT_CALIBRATION}) or on frames of more drives")
            # real frames only, the cars in one fold: that fold's held-out forest would learn no part
            trainable = trainable_car_counts(ds, frames) if real_only else {}
            if real_only and len({k for f, k in zip(frames, fold) if trainable[f]}) < 2:
                raise ArgumentError("calibrate_real", f"the held-out calibration needs labelled cars "
                                    f"({REAL_MIN_BOX_H:g} px high or more, occlusion {REAL_MAX_OCCLUDED} or less) "
                                    f"in 2 or more folds (drives); those of the {len(frames)} frame(s) given lie in "
                                    f"one, so the forest held out from it would learn no part: train without it "
                                    f"({WITHOUT_CALIBRATION}), on frames of more drives or with synthetic scenes "
                                    "(--synth-scenes)")
    t0 = time.time()
    data = None
    report = {"cars": []}
    if n_az:
        data = make_patch_data(seed=seed, n_azimuth=n_az, cars=cars, kinds=kinds, n_aug=n_aug,
                               kitti_background=kitti_background, progress=progress)
        report["cars"] = sorted(set(data.names[g] for g in data.group[data.group >= 0]))
    if synth_scenes:
        sd = make_synth_patch_data(n_scenes=synth_scenes, seed=synth_seed, kinds=kinds, sample_seed=seed,
                                   augment=augment, cache_dir=synth_cache, progress=progress)
        data = sd if data is None else _merge(data, sd)
    real = None
    if kitti_root is not None:
        from wirescene.training.parts_real import make_real_patch_data

        frames = ds.frame_ids() if frames is None else list(frames)
        real = make_real_patch_data(kitti_root, frames, kinds=kinds, seed=seed, max_patches=max_real_patches,
                                    label_shapes=label_shapes, progress=progress)
        report["frames"] = frames
    other = data
    data = real if data is None else (data if real is None else _merge(real, data))
    t_data = time.time() - t0
    n_part = int((data.y < N_PARTS).sum())
    say(f"patches: {len(data)} ({n_part} part, {len(data) - n_part} background) in {t_data:.0f} s")
    report.update({"n_patches": len(data), "n_part": n_part, "n_background": len(data) - n_part, "t_data_s": t_data,
                   "n_azimuth": n_az, "n_real": 0 if real is None else len(real)})
    if heldout and n_az:
        names = report["cars"]
        held = names[-int(heldout):]
        report["heldout_cars"] = held
        for k in kinds:
            t1 = time.time()
            report[f"heldout_{k}"] = heldout_accuracy(data, held, kind=k, n_trees=n_trees, max_depth=max_depth,
                                                      seed=seed, n_jobs=n_jobs)
            r = report[f"heldout_{k}"]
            say(f"held-out {k}: mean part acc {r['mean_part']:.3f} (mirror-tolerant {r['mean_part_mirror']:.3f}), "
                f"background {r['background']:.3f} [{time.time() - t1:.0f} s]")
    fit_kwargs = dict(n_trees=n_trees, max_depth=max_depth, seed=seed, n_jobs=n_jobs, class_weight=class_weight,
                      min_samples_leaf=min_samples_leaf)
    cal = None
    if calibrate_real:
        cal = heldout_calibration(real, other, kind=kind, position=position, context=context, folds=calibration_folds,
                                  progress=progress, **fit_kwargs)
        report["calibration"] = cal[2]
    t1 = time.time()
    meta = {"seed": seed, "n_views": n_az * len(ELEVATIONS), "n_trees": n_trees, "max_depth": max_depth,
            "n_aug": n_aug, "n_patches": len(data), "n_part": n_part, "cars": ",".join(report["cars"]),
            "kitti_background": str(kitti_background is not None), "synth_scenes": synth_scenes,
            "synth_seed": synth_seed, "class_weight": str(class_weight), "min_samples_leaf": min_samples_leaf,
            "augment": str(augment), "real_frames": ",".join(report.get("frames", [])), "position": str(position), "context": str(context), "smooth": smooth,
            "label_shapes": str(label_shapes is not None),
            "calibrated": str(cal is not None)}
    det = fit_detector(data, kind=kind, position=position, context=context, smooth=smooth, meta=meta, **fit_kwargs)
    report["t_fit_s"] = time.time() - t1
    if cal is not None:
        det.calib_scale, det.calib_offset = cal[0], cal[1]
    det.trained_images = _trained_images(ds if kitti_root is not None else None, frames,
                                         kitti_background if n_az else None)
    X = design_matrix(data, kind, position=position, context=context)
    report["train_acc"] = float(np.mean(det.predict(X) == data.y))
    if out_path is not None:
        det.save(out_path)
        report["model_bytes"] = Path(out_path).stat().st_size
        say(f"wrote {out_path} ({report['model_bytes'] / 1e6:.1f} MB), fit {report['t_fit_s']:.0f} s")
    report["_data"] = data
    return det, report


def raw_log_ratio(detector: PartDetector, X, *, eps: float = 1e-3) -> np.ndarray:
    """Uncalibrated ``log(S_j / S_b)`` ``(N, 36)`` of forest inputs ``X``."""
    pc = np.clip(detector.predict_proba(X), eps, 1.0)
    return np.log(pc[:, :N_PARTS]) - np.log(pc[:, N_PARTS:])


def calibrate(log_ratio, y, *, reg: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """Per-class affine calibration of the part log ratio from held-out patches.

    For every part ``j`` a logistic regression of "this patch is vertex ``j``" (``y ==
    j``) against "it is anything else" (background or another part) on the raw
    ``log(S_j / S_b)``, with class-balanced weights, gives ``a_j * r + b_j``: with equal
    weight on both sides the intercept carries no prior odds, so this estimates the log
    likelihood ratio ``log p(r | vertex j) / p(r | not j)`` -- the quantity the fine
    stage's likelihood sums -- whatever the mix of the calibration patches.

    Parameters
    ----------
    log_ratio : (N, 36) -- raw log ratios of held-out patches (:func:`raw_log_ratio` of a
        forest that did not see them)
    y : (N,) int -- their labels (36 = background)
    reg : float -- L2 penalty pulling ``(a_j, b_j)`` towards ``(1, 0)`` (rare parts)

    Returns
    -------
    scale, offset : (36,) float arrays (``scale > 0``; identity where part ``j`` has
        fewer than 5 patches)
    """
    from scipy.optimize import minimize

    r = np.asarray(log_ratio, dtype=float)
    y = np.asarray(y)
    if r.ndim != 2 or r.shape[1] != N_PARTS or len(r) != len(y):
        raise ValueError(f"log_ratio must be (N, {N_PARTS}) with N = len(y)")
    scale = np.ones(N_PARTS)
    offset = np.zeros(N_PARTS)
    for j in range(N_PARTS):
        t = (y == j).astype(float)
        n1 = t.sum()
        if n1 < 5 or n1 == len(t):
            continue
        x = r[:, j]
        w = np.where(t > 0, 0.5 / n1, 0.5 / (len(t) - n1))

        def nll(p, x=x, t=t, w=w):
            z = p[0] * x + p[1]
            ll = np.logaddexp(0.0, -z) * t + np.logaddexp(0.0, z) * (1 - t)
            return float((w * ll).sum() + reg * (p[0] - 1.0) ** 2 + reg * p[1] ** 2)

        res = minimize(nll, np.array([1.0, 0.0]), method="Nelder-Mead",
                       options={"xatol": 1e-4, "fatol": 1e-8, "maxiter": 400})
        a, b = res.x
        if a > 1e-3:
            scale[j], offset[j] = a, b
    return scale, offset
