"""How far other drives could move a figure: bootstrap intervals clustered by drive.

Cars of one recording drive share their road, their light and often their parked rows,
so they pass or fail together; a set of frames from few drives holds fewer independent
draws than it holds cars. These intervals resample whole drives (clusters) with
replacement and recompute the pooled share each time; the 5th and 95th percentiles of
the draws give a 90% interval of what another set of drives like these could show.

Examples
--------
>>> from wirescene.eval.intervals import clustered_share
>>> share, (lo, hi) = clustered_share([9, 1], [10, 10], n_boot=200)
>>> share, lo <= 50.0 <= hi
(50.0, True)
"""

from __future__ import annotations

from functools import partial
from typing import Iterator, Mapping, Sequence

import numpy as np

from wirescene.eval.kitti_metrics import DIFFICULTIES, MIN_OVERLAP, average_precision, drawn_alike, kitti_curves

#: Bootstrap draws of an interval unless told otherwise.
N_BOOT = 10000
#: Draws of a KITTI AP interval (each draw re-ranks every estimate: 1,000 draws of a 3,769-frame split take
#: seconds per figure).
N_BOOT_AP = 1000
#: Most draws of a KITTI AP interval (``--draws``): 100x :data:`N_BOOT_AP`, some minutes a figure of a
#: 3,769-frame split; memory does not grow with them (:data:`_CHUNK` at once).
MAX_BOOT_AP = 100_000
#: Draws generated at once (memory: ``_CHUNK x clusters`` floats).
_CHUNK = 1000


def bootstrap_weights(n_clusters: int, n_boot: int, *, seed: int = 0) -> Iterator[np.ndarray]:
    """Chunks ``(<= 1000, n_clusters)`` float of ``n_boot`` bootstrap samples: how often each
    cluster is drawn in each sample of ``n_clusters`` clusters drawn with replacement (one
    random stream, so the draws do not depend on the chunking).

    Examples
    --------
    >>> [w.sum(axis=1).tolist() for w in bootstrap_weights(3, 2, seed=0)]
    [[3.0, 3.0]]
    """
    if n_clusters < 1 or n_boot < 1:
        raise ValueError(f"bootstrap needs at least one cluster and one draw, got {n_clusters} and {n_boot}")
    rng = np.random.default_rng(seed)
    p = np.full(n_clusters, 1.0 / n_clusters)
    for start in range(0, n_boot, _CHUNK):
        yield rng.multinomial(n_clusters, p, size=min(_CHUNK, n_boot - start)).astype(float)


def percentile_interval(draws, *, level: float = 90.0) -> tuple[float, float]:
    """The central ``level`` % interval of the finite ``draws``.

    Examples
    --------
    >>> percentile_interval(np.arange(101.0))
    (5.0, 95.0)
    """
    draws = np.asarray(draws, float)
    draws = draws[np.isfinite(draws)]
    if draws.size == 0:
        raise ValueError("no finite bootstrap draw")
    tail = (100.0 - level) / 2.0
    return float(np.percentile(draws, tail)), float(np.percentile(draws, 100.0 - tail))


def clustered_share(k, n, *, n_boot: int = N_BOOT, seed: int = 0,
                    level: float = 90.0) -> tuple[float, tuple[float, float] | None]:
    """A pooled share in percent and its cluster bootstrap interval.

    Parameters
    ----------
    k, n : (C,) array_like
        Per cluster (e.g. drive), the cars that pass and the cars counted.
    n_boot : int, keyword-only
        Bootstrap draws; 0 gives no interval.
    seed : int, keyword-only
    level : float, keyword-only
        Width of the interval in percent.

    Returns
    -------
    share : float
        ``100 sum(k) / sum(n)`` (NaN without cars).
    interval : (float, float) or None
        Its central ``level`` % bootstrap interval (None without draws or cars).

    Examples
    --------
    >>> share, interval = clustered_share([3, 0], [4, 0], n_boot=0)
    >>> share, interval
    (75.0, None)
    """
    k, n = np.asarray(k, float), np.asarray(n, float)
    if k.shape != n.shape or k.ndim != 1:
        raise ValueError(f"per-cluster counts of one shape (C,) expected, got {k.shape} and {n.shape}")
    if np.any(k < 0) or np.any(k > n):
        raise ValueError("per-cluster counts need 0 <= k <= n")
    total = n.sum()
    share = 100.0 * k.sum() / total if total > 0 else float("nan")
    if n_boot <= 0 or total <= 0:
        return float(share), None
    draws = []
    for w in bootstrap_weights(len(k), n_boot, seed=seed):
        with np.errstate(invalid="ignore", divide="ignore"):
            draws.append(100.0 * (w @ k) / (w @ n))
    return float(share), percentile_interval(np.concatenate(draws), level=level)


