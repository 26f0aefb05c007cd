"""The files of one fitted image: KITTI labels, JSON, wireframe overlay and bird's-eye view
(matplotlib imported only to draw the pictures: ``predict`` writes the JSON without it)."""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import numpy as np

from wirescene.core.atomic import atomic_path, missing_dirs, remove_empty
from wirescene.core.camera import Camera
from wirescene.core.errors import ArgumentError, InputError
from wirescene.core.jsonio import dumps
from wirescene.core.labels import Label
from wirescene.core.types import Detections, SceneEstimate, dropped_detections, fitted_detections
from wirescene.core.wireframe import EDGES


def boxes_in_words(source: str) -> str:
    """What a fit started from, for a picture's title: ``Detections.source`` in words.

    Examples
    --------
    >>> boxes_in_words("gt"), boxes_in_words("bank"), boxes_in_words("dets/000010.json")
    ('label boxes', 'own pre-detection', 'boxes of 000010.json')
    """
    named = {"gt": "label boxes", "bank": "own pre-detection", "api": "given boxes", "": "given boxes"}
    return named.get(source, f"boxes of {Path(source).name}")


def fit_output_paths(out_dir: Path, stem: str) -> dict[str, Path]:
    """``{"labels", "json", "overlay", "bev": path}``: the files :func:`write_fit_outputs` writes
    (and ``predict --json-dir`` / ``--pictures`` by the same names).

    Examples
    --------
    >>> {kind: path.name for kind, path in fit_output_paths(Path("out"), "000010").items()}
    {'labels': '000010.txt', 'json': '000010.json', 'overlay': '000010_overlay.png', 'bev': '000010_bev.png'}
    """
    out_dir = Path(out_dir)
    return {"labels": out_dir / f"{stem}.txt", "json": out_dir / f"{stem}.json",
            "overlay": out_dir / f"{stem}_overlay.png", "bev": out_dir / f"{stem}_bev.png"}


def fit_outputs_problem(paths: dict[str, Path]) -> tuple[Path, str] | None:
    """``(path, problem)`` of the first of ``paths`` (:func:`fit_output_paths`) that cannot be
    written as a file (a folder of its name is there), or None."""
    for path in paths.values():
        if path.is_dir():
            return path, "a folder where the fit writes a file"
    return None


def write_fit_outputs(
    out_dir: Path,
    stem: str,
    *,
    image: np.ndarray,
    camera: Camera,
    estimate: SceneEstimate,
    detections: Detections,
    gt: list[Label] | None = None,
) -> dict[str, Path]:
    """Write ``STEM.txt`` (KITTI labels), ``STEM.json`` (:func:`scene_json`), ``STEM_overlay.png``
    and ``STEM_bev.png`` (:func:`scene_pictures`). The four files are made in memory, written to
    temporary files in ``out_dir`` and renamed into place only when all are complete: if any
    fails (a picture too large to draw, a full disk) ``out_dir`` is left as it was, an earlier
    run's files of ``STEM`` included, and the directories made for it are removed."""
    out_dir = Path(out_dir)
    paths = fit_output_paths(out_dir, stem)
    problem = fit_outputs_problem(paths)
    if problem:
        raise InputError(problem[1], path=problem[0])
    made = missing_dirs(out_dir)
    try:
        files = {"labels": estimate.to_kitti().encode(),
                 "json": scene_json(stem, estimate, detections).encode(),
                 **scene_pictures(stem, image=image, camera=camera, estimate=estimate, detections=detections, gt=gt)}
        with ExitStack() as stack:  # each temporary file replaces its path as the block ends without error
            for kind, path in paths.items():
                stack.enter_context(atomic_path(path, suffix=path.suffix)).write_bytes(files[kind])
    except BaseException:
        remove_empty(made)
        raise
    return paths


def scene_json(stem: str, estimate: SceneEstimate, detections: Detections) -> str:
    """The JSON file of a fitted image (``fit``'s ``STEM.json``, ``predict --json-dir``'s
    ``FRAME.json``): the frame, where its boxes came from and the scene
    (:meth:`~wirescene.core.types.SceneEstimate.to_dict`: each car's 3D box and ground plane, and
    of a fine variant its wireframe and visible vertices); strict JSON (``null`` for a non-finite
    number).

    Parameters
    ----------
    stem : str
        The frame's name, written as ``"frame"``.
    estimate : SceneEstimate
        What :func:`wirescene.fit` returned.
    detections : Detections
        The boxes the scene was fitted to (``estimate.detections``); their ``source`` is
        written as ``"detections_source"``.

    Returns
    -------
    str

    Raises
    ------
    ArgumentError
        An argument of another type, naming it.

    Examples
    --------
    >>> import json
    >>> scene = json.loads(scene_json("000010", SceneEstimate("coarse", []), Detections(np.zeros((0, 4)), 1.0, np.nan)))
    >>> scene["frame"], scene["variant"], scene["objects"]
    ('000010', 'coarse', [])
    >>> scene_json("000010", SceneEstimate("coarse", []), None)
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ArgumentError: detections: expected Detections (the scene's own: scene.detections), got NoneType
    """
    for name, value, kind, said in (("stem", stem, str, "the frame's name (str)"),
                                    ("estimate", estimate, SceneEstimate, "what wirescene.fit returns (SceneEstimate)"),
                                    ("detections", detections, Detections,
                                     "Detections (the scene's own: scene.detections)")):
        if not isinstance(value, kind):
            raise ArgumentError(name, f"expected {said}, got {type(value).__name__}")
    return dumps({"frame": stem, "detections_source": detections.source, **estimate.to_dict()})


def scene_figures(stem: str, *, image: np.ndarray, camera: Camera, estimate: SceneEstimate, detections: Detections,
                  gt: list[Label] | None = None):
    """``(overlay, bird's-eye view)``: the two pictures of a fitted image, as matplotlib figures
    (:func:`wirescene.io.pictures.overlay`, :func:`~wirescene.io.pictures.birds_eye`). The overlay
    draws the pre-detections of the fitted cars dashed and those the fit's verification dropped
    dotted grey; ``gt``: label cars drawn beside the estimate (None: no labels; empty: none a car)."""
    from wirescene.io.pictures import birds_eye, overlay

    title = f"{stem}  {estimate.variant}, {boxes_in_words(detections.source)}"
    fig_overlay = overlay(image, camera, estimate, gt=gt, detections=fitted_detections(detections, estimate),
                          dropped=dropped_detections(detections, estimate), title=title, edges=EDGES)
    return fig_overlay, birds_eye(estimate, gt=gt, camera=camera, title=title)


def scene_pictures(stem: str, *, image: np.ndarray, camera: Camera, estimate: SceneEstimate, detections: Detections,
                   gt: list[Label] | None = None) -> dict[str, bytes]:
    """``{"overlay", "bev": PNG bytes}``: :func:`scene_figures` as the files ``fit`` and ``predict
    --pictures`` write (:func:`wirescene.io.pictures.figure_bytes`; keys those of
    :func:`fit_output_paths`)."""
    from wirescene.io.pictures import figure_bytes

    figures = scene_figures(stem, image=image, camera=camera, estimate=estimate, detections=detections, gt=gt)
    return {kind: figure_bytes(fig) for kind, fig in zip(("overlay", "bev"), figures)}
