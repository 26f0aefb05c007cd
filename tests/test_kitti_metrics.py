"""KITTI benchmark metrics: hand-computed cases of the devkit's rules, overlaps against
brute-force rasterisation, and the vectorised matching against a plain per-frame loop."""

import math

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.errors import InputError
from wirescene.eval.kitti_metrics import (
    DIFFICULTIES,
    N_SAMPLE_PTS,
    _threshold_columns,
    average_precision,
    bev_corners,
    box_overlap_2d,
    convex_intersection_area,
    difficulty_of,
    iou_3d,
    iou_bev,
    kitti_curves,
    kitti_metrics,
    read_label_dirs,
)
from wirescene.io.kitti import FrameLabels, Label, read_labels


def lab(box, *, typ="Car", loc=(0.0, 1.6, 20.0), dims=(1.5, 1.6, 3.9), ry=0.0, alpha=0.0, score=None, occ=0, trunc=0.0):
    return Label(typ, trunc, occ, alpha, box, dims, loc, ry, score)


BOX = [100.0, 100.0, 200.0, 200.0]  # 100 px high: every difficulty


def frames_of_one_car(n, *, detected=None, score=lambda i: 1.0 - i / 1000):
    """``n`` frames with one easy car each; the first ``detected`` get a perfect detection."""
    detected = n if detected is None else detected
    gts = [[lab(BOX)] for _ in range(n)]
    preds = [[lab(BOX, score=score(i))] if i < detected else [] for i in range(n)]
    return gts, preds


# --------------------------------------------------------------------------- AP by the devkit's rule


def test_many_perfect_detections_give_100():
    # 80 GT, 80 perfect TPs: thresholds at i = 0, 1, 3, ..., 79 -> 41 points, all precision 1.
    r = kitti_metrics(*frames_of_one_car(80))
    for metric in ("2d", "aos", "bev", "3d"):
        assert r["car"][metric] == {"easy": 100.0, "moderate": 100.0, "hard": 100.0}
        assert r["r11"]["car"][metric]["moderate"] == 100.0
        assert r["iou_0.5"]["car"][metric]["hard"] == 100.0
    assert r["recall_points"] == 40 and r["n_gt"]["car"] == {"easy": 80, "moderate": 80, "hard": 80}


def test_one_gt_one_perfect_detection_is_one_sample_point():
    # The devkit samples one threshold per reached recall step of 1/40: a single TP fills
    # precision point 0 only, which R40 leaves out and R11 counts once.
    r = kitti_metrics([[lab(BOX)]], [[lab(BOX, score=0.9)]])
    assert r["car"]["3d"]["moderate"] == 0.0
    assert r["r11"]["car"]["3d"]["moderate"] == pytest.approx(100 / 11)


def test_half_of_80_detected():
    # 80 GT, 40 TPs: kept thresholds i = 0, 1, 3, ..., 39 -> 21 points of precision 1:
    # R40 = 20/40, R11 = points 0, 4, ..., 20 -> 6/11.
    r = kitti_metrics(*frames_of_one_car(80, detected=40))
    assert r["car"]["2d"]["easy"] == pytest.approx(50.0)
    assert r["r11"]["car"]["2d"]["easy"] == pytest.approx(600 / 11)


def test_false_positives_below_the_tp_scores_do_not_count():
    gts, preds = frames_of_one_car(80)
    for p in preds:  # a far-away FP in every frame, scoring below every TP
        p.append(lab([600, 100, 700, 200], loc=(10.0, 1.6, 40.0), score=0.01))
    assert kitti_metrics(gts, preds)["car"]["3d"]["hard"] == 100.0


def test_false_positives_above_the_tp_scores_halve_precision():
    gts, preds = frames_of_one_car(80)
    for p in preds:
        p.append(lab([600, 100, 700, 200], loc=(10.0, 1.6, 40.0), score=2.0))
    # every threshold admits all 80 FPs: precision at point i is (tp_i) / (tp_i + 80),
    # made monotone; at the last point 80/160.
    r = kitti_metrics(gts, preds)
    curve = kitti_curves(gts, preds)[0.7]["2d"]["easy"].precision
    tps = np.array([1] + list(range(2, 81, 2)))  # TPs admitted at the 41 thresholds
    expected = np.maximum.accumulate((tps / (tps + 80.0))[::-1])[::-1]
    assert_close(curve, expected)
    assert r["car"]["2d"]["easy"] == pytest.approx(expected[1:].mean() * 100)


def test_van_detection_is_no_false_positive():
    gts, preds = frames_of_one_car(80)
    van_box = [400.0, 100.0, 500.0, 200.0]
    for g, p in zip(gts, preds):
        g.append(lab(van_box, typ="Van", loc=(5.0, 1.6, 20.0)))
        p.append(lab(van_box, loc=(5.0, 1.6, 20.0), score=2.0))  # a "Car" on the Van, top score
    r = kitti_metrics(gts, preds)
    assert r["car"]["2d"]["moderate"] == 100.0 and r["car"]["3d"]["moderate"] == 100.0
    # Without the Van label the same detections are FPs.
    r_fp = kitti_metrics([[g[0]] for g in gts], preds)
    assert r_fp["car"]["2d"]["moderate"] < 60


