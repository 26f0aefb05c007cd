"""Cars near a viewpoint bin's edge shared with the neighbouring bin (``train_bank_on_frames(share_deg=)``)."""

import numpy as np

from conftest import KITTI_ROOT
from wirescene.core.viewpoints import BIN_WIDTH, bin_center, viewpoint_bin
from wirescene.io.kitti import KittiDataset
from wirescene.predetect.configurations import CarExample, mirror_alpha, mirror_bin
from wirescene.training.kitti_detector import load_training_frames, shared_examples


def _example(alpha: float, b: int | None = None) -> CarExample:
    box = np.array([0.0, 0.0, 10.0, 10.0])
    b = int(viewpoint_bin(alpha)) if b is None else b
    return CarExample(0, False, b, np.zeros((36, 2)), np.ones(36, bool), np.ones(36, bool), box, 0.0, 0.0, alpha=alpha)


def test_cars_near_a_bins_edge_join_the_neighbouring_bin():
    deg = np.radians
    cars = [_example(bin_center(2) + deg(20)), _example(bin_center(2) - deg(18)), _example(bin_center(2) + deg(10)),
            _example(float(bin_center(0)) - deg(21)), _example(float("nan"), 3)]  # unknown angle: never shared
    none = np.zeros(8, bool)
    assert shared_examples(cars, 0.0, skip=none) == []
    assert [e.bin for e in shared_examples(cars, 5.0, skip=none)] == [3, 1, 7]  # 20, -18 and -21 deg off centre
    assert [e.bin for e in shared_examples(cars, 13.0, skip=none)] == [3, 1, 3, 7]
    skip = none.copy()
    skip[7] = True  # a sparse bin already borrows all its neighbours' cars
    shared = shared_examples(cars, 5.0, skip=skip)
    assert [e.bin for e in shared] == [3, 1]
    assert [e.alpha for e in shared] == [cars[0].alpha, cars[1].alpha]  # copies: the car itself, another bin


def test_training_examples_carry_their_observation_angle_mirrored_too():
    ds = KittiDataset(KITTI_ROOT)
    frame = ds.frame_ids()[0]
    images, examples = load_training_frames(ds, [frame], flips=True)
    cars = [o for o in ds.labels(frame).objects if o.type == "Car"]
    plain = [e for e in examples if not e.flipped]
    assert len(plain) == len(cars) and all(np.isfinite(e.alpha) for e in examples)
    for e, m in zip(plain, [e for e in examples if e.flipped]):
        assert viewpoint_bin(e.alpha) == e.bin and viewpoint_bin(m.alpha) == m.bin == mirror_bin(e.bin)
        assert abs(m.alpha - mirror_alpha(e.alpha)) < 1e-12 and -np.pi <= m.alpha < np.pi
    assert abs(mirror_alpha(BIN_WIDTH / 2) - (np.pi - BIN_WIDTH / 2)) < 1e-12
