"""The Python API: arrays in, a SceneEstimate out, argument errors that name the argument,
the same result as the CLI, and a package that reads nothing at import time and keeps
its layers."""

import doctest
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import wirescene
import wirescene.api
from conftest import KITTI_ROOT, assert_close
from wirescene.cli.main import main
from wirescene.fitting.options import FitOptions
from wirescene.io.detections import read_detections
from wirescene.io.kitti import KittiDataset
from wirescene.lift import LiftingOptions

SPLIT = KITTI_ROOT / "training"
FRAME = "000010"
P2 = np.array([[721.5377, 0, 609.5593, 44.85728], [0, 721.5377, 172.854, 0.2163791], [0, 0, 1, 0.002745884]])


@pytest.fixture(scope="module")
def frame():
    ds = KittiDataset(KITTI_ROOT)
    return ds.image(FRAME), ds.camera(FRAME), ds.labels(FRAME)


def test_the_entry_points_and_returned_types_have_examples():
    # they run in test_examples.py; here: fit, detect and evaluate and the types they return show one each
    import wirescene.core.types as types

    def count(module):
        return sum(len(t.examples) for t in doctest.DocTestFinder().find(module))

    assert count(wirescene.api) >= 15 and count(types) >= 20
    for cls in (types.Detections, types.ObjectEstimate, types.SceneEstimate):
        assert "Examples\n    --------\n    >>> " in cls.__doc__, cls.__name__


