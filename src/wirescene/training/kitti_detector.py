"""Train the configuration detector bank on real KITTI frames (deterministic).

The paper's bank (Sec. 3.4) is trained on real street images; the synthetic-only bank of
:mod:`.training` reached ~1-3% KITTI AP on real frames. This module builds the same kind
of bank -- per viewpoint bin one full-car configuration plus part configurations, each a
linear HOG template trained as a linear SVM -- from the labelled frames of a KITTI root:

1. Car examples. Every ``Car`` label gets the mean wireframe of the shape model scaled to
   its 3D box size and placed at its 3D pose; the 36 vertices are projected with P2.
   Geometric visibility = not self-occluded (ray casting against the wireframe surface)
   and inside the image; vertices that fall into the 2D box of a labelled object standing
   nearer to the camera count as occluded (KITTI has no per-vertex visibility). Every car
   also yields its horizontally mirrored copy (alpha -> pi - alpha, i.e. bin b -> 4 - b,
   left and right vertices swapped), so every training image is used twice (flipped).
2. Configurations are chosen as for synthetic data (:func:`wirescene.predetect.configurations.select_configurations`)
   from the (scarce) real examples. Part configurations only need their own vertices to be
   visible, so they are trained on -- and fire on -- cars truncated by the image border or
   partly occluded; their votes predict the amodal full box, which is clipped to the image.
3. Positives: crops warped to the template plus jittered copies (shift +-5%, scale +-7%)
   up to ``min_pos``; a viewpoint bin with fewer than ``min_bin_examples`` cars borrows
   the examples of its two neighbouring bins (real KITTI has almost no side views).
4. Negatives: random windows of the training images (original and flipped) that overlap
   no labelled object (Car, Van, Truck, Tram, Misc, DontCare; overlap <= 30% of the
   window), then ``mining_rounds`` rounds of hard-negative mining on all training images
   (at most ``mining_images`` of them a round, where set).
5. The bank's scores are SVM margins of the best member of each cluster of votes; a Platt
   calibration (``a * margin + b`` -> probability that the detection is a car with IoU >=
   0.5) fitted on *held-out* detections (:func:`fit_platt`, used by the cross-validation in
   ``benchmarks/bench_predetect.py`` and by ``wirescene train detector --kitti-root``)
   turns them into confidences.
6. Box regression (:func:`fit_box_regression`): the cluster boxes average votes for the
   placed wireframe's box (the better training target), but detections are scored
   against the labelled 2D boxes at IoU 0.7; a ridge regression on the bank's own
   detections of its training images maps the one onto the other (held out by drive,
   2D AP easy / moderate / hard 24.8 / 22.3 / 17.4 -> 36.8 / 26.1 / 20.2).
7. Box refinement from the image (:func:`fit_box_refinement`, :mod:`wirescene.predetect.refine`):
   a ridge regression from the HOG cells around a box to its sides' offsets, fitted on
   jittered label boxes and the bank's own detections (held out: moderate 26.1 -> 29.5
   alone, 32.2 -> 38.9 with the ground prior).
8. Ground prior (:func:`fit_bank_ground_prior`, :mod:`wirescene.predetect.geometry`): the
   ratio (bottom - horizon) / height of the labelled cars against that of the bank's own
   background detections on its training images; with a camera, each detection's score
   gains the log ratio of the two densities, and the Platt calibration is fitted with that
   log ratio as an offset (held out by drive: moderate 26.1 -> 32.2, IoU 0.5 47.0 -> 65.0).
9. Viewpoint prior (:func:`fit_bank_viewpoint_prior`, :mod:`wirescene.predetect.viewpoint_prior`):
   which way the labelled cars face at each lateral position on the road (traffic); with a
   camera it settles front against back views among a detection's candidate clusters.
10. Verifier (:func:`fit_bank_verifier`, :mod:`wirescene.predetect.verifier`): a logistic
   regression on the HOG cells and the colour and gradient-magnitude channels
   (:mod:`wirescene.predetect.channels`) in and around each final box, fitted on the bank's own
   detections of its training images and the labelled boxes; its logit enters the score
   with the weight ``c`` of a three-parameter Platt calibration fitted on held-out
   detections (:func:`fit_platt`, :func:`set_calibration`).

Memory does not grow with the number of training frames beyond fixed bounds
(:mod:`wirescene.training.scale`): the training images hold no pixels (read again where a
pass needs them), grey images and pyramids live in a cache of ``pyramid_cache_mb``, each
configuration's negatives are capped at ``max_negatives``, positives at ``max_pos``. What
still grows is small: the car examples (~1 kB each) and, with ``cut_paste``, the
composites' pixels. The passes over the images (mining, detections) run in ``workers``
processes.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Mapping

import numpy as np

from wirescene.core.errors import ArgumentError, InputError
from wirescene.core.groundplane import wrap_angle
from wirescene.core.labels import CAR_TYPES
from wirescene.core.resources import images_sha256
from wirescene.core.viewpoints import BIN_WIDTH, N_BINS, bin_center, viewpoint_bin
from wirescene.predetect.bank import (
    SUPPORT_WEIGHT,
    DetectorBank,
    bank_scales,
    detect_pyramid,
    finish_clusters,
    pad_pyramid,
    pyramid_clusters,
    score_pyramid,
)
from wirescene.predetect.configurations import (
    CarExample,
    apply_full_box,
    learn_full_box_correction,
    mirror_alpha,
    mirror_bin,
    select_configurations,
)
from wirescene.predetect.geometry import bottom_ratio, fit_ground_prior, horizon_row
from wirescene.predetect.hog import feature_pyramid, pyramid_scales, to_gray
from wirescene.predetect.verifier import CHANNELS as VERIFIER_CHANNELS
from wirescene.predetect.verifier import C as VERIFIER_C
from wirescene.predetect.viewpoint_prior import fit_viewpoint_prior, lateral_position
from wirescene.training.detector import (
    _overlap_frac,
    align_positives,
    alignment_offsets,
    fit_svms,
    mining_subsets,
    positive_features,
    sample_random_negatives,
)
from wirescene.training.scale import (
    CACHE,
    DEFAULT_CACHE_MB,
    DEFAULT_MAX_NEGATIVES,
    DEFAULT_MAX_REFINEMENT_ROWS,
    NegativePool,
    RowSample,
    map_images,
    single_threaded,
)

BLOCKING_TYPES = ("Car", "Van", "Truck", "Tram", "Misc")
"""Labelled objects no negative window may overlap (DontCare regions too)."""


@dataclass
class TrainImage:
    """One training image (the original or the flipped copy of a frame).

    Its grey image is read from ``source`` (a :class:`~wirescene.io.kitti.KittiDataset`)
    on demand, or held in ``pixels`` where it cannot be read (composites); both it and its
    HOG pyramids are kept in :data:`wirescene.training.scale.CACHE` within its budget."""

    frame: str
    flipped: bool
    block: np.ndarray  # (K, 4) boxes negatives must not overlap (in this image's frame)
    size: tuple  # (W, H) in pixels
    source: object = None  # the dataset the grey image is read from (None: ``pixels``)
    pixels: np.ndarray | None = None  # (H, W) uint8 grey image where it is not read from ``source``
    horizon: float | None = None  # image row of the ground plane's horizon (flips keep rows)
    center_column: float | None = None  # column of the principal point (mirrored in flipped copies)
    composite: bool = False  # made by pasting cars of other frames in (:mod:`.cut_paste`)
    occupied: np.ndarray | None = None  # (K, 4) boxes of every labelled object (pedestrians too), unflipped frame
    key: tuple = ()  # identity in the cache: (split directory, frame, flipped), or a composite's number

    @property
    def gray(self) -> np.ndarray:
        """``(H, W)`` uint8 grey image, already flipped if ``flipped``."""
        if self.pixels is not None:
            return self.pixels
        return CACHE.get(("gray",) + self.key, lambda: read_gray(self.source, self.frame, flipped=self.flipped))

    @property
    def channels(self) -> np.ndarray:
        """The image's :func:`~wirescene.predetect.channels.integral_channels` (flipped if
        ``flipped``; a composite holds grey pixels only, so its channels carry no colour)."""
        from wirescene.predetect.channels import integral_channels

        def read():
            if self.pixels is not None:
                return integral_channels(self.pixels)
            rgb = self.source.image(self.frame)
            return integral_channels(rgb[:, ::-1] if self.flipped else rgb)
        return CACHE.get(("channels",) + self.key, read)

    def hog_pyramid(self, scales) -> list:
        """The HOG pyramid (:func:`~wirescene.predetect.hog.feature_pyramid`) at ``scales``."""
        scales = tuple(float(s) for s in scales)
        return CACHE.get(("pyramid", scales) + self.key, lambda: feature_pyramid(self.gray, scales))

    def with_pixels(self, pixels: np.ndarray, **changes) -> TrainImage:
        """A copy holding its grey image ``pixels`` (a composite), with ``changes``."""
        from dataclasses import replace

        return replace(self, pixels=pixels, source=None, key=("composite", next(_COMPOSITES)), **changes)


_COMPOSITES = itertools.count()


def read_gray(dataset, frame: str, *, flipped: bool = False) -> np.ndarray:
    """``(H, W)`` uint8 grey image of ``frame`` of ``dataset``, mirrored if ``flipped``."""
    gray = np.round(to_gray(dataset.image(frame)) * 255).astype(np.uint8)
    return np.ascontiguousarray(gray[:, ::-1]) if flipped else gray


def car_wireframe(label, camera, mean: np.ndarray):
    """``(vertices (36, 3) camera frame, uv (36, 2), depth (36,))`` of the mean wireframe
    scaled to ``label.dims`` and placed at the label's pose."""
    from wirescene.core.groundplane import rotation_y, transform

    h, w, l = (float(v) for v in label.dims)
    ext = np.maximum(mean.max(0) - mean.min(0), 1e-6)
    X = transform(mean * np.array([l, h, w]) / ext, label.location, rotation_y(label.rotation_y))
    uv, depth = camera.project_with_depth(X)
    return X, uv, depth


