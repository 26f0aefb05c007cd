"""Benchmark of the part-configuration detector bank on real KITTI frames, plain script.

Protocol: 4-fold cross-validation by recording drive (:mod:`wirescene.io.folds`):
for each fold k a bank is trained (:func:`wirescene.training.kitti_detector.train_bank_on_frames`)
on the frames of the other three folds and detects on the frames of fold k; the held-out
detections of all folds are pooled (72 frames, 294 cars) and scored. No figure is computed
on a frame the scoring model was trained on. ``--bank PATH`` instead scores one given bank
on all frames (fair only for a bank that never saw these frames).

Metrics (all on the pooled held-out detections):
* KITTI 2D AP and AOS for Car, easy / moderate / hard, R40, at IoU 0.7 and 0.5, by the
  devkit's rules (:func:`wirescene.eval.kitti_metrics.detection_ap_2d`, the project's one
  KITTI evaluation);
* the operating point at the shipped threshold and at ``--operating-points``: detections,
  the share on a car (IoU >= ``--min-iou``), the share of cars found, by box height (< 25,
  25-40, 40-60, > 60 px), and the viewpoint error of the detections on a car (> 45 deg, and
  > 135 deg: front and back swapped);
* seconds per frame on one core of :func:`wirescene.predetect.detect_cars` (whole image:
  pyramid + templates + clustering), and side by side without the verifier and of the
  pipeline's own pre-detection (:func:`wirescene.fitting.own_boxes.own_detections` at the fit's
  threshold: the bank, then the box rule's viewpoints) on the image alone and with the image
  enlarged (``--upsample``, else the pipeline's default ``predetect.upsample``), on
  ``--time-frames`` frames spread evenly over the scored ones (the first frames of a set may
  hold few cars). The detections scored are the image's alone unless ``--upsample`` is given.

Detection passes each frame's camera, so banks with a ground prior score with it
(:mod:`wirescene.predetect.geometry`; pooled scores are then each fold bank's calibrated
confidences, whose calibration left that fold out) and banks with a viewpoint prior
(:mod:`wirescene.predetect.viewpoint_prior`) choose their viewpoints with it; ``--no-ground``
scores without either.

Usage:
  python benchmarks/bench_predetect.py --root ROOT --cv [--models-dir DIR] [--pr-curve pr.png] [--json out.json]
  python benchmarks/bench_predetect.py --root ROOT --cv --fold 0 --fold 2 --models-dir DIR   # in parallel with 1, 3
  python benchmarks/bench_predetect.py --root ROOT --from-raw DIR --models-dir DIR        # then score them
  python benchmarks/bench_predetect.py --root ROOT --bank src/wirescene/data/detector_bank.npz   # a fixed bank
Training options of the CV run: --partial, --mining-rounds, --C, --no-flips, --min-bin-examples,
--per-octave, --cut-paste, --pad-cells, --whiten, --align, --share-deg, --full-area, --partial-area, --synth-root [--synth-scenes N], --support-weight W (also --from-raw; the recipe's 0.3 by default, 0 for the best vote alone); --train-fraction F [--subset-seed S] trains each fold bank on a share F
of its training drives, each with all its frames (a learning curve: held-out AP against the amount of real training
data; --subset-unit frame: a share of the frames).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import operating_point, write_saved_detections  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.eval.kitti_metrics import N_SAMPLE_PTS, detection_ap_2d  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of, frame_drives  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.ap import plot_pr  # noqa: E402
from wirescene.predetect.bank import SUPPORT_WEIGHT, DetectorBank, detect_cars, load_default_bank  # noqa: E402
from wirescene.training.kitti_detector import (  # noqa: E402
    add_verifier,
    detect_training_image,
    detection_labels,
    finish_bank,
    fit_platt,
    heldout_rows,
    kitti_gt_boxes,
    load_training_frames,
    set_calibration,
    train_bank_on_frames,
)


def with_enlarged(ds, frame: str, upsample: float, bank, *, ground: bool = True,
                  cross_view_nms: float | None = 0.3) -> Detections:
    """``bank``'s every detection of ``frame`` (with its camera's priors where ``ground``) and, with
    ``upsample`` > 1, those of the image enlarged (at its levels finer than the image's) above the fit's
    threshold that none of the image's above it covers (the image's below it that overlap one going), as
    the pipeline adds them (``predetect.upsample``: :func:`wirescene.fitting.own_boxes.own_detections`)."""
    from wirescene.fitting.own_boxes import own_detections

    every, _ = own_detections(ds.camera(frame) if ground else None, ds.image(frame), bank=bank, fit_viewpoints=True,
                              return_all=True, viewpoints=False, upsample=upsample, cross_view_nms=cross_view_nms)
    return every


def metrics(dets, labels) -> dict:
    """2D AP by the devkit's rules (:func:`wirescene.eval.kitti_metrics.detection_ap_2d`) and
    the precision curves to plot."""
    r = detection_ap_2d(dets, labels)
    recall = np.linspace(0.0, 1.0, N_SAMPLE_PTS)
    curves = {k: {"recall": recall, "precision": r["curves"][k]["moderate"],
                  "ap": (r[k]["moderate"] or 0.0) / 100} for k in ("2d", "2d_iou_0.5") if r["curves"][k]["moderate"] is not None}
    return {"2d": r["2d"], "aos": r["aos"], "2d_iou_0.5": r["2d_iou_0.5"], "n_gt": r["n_gt"], "_curves": curves}


def fmt(name, m) -> str:
    def ap(v):
        return "-" if v is None else f"{v:.1f}"

    d = ("easy", "moderate", "hard")
    return (f"{name}: 2D AP easy / moderate / hard {' / '.join(ap(m['2d'][k]) for k in d)} "
            f"({' / '.join(str(m['n_gt'][k]) for k in d)} cars); AOS {' / '.join(ap(m['aos'][k]) for k in d)}; "
            f"2D AP at IoU 0.5 {' / '.join(ap(m['2d_iou_0.5'][k]) for k in d)}")


def public(m):
    return {k: v for k, v in m.items() if not k.startswith("_")}


def fmt_operating_point(o) -> str:
    def parts(groups: dict) -> str:
        return ", ".join(f"{k} {v[0]:.2f} ({v[1]})" if v[0] is not None else f"{k} - (0)" for k, v in groups.items())

    bands = parts(o["recall_by_height"])
    return (f"at threshold {o['threshold']:g}: {o['n_detections']} detections, {o['n_on_car']} on a car at IoU "
            f"{o['iou']:g} (precision {o['precision']:.2f}); cars found {o['recall']:.2f} of {o['n_cars']} "
            f"(by height: {bands}; {parts(o['recall_by_truncation'])}; occlusion flag "
            f"{parts(o['recall_by_occlusion'])}); missed: {o['missed_without_candidate']} without any detection at IoU "
            f"{o['iou']:g} (by height, with one at IoU >= 0.3: "
            f"{', '.join(f'{k} {v[0]} ({v[1]})' for k, v in o['missed_without_candidate_by_height'].items())}), "
            f"{o['missed_below_threshold']} only below the threshold; viewpoint of the detections on a car off by > 45 deg "
            f"{o['viewpoint_over_45'] if o['viewpoint_over_45'] is None else round(o['viewpoint_over_45'], 2)}, "
            f"> 135 deg {o['viewpoint_over_135'] if o['viewpoint_over_135'] is None else round(o['viewpoint_over_135'], 2)}")


def training_subset(frames: list, fraction: float, *, seed, groups: dict | None = None) -> set:
    """A share ``fraction`` of ``frames`` (at least one), drawn without replacement with
    ``seed``; all of them at 1. With ``groups`` (``{frame: group}``, e.g. its drive) the
    share is of the groups, and a drawn group brings all its frames (frames of one drive
    share cars and streets, so a share of the frames would overstate a share of the data)."""
    if fraction >= 1:
        return set(frames)
    units = sorted({groups[f] for f in frames}) if groups is not None else list(frames)
    n = max(1, int(round(fraction * len(units))))
    rng = np.random.default_rng(list(np.atleast_1d(seed)))
    drawn = set(rng.choice(np.array(units, dtype=object), size=n, replace=False).tolist())
    return {f for f in frames if (groups[f] if groups is not None else f) in drawn}


def with_detection_options(bank: DetectorBank, args) -> DetectorBank:
    """``bank`` with the detection options given on the command line (clustering: ``--box-weight``,
    ``--cluster-rx``, ``--cluster-ry``; candidates: ``--detect-per-octave``, ``--per-detector``)
    stored in its meta, where the detector reads them."""
    for key, value in (("box_weight", args.box_weight), ("cluster_rx", args.cluster_rx), ("cluster_ry", args.cluster_ry),
                       ("per_octave", args.detect_per_octave), ("per_detector", args.per_detector)):
        if value is not None:
            bank.meta[key] = value
    return bank


def add_verifiers(args) -> None:
    """The ``--add-verifier`` mode: earlier fold banks finished with today's last step."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    ds = KittiDataset(args.root)
    for k in sorted(set(args.fold or range(N_FOLDS))):
        bank = DetectorBank.load(Path(args.add_verifier) / f"fold{k}_raw.npz")
        if bank.verifier is not None:
            print(f"--- fold {k}: its verifier is replaced", flush=True)
            bank = replace(bank, verifier=None, meta={m: v for m, v in bank.meta.items() if m != "verifier"})
        images, _ = load_training_frames(ds, [f for f in ds.frame_ids() if fold_of(f) != k])
        print(f"--- fold {k}: verifier on {len(images)} images (cars at IoU >= {args.verifier_iou:g})", flush=True)
        add_verifier(bank, images, ds, car_iou=args.verifier_iou, view_groups=args.view_groups,
                     channels=not args.grey_verifier,
                     progress=lambda m: print("   ", m, flush=True))
        bank.save(Path(args.models_dir) / f"fold{k}_raw.npz")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames (e.g. ../shared/data/kitti)")
    ap.add_argument("--bank", default=None, help="score this fixed bank on all frames instead of cross-validating")
    ap.add_argument("--cv", action="store_true", help="4-fold cross-validation by drive")
    ap.add_argument("--models-dir", default=None, help="write the fold banks here (foldK.npz, calibrated)")
    ap.add_argument("--threshold", type=float, default=0.5,
                    help="default detection threshold (confidence) stored in the saved fold banks, as the shipped bank's")
    ap.add_argument("--fold-models", default=None,
                    help="score saved fold banks DIR/fold{k}.npz (or a path pattern with {k}), each on its "
                         "held-out fold (raw margins pooled)")
    ap.add_argument("--save-dets", default=None, help="write the held-out detections to this .npz")
    ap.add_argument("--partial", type=int, default=3)
    ap.add_argument("--mining-rounds", type=int, default=3)
    ap.add_argument("--mining-images", type=int, default=None,
                    help="--cv: the most training images a mining round searches (default: all)")
    ap.add_argument("--C", type=float, default=0.01)
    ap.add_argument("--min-bin-examples", type=int, default=5)
    ap.add_argument("--no-flips", action="store_true")
    ap.add_argument("--per-octave", type=int, default=6, help="pyramid levels per octave")
    ap.add_argument("--train-seed", type=int, default=0, help="--cv: seed of the templates' training (random "
                    "negatives, the positives drawn and jittered; train_bank_on_frames seed; the recipe's 0)")
    ap.add_argument("--cut-paste", type=int, default=0,
                    help="cars pasted into a composite copy of every training frame (0: none)")
    ap.add_argument("--label-boxes", action="store_true",
                    help="labelled boxes as full-car targets of clean cars (default: placed wireframe + correction)")
    ap.add_argument("--box-weight", type=float, default=None,
                    help="override the banks' cluster box weighting (fold-models / bank modes)")
    ap.add_argument("--cross-view-nms", type=float, default=0.3,
                    help="fold-models / bank modes: IoU above which detections of different viewpoints suppress "
                         "each other (1: none)")
    ap.add_argument("--cluster-rx", type=float, default=None,
                    help="override the banks' vote-clustering radius across (and, with --cluster-ry unset, along) "
                         "the box, in box widths / heights: --cv trains the steps after the templates with it, "
                         "--from-raw fits the calibration with it, and the banks of --models-dir keep it")
    ap.add_argument("--pad-cells", type=int, help="empty HOG cells padded left and right of the image, so that "
                    "windows reach past its sides (truncated cars): --cv trains the banks with them, --fold-models "
                    "detects with them")
    ap.add_argument("--whiten", action="store_true", help="--cv: train the templates in whitened HOG "
                    "(training/whitening.py)")
    ap.add_argument("--max-truncated", type=float, default=0.15,
                    help="--cv: the largest KITTI truncation of a full-car positive")
    ap.add_argument("--cluster-ry", type=float, default=None)
    ap.add_argument("--support-weight", type=float, default=SUPPORT_WEIGHT,
                    help="--cv / --from-raw: margin added per e-fold of a cluster's votes, as the recipe sets it on "
                         "the finished bank (0: the best vote alone)")
    ap.add_argument("--align", action="store_true", help="--cv: latent placement of the positive windows "
                    "(train_bank_on_frames align)")
    ap.add_argument("--share-deg", type=float, default=0.0, help="--cv: cars within this many degrees of their "
                    "viewpoint bin's edge also train the neighbouring bin (train_bank_on_frames share_deg)")
    ap.add_argument("--synth-root", default=None, help="--cv: a `wirescene synth` root whose rendered cars join "
                    "every fold bank's positives (negatives stay real)")
    ap.add_argument("--synth-scenes", type=int, default=None, help="--synth-root: its first N scenes (default: all)")
    ap.add_argument("--full-area", type=float, default=48,
                    help="--cv: HOG cells of a full-car template (its resolution)")
    ap.add_argument("--partial-area", type=float, default=36,
                    help="--cv: HOG cells of a partial configuration's template")
    ap.add_argument("--min-height", type=float, help="--fold-models: the smallest full-car height searched, px "
                    "(default: each bank's)")
    ap.add_argument("--max-scale", type=float, help="--fold-models: the pyramid's largest upsampling (default: "
                    "each bank's)")
    ap.add_argument("--detect-per-octave", type=int, help="pyramid levels per octave at detection, stored in each "
                    "bank as the clustering options are (--cv: the steps after the templates too; default: each "
                    "bank's, the levels it was trained on)")
    ap.add_argument("--per-detector", type=int, help="windows each template keeps in a frame after its own "
                    "suppression, stored likewise (default: each bank's, 30)")
    ap.add_argument("--smallest-car", type=float, default=None,
                    help="also time the pipeline's pre-detection with predetect.smallest_car at this height (px)")
    ap.add_argument("--upsample", type=float, default=1.0,
                    help="fold-models / bank modes: also detect on each image enlarged by this factor, adding the "
                         "cars above the fit's threshold the image misses (predetect.upsample; default 1: the image "
                         "alone, the bank's own); also timed (default: the pipeline's predetect.upsample)")
    ap.add_argument("--time-frames", type=int, default=12,
                    help="frames timed, spread evenly over the scored frames (0: no timing)")
    ap.add_argument("--pr-curve", default=None)
    ap.add_argument("--no-ground", action="store_true",
                    help="score without the banks' ground prior (no camera passed; raw margins pooled)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--train-fraction", type=float, default=1.0,
                    help="--cv: train each fold bank on this share of its training drives (a learning curve; "
                         "the drives are drawn per fold with --subset-seed, each with all its frames, flips "
                         "follow their frames; --subset-unit frame: a share of the frames)")
    ap.add_argument("--subset-unit", choices=("drive", "frame"), default="drive",
                    help="--train-fraction: draw a share of the drives (default) or of the frames")
    ap.add_argument("--subset-seed", type=int, default=0)
    ap.add_argument("--fold", type=int, action="append", default=None,
                    help="--cv: train only this fold's bank (repeatable) and save it uncalibrated as "
                         "MODELS_DIR/fold{k}_raw.npz, to run the folds in parallel processes; --from-raw then scores them")
    ap.add_argument("--from-raw", default=None,
                    help="DIR of the four foldK_raw.npz of --cv --fold runs: detect, calibrate (and save with "
                         "--models-dir) and score them as --cv does")
    ap.add_argument("--operating-points", type=float, nargs="*", default=[0.05, 0.1, 0.2, 0.3],
                    help="further confidence thresholds at which to report the operating point")
    ap.add_argument("--min-iou", type=float, default=0.5, help="overlap at which the operating point counts a car found")
    ap.add_argument("--add-verifier", default=None, metavar="DIR",
                    help="fit the verifier (the last step of the bank training) to the foldK_raw.npz of DIR (replacing "
                         "one they have), on each bank's own training frames, and save them to --models-dir (the "
                         "--fold folds, default all); the same banks a --cv --fold run of today's recipe writes")
    ap.add_argument("--grey-verifier", action="store_true",
                    help="--add-verifier: a verifier of the HOG cells and geometry alone, without the colour channels "
                         "(the verifier of banks before December 2026)")
    ap.add_argument("--view-groups", action="store_true",
                    help="--add-verifier: one verifier regression per viewpoint group (side, diagonal, front or "
                         "back) instead of one for all (a study, not adopted)")
    ap.add_argument("--verifier-iou", type=float, default=0.5,
                    help="--add-verifier: IoU with a Car label at which the verifier's training boxes count as cars")
    args = ap.parse_args()
    if args.add_verifier:
        if not args.models_dir:
            ap.error("--add-verifier needs --models-dir")
        return add_verifiers(args)
    if args.fold and not (args.cv and args.models_dir):
        ap.error("--fold needs --cv and --models-dir")
    if not 0 < args.train_fraction <= 1:
        ap.error("--train-fraction must be in (0, 1]")
    if args.upsample != 1.0 and (args.cv or args.from_raw):
        ap.error("--upsample: the --fold-models and --bank modes only")
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    ds = KittiDataset(args.root)
    ids = ds.frame_ids()
    gts = {f: ds.labels(f) for f in ids}
    out, times = {"frames": len(ids)}, []
    dets = {}
    fold_banks = {}
    if args.from_raw:
        # the fold banks of earlier --cv --fold runs: detect on each one's held-out frames
        t0 = time.time()
        images, _ = load_training_frames(ds, ids, flips=False)
        for k in range(N_FOLDS):
            fold_banks[k] = with_detection_options(DetectorBank.load(Path(args.from_raw) / f"fold{k}_raw.npz"), args)
            fold_banks[k].meta["support_weight"] = args.support_weight  # as the recipe sets it on the finished bank
        for im in images:
            dets[im.frame] = detect_training_image(fold_banks[fold_of(im.frame)], im)
        out["cv_seconds"] = round(time.time() - t0, 1)
    if args.cv:
        t0 = time.time()
        train_folds = sorted(set(args.fold)) if args.fold else list(range(N_FOLDS))
        # a --fold run loads only the frames its banks train on (memory), and the others to score
        need = ids if not args.fold else [f for f in ids if any(fold_of(f) != k for k in train_folds)]
        images, examples = load_training_frames(ds, need, flips=not args.no_flips, progress=print)
        synthetic = None
        if args.synth_root:
            sds = KittiDataset(args.synth_root)
            synthetic = load_training_frames(sds, sds.frame_ids()[:args.synth_scenes], flips=not args.no_flips,
                                             progress=print)
        for k in train_folds:
            kept = training_subset(sorted({im.frame for im in images if fold_of(im.frame) != k}),
                                   args.train_fraction, seed=(args.subset_seed, k),
                                   groups=frame_drives() if args.subset_unit == "drive" else None)
            tr = [i for i, im in enumerate(images) if im.frame in kept]
            remap = {old: new for new, old in enumerate(tr)}
            ex = [replace(e, image=remap[e.image]) for e in examples if e.image in remap]
            print(f"--- fold {k}: training on {len(tr)} images, {len(ex)} car examples")
            bank = train_bank_on_frames([images[i] for i in tr], ex, n_partial=args.partial, C=args.C,
                                        mining_rounds=args.mining_rounds, min_bin_examples=args.min_bin_examples,
                                        label_boxes=args.label_boxes, per_octave=args.per_octave,
                                        cut_paste=args.cut_paste, pad_cells=args.pad_cells or 0,
                                        max_truncated=args.max_truncated, whiten=args.whiten, align=args.align,
                                        share_deg=args.share_deg, mining_images=args.mining_images,
                                        synthetic=synthetic,
                                        full_area=args.full_area, partial_area=args.partial_area, seed=args.train_seed,
                                        progress=lambda m: print("   ", m, flush=True))
            train_images = [images[i] for i in tr]
            with_detection_options(bank, args)  # the steps after the templates detect with it
            finish_bank(bank, train_images, ds, support_weight=args.support_weight,
                        progress=lambda m: print("   ", m, flush=True))
            if args.fold:
                bank.save(Path(args.models_dir) / f"fold{k}_raw.npz")
                print(f"    saved {Path(args.models_dir) / f'fold{k}_raw.npz'}", flush=True)
                continue
            fold_banks[k] = bank
            for im in images:
                if fold_of(im.frame) == k and not im.flipped:
                    dets[im.frame] = detect_training_image(bank, im)
            print(f"    fold {k} held out: " + fmt("", metrics([dets[f] for f in ids if fold_of(f) == k],
                                                             [gts[f] for f in ids if fold_of(f) == k])).strip(),
                  flush=True)
        if args.fold:
            return
        out["cv_seconds"] = round(time.time() - t0, 1)
        out["train_fraction"] = args.train_fraction
        out["train_subset"] = {"unit": args.subset_unit, "seed": args.subset_seed}
    if args.cv or args.from_raw:
        # Platt calibration of each fold bank from the OTHER folds' held-out detections, with
        # their ground-prior log ratios as offsets (the ground term's weight rests on it, so
        # no fold's calibration sees that fold's frames)
        # (with verifiers: (a, b, c), c the weight of each detection's verifier logit)
        rows = {im.frame: heldout_rows(fold_banks[fold_of(im.frame)], im, dets[im.frame], ds)
                for im in images if not im.flipped}
        verified = all(b.verifier is not None for b in fold_banks.values())

        def platt(frames):
            s, y, off, logits = (np.concatenate(col) for col in zip(*(rows[f] for f in frames)))
            return fit_platt(s, y, offset=off, verifier=logits if verified else None)

        for k, bank in fold_banks.items():
            set_calibration(bank, platt([f for f in ids if fold_of(f) != k]))
            bank.threshold = args.threshold
            if args.models_dir:
                bank.save(Path(args.models_dir) / f"fold{k}.npz")
        allc = platt(ids)
        out["pooled_platt"] = allc.tolist()
        print(f"Platt calibration of the pooled held-out detections ({'a, b, c' if verified else 'a, b'}):",
              allc.tolist())
        if not args.no_ground:
            # final held-out detections: calibrated confidences with the ground term
            for im in images:
                if not im.flipped:
                    bank = fold_banks[fold_of(im.frame)]
                    d = detect_training_image(bank, im, horizon=im.horizon, center_column=im.center_column)
                    dets[im.frame] = Detections(d.boxes, bank.confidence(d.scores), d.alpha, d.source)
        time_bank = fold_banks[0]
        name = "cross-validated real-data bank"
    elif args.cv:
        pass
    elif args.fold_models:
        pattern = args.fold_models if "{k}" in args.fold_models else str(Path(args.fold_models) / "fold{k}.npz")
        banks = {k: DetectorBank.load(pattern.format(k=k)) for k in range(N_FOLDS)}
        ground = not args.no_ground and all(b.meta.get("ground_prior") for b in banks.values())
        if args.upsample != 1.0 and not ground:  # raw margins: no common scale with the fit's threshold
            ap.error("--upsample: the fold banks' calibrated scores are needed (a ground prior, no --no-ground)")
        for b in banks.values():
            if not ground:
                b.calibration = None  # pool raw margins (monotone per fold)
            with_detection_options(b, args)
            if args.pad_cells is not None:
                b.meta["pad_cells"] = args.pad_cells
            if args.min_height is not None:
                b.meta["min_height"] = args.min_height
            if args.max_scale is not None:
                b.meta["max_scale"] = args.max_scale
        for f in ids:
            # with the ground term the scores are each fold bank's calibrated confidences
            held = banks[fold_of(f)]
            dets[f] = with_enlarged(ds, f, args.upsample, held, ground=ground, cross_view_nms=args.cross_view_nms)
        time_bank = banks[0]
        name = f"fold banks {args.fold_models}"
        if not ground:
            ys = {f: detection_labels(dets[f].boxes, kitti_gt_boxes(ds.labels(f))) for f in ids}
            allc = fit_platt(np.concatenate([dets[f].scores for f in ids]), np.concatenate([ys[f] for f in ids]))
            out["pooled_platt"] = allc.tolist()
            print("Platt calibration of the pooled held-out detections (a, b):", allc.tolist())
    else:
        bank = with_detection_options(DetectorBank.load(args.bank) if args.bank else load_default_bank(), args)
        if args.upsample != 1.0 and bank.calibration is None:  # raw margins: no common scale with the fit's threshold
            ap.error("--upsample: the bank's calibrated scores are needed")
        for f in ids:
            dets[f] = with_enlarged(ds, f, args.upsample, bank, ground=not args.no_ground)
        time_bank = bank
        name = f"fixed bank {args.bank or 'shipped'}"
    if args.save_dets:
        write_saved_detections(args.save_dets, {f: dets[f] for f in ids})
    per_fold = {}
    for k in range(N_FOLDS):
        fk = [f for f in ids if fold_of(f) == k]
        if not fk:
            continue
        m = metrics([dets[f] for f in fk], [gts[f] for f in fk])
        per_fold[k] = public(m)
        print(fmt(f"fold {k} ({len(fk)} frames)", m))
    per_group = {}
    for group in FOLD_GROUPS:  # a setting is chosen on one group and reported on the other
        fg = [f for f in ids if fold_of(f) in group]
        if fg:
            per_group[str(group)] = public(m := metrics([dets[f] for f in fg], [gts[f] for f in fg]))
            print(fmt(f"folds {group} ({len(fg)} frames)", m))
    pooled = metrics([dets[f] for f in ids], [gts[f] for f in ids])
    print(fmt(f"POOLED {name} ({len(ids)} frames)", pooled))
    calibrated = args.bank is not None or not args.no_ground
    if calibrated:
        thresholds = sorted({args.threshold, *args.operating_points})
        pooled["operating_points"] = [operating_point([dets[f] for f in ids], [ds.labels(f) for f in ids], t,
                                                      iou=args.min_iou) for t in thresholds]
        for o in pooled["operating_points"]:
            print("   ", fmt_operating_point(o))
    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.own_boxes import own_detections

    cpu, plain, own, small, enlarged = [], [], [], [], []
    unverified = replace(time_bank, verifier=None)
    fit_threshold = PredetectOptions().threshold
    # the enlargement timed beside the image alone: --upsample's, else the pipeline's default
    timed_upsample = args.upsample if args.upsample != 1.0 else PredetectOptions().upsample
    timed = list(dict.fromkeys(ids[i] for i in np.linspace(0, len(ids) - 1, args.time_frames).round().astype(int)))
    for f in timed:  # side by side, frame by frame: load falls on all three alike
        img = ds.image(f)
        use_ground = not args.no_ground and time_bank.calibration is not None and time_bank.meta.get("ground_prior")
        camera = ds.camera(f) if use_ground else None
        t, c = time.perf_counter(), time.process_time()
        detect_cars(img, bank=time_bank, return_all=True, camera=camera)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
        c = time.process_time()
        detect_cars(img, bank=unverified, return_all=True, camera=camera)
        plain.append(time.process_time() - c)
        c = time.process_time()
        # the image alone, the box rule's viewpoints
        own_detections(camera, img, bank=time_bank, threshold=fit_threshold)
        own.append(time.process_time() - c)
        if args.smallest_car:
            c = time.process_time()
            own_detections(camera, img, bank=time_bank, threshold=fit_threshold, smallest_car=args.smallest_car)
            small.append(time.process_time() - c)
        if timed_upsample != 1.0:
            c = time.process_time()
            own_detections(camera, img, bank=time_bank, threshold=fit_threshold, upsample=timed_upsample)
            enlarged.append(time.process_time() - c)
    # CPU time of this single-threaded process = seconds on one free core (wall time grows
    # with whatever else shares the machine)
    if times:  # (--time-frames 0: no timing)
        print(f"time per frame (detect_cars, 1 thread, {len(times)} frames): CPU {np.mean(cpu):.2f} s (max "
              f"{np.max(cpu):.2f}), wall {np.mean(times):.2f} s (load average {os.getloadavg()[0]:.1f}); side by side: "
              f"without the verifier {np.mean(plain):.2f} s, the pipeline's own pre-detection on the image alone "
              f"(fitting.own_boxes.own_detections at the fit's threshold {fit_threshold}, shipped viewpoint "
              f"classifier, upsample 1) {np.mean(own):.2f} s (max {np.max(own):.2f})")
        if small:
            print(f"  the same searching cars down to {args.smallest_car:g} px (predetect.smallest_car): "
                  f"{np.mean(small):.2f} s (max {np.max(small):.2f}), {np.mean(small) / np.mean(own):.2f}x")
        if enlarged:
            which = "the pipeline's default" if timed_upsample == PredetectOptions().upsample else "not the default"
            print(f"  the same with the image enlarged {timed_upsample:g}x too (predetect.upsample, {which}): "
                  f"{np.mean(enlarged):.2f} s (max {np.max(enlarged):.2f}), {np.mean(enlarged) / np.mean(own):.2f}x")
        out.update(seconds_per_frame=float(np.mean(times)), cpu_seconds_per_frame=float(np.mean(cpu)))
    out.update(pooled=public(pooled), per_fold=per_fold, per_group=per_group)
    if args.pr_curve:
        c = pooled["_curves"]
        print("PR curve:", plot_pr({"moderate, IoU 0.7": c["2d"], "moderate, IoU 0.5": c["2d_iou_0.5"]},
                                   args.pr_curve, title=f"{name} ({len(ids)} frames)"))
    if args.json:
        write_json(args.json, out)


if __name__ == "__main__":
    main()
