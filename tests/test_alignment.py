"""Latent placement of the detector's positive windows (``train_bank_on_frames(align=True)``)."""

import numpy as np

from conftest import KITTI_ROOT, TINY_BANK, assert_close
from wirescene.training.detector import align_positives, alignment_offsets, moved_box


def test_moved_box_shifts_by_cells_and_scales_about_the_centre():
    box = np.array([10.0, 20.0, 130.0, 60.0])  # a 4 x 12-cell window of 10 px cells
    assert_close(moved_box(box, (0, 0, 0), 4, 12), box)
    assert_close(moved_box(box, (1, -0.5, 0), 4, 12), box + [10, -5, 10, -5])
    assert_close(moved_box(box, (0, 0, 1), 4, 12), [-50.0, 0.0, 190.0, 80.0])
    offsets = alignment_offsets()
    assert offsets.shape == (27, 3) and np.all(offsets[0] == 0)
    assert len({tuple(o) for o in offsets}) == 27


def test_align_positives_keeps_each_positives_best_window():
    rng = np.random.default_rng(0)
    cands = [rng.normal(size=(5, 27, 12)).astype(np.float32), np.zeros((0, 27, 6), np.float32)]
    weights = [rng.normal(size=(2, 2, 3)), np.zeros((1, 2, 3))]
    pos = align_positives(cands, weights)
    scores = cands[0] @ weights[0].ravel().astype(np.float32)
    assert_close(pos[0] @ weights[0].ravel().astype(np.float32), scores.max(1))
    assert pos[0].shape == (5, 12) and pos[1].shape == (0, 6)


def test_aligned_training_starts_from_the_plain_positives_and_moves_some():
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.detector import positive_features
    from wirescene.training.kitti_detector import load_training_frames, train_bank_on_frames

    images, examples = load_training_frames(KittiDataset(KITTI_ROOT), ["000010", "001545"])
    bank = train_bank_on_frames(images, examples, **TINY_BANK, align=True)
    plain = train_bank_on_frames(images, examples, **TINY_BANK)
    assert bank.meta["align"] and "align" not in plain.meta
    assert bank.meta["n_positives"] == plain.meta["n_positives"]

    configs = bank.configs
    gray = {(e.image, e.flipped): images[e.image].gray.astype(np.float32) / 255 for e in examples}
    opts = dict(min_height=40.0, max_pos=600, min_pos=20, max_jitter=6, max_occluded=0.35, max_truncated=0.15)
    flat, _ = positive_features(configs, examples, lambda e: gray[e.image, e.flipped],
                                np.random.default_rng(5), **opts)
    cands, _ = positive_features(configs, examples, lambda e: gray[e.image, e.flipped],
                                 np.random.default_rng(5), **opts, offsets=alignment_offsets())
    t = int(np.argmax([len(p) for p in flat]))
    assert cands[t].shape == (len(flat[t]), 27, flat[t].shape[1])
    assert_close(cands[t][:, 0], flat[t])  # the unmoved windows are the plain positives
    # under the trained template many positives prefer a moved window (24 positives: 10 here)
    aligned = align_positives(cands, bank.weights)[t]
    w = np.asarray(bank.weights[t], np.float32).ravel()
    assert np.all(aligned @ w >= flat[t] @ w - 1e-5)
    assert np.mean(aligned @ w > flat[t] @ w + 1e-6) > 0.25
