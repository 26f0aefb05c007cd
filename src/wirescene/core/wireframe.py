"""Topology of the 36-vertex car wireframe (constant data only).

The wireframe follows the spirit of Zia et al. (PAMI 2013, IJCV 2015, Fig. 2): 18
landmarks per side of the car, in left/right symmetric pairs. Vertex ``i`` (``i < 18``)
is on the car's LEFT side (object frame ``z > 0``), vertex ``i + 18`` is its mirror on
the RIGHT side (``z < 0``), so ``MIRROR`` swaps the two halves.

The 18 landmarks of one side, front to back (object frame: x forward, y down, z left):

==================== ==========================================================
``nose_bottom``      front bumper, lower outer corner
``nose_top``         front bumper / bonnet, upper outer corner
``headlight``        on the front face, inboard of the corner (nose rounding)
``front_arch_front`` front wheel arch, front foot (where it meets the body bottom)
``front_wheel_center`` front wheel hub, outer face
``front_wheel_ground`` front tyre contact point on the ground (y = 0)
``front_arch_rear``  front wheel arch, rear foot
``windscreen_bottom`` A-pillar base (bonnet / windscreen corner)
``windscreen_top``   A-pillar top (front roof corner)
``rear_window_top``  C-pillar top (rear roof corner)
``rear_window_bottom`` C-pillar base (rear window / boot-lid corner)
``rear_arch_front``  rear wheel arch, front foot
``rear_wheel_center`` rear wheel hub, outer face
``rear_wheel_ground`` rear tyre contact point on the ground (y = 0)
``rear_arch_rear``   rear wheel arch, rear foot
``taillight``        on the rear face, inboard of the corner (tail rounding)
``tail_top``         rear bumper / boot lid, upper outer corner
``tail_bottom``      rear bumper, lower outer corner
==================== ==========================================================

``FACES`` triangulate a closed surface (every edge is shared by exactly two faces,
normals point outwards, i.e. counter-clockwise seen from outside): each side is the
polygon running along the body bottom through the tyre contact points and back over
the greenhouse, the two sides are joined by bands over the top (bonnet, windscreen,
roof, rear window, boot) and along the bottom, and front and rear faces are closed
through the headlights / taillights. The wheel arches are not cut out: the wheels fill
them, which is what matters for occlusion reasoning.
"""

from __future__ import annotations

import numpy as np

PART_NAMES = (
    "nose_bottom",
    "nose_top",
    "headlight",
    "front_arch_front",
    "front_wheel_center",
    "front_wheel_ground",
    "front_arch_rear",
    "windscreen_bottom",
    "windscreen_top",
    "rear_window_top",
    "rear_window_bottom",
    "rear_arch_front",
    "rear_wheel_center",
    "rear_wheel_ground",
    "rear_arch_rear",
    "taillight",
    "tail_top",
    "tail_bottom",
)
"""The 18 landmark names of one side."""

N_PER_SIDE = len(PART_NAMES)
N_VERTICES = 2 * N_PER_SIDE

VERTEX_NAMES = tuple(f"{p}_left" for p in PART_NAMES) + tuple(f"{p}_right" for p in PART_NAMES)
"""Names of the 36 vertices: 18 on the left side (z > 0), then their mirrors."""

VERTEX_INDEX = {name: i for i, name in enumerate(VERTEX_NAMES)}

MIRROR = np.concatenate([np.arange(N_PER_SIDE, N_VERTICES), np.arange(N_PER_SIDE)])
"""Left/right permutation: ``X[MIRROR] * (1, 1, -1)`` is the mirror image of ``X``."""
MIRROR.setflags(write=False)

SIDE = np.concatenate([np.ones(N_PER_SIDE, dtype=np.int8), -np.ones(N_PER_SIDE, dtype=np.int8)])
"""+1 for vertices on the left (z > 0), -1 on the right."""
SIDE.setflags(write=False)

HIDDEN_BY = ("visible", "self", "truncated", "other-car", "occluder")
"""Why a vertex of a fitted car is hidden (:attr:`wirescene.core.types.ObjectEstimate.hidden_by`), the
words of ``wirescene synth``'s per-vertex ground truth: not (``visible``), by its own car (``self``),
by the image's border (``truncated``: projected outside the image), by another car of the scene
(``other-car``) or by the occluder mask the fit chose (``occluder``); a vertex hidden twice takes
the first of these (synth's own takes ``truncated`` before ``self``: a vertex of the far side outside
the image is ``self`` here, ``truncated`` there)."""

