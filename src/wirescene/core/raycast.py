"""Ray/triangle occlusion tests.

Two paths, for two different workloads:

* :func:`segment_blocked` and :func:`mesh_vertices_blocked` -- pure numpy, a batched
  ray/triangle test for the inference hot path: a few dozen wireframe vertices tested
  against a few dozen wireframe triangles, for thousands of hypotheses (particles x
  objects x samples) at once. All rays of one batch element share their origin (the
  camera centre), so Moller-Trumbore's barycentric tests become three dot products with
  per-triangle vectors: one float32 batched matrix product and three comparisons per
  (ray, triangle) pair, then a float64 depth test of the few pairs that pass.
* :func:`first_hit_distance` -- Embree (via trimesh) for large meshes, e.g. one ray per
  pixel against a 10k-triangle CAD model in the renderer.
"""

from __future__ import annotations

import warnings

import numpy as np

from wirescene.core.arrays import point_bounds
from wirescene.core.errors import DependencyError, ShapeError, check_shape

# Default relative tolerance on the segment parameter t (0 at the origin, 1 at the
# target). A hit only blocks the segment if 0 < t < 1 - eps. 1e-6 of the segment
# length is 10 micrometres at 10 m: far below any geometric detail of a car, yet far
# above float64 rounding of t (about 1e-15 / sin(grazing angle)), so a vertex is not
# reported as occluded by the faces it is a corner of, even at grazing view angles.
DEFAULT_EPS = 1e-6

# Upper bound on (rays x triangles) pairs handled per chunk. The largest temporary is
# 3 float32 per pair (1.5 MB at 2**17); chunks of 2**16..2**18 pairs were fastest on a
# 250 particles x 6 objects x 12 samples batch (cache-sized temporaries), 2**14 was
# 1.6x slower (Python overhead per chunk).
DEFAULT_CHUNK = 1 << 17

# Corner order B, C, A: the second factor of the edge cross products in _blocked_chunk.
_NEXT_CORNER = np.array([1, 2, 0])
# A triangle's corners A, B, C, then B, C, A: one gather gives both factors of its edge cross products.
_CORNERS_AND_NEXT = np.array([0, 1, 2, 1, 2, 0])


def check_eps(eps: float) -> None:
    """A ``ValueError`` unless ``eps`` (:func:`segment_blocked`) lies in ``[0, 0.5)``."""
    if not 0 <= eps < 0.5:
        raise ValueError(f"eps must be in [0, 0.5), got {eps}")


def _batch_shape(*shapes) -> tuple:
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ShapeError(f"batch dimensions do not broadcast: {' '.join(map(str, shapes))}") from exc


def segment_inputs(origins, targets, triangles, eps):
    """Checked float arrays of :func:`segment_blocked`'s inputs and their broadcast batch shape."""
    origins = np.asarray(origins, dtype=float)
    targets = np.asarray(targets, dtype=float)
    triangles = np.asarray(triangles, dtype=float)
    check_shape("origins", origins, (..., 3))
    check_shape("targets", targets, (..., None, 3))
    check_shape("triangles", triangles, (..., None, 3, 3))
    check_eps(eps)
    return origins, targets, triangles, _batch_shape(origins.shape[:-1], targets.shape[:-2], triangles.shape[:-3])


def _ignore_rows(ignore, batch: tuple, P: int, F: int):
    """``ignore`` as ``(1 or B, P, F)`` (a mask shared by the batch is not materialised)."""
    if ignore is None:
        return None
    ignore = np.asarray(ignore, dtype=bool)
    if ignore.ndim <= 2:
        return np.broadcast_to(ignore, (P, F))[None]
    try:
        return np.broadcast_to(ignore, batch + (P, F)).reshape(-1, P, F)
    except ValueError as exc:
        raise ShapeError(f"ignore {ignore.shape} does not broadcast to {batch + (P, F)}") from exc