def clustered_margin(k, n, k_ref, n_ref, *, n_boot: int = N_BOOT, seed: int = 0,
                     level: float = 90.0) -> tuple[float, tuple[float, float] | None]:
    """A margin in points between two pooled shares over the same clusters, and its paired
    bootstrap interval (each draw takes the same clusters for both).

    Parameters
    ----------
    k, n : (C,) array_like
        Per cluster, the cars that pass and the cars counted, of one variant.
    k_ref, n_ref : (C,) array_like
        The same of the reference.
    n_boot, seed : int, keyword-only
        Draws (0: none).
    level : float, keyword-only

    Returns
    -------
    margin : float
        ``100 (sum k / sum n - sum k_ref / sum n_ref)`` (NaN without cars).
    interval : (float, float) or None

    Examples
    --------
    >>> margin, _ = clustered_margin([10, 1], [20, 10], [5, 2], [20, 10], n_boot=0)
    >>> round(margin, 1)
    13.3
    """
    counts = [np.asarray(a, float) for a in (k, n, k_ref, n_ref)]
    if len({c.shape for c in counts}) != 1 or counts[0].ndim != 1:
        raise ValueError(f"per-cluster counts of one shape (C,) expected, got {[c.shape for c in counts]}")
    k, n, k_ref, n_ref = counts
    if np.any(k < 0) or np.any(k > n) or np.any(k_ref < 0) or np.any(k_ref > n_ref):
        raise ValueError("per-cluster counts need 0 <= k <= n")

    def margin(w):
        with np.errstate(invalid="ignore", divide="ignore"):
            return 100.0 * ((w @ k) / (w @ n) - (w @ k_ref) / (w @ n_ref))

    point = float(margin(np.ones(len(k))))
    if n_boot <= 0 or not np.isfinite(point):
        return point, None
    draws = np.concatenate([margin(w) for w in bootstrap_weights(len(k), n_boot, seed=seed)])
    return point, percentile_interval(draws, level=level) if np.isfinite(draws).any() else None


def _clusters(frame_ids: Sequence[str], cluster_of: Mapping[str, str]) -> tuple[np.ndarray, int, int]:
    """Each frame's cluster index, the number of clusters and how many are lone frames of no known drive."""
    clusters = [cluster_of.get(f, (f,)) for f in frame_ids]  # a frame of no known drive: a cluster of its own
    index = {c: i for i, c in enumerate(dict.fromkeys(clusters))}
    alone = sum(isinstance(c, tuple) for c in index)
    return np.array([index[c] for c in clusters], int), len(index), alone


def localisation_intervals(reports: Mapping, cluster_of: Mapping[str, str], *, threshold: float = 1.0,
                           n_boot: int = N_BOOT, seed: int = 0) -> dict[str, dict]:
    """Per variant, the share of true positives localised within ``threshold`` metres (the
    paper's Table 1) with its bootstrap interval over clusters of frames.

    Parameters
    ----------
    reports : mapping
        ``{variant: EvaluationReport}`` (:func:`wirescene.eval.metrics.evaluate`).
    cluster_of : mapping
        ``{frame id: drive}``; a frame it lacks is a cluster of its own.
    threshold : float, keyword-only
        Metres (Table 1's 1 m by default).
    n_boot, seed : int, keyword-only

    Returns
    -------
    dict
        ``{variant: {"share", "interval", "true_positives", "drives", "frames_alone"}}``:
        ``drives`` the drives with a true positive, ``frames_alone`` the frames of no known
        drive with one (each drawn on its own); ``share`` None without true positives.

    Examples
    --------
    >>> from wirescene.eval.metrics import EvaluationReport, TPRecord
    >>> def report(errors):  # a true positive in each of frames 000000, 000001, ... with these errors (m)
    ...     records = [TPRecord(f"{i:06d}", 0, 0, 0.9, e, 0.0, 0.0, True, None, 0) for i, e in enumerate(errors)]
    ...     return EvaluationReport({}, records, "kitti_flag", "applied")
    >>> drives = {"000000": "d1", "000001": "d1", "000002": "d2", "000003": "d2"}
    >>> reports = {"ours": report([0.5, 0.8, 2.0, 3.0]), "base": report([0.5, 2.0, 2.5, 3.0])}
    >>> out = localisation_intervals(reports, drives, n_boot=200)
    >>> out["ours"]  # 2 of 4 within 1 m; drawing drive d1 twice gives 100%, d2 twice 0%
    {'share': 50.0, 'interval': (0.0, 100.0), 'true_positives': 4, 'drives': 2, 'frames_alone': 0}
    """
    out = {}
    for variant, report in reports.items():
        frames = [r.frame_id for r in report.records]
        rows, n_clusters, alone = _clusters(frames, cluster_of)
        within = np.array([r.loc_error < threshold for r in report.records], float)
        n = np.bincount(rows, minlength=n_clusters).astype(float)
        k = np.bincount(rows, weights=within, minlength=n_clusters)
        share, interval = clustered_share(k, n, n_boot=n_boot, seed=seed)
        out[variant] = {"share": share if frames else None, "interval": interval, "true_positives": len(frames),
                        "drives": n_clusters - alone, "frames_alone": alone}
    return out


