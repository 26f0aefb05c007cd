"""Real-image training data and evaluation labels for the part detectors (issue 18).

KITTI labels carry 3D boxes, not vertices. The vertex "labels" of a car are the shape
model's mean wireframe scaled per axis to the labelled ``h w l`` and placed at the
labelled pose (location = bottom centre, ``rotation_y``; the same placement as
``wirescene gt``), projected with the frame's ``P2`` camera. A vertex is *visible* when it
is neither self-occluded (ray cast against the wireframe's own faces,
:func:`wirescene.infer.occlusion.self_occlusion`) nor hidden by another labelled car's
wireframe (:func:`wirescene.infer.occlusion.inter_object_occlusion`), and it lies inside the
image. These labels are approximate (a mean shape, not the car's own), a few percent of
the car length off, which bounds what localisation figures can show.

* :func:`kitti_car_wireframes` -- the labelled wireframes of one frame;
* :func:`real_frames` -- ``(image, cars)`` for :func:`wirescene.training.parts.localisation`;
* :func:`make_real_patch_data` -- descriptors of real part and background patches, each
  car also mirrored (image flipped horizontally, vertex labels swapped left/right with
  :data:`wirescene.core.wireframe.MIRROR`), described exactly as at test time
  (:func:`wirescene.parts.detector.box_descriptors`).

Real frames used here for training must never be scored: cross-validate by drive
(:mod:`wirescene.io.folds`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.core.labels import CAR_TYPES
from wirescene.parts import features as feat
from wirescene.parts.detector import BACKGROUND
from wirescene.training.patches import PatchCollector, _rng

__all__ = [
    "LabelledCar",
    "kitti_car_wireframes",
    "make_real_patch_data",
    "mirror_cars",
    "real_frames",
    "scaled_mean_shape",
]


@dataclass
class LabelledCar:
    """One labelled car of a frame with its projected wireframe.

    box : (4,) 2D label box; uv : (36, 2) projected vertices; visible : (36,) bool;
    occluded : KITTI occlusion level; truncated : KITTI truncation; X : (36, 3) camera frame.
    """

    box: np.ndarray
    uv: np.ndarray
    visible: np.ndarray
    occluded: int
    truncated: float
    X: np.ndarray


def scaled_mean_shape(dims, mean=None) -> np.ndarray:
    """The mean wireframe ``(36, 3)`` (object frame: x forward, y down, z left), or any
    wireframes ``mean`` ``(..., 36, 3)``, scaled per axis to KITTI ``dims = (h, w, l)``
    (scaled about the object origin: the bottom centre)."""
    if mean is None:
        from wirescene.core.shape import load_default

        mean = load_default().mean
    mean = np.asarray(mean, float)
    h, w, l = np.asarray(dims, float)
    return mean * (np.array([l, h, w]) / np.ptp(mean, axis=-2))[..., None, :]


def _placed(cars, shapes) -> np.ndarray:
    """Camera-frame wireframes ``(N, 36, 3)`` of labels ``cars``: object-frame ``shapes``
    ``(N, 36, 3)`` at each label's bottom centre and ``rotation_y``."""
    from wirescene.core.groundplane import rotation_y, transform

    return np.stack([transform(x, np.asarray(o.location, float), rotation_y(o.rotation_y))
                     for x, o in zip(shapes, cars)])


