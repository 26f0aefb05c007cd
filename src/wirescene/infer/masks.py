"""Occluder masks (paper Sec. 3.3) in the fit: which vertices each mask hides, and the search of
the mask that explains a car's missing evidence (:func:`best_mask`) or the occlusion by the other
cars (:func:`fit_mask`). The mask set and its frame, the object's projected box
(:func:`occluder_masks`, :func:`normalised_coordinates`), live in :mod:`wirescene.core.occluders`,
where the pictures find them too.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.core.occluders import normalised_coordinates, occluder_masks

__all__ = ["occluder_masks", "normalised_coordinates", "mask_hidden", "all_mask_hidden", "mask_weight_sums",
           "best_mask", "fit_mask"]


def mask_hidden(uv: np.ndarray, mask_index, *, masks: np.ndarray | None = None) -> np.ndarray:
    """Vertices ``(..., V)`` hidden by masks ``mask_index`` ``(...)`` (0 hides nothing).

    Examples
    --------
    >>> uv = np.array([[10.0, 20.0], [30.0, 20.0], [10.0, 40.0], [30.0, 40.0], [20.0, 30.0]])  # corners, centre
    >>> left_half = int(np.flatnonzero((occluder_masks() == [0.0, 0.0, 0.5, 1.0]).all(1))[0])
    >>> mask_hidden(uv, left_half)  # the left corners and the centre (on the band's edge)
    array([ True, False,  True, False,  True])
    >>> bool(mask_hidden(uv, 0).any())  # a0
    False
    """
    masks = occluder_masks() if masks is None else masks
    q = normalised_coordinates(uv)
    r = masks[np.asarray(mask_index)][..., None, :]
    return (q[..., 0] >= r[..., 0]) & (q[..., 0] <= r[..., 2]) & (q[..., 1] >= r[..., 1]) & (q[..., 1] <= r[..., 3]) & (
        r[..., 2] > r[..., 0]
    )


def all_mask_hidden(uv: np.ndarray, *, masks: np.ndarray | None = None) -> np.ndarray:
    """Hidden flags ``(..., A, V)`` of every mask for vertices ``uv`` ``(..., V, 2)``.

    Examples
    --------
    >>> uv = np.array([[10.0, 20.0], [30.0, 20.0], [10.0, 40.0], [30.0, 40.0], [20.0, 30.0]])  # corners, centre
    >>> hidden = all_mask_hidden(uv)
    >>> hidden.shape, bool(np.array_equal(hidden[7], mask_hidden(uv, 7)))  # (A, V): every mask at once
    ((246, 5), True)
    """
    masks = occluder_masks() if masks is None else masks
    q = normalised_coordinates(uv)[..., None, :, :]
    r = masks[:, None, :]
    return (q[..., 0] >= r[..., 0]) & (q[..., 0] <= r[..., 2]) & (q[..., 1] >= r[..., 1]) & (q[..., 1] <= r[..., 3]) & (
        r[..., 2] > r[..., 0]
    )


#: Point sets :func:`mask_weight_sums` reads at a time.
MASK_BLOCK = 32


@lru_cache(maxsize=1)
def _factorised_masks():
    """The mask set as products of x- and y-intervals: ``(x_intervals (I, 2),
    y_intervals (J, 2), i (A,), j (A,), nonempty (A,))``."""
    m = occluder_masks()
    xs, i = np.unique(m[:, [0, 2]], axis=0, return_inverse=True)
    ys, j = np.unique(m[:, [1, 3]], axis=0, return_inverse=True)
    return xs, ys, i.ravel(), j.ravel(), m[:, 2] > m[:, 0]


def mask_weight_sums(uv: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``sum_v hidden_a(v) * weights_v`` for every mask ``a``: ``(..., A)``.

    Parameters
    ----------
    uv : (..., V, 2) array
        Vertex projections.
    weights : (..., V) array

    Notes
    -----
    Equal to ``(all_mask_hidden(uv) * weights[..., None, :]).sum(-1)`` but never builds
    the ``(..., A, V)`` flags: every mask is a product of one of I x-intervals and one
    of J y-intervals (I, J << A), so the sums for all masks are the entries of the
    ``(I, J)`` matrix ``X diag(w) Y^T`` -- one small batched matrix product.

    Examples
    --------
    >>> uv = np.array([[10.0, 20.0], [30.0, 20.0], [10.0, 40.0], [30.0, 40.0], [20.0, 30.0]])  # corners, centre
    >>> weights = np.ones(5)
    >>> sums = mask_weight_sums(uv, weights)  # vertices each mask hides
    >>> sums.shape, float(sums[0]), bool(np.allclose(sums, (all_mask_hidden(uv) * weights).sum(-1)))
    ((246,), 0.0, True)
    """
    xs, ys, i, j, nonempty = _factorised_masks()
    q = normalised_coordinates(uv)
    w = np.asarray(weights, dtype=float)
    check_shape("weights", w, q.shape[:-1])
    V = q.shape[-2]
    q, w = q.reshape(-1, V, 2), w.reshape(-1, V)
    sums = np.empty((len(q), len(i)))
    x_lo, x_hi = xs[:, :1, None], xs[:, 1:, None]  # (I, 1, 1)
    # MASK_BLOCK point sets at a time, their (I, rows, V) flags in cache, long rows for the comparisons;
    # each point set's matrix product is the one of the whole batch (the same BLAS call, the rows
    # of X further apart).
    for start in range(0, len(q), MASK_BLOCK):
        rows = slice(start, start + MASK_BLOCK)
        qx = np.ascontiguousarray(q[rows, :, 0])  # (r, V)
        inside = qx >= x_lo
        inside &= qx <= x_hi
        X = np.multiply(inside, w[rows])  # (I, r, V)
        qy = q[rows, None, :, 1]
        Y = ((qy >= ys[:, :1]) & (qy <= ys[:, 1:])).astype(float)  # (r, J, V)
        block = np.matmul(X.transpose(1, 0, 2), np.swapaxes(Y, -1, -2))  # (r, I, J)
        sums[rows] = np.where(nonempty, block[:, i, j], 0.0)
    return sums.reshape(uv.shape[:-2] + (len(i),))


