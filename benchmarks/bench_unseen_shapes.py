"""The fine stage's ceiling on cars its shape model never saw: leave-one-exemplar-out on
synthetic scenes with perfect part evidence, plain script.

Protocol: for each of the shape model's CAD exemplars ``e``, ``--scenes`` synthetic scenes
(``wirescene.synth.generate_scene``, stream ``--seed``) whose every car is ``e`` (resized to
KITTI car sizes, as ``wirescene synth`` does) are written to ``WORK_DIR/kitti`` (kept for a
later run). Each scene is fitted twice from the same label boxes, oracle evidence
(``wirescene.infer.evidence.oracle_evidence``) and coarse particles: once with the shipped
shape model (``seen``: it was built from ``e`` too) and once with the model refitted the
shipped way (100 size-augmented copies per exemplar, seed 0) on the other exemplars
(``unseen``). The difference is what the synthetic figures owe to testing on the training
shapes. The shape model's own limit (``ceiling``, as ``bench_inference.py --ceiling``): every
true wireframe approximated by the first ``n_shape`` components (least squares in the object
frame), placed with its true pose and scored like a fit; with it the median vertex error
(metres) of that approximation.

Reported per model: cars within 1 m, median location error, median 3D azimuth error and the
paper's Table 3 measure (share of the eligible cars with >= 70% of their parts within 4% of
the box), pooled and per exemplar, and the ceiling's Table 3 measure.

Usage:
  python benchmarks/bench_unseen_shapes.py WORK_DIR [--scenes 2] [--seed 8128] [--variant fg+gp]
      [--json out.json]
"""

from __future__ import annotations

import os
import sys

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import approximated_wireframes, frame_result_2d  # noqa: E402
from wirescene.core.atomic import write_text  # noqa: E402
from wirescene.core.jsonio import dumps  # noqa: E402
from wirescene.core.shape import fit_shape_model, load_default  # noqa: E402
from wirescene.eval.metrics import evaluate  # noqa: E402
from wirescene.eval.runner import frame_result  # noqa: E402
from wirescene.fitting.variants import VARIANTS  # noqa: E402
from wirescene.infer.evidence import oracle_evidence  # noqa: E402
from wirescene.infer.inference import InferenceOptions, estimate_from_refined, refine_particles  # noqa: E402
from wirescene.io.detections import detections_from_labels  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.io.wireframes import read_wireframe_gt, wireframe_gt_path  # noqa: E402
from wirescene.lift import LiftingOptions, lift_table, plane_vote_weights, select_particles  # noqa: E402
from wirescene.synth.generate import default_camera, generate_scene, load_car_library, write_scene  # noqa: E402

AUGMENT, AUGMENT_SEED = 100, 0  # the shipped model's (`wirescene train shape` defaults)


def scenes(root: Path, library: dict, per_car: int, seed: int) -> dict[str, str]:
    """``{frame id: exemplar}``: ``per_car`` scenes of each exemplar of ``library`` alone under ``root``."""
    camera, names = default_camera(), sorted(library)
    out = {}
    for k, name in enumerate(names):
        for j in range(per_car):
            index = k * per_car + j
            fid = f"{index:06d}"
            path = root / "training" / "wireframes" / f"{fid}.json"
            if not (path.is_file() and {c["cad_model"] for c in json.loads(path.read_text())["cars"]} == {name}):
                scene = generate_scene(seed, index, camera=camera, library={name: library[name]})
                write_scene(root, fid, scene)
            out[fid] = name
    return out


def leave_one_out(model, name):
    """The shape model refitted without exemplar ``name``."""
    keep = [i for i, n in enumerate(model.exemplar_names) if n != name]
    return fit_shape_model(model.exemplars[keep], [model.exemplar_names[i] for i in keep], augment=AUGMENT,
                           rng=np.random.default_rng(AUGMENT_SEED))


