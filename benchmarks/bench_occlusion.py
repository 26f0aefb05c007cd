"""Micro-benchmark of vertex occlusion by ray casting (wirescene.occlusion).

Times the batched implementation against two naive baselines measured in the same run
on the same data:

* per-hypothesis loop -- a Python loop over hypotheses, calling the same kernel on one
  hypothesis at a time (isolates the benefit of batching);
* per-vertex loop -- a Python loop over hypotheses and vertices, each vertex tested
  against all faces with textbook (per-ray) Moller-Trumbore in numpy (what a
  straightforward implementation looks like).

Results are checked to agree, and printed as vertices/second and speed-up ratios.

    python benchmarks/bench_occlusion.py [--particles 250] [--objects 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial import ConvexHull

from wirescene.groundplane import object_pose, transform
from wirescene.occlusion import incidence, inter_object_occlusion, self_occlusion


def car_like_wireframe(n_vertices: int = 36, seed: int = 0):
    """A closed convex mesh with ``n_vertices`` vertices (all on a car-sized ellipsoid,
    hence all on the hull) -- the size of the paper's 36-vertex wireframe."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n_vertices, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = u * [2.2, 0.75, 0.9] + [0, -0.75, 0]
    return pts, ConvexHull(pts).simplices


def naive_mt_blocked(origin, target, triangles, eps=1e-6):
    """Textbook Moller-Trumbore for one segment against (F, 3, 3) triangles."""
    d = target - origin
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("fi,fi->f", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    tv = origin - v0
    u = np.einsum("fi,fi->f", tv, p) * inv
    q = np.cross(tv, e1)
    v = (q @ d) * inv
    t = np.einsum("fi,fi->f", e2, q) * inv
    return bool(np.any(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > eps) & (t < 1 - eps)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--objects", type=int, default=5)
    ap.add_argument("--naive-hypotheses", type=int, default=100,
                    help="hypotheses timed with the per-vertex loop (it is slow); rate is per vertex")
    args = ap.parse_args()

    verts, faces = car_like_wireframe()
    V, F = len(verts), len(faces)
    rng = np.random.default_rng(1)
    S, N = args.particles, args.objects
    x = rng.uniform(-6, 6, (S, N))
    z = rng.uniform(8, 30, (S, N))
    az = rng.uniform(-np.pi, np.pi, (S, N))
    location, R = object_pose(x, z, az)
    X = transform(np.broadcast_to(verts, (S, N, V, 3)), location, R)  # (S, N, V, 3)
    center = np.array([0.06, 0.0, 0.0])  # KITTI P2 optical centre is slightly off origin
    n_vert = S * N * V
    print(f"{S} particles x {N} objects x {V} vertices = {n_vert} vertices, {F} faces per object")

    def best_of(fn, repeat=3):
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - t0)
        return min(times), out

    # --- self-occlusion
    t_vec, so = best_of(lambda: self_occlusion(X, faces, center))
    flat = X.reshape(S * N, V, 3)
    t_hyp, so_hyp = best_of(lambda: np.stack([self_occlusion(h, faces, center) for h in flat]), repeat=1)
    inc = incidence(faces, V)
    H = min(args.naive_hypotheses, S * N)

    def per_vertex():
        out = np.zeros((H, V), bool)
        for h in range(H):
            tri = flat[h][faces]
            for v in range(V):
                out[h, v] = naive_mt_blocked(center, flat[h, v], tri[~inc[v]])
        return out

    t_vert, so_vert = best_of(per_vertex, repeat=1)
    assert np.array_equal(so.reshape(S * N, V), so_hyp)
    assert np.array_equal(so.reshape(S * N, V)[:H], so_vert)
    rate_vec, rate_hyp, rate_vert = n_vert / t_vec, n_vert / t_hyp, H * V / t_vert
    print("self_occlusion (hidden fraction %.2f)" % so.mean())
    print(f"  batched            {rate_vec:12.0f} vertices/s  ({t_vec * 1e3:.1f} ms for the batch)")
    print(f"  per-hypothesis loop{rate_hyp:12.0f} vertices/s  -> batched is {rate_vec / rate_hyp:.1f}x faster")
    print(f"  per-vertex loop    {rate_vert:12.0f} vertices/s  -> batched is {rate_vec / rate_vert:.1f}x faster")

    # --- inter-object occlusion
    t_vec, io = best_of(lambda: inter_object_occlusion(X, faces, center))
    t_hyp, io_hyp = best_of(lambda: np.stack([inter_object_occlusion(p, faces, center) for p in X]), repeat=1)
    Hs = max(1, min(S, args.naive_hypotheses // N))

    def per_vertex_scene():
        out = np.zeros((Hs, N, V), bool)
        for s in range(Hs):
            for i in range(N):
                tri = np.concatenate([X[s, j][faces] for j in range(N) if j != i])
                for v in range(V):
                    out[s, i, v] = naive_mt_blocked(center, X[s, i, v], tri)
        return out

    t_vert, io_vert = best_of(per_vertex_scene, repeat=1)
    assert np.array_equal(io, io_hyp)
    assert np.array_equal(io[:Hs], io_vert)
    rate_vec, rate_hyp, rate_vert = n_vert / t_vec, n_vert / t_hyp, Hs * N * V / t_vert
    print("inter_object_occlusion (hidden fraction %.3f)" % io.mean())
    print(f"  batched            {rate_vec:12.0f} vertices/s  ({t_vec * 1e3:.1f} ms for the batch)")
    print(f"  per-particle loop  {rate_hyp:12.0f} vertices/s  -> batched is {rate_vec / rate_hyp:.1f}x faster")
    print(f"  per-vertex loop    {rate_vert:12.0f} vertices/s  -> batched is {rate_vec / rate_vert:.1f}x faster")


if __name__ == "__main__":
    main()
