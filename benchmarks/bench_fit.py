"""Speed of the fine-grained model on a real KITTI frame (plain script, not a test).

1. Likelihood evaluations per second: the batched implementation (one call for
   particles x objects x samples) against a naive loop calling it once per hypothesis,
   measured side by side in this run, reported as a ratio; likewise the lifting's box
   projection (two terms an axis) against projecting the 8 placed corners, on the
   lifting's batch (cars x planes x azimuths).
2. One full fit per variant, per stage (lifting, part evidence, inference), and the peak
   resident memory of the process.
3. ``--against SRC`` (another checkout's ``src`` directory, e.g. a ``git worktree`` of the
   revision before a change): this checkout and that one side by side in one process,
   alternating, best of ``--repeats``: ``wirescene.fit`` per variant from plain boxes (the
   whole frame: the box rule's viewpoints, lifting, part maps, inference) and
   ``wirescene.detect``, then each stage alone (viewpoints, lifting, part maps, each
   variant's inference), on every ``--frame``; the ratio is the other revision's seconds
   over this one's (> 1: this one is faster), and every fit and detection is compared to
   the bit (``--no-stages``: the whole frame and detect only; ``--cpu``: CPU seconds of this
   process instead of wall seconds, for a machine that runs other work).

Usage: python benchmarks/bench_fit.py [--root tests/data/kitti] [--frame 000010] [--cars 5] [--particles 250]
       [--variants fg fg+gp full]
       python benchmarks/bench_fit.py --against OTHER/src --root ../shared/data/kitti --frame 000010 000095 000098
       [--variants coarse+gp fg+gp full] [--repeats 3] [--no-stages] [--cpu]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.core.boxes import MEAN_CAR_DIMS, box_corners, box_extent_object, project_points_to_box  # noqa: E402
from wirescene.core.groundplane import object_pose  # noqa: E402
from wirescene.core.shape import load_default  # noqa: E402
from wirescene.fitting.options import FitOptions  # noqa: E402
from wirescene.fitting.pipeline import fit_scene  # noqa: E402
from wirescene.infer.evidence import part_evidence  # noqa: E402
from wirescene.infer.inference import InferenceOptions  # noqa: E402
from wirescene.infer.likelihood import instantiate_wireframes, wireframe_likelihood  # noqa: E402
from wirescene.io.detections import detections_from_labels  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.lift import LiftingOptions, lift_table, project_boxes, select_particles  # noqa: E402


def likelihood_batch(camera, model, evidence, x, z, az, s, obj, c):
    b = instantiate_wireframes(camera, model, x=x, z=z, azimuth=az, pitch=np.zeros_like(x), roll=np.zeros_like(x),
                               shape=s, height=1.65)
    return wireframe_likelihood(b, evidence, obj, c=c)


def box_projection_ratio(camera, lifted, n_azimuths: int, repeats: int = 5) -> tuple[float, float]:
    """Seconds of one box projection of the lifting's batch, closed form and 8 corners."""
    n, G = lifted.cost.shape
    rng = np.random.default_rng(0)
    shape = (n, G, n_azimuths)
    loc, R = object_pose(lifted.x[..., None] + rng.normal(0, 0.1, shape), lifted.z[..., None] + rng.normal(0, 0.1, shape),
                         rng.uniform(-np.pi, np.pi, shape), lifted.pitch[:, None], lifted.roll[:, None])
    dims = np.broadcast_to(MEAN_CAR_DIMS, shape + (3,))
    lo, hi = box_extent_object(MEAN_CAR_DIMS)

    def corners():
        X = box_corners(dims, loc, R)
        return project_points_to_box(camera, X), camera.project_with_depth(X)[1].min(axis=-1)

    timings = {}
    for name, f in (("closed", lambda: project_boxes(camera, lo, hi, loc, R)), ("corners", corners)):
        f()
        t = time.perf_counter()
        for _ in range(repeats):
            out = f()
        timings[name] = (time.perf_counter() - t) / repeats, out
    (t_closed, a), (t_corners, b) = timings["closed"], timings["corners"]
    assert np.allclose(a[0], b[0], atol=1e-6) and np.allclose(a[1], b[1], atol=1e-9)
    return t_closed, t_corners


