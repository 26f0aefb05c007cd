"""Loading CAD car meshes and bringing them into the object frame.

Object frame (the one representation of shape in wirescene): KITTI object coordinates
in metres, x forward (front bumper at +x), y DOWN (ground at y = 0), z to the car's
left; origin at the bottom centre of the axis-aligned bounding box.

Canonicalisation rules (:func:`canonicalize`), each decided from geometry alone:

1. **Units.** ``units="auto"`` picks the factor among metres, centimetres, millimetres
   and inches that brings the longest bounding-box side into 2.5..7 m (a car).
2. **Up axis.** Given (``up=``) or, if ``None``, the shortest bounding-box axis. Its
   sign is chosen so that the car is narrower at the top than at the bottom (the
   greenhouse sits on a wider body), measured as the mean absolute lateral coordinate
   of the vertices in the top vs. the bottom fifth of the height.
3. **Left/right axis.** Of the two horizontal axes, the one about whose mid-plane the
   mesh is most mirror-symmetric (median nearest-neighbour distance of the mirrored
   vertices, relative to the extent); the other is the length axis. Cars are
   left/right symmetric, but never front/back symmetric.
4. **Front.** The bonnet slopes down to the nose while the tail carries the boot lid
   (and, on race cars, a spoiler): over the outer 15 % of the length at each end, the
   end whose upper silhouette (highest vertex per length bin) is lower on average is
   the front -- if it is lower by at least 10 cm. Otherwise the evidence is too weak
   (e.g. a VW Beetle, whose engine lid falls like a bonnet) and the file's positive
   length axis is taken as forward, the TORCS/AC3D convention. On the 16 TORCS
   models with a clear margin (0.24..0.64 m) the rule agrees with that convention and
   with the steering wheel / driver position and rear wings where present.
5. **Placement.** Ground at the lowest vertex (y = 0), centred on the bounding box in
   x and z. The transform is a proper rotation (z = x cross y), so face winding is kept.

Road-car rule (:func:`road_car_check`): a mesh is a road car if (a) its height is at
least 1.0 m (open-wheelers and buggies have no closed cabin roof and are lower), (b)
its body is at least 1.5 m wide (an open-wheeler's tub is narrow; its wheels stick out
of it), and (c) the approach clearance -- the lowest point of the side silhouette between the
front end and the front wheel arch, see :func:`wirescene.cad.sideview.approach_clearance`
-- is below 0.15 m (off-road bodies with cut-away bumpers and lifted suspension are
higher; measured 0.20 m on the baja-bug and at most 0.055 m on the road cars). Mesh heights include antennas, so (a) is generous.
"""

from __future__ import annotations

import os
import re
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from wirescene.core.errors import InputError
from wirescene.core.validate import path_problem

__all__ = [
    "CarMesh",
    "read_mesh",
    "canonicalize",
    "load_car",
    "road_car_check",
    "list_cad_files",
    "default_cad_dir",
    "MESH_SUFFIXES",
    "naming_the_file",
]

MESH_SUFFIXES = (".acc", ".ac", ".obj", ".ply", ".off", ".stl")
_UNREAD_MESHES = {".joe": "VDrift's format", ".blend": "Blender's format", ".fbx": "Autodesk FBX",
                  ".dae": "COLLADA", ".3ds": "3D Studio"}

MIN_ROAD_HEIGHT = 1.0
MIN_ROAD_WIDTH = 1.5
MAX_ROAD_CLEARANCE = 0.15
MIN_FRONT_MARGIN = 0.10

_UNIT_FACTORS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254}


