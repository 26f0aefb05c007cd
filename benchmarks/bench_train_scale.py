"""Training at scale: wall time and peak memory of the detector-bank training against the
number of training frames, plain script.

Protocol: ``wirescene synth`` writes ``max(--frames)`` synthetic KITTI-layout scenes into
``WORK_DIR/kitti`` (kept for a later run); for each N of ``--frames`` the detector step
(``wirescene train detector --kitti-root``) trains on the first N of them in a
subprocess, whose wall time and peak resident memory (``os.wait4``: the largest of the
process and its workers) are recorded. With ``--workers-check N`` the run at N frames
is repeated with 2 workers: the speed-up gives the share of the time spent in the
per-image passes that run in parallel (Amdahl: ``t2 = t1 * (1 - p / 2)``). The points of
``--two-workers`` run with 2 workers only (a large point that would take too long on one);
each is set against the serial law's projection for it, as a check of that projection.
Every row also gives the sizes of the bounded pools of its bank (the largest configuration's
negatives, the refinement's rows and the rows they were sampled from), so that one can see
where each bound binds.

Fitted: time = a + b N (least squares), peak MB = c + d N; projected: the 3,712-frame
KITTI train split on 2 and 16 workers, assuming the parallel share ``p`` measured here
speeds up linearly (``t * (1 - p + p / workers)``) and the rest stays serial.

The recipe is a light one by default, so that the points fit in minutes (``RECIPES["light"]``:
1 partial configuration per viewpoint, 3 pyramid levels per octave, 1 mining round, a given
Platt calibration instead of the held-out fold banks); ``--recipe shipped`` runs the recipe of
the shipped ``detector_bank.npz`` (the command's defaults: 3 partial configurations, 6 levels
per octave, 3 mining rounds, with the shipped calibration given). The figures are for the
recipe run. ``--cache-mb`` and ``--max-negatives`` set the caches' bounds (small by default,
so that the bounds bind within the frames measured here: above them memory must stay flat,
and every pass describes its images again, as on a whole KITTI split). ``--root`` trains on
the first N labelled frames of a KITTI root (in id order) instead of synthetic scenes.

Usage:
  python benchmarks/bench_train_scale.py WORK_DIR [--frames 10,20,40,80] [--workers-check 20]
      [--two-workers 800] [--recipe light|shipped] [--root KITTI_ROOT] [--json out.json]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

RECIPES = {
    "light": ["--partial", "1", "--per-octave", "3", "--mining-rounds", "1", "--calibration", "7.5854,0.6654,0.4381",
              "--threshold", "0.1"],
    # README, "Trained artefacts": the detector_bank.npz row
    "shipped": ["--calibration", "4.0416,-2.3012,0.6323", "--threshold", "0.5"],
}
KITTI_TRAIN_FRAMES = 3712


def run_child(args: list[str]) -> tuple[float, float, str]:
    """``(seconds, peak MB, output)`` of ``python -m wirescene.cli.main ARGS``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "wirescene.cli.main", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(args[:3])} failed:\n{out[-3000:]}")
    peak = usage.ru_maxrss / (1 << 20 if sys.platform == "darwin" else 1 << 10)  # bytes on macOS, KiB on Linux
    return seconds, peak, out


def make_frames(work: Path, n: int) -> Path:
    """``work/kitti`` holding at least ``n`` synthetic scenes (written if fewer)."""
    root = work / "kitti"
    images = root / "training" / "image_2"
    if not images.is_dir() or len(list(images.glob("*.png"))) < n:
        run_child(["synth", str(root), "--scenes", str(n), "--overwrite"])
    return root


def labelled_frames(root: Path) -> list[str]:
    """Ids of the frames of the KITTI root ``root`` that have a label file, in id order."""
    from wirescene.io.kitti import KittiDataset

    dataset = KittiDataset(root)
    return sorted(f for f in dataset.frame_ids() if dataset.label_path(f).is_file())


def train(root: Path, work: Path, n: int, *, workers: int, cache_mb: float, max_negatives: int,
          recipe: str = "light") -> dict:
    """One detector-step run on the first ``n`` labelled frames of ``root``."""
    from wirescene.core.jsonio import dumps

    ids = labelled_frames(root)
    if n > len(ids):
        raise SystemExit(f"{root}: {len(ids)} labelled frames, fewer than the {n} asked for")
    frames = ",".join(ids[:n])
    out_path = work / f"bank_{recipe}_{n}_{workers}.npz"
    seconds, peak, out = run_child(["train", "detector", "--kitti-root", str(root), "--frames", frames,
                                    *RECIPES[recipe],
                                    "--pyramid-cache-mb", str(cache_mb), "--max-negatives", str(max_negatives),
                                    "--workers", str(workers), "--out", str(out_path)])
    row = {"frames": n, "workers": workers, "seconds": round(seconds, 1), "peak_mb": round(peak),
           **pool_sizes(out_path)}
    print(dumps(row, indent=None), flush=True)
    return row


