"""The confidence written with each car: trained from evaluation records, monotone in
the evidence it was trained on, loud when its artefact is broken."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import KITTI_ROOT
from wirescene.cli.main import main
from wirescene.core.errors import InputError
from wirescene.fitting.confidence import (
    apply_confidence,
    calibrated_confidence,
    confidence_features,
    load_score_calibration,
)


def test_train_scores_from_an_eval_run_and_use_them(tmp_path):
    pred, cal = tmp_path / "pred", tmp_path / "cal.json"
    r = CliRunner().invoke(main, ["eval", str(KITTI_ROOT), "--variant", "coarse", "--variant", "fg+gp", "--raw-scores",
                                  "--predictions", str(pred), "--particles", "15", "--workers", "1",
                                  "--device", "numpy"])
    assert r.exit_code == 0, r.output
    # Raw scores: the label boxes' score 1 is what was written.
    assert {row.split()[15] for row in (pred / "coarse" / "000010.txt").read_text().splitlines()} == {"1"}
    r = CliRunner().invoke(main, ["train", "scores", str(pred), "--out", str(cal)])
    assert r.exit_code == 0, r.output
    record = json.loads(cal.read_text())
    assert record["format"] == "wirescene-score-calibration/1"
    assert record["coarse"]["n"] == 15 and record["fine"]["n"] == 15
    model = load_score_calibration(cal)
    feats = confidence_features([0.9, 0.9], [0.1, 5.0], [[0, 0, 10, 100], [0, 0, 10, 100]])
    p = calibrated_confidence(feats, fine=False, calibration=model)
    assert np.all((p > 0) & (p < 1))


def test_confidence_is_the_calibrated_model_and_keeps_the_detection_score():
    from wirescene.core.types import ObjectEstimate, SceneEstimate

    cal = {s: {"mean": [0, 0, 0], "scale": [1, 1, 1], "weights": [1.0, -1.0, 0.0], "bias": 0.0} for s in ("coarse", "fine")}
    objs = [ObjectEstimate(i, np.array([0, 0, 10, 50.0]), 0.5, np.zeros(3), np.eye(3), np.ones(3), cost)
            for i, cost in enumerate([0.0, 2.0])]
    est = apply_confidence(SceneEstimate("coarse", objs), fine=False, calibration=cal)
    assert [o.detection_score for o in est.cars] == [0.5, 0.5]
    assert est.cars[0].score == pytest.approx(0.5) and est.cars[1].score == pytest.approx(1 / (1 + np.exp(2)))


def test_broken_calibration_is_an_error_naming_the_file(tmp_path):
    bad = tmp_path / "cal.json"
    bad.write_text('{"format": "wirescene-score-calibration/1", "coarse": {}}')
    with pytest.raises(InputError, match="cal.json: malformed score calibration"):
        load_score_calibration(bad)
