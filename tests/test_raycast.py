"""Ray/triangle occlusion (wirescene.core.raycast) and vertex occlusion (wirescene.infer.occlusion)
against Embree ray casting and analytic ground truth."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull

from conftest import assert_close
from wirescene.core.errors import ShapeError
from wirescene.core.groundplane import object_pose, transform
from wirescene.core.raycast import first_hit_distance, segment_blocked
from wirescene.infer.occlusion import incidence, inter_object_occlusion, self_occlusion


def embree_blocked(mesh_vertices, mesh_faces, origin, targets):
    """Ground truth: first Embree hit nearer than the target. Also returns a mask of
    near-ties (hit within 1e-4 relative of the target), where float32 Embree and the
    float64 test may legitimately disagree."""
    d = targets - origin
    dist = np.linalg.norm(d, axis=-1)
    hit, _ = first_hit_distance(mesh_vertices, mesh_faces, origin, d / dist[:, None])
    tie = np.abs(hit - dist) < 1e-4 * dist
    return hit < dist, tie


def random_hull(rng, n=36, scale=(2.2, 0.75, 0.9)):
    """Vertices on a car-sized ellipsoid (all on the hull) and the hull's triangles."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = u * scale + [0, -0.75, 0]
    hull = ConvexHull(pts)
    return pts, hull.simplices, hull.equations


def test_segment_blocked_matches_embree_on_triangle_soup():
    rng = np.random.default_rng(0)
    for _ in range(3):
        centers = rng.uniform(-2, 2, size=(60, 1, 3))
        tri = centers + rng.normal(scale=0.6, size=(60, 3, 3))
        verts, faces = tri.reshape(-1, 3), np.arange(180).reshape(60, 3)
        origin = rng.uniform(-8, 8, size=3)
        targets = rng.uniform(-3, 3, size=(400, 3))
        got = segment_blocked(origin, targets, tri)
        want, tie = embree_blocked(verts, faces, origin, targets)
        assert 0.1 < want.mean() < 0.9  # the test is not trivial
        assert np.array_equal(got[~tie], want[~tie])


def test_segment_blocked_batches_like_a_loop_and_chunking_is_invisible():
    rng = np.random.default_rng(1)
    origins = rng.normal(size=(4, 3, 3)) * 6
    targets = rng.normal(size=(4, 3, 20, 3))
    triangles = rng.normal(size=(4, 3, 15, 3, 3))
    got = segment_blocked(origins, targets, triangles)
    assert got.shape == (4, 3, 20)
    loop = np.array([[segment_blocked(origins[i, j], targets[i, j], triangles[i, j]) for j in range(3)] for i in range(4)])
    assert np.array_equal(got, loop)
    assert np.array_equal(segment_blocked(origins, targets, triangles, chunk=7), got)
    # A shared origin and shared triangles broadcast against batched targets.
    shared = segment_blocked(origins[0, 0], targets, triangles[0, 0])
    loop = np.array([[segment_blocked(origins[0, 0], t, triangles[0, 0]) for t in row] for row in targets])
    assert np.array_equal(shared, loop)


def test_segment_blocked_is_watertight_on_shared_edges_and_respects_the_target():
    # A unit square at z = 5 split along its diagonal; rays through the diagonal.
    sq = np.array([[-1, -1, 5], [1, -1, 5], [1, 1, 5], [-1, 1, 5]], float)
    tri = sq[np.array([[0, 1, 2], [0, 2, 3]])]
    s = np.linspace(-0.9, 0.9, 37)
    targets = np.stack([s * 2, s * 2, np.full_like(s, 10.0)], axis=-1)
    assert segment_blocked(np.zeros(3), targets, tri).all()
    # Targets in front of the square, and on it, are not blocked.
    assert not segment_blocked(np.zeros(3), targets * 0.4, tri).any()
    assert not segment_blocked(np.zeros(3), sq, tri).any()
    # ...but with the tolerance switched off and a target just behind, they are.
    assert segment_blocked(np.zeros(3), sq * (1 + 1e-9), tri, eps=0.0).any()


def test_segment_blocked_ignore_and_shape_errors():
    tri = np.array([[[-1, -1, 5], [1, -1, 5], [0, 1, 5]]], float)
    target = np.array([[0, 0, 10.0]])
    assert segment_blocked(np.zeros(3), target, tri).all()
    assert not segment_blocked(np.zeros(3), target, tri, ignore=np.ones((1, 1), bool)).any()
    with pytest.raises(ShapeError):
        segment_blocked(np.zeros(3), np.zeros((4, 2)), tri)
    with pytest.raises(ShapeError):
        segment_blocked(np.zeros(3), target, np.zeros((1, 3, 2)))
    with pytest.raises(ShapeError):
        segment_blocked(np.zeros((2, 3)), np.zeros((3, 1, 3)), tri)