def test_detection_in_dontcare_is_ignored_in_2d():
    gts, preds = frames_of_one_car(80)
    dc_box = [400.0, 100.0, 560.0, 220.0]
    for g, p in zip(gts, preds):
        g.append(lab(dc_box, typ="DontCare", loc=(-1000, -1000, -1000), dims=(-1, -1, -1), ry=-10, alpha=-10))
        p.append(lab([410.0, 110.0, 500.0, 200.0], loc=(5.0, 1.6, 20.0), score=2.0))  # wholly inside
    r = kitti_metrics(gts, preds)
    assert r["car"]["2d"]["easy"] == 100.0 and r["car"]["aos"]["easy"] == 100.0
    # BEV / 3D: KITTI's DontCare rows have no 3D box, so there the detections are FPs.
    assert r["car"]["3d"]["easy"] < 60
    # A detection only 60% inside the region (of its own area) is an FP in 2D too.
    for p in preds:
        p[-1] = lab([500.0, 110.0, 600.0, 210.0], loc=(5.0, 1.6, 20.0), score=2.0)
    assert kitti_metrics(gts, preds)["car"]["2d"]["easy"] < 60


def test_low_detection_is_ignored_not_false_positive():
    gts, preds = frames_of_one_car(80)
    for p in preds:  # 30 px high: ignored for easy (40 px), an FP for moderate (25 px)
        p.append(lab([600, 100, 630, 130], loc=(10.0, 1.6, 50.0), score=2.0))
    r = kitti_metrics(gts, preds)
    assert r["car"]["2d"]["easy"] == 100.0
    assert r["car"]["2d"]["moderate"] < 60


def test_aos_with_pi_error_is_zero_and_half_pi_is_half():
    gts, preds = frames_of_one_car(80)
    for p in preds:
        p[0].alpha = math.pi
    r = kitti_metrics(gts, preds)
    assert r["car"]["2d"]["easy"] == 100.0 and r["car"]["aos"]["easy"] == pytest.approx(0.0, abs=1e-9)
    for p in preds:
        p[0].alpha = math.pi / 2
    assert kitti_metrics(gts, preds)["car"]["aos"]["easy"] == pytest.approx(50.0)


def test_no_orientation_marker_disables_aos():
    gts, preds = frames_of_one_car(80)
    preds[3][0].alpha = -10
    r = kitti_metrics(gts, preds)
    assert r["car"]["aos"] == {"easy": None, "moderate": None, "hard": None}
    assert r["car"]["2d"]["easy"] == 100.0


def test_difficulty_assignment_and_none_without_ground_truth():
    assert difficulty_of(lab([0, 0, 10, 40])) == "easy"
    assert difficulty_of(lab([0, 0, 10, 39.9])) == "moderate"
    assert difficulty_of(lab([0, 0, 10, 24.9])) is None
    assert difficulty_of(lab(BOX, occ=1)) == "moderate"
    assert difficulty_of(lab(BOX, occ=2)) == "hard"
    assert difficulty_of(lab(BOX, occ=3)) is None
    assert difficulty_of(lab(BOX, trunc=0.16)) == "moderate"
    assert difficulty_of(lab(BOX, trunc=0.31)) == "hard"
    assert difficulty_of(lab(BOX, trunc=0.51)) is None
    # 80 moderate-only cars (occluded 1): easy has no ground truth -> None, detected -> 100.
    gts, preds = frames_of_one_car(80)
    for g in gts:
        g[0].occluded = 1
    r = kitti_metrics(gts, preds)
    assert r["car"]["2d"]["easy"] is None and r["n_gt"]["car"]["easy"] == 0
    # exactly 40 px high is easy (the devkit drops ground truth *lower* than the minimum)
    for g, p in zip(gts, preds):
        g[0].occluded = 0
        g[0].box = p[0].box = np.array([100.0, 100.0, 200.0, 140.0])
    curves = kitti_curves(gts, preds)[0.7]
    assert curves["2d"]["easy"].n_gt == 80 and average_precision(curves["2d"]["easy"].precision) == 100.0
    assert r["car"]["2d"]["moderate"] == 100.0 and r["car"]["2d"]["hard"] == 100.0


def test_no_detection_at_all_is_not_evaluated():
    gts, _ = frames_of_one_car(5)
    r = kitti_metrics(gts, [[] for _ in gts])
    assert r["car"]["3d"]["moderate"] is None and r["n_gt"]["car"]["moderate"] == 5


def test_missed_3d_location_counts_in_3d_but_not_2d():
    gts, preds = frames_of_one_car(80)
    for p in preds:  # right 2D box, 3D box 0.5 m too high: 3D IoU 2/3 < 0.7, BEV IoU 1
        p[0].location = np.array([0.0, 1.1, 20.0])
    r = kitti_metrics(gts, preds)
    assert r["car"]["2d"]["easy"] == 100.0 and r["car"]["bev"]["easy"] == 100.0
    assert r["car"]["3d"]["easy"] == 0.0 and r["iou_0.5"]["car"]["3d"]["easy"] == 100.0


