"""Non-photorealistic CPU rendering of triangle meshes (paper Sec. 3.2 and 5.1).

Part detectors are trained on line drawings of CAD models in the style of Stark et al.
(BMVC 2010): silhouette and crease edges only, no texture or shading. Rendering casts
one ray per pixel through the pixel centre (Embree via trimesh, see
:mod:`wirescene.core.raycast`), which yields depth, face and object ids and face normals;
edges are then found between 4-neighbouring pixels:

* silhouette -- the two pixels see different objects (or one sees background);
* occluding contour -- same object, but the depth of one pixel differs from the depth
  its neighbour's face plane predicts along its ray by more than ``depth_jump``
  (relative), i.e. the surface is not continuous between them;
* crease -- same object, the visible face normals differ by more than
  ``crease_angle_deg``.

The edge is drawn on the nearer pixel of the pair, so lines are one pixel wide and lie
on the occluding surface. No OpenGL or display is needed.

Pixel convention: integer coordinates ``(u, v) = (column, row)`` are pixel centres, as
in :meth:`wirescene.core.camera.Camera.project`.

Also here: viewing-sphere cameras for training-data generation (:func:`view_camera`,
:func:`iter_views`, the paper's 72 azimuths x 2 elevations) and Lambertian shading for
synthetic scenes (:func:`shade`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Sequence

import numpy as np

from wirescene.core.camera import Camera
from wirescene.core.errors import ShapeError, check_shape
from wirescene.core.groundplane import rotation_x, rotation_y
from wirescene.core.raycast import first_hit_distance

DEFAULT_CREASE_ANGLE_DEG = 35.0
DEFAULT_DEPTH_JUMP = 0.01


@dataclass(frozen=True)
class SceneRendering:
    """Per-pixel buffers of a rendered scene of several meshes, shape (H, W).

    Attributes
    ----------
    depth : float array
        Depth (third homogeneous coordinate of ``P @ X``, i.e. z from the optical
        centre) of the visible surface; ``inf`` on background.
    object_id : int array
        Index of the mesh seen at each pixel, -1 on background.
    face_id : int array
        Index of the face seen, within its own mesh's face list; -1 on background.
    edges : bool array
        Silhouette, occluding-contour and crease edges (see module docstring).
    normals : (H, W, 3) float array
        Unit face normals, camera frame, flipped to face the camera; 0 on background.
    """

    depth: np.ndarray
    object_id: np.ndarray
    face_id: np.ndarray
    edges: np.ndarray
    normals: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: some object is seen."""
        return self.object_id >= 0


@dataclass(frozen=True)
class Rendering:
    """Per-pixel buffers of one rendered object, shape (H, W); see :class:`SceneRendering`."""

    depth: np.ndarray
    face_id: np.ndarray
    edges: np.ndarray
    mask: np.ndarray
    normals: np.ndarray

    @property
    def object_id(self) -> np.ndarray:
        """(H, W) int: 0 on the object, -1 on background (for :func:`shade`)."""
        return np.where(self.mask, 0, -1)


def _image_size(camera: Camera, image_size) -> tuple[int, int]:
    size = image_size if image_size is not None else camera.image_size
    if size is None:
        raise ShapeError("image_size must be given when the camera has none")
    w, h = (int(s) for s in size)
    if w <= 0 or h <= 0:
        raise ShapeError(f"image_size must be positive, got {size}")
    return w, h


