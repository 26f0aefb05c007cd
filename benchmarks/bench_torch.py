"""Numpy vs the optional PyTorch backend (wirescene.infer.torch_backend) on the inference hot
path, side by side in one run on the same data:

* self-occlusion of 250 particles x 5 objects x 12 samples = 15000 placed wireframes
  (the ray casting of ``wirescene.infer.likelihood.instantiate_wireframes``);
* inter-object occlusion of 250 scenes x 5 objects;
* the object likelihood (paper Eq. 2) of the 15000 hypotheses.

Cars are shape-model wireframes 5-40 m in front of a camera at KITTI height. Every
backend's flags are compared with numpy's (disagreements are float32 near-grazing
cases). Times are the best of ``--repeat`` runs after one warm-up run; the CUDA times
include the transfers to and from the GPU (inputs and outputs are numpy arrays).

By default everything runs on one core (``--threads 1`` sets OMP/MKL/OpenBLAS threads
and ``torch.set_num_threads``) for a like-for-like comparison of the kernels.

    python benchmarks/bench_torch.py [--threads 1] [--device auto|cpu|cuda|cpu,cuda]
"""

from __future__ import annotations

import argparse
import os
import sys


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--objects", type=int, default=5)
    ap.add_argument("--samples", type=int, default=12)
    ap.add_argument("--threads", type=int, default=1, help="CPU threads for numpy's BLAS and torch (default 1)")
    ap.add_argument("--device", default="auto",
                    help="torch devices, comma-separated: cpu, cuda, cuda:N; auto = cpu and cuda if available")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args(None if __name__ == "__main__" else [])


ARGS = parse_args()  # at import: thread counts must be set before numpy/torch load their runtimes
if __name__ == "__main__":
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(ARGS.threads)

import numpy as np

from _common import best_of
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, object_pose, transform
from wirescene.core.shape import load_default
from wirescene.core.wireframe import FACES
from wirescene.infer import torch_backend as tb
from wirescene.infer.likelihood import object_likelihood
from wirescene.infer.occlusion import inter_object_occlusion, self_occlusion

CENTER = np.array([0.06, 0.0, 0.0])  # KITTI P2's optical centre is slightly off the origin


def placed_wireframes(shape_model, batch, rng, max_bearing_deg=40.0):
    dist = rng.uniform(5, 40, batch)
    bearing = np.radians(rng.uniform(-max_bearing_deg, max_bearing_deg, batch))
    location, R = object_pose(
        dist * np.sin(bearing), dist * np.cos(bearing), rng.uniform(-np.pi, np.pi, batch),
        rng.normal(0, 0.02, batch), rng.normal(0, 0.02, batch), KITTI_CAMERA_HEIGHT,
    )
    return transform(shape_model.instantiate(rng.normal(size=batch + (5,))), location, R)


def devices():
    if not tb.available():
        print("PyTorch is not installed (pip install torch): numpy only")
        return []
    names = ["cpu", "cuda"] if ARGS.device == "auto" else [d.strip() for d in ARGS.device.split(",") if d.strip()]
    out = []
    for name in names:
        try:
            out.append(tb.resolve_device(name))
        except tb.DeviceError as exc:
            if ARGS.device != "auto":
                sys.exit(f"bench_torch: error: {exc}")
    return out


def report(title, n, unit, rows, reference):
    """rows: [(label, seconds, flags or values)]; ratios against the first row."""
    print(title)
    t0 = rows[0][1]
    for label, t, out in rows:
        if out.dtype == bool:
            diff = int(np.count_nonzero(out != reference))
            check = f"{diff} of {out.size} flags differ from numpy"
        else:
            check = f"max |diff| vs numpy {np.max(np.abs(out - reference)):.1e}"
        print(f"  {label:<12}{n / t:12.0f} {unit}/s  {t * 1e3:8.1f} ms  {t0 / t:6.2f}x numpy   ({check})")


def main():
    devs = devices()
    if devs:
        import torch

        torch.set_num_threads(ARGS.threads)
    S, N, K = ARGS.particles, ARGS.objects, ARGS.samples
    rng = np.random.default_rng(ARGS.seed)
    shape_model = load_default()
    hyp = placed_wireframes(shape_model, (S, N, K), rng)  # (S, N, K, 36, 3)
    scenes = placed_wireframes(shape_model, (S, N), rng, max_bearing_deg=25.0)
    H = S * N * K
    version = f"torch {torch.__version__}" if devs else "no torch"
    load = f", load average {os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else ""
    print(f"{version}, {ARGS.threads} thread(s), {os.cpu_count()} CPUs{load}; backends: numpy"
          + "".join(f", torch {d}" for d in devs))
    print(f"{S} particles x {N} objects x {K} samples = {H} hypotheses x {hyp.shape[-2]} vertices, {len(FACES)} faces")

    t, ref = best_of(lambda: self_occlusion(hyp, FACES, CENTER), ARGS.repeat, warmup=True)
    self_hidden = ref
    rows = [("numpy", t, ref)]
    for dev in devs:
        rows.append((f"torch {dev}",) + best_of(lambda dev=dev: tb.self_occlusion(hyp, FACES, CENTER, device=dev), ARGS.repeat, warmup=True))
    report(f"self_occlusion (hidden fraction {ref.mean():.3f})", H, "hypotheses", rows, ref)

    t, ref = best_of(lambda: inter_object_occlusion(scenes, FACES, CENTER), ARGS.repeat, warmup=True)
    rows = [("numpy", t, ref)]
    for dev in devs:
        rows.append((f"torch {dev}",) + best_of(lambda dev=dev: tb.inter_object_occlusion(scenes, FACES, CENTER, device=dev), ARGS.repeat, warmup=True))
    report(f"inter_object_occlusion, {S} scenes x {N} objects (hidden fraction {ref.mean():.3f})", S, "scenes", rows, ref)

    evidence = rng.normal(scale=2.0, size=hyp.shape[:-1])
    mask_hidden = rng.random(hyp.shape[:-1]) < 0.2
    t, ref = best_of(lambda: object_likelihood(evidence, self_hidden, mask_hidden, c=-0.5), ARGS.repeat, warmup=True)
    rows = [("numpy", t, ref)]
    for dev in devs:
        rows.append((f"torch {dev}",) + best_of(
            lambda dev=dev: tb.object_likelihood(evidence, self_hidden, mask_hidden, c=-0.5, device=dev), ARGS.repeat, warmup=True))
    report("object_likelihood", H, "hypotheses", rows, ref)


if __name__ == "__main__":
    main()