def test_version_is_the_package_metadata_and_options_and_reports_are_exported(monkeypatch):
    import importlib
    import importlib.metadata

    import wirescene.core.version as version_module
    from wirescene.eval.metrics import EvaluationReport
    from wirescene.infer.inference import InferenceOptions
    from wirescene.lift import LiftingOptions

    assert wirescene.__version__ == importlib.metadata.version("wirescene")
    assert (wirescene.InferenceOptions, wirescene.LiftingOptions, wirescene.EvaluationReport) == (
        InferenceOptions, LiftingOptions, EvaluationReport)
    assert {"InferenceOptions", "LiftingOptions", "EvaluationReport"} <= set(wirescene.__all__)

    def not_installed(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    try:
        assert importlib.reload(version_module).__version__ == "0+unknown"
    finally:
        monkeypatch.undo()
        importlib.reload(version_module)
    assert version_module.__version__ == wirescene.__version__


def test_fit_on_arrays_gives_the_scene_contract(frame):
    image, camera, labels = frame
    boxes = np.array([o.box for o in labels.of_type("Car")])[:3]
    scene = wirescene.fit(image, camera.P, boxes, variant="fg+gp", particles=20)
    assert isinstance(scene, wirescene.SceneEstimate) and len(scene.cars) == 3
    for car, box in zip(scene.cars, boxes):
        assert car.location.shape == (3,) and car.dimensions.shape == (3,) and np.isfinite(car.rotation_y)
        assert car.vertices.shape == (36, 3) and car.visible.shape == (36,) and car.visible.dtype == bool
        assert_close(car.box, box) and car.score == 1.0 and isinstance(car.cad_model, str)
    assert scene.ground_plane is not None and abs(scene.ground_plane.pitch) < 0.2
    rows = scene.to_kitti().splitlines()
    assert len(rows) == 3 and all(r.split()[0] == "Car" and len(r.split()) == 16 for r in rows)
    assert len(json.loads(json.dumps(scene.to_dict()))["objects"]) == 3
    assert scene.n_particles == 20  # the search's particles, not the one the polish refined to the end


def test_image_encodings_and_calib_forms_agree(frame, tmp_path):
    image, camera, labels = frame
    boxes = np.array([o.box for o in labels.of_type("Car")])[:2]
    ref = wirescene.fit(image, camera, boxes, variant="coarse+gp", particles=10)
    # A path, float [0, 1] and uint16 encodings of the same pixels, a calib file and a P matrix.
    for img, calib in (
        (SPLIT / "image_2" / f"{FRAME}.png", SPLIT / "calib" / f"{FRAME}.txt"),
        (image / 255.0, camera.P),
        (image.astype(np.uint16) * 257, camera),
    ):
        other = wirescene.fit(img, calib, boxes, variant="coarse+gp", particles=10)
        for a, b in zip(ref.cars, other.cars):
            assert_close(a.location, b.location, atol=1e-9)


def test_integer_images_holding_8_bit_values_are_read_as_8_bit(frame):
    from wirescene.core.image import to_rgb_uint8

    image = frame[0]
    for dtype in (np.int16, np.int32, np.int64):  # e.g. after arithmetic on the pixels
        assert (to_rgb_uint8(image.astype(dtype)) == image).all(), dtype
    assert (to_rgb_uint8(image.astype(np.uint16) * 257) == image).all()  # a 16-bit PNG's range


def test_integer_images_beyond_8_bit_values_but_uint16_are_refused_not_read_black(frame):
    """An int32 array of a 16-bit image's values was scaled by int32's range (a black image, no car found), a
    negative value cut to 0: refused, naming the argument; uint16 and 8-bit values in any integer type are read."""
    image = frame[0]
    for values, says in ((image.astype(np.int32) * 257, r"dtype int32, 0\.\.65535. would be read by the range of int32"),
                         # 8-bit values but the negative ones: read as 8-bit, -1 as 0 (not by int16's range)
                         (image.astype(np.int16) - 1, r"dtype int16, -1\.\.254.: the negative ones would be read as 0"),
                         (image.astype(np.uint32) + 1000, r"dtype uint32, 1000\.\.1255. would be read by the range")):
        with pytest.raises(wirescene.ArgumentError, match=f"^image: integer values outside 0..255 .{says}.*uint16"):
            wirescene.api.as_image(values)
        with pytest.raises(wirescene.ArgumentError, match="^image: integer values"):
            wirescene.fit(values, P2, [[300, 180, 520, 300]], variant="coarse", particles=5)
    for values in (image.astype(np.int64), image.astype(np.uint16) * 257, (image.astype(np.uint16) * 257).astype(">u2")):
        assert (wirescene.api.as_image(values) == image).all()  # big-endian uint16 was refused as beyond 8 bits


def test_float_images_fitting_neither_0_1_nor_0_255_are_refused_not_clipped(frame):
    """A float image of values outside both [0, 1] and [0, 255] (a normalised network input, a sum of images) was
    clipped without a word: refused naming the argument and the range found; NaN pixels say how many. Floats that
    fit are read as before: [0, 1] when the maximum is at most 1, else [0, 255], a rounding's undershoot clipped."""
    image = frame[0]
    unit = image / 255.0
    for values, found in ((unit * 403 - 3, r"float64, -3\.\.400"), (unit - 0.5, r"float64, -0\.5\.\.0\.5"),
                          ((image * 1.5).astype(np.float32), r"float32, 0\.\.382\.5")):
        says = ("^image: float values outside both 0..1 and 0..255 "
                f".dtype {found}. would be clipped: scale to 0..1 or 0..255$")
        with pytest.raises(wirescene.ArgumentError, match=says):
            wirescene.api.as_image(values)
        with pytest.raises(wirescene.ArgumentError, match="^image: float values outside both"):
            wirescene.detect(values, P2)
    nan = unit.copy()
    nan[0, :3, 0] = np.nan
    with pytest.raises(wirescene.ArgumentError, match=r"^image: image has non-finite values \(3 NaN, 0 infinite of "):
        wirescene.fit(nan, P2, [[300, 180, 520, 300]], variant="coarse", particles=5)
    # accepted floats: read exactly as before, a -1e-4 (rounding to level 0) and 255.4 (to 255) included
    assert_close(wirescene.api.as_image(unit), image, atol=0, rtol=0)
    assert_close(wirescene.api.as_image(image.astype(np.float32)), image, atol=0, rtol=0)
    edges = np.array([[-1e-4, 0.5, 1.0]]), np.array([[-0.1, 128.0, 255.4]])
    for values in edges:
        assert_close(wirescene.api.as_image(np.tile(values, (16, 6)))[0, :3, 0], [0, 128, 255], atol=0, rtol=0)


def test_a_float_image_s_overshoot_of_1_is_read_as_0_1_not_as_0_255(frame):
    """A float image of [0, 1.001] (a resampling's overshoot) was read as [0, 255]: nearly black. A maximum that rounds
    to level 255 is read as [0, 1], as an undershoot that rounds to 0 is; one past half a level stays [0, 255]."""
    unit = frame[0] / 255.0
    for top in (1.001, np.float32(1.0019)):
        assert_close(wirescene.api.as_image(unit * top), frame[0], atol=1, rtol=0)
    assert int(wirescene.api.as_image(unit * 1.0021).max()) == 1  # 255 levels of 1.0021: [0, 255]
    from wirescene.core.image import to_grey

    assert_close(to_grey(unit * 1.001), to_grey(frame[0]) * 1.001, atol=1e-5, rtol=0)


def test_an_image_s_range_is_read_off_its_colours_not_its_alpha_channel(frame):
    """The conversion drops an alpha channel before it reads the range: so do the checks of the range. Colours in
    [-0.2, 1] beside an alpha of 255 were read by 0..255 (no pixel clipped: accepted) and then clipped by 0..1; an
    alpha the conversion drops refused an image it reads whole."""
    unit = frame[0] / 255.0
    alpha = np.full(unit.shape[:2] + (1,), 255.0)
    with pytest.raises(wirescene.ArgumentError, match=r"^image: float values outside both .* -0\.2\.\.1\)"):
        wirescene.api.as_image(np.concatenate([unit * 1.2 - 0.2, alpha], axis=2))
    for odd in (-1.0, 300.0):  # an alpha channel's values, dropped
        assert_close(wirescene.api.as_image(np.concatenate([unit, np.full_like(alpha, odd)], axis=2)), frame[0],
                     atol=0, rtol=0)
    assert (wirescene.api.as_image(np.concatenate([frame[0], np.full(alpha.shape, 300)], axis=2)) == frame[0]).all()


def test_detect_returns_the_fits_own_boxes_and_viewpoints_above_its_threshold(frame):
    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.own_boxes import own_detections

    image, camera, _ = frame
    fit = PredetectOptions()
    own = own_detections(camera, image, threshold=fit.threshold, upsample=fit.upsample)  # what the fit starts from
    both = wirescene.detect(image, camera, threshold=PredetectOptions().threshold)
    assert_close(both.boxes, own.boxes, atol=0, rtol=0)
    assert_close(both.alpha, own.alpha, atol=0, rtol=0)
    shown = wirescene.detect(image, camera)  # the bank's 2D operating point, 0.5
    assert (shown.scores > 0.5).all() and len(shown) == int((own.scores > 0.5).sum())
    assert_close(shown.alpha, own.alpha[own.scores > 0.5], atol=0, rtol=0)  # the same viewpoints, whatever the threshold
    more = wirescene.detect(image, camera, threshold=0.05)  # the rule reads more boxes; the fit's keep their viewpoints
    fits = more.scores > PredetectOptions().threshold
    assert len(more) > len(own) and fits.sum() == len(own)
    assert_close(more.boxes[fits], own.boxes, atol=0, rtol=0)
    assert_close(more.alpha[fits], own.alpha, atol=0, rtol=0)
    with pytest.raises(wirescene.ArgumentError, match="^threshold: "):
        wirescene.detect(image, camera, threshold=float("nan"))
    with pytest.raises(wirescene.ArgumentError, match="^threshold: "):
        wirescene.detect(image, camera, threshold=True)


def test_boxes_past_the_image_are_fitted_and_written_clipped(frame):
    image, camera, _ = frame
    W, H = camera.image_size
    amodal = [[-300.0, 200.0, 85.9, 420.0], [1013.4, 182.5, 1300.0, 380.0]]  # another detector's cut cars
    clipped = [[0.0, 200.0, 85.9, H - 1.0], [1013.4, 182.5, W - 1.0, H - 1.0]]
    a = wirescene.fit(image, camera, amodal, variant="coarse+gp", particles=20)
    b = wirescene.fit(image, camera, clipped, variant="coarse+gp", particles=20)
    assert_close([c.box for c in a.cars], clipped)  # as KITTI's labelled boxes are: the 2D AP reads them
    assert_close([c.location for c in a.cars], [c.location for c in b.cars], atol=0, rtol=0)
    last = wirescene.fit(image, camera, [[W - 0.5, 100.0, W + 50.0, 150.0]], variant="coarse", particles=20)
    assert_close(last.cars[0].box, [W - 2.0, 100.0, W - 1.0, 150.0])  # a box in the last column keeps a pixel
    first = wirescene.fit(image, camera, [[-300.0, 200.0, 0.5, 330.0]], variant="coarse", particles=20)
    assert_close(first.cars[0].box, [0.0, 200.0, 1.0, 330.0])  # and one in the first, inside the image


def test_a_sliver_without_a_viewpoint_beside_a_box_with_one_is_fitted(frame, tmp_path):
    """Boxes in normalised coordinates (every box under a pixel) are refused where they enter; a
    sliver among real boxes is fitted, its viewpoint from the box rule, which read it as a file's
    every box (it stopped the fit)."""
    from wirescene.core.types import Detections

    image, camera, _ = frame
    dets = Detections([[300.0, 180.0, 520.0, 300.0], [700.2, 200.1, 700.8, 200.6]], 1.0, [0.5, np.nan])
    assert len(wirescene.fit(image, camera, dets, variant="coarse", particles=10).cars) == 2
    path = tmp_path / "dets.json"
    path.write_text('[{"box": [300, 180, 520, 300], "alpha": 0.5}, {"box": [700.2, 200.1, 700.8, 200.6]}]')
    assert len(wirescene.fit(image, camera, read_detections(path), variant="coarse", particles=10).cars) == 2
    with pytest.raises(wirescene.ArgumentError, match="^boxes: every box is under a pixel"):
        wirescene.fit(image, camera, [[0.24, 0.48, 0.42, 0.8]], variant="coarse", particles=10)


def test_fit_and_detect_warn_of_a_calibration_made_for_another_image_size(frame, tmp_path):
    """A calibration carries no image size: the left half of a KITTI frame with the frame's own
    P2 (its principal point in the outer quarter of the cropped image) is fitted and searched
    with one CalibrationWarning a call, attributed to the caller and naming an image given as a
    path; the whole frame is fitted and searched without one."""
    import warnings

    from PIL import Image

    image, _, labels = frame
    half = image[:, :621]
    boxes = np.array([o.box for o in labels.of_type("Car")])
    box = boxes[boxes[:, 2] < 600][:1]  # a car of the left half
    problem = (r"the principal point \(609\.\d+, 172\.\d+\) lies in the outer quarter of the 621x375 image: "
               r"the calibration of a larger image, or of a crop\?")
    with pytest.warns(wirescene.CalibrationWarning) as said:
        assert wirescene.fit(half, P2, box, variant="coarse", particles=8).cars
    said = [w for w in said if w.category is wirescene.CalibrationWarning]  # once, whatever else a library says
    assert len(said) == 1 and re.fullmatch(problem, str(said[0].message)) and said[0].filename == __file__
    path = tmp_path / "left.png"
    Image.fromarray(half).save(path)
    with pytest.warns(wirescene.CalibrationWarning) as said:  # (said before the search: the image alone searched)
        wirescene.detect(path, P2, upsample=1.0)
    said = [w for w in said if w.category is wirescene.CalibrationWarning]
    assert len(said) == 1 and re.fullmatch(re.escape(str(path)) + ": " + problem, str(said[0].message)) and said[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error", wirescene.CalibrationWarning)
        wirescene.detect(half, upsample=1.0)  # no calibration: nothing to say
        assert wirescene.fit(image, P2, box, variant="coarse", particles=8).cars
        wirescene.detect(image, P2, upsample=1.0)


def test_pil_images_are_read_as_their_files_are(frame, tmp_path):
    from PIL import Image

    from wirescene.api import as_image

    image = frame[0]
    with Image.open(KITTI_ROOT / "training" / "image_2" / f"{FRAME}.png") as png:
        assert (as_image(png) == image).all()
    grey16 = Image.fromarray(image[..., 1].astype(np.uint16) * 257)  # mode I;16, as a 16-bit PNG opens
    grey16.save(tmp_path / "grey16.png")
    assert (as_image(grey16) == as_image(tmp_path / "grey16.png")).all()
    assert (as_image(grey16)[..., 0] == image[..., 1]).all()
    for mode in ("L", "P", "RGBA"):
        converted = Image.fromarray(image).convert(mode)
        converted.save(tmp_path / f"{mode}.png")
        assert (as_image(converted) == as_image(tmp_path / f"{mode}.png")).all(), mode
    # a float image's range checked as an array's: one fitting neither 0..1 nor 0..255 was clipped without a word
    unit = (image[..., 1] / 255).astype(np.float32)
    assert (as_image(Image.fromarray(unit))[..., 0] == image[..., 1]).all()
    with pytest.raises(wirescene.ArgumentError, match=r"^image: float values outside both 0\.\.1 and 0\.\.255 "
                                                      r"\(dtype float32, [-\d.]+\.\.[\d.]+\) would be clipped"):
        as_image(Image.fromarray(unit * 403 - 3))
    with pytest.raises(wirescene.ArgumentError, match=r"^image: integer values outside 0\.\.65535 \(mode I, -\d+\.\."):
        as_image(Image.fromarray(image[..., 1].astype(np.int32) - 1000))  # mode I, negative: was clipped to 0


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(image=np.zeros((5, 5, 3), np.uint8)), "image"),
        (dict(image=np.zeros((100, 100, 2), np.uint8)), "image"),
        (dict(image="not an image"), None),  # a path that does not exist: InputError naming it
        (dict(calib=np.zeros((3, 4))), "calib"),
        (dict(calib=np.full((3, 4), np.nan)), "calib"),
        (dict(calib=P2 * [[-1], [1], [1]]), "calib"),
        (dict(calib=np.eye(3)), "calib"),
        (dict(calib=42), "calib"),
        (dict(boxes=[[10, 10, 5, 50]]), "boxes"),
        (dict(boxes=[[10, 10, np.inf, 50]]), "boxes"),
        (dict(boxes=[[5000, 10, 5100, 50]]), "boxes"),
        (dict(boxes=np.zeros((2, 3))), "boxes"),
        (dict(boxes="1 2 3 4"), "boxes"),
        (dict(boxes=[[1, 2, 3, 4], [1, 2]]), "boxes"),
        (dict(calib=[[1, 2], [3]]), "calib"),
        (dict(variant="fancy"), "variant"),
        (dict(variant=None), "variant"),
        (dict(variant=["full", "coarse"]), "variant"),
        (dict(settings={"lifting.n_particles": 0}), "settings"),
        (dict(settings={"inference.samples": 1}), "settings"),
        (dict(settings={"lifting.pitch_step": 0}), "settings"),
        (dict(settings={"inference.box_weight": float("nan")}), "settings"),
        (dict(settings={"lifting.camera_height": -1.0}), "settings"),
        (dict(settings={"inference.keep_fraction": 1.5}), "settings"),
        (dict(settings={"lifting.n_particles": 20.5}), "settings"),
        (dict(settings={"inference.flip_evidence": 1}), "settings"),
        (dict(options=FitOptions(lifting=LiftingOptions(n_particles=0))), "options"),
        (dict(options=FitOptions(seed=-1)), "options"),
        (dict(particles=0), "particles"),
        (dict(particles=2.5), "particles"),
        (dict(seed=-1), "seed"),
    ],
)
def test_bad_arguments_raise_value_errors_that_name_them(kwargs, name):
    args = dict(image=np.zeros((375, 1242, 3), np.uint8), calib=P2, boxes=[[300, 180, 520, 300]], variant="coarse")
    args.update(kwargs)
    image, calib, boxes = args.pop("image"), args.pop("calib"), args.pop("boxes")
    if name is None:
        with pytest.raises(wirescene.InputError, match="not an image"):
            wirescene.fit(image, calib, boxes, **args)
        return
    with pytest.raises(ValueError) as info:
        wirescene.fit(image, calib, boxes, **args)
    assert isinstance(info.value, wirescene.ArgumentError)
    assert str(info.value).startswith(f"{name}: ")


