"""Write the labelled cars of a KITTI root as another detector's boxes would come: one
``FRAME.json`` per frame with boxes and scores only (no viewpoint), for
``bench_real_folds.py --detections DIR``. With ``--jitter`` each side moves by Gaussian noise
of 5% of the box's width / height (seeded per frame, as ``bench_box_viewpoints.py``'s
jittered boxes), as a good detector's boxes would.

    python benchmarks/write_box_files.py --root ../shared/data/kitti --out DIR [--jitter] [--seed 0]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _common import jitter_rng, jittered  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.jsonio import write_json
from wirescene.io.kitti import KittiDataset


def frame_boxes(dataset: KittiDataset, frame_id: str, *, jitter: bool, seed: int) -> list[dict]:
    """The frame's ``Car`` label boxes as ``[{"box": [x1, y1, x2, y2], "score": 1.0}]``."""
    boxes = np.array([o.box for o in dataset.labels(frame_id).of_type("Car")], float).reshape(-1, 4)
    if jitter and len(boxes):
        height, width = dataset.image(frame_id).shape[:2]
        boxes = jittered(boxes, (width, height), jitter_rng(seed, frame_id))
    return [{"box": [round(float(v), 2) for v in b], "score": 1.0} for b in boxes]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--jitter", action="store_true", help="move each side by N(0, 5%%) of the box's size")
    ap.add_argument("--seed", type=int, default=0, help="seed of the jitter")
    args = ap.parse_args()
    dataset = KittiDataset(args.root)
    args.out.mkdir(parents=True, exist_ok=True)
    frames = dataset.frame_ids()
    for f in frames:
        write_json(args.out / f"{f}.json", frame_boxes(dataset, f, jitter=args.jitter, seed=args.seed), indent=None)
    print(f"{len(frames)} frames -> {args.out}")


if __name__ == "__main__":
    main()