def _record(scene) -> str:
    """A fit to the bit: its JSON and the raw bytes of every car's arrays."""
    cars = [{k: v.tobytes().hex() if isinstance(v, np.ndarray) else v for k, v in vars(o).items()}
            for o in scene.objects]
    return json.dumps([scene.to_dict(), cars], sort_keys=True, default=str)  # plain json: compared, NaN kept


def _detection_record(d) -> bytes:
    return b"".join(np.ascontiguousarray(a).tobytes() for a in (d.boxes, d.scores, d.alpha))


def side_by_side(args) -> None:
    """Section 3 of the module docstring."""
    from _common import Checkout

    modules = ("wirescene", "wirescene.api", "wirescene.fitting.pipeline", "wirescene.lift", "wirescene.infer.evidence",
               "wirescene.infer.inference")
    revisions = {"this": Checkout(None, modules), "other": Checkout(args.against, modules)}
    print(f"this: {revisions['this'].path}\nother: {revisions['other'].path}")
    ds = KittiDataset(args.root)
    seconds: dict = {}  # (row, revision) -> summed best-of seconds
    differ: list = []
    for fid in args.frame:
        _frame_side_by_side(args, revisions, ds, fid, seconds, differ)
    rows = list(dict.fromkeys(r for r, _ in seconds))
    print(f"\n{len(args.frame)} frames ({', '.join(args.frame)}), best of {args.repeats} each, summed over the frames:")
    print(f"| {'':22s} | this (s) | other (s) | other / this |")
    for r in rows:
        a, b = seconds[(r, "this")], seconds[(r, "other")]
        print(f"| {r:22s} | {a:8.2f} | {b:9.2f} | {b / a:11.2f}x |")
    print("every result the same to the bit" if not differ else f"DIFFERENT results: {', '.join(differ)}")


def _frame_side_by_side(args, revisions: dict, ds, fid: str, seconds: dict, differ: list) -> None:
    """One frame of :func:`side_by_side`: every row timed for both revisions, alternating."""

    def timed(row: str, calls: dict) -> None:
        """Best of ``args.repeats`` for both revisions, alternating; ``calls`` maps each
        revision to ``(call, record of its result)``."""
        best, out = dict.fromkeys(revisions, np.inf), {}
        clock = time.process_time if args.cpu else time.perf_counter
        for _ in range(args.repeats):
            for name, rev in revisions.items():
                with rev.active():
                    t = clock()
                    out[name] = calls[name][0]()
                    best[name] = min(best[name], clock() - t)
        same = calls["this"][1](out["this"]) == calls["other"][1](out["other"])
        if not same:
            differ.append(f"{row} {fid}")
        for name in revisions:
            seconds[(row, name)] = seconds.get((row, name), 0.0) + best[name]
        print(f"  {fid} {row:22s} this {best['this']:7.3f} s, other {best['other']:7.3f} s, "
              f"ratio {best['other'] / best['this']:.2f}x, {'same' if same else 'DIFFERENT'}", flush=True)

    image, P2 = ds.image(fid), ds.calib(fid).P2
    boxes = detections_from_labels(ds.labels(fid)).boxes
    if args.cars is not None:
        boxes = boxes[:args.cars]
    settings = {"lifting.n_particles": args.particles}
    api = {name: rev.module("wirescene") for name, rev in revisions.items()}
    for name, rev in revisions.items():  # warm-up: each revision loads its models
        with rev.active():
            api[name].fit(image, P2, boxes[:1], variant="full", particles=20)
            api[name].detect(image, P2)
    print(f"{fid}: {len(boxes)} cars")
    for v in args.variants:
        timed(f"fit {v}", {name: (lambda a=a, v=v: a.fit(image, P2, boxes, variant=v, settings=settings), _record)
                           for name, a in api.items()})
    timed("detect", {name: (lambda a=a: a.detect(image, P2), _detection_record) for name, a in api.items()})
    if not args.stages:
        return
    stages = {name: _stage_calls(rev, image, P2, boxes, args.particles) for name, rev in revisions.items()}
    for row in stages["this"]:
        if row.startswith("inference") and row.split()[1] not in args.variants:
            continue
        timed(row, {name: stages[name][row] for name in revisions})


