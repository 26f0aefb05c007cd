"""The pictures (wirescene.io.pictures): what a reader can tell from them, measured on made-up scenes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from conftest import KITTI_ROOT
from wirescene.core.boxes import box_corners
from wirescene.core.groundplane import rotation_y
from wirescene.core.labels import FrameLabels, Label
from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate
from wirescene.core.wireframe import EDGES
from wirescene.io import KittiDataset

# Machado, Oliveira and Fernandes (2009): linear RGB as seen with a full deficiency of one cone type.
_DEFICIENCIES = {
    "deuteranopia": [[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413], [-0.011820, 0.042940, 0.968881]],
    "protanopia": [[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216], [-0.003882, -0.048116, 1.051998]],
    "tritanopia": [[1.255528, -0.076749, -0.178779], [-0.078411, 0.930809, 0.147602], [0.004733, 0.691367, 0.303900]],
}


def _seen(color: str, deficiency: str | None) -> np.ndarray:
    """CIELAB of the colour ``#rrggbb`` as a reader with ``deficiency`` (None: none) sees it."""
    from matplotlib.colors import to_rgb
    from skimage.color import rgb2lab

    c = np.asarray(to_rgb(color))
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    if deficiency is not None:
        linear = np.clip(np.asarray(_DEFICIENCIES[deficiency]) @ linear, 0.0, 1.0)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return rgb2lab(srgb[None, None])[0, 0]


@pytest.fixture(scope="module")
def camera():
    return KittiDataset(KITTI_ROOT).camera("000010")


def _image_box(camera, dims, location, ry):
    uv = camera.project(box_corners(dims, location, rotation_y(ry)))
    return np.clip(np.concatenate([uv.min(axis=0), uv.max(axis=0)]), 0, [1241, 374, 1241, 374])


def _scene(camera, places, *, wireframes=False, heading=0.4):
    """An estimate of a car at each ``(x, z)`` of ``places`` (``heading``: its ``rotation_y``), in
    detection order, scored 0.05, 0.1, ..."""
    from wirescene.core.groundplane import transform
    from wirescene.core.shape import load_default

    dims = np.array([1.5, 1.6, 3.9])
    cars = []
    for j, (x, z) in enumerate(places):
        location = np.array([x, 1.65, z])
        vertices = visible = None
        if wireframes:
            vertices = transform(load_default().mean, location, rotation_y(heading))
            visible = np.arange(36) % 3 != 0
        cars.append(ObjectEstimate(j, _image_box(camera, dims, location, heading), round(0.05 * (j + 1), 2), location,
                                   rotation_y(heading), dims, 0.0, vertices=vertices, visibility=visible))
    return SceneEstimate("full" if wireframes else "coarse", cars[::-1])  # listed out of order: numbers are not


def _drawn(fig):
    """``fig`` laid out by an Agg canvas, and its renderer (to measure what it shows)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _tags(fig, renderer):
    """``{text: window extent}`` of the cars' numbers of the figure."""
    return {t.get_text(): (t.get_bbox_patch() or t).get_window_extent(renderer) for ax in fig.axes
            for t in ax.texts if t.get_text().startswith("#")}


def test_picture_colours_stay_apart_for_colour_blind_readers():
    """Estimate, false car, ground truth and pre-detections differ for readers with any of the
    three dichromacies (the paper's red and green were 12 CIELAB units apart with deuteranopia)."""
    from wirescene.io.pictures import DET_COLOR, EST_COLOR, FALSE_COLOR, GT_COLOR

    for a, b in itertools.combinations((EST_COLOR, FALSE_COLOR, GT_COLOR, DET_COLOR), 2):
        for deficiency in (None, *_DEFICIENCIES):
            distance = np.linalg.norm(_seen(a, deficiency) - _seen(b, deficiency))
            assert distance > 40, (a, b, deficiency, distance)


def test_hidden_parts_differ_by_shape_and_the_key_says_so(camera):
    """Hidden vertices are open dots and the edges between two of them dashed: they are
    told from the visible ones without telling colours apart."""
    from matplotlib.collections import LineCollection, PathCollection
    from matplotlib.colors import to_rgba

    from wirescene.io.pictures import EST_COLOR, overlay

    scene = _scene(camera, [(2.0, 12.0)], wireframes=True)
    ax = overlay(np.zeros((375, 1242, 3), np.uint8), camera, scene, edges=EDGES).axes[0]
    dots = [c for c in ax.collections if isinstance(c, PathCollection)]
    visible, hidden = dots[0], dots[1]
    assert len(visible.get_offsets()) == 24 and len(hidden.get_offsets()) == 12
    assert np.allclose(visible.get_facecolor()[0], to_rgba(EST_COLOR))
    assert np.allclose(hidden.get_facecolor()[0], to_rgba("white"))  # open
    assert np.allclose(hidden.get_edgecolor()[0], to_rgba(EST_COLOR))
    lines = [c for c in ax.collections if isinstance(c, LineCollection)]
    dashed = [c for c in lines if c.get_linestyle()[0][1] is not None]
    hidden_edges = [e for e in EDGES if e[0] % 3 == 0 and e[1] % 3 == 0]
    assert len(dashed) == 1 and len(dashed[0].get_segments()) == len(hidden_edges) > 0
    assert "hidden part" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_overlay_numbers_every_car_inside_the_picture_clear_of_each_other(camera):
    """Fifteen cars, two cut by the image's sides: each gets its number (its line of the label
    file, detection order) and confidence, inside the picture, on none of the other numbers,
    the title or the key."""
    from wirescene.io.pictures import overlay

    places = [(-7.5, 6.0), (8.0, 7.0), *[(x, z) for z in (14.0, 24.0, 40.0) for x in (-7.0, -3.5, 0.0, 3.5)],
              (4.0, 60.0)]
    scene = _scene(camera, places)
    fig = overlay(np.zeros((375, 1242, 3), np.uint8), camera, scene, title="000010  coarse, label boxes",
                  detections=Detections([c.box for c in scene.cars], 1.0, np.nan))
    renderer = _drawn(fig)
    tags = _tags(fig, renderer)
    assert sorted(tags) == sorted(f"#{j + 1} {0.05 * (j + 1):.2f}" for j in range(len(places)))
    inside = fig.bbox
    ax = fig.axes[0]
    others = [ax.get_legend().get_window_extent(renderer),
              next(t for t in ax.texts if t.get_text().startswith("000010")).get_bbox_patch().get_window_extent(renderer)]
    for text, box in tags.items():
        assert inside.x0 - 0.5 <= box.x0 and box.x1 <= inside.x1 + 0.5, text
        assert inside.y0 - 0.5 <= box.y0 and box.y1 <= inside.y1 + 0.5, text
        assert not any(box.overlaps(o) for o in others), text
    for (a, box_a), (b, box_b) in itertools.combinations(tags.items(), 2):
        assert not box_a.shrunk(0.95, 0.95).overlaps(box_b), (a, b)
    key = [t.get_text() for t in ax.get_legend().get_texts()]
    assert key[1] == "#n c: car n (line n of the label file), confidence c"


