"""2D pre-detections: from ground-truth labels (with controllable viewpoint noise) and
adapters for boxes of any external detector (JSON, CSV, KITTI label files with scores).

Every source yields a :class:`~wirescene.core.types.Detections` whose ``alpha`` is
the centre of the coarse viewpoint bin (8 bins, paper Sec. 3.4), or NaN when the source
has no viewpoint (no ``alpha`` given, or KITTI's ``-10``, "not estimated"); the lifting
stage then searches all azimuths.
"""

from __future__ import annotations

import csv
import json
from collections import Counter
from pathlib import Path

import numpy as np

from wirescene.core.errors import InputError
from wirescene.core.labels import angle_problem, is_type
from wirescene.core.types import Detections
from wirescene.core.validate import boxes_problem, normalised_boxes_problem, path_problem
from wirescene.core.viewpoints import bin_center, viewpoint_bin
from wirescene.io.kitti import ALPHA_NOT_ESTIMATED, CAR_TYPES, FrameLabels, read_labels


def _binned_viewpoint(alpha) -> np.ndarray:
    """Centre of the viewpoint bin of each observation angle ``alpha`` (radians, any
    range: angles wrap); NaN (unknown viewpoint) where ``alpha`` is KITTI's ``-10``."""
    alpha = np.asarray(alpha, dtype=float)
    known = alpha != ALPHA_NOT_ESTIMATED
    return np.where(known, bin_center(viewpoint_bin(np.where(known, alpha, 0.0))), np.nan)


#: The problem of a detection file without a car (a frame without cars to ``eval`` and ``fit``): the
#: start of the message, which names the classes of the file's other boxes where it has some.
NO_CARS = "no car detections in file"

#: COCO's category id of a car (``category_id`` in COCO result files).
COCO_CAR_ID = 3


#: The keys of an entry's class, in the order read: its name's, then COCO's number.
_CLASS_KEYS = ("category", "category_name", "label", "class", "type", "category_id")


def _class_of(entry: dict):
    """The class a JSON / CSV entry names under ``category``, ``category_name``, ``label``,
    ``class``, ``type`` or COCO's ``category_id`` (the first given), or None."""
    for key in _CLASS_KEYS:
        value = entry.get(key)
        if value not in (None, ""):
            return value
    return None


def is_car(entry: dict) -> bool:
    """Whether a JSON / CSV entry is a car: its class (:func:`_class_of`) ``car`` in any case,
    or the number 3 (COCO's id of a car); an entry naming no class is one.

    Examples
    --------
    >>> is_car({"label": "Car"}), is_car({"category_id": 3}), is_car({"category_id": 1}), is_car({})
    (True, True, False, True)
    """
    value = _class_of(entry)
    if value is None:
        return True
    try:
        return float(value) == COCO_CAR_ID
    except (TypeError, ValueError):
        return is_type(str(value).strip(), CAR_TYPES)


def _no_cars(others: Counter) -> str:
    """:data:`NO_CARS`, naming the classes of a file's ``others`` boxes (class to boxes) where it
    holds some (a detector whose cars are "vehicle" or "Automobile" would otherwise read as an
    empty street)."""
    if not others:
        return NO_CARS
    n = others.total()
    return f"{NO_CARS} (its {n} {'box is' if n == 1 else 'boxes are'} of other classes: {format_classes(others)})"


def format_classes(counts: Counter, *, shown: int = 3) -> str:
    """The ``shown`` most common classes of ``counts`` (class to boxes) with their counts, in one
    line of bounded length: each name cut at 20 characters, the others counted.

    Examples
    --------
    >>> format_classes(Counter({"truck": 1, "vehicle": 2}))
    "'vehicle' x2, 'truck' x1"
    >>> format_classes(Counter({"1": 3000, "2": 40, "4": 40, "8": 2, "a" * 30: 1}))  # ties by name
    "'1' x3,000, '2' x40, '4' x40 and 2 more classes"
    """
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    said = ", ".join(f"{name[:20] + ('...' if len(name) > 20 else '')!r} x{n:,}" for name, n in ranked[:shown])
    more = len(ranked) - shown
    return said + (f" and {more} more {'class' if more == 1 else 'classes'}" if more > 0 else "")


