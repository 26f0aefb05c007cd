"""Whitened HOG: the background statistics of HOG cells, for templates trained in decorrelated
features (Hariharan, Malik and Ramanan, "Discriminative decorrelation for clustering and
classification", ECCV 2012).

HOG cells of natural images are strongly correlated with their neighbours. A linear SVM
regularised by ``|w|^2`` treats every template dimension alike; trained on features whitened
by the background covariance ``S`` it is regularised by ``w^T S w`` instead, which penalises the
directions every background window already varies in, so that few positives suffice. The
covariance of a ``th x tw``-cell window is assembled from one stationary auto-covariance of
the cells at every offset (:func:`background_statistics`), so one estimate serves every
template size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wirescene.core.errors import ShapeError
from wirescene.predetect.hog import N_FEAT


@dataclass(frozen=True)
class BackgroundStatistics:
    """Stationary statistics of HOG cells: ``mean`` ``(31,)`` and ``gamma`` ``(Th, 2 Tw - 1,
    31, 31)``, ``gamma[dy, Tw - 1 + dx]`` the covariance of a cell with the cell ``dy`` rows
    below and ``dx`` columns right of it."""

    mean: np.ndarray
    gamma: np.ndarray

    @property
    def max_cells(self) -> tuple[int, int]:
        return self.gamma.shape[0], (self.gamma.shape[1] + 1) // 2


def background_statistics(levels, max_cells: tuple[int, int]) -> BackgroundStatistics:
    """:class:`BackgroundStatistics` of the HOG levels ``levels`` (arrays ``(Hc, Wc, 31)``),
    for windows of up to ``max_cells`` ``(Th, Tw)`` cells.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> stats = background_statistics([rng.random((20, 30, 31), np.float32)], (2, 3))
    >>> stats.gamma.shape
    (2, 5, 31, 31)
    """
    Th, Tw = (int(v) for v in max_cells)
    levels = [np.asarray(F, np.float64) for F in levels]
    if not levels or any(F.ndim != 3 or F.shape[2] != N_FEAT for F in levels):
        raise ShapeError(f"levels must be (Hc, Wc, {N_FEAT}) arrays")
    n = sum(F.shape[0] * F.shape[1] for F in levels)
    mean = sum(F.sum((0, 1)) for F in levels) / n
    gamma = np.zeros((Th, 2 * Tw - 1, N_FEAT, N_FEAT))
    count = np.zeros((Th, 2 * Tw - 1))
    for F in levels:
        G = F - mean
        Hc, Wc = G.shape[:2]
        for dy in range(min(Th, Hc)):
            for dx in range(-min(Tw, Wc) + 1, min(Tw, Wc)):
                a = G[: Hc - dy, max(0, -dx): Wc - max(0, dx)].reshape(-1, N_FEAT)
                b = G[dy:, max(0, dx): Wc + min(0, dx)].reshape(-1, N_FEAT)
                gamma[dy, Tw - 1 + dx] += a.T @ b
                count[dy, Tw - 1 + dx] += len(a)
    gamma /= np.maximum(count, 1)[..., None, None]
    return BackgroundStatistics(mean.astype(np.float32), gamma)


def window_covariance(stats: BackgroundStatistics, th: int, tw: int) -> np.ndarray:
    """``(th * tw * 31, th * tw * 31)`` covariance of the flattened features of a ``th x tw``-cell
    window (row-major cells, as :func:`~wirescene.predetect.hog.crop_features` flattens them)."""
    Th, Tw = stats.max_cells
    if th > Th or tw > Tw:
        raise ShapeError(f"a {th} x {tw}-cell window exceeds the statistics' {Th} x {Tw} cells")
    cells = [(y, x) for y in range(th) for x in range(tw)]
    D = len(cells) * N_FEAT
    S = np.empty((D, D))
    for i, (y1, x1) in enumerate(cells):
        for j, (y2, x2) in enumerate(cells):
            dy, dx = y2 - y1, x2 - x1
            block = stats.gamma[dy, Tw - 1 + dx] if dy >= 0 else stats.gamma[-dy, Tw - 1 - dx].T
            S[i * N_FEAT:(i + 1) * N_FEAT, j * N_FEAT:(j + 1) * N_FEAT] = block
    return (S + S.T) / 2


def whitening_matrix(stats: BackgroundStatistics, th: int, tw: int, *, ridge: float = 0.1) -> np.ndarray:
    """``M`` ``(D, D)``: features ``x @ M`` of a ``th x tw``-cell window are decorrelated under
    the background (covariance ``S + ridge * mean(diag S) * I`` made the identity), scaled back
    to the raw features' mean variance so that an SVM's ``C`` keeps its meaning. A template
    ``w'`` learnt on them is ``M @ w'`` on the raw features.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> stats = background_statistics([rng.random((20, 30, 31), np.float32)], (2, 2))
    >>> whitening_matrix(stats, 1, 2).shape
    (62, 62)
    """
    S = window_covariance(stats, th, tw)
    scale = float(np.mean(np.diag(S)))
    L = np.linalg.cholesky(S + ridge * scale * np.eye(len(S)))
    # x' = L^-1 x: with S' = L L^T, cov(x') = I; as a right-multiplied row vector that is x @ L^-T
    return (np.linalg.inv(L).T * np.sqrt(scale)).astype(np.float32)
