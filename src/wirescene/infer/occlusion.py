"""Vertex-level occlusion of wireframe hypotheses (paper Sec. 3.3 and 4.3).

Deterministic occlusion is computed by ray casting from the camera centre to every
wireframe vertex:

* :func:`self_occlusion` -- hidden by a face of the same object (the ``a_0`` visibility
  ``o_j(theta_gp, q_az, s, a_0)`` of the likelihood's denominator);
* :func:`inter_object_occlusion` -- hidden by a face of another modelled object of the
  same scene hypothesis (the paper's ``Gamma`` operator, before occluder-mask fitting).

Both are vectorised over any leading batch (samples x objects), with no Python loop
over hypotheses or vertices; see ``benchmarks/bench_occlusion.py``.

A back-facing pre-test (skip faces turned away from the camera) was considered and not
used: it is exact only for closed, consistently outward-oriented meshes with the camera
outside, which the wireframe's face list does not guarantee, and in the batched
formulation every (vertex, face) pair is evaluated by one matrix product anyway, so
masking faces would not save work.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.arrays import point_bounds
from wirescene.core.errors import ShapeError, check_shape
from wirescene.core.raycast import DEFAULT_EPS, mesh_vertices_blocked, segment_blocked


def _check_faces(faces, n_vertices: int) -> np.ndarray:
    faces = np.asarray(faces)
    check_shape("faces", faces, (None, 3))
    if not np.issubdtype(faces.dtype, np.integer):
        raise ShapeError(f"faces must be integer indices, got dtype {faces.dtype}")
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        raise ShapeError(f"faces index vertices outside [0, {n_vertices})")
    return faces


def incidence(faces, n_vertices: int) -> np.ndarray:
    """``(V, F)`` bool: True where vertex ``v`` is a corner of face ``f``."""
    faces = _check_faces(faces, n_vertices)
    inc = np.zeros((n_vertices, len(faces)), dtype=bool)
    inc[faces, np.arange(len(faces))[:, None]] = True
    return inc


def self_occlusion(vertices, faces, camera_center, *, eps: float = DEFAULT_EPS, device: str = "numpy") -> np.ndarray:
    """Vertices hidden by their own object's surface.

    Parameters
    ----------
    vertices : (..., V, 3) array
        Wireframe vertices in the camera frame, any batch of hypotheses.
    faces : (F, 3) int array
        Triangles of the wireframe surface (vertex indices), shared by the batch.
    camera_center : (3,) or (..., 3) array
        Optical centre (``Camera.center``), broadcast against the batch.
    eps : float, optional
        Relative tolerance of :func:`wirescene.core.raycast.segment_blocked`.
    device : str, optional
        ``"numpy"`` (default), or a PyTorch device (``"cpu"``, ``"cuda"``,
        ``"cuda:N"``) to compute with :mod:`wirescene.infer.torch_backend`.

    Returns
    -------
    hidden : (..., V) bool array
        True where the segment from the camera centre to the vertex crosses a face of
        the same object before reaching it. Faces incident to a vertex are never tested
        against it, so a vertex is never hidden by its own faces.
    """
    if device != "numpy":
        from wirescene.infer import torch_backend

        return torch_backend.self_occlusion(vertices, faces, camera_center, eps=eps, device=device)
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (..., None, 3))
    faces = _check_faces(faces, vertices.shape[-2])
    return mesh_vertices_blocked(camera_center, vertices, faces, eps=eps, ignore=incidence(faces, vertices.shape[-2]))


def interaction_candidates(rel) -> np.ndarray:
    """Which (target object ``i``, occluder object ``j != i``) pairs of each scene can
    interact: ``(S, N, N)`` bool for vertices ``rel`` ``(S, N, V, 3)`` relative to the
    camera centre.

    An exact prefilter of :func:`inter_object_occlusion`: in a street scene most cars do
    not overlap in the image. A segment from the camera to a vertex of ``i`` hits a
    triangle of ``j`` only where the central projections of both overlap, and only at a
    depth between ``j``'s nearest point and the target's depth. The projection onto
    ``z = 1`` is used where every vertex of both objects lies in front of that plane;
    other pairs are always kept.
    """
    rel = np.asarray(rel, dtype=float)
    check_shape("rel", rel, (None, None, None, 3))
    N = rel.shape[1]
    z = rel[..., 2]
    front = (z > 1e-6).all(axis=-1)  # (S, N)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = rel[..., :2] / z[..., None]
    lo, hi = point_bounds(p)  # (S, N, 2); meaningless where not front, masked below
    overlap = np.all((lo[:, :, None] <= hi[:, None, :]) & (lo[:, None, :] <= hi[:, :, None]), axis=-1)
    nearer = z.min(axis=-1)[:, None, :] < z.max(axis=-1)[:, :, None]  # occluder j starts before i ends
    candidate = ~(front[:, :, None] & front[:, None, :]) | (overlap & nearer)
    return candidate & ~np.eye(N, dtype=bool)


def inter_object_occlusion(vertices, faces, camera_center, *, eps: float = DEFAULT_EPS, device: str = "numpy") -> np.ndarray:
    """Vertices of each object hidden by faces of any *other* object (``Gamma``).

    Parameters
    ----------
    vertices : (..., N, V, 3) array
        Wireframe vertices of the N objects of each scene hypothesis, camera frame.
    faces : (F, 3) int array
        Wireframe triangles, shared by all objects.
    camera_center : (3,) or (..., 3) array
        Optical centre, broadcast against the leading batch ``...`` (one per scene,
        not per object).
    eps : float, optional
        Relative tolerance of :func:`wirescene.core.raycast.segment_blocked`.
    device : str, optional
        As in :func:`self_occlusion`.

    Returns
    -------
    hidden : (..., N, V) bool array
        True where the segment from the camera centre to vertex ``v`` of object ``i``
        crosses a face of some object ``j != i`` before reaching it. Self-occlusion is
        *not* included; combine with :func:`self_occlusion` as needed (the paper casts
        rays only to vertices that are not self-occluded, which gives the same flags
        on those vertices).
    """
    if device != "numpy":
        from wirescene.infer import torch_backend

        return torch_backend.inter_object_occlusion(vertices, faces, camera_center, eps=eps, device=device)
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (..., None, None, 3))
    N, V = vertices.shape[-3], vertices.shape[-2]
    faces = _check_faces(faces, V)
    if N < 2:
        return np.zeros(vertices.shape[:-1], dtype=bool)
    center = np.asarray(camera_center, dtype=float)
    check_shape("camera_center", center, (..., 3))
    batch = np.broadcast_shapes(vertices.shape[:-3], center.shape[:-1])
    q = np.broadcast_to(vertices - center[..., None, None, :], batch + (N, V, 3)).reshape(-1, N, V, 3)
    # Only object pairs that can interact are ray cast (an exact prefilter).
    s_idx, i_idx, j_idx = np.nonzero(interaction_candidates(q))
    hidden = np.zeros(q.shape[:-1], dtype=bool)
    if len(s_idx):
        blocked = segment_blocked(np.zeros(3), q[s_idx, i_idx], q[s_idx, j_idx][:, faces], eps=eps)
        # A target may be hidden by several occluders: accumulate with logical or.
        np.logical_or.at(hidden, (s_idx, i_idx), blocked)
    return hidden.reshape(batch + (N, V))
