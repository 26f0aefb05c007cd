"""Smoothing-based optimisation (Algorithm 1) versus CMA-ES on the same objective.

For every car of synthetic scenes (``wirescene synth``), starting from the best
``coarse+gp`` particle, the fine-grained objective of that car is maximised over its
pose and shape by (a) our smoothing-based optimisation and (b) CMA-ES (package ``cma``)
with the same number of objective evaluations. Reported, side by side from one run:
the final objective, the 3D localisation error and the azimuth error against the
ground truth, and the wall time.

Usage: python benchmarks/bench_inference.py SYNTH_DIR [--frames 10] [--evidence oracle|parts]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.io.wireframes import read_wireframe_gt, wireframe_gt_path  # noqa: E402
from wirescene.io.detections import detections_from_labels  # noqa: E402
from wirescene.infer.evidence import oracle_evidence, part_evidence  # noqa: E402
from wirescene.infer.inference import InferenceOptions, _evaluate, _to_viewing, refine_particles  # noqa: E402
from wirescene.lift import lift_table, select_particles  # noqa: E402
from wirescene.core.shape import load_default  # noqa: E402
from wirescene.core.viewpoints import angle_difference  # noqa: E402


def cma_refine(camera, particles, evidence, model, options, seed):
    """CMA-ES per object (one particle), population = options.samples, same budget."""
    import cma

    P, N = particles.x.shape
    K = options.n_shape
    phi, logr, alpha = _to_viewing(particles.x, particles.z, particles.azimuth)
    scale = np.r_[np.deg2rad(options.sigma_bearing_deg), options.sigma_range_frac,
                  np.deg2rad(options.sigma_azimuth_deg), np.full(K, options.sigma_shape)]
    best = np.zeros((P, N, 3 + K))
    for j in range(N):
        x0 = np.r_[phi[0, j], logr[0, j], alpha[0, j], np.zeros(K)]
        es = cma.CMAEvolutionStrategy(np.zeros(3 + K), 1.0, {
            "popsize": options.samples, "seed": seed + 1, "verbose": -9,
            "maxfevals": options.samples * options.iterations})
        while not es.stop():
            xs = np.array(es.ask())
            theta = np.zeros((1, N, len(xs), 3 + K))
            theta[0, :, :, 0], theta[0, :, :, 1], theta[0, :, :, 2] = phi[0][:, None], logr[0][:, None], alpha[0][:, None]
            theta[0, j] = x0 + xs * scale
            vals = _evaluate(camera, model, evidence, particles.take([0]), theta, K, options.occluded_score)[0, j]
            es.tell(list(xs), list(-vals))
        best[0, j] = x0 + np.asarray(es.result.xbest) * scale
    return best[0]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--evidence", choices=["oracle", "parts"], default="oracle")
    ap.add_argument("--iterations", type=int, default=12)
    ap.add_argument("--samples", type=int, default=12)
    args = ap.parse_args()
    ds = KittiDataset(args.root)
    model = load_default()
    opts = InferenceOptions(iterations=args.iterations, samples=args.samples)
    rows = {"sbo": [], "cma": []}
    times = {"sbo": 0.0, "cma": 0.0}
    for fid in ds.frame_ids()[: args.frames]:
        labels = ds.labels(fid)
        vgt = read_wireframe_gt(wireframe_gt_path(ds.split_dir, fid))
        dets = detections_from_labels(labels)
        cam = ds.camera(fid)
        ev = (oracle_evidence(dets, np.array([o.box for o in labels.objects]), vgt) if args.evidence == "oracle"
              else part_evidence(ds.image(fid), dets))
        p = select_particles(lift_table(cam, dets), shared_plane=True, n_particles=1)
        t = time.perf_counter()
        r = refine_particles(cam, p, ev, model, options=opts, rng=np.random.default_rng(0))
        times["sbo"] += time.perf_counter() - t
        sbo_theta = np.concatenate([np.stack(_to_viewing(r.particles.x, r.particles.z, r.particles.azimuth), -1)[0], r.shape[0]], -1)
        t = time.perf_counter()
        cma_theta = cma_refine(cam, p, ev, model, opts, 0)
        times["cma"] += time.perf_counter() - t
        cars = labels.objects
        for name, th in (("sbo", sbo_theta), ("cma", cma_theta)):
            val = _evaluate(cam, model, ev, p, th[None, :, None, :], opts.n_shape, opts.occluded_score)[0, :, 0]
            rng_ = np.exp(th[:, 1])
            x, z, az = rng_ * np.sin(th[:, 0]), rng_ * np.cos(th[:, 0]), th[:, 2] + th[:, 0]
            for j, g in enumerate(cars):
                rows[name].append((val[j], np.hypot(x[j] - g.location[0], z[j] - g.location[2]),
                                   np.rad2deg(angle_difference(az[j], g.rotation_y))))
    print(f"{len(rows['sbo'])} cars, {args.evidence} evidence, budget {args.iterations} x {args.samples} evaluations per car")
    print(f"{'':5s} {'mean objective':>15s} {'median loc err [m]':>19s} {'median az err [deg]':>20s} {'time [s]':>9s}")
    for name in ("sbo", "cma"):
        a = np.array(rows[name])
        print(f"{name:5s} {a[:, 0].mean():15.3f} {np.median(a[:, 1]):19.2f} {np.median(a[:, 2]):20.1f} {times[name]:9.1f}")
    print(f"ratio cma/sbo time: {times['cma'] / max(times['sbo'], 1e-9):.1f}")


if __name__ == "__main__":
    main()
