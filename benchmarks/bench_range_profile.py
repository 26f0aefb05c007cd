"""The fine objective along each car's viewing ray: which term puts the car at the wrong range?

Range along the viewing ray decides both the 1 m test and KITTI's IoU 0.7
(``bench_error_budget.py``), and the fit's objective ranks its own fits no better than a coin
(``bench_restarts.py``). This refits the frames with label boxes (each with the part model
of its fold, held out by drive) and, for every fitted car, slides it along the ground plane
towards and away from the camera (everything else of the scene as fitted) and evaluates the
fine objective's terms there:

* ``own parts``: the car's part likelihood (paper Eq. 2, with its occlusion as the variant
  derives it: the image border, the searched occluder of the fit, the other cars);
* ``box``: the car's box penalty against its 2D box;
* ``other cars``: the other cars' part likelihoods (the slid car may hide their parts);
* ``total``: the objective of the scene (lower is better), the sum of the three (the shape,
  size and road priors do not change as the car slides);
* ``box bottom`` and ``box sides, top``: the box penalty of the bottom side alone (the ground
  contact: range from the plane) and of the other three (range from the car's image size).

For each term, the range error the car would have at that term's minimum along the ray (a
term that does not change along it is left at the fit and counted as flat), and for the total, how much worse the objective finds the labelled range than the fitted one.
Reported by fold group, with the cars counted.

    python benchmarks/bench_range_profile.py --root KITTI --models DIR [--variant full] [--seed 1] [--workers 2]
        [--frames 000010,...] [--json OUT] [--rows OUT.npz]

DIR holds ``parts_fold{k}.npz`` (the README's fold part models).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np

from wirescene.core.camera import NEAR_PLANE
from wirescene.core.jsonio import write_json
from wirescene.core.wireframe import FACES
from wirescene.eval.sources import frame_seed
from wirescene.fitting.models import load_shape_model
from wirescene.fitting.options import FitOptions
from wirescene.fitting.pipeline import fit_frame
from wirescene.fitting.variants import VARIANTS
from wirescene.infer.inference import BOX_ROBUST
from wirescene.infer.likelihood import object_likelihood, outside_image
from wirescene.infer.masks import mask_hidden
from wirescene.infer.occlusion import inter_object_occlusion, self_occlusion
from wirescene.io.detections import detections_from_labels
from wirescene.io.folds import DRIVE_FOLDS, FOLD_GROUPS, frame_drives
from wirescene.io.kitti import KittiDataset
from wirescene.lift import box_residual, project_boxes

#: The slide along the ray, as a share of the fitted car's range.
STEPS = np.linspace(-0.2, 0.2, 161)
#: The terms profiled (``total`` is the sum of the first three), and the box term split into
#: its bottom side (where the car meets the ground) and its other three sides (its image size).
TERMS = ("own parts", "box", "other cars", "total", "box bottom", "box sides, top")


def scene_profiles(camera, scene, evidence, boxes, *, variant, c: float, box_weight: float,
                   border_occludes: bool = True, steps=STEPS) -> list[dict]:
    """For each car of a fitted ``scene``, the objective's terms ``(S,)`` with that car slid
    along the ground plane by ``steps`` times its range (others as fitted), and the slide's
    direction: ``[{"range", "u" (3,), "location" (3,), TERM: (S,)}]``."""
    objs = scene.objects
    N = len(objs)
    verts = np.stack([o.vertices for o in objs])  # (N, 36, 3)
    masks = np.array([ob.occluder_mask for ob in objs]) if variant.searched_occluder else None
    # the part detectors' scale: focal length times car length over the distance of the wireframe's origin
    X_obj = load_shape_model().instantiate(np.stack([ob.shape for ob in objs]))  # (N, 36, 3)
    origins = (verts - np.einsum("nvi,nji->nvj", X_obj, np.stack([ob.R for ob in objs]))).mean(axis=1)  # (N, 3)
    length = np.ptp(X_obj[..., 0], axis=-1)
    out = []
    for j, o in enumerate(objs):
        normal = o.R[:, 1]  # the plane's normal (the object's y axis) in the camera frame
        d = o.location - camera.center
        u = d - (d @ normal) * normal
        rng_ = float(np.linalg.norm(u))
        u /= rng_
        shift = (steps * rng_)[:, None, None] * u  # (S, 1, 3)
        scene_v = np.broadcast_to(verts, (len(steps),) + verts.shape).copy()  # (S, N, 36, 3)
        scene_v[:, j] += shift
        uv, depth = camera.project_with_depth(scene_v)
        self_hidden = self_occlusion(scene_v, FACES, camera.center) | (depth <= NEAR_PLANE)
        hidden = outside_image(camera, uv) if border_occludes else np.zeros(uv.shape[:-1], bool)
        if variant.deterministic_occlusion and N > 1:
            hidden = hidden | inter_object_occlusion(scene_v, FACES, camera.center)
        if masks is not None:
            hidden = hidden | mask_hidden(uv, np.broadcast_to(masks, (len(steps), N)))
        origin = np.broadcast_to(origins, (len(steps), N, 3)).copy()
        origin[:, j] += shift[:, 0]
        scale = camera.focal * length / np.maximum(np.linalg.norm(origin - camera.center, axis=-1), 0.5)
        e = evidence.log_ratio(uv, np.broadcast_to(np.arange(N), scale.shape), scale)
        lik = object_likelihood(e, self_hidden, hidden, c=c)  # (S, N)
        Xj = (o.vertices - o.location) @ o.R
        det = np.asarray(boxes[o.detection_index], float)[None]
        loc = o.location[None] + shift[:, 0]
        # the box term's squared side residuals (box_cost is their sum), kept apart to split the term
        projected, min_depth = project_boxes(camera, Xj.min(axis=0), Xj.max(axis=0), loc, o.R[None])
        r2 = box_residual(projected, det, min_depth) ** 2

        def robust(cost):
            return box_weight * BOX_ROBUST * np.log1p(cost / BOX_ROBUST)

        prof = {"range": rng_, "u": u, "location": o.location, "own parts": -lik[:, j],
                "box": robust(np.sum(r2, axis=-1)), "other cars": -(lik.sum(axis=1) - lik[:, j])}
        prof["total"] = prof["own parts"] + prof["box"] + prof["other cars"]
        # the box's bottom side alone (where the car meets the ground) and its other three (its image size)
        prof["box bottom"] = robust(r2[:, 3])
        prof["box sides, top"] = robust(r2[:, :3].sum(axis=1))
        out.append(prof)
    return out


def frame_rows(frame: str, *, root: str, models: str, variant: str, seed: int) -> list[dict]:
    """Fit ``frame`` with label boxes and the part model of its fold; one row per true positive."""
    from wirescene.eval.metrics import evaluate
    from wirescene.eval.runner import frame_result

    ds = KittiDataset(root)
    fold = DRIVE_FOLDS[frame_drives()[frame]]
    v = VARIANTS[variant]
    options = FitOptions(seed=seed, calibrate_scores=False, parts_model=str(Path(models) / f"parts_fold{fold}.npz"))
    gt = ds.labels(frame)
    dets = detections_from_labels(gt, rng=frame_seed(seed, frame))
    camera, image = ds.camera(frame), ds.image(frame)
    fitted = fit_frame(camera, dets, [v], image=image, options=options)
    scene = fitted.estimates[v.name]
    if not scene.objects:
        return []
    profiles = scene_profiles(camera, scene, fitted.evidence, fitted.detections.boxes, variant=v,
                              c=options.inference.occluded_score, box_weight=options.inference.box_weight,
                              border_occludes=options.inference.border_occludes)
    result = frame_result(frame, gt, fitted.detections, scene, None, camera)
    rows = []
    for tp in evaluate([result]).records:
        label = result.gt[tp.gt_index]
        p = profiles[tp.det_index]
        # the fit's range error along the slide: the fitted bottom centre against the label's
        error = float((p["location"] - np.asarray(label.location, float)) @ p["u"])
        row = {"frame": frame, "fold": fold, "range": p["range"], "error": error}
        for t in TERMS:
            row[t] = p[t].tolist()
        rows.append(row)
    return rows


def summarise(rows: Sequence[dict], steps=STEPS) -> dict:
    """Per term: the range error at the term's minimum (median signed and absolute, within
    1 m); for the total, the objective at the label's range against the fit's."""
    if not rows:
        return {"cars": 0}
    rng_ = np.array([r["range"] for r in rows])
    err = np.array([r["error"] for r in rows])
    out = {"cars": len(rows), "fit": {"median error m": float(np.median(err)),
                                      "median |error| m": float(np.median(np.abs(err))),
                                      "within 1 m of range": int((np.abs(err) < 1).sum())}}
    for t in TERMS:
        prof = np.array([r[t] for r in rows])  # (cars, S)
        # a term that does not change along the ray (e.g. no other car nearby) prefers no range: left at the fit
        flat = np.ptp(prof, axis=1) < 1e-9
        at = np.where(flat, 0.0, steps[np.argmin(prof, axis=1)] * rng_)  # the slide to the term's minimum, metres
        e = err + at
        out[t] = {"median error m": float(np.median(e)), "median |error| m": float(np.median(np.abs(e))),
                  "within 1 m of range": int((np.abs(e) < 1).sum()),
                  "minimum at the fit (|slide| < 0.25 m)": int((np.abs(at) < 0.25).sum()),
                  "flat": int(flat.sum())}
    total = np.array([r["total"] for r in rows])
    # the label's range: the slide that undoes the error (inside the profiled span)
    s = -err / rng_
    inside = np.abs(s) <= steps[-1]
    at_label = np.array([np.interp(si, steps, pr) for si, pr in zip(s, total)])
    worse = at_label - total[:, len(steps) // 2]
    out["label range against the fit"] = {
        "cars inside the span": int(inside.sum()),
        "objective worse at the label's range": int((worse[inside] > 0).sum()),
        "median difference": float(np.median(worse[inside])) if inside.any() else None,
    }
    return out


def format_summary(group: str, s: dict) -> str:
    if not s.get("cars"):
        return f"-- {group}: no cars"
    lines = [f"-- {group} ({s['cars']} cars): range error at each term's minimum along the ray"]
    lines.append(f"  {'':12s} {'median':>8s} {'median |.|':>11s} {'< 1 m':>6s} {'min at fit':>11s} {'flat':>5s}")
    f = s["fit"]
    lines.append(f"  {'as fitted':12s} {f['median error m']:+8.2f} {f['median |error| m']:11.2f} "
                 f"{f['within 1 m of range']:6d}")
    for t in TERMS:
        x = s[t]
        lines.append(f"  {t:12s} {x['median error m']:+8.2f} {x['median |error| m']:11.2f} {x['within 1 m of range']:6d} "
                     f"{x['minimum at the fit (|slide| < 0.25 m)']:11d} {x['flat']:5d}")
    la = s["label range against the fit"]
    worse, inside, diff = la["objective worse at the label's range"], la["cars inside the span"], la["median difference"]
    lines.append(f"  total at the label's range worse than at the fit's: {worse} of {inside} cars (median difference "
                 f"{diff:+.4f})")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (module docstring); ``argv`` as for :meth:`argparse.ArgumentParser.parse_args`."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", required=True, help="KITTI root (training split with labels)")
    ap.add_argument("--models", required=True, help="directory of parts_fold{k}.npz")
    ap.add_argument("--variant", default="full", choices=[n for n, v in VARIANTS.items() if v.fine])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--frames", help="comma-separated frame ids (default: every labelled frame)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--rows", type=Path, help="also write every car's profiles here (.npz)")
    args = ap.parse_args(argv)
    ds = KittiDataset(args.root)
    frames = args.frames.split(",") if args.frames else ds.frame_ids()
    drive_of = frame_drives()
    missing = [f for f in frames if f not in drive_of]
    if missing:
        ap.error(f"frame {missing[0]} has no drive in wirescene's drive map")
    for k in sorted({DRIVE_FOLDS[drive_of[f]] for f in frames}):
        if not (Path(args.models) / f"parts_fold{k}.npz").is_file():
            ap.error(f"{Path(args.models) / f'parts_fold{k}.npz'}: no such part model")
    work = partial(frame_rows, root=args.root, models=args.models, variant=args.variant, seed=args.seed)
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = [r for rs in pool.map(work, frames) for r in rs]
    else:
        rows = [r for f in frames for r in work(f)]
    if args.rows:
        np.savez_compressed(args.rows, steps=STEPS, frame=np.array([r["frame"] for r in rows]),
                            **{k: np.array([r[k] for r in rows]) for k in ("fold", "range", "error") + TERMS})
    groups = {"{" + ", ".join(map(str, g)) + "}": g for g in FOLD_GROUPS}
    groups["all"] = tuple(k for g in FOLD_GROUPS for k in g)
    out = {}
    print(f"== {args.variant}, label boxes, seed {args.seed}")
    for name, folds in groups.items():
        out[name] = summarise([r for r in rows if r["fold"] in folds])
        print(format_summary(name, out[name]))
    if args.json:
        write_json(args.json, {"variant": args.variant, "seed": args.seed, "groups": out})
        print(f"json: {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
