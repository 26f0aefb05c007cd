"""Sampling a synthetic street: ground plane, road layout, car placements and occluders.

Pure geometry (numpy only, no rendering). Coordinates:

* The *street frame* is the camera frame rotated by the ground plane, ``X_street =
  R_gp.T @ X_cam`` with ``R_gp = plane_rotation(pitch, roll)``; in it the ground is the
  level plane ``y = height`` (y down), x is to the right and z forward along the road.
  Lanes, kerbs, footprints and occluders are laid out in its ``(x, z)``.
* A car at street position ``(x, z)`` with azimuth ``a`` stands on the plane at the
  camera-frame bottom centre ``location = R_gp @ (x, height, z)`` with rotation ``R =
  R_gp @ R_y(a)`` (:func:`place`), i.e. :func:`wirescene.core.groundplane.object_pose`
  with the plane-aligned ``(x, z)`` instead of the camera's. On a level plane the two
  coincide and ``a`` is KITTI's ``rotation_y``.

The street: the camera drives in the ego lane (lane width 3.5 m); 1-2 lanes in its
direction, 0-2 oncoming lanes to the left; optional parking at each kerb, parallel
(a 2.2 m parking lane inside the road) or perpendicular (bays beyond the kerb);
then a sidewalk and building facades. Cars are parked in rows (bumper gaps 0.5-2.5 m,
azimuth jitter a few degrees) or drive in lanes (gaps 5-25 m, jitter 2 deg); a car is a
candidate if its bottom centre is 5-50 m ahead and at least 30% of its projected 3D box
lies inside the image; candidates crossing the image border are preferred (weight 6) so
that most scenes have a truncated car. Footprints (oriented
rectangles grown by a margin) never overlap. Occluders (poles, boxes, bushes) are put
on the line of sight to a random car, outside the ego lane and off every footprint.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wirescene.core.camera import NEAR_PLANE, Camera
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, GroundPlane, plane_rotation, rotation_y

LANE_WIDTH = 3.5
PARKING_LANE_WIDTH = 2.2
SIDEWALK_WIDTH = (2.0, 4.0)
MIN_DEPTH, MAX_DEPTH = 5.0, 50.0
MIN_INSIDE_FRACTION = 0.3
TRUNCATED_WEIGHT = 6.0  # preference for candidates crossing the image border
FOOTPRINT_MARGIN = 0.25  # metres added to every side of a car footprint for the overlap test
OCCLUDER_KINDS = ("pole", "box", "bush")


@dataclass(frozen=True)
class Street:
    """Road geometry in the street frame (metres)."""

    lane_centers: tuple  # x of each driving lane centre
    lane_directions: tuple  # +1 same direction as the camera, -1 oncoming
    ego_lane: int
    road_left: float  # x of the left kerb (road edge)
    road_right: float  # x of the right kerb
    parking_left: str  # "none" | "parallel" | "perpendicular"
    parking_right: str
    sidewalk_left: float  # width
    sidewalk_right: float
    facade_left: float  # x of the building facade
    facade_right: float
    markings: tuple = ()  # (x, kind) lane lines, kind "dashed" | "solid"

    def to_dict(self) -> dict:
        return {
            "lane_centers": [float(v) for v in self.lane_centers],
            "lane_directions": [int(v) for v in self.lane_directions],
            "ego_lane": int(self.ego_lane),
            "road_left": float(self.road_left),
            "road_right": float(self.road_right),
            "parking_left": self.parking_left,
            "parking_right": self.parking_right,
            "facade_left": float(self.facade_left),
            "facade_right": float(self.facade_right),
        }


@dataclass(frozen=True)
class CarPlacement:
    model: str
    x: float
    z: float
    azimuth: float
    dims: tuple  # (h, w, l)
    role: str  # "parked-left" | "parked-right" | "lane-<k>"

    def footprint(self, margin: float = 0.0) -> np.ndarray:
        h, w, l = self.dims
        return footprint(self.x, self.z, self.azimuth, l + 2 * margin, w + 2 * margin)


@dataclass(frozen=True)
class Occluder:
    kind: str  # "pole" | "box" | "bush"
    x: float
    z: float
    size: tuple  # pole (radius, height); box (length, width, height); bush (radius, height)
    yaw: float = 0.0

    def footprint(self, margin: float = 0.0) -> np.ndarray:
        if self.kind == "box":
            return footprint(self.x, self.z, self.yaw, self.size[0] + 2 * margin, self.size[1] + 2 * margin)
        r = self.size[0] + margin
        a = np.arange(8) * np.pi / 4
        return np.stack([self.x + r * np.cos(a), self.z + r * np.sin(a)], axis=-1)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "x": float(self.x), "z": float(self.z),
                "size": [float(s) for s in self.size], "yaw": float(self.yaw)}


@dataclass(frozen=True)
class SceneLayout:
    plane: GroundPlane
    street: Street
    cars: list = field(default_factory=list)
    occluders: list = field(default_factory=list)

    @property
    def R_gp(self) -> np.ndarray:
        return plane_rotation(self.plane.pitch, self.plane.roll)


# --------------------------------------------------------------------------- geometry


def place(x, z, azimuth, plane: GroundPlane):
    """Camera-frame ``(location (3,), R (3, 3))`` of an object at street ``(x, z)``."""
    R_gp = plane_rotation(plane.pitch, plane.roll)
    location = R_gp @ np.array([float(x), float(plane.height), float(z)])
    return location, R_gp @ rotation_y(float(azimuth))


def footprint(x, z, azimuth, length, width) -> np.ndarray:
    """Corners ``(4, 2)`` (street x, z) of an oriented rectangle: object-frame
    ``x in +-length/2`` (forward), ``z in +-width/2``, rotated by ``R_y(azimuth)``."""
    c, s = np.cos(azimuth), np.sin(azimuth)
    local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], dtype=float) * [length / 2, width / 2]
    # R_y maps object (x, z) to (c x + s z, -s x + c z)
    return np.stack([x + c * local[:, 0] + s * local[:, 1], z - s * local[:, 0] + c * local[:, 1]], axis=-1)


def polygons_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test of two convex polygons ``(N, 2)`` (touching counts as overlap)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        axes = np.stack([-edges[:, 1], edges[:, 0]], axis=-1)
        pa, pb = a @ axes.T, b @ axes.T
        if np.any((pa.max(0) < pb.min(0)) | (pb.max(0) < pa.min(0))):
            return False
    return True


def inside_fraction(camera: Camera, dims, location, R) -> float:
    """Fraction of the (unclipped) projected 3D box's area inside the image (0 if any
    corner is behind the camera)."""
    from wirescene.core.boxes import box_corners

    uv, depth = camera.project_with_depth(box_corners(dims, location, R))
    if np.any(depth <= NEAR_PLANE):
        return 0.0
    x1, y1 = uv.min(0)
    x2, y2 = uv.max(0)
    w, h = camera.image_size
    iw = max(0.0, min(x2, w) - max(x1, 0.0))
    ih = max(0.0, min(y2, h) - max(y1, 0.0))
    area = (x2 - x1) * (y2 - y1)
    return float(iw * ih / area) if area > 0 else 0.0


# --------------------------------------------------------------------------- sampling


def sample_plane(rng: np.random.Generator, *, max_pitch_deg=2.0, max_roll_deg=1.0,
                 height=KITTI_CAMERA_HEIGHT) -> GroundPlane:
    """Ground plane with pitch ~ U(+-max_pitch) and roll ~ U(+-max_roll), fixed height."""
    pitch = np.deg2rad(rng.uniform(-max_pitch_deg, max_pitch_deg))
    roll = np.deg2rad(rng.uniform(-max_roll_deg, max_roll_deg))
    return GroundPlane(float(pitch), float(roll), float(height))


def sample_street(rng: np.random.Generator) -> Street:
    n_same = int(rng.choice([1, 2], p=[0.6, 0.4]))
    n_opp = int(rng.choice([0, 1, 2], p=[0.3, 0.5, 0.2]))
    ego = int(rng.integers(n_same))  # index among same-direction lanes, 0 = leftmost
    offset = rng.uniform(-0.4, 0.4)  # camera offset from its lane centre
    # lanes left to right: oncoming lanes, then same-direction lanes
    n = n_opp + n_same
    ego_index = n_opp + ego
    centers = tuple(float((k - ego_index) * LANE_WIDTH - offset) for k in range(n))
    directions = tuple([-1] * n_opp + [1] * n_same)
    park_l = str(rng.choice(["none", "parallel", "perpendicular"], p=[0.3, 0.55, 0.15]))
    park_r = str(rng.choice(["none", "parallel", "perpendicular"], p=[0.15, 0.65, 0.2]))
    road_left = centers[0] - LANE_WIDTH / 2 - (PARKING_LANE_WIDTH if park_l == "parallel" else 0.0)
    road_right = centers[-1] + LANE_WIDTH / 2 + (PARKING_LANE_WIDTH if park_r == "parallel" else 0.0)
    sw_l, sw_r = (float(rng.uniform(*SIDEWALK_WIDTH)) for _ in range(2))
    bay_l = 5.5 if park_l == "perpendicular" else 0.0
    bay_r = 5.5 if park_r == "perpendicular" else 0.0
    facade_left = road_left - bay_l - sw_l - rng.uniform(0.0, 3.0)
    facade_right = road_right + bay_r + sw_r + rng.uniform(0.0, 3.0)
    markings = []
    for k in range(n - 1):
        x = 0.5 * (centers[k] + centers[k + 1])
        markings.append((x, "solid" if directions[k] != directions[k + 1] else "dashed"))
    markings.append((centers[0] - LANE_WIDTH / 2 + 0.2, "solid"))
    markings.append((centers[-1] + LANE_WIDTH / 2 - 0.2, "solid"))
    return Street(centers, directions, ego_index, float(road_left), float(road_right), park_l, park_r,
                  sw_l, sw_r, float(facade_left), float(facade_right), tuple(markings))


def kitti_car_size(rng: np.random.Generator) -> tuple:
    """A car size ``(h, w, l)`` drawn from KITTI's Car statistics (normal, cut at 2 sigma).

    The TORCS exemplars are race cars (4.4-5.1 m long, 1.1-1.5 m high); every car
    instance is resized to a KITTI-like size so that the synthetic scenes have the size
    distribution of the real data the shape model is built for."""
    from wirescene.core.boxes import KITTI_CAR_SIZE

    mean, std = np.array(KITTI_CAR_SIZE["mean"]), np.array(KITTI_CAR_SIZE["std"])  # (l, w, h)
    l, w, h = mean + std * np.clip(rng.standard_normal(3), -2.0, 2.0)
    return float(h), float(w), float(l)


def _row_slots(rng, models, dims, *, x_of, azimuth_of, gap, role, z_start):
    """Cars of one parking row or lane, from ``z_start`` up to beyond MAX_DEPTH.
    Each car gets a CAD model and its own KITTI-like size (``dims`` is unused but for
    the model names)."""
    out = []
    z = z_start
    prev_half = 0.0
    while True:
        name = str(rng.choice(models))
        h, w, l = kitti_car_size(rng)
        az = azimuth_of()
        along = l if abs(np.cos(az)) < 0.5 else w  # extent along the street
        z = z + prev_half + gap() + along / 2
        if z - along / 2 > MAX_DEPTH:
            break
        out.append(CarPlacement(name, float(x_of(w, l)), float(z), float(az), (h, w, l), role))
        prev_half = along / 2
        if rng.random() < 0.25:  # leave an empty space now and then
            z += rng.uniform(2.0, 8.0)
    return out


def candidate_cars(rng: np.random.Generator, street: Street, dims: dict) -> list:
    """All cars of every parking row and lane (before field-of-view and count selection)."""
    models = sorted(dims)
    deg = np.pi / 180
    cands = []
    for side in ("left", "right"):
        style = street.parking_left if side == "left" else street.parking_right
        sign = -1.0 if side == "left" else 1.0
        kerb = street.road_left if side == "left" else street.road_right
        if style == "parallel":
            # right side parks with the traffic (+z, azimuth -90 deg); the left, opposite
            base = -np.pi / 2 if side == "right" else (np.pi / 2 if street.lane_directions[0] < 0 else -np.pi / 2)
            cands += _row_slots(
                rng, models, dims,
                x_of=lambda w, l, kerb=kerb, sign=sign: kerb - sign * (w / 2 + rng.uniform(0.1, 0.4)),
                azimuth_of=lambda base=base: base + rng.normal(0, 2.5) * deg,
                gap=lambda: rng.uniform(0.5, 2.5), role=f"parked-{side}", z_start=rng.uniform(-2.0, 6.0))
        elif style == "perpendicular":
            # nose towards or away from the road: azimuth 0 or 180 deg
            flip = rng.random() < 0.5
            cands += _row_slots(
                rng, models, dims,
                x_of=lambda w, l, kerb=kerb, sign=sign: kerb + sign * (l / 2 + rng.uniform(0.2, 0.6)),
                azimuth_of=lambda flip=flip: (np.pi if flip ^ (rng.random() < 0.2) else 0.0) + rng.normal(0, 4) * deg,
                gap=lambda: rng.uniform(0.5, 1.3), role=f"parked-{side}", z_start=rng.uniform(-2.0, 6.0))
    for k, (xc, d) in enumerate(zip(street.lane_centers, street.lane_directions)):
        base = -np.pi / 2 if d > 0 else np.pi / 2
        cands += _row_slots(
            rng, models, dims,
            x_of=lambda w, l, xc=xc: xc + rng.uniform(-0.35, 0.35),
            azimuth_of=lambda base=base: base + rng.normal(0, 2.0) * deg,
            gap=lambda: rng.uniform(5.0, 25.0), role=f"lane-{k}", z_start=rng.uniform(0.0, 12.0))
    return cands


def sample_cars(rng, street: Street, plane: GroundPlane, camera: Camera, dims: dict, n: int) -> list:
    """``n`` cars (fewer only if the street has too few valid slots), no two footprints
    overlapping, each 5-50 m ahead and mostly inside the field of view."""
    cands, weights = [], []
    for c in candidate_cars(rng, street, dims):
        if not (MIN_DEPTH <= c.z <= MAX_DEPTH):
            continue
        loc, R = place(c.x, c.z, c.azimuth, plane)
        inside = inside_fraction(camera, c.dims, loc, R)
        if inside < MIN_INSIDE_FRACTION:
            continue
        cands.append(c)
        weights.append(TRUNCATED_WEIGHT if inside < 0.98 else 1.0)
    # weighted sampling without replacement (Efraimidis-Spirakis): keys u^(1/w)
    keys = rng.random(len(cands)) ** (1.0 / np.asarray(weights, dtype=float).reshape(-1))
    order = np.argsort(-keys, kind="stable")
    chosen, prints = [], []
    for i in order:
        if len(chosen) >= n:
            break
        fp = cands[i].footprint(FOOTPRINT_MARGIN)
        if any(polygons_overlap(fp, p) for p in prints):
            continue
        chosen.append(cands[i])
        prints.append(fp)
    chosen.sort(key=lambda c: (c.z, c.x))
    return chosen


def sample_occluders(rng, street: Street, cars: list, n: int) -> list:
    """Up to ``n`` poles, boxes and bushes on the lines of sight to random cars."""
    out = []
    if not cars:
        return out
    ego_x = street.lane_centers[street.ego_lane]
    prints = [c.footprint(FOOTPRINT_MARGIN) for c in cars]
    for _ in range(n):
        kind = str(rng.choice(OCCLUDER_KINDS, p=[0.4, 0.3, 0.3]))
        for _try in range(30):
            target = cars[int(rng.integers(len(cars)))]
            f = rng.uniform(0.3, 0.85)
            ray = np.array([target.x, target.z])
            perp = np.array([-ray[1], ray[0]]) / np.linalg.norm(ray)
            p = f * ray + perp * rng.uniform(-1.2, 1.2)
            if p[1] < 3.0 or abs(p[0] - ego_x) < LANE_WIDTH / 2 + 0.3:
                continue
            if kind == "pole":
                size = (float(rng.uniform(0.05, 0.14)), float(rng.uniform(2.5, 5.0)))
            elif kind == "box":
                size = (float(rng.uniform(0.5, 1.4)), float(rng.uniform(0.4, 0.9)), float(rng.uniform(0.8, 1.6)))
            else:
                size = (float(rng.uniform(0.45, 1.1)), float(rng.uniform(0.7, 1.6)))
            occ = Occluder(kind, float(p[0]), float(p[1]), size, float(rng.uniform(0, np.pi)))
            fp = occ.footprint(0.1)
            if any(polygons_overlap(fp, q) for q in prints):
                continue
            out.append(occ)
            prints.append(fp)
            break
    return out


def sample_layout(rng: np.random.Generator, camera: Camera, dims: dict, *, n_cars: int,
                  n_occluders: int = 0, camera_height: float = KITTI_CAMERA_HEIGHT,
                  camera_pitch_deg: float = 0.0) -> SceneLayout:
    """A full scene layout. ``dims`` maps CAD model names to ``(h, w, l)``; the camera stands
    ``camera_height`` above the road, pitched ``camera_pitch_deg`` further down than the
    sampled rig pitch (the road's horizon rises above the principal point's row)."""
    plane = sample_plane(rng, height=camera_height)
    if camera_pitch_deg:
        plane = GroundPlane(plane.pitch + np.deg2rad(camera_pitch_deg), plane.roll, plane.height)
    street = sample_street(rng)
    cars = sample_cars(rng, street, plane, camera, dims, n_cars)
    occluders = sample_occluders(rng, street, cars, n_occluders)
    return SceneLayout(plane, street, cars, occluders)