def margin_intervals(reports: Mapping, cluster_of: Mapping[str, str], *, reference: str, threshold: float = 1.0,
                     n_boot: int = N_BOOT, seed: int = 0) -> dict[str, dict]:
    """Per variant other than ``reference``, its margin over the reference in points of the
    true positives within ``threshold`` metres, with a paired bootstrap interval over
    clusters of frames (:func:`clustered_margin`: each draw takes the same drives for both).

    Parameters
    ----------
    reports : mapping
        ``{variant: EvaluationReport}``; must hold ``reference``.
    cluster_of : mapping
        ``{frame id: drive}``; a frame it lacks is a cluster of its own.
    reference : str, keyword-only
    threshold : float, keyword-only
    n_boot, seed : int, keyword-only

    Returns
    -------
    dict
        ``{variant: {"reference", "margin", "interval", "drives", "frames_alone"}}``: ``drives``
        and ``frames_alone`` those of either variant's true positives, the clusters drawn.

    Examples
    --------
    >>> from wirescene.eval.metrics import EvaluationReport, TPRecord
    >>> def report(errors):  # a true positive in each of frames 000000, 000001, ... with these errors (m)
    ...     records = [TPRecord(f"{i:06d}", 0, 0, 0.9, e, 0.0, 0.0, True, None, 0) for i, e in enumerate(errors)]
    ...     return EvaluationReport({}, records, "kitti_flag", "applied")
    >>> drives = {"000000": "d1", "000001": "d1", "000002": "d2", "000003": "d2"}
    >>> reports = {"ours": report([0.5, 0.8, 2.0, 3.0]), "base": report([0.5, 2.0, 2.5, 3.0])}
    >>> margin_intervals(reports, drives, reference="base", n_boot=200)  # 50% - 25%
    {'ours': {'reference': 'base', 'margin': 25.0, 'interval': (0.0, 50.0), 'drives': 2, 'frames_alone': 0}}
    """
    if reference not in reports:
        raise ValueError(f"reference variant {reference!r} is not among {sorted(reports)}")
    out = {}
    for variant, report in reports.items():
        if variant == reference:
            continue
        pair = (report.records, reports[reference].records)
        rows, n_clusters, alone = _clusters([r.frame_id for records in pair for r in records], cluster_of)
        counts = []
        for records, at in zip(pair, (rows[: len(pair[0])], rows[len(pair[0]):])):
            within = np.array([r.loc_error < threshold for r in records], float)
            counts += [np.bincount(at, weights=within, minlength=n_clusters),
                       np.bincount(at, minlength=n_clusters).astype(float)]
        margin, interval = clustered_margin(*counts, n_boot=n_boot, seed=seed)
        out[variant] = {"reference": reference, "margin": margin if np.isfinite(margin) else None,
                        "interval": interval, "drives": n_clusters - alone, "frames_alone": alone}
    return out


