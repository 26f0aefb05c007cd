"""Training at scale (:mod:`wirescene.training.scale`): bounded caches and negative pools,
bounded real part patches, and per-image passes in worker processes that train the same bank."""

import numpy as np
import pytest

from conftest import KITTI_ROOT, TINY_BANK, kitti_copy
from wirescene.training.detector import mining_subsets
from wirescene.training.scale import FrameCache, NegativePool, can_fork, map_images


def test_negative_pool_below_its_cap_is_the_plain_list_and_draws_nothing():
    rng = np.random.default_rng(3)
    state = rng.bit_generator.state
    pool = NegativePool(10, rng)
    items = [np.full(4, i, np.float32) for i in range(10)]
    for x in items:
        pool.append(x)
    pool.shrink(np.ones(4), 0.0)
    assert [int(x[0]) for x in pool.items] == list(range(10))
    assert rng.bit_generator.state == state


def test_negative_pool_reservoir_never_exceeds_its_cap_and_samples_uniformly():
    counts = np.zeros(100)
    for seed in range(400):
        pool = NegativePool(10, np.random.default_rng(seed))
        for i in range(100):
            pool.add_random(np.array([i], np.float32))
            assert len(pool) <= 10
        counts[[int(x[0]) for x in pool.items]] += 1
    # every window offered is held with probability 10 / 100 (400 draws: 40 +- 6 each)
    assert counts.sum() == 4000
    assert abs(counts[:50].mean() - 40) < 4 and abs(counts[50:].mean() - 40) < 4
    assert counts.min() > 15 and counts.max() < 70


def test_negative_pool_shrink_keeps_the_hardest_in_order():
    rng = np.random.default_rng(0)
    pool = NegativePool(5, rng)
    X = rng.normal(size=(12, 3)).astype(np.float32)
    for x in X:
        pool.add_hard(x)
    w = np.array([1.0, -2.0, 0.5], np.float32)
    pool.shrink(w, 0.3, slack=1.5)  # 12 <= 7.5? no: shrinks
    margin = X @ w + 0.3
    hardest = np.sort(np.argsort(-margin)[:5])
    assert len(pool) == 5
    np.testing.assert_array_equal(np.stack(pool.items), X[hardest])
    pool.add_hard(X[0])
    pool.shrink(w, 0.3, slack=1.5)  # 6 <= 7.5: kept as is
    assert len(pool) == 6


def test_frame_cache_keeps_the_recently_used_within_its_budget():
    cache = FrameCache(max_mb=0.0025)  # 2,500 bytes: two arrays of 1,000
    computed = []

    def make(key):
        computed.append(key)
        return np.zeros(1000, np.uint8)

    for key in ("a", "b", "a", "c", "a", "b"):
        cache.get(key, lambda key=key: make(key))
        assert cache.bytes <= 2500
    # c evicts b (a was used since), then b evicts c
    assert computed == ["a", "b", "c", "b"] and cache.hits == 2 and len(cache) == 2
    cache.put("big", np.zeros(3000, np.uint8))  # larger than the budget: not kept
    assert len(cache) == 2
    cache.resize(0.0)
    assert len(cache) == 0 and cache.bytes == 0


@pytest.mark.skipif(not can_fork(), reason="no fork start method")
def test_map_images_in_workers_keeps_the_order():
    lines = []
    assert list(map_images(np.square, list(range(7)), workers=3, progress=lines.append)) == \
        [i * i for i in range(7)]
    assert list(map_images(np.square, [], workers=3)) == []


def _interrupted(item):
    """How a worker takes Ctrl-C, which reaches every process of the group."""
    import signal

    try:
        signal.raise_signal(signal.SIGINT)
    except SystemExit:  # the process ends without a word (multiprocessing prints no traceback for it)
        return "ends quietly"
    except KeyboardInterrupt:  # the process ends printing a traceback, every worker its own
        return "traceback"
    return "ignored"


@pytest.mark.skipif(not can_fork(), reason="no fork start method")
def test_a_worker_interrupted_by_ctrl_c_ends_without_a_traceback():
    import signal

    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # as a terminal's run has it
    try:
        assert list(map_images(_interrupted, [0, 1], workers=2)) == ["ends quietly"] * 2
    finally:
        signal.signal(signal.SIGINT, before)


@pytest.mark.skipif(not can_fork(), reason="no fork start method")
def test_workers_of_a_parent_that_ignores_ctrl_c_ignore_it_too():
    """A run started in the background of a script ignores Ctrl-C: a worker that ended on it
    would leave the parent waiting for its result for ever."""
    import signal

    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        assert list(map_images(_interrupted, [0, 1], workers=2)) == ["ignored"] * 2
    finally:
        signal.signal(signal.SIGINT, before)