def _fit_name(rev, name: str):
    """``name`` of revision ``rev``'s fitting package, from the module that holds it: the options,
    loaders and own pre-detection left ``fitting.pipeline`` for modules of their own, where an older
    ``--against`` checkout does not have them."""
    for module in ("wirescene.fitting.options", "wirescene.fitting.models", "wirescene.fitting.own_boxes"):
        try:
            found = getattr(rev.module(module), name, None)
        except ImportError:  # a checkout before the split
            continue
        if found is not None:
            return found
    return getattr(rev.module("wirescene.fitting.pipeline"), name)


def _stage_calls(rev, image, P2, boxes, particles: int) -> dict:
    """``{row: (call, record)}`` of the stages of a fit in revision ``rev``, each with the
    inputs the stages before it made (in that revision)."""
    with rev.active():
        api, pipe = rev.module("wirescene.api"), rev.module("wirescene.fitting.pipeline")
        lift, evidence_of = rev.module("wirescene.lift"), rev.module("wirescene.infer.evidence").part_evidence
        camera = api.as_camera(P2, (image.shape[1], image.shape[0]))
        dets = pipe.inside_image(api.as_detections(boxes, camera.image_size), camera.image_size)
        bank, classifier = _fit_name(rev, "detector_bank")(None), _fit_name(rev, "viewpoint_classifier")(None)
        complete_viewpoints = _fit_name(rev, "complete_viewpoints")
        known = complete_viewpoints(camera, dets, image, bank=bank, classifier=classifier)
        options = _fit_name(rev, "FitOptions")(lifting=lift.LiftingOptions(n_particles=particles))
        lifted = lift.lift_table(camera, known, options=options.lifting)
        flip = rev.module("wirescene.infer.inference").InferenceOptions().flip_evidence
        evidence = evidence_of(image, known, flip=flip)
    calls = {
        "viewpoints": (lambda: complete_viewpoints(camera, dets, image, bank=bank, classifier=classifier),
                       _detection_record),
        "lifting": (lambda: lift.lift_table(camera, known, options=options.lifting),
                    lambda t: b"".join(np.ascontiguousarray(getattr(t, f)).tobytes() for f in ("x", "z", "azimuth", "cost"))),
        "part maps": (lambda: evidence_of(image, known, flip=flip),
                      lambda e: b"".join(b.log_ratio.tobytes() for b in e.responses.boxes)),
    }
    for v in ("fg+gp", "full", "fg", "fg+so", "fg+do"):
        calls[f"inference {v}"] = (lambda v=v: pipe.fit_scene(camera, known, variant=v, options=options, lifted=lifted,
                                                              evidence=evidence), _record)
    return calls


