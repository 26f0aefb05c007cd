"""The pipeline's own pre-detection of this checkout against another checkout's, side by side.

:func:`wirescene.fitting.own_boxes.own_detections` (the shipped bank at the fit's threshold, with the
enlarged image's cars where the checkout's default adds them, then the box rule's viewpoints)
runs in two worker processes, one importing this checkout's ``src``, the other ``--other``'s
(e.g. ``git worktree add BASE REV``, then ``--other BASE/src``), each on one core (BLAS threads
1). They take the frames in turn, frame by frame, so that a change in the machine's speed falls
on both alike; each reports the CPU seconds of its call (= seconds on one free core). Prints the
mean seconds a frame of each, their ratio, and whether the two give the same detections (boxes,
scores and viewpoints to the bit, or how far apart). ``--fold-banks`` / ``--fold-classifiers``
(path patterns with ``{k}``) detect each frame with the bank and crop classifier of its fold
(:func:`wirescene.io.folds.fold_of`), trained without its drives: the models the README's
held-out figures from our own boxes come from. ``--stages`` also prints the CPU seconds a frame
of the stages each worker times inside the call (the colour channels' integral images, the
HOG pyramids, the windows' warps and HOG for the box refinement and the verifier, the
templates' responses), the two checkouts side by side.

    python benchmarks/bench_own_predetect.py --root ../shared/data/kitti --other BASE/src [--frames 24] [--stages]
    python benchmarks/bench_own_predetect.py --root ../shared/data/kitti --other BASE/src --frames 72 \
        --fold-banks 'M/bank_fold{k}.npz' --fold-classifiers 'M/viewpoint_classifier_fold{k}.npz'
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

_WORKER = r"""
import json, sys, time
from threadpoolctl import threadpool_limits
threadpool_limits(1)
try:
    from wirescene.fitting.models import detector_bank, viewpoint_classifier
    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.own_boxes import own_detections
except ImportError:  # a checkout before fitting.pipeline was split, whose detect_own ran the passes
    from wirescene.fitting.pipeline import PredetectOptions, detector_bank, viewpoint_classifier
    from wirescene.fitting.pipeline import detect_own as own_detections
from wirescene.io.folds import N_FOLDS, fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.predetect.bank import DetectorBank
from wirescene.predetect.viewpoint_classifier import ViewpointClassifier
ds = KittiDataset(sys.argv[1])
seconds = {}


def timed(module, name, stage):  # CPU seconds of a stage inside detect_own, where this checkout has the function
    fn = getattr(module, name, None)
    if fn is None:
        return

    def wrapper(*args, **kwargs):
        c = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            seconds[stage] = seconds.get(stage, 0.0) + time.process_time() - c
    setattr(module, name, wrapper)


if sys.argv[5] == "stages":
    import wirescene.predetect.bank as bank_module
    import wirescene.predetect.refine as refine_module
    for module, name, stage in ((bank_module, "integral_channels", "colour channels"),
                                (bank_module, "feature_pyramid", "HOG pyramids"),
                                (refine_module, "crops_features", "windows' warps and HOG"),
                                (bank_module, "score_pyramid", "templates' responses")):
        timed(module, name, stage)
threshold = PredetectOptions().threshold if sys.argv[2] == "fit" else float(sys.argv[2])
# each checkout's own default enlargement (predetect.upsample), where it has one
enlarged = {"upsample": PredetectOptions().upsample} if hasattr(PredetectOptions(), "upsample") else {}
banks = [DetectorBank.load(sys.argv[3].format(k=k)) for k in range(N_FOLDS)] if sys.argv[3] else None
classifiers = [ViewpointClassifier.load(sys.argv[4].format(k=k)) for k in range(N_FOLDS)] if sys.argv[4] else None
for line in sys.stdin:
    f = line.strip()
    camera, image = ds.camera(f), ds.image(f)
    bank = detector_bank(None) if banks is None else banks[fold_of(f)]
    classifier = viewpoint_classifier(None) if classifiers is None else classifiers[fold_of(f)]
    seconds.clear()
    c = time.process_time()
    d = own_detections(camera, image, bank=bank, classifier=classifier, threshold=threshold, **enlarged)
    cpu = time.process_time() - c
    rows = [[float(v) for v in (*b, s, a)] for b, s, a in zip(d.boxes, d.scores, d.alpha)]
    print(json.dumps({"frame": f, "cpu": cpu, "detections": rows, "stages": seconds}), flush=True)