def kitti_car_wireframes(labels, camera, *, image_size=None, scaled: bool = True, mean=None,
                         shapes=None) -> list:
    """:class:`LabelledCar` of every ``Car`` label of a frame.

    Parameters
    ----------
    labels : FrameLabels
    camera : Camera -- the frame's ``P2`` camera
    image_size : (W, H), optional -- vertices outside the image are not visible
    scaled : bool -- scale the mean shape to the labelled dims (else the plain mean)
    mean : (36, 3) array, optional -- the mean shape placed (default: the shipped shape
        model's)
    shapes : (N, 36, 3) array, optional -- each ``Car`` label's own wireframe in the object
        frame (e.g. :func:`refit_label_shapes`), placed instead of the mean
    """
    from wirescene.core import wireframe
    from wirescene.infer.occlusion import inter_object_occlusion, self_occlusion

    if mean is None:
        from wirescene.core.shape import load_default

        mean = load_default().mean
    cars = labels.of_type(*CAR_TYPES)
    if not cars:
        return []
    if shapes is not None:
        shapes = np.asarray(shapes, float)
        check_shape("shapes", shapes, (len(cars), 36, 3))
    else:
        shapes = [scaled_mean_shape(o.dims, mean) if scaled else np.asarray(mean, float) for o in cars]
    X = _placed(cars, shapes)
    hidden = self_occlusion(X, wireframe.FACES, camera.center)
    # Other labelled cars hide vertices too (their wireframes approximate their bodies).
    hidden |= inter_object_occlusion(X, wireframe.FACES, camera.center)
    uv, depth = camera.project_with_depth(X)
    vis = ~hidden & (depth > 0.5)
    if image_size is not None:
        W, H = image_size
        vis &= (uv[..., 0] >= 0) & (uv[..., 1] >= 0) & (uv[..., 0] <= W - 1) & (uv[..., 1] <= H - 1)
    return [LabelledCar(box=np.asarray(o.box, float), uv=uv[i], visible=vis[i], occluded=int(o.occluded),
                        truncated=float(o.truncated), X=X[i]) for i, o in enumerate(cars)]


def _usable(c, *, min_box_h: float, max_occluded: int, clean: bool) -> bool:  # a LabelledCar or a Label
    if c.box[3] - c.box[1] < min_box_h or c.occluded > max_occluded:
        return False
    return not clean or (c.occluded == 0 and c.truncated <= 1e-9)


def real_frames(root, frame_ids=None, *, min_box_h: float = 40.0, clean: bool = True, max_occluded: int = 1,
                scaled: bool = True, subsets: dict | None = None):
    """``(image, cars)`` of labelled KITTI frames for
    :func:`wirescene.training.parts.localisation`, ``cars`` a list of ``(box, uv,
    visible)``. ``clean``: only cars with occlusion 0 and truncation 0; otherwise cars
    with occlusion level <= ``max_occluded``; boxes at least ``min_box_h`` px high.

    ``subsets``: ``{name: dict(min_box_h=, clean=, max_occluded=)}`` -- instead, yield
    every car that belongs to any subset as ``(box, uv, visible, names of its subsets)``
    (one pass over the frames scores several selections)."""
    from wirescene.io.kitti import KittiDataset

    ds = KittiDataset(root)
    for fid in (ds.frame_ids() if frame_ids is None else list(frame_ids)):
        cam = ds.camera(fid)
        img = ds.image(fid)
        labelled = kitti_car_wireframes(ds.labels(fid), cam, image_size=img.shape[1::-1], scaled=scaled)
        if subsets is None:
            cars = [(c.box, c.uv, c.visible) for c in labelled
                    if _usable(c, min_box_h=min_box_h, max_occluded=max_occluded, clean=clean)]
        else:
            cars = []
            for c in labelled:
                tags = tuple(name for name, sel in subsets.items()
                             if _usable(c, **{"min_box_h": 0.0, "max_occluded": 3, "clean": False, **sel}))
                if tags:
                    cars.append((c.box, c.uv, c.visible, tags))
        yield img, cars


def mirror_cars(image, boxes, uv, visible):
    """Horizontally flipped image and the matching car annotations: ``u -> W - 1 - u``,
    boxes ``x1, x2 -> W - 1 - x2, W - 1 - x1`` and vertex ``j`` becomes vertex
    ``MIRROR[j]`` (left and right swap in a mirror image)."""
    from wirescene.core.wireframe import MIRROR

    img = np.ascontiguousarray(np.asarray(image)[:, ::-1])
    W = img.shape[1]
    b = np.asarray(boxes, float).reshape(-1, 4)
    b = np.stack([W - 1 - b[:, 2], b[:, 1], W - 1 - b[:, 0], b[:, 3]], axis=1)
    u = np.asarray(uv, float).copy()
    u[..., 0] = W - 1 - u[..., 0]
    # vertex MIRROR[j] of the flipped car sits where vertex j of the original car was
    return img, b, u[..., MIRROR, :], np.asarray(visible, bool)[..., MIRROR]


#: The real cars :func:`make_real_patch_data` learns parts from by default: boxes this high (px) at least, ...
REAL_MIN_BOX_H = 25.0
#: ... and occlusion levels up to this.
REAL_MAX_OCCLUDED = 1