def segment_blocked(
    origins,
    targets,
    triangles,
    *,
    eps: float = DEFAULT_EPS,
    ignore=None,
    chunk: int = DEFAULT_CHUNK,
) -> np.ndarray:
    """Whether the open segment from an origin to each target hits a triangle.

    Parameters
    ----------
    origins : (..., 3) or (3,) array
        One ray origin (typically the camera centre) per batch element.
    targets : (..., P, 3) array
        Segment end points (e.g. wireframe vertices).
    triangles : (..., F, 3, 3) array
        Occluding triangles, corners along the second-to-last axis.
    eps : float, optional
        Relative tolerance on the segment parameter ``t`` (0 at the origin, 1 at the
        target): a hit counts only if ``0 < t < 1 - eps``. It keeps a vertex from
        being blocked by the faces it belongs to (those are hit at ``t = 1`` up to
        rounding). See ``DEFAULT_EPS`` for the choice of the default.
    ignore : bool array broadcastable to (..., P, F), optional
        True where a triangle must not be tested against a target (e.g. the faces
        incident to that vertex), which makes the test exact regardless of ``eps``.
    chunk : int, optional
        Maximum number of ray-triangle pairs evaluated at once (memory bound).

    Returns
    -------
    blocked : (..., P) bool array
        True where some triangle is hit strictly between origin and target.

    Notes
    -----
    Leading dimensions of the three inputs broadcast against each other. Edges of
    triangles count as inside (watertight on indexed meshes, see ``_blocked_chunk``);
    a triangle whose plane contains the origin never blocks. Orientation of the
    triangles is irrelevant (two-sided test). The origin is assumed not to lie on a
    triangle. See :func:`mesh_vertices_blocked` for targets that are the vertices of
    the occluding mesh itself (cheaper: no triangle array is materialised).

    Examples
    --------
    >>> wall = np.array([[[-1.0, -1.0, 5.0], [1.0, -1.0, 5.0], [0.0, 1.0, 5.0]]])  # one triangle, z = 5 m
    >>> segment_blocked(np.zeros(3), [[0.0, 0.0, 10.0], [0.0, 0.0, 3.0], [5.0, 0.0, 10.0]], wall)
    array([ True, False, False])
    >>> # a batch: 250 origins, each with its own 36 targets, against one shared set of triangles
    >>> segment_blocked(np.zeros((250, 3)), np.full((250, 36, 3), 10.0), wall).shape
    (250, 36)
    """
    origins, targets, triangles, batch = segment_inputs(origins, targets, triangles, eps)
    F = triangles.shape[-3]
    tri = np.broadcast_to(triangles, batch + (F, 3, 3)).reshape((int(np.prod(batch, dtype=int)), F, 3, 3))

    def corners(d, o, sl):
        t = np.ascontiguousarray((tri[sl] - o[:, None, None, :]).transpose(0, 3, 2, 1))  # (b, xyz, corner, F)
        return t, t[:, :, _NEXT_CORNER]

    return _run_chunks(origins, targets, batch, F, corners, eps, ignore, chunk)


