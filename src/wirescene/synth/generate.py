"""Rendering of synthetic street scenes with full ground truth, written in KITTI layout.

One scene (:func:`generate_scene`) is drawn from ``numpy.random.default_rng([seed,
index])``, so every frame is reproducible on its own and the output bytes depend only
on (seed, index, options).

Image formation
---------------
* Cars (CAD meshes of :func:`wirescene.cad.training.load_cad_meshes`) and occluders
  (poles, boxes, bushes as simple meshes) are ray cast with
  :func:`wirescene.render.render_scene` over the image window that contains them
  (a cropped camera; the rest of the image sees no object), giving depth, object id,
  face normals and the edge map.
* Background by analytic ray casting: the ground plane (road with lane markings,
  parking lanes, kerbs, sidewalks; value-noise texture; soft contact shadows under the
  cars), building facades (vertical planes with window grids) and a sky gradient,
  with distance haze.
* Objects: Lambertian + ambient shading of the face normals with per-car colours
  (glass for steep surfaces above 62% of the car's height, dark trim/tyres below
  0.28 m, decided per pixel); Gaussian sensor noise.

Ground truth
------------
* ``label_2``: type ``Car``; ``truncated`` = fraction of the car's full silhouette
  (rendered alone, outside the image sampled on a grid) that lies outside the image;
  ``occluded`` from the fraction ``f`` of its in-image silhouette pixels hidden by other
  objects (cars or occluders): 0 if ``f < 0.10``, 1 if ``f < 0.40``, else 2; 2D box in
  KITTI's convention: the projection of the label's 3D box (``dims``, ``location``,
  ``rotation_y``) clipped to the image -- not the extent of the visible pixels, which
  the JSON keeps as ``visible_box`` -- so that a detection-box term of the fine stage
  means the same on synthetic and real data;
  ``dims`` = the mesh's bounding box ``h w l``; ``location`` = its bottom centre;
  ``rotation_y`` and ``alpha`` of the object rotation (on a tilted plane the car is
  tilted by the plane's pitch/roll, which the KITTI box cannot express). Cars of which
  no pixel is visible are left out of the labels (listed as ``hidden_cars`` in the JSON).
* ``wireframes/FRAME.json``: ground plane, street, occluders and per labelled car (same
  order as the label file) its CAD name, the 36 annotated vertices in the camera frame,
  their projections, per-vertex visibility with a reason (``visible``, ``truncated``
  -- projected outside the image --, ``self``, ``other-car``, ``occluder``; tested in
  this order, the blocker being the first surface hit), the count of vertices occluded
  by other objects (``other-car`` + ``occluder``) and the shape coefficients.
  Visibility is exact ray casting from the camera centre to the vertex pushed
  ``VERTEX_PUSH`` metres away from the car's centre, a surface hit more than
  ``VERTEX_TOL`` before it blocks. The push makes a landmark at the car's outline agree
  with the wireframe hull's self-occlusion, which the real frames' labels and the fit
  use, more often than the exact ray to it does (``benchmarks/bench_landmark_visibility.py``).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np
from PIL import Image

from wirescene.cad.mesh import body_extent
from wirescene.core.atomic import atomic_path, write_bytes
from wirescene.core.boxes import box_corners, project_points_to_box
from wirescene.core.camera import Camera, read_kitti_calib, write_kitti_calib
from wirescene.core.errors import InputError
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, alpha_from_rotation_y, rotation_y, rotation_y_of
from wirescene.core.raycast import first_hit_distance, mesh_intersector
from wirescene.core.wireframe import VERTEX_NAMES
from wirescene.io.kitti import FrameLabels, Label, write_labels
from wirescene.io.wireframes import wireframe_gt_path
from wirescene.render import render_scene
from wirescene.synth.layout import Occluder, SceneLayout, place, sample_layout

IMAGE_SIZE = (1242, 375)
OCCLUSION_THRESHOLDS = (0.10, 0.40)  # hidden silhouette fraction -> KITTI occluded 0 / 1 / 2
VERTEX_PUSH = 0.03
VERTEX_TOL = 0.02
MAX_TRUNCATION_RAYS = 60_000

CAR_COLOURS = np.array([
    [0.85, 0.86, 0.87], [0.62, 0.64, 0.66], [0.12, 0.12, 0.13], [0.55, 0.08, 0.07],
    [0.10, 0.20, 0.45], [0.35, 0.36, 0.38], [0.80, 0.78, 0.70], [0.12, 0.28, 0.16],
    [0.70, 0.45, 0.10], [0.30, 0.35, 0.55],
])
OCCLUDER_COLOURS = {"pole": (0.45, 0.46, 0.47), "box": (0.30, 0.42, 0.30), "bush": (0.18, 0.36, 0.12)}
LIGHT = np.array([-0.35, -1.0, -0.45]) / np.linalg.norm([-0.35, -1.0, -0.45])


# --------------------------------------------------------------------------- resources


def default_calib_path() -> Path:
    return Path(str(resources.files("wirescene") / "data" / "sample" / "kitti" / "training" / "calib" / "000010.txt"))


def default_camera() -> Camera:
    """KITTI ``P2`` of frame 000010, image 1242 x 375."""
    return read_kitti_calib(default_calib_path()).camera(IMAGE_SIZE)


@dataclass(frozen=True)
class CarModel:
    name: str
    vertices: np.ndarray  # (N, 3) object frame
    faces: np.ndarray  # (F, 3)
    landmarks: np.ndarray  # (36, 3) object frame
    dims: tuple  # (h, w, l)


def resized(model: CarModel, dims_hwl) -> CarModel:
    """``model`` scaled per axis to the box size ``dims_hwl`` (h, w, l) about its bottom
    centre (the object-frame origin), landmarks included."""
    h, w, l = dims_hwl
    factor = np.array([l / model.dims[2], h / model.dims[0], w / model.dims[1]])
    return CarModel(model.name, model.vertices * factor, model.faces, model.landmarks * factor, tuple(map(float, dims_hwl)))


@lru_cache(maxsize=2)
def load_car_library(meshes_path=None, landmarks_path=None) -> dict:
    """``{name: CarModel}`` of the road cars with both a mesh and 36 landmarks."""
    from wirescene.cad.training import load_cad_landmarks, load_cad_meshes

    meshes = load_cad_meshes(meshes_path)
    marks = load_cad_landmarks(landmarks_path)
    out = {}
    for name in sorted(set(meshes) & set(marks)):
        v, f = meshes[name]
        v = np.asarray(v, dtype=float)
        f = np.asarray(f, dtype=np.int64)
        # Label boxes enclose the body, not antennas: centre the model on its robust
        # extent (ground stays at y = 0) and take that as its size.
        lo, hi = body_extent(v, f)
        f = f[v[f][:, :, 1].min(axis=1) >= lo[1] - 0.02]  # drop antennas reaching above the roof (y is down)
        shift = np.array([(lo[0] + hi[0]) / 2, 0.0, (lo[2] + hi[2]) / 2])
        h, w, l = -lo[1], hi[2] - lo[2], hi[0] - lo[0]
        out[name] = CarModel(name, v - shift, f, np.asarray(marks[name], float) - shift, (float(h), float(w), float(l)))
    if not out:
        raise InputError("no CAD car has both a mesh and landmarks (run `wirescene train shape`)")
    return out


@lru_cache(maxsize=1)
def _shape_model():
    from wirescene.core.shape import load_default

    try:
        return load_default()
    except InputError:
        return None


@lru_cache(maxsize=4)
def _pixel_rays(P_bytes: bytes, w: int, h: int):
    cam = Camera(np.frombuffer(P_bytes).reshape(3, 4), (w, h))
    cols, rows = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    d = np.stack([cols, rows, np.ones_like(cols)], -1) @ np.linalg.inv(cam.K).T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d  # (h, w, 3) unit


# --------------------------------------------------------------------------- meshes


def occluder_mesh(occ: Occluder, rng: np.random.Generator):
    """Object-frame mesh (y down, ground at y = 0) of an occluder, rotated by its yaw."""
    import trimesh

    if occ.kind == "pole":
        r, hgt = occ.size
        m = trimesh.creation.cylinder(radius=r, height=hgt, sections=12)
        v = m.vertices[:, [0, 2, 1]] * [1, -1, 1] - [0, hgt / 2, 0]
        f = m.faces
    elif occ.kind == "box":
        l, w, hgt = occ.size
        m = trimesh.creation.box(extents=(l, hgt, w))
        v = m.vertices - [0, hgt / 2, 0]
        f = m.faces
    else:
        r, hgt = occ.size
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        v = m.vertices * (1.0 + 0.18 * rng.standard_normal((len(m.vertices), 1)))
        v = v * [r, hgt / 2, r] - [0, hgt / 2 - 0.05, 0]
        v[:, 1] = np.minimum(v[:, 1], 0.0)
        f = m.faces
    c, s = np.cos(occ.yaw), np.sin(occ.yaw)
    Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.asarray(v, float) @ Ry.T, np.asarray(f, np.int64)


def _to_cam(v, loc, R):
    return v @ R.T + loc


# --------------------------------------------------------------------------- background


def _value_noise(rng, n=257):
    return rng.standard_normal((n, n))


def _sample_noise(grid, a, b):
    """Bilinear lookup of a periodic noise grid at real coordinates ``a, b`` (cells)."""
    n = grid.shape[0] - 1
    a0, b0 = np.floor(a), np.floor(b)
    fa, fb = a - a0, b - b0
    i, j = a0.astype(np.int64) % n, b0.astype(np.int64) % n
    g = grid
    return ((1 - fa) * (1 - fb) * g[i, j] + fa * (1 - fb) * g[i + 1, j]
            + (1 - fa) * fb * g[i, j + 1] + fa * fb * g[i + 1, j + 1])


def _facade(img, dist, xf: float, c, d, tg, g_ok, hgt: float, noise2, rng) -> None:
    """Paint the building facade in the vertical plane ``x = xf`` (street frame) into the
    flat ``img`` and ``dist``, where its rays ``d`` from ``c`` meet it before the ground:
    blocks along z of random length, height and colour, with a window grid."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (xf - c[0]) / d[:, 0]
    idx = np.flatnonzero(np.isfinite(t) & (t > 0) & ~(g_ok & (tg < t)))
    block_len = rng.uniform(8, 20, size=64)
    edges_z = np.cumsum(block_len) - rng.uniform(0, 10)
    heights = rng.uniform(6, 18, size=64)
    colours = rng.uniform(0.35, 0.75, size=(64, 1)) * np.array([1.0, 0.93, 0.82]) + rng.uniform(-0.05, 0.05, (64, 3))
    P = c + t[idx, None] * d[idx]
    blk = np.clip(np.searchsorted(edges_z, P[:, 2]), 0, 63)
    up = hgt - P[:, 1]  # height above ground
    keep = (up >= 0) & (up <= heights[blk]) & (P[:, 2] > -5)
    idx, P, blk, up = idx[keep], P[keep], blk[keep], up[keep]
    col = colours[blk]
    # window grid: 1.4 m wide windows every 3 m, 1.5 m high every 3.2 m, from 1 m up
    win = ((P[:, 2] % 3.0) < 1.4) & ((up - 1.0) % 3.2 < 1.5) & (up > 1.0) & (up < heights[blk] - 0.8)
    col[win] = col[win] * 0.35 + [0.05, 0.07, 0.1]
    col *= (1 + 0.06 * _sample_noise(noise2, P[:, 2] * 3, up * 3))[:, None]
    img[idx] = col
    dist[idx] = t[idx]


