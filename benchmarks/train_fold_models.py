"""Train the fold models behind the README's held-out figures, plain script.

For each fold k of :mod:`wirescene.io.folds` (4 folds of whole drives), on the labelled
frames of the other three folds (``OUT/splits/train_fold{k}.txt``, written first):

* ``parts_fold{k}.npz``: ``wirescene train parts --kitti-root ROOT --split-file ...`` (the
  shipped recipe is the command's default; the synthetic scenes' patches are rendered once
  into ``OUT/synth_cache`` and read by every fold);
* ``viewpoint_classifier_fold{k}.npz``: ``wirescene train viewpoints ROOT --split-file ...``;
* ``bank_fold{k}.npz``: ``benchmarks/bench_predetect.py --root ROOT --cv --fold k
  --models-dir OUT/banks`` (the shipped bank's recipe), then, once the four are trained,
  ``--from-raw OUT/banks --models-dir OUT/banks`` detects each fold's frames with its bank and
  gives each bank the Platt calibration fitted on the other folds' held-out detections; the
  calibrated ``OUT/banks/fold{k}.npz`` is copied to ``OUT/bank_fold{k}.npz``.

``OUT`` is then the ``--models`` directory of ``benchmarks/bench_real_folds.py``. A step whose
output exists is skipped, so an interrupted run resumes; ``--jobs N`` runs N steps at once
(each step uses one core; about 10 min a part model, 30 min and 6.5 GB a bank on the 72
shared frames). Each step's output goes to ``OUT/logs/STEP.log``.

The README's models were trained on a CPU without AVX-512. On one with AVX-512, OpenBLAS picks
other kernels and the models differ in their last digits (held-out figures within a training
seed's spread); ``OPENBLAS_CORETYPE=Haswell`` before the command gives the README's banks and
crop classifiers there, not its part models (benchmarks/RESULTS.md, "The held-out figures on a
CPU with AVX-512").

Usage:
  python benchmarks/train_fold_models.py --root ../shared/data/kitti --out FOLD_MODELS [--jobs 2]
      [--steps parts,viewpoints,banks] [--folds 0,1,2,3]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train_parts_scale import fill_synth_cache  # noqa: E402
from bench_train_scale import labelled_frames  # noqa: E402
from wirescene.io.folds import N_FOLDS, fold_of  # noqa: E402

HERE = Path(__file__).resolve().parent
STEPS = ("parts", "viewpoints", "banks")


def write_splits(root: Path, out: Path) -> dict[int, Path]:
    """``{k: OUT/splits/train_fold{k}.txt}``: the labelled frames of the folds other than k."""
    frames = labelled_frames(root)
    (out / "splits").mkdir(parents=True, exist_ok=True)
    paths = {}
    for k in range(N_FOLDS):
        paths[k] = out / "splits" / f"train_fold{k}.txt"
        paths[k].write_text("".join(f"{f}\n" for f in frames if fold_of(f) != k))
    return paths


def cli(*args) -> list[str]:
    return [sys.executable, "-m", "wirescene.cli.main", *map(str, args)]


def tasks(root: Path, out: Path, splits: dict[int, Path], steps, folds) -> list[tuple[str, Path, list[str]]]:
    """``(name, output, command)`` of every per-fold step asked for."""
    todo = []
    for k in folds:
        if "parts" in steps:
            todo.append((f"parts_fold{k}", out / f"parts_fold{k}.npz",
                         cli("train", "parts", "--kitti-root", root, "--split-file", splits[k],
                             "--synth-cache", out / "synth_cache", "--out", out / f"parts_fold{k}.npz")))
        if "viewpoints" in steps:
            todo.append((f"viewpoints_fold{k}", out / f"viewpoint_classifier_fold{k}.npz",
                         cli("train", "viewpoints", root, "--split-file", splits[k],
                             "--out", out / f"viewpoint_classifier_fold{k}.npz")))
        if "banks" in steps:
            todo.append((f"bank_fold{k}", out / "banks" / f"fold{k}_raw.npz",
                         [sys.executable, str(HERE / "bench_predetect.py"), "--root", str(root), "--cv", "--fold",
                          str(k), "--models-dir", str(out / "banks"), "--time-frames", "0"]))
    return todo


def run_all(todo, logs: Path, jobs: int) -> None:
    """Run ``todo``'s commands, ``jobs`` at a time, skipping those whose output exists."""
    logs.mkdir(parents=True, exist_ok=True)
    pending = [t for t in todo if not t[1].exists()]
    for name, output, _ in todo:
        if output.exists():
            print(f"{name}: {output} exists, skipped", flush=True)
    running: dict[str, tuple[subprocess.Popen, float, object]] = {}
    failed = []
    while pending or running:
        while pending and len(running) < jobs:
            name, output, command = pending.pop(0)
            output.parent.mkdir(parents=True, exist_ok=True)
            log = open(logs / f"{name}.log", "w")  # noqa: SIM115  (closed when the step ends)
            running[name] = (subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT), time.perf_counter(), log)
            print(f"{name}: started", flush=True)
        time.sleep(2)
        for name, (proc, t0, log) in list(running.items()):
            if proc.poll() is None:
                continue
            log.close()
            del running[name]
            status = "done" if proc.returncode == 0 else f"FAILED (exit {proc.returncode}, see {logs / name}.log)"
            print(f"{name}: {status} in {time.perf_counter() - t0:.0f} s", flush=True)
            if proc.returncode:
                failed.append(name)
    if failed:
        raise SystemExit(f"failed steps: {', '.join(failed)}")