def test_average_precision_sample_points():
    curve = np.zeros(N_SAMPLE_PTS)
    curve[:21] = 1.0
    assert average_precision(curve) == 50.0
    assert average_precision(curve, recall_points=11) == pytest.approx(600 / 11)
    with pytest.raises(ValueError):
        average_precision(curve, recall_points=12)
    # a stack of curves (bootstrap draws) gives an AP each
    assert_close(average_precision(np.stack([curve, np.ones(N_SAMPLE_PTS)])), np.array([50.0, 100.0]))
    with pytest.raises(ValueError, match="shape"):
        average_precision(np.ones(40))


# --------------------------------------------------------------------------- overlaps


def raster_area(p, q, *, n=600):
    """Area of the intersection of two convex polygons by counting grid points."""
    pts = np.concatenate([p, q])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    xs = lo[0] + (np.arange(n) + 0.5) * (hi[0] - lo[0]) / n  # cell centres
    ys = lo[1] + (np.arange(n) + 0.5) * (hi[1] - lo[1]) / n
    X, Y = np.meshgrid(xs, ys)
    xy = np.stack([X.ravel(), Y.ravel()], axis=1)

    def inside(poly):
        e = np.roll(poly, -1, axis=0) - poly
        c = e[None, :, 0] * (xy[:, None, 1] - poly[None, :, 1]) - e[None, :, 1] * (xy[:, None, 0] - poly[None, :, 0])
        return (c >= 0).all(axis=1) | (c <= 0).all(axis=1)

    return (inside(p) & inside(q)).mean() * (hi[0] - lo[0]) * (hi[1] - lo[1])


def square(ry, *, x=0.0, z=0.0, l=1.0, w=1.0):
    return bev_corners(np.array([[x, 0.0, z]]), np.array([[1.0, w, l]]), np.array([ry]))


def test_unit_squares_rotated_45_degrees():
    area = convex_intersection_area(square(0.0), square(math.pi / 4))
    assert_close(area, [2 * (math.sqrt(2) - 1)], atol=1e-12)  # the regular octagon
    iou = iou_bev(np.zeros((1, 3)), [[1.0, 1.0, 1.0]], [0.0], np.zeros((1, 3)), [[1.0, 1.0, 1.0]], [math.pi / 4])
    a = 2 * (math.sqrt(2) - 1)
    assert_close(iou, [a / (2 - a)], atol=1e-12)


@pytest.mark.parametrize(
    "a, b, expected",
    [
        ((0.0, 0, 0), (0.0, 0, 0), 1.0),  # identical
        ((0.0, 0, 0), (0.0, 0.5, 0), 0.5),  # shifted half a side
        ((0.0, 0, 0), (math.pi / 2, 0, 0), 1.0),  # a square turned by 90 deg is itself
        ((0.0, 0, 0), (0.0, 1.0, 0), 0.0),  # touching edges
        ((0.0, 0, 0), (0.3, 5.0, 5.0), 0.0),  # far apart
    ],
)
def test_known_square_overlaps(a, b, expected):
    area = convex_intersection_area(square(a[0], x=a[1], z=a[2]), square(b[0], x=b[1], z=b[2]))
    assert_close(area, [expected], atol=1e-9)


def test_rotated_rectangles_against_rasterisation():
    rng = np.random.default_rng(3)
    for _ in range(10):
        l1, w1, l2, w2 = rng.uniform(0.5, 4.0, 4)
        p = square(rng.uniform(-math.pi, math.pi), l=l1, w=w1)
        q = square(rng.uniform(-math.pi, math.pi), x=rng.uniform(-1.5, 1.5), z=rng.uniform(-1.5, 1.5), l=l2, w=w2)
        exact = convex_intersection_area(p, q)[0]
        approx = raster_area(p[0], q[0])
        assert exact > 0.05 and abs(exact - approx) < 0.002 * exact, (exact, approx)
    # and the area is symmetric, batch-independent, and orientation-independent
    P = np.concatenate([square(0.2 * k, x=0.1 * k) for k in range(10)])
    Q = np.concatenate([square(-0.3 * k, z=0.05 * k, l=2.0) for k in range(10)])
    assert_close(convex_intersection_area(P, Q), convex_intersection_area(Q[:, ::-1], P))


def test_bev_footprint_follows_kitti_rotation():
    # rotation_y = pi/2: the car's length points along -z (KITTI: x_obj -> (cos, -sin) in x-z)
    corners = bev_corners(np.array([[0.0, 0, 0]]), np.array([[1.5, 1.6, 4.0]]), np.array([math.pi / 2]))[0]
    assert_close(np.ptp(corners[:, 0]), 1.6, atol=1e-12)
    assert_close(np.ptp(corners[:, 1]), 4.0, atol=1e-12)
    assert_close(corners[0], [0.8, -2.0], atol=1e-12)