def pool_sizes(path: Path) -> dict:
    """Sizes of the bounded pools recorded in the meta of the bank at ``path``."""
    from wirescene.predetect.bank import DetectorBank

    meta = DetectorBank.load(path).meta
    refinement = meta.get("box_refinement", {})
    return {"negatives_max": max(meta.get("n_negatives", [0])), "refinement_rows": refinement.get("n", 0),
            "refinement_offered": refinement.get("sampled_from", refinement.get("n", 0))}


def fit_line(x, y) -> tuple[float, float]:
    """``(a, b)`` of the least-squares line ``y = a + b x``."""
    import numpy as np

    b, a = np.polyfit(np.asarray(x, float), np.asarray(y, float), 1)
    return float(a), float(b)


def summarise(rows: list[dict], check: list[dict], large: list[dict] = ()) -> dict:
    """Fitted laws and the projection of the 3,712-frame split; ``large``: points run with
    2 workers, set against the serial law's projection for them."""
    serial = [r for r in rows if r["workers"] == 1]
    n = [r["frames"] for r in serial]
    a, b = fit_line(n, [r["seconds"] for r in serial])
    c, d = fit_line(n, [r["peak_mb"] for r in serial])
    out = {"time_s": {"a": round(a, 1), "b_per_frame": round(b, 2)},
           "peak_mb": {"c": round(c), "d_per_frame": round(d, 2), "first": serial[0]["peak_mb"],
                       "last": serial[-1]["peak_mb"], "ratio_last_first": round(serial[-1]["peak_mb"]
                                                                                / serial[0]["peak_mb"], 2)}}
    t1 = a + b * KITTI_TRAIN_FRAMES
    out["projection_3712"] = {"serial_h": round(t1 / 3600, 1)}
    if check:
        one, two = check
        p = min(max(2 * (1 - two["seconds"] / one["seconds"]), 0.0), 1.0)
        out["parallel_share"] = round(p, 2)
        for w in (2, 16):
            out["projection_3712"][f"workers_{w}_h"] = round(t1 * (1 - p + p / w) / 3600, 1)
        out["two_workers"] = [{"frames": r["frames"], "seconds": r["seconds"],
                               "projected_s": round((a + b * r["frames"]) * (1 - p / 2), 1), "peak_mb": r["peak_mb"],
                               "peak_over_first_serial": round(r["peak_mb"] / serial[0]["peak_mb"], 2)}
                              for r in large]
    return out


def main():
    from wirescene.core.atomic import write_text
    from wirescene.core.jsonio import dumps

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work_dir", type=Path, help="directory for the synthetic frames and the banks")
    ap.add_argument("--frames", default="10,20,40,80", help="numbers of training frames, comma-separated")
    ap.add_argument("--workers-check", type=int, default=20, help="frames of the 1- and 2-worker runs (0: none)")
    ap.add_argument("--two-workers", default="", help="numbers of frames run with 2 workers only, comma-separated")
    ap.add_argument("--cache-mb", type=float, default=300.0, help="--pyramid-cache-mb of the runs")
    ap.add_argument("--max-negatives", type=int, default=2000, help="--max-negatives of the runs")
    ap.add_argument("--recipe", choices=sorted(RECIPES), default="light", help="the detector recipe timed")
    ap.add_argument("--root", type=Path, default=None,
                    help="a KITTI root whose labelled frames are trained on (default: synthetic scenes)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows and the fitted laws here")
    args = ap.parse_args()
    counts = sorted({int(v) for v in args.frames.split(",") if v.strip()})
    large = sorted({int(v) for v in args.two_workers.split(",") if v.strip()})
    if large and not args.workers_check:
        ap.error("--two-workers needs --workers-check (the parallel share of its projection)")
    args.work_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.root is None:
        root = make_frames(args.work_dir, max(counts + large + [args.workers_check]))
        print(f"synthetic frames ready in {time.perf_counter() - t0:.0f} s", flush=True)
    else:
        root = args.root
    caps = dict(cache_mb=args.cache_mb, max_negatives=args.max_negatives, recipe=args.recipe)
    rows = [train(root, args.work_dir, n, workers=1, **caps) for n in counts]
    check = []
    if args.workers_check:
        one = next((r for r in rows if r["frames"] == args.workers_check), None)
        one = one or train(root, args.work_dir, args.workers_check, workers=1, **caps)
        check = [one, train(root, args.work_dir, args.workers_check, workers=2, **caps)]
    two = [train(root, args.work_dir, n, workers=2, **caps) for n in large]
    result = {"recipe": RECIPES[args.recipe], "root": str(root), **caps, "rows": rows, "workers_check": check, "two_workers": two,
              "fit": summarise(rows, check, two)}
    print(dumps(result["fit"]))
    if args.json:
        write_text(args.json, dumps(result) + "\n")


if __name__ == "__main__":
    main()
