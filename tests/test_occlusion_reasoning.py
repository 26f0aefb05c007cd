import numpy as np

from conftest import KITTI_ROOT, assert_close
from wirescene.io.kitti import KittiDataset
from wirescene.infer.masks import all_mask_hidden, fit_mask, mask_hidden, mask_weight_sums, normalised_coordinates, occluder_masks
from wirescene.training.occlusion import occlusion_accuracy_by_c
from wirescene.infer.inference import update_occlusion
from wirescene.core.types import SceneParticles
from wirescene.infer.inference import _to_viewing
from wirescene.core.shape import load_default

rng = np.random.default_rng(0)
UV = rng.uniform([100, 50], [300, 120], size=(36, 2))


def test_mask_set_is_deterministic_and_covers_the_modes():
    m = occluder_masks()
    assert len(m) >= 200 and len(np.unique(m, axis=0)) == len(m)
    assert np.all(m[0] == 0) and not mask_hidden(UV, 0).any()  # a0 hides nothing
    q = normalised_coordinates(UV)
    left = np.flatnonzero((m[:, 0] == 0) & (m[:, 1] == 0) & (m[:, 3] == 1) & np.isclose(m[:, 2], 0.5))[0]
    assert np.array_equal(mask_hidden(UV, left), q[:, 0] <= 0.5)
    bottom = np.flatnonzero((m[:, 0] == 0) & (m[:, 2] == 1) & (m[:, 3] == 1) & np.isclose(m[:, 1], 0.6))[0]
    assert np.array_equal(mask_hidden(UV, bottom), q[:, 1] >= 0.6)
    assert all_mask_hidden(UV).shape == (len(m), 36)
    np.testing.assert_array_equal(all_mask_hidden(UV)[left], mask_hidden(UV, left))


def test_fit_mask_recovers_a_mask_pattern():
    m = occluder_masks()
    for a in (5, 40, 120, len(m) - 3):
        occluded = mask_hidden(UV, a)
        fitted = fit_mask(UV, occluded, np.ones(36, bool))
        np.testing.assert_array_equal(mask_hidden(UV, fitted), occluded)


def test_occluded_score_choice_separates_evidence():
    # Visible parts score +1, parts hidden by a left band score -3: any c between the
    # two predicts the band exactly; c above +1 hides everything, below -3 nothing.
    occl = normalised_coordinates(UV)[:, 0] <= 0.4
    evidence = np.where(occl, -3.0, 1.0)[None]
    acc = occlusion_accuracy_by_c(evidence, np.zeros((1, 36), bool), ~occl[None], UV[None], [-5.0, -1.0, 0.0, 3.0])
    assert acc[1] == 1.0 and acc[2] == 1.0
    assert acc[0] < 1.0 and acc[3] < 1.0


class _Flat:
    def log_ratio(self, uv, obj, scale):
        return np.zeros(uv.shape[:-1])


def test_deterministic_occlusion_hides_the_car_behind():
    camera = KittiDataset(KITTI_ROOT).camera("000010")
    model = load_default()
    # Two cars on the optical axis, the second 6 m behind the first.
    x, z, az = np.array([[0.0, 0.0]]), np.array([[10.0, 16.0]]), np.array([[0.0, 0.0]])
    p = SceneParticles(np.zeros((1, 2)), np.zeros((1, 2)), x, z, az, np.zeros((1, 2)), np.ones((1, 2, 3)))
    theta = np.zeros((1, 2, 8))
    theta[..., 0], theta[..., 1], theta[..., 2] = _to_viewing(x, z, az)
    mask, gamma = update_occlusion(camera, model, _Flat(), p, theta, 5, -0.5, searched=True, deterministic=True)
    assert gamma[0, 1].sum() >= 5  # the far car is largely hidden by the near one
    assert not gamma[0, 0].any()  # nothing hides the near car
    mask_do, gamma_do = update_occlusion(camera, model, _Flat(), p, theta, 5, -0.5, searched=False, deterministic=True)
    assert gamma_do is None and mask_do[0, 1] != 0 and mask_do[0, 0] == 0


def test_mask_weight_sums_equal_the_explicit_sums_over_all_masks():
    rng = np.random.default_rng(3)
    uv = rng.uniform(0, 300, size=(4, 3, 36, 2))
    w = rng.normal(size=(4, 3, 36))
    explicit = (all_mask_hidden(uv) * w[..., None, :]).sum(axis=-1)
    assert explicit.shape == (4, 3, len(occluder_masks()))
    assert_close(mask_weight_sums(uv, w), explicit, atol=1e-9)