def render_scene(
    meshes: Sequence[tuple[np.ndarray, np.ndarray]],
    camera: Camera,
    *,
    image_size: tuple[int, int] | None = None,
    crease_angle_deg: float = DEFAULT_CREASE_ANGLE_DEG,
    depth_jump: float = DEFAULT_DEPTH_JUMP,
) -> SceneRendering:
    """Render several triangle meshes, given in the camera frame, into one image.

    Parameters
    ----------
    meshes : sequence of (vertices (V, 3), faces (F, 3) int)
        The meshes, camera frame (metres).
    camera : Camera
    image_size : (width, height), optional
        Defaults to ``camera.image_size``.
    crease_angle_deg : float, optional
        Normal change above which two visible adjacent faces form a crease edge.
    depth_jump : float, optional
        Relative depth discontinuity (w.r.t. the neighbour's face plane) above which an
        occluding contour is drawn.

    Returns
    -------
    SceneRendering

    Examples
    --------
    >>> cube = np.array([[x, y, z] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])  # a 2 m cube
    >>> faces = np.array([[0, 1, 3], [0, 3, 2], [4, 7, 5], [4, 6, 7], [0, 4, 5], [0, 5, 1],
    ...                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    >>> camera = Camera([[100.0, 0, 32, 0], [0, 100.0, 24, 0], [0, 0, 1, 0]], image_size=(64, 48))
    >>> # one cube 9 to 11 m ahead, a second one behind it and to the right
    >>> scene = render_scene([(cube + [0.0, 0.0, 10.0], faces), (cube + [1.5, 0.0, 15.0], faces)], camera)
    >>> scene.object_id.shape, np.unique(scene.object_id).tolist()  # -1: background
    ((48, 64), [-1, 0, 1])
    >>> int(scene.object_id[24, 32]), float(scene.depth[24, 32])  # the near cube's front face hides the far one
    (0, 9.0)
    >>> int(scene.object_id[24, 45]), float(scene.depth[24, 45])  # the far cube shows beside it
    (1, 14.0)
    """
    w, h = _image_size(camera, image_size)
    all_v, all_f, obj_of_face, local_face = [], [], [], []
    offset = 0
    for i, (v, f) in enumerate(meshes):
        v = np.asarray(v, dtype=float)
        f = np.asarray(f)
        check_shape(f"meshes[{i}] vertices", v, (None, 3))
        check_shape(f"meshes[{i}] faces", f, (None, 3))
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ShapeError(f"meshes[{i}] faces index vertices outside [0, {len(v)})")
        all_v.append(v)
        all_f.append(f.astype(np.int64) + offset)
        obj_of_face.append(np.full(len(f), i, dtype=np.int64))
        local_face.append(np.arange(len(f), dtype=np.int64))
        offset += len(v)
    vertices = np.concatenate(all_v) if all_v else np.zeros((0, 3))
    faces = np.concatenate(all_f) if all_f else np.zeros((0, 3), dtype=np.int64)
    obj_of_face = np.concatenate(obj_of_face) if obj_of_face else np.zeros(0, dtype=np.int64)
    local_face = np.concatenate(local_face) if local_face else np.zeros(0, dtype=np.int64)

    cols, rows = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    uv = np.stack([cols.ravel(), rows.ravel()], axis=-1)
    dirs = camera.rays(uv)
    origin = camera.center
    if len(faces):
        dist, face = first_hit_distance(vertices, faces, origin, dirs)
    else:
        dist, face = np.full(len(dirs), np.inf), np.full(len(dirs), -1, dtype=np.int64)
    hit = face >= 0

    depth = np.full(len(dirs), np.inf)
    points = origin + dist[hit, None] * dirs[hit]
    depth[hit] = points @ camera.P[2, :3] + camera.P[2, 3]

    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(fn, axis=-1, keepdims=True)
    fn = np.divide(fn, norm, out=np.zeros_like(fn), where=norm > 0)
    normals = np.zeros((len(dirs), 3))
    n_hit = fn[face[hit]]
    # Face the camera: CAD meshes are rarely consistently oriented.
    flip = np.einsum("ri,ri->r", n_hit, dirs[hit]) > 0
    n_hit[flip] *= -1
    normals[hit] = n_hit

    object_id = np.full(len(dirs), -1, dtype=np.int64)
    object_id[hit] = obj_of_face[face[hit]]
    face_id = np.full(len(dirs), -1, dtype=np.int64)
    face_id[hit] = local_face[face[hit]]

    shape = (h, w)
    edges = _edges(
        dist.reshape(shape),
        face.reshape(shape),
        object_id.reshape(shape),
        normals.reshape(shape + (3,)),
        dirs.reshape(shape + (3,)),
        crease_angle_deg=crease_angle_deg,
        depth_jump=depth_jump,
    )
    return SceneRendering(
        depth=depth.reshape(shape),
        object_id=object_id.reshape(shape),
        face_id=face_id.reshape(shape),
        edges=edges,
        normals=normals.reshape(shape + (3,)),
    )


def _edges(dist, face, obj, normals, dirs, *, crease_angle_deg, depth_jump):
    """Edge pixels from 4-neighbour pairs (see module docstring)."""
    cos_crease = np.cos(np.deg2rad(crease_angle_deg))
    edges = np.zeros(dist.shape, dtype=bool)
    for axis in (0, 1):  # vertical and horizontal neighbour pairs
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        a, b = tuple(a), tuple(b)
        silhouette = obj[a] != obj[b]
        same = (~silhouette) & (obj[a] >= 0) & (face[a] != face[b])
        na, nb = normals[a], normals[b]
        crease = same & (np.einsum("...i,...i->...", na, nb) < cos_crease)
        # Distance along b's ray to a's face plane, n_a . (o + t d_b) = n_a . X_a, with
        # X_a = o + dist_a d_a: t = dist_a (n_a . d_a) / (n_a . d_b).
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            pred = dist[a] * np.einsum("...i,...i->...", na, dirs[a]) / np.einsum("...i,...i->...", na, dirs[b])
            jump = np.abs(pred - dist[b]) > depth_jump * dist[b]
        contour = same & ~crease & (jump | ~np.isfinite(pred))
        pair = silhouette | crease | contour
        a_nearer = dist[a] <= dist[b]
        edges[a] |= pair & a_nearer
        edges[b] |= pair & ~a_nearer
    return edges