def test_3d_iou_uses_the_height_overlap():
    loc = np.array([[0.0, 1.6, 20.0]])
    dims = np.array([[1.5, 1.6, 3.9]])
    assert_close(iou_3d(loc, dims, [0.3], loc, dims, [0.3]), [1.0])
    # same footprint, raised by 0.5 m (y is down): overlap 1.0 of 1.5 m -> 1 / (1.5 + 1.5 - 1)
    assert_close(iou_3d(loc, dims, [0.0], loc - [0, 0.5, 0], dims, [0.0]), [0.5])
    assert_close(iou_bev(loc, dims, [0.0], loc - [0, 0.5, 0], dims, [0.0]), [1.0])
    # no vertical overlap at all
    assert_close(iou_3d(loc, dims, [0.0], loc - [0, 1.6, 0], dims, [0.0]), [0.0])
    # half the length off along x (ry = 0: length along x) and 0.75 m higher
    other = loc + [1.95, -0.75, 0]
    inter = 1.95 * 1.6 * 0.75
    vol = 1.5 * 1.6 * 3.9
    assert_close(iou_3d(loc, dims, [0.0], other, dims, [0.0]), [inter / (2 * vol - inter)])


def test_2d_overlap_criteria():
    a = np.array([0.0, 0, 10, 10])
    b = np.array([5.0, 0, 25, 10])
    assert_close(box_overlap_2d(a, b), 50 / 250)
    assert_close(box_overlap_2d(a, b, criterion="a"), 0.5)
    assert box_overlap_2d(a, [10.0, 0, 20, 10]) == 0.0


# --------------------------------------------------------------------------- against a plain loop


def _loop_thresholds(v, n_gt):
    """The devkit's getThresholds as its loop: TP scores ``v`` sorted descending."""
    thresholds, current = [], 0.0
    for i, s in enumerate(v):
        left = (i + 1) / n_gt
        right = (i + 2) / n_gt if i < len(v) - 1 else left
        if (right - current) < (current - left) and i < len(v) - 1:
            continue
        thresholds.append(s)
        current += 1 / 40
    return thresholds


def _loop_curve(gts, preds, metric, difficulty, thr):
    """The rules of the module docstring as a literal per-frame, per-threshold loop."""
    from wirescene.eval.kitti_metrics import MAX_OCCLUSION, MAX_TRUNCATION, MIN_HEIGHT

    cache = {}

    def overlap(d, g):
        key = (id(d), id(g))
        if key not in cache:
            if metric == "2d":
                cache[key] = float(box_overlap_2d(d.box, g.box))
            else:
                f = iou_bev if metric == "bev" else iou_3d
                cache[key] = float(f(d.location[None], d.dims[None], [d.rotation_y],
                                     g.location[None], g.dims[None], [g.rotation_y])[0])
        return cache[key]

    def clean(g_rows, d_rows):
        ig, idet, dc = [], [], []
        for g in g_rows:
            t = g.type.lower()
            valid = 1 if t == "car" else (0 if t == "van" else -1)
            bad = (g.occluded > MAX_OCCLUSION[difficulty] or g.truncated > MAX_TRUNCATION[difficulty]
                   or g.box[3] - g.box[1] < MIN_HEIGHT[difficulty])
            ig.append(0 if valid == 1 and not bad else (1 if valid == 0 or valid == 1 else -1))
            if t == "dontcare":
                dc.append(g)
        for d in d_rows:
            if int(abs(d.box[1] - d.box[3])) < MIN_HEIGHT[difficulty]:
                idet.append(1)
            else:
                idet.append(0 if d.type.lower() == "car" else -1)
        return ig, idet, dc

    def stats(g_rows, d_rows, ig, idet, dc, t):
        assigned = [False] * len(d_rows)
        tp = fp = fn = 0
        sim, scores = 0.0, []
        for i, g in enumerate(g_rows):
            if ig[i] == -1:
                continue
            best, best_ov, best_score, took_ignored = -1, 0.0, -np.inf, False
            for j, d in enumerate(d_rows):
                if idet[j] == -1 or assigned[j] or (t is not None and d.score < t):
                    continue
                ov = overlap(d, g)
                if ov <= thr:
                    continue
                if t is None:
                    if d.score > best_score:
                        best, best_score = j, d.score
                elif idet[j] == 0 and (ov > best_ov or took_ignored):
                    best, best_ov, took_ignored = j, ov, False
                elif idet[j] == 1 and best < 0:
                    best, took_ignored = j, True
            if best < 0:
                fn += ig[i] == 0
            elif ig[i] == 1 or idet[best] == 1:
                assigned[best] = True
            else:
                tp += 1
                scores.append(d_rows[best].score)
                sim += (1 + math.cos(g.alpha - d_rows[best].alpha)) / 2
                assigned[best] = True
        if t is not None:
            for j, d in enumerate(d_rows):
                if assigned[j] or idet[j] != 0 or d.score < t:
                    continue
                in_dc = metric == "2d" and any(float(box_overlap_2d(d.box, c.box, criterion="a")) > thr for c in dc)
                fp += not in_dc
        return tp, fp, fn, sim, scores

    cleaned = [clean(g, d) for g, d in zip(gts, preds)]
    n_gt = sum(c[0].count(0) for c in cleaned)
    v = sorted((s for (g, d), c in zip(zip(gts, preds), cleaned) for s in stats(g, d, *c, None)[4]), reverse=True)
    thresholds = _loop_thresholds(v, n_gt)
    prec, aos = np.zeros(41), np.zeros(41)
    for k, t in enumerate(thresholds):
        tp, fp, sim = 0, 0, 0.0
        for (g, d), c in zip(zip(gts, preds), cleaned):
            a, b, _, s, _ = stats(g, d, *c, t)
            tp, fp, sim = tp + a, fp + b, sim + s
        prec[k] = tp / (tp + fp) if tp + fp else 0.0
        aos[k] = sim / (tp + fp) if tp + fp else 0.0
    for k in range(len(thresholds)):
        prec[k], aos[k] = prec[k:].max(), aos[k:].max()
    return prec, aos, n_gt


