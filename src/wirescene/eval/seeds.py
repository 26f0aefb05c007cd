"""One evaluation repeated with several seeds: each figure per seed, its mean and its range.

The fine stage samples, so the seed alone moves a variant's figures: over seven seeds of the
same label boxes on the 294 shared cars (the README's "The seed moves the fine rows"), ``full``
scores 3D AP@0.7 from 11.4 to 14.9 and places 53.4% to 58.2% of the cars within 1 m. A
difference between two settings smaller than that range is noise, so ``wirescene eval --seed 1
--seed 2 ...`` reports every seed's figures and these summaries.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from wirescene.eval.kitti_metrics import kitti_figure

#: Most seeds of one evaluation (``eval --seed``, repeated): each evaluates every frame again (some
#: 0.4 s a frame of ``coarse``, 6 s of ``full``: 6 hours of ``full`` a seed on the 3,769 val frames on
#: one core) and keeps its figures, and with ``--json`` its records (some 2.6 kB a frame of ``coarse``),
#: to the end; 100 is 14x the seven seeds above.
MAX_SEEDS = 100

#: ``(column, source, key)``: figures of the paper's protocol (``metrics``: a variant's
#: :class:`~wirescene.eval.metrics.EvaluationReport` figures over all cars) and KITTI's moderate
#: R40 APs (``kitti``: ``(block, metric)`` of :func:`~wirescene.eval.kitti_metrics.kitti_figure`).
FIGURES: tuple = (
    ("TP", "metrics", "n_tp"),
    ("<1m %", "metrics", "loc_1m"),
    ("<1.5m %", "metrics", "loc_1_5m"),
    ("med az", "metrics", "median_az3d"),
    ("2d@.7", "kitti", ("car", "2d")),
    ("bev@.7", "kitti", ("car", "bev")),
    ("3d@.7", "kitti", ("car", "3d")),
    ("3d@.5", "kitti", ("iou_0.5", "3d")),
)

#: Columns of :data:`FIGURES` that count cars (their range is printed without decimals).
COUNTS = ("TP",)


def seed_folder(seed) -> str:
    """The folder of one seed's outputs (its predictions, its report page) where an evaluation
    has several seeds.

    Examples
    --------
    >>> seed_folder(3)
    'seed-3'
    """
    return f"seed-{seed}"


def _finite(v) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


def seed_figures(metrics: Mapping[str, Mapping], kitti: Mapping[str, dict]) -> dict[str, dict[str, float | None]]:
    """``{variant: {column: figure}}`` of one seed's evaluation (:data:`FIGURES`).

    Parameters
    ----------
    metrics : {variant: dict}
        Each variant's figures over all cars (``EvaluationReport.metrics["all"]``).
    kitti : {variant: dict}
        Each variant's :func:`~wirescene.eval.kitti_metrics.kitti_metrics` result; a variant
        without one has no KITTI figures (None).

    Examples
    --------
    >>> figs = seed_figures({"full": {"n_tp": 9, "loc_1m": 55.5, "loc_1_5m": 66.6, "median_az3d": 2.0}}, {})
    >>> figs["full"]["TP"], figs["full"]["3d@.7"]
    (9.0, None)
    """
    out = {}
    for v, m in metrics.items():
        row = {}
        for column, source, key in FIGURES:
            if source == "metrics":
                row[column] = _finite(m.get(key))
            else:
                row[column] = _finite(kitti_figure(kitti[v], *key)["moderate"]) if v in kitti else None
        out[v] = row
    return out


def over_seeds(per_seed: Mapping[int, Mapping[str, Mapping[str, float | None]]]) -> dict[str, dict[str, dict]]:
    """``{variant: {column: {"mean", "min", "max", "values"}}}`` of :func:`seed_figures` of
    several seeds ``{seed: figures}``; ``values`` in the seeds' order, the summaries over the
    seeds that have the figure (None where none has).

    Examples
    --------
    >>> s = over_seeds({1: {"full": {"TP": 9.0}}, 2: {"full": {"TP": 11.0}}})
    >>> s["full"]["TP"]["mean"], s["full"]["TP"]["min"], s["full"]["TP"]["max"]
    (10.0, 9.0, 11.0)
    """
    seeds = list(per_seed)
    if not seeds:
        raise ValueError("no seeds to summarise")
    variants = list(per_seed[seeds[0]])
    for s in seeds[1:]:
        if list(per_seed[s]) != variants:
            raise ValueError(f"seed {s} evaluated variants {list(per_seed[s])}, seed {seeds[0]} {variants}")
    out: dict[str, dict[str, dict]] = {}
    for v in variants:
        out[v] = {}
        for column in per_seed[seeds[0]][v]:
            values = [per_seed[s][v].get(column) for s in seeds]
            known = [x for x in values if x is not None]
            out[v][column] = {"mean": sum(known) / len(known) if known else None,
                              "min": min(known) if known else None, "max": max(known) if known else None,
                              "values": values}
    return out


def mean_and_range(figure: Mapping, column: str) -> tuple[str, str]:
    """One figure of :func:`over_seeds` in words: its mean (one decimal) and its range ``min-max``
    over the seeds (without decimals for a count of :data:`COUNTS`); ``-`` where no seed has it.

    Examples
    --------
    >>> mean_and_range(over_seeds({1: {"full": {"TP": 9.0}}, 2: {"full": {"TP": 11.0}}})["full"]["TP"], "TP")
    ('10.0', '9-11')
    """
    digits = 0 if column in COUNTS else 1
    mean = "-" if figure["mean"] is None else f"{figure['mean']:.1f}"
    spread = "-" if figure["min"] is None else f"{figure['min']:.{digits}f}-{figure['max']:.{digits}f}"
    return mean, spread


def format_over_seeds(summary: Mapping[str, Mapping[str, dict]], seeds) -> str:
    """A table of :func:`over_seeds`: per variant and figure the mean and, below it, the range
    ``min-max`` over ``seeds`` (:func:`mean_and_range`).

    Examples
    --------
    >>> print(format_over_seeds(over_seeds({1: {"full": {"TP": 9.0}}, 2: {"full": {"TP": 11.0}}}), [1, 2]))
    Over 2 seeds (1, 2): mean, and below it min-max
    variant          TP
    full           10.0
                   9-11
    """
    seeds = list(seeds)
    columns = list(next(iter(summary.values())))
    name_w = max(len("variant"), *(len(v) for v in summary))
    lines = [f"Over {len(seeds)} seeds ({', '.join(map(str, seeds))}): mean, and below it min-max",
             f"{'variant':<{name_w}} " + " ".join(f"{c:>11}" for c in columns)]
    for v, figures in summary.items():
        cells = [mean_and_range(figures[c], c) for c in columns]
        lines.append(f"{v:<{name_w}} " + " ".join(f"{mean:>11}" for mean, _ in cells))
        lines.append(f"{'':<{name_w}} " + " ".join(f"{spread:>11}" for _, spread in cells))
    return "\n".join(lines)
