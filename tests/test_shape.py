"""Wireframe topology and the PCA shape model."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from conftest import DATA, assert_close
from wirescene.core import wireframe as wf
from wirescene.core.errors import InputError, ShapeError
from wirescene.core.shape import (
    KITTI_CAR_SIZE,
    ShapeModel,
    augment_to_kitti_sizes,
    component_signs,
    fit_shape_model,
    load_default,
)

FLIP = np.array([1.0, 1.0, -1.0])


@pytest.fixture(scope="module")
def model():
    return load_default()


def test_topology_constants():
    assert len(wf.VERTEX_NAMES) == 36 == len(set(wf.VERTEX_NAMES))
    assert sorted(wf.MIRROR) == list(range(36))
    assert np.all(wf.MIRROR[wf.MIRROR] == np.arange(36))
    for i, j in enumerate(wf.MIRROR):
        assert wf.VERTEX_NAMES[i].rsplit("_", 1)[0] == wf.VERTEX_NAMES[j].rsplit("_", 1)[0]
        assert wf.SIDE[i] == -wf.SIDE[j]
    assert wf.EDGES.min() >= 0 and wf.EDGES.max() < 36
    # the surface is closed: every edge is shared by exactly two faces, in opposite directions
    directed = {(int(a), int(b)) for f in wf.FACES for a, b in zip(f, np.roll(f, -1))}
    assert len(directed) == 3 * len(wf.FACES)
    assert all((b, a) in directed for a, b in directed)


def test_mean_shape_symmetric_metric_and_outward(model):
    mu = model.mean
    assert_close(mu[wf.MIRROR] * FLIP, mu, atol=1e-9)
    l, w, h = np.ptp(mu[:, 0]), np.ptp(mu[:, 2]), np.ptp(mu[:, 1])
    for value, mean, std in zip((l, w, h), KITTI_CAR_SIZE["mean"], KITTI_CAR_SIZE["std"]):
        assert abs(value - mean) < 2 * std
    assert mu[:, 1].max() == pytest.approx(0.0, abs=1e-6)  # stands on the ground
    mesh = trimesh.Trimesh(mu, wf.FACES, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0.5 * l * w * h * 0.5  # positive signed volume: outward normals


def test_exemplars_symmetric(model):
    assert len(model.exemplar_names) == len(model.exemplars) >= 10
    for X in model.exemplars:
        assert_close(X[wf.MIRROR] * FLIP, X, atol=1e-9)
        assert trimesh.Trimesh(X, wf.FACES, process=False).volume > 0


def test_components_orthonormal_and_symmetric(model):
    P = model.components.reshape(model.n_components, -1)
    assert_close(P @ P.T, np.eye(model.n_components), atol=1e-9)
    assert np.all(np.diff(model.stds) <= 1e-12) and np.all(model.stds > 0)
    # symmetric training data give symmetric modes
    assert_close(model.components[:, wf.MIRROR] * FLIP, model.components, atol=1e-8)


def test_instantiate_batches(model):
    s = np.random.default_rng(0).standard_normal((4, 5, 3))
    X = model.instantiate(s)
    assert X.shape == (4, 5, 36, 3)
    expected = model.mean + sum(s[1, 2, k] * model.stds[k] * model.components[k] for k in range(3))
    assert_close(X[1, 2], expected, atol=1e-12)
    assert_close(model.instantiate(np.zeros(2)), model.mean)
    with pytest.raises(ValueError):
        model.instantiate(np.zeros(model.n_components + 1))
    with pytest.raises(ShapeError):
        model.project_coefficients(np.zeros((35, 3)))


def test_reconstruction_error_decreases_and_is_exact_with_all():
    rng = np.random.default_rng(1)
    base = load_default().exemplars
    model = fit_shape_model(base, [f"c{i}" for i in range(len(base))])
    errors = [np.sqrt(((model.reconstruct(base, k) - base) ** 2).sum()) for k in range(1, model.n_components + 1)]
    assert all(b <= a + 1e-12 for a, b in zip(errors, errors[1:]))
    assert errors[0] > 0.1 and errors[-1] < 1e-9
    s = rng.standard_normal(model.n_components)
    assert_close(model.project_coefficients(model.instantiate(s)), s, atol=1e-8)


def test_component_signs_survive_rounding(model):
    """Mirrored vertices tie for a component's largest entry; rounding (another CPU's BLAS kernels)
    breaks the tie one way or the other, and must not flip the component."""
    names = [str(i) for i in range(len(model.exemplars))]

    def components(side):
        W = model.exemplars.copy()
        W[:, wf.SIDE == side, 2] *= 1 + 1e-11  # a rounding-sized asymmetry on one side
        return fit_shape_model(W, names).components

    left, right = components(1), components(-1)
    agreement = (left * right).reshape(len(left), -1).sum(axis=1)
    assert_close(agreement, np.ones(len(left)), atol=1e-6)
    assert (component_signs(model.components.reshape(model.n_components, -1)) == 1).all()  # shipped: the convention


def test_nearest_exemplar_of_exemplar_is_itself(model):
    for m, X in enumerate(model.exemplars):
        idx, name, dist = model.nearest_exemplar(X)
        assert idx == m and name == model.exemplar_names[m] and dist == 0.0
    idx, names, dist = model.nearest_exemplar(model.exemplars[:3] + 0.01)
    assert list(idx) == [0, 1, 2] and names.shape == (3,)


def test_save_load_round_trip(tmp_path, model):
    path = tmp_path / "m.npz"
    model.save(path)
    loaded = ShapeModel.load(path)
    for field in ("mean", "components", "stds", "explained_variance_ratio", "exemplars"):
        assert_close(getattr(loaded, field), getattr(model, field), atol=0)
    assert loaded.exemplar_names == model.exemplar_names and loaded.version == model.version
    with np.load(path, allow_pickle=False) as z:  # no pickled objects inside
        assert all(z[k].dtype != object for k in z.files)
    np.savez(tmp_path / "old.npz", version=np.int64(99), mean=model.mean)
    with pytest.raises(InputError):
        ShapeModel.load(tmp_path / "old.npz")


def test_sample_and_augmentation():
    base = load_default().exemplars
    aug = augment_to_kitti_sizes(base, n_per_exemplar=200, rng=0)
    dims = np.stack([np.ptp(aug[..., 0], axis=1), np.ptp(aug[..., 2], axis=1), np.ptp(aug[..., 1], axis=1)], 1)
    assert_close(dims.mean(axis=0), KITTI_CAR_SIZE["mean"], atol=0.03)
    assert_close(dims.std(axis=0), KITTI_CAR_SIZE["std"], atol=0.03)
    X = load_default().sample(7, rng=3)
    assert X.shape == (7, 36, 3)
    assert_close(X, load_default().sample(7, rng=3))


def test_retrain_on_tiny_subset(tmp_path):
    from wirescene.cad.training import load_cad_landmarks, load_cad_meshes, train_shape_model

    out = tmp_path / "tiny.npz"
    model = train_shape_model(DATA / "cad", out, seed=5, augment=10)
    again = train_shape_model(DATA / "cad", tmp_path / "again.npz", seed=5, augment=10, landmarks_path=False,
                              meshes_path=False)
    assert_close(again.components, model.components, atol=0)  # deterministic given the seed
    loaded = ShapeModel.load(out)
    assert loaded.exemplar_names == ("155-DTM", "acura-nsx-sz", "car1-stock2")
    X = loaded.instantiate(np.ones((2, loaded.n_components)))
    assert X.shape == (2, 36, 3) and np.isfinite(X).all()
    lm = json.loads((tmp_path / "cad_landmarks.json").read_text())
    assert {c["name"]: c["road_car"] for c in lm["cars"]}["buggy"] is False
    assert set(load_cad_landmarks(tmp_path / "cad_landmarks.json")) == set(loaded.exemplar_names)
    meshes = load_cad_meshes(tmp_path / "cad_meshes.npz")
    V, F = meshes["155-DTM"]
    assert V.dtype == np.float32 and F.dtype == np.int32 and F.max() < len(V)
    # files whose cars lack faces or vertices are refused naming the file, not met later as index errors
    from wirescene.core.artefacts import load_npz, save_npz
    from wirescene.core.errors import InputError

    arrays = dict(load_npz(tmp_path / "cad_meshes.npz", kind="cad-meshes", version=1))
    arrays["faces"] = arrays["faces"] + 10_000
    save_npz(tmp_path / "bad_meshes.npz", arrays, kind="cad-meshes", version=1)
    with pytest.raises(InputError, match="faces past its") as e:
        load_cad_meshes(tmp_path / "bad_meshes.npz")
    assert "bad_meshes.npz" in str(e.value)
    del lm["cars"][0]["vertices"]["nose_top_left"]
    (tmp_path / "bad_landmarks.json").write_text(json.dumps(lm))
    with pytest.raises(InputError, match="lacks vertex 'nose_top_left'"):
        load_cad_landmarks(tmp_path / "bad_landmarks.json")


def test_committed_artefacts_agree(model):
    from wirescene.cad.training import load_cad_landmarks, load_cad_meshes

    lm = load_cad_landmarks()
    assert set(lm) == set(model.exemplar_names)
    for m, name in enumerate(model.exemplar_names):
        assert_close(lm[name], model.exemplars[m], atol=1e-9)
    assert set(load_cad_meshes()) == set(model.exemplar_names)
