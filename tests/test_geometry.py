import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.boxes import MEAN_CAR_DIMS, box_centers, box_corners, iou_2d, project_points_to_box
from wirescene.core.camera import Camera, read_kitti_calib, write_kitti_calib
from wirescene.core.errors import InputError, ShapeError
from wirescene.core.groundplane import (
    GroundPlane,
    alpha_from_rotation_y,
    object_pose,
    plane_normal,
    point_on_plane,
    rotation_y,
    rotation_y_from_alpha,
    rotation_y_of,
    wrap_angle,
)
from wirescene.core.viewpoints import angle_difference, bin_center, viewpoint_bin

CALIB = KITTI_ROOT / "training" / "calib" / "000010.txt"


@pytest.fixture
def camera():
    return read_kitti_calib(CALIB).camera((1242, 375))


def test_calib_p2_values(camera):
    assert_close(camera.P[0, 0], 721.5377)
    assert_close(camera.P[0, 3], 44.85728)
    # The optical centre is the null space of P; the colour camera sits ~6 cm left of
    # the reference camera.
    assert_close(camera.P @ np.append(camera.center, 1.0), np.zeros(3), atol=1e-9)
    assert -0.07 < camera.center[0] < -0.05


def test_projection_roundtrip(camera):
    rng = np.random.default_rng(0)
    X = rng.uniform([-10, -2, 3], [10, 3, 60], size=(100, 3))
    uv, depth = camera.project_with_depth(X)
    assert_close(camera.backproject(uv, depth), X, atol=1e-9)
    # Rays from the optical centre pass through the points.
    d = camera.rays(uv)
    v = X - camera.center
    assert_close(np.cross(d, v / np.linalg.norm(v, axis=1, keepdims=True)), np.zeros_like(X), atol=1e-9)


def test_projection_and_placement_add_like_whole_rows_to_the_bit(camera):
    """project_with_depth and transform add the translation (and divide the pixels) a
    component at a time, in place: the same values, to the bit, as on whole rows."""
    from wirescene.core.groundplane import transform

    rng = np.random.default_rng(4)
    X = rng.uniform([-10, -2, -1], [10, 3, 60], size=(50, 7, 36, 3))
    X[0, 0, 0] = camera.center  # depth 0: the clamped divisor
    uvw = X @ camera.P[:, :3].T + camera.P[:, 3]
    w = uvw[..., 2]
    want = uvw[..., :2] / np.where(np.abs(w) < 1e-9, 1e-9, w)[..., None]
    uv, depth = camera.project_with_depth(X)
    assert uv.tobytes() == want.tobytes() and depth.tobytes() == w.tobytes()
    one = camera.project_with_depth(X[1, 1, 1])
    assert one[0].tobytes() == want[1, 1, 1].tobytes() and one[1].shape == ()
    location, R = rng.normal(size=(50, 7, 3)), rng.normal(size=(50, 7, 3, 3))
    placed = transform(X, location, R)
    assert placed.tobytes() == (np.matmul(X, np.swapaxes(R, -1, -2)) + location[..., None, :]).tobytes()
    # a location that widens the batch, and integer points: the plain sum
    wide = transform(X[0, 0], location, rotation_y(0.3))
    assert wide.shape == (50, 7, 36, 3)
    assert wide.tobytes() == (X[0, 0] @ rotation_y(0.3).T + location[..., None, :]).tobytes()
    assert transform(np.ones((2, 3), int), np.array([0.5, 0, 0]), np.eye(3, dtype=int)).tolist() == [[1.5, 1, 1]] * 2


def test_point_bounds_are_the_pointwise_minima_in_order_to_the_bit():
    """point_bounds reads blocks of point sets component-major: the same minima and maxima,
    in the same order (signed zeros and NaN included), as the loop over whole points."""
    from wirescene.core import arrays

    def loop(points):
        lo = points[..., 0, :].copy()
        hi = lo.copy()
        for k in range(1, points.shape[-2]):
            np.minimum(lo, points[..., k, :], out=lo)
            np.maximum(hi, points[..., k, :], out=hi)
        return lo, hi

    rng = np.random.default_rng(2)
    for shape in ((arrays.BOUNDS_BLOCK + 5, 36, 3), (3, 4, 8, 2), (36, 3), (0, 5, 3), (6, 1, 3)):
        points = rng.normal(size=shape)
        points[..., ::3, :], points[..., 1::4, :] = 0.0, -0.0
        points[..., 2:5, 0] = np.where(rng.random(points[..., 2:5, 0].shape) < 0.1, np.nan, points[..., 2:5, 0])
        for got, want in zip(arrays.point_bounds(points), loop(points)):
            assert got.shape == want.shape and got.tobytes() == want.tobytes()
    assert arrays.point_bounds(np.arange(12).reshape(4, 3))[1].tolist() == [9, 10, 11]


def test_kitti_label_projects_into_its_box(camera):
    # First car of 000010: its 3D box projected must match the labelled 2D box where untruncated.
    line = "Car 0.00 0 1.95 354.43 185.52 549.52 294.49 1.43 1.70 3.95 -2.39 1.66 11.80 1.76"
    v = line.split()
    dims, loc, ry = np.array(v[8:11], float), np.array(v[11:14], float), float(v[14])
    box = project_points_to_box(camera, box_corners(dims, loc, rotation_y(ry)))
    assert_close(box, np.array(v[4:8], float), atol=3.0)


