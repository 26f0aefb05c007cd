"""An evaluation run as one HTML page with PNG plots (``wirescene eval --report DIR``).

* localisation error against ground-truth depth, with the physical limit of a
  monocular estimate: a car's depth comes from where it touches the ground in the image,
  so one pixel of error there moves it by ``z**2 / (f * H)`` metres (camera height ``H``);
* the distribution of localisation errors (share of the labelled cars within d metres; the
  table's shares are of the true positives) and a histogram of 3D azimuth errors, per variant;
* a gallery of the best and worst frames of the first fine variant, else the first
  variant (ranked by :func:`rank_frames`, which counts missed and false cars as well as
  errors) with overlays and bird's-eye views, the cars numbered alike in both;
* how the run was made (:func:`run_settings`): package, pre-detections, seed, particles,
  device, the model files' hashes and the options changed from their defaults.

Everything is written atomically into one directory (the page and its pictures appear
together or not at all); the page references its PNGs by relative path, so the
directory can be moved or served as it is. An evaluation over several seeds writes one
such page a seed in ``seed-S`` folders under a page of the figures' mean and range over
the seeds (:func:`write_seeds_page`), all staged by :func:`staged_report` and put in place
together; either layout removes the other's files of an earlier report.
"""

from __future__ import annotations

import html
import urllib.parse
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from wirescene.core.atomic import atomic_dir, write_text
from wirescene.core.camera import Camera
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT
from wirescene.core.labels import CAR_TYPES, Label
from wirescene.core.types import Detections, SceneEstimate, dropped_detections, fitted_detections
from wirescene.core.wireframe import EDGES
from wirescene.eval.kitti_metrics import drawn_alike, kitti_figure
from wirescene.eval.metrics import EvaluationReport
from wirescene.eval.seeds import mean_and_range, seed_folder
from wirescene.fitting.variants import get_variant
from wirescene.io.pictures import birds_eye, new_figure, overlay, save_figure

#: Localisation error (m) at the top of the error-vs-distance plot; larger errors are drawn on its top edge.
ERROR_AXIS_CAP = 10.0

#: The variants' colours in the plots (Okabe and Ito's, told apart with any common colour-vision
#: deficiency; matplotlib's default cycle has red and green third and fourth), each variant with its
#: own marker and line style as well, so that a grey print keeps them apart too.
VARIANT_COLORS = ("#0072b2", "#e69f00", "#009e73", "#cc79a7", "#56b4e9", "#d55e00", "#000000")
_MARKERS = ("o", "s", "D", "v", "P", "X", "*")  # not "^": it marks the errors off the scale
_LINESTYLES = ("-", "--", "-.", ":", (0, (5, 1)), (0, (3, 1, 1, 1)), (0, (1, 1)))


def variant_style(i: int) -> dict:
    """``{"color", "marker", "linestyle"}`` of the ``i``-th variant of a report's plots.

    Examples
    --------
    >>> variant_style(0)
    {'color': '#0072b2', 'marker': 'o', 'linestyle': '-'}
    """
    return {"color": VARIANT_COLORS[i % len(VARIANT_COLORS)], "marker": _MARKERS[i % len(_MARKERS)],
            "linestyle": _LINESTYLES[i % len(_LINESTYLES)]}


#: The files of one report page (globs): the page, its plots and its gallery.
PAGE_FILES = ("index.html", "error_vs_depth.png", "error_cdf.png", "azimuth_hist.png", "best_*_overlay.png",
              "best_*_bev.png", "worst_*_overlay.png", "worst_*_bev.png")
#: The files a report of either layout leaves in its directory (a page, or a page a seed in its folder).
REPORT_FILES = PAGE_FILES + tuple(f"{seed_folder('[0-9]*')}/{name}" for name in PAGE_FILES)


@dataclass
class Gallery:
    """Estimates kept for the report's gallery: ``frames[frame_id] = (camera, gt cars,
    detections, {variant: estimate})``; images are read again when drawn."""

    frames: dict[str, tuple[Camera, list[Label], Detections, dict[str, SceneEstimate]]] = field(default_factory=dict)

    def add(self, frame_id, variant, estimate, camera, detections, gt) -> None:
        """An ``on_estimate`` callback of :func:`wirescene.eval.runner.evaluate_dataset`."""
        entry = self.frames.setdefault(frame_id, (camera, gt.of_type(*CAR_TYPES), detections, {}))
        entry[3][variant] = estimate


