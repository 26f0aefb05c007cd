import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.shape import load_default
from wirescene.core.types import SceneParticles
from wirescene.infer.inference import InferenceOptions, _evaluate, _terms, _to_viewing, update_occlusion
from wirescene.infer.likelihood import outside_image
from wirescene.infer.masks import (
    all_mask_hidden,
    fit_mask,
    mask_hidden,
    mask_weight_sums,
    normalised_coordinates,
    occluder_masks,
)
from wirescene.io.kitti import KittiDataset
from wirescene.training.occlusion import occlusion_accuracy_by_c

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


def _car_at_the_border():
    """Camera, shape model, particles and viewing parameters ``(1, 1, 1, 8)`` of one car at
    the right border of 000010's image, part of it beyond."""
    camera = KittiDataset(KITTI_ROOT).camera("000010")
    x, z, az = np.array([[6.5]]), np.array([[9.0]]), np.array([[0.3]])
    p = SceneParticles(np.zeros((1, 1)), np.zeros((1, 1)), x, z, az, np.zeros((1, 1)), np.ones((1, 1, 3)))
    theta = np.zeros((1, 1, 1, 8))
    theta[..., 0], theta[..., 1], theta[..., 2] = (v[..., None] for v in _to_viewing(x, z, az))
    return camera, load_default(), p, theta


class _Floor:
    """Part evidence of one constant log ratio everywhere."""

    def __init__(self, floor):
        self.floor = floor

    def log_ratio(self, uv, obj, scale):
        return np.full(uv.shape[:-1], self.floor)


def test_parts_outside_the_image_score_c_not_the_evidence():
    # A car at the right image border, part of it beyond: with border occlusion its
    # visible vertices outside the image score c, inside they keep the evidence (here
    # a constant floor), as a mask hiding exactly those vertices would give.
    camera, model, p, theta = _car_at_the_border()
    floor, c = -2.0, 0.75

    terms = _terms(camera, model, _Floor(floor), p, theta, 5, border_occludes=True)
    visible = ~terms.self_hidden[0, 0, 0]
    out = outside_image(camera, terms.uv[0, 0, 0]) & visible
    assert 3 <= out.sum() < visible.sum()  # truncated, not gone
    assert np.array_equal(terms.border[0, 0, 0], out)
    expected = (floor * (visible & ~out).sum() + c * out.sum()) / visible.sum()
    assert_close(_evaluate(camera, model, _Floor(floor), p, theta, 5, c, border_occludes=True)[0, 0, 0], expected)
    assert_close(_evaluate(camera, model, _Floor(floor), p, theta, 5, c)[0, 0, 0], floor)
    # Good evidence inside the image, the floor beyond it: without border occlusion the
    # searched mask must hide the outside vertices; with it, hiding anything costs.

    class _Inside:
        def log_ratio(self, uv, obj, scale):
            return np.where(outside_image(camera, uv), floor, 3.0)

    masks = [update_occlusion(camera, model, _Inside(), p, theta[:, :, 0], 5, c, searched=True, deterministic=False,
                              border_occludes=b)[0][0, 0] for b in (False, True)]
    assert mask_hidden(terms.uv[0, 0, 0], masks[0])[out].mean() > 0.5
    assert masks[1] == 0


def test_parts_hidden_by_known_occluders_score_their_own_c():
    # The border and the scene's other cars (gamma) hide parts for a known reason: with
    # known_c those score known_c, the searched mask's parts keep c, the rest the evidence.
    camera, model, p, theta = _car_at_the_border()
    floor, c, known_c = -2.0, 0.75, 0.25

    terms = _terms(camera, model, _Floor(floor), p, theta, 5, border_occludes=True)
    uv, visible, border = terms.uv[0, 0, 0], ~terms.self_hidden[0, 0, 0], terms.border[0, 0, 0]
    gamma = np.zeros((1, 1, 36), bool)
    gamma[0, 0, np.flatnonzero(visible & ~border)[:3]] = True  # three parts behind another car
    known = border | gamma[0, 0]
    searched = [a for a in range(len(occluder_masks())) if (mask_hidden(uv, a) & visible & ~known).sum() >= 4][0]
    by_mask = mask_hidden(uv, searched) & visible & ~known
    mask = np.full((1, 1), searched)
    free = visible & ~known & ~by_mask
    expected = (floor * free.sum() + c * by_mask.sum() + known_c * (known & visible).sum()) / visible.sum()
    assert_close(terms.value(c, mask, gamma, known_c=known_c)[0, 0, 0], expected)
    assert_close(terms.value(c, mask, gamma, known_c=c)[0, 0, 0], terms.value(c, mask, gamma)[0, 0, 0])
    plain = (floor * free.sum() + c * (visible & ~free).sum()) / visible.sum()
    assert_close(terms.value(c, mask, gamma)[0, 0, 0], plain)
    with pytest.raises(ValueError, match="known_occluded_score"):
        InferenceOptions(known_occluded_score="low")


