"""Cut-and-paste augmentation of real training frames (wirescene.training.cut_paste)."""

from __future__ import annotations

import numpy as np

from conftest import KITTI_ROOT, assert_close
from wirescene.io.kitti import KittiDataset
from wirescene.predetect.geometry import bottom_ratio
from wirescene.training.cut_paste import car_silhouette, paste_cars
from wirescene.training.kitti_detector import load_training_frames, mirrored_boxes, mirrored_image

FRAMES = ["000010", "001545", "000002"]


def test_car_silhouette_is_the_feathered_hull_of_the_vertices():
    v = np.array([[10.0, 10.0], [50.0, 10.0], [50.0, 30.0], [10.0, 30.0], [30.0, 20.0]])
    m = car_silhouette(v, (40, 60))
    assert m.shape == (40, 60) and m.min() >= 0.0 and m.max() <= 1.0
    assert m[20, 30] > 0.99 and m[2, 2] == 0.0 and m[35, 55] == 0.0
    assert 0.1 < m[10, 30] < 0.9  # the edge is feathered


def test_pasted_cars_stand_on_the_road_of_their_new_frame():
    ds = KittiDataset(KITTI_ROOT)
    images, examples = load_training_frames(ds, FRAMES)
    new_images, new_examples = paste_cars(images, examples, per_image=3, seed=0, mirror=mirrored_image)
    assert len(new_images) >= 4 and len(new_images) % 2 == 0 and len(new_examples) >= 8
    donors = [e for e in examples if not e.flipped and e.clean]
    for k in range(0, len(new_images), 2):
        comp, flip = new_images[k], new_images[k + 1]
        index = len(images) + k
        assert comp.composite and not comp.flipped and flip.flipped
        target = next(im for im in images if im.frame == comp.frame and not im.flipped)
        pasted = [e for e in new_examples if e.image == index]
        assert pasted and all(not e.flipped for e in pasted)
        boxes = np.array([e.label_box for e in pasted])
        # nothing labelled in the target is covered, and the composite keeps its pixels outside the pasted cars
        occ = target.occupied
        inter = ((np.minimum(boxes[:, None, 2], occ[None, :, 2]) > np.maximum(boxes[:, None, 0], occ[None, :, 0]))
                 & (np.minimum(boxes[:, None, 3], occ[None, :, 3]) > np.maximum(boxes[:, None, 1], occ[None, :, 1])))
        assert not inter.any()
        outside = np.ones(comp.gray.shape, bool)
        for b in boxes:
            outside[max(int(b[1]) - 6, 0):int(b[3]) + 7, max(int(b[0]) - 6, 0):int(b[2]) + 7] = False
        assert np.array_equal(comp.gray[outside], target.gray[outside])
        assert (comp.gray[~outside] != target.gray[~outside]).mean() > 0.3
        # each pasted car is a donor of another frame, scaled, at the same ratio (bottom - horizon) / height
        for e in pasted:
            r = bottom_ratio(e.label_box, comp.horizon)[0]
            aspect = (e.label_box[2] - e.label_box[0]) / (e.label_box[3] - e.label_box[1])
            match = [d for d in donors if images[d.image].frame != comp.frame and d.bin == e.bin
                     and np.array_equal(d.visible, e.visible)
                     and abs(bottom_ratio(d.label_box, images[d.image].horizon)[0] - r) < 0.03
                     and abs((d.label_box[2] - d.label_box[0]) / (d.label_box[3] - d.label_box[1]) - aspect) < 0.03 * aspect]
            assert match, e.label_box
        # the mirrored composite and its cars
        W = comp.gray.shape[1]
        assert np.array_equal(flip.gray, comp.gray[:, ::-1])
        mirrored = [e for e in new_examples if e.image == index + 1]
        assert_close(np.array([e.label_box for e in mirrored]), mirrored_boxes(boxes, W))
        assert sorted((e.bin + m.bin) % 8 for e, m in zip(pasted, mirrored)) == [4] * len(pasted)
    # the same seed pastes the same cars
    again_images, again = paste_cars(images, examples, per_image=3, seed=0, mirror=mirrored_image)
    assert all(np.array_equal(a.gray, b.gray) for a, b in zip(again_images, new_images))
    assert_close(np.array([e.label_box for e in again]), np.array([e.label_box for e in new_examples]))


def test_bank_training_takes_pasted_cars_as_extra_positives():
    from wirescene.training.kitti_detector import train_bank_on_frames

    ds = KittiDataset(KITTI_ROOT)
    kw = dict(n_partial=0, mining_rounds=0, neg_per_image=5, min_pos=1, max_jitter=0, min_height=40.0,
              max_scale=1.0, per_octave=4)
    images, examples = load_training_frames(ds, FRAMES)
    plain = train_bank_on_frames(images, examples, **kw)
    images, examples = load_training_frames(ds, FRAMES)
    said = []
    pasted = train_bank_on_frames(images, examples, cut_paste=3, progress=said.append, **kw)
    assert any(m.startswith("cut and paste:") for m in said)
    assert pasted.meta["cut_paste"] == 3 and plain.meta["cut_paste"] == 0
    assert pasted.meta["frames"] == plain.meta["frames"] == sorted(FRAMES)  # composites are not frames
    assert sum(pasted.meta["n_positives"]) > sum(plain.meta["n_positives"])
    assert len(images) == 2 * len(FRAMES)  # the caller's list is left alone