def trainable_car_counts(dataset, frame_ids, *, min_box_h: float = REAL_MIN_BOX_H,
                         max_occluded: int = REAL_MAX_OCCLUDED) -> dict:
    """``{frame: number of its Car labels :func:`make_real_patch_data` learns parts from}``
    (box at least ``min_box_h`` px high, occlusion level at most ``max_occluded``) of
    ``dataset`` (a :class:`~wirescene.io.kitti.KittiDataset`), for the checks made before any
    patch is."""
    return {f: sum(_usable(o, min_box_h=min_box_h, max_occluded=max_occluded, clean=False)
                   for o in dataset.labels(f).of_type(*CAR_TYPES)) for f in frame_ids}


def make_real_patch_data(root, frame_ids, *, kinds=("ghog",), seed: int = 0, mirror: bool = True,
                         scale_samples: int = 3, n_jitter: int = 2, jitter: float = 2.0, bg_per_car: int = 60,
                         bg_boxes: int = 12, bg_per_box: int = 15, min_box_h: float = REAL_MIN_BOX_H,
                         max_occluded: int = REAL_MAX_OCCLUDED,
                         min_dist: float = 8.0, box_jitter: float = 0.04, max_patches: int | None = None,
                         label_shapes=None, progress=None):
    """Descriptors of real part and background patches of labelled KITTI frames.

    For every ``Car`` with occlusion level <= ``max_occluded`` and box height >=
    ``min_box_h`` (and, with ``mirror``, its mirror image):

    * parts: every visible vertex inside the image (:func:`kitti_car_wireframes`), at
      ``scale_samples`` scales ``s ~ exp(U(-0.2, 0.2))`` (object height ``s x`` box
      height, as the test-time scales) plus ``n_jitter`` copies displaced by up to
      ``jitter`` canonical px; every sample but the first is described in the label box
      jittered by ``box_jitter`` x its size (Gaussian, per side: detection boxes differ);
    * hard negatives: ``bg_per_car`` points of the padded box at least ``min_dist``
      canonical px from every projected vertex (visible or not: the labels are
      approximate) of every car;
    * background outside cars: ``bg_boxes`` random box-like windows per frame (height
      25..150 px, aspect 2.5), ``bg_per_box`` points each outside every padded
      Car / Van / DontCare box.

    ``max_patches``: keep at most that many, a uniform random sample of all
    (:class:`~wirescene.training.patches.PatchCollector`; None: all).

    ``label_shapes``: ``{frame id: (N, 36, 3)}`` wireframes of each frame's ``Car`` labels in
    the object frame (:func:`refit_label_shapes`) instead of the scaled mean shape; frames
    it does not hold keep the mean.

    Returns
    -------
    wirescene.training.parts.PatchData -- ``group`` is the frame's index in ``frame_ids``.
    """
    from wirescene.io.kitti import KittiDataset

    ds = KittiDataset(root)
    frame_ids = list(frame_ids)
    if label_shapes is not None:  # refused before any patch is cut, naming the frame
        from wirescene.core.errors import InputError

        for fid, n in ds.car_counts(frame_ids).items():
            if fid in label_shapes and np.shape(label_shapes[fid]) != (n, 36, 3):
                raise InputError(f"label shapes of frame {fid} are {np.shape(label_shapes[fid])}, but it has {n} "
                                 f"Car labels: (N, 36, 3) expected")
    patches = PatchCollector(kinds, max_patches=max_patches, seed=seed)
    add = patches.add
    t0 = time.time()

    for fi, fid in enumerate(frame_ids):
        img0 = ds.image(fid)
        H, W = img0.shape[:2]
        lab = ds.labels(fid)
        cars = kitti_car_wireframes(lab, ds.camera(fid), image_size=(W, H),
                                    shapes=None if label_shapes is None else label_shapes.get(fid))
        other = np.array([o.box for o in list(lab.of_type(*CAR_TYPES, "Van", "Truck")) + list(lab.dontcare)],
                         float).reshape(-1, 4)
        use = [i for i, c in enumerate(cars) if _usable(c, min_box_h=min_box_h, max_occluded=max_occluded,
                                                        clean=False)]
        boxes0 = np.array([c.box for c in cars]).reshape(-1, 4)
        uv0 = np.array([c.uv for c in cars]).reshape(-1, 36, 2)
        vis0 = np.array([c.visible for c in cars]).reshape(-1, 36)
        for flip in ((False, True) if mirror else (False,)):
            rng = _rng(seed, 7, fi, int(flip))
            if flip:
                img, boxes, uv, vis = mirror_cars(img0, boxes0, uv0, vis0)
                _, oth, _, _ = mirror_cars(img0[:1, :, :], other, np.zeros((len(other), 36, 2)),
                                           np.zeros((len(other), 36), bool))
            else:
                img, boxes, uv, vis, oth = img0, boxes0, uv0, vis0, other
            edges = feat.image_edges(img) if any(k in feat.EDGE_KINDS for k in kinds) else None
            all_pts = uv.reshape(-1, 2)
            for i in use:
                box = boxes[i]
                bw, bh = box[2] - box[0], box[3] - box[1]
                j = np.nonzero(vis[i])[0]
                for a in range(scale_samples):
                    s = float(np.exp(rng.uniform(-0.2, 0.2)))
                    z = feat.CANONICAL_HEIGHT / (s * bh)
                    # a detector's box is not the label's: the first sample keeps the label box
                    jb = box + (rng.normal(0.0, box_jitter, 4) * [bw, bh, bw, bh] if a else 0.0)
                    if len(j):
                        pts = [uv[i, j]] + [uv[i, j] + rng.uniform(-jitter, jitter, (len(j), 2)) / z
                                            for _ in range(n_jitter)]
                        add(img, jb, np.concatenate(pts), np.tile(j, 1 + n_jitter), s, edges, fi)
                    lo = box[:2] - 0.1 * np.array([bw, bh])
                    hi = box[2:] + 0.1 * np.array([bw, bh])
                    cand = rng.uniform(lo, hi, size=(bg_per_car * 3, 2))
                    d = np.linalg.norm(cand[:, None] - all_pts[None], axis=-1).min(1)
                    cand = cand[d * z >= min_dist]
                    add(img, jb, cand[:bg_per_car], BACKGROUND, s, edges, fi)
            grown = np.concatenate([oth[:, :2] - 0.1 * (oth[:, 2:] - oth[:, :2]),
                                    oth[:, 2:] + 0.1 * (oth[:, 2:] - oth[:, :2])], axis=1)
            for _ in range(bg_boxes):
                h = float(np.exp(rng.uniform(np.log(25), np.log(150))))
                cx, cy = rng.uniform(0, W), rng.uniform(0.25 * H, H)
                fake = np.array([cx - 1.25 * h, cy - h / 2, cx + 1.25 * h, cy + h / 2])
                cand = rng.uniform(fake[:2], fake[2:], size=(bg_per_box * 3, 2))
                cand = cand[(cand[:, 0] >= 0) & (cand[:, 1] >= 0) & (cand[:, 0] < W) & (cand[:, 1] < H)]
                if len(grown):
                    inside = ((cand[:, None, 0] >= grown[None, :, 0]) & (cand[:, None, 0] <= grown[None, :, 2])
                              & (cand[:, None, 1] >= grown[None, :, 1])
                              & (cand[:, None, 1] <= grown[None, :, 3])).any(1)
                    cand = cand[~inside]
                add(img, fake, cand[:bg_per_box], BACKGROUND, 1.0, edges, fi)
        if progress:
            progress(f"real frames: {fi + 1}/{len(frame_ids)} in {time.time() - t0:.0f} s")
    if not len(patches):
        raise ValueError("no real training patches in these frames")
    return patches.data(frame_ids)