def best_mask(uv: np.ndarray, evidence: np.ndarray, self_hidden: np.ndarray, *, c: float, hidden=None) -> np.ndarray:
    """The searched occluder mask (paper Sec. 4.3): the index ``(...)`` maximising the
    object likelihood (Eq. 2) over the whole mask set.

    Parameters
    ----------
    uv : (..., V, 2) array
    evidence : (..., V) array
        Part evidence ``log(S_j / S_b)`` at the vertices.
    self_hidden : (..., V) bool array
    c : float
        The score charged to occluded parts.
    hidden : (..., V) bool array, optional
        Vertices occluded whatever the mask (e.g. the deterministic ``Gamma``).

    Notes
    -----
    With ``H_a`` the vertices hidden by mask ``a`` or by ``hidden``, Eq. 2's numerator is
    ``sum_{visible0} e - sum_{visible0 & H_a} (e - c)`` and its denominator does not
    depend on ``a``, so the best mask minimises the sum of ``e - c`` over the visible0
    vertices it hides beyond ``hidden``: one :func:`mask_weight_sums` call.

    Examples
    --------
    >>> uv = np.array([[10.0, 20.0], [30.0, 20.0], [10.0, 40.0], [30.0, 40.0], [20.0, 30.0]])  # corners, centre
    >>> evidence = np.array([2.0, -1.0, 2.0, -1.0, 2.0])  # nothing seen at the right corners
    >>> a = best_mask(uv, evidence, np.zeros(5, bool), c=0.5)
    >>> occluder_masks()[a], mask_hidden(uv, a)  # hide the right 10%: those score c = 0.5 instead of -1
    (array([0.9, 0. , 1. , 1. ]), array([False,  True, False,  True, False]))
    """
    loss = np.where(self_hidden, 0.0, np.asarray(evidence, dtype=float) - c)
    if hidden is not None:
        loss = np.where(hidden, 0.0, loss)
    return np.argmin(mask_weight_sums(uv, loss), axis=-1)


def fit_mask(uv: np.ndarray, occluded: np.ndarray, candidates: np.ndarray, *, weight_occluded: float = 2.0) -> np.ndarray:
    """Index ``(...)`` of the mask that best represents a set of occluded vertices.

    Maximises the number of candidate vertices with the right label, occluded ones
    counting ``weight_occluded`` times (paper Sec. 4.3: twice as much).

    Parameters
    ----------
    uv : (..., V, 2) array
    occluded : (..., V) bool array
        E.g. the deterministic inter-object occlusion ``Gamma``.
    candidates : (..., V) bool array
        The vertices that count (not self-occluded).
    weight_occluded : float, optional
        What an occluded vertex counts against a visible one.

    Returns
    -------
    (...) int array
        The index of the best mask of :func:`occluder_masks`.

    Examples
    --------
    >>> uv = np.array([[10.0, 20.0], [30.0, 20.0], [10.0, 40.0], [30.0, 40.0], [20.0, 30.0]])  # corners, centre
    >>> occluded = np.array([False, True, False, True, False])  # e.g. the right side hidden by another car
    >>> a = fit_mask(uv, occluded, np.ones(5, bool))
    >>> bool(np.array_equal(mask_hidden(uv, a), occluded))
    True
    """
    occ = np.asarray(occluded, bool)
    cand = np.asarray(candidates, bool)
    # sum_v cand (w_o H occ + (1 - H)(1 - occ)) = sum_v cand (1 - occ) + sum_v H u_v; the
    # first term does not depend on the mask.
    u = cand * np.where(occ, weight_occluded, -1.0)
    return np.argmax(mask_weight_sums(uv, np.broadcast_to(u, np.shape(uv)[:-1])), axis=-1)
