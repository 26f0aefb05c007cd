"""A viewpoint for every box: the bank scores the 8 bins inside given boxes (issue 27, item 2)."""

from __future__ import annotations

import numpy as np
import pytest

from wirescene.core.boxes import iou_2d
from wirescene.core.camera import Camera
from wirescene.core.errors import ArgumentError, ShapeError
from wirescene.core.types import Detections
from wirescene.core.viewpoints import bin_center, viewpoint_bin
from wirescene.fitting.pipeline import fit_frame
from wirescene.io.kitti import KittiDataset
from wirescene.predetect import load_default_bank
from wirescene.predetect.bank import detect_pyramid
from wirescene.predetect.box_viewpoints import box_bin_log_odds, box_viewpoints
from wirescene.predetect.hog import feature_pyramid, pyramid_scales, to_gray

from conftest import KITTI_ROOT

# A 600 x 160 px crop of frame 000010 holding seven labelled cars (fast to score).
FRAME, X0, Y0, X1, Y1 = "000010", 340, 150, 940, 310


@pytest.fixture(scope="module")
def scene():
    """The crop, its camera (principal point moved with the crop), its labelled cars and the
    bank's pyramid of it, with the per-bin log-odds of the cars' label boxes."""
    ds = KittiDataset(KITTI_ROOT)
    image, camera = ds.image(FRAME), ds.camera(FRAME)
    crop = np.ascontiguousarray(image[Y0:Y1, X0:X1])
    shift = np.array([[1.0, 0, -X0], [0, 1.0, -Y0], [0, 0, 1.0]])
    cam = Camera(shift @ camera.P, (X1 - X0, Y1 - Y0))
    cars = [o for o in ds.labels(FRAME).objects if o.type == "Car" and o.box[0] >= X0 and o.box[2] <= X1]
    boxes = np.array([o.box for o in cars]) - [X0, Y0, X0, Y0]
    bank = load_default_bank()
    pyr = feature_pyramid(crop, pyramid_scales(X1 - X0, Y1 - Y0, max_scale=float(bank.meta["max_scale"]),
                                               per_octave=int(bank.meta["per_octave"])))
    horizon, center = float(cam.K[1, 2]), float(cam.K[0, 2])
    log_odds = box_bin_log_odds(bank, crop, boxes, pyramid=pyr, horizon=horizon, center_column=center)
    return dict(image=crop, camera=cam, cars=cars, boxes=boxes, bank=bank, pyramid=pyr, horizon=horizon,
                center=center, log_odds=log_odds)


def test_one_viewpoint_per_box_and_the_shape_contract(scene):
    bank, image = scene["bank"], scene["image"]
    boxes = scene["boxes"][:2]
    alpha = box_viewpoints(bank, image, boxes, pyramid=scene["pyramid"])
    assert alpha.shape == (2,) and np.all(np.isfinite(alpha))
    assert np.allclose(alpha, bin_center(viewpoint_bin(alpha)))  # bin centres
    assert box_viewpoints(bank, image, np.zeros((0, 4))).shape == (0,)
    assert scene["log_odds"].shape == (len(scene["boxes"]), 8) and np.all(np.isfinite(scene["log_odds"]))
    for bad in (np.zeros((2, 3)), np.zeros(4), np.zeros((1, 2, 4))):
        with pytest.raises(ShapeError, match="boxes must have shape"):
            box_viewpoints(bank, image, bad)
    with pytest.raises(ArgumentError, match="empty or inverted"):
        box_viewpoints(bank, image, [[50, 50, 40, 80]])
    with pytest.raises(ShapeError):
        box_bin_log_odds(bank, image, np.zeros((3, 5)))


def test_label_boxes_get_the_viewpoint_of_our_own_detections(scene):
    bank, image = scene["bank"], scene["image"]
    h, w = image.shape[:2]
    dets = detect_pyramid(bank, scene["pyramid"], (w, h), threshold=bank.threshold,
                          min_height=float(bank.meta["min_height"]), horizon=scene["horizon"],
                          center_column=scene["center"], gray=to_gray(image))
    chosen = np.argmax(scene["log_odds"], axis=1)
    ov = iou_2d(scene["boxes"][:, None], dets.boxes[None])
    matched = np.flatnonzero(ov.max(1) >= 0.5)
    assert len(matched) >= 4
    own = viewpoint_bin(dets.alpha[ov[matched].argmax(1)])
    steps = np.abs((chosen[matched] - own + 4) % 8 - 4)
    assert np.all(steps <= 1), (chosen[matched], own)
    # the unoccluded cars (both sides of the road) get their label's bin
    clear = [i for i, o in enumerate(scene["cars"]) if o.occluded == 0]
    assert len(clear) >= 3
    assert list(chosen[clear]) == [int(viewpoint_bin(scene["cars"][i].alpha)) for i in clear]


def test_only_the_cells_the_boxes_need_give_the_whole_pyramid_scores_and_the_prior_adds(scene):
    bank, image = scene["bank"], scene["image"]
    # without a pyramid only the cells around the boxes are computed: the same scores
    plain = box_bin_log_odds(bank, image, scene["boxes"])
    with_prior = box_bin_log_odds(bank, image, scene["boxes"], horizon=scene["horizon"], center_column=scene["center"])
    assert with_prior.shape == scene["log_odds"].shape
    assert np.allclose(with_prior, scene["log_odds"], rtol=0, atol=1e-4)
    diff = with_prior - plain
    # the prior is a log probability over the 8 bins of each box
    assert np.allclose(np.exp(diff).sum(1), 1.0) and np.all(diff < 0)


def test_fit_frame_completes_unknown_viewpoints_with_the_bank(scene):
    boxes = scene["boxes"]
    alpha = np.full(len(boxes), np.nan)
    alpha[0] = bin_center(4)  # a known viewpoint is kept
    dets = Detections(boxes, np.ones(len(boxes)), alpha, "external")
    fit = fit_frame(scene["camera"], dets, ["coarse"], image=scene["image"])
    out = fit.detections.alpha
    assert out[0] == pytest.approx(bin_center(4)) and np.all(np.isfinite(out))
    expected = bin_center(np.argmax(scene["log_odds"], axis=1))
    assert np.allclose(out[1:], expected[1:])
    assert fit.evidence is None  # a coarse variant needs no part evidence for it any more
