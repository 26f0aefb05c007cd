"""Non-photorealistic renderer (wirescene.render) on a synthetic car-like mesh."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.ndimage import binary_erosion

from conftest import assert_close
from wirescene.core.camera import Camera
from wirescene.core.errors import ShapeError
from wirescene.core.groundplane import transform
from wirescene.render import (
    Rendering,
    iter_views,
    project_landmarks,
    render,
    render_scene,
    shade,
    view_camera,
)


def car_mesh():
    """Object frame (x forward, y down, z left, ground y = 0): a body box with a
    smaller cabin box on top, sunk slightly into the body."""
    body = trimesh.creation.box((4.2, 1.0, 1.8))
    cabin = trimesh.creation.box((2.2, 0.5, 1.5))
    v = np.vstack([body.vertices + [0, -0.5, 0], cabin.vertices + [-0.3, -1.2, 0]])
    f = np.vstack([body.faces, cabin.faces + len(body.vertices)])
    return v, f


def pixel(uv):
    return np.round(uv[..., 1]).astype(int), np.round(uv[..., 0]).astype(int)


@pytest.fixture(scope="module")
def scene():
    v, f = car_mesh()
    view = view_camera(35.0, 15.0)
    return v, f, view, render(v, f, view.camera, view.location, view.R)


def test_buffers_are_consistent(scene):
    v, f, view, r = scene
    assert isinstance(r, Rendering)
    assert r.depth.shape == r.face_id.shape == r.edges.shape == r.mask.shape == (256, 256)
    assert r.normals.shape == (256, 256, 3)
    assert 0.05 < r.mask.mean() < 0.6  # the car is in view, not filling it
    assert np.array_equal(r.mask, np.isfinite(r.depth))
    assert np.array_equal(r.mask, r.face_id >= 0)
    assert r.face_id.max() < len(f)
    assert_close(np.linalg.norm(r.normals[r.mask], axis=-1), 1.0)
    # Normals face the camera.
    rows, cols = np.nonzero(r.mask)
    rays = view.camera.rays(np.stack([cols, rows], -1).astype(float))
    assert np.all(np.einsum("ri,ri->r", r.normals[rows, cols], rays) < 0)
    # Face orientation does not matter (CAD meshes are rarely consistently oriented).
    flipped = render(v, f[:, ::-1], view.camera, view.location, view.R)
    assert_close(flipped.normals, r.normals)
    assert np.array_equal(flipped.mask, r.mask) and np.array_equal(flipped.edges, r.edges)
    assert_close(flipped.depth[r.mask], r.depth[r.mask], atol=1e-9)


def test_landmark_projection_agrees_with_camera_and_depth_buffer(scene):
    v, f, view, r = scene
    cam, loc, R = view.camera, view.location, view.R
    uv, depth, visible = project_landmarks(v, v, f, cam, loc, R)
    X = transform(v, loc, R)
    uv_ref, depth_ref = cam.project_with_depth(X)
    assert_close(uv, uv_ref)
    assert_close(depth, depth_ref)
    assert 0 < visible.sum() < len(v)
    rows, cols = pixel(uv)
    for k in range(len(v)):
        window = r.depth[rows[k] - 1 : rows[k] + 2, cols[k] - 1 : cols[k] + 2]
        if visible[k]:
            # A visible corner: some pixel next to it sees the surface at its depth.
            assert np.min(np.abs(window - depth[k])) < 0.1, k
        else:
            # A hidden corner: something nearer covers it.
            assert r.depth[rows[k], cols[k]] < depth[k] - 0.1, k


def test_rendered_depth_is_exact_on_faces(scene):
    v, f, view, r = scene
    cam, loc, R = view.camera, view.location, view.R
    X = transform(v, loc, R)
    centroids = X[f].mean(axis=1)
    uv, depth = cam.project_with_depth(centroids)
    rows, cols = pixel(uv)
    seen = r.face_id[rows, cols] == np.arange(len(f))
    assert seen.sum() >= 4
    # Depth along the pixel's ray to the face plane, vs the buffer: exact.
    for k in np.flatnonzero(seen):
        n = np.cross(X[f[k, 1]] - X[f[k, 0]], X[f[k, 2]] - X[f[k, 0]])
        d = cam.rays(np.array([cols[k], rows[k]], float))
        t = n @ (X[f[k, 0]] - cam.center) / (n @ d)
        assert_close(r.depth[rows[k], cols[k]], cam.project_with_depth(cam.center + t * d)[1], atol=1e-9)
        # ...and within half a pixel's footprint of the centroid's own depth.
        assert abs(r.depth[rows[k], cols[k]] - depth[k]) < 0.1


def test_edges_contain_silhouette_and_creases_but_not_face_interiors(scene):
    v, f, view, r = scene
    boundary = r.mask & ~binary_erosion(r.mask, border_value=1)
    assert boundary.sum() > 100
    assert r.edges[boundary].all()
    assert not r.edges[~r.mask].any()  # lines lie on the occluding surface
    # Visible box edges where two visible faces meet are creases: check edge midpoints.
    cam, loc, R = view.camera, view.location, view.R
    X = transform(v, loc, R)
    uv, _, visible = project_landmarks(v, v, f, cam, loc, R)
    body_edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(v[a] != v[b]) == 1]
    checked = 0
    for a, b in body_edges:
        if visible[a] and visible[b]:
            mid = cam.project(0.5 * (X[a] + X[b]))
            rr, cc = pixel(mid)
            assert r.edges[rr - 1 : rr + 2, cc - 1 : cc + 2].any(), (a, b)
            checked += 1
    assert checked >= 3
    # Flat face interiors carry no lines: most masked pixels are not edges.
    assert r.edges.sum() < 0.25 * r.mask.sum()
    _, _, visible_faces = project_landmarks(v[f].mean(axis=1), v, f, cam, loc, R)
    assert visible_faces.sum() >= 4
    for k in np.flatnonzero(visible_faces):
        rr, cc = pixel(cam.project(X[f[k]].mean(axis=0)))
        if r.face_id[rr, cc] == k:  # centroid pixel interior to its own (big) face
            assert not r.edges[rr, cc], k


def test_render_scene_object_ids_and_mutual_occlusion():
    v, f = car_mesh()
    cam = Camera(np.array([[400.0, 0, 160, 0], [0, 400.0, 120, 0], [0, 0, 1, 0]]), (320, 240))
    front = v + [0.0, 1.65, 10.0]
    back = v + [1.5, 1.65, 16.0]
    s = render_scene([(front, f), (back, f)], cam)
    assert set(np.unique(s.object_id)) == {-1, 0, 1}
    assert np.array_equal(s.mask, s.object_id >= 0)
    # Where both project, the front car wins (checked against rendering the back alone).
    alone = render_scene([(back, f)], cam)
    overlap = alone.mask & (s.object_id == 0)
    assert overlap.sum() > 50
    assert np.all(s.depth[overlap] < alone.depth[overlap])
    assert np.all(s.depth[s.object_id == 1] == alone.depth[s.object_id == 1])
    # The boundary between the two cars is drawn on the front car.
    between = np.zeros_like(s.mask)
    between[:, :-1] |= (s.object_id[:, :-1] == 0) & (s.object_id[:, 1:] == 1)
    between[:, 1:] |= (s.object_id[:, 1:] == 0) & (s.object_id[:, :-1] == 1)
    assert between.sum() > 5 and s.edges[between].all()
    # Face ids are local to each mesh.
    assert s.face_id[s.object_id == 1].max() < len(f)


def test_view_camera_geometry():
    v, f = car_mesh()
    view = view_camera(0.0, 0.0, distance=12.0, image_size=(200, 100))
    assert view.camera.image_size == (200, 100)
    centre = view.camera.project(transform(np.array([[0, -0.75, 0.0]]), view.location, view.R))
    assert_close(centre, [[99.5, 49.5]], atol=1e-9)
    # Azimuth 0: side view, the car's front (+x) to the image's right.
    front, rear = view.camera.project(transform(np.array([[2.0, -0.5, 0], [-2.0, -0.5, 0]]), view.location, view.R))
    assert front[0] > 120 > 80 > rear[0]
    # Azimuth 90: the front faces the camera.
    view = view_camera(90.0, 0.0)
    _, d = view.camera.project_with_depth(transform(np.array([[2.0, -0.5, 0], [-2.0, -0.5, 0]]), view.location, view.R))
    assert d[0] < d[1]
    # Positive elevation looks down on the roof, negative from below.
    top = np.array([[0.0, -1.45, 0.0]])
    for elev, roof_visible in ((15.0, True), (-15.0, False)):
        view = view_camera(30.0, elev)
        r = render(v, f, view.camera, view.location, view.R)
        rr, cc = pixel(view.camera.project(transform(top, view.location, view.R)))
        up = np.array([0.0, -1.0, 0.0]) @ view.R.T
        assert (r.normals[rr[0], cc[0]] @ up > 0.99) == roof_visible


def test_iter_views_covers_the_viewing_sphere_like_the_paper():
    views = list(iter_views())
    assert len(views) == 144
    assert sorted({w.elevation_deg for w in views}) == [7.5, 15.0]
    az = sorted({w.azimuth_deg for w in views})
    assert len(az) == 72 and az[0] == 0.0 and np.allclose(np.diff(az), 5.0)


def test_shade_lambert_and_albedo():
    v, f = car_mesh()
    view = view_camera(30.0, 15.0)
    r = render(v, f, view.camera, view.location, view.R)
    up = view.R @ np.array([0.0, -1.0, 0.0])  # the car's up, camera frame
    grey = shade(r, light_dir=up, albedo=1.0, ambient=0.2)
    assert grey.shape == (256, 256)
    assert np.all(grey[~r.mask] == 0) and np.all((grey[r.mask] >= 0.2 - 1e-12) & (grey[r.mask] <= 1 + 1e-12))
    roof = r.mask & (r.normals @ up > 0.999)
    side = r.mask & (np.abs(r.normals @ up) < 1e-6)
    assert roof.any() and side.any()
    assert_close(grey[roof], 1.0)
    assert_close(grey[side], 0.2)
    rgb = shade(r, albedo=[[1.0, 0.0, 0.0]], background=(0, 0, 1))
    assert rgb.shape == (256, 256, 3)
    assert np.all(rgb[r.mask][:, 1:] == 0) and np.all(rgb[~r.mask] == [0, 0, 1])
    with pytest.raises(ShapeError):
        shade(r, albedo=np.ones((2, 2, 2)))


def test_project_landmarks_behind_camera_is_not_visible():
    v, f = car_mesh()
    view = view_camera(0.0, 7.5)
    pts = np.array([[0.0, -0.5, 0.0], [0.0, 0.0, 0.0]])
    # Pose the car behind the camera.
    _, depth, visible = project_landmarks(pts, v, f, view.camera, view.location * [1, 1, -1], view.R)
    assert np.all(depth < 0) and not visible.any()


def test_render_rejects_bad_input():
    v, f = car_mesh()
    cam = Camera(np.hstack([np.eye(3), np.zeros((3, 1))]))
    with pytest.raises(ShapeError):
        render(v, f, cam, np.zeros(3), np.eye(3))  # no image size anywhere
    with pytest.raises(ShapeError):
        render(v, f + 100, cam, np.zeros(3), np.eye(3), image_size=(8, 8))
    with pytest.raises(ShapeError):
        render(v[:, :2], f, cam, np.zeros(3), np.eye(3), image_size=(8, 8))