def depth_error_per_pixel(z, focal: float, camera_height: float = KITTI_CAMERA_HEIGHT):
    """Depth change (m) of a ground contact point at depth ``z`` moved by one pixel.

    Examples
    --------
    >>> depth_error_per_pixel([10.0, 20.0, 40.0], focal=721.5).round(2)  # KITTI's focal length and camera height
    array([0.08, 0.34, 1.34])
    """
    z = np.asarray(z, float)
    return z**2 / (focal * camera_height)


def _plot_error_vs_depth(reports, focal):
    """The figure of localisation error against ground-truth depth; errors above
    :data:`ERROR_AXIS_CAP` are drawn as triangles on the top edge and counted in the legend."""
    fig = new_figure(figsize=(7, 4.2), dpi=100)
    ax = fig.subplots()
    zmax = 5.0
    largest = max((r.loc_error for rep in reports.values() for r in rep.records if r.gt_depth is not None), default=0.0)
    top = max(4.0, min(ERROR_AXIS_CAP, 1.05 * largest))
    off_scale = 0
    for i, (name, rep) in enumerate(reports.items()):
        style = variant_style(i)
        z = np.array([np.nan if r.gt_depth is None else r.gt_depth for r in rep.records], float)
        err = np.array([r.loc_error for r in rep.records], float)
        ok = np.isfinite(z)
        over = ok & (err > top)
        n_over = int(over.sum())
        label = f"{name} ({ok.sum()} TP" + (f", {n_over} over {top:g} m: ▲ on the top edge)" if n_over else ")")
        ax.scatter(z[ok & ~over], err[ok & ~over], s=14, alpha=0.75, label=label, color=style["color"],
                   marker=style["marker"])
        if n_over:  # unclipped on the edge: no car leaves the plot while the legend counts it
            ax.scatter(z[over], np.full(n_over, top), s=30, marker="^", color=style["color"], clip_on=False)
        off_scale += n_over
        if ok.any():
            zmax = max(zmax, float(z[ok].max()))
    zz = np.linspace(0, zmax * 1.05, 100)
    for px, style in ((1, "-"), (3, "--")):
        ax.plot(zz, px * depth_error_per_pixel(zz, focal), "k" + style, lw=1,
                label=f"{px} px of ground-contact error: z²/(f·H)" if px == 1 else f"{px} px")
    ax.axhline(1.0, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("ground-truth depth z (m)")
    ax.set_ylabel("localisation error (m)")
    ax.set_ylim(0, top)
    ax.legend(fontsize=7, loc="upper left")
    off = f"\n{off_scale} errors over {top:g} m drawn as ▲ on the top edge" if off_scale else ""
    ax.set_title(f"Localisation error vs distance (paper threshold 1 m dotted){off}")
    fig.tight_layout()
    return fig


def _plot_error_cdf(reports):
    """The figure of the share of labelled cars (not of true positives) localised within d metres."""
    fig = new_figure(figsize=(5.5, 4.2), dpi=100)
    ax = fig.subplots()
    d = np.linspace(0, 5, 201)
    for i, (name, rep) in enumerate(reports.items()):
        style = variant_style(i)
        err = np.sort([r.loc_error for r in rep.records])
        n_gt = rep.metrics["all"].get("n_gt", len(err)) or max(len(err), 1)
        ax.plot(d, np.searchsorted(err, d, side="right") / n_gt * 100, label=name, color=style["color"],
                ls=style["linestyle"])
    ax.axvline(1.0, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("localisation error d (m)")
    ax.set_ylabel("share of labelled cars within d (%)")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=8)
    ax.set_title("Labelled cars localised within d metres")
    fig.tight_layout()
    return fig


def _plot_azimuth_histogram(reports):
    """The figure of the 3D azimuth errors' histogram, as shares of the true positives: bins of
    2.5 deg up to 30 deg, then 30-90 and 90-180, drawn equally wide with their edges on the ticks."""
    fig = new_figure(figsize=(5.5, 4.2), dpi=100)
    ax = fig.subplots()
    bins = np.concatenate([np.arange(0, 30, 2.5), [30, 90, 180]])
    for i, (name, rep) in enumerate(reports.items()):
        style = variant_style(i)
        err = np.array([r.az3d_error for r in rep.records])
        counts, _ = np.histogram(np.clip(err, 0, 179.9), bins=bins)
        ax.stairs(counts / max(len(err), 1) * 100, np.arange(len(bins)), label=name, color=style["color"],
                  ls=style["linestyle"], lw=1.5)
    ax.set_xticks(np.arange(len(bins)))
    ax.set_xticklabels([f"{b:g}" for b in bins], rotation=60, fontsize=7)
    ax.set_xlim(0, len(bins) - 1)
    ax.set_xlabel("3D azimuth error (deg; the last two bins are 30-90 and 90-180)")
    ax.set_ylabel("% of true positives")
    ax.legend(fontsize=8)
    ax.set_title("Azimuth error")
    fig.tight_layout()
    return fig


#: Localisation error (m) at which a found car's share of the gallery score falls to 0.
SCORE_ZERO_ERROR = 2.0


def frame_scores(report: EvaluationReport, counts: dict[str, tuple[int, int]]) -> dict[str, float]:
    """Per frame: (sum over true positives of max(0, 1 - error / 2 m) - false cars) / labelled cars.

    ``counts`` is ``{frame_id: (labelled cars, cars output)}`` (the cars the variant output,
    not the pre-detections its fit dropped); a false car is any output that is not a true
    positive (unmatched, or of a wrong viewpoint). A frame scores 1 when every car is found
    exactly and nothing else is output; a missed car adds nothing and a false car costs what
    a perfect car earns, so a few cars found precisely do not outrank many found well. A
    frame without labelled cars divides by 1.

    Examples
    --------
    >>> from wirescene.eval.metrics import TPRecord
    >>> found = [TPRecord("a", 0, 0, 0.9, 0.0, 0.0, 0.0, True, None, 0),  # frame a: its car found exactly
    ...          TPRecord("b", 0, 0, 0.9, 1.0, 0.0, 0.0, True, None, 0)]  # frame b: one of two, 1 m off
    >>> report = EvaluationReport({}, found, "kitti_flag", "applied")
    >>> counts = {"a": (1, 1), "b": (2, 3), "c": (1, 0)}  # (labelled cars, cars output); c: its car missed
    >>> frame_scores(report, counts)  # b: (0.5 - 2 false cars) / 2 cars
    {'a': 1.0, 'b': -0.75, 'c': 0.0}
    """
    credit: dict[str, float] = {}
    found: dict[str, int] = {}
    for r in report.records:
        credit[r.frame_id] = credit.get(r.frame_id, 0.0) + max(0.0, 1.0 - r.loc_error / SCORE_ZERO_ERROR)
        found[r.frame_id] = found.get(r.frame_id, 0) + 1
    return {f: (credit.get(f, 0.0) - (n_out - found.get(f, 0))) / max(n_cars, 1)
            for f, (n_cars, n_out) in counts.items()}


def _errors_by_frame(report: EvaluationReport) -> dict[str, list[float]]:
    """The localisation errors of each frame's true positives."""
    errors: dict[str, list[float]] = {}
    for r in report.records:
        errors.setdefault(r.frame_id, []).append(r.loc_error)
    return errors


def rank_frames(report: EvaluationReport, counts: dict[str, tuple[int, int]]) -> list[str]:
    """The frames of ``counts`` the gallery may show, best first.

    The order: by :func:`frame_scores`, highest first; equal scores by the mean localisation
    error of the frame's true positives, smallest first (a frame without one after those
    with one), then by frame id. The worst frames are the list read from its end: the
    lowest score first and, of equal scores, the largest mean error first. A frame with
    neither a labelled car nor a car output is left out: nothing in it is right or wrong.

    Parameters
    ----------
    report : EvaluationReport
        The variant's evaluation (its true positives).
    counts : dict
        ``{frame_id: (labelled cars, cars output)}``, as of :func:`frame_scores`.

    Returns
    -------
    list of str

    Examples
    --------
    >>> from wirescene.eval.metrics import TPRecord
    >>> found = [TPRecord("a", 0, 0, 0.9, 0.0, 0.0, 0.0, True, None, 0),  # frame a: its car found exactly
    ...          TPRecord("b", 0, 0, 0.9, 1.0, 0.0, 0.0, True, None, 0)]  # frame b: one of two, 1 m off
    >>> report = EvaluationReport({}, found, "kitti_flag", "applied")
    >>> counts = {"a": (1, 1), "b": (2, 3), "c": (1, 0)}  # (labelled cars, cars output); c: its car missed
    >>> rank_frames(report, counts)  # the gallery's best first, its worst read from the end
    ['a', 'c', 'b']
    """
    scores = frame_scores(report, counts)
    mean = {f: float(np.mean(e)) for f, e in _errors_by_frame(report).items()}
    candidates = [f for f, (n_cars, n_out) in counts.items() if n_cars or n_out]
    return sorted(candidates, key=lambda f: (-scores[f], mean.get(f, np.inf), f))


def _href(name: str) -> str:
    """A file name of the report as a relative URL inside an HTML attribute."""
    return html.escape(urllib.parse.quote(name))


def run_settings(options, *, detections: str, evidence: str = "parts", fine: bool = True,
                 min_score: float | None = None, read: Iterable[str] | None = None) -> dict[str, str]:
    """What made an evaluation run, for its report page: the package, the pre-detections, the
    seed, the scene particles, the device, the trained models the fit reads (file, or
    ``shipped``, and the start of its SHA-256; :func:`~wirescene.fitting.models.model_files_read`)
    and every option changed from its default.

    Parameters
    ----------
    options : FitOptions
        The run's options (models and ``--set`` applied).
    detections : str
        The pre-detections: ``gt``, ``bank`` or a directory of detection files.
    evidence : str
        The fine variants' evidence (``parts`` or ``oracle``).
    fine : bool
        A fine variant was fitted (the part and shape models are read).
    min_score : float, optional
        The score floor of the boxes of detection files (``--min-score``; None: every box).
    read : iterable of str, optional
        The model files the fits read, their boxes read
        (:func:`~wirescene.eval.runner.model_files_of_run`); None: those of ``fine``,
        ``detections`` and ``evidence`` (the bank and classifier of boxes not our own counted).

    Returns
    -------
    dict
        ``{what: value}``, in the page's order.
    """
    from dataclasses import asdict

    from wirescene.core.version import __version__
    from wirescene.fitting.models import MODEL_FILES, models_fingerprint
    from wirescene.fitting.options import FitOptions

    named = {"gt": "label boxes", "bank": "own pre-detection"}
    files = f"files in {detections}" + ("" if min_score is None else f", boxes scoring at least {min_score:g}")
    out = {"wirescene": __version__, "pre-detections": named.get(detections, files),
           "evidence of the fine variants": evidence, "seed": str(options.seed),
           "scene particles": str(options.lifting.n_particles), "device": str(options.inference.device)}
    for name, digest in models_fingerprint(options, fine=fine, own=detections == "bank", evidence=evidence,
                                           read=read).items():
        out[name.replace("_", " ")] = f"{getattr(options, name) or 'shipped'} (SHA-256 {digest[:12]}…)"
    shown = {"seed", "lifting.n_particles", "inference.device", *MODEL_FILES}
    default = asdict(FitOptions())
    changed = []
    for key, value in asdict(options).items():
        # a stage's options are one level down (lifting.n_particles); the others sit at the top (seed)
        pairs = ({f"{key}.{k}": (v, default[key].get(k)) for k, v in value.items()} if isinstance(value, dict)
                 else {key: (value, default.get(key))})
        changed += [f"{name}={now}" for name, (now, was) in pairs.items() if name not in shown and now != was]
    out["options changed from the defaults"] = ", ".join(changed) or "none"
    return out


def _run_table(run: dict) -> str:
    rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(str(v))}</td></tr>" for k, v in run.items())
    return f'<h2>How this run was made</h2>\n<table class="run">{rows}</table>'


