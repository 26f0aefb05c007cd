import json
import shutil
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import KITTI_ROOT, assert_close
from wirescene.cli.main import main
from wirescene.core.errors import InputError
from wirescene.eval.metrics import FrameResult
from wirescene.eval.records import RECORDS_DIR
from wirescene.eval.runner import _FrameJob, evaluate_dataset
from wirescene.eval.sources import DetectionSource
from wirescene.fitting.options import FitOptions
from wirescene.infer.inference import InferenceOptions
from wirescene.io.kitti import KittiDataset, Label
from wirescene.lift import LiftingOptions

# Few particles and iterations keep every run of the two frames at a few seconds.
OPTS = FitOptions(lifting=LiftingOptions(n_particles=6), inference=InferenceOptions(iterations=2, samples=4), seed=1)
VARIANTS = ["coarse+gp", "fg"]  # a coarse one, and a fine one with per-vertex estimates
FRAMES = ["000002", "001545"]


def _reports_json(reports):
    # to_json_dict turns NaN into None, so equal reports compare equal (NaN != NaN).
    return {v: r.to_json_dict(include_records=True) for v, r in reports.items()}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted serial run, with its predictions directory."""
    pred = tmp_path_factory.mktemp("reference") / "pred"
    reports = evaluate_dataset(KittiDataset(KITTI_ROOT), VARIANTS, frames=FRAMES, options=OPTS, predictions_dir=pred)
    return reports, pred


def _collecting_progress(seen):
    def progress(items):
        for item in items:
            seen.append(item)
            yield item

    return progress


def test_parallel_evaluation_equals_serial(reference):
    serial, _ = reference
    parallel = evaluate_dataset(KittiDataset(KITTI_ROOT), VARIANTS, frames=FRAMES, options=OPTS, workers=2)
    for v in serial:
        a = [r.loc_error for r in serial[v].records]
        b = [r.loc_error for r in parallel[v].records]
        assert len(a) == 7 and np.array_equal(a, b)
    assert _reports_json(parallel) == _reports_json(serial)


def _assert_frame_results_equal(a: FrameResult, b: FrameResult):
    def same(x, y, name):
        if isinstance(x, np.ndarray):
            assert isinstance(y, np.ndarray) and x.dtype == y.dtype and x.shape == y.shape, name
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
        elif isinstance(x, (list, tuple)):
            assert isinstance(y, (list, tuple)) and len(x) == len(y), name
            for i, (xi, yi) in enumerate(zip(x, y)):
                same(xi, yi, f"{name}[{i}]")
        elif isinstance(x, Label):
            for k in vars(x):
                same(getattr(x, k), getattr(y, k), f"{name}.{k}")
        else:
            assert type(x) is type(y) and x == y, name

    for k in vars(a):
        same(getattr(a, k), getattr(b, k), k)


def _round_trip(result: FrameResult) -> FrameResult:
    return FrameResult.from_dict(json.loads(json.dumps(result.to_dict())))


def test_frame_result_round_trip_is_exact():
    rng = np.random.default_rng(0)
    gt = [Label("Car", 0.1, 1, 0.3, [1.5, 2.25, 100.125, 80.0], [1.5, 1.6, 3.9], [1.0, 1.7, 20.0], 0.1 + 0.2),
          Label("DontCare", -1, -1, -10, [0, 0, 5, 5], [-1, -1, -1], [-1000, -1000, -1000], -10, score=0.5)]
    full = FrameResult(
        frame_id="000007",
        gt=gt,
        det_boxes=rng.random((2, 4)) * 100,
        det_alpha=[np.nan, 1 / 3],
        det_scores=[1.0, 0.1],
        est_location=rng.normal(size=(2, 3)),
        est_dims=rng.random((2, 3)),
        est_rotation_y=[np.pi, -1e-300],
        est_alpha=[np.inf, 0.0],
        est_occluded=rng.random((2, 36)) < 0.5,
        est_vertices_2d=rng.normal(size=(2, 36, 2)) * 1e3,
        gt_occluded_parts=[3, None],
        gt_vertices_2d=[np.full((36, 2), np.nan), None],
        gt_vertex_visible=[rng.random(36) < 0.5, None],
        gt_self_occluded=np.zeros((2, 36), bool),  # an array, not a list: stays an array
        image_size=(1242, 375),
    )
    empty = FrameResult("000008", [], np.zeros((0, 4)), [], [], np.zeros((0, 3)), np.zeros((0, 3)), [], [])
    for result in (full, empty):
        _assert_frame_results_equal(result, _round_trip(result))
    # The records of real fits too (the fine variant has per-vertex estimates).
    job = _FrameJob(KittiDataset(KITTI_ROOT), tuple(VARIANTS), DetectionSource(), OPTS, "parts")
    for _, result in job("000002")[4].values():
        _assert_frame_results_equal(result, _round_trip(result))
    with pytest.raises(ValueError, match="not a FrameResult record"):
        FrameResult.from_dict({"frame_id": "1"})


def test_resume_reuses_finished_frames_and_equals_uninterrupted_run(reference, tmp_path):
    ref_reports, ref_dir = reference
    pred = tmp_path / "pred"
    shutil.copytree(ref_dir, pred)
    (pred / RECORDS_DIR / "001545.json").unlink()  # interrupted before this frame was complete
    (pred / "fg" / "000002.txt").unlink()  # a lost label file of a complete frame comes back
    (pred / "coarse+gp" / "000002.txt").write_text("Car 0 0 0 0 0 1 1 1 1 1 1 1 1 1\n")  # so does another run's
    with pytest.raises(InputError, match="holds the records of an earlier run"):  # no mixing without --resume
        evaluate_dataset(KittiDataset(KITTI_ROOT), VARIANTS, frames=FRAMES, options=OPTS, predictions_dir=pred)
    fitted, seen, notes = set(), [], []
    resumed = evaluate_dataset(
        KittiDataset(KITTI_ROOT), VARIANTS, frames=FRAMES, options=OPTS, predictions_dir=pred, resume=True,
        progress=_collecting_progress(seen), on_estimate=lambda frame_id, *_: fitted.add(frame_id), notify=notes.append,
    )
    assert fitted == {"001545"}
    assert len(seen) == 2  # the reused frame is counted by the progress bar too
    assert notes == [f"resuming: 1 of 2 frames already done in {pred}"]
    assert _reports_json(resumed) == _reports_json(ref_reports)
    ref_files = sorted(p.relative_to(ref_dir) for p in ref_dir.rglob("*") if p.is_file())
    assert sorted(p.relative_to(pred) for p in pred.rglob("*") if p.is_file()) == ref_files  # no temporary leftovers
    for rel in ref_files:
        assert (pred / rel).read_text() == (ref_dir / rel).read_text(), rel


def test_evaluate_dataset_writes_an_int_frame_id_as_kitti_dataset_reads_it(tmp_path):
    """An int frame id is written %06d, as KittiDataset reads it: its label files and record are 000002's (they were
    2.txt and 2.json, a frame of no split); a bool, a negative int or a float is refused naming frames."""
    from wirescene.core.errors import ArgumentError

    pred = tmp_path / "pred"
    reports = evaluate_dataset(KittiDataset(KITTI_ROOT), ["coarse"], frames=[2], options=OPTS, predictions_dir=pred)
    assert [r.frame_id for r in reports["coarse"].records] == ["000002"]
    written = sorted(str(p.relative_to(pred)) for p in pred.rglob("*") if p.is_file())
    assert written == [f"{RECORDS_DIR}/000002.json", "coarse/000002.txt"]
    for bad in ([True], [-2], [2.0]):
        with pytest.raises(ArgumentError, match="^frames: "):
            evaluate_dataset(KittiDataset(KITTI_ROOT), ["coarse"], frames=bad, options=OPTS)


def test_evaluate_dataset_refuses_a_predictions_dir_it_cannot_write_before_any_fit(tmp_path, monkeypatch):
    """evaluate_dataset called directly checks predictions_dir as wirescene.evaluate checks predictions and the
    command --predictions: a file, an empty path (it wrote into the working directory), a folder under a file or
    no path at all is refused naming it, before any frame is fitted."""
    import wirescene.eval.runner as runner
    from wirescene.core.errors import ArgumentError

    def no_fit(*args, **kwargs):
        raise AssertionError("a frame was fitted")

    monkeypatch.setattr(runner, "fit_frames", no_fit)
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    for folder, problem in ((a_file, f"{a_file} is a file, expected a directory"),
                            ("", "empty path (give a directory, e.g. '.')"),
                            (a_file / "pred", f"{a_file / 'pred'}: {a_file} is a file, not a directory"),
                            (5, "expected a directory path, got int")):
        with pytest.raises(ArgumentError) as exc:
            evaluate_dataset(KittiDataset(KITTI_ROOT), ["coarse"], frames=["000002"], options=OPTS,
                             predictions_dir=folder)
        assert str(exc.value) == f"predictions_dir: {problem}"
    assert [p.name for p in tmp_path.iterdir()] == ["a_file"]


def test_record_of_another_configuration_is_refit(reference, tmp_path):
    _, ref_dir = reference
    pred = tmp_path / "pred"
    shutil.copytree(ref_dir, pred)
    for left_out in [pred / RECORDS_DIR / "001545.json", *(pred / v / "001545.txt" for v in VARIANTS)]:
        left_out.unlink()  # the folder of a run of 000002 alone: a run resumed of fewer frames is refused
    record = pred / RECORDS_DIR / "000002.json"
    other = FitOptions(lifting=OPTS.lifting, inference=OPTS.inference, seed=2)
    fitted, notes = set(), []
    kw = dict(frames=["000002"], predictions_dir=pred, on_estimate=lambda frame_id, *_: fitted.add(frame_id))
    refit = evaluate_dataset(KittiDataset(KITTI_ROOT), VARIANTS, options=other, resume=True, notify=notes.append, **kw)
    assert fitted == {"000002"}
    assert len(notes) == 1 and str(record) in notes[0] and "different configuration (options.seed)" in notes[0]
    assert json.loads(record.read_text())["config"]["options"]["seed"] == 2
    fresh = evaluate_dataset(KittiDataset(KITTI_ROOT), VARIANTS, frames=["000002"], options=other)
    assert _reports_json(refit) == _reports_json(fresh)
    # An unreadable record (not written by us: ours are atomic) is refit as well.
    record.write_text('{"format": ')
    fitted.clear()
    notes.clear()
    evaluate_dataset(KittiDataset(KITTI_ROOT), VARIANTS, options=other, resume=True, notify=notes.append, **kw)
    assert fitted == {"000002"} and len(notes) == 1 and "unreadable" in notes[0]


def test_the_score_floor_of_boxes_from_files_is_in_the_resume_records(tmp_path):
    import pickle

    from wirescene.eval.predict import _config
    from wirescene.eval.records import config_difference, run_config

    dataset = KittiDataset(KITTI_ROOT)
    every, floor, other = (DetectionSource(str(tmp_path), min_score=m) for m in (None, 0.5, 0.6))
    for config in (lambda source: run_config(dataset, VARIANTS, source, OPTS, "parts"),
                   lambda source: _config(dataset, "coarse", source, OPTS)):
        # no floor: no key, so that the records written before the option stay valid
        assert "min_score" not in config(every)["detections"]
        assert config(floor)["detections"]["min_score"] == 0.5
        assert config_difference(config(every), config(floor)) == ["detections.min_score"]
        assert config_difference(config(floor), config(other)) == ["detections.min_score"]
    # sent to worker processes (and Dask's) whole
    assert pickle.loads(pickle.dumps(floor)) == floor


def test_a_file_whose_boxes_all_fall_below_the_floor_is_a_frame_without_detections(tmp_path):
    (tmp_path / "000010.json").write_text(json.dumps([{"box": [354.4, 185.5, 549.5, 294.5], "score": 0.3},
                                                      {"box": [600, 170, 680, 230], "score": 0.7}]))
    dataset, rng = KittiDataset(KITTI_ROOT), np.random.default_rng(0)
    scores = {m: DetectionSource(str(tmp_path), min_score=m).for_frame(dataset, "000010", rng).scores.tolist()
              for m in (None, 0.3, 0.5, 0.8)}
    assert scores == {None: [0.3, 0.7], 0.3: [0.3, 0.7], 0.5: [0.7], 0.8: []}


def test_dask_cluster_equals_serial(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    ref_reports, ref_dir = reference
    seen = []
    # Worker processes, so the job crosses a process boundary as on a real cluster
    # (about 10 s here, 3 s with processes=False).
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        reports = evaluate_dataset(
            KittiDataset(KITTI_ROOT), VARIANTS, frames=FRAMES, options=OPTS, predictions_dir=tmp_path / "pred",
            workers=4, dask_client=cluster.scheduler_address, progress=_collecting_progress(seen),
        )
    assert len(seen) == 2
    assert _reports_json(reports) == _reports_json(ref_reports)
    for path in (p for p in ref_dir.rglob("*") if p.is_file()):
        assert (tmp_path / "pred" / path.relative_to(ref_dir)).read_text() == path.read_text()


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_eval_cli_resume(tmp_path):
    args = ["eval", KITTI_ROOT, "--variant", "coarse+gp", "--frames", "000002", "--particles", 6, "--iterations", 2,
            "--samples", 4, "--seed", 1, "--predictions", tmp_path / "pred"]
    first = _run(*args, "--json", tmp_path / "a.json")
    assert first.exit_code == 0, first.output
    again = _run(*args, "--resume", "--json", tmp_path / "b.json")
    assert again.exit_code == 0, again.output
    assert "wirescene: resuming: 1 of 1 frames already done" in again.stderr
    assert json.loads((tmp_path / "a.json").read_text()) == json.loads((tmp_path / "b.json").read_text())
    stale = _run(*args[:-4], "--seed", 2, "--predictions", tmp_path / "pred", "--resume")
    assert stale.exit_code == 0, stale.output
    assert "refitting 1 frame(s)" in stale.stderr and "000002.json" in stale.stderr


def test_eval_cli_resume_needs_predictions_and_dask_needs_distributed(monkeypatch):
    r = _run("eval", KITTI_ROOT, "--frames", "000002", "--resume")
    assert r.exit_code == 2 and "--resume needs --predictions DIR" in r.output
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    r = _run("eval", KITTI_ROOT, "--frames", "000002", "--dask", "tcp://127.0.0.1:8786")
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert r.exit_code == 2  # the one-line error of any refused input, not click's "Error:" with code 1
    assert lines == ["wirescene: error: --dask needs the 'distributed' package: pip install wirescene[dask]"]


def test_frame_result_leaves_out_the_cars_the_fit_dropped():
    from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate
    from wirescene.eval.runner import frame_result

    labels = KittiDataset(KITTI_ROOT).labels("000002")
    dets = Detections([[0, 0, 10, 10], [20, 20, 40, 40], [50, 50, 80, 90]], [0.9, 0.5, 0.4], 0.0)
    objs = [ObjectEstimate(j, dets.boxes[j], dets.scores[j], np.array([0.0, 1.6, 10.0 + j]), np.eye(3), np.ones(3),
                           0.1 * j) for j in (2, 0)]
    r = frame_result("000002", labels, dets, SceneEstimate("coarse", objs))
    assert np.array_equal(r.det_boxes, dets.boxes[[0, 2]]) and r.est_cost.tolist() == [0.0, 0.2]
    assert r.subset([1]).det_scores.tolist() == [0.4] and r.subset(np.array([True, False])).n_detections == 1
    with pytest.raises(ValueError, match="at most one object per detection"):
        frame_result("000002", labels, dets, SceneEstimate("coarse", objs + [objs[0]]))


def test_the_json_lists_the_cars_in_the_label_files_order():
    """The JSON file's cars, the label file's lines and the pictures' ``#n`` tags follow one
    order (detection order), whatever order the estimate holds its objects in."""
    from wirescene.core.types import ObjectEstimate, SceneEstimate

    objs = [ObjectEstimate(j, np.array([10.0 * j, 0, 10.0 * j + 5, 5]), 0.5, np.array([0.0, 1.6, 10.0 + j]), np.eye(3),
                           np.ones(3), 0.0) for j in (2, 0, 1)]
    estimate = SceneEstimate("coarse", objs)
    listed = [o["detection_index"] for o in estimate.to_dict()["objects"]]
    lines = [float(line.split()[4]) for line in estimate.to_kitti().splitlines()]
    assert listed == [0, 1, 2] and lines == [0.0, 10.0, 20.0]


def test_own_boxes_weigh_by_the_predetect_stage():
    """Our own boxes are fitted with ``predetect.box_weight``, any other boxes with
    ``inference.box_weight``: the same boxes fitted as our own at weight 30 are the boxes
    fitted as given at weight 30, and differ from those at weight 100."""
    from dataclasses import replace

    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.pipeline import fit_frame
    from wirescene.io.detections import detections_from_labels

    ds = KittiDataset(KITTI_ROOT)
    camera, image = ds.camera("000002"), ds.image("000002")
    dets = detections_from_labels(ds.labels("000002"))
    unverified = replace(OPTS, predetect=PredetectOptions(min_car_probability=0, box_weight=30.0),
                         calibrate_scores=False)

    def locations(options, own):
        est = fit_frame(camera, dets, ["fg"], image=image, options=options, own=own).estimates["fg"]
        return np.array([o.location for o in est.objects])

    as_own = locations(unverified, True)
    assert np.array_equal(as_own, locations(replace(unverified, inference=replace(OPTS.inference, box_weight=30.0)),
                                            False))
    assert not np.allclose(as_own, locations(unverified, False))  # inference.box_weight: 100


@pytest.fixture(scope="module")
def half_frame():
    """``(camera, image, half, small)``: frame 000010 and the frame at half its size (Lanczos) with
    the camera that sees it, each axis by its own factor (375 rows: 187)."""
    from PIL import Image

    from wirescene.core.camera import Camera
    from wirescene.predetect.enlarge import scaled_projection

    ds = KittiDataset(KITTI_ROOT)
    image, camera = ds.image("000010"), ds.camera("000010")
    h, w = image.shape[:2]
    small = np.asarray(Image.fromarray(image).resize((w // 2, h // 2), Image.LANCZOS))
    half = Camera(scaled_projection(camera.P, (w // 2) / w, (h // 2) / h), (w // 2, h // 2))
    return camera, image, half, small


def test_smallest_car_searched_moves_the_pyramid_so_that_the_templates_reach_it(half_frame):
    """``predetect.smallest_car``: at half the resolution the frame's cars fall below the bank's
    25 px; searched down to 12 px they are found again, boxes under 25 px among them."""
    from wirescene.eval.sources import DetectionSource
    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.own_boxes import own_detections

    ds = KittiDataset(KITTI_ROOT)
    camera, image, half, small = half_frame
    heights = {}
    for smallest in (None, 12.0):
        found = own_detections(half, small, threshold=0.3, smallest_car=smallest)
        heights[smallest] = found.boxes[:, 3] - found.boxes[:, 1]
    assert (heights[None] >= 24).all()  # the bank's own range (a box may shrink a little in its refinement)
    assert (heights[12.0] < 24).sum() >= 2 and len(heights[12.0]) > len(heights[None])
    # the API's and the detector command's pre-detection search as far
    import wirescene
    from wirescene.core.errors import ArgumentError

    # (at the API's default enlargement too: no finer level left for the enlarged image at 12 px)
    assert_close(wirescene.detect(small, half, threshold=0.3, smallest_car=12.0).boxes, found.boxes, atol=0)
    with pytest.raises(ArgumentError, match="smallest_car"):  # 2 px would upsample 25x: some 40 GB
        wirescene.detect(small, half, smallest_car=2.0)
    with pytest.raises(ValueError, match=r"predetect.smallest_car must be 0 \(the bank's own\) or at least 10"):
        FitOptions().with_settings({"predetect.smallest_car": 5.0})
    assert FitOptions().with_settings({"predetect.smallest_car": 0}).predetect.smallest_car == 0
    # the evaluation's detections take the option from the fit's options
    via_source = DetectionSource("bank").for_frame(ds, "000010", np.random.default_rng(0),
                                                   predetect=PredetectOptions(threshold=0.3, smallest_car=12.0))
    direct = own_detections(camera, image, threshold=0.3, smallest_car=12.0)
    assert np.array_equal(via_source.boxes, direct.boxes)


def test_upsample_detects_on_the_enlarged_image_and_brings_the_boxes_back(tmp_path, half_frame):
    """``predetect.upsample``: at half the resolution the frame's cars fall below the bank's
    25 px; detected on the half image enlarged 2x too they are found again and added to the
    half image's own, their boxes in the half image's pixels (those of the full frame halved)
    and inside it, with the same boxes and viewpoints from the fit, the API, the detect command
    and the evaluation's source."""
    from PIL import Image

    import wirescene
    from wirescene.core.boxes import iou_2d
    from wirescene.core.camera import write_kitti_calib
    from wirescene.fitting.options import PredetectOptions
    from wirescene.fitting.own_boxes import own_detections
    from wirescene.fitting.pipeline import fit_frame

    camera, image, half, small = half_frame
    h, w = image.shape[:2]
    full = own_detections(camera, image, threshold=0.3)
    plain = own_detections(half, small, threshold=0.3)
    found = own_detections(half, small, threshold=0.3, upsample=2.0)
    assert len(found) > len(plain)
    assert_close(found.boxes[:len(plain)], plain.boxes, atol=0)  # the image's own boxes stay, the others added
    overlaps = iou_2d(found.boxes[:, None], found.boxes[None])
    np.fill_diagonal(overlaps, 0.0)
    assert overlaps.max() < 0.5  # a car the enlarged image finds too is not added twice
    halved = (full.boxes + 0.5) * np.array([(w // 2) / w, (h // 2) / h] * 2) - 0.5
    matched = [max(iou_2d(b, c) for c in halved) for b in found.boxes[len(plain):]]
    assert sum(m > 0.7 for m in matched) >= 2, matched  # the full frame's cars, where they lie in the half image
    assert (found.boxes >= 0).all() and (found.boxes[:, [0, 2]] <= w // 2 - 1).all()
    assert (found.boxes[:, [1, 3]] <= h // 2 - 1).all()

    def same(dets):
        assert_close(dets.boxes, found.boxes, atol=0)
        assert_close(dets.alpha, found.alpha, atol=0)

    same(wirescene.detect(small, half, threshold=0.3, upsample=2.0))
    strict = wirescene.detect(small, half, upsample=2.0)  # the bank's own threshold: some of the fit's boxes
    assert 0 < len(strict) < len(found) and all((found.boxes == b).all(axis=1).any() for b in strict.boxes)
    fitted = fit_frame(half, None, ["coarse"], image=small,
                       options=FitOptions().with_settings({"predetect.upsample": 2}))
    same(fitted.detections)
    # the evaluation's source and the detect command read a KITTI root: the half-size frame's
    root = tmp_path / "kitti" / "training"
    (root / "image_2").mkdir(parents=True)
    (root / "calib").mkdir()
    Image.fromarray(small).save(root / "image_2" / "000010.png")
    write_kitti_calib(root / "calib" / "000010.txt", half.P)
    same(DetectionSource("bank").for_frame(KittiDataset(tmp_path / "kitti"), "000010", np.random.default_rng(0),
                                           predetect=PredetectOptions(threshold=0.3, upsample=2.0)))
    r = CliRunner().invoke(main, ["detect", str(tmp_path / "kitti"), "--upsample", "2", "--threshold", "0.3",
                                  "--out", str(tmp_path / "dets")])
    assert r.exit_code == 0, r.output
    written = json.loads((tmp_path / "dets" / "000010.json").read_text())["detections"]
    assert_close(np.array([d["box"] for d in written]), found.boxes, atol=0.006)  # rounded to 0.01 px
    for value in (0.5, 4):
        with pytest.raises(ValueError, match=r"predetect.upsample must be"):
            FitOptions().with_settings({"predetect.upsample": value})


def test_the_enlarged_image_is_searched_at_the_levels_finer_than_the_images_only(monkeypatch, half_frame):
    """``predetect.upsample``: the enlarged image's pyramid holds the levels finer than the
    image's finest alone (the small, far cars; the image's own levels hold the others); where
    ``smallest_car`` already takes the image's levels as fine, or bars cars under the bank's
    own, there is no second pass; a pitch read off the boxes is read once, for both passes."""
    import functools

    import wirescene.predetect.bank as bank_module
    from wirescene.fitting.models import detector_bank
    from wirescene.fitting.own_boxes import own_detections

    ds = KittiDataset(KITTI_ROOT)
    image, camera = ds.image("000010"), ds.camera("000010")
    top = float(detector_bank(None).meta["max_scale"])
    searched = []  # (image height, scales) of every pyramid computed

    @functools.wraps(bank_module.feature_pyramid)
    def seen(img, scales):
        searched.append((np.asarray(img).shape[0], list(scales)))
        return seen.__wrapped__(img, scales)

    monkeypatch.setattr(bank_module, "feature_pyramid", seen)
    plain = own_detections(camera, image, threshold=0.3)
    found = own_detections(camera, image, threshold=0.3, upsample=1.5)
    (h0, own), (h1, same), (h2, finer) = searched
    assert h0 == h1 == image.shape[0] and own == same and max(own) == top
    factor = h2 / image.shape[0]
    assert 1.49 < factor <= 1.5 and len(finer) >= 2
    assert min(finer) * factor > top and max(finer) == top  # finer than the image's finest, down from the bank's top
    assert len(found) > len(plain)
    assert_close(found.boxes[:len(plain)], plain.boxes, atol=0)  # the image's own boxes stay
    _, _, half, small = half_frame  # (the passes do not depend on the image's size: the half frame, 4x faster)
    for smallest in (12.5, 25.0):  # its levels reach 4x: as fine; no car under 25 px searched, in either image
        searched.clear()
        own_detections(half, small, threshold=0.3, upsample=1.5, smallest_car=smallest)
        assert [h for h, _ in searched] == [small.shape[0]], smallest
    # a camera's pitch is read once, off the image's own boxes, for both passes
    import wirescene.fitting.mount as mount

    mounts = []

    @functools.wraps(mount.image_mount)
    def read(*args, **kwargs):
        mounts.append(read.__wrapped__(*args, **kwargs))
        return mounts[-1]

    monkeypatch.setattr(mount, "image_mount", read)
    searched.clear()
    own_detections(camera, image, threshold=0.3, upsample=1.5, estimate_pitch=True)
    assert len(mounts) == 1 and [h for h, _ in searched] == [h0, h2]  # the image's pyramid read by both


def test_a_fit_told_to_estimate_the_pitch_reads_it_off_its_boxes():
    """A calibration whose principal point lies 50 px below the road's horizon (a camera
    pitched down 4 deg, not told): the shared plane, searched within 3 deg of level, stands
    the cars where they are not; reading the pitch off the label boxes (``lifting.estimate_pitch``)
    the fit places them as with the true calibration (compared by lateral offset and distance
    from the camera, which the frames' rotation about the x axis keeps)."""
    from wirescene.core.camera import Camera
    from wirescene.fitting.options import FitOptions
    from wirescene.fitting.pipeline import fit_frame
    from wirescene.io.detections import detections_from_labels

    ds = KittiDataset(KITTI_ROOT)
    camera, image = ds.camera("000010"), ds.image("000010")
    dets = detections_from_labels(ds.labels("000010"))
    P = camera.P.copy()
    P[1, 2] += 50.0
    moved = Camera(P, camera.image_size)
    options = FitOptions(seed=1).with_settings({"lifting.n_particles": 50})

    def locations(cam, settings):
        est = fit_frame(cam, dets, ["coarse+gp"], image=image, options=options.with_settings(settings))
        xyz = np.array([o.location for o in est.estimates["coarse+gp"].objects])
        return np.stack([xyz[:, 0], np.linalg.norm(xyz, axis=1)], axis=1)

    truth = locations(camera, {})
    off = np.linalg.norm(locations(moved, {}) - truth, axis=1)
    read = np.linalg.norm(locations(moved, {"lifting.estimate_pitch": True}) - truth, axis=1)
    assert np.median(read) < 0.5 < np.median(off), (np.median(read), np.median(off))
    # the option leaves a level rig's fit where it was, to within the estimate's tenths of a degree
    level = np.linalg.norm(locations(camera, {"lifting.estimate_pitch": True}) - truth, axis=1)
    assert np.median(level) < 0.5, np.median(level)


def test_a_bank_without_ground_prior_spends_no_detection_on_the_pitch(monkeypatch):
    """The pitch is read with the bank's ground prior: a bank without one (a synthetic one)
    keeps the pitch told and runs no detection pass for it (1.3x the pre-detection's time, 1.6x
    on the image alone)."""
    from types import SimpleNamespace

    import wirescene.predetect
    from wirescene.core.groundplane import Mount
    from wirescene.fitting.mount import image_mount

    ds = KittiDataset(KITTI_ROOT)
    calls = []
    monkeypatch.setattr(wirescene.predetect, "detect_cars", lambda *a, **k: calls.append(a))
    told = Mount(1.3, 2.0)
    assert image_mount(ds.camera("000010"), ds.image("000010"), bank=SimpleNamespace(meta={}), told=told) == told
    assert not calls


def test_decoding_many_images_before_the_first_fit_is_said(monkeypatch):
    """A split's images decoded before the first fit take half a minute or more: said once, from SAY_DECODING
    images, so that the pause before the progress bar is no mystery."""
    import wirescene.eval.runner as runner
    from wirescene.eval.sources import DetectionSource
    from wirescene.io.kitti import KittiDataset

    dataset, said = KittiDataset(KITTI_ROOT), []
    frames = dataset.frame_ids()
    runner.check_images_read(dataset, DetectionSource("gt"), ["full"], frames, notify=said.append)
    assert said == []  # three images
    monkeypatch.setattr(runner, "SAY_DECODING", 3)
    runner.check_images_read(dataset, DetectionSource("gt"), ["full"], frames, notify=said.append)
    runner.check_images_read(dataset, DetectionSource("gt"), ["coarse"], frames, notify=said.append)  # none read
    assert said == ["decoding the 3 images the fits read before the first fit (a corrupt one refused now)"]


@pytest.mark.parametrize("spec", ["gt", "files"])
def test_each_label_or_detection_file_is_read_once_before_the_first_fit(tmp_path, monkeypatch, spec):
    """eval and predict read each frame's label or detection file once before the first fit: the checks of the files,
    of the images the fits decode and of the boxes' viewpoints (held-out line) each read them again (three reads of
    some 0.6 ms a frame; four of a file without a car, read again to name its classes)."""
    from collections import Counter

    import wirescene.eval.predict as predict
    import wirescene.eval.runner as runner
    import wirescene.eval.sources as sources
    import wirescene.io.kitti as kitti

    class FirstFit(Exception):
        pass

    def first_fit(*args, **kwargs):
        raise FirstFit

    reads = Counter()

    def counted(read):
        def reader(path, **kwargs):
            reads[str(path)] += 1
            return read(path, **kwargs)
        return reader

    monkeypatch.setattr(kitti, "read_labels", counted(kitti.read_labels))
    monkeypatch.setattr(sources, "read_boxes_and_classes", counted(sources.read_boxes_and_classes))
    monkeypatch.setattr(runner, "fit_frames", first_fit)
    monkeypatch.setattr(predict, "fit_frames", first_fit)
    dataset = KittiDataset(KITTI_ROOT)
    source = DetectionSource("gt")
    if spec == "files":  # a first file of another class's boxes alone, one without viewpoints, one with
        folder = tmp_path / "dets"
        folder.mkdir()
        entries = {"000002": [{"box": [600, 170, 680, 230], "label": "truck"}],
                   "000010": [{"box": [354, 185, 549, 294], "score": 0.9}],
                   "001545": [{"box": [600, 170, 680, 230], "score": 0.8, "alpha": 1.0}]}
        for frame, boxes in entries.items():
            (folder / f"{frame}.json").write_text(json.dumps(boxes))
        source = DetectionSource(str(folder))
    labels = [str(dataset.label_path(f)) for f in dataset.frame_ids()]
    boxes = labels if spec == "gt" else [str(folder / f"{f}.json") for f in dataset.frame_ids()]
    runs = {"eval": lambda: evaluate_dataset(dataset, ["coarse"], source=source, notify=lambda _: None,
                                             held_out=lambda _: None),
            "predict": lambda: predict.predict_dataset(dataset, tmp_path / "out", variant="coarse", source=source,
                                                       notify=lambda _: None)}
    for command, run in runs.items():
        reads.clear()
        with pytest.raises(FirstFit):
            run()
        read = set(boxes) | (set(labels) if command == "eval" else set())  # predict reads labels of "gt" alone
        assert reads == {path: 1 for path in read}, command
