"""End to end, side by side in one run: `wirescene eval` on the same real frames under several
``--device`` / ``--workers`` configurations, with each one's wall time (the ratio to the first)
and how far its cars are from the first configuration's.

Each configuration is one fresh ``wirescene eval`` process (label boxes, one variant, one seed,
``--draws 0``), so its time includes the start-up a user pays. Agreement is read car by car from
the runs' records (the same label boxes in the same order): the number of cars whose 3D
position moved more than 1 cm, the largest move, and the within-1 m count. A backend whose ray
casting differs from numpy's in float rounding can flip a near-grazing visibility flag, and the
particle filter then follows another path: exact agreement is not expected, equal quality is.

    python benchmarks/bench_devices.py --root KITTI_ROOT [--frames 24] [--variant full]
        [--seed 2] [--config numpy:1] [--config numpy:all] [--config cuda:1] [--out DIR]

``--config DEVICE:WORKERS`` (WORKERS a number or ``all``; DEVICE ``numpy``, ``cpu``, ``cuda``
or ``cuda:N``); default: ``numpy:1``, ``numpy:all``, and ``cuda:1`` where PyTorch sees a GPU.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", type=Path, required=True, help="KITTI root with training/{image_2,label_2,calib}")
    ap.add_argument("--frames", type=int, default=24, help="the first N labelled frames (default 24)")
    ap.add_argument("--variant", default="full")
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--config", action="append", default=None, metavar="DEVICE:WORKERS")
    ap.add_argument("--out", type=Path, default=None, help="keep each run's JSON here (default: a temporary folder)")
    return ap.parse_args(argv)


def default_configs() -> list[str]:
    configs = ["numpy:1", "numpy:all"]
    try:
        import torch

        if torch.cuda.is_available():
            configs.append("cuda:1")
    except ImportError:
        pass
    return configs


def eval_command(root: Path, frames: list[str], variant: str, seed: int, config: str, run_dir: Path) -> list[str]:
    device, _, workers = config.partition(":")
    workers = str(os.cpu_count() or 1) if workers == "all" else workers
    cmd = [sys.executable, "-m", "wirescene.cli.main", "eval", str(root), "--detections", "gt",
           "--variant", variant, "--seed", str(seed), "--draws", "0", "--frames", ",".join(frames),
           "--device", device, "--json", str(run_dir / "metrics.json"), "--predictions", str(run_dir)]
    if not device.startswith("cuda"):  # a CUDA device fits in one process (eval refuses --workers)
        cmd += ["--workers", workers]
    return cmd


def positions(run_dir: Path, variant: str) -> dict:
    """``{(frame, line): (x, y, z)}``: each output car's 3D position (KITTI label columns 12-14),
    one per label box in the order of the boxes."""
    out = {}
    for path in sorted((run_dir / variant).glob("*.txt")):
        for i, line in enumerate(path.read_text().splitlines()):
            out[path.stem, i] = tuple(float(v) for v in line.split()[11:14])
    return out


def main(argv=None):
    args = parse_args(argv)
    from wirescene.io.kitti import KittiDataset

    frames = KittiDataset(args.root).frame_ids()[:args.frames]
    configs = args.config or default_configs()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_devices_"))
    out.mkdir(parents=True, exist_ok=True)
    print(f"{len(frames)} frames, variant {args.variant}, seed {args.seed}, {os.cpu_count()} CPUs; configs {configs}")
    runs = []
    for config in configs:
        run_dir = out / config.replace(":", "_")
        shutil.rmtree(run_dir, ignore_errors=True)  # a new run each time: eval refuses to mix it with an earlier one
        t0 = time.perf_counter()
        proc = subprocess.run(eval_command(args.root, frames, args.variant, args.seed, config, run_dir),
                              capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        if proc.returncode:
            sys.exit(f"bench_devices: {config} failed (exit {proc.returncode}): {proc.stderr.strip().splitlines()[-1:]}")
        runs.append((config, seconds, run_dir))
    ref_config, ref_seconds, ref_dir = runs[0]
    ref_pos = positions(ref_dir, args.variant)
    print(f"{'config':<12}{'wall s':>8}{'vs ' + ref_config:>14}{'s/frame':>9}{'cars':>6}{'<1 m':>6}"
          f"{'moved>1cm':>11}{'max move m':>12}")
    summary = []
    for config, seconds, run_dir in runs:
        metrics = json.loads((run_dir / "metrics.json").read_text())
        pos = positions(run_dir, args.variant)
        common = sorted(set(pos) & set(ref_pos))
        moves = [sum((a - b) ** 2 for a, b in zip(pos[k], ref_pos[k])) ** 0.5 for k in common]
        moved = sum(m > 0.01 for m in moves)
        within = sum(r["loc_error"] < 1.0 for r in metrics["records"])  # counted, as eval.metrics's loc_1m
        print(f"{config:<12}{seconds:8.1f}{ref_seconds / seconds:13.2f}x{seconds / len(frames):9.2f}"
              f"{metrics['n_gt']:6d}{within:6d}{moved:11d}{max(moves, default=0.0):12.3f}")
        summary.append({"config": config, "seconds": seconds, "cars": metrics["n_gt"], "within_1m": within,
                        "moved_over_1cm": moved, "max_move_m": max(moves, default=0.0), "compared": len(common)})
    from wirescene.core.jsonio import write_json

    write_json(out / "summary.json", {"frames": frames, "variant": args.variant, "seed": args.seed, "runs": summary})
    print(f"runs in {out}")


if __name__ == "__main__":
    main()
