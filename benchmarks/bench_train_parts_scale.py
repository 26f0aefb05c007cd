"""Training at scale, the part detectors' step: wall time, peak memory and patch counts of
``wirescene train parts`` (the shipped recipe) against the number of real training frames,
plain script.

Protocol: the 100 synthetic scenes of the recipe are rendered into ``WORK_DIR/synth_cache``
first (their patches are the same for every N, and every run reads them from there); then
for each N of ``--frames`` the step trains on the first N labelled frames of ``--root`` (or
of ``max(--frames)`` synthetic KITTI-layout scenes written into ``WORK_DIR/kitti``) in a
subprocess, whose wall time and peak resident memory are recorded with the command's own
report: real patches, all patches, the seconds spent making patches and fitting the final
forest (the rest is the held-out per-part calibration: one forest a fold).

The real patches grow with the frames until their cap (600,000, a uniform sample), so the
projection to the 3,712-frame KITTI train split has two parts: making patches, linear in
the frames (fitted on the points), and the forests, whose cost follows the number of
patches (a power law fitted on the points, taken to the capped count). It is a
projection, not a measurement: say so wherever it is quoted.

Usage:
  python benchmarks/bench_train_parts_scale.py WORK_DIR --root KITTI_ROOT [--frames 24,72] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train_scale import KITTI_TRAIN_FRAMES, fit_line, labelled_frames, make_frames, run_child  # noqa: E402

MAX_REAL_PATCHES = 600_000  # training.parts.train_part_detector's default cap


def fill_synth_cache(cache: Path) -> float:
    """Render the recipe's synthetic patches into ``cache`` (read by every run); seconds."""
    from wirescene.training.parts import make_synth_patch_data
    from wirescene.training.recipe import RECIPE

    t0 = time.perf_counter()
    recipe = RECIPE["parts"]
    make_synth_patch_data(n_scenes=recipe["synth_scenes"], kinds=(recipe["kind"],), sample_seed=0, cache_dir=cache)
    return time.perf_counter() - t0


def train(root: Path, work: Path, n: int) -> dict:
    """One ``train parts`` run (the shipped recipe: the command's defaults) on the first ``n``
    labelled frames of ``root``."""
    from wirescene.core.jsonio import dumps

    ids = labelled_frames(root)
    if n > len(ids):
        raise SystemExit(f"{root}: {len(ids)} labelled frames, fewer than the {n} asked for")
    report = work / f"parts_{n}.json"
    seconds, peak, _ = run_child(["train", "parts", "--kitti-root", str(root), "--frames", ",".join(ids[:n]),
                                  "--synth-cache", str(work / "synth_cache"), "--report", str(report),
                                  "--out", str(work / f"parts_{n}.npz")])
    r = json.loads(report.read_text())
    row = {"frames": n, "seconds": round(seconds, 1), "peak_mb": round(peak), "real_patches": r["n_real"],
           "patches": r["n_patches"], "patches_s": round(r["t_data_s"], 1), "final_forest_s": round(r["t_fit_s"], 1)}
    row["calibration_s"] = round(seconds - row["patches_s"] - row["final_forest_s"], 1)
    print(dumps(row, indent=None), flush=True)
    return row


def project(rows: list[dict]) -> dict:
    """The 3,712-frame projection (see the module docstring) from two or more rows."""
    n = [r["frames"] for r in rows]
    a, b = fit_line(n, [r["patches_s"] for r in rows])
    real_per_frame = rows[-1]["real_patches"] / rows[-1]["frames"]
    synth = rows[-1]["patches"] - rows[-1]["real_patches"]
    capped = min(MAX_REAL_PATCHES, real_per_frame * KITTI_TRAIN_FRAMES) + synth
    forests = [r["final_forest_s"] + r["calibration_s"] for r in rows]
    k = math.log(forests[-1] / forests[0]) / math.log(rows[-1]["patches"] / rows[0]["patches"])
    forests_3712 = forests[-1] * (capped / rows[-1]["patches"]) ** k
    patches_3712 = a + b * KITTI_TRAIN_FRAMES
    return {"patches_s": {"a": round(a, 1), "b_per_frame": round(b, 2)},
            "real_patches_per_frame": round(real_per_frame, 1), "patches_3712": round(capped),
            "forests_exponent": round(k, 2), "projection_3712_h": {
                "patches": round(patches_3712 / 3600, 1), "forests": round(forests_3712 / 3600, 1),
                "total": round((patches_3712 + forests_3712) / 3600, 1)}}


def main():
    from wirescene.core.atomic import write_text
    from wirescene.core.jsonio import dumps

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work_dir", type=Path, help="directory for the synthetic cache, the models and their reports")
    ap.add_argument("--root", type=Path, default=None,
                    help="a KITTI root whose labelled frames are trained on (default: synthetic scenes)")
    ap.add_argument("--frames", default="24,72", help="numbers of training frames, comma-separated (two or more)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows and the projection here")
    args = ap.parse_args()
    counts = sorted({int(v) for v in args.frames.split(",") if v.strip()})
    if len(counts) < 2:
        ap.error("--frames needs two or more numbers (the projection fits a law)")
    args.work_dir.mkdir(parents=True, exist_ok=True)
    root = args.root or make_frames(args.work_dir, max(counts))
    print(f"synthetic patches cached in {fill_synth_cache(args.work_dir / 'synth_cache'):.0f} s", flush=True)
    rows = [train(root, args.work_dir, n) for n in counts]
    result = {"root": str(root), "rows": rows, "projection": project(rows)}
    print(dumps(result["projection"]))
    if args.json:
        write_text(args.json, dumps(result) + "\n")


if __name__ == "__main__":
    main()
