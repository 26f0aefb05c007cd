"""A rig's camera pitch read off the boxes of many frames (``wirescene pitch``), plain script.

Each frame's boxes, found by a detector bank without its priors, give a log-likelihood of
the camera's pitch (:func:`wirescene.fitting.mount.image_pitch_likelihood`); the frames
of one rig add theirs (:func:`wirescene.predetect.geometry.pitch_of`). KITTI's frames come
from one car, its camera mounted level (to about a degree, as the road and the car's own
pitch allow): the pitch read off every frame pooled is the reference. With ``--fold-models``
each frame is read by the bank of the fold that left its drive out (held out; ``M`` as
``benchmarks/train_fold_models.py`` writes it), else by the shipped bank (which was trained
on these frames). Reported: each frame's pitch read alone (what ``--estimate-pitch`` reads),
the pitch pooled over all frames and over each drive, and how far the pitch pooled over ``n``
frames drawn at random falls from that of the frames not drawn (``--draws`` draws of each
``n``, up to half the frames; frames without a box read the prior's centre, the level rig).

Usage:
  python benchmarks/bench_rig_pitch.py --root ../shared/data/kitti [--fold-models M] [--sizes 1,3,5,10,20,36]
      [--draws 2000] [--json out.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.core.groundplane import KITTI_MOUNT  # noqa: E402
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.fitting.models import detector_bank  # noqa: E402
from wirescene.fitting.mount import image_pitch_likelihood, rig_pitch  # noqa: E402
from wirescene.io.folds import drive_map, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, required=True, help="KITTI root of labelled frames (training/).")
    ap.add_argument("--fold-models", type=Path, default=None,
                    help="Directory of bank_fold{k}.npz: each frame read by the bank that left its drive out.")
    ap.add_argument("--sizes", default="1,3,5,10,20,36", help="Frames pooled per draw (comma-separated).")
    ap.add_argument("--draws", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    ds = KittiDataset(args.root)
    ids = ds.frame_ids()
    drives, _ = drive_map(args.root)
    banks = {}
    likelihoods, boxes, seconds = {}, {}, []
    for fid in ids:
        k = fold_of(fid) if args.fold_models else None
        if k not in banks:
            banks[k] = detector_bank(None if k is None else args.fold_models / f"bank_fold{k}.npz")
        t = time.process_time()
        likelihoods[fid], boxes[fid] = image_pitch_likelihood(ds.camera(fid), ds.image(fid), bank=banks[k],
                                                              told=KITTI_MOUNT)
        seconds.append(time.process_time() - t)

    def pooled(frames) -> float:
        return rig_pitch([likelihoods[f] for f in frames], told=KITTI_MOUNT)

    alone = np.array([pooled([f]) for f in ids])
    reference = pooled(ids)
    by_drive = {}
    for fid in ids:
        by_drive.setdefault(drives.get(fid, "unknown"), []).append(fid)
    drive_pitch = {d: pooled(fs) for d, fs in sorted(by_drive.items())}
    rng = np.random.default_rng(args.seed)
    sizes = [int(s) for s in args.sizes.split(",") if int(s) <= len(ids) // 2]
    errors = {}
    for n in sizes:  # each draw against the frames it left: no frame on both sides
        off = []
        for _ in range(args.draws):
            drawn = set(rng.choice(ids, n, replace=False))
            off.append(abs(pooled(sorted(drawn)) - pooled([f for f in ids if f not in drawn])))
        errors[n] = {"median": float(np.median(off)), "p90": float(np.percentile(off, 90)), "max": float(np.max(off))}

    which = "held out (fold banks)" if args.fold_models else "the shipped bank (trained on these frames)"
    print(f"{len(ids)} frames, {sum(boxes.values())} boxes, {which}; {np.mean(seconds):.2f} s a frame (CPU)")
    print(f"pitch pooled over all frames: {reference:+.1f} deg")
    print(f"each frame alone: median {np.median(alone):+.1f}, standard deviation {alone.std():.2f}, "
          f"|.| 90th percentile {np.percentile(np.abs(alone), 90):.1f} deg")
    print(f"pooled by drive ({len(drive_pitch)} drives): standard deviation {np.std(list(drive_pitch.values())):.2f}, "
          f"range {min(drive_pitch.values()):+.1f} .. {max(drive_pitch.values()):+.1f} deg")
    print(f"| frames pooled | |pitch - the other frames'| median | 90th percentile | max ({args.draws} draws) |")
    print("|---|---|---|---|")
    for n, e in errors.items():
        print(f"| {n} | {e['median']:.2f} | {e['p90']:.2f} | {e['max']:.2f} |")
    if args.json:
        write_json(args.json, {"reference": reference, "alone": dict(zip(ids, alone.tolist())), "boxes": boxes,
                               "drives": drive_pitch, "errors": errors, "held_out": bool(args.fold_models)})


if __name__ == "__main__":
    main()