@dataclass
class CarMesh:
    """A car mesh in the object frame.

    Attributes
    ----------
    name : str
        File stem, e.g. ``"p406"``.
    vertices : (N, 3) float array
        Object frame, metres.
    faces : (F, 3) int array
    source : str
        File the mesh was read from.
    info : dict
        What canonicalisation decided (scale, axes, front evidence, symmetry error).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    source: str = ""
    info: dict = field(default_factory=dict)

    @property
    def dimensions(self) -> np.ndarray:
        """(3,) length, width, height in metres (KITTI's l, w, h)."""
        ext = self.vertices.max(axis=0) - self.vertices.min(axis=0)
        return np.array([ext[0], ext[2], ext[1]])


def default_cad_dir() -> Path:
    """``$WIRESCENE_CAD_DIR`` if set, else ``../shared/data/cad/torcs`` (relative to the
    current directory)."""
    env = os.environ.get("WIRESCENE_CAD_DIR")
    return Path(env) if env else Path("..") / "shared" / "data" / "cad" / "torcs"


def list_cad_files(cad_dir) -> list[Path]:
    """Sorted mesh files (by suffix) in ``cad_dir`` and in its subfolders one level down
    (Speed Dreams keeps one folder per car); :class:`InputError` if there are none."""
    cad_dir = Path(cad_dir)
    problem = path_problem(cad_dir, "CAD", directory=True,
                           missing="CAD directory not found (pass --cad-dir or set WIRESCENE_CAD_DIR)")
    if problem:
        raise InputError(problem, path=cad_dir)
    found = [*cad_dir.glob("*"), *cad_dir.glob("*/*")]
    files = sorted((p for p in found if p.suffix.lower() in MESH_SUFFIXES and p.is_file()),
                   key=lambda p: (p.name, p.as_posix()))
    if not files:
        others = sorted({p.suffix.lower() for p in found if p.is_file() and p.suffix.lower() in _UNREAD_MESHES})
        unread = f"; {', '.join(f'{s} ({_UNREAD_MESHES[s]})' for s in others)} not read" if others else ""
        raise InputError(f"no mesh files ({', '.join(MESH_SUFFIXES)}) in CAD directory or its subfolders{unread}",
                         path=cad_dir)
    seen: dict[str, Path] = {}
    for f in files:  # a car is its file's name: two alike (car_a/model.obj, car_b/model.obj) would be one
        if f.stem in seen:
            raise InputError(f"two meshes named {f.stem!r}: {seen[f.stem].relative_to(cad_dir)} and "
                             f"{f.relative_to(cad_dir)} (a car is named by its file: rename one)", path=cad_dir)
        seen[f.stem] = f
    return files


@contextmanager
def naming_the_file(path):
    """Re-raise an :class:`InputError` of the block that names no file as one naming
    ``path`` (the mesh a canonicalisation or landmarking failed on)."""
    try:
        yield
    except InputError as exc:
        if exc.path is not None:
            raise
        raise InputError(exc.problem, path=path) from None


def read_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh in its file's own frame.

    ``.acc``/``.ac`` go through :func:`wirescene.cad.ac3d.read_ac3d`; OBJ, PLY, OFF and
    STL through trimesh (scenes are concatenated).

    Returns
    -------
    vertices : (N, 3) float array
    faces : (F, 3) int array
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".acc", ".ac"):
        from wirescene.cad.ac3d import read_ac3d

        m = read_ac3d(path)
        vertices, faces = m.vertices, m.faces
    else:
        vertices, faces = _read_with_trimesh(path, suffix)
    if not np.isfinite(vertices).all():
        raise InputError("mesh has vertex coordinates that are not finite numbers", path=path)
    return vertices, faces


def _read_with_trimesh(path: Path, suffix: str) -> tuple[np.ndarray, np.ndarray]:
    if suffix not in MESH_SUFFIXES:
        raise InputError(f"unsupported mesh format {suffix!r} (use one of {', '.join(MESH_SUFFIXES)})", path=path)
    # an OBJ checked before trimesh, which reads a face of vertex 0 as the last vertex without a word
    problem = path_problem(path, "mesh") or (_obj_problem(path) if suffix == ".obj" else None)
    if problem:
        raise InputError(problem, path=path)
    import trimesh

    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except MemoryError:
        raise
    except Exception as e:  # trimesh raises many types for malformed files
        if suffix == ".obj" and isinstance(e, IndexError):
            raise InputError("a face refers to a vertex the file does not have", path=path) from None
        raise InputError(f"cannot read mesh ({type(e).__name__}: {e})".splitlines()[0], path=path) from None
    if len(loaded.faces) == 0:
        raise InputError("mesh has no faces", path=path)
    vertices, faces = np.asarray(loaded.vertices, dtype=float), np.asarray(loaded.faces, dtype=np.int64)
    if faces.min() < 0 or faces.max() >= len(vertices):  # trimesh loads a PLY's faces past its vertices as they are
        bad = faces.max() if faces.max() >= len(vertices) else faces.min()
        raise InputError(f"a face refers to vertex {bad}, the file has {len(vertices)} vertices (0 to "
                         f"{len(vertices) - 1})", path=path)
    return vertices, faces


