"""Automatic annotation of the 36 wireframe vertices on a canonical car mesh.

All landmarks are read off the left-side :class:`~wirescene.cad.sideview.SideView`
(rays cast from +z), then mirrored to the right side so that every exemplar is exactly
left/right symmetric (``X[MIRROR] == X * (1, 1, -1)``). Definitions (heights are above
the ground, d = 10 cm):

- ``nose_top`` / ``nose_bottom``: upper end of the lowest silhouette run (``top``) and
  lowest skin pixel at ``d`` behind the front-most silhouette column; ``tail_*`` the
  same ``d`` in front of the rear-most column.
- ``headlight`` / ``taillight``: on the front (rear) face, half-way between the nose
  (tail) top and bottom, at 60 % of the nose-top half-width, x from a ray along the
  length axis.
- Wheel arches: see :func:`wirescene.cad.sideview.find_arches`. ``*_arch_front/rear``
  are the run ends at the sill / bumper height just outside the run. The wheel centre
  x is the middle of the run; the wheels are not part of the TORCS meshes, so the tyre
  is assumed to touch the ground and to leave 4 cm below the arch top: radius
  ``(arch_top - 0.04) / 2`` clipped to 0.25..0.40 m. ``*_wheel_ground`` lies below the
  centre at y = 0. Hub z: 3 cm inside the body side at the arch; contact point 10 cm further in
  (half a tyre width).
- Greenhouse: on the upper profile between ``tail_top`` and ``nose_top`` the roof is the
  stretch within 5 cm of the highest point; its ends are ``rear_window_top`` and
  ``windscreen_top``. ``windscreen_bottom`` is the most concave point of the profile
  between ``windscreen_top`` and ``nose_top`` (largest second difference
  ``h(x - 20 cm) + h(x + 20 cm) - 2 h(x)``: the steep windscreen meets the flatter
  bonnet; the nose's convex rounding scores negative), ``rear_window_bottom`` likewise
  between ``tail_top`` and ``rear_window_top``. z is the silhouette depth 4 cm
  inside the profile (for the two lower corners read 12 cm up the glass, since at the
  corner itself a side ray meets the wider wing) -- the first surface a ray from the
  side meets, so on a rounded greenhouse it may lie inboard of the true pillar.

Known limits: a fastback's rear window and boot form one slope, so the rear-window
bottom breakpoint is weakly determined; rear wings connected to the body by broad
mounting plates raise ``tail_top``. Such cases are fixed per car in
``wirescene/data/landmark_corrections.json`` ({car: {vertex name: [x, y, z]}}), which
:func:`annotate` applies after the automatic step; a corrected vertex also fixes its
mirror partner.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from wirescene.cad.sideview import SideView, find_arches, side_view
from wirescene.core.errors import InputError
from wirescene.core.raycast import require_ray_tracer
from wirescene.core.resources import DATA_DIR
from wirescene.core.validate import finite_real
from wirescene.core.wireframe import MIRROR, N_PER_SIDE, PART_NAMES, VERTEX_INDEX, VERTEX_NAMES

__all__ = ["annotate", "auto_landmarks", "load_corrections", "apply_corrections",
           "symmetrize", "CORRECTIONS_PATH"]

CORRECTIONS_PATH = DATA_DIR / "landmark_corrections.json"

END_INSET = 0.10
WHEEL_GAP = 0.04
WHEEL_RADIUS_RANGE = (0.25, 0.40)
HALF_TYRE = 0.10
CORNER_SCALE = 0.2
PILLAR_STEP = 0.12
ROOF_DROP = 0.05


def auto_landmarks(vertices, faces, *, res: float = 0.01, view: SideView | None = None) -> np.ndarray:
    """Automatic 36 landmarks (see the module docstring) of an object-frame car mesh.

    Returns
    -------
    (36, 3) array, exactly left/right symmetric.

    Raises
    ------
    InputError
        If no wheel arch or no silhouette can be found (not a car-like mesh).
    """
    import trimesh

    sv = view if view is not None else side_view(vertices, faces, res=res)
    v = np.asarray(vertices, dtype=float)
    if sv.front_col - sv.rear_col < 10:
        raise InputError("mesh has no usable side silhouette")
    left = {}

    def put(name, x, h, z):
        left[name] = (float(x), -float(h), float(z))

    # Ends of the car.
    inset = int(round(END_INSET / sv.res))
    front_col, rear_col = sv.front_col - inset, sv.rear_col + inset
    for prefix, c in (("nose", front_col), ("tail", rear_col)):
        x = sv.xs[c]
        h_top, h_bot = sv.top[c], sv.low_skin[c]
        if not np.isfinite(h_bot):
            h_bot = sv.hs[int(np.argmax(sv.silhouette[:, c]))]
        put(f"{prefix}_top", x, h_top, sv.z_near(x, h_top - 0.03))
        put(f"{prefix}_bottom", x, h_bot, sv.z_near(x, h_bot + 0.03))

    # Head/tail lights: rays along the length axis onto the front/rear face.
    mesh = trimesh.Trimesh(v, np.asarray(faces), process=False)
    require_ray_tracer()
    for light, prefix, sign in (("headlight", "nose", 1.0), ("taillight", "tail", -1.0)):
        top, bot = left[f"{prefix}_top"], left[f"{prefix}_bottom"]
        y = 0.5 * (top[1] + bot[1])
        z = 0.6 * top[2]
        origin = np.array([[sign * (np.abs(v[:, 0]).max() + 1.0), y, z]])
        loc, _, _ = mesh.ray.intersects_location(origin, np.array([[-sign, 0.0, 0.0]]), multiple_hits=False)
        x = loc[0, 0] if len(loc) else top[0]
        left[light] = (float(x), float(y), float(z))

    # Wheels and arches.
    front, rear, sill = find_arches(sv)
    for axle, run in (("front", front), ("rear", rear)):
        if run is None:
            raise InputError(f"no {axle} wheel arch found in the side silhouette")
        a, b = run
        cx = 0.5 * (sv.xs[a] + sv.xs[b - 1])
        arch_top = float(np.nanmax(sv.low_skin[a:b]))
        r = float(np.clip((arch_top - WHEEL_GAP) / 2, *WHEEL_RADIUS_RANGE))
        # Hub: just inside the body side at the top of the arch.
        z_side = sv.z_near(cx, arch_top + 0.03, toward=(cx, sv.hs[-1]))
        z_hub = z_side - 0.03
        put(f"{axle}_wheel_center", cx, r, z_hub)
        put(f"{axle}_wheel_ground", cx, 0.0, z_hub - HALF_TYRE)
        for name, c in (("arch_front", min(b, len(sv.xs) - 1)), ("arch_rear", max(a - 1, 0))):
            h = sv.low_skin[c]
            h = sill if not np.isfinite(h) else h
            put(f"{axle}_{name}", sv.xs[c], h, sv.z_near(sv.xs[c], h + 0.03))

    # Greenhouse from the upper profile: the roof is where the profile is within
    # ROOF_DROP of its peak; the glass meets bonnet / boot at the concave corners.
    step = max(1, int(round(0.02 / sv.res)))
    idx = np.arange(rear_col, front_col + 1, step)
    idx = idx[np.isfinite(sv.top[idx])]
    prof = sv.top[idx]
    roof = np.flatnonzero(prof >= np.nanmax(prof) - ROOF_DROP)
    r0, r1 = int(roof[0]), int(roof[-1])
    w = max(1, int(round(CORNER_SCALE / (step * sv.res))))
    corners = {"rear_window_top": r0, "windscreen_top": r1}
    for name, lo, hi in (("rear_window_bottom", 0, r0), ("windscreen_bottom", r1, len(idx) - 1)):
        k = np.arange(lo + w, hi - w + 1)
        if len(k):
            # Concave corner (steep glass meets flatter bonnet / boot): largest second
            # difference at the scale of CORNER_SCALE.
            corners[name] = int(k[np.argmax(prof[k - w] + prof[k + w] - 2 * prof[k])])
        else:
            corners[name] = (lo + hi) // 2
    roof_mid = 0.5 * (sv.xs[idx[r0]] + sv.xs[idx[r1]])
    up_to = {"windscreen_bottom": "windscreen_top", "rear_window_bottom": "rear_window_top"}
    for name, k in corners.items():
        x, h = sv.xs[idx[k]], prof[k]
        zx, zh = x, h
        if name in up_to:
            # Read the pillar's z a little way up the glass: at the corner itself the
            # side ray meets the (wider) wing / fender.
            k2 = corners[up_to[name]]
            d = np.array([sv.xs[idx[k2]] - x, prof[k2] - h])
            zx, zh = np.array([x, h]) + PILLAR_STEP * d / max(np.linalg.norm(d), 1e-9)
        put(name, x, h, sv.z_near(zx, zh - 0.04, toward=(roof_mid, 0.0), max_dist=0.3))

    X = np.zeros((len(VERTEX_NAMES), 3))
    for i, p in enumerate(PART_NAMES):
        X[i] = left[p]
    X[N_PER_SIDE:] = X[:N_PER_SIDE] * (1, 1, -1)
    return X


def symmetrize(X: np.ndarray) -> np.ndarray:
    """Average a wireframe with its mirror image (exact left/right symmetry)."""
    X = np.asarray(X, dtype=float)
    return 0.5 * (X + X[..., MIRROR, :] * np.array([1.0, 1.0, -1.0]))


def load_corrections(path=None) -> dict:
    """Manual landmark corrections ``{car: {vertex name: [x, y, z]}}`` (object frame).

    ``path`` defaults to the package's ``data/landmark_corrections.json``; a missing
    default file means no corrections."""
    p = CORRECTIONS_PATH if path is None else Path(path)
    if not p.exists():
        if path is None:
            return {}
        raise InputError("landmark corrections file not found", path=p)
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError) as e:  # ValueError: bad JSON or bytes not UTF-8 (UnicodeDecodeError)
        raise InputError(f"cannot read landmark corrections ({e})", path=p) from None
    if not isinstance(data, dict):
        raise InputError("landmark corrections must be a JSON object {car: {vertex: [x, y, z]}}", path=p)
    for car, fixes in data.items():
        if car.startswith("_"):
            continue  # comments
        if not isinstance(fixes, dict):
            raise InputError(f"corrections of car {car!r} must be a JSON object {{vertex: [x, y, z]}}", path=p)
        for name, xyz in fixes.items():
            if name not in VERTEX_INDEX:
                raise InputError(f"unknown vertex name {name!r} for car {car!r}", path=p)
            if not (isinstance(xyz, list) and len(xyz) == 3 and all(finite_real(v) for v in xyz)):
                got = repr(xyz)  # cut: a list of thousands of numbers is no line to read
                raise InputError(f"correction of {car}/{name} must be [x, y, z] of finite numbers, got "
                                 f"{got if len(got) <= 60 else got[:57] + '...'}", path=p)
    return data


def apply_corrections(name: str, X: np.ndarray, corrections: dict) -> np.ndarray:
    """Overwrite vertices of car ``name`` from ``corrections`` and set each corrected
    vertex's mirror partner to its mirror image."""
    X = np.array(X, dtype=float)
    for vname, xyz in corrections.get(name, {}).items():
        i = VERTEX_INDEX[vname]
        X[i] = xyz
        X[MIRROR[i]] = np.array(xyz, dtype=float) * (1, 1, -1)
    return X


def annotate(vertices, faces, *, name: str | None = None, corrections: dict | None = None,
             res: float = 0.01) -> np.ndarray:
    """36 landmarks of an object-frame car mesh: automatic, then manual corrections.

    Parameters
    ----------
    vertices : (N, 3) array
    faces : (F, 3) int array
    name : str, optional
        Car name looked up in ``corrections``.
    corrections : dict, optional
        Defaults to :func:`load_corrections` ().
    res : float, optional
        Metres per pixel of the side-view silhouette the automatic landmarks are read
        from (:func:`auto_landmarks`).

    Returns
    -------
    (36, 3) array
    """
    X = auto_landmarks(vertices, faces, res=res)
    if name is not None:
        X = apply_corrections(name, X, load_corrections() if corrections is None else corrections)
    return X