def test_detections_check_their_shapes():
    from wirescene.core.types import Detections

    assert Detections([300, 180, 520, 300], 0.9, np.nan).boxes.shape == (1, 4)  # one box
    assert Detections([], [], []).boxes.shape == (0, 4)
    for boxes, scores, says in ((np.zeros((2, 5)), 1.0, r"boxes must have shape \(\*, 4\), got \(2, 5\)"),
                                (np.zeros((4, 5)), 1.0, "boxes must have shape"),  # was read as 5 boxes
                                (np.zeros(8), 1.0, "boxes must have shape"),
                                (np.zeros((2, 4)), [1, 1, 1], r"scores must have shape \(2,\)"),
                                (np.zeros((2, 4)), np.ones((2, 1)), "scores must have shape")):
        with pytest.raises(wirescene.ShapeError, match=says):
            Detections(boxes, scores, np.nan)
    with pytest.raises(wirescene.ShapeError, match="alpha must have shape"):
        Detections(np.zeros((2, 4)), 1.0, [0.1, 0.2, 0.3])
    with pytest.raises(wirescene.ArgumentError, match="^boxes: expected numbers"):
        Detections([[1, 2, 3, 4], [1, 2]], 1.0, np.nan)
    for name, values in (("boxes", np.ones((1, 4)) * 1j), ("scores", [0.9 + 0.1j]), ("alpha", [True]),
                         ("boxes", [["300", "180", "520", "300"]])):
        args = {"boxes": np.ones((1, 4)), "scores": [0.9], "alpha": [0.1], name: values}
        with pytest.raises(wirescene.ArgumentError, match=f"^{name}: (complex numbers|booleans|text) .dtype"):
            Detections(**args)  # a complex number lost its imaginary part with a mere warning


def test_estimates_check_their_shapes_where_they_are_made():
    """An ObjectEstimate of a wrong shape (a location of 2 numbers, a wireframe of 10 vertices) was accepted, to fail
    as an IndexError in its label line or its picture: refused with the argument and the shape expected."""
    from wirescene.core.types import ObjectEstimate

    car = dict(detection_index=0, box2d=[300.0, 180.0, 520.0, 300.0], score=0.8, location=[-2.0, 1.65, 12.0],
               R=np.eye(3), dims=[1.5, 1.6, 3.9], cost=0.0)
    ObjectEstimate(**car, shape=np.zeros(5), vertices=np.zeros((36, 3)), visibility=np.ones(36, bool))
    for name, value, says in (("location", [-2.0, 12.0], r"location must have shape \(3,\), got \(2,\)"),
                              ("box2d", [[300.0, 180.0, 520.0, 300.0]], r"box2d must have shape \(4,\), got \(1, 4\)"),
                              ("R", np.eye(4), r"R must have shape \(3, 3\)"),
                              ("dims", [1.5, 1.6], r"dims must have shape \(3,\)"),
                              ("shape", np.zeros((1, 5)), r"shape must have shape \(\*,\)"),
                              ("vertices", np.zeros((10, 3)), r"vertices must have shape \(36, 3\), got \(10, 3\)"),
                              ("visibility", np.ones(10, bool), r"visibility must have shape \(36,\)"),
                              ("hidden_by", ["self"] * 10, r"hidden_by must have shape \(36,\)")):
        with pytest.raises(wirescene.ShapeError, match=f"^{says}"):
            ObjectEstimate(**{**car, name: value})