def _ground_colour(layout: SceneLayout, x, z, noise, noise2) -> np.ndarray:
    """Colour ``(n, 3)`` of ground points at street-frame ``x, z``: textured asphalt,
    parking bays, kerbs, paved sidewalks, lane markings and the cars' contact shadows."""
    st = layout.street
    n_fine = _sample_noise(noise, x * 8.0, z * 8.0)
    n_coarse = _sample_noise(noise2, x * 0.7 + 50, z * 0.7)
    ground = np.array([0.33, 0.33, 0.34]) * (1 + 0.07 * n_fine + 0.08 * n_coarse)[:, None]
    asphalt = ground.copy()
    for lim, sign, park in ((st.road_left, -1, st.parking_left), (st.road_right, 1, st.parking_right)):
        beyond = sign * (x - lim)
        if park == "perpendicular":
            bay = (beyond > 0) & (beyond < 5.5)
            ground[bay] = asphalt[bay] * 1.08
            ground[bay & ((z % 2.6) < 0.12)] = [0.8, 0.8, 0.78]
            beyond = beyond - 5.5
        walk = beyond >= 0.2
        pave = np.array([0.58, 0.55, 0.52]) * (1 + 0.05 * n_fine[walk] + 0.05 * n_coarse[walk])[:, None]
        joints = ((x[walk] % 0.6) < 0.03) | ((z[walk] % 0.6) < 0.03)
        pave[joints] *= 0.8
        ground[walk] = pave
        kerb = (beyond > 0) & (beyond < 0.2)
        ground[kerb] = np.array([0.68, 0.67, 0.65]) * (1 + 0.04 * n_fine[kerb])[:, None]
    for xm, kind in st.markings:
        on = np.abs(x - xm) < 0.075
        if kind == "dashed":
            on &= (z % 9.0) < 3.0
        ground[on] = np.array([0.85, 0.85, 0.83]) * (1 + 0.03 * n_fine[on])[:, None]
    # soft contact shadows under the cars
    for car in layout.cars:
        h_, w_, l_ = car.dims
        near = np.flatnonzero((np.abs(x - car.x) < l_ + 1) & (np.abs(z - car.z) < l_ + 1))
        ca, sa = np.cos(car.azimuth), np.sin(car.azimuth)
        dx, dz = x[near] - car.x, z[near] - car.z
        u = ca * dx - sa * dz  # object-frame x (inverse of R_y)
        v = sa * dx + ca * dz
        out = np.hypot(np.maximum(np.abs(u) - l_ / 2, 0), np.maximum(np.abs(v) - w_ / 2, 0))
        ground[near] *= (1 - 0.6 * np.clip(1 - out / 0.4, 0, 1))[:, None]
    return ground