def main():
    ap = argparse.ArgumentParser()
    # The real frames the repository itself carries, so that a fresh clone can run it.
    ap.add_argument("--root", default=str(Path(__file__).resolve().parents[1] / "tests" / "data" / "kitti"))
    ap.add_argument("--frame", nargs="+", default=["000010"], help="frame(s); several with --against")
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--cars", type=int, default=None, help="use only the first N labelled cars of the frame")
    ap.add_argument("--variants", nargs="+", default=None,
                    help="default: fg fg+gp full; coarse+gp fg+gp full with --against")
    ap.add_argument("--against", default=None, help="another checkout's src directory, timed side by side")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many calls (--against)")
    ap.add_argument("--no-stages", dest="stages", action="store_false", help="--against: the whole frame only")
    ap.add_argument("--cpu", action="store_true", help="--against: CPU seconds of this process, not wall seconds")
    args = ap.parse_args()
    if args.against is not None:
        args.variants = args.variants or ["coarse+gp", "fg+gp", "full"]
        return side_by_side(args)
    args.variants = args.variants or ["fg", "fg+gp", "full"]
    if len(args.frame) != 1:
        raise SystemExit("one --frame without --against")
    args.frame = args.frame[0]
    ds = KittiDataset(args.root)
    camera, image = ds.camera(args.frame), ds.image(args.frame)
    dets = detections_from_labels(ds.labels(args.frame))
    if args.cars is not None:
        dets = dets.subset(np.arange(min(args.cars, len(dets))))
    model = load_default()
    c = InferenceOptions().occluded_score

    t, c = time.perf_counter(), time.process_time()
    lifted = lift_table(camera, dets, options=LiftingOptions(n_particles=args.particles))
    t_lift, c_lift = time.perf_counter() - t, time.process_time() - c
    flip = InferenceOptions().flip_evidence
    part_evidence(image, dets.subset(np.arange(1)), flip=True)  # warm-up: the part model's load, lazy imports
    t, c = time.perf_counter(), time.process_time()
    evidence = part_evidence(image, dets, flip=flip)  # as the fit reads it
    t_parts, c_parts = time.perf_counter() - t, time.process_time() - c
    c = time.process_time()
    part_evidence(image, dets, flip=not flip)  # the other reading, side by side
    c_other = time.process_time() - c

    # 1. batched vs naive likelihood on the same hypotheses
    p = select_particles(lifted, shared_plane=True, n_particles=args.particles)
    rng = np.random.default_rng(0)
    H = p.x.size
    x, z, az = p.x.ravel(), p.z.ravel(), p.azimuth.ravel()
    s = rng.standard_normal((H, 5)) * 0.5
    obj = np.tile(np.arange(p.n_objects), p.n_particles)
    t = time.perf_counter()
    batched = likelihood_batch(camera, model, evidence, x, z, az, s, obj, c)
    t_batch = time.perf_counter() - t
    n_naive = min(H, 300)
    t = time.perf_counter()
    naive = np.array([likelihood_batch(camera, model, evidence, x[i:i + 1], z[i:i + 1], az[i:i + 1], s[i:i + 1],
                                       obj[i:i + 1], c)[0] for i in range(n_naive)])
    t_naive = (time.perf_counter() - t) * H / n_naive
    assert np.allclose(naive, batched[:n_naive])
    print(f"{args.frame}: {len(dets)} cars, {p.n_particles} particles -> {H} hypotheses")
    print(f"likelihood: batched {H / t_batch:,.0f} hyp/s, naive {H / t_naive:,.0f} hyp/s, ratio {t_naive / t_batch:.1f}x")
    n_az = len(LiftingOptions().alpha_offsets(True))
    t_closed, t_corners = box_projection_ratio(camera, lifted, n_az)
    print(f"lifting's box projection ({len(dets)} x {lifted.cost.shape[1]} x {n_az} boxes): closed form "
          f"{t_closed * 1e3:.1f} ms, 8 corners {t_corners * 1e3:.1f} ms, ratio {t_corners / t_closed:.1f}x")

    # 2. full fits, per stage
    # Wall and CPU time of this process: on a busy machine the CPU time is the figure
    # to compare with a single free core.
    print(f"lifting (once per frame) {t_lift:.2f} s wall / {c_lift:.2f} s CPU, "
          f"part response maps {t_parts:.2f} s wall / {c_parts:.2f} s CPU "
          f"({'mirrored too' if flip else 'one reading'}; {'one reading' if flip else 'mirrored too'}: "
          f"{c_other:.2f} s CPU)")
    # Default options (pruning after 4 iterations) side by side with refining every
    # particle to the end (prune_after=0, wirescene 0.1's schedule).
    for v in args.variants:
        times = {}
        for prune in (InferenceOptions().prune_after, 0):
            opts = FitOptions(lifting=LiftingOptions(n_particles=args.particles),
                              inference=InferenceOptions(prune_after=prune))
            t, c = time.perf_counter(), time.process_time()
            fit_scene(camera, dets, variant=v, options=opts, lifted=lifted, evidence=evidence)
            times[prune] = time.perf_counter() - t, time.process_time() - c
        (t, c), (t0, c0) = times.values()
        print(f"{v:6s} inference {t:.2f} s wall / {c:.2f} s CPU; whole frame (lifting + parts + inference) "
              f"{t + t_lift + t_parts:.2f} s wall / {c + c_lift + c_parts:.2f} s CPU; "
              f"without pruning {t0:.2f} s wall ({t0 / t:.1f}x)")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
