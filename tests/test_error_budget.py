"""The error budget of benchmarks/bench_error_budget.py on constructed cars: the split
along / across the viewing ray, the azimuth wrap, the one-pixel limit, the one-component
replacement, and a run read back from frame records."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from wirescene.core.camera import read_kitti_calib
from wirescene.eval.metrics import FrameResult
from wirescene.eval.records import FrameRecords
from wirescene.io.kitti import KittiDataset

ROOT = Path(__file__).resolve().parents[1]
KITTI = ROOT / "tests" / "data" / "kitti"


@pytest.fixture(scope="module")
def budget():
    # The script imports benchmarks/_common.py, as when run from benchmarks/.
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(ROOT / "benchmarks"))
        script = ROOT / "benchmarks" / "bench_error_budget.py"
        spec = importlib.util.spec_from_file_location("_bench_error_budget", script)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        yield module


CENTRE = np.array([0.06, -0.01, 0.003])  # a P2-like optical centre, off the origin


def _labels(budget):
    # Three cars at different bearings and distances, one turned.
    return budget.Boxes.of([[4.0, 1.6, 20.0], [-6.0, 1.7, 9.0], [1.0, 1.5, 40.0]],
                           [[1.5, 1.6, 4.0], [1.4, 1.7, 3.8], [1.6, 1.8, 4.4]], [0.3, -1.5, 2.9])


def _ray(labels):
    d = labels.location[:, [0, 2]] - CENTRE[[0, 2]]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _moved(budget, labels, xz):
    loc = labels.location.copy()
    loc[:, [0, 2]] += xz
    return budget.Boxes(loc, labels.dims.copy(), labels.rotation_y.copy())


def test_a_shift_along_the_ray_is_range_error_only(budget):
    labels = _labels(budget)
    fitted = _moved(budget, labels, 1.0 * _ray(labels))
    e = budget.error_components(fitted, labels, CENTRE)
    np.testing.assert_allclose(e["range"], 1.0, atol=1e-12)
    np.testing.assert_allclose(e["lateral"], 0.0, atol=1e-12)
    np.testing.assert_allclose(e["height"], 0.0, atol=1e-12)
    np.testing.assert_allclose(e["centre_distance"], 1.0, atol=1e-12)
    # Signed: a box short of its label has a negative range error.
    short = budget.error_components(_moved(budget, labels, -0.4 * _ray(labels)), labels, CENTRE)
    np.testing.assert_allclose(short["range"], -0.4, atol=1e-12)


def test_a_sideways_shift_is_lateral_error_only(budget):
    labels = _labels(budget)
    u = _ray(labels)
    right = np.stack([u[:, 1], -u[:, 0]], axis=1)
    e = budget.error_components(_moved(budget, labels, 0.5 * right), labels, CENTRE)
    np.testing.assert_allclose(e["lateral"], 0.5, atol=1e-12)
    np.testing.assert_allclose(e["range"], 0.0, atol=1e-12)
    # The car straight ahead shifted to +x is to the right of its ray.
    ahead = budget.Boxes.of([[0.06, 1.6, 15.0]], [[1.5, 1.6, 4.0]], [0.0])
    e = budget.error_components(_moved(budget, ahead, np.array([[0.3, 0.0]])), ahead, CENTRE)
    assert e["lateral"][0] == pytest.approx(0.3) and e["range"][0] == pytest.approx(0.0, abs=1e-12)


def test_height_and_size_errors_and_the_centre_distance(budget):
    labels = _labels(budget)
    loc = labels.location + np.array([0.0, 0.2, 0.0])  # bottoms 0.2 m lower
    dims = labels.dims + np.array([0.2, -0.1, 0.3])  # 0.2 m taller: centres 0.1 m lower
    e = budget.error_components(budget.Boxes(loc, dims, labels.rotation_y), labels, CENTRE)
    np.testing.assert_allclose(e["height"], 0.1, atol=1e-12)
    np.testing.assert_allclose([e["dh"], e["dw"], e["dl"]], [[0.2] * 3, [-0.1] * 3, [0.3] * 3], atol=1e-12)
    np.testing.assert_allclose(e["centre_distance"], 0.1, atol=1e-12)
    assert (e["iou"] < 1.0).all() and (e["iou"] > 0.7).all()


def test_azimuth_error_wraps_around(budget):
    labels = budget.Boxes.of([[2.0, 1.6, 12.0]] * 3, [[1.5, 1.6, 4.0]] * 3, np.deg2rad([-179.0, 10.0, 170.0]))
    fitted = budget.Boxes(labels.location, labels.dims, np.deg2rad([179.0, 5.0, -175.0]))
    e = budget.error_components(fitted, labels, CENTRE)
    np.testing.assert_allclose(e["azimuth"], [-2.0, -5.0, 15.0], atol=1e-9)


def test_one_pixel_limit_is_one_row_at_the_ground_contact(budget):
    """z^2 / (f h) straight ahead, checked against the projection of the contact point."""
    camera = read_kitti_calib(KITTI / "training" / "calib" / "000002.txt").camera()
    f, h = camera.P[1, 1], 1.65
    module = budget
    for z in (10.0, 30.0, 50.0):
        dz = module.one_pixel_range_limit(z, z, focal=f, camera_height=h)
        assert dz == pytest.approx(z * z / (f * h))
        # A ground point (camera y + h) at z and at z + dz: one image row apart, to first order.
        (_, v0), (_, v1) = camera.project(np.array([[0.0, h, z], [0.0, h, z + dz]]))
        assert v0 - v1 == pytest.approx(1.0, rel=2 * dz / z + 0.01)
    # Off to the side the ground-plane range moves by dz r / z.
    assert module.one_pixel_range_limit(30.0, 31.0, focal=f, camera_height=h) == pytest.approx(30 * 31 / (f * h))


def test_perfect_range_turns_a_range_only_failure_into_a_pass(budget):
    labels = _labels(budget)
    u = _ray(labels)
    right = np.stack([u[:, 1], -u[:, 0]], axis=1)
    # Good in everything but range: 1.5 m too far, 5 cm across, 3 deg off, 5 cm too long.
    fitted = _moved(budget, labels, 1.5 * u + 0.05 * right)
    fitted = budget.Boxes(fitted.location, fitted.dims + np.array([0.0, 0.0, 0.05]),
                          fitted.rotation_y + np.deg2rad(3.0))
    d = budget.decompose(fitted, labels, CENTRE)
    assert not d["as fitted"]["iou"].any() and not d["as fitted"]["loc"].any()
    assert d["perfect range"]["iou"].all() and d["perfect range"]["loc"].all()
    for c in ("lateral", "height", "azimuth", "size"):
        assert not d[f"perfect {c}"]["iou"].any(), c
    assert not d["only range wrong"]["iou"].any()
    assert d["only azimuth wrong"]["iou"].all() and d["only lateral wrong"]["loc"].all()
    # Making the range perfect keeps the other errors as they were.
    fixed = budget.replace_components(fitted, labels, CENTRE, ["range"])
    e = budget.error_components(fixed, labels, CENTRE)
    np.testing.assert_allclose(e["range"], 0.0, atol=1e-12)
    np.testing.assert_allclose(e["lateral"], 0.05, atol=1e-12)
    np.testing.assert_allclose(e["azimuth"], 3.0, atol=1e-9)
    # Every component perfect gives the label boxes.
    exact = budget.replace_components(fitted, labels, CENTRE, budget.COMPONENTS)
    for a, b in zip(exact, labels):
        np.testing.assert_allclose(a, b, atol=1e-12)
    with pytest.raises(ValueError, match="unknown"):
        budget.replace_components(fitted, labels, CENTRE, ["depth"])


def test_the_passes_use_kittis_iou_threshold_and_the_papers_metre(budget):
    # The same box moved s along its own length l = 4: IoU (l - s) / (l + s), 0.7 at s = 0.706.
    label = budget.Boxes.of([[0.0, 1.6, 20.0]] * 4, [[1.5, 1.6, 4.0]] * 4, [0.0] * 4)
    s = np.array([0.68, 0.73, 0.98, 1.02])
    fitted = budget.Boxes(label.location + np.stack([s, 0 * s, 0 * s], axis=1), label.dims, label.rotation_y)
    p = budget.passes(fitted, label)
    assert p["iou"].tolist() == [True, False, False, False]
    assert p["loc"].tolist() == [True, True, True, False]


def test_perfect_size_keeps_the_centre(budget):
    labels = _labels(budget)
    fitted = budget.Boxes(labels.location + np.array([0.0, 0.3, 0.0]), labels.dims * 1.2, labels.rotation_y)
    fixed = budget.replace_components(fitted, labels, CENTRE, ["size"])
    np.testing.assert_allclose(fixed.dims, labels.dims)
    np.testing.assert_allclose(fixed.centres(), fitted.centres(), atol=1e-12)


def _write_run(folder: Path, shift: dict[str, float]):
    """Frame records of variants whose boxes are the labels moved ``shift[v]`` m along
    each car's viewing ray (label boxes as detections)."""
    dataset = KittiDataset(KITTI)
    records = FrameRecords(folder, {"detections": {"spec": "gt"}})
    for frame in dataset.frame_ids():
        gt = dataset.labels(frame)
        centre = dataset.calib(frame).camera().center
        cars = [o for o in gt.objects if o.type == "Car"]
        fits = {}
        for variant, s in shift.items():
            loc = np.array([o.location for o in cars]).reshape(-1, 3)
            d = loc[:, [0, 2]] - centre[[0, 2]]
            loc[:, [0, 2]] += s * d / np.linalg.norm(d, axis=1, keepdims=True)
            result = FrameResult(frame, gt.objects, [o.box for o in cars], [o.alpha for o in cars],
                                 np.ones(len(cars)), loc, [o.dims for o in cars], [o.rotation_y for o in cars],
                                 [o.alpha for o in cars])
            fits[variant] = ("", result)
        records.save(frame, fits)
    return sum(o.type == "Car" for f in dataset.frame_ids() for o in dataset.labels(f).objects)