def calibrate_banks(root: Path, out: Path) -> None:
    """The four raw fold banks detect their held-out frames and are calibrated; copied to ``bank_fold{k}.npz``."""
    banks = out / "banks"
    if all((out / f"bank_fold{k}.npz").exists() for k in range(N_FOLDS)):
        print("bank_fold{k}.npz exist, calibration skipped", flush=True)
        return
    missing = [k for k in range(N_FOLDS) if not (banks / f"fold{k}_raw.npz").exists()]
    if missing:
        raise SystemExit(f"the calibration needs all four raw fold banks; missing folds {missing} in {banks}")
    t0 = time.perf_counter()
    with open(out / "logs" / "banks_calibration.log", "w") as log:
        subprocess.run([sys.executable, str(HERE / "bench_predetect.py"), "--root", str(root), "--from-raw",
                        str(banks), "--models-dir", str(banks), "--time-frames", "0"],
                       stdout=log, stderr=subprocess.STDOUT, check=True)
    for k in range(N_FOLDS):
        shutil.copyfile(banks / f"fold{k}.npz", out / f"bank_fold{k}.npz")
    print(f"banks calibrated in {time.perf_counter() - t0:.0f} s: {out}/bank_fold{{0..3}}.npz", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, required=True, help="the shared KITTI root (its frames' drives are known)")
    ap.add_argument("--out", type=Path, required=True, help="the fold models' directory (bench_real_folds --models)")
    ap.add_argument("--jobs", type=int, default=1, help="steps run at once (one core each)")
    ap.add_argument("--steps", default=",".join(STEPS), help="comma-separated subset of " + ", ".join(STEPS))
    ap.add_argument("--folds", default="0,1,2,3", help="comma-separated folds (the banks' calibration needs all four)")
    args = ap.parse_args()
    steps = [s.strip() for s in args.steps.split(",") if s.strip()]
    if set(steps) - set(STEPS):
        ap.error(f"--steps: unknown {sorted(set(steps) - set(STEPS))}; choose from {', '.join(STEPS)}")
    folds = sorted({int(k) for k in args.folds.split(",") if k.strip()})
    if any(not 0 <= k < N_FOLDS for k in folds):
        ap.error(f"--folds: folds are 0..{N_FOLDS - 1}")
    if args.jobs < 1:
        ap.error("--jobs must be >= 1")
    args.out.mkdir(parents=True, exist_ok=True)
    splits = write_splits(args.root, args.out)
    todo = tasks(args.root, args.out, splits, steps, folds)
    if any(name.startswith("parts") and not output.exists() for name, output, _ in todo):
        # rendered once here, so that part models trained at once do not each render them
        print(f"synthetic patches cached in {fill_synth_cache(args.out / 'synth_cache'):.0f} s", flush=True)
    run_all(todo, args.out / "logs", args.jobs)
    if "banks" in steps and folds == list(range(N_FOLDS)):
        calibrate_banks(args.root, args.out)


if __name__ == "__main__":
    main()
