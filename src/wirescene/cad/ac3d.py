"""Reader for the AC3D text format (``.ac``) and its TORCS multi-texture variant (``.acc``).

The format is a tree of ``OBJECT`` blocks. Each object may carry a ``rot`` (3x3,
row-major) and a ``loc`` offset relative to its parent; vertices of an object are in
its local frame, so world coordinates are obtained by composing the transforms from
the root down: ``X_parent = rot @ X_local + loc``. The low four bits of a ``SURF``
flag give the surface type: 0 polygon, 1 closed line, 2 line (lines bound no area and
are skipped), and, as extensions written by the TORCS ``accc`` tool, 3 triangle list
and 4 triangle strip (the TORCS car files are almost entirely ``SURF 0x14`` strips).
Each ``refs`` line starts with a vertex index followed by one or more ``u v`` pairs
(the ``.acc`` files carry up to four texture layers per line, which we ignore).

Polygons are triangulated as fans. That is exact for the convex polygons of which
these models are made, and only a rendering approximation for a concave polygon.
Strips keep a consistent winding by swapping every other triangle.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wirescene.core.errors import InputError

__all__ = ["AC3DMesh", "read_ac3d", "parse_ac3d"]


@dataclass(frozen=True)
class AC3DMesh:
    """Triangle soup of an AC3D file in the file's own (world) frame.

    Attributes
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array
        Indices into ``vertices``; vertices of different objects are not merged.
    object_names : tuple of str
        Names of the objects, in file order (``""`` for unnamed ones).
    face_object : (F,) int array
        Index into ``object_names`` of the object each face belongs to.
    """

    vertices: np.ndarray
    faces: np.ndarray
    object_names: tuple
    face_object: np.ndarray


class _Lines:
    """Line cursor that remembers the line number for error messages."""

    def __init__(self, text: str, path):
        self.lines = text.splitlines()
        self.i = 0
        self.path = path

    def next(self) -> str:
        while self.i < len(self.lines):
            line = self.lines[self.i].strip()
            self.i += 1
            if line:
                return line
        raise self.error("unexpected end of file")

    def peek(self):
        j = self.i
        while j < len(self.lines):
            if self.lines[j].strip():
                return self.lines[j].strip()
            j += 1
        return None

    def error(self, problem: str) -> InputError:
        return InputError(f"AC3D line {self.i}: {problem}", path=self.path)


def _floats(cur: _Lines, tokens, n: int, what: str) -> np.ndarray:
    try:
        values = np.array([float(t) for t in tokens[:n]])
    except ValueError:
        raise cur.error(f"non-numeric {what}") from None
    if values.size != n:
        raise cur.error(f"{what} needs {n} numbers, got {values.size}")
    return values


def _read_object(cur, rot, loc, out_v, out_f, names, face_obj, n_verts):
    """Read one OBJECT block (header line already consumed) and its kids, recursively."""
    local_rot, local_loc = np.eye(3), np.zeros(3)
    verts = np.zeros((0, 3))
    polys = []
    name = ""
    kids = None
    while kids is None:
        line = cur.next()
        tokens = line.split()
        key = tokens[0]
        if key == "name":
            name = line[len("name"):].strip().strip('"')
        elif key == "data":
            # 'data <nchars>' is followed by that many characters of free text.
            n = int(tokens[1])
            consumed = 0
            while consumed < n:
                consumed += len(cur.next()) + 1
        elif key == "rot":
            local_rot = _floats(cur, tokens[1:], 9, "rot").reshape(3, 3)
        elif key == "loc":
            local_loc = _floats(cur, tokens[1:], 3, "loc")
        elif key == "numvert":
            n = int(tokens[1])
            verts = np.empty((n, 3))
            for k in range(n):
                verts[k] = _floats(cur, cur.next().split(), 3, "vertex")
        elif key == "numsurf":
            for _ in range(int(tokens[1])):
                polys.extend(_read_surface(cur, n_verts_local=len(verts)))
        elif key == "kids":
            kids = int(tokens[1])
        elif key in {"texture", "texrep", "texoff", "crease", "url", "subdiv", "hidden",
                     "locked", "folded"}:
            pass
        else:
            raise cur.error(f"unknown object token {key!r}")

    # Compose with the parent transform: world = rot (local_rot v + local_loc) + loc.
    world_rot = rot @ local_rot
    world_loc = rot @ local_loc + loc
    obj_index = len(names)
    names.append(name)
    if len(verts):
        out_v.append(verts @ world_rot.T + world_loc)
        for tri in polys:
            out_f.append((tri[0] + n_verts[0], tri[1] + n_verts[0], tri[2] + n_verts[0]))
            face_obj.append(obj_index)
        n_verts[0] += len(verts)
    for _ in range(kids):
        if cur.peek() is None:  # Speed Dreams' cars declare more kids than they hold: stop at the end, as its loader
            break
        header = cur.next().split()
        if header[0] != "OBJECT":
            raise cur.error(f"expected OBJECT for a kid, got {header[0]!r}")
        _read_object(cur, world_rot, world_loc, out_v, out_f, names, face_obj, n_verts)


def _read_surface(cur, *, n_verts_local):
    tokens = cur.next().split()
    if tokens[0] != "SURF":
        raise cur.error(f"expected SURF, got {tokens[0]!r}")
    surf_type = int(tokens[1], 16) & 0xF
    refs = None
    while refs is None:
        tokens = cur.next().split()
        if tokens[0] == "mat":
            continue
        if tokens[0] != "refs":
            raise cur.error(f"expected mat or refs, got {tokens[0]!r}")
        refs = int(tokens[1])
    idx = []
    for _ in range(refs):
        try:
            i = int(cur.next().split()[0])
        except ValueError:
            raise cur.error("non-integer vertex reference") from None
        if not 0 <= i < n_verts_local:
            raise cur.error(f"vertex reference {i} out of range (object has {n_verts_local})")
        idx.append(i)
    # Degenerate (repeated-index) triangles are dropped by the caller.
    if len(idx) < 3:
        return []
    if surf_type == 0:  # polygon: fan
        return [(idx[0], a, b) for a, b in zip(idx[1:-1], idx[2:])]
    if surf_type == 3:  # triangle list
        return [tuple(idx[k:k + 3]) for k in range(0, len(idx) - 2, 3)]
    if surf_type == 4:  # triangle strip: every other triangle is swapped to keep winding
        return [(idx[k], idx[k + 1], idx[k + 2]) if k % 2 == 0 else (idx[k + 1], idx[k], idx[k + 2])
                for k in range(len(idx) - 2)]
    return []  # closed line / line: bound no area


def parse_ac3d(text: str, *, path=None) -> AC3DMesh:
    """Parse AC3D text; see :func:`read_ac3d`."""
    cur = _Lines(text, path)
    first = cur.next()
    if not first.startswith("AC3D"):
        raise InputError("not an AC3D file (missing 'AC3D' header)", path=path)
    out_v, out_f, names, face_obj = [], [], [], []
    n_verts = [0]
    while cur.peek() is not None:
        tokens = cur.next().split()
        if tokens[0] == "MATERIAL":
            continue
        if tokens[0] != "OBJECT":
            raise cur.error(f"expected MATERIAL or OBJECT, got {tokens[0]!r}")
        _read_object(cur, np.eye(3), np.zeros(3), out_v, out_f, names, face_obj, n_verts)
    vertices = np.concatenate(out_v) if out_v else np.zeros((0, 3))
    faces = np.asarray(out_f, dtype=np.int64).reshape(-1, 3)
    face_object = np.asarray(face_obj, dtype=np.int64)
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    if not keep.all():
        faces, face_object = faces[keep], face_object[keep]
    if len(faces) == 0:
        raise InputError("AC3D file contains no polygons", path=path)
    return AC3DMesh(vertices, faces, tuple(names), face_object)


def read_ac3d(path) -> AC3DMesh:
    """Read an AC3D ``.ac``/``.acc`` file into a triangle mesh.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    AC3DMesh
        Vertices in the file's frame with all ``rot``/``loc`` transforms of the object
        hierarchy applied, and fan-triangulated polygon faces.

    Raises
    ------
    InputError
        If the file is missing or malformed.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="latin-1")
    except OSError as e:
        raise InputError(f"cannot read AC3D file ({e.strerror})", path=path) from None
    return parse_ac3d(text, path=path)