def test_patch_collector_cap_keeps_a_uniform_sample_in_order():
    from wirescene.training.patches import PatchCollector

    def collect(cap):
        patches = PatchCollector(("ghog",), max_patches=cap, seed=1)
        rng = np.random.default_rng(0)
        image = rng.uniform(0, 1, (120, 160, 3)).astype(np.float32)
        for g in range(40):
            pts = rng.uniform(30, 90, (25, 2))
            patches.add(image, np.array([20.0, 20.0, 140.0, 100.0]), pts, g % 37, 1.0, None, g)
        return patches.data(["frame"])

    full, same, capped = collect(None), collect(1000), collect(300)
    assert len(full) == len(same) == 1000
    for a, b in ((full.X["ghog"], same.X["ghog"]), (full.y, same.y), (full.group, same.group)):
        np.testing.assert_array_equal(a, b)
    assert len(capped) == 300 and np.all(np.diff(capped.group) >= 0)  # in the order they came
    rows = {row.tobytes(): i for i, row in enumerate(full.pos)}  # each point's own position in its box
    kept = np.array([rows[row.tobytes()] for row in capped.pos])
    assert len(set(kept.tolist())) == 300 and np.all(np.diff(kept) > 0)
    np.testing.assert_array_equal(full.X["ghog"][kept], capped.X["ghog"])
    np.testing.assert_array_equal(full.group[kept], capped.group)
    # early and late patches alike are kept (150 of 500 each, +- ~10)
    assert abs(int((kept < 500).sum()) - 150) < 35


def _tiny_bank(**options):
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.kitti_detector import finish_bank, load_training_frames, train_bank_on_frames

    ds = KittiDataset(KITTI_ROOT)
    images, examples = load_training_frames(ds, ["000010", "001545"])
    workers = options.get("workers", 1)
    bank = train_bank_on_frames(images, examples, **TINY_BANK, **options)
    return finish_bank(bank, images, ds, workers=workers)


def _arrays(bank):
    meta = {k: v for k, v in bank.meta.items() if k != "train_seconds"}
    return [np.asarray(w) for w in bank.weights] + [bank.biases], meta


@pytest.mark.skipif(not can_fork(), reason="no fork start method")
def test_bank_is_the_same_in_workers_and_without_a_cache():
    from wirescene.training.scale import CACHE

    weights, meta = _arrays(_tiny_bank())
    # nothing cached: every pass reads and describes its images again, in two processes
    again, meta_again = _arrays(_tiny_bank(workers=2, pyramid_cache_mb=0))
    assert len(CACHE) == 0
    assert meta_again == meta and "max_negatives" not in meta
    for a, b in zip(weights, again):
        np.testing.assert_array_equal(a, b)


def test_capped_negatives_bound_every_pool():
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.kitti_detector import load_training_frames, train_bank_on_frames

    images, examples = load_training_frames(KittiDataset(KITTI_ROOT), ["000010", "001545"])
    bank = train_bank_on_frames(images, examples, **TINY_BANK, max_negatives=12)
    assert bank.meta["max_negatives"] == 12 and max(bank.meta["n_negatives"]) == 12


def test_mining_rounds_search_at_most_mining_images_each_and_every_image_between_them(monkeypatch):
    import wirescene.training.kitti_detector as kd
    from wirescene.io.kitti import KittiDataset

    subsets = mining_subsets(10, 3, 4, seed=0)
    assert [len(s) for s in subsets] == [4, 4, 4] and all(np.all(np.diff(s) > 0) for s in subsets)
    assert sorted(set(np.concatenate(subsets).tolist())) == list(range(10))  # 12 slots reach all 10 images
    for cap in (None, 10, 99):  # no cap, or one the images do not reach: every round searches every image
        assert [s.tolist() for s in mining_subsets(10, 2, cap)] == [list(range(10))] * 2
    assert [s.tolist() for s in mining_subsets(10, 3, 4, seed=1)] != [s.tolist() for s in subsets]
    with pytest.raises(ValueError, match="mining_images"):
        mining_subsets(10, 3, 0)

    searched = []
    real = kd.hard_negatives

    def counting(bank, image, **kw):
        searched.append((image.frame, image.flipped))
        return real(bank, image, **kw)

    monkeypatch.setattr(kd, "hard_negatives", counting)
    images, examples = kd.load_training_frames(KittiDataset(KITTI_ROOT), ["000010", "001545"])  # and mirrors: 4
    options = {**TINY_BANK, "mining_rounds": 2}
    plain = kd.train_bank_on_frames(images, examples, **options)
    assert len(searched) == 8 and "mining_images" not in plain.meta
    searched.clear()
    same = kd.train_bank_on_frames(images, examples, **options, mining_images=4)  # not below the images: no cap
    assert len(searched) == 8 and "mining_images" not in same.meta
    for a, b in zip(_arrays(plain)[0], _arrays(same)[0]):
        np.testing.assert_array_equal(a, b)
    searched.clear()
    capped = kd.train_bank_on_frames(images, examples, **options, mining_images=2)
    assert len(searched) == 4 and len(set(searched)) == 4  # two rounds of two: every image once
    assert capped.meta["mining_images"] == 2