PART = np.concatenate([np.arange(N_PER_SIDE), np.arange(N_PER_SIDE)])
"""Index into ``PART_NAMES`` of every vertex (the same for a symmetric pair)."""
PART.setflags(write=False)

GROUPS = {
    "front": ("nose_bottom", "nose_top", "headlight"),
    "rear": ("taillight", "tail_top", "tail_bottom"),
    "wheels": ("front_wheel_center", "front_wheel_ground", "rear_wheel_center", "rear_wheel_ground"),
    "arches": ("front_arch_front", "front_arch_rear", "rear_arch_front", "rear_arch_rear"),
    "greenhouse": ("windscreen_bottom", "windscreen_top", "rear_window_top", "rear_window_bottom"),
}
"""Part groups (one-side names) useful for drawing and for part configurations."""


def _i(part: str, side: str) -> int:
    return VERTEX_INDEX[f"{part}_{side}"]


def _build_edges() -> np.ndarray:
    outline = ["nose_bottom", "front_arch_front", "front_arch_rear", "rear_arch_front", "rear_arch_rear",
               "tail_bottom", "tail_top", "rear_window_bottom", "rear_window_top", "windscreen_top",
               "windscreen_bottom", "nose_top"]
    edges = []
    for side in ("left", "right"):
        for a, b in zip(outline, outline[1:] + outline[:1]):
            edges.append((_i(a, side), _i(b, side)))
        edges.append((_i("windscreen_bottom", side), _i("rear_window_bottom", side)))  # beltline
        for axle in ("front", "rear"):
            c = _i(f"{axle}_wheel_center", side)
            for p in ("arch_front", "arch_rear", "wheel_ground"):
                edges.append((c, _i(f"{axle}_{p}", side)))
        edges.append((_i("headlight", side), _i("nose_top", side)))
        edges.append((_i("headlight", side), _i("nose_bottom", side)))
        edges.append((_i("taillight", side), _i("tail_top", side)))
        edges.append((_i("taillight", side), _i("tail_bottom", side)))
    for p in ("nose_bottom", "nose_top", "headlight", "windscreen_bottom", "windscreen_top",
              "rear_window_top", "rear_window_bottom", "taillight", "tail_top", "tail_bottom"):
        edges.append((_i(p, "left"), _i(p, "right")))
    return np.array(edges, dtype=np.int64)


EDGES = _build_edges()
"""(E, 2) vertex index pairs to draw the wireframe."""
EDGES.setflags(write=False)

# Literal (F, 3) triangle table; see the module docstring for its layout. Orientation:
# counter-clockwise seen from outside (outward normals), checked in tests/test_shape.py.
FACES = np.array(
    [
        [3, 5, 4],
        [22, 23, 21],
        [5, 6, 4],
        [22, 24, 23],
        [11, 13, 12],
        [30, 31, 29],
        [13, 14, 12],
        [30, 32, 31],
        [0, 3, 4],
        [22, 21, 18],
        [0, 4, 1],
        [19, 22, 18],
        [1, 4, 7],
        [25, 22, 19],
        [4, 6, 11],
        [29, 24, 22],
        [4, 11, 12],
        [30, 29, 22],
        [4, 12, 7],
        [25, 30, 22],
        [7, 12, 10],
        [28, 30, 25],
        [12, 14, 17],
        [35, 32, 30],
        [12, 17, 16],
        [34, 35, 30],
        [12, 16, 10],
        [28, 34, 30],
        [7, 10, 9],
        [27, 28, 25],
        [7, 9, 8],
        [26, 27, 25],
        [1, 7, 25],
        [1, 25, 19],
        [7, 8, 26],
        [7, 26, 25],
        [8, 9, 27],
        [8, 27, 26],
        [9, 10, 28],
        [9, 28, 27],
        [10, 16, 34],
        [10, 34, 28],
        [21, 3, 0],
        [18, 21, 0],
        [23, 5, 3],
        [21, 23, 3],
        [24, 6, 5],
        [23, 24, 5],
        [29, 11, 6],
        [24, 29, 6],
        [31, 13, 11],
        [29, 31, 11],
        [32, 14, 13],
        [31, 32, 13],
        [35, 17, 14],
        [32, 35, 14],
        [1, 2, 0],
        [20, 2, 1],
        [19, 20, 1],
        [20, 18, 0],
        [2, 20, 0],
        [20, 19, 18],
        [17, 15, 16],
        [16, 15, 33],
        [16, 33, 34],
        [17, 35, 33],
        [17, 33, 15],
        [35, 34, 33],
    ],
    dtype=np.int64,
)
"""(F, 3) outward-oriented triangles of the closed wireframe surface."""
FACES.setflags(write=False)
