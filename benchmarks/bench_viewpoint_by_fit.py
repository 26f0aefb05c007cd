"""Front or back by the fit: does the fine objective tell a box's viewpoint from its opposite?

Boxes given without a viewpoint (issue 27, item 2) take the box rule's
(:func:`wirescene.fitting.own_boxes.complete_viewpoints`); its errors are mostly front/back
swaps. Here every labelled Car of every frame is given as its label box without a viewpoint,
completed by the rule with the models of the frame's fold (``--models DIR`` with
``bank_fold{k}.npz``, ``viewpoint_classifier_fold{k}.npz``, ``parts_fold{k}.npz``, trained
without its drives), and the frame is fitted twice with one fine variant: once with the
rule's viewpoints, once with every viewpoint turned by 180 deg. Per car, the fit whose
objective is lower by more than ``delta`` gives the viewpoint. Reported by fold group: the
share of cars within 45 deg of the label's observation angle (the paper's criterion) and of
front/back swaps (> 135 deg), for the rule and for the choice by fit at each ``delta``.

    python benchmarks/bench_viewpoint_by_fit.py --root KITTI_ROOT --models DIR [--variant fg+gp]
        [--folds 0 1] [--delta 0 0.05 0.1 0.2] [--json OUT.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wirescene.core.atomic import write_text  # noqa: E402
from wirescene.core.groundplane import wrap_angle  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.core.viewpoints import angle_difference  # noqa: E402
from wirescene.fitting.models import detector_bank, part_detector, viewpoint_classifier  # noqa: E402
from wirescene.fitting.options import FitOptions  # noqa: E402
from wirescene.fitting.own_boxes import complete_viewpoints  # noqa: E402
from wirescene.fitting.pipeline import fit_frame  # noqa: E402
from wirescene.infer.evidence import part_evidence  # noqa: E402
from wirescene.io.folds import FOLD_GROUPS, N_FOLDS, fold_of  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402

GOOD, SWAP = np.radians(45.0), np.radians(135.0)


def frame_costs(dataset, frame_id, models: Path, variant: str, seed: int) -> dict:
    """The label cars of one frame: the label's and the rule's observation angles and the
    fitted objective of each car with the rule's viewpoints and with their opposites."""
    k = fold_of(frame_id)
    cars = dataset.labels(frame_id).of_type("Car")
    camera, image = dataset.camera(frame_id), dataset.image(frame_id)
    options = FitOptions(seed=seed, calibrate_scores=False, parts_model=str(models / f"parts_fold{k}.npz"),
                         detector_bank=str(models / f"bank_fold{k}.npz"),
                         viewpoint_classifier=str(models / f"viewpoint_classifier_fold{k}.npz"))
    boxes = np.array([c.box for c in cars], float).reshape(-1, 4)
    rule = complete_viewpoints(camera, Detections(boxes, 1.0, np.nan, "labels"), image,
                               bank=detector_bank(options.detector_bank),
                               classifier=viewpoint_classifier(options.viewpoint_classifier))
    turned = Detections(rule.boxes, rule.scores, wrap_angle(rule.alpha + np.pi), rule.source)
    evidence = part_evidence(image, rule, detector=part_detector(options.parts_model),
                             flip=options.inference.flip_evidence)
    costs = []
    for dets in (rule, turned):
        est = fit_frame(camera, dets, [variant], image=image, evidence=evidence, options=options).estimates[variant]
        by_index = {o.detection_index: o.cost for o in est.objects}
        costs.append([by_index[j] for j in range(len(dets))])
    return {"frame": frame_id, "fold": k, "label_alpha": [c.alpha for c in cars], "rule_alpha": rule.alpha.tolist(),
            "cost_rule": costs[0], "cost_turned": costs[1]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", required=True)
    ap.add_argument("--models", type=Path, required=True)
    ap.add_argument("--variant", default="fg+gp")
    ap.add_argument("--folds", type=int, nargs="+", default=list(range(N_FOLDS)))
    ap.add_argument("--delta", type=float, nargs="+", default=[0.0, 0.05, 0.1, 0.2])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None, help="write the per-car records (and read them with --from)")
    ap.add_argument("--from", dest="from_json", type=Path, nargs="+", default=None,
                    help="report from records written by --json (e.g. of runs on different folds)")
    args = ap.parse_args()
    if args.from_json:
        rows = [r for p in args.from_json for r in json.loads(p.read_text())]
    else:
        dataset = KittiDataset(args.root)
        rows = []
        for f in [f for f in dataset.frame_ids() if fold_of(f) in args.folds]:
            t = time.perf_counter()
            rows.append(frame_costs(dataset, f, args.models, args.variant, args.seed))
            print(f"frame {f} fold {fold_of(f)}: {len(rows[-1]['label_alpha'])} cars, {time.perf_counter() - t:.1f} s",
                  flush=True)
        if args.json:
            write_text(args.json, json.dumps(rows))  # plain json: --from reads it back, an infinite cost exact
    fold = np.concatenate([[r["fold"]] * len(r["label_alpha"]) for r in rows])
    label = np.concatenate([r["label_alpha"] for r in rows])
    rule = np.concatenate([r["rule_alpha"] for r in rows])
    gain = np.concatenate([np.subtract(r["cost_rule"], r["cost_turned"]) for r in rows])  # > 0: turned fits better

    def line(name, alpha):
        err = np.abs(angle_difference(alpha, label))
        cells = []
        for g in FOLD_GROUPS + ("all",):
            m = np.ones(len(err), bool) if g == "all" else np.isin(fold, g)
            if m.any():
                cells.append(f"{g}: {100 * np.mean(err[m] <= GOOD):.1f}% ({m.sum()}) swaps {100 * np.mean(err[m] > SWAP):.1f}%")
        print(f"{name:18s} " + " | ".join(cells))

    line("rule", rule)
    for delta in args.delta:
        line(f"by fit, delta {delta:g}", np.where(gain > delta, wrap_angle(rule + np.pi), rule))


if __name__ == "__main__":
    main()
