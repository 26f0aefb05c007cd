"""Where each variant's 3D error lies on the real folds, and which error decides KITTI's tests.

Reads the frame records of one or more runs of ``bench_real_folds.py`` (``RUN/fold{k}/``)
or ``wirescene eval --predictions DIR`` (``DIR/.frames/``) and, for every car the paper's
protocol counts as a true positive (:func:`wirescene.eval.metrics.evaluate`: detection
matched to a label at 2D IoU > 0.5, coarse viewpoint within 45 deg), splits each variant's
error against the label into

* **lateral**: across the viewing ray, in the ground (x-z) plane, signed (+: right);
* **range**: along the viewing ray (camera centre to the label's centre), signed, fitted
  minus label (+: too far);
* **height**: of the box centre (y, down), fitted minus label;
* **azimuth**: ``rotation_y``, fitted minus label, wrapped to [-180, 180) deg;
* **size**: ``h``, ``w``, ``l``, fitted minus label;

with the centre distance (the paper's localisation error, ``sqrt(lat^2 + range^2 +
height^2)``) and the 3D IoU (:func:`wirescene.eval.kitti_metrics.iou_3d`). Beside the range
error stands its physical limit: the range error of one pixel at the ground contact,
``z r / (f h)`` (``z^2 / (f h)`` straight ahead; ``f`` the vertical focal length of P2,
``h`` the camera height above the ground).

The decomposition replaces one component at a time by the label's ("perfect range"
puts the fitted box at the label's range along the ray, keeping its lateral offset,
height, azimuth and size) and counts the cars that would then pass IoU > 0.7 (KITTI's
rule for cars) or a centre within 1 m; "only X wrong" makes every other component
perfect. All of it is reported per distance band, KITTI occlusion flag and truncation, and each
variant against a reference (default coarse+gp) on the same cars.

    python benchmarks/bench_error_budget.py RUN [RUN ...] --root KITTI \\
        [--json OUT.json] [--plot OUT.png] [--camera-height 1.65] [--reference coarse+gp]

Each RUN is reported on its own (e.g. a ``--detections gt`` and a ``--detections bank``
run side by side); its fold directories are pooled.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from _common import read_run  # noqa: E402  (benchmarks/ is on the path of a script run from it)
from wirescene.core.errors import InputError
from wirescene.core.jsonio import write_json
from wirescene.core.labels import is_type
from wirescene.core.viewpoints import wrap_angle
from wirescene.eval.kitti_metrics import iou_3d
from wirescene.eval.metrics import FrameResult, evaluate
from wirescene.io.kitti import CAR_TYPES, DEFAULT_SPLIT, KittiDataset, given_split_problem

#: KITTI's camera height above the road (the recording car's mounting, metres).
KITTI_CAMERA_HEIGHT = 1.65
#: KITTI's minimum 3D overlap for cars (a detection must exceed it).
IOU_THRESHOLD = 0.7
#: The paper's localisation threshold (centre distance below it, metres).
LOC_THRESHOLD = 1.0
#: Distance bands by the label's depth z: (label, lower, upper), lower inclusive.
BANDS = (("<15 m", 0.0, 15.0), ("15-25 m", 15.0, 25.0), ("25-35 m", 25.0, 35.0), (">35 m", 35.0, math.inf))
#: KITTI occlusion groups: (label, flags). Flag 3 ("unknown") counts as occluded, as in
#: :mod:`wirescene.eval.metrics`.
OCCLUSION_GROUPS = (("occ 0", (0,)), ("occ 1", (1,)), ("occ 2+", (2, 3)))
#: Truncation groups by KITTI's ``truncated`` (the share of the car outside the image):
#: (label, lower, upper), lower exclusive except for the first.
TRUNCATION_GROUPS = (("inside", -math.inf, 0.0), ("truncated", 0.0, math.inf))
#: The components the decomposition makes perfect one at a time.
COMPONENTS = ("range", "lateral", "height", "azimuth", "size")
#: Width of the depth bins of the plot, metres.
PLOT_BIN = 5.0


class Boxes(NamedTuple):
    """KITTI 3D boxes as arrays: ``location`` (N, 3) bottom centres in the camera frame,
    ``dims`` (N, 3) ``h w l``, ``rotation_y`` (N,) radians."""

    location: np.ndarray
    dims: np.ndarray
    rotation_y: np.ndarray

    @classmethod
    def of(cls, location, dims, rotation_y) -> "Boxes":
        """Boxes with the arrays converted to float and checked for shape."""
        location = np.asarray(location, float).reshape(-1, 3)
        dims = np.asarray(dims, float).reshape(-1, 3)
        rotation_y = np.asarray(rotation_y, float).reshape(-1)
        if not len(location) == len(dims) == len(rotation_y):
            raise ValueError(f"boxes of unequal length: {len(location)}, {len(dims)}, {len(rotation_y)}")
        return cls(location, dims, rotation_y)

    def centres(self) -> np.ndarray:
        """(N, 3) box centres: the bottom centre raised by h/2 (y points down)."""
        return self.location - np.stack([np.zeros(len(self.dims)), 0.5 * self.dims[:, 0], np.zeros(len(self.dims))],
                                        axis=1)


def _ray_frame(labels: Boxes, camera_centre) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit viewing directions ``u`` (N, 2) in the x-z plane from the camera centre to each
    label's centre, the unit normals ``n`` (N, 2) to their right, and the ground-plane
    distances (N,)."""
    centre = np.broadcast_to(np.asarray(camera_centre, float), labels.location.shape)
    d = labels.location[:, [0, 2]] - centre[:, [0, 2]]
    dist = np.hypot(d[:, 0], d[:, 1])
    u = d / np.where(dist > 0, dist, 1.0)[:, None]
    # Right of the ray seen from above (x right, z forward): (u_z, -u_x).
    n = np.stack([u[:, 1], -u[:, 0]], axis=1)
    return u, n, dist