def test_first_hit_distance_exact_and_misses():
    quad = np.array([[-1, -1, 4], [1, -1, 4], [1, 1, 4], [-1, 1, 4]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    dirs = np.array([[0, 0, 1.0], [0.1, 0.05, 1.0], [0, 0, -1.0], [1.0, 0, 0]])
    dist, face = first_hit_distance(quad, faces, np.zeros(3), dirs)
    # Distances are ray parameters: the hit is origin + dist * direction.
    assert_close(dist[:2], [4.0, 4.0], atol=1e-12)
    dist, _ = first_hit_distance(quad, faces, np.zeros(3), dirs[:2] / np.linalg.norm(dirs[:2], axis=1, keepdims=True))
    assert_close(dist, 4.0 * np.linalg.norm(dirs[:2], axis=1), atol=1e-12)
    assert np.all(face[:2] >= 0)
    assert np.all(np.isinf(dist[2:])) and np.all(face[2:] == -1)


def test_self_occlusion_of_a_cube_from_known_viewpoints():
    box = trimesh.creation.box((2, 2, 2))
    v, f = box.vertices, box.faces
    # From a generic corner direction only the opposite corner is hidden.
    hidden = self_occlusion(v, f, np.array([5.0, 4.0, 3.0]))
    assert_close(v[hidden], [[-1, -1, -1]])
    # Looking down the z axis the four far corners are hidden, the near ones are not.
    hidden = self_occlusion(v, f, np.array([0.0, 0.0, 10.0]))
    assert np.array_equal(hidden, v[:, 2] < 0)


def test_self_occlusion_eps_alone_protects_vertices_from_their_own_faces():
    rng = np.random.default_rng(2)
    v, f, _ = random_hull(rng)
    cams = rng.normal(size=(50, 3)) * 8
    with_ignore = self_occlusion(np.broadcast_to(v, (50,) + v.shape), f, cams)
    without = segment_blocked(cams, np.broadcast_to(v, (50,) + v.shape), v[f])
    assert np.array_equal(with_ignore, without)


def test_self_occlusion_of_random_convex_hulls_matches_analytic_and_embree():
    rng = np.random.default_rng(3)
    v, f, eq = random_hull(rng)
    S, N = 20, 3
    location, R = object_pose(rng.uniform(-8, 8, (S, N)), rng.uniform(5, 40, (S, N)), rng.uniform(-np.pi, np.pi, (S, N)))
    X = transform(np.broadcast_to(v, (S, N) + v.shape), location, R)
    center = np.array([0.06, 0.0, 0.0])
    hidden = self_occlusion(X, f, center)
    assert hidden.shape == (S, N, len(v))
    assert 0.2 < hidden.mean() < 0.8
    # Analytic: a vertex of a convex polytope is visible iff the camera is outside the
    # plane of one of its faces (hull equations are outward, in the object frame).
    inc = incidence(f, len(v))
    c_obj = np.einsum("snji,snj->sni", R, center - location)  # R^T (c - t)
    outside = np.einsum("fi,sni->snf", eq[:, :3], c_obj) + eq[:, 3] > 0  # (S, N, F)
    visible = (inc[None, None] & outside[:, :, None, :]).any(-1)
    assert np.array_equal(hidden, ~visible)
    # Embree on the posed meshes.
    for s in range(3):
        for n in range(N):
            want, tie = embree_blocked(X[s, n], f, center, X[s, n] * (1 - 1e-7) + center * 1e-7)
            assert np.array_equal(hidden[s, n][~tie], want[~tie])


def two_boxes(z_front, z_back, x_back=0.0):
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v = np.stack([box.vertices + [0, 0, z_front], box.vertices + [x_back, 0, z_back]])
    return v, box.faces


def test_inter_object_occlusion_of_boxes_in_a_row():
    v, f = two_boxes(5.0, 10.0)
    hidden = inter_object_occlusion(v, f, np.zeros(3))
    assert not hidden[0].any()  # the front box is not occluded
    assert hidden[1].all()  # the back box (same apparent size x 1/2) is fully covered
    # Moved sideways, the back box is free.
    v, f = two_boxes(5.0, 10.0, x_back=6.0)
    assert not inter_object_occlusion(v, f, np.zeros(3)).any()
    # Self-occlusion is not part of it, and a single object is never inter-occluded.
    assert not inter_object_occlusion(v[:1], f, np.zeros(3)).any()


def test_inter_object_occlusion_matches_embree_on_random_scenes():
    rng = np.random.default_rng(4)
    v, f, _ = random_hull(rng)
    S, N = 6, 4
    location, R = object_pose(rng.uniform(-3, 3, (S, N)), rng.uniform(6, 20, (S, N)), rng.uniform(-np.pi, np.pi, (S, N)))
    X = transform(np.broadcast_to(v, (S, N) + v.shape), location, R)
    center = np.array([0.06, 0.0, 0.0])
    hidden = inter_object_occlusion(X, f, center)
    assert hidden.shape == (S, N, len(v))
    assert 0.05 < hidden.mean() < 0.95
    n_checked = 0
    for s in range(S):
        for i in range(N):
            others = [j for j in range(N) if j != i]
            mv = np.concatenate([X[s, j] for j in others])
            mf = np.concatenate([f + k * len(v) for k in range(len(others))])
            want, tie = embree_blocked(mv, mf, center, X[s, i])
            assert np.array_equal(hidden[s, i][~tie], want[~tie]), (s, i)
            n_checked += (~tie).sum()
    assert n_checked > 0.99 * S * N * len(v)


def test_inter_object_occlusion_pair_culling_is_exact():
    """Only image-overlapping, depth-compatible object pairs are ray cast; the result
    must equal testing every vertex against every other object's faces, also for
    objects beside or behind the camera, where the culling projection does not apply."""
    rng = np.random.default_rng(5)
    v, f, _ = random_hull(rng)
    S, N = 30, 5
    # Crowded scenes (many overlaps), some objects straddling or behind the camera plane.
    location, R = object_pose(rng.uniform(-4, 4, (S, N)), rng.uniform(-3, 15, (S, N)), rng.uniform(-np.pi, np.pi, (S, N)))
    X = transform(np.broadcast_to(v, (S, N) + v.shape), location, R)
    center = np.array([0.06, -0.1, 0.0])
    hidden = inter_object_occlusion(X, f, center)
    others = np.stack([np.concatenate([X[:, j][:, f] for j in range(N) if j != i], axis=1) for i in range(N)], axis=1)
    brute = segment_blocked(center, X, others)
    assert np.array_equal(hidden, brute)
    assert 0.05 < hidden.mean() < 0.6
    behind = (X[..., 2] <= center[2]).any(-1)
    assert behind.any() and (~behind).any()


def test_without_embree_rendering_says_what_to_install_or_warns_of_the_slow_tracer(monkeypatch):
    import sys
    import types

    from wirescene.core.errors import DependencyError
    from wirescene.core.raycast import has_embree, require_ray_tracer

    require_ray_tracer()  # this machine has Embree: silent
    assert has_embree()
    monkeypatch.setitem(sys.modules, "embreex", None)  # as where pip installed no embreex
    assert not has_embree()
    monkeypatch.setitem(sys.modules, "rtree", None)
    with pytest.raises(DependencyError, match="pip install embreex"):
        require_ray_tracer()
    with pytest.raises(DependencyError):
        first_hit_distance(np.eye(3), np.array([[0, 1, 2]]), np.zeros(3), np.array([[1.0, 1.0, 1.0]]))
    monkeypatch.setitem(sys.modules, "rtree", types.ModuleType("rtree"))  # trimesh's slow tracer is there
    with pytest.warns(RuntimeWarning, match="slow ray tracer"):
        require_ray_tracer()


def test_embreex_is_required_where_it_has_wheels_only():
    """pip must not try to build embreex from source (no wheels: Linux aarch64, macOS arm64
    before 13), and the marker must read no version-like field a machine may spell its own
    way (a kernel release such as '6.18.44-fc-v1294' broke pip's marker evaluation);
    fitting and evaluating do not need embreex, and the `render` extra asks for it anywhere."""
    from importlib.metadata import requires

    from packaging.requirements import Requirement

    reqs = [Requirement(r) for r in requires("wirescene") if r.startswith("embreex")]
    (core,) = [r for r in reqs if "extra" not in str(r.marker)]
    (extra,) = [r for r in reqs if "extra" in str(r.marker)]
    assert "platform_release" not in str(core.marker) and "platform_version" not in str(core.marker)
    for machine, system, wanted in [("x86_64", "linux", True), ("AMD64", "win32", True), ("x86_64", "darwin", True),
                                    ("arm64", "darwin", False), ("aarch64", "linux", False), ("ARM64", "win32", False)]:
        env = {"extra": "", "platform_machine": machine, "sys_platform": system, "platform_release": "6.18.44-fc-v1294"}
        assert core.marker.evaluate(env) == wanted, (machine, system)
        assert extra.marker.evaluate({**env, "extra": "render"})