def _metrics_table(reports, intervals=None) -> str:
    cols = [("n_gt", "GT cars", "{:.0f}"), ("n_tp", "TP", "{:.0f}"), ("loc_1m", "&lt;1 m (of TPs)", "{:.0f}%"),
            ("loc_1_5m", "&lt;1.5 m (of TPs)", "{:.0f}%"), ("median_loc", "median loc. (m)", "{:.2f}"),
            ("az_5", "az &lt;5° (of TPs)", "{:.0f}%"), ("median_az3d", "median az (°)", "{:.1f}")]
    if intervals is not None:  # beside the 1 m share: how far other drives could move it
        cols.insert(3, ("loc_1m_interval", "&lt;1 m (of TPs), 90% over drives", "[{:.0f}, {:.0f}]%"))
    head = "".join(f"<th>{c[1]}</th>" for c in cols)
    rows = []
    for name, rep in reports.items():
        m = rep.metrics["all"]
        cells = []
        for key, _, fmt in cols:
            if key == "loc_1m_interval":
                span = intervals[name]["interval"]  # of one drive none: [x, x] would read as a share known exactly
                cells.append("–" if span is None or drawn_alike(intervals[name]) else fmt.format(*span))
                continue
            v = m.get(key)
            cells.append("–" if v is None or not np.isfinite(v) else fmt.format(v))
        rows.append(f"<tr><td>{html.escape(name)}</td>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return f"<table><tr><th>variant</th>{head}</tr>{''.join(rows)}</table>"


def _kitti_table(kitti: dict, kitti_intervals: dict | None) -> str:
    """KITTI's moderate APs (R40) of each variant, each with its interval over drives if given."""
    if kitti_intervals and drawn_alike(next(iter(kitti_intervals.values()))):  # one drive: every draw the same
        kitti_intervals = None
    cols = [("3D AP@0.7", "car", "3d"), ("BEV AP@0.7", "car", "bev"), ("3D AP@0.5", "iou_0.5", "3d"),
            ("2D AP@0.7", "car", "2d")]

    rows = []
    for name, result in kitti.items():
        cells = []
        for _, block, metric in cols:
            v = kitti_figure(result, block, metric)["moderate"]
            span = kitti_figure(kitti_intervals[name], block, metric) if kitti_intervals else None
            cells.append("–" if v is None else f"{v:.1f}" + ("" if span is None else f" [{span[0]:.1f}, {span[1]:.1f}]"))
        rows.append(f"<tr><td>{html.escape(name)}</td>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    n = next(iter(kitti.values()))["n_gt"]["car"]["moderate"]
    spread = " with its 90% bootstrap interval over drives" if kitti_intervals else ""
    ceiling = f" With fewer than 40 cars the devkit's AP is at most {100 * (n - 1) / 40:.1f}." if 0 < n < 40 else ""
    return (f"<p>KITTI's own measure (R40, moderate, {n} cars; the devkit's rules), each AP{spread}:{ceiling}</p>"
            f"<table><tr><th>variant</th>{''.join(f'<th>{c[0]}</th>' for c in cols)}</tr>{''.join(rows)}</table>")


def write_report(out_dir, reports: dict[str, EvaluationReport], *, gallery: Gallery, image_of, title: str = "",
                 n_gallery: int = 3, intervals: dict | None = None, kitti: dict | None = None,
                 kitti_intervals: dict | None = None, run: dict | None = None, raw_scores: bool = False) -> Path:
    """Write ``out_dir/index.html`` and its PNGs; returns the page's path.

    Parameters
    ----------
    out_dir : path
        The report's directory (made if needed): files of the same names are replaced and an
        earlier report's files this one lacks removed, ``seed-S`` pages of several seeds
        included (see :func:`staged_report`); other files stay.
    reports : dict
        ``{variant: EvaluationReport}`` of one run.
    gallery : Gallery
        The run's estimates (see :meth:`Gallery.add`).
    image_of : callable
        ``image_of(frame_id)`` -> ``(H, W, 3)`` uint8 image, for the overlays.
    title : str
        The page's heading.
    n_gallery : int
        Number of best and of worst frames shown.
    intervals : dict, optional
        ``{variant: figures}`` of :func:`wirescene.eval.intervals.localisation_intervals`: the
        table then gives the 1 m share's interval over drives.
    kitti, kitti_intervals : dict, optional
        ``{variant: figures}`` of :func:`wirescene.eval.kitti_metrics.kitti_metrics` and of
        :func:`wirescene.eval.intervals.kitti_intervals`: a second table gives KITTI's
        moderate APs (with their intervals).
    run : dict, optional
        ``{what: value}`` of :func:`run_settings`: the page says how the run was made.
    raw_scores : bool, optional
        The cars' scores are their pre-detections' (``wirescene eval --raw-scores``), not
        calibrated confidences: the gallery's key and the page call them so.
    """
    with staged_report(out_dir) as staging:
        _write_report(staging, reports, gallery=gallery, image_of=image_of, title=title, n_gallery=n_gallery,
                      intervals=intervals, kitti=kitti, kitti_intervals=kitti_intervals, run=run,
                      raw_scores=raw_scores)
    return Path(out_dir) / "index.html"


@contextmanager
def staged_report(out_dir):
    """Yield an empty staging directory for a report's files (one page, or a page a seed in
    ``seed-S`` folders and :func:`write_seeds_page`'s page above them) that take their
    place in ``out_dir`` when the block succeeds: an earlier report's files of either layout
    that the new set lacks go then (:data:`REPORT_FILES`; other files stay). When the block
    raises, ``out_dir`` is left as it was.

    Parameters
    ----------
    out_dir : path
        The report's directory (made if needed).
    """
    with atomic_dir(out_dir, stale=REPORT_FILES) as staging:
        yield staging


#: Headers of the figures over seeds that are shares of the true positives, saying so.
_OF_TPS = {"<1m %": "<1m % (of TPs)", "<1.5m %": "<1.5m % (of TPs)"}


def write_seeds_page(out_dir, summary: dict, seeds, *, title: str = "") -> Path:
    """Write ``out_dir/index.html`` of an evaluation over several seeds: the seeds, the mean and
    range over them of each variant's figures, and a link to each seed's page (``seed-S/index.html``,
    written by :func:`write_report`); returns the page's path.

    Parameters
    ----------
    out_dir : path
        The report's directory (a :func:`staged_report` staging directory).
    summary : dict
        ``{variant: {column: figure}}`` of :func:`wirescene.eval.seeds.over_seeds` (what
        ``wirescene eval`` prints and writes as ``over_seeds`` in ``--json``).
    seeds : sequence of int
        The seeds, in the order evaluated.
    title : str
        The page's heading.
    """
    seeds = [int(s) for s in seeds]
    if not seeds or not summary:
        raise ValueError("write_seeds_page: no seeds or no variants to summarise")
    columns = list(next(iter(summary.values())))
    rows = []
    for variant, figures in summary.items():
        cells = [mean_and_range(figures[c], c) for c in columns]
        rows.append(f"<tr><td>{html.escape(variant)}</td>"
                    + "".join(f"<td>{mean}<br><small>{spread}</small></td>" for mean, spread in cells) + "</tr>")
    links = "".join(f'<li><a href="{_href(seed_folder(s) + "/index.html")}">seed {s}</a></li>' for s in seeds)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>wirescene report {html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }} td, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: right; }}
