"""Evaluation at scale: peak memory and time of ``wirescene eval`` as the frames grow, the
parent process and each worker apart, plain script (Linux: it reads ``/proc``).

A user evaluates a whole KITTI split (``wirescene eval KITTI --split-file val.txt``: 3,769
frames) in ``--workers`` processes, all cores by default, so what must fit the machine is the
parent (which keeps every frame's evaluation record) plus one fitting process per worker.

Protocol: ``WORK_DIR/kitti`` becomes a KITTI-layout root of N frames whose files are links to
the labelled frames of ``--root``, dealt out again and again under new ids (``000000``,
``000001``, ...), so that the memory of many frames can be measured with the frames at hand.
For each N of ``--frames`` the command ``wirescene eval WORK_DIR/kitti --frames 000000,...``
runs in a subprocess with ``--workers`` (2 or more, and N too: ``eval`` fits a run of one worker
or one frame in its own process, with no worker to measure) and the evaluation arguments given after ``--``
(default ``--variant coarse --detections gt``: cheap fits, for the parent's growth). At its
exit the subprocess writes its own peak resident set and the largest of its workers'
(``getrusage``: self and reaped children), and a thread sums, every 0.2 s, the resident sets
(``VmRSS``) of the process and its descendants: the peak of that sum is what the machine
held at once (a sample: a shorter spike can pass between two readings).

Fitted over the points: the parent's peak = c + d N. Projected for a 3,769-frame split: the
parent there plus W workers at the largest worker peak measured, for W = 1, 2, 8, 16, and
the workers a 24 GB machine holds. The worker's peak is a property of the fit (variants,
detections), not of N: measure it with the command a user runs, e.g. ``-- --variant
coarse+gp --variant full --detections bank``.

Usage:
  python benchmarks/bench_eval_scale.py WORK_DIR --root KITTI_ROOT [--frames 72,720] [--workers 2]
      [--json out.json] [-- EVAL_ARGS...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train_scale import fit_line, labelled_frames  # noqa: E402

KITTI_VAL_FRAMES = 3769
MACHINE_GB = 24
SUBDIRS = ("image_2", "calib", "label_2")


def repeated_root(source: Path, work: Path, n: int) -> tuple[Path, list[str]]:
    """``(root, ids)``: ``work/kitti/training`` holding ``n`` frames, frame ``i`` a link to the
    files of the ``i % m``-th of the ``m`` labelled frames of ``source`` (in id order)."""
    from wirescene.io.kitti import KittiDataset

    dataset = KittiDataset(source)
    frames = labelled_frames(source)
    if not frames:
        raise SystemExit(f"{source}: no labelled frames")
    paths = {f: (dataset.image_path(f), dataset.calib_path(f), dataset.label_path(f)) for f in frames}
    root = work / "kitti"
    ids = [f"{i:06d}" for i in range(n)]
    for sub in SUBDIRS:
        (root / "training" / sub).mkdir(parents=True, exist_ok=True)
    for i, new in enumerate(ids):
        for sub, target in zip(SUBDIRS, paths[frames[i % len(frames)]]):
            link = root / "training" / sub / f"{new}{target.suffix}"
            if link.is_symlink() or link.exists():
                link.unlink()
            link.symlink_to(target.resolve())
    return root, ids


def _rss_kb(pid: int) -> int:
    """Resident set (kB) of process ``pid``; 0 once it has gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        pass
    return 0


def descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (from each process's parent id in ``/proc/*/stat``)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        ppid = int(stat[stat.rindex(")") + 2:].split()[1])  # the name may hold spaces or ')'
        children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        below = children.get(todo.pop(), [])
        out += below
        todo += below
    return out


class TreeMemory:
    """Samples, in a thread, the summed resident set (MB) of a process and its descendants."""

    def __init__(self, pid: int, interval: float = 0.2):
        self.pid, self.interval = pid, interval
        self.peak_sum = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def sample(self) -> None:
        total = sum(_rss_kb(p) for p in [self.pid, *descendants(self.pid)]) / 1024
        self.peak_sum = max(self.peak_sum, total)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.sample()
            self._stop.wait(self.interval)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


# Runs the CLI in the child and, at its exit, writes the peak resident sets (KiB on Linux) of
# the child itself and of the largest worker it reaped to the file named by argv[1].
_CHILD = """import atexit, json, resource, sys
out = sys.argv.pop(1)
def _peaks():
    with open(out, "w") as f:
        json.dump({"self": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                   "children": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}, f)
atexit.register(_peaks)
from wirescene.cli.main import console_main
sys.argv[0] = "wirescene"
console_main()
"""