def detections_from_labels(
    labels: FrameLabels,
    *,
    types=CAR_TYPES,
    viewpoint_noise_deg: float = 0.0,
    rng: np.random.Generator | None = None,
    source: str = "gt",
) -> Detections:
    """Ground-truth boxes as pre-detections (the paper's oracle initialisation).

    The viewpoint is the bin of the true observation angle after adding zero-mean
    Gaussian noise of ``viewpoint_noise_deg`` (so bins can be wrong, as a detector's
    would), unknown (NaN) where the label's ``alpha`` is KITTI's ``-10``; the score is
    1, or the label's score if it has one. ``rng`` defaults to a generator seeded 0.

    Examples
    --------
    >>> from wirescene.core.resources import DATA_DIR
    >>> from wirescene.io.kitti import read_labels
    >>> labels = read_labels(DATA_DIR / "sample" / "kitti" / "training" / "label_2" / "000010.txt")
    >>> dets = detections_from_labels(labels)  # the 8 cars; the pedestrian and DontCare left out
    >>> dets.boxes.shape, dets.scores.tolist()[:3], dets.source
    ((8, 4), [1.0, 1.0, 1.0], 'gt')
    >>> labels.objects[1].alpha, float(np.rad2deg(dets.alpha[1]))  # 1.95 rad (112 deg): the 90 deg bin
    (1.95, 90.0)
    """
    objs = labels.of_type(*types)
    if not objs:
        return Detections.empty(source)
    alpha = np.array([o.alpha for o in objs])
    known = alpha != ALPHA_NOT_ESTIMATED
    if viewpoint_noise_deg > 0:
        rng = np.random.default_rng(0) if rng is None else rng
        alpha = np.where(known, alpha + np.deg2rad(viewpoint_noise_deg) * rng.standard_normal(len(alpha)), alpha)
    scores = np.array([1.0 if o.score is None else o.score for o in objs])
    return Detections(np.stack([o.box for o in objs]), scores, _binned_viewpoint(alpha), source)


def _viewpoint_of(entry: dict, path: Path, where: str) -> float:
    if entry.get("viewpoint_bin") not in (None, ""):
        value = entry["viewpoint_bin"]
        try:
            b = int(value)
            if isinstance(value, bool) or (isinstance(value, float) and b != value):  # int() drops a fraction
                raise ValueError
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{where}: viewpoint_bin must be an integer 0..7, got {str(value)[:20]!r}",
                             path=path) from None
        if not 0 <= b < 8:
            raise InputError(f"{where}: viewpoint_bin must be in 0..7, got {b}", path=path)
        return float(bin_center(b))
    if entry.get("alpha") not in (None, ""):
        try:
            alpha = float(entry["alpha"])
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{where}: alpha must be a number (radians)", path=path) from None
        if np.isnan(alpha):  # NaN: no viewpoint, as in Detections
            return float("nan")
        if not np.isfinite(alpha):
            raise InputError(f"{where}: alpha must be finite (radians), got {alpha}", path=path)
        problem = angle_problem("alpha", alpha)
        if problem:
            raise InputError(f"{where}: {problem}", path=path)
        return float(_binned_viewpoint(alpha))
    return float("nan")


def _box_of(entry: dict, path: Path, where: str) -> list[float]:
    if "box" in entry:
        box = entry["box"]
    elif "bbox" in entry:  # COCO: x, y, width, height
        b = entry["bbox"]
        try:
            if not isinstance(b, (list, tuple)) or len(b) != 4 or any(isinstance(v, (str, bool)) for v in b):
                raise TypeError
            x, y, w, h = (float(v) for v in b)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{where}: bbox must be four numbers [x, y, width, height]", path=path) from None
        box = [x, y, x + w, y + h]
    else:
        box = [entry.get(k) for k in ("x1", "y1", "x2", "y2")]
    try:
        if not isinstance(box, (list, tuple)) or any(isinstance(v, bool) for v in box):
            raise TypeError
        box = [float(v) for v in box]
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{where}: box must be four numbers x1 y1 x2 y2", path=path) from None
    if len(box) != 4 or not np.all(np.isfinite(box)):
        raise InputError(f"{where}: box must be four finite numbers x1 y1 x2 y2", path=path)
    if box[2] <= box[0] or box[3] <= box[1]:
        raise InputError(f"{where}: box has x2 <= x1 or y2 <= y1", path=path)
    return box