def error_components(fitted: Boxes, labels: Boxes, camera_centre) -> dict[str, np.ndarray]:
    """Each fitted box's error against its label, split along and across the viewing ray.

    Parameters
    ----------
    fitted, labels : Boxes
        Paired boxes, ``N`` each.
    camera_centre : (3,) or (N, 3) array
        Optical centre of each car's camera (:attr:`wirescene.core.camera.Camera.center`),
        where the viewing rays start.

    Returns
    -------
    dict of (N,) arrays
        ``lateral`` (m, signed, + to the right of the ray), ``range`` (m, signed, + too
        far), ``height`` (m, of the box centres, + lower), ``azimuth`` (deg, wrapped to
        [-180, 180)), ``dh``, ``dw``, ``dl`` (m, fitted minus label), ``centre_distance``
        (m, as the paper's localisation error), ``iou`` (3D IoU), ``label_range`` (m,
        ground-plane distance of the label from the camera centre) and ``label_depth``
        (the label's z, m).

    Notes
    -----
    The viewing ray goes through the label's centre, so a fitted box displaced along it
    has a range error equal to the displacement and no lateral error; to first order the
    range error is the fitted minus the label distance. ``centre_distance**2 ==
    lateral**2 + range**2 + height**2`` exactly.
    """
    u, n, dist = _ray_frame(labels, camera_centre)
    delta = fitted.location[:, [0, 2]] - labels.location[:, [0, 2]]
    centre_delta = fitted.centres() - labels.centres()
    return {
        "lateral": np.sum(delta * n, axis=1),
        "range": np.sum(delta * u, axis=1),
        "height": centre_delta[:, 1],
        "azimuth": np.rad2deg(wrap_angle(fitted.rotation_y - labels.rotation_y)),
        "dh": fitted.dims[:, 0] - labels.dims[:, 0],
        "dw": fitted.dims[:, 1] - labels.dims[:, 1],
        "dl": fitted.dims[:, 2] - labels.dims[:, 2],
        "centre_distance": np.linalg.norm(centre_delta, axis=1),
        "iou": iou_3d(fitted.location, fitted.dims, fitted.rotation_y, labels.location, labels.dims,
                      labels.rotation_y),
        "label_range": dist,
        "label_depth": labels.location[:, 2].copy(),
    }