def test_what_hides_a_cars_vertices_is_said_in_known_words_and_agrees_with_its_visibility():
    """``hidden_by`` names what hides each vertex in the words of ``HIDDEN_BY`` and makes the car's
    visibility (given, it must agree): a picture would draw one and a metric count the other."""
    from wirescene.core.types import ObjectEstimate

    car = dict(detection_index=0, box2d=[300.0, 180.0, 520.0, 300.0], score=0.8, location=[-2.0, 1.65, 12.0],
               R=np.eye(3), dims=[1.5, 1.6, 3.9], cost=0.0, vertices=np.zeros((36, 3)))
    reasons = ["visible"] * 30 + ["self", "truncated", "other-car", "occluder", "self", "self"]
    made = ObjectEstimate(**car, hidden_by=reasons)
    assert made.visibility.tolist() == [True] * 30 + [False] * 6 and made.to_dict()["hidden_by"] == reasons
    with pytest.raises(wirescene.ArgumentError, match="^hidden_by: unknown reason 'mask' "):
        ObjectEstimate(**car, hidden_by=reasons[:-1] + ["mask"])
    with pytest.raises(wirescene.ArgumentError, match="^hidden_by: vertex 30 is 'self', but visibility says it is vis"):
        ObjectEstimate(**car, hidden_by=reasons, visibility=np.ones(36, bool))


def test_what_hides_a_cars_vertices_stays_checked_and_agreeing_when_set_later():
    """Every assignment of an estimate is checked, ``hidden_by`` and ``visibility`` too: set after
    the estimate was made they were taken as they came (a wrong shape, an unknown word, a
    visibility the reasons contradict, which the pictures and the metrics would then each read
    their own way)."""
    from wirescene.core.types import ObjectEstimate

    reasons = ["visible"] * 30 + ["self"] * 6
    car = ObjectEstimate(detection_index=0, box2d=[300.0, 180.0, 520.0, 300.0], score=0.8,
                         location=[-2.0, 1.65, 12.0], R=np.eye(3), dims=[1.5, 1.6, 3.9], cost=0.0,
                         vertices=np.zeros((36, 3)), hidden_by=reasons)
    with pytest.raises(wirescene.ShapeError, match=r"^hidden_by must have shape \(36,\)"):
        car.hidden_by = ["self"] * 10
    with pytest.raises(wirescene.ArgumentError, match="^hidden_by: unknown reason 'mask' "):
        car.hidden_by = reasons[:-1] + ["mask"]
    with pytest.raises(wirescene.ArgumentError, match="^hidden_by: vertex 0 is 'occluder', but visibility says it is vis"):
        car.hidden_by = ["occluder"] + reasons[1:]
    with pytest.raises(wirescene.ArgumentError, match="^visibility: vertex 30 is 'self', but visibility says it is vis"):
        car.visibility = np.ones(36, bool)
    with pytest.raises(wirescene.ArgumentError, match="^visibility: visibility cannot be None where hidden_by says"):
        car.visibility = None
    assert car.hidden_by.tolist() == reasons and car.visibility.tolist() == [True] * 30 + [False] * 6
    car.hidden_by = ["visible"] * 30 + ["truncated"] + ["self"] * 5  # where they agree: taken, as an array
    assert car.hidden_by.dtype.kind == "U" and car.visibility.tolist() == [True] * 30 + [False] * 6
    car.hidden_by, car.visibility = None, None  # cleared in that order: a car without them
    car.visibility = np.ones(36, bool)
    car.hidden_by = ["visible"] * 36
    assert car.visibility.all()


def test_estimates_refuse_non_finite_numbers_where_they_are_made():
    """An ObjectEstimate of a NaN location, an infinite size or a NaN azimuth was accepted, to reach the JSON of `fit`
    (as null), metrics and label files: refused naming the argument; a fit's unknown detection score and infinite
    cost (not in a label line) stay accepted."""
    from wirescene.core.groundplane import rotation_y
    from wirescene.core.types import ObjectEstimate

    car = dict(detection_index=0, box2d=[300.0, 180.0, 520.0, 300.0], score=0.8, location=[-2.0, 1.65, 12.0],
               R=rotation_y(0.3), dims=[1.5, 1.6, 3.9], cost=0.0)
    ObjectEstimate(**{**car, "cost": np.inf}, detection_score=np.nan)
    for name, value, says in (("location", [np.nan, 1.65, 12.0], r"location: must be finite, got \[nan, 1\.65, 12\.0]"),
                              ("dims", [1.5, np.inf, 3.9], r"dims: must be finite, got \[1\.5, inf, 3\.9]"),
                              ("R", rotation_y(np.nan), r"R: must be finite, got \[\[nan, 0\.0, nan\]"),
                              ("box2d", [300.0, 180.0, np.inf, 300.0], r"box2d: must be finite"),
                              ("score", np.nan, r"score: must be a finite number, got nan"),
                              ("location", ["a", "b", "c"], r"location: text .dtype <U1., expected real numbers")):
        with pytest.raises(wirescene.ArgumentError, match=f"^{says}"):
            ObjectEstimate(**{**car, name: value})


def test_estimates_check_a_field_set_later_and_refuse_a_size_not_positive():
    """A confidence set after the estimate was made (as fitting.confidence sets ``score``) was not checked: a NaN
    reached the label line; a size of zero or below was accepted. Both refused as at construction."""
    from wirescene.core.groundplane import rotation_y
    from wirescene.core.types import ObjectEstimate

    car = dict(detection_index=0, box2d=[300.0, 180.0, 520.0, 300.0], score=0.8, location=[-2.0, 1.65, 12.0],
               R=rotation_y(0.3), dims=[1.5, 1.6, 3.9], cost=0.0)
    for dims, says in (([1.5, 0.0, 3.9], r"\[1\.5, 0\.0, 3\.9]"), ([-1.0, -1.0, -1.0], r"\[-1\.0, -1\.0, -1\.0]")):
        with pytest.raises(wirescene.ArgumentError, match=rf"^dims: must be positive \(h w l, metres\), got {says}$"):
            ObjectEstimate(**{**car, "dims": dims})
    made = ObjectEstimate(**car)
    for name, value, says in (("score", np.nan, r"score: must be a finite number, got nan"),
                              ("score", "0.9", r"score: must be a finite number, got '0\.9'"),
                              ("location", [np.inf, 1.65, 12.0], r"location: must be finite, got \[inf, 1\.65, 12\.0]"),
                              ("dims", [1.5, 1.6, 0.0], r"dims: must be positive"),
                              ("box2d", [300.0, 180.0, 520.0], r"box2d must have shape \(4,\)")):
        with pytest.raises((wirescene.ArgumentError, wirescene.ShapeError), match=f"^{says}"):
            setattr(made, name, value)
    assert made.score == 0.8 and made.dims.tolist() == [1.5, 1.6, 3.9]  # left as they were
    made.score = np.float32(0.25)  # a confidence, as apply_confidence sets it
    made.location = (1.0, 1.65, 20.0)
    assert made.score == np.float32(0.25) and isinstance(made.location, np.ndarray)


