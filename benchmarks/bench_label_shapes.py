"""Self-training of the real part labels: each labelled car's shape refitted with its pose fixed.

The real part detectors learn from the mean wireframe scaled into each label's 3D box
(``training/parts_real.py``), a few percent of the car's length off its own corners. This
refits every labelled car of a KITTI root with its labelled pose and box fixed
(:func:`wirescene.training.parts_real.refit_label_shapes`), each frame with the part model of
its fold (held out by drive: ``DIR/parts_fold{k}.npz``), writes the shapes for
``wirescene train parts --label-shapes FILE`` and reports how far they moved from the scaled
mean (mean and largest vertex move, as a share of the car's length).

    python benchmarks/bench_label_shapes.py --root KITTI --models DIR --out SHAPES.npz [--shape-prior 1.0]
        [--frames 000010,...] [--json OUT]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from wirescene.core.jsonio import write_json
from wirescene.io.folds import fold_of
from wirescene.io.kitti import KittiDataset
from wirescene.parts.detector import PartDetector
from wirescene.training.parts_real import refit_label_shapes, save_label_shapes, scaled_mean_shape


def refit_frames(root, models: Path, frames, *, shape_prior: float) -> tuple[dict, np.ndarray]:
    """``({frame: (N, 36, 3)}, moves (cars, 2))``: the refitted shapes and each car's mean and
    largest vertex move from the scaled mean shape, in shares of its length."""
    ds = KittiDataset(root)
    detectors: dict[int, PartDetector] = {}
    shapes, moves = {}, []
    for f in frames:
        k = fold_of(f)
        if k not in detectors:
            detectors[k] = PartDetector.load(models / f"parts_fold{k}.npz")
        labels = ds.labels(f)
        shapes[f] = refit_label_shapes(ds.image(f), labels, ds.camera(f), detectors[k], shape_prior=shape_prior)
        for shape, car in zip(shapes[f], labels.of_type("Car")):
            d = np.linalg.norm(shape - scaled_mean_shape(car.dims), axis=1) / car.dims[2]
            moves.append((d.mean(), d.max()))
    return shapes, np.array(moves, float).reshape(-1, 2)


def summary(moves: np.ndarray) -> dict:
    """Median and upper quantiles of the cars' mean vertex move, the share kept at the mean and
    the median largest vertex move (percent of the car's length)."""
    m = 100 * moves
    return {"cars": len(m), "median": float(np.median(m[:, 0])), "q75": float(np.percentile(m[:, 0], 75)),
            "q90": float(np.percentile(m[:, 0], 90)), "max": float(m[:, 0].max()),
            "kept_mean_pct": float(100 * np.mean(m[:, 0] < 1e-9)), "largest_median": float(np.median(m[:, 1]))}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", required=True, type=Path)
    ap.add_argument("--models", required=True, type=Path, help="directory of parts_fold{k}.npz")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--shape-prior", type=float, default=1.0, help="weight of the shape prior (the fit's: 1)")
    ap.add_argument("--frames", default=None, help="comma-separated frame ids (default: all)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    frames = args.frames.split(",") if args.frames else KittiDataset(args.root).frame_ids()
    t0 = time.time()
    shapes, moves = refit_frames(args.root, args.models, frames, shape_prior=args.shape_prior)
    save_label_shapes(args.out, shapes)
    s = summary(moves)
    print(f"shape prior {args.shape_prior}: {s['cars']} cars in {time.time() - t0:.0f} s; mean vertex move "
          f"(% of the car's length) median {s['median']:.2f}, q75 {s['q75']:.2f}, q90 {s['q90']:.2f}, "
          f"max {s['max']:.2f}; cars kept at the mean {s['kept_mean_pct']:.0f}%; largest vertex move median "
          f"{s['largest_median']:.2f}", file=sys.stderr)
    if args.json:
        write_json(args.json, s)


if __name__ == "__main__":
    main()