def _background(layout: SceneLayout, camera: Camera, rays_cam, rng):
    """RGB background (H, W, 3) float32 and the distance to the background surface per
    pixel (inf on sky). Works on flat pixel subsets (sky, facades, ground)."""
    H, W = rays_cam.shape[:2]
    R_gp = layout.R_gp
    st = layout.street
    hgt = layout.plane.height
    c = R_gp.T @ camera.center
    d = rays_cam.reshape(-1, 3) @ R_gp  # street-frame directions (R_gp.T @ d per pixel)
    N = len(d)
    noise = _value_noise(rng)
    noise2 = _value_noise(rng)

    # sky gradient
    elev = -d[:, 1]
    tsky = np.clip(elev * 4, 0, 1)[:, None]
    img = (np.array([0.80, 0.86, 0.92]) * (1 - tsky) + np.array([0.45, 0.62, 0.85]) * tsky)
    dist = np.full(N, np.inf)

    # ground: y = hgt in the street frame
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = (hgt - c[1]) / d[:, 1]
    g_ok = np.isfinite(tg) & (tg > 0)
    for xf in (st.facade_left, st.facade_right):  # vertical planes, blocks along z
        _facade(img, dist, xf, c, d, tg, g_ok, hgt, noise2, rng)
    idx = np.flatnonzero(g_ok & (tg < dist))
    t = tg[idx]
    P = c + t[:, None] * d[idx]
    img[idx] = _ground_colour(layout, P[:, 0], P[:, 2], noise, noise2)
    dist[idx] = t
    return img.reshape(H, W, 3), dist.reshape(H, W)


