"""The pictures (wirescene.io.pictures): what a reader can tell from them, measured on made-up scenes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from conftest import KITTI_ROOT
from wirescene.core.boxes import box_corners
from wirescene.core.groundplane import rotation_y
from wirescene.core.labels import Label
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


def _scene(camera, places, *, wireframes=False):
    """An estimate of a car at each ``(x, z)`` of ``places``, in detection order, scored 0.05, 0.1, ..."""
    from wirescene.core.groundplane import transform
    from wirescene.core.shape import load_default

    dims = np.array([1.5, 1.6, 3.9])
    cars = []
    for j, (x, z) in enumerate(places):
        location = np.array([x, 1.65, z])
        vertices = visible = None
        if wireframes:
            vertices = transform(load_default().mean, location, rotation_y(0.4))
            visible = np.arange(36) % 3 != 0
        cars.append(ObjectEstimate(j, _image_box(camera, dims, location, 0.4), round(0.05 * (j + 1), 2), location,
                                   rotation_y(0.4), dims, 0.0, vertices=vertices, visibility=visible))
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
    """Estimate, ground truth and pre-detections differ for readers with any of the three
    dichromacies (the paper's red and green were 12 CIELAB units apart with deuteranopia)."""
    from wirescene.io.pictures import DET_COLOR, EST_COLOR, GT_COLOR

    for a, b in itertools.combinations((EST_COLOR, GT_COLOR, DET_COLOR), 2):
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
        assert labels[:2] == ["estimate (#n: car n; a line marks the front)", "ground truth"]
        assert {"camera", "field of view"} <= set(labels)
    tags = _tags(fig, renderer)
    assert sorted(tags) == ["#1", "#2"]
    near = next(t for t in ax.texts if t.get_text() == "#1")
    assert abs(near.get_position()[1] - 10.0) < 1.0  # by car 1, 10 m ahead


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
