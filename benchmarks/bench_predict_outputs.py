"""What ``wirescene predict --json-dir / --pictures`` cost beside the label files alone, plain
script (not a test).

Runs :func:`wirescene.eval.predict.predict_dataset` on the same frames three ways side by side,
in this process, one thread: the label files alone, with each frame's JSON, and with the JSON
and the two pictures; each way ``--repeats`` times, alternating, after one warm-up frame of
each (matplotlib's import and the models' loading are not counted). Prints the seconds a frame
of each way, the extra seconds a frame against the labels alone, and the ratio.

Usage: python benchmarks/bench_predict_outputs.py [--root src/wirescene/data/sample/kitti]
       [--frames 12] [--variant coarse+gp] [--detections gt] [--particles 50] [--repeats 2]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
WAYS = {"labels": (False, False), "labels + JSON": (True, False), "labels + JSON + pictures": (True, True)}


def main() -> None:
    from wirescene.eval.predict import predict_dataset
    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.options import FitOptions
    from wirescene.io.kitti import KittiDataset

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=str(HERE.parent / "src/wirescene/data/sample/kitti"),
                    help="KITTI root (its training split; default: the two bundled frames)")
    ap.add_argument("--frames", type=int, default=12, help="the first N frames of the split")
    ap.add_argument("--variant", default="coarse+gp")
    ap.add_argument("--detections", default="gt", help="gt or bank")
    ap.add_argument("--particles", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    frames = dataset.require_frames(images=True)[: args.frames]
    options = FitOptions().with_settings({"lifting.n_particles": args.particles})
    source = DetectionSource(args.detections)
    seconds: dict[str, list[float]] = {way: [] for way in WAYS}
    with tempfile.TemporaryDirectory() as tmp:
        def run(way: str, run_frames: list[str], tag: str) -> float:
            scenes, pictures = WAYS[way]
            out = Path(tmp) / tag
            t0 = time.perf_counter()
            predict_dataset(dataset, out / "labels", variant=args.variant, source=source, options=options,
                            frames=run_frames, json_dir=out / "json" if scenes else None,
                            pictures_dir=out / "pictures" if pictures else None)
            return time.perf_counter() - t0

        for way in WAYS:
            run(way, frames[:1], f"warm-{way}")
        for k in range(args.repeats):
            for way in WAYS:
                seconds[way].append(run(way, frames, f"{k}-{way}") / len(frames))
    base = min(seconds["labels"])
    print(f"{len(frames)} frames of {args.root}, {args.variant}, {args.detections} boxes, {args.particles} particles, "
          f"best of {args.repeats}:")
    for way, each in seconds.items():
        print(f"  {way:26s} {min(each):6.3f} s a frame  ({min(each) - base:+.3f} s, {min(each) / base:.2f}x)")


if __name__ == "__main__":
    main()