def test_mask_weight_sums_equal_the_explicit_sums_over_all_masks():
    rng = np.random.default_rng(3)
    uv = rng.uniform(0, 300, size=(4, 3, 36, 2))
    w = rng.normal(size=(4, 3, 36))
    explicit = (all_mask_hidden(uv) * w[..., None, :]).sum(axis=-1)
    assert explicit.shape == (4, 3, len(occluder_masks()))
    assert_close(mask_weight_sums(uv, w), explicit, atol=1e-9)


def test_mask_weight_sums_by_blocks_are_the_whole_batch_product_to_the_bit():
    """mask_weight_sums builds its interval flags for MASK_BLOCK point sets at a time: the
    same sums, to the bit, as the one product over the whole batch it replaced (each point
    set's matrix product is the same BLAS call), with ties on the intervals' ends, signed
    zero weights and a batch that is not a multiple of the block."""
    from wirescene.infer import masks

    rng = np.random.default_rng(5)
    uv = rng.uniform(0, 300, size=(3 * masks.MASK_BLOCK + 7, 2, 36, 2))
    uv[::3, :, ::4] = uv[::3, :, :1]  # vertices on their box's edge
    uv[::5] = np.round(uv[::5] / 30) * 30  # on the masks' 0.05 steps
    w = rng.normal(size=uv.shape[:-1])
    w[::2, :, ::3], w[1::2, :, ::5] = 0.0, -0.0
    xs, ys, i, j, nonempty = masks._factorised_masks()
    q = normalised_coordinates(uv)
    qx, qy = q[..., None, :, 0], q[..., None, :, 1]
    X = ((qx >= xs[:, :1]) & (qx <= xs[:, 1:])) * w[..., None, :]
    Y = ((qy >= ys[:, :1]) & (qy <= ys[:, 1:])).astype(float)
    whole = np.where(nonempty, np.matmul(X, np.swapaxes(Y, -1, -2))[..., i, j], 0.0)
    got = mask_weight_sums(uv, w)
    assert got.shape == whole.shape and got.tobytes() == whole.tobytes()
    assert mask_weight_sums(uv[0, 0], w[0, 0]).tobytes() == whole[0, 0].tobytes()  # one point set, no batch


def test_normalised_coordinates_are_the_whole_rows_to_the_bit():
    """normalised_coordinates works a coordinate at a time: the same values as on whole rows."""
    rng = np.random.default_rng(6)
    uv = rng.uniform(-50, 300, size=(40, 3, 36, 2))
    uv[::4, :, :, 1] = 7.0  # a flat point set: the extent's floor
    lo, hi = uv.min(axis=-2), uv.max(axis=-2)
    want = (uv - lo[..., None, :]) / np.maximum(hi - lo, 1e-9)[..., None, :]
    assert normalised_coordinates(uv).tobytes() == want.tobytes()


@pytest.fixture(scope="module")
def near_and_far():
    """A scene built to need occlusion reasoning: the far car's rear-left is hidden by the near
    car, and perfect evidence is missing exactly there; fitted with fg, fg+so, fg+do and full.
    ``(fit, self_hidden (2, 36), gamma (2, 36))``."""
    from wirescene.core.groundplane import alpha_from_rotation_y, object_pose, transform
    from wirescene.core.types import Detections
    from wirescene.core.wireframe import FACES
    from wirescene.fitting.options import FitOptions
    from wirescene.fitting.pipeline import fit_frame
    from wirescene.infer.inference import InferenceOptions
    from wirescene.infer.likelihood import GaussianVertexEvidence
    from wirescene.infer.occlusion import inter_object_occlusion, self_occlusion
    from wirescene.lift import LiftingOptions

    camera = KittiDataset(KITTI_ROOT).camera("000010")
    model = load_default()
    x, z, az = np.array([0.0, 1.2]), np.array([9.0, 15.0]), np.zeros(2)
    loc, R = object_pose(x, z, az, np.zeros(2), np.zeros(2), 1.65)
    V = transform(np.broadcast_to(model.mean, (2, 36, 3)), loc, R)
    uv = camera.project(V)
    self_hidden = self_occlusion(V, FACES, camera.center)
    gamma = inter_object_occlusion(V, FACES, camera.center) & ~self_hidden
    dets = Detections(np.concatenate([uv.min(1), uv.max(1)], 1), np.ones(2), alpha_from_rotation_y(az, x, z))
    # c for this evidence's own scale (floor -0.55, peak 1.75), not the shipped calibration,
    # which belongs to the part detectors: the test is about the mechanism.
    options = FitOptions(lifting=LiftingOptions(n_particles=10), inference=InferenceOptions(occluded_score=0.25))
    fit = fit_frame(camera, dets, ["fg", "fg+so", "fg+do", "full"],
                    evidence=GaussianVertexEvidence(uv, ~self_hidden & ~gamma), options=options)
    return fit, self_hidden, gamma


