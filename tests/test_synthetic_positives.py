"""Rendered cars as extra positives of the detector bank (``train_bank_on_frames(synthetic=...)``)."""

import wirescene.training.kitti_detector as kd
from conftest import KITTI_ROOT, TINY_BANK
from wirescene.io.kitti import KittiDataset
from wirescene.synth.generate import generate_dataset


def test_rendered_cars_join_the_positives_and_never_the_negatives(tmp_path, monkeypatch):
    generate_dataset(tmp_path, 2, seed=1000, cars=(3, 4), occluders=False)
    synth = KittiDataset(tmp_path)
    s_images, s_examples = kd.load_training_frames(synth, synth.frame_ids())
    assert len(s_images) == 4 and len(s_examples) >= 8  # both scenes and their mirror images

    images, examples = kd.load_training_frames(KittiDataset(KITTI_ROOT), ["000010", "001545"])
    mined = []
    hard = kd.hard_negatives
    monkeypatch.setattr(kd, "hard_negatives", lambda bank, image, **kw: mined.append(image.key) or hard(bank, image, **kw))
    bank = kd.train_bank_on_frames(images, examples, **TINY_BANK, synthetic=(s_images, s_examples))
    assert sorted(mined) == sorted(im.key for im in images)  # the rendered images are never mined
    assert bank.meta["synthetic_examples"] == len(s_examples)
    assert bank.meta["frames"] == ["000010", "001545"]

    plain = kd.train_bank_on_frames(images, examples, **TINY_BANK)
    assert "synthetic_examples" not in plain.meta
    assert sum(bank.meta["n_positives"]) > sum(plain.meta["n_positives"])
    assert sum(bank.meta["car_examples_per_bin"]) == sum(plain.meta["car_examples_per_bin"]) + len(s_examples)
