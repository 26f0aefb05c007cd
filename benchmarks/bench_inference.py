"""Fine-stage inference studies on synthetic scenes (``wirescene synth DIR --scenes 20 --seed 7``).

1. Study (default): precision of the fine stage as a function of its settings --
   iterations, samples, ground-plane sampling, box term, shape prior, polish, number of
   shape coefficients, pruning and (with ``--evidence parts``) bilinear map lookup -- with perfect
   (``oracle``) or part-detector evidence, label boxes as pre-detections. Per setting:
   share of cars within 1 m, median 3D azimuth error, share of cars with >= 70% of their
   visible parts within 4% of the box (paper Table 3) and seconds per frame; ``--plot
   PNG`` draws precision against seconds per frame.
2. ``--cma``: smoothing-based optimisation (Algorithm 1) versus CMA-ES (package
   ``cma``) on the same per-car objective with the same number of evaluations.
3. ``--ceiling``: what the shape model allows at all -- the true wireframes of the
   synthetic cars approximated by the first K coefficients (least squares, true pose)
   and scored with the paper's 2D part measure, per K.
4. ``--true-plane``: fg+gp with oracle evidence fitted once on the estimated ground
   plane (as the pipeline does) and once on the scene's true plane (not refined): the
   share of the 1 m error that the plane causes. (Perfect 2D evidence does not fix the
   plane: a pitched plane with every car scaled along its ray by ``1 / (1 - z t / h)``
   explains the same image, so the plane rests on the car-size prior.)
5. ``--evidence-scale``: the shipped part detectors' log ratio at the true visible
   vertices, at points displaced from them by a fraction of the projected car length,
   at occluded vertices and at random points of the box, beside the oracle evidence's
   (``wirescene.infer.evidence.ORACLE_*`` are set from this).

Usage: python benchmarks/bench_inference.py SYNTH_DIR [--frames 20] [--evidence oracle|parts]
           [--variant fg+gp] [--config NAME:key=value,...] [--plot study.png] [--json study.json]
       python benchmarks/bench_inference.py SYNTH_DIR --cma [--frames 10]
       python benchmarks/bench_inference.py SYNTH_DIR --ceiling
       python benchmarks/bench_inference.py SYNTH_DIR --true-plane [--config NAME:key=value,...]
       python benchmarks/bench_inference.py SYNTH_DIR --evidence-scale [--frames 6]
"""

from __future__ import annotations

import os
import sys

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from _common import approximated_wireframes, frame_result_2d, parse_config, run_configs  # noqa: E402
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.core.shape import load_default  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.core.viewpoints import angle_difference  # noqa: E402
from wirescene.eval.metrics import evaluate  # noqa: E402
from wirescene.eval.runner import frame_result  # noqa: E402
from wirescene.infer.evidence import oracle_evidence, part_evidence  # noqa: E402
from wirescene.infer.inference import InferenceOptions, _evaluate, _to_viewing, estimate_from_refined, refine_particles  # noqa: E402
from wirescene.io.detections import detections_from_labels  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.io.wireframes import read_wireframe_gt, wireframe_gt_path  # noqa: E402
from wirescene.lift import LiftingOptions, lift_table, plane_vote_weights, select_particles  # noqa: E402

#: The settings of the study: the paper's schedule, each addition alone, the previous
#: default (shape prior 10, box 300, polish 24), then the default and its variations of weights,
#: budget and model.
STUDY = [
    "paper:box_weight=0,plane_refinement=0,shape_prior=0,size_prior=0,polish_iterations=0",
    "paper+plane:box_weight=0,shape_prior=0,size_prior=0,polish_iterations=0",
    "paper+box:plane_refinement=0,shape_prior=0,size_prior=0,polish_iterations=0",
    "box+plane:shape_prior=0,size_prior=0,polish_iterations=0",
    "prior10:shape_prior=10,size_prior=0,box_weight=300,polish_iterations=24",
    "default:",
    "box300:box_weight=300",
    "nosize:size_prior=0",
    "6it:iterations=6",
    "24it:iterations=24",
    "24smp:samples=24",
    "polish48:polish_iterations=48",
    "shape10:n_shape=10",
    "shape10+prior0:n_shape=10,shape_prior=0",
    "noprune:prune_after=0",
]