def _id_key(value) -> str | None:
    """The key of a COCO id (an image's ``id`` and an entry's ``image_id``, matched by it; a class
    number, counted by it): its text, a whole float's that of its integer (``10.0`` as ``10``: JSON
    writers that write every number as a float); None for a float that is no whole number.

    Examples
    --------
    >>> _id_key(10), _id_key(10.0), _id_key("000010"), _id_key(10.5)
    ('10', '10', '000010', None)
    """
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() else None
    return str(value)


def _one_image(entries: list, path: Path) -> None:
    """Refuse ``entries`` naming more than one ``image_id`` (a COCO result file holds every image's
    boxes): the boxes of other images would be fitted to this one's."""
    first = None
    for i, entry in enumerate(entries):
        image = entry.get("image_id") if isinstance(entry, dict) else None
        if image in (None, ""):
            continue
        if first is None:
            first = (i, image)
        elif (_id_key(image) or str(image)) != (_id_key(first[1]) or str(first[1])):
            raise InputError(f"detection {i} is of image_id {str(image)[:20]}, detection {first[0]} of "
                             f"{str(first[1])[:20]}: a detections file holds one image's boxes (split a COCO result "
                             "file by image_id: wirescene split-coco)", path=path)


def _car_of(entry, path: Path, where: str) -> tuple[list[float], float, float] | None:
    """The box, score and viewpoint (:func:`_viewpoint_of`) of a JSON / CSV entry, or None where
    it is of another class than a car; an :class:`InputError` naming ``where`` if malformed."""
    if not isinstance(entry, dict):
        raise InputError(f"{where}: expected an object with a box", path=path)
    if not is_car(entry):
        return None
    box = _box_of(entry, path, where)
    try:
        score = entry.get("score", 1.0)
        if isinstance(score, bool):  # float(True) is 1.0: a flag, not a score
            raise TypeError
        score = 1.0 if score in (None, "") else float(score)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{where}: score must be a number", path=path) from None
    if not np.isfinite(score):
        raise InputError(f"{where}: score must be finite, got {score}", path=path)
    return box, score, _viewpoint_of(entry, path, where)


def _from_entries(entries: list, path: Path) -> Detections:
    _one_image(entries, path)
    cars = [car for i, entry in enumerate(entries) if (car := _car_of(entry, path, f"detection {i}")) is not None]
    boxes, scores, alpha = ([c[k] for c in cars] for k in range(3))
    return Detections(np.array(boxes).reshape(-1, 4), np.array(scores), np.array(alpha), str(path))