# --------------------------------------------------------------------------- one scene


@dataclass
class SyntheticScene:
    image: np.ndarray  # (H, W, 3) uint8
    edges: np.ndarray  # (H, W) bool
    labels: FrameLabels
    wireframes: dict
    depth: np.ndarray  # (H, W) rendered object depth (inf on background)
    object_id: np.ndarray  # (H, W): car index (layout order), n_cars + k for occluder k, -1 background
    camera: Camera


def _render_objects(meshes, camera: Camera):
    """render_scene over the window containing all meshes, pasted into full buffers."""
    W, H = camera.image_size
    depth = np.full((H, W), np.inf)
    obj = np.full((H, W), -1, dtype=np.int64)
    face = np.full((H, W), -1, dtype=np.int64)
    normals = np.zeros((H, W, 3))
    edges = np.zeros((H, W), dtype=bool)
    if not meshes:
        return depth, obj, face, normals, edges
    uv = np.concatenate([camera.project(v) for v, _ in meshes])
    u0 = int(np.clip(np.floor(uv[:, 0].min()) - 2, 0, W))
    u1 = int(np.clip(np.ceil(uv[:, 0].max()) + 3, 0, W))
    v0 = int(np.clip(np.floor(uv[:, 1].min()) - 2, 0, H))
    v1 = int(np.clip(np.ceil(uv[:, 1].max()) + 3, 0, H))
    if u1 <= u0 or v1 <= v0:
        return depth, obj, face, normals, edges
    T = np.array([[1.0, 0, -u0], [0, 1.0, -v0], [0, 0, 1.0]])
    crop = Camera(T @ camera.P, (u1 - u0, v1 - v0))
    r = render_scene(meshes, crop, image_size=(u1 - u0, v1 - v0))
    win = (slice(v0, v1), slice(u0, u1))
    depth[win], obj[win], face[win], normals[win], edges[win] = r.depth, r.object_id, r.face_id, r.normals, r.edges
    return depth, obj, face, normals, edges


