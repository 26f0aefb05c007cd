"""Does a fitting worker's memory grow with the frames it has fitted? Plain script (Linux: it
reads ``/proc`` and calls glibc's ``malloc_trim``).

``wirescene eval --workers W`` keeps its W processes for the whole run, each fitting frame
after frame, so a worker that kept a little of every frame would outgrow a machine on a
3,769-frame split even where its peak on 72 frames looks small. Here one process does a
worker's job (:class:`wirescene.eval.runner._FrameJob`, what each worker calls) on the same
``--frames`` first labelled frames ``--passes`` times over. After each pass it prints its
resident set, the same after glibc's ``malloc_trim`` (memory held by the allocator but free),
and its peak so far. A leak shows as a resident set rising pass after pass; freed memory the
allocator keeps shows as the gap before and after the trim.

(Python's own ``tracemalloc`` is not used: its bookkeeping grows the resident set by tens of
MB a pass by itself.)

Usage:
  python benchmarks/bench_worker_memory.py --root KITTI_ROOT [--frames 6] [--passes 5]
      [--variant coarse+gp --variant full] [--detections bank]
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import os
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_eval_scale import _rss_kb  # noqa: E402
from bench_train_scale import labelled_frames  # noqa: E402


def trim() -> None:
    """Hand the allocator's free memory back to the system (glibc only; elsewhere nothing)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def passes(root: str, *, frames: int, n_passes: int, variants: list[str], detections: str):
    """Yield ``(pass, seconds, rss_mb, rss_trimmed_mb, peak_mb)`` after each pass."""
    from wirescene.eval.runner import _FrameJob
    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.options import FitOptions
    from wirescene.io.kitti import KittiDataset

    dataset = KittiDataset(root)
    ids = labelled_frames(root)[:frames]
    job = _FrameJob(dataset, tuple(variants), DetectionSource(detections), FitOptions(), "parts")
    for k in range(n_passes):
        t0 = time.time()
        for frame_id in ids:
            job(frame_id)
        gc.collect()
        rss = _rss_kb(os.getpid()) / 1024
        trim()
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        yield k, time.time() - t0, rss, _rss_kb(os.getpid()) / 1024, peak


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", required=True, help="KITTI root with labelled frames")
    ap.add_argument("--frames", type=int, default=6, help="the first N labelled frames, fitted each pass")
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--variant", action="append", help="default: coarse+gp and full")
    ap.add_argument("--detections", default="bank", help="gt, bank or a folder of detection files")
    args = ap.parse_args(argv)
    variants = args.variant or ["coarse+gp", "full"]
    print(f"{args.frames} frames a pass, variants {', '.join(variants)}, detections {args.detections}")
    for k, seconds, rss, trimmed, peak in passes(args.root, frames=args.frames, n_passes=args.passes,
                                                  variants=variants, detections=args.detections):
        print(f"pass {k}: resident {rss:.0f} MB, after malloc_trim {trimmed:.0f} MB, peak {peak:.0f} MB "
              f"({seconds:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
