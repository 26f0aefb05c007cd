"""Training patches of the part detectors: the container shared by the synthetic
(:mod:`wirescene.training.parts`) and real (:mod:`wirescene.training.parts_real`) sources,
and the descriptor extraction both use."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wirescene.parts import features as feat
from wirescene.training.scale import RowSample


@dataclass
class PatchData:
    """Descriptors per kind ``{kind: (N, D)}``, labels ``y (N,)`` (36 = background),
    ``group (N,)``: CAD model index, -1 for non-rendered background; ``pos (N, 2)``:
    position relative to the (jittered) box the patch was described in
    (:func:`wirescene.parts.detector.box_position`), where known; ``ctx (N, 72)``: the box's
    gradient layout (:func:`wirescene.parts.features.box_context`), where known."""

    X: dict
    y: np.ndarray
    group: np.ndarray
    names: list
    pos: np.ndarray | None = None
    ctx: np.ndarray | None = None

    def __len__(self):
        return len(self.y)


def describe_in_box(image, box, pts, kinds, *, scale, edges=None):
    """``({kind: (N, D)}, ctx (N, 72) or None, pos (N, 2))`` of native points in ``box``
    (:func:`wirescene.parts.detector.box_descriptors`); ``ctx`` when a multi-scale kind is asked."""
    from wirescene.parts.detector import box_descriptors, box_position

    X, ctx = {}, None
    for k in kinds:
        e = edges if k in feat.EDGE_KINDS else None
        if ctx is None and k in ("ghog_ms", "ghog_msc"):
            d = box_descriptors(image, box, pts, k, scale=scale, edges=e, context=True)
            X[k], ctx = d[:, :-feat.CONTEXT_DIM], d[:, -feat.CONTEXT_DIM:]
        else:
            X[k] = box_descriptors(image, box, pts, k, scale=scale, edges=e)
    return X, ctx, box_position(pts, box)


def _rng(seed, *keys):
    return np.random.default_rng(np.random.SeedSequence([int(seed)] + [int(k) for k in keys]))


class PatchCollector:
    """Accumulates described patches of one training source into a :class:`PatchData`.

    ``max_patches``: keep at most that many (None: all), a uniform random sample of every
    patch added (:class:`~wirescene.training.scale.RowSample`: each patch draws a key from
    the stream ``seed``, and the ``max_patches`` of lowest key are kept, in the order they
    came); below it nothing is dropped. The collector holds at most 1.5 times
    ``max_patches`` at once.
    """

    def __init__(self, kinds, *, max_patches: int | None = None, seed: int = 0):
        self.kinds = tuple(kinds)
        # columns: one descriptor array per kind, then y, group, pos and (ghog_ms kinds) ctx
        self._rows = RowSample(max_patches, rng=_rng(seed, 11))

    def __len__(self):
        return self._rows.n

    def add(self, image, box, pts, y, scale, edges, group):
        """Describe points ``pts`` ``(N, 2)`` of ``image`` in ``box`` with label(s) ``y``."""
        if len(pts) == 0:
            return
        X, ctx, pos = describe_in_box(image, box, pts, self.kinds, scale=scale, edges=edges)
        labels = np.broadcast_to(np.asarray(y, dtype=np.int64), (len(pts),)).copy()
        self._rows.add(*(X[k] for k in self.kinds), labels, np.full(len(pts), group, dtype=np.int64), pos,
                       *(() if ctx is None else (ctx,)))

    def data(self, names) -> PatchData:
        if not len(self):
            raise ValueError("need at least one patch")
        cols = self._rows.arrays()
        n = len(self.kinds)
        X = {k: c.astype(np.float32) for k, c in zip(self.kinds, cols[:n])}
        y, group, pos = cols[n:n + 3]
        ctx = cols[n + 3] if len(cols) > n + 3 else None
        return PatchData(X=X, y=y, group=group, names=list(names), pos=pos, ctx=ctx)