def crowded_scenes(n_frames, seed):
    """Small scenes with overlapping cars, vans, low boxes, DontCare and tied scores."""
    rng = np.random.default_rng(seed)
    gts, preds = [], []
    for _ in range(n_frames):
        g, p = [], []
        for _ in range(rng.integers(0, 6)):
            x, z = rng.uniform(-3, 3), rng.uniform(10, 16)
            h = rng.choice([20.0, 25.0, 30.0, 40.0, 60.0, 90.0])
            x1, y1 = 300 + 40 * x, 150.0
            g.append(lab([x1, y1, x1 + 1.5 * h, y1 + h], typ=rng.choice(["Car", "Car", "Van", "Pedestrian"]),
                         loc=(x, 1.6, z), ry=rng.uniform(-3, 3), alpha=rng.uniform(-3, 3),
                         occ=int(rng.integers(0, 4)), trunc=float(rng.choice([0.0, 0.2, 0.4, 0.6]))))
            for _ in range(rng.integers(0, 3)):  # several detections per object
                j = rng.normal(0, 1, 8)
                box = np.array(g[-1].box) + 0.08 * h * j[:4]
                p.append(lab(box, typ=rng.choice(["Car", "Car", "Car", "Pedestrian"]),
                             loc=g[-1].location + [0.4 * j[4], 0.2 * j[5], 0.4 * j[6]], ry=g[-1].rotation_y + 0.3 * j[7],
                             alpha=g[-1].alpha + 0.5 * j[7], score=float(rng.choice([0.2, 0.5, 0.5, 0.9, rng.random()]))))
        if rng.random() < 0.5:
            g.append(lab([250, 120, 450, 260], typ="DontCare", loc=(-1000, -1000, -1000), dims=(-1, -1, -1)))
        gts.append(g)
        preds.append(p)
    return gts, preds


@pytest.mark.parametrize("seed", [0, 1])
def test_vectorised_matching_equals_plain_loop(seed):
    gts, preds = crowded_scenes(60, seed)
    for thr in (0.7, 0.5):
        curves = kitti_curves(gts, preds, min_overlaps=(thr,))[thr]
        for metric in ("2d", "bev", "3d"):
            for d, name in enumerate(DIFFICULTIES):
                prec, aos, n_gt = _loop_curve(gts, preds, metric, d, thr)
                got = curves[metric][name]
                assert got.n_gt == n_gt
                assert_close(got.precision, prec, msg=f"{metric} {name} {thr}")
                if metric == "2d":
                    assert_close(got.orientation, aos, msg=f"aos {name} {thr}")


@pytest.mark.parametrize("n_scores, n_gt", [(1, 1), (2, 2), (7, 80), (39, 40), (40, 40), (80, 80), (123, 300)])
def test_threshold_positions_equal_the_devkit_loop(n_scores, n_gt):
    rng = np.random.default_rng(n_scores)
    counts = rng.integers(1, 4, size=n_scores).astype(float)  # repeated (tied or redrawn) scores
    scores = np.sort(rng.random(n_scores))[::-1]
    expanded = np.repeat(scores, counts.astype(int))
    n_gt = max(n_gt, len(expanded))
    columns = _threshold_columns(counts, float(n_gt))
    assert_close(scores[columns], np.array(_loop_thresholds(list(expanded), n_gt)), atol=0)


def test_threshold_positions_of_many_weighted_sets_equal_each_set_alone():
    # the bootstrap's draws at once: rows of weighted counts (zeros, an empty row, no ground truth among them)
    rng = np.random.default_rng(5)
    counts = rng.integers(0, 4, size=(30, 57)).astype(float)
    counts[3] = 0.0
    n_gt = counts.sum(axis=1) + rng.integers(0, 90, size=30)
    n_gt[7] = 0.0
    counts[7] = 0.0
    rows = _threshold_columns(counts, n_gt)
    assert rows.shape == (30, 41)
    for b in range(30):
        alone = _threshold_columns(counts[b], n_gt[b]) if n_gt[b] else np.zeros(0, dtype=int)
        assert_close(rows[b][rows[b] >= 0], alone, atol=0, msg=f"row {b}")
        assert (rows[b][len(alone):] == -1).all()


