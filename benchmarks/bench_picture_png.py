"""The time and size of a fitted image's two pictures by PNG compression level, plain script (not a test).

``fit`` writes an overlay and a bird's-eye view of every image, ``predict --pictures`` of every
frame, and zlib's compression is a good part of their time. This fits each frame once
(``coarse+gp``, label boxes), draws its two pictures (:func:`wirescene.io.outputs.scene_figures`)
and encodes them (:func:`wirescene.io.pictures.figure_bytes`) at each level of ``--levels``, side by
side, best of ``--repeats``, one thread; the pixels are the same at every level (checked).

Usage: python benchmarks/bench_picture_png.py [--root src/wirescene/data/sample/kitti] [--frames 6]
       [--levels 6 3 1] [--repeats 3]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import io  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent


def main() -> None:
    from PIL import Image

    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.options import FitOptions
    from wirescene.fitting.pipeline import fit_frame
    from wirescene.io.kitti import KittiDataset
    from wirescene.io.outputs import scene_figures
    from wirescene.io.pictures import figure_bytes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=str(HERE.parent / "src/wirescene/data/sample/kitti"),
                    help="KITTI root (its training split; default: the two bundled frames)")
    ap.add_argument("--frames", type=int, default=6, help="the first N labelled frames of the split")
    ap.add_argument("--levels", type=int, nargs="+", default=[6, 3, 1], help="zlib levels (Pillow's default: 6)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    seconds = {level: 0.0 for level in args.levels}
    sizes = {level: 0 for level in args.levels}
    frames = dataset.require_frames()[: args.frames]
    for frame in frames:
        camera, image = dataset.camera(frame), dataset.image(frame)
        fitted = fit_frame(camera, DetectionSource("gt").for_frame(dataset, frame, 0), ["coarse+gp"], image=image,
                           options=FitOptions())
        pixels = None
        for level in args.levels:
            best = np.inf
            for _ in range(args.repeats):
                figures = scene_figures(frame, image=image, camera=camera, estimate=fitted.estimates["coarse+gp"],
                                        detections=fitted.detections, gt=dataset.labels(frame).of_type("Car"))
                t0 = time.perf_counter()
                data = [figure_bytes(fig, pil_kwargs={"compress_level": level}) for fig in figures]
                best = min(best, time.perf_counter() - t0)
            seconds[level] += best
            sizes[level] += sum(len(d) for d in data)
            decoded = [np.asarray(Image.open(io.BytesIO(d))) for d in data]
            if pixels is None:
                pixels = decoded
            assert all(np.array_equal(a, b) for a, b in zip(pixels, decoded)), "the levels' pixels differ"
    first = args.levels[0]
    print(f"{len(frames)} frames of {args.root}, the two pictures each, best of {args.repeats}:")
    for level in args.levels:
        print(f"  level {level}: {seconds[level] / len(frames):.3f} s a frame ({seconds[first] / seconds[level]:.2f}x "
              f"level {first}'s speed), {sizes[level] / len(frames) / 1e6:.2f} MB a frame "
              f"({sizes[level] / sizes[first]:.2f}x)")


if __name__ == "__main__":
    main()