def _first_hits(intersectors, meshes, origin, dirs):
    """(n_meshes, R) hit distances of unit rays against each mesh."""
    return np.stack([first_hit_distance(v, f, origin, dirs, intersector=it)[0]
                     for it, (v, f) in zip(intersectors, meshes)]) if meshes else np.zeros((0, len(dirs)))


def _scene_meshes(layout: SceneLayout, library: dict, rng: np.random.Generator):
    """Camera-frame meshes of the layout's cars (each resized to its KITTI-like size)
    and occluders: the resized car models, the cars' poses ``(loc, R)``, the car meshes
    and the occluder meshes (``rng`` shapes the bushes)."""
    instances = [resized(library[car.model], car.dims) for car in layout.cars]
    poses, car_meshes = [], []
    for car, m in zip(layout.cars, instances):
        loc, R = place(car.x, car.z, car.azimuth, layout.plane)
        poses.append((loc, R))
        car_meshes.append((_to_cam(m.vertices, loc, R), m.faces))
    occ_meshes = []
    for occ in layout.occluders:
        v, f = occluder_mesh(occ, rng)
        loc, R = place(occ.x, occ.z, 0.0, layout.plane)
        occ_meshes.append((_to_cam(v, loc, R), f))
    return instances, poses, car_meshes, occ_meshes


def _car_colours(rng: np.random.Generator, n_cars: int) -> np.ndarray:
    """Body colours ``(max(n_cars, 1), 3)``: a paint of the palette, brightness varied."""
    cols = CAR_COLOURS[rng.integers(len(CAR_COLOURS), size=max(n_cars, 1))]
    return np.clip(cols * rng.uniform(0.9, 1.1, size=(len(cols), 1)), 0, 1)


def _albedo(layout: SceneLayout, instances: list, car_cols, o, above, steep) -> np.ndarray:
    """Albedo ``(n, 3)`` of seen object points of object ids ``o``: car paint with glass
    (steep surfaces high on the car) and dark trim (low), occluders plain."""
    nc = len(instances)
    alb = np.zeros((len(o), 3))
    for i in range(nc + len(layout.occluders)):
        sel = o == i
        if not sel.any():
            continue
        if i < nc:
            hcar = instances[i].dims[0]
            a = np.broadcast_to(car_cols[i], (sel.sum(), 3)).copy()
            a[(above[sel] > 0.62 * hcar) & steep[sel]] = [0.10, 0.12, 0.14]
            a[above[sel] < 0.28] = [0.07, 0.07, 0.07]
        else:
            a = np.broadcast_to(OCCLUDER_COLOURS[layout.occluders[i - nc].kind], (sel.sum(), 3))
        alb[sel] = a
    return alb


def _shade_objects(img, layout: SceneLayout, camera: Camera, rays, depth, obj, normals, instances, car_cols):
    """Lambertian + ambient shading with haze of the object pixels of ``img``, in place."""
    hit = obj >= 0
    if not hit.any():
        return
    # height of each seen point above the ground plane (per pixel, so that the glass
    # and trim bands have straight edges whatever the mesh's triangulation)
    ray_h = rays[hit]
    X = camera.center + ray_h * (depth[hit] / (ray_h @ camera.P[2, :3]))[:, None]
    n_gp = layout.plane.normal
    above = layout.plane.height - X @ n_gp
    steep = np.abs(normals[hit] @ n_gp) < 0.8
    alb = _albedo(layout, instances, car_cols, obj[hit], above, steep)
    lam = np.clip(normals[hit] @ LIGHT, 0, None)
    # a little specular sky reflection on glass / bright body panels
    shade = alb * (0.35 + 0.65 * lam)[:, None] + 0.08 * lam[:, None] ** 8
    pts_dist = depth[hit]
    haze = (1 - np.exp(-pts_dist / 300.0))[:, None]
    img[hit] = shade * (1 - haze) + haze * np.array([0.8, 0.85, 0.9])


