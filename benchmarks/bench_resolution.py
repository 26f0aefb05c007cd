"""Another camera's resolution: a KITTI root whose images are resized by a factor, for the held-out runs.

A user's camera need not have KITTI's 1242 x 375 pixels and focal length of 721 px. This
writes a copy of the labelled frames of ``--root`` as another camera would have taken them:
each image resized by ``--scale`` (PIL, Lanczos), each calibration's ``P2`` rescaled alike
(rows 0 and 1, with the half-pixel shift of pixel centres; written as P0..P3), each
label's 2D box scaled; 3D boxes, frame ids and drives unchanged. Fitting it with the fold
models (``bench_real_folds.py --root OUT``) and the original side by side tells whether the
pipeline holds at that resolution (the fit's evidence and box terms are in units of the box;
the detector bank searches a pyramid of heights from 25 px).

KITTI's difficulties count pixels (moderate: boxes of at least 25 px), so at another scale
the moderate cars are not the same ones and APs are not comparable; the shares of all 294
cars (found, within 1 m) are.

Usage:
  python benchmarks/bench_resolution.py --root ../shared/data/kitti --scale 1.5 --out WORK/kitti_x1.5
  python benchmarks/bench_real_folds.py --root WORK/kitti_x1.5 --models FOLD_MODELS --detections bank \\
      --variant coarse+gp --variant full --seed 1 --out RUN_X1.5
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train_scale import labelled_frames  # noqa: E402
from wirescene.core.camera import read_kitti_calib, write_kitti_calib  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402


def scaled_projection(P: np.ndarray, scale: float) -> np.ndarray:
    """``P`` ``(3, 4)`` of the same camera whose image is resized by ``scale``: a pixel centre
    ``u`` moves to ``scale * (u + 0.5) - 0.5``."""
    out = np.array(P, dtype=float)
    shift = 0.5 * (scale - 1.0)
    out[:2] = scale * out[:2] + shift * out[2]
    return out


def scaled_label_line(line: str, scale: float) -> str:
    """A KITTI label line with its 2D box (columns 5-8) scaled; the rest as it was."""
    cols = line.split()
    if len(cols) < 15:
        return line
    cols[4:8] = [f"{scale * (float(v) + 0.5) - 0.5:.2f}" for v in cols[4:8]]
    return " ".join(cols)


def resized_root(source: Path, out: Path, scale: float) -> list[str]:
    """Write ``out/training/{image_2,calib,label_2}`` of the labelled frames of ``source``
    resized by ``scale``; returns the frame ids."""
    dataset = KittiDataset(source)
    frames = labelled_frames(source)
    if not frames:
        raise SystemExit(f"{source}: no labelled frames")
    split = out / "training"
    for sub in ("image_2", "calib", "label_2"):
        (split / sub).mkdir(parents=True, exist_ok=True)
    for f in frames:
        image = Image.open(dataset.image_path(f))
        w, h = image.size
        image.resize((round(w * scale), round(h * scale)), Image.LANCZOS).save(split / "image_2" / f"{f}.png")
        write_kitti_calib(split / "calib" / f"{f}.txt", scaled_projection(read_kitti_calib(dataset.calib_path(f)).P2, scale))
        lines = dataset.label_path(f).read_text().splitlines()
        (split / "label_2" / f"{f}.txt").write_text("".join(scaled_label_line(ln, scale) + "\n" for ln in lines))
    image_sets = Path(source) / "ImageSets"
    if image_sets.is_dir():
        shutil.copytree(image_sets, out / "ImageSets", dirs_exist_ok=True)
    return frames


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, type=Path, help="KITTI root with labelled frames")
    ap.add_argument("--scale", required=True, type=float, help="resize factor of the images (e.g. 0.75, 1.5, 2)")
    ap.add_argument("--out", required=True, type=Path, help="the resized KITTI root to write")
    args = ap.parse_args(argv)
    if not args.scale > 0:
        ap.error("--scale must be positive")
    frames = resized_root(args.root, args.out, args.scale)
    print(f"{len(frames)} frames resized by {args.scale:g} into {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
