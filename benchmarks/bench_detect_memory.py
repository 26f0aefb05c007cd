"""Peak memory and time of our own pre-detection on one frame at other cameras' resolutions. Plain script (Linux:
it reads ``/proc`` and runs ``/usr/bin/time``'s resource usage through ``os.wait4``).

A user's camera need not have KITTI's 1242 x 375 pixels: dashcams give 1920 x 1080, 4K ones 3840 x 2160. This
writes a one-frame KITTI root per ``--size WxH`` from a labelled frame of ``--root``: the image upsampled to the
width (PIL, Lanczos; ``P2`` rescaled by :func:`wirescene.predetect.enlarge.scaled_projection`) and, where ``H`` is
taller than the result, centred on a grey canvas of ``H`` rows (the principal point moved down with it). It then runs
``wirescene detect`` (or ``wirescene fit --variant coarse``, ``--command fit``, both from raw pixels) on it in a
fresh process, polling its resident set and ending it above ``--limit-gb``, and prints the peak resident set (the
kernel's ``ru_maxrss``, what ``/usr/bin/time -v`` reports as "Maximum resident set size") and the wall time.
``--src`` runs another checkout's ``src`` (e.g. the commit before a change) on the same roots, side by side.

Usage:
  python benchmarks/bench_detect_memory.py --root ../shared/data/kitti --frame 000010 --size 1242x375 \\
      --size 1920x1080 --size 3840x2160 --size 7680x4320 --work WORK [--command fit] [--src BASE/src]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))

from wirescene.core.camera import write_kitti_calib  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.predetect.enlarge import scaled_projection  # noqa: E402

SRC = Path(__file__).resolve().parents[1] / "src"


def sized_root(source: Path, frame: str, width: int, height: int, out: Path) -> Path:
    """``out`` as a KITTI root holding ``frame`` of ``source`` at ``width`` x ``height`` (module docstring)."""
    dataset = KittiDataset(source)
    image = Image.open(dataset.image_path(frame)).convert("RGB")
    factor = width / image.size[0]
    big = image.resize((width, round(image.size[1] * factor)), Image.LANCZOS)
    top = max(0, (height - big.size[1]) // 2)
    canvas = Image.new("RGB", (width, max(height, big.size[1])), (110, 110, 110))
    canvas.paste(big, (0, top))
    P = scaled_projection(dataset.calib(frame).P2, factor)
    P[1] += top * P[2]  # rows moved down by the canvas's top margin
    for sub in ("image_2", "calib"):
        (out / "training" / sub).mkdir(parents=True, exist_ok=True)
    canvas.save(out / "training" / "image_2" / f"{frame}.png")
    write_kitti_calib(out / "training" / "calib" / f"{frame}.txt", P)
    return out


def measured_run(argv: list[str], *, src: Path, limit_kb: int, log: Path) -> tuple[float, float, bool]:
    """``(peak resident set in MB, wall seconds, ended for memory)`` of ``python -m wirescene.cli.main argv``, its
    output written to ``log``."""
    env = dict(os.environ, PYTHONPATH=str(src))
    t0 = time.time()
    with open(log, "wb") as sink:
        proc = subprocess.Popen([sys.executable, "-m", "wirescene.cli.main", *argv], env=env, stdout=sink,
                                stderr=subprocess.STDOUT)
    killed, usage = False, None
    while usage is None:
        pid, status, rusage = os.wait4(proc.pid, os.WNOHANG)  # (the child's own usage, as /usr/bin/time reads it)
        if pid:
            usage, proc.returncode = rusage, os.waitstatus_to_exitcode(status)
            break
        try:
            rss = int(next(ln for ln in Path(f"/proc/{proc.pid}/status").read_text().splitlines()
                           if ln.startswith("VmRSS")).split()[1])
        except (OSError, StopIteration):
            rss = 0
        if rss > limit_kb:
            proc.kill()
            killed = True
        time.sleep(0.1)
    peak = usage.ru_maxrss / 1024
    if proc.returncode and not killed:
        raise SystemExit(f"{' '.join(argv)} failed:\n{log.read_text()[-2000:]}")
    return peak, time.time() - t0, killed


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, type=Path, help="KITTI root with the frame")
    ap.add_argument("--frame", default="000010")
    ap.add_argument("--size", action="append", required=True, help="WxH, e.g. 3840x2160 (repeat)")
    ap.add_argument("--work", required=True, type=Path, help="where the resized roots and outputs go")
    ap.add_argument("--command", choices=("detect", "fit"), default="detect")
    ap.add_argument("--src", type=Path, default=SRC, help="the checkout's src to run (default: this one)")
    ap.add_argument("--limit-gb", type=float, default=16.0, help="end a run whose resident set passes this")
    args = ap.parse_args(argv)
    print(f"| {args.command}, frame {args.frame} | megapixels | peak RSS (MB) | wall (s) |\n|---|---|---|---|")
    for size in args.size:
        width, height = (int(v) for v in size.lower().split("x"))
        root = sized_root(args.root, args.frame, width, height, args.work / f"root_{width}x{height}")
        out = args.work / f"{args.command}_{width}x{height}"
        if args.command == "detect":
            cmd = ["detect", str(root), "--frames", args.frame, "--out", str(out)]
        else:
            split = root / "training"
            cmd = ["fit", str(split / "image_2" / f"{args.frame}.png"), "--calib",
                   str(split / "calib" / f"{args.frame}.txt"), "--variant", "coarse", "--out", str(out)]
        peak, seconds, killed = measured_run(cmd, src=args.src, limit_kb=int(args.limit_gb * 2**20),
                                             log=args.work / f"{args.command}_{width}x{height}.log")
        pixels = np.prod(Image.open(root / "training" / "image_2" / f"{args.frame}.png").size) / 1e6
        print(f"| {width} x {height} | {pixels:.1f} | {'> ' if killed else ''}{peak:.0f} | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