@pytest.mark.parametrize("seed", [0, 1])
def test_frame_weights_equal_repeated_frames(seed):
    # a bootstrap draw (frames drawn 0, 1, 2 or 3 times) evaluated at once equals the devkit on the repeated frames
    gts, preds = crowded_scenes(40, seed)
    weights = np.random.default_rng(seed).integers(0, 4, size=(3, 40)).astype(float)
    weights[0] = 1.0
    drawn = kitti_curves(gts, preds, min_overlaps=(0.7, 0.5), frame_weights=weights)
    for b, w in enumerate(weights):
        index = np.repeat(np.arange(40), w.astype(int))
        plain = kitti_curves([gts[i] for i in index], [preds[i] for i in index], min_overlaps=(0.7, 0.5))
        for thr in (0.7, 0.5):
            for metric in ("2d", "bev", "3d"):
                for name in DIFFICULTIES:
                    got, want = drawn[thr][metric][name], plain[thr][metric][name]
                    assert got.n_gt[b] == want.n_gt
                    assert_close(got.precision[b], want.precision, msg=f"{metric} {name} {thr} draw {b}")
                    assert_close(got.orientation[b], want.orientation, msg=f"aos {name} {thr} draw {b}")
    assert_close(average_precision(drawn[0.7]["3d"]["moderate"].precision)[0],
                 kitti_metrics(gts, preds)["car"]["3d"]["moderate"])


def test_frame_weights_are_checked():
    gts, preds = frames_of_one_car(4)
    for bad, problem in ((np.ones((2, 3)), "frame_weights must have shape"), (np.full((1, 4), 0.5), "whole"),
                         (-np.ones((1, 4)), "whole")):
        with pytest.raises(ValueError, match=problem):
            kitti_curves(gts, preds, frame_weights=bad)
    with pytest.raises(ValueError, match="difficulties"):
        kitti_curves(gts, preds, difficulties=("medium",))
    only = kitti_curves(gts, preds, difficulties=("moderate",))[0.7]["3d"]
    assert list(only) == ["moderate"]


# --------------------------------------------------------------------------- files


def test_read_label_dirs(tmp_path):
    gt_dir = KITTI_ROOT / "training" / "label_2"
    ids = sorted(p.stem for p in gt_dir.glob("*.txt"))[:3]
    pred = tmp_path / "pred"
    pred.mkdir()
    (pred / f"{ids[0]}.txt").write_text("".join(ln + " 0.5\n" for ln in (gt_dir / f"{ids[0]}.txt").read_text().splitlines()))
    frames, gts, preds = read_label_dirs(gt_dir, pred, frames=ids)
    assert frames == ids and len(gts) == 3
    assert len(preds[0].objects) == len(read_labels(gt_dir / f"{ids[0]}.txt").objects)
    assert preds[1] == FrameLabels() and preds[2] == FrameLabels()  # missing file: no detections
    with pytest.raises(InputError, match="not found"):
        read_label_dirs(tmp_path / "nope", pred)
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "000001.txt").write_text("Car 0 0\n")
    with pytest.raises(InputError, match="line 1"):
        read_label_dirs(tmp_path / "bad", pred)


# --------------------------------------------------------------------------- command line


def _cli(*args):
    from click.testing import CliRunner

    from wirescene.cli.main import main

    return CliRunner().invoke(main, [str(a) for a in args])


def _one_line_error(result):
    err = result.stderr if hasattr(result, "stderr") else result.output
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("wirescene: error:"), err
    return lines[0]