def test_occlusion_reasoning_changes_the_estimate_where_a_car_hides_another(near_and_far):
    """Without occlusion reasoning (fg) the fit calls the far car's vertices the near car hides
    visible; the searched occluder (fg+so), deterministic occlusion (fg+do) and both (full)
    recover them."""
    fit, self_hidden, gamma = near_and_far
    assert gamma[1].sum() >= 8 and not gamma[0].any()
    visible = ~self_hidden & ~gamma
    candidates = ~self_hidden[1]

    def occlusion_accuracy(variant):
        far = fit.estimates[variant].cars[1]
        return ((far.visible == visible[1]) & candidates).sum() / candidates.sum()

    assert occlusion_accuracy("fg") < 0.75
    for variant in ("fg+so", "fg+do", "full"):
        assert occlusion_accuracy(variant) >= 0.85, variant


def test_the_fit_says_what_hides_each_vertex(near_and_far):
    """Each fitted car names what hides each vertex, as the variant's model does: the near car
    (``other-car``) where the variant casts rays between cars and searches a mask too (full),
    the occluder mask it chose (``occluder``) where a mask alone stands for the occlusion (fg+so,
    fg+do), nothing but the car itself without occlusion reasoning (fg); ``visibility`` is where
    it says ``visible``, and the JSON carries it."""
    from wirescene.core.wireframe import HIDDEN_BY

    fit, self_hidden, gamma = near_and_far
    kinds = {}
    for variant, estimate in fit.estimates.items():
        near, far = estimate.cars
        for car in (near, far):
            assert car.hidden_by.shape == (36,) and set(car.hidden_by) <= set(HIDDEN_BY)
            assert np.array_equal(car.visibility, car.hidden_by == "visible"), variant
            assert car.to_dict()["hidden_by"] == car.hidden_by.tolist()
        assert not {"other-car", "occluder"} & set(near.hidden_by), variant  # nothing before the near car
        kinds[variant] = {str(r) for r in far.hidden_by if r in ("other-car", "occluder")}
        assert ("occluder" in kinds[variant]) == (far.occluder_mask != 0), variant
    assert kinds["fg"] == set() and kinds["fg+so"] == kinds["fg+do"] == {"occluder"}
    assert "other-car" in kinds["full"]
    far = fit.estimates["full"].cars[1]
    assert (far.hidden_by == "self").sum() >= 8  # its far side


def test_c_calibration_round_trip_and_loud_failures(tmp_path):
    """`train occlusion`'s record is what the likelihood reads; a missing, corrupt or
    foreign file is an error naming it, never a silent default."""
    import pytest

    from wirescene.core.errors import InputError
    from wirescene.infer.occluded_score import load_occluded_score, save_occluded_score
    from wirescene.training.occlusion import calibrate_occluded_score

    record = calibrate_occluded_score(n_scenes=2, grid=[-3.0, -1.0, 0.0, 0.5, 3.0])
    assert record["c"] in record["grid"] and len(record["accuracy"]) == 5 and record["n_cars"] > 0
    # The chosen c is a best value of the grid, and hiding everything (c = 3) is never better
    # than the all-visible baseline on scenes that are mostly visible.
    assert record["accuracy"][record["grid"].index(record["c"])] == max(record["accuracy"])
    path = save_occluded_score(tmp_path / "occlusion.json", record)
    assert load_occluded_score(path) == record["c"]
    with pytest.raises(InputError, match="missing"):
        load_occluded_score(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="bad.json: corrupt"):
        load_occluded_score(tmp_path / "bad.json")
    (tmp_path / "old.json").write_text('{"format": "wirescene-occlusion-v1", "c": 0.25}')
    with pytest.raises(InputError, match="format"):
        load_occluded_score(tmp_path / "old.json")


def test_train_occlusion_records_whether_it_read_the_mirrored_evidence(tmp_path):
    """`train occlusion --flip-evidence` calibrates c on the maps the fit reads by default,
    and its record says so; the default stays the shipped recipe's (one reading)."""
    import json

    from click.testing import CliRunner

    from wirescene.cli.main import main
    from wirescene.infer.occluded_score import load_occluded_score

    records = {}
    for flag in ("--flip-evidence", "--no-flip-evidence"):
        out = tmp_path / f"{flag}.json"
        r = CliRunner().invoke(main, ["train", "occlusion", "--scenes", "1", flag, "--out", str(out)])
        assert r.exit_code == 0, r.output
        records[flag] = json.loads(out.read_text())
        assert load_occluded_score(out) == records[flag]["c"]
    assert records["--flip-evidence"]["flip"] is True and records["--no-flip-evidence"]["flip"] is False
    assert records["--flip-evidence"]["accuracy"] != records["--no-flip-evidence"]["accuracy"]
