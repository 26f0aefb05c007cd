"""Part detector: descriptors, numpy forest, retraining, response maps, shipped model."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.parts import features as feat
from wirescene.parts.detector import BACKGROUND, N_CLASSES, N_PARTS, PartDetector, load_default, response_maps


def _pattern(shape=(80, 100), seed=0):
    rng = np.random.default_rng(seed)
    e = np.zeros(shape, np.float32)
    e[20, 10:60] = 1
    e[10:50, 40] = 1
    e[rng.integers(0, shape[0], 40), rng.integers(0, shape[1], 40)] = 1
    return e


# ------------------------------------------------------------------ features

def test_feature_shapes():
    e = _pattern()
    pts = np.array([[10, 10], [40, 50], [79, 99]])
    for kind in ("sc", "hog"):
        x = feat.extract(e, kind, points=pts)
        assert x.shape == (3, feat.feature_dim(kind)) and x.dtype == np.float32
        assert np.isfinite(x).all()
    patches = feat.extract_patches(e, pts)
    assert patches.shape == (3, feat.PATCH, feat.PATCH)
    assert feat.extract(e, "sc").shape == e.shape + (feat.feature_dim("sc"),)
    with pytest.raises(ValueError):
        feat.extract(e, "nope")
    img = (np.random.default_rng(0).random((60, 90, 3)) * 255).astype(np.uint8)
    for kind in feat.KINDS:
        x = feat.describe(feat.canonical_inputs(img, 1.3, kind), pts, kind)
        assert x.shape == (3, feat.feature_dim(kind)) and x.dtype == np.float32 and np.isfinite(x).all()


def test_ghog_sees_orientation_and_is_translation_equivariant():
    g = np.zeros((80, 100), np.float32)
    g[:, 50:] = 1.0  # vertical step edge at column 49.5
    cells = feat.orientation_cells(g)
    # gradient along x -> orientation 0 -> bins 0 and 8 (the vote is split around 0)
    assert cells[40, 50, [0, 8]].sum() > 0.95 * cells[40, 50].sum() > 0
    shifted = np.zeros((100, 130), np.float32)
    shifted[13:93, 21:121] = g
    shifted[13:93, 121:] = 1.0
    pts = np.array([[30, 40], [40, 50], [50, 60]])
    d0 = feat.ghog_at(cells, pts)
    d1 = feat.ghog_at(feat.orientation_cells(shifted), pts + [13, 21])
    assert_close(d0, d1, atol=1e-5)
    # a blank patch: no structure, zero mass
    assert np.all(feat.ghog_at(cells, np.array([[40, 10]])) == 0)


def test_orientation_votes_split_linearly_between_the_two_nearest_bins():
    yy, xx = np.mgrid[:20, :30].astype(np.float64)
    for theta in (0.3, 2.0, 3.1):
        g = (xx * np.cos(theta) + yy * np.sin(theta)).astype(np.float32)  # gradient (cos, sin): magnitude 1
        votes = feat._orientation_votes(g)[5:15, 5:25]
        pos = np.mod(theta, np.pi) * feat.GHOG_BINS / np.pi - 0.5
        b0, frac = int(np.floor(pos)) % feat.GHOG_BINS, pos - np.floor(pos)
        expected = np.zeros(feat.GHOG_BINS)
        expected[b0] += 1 - frac
        expected[(b0 + 1) % feat.GHOG_BINS] += frac
        assert_close(votes, np.broadcast_to(expected, votes.shape), atol=1e-4)


def test_dense_sc_equals_sparse():
    e = _pattern()
    d = feat.extract(e, "sc")
    pts = np.array([[0, 0], [20, 40], [79, 99], [33, 7]])
    assert_close(d[pts[:, 0], pts[:, 1]], feat.extract(e, "sc", points=pts), atol=1e-5)


def test_shape_context_translation_equivariance():
    e = _pattern()
    shifted = np.zeros((100, 130), np.float32)
    shifted[13:93, 21:121] = e
    d0, d1 = feat.extract(e, "sc"), feat.extract(shifted, "sc")
    # away from the borders (patch radius) the dense map is translated as well
    r = feat.RADIUS
    assert_close(d1[13 + r:93 - r, 21 + r:121 - r], d0[r:-r, r:-r], atol=1e-5)
    # and a histogram actually sees the lines (not all-empty)
    assert d0[20, 40, -1] > 2.0


def test_canonical_edges_preserve_line_length():
    e = np.zeros((200, 200), np.float32)
    e[100, 20:180] = 1  # 160 px line
    for z in (0.5, 0.8, 1.6):
        assert abs(feat.canonical_edges(e, z).sum() - 160 * z) < 0.1 * 160 * z


# ------------------------------------------------------------------ numpy forest

@pytest.fixture(scope="module")
def sk_forest():
    from sklearn.ensemble import RandomForestClassifier

    rng = np.random.default_rng(0)
    X = rng.normal(size=(3000, 12)).astype(np.float32)
    y = (np.abs(X[:, :3]).sum(1) * 6).astype(int) % N_CLASSES
    y[:N_CLASSES] = np.arange(N_CLASSES)
    return RandomForestClassifier(n_estimators=7, max_depth=9, random_state=0).fit(X, y)


def test_numpy_forest_equals_sklearn(sk_forest, tmp_path):
    X = np.random.default_rng(1).normal(size=(2000, 12)).astype(np.float32)
    exact = PartDetector.from_sklearn(sk_forest, kind="sc", quantize=False)
    assert_close(exact.predict_proba(X), sk_forest.predict_proba(X), atol=1e-12)
    q = PartDetector.load(PartDetector.from_sklearn(sk_forest, kind="sc").save(tmp_path / "m.npz"))
    p = q.predict_proba(X)
    assert_close(p, sk_forest.predict_proba(X), atol=0.01)
    assert np.mean(p.argmax(1) == sk_forest.predict(X)) > 0.99


def test_numpy_forest_at_its_thresholds_and_in_any_chunks(sk_forest):
    """Inputs at the split thresholds (rounded to float32, the dtype sklearn compares in)
    go the way sklearn sends them through the renumbered traversal tables; the chunking
    changes nothing."""
    rng = np.random.default_rng(2)
    X = rng.normal(size=(1500, 12)).astype(np.float32)
    for est in sk_forest.estimators_:  # every inner node's threshold, on its own feature
        t = est.tree_
        inner = np.flatnonzero(t.children_left >= 0)
        rows = rng.integers(0, len(X), len(inner))
        X[rows, t.feature[inner]] = t.threshold[inner].astype(np.float32)
    exact = PartDetector.from_sklearn(sk_forest, kind="sc", quantize=False)
    p = exact.predict_proba(X)
    assert_close(p, sk_forest.predict_proba(X), atol=1e-12)
    assert np.array_equal(exact.predict_proba(X, chunk=7), p)


# ------------------------------------------------------------------ tiny retraining

@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from wirescene.training.parts import train_part_detector

    path = tmp_path_factory.mktemp("parts") / "tiny.npz"
    det, rep = train_part_detector(path, seed=3, n_views=8, n_trees=3, max_depth=10, kind="sc", synth_scenes=0,
                                   class_weight=None, cars=["acura-nsx-sz", "car1-stock1"])
    return path, rep


def test_tiny_retraining_loads_and_learns(tiny):
    path, rep = tiny
    det = PartDetector.load(path)
    data = rep["_data"]
    assert len(data) > 500 and (data.y < N_PARTS).sum() > 200 and (data.y == BACKGROUND).sum() > 200
    acc = np.mean(det.predict(data.X["sc"]) == data.y)
    assert acc > 0.5  # chance (uniform) is 1/37, majority class below 0.5
    assert det.meta["n_trees"] == "3"


def test_a_model_smoothed_beyond_its_box_is_refused_naming_the_file(tiny, tmp_path):
    """The fit's Gaussian kernel of a smoothing of 1e300 box heights cannot be made (a traceback
    in every fit): the file is refused as it is read, as `train parts --smooth` refuses it."""
    from wirescene.core.errors import InputError

    det = PartDetector.load(tiny[0])
    for smooth in (1e300, float("nan"), -0.1):
        det.smooth = smooth
        det.save(tmp_path / "smooth.npz")
        with pytest.raises(InputError, match=r"smooth\.npz: part model's smoothing .* is not within 0 to 1 box heights"):
            PartDetector.load(tmp_path / "smooth.npz")
    det.smooth = 1.0
    det.save(tmp_path / "smooth.npz")
    assert PartDetector.load(tmp_path / "smooth.npz").smooth == 1.0


def test_training_is_deterministic(tiny):
    from wirescene.training.parts import make_patch_data

    a = make_patch_data(seed=3, n_azimuth=2, cars=["acura-nsx-sz"], n_real_bg=60)
    b = make_patch_data(seed=3, n_azimuth=2, cars=["acura-nsx-sz"], n_real_bg=60)
    assert np.array_equal(a.y, b.y) and np.array_equal(a.X["sc"], b.X["sc"])


@pytest.fixture(scope="module")
def kitti_frame():
    from wirescene.io.kitti import KittiDataset


    ds = KittiDataset(KITTI_ROOT)
    fid = "000010"
    return ds.image(fid), np.array([o.box for o in ds.labels(fid).of_type("Car")])


def _check_lookup_matches_box_descriptors(det, img, box):
    from wirescene.parts.detector import box_descriptors

    R = response_maps(img, box, detector=det, scales=(1.0,), stride=3.0)
    b = R.boxes[0]
    guv = b.grid_uv()
    ij = [(3, 4), (10, 20), (b.probs.shape[1] // 2, b.probs.shape[2] // 2)]
    uv = np.array([guv[i, j] for i, j in ij])
    # the training path (box_descriptors) describes a point exactly as the dense maps do
    p = det.predict_proba(box_descriptors(img, box[0], uv, det.kind, scale=1.0))
    for k, (i, j) in enumerate(ij):
        assert_close(b.probs[0, i, j], p[k], atol=2e-3)
        pc = np.clip(p[k], R.eps, 1)
        assert_close(R.log_ratio(np.broadcast_to(guv[i, j], (N_PARTS, 2)), 0),
                     np.log(pc[:N_PARTS] / pc[BACKGROUND]), atol=2e-2)


def test_response_lookup_matches_patch_classification(tiny, kitti_frame):
    det = PartDetector.load(tiny[0])
    img, boxes = kitti_frame
    box = boxes[1:2]
    _check_lookup_matches_box_descriptors(det, img, box)
    # and the patch path of the edge descriptors agrees with the dense shape context
    from wirescene.parts.detector import box_crop

    R = response_maps(img, box, detector=det, scales=(1.0,), stride=3.0)
    b = R.boxes[0]
    _, (cx0, cy0, cx1, cy1), (z,) = box_crop(box[0], img.shape[1::-1], (1.0,))
    cmap = feat.canonical_edges(feat.image_edges(img[cy0:cy1, cx0:cx1]), z)
    i, j = 10, 20
    u, v = b.grid_uv()[i, j]
    rc = np.rint(feat.to_canonical(np.array([u - cx0, v - cy0]), z)).astype(int)
    assert_close(b.probs[0, i, j], det.classify_patches(feat.extract_patches(cmap, rc[None]))[0], atol=2e-3)


# ------------------------------------------------------------------ synthetic shaded training

@pytest.fixture(scope="module")
def tiny_synth():
    from sklearn.ensemble import RandomForestClassifier

    from wirescene.synth.generate import generate_scene
    from wirescene.training.parts import make_synth_patch_data

    data = make_synth_patch_data(n_scenes=3, seed=1000, kinds=("ghog",))
    rf = RandomForestClassifier(n_estimators=8, max_depth=14, random_state=0, class_weight="balanced",
                                min_samples_leaf=2).fit(data.X["ghog"], data.y)
    scenes = [generate_scene(1000, i) for i in range(3)]
    return PartDetector.from_sklearn(rf, kind="ghog"), data, scenes


def test_synth_patch_data_deterministic_and_seed_guard(tiny_synth):
    from wirescene.training.parts import make_synth_patch_data

    _, data, _ = tiny_synth
    assert (data.y < N_PARTS).sum() > 200 and (data.y == BACKGROUND).sum() > 200
    again = make_synth_patch_data(n_scenes=1, seed=1000, kinds=("ghog",))
    n = len(again.y)
    assert np.array_equal(again.y, data.y[:n]) and np.array_equal(again.X["ghog"], data.X["ghog"][:n])
    with pytest.raises(ValueError):
        make_synth_patch_data(n_scenes=1, seed=1, kinds=("ghog",))  # evaluation stream


def test_synth_trained_detector_localises_its_training_vertices(tiny_synth, kitti_frame):
    from wirescene.training.parts import localisation, scene_frames

    det, _, scenes = tiny_synth
    r = localisation(det, scene_frames(scenes, min_box_h=30, clean=False))
    assert r["n_vertices"] > 50
    # far better than chance (a random grid location: ~0.04 within 10%, rank 0.5)
    assert r["hits"][0.1] > max(0.4, 5 * r["chance"][0.1])
    assert r["rank"] > 0.85
    # grey-image kind: dense maps == the training path
    img, boxes = kitti_frame
    _check_lookup_matches_box_descriptors(det, img, boxes[1:2])


def test_log_ratio_vectorised_and_outside(tiny, kitti_frame):
    det = PartDetector.load(tiny[0])
    img, boxes = kitti_frame
    R = response_maps(img, boxes[:2], detector=det)
    rng = np.random.default_rng(0)
    uv = rng.uniform(boxes[0, :2], boxes[0, 2:], size=(5, 7, N_PARTS, 2))
    bi = np.zeros((5, 7), int)
    bi[:, 3:] = 1
    out = R.log_ratio(uv, bi)
    assert out.shape == (5, 7, N_PARTS) and out.dtype == np.float32
    assert_close(out[:, :3], R.log_ratio(uv[:, :3], 0))
    far = np.full((2, N_PARTS, 2), -1e4)
    assert np.all(R.log_ratio(far, 0) == R.floor)
    assert np.all(R.log_ratio(far, 0, outside=-1.5) == -1.5)
    assert np.all(np.abs(out) <= -R.floor + 1e-5)


def test_log_ratio_bilinear(tiny, kitti_frame):
    det = PartDetector.load(tiny[0])
    img, boxes = kitti_frame
    R = response_maps(img, boxes[:1], detector=det)
    b = R.boxes[0]
    gh, gw = b.log_ratio.shape[:2]
    grid = b.grid_uv()
    # at grid points both lookups are the map itself
    uv = np.broadcast_to(grid[gh // 2, gw // 2], (N_PARTS, 2))
    assert_close(R.log_ratio(uv, 0, bilinear=True), b.log_ratio[gh // 2, gw // 2])
    # a quarter of the way to the right neighbour: the linear mix of the two
    uv = uv + [0.25 * b.stride, 0.0]
    want = 0.75 * b.log_ratio[gh // 2, gw // 2] + 0.25 * b.log_ratio[gh // 2, gw // 2 + 1]
    assert_close(R.log_ratio(uv, 0, bilinear=True), want)
    # continuous where nearest-point lookup jumps, and the floor far outside
    far = np.full((N_PARTS, 2), -1e4)
    assert np.all(R.log_ratio(far, 0, bilinear=True) == R.floor)


def test_log_ratio_reads_each_corner_like_a_four_index_gather():
    """The lookup gathers by flat index (the rows' and columns' offsets shared by the corners
    on one grid line): the same values, to the bit, as indexing the stacked maps
    ``lr[b, i, j, part]`` at each corner, inside the grids, on their last lines, just past
    them (past the largest grid, in the last box of the stack, too), far away and at NaN,
    nearest and bilinear."""
    from wirescene.parts.detector import BoxResponses, PartResponses

    rng = np.random.default_rng(3)
    boxes = [BoxResponses(np.zeros(4), np.zeros(4), np.array(origin), stride, (1.0,), np.zeros(0),
                          rng.normal(size=(gh, gw, N_PARTS)).astype(np.float32))
             for origin, stride, gh, gw in (((10.0, 20.0), 2.5, 7, 11), ((-30.0, 5.0), 4.0, 12, 5),
                                            ((300.0, 40.0), 1.0, 3, 3),
                                            ((50.0, -10.0), 2.0, 14, 13))]  # the last box: the stack's largest grid
    R = PartResponses(boxes, eps=1e-3)
    b = rng.integers(0, len(boxes), (200, 3))
    b[-20:] = len(boxes) - 1  # the lines past the last grid of the stack: the padding's end, not the next box's start
    origin = np.array([boxes[k].origin for k in b.ravel()]).reshape(200, 3, 1, 2)
    stride = np.array([boxes[k].stride for k in b.ravel()]).reshape(200, 3, 1, 1)
    size = np.array([boxes[k].log_ratio.shape[1::-1] for k in b.ravel()]).reshape(200, 3, 1, 2)
    cell = rng.uniform(-1.5, 1.0, (200, 3, N_PARTS, 2)) * (size + 1)
    cell[:50] = np.round(cell[:50])  # on the grid lines, the last ones and those just past them included
    uv = origin + stride * cell
    uv[::17, :, 4] = np.nan
    uv[::13, :, 5] = -1e9
    uv[::11, :, 6] = 1e9
    uv[::19, :, 7] = np.inf
    uv[::23, :, 8] = -np.inf

    def reference(bilinear, outside=None):  # the former lookup
        lr, shape, org, st = R._stacked()
        bb = b[..., None]
        fj, fi = (uv[..., 0] - org[bb, 0]) / st[bb], (uv[..., 1] - org[bb, 1]) / st[bb]
        h, w, part = shape[bb, 0], shape[bb, 1], np.arange(N_PARTS)
        value = np.float32(R.floor if outside is None else outside)

        def at(i, j):
            ok = (i >= 0) & (j >= 0) & (i < h) & (j < w)
            return np.where(ok, lr[bb, np.where(ok, i, 0).astype(np.int64), np.where(ok, j, 0).astype(np.int64), part],
                            value)

        if not bilinear:
            return at(np.rint(fi), np.rint(fj)).astype(np.float32)
        i0, j0 = np.floor(fi), np.floor(fj)
        ti, tj = fi - i0, fj - j0
        top = (1 - tj) * at(i0, j0) + tj * at(i0, j0 + 1)
        bottom = (1 - tj) * at(i0 + 1, j0) + tj * at(i0 + 1, j0 + 1)
        return ((1 - ti) * top + ti * bottom).astype(np.float32)

    with np.errstate(invalid="ignore"):
        for bilinear in (False, True):
            for outside in (None, -1.5):
                got = R.log_ratio(uv, b, bilinear=bilinear, outside=outside)
                want = reference(bilinear, outside)
                assert got.dtype == np.float32 and got.tobytes() == want.tobytes()
                if not bilinear:  # a NaN pixel is off the grid (bilinear weights of NaN give NaN)
                    assert np.all(got[::17, :, 4] == np.float32(R.floor if outside is None else outside))


# ------------------------------------------------------------------ shipped model

def test_committed_model_on_real_kitti_box(kitti_frame):
    det = load_default()
    assert det.n_trees >= 10 and det.kind in feat.KINDS
    assert len(det.meta.get("real_frames", "").split(",")) >= 30  # trained on the labelled real frames
    assert det.calib_scale is not None and (det.calib_scale > 0).all()
    img, boxes = kitti_frame
    R = response_maps(img, boxes[1:2], detector=det)
    c = (boxes[1, :2] + boxes[1, 2:]) / 2
    lr = R.log_ratio(np.broadcast_to(c, (N_PARTS, 2)), 0)
    assert lr.shape == (N_PARTS,) and np.isfinite(lr).all()
    assert R.boxes[0].probs.shape[-1] == N_CLASSES


def test_response_map_smoothing(tiny, kitti_frame):
    from scipy.ndimage import gaussian_filter

    det = PartDetector.load(tiny[0])
    img, boxes = kitti_frame
    R0 = response_maps(img, boxes[1:2], detector=det, stride=2.0, smooth=0.0)
    R1 = response_maps(img, boxes[1:2], detector=det, stride=2.0, smooth=0.05)
    sig = 0.05 * (boxes[1, 3] - boxes[1, 1]) / 2.0
    assert_close(R1.boxes[0].log_ratio, gaussian_filter(R0.boxes[0].log_ratio, (sig, sig, 0), mode="nearest"),
                 atol=1e-5)
    assert R1.boxes[0].log_ratio.std() < R0.boxes[0].log_ratio.std()


def test_boxes_far_past_the_image_or_flatter_than_a_car_stay_cheap(tiny, kitti_frame, monkeypatch):
    import wirescene.parts.detector as detector

    det = PartDetector.load(tiny[0])
    img, boxes = kitti_frame
    H, W = img.shape[:2]
    near = np.array([-800.0, 100.0, 600.0, 900.0])  # a near car's box from an amodal detector
    kept = response_maps(img, near, detector=det, scales=(1.0,), smooth=0.0).boxes[0]
    gh, gw = kept.log_ratio.shape[:2]
    uv = kept.grid_uv()
    assert uv[..., 0].min() >= -0.25 * W and uv[..., 0].max() <= 1.25 * W and uv[..., 1].max() <= 1.25 * H
    own = [response_maps(img, box, detector=det, scales=(1.0,)).boxes[0].log_ratio for box in boxes]
    monkeypatch.setattr(detector, "GRID_MARGIN", 1e6)  # no limit
    whole = response_maps(img, near, detector=det, scales=(1.0,), smooth=0.0).boxes[0]
    assert whole.log_ratio.shape[0] * whole.log_ratio.shape[1] > 2 * gh * gw
    # the points kept are the whole grid's, scored alike
    i0, j0 = np.rint((kept.origin[::-1] - whole.origin[::-1]) / kept.stride).astype(int)
    assert_close(whole.grid_uv()[i0:i0 + gh, j0:j0 + gw], uv)
    assert_close(whole.log_ratio[i0:i0 + gh, j0:j0 + gw], kept.log_ratio)
    # the boxes of the image's own cars are scored as without the limit
    for box, lr in zip(boxes, own):
        assert_close(response_maps(img, box, detector=det, scales=(1.0,)).boxes[0].log_ratio, lr, atol=0, rtol=0)
    monkeypatch.undo()
    # a sliver one pixel high across the image would need a crop of 40 M canonical pixels: no evidence
    sliver = response_maps(img, [0.0, 200.0, W - 1.0, 201.0], detector=det).boxes[0]
    assert (sliver.log_ratio == 0).all() and sliver.log_ratio.shape[1] <= 1.25 * W


def test_flipped_evidence_is_mirror_equivariant(kitti_frame):
    from wirescene.core.wireframe import MIRROR

    det = load_default()
    img, _ = kitti_frame
    W = img.shape[1]
    # Width 100 and height 64 (stride 2): the grid of the mirrored box falls on the mirrored grid points.
    box = np.array([[500.0, 150.0, 600.0, 214.0]])
    mirrored = np.ascontiguousarray(img[:, ::-1])
    mbox = np.array([[W - 1 - 600.0, 150.0, W - 1 - 500.0, 214.0]])

    maps = {flip: response_maps(img, box, detector=det, flip=flip).boxes[0].log_ratio for flip in (False, True)}

    def agreement(flip):
        b = response_maps(mirrored, mbox, detector=det, flip=flip).boxes[0].log_ratio[:, ::-1][..., MIRROR]
        return np.corrcoef(maps[flip].ravel(), b.ravel())[0, 1]

    # The forest alone is not mirror-symmetric; averaged with the mirror image's reading it nearly is
    # (the rest: the crops' pixel rounding). Swapping no parts, or the wrong ones, breaks the symmetry.
    plain, flipped = agreement(False), agreement(True)
    assert flipped > 0.98 and flipped > plain + 0.02
    assert maps[True].shape == maps[False].shape


# ------------------------------------------------------------------ real training data (issue 18)

def test_kitti_car_wireframes_fit_label_boxes():
    from wirescene.core.boxes import iou_2d
    from wirescene.core.wireframe import SIDE
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.parts_real import kitti_car_wireframes

    ds = KittiDataset(KITTI_ROOT)
    n = 0
    for fid in ds.frame_ids():
        img = ds.image(fid)
        cars = kitti_car_wireframes(ds.labels(fid), ds.camera(fid), image_size=img.shape[1::-1])
        for c in cars:
            if c.occluded or c.truncated > 0:
                continue
            n += 1
            bb = np.r_[c.uv.min(0), c.uv.max(0)]
            assert iou_2d(bb, c.box) > 0.5  # the scaled mean wireframe covers the labelled box
            # a car is seen from one side: never every vertex of both sides visible
            assert 6 <= c.visible.sum() < 30
            assert not (c.visible[SIDE > 0].all() and c.visible[SIDE < 0].all())
    assert n >= 3


def test_mirror_cars_swaps_sides_and_is_an_involution():
    from wirescene.core.wireframe import MIRROR
    from wirescene.training.parts_real import mirror_cars

    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (30, 50, 3)).astype(np.uint8)
    box = np.array([[5.0, 3.0, 20.0, 25.0]])
    uv = rng.uniform(5, 25, (1, N_PARTS, 2))
    vis = rng.random((1, N_PARTS)) < 0.5
    im2, b2, uv2, vis2 = mirror_cars(img, box, uv, vis)
    assert np.array_equal(im2[:, 49 - 7], img[:, 7]) and np.allclose(b2, [[29, 3, 44, 25]])
    j = 4
    assert np.allclose(uv2[0, MIRROR[j]], [49 - uv[0, j, 0], uv[0, j, 1]]) and vis2[0, MIRROR[j]] == vis[0, j]
    im3, b3, uv3, vis3 = mirror_cars(im2, b2, uv2, vis2)
    assert np.array_equal(im3, img) and np.allclose(b3, box) and np.allclose(uv3, uv) and np.array_equal(vis3, vis)


def test_calibrate_recovers_overconfident_scores():
    from wirescene.training.parts import calibrate

    rng = np.random.default_rng(0)
    n = 4000
    y = np.where(rng.random(n) < 0.2, 0, BACKGROUND)
    # true log likelihood ratio of "vertex 0": +-1.5 (unit Gaussians at +-1.5, LLR = 3 x)
    x = rng.normal(np.where(y == 0, 1.5, -1.5), 1.0)
    r = np.zeros((n, N_PARTS))
    r[:, 0] = 2.0 * 3.0 * x  # twice too confident
    scale, offset = calibrate(r, y)
    assert abs(scale[0] - 0.5) < 0.08 and abs(offset[0]) < 0.3
    assert scale[1] == 1.0 and offset[1] == 0.0  # no positives: identity


@pytest.fixture(scope="module")
def tiny_real(tmp_path_factory):
    from wirescene.training.parts import train_part_detector

    path = tmp_path_factory.mktemp("parts") / "tiny_real.npz"
    det, rep = train_part_detector(path, seed=1, n_trees=3, max_depth=8, kind="ghog_ms", synth_scenes=0,
                                   kitti_root=KITTI_ROOT, frames=["000002", "000010"], position=True,
                                   calibrate_real=True)
    return path, rep


def test_tiny_real_retraining_reproduces_the_pipeline(tiny_real, kitti_frame):
    path, rep = tiny_real
    det = PartDetector.load(path)
    data = rep["_data"]
    assert (data.y < N_PARTS).sum() > 300 and (data.y == BACKGROUND).sum() > 300
    assert det.position and det.kind == "ghog_ms" and det.n_features == feat.feature_dim("ghog_ms") + 2
    assert det.calib_scale.shape == (N_PARTS,) and (det.calib_scale > 0).all()
    assert det.meta["real_frames"] == "000002,000010"
    assert "logloss_calibrated" in rep["calibration"]
    # response maps use the position feature and the calibration exactly as training describes
    from wirescene.parts.detector import box_descriptors

    img, boxes = kitti_frame
    box = boxes[1:2]
    R = response_maps(img, box, detector=det, scales=(1.0,), stride=3.0)
    b = R.boxes[0]
    guv = b.grid_uv()
    ij = [(3, 4), (b.probs.shape[1] // 2, b.probs.shape[2] // 2)]
    uv = np.array([guv[i, j] for i, j in ij])
    p = det.predict_proba(box_descriptors(img, box[0], uv, det.kind, scale=1.0, position=True))
    for k, (i, j) in enumerate(ij):
        assert_close(b.probs[0, i, j], p[k], atol=2e-3)
        assert_close(R.log_ratio(np.broadcast_to(guv[i, j], (N_PARTS, 2)), 0), det.log_ratio_of(p[k]), atol=2e-2)


def test_held_out_calibration_of_a_fold_without_cars_measures_the_others(tmp_path):
    """A fold without cars has no part to score: its held-out log loss was NaN (numpy's "Mean of empty slice"), and
    so the report's (``train parts --report``'s JSON, train all's manifest); it is measured on the folds with parts."""
    import json

    from conftest import kitti_copy
    from wirescene.training.parts import train_part_detector

    root = kitti_copy(tmp_path / "kitti", ["000002", "000010", "001545"])
    (root / "training" / "label_2" / "001545.txt").write_text(
        "DontCare -1 -1 -10 1000 160 1040 190 -1 -1 -1 -1000 -1000 -1000 -10\n")
    folds = {"000002": 0, "000010": 1, "001545": 2}
    said = []
    det, rep = train_part_detector(tmp_path / "p.npz", seed=1, n_trees=3, max_depth=8, kind="ghog_ms", synth_scenes=0,
                                   kitti_root=root, frames=list(folds), position=True, calibrate_real=True,
                                   calibration_folds=folds, progress=said.append)
    cal = rep["calibration"]
    json.dumps(cal, allow_nan=False)  # was "Out of range float values are not JSON compliant"
    assert np.isfinite([cal["logloss_raw"], cal["logloss_calibrated"]]).all() and cal["logloss_raw"] > 0
    assert any("calibrated over 2 of 3 folds" in line for line in said), said
    assert (det.calib_scale > 0).all() and np.isfinite(det.calib_offset).all()


def test_train_parts_deals_its_calibration_folds_as_train_all_does(monkeypatch):
    """train parts held out its calibration by the shared frames' fixed folds, other frames dealt round the folds in
    turn, where train all deals the frames by drive, balanced by their cars: a subset's calibration differed. Now
    both deal them one way (the 72 shared frames' folds either way)."""
    import wirescene.training.parts as parts
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.kitti_detector import calibration_folds

    class Stop(Exception):
        pass

    seen = []

    def held_out(*a, folds, **kw):
        seen.append(dict(folds))
        raise Stop

    monkeypatch.setattr(parts, "heldout_calibration", held_out)
    frames = ["000002", "000010", "001545"]
    with pytest.raises(Stop):
        parts.train_part_detector(None, seed=1, n_trees=2, max_depth=4, kind="ghog_ms", synth_scenes=0,
                                  kitti_root=KITTI_ROOT, frames=frames, position=True, calibrate_real=True)
    assert seen == [calibration_folds(KittiDataset(KITTI_ROOT), frames)]


def test_train_parts_of_two_drives_with_a_bad_label_file_says_so_not_one_drive(tmp_path):
    """The folds' dealing caught every InputError as "frames of one drive": a malformed label file of a frame (read
    first by the dealing where synthetic scenes are added) was refused as frames falling in one fold."""
    import shutil

    import wirescene.training.parts as parts
    from wirescene.core.errors import InputError

    root = tmp_path / "kitti"
    for folder in ("image_2", "label_2", "calib"):
        (root / "training" / folder).mkdir(parents=True)
        for f in ("000002", "000010"):  # two drives
            name = f"{f}.png" if folder == "image_2" else f"{f}.txt"
            shutil.copy(KITTI_ROOT / "training" / folder / name, root / "training" / folder / name)
    (root / "training" / "label_2" / "000002.txt").write_text("Car 0 0 garbage\n")
    with pytest.raises(InputError, match="000002.txt: line 1: expected 15 columns"):
        parts.train_part_detector(None, seed=1, n_trees=2, max_depth=4, kind="ghog_ms", synth_scenes=1,
                                  kitti_root=root, frames=["000002", "000010"], calibrate_real=True)


def test_train_part_detector_refuses_a_split_without_labels_first(tmp_path, monkeypatch):
    """A root without label_2/ was refused for its frames' one fold (the held-out calibration's reason, not the real
    one) or, without the calibration, after its synthetic scenes (some 1.3 s each) were made."""
    import wirescene.training.parts as parts
    from conftest import kitti_copy
    from wirescene.core.errors import InputError

    def no_scenes(*a, **kw):
        raise AssertionError("synthetic scenes made")

    monkeypatch.setattr(parts, "make_synth_patch_data", no_scenes)
    split = kitti_copy(tmp_path, ["000010"], subdirs=("image_2", "calib"), split="testing") / "testing"
    for calibrate, scenes in ((True, 0), (True, 1), (False, 1)):
        with pytest.raises(InputError) as info:
            parts.train_part_detector(None, n_trees=2, max_depth=4, kind="ghog_ms", synth_scenes=scenes,
                                      kitti_root=split, calibrate_real=calibrate)
        assert str(info.value) == f"{split}: training needs label_2/ ground truth", (calibrate, scenes)


def test_kitti_eval_frames_reads_the_frames_asked_for():
    from wirescene.training.parts import kitti_eval_frames

    every = list(kitti_eval_frames(KITTI_ROOT, clean=False, min_box_h=0.0))
    one = list(kitti_eval_frames(KITTI_ROOT, clean=False, min_box_h=0.0, frames=["001545"]))
    assert len(every) == 3 and len(one) == 1
    image, cars = one[0]
    assert_close(np.array([c[0] for c in cars]), np.array([c[0] for c in every[2][1]]))
    assert image.shape == every[2][0].shape


# ------------------------------------------------------------------ refitted label shapes (self-training)

def test_refit_label_shapes_keep_the_box_and_the_mean_under_a_strong_prior():
    from wirescene.core.errors import ShapeError
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.parts_real import kitti_car_wireframes, refit_label_shapes, scaled_mean_shape

    ds = KittiDataset(KITTI_ROOT)
    fid = "000010"
    image, labels, camera = ds.image(fid), ds.labels(fid), ds.camera(fid)
    cars = labels.of_type("Car")
    means = np.stack([scaled_mean_shape(o.dims) for o in cars])
    kw = dict(n_draws=60, rounds=1, round_draws=20)
    # an overwhelming prior keeps the mean itself; the evidence alone moves it, inside the label's box
    assert_close(refit_label_shapes(image, labels, camera, load_default(), shape_prior=1e6, **kw), means)
    free = refit_label_shapes(image, labels, camera, load_default(), shape_prior=0.0, **kw)
    assert free.shape == (len(cars), 36, 3) and not np.allclose(free, means)
    assert_close(np.ptp(free, axis=1), np.array([[o.dims[2], o.dims[0], o.dims[1]] for o in cars]), atol=1e-9)
    # the labelled wireframes take the given shapes, placed at the labels' poses
    given = kitti_car_wireframes(labels, camera, shapes=free)
    default = kitti_car_wireframes(labels, camera)
    assert_close(np.stack([c.X for c in kitti_car_wireframes(labels, camera, shapes=means)]),
                 np.stack([c.X for c in default]), atol=1e-9)
    assert not np.allclose(np.stack([c.uv for c in given]), np.stack([c.uv for c in default]))
    with pytest.raises(ShapeError):
        kitti_car_wireframes(labels, camera, shapes=free[1:])


def test_label_shapes_file_round_trip_and_refusal(tmp_path):
    from wirescene.core.errors import InputError
    from wirescene.training.parts_real import load_label_shapes, save_label_shapes

    shapes = {"000010": np.random.default_rng(0).normal(size=(2, 36, 3))}
    save_label_shapes(tmp_path / "s.npz", shapes)
    back = load_label_shapes(tmp_path / "s.npz")
    assert list(back) == ["000010"]
    assert_close(back["000010"], shapes["000010"])
    np.savez(tmp_path / "bad.npz", x=np.zeros(3))
    with pytest.raises(InputError, match="bad.npz"):
        load_label_shapes(tmp_path / "bad.npz")


def test_real_patches_follow_the_label_shapes():
    from wirescene.core.errors import InputError
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.parts_real import make_real_patch_data, scaled_mean_shape

    ds = KittiDataset(KITTI_ROOT)
    means = np.stack([scaled_mean_shape(o.dims) for o in ds.labels("000010").of_type("Car")])
    kw = dict(kinds=("ghog",), mirror=False, scale_samples=1, n_jitter=0, bg_per_car=2, bg_boxes=0)
    base = make_real_patch_data(KITTI_ROOT, ["000010"], **kw)
    same = make_real_patch_data(KITTI_ROOT, ["000010"], label_shapes={"000010": means}, **kw)
    moved = make_real_patch_data(KITTI_ROOT, ["000010"], label_shapes={"000010": means * [1.0, 0.7, 1.0]}, **kw)
    assert_close(same.X["ghog"], base.X["ghog"])
    moved_parts, base_parts = moved.X["ghog"][moved.y < N_PARTS], base.X["ghog"][base.y < N_PARTS]
    assert len(base_parts) > 20
    assert moved_parts.shape != base_parts.shape or not np.allclose(moved_parts, base_parts)
    with pytest.raises(InputError, match="frame 000010 .* Car labels"):
        make_real_patch_data(KITTI_ROOT, ["000010"], label_shapes={"000010": means[1:]}, **kw)


def test_hidden_by_other_labels_leaves_self_occlusion_out(tmp_path):
    from wirescene.io.kitti import KittiDataset, read_labels
    from wirescene.training.parts_real import hidden_by_other_labels, kitti_car_wireframes

    ds = KittiDataset(KITTI_ROOT)
    labels, camera = ds.labels("000010"), ds.camera("000010")
    others = hidden_by_other_labels(labels, camera)
    unseen = ~np.stack([c.visible for c in kitti_car_wireframes(labels, camera)])
    assert others.shape == unseen.shape and others.any()
    assert not (others & ~unseen).any() and (unseen & ~others).sum() > others.sum()  # self-hidden ones excluded
    one = tmp_path / "one.txt"
    one.write_text(ds.label_path("000010").read_text().splitlines()[0] + "\n")
    lone = read_labels(one)
    assert len(lone.of_type("Car")) == 1 and not hidden_by_other_labels(lone, camera).any()


def test_train_parts_cli_trains_on_the_label_shapes_given(tmp_path):
    """`train parts --label-shapes` learns from the wireframes given; its --report is JSON without the report's
    private keys (its training data)."""
    import json

    from click.testing import CliRunner

    from wirescene.cli.main import main
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.parts_real import save_label_shapes, scaled_mean_shape

    cars = KittiDataset(KITTI_ROOT).labels("000010").of_type("Car")
    save_label_shapes(tmp_path / "s.npz", {"000010": np.stack([scaled_mean_shape(o.dims) for o in cars]) * 1.02})
    args = ["train", "parts", "--kitti-root", str(KITTI_ROOT), "--frames", "000010", "--n-trees", "2",
            "--max-depth", "4", "--synth-scenes", "0", "--no-calibrate", "--out", str(tmp_path / "p.npz")]
    r = CliRunner().invoke(main, [*args, "--label-shapes", str(tmp_path / "s.npz"), "--report",
                                  str(tmp_path / "r.json")])
    assert r.exit_code == 0, r.output
    assert PartDetector.load(tmp_path / "p.npz").meta["label_shapes"] == "True"

    def refuse(token):  # a strict parser's reading: no NaN / Infinity token
        raise ValueError(f"not strict JSON: {token}")

    report = json.loads((tmp_path / "r.json").read_text(), parse_constant=refuse)
    assert {"frames", "n_patches", "n_part", "n_background", "n_real", "train_acc", "model_bytes"} <= set(report)
    assert not [k for k in report if k.startswith("_")] and report["frames"] == ["000010"]
    assert report["n_patches"] == report["n_part"] + report["n_background"] > 0 and 0 <= report["train_acc"] <= 1
    r = CliRunner().invoke(main, ["train", "parts", "--out", str(tmp_path / "q.npz"), "--label-shapes",
                                  str(tmp_path / "s.npz")])
    assert r.exit_code == 2 and "--label-shapes needs a KITTI root (KITTI_ROOT or --kitti-root)" in r.output
