"""Metric PCA shape model of the 36-vertex wireframe (paper Sec. 3.1, Eq. 1):

    X(s) = mu + sum_k s_k sigma_k p_k

with mean ``mu`` (36, 3), orthonormal components ``p_k`` (as flattened 108-vectors)
and standard deviations ``sigma_k``, all in metres in the object frame
(:mod:`wirescene.core.wireframe`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wirescene.core.artefacts import load_npz, save_npz
from wirescene.core.boxes import KITTI_CAR_SIZE
from wirescene.core.errors import InputError, check_shape
from wirescene.core.resources import DATA_DIR
from wirescene.core.wireframe import N_VERTICES

__all__ = ["ShapeModel", "fit_shape_model", "component_signs", "augment_to_kitti_sizes", "load_default",
           "FORMAT_VERSION", "DEFAULT_MODEL_PATH", "KITTI_CAR_SIZE"]

FORMAT_VERSION = 1
ARTEFACT_KIND = "shape-model"
DEFAULT_MODEL_PATH = DATA_DIR / "shape_model.npz"



@dataclass(frozen=True)
class ShapeModel:
    """PCA wireframe model.

    Attributes
    ----------
    mean : (36, 3) array
    components : (K, 36, 3) array
        Orthonormal as flattened vectors.
    stds : (K,) array
        Standard deviation of the training set along each component.
    explained_variance_ratio : (K,) array
    exemplar_names : tuple of str
        Names of the (un-augmented) CAD exemplars.
    exemplars : (M, 36, 3) array
        Their annotated wireframes, as measured (before any augmentation).
    version : int
        File format version.

    Examples
    --------
    >>> model = load_default()
    >>> model.mean.shape, model.components.shape[1:], model.stds.shape == (model.n_components,)
    ((36, 3), (36, 3), True)
    >>> X = model.instantiate([1.0, -0.5])  # +1 sd along the first component, -0.5 sd along the second
    >>> X.shape, model.instantiate(np.zeros((250, 2))).shape  # one wireframe, a batch of 250
    ((36, 3), (250, 36, 3))
    >>> bool(np.allclose(model.project_coefficients(X, n_components=3), [1.0, -0.5, 0.0]))  # the inverse
    True
    >>> index, name, distance = model.nearest_exemplar(model.exemplars[2])
    >>> name == model.exemplar_names[2], distance
    (True, 0.0)
    """

    mean: np.ndarray
    components: np.ndarray
    stds: np.ndarray
    explained_variance_ratio: np.ndarray
    exemplar_names: tuple
    exemplars: np.ndarray
    version: int = FORMAT_VERSION

    @property
    def n_components(self) -> int:
        """``K``, the number of components."""
        return int(self.components.shape[0])

    def instantiate(self, s) -> np.ndarray:
        """Wireframes ``(..., 36, 3)`` for coefficients ``s`` ``(..., k)``, ``k <= K``
        (the first ``k`` components are used), in units of standard deviations."""
        s = np.asarray(s, dtype=float)
        check_shape("s", s, (..., None))
        k = s.shape[-1]
        if k > self.n_components:
            raise ValueError(f"s has {k} coefficients but the model has {self.n_components} components")
        weighted = (self.components[:k] * self.stds[:k, None, None]).reshape(k, -1)
        # one matrix product over the flattened batch (einsum was 3x slower here)
        X = (s.reshape(-1, k) @ weighted).reshape(s.shape[:-1] + self.mean.shape)
        X += self.mean  # in place: the same sums as mean + X
        return X

    def project_coefficients(self, X, n_components: int | None = None) -> np.ndarray:
        """Least-squares coefficients ``(..., k)`` of wireframes ``X`` ``(..., 36, 3)``
        (orthonormal components: a projection), in units of standard deviations."""
        X = np.asarray(X, dtype=float)
        check_shape("X", X, (..., N_VERTICES, 3))
        k = self.n_components if n_components is None else int(n_components)
        d = (X - self.mean).reshape(*X.shape[:-2], -1)
        P = self.components[:k].reshape(k, -1)
        return (d @ P.T) / self.stds[:k]

    def reconstruct(self, X, n_components: int | None = None) -> np.ndarray:
        """Best approximation of ``X`` with the first ``n_components`` components."""
        return self.instantiate(self.project_coefficients(X, n_components))

    def nearest_exemplar(self, X):
        """Nearest CAD exemplar of wireframes ``X`` ``(..., 36, 3)`` by Euclidean distance of
        the 108-vectors (paper Sec. 5.4); Python scalars for one wireframe.

        Returns
        -------
        index : int array ``(...)``
        name : str or object array of str ``(...)``
        distance : float array ``(...)`` in metres (norm over all 36 vertices)
        """
        X = np.asarray(X, dtype=float)
        check_shape("X", X, (..., N_VERTICES, 3))
        d = np.linalg.norm((X[..., None, :, :] - self.exemplars).reshape(*X.shape[:-2], len(self.exemplars), -1), axis=-1)
        index = np.argmin(d, axis=-1)
        distance = np.take_along_axis(d, index[..., None], axis=-1)[..., 0]
        names = np.asarray(self.exemplar_names, dtype=object)[index]
        if index.ndim == 0:
            return int(index), str(names), float(distance)
        return index, names, distance

    def sample(self, n: int, rng=None, *, n_components: int | None = None) -> np.ndarray:
        """``n`` random wireframes ``(n, 36, 3)`` with ``s ~ N(0, I)``."""
        rng = np.random.default_rng(rng)
        k = self.n_components if n_components is None else int(n_components)
        return self.instantiate(rng.standard_normal((int(n), k)))

    def save(self, path) -> None:
        """Write a versioned ``.npz`` (no pickled objects; :mod:`wirescene.core.artefacts`).

        Examples
        --------
        >>> import tempfile
        >>> from pathlib import Path
        >>> model = load_default()
        >>> with tempfile.TemporaryDirectory() as d:
        ...     model.save(Path(d) / "shape_model.npz")
        ...     again = ShapeModel.load(Path(d) / "shape_model.npz")
        >>> bool(np.array_equal(again.components, model.components)), again.exemplar_names == model.exemplar_names
        (True, True)
        """
        save_npz(path, dict(
            mean=self.mean, components=self.components, stds=self.stds,
            explained_variance_ratio=self.explained_variance_ratio,
            exemplar_names=np.asarray(self.exemplar_names, dtype=str),
            exemplars=self.exemplars,
        ), kind=ARTEFACT_KIND, version=FORMAT_VERSION)

    @staticmethod
    def load(path) -> "ShapeModel":
        """Read a model written by :meth:`save`; :class:`InputError` naming the file if
        missing, unreadable, of another kind or format version, or of arrays that do not
        make a model of the 36-vertex wireframe (:func:`_arrays_problem`)."""
        data = load_npz(path, kind=ARTEFACT_KIND, version=FORMAT_VERSION)
        missing = {"mean", "components", "stds", "explained_variance_ratio", "exemplar_names", "exemplars"} - set(data)
        if missing:
            raise InputError(f"not a shape model file (missing {', '.join(sorted(missing))})", path=path)
        problem = _arrays_problem(data)
        if problem:
            raise InputError(f"malformed shape model ({problem})", path=path)
        return ShapeModel(
            mean=data["mean"], components=data["components"], stds=data["stds"],
            explained_variance_ratio=data["explained_variance_ratio"],
            exemplar_names=tuple(str(n) for n in data["exemplar_names"]),
            exemplars=data["exemplars"], version=FORMAT_VERSION,
        )


def _arrays_problem(data: dict) -> str | None:
    """What keeps the arrays of a shape model file from making a model (None: nothing):
    shapes other than ``mean (36, 3)``, ``components (K, 36, 3)``, ``stds (K,)``,
    ``explained_variance_ratio (K,)``, ``exemplars (M, 36, 3)`` and ``M`` names with ``K``
    and ``M`` at least 1; numbers that are not finite, or standard deviations not above 0."""
    expected = {"mean": ("", N_VERTICES, 3), "components": ("K", N_VERTICES, 3), "stds": ("K",),
                "explained_variance_ratio": ("K",), "exemplars": ("M", N_VERTICES, 3), "exemplar_names": ("M",)}
    for key, shape in expected.items():
        want = tuple(d for d in shape if d != "")
        found = np.shape(data[key])
        if len(found) != len(want) or any(isinstance(w, int) and f != w for f, w in zip(found, want)):
            return f"{key} of shape {found}, expected ({', '.join(map(str, want))}{',' * (len(want) == 1)})"
    k, m = len(data["components"]), len(data["exemplars"])
    if k < 1 or m < 1:
        return f"{k} components and {m} exemplars, at least one of each needed"
    if len(data["stds"]) != k or len(data["explained_variance_ratio"]) != k:
        return f"{k} components but {len(data['stds'])} stds and {len(data['explained_variance_ratio'])} variance ratios"
    if len(data["exemplar_names"]) != m:
        return f"{m} exemplars but {len(data['exemplar_names'])} names"
    for key in ("mean", "components", "stds", "exemplars"):
        if not np.issubdtype(np.asarray(data[key]).dtype, np.number) or not np.all(np.isfinite(data[key])):
            return f"{key} holds values that are not finite numbers"
    if np.any(np.asarray(data["stds"]) <= 0):
        return "stds must be above 0"
    return None


def augment_to_kitti_sizes(wireframes, *, n_per_exemplar: int, rng=None,
                           size_mean=KITTI_CAR_SIZE["mean"], size_std=KITTI_CAR_SIZE["std"]) -> np.ndarray:
    """Anisotropically rescaled copies of the exemplars with KITTI car size statistics.

    Each copy of exemplar ``m`` gets target dimensions ``(l, w, h)`` drawn independently
    from normal distributions with the KITTI 'Car' means and standard deviations
    (truncated at +-2.5 std), and is scaled along x, z and y by target / exemplar
    dimension, about the object origin (bottom centre, so it keeps standing on the
    ground). The exemplar's dimensions are those of its wireframe's bounding box. The
    copies thus carry the exemplar's proportions-free shape detail (where the pillars,
    arches, lights sit relative to the box) combined with a realistic metric size; no
    new shape detail is invented.

    Returns
    -------
    (M * n_per_exemplar, 36, 3) array
        The copies of exemplar ``m`` are rows ``m * n_per_exemplar`` to
        ``(m + 1) * n_per_exemplar - 1``.

    Examples
    --------
    >>> exemplars = load_default().exemplars[:2]  # two CAD wireframes (M, 36, 3)
    >>> copies = augment_to_kitti_sizes(exemplars, n_per_exemplar=5, rng=0)
    >>> copies.shape
    (10, 36, 3)
    >>> lengths = copies[..., 0].max(axis=1) - copies[..., 0].min(axis=1)
    >>> bool(np.all(np.abs(lengths - 3.88) <= 2.5 * 0.43 + 1e-9))  # KITTI's mean length +- 2.5 std
    True
    >>> bool(np.all(copies[..., 1].max(axis=1) == 0))  # still standing on the ground (y = 0)
    True
    """
    W = np.asarray(wireframes, dtype=float)
    check_shape("wireframes", W, (None, N_VERTICES, 3))
    rng = np.random.default_rng(rng)
    ext = W.max(axis=1) - W.min(axis=1)  # (M, 3) in x, y, z
    dims = np.stack([ext[:, 0], ext[:, 2], ext[:, 1]], axis=1)  # l, w, h
    z = np.clip(rng.standard_normal((len(W), n_per_exemplar, 3)), -2.5, 2.5)
    target = np.asarray(size_mean) + z * np.asarray(size_std)
    factor = target / dims[:, None, :]  # (M, n, 3) l, w, h
    scale_xyz = np.stack([factor[..., 0], factor[..., 2], factor[..., 1]], axis=-1)
    return (W[:, None] * scale_xyz[:, :, None, :]).reshape(-1, N_VERTICES, 3)


def component_signs(vt: np.ndarray, *, rtol: float = 1e-6) -> np.ndarray:
    """Signs ``(K,)`` that make each row of ``vt`` ``(K, D)`` start positive where it is largest.

    A component's sign is arbitrary; the convention makes it reproducible: the first entry whose
    magnitude lies within ``rtol`` of the row's largest is made positive. The first, not the
    largest: a left/right symmetric wireframe's components have exact ties between mirrored
    vertices, which rounding (another BLAS kernel) would break either way.

    Examples
    --------
    >>> vt = np.array([[0.6, -0.6, 0.1], [-0.9, 0.2, 0.0]])
    >>> component_signs(vt)  # a tie: the first of the two decides
    array([ 1., -1.])
    >>> component_signs(vt - np.array([[0.0, 1e-12, 0.0], [0.0, 0.0, 0.0]]))  # rounding: the same
    array([ 1., -1.])
    """
    vt = np.asarray(vt, dtype=float)
    mag = np.abs(vt)
    first = np.argmax(mag >= mag.max(axis=1, keepdims=True) * (1.0 - rtol), axis=1)
    return np.where(vt[np.arange(len(vt)), first] < 0, -1.0, 1.0)


def fit_shape_model(wireframes, names, *, n_components: int | None = None,
                    augment: int = 0, rng=None) -> ShapeModel:
    """PCA of annotated wireframes.

    Parameters
    ----------
    wireframes : (M, 36, 3) array
        Annotated exemplars (object frame, metres).
    names : sequence of M str
    n_components : int, optional
        Components kept; default: all with non-negligible variance (at most
        ``M * (augment or 1) - 1``).
    augment : int
        If > 0, the PCA is fitted on ``augment`` copies per exemplar made by
        :func:`augment_to_kitti_sizes` (the exemplars themselves are not added), so
        that the mean and the size modes follow KITTI car dimensions. The stored
        ``exemplars`` are always the measured, un-augmented wireframes.
    rng : seed or Generator, for the augmentation.

    Returns
    -------
    ShapeModel

    Examples
    --------
    >>> exemplars = load_default().exemplars[:4]  # four CAD wireframes (M, 36, 3)
    >>> model = fit_shape_model(exemplars, ["a", "b", "c", "d"])
    >>> model.n_components  # M - 1: four shapes span a 3-dimensional space about their mean
    3
    >>> bool(np.allclose(model.reconstruct(exemplars), exemplars))  # all components: exact
    True
    >>> round(float(model.explained_variance_ratio.sum()), 6)
    1.0
    """
    W = np.asarray(wireframes, dtype=float)
    check_shape("wireframes", W, (None, N_VERTICES, 3))
    names = tuple(str(n) for n in names)
    if len(names) != len(W):
        raise ValueError(f"{len(W)} wireframes but {len(names)} names")
    if len(W) < 2:
        raise ValueError("need at least 2 exemplars to fit a shape model")
    data = augment_to_kitti_sizes(W, n_per_exemplar=augment, rng=rng) if augment > 0 else W
    flat = data.reshape(len(data), -1)
    mean = flat.mean(axis=0)
    _, sv, vt = np.linalg.svd(flat - mean, full_matrices=False)
    var = sv**2 / max(len(data) - 1, 1)
    keep = var > 1e-12 * max(var.max(), 1e-300)
    k = int(keep.sum()) if n_components is None else min(int(n_components), int(keep.sum()))
    vt = vt * component_signs(vt)[:, None]
    return ShapeModel(
        mean=mean.reshape(N_VERTICES, 3),
        components=vt[:k].reshape(k, N_VERTICES, 3),
        stds=np.sqrt(var[:k]),
        explained_variance_ratio=var[:k] / var.sum(),
        exemplar_names=names,
        exemplars=W.copy(),
    )


def load_default() -> ShapeModel:
    """The shape model shipped with wirescene (``wirescene/data/shape_model.npz``),
    trained by ``wirescene train shape``.

    Examples
    --------
    >>> model = load_default()
    >>> model.mean.shape, len(model.exemplar_names) == len(model.exemplars)
    ((36, 3), True)
    """
    if not DEFAULT_MODEL_PATH.exists():
        raise InputError("default shape model missing; run `wirescene train shape`", path=DEFAULT_MODEL_PATH)
    return ShapeModel.load(DEFAULT_MODEL_PATH)