def format_intervals(intervals: Mapping[str, dict], *, threshold: float = 1.0,
                     margins: Mapping[str, dict] | None = None) -> str:
    """Lines of :func:`localisation_intervals`' figures, a variant a line, and of
    :func:`margin_intervals`' if given.

    Examples
    --------
    >>> from wirescene.eval.metrics import EvaluationReport, TPRecord
    >>> def report(errors):  # a true positive in each of frames 000000, 000001, ... with these errors (m)
    ...     records = [TPRecord(f"{i:06d}", 0, 0, 0.9, e, 0.0, 0.0, True, None, 0) for i, e in enumerate(errors)]
    ...     return EvaluationReport({}, records, "kitti_flag", "applied")
    >>> drives = {"000000": "d1", "000001": "d1", "000002": "d2", "000003": "d2"}
    >>> reports = {"ours": report([0.5, 0.8, 2.0, 3.0]), "base": report([0.5, 2.0, 2.5, 3.0])}
    >>> spread = localisation_intervals(reports, drives, n_boot=200)
    >>> margins = margin_intervals(reports, drives, reference="base", n_boot=200)
    >>> print(format_intervals(spread, margins=margins))
    Within 1 m, 90% bootstrap interval over drives (...):
      ours     50.0% [0.0, 100.0] of 4 true positives, 2 drives
      base     25.0% [0.0, 50.0] of 4 true positives, 2 drives
    Margins over base in points within 1 m, the same drives drawn for both:
      ours     +25.0 [+0.0, +50.0]
    """
    lines = [f"Within {threshold:g} m, 90% bootstrap interval over drives (other drives could move the share so far; "
             "a frame of no known drive is drawn alone):"]
    width = max([len(v) for v in intervals] + [7])
    for variant, f in intervals.items():
        if f["interval"] is None:
            lines.append(f"  {variant.ljust(width)}  -")
            continue
        n_alone, n_drives = f["frames_alone"], f["drives"]
        alone = f" and {n_alone} frame{'s' * (n_alone != 1)} of no known drive" if n_alone else ""
        # one cluster drawn again and again: [x, x] would read as no spread, not as no measure of it
        span = (f"[{f['interval'][0]:.1f}, {f['interval'][1]:.1f}]" if not drawn_alike(f)
                else f"(no interval: one {'drive' if n_drives else 'frame'})")
        lines.append(f"  {variant.ljust(width)}  {f['share']:.1f}% {span} of {f['true_positives']} true positives, "
                     f"{n_drives} drive{'s' * (n_drives != 1)}{alone}")
    if margins:
        reference = next(iter(margins.values()))["reference"]
        lines.append(f"Margins over {reference} in points within {threshold:g} m, the same drives drawn for both:")
        for variant, f in margins.items():
            # the drives of either variant's true positives drawn: not those of the variant's alone
            span = "" if f["interval"] is None or drawn_alike(f) else " [{:+.1f}, {:+.1f}]".format(*f["interval"])
            lines.append(f"  {variant.ljust(width)}  " + ("-" if f["margin"] is None else f"{f['margin']:+.1f}{span}"))
    return "\n".join(lines)


def _ap_draws(gt_frames, pred_runs, rows, n_clusters, *, difficulty, n_boot, seed) -> dict:
    """``{(min overlap, metric): (n_boot,) AP draws}`` over clusters (``rows``: each frame's
    cluster), NaN where a draw holds no car of the difficulty; none where KITTI gives no figure.
    ``pred_runs``: one or more runs' predictions of the frames; with several, each draw also
    takes one run at random (a stream of its own, so the drawn clusters do not depend on it)."""
    overlaps = (MIN_OVERLAP["car"], 0.5)
    draws: dict = {}
    aos_valid = True
    pick = np.random.default_rng([seed, len(pred_runs)]) if len(pred_runs) > 1 else None
    for w in bootstrap_weights(max(n_clusters, 1), n_boot, seed=seed) if len(rows) else ():
        run = np.zeros(len(w), int) if pick is None else pick.integers(len(pred_runs), size=len(w))
        chunk: dict = {}
        for r in np.unique(run):
            sel = run == r
            curves = kitti_curves(gt_frames, pred_runs[r], min_overlaps=overlaps, difficulties=(difficulty,),
                                  frame_weights=w[sel][:, rows])
            for thr in overlaps:
                aos_valid = aos_valid and curves[thr]["aos_valid"]
                for metric in ("2d", "aos", "bev", "3d"):
                    curve = curves[thr]["2d" if metric == "aos" else metric][difficulty]
                    if curve is None:
                        continue
                    points = curve.orientation if metric == "aos" else curve.precision
                    ap = np.where(curve.n_gt > 0, average_precision(points), np.nan)
                    chunk.setdefault((thr, metric), np.full(len(w), np.nan))[sel] = ap
        for key, ap in chunk.items():
            draws.setdefault(key, []).append(ap)
    return {key: np.concatenate(d) for key, d in draws.items() if aos_valid or key[1] != "aos"}