def test_overlay_and_birds_eye_view_of_a_scene_without_cars_say_so(camera):
    from wirescene.io.pictures import birds_eye, overlay

    empty = SceneEstimate("full", [])
    legend = overlay(np.zeros((375, 1242, 3), np.uint8), camera, empty).axes[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == ["no car estimated"]
    assert "no car estimated" in [t.get_text() for t in birds_eye(empty, camera=camera).axes[0].texts]


def test_birds_eye_view_names_kitti_axes_numbers_the_overlays_cars_and_keeps_its_key_legible(camera):
    """x to the right, z ahead, in metres; each car the number it has in the overlay, by its
    footprint; the key under the axes' label, not over it, however short the axes."""
    from wirescene.io.pictures import birds_eye

    for scene in (SceneEstimate("full", []), _scene(camera, [(-3.0, 10.0), (4.0, 30.0)])):
        fig = birds_eye(scene, gt=[Label("Car", 0, 0, 0.0, [0, 0, 10, 10], [1.5, 1.6, 3.9], [3.0, 1.65, 28.0], 0.0)],
                        camera=camera)
        ax = fig.axes[0]
        assert ax.get_xlabel() == "x: right of the camera (m)" and ax.get_ylabel() == "z: ahead of the camera (m)"
        renderer = _drawn(fig)
        key = fig.legends[0]
        assert not key.get_window_extent(renderer).overlaps(ax.xaxis.label.get_window_extent(renderer))
        assert not key.get_window_extent(renderer).overlaps(ax.get_window_extent(renderer))
        assert fig.bbox.y0 <= key.get_window_extent(renderer).y0  # not cut off by the figure's edge
        labels = [t.get_text() for t in key.get_texts()]
        drawn = ["estimate (#n: car n; a line marks the front)"] if scene.objects else []  # no car, no red entry
        assert labels[:len(drawn) + 1] == [*drawn, "ground truth"]
        assert {"camera", "field of view"} <= set(labels)
    tags = _tags(fig, renderer)
    assert sorted(tags) == ["#1", "#2"]
    near = next(t for t in ax.texts if t.get_text() == "#1")
    assert abs(near.get_position()[1] - 10.0) < 1.0  # by car 1, 10 m ahead


def test_birds_eye_view_numbers_each_car_of_a_dense_row_by_its_own_clear_of_the_others(camera):
    """Two staggered rows of parked cars, as in KITTI 000095 (where the numbers were written over each
    other and over the next row's cars): each number lies by its own car's footprint, inside the
    axes, on no other number and no footprint."""
    from matplotlib.transforms import Bbox

    from wirescene.io.pictures import birds_eye

    places = [(-8.0, z) for z in np.arange(10.0, 60.0, 5.0)] + [(-5.5, z) for z in np.arange(11.5, 60.0, 5.0)]
    scene = _scene(camera, [*places, (4.0, 12.0), (4.0, 20.0)], heading=np.pi / 2)  # along the road
    fig = birds_eye(scene, camera=camera)
    ax = fig.axes[0]
    renderer = _drawn(fig)
    corners = [ax.transData.transform(box_corners(c.dims, c.location, c.R)[:, [0, 2]]) for c in scene.cars]
    feet = [Bbox([uv.min(axis=0), uv.max(axis=0)]) for uv in corners]  # pixels
    tags = _tags(fig, renderer)
    assert sorted(tags) == sorted(f"#{n}" for n in range(1, len(scene.cars) + 1))
    inside = ax.get_window_extent(renderer)
    for text, box in tags.items():
        assert inside.x0 - 0.5 <= box.x0 and box.x1 <= inside.x1 + 0.5 and inside.y0 - 0.5 <= box.y0, text
        assert box.y1 <= inside.y1 + 0.5, text
        assert not any(box.overlaps(foot) for foot in feet), text
        own = feet[int(text[1:]) - 1]
        gap = max(own.x0 - box.x1, box.x0 - own.x1, own.y0 - box.y1, box.y0 - own.y1)
        assert gap < 6, (text, gap)  # pixels: right by its own car
    for (a, box_a), (b, box_b) in itertools.combinations(tags.items(), 2):
        assert not box_a.overlaps(box_b), (a, b)


def test_overlay_draws_the_pre_detections_the_fit_dropped_apart(camera):
    from matplotlib.patches import Rectangle

    from wirescene.core.types import dropped_detections, fitted_detections
    from wirescene.io.pictures import DET_COLOR, DROPPED_COLOR, overlay

    scene = _scene(camera, [(-3.0, 10.0), (4.0, 30.0)])
    boxes = [scene.cars[0].box, [600.0, 150.0, 640.0, 180.0], scene.cars[1].box]
    scene = SceneEstimate("coarse", [ObjectEstimate(j, np.asarray(boxes[j]), c.score, c.location, c.R, c.dims, 0.0)
                                     for j, c in zip((0, 2), scene.cars)])
    dets = Detections(boxes, 1.0, np.nan, "bank")
    ax = overlay(np.zeros((375, 1242, 3), np.uint8), camera, scene, detections=fitted_detections(dets, scene),
                 dropped=dropped_detections(dets, scene)).axes[0]
    rectangles = {(r.get_x(), r.get_y()): r for r in ax.patches if isinstance(r, Rectangle)}
    assert rectangles[(600.0, 150.0)].get_linestyle() == ":"
    assert np.allclose(rectangles[(600.0, 150.0)].get_edgecolor()[:3], np.array([0xD9] * 3) / 255)
    assert DROPPED_COLOR != DET_COLOR and len(rectangles) == 3
    assert [t.get_text() for t in ax.get_legend().get_texts()][-2:] == ["pre-detection",
                                                                       "pre-detection the fit dropped"]


def test_the_dropped_pre_detections_and_their_key_stand_out_on_a_bright_picture(camera):
    """The light grey of a dropped pre-detection, drawn on a white image (a bright sky, a
    white wall) and shown in the key's light box, keeps a dark rim: the box and its key's
    sample are seen (they were grey on white, 1.4:1, the key's sample all but blank)."""
    from wirescene.io.pictures import overlay

    fig = overlay(np.full((375, 1242, 3), 255, np.uint8), camera,
                  dropped=Detections([[600.0, 150.0, 640.0, 180.0]], 1.0, np.nan))
    renderer = _drawn(fig)
    pixels = np.asarray(fig.canvas.buffer_rgba())[..., :3].mean(axis=-1)  # rows from the top, as the image's

    def darkest(bbox) -> float:
        rows = slice(int(pixels.shape[0] - bbox.y1) - 1, int(pixels.shape[0] - bbox.y0) + 2)
        return float(pixels[rows, int(bbox.x0) - 1:int(bbox.x1) + 2].min())

    box = fig.axes[0].patches[0].get_window_extent(renderer)
    assert darkest(box) < 110  # the box's line, on white
    sample = fig.axes[0].get_legend().legend_handles[0].get_window_extent(renderer)
    assert darkest(sample) < 110  # its sample in the key


def test_a_nearer_cars_wireframe_covers_a_farther_cars_dots(camera):
    """Cars are drawn far to near, each in a layer of its own: a far car's vertices are not
    drawn over a nearer car's edges (they were: every dot above every edge, so that a car
    behind seemed to have its vertices on the car in front)."""
    from matplotlib.collections import LineCollection, PathCollection

    from wirescene.io.pictures import overlay

    scene = _scene(camera, [(2.0, 12.0), (2.6, 20.0)], wireframes=True)
    ax = overlay(np.zeros((375, 1242, 3), np.uint8), camera, scene, edges=EDGES).axes[0]
    far, near = ax.collections[:4], ax.collections[4:]  # drawn far to near: edges (solid, dashed), dots
    assert [type(c) for c in far] == [type(c) for c in near] == [LineCollection] * 2 + [PathCollection] * 2
    assert max(c.get_zorder() for c in far) < min(c.get_zorder() for c in near)
    assert all(c.get_zorder() > e.get_zorder() for c in near[2:] for e in near[:2])  # a car's dots on its edges
    assert max(c.get_zorder() for c in ax.collections) < min(t.get_zorder() for t in ax.texts)  # the numbers on top


def test_the_key_says_which_face_the_cross_of_a_box_marks(camera):
    """Every 3D box carries a cross on its front face; the key says so by the boxes drawn (a
    crossed box is read as an ignored one elsewhere), also where the estimates are wireframes."""
    from wirescene.io.pictures import overlay

    image = np.zeros((375, 1242, 3), np.uint8)
    gt = [Label("Car", 0, 0, 0.0, [0, 0, 10, 10], [1.5, 1.6, 3.9], [3.0, 1.65, 28.0], 0.0)]

    def key(scene):
        return [t.get_text() for t in overlay(image, camera, scene, gt=gt, edges=EDGES).axes[0]
                .get_legend().get_texts()]

    assert key(None) == ["ground truth (a cross marks the front)"]
    wireframes = key(_scene(camera, [(2.0, 12.0)], wireframes=True))
    assert wireframes[0] == "estimate" and "ground truth (a cross marks the front)" in wireframes
    boxes = key(_scene(camera, [(2.0, 12.0)]))
    assert boxes[0] == "estimate (a cross marks the front)" and "ground truth" in boxes


def test_the_overlay_draws_the_shared_ground_plane_under_the_cars(camera):
    """A `+gp` estimate's one ground plane (every car stands on it) is drawn as a grid under the cars, its key
    saying the grid's spacing; an estimate whose cars stand on planes of their own draws none."""
    from dataclasses import replace

    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba

    from wirescene.core.groundplane import point_on_plane
    from wirescene.io.pictures import GROUND_COLOR, overlay

    image = np.zeros((375, 1242, 3), np.uint8)
    own = _scene(camera, [(2.0, 12.0), (-3.0, 20.0)])
    pitched = [replace(o, pitch=0.02) for o in own.objects]
    shared = replace(own, variant="coarse+gp", shared_plane=True, objects=pitched)

    def grid_and_key(scene):
        ax = overlay(image, camera, scene).axes[0]
        grid = [c for c in ax.collections if isinstance(c, LineCollection)
                and np.allclose(c.get_colors()[0], to_rgba(GROUND_COLOR))]
        return grid, [t.get_text() for t in ax.get_legend().get_texts()], ax

    grid, key, ax = grid_and_key(shared)
    assert len(grid) == 1 and "ground plane: a line every 10 m ahead, 5 m aside" in key
    cars = [c for c in ax.collections if isinstance(c, LineCollection) and c is not grid[0]]
    assert grid[0].get_zorder() < min(c.get_zorder() for c in cars)  # under the cars
    # the line across the road 10 m ahead lies where the pitched plane projects, not on the level road
    ahead = camera.project(point_on_plane(np.array([-10.0, 10.0]), np.array([10.0, 10.0]), 0.02, 0.0))
    assert any(np.allclose(segment, ahead, atol=1e-6) for segment in grid[0].get_segments())
    grid, key, _ = grid_and_key(own)
    assert grid == [] and not any(k.startswith("ground plane") for k in key)


def _rectangles(ax) -> dict:
    """``{(x, y): (line style, edge colour)}`` of the boxes drawn on ``ax``."""
    from matplotlib.patches import Rectangle

    return {(r.get_x(), r.get_y()): (r.get_linestyle(), tuple(r.get_edgecolor())) for r in ax.patches
            if isinstance(r, Rectangle)}


def test_draw_tells_the_boxes_the_fit_dropped_apart_as_fit_does(camera):
    """``wirescene.draw(..., boxes=...)`` draws a box the fit of its scene dropped (one of
    ``scene.detections`` with no car) dotted grey, as ``wirescene fit``'s overlay does; a box
    of our own pre-detection is found among them once clipped to the image, as the fit clips
    it; a box the fit never saw stays dashed yellow."""
    from matplotlib.colors import to_rgba

    import wirescene
    from wirescene.core.types import dropped_detections, fitted_detections
    from wirescene.io.pictures import DET_COLOR, DROPPED_COLOR, overlay

    cars = _scene(camera, [(-3.0, 10.0), (4.0, 30.0)]).cars
    boxes = [cars[0].box, [600.0, 150.0, 640.0, 180.0], cars[1].box, [0.0, 200.0, 40.0, 240.0]]
    fitted = Detections(boxes, 0.6, 0.0, "bank")
    scene = SceneEstimate("coarse", [ObjectEstimate(j, np.asarray(boxes[j]), c.score, c.location, c.R, c.dims, 0.0)
                                     for j, c in zip((0, 2), cars)], detections=fitted)
    image = np.zeros((375, 1242, 3), np.uint8)
    # the scene's own boxes: the picture of `wirescene fit`
    ax = wirescene.draw(image, camera, scene, boxes=scene.detections).axes[0]
    told = overlay(image, camera, scene, detections=fitted_detections(fitted, scene),
                   dropped=dropped_detections(fitted, scene)).axes[0]
    assert _rectangles(ax) == _rectangles(told)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [t.get_text() for t in told.get_legend().get_texts()]
    dotted, dashed = (":", to_rgba(DROPPED_COLOR)), ("--", to_rgba(DET_COLOR))
    assert [_rectangles(ax)[tuple(b[:2])] for b in boxes] == [dashed, dotted, dashed, dotted]
    assert [t.get_text() for t in ax.get_legend().get_texts()][-2:] == ["pre-detection", "pre-detection the fit dropped"]
    # the detector's boxes before the fit clipped them, and one the fit never saw
    found = Detections([[-30.0, 200.0, 40.0, 240.0], boxes[1], [900.0, 150.0, 960.0, 190.0], boxes[2]], 0.6, 0.0)
    drawn = _rectangles(wirescene.draw(image, camera, scene, boxes=found).axes[0])
    assert [drawn[tuple(b[:2])] for b in found.boxes.tolist()] == [dotted, dotted, dashed, dashed]
    # a scene that does not say which boxes it was fitted to: every box dashed, as before
    bare = SceneEstimate("coarse", scene.objects)
    assert set(_rectangles(wirescene.draw(image, camera, bare, boxes=found).axes[0]).values()) == {dashed}


def test_the_key_says_what_the_number_after_a_car_is(camera, tmp_path, monkeypatch):
    """A calibrated confidence, or (``eval --raw-scores``) the pre-detection's score: the key
    of the overlay says which, in the report's gallery too."""
    import functools

    from click.testing import CliRunner

    import wirescene.eval.report as report
    from wirescene.cli.main import main
    from wirescene.io.pictures import overlay

    scene = _scene(camera, [(2.0, 12.0)])
    image = np.zeros((375, 1242, 3), np.uint8)
    key = [t.get_text() for t in overlay(image, camera, scene, score_name="pre-detection score").axes[0]
           .get_legend().get_texts()]
    assert key[1] == "#n c: car n (line n of the label file), pre-detection score c"
    keys = []

    @functools.wraps(report.overlay)
    def keeping_the_key(*args, **kwargs):
        fig = overlay(*args, **kwargs)
        keys.append([t.get_text() for t in fig.axes[0].get_legend().get_texts()])
        return fig

    monkeypatch.setattr(report, "overlay", keeping_the_key)
    for raw, said in ((["--raw-scores"], "pre-detection score c"), ([], "confidence c")):
        keys.clear()
        r = CliRunner().invoke(main, [str(a) for a in ("eval", KITTI_ROOT, "--variant", "coarse", "--frames", "000010",
                                                       "--particles", 5, "--workers", 1, *raw, "--report",
                                                       tmp_path / f"report{len(raw)}")])
        assert r.exit_code == 0, r.output + r.stderr
        tags = [k for frame in keys for k in frame if k.startswith("#n c:")]
        assert tags and all(k.endswith(f"), {said}") for k in tags), keys
        assert f"with its {said[:-2]}" in (tmp_path / f"report{len(raw)}" / "index.html").read_text()


def test_pr_curve_counts_the_cars_of_its_ap(tmp_path, monkeypatch):
    """An AP over 11 cars is not one over thousands: the key counts them."""
    import wirescene.io.pictures as pictures
    from wirescene.predetect.ap import plot_pr

    drawn = []
    monkeypatch.setattr(pictures, "save_figure", lambda fig, path, **kw: drawn.append(fig) or path)
    result = {"recall": np.linspace(0, 1, 5), "precision": np.ones(5), "ap": 0.992, "n_gt": 11}
    plot_pr({"detector bank": result}, tmp_path / "pr.png", title="IoU 0.5")
    assert [t.get_text() for t in drawn[0].axes[0].get_legend().get_texts()] == ["detector bank (AP 99.2%, 11 cars)"]


def _marks(fig) -> dict:
    """What an overlay or bird's-eye view marks: ``{"tags": car tags, "missed": count, "key": key texts}``."""
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    legend = fig.axes[0].get_legend() or fig.legends[0]
    return {"tags": sorted(t for t in texts if t.startswith("#")), "missed": texts.count("missed"),
            "key": [t.get_text() for t in legend.get_texts()]}


def _judged_scene(camera):
    """Cars #1 on a labelled car, #2 on a DontCare region, #3 on a labelled car but from a viewpoint
    160 deg off its; a fourth labelled car without an estimate. ``(scene, labels)``."""
    scene = _scene(camera, [(-3.0, 10.0), (5.0, 25.0), (3.0, 16.0)])
    boxes = np.array([c.box for c in scene.cars])
    alpha = np.array([c.alpha for c in scene.cars])
    scene.detections = Detections(boxes, [0.9, 0.8, 0.7], alpha + np.array([0.0, 0.0, np.deg2rad(160)]), "bank")

    def label(type_, box, car):
        return Label(type_, 0.0, 0, car.alpha, box, car.dims, car.location, car.rotation_y)

    far = _scene(camera, [(-6.0, 40.0)]).cars[0]
    labels = [label("Car", boxes[0], scene.cars[0]), label("DontCare", boxes[1], scene.cars[1]),
              label("Car", boxes[2], scene.cars[2]), label("Car", _image_box(camera, far.dims, far.location, 0.4), far)]
    return scene, labels


def test_the_pictures_mark_the_false_cars_and_the_missed_labelled_cars_as_the_evaluation_counts_them(camera):
    """Where labels are drawn beside a fit, a car on no labelled car (a DontCare region is none)
    or on one from a viewpoint over 45 deg off is violet and tagged ``false`` (``false view``), a
    labelled car of no true positive dashed and tagged ``missed``, in both views, each mark in
    the key only where drawn; they are :func:`evaluate`'s false positives and missed cars."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba

    from wirescene.eval.metrics import evaluate
    from wirescene.eval.runner import frame_result
    from wirescene.io.pictures import FALSE_COLOR, GT_COLOR, birds_eye, overlay

    scene, labels = _judged_scene(camera)
    image = np.zeros((375, 1242, 3), np.uint8)
    gt = [g for g in labels if g.type == "Car"]  # as the pictures' callers draw them
    fig = overlay(image, camera, scene, gt=gt, detections=scene.detections)
    marks = _marks(fig)
    assert marks["tags"] == ["#1 0.05", "#2 0.10 false", "#3 0.15 false view"]
    assert marks["missed"] == 2  # the car of the wrong viewpoint is no true positive either
    assert {"#n c false: no labelled car of its own (IoU > 0.5)", "#n c false view: viewpoint > 45° off its car",
            "missed: a labelled car without a true positive"} <= set(marks["key"])
    lines = [c for c in fig.axes[0].collections if isinstance(c, LineCollection)]
    violet = [c for c in lines if np.allclose(c.get_color()[0], to_rgba(FALSE_COLOR))]
    assert len(violet) == 4  # the boxes (edges and cross) of cars #2 and #3
    dashed = [c for c in lines if np.allclose(c.get_color()[0], to_rgba(GT_COLOR)) and c.get_linestyle()[0][1]]
    assert len(dashed) == 4  # the boxes of the two missed cars
    # the evaluation, of the record it makes of the same fit and the frame's every label line
    record = frame_result("f", FrameLabels(labels), scene.detections, scene)
    report = evaluate([record])
    found = {r.det_index for r in report.records}
    assert {f"#{d + 1}" for d in range(record.n_detections) if d not in found} == {"#2", "#3"}
    assert {id(labels[r.gt_index]) for r in report.records} == {id(gt[0])}  # the other two cars missed
    bev = birds_eye(scene, gt=gt, camera=camera)
    marks = _marks(bev)
    assert marks["tags"] == ["#1", "#2 false", "#3 false view"] and marks["missed"] == 2
    assert {"#n false: no labelled car of its own (IoU > 0.5)", "missed labelled car", "found: estimate to its car",
            "view off: estimate to its car"} <= set(marks["key"])
    links = [line for line in bev.axes[0].lines if line.get_color() == "#404040"]
    assert sorted(line.get_linestyle() for line in links) == ["-", "-."]  # #1 to its car; #3, its view off
    renderer = _drawn(bev)
    assert bev.bbox.x0 <= bev.legends[0].get_window_extent(renderer).x0  # the longer key stays inside
    assert bev.legends[0].get_window_extent(renderer).x1 <= bev.bbox.x1


def test_without_labels_or_without_a_fault_the_pictures_mark_nothing(camera):
    """No labels drawn, or an estimate that says not which pre-detections it was fitted to: the
    pictures are as before; every car found and none missed: no mark, no key entry of one."""
    from wirescene.io.pictures import birds_eye, overlay

    scene, labels = _judged_scene(camera)
    image = np.zeros((375, 1242, 3), np.uint8)
    gt = [g for g in labels if g.type == "Car"]
    bare = SceneEstimate("coarse", scene.objects)  # no detections: not judged
    for estimate, drawn in ((scene, None), (bare, gt)):  # None: no labels ([]: labelled without cars)
        for fig in (overlay(image, camera, estimate, gt=drawn), birds_eye(estimate, gt=drawn, camera=camera)):
            marks = _marks(fig)
            assert not any("false" in t for t in marks["tags"] + marks["key"]) and marks["missed"] == 0
            assert not any("missed" in k or "found" in k for k in marks["key"])
    right = SceneEstimate("coarse", scene.cars[:1], detections=scene.detections)
    for fig in (overlay(image, camera, right, gt=gt[:1]), birds_eye(right, gt=gt[:1], camera=camera)):
        marks = _marks(fig)
        assert marks["missed"] == 0 and not any("false" in t or "missed" in t for t in marks["tags"] + marks["key"])


def test_the_false_and_missed_cars_of_a_real_fit_are_those_the_evaluation_counts():
    """A real frame fitted from our own pre-detection (the detector bank's boxes): the cars the
    overlay tags ``false`` are the evaluation's outputs that are no true positive, its ``missed``
    labelled cars those of no true positive (the record indexes every label line, the picture
    the cars it draws), and the frame has some of each."""
    import wirescene
    from wirescene.core.matching import match_estimate
    from wirescene.eval.metrics import evaluate
    from wirescene.eval.runner import frame_result
    from wirescene.io.pictures import overlay

    dataset = KittiDataset(KITTI_ROOT)
    image, camera, labels = dataset.image("000010"), dataset.camera("000010"), dataset.labels("000010")
    scene = wirescene.fit(image, camera, None, variant="coarse", particles=20)  # None: the bank's boxes
    report = evaluate([frame_result("000010", labels, scene.detections, scene, camera=camera)])
    true = {r.det_index for r in report.records}
    false = {f"#{d + 1}" for d in range(len(scene.cars)) if d not in true}
    cars = labels.of_type("Car")
    missed = {id(g) for g in cars} - {id(labels.objects[r.gt_index]) for r in report.records}
    assert false and missed and len(cars) < len(labels.objects)  # something to mark; DontCare lines besides the cars
    marks = _marks(overlay(image, camera, scene, gt=cars, detections=scene.detections, edges=EDGES))
    assert {t.split()[0] for t in marks["tags"] if "false" in t} == false
    assert marks["missed"] == len(missed) == len(cars) - report["all"]["n_tp"]
    assert {id(cars[g]) for g in match_estimate(scene, cars).missed} == missed


def test_a_frame_labelled_without_cars_marks_every_car_false_and_no_labels_mark_nothing(camera):
    """Labels of no car (a frame of DontCare regions only: the report's gallery shows such a frame
    as its worst, 'n of the n cars output false') make every car false in the pictures as in the
    evaluation; no labels at all (``gt=None``) judge nothing (an empty list judged nothing either)."""
    from wirescene.eval.metrics import evaluate
    from wirescene.eval.runner import frame_result
    from wirescene.io.pictures import birds_eye, overlay

    scene, labels = _judged_scene(camera)
    image = np.zeros((375, 1242, 3), np.uint8)
    dontcare = [g for g in labels if g.type == "DontCare"]
    assert evaluate([frame_result("f", FrameLabels(dontcare), scene.detections, scene)]).records == []
    for fig in (overlay(image, camera, scene, gt=[]), birds_eye(scene, gt=[], camera=camera)):
        assert [t.split()[-1] for t in _marks(fig)["tags"]] == ["false"] * 3
    for fig in (overlay(image, camera, scene), birds_eye(scene, gt=None, camera=camera)):
        assert not any("false" in t for t in _marks(fig)["tags"] + _marks(fig)["key"])


def test_a_text_is_measured_once_in_each_font():
    """The tags' and the key's texts are measured once (a picture measured its key's every entry and
    each 'missed' tag again: overlay and bird's-eye view 1.5x slower on a crowded frame), but again
    in another font."""
    from matplotlib import rc_context

    from wirescene.io.pictures import _text_width, text_size

    _text_width.cache_clear()
    first = text_size("missed", 7, 1.0, 0.2)
    assert text_size("missed", 7, 1.0, 0.2) == first and _text_width.cache_info().hits == 1
    with rc_context({"font.family": "monospace"}):
        assert text_size("missed", 7, 1.0, 0.2) != first


def _occluded_car(camera, *, mask: int | None | str = "band"):
    """A car cut by the image's right side whose vertices are hidden by each thing that can hide one:
    the car itself, the border, another car (three vertices said so) and the occluder mask of the
    bottom 40%, the car's ``occluder_mask`` (``mask``: another index or None). ``(car, uv (36, 2))``."""
    from wirescene.core.groundplane import transform
    from wirescene.core.shape import load_default
    from wirescene.core.wireframe import FACES
    from wirescene.infer.likelihood import outside_image
    from wirescene.infer.masks import mask_hidden, occluder_masks
    from wirescene.infer.occlusion import hidden_reasons, self_occlusion

    band = int(np.flatnonzero((occluder_masks() == [0.0, 0.6, 1.0, 1.0]).all(1))[0])
    mask = band if mask == "band" else mask
    dims, location = np.array([1.5, 1.6, 3.9]), np.array([6.5, 1.65, 9.0])
    vertices = transform(load_default().mean, location, rotation_y(0.3))
    uv = camera.project(vertices)
    own, border = self_occlusion(vertices, FACES, camera.center), outside_image(camera, uv)
    other = np.zeros(36, bool)
    other[np.flatnonzero(~own & ~border & ~mask_hidden(uv, band))[:3]] = True
    reasons = hidden_reasons(own, truncated=border, other_car=other, occluder=mask_hidden(uv, band))
    car = ObjectEstimate(0, _image_box(camera, dims, location, 0.3), 0.5, location, rotation_y(0.3), dims, 0.0,
                         vertices=vertices, hidden_by=reasons, occluder_mask=mask)
    return car, uv


def _marker(collection) -> str:
    """The marker of a scatter's ``collection`` (of those the overlay draws)."""
    from matplotlib.markers import MarkerStyle

    path = collection.get_paths()[0]
    for m in ("o", "x", "s", "<", ">", "^", "v"):
        style = MarkerStyle(m)
        own = style.get_path().transformed(style.get_transform())
        if own.vertices.shape == path.vertices.shape and np.allclose(own.vertices, path.vertices):
            return m
    raise AssertionError("an unknown marker")


def test_the_overlay_marks_each_hidden_vertex_by_what_hides_it(camera):
    """A fitted car's hidden vertex is marked by what hides it, by shape (colour is the car's
    verdict): a faint ring the car itself, an x another car, an open square the occluder mask, a
    triangle pointing out at the image's edge the border (off the picture, it was not drawn at
    all); the key lists the marks drawn, no others (all hidden vertices were one open dot)."""
    from matplotlib.collections import PathCollection
    from matplotlib.colors import to_rgba

    from wirescene.io.pictures import EST_COLOR, HIDDEN_MARKS, overlay

    car, uv = _occluded_car(camera)
    reasons = car.hidden_by
    assert {"self", "truncated", "other-car", "occluder", "visible"} == set(reasons)
    ax = overlay(np.zeros((375, 1242, 3), np.uint8), camera, SceneEstimate("full", [car]), edges=EDGES).axes[0]
    drawn = {}
    for c in ax.collections:
        if isinstance(c, PathCollection) and len(c.get_offsets()):
            drawn.setdefault(_marker(c), []).append(c)
    dots = drawn.pop("o")
    filled = [c for c in dots if len(c.get_facecolor()) and np.allclose(c.get_facecolor()[0], to_rgba(EST_COLOR))]
    ring = [c for c in dots if c not in filled]
    assert len(filled) == len(ring) == 1 and np.allclose(filled[0].get_offsets(), uv[reasons == "visible"])
    assert np.allclose(ring[0].get_offsets(), uv[reasons == "self"])
    assert not np.any(ring[0].get_facecolor()[:, 3])  # no face: faint
    assert np.allclose(drawn["x"][0].get_offsets(), uv[reasons == "other-car"])
    assert np.allclose(drawn["s"][0].get_offsets(), uv[reasons == "occluder"])
    assert np.allclose(drawn["s"][0].get_facecolor()[0], to_rgba("white"))
    # off the right side: at the edge, inside the picture, at the height it left at, pointing right
    edge = drawn.pop(">")[0].get_offsets()
    assert set(drawn) == {"x", "s"} and len(edge) == (reasons == "truncated").sum() > 0
    assert np.all((edge[:, 0] > 1230) & (edge[:, 0] < 1242))
    assert np.allclose(np.sort(edge[:, 1]), np.sort(uv[reasons == "truncated", 1]))
    key = [t.get_text() for t in ax.get_legend().get_texts()]
    assert [k for k in key if k.startswith(("hidden", "outside"))] == [m[3] for m in HIDDEN_MARKS.values()]
    alone = ObjectEstimate(0, car.box, 0.5, car.location, car.R, car.dims, 0.0, vertices=car.vertices,
                           hidden_by=np.where(reasons == "visible", "visible", "self"))  # only the car itself hides
    key = [t.get_text() for t in overlay(np.zeros((375, 1242, 3), np.uint8), camera, SceneEstimate("full", [alone]),
                                         edges=EDGES).axes[0].get_legend().get_texts()]
    assert [k for k in key if k.startswith(("hidden", "outside"))] == ["hidden by the car itself"]


def test_the_overlay_hatches_the_occluder_mask_the_fit_chose(camera):
    """The region of the car's projected box that the occluder mask the fit chose covers (the
    vertices in it are those the mask hides) is drawn lighter and hatched, nothing else changes;
    a car without a mask (0, or a variant without one: None) gets none."""
    from wirescene.core.occluders import mask_box
    from wirescene.infer.masks import mask_hidden
    from wirescene.io.pictures import overlay

    def pixels(mask):
        car = _occluded_car(camera, mask=mask)[0]
        fig = overlay(np.zeros((375, 1242, 3), np.uint8), camera, SceneEstimate("full", [car]), edges=EDGES)
        hatched = [p for p in fig.axes[0].patches if p.get_hatch()]
        _drawn(fig)
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int), hatched

    car, uv = _occluded_car(camera)
    u0, v0, u1, v1 = mask_box(uv, car.occluder_mask)
    inside = (uv[:, 0] >= u0) & (uv[:, 0] <= u1) & (uv[:, 1] >= v0) & (uv[:, 1] <= v1)
    assert np.array_equal(inside, mask_hidden(uv, car.occluder_mask)) and inside.any() and not inside.all()
    with_mask, hatched = pixels(car.occluder_mask)
    assert len(hatched) == 1 and np.allclose(hatched[0].get_bbox().bounds, (u0, v0, u1 - u0, v1 - v0))
    for none in (0, None):
        without, hatched = pixels(none)
        assert not hatched
        changed = np.any(with_mask != without, axis=2)
        rows, cols = np.nonzero(changed)
        assert rows.min() >= v0 - 1 and rows.max() <= v1 + 1 and cols.min() >= u0 - 1  # only in the region
        region = changed[int(np.ceil(v0)):int(v1), int(np.ceil(u0)):1242]
        assert region.mean() > 0.5  # lighter all over, but where the car's lines lie on it
        assert np.all(with_mask[changed] >= without[changed])


def test_the_key_lists_the_estimates_red_only_where_a_red_car_is_drawn(camera):
    """Every car counted false (a frame labelled without cars): violet, and neither view's key
    lists the red estimate; the front's mark is still said, by the first car entry."""
    from wirescene.io.pictures import birds_eye, overlay

    scene, _ = _judged_scene(camera)
    image = np.zeros((375, 1242, 3), np.uint8)
    overlay_key = _marks(overlay(image, camera, scene, gt=[]))["key"]
    assert not any(k.startswith("estimate") for k in overlay_key)
    assert overlay_key[1] == "#n c false: no labelled car of its own (IoU > 0.5) (a cross marks the front)"
    bev_key = _marks(birds_eye(scene, gt=[], camera=camera))["key"]
    assert not any(k.startswith("estimate") for k in bev_key)
    assert bev_key[0] == "#n false: no labelled car of its own (IoU > 0.5) (#n: car n; a line marks the front)"
    assert _marks(overlay(image, camera, scene))["key"][0] == "estimate (a cross marks the front)"  # not judged: red


def test_the_pictures_draw_the_labels_the_evaluation_counts_as_cars():
    """The labels drawn beside a fit are the evaluation's cars (``CAR_TYPES``, its matching's
    one definition), not a type spelt again where the pictures are made."""
    import re
    from pathlib import Path

    import wirescene

    root = Path(wirescene.__file__).parent
    spelt = []
    for name in ("api.py", "cli/main.py", "eval/predict.py", "eval/report.py", "io/outputs.py", "io/pictures.py"):
        for n, line in enumerate((root / name).read_text().splitlines(), 1):
            if re.search(r'of_type\("Car"|type\s*==\s*"Car"', line):
                spelt.append(f"{name}:{n}")
    assert not spelt


def test_the_occluder_masks_hatching_lies_under_the_pre_detections_boxes(camera):
    """The hatched region of a car's occluder mask lies over the ground's grid but under the
    pre-detections' dashed boxes (which it striped red and veiled where they cross it) and the
    cars, as its docstring says."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgb

    from wirescene.io.pictures import GROUND_COLOR, overlay

    car, _ = _occluded_car(camera)
    scene = SceneEstimate("full", [car], shared_plane=True)
    detections, dropped = Detections([car.box], 0.9, 0.0), Detections([car.box + [-8, -8, 8, 8]], 0.2, 0.0)
    ax = overlay(np.zeros((375, 1242, 3), np.uint8), camera, scene, detections=detections, dropped=dropped,
                 edges=EDGES).axes[0]
    (hatch,) = [p for p in ax.patches if p.get_hatch()]
    boxes = [p for p in ax.patches if not p.get_hatch()]
    grid = [c for c in ax.collections if isinstance(c, LineCollection)
            and np.allclose(c.get_color()[0][:3], to_rgb(GROUND_COLOR))]
    assert len(boxes) == 2 and grid
    assert max(c.get_zorder() for c in grid) < hatch.get_zorder() < min(p.get_zorder() for p in boxes)


def test_a_vertex_outside_the_image_points_the_way_the_axes_show_it_and_needs_no_image_size(camera):
    """The triangles of vertices outside the image point where the vertex lies as the axes show
    it (an upright axes, as ``draw_wireframe``'s own example, turns ``^`` and ``v``), and a camera
    without an image size (``Camera(P)``) takes the axes' view as the picture: it raised a
    TypeError."""
    from matplotlib.collections import PathCollection

    from wirescene.core.camera import Camera
    from wirescene.core.groundplane import transform
    from wirescene.core.shape import load_default
    from wirescene.core.wireframe import FACES
    from wirescene.infer.likelihood import outside_image
    from wirescene.infer.occlusion import hidden_reasons, self_occlusion
    from wirescene.io.pictures import draw_wireframe, new_figure

    vertices = transform(load_default().mean, np.array([0.0, 3.2, 9.0]), rotation_y(0.3))  # low: cut by the bottom
    uv = camera.project(vertices)
    below = outside_image(camera, uv)
    nothing = np.zeros(36, bool)
    reasons = hidden_reasons(self_occlusion(vertices, FACES, camera.center), truncated=below, other_car=nothing,
                             occluder=nothing)
    shown = reasons == "truncated"
    assert shown.any() and np.all(uv[below, 1] > 374) and np.all((uv[:, 0] > 0) & (uv[:, 0] < 1241))
    for size, inverted, want in ((True, True, "v"), (True, False, "^"), (False, True, "v")):
        ax = new_figure().subplots()
        ax.set_xlim(0, 1242)
        ax.set_ylim(*((375, 0) if inverted else (0, 375)))
        assert "truncated" in draw_wireframe(ax, camera if size else Camera(camera.P), vertices, EDGES,
                                             hidden_by=reasons)
        edge = [c for c in ax.collections if isinstance(c, PathCollection) and _marker(c) in "<>^v"]
        assert [_marker(c) for c in edge] == [want], (size, inverted)
        assert np.allclose(np.sort(edge[0].get_offsets()[:, 0]), np.sort(uv[shown, 0]))  # where they left
        assert np.all((edge[0].get_offsets()[:, 1] > 360) & (edge[0].get_offsets()[:, 1] < 375))
