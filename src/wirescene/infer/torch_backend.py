"""Optional PyTorch backend for the inference hot path: batched ray casting for vertex
occlusion and the batched object likelihood, on the CPU or a CUDA GPU.

Every function mirrors a numpy one and takes and returns numpy arrays:

==================================  ================================================
here                                numpy reference
==================================  ================================================
:func:`segment_blocked`             :func:`wirescene.core.raycast.segment_blocked`
:func:`self_occlusion`              :func:`wirescene.infer.occlusion.self_occlusion`
:func:`inter_object_occlusion`      :func:`wirescene.infer.occlusion.inter_object_occlusion`
:func:`object_likelihood`           :func:`wirescene.infer.likelihood.object_likelihood`
==================================  ================================================

PyTorch is *not* a dependency of wirescene: importing this module does not import
torch (every function imports it lazily), :func:`available` tells whether it is
installed, and :func:`resolve_device` turns a ``--device`` option (``cpu``, ``cuda``,
``cuda:N``, ``auto``) into a ``torch.device`` or a one-line :class:`DeviceError`.

Precision. The ray casting computes in float32 by default (``dtype="float64"`` is
available). Coordinates are made relative to the ray origin (the camera centre) in
float64 on the host *before* the cast, so float32 keeps about 7 significant digits of
the camera-to-vertex geometry, not of absolute positions, and the per-triangle terms
are formed from well-conditioned differences (see :func:`_triangle_terms`). The
``ignore`` masks of the occlusion functions (faces incident to a vertex, faces of the
same object) make the answers independent of ``eps`` in the usual cases; what is left
to rounding are rays that pass within about 1e-6 relative of a triangle edge *and* of
its plane, i.e. a vertex lying on another face. On 10 random batches of 15000 placed
wireframes (5.4 million vertices) float32 self-occlusion flags differed from numpy's
on 9 vertices, float64 ones on none; inter-object flags on none of 450000.

Cross products are computed with separate elementwise multiplications and subtractions
(never ``torch.linalg.cross`` nor a fused kernel), so that no fused multiply-add can
break the exact antisymmetry ``A x B == -(B x A)`` on which the watertightness of the
edge test depends (see :func:`wirescene.core.raycast._blocked_chunk`).
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os
import threading

import numpy as np

from wirescene.core.errors import ShapeError, WiresceneError, check_shape
from wirescene.core.raycast import (
    DEFAULT_EPS,
    check_eps,
    check_faces,
    incidence,
    interaction_candidates,
    segment_inputs,
)

# Upper bound on (ray x triangle) pairs per chunk. The pair temporaries are the
# (rays, 4F) matrix of dot products and two (rays, F) minima, 6 values per pair, so
# 2**17 pairs are 3 MB of float32 (cache-sized: fastest on one CPU core for 15000
# placed wireframes; 2**16 and 2**18 were within 20%, 2**19 1.3x and 2**14 2.6x slower,
# the latter from per-chunk overhead) and 2**24 pairs 384 MB on a GPU (large enough to
# fill it). Memory stays bounded whatever the batch; the per-triangle terms of a block
# take about as much again.
DEFAULT_CHUNK_CPU = 1 << 17
DEFAULT_CHUNK_CUDA = 1 << 24

# Environment override of the chunk size (pairs), e.g. for GPUs with little memory.
CHUNK_ENV = "WIRESCENE_TORCH_CHUNK"

_INSTALL_HINT = "--device {name} needs PyTorch: pip install torch"

#: Threads PyTorch may use in this process, set by a frame worker for its share of the cores.
TORCH_THREADS_ENV = "WIRESCENE_TORCH_THREADS"


class DeviceError(WiresceneError, ValueError):
    """A ``--device`` that cannot be used here (unknown name, PyTorch missing, no CUDA).

    Examples
    --------
    >>> try:
    ...     choose_device("tpu")
    ... except DeviceError as exc:  # also a ValueError: one line, fit for a command line
    ...     print(isinstance(exc, ValueError), exc)
    True unknown device 'tpu': expected numpy, cpu, cuda, cuda:N or auto
    """


def available() -> bool:
    """Whether PyTorch is installed (checked without importing it)."""
    try:
        return importlib.util.find_spec("torch") is not None
    except (ImportError, ValueError):  # a broken or half-removed installation
        return False


def _torch():
    """``import torch``, or a :class:`DeviceError`: the install hint where it is missing,
    the import's own error where an installed PyTorch cannot be loaded (a missing CUDA
    library, a build for another Python)."""
    try:
        import torch
    except Exception as exc:  # a broken build raises OSError, RuntimeError, ... as well
        if isinstance(exc, ImportError) and not available():
            raise DeviceError("the PyTorch backend needs PyTorch: pip install torch") from exc
        problem = f"{type(exc).__name__}: {exc}".splitlines()[0]
        raise DeviceError(f"PyTorch is installed but cannot be imported ({problem}); use --device numpy") from exc
    threads = os.environ.get(TORCH_THREADS_ENV, "")
    if threads.isdigit() and int(threads) > 0 and torch.get_num_threads() != int(threads):
        torch.set_num_threads(int(threads))
    return torch


def choose_device(name="auto", *, parallel: bool = False, casts_rays: bool = True) -> str:
    """The inference device for a ``--device`` / ``inference.device`` value: ``"numpy"``
    or a PyTorch device name (``"cpu"``, ``"cuda"``, ``"cuda:N"``), checked here.

    ``"auto"`` takes a CUDA GPU when PyTorch sees one and the frames are fitted in one
    process anyway, else numpy: with ``parallel`` (several frame processes) it stays with
    numpy, the GPU speeding up the ray casting alone (a fit 1.3x end to end) while CUDA
    would keep the frames in one process (benchmarks/RESULTS.md, "The PyTorch backend on a
    GPU"); a PyTorch that is missing or cannot be imported is numpy too. PyTorch is
    imported only to look for the GPU, and only if it is installed and ``casts_rays``: without
    it (no variant to be fitted is a fine one, the only stage that casts rays) ``"auto"`` is
    numpy at once.

    Raises
    ------
    DeviceError (a ValueError)
        A name other than ``numpy``, ``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (case and
        surrounding blanks ignored), or a PyTorch device this machine lacks.

    Examples
    --------
    >>> choose_device(" NumPy "), choose_device("auto", parallel=True), choose_device("auto", casts_rays=False)
    ('numpy', 'numpy', 'numpy')
    """
    key = name.strip().lower() if isinstance(name, str) else name
    if key == "numpy":
        return "numpy"
    if key == "auto":
        if parallel or not casts_rays or not available():
            return "numpy"
        try:
            return "cuda" if resolve_device("auto").type == "cuda" else "numpy"
        except DeviceError:  # installed but broken: auto asked for nothing that needs it
            return "numpy"
    return str(resolve_device(key))


def resolve_device(name="auto"):
    """The ``torch.device`` for a ``--device`` value.

    Parameters
    ----------
    name : str or torch.device
        ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"auto"`` (CUDA if available, else the
        CPU). Case and surrounding blanks are ignored.

    Raises
    ------
    DeviceError (a ValueError)
        With a one-line message if the name is unknown, PyTorch is not installed, CUDA
        is asked for but not available, or the CUDA device index does not exist.

    Examples
    --------
    >>> resolve_device("cuda:x")  # refused by its name alone, whether or not PyTorch is installed
    Traceback (most recent call last):
    ...
    wirescene.infer.torch_backend.DeviceError: unknown device 'cuda:x': expected numpy, cpu, cuda, cuda:N or auto
    """
    if not isinstance(name, str):
        if type(name).__name__ == "device" and type(name).__module__.startswith("torch"):
            name = str(name)
        else:
            raise DeviceError(f"device must be a string such as 'cpu', 'cuda', 'cuda:0' or 'auto', got {name!r}")
    key = name.strip().lower()
    if key not in ("cpu", "cuda", "auto") and not (key.startswith("cuda:") and key[5:].isdigit()):
        raise DeviceError(f"unknown device {name!r}: expected numpy, cpu, cuda, cuda:N or auto")
    if not available():
        raise DeviceError(_INSTALL_HINT.format(name=key))
    torch = _torch()
    if key == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if key == "cpu":
        return torch.device("cpu")
    if not torch.cuda.is_available():
        why = "this PyTorch build has no CUDA support" if torch.version.cuda is None else "no CUDA GPU is visible"
        raise DeviceError(f"--device {key}: CUDA is not available ({why}); use --device cpu")
    if ":" in key:
        index, count = int(key[5:]), torch.cuda.device_count()
        if index >= count:
            raise DeviceError(f"--device {key}: only {count} CUDA device(s) visible")
    return torch.device(key)


def _dtype(torch, dtype):
    if isinstance(dtype, torch.dtype):
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"dtype must be float32 or float64, got {dtype}")
        return dtype
    table = {"float32": torch.float32, "float64": torch.float64}
    if dtype not in table:
        raise ValueError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    return table[dtype]


def default_chunk(device) -> int:
    """Pairs per chunk on ``device``: ``$WIRESCENE_TORCH_CHUNK`` if set, else
    ``DEFAULT_CHUNK_CUDA`` on a GPU and ``DEFAULT_CHUNK_CPU`` on the CPU."""
    env = os.environ.get(CHUNK_ENV)
    if env:
        try:
            value = int(env)
        except ValueError:
            raise ValueError(f"${CHUNK_ENV} must be an integer, got {env!r}") from None
        if value < 1:
            raise ValueError(f"${CHUNK_ENV} must be positive, got {value}")
        return value
    return DEFAULT_CHUNK_CUDA if getattr(device, "type", "cpu") == "cuda" else DEFAULT_CHUNK_CPU


#: The calls inside :func:`_ieee_matmul` (fits in threads overlap) and the caller's setting they saved.
_IEEE_LOCK = threading.Lock()
_IEEE_USERS: dict = {"count": 0, "saved": None}


@contextlib.contextmanager
def _ieee_matmul(torch, dev):
    """Float32 matrix products in full precision on CUDA for the duration: TF32 (10-bit
    mantissa), if a caller enabled it globally, would break the ray/edge tests. The flag is
    process-wide: the first of overlapping calls (threads) saves the caller's setting and
    the last one restores it."""
    if getattr(dev, "type", "cpu") != "cuda":
        yield
        return
    matmul = torch.backends.cuda.matmul
    # The per-backend setting (PyTorch >= 2.9), which overrides the global one; the
    # legacy allow_tf32 flag is only touched on older versions (mixing the two APIs
    # makes torch.get_float32_matmul_precision raise).
    name = "fp32_precision" if hasattr(matmul, "fp32_precision") else "allow_tf32"
    with _IEEE_LOCK:
        if _IEEE_USERS["count"] == 0:
            _IEEE_USERS["saved"] = getattr(matmul, name)
            setattr(matmul, name, "ieee" if name == "fp32_precision" else False)
        _IEEE_USERS["count"] += 1
    try:
        yield
    finally:
        with _IEEE_LOCK:
            _IEEE_USERS["count"] -= 1
            if _IEEE_USERS["count"] == 0:
                setattr(matmul, name, _IEEE_USERS["saved"])


def _setup(device, dtype, chunk):
    """Validated ``(torch, device, dtype, chunk)`` for a public function's arguments."""
    dev = resolve_device(device) if isinstance(device, str) else None  # the --device messages
    torch = _torch()
    if dev is None:
        dev = device if isinstance(device, torch.device) else resolve_device(device)
    dt = _dtype(torch, dtype)
    chunk = default_chunk(dev) if chunk is None else int(chunk)
    if chunk < 1:
        raise ValueError(f"chunk must be positive, got {chunk}")
    return torch, dev, dt, chunk


# ----------------------------------------------------------------------------- kernel


def _cross_into(out, a, b):
    """``out = a x b`` for ``(b, 3, k)`` component-major vectors, unfused: each
    component is ``fl(fl(a_i b_j) - fl(a_j b_i))``, so ``a x b == -(b x a)`` exactly
    (see the module docstring)."""
    import torch

    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        o = torch.mul(a[:, j], b[:, k], out=out[:, i])
        o -= a[:, k] * b[:, j]
    return out


def _triangle_terms(torch, K, eps):
    """Per-triangle terms of :func:`wirescene.core.raycast._blocked_chunk`.

    ``K`` ``(b, 3, 3F)``: the corners A | B | C of the F triangles, component-major,
    relative to each row's origin. Returns ``M`` ``(b, 3, 4F)``, the columns
    ``s A x B | s B x C | s C x A | s n`` with ``n = (B - A) x (C - A)`` and
    ``s = sign(det)``, and ``thr+`` ``(b, 1, F)``, the next float above the distance
    threshold ``|det| / (1 - eps)`` (inf where det = 0).

    ``det`` is computed as ``n . A``, not ``A . (B x C)``: the same value, but the
    latter cancels terms of size ``|A| |B| |C|`` down to a volume of size ``|n| |A|``
    and loses 3 to 4 digits in float32 for a car 40 m away; ``n`` is built from the
    small corner differences and keeps them. For the same reason ``n`` is not taken
    as the sum of the three edge cross products.
    """
    b, _, F3 = K.shape
    F = F3 // 3
    M = K.new_empty((b, 3, 4 * F))
    _cross_into(M[:, :, :2 * F], K[:, :, :2 * F], K[:, :, F:])  # A x B | B x C
    _cross_into(M[:, :, 2 * F:F3], K[:, :, 2 * F:], K[:, :, :F])  # C x A
    A = K[:, :, :F]
    n = _cross_into(M[:, :, F3:], K[:, :, F:2 * F] - A, K[:, :, 2 * F:] - A)
    det = (n * A).sum(1)  # (b, F)
    M *= torch.sign(det).repeat(1, 4).unsqueeze(1)
    inf = torch.tensor(math.inf, dtype=det.dtype, device=det.device)
    thr = torch.where(det != 0, det.abs() / (1.0 - eps), inf)
    return M, torch.nextafter(thr, inf).unsqueeze(1)


def _pair_test(torch, D, M, thr_up, ign_add, buf, out):
    """Segments ``D`` ``(b, P, 3)`` against the triangles of ``_triangle_terms``
    (``M`` ``(b, 3, 4F)``, ``thr_up`` ``(b, 1, F)``); ``ign_add`` ``(1 or b, P, F)``
    is -inf where a pair is ignored, else 0 (or None). Writes ``(b, P)`` bool to
    ``out``; ``buf`` holds preallocated work space (see ``_blocked``).

    The four tests of a pair, ``s D.m1 >= 0``, ``s D.m2 >= 0``, ``s D.m3 >= 0`` and
    ``s D.n > thr``, are folded into one: ``s D.n > thr`` iff ``s D.n - thr+ >= 0``
    (the sign of an IEEE difference is exact), so a pair is a hit iff the minimum of
    its four values is ``>= 0``, and a segment is blocked iff the maximum of that
    minimum over the (non-ignored) triangles is. Non-finite coordinates give
    unspecified results.
    """
    b, F = D.shape[0], thr_up.shape[-1]
    c = torch.bmm(D, M, out=buf["c"][:b])  # (b, P, 4F): every segment . every column
    c4 = c[..., 3 * F:]
    c4 -= thr_up
    lo, lo2 = buf["lo"][0, :b], buf["lo"][1, :b]
    torch.minimum(c[..., :F], c[..., F:2 * F], out=lo)
    torch.minimum(c[..., 2 * F:3 * F], c4, out=lo2)
    torch.minimum(lo, lo2, out=lo)
    if ign_add is not None:
        lo += ign_add
    hi = torch.amax(lo, dim=-1, out=buf["hi"][:b])
    torch.ge(hi, 0, out=out)


def _blocked(torch, block, Bn: int, P: int, F: int, eps: float, chunk: int, dev, dt, *, to_numpy=True):
    """Run the kernel over a flattened batch of ``Bn`` rows; ``block(start, stop)``
    returns ``(D, K, ign_add)`` for those rows: segments ``(b, P, 3)`` and triangle
    corners ``(b, 3, 3F)`` as for ``_triangle_terms``, on the device, relative to the
    origin, and ``ign_add`` as for ``_pair_test`` with 1 or ``b`` rows.

    Two levels of chunks: the (ray, triangle) pair temporaries are bounded by
    ``chunk`` pairs (6 values per pair, preallocated once: freshly allocated large
    tensors cost page faults on the CPU); the per-triangle terms, which cost per pair
    about 1/P of that, are computed for ``P // 4`` such chunks at once (fewer, larger
    tensor operations). Returns ``(Bn, P)`` bool, numpy or (``to_numpy=False``) a
    tensor on the device."""
    inner = min(Bn, max(1, chunk // max(1, P * F)))
    outer = inner * max(1, P // 4)
    buf = {
        "c": torch.empty((inner, P, 4 * F), dtype=dt, device=dev),
        "lo": torch.empty((2, inner, P, F), dtype=dt, device=dev),
        "hi": torch.empty((inner, P), dtype=dt, device=dev),
    }
    out = torch.empty((Bn, P), dtype=torch.bool, device=dev)
    with _ieee_matmul(torch, dev):
        _blocked_loop(torch, block, Bn, inner, outer, eps, buf, out)
    return out.cpu().numpy() if to_numpy else out


def _blocked_loop(torch, block, Bn, inner, outer, eps, buf, out):
    for s0 in range(0, Bn, outer):
        s1 = min(Bn, s0 + outer)
        D, K, ign_add = block(s0, s1)
        M, thr_up = _triangle_terms(torch, K, eps)
        for i0 in range(0, s1 - s0, inner):
            i1 = min(s1 - s0, i0 + inner)
            ig = ign_add if ign_add is None or ign_add.shape[0] == 1 else ign_add[i0:i1]
            _pair_test(torch, D[i0:i1], M[i0:i1], thr_up[i0:i1], ig, buf, out[s0 + i0:s0 + i1])


def _additive(torch, ignore_bool, dt):
    """-inf where ``ignore_bool``, else 0, in ``dt``."""
    return torch.zeros(ignore_bool.shape, dtype=dt, device=ignore_bool.device).masked_fill_(ignore_bool, -math.inf)


# ------------------------------------------------------------------------- public API


def _tensor(torch, array, dev, dt=None):
    """A numpy array on the device, cast to ``dt`` on the host first (half the bytes to
    move for float32); always copied, as inputs may be read-only broadcast views."""
    if dt is not None:
        array = np.array(array, dtype=np.float32 if dt == torch.float32 else np.float64, order="C")
    else:
        array = np.array(array, order="C")
    return torch.from_numpy(array).to(dev)


def segment_blocked(
    origins,
    targets,
    triangles,
    *,
    eps: float = DEFAULT_EPS,
    ignore=None,
    device="cpu",
    dtype="float32",
    chunk: int | None = None,
) -> np.ndarray:
    """:func:`wirescene.core.raycast.segment_blocked` on a torch device.

    Same arguments, broadcasting and result (a ``(..., P)`` numpy bool array); in
    addition ``device`` (a name for :func:`resolve_device` or a ``torch.device``),
    ``dtype`` of the computation (``"float32"`` or ``"float64"``) and ``chunk``, the
    maximum number of (ray, triangle) pairs per step (default :func:`default_chunk`:
    larger on a GPU). Coordinates are made relative to the origins in float64 on the
    host, block by block, before they are cast and moved to the device, so a broadcast
    input is never materialised for the whole batch.
    """
    torch, dev, dt, chunk = _setup(device, dtype, chunk)
    origins, targets, triangles, batch = segment_inputs(origins, targets, triangles, eps)
    P, F = targets.shape[-2], triangles.shape[-3]
    if P == 0 or F == 0 or 0 in batch:
        return np.zeros(batch + (P,), dtype=bool)
    Bn = int(np.prod(batch, dtype=int))

    def rows_of(arr, tail):
        """``rows(start, stop)``: those rows of the flattened broadcast batch, copying
        only them (reshaping a broadcast view would copy all of it)."""
        arr = np.broadcast_to(arr, batch + tail)
        if arr.flags.c_contiguous or len(batch) <= 1:  # the reshape is a view
            flat = arr.reshape((Bn,) + tail)
            return lambda start, stop: flat[start:stop]
        return lambda start, stop: arr[np.unravel_index(np.arange(start, stop), batch)]

    o_rows, x_rows, t_rows = rows_of(origins, (3,)), rows_of(targets, (P, 3)), rows_of(triangles, (F, 3, 3))
    ign_shared = ign_rows = None
    if ignore is not None:
        ignore = np.asarray(ignore, dtype=bool)
        if ignore.ndim <= 2:  # shared by the whole batch: converted once
            try:
                shared = np.broadcast_to(ignore, (P, F))
            except ValueError as exc:
                raise ShapeError(f"ignore {ignore.shape} does not broadcast to {(P, F)}") from exc
            ign_shared = _additive(torch, _tensor(torch, shared, dev), dt)[None]
        else:
            try:
                ign_rows = rows_of(ignore, (P, F))
            except ValueError as exc:
                raise ShapeError(f"ignore {ignore.shape} does not broadcast to {batch + (P, F)}") from exc

    def block(start, stop):
        o = o_rows(start, stop)
        D = _tensor(torch, x_rows(start, stop) - o[:, None, :], dev, dt)
        # (b, F, 3 corners, 3 xyz) -> (b, xyz, corner, F) -> (b, 3, 3F)
        t = (t_rows(start, stop) - o[:, None, None, :]).transpose(0, 3, 2, 1)
        K = _tensor(torch, t, dev, dt).view(len(t), 3, 3 * F)
        ign = ign_shared
        if ign_rows is not None:
            ign = _additive(torch, _tensor(torch, ign_rows(start, stop), dev), dt)
        return D, K, ign

    with torch.no_grad():
        out = _blocked(torch, block, Bn, P, F, eps, chunk, dev, dt)
    return out.reshape(batch + (P,))


def _relative_vertices(vertices, camera_center, n_tail: int):
    """``(batch, vertices - camera_center)``: the broadcast batch shape and the
    vertices relative to the centre in float64 (host), before any cast."""
    center = np.asarray(camera_center, dtype=float)
    check_shape("camera_center", center, (..., 3))
    try:
        batch = np.broadcast_shapes(vertices.shape[:-n_tail], center.shape[:-1])
    except ValueError as exc:
        raise ShapeError(
            f"camera_center {center.shape} does not broadcast against vertices {vertices.shape}"
        ) from exc
    c = np.broadcast_to(center, batch + (3,)).reshape(batch + (1,) * (n_tail - 1) + (3,))
    return batch, np.broadcast_to(vertices, batch + vertices.shape[-n_tail:]) - c


def _occlusion(torch, rel, faces, ignore, eps, chunk, dev, dt):
    """Rows ``rel`` ``(Bn, P, 3)`` (relative vertices) against their own triangles
    ``faces`` ``(F, 3)`` (indices into P), with the shared ``ignore`` ``(P, F)``.
    Only the vertices travel to the device; the triangles are gathered there."""
    Bn, P, F = rel.shape[0], rel.shape[1], len(faces)
    X = _tensor(torch, rel, dev, dt)
    fidx = _tensor(torch, faces.T.reshape(-1).astype(np.int64), dev)  # corner-major (3 F,)
    ign = _additive(torch, _tensor(torch, ignore, dev), dt)[None]

    Xc = X.transpose(1, 2).contiguous()  # (Bn, 3, P) component-major

    def block(start, stop):
        return X[start:stop], torch.index_select(Xc[start:stop], 2, fidx), ign

    return _blocked(torch, block, Bn, P, F, eps, chunk, dev, dt)


def self_occlusion(vertices, faces, camera_center, *, eps: float = DEFAULT_EPS, device="cpu",
                   dtype="float32", chunk: int | None = None) -> np.ndarray:
    """:func:`wirescene.infer.occlusion.self_occlusion` on a torch device.

    ``vertices`` ``(..., V, 3)``, ``faces`` ``(F, 3)``, ``camera_center`` ``(3,)`` or
    ``(..., 3)``; returns ``(..., V)`` bool (numpy). Faces incident to a vertex are
    never tested against it. ``device``, ``dtype``, ``chunk``: see
    :func:`segment_blocked`.
    """

    torch, dev, dt, chunk = _setup(device, dtype, chunk)
    check_eps(eps)
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (..., None, 3))
    V = vertices.shape[-2]
    faces = check_faces(faces, V)
    batch, rel = _relative_vertices(vertices, camera_center, 2)
    if V == 0 or len(faces) == 0 or 0 in batch:
        return np.zeros(batch + (V,), dtype=bool)
    Bn = int(np.prod(batch, dtype=int))
    with torch.no_grad():
        out = _occlusion(torch, rel.reshape(Bn, V, 3), faces, incidence(faces, V), eps, chunk, dev, dt)
    return out.reshape(batch + (V,))


def inter_object_occlusion(vertices, faces, camera_center, *, eps: float = DEFAULT_EPS, device="cpu",
                           dtype="float32", chunk: int | None = None, cull: bool = True) -> np.ndarray:
    """:func:`wirescene.infer.occlusion.inter_object_occlusion` on a torch device.

    ``vertices`` ``(..., N, V, 3)``, ``faces`` ``(F, 3)``, ``camera_center`` ``(3,)``
    or ``(..., 3)`` (one per scene); returns ``(..., N, V)`` bool (numpy): hidden by a
    face of another object of the same scene (self-occlusion not included).

    Each (target object, occluder object) pair of a scene is one row of the kernel
    (V segments against F triangles); with ``cull`` (default) only the pairs of
    :func:`wirescene.infer.occlusion.interaction_candidates` are cast, which does not change the result (in a
    street scene most cars do not overlap in the image). ``device``, ``dtype``,
    ``chunk``: see :func:`segment_blocked`.
    """
    torch, dev, dt, chunk = _setup(device, dtype, chunk)
    check_eps(eps)
    vertices = np.asarray(vertices, dtype=float)
    check_shape("vertices", vertices, (..., None, None, 3))
    N, V = vertices.shape[-3], vertices.shape[-2]
    faces = check_faces(faces, V)
    F = len(faces)
    batch, rel = _relative_vertices(vertices, camera_center, 3)
    if N < 2 or V == 0 or F == 0 or 0 in batch:
        return np.zeros(batch + (N, V), dtype=bool)
    Bn = int(np.prod(batch, dtype=int))
    q = rel.reshape(Bn, N, V, 3)
    if cull:

        candidate = interaction_candidates(q)
    else:
        candidate = np.broadcast_to(~np.eye(N, dtype=bool), (Bn, N, N))
    s_idx, i_idx, j_idx = np.nonzero(candidate)
    if len(s_idx) == 0:
        return np.zeros(batch + (N, V), dtype=bool)
    with torch.no_grad():
        X = _tensor(torch, q.reshape(Bn * N, V, 3), dev, dt)
        Xc = X.transpose(1, 2).contiguous()  # (Bn N, 3, V) component-major
        fidx = _tensor(torch, faces.T.reshape(-1).astype(np.int64), dev)
        target = _tensor(torch, s_idx * N + i_idx, dev)
        occluder = _tensor(torch, s_idx * N + j_idx, dev)

        def block(start, stop):
            D = torch.index_select(X, 0, target[start:stop])
            K = torch.index_select(torch.index_select(Xc, 0, occluder[start:stop]), 2, fidx)
            return D, K, None

        blocked = _blocked(torch, block, len(s_idx), V, F, eps, chunk, dev, dt, to_numpy=False)
        # A vertex may be hidden by several occluders: or-accumulate over the pairs.
        count = torch.zeros((Bn * N, V), dtype=torch.int32, device=dev)
        count.index_add_(0, target, blocked.to(torch.int32))
        hidden = (count > 0).cpu().numpy()
    return hidden.reshape(batch + (N, V))


def object_likelihood(evidence, self_hidden, mask_hidden, *, c: float, device="cpu",
                      dtype="float32") -> np.ndarray:
    """:func:`wirescene.infer.likelihood.object_likelihood` (paper Eq. 2) on a torch
    device: ``evidence``, ``self_hidden``, ``mask_hidden`` (or None) are ``(..., V)``
    and broadcast like numpy's; returns ``(...)`` float64 numpy, computed in ``dtype``
    (float32: about 1e-7 relative to the evidence magnitudes)."""
    torch, dev, dt, _ = _setup(device, dtype, 1)
    evidence = np.asarray(evidence, dtype=float)
    self_hidden = np.asarray(self_hidden, dtype=bool)
    shapes = [evidence.shape, self_hidden.shape]
    if mask_hidden is not None:
        mask_hidden = np.asarray(mask_hidden, dtype=bool)
        shapes.append(mask_hidden.shape)
    try:
        np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ShapeError(f"evidence/self_hidden/mask_hidden shapes do not broadcast: {shapes}") from exc
    with torch.no_grad():
        e = _tensor(torch, evidence, dev, dt)
        visible0 = ~_tensor(torch, self_hidden, dev)
        if mask_hidden is None:
            visible, n_masked = visible0, 0
        else:
            hidden_by_mask = _tensor(torch, mask_hidden, dev)
            visible = visible0 & ~hidden_by_mask
            n_masked = (visible0 & hidden_by_mask).sum(-1).to(dt)
        num = torch.where(visible, e, 0.0).sum(-1) + c * n_masked
        out = num / visible0.sum(-1).clamp_min(1).to(dt)
    return out.cpu().numpy().astype(np.float64)