def _shade(layout: SceneLayout, camera: Camera, rays, rendered, instances, car_cols, rng) -> np.ndarray:
    """The uint8 image: background, shaded objects, distance haze and sensor noise."""
    depth, obj, _, normals, _ = rendered
    img, bg_dist = _background(layout, camera, rays, rng)
    _shade_objects(img, layout, camera, rays, depth, obj, normals, instances, car_cols)
    bgh = ~(obj >= 0) & np.isfinite(bg_dist)
    img[bgh] = (img[bgh] * np.exp(-bg_dist[bgh] / 300.0)[:, None]
                + (1 - np.exp(-bg_dist[bgh] / 300.0))[:, None] * [0.8, 0.85, 0.9])
    img = img + rng.normal(0, 0.012, size=img.shape)
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


def _silhouette(camera: Camera, obj, rays, i: int, mesh, intersector):
    """Car ``i``'s truncation and occlusion: KITTI's ``truncated`` (the share of its full
    silhouette outside the image), the hidden fraction of its in-image silhouette, and
    its count of visible pixels."""
    W, H = camera.image_size
    Vc, Fc = mesh
    origin = camera.center
    vis = obj == i
    n_vis = int(vis.sum())
    uvm = camera.project(Vc)
    bx0, by0 = np.floor(uvm.min(0)).astype(int)
    bx1, by1 = np.ceil(uvm.max(0)).astype(int)
    cx0, cx1 = max(bx0, 0), min(bx1, W - 1)
    cy0, cy1 = max(by0, 0), min(by1, H - 1)
    n_hidden = 0
    if cx1 >= cx0 and cy1 >= cy0:
        win = (slice(cy0, cy1 + 1), slice(cx0, cx1 + 1))
        cand = (obj[win] >= 0) & (obj[win] != i)
        if cand.any():
            rr, cc = np.nonzero(cand)
            dirs = rays[rr + cy0, cc + cx0]
            t, _ = first_hit_distance(Vc, Fc, origin, dirs, intersector=intersector)
            n_hidden = int(np.isfinite(t).sum())
    n_out = 0.0
    area = (bx1 - bx0 + 1) * (by1 - by0 + 1)
    if bx0 < 0 or by0 < 0 or bx1 > W - 1 or by1 > H - 1:
        s = max(1, int(np.ceil(np.sqrt(area / MAX_TRUNCATION_RAYS))))
        gu, gv = np.meshgrid(np.arange(bx0, bx1 + 1, s, dtype=float), np.arange(by0, by1 + 1, s, dtype=float))
        outside = (gu < 0) | (gu > W - 1) | (gv < 0) | (gv > H - 1)
        if outside.any():
            uv_o = np.stack([gu[outside], gv[outside]], -1)
            t, _ = first_hit_distance(Vc, Fc, origin, camera.rays(uv_o), intersector=intersector)
            n_out = float(np.isfinite(t).sum()) * s * s
    n_in = n_vis + n_hidden
    truncated = n_out / (n_out + n_in) if n_out + n_in > 0 else 1.0
    occ_frac = n_hidden / n_in if n_in > 0 else 1.0
    return truncated, occ_frac, n_vis


def _vertex_visibility(camera: Camera, m: CarModel, pose, i: int, meshes, intersectors, n_cars: int):
    """Car ``i``'s 36 vertices in the camera frame, their projections and depths, and
    the reason of each one's visibility (see the module docstring)."""
    W, H = camera.image_size
    loc, R = pose
    origin = camera.center
    X = _to_cam(m.landmarks, loc, R)
    uv, vdepth = camera.project_with_depth(X)
    centre_obj = np.array([0.0, -m.dims[0] / 2, 0.0])
    push = m.landmarks - centre_obj
    push /= np.maximum(np.linalg.norm(push, axis=1, keepdims=True), 1e-9)
    Xp = _to_cam(m.landmarks + VERTEX_PUSH * push, loc, R)
    dv = Xp - origin
    dist = np.linalg.norm(dv, axis=1)
    dv = dv / dist[:, None]
    hits = _first_hits(intersectors, meshes, origin, dv)  # (n_meshes, 36)
    blocked = hits < (dist - VERTEX_TOL)
    ui, vi = np.round(uv[:, 0]), np.round(uv[:, 1])
    reasons = []
    for k in range(len(X)):
        if vdepth[k] <= 0 or not (0 <= ui[k] <= W - 1 and 0 <= vi[k] <= H - 1):
            reasons.append("truncated")
        elif blocked[i, k]:
            reasons.append("self")
        else:
            others = [j for j in range(len(meshes)) if j != i and blocked[j, k]]
            if not others:
                reasons.append("visible")
            else:
                j = min(others, key=lambda j: hits[j, k])
                reasons.append("other-car" if j < n_cars else "occluder")
    return X, uv, vdepth, reasons