def study(args):
    configs = dict(parse_config(c) for c in (args.config or STUDY))
    if args.evidence == "parts" and not args.config:
        configs["nearest"] = {"bilinear": False}
    results, seconds, n_frames = run_configs(args.root, args.variant, configs, evidence=args.evidence,
                                             frames=args.frames, seed=args.seed,
                                             log=lambda m: print(m, file=sys.stderr, flush=True))
    rows = []
    for (name, v), frames in results.items():
        m = evaluate(frames).metrics["all"]
        rows.append(dict(config=name, variant=v, cars=m["n_tp"], loc_1m=m["loc_1m"], median_az3d=m["median_az3d"],
                         median_loc=m["median_loc"], parts_70=m["parts_70"],
                         s_per_frame=seconds[name] / len(args.variant) / max(n_frames, 1)))
    print(f"{args.evidence} evidence, {n_frames} frames; CPU seconds per frame and variant (fitting only)")
    print(f"{'config':12s} {'variant':7s} {'cars':>4s} {'<1m %':>6s} {'az deg':>6s} {'loc m':>6s} {'parts70 %':>9s} {'s/frame':>8s}")
    for r in rows:
        print(f"{r['config']:12s} {r['variant']:7s} {r['cars']:4d} {r['loc_1m']:6.1f} {r['median_az3d']:6.2f} "
              f"{r['median_loc']:6.2f} {r['parts_70']:9.1f} {r['s_per_frame']:8.2f}")
    if args.json:
        write_json(args.json, {"evidence": args.evidence, "frames": n_frames, "configs": configs, "rows": rows})
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4.5))
        for v in args.variant:
            sel = [r for r in rows if r["variant"] == v]
            ax.scatter([r["s_per_frame"] for r in sel], [r["loc_1m"] for r in sel], label=v)
            for r in sel:
                ax.annotate(r["config"], (r["s_per_frame"], r["loc_1m"]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
        ax.set_xlabel("CPU seconds per frame (fitting, one core)")
        ax.set_ylabel("% cars within 1 m")
        ax.set_title(f"fine stage, {args.evidence} evidence, {n_frames} synthetic frames")
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"plot written to {args.plot}")


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
            vals = _evaluate(camera, model, evidence, particles.take([0]), theta, K, options.occluded_score,
                             border_occludes=options.border_occludes)[0, j]
            es.tell(list(xs), list(-vals))
        best[0, j] = x0 + np.asarray(es.result.xbest) * scale
    return best[0]


def cma_comparison(args):
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
            val = _evaluate(cam, model, ev, p, th[None, :, None, :], opts.n_shape, opts.occluded_score,
                            border_occludes=opts.border_occludes)[0, :, 0]
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


def ceiling(args):
    """Paper Table 3 measure of the true wireframes approximated with K coefficients."""
    ds = KittiDataset(args.root)
    model = load_default()
    frames = []
    for fid in ds.frame_ids()[: args.frames]:
        path = wireframe_gt_path(ds.split_dir, fid)
        frames.append((ds.labels(fid), read_wireframe_gt(path), json.loads(path.read_text()), ds.camera(fid)))
    print(f"{sum(len(f[0].objects) for f in frames)} cars of {len(frames)} frames; true pose, least-squares shape")
    print(f"{'K':>3s} {'parts70 %':>9s} {'median vertex error / threshold':>32s}")
    for K in (0, 3, 5, 8, 10, 12, 15, 20):
        frame_results, ratio = [], []
        for labels, vgt, raw, camera in frames:
            uv, _ = approximated_wireframes(model, raw["cars"], camera, K)
            for j, box in enumerate(o.box for o in labels.objects):
                err = np.linalg.norm(uv[j] - vgt.vertices_2d[j], axis=1)[~vgt.self_occluded[j]]
                ratio.append(np.median(err) / (0.04 * max(box[2] - box[0], box[3] - box[1])))
            frame_results.append(frame_result_2d(labels, vgt, camera, uv))
        m = evaluate(frame_results).metrics["all"]
        print(f"{K:3d} {m['parts_70']:9.1f} {np.median(ratio):32.2f}")


def true_plane(args):
    """fg+gp on the estimated and on the true ground plane (oracle evidence, label boxes)."""
    ds = KittiDataset(args.root)
    model = load_default()
    configs = dict(parse_config(c) for c in (args.config or ["default:"]))
    results = {(n, m): [] for n in configs for m in ("estimated", "true")}
    for fid in ds.frame_ids()[: args.frames]:
        labels, camera = ds.labels(fid), ds.camera(fid)
        vgt = read_wireframe_gt(wireframe_gt_path(ds.split_dir, fid))
        dets = detections_from_labels(labels)
        ev = oracle_evidence(dets, np.array([o.box for o in labels.objects]), vgt)
        weights = plane_vote_weights(dets.scores)
        particles = select_particles(lift_table(camera, dets), shared_plane=True,
                                     n_particles=LiftingOptions().n_particles, weights=weights)
        plane = vgt.ground_plane
        for name, kw in configs.items():
            for mode in ("estimated", "true"):
                p, opts = particles, InferenceOptions(**kw)
                if mode == "true":
                    p = dataclasses.replace(particles, pitch=np.full_like(p.pitch, plane["pitch"]),
                                            roll=np.full_like(p.roll, plane["roll"]))
                    opts = dataclasses.replace(opts, plane_refinement=False)
                refined = refine_particles(camera, p, ev, model, options=opts, boxes=dets.boxes, weights=weights,
                                           rng=np.random.default_rng([args.seed, len(dets)]))
                est = estimate_from_refined(camera, refined, dets, model, variant="fg+gp")
                results[(name, mode)].append(frame_result(fid, labels, dets, est, vgt, camera))
        print(f"{fid} done", file=sys.stderr, flush=True)
    print(f"oracle evidence, fg+gp, {args.frames or len(ds.frame_ids())} frames")
    print(f"{'config':12s} {'plane':9s} {'cars':>4s} {'<1m %':>6s} {'az deg':>6s} {'loc m':>6s} {'parts70 %':>9s}")
    for (name, mode), frames in results.items():
        m = evaluate(frames).metrics["all"]
        print(f"{name:12s} {mode:9s} {m['n_tp']:4d} {m['loc_1m']:6.1f} {m['median_az3d']:6.2f} {m['median_loc']:6.2f} "
              f"{m['parts_70']:9.1f}")


def evidence_scale(args):
    """Detectors' log ratio against the distance from the true vertex, beside the oracle's."""
    ds = KittiDataset(args.root)
    rng = np.random.default_rng(args.seed)
    dist = np.array([0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.10, 0.15])
    near, occluded, inside = [], [], []
    for fid in ds.frame_ids()[: args.frames]:
        labels, camera = ds.labels(fid), ds.camera(fid)
        vgt = read_wireframe_gt(wireframe_gt_path(ds.split_dir, fid))
        dets = detections_from_labels(labels)
        ev = part_evidence(ds.image(fid), dets)
        for j, car in enumerate(labels.objects):
            uv, vis = vgt.vertices_2d[j], vgt.visible[j]
            scale = camera.focal * car.dims[2] / np.linalg.norm(car.location)  # projected length, px
            angle = rng.uniform(0, 2 * np.pi, (len(dist), 8, 36))
            pts = uv + np.stack([np.cos(angle), np.sin(angle)], -1) * (dist[:, None, None, None] * scale)
            lr = ev.log_ratio(pts, np.full(pts.shape[:-2], j), np.full(pts.shape[:-2], scale))
            if vis.any():
                near.append(lr[..., vis].mean(axis=(1, 2)))
            occluded.extend(lr[0, 0, ~vis & ~vgt.self_occluded[j]])
            b = dets.boxes[j]
            pts = np.stack([rng.uniform(b[0], b[2], (8, 36)), rng.uniform(b[1], b[3], (8, 36))], -1)
            inside.extend(ev.log_ratio(pts, np.full(8, j), np.full(8, scale)).ravel())
    oracle = oracle_evidence(Detections(np.zeros((1, 4)), 1.0, np.zeros(1)), np.zeros((0, 4)), None)
    curve = np.mean(near, axis=0)
    print(f"{len(near)} cars of {args.frames or len(ds.frame_ids())} frames, shipped part detectors")
    print(f"{'distance / car length':>22s} {'detectors':>9s} {'oracle':>7s}")
    for d, v in zip(dist, curve):
        o = oracle.floor + (oracle.peak - oracle.floor) * np.exp(-0.5 * (d / oracle.sigma_frac) ** 2)
        print(f"{d:22.2f} {v:9.2f} {o:7.2f}")
    print(f"occluded vertices at their true place: median {np.median(occluded):.2f} (oracle {oracle.floor:.2f})")
    print(f"random points of the box: median {np.median(inside):.2f} (oracle {oracle.floor:.2f})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--evidence", choices=["oracle", "parts"], default="oracle")
    ap.add_argument("--variant", action="append", default=None)
    ap.add_argument("--config", action="append", default=None, help="NAME:key=value,... (InferenceOptions)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--plot", default=None, help="PNG of precision against seconds per frame")
    ap.add_argument("--json", default=None)
    ap.add_argument("--cma", action="store_true", help="Algorithm 1 vs CMA-ES instead of the study")
    ap.add_argument("--ceiling", action="store_true", help="2D part measure of the shape model's best fits per K")
    ap.add_argument("--true-plane", action="store_true", help="fg+gp on the estimated vs the true ground plane")
    ap.add_argument("--evidence-scale", action="store_true", help="part detectors' log ratio vs the oracle's")
    ap.add_argument("--iterations", type=int, default=12)
    ap.add_argument("--samples", type=int, default=12)
    args = ap.parse_args()
    if args.cma:
        args.frames = args.frames or 10
        cma_comparison(args)
    elif args.ceiling:
        ceiling(args)
    elif args.true_plane:
        true_plane(args)
    elif args.evidence_scale:
        args.frames = args.frames or 6
        evidence_scale(args)
    else:
        args.variant = args.variant or ["fg+gp"]
        study(args)


if __name__ == "__main__":
    main()