def _to_camera(points, location, R):
    location = np.asarray(location, dtype=float)
    R = np.asarray(R, dtype=float)
    check_shape("location", location, (3,))
    check_shape("R", R, (3, 3))
    return np.asarray(points, dtype=float) @ R.T + location


def render(
    vertices,
    faces,
    camera: Camera,
    location,
    R,
    *,
    image_size: tuple[int, int] | None = None,
    crease_angle_deg: float = DEFAULT_CREASE_ANGLE_DEG,
    depth_jump: float = DEFAULT_DEPTH_JUMP,
) -> Rendering:
    """Render one object mesh given in its object frame at pose ``(location, R)``.

    Parameters
    ----------
    vertices : (V, 3) array
        Object-frame mesh vertices (x forward, y down, z left; metres).
    faces : (F, 3) int array
    camera : Camera
    location : (3,) array
    R : (3, 3) array
        Object-to-camera pose, ``X_cam = R @ X_obj + location``.
    image_size, crease_angle_deg, depth_jump
        See :func:`render_scene`.

    Returns
    -------
    Rendering

    Examples
    --------
    >>> cube = np.array([[x, y, z] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])  # a 2 m cube
    >>> faces = np.array([[0, 1, 3], [0, 3, 2], [4, 7, 5], [4, 6, 7], [0, 4, 5], [0, 5, 1],
    ...                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    >>> camera = Camera([[100.0, 0, 32, 0], [0, 100.0, 24, 0], [0, 0, 1, 0]], image_size=(64, 48))
    >>> rendering = render(cube, faces, camera, [0.0, 0.0, 10.0], np.eye(3))
    >>> rendering.depth.shape, float(rendering.depth[24, 32]), float(rendering.depth[0, 0])
    ((48, 64), 9.0, inf)
    >>> # the front face spans u = 32 +- 100 * 1 / 9 = 20.9 to 43.1: pixels 21 to 43 (rows alike)
    >>> int(rendering.mask.sum()), int(rendering.edges.sum())  # 23 x 23 pixels, outlined by a 1-pixel line
    (529, 88)
    >>> # a line drawing of the mean car wireframe seen from 30 deg, for part-detector training
    >>> from wirescene.core.shape import load_default
    >>> from wirescene.core.wireframe import FACES
    >>> view = view_camera(30.0, 10.0, image_size=(64, 48))
    >>> car = render(load_default().mean, FACES, view.camera, view.location, view.R)
    >>> car.edges.dtype.name, bool(car.mask[24, 32])  # the car's middle is at the image centre
    ('bool', True)
    """
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (None, 3))
    scene = render_scene(
        [(_to_camera(vertices, location, R), faces)],
        camera,
        image_size=image_size,
        crease_angle_deg=crease_angle_deg,
        depth_jump=depth_jump,
    )
    return Rendering(
        depth=scene.depth, face_id=scene.face_id, edges=scene.edges, mask=scene.mask, normals=scene.normals
    )