def one_pixel_range_limit(depth, ground_range, *, focal, camera_height=KITTI_CAMERA_HEIGHT) -> np.ndarray:
    """Range error (m) that one pixel of error in the image row of the ground contact gives.

    On a flat road the contact at depth ``z`` is imaged ``f h / z`` pixels below the
    horizon, so one row moves it by ``dz = z^2 / (f h)``; along the pixel's viewing ray the
    ground-plane distance ``r`` moves by ``dz r / z``.

    Parameters
    ----------
    depth : array
        The label's depth z (m).
    ground_range : array
        The label's ground-plane distance from the camera centre (m), ``>= z``.
    focal : float or array
        Vertical focal length in pixels (P2[1, 1], equal to P2[0, 0] on KITTI).
    camera_height : float or array
        Height of the camera above the ground under the car (m).

    Returns
    -------
    array
        ``z r / (f h)``, metres per pixel.
    """
    depth, ground_range = np.asarray(depth, float), np.asarray(ground_range, float)
    return depth * ground_range / (np.asarray(focal, float) * np.asarray(camera_height, float))


def replace_components(fitted: Boxes, labels: Boxes, camera_centre, components: Sequence[str]) -> Boxes:
    """The fitted boxes with the named error components set to zero, the rest kept.

    ``range`` / ``lateral`` move the box along / across the viewing ray of
    :func:`error_components` by its error; ``height`` puts its centre at the label's
    height; ``azimuth`` takes the label's rotation; ``size`` the label's ``h w l`` about
    the fitted centre (so that a perfect size leaves the other errors as they were). The
    replacements commute; all of :data:`COMPONENTS` gives the label boxes.

    Parameters
    ----------
    fitted, labels : Boxes
    camera_centre : (3,) or (N, 3) array
    components : sequence of str
        Names from :data:`COMPONENTS`.

    Returns
    -------
    Boxes
    """
    unknown = set(components) - set(COMPONENTS)
    if unknown:
        raise ValueError(f"unknown error components {sorted(unknown)}; known: {COMPONENTS}")
    u, n, _ = _ray_frame(labels, camera_centre)
    delta = fitted.location[:, [0, 2]] - labels.location[:, [0, 2]]
    xz = fitted.location[:, [0, 2]].copy()
    if "range" in components:
        xz -= np.sum(delta * u, axis=1)[:, None] * u
    if "lateral" in components:
        xz -= np.sum(delta * n, axis=1)[:, None] * n
    dims = labels.dims.copy() if "size" in components else fitted.dims.copy()
    centre_y = (labels if "height" in components else fitted).centres()[:, 1]
    location = np.stack([xz[:, 0], centre_y + 0.5 * dims[:, 0], xz[:, 1]], axis=1)
    rotation_y = (labels if "azimuth" in components else fitted).rotation_y.copy()
    return Boxes(location, dims, rotation_y)


def passes(fitted: Boxes, labels: Boxes) -> dict[str, np.ndarray]:
    """``{"iou": 3D IoU > 0.7, "loc": centre within 1 m}``, (N,) bool each."""
    iou = iou_3d(fitted.location, fitted.dims, fitted.rotation_y, labels.location, labels.dims, labels.rotation_y)
    dist = np.linalg.norm(fitted.centres() - labels.centres(), axis=1)
    return {"iou": iou > IOU_THRESHOLD, "loc": dist < LOC_THRESHOLD}