td:first-child {{ text-align: left; }} small {{ color: #666; }}
</style></head><body>
<h1>wirescene evaluation report over {len(seeds)} seeds</h1>
<p>{html.escape(title)} — every frame fitted once with each of the seeds {", ".join(map(str, seeds))}; the fine
stage samples, so the seed alone moves the figures. Each cell: the mean over the seeds, below it the range
(min–max).</p>
<table><tr><th>variant</th>{"".join(f"<th>{html.escape(_OF_TPS.get(c, c))}</th>" for c in columns)}</tr>{"".join(rows)}</table>
<p>TP: true positives; &lt;1m % and &lt;1.5m %: shares of the true positives localised within 1 and 1.5 m;
med az: median 3D azimuth error (°) of the true positives; 2d@.7, bev@.7, 3d@.7 and 3d@.5: KITTI's moderate
APs (R40) at IoU 0.7 and 0.5.</p>
<h2>Each seed's page</h2>
<ul>{links}</ul>
</body></html>
"""
    out = Path(out_dir) / "index.html"
    write_text(out, page)
    return out


def _write_report(out: Path, reports, *, gallery, image_of, title, n_gallery, intervals, kitti,
                  kitti_intervals, run=None, raw_scores=False) -> None:
    """:func:`write_report`'s files, written into the directory ``out``."""
    score_name = "pre-detection score" if raw_scores else "confidence"
    focal = next((c.focal for c, *_ in gallery.frames.values()), 721.5)
    plots = {
        "error_vs_depth.png": _plot_error_vs_depth(reports, focal),
        "error_cdf.png": _plot_error_cdf(reports),
        "azimuth_hist.png": _plot_azimuth_histogram(reports),
    }
    for name, fig in plots.items():
        save_figure(fig, out / name)
    fine = [v for v in reports if get_variant(v).fine]
    lead = fine[0] if fine else next(iter(reports))
    counts = {f: (len(cars), len(estimates[lead].objects)) for f, (_, cars, _, estimates) in gallery.frames.items()}
    scores = frame_scores(reports[lead], counts)
    errors = _errors_by_frame(reports[lead])
    ranked = rank_frames(reports[lead], counts)
    k = min(n_gallery, max(1, len(ranked) // 2))  # best and worst never share a frame, nor take the middle one
    picks = [("best", f) for f in ranked[:k]] + [("worst", f) for f in ranked[::-1][:min(k, len(ranked) - k)]]
    n_best, n_worst = sum(kind == "best" for kind, _ in picks), sum(kind == "worst" for kind, _ in picks)
    shown = (f"best {n_best} and worst {n_worst} of the {len(ranked)} ranked frame{'s' * (len(ranked) != 1)}"
             if ranked else "best and worst frames")
    seen, cards = set(), []
    for kind, frame_id in picks:
        if frame_id in seen:
            continue
        seen.add(frame_id)
        camera, cars, dets, estimates = gallery.frames[frame_id]
        estimate = estimates[lead]
        stem = f"{kind}_{frame_id}"
        save_figure(overlay(image_of(frame_id), camera, estimate, gt=cars, detections=fitted_detections(dets, estimate),
                            dropped=dropped_detections(dets, estimate), edges=EDGES, title=f"{frame_id}  {lead}",
                            score_name=score_name),
                    out / f"{stem}_overlay.png")
        save_figure(birds_eye(estimate, gt=cars, camera=camera, title=f"{frame_id}  {lead}"), out / f"{stem}_bev.png")
        found = errors.get(frame_id, [])
        n_out = len(estimate.objects)
        mean = f", mean localisation error {np.mean(found):.2f} m" if found else ""
        cards.append(f'<figure><figcaption>{kind}: {html.escape(frame_id)} — score {scores[frame_id]:.2f}: '
                     f'{len(found)} of {len(cars)} cars found{mean}; {n_out - len(found)} of the {n_out} cars output '
                     f'false ({html.escape(lead)})</figcaption><img class="wide" src="{_href(stem + "_overlay.png")}">'
                     f'<img class="bev" src="{_href(stem + "_bev.png")}"></figure>')
    evaluated = max((r.counts.get("frames", 0) for r in reports.values()), default=0)
    n_frames = max(len(gallery.frames), evaluated)
    reused = evaluated - len(gallery.frames)
    unpictured = (f"<p>The gallery ranks the {len(gallery.frames)} frames fitted by this run; {reused} frames "
                  "reused from an earlier run's records are in the tables, not pictured.</p>") if reused > 0 else ""
    if not ranked:
        unpictured += "<p>No frame of this run has a labelled car or a car output: the gallery is empty.</p>"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>wirescene report {html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }} td, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: right; }}
td:first-child {{ text-align: left; }} .plots img {{ max-width: 32%; }} figure {{ margin: 1em 0; }}
img.wide {{ max-width: 70%; vertical-align: top; }} img.bev {{ max-width: 25%; vertical-align: top; }}
table.run td {{ text-align: left; }}
</style></head><body>
<h1>wirescene evaluation report</h1>
<p>{html.escape(title)} — {n_frames} frames; the paper's protocol (true-positive initialisations, IoU &gt; 0.5,
viewpoint within 45°).{" How the run was made (models, seed, settings): at the end of the page." if run else ""}</p>
{_metrics_table(reports, intervals)}
<p>The table's shares are of the true positives (TP); the plot of cars localised within d metres counts
every labelled car (a missed car is never within d), so its value at 1 m is the lower one.</p>
{_kitti_table(kitti, kitti_intervals) if kitti else ""}
<div class="plots">{''.join(f'<img src="{_href(name)}" alt="{html.escape(name)}">' for name in plots)}</div>
<h2>Gallery ({html.escape(lead)}): {shown}</h2>
<p>Red: estimate ({"wireframe, each hidden vertex marked by what hides it (the key says how), the occluder mask "
                    "the fit chose hatched" if get_variant(lead).fine
else "3D box, a cross on its front"}), each numbered #n in detection order (the order of the label files
<code>--predictions</code> writes) with its {score_name}{" (--raw-scores)" if raw_scores else ""} (the same number
in the bird's-eye view); cyan: ground truth;
dashed yellow: the pre-detections of the cars output; dotted grey: those the fit's verification dropped (our own
pre-detection only).
Frames ranked by a score that counts missed and false cars: (sum over true positives of
max(0, 1 &minus; error / {SCORE_ZERO_ERROR:g} m) &minus; false cars output) / labelled cars; equal scores by the
mean localisation error; frames with neither a labelled car nor a car output are not ranked.</p>
{unpictured}{''.join(cards)}
{_run_table(run) if run else ""}
</body></html>
"""
    write_text(out / "index.html", page)