def mesh_vertices_blocked(
    origins,
    vertices,
    faces,
    *,
    eps: float = DEFAULT_EPS,
    ignore=None,
    chunk: int = DEFAULT_CHUNK,
) -> np.ndarray:
    """:func:`segment_blocked` with the vertices of a batch of meshes as targets and
    the same meshes' faces as occluders.

    Parameters
    ----------
    origins : (..., 3) or (3,) array
    vertices : (..., P, 3) array
        One mesh per batch element (e.g. a placed wireframe, or all wireframes of a
        scene hypothesis stacked).
    faces : (F, 3) int array
        Triangles as vertex indices, shared by the batch.
    eps, ignore, chunk
        As in :func:`segment_blocked`.

    Returns
    -------
    blocked : (..., P) bool array

    Notes
    -----
    Triangles are gathered one chunk at a time, so the ``(..., F, 3, 3)`` corner array
    (88 MB for 15k wireframes) is never built.

    Examples
    --------
    >>> # a 2 m cube 9 to 11 m ahead: vertices 0-3 its front face (z = 9), 4-7 its back face (z = 11)
    >>> vertices = np.array([[x, y, z] for z in (9.0, 11.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])
    >>> faces = np.array([[0, 1, 3], [0, 3, 2], [4, 7, 5], [4, 6, 7], [0, 4, 5], [0, 5, 1],
    ...                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    >>> mesh_vertices_blocked(np.zeros(3), vertices, faces)  # seen from the origin: the back face is hidden
    array([False, False, False, False,  True,  True,  True,  True])
    >>> mesh_vertices_blocked(np.zeros(3), np.stack([vertices] * 5), faces).shape  # 5 meshes, one face list
    (5, 8)
    """
    origins = np.asarray(origins, dtype=float)
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces)
    check_shape("origins", origins, (..., 3))
    check_shape("vertices", vertices, (..., None, 3))
    check_shape("faces", faces, (None, 3))
    check_eps(eps)
    batch = _batch_shape(origins.shape[:-1], vertices.shape[:-2])
    columns = np.ascontiguousarray(faces[:, _CORNERS_AND_NEXT].T)  # (6, F): corners A, B, C, then B, C, A

    def corners(d, o, sl):
        g = np.take(np.ascontiguousarray(d.transpose(0, 2, 1)), columns, axis=2)  # (b, xyz, 6, F)
        return g[:, :, :3], g[:, :, 3:]

    return _run_chunks(origins, vertices, batch, len(faces), corners, eps, ignore, chunk)


