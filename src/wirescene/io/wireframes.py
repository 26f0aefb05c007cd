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
    """Read a ``wireframes/FRAME.json`` file; :class:`InputError` if malformed."""
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
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed wireframe ground truth ({exc.__class__.__name__}: {exc})", path=path) from None


def wireframe_gt_dir(split_dir: Path) -> Path:
    """Where a split keeps its per-vertex ground truth (synthetic scenes have one)."""
    return Path(split_dir) / "wireframes"


def wireframe_gt_path(split_dir: Path, frame_id: str) -> Path:
    return wireframe_gt_dir(split_dir) / f"{frame_id}.json"
