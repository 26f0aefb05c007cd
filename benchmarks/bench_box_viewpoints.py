"""A viewpoint for boxes given without one (issue 27, item 2), held out by drive.

Every labelled Car of every frame of ``--root`` is given to each method as its label box
without a viewpoint -- and as a copy whose four sides are moved by Gaussian noise of 5% of
the box's width / height (seeded per frame id), as a good external detector's would be -- with
the models of the frame's fold (:mod:`wirescene.io.folds`), trained without its drives:

* ``bank``: :func:`wirescene.predetect.box_viewpoints.box_bin_log_odds` of the fold bank
  (``--fold-models DIR/fold{k}.npz``) plus ``--prior-weight`` times the camera's road prior
  (:func:`~wirescene.predetect.box_viewpoints.box_log_prior`), what
  :func:`wirescene.fitting.pipeline.fit_frame` does for boxes without a viewpoint;
* ``bank-templates``: the same without the prior; ``prior``: the prior alone;
* ``bank+classifier``: ``bank`` plus the log-probabilities of a crop viewpoint classifier
  (:mod:`wirescene.predetect.viewpoint_classifier`) trained here for each fold on the other
  folds' frames; ``classifier`` alone and ``classifier+prior``;
* ``bank+classifier+rows``: its bins chosen for all boxes of a frame at once, cars in one row
  agreeing (:func:`~wirescene.predetect.box_viewpoints.row_coherent_bins`, ``--row-weight``,
  ``--row-width``) -- the pipeline's default;
* ``evidence``: :func:`wirescene.infer.evidence.viewpoint_from_evidence` with the fold's part
  model (``--parts-models DIR/parts_fold{k}.npz``; skipped without it);
* ``bank+classifier+evidence*W``: the pipeline's per-bin scores plus ``W`` times the
  evidence's per-bin score (``--evidence-weights``);
* ``own``: with ``--own``, the fold bank's own detections (:func:`wirescene.predetect.detect_cars`
  at its threshold or ``--own-threshold``, with the camera) matched to the cars at IoU >= 0.5, for reference: the
  viewpoint of the matched detection, over the cars found only; and ``own/pipeline``, the
  pipeline's rule applied to every detection of the frame (as
  :func:`wirescene.fitting.own_boxes.own_detections` does), read on the matched ones
  (``own/pipeline-rowless``: each box alone).

Reported per method and box set: the share of cars whose ``|alpha_est - alpha_true|``
(wrapped) is <= 45 deg -- the paper's criterion -- overall, by fold group
(:data:`~wirescene.io.folds.FOLD_GROUPS`), by occlusion flag and by box height band, and the
share of front/back swaps (> 135 deg), with numbers of cars. Each image's feature pyramid,
template responses and part evidence are computed once per frame for all boxes.

    python benchmarks/bench_box_viewpoints.py --root KITTI_ROOT --fold-models BANKS \\
        [--parts-models PARTS] [--folds 0 1] [--own [--own-threshold 0.3]] \\
        [--row-weight 2 0 1] [--row-width 3 1.5] [--json out.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _common import HEIGHT_BANDS, jitter_rng, jittered  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.boxes import MEAN_CAR_DIMS, iou_2d  # noqa: E402
from wirescene.core.jsonio import write_json  # noqa: E402
from wirescene.core.shape import load_default as load_shape_model  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.core.viewpoints import N_BINS, angle_difference, bin_center  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.bank import DetectorBank, detect_pyramid  # noqa: E402
from wirescene.predetect.box_viewpoints import (  # noqa: E402
    FLOOR_MARGIN,  # noqa: E402
    IOU,
    PRIOR_WEIGHT,
    ROAD_SPREAD,
    ROW_WEIGHT,
    ROW_WIDTH,
    box_bin_log_odds,
    box_log_prior,
    box_viewpoints,
    row_coherent_bins,
)
from wirescene.predetect.channels import integral_channels  # noqa: E402
from wirescene.predetect.geometry import horizon_row  # noqa: E402
from wirescene.predetect.hog import feature_pyramid, pyramid_scales, to_gray  # noqa: E402
from wirescene.predetect.viewpoint_classifier import train_on_kitti  # noqa: E402

GOOD, SWAP = np.radians(45.0), np.radians(135.0)


def evidence_bin_scores(camera, boxes, evidence, shape_model) -> np.ndarray:
    """``(N, 8)`` per-bin part-evidence score of ``boxes`` (evidence object ``i`` = box ``i``):
    the quantity :func:`wirescene.infer.evidence.viewpoint_from_evidence` maximises (its
    argmax is checked against it in :func:`main`)."""
    from wirescene.infer.likelihood import instantiate_wireframes, wireframe_likelihood
    from wirescene.lift import LiftingOptions, solve_positions

    n = len(boxes)
    alpha = bin_center(np.arange(N_BINS))[None, :]
    dims = np.broadcast_to(MEAN_CAR_DIMS, (n, N_BINS, 3))
    opts = LiftingOptions()
    x, z, az, _ = solve_positions(camera, boxes[:, None, :], alpha, 0.0, 0.0, dims, height=opts.camera_height,
                                  iterations=opts.iterations)
    batch = instantiate_wireframes(camera, shape_model, x=x, z=z, azimuth=az, pitch=np.zeros_like(x),
                                   roll=np.zeros_like(x), shape=np.zeros(x.shape + (1,)), height=opts.camera_height)
    return wireframe_likelihood(batch, evidence, np.broadcast_to(np.arange(n)[:, None], x.shape), c=0.0)


def summary(err: np.ndarray, rec: dict, sel: np.ndarray | None = None) -> dict:
    """Share within 45 deg and of swaps (> 135 deg) of the errors ``err`` (radians; NaN: no
    estimate, counted as missing), overall and by the groups of ``rec``."""
    def one(mask):
        e = err[mask]
        e = e[np.isfinite(e)]
        return {"n": int(len(e)), "within45": float(np.mean(e <= GOOD)) if len(e) else float("nan"),
                "swaps": float(np.mean(e > SWAP)) if len(e) else float("nan")}

    base = np.ones(len(err), bool) if sel is None else sel
    out = {"all": one(base)}
    for g in FOLD_GROUPS:
        out[f"folds{''.join(map(str, g))}"] = one(base & np.isin(rec["fold"], g))
    for o in range(4):
        out[f"occ{o}"] = one(base & (rec["occluded"] == o))
    for lo, hi in zip(HEIGHT_BANDS[:-1], HEIGHT_BANDS[1:]):
        out[f"h{lo:g}-{f'{hi:g}' if np.isfinite(hi) else ''}"] = one(base & (rec["height"] >= lo) & (rec["height"] < hi))
    return out


def fmt(name: str, s: dict) -> str:
    def cell(d):
        return f"{100 * d['within45']:5.1f}% ({d['n']:3d})" if d["n"] else "    -   (  0)"

    cols = ["all"] + [k for k in s if k.startswith("folds")] + [k for k in s if k.startswith("occ")] + \
        [k for k in s if k.startswith("h")]
    return f"{name:26s} " + " ".join(f"{k}={cell(s[k])}" for k in cols) + \
        f" swaps={100 * s['all']['swaps']:.1f}%"


def floored(log_odds: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """The templates' log-odds raised to each box's ``floor`` (the log-odds of the floor margin)."""
    return np.maximum(log_odds, floor[:, None])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames")
    ap.add_argument("--fold-models", required=True, help="DIR with fold{k}.npz: bank k trained without fold k")
    ap.add_argument("--parts-models", default=None, help="DIR with parts_fold{k}.npz, for the evidence methods")
    ap.add_argument("--folds", type=int, nargs="*", default=list(range(N_FOLDS)), help="score only these folds")
    ap.add_argument("--iou", type=float, nargs="+", default=[IOU],
                    help="overlaps of a window's vote with the box (the first: the main table; others: the grid)")
    ap.add_argument("--floor-margin", type=float, nargs="+", default=[FLOOR_MARGIN],
                    help="floor margins (the first: the main table)")
    ap.add_argument("--prior-weight", type=float, nargs="+", default=[PRIOR_WEIGHT],
                    help="weights of the log prior (the first: the main table)")
    ap.add_argument("--road-spread", type=float, nargs="+", default=[-1.0 if ROAD_SPREAD is None else ROAD_SPREAD],
                    help="widths of the road-aligned prior's kernel, radians; a negative one: the traffic prior "
                         "alone (the first: the main table)")
    ap.add_argument("--row-weight", type=float, nargs="+", default=[ROW_WEIGHT],
                    help="weights of the rows' agreement (the first: the main table; 0: each box alone)")
    ap.add_argument("--row-width", type=float, nargs="+", default=[ROW_WIDTH],
                    help="lateral widths of a row, metres (the first: the main table)")
    ap.add_argument("--classifier-weight", type=float, nargs="+", default=[1.0],
                    help="weights of the crop classifier's log-probabilities in the grid (the pipeline's: 1)")
    ap.add_argument("--evidence-weights", type=float, nargs="*", default=[0.1, 0.3, 1.0])
    ap.add_argument("--no-classifier", action="store_true",
                    help="skip the crop viewpoint classifiers (trained here, per fold, on the other folds' frames)")
    ap.add_argument("--own", action="store_true", help="also our own detections' viewpoints (reference)")
    ap.add_argument("--own-threshold", type=float, default=None,
                    help="--own: the banks' detection threshold (default: each bank's own; the fit takes 0.3)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the box jitter")
    ap.add_argument("--json", default=None)
    ap.add_argument("--save", default=None, help="write the per-car, per-bin scores to this .npz")
    args = ap.parse_args()
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    ds = KittiDataset(args.root)
    banks = {k: DetectorBank.load(Path(args.fold_models) / f"fold{k}.npz") for k in args.folds}
    known = {}
    for f in ds.frame_ids():
        try:
            known[f] = fold_of(f)
        except KeyError:
            print(f"skipping frame {f}: unknown drive")
    parts = {}
    if args.parts_models:
        from wirescene.parts.detector import PartDetector

        parts = {k: PartDetector.load(Path(args.parts_models) / f"parts_fold{k}.npz") for k in args.folds}
    shape_model = load_shape_model()
    classifiers = {}
    if not args.no_classifier:
        for k in args.folds:
            t0 = time.time()
            train = [f for f in ds.frame_ids() if f in known and known[f] != k]
            classifiers[k] = train_on_kitti(ds, train)
            print(f"viewpoint classifier of fold {k}: {classifiers[k].meta['n']} examples from {len(train)} frames "
                  f"[{time.time() - t0:.0f} s]", flush=True)
    frames = []
    frames = [(f, k) for f, k in known.items() if k in banks]
    sets = ("label", "jittered")
    rec = {k: [] for k in ("fold", "occluded", "height", "alpha", "frame")}
    set_boxes, cameras = {s: [] for s in sets}, []
    spreads = [None if r < 0 else r for r in args.road_spread]
    keys = [f"templates@{u:g}" for u in args.iou] + [f"floor@{m:g}" for m in args.floor_margin] + \
        [f"prior@{r}" for r in spreads] + ["evidence", "classifier"]
    scores = {s: {key: [] for key in keys} for s in sets}
    own_alpha, own_rule, own_rowless, mismatch, seconds = [], [], [], 0, []
    for f, k in frames:
        t0 = time.time()
        cars = [o for o in ds.labels(f).objects if o.type == "Car"]
        if not cars:
            continue
        image, camera, bank = ds.image(f), ds.camera(f), banks[k]
        H, W = image.shape[:2]
        label = np.array([o.box for o in cars], float)
        boxes = {"label": label, "jittered": jittered(label, (W, H), jitter_rng(args.seed, f))}
        both = np.concatenate([boxes[s] for s in sets])
        pyr = feature_pyramid(image, pyramid_scales(W, H, max_scale=float(bank.meta.get("max_scale", 2.0)),
                                                    per_octave=int(bank.meta.get("per_octave", 4))))
        # unfloored log-odds (-inf: no window); a floor applies after (calibration is increasing)
        got = {f"templates@{u:g}": box_bin_log_odds(bank, image, both, pyramid=pyr, iou=u, floor_margin=-np.inf)
               for u in args.iou}
        a, c = (1.0, 0.0) if bank.calibration is None else (float(v) for v in bank.calibration)
        got.update({f"floor@{m:g}": np.full(len(both), a * m + c) for m in args.floor_margin})
        got["classifier"] = (classifiers[k].log_probs(image, both) if classifiers
                             else np.zeros((len(both), N_BINS)))
        for r in spreads:
            prior = box_log_prior(bank, both, camera, road_spread=r)
            got[f"prior@{r}"] = np.zeros((len(both), N_BINS)) if prior is None else prior
        if parts:
            from wirescene.infer.evidence import part_evidence, viewpoint_from_evidence

            dets = Detections(both, np.ones(len(both)), np.full(len(both), np.nan), "labels")
            ev = part_evidence(image, dets, detector=parts[k])
            got["evidence"] = evidence_bin_scores(camera, both, ev, shape_model)
            ref = viewpoint_from_evidence(camera, dets, ev, shape_model).alpha
            mismatch += int(np.sum(angle_difference(ref, bin_center(np.argmax(got["evidence"], 1))) > 1e-6))
        else:
            got["evidence"] = np.full((len(both), N_BINS), np.nan)
        n = len(label)
        for i, s in enumerate(sets):
            for key in keys:
                scores[s][key].append(got[key][i * n:(i + 1) * n])
        rec["fold"] += [k] * n
        rec["occluded"] += [o.occluded for o in cars]
        rec["height"] += list(label[:, 3] - label[:, 1])
        rec["alpha"] += [o.alpha for o in cars]
        rec["frame"] += [len(cameras)] * n
        cameras.append(camera)
        for s in sets:
            set_boxes[s].append(boxes[s])
        if args.own:
            # what detect_cars does with the camera, on the pyramid already computed
            d = detect_pyramid(bank, pyr, (W, H), threshold=bank.threshold if args.own_threshold is None
                               else args.own_threshold,
                               min_height=float(bank.meta.get("min_height", 30.0)), horizon=horizon_row(camera),
                               center_column=float(camera.K[0, 2]),
                               gray=None if bank.refinement is None and bank.verifier is None else to_gray(image),
                               channels=integral_channels(image) if bank.needs_channels else None)
            ov = iou_2d(label[:, None], d.boxes[None]) if len(d) else np.zeros((n, 0))
            match = [int(np.argmax(ov[i])) if ov.shape[1] and ov[i].max() >= 0.5 else -1 for i in range(n)]
            own_alpha += [d.alpha[j] if j >= 0 else np.nan for j in match]
            # the pipeline's rule for boxes without a viewpoint, given every detection of the frame (as
            # own_detections), read on the matched ones; with and without the rows
            found = [i for i, j in enumerate(match) if j >= 0]
            for weight, out_list in ((args.row_weight[0], own_rule), (0.0, own_rowless)):
                rule = np.full(n, np.nan)
                if len(d):
                    rule[found] = box_viewpoints(
                        bank, image, d.boxes, camera=camera, classifier=classifiers.get(k), iou=args.iou[0],
                        floor_margin=args.floor_margin[0], prior_weight=args.prior_weight[0],
                        road_spread=spreads[0], pyramid=pyr, row_weight=weight)[[match[i] for i in found]]
                out_list += list(rule)
        seconds.append(time.time() - t0)
        print(f"frame {f} fold {k}: {n} cars, {seconds[-1]:.1f} s", flush=True)
    rec = {key: np.asarray(v) for key, v in rec.items()}
    scores = {s: {key: np.concatenate(v) for key, v in scores[s].items()} for s in sets}
    set_boxes = {s: np.concatenate(v) if v else np.zeros((0, 4)) for s, v in set_boxes.items()}

    def rows(m: np.ndarray, s: str, weight: float, width: float) -> np.ndarray:
        """Per-bin scores ``m`` of box set ``s`` made one-hot at each frame's row-coherent bins."""
        best = np.argmax(m, 1)
        if weight:
            for fi, camera in enumerate(cameras):
                sel = np.flatnonzero(rec["frame"] == fi)
                best[sel] = row_coherent_bins(m[sel], set_boxes[s][sel], camera, weight=weight, width=width)
        return np.eye(N_BINS)[best]
    if args.own:
        rec["own_alpha"] = np.asarray(own_alpha)
    if args.save:
        np.savez(args.save, **{f"rec_{key}": v for key, v in rec.items()},
                 **{f"{s}_{key}": v for s in sets for key, v in scores[s].items()})
    if parts:
        print(f"evidence argmax differs from viewpoint_from_evidence on {mismatch} boxes (expected 0)")
    out = {"frames": len(seconds), "cars": int(len(rec["alpha"])), "iou": args.iou[0],
           "floor_margin": args.floor_margin[0], "road_spread": spreads[0], "prior_weight": args.prior_weight[0],
           "seconds_per_frame": float(np.mean(seconds)) if seconds else 0.0,
           "methods": {}, "grid": {}}
    print(f"{out['frames']} frames, {out['cars']} cars, {out['seconds_per_frame']:.1f} s per frame; "
          f"cells: share within 45 deg (cars); bank: IoU {args.iou[0]:g}, floor margin {args.floor_margin[0]:g}, "
          f"road spread {spreads[0]}, prior weight {args.prior_weight[0]:g}")

    def share(m):
        return summary(angle_difference(bin_center(np.argmax(m, 1)), rec["alpha"]), rec)

    for s in sets:
        sc = scores[s]
        templ = floored(sc[f"templates@{args.iou[0]:g}"], sc[f"floor@{args.floor_margin[0]:g}"])
        prior = sc[f"prior@{spreads[0]}"]
        bank_scores = templ + args.prior_weight[0] * prior
        methods = {"bank": bank_scores, "bank-templates": templ, "prior": prior}
        if classifiers:
            methods.update({"bank+classifier": bank_scores + sc["classifier"], "classifier": sc["classifier"],
                            "classifier+prior": sc["classifier"] + args.prior_weight[0] * prior})
            bank_scores = methods["bank+classifier"]
        methods[f"{'bank+classifier' if classifiers else 'bank'}+rows"] = \
            rows(bank_scores, s, args.row_weight[0], args.row_width[0])  # the pipeline's
        if parts:
            methods["evidence"] = sc["evidence"]
            for w in args.evidence_weights:
                methods[f"{'bank+classifier' if classifiers else 'bank'}+evidence*{w:g}"] = \
                    bank_scores + w * sc["evidence"]
        if s == "label":
            pipeline_scores = methods[f"{'bank+classifier' if classifiers else 'bank'}+rows"]
        print(f"--- {s} boxes")
        for name, m in methods.items():
            out["methods"][f"{s}/{name}"] = share(m)
            print(fmt(name, out["methods"][f"{s}/{name}"]))
    grid = [(u, m, r, w, c, rw, rs) for u in args.iou for m in args.floor_margin for r in spreads
            for w in args.prior_weight for c in (dict.fromkeys([*args.classifier_weight, 0.0]) if classifiers else (0.0,))
            for rw in args.row_weight for rs in (args.row_width if rw else args.row_width[:1])]
    if len(grid) > 1:
        print("--- grid of the bank's settings (label / jittered boxes): share within 45 deg by fold group")
        for u, m, r, w, c, rw, rs in grid:
            line = []
            for s in sets:
                sc = scores[s]
                res = share(rows(floored(sc[f"templates@{u:g}"], sc[f"floor@{m:g}"]) + w * sc[f"prior@{r}"]
                                 + c * sc["classifier"], s, rw, rs))
                name = f"iou={u:g} floor={m:g} road_spread={r} prior*{w:g} classifier*{c:g} rows={rw:g}@{rs:g}m"
                out["grid"][f"{s}/{name}"] = res
                line.append(" ".join(f"{g}={100 * res[g]['within45']:5.1f}% ({res[g]['n']:3d})"
                                     for g in res if g.startswith("folds") and res[g]["n"]))
            print(f"{name}:  " + "  |  ".join(line))
    if args.own:
        err = angle_difference(np.asarray(own_alpha), rec["alpha"])
        out["methods"]["own"] = summary(err, rec)
        out["methods"]["own"]["found"] = int(np.isfinite(err).sum())
        print("--- our own detections, cars found at IoU >= 0.5; the pipeline's method on the same cars' label boxes")
        print(fmt("own", out["methods"]["own"]))
        found = np.isfinite(err)
        ours = angle_difference(bin_center(np.argmax(pipeline_scores, 1)), rec["alpha"])
        out["methods"]["label/pipeline-on-found"] = summary(np.where(found, ours, np.nan), rec)
        print(fmt("pipeline on found", out["methods"]["label/pipeline-on-found"]))
        out["methods"]["own/pipeline"] = summary(angle_difference(np.asarray(own_rule), rec["alpha"]), rec)
        print(fmt("pipeline on own boxes", out["methods"]["own/pipeline"]))
        out["methods"]["own/pipeline-rowless"] = summary(angle_difference(np.asarray(own_rowless), rec["alpha"]), rec)
        print(fmt("each own box alone", out["methods"]["own/pipeline-rowless"]))
    if args.json:
        write_json(args.json, out)


if __name__ == "__main__":
    main()