def test_padded_training_shows_truncated_cars_as_detection_sees_them():
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.bank import score_pyramid
    from wirescene.predetect.hog import pyramid_scales
    from wirescene.training.detector import outside_cells_zeroed
    from wirescene.training.kitti_detector import load_training_frames, train_bank_on_frames

    f = outside_cells_zeroed(np.ones((2, 4, 31), np.float32), [-20.0, 0.0, 20.0, 10.0], 100)
    assert f[:, :2].max() == 0 and f[:, 2:].min() == 1  # column centres -15, -5 | 5, 15
    # both frames hold a car cut by the image's side (KITTI truncation 0.8 and 0.71)
    images, examples = load_training_frames(KittiDataset(KITTI_ROOT), ["000010", "001545"])
    plain = train_bank_on_frames(images, examples, **TINY_BANK)
    padded = train_bank_on_frames(images, examples, **TINY_BANK, pad_cells=4, max_truncated=0.9)
    assert "pad_cells" not in plain.meta and padded.meta["pad_cells"] == 4
    assert sum(padded.meta["n_positives"]) > sum(plain.meta["n_positives"])
    W, H = images[0].size
    pyramid = images[0].hog_pyramid(pyramid_scales(W, H, max_scale=1.0, per_octave=2))
    act = score_pyramid(padded, pyramid, threshold=-np.inf, min_height=40.0, pad_cells=4)
    width = act.boxes[:, 2] - act.boxes[:, 0]
    inside = np.minimum(act.boxes[:, 2], W) - np.maximum(act.boxes[:, 0], 0)
    assert act.boxes[:, 0].min() < 0 and act.boxes[:, 2].max() > W  # windows past both sides
    assert np.all(inside >= width / 2 - 1e-6)  # each keeps at least half of itself in the image


def test_row_sample_is_the_plain_rows_below_the_cap_and_a_uniform_ordered_sample_above():
    from wirescene.training.scale import RowSample

    rows = RowSample(100, seed=3)
    for i in range(10):
        rows.add(np.arange(i * 5, i * 5 + 5, dtype=float)[:, None], np.full(5, i))
    X, T = rows.arrays()
    assert X[:, 0].tolist() == list(range(50)) and T.tolist() == sorted(T.tolist())

    capped = RowSample(50, seed=3)
    for i in range(100):
        capped.add(np.arange(i * 10, i * 10 + 10, dtype=float)[:, None], np.arange(i * 10, i * 10 + 10))
        assert capped.n <= 75  # never more than 1.5 x the cap held
    X, T = capped.arrays()
    assert len(X) == 50 and capped.offered == 1000
    assert np.all(np.diff(X[:, 0]) > 0)  # arrival order kept
    assert np.all(X[:, 0] == T)  # the columns stay aligned row by row
    assert X[:, 0].min() < 200 and X[:, 0].max() > 800  # spread over the whole stream


def test_training_passes_from_vote_clusters_detect_and_fit_what_whole_passes_do(tmp_path):
    """finish_bank computes each image's vote clusters once and finishes every later pass's
    detections from them: at every stage of the bank those are the whole passes' detections,
    and each step fitted from them is the same, array for array (an image without a car
    among them: the box regression reads only those with one)."""
    from dataclasses import replace

    from wirescene.io.kitti import KittiDataset
    from wirescene.training.kitti_detector import (
        detect_training_image,
        fit_box_refinement,
        fit_box_regression,
        load_training_frames,
        training_clusters,
        training_detections,
        training_gt_boxes,
        verifier_training_rows,
    )

    root = kitti_copy(tmp_path, ["000002", "000010", "001545"])
    (root / "training" / "label_2" / "000002.txt").write_text("")  # a frame without a car
    ds = KittiDataset(root)
    bank = _tiny_bank()
    bank.verifier["gain"] = np.float32(0.5)  # so that the last stage applies it
    images, _ = load_training_frames(ds, ["000002", "000010", "001545"])
    gt = training_gt_boxes(ds, images)
    assert sum(len(g) == 0 for g in gt) > 0 and sum(len(g) > 0 for g in gt) > 0
    templates = replace(bank, meta={k: v for k, v in bank.meta.items() if k != "box_regression"}, refinement=None,
                        verifier=None)
    clusters = [training_clusters(templates, im) for im in images]  # from another bank with the same templates
    stages = [templates, replace(bank, refinement=None, verifier=None), replace(bank, verifier=None), bank]
    for stage in stages:
        for im, c in zip(images, clusters):
            whole, finished = detect_training_image(stage, im), detect_training_image(stage, im, clusters=c)
            assert len(whole) > 0
            for a, b in ((whole.boxes, finished.boxes), (whole.scores, finished.scores), (whole.alpha, finished.alpha)):
                np.testing.assert_array_equal(a, b)
    regression = fit_box_regression(bank, images, gt, clusters=clusters)
    assert regression == fit_box_regression(bank, images, gt) and regression["n"] > 0
    refinement = fit_box_refinement(bank, images, ds, clusters=clusters)
    for key, value in fit_box_refinement(bank, images, ds).items():
        np.testing.assert_array_equal(value, refinement[key])
    plain = replace(bank, verifier=None)
    detections = list(training_detections(plain, images, clusters=clusters))
    for a, b in zip(verifier_training_rows(plain, images, ds, detections=detections),
                    verifier_training_rows(plain, images, ds)):
        np.testing.assert_array_equal(a, b)