def _check_frames(gt_frames, preds: Mapping[str, Sequence], frame_ids, difficulty: str) -> None:
    """A ``ValueError`` unless ``difficulty`` is KITTI's and every named prediction sequence
    (``""``: unnamed) has as many frames as ``gt_frames`` and ``frame_ids``."""
    if difficulty not in DIFFICULTIES:
        raise ValueError(f"difficulty must be one of {DIFFICULTIES}, got {difficulty!r}")
    for name, pred_frames in preds.items():
        if not (len(gt_frames) == len(pred_frames) == len(frame_ids)):
            raise ValueError(f"{len(gt_frames)} ground-truth frames, {len(pred_frames)} prediction frames"
                             + (f" of {name}" if name else "") + f" and {len(frame_ids)} frame ids")


def _layout(values: dict, *, difficulty: str, level: float, n_boot: int, n_clusters: int, alone: int,
            margin_over) -> dict:
    """Intervals of AP draws ``{(min overlap, metric): (n_boot,)}`` laid out as
    :func:`~wirescene.eval.kitti_metrics.kitti_metrics` lays out its figures."""
    def interval(thr, metric):
        v = values.get((thr, metric))
        return None if v is None or not np.isfinite(v).any() else list(percentile_interval(v, level=level))

    def block(thr):
        return {m: interval(thr, m) for m in ("2d", "aos", "bev", "3d")}

    return {"car": block(MIN_OVERLAP["car"]), "iou_0.5": {"car": block(0.5)}, "difficulty": difficulty,
            "level": level, "draws": n_boot, "drives": n_clusters - alone, "frames_alone": alone,
            "margin_over": margin_over}


def kitti_intervals(gt_frames: Sequence, pred_frames: Sequence, frame_ids: Sequence[str],
                    cluster_of: Mapping[str, str], *, difficulty: str = "moderate", n_boot: int = N_BOOT_AP,
                    seed: int = 0, level: float = 90.0) -> dict:
    """Bootstrap intervals over clusters of frames of the KITTI Car APs (R40) of one difficulty.

    Each draw takes as many clusters (drives) as there are, with replacement, and evaluates
    the frames they hold by the devkit's rules (:func:`wirescene.eval.kitti_metrics.kitti_curves`
    with frame weights: the estimates are ranked again in every draw, as AP ranks them).

    Parameters
    ----------
    gt_frames, pred_frames : sequences of FrameLabels or lists of Label
        As :func:`wirescene.eval.kitti_metrics.kitti_metrics` takes them.
    frame_ids : sequence of str
        The frames' ids, in the same order.
    cluster_of : mapping
        ``{frame id: drive}``; a frame it lacks is a cluster of its own.
    difficulty : str, keyword-only
        One of easy / moderate / hard.
    n_boot, seed : int, keyword-only
    level : float, keyword-only
        Width of the intervals in percent.

    Returns
    -------
    dict
        ``{"car": {"2d"|"aos"|"bev"|"3d": [lo, hi] or None}, "iou_0.5": {"car": {...}},
        "difficulty", "level", "draws", "drives", "frames_alone", "margin_over"}``, laid out
        as :func:`~wirescene.eval.kitti_metrics.kitti_metrics` lays out its figures; None
        where that gives no figure (or no draw holds a car of the difficulty);
        ``margin_over`` None (see :func:`kitti_variant_intervals`).

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    >>> out = kitti_intervals([[car]] * 50, [[car]] * 50, [f"{i:06d}" for i in range(50)], {}, n_boot=20)
    >>> out["car"]["3d"], out["drives"], out["frames_alone"]
    ([100.0, 100.0], 0, 50)
    """
    spread, _ = kitti_variant_intervals(gt_frames, {"": pred_frames}, frame_ids, cluster_of, difficulty=difficulty,
                                        n_boot=n_boot, seed=seed, level=level)
    return spread[""]


