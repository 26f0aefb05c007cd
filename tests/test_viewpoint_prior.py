"""The traffic viewpoint prior (wirescene.predetect.viewpoint_prior) and its use by the bank."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.camera import Camera
from wirescene.predetect.viewpoint_prior import (
    choose_viewpoints,
    fit_viewpoint_prior,
    lateral_position,
    viewpoint_log_prior,
)

FRONT, REAR = 2, 6  # bins of alpha = +90 deg (facing the camera) and -90 deg (facing away)


def _box_of_car(K, x, z, *, cam_height=1.65, car_height=1.5, width=1.7):
    """Image box of an upright car box standing on the road at lateral x, depth z."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    u = [fx * (x + dx) / z + cx for dx in (-width / 2, width / 2)]
    return np.array([u[0], fy * (cam_height - car_height) / z + cy, u[1], fy * cam_height / z + cy])


def test_lateral_position_is_metres_over_camera_height():
    K = np.array([[721.5, 0.0, 609.6], [0.0, 721.5, 172.9], [0.0, 0.0, 1.0]])
    for x, z in [(-6.0, 12.0), (0.0, 30.0), (2.5, 8.0), (4.0, 45.0)]:
        s = lateral_position(_box_of_car(K, x, z), K[1, 2], K[0, 2])
        assert_close(s, np.array([x / 1.65]), atol=1e-9)
    # a box in the sky is measured as if it stood half its height below the horizon
    sky = np.array([[700.0, 20.0, 760.0, 60.0]])
    assert_close(lateral_position(sky, 172.9, 609.6), np.array([(730.0 - 609.6) / 20.0]))


def test_viewpoint_prior_learns_the_sides_of_the_traffic():
    rng = np.random.default_rng(0)
    left, right = rng.normal(-3.0, 1.0, 40), rng.normal(2.0, 1.0, 40)
    prior = fit_viewpoint_prior(np.concatenate([left, right]), [FRONT] * 40 + [REAR] * 40)
    lp = viewpoint_log_prior(prior, [-3.0, 0.0 - 0.5, 2.0])
    assert lp.shape == (3, 8) and np.isfinite(lp).all()
    assert_close(np.exp(lp).sum(1), np.ones(3))
    assert np.argmax(lp[0]) == FRONT and np.argmax(lp[2]) == REAR
    assert lp[0, FRONT] - lp[0, REAR] > 2.0 and lp[2, REAR] - lp[2, FRONT] > 2.0
    # every viewpoint keeps a pseudo-count: none is ruled out
    assert lp[:, 0].min() > np.log(1e-3)
    with pytest.raises(ValueError, match="needs >= 5 cars"):
        fit_viewpoint_prior([0.0, 1.0], [FRONT, REAR])
    with pytest.raises(ValueError, match="differ in length"):
        fit_viewpoint_prior([0.0, 1.0, 2.0], [FRONT, REAR])


def test_choose_viewpoints_lets_the_prior_settle_close_calls_only():
    kept = np.array([[100.0, 100.0, 200.0, 180.0]])
    candidates = np.array([kept[0], kept[0] + 4.0, kept[0] + 300.0])  # front (kept), rear nearby, rear elsewhere
    bins = np.array([FRONT, REAR, REAR])
    prefer_rear = np.log(np.array([[0.02] * 2 + [0.1] + [0.02] * 3 + [0.8] + [0.02]]))
    close = choose_viewpoints(kept, candidates, np.array([1.0, 0.5, 9.0]), bins, prefer_rear, iou=0.3)
    assert close.tolist() == [REAR]
    clear = choose_viewpoints(kept, candidates, np.array([6.0, 0.5, 9.0]), bins, prefer_rear, iou=0.3)
    assert clear.tolist() == [FRONT]
    # a candidate that does not overlap the detection never lends it its bin
    alone = choose_viewpoints(kept, candidates[[0, 2]], np.array([1.0, 9.0]), bins[[0, 2]], prefer_rear, iou=0.3)
    assert alone.tolist() == [FRONT]
    assert choose_viewpoints(np.zeros((0, 4)), candidates, np.zeros(3), bins, prefer_rear, iou=0.3).shape == (0,)


def test_viewpoint_prior_changes_only_the_viewpoints_of_real_detections():
    """On real frame 000010 the shipped bank's boxes and scores are the same with and
    without the principal column; only some viewpoints change, and only with the prior."""
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.bank import detect_pyramid, load_default_bank
    from wirescene.predetect.geometry import horizon_row
    from wirescene.predetect.hog import feature_pyramid, pyramid_scales

    bank = load_default_bank()
    assert bank.meta.get("viewpoint_prior") and bank.calibration is not None
    ds = KittiDataset(KITTI_ROOT)
    img, cam = ds.image("000010"), ds.camera("000010")
    assert isinstance(cam, Camera)
    H, W = img.shape[:2]
    pyr = feature_pyramid(img, pyramid_scales(W, H, max_scale=float(bank.meta["max_scale"]),
                                              per_octave=int(bank.meta["per_octave"])))
    kw = dict(min_height=float(bank.meta["min_height"]), horizon=horizon_row(cam))
    plain = detect_pyramid(bank, pyr, (W, H), **kw)
    traffic = detect_pyramid(bank, pyr, (W, H), center_column=float(cam.K[0, 2]), **kw)
    assert_close(traffic.boxes, plain.boxes)
    assert_close(traffic.scores, plain.scores)
    assert len(plain) >= 3
    assert (traffic.alpha != plain.alpha).any()  # the prior does move some viewpoints
    # without the prior in the bank the principal column changes nothing
    from dataclasses import replace

    bare = replace(bank, meta={k: v for k, v in bank.meta.items() if k != "viewpoint_prior"})
    assert_close(detect_pyramid(bare, pyr, (W, H), center_column=float(cam.K[0, 2]), **kw).alpha, plain.alpha)