"""


def worker(src: str, args) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(Path(src).resolve()), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return subprocess.Popen([sys.executable, "-c", _WORKER, args.root, args.threshold, args.fold_banks or "",
                             args.fold_classifiers or "", "stages" if args.stages else ""],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)


def ask(proc: subprocess.Popen, frame: str) -> dict:
    proc.stdin.write(frame + "\n")
    proc.stdin.flush()
    line = proc.stdout.readline()
    if not line:
        raise SystemExit(f"a worker stopped on frame {frame} (exit code {proc.poll()})")
    return json.loads(line)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", required=True, help="KITTI root (e.g. ../shared/data/kitti)")
    ap.add_argument("--other", required=True, help="src/ folder of the other checkout")
    ap.add_argument("--frames", type=int, default=24, help="frames timed, spread evenly over the root's")
    ap.add_argument("--threshold", default="fit", help="the bank's threshold (default: the fit's)")
    ap.add_argument("--fold-banks", help="fold banks, a path pattern with {k} (default: the shipped bank)")
    ap.add_argument("--fold-classifiers", help="fold crop classifiers, a path pattern with {k} (default: the shipped one)")
    ap.add_argument("--stages", action="store_true", help="also time the stages inside the call")
    args = ap.parse_args()
    for name in ("fold_banks", "fold_classifiers"):
        pattern = getattr(args, name)
        if pattern and "{k}" not in pattern:
            raise SystemExit(f"--{name.replace('_', '-')} {pattern}: a path pattern with {{k}} for the fold")

    from wirescene.io.kitti import KittiDataset

    ids = KittiDataset(args.root).frame_ids()
    frames = list(dict.fromkeys(ids[i] for i in np.linspace(0, len(ids) - 1, args.frames).round().astype(int)))
    here = str(Path(__file__).resolve().parents[1] / "src")
    procs = {"this": worker(here, args), "other": worker(args.other, args)}
    try:
        ask(procs["this"], frames[0]), ask(procs["other"], frames[0])  # imports and caches, untimed
        cpu = {k: [] for k in procs}
        stages = {k: {} for k in procs}  # {checkout: {stage: summed CPU seconds}}
        same, gap, n_det = 0, 0.0, 0
        for i, f in enumerate(frames):
            order = ("this", "other") if i % 2 == 0 else ("other", "this")
            got = {k: ask(procs[k], f) for k in order}
            for k in procs:
                cpu[k].append(got[k]["cpu"])
                for stage, sec in got[k].get("stages", {}).items():
                    stages[k][stage] = stages[k].get(stage, 0.0) + sec
            a, b = (np.array(got[k]["detections"], float).reshape(-1, 6) for k in ("this", "other"))
            n_det += len(a)
            if a.shape == b.shape and np.array_equal(a, b):
                same += 1
            elif a.shape == b.shape:
                gap = max(gap, float(np.abs(a - b).max()))
            else:
                gap = np.inf
    finally:
        for p in procs.values():
            p.stdin.close()
            p.wait()
    t, o = np.mean(cpu["this"]), np.mean(cpu["other"])
    print(f"own_detections on {len(frames)} frames ({n_det} detections here), CPU s a frame on one core: this {t:.2f} "
          f"(max {np.max(cpu['this']):.2f}), other {o:.2f} (max {np.max(cpu['other']):.2f}), other / this {o / t:.2f}x; "
          f"detections identical on {same} of {len(frames)} frames"
          + ("" if same == len(frames) else f" (largest difference {gap:.3g})"))
    for stage in dict.fromkeys([*stages["this"], *stages["other"]]):
        a, b = (stages[k].get(stage, np.nan) / len(frames) for k in ("this", "other"))
        print(f"  {stage}: this {a:.3f} s a frame, other {b:.3f}, other / this {b / a:.2f}x")


if __name__ == "__main__":
    main()