def test_a_run_read_back_from_its_records(budget, tmp_path, capsys):
    n_cars = _write_run(tmp_path / "run" / "fold0", {"coarse+gp": 0.5, "fg": 1.5, "full": 0.0})
    out = tmp_path / "budget.json"
    budget.main([str(tmp_path / "run"), "--root", str(KITTI), "--json", str(out), "--plot", str(tmp_path / "p.png")])
    text = capsys.readouterr().out
    assert "| fg | " in text and "range (+" in text  # fg's failures are decided by range
    run = json.loads(out.read_text())["runs"][str(tmp_path / "run")]
    assert run["detections"] == "gt" and run["labelled_cars"] == n_cars
    summary = {v: run["summaries"][v]["all"] for v in ("coarse+gp", "fg", "full")}
    assert all(s["n"] == n_cars for s in summary.values())  # every label box is a true positive
    fg, full = summary["fg"], summary["full"]
    assert fg["median_range"] == pytest.approx(1.5) and fg["median_abs_lateral"] == pytest.approx(0.0, abs=1e-9)
    assert summary["coarse+gp"]["median_range"] == pytest.approx(0.5) and summary["coarse+gp"]["within_1m"] == 100.0
    assert fg["within_1m"] == 0.0 and fg["decomposition"]["perfect range"]["within_1m"] == 100.0
    assert fg["decomposition"]["perfect azimuth"]["within_1m"] == 0.0
    assert full["within_1m"] == 100.0 and full["iou_0.7"] == 100.0 and full["median_iou"] == pytest.approx(1.0)
    vs = run["versus_reference"]
    assert (vs["fg"]["all"]["gained"], vs["fg"]["all"]["lost"], vs["fg"]["all"]["d_within_1m"]) == (0, n_cars, -100.0)
    assert (vs["full"]["all"]["gained"], vs["full"]["all"]["lost"]) == (0, 0)
    assert vs["full"]["all"]["d_median_abs_range"] == pytest.approx(-0.5)
    bands = sum(run["summaries"]["full"][b]["n"] for b in ("<15 m", "15-25 m", "25-35 m", ">35 m"))
    occ = sum(run["summaries"]["full"][g]["n"] for g in ("occ 0", "occ 1", "occ 2+"))
    trunc = sum(run["summaries"]["full"][g]["n"] for g in ("inside", "truncated"))
    assert bands == occ == trunc == n_cars
    assert len(run["cars"]["full"]["frame"]) == n_cars
    assert (tmp_path / "p.png").stat().st_size > 0


def test_a_run_without_records_is_refused(budget, tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(budget.InputError, match="no frame records"):
        budget.main([str(tmp_path / "empty"), "--root", str(KITTI)])