def project_landmarks(
    points,
    vertices,
    faces,
    camera: Camera,
    location,
    R,
    *,
    tolerance: float = 0.02,
    intersector=None,
):
    """Project object-frame landmarks (e.g. the 36 annotated wireframe vertices of a
    CAD model) and test whether the mesh hides them.

    Parameters
    ----------
    points : (K, 3) array
        Landmarks, object frame.
    vertices, faces : (V, 3) array, (F, 3) int array
        The object's mesh, object frame.
    camera : Camera
    location, R : (3,) array, (3, 3) array
        Object pose, ``X_cam = R @ X_obj + location``.
    tolerance : float, optional
        Metres. A landmark is visible if the first surface hit on the ray from the
        camera centre towards it is no nearer than ``tolerance`` before it. The slack
        absorbs annotations that lie slightly under the surface and Embree's float32
        arithmetic; it is exact ray casting, not a depth-buffer lookup, so it does not
        depend on pixel sampling.
    intersector : optional
        A :func:`wirescene.core.raycast.mesh_intersector` of the mesh *in the camera frame*,
        to reuse across calls.

    Returns
    -------
    uv : (K, 2) float array
        Pixel coordinates (identical to ``camera.project`` of the posed points).
    depth : (K,) float array
    visible : (K,) bool array
        In front of the camera and not hidden by the mesh. Truncation by the image
        border is not considered here.

    Examples
    --------
    >>> cube = np.array([[x, y, z] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])  # a 2 m cube
    >>> faces = np.array([[0, 1, 3], [0, 3, 2], [4, 7, 5], [4, 6, 7], [0, 4, 5], [0, 5, 1],
    ...                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    >>> camera = Camera([[100.0, 0, 32, 0], [0, 100.0, 24, 0], [0, 0, 1, 0]], image_size=(64, 48))
    >>> uv, depth, visible = project_landmarks(cube, cube, faces, camera, [0.0, 0.0, 10.0], np.eye(3))
    >>> np.round(uv[:2], 2).tolist(), depth.tolist()  # the cube's own corners as landmarks
    ([[20.89, 12.89], [43.11, 12.89]], [9.0, 9.0, 9.0, 9.0, 11.0, 11.0, 11.0, 11.0])
    >>> visible.tolist()  # the front face's corners are seen, the back face's hidden
    [True, True, True, True, False, False, False, False]
    """
    points = np.asarray(points, dtype=float)
    check_shape("points", points, (None, 3))
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (None, 3))
    X = _to_camera(points, location, R)
    Vc = _to_camera(vertices, location, R)
    uv, depth = camera.project_with_depth(X)
    o = camera.center
    d = X - o
    dist = np.linalg.norm(d, axis=-1)
    safe = np.where(dist > 0, dist, 1.0)
    hit, _ = first_hit_distance(Vc, faces, o, d / safe[:, None], intersector=intersector)
    visible = (depth > 0) & (hit >= dist - tolerance)
    return uv, depth, visible


@dataclass(frozen=True)
class View:
    """A camera and an object pose that show the object from one point of the viewing
    sphere. Pass ``camera, location, R`` to :func:`render` / :func:`project_landmarks`."""

    camera: Camera
    location: np.ndarray
    R: np.ndarray
    azimuth_deg: float
    elevation_deg: float


def view_camera(
    azimuth_deg: float,
    elevation_deg: float,
    *,
    distance: float = 10.0,
    image_size: tuple[int, int] = (256, 256),
    focal: float | None = None,
    field_width: float = 6.0,
    target=(0.0, -0.75, 0.0),
) -> View:
    """Camera and object pose viewing a car from ``(azimuth, elevation)``.

    The camera is KITTI-like (at the origin, looking along +z, y down). The object is
    placed so that its ``target`` point lands on the optical axis at ``distance``, and
    rotated by ``R = R_x(elevation) @ R_y(azimuth)``.

    Parameters
    ----------
    azimuth_deg : float
        The object's ``rotation_y``; as the object is on the optical axis this equals
        KITTI's observation angle ``alpha`` (the 2D viewpoint of
        :mod:`wirescene.core.viewpoints`). 0 is a side view with the car's front pointing
        to the image's right; 90 shows the front.
    elevation_deg : float
        Angle of the viewing direction above the ground (positive: seen from above).
    distance : float, optional
        Metres from the optical centre to the target.
    image_size : (width, height), optional
    focal : float, optional
        Focal length in pixels; by default chosen so that ``field_width`` metres at the
        target distance span the image width.
    field_width : float, optional
        See ``focal``. 6 m frames a typical car (about 4.5 m long) with a margin.
    target : (3,) array, optional
        Object-frame point put at the image centre: the middle of a typical car
        (object frame: y down, ground at y = 0).

    Returns
    -------
    View

    Examples
    --------
    >>> view = view_camera(90.0, 15.0, image_size=(64, 48))  # the car's front, seen from 15 deg above
    >>> view.camera.image_size, round(view.camera.focal, 2)  # 6 m at 10 m span the 64 px
    ((64, 48), 106.67)
    >>> target = view.location + view.R @ np.array([0.0, -0.75, 0.0])  # the car's middle ...
    >>> np.round(view.camera.project(target), 6).tolist(), round(float(np.linalg.norm(target)), 6)  # ... at the centre
    ([31.5, 23.5], 10.0)
    """
    w, h = (int(s) for s in image_size)
    if distance <= 0:
        raise ValueError(f"distance must be positive, got {distance}")
    f = float(focal) if focal is not None else w * distance / field_width
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    camera = Camera(np.hstack([K, np.zeros((3, 1))]), (w, h))
    R = rotation_x(np.deg2rad(elevation_deg)) @ rotation_y(np.deg2rad(azimuth_deg))
    location = np.array([0.0, 0.0, distance]) - R @ np.asarray(target, dtype=float)
    return View(camera, location, R, float(azimuth_deg), float(elevation_deg))