def decompose(fitted: Boxes, labels: Boxes, camera_centre) -> dict[str, dict[str, np.ndarray]]:
    """Which error decides each car's pass: the tests of :func:`passes` as fitted, with each
    component of :data:`COMPONENTS` made perfect (``"perfect X"``) and with every component
    but one made perfect (``"only X wrong"``).

    Returns
    -------
    dict
        ``{"as fitted" | "perfect X" | "only X wrong": {"iou": (N,) bool, "loc": (N,) bool}}``.
    """
    out = {"as fitted": passes(fitted, labels)}
    for c in COMPONENTS:
        out[f"perfect {c}"] = passes(replace_components(fitted, labels, camera_centre, [c]), labels)
    for c in COMPONENTS:
        others = [o for o in COMPONENTS if o != c]
        out[f"only {c} wrong"] = passes(replace_components(fitted, labels, camera_centre, others), labels)
    return out


# --------------------------------------------------------------------------- reading runs


def true_positive_cars(results: Sequence[FrameResult], cameras: dict) -> dict[str, np.ndarray]:
    """The true positives of one variant (the evaluation's own matching) as arrays.

    Parameters
    ----------
    results : sequence of FrameResult
    cameras : dict
        ``{frame id: Camera}``.

    Returns
    -------
    dict
        ``frame``, ``gt_index``, ``det_index``, ``occluded`` (KITTI flag), ``truncated``
        (KITTI's share outside the image), ``focal``,
        ``camera_centre`` (N, 3) and the ``fitted`` / ``labels`` :class:`Boxes`.
    """
    by_frame = {r.frame_id: r for r in results}
    rows = []
    for tp in evaluate(results).records:
        frame = by_frame[tp.frame_id]
        label, d = frame.gt[tp.gt_index], tp.det_index
        camera = cameras[tp.frame_id]
        rows.append((tp.frame_id, tp.gt_index, d, tp.kitti_occluded, camera.P[1, 1], camera.center,
                     frame.est_location[d], frame.est_dims[d], frame.est_rotation_y[d],
                     label.location, label.dims, label.rotation_y, label.truncated))
    cols = list(zip(*rows)) if rows else [[]] * 13  # no true positive: empty columns of the right kinds
    return {
        "frame": np.array(cols[0], dtype=object),
        "gt_index": np.array(cols[1], dtype=int),
        "det_index": np.array(cols[2], dtype=int),
        "occluded": np.array(cols[3], dtype=int),
        "truncated": np.array(cols[12], dtype=float),
        "focal": np.array(cols[4], dtype=float),
        "camera_centre": np.array(cols[5], dtype=float).reshape(-1, 3),
        "fitted": Boxes.of(np.array(cols[6]), np.array(cols[7]), np.array(cols[8])),
        "labels": Boxes.of(np.array(cols[9]), np.array(cols[10]), np.array(cols[11])),
    }


def car_table(cars: dict, *, camera_height: float, keep_boxes: bool = False) -> dict[str, np.ndarray]:
    """Per car: the keys of :func:`true_positive_cars` that are not boxes (with ``keep_boxes``
    the ``fitted`` and ``labels`` :class:`Boxes` too), the errors of :func:`error_components`,
    the one-pixel limit (``limit``) and the decomposition's tests (``pass_iou`` / ``pass_loc``
    for ``"as fitted"``, ``pass_iou:perfect range``, ...)."""
    dropped = ("camera_centre",) if keep_boxes else ("fitted", "labels", "camera_centre")
    out = {k: v for k, v in cars.items() if k not in dropped}
    errors = error_components(cars["fitted"], cars["labels"], cars["camera_centre"])
    out.update(errors)
    out["limit"] = one_pixel_range_limit(errors["label_depth"], errors["label_range"], focal=cars["focal"],
                                         camera_height=camera_height)
    for case, tests in decompose(cars["fitted"], cars["labels"], cars["camera_centre"]).items():
        suffix = "" if case == "as fitted" else f":{case}"
        out[f"pass_iou{suffix}"], out[f"pass_loc{suffix}"] = tests["iou"], tests["loc"]
    return out


