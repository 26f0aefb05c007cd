"""Detections, batched scene particles and the final scene estimate.

One representation for a batch of scene hypotheses: :class:`SceneParticles` stores
``P`` particles of ``N`` objects as arrays, every object with its own ground-plane
pitch/roll column so that the variants with and without a shared plane use the same
code (with a shared plane all columns of a particle are equal).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wirescene.core.boxes import box_centers
from wirescene.core.errors import ArgumentError, ShapeError, check_shape
from wirescene.core.groundplane import (
    KITTI_CAMERA_HEIGHT,
    GroundPlane,
    alpha_from_rotation_y,
    object_pose,
    rotation_y_of,
)
from wirescene.core.labels import MAX_ALPHA, Label, format_labels
from wirescene.core.validate import finite_real, real_dtype_problem
from wirescene.core.wireframe import HIDDEN_BY, N_VERTICES


def _numbers(name: str, values) -> np.ndarray:
    """``values`` as a float array; an :class:`ArgumentError` naming ``name`` where they are no
    real numbers (:func:`~wirescene.core.validate.real_dtype_problem`: complex numbers, booleans,
    text) or ragged rows."""
    try:
        held = np.asarray(values)
    except ValueError:  # ragged rows: the cast below says so
        held = None
    problem = None if held is None else real_dtype_problem(held)
    if problem is not None:  # complex numbers would lose their imaginary part with a mere warning
        raise ArgumentError(name, problem)
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ArgumentError(name, f"expected numbers (rows of equal length), {str(exc).splitlines()[0]}") from None


@dataclass
class Detections:
    """2D pre-detections of one image.

    Attributes
    ----------
    boxes : (D, 4) float array
        ``x1, y1, x2, y2`` in pixels.
    scores : (D,) float array
    alpha : (D,) float array
        Coarse viewpoint (observation angle, radians, within one turn) of each detection,
        typically the centre of one of 8 bins; NaN where the detector gives no viewpoint.
    source : str
        Where the detections came from (``"gt"``, a file name, ...).

    Returned by :func:`wirescene.detect` and by the readers of
    :mod:`wirescene.io.detections`; ``scores`` and ``alpha`` broadcast to one per box.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.types import Detections
    >>> dets = Detections([[300, 180, 520, 300], [600, 170, 680, 230]], scores=[0.9, 0.4], alpha=np.nan)
    >>> len(dets), dets.boxes.shape
    (2, (2, 4))
    >>> bool(np.isnan(dets.alpha).all())  # no viewpoint: the lifting searches every azimuth
    True
    >>> dets.subset(dets.scores > 0.5).boxes
    array([[300., 180., 520., 300.]])
    >>> len(Detections.empty())
    0
    """

    boxes: np.ndarray
    scores: np.ndarray
    alpha: np.ndarray
    source: str = ""

    def __post_init__(self):
        self.boxes = _numbers("boxes", self.boxes)
        if self.boxes.size == 0 or self.boxes.shape == (4,):  # no box, or one box
            self.boxes = self.boxes.reshape(-1, 4)
        check_shape("boxes", self.boxes, (None, 4))
        n = len(self.boxes)
        for name in ("scores", "alpha"):
            values = _numbers(name, getattr(self, name))
            if values.shape not in ((), (n,)):
                raise ShapeError(f"{name} must have shape ({n},) (one per box) or be one number, got {values.shape}")
            setattr(self, name, np.broadcast_to(values, (n,)).copy())
        bad = np.abs(np.nan_to_num(self.alpha, nan=0.0, posinf=np.inf, neginf=np.inf)) > MAX_ALPHA
        if bad.any():
            v = float(self.alpha[bad.argmax()])
            hint = {-10.0: " (KITTI's -10, not estimated, is NaN here)"}.get(v, " (degrees?)" if np.isfinite(v) else "")
            raise ArgumentError("alpha", f"expected radians within one turn (|alpha| <= 2 pi; NaN: no viewpoint), got "
                                         f"{v:g}{hint}")

    def __len__(self) -> int:
        return len(self.boxes)

    @staticmethod
    def empty(source: str = "") -> "Detections":
        """No detection (an image without cars)."""
        return Detections(np.zeros((0, 4)), np.zeros(0), np.zeros(0), source)

    def subset(self, index) -> "Detections":
        """The detections selected by ``index`` (a boolean mask or indices)."""
        return Detections(self.boxes[index], self.scores[index], self.alpha[index], self.source)


@dataclass
class SceneParticles:
    """A batch of ``P`` scene hypotheses over the same ``N`` detections.

    All arrays are ``(P, N)``: ground plane ``pitch``/``roll`` per object (equal across a
    row when the plane is shared), position ``x``/``z`` on that plane, ``azimuth`` about
    the plane normal, and the per-object ``cost`` (lower is better) of the stage that
    made them. ``dims`` ``(P, N, 3)`` holds each object's box size (h, w, l).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.types import SceneParticles
    >>> zeros = np.zeros((3, 2))  # 3 particles of 2 cars, on a level road
    >>> particles = SceneParticles(pitch=zeros, roll=zeros, x=np.array([[-2.0, 3.0]] * 3), z=np.full((3, 2), 12.0),
    ...                            azimuth=zeros, object_cost=np.array([[0.1, 0.2], [0.3, 0.0], [0.0, 0.05]]),
    ...                            dims=np.full((3, 2, 3), [1.5, 1.6, 3.9]))
    >>> particles.n_particles, particles.n_objects, np.round(particles.cost, 2).tolist()
    (3, 2, [0.3, 0.3, 0.05])
    >>> location, R = particles.poses()
    >>> location.shape, R.shape, location[0, 0].tolist()  # bottom centres on the road, 1.65 m below the camera
    ((3, 2, 3), (3, 2, 3, 3), [-2.0, 1.65, 12.0])
    >>> best = particles.take(np.argsort(particles.cost)[:1])  # the best particle
    >>> best.n_particles, best.object_cost.tolist()
    (1, [[0.0, 0.05]])
    """

    pitch: np.ndarray
    roll: np.ndarray
    x: np.ndarray
    z: np.ndarray
    azimuth: np.ndarray
    object_cost: np.ndarray
    dims: np.ndarray
    height: float = KITTI_CAMERA_HEIGHT
    shared_plane: bool = False

    def __post_init__(self):
        for name in ("pitch", "roll", "x", "z", "azimuth", "object_cost"):
            check_shape(name, getattr(self, name), self.x.shape)
        check_shape("dims", self.dims, self.x.shape + (3,))

    @property
    def n_particles(self) -> int:
        """``P``, the number of scene hypotheses."""
        return self.x.shape[0]

    @property
    def n_objects(self) -> int:
        """``N``, the number of objects (detections) of each hypothesis."""
        return self.x.shape[1]

    @property
    def cost(self) -> np.ndarray:
        """(P,) scene cost: the sum of object costs."""
        return self.object_cost.sum(axis=1)

    def poses(self):
        """Bottom-centre ``location`` ``(P, N, 3)`` and rotation ``R`` ``(P, N, 3, 3)``."""
        return object_pose(self.x, self.z, self.azimuth, self.pitch, self.roll, self.height)

    def take(self, index) -> "SceneParticles":
        """The particles selected by ``index`` along the particle axis: ``(k,)`` rows,
        or ``(k, N)`` a row per object (regrouping objects of different particles)."""
        index = np.asarray(index)
        if index.ndim == 2:
            cols = np.arange(self.n_objects)
            pick = lambda a: np.asarray(a)[index, cols]  # noqa: E731
        else:
            pick = lambda a: np.asarray(a)[index]  # noqa: E731
        return SceneParticles(
            pick(self.pitch), pick(self.roll), pick(self.x), pick(self.z), pick(self.azimuth),
            pick(self.object_cost), pick(self.dims), self.height, self.shared_plane,
        )


_ESTIMATE_SHAPES = {"box2d": (4,), "location": (3,), "R": (3, 3), "dims": (3,), "shape": (None,),
                    "vertices": (N_VERTICES, 3), "visibility": (N_VERTICES,)}


def _estimate_field(name: str, value):
    """``value`` as :class:`ObjectEstimate` holds its field ``name`` (arrays as own copies: a view
    into the search's arrays would keep them all alive), checked: shapes (a wrong one fails where
    it is made, not in a label line or a picture), the label line's numbers finite (``R`` holds
    rotation_y: a NaN car would reach label files and metrics) and the size positive."""
    if name in _ESTIMATE_SHAPES and value is not None:
        value = np.array(value)
        check_shape(name, value, _ESTIMATE_SHAPES[name])
    if name in ("box2d", "location", "R", "dims"):
        values = _numbers(name, value)
        if not np.all(np.isfinite(values)):
            raise ArgumentError(name, f"must be finite, got {np.round(values, 6).tolist()}")
        if name == "dims" and not np.all(values > 0):
            raise ArgumentError(name, f"must be positive (h w l, metres), got {np.round(values, 6).tolist()}")
    elif name == "score" and not finite_real(value):
        raise ArgumentError("score", f"must be a finite number, got {value!r}")
    return value


def _disagreement(name: str, visibility, reasons: np.ndarray) -> None:
    """Refuse, as argument ``name``, a ``visibility`` ``(36,)`` (None included) that is not where
    ``reasons`` (an :attr:`ObjectEstimate.hidden_by`) says ``visible``."""
    visible = reasons == "visible"
    if visibility is None:
        raise ArgumentError(name, "visibility cannot be None where hidden_by says what hides each vertex")
    visibility = np.asarray(visibility, bool)
    if not np.array_equal(visibility, visible):
        v = int(np.flatnonzero(visibility != visible)[0])
        raise ArgumentError(name, f"vertex {v} is {str(reasons[v])!r}, but visibility says it is "
                                  f"{'visible' if visibility[v] else 'hidden'}")


@dataclass
class ObjectEstimate:
    """One car of a scene estimate (camera frame, metres, radians).

    Attributes
    ----------
    detection_index : int
        Index of the pre-detection the car was fitted to.
    box2d : (4,) array
        That pre-detection's box ``x1 y1 x2 y2`` (also :attr:`box`).
    score : float
        Confidence that the estimate is right (KITTI's 16th column).
    location : (3,) array
        Bottom centre of the 3D box.
    R : (3, 3) array
        Object-to-camera rotation (azimuth :attr:`rotation_y`, tilted by the plane).
    dims : (3,) array
        Box size ``h w l`` (also :attr:`dimensions`).
    cost : float
        The fit's objective for this car (lower is better).
    pitch, roll : float
        The ground plane under the car.
    shape, vertices, visibility, exemplar, occluder_mask
        Fine variants only: shape coefficients ``(K,)``, wireframe vertices ``(36, 3)``,
        their visibility ``(36,)`` (also :attr:`visible`), the nearest CAD exemplar
        (also :attr:`cad_model`) and the occluder mask's index; ``None`` otherwise.
    detection_score : float or None
        The pre-detection's own score.
    hidden_by : (36,) str array or None
        Fine variants only: what hides each vertex (:data:`wirescene.core.wireframe.HIDDEN_BY`:
        ``"visible"``, ``"self"``, ``"truncated"``, ``"other-car"``, ``"occluder"``); where
        given, :attr:`visibility` is where it says ``"visible"`` (derived when not given).

    Raises
    ------
    ShapeError
        An array of another shape than above.
    ArgumentError
        A non-finite (or non-numeric) number of the label line: ``box2d``, ``score``,
        ``location``, ``R`` (the azimuth) or ``dims``, or a size ``dims`` not positive; where
        the estimate is made and where a field is set later (``car.score = nan``); a
        ``hidden_by`` of another word than ``HIDDEN_BY``'s, or one and a ``visibility`` that
        disagree, whichever is set last.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import ObjectEstimate
    >>> car = ObjectEstimate(detection_index=0, box2d=np.array([300.0, 180.0, 520.0, 300.0]), score=0.8,
    ...                      location=np.array([-2.0, 1.65, 12.0]), R=rotation_y(0.3),
    ...                      dims=np.array([1.5, 1.6, 3.9]), cost=0.0)
    >>> round(car.rotation_y, 6), round(car.alpha, 6)  # alpha = rotation_y - atan2(x, z)
    (0.3, 0.465149)
    >>> car.centroid  # the bottom centre raised by h / 2 (y points down)
    array([-2. ,  0.9, 12. ])
    >>> car.to_label().type, car.to_label().score
    ('Car', 0.8)
    >>> ObjectEstimate(detection_index=0, box2d=car.box2d, score=0.8, location=[-2.0, 12.0], R=car.R, dims=car.dims,
    ...                cost=0.0)
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ShapeError: location must have shape (3,), got (2,)
    >>> ObjectEstimate(detection_index=0, box2d=car.box2d, score=0.8, location=[np.nan, 1.65, 12.0], R=car.R,
    ...                dims=car.dims, cost=0.0)
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ArgumentError: location: must be finite, got [nan, 1.65, 12.0]
    >>> car.score = float("nan")  # a confidence set later: checked too
    Traceback (most recent call last):
    ...
    wirescene.core.errors.ArgumentError: score: must be a finite number, got nan
    """

    detection_index: int
    box2d: np.ndarray
    score: float
    location: np.ndarray  # (3,) bottom centre
    R: np.ndarray  # (3, 3) object-to-camera
    dims: np.ndarray  # (3,) h, w, l
    cost: float
    pitch: float = 0.0
    roll: float = 0.0
    shape: np.ndarray | None = None  # (K,) shape coefficients
    vertices: np.ndarray | None = None  # (36, 3) camera frame
    visibility: np.ndarray | None = None  # (36,) bool
    exemplar: str | None = None
    occluder_mask: int | None = None  # index into wirescene.core.occluders.occluder_masks()
    # The pre-detection's own score; ``score`` is then the calibrated confidence of the
    # estimate (wirescene.fitting.confidence), written as KITTI's 16th column.
    detection_score: float | None = None
    hidden_by: np.ndarray | None = None  # (36,) str, wirescene.core.wireframe.HIDDEN_BY

    def __setattr__(self, name, value):
        # every assignment checked, the dataclass's own and later ones (apply_confidence sets the score after the fit)
        value = _estimate_field(name, value)
        # hidden_by and visibility agree whichever is set, when made (hidden_by comes last) or later
        if name == "hidden_by" and value is not None:
            value = self._hidden_by(value)
        elif name == "visibility" and getattr(self, "hidden_by", None) is not None:
            _disagreement("visibility", value, self.hidden_by)
        super().__setattr__(name, value)

    def _hidden_by(self, value) -> np.ndarray:
        """``value`` as :attr:`hidden_by`, a (36,) str array of known words that agrees with
        :attr:`visibility` (which it makes where there is none)."""
        reasons = np.array(value, dtype=str)
        check_shape("hidden_by", reasons, (N_VERTICES,))
        unknown = sorted(set(reasons.tolist()) - set(HIDDEN_BY))
        if unknown:
            raise ArgumentError("hidden_by", f"unknown reason {unknown[0]!r} (one of {', '.join(HIDDEN_BY)})")
        if getattr(self, "visibility", None) is None:
            super().__setattr__("visibility", reasons == "visible")
        else:
            _disagreement("hidden_by", self.visibility, reasons)
        return reasons

    def __repr__(self) -> str:
        extra = "" if self.exemplar is None else f", exemplar={self.exemplar!r}"
        return (f"ObjectEstimate(detection_index={self.detection_index}, "
                f"location={np.round(np.asarray(self.location, float), 2).tolist()}, "
                f"rotation_y={self.rotation_y:.3f}, dims={np.round(np.asarray(self.dims, float), 2).tolist()}, "
                f"score={self.score:.3f}{extra})")

    @property
    def rotation_y(self) -> float:
        """Azimuth about the camera's y axis (KITTI ``rotation_y``), radians."""
        return float(rotation_y_of(self.R))

    # The public names of the API (``wirescene.fit(...).cars[i].dimensions`` etc.).
    @property
    def dimensions(self) -> np.ndarray:
        """(3,) box size ``h, w, l`` in metres (KITTI order)."""
        return self.dims

    @property
    def box(self) -> np.ndarray:
        """(4,) the pre-detection box ``x1, y1, x2, y2`` this car was fitted to."""
        return self.box2d

    @property
    def visible(self) -> np.ndarray | None:
        """(36,) bool: vertices neither self-occluded nor occluded (fine variants)."""
        return self.visibility

    @property
    def cad_model(self) -> str | None:
        """Name of the nearest CAD exemplar of the fitted shape (fine variants)."""
        return self.exemplar

    def to_label(self, type_: str = "Car") -> Label:
        """The KITTI label row of this car (with its score; truncation and occlusion
        are not estimated and written as -1, as KITTI detection files do)."""
        return Label(type=type_, truncated=-1.0, occluded=-1, alpha=self.alpha, box=self.box2d, dims=self.dims,
                     location=self.location, rotation_y=self.rotation_y, score=self.score)

    @property
    def alpha(self) -> float:
        """Observation angle (KITTI ``alpha``), radians."""
        return float(alpha_from_rotation_y(self.rotation_y, self.location[0], self.location[2]))

    @property
    def centroid(self) -> np.ndarray:
        """(3,) centre of the 3D box."""
        return box_centers(self.dims, self.location, self.R)

    def to_dict(self) -> dict:
        """The car as plain JSON-ready values (fine-variant fields only where set)."""
        d = {
            "detection_index": int(self.detection_index),
            "box2d": [float(v) for v in self.box2d],
            "score": float(self.score),
            "detection_score": None if self.detection_score is None else float(self.detection_score),
            "location": [float(v) for v in self.location],
            "rotation_y": self.rotation_y,
            "alpha": self.alpha,
            "dimensions_hwl": [float(v) for v in self.dims],
            "ground_plane": {"pitch": float(self.pitch), "roll": float(self.roll)},
            "cost": float(self.cost),
        }
        if self.shape is not None:
            d["shape"] = [float(v) for v in self.shape]
        if self.vertices is not None:
            d["vertices"] = np.round(self.vertices, 4).tolist()
        if self.visibility is not None:
            d["visibility"] = [bool(v) for v in self.visibility]
        if self.exemplar is not None:
            d["exemplar"] = self.exemplar
        if self.occluder_mask is not None:
            d["occluder_mask"] = int(self.occluder_mask)
        if self.hidden_by is not None:
            d["hidden_by"] = [str(r) for r in self.hidden_by]
        return d


@dataclass
class SceneEstimate:
    """The result of fitting a scene: the chosen particle, as per-object estimates.

    Returned by :func:`wirescene.fit`.

    Attributes
    ----------
    variant : str
        The model variant that made it (``"coarse+gp"``, ``"full"``, ...).
    objects : list of ObjectEstimate
        The cars, one per pre-detection (:attr:`cars` sorts them by detection).
    camera_height : float
        Height of the camera above the ground plane, metres.
    shared_plane : bool
        Whether all cars stand on one ground plane (:attr:`ground_plane`).
    n_particles : int
        Number of scene particles of the search.
    extras : dict
        Further JSON-ready entries of :meth:`to_dict`.
    detections : Detections or None
        The pre-detections the scene was fitted to (viewpoints completed).

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.groundplane import rotation_y
    >>> from wirescene.core.types import ObjectEstimate, SceneEstimate
    >>> car = ObjectEstimate(detection_index=0, box2d=np.array([300.0, 180.0, 520.0, 300.0]), score=0.8,
    ...                      location=np.array([-2.0, 1.65, 12.0]), R=rotation_y(0.3),
    ...                      dims=np.array([1.5, 1.6, 3.9]), cost=0.0)
    >>> scene = SceneEstimate(variant="coarse+gp", objects=[car], shared_plane=True)
    >>> scene.ground_plane
    GroundPlane(pitch=0.0, roll=0.0, height=1.65)
    >>> print(scene.to_kitti(), end="")
    Car -1.00 -1 0.465149 300.00 180.00 520.00 300.00 1.500000 1.600000 3.900000 -2.000000 1.650000 12.000000 0.300000 0.8
    >>> sorted(scene.to_dict())
    ['camera_height', 'n_particles', 'objects', 'shared_plane', 'variant']
    """

    variant: str
    objects: list[ObjectEstimate]
    camera_height: float = KITTI_CAMERA_HEIGHT
    shared_plane: bool = False
    n_particles: int = 0
    extras: dict = field(default_factory=dict)
    # The pre-detections the scene was fitted to (viewpoints completed), one per car.
    detections: Detections | None = None

    def __repr__(self) -> str:  # a notebook's display: the cars' own reprs, not every array of the fit
        cars = "".join(f"\n    {car!r}," for car in self.cars)
        return (f"SceneEstimate(variant={self.variant!r}, shared_plane={self.shared_plane}, "
                f"n_particles={self.n_particles}, cars=[{cars}{chr(10) if cars else ''}])")

    @property
    def cars(self) -> list[ObjectEstimate]:
        """The estimated cars, one per pre-detection, in detection order."""
        return sorted(self.objects, key=lambda o: o.detection_index)

    @property
    def ground_plane(self) -> GroundPlane | None:
        """The scene's shared ground plane (``+gp`` variants), else ``None`` (every car
        then has its own ``pitch`` / ``roll``)."""
        if not self.shared_plane or not self.objects:
            return None
        o = self.objects[0]
        return GroundPlane(pitch=o.pitch, roll=o.roll, height=self.camera_height)

    def to_labels(self, type_: str = "Car") -> list[Label]:
        """KITTI label rows of the cars (with scores)."""
        return [o.to_label(type_) for o in self.cars]

    def to_kitti(self) -> str:
        """The text of a KITTI label file (16 columns, with scores) for these cars."""
        return format_labels(self.to_labels())

    def to_dict(self) -> dict:
        """The scene as plain JSON-ready values (the body of the JSON file ``wirescene fit`` writes),
        its cars in detection order (:attr:`cars`), the label file's order. A non-finite float stays
        a float here: :func:`wirescene.core.jsonio.dumps` writes it as ``null``, as ``fit`` does."""
        return {
            "variant": self.variant,
            "camera_height": float(self.camera_height),
            "shared_plane": bool(self.shared_plane),
            "n_particles": int(self.n_particles),
            "objects": [o.to_dict() for o in self.cars],
            **self.extras,
        }

    @staticmethod
    def from_particle(
        particles: SceneParticles, index: int, detections: Detections, *, variant: str
    ) -> "SceneEstimate":
        """The scene of particle ``index`` of ``particles``: one car per detection, with its
        box and score, its pose and size from the particle."""
        location, R = particles.poses()
        objects = [
            ObjectEstimate(
                detection_index=j,
                box2d=detections.boxes[j],
                score=float(detections.scores[j]),
                location=location[index, j],
                R=R[index, j],
                dims=particles.dims[index, j],
                cost=float(particles.object_cost[index, j]),
                pitch=float(particles.pitch[index, j]),
                roll=float(particles.roll[index, j]),
            )
            for j in range(particles.n_objects)
        ]
        return SceneEstimate(
            variant=variant,
            objects=objects,
            camera_height=particles.height,
            shared_plane=particles.shared_plane,
            n_particles=particles.n_particles,
        )


def fitted_detections(detections: Detections, estimate: SceneEstimate) -> Detections:
    """The pre-detections of the cars of ``estimate``, in detection order: those the fit's
    verification dropped (our own pre-detection's) are left out, as from the fit's output.

    Examples
    --------
    >>> import numpy as np
    >>> from wirescene.core.types import ObjectEstimate
    >>> dets = Detections([[0, 0, 10, 10], [20, 0, 30, 10], [40, 0, 50, 10]], 1.0, np.nan)
    >>> car = ObjectEstimate(detection_index=2, box2d=dets.boxes[2], score=1.0, location=np.array([0.0, 1.65, 9.0]),
    ...                      R=np.eye(3), dims=np.array([1.5, 1.6, 3.9]), cost=0.0)
    >>> fitted_detections(dets, SceneEstimate(variant="coarse", objects=[car])).boxes
    array([[40.,  0., 50., 10.]])
    """
    return detections.subset(car_fitted(detections, estimate))


def car_fitted(detections: Detections, estimate: SceneEstimate) -> np.ndarray:
    """Which of ``detections`` (those ``estimate`` was fitted to, in order) a car of
    ``estimate`` was fitted to; a car whose index lies past them (a scene put together by
    hand) is none of theirs.

    Examples
    --------
    >>> dets = Detections([[0, 0, 10, 10], [20, 0, 30, 10]], 1.0, np.nan)
    >>> cars = [ObjectEstimate(detection_index=i, box2d=dets.boxes[0], score=1.0, location=np.array([0.0, 1.65, 9.0]),
    ...                        R=np.eye(3), dims=np.array([1.5, 1.6, 3.9]), cost=0.0) for i in (1, 5)]
    >>> car_fitted(dets, SceneEstimate(variant="coarse", objects=cars)).tolist()
    [False, True]
    """
    fitted = np.zeros(len(detections), bool)
    fitted[[o.detection_index for o in estimate.objects if 0 <= o.detection_index < len(detections)]] = True
    return fitted


def dropped_detections(detections: Detections, estimate: SceneEstimate) -> Detections:
    """The pre-detections of ``detections`` that no car of ``estimate`` was fitted to: those
    the fit's verification dropped (our own pre-detection's), in detection order
    (:func:`car_fitted`).

    Examples
    --------
    >>> dets = Detections([[0, 0, 10, 10], [20, 0, 30, 10]], 1.0, np.nan)
    >>> dropped_detections(dets, SceneEstimate(variant="coarse", objects=[])).boxes.tolist()  # no car: both dropped
    [[0.0, 0.0, 10.0, 10.0], [20.0, 0.0, 30.0, 10.0]]
    """
    return detections.subset(~car_fitted(detections, estimate))
