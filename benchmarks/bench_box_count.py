"""The fit's time against the number of boxes a frame is given, plain script (not a test).

Boxes read from another detector's files are all fitted (``--min-score`` cuts them), so a
detector's raw output costs the fit per box. This times ``wirescene.fit`` on one frame with
N boxes drawn at random (heights 25-120 px, widths 1-2.5 heights, bottoms in the lower half
of the image, seeded), for each N of ``--boxes`` and each ``--variant``, one thread, after
a warm-up fit, and prints the seconds a box on average at each N and between the two
largest N (a box added to many can cost more than one added to few).

Usage: python benchmarks/bench_box_count.py [--root src/wirescene/data/sample/kitti] [--frame 000010]
       [--boxes 0 10 50] [--variant coarse --variant full] [--particles 250]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent


def random_boxes(n: int, width: int, height: int, *, seed: int = 0) -> np.ndarray:
    """``(n, 4)`` boxes ``x1 y1 x2 y2`` of car-like shapes standing in the image's lower half."""
    rng = np.random.default_rng(seed)
    h = rng.uniform(25, 120, n)
    w = np.minimum(h * rng.uniform(1.0, 2.5, n), width - 1)
    x1 = rng.uniform(0, width - w)
    y2 = rng.uniform(height / 2 + 2, height - 1, n)
    return np.stack([x1, np.maximum(y2 - h, 0), x1 + w, y2], axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=HERE.parent / "src" / "wirescene" / "data" / "sample" / "kitti")
    ap.add_argument("--frame", default="000010")
    ap.add_argument("--boxes", type=int, nargs="+", default=[0, 10, 50])
    ap.add_argument("--variant", action="append", default=None, help="default: coarse and full")
    ap.add_argument("--particles", type=int, default=250)
    args = ap.parse_args()

    import wirescene
    from wirescene.io.kitti import KittiDataset

    ds = KittiDataset(args.root)
    image, camera = ds.image(args.frame), ds.camera(args.frame)
    H, W = image.shape[:2]
    for variant in args.variant or ["coarse", "full"]:
        wirescene.fit(image, camera.P, random_boxes(2, W, H, seed=1), variant=variant, particles=args.particles)
        seconds = {}
        for n in args.boxes:
            boxes = random_boxes(n, W, H) if n else np.zeros((0, 4))
            t0 = time.perf_counter()
            wirescene.fit(image, camera.P, boxes, variant=variant, particles=args.particles)
            seconds[n] = time.perf_counter() - t0
        cells = ", ".join(f"{n} boxes {s:.2f} s" for n, s in seconds.items())
        ns = sorted(n for n in seconds if n)
        per = ", ".join(f"{seconds[n] / n:.3f} s ({n})" for n in ns)
        last = "" if len(ns) < 2 else (f"; each box from {ns[-2]} to {ns[-1]}: "
                                       f"{(seconds[ns[-1]] - seconds[ns[-2]]) / (ns[-1] - ns[-2]):.3f} s")
        print(f"{variant}: {cells}; a box on average {per}{last}")


if __name__ == "__main__":
    main()