#: Kind and version of a file of refitted label shapes (:func:`save_label_shapes`).
LABEL_SHAPES_KIND = "label_shapes"
LABEL_SHAPES_VERSION = 1


def hidden_by_other_labels(labels, camera) -> np.ndarray:
    """``(N, 36)`` bool: the vertices of each ``Car`` label's scaled mean wireframe that another
    labelled car's wireframe hides from the camera (not those the car hides itself)."""
    from wirescene.core import wireframe
    from wirescene.infer.occlusion import inter_object_occlusion

    cars = labels.of_type(*CAR_TYPES)
    if not cars:
        return np.zeros((0, 36), bool)
    X = _placed(cars, [scaled_mean_shape(o.dims) for o in cars])
    return inter_object_occlusion(X, wireframe.FACES, camera.center)


def refit_label_shapes(image, labels, camera, detector, *, n_components: int = 10, n_draws: int = 2000,
                       rounds: int = 3, round_draws: int = 500, c: float = 0.75, shape_prior: float = 1.0,
                       seed: int = 0, shape_model=None) -> np.ndarray:
    """Each ``Car`` label's own wireframe ``(N, 36, 3)`` (object frame), refitted to the part
    evidence with the label's pose and box fixed.

    The objective is the fine stage's part term (the mean calibrated log ratio over the
    self-visible vertices; those hidden by the other labelled cars, :func:`hidden_by_other_labels`,
    or by the image border score ``c``) minus ``shape_prior`` times half the squared shape
    coefficients (the fit's prior at 1). It is maximised over ``n_draws`` prior draws of the
    first ``n_components`` coefficients, then ``rounds`` of ``round_draws`` draws about the best
    (spread halved a round); every candidate is scaled per axis into the label's box, as
    :func:`scaled_mean_shape`, and the draw of zeros keeps the mean in the running.

    ``detector`` must not have seen the frame's drive (its maps would echo its own labels).
    """
    from wirescene.core import wireframe
    from wirescene.core.camera import NEAR_PLANE
    from wirescene.core.groundplane import rotation_y, transform
    from wirescene.infer.likelihood import object_likelihood, outside_image
    from wirescene.infer.occlusion import self_occlusion
    from wirescene.parts.detector import response_maps

    if shape_model is None:
        from wirescene.core.shape import load_default

        shape_model = load_default()
    cars = labels.of_type(*CAR_TYPES)
    if not cars:
        return np.zeros((0, 36, 3))
    k = min(int(n_components), shape_model.n_components)
    others_hide = hidden_by_other_labels(labels, camera)
    maps = response_maps(image, np.array([o.box for o in cars], float), detector=detector)
    rng = np.random.default_rng(seed)

    def value(S, i, hwl, loc, R):
        X = scaled_mean_shape(hwl, shape_model.instantiate(S))
        V = transform(X, loc, R)
        uv, depth = camera.project_with_depth(V)
        self_hidden = self_occlusion(V, wireframe.FACES, camera.center) | (depth <= NEAR_PLANE)
        known = outside_image(camera, uv) | others_hide[i]
        e = maps.log_ratio(uv, i, bilinear=True).astype(float)
        return object_likelihood(e, self_hidden, known, c=c) - 0.5 * shape_prior * np.sum(S ** 2, axis=-1), X

    out = []
    for i, o in enumerate(cars):
        pose = (i, o.dims, np.asarray(o.location, float), rotation_y(o.rotation_y))
        S = np.concatenate([np.zeros((1, k)), rng.standard_normal((n_draws - 1, k))])
        v, X = value(S, *pose)
        best = int(np.argmax(v))
        s_best, v_best, x_best = S[best], v[best], X[best]
        for r in range(rounds):
            S = s_best + rng.standard_normal((round_draws, k)) * 0.5 ** (r + 1)
            v, X = value(S, *pose)
            j = int(np.argmax(v))
            if v[j] > v_best:
                s_best, v_best, x_best = S[j], v[j], X[j]
        out.append(x_best)
    return np.stack(out)


def save_label_shapes(path, shapes: dict) -> None:
    """Write ``{frame id: (N, 36, 3)}`` refitted label shapes as a versioned ``.npz``."""
    from wirescene.core.artefacts import save_npz

    save_npz(path, {str(f): np.asarray(s, float) for f, s in shapes.items()}, kind=LABEL_SHAPES_KIND,
             version=LABEL_SHAPES_VERSION)


def load_label_shapes(path) -> dict:
    """``{frame id: (N, 36, 3)}`` written by :func:`save_label_shapes`; :class:`InputError`
    naming the file if it is not one."""
    from wirescene.core.artefacts import load_npz
    from wirescene.core.errors import InputError

    data = load_npz(path, kind=LABEL_SHAPES_KIND, version=LABEL_SHAPES_VERSION)
    for f, s in data.items():
        if s.ndim != 3 or s.shape[1:] != (36, 3):
            raise InputError(f"label shapes of frame {f} are {s.shape}, not (N, 36, 3)", path=path)
    return data
