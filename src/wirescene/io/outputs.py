"""The files of one fitted image: KITTI labels, JSON, wireframe overlay and bird's-eye view."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from wirescene.core.atomic import write_text
from wirescene.core.camera import Camera
from wirescene.core.labels import Label
from wirescene.core.types import Detections, SceneEstimate
from wirescene.core.wireframe import EDGES
from wirescene.io.kitti import write_labels
from wirescene.io.pictures import birds_eye, overlay, save_figure


def boxes_in_words(source: str) -> str:
    """What a fit started from, for a picture's title: ``Detections.source`` in words.

    Examples
    --------
    >>> boxes_in_words("gt"), boxes_in_words("bank"), boxes_in_words("dets/000010.json")
    ('label boxes', 'own pre-detection', 'boxes of 000010.json')
    """
    named = {"gt": "label boxes", "bank": "own pre-detection", "api": "given boxes", "": "given boxes"}
    return named.get(source, f"boxes of {Path(source).name}")


def fitted_detections(detections: Detections, estimate: SceneEstimate) -> Detections:
    """The pre-detections of the cars of ``estimate``, in detection order: those the fit's
    verification dropped (our own pre-detection's) are left out, as from the fit's output.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.types import ObjectEstimate
    >>> dets = Detections([[0, 0, 10, 10], [20, 0, 30, 10], [40, 0, 50, 10]], 1.0, np.nan)
    >>> car = ObjectEstimate(detection_index=2, box2d=dets.boxes[2], score=1.0, location=np.array([0.0, 1.65, 9.0]),
    ...                      R=np.eye(3), dims=np.array([1.5, 1.6, 3.9]), cost=0.0)
    >>> fitted_detections(dets, SceneEstimate(variant="coarse", objects=[car])).boxes
    array([[40.,  0., 50., 10.]])
    """
    return detections.subset(np.array(sorted(o.detection_index for o in estimate.objects), dtype=int))


def write_fit_outputs(
    out_dir: Path,
    stem: str,
    *,
    image: np.ndarray,
    camera: Camera,
    estimate: SceneEstimate,
    detections: Detections,
    gt: list[Label] = (),
) -> dict[str, Path]:
    """Write ``STEM.txt`` (KITTI labels), ``STEM.json``, ``STEM_overlay.png`` and
    ``STEM_bev.png``. The overlay draws the pre-detections of the fitted cars (not those
    the fit's verification dropped). Everything is rendered in memory first; if any write
    fails the files already written by this call are removed, so no partial result remains."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    payload = json.dumps({"frame": stem, "detections_source": detections.source, **estimate.to_dict()}, indent=1)
    fitted = fitted_detections(detections, estimate)
    title = f"{stem}  {estimate.variant}, {boxes_in_words(detections.source)}"
    fig_overlay = overlay(image, camera, estimate, gt=gt, detections=fitted, title=title, edges=EDGES)
    fig_bev = birds_eye(estimate, gt=gt, camera=camera, title=title)
    paths = {
        "labels": out_dir / f"{stem}.txt",
        "json": out_dir / f"{stem}.json",
        "overlay": out_dir / f"{stem}_overlay.png",
        "bev": out_dir / f"{stem}_bev.png",
    }
    written: list[Path] = []
    try:
        write_labels(paths["labels"], estimate.to_labels())
        written.append(paths["labels"])
        write_text(paths["json"], payload)
        written.append(paths["json"])
        save_figure(fig_overlay, paths["overlay"])
        written.append(paths["overlay"])
        save_figure(fig_bev, paths["bev"])
        written.append(paths["bev"])
    except BaseException:
        for p in written:
            p.unlink(missing_ok=True)
        raise
    return paths
