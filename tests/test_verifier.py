"""The verifier: a second look at every detection box, stored with the bank, weighted by its calibration."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.errors import InputError
from wirescene.predetect.bank import DetectorBank, detect_pyramid, load_default_bank, verification_logits
from wirescene.predetect.configurations import Configuration
from wirescene.predetect.hog import N_FEAT
from wirescene.predetect.verifier import N_VIEW_GROUPS, VIEW_GROUPS, fit_verifier, verifier_features, verifier_logits
from wirescene.training.kitti_detector import check_calibration, fit_platt, set_calibration


def _small_bank(seed=0):
    rng = np.random.default_rng(seed)
    configs = [Configuration(2, tuple(range(36)), (4, 6), np.zeros(4), np.ones(2), 1.0, 10)]
    weights = [rng.normal(size=(4, 6, N_FEAT)).astype(np.float32)]
    return DetectorBank(configs, weights, np.array([-1.0], np.float32), 0.25, {"seed": seed})


def _scenes(rng, n):
    """Grey images with one bright textured rectangle each: its box (a 'car') and a box of
    the same size elsewhere on the background."""
    out = []
    for _ in range(n):
        img = rng.uniform(0.0, 0.15, (160, 320)).astype(np.float32)
        w, h = rng.uniform(60, 100), rng.uniform(30, 50)
        x, y = rng.uniform(20, 140 - w), rng.uniform(30, 160 - 30 - h)
        img[int(y):int(y + h), int(x):int(x + w)] += 0.5 + 0.2 * rng.uniform(size=(int(y + h) - int(y), int(x + w) - int(x)))
        car = np.array([int(x), int(y), int(x + w), int(y + h)], float)
        out.append((img, car, car + [170, 0, 170, 0]))
    return out


def _features(scenes):
    geometry = np.zeros((2, 3))
    X = np.concatenate([verifier_features(img, np.stack([car, bg]), geometry) for img, car, bg in scenes])
    return X, np.tile([1, 0], len(scenes))


def test_verifier_tells_the_object_from_background_on_new_images():
    rng = np.random.default_rng(0)
    X, y = _features(_scenes(rng, 40))
    verifier = fit_verifier(X, y)
    assert verifier["weights"].shape == (X.shape[1] + 1,) and verifier["mean"].shape == (X.shape[1],)
    Xt, yt = _features(_scenes(rng, 20))
    logits = verifier_logits(verifier, Xt)
    assert logits.shape == (40,) and np.mean((logits > 0) == yt) >= 0.9
    with pytest.raises(ValueError, match="verifier weights"):  # weights of another feature set
        verifier_logits({**verifier, "weights": verifier["weights"][:-3]}, Xt)
    with pytest.raises(ValueError, match="both cars and non-cars"):
        fit_verifier(X[y == 1], y[y == 1])


def test_one_regression_per_viewpoint_group_is_each_groups_own_fit():
    """The grouped verifier gives every row the logit of the regression fitted on its group's
    rows alone (re-expressed exactly on the standardisation of all rows); a group without
    both classes falls back on the regression of all rows."""
    rng = np.random.default_rng(4)
    n, F = 600, 6
    g = rng.integers(0, 2, n)  # group 2 has no rows
    y = rng.integers(0, 2, n)
    # the groups need opposite weights: no single regression fits both
    X = rng.normal(size=(n, F)) * rng.uniform(0.5, 3.0, F) + 2.0 + np.where(g == 0, 1.0, -1.0)[:, None] * y[:, None]
    v = fit_verifier(X, y, C=1.0, groups=g)
    assert v["weights"].shape == (N_VIEW_GROUPS, F + 1)
    for j in (0, 1):
        own = fit_verifier(X[g == j], y[g == j], C=1.0)
        assert_close(verifier_logits(v, X[g == j], groups=g[g == j]), verifier_logits(own, X[g == j]), atol=1e-3)
    everyone = fit_verifier(X, y, C=1.0)
    assert_close(v["weights"][2], everyone["weights"])
    grouped_right = np.mean((verifier_logits(v, X, groups=g) > 0) == y)
    assert grouped_right > np.mean((verifier_logits(everyone, X) > 0) == y) + 0.2
    with pytest.raises(ValueError, match="needs the rows' groups"):
        verifier_logits(v, X)
    with pytest.raises(ValueError, match="groups must be integers"):
        fit_verifier(X, y, groups=np.full(n, N_VIEW_GROUPS))
    assert VIEW_GROUPS.tolist() == [0, 1, 2, 1, 0, 1, 2, 1]  # mirror images share a group


def test_bank_verifier_round_trip_and_format_3_banks(tmp_path):
    bank = _small_bank()
    F = 12
    rng = np.random.default_rng(1)
    bank.verifier = {"mean": rng.normal(size=F).astype(np.float32), "scale": np.ones(F, np.float32),
                     "weights": rng.normal(size=F + 1).astype(np.float32), "gain": np.float32(0.3)}
    path = bank.save(tmp_path / "v.npz")
    with np.load(path, allow_pickle=False) as z:
        assert str(z["format"]) == "wirescene-detector-bank/6"
        arrays = {k: z[k] for k in z.files if k != "format"}
    back = DetectorBank.load(path)
    for k in ("mean", "scale", "weights", "gain"):
        np.testing.assert_array_equal(back.verifier[k], bank.verifier[k])
    assert not back.needs_channels
    bank.verifier["channels"] = True
    assert DetectorBank.load(bank.save(tmp_path / "c.npz")).needs_channels
    # banks of formats 4 (one regression) and 5 read the same, with a grey verifier; a grouped verifier round-trips
    for version in (4, 5):
        old = {k: v for k, v in arrays.items() if k != "verify_channels"}
        np.savez(tmp_path / f"v{version}.npz", format=np.array(f"wirescene-detector-bank/{version}"), **old)
        back = DetectorBank.load(tmp_path / f"v{version}.npz")
        np.testing.assert_array_equal(back.verifier["weights"], bank.verifier["weights"])
        assert not back.needs_channels
    bank.verifier["weights"] = rng.normal(size=(N_VIEW_GROUPS, F + 1)).astype(np.float32)
    back = DetectorBank.load(bank.save(tmp_path / "g.npz"))
    np.testing.assert_array_equal(back.verifier["weights"], bank.verifier["weights"])
    # a bank written before the verifier (format 3) reads as one without
    old = {k: v for k, v in arrays.items() if not k.startswith("verify_")}
    np.savez(tmp_path / "v3.npz", format=np.array("wirescene-detector-bank/3"), **old)
    assert DetectorBank.load(tmp_path / "v3.npz").verifier is None
    # mismatched arrays, and a foreign format, are errors naming the file
    np.savez(tmp_path / "bad.npz", format=np.array("wirescene-detector-bank/6"),
             **{**arrays, "verify_scale": np.ones(F + 2, np.float32)})
    with pytest.raises(InputError, match="bad.npz: detector bank verifier arrays do not match"):
        DetectorBank.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "v9.npz", format=np.array("wirescene-detector-bank/9"), **arrays)
    with pytest.raises(InputError, match="v9.npz: format 'wirescene-detector-bank/9', expected 'wirescene-detector-bank/6'"):
        DetectorBank.load(tmp_path / "v9.npz")
    np.savez(tmp_path / "bad_groups.npz", format=np.array("wirescene-detector-bank/6"),
             **{**arrays, "verify_weights": np.ones((2, F + 1), np.float32)})
    with pytest.raises(InputError, match="bad_groups.npz: detector bank verifier arrays do not match"):
        DetectorBank.load(tmp_path / "bad_groups.npz")


def test_calibration_sets_the_verifier_gain_and_refuses_what_does_not_fit():
    bank = _small_bank()
    with pytest.raises(ValueError, match="without a verifier takes 2"):
        set_calibration(bank, [2.0, -1.0, 0.5])
    set_calibration(bank, [2.0, -1.0])
    assert_close(bank.calibration, [2.0, -1.0])
    bank.verifier = {"mean": np.zeros(3), "scale": np.ones(3), "weights": np.zeros(4), "gain": np.float32(0)}
    with pytest.raises(ValueError, match="with a verifier takes 3"):
        set_calibration(bank, [2.0, -1.0])
    set_calibration(bank, [2.0, -1.0, 0.5])
    assert float(bank.verifier["gain"]) == pytest.approx(0.25) and bank.calibration.shape == (2,)
    for bad in ([0.0, 1.0], [1.0, 2.0, -0.1], [1.0], [1.0, np.nan], ["a", "b"], None):
        with pytest.raises(ValueError, match="a calibration is"):
            check_calibration(bad)


def test_platt_recovers_the_verifier_weight():
    rng = np.random.default_rng(3)
    s, v, off = rng.normal(0, 1, 6000), rng.normal(0, 1.5, 6000), rng.normal(0, 1, 6000)
    y = rng.uniform(size=6000) < 1 / (1 + np.exp(-(2.0 * s - 1.0 + 0.8 * v + off)))
    a, b, c = fit_platt(s, y, offset=off, verifier=v)
    assert a == pytest.approx(2.0, abs=0.25) and b == pytest.approx(-1.0, abs=0.2) and c == pytest.approx(0.8, abs=0.1)


def test_gain_adds_the_weighted_logit_to_every_margin():
    """With a grey image (and the colour channels its verifier reads), each detection's
    margin gains exactly gain x the verifier's logit of its final box (the shipped bank's
    verifier); without one, nothing."""
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.channels import integral_channels
    from wirescene.predetect.hog import feature_pyramid, pyramid_scales, to_gray

    bank = load_default_bank()
    assert bank.verifier is not None and float(bank.verifier["gain"]) > 0
    ds = KittiDataset(KITTI_ROOT)
    img = ds.image("000010")
    H, W = img.shape[:2]
    gray = to_gray(img)
    pyr = feature_pyramid(img, pyramid_scales(W, H, max_scale=float(bank.meta["max_scale"]),
                                              per_octave=int(bank.meta["per_octave"])))
    channels = integral_channels(img) if bank.needs_channels else None
    kw = dict(calibrated=False, cross_view_nms=None, min_height=float(bank.meta["min_height"]), gray=gray,
              channels=channels)
    off = DetectorBank(bank.configs, bank.weights, bank.biases, meta=dict(bank.meta), calibration=bank.calibration,
                       refinement=bank.refinement, verifier={**bank.verifier, "gain": np.float32(0.0)})
    plain, verified = detect_pyramid(off, pyr, (W, H), **kw), detect_pyramid(bank, pyr, (W, H), **kw)
    key = lambda d: np.lexsort(d.boxes.T[::-1])  # noqa: E731
    p, v = key(plain), key(verified)
    assert_close(verified.boxes[v], plain.boxes[p])
    from wirescene.core.viewpoints import viewpoint_bin

    logits = verification_logits(bank, gray, plain.boxes[p], viewpoint_bin(plain.alpha[p]), channels=channels)
    assert_close(verified.scores[v] - plain.scores[p], float(bank.verifier["gain"]) * logits, atol=1e-5)
    # the labelled cars' boxes look more like cars to it than the same boxes moved into the sky
    cars = np.array([o.box for o in ds.labels("000010").objects if o.type == "Car"])
    sky = cars.copy()
    sky[:, [1, 3]] -= cars[:, [3]] - 10
    bins = np.full(len(cars), 2)
    assert (np.median(verification_logits(bank, gray, cars, bins, channels=channels))
            > np.median(verification_logits(bank, gray, sky, bins, channels=channels)))
    if bank.needs_channels:
        with pytest.raises(ValueError, match="reads the image's colour channels"):
            verification_logits(bank, gray, cars, bins)


def test_train_detector_refuses_a_calibration_without_the_verifier_weight(tmp_path):
    """The recipe trains a verifier, so a given calibration is [a, b, c]: a pair, or a
    malformed triple, is a one-line error before any training, and nothing is written."""
    from click.testing import CliRunner

    from wirescene.cli.main import main

    for bad, says in (("1,2", "is [a, b, c]"), ("1,a,2", "finite numbers"), ("1,2,-1", "c >= 0")):
        r = CliRunner().invoke(main, ["train", "detector", "--kitti-root", str(KITTI_ROOT), "--calibration", bad,
                                      "--out", str(tmp_path / "bank.npz")])
        lines = r.stderr.strip().splitlines()
        assert r.exit_code == 2 and len(lines) == 1, r.stderr
        assert lines[0].startswith("wirescene: error: --calibration") and says in lines[0], lines[0]
        assert not (tmp_path / "bank.npz").exists()


def test_an_image_without_boxes_gives_no_rows():
    from wirescene.predetect.bank import regression_features

    boxes = np.zeros((0, 4))
    X = verifier_features(np.zeros((60, 80), np.float32), boxes, regression_features(boxes, np.zeros(0, int), (80, 60)))
    assert X.shape[0] == 0 and X.shape[1] > 0
