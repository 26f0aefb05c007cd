"""A viewpoint for every box: the bank scores the 8 bins inside given boxes (issue 27, item 2)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.boxes import clip_boxes, iou_2d
from wirescene.core.camera import Camera
from wirescene.core.errors import ArgumentError, InputError, ShapeError
from wirescene.core.types import Detections
from wirescene.core.viewpoints import bin_center, viewpoint_bin
from wirescene.fitting.pipeline import fit_frame
from wirescene.io.kitti import KittiDataset
from wirescene.predetect import load_default_bank
from wirescene.predetect.bank import (
    apply_box_regression,
    bank_pyramid,
    detect_pyramid,
    template_responses,
)
from wirescene.predetect.box_viewpoints import (
    FLOOR_MARGIN,
    IOU,
    PRIOR_WEIGHT,
    ROW_WEIGHT,
    box_bin_log_odds,
    box_ground_positions,
    box_log_prior,
    box_viewpoints,
    row_coherent_bins,
)
from wirescene.predetect.hog import CELL, feature_pyramid, pyramid_scales, to_gray
from wirescene.predetect.viewpoint_classifier import (
    ViewpointClassifier,
    crop_viewpoint_features,
    fit_viewpoint_classifier,
    kitti_examples,
    load_default_classifier,
)

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
    templates = box_bin_log_odds(bank, crop, boxes, pyramid=pyr)
    prior = box_log_prior(bank, boxes, cam)
    return dict(image=crop, camera=cam, cars=cars, boxes=boxes, bank=bank, pyramid=pyr, horizon=horizon,
                center=center, templates=templates, prior=prior, log_odds=templates + PRIOR_WEIGHT * prior)


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
    # without the verifier, whose logit also reads the bin (its geometry features) and so may tip front against back
    plain = replace(bank, verifier=None)
    dets = detect_pyramid(plain, scene["pyramid"], (w, h), threshold=bank.threshold,
                          min_height=float(bank.meta["min_height"]), horizon=scene["horizon"],
                          center_column=scene["center"], gray=to_gray(image))
    # under the bank's own rule (the traffic prior alone, naive Bayes) the bins of its detections
    own_rule = scene["templates"] + box_log_prior(bank, scene["boxes"], scene["camera"], road_spread=None)
    chosen = np.argmax(own_rule, axis=1)
    ov = iou_2d(scene["boxes"][:, None], dets.boxes[None])
    matched = np.flatnonzero(ov.max(1) >= 0.5)
    assert len(matched) >= 4
    own = viewpoint_bin(dets.alpha[ov[matched].argmax(1)])
    steps = np.abs((chosen[matched] - own + 4) % 8 - 4)
    assert np.all(steps <= 1), (chosen[matched], own)
    # the unoccluded cars (both sides of the road) get their label's bin under the pipeline's
    # rule (templates, crop classifier and road prior; the templates and the prior alone
    # hardly tell a front from a back)
    clear = [i for i, o in enumerate(scene["cars"]) if o.occluded == 0]
    assert len(clear) >= 3
    alpha = box_viewpoints(bank, image, scene["boxes"], camera=scene["camera"], classifier=load_default_classifier(),
                           pyramid=scene["pyramid"])
    assert list(viewpoint_bin(alpha)[clear]) == [int(viewpoint_bin(scene["cars"][i].alpha)) for i in clear]
    side = np.abs((np.argmax(scene["log_odds"], axis=1)[clear] % 4) - viewpoint_bin(alpha)[clear] % 4)
    assert np.all(side == 0)  # ... but the axis they agree on


def test_only_the_cells_the_boxes_need_give_the_whole_pyramid_scores(scene):
    # without a pyramid only the cells around the boxes are computed: the same scores
    alone = box_bin_log_odds(scene["bank"], scene["image"], scene["boxes"])
    assert alone.shape == scene["templates"].shape
    assert np.allclose(alone, scene["templates"], rtol=0, atol=1e-4)


def test_the_windows_the_rule_searches_are_all_that_can_vote(scene):
    # every window of every template and level, each placed, regressed and clipped: the rule prunes
    # windows by their vote's size and place and skips those under the floor, and finds the same best votes
    bank, boxes, (H, W) = scene["bank"], scene["boxes"], scene["image"].shape[:2]
    best = np.full((len(boxes), 8), -np.inf)
    for t, _, s, R in template_responses(bank, scene["pyramid"], min_height=0.0, max_height=np.inf):
        config = bank.configs[t]
        th, tw = config.template
        r, q = np.divmod(np.arange(R.size), R.shape[1])
        windows = np.column_stack([q, r, q + tw, r + th]) * CELL / s
        bins = np.full(len(windows), config.bin)
        votes = clip_boxes(config.full_box(windows), W, H)
        votes = clip_boxes(apply_box_regression(bank.meta["box_regression"], votes, bins, (W, H)), W, H)
        ok = iou_2d(votes[:, None], boxes[None]) >= IOU  # (windows, boxes)
        values = np.where(ok, R.ravel()[:, None].astype(float), -np.inf).max(0)
        best[:, config.bin] = np.maximum(best[:, config.bin], values)
    a, c = bank.calibration
    assert_close(scene["templates"], a * np.maximum(best, FLOOR_MARGIN) + c, atol=1e-9)
    # no window under the floor changes a bin: the floor applied after a search without one
    unfloored = box_bin_log_odds(bank, scene["image"], boxes, pyramid=scene["pyramid"], floor_margin=-np.inf)
    assert np.array_equal(scene["templates"], np.maximum(unfloored, a * FLOOR_MARGIN + c))
    assert (best > FLOOR_MARGIN).sum() >= len(boxes)  # (cars whose bins some window scores above the floor)


def test_the_rule_reads_the_response_maps_the_bank_left(scene):
    bank, image, boxes, pyr = scene["bank"], scene["image"], scene["boxes"], scene["pyramid"]
    h, w = image.shape[:2]
    maps = {}
    detect_pyramid(bank, pyr, (w, h), threshold=bank.threshold, responses=maps)
    assert 0 < len(maps) < len(bank) * len(pyr)  # (templates too large or small for a level: the rule computes them)
    for (t, li), R in maps.items():
        th, tw = bank.configs[t].template
        assert R.shape == (pyr[li][1].shape[0] - th + 1, pyr[li][1].shape[1] - tw + 1)
    read = box_bin_log_odds(bank, image, boxes, pyramid=pyr, responses=maps)
    assert_close(read, scene["templates"], atol=1e-5)  # the same products, summed in other blocks
    raised = {k: R + 5.0 for k, R in maps.items()}  # ... and they are read, not computed again
    assert np.all(box_bin_log_odds(bank, image, boxes, pyramid=pyr, responses=raised) > read + 1.0)


def test_the_road_prior_puts_front_and_back_along_the_road(scene):
    bank, camera = scene["bank"], scene["camera"]
    prior = scene["prior"]
    assert prior.shape == (len(scene["boxes"]), 8) and np.allclose(np.exp(prior).sum(1), 1.0)
    # a box straight ahead: the road's two headings are bins 2 (front) and 6 (back)
    ahead = np.array([[camera.K[0, 2] - 30, 40.0, camera.K[0, 2] + 30, 90.0]])
    p = np.exp(box_log_prior(bank, ahead, camera))[0]
    assert set(np.argsort(p)[-2:]) == {2, 6} and p[6] > p[2]  # in the ego lane traffic goes away
    # seen 45 deg to the right, the same headings are bins 1 and 5
    f = float(camera.K[0, 0])
    right = ahead + [f, 0.0, f, 0.0]
    p = np.exp(box_log_prior(bank, right, camera))[0]
    assert set(np.argsort(p)[-2:]) == {1, 5}
    # without the road, the traffic prior alone (the bank's own), which knows no ray angle
    kde = np.exp(box_log_prior(bank, right, camera, road_spread=None))[0]
    assert p[1] + p[5] > kde[1] + kde[5]
    assert box_log_prior(bank, np.zeros((0, 4)), camera) is None


def test_fit_frame_completes_unknown_viewpoints_with_the_bank(scene):
    boxes = scene["boxes"]
    alpha = np.full(len(boxes), np.nan)
    alpha[0] = bin_center(4)  # a known viewpoint is kept
    dets = Detections(boxes, np.ones(len(boxes)), alpha, "external")
    fit = fit_frame(scene["camera"], dets, ["coarse"], image=scene["image"])
    out = fit.detections.alpha
    assert out[0] == pytest.approx(bin_center(4)) and np.all(np.isfinite(out))
    # box_viewpoints' rule with the shipped bank and classifier: templates + classifier + road prior
    # (the templates' scores without a pyramid are the whole pyramid's: see the test above)
    classified = load_default_classifier().log_probs(scene["image"], boxes)
    expected = row_coherent_bins((scene["log_odds"] + classified)[1:], boxes[1:], scene["camera"])
    assert np.allclose(out[1:], bin_center(expected))
    assert fit.evidence is None  # a coarse variant needs no part evidence for it any more


def test_our_own_detections_take_the_viewpoint_of_the_box_rule(scene):
    from wirescene.fitting.own_boxes import own_detections, with_rule_viewpoints
    from wirescene.predetect import detect_cars

    image, camera, bank = scene["image"], scene["camera"], scene["bank"]
    raw = detect_cars(image, bank=bank, camera=camera)
    own = own_detections(camera, image, bank=bank)
    assert len(raw) >= 3
    assert np.array_equal(own.boxes, raw.boxes) and np.array_equal(own.scores, raw.scores)
    expected = box_viewpoints(bank, image, raw.boxes, camera=camera, classifier=load_default_classifier())
    assert np.allclose(own.alpha, expected)
    # detections made elsewhere, with the pyramid and response maps they came from (`wirescene detect --out`)
    pyramid, maps = bank_pyramid(bank, image), {}
    kept = detect_cars(image, bank=bank, camera=camera, pyramid=pyramid, responses=maps)
    given = with_rule_viewpoints(camera, image, kept, bank=bank, pyramid=pyramid, responses=maps)
    assert np.array_equal(given.boxes, own.boxes) and np.array_equal(given.alpha, own.alpha)
    # a pyramid alone is read by the detection too, not computed again
    import wirescene.predetect.bank as bank_module

    def no_pyramid(*args, **kwargs):
        raise AssertionError("the given pyramid was computed again")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(bank_module, "bank_pyramid", no_pyramid)
        mp.setattr(bank_module, "feature_pyramid", no_pyramid)
        alone = own_detections(camera, image, bank=bank, pyramid=pyramid)
    assert np.array_equal(alone.boxes, own.boxes) and np.array_equal(alone.alpha, own.alpha)
    # fit_frame's own pre-detection is this one at the fit's lower threshold, its cars verified by the fit
    from dataclasses import replace

    from wirescene.fitting.confidence import car_probabilities
    from wirescene.fitting.options import FitOptions, PredetectOptions

    options = FitOptions()
    at_fit = own_detections(camera, image, bank=bank, threshold=options.predetect.threshold,
                            upsample=options.predetect.upsample)
    assert len(at_fit) >= len(own)
    fit = fit_frame(camera, None, ["coarse"], image=image)
    assert np.array_equal(fit.detections.boxes, at_fit.boxes) and np.allclose(fit.detections.alpha, at_fit.alpha)
    unverified = fit_frame(camera, None, ["coarse"], image=image,
                           options=replace(options, predetect=PredetectOptions(min_car_probability=0)))
    est = unverified.estimates["coarse"]
    assert len(est.objects) == len(at_fit)
    likely = [o.detection_index for o, p in zip(est.objects, car_probabilities(est, fine=False)) if p >= 0.5]
    assert [o.detection_index for o in fit.estimates["coarse"].objects] == likely
    # no camera, no road prior: the detector's own viewpoints stay
    assert np.array_equal(own_detections(None, image, bank=bank).alpha, detect_cars(image, bank=bank).alpha)


def test_crop_classifier_contract_storage_and_mirror_training(scene, tmp_path):
    image, boxes = scene["image"], scene["boxes"]
    x = crop_viewpoint_features(image, boxes)
    assert x.shape[0] == len(boxes) and np.all(np.isfinite(x))
    with pytest.raises(ShapeError):
        crop_viewpoint_features(image, boxes[:, :3])
    model = load_default_classifier()
    lp = model.log_probs(image, boxes)
    assert lp.shape == (len(boxes), 8) and np.allclose(np.exp(lp).sum(1), 1.0)
    with pytest.raises(ShapeError):
        model.log_probs_of_features(x[:, :-1])
    path = model.save(tmp_path / "vc.npz")
    assert np.allclose(ViewpointClassifier.load(path).log_probs_of_features(x), model.log_probs_of_features(x))
    (tmp_path / "bad.npz").write_bytes(b"not a model")
    with pytest.raises(InputError):
        ViewpointClassifier.load(tmp_path / "bad.npz")
    # trained on one frame's cars, their mirror images and jittered copies: each car's bin and its mirror
    ds = KittiDataset(KITTI_ROOT)
    feats, bins = kitti_examples(ds, [FRAME])
    n = sum(o.type == "Car" for o in ds.labels(FRAME).objects)
    assert len(feats) == 4 * n
    truth = viewpoint_bin(np.array([o.alpha for o in ds.labels(FRAME).objects if o.type == "Car"]))
    assert list(bins[:n]) == list(truth) and list(bins[2 * n:3 * n]) == list((4 - truth) % 8)
    fitted = fit_viewpoint_classifier(feats, bins, C=1.0)
    assert np.mean(fitted.log_probs_of_features(feats).argmax(1) == bins) > 0.9


def _row_objective(scores, bins, boxes, camera, weight):
    """The quantity row_coherent_bins maximises, written out pair by pair."""
    from wirescene.predetect.box_viewpoints import ROW_DEPTH, ROW_WIDTH

    x, z = box_ground_positions(boxes, camera)
    heading = bin_center(bins) + np.arctan2(x, z)
    total = float(scores[np.arange(len(bins)), bins].sum())
    for i in range(len(bins)):
        for j in range(i + 1, len(bins)):
            if abs(z[i] - z[j]) < ROW_DEPTH:
                near = np.exp(-0.5 * ((x[i] - x[j]) / ROW_WIDTH) ** 2)
                total += weight * near * np.cos(heading[i] - heading[j])
    return total


def test_cars_of_one_row_share_their_heading():
    camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    # a row ahead (x ~ 0 m at 10, 17 and 27 m) and a car 12 m to the right at 20 m
    boxes = np.array([[540.0, 110, 660, 218], [565.0, 140, 635, 204], [580.0, 155, 620, 195],
                      [1010.0, 150, 1110, 204]])
    x, z = box_ground_positions(boxes, camera)
    assert_close(z[:3], [10.0, 16.875, 27.0], atol=1e-9)
    assert np.all(np.abs(x[:3]) < 0.1) and x[3] > 11
    scores = np.full((4, 8), -20.0)
    scores[0, 6] = scores[1, 6] = 0.0  # clearly seen from the back
    scores[2, [2, 6]] = [-0.3, -0.6]  # barely front rather than back
    scores[3, [2, 6]] = [-0.3, -0.6]  # the same, but in no row
    alone = row_coherent_bins(scores, boxes, camera, weight=0.0)
    assert alone.tolist() == [6, 6, 2, 2] and np.array_equal(alone, np.argmax(scores, 1))
    rows = row_coherent_bins(scores, boxes, camera)
    assert rows.tolist() == [6, 6, 6, 2]
    assert _row_objective(scores, rows, boxes, camera, ROW_WEIGHT) > _row_objective(scores, alone, boxes, camera,
                                                                                    ROW_WEIGHT)
    # a confident front is not overruled by its row (two cars agreeing weigh 2 x 2 x ROW_WEIGHT)
    scores[2, [2, 6]] = [0.0, -4.5 * ROW_WEIGHT]
    assert row_coherent_bins(scores, boxes, camera).tolist() == [6, 6, 2, 2]
    # one box, or none
    assert row_coherent_bins(scores[:1], boxes[:1], camera).tolist() == [6]
    assert row_coherent_bins(np.zeros((0, 8)), np.zeros((0, 4)), camera).shape == (0,)
    with pytest.raises(ShapeError, match="scores"):
        row_coherent_bins(scores[:, :7], boxes, camera)
    with pytest.raises(ShapeError, match="scores"):
        row_coherent_bins(scores[:3], boxes, camera)


def test_the_rows_never_lower_the_frames_objective(scene):
    rng = np.random.default_rng(3)
    boxes, camera = scene["boxes"], scene["camera"]
    for _ in range(20):
        scores = rng.normal(0.0, 1.5, (len(boxes), 8))
        got = row_coherent_bins(scores, boxes, camera)
        assert _row_objective(scores, got, boxes, camera, ROW_WEIGHT) >= \
            _row_objective(scores, np.argmax(scores, 1), boxes, camera, ROW_WEIGHT) - 1e-9