def run_tables(run, dataset: KittiDataset, *, camera_height: float = KITTI_CAMERA_HEIGHT,
               keep_boxes: bool = False) -> tuple[dict, str, dict]:
    """``(records, detections, tables)`` of a run: its records pooled over folds
    (:func:`_common.read_run`, verified held out), the detections spec, and per variant
    the :func:`car_table` of its true positives (cameras read from ``dataset``; ``keep_boxes``
    as :func:`car_table` takes it)."""
    records, detections = read_run(run)
    cameras = {}
    for f in sorted({r.frame_id for rs in records.values() for r in rs}):
        if not dataset.calib_path(f).is_file():
            raise InputError(f"frame {f} of {run} has no calibration under --root", path=dataset.calib_path(f))
        cameras[f] = dataset.calib(f).camera()
    tables = {v: car_table(true_positive_cars(rs, cameras), camera_height=camera_height, keep_boxes=keep_boxes)
              for v, rs in records.items()}
    return records, detections, tables


# --------------------------------------------------------------------------- summaries


def _median(x) -> float | None:
    x = np.asarray(x, float)
    return float(np.median(x)) if x.size else None


def _share(mask) -> float | None:
    mask = np.asarray(mask, bool)
    return float(100.0 * mask.mean()) if mask.size else None


def group_masks(table: dict) -> dict[str, np.ndarray]:
    """``{"all" | band | occlusion group | truncation group: (N,) bool}`` of the cars of a
    :func:`car_table`."""
    z, occ, trunc = table["label_depth"], table["occluded"], table["truncated"]
    masks = {"all": np.ones(len(z), bool)}
    for name, lo, hi in BANDS:
        masks[name] = (z >= lo) & (z < hi)
    for name, flags in OCCLUSION_GROUPS:
        masks[name] = np.isin(occ, flags)
    for name, lo, hi in TRUNCATION_GROUPS:
        masks[name] = (trunc > lo) & (trunc <= hi)
    return masks


def summarise(table: dict, mask: np.ndarray) -> dict:
    """Medians and shares of the cars in ``mask`` (``None`` where there are none)."""
    t = {k: v[mask] for k, v in table.items()}
    out = {
        "n": int(mask.sum()),
        "median_abs_lateral": _median(np.abs(t["lateral"])),
        "median_abs_range": _median(np.abs(t["range"])),
        "median_range": _median(t["range"]),
        "median_abs_height": _median(np.abs(t["height"])),
        "median_abs_azimuth": _median(np.abs(t["azimuth"])),
        "median_abs_dh": _median(np.abs(t["dh"])),
        "median_abs_dw": _median(np.abs(t["dw"])),
        "median_abs_dl": _median(np.abs(t["dl"])),
        "median_centre_distance": _median(t["centre_distance"]),
        "median_iou": _median(t["iou"]),
        "median_limit": _median(t["limit"]),
        "median_abs_range_over_limit": _median(np.abs(t["range"]) / t["limit"]),
        "within_1m": _share(t["pass_loc"]),
        "iou_0.7": _share(t["pass_iou"]),
    }
    out["decomposition"] = {
        case: {"iou_0.7": _share(t[f"pass_iou:{case}"]), "within_1m": _share(t[f"pass_loc:{case}"])}
        for case in [f"perfect {c}" for c in COMPONENTS] + [f"only {c} wrong" for c in COMPONENTS]
    }
    return out


def deciding_component(summary: dict, test: str) -> tuple[str | None, float]:
    """The component whose perfection lifts ``test`` (``"iou_0.7"`` or ``"within_1m"``)
    the most, and the lift in percentage points (``(None, 0.0)`` if none helps)."""
    base = summary[test]
    if base is None:
        return None, 0.0
    lifts = {c: summary["decomposition"][f"perfect {c}"][test] - base for c in COMPONENTS}
    best = max(COMPONENTS, key=lambda c: lifts[c])  # ties: the first in COMPONENTS
    return (best, lifts[best]) if lifts[best] > 0 else (None, 0.0)


