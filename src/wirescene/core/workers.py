"""What a run's worker processes share, whichever pool starts them (the evaluation's frames,
the training's per-image passes): the cores they may use, and what the stop signals do in
them."""

from __future__ import annotations

import os
import signal

__all__ = ["usable_cores", "end_on_stop_signals"]


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity where the system tells it (a job
    scheduler's or a container's share of the machine, e.g. ``taskset`` or a SLURM
    allocation), else every core of the machine.

    Examples
    --------
    >>> 1 <= usable_cores() <= (os.cpu_count() or 1)
    True
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # macOS and Windows have no affinity call
        return os.cpu_count() or 1


def end_on_stop_signals() -> None:
    """In a worker process: SIGTERM (a pool's own stop) and SIGHUP (a closed terminal) end it
    at once, by the default action, not by a handler its parent's command set before the
    fork; a SIGHUP the parent ignores (``nohup``) stays ignored. Workers write no file, so
    there is nothing to clean up: the parent does that."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "SIGHUP") and signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
        signal.signal(signal.SIGHUP, signal.SIG_DFL)
