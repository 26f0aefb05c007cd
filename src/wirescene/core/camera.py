"""Pinhole camera: projection, back-projection and rays; KITTI calibration parsing.

The camera frame is KITTI's rectified reference frame (x right, y down, z forward,
metres). A :class:`Camera` wraps a full 3x4 projection matrix such as KITTI's ``P2``,
whose fourth column encodes the small offset of the colour camera from the reference
camera, so the optical centre is not exactly at the origin.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wirescene.core.errors import ArgumentError, InputError, ShapeError, check_shape
from wirescene.core.validate import path_problem, projection_problem, real_dtype_problem

KITTI_CALIB_KEYS = ("P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam")
#: Points closer than this (metres, along the optical axis) are treated as behind the
#: camera: their projection is meaningless.
NEAR_PLANE = 0.1


@dataclass(frozen=True)
class Camera:
    """A pinhole camera given by a 3x4 projection matrix ``P`` (pixels from metres).

    Parameters
    ----------
    P : (3, 4) array
        Projection matrix, ``uvw = P @ [X, 1]``.
    image_size : (width, height) or None
        Image size in pixels, used for clipping boxes and truncation tests.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.array([[721.5, 0, 609.6], [0, 721.5, 172.9], [0, 0, 1]])
    >>> camera = Camera(np.hstack([K, np.zeros((3, 1))]), image_size=(1242, 375))
    >>> camera.project([[0.0, 0.0, 10.0]])  # a point on the optical axis: the principal point
    array([[609.6, 172.9]])
    >>> uv, depth = camera.project_with_depth([[1.0, 1.65, 10.0], [0.0, 0.0, -5.0]])
    >>> uv[0].tolist(), depth.tolist()  # u = 609.6 + 721.5 * 1 / 10; depth <= 0: behind the camera
    ([681.75, 291.9475], [10.0, -5.0])
    >>> camera.backproject(uv[0], 10.0)  # the inverse, given the depth
    array([ 1.  ,  1.65, 10.  ])
    >>> np.round(camera.rays([[609.6, 172.9], [609.6 + 721.5, 172.9]]), 4)  # unit rays, 45 deg apart
    array([[0.    , 0.    , 1.    ],
           [0.7071, 0.    , 0.7071]])
    """

    P: np.ndarray
    image_size: tuple[int, int] | None = None

    def __post_init__(self):
        problem = real_dtype_problem(self.P)
        if problem:  # complex numbers: their cast to float would drop the imaginary part
            raise ArgumentError("P", problem)
        P = np.asarray(self.P, dtype=float)
        check_shape("P", P, (3, 4))
        if not np.all(np.isfinite(P)):
            raise ArgumentError("P", "must be finite, got non-finite values")
        object.__setattr__(self, "P", P)
        if self.image_size is not None:
            size = tuple(np.ravel(np.asarray(self.image_size, dtype=object)))
            if len(size) != 2 or not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and v > 0
                                         for v in size):
                raise ShapeError(f"image_size must be (width, height), two positive integers, got {self.image_size!r}")
            object.__setattr__(self, "image_size", (int(size[0]), int(size[1])))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix."""
        return self.P[:, :3]

    @property
    def center(self) -> np.ndarray:
        """(3,) optical centre in the camera frame (the null space of ``P``)."""
        return -np.linalg.solve(self.K, self.P[:, 3])

    @property
    def focal(self) -> float:
        """Horizontal focal length in pixels."""
        return float(self.P[0, 0])

    def project(self, X: np.ndarray) -> np.ndarray:
        """Project points ``(..., 3)`` to pixels ``(..., 2)``."""
        uv, _ = self.project_with_depth(X)
        return uv

    def project_with_depth(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points ``(..., 3)``; return pixels ``(..., 2)`` and depth ``(...)``.

        Depth is the third homogeneous coordinate (z relative to the optical centre).
        Points at or behind the camera get depth <= 0 and non-finite pixels are avoided
        by clamping the divisor; callers must test the depth themselves.
        """
        X = np.asarray(X, dtype=float)
        check_shape("X", X, (..., 3))
        uvw = X @ self.P[:, :3].T
        # The translation added and the pixels divided a component at a time: the same
        # operations as on whole (..., 3) rows, in long loops rather than short ones of 2 or 3.
        for k in range(3):
            uvw[..., k] += self.P[k, 3]
        w = uvw[..., 2]
        safe = np.where(np.abs(w) < 1e-9, 1e-9, w)
        uv = np.empty(uvw.shape[:-1] + (2,))
        np.divide(uvw[..., 0], safe, out=uv[..., 0])
        np.divide(uvw[..., 1], safe, out=uv[..., 1])
        return uv, w

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Unit viewing directions ``(..., 3)`` through pixels ``uv`` ``(..., 2)``."""
        uv = np.asarray(uv, dtype=float)
        check_shape("uv", uv, (..., 2))
        homog = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
        d = homog @ np.linalg.inv(self.K).T
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def backproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Points ``(..., 3)`` seen at pixels ``uv`` ``(..., 2)`` with depth ``(...)``.

        Inverse of :meth:`project_with_depth`.
        """
        uv = np.asarray(uv, dtype=float)
        check_shape("uv", uv, (..., 2))
        depth = np.asarray(depth, dtype=float)
        try:
            fits = np.broadcast_shapes(depth.shape, uv.shape[:-1]) == uv.shape[:-1]
        except ValueError:
            fits = False
        if not fits:
            raise ShapeError(f"depth must have shape {uv.shape[:-1]} (one per pixel) or broadcast to it, got {depth.shape}")
        homog = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1) * depth[..., None]
        return (homog - self.P[:, 3]) @ np.linalg.inv(self.K).T


@dataclass(frozen=True)
class KittiCalib:
    """The matrices of a KITTI object calibration file (all as float arrays): ``P0`` to
    ``P3`` ``(3, 4)``, ``R0_rect`` ``(3, 3)`` and ``Tr_velo_to_cam`` ``(3, 4)``.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.resources import DATA_DIR
    >>> calib = read_kitti_calib(DATA_DIR / "sample" / "kitti" / "training" / "calib" / "000010.txt")
    >>> camera = calib.camera((1242, 375))  # the left colour camera, P2
    >>> camera.focal, camera.image_size
    (721.5377, (1242, 375))
    >>> np.round(camera.center, 3)  # P2's fourth column: the colour camera sits 6 cm left of the reference
    array([-0.06 ,  0.   , -0.003])
    """

    P0: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    P3: np.ndarray
    R0_rect: np.ndarray = field(default_factory=lambda: np.eye(3))
    Tr_velo_to_cam: np.ndarray = field(default_factory=lambda: np.eye(4)[:3])
    source: str | None = None  # the file it was read from, named in errors

    def camera(self, image_size: tuple[int, int] | None = None) -> Camera:
        """The left colour camera (``P2``) used by every KITTI object label; with the
        image size, its principal point is checked to lie near the image."""
        problem = projection_problem(self.P2, image_size)
        if problem:
            raise InputError(f"P2: {problem}", path=self.source)
        return Camera(self.P2, image_size)


def _calibration_text(path: Path) -> str:
    """The text of a calibration file; an :class:`InputError` naming it if it cannot be read."""
    problem = path_problem(path, "calibration")
    if problem:
        raise InputError(problem, path=path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read calibration file ({exc.__class__.__name__})", path=path) from exc


def read_projection(path: str | Path) -> np.ndarray:
    """The ``(3, 4)`` projection matrix of a calibration file: a KITTI calibration's ``P2``
    (lines ``KEY: numbers``), or a file holding only the numbers of one matrix (spaces,
    commas or lines between them): 12, the projection ``P`` row by row, or 9, the
    intrinsics ``K`` of a camera at the frame's origin (``P = K [I | 0]``).

    The fit places that camera as KITTI's: about 1.65 m above a road it looks along
    (``LiftingOptions.camera_height`` and ``camera_pitch`` for another rig).

    Raises
    ------
    InputError
        If the file is missing or unreadable, holds another count of numbers, or its
        matrix is no street camera's (:func:`wirescene.core.validate.projection_problem`).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = Path(d) / "K.txt"
    ...     _ = path.write_text("721.5 0 609.6  0 721.5 172.9  0 0 1")
    ...     P = read_projection(path)
    >>> P.shape, P[:, 3].tolist()
    ((3, 4), [0.0, 0.0, 0.0])
    >>> from wirescene.core.resources import DATA_DIR
    >>> read_projection(DATA_DIR / "sample" / "kitti" / "training" / "calib" / "000010.txt")[0].tolist()  # P2
    [721.5377, 0.0, 609.5593, 44.85728]
    """
    return read_calibration(path).P2


def read_calibration(path: str | Path) -> KittiCalib:
    """A calibration file in any form :func:`read_projection` reads, as a :class:`KittiCalib`:
    a KITTI calibration file's matrices (:func:`read_kitti_calib`), or the ``P`` of the
    numbers of ``K`` or ``P`` as ``P0`` to ``P3`` (``R0_rect`` and ``Tr_velo_to_cam`` their
    defaults); ``source`` names the file in later errors.

    Raises
    ------
    InputError
        As :func:`read_projection`, naming the file.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = Path(d) / "P.txt"
    ...     _ = path.write_text("721.5, 0, 609.6, 44.9,  0, 721.5, 172.9, 0.2,  0, 0, 1, 0.003")
    ...     calib = read_calibration(path)
    >>> calib.P2[:, 3].tolist(), calib.source.endswith("P.txt")
    ([44.9, 0.2, 0.003], True)
    >>> calib.camera((1242, 375)).focal  # the camera every frame of a folder takes (KittiDataset calib=)
    721.5
    """
    path = Path(path)
    text = _calibration_text(path)
    if ":" in text:
        return _parse_kitti_calib(text, path)
    expected = "expected a KITTI calibration ('KEY: numbers' lines) or the 9 numbers of K or 12 of P"
    try:
        numbers = np.array([float(v) for v in text.replace(",", " ").split()])
    except ValueError as exc:
        raise InputError(f"{expected}, found text that is not a number", path=path) from exc
    if numbers.size == 12:
        P = numbers.reshape(3, 4)
    elif numbers.size == 9:
        P = np.hstack([numbers.reshape(3, 3), np.zeros((3, 1))])
    else:
        raise InputError(f"{expected}, found {numbers.size} numbers", path=path)
    problem = projection_problem(P)
    if problem:
        raise InputError(problem, path=path)
    return KittiCalib(P, P, P, P, source=str(path))


def read_kitti_calib(path: str | Path) -> KittiCalib:
    """Parse a KITTI object calibration file.

    Lines are ``KEY: numbers``; ``P2`` is required, ``P0``, ``P1`` and ``P3`` default to
    it, ``R0_rect`` to the identity and ``Tr_velo_to_cam`` to ``[I | 0]``; other keys
    (``Tr_imu_to_velo``) are read and dropped.

    Raises
    ------
    InputError
        If the file is missing, a line is malformed or ``P2`` is absent.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> calib = read_kitti_calib(DATA_DIR / "sample" / "kitti" / "training" / "calib" / "000010.txt")
    >>> calib.P2.shape, calib.R0_rect.shape, calib.Tr_velo_to_cam.shape
    ((3, 4), (3, 3), (3, 4))
    >>> calib.P2[:, 3].tolist()  # the colour camera's offset from the reference camera (pixels x metres)
    [44.85728, 0.2163791, 0.002745884]
    """
    path = Path(path)
    return _parse_kitti_calib(_calibration_text(path), path)


def _parse_kitti_calib(text: str, path: Path) -> KittiCalib:
    """:func:`read_kitti_calib` of the text of the file ``path`` (named in errors)."""
    values: dict[str, np.ndarray] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, rest = line.partition(":")
        if not sep:
            raise InputError(f"line {lineno}: expected 'KEY: numbers'", path=path)
        key = key.strip()
        if key in values:
            raise InputError(f"line {lineno}: {key} is given twice", path=path)
        try:
            values[key] = np.array([float(v) for v in rest.split()])
        except ValueError as exc:
            raise InputError(f"line {lineno}: non-numeric value in {key}", path=path) from exc
    if "P2" not in values:
        raise InputError("calibration has no P2 matrix", path=path)
    shapes = {"P0": (3, 4), "P1": (3, 4), "P2": (3, 4), "P3": (3, 4), "R0_rect": (3, 3), "Tr_velo_to_cam": (3, 4)}
    out = {}
    for key, shape in shapes.items():
        if key not in values:
            continue
        if values[key].size != shape[0] * shape[1]:
            raise InputError(f"{key} has {values[key].size} numbers, expected {shape[0] * shape[1]}", path=path)
        out[key] = values[key].reshape(shape)
    problem = projection_problem(out["P2"])
    if problem:
        raise InputError(f"P2: {problem}", path=path)
    for key in ("P0", "P1", "P3"):
        out.setdefault(key, out["P2"])
    return KittiCalib(**out, source=str(path))


#: ``Tr_velo_to_cam`` of a LiDAR at the camera with KITTI's LiDAR axes (x forward, y left, z up).
VELO_TO_CAM_AXES = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0]])


def write_kitti_calib(path: str | Path, P2: np.ndarray) -> None:
    """Write a minimal KITTI calibration file, the seven lines of KITTI's in their order:
    P0..P3 are ``P2``, R0 is identity, ``Tr_velo_to_cam`` that of a LiDAR at the camera
    with KITTI's axes (:data:`VELO_TO_CAM_AXES`; tools that take label boxes into the LiDAR
    frame need them), ``Tr_imu_to_velo`` identity.

    Examples
    --------
    >>> import tempfile
    >>> P2 = np.array([[721.5, 0, 609.6, 44.9], [0, 721.5, 172.9, 0.2], [0, 0, 1, 0.003]])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_kitti_calib(Path(d) / "000000.txt", P2)
    ...     keys = [line.split(":")[0] for line in (Path(d) / "000000.txt").read_text().splitlines()]
    ...     calib = read_kitti_calib(Path(d) / "000000.txt")
    >>> keys
    ['P0', 'P1', 'P2', 'P3', 'R0_rect', 'Tr_velo_to_cam', 'Tr_imu_to_velo']
    >>> bool(np.array_equal(calib.P2, P2))  # written with 13 significant digits: these numbers round-trip
    True
    """
    P2 = np.asarray(P2, dtype=float)
    check_shape("P2", P2, (3, 4))
    fmt = lambda a: " ".join(f"{v:.12e}" for v in np.asarray(a).ravel())  # noqa: E731
    lines = [f"P{i}: {fmt(P2)}" for i in range(4)]
    lines.append(f"R0_rect: {fmt(np.eye(3))}")
    lines.append(f"Tr_velo_to_cam: {fmt(VELO_TO_CAM_AXES)}")
    lines.append(f"Tr_imu_to_velo: {fmt(np.eye(4)[:3])}")
    Path(path).write_text("\n".join(lines) + "\n")