def test_calib_errors(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_kitti_calib(tmp_path / "missing.txt")
    bad = tmp_path / "bad.txt"
    bad.write_text("P0: 1 2 3\n")
    with pytest.raises(InputError, match="no P2"):
        read_kitti_calib(bad)
    bad.write_text("P2: 1 2 3\n")
    with pytest.raises(InputError, match="P2 has 3 numbers"):
        read_kitti_calib(bad)
    bad.write_text("P2: 1 2 x 4 5 6 7 8 9 10 11 12\n")
    with pytest.raises(InputError, match="line 1: non-numeric"):
        read_kitti_calib(bad)
    assert str(InputError("oops", path=bad)).startswith(str(bad))


def test_write_calib_roundtrip(tmp_path, camera):
    write_kitti_calib(tmp_path / "c.txt", camera.P)
    assert_close(read_kitti_calib(tmp_path / "c.txt").P2, camera.P, atol=1e-9)


def test_written_calib_has_kittis_seven_lines_and_lidar_axes(tmp_path, camera):
    """The seven lines of a KITTI object calibration in their order (mmdetection3d's converter reads the
    seventh, Tr_imu_to_velo), and a Tr_velo_to_cam of KITTI's axes (LiDAR x forward, y left, z up), so that a
    label box taken into the LiDAR frame (OpenPCDet, mmdetection3d) stands upright and faces forward."""
    write_kitti_calib(tmp_path / "c.txt", camera.P)
    lines = (tmp_path / "c.txt").read_text().splitlines()
    assert [ln.split(":")[0] for ln in lines] == ["P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo"]
    velo_to_cam = np.array(lines[5].split()[1:], float).reshape(3, 4)
    assert_close(velo_to_cam[:, :3] @ np.eye(3), [[0, -1, 0], [0, 0, -1], [1, 0, 0]])  # forward, left, up -> z, -x, -y
    assert_close(np.array(lines[6].split()[1:], float).reshape(3, 4), np.eye(4)[:3])
    assert_close(read_kitti_calib(tmp_path / "c.txt").Tr_velo_to_cam, velo_to_cam)


def test_shape_contract():
    with pytest.raises(ShapeError, match=r"\(3, 4\)"):
        Camera(np.eye(3))
    with pytest.raises(ShapeError):
        Camera(np.eye(3, 4)).project(np.zeros((5, 2)))


def test_level_plane_matches_kitti_convention():
    loc, R = object_pose(2.0, 20.0, 0.7)
    assert_close(loc, [2.0, 1.65, 20.0])
    assert_close(R, rotation_y(0.7))
    assert_close(rotation_y_of(R), 0.7)


def test_plane_points_satisfy_plane_equation():
    rng = np.random.default_rng(1)
    pitch, roll = rng.uniform(-0.05, 0.05, (2, 50))
    x, z = rng.uniform(-10, 10, 50), rng.uniform(5, 50, 50)
    p = point_on_plane(x, z, pitch, roll, 1.7)
    n = plane_normal(pitch, roll)
    assert_close(np.sum(n * p, axis=-1), np.full(50, 1.7))
    # Objects stand upright on the plane: their down axis is the plane normal.
    _, R = object_pose(x, z, rng.uniform(-3, 3, 50), pitch, roll, 1.7)
    assert_close(R[..., :, 1], n, atol=1e-12)
    assert_close(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)


def test_groundplane_fit_recovers_plane():
    gp = GroundPlane(pitch=0.02, roll=-0.01, height=1.7)
    rng = np.random.default_rng(2)
    pts = point_on_plane(rng.uniform(-10, 10, 30), rng.uniform(5, 40, 30), gp.pitch, gp.roll, gp.height)
    fit = GroundPlane.fit(pts)
    assert_close([fit.pitch, fit.roll, fit.height], [0.02, -0.01, 1.7], atol=1e-9)


def test_alpha_rotation_y_inverse():
    ry, x, z = 1.76, -2.39, 11.80
    a = alpha_from_rotation_y(ry, x, z)
    assert_close(a, 1.95, atol=0.01)  # the label's own alpha
    assert_close(rotation_y_from_alpha(a, x, z), ry)
    assert_close(wrap_angle(3 * np.pi), -np.pi)


def test_box_centroid_and_iou():
    c = box_centers(MEAN_CAR_DIMS, np.array([0, 1.65, 10.0]), np.eye(3))
    assert_close(c, [0, 1.65 - MEAN_CAR_DIMS[0] / 2, 10.0])
    assert_close(iou_2d([0, 0, 10, 10], [5, 0, 15, 10]), 1 / 3)
    assert_close(iou_2d([0, 0, 10, 10], [20, 20, 30, 30]), 0.0)


def test_viewpoint_bins():
    assert viewpoint_bin(0.0) == 0
    assert viewpoint_bin(np.deg2rad(44)) == 1
    assert viewpoint_bin(np.deg2rad(-44)) == 7
    assert viewpoint_bin(np.pi) == 4 and viewpoint_bin(-np.pi) == 4
    assert_close(bin_center(2), np.pi / 2)
    assert_close(angle_difference(np.deg2rad(179), np.deg2rad(-179)), np.deg2rad(2))
