"""KITTI object labels as data: one :class:`Label` per object, the label-line text
format and the evaluation-car filters. File reading and writing live in
:mod:`wirescene.io.kitti`; this module has no I/O, so that the scene estimate can
turn itself into label lines.

A KITTI label line has 15 columns (ground truth) or 16 (detections, with a score)::

    type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from wirescene.core.boxes import box_centers
from wirescene.core.groundplane import rotation_y as _rotation_y_matrix

#: The label types that are cars, matched in any case (:func:`is_type`), as every car pick reads them.
CAR_TYPES = ("Car",)
DONTCARE = "DontCare"
#: KITTI's ``alpha`` of a row whose viewpoint is not estimated (DontCare, 2D-only detectors).
ALPHA_NOT_ESTIMATED = -10.0
# Largest |alpha| a detection may carry: one turn. A detector's angles lie in [-pi, pi] (KITTI's range; wrapped
# values are taken), so anything beyond is an angle in degrees.
MAX_ALPHA = 2 * np.pi

COLUMNS = (
    "type", "truncated", "occluded", "alpha", "x1", "y1", "x2", "y2",
    "h", "w", "l", "x", "y", "z", "rotation_y", "score",
)


@dataclass
class Label:
    """One object of a KITTI label file.

    Attributes
    ----------
    type : str
        Object class (``Car``, ``Van``, ``Pedestrian``, ``DontCare``, ...).
    truncated : float
        Fraction of the object outside the image, 0..1 (-1 for DontCare).
    occluded : int
        0 fully visible, 1 partly occluded, 2 largely occluded, 3 unknown (-1 DontCare).
    alpha : float
        Observation angle in radians, ``[-pi, pi]``.
    box : (4,) array
        2D box ``x1 y1 x2 y2`` in pixels.
    dims : (3,) array
        3D size ``h w l`` in metres.
    location : (3,) array
        Bottom centre of the 3D box in the camera frame, metres.
    rotation_y : float
        Azimuth about the camera y axis, radians.
    score : float or None
        Detection confidence (16th column); ``None`` for ground truth.

    Examples
    --------
    >>> car = Label("Car", truncated=0.0, occluded=0, alpha=1.95, box=[354.43, 185.52, 549.52, 294.49],
    ...             dims=[1.43, 1.70, 3.95], location=[-2.39, 1.66, 11.80], rotation_y=1.76)
    >>> car.box.shape, car.dims.tolist(), car.score is None  # arrays of floats; ground truth has no score
    ((4,), [1.43, 1.7, 3.95], True)
    >>> round(car.height_px, 2), np.round(car.centroid, 3).tolist()  # centroid: h / 2 above the bottom (y down)
    (108.97, [-2.39, 0.945, 11.8])
    """

    type: str
    truncated: float
    occluded: int
    alpha: float
    box: np.ndarray
    dims: np.ndarray
    location: np.ndarray
    rotation_y: float
    score: float | None = None

    def __post_init__(self):
        self.box = np.asarray(self.box, dtype=float).reshape(4)
        self.dims = np.asarray(self.dims, dtype=float).reshape(3)
        self.location = np.asarray(self.location, dtype=float).reshape(3)
        self.truncated = float(self.truncated)
        self.occluded = int(self.occluded)
        self.alpha = float(self.alpha)
        self.rotation_y = float(self.rotation_y)
        self.score = None if self.score is None else float(self.score)

    @property
    def centroid(self) -> np.ndarray:
        """(3,) centre of the 3D box: the bottom centre raised by ``h / 2`` (level box)."""
        return box_centers(self.dims, self.location, _rotation_y_matrix(self.rotation_y))

    @property
    def height_px(self) -> float:
        """Height of the 2D box in pixels."""
        return float(self.box[3] - self.box[1])

    @property
    def is_dontcare(self) -> bool:
        """Whether the row is a ``DontCare`` region (kept apart in :class:`FrameLabels`), in any case
        (:func:`is_type`)."""
        return is_type(self.type, DONTCARE)


@dataclass
class FrameLabels:
    """The labels of one frame: real objects, and DontCare regions kept apart.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> from wirescene.io.kitti import read_labels
    >>> labels = read_labels(DATA_DIR / "sample" / "kitti" / "training" / "label_2" / "000010.txt")
    >>> len(labels), len(labels.dontcare)  # len counts the objects only
    (9, 4)
    >>> [o.type for o in labels.of_type("Pedestrian", "Cyclist")]
    ['Pedestrian']
    >>> len(labels.of_type(*CAR_TYPES)), len(labels.of_type("car"))  # any case, as KITTI's devkit reads types
    (8, 8)
    """

    objects: list[Label] = field(default_factory=list)
    dontcare: list[Label] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.objects)

    def of_type(self, *types: str) -> list[Label]:
        """Objects whose type is one of ``types``, whatever its case (:func:`is_type`)."""
        return [o for o in self.objects if is_type(o.type, types)]


def format_label(label: Label, *, with_score: bool = True) -> str:
    """One KITTI label line (no newline).

    Precision: ``truncated`` and the 2D box use 2 decimals as the KITTI devkit does;
    dimensions, location and both angles use 6 decimals (the devkit's 2 decimals would
    lose up to 0.3 deg of azimuth and 5 mm of position, which matters for the 5 deg /
    1 m metrics of the paper); the score is written with 6 significant digits. KITTI's
    own readers parse any of these with ``%f``. ``with_score`` writes the 16th column
    (a label without a score gets 0).

    Raises
    ------
    ValueError
        If a number is not finite or the type is not one word.

    Examples
    --------
    >>> car = Label("Car", 0.0, 0, 1.95, [354.43, 185.52, 549.52, 294.49], [1.43, 1.70, 3.95],
    ...             [-2.39, 1.66, 11.80], 1.76)
    >>> format_label(car, with_score=False)  # ground truth: 15 columns
    'Car 0.00 0 1.950000 354.43 185.52 549.52 294.49 1.430000 1.700000 3.950000 -2.390000 1.660000 11.800000 1.760000'
    >>> car.score = 0.87654321
    >>> format_label(car).split()[-1]  # a detection: the score, 6 significant digits
    '0.876543'
    """
    numbers = [label.alpha, *label.box, *label.dims, *label.location, label.rotation_y]
    if not np.all(np.isfinite([label.truncated, *numbers])):
        raise ValueError(f"label of type {label.type!r} has non-finite values; KITTI files cannot hold them")
    if not label.type or any(c.isspace() for c in label.type):
        raise ValueError(f"object type {label.type!r} must be one word")
    parts = [
        label.type,
        f"{label.truncated:.2f}",
        f"{int(label.occluded):d}",
        f"{label.alpha:.6f}",
        *(f"{v:.2f}" for v in label.box),
        *(f"{v:.6f}" for v in label.dims),
        *(f"{v:.6f}" for v in label.location),
        f"{label.rotation_y:.6f}",
    ]
    if with_score:
        parts.append(f"{0.0 if label.score is None else label.score:.6g}")
    return " ".join(parts)


def format_labels(labels: FrameLabels | Iterable[Label], *, with_score: bool = True) -> str:
    """The text of a KITTI label file (see :func:`wirescene.io.kitti.write_labels`): one line
    a label (:func:`format_label`), each ended by a newline; a :class:`FrameLabels` gives
    its objects, then its DontCare regions.

    Examples
    --------
    >>> car = Label("Car", 0.0, 0, 1.95, [354.43, 185.52, 549.52, 294.49], [1.43, 1.70, 3.95],
    ...             [-2.39, 1.66, 11.80], 1.76, score=0.9)
    >>> text = format_labels([car, car])
    >>> text.endswith("0.9\\n"), [len(line.split()) for line in text.splitlines()]  # two lines of 16 columns
    (True, [16, 16])
    >>> format_labels([])  # a frame without objects: an empty file
    ''
    """
    items = list(labels.objects) + list(labels.dontcare) if isinstance(labels, FrameLabels) else list(labels)
    return "".join(format_label(lab, with_score=with_score) + "\n" for lab in items)


def car_indices(
    labels: FrameLabels | Sequence[Label],
    *,
    types: Sequence[str] = CAR_TYPES,
    min_height: float = 0.0,
    max_truncated: float = 1.0,
    max_occluded: int = 3,
) -> list[int]:
    """Indices (into ``labels.objects`` or the list) of the evaluation cars.

    Defaults select every ``Car``, in any case (:func:`is_type`; the paper annotates all
    cars of its test frames); ``min_height`` (pixels), ``max_truncated`` and ``max_occluded``
    (KITTI flag) give KITTI-style difficulty filters, e.g. the paper's pre-detection protocol
    uses cars taller than 50 px.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> from wirescene.io.kitti import read_labels
    >>> labels = read_labels(DATA_DIR / "sample" / "kitti" / "training" / "label_2" / "000010.txt")
    >>> [o.type for o in labels.objects].index("Pedestrian")
    2
    >>> car_indices(labels)  # every Car, the pedestrian left out
    [0, 1, 3, 4, 5, 6, 7, 8]
    >>> car_indices(labels, min_height=50)  # cars at least 50 px tall
    [0, 1, 3, 4, 5]
    >>> car_indices(labels, min_height=50, max_truncated=0.15, max_occluded=0)  # and fully visible, not cut
    [1, 3, 5]
    """
    objects = labels.objects if isinstance(labels, FrameLabels) else list(labels)
    return [
        i
        for i, o in enumerate(objects)
        if is_type(o.type, types)
        and o.height_px >= min_height and o.truncated <= max_truncated and o.occluded <= max_occluded
    ]


def angle_problem(name: str, angle: float) -> str | None:
    """Why ``angle`` (``alpha`` or ``rotation_y`` of a label row or a detection, radians) is no
    angle in radians, as a phrase, or None: beyond one turn (:data:`MAX_ALPHA`), unless KITTI's
    :data:`ALPHA_NOT_ESTIMATED`.

    Examples
    --------
    >>> angle_problem("alpha", -1.58) is None, angle_problem("alpha", ALPHA_NOT_ESTIMATED) is None
    (True, True)
    >>> angle_problem("rotation_y", 90.0)
    'rotation_y must be radians within one turn, got 90 (degrees?)'
    """
    if angle != ALPHA_NOT_ESTIMATED and abs(angle) > MAX_ALPHA:
        return f"{name} must be radians within one turn, got {angle:g} (degrees?)"
    return None


def no_3d_box(dims) -> bool:
    """Whether a label row's dimensions ``h w l`` are a 2D detector's ``-1 -1 -1`` (KITTI's "not
    estimated"): the row has no 3D box.

    Examples
    --------
    >>> no_3d_box([-1, -1, -1]), no_3d_box([1.5, 1.6, 3.9])
    (True, False)
    """
    return bool(np.all(np.asarray(dims, dtype=float) == -1.0))


def is_type(label_type: str, types: str | Iterable[str]) -> bool:
    """Whether a label row's type is one of ``types``, whatever its case: the one rule by which
    cars (:data:`CAR_TYPES`), DontCare regions and other classes are picked, as KITTI's devkit
    compares types (``strcasecmp``), so that a label folder another tool wrote with ``car`` rows
    reads the same everywhere.

    Examples
    --------
    >>> is_type("car", CAR_TYPES), is_type("CAR", "Car"), is_type("Van", CAR_TYPES), is_type("dontcare", DONTCARE)
    (True, True, False, True)
    """
    wanted = (types,) if isinstance(types, str) else types
    return label_type.lower() in {t.lower() for t in wanted}


def select_cars(labels: FrameLabels | Sequence[Label], **filters) -> list[Label]:
    """The evaluation cars themselves; see :func:`car_indices` for the filters.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> from wirescene.io.kitti import read_labels
    >>> labels = read_labels(DATA_DIR / "sample" / "kitti" / "training" / "label_2" / "000010.txt")
    >>> [round(o.height_px, 1) for o in select_cars(labels, min_height=50, max_occluded=0)]
    [191.5, 109.0, 73.4, 51.6]
    """
    objects = labels.objects if isinstance(labels, FrameLabels) else list(labels)
    return [objects[i] for i in car_indices(objects, **filters)]