def versus_reference(tables: dict[str, dict], reference: str) -> dict:
    """Per variant and group: differences to ``reference`` on the cars both count.

    Returns
    -------
    dict
        ``{variant: {group: {n, within_1m, d_within_1m (points), median_abs_range,
        d_median_abs_range (m), gained, lost}}}``; ``gained`` / ``lost`` count the cars
        within 1 m in the variant but not in the reference / the other way round.
    """
    ref = tables[reference]
    ref_index = {(f, g): i for i, (f, g) in enumerate(zip(ref["frame"], ref["gt_index"]))}
    out = {}
    for variant, table in tables.items():
        if variant == reference:
            continue
        pairs = [(i, ref_index[(f, g)]) for i, (f, g) in enumerate(zip(table["frame"], table["gt_index"]))
                 if (f, g) in ref_index]
        a = np.array([p[0] for p in pairs], int)
        b = np.array([p[1] for p in pairs], int)
        shared = {k: v[a] for k, v in table.items()}
        shared_ref = {k: v[b] for k, v in ref.items()}
        out[variant] = {}
        for group, mask in group_masks(shared).items():
            va, vb = shared["pass_loc"][mask], shared_ref["pass_loc"][mask]
            ra, rb = _median(np.abs(shared["range"][mask])), _median(np.abs(shared_ref["range"][mask]))
            sa, sb = _share(va), _share(vb)
            out[variant][group] = {
                "n": int(mask.sum()),
                "within_1m": sa,
                "d_within_1m": None if sa is None else sa - sb,
                "median_abs_range": ra,
                "d_median_abs_range": None if ra is None else ra - rb,
                "gained": int(np.sum(va & ~vb)),
                "lost": int(np.sum(~va & vb)),
            }
    return out


# --------------------------------------------------------------------------- output


def _f(v, fmt: str = ".2f") -> str:
    return "-" if v is None else format(v, fmt)


def _pct(v) -> str:
    return "-" if v is None else f"{v:.0f}%"