def summary(frames) -> dict:
    m = evaluate(frames).metrics["all"]
    return {k: (round(float(m[k]), 2) if isinstance(m[k], float) else m[k])
            for k in ("n_tp", "loc_1m", "median_loc", "median_az3d", "parts_70", "n_parts_70_eligible")}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work_dir", type=Path, help="directory for the synthetic scenes")
    ap.add_argument("--scenes", type=int, default=2, help="scenes per exemplar")
    ap.add_argument("--seed", type=int, default=8128, help="scene stream")
    ap.add_argument("--variant", default="fg+gp", choices=[v for v, spec in VARIANTS.items() if spec.fine])
    ap.add_argument("--library", type=Path, default=None,
                    help="directory of another collection's cad_meshes.npz and cad_landmarks.json (see above)")
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = ap.parse_args()
    shipped, spec, options = load_default(), VARIANTS[args.variant], InferenceOptions()
    t0 = time.perf_counter()
    if args.library is None:
        library, root = load_car_library(), args.work_dir / "kitti"
        library = {n: library[n] for n in shipped.exemplar_names}
    else:
        library = load_car_library(args.library / "cad_meshes.npz", args.library / "cad_landmarks.json")
        library, root = {n: m for n, m in library.items() if n not in shipped.exemplar_names}, args.work_dir / "library"
        if not library:
            ap.error(f"{args.library}: no car the shipped model has not seen")
    frame_car = scenes(root, library, args.scenes, args.seed)
    print(f"{len(frame_car)} scenes ready in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    ds = KittiDataset(root)
    results = {m: {} for m in (("seen", "unseen") if args.library is None else ("unseen",))}
    ceiling, approx = {m: [] for m in results}, {m: [] for m in results}
    for name in sorted(library):
        models = {"seen": shipped, "unseen": leave_one_out(shipped, name)} if args.library is None else {"unseen": shipped}
        for fid in [f for f, n in frame_car.items() if n == name]:
            labels, camera = ds.labels(fid), ds.camera(fid)
            path = wireframe_gt_path(ds.split_dir, fid)
            vgt, wire = read_wireframe_gt(path), json.loads(path.read_text())  # wire: the cars' true wireframes
            dets = detections_from_labels(labels)
            ev = oracle_evidence(dets, np.array([o.box for o in labels.objects]).reshape(-1, 4), vgt)
            weights = plane_vote_weights(dets.scores)
            particles = select_particles(lift_table(camera, dets), shared_plane=spec.shared_plane,
                                         n_particles=LiftingOptions().n_particles, weights=weights)
            for key, model in models.items():
                refined = refine_particles(camera, particles, ev, model, options=options, boxes=dets.boxes,
                                           weights=weights, alpha=dets.alpha, rng=np.random.default_rng([1, len(dets)]),
                                           searched_occluder=spec.searched_occluder,
                                           deterministic_occlusion=spec.deterministic_occlusion)
                est = estimate_from_refined(camera, refined, dets, model, variant=args.variant)
                results[key].setdefault(name, []).append(frame_result(fid, labels, dets, est, vgt, camera))
                uv, err = approximated_wireframes(model, wire["cars"], camera, options.n_shape)
                ceiling[key].append(frame_result_2d(labels, vgt, camera, uv))
                approx[key].append(err)
        print(f"{name} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    out = {"variant": args.variant, "scenes_per_exemplar": args.scenes, "seed": args.seed,
           "n_shape": options.n_shape, "library": None if args.library is None else sorted(library)}
    for key, per_car in results.items():
        out[key] = {"all": summary([f for fs in per_car.values() for f in fs]),
                    "ceiling_parts_70": round(float(evaluate(ceiling[key]).metrics["all"]["parts_70"]), 2),
                    "approx_median_m": round(float(np.median(np.concatenate(approx[key]))), 3),
                    "per_exemplar": {n: summary(fs) for n, fs in per_car.items()}}
    print(f"{args.variant}, oracle evidence, label boxes, {len(frame_car)} scenes ({args.scenes} per exemplar)")
    print(f"{'model':7s} {'cars':>4s} {'<1m %':>6s} {'loc m':>6s} {'az deg':>6s} {'parts70 %':>9s} {'of':>4s} "
          f"{'ceiling %':>9s} {'approx m':>8s}")
    for key in results:
        a = out[key]["all"]
        print(f"{key:7s} {a['n_tp']:4d} {a['loc_1m']:6.1f} {a['median_loc']:6.2f} {a['median_az3d']:6.2f} "
              f"{a['parts_70']:9.1f} {a['n_parts_70_eligible']:4d} {out[key]['ceiling_parts_70']:9.1f} "
              f"{out[key]['approx_median_m']:8.3f}")
    print(f"{'exemplar':16s} {'cars':>4s} {'seen <1m':>8s} {'unseen <1m':>10s} {'seen p70':>8s} {'unseen p70':>10s}")
    for n in sorted(library):
        u = out["unseen"]["per_exemplar"][n]
        s = out["seen"]["per_exemplar"][n] if "seen" in out else {"loc_1m": float("nan"), "parts_70": float("nan")}
        print(f"{n:16s} {u['n_tp']:4d} {s['loc_1m']:8.1f} {u['loc_1m']:10.1f} {s['parts_70']:8.1f} {u['parts_70']:10.1f}")
    if args.json:
        write_text(args.json, dumps(out) + "\n")


if __name__ == "__main__":
    main()
