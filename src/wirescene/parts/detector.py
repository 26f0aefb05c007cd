"""Part detectors: a 37-class random forest on edge-map descriptors (paper Sec. 3.2).

Classes ``0..35`` are the wireframe vertices (:data:`wirescene.core.wireframe.VERTEX_NAMES`),
class 36 (:data:`BACKGROUND`) is background. Training lives in
:mod:`wirescene.training.parts`; this module holds inference:

* :class:`PartDetector` -- the forest as plain numpy arrays (exported from scikit-learn,
  saved as a versioned ``.npz`` without pickle) and a vectorised numpy traversal, so a
  saved model loads and predicts without scikit-learn or a matching version.
* :func:`response_maps` -- dense multi-scale part probability maps ``S_j`` and background
  ``S_b`` inside (padded) detection boxes, and :meth:`PartResponses.log_ratio` -- the O(1)
  lookup of ``log(S_j / S_b)`` (max over scales) at projected vertices, vectorised over
  any batch of hypotheses (the likelihood's hot path).

Scale convention: a box of height ``h`` px is resampled so that an object of height
``s * h`` becomes :data:`wirescene.parts.features.CANONICAL_HEIGHT` px, for each ``s`` in
``scales``; patches are then ``PATCH`` canonical px wide (about half the car height).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

from wirescene.core.errors import InputError, ShapeError, check_shape
from wirescene.core.resources import DATA_DIR
from wirescene.parts import MAX_SMOOTH
from wirescene.parts import features as feat

__all__ = [
    "N_PARTS", "BACKGROUND", "N_CLASSES", "MODEL_FORMAT", "DEFAULT_MODEL_PATH", "DEFAULT_SCALES",
    "PartDetector", "BoxResponses", "PartResponses", "response_maps", "box_crop", "box_descriptors", "box_position", "log_ratio",
    "load_default",
]

N_PARTS = 36
BACKGROUND = 36
N_CLASSES = 37
FORMAT_KIND = "parts-forest"
FORMAT_VERSION = 2
MODEL_FORMAT = f"wirescene-{FORMAT_KIND}/{FORMAT_VERSION}"
"""Version 2 adds ``position`` and ``context`` (box-relative features) and a per-class
affine calibration of the log ratio (``calib_scale``, ``calib_offset``); version 1 files
load with none of them."""
DEFAULT_MODEL_PATH = DATA_DIR / "parts_model.npz"
DEFAULT_SCALES = (0.85, 1.0, 1.2)
DEFAULT_EPS = 1e-3
#: How far past the image a box's grid of responses reaches, as a share of the image's side (310 px
#: left and right at KITTI's size; a truncated car's padded box reaches 0.1 x its width past the side;
#: parts beyond the image are hidden by its border in the fit).
GRID_MARGIN = 0.25
#: Most pixels a box's crop may have at its canonical scale; a box far flatter than a car (a
#: sliver 1 px high across the image would need 40 M) gets no part evidence instead.
MAX_CANONICAL_PIXELS = 4_000_000


@dataclass
class PartDetector:
    """A random forest stored as flat numpy arrays (all trees concatenated).

    Attributes
    ----------
    roots : (T,) int32 -- node index of each tree's root
    left, right : (N,) int32 -- global child indices, -1 at leaves
    feature : (N,) int16 -- split feature (-1 at leaves)
    threshold : (N,) float64 -- go left if ``float32(x[feature]) <= threshold``
    leaf : (N,) int32 -- row of ``values`` for leaves, -1 at inner nodes
    values : (L, C) uint8 (quantised, ``/ scale``) or float -- leaf class distributions
    value_scale : float -- divide ``values`` by this to get probabilities
    kind : str -- descriptor (see :func:`wirescene.parts.features.extract`)
    max_depth : int
    meta : dict of str -- provenance (training parameters), saved with the model
    position : bool -- the descriptor ends with the point's position relative to the
        box (:func:`box_position`), the forest's last 2 features
    context : bool -- between descriptor and position: the box's gradient layout
        (:func:`wirescene.parts.features.box_context`, 72 features, multi-scale kinds only)
    smooth : float -- default spatial smoothing of the log-ratio maps in
        :func:`response_maps` (Gaussian, sigma in box heights; 0: none)
    calib_scale, calib_offset : (36,) float, optional -- the log ratio reported by
        :func:`response_maps` is ``calib_scale[j] * log(S_j / S_b) + calib_offset[j]``
        (per-class calibration on real data, see
        :func:`wirescene.training.parts.calibrate`); None: identity
    trained_images : dict of str -- ``{frame id: image SHA-256}`` of the real frames it was
        trained on (:func:`wirescene.core.resources.images_sha256`; empty: none, or a file written
        before the record was), saved with it (:func:`wirescene.core.artefacts.trained_arrays`)

    Examples
    --------
    >>> detector = load_default()
    >>> n_context = feat.CONTEXT_DIM * detector.context  # a descriptor, the box's context, the point's position
    >>> detector.n_features == feat.feature_dim(detector.kind) + n_context + 2 * detector.position
    True
    >>> X = np.zeros((3, detector.n_features))  # 3 descriptors
    >>> probs = detector.predict_proba(X)
    >>> probs.shape, bool(np.allclose(probs.sum(1), 1.0)), detector.predict(X).shape  # 36 parts, background
    ((3, 37), True, (3,))
    """

    roots: np.ndarray
    left: np.ndarray
    right: np.ndarray
    feature: np.ndarray
    threshold: np.ndarray
    leaf: np.ndarray
    values: np.ndarray
    value_scale: float
    kind: str
    max_depth: int
    n_features: int
    meta: dict = field(default_factory=dict)
    position: bool = False
    context: bool = False
    smooth: float = 0.0
    calib_scale: np.ndarray | None = None
    calib_offset: np.ndarray | None = None
    trained_images: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_sklearn(cls, forest, *, kind: str, quantize: bool = True, meta: dict | None = None,
                     position: bool = False, context: bool = False) -> "PartDetector":
        """Export a fitted :class:`sklearn.ensemble.RandomForestClassifier` whose classes
        are ``0..36``. ``quantize``: leaf distributions as uint8 (x255) instead of float64."""
        classes = np.asarray(forest.classes_)
        n_classes = N_CLASSES
        roots, L, R, Fe, Th, Lf, Va = [], [], [], [], [], [], []
        offset, leaf_off = 0, 0
        depth = 0
        for est in forest.estimators_:
            t = est.tree_
            n = t.node_count
            is_leaf = t.children_left < 0
            roots.append(offset)
            L.append(np.where(is_leaf, -1, t.children_left + offset))
            R.append(np.where(is_leaf, -1, t.children_right + offset))
            Fe.append(np.where(is_leaf, -1, t.feature))
            Th.append(np.where(is_leaf, 0.0, t.threshold))
            li = np.full(n, -1, dtype=np.int64)
            li[is_leaf] = np.arange(is_leaf.sum()) + leaf_off
            Lf.append(li)
            v = t.value[is_leaf, 0, :].astype(float)
            v = v / np.maximum(v.sum(axis=1, keepdims=True), 1e-300)
            full = np.zeros((len(v), n_classes))
            full[:, classes.astype(int)] = v
            Va.append(full)
            offset += n
            leaf_off += int(is_leaf.sum())
            depth = max(depth, int(t.max_depth))
        values = np.concatenate(Va)
        if quantize:
            values, scale = np.round(values * 255).astype(np.uint8), 255.0
        else:
            scale = 1.0
        return cls(
            roots=np.asarray(roots, np.int32), left=np.concatenate(L).astype(np.int32),
            right=np.concatenate(R).astype(np.int32), feature=np.concatenate(Fe).astype(np.int16),
            threshold=np.concatenate(Th).astype(np.float64), leaf=np.concatenate(Lf).astype(np.int32),
            values=values, value_scale=scale, kind=kind, max_depth=depth,
            n_features=int(forest.n_features_in_), meta=dict(meta or {}), position=bool(position),
            context=bool(context),
        )

    # ------------------------------------------------------------------ persistence
    def save(self, path) -> Path:
        """Write a compressed ``.npz`` (no pickled objects; :func:`wirescene.core.artefacts.save_npz`)."""
        from wirescene.core.artefacts import save_npz, trained_arrays

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {str(k): str(v) for k, v in self.meta.items()}
        calib = {}
        if self.calib_scale is not None:
            calib = {"calib_scale": np.asarray(self.calib_scale, np.float64).reshape(N_PARTS),
                     "calib_offset": np.asarray(self.calib_offset, np.float64).reshape(N_PARTS)}
        arrays = dict(
            kind=np.array(self.kind), roots=self.roots,
            left=self.left, right=self.right, feature=self.feature, threshold=self.threshold,
            leaf=self.leaf, values=self.values, value_scale=np.array(self.value_scale),
            max_depth=np.array(self.max_depth), n_features=np.array(self.n_features),
            canonical_height=np.array(feat.CANONICAL_HEIGHT), radius=np.array(feat.RADIUS),
            meta_keys=np.array(list(meta.keys()), dtype=str), meta_values=np.array(list(meta.values()), dtype=str),
            position=np.array(self.position), context=np.array(self.context), smooth=np.array(float(self.smooth)),
            **calib, **trained_arrays(self.trained_images),
        )
        return save_npz(path, arrays, kind=FORMAT_KIND, version=FORMAT_VERSION)

    @classmethod
    def load(cls, path=None) -> "PartDetector":
        """Load a model written by :meth:`save` (default: the package's model); version 1
        files (no position, context or calibration) load too."""
        from wirescene.core.artefacts import load_npz, trained_images

        path = DEFAULT_MODEL_PATH if path is None else Path(path)
        z = load_npz(path, kind=FORMAT_KIND, version=FORMAT_VERSION, older=(1,))
        try:
            if int(z["canonical_height"]) != feat.CANONICAL_HEIGHT or int(z["radius"]) != feat.RADIUS:
                raise InputError("part model was trained with other canonical patch geometry", path=path)
            d = {k: z[k] for k in ("roots", "left", "right", "feature", "threshold", "leaf", "values")}
            meta = dict(zip(z["meta_keys"].tolist(), z["meta_values"].tolist()))
            has_cal = "calib_scale" in z
            smooth = float(z["smooth"]) if "smooth" in z else 0.0
            if not 0.0 <= smooth <= MAX_SMOOTH:  # NaN too
                raise InputError(f"part model's smoothing {smooth:g} is not within 0 to {MAX_SMOOTH:g} box heights",
                                 path=path)
            return cls(**d, value_scale=float(z["value_scale"]), kind=str(z["kind"]),
                       max_depth=int(z["max_depth"]), n_features=int(z["n_features"]), meta=meta,
                       position=bool(z["position"]) if "position" in z else False,
                       context=bool(z["context"]) if "context" in z else False,
                       smooth=smooth,
                       calib_scale=z["calib_scale"] if has_cal else None,
                       calib_offset=z["calib_offset"] if has_cal else None,
                       trained_images=trained_images(z, path=path))
        except (KeyError, ValueError) as e:
            raise InputError(f"cannot read part model ({e})", path=path) from None

    # ------------------------------------------------------------------ prediction
    @property
    def n_trees(self) -> int:
        return len(self.roots)

    def predict_proba(self, X, *, chunk: int = 1024) -> np.ndarray:
        """``(N, 37)`` class probabilities (mean of the trees' leaf distributions).

        ``chunk`` rows are traversed at a time: some thousand rows keep the traversal's
        temporaries in the CPU's cache (``benchmarks/bench_forest.py`` times it)."""
        X = np.asarray(X, dtype=np.float32)
        check_shape("X", X, (None, self.n_features))
        out = np.empty((len(X), N_CLASSES), dtype=np.float64)
        for s in range(0, len(X), chunk):
            out[s:s + chunk] = self._predict(X[s:s + chunk])
        return out

    def _tables(self):
        """Traversal tables (cached).

        The nodes are renumbered so that each inner node's right child directly follows
        its left one: a step is then ``left + (x > threshold)``. ``nodes`` holds one
        16-byte record a node (left child, feature, float32 threshold, leaf row), so a
        step gathers one record instead of three arrays. Leaves point to themselves with
        an infinite threshold (nothing, NaN included, goes right of it). The float32
        thresholds are equivalent to the float64 ones for float32 inputs (the largest
        float32 <= the threshold). Returns ``nodes`` (N,) complex128 (the records' raw
        bytes), the renumbered ``roots`` and the float32 leaf values over the trees.
        """
        t = self.__dict__.get("_tab")
        if t is None:
            left, right = self.left.astype(np.intp), self.right.astype(np.intp)
            leaf = left < 0
            new = np.empty(len(left), dtype=np.intp)
            level = self.roots.astype(np.intp)
            new[level] = np.arange(len(level))
            start = len(level)
            while len(level):  # one level of all trees at a time: the children in pairs
                inner = level[~leaf[level]]
                pair = start + 2 * np.arange(len(inner))
                new[left[inner]], new[right[inner]] = pair, pair + 1
                start += 2 * len(inner)
                level = np.stack([left[inner], right[inner]], 1).ravel()
            thr = self.threshold.astype(np.float32)
            over = thr.astype(np.float64) > self.threshold
            thr[over] = np.nextafter(thr[over], np.float32(-np.inf))
            thr[leaf] = np.inf
            nodes = np.zeros((len(left), 4), dtype=np.int32)
            nodes[new, 0] = np.where(leaf, new, new[np.where(leaf, 0, left)])
            nodes[new, 1] = np.maximum(self.feature, 0)
            nodes[new, 2] = thr.view(np.int32)
            nodes[new, 3] = self.leaf
            vals = self.values.astype(np.float32) / np.float32(self.value_scale * self.n_trees)
            t = (nodes.view(np.complex128).ravel(), new[self.roots], vals)
            self.__dict__["_tab"] = t
        return t

    def _predict(self, X):
        nodes, roots, vals = self._tables()
        n, T = len(X), self.n_trees
        node = np.broadcast_to(roots[None, :], (n, T)).copy()
        flat = np.ascontiguousarray(X).ravel()
        rows = (np.arange(n, dtype=np.intp) * X.shape[1])[:, None]
        for _ in range(self.max_depth):
            rec = np.take(nodes, node).view(np.int32).reshape(n, T, 4)
            node = rec[..., 0] + (np.take(flat, rows + rec[..., 1]) > rec[..., 2].view(np.float32))
        leaves = np.ascontiguousarray(np.take(nodes, node).view(np.int32).reshape(n, T, 4)[..., 3].T)
        p = np.zeros((n, N_CLASSES), np.float32)
        for t in range(T):  # tree by tree, in order: the sums are the same to the bit
            p += np.take(vals, leaves[t], axis=0)
        p = p.astype(np.float64)
        if self.value_scale != 1.0:
            p /= np.maximum(p.sum(axis=1, keepdims=True), 1e-12)
        return p

    def predict(self, X) -> np.ndarray:
        return np.argmax(self.predict_proba(X), axis=1)

    def classify_patches(self, patches) -> np.ndarray:
        """``(N, 37)`` probabilities of canonical ``(N, PATCH, PATCH)`` edge patches."""
        if self.position or self.context:
            raise ValueError("this model needs box positions: use box_descriptors / response_maps")
        return self.predict_proba(feat.extract(np.asarray(patches), self.kind))

    def log_ratio_of(self, probs, *, eps: float = DEFAULT_EPS) -> np.ndarray:
        """Calibrated ``log(S_j / S_b)`` ``(..., 36)`` of class probabilities ``(..., 37)``
        (clipped to ``[eps, 1]`` first; calibrated values clipped to ``+-|log eps|``).

        Examples
        --------
        >>> probs = np.zeros((2, N_CLASSES))
        >>> probs[0, 0], probs[0, BACKGROUND], probs[1, BACKGROUND] = 0.9, 0.1, 1.0
        >>> lr = load_default().log_ratio_of(probs)
        >>> lr.shape, bool(np.abs(lr).max() <= -np.log(DEFAULT_EPS) + 1e-6)  # (..., 36), within +-|log eps|
        ((2, 36), True)
        """
        pc = np.clip(np.asarray(probs, dtype=np.float32), eps, 1.0)
        lr = np.log(pc[..., :N_PARTS]) - np.log(pc[..., N_PARTS:])
        if self.calib_scale is not None:
            lr = lr * self.calib_scale.astype(np.float32) + self.calib_offset.astype(np.float32)
            lim = np.float32(-np.log(eps))
            lr = np.clip(lr, -lim, lim)
        return lr


_DEFAULT = None


def load_default() -> PartDetector:
    """The package's trained model (cached). Another model file is chosen per run with
    ``FitOptions.parts_model`` (``--parts-model``), which the resume records include.

    Examples
    --------
    >>> detector = load_default()
    >>> detector is load_default(), 0 <= detector.smooth <= MAX_SMOOTH  # cached; its smoothing in box heights
    (True, True)
    """
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = PartDetector.load()
    return _DEFAULT


# ---------------------------------------------------------------------- response maps


@dataclass
class BoxResponses:
    """Responses inside one (padded) box, on an image grid
    ``u = origin[0] + stride * j``, ``v = origin[1] + stride * i``.

    probs : (n_scales, Gh, Gw, 37) float16 -- ``S_j`` (columns 0..35) and ``S_b`` (36)
    log_ratio : (Gh, Gw, 36) float32 -- ``max_s log(clip(S_j) / clip(S_b))``

    Examples
    --------
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> responses = response_maps(image, [[20, 20, 44, 34]])  # one box, 24 x 14 px
    >>> maps = responses.boxes[0]
    >>> maps.stride, maps.region  # the box grown by 10% of its size, a grid point a pixel
    (1.0, array([17.6, 18.6, 46.4, 35.4]))
    >>> maps.probs.shape, maps.log_ratio.shape  # (scales, Gh, Gw, 37), (Gh, Gw, 36)
    ((3, 17, 29, 37), (17, 29, 36))
    >>> grid = maps.grid_uv()
    >>> grid.shape, grid[0, 0], grid[0, 1]
    ((17, 29, 2), array([17.6, 18.6]), array([18.6, 18.6]))
    """

    box: np.ndarray
    region: np.ndarray
    origin: np.ndarray
    stride: float
    scales: tuple
    probs: np.ndarray
    log_ratio: np.ndarray

    def grid_uv(self) -> np.ndarray:
        """``(Gh, Gw, 2)`` image coordinates of the grid points."""
        gh, gw = self.log_ratio.shape[:2]
        u = self.origin[0] + self.stride * np.arange(gw)
        v = self.origin[1] + self.stride * np.arange(gh)
        return np.stack(np.meshgrid(u, v), axis=-1)


@dataclass
class PartResponses:
    """Response maps of all boxes of an image (see :func:`response_maps`).

    Examples
    --------
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> responses = response_maps(image, [[20, 20, 44, 34]])  # one box, 24 x 14 px
    >>> len(responses), round(responses.floor, 4)  # log(eps)
    (1, -6.9078)
    >>> maps = responses.boxes[0]
    >>> uv = np.tile(maps.grid_uv()[3, 4], (36, 1))  # every vertex at grid point (3, 4)
    >>> bool(np.allclose(responses.log_ratio(uv, 0), maps.log_ratio[3, 4]))
    True
    >>> responses.log_ratio(np.full((36, 2), -500.0), 0)[:2]  # far outside the grid: the floor
    array([-6.9077554, -6.9077554], dtype=float32)
    """

    boxes: list
    eps: float
    _stack: tuple | None = None
    _padded: np.ndarray | None = None

    def __len__(self):
        return len(self.boxes)

    @property
    def floor(self) -> float:
        """Lowest possible log ratio, ``log(eps / 1)``."""
        return float(np.log(self.eps))

    def _stacked(self):
        """``(lr, shape, origin, stride)``: the boxes' maps stacked ``(n, gh, gw, 36)`` (the
        floor past each box's grid), their grid sizes, origins and strides. ``lr`` is the
        inside of :attr:`_padded`, the stack with two more grid lines of the floor before and
        after each axis, ``(n, gh + 4, gw + 4, 36)``, which the lookups read."""
        if self._stack is None:
            gh = max((b.log_ratio.shape[0] for b in self.boxes), default=1)
            gw = max((b.log_ratio.shape[1] for b in self.boxes), default=1)
            padded = np.full((max(len(self.boxes), 1), gh + 4, gw + 4, N_PARTS), self.floor, dtype=np.float32)
            lr = padded[:, 2:gh + 2, 2:gw + 2]
            shape = np.zeros((max(len(self.boxes), 1), 2), dtype=np.int64)
            origin = np.zeros((max(len(self.boxes), 1), 2))
            stride = np.ones(max(len(self.boxes), 1))
            for i, b in enumerate(self.boxes):
                h, w = b.log_ratio.shape[:2]
                lr[i, :h, :w] = b.log_ratio
                shape[i] = (h, w)
                origin[i] = b.origin
                stride[i] = b.stride
            self._stack, self._padded = (lr, shape, origin, stride), padded
        return self._stack

    def log_ratio(self, uv, box_index, *, outside: float | None = None, bilinear: bool = False) -> np.ndarray:
        """``log(S_j / S_b)`` of part ``j`` at ``uv[..., j, :]`` (max over scales), at the
        nearest grid point or, with ``bilinear``, interpolated between the four around it.

        Parameters
        ----------
        uv : (..., 36, 2) array -- image coordinates of the 36 projected vertices
        box_index : int or int array broadcastable to ``uv.shape[:-2]``
        outside : float, optional -- value outside the box's grid (default :attr:`floor`)
        bilinear : bool -- interpolate (grid points outside the grid count as ``outside``).
            The nearest grid point makes the objective piecewise constant on cells of a
            stride (up to 4 px), so sub-stride moves of a hypothesis change nothing.

        Returns
        -------
        (..., 36) float32
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim < 2 or uv.shape[-2:] != (N_PARTS, 2):
            raise ShapeError(f"uv must be (..., {N_PARTS}, 2), got {uv.shape}")
        if not self.boxes:
            raise ShapeError("no boxes in these responses")
        lr, shape, origin, stride = self._stacked()
        b = np.broadcast_to(np.asarray(box_index, dtype=np.int64), uv.shape[:-2])[..., None]
        if b.size and (b.min() < 0 or b.max() >= len(self.boxes)):
            raise ShapeError(f"box_index out of range [0, {len(self.boxes)})")
        s = stride[b]
        fj = uv[..., 0] - origin[b, 0]
        fj /= s
        fi = uv[..., 1] - origin[b, 1]
        fi /= s
        out_value = np.float32(self.floor if outside is None else outside)
        h, w = shape[b, 0], shape[b, 1]
        if bilinear and outside is None:
            return self._bilinear_floor(fi, fj, b, h, w)
        # Entry (b, i, j, part) of the stacked maps read by its flat index: the row's and the
        # column's offsets are computed once for each grid line a corner lies on (shared by
        # two of the four corners) and the values gathered with one take, the same values as
        # indexing lr[b, i, j, part] (1.5x faster, benchmarks/RESULTS.md); lr lies inside the
        # padded stack, two grid lines from each edge.
        n_rows, gw = self._padded.shape[1:3]
        flat = self._padded.reshape(-1)
        base = (b * n_rows + 2) * (gw * N_PARTS) + 2 * N_PARTS + np.arange(N_PARTS)

        def line(k, n, step):
            """Whether grid lines ``k`` lie in ``[0, n)``, and their flat offsets (0 where not)."""
            ok = (k >= 0) & (k < n)
            return ok, np.where(ok, k, 0).astype(np.int64) * step

        def at(row, col):
            (ok_i, ii), (ok_j, jj) = row, col
            return np.where(ok_i & ok_j, flat.take(base + ii + jj), out_value)

        if not bilinear:
            return at(line(np.rint(fi), h, gw * N_PARTS), line(np.rint(fj), w, N_PARTS)).astype(np.float32)
        i0, j0 = np.floor(fi), np.floor(fj)
        ti, tj = fi - i0, fj - j0
        r0, r1 = line(i0, h, gw * N_PARTS), line(i0 + 1, h, gw * N_PARTS)
        c0, c1 = line(j0, w, N_PARTS), line(j0 + 1, w, N_PARTS)
        top = (1 - tj) * at(r0, c0) + tj * at(r0, c1)
        bottom = (1 - tj) * at(r1, c0) + tj * at(r1, c1)
        return ((1 - ti) * top + ti * bottom).astype(np.float32)

    def _bilinear_floor(self, fi, fj, b, h, w) -> np.ndarray:
        """:meth:`log_ratio`'s bilinear lookup with the floor outside the grids, from the
        grid coordinates ``fi``, ``fj`` ``(..., 36)`` of boxes ``b`` ``(..., 1)`` with grids of
        ``h`` x ``w`` points: the same values, to the bit, by the same operations, read without
        bounds tests. The lower corners' grid line ``floor(fi)`` is clipped to ``[-2, h]`` (``floor(fj)``
        to ``[-2, w]``), the upper corners' one past it, and both read off the padded stack
        (:meth:`_stacked`), where every line before a grid or past it holds the floor, as the bounds
        tests give; ``fmax``/``fmin`` map NaN to the floor's line, as the tests do.
        The four corners' flat indices differ by constants: one index array moved in place."""
        padded = self._padded
        n_rows, n_cols = padded.shape[1:3]
        i0, j0 = np.floor(fi), np.floor(fj)
        ti, tj = np.subtract(fi, i0, out=fi), np.subtract(fj, j0, out=fj)
        i = np.fmin(np.fmax(i0, -2.0, out=i0), h, out=i0).astype(np.int64)
        j = np.fmin(np.fmax(j0, -2.0, out=j0), w, out=j0).astype(np.int64)
        row = n_cols * N_PARTS
        index = np.multiply(i, row, out=i)
        index += np.multiply(j, N_PARTS, out=j)
        index += ((b * n_rows + 2) * n_cols + 2) * N_PARTS
        index += np.arange(N_PARTS)
        flat = padded.reshape(-1)
        v00 = flat.take(index)
        index += N_PARTS
        v01 = flat.take(index)
        index += row
        v11 = flat.take(index)
        index -= N_PARTS
        v10 = flat.take(index)
        # (1 - tj) v00 + tj v01, (1 - tj) v10 + tj v11, then (1 - ti) top + ti bottom, in place
        sj = np.subtract(1, tj, out=i0)
        top = np.multiply(sj, v00)
        product = np.multiply(tj, v01, out=j0)
        top += product
        bottom = np.multiply(sj, v10, out=sj)
        bottom += np.multiply(tj, v11, out=product)
        top *= np.subtract(1, ti, out=product)
        bottom *= ti
        top += bottom
        return top.astype(np.float32)


def log_ratio(responses: PartResponses, uv, box_index, **kwargs) -> np.ndarray:
    """Function form of :meth:`PartResponses.log_ratio`.

    Examples
    --------
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> responses = response_maps(image, [[20, 20, 44, 34]])  # one box, 24 x 14 px
    >>> uv = np.full((4, 36, 2), [32.0, 27.0])  # 4 hypotheses of box 0, every vertex at the box centre
    >>> log_ratio(responses, uv, 0, bilinear=True).shape
    (4, 36)
    """
    return responses.log_ratio(uv, box_index, **kwargs)


def _auto_stride(box_h: float) -> float:
    return float(np.clip(box_h / 32.0, 1.0, 4.0))


def box_crop(box, image_size, scales=DEFAULT_SCALES, *, pad: float = 0.1, radius: int = feat.RADIUS):
    """The padded region ``(rx0, ry0, rx1, ry1)`` that :func:`response_maps` scores for
    ``box`` and the integer native crop ``(cx0, cy0, cx1, cy1)`` it describes (the region
    plus room for the largest patch of half-width ``radius`` canonical px, see
    :func:`wirescene.parts.features.context_radius`). ``image_size = (W, H)``.

    Examples
    --------
    >>> region, crop, zs = box_crop([20, 20, 44, 34], (96, 64))
    >>> region, crop  # the box grown by 10%; the native pixels its descriptors read
    (array([17.6, 18.6, 46.4, 35.4]), (11, 12, 53, 42))
    >>> np.round(zs, 2)  # canonical px per native px at scales 0.85, 1.0, 1.2 (64 px per car height)
    array([5.38, 4.57, 3.81])
    """
    W, H = image_size
    x1, y1, x2, y2 = np.asarray(box, dtype=float)
    bw, bh = max(x2 - x1, 1.0), max(y2 - y1, 1.0)
    region = np.array([x1 - pad * bw, y1 - pad * bh, x2 + pad * bw, y2 + pad * bh])
    zs = [feat.CANONICAL_HEIGHT / (s * bh) for s in scales]
    margin = radius / min(zs) + 2
    cx0 = int(np.clip(np.floor(region[0] - margin), 0, W - 1))
    cy0 = int(np.clip(np.floor(region[1] - margin), 0, H - 1))
    cx1 = int(np.clip(np.ceil(region[2] + margin), cx0 + 1, W))
    cy1 = int(np.clip(np.ceil(region[3] + margin), cy0 + 1, H))
    return region, (cx0, cy0, cx1, cy1), zs


def _grid_within(start: float, n: int, step: float, size: int) -> tuple[float, int]:
    """The points ``start + step * k`` (``k < n``) that lie at most :data:`GRID_MARGIN` x the
    image's side ``size`` past it, as ``(first point, count)`` (at least one): a subset of the
    same points, each scored as before (the fit clips its boxes to the image first, so for
    its boxes the bound never binds)."""
    m = GRID_MARGIN * size
    k0 = min(max(0, int(np.ceil((-m - start) / step))), n - 1)
    k1 = max(min(n, int(np.floor((size + m - start) / step)) + 1), k0 + 1)
    return start + step * k0, k1 - k0


def box_position(uv, box) -> np.ndarray:
    """``(..., 2)`` float32 position of points ``uv (..., 2)`` relative to ``box``:
    ``((u - x1) / w, (v - y1) / h)`` (0..1 inside the box).

    Examples
    --------
    >>> box_position([[20, 20], [44, 34], [32, 27]], [20, 20, 44, 34])
    array([[0. , 0. ],
           [1. , 1. ],
           [0.5, 0.5]], dtype=float32)
    """
    x1, y1, x2, y2 = np.asarray(box, dtype=float)
    uv = np.asarray(uv, dtype=float)
    return np.stack([(uv[..., 0] - x1) / max(x2 - x1, 1.0), (uv[..., 1] - y1) / max(y2 - y1, 1.0)],
                    axis=-1).astype(np.float32)


def box_descriptors(image, box, uv, kind: str, *, scale: float = 1.0, pad: float = 0.1, edges=None,
                    position: bool = False, context: bool = False) -> np.ndarray:
    """Descriptors ``(N, D)`` at native points ``uv (N, 2)`` exactly as
    :func:`response_maps` computes them for ``box`` at one ``scale`` (used by training).
    ``edges``: precomputed full-image :func:`wirescene.parts.features.image_edges`;
    ``context``, ``position``: append :func:`wirescene.parts.features.box_context`, then
    :func:`box_position` (models with ``context`` / ``position``).

    Examples
    --------
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> detector = load_default()
    >>> X = box_descriptors(image, [20, 20, 44, 34], [[32, 27], [25, 25]], detector.kind,
    ...                     position=detector.position, context=detector.context)
    >>> X.shape == (2, detector.n_features), detector.predict_proba(X).shape
    (True, (2, 37))
    """
    img = np.asarray(image)
    H, W = img.shape[:2]
    _, (cx0, cy0, cx1, cy1), (z,) = box_crop(box, (W, H), (scale,), pad=pad, radius=feat.context_radius(kind))
    e = None if edges is None else np.asarray(edges)[cy0:cy1, cx0:cx1]
    inp = feat.canonical_inputs(img[cy0:cy1, cx0:cx1], z, kind, edges=e)
    return _descriptors(inp, np.asarray(uv, dtype=float).reshape(-1, 2), box, (cx0, cy0), z, kind,
                        context=context, position=position)


def _descriptors(inp, uv, box, crop_origin, z: float, kind: str, *, context: bool, position: bool) -> np.ndarray:
    """Descriptors ``(N, D)`` at points ``uv (N, 2)`` of the crop at ``crop_origin`` whose
    :func:`~wirescene.parts.features.canonical_inputs` are ``inp``: the descriptor, then the
    box's context and the points' place in ``box`` as the model asks (``uv``, ``box`` in the
    same pixel frame as ``crop_origin``)."""
    rc = np.rint(feat.to_canonical(uv - np.asarray(crop_origin), z)).astype(np.int64)
    X = feat.describe(inp, rc, kind)
    if context:
        X = np.concatenate([X, np.broadcast_to(_context(inp, box, crop_origin, z), (len(X), feat.CONTEXT_DIM))], 1)
    return np.concatenate([X, box_position(uv, box)], axis=1) if position else X


def _context(inp, box, crop_origin, z):
    b = np.asarray(box, dtype=float) - np.r_[crop_origin, crop_origin]
    a = feat.to_canonical(b[:2], z)
    c = feat.to_canonical(b[2:], z)
    return feat.box_context(inp, (a[0], a[1], c[0], c[1]))


def _mirrored_probs(detector: PartDetector, crop, edges, box, crop_origin, z: float, uv) -> np.ndarray:
    """``(N, N_CLASSES)`` class probabilities at points ``uv (N, 2)`` read off the mirror
    image of ``crop``: each point at its mirrored place, part ``MIRROR[j]``'s probability as
    part ``j``'s (as the training's mirrored cars, ``parts_real.mirror_cars``)."""
    from wirescene.core.wireframe import MIRROR

    last = crop.shape[1] - 1  # u -> last - u within the crop, whose origin is then (0, 0)
    x1, y1, x2, y2 = np.asarray(box, dtype=float) - np.r_[crop_origin, crop_origin]
    e = None if edges is None else np.ascontiguousarray(np.asarray(edges)[:, ::-1])
    inp = feat.canonical_inputs(np.ascontiguousarray(crop[:, ::-1]), z, detector.kind, edges=e)
    mirrored_uv = np.stack([last - (uv[:, 0] - crop_origin[0]), uv[:, 1] - crop_origin[1]], -1)
    X = _descriptors(inp, mirrored_uv, np.array([last - x2, y1, last - x1, y2]), (0, 0), z, detector.kind,
                     context=detector.context, position=detector.position)
    return detector.predict_proba(X)[:, np.append(MIRROR, BACKGROUND)]


def response_maps(image, boxes, *, detector: PartDetector | None = None, scales=DEFAULT_SCALES,
                  stride: float | None = None, pad: float = 0.1, eps: float = DEFAULT_EPS,
                  edges: np.ndarray | None = None, smooth: float | None = None, flip: bool = False) -> PartResponses:
    """Dense multi-scale part responses inside detection boxes.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) array
    boxes : (B, 4) array -- ``x1 y1 x2 y2`` pixels
    detector : PartDetector, optional -- default :func:`load_default`
    scales : sequence of float -- assumed object height = ``scale * box height``
    stride : float, optional -- grid step in image px (default ``clip(h / 32, 1, 4)``)
    pad : float -- the grid covers the box grown by ``pad`` x its size on every side
    eps : float -- probabilities are clipped to ``[eps, 1]`` before the log ratio
    edges : (H, W) bool, optional -- precomputed :func:`wirescene.parts.features.image_edges`
        (ignored by grey-image descriptors)
    smooth : float, optional -- Gaussian smoothing of each part's log-ratio map, sigma in
        box heights (default: the detector's ``smooth``). Neighbouring grid points see
        overlapping patches, so their scores are correlated evidence of one location;
        averaging them suppresses isolated false peaks (on real frames a sigma of about
        1/16 of the box height roughly doubles the vertices whose best-scoring location
        lies within 4% of the car length, ``benchmarks/bench_real.py``).
    flip : bool -- also score each box's mirror image (left and right parts swapped back)
        and average the two class probabilities before the log ratio

    Returns
    -------
    PartResponses

    Notes
    -----
    Two bounds keep a box that is no car's from costing minutes and gigabytes: the grid
    stops :data:`GRID_MARGIN` x the image's width / height past the image (the same points,
    scored alike; within the smoothing's reach of the cut edge the smoothed responses differ),
    and a box whose crop at its canonical
    scale would exceed :data:`MAX_CANONICAL_PIXELS` (a sliver far flatter than a car) gets
    no evidence (log ratio 0 everywhere). Neither binds for any label box or detection of
    the 72 shared KITTI frames.

    Examples
    --------
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> responses = response_maps(image, [[20, 20, 44, 34]])  # one box, 24 x 14 px
    >>> len(responses), responses.boxes[0].log_ratio.shape  # per box: (Gh, Gw, 36) max over 3 scales
    (1, (17, 29, 36))
    """
    detector = load_default() if detector is None else detector
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ShapeError(f"image must be (H, W) or (H, W, 3), got {img.shape}")
    H, W = img.shape[:2]
    boxes = np.asarray(boxes, dtype=float).reshape(-1, 4)
    scales = tuple(float(s) for s in scales)
    if not scales or min(scales) <= 0:
        raise ValueError("scales must be positive")
    out = []
    for box in boxes:
        bh = max(box[3] - box[1], 1.0)
        st = _auto_stride(bh) if stride is None else float(stride)
        (rx0, ry0, rx1, ry1), (cx0, cy0, cx1, cy1), zs = box_crop(box, (W, H), scales, pad=pad,
                                                                  radius=feat.context_radius(detector.kind))
        gw = int(np.floor((rx1 - rx0) / st)) + 1
        gh = int(np.floor((ry1 - ry0) / st)) + 1
        (rx0, gw), (ry0, gh) = _grid_within(rx0, gw, st, W), _grid_within(ry0, gh, st, H)
        gu = rx0 + st * np.arange(gw)
        gv = ry0 + st * np.arange(gh)
        uu, vv = np.meshgrid(gu, gv)
        if (cx1 - cx0) * (cy1 - cy0) * max(zs) ** 2 > MAX_CANONICAL_PIXELS:  # no car's box: no evidence
            out.append(BoxResponses(box=box.copy(), region=np.array([rx0, ry0, rx1, ry1]), origin=np.array([rx0, ry0]),
                                    stride=st, scales=scales,
                                    probs=np.full((len(scales), gh, gw, N_CLASSES), 1 / N_CLASSES, np.float16),
                                    log_ratio=np.zeros((gh, gw, N_PARTS), np.float32)))
            continue
        crop = img[cy0:cy1, cx0:cx1]
        e = None if edges is None else np.asarray(edges)[cy0:cy1, cx0:cx1]
        if e is None and detector.kind in feat.EDGE_KINDS:
            e = feat.image_edges(crop)
        probs = np.empty((len(scales), gh, gw, N_CLASSES), dtype=np.float32)
        uv = np.stack([uu, vv], -1).reshape(-1, 2)
        for k, z in enumerate(zs):
            inp = feat.canonical_inputs(crop, z, detector.kind, edges=e)
            X = _descriptors(inp, uv, box, (cx0, cy0), z, detector.kind, context=detector.context,
                             position=detector.position)
            probs[k] = detector.predict_proba(X).reshape(gh, gw, N_CLASSES)
            if flip:
                mirrored = _mirrored_probs(detector, crop, e, box, (cx0, cy0), z, uv)
                probs[k] = 0.5 * (probs[k] + mirrored.reshape(gh, gw, N_CLASSES))
        lr = detector.log_ratio_of(probs, eps=eps).max(axis=0)
        sig = (detector.smooth if smooth is None else float(smooth)) * bh / st
        if sig > 0:
            lr = gaussian_filter(lr, (sig, sig, 0), mode="nearest")
        out.append(BoxResponses(box=box.copy(), region=np.array([rx0, ry0, rx1, ry1]), origin=np.array([rx0, ry0]),
                                stride=st, scales=scales, probs=probs.astype(np.float16),
                                log_ratio=lr.astype(np.float32)))
    return PartResponses(boxes=out, eps=float(eps))
