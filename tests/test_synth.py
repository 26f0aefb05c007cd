"""Synthetic scene generator: KITTI round trip, labels vs. renderings, per-vertex
visibility vs. depth maps, determinism, no interpenetration."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("embreex")

from wirescene.core.boxes import box_corners, project_points_to_box  # noqa: E402
from wirescene.core.groundplane import rotation_y  # noqa: E402
from wirescene.io.kitti import KittiDataset  # noqa: E402
from wirescene.synth import OCCLUSION_THRESHOLDS, generate_dataset, generate_scene, write_scene  # noqa: E402
from wirescene.synth.layout import CarPlacement, Occluder, polygons_overlap  # noqa: E402

SEED = 3
N = 3


@pytest.fixture(scope="module")
def scenes():
    return [generate_scene(SEED, i) for i in range(N)]


@pytest.fixture(scope="module")
def written(scenes, tmp_path_factory):
    root = tmp_path_factory.mktemp("synth")
    for i, sc in enumerate(scenes):
        write_scene(root, f"{i:06d}", sc)
    return root


def test_kitti_round_trip(scenes, written):
    ds = KittiDataset(written)
    assert ds.frame_ids() == [f"{i:06d}" for i in range(N)]
    for i, sc in enumerate(scenes):
        fid = f"{i:06d}"
        assert ds.image_size(fid) == (1242, 375)
        np.testing.assert_array_equal(ds.image(fid), sc.image)
        np.testing.assert_allclose(ds.camera(fid).P, sc.camera.P, rtol=1e-10)
        labels = ds.labels(fid).objects
        assert len(labels) == len(sc.labels.objects) == len(sc.wireframes["cars"]) >= 1
        for got, want in zip(labels, sc.labels.objects):
            assert got.type == "Car" and got.occluded == want.occluded
            np.testing.assert_allclose(got.box, want.box, atol=0.006)
            np.testing.assert_allclose(got.location, want.location, atol=1e-5)
            np.testing.assert_allclose(got.dims, want.dims, atol=1e-5)
            assert abs(got.rotation_y - want.rotation_y) < 1e-5
        wf = json.loads((written / "training" / "wireframes" / f"{fid}.json").read_text())
        assert set(wf["ground_plane"]) == {"pitch", "roll", "height"}
        assert abs(wf["ground_plane"]["height"] - 1.65) < 1e-9
        for car in wf["cars"]:
            assert len(car["vertices_3d"]) == len(car["vertices_2d"]) == len(car["visibility"]) == 36
            assert set(car["visibility"]) <= {"visible", "self", "other-car", "occluder", "truncated"}
            assert car["n_occluded_not_self"] == sum(r in ("other-car", "occluder") for r in car["visibility"])
        assert (written / "training" / "edges_2" / f"{fid}.png").is_file()


def test_label_boxes_follow_kitti_convention(scenes):
    """Label boxes are the projected, clipped 3D label boxes (KITTI), which contain the
    visible silhouette (kept as ``visible_box``)."""
    n_occluded = 0
    for sc in scenes:
        W, H = sc.camera.image_size
        for lab, car in zip(sc.labels.objects, sc.wireframes["cars"]):
            rows, cols = np.nonzero(sc.object_id == car["scene_object_id"])
            visible = [cols.min(), rows.min(), cols.max(), rows.max()]
            np.testing.assert_array_equal(car["visible_box"], visible)
            proj = project_points_to_box(sc.camera, box_corners(lab.dims, lab.location, rotation_y(lab.rotation_y)))
            np.testing.assert_allclose(lab.box, proj, atol=1e-6)
            assert 0 <= lab.box[0] <= lab.box[2] <= W - 1 and 0 <= lab.box[1] <= lab.box[3] <= H - 1
            # the body's robust extent (cad.mesh.body_extent) contains the silhouette to 2 px,
            # tilted planes (up to a few degrees) add a little
            assert np.all(lab.box[:2] <= np.array(visible[:2]) + 3.0) and np.all(lab.box[2:] >= np.array(visible[2:]) - 3.0)
            # occluded flag follows the documented thresholds on the hidden fraction
            assert lab.occluded == int(np.searchsorted(OCCLUSION_THRESHOLDS, car["occluded_fraction"], side="right"))
            assert 0.0 <= lab.truncated <= 1.0
            n_occluded += car["occluded_fraction"] > 0.3
    assert n_occluded >= 1  # boxes of occluded cars exceed their visible pixels


def test_vertex_visibility_agrees_with_depth_maps(scenes):
    n = {"visible": [0, 0], "blocked": [0, 0], "free": [0, 0]}
    for sc in scenes:
        H, W = sc.depth.shape
        for car in sc.wireframes["cars"]:
            i = car["scene_object_id"]
            uv, vd = np.array(car["vertices_2d"]), np.array(car["vertex_depth"])
            for k, reason in enumerate(car["visibility"]):
                u, v = int(round(uv[k, 0])), int(round(uv[k, 1]))
                if reason == "truncated":
                    assert not (0 <= u < W and 0 <= v < H) or vd[k] <= 0
                    continue
                assert 0 <= u < W and 0 <= v < H
                win = (slice(max(v - 2, 0), v + 3), slice(max(u - 2, 0), u + 3))
                o, d = sc.object_id[win], sc.depth[win]
                tol = 0.3 + 0.02 * vd[k]
                if reason == "visible":
                    # landmarks sit on silhouettes, so look in a 5x5 window
                    n["visible"][0] += bool(np.any((o == i) & (np.abs(d - vd[k]) < tol)))
                    n["visible"][1] += 1
                    n["free"][0] += bool(np.any(d > vd[k] - tol))
                    n["free"][1] += 1
                elif reason in ("other-car", "occluder"):
                    o1, d1 = sc.object_id[v, u], sc.depth[v, u]
                    n_cars = len(sc.wireframes["cars"]) + len(sc.wireframes["hidden_cars"])
                    right_kind = (o1 < n_cars) if reason == "other-car" else (o1 >= n_cars)
                    n["blocked"][0] += bool(o1 >= 0 and o1 != i and d1 < vd[k] - 0.02 and right_kind)
                    n["blocked"][1] += 1
    assert n["visible"][1] > 50 and n["blocked"][1] > 5
    assert n["visible"][0] >= 0.9 * n["visible"][1], n
    assert n["free"][0] >= 0.99 * n["free"][1], n
    assert n["blocked"][0] >= 0.9 * n["blocked"][1], n


def test_no_interpenetration(scenes):
    for sc in scenes:
        wf = sc.wireframes
        cars = [CarPlacement(c["cad_model"], *c["street_xz"], c["azimuth"], tuple(c["dims_hwl"]), c["role"])
                for c in wf["cars"] + wf["hidden_cars"]]
        occs = [Occluder(o["kind"], o["x"], o["z"], tuple(o["size"]), o["yaw"]) for o in wf["occluders"]]
        prints = [c.footprint() for c in cars] + [o.footprint() for o in occs]
        for a in range(len(prints)):
            for b in range(a + 1, len(prints)):
                assert not polygons_overlap(prints[a], prints[b]), (a, b)
        for c in wf["cars"]:
            assert 5.0 <= c["street_xz"][1] <= 50.0


def _files(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_deterministic(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for out, seed in ((a, 11), (b, 11), (c, 12)):
        generate_dataset(out, 2, seed, cars=(2, 4))
    fa, fb, fc = _files(a), _files(b), _files(c)
    assert fa.keys() == fb.keys() and len(fa) == 2 * 5
    assert fa == fb
    assert fa["training/image_2/000000.png"] != fc["training/image_2/000000.png"]
    assert fa["training/label_2/000000.txt"] != fc["training/label_2/000000.txt"]


def test_cli_errors(tmp_path):
    from click.testing import CliRunner

    from wirescene.cli.synth import synth

    r = CliRunner().invoke(synth, [str(tmp_path / "o"), "--scenes", "1", "--cars-per-scene", "5-2"])
    assert r.exit_code == 2 and "A <= B" in r.output
    r = CliRunner().invoke(synth, [str(tmp_path / "o"), "--scenes", "1", "--cars-per-scene", "9" * 23])
    assert r.exit_code == 2 and "B <= 1000" in r.output and not (tmp_path / "o").exists()
    r = CliRunner().invoke(synth, [str(tmp_path / "o"), "--scenes", "1", "--cars-per-scene", "2", "--no-occluders"])
    assert r.exit_code == 0, r.output
    labels = (tmp_path / "o" / "training" / "label_2" / "000000.txt").read_text().splitlines()
    wf = json.loads((tmp_path / "o" / "training" / "wireframes" / "000000.json").read_text())
    assert len(labels) + len(wf["hidden_cars"]) <= 2 and wf["occluders"] == []


def test_cli_writes_a_set_whole_or_not_at_all(tmp_path, monkeypatch):
    import functools

    from click.testing import CliRunner

    import wirescene.synth.generate as generate
    from wirescene.cli.synth import synth

    out = tmp_path / "o"
    args = [str(out), "--cars-per-scene", "2", "--no-occluders"]
    assert CliRunner().invoke(synth, [*args, "--scenes", "2"]).exit_code == 0
    before = _files(out)
    # the set's directory has the permissions of any new directory there (a staging one's are 0o700)
    assert (out / "training").stat().st_mode & 0o777 == (out / "training" / "image_2").stat().st_mode & 0o777
    real = generate.generate_scene

    @functools.wraps(real)
    def interrupted(seed, index, **kwargs):
        if index == 1:
            raise KeyboardInterrupt
        return real(seed, index, **kwargs)

    # an interrupted --overwrite keeps the old set whole and leaves no staging directory
    monkeypatch.setattr(generate, "generate_scene", interrupted)
    r = CliRunner().invoke(synth, [*args, "--scenes", "2", "--seed", "5", "--overwrite"])
    assert r.exit_code != 0
    assert _files(out) == before and sorted(p.name for p in out.iterdir()) == ["training"]
    # an interrupted first run leaves nothing, not even the directories made for it
    r = CliRunner().invoke(synth, [str(tmp_path / "new" / "set"), "--scenes", "2"])
    assert r.exit_code != 0 and not (tmp_path / "new").exists()
    monkeypatch.undo()
    # a finished --overwrite replaces the whole set: no stale scene of the old one is left
    assert CliRunner().invoke(synth, [*args, "--scenes", "1", "--seed", "5", "--overwrite"]).exit_code == 0
    after = _files(out)
    assert sorted(after) == sorted(k for k in before if "000000" in k)
    assert after["training/image_2/000000.png"] != before["training/image_2/000000.png"]
    assert sorted(p.name for p in out.iterdir()) == ["training"]
