"""A viewpoint classifier on the crop of a box: the cues the configuration templates miss.

The bank's HOG templates tell a side view from a front or back view, but hardly a front
from a back (a symmetric box with two lamps and a plate either way): on the shared KITTI
frames held out by drive, the templates alone put 59% of the label boxes within 45 deg,
a quarter of them facing the wrong way. This classifier looks at the whole box at once:
HOG cells of the box warped to a fixed grid (:data:`HOG_GRID`), where each colour and
brightness sits (tail lights are red, a windscreen is brighter than a rear window:
:data:`COLOUR_GRID`) and the box's aspect ratio, standardised, and a multinomial logistic
regression (L2, :data:`C`) over the 8 viewpoint bins trained on the labelled cars, their
mirror images (mirrored bins) and copies jittered by 5% of their size, as another detector's
boxes would be. Its log-probabilities add to the templates' log-odds and the road prior in
:func:`wirescene.predetect.box_viewpoints.box_viewpoints` (naive Bayes).

The model is stored without pickle in a versioned ``.npz``; the shipped one
(``wirescene/data/viewpoint_classifier.npz``) is trained on the 72 shared KITTI frames
(:func:`train_on_kitti`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from PIL import Image

from wirescene.core.artefacts import load_npz, save_npz, trained_arrays, trained_images
from wirescene.core.errors import InputError, check_shape
from wirescene.core.labels import CAR_TYPES
from wirescene.core.resources import DATA_DIR, images_sha256
from wirescene.core.viewpoints import N_BINS, viewpoint_bin
from wirescene.predetect.configurations import mirror_bin
from wirescene.predetect.hog import crops_features, to_gray

FORMAT_VERSION = 1
ARTEFACT_KIND = "viewpoint-classifier"
DEFAULT_PATH = DATA_DIR / "viewpoint_classifier.npz"

#: (rows, cols) of HOG cells the box is warped to.
HOG_GRID = (6, 10)
#: (rows, cols) of the grid of colour cells (redness and brightness, mean and maximum).
COLOUR_GRID = (4, 6)
#: Inverse L2 regularisation of the logistic regression (chosen on fold group (0, 1)).
C = 0.01
#: Box jitter of the training copies, as a share of the box's width / height per side.
JITTER = 0.05
_SUB = 4  # pixels per colour cell side in the resampled crop
#: Features of a crop (:func:`crop_viewpoint_features`): 31 HOG channels per cell, the mean
#: and maximum redness and brightness per colour cell, the aspect ratio.
N_FEATURES = HOG_GRID[0] * HOG_GRID[1] * 31 + 4 * COLOUR_GRID[0] * COLOUR_GRID[1] + 1


def crop_viewpoint_features(image: np.ndarray, boxes) -> np.ndarray:
    """``(N, F)`` appearance features of boxes ``(N, 4)`` in an ``(H, W, 3)`` uint8 image:
    HOG of the box warped to :data:`HOG_GRID` cells, per cell of :data:`COLOUR_GRID` the mean
    and maximum redness (``R - max(G, B)``, clipped at 0) and brightness, and the log
    aspect ratio.

    Examples
    --------
    >>> image = np.zeros((64, 96, 3), np.uint8)
    >>> f = crop_viewpoint_features(image, [[10, 10, 70, 40], [0, 0, 30, 30]])
    >>> f.shape == (2, N_FEATURES), N_FEATURES, f.dtype.name  # 6 x 10 cells x 31, 4 numbers x 24 colour cells, aspect
    (True, 1957, 'float32')
    >>> f[:, -1].round(3)  # log(60 / 30), log(30 / 30)
    array([0.693, 0.   ], dtype=float32)
    """
    b = np.asarray(boxes, float)
    check_shape("boxes", b, (None, 4))
    image = np.asarray(image)
    gray = to_gray(image)
    rgb = Image.fromarray(np.ascontiguousarray(image[..., :3] if image.ndim == 3 else np.stack([image] * 3, -1)))
    gh, gw = COLOUR_GRID
    H, W = gray.shape
    hogs = crops_features(gray, b, *HOG_GRID).reshape(len(b), -1)
    out = []
    for (x1, y1, x2, y2), hog in zip(b, hogs):
        # the colour of the part of the box inside the image (PIL resamples only from within it)
        cx1, cy1 = min(max(x1, 0.0), W - 1.0), min(max(y1, 0.0), H - 1.0)
        cx2, cy2 = max(min(x2, float(W)), cx1 + 1.0), max(min(y2, float(H)), cy1 + 1.0)
        a = np.asarray(rgb.resize((gw * _SUB, gh * _SUB), Image.BILINEAR, box=(cx1, cy1, cx2, cy2)), np.float32) / 255.0
        red = np.clip(a[..., 0] - np.maximum(a[..., 1], a[..., 2]), 0.0, None)
        cells = [m.reshape(gh, _SUB, gw, _SUB) for m in (red, a.mean(-1))]
        colour = np.concatenate([f for c in cells for f in (c.mean((1, 3)).ravel(), c.max((1, 3)).ravel())])
        aspect = np.log(max(x2 - x1, 1.0) / max(y2 - y1, 1.0))
        out.append(np.concatenate([hog, colour, [aspect]]))
    return np.array(out, np.float32).reshape(len(b), N_FEATURES)


@dataclass
class ViewpointClassifier:
    """Standardisation and multinomial logistic regression over the 8 viewpoint bins.

    Examples
    --------
    >>> model = load_default_classifier()
    >>> model.mean.shape, model.weights.shape, model.bias.shape
    ((1957,), (1957, 8), (8,))
    >>> log_p = model.log_probs_of_features(np.zeros((3, 1957)))
    >>> log_p.shape, bool(np.allclose(np.exp(log_p).sum(1), 1.0))
    ((3, 8), True)
    """

    mean: np.ndarray  # (F,)
    scale: np.ndarray  # (F,)
    weights: np.ndarray  # (F, 8)
    bias: np.ndarray  # (8,)
    meta: dict = field(default_factory=dict)
    trained_images: dict = field(default_factory=dict)  # {frame id: image SHA-256} of its real training frames

    def log_probs_of_features(self, features) -> np.ndarray:
        """``(N, 8)`` log P(bin | features) of features ``(N, F)``."""
        x = np.asarray(features, float)
        check_shape("features", x, (None, len(self.mean)))
        z = ((x - self.mean) / self.scale) @ self.weights + self.bias
        z -= z.max(1, keepdims=True)
        return z - np.log(np.exp(z).sum(1, keepdims=True))

    def log_probs(self, image: np.ndarray, boxes) -> np.ndarray:
        """``(N, 8)`` log P(bin | crop) of boxes ``(N, 4)`` of an ``(H, W, 3)`` image.

        Examples
        --------
        >>> import numpy as np
        >>> image = np.zeros((64, 96, 3), np.uint8)
        >>> lp = load_default_classifier().log_probs(image, [[10, 10, 70, 40]])
        >>> lp.shape, bool(np.isclose(np.exp(lp).sum(), 1.0))
        ((1, 8), True)
        """
        return self.log_probs_of_features(crop_viewpoint_features(image, boxes))

    def save(self, path) -> Path:
        from wirescene.core.jsonio import dumps

        arrays = {k: np.asarray(getattr(self, k), np.float32) for k in ("mean", "scale", "weights", "bias")}
        return save_npz(path, {**arrays, "meta_json": np.array(dumps(self.meta, indent=None, sort_keys=True)),
                               **trained_arrays(self.trained_images)}, kind=ARTEFACT_KIND, version=FORMAT_VERSION)

    @classmethod
    def load(cls, path) -> "ViewpointClassifier":
        import json

        z = load_npz(path, kind=ARTEFACT_KIND, version=FORMAT_VERSION)  # missing / corrupt / foreign: InputError
        try:
            model = cls(*(z[k].astype(float) for k in ("mean", "scale", "weights", "bias")),
                        json.loads(str(z["meta_json"])),  # strict JSON, or an older file's NaN
                        trained_images(z, path=path))
        except KeyError as exc:
            raise InputError(f"malformed viewpoint classifier (missing {exc})", path=path) from None
        F = len(model.mean)
        if model.scale.shape != (F,) or model.weights.shape != (F, N_BINS) or model.bias.shape != (N_BINS,):
            raise InputError("viewpoint classifier arrays do not match", path=path)
        if F != N_FEATURES:  # another crop description than this version computes
            raise InputError(f"viewpoint classifier of {F} features, expected {N_FEATURES}", path=path)
        if not all(np.all(np.isfinite(a)) for a in (model.mean, model.scale, model.weights, model.bias)) \
                or np.any(model.scale <= 0):
            raise InputError("viewpoint classifier holds values that are not finite (or a scale not above 0)",
                             path=path)
        return model


def fit_viewpoint_classifier(features, bins, *, C: float = C, meta: dict | None = None) -> ViewpointClassifier:
    """The classifier of training ``features`` ``(N, F)`` with viewpoint ``bins`` ``(N,)``.

    A bin absent from the training set keeps a log-probability far below the others'.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> bins = np.arange(40) % 8
    >>> x = np.eye(8)[bins] + 0.1 * rng.normal(size=(40, 8))
    >>> model = fit_viewpoint_classifier(x, bins, C=1.0)
    >>> bool(np.all(model.log_probs_of_features(x).argmax(1) == bins))
    True
    """
    from sklearn.linear_model import LogisticRegression

    x = np.asarray(features, float)
    y = np.asarray(bins, int)
    check_shape("bins", y, (len(x),))
    mean = x.mean(0)
    scale = x.std(0)
    scale[scale < 1e-6] = 1.0  # constant features: left as they are
    clf = LogisticRegression(C=C, max_iter=5000).fit((x - mean) / scale, y)
    weights = np.zeros((x.shape[1], N_BINS))
    bias = np.full(N_BINS, -np.inf)
    coef, icpt = clf.coef_, clf.intercept_
    if len(clf.classes_) == 2:  # sklearn's binary form: one row for the second class
        coef, icpt = np.vstack([-coef / 2, coef / 2]), np.array([-icpt[0] / 2, icpt[0] / 2])
    weights[:, clf.classes_] = coef.T
    bias[clf.classes_] = icpt
    bias[~np.isfinite(bias)] = bias[np.isfinite(bias)].min() - 10.0
    return ViewpointClassifier(mean, scale, weights, bias, dict(meta or {}, C=C, n=int(len(y))))


def kitti_examples(dataset, frames, *, jitter: float = JITTER, seed: int = 0, copies: int = 1,
                   photometric: bool = False):
    """Training ``(features (M, F), bins (M,))`` of the labelled cars of ``frames`` of a
    :class:`~wirescene.io.kitti.KittiDataset`: each label box, its mirror image and ``copies``
    copies of each with the sides moved by N(0, ``jitter``) of the box's width / height (the
    recipe: one); with ``photometric`` (a study's option, ``benchmarks/bench_viewpoint_classifier.py``)
    also each box of an image copy of other brightness and contrast.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> from wirescene.io.kitti import KittiDataset
    >>> x, bins = kitti_examples(KittiDataset(DATA_DIR / "sample" / "kitti"), ["000010"])
    >>> x.shape, bins.shape  # 8 cars, each with its mirror image, each with one jittered copy
    ((32, 1957), (32,))
    """
    rng = np.random.default_rng(seed)
    frames = list(frames)
    feats, bins = [], []
    for f in frames:
        cars = dataset.labels(f).of_type(*CAR_TYPES)
        if not cars:
            continue
        image = dataset.image(f)
        W = image.shape[1]
        boxes = np.array([o.box for o in cars], float)
        b = viewpoint_bin(np.array([o.alpha for o in cars]))
        for flip in (False, True):
            im = np.ascontiguousarray(image[:, ::-1]) if flip else image
            bx = np.column_stack([W - boxes[:, 2], boxes[:, 1], W - boxes[:, 0], boxes[:, 3]]) if flip else boxes
            wh = np.tile(np.column_stack([bx[:, 2] - bx[:, 0], bx[:, 3] - bx[:, 1]]), 2)
            every = [bx]
            for _ in range(copies):
                moved = bx + rng.normal(0.0, jitter, bx.shape) * wh
                moved[:, 2:] = np.maximum(moved[:, 2:], moved[:, :2] + 2.0)
                every.append(moved)
            feats.append(crop_viewpoint_features(im, np.concatenate(every)))
            bins.append(np.tile(mirror_bin(b) if flip else b, 1 + copies))
            if photometric:
                gain, offset = rng.uniform(0.6, 1.4), rng.uniform(-30, 30)
                lit = np.clip(im.astype(np.float32) * gain + offset, 0, 255).astype(np.uint8)
                feats.append(crop_viewpoint_features(lit, bx))
                bins.append(mirror_bin(b) if flip else b)
    if not feats:
        raise InputError(f"no labelled cars in the {len(frames)} frames to train a viewpoint classifier on",
                         path=dataset.split_dir)
    return np.concatenate(feats), np.concatenate(bins)


def check_trainable(dataset, frames) -> None:
    """An :class:`InputError` naming the split if the labelled cars of ``frames`` and their
    mirror images show a single viewpoint bin (read off the labels alone, so that ``train all``
    refuses them before its first step); frames without any car are left to
    :func:`kitti_examples` to refuse.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> from wirescene.io.kitti import KittiDataset
    >>> check_trainable(KittiDataset(DATA_DIR / "sample" / "kitti"), ["000010"]) is None  # cars of several bins
    True
    """
    frames = list(frames)
    alpha = np.array([o.alpha for f in frames for o in dataset.labels(f).of_type(*CAR_TYPES)], float)
    if not len(alpha):
        return
    bins = viewpoint_bin(alpha)
    if len(np.unique(np.concatenate([bins, mirror_bin(bins)]))) < 2:
        # mirror images turn every bin but the two pure side views into another
        raise InputError(f"the labelled cars of the {len(frames)} frames show one viewpoint bin (with their mirror "
                         "images); a viewpoint classifier needs two or more", path=dataset.split_dir)


def train_on_kitti(dataset, frames, *, C: float = C, seed: int = 0) -> ViewpointClassifier:
    """:func:`fit_viewpoint_classifier` of :func:`kitti_examples` of ``frames`` (refused by
    :func:`check_trainable` first), with the record of their images
    (:attr:`ViewpointClassifier.trained_images`)."""
    frames = list(frames)
    dataset.require_labels("training")
    check_trainable(dataset, frames)
    x, y = kitti_examples(dataset, frames, seed=seed)
    model = fit_viewpoint_classifier(x, y, C=C, meta={"frames": [str(f) for f in frames], "seed": seed})
    # by which an evaluation on these frames says that its figures are not held out
    model.trained_images = images_sha256(dataset.image_path, frames)
    return model


@lru_cache(maxsize=1)
def load_default_classifier() -> ViewpointClassifier:
    """The classifier shipped in ``wirescene/data/viewpoint_classifier.npz`` (cached)."""
    return ViewpointClassifier.load(DEFAULT_PATH)