def frame_examples(labels, camera, width: int, height: int, image_index: int, mean: np.ndarray, *,
                   flips: bool = True) -> list:
    """Car examples (and their mirror images, image ``image_index + 1``) of one labelled frame."""
    from wirescene.core.wireframe import FACES
    from wirescene.infer.occlusion import self_occlusion

    objs = [o for o in labels.objects if not o.is_dontcare]  # the objects that may hide a car's vertices
    out = []
    for o in labels.of_type(*CAR_TYPES):
        X, uv, depth = car_wireframe(o, camera, mean)
        if depth.min() < 0.5:  # partly behind the camera: no sensible projection
            continue
        self_hidden = self_occlusion(X, FACES, camera.center)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
        geom = ~self_hidden & inside
        hidden = np.zeros(len(uv), bool)
        for p in objs:
            if p is o or p.location[2] >= o.location[2] - 0.5:
                continue
            b = p.box
            hidden |= (uv[:, 0] > b[0]) & (uv[:, 0] < b[2]) & (uv[:, 1] > b[1]) & (uv[:, 1] < b[3])
        vis = geom & ~hidden
        occ = float(np.mean(hidden[geom])) if geom.any() else 1.0
        occ = max(occ, {0: 0.0, 1: 0.1, 2: 0.4}.get(o.occluded, 0.6))
        b = int(viewpoint_bin(o.alpha))
        kw = dict(occ_frac=occ, truncated=float(o.truncated))
        out.append(CarExample(image_index, False, b, uv.copy(), vis, geom, o.box.copy(), alpha=float(o.alpha), **kw))
        if flips:
            out.append(mirrored_example(out[-1], width, image_index + 1))
    return out


def mirrored_example(e: CarExample, width: int, image: int) -> CarExample:
    """The car example ``e`` in its image mirrored horizontally (``width`` px wide), as image
    ``image``: vertices swap sides (alpha -> pi - alpha, bin b -> 4 - b)."""
    from dataclasses import replace

    from wirescene.core.wireframe import MIRROR

    fv = e.v2d[MIRROR].copy()
    fv[:, 0] = (width - 1) - fv[:, 0]
    return replace(e, image=image, flipped=not e.flipped, bin=int(mirror_bin(e.bin)), v2d=fv,
                   visible=e.visible[MIRROR], geom_visible=e.geom_visible[MIRROR],
                   label_box=mirrored_boxes(e.label_box, width)[0], full_box=None,
                   alpha=float(mirror_alpha(e.alpha)))


def mirrored_image(image: TrainImage, examples, index: int):
    """``(image, examples)`` of ``image`` mirrored horizontally, as training image ``index``."""
    from dataclasses import replace

    W = image.size[0]
    changes = dict(flipped=not image.flipped, block=mirrored_boxes(image.block, W),
                   center_column=None if image.center_column is None else (W - 1) - image.center_column)
    if image.pixels is not None:
        flipped = image.with_pixels(np.ascontiguousarray(image.pixels[:, ::-1]), **changes)
    else:
        flipped = replace(image, key=image.key[:-1] + (not image.flipped,), **changes)
    return flipped, [mirrored_example(e, W, index) for e in examples]


def load_training_frames(dataset, frame_ids, *, flips: bool = True, progress=None):
    """``(images, examples)`` of labelled KITTI frames (see the module docstring).

    The images hold no pixels (:class:`TrainImage`): each frame's grey image is read here
    once, for its size, and offered to the cache."""
    from wirescene.core.shape import load_default

    mean = load_default().mean
    images, examples = [], []
    where = str(Path(dataset.split_dir).resolve())
    for fid in frame_ids:
        gray = read_gray(dataset, fid)
        H, W = gray.shape
        CACHE.put(("gray", where, fid, False), gray)
        labels = dataset.labels(fid)
        block = np.array([o.box for o in labels.of_type(*BLOCKING_TYPES)]
                         + [d.box for d in labels.dontcare], float).reshape(-1, 4)
        camera = dataset.camera(fid)
        horizon = horizon_row(camera)
        cx = float(camera.K[0, 2])
        occupied = np.array([o.box for o in labels.objects] + [d.box for d in labels.dontcare], float).reshape(-1, 4)
        examples += frame_examples(labels, camera, W, H, len(images), mean, flips=flips)
        images.append(TrainImage(fid, False, block, (W, H), source=dataset, horizon=horizon, center_column=cx,
                                 occupied=occupied, key=(where, fid, False)))
        if flips:
            images.append(mirrored_image(images[-1], [], len(images))[0])
    if progress:
        progress(f"{len(frame_ids)} frames, {len(images)} training images, {len(examples)} car examples")
    return images, examples


