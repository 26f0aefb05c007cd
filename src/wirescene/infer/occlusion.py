"""Vertex-level occlusion of wireframe hypotheses (paper Sec. 3.3 and 4.3).

Deterministic occlusion is computed by ray casting from the camera centre to every
wireframe vertex:

* :func:`self_occlusion` -- hidden by a face of the same object (the ``a_0`` visibility
  ``o_j(theta_gp, q_az, s, a_0)`` of the likelihood's denominator);
* :func:`inter_object_occlusion` -- hidden by a face of another modelled object of the
  same scene hypothesis (the paper's ``Gamma`` operator, before occluder-mask fitting).

:func:`hidden_reasons` names what hides each vertex of a fitted car (the pictures draw it).

Both are vectorised over any leading batch (samples x objects), with no Python loop
over hypotheses or vertices; see ``benchmarks/bench_occlusion.py``.

A back-facing pre-test (skip faces turned away from the camera) is not used: the face
list is closed and consistently oriented, but deformed shapes can fold through
themselves, and then the faces turned to the camera miss some hidden vertices
(``benchmarks/bench_occlusion.py`` counts them; ``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import numpy as np

from wirescene.core.errors import check_shape
from wirescene.core.raycast import (
    DEFAULT_EPS,
    check_faces,
    incidence,
    interaction_candidates,
    mesh_vertices_blocked,
    segment_blocked,
)
from wirescene.core.wireframe import HIDDEN_BY

__all__ = ["self_occlusion", "inter_object_occlusion", "hidden_reasons", "incidence", "interaction_candidates"]


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

    Examples
    --------
    >>> faces = np.array([[0, 1, 2]])  # one triangle 5 m ahead of the camera
    >>> vertices = np.array([[-1.0, -1, 5], [1, -1, 5], [0, 1, 5], [0, 0, 10], [5, 0, 10]])
    >>> self_occlusion(vertices, faces, np.zeros(3))  # the vertex right behind it is hidden
    array([False, False, False,  True, False])
    """
    if device != "numpy":
        from wirescene.infer import torch_backend

        return torch_backend.self_occlusion(vertices, faces, camera_center, eps=eps, device=device)
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (..., None, 3))
    faces = check_faces(faces, vertices.shape[-2])
    return mesh_vertices_blocked(camera_center, vertices, faces, eps=eps, ignore=incidence(faces, vertices.shape[-2]))


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

    Examples
    --------
    >>> faces = np.array([[0, 1, 2]])
    >>> near = np.array([[-1.0, -1, 5], [1, -1, 5], [0, 1, 5], [9, 9, 9]])  # a triangle at 5 m, a point aside
    >>> far = np.array([[-1.0, -1, 20], [1, -1, 20], [0, 1, 20], [0, 0, 10]])  # the same at 20 m, a point at 10 m
    >>> inter_object_occlusion(np.stack([near, far]), faces, np.zeros(3))  # (N, V): all of the far one hidden
    array([[False, False, False, False],
           [ True,  True,  True,  True]])
    """
    if device != "numpy":
        from wirescene.infer import torch_backend

        return torch_backend.inter_object_occlusion(vertices, faces, camera_center, eps=eps, device=device)
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (..., None, None, 3))
    N, V = vertices.shape[-3], vertices.shape[-2]
    faces = check_faces(faces, V)
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


def hidden_reasons(self_hidden, *, truncated, other_car, occluder) -> np.ndarray:
    """What hides each vertex, in the words of :data:`wirescene.core.wireframe.HIDDEN_BY`:
    ``"visible"`` where nothing does, else the first of its own car (``self_hidden``), the image's
    border (``truncated``), another car (``other_car``, ``Gamma``) and the occluder mask
    (``occluder``): the order in which the likelihood counts them (a mask is charged only for
    the vertices nothing else hides, :func:`wirescene.infer.masks.best_mask`).

    Parameters
    ----------
    self_hidden, truncated, other_car, occluder : (..., V) bool arrays

    Returns
    -------
    (..., V) str array

    Examples
    --------
    >>> own, border = np.array([0, 1, 1, 0, 0], bool), np.array([0, 0, 1, 1, 0], bool)
    >>> masked = np.array([0, 1, 0, 1, 1], bool)
    >>> hidden_reasons(own, truncated=border, other_car=np.zeros(5, bool), occluder=masked).tolist()
    ['visible', 'self', 'self', 'truncated', 'occluder']
    """
    flags = np.broadcast_arrays(*(np.asarray(f, bool) for f in (self_hidden, truncated, other_car, occluder)))
    first = np.argmax(np.stack([*flags, np.ones_like(flags[0])]), axis=0)  # the first reason that holds
    return np.asarray(HIDDEN_BY[1:] + HIDDEN_BY[:1])[first]
