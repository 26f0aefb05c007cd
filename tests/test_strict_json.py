"""The JSON files users read are strict JSON: a non-finite figure is ``null``, never the ``NaN`` /
``Infinity`` tokens that jq, JavaScript's ``JSON.parse`` and other strict parsers refuse."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from conftest import KITTI_ROOT, kitti_copy
from wirescene.cli.main import main
from wirescene.core.jsonio import dumps, strict_values, write_json


def strict_loads(text: str):
    """``json.loads`` as a strict parser reads: ``NaN``, ``Infinity`` and ``-Infinity`` refused."""
    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    return json.loads(text, parse_constant=refuse)


def _no_car_root(tmp_path):
    """A KITTI root of one grey frame (000010's size and camera) whose only label is a pedestrian."""
    root = kitti_copy(tmp_path / "kitti", ["000010"])
    image = root / "training" / "image_2" / "000010.png"
    width, height = Image.open(image).size
    Image.fromarray(np.full((height, width, 3), 128, np.uint8)).save(image)
    (root / "training" / "label_2" / "000010.txt").write_text(
        "Pedestrian 0.00 0 -0.20 712.40 143.00 810.73 307.92 1.89 0.48 1.20 1.84 1.47 8.41 0.01\n")
    return root


def test_strict_values_replaces_every_non_finite_float(tmp_path):
    value = {"ap": np.float32("nan"), "inf": np.inf, "low": -np.inf, np.int64(3): (np.bool_(True), None),
             "rows": np.array([[1.0, np.nan]]), "nested": [{"x": float("nan")}, "NaN"]}
    assert strict_values(value) == {"ap": None, "inf": None, "low": None, 3: [True, None], "rows": [[1.0, None]],
                                    "nested": [{"x": None}, "NaN"]}  # the string stays a string
    assert strict_loads(dumps(value)) == json.loads(json.dumps(strict_values(value)))
    path = write_json(tmp_path / "a" / "out.json", {"median": float("nan")})
    assert strict_loads(path.read_text()) == {"median": None}
    with pytest.raises(TypeError):  # what it cannot write is refused, not written as a string
        dumps({"where": object()})


def test_detect_json_of_a_frame_without_cars_is_strict(tmp_path):
    """AP and precision of a split without a car: null (they were NaN)."""
    root = _no_car_root(tmp_path)
    out = tmp_path / "ap.json"
    r = CliRunner().invoke(main, ["detect", str(root), "--upsample", "1", "--out", str(tmp_path / "dets"),
                                  "--json", str(out)])
    assert r.exit_code == 0, r.output
    data = strict_loads(out.read_text())
    assert data["ap"]["n_gt"] == 0 and data["ap"]["ap"] is None and data["ap"]["viewpoint_bin_acc"] is None
    assert data["at_threshold"]["precision"] is None and data["kitti_2d_ap"]["moderate"]["ap"] is None
    for path in (tmp_path / "dets").glob("*.json"):  # --out's files, if the bank found a box on grey
        strict_loads(path.read_text())


def test_kitti_eval_json_of_an_empty_subset_is_strict(tmp_path):
    root = _no_car_root(tmp_path)
    pred = tmp_path / "pred"
    pred.mkdir()
    (pred / "000010.txt").write_text("")
    out = tmp_path / "k.json"
    r = CliRunner().invoke(main, ["kitti-eval", str(root / "training" / "label_2"), str(pred), "--json", str(out),
                                  "--draws", "20"])
    assert r.exit_code == 0, r.output
    data = strict_loads(out.read_text())
    assert data["n_gt"]["car"]["moderate"] == 0 and data["car"]["3d"]["moderate"] is None
    assert data["kitti_interval"]["car"]["3d"] is None


def test_evaluation_report_json_of_empty_subsets_is_strict():
    from wirescene.eval.metrics import FrameResult, evaluate
    from wirescene.io.kitti import Label

    car = Label("Car", 0.0, 0, 0.3, [100, 100, 200, 160], [1.5, 1.6, 4.0], [2.0, 1.6, 20.0], 0.4)
    frame = FrameResult("000001", [car], det_boxes=[[102, 100, 200, 160]], det_alpha=[np.nan], det_scores=[0.9],
                        est_location=[[2.0, 1.6, 20.5]], est_dims=[[1.5, 1.6, 4.0]], est_rotation_y=[0.45],
                        est_alpha=[0.35])
    data = strict_loads(dumps(evaluate([frame]).to_json_dict(include_records=True)))
    assert data["subsets"]["occ>0"]["loc_1m"] is None and data["occ_pred_acc"] is None
    assert data["records"][0]["loc_error"] == pytest.approx(0.5)


def test_fit_output_json_writes_non_finite_values_as_null(tmp_path):
    """The JSON file of ``fit`` (``write_fit_outputs``): a car's unknown detection score, an infinite cost."""
    from wirescene.core.groundplane import rotation_y
    from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate
    from wirescene.io.kitti import KittiDataset
    from wirescene.io.outputs import write_fit_outputs

    ds = KittiDataset(KITTI_ROOT)
    box = np.array([300.0, 180.0, 520.0, 300.0])
    car = ObjectEstimate(detection_index=0, box2d=box, score=0.8, location=np.array([-2.0, 1.65, 12.0]),
                         R=rotation_y(0.3), dims=np.array([1.5, 1.6, 3.9]), cost=np.inf, detection_score=np.nan)
    detections = Detections(box[None], [0.9], np.nan, "api")
    estimate = SceneEstimate(variant="coarse", objects=[car], detections=detections,
                             extras={"objective_history": [np.nan, 1.0]})
    paths = write_fit_outputs(tmp_path, "000010", image=ds.image("000010"), camera=ds.camera("000010"),
                              estimate=estimate, detections=detections)
    data = strict_loads(paths["json"].read_text())
    (written,) = data["objects"]
    assert written["cost"] is None and written["detection_score"] is None and written["score"] == 0.8
    assert data["objective_history"] == [None, 1.0] and written["location"] == [-2.0, 1.65, 12.0]


def test_detection_file_with_a_null_alpha_reads_as_no_viewpoint(tmp_path):
    """A detection without a viewpoint written as strict JSON (alpha null) reads back as NaN."""
    from wirescene.core.types import Detections
    from wirescene.io.detections import read_detections

    dets = Detections([[300, 180, 520, 300], [600, 170, 680, 230]], scores=[0.9, 0.4], alpha=[np.pi / 2, np.nan])
    entries = [{"box": b, "score": s, "alpha": a} for b, s, a in zip(dets.boxes, dets.scores, dets.alpha)]
    path = write_json(tmp_path / "000010.json", {"detections": entries})
    assert strict_loads(path.read_text())["detections"][1]["alpha"] is None
    back = read_detections(path)
    np.testing.assert_array_equal(back.boxes, dets.boxes)
    assert back.scores.tolist() == [0.9, 0.4]
    assert back.alpha[0] == pytest.approx(np.pi / 2) and np.isnan(back.alpha[1])
    (tmp_path / "bins.json").write_text('[{"box": [300, 180, 520, 300], "viewpoint_bin": null}]')
    assert np.isnan(read_detections(tmp_path / "bins.json").alpha).all()  # a null bin: no viewpoint either


@pytest.mark.parametrize("source", [
    # real frames, the shipped recipe's kind: one frame and a given calibration (no held-out fold banks to train)
    ["--kitti-root", KITTI_ROOT, "--frames", "000010", "--calibration", "4,-2,0.6", "--per-octave", 2, "--workers", 1,
     "--mining-rounds", 0],
    # synthetic scenes: the bank's meta (numpy arrays) and the validation's figures
    ["--scenes", 2, "--val-scenes", 1, "--mining-rounds", 0],
], ids=["kitti", "synthetic"])
def test_train_detector_report_is_json_with_its_keys(tmp_path, source):
    report = tmp_path / "report.json"
    r = CliRunner().invoke(main, [str(a) for a in ["train", "detector", *source, "--partial", 0, "--out",
                                                   tmp_path / "bank.npz", "--report", report]])
    assert r.exit_code == 0, r.output + r.stderr
    data = strict_loads(report.read_text())
    assert {"n_detectors", "names", "total_seconds"} <= set(data) and data["n_detectors"] == len(data["names"]) > 0
    if "--kitti-root" in source:
        assert set(data) == {"frames", "calibration", "n_detectors", "names", "total_seconds"}
        assert data["frames"] == ["000010"] and data["calibration"] == {"a": 4.0, "b": -2.0, "c": 0.6,
                                                                        "source": "given"}
    else:
        assert data["n_scenes"] == 2 and data["validation"]["n_scenes"] == 1 and 0 <= data["validation"]["ap"] <= 1
        assert len(data["full_box_correction"]) == len(data["bins"])  # an array of the bank's meta, as a list


@pytest.mark.parametrize("kind", ["bank", "classifier"])
def test_trained_file_meta_is_strict_json_and_reads_back(tmp_path, kind):
    """A bank's or viewpoint classifier's ``meta_json`` (a synthetic bank's validation summary can hold NaN):
    strict JSON, NaN as null; an older file's NaN token still reads; a shipped file's meta keeps its bytes."""
    from dataclasses import replace

    from wirescene.core.artefacts import load_npz, save_npz
    from wirescene.predetect import bank as module_bank
    from wirescene.predetect import viewpoint_classifier as module_clf

    module = module_bank if kind == "bank" else module_clf
    shipped = module.load_default_bank() if kind == "bank" else module.load_default_classifier()
    stored = str(np.load(module.DATA_DIR / ("detector_bank.npz" if kind == "bank" else "viewpoint_classifier.npz"))
                 ["meta_json"])
    model = replace(shipped, meta={**shipped.meta, "validation": {"ap": float("nan"), "n": 2},
                                   "ratio": -np.inf})
    path = model.save(tmp_path / "model.npz")
    arrays = load_npz(path, kind=module.ARTEFACT_KIND, version=module.FORMAT_VERSION)
    assert strict_loads(str(arrays["meta_json"]))["validation"] == {"ap": None, "n": 2}
    back = type(model).load(path)
    assert back.meta == {**shipped.meta, "validation": {"ap": None, "n": 2}, "ratio": None}
    # a file written before, with json.dumps' NaN token, reads as it did
    old = save_npz(tmp_path / "old.npz", {**arrays, "meta_json": np.array('{"validation": {"ap": NaN}}')},
                   kind=module.ARTEFACT_KIND, version=module.FORMAT_VERSION)
    assert np.isnan(type(model).load(old).meta["validation"]["ap"])
    # a meta of finite values: the bytes json.dumps wrote (the shipped file re-saves identical)
    assert str(np.load(shipped.save(tmp_path / "again.npz"))["meta_json"]) == stored == json.dumps(shipped.meta,
                                                                                                      sort_keys=True)
