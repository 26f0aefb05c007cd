"""Per-vertex ground truth stored beside KITTI labels in ``wireframes/FRAME.json``
(written by ``wirescene synth``): for every labelled car, in label order, its 36
wireframe vertices, their projections and a visibility reason per vertex."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wirescene.core.errors import InputError


@dataclass
class WireframeGT:
    """Vertex ground truth of the labelled cars of one frame (lists aligned with labels)."""

    vertices_2d: list  # (36, 2) arrays
    visible: list  # (36,) bool arrays
    self_occluded: list  # (36,) bool arrays
    occluded_parts: list  # int: occluded, not self-occluded vertices
    ground_plane: dict


def read_wireframe_gt(path: str | Path) -> WireframeGT:
    """Read a ``wireframes/FRAME.json`` file; :class:`InputError` if missing or malformed.

    Each car of its ``"cars"`` list needs ``vertices_2d`` ``(36, 2)``, ``visible`` ``(36,)``,
    ``visibility`` (a reason a vertex: ``"visible"``, ``"self"``, ``"other-car"`` or
    ``"occluder"``) and ``n_occluded_not_self``.

    Examples
    --------
    >>> import json, tempfile
    >>> reasons = ["visible"] * 30 + ["self"] * 4 + ["other-car"] * 2
    >>> car = {"vertices_2d": np.zeros((36, 2)).tolist(), "visible": [r == "visible" for r in reasons],
    ...        "visibility": reasons, "n_occluded_not_self": 2}
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = wireframe_gt_path(Path(d), "000003")
    ...     path.parent.mkdir()
    ...     _ = path.write_text(json.dumps({"cars": [car], "ground_plane": {"pitch": 0.0}}))
    ...     gt = read_wireframe_gt(path)
    >>> gt.vertices_2d[0].shape, int(gt.visible[0].sum()), int(gt.self_occluded[0].sum()), gt.occluded_parts
    ((36, 2), 30, 4, [2])
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        cars = data["cars"]
        return WireframeGT(
            vertices_2d=[np.asarray(c["vertices_2d"], float) for c in cars],
            visible=[np.asarray(c["visible"], bool) for c in cars],
            self_occluded=[np.asarray([r == "self" for r in c["visibility"]]) for c in cars],
            occluded_parts=[int(c["n_occluded_not_self"]) for c in cars],
            ground_plane=dict(data.get("ground_plane", {})),
        )
    except FileNotFoundError:
        raise InputError("wireframe ground truth not found", path=path) from None
    except OSError as exc:  # a directory, a file that may not be read
        raise InputError(f"cannot read the wireframe ground truth ({exc.strerror or exc})", path=path) from None
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed wireframe ground truth ({exc.__class__.__name__}: {exc})", path=path) from None


def wireframe_gt_dir(split_dir: Path) -> Path:
    """Where a split keeps its per-vertex ground truth (synthetic scenes have one).

    Examples
    --------
    >>> wireframe_gt_dir(Path("synth") / "training").as_posix()
    'synth/training/wireframes'
    >>> wireframe_gt_path(Path("synth") / "training", "000003").as_posix()
    'synth/training/wireframes/000003.json'
    """
    return Path(split_dir) / "wireframes"


def wireframe_gt_path(split_dir: Path, frame_id: str) -> Path:
    """``wireframes/FRAME.json`` of a split (see :func:`wireframe_gt_dir`)."""
    return wireframe_gt_dir(split_dir) / f"{frame_id}.json"
