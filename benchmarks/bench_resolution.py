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

``--boxes`` also runs the pre-detection (``--bank``, default the shipped one; the fit's
threshold 0.3) on both roots and prints how the boxes of the resized images, mapped back to
the original pixels, compare with the original's and with the label boxes (median height
ratio, median IoU): whether the bank's boxes keep their size at another resolution.

Usage:
  python benchmarks/bench_resolution.py --root ../shared/data/kitti --scale 1.5 --out WORK/kitti_x1.5
  python benchmarks/bench_real_folds.py --root WORK/kitti_x1.5 --models FOLD_MODELS --detections bank \\
      --variant coarse+gp --variant full --seed 1 --out RUN_X1.5
  python benchmarks/bench_resolution.py --root ../shared/data/kitti --scale 1.5 --out WORK/kitti_x1.5 --boxes
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
from wirescene.core.boxes import iou_2d  # noqa: E402
from wirescene.core.camera import read_kitti_calib, write_kitti_calib  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.enlarge import scaled_projection  # noqa: E402


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


def box_agreement(source: Path, resized: Path, scale: float, frames: list[str], *, bank=None,
                  threshold: float = 0.3) -> dict:
    """The pre-detection's boxes of ``frames`` in the ``source`` root and in its copy
    ``resized`` by ``scale`` (mapped back to the source's pixels): ``{"detections": (n, n_resized),
    "matched": [(height ratio, IoU)] of each source box and the resized box it overlaps most
    (IoU > 0.5), "labelled": [[(height / label's, IoU)] for each root] of the boxes on a
    labelled car (IoU > 0.5)}``."""
    from wirescene.fitting.own_boxes import own_detections

    roots = (KittiDataset(source), KittiDataset(resized))
    out = {"detections": [0, 0], "matched": [], "labelled": [[], []]}
    for f in frames:
        boxes = []
        for k, root in enumerate(roots):
            b = own_detections(root.camera(f), root.image(f), bank=bank, threshold=threshold).boxes
            boxes.append(b if k == 0 else (b + 0.5) / scale - 0.5)
            out["detections"][k] += len(b)
        labels = np.array([o.box for o in roots[0].labels(f).of_type("Car")], float).reshape(-1, 4)
        for k, b in enumerate(boxes):
            out["labelled"][k] += [(_height(b)[i] / _height(labels)[j], iou) for i, j, iou in _best_overlaps(b, labels)]
        out["matched"] += [(_height(boxes[1])[j] / _height(boxes[0])[i], iou)
                           for i, j, iou in _best_overlaps(boxes[0], boxes[1])]
    return out


def _height(boxes: np.ndarray) -> np.ndarray:
    return boxes[:, 3] - boxes[:, 1]


def _best_overlaps(a: np.ndarray, b: np.ndarray) -> list[tuple[int, int, float]]:
    """``(i, j, IoU)`` of each box ``a[i]`` and the box ``b[j]`` it overlaps most, where that IoU exceeds 0.5."""
    if not len(a) or not len(b):
        return []
    pairs = iou_2d(a[:, None], b[None])
    return [(i, j, pairs[i, j]) for i, j in enumerate(pairs.argmax(axis=1)) if pairs[i, j] > 0.5]


def _medians(pairs) -> str:
    v = np.array(pairs, float).reshape(-1, 2)
    return "none" if not len(v) else f"height ratio {np.median(v[:, 0]):.4f}, IoU {np.median(v[:, 1]):.3f} (medians)"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, type=Path, help="KITTI root with labelled frames")
    ap.add_argument("--scale", required=True, type=float, help="resize factor of the images (e.g. 0.75, 1.5, 2)")
    ap.add_argument("--out", required=True, type=Path, help="the resized KITTI root to write")
    ap.add_argument("--boxes", action="store_true", help="also compare the pre-detection's boxes on both roots")
    ap.add_argument("--bank", type=Path, help="detector bank for --boxes (default: the shipped one)")
    ap.add_argument("--frames", type=int, help="for --boxes: only the first N labelled frames")
    args = ap.parse_args(argv)
    if not args.scale > 0:
        ap.error("--scale must be positive")
    frames = resized_root(args.root, args.out, args.scale)
    print(f"{len(frames)} frames resized by {args.scale:g} into {args.out}", file=sys.stderr)
    if args.boxes:
        from wirescene.predetect.bank import DetectorBank

        frames = frames[: args.frames] if args.frames else frames
        bank = DetectorBank.load(args.bank) if args.bank else None
        got = box_agreement(args.root, args.out, args.scale, frames, bank=bank)
        n, n_resized = got["detections"]
        print(f"{len(frames)} frames, {n} / {n_resized} detections at 1 / {args.scale:g}x")
        print(f"  resized against original ({len(got['matched'])} boxes matched): {_medians(got['matched'])}")
        for name, pairs in zip(("original", f"{args.scale:g}x"), got["labelled"]):
            print(f"  {name} against the labels ({len(pairs)} boxes on a car): {_medians(pairs)}")


if __name__ == "__main__":
    main()
