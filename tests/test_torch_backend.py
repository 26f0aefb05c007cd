"""The optional PyTorch backend (wirescene.infer.torch_backend) against the numpy reference.

Everything that needs torch asks for the ``torch`` fixture (skipped without it); the
import-isolation test and the "PyTorch missing" message test run without torch.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from conftest import assert_close
from wirescene.core.errors import ShapeError, WiresceneError
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, object_pose, transform
from wirescene.core.raycast import segment_blocked
from wirescene.core.shape import load_default
from wirescene.core.wireframe import FACES, N_VERTICES
from wirescene.infer import torch_backend as tb
from wirescene.infer.likelihood import object_likelihood
from wirescene.infer.occlusion import incidence, inter_object_occlusion, self_occlusion

CENTER = np.array([0.06, 0.0, 0.0])  # KITTI P2's optical centre is slightly off the origin
AGREEMENT = 0.9999  # float32 vs float64 occlusion flags, fraction of vertices


@pytest.fixture(scope="module")
def torch():
    torch = pytest.importorskip("torch")
    torch.set_num_threads(1)  # the tests are small; do not compete with xdist/other jobs
    return torch


@pytest.fixture(scope="module")
def shape_model():
    return load_default()


def placed_wireframes(shape_model, batch, seed, *, max_bearing_deg=40.0):
    """Random shape-model cars on random ground planes, 5-40 m from a camera at KITTI
    height, placed like ``wirescene.infer.likelihood.instantiate_wireframes``; ``(*batch, 36, 3)``."""
    rng = np.random.default_rng(seed)
    shape = rng.normal(size=batch + (5,))
    dist = rng.uniform(5, 40, batch)
    bearing = np.radians(rng.uniform(-max_bearing_deg, max_bearing_deg, batch))
    location, R = object_pose(
        dist * np.sin(bearing), dist * np.cos(bearing), rng.uniform(-np.pi, np.pi, batch),
        rng.normal(0, 0.02, batch), rng.normal(0, 0.02, batch), KITTI_CAMERA_HEIGHT,
    )
    return transform(shape_model.instantiate(shape), location, R)


def disagreement(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == bool and b.dtype == bool
    return int(np.count_nonzero(a != b))


# ----------------------------------------------------------------- import and devices


def test_importing_the_backend_does_not_import_torch():
    code = "import wirescene, wirescene.infer.torch_backend, sys; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_available_matches_an_import():
    try:
        import torch  # noqa: F401
        importable = True
    except ImportError:
        importable = False
    assert tb.available() is importable


def test_resolve_device_without_pytorch_gives_the_install_hint(monkeypatch):
    monkeypatch.setattr(tb, "available", lambda: False)
    with pytest.raises(tb.DeviceError) as info:
        tb.resolve_device("cuda")
    assert str(info.value) == "--device cuda needs PyTorch: pip install torch"
    assert isinstance(info.value, ValueError) and isinstance(info.value, WiresceneError)
    with pytest.raises(tb.DeviceError, match="^--device cpu needs PyTorch: pip install torch$"):
        tb.self_occlusion(np.zeros((1, N_VERTICES, 3)), FACES, CENTER, device="cpu")


def test_a_pytorch_that_cannot_be_imported_is_numpy_for_auto_and_named_for_a_device(monkeypatch):
    import sys

    monkeypatch.setattr(tb, "available", lambda: True)
    monkeypatch.setitem(sys.modules, "torch", None)  # installed, but its import fails
    assert tb.choose_device("auto") == "numpy" and tb.choose_device(" NumPy ") == "numpy"
    with pytest.raises(tb.DeviceError, match=r"^PyTorch is installed but cannot be imported \((ModuleNotFound|Import)Error: "):
        tb.choose_device("cpu")
    with pytest.raises(tb.DeviceError, match="expected numpy, cpu, cuda, cuda:N or auto"):
        tb.choose_device("tpu")


def test_auto_imports_no_pytorch_when_nothing_casts_rays(monkeypatch):
    """The coarse variants cast no rays: ``auto`` is numpy at once, without importing PyTorch
    to look for a GPU; a device named is checked as before."""
    looked = []

    class Cuda(str):  # a torch.device of a GPU: its type, and its name as a string
        type = "cuda"

    def gpu(name):
        looked.append(name)
        return Cuda("cuda")

    monkeypatch.setattr(tb, "available", lambda: True)
    monkeypatch.setattr(tb, "resolve_device", gpu)
    assert tb.choose_device("auto", casts_rays=False) == "numpy" and not looked
    assert tb.choose_device("cuda", casts_rays=False) == "cuda" and looked == ["cuda"]
    assert tb.choose_device("auto") == "cuda"


def test_resolve_device_names(torch):
    assert tb.resolve_device("cpu") == torch.device("cpu")
    assert tb.resolve_device(" CPU ") == torch.device("cpu")
    assert tb.resolve_device(torch.device("cpu")) == torch.device("cpu")
    assert tb.resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    for bad in ("gpu", "cuda:x", "", 3):
        with pytest.raises(tb.DeviceError, match="device"):
            tb.resolve_device(bad)


def test_resolve_device_cuda_unavailable_raises_cleanly(torch):
    if torch.cuda.is_available():
        pytest.skip("CUDA is available here")
    for name in ("cuda", "cuda:0", "cuda:1"):
        with pytest.raises(tb.DeviceError) as info:
            tb.resolve_device(name)
        message = str(info.value)
        assert "\n" not in message and message.startswith(f"--device {name}: CUDA is not available")
        assert "--device cpu" in message
    # The functions fail the same way, before any work.
    with pytest.raises(tb.DeviceError):
        tb.self_occlusion(np.zeros((1, N_VERTICES, 3)), FACES, CENTER, device="cuda")


def test_tf32_is_off_during_cuda_kernels_and_restored(torch):
    matmul = torch.backends.cuda.matmul
    if not hasattr(matmul, "fp32_precision"):
        pytest.skip("PyTorch < 2.9")
    old = matmul.fp32_precision
    try:
        matmul.fp32_precision = "tf32"  # as a caller's set_float32_matmul_precision("high")
        with tb._ieee_matmul(torch, torch.device("cuda")):
            assert matmul.fp32_precision == "ieee"
        assert matmul.fp32_precision == "tf32"
    finally:
        matmul.fp32_precision = old



def test_overlapping_cuda_calls_restore_the_callers_tf32_setting():
    """Fits in threads overlap: the flag stays off until the last call leaves, then is the
    caller's again (a stand-in for torch's process-wide flag; no GPU needed)."""
    from types import SimpleNamespace

    matmul = SimpleNamespace(fp32_precision="tf32")  # the caller's choice
    fake = SimpleNamespace(backends=SimpleNamespace(cuda=SimpleNamespace(matmul=matmul)))
    cuda = SimpleNamespace(type="cuda")
    a, b = tb._ieee_matmul(fake, cuda), tb._ieee_matmul(fake, cuda)
    a.__enter__()
    b.__enter__()  # a second fit's kernels start while the first's run
    a.__exit__(None, None, None)  # the first leaves before the second
    assert matmul.fp32_precision == "ieee"
    b.__exit__(None, None, None)
    assert matmul.fp32_precision == "tf32"
    legacy = SimpleNamespace(allow_tf32=True)  # PyTorch < 2.9
    with tb._ieee_matmul(SimpleNamespace(backends=SimpleNamespace(cuda=SimpleNamespace(matmul=legacy))), cuda):
        assert legacy.allow_tf32 is False
    assert legacy.allow_tf32 is True

def test_dtype_and_chunk_arguments(torch, monkeypatch):
    with pytest.raises(ValueError, match="dtype"):
        tb.segment_blocked(np.zeros(3), np.ones((1, 3)), np.ones((1, 3, 3)), dtype="float16")
    with pytest.raises(ValueError, match="chunk"):
        tb.segment_blocked(np.zeros(3), np.ones((1, 3)), np.ones((1, 3, 3)), chunk=0)
    assert tb.default_chunk(torch.device("cpu")) == tb.DEFAULT_CHUNK_CPU
    monkeypatch.setenv(tb.CHUNK_ENV, "4096")
    assert tb.default_chunk(torch.device("cpu")) == 4096
    monkeypatch.setenv(tb.CHUNK_ENV, "lots")
    with pytest.raises(ValueError, match=tb.CHUNK_ENV):
        tb.default_chunk(torch.device("cpu"))


# ---------------------------------------------------------------------- ray casting


def test_segment_blocked_matches_numpy_with_broadcasting_and_ignore(torch):
    rng = np.random.default_rng(1)
    origins = rng.normal(size=(4, 3, 3)) * 6
    targets = rng.normal(size=(4, 3, 20, 3))
    triangles = rng.normal(size=(4, 3, 15, 3, 3))
    want = segment_blocked(origins, targets, triangles)
    assert 0.1 < want.mean() < 0.9
    got = tb.segment_blocked(origins, targets, triangles)
    assert got.shape == (4, 3, 20) and got.dtype == bool
    assert np.array_equal(got, want)
    assert np.array_equal(tb.segment_blocked(origins, targets, triangles, chunk=7), want)
    assert np.array_equal(tb.segment_blocked(origins, targets, triangles, dtype="float64"), want)
    # Shared origin and triangles against batched targets (broadcast, non-contiguous).
    want = segment_blocked(origins[0, 0], targets, triangles[0, 0])
    assert np.array_equal(tb.segment_blocked(origins[0, 0], targets, triangles[0, 0], chunk=50), want)
    assert np.array_equal(tb.segment_blocked(origins[:, :1], targets, triangles[:1], chunk=50),
                          segment_blocked(origins[:, :1], targets, triangles[:1]))
    # Shared and per-element ignore masks.
    ignore = rng.random((20, 15)) < 0.5
    assert np.array_equal(tb.segment_blocked(origins, targets, triangles, ignore=ignore),
                          segment_blocked(origins, targets, triangles, ignore=ignore))
    ignore = rng.random((4, 1, 20, 15)) < 0.5
    assert np.array_equal(tb.segment_blocked(origins, targets, triangles, ignore=ignore, chunk=300),
                          segment_blocked(origins, targets, triangles, ignore=ignore))


def test_segment_blocked_edge_cases_and_errors(torch):
    # Watertight: a square split along its diagonal blocks every ray through the diagonal.
    sq = np.array([[-1, -1, 5], [1, -1, 5], [1, 1, 5], [-1, 1, 5]], float)
    tri = sq[np.array([[0, 1, 2], [0, 2, 3]])]
    s = np.linspace(-0.9, 0.9, 37)
    targets = np.stack([s * 2, s * 2, np.full_like(s, 10.0)], axis=-1)
    assert tb.segment_blocked(np.zeros(3), targets, tri).all()
    assert not tb.segment_blocked(np.zeros(3), targets * 0.4, tri).any()
    assert not tb.segment_blocked(np.zeros(3), sq, tri).any()
    assert tb.segment_blocked(np.zeros(3), sq * (1 + 1e-5), tri, eps=0.0).any()
    # A triangle seen edge-on never blocks.
    assert not tb.segment_blocked(np.zeros(3), [[0, 0, 10.0]], [[[-1, 0, 1], [1, 0, 1], [0, 0, 9]]]).any()
    # Empty inputs, shape errors, eps range.
    assert tb.segment_blocked(np.zeros(3), np.zeros((2, 0, 3)), tri).shape == (2, 0)
    assert not tb.segment_blocked(np.zeros(3), targets, np.zeros((0, 3, 3))).any()
    with pytest.raises(ShapeError):
        tb.segment_blocked(np.zeros(3), np.zeros((4, 2)), tri)
    with pytest.raises(ShapeError):
        tb.segment_blocked(np.zeros((2, 3)), np.zeros((3, 1, 3)), tri)
    with pytest.raises(ShapeError):
        tb.segment_blocked(np.zeros(3), targets, tri, ignore=np.ones((5, 2, 2), bool))
    with pytest.raises(ValueError, match="eps"):
        tb.segment_blocked(np.zeros(3), targets, tri, eps=0.5)


def test_self_occlusion_matches_numpy_on_placed_wireframes(torch, shape_model):
    vertices = placed_wireframes(shape_model, (250, 5, 12), seed=0)  # 15000 hypotheses
    want = self_occlusion(vertices, FACES, CENTER)
    assert 0.2 < want.mean() < 0.6
    got = tb.self_occlusion(vertices, FACES, CENTER)
    assert got.shape == want.shape == (250, 5, 12, N_VERTICES)
    n = disagreement(got, want)
    print(f"self_occlusion float32: {n} of {want.size} vertex flags differ from numpy")
    assert n <= (1 - AGREEMENT) * want.size, f"{n} of {want.size} flags differ"
    n64 = disagreement(tb.self_occlusion(vertices, FACES, CENTER, dtype="float64"), want)
    print(f"self_occlusion float64: {n64} of {want.size} vertex flags differ from numpy")
    assert n64 <= (1 - AGREEMENT) * want.size
    # Chunking is invisible (same kernel rows, any grouping), and a small batch with a
    # per-hypothesis camera centre broadcasts like numpy.
    assert np.array_equal(tb.self_occlusion(vertices[:3], FACES, CENTER, chunk=1000), got[:3])
    centers = CENTER + np.random.default_rng(3).normal(scale=0.5, size=(3, 5, 1, 3))
    assert disagreement(tb.self_occlusion(vertices[:3], FACES, centers),
                        self_occlusion(vertices[:3], FACES, centers)) <= 1


def test_self_occlusion_equals_segment_blocked_with_incidence(torch, shape_model):
    vertices = placed_wireframes(shape_model, (40,), seed=1)
    got = tb.self_occlusion(vertices, FACES, CENTER)
    generic = tb.segment_blocked(CENTER, vertices, vertices[..., FACES, :], ignore=incidence(FACES, N_VERTICES))
    assert np.array_equal(got, generic)


def test_inter_object_occlusion_matches_numpy_on_placed_scenes(torch, shape_model):
    # 250 scenes of 5 cars, closer together than in the other test, so that they overlap.
    vertices = placed_wireframes(shape_model, (250, 5), seed=2, max_bearing_deg=25.0)
    want = inter_object_occlusion(vertices, FACES, CENTER)
    assert 0.05 < want.mean() < 0.5
    got = tb.inter_object_occlusion(vertices, FACES, CENTER)
    assert got.shape == want.shape == (250, 5, N_VERTICES)
    n = disagreement(got, want)
    print(f"inter_object_occlusion float32: {n} of {want.size} vertex flags differ from numpy")
    assert n <= (1 - AGREEMENT) * want.size, f"{n} of {want.size} flags differ"
    # Culling object pairs whose images do not overlap is exact.
    assert np.array_equal(tb.inter_object_occlusion(vertices[:60], FACES, CENTER, cull=False), got[:60])
    assert np.array_equal(tb.inter_object_occlusion(vertices[:60], FACES, CENTER, chunk=5000), got[:60])
    # One object: nothing to be hidden by; no scenes: empty.
    assert not tb.inter_object_occlusion(vertices[:, :1], FACES, CENTER).any()
    assert tb.inter_object_occlusion(vertices[:0], FACES, CENTER).shape == (0, 5, N_VERTICES)


def test_occlusion_input_errors(torch):
    with pytest.raises(ShapeError):
        tb.self_occlusion(np.zeros((2, N_VERTICES, 2)), FACES, CENTER)
    with pytest.raises(ShapeError):
        tb.self_occlusion(np.zeros((2, N_VERTICES, 3)), FACES + 1, CENTER)
    with pytest.raises(ShapeError):
        tb.inter_object_occlusion(np.zeros((2, 3, N_VERTICES, 3)), FACES, np.zeros((3, 3)))


# ---------------------------------------------------------------------- likelihood


def test_object_likelihood_matches_numpy(torch):
    rng = np.random.default_rng(4)
    shape = (250, 5, 12, N_VERTICES)
    evidence = rng.normal(scale=2.0, size=shape)
    self_hidden = rng.random(shape) < 0.4
    self_hidden[0, 0, 0] = True  # an object with no visible vertex scores 0, not nan
    mask_hidden = rng.random(shape) < 0.2
    for mask in (mask_hidden, None, mask_hidden[0, 0]):  # per hypothesis, none, broadcast
        want = object_likelihood(evidence, self_hidden, mask, c=-0.5)
        got = tb.object_likelihood(evidence, self_hidden, mask, c=-0.5)
        assert got.shape == want.shape == shape[:-1] and got.dtype == np.float64
        assert_close(got, want, atol=1e-5, rtol=0)
    assert got[0, 0, 0] == 0.0
    got64 = tb.object_likelihood(evidence, self_hidden, mask_hidden, c=-0.5, dtype="float64")
    assert_close(got64, object_likelihood(evidence, self_hidden, mask_hidden, c=-0.5), atol=1e-12, rtol=0)
