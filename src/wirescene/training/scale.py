"""Training at scale: what keeps the detector-bank training's memory independent of the
number of training frames, and runs its per-image passes in parallel.

* :class:`FrameCache` -- a least-recently-used cache of grey images and HOG pyramids,
  bounded in megabytes (:data:`CACHE`, shared by every training of a process, so that
  cross-validation folds and the held-out calibration's fold banks reuse what is held);
  a pass over more images than it holds recomputes them.
* :class:`NegativePool` -- one configuration's negative descriptors, at most ``cap``:
  random negatives by reservoir sampling, hard negatives kept by margin (the hardest
  under the current SVM, as the cache shrinking of DPM).
* :class:`RowSample` -- a bounded uniform sample of regression rows (the box refinement's).
* :func:`map_images` -- a function over training images, in order, in ``workers`` forked
  processes (each computes its own pyramids), with progress and time left.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import signal
import time
from collections import OrderedDict
from typing import Callable, Iterator, Sequence

import numpy as np

from wirescene.core.workers import end_on_stop_signals

#: Default budget of :data:`CACHE`: the grey images and HOG pyramids (6 levels per
#: octave, up to scale 2) of the 72 shared KITTI frames and their mirror images (144 x
#: 17.3 MB = 2.5 GB): at that scale nothing is computed twice.
DEFAULT_CACHE_MB = 3000

#: Default cap of a configuration's negatives: the shipped recipe on the 72 shared frames
#: gathers at most 144 x (40 + 3 x 15) = 12,240 per configuration, so it never reaches it.
DEFAULT_MAX_NEGATIVES = 12800

#: Most HOG pyramid levels an octave (``train detector --per-octave``, default 6), stored with the
#: bank: each level costs every detection and training pass about a sixth of the default's time
#: (some 86 ms of a KITTI frame's 2.2 s detection) and 0.6 MB of the frame's pyramid; 48 is 8x the
#: default, scales 1.4% apart.
MAX_PER_OCTAVE = 48

#: Most trees of the part model's forest (``train parts --n-trees``, default 30, the paper's): each
#: takes some 2 minutes to grow on the real patches at their cap and up to 6 MB while it is built
#: (16,383 nodes of depth 13), and every fit's part maps take time in proportion: 1,000 trees are
#: some 30 hours and 6 GB of training.
MAX_TREES = 1000

#: Most levels of each tree of the part model's forest (``train parts --max-depth``, default 13, the
#: paper's): a tree stops where its patches run out (leaves of 2), so its nodes and memory are bounded by
#: the patches whatever the limit (unbounded, trees reached 40-42 levels and some 31,000 nodes on the
#: 160,506 real patches of the 72 shared frames, 31 levels on 24 frames' 33,184; 13 and 7,200 at the
#: default), but every fit's part maps step once a level of the deepest tree (some 24 ms a level of
#: 80,000 descriptors, a 5-car frame's: 0.37 s at 13 levels, 1.25 s at 52); 100 leaves any forest free to
#: grow whole, and far beyond it scikit-learn's C integer overflows (2**63) once the patches are made.
MAX_DEPTH = 100

#: Most synthetic scenes of ``train detector`` without ``--kitti-root`` (``--scenes``, default 200):
#: each costs some 0.6 s and 4 MB held to the end (its grey image and car examples), so 2,000 are some
#: 20 minutes and 8 GB before the mining.
MAX_DETECTOR_SCENES = 2000

#: Most held-out synthetic scenes of the synthetic bank's threshold (``--val-scenes``, default 20):
#: some 0.8 s each (a scene drawn and detected), no memory kept: 2,000 are some 27 minutes.
MAX_VAL_SCENES = 2000

#: Most hard-negative mining rounds (``--mining-rounds``, default 2 synthetic, 3 real): each round
#: describes every mined image again (0.7 s a synthetic scene; on KITTI a sixth of the detector
#: step, some 2.5 hours of a 3,712-frame split on one core).
MAX_MINING_ROUNDS = 20

#: Most images a hard-negative mining round searches (``--mining-images``; default: synthetic 80, real
#: all): beyond the training images a round searches them all, so it never costs more than the real
#: default (some 0.7 s a synthetic scene and 1.2 s a KITTI image a round, no memory kept); 100,000 is 6.7x
#: KITTI's training split with its mirror images (14,962).
MAX_MINING_IMAGES = 100_000

#: Most partial configurations a viewpoint (``--partial``, default 3; plus the full car): the greedy
#: choice finds no more than some 7 a viewpoint (a connected 3-4 vertex set seen in 90% of the viewpoint's
#: cars, overlapping those chosen by IoU 0.3 at most: 49 configurations from ``--partial 10`` on the 72
#: shared frames, 32 by default); were 20 found, each of the 168 configurations would cost its share of
#: every detection (some 70 ms of a KITTI frame's 2.2 s) and up to 61 MB of negatives (10 GB).
MAX_PARTIAL = 20

#: Most held-out calibration folds of ``train all --folds`` (default 4; fewer where there are fewer
#: drives): each fold trains a bank on the other folds' frames, about the detector step again (some
#: 13 minutes on the 72 shared frames, 11 hours on a 3,712-frame split on one core), and a part forest;
#: 25 is the 25 drives of the shared frames one a fold, 6x the default's time.
MAX_FOLDS = 25

#: Most cars pasted into each composite frame (``--cut-paste``, default 0): a KITTI frame has room for
#: a few tens, and every car beyond the room still costs its placement tries against all those placed.
MAX_CUT_PASTE = 50

#: Most of a configuration's negatives (``--max-negatives``, default :data:`DEFAULT_MAX_NEGATIVES`):
#: a descriptor is some 4.8 kB (the shipped bank's 32 templates average 1,198 floats), so 32
#: configurations at 100,000 hold 15 GB, which with the rest of the step (some 4 GB) fits 24 GB.
MAX_NEGATIVES = 100_000

#: Most megabytes of :data:`CACHE` (``--pyramid-cache-mb``, default :data:`DEFAULT_CACHE_MB`): the
#: cache fills up to it on a large split, and the step needs some 6 GB besides (README, "Scale"), so
#: 16,000 keeps the step within 24 GB.
MAX_CACHE_MB = 16_000

#: Most synthetic shaded scenes of the part model's patches (``train parts --synth-scenes``, default
#: 300): some 1.3 s and 4 MB of patches each, not capped as the real patches are, so 3,000 are some
#: 12 GB and an hour before the forest.
MAX_PART_SCENES = 3000

#: Most CAD edge renderings a car of ``train parts --n-views`` (views; default 0, none) and of
#: ``--n-aug`` (copies a view; default 2).
MAX_VIEWS = 360
MAX_AUG = 20

#: Most held-out synthetic scenes of ``train occlusion --scenes`` (default 30): some 1.6 s each, the
#: cars' small arrays kept: 3,000 are some 80 minutes.
MAX_OCCLUSION_SCENES = 3000

#: Default cap of the box refinement's regression rows (:class:`RowSample`): the 72 shared
#: frames give 11,572 (jittered label boxes and the bank's own detections), below it.
DEFAULT_MAX_REFINEMENT_ROWS = 16000


class FrameCache:
    """Least-recently-used values (numpy arrays or lists of ``(scale, array)``) within
    ``max_mb`` megabytes."""

    def __init__(self, max_mb: float = DEFAULT_CACHE_MB):
        self.max_bytes = int(max_mb * 1e6)
        self.bytes = 0
        self.hits = self.misses = 0
        self._items: OrderedDict = OrderedDict()

    def __len__(self) -> int:
        return len(self._items)

    def resize(self, max_mb: float) -> None:
        """Set the budget to ``max_mb`` megabytes, dropping the oldest values beyond it."""
        self.max_bytes = int(max_mb * 1e6)
        self._evict()

    def clear(self) -> None:
        """Drop every value (a training's images are not needed by what follows it)."""
        self._items.clear()
        self.bytes = 0

    def get(self, key, compute: Callable[[], object]):
        """The value of ``key``, from ``compute()`` (and kept, budget permitting) if not held."""
        if key in self._items:
            self._items.move_to_end(key)
            self.hits += 1
            return self._items[key][0]
        self.misses += 1
        value = compute()
        self.put(key, value)
        return value

    def put(self, key, value) -> None:
        """Keep ``value`` under ``key`` unless it alone exceeds the budget."""
        size = _nbytes(value)
        if size > self.max_bytes:
            return
        if key in self._items:
            self.bytes -= self._items.pop(key)[1]
        self._items[key] = (value, size)
        self.bytes += size
        self._evict()

    def _evict(self) -> None:
        while self.bytes > self.max_bytes and self._items:
            self.bytes -= self._items.popitem(last=False)[1][1]


def _nbytes(value) -> int:
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    return int(sum(F.nbytes for _, F in value))


#: The process's cache of training images and pyramids (:class:`FrameCache`).
CACHE = FrameCache()


class NegativePool:
    """Negative descriptors of one configuration, at most ``cap`` (None: unbounded).

    Random negatives beyond the cap replace held ones by reservoir sampling (every
    random window offered so far is held with the same probability); hard negatives are
    appended, and :meth:`shrink` keeps the ``cap`` of highest margin under an SVM. Below
    the cap nothing is drawn or dropped: the pool is the plain list of what was added.
    ``rng`` draws the reservoir's replacements (its own stream: the training's is untouched).
    """

    def __init__(self, cap: int | None, rng: np.random.Generator):
        self.cap = cap
        self.items: list[np.ndarray] = []
        self.offered = 0
        self._rng = rng

    def __len__(self) -> int:
        return len(self.items)

    def add_random(self, x: np.ndarray) -> None:
        """Offer a random negative (Algorithm R)."""
        self.offered += 1
        if self.cap is None or len(self.items) < self.cap:
            self.items.append(x)
            return
        j = int(self._rng.integers(self.offered))
        if j < self.cap:
            self.items[j] = x

    append = add_random  # filled like a list by :func:`~wirescene.training.detector.sample_random_negatives`

    def add_hard(self, x: np.ndarray) -> None:
        """Append a hard negative (:meth:`shrink` bounds the pool)."""
        self.items.append(x)

    def shrink(self, weights: np.ndarray, bias: float, *, slack: float = 1.0) -> None:
        """Keep the ``cap`` negatives of highest margin ``weights . x + bias`` (ties: the
        earlier; order kept) once the pool holds more than ``slack * cap``."""
        if self.cap is None or len(self.items) <= slack * self.cap:
            return
        margin = np.stack(self.items) @ np.asarray(weights, np.float32).ravel() + bias
        keep = np.sort(np.argsort(-margin, kind="stable")[:self.cap])
        self.items = [self.items[k] for k in keep]


def lowest_keys(keys: np.ndarray, k: int) -> np.ndarray:
    """Indices of the ``k`` lowest of ``keys``, in their original order (bottom-k sampling:
    with uniform random keys, a uniform sample of the rows that keeps their order)."""
    return np.sort(np.argpartition(keys, k - 1)[:k])


class RowSample:
    """At most ``max_rows`` rows of parallel arrays (None: all), a uniform sample of every
    row added, in the order they came (:func:`lowest_keys`; each row draws a key from its
    own stream: ``rng``, else one of ``seed``). Below the cap nothing is dropped; it holds
    at most 1.5 times the cap at once."""

    def __init__(self, max_rows: int | None, *, seed: int = 0, rng: np.random.Generator | None = None):
        self.max_rows = max_rows
        self.parts: list[tuple[np.ndarray, ...]] = []
        self.keys: list[np.ndarray] = []
        self.n = 0
        self.offered = 0
        self._rng = np.random.default_rng([seed, 7]) if rng is None else rng

    def add(self, *arrays: np.ndarray) -> None:
        """Add rows (every array with the same number of rows)."""
        n = len(arrays[0])
        self.parts.append(arrays)
        self.keys.append(self._rng.random(n))
        self.n += n
        self.offered += n
        if self.max_rows is not None and self.n > 1.5 * self.max_rows:
            self._shrink()

    def _shrink(self) -> None:
        keys = np.concatenate(self.keys)
        keep = lowest_keys(keys, self.max_rows)
        self.parts = [tuple(np.concatenate(col)[keep] for col in zip(*self.parts))]
        self.keys, self.n = [keys[keep]], len(keep)

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The kept rows, one concatenated array per column."""
        if self.max_rows is not None and self.n > self.max_rows:
            self._shrink()
        return tuple(np.concatenate(col) for col in zip(*self.parts))


# --------------------------------------------------------------------------- parallel passes

_TASK: tuple | None = None  # (function, items) of the pass being run: forked workers inherit it


def _run_task(index: int):
    fn, items = _TASK
    return fn(items[index])


def _worker_init() -> None:
    # what the parent held is shared (copy-on-write); a worker keeps nothing new
    CACHE.max_bytes = 0
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:  # a parent that ignores Ctrl-C waits on its workers
        signal.signal(signal.SIGINT, _end_quietly)
    end_on_stop_signals()  # the pool's own stop (terminate()) is SIGTERM


def _end_quietly(signum, frame) -> None:
    """A worker's Ctrl-C (it reaches the whole process group): the worker ends, as it would by
    default, without the traceback every worker would print; the parent says it was interrupted.
    Not ignored: the pool's shutdown would wait on a worker that still sends a result."""
    raise SystemExit(1)


def single_thread():
    """A context in which the BLAS / OpenMP libraries run on one thread: what they sum in
    float32 (window scores, Gram matrices) then does not depend on the machine's cores, so a
    training gives the same artefact everywhere (workers are processes, not threads)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - installed with scikit-learn
        return contextlib.nullcontext()
    return threadpool_limits(1)


def single_threaded(fn: Callable) -> Callable:
    """``fn`` run inside :func:`single_thread`."""
    @functools.wraps(fn)
    def run(*args, **kwargs):
        with single_thread():
            return fn(*args, **kwargs)

    return run


def can_fork() -> bool:
    """Whether worker processes can be forked here (else passes run serially)."""
    return "fork" in multiprocessing.get_all_start_methods()


def map_images(fn: Callable, items: Sequence, *, workers: int = 1, progress=None, name: str = "images") -> Iterator:
    """``fn(item)`` for every item, in order: serially (``workers`` <= 1, or where
    processes cannot be forked) or in ``workers`` forked processes. ``progress`` receives
    lines with the images done, the elapsed time and the time left."""
    global _TASK
    tick = _ticker(progress, name, len(items))
    if workers <= 1 or len(items) < 2 or not can_fork():
        for i, item in enumerate(items):
            result = fn(item)
            tick(i + 1)
            yield result
        return
    _TASK = (fn, items)
    try:
        with multiprocessing.get_context("fork").Pool(min(workers, len(items)), initializer=_worker_init) as pool:
            for i, result in enumerate(pool.imap(_run_task, range(len(items)))):
                tick(i + 1)
                yield result
    finally:
        _TASK = None


def _ticker(progress, name: str, total: int, *, every_s: float = 10.0) -> Callable[[int], None]:
    """``tick(done)`` saying ``name: done/total images, elapsed, left`` at most every
    ``every_s`` seconds, and at the end of a pass that took longer."""
    if progress is None or not total:
        return lambda done: None
    t0 = time.perf_counter()
    last = [t0]

    def tick(done: int) -> None:
        now = time.perf_counter()
        if now - last[0] < every_s:
            return
        last[0] = now
        left = (now - t0) / done * (total - done)
        progress(f"{name}: {done}/{total} images, {now - t0:.0f} s, ~{left:.0f} s left")

    return tick
