"""Micro-benchmark of vertex occlusion by ray casting (wirescene.infer.occlusion).

Times the batched implementation against two naive baselines measured in the same run
on the same data:

* per-hypothesis loop -- a Python loop over hypotheses, calling the same kernel on one
  hypothesis at a time (isolates the benefit of batching);
* per-vertex loop -- a Python loop over hypotheses and vertices, each vertex tested
  against all faces with textbook (per-ray) Moller-Trumbore in numpy (what a
  straightforward implementation looks like);
* dense float64 -- the batched kernel of wirescene 0.1 (every vertex against every
  face, all in float64; for Gamma every object pair), kept here as the reference the
  current kernel (float32 cone test, float64 depth test on the few candidate pairs,
  image-overlap culling of object pairs) is measured against.

The wireframes are the shape model's (36 vertices, 68 faces) with random shapes, placed
like cars in a street (5-40 m ahead, +-8 m sideways).

Results are checked to agree, and printed as vertices/second and speed-up ratios.

    python benchmarks/bench_occlusion.py [--particles 250] [--objects 5]
"""

from __future__ import annotations

import argparse

import numpy as np

from _common import best_of
from wirescene.core.groundplane import object_pose, transform
from wirescene.core.raycast import mesh_vertices_blocked
from wirescene.core.shape import load_default
from wirescene.core.wireframe import FACES
from wirescene.infer.occlusion import incidence, inter_object_occlusion, self_occlusion


def dense_reference_blocked(origin, targets, triangles, ignore=None, eps=1e-6, chunk=1 << 17):
    """wirescene 0.1's kernel: every (segment, triangle) pair, float64, one shared
    origin; ``targets`` (B, P, 3), ``triangles`` (B, F, 3, 3), ``ignore`` (P, F)."""
    B, P = targets.shape[:2]
    F = triangles.shape[1]
    out = np.empty((B, P), bool)
    step = max(1, chunk // (P * F))
    for s0 in range(0, B, step):
        x, tri = targets[s0:s0 + step] - origin, triangles[s0:s0 + step] - origin
        A, Bc, C = tri[:, :, 0], tri[:, :, 1], tri[:, :, 2]
        m1, m2, m3 = np.cross(A, Bc), np.cross(Bc, C), np.cross(C, A)
        det = np.einsum("bfi,bfi->bf", A, m2)
        sg = np.sign(det)[..., None]
        n = np.cross(Bc - A, C - A)
        with np.errstate(divide="ignore"):
            thr = np.where(det != 0, np.abs(det) / (1.0 - eps), np.inf)
        c = x @ np.concatenate([m1 * sg, m2 * sg, m3 * sg, n * sg], axis=1).transpose(0, 2, 1)
        hit = (c[..., :F] >= 0) & (c[..., F:2 * F] >= 0) & (c[..., 2 * F:3 * F] >= 0) & (c[..., 3 * F:] > thr[:, None])
        if ignore is not None:
            hit &= ~ignore
        out[s0:s0 + step] = hit.any(-1)
    return out


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

    model, faces = load_default(), FACES
    rng = np.random.default_rng(1)
    S, N = args.particles, args.objects
    shapes = np.clip(rng.standard_normal((S, N, 5)), -2, 2)
    x = rng.uniform(-8, 8, (S, N))
    z = rng.uniform(5, 40, (S, N))
    az = rng.uniform(-np.pi, np.pi, (S, N))
    location, R = object_pose(x, z, az)
    X = transform(model.instantiate(shapes), location, R)  # (S, N, V, 3)
    V, F = X.shape[-2], len(faces)
    center = np.array([0.06, 0.0, 0.0])  # KITTI P2 optical centre is slightly off origin
    n_vert = S * N * V
    print(f"{S} particles x {N} objects x {V} vertices = {n_vert} vertices, {F} faces per object")

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
    t_dense, so_dense = best_of(lambda: dense_reference_blocked(center, flat, flat[:, faces], inc))
    assert np.array_equal(so.reshape(S * N, V), so_hyp)
    assert np.array_equal(so.reshape(S * N, V)[:H], so_vert)
    print(f"  (flags differing from the dense float64 kernel: {(so.reshape(S * N, V) != so_dense).sum()})")
    rate_vec, rate_hyp, rate_vert = n_vert / t_vec, n_vert / t_hyp, H * V / t_vert
    print("self_occlusion (hidden fraction %.2f)" % so.mean())
    print(f"  batched            {rate_vec:12.0f} vertices/s  ({t_vec * 1e3:.1f} ms for the batch)")
    print(f"  dense float64 (0.1){n_vert / t_dense:12.0f} vertices/s  -> batched is {t_dense / t_vec:.1f}x faster")
    print(f"  per-hypothesis loop{rate_hyp:12.0f} vertices/s  -> batched is {rate_vec / rate_hyp:.1f}x faster")
    print(f"  per-vertex loop    {rate_vert:12.0f} vertices/s  -> batched is {rate_vec / rate_vert:.1f}x faster")
    # A back-face pre-test: a segment entering a closed surface crosses a face turned to the
    # camera (the wireframe's faces are closed and consistently oriented), so testing those
    # alone would be exact unless a deformed shape folds through itself. How far it is not:
    rel = flat - center
    A, B, C = (rel[:, faces[:, k]] for k in range(3))
    turned = np.einsum("hfi,hfi->hf", A, np.cross(B, C)) < 0  # the outward side faces the camera
    front = mesh_vertices_blocked(center, flat, faces, ignore=inc[None] | ~turned[:, None, :])
    differ = front != so.reshape(S * N, V)
    print(f"  faces turned to the camera only ({turned.sum(1).mean():.1f} of {F} a hypothesis): "
          f"{differ.sum()} of {differ.size} flags differ, in {differ.any(1).sum()} of {S * N} hypotheses")

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
    own = np.kron(np.eye(N, dtype=bool), np.ones((V, F), dtype=bool))
    scene = X.reshape(S, N * V, 3)
    t_dense, io_dense = best_of(lambda: dense_reference_blocked(center, scene, X[:, :, faces].reshape(S, N * F, 3, 3), own))
    assert np.array_equal(io, io_hyp)
    assert np.array_equal(io[:Hs], io_vert)
    print(f"  (flags differing from the dense float64 kernel: {(io.reshape(S, N * V) != io_dense).sum()})")
    rate_vec, rate_hyp, rate_vert = n_vert / t_vec, n_vert / t_hyp, Hs * N * V / t_vert
    print("inter_object_occlusion (hidden fraction %.3f)" % io.mean())
    print(f"  batched            {rate_vec:12.0f} vertices/s  ({t_vec * 1e3:.1f} ms for the batch)")
    print(f"  dense float64 (0.1){n_vert / t_dense:12.0f} vertices/s  -> batched is {t_dense / t_vec:.1f}x faster")
    print(f"  per-particle loop  {rate_hyp:12.0f} vertices/s  -> batched is {rate_vec / rate_hyp:.1f}x faster")
    print(f"  per-vertex loop    {rate_vert:12.0f} vertices/s  -> batched is {rate_vec / rate_vert:.1f}x faster")


if __name__ == "__main__":
    main()