def iter_views(n_azimuth: int = 72, elevations: Sequence[float] = (7.5, 15.0), **kwargs) -> Iterator[View]:
    """All views of the paper's training renderings: ``n_azimuth`` equally spaced
    azimuths (5 deg steps for 72) at each elevation. Keyword arguments go to
    :func:`view_camera`.

    Examples
    --------
    >>> len(list(iter_views()))  # 72 azimuths x 2 elevations
    144
    >>> [(v.azimuth_deg, v.elevation_deg) for v in iter_views(4, (10.0,), image_size=(32, 32))]
    [(0.0, 10.0), (90.0, 10.0), (180.0, 10.0), (270.0, 10.0)]
    """
    for elevation in elevations:
        for k in range(int(n_azimuth)):
            yield view_camera(360.0 * k / n_azimuth, float(elevation), **kwargs)


def shade(
    rendering,
    *,
    light_dir=(-0.3, -1.0, -0.6),
    albedo=0.8,
    ambient=0.3,
    background=0.0,
) -> np.ndarray:
    """Lambertian + ambient shading of a rendering (face normals, flat shading).

    Parameters
    ----------
    rendering : SceneRendering or Rendering
        Uses its ``normals`` and ``object_id``.
    light_dir : (3,) array, optional
        Direction *towards* the light, camera frame (y down: the default light is
        above, slightly left and behind the camera).
    albedo : float, (3,) array or (n_objects, C) array, optional
        A grey value, an RGB colour for all objects, or one row per object id with
        C = 1 (grey) or C = 3 (RGB).
    ambient : float, optional
        Fraction of the albedo seen regardless of the light direction.
    background : float or (3,) array, optional

    Returns
    -------
    image : (H, W) or (H, W, 3) float array
        ``albedo * (ambient + (1 - ambient) * max(0, n . l))``, in [0, 1] for albedos
        in [0, 1].

    Examples
    --------
    >>> cube = np.array([[x, y, z] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])  # a 2 m cube
    >>> faces = np.array([[0, 1, 3], [0, 3, 2], [4, 7, 5], [4, 6, 7], [0, 4, 5], [0, 5, 1],
    ...                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    >>> camera = Camera([[100.0, 0, 32, 0], [0, 100.0, 24, 0], [0, 0, 1, 0]], image_size=(64, 48))
    >>> rendering = render(cube, faces, camera, [0.0, 0.0, 10.0], np.eye(3))
    >>> grey = shade(rendering, light_dir=(0, 0, -1))  # light from the camera: the front face fully lit
    >>> grey.shape, float(grey[24, 32]), float(grey[0, 0])  # the albedo 0.8; the background 0
    ((48, 64), 0.8, 0.0)
    >>> rgb = shade(rendering, albedo=(1.0, 0.2, 0.2), background=(0.0, 0.0, 1.0))
    >>> rgb.shape, rgb[0, 0].tolist()
    ((48, 64, 3), [0.0, 0.0, 1.0])
    """
    normals = np.asarray(rendering.normals, dtype=float)
    obj = np.asarray(rendering.object_id)
    l = np.asarray(light_dir, dtype=float)
    check_shape("light_dir", l, (3,))
    l = l / np.linalg.norm(l)
    intensity = ambient + (1.0 - ambient) * np.clip(normals @ l, 0.0, None)
    albedo = np.asarray(albedo, dtype=float)
    if albedo.ndim == 2:
        if albedo.shape[0] <= max(int(obj.max(initial=-1)), -1):
            raise ShapeError(f"albedo has {albedo.shape[0]} rows but object ids reach {obj.max()}")
        per_pixel = albedo[np.clip(obj, 0, None)]  # (H, W, C)
    elif albedo.ndim <= 1 and albedo.size in (1, 3):
        per_pixel = np.broadcast_to(albedo.reshape(-1), obj.shape + (albedo.size,))
    else:
        raise ShapeError(f"albedo must be a scalar, (3,) or (n_objects, C), got {albedo.shape}")
    image = per_pixel * intensity[..., None]
    background = np.broadcast_to(np.asarray(background, dtype=float).reshape(-1), (image.shape[-1],))
    image = np.where((obj >= 0)[..., None], image, background)
    return image[..., 0] if image.shape[-1] == 1 else image