def test_cli_kitti_eval_table_json_and_missing_predictions(tmp_path):
    import json

    from wirescene.io.kitti import write_labels

    gt_dir = KITTI_ROOT / "training" / "label_2"
    pred = tmp_path / "pred"
    pred.mkdir()
    for f in ("000002", "000010"):  # GT rows as predictions with score 1; 001545 has no file
        labels = read_labels(gt_dir / f"{f}.txt")
        for o in labels.objects:
            o.score = 1.0
        write_labels(pred / f"{f}.txt", labels.objects)
    out = tmp_path / "k.json"
    r = _cli("kitti-eval", gt_dir, pred, "--json", out)
    assert r.exit_code == 0, r.output
    assert "KITTI Car AP" in r.output and "moderate" in r.output
    # what the score of a folder lacking a frame means, and that KITTI's server would refuse it (was "(no detections)")
    assert (f"wirescene: {pred}: 1 of 3 frames have no prediction file (e.g. 001545.txt): scored as frames without "
            "detections, their cars missed; KITTI's server refuses a submission lacking a frame (an empty FRAME.txt "
            "is a frame without cars; --frames or --split-file scores a selection)") in r.stderr.splitlines()
    n = kitti_metrics([read_labels(gt_dir / f"{f}.txt") for f in ("000002", "000010", "001545")],
                      [FrameLabels()] * 3)["n_gt"]["car"]  # fewer than 40 cars: the devkit's ceiling is said
    assert (f"at most (N - 1) / 40: easy {100 * (n['easy'] - 1) / 40:.1f}, moderate {100 * (n['moderate'] - 1) / 40:.1f}"
            in r.output)
    rows = [ln.split() for ln in r.output.splitlines() if ln.split()[:1] in (["2d"], ["aos"], ["bev"], ["3d"])]
    assert len(rows) == 12
    data = json.loads(out.read_text())
    assert set(data["car"]) == {"2d", "aos", "bev", "3d"} and data["recall_points"] == 40
    gts = [read_labels(gt_dir / f"{f}.txt") for f in ("000002", "000010", "001545")]
    preds = [read_labels(pred / "000002.txt"), read_labels(pred / "000010.txt"), FrameLabels()]
    assert data["car"] == kitti_metrics(gts, preds)["car"]
    # the moderate APs' interval over the three frames' drives, each draw evaluated by the devkit's rules
    assert "90% bootstrap interval over 3 drives, moderate (1000 draws" in r.output
    spread = data["kitti_interval"]
    assert spread["drives"] == 3 and spread["frames_alone"] == 0
    lo, hi = spread["car"]["3d"]
    assert 0.0 <= lo <= data["car"]["3d"]["moderate"] <= hi <= 100.0
    # only the frames given: with every car found exactly, precision is 1 at each threshold
    r = _cli("kitti-eval", gt_dir, pred, "--frames", "000010", "--json", out, "--draws", "0")
    assert r.exit_code == 0, r.output
    assert "bootstrap" not in r.output
    one = json.loads(out.read_text())
    assert "kitti_interval" not in one
    n = one["n_gt"]["car"]["moderate"]
    assert one["n_frames"] == 1 and one["car"]["3d"]["moderate"] == pytest.approx((n - 1) / 40 * 100)
    # a 2D detector's rows (dimensions -1 -1 -1): scored as boxes of no size, which the output says
    flat = tmp_path / "flat"
    flat.mkdir()
    labels = read_labels(pred / "000010.txt")
    for o in labels.objects[:2]:  # two Car rows
        o.dims = np.array([-1.0, -1.0, -1.0])
    write_labels(flat / "000010.txt", labels.objects)
    r = _cli("kitti-eval", gt_dir, flat, "--frames", "000010", "--draws", "0")
    cars = sum(o.type == "Car" for o in labels.objects)
    assert r.exit_code == 0 and (f"{flat}: 2 of {cars} Car rows have no 3D box (dimensions -1 -1 -1): BEV and 3D AP "
                                 "count them as misses") in r.output, r.output
    assert "no 3D box" not in _cli("kitti-eval", gt_dir, pred, "--frames", "000010", "--draws", "0").output


@pytest.mark.parametrize("case, problem", [("no_gt_dir", "not found"), ("bad_gt", "line 1"),
                                           ("no_score", "score"), ("unknown_frame", "000009"),
                                           ("no_drive_map", "not a KITTI devkit mapping directory"),
                                           ("no_predictions", "pred: no prediction file of any of the 1 frames"),
                                           ("a_run_of_variants", "it holds folders of them (full): give one")])
def test_cli_kitti_eval_bad_input_is_one_line_error(tmp_path, case, problem):
    gt_dir = tmp_path / "gt"
    pred = tmp_path / "pred"
    gt_dir.mkdir()
    pred.mkdir()
    (gt_dir / "000001.txt").write_text((KITTI_ROOT / "training" / "label_2" / "000010.txt").read_text())
    args = []
    if case == "no_gt_dir":
        gt_dir = tmp_path / "missing"
    elif case == "bad_gt":
        (gt_dir / "000001.txt").write_text("Car 0.0 0 1.0 10 20 30\n")
    elif case == "no_score":
        (pred / "000001.txt").write_text((gt_dir / "000001.txt").read_text())
    elif case == "unknown_frame":
        args = ["--frames", "000009"]
    elif case == "a_run_of_variants":  # `eval --predictions pred` keeps one folder per variant
        (pred / "full").mkdir()
        (pred / "full" / "000001.txt").write_text("")
    elif case == "no_predictions":
        pass
    else:
        args = ["--drive-map", tmp_path]
    line = _one_line_error(_cli("kitti-eval", gt_dir, pred, *args))
    assert problem in line


