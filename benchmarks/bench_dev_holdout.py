"""The fine-stage defaults on the frames they were chosen on against frames of drives they never saw.

The defaults of ``LiftingOptions`` / ``InferenceOptions`` (``benchmarks/RESULTS.md``) were
chosen on the first 33 shared frames (8 drives; ``benchmarks/data/tuning_frames.txt``). The
39 frames added later come from 17 other drives, so on them the figures of a fold run
(every frame fitted with models that never saw its drive, ``bench_real_folds.py``) are held
out twice: from the models and from the choice of the defaults. This splits each run's
variants into the two sets and reports within 1 m, the true positives and the margin of
each variant over a reference (default ``coarse+gp``).

    python benchmarks/bench_dev_holdout.py RUN [RUN ...] [--tuning-frames benchmarks/data/tuning_frames.txt]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.jsonio import write_json
from wirescene.eval.metrics import evaluate
from wirescene.io.splits import read_split_file

HERE = Path(__file__).resolve().parent


def split_figures(records: dict, tuning: set[str], reference: str) -> dict:
    """``{set: {variant: {loc_1m, n_tp, n_gt, margin}}}`` for the tuning frames and the others."""
    out = {}
    for name, keep in (("tuning frames", lambda f: f in tuning), ("new drives", lambda f: f not in tuning)):
        rows = {}
        for variant, results in records.items():
            chosen = [r for r in results if keep(r.frame_id)]
            if not chosen:
                continue
            m = evaluate(chosen).metrics["all"]
            rows[variant] = {"loc_1m": m["loc_1m"], "n_tp": int(m["n_tp"]), "n_gt": int(m["n_gt"]),
                             "frames": len(chosen)}
        if reference in rows:
            for r in rows.values():
                r["margin"] = None if r["loc_1m"] is None else r["loc_1m"] - rows[reference]["loc_1m"]
        out[name] = rows
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="bench_real_folds.py --out directories (RUN/fold{k})")
    ap.add_argument("--tuning-frames", type=Path, default=HERE / "data" / "tuning_frames.txt",
                    help="the frames the defaults were chosen on, one id a line")
    ap.add_argument("--reference", default="coarse+gp")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    tuning = set(read_split_file(args.tuning_frames))
    out = {}
    for run in args.runs:
        records, detections = read_run(run)
        out[str(run)] = figures = split_figures(records, tuning, args.reference)
        print(f"{run} (detections {detections})")
        for name, rows in figures.items():
            cells = [f"{v} {r['loc_1m']:.1f}% of {r['n_tp']} TP / {r['n_gt']} cars"
                     + ("" if r.get("margin") is None or v == args.reference else f" ({r['margin']:+.1f})")
                     for v, r in rows.items() if r["loc_1m"] is not None]
            frames = next(iter(rows.values()))["frames"] if rows else 0
            print(f"  {name} ({frames} frames): " + "; ".join(cells))
    if args.json:
        write_json(args.json, out)


if __name__ == "__main__":
    main()