def kitti_variant_intervals(gt_frames: Sequence, preds: Mapping[str, Sequence], frame_ids: Sequence[str],
                            cluster_of: Mapping[str, str], *, reference: str | None = None,
                            difficulty: str = "moderate", n_boot: int = N_BOOT_AP, seed: int = 0,
                            level: float = 90.0) -> tuple[dict[str, dict], dict[str, dict]]:
    """:func:`kitti_intervals` of several estimators' predictions of the same frames, each
    evaluated once per draw on the same drawn drives, and the intervals of their margins
    ``AP - reference AP`` in points.

    Parameters
    ----------
    gt_frames : sequence of FrameLabels or lists of Label
    preds : mapping
        ``{name: predictions of the frames}`` (e.g. a variant's).
    frame_ids, cluster_of, difficulty, n_boot, seed, level
        As :func:`kitti_intervals` takes them.
    reference : str, keyword-only
        A name in ``preds``: the margins are over its APs (None: no margins).

    Returns
    -------
    intervals : dict
        ``{name: intervals}`` as :func:`kitti_intervals` gives them.
    margins : dict
        ``{name: intervals of the margin}`` for every name but the reference, laid out
        alike, with ``margin_over`` the reference.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    >>> ids = [f"{i:06d}" for i in range(50)]
    >>> _, margins = kitti_variant_intervals([[car]] * 50, {"a": [[car]] * 50, "b": [[car]] * 50}, ids, {},
    ...                                      reference="a", n_boot=20)
    >>> margins["b"]["car"]["3d"], margins["b"]["margin_over"]
    ([0.0, 0.0], 'a')
    """
    _check_frames(gt_frames, preds, frame_ids, difficulty)
    if reference is not None and reference not in preds:
        raise ValueError(f"reference {reference!r} is not among {sorted(preds)}")
    rows, n_clusters, alone = _clusters(frame_ids, cluster_of)
    # the same seed and clusters for every name: the same drawn drives, so margins are paired
    draws = {name: _ap_draws(gt_frames, [p], rows, n_clusters, difficulty=difficulty, n_boot=n_boot, seed=seed)
             for name, p in preds.items()}
    layout = partial(_layout, difficulty=difficulty, level=level, n_boot=n_boot, n_clusters=n_clusters, alone=alone)
    intervals = {name: layout(d, margin_over=None) for name, d in draws.items()}
    margins = {name: layout({k: v - draws[reference][k] for k, v in d.items() if k in draws[reference]},
                            margin_over=reference)
               for name, d in draws.items() if reference is not None and name != reference}
    return intervals, margins


def kitti_run_intervals(gt_frames: Sequence, runs: Sequence[Sequence], frame_ids: Sequence[str],
                        cluster_of: Mapping[str, str], *, difficulty: str = "moderate", n_boot: int = N_BOOT_AP,
                        seed: int = 0, level: float = 90.0) -> dict:
    """:func:`kitti_intervals` of several runs of one estimator on the same frames (fits with
    other seeds, say): each draw resamples the drives and takes one of the runs at random, so
    the interval spans what one more run on another set of drives like these could show, the
    sampler's spread and the drives' together.

    Parameters
    ----------
    gt_frames : sequence of FrameLabels or lists of Label
    runs : sequence of sequences
        Each run's predictions of the frames, in the order of ``gt_frames``.
    frame_ids, cluster_of, difficulty, n_boot, seed, level
        As :func:`kitti_intervals` takes them.

    Returns
    -------
    dict
        As :func:`kitti_intervals`, with ``runs`` the number of runs.

    Examples
    --------
    >>> from wirescene.core.labels import Label
    >>> car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    >>> miss = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 25.0], 0.0, 0.9)
    >>> ids = [f"{i:06d}" for i in range(50)]
    >>> out = kitti_run_intervals([[car]] * 50, [[[car]] * 50, [[miss]] * 50], ids, {}, n_boot=40)
    >>> out["car"]["3d"], out["runs"]
    ([0.0, 100.0], 2)
    """
    if not len(runs):
        raise ValueError("no run given")
    _check_frames(gt_frames, {f"run {i}": p for i, p in enumerate(runs)}, frame_ids, difficulty)
    rows, n_clusters, alone = _clusters(frame_ids, cluster_of)
    draws = _ap_draws(gt_frames, list(runs), rows, n_clusters, difficulty=difficulty, n_boot=n_boot, seed=seed)
    out = _layout(draws, difficulty=difficulty, level=level, n_boot=n_boot, n_clusters=n_clusters, alone=alone,
                  margin_over=None)
    out["runs"] = len(runs)
    return out