def test_cli_eval_adds_kitti_figures(tmp_path):
    import json

    out = tmp_path / "m.json"
    pred = tmp_path / "pred"
    r = _cli("eval", KITTI_ROOT, "--variant", "coarse", "--raw-scores", "--frames", "000010", "--workers", "1",
             "--json", out, "--predictions", pred)
    assert r.exit_code == 0, r.output
    assert "KITTI Car AP R40" in r.output
    written = json.loads(out.read_text())
    kitti = written["kitti"]
    # the figures are those of the label files it wrote, and so are their intervals (same drives, same draws)
    r2 = _cli("kitti-eval", KITTI_ROOT / "training" / "label_2", pred / "coarse", "--frames", "000010",
              "--json", tmp_path / "k.json")
    assert r2.exit_code == 0, r2.output
    again = json.loads((tmp_path / "k.json").read_text())
    assert again.pop("kitti_interval") == written["kitti_interval"]
    assert again == kitti
    # 000010: 8 cars; 3 easy, 2 more occluded 1 (28.8 and 42 px), 2 more occluded 2, one truncated 0.8
    assert kitti["n_gt"]["car"] == {"easy": 3, "moderate": 5, "hard": 7}
    # --resume reuses the frame, with the same figures
    r3 = _cli("eval", KITTI_ROOT, "--variant", "coarse", "--raw-scores", "--frames", "000010", "--workers", "1",
              "--json", out, "--predictions", pred, "--resume", "--draws", "0")
    assert r3.exit_code == 0, r3.output
    assert "resuming: 1 of 1" in r3.output
    resumed = json.loads(out.read_text())
    assert resumed["kitti"] == kitti
    assert "kitti_interval" not in resumed and "every draw ranks" not in r3.output  # --draws 0: no AP intervals
    # without --predictions: the figures of the rows in memory (equal up to the files' rounding)
    r4 = _cli("eval", KITTI_ROOT, "--variant", "coarse", "--raw-scores", "--frames", "000010", "--workers", "1", "--json", out)
    assert r4.exit_code == 0, r4.output
    in_memory = json.loads(out.read_text())["kitti"]
    assert in_memory["car"]["3d"] == pytest.approx(kitti["car"]["3d"], rel=1e-5)
    assert in_memory["car"]["aos"] == pytest.approx(kitti["car"]["aos"], rel=1e-5)


def test_cli_kitti_eval_of_several_runs_gives_each_their_mean_and_one_interval(tmp_path):
    import json

    from wirescene.io.kitti import write_labels

    gt_dir = KITTI_ROOT / "training" / "label_2"
    frames = ("000002", "000010", "001545")
    runs = {"s1": 0.0, "s2": 3.0}  # the second run places every car 3 m too far: no 3D match at IoU 0.7
    for name, dz in runs.items():
        (tmp_path / name / "full").mkdir(parents=True)
        for f in frames:
            labels = read_labels(gt_dir / f"{f}.txt")
            for o in labels.objects:
                o.score = 1.0
                o.location = np.asarray(o.location, float) + [0.0, 0.0, dz]
            write_labels(tmp_path / name / "full" / f"{f}.txt", labels.objects)
    out = tmp_path / "k.json"
    dirs = [tmp_path / n / "full" for n in runs]
    r = _cli("kitti-eval", gt_dir, *dirs, "--json", out, "--draws", "200")
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    # the two runs share a directory name, so they are named by their paths
    assert list(data["runs"]) == [str(d) for d in dirs] and data["mean"]["runs"] == 2
    exact, far = (data["runs"][str(d)]["car"]["3d"]["moderate"] for d in dirs)
    # three frames' cars at 40 recall points: exact boxes score what their 2D boxes score
    assert far == 0.0 and exact > 0.0 and exact == data["runs"][str(dirs[0])]["car"]["2d"]["moderate"]
    assert data["mean"]["car"]["3d"]["moderate"] == pytest.approx(exact / 2)
    assert data["mean"]["car"]["2d"] == data["runs"][str(dirs[0])]["car"]["2d"]  # the same 2D boxes
    lo, hi = data["kitti_interval"]["car"]["3d"]
    assert lo == 0.0 and hi >= data["mean"]["car"]["3d"]["moderate"] and data["kitti_interval"]["runs"] == 2
    assert "mean of 2" in r.output and "takes one of the 2 runs" in r.output
    line = _one_line_error(_cli("kitti-eval", gt_dir, dirs[0], dirs[0]))
    assert "given twice" in line


def test_cli_kitti_eval_warns_of_unscored_files_and_another_splits_predictions(tmp_path):
    import json

    from wirescene.eval.predict import CONFIG_FILE
    from wirescene.io.kitti import write_labels

    gt_dir = KITTI_ROOT / "training" / "label_2"
    pred = tmp_path / "pred"
    pred.mkdir()
    for f in ("000002", "424242"):  # 424242: no such labelled frame
        labels = read_labels(gt_dir / "000002.txt")
        for o in labels.objects:
            o.score = 1.0
        write_labels(pred / f"{f}.txt", labels.objects)
    r = _cli("kitti-eval", gt_dir, pred, "--draws", "0")
    assert r.exit_code == 0, r.output
    assert (f"{pred}: 1 prediction files have no label file in {gt_dir} and are not scored (e.g. 424242.txt)"
            in r.stderr)
    r = _cli("kitti-eval", gt_dir, pred, "--frames", "000002", "--draws", "0")  # frames chosen: the rest is expected
    assert r.exit_code == 0 and "not scored" not in r.stderr
    (pred / CONFIG_FILE).write_text(json.dumps({"dataset": str(tmp_path / "kitti" / "testing")}))
    r = _cli("kitti-eval", gt_dir, pred, "--frames", "000002", "--draws", "0")
    assert r.exit_code == 0, r.output
    assert f"predicted from the images of {tmp_path / 'kitti' / 'testing'}, scored against the labels" in r.stderr
    (pred / CONFIG_FILE).write_text(json.dumps({"dataset": str(tmp_path / "moved" / "training")}))
    assert "predicted from" not in _cli("kitti-eval", gt_dir, pred, "--frames", "000002", "--draws", "0").stderr
