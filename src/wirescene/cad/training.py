"""Training of the metric PCA shape model from a directory of CAD car meshes.

``train_shape_model`` loads every mesh, canonicalises it (:mod:`wirescene.cad.mesh`),
keeps the road cars, landmarks them (:mod:`wirescene.cad.landmarks`, with the manual
corrections), fits the PCA (:func:`wirescene.core.shape.fit_shape_model`) and writes

- the shape model (``.npz``),
- ``cad_landmarks.json``: per car name, source file, dimensions (l, w, h of the mesh),
  road-car decision and reason, and the 36 vertices,
- ``cad_meshes.npz``: the canonical meshes of the road cars (float32 vertices, int32
  faces, concatenated with offsets) for rendering; the TORCS meshes are small (about
  50 k vertices in all), so they are stored undecimated.

Everything is deterministic given the seed (the seed only drives the size
augmentation).
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import numpy as np

from wirescene.core.artefacts import load_json, load_npz, save_json, save_npz
from wirescene.core.atomic import atomic_path
from wirescene.core.errors import InputError
from wirescene.core.resources import DATA_DIR
from wirescene.core.shape import DEFAULT_MODEL_PATH, ShapeModel, fit_shape_model
from wirescene.core.wireframe import VERTEX_NAMES

__all__ = ["train_shape_model", "load_cad_meshes", "load_cad_landmarks", "DEFAULT_AUGMENT"]

DEFAULT_AUGMENT = 100


def train_shape_model(cad_dir, out_path=DEFAULT_MODEL_PATH, *, seed: int = 0, augment: int = DEFAULT_AUGMENT,
                      n_components: int | None = None, landmarks_path=None, meshes_path=None,
                      corrections: dict | None = None, progress=None) -> ShapeModel:
    """Train and write the shape model (see the module docstring).

    Parameters
    ----------
    cad_dir : path
        Directory of mesh files (see :func:`wirescene.cad.mesh.list_cad_files`).
    out_path : path
        Shape model ``.npz`` to write.
    seed : int
        Seed of the size augmentation.
    augment : int
        Size-augmented copies per exemplar (0: fit the exemplars as they are).
    n_components : int, optional
    landmarks_path, meshes_path : path, optional
        Where to write ``cad_landmarks.json`` / ``cad_meshes.npz``; default: next to
        ``out_path``. Pass ``False`` to skip.
    corrections : dict, optional
        Landmark corrections; default: the package's corrections file.
    progress : callable(str), optional
        Called with one line per car.
    """
    from wirescene.cad.landmarks import annotate, load_corrections
    from wirescene.cad.mesh import list_cad_files, load_car, naming_the_file, road_car_check
    from wirescene.cad.sideview import side_view

    out_path = Path(out_path)
    corrections = load_corrections() if corrections is None else corrections
    records, wireframes, names, meshes = [], [], [], []
    for path in list_cad_files(cad_dir):
        car = load_car(path)
        sv = side_view(car.vertices, car.faces)
        is_road, reason = road_car_check(car, view=sv)
        record = {"name": car.name, "source": path.name, "dimensions_lwh": [round(float(d), 4) for d in car.dimensions],
                  "road_car": is_road, "reason": reason}
        if is_road:
            with naming_the_file(path):
                X = annotate(car.vertices, car.faces, name=car.name, corrections=corrections)
            record["vertices"] = {n: [round(float(c), 4) for c in X[i]] for i, n in enumerate(VERTEX_NAMES)}
            wireframes.append(X)
            names.append(car.name)
            meshes.append(car)
        records.append(record)
        if progress is not None:
            progress(f"{car.name}: {reason}")
    if len(wireframes) < 2:
        raise InputError(f"need at least 2 road cars to train a shape model, found {len(wireframes)}", path=cad_dir)
    W = np.round(np.stack(wireframes), 4)  # the JSON precision, so that both files agree
    model = fit_shape_model(W, names, n_components=n_components, augment=augment, rng=np.random.default_rng(seed))
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with ExitStack() as files:  # each file written beside its place, which all take once all are written
        staged = lambda path: files.enter_context(atomic_path(path))  # noqa: E731
        model.save(staged(out_path))
        if landmarks_path is not False:
            lp = Path(landmarks_path) if landmarks_path else out_path.parent / "cad_landmarks.json"
            save_json(staged(lp), {"frame": "object (x forward, y down, z left; metres)", "cars": records},
                      kind="cad-landmarks", version=1)
        if meshes_path is not False:
            mp = Path(meshes_path) if meshes_path else out_path.parent / "cad_meshes.npz"
            nv = np.cumsum([0] + [len(m.vertices) for m in meshes])
            nf = np.cumsum([0] + [len(m.faces) for m in meshes])
            save_npz(staged(mp), dict(
                names=np.array([m.name for m in meshes], dtype=str),
                vertex_offsets=nv.astype(np.int64), face_offsets=nf.astype(np.int64),
                vertices=np.concatenate([m.vertices for m in meshes]).astype(np.float32),
                faces=np.concatenate([m.faces for m in meshes]).astype(np.int32),
            ), kind="cad-meshes", version=1)
    return model


def load_cad_meshes(path=None) -> dict:
    """Canonical road-car meshes ``{name: (vertices (N, 3) float32, faces (F, 3) int32)}``
    written by :func:`train_shape_model` (default: the package's ``cad_meshes.npz``)."""
    path = DATA_DIR / "cad_meshes.npz" if path is None else Path(path)
    z = load_npz(path, kind="cad-meshes", version=1)
    try:
        names, nv, nf = z["names"], z["vertex_offsets"], z["face_offsets"]
        V, F = z["vertices"], z["faces"]
    except KeyError as e:
        raise InputError(f"not a CAD mesh file (missing {e})", path=path) from None
    out = {}
    for i, n in enumerate(names):
        v, f = V[nv[i]:nv[i + 1]], F[nf[i]:nf[i + 1]]
        if len(f) == 0 or f.min() < 0 or f.max() >= len(v) or not np.isfinite(v).all():
            raise InputError(f"car {str(n)!r} has no faces, faces past its {len(v)} vertices or vertices that "
                             "are not finite", path=path)
        out[str(n)] = (v, f)
    return out


def load_cad_landmarks(path=None) -> dict:
    """``cad_landmarks.json`` as ``{name: (36, 3) array}`` for the road cars."""
    path = DATA_DIR / "cad_landmarks.json" if path is None else Path(path)
    data = load_json(path, kind="cad-landmarks", version=1)
    out = {}
    for c in data.get("cars", []):
        if c.get("road_car"):
            missing = [n for n in VERTEX_NAMES if n not in c.get("vertices", {})]
            if missing:
                raise InputError(f"car {c.get('name')!r} lacks vertex {missing[0]!r} ({len(missing)} of 36 missing)",
                                 path=path)
            out[c["name"]] = np.array([c["vertices"][n] for n in VERTEX_NAMES], dtype=float)
    return out