def _read_json(path: Path):
    """The JSON document of the file ``path``; an :class:`InputError` naming it where it is none."""
    try:
        return json.loads(path.read_text(encoding="utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid JSON ({exc.__class__.__name__}: {exc})".splitlines()[0], path=path) from None
    except RecursionError:
        raise InputError("not a detections file (JSON nested too deeply)", path=path) from None
    except ValueError as exc:  # e.g. an integer of thousands of digits
        raise InputError(f"not a usable JSON file ({' '.join(str(exc).split())[:80]})", path=path) from None


def _parsed(path: Path, image_size: tuple[int, int] | None) -> tuple[Detections, list]:
    """The car boxes of the detection file ``path`` (every one, whatever its score) and the class of
    each of its other boxes; an :class:`InputError` where it is missing or malformed."""
    problem = path_problem(path, "detections")
    if problem:
        raise InputError(problem, path=path)
    suffix = path.suffix.lower()
    if suffix == ".txt":
        labels = read_labels(path, image_size=image_size)  # an angle in degrees refused there, naming its line
        dets = detections_from_labels(labels, source=str(path))
        cars = {id(o) for o in labels.of_type(*CAR_TYPES)}
        others = [o.type for o in labels.objects if id(o) not in cars]
    elif suffix == ".json":
        data = _read_json(path)
        entries = data.get("detections") if isinstance(data, dict) else data
        if not isinstance(entries, list):
            raise InputError("expected a list of detections or {'detections': [...]}", path=path)
        dets = _from_entries(entries, path)
        others = [_class_of(e) for e in entries if isinstance(e, dict) and not is_car(e)]
    elif suffix == ".csv":
        try:
            # utf-8-sig: spreadsheets write a byte-order mark before the header.
            with path.open(newline="", encoding="utf-8-sig") as fh:
                reader = csv.DictReader(fh)
                rows = list(reader)
                fieldnames = reader.fieldnames  # read here: an empty file's are looked for in the closed file later
        except (csv.Error, UnicodeDecodeError, OSError) as exc:
            raise InputError(f"not a readable CSV file ({exc})", path=path) from None
        # the header itself, rows or not: a file without one takes its first box for it (and reads no box)
        if fieldnames is not None and not {"x1", "y1", "x2", "y2"} <= set(fieldnames):
            header = ",".join(fieldnames)
            raise InputError(f"CSV header must name x1,y1,x2,y2 (optional score, viewpoint_bin, alpha), got "
                             f"{header if len(header) <= 40 else header[:37] + '...'!r}", path=path)
        twice = sorted({name for name in fieldnames or () if name and fieldnames.count(name) > 1})
        if twice:  # a row keeps a name's last column: another column's numbers (an unnamed one is never read)
            raise InputError(f"CSV header names the column {twice[0]!r} twice", path=path)
        dets = _from_entries(rows, path)
        others = [_class_of(e) for e in rows if not is_car(e)]
    else:
        raise InputError(f"unknown detections format {suffix!r} (use .json, .csv or a KITTI .txt)", path=path)
    return dets, others


def read_boxes_and_classes(path: str | Path, *,
                           image_size: tuple[int, int] | None = None) -> tuple[Detections, Counter]:
    """Every car box of the detection file ``path``, whatever its score, and how many boxes of
    each other class it holds (those :func:`read_detections` skips): one read for a run that keeps
    a file's boxes and says what its files hold where none holds a car (:func:`format_classes`).

    Raises
    ------
    InputError
        A missing or malformed file, or boxes outside ``image_size``, as :func:`read_detections`
        refuses them; a file without a car is no error here.

    Examples
    --------
    >>> import json, tempfile
    >>> entries = [{"bbox": [10, 10, 40, 80], "category_id": 1}, {"bbox": [600, 170, 80, 60], "category_id": 1},
    ...            {"bbox": [700, 170, 80, 60], "category_id": 2}]
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "000010.json").write_text(json.dumps(entries))
    ...     dets, classes = read_boxes_and_classes(Path(d) / "000010.json")
    >>> len(dets), classes
    (0, Counter({'1': 2, '2': 1}))
    >>> entries[1]["category_id"] = 1.0  # the same class, written as a float
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "000010.json").write_text(json.dumps(entries))
    ...     read_boxes_and_classes(Path(d) / "000010.json")[1]
    Counter({'1': 2, '2': 1})
    """
    path = Path(path)
    dets, others = _parsed(path, image_size)
    # every box, before the floor: a file of another image is one
    problem = boxes_problem(dets.boxes, image_size) or normalised_boxes_problem(dets.boxes)
    if problem:
        raise InputError(problem, path=path)
    # a class numbered 1 and 1.0 (writers that write every number as a float) is one class
    return dets, Counter(_id_key(c) or str(c) for c in others)


def read_detections(path: str | Path, *, min_score: float | None = None,
                    image_size: tuple[int, int] | None = None) -> Detections:
    """Read 2D car detections of one image.

    Formats, by extension:

    * ``.json``: a list of objects, or ``{"detections": [...]}``; each object has
      ``box`` ``[x1, y1, x2, y2]`` (or COCO ``bbox`` ``[x, y, w, h]``, or keys
      ``x1 y1 x2 y2``), optional ``score``, optional ``viewpoint_bin`` (0..7) or
      ``alpha`` (radians) and an optional class: ``category``, ``category_name``,
      ``label``, ``class``, ``type`` or COCO's ``category_id``, ``car`` in any case or the
      number 3 (COCO's id of a car; a detector numbering its classes otherwise must name
      them); entries of another class are skipped. Entries naming an ``image_id`` (COCO)
      must all name the same one (``10`` and ``10.0`` are one): a COCO result file of several
      images is refused.
    * ``.csv``: a header with ``x1,y1,x2,y2`` and optional ``score``, ``viewpoint_bin``,
      ``alpha``, ``image_id`` and class columns as in JSON (a file without the header is refused;
      an empty one holds no box).
    * ``.txt``: a KITTI label file (15 or 16 columns); Car rows (``car`` in any case, as
      KITTI's devkit reads them) are used, with their ``alpha`` binned and their score (16th
      column) if present.

    An ``alpha`` of ``-10`` (KITTI's "not estimated", as 2D-only detectors write) is an
    unknown viewpoint in every format, and so is NaN in JSON and CSV and ``null`` in JSON (as
    strict JSON writes NaN); any other beyond one turn (2 pi) is refused as an angle in degrees.

    A box given without a score (JSON, CSV, a KITTI file of 15 columns) scores 1. Only the
    boxes scoring ``min_score`` (None: no floor) or more are kept (a file left without one is an
    :class:`InputError` of :data:`NO_CARS`). With ``image_size`` (width, height), every box,
    kept or not, must overlap the image (:func:`wirescene.core.validate.boxes_problem`).

    Raises
    ------
    InputError
        Missing or malformed file, a file without any detection, boxes of several images, an
        ``alpha`` beyond one turn, boxes all under a pixel (normalised coordinates) or (with
        ``image_size``) a box outside the image.

    Examples
    --------
    >>> import json, tempfile
    >>> entries = [{"box": [300, 180, 520, 300], "score": 0.9, "alpha": 1.9},
    ...            {"bbox": [600, 170, 80, 60], "score": 0.4, "category_id": 3},  # COCO: x, y, w, h; a car
    ...            {"box": [10, 10, 50, 90], "score": 0.8, "label": "person"}]  # not a car: skipped
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "000010.json").write_text(json.dumps(entries))
    ...     dets = read_detections(Path(d) / "000010.json", image_size=(1242, 375))
    ...     confident = read_detections(Path(d) / "000010.json", min_score=0.5)
    >>> dets.boxes
    array([[300., 180., 520., 300.],
           [600., 170., 680., 230.]])
    >>> dets.scores.tolist(), np.rad2deg(dets.alpha).tolist()  # alpha binned; none given: NaN
    ([0.9, 0.4], [90.0, nan])
    >>> len(confident)
    1
    """
    path = Path(path)
    dets, others = read_boxes_and_classes(path, image_size=image_size)
    if len(dets) == 0:
        raise InputError(_no_cars(others), path=path)
    dets = dets if min_score is None else dets.subset(dets.scores >= min_score)
    if len(dets) == 0:
        raise InputError(NO_CARS, path=path)
    return dets


def split_coco_results(results: str | Path, images: str | Path) -> dict[str, list]:
    """Each image's detections of a COCO result file of a whole data set (mmdetection's or
    detectron2's ``bbox`` results: one list of entries, each naming its ``image_id``), for
    one detection file a frame that :func:`read_detections` reads.

    ``images`` is the COCO annotation file the detector ran on: its ``images`` name each
    ``id``'s ``file_name``, whose stem is the frame id (``training/image_2/000010.png``:
    ``000010``); an entry's ``image_id`` matches the image of its ``id``, a whole float (``10.0``,
    as some JSON writers write every number) that of its integer. Where ``images`` names its
    ``categories``, an entry of a ``category_id`` alone gets its name as ``category`` (a detector
    trained on KITTI numbers its cars 1, not COCO's 3: its ``Car`` is then read as a car, and its
    ``Cyclist`` 3 not). Every entry is checked as
    :func:`read_detections` checks a file's, naming its place in ``results``; entries of another
    class than a car are kept (the reader skips them).

    Returns
    -------
    dict
        Frame id to its entries, in their order in ``results``, for every image of ``images``
        (an image without an entry: ``[]``, a frame without cars), in the order of ``images``.

    Raises
    ------
    InputError
        Either file missing or malformed, annotations without images, an entry without an
        ``image_id`` or of one that ``images`` lacks, an ``id`` or ``image_id`` that is a float
        but no whole number, two images of one ``id`` or one frame id (naming both file names),
        a malformed entry, or boxes all under a pixel (normalised coordinates).

    Examples
    --------
    >>> import json, tempfile
    >>> ann = {"images": [{"id": 7, "file_name": "training/image_2/000010.png"}, {"id": 8, "file_name": "000011.png"}]}
    >>> res = [{"image_id": 7, "category_id": 3, "bbox": [300, 180, 220, 120], "score": 0.9},
    ...        {"image_id": 7, "category_id": 1, "bbox": [10, 10, 40, 80], "score": 0.8}]
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "ann.json").write_text(json.dumps(ann))
    ...     _ = (Path(d) / "res.json").write_text(json.dumps(res))
    ...     by_frame = split_coco_results(Path(d) / "res.json", Path(d) / "ann.json")
    >>> {frame: len(entries) for frame, entries in by_frame.items()}
    {'000010': 2, '000011': 0}
    >>> ann["categories"] = [{"id": 1, "name": "Car"}, {"id": 3, "name": "Cyclist"}]  # a detector trained on KITTI
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "ann.json").write_text(json.dumps(ann))
    ...     _ = (Path(d) / "res.json").write_text(json.dumps(res))
    ...     by_frame = split_coco_results(Path(d) / "res.json", Path(d) / "ann.json")
    >>> [(e["category_id"], e["category"]) for e in by_frame["000010"]]  # its car is 1, its 3 a cyclist
    [(3, 'Cyclist'), (1, 'Car')]
    """
    results, images = Path(results), Path(images)
    for path, what in ((results, "COCO results"), (images, "COCO annotations")):
        problem = path_problem(path, what)
        if problem:
            raise InputError(problem, path=path)
    document = _read_json(images)
    listed = document.get("images") if isinstance(document, dict) else None
    if not isinstance(listed, list):
        raise InputError("expected COCO annotations: {'images': [{'id': ..., 'file_name': ...}, ...]}", path=images)
    if not listed:  # no frame to write: an empty --out and a run of nothing
        raise InputError("no images: the COCO annotations list none", path=images)
    frame_of, seen = {}, {}
    for i, image in enumerate(listed):
        if not isinstance(image, dict) or image.get("id") in (None, "") or not isinstance(image.get("file_name"), str):
            raise InputError(f"image {i}: expected an object with an id and a file_name", path=images)
        key, name = _id_key(image["id"]), image["file_name"]
        frame = Path(name.replace("\\", "/")).stem
        if key is None:
            raise InputError(f"image {i}: its id {image['id']!r} is no whole number", path=images)
        if not frame:
            raise InputError(f"image {i}: its file_name {name[:60]!r} names no frame", path=images)
        if key in frame_of:
            raise InputError(f"image {i}: the id {key[:20]} of an image before it", path=images)
        if frame in seen:  # image_2/000010.png and image_3/000010.png: one FRAME.json for two images
            j, other = seen[frame]
            raise InputError(f"image {i} ({name[:60]!r}) and image {j} ({other[:60]!r}) are both frame "
                             f"{frame[:40]}: one FRAME.json holds one image's boxes (list one camera's images)",
                             path=images)
        frame_of[key], seen[frame] = frame, (i, name)
    names = _category_names(document.get("categories"), images)
    entries = _read_json(results)
    entries = entries.get("detections") if isinstance(entries, dict) else entries
    if not isinstance(entries, list):
        raise InputError("expected a COCO result file: a list of detections, each with an image_id", path=results)
    by_frame = {frame: [] for frame in frame_of.values()}
    boxes = []
    for i, entry in enumerate(entries):
        name = names.get(str(entry.get("category_id"))) if isinstance(entry, dict) else None
        if name is not None and all(entry.get(key) in (None, "") for key in _CLASS_KEYS[:-1]):  # a number alone
            entry = {**entry, "category": name}  # read by its name: the annotations' numbers are not COCO's
        car = _car_of(entry, results, f"detection {i}")
        image = entry.get("image_id")
        if image in (None, ""):
            raise InputError(f"detection {i}: no image_id", path=results)
        key = _id_key(image)
        if key is None:
            raise InputError(f"detection {i}: its image_id {image!r} is no whole number (an image's id)", path=results)
        if key not in frame_of:
            raise InputError(f"detection {i}: image_id {str(image)[:20]} is not an image of {images}", path=results)
        by_frame[frame_of[key]].append(entry)
        if car is not None:
            boxes.append(car[0])
    problem = normalised_boxes_problem(boxes)
    if problem:
        raise InputError(problem, path=results)
    return by_frame


def _category_names(categories, path: Path) -> dict[str, str]:
    """``{str(id): name}`` of a COCO annotation file's ``categories`` (None: it has none, ``{}``);
    an :class:`InputError` naming ``path`` where they are malformed."""
    if categories is None:
        return {}
    if not isinstance(categories, list):
        raise InputError("categories: expected a list of {'id': ..., 'name': ...}", path=path)
    names = {}
    for i, category in enumerate(categories):
        if (not isinstance(category, dict) or category.get("id") in (None, "")
                or not isinstance(category.get("name"), str) or not category["name"].strip()):
            raise InputError(f"category {i}: expected an object with an id and a name", path=path)
        key = str(category["id"])
        if key in names:
            raise InputError(f"category {i}: the id {key[:20]} of a category before it", path=path)
        names[key] = category["name"]
    return names
