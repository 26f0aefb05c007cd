"""Training patches of the part detectors: the container shared by the synthetic
(:mod:`wirescene.training.parts`) and real (:mod:`wirescene.training.parts_real`) sources,
and the descriptor extraction both use."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wirescene.parts import features as feat


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
