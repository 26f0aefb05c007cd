"""The benchmark scripts stay importable as the package's layout changes.

Benchmarks are not run by the test suite (they take minutes to hours), but a script
whose imports no longer resolve is found here rather than by the next person who needs
its figures.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p for p in BENCHMARKS.glob("*.py") if not p.stem.startswith("_"))  # _common.py: helpers


def test_there_are_benchmarks():
    assert len(SCRIPTS) >= 5


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_benchmark_imports(script, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(f"_bench_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)  # every script guards its main with __name__
    finally:
        sys.modules.pop(f"_bench_{script.stem}", None)
    assert callable(getattr(module, "main", None)), f"{script.name} has no main()"


def test_benchmarks_write_json_through_the_strict_writer():
    """Benchmark JSON goes through :mod:`wirescene.core.jsonio` (NaN as null), not bare ``json.dump`` /
    ``json.dumps``: the calls in each script's code (not the code strings its child processes run) are
    found, and one that writes no file for people says why on its line (``# plain json: ...``). Every JSON
    file is written atomically (:func:`~wirescene.core.jsonio.write_json`, or
    :func:`~wirescene.core.atomic.write_text` of its text), plain JSON too: a ``Path.write_text`` /
    ``write_bytes`` of a ``dumps`` (or of a name holding one) left half a file where a run failed or stopped."""
    import ast

    def holds_dumps(tree) -> bool:
        return any(isinstance(n, ast.Call) and (getattr(n.func, "id", None) == "dumps"
                                                or getattr(n.func, "attr", None) == "dumps") for n in ast.walk(tree))

    bare, unsafe = [], []
    for script in sorted(BENCHMARKS.glob("*.py")):
        source = script.read_text()
        lines = source.splitlines()
        tree = ast.parse(source)
        # names given JSON text (text = dumps(...)), written by a later call
        texts = {t.id for node in ast.walk(tree) if isinstance(node, ast.Assign) and holds_dumps(node.value)
                 for t in node.targets if isinstance(t, ast.Name)}
        for node in ast.walk(tree):
            # a Path's own write (its one argument the text), not core.atomic.write_text(path, text)
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("write_text", "write_bytes") and node.args
                    and (holds_dumps(node.args[0]) or getattr(node.args[0], "id", None) in texts)):
                unsafe.append(f"{script.name}:{node.lineno}")
            if isinstance(node, ast.ImportFrom) and node.module == "json":
                called = [a.name for a in node.names if a.name in ("dump", "dumps")]
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and isinstance(node.func.value, ast.Name) and node.func.value.id == "json"):
                called = [node.func.attr] if node.func.attr in ("dump", "dumps") else []
            else:
                continue
            if called and not any("# plain json:" in line for line in lines[node.lineno - 1:node.end_lineno]):
                bare.append(f"{script.name}:{node.lineno}")
    assert not bare, f"bare json.dump(s) (use wirescene.core.jsonio's write_json / dumps): {bare}"
    assert not unsafe, f"JSON written in place, not atomically (use write_json, or core.atomic's write_text): {unsafe}"


def test_choose_by_fold_never_uses_the_scored_fold(monkeypatch):
    """Each fold's configuration is the best on the other folds, whatever it scores on its own."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from choose_by_fold import choose_leaving_one_out

    # "a" wins overall only through fold 0; on folds 1-3 "b" leads.
    counts = {"a": [50, 10, 10, 10], "b": [0, 12, 12, 12]}
    assert choose_leaving_one_out(counts) == {0: "b", 1: "a", 2: "a", 3: "a"}
    # Ties go to the first configuration given.
    assert choose_leaving_one_out({"off": [1, 1], "on": [1, 1]}) == {0: "off", 1: "off"}


def test_learning_curve_subsets_are_reproducible_shares_of_the_training_frames(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_predetect import training_subset

    frames = [f"{i:06d}" for i in range(24)]
    third = training_subset(frames, 1 / 3, seed=(0, 2))
    assert len(third) == 8 and third <= set(frames)
    assert training_subset(frames, 1 / 3, seed=(0, 2)) == third  # same seed, same frames
    assert training_subset(frames, 1 / 3, seed=(0, 3)) != third  # each fold draws its own
    assert training_subset(frames, 1.0, seed=(0, 2)) == set(frames)
    assert len(training_subset(frames, 0.01, seed=(0, 2))) == 1
    # By drive: a share of the drives, each drawn with all its frames.
    drives = {f: f"drive{int(f) % 6}" for f in frames}
    two = training_subset(frames, 1 / 3, seed=(0, 2), groups=drives)
    assert len({drives[f] for f in two}) == 2 and len(two) == 8
    assert two == {f for f in frames if drives[f] in {drives[g] for g in two}}


def test_operating_point_says_why_cars_are_missed(monkeypatch):
    import numpy as np

    from wirescene.core.types import Detections
    from wirescene.io.kitti import FrameLabels, Label

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from _common import operating_point

    def car(box, truncated=0.0, occluded=0):
        return Label("Car", truncated, occluded, 0.0, np.array(box, float), np.array([1.5, 1.6, 3.9]),
                     np.array([0.0, 1.6, 10.0]), 0.0)

    labels = FrameLabels([car([0, 100, 80, 160], truncated=0.4), car([200, 100, 280, 160], occluded=1),
                          car([400, 100, 480, 160], occluded=2)])
    # the truncated car found, the occluded one only below the threshold, the last one not at all;
    # one detection on no car
    dets = Detections(np.array([[1, 100, 80, 160], [200, 101, 280, 160], [600, 100, 680, 160]], float),
                      np.array([0.9, 0.3, 0.8]), np.zeros(3))
    o = operating_point([dets], [labels], 0.5)
    assert (o["n_detections"], o["n_on_car"], o["n_cars"]) == (2, 1, 3)
    assert o["recall_by_truncation"] == {"truncated": [1.0, 1], "whole": [0.0, 2]}
    assert o["recall_by_occlusion"] == {"0": [1.0, 1], "1": [0.0, 1], "2": [0.0, 1]}
    assert (o["missed_below_threshold"], o["missed_without_candidate"]) == (1, 1)
    assert o["missed_without_candidate_by_height"]["60-infpx"] == [1, 0]  # (the boxes are 60 px high)
    # a low-scoring box half off the missed car (IoU 0.33): still no candidate, but one at IoU >= 0.3
    near = Detections(np.vstack([dets.boxes, [440, 100, 520, 160]]), np.append(dets.scores, 0.1), np.zeros(4))
    o = operating_point([near], [labels], 0.5)
    assert o["missed_without_candidate_by_height"] == {"0-25px": [0, 0], "25-40px": [0, 0], "40-60px": [0, 0],
                                                       "60-infpx": [1, 1]}


def test_rescoring_context_features_see_the_higher_scoring_neighbours(monkeypatch):
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_rescore import FEATURES, rescoring_features

    # a car box, a box half over it scoring lower, and one inside it scoring lower still
    boxes = np.array([[100.0, 150, 200, 220], [150, 150, 250, 220], [110, 160, 150, 200]])
    X = rescoring_features(boxes, np.array([0.9, 0.3, 0.2]), np.zeros(3), (1242, 375), horizon=180, center_column=620)
    col = {name: X[:, i] for i, name in enumerate(FEATURES)}
    assert X.shape == (3, len(FEATURES))
    assert col["best_iou_above"][0] == 0.0 and abs(col["best_iou_above"][1] - 1 / 3) < 1e-9
    assert col["inside_above"][2] == 1.0 and col["covers_above"][0] == 0.0
    assert col["logit_gap"][1] > 0 and col["n_above"].tolist() == [0, 1, 1]  # the third only touches the second
    assert col["best_iou_below"][0] > 0 and col["best_iou_below"][2] == 0.0


def test_range_bias_correction_is_fitted_on_the_other_group(monkeypatch):
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_range_bias import corrected_within_1m
    from wirescene.io.folds import DRIVE_FOLDS, frame_drives

    drives = frame_drives()
    by_fold = {k: next(f for f, d in sorted(drives.items()) if DRIVE_FOLDS[d] == k) for k in range(4)}
    frames = [by_fold[k] for k in (0, 1, 2, 3) for _ in range(5)]
    label = np.full(20, 20.0)
    bias = np.where(np.arange(20) < 10, 0.10, 0.0)  # folds 0-1 10% long, folds 2-3 exact
    cars = {"frame": frames, "label_range": label.tolist(), "range": (label * bias).tolist(),
            "lateral": [0.0] * 20, "height": [0.0] * 20}
    to_23, to_01 = corrected_within_1m(cars)
    assert to_23["test"] == [2, 3] and abs(to_23["bias_fitted_on_other"] - 10) < 1e-9
    assert to_23["within_1m_before"] == 100 and to_23["within_1m_after"] == 0  # 2 m short after dividing by 1.1
    assert to_01["within_1m_before"] == 0 and to_01["within_1m_after"] == 0  # fitted 0% on {2, 3}: unchanged


def test_dev_holdout_keeps_the_tuning_frames_apart(monkeypatch):
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_dev_holdout import split_figures
    from wirescene.core.labels import Label
    from wirescene.eval.metrics import FrameResult

    car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)

    def frame(fid, dz):  # one car found, its centre dz metres off in depth
        return FrameResult(fid, [car], np.array([car.box]), np.array([0.0]), np.array([1.0]),
                           np.array([[0, 1.6, 20 + dz]]), np.array([[1.5, 1.6, 4.0]]), np.array([0.0]),
                           np.array([0.0]))

    records = {"coarse+gp": [frame("a", 0.1), frame("b", 3.0)], "full": [frame("a", 0.1), frame("b", 0.2)]}
    out = split_figures(records, {"a"}, "coarse+gp")
    assert out["tuning frames"]["full"]["loc_1m"] == 100 and out["tuning frames"]["full"]["margin"] == 0
    assert out["new drives"]["coarse+gp"]["loc_1m"] == 0 and out["new drives"]["full"]["margin"] == 100
    assert out["new drives"]["full"]["n_gt"] == 1 and out["new drives"]["full"]["frames"] == 1


def test_by_drive_margin_shows_the_drive_that_carries_it(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_by_drive import drive_counts, margin_by_drive
    from wirescene.eval.intervals import clustered_share

    table = {"frame": np.array(["a", "a", "b", "c"], dtype=object), "pass_loc": np.array([True, False, True, True])}
    n, k = drive_counts(table, ["d1", "d2", "d3"], {"a": "d1", "b": "d1", "c": "d3"}, column="pass_loc")
    assert n.tolist() == [3, 0, 1] and k.tolist() == [2, 0, 1]

    # The variant gains 10 cars on the big drive and none on the four small ones.
    k_ref, n_cars = np.array([20, 5, 5, 5, 5]), np.array([50, 10, 10, 10, 10])
    k_var = k_ref + np.array([10, 0, 0, 0, 0])
    out = margin_by_drive(k_var, n_cars, k_ref, n_cars, n_boot=2000, seed=3)
    assert_close(out["margin"], 100 * 10 / 90)
    assert out["net"].tolist() == [10, 0, 0, 0, 0]
    assert_close(out["leave_one_out"][0], 0.0)  # without the big drive nothing is left
    assert_close(out["leave_one_out"][1:], np.full(4, 100 * 10 / 80))
    lo, hi = out["interval"]
    assert lo < out["margin"] < hi and lo <= 1e-9  # some draws hold no big drive at all
    assert margin_by_drive(k_var, n_cars, k_ref, n_cars, n_boot=2000, seed=3)["interval"] == (lo, hi)
    assert margin_by_drive(k_var, n_cars, k_ref, n_cars, n_boot=0)["interval"] is None
    with pytest.raises(ValueError, match="one shape"):
        margin_by_drive(k_var, n_cars[:4], k_ref, n_cars)
    share, (lo, hi) = clustered_share(k_var, n_cars, n_boot=2000, seed=3)
    assert_close(share, 100 * 50 / 90)
    assert lo < share < hi
    assert lo >= 100 * 5 / 10 - 1e-9 and hi <= 100 * 30 / 50 + 1e-9  # between the small drives' and the big one's
    assert clustered_share(k_var, n_cars, n_boot=0) == (share, None)


def test_operating_point_counts_boxes_on_no_car_and_second_boxes_as_false(monkeypatch):
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_operating_point import false_cars
    from wirescene.core.labels import Label
    from wirescene.eval.metrics import FrameResult

    car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 160], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)
    van = Label("Van", 0.0, 0, 0.0, [400, 100, 500, 160], [2.0, 1.8, 5.0], [5, 1.6, 20], 0.0)
    boxes = np.array([[102, 100, 200, 160], [100, 102, 198, 160], [400, 100, 500, 160], [700, 100, 800, 160]], float)
    n = len(boxes)
    result = FrameResult("f", [car, van], boxes, np.zeros(n), np.array([0.9, 0.8, 0.7, 0.6]),
                         np.zeros((n, 3)), np.ones((n, 3)), np.zeros(n), np.zeros(n))
    assert false_cars(result) == 3  # the second box on the car, the van, the empty road


