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

from typing import Iterator, Mapping

import numpy as np

#: Bootstrap draws of an interval unless told otherwise.
N_BOOT = 10000
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
    """
    out = {}
    for variant, report in reports.items():
        frames = [r.frame_id for r in report.records]
        clusters = [cluster_of.get(f, (f,)) for f in frames]  # a frame of no known drive: a cluster of its own
        index = {c: i for i, c in enumerate(dict.fromkeys(clusters))}
        rows = np.array([index[c] for c in clusters], int)
        within = np.array([r.loc_error < threshold for r in report.records], float)
        n = np.bincount(rows, minlength=len(index)).astype(float)
        k = np.bincount(rows, weights=within, minlength=len(index))
        share, interval = clustered_share(k, n, n_boot=n_boot, seed=seed)
        alone = sum(isinstance(c, tuple) for c in index)
        out[variant] = {"share": share if frames else None, "interval": interval, "true_positives": len(frames),
                        "drives": len(index) - alone, "frames_alone": alone}
    return out


def format_intervals(intervals: Mapping[str, dict], *, threshold: float = 1.0) -> str:
    """Lines of :func:`localisation_intervals`' figures, a variant a line."""
    lines = [f"Within {threshold:g} m, 90% bootstrap interval over drives (other drives could move the share so far; "
             "a frame of no known drive is drawn alone):"]
    width = max([len(v) for v in intervals] + [7])
    for variant, f in intervals.items():
        if f["interval"] is None:
            lines.append(f"  {variant.ljust(width)}  -")
            continue
        n_alone = f["frames_alone"]
        alone = f" and {n_alone} frame{'s' * (n_alone != 1)} of no known drive" if n_alone else ""
        lines.append(f"  {variant.ljust(width)}  {f['share']:.1f}% [{f['interval'][0]:.1f}, {f['interval'][1]:.1f}] "
                     f"of {f['true_positives']} true positives, {f['drives']} drives{alone}")
    return "\n".join(lines)