def test_scene_json_names_an_argument_of_the_wrong_type():
    """scene_json (the README's way to the JSON `fit` writes) took anything: None for the detections failed as an
    AttributeError, an int frame was written as a number."""
    from wirescene.core.types import Detections, SceneEstimate
    from wirescene.io.outputs import scene_json

    scene, dets = SceneEstimate("coarse", []), Detections.empty()
    assert json.loads(scene_json("000010", scene, dets))["frame"] == "000010"
    for args, name in (((10, scene, dets), "stem"), (("000010", scene.to_dict(), dets), "estimate"),
                       (("000010", scene, None), "detections")):
        with pytest.raises(wirescene.ArgumentError, match=f"^{name}: expected "):
            scene_json(*args)


def test_detections_refuse_angles_that_are_no_radians():
    from wirescene.core.types import Detections

    boxes = np.zeros((3, 4))
    alpha = Detections(boxes, 1.0, [np.nan, -np.pi, 6.0]).alpha  # NaN: no viewpoint; wrapped values taken
    assert np.isnan(alpha[0])
    assert_close(alpha[1:], [-np.pi, 6.0])
    for alpha, says in (([np.nan, 90.0, 0.1], r"got 90 \(degrees\?\)"),
                        ([0.1, -10.0, 0.2], "got -10 .KITTI's -10, not estimated, is NaN here"),
                        ([0.1, 0.2, np.inf], "got inf$")):
        with pytest.raises(wirescene.ArgumentError, match="^alpha: expected radians within one turn.*" + says):
            Detections(boxes, 1.0, alpha)


def test_camera_checks_its_arguments():
    from wirescene.core.camera import Camera

    assert Camera(P2, np.array([1242, 375])).image_size == (1242, 375)
    for size in (5, (1242.0, 375), (0, 375), (1242, 375, 3)):
        with pytest.raises(wirescene.ShapeError, match="image_size must be"):
            Camera(P2, size)
    with pytest.raises(wirescene.ArgumentError, match="^P: must be finite"):
        Camera(np.full((3, 4), np.nan))
    camera = Camera(P2, (1242, 375))
    with pytest.raises(wirescene.ShapeError, match=r"depth must have shape \(5,\)"):
        camera.backproject(np.zeros((5, 2)), np.ones(3))
    uv = np.array([[600.0, 200.0], [100.0, 300.0]])
    assert_close(camera.project(camera.backproject(uv, 12.0)), uv, atol=1e-9)  # one depth for all


def test_complex_numbers_are_refused_not_cast_to_their_real_part():
    """A complex calibration (given as a matrix or in a Camera) or complex boxes lost their imaginary part with
    numpy's ComplexWarning only: refused naming the argument, as a complex image is."""
    import warnings

    from wirescene.core.camera import Camera

    image, box = np.zeros((375, 1242, 3), np.uint8), np.array([[300, 180, 520, 300]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ComplexWarning was all that was said
        for kwargs, says in ((dict(calib=P2.astype(complex)), r"^calib: complex numbers \(dtype complex128\), expected "
                                                              r"real numbers$"),
                             (dict(calib=(P2 + 1e-3j)[:, :3]), r"^calib: complex numbers \(dtype complex128\)"),
                             (dict(calib=P2 > 0), r"^calib: booleans \(dtype bool\), expected real numbers$"),
                             (dict(boxes=box + 0j), r"^boxes: boxes must be real numbers, got dtype complex128$"),
                             (dict(image=image + 0j), r"^image: image must have a numeric dtype, got complex128$")):
            args = {"image": image, "calib": P2, "boxes": box, **kwargs}
            with pytest.raises(wirescene.ArgumentError, match=says):
                wirescene.fit(args["image"], args["calib"], args["boxes"], variant="coarse")
        with pytest.raises(wirescene.ArgumentError, match=r"^P: complex numbers \(dtype complex128\)"):
            Camera(P2 + 1e-3j, (1242, 375))
        # a matrix of objects holding real numbers is read as before
        assert_close(wirescene.api.as_camera(P2.astype(object), (1242, 375)).P, P2)


def test_fit_takes_what_read_kitti_calib_returns(frame):
    image, camera, _ = frame
    calib = wirescene.read_kitti_calib(SPLIT / "calib" / f"{FRAME}.txt")
    a = wirescene.fit(image, calib, [[300, 180, 520, 300]], variant="coarse", particles=10)
    b = wirescene.fit(image, camera, [[300, 180, 520, 300]], variant="coarse", particles=10)
    assert a.to_kitti() == b.to_kitti()


def test_fit_frame_checks_its_arguments(frame):
    from wirescene.fitting.pipeline import fit_frame

    image, camera, _ = frame
    dets = wirescene.Detections([[300, 180, 520, 300]], 1.0, 0.0)
    with pytest.raises(wirescene.ShapeError, match=r"image must have shape \(375, 1242, 3\), got \(188, 621, 3\)"):
        fit_frame(camera, dets, ["coarse"], image=image[::2, ::2])  # another size than the camera's
    with pytest.raises(wirescene.ArgumentError, match="^image: expected uint8"):
        fit_frame(camera, dets, ["coarse"], image=image / 255.0)
    with pytest.raises(wirescene.ArgumentError, match="^camera: expected a Camera"):
        fit_frame(camera.P, dets, ["coarse"])
    with pytest.raises(wirescene.ArgumentError, match="^options: expected FitOptions"):
        fit_frame(camera, dets, ["coarse"], options={})
    with pytest.raises(wirescene.ArgumentError, match="^options: inference.samples must be at least 2, got 1"):
        fit_frame(camera, dets, ["coarse"], options=FitOptions(inference=wirescene.api.InferenceOptions(samples=1)))
    one = fit_frame(camera, dets, "coarse", options=FitOptions(lifting=LiftingOptions(n_particles=10)))
    assert list(one.estimates) == ["coarse"]  # a variant's name alone, not its letters


def test_arguments_that_reached_a_library_are_named_before_it(tmp_path):
    """Each was an untyped error from deep inside (str.partition, matplotlib, pathlib) or, for
    the labels, passed unchecked: now the argument's ArgumentError, or the file's InputError."""
    image = np.full((375, 1242, 3), 128, np.uint8)
    with pytest.raises(wirescene.ArgumentError, match=r"^settings: 1: settings are STAGE\.FIELD"):
        wirescene.fit(image, P2, [[300, 180, 520, 300]], variant="coarse", particles=10, settings={1: 2})
    with pytest.raises(wirescene.ArgumentError, match=r"^settings: predetect\.min_car_probability must be at most 1"):
        wirescene.fit(image, P2, variant="coarse", particles=10, settings={"predetect.min_car_probability": 2})
    with pytest.raises(wirescene.ArgumentError, match="^title: expected a string, got int"):
        wirescene.draw(image, P2, title=5)
    gt = tmp_path / "gt.txt"  # a label file of another image: the same check as a frame's labels
    gt.write_text("Car 0.00 0 1.95 3000 185.52 3100 294.49 1.43 1.70 3.95 -2.39 1.66 11.80 1.76\n")
    with pytest.raises(wirescene.InputError, match=r"gt\.txt: line 1: 2D box .* entirely outside the 1242x375 image"):
        wirescene.draw(image, P2, gt=gt)
    a_file = tmp_path / "f"
    a_file.write_text("x")
    for predictions, says in ((a_file, "is a file, expected a directory"), (a_file / "pred", "is a file, not a directory")):
        with pytest.raises(wirescene.ArgumentError, match=f"^predictions: .*{says}$"):
            wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=[FRAME], particles=10, predictions=predictions)


def test_evaluate_takes_one_frame_id_and_refuses_none_and_what_is_no_path(tmp_path):
    from wirescene.core.resources import DATA_DIR

    root = DATA_DIR / "sample" / "kitti"
    with pytest.raises(wirescene.ArgumentError, match="^kitti_root: expected a directory path, got int"):
        wirescene.evaluate(5, variants="coarse")
    with pytest.raises(wirescene.ArgumentError, match="^predictions: expected a directory path"):
        wirescene.evaluate(root, variants="coarse", predictions=5)
    with pytest.raises(wirescene.ArgumentError, match="^frames: no frame given"):
        wirescene.evaluate(root, variants="coarse", frames=[], particles=10)
    with pytest.raises(wirescene.ArgumentError, match="^calib: expected a calibration file's path, got ndarray"):
        wirescene.evaluate(root, variants="coarse", calib=P2)  # a raw TypeError before
    with pytest.raises(wirescene.ArgumentError, match="^calib: "):
        wirescene.evaluate(root, variants="coarse", calib="")
    one = wirescene.evaluate(root, variants="coarse", frames="000010", particles=10)
    listed = wirescene.evaluate(root, variants="coarse", frames=["000010"], particles=10)
    assert one["coarse"].metrics["all"]["n_gt"] == listed["coarse"].metrics["all"]["n_gt"] > 0


def test_evaluate_reads_an_int_frame_id_as_kitti_dataset_does():
    """An int frame id is written %06d, as KittiDataset reads it (10 is 000010; it was refused as no frame of the
    split); a bool, a negative int and a float are refused naming frames, before any fit."""
    from wirescene.core.resources import DATA_DIR

    root = DATA_DIR / "sample" / "kitti"
    named = wirescene.evaluate(root, variants="coarse", frames=["000010"], particles=10)
    for frames in ([10], 10, [np.int64(10)], [10, "000010"]):  # the last: one frame, listed twice
        reports = wirescene.evaluate(root, variants="coarse", frames=frames, particles=10)
        assert reports["coarse"].to_json_dict() == named["coarse"].to_json_dict(), frames
    for bad, says in ((True, "got bool True"), ([False], "got bool False"), ([-10], "must be non-negative, got -10"),
                      ([10.5], "got float 10.5"), (10.0, "got float 10.0")):
        with pytest.raises(wirescene.ArgumentError, match=f"^frames: .*{says}"):
            wirescene.evaluate(root, variants="coarse", frames=bad, particles=10)


def test_evaluate_min_score_floors_the_boxes_of_detection_files(tmp_path):
    dets = tmp_path / "dets"
    dets.mkdir()
    (dets / f"{FRAME}.json").write_text(json.dumps([{"box": [354.43, 185.52, 549.52, 294.49], "score": 0.9},
                                                    {"box": [600.0, 170.0, 680.0, 230.0], "score": 0.1}]))
    for bad, says in ((float("nan"), "must be a finite number"), (np.inf, "must be a finite number"),
                      ("0.5", "must be a finite number"), (True, "must be a finite number"),
                      (10**400, "must be a finite number")):
        with pytest.raises(wirescene.ArgumentError, match=f"^min_score: {says}"):
            wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=[FRAME], detections=dets, min_score=bad)
    with pytest.raises(wirescene.ArgumentError, match=r"^min_score: needs detection files: label boxes \('gt'\)"):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=[FRAME], min_score=0.5)  # label boxes
    fitted = {}
    for m in (None, 0.5):
        pred = tmp_path / f"pred-{m}"
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=[FRAME], particles=5, detections=dets, min_score=m,
                           predictions=pred)
        fitted[m] = len((pred / "coarse" / f"{FRAME}.txt").read_text().splitlines())
    assert fitted == {None: 2, 0.5: 1}