def test_funnel_says_where_cars_are_lost_on_the_way_to_a_true_positive(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_operating_point import figures, funnel
    from wirescene.core.labels import Label
    from wirescene.eval.metrics import FrameResult

    dims, ry = [1.5, 1.6, 4.0], 0.0
    cars = [Label("Car", 0.0, 0, 0.0, [100 + 300 * i, 100, 200 + 300 * i, 160], dims, [5.0 * i, 1.6, 20.0], ry)
            for i in range(3)]

    def frame(keep, alpha, offset):  # detections on the cars `keep` and one on the empty road
        boxes = np.array([cars[i].box for i in keep] + [[1000, 100, 1100, 160]], float)
        n = len(boxes)
        loc = np.array([cars[i].location for i in keep] + [[0.0, 1.6, 30.0]], float) + [0.0, 0.0, offset]
        return FrameResult("000000", cars, boxes, np.asarray(alpha, float), np.linspace(0.9, 0.5, n), loc,
                           np.tile(dims, (n, 1)), np.full(n, ry), np.zeros(n))

    # before the verification the three cars are matched; it drops the third; the second's viewpoint is turned
    before = frame([0, 1, 2], [0.0, np.pi, 0.0, 0.0], 0.0)
    after = frame([0, 1], [0.0, np.pi, 0.0], 0.0)
    assert funnel([before], figures([after])) == {"cars": 3, "matched": 3, "verified": 2, "tp": 1, "within_1m": 1}
    # the same true positive placed 2 m too far is no longer within 1 m
    assert funnel([before], figures([frame([0, 1], [0.0, np.pi, 0.0], 2.0)]))["within_1m"] == 0


def test_paired_comparison_counts_only_cars_both_runs_place(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_operating_point import CLIP, paired

    # one frame (so one fold group), with a car only the first run finds
    first = {("000000", 0): 0.5, ("000000", 1): 2.0, ("000000", 2): 9.0, ("000000", 3): 0.4}
    other = {("000000", 0): 0.7, ("000000", 1): 1.2, ("000000", 2): 6.0}
    (row,) = paired(first, other).values()
    assert row["cars"] == 3 and row["nearer"] == 2 and row["farther"] == 1
    assert row["within_1m"] == [1, 1] and row["within_1.5m"] == [1, 2]
    assert_close(row["mean_clipped"], [(0.5 + 2.0 + CLIP) / 3, (0.7 + 1.2 + CLIP) / 3])


def test_range_cues_size_move_keeps_the_image_and_k0_is_the_fit(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_range_cues import MEAN_HEIGHT, size_against_plane
    from wirescene.core.labels import Label

    label = Label("Car", 0.0, 0, 0.0, [0, 0, 10, 10], [MEAN_HEIGHT, 1.6, 4.0], [1.0, 1.6, 20.0], 0.3)
    # fitted 10% too tall and 10% too far along the ray from the camera centre (0, 0, 0)
    cars = {"group": np.array([0]), "centre": np.zeros((1, 3)), "location": np.array([[1.1, 1.76, 22.0]]),
            "dims": np.array([[1.1 * MEAN_HEIGHT, 1.76, 4.4]]), "rotation_y": np.array([0.3]), "labels": [label],
            "focal": np.array([721.5])}
    rows = size_against_plane(cars)
    assert rows[0].startswith("| k = 0 | 0 / 0 of 1 |")  # the fit: 2 m off
    assert rows[-2].startswith("| k = 1 | 1 / 1 of 1 |")  # the mean height puts it back on the label
    assert rows[-1].startswith("| k(z), error model | 0 / 0 of 1 |")  # a sixth of the way back: 1.7 m off


def test_box_files_are_the_label_boxes_and_their_jitter_is_seeded(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from wirescene.io.kitti import KittiDataset
    from write_box_files import frame_boxes

    ds = KittiDataset(KITTI_ROOT)
    cars = ds.labels("000010").of_type("Car")
    plain = frame_boxes(ds, "000010", jitter=False, seed=0)
    assert [b["box"] for b in plain] == [[round(float(v), 2) for v in o.box] for o in cars]
    assert all(set(b) == {"box", "score"} for b in plain)  # no viewpoint: the fit completes it
    moved = frame_boxes(ds, "000010", jitter=True, seed=0)
    assert moved == frame_boxes(ds, "000010", jitter=True, seed=0) != frame_boxes(ds, "000010", jitter=True, seed=1)
    a, b = np.array([x["box"] for x in plain]), np.array([x["box"] for x in moved])
    assert a.shape == b.shape and not np.allclose(a, b)
    height, width = ds.image("000010").shape[:2]
    assert (b[:, :2] >= 0).all() and (b[:, 2] <= width - 1).all() and (b[:, 3] <= height - 1).all()


def test_unseen_shape_model_leaves_its_exemplar_out(monkeypatch):
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from _common import approximated_wireframes
    from bench_unseen_shapes import leave_one_out
    from wirescene.core.shape import load_default
    from wirescene.synth.generate import default_camera

    shipped = load_default()
    name = shipped.exemplar_names[3]
    unseen = leave_one_out(shipped, name)
    assert name not in unseen.exemplar_names and len(unseen.exemplar_names) == len(shipped.exemplar_names) - 1
    # one car of that exemplar, 12 m ahead, turned 30 degrees
    c, s = np.cos(0.5), np.sin(0.5)
    R, t = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]), np.array([1.0, 1.6, 12.0])
    car = {"vertices_3d": (shipped.exemplars[3] @ R.T + t).tolist(), "R": R.tolist(), "location": t.tolist()}
    uv_seen, err_seen = approximated_wireframes(shipped, [car], default_camera(), 5)
    uv_unseen, err_unseen = approximated_wireframes(unseen, [car], default_camera(), 5)
    assert uv_seen.shape == (1, 36, 2) and err_seen.shape == (1, 36)
    assert np.median(err_unseen) > np.median(err_seen)


def test_train_scale_checks_its_two_worker_points_against_the_serial_law(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_train_scale import summarise

    rows = [{"frames": 50, "workers": 1, "seconds": 300.0, "peak_mb": 1000},
            {"frames": 200, "workers": 1, "seconds": 1200.0, "peak_mb": 1500}]
    check = [rows[0], {"frames": 50, "workers": 2, "seconds": 180.0, "peak_mb": 1000}]
    out = summarise(rows, check, [{"frames": 800, "workers": 2, "seconds": 3000.0, "peak_mb": 1600}])
    assert out["time_s"] == {"a": 0.0, "b_per_frame": 6.0} and out["parallel_share"] == 0.8
    # 800 frames: 4,800 s serial, 60% of it with 2 workers at a parallel share of 0.8
    assert out["two_workers"] == [{"frames": 800, "seconds": 3000.0, "projected_s": 2880.0, "peak_mb": 1600,
                                   "peak_over_first_serial": 1.6}]


def test_eval_scale_repeats_the_labelled_frames_and_projects_parent_plus_workers(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_eval_scale import descendants, project, repeated_root
    from wirescene.io.kitti import KittiDataset

    root, ids = repeated_root(KITTI_ROOT, tmp_path, 5)
    source = KittiDataset(KITTI_ROOT)
    labelled = sorted(f for f in source.frame_ids() if source.label_path(f).is_file())
    m = len(labelled)
    assert ids == ["000000", "000001", "000002", "000003", "000004"] and 1 < m < 5
    dataset = KittiDataset(root)
    assert dataset.frame_ids() == ids
    for i, f in enumerate(ids):  # frame i is the (i mod m)-th labelled frame, every file of it
        assert dataset.label_path(f).read_text() == source.label_path(labelled[i % m]).read_text()
        assert dataset.image_path(f).resolve() == source.image_path(labelled[i % m]).resolve()
        assert dataset.calib_path(f).resolve() == source.calib_path(labelled[i % m]).resolve()
    assert repeated_root(KITTI_ROOT, tmp_path, 5)[1] == ids  # a second run relinks in place
    rows = [{"frames": 100, "parent_mb": 60, "worker_max_mb": 900},
            {"frames": 300, "parent_mb": 80, "worker_max_mb": 1000}]
    out = project(rows, frames=1100, machine_gb=4)
    # the parent grows 0.1 MB a frame: 50 + 110 = 160 MB at 1,100 frames, plus W x the largest worker
    assert out["parent_mb"] == {"c": 50, "d_per_frame": 0.1, "at_1100": 160} and out["worker_mb"] == 1000
    assert out["total_mb_at_1100"] == {"1": 1160, "2": 2160, "8": 8160, "16": 16160}
    assert out["workers_in_4_gb"] == 3  # (4,096 - 160) // 1,000
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert child.pid in descendants(os.getpid())
    finally:
        child.kill()
        child.wait()


@pytest.mark.parametrize("args", [["--workers", "1", "--frames", "2,3"], ["--workers", "2", "--frames", "1,3"]],
                         ids=["one worker", "one frame"])
def test_eval_scale_refuses_runs_that_fit_in_the_parent(monkeypatch, tmp_path, capsys, args):
    """wirescene eval fits a run of one worker or one frame in its own process: no worker's
    peak (it read 0 MB and projected 12,000 workers in 24 GB) and the fits in the parent's law."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_eval_scale

    monkeypatch.setattr(sys, "argv", ["bench_eval_scale.py", str(tmp_path / "work"), "--root", str(KITTI_ROOT), *args])
    with pytest.raises(SystemExit):
        bench_eval_scale.main()
    assert "must be 2 or more" in capsys.readouterr().err
    assert not (tmp_path / "work").exists()  # refused before linking a root or running an evaluation


def test_plane_height_bound_moves_cars_along_their_rays(monkeypatch):
    """A car moved by its own height factor stands at its label's height, on the same ray."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_error_budget import Boxes
    from bench_plane_height import moved_along_rays

    centre = np.array([[0.06, -0.01, 0.0], [0.06, -0.01, 0.0]])
    fitted = Boxes.of([[2.0, 1.70, 20.0], [-3.0, 1.62, 9.0]], [[1.5, 1.6, 3.9]] * 2, [0.1, -1.5])
    label_y = np.array([1.60, 1.66])
    factor = (label_y - centre[:, 1]) / (fitted.location[:, 1] - centre[:, 1])
    moved = moved_along_rays({"camera_centre": centre, "fitted": fitted}, factor)
    assert_close(moved.location[:, 1], label_y)
    ray = fitted.location - centre
    assert_close(np.cross(moved.location - centre, ray), np.zeros((2, 3)), atol=1e-9)
    assert_close(moved.dims, fitted.dims)
    assert_close(moved.rotation_y, fitted.rotation_y)


def test_missed_cars_are_the_labels_no_detection_reaches_and_the_verifier_sees_their_boxes(monkeypatch):
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.bank import load_default_bank

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_missed_cars import frame_logits

    ds = KittiDataset(KITTI_ROOT)
    cars = [o for o in ds.labels("000010").objects if o.type == "Car"]
    bank = load_default_bank()
    gt = np.array([o.box for o in cars], float)
    # one detection on the first car, one on no car, none near the others
    boxes = np.vstack([gt[0] + [2, 1, -2, 0], [5, 5, 60, 40]])
    on, off, missed = frame_logits(bank, ds.image("000010"), boxes, np.array([0.9, 0.8]), np.zeros(2), cars,
                                   threshold=0.3)
    assert (len(on), len(off), missed.shape) == (1, 1, (len(cars) - 1, 3))
    assert_close(missed[:, 2], gt[1:, 3] - gt[1:, 1])
    assert np.all(missed[:, 1] >= missed[:, 0])  # the best of the 8 bins is at least the label's
    # a verifier that reads the pixels: a labelled car scores above a patch of sky
    assert np.median(missed[:, 1]) > off[0]
    # below the threshold nothing is kept, and the missed cars stay the same
    on, off, again = frame_logits(bank, ds.image("000010"), boxes, np.array([0.2, 0.1]), np.zeros(2), cars,
                                  threshold=0.3)
    assert (len(on), len(off)) == (0, 0)
    assert_close(again, missed)


def test_acf_scores_windows_from_the_channel_map_as_the_trees_score_their_features(monkeypatch):
    from sklearn.ensemble import HistGradientBoostingClassifier

    from wirescene.io.kitti import KittiDataset

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_acf as acf

    ds = KittiDataset(KITTI_ROOT)
    pos = acf.positives(ds, ["000010"])
    assert sum(len(p) for p in pos) == 2 * sum(o.type == "Car" and o.box[3] - o.box[1] >= 0.9 * acf.MIN_HEIGHT
                                               for o in ds.labels("000010").objects)  # each car and its mirror
    aspect = acf.ASPECTS[0]
    pyr = acf.pyramid(ds.image("000010"))
    s, ch = pyr[4]
    assert ch.shape[0] == acf.N_CH and np.isfinite(ch).all()
    yy, xx, boxes = acf.window_positions(s, ch.shape[1:], aspect, acf.horizon_row(ds.camera("000010")))
    ratio = (boxes[:, 3] - acf.horizon_row(ds.camera("000010"))) / (boxes[:, 3] - boxes[:, 1])
    assert len(yy) and ratio.min() >= acf.RATIO_BAND[0] - 1e-9 and ratio.max() <= acf.RATIO_BAND[1] + 1e-9
    X = acf.gather(ch, yy, xx, aspect)
    rng = np.random.default_rng(0)
    labels_ = rng.random(len(X)) < 0.2
    # unweighted (the benchmark's class weights make scikit-learn's binning slow), the trees as acf.fit grows them
    clf = HistGradientBoostingClassifier(max_iter=12, max_depth=2, max_bins=64, early_stopping=False).fit(X, labels_)
    trees = acf.compile_trees(clf, aspect)
    assert_close(acf.score_windows(trees, ch, yy, xx, chunk=97), clf.decision_function(X), atol=1e-9, rtol=0)


def test_acf_found_at_precision_counts_each_car_once(monkeypatch):
    from wirescene.core.labels import FrameLabels, Label
    from wirescene.core.types import Detections

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_acf import found_at_precision

    cars = [Label("Car", 0.0, 0, 0.0, [0, 0, 10, 10], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0),
            Label("Car", 0.0, 0, 0.0, [50, 0, 60, 10], [1.5, 1.6, 4.0], [0, 1.6, 20], 0.0)]
    # two detections of the first car, one off every car, then the second car
    d = Detections(np.array([[0, 0, 10, 10], [1, 0, 10, 10], [20, 0, 30, 10], [50, 0, 60, 10.0]]),
                   np.array([0.9, 0.8, 0.7, 0.6]), np.zeros(4))
    (r1, k1, t1), (r2, k2, t2) = found_at_precision([d], [FrameLabels(cars)], (1.0, 0.7))
    assert (r1, k1, t1) == (0.5, 1, 0.9)  # the second detection on the first car finds no new one
    assert (r2, k2, t2) == (1.0, 4, 0.6)  # 3 of 4 on a car


def test_acf_fusion_features_read_the_other_source_where_boxes_overlap(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_acf import fusion_features

    bank = (np.array([[0, 0, 10, 10], [100, 0, 110, 10.0]]), np.array([0.5, 0.9]), np.zeros(2))
    acf = (np.array([[1, 0, 10, 10], [200, 0, 240, 20.0]]), np.array([2.0, -1.0]))
    xb, xa = fusion_features(bank, acf)
    assert_close(xb, np.array([[0.0, 2.0, 1.0], [np.log(9.0), -10.0, 0.0]]))  # bank logit, ACF score, overlap
    assert_close(xa[:, [0, 3, 4]], np.array([[2.0, 0.0, 1.0], [-1.0, -10.0, 0.0]]))
    assert_close(xa[:, 1], np.log([10.0, 20.0]))
    assert_close(xa[:, 2], xa[:, 0] * xa[:, 1])


def test_worker_memory_fits_the_same_frames_pass_after_pass_and_reads_the_resident_set(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_worker_memory import passes

    rows = list(passes(str(KITTI_ROOT), frames=1, n_passes=2, variants=["coarse"], detections="gt"))
    assert [r[0] for r in rows] == [0, 1]
    for _, seconds, rss, trimmed, peak in rows:
        assert seconds > 0 and 20 < trimmed <= rss + 1 and rss <= peak + 1  # MB of a Python process with numpy


def test_resolution_root_resizes_images_calibrations_and_boxes_alike(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_resolution import resized_root
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.enlarge import scaled_projection

    frames = resized_root(KITTI_ROOT, tmp_path / "kitti", 1.5)
    source, resized = KittiDataset(KITTI_ROOT), KittiDataset(tmp_path / "kitti")
    assert resized.frame_ids() == frames and len(frames) >= 2
    for f in frames:
        h, w = source.image(f).shape[:2]
        assert resized.image(f).shape[:2] == (round(1.5 * h), round(1.5 * w))
        P, P15 = source.camera(f).P, resized.camera(f).P
        X = np.array([[2.0, 1.6, 15.0], [-4.0, 1.5, 30.0]])
        uv, uv15 = source.camera(f).project(X), resized.camera(f).project(X)
        assert_close(uv15, 1.5 * (uv + 0.5) - 0.5, atol=1e-9)  # a pixel centre goes where the resized image puts it
        assert_close(P15, scaled_projection(P, 1.5))
        for a, b in zip(source.labels(f).objects, resized.labels(f).objects):
            assert_close(np.asarray(b.box), 1.5 * (np.asarray(a.box) + 0.5) - 0.5, atol=0.006)
            assert_close(np.asarray(b.location), np.asarray(a.location))
            assert b.type == a.type


def test_resolution_box_agreement_maps_the_resized_boxes_back(monkeypatch, tmp_path):
    # a copy at scale 1 gives every box back in place; the comparison must find that
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_resolution import box_agreement, resized_root

    frames = resized_root(KITTI_ROOT, tmp_path / "kitti", 1.0)[:1]
    got = box_agreement(KITTI_ROOT, tmp_path / "kitti", 1.0, frames)
    n, n_copy = got["detections"]
    assert n == n_copy and len(got["matched"]) == n > 0
    assert_close(np.array(got["matched"]), np.ones((n, 2)), atol=1e-6)
    assert len(got["labelled"][0]) == len(got["labelled"][1]) > 0


def test_confidence_cues_read_the_box_fit_and_the_frame_scale(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_confidence_cues import _MEAN_HEIGHT, CUES, cue_features
    from wirescene.eval.metrics import FrameResult

    focal = 700.0
    boxes = np.array([[100.0, 150.0, 200.0, 220.0], [0.0, 160.0, 80.0, 200.0]])  # the second at the left border
    heights = boxes[:, 3] - boxes[:, 1]
    # the first car at the depth a car of the mean height has at its box height, the second twice as far
    depth = np.array([1.0, 2.0]) * focal * _MEAN_HEIGHT / heights
    corners = np.stack([boxes[:, [0, 1]], boxes[:, [2, 3]]], axis=1)  # (2, 2, 2): the boxes' corners
    corners[1, 0, 0] -= 30.0  # the second wireframe reaches past the image's left side, where its box is cut
    corners[0, 1, 1] += 7.0  # the first wireframe's bottom 10% of its box's height below the box
    result = FrameResult("f", [], boxes, np.zeros(2), np.ones(2), np.column_stack([[0.0, 3.0], [1.6, 1.7], depth]),
                         np.tile([1.5, 1.6, 3.9], (2, 1)), np.zeros(2), np.zeros(2), est_vertices_2d=corners,
                         image_size=(1242, 375))
    cues = dict(zip(CUES, cue_features(result, focal).T))
    assert_close(cues["box fit"], np.log([0.1 + 1e-3, 1e-3]))
    assert_close(cues["frame scale"], np.full(2, np.log(2.0) / 2))  # the median of log 1 and log 2
    assert_close(cues["own scale"], np.array([-1.0, 1.0]) * np.log(2.0) / 2)
    assert_close(cues["pitch"], np.full(2, 0.1 / (depth[1] - depth[0])))
    assert_close(cues["cars"], np.full(2, np.log(2.0)))


def test_seed_comparison_pairs_runs_by_seed_and_cars_by_label(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_seeds import compare, sign_test

    def table(rows):  # (frame, label index, within 1 m, 3D IoU)
        f, g, loc, iou = zip(*rows)
        return {"frame": np.array(f, dtype=object), "gt_index": np.array(g), "pass_loc": np.array(loc),
                "iou": np.array(iou, float), "pass_iou": np.array(iou) > 0.7}

    fold_of = {"a": 0, "b": 2}
    # seed 1 of A also matches car a2, which no other run does: counted in its seed's figures, not car by car
    runs_a = [table([("a", 0, True, 0.8), ("a", 1, False, 0.3), ("a", 2, False, 0.1), ("b", 0, True, 0.5)]),
              table([("a", 0, True, 0.75), ("a", 1, True, 0.4), ("b", 0, False, 0.2)])]
    runs_b = [table([("a", 0, True, 0.8), ("a", 1, True, 0.5), ("b", 0, True, 0.6)]),
              table([("a", 0, True, 0.72), ("a", 1, True, 0.45), ("b", 0, True, 0.55)])]
    report = compare(runs_a, runs_b, fold_of, classes={"near": {("a", 0), ("b", 0)}})
    g = report["{0, 1}"]
    assert g["seeds"]["true positives"] == {"A": [3, 2], "B": [2, 2]}
    assert g["seeds"]["within 1 m"] == {"A": [1, 2], "B": [2, 2]} and g["summed"]["within 1 m"] == [3, 4]
    assert g["B ahead / level / behind"]["within 1 m"] == [1, 1, 0]
    assert g["summed"]["IoU > 0.7"] == [2, 2] and g["B ahead / level / behind"]["IoU > 0.7"] == [0, 2, 0]
    assert_close(np.array(g["seeds"]["mean IoU"]["A"]), np.array([0.4, 0.575]))
    assert_close(np.array(g["summed"]["mean IoU"]), np.array([(0.4 + 0.575) / 2, (0.65 + 0.585) / 2]))
    # car by car over a0 and a1: B places a1 at both seeds, A at one
    assert g["paired"]["within 1 m"] == {"cars": 2, "passes": [3, 4], "B more": 1, "B fewer": 0, "p": 1.0}
    # by class: the near cars are a0 (group {0, 1}) and b0 (group {2, 3}), which B places at both seeds, A at one
    assert g["by class"]["near"]["within 1 m"] == {"cars": 1, "passes": [2, 2], "B more": 0, "B fewer": 0, "p": 1.0}
    assert report["all"]["by class"]["near"]["within 1 m"]["passes"] == [3, 4]
    assert "by class" not in compare(runs_a, runs_b, fold_of)["all"]
    assert g["stability"]["A"]["within 1 m"] == {"every seed": 1, "some seeds": 1, "no seed": 0}
    assert g["stability"]["B"]["within 1 m"] == {"every seed": 2, "some seeds": 0, "no seed": 0}
    assert report["{2, 3}"]["summed"]["within 1 m"] == [1, 2] and report["all"]["summed"]["within 1 m"] == [4, 6]
    assert report["all"]["paired"]["within 1 m"]["cars"] == 3
    assert_close(sign_test(8, 0), 2 * 0.5 ** 8)
    assert sign_test(0, 0) == 1.0
    with pytest.raises(ValueError, match="same number of seeds"):
        compare(runs_a, runs_b[:1], fold_of)


def test_seed_comparison_reads_each_runs_recorded_seed(monkeypatch, tmp_path):
    import json

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_seeds import run_seed

    (tmp_path / "summary.json").write_text(json.dumps({"full": {}, "_run": {"seed": 3, "frames": 72}}))
    assert run_seed(tmp_path) == 3
    assert run_seed(tmp_path / "elsewhere") is None


def test_restarts_keep_the_lowest_objective_and_average_boxes(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_restarts import agreement, best_of, mean_boxes

    def box(x, z, theta):  # a KITTI car's box at (x, 0, z)
        return [x, 0.0, z, 1.5, 1.6, 3.9, theta]

    label = np.array([box(0.0, 20.0, 0.0)])
    # Three runs of one one-car frame: run 0 is 2 m long with the lowest objective, run 1 exact, run 2 2 m short.
    fitted = np.array([[box(0.0, 22.0, 0.0)], [box(0.0, 20.0, np.pi)], [box(0.0, 18.0, 0.0)]])
    cost = np.array([1.0, 2.0, 3.0])
    loc = np.array([[False], [True], [False]])
    iou = np.array([[0.3], [1.0], [0.3]])
    cars = {"a": (cost, loc, iou > 0.7, iou, fitted, label)}
    one = best_of(cars, ["a"], 1, 3)
    assert_close(np.array([one[s]["within 1 m"] for s in ("objective", "oracle", "worst", "average")]), np.full(4, 1 / 3))
    every = best_of(cars, ["a"], 3, 3)
    assert every["objective"]["within 1 m"] == 0 and every["oracle"]["within 1 m"] == 1
    assert every["worst"]["mean IoU"] == 0.3
    # the mean of the three: at the label (a box turned by pi is the same box), so it passes both tests
    assert every["average"]["within 1 m"] == 1 and every["average"]["IoU > 0.7"] == 1
    mean = mean_boxes(fitted)
    assert_close(mean.location, np.array([[0.0, 0.0, 20.0]]))
    assert_close(np.cos(mean.rotation_y), np.ones(1))
    # of the two pairs whose IoU differs, the lower objective is the better fit in (1, 2), not in (0, 1)
    assert agreement(cars, ["a"]) == {"pairs": 2, "agree": 1, "share": 0.5}


def test_range_profile_finds_the_evidence_range_of_a_car_placed_too_far(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_range_profile import STEPS, scene_profiles
    from wirescene.core.shape import load_default
    from wirescene.core.types import ObjectEstimate, SceneEstimate
    from wirescene.fitting.variants import VARIANTS
    from wirescene.infer.likelihood import GaussianVertexEvidence, instantiate_wireframes
    from wirescene.io.kitti import KittiDataset
    from wirescene.lift import project_boxes

    camera = KittiDataset(KITTI_ROOT).camera("000010")
    model = load_default()
    place = dict(azimuth=np.array([0.4, -1.2]), shape=np.zeros((2, 5)), pitch=np.zeros(2), roll=np.zeros(2),
                 height=1.65)
    truth = instantiate_wireframes(camera, model, x=np.array([-3.0, 4.0]), z=np.array([15.0, 22.0]), **place)
    # the 2D boxes KITTI would label: the projections of the cars' 3D boxes (the wireframes' extents)
    extent = np.matmul(truth.vertices - truth.location[:, None], truth.R)
    boxes = project_boxes(camera, extent.min(1), extent.max(1), truth.location, truth.R)[0]
    evidence = GaussianVertexEvidence(truth.uv, ~truth.self_hidden)
    # the first car fitted 1.5 m too far along its ray (on the plane), the second at the truth
    ray = np.array([-3.0, 15.0]) / np.hypot(3.0, 15.0)
    fitted = instantiate_wireframes(camera, model, x=np.array([-3.0 + 1.5 * ray[0], 4.0]),
                                    z=np.array([15.0 + 1.5 * ray[1], 22.0]), **place)
    cars = [ObjectEstimate(detection_index=j, box2d=boxes[j], score=1.0, location=fitted.location[j], R=fitted.R[j],
                           dims=np.array([1.5, 1.6, 3.9]), cost=0.0, shape=np.zeros(5), vertices=fitted.vertices[j],
                           occluder_mask=0) for j in range(2)]
    scene = SceneEstimate(variant="full", objects=cars, camera_height=1.65, shared_plane=True)
    profiles = scene_profiles(camera, scene, evidence, boxes, variant=VARIANTS["full"], c=0.75, box_weight=100.0)
    for p, slide in zip(profiles, (-1.5, 0.0)):
        for term in ("own parts", "box", "total"):
            at = STEPS[np.argmin(p[term])] * p["range"]
            assert abs(at - slide) < 0.2, (term, at, slide)
    # the bottom side alone (ground contact) and the other three (image size) agree here: the car stands on the plane
    at = [STEPS[np.argmin(profiles[0][t])] * profiles[0]["range"] for t in ("box bottom", "box sides, top")]
    assert_close(np.array(at), np.full(2, -1.5), atol=0.2)


def test_seed_aps_give_each_run_their_mean_and_one_interval(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_seed_aps import seed_aps
    from wirescene.core.labels import Label

    def car(z, score=None):
        return Label("Car", 0.0, 0, 0.0, [100.0, 100.0, 200.0, 200.0], [1.5, 1.6, 3.9], [0.0, 1.6, z], 0.0, score)

    frames = [f"{i:06d}" for i in range(50)]
    gts = [[car(20.0)] for _ in frames]
    runs = [{"full": [[car(20.0, 0.9)] for _ in frames]}, {"full": [[car(23.0, 0.9)] for _ in frames]}]
    out = seed_aps(runs, gts, frames, {f: ("A" if i < 25 else "B") for i, f in enumerate(frames)}, variants=["full"],
                   n_boot=50)["full"]
    assert out["3D AP@0.7"]["runs"][1] == 0.0 and out["3D AP@0.7"]["runs"][0] > 90.0
    assert_close(np.array(out["3D AP@0.7"]["mean"]), np.array(sum(out["3D AP@0.7"]["runs"]) / 2))
    assert out["3D AP@0.7"]["interval"][0] == 0.0 and out["3D AP@0.7"]["interval"][1] > 90.0


def test_label_shapes_benchmark_writes_the_refits_it_measures(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_label_shapes import main, refit_frames, summary
    from wirescene.core.resources import shipped_path
    from wirescene.training.parts_real import load_label_shapes

    models = tmp_path / "models"
    models.mkdir()
    for k in range(4):  # every fold's model the shipped one: enough to exercise the file handling
        (models / f"parts_fold{k}.npz").symlink_to(shipped_path("parts_model"))
    shapes, moves = refit_frames(KITTI_ROOT, models, ["000010"], shape_prior=1e6)
    assert shapes["000010"].shape == (len(moves), 36, 3) and len(moves) > 3
    assert summary(moves)["kept_mean_pct"] == 100.0  # an overwhelming prior keeps every car's mean shape
    main(["--root", str(KITTI_ROOT), "--models", str(models), "--out", str(tmp_path / "s.npz"), "--frames", "000010",
          "--shape-prior", "0", "--json", str(tmp_path / "s.json")])
    written = load_label_shapes(tmp_path / "s.npz")["000010"]
    assert written.shape == shapes["000010"].shape and not np.allclose(written, shapes["000010"])
    assert (tmp_path / "s.json").is_file()


def test_seed_benchmarks_refuse_runs_of_other_frames(monkeypatch, capsys):
    import argparse

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_seeds import same_frames

    ap = argparse.ArgumentParser(prog="bench")
    assert same_frames(ap, {"a": {"000010", "000002"}, "b": {"000002", "000010"}}) == ["000002", "000010"]
    with pytest.raises(SystemExit):
        same_frames(ap, {"a": {"000010", "000002"}, "b": {"000010"}})
    assert "b holds 1 frames and a 2, not the same ones" in capsys.readouterr().err


def test_saved_detections_read_back_as_written_and_name_a_missing_frame(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from _common import read_saved_detections, write_saved_detections
    from wirescene.core.types import Detections

    dets = {"000010": Detections(np.array([[1.0, 2, 30, 40], [5, 6, 70, 80]]), np.array([0.9, 0.4]),
                                 np.array([0.5, -2.0])),
            "000002": Detections(np.zeros((0, 4)), np.zeros(0), np.zeros(0))}
    write_saved_detections(tmp_path / "d.npz", dets)
    back = read_saved_detections(tmp_path / "d.npz")
    assert sorted(back) == ["000002", "000010"]
    for f, d in dets.items():
        for key in ("boxes", "scores", "alpha"):
            assert_close(getattr(back[f], key), getattr(d, key))
    with pytest.raises(SystemExit, match=r"d\.npz: no detections of frame 000003"):
        read_saved_detections(tmp_path / "d.npz", ["000010", "000003"])


def test_device_benchmark_compares_the_cars_of_each_configuration(monkeypatch, tmp_path, capsys):
    import json

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_devices import main, positions

    main(["--root", str(KITTI_ROOT), "--frames", "2", "--variant", "coarse", "--config", "numpy:1",
          "--config", "numpy:2", "--out", str(tmp_path)])
    runs = json.loads((tmp_path / "summary.json").read_text())["runs"]
    assert [r["config"] for r in runs] == ["numpy:1", "numpy:2"]
    # The same seed per frame in one process or two: the same cars, to the last digit written.
    assert runs[1]["compared"] == runs[0]["cars"] > 0 and runs[1]["moved_over_1cm"] == 0
    assert positions(tmp_path / "numpy_1", "coarse") == positions(tmp_path / "numpy_2", "coarse")
    assert "numpy:2" in capsys.readouterr().out


def test_run_configs_fits_each_configuration_on_the_evidence_it_asks_for(monkeypatch):
    """A configuration that turns the mirroring off is fitted on maps read without it."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import wirescene.fitting.pipeline as pipeline
    import wirescene.infer.evidence as evidence
    from _common import run_configs

    read, fitted = {}, []
    real_evidence, real_fit = evidence.part_evidence, pipeline.fit_scene

    def spy_evidence(image, detections, *, flip, **kw):
        read[flip] = real_evidence(image, detections, flip=flip, **kw)
        return read[flip]

    def spy_fit(*args, options, evidence, **kw):
        fitted.append((options.inference.flip_evidence, evidence))
        return real_fit(*args, options=options, evidence=evidence, **kw)

    monkeypatch.setattr(evidence, "part_evidence", spy_evidence)
    monkeypatch.setattr(pipeline, "fit_scene", spy_fit)
    configs = {"mirrored": {}, "plain": {"flip_evidence": False}}
    results, _, n_frames = run_configs(KITTI_ROOT, ["coarse"], configs, frames=1, log=lambda *a: None)
    assert n_frames == 1 and sorted(read) == [False, True]
    assert [flip for flip, _ in fitted] == [True, False]
    assert all(ev is read[flip] for flip, ev in fitted)
    assert len(results[("plain", "coarse")]) == 1


def test_fold_model_splits_hold_each_frame_in_every_fold_but_its_own(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from train_fold_models import write_splits
    from wirescene.io.folds import N_FOLDS, fold_of

    splits = write_splits(KITTI_ROOT, tmp_path)
    frames = {"000002", "000010", "001545"}  # the bundled labelled frames, of folds 0, 3 and 1
    held = {k: set(splits[k].read_text().split()) for k in range(N_FOLDS)}
    for k in range(N_FOLDS):
        assert held[k] == {f for f in frames if fold_of(f) != k}
    assert held[0] == {"000010", "001545"} and held[2] == frames


def test_fold_model_steps_skip_what_exists_and_name_what_failed(monkeypatch, tmp_path, capsys):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from train_fold_models import run_all

    done, made, failing = tmp_path / "done.npz", tmp_path / "made.npz", tmp_path / "never.npz"
    done.write_text("")
    py = sys.executable
    todo = [("kept", done, [py, "-c", "raise SystemExit(3)"]),  # exists: never run
            ("made", made, [py, "-c", f"open({str(made)!r}, 'w').write('x')"]),
            ("bad", failing, [py, "-c", "raise SystemExit(2)"])]
    with pytest.raises(SystemExit, match="failed steps: bad"):
        run_all(todo, tmp_path / "logs", jobs=2)
    out = capsys.readouterr().out
    assert "kept: " in out and "skipped" in out and "made: done" in out and "bad: FAILED (exit 2" in out
    assert made.read_text() == "x" and not failing.exists() and (tmp_path / "logs" / "bad.log").exists()


def test_parts_scale_projection_caps_the_real_patches_and_scales_the_forests(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_train_parts_scale import MAX_REAL_PATCHES, project

    rows = [{"frames": 20, "real_patches": 40_000, "patches": 140_000, "patches_s": 200.0, "final_forest_s": 100.0,
             "calibration_s": 300.0},
            {"frames": 60, "real_patches": 120_000, "patches": 220_000, "patches_s": 600.0, "final_forest_s": 200.0,
             "calibration_s": 600.0}]
    out = project(rows)
    assert out["patches_s"] == {"a": 0.0, "b_per_frame": 10.0}
    assert out["real_patches_per_frame"] == 2000.0
    assert out["patches_3712"] == MAX_REAL_PATCHES + 100_000  # 2,000 a frame would be 7.4 million: capped
    k = np.log(800 / 400) / np.log(220 / 140)
    assert_close(out["forests_exponent"], round(k, 2))
    assert_close(out["projection_3712_h"]["patches"], round(10.0 * 3712 / 3600, 1))
    assert_close(out["projection_3712_h"]["forests"], round(800 * (700_000 / 220_000) ** k / 3600, 1))


def test_viewpoint_classifier_study_trains_the_shipped_recipe_examples_by_default(monkeypatch):
    from conftest import KITTI_ROOT

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_viewpoint_classifier as bench
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.viewpoint_classifier import C, kitti_examples

    assert bench.COPIES["shipped recipe"] == ({}, C)  # the study's baseline is the shipped recipe
    ds = KittiDataset(KITTI_ROOT)
    frames = ds.frame_ids()
    cars = sum(len(ds.labels(f).of_type("Car")) for f in frames)
    x, y = kitti_examples(ds, frames)
    assert len(x) == len(y) == 4 * cars  # each box and one jittered copy, and their mirror images
    more, bins = kitti_examples(ds, frames, **bench.COPIES["three jittered copies"][0], photometric=True)
    assert len(more) == len(bins) == 10 * cars > len(x)


def test_the_synthetic_self_occlusion_labels_side_with_the_wireframe_hull(monkeypatch):
    """The synthetic label (ray to the landmark pushed 3 cm out) agrees with the hull the real
    labels and the fit use more often than the exact ray to the landmark does (RESULTS:
    "Which rule hides a synthetic landmark")."""
    pytest.importorskip("embreex")
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_landmark_visibility import own_hidden
    from wirescene.synth import generate_scene

    hidden = [own_hidden(generate_scene(3, i)) for i in range(3)]
    h = {rule: np.concatenate([x[rule] for x in hidden]) for rule in hidden[0]}
    assert len(h["label"]) > 500 and h["label"].any() and not h["label"].all()
    label, ray = np.mean(h["label"] == h["hull"]), np.mean(h["ray 0.02 m"] == h["hull"])
    assert label > 0.8 and label > ray + 0.02, (label, ray)
