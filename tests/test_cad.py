"""CAD reading, canonicalisation, road-car rule and landmarking (tests/data/cad copies of
TORCS meshes; see tests/data/cad/README.md for their origin and licence)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import DATA, assert_close
from wirescene.cad.ac3d import parse_ac3d, read_ac3d
from wirescene.cad.landmarks import annotate, apply_corrections, auto_landmarks, load_corrections
from wirescene.cad.mesh import canonicalize, load_car, road_car_check
from wirescene.core.errors import InputError
from wirescene.core.wireframe import MIRROR, VERTEX_INDEX

CAD = DATA / "cad"
ROAD = ("acura-nsx-sz", "155-DTM", "car1-stock2")
FULL_CAD = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "cad" / "torcs"

MINI_AC = """AC3Db
MATERIAL "m" rgb 1 1 1 amb 1 1 1 emis 0 0 0 spec 0 0 0 shi 0 trans 0
OBJECT world
kids 1
OBJECT group
loc 1 0 0
kids 1
OBJECT poly
name "quad"
loc 0 2 0
numvert 4
0 0 0
1 0 0
1 1 0
0 1 0
numsurf 2
SURF 0x10
mat 0
refs 4
0 0 0
1 0 0
2 0 0
3 0 0
SURF 0x14
mat 0
refs 4
0 0 0
1 0 0
3 0 0
2 0 0
kids 0
"""


@pytest.fixture(scope="module")
def cars():
    return {n: load_car(CAD / f"{n}.acc") for n in ROAD + ("buggy", "baja-bug")}


def test_ac3d_loc_offsets_accumulate_and_surfaces_triangulate():
    m = parse_ac3d(MINI_AC)
    # loc of the group (1, 0, 0) and of the object (0, 2, 0) add up.
    assert_close(m.vertices.min(axis=0), [1, 2, 0])
    assert_close(m.vertices.max(axis=0), [2, 3, 0])
    # polygon: 2 fan triangles; strip of 4: 2 triangles with consistent winding
    assert m.faces.shape == (4, 3)
    normals = np.cross(*(m.vertices[m.faces[:, k]] - m.vertices[m.faces[:, 0]] for k in (1, 2)))
    assert np.all(normals[:, 2] > 0)
    assert m.object_names[-1] == "quad"


def test_ac3d_real_file():
    m = read_ac3d(CAD / "car1-stock2.acc")
    assert 1000 < len(m.vertices) < 5000 and 1000 < len(m.faces) < 10000
    assert m.faces.min() >= 0 and m.faces.max() < len(m.vertices)
    ext = m.vertices.max(axis=0) - m.vertices.min(axis=0)
    assert 4.0 < ext[0] < 5.5 and 1.0 < ext[1] < 1.6 and 1.7 < ext[2] < 2.2  # x length, y up, z width


def test_ac3d_errors(tmp_path):
    with pytest.raises(InputError, match="not an AC3D"):
        parse_ac3d("hello\n")
    bad = tmp_path / "bad.ac"
    bad.write_text(MINI_AC.replace("refs 4\n0 0 0\n1 0 0\n2 0 0\n3 0 0", "refs 4\n0 0 0\n1 0 0\n2 0 0\n9 0 0"))
    with pytest.raises(InputError, match="out of range") as e:
        read_ac3d(bad)
    assert "bad.ac" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(InputError):
        read_ac3d(tmp_path / "missing.acc")
    # a file cut inside an object is an error; one that ends where a kid would begin is not
    # (Speed Dreams' cars declare more kids than they hold, and its loader stops at the end)
    with pytest.raises(InputError, match="unexpected end of file"):
        parse_ac3d(MINI_AC[:MINI_AC.index("SURF 0x14")])
    more_kids = MINI_AC.replace("OBJECT group\nloc 1 0 0\nkids 1", "OBJECT group\nloc 1 0 0\nkids 3")
    assert_close(parse_ac3d(more_kids).vertices, parse_ac3d(MINI_AC).vertices)


@pytest.mark.parametrize("name", ROAD)
def test_canonical_frame(cars, name):
    car = cars[name]
    v = car.vertices
    assert v[:, 1].max() == pytest.approx(0.0, abs=1e-9)  # ground at y = 0, y down
    assert_close(0.5 * (v.min(axis=0) + v.max(axis=0))[[0, 2]], [0, 0], atol=1e-9)
    l, w, h = car.dimensions
    assert l > w > h > 1.0
    # symmetric about z = 0: the mirrored mesh lies on the original (the outer body
    # exactly; interiors such as a stock car's driver seat may be one-sided)
    d, _ = cKDTree(v).query(v * (1, 1, -1))
    assert np.median(d) < 0.01
    outer = np.abs(v[:, 2]) > 0.35 * w
    d, _ = cKDTree(v).query(v[outer] * (1, 1, -1))
    assert np.quantile(d, 0.95) < 0.02
    # front at +x: in the TORCS files the front is at +x already (rear wings at -x)
    assert car.info["rotation"][0] == [1.0, 0.0, 0.0]
    assert car.info["front_margin"] > 0.2


def test_canonicalize_recovers_rotated_and_rescaled_input(cars):
    car = cars["155-DTM"]
    # a Z-up, y-forward, millimetre version of the same car: front at +y, left at -x
    R = np.array([[0, 0, -1], [1, 0, 0], [0, -1, 0]], dtype=float)  # object -> file (proper rotation)
    v_file = (car.vertices @ R.T) * 1000.0 + np.array([10.0, -20.0, 300.0])
    v, f, info = canonicalize(v_file, car.faces)
    assert info["scale"] == 0.001
    assert_close(v, car.vertices, atol=1e-6)


def test_road_car_rule_on_real_files(cars):
    for name in ROAD:
        ok, reason = road_car_check(cars[name])
        assert ok, reason
    ok, reason = road_car_check(cars["buggy"])
    assert not ok and "lower than" in reason
    ok, reason = road_car_check(cars["baja-bug"])
    assert not ok and "clearance" in reason


@pytest.mark.skipif(not FULL_CAD.is_dir(), reason="full TORCS CAD set (../shared/data/cad/torcs) not present")
def test_road_car_rule_on_full_set():
    from wirescene.cad.mesh import list_cad_files

    non_road = {p.stem for p in list_cad_files(FULL_CAD) if not road_car_check(load_car(p))[0]}
    assert non_road == {"buggy", "baja-bug", "car1-ow1"}


@pytest.mark.parametrize("name", ROAD)
def test_landmarks_symmetric_and_plausible(cars, name):
    car = cars[name]
    X = auto_landmarks(car.vertices, car.faces)
    assert X.shape == (36, 3) and np.isfinite(X).all()
    assert_close(X[MIRROR] * (1, 1, -1), X, atol=1e-12)
    i = VERTEX_INDEX
    assert np.all(X[:18, 2] > 0)  # left side
    assert X[i["front_wheel_center_left"], 0] > 0.8 > -0.8 > X[i["rear_wheel_center_left"], 0]
    assert X[i["front_wheel_ground_left"], 1] == 0.0
    wheelbase = X[i["front_wheel_center_left"], 0] - X[i["rear_wheel_center_left"], 0]
    assert 2.2 < wheelbase < 3.2
    # greenhouse order front to back and above the beltline
    xs = X[[i[f"{p}_left"] for p in ("nose_top", "windscreen_bottom", "windscreen_top", "rear_window_top",
                                       "rear_window_bottom", "tail_top")], 0]
    assert np.all(np.diff(xs) < 0)
    assert X[i["windscreen_top_left"], 1] < X[i["windscreen_bottom_left"], 1] < X[i["nose_top_left"], 1]
    # every landmark lies near the mesh surface (within 12 cm; wheels are not in the mesh)
    not_wheel = [k for k, n in enumerate(VERTEX_INDEX) if "wheel" not in n]
    d, _ = cKDTree(car.vertices).query(X[not_wheel])
    assert np.median(d) < 0.12


def test_corrections_applied_with_mirror(tmp_path, cars):
    car = cars["acura-nsx-sz"]
    path = tmp_path / "corr.json"
    path.write_text('{"_comment": "test", "acura-nsx-sz": {"headlight_right": [2.0, -0.5, -0.4]}}')
    corr = load_corrections(path)
    X = annotate(car.vertices, car.faces, name="acura-nsx-sz", corrections=corr)
    assert_close(X[VERTEX_INDEX["headlight_right"]], [2.0, -0.5, -0.4])
    assert_close(X[VERTEX_INDEX["headlight_left"]], [2.0, -0.5, 0.4])
    Y = apply_corrections("other-car", X, corr)
    assert_close(Y, X)
    path.write_text('{"acura-nsx-sz": {"no_such_vertex": [0, 0, 0]}}')
    with pytest.raises(InputError, match="no_such_vertex"):
        load_corrections(path)
    # a car's corrections not an object, a vertex's not three finite numbers: one line naming the file, no traceback
    for text, match in (('{"acura-nsx-sz": [2.0, -0.5, -0.4]}', "must be a JSON object"),
                        ('{"acura-nsx-sz": {"headlight_right": [2.0, NaN, -0.4]}}', "finite numbers, got"),
                        ('{"acura-nsx-sz": {"headlight_right": 2.0}}', "finite numbers, got 2.0")):
        path.write_text(text)
        with pytest.raises(InputError, match=match) as err:
            load_corrections(path)
        assert "corr.json" in str(err.value) and "\n" not in str(err.value)


def test_corrections_not_utf8_or_of_a_long_list_are_one_short_line(tmp_path):
    """A corrections file not of UTF-8 text raised a UnicodeDecodeError (a traceback), and a vertex's list of
    thousands of numbers was quoted whole in the error line."""
    path = tmp_path / "corr.json"
    for data, match in ((b"\xff\xfe{}", "cannot read landmark corrections"),
                        (b'{"acura-nsx-sz": {"headlight_right": [' + b", ".join([b"1.5"] * 5000) + b"]}}",
                         r"finite numbers, got \[1\.5, .*\.\.\.$")):
        path.write_bytes(data)
        with pytest.raises(InputError, match=match) as err:
            load_corrections(path)
        assert "corr.json" in str(err.value) and len(str(err.value)) < 200 + len(str(path))


def test_cad_picture_has_a_key_to_its_colours():
    """Red and orange dots are landmarks on the near and the far side of each view, blue lines
    the wireframe, grey the mesh: the picture says so."""
    from wirescene.cli.cad import draw_car
    from wirescene.core.shape import load_default

    X = load_default().mean
    fig = draw_car(X, np.array([[0, 1, 2]]), X, title="mean wireframe")
    keys = [t.get_text() for legend in [*fig.legends, *(ax.get_legend() for ax in fig.axes)] if legend is not None
            for t in legend.get_texts()]
    assert keys == ["landmark, near side (named)", "landmark, far side", "wireframe edge", "mesh"]


def test_cad_picture_names_its_axes_in_metres_and_keeps_the_landmark_names_apart():
    """Each view's axes say which object axis they are, in metres; no two landmark names of a
    view overlap (the front view's wheel, arch and nose names used to sit on each other)."""
    import itertools

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    from wirescene.cli.cad import draw_car
    from wirescene.core.shape import load_default

    X = load_default().mean
    fig = draw_car(X, np.array([[0, 1, 2]]), X, title="mean wireframe")
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    assert [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes] == [
        ("x: forward (m)", "height above the ground (m)"), ("x: forward (m)", "z: to the car's left (m)"),
        ("z: to the car's left (m)", "height above the ground (m)")]
    for ax in fig.axes:
        names = {t.get_text(): Text.get_window_extent(t, renderer) for t in ax.texts}  # the name, not its line
        assert len(names) >= 9
        for (a, box_a), (b, box_b) in itertools.combinations(names.items(), 2):
            assert not box_a.overlaps(box_b), (ax.get_title(), a, b)


def test_cli_list_and_show(tmp_path):
    from click.testing import CliRunner

    from wirescene.cli.cad import cad

    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(CAD)])
    assert r.exit_code == 0, r.output
    assert "NON-ROAD" in r.output and "buggy" in r.output
    out = tmp_path / "pictures" / "nsx.png"  # its directory made as the picture is written
    r = CliRunner().invoke(cad, ["show", "acura-nsx-sz", "--out", str(out), "--cad-dir", str(CAD)])
    assert r.exit_code == 0, r.output
    assert out.stat().st_size > 10_000
    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(tmp_path / "nope")])
    assert r.exit_code != 0 and isinstance(r.exception, InputError)
    # a folder per car (Speed Dreams' layout) is searched one level down; formats not read are named
    per_car = tmp_path / "per_car"
    (per_car / "nsx").mkdir(parents=True)
    (per_car / "nsx" / "acura-nsx-sz.acc").write_bytes((CAD / "acura-nsx-sz.acc").read_bytes())
    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(per_car)])
    assert r.exit_code == 0 and r.output.startswith("acura-nsx-sz"), r.output
    # a mesh that is no car, or has no finite coordinates, is named with its problem
    import trimesh

    trimesh.creation.box(extents=(10.0, 1.5, 2.0)).export(per_car / "zz_truck.obj")
    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(per_car)])
    assert isinstance(r.exception, InputError) and str(r.exception).startswith(f"{per_car / 'zz_truck.obj'}: ")
    (per_car / "zz_truck.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(per_car)])
    assert isinstance(r.exception, InputError) and "not finite" in str(r.exception) and "zz_truck.obj" in str(r.exception)
    (per_car / "zz_truck.obj").unlink()
    (per_car / "again").mkdir()  # a car is named by its file: two files of one name are refused
    (per_car / "again" / "acura-nsx-sz.acc").write_bytes((CAD / "acura-nsx-sz.acc").read_bytes())
    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(per_car)])
    assert isinstance(r.exception, InputError) and "two meshes named 'acura-nsx-sz'" in str(r.exception)
    (per_car / "again" / "acura-nsx-sz.acc").unlink()
    (per_car / "nsx" / "acura-nsx-sz.acc").rename(per_car / "nsx" / "body.joe")
    r = CliRunner().invoke(cad, ["list", "--cad-dir", str(per_car)])
    assert isinstance(r.exception, InputError) and ".joe (VDrift's format) not read" in str(r.exception)