def _markdown(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def format_report(name: str, detections: str, summaries: dict, comparison: dict | None, reference: str,
                  *, camera_height: float) -> str:
    """The markdown tables of one run (:func:`main`'s stdout)."""
    variants = list(summaries)
    out = [f"## {name} (detections: {detections})", ""]
    out.append(f"True positives of the paper's protocol; errors fitted minus label; limit: range error of one "
               f"pixel at the ground contact, z r / (f h), h = {camera_height:g} m. Errors are medians of absolute "
               f"values (m, deg), except the signed median range (+: too far); <1 m, IoU>0.7: shares of the cars; "
               f"IoU: median.\n")
    # No "|x|" in headers: a pipe ends a markdown cell.
    header = ["variant", "cars", "lateral", "range", "range (signed)", "height", "az (deg)", "dh", "dw", "dl",
              "centre", "<1 m", "IoU>0.7", "IoU", "1-px limit"]
    rows = []
    for v in variants:
        s = summaries[v]["all"]
        rows.append([v, str(s["n"]), _f(s["median_abs_lateral"]), _f(s["median_abs_range"]),
                     _f(s["median_range"], "+.2f"), _f(s["median_abs_height"]), _f(s["median_abs_azimuth"], ".1f"),
                     _f(s["median_abs_dh"]), _f(s["median_abs_dw"]), _f(s["median_abs_dl"]),
                     _f(s["median_centre_distance"]), _pct(s["within_1m"]), _pct(s["iou_0.7"]), _f(s["median_iou"]),
                     _f(s["median_limit"])])
    out += ["### All cars", "", _markdown(header, rows), ""]
    for title, groups in (("By distance (label depth z)", [b[0] for b in BANDS]),
                          ("By KITTI occlusion flag", [g[0] for g in OCCLUSION_GROUPS]),
                          ("By truncation at the image border (KITTI's truncated > 0)",
                           [g[0] for g in TRUNCATION_GROUPS])):
        header = ["variant", "group", "cars", "lateral", "range", "range (signed)", "1-px limit", "range / limit",
                  "az (deg)", "<1 m", "IoU>0.7"]
        rows = []
        for v in variants:
            for g in groups:
                s = summaries[v][g]
                rows.append([v, g, str(s["n"]), _f(s["median_abs_lateral"]), _f(s["median_abs_range"]),
                             _f(s["median_range"], "+.2f"), _f(s["median_limit"]),
                             _f(s["median_abs_range_over_limit"], ".1f"), _f(s["median_abs_azimuth"], ".1f"),
                             _pct(s["within_1m"]), _pct(s["iou_0.7"])])
        out += [f"### {title}", "", _markdown(header, rows), ""]
    for test, title in (("iou_0.7", "IoU > 0.7"), ("within_1m", "centre within 1 m")):
        for kind in ("perfect", "only"):
            cases = [f"perfect {c}" if kind == "perfect" else f"only {c} wrong" for c in COMPONENTS]
            header = ["variant", "cars", "as fitted"] + [c.replace(" wrong", "") for c in cases]
            if kind == "perfect":
                header.append("decided by")
            rows = []
            for v in variants:
                s = summaries[v]["all"]
                row = [v, str(s["n"]), _pct(s[test])] + [_pct(s["decomposition"][c][test]) for c in cases]
                if kind == "perfect":
                    best, lift = deciding_component(s, test)
                    row.append("-" if best is None else f"{best} (+{lift:.0f} pts)")
                rows.append(row)
            what = ("share passing with one component made perfect" if kind == "perfect"
                    else "share passing with every other component made perfect")
            out += [f"### {title}: {what}", "", _markdown(header, rows), ""]
    if comparison:
        header = ["variant", "group", "cars", "<1 m", f"vs {reference} (pts)", "range", f"vs {reference} (m)",
                  "gained", "lost"]
        rows = []
        for v, groups in comparison.items():
            for g in ["all"] + [b[0] for b in BANDS]:
                c = groups[g]
                rows.append([v, g, str(c["n"]), _pct(c["within_1m"]), _f(c["d_within_1m"], "+.1f"),
                             _f(c["median_abs_range"]), _f(c["d_median_abs_range"], "+.2f"), str(c["gained"]),
                             str(c["lost"])])
        out += [f"### Against {reference} (same cars; gained / lost: within 1 m here but not there / the reverse)", "",
                _markdown(header, rows), ""]
    return "\n".join(out)


def depth_curve(table: dict, *, bin_width: float = PLOT_BIN) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(median depth, median |range error|, cars) per ``bin_width`` bin of label depth,
    for the bins that hold cars."""
    z, err = table["label_depth"], np.abs(table["range"])
    if not z.size:
        return np.zeros(0), np.zeros(0), np.zeros(0, int)
    index = np.floor(z / bin_width).astype(int)
    bins = np.unique(index)
    return (np.array([np.median(z[index == b]) for b in bins]), np.array([np.median(err[index == b]) for b in bins]),
            np.array([np.sum(index == b) for b in bins]))


def plot(path: Path, runs: dict[str, dict[str, dict]], *, camera_height: float) -> None:
    """Median |range error| against depth per variant, one panel per run, with the
    one-pixel limit straight ahead (``z^2 / (f h)``, the runs' median focal length)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(runs), figsize=(6.5 * len(runs), 4.5), squeeze=False)
    for ax, (name, tables) in zip(axes[0], runs.items()):
        zmax, focal = 0.0, []
        for variant, table in tables.items():
            z, med, count = depth_curve(table)
            if z.size:
                ax.plot(z, med, marker="o", label=f"{variant} ({int(count.sum())} cars)")
                zmax = max(zmax, float(table["label_depth"].max()))
                focal.append(table["focal"])
        if focal:
            f = float(np.median(np.concatenate(focal)))
            zz = np.linspace(0.0, max(zmax, 5.0), 100)
            ax.plot(zz, one_pixel_range_limit(zz, zz, focal=f, camera_height=camera_height), "k--",
                    label=f"1 px at the ground contact, z²/(f h), f={f:.0f} px, h={camera_height:g} m")
        ax.set_xlabel("label depth z (m)")
        ax.set_ylabel(f"median |range error| (m), {PLOT_BIN:g} m bins")
        ax.set_title(name)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (module docstring); ``argv`` as for :meth:`argparse.ArgumentParser.parse_args`."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, metavar="RUN",
                    help="bench_real_folds.py --out directory (fold*/), or an eval --predictions directory")
    ap.add_argument("--root", required=True, help="the KITTI root the runs were fitted on (calibrations)")
    ap.add_argument("--split", default=None, help="the split folder under --root (default: training)")
    ap.add_argument("--camera-height", type=float, default=KITTI_CAMERA_HEIGHT,
                    help="camera height above the road for the one-pixel limit (m; the records hold no plane)")
    ap.add_argument("--reference", default="coarse+gp", help="variant the others are compared with")
    ap.add_argument("--json", type=Path, help="write everything, per car too, here")
    ap.add_argument("--plot", type=Path, help="write the range-error-against-depth plot here (PNG)")
    args = ap.parse_args(argv)
    if args.camera_height <= 0:
        ap.error("--camera-height must be positive")
    dataset = KittiDataset.of_default_split(args.root, args.split or DEFAULT_SPLIT)
    problem = args.split and given_split_problem(dataset, args.split, root=args.root, names=("--split", "--calib"))
    if problem:
        ap.error(problem)
    report, plotted = {}, {}
    names = [str(r) for r in args.runs]
    if len(set(names)) != len(names):
        ap.error("a run is given twice")
    for run, name in zip(args.runs, names):
        records, detections, tables = run_tables(run, dataset, camera_height=args.camera_height)
        frames = sorted({r.frame_id for rs in records.values() for r in rs})
        summaries = {v: {g: summarise(t, m) for g, m in group_masks(t).items()} for v, t in tables.items()}
        comparison = versus_reference(tables, args.reference) if args.reference in tables else None
        n_labels = sum(sum(is_type(o.type, CAR_TYPES) for o in r.gt) for r in next(iter(records.values())))
        print(format_report(name, detections, summaries, comparison, args.reference, camera_height=args.camera_height))
        print(f"{len(frames)} frames, {n_labels} labelled cars"
              + ("" if comparison else f"; no {args.reference} in this run, no comparison") + "\n")
        report[name] = {"detections": detections, "frames": len(frames), "labelled_cars": int(n_labels),
                        "summaries": summaries, "versus_reference": comparison,
                        "cars": tables}
        plotted[f"{Path(run).name} (detections: {detections})"] = tables
    if args.json:
        meta = {"camera_height": args.camera_height, "reference": args.reference, "iou_threshold": IOU_THRESHOLD,
                "loc_threshold": LOC_THRESHOLD, "bands": [b[0] for b in BANDS],
                "occlusion_groups": [g[0] for g in OCCLUSION_GROUPS],
                "truncation_groups": [g[0] for g in TRUNCATION_GROUPS], "components": list(COMPONENTS)}
        write_json(args.json, {"_meta": meta, "runs": report})
        print(f"json: {args.json}", file=sys.stderr)
    if args.plot:
        plot(args.plot, plotted, camera_height=args.camera_height)
        print(f"plot: {args.plot}", file=sys.stderr)


if __name__ == "__main__":
    main()