def _kitti_box(camera: Camera, m: CarModel, loc, ry: float, visible_box: list) -> list:
    """KITTI's 2D box: the level 3D label box projected and clipped to the image (a box
    reaching behind the camera has no projection: its visible extent stands in)."""
    corners = box_corners(np.asarray(m.dims), loc, rotation_y(ry))
    if corners[:, 2].min() > 0.1:
        return [float(b) for b in project_points_to_box(camera, corners)]
    return visible_box


def _car_record(car, m: CarModel, pose, colour, silhouette, vertices, shape_model) -> dict:
    """The wireframes-JSON record of one car (without its boxes)."""
    loc, R = pose
    truncated, occ_frac, n_vis = silhouette
    X, uv, vdepth, reasons = vertices
    return {
        "cad_model": car.model,
        "role": car.role,
        "street_xz": [car.x, car.z],
        "azimuth": car.azimuth,
        "location": loc.tolist(),
        "R": R.tolist(),
        "rotation_y": float(rotation_y_of(R)),
        "dims_hwl": list(m.dims),
        "colour": colour.tolist(),
        "truncated": truncated,
        "occluded_fraction": occ_frac,
        "occluded": int(np.searchsorted(OCCLUSION_THRESHOLDS, occ_frac, side="right")),
        "visible_pixels": n_vis,
        "vertices_3d": X.tolist(),
        "vertices_2d": uv.tolist(),
        "vertex_depth": vdepth.tolist(),
        "visibility": reasons,
        "visible": [r == "visible" for r in reasons],
        "n_occluded_not_self": int(sum(r in ("other-car", "occluder") for r in reasons)),
        "shape_coefficients": None if shape_model is None else shape_model.project_coefficients(m.landmarks).tolist(),
    }


def _annotate(camera: Camera, layout: SceneLayout, instances, poses, meshes, obj, rays, car_cols):
    """Ground truth of every car: KITTI labels, the JSON records of the labelled cars
    (same order) and those of the cars of which no pixel is visible."""
    nc = len(instances)
    intersectors = [mesh_intersector(v, f) for v, f in meshes]
    shape_model = _shape_model()
    labels, cars_json, hidden = FrameLabels(), [], []
    for i, car in enumerate(layout.cars):
        m, loc = instances[i], poses[i][0]
        silhouette = _silhouette(camera, obj, rays, i, meshes[i], intersectors[i])
        vertices = _vertex_visibility(camera, m, poses[i], i, meshes, intersectors, nc)
        rec = _car_record(car, m, poses[i], car_cols[i], silhouette, vertices, shape_model)
        if rec["visible_pixels"] == 0:
            hidden.append(rec)
            continue
        rr, cc = np.nonzero(obj == i)
        rec["visible_box"] = [float(cc.min()), float(rr.min()), float(cc.max()), float(rr.max())]
        ry = rec["rotation_y"]
        rec["box"] = box = _kitti_box(camera, m, loc, ry, rec["visible_box"])
        rec["scene_object_id"] = i
        labels.objects.append(Label("Car", rec["truncated"], rec["occluded"],
                                    float(alpha_from_rotation_y(ry, loc[0], loc[2])), box, m.dims, loc, ry))
        cars_json.append(rec)
    return labels, cars_json, hidden


