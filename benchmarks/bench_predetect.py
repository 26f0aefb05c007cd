"""Benchmark of the part-configuration detector bank (paper Sec. 3.4 / 5.2), plain script.

1. Time per KITTI frame on one core (HOG pyramid + all templates + clustering).
2. AP (PASCAL, IoU >= 0.5, cars > 50 px high and >= 20% visible; see
   :mod:`wirescene.predetect.ap`) and viewpoint accuracy of true positives
   (a) on held-out synthetic scenes (stream ``--synth-seed``, never used for training:
       the shipped bank trains on stream 0 and picks its threshold on stream 1),
   (b) on the real KITTI frames (evaluation frames; the bank never saw real images).

Usage: python benchmarks/bench_predetect.py [--root /work/shared/data/kitti] [--synth 40]
       [--synth-seed 42] [--bank PATH] [--pr-curve pr.png] [--json out.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.ap import evaluate_detections, frame_gt, load_frame_gt, plot_pr, summary  # noqa: E402
from wirescene.predetect.bank import DetectorBank, detect_cars, load_default_bank  # noqa: E402


def _fmt(name, r, thr_r=None):
    s = (f"{name:>10}: AP {100 * r['ap']:5.1f}%  ({r['n_gt']} cars, {r['n_tp']} TP at full recall "
         f"{r['max_recall']:.2f}); viewpoint of TPs: bin {r['viewpoint_bin_acc']:.2f}, "
         f"within 45 deg {r['viewpoint_within_45']:.2f}")
    if thr_r is not None:
        p = float(thr_r["precision"][-1]) if len(thr_r["precision"]) else float("nan")
        s += f"; at bank threshold: recall {thr_r['max_recall']:.2f} precision {p:.2f}"
    return s


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default="/work/shared/data/kitti")
    ap.add_argument("--synth", type=int, default=40, help="held-out synthetic scenes")
    ap.add_argument("--synth-seed", type=int, default=42)
    ap.add_argument("--bank", default=None)
    ap.add_argument("--pr-curve", default=None)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    bank = DetectorBank.load(args.bank) if args.bank else load_default_bank()
    print(f"bank: {len(bank)} detectors, threshold {bank.threshold:.3f}, trained on {bank.meta.get('n_scenes')} "
          f"synthetic scenes (seed {bank.meta.get('seed')})")
    out, curves = {"n_detectors": len(bank)}, {}

    ds = KittiDataset(args.root)
    dets, gts, times = [], [], []
    for fid in ds.frame_ids():
        img = ds.image(fid)
        t = time.perf_counter()
        dets.append(detect_cars(img, bank=bank, return_all=True))
        times.append(time.perf_counter() - t)
        gts.append(load_frame_gt(ds.split_dir, fid))
    real = evaluate_detections(dets, gts)
    real_thr = evaluate_detections([d.subset(d.scores > bank.threshold) for d in dets], gts)
    print(f"time per KITTI frame (1 core): {np.mean(times):.2f} s (min {np.min(times):.2f}, max {np.max(times):.2f}); "
          f"paper: ~120 s")
    out["seconds_per_frame"] = float(np.mean(times))
    out["kitti"] = summary(real)
    curves[f"KITTI ({len(dets)} frames)"] = real

    if args.synth:
        from wirescene.synth.generate import default_camera, generate_scene, load_car_library

        cam, lib = default_camera(), load_car_library()
        sd, sg = [], []
        for i in range(args.synth):
            sc = generate_scene(args.synth_seed, i, camera=cam, library=lib)
            sd.append(detect_cars(sc.image, bank=bank, return_all=True))
            sg.append(frame_gt(sc.labels, wireframes=sc.wireframes))
        syn = evaluate_detections(sd, sg)
        syn_thr = evaluate_detections([d.subset(d.scores > bank.threshold) for d in sd], sg)
        print(_fmt("synthetic", syn, syn_thr) + f"  [{args.synth} scenes, seed {args.synth_seed}]")
        out["synthetic"] = summary(syn) | {"n_scenes": args.synth, "seed": args.synth_seed}
        curves[f"synthetic ({args.synth} held-out)"] = syn
    print(_fmt("KITTI", real, real_thr) + f"  [{len(dets)} frames]")
    print("paper (118 DPMs trained on 1,150 real images, 260 KITTI test images): AP 57.8%")
    if args.pr_curve:
        print("PR curve:", plot_pr(curves, args.pr_curve))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