def _obj_problem(path: Path) -> str | None:
    """What trimesh would refuse, or read as another mesh, in the OBJ file ``path``, in plain
    words with its line (as :mod:`wirescene.cad.ac3d` says its errors), or None where no such
    line is found: a vertex coordinate that is no number, or a face's vertex reference that is
    no integer or names a vertex the file does not have (1 to N, or -1 to -N counting back from
    the last; 0, which OBJ's counting from 1 does not have, trimesh reads as the last vertex).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "car.obj").write_text("v 0 0 0\\nv 1 0 0\\nf 1 2 3 # a triangle\\n")
    ...     _obj_problem(Path(d) / "car.obj")
    'OBJ line 3: vertex reference 3 out of range (the file has 2 vertices)'
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "car.obj").write_text("v 0 0 0\\nv 1 0 0\\nv 0 1 0\\nf 0 1 2\\nf -1 -2 -3\\n")
    ...     _obj_problem(Path(d) / "car.obj")
    'OBJ line 4: vertex reference 0 (OBJ counts vertices from 1, or back from -1)'
    """
    try:
        # lines end at \n, \r\n or \r: str.splitlines would also break at the latin-1 reading of UTF-8 bytes (0x85)
        physical = re.split(r"\r\n?|\n", path.read_text(encoding="latin-1"))
    except OSError:
        return None
    lines, start, parts = [], 1, []  # (number of its first line, tokens): a line ending in \ goes on (as trimesh reads)
    for i, line in enumerate(physical, 1):
        parts.append(line[:-1] if line.endswith("\\") else line)
        if not line.endswith("\\") or i == len(physical):
            lines.append((start, "".join(parts).partition("#")[0].split()))
            start, parts = i + 1, []
    n = sum(tokens[:1] == ["v"] for _, tokens in lines)
    for i, tokens in lines:
        if tokens[:1] == ["v"]:
            for t in tokens[1:4]:
                try:
                    float(t)
                except ValueError:
                    return f"OBJ line {i}: non-numeric vertex coordinate {t!r}"
        elif tokens[:1] == ["f"]:
            for t in tokens[1:]:
                ref = t.split("/")[0]
                try:
                    k = int(ref)
                except ValueError:
                    return f"OBJ line {i}: non-integer vertex reference {ref!r}"
                if k == 0:
                    return f"OBJ line {i}: vertex reference 0 (OBJ counts vertices from 1, or back from -1)"
                if not (1 <= k <= n or -n <= k <= -1):
                    return f"OBJ line {i}: vertex reference {k} out of range (the file has {n} vertices)"
    return None


def _mirror_error(points: np.ndarray, axis: int) -> float:
    """Median distance of the points mirrored about the mid-plane of ``axis`` to the
    nearest original point."""
    centre = 0.5 * (points[:, axis].min() + points[:, axis].max())
    mirrored = points.copy()
    mirrored[:, axis] = 2 * centre - mirrored[:, axis]
    d, _ = cKDTree(points).query(mirrored)
    return float(np.median(d))


def _upper_profile(x: np.ndarray, h: np.ndarray, bins: int = 60) -> np.ndarray:
    """Highest ``h`` per bin of ``x`` (NaN for empty bins)."""
    edges = np.linspace(x.min(), x.max(), bins + 1)
    which = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    top = np.full(bins, np.nan)
    np.fmax.at(top, which, h)
    return top