def test_cli_fit_and_api_fit_give_identical_results(tmp_path, frame):
    image, camera, _ = frame
    dets = read_detections(SPLIT / "label_2" / f"{FRAME}.txt")
    out = tmp_path / "cli"
    r = CliRunner().invoke(main, ["fit", str(SPLIT / "image_2" / f"{FRAME}.png"), "--calib",
                                  str(SPLIT / "calib" / f"{FRAME}.txt"), "--detections",
                                  str(SPLIT / "label_2" / f"{FRAME}.txt"), "--variant", "fg+gp", "--particles", "15",
                                  "--seed", "3", "--device", "numpy", "--out", str(out)], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    api = wirescene.fit(image, camera, dets, variant="fg+gp", particles=15, seed=3)
    assert (out / f"{FRAME}.txt").read_text() == api.to_kitti()
    cli_objects = json.loads((out / f"{FRAME}.json").read_text())["objects"]
    for a, b in zip(cli_objects, api.to_dict()["objects"]):
        assert_close(a["vertices"], b["vertices"], atol=0)


def test_importing_the_package_reads_no_data_file():
    code = (
        "import sys\n"
        "opened = []\n"
        "sys.addaudithook(lambda ev, args: opened.append(str(args[0])) if ev == 'open' else None)\n"
        "import wirescene, wirescene.cli.main\n"
        "print([p for p in opened if '/wirescene/data/' in p])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# The dependency rule: a module may import its own layer or lower ones only. training,
# synth, cad and render may use anything, but no runtime layer imports them. The package
# root (``import wirescene``, ``from wirescene import ...``) imports the API and with it
# every runtime layer: only the CLI, above the API, may import it.
LAYERS = {"core": 0, "io": 1, "predetect": 2, "parts": 2, "lift": 3, "infer": 4, "fitting": 5, "eval": 6,
          "api": 7, "cli": 8, "training": 9, "synth": 9, "cad": 9, "render": 9}
# ``import wirescene.X`` / ``from wirescene.X import``: group 1 is X; the root itself: None.
IMPORT = re.compile(r"\s*(?:from|import)\s+wirescene(?:\.(\w+)|(?=\s+import\b|\s*(?:$|[,;#]|\bas\b)))")


def test_the_layer_rule_reads_every_form_of_import():
    room = lambda line: (m := IMPORT.match(line)) and (m.group(1) or "root")  # noqa: E731
    assert room("from wirescene import __version__") == "root"
    assert room("    import wirescene") == "root" and room("import wirescene as ws") == "root"
    assert room("import wirescene, sys") == "root"
    assert room("from wirescene.core.version import __version__") == "core"
    assert room("import wirescene.lift") == "lift"
    assert not room("import wirescenery") and not room("# see wirescene.api")


def test_lower_layers_never_import_higher_ones():
    root = Path(wirescene.__file__).parent
    violations, root_imports = [], []
    for path in root.rglob("*.py"):
        rel = path.relative_to(root)
        room = rel.parts[0].removesuffix(".py")
        if room not in LAYERS:  # the root's own __init__.py
            continue
        for lineno, line in enumerate(path.read_text().splitlines(), 1):
            m = IMPORT.match(line)
            if m is None:
                continue
            if m.group(1) is None:
                root_imports.append(f"{rel}:{lineno}: imports the package root: {line.strip()}")
            elif m.group(1) is not None and LAYERS[room] != 9 and LAYERS.get(m.group(1), -1) > LAYERS[room]:
                violations.append(f"{rel}:{lineno}: {line.strip()}")
    # cli is the one layer that runs the training commands.
    violations = [v for v in violations if not v.startswith("cli/")] + root_imports
    assert violations == []


def test_detect_and_evaluate_entry_points(frame):
    image, camera, _ = frame
    dets = wirescene.detect(image, camera.P)
    assert isinstance(dets, wirescene.Detections) and dets.boxes.shape[1] == 4
    assert np.all(np.isfinite(dets.scores)) and np.all((dets.scores >= 0) & (dets.scores <= 1))
    reports = wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000002"], particles=10)
    assert list(reports) == ["coarse"] and reports["coarse"].metrics["all"]["n_tp"] == 1
    with pytest.raises(wirescene.ArgumentError, match="^frames: "):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["424242"])
    with pytest.raises(wirescene.ArgumentError, match="^variants: "):
        wirescene.evaluate(KITTI_ROOT, variants=["coarse", "nope"])


def test_pictures_leave_the_callers_matplotlib_backend_and_pyplot_alone(tmp_path):
    """A notebook's backend stays (the pictures never call ``matplotlib.use``), pyplot is
    not imported for them, and a figure the caller made with pyplot is closed once saved."""
    script = f"""
import sys
import matplotlib
matplotlib.use("svg")
from wirescene.io.pictures import birds_eye, save_figure
from wirescene.predetect.ap import plot_pr
import numpy as np
save_figure(birds_eye(), {str(tmp_path / "bev.png")!r})
plot_pr({{"x": {{"recall": np.linspace(0, 1, 5), "precision": np.ones(5), "ap": 1.0}}}}, {str(tmp_path / "pr.png")!r})
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert "matplotlib.pyplot" not in sys.modules
import matplotlib.pyplot as plt
fig = plt.figure()
save_figure(fig, {str(tmp_path / "own.png")!r})
assert not plt.fignum_exists(fig.number)
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert all((tmp_path / f).stat().st_size > 1000 for f in ("bev.png", "pr.png", "own.png"))


def test_overlay_cuts_what_reaches_behind_the_camera_and_keys_its_colours(frame):
    from matplotlib.collections import LineCollection

    from wirescene.core.labels import Label
    from wirescene.core.wireframe import EDGES
    from wirescene.io.pictures import overlay

    image, camera, _ = frame
    # a car beside the camera, its rear corners behind it (a truncated neighbour, as in trk0001_000005)
    beside = Label("Car", 0.6, 0, -1.6, [1000.0, 150.0, 1241.0, 374.0], [1.5, 1.7, 4.2], [3.0, 1.6, 0.8], -1.6)
    fig = overlay(image, camera, gt=[beside])
    ax = fig.axes[0]
    segments = np.concatenate([c.get_segments() for c in ax.collections if isinstance(c, LineCollection)])
    assert len(segments) > 0 and np.isfinite(segments).all()  # was: the whole box left out
    assert segments[..., 0].max() > image.shape[1] * 0.8 and np.abs(segments).max() < 1e5  # no flipped projection
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["ground truth (a cross marks the front)"]
    scene = wirescene.fit(image, camera, [[354, 185, 549, 294]], variant="full", particles=20)
    legend = overlay(image, camera, scene, detections=scene.detections, edges=EDGES).axes[0].get_legend()
    key = [t.get_text() for t in legend.get_texts()]
    assert key[0] == "estimate" and key[-1] == "pre-detection"
    legend = overlay(image, camera, scene, edges=EDGES, estimate_name="mean wireframe").axes[0].get_legend()
    assert legend.get_texts()[0].get_text() == "mean wireframe"  # wirescene gt draws no estimate


def test_pictures_are_saved_in_the_format_their_suffix_names_else_png(tmp_path):
    from wirescene.io.pictures import birds_eye, save_figure

    magic = {"bev.svg": b"<?xml", "bev.pdf": b"%PDF", "bev.png": b"\x89PNG", "bev.picture": b"\x89PNG", "bev": b"\x89PNG"}
    for name, start in magic.items():
        assert save_figure(birds_eye(), tmp_path / name) == tmp_path / name
        assert (tmp_path / name).read_bytes().startswith(start), name
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(magic)  # no temporary file left
    # the same figure saved again (a second later: a date would differ) gives the same bytes
    time.sleep(1.1)
    for name in ("bev.svg", "bev.pdf", "bev.png"):
        again = save_figure(birds_eye(), tmp_path / f"again_{name}")
        assert again.read_bytes() == (tmp_path / name).read_bytes(), name


def test_draw_shows_the_fitted_wireframes_and_the_labels_where_they_stand(frame, tmp_path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    image, camera, labels = frame
    cars = labels.of_type("Car")[:2]
    boxes = np.array([c.box for c in cars])
    scene = wirescene.fit(image, camera.P, boxes, variant="coarse", particles=20)
    label_file = tmp_path / "gt.txt"
    label_file.write_text("".join(line + "\n" for line in scene.to_kitti().splitlines()))  # any KITTI label file
    fig = wirescene.draw(image, camera.P, scene, gt=labels, boxes=boxes)
    assert [int(v) for v in fig.get_size_inches() * fig.dpi] == [image.shape[1], image.shape[0]]
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].astype(int)
    red = (rgb[..., 0] > 200) & (rgb[..., 1] < 80) & (rgb[..., 2] < 80)  # the estimates' colour
    cyan = (rgb[..., 2] > 200) & (rgb[..., 1] > 150) & (rgb[..., 0] < 100)  # the labels'
    for b in boxes.astype(int):  # each fitted car's wireframe and its label's box lie in its 2D box
        assert red[b[1]:b[3], b[0]:b[2]].sum() > 50
        assert cyan[b[1]:b[3], b[0]:b[2]].sum() > 50
    assert red.sum() < 0.2 * red.size and not red[:, :150].any()  # nothing drawn far left of the cars
    assert len(wirescene.draw(image, camera.P, scene, view="bev", gt=label_file).axes) == 1
    with pytest.raises(wirescene.ArgumentError, match="^view: "):
        wirescene.draw(image, camera.P, scene, view="side")
    with pytest.raises(wirescene.ArgumentError, match="^scene: "):
        wirescene.draw(image, camera.P, scene.to_dict())
    for view in ("overlay", "bev"):  # boxes the bird's-eye view does not draw are checked all the same
        with pytest.raises(wirescene.ArgumentError, match="^boxes: "):
            wirescene.draw(image, camera.P, scene, view=view, boxes=[[1, 2, np.nan, 4]])
    for bad in ([1, 2], 3):
        with pytest.raises(wirescene.ArgumentError, match="^gt: "):
            wirescene.draw(image, camera.P, scene, gt=bad)
    with pytest.raises(wirescene.InputError, match="missing.txt"):
        wirescene.draw(image, camera.P, scene, gt=tmp_path / "missing.txt")


def test_a_huge_image_is_drawn_reduced_with_everything_where_it_stands(frame):
    """An image beyond MAX_OVERLAY_PIXELS is drawn on a canvas reduced by a whole factor (matplotlib
    takes some 115 bytes a canvas pixel: a 9,000 x 9,000 image took 9.7 GB to draw, now under 1 GB),
    the labels' boxes where they stand on it; a KITTI frame keeps its own size (above)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    image, camera, labels = frame
    f = 6  # the frame 6x larger: 7452 x 2250 pixels, twice the most drawn
    big = np.repeat(np.repeat(image, f, axis=0), f, axis=1)
    P = camera.P.copy()
    P[:2] *= f
    cars = labels.of_type("Car")[:2]
    fig = wirescene.draw(big, P, gt=cars)
    size = [int(v) for v in fig.get_size_inches() * fig.dpi]
    assert size == [big.shape[1] // 2, big.shape[0] // 2]
    from wirescene.io.pictures import MAX_OVERLAY_PIXELS

    assert size[0] * size[1] <= MAX_OVERLAY_PIXELS
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].astype(int)
    cyan = (rgb[..., 0] < 90) & (rgb[..., 1] > 150) & (rgb[..., 2] > 200)  # the ground truth's colour
    for c in cars:  # the box of each label, at half the big image's coordinates
        b = (np.asarray(c.box) * f / 2).astype(int)
        assert cyan[b[1]:b[3], b[0]:b[2]].sum() > 50
    assert cyan.sum() < 0.2 * cyan.size


def test_the_api_resolves_and_checks_the_device_before_any_work(frame, monkeypatch):
    from wirescene.infer import torch_backend

    image, camera, labels = frame
    boxes = [o.box for o in labels.of_type("Car")][:1]
    calls = []
    monkeypatch.setattr("wirescene.api.fit_frame", lambda *a, **k: calls.append(1))
    with pytest.raises(torch_backend.DeviceError, match="unknown device 'tpu'"):
        wirescene.fit(image, camera, boxes, variant="coarse+gp", settings={"inference.device": "tpu"})
    assert not calls  # refused before the fit, whatever the variant
    monkeypatch.undo()
    scene = wirescene.fit(image, camera, boxes, variant="coarse", particles=10, settings={"inference.device": " NUMPY"})
    assert len(scene.objects) == 1
    if not torch_backend.available():  # auto without PyTorch: numpy, as on the command line
        assert len(wirescene.fit(image, camera, boxes, variant="coarse", particles=10,
                                 settings={"inference.device": "auto"}).objects) == 1


def test_the_api_looks_for_no_gpu_when_no_variant_casts_rays(frame, monkeypatch):
    """``inference.device`` ``auto`` with only coarse variants is numpy, PyTorch never imported
    to look for a GPU; a fine variant looks (a machine whose PyTorch sees one, faked)."""
    from collections import defaultdict
    from types import SimpleNamespace

    import wirescene.eval.runner
    from wirescene.infer import torch_backend

    image, camera, labels = frame
    boxes = [o.box for o in labels.of_type("Car")][:1]
    looked, devices = [], []
    monkeypatch.setattr(torch_backend, "available", lambda: True)
    monkeypatch.setattr(torch_backend, "resolve_device",
                        lambda name: looked.append(name) or SimpleNamespace(type="cuda"))
    monkeypatch.setattr("wirescene.api.fit_frame", lambda *a, options, **k: devices.append(options.inference.device)
                        or SimpleNamespace(estimates=defaultdict(lambda: None)))
    monkeypatch.setattr(wirescene.eval.runner, "evaluate_dataset", lambda *a, options, **k: devices.append(
        options.inference.device))
    auto = {"inference.device": "auto"}
    wirescene.fit(image, camera, boxes, variant="coarse+gp", settings=auto)
    wirescene.evaluate(KITTI_ROOT, variants=("coarse", "coarse+gp"), frames=[FRAME], settings=auto)
    assert devices == ["numpy", "numpy"] and not looked
    wirescene.fit(image, camera, boxes, variant="fg", settings=auto)
    wirescene.evaluate(KITTI_ROOT, variants=("coarse", "full"), frames=[FRAME], settings=auto)
    assert devices[2:] == ["cuda", "cuda"] and looked == ["auto", "auto"]


def test_a_model_retrained_in_place_is_loaded_anew(tmp_path):
    """Models are loaded once per version of their file: one retrained (or broken) at the same
    path, in a notebook or a long-lived process, is read again, never the cached one."""
    import shutil

    from wirescene.core.errors import InputError
    from wirescene.core.resources import shipped_path
    from wirescene.fitting.confidence import load_score_calibration, save_score_calibration
    from wirescene.fitting.models import detector_bank
    from wirescene.infer.occluded_score import load_occluded_score, save_occluded_score

    occlusion = tmp_path / "occlusion.json"
    save_occluded_score(occlusion, {"c": 0.75})
    assert load_occluded_score(occlusion) == 0.75 and load_occluded_score(occlusion) == 0.75
    save_occluded_score(occlusion, {"c": -3.0})  # written to a new file moved onto the path
    assert load_occluded_score(occlusion) == -3.0
    scores = tmp_path / "score_calibration.json"
    shutil.copy(shipped_path("score_calibration"), scores)
    record = load_score_calibration(scores)
    save_score_calibration(scores, {**record, "note": "retrained"})
    assert load_score_calibration(scores)["note"] == "retrained"
    bank = tmp_path / "detector_bank.npz"
    shutil.copy(shipped_path("detector_bank"), bank)
    assert detector_bank(str(bank)) is detector_bank(str(bank))  # loaded once
    bank.write_bytes(b"not a bank")  # overwritten in place
    with pytest.raises(InputError, match="detector_bank.npz"):
        detector_bank(str(bank))


def test_estimates_hold_their_own_arrays_and_print_in_a_line_a_car():
    """A result keeps no view into the search's (particles, cars) arrays, and a notebook shows
    it as one line a car, not every array of the fit."""
    from wirescene.core.groundplane import rotation_y
    from wirescene.core.types import ObjectEstimate, SceneEstimate

    search = np.zeros((250, 15, 3))  # a search's locations, (particles, cars, 3)
    cars = [ObjectEstimate(detection_index=j, box2d=[0.0, 0.0, 10.0, 10.0], score=0.5, location=search[0, j],
                           R=rotation_y(0.1), dims=np.array([1.5, 1.6, 3.9]), cost=0.0,
                           vertices=np.zeros((36, 3)), visibility=np.ones(36, bool), exemplar="golf")
            for j in range(15)]
    assert not any(np.shares_memory(car.location, search) for car in cars)
    assert isinstance(cars[0].box2d, np.ndarray)
    text = repr(SceneEstimate(variant="full", objects=cars, shared_plane=True))
    assert text.count("\n") == 16 and len(text) < 3000 and "array(" not in text
    assert "exemplar='golf'" in text and "rotation_y=0.100" in text


def test_evaluate_warns_where_the_shipped_models_were_trained_on_the_frames(tmp_path):
    """`wirescene.evaluate` says, as `wirescene eval` does, that a frame the shipped models were trained on gives no
    held-out figure (a HeldOutWarning); a frame of another image under the same id says nothing."""
    import warnings

    from PIL import Image

    from conftest import kitti_copy

    with pytest.warns(wirescene.HeldOutWarning, match=r"^1 of the 1 frames evaluated is among the 72 the shipped "
                                                      r"score calibration was trained on \(e\.g\. 000010\)"):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000010"], particles=5)
    root = kitti_copy(tmp_path / "kitti", ["000010"])
    image = root / "training" / "image_2" / "000010.png"
    Image.open(image).transpose(Image.FLIP_LEFT_RIGHT).save(image)
    with warnings.catch_warnings():
        warnings.simplefilter("error", wirescene.HeldOutWarning)
        wirescene.evaluate(root, variants="coarse", frames=["000010"], particles=5)


def test_evaluate_warns_of_held_out_frames_at_the_caller_s_line_and_not_for_a_call_refused(tmp_path):
    """The HeldOutWarning points at the caller's line; a call refused before any fit (its predictions directory
    holding an earlier run's records) warns of nothing."""
    import warnings

    pred = tmp_path / "pred"
    with pytest.warns(wirescene.HeldOutWarning) as said:
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000010"], particles=5, predictions=pred)
    assert [Path(w.filename).name for w in said] == [Path(__file__).name]
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        with pytest.raises(wirescene.InputError, match="earlier run"):
            wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000010"], particles=5, predictions=pred)
    assert not [w for w in said if issubclass(w.category, wirescene.HeldOutWarning)]


def test_the_shipped_frames_are_told_by_the_one_file_hash():
    """The images' SHA-256 is core.resources.file_sha256's (one implementation, cached by file version)."""
    from wirescene.core import resources
    from wirescene.io.shipped_frames import among_shipped_training_frames, shipped_training_frames

    dataset = KittiDataset(KITTI_ROOT)
    image = dataset.image_path("000010")
    resources._sha256.cache_clear()
    assert among_shipped_training_frames(dataset.image_path, ["000010"]) == ["000010"]
    assert resources._sha256.cache_info().currsize == 1
    assert resources.file_sha256(image, what="image") == shipped_training_frames()["000010"]