def generate_scene(seed: int, index: int, *, cars=(2, 8), occluders: bool = True,
                   camera: Camera | None = None, library: dict | None = None,
                   camera_height: float = KITTI_CAMERA_HEIGHT, camera_pitch_deg: float = 0.0) -> SyntheticScene:
    """Sample, render and annotate scene ``index`` of the stream ``seed`` (with KITTI's
    camera, 1.65 m above the road, unless told otherwise: see :func:`sample_layout`)."""
    camera = default_camera() if camera is None else camera
    library = load_car_library() if library is None else library
    W, H = camera.image_size
    rng = np.random.default_rng([int(seed), int(index)])
    n_cars = int(rng.integers(cars[0], cars[1] + 1))
    n_occ = int(rng.integers(0, 4)) if occluders else 0
    dims = {k: m.dims for k, m in library.items()}
    layout = sample_layout(rng, camera, dims, n_cars=n_cars, n_occluders=n_occ, camera_height=camera_height,
                           camera_pitch_deg=camera_pitch_deg)
    colour_rng = np.random.default_rng([int(seed), int(index), 1])
    noise_rng = np.random.default_rng([int(seed), int(index), 2])

    instances, poses, car_meshes, occ_meshes = _scene_meshes(layout, library, noise_rng)
    meshes = car_meshes + occ_meshes
    nc = len(car_meshes)
    rendered = _render_objects(meshes, camera)
    depth, obj, _, _, edges = rendered
    rays = _pixel_rays(camera.P.tobytes(), W, H)
    car_cols = _car_colours(colour_rng, nc)
    image = _shade(layout, camera, rays, rendered, instances, car_cols, noise_rng)
    labels, cars_json, hidden = _annotate(camera, layout, instances, poses, meshes, obj, rays, car_cols)
    wire = {
        "format": 1,
        "seed": int(seed),
        "index": int(index),
        "image_size": [W, H],
        "P2": camera.P.tolist(),
        "ground_plane": layout.plane.to_dict(),
        "street": layout.street.to_dict(),
        "occluders": [o.to_dict() | {"scene_object_id": nc + k} for k, o in enumerate(layout.occluders)],
        "vertex_names": list(VERTEX_NAMES),
        "visibility_rule": {"push_m": VERTEX_PUSH, "tol_m": VERTEX_TOL,
                            "occluded_thresholds": list(OCCLUSION_THRESHOLDS)},
        "cars": cars_json,
        "hidden_cars": hidden,
    }
    return SyntheticScene(image, edges, labels, _round(wire), depth, obj, camera)


def _round(x, nd=6):
    if isinstance(x, float):
        return round(x, nd)
    if isinstance(x, dict):
        return {k: _round(v, nd) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_round(v, nd) for v in x]
    if isinstance(x, np.generic):
        return _round(x.item(), nd)
    return x


# --------------------------------------------------------------------------- writing


def _png_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def write_scene(out_dir, frame_id: str, scene: SyntheticScene, *, split: str = "training") -> None:
    """Write one scene in KITTI layout under ``out_dir/split`` (each file atomically)."""
    split = Path(out_dir) / split
    write_bytes(split / "image_2" / f"{frame_id}.png", _png_bytes(scene.image))
    write_bytes(split / "edges_2" / f"{frame_id}.png", _png_bytes(scene.edges.astype(np.uint8) * 255))
    calib = split / "calib" / f"{frame_id}.txt"
    with atomic_path(calib) as tmp:
        write_kitti_calib(tmp, scene.camera.P)
    write_labels(split / "label_2" / f"{frame_id}.txt", scene.labels, with_score=False)
    write_bytes(wireframe_gt_path(split, frame_id),
                  (json.dumps(scene.wireframes, indent=1) + "\n").encode())


def generate_dataset(out_dir, n_scenes: int, seed: int = 0, *, cars=(2, 8), occluders: bool = True,
                     progress=None, split: str = "training") -> list:
    """Generate and write ``n_scenes`` scenes (frame ids 000000, 000001, ...) under
    ``out_dir/split``; returns the ids.

    ``progress`` wraps the index iterable (e.g. tqdm)."""
    if n_scenes < 0:
        raise ValueError("n_scenes must be >= 0")
    if not (1 <= cars[0] <= cars[1]):
        raise ValueError(f"cars per scene must be 1 <= A <= B, got {cars[0]}-{cars[1]}")
    camera = default_camera()
    library = load_car_library()
    ids = []
    indices = range(int(n_scenes))
    for index in (progress(indices) if progress else indices):
        scene = generate_scene(seed, index, cars=cars, occluders=occluders, camera=camera, library=library)
        fid = f"{index:06d}"
        write_scene(out_dir, fid, scene, split=split)
        ids.append(fid)
    return ids
