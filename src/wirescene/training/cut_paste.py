"""Cut-and-paste augmentation of real training frames for the detector bank.

Real labelled KITTI cars are few (~100 per training fold). Following Dwibedi, Misra and
Hebert ("Cut, Paste and Learn", ICCV 2017) and Dvornik et al. ("Modeling visual context is
key to augmenting object detection datasets", ECCV 2018), every training frame gets a
composite copy into which cars of *other* training frames are pasted, so the templates see
each car against new backgrounds, at new scales, next to new neighbours.

Where a car may go is fixed by the road (:mod:`wirescene.predetect.geometry`): moving a car
from depth ``Z`` to ``Z / s`` scales its box by ``s`` and its bottom edge's distance below
the horizon by the same ``s``, so a donor whose bottom lies ``d`` rows below its frame's
horizon is pasted ``s * d`` rows below the target's horizon, ``s`` times larger. Its
column is free (the ratio that makes it a car on the road does not depend on it), but the
pasted car may not cover any labelled object of the target (so no label is corrupted) nor
leave the image (pedestrians and DontCare regions included). Its viewpoint (``alpha``) is what the pixels show, so it is kept.

Only clean donors are cut (not occluded, not truncated): their silhouette -- the convex
hull of the placed wireframe's 36 projected vertices -- is the whole car, and is pasted
with a feathered edge so the templates do not learn a seam. Composites are grey images,
as the bank's HOG features are.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wirescene.training.detector import _overlap_frac

#: Range of the depth scale ``s`` (new box size / donor box size), sampled log-uniformly.
SCALE_RANGE = (0.7, 1.4)
FEATHER_SIGMA = 1.0  # px, of the pasted silhouette's edge


def car_silhouette(v2d: np.ndarray, shape) -> np.ndarray:
    """``(h, w)`` float mask in [0, 1]: the convex hull of the projected vertices ``v2d``
    ``(36, 2)`` (in the crop's pixel frame), feathered by :data:`FEATHER_SIGMA`."""
    from scipy.ndimage import gaussian_filter
    from scipy.spatial import ConvexHull
    from skimage.draw import polygon

    hull = v2d[ConvexHull(v2d).vertices]
    mask = np.zeros(shape, np.float32)
    rr, cc = polygon(hull[:, 1], hull[:, 0], shape)
    mask[rr, cc] = 1.0
    return np.clip(gaussian_filter(mask, FEATHER_SIGMA), 0.0, 1.0)


def paste_cars(images, examples, *, per_image: int = 3, seed: int = 0, min_height: float = 25.0,
               max_tries: int = 30, mirror) -> tuple:
    """Composite training images with cars of other frames pasted in (module docstring).

    ``images``: :class:`~wirescene.training.kitti_detector.TrainImage` (originals and flipped
    copies; each original gets one composite and, through ``mirror``, its mirrored copy);
    ``examples``: their :class:`~wirescene.predetect.configurations.CarExample`. ``mirror(image,
    examples_of_it, index)`` returns the mirrored ``(image, examples)`` with image index
    ``index``. Donors are the clean, unflipped examples of the other frames at least
    ``min_height`` px high after scaling. Returns ``(new_images, new_examples)`` whose
    image indices continue after ``images``.
    """
    from skimage.transform import resize

    rng = np.random.default_rng(seed)
    donors = [e for e in examples if not e.flipped and e.clean and images[e.image].horizon is not None]
    new_images, new_examples = [], []
    if not donors:
        return new_images, new_examples
    base = len(images)
    for target in images:
        if target.flipped or target.horizon is None:
            continue
        canvas = target.gray.astype(np.float32)
        H, W = canvas.shape
        occupied = target.block if target.occupied is None else target.occupied
        blocked = [np.asarray(b, float) for b in occupied]
        pasted = []
        for _ in range(per_image):
            for _ in range(max_tries):
                d = donors[int(rng.integers(len(donors)))]
                src = images[d.image]
                if src.frame == target.frame:
                    continue
                s = float(np.exp(rng.uniform(*np.log(SCALE_RANGE))))
                lb = d.label_box.astype(float)
                if s * (lb[3] - lb[1]) < min_height:
                    continue
                Hs, Ws = src.gray.shape
                x0, y0 = np.floor(np.minimum(d.v2d.min(0), lb[:2]) - 2).astype(int)
                x1, y1 = np.ceil(np.maximum(d.v2d.max(0), lb[2:]) + 2).astype(int)
                x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, Ws - 1), min(y1, Hs - 1)
                nw, nh = int(round(s * (x1 - x0 + 1))), int(round(s * (y1 - y0 + 1)))
                sx, sy = nw / (x1 - x0 + 1), nh / (y1 - y0 + 1)
                # ground-consistent row: the bottom's distance below the horizon scales with s
                bottom = target.horizon + sy * (lb[3] - src.horizon)
                Y0 = int(round(bottom - sy * (lb[3] - y0)))
                if Y0 < 0 or Y0 + nh > H or nw >= W:
                    continue
                X0 = int(rng.integers(0, W - nw + 1))
                shift = np.array([X0 - sx * x0, Y0 - sy * y0])
                box = np.concatenate([lb[:2] * [sx, sy] + shift, lb[2:] * [sx, sy] + shift])
                w, h = box[2] - box[0], box[3] - box[1]
                grown = box + 0.05 * np.array([-w, -h, w, h])  # keep a margin from what is there
                if _overlap_frac(grown[None], np.array(blocked, float).reshape(-1, 4))[0] > 0:
                    continue
                crop = src.gray[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
                mask = car_silhouette(d.v2d - [x0, y0], crop.shape)
                crop = resize(crop, (nh, nw), anti_aliasing=s < 1, preserve_range=True)
                mask = resize(mask, (nh, nw), anti_aliasing=s < 1, preserve_range=True)
                region = canvas[Y0:Y0 + nh, X0:X0 + nw]
                canvas[Y0:Y0 + nh, X0:X0 + nw] = mask * crop + (1 - mask) * region
                blocked.append(box)
                pasted.append(replace(d, image=base + len(new_images), v2d=d.v2d * [sx, sy] + shift, label_box=box,
                                      full_box=None))
                break
        if not pasted:
            continue
        gray = np.clip(np.round(canvas), 0, 255).astype(np.uint8)
        block = np.concatenate([np.asarray(target.block, float).reshape(-1, 4), np.array([e.label_box for e in pasted])])
        composite = target.with_pixels(gray, block=block, composite=True, occupied=None)
        new_images.append(composite)
        new_examples += pasted
        flipped, flipped_examples = mirror(composite, pasted, base + len(new_images))
        new_images.append(flipped)
        new_examples += flipped_examples
    return new_images, new_examples