def train_bank_on_frames(images, examples, *, seed: int = 0, n_partial: int = 3, C: float = 0.01,
                         max_pos: int = 600, min_pos: int = 120, max_jitter: int = 6, min_bin_examples: int = 5,
                         neg_per_image: int = 40, mining_rounds: int = 3, hard_per_image: int = 15,
                         min_height: float = 25.0, max_scale: float = 2.0, full_area: float = 48,
                         partial_area: float = 36, label_boxes: bool = False, per_octave: int = 6, box_weight: float = 2.0,
                         cluster_radius: float = 0.2, cut_paste: int = 0, max_negatives: int | None = DEFAULT_MAX_NEGATIVES,
                         pyramid_cache_mb: float = DEFAULT_CACHE_MB, pad_cells: int = 0, max_truncated: float = 0.15,
                         whiten: bool = False, align: bool = False, share_deg: float = 0.0, synthetic=None,
                         mining_images: int | None = None, workers: int = 1, progress=None) -> DetectorBank:
    """Train a :class:`DetectorBank` on real training images and their car examples.

    ``images``/``examples`` as returned by :func:`load_training_frames` (grey images and
    pyramids are computed on demand and kept in :data:`~wirescene.training.scale.CACHE`, so
    cross-validation folds share them).
    Returns an uncalibrated bank (``calibration`` None, ``threshold`` 0 in margin units).
    ``box_weight``: detections average the votes of a cluster with weights
    ``exp(box_weight * margin)`` (stored in the bank's meta; see :func:`wirescene.predetect.bank.cluster_activations`).
    ``label_boxes``: the full box of a car that is neither truncated nor largely occluded is
    its labelled 2D box (else the placed wireframe's box with the learned per-bin correction).
    ``per_octave``: HOG pyramid levels per octave, stored with the bank for detection (6
    rather than 4: held out by drive, 2D AP easy / moderate / hard 45.7 / 39.2 / 31.4 ->
    55.2 / 40.8 / 32.6, at 1.2x the detection time).
    ``cluster_radius``: how far apart (in box widths across, box heights along) two votes of
    one viewpoint may be to join one cluster (:func:`wirescene.predetect.bank.cluster_activations`),
    stored in the bank's meta: the steps after the templates (box regression and refinement,
    ground prior, verifier, calibration) and detection use it. 0.2 rather than the 0.4 of
    earlier banks, chosen on fold group {0, 1}: held out by drive, moderate 2D AP 57.8 ->
    62.5 (fold group {2, 3}: 56.6 -> 58.2; ``benchmarks/RESULTS.md``).
    ``cut_paste``: cars pasted into a composite copy of every training frame (and its
    mirror image; :mod:`wirescene.training.cut_paste`), 0 for none; the composites add
    positives and negatives and are dropped afterwards. It did not help: held out by drive,
    3 pasted cars per frame took the first two folds' moderate AP from 35.4 / 56.6 to
    22.7 / 54.0 (the convex hull of the placed wireframe is not the car's outline, and the
    HOG templates see the seam).
    ``max_negatives``: cap of each configuration's negatives (:class:`~wirescene.training.scale.NegativePool`;
    None: unbounded): random ones by reservoir sampling, after each mining round the
    hardest under the current SVM. The default is above what the 72 shared frames gather
    with the default recipe (144 x (40 + 3 x 15) = 12,240), so it shapes only a bank of more
    frames: from about 80 frames on the random negatives are a uniform sample of all
    frames' windows, and each round keeps the 12,800 windows of highest margin (about 1 GB
    for the 32 configurations at 1.3k floats each, whatever the number of frames).
    ``pad_cells``: columns of empty cells left and right of every pyramid level, so that
    windows reach past the image's sides (DPM's padding, for cars the image truncates;
    stored in the bank's meta, detection pads alike): random and hard negatives are drawn
    from the padded levels, and the cells of a positive past the image's sides are zero.
    ``max_truncated``: the largest KITTI truncation of a full-car positive (0.15 suits
    windows inside the image; with ``pad_cells`` a truncated car is shown as detection sees it).
    ``whiten``: train the templates in whitened HOG (:mod:`wirescene.training.whitening`),
    with background statistics of the training images' pyramid levels at scales up to 1.
    ``align``: latent placement of the positives (DPM's relabelling of root windows): before
    every mining round's fit each positive takes, of its window moved by half a cell and a
    pyramid level either way (:func:`~wirescene.training.detector.alignment_offsets`), the one
    the current template scores highest; the first fit takes the unmoved windows. The 27
    windows of every positive are kept (at most 600 per configuration: about 3 GB for 32
    configurations at 1.5k floats each, whatever the number of frames).
    ``share_deg``: a car whose observation angle lies within this many degrees of its bin's
    edge also trains the neighbouring bin's configurations (viewpoints shared across bins;
    bins sparse enough to borrow both neighbours' cars take no more).
    ``synthetic``: ``(images, examples)`` of rendered scenes (:func:`load_training_frames` of a
    ``wirescene synth`` root), whose cars join the positives only: the negatives, random and
    mined, and the full-box correction come from the real images.
    ``mining_images``: the most training images a mining round searches (None: all of them);
    where there are more, the rounds take consecutive stretches of one random order of the
    images, so that together they search as many different images as they can.
    ``pyramid_cache_mb``: budget of the process's cache of grey images and HOG pyramids
    (:data:`~wirescene.training.scale.CACHE`, set here); the default holds the 72 shared
    frames' (nothing is computed twice), more frames are read and described again in
    every pass. ``workers``: processes of the per-image passes (hard-negative mining), 0 or
    1 serial; the bank is the same.
    """
    say = progress or (lambda msg: None)
    t0 = time.time()
    rng = np.random.default_rng(seed)
    CACHE.resize(pyramid_cache_mb)
    from dataclasses import replace

    corr = learn_full_box_correction(examples)
    n_real_images = len(images)
    if cut_paste:
        from wirescene.training.cut_paste import paste_cars

        extra_images, extra = paste_cars(images, examples, per_image=cut_paste, seed=seed, min_height=min_height,
                                         mirror=mirrored_image)
        images, examples = list(images) + extra_images, list(examples) + extra
        say(f"cut and paste: {len(extra)} pasted cars in {len(extra_images)} composite images")
    negative_images = list(images)
    n_synthetic = 0
    if synthetic is not None:
        synth_images, synth_examples = synthetic
        images = negative_images + list(synth_images)
        examples = list(examples) + [replace(e, image=e.image + len(negative_images)) for e in synth_examples]
        n_synthetic = len(synth_examples)
        say(f"synthetic: {n_synthetic} car examples in {len(synth_images)} rendered images (positives only)")
    apply_full_box(examples, corr)
    if label_boxes:
        # the labelled box is the exact target where it shows the whole car (not truncated,
        # at most partly occluded); the wireframe-derived box elsewhere (amodal extent)
        for e in examples:
            if e.truncated <= 0.0 and e.occ_frac < 0.4:
                e.full_box = e.label_box.astype(float).copy()
    per_bin = np.bincount([e.bin for e in examples], minlength=N_BINS)
    # sparse viewpoints (side views are rare in KITTI) borrow the cars of both neighbouring bins
    examples = list(examples) + [replace(e, bin=b) for b in range(N_BINS) if per_bin[b] < min_bin_examples
                                 for e in examples if e.bin in ((b + 1) % N_BINS, (b - 1) % N_BINS)] + \
        shared_examples(examples, share_deg, skip=per_bin < min_bin_examples)
    configs = select_configurations(examples, n_partial=n_partial, min_height=min_height, full_area=full_area,
                                    partial_area=partial_area)
    say(f"{len(configs)} configurations; car examples per bin {per_bin.tolist()}")
    if not configs:  # else a bank without a detector, which finds nothing, written without a word
        raise InputError(f"no detector can be trained: none of the {int(per_bin.sum())} car examples (labelled cars "
                         f"and their mirror images) is whole (not truncated) and at least {min_height:g} px high")

    # ---- positives
    cands, counts = positive_features(
        configs, examples, lambda e: images[e.image].gray.astype(np.float32) / 255.0, rng, min_height=min_height,
        max_pos=max_pos, min_pos=min_pos, max_jitter=max_jitter, max_occluded=0.35, max_truncated=max_truncated,
        truncated_windows=pad_cells > 0, offsets=alignment_offsets() if align else None)
    pos = [c[:, 0] for c in cands] if align else cands  # the unmoved windows first
    for c, n in zip(configs, counts):
        c.n_examples = n
    say("positives per detector: " + " ".join(str(len(p)) for p in pos) + f" [{time.time() - t0:.0f}s]")

    # ---- random negatives
    H = max(im.size[1] for im in negative_images)
    scales = pyramid_scales(*images[0].size, max_scale=max_scale, per_octave=per_octave)
    reservoir = np.random.default_rng([seed, 1])  # only drawn from once a pool is full
    neg = [NegativePool(max_negatives, reservoir) for _ in configs]
    for im in negative_images:
        sample_random_negatives(neg, im.hog_pyramid(scales), configs, im.block, H=H, min_height=min_height,
                                per_image=neg_per_image, rng=rng, pad_cells=pad_cells)
    say(f"random negatives: {sum(len(n) for n in neg)} [{time.time() - t0:.0f}s]")

    whiteners = None  # one per configuration, for every round's fit
    if whiten:
        from wirescene.training.whitening import background_statistics, whitening_matrix

        step = max(1, len(images) // 8)  # a few images hold the cells' statistics many times over
        levels = [F for im in images[:n_real_images:step] for s, F in im.hog_pyramid(scales) if s <= 1.0]
        background = background_statistics(levels, tuple(np.max([c.template for c in configs], 0)))
        whiteners = [whitening_matrix(background, *c.template) for c in configs]
        say(f"background statistics of {len(levels)} levels [{time.time() - t0:.0f}s]")
    weights, biases = fit_svms(configs, pos, [n.items for n in neg], C=C, seed=seed, whiteners=whiteners)
    bank = DetectorBank(configs, weights, biases)
    rounds_images = mining_subsets(len(negative_images), mining_rounds, mining_images, seed=seed)
    for rnd, subset in enumerate(rounds_images):
        mine = partial(hard_negatives, bank, scales=scales, min_height=min_height, max_height=3.0 * H,
                       per_image=hard_per_image, pad_cells=pad_cells)
        n_new = 0
        mined = [negative_images[i] for i in subset]
        for found in map_images(mine, mined, workers=workers, progress=say, name=f"mining round {rnd + 1}"):
            for t, feats in found:
                for x in feats:
                    neg[t].add_hard(x)
                neg[t].shrink(bank.weights[t], bank.biases[t], slack=1.1)
                n_new += len(feats)
        for t, pool in enumerate(neg):
            pool.shrink(bank.weights[t], bank.biases[t])
        if align:
            pos = align_positives(cands, bank.weights)
        weights, biases = fit_svms(configs, pos, [n.items for n in neg], C=C, seed=seed, whiteners=whiteners)
        bank = DetectorBank(configs, weights, biases)
        say(f"mining round {rnd + 1}: {n_new} hard negatives [{time.time() - t0:.0f}s]")
    bank.meta = {
        "trained_on": "real KITTI frames", "frames": sorted({im.frame for im in images[:n_real_images]}),
        "seed": int(seed), "cut_paste": int(cut_paste),
        "n_partial": int(n_partial), "C": C, "label_boxes": bool(label_boxes), "mining_rounds": int(mining_rounds), "min_height": min_height,
        "max_scale": max_scale, "per_octave": int(per_octave), "box_weight": float(box_weight),
        "cluster_rx": float(cluster_radius), "cluster_ry": float(cluster_radius), "n_positives": [int(len(p)) for p in pos], "n_negatives": [int(len(n)) for n in neg],
        "car_examples_per_bin": per_bin.tolist(), "full_box_correction": np.round(corr, 5).tolist(),
        "train_seconds": round(time.time() - t0, 1),
    }
    if whiten:
        bank.meta["whiten"] = True
    if align:
        bank.meta["align"] = True
    if share_deg:
        bank.meta["share_deg"] = float(share_deg)
    if mining_images is not None and mining_images < len(negative_images):
        bank.meta["mining_images"] = int(mining_images)  # recorded where the cap shaped the bank
    if n_synthetic:
        bank.meta["synthetic_examples"] = int(n_synthetic)
    if pad_cells:  # recorded where set: older banks and their detection stay as they were
        bank.meta.update(pad_cells=int(pad_cells), max_truncated=float(max_truncated))
    if any(n.offered > len(n) or len(n) == max_negatives for n in neg):
        bank.meta["max_negatives"] = int(max_negatives)  # recorded where the cap shaped the bank
    return bank


def shared_examples(examples, share_deg: float, *, skip) -> list:
    """Copies, in the neighbouring bin, of the ``examples`` whose ``alpha`` lies within
    ``share_deg`` degrees of their bin's edge; none for a neighbour marked in ``skip`` ``(8,)``
    or an example of unknown angle."""
    from dataclasses import replace

    if share_deg <= 0:
        return []
    out = []
    for e in examples:
        off = float(wrap_angle(e.alpha - bin_center(e.bin)))  # nan when unknown: never near an edge
        if abs(off) > BIN_WIDTH / 2 - np.radians(share_deg):
            b = (e.bin + (1 if off > 0 else -1)) % N_BINS
            if not skip[b]:
                out.append(replace(e, bin=b))
    return out


def hard_negatives(bank: DetectorBank, image: TrainImage, *, scales, min_height: float, max_height: float,
                   per_image: int, pad_cells: int = 0) -> list:
    """``[(configuration, (k, D) descriptors)]``: the ``per_image`` best-scoring windows of
    each configuration in ``image`` (margin above -1) overlapping no blocked box by more
    than 30% of the window (one pass of hard-negative mining); ``pad_cells`` as
    :func:`~wirescene.predetect.bank.score_pyramid` takes it."""
    pyramid = image.hog_pyramid(scales)
    act = score_pyramid(bank, pyramid, threshold=-1.0, top_k=40, min_height=min_height, max_height=max_height,
                        pad_cells=pad_cells)
    pyramid = pad_pyramid(pyramid, pad_cells)  # the cells act.cell indexes
    if not len(act.det):
        return []
    ok = _overlap_frac(act.boxes, image.block) <= 0.3
    out = []
    for t in np.unique(act.det[ok]):
        sel = np.flatnonzero(ok & (act.det == t))
        sel = sel[np.argsort(-act.scores[sel])[:per_image]]
        th, tw = bank.configs[t].template
        out.append((int(t), [pyramid[act.level[k]][1][r:r + th, q:q + tw].flatten() for k, (r, q) in
                             zip(sel, act.cell[sel])]))
    return out


# --------------------------------------------------------------------------- calibration


def detection_labels(boxes, gt_boxes, *, iou: float = 0.5) -> np.ndarray:
    """(D,) 1 where a detection (in descending score order) is the first to match a car
    with IoU >= ``iou``, else 0 (duplicates are 0)."""
    from wirescene.core.boxes import iou_2d

    boxes = np.asarray(boxes, float).reshape(-1, 4)
    gt_boxes = np.asarray(gt_boxes, float).reshape(-1, 4)
    y = np.zeros(len(boxes), int)
    used = np.zeros(len(gt_boxes), bool)
    for d in range(len(boxes)):
        if not len(gt_boxes):
            break
        ov = np.where(used, -1.0, iou_2d(boxes[d][None], gt_boxes))
        j = int(np.argmax(ov))
        if ov[j] >= iou:
            used[j] = True
            y[d] = 1
    return y


def fit_platt(scores, labels, *, reg: float = 1.0, offset=None, verifier=None) -> np.ndarray:
    """``(a, b)`` of ``P(car) = 1 / (1 + exp(-(a * score + b + offset)))`` by (lightly
    L2-regularised) logistic regression with Platt's target smoothing; ``a`` is forced
    positive so that calibration never reorders detections of equal ``offset`` (the ground
    prior's log ratio of each detection, :meth:`DetectorBank.ground_log_ratio`; None: 0).
    With ``verifier`` (each detection's verifier log-odds, :func:`wirescene.predetect.bank.verification_logits`)
    ``(a, b, c)`` of ``a * score + b + c * verifier + offset``, ``c`` >= 0 as well."""
    from scipy.optimize import minimize

    s = np.asarray(scores, float)
    y = np.asarray(labels, float)
    off = np.zeros(len(s)) if offset is None else np.asarray(offset, float)
    v = None if verifier is None else np.asarray(verifier, float)
    n1, n0 = y.sum(), len(y) - y.sum()
    t = np.where(y > 0, (n1 + 1) / (n1 + 2), 1 / (n0 + 2))

    def nll(p):
        z = p[0] * s + p[1] + off + (0.0 if v is None else p[2] * v)
        return np.sum(np.logaddexp(0, z) - t * z) + 0.5 * reg * p[0] ** 2 * 1e-3

    start, bounds = [1.0, 0.0], [(1e-3, None), (None, None)]
    if v is not None:
        start, bounds = start + [0.0], bounds + [(0.0, None)]
    p = minimize(nll, np.array(start), method="L-BFGS-B", bounds=bounds).x
    return p.astype(float)


def kitti_gt_boxes(labels) -> np.ndarray:
    """Boxes of a frame's ``Car`` labels (:data:`~wirescene.core.labels.CAR_TYPES`, any case)."""
    return np.array([o.box for o in labels.of_type(*CAR_TYPES)], float).reshape(-1, 4)


def training_gt_boxes(dataset, images) -> list:
    """The ``Car`` boxes of every training image (mirrored for the flipped copies)."""
    out = []
    for im in images:
        gt = kitti_gt_boxes(dataset.labels(im.frame))
        out.append(mirrored_boxes(gt, im.size[0]) if im.flipped else gt)
    return out


def training_clusters(bank: DetectorBank, image: TrainImage):
    """The vote clusters of a training image (:func:`~wirescene.predetect.bank.pyramid_clusters`
    on its cached pyramid, every cluster kept): the costly half of a detection, which depends
    only on the bank's templates and clustering options, so that the passes of
    :func:`finish_bank`, which change only the steps after them, compute it once."""
    W, H = image.size
    return pyramid_clusters(bank, image.hog_pyramid(bank_scales(bank, W, H)), (W, H),
                            min_height=float(bank.meta.get("min_height", 30.0)))


def detect_training_image(bank: DetectorBank, image: TrainImage, *, clusters=None, **kw):
    """Raw (uncalibrated, unthresholded) detections of a training image from its (cached)
    pyramid, or from its ``clusters`` (:func:`training_clusters` of a bank with the same
    templates and clustering options: the same detections, without the pyramid)."""
    W, H = image.size
    gray = None if bank.refinement is None and bank.verifier is None else image.gray.astype(np.float32) / 255.0
    channels = image.channels if bank.needs_channels else None
    if clusters is not None:
        return finish_clusters(clusters, bank, (W, H), threshold=None, gray=gray, channels=channels, **kw)
    pyramid = image.hog_pyramid(bank_scales(bank, W, H))
    kw.setdefault("min_height", float(bank.meta.get("min_height", 30.0)))
    return detect_pyramid(bank, pyramid, (W, H), calibrated=False, threshold=None, gray=gray, channels=channels, **kw)


def _detect_with_clusters(bank: DetectorBank, item, **kw):
    image, clusters = item
    return detect_training_image(bank, image, clusters=clusters, **kw)


def training_detections(bank: DetectorBank, images, *, clusters=None, workers: int = 1, progress=None,
                        name: str = "detections", **kw):
    """:func:`detect_training_image` of every image, in order, in ``workers`` processes
    (:func:`~wirescene.training.scale.map_images`), from each image's ``clusters`` where
    given (a list in the order of ``images``); an iterator."""
    if clusters is None:
        return map_images(partial(detect_training_image, bank, **kw), images, workers=workers, progress=progress,
                          name=name)
    return map_images(partial(_detect_with_clusters, bank, **kw), list(zip(images, clusters)), workers=workers,
                      progress=progress, name=name)


def _matched(boxes, gt, min_iou: float):
    """``(keep (D,) bool, targets (k, 4))``: which of ``boxes`` ``(D, 4)`` overlap a box of
    ``gt`` ``(K, 4)`` with IoU >= ``min_iou``, and the best-overlapping one of each."""
    from wirescene.core.boxes import iou_2d

    ov = iou_2d(boxes[:, None, :], gt[None])
    best = np.argmax(ov, axis=1)
    keep = ov[np.arange(len(best)), best] >= min_iou
    return keep, gt[best[keep]]


def _side_offsets(moved, target) -> np.ndarray:
    """``(D, 4)`` offset of each side of boxes ``moved`` to ``target`` in units of the moved
    box's width / height, clipped to +-0.5: the box regressions' targets."""
    w, h = moved[:, 2] - moved[:, 0], moved[:, 3] - moved[:, 1]
    return np.clip((target - moved) / np.column_stack([w, h, w, h]), -0.5, 0.5)


def fit_box_regression(bank: DetectorBank, images, gt_boxes, *, reg: float = 10.0, min_iou: float = 0.5,
                       clusters=None, workers: int = 1, progress=None) -> dict:
    """The bank's box regression (:func:`wirescene.predetect.bank.apply_box_regression`)
    by ridge regression on its own detections of ``images`` (``TrainImage``; without any
    regression) that overlap a box of ``gt_boxes`` (one ``(K, 4)`` array per image) with
    IoU >= ``min_iou``: targets are each side's offset to the best-overlapping box in
    units of the detection's width or height (clipped to +-0.5). ``reg`` is the ridge
    weight on everything but the constant. ``clusters``, ``workers``, ``progress``: of the detection
    pass (:func:`training_detections`)."""
    from dataclasses import replace

    from wirescene.predetect.bank import REGRESSION_FEATURES, regression_features

    plain = replace(bank, meta={k: v for k, v in bank.meta.items() if k != "box_regression"}, refinement=None)
    X, T = [], []
    gt_boxes = [np.asarray(gt, float).reshape(-1, 4) for gt in gt_boxes]
    with_cars = [i for i, gt in enumerate(gt_boxes) if len(gt)]
    found = training_detections(plain, [images[i] for i in with_cars], workers=workers, progress=progress,
                                clusters=None if clusters is None else [clusters[i] for i in with_cars],
                                name="box regression")
    for i, det in zip(with_cars, found):
        im, gt = images[i], gt_boxes[i]
        if not len(det):
            continue
        keep, g = _matched(det.boxes, gt, min_iou)
        if not keep.any():
            continue
        d = det.boxes[keep]
        T.append(_side_offsets(d, g))
        X.append(regression_features(d, viewpoint_bin(det.alpha[keep]), im.size))
    F = len(REGRESSION_FEATURES)
    if not X:
        return {"weights": np.zeros((F, 4)).tolist(), "features": list(REGRESSION_FEATURES), "n": 0}
    X, T = np.concatenate(X), np.concatenate(T)
    penalty = np.full(F, float(reg))
    penalty[0] = 0.0
    weights = np.linalg.solve(X.T @ X + np.diag(penalty), X.T @ T)
    return {"weights": weights.tolist(), "features": list(REGRESSION_FEATURES), "n": int(len(X)), "reg": float(reg)}


def image_cars(dataset, image: TrainImage) -> tuple[np.ndarray, np.ndarray]:
    """``(boxes (K, 4), alpha (K,))`` of the ``Car`` labels of a training image, mirrored
    (:func:`~wirescene.predetect.configurations.mirror_alpha`) for a flipped copy."""
    cars = dataset.labels(image.frame).of_type(*CAR_TYPES)
    boxes = np.array([o.box for o in cars], float).reshape(-1, 4)
    alpha = np.array([o.alpha for o in cars], float)
    if image.flipped:
        boxes, alpha = mirrored_boxes(boxes, image.size[0]), mirror_alpha(alpha)
    return boxes, alpha


def fit_box_refinement(bank: DetectorBank, images, dataset, *, jitter: int = 20, sigma: float = 0.12,
                       reg: float = 1e5, min_iou: float = 0.4, per_image: int = 60, min_height: float = 20.0,
                       seed: int = 0, max_rows: int | None = DEFAULT_MAX_REFINEMENT_ROWS, clusters=None,
                       workers: int = 1, progress=None) -> dict:
    """The bank's image-based box refinement (:mod:`wirescene.predetect.refine`), a ridge
    regression (weight ``reg`` on standardised features) fitted on ``images``
    (``TrainImage``, flipped copies included) from two sources: ``jitter`` copies of every
    labelled car at least ``min_height`` px high, each side moved by a normal offset of
    ``sigma`` of the box size (clipped to 40%), and the bank's own detections (with its box
    regression, without refinement; best ``per_image``) overlapping a car with IoU >=
    ``min_iou``. Targets: each side's offset to the car's box in units of the moved box's
    width / height, clipped to +-0.5. ``sigma`` and ``reg`` were chosen among 6 settings
    on the held-out folds (0.08-0.16 x 3e4-1e5: all gained 2.6-7.4 points of moderate AP).
    ``max_rows``: at most that many rows, a uniform sample (:class:`~wirescene.training.scale.RowSample`;
    the 72 shared frames give 11,572, below the default, so memory stops growing at about
    16k x 12 kB = 0.2 GB, and the ridge fit adds only its normal equations). ``clusters``
    (:func:`training_detections`), ``workers``, ``progress``: of the per-image pass (the bank's
    detections and every row's features)."""
    from dataclasses import replace

    from wirescene.predetect.refine import fit_ridge

    rng = np.random.default_rng(seed)
    plain = replace(bank, refinement=None)
    rows = RowSample(max_rows, seed=seed)
    # the jittered copies are drawn here in image order (the random stream of a serial pass);
    # the detections and every row's features are computed per image, in the workers
    tasks = []
    for i, im in enumerate(images):
        boxes, alpha = image_cars(dataset, im)
        jittered = []
        for g, a in zip(boxes, alpha):
            size = np.array([g[2] - g[0], g[3] - g[1]] * 2)
            if size[1] < min_height:
                continue
            moved = g - np.clip(rng.normal(0.0, sigma, (jitter, 4)), -0.4, 0.4) * size
            ok = np.all(moved[:, 2:] - moved[:, :2] > 8, axis=1)
            if ok.any():
                jittered.append((moved[ok], g, np.full(int(ok.sum()), viewpoint_bin(a))))
        tasks.append((im, boxes, jittered, None if clusters is None else clusters[i]))
    rows_of = partial(_refinement_rows, plain, per_image=per_image, min_iou=min_iou)
    for found in map_images(rows_of, tasks, workers=workers, progress=progress, name="box refinement"):
        for X, T in found:
            rows.add(X, T)
    if not rows.n:
        raise ValueError("no training cars for the box refinement")
    X, T = rows.arrays()
    out = fit_ridge(X, T, reg)
    out["n"] = int(len(X))
    if rows.offered > len(X):
        out["sampled_from"] = int(rows.offered)  # recorded where the cap shaped the refinement
    return out


def _refinement_rows(bank: DetectorBank, task, *, per_image: int, min_iou: float) -> list:
    """``[(features (k, F) float32, side offsets (k, 4))]`` of one image of
    :func:`fit_box_refinement`: its jittered cars in order, then its matched detections."""
    from wirescene.predetect.bank import regression_features
    from wirescene.predetect.refine import refinement_features

    image, boxes, jittered, clusters = task
    gray = image.gray.astype(np.float32) / 255.0

    def rows(moved, target, bins):
        X = refinement_features(gray, moved, regression_features(moved, bins, gray.shape[::-1])).astype(np.float32)
        return X, _side_offsets(moved, target)

    out = [rows(*j) for j in jittered]
    det = detect_training_image(bank, image, clusters=clusters)
    d = det.boxes[:per_image]
    if len(d) and len(boxes):
        keep, targets = _matched(d, boxes, min_iou)
        if keep.any():
            out.append(rows(d[keep], targets, viewpoint_bin(det.alpha[:per_image][keep])))
    return out


def fit_bank_ground_prior(bank: DetectorBank, images, dataset, *, per_image: int = 30,
                          max_overlap: float = 0.1, detections=None, workers: int = 1, progress=None) -> dict:
    """The bank's ground prior (:mod:`wirescene.predetect.geometry`) from its training
    images: the ``Car`` labels' boxes (each frame once) against the ``per_image``
    best-scoring detections (with the bank's box regression and refinement, without any ground term) that
    overlap no labelled object or DontCare region by more than ``max_overlap`` IoU.
    ``detections``: those of every image (a list in the order of ``images``; None: detected
    here); ``workers``, ``progress``: of the detection pass (:func:`training_detections`)."""
    from wirescene.core.boxes import iou_2d

    cars, background, seen = [], [], set()
    for im in images:
        if im.horizon is None:
            raise ValueError(f"training image {im.frame} has no horizon (camera) for the ground prior")
    if detections is None:
        detections = training_detections(bank, images, workers=workers, progress=progress, name="ground prior")
    for im, det in zip(images, detections):
        if im.frame not in seen:
            seen.add(im.frame)
            cars.append(bottom_ratio(kitti_gt_boxes(dataset.labels(im.frame)), im.horizon))
        boxes = det.boxes[:per_image]
        if len(boxes) and len(im.block):
            boxes = boxes[iou_2d(boxes[:, None], im.block[None]).max(1) <= max_overlap]
        background.append(bottom_ratio(boxes, im.horizon))
    return fit_ground_prior(np.concatenate(cars), np.concatenate(background))


def fit_bank_verifier(bank: DetectorBank, images, dataset, *, per_image: int = 150, max_rows: int | None = 40_000,
                      C: float = VERIFIER_C, car_iou: float = 0.5, view_groups: bool = False,
                      channels: bool = VERIFIER_CHANNELS, seed: int = 0, detections=None, workers: int = 1,
                      progress=None) -> dict:
    """The bank's verifier (:mod:`wirescene.predetect.verifier`), fitted on the rows of
    :func:`verifier_training_rows` (the same options): one regression for all boxes, or with
    ``view_groups`` one per viewpoint group (:data:`~wirescene.predetect.verifier.VIEW_GROUPS`;
    a study, not adopted: ``benchmarks/RESULTS.md``); with ``channels`` it also reads the
    boxes' colour channels (:mod:`wirescene.predetect.channels`). The returned verifier's
    ``gain`` is 0 until a calibration sets it (:func:`set_calibration`)."""
    from wirescene.predetect.verifier import VIEW_GROUPS, fit_verifier

    X, y, bins, offered = verifier_training_rows(bank, images, dataset, per_image=per_image, max_rows=max_rows,
                                                 car_iou=car_iou, channels=channels, seed=seed,
                                                 detections=detections, workers=workers, progress=progress)
    out = fit_verifier(X, y, C=C, groups=VIEW_GROUPS[bins] if view_groups else None)
    out["gain"] = np.float32(0.0)
    out["channels"] = bool(channels)
    out["n"], out["n_car"] = int(len(y)), int(y.sum())
    if offered > len(y):
        out["sampled_from"] = int(offered)  # recorded where the cap shaped the verifier
    return out


def verifier_training_rows(bank: DetectorBank, images, dataset, *, per_image: int = 150,
                           max_rows: int | None = 40_000, car_iou: float = 0.5, channels: bool = VERIFIER_CHANNELS,
                           seed: int = 0, detections=None, workers: int = 1,
                           progress=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(features (N, F) float32, labels (N,), viewpoint bins (N,), rows offered)`` the
    bank's verifier trains on, from its training ``images`` (flipped copies included): the
    ``per_image`` best-scoring detections of each (with the bank's box regression and
    refinement, no ground term, no verifier), a car where one overlaps a ``Car`` label at IoU
    >= ``car_iou``, left out where it overlaps another labelled object or DontCare region
    that much (a Van is neither car nor background), and the labelled cars' own boxes with
    one copy jittered by 5% of their size per side, as further cars (the copy as a car where
    it keeps IoU >= ``car_iou``); with ``channels``, the features include the boxes' colour
    channels (:func:`~wirescene.predetect.verifier.verifier_features`). ``max_rows``: a
    uniform sample of at most that many rows (:class:`~wirescene.training.scale.RowSample`).
    ``detections``: the bank's detections of every image (without its verifier; a list in the
    order of ``images``; None: detected here); ``workers``, ``progress``: of the per-image pass."""
    from dataclasses import replace

    rng = np.random.default_rng([seed, 11])
    plain = replace(bank, verifier=None)
    tasks = []
    for i, im in enumerate(images):
        boxes, alpha = image_cars(dataset, im)
        size = np.tile(np.column_stack([boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]]), 2)
        moved = boxes + np.clip(rng.normal(0.0, 0.05, boxes.shape), -0.2, 0.2) * size
        tasks.append((im, boxes, np.concatenate([boxes, moved]), np.tile(viewpoint_bin(alpha), 2),
                      None if detections is None else detections[i]))
    rows = RowSample(max_rows, seed=seed)
    for X, y, bins in map_images(partial(_verifier_rows, plain, per_image=per_image, car_iou=car_iou,
                                         channels=channels), tasks,
                                 workers=workers, progress=progress, name="verifier"):
        rows.add(X, y, bins)
    X, y, bins = rows.arrays()
    return X, y, bins, int(rows.offered)


def _verifier_rows(bank: DetectorBank, task, *, per_image: int, car_iou: float = 0.5, channels: bool = False):
    """``(features (k, F) float32, labels (k,), bins (k,))`` of one image of :func:`verifier_training_rows`."""
    from wirescene.core.boxes import iou_2d
    from wirescene.predetect.bank import regression_features
    from wirescene.predetect.verifier import verifier_features

    image, cars, positives, positive_bins, det = task
    gray = image.gray.astype(np.float32) / 255.0
    det = detect_training_image(bank, image) if det is None else det
    boxes, bins = det.boxes[:per_image], viewpoint_bin(det.alpha[:per_image])
    y = np.zeros(len(boxes), int)
    if len(boxes) and len(cars):
        y = (iou_2d(boxes[:, None], cars[None]).max(1) >= car_iou).astype(int)
    if len(boxes) and len(image.block):
        ambiguous = (y == 0) & (iou_2d(boxes[:, None], image.block[None]).max(1) >= 0.5)
        boxes, bins, y = boxes[~ambiguous], bins[~ambiguous], y[~ambiguous]
    boxes, bins = np.concatenate([boxes, positives]), np.concatenate([bins, positive_bins]).astype(int)
    y = np.concatenate([y, (iou_2d(positives[:, None], cars[None]).max(1) >= car_iou).astype(int) if len(positives)
                        else np.zeros(0, int)])
    X = verifier_features(gray, boxes, regression_features(boxes, bins, image.size),
                          channels=image.channels if channels else None)
    return X.astype(np.float32), y, bins


def fit_bank_viewpoint_prior(images, dataset) -> dict:
    """The viewpoint prior (:mod:`wirescene.predetect.viewpoint_prior`) of the ``Car`` labels
    of the frames of ``images`` (their unmirrored originals, at each one's horizon and
    principal column; never a mirrored copy: mirroring swaps the sides of the traffic)."""
    lateral, bins = [], []
    for im in images:
        if im.flipped or im.composite:
            continue
        cars = dataset.labels(im.frame).of_type(*CAR_TYPES)
        if cars:
            lateral.append(lateral_position(np.array([o.box for o in cars], float), im.horizon, im.center_column))
            bins.append(viewpoint_bin(np.array([o.alpha for o in cars], float)))
    if not lateral:
        raise ValueError("no labelled cars for the viewpoint prior")
    return fit_viewpoint_prior(np.concatenate(lateral), np.concatenate(bins))


def finish_bank(bank: DetectorBank, images, dataset, *, support_weight: float | None = None, workers: int = 1,
                progress=None) -> DetectorBank:
    """The steps after the SVMs, on the bank's own training images: the box regression
    (:func:`fit_box_regression`), the box refinement (:func:`fit_box_refinement`), the
    ground prior (:func:`fit_bank_ground_prior`) of the refined boxes, the viewpoint
    prior of the labelled cars (:func:`fit_bank_viewpoint_prior`) and the verifier
    (:func:`add_verifier`); they detect without a vote count, and ``support_weight`` (None:
    the bank's meta left as it is) is stored last, for the bank's own detections
    (:func:`~wirescene.predetect.bank.merge_activations`). ``workers``: processes of their
    detection passes (0 or 1 serial; the bank is the same).

    The templates do not change after the SVMs, so each image's vote clusters
    (:func:`training_clusters`) are computed once, in the first pass, and every later pass
    finishes its detections from them; the ground prior and the verifier read the same
    detections (with the box regression and refinement), made once. The bank is the one
    four separate detection passes give, array for array."""
    say = progress or (lambda msg: None)
    passes = dict(workers=workers, progress=say)
    clusters = list(map_images(partial(training_clusters, bank), images, name="vote clusters", **passes))
    bank.meta["box_regression"] = fit_box_regression(bank, images, training_gt_boxes(dataset, images),
                                                     clusters=clusters, **passes)
    say(f"box regression fitted on {bank.meta['box_regression']['n']} detections")
    # a handful of training frames may hold too few cars for either; the bank then goes without
    try:
        refinement = fit_box_refinement(bank, images, dataset, clusters=clusters, **passes)
    except ValueError as exc:
        say(f"no box refinement: {exc}")
    else:
        bank.meta["box_refinement"] = {"n": refinement.pop("n"), "features": int(len(refinement["mean"]))}
        if "sampled_from" in refinement:
            bank.meta["box_refinement"]["sampled_from"] = refinement.pop("sampled_from")
        bank.refinement = refinement
        say(f"box refinement fitted on {bank.meta['box_refinement']['n']} boxes")
    # what the ground prior and the verifier read: the detections with the regression and the
    # refinement, before any verifier (a bank given with one keeps the passes apart)
    shared = None
    if bank.verifier is None:
        shared = list(training_detections(bank, images, clusters=clusters, name="detections", **passes))
    del clusters
    try:
        gp = bank.meta["ground_prior"] = fit_bank_ground_prior(bank, images, dataset, detections=shared, **passes)
    except ValueError as exc:
        say(f"no ground prior: {exc}")
    else:
        say(f"ground prior: cars r = {gp['car'][0]:.2f} +- {gp['car'][1]:.2f} ({gp['n_car']}), "
            f"background {gp['background'][0]:.2f} +- {gp['background'][1]:.2f} ({gp['n_background']})")
    try:
        vp = bank.meta["viewpoint_prior"] = fit_bank_viewpoint_prior(images, dataset)
    except ValueError as exc:
        say(f"no viewpoint prior: {exc}")
    else:
        say(f"viewpoint prior: {vp['n']} cars, bandwidth {vp['bandwidth']:.2f} camera heights")
    add_verifier(bank, images, dataset, detections=shared, **passes)
    if support_weight is not None:
        bank.meta["support_weight"] = float(support_weight)
    return bank


def add_verifier(bank: DetectorBank, images, dataset, *, car_iou: float = 0.5, view_groups: bool = False,
                 channels: bool = VERIFIER_CHANNELS, detections=None, workers: int = 1,
                 progress=None) -> DetectorBank:
    """Fit the bank's verifier (:func:`fit_bank_verifier`; ``detections`` as there) on its
    training ``images``, the last step of :func:`finish_bank` (nothing before it reads the
    verifier); its gain stays 0 until a calibration sets it (:func:`set_calibration`)."""
    say = progress or (lambda msg: None)
    try:
        verifier = fit_bank_verifier(bank, images, dataset, car_iou=car_iou, view_groups=view_groups,
                                     channels=channels, detections=detections, workers=workers, progress=say)
    except ValueError as exc:
        say(f"no verifier: {exc}")
        return bank
    bank.meta["verifier"] = {k: verifier.pop(k) for k in ("n", "n_car", "sampled_from") if k in verifier}
    if np.ndim(verifier["weights"]) == 2:
        bank.meta["verifier"]["view_groups"] = len(verifier["weights"])  # recorded where the study's option is on
    bank.verifier = verifier
    say(f"verifier fitted on {bank.meta['verifier']['n']} boxes ({bank.meta['verifier']['n_car']} cars)")
    return bank


def set_calibration(bank: DetectorBank, params) -> DetectorBank:
    """Give ``bank`` the calibration ``params``: Platt ``(a, b)``, or ``(a, b, c)`` for a
    bank with a verifier, whose logit then adds ``c / a`` of itself to every margin (so
    that ``confidence = sigmoid(a * margin + b)`` reads ``a * margin + b + c * logit``)."""
    p = check_calibration(params)
    if (len(p) == 3) != (bank.verifier is not None):
        raise ValueError(f"a bank {'with' if bank.verifier is not None else 'without'} a verifier takes "
                         f"{'3' if bank.verifier is not None else '2'} calibration numbers, got {len(p)}")
    bank.calibration = p[:2].copy()
    if bank.verifier is not None:
        bank.verifier["gain"] = np.float32(p[2] / p[0])
    return bank


def check_calibration(params, *, size: int | None = None) -> np.ndarray:
    """``params`` as a float array if they are a calibration :func:`set_calibration` takes:
    ``(a, b)`` or ``(a, b, c)`` (``size`` numbers where given), finite, ``a > 0`` and
    ``c >= 0``; else a ``ValueError``."""
    try:
        p = np.asarray(params, float).ravel()
    except (TypeError, ValueError):
        p = np.zeros(0)
    if p.shape not in ((2,), (3,)) or not np.all(np.isfinite(p)) or p[0] <= 0 or (len(p) == 3 and p[2] < 0):
        raise ValueError(f"a calibration is [a, b] or [a, b, c], finite numbers with a > 0 and c >= 0; got {params!r}")
    if size is not None and len(p) != size:
        raise ValueError(f"a calibration of a bank {'with' if size == 3 else 'without'} a verifier is "
                         f"{'[a, b, c]' if size == 3 else '[a, b]'}; got {params!r}")
    return p


def calibration_record(params, **extra) -> dict:
    """``{"a", "b"[, "c"], **extra}`` of calibration ``params`` (as :func:`set_calibration` takes them)."""
    return {**dict(zip("abc", (float(v) for v in np.asarray(params, float).ravel()))), **extra}


def heldout_rows(bank: DetectorBank, image: TrainImage, det, dataset) -> tuple:
    """``(margins, labels, ground offsets, verifier logits)`` of one held-out image's
    detections ``det`` (raw margins of ``bank``), for :func:`fit_platt`."""
    from wirescene.predetect.bank import verification_logits

    y = detection_labels(det.boxes, kitti_gt_boxes(dataset.labels(image.frame)))
    logits = np.zeros(len(det.boxes))
    if bank.verifier is not None:
        logits = verification_logits(bank, image.gray.astype(np.float32) / 255.0, det.boxes, viewpoint_bin(det.alpha),
                                     channels=image.channels if bank.needs_channels else None)
    return det.scores, y, bank.ground_log_ratio(det.boxes, image.horizon), logits


def mirrored_boxes(boxes, width: int) -> np.ndarray:
    """Boxes ``(K, 4)`` of an image mirrored horizontally (``width`` px wide)."""
    b = np.asarray(boxes, float).reshape(-1, 4).copy()
    b[:, [0, 2]] = (width - 1) - b[:, [2, 0]]
    return b


def frames_in_folds(frame_ids, folds) -> list[str]:
    """The frames of ``frame_ids`` that lie in the :mod:`wirescene.io.folds` folds ``folds``,
    in their order (``train detector --folds``).

    Parameters
    ----------
    frame_ids : iterable of str
        Frame ids, each one of the shared frames (:func:`wirescene.io.folds.frame_drives`),
        whose drives the folds are made of.
    folds : iterable of int
        Fold numbers.

    Returns
    -------
    list of str

    Raises
    ------
    ArgumentError
        Naming ``folds``: a frame is not one of the shared frames, or none lies in ``folds``.

    Examples
    --------
    >>> frames_in_folds(["000002", "000010"], [3])  # 000002 is of fold 0
    ['000010']
    """
    from wirescene.io.folds import fold_of, frame_drives

    ids, wanted = list(frame_ids), set(folds)
    unknown = [f for f in ids if f not in frame_drives()]
    if unknown:  # the study's folds are those of the shared frames' drives
        raise ArgumentError("folds", f"frame {unknown[0]} is not one of the shared frames, whose drives the folds "
                                     "are made of (--folds is for their studies)")
    kept = [f for f in ids if fold_of(f) in wanted]
    if not kept:
        raise ArgumentError("folds", f"none of the {len(ids)} frame(s) given lies in folds {sorted(wanted)} (--folds)")
    return kept


@single_threaded
def train_detector_bank_kitti(out_path, kitti_root, *, frames=None, folds=None, split: str | None = None,
                              seed: int = 0, calibration_folds: bool | Mapping[str, int] = True, calibration=None,
                              threshold: float = 0.5, support_weight: float = SUPPORT_WEIGHT, workers: int = 1,
                              drives: Mapping[str, str] | None = None, progress=None, **train_kw):
    """``wirescene train detector --kitti-root``: train on the labelled frames of a KITTI root.

    ``frames``: frame ids to train on (default all); ``folds``: restrict to the frames of
    these :mod:`wirescene.io.folds` folds. With ``calibration_folds`` the Platt calibration
    and default threshold come from held-out detections (:func:`heldout_bank_calibration`)
    over the folds of :func:`calibration_folds` (drives, else frames, balanced by cars), or
    over a given ``{frame: fold}`` mapping; frames of a single group (one drive) cannot
    hold any out, an :class:`InputError` (give a ``calibration``, or
    ``calibration_folds=False`` for an uncalibrated bank). ``calibration``: given Platt
    ``(a, b, c)`` (``c``: the verifier's weight, :func:`set_calibration`) -- e.g. the pooled
    held-out fit printed by ``benchmarks/bench_predetect.py`` for the same recipe -- instead
    of the leave-one-fold-out run (saves four trainings).
    ``threshold``: default detection threshold of a calibrated bank (probability).
    ``support_weight``: stored in the finished bank's meta by :func:`finish_bank` (its
    detections, the held-out calibration's included, score a cluster by its best vote plus
    this weight times the log of its number of votes); the steps before detect without it,
    as the study that chose it did.
    ``workers``: processes of the per-image passes (:func:`train_bank_on_frames`,
    :func:`finish_bank`, :func:`heldout_bank_calibration`); the bank is the same.
    ``drives``: ``{frame: drive}`` grouping the calibration's folds (default
    :func:`wirescene.io.folds.frame_drives`; :func:`wirescene.io.folds.drive_map` adds a
    user's devkit mapping).
    The bank records the SHA-256 of the images of the frames it learnt from, its held-out
    calibration's included (:attr:`~wirescene.predetect.bank.DetectorBank.trained_images`).
    Returns ``(bank, report)``.
    """
    from wirescene.io.kitti import KittiDataset

    say = progress or (lambda msg: None)
    t0 = time.time()
    ds = KittiDataset(kitti_root, split=split)
    ds.require_labels("training")
    ids = list(frames) if frames else ds.frame_ids()
    if folds is not None:
        ids = frames_in_folds(ids, folds)
    if not ids:
        raise ArgumentError("frames", "no training frames selected")
    if not any(ds.car_counts(ids).values()):  # else an empty bank, written without a word
        raise InputError(f"none of the {len(ids)} training frame(s) has a labelled Car to learn from", path=ds.split_dir)
    report = {"frames": ids}
    learnt = list(ids)  # the frames it learns from, with those of its held-out calibration
    # the recipe trains a verifier (finish_bank), weighted by the calibration's third number
    calib = None if calibration is None else check_calibration(calibration, size=3)
    if calib is not None:
        report["calibration"] = calibration_record(calib, source="given")
    elif calibration_folds:
        folds = calibration_folds if isinstance(calibration_folds, Mapping) else _frame_folds(ds, ids, drives)
        if folds is None:
            raise InputError(f"the {len(ids)} training frames form a single group (one drive), so no held-out "
                             "calibration can be fitted: give one (--calibration A,B,C) or train an uncalibrated "
                             "bank (--no-calibration)", path=ds.split_dir)
        else:
            report["calibration"] = heldout_bank_calibration(kitti_root, folds, split=split, seed=seed, progress=say,
                                                             workers=workers, support_weight=support_weight,
                                                             **train_kw)
            calib = np.array([report["calibration"][k] for k in "abc" if k in report["calibration"]])
            learnt += sorted(set(folds) - set(ids))
    # loaded after the calibration, whose fold banks load their own frames
    images, examples = load_training_frames(ds, ids, progress=say)
    bank = train_bank_on_frames(images, examples, seed=seed, workers=workers, progress=say, **train_kw)
    bank = finish_bank(bank, images, ds, support_weight=support_weight, workers=workers, progress=say)
    if calib is not None:
        if bank.verifier is None and len(calib) == 3:
            say("the bank has no verifier: the calibration's c goes unused")
            calib = calib[:2]
        elif bank.verifier is not None and len(calib) == 2:  # a held-out fold bank had none to weigh
            say("the held-out calibration has no weight for the verifier: the bank goes without one")
            bank.verifier = None
            bank.meta.pop("verifier", None)
        set_calibration(bank, calib)
        bank.threshold = float(threshold)  # probability of a true car (IoU >= 0.5)
    bank.meta["calibration"] = report.get("calibration")
    # by which an evaluation on these frames says that its figures are not held out
    bank.trained_images = images_sha256(ds.image_path, learnt)
    if out_path is not None:
        bank.save(out_path)
        say(f"saved {len(bank)} detectors to {out_path} ({Path(out_path).stat().st_size / 1e6:.2f} MB)")
    report.update(n_detectors=len(bank), names=[c.name for c in bank.configs], total_seconds=round(time.time() - t0, 1))
    return bank, report


def calibration_folds(dataset, frames: list[str], *, n_folds: int = 4,
                      drives: Mapping[str, str] | None = None) -> dict[str, int]:
    """``{frame: fold}`` of the held-out calibrations: groups of frames by drive (``drives``,
    default :func:`wirescene.io.folds.frame_drives`; a frame of unknown drive alone), dealt
    to ``min(n_folds, groups)`` folds balanced by their cars. An :class:`InputError` if
    there are fewer than two groups."""
    from wirescene.io.folds import assign_folds, drive_groups

    group = drive_groups(frames, drives)
    cars: dict[str, int] = {}
    for f, n in dataset.car_counts(frames).items():
        cars[group[f]] = cars.get(group[f], 0) + n
    if len(cars) < 2:
        raise InputError(f"held-out calibration needs frames of at least two drives (or two frames of unknown drive); "
                         f"got {len(frames)} frame(s) of one", path=dataset.split_dir)
    folds = assign_folds(cars, n_folds=min(n_folds, len(cars)))
    return {f: folds[group[f]] for f in frames}


@single_threaded
def heldout_bank_calibration(kitti_root, folds: Mapping[str, int], *, split: str | None = None, seed: int = 0,
                             workers: int = 1, progress=None, **bank_options) -> dict:
    """Platt calibration of a detector bank from held-out detections: for each fold, a
    bank trained on the other folds' frames detects on that fold's (unmirrored) frames;
    :func:`~wirescene.training.kitti_detector.fit_platt` on all of them, with the ground
    prior's log ratio as offset. ``workers``: processes of the fold banks' trainings and
    of the held-out detections (the result is the same).

    Returns ``{"a", "b", "n_detections", "n_positive", "n_folds", "source"}``.
    """
    from wirescene.io.kitti import KittiDataset

    say = progress or (lambda message: None)
    dataset = KittiDataset(kitti_root, split=split)
    rows, verified = [], []
    for k in sorted(set(folds.values())):
        held = [f for f, j in folds.items() if j == k]
        train = [f for f, j in folds.items() if j != k]
        say(f"calibration: fold {k} held out ({len(held)} frames), bank trained on {len(train)}")
        bank, _ = train_detector_bank_kitti(None, kitti_root, frames=train, split=split, seed=seed,
                                            calibration_folds=False, workers=workers, progress=say, **bank_options)
        verified.append(bank.verifier is not None)
        images, _ = load_training_frames(dataset, held, flips=False)
        for image, d in zip(images, training_detections(bank, images, workers=workers, progress=say,
                                                        name=f"fold {k} held-out detections")):
            rows.append(heldout_rows(bank, image, d, dataset))
    s, y, off, logits = (np.concatenate(col) for col in zip(*rows))
    if not y.any():
        raise InputError(f"no held-out detection of the fold banks matches a labelled car ({len(s)} detections): "
                         "too few training frames for a calibrated bank", path=dataset.split_dir)
    params = fit_platt(s, y, offset=off, verifier=logits if all(verified) else None)
    return calibration_record(params, n_detections=int(len(s)), n_positive=int(y.sum()),
                              n_folds=len(set(folds.values())), source="leave-one-fold-out detections")


def _frame_folds(dataset, frames, drives=None) -> dict[str, int] | None:
    """:func:`calibration_folds` of ``frames``, or None where they form a single group (no
    held-out calibration is possible: the bank stays uncalibrated)."""
    try:
        return calibration_folds(dataset, list(frames), drives=drives)
    except InputError:
        return None