def canonicalize(vertices, faces, *, units: str = "auto", up: int | None = None):
    """Transform a car mesh into the object frame (see module docstring for the rules).

    Parameters
    ----------
    vertices : (N, 3) array
    faces : (F, 3) int array
    units : {"auto", "m", "cm", "mm", "inch"}
    up : int or None
        Index of the file's up axis; ``None`` detects it.

    Returns
    -------
    vertices : (N, 3) float array
        Object-frame vertices.
    faces : (F, 3) int array
        Unchanged (the transform is a proper rotation).
    info : dict
        ``scale``, ``rotation`` (3x3, file -> object, before scaling and translation),
        ``front_margin`` (m; how much lower the front end is than the tail),
        ``symmetry_error`` (median mirrored nearest-neighbour distance, m).
    """
    v = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    ext = v.max(axis=0) - v.min(axis=0)
    if units == "auto":
        longest = ext.max()
        fits = [u for u, f in _UNIT_FACTORS.items() if 2.5 <= longest * f <= 7.0]
        if not fits:
            raise InputError(f"cannot infer units: longest side {longest:g} is no car length in m/cm/mm/inch")
        scale = _UNIT_FACTORS[fits[0]]
    elif units in _UNIT_FACTORS:
        scale = _UNIT_FACTORS[units]
    else:
        raise ValueError(f"units must be 'auto' or one of {sorted(_UNIT_FACTORS)}, got {units!r}")
    v = v * scale

    if up is None:
        up = int(np.argmin(ext))
    horizontal = [a for a in range(3) if a != up]
    sym = {a: _mirror_error(v, a) / (np.ptp(v[:, a]) or 1.0) for a in horizontal}
    lateral = min(horizontal, key=sym.get)
    length = next(a for a in horizontal if a != lateral)

    # Up sign: the top fifth is narrower than the bottom fifth.
    h = v[:, up]
    lat = np.abs(v[:, lateral] - 0.5 * (v[:, lateral].min() + v[:, lateral].max()))
    lo, hi = np.quantile(h, [0.0, 1.0])
    top_w = lat[h >= hi - 0.2 * (hi - lo)].mean()
    bot_w = lat[h <= lo + 0.2 * (hi - lo)].mean()
    up_sign = 1.0 if top_w <= bot_w else -1.0
    height = up_sign * h

    # Front sign: the lower end of the upper silhouette is the front.
    prof = _upper_profile(v[:, length], height)
    n_end = max(1, int(round(0.15 * len(prof))))
    high_end_mean = np.nanmean(prof[-n_end:])
    low_end_mean = np.nanmean(prof[:n_end])
    if abs(high_end_mean - low_end_mean) >= MIN_FRONT_MARGIN:
        fwd_sign = 1.0 if high_end_mean < low_end_mean else -1.0
    else:
        fwd_sign = 1.0

    ex = np.zeros(3)
    ex[length] = fwd_sign
    ey = np.zeros(3)
    ey[up] = -up_sign  # object y points down
    ez = np.cross(ex, ey)
    R = np.stack([ex, ey, ez])  # rows: object axes in file coordinates
    out = v @ R.T
    lo_b, hi_b = out.min(axis=0), out.max(axis=0)
    offset = np.array([0.5 * (lo_b[0] + hi_b[0]), hi_b[1], 0.5 * (lo_b[2] + hi_b[2])])
    out = out - offset
    info = {
        "scale": scale,
        "rotation": R.tolist(),
        "front_margin": float(abs(high_end_mean - low_end_mean)),
        "symmetry_error": _mirror_error(out, 2),
    }
    return out, faces, info


def load_car(path, *, units: str = "auto", up: int | None = None) -> CarMesh:
    """Read a mesh file and canonicalise it; see :func:`canonicalize`."""
    path = Path(path)
    v, f = read_mesh(path)
    with naming_the_file(path):
        v, f, info = canonicalize(v, f, units=units, up=up)
    return CarMesh(path.stem, v, f, str(path), info)


def road_car_check(car: CarMesh, *, view=None) -> tuple[bool, str]:
    """Apply the road-car rule of the module docstring.

    Parameters
    ----------
    car : CarMesh
    view : SideView, optional
        Precomputed :func:`wirescene.cad.sideview.side_view` of ``car``.

    Returns
    -------
    is_road : bool
    reason : str
        One line with the measured quantities and, if rejected, the failed criterion.
    """
    from wirescene.cad.sideview import approach_clearance, side_view

    l, w, h = car.dimensions
    sv = view if view is not None else side_view(car.vertices, car.faces)
    clearance = approach_clearance(sv)
    facts = f"l={l:.2f} w={w:.2f} h={h:.2f} approach clearance={clearance:.2f} m"
    if h < MIN_ROAD_HEIGHT:
        return False, f"{facts}: lower than {MIN_ROAD_HEIGHT} m (no closed cabin)"
    if w < MIN_ROAD_WIDTH:
        return False, f"{facts}: body narrower than {MIN_ROAD_WIDTH} m (open wheels)"
    if not clearance < MAX_ROAD_CLEARANCE:
        return False, f"{facts}: approach clearance not below {MAX_ROAD_CLEARANCE} m (off-road body, or no front arch)"
    return True, f"{facts}: road car"


def body_extent(vertices, faces, *, quantile: float = 0.0005) -> tuple[np.ndarray, np.ndarray]:
    """Robust axis-aligned extent ``(lo, hi)`` ``(3,)`` of a mesh's surface.

    The bounds are area-weighted quantiles of the face centroids, so thin parts with
    almost no surface -- antennas, mirrors' stalks, wing struts -- do not count: a
    KITTI box is drawn around the body, and an image box spans what is visible.
    """
    v = np.asarray(vertices, dtype=float)
    tri = v[np.asarray(faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    centre = tri.mean(axis=1)
    lo, hi = np.empty(3), np.empty(3)
    for k in range(3):
        order = np.argsort(centre[:, k])
        cdf = np.cumsum(area[order]) / area.sum()
        lo[k] = centre[order[np.searchsorted(cdf, quantile)], k]
        hi[k] = centre[order[min(np.searchsorted(cdf, 1.0 - quantile), len(order) - 1)], k]
    return lo, hi