def test_obj_faces_of_vertex_0_are_refused_and_relative_references_read(tmp_path):
    """OBJ counts vertices from 1 (or back from -1): trimesh read a face's 0 as the last vertex, another mesh
    without a word; a reference counted back from the last vertex is OBJ's and read as the one it names."""
    from wirescene.cad.mesh import read_mesh

    vertices = "v 0 0 0\nv 4 0 0\nv 0 1.5 0\nv 0 0 1.7\n"
    (tmp_path / "zero.obj").write_text(vertices + "f 1 2 3\nf 0 1 2\n")
    with pytest.raises(InputError, match=r"zero\.obj: OBJ line 6: vertex reference 0 \(OBJ counts vertices from 1"):
        read_mesh(tmp_path / "zero.obj")
    (tmp_path / "absolute.obj").write_text(vertices + "f 1 2 3\nf 2 3 4\n")
    (tmp_path / "relative.obj").write_text(vertices + "f -4 -3 -2\nf 2 -2 -1\n")
    for a, b in zip(read_mesh(tmp_path / "absolute.obj"), read_mesh(tmp_path / "relative.obj")):
        assert_close(b, a)


def test_obj_lines_continued_by_a_backslash_are_read_and_checked_whole(tmp_path):
    """A line ending in a backslash goes on at the next (as trimesh reads it): legal OBJ, read as the one-line
    file; a bad reference on a continued line is said at the line where it starts."""
    from wirescene.cad.mesh import read_mesh

    vertices = "v 0 0 0\nv 4 0 0\nv 0 1.5 0\nv 0 0 1.7\n"
    (tmp_path / "plain.obj").write_text(vertices + "f 1 2 3\nf 2 4 3\n")
    (tmp_path / "continued.obj").write_text("v 0 0 \\\n0\nv 4 0 0\nv 0 1.5 0\nv 0 0 1.7\nf 1 2 \\\n3\nf 2 4 3\n")
    for a, b in zip(read_mesh(tmp_path / "plain.obj"), read_mesh(tmp_path / "continued.obj")):
        assert_close(b, a)
    (tmp_path / "bad.obj").write_text(vertices + "f 1 2 \\\n9\n")
    with pytest.raises(InputError, match=r"bad\.obj: OBJ line 5: vertex reference 9 out of range"):
        read_mesh(tmp_path / "bad.obj")