def run_eval(root: Path, ids: list[str], work: Path, *, workers: int, eval_args: list[str]) -> dict:
    """One ``wirescene eval`` of the frames ``ids`` of ``root``, with its time and memory."""
    from wirescene.core.jsonio import dumps

    out, peaks = work / f"eval_{len(ids)}.json", work / f"peaks_{len(ids)}.json"
    cmd = [sys.executable, "-c", _CHILD, str(peaks), "eval", str(root), "--frames", ",".join(ids),
           "--workers", str(workers), "--draws", "0", "--json", str(out), *eval_args]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    with TreeMemory(proc.pid) as memory:
        log = proc.stdout.read()
        proc.wait()
    if proc.returncode != 0:
        raise RuntimeError(f"wirescene eval failed ({proc.returncode}):\n{log[-3000:]}")
    kib = json.loads(peaks.read_text())
    if kib["children"] == 0:  # e.g. --device cuda or --dask after --: the fits ran in the parent, or elsewhere
        raise RuntimeError("no worker process was reaped: the run was not parallel, so no worker's peak was measured "
                           "and the parent's holds the fits")
    row = {"frames": len(ids), "workers": workers, "seconds": round(time.perf_counter() - t0, 1),
           "parent_mb": round(kib["self"] / 1024), "worker_max_mb": round(kib["children"] / 1024),
           "peak_sum_mb": round(memory.peak_sum)}
    print(dumps(row, indent=None), flush=True)
    return row


def project(rows: list[dict], *, frames: int = KITTI_VAL_FRAMES, machine_gb: float = MACHINE_GB) -> dict:
    """The parent's law ``c + d N`` over ``rows`` and the memory of ``frames`` frames on W workers."""
    n, parent = [r["frames"] for r in rows], [r["parent_mb"] for r in rows]
    c, d = fit_line(n, parent) if len(rows) > 1 else (float(parent[0]), 0.0)
    worker = max(r["worker_max_mb"] for r in rows)
    parent_at = c + d * frames
    return {"parent_mb": {"c": round(float(c)), "d_per_frame": round(float(d), 3), f"at_{frames}": round(float(parent_at))},
            "worker_mb": round(worker),
            f"total_mb_at_{frames}": {str(w): round(float(parent_at + w * worker)) for w in (1, 2, 8, 16)},
            f"workers_in_{machine_gb:g}_gb": int(max(0, (machine_gb * 1024 - parent_at) // max(worker, 1.0)))}


def main():
    from wirescene.core.jsonio import dumps, write_json

    argv = sys.argv[1:]
    eval_args = ["--variant", "coarse", "--detections", "gt"]
    if "--" in argv:
        i = argv.index("--")
        argv, eval_args = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work_dir", type=Path, help="directory for the linked KITTI root and the runs' outputs")
    ap.add_argument("--root", type=Path, required=True, help="KITTI root whose labelled frames are repeated")
    ap.add_argument("--frames", default="72,720", help="numbers of frames, comma-separated")
    ap.add_argument("--workers", type=int, default=2, help="--workers of the evaluations")
    ap.add_argument("--json", type=Path, default=None, help="write the rows and the projection here")
    args = ap.parse_args(argv)
    sizes = sorted(int(v) for v in args.frames.split(","))
    # eval fits one worker's or one frame's run in its own process: no worker to measure, the fits in the parent's law
    if args.workers < 2 or sizes[0] < 2:
        ap.error("--workers and every number of --frames must be 2 or more: wirescene eval fits a run of one "
                 "worker or one frame in its own process, so no worker's peak is measured and the parent's holds the fits")
    if not Path("/proc/self/status").is_file():
        raise SystemExit("this benchmark reads /proc (Linux)")
    args.work_dir.mkdir(parents=True, exist_ok=True)
    root, ids = repeated_root(args.root, args.work_dir, max(sizes))
    rows = [run_eval(root, ids[:n], args.work_dir, workers=args.workers, eval_args=eval_args) for n in sizes]
    summary = project(rows)
    print(dumps(summary))
    if args.json:
        write_json(args.json, {"eval_args": eval_args, "rows": rows, "projection": summary})


if __name__ == "__main__":
    main()