def _run_chunks(origins, targets, batch, F, triangles_of, eps, ignore, chunk):
    """:func:`_blocked_chunk` over the flattened ``batch``, a chunk of rows at a time;
    returns ``(*batch, P)``. ``triangles_of(d, o, sl)`` gives the corners of the ``F``
    triangles of rows ``sl`` relative to their origins ``o`` and the corners that follow
    them (B, C, A), both ``(b, xyz, corner, F)``, ``d`` being the targets relative to them."""
    P = targets.shape[-2]
    if P == 0 or F == 0 or 0 in batch:
        return np.zeros(batch + (P,), dtype=bool)
    B = int(np.prod(batch, dtype=int))
    o = np.broadcast_to(origins, batch + (3,)).reshape(B, 3)
    x = np.broadcast_to(targets, batch + (P, 3)).reshape(B, P, 3)
    ignore = _ignore_rows(ignore, batch, P, F)
    keep = None if ignore is None else ~ignore
    out = np.empty((B, P), dtype=bool)
    step = max(1, int(chunk) // max(1, P * F))
    for start in range(0, B, step):
        sl = slice(start, min(B, start + step))
        rows = None if keep is None else (keep if keep.shape[0] == 1 else keep[sl])
        d = x[sl] - o[sl, None, :]
        out[sl] = _blocked_chunk(d, *triangles_of(d, o[sl], sl), eps, rows)
    return out.reshape(batch + (P,))


def _blocked_chunk(d, t, nxt, eps, keep):
    """Segments from the origin to ``d`` (b, P, 3) against the triangles of corners ``t``
    (b, 3 xyz, 3 corners, F), both relative to the rows' shared origin, ``nxt`` being
    each triangle's corners in the order B, C, A; ``keep`` (1 or b, P, F) says which
    pairs are tested.

    With the triangle corners A, B, C, the direction D of a
    segment lies in the triangle's viewing cone iff ``s D.(A x B)``, ``s D.(B x C)`` and
    ``s D.(C x A)`` are all >= 0, where ``s = sign(A.(B x C))`` (equivalent to the
    barycentric tests of Moller-Trumbore, since all rays share the origin). The plane is
    then hit at ``t = |det| / (s n.D)`` with ``n = (B - A) x (C - A)``, ``n.A = det``,
    so ``t < 1 - eps`` iff ``s n.D > |det| / (1 - eps)``.

    The per-triangle vectors are computed in float64; the cone test of every (segment,
    triangle) pair -- the bulk of the work, one batched matrix product -- runs in
    float32, which halves the memory traffic. Only the few pairs that pass it (a vertex
    lies in the image of a handful of a car's 68 faces) get the depth test, in float64,
    so the tolerance ``eps`` keeps its meaning.

    The cone tests are inclusive and watertight on indexed meshes: two triangles that
    share an edge compute the same cross product with opposite sign, exactly (also
    after rounding to float32), so a ray through the edge passes the test of at least
    one of them. A triangle whose plane contains the origin (seen edge-on) never blocks.

    The per-triangle terms are computed component-major (``(b, xyz, edge, F)``, the
    cone's layout: whole-array operations along rows of ``F``, not along axes of 3), and
    the sign ``s`` is applied as the cone is rounded to float32 and to ``n`` after its
    sum (a sign flip is exact: the values of signing ``m`` first). ``det`` and the depth
    test stay einsum's over contiguous rows of 3: over strided rows einsum sums in another
    order (``(a0 b0 + a1 b1) + a2 b2`` instead of numpy's SIMD ``(a0 b0 + a2 b2) + a1 b1``),
    which moves ``det`` in its last bit.
    """
    b, F = t.shape[0], t.shape[-1]
    P = d.shape[1]
    # Edge normals m[:, :, e] = corner_e x corner_(e+1), i.e. A x B, B x C, C x A.
    m = np.empty((b, 3, 3, F))  # (b, xyz, edge, F)
    m[:, 0] = t[:, 1] * nxt[:, 2] - t[:, 2] * nxt[:, 1]
    m[:, 1] = t[:, 2] * nxt[:, 0] - t[:, 0] * nxt[:, 2]
    m[:, 2] = t[:, 0] * nxt[:, 1] - t[:, 1] * nxt[:, 0]
    det = np.einsum("bfi,bfi->bf", _rows(t[:, :, 0]), _rows(m[:, :, 1]))  # A . (B x C)
    s = np.sign(det)
    cone = np.empty((b, 3, 3, F), np.float32)  # (b, xyz, edge, F): s m, rounded to float32
    np.multiply(m, s[:, None, None, :], out=cone, casting="same_kind")
    c = np.matmul(d.astype(np.float32), cone.reshape(b, 3, 3 * F)).reshape(b, P, 3, F)
    ge = c >= 0  # one pass over the whole product, then the three edges' flags combined
    inside = ge[:, :, 0] & ge[:, :, 1]
    inside &= ge[:, :, 2]
    if keep is not None:
        inside &= keep
    pair = np.flatnonzero(inside)  # (one flat index array is much cheaper than three)
    ray, face = pair // F, pair % F
    tri_row = ray // P * F + face
    # s (B - A) x (C - A) = s (A x B + B x C + C x A)
    n = _rows((m[:, :, 0] + m[:, :, 1] + m[:, :, 2]) * s[:, None, :]).reshape(b * F, 3)
    with np.errstate(divide="ignore"):
        thr = np.where(det != 0, np.abs(det) / (1.0 - eps), np.inf).reshape(b * F)
    hit = np.einsum("ij,ij->i", np.take(d.reshape(b * P, 3), ray, axis=0), np.take(n, tri_row, axis=0)) \
        > np.take(thr, tri_row)
    out = np.zeros(b * P, dtype=bool)
    out[ray[hit]] = True
    return out.reshape(b, P)


def _rows(a: np.ndarray) -> np.ndarray:
    """Component-major vectors ``(b, 3, F)`` as contiguous rows ``(b, F, 3)``."""
    return np.ascontiguousarray(a.transpose(0, 2, 1))


def has_embree() -> bool:
    """Whether trimesh's Embree ray tracer (``embreex``) is importable."""
    try:
        import embreex  # noqa: F401
        from trimesh.ray import ray_pyembree  # noqa: F401
    except ImportError:
        return False
    return True


def require_ray_tracer() -> None:
    """Check that trimesh can cast rays against a mesh here: with Embree (``embreex``,
    installed with wirescene on x86-64; the ``render`` extra elsewhere, where wheels exist:
    arm64 macOS 13 and later), or with trimesh's pure-Python tracer, which needs ``rtree``
    and is much slower (a warning says so); a :class:`~wirescene.core.errors.DependencyError`
    saying what to install otherwise. Only rendering needs it (synthetic scenes, the CAD
    tools, training on rendered cars); fitting and evaluating do not."""
    if has_embree():
        return
    try:
        import rtree  # noqa: F401
    except ImportError:
        raise DependencyError("rendering meshes needs a ray tracer: pip install embreex (wheels for x86-64 and "
                              "arm64 macOS 13+; the 'render' extra), or pip install rtree for trimesh's slow one") from None
    warnings.warn("embreex not installed: falling back to trimesh's slow ray tracer", RuntimeWarning, stacklevel=3)


def mesh_intersector(mesh_vertices, mesh_faces):
    """A trimesh ray intersector for a triangle mesh: Embree if available, else
    trimesh's (much slower) pure-Python one, with a warning.

    Reuse it across calls of :func:`first_hit_distance` to avoid rebuilding the BVH.

    Examples
    --------
    >>> vertices = np.array([[-1.0, -1.0, 5.0], [1.0, -1.0, 5.0], [0.0, 1.0, 5.0]])  # one triangle, 5 m ahead
    >>> faces = np.array([[0, 1, 2]])
    >>> intersector = mesh_intersector(vertices, faces)  # built once ...
    >>> for z in (1.0, 2.0):  # ... for several batches of rays
    ...     first_hit_distance(vertices, faces, np.zeros(3), [[0.0, 0.0, z]], intersector=intersector)[0].tolist()
    [5.0]
    [2.5]
    """
    import trimesh

    mesh_vertices = np.asarray(mesh_vertices, dtype=float)
    mesh_faces = np.asarray(mesh_faces)
    check_shape("mesh_vertices", mesh_vertices, (None, 3))
    check_shape("mesh_faces", mesh_faces, (None, 3))
    mesh = trimesh.Trimesh(mesh_vertices, mesh_faces, process=False, validate=False)
    require_ray_tracer()
    if has_embree():
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        return RayMeshIntersector(mesh, scale_to_box=True)
    from trimesh.ray.ray_triangle import RayMeshIntersector

    return RayMeshIntersector(mesh)


def first_hit_distance(mesh_vertices, mesh_faces, origins, directions, *, intersector=None):
    """Distance to and index of the first triangle hit by each ray.

    Parameters
    ----------
    mesh_vertices : (V, 3) array
    mesh_faces : (F, 3) int array
    origins : (R, 3) or (3,) array
        Ray origins (one shared origin is broadcast).
    directions : (R, 3) array
        Ray directions (need not be unit).
    intersector : optional
        A prebuilt :func:`mesh_intersector` for this mesh (then the mesh arguments are
        only used for the exact distance computation).

    Returns
    -------
    distance : (R,) float array
        Ray parameter of the hit in units of ``|direction|`` (metres for unit
        directions); ``inf`` where nothing is hit.
    face : (R,) int array
        Index of the hit face, -1 where nothing is hit.

    Notes
    -----
    Embree works in float32; it is only used to find *which* face is hit first. The
    distance is then recomputed in float64 against that face's plane, so depth values
    are as precise as the inputs.

    Examples
    --------
    >>> # a 2 m cube 9 to 11 m ahead: vertices 0-3 its front face (z = 9), 4-7 its back face (z = 11)
    >>> vertices = np.array([[x, y, z] for z in (9.0, 11.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])
    >>> faces = np.array([[0, 1, 3], [0, 3, 2], [4, 7, 5], [4, 6, 7], [0, 4, 5], [0, 5, 1],
    ...                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    >>> distance, face = first_hit_distance(vertices, faces, np.zeros(3), [[0.05, 0.02, 1.0], [1.0, 0.0, 0.0]])
    >>> distance.tolist(), face.tolist()  # the front face at 9 (units of |direction|: z = 1); the other misses
    ([9.0, inf], [0, -1])
    """
    mesh_vertices = np.asarray(mesh_vertices, dtype=float)
    mesh_faces = np.asarray(mesh_faces, dtype=np.int64)
    directions = np.asarray(directions, dtype=float)
    check_shape("directions", directions, (None, 3))
    origins = np.broadcast_to(np.asarray(origins, dtype=float), directions.shape)
    if intersector is None:
        intersector = mesh_intersector(mesh_vertices, mesh_faces)
    R = directions.shape[0]
    distance = np.full(R, np.inf)
    if R == 0 or len(mesh_faces) == 0:
        return distance, np.full(R, -1, dtype=np.int64)
    face = np.asarray(intersector.intersects_first(origins, directions), dtype=np.int64)
    hit = np.flatnonzero(face >= 0)
    tri = mesh_vertices[mesh_faces[face[hit]]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    denom = np.einsum("ri,ri->r", n, directions[hit])
    num = np.einsum("ri,ri->r", n, tri[:, 0] - origins[hit])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / denom
    # A grazing hit (ray in the face plane) has no well-defined plane distance; fall
    # back to the distance to the face centroid along the ray.
    bad = ~np.isfinite(t) | (t < 0)
    if np.any(bad):
        c = tri[bad].mean(axis=1)
        d = directions[hit][bad]
        t[bad] = np.einsum("ri,ri->r", c - origins[hit][bad], d) / np.einsum("ri,ri->r", d, d)
    distance[hit] = t
    return distance, face


def check_faces(faces, n_vertices: int) -> np.ndarray:
    """``faces`` as an ``(F, 3)`` integer array indexing ``n_vertices`` vertices (else ShapeError).

    Examples
    --------
    >>> check_faces([[0, 1, 2]], 3)
    array([[0, 1, 2]])
    >>> check_faces([[0, 1, 3]], 3)
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ShapeError: faces index vertices outside [0, 3)
    """
    faces = np.asarray(faces)
    check_shape("faces", faces, (None, 3))
    if not np.issubdtype(faces.dtype, np.integer):
        raise ShapeError(f"faces must be integer indices, got dtype {faces.dtype}")
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        raise ShapeError(f"faces index vertices outside [0, {n_vertices})")
    return faces


def incidence(faces, n_vertices: int) -> np.ndarray:
    """``(V, F)`` bool: True where vertex ``v`` is a corner of face ``f`` (the ``ignore``
    mask of :func:`segment_blocked` that exempts a vertex from its own faces).

    Examples
    --------
    >>> from wirescene.core.wireframe import FACES, N_VERTICES
    >>> inc = incidence(FACES, N_VERTICES)
    >>> inc.shape, bool((inc.sum(axis=0) == 3).all())  # the car's wireframe surface: three corners a face
    ((36, 68), True)
    """
    faces = check_faces(faces, n_vertices)
    inc = np.zeros((n_vertices, len(faces)), dtype=bool)
    inc[faces, np.arange(len(faces))[:, None]] = True
    return inc


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

    Examples
    --------
    >>> from wirescene.core.boxes import box_corners
    >>> # one scene of three cars: A 10 m ahead, B right behind it (20 m), C 10 m to the right of A
    >>> cars = np.stack([box_corners([1.5, 1.6, 4.0], location, np.eye(3))
    ...                  for location in ([0.0, 1.65, 10.0], [0.0, 1.65, 20.0], [10.0, 1.65, 10.0])])
    >>> interaction_candidates(cars[None])  # only A can hide B: [target B, occluder A]
    array([[[False, False, False],
            [ True, False, False],
            [False, False, False]]])
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
