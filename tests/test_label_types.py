"""One rule for which label rows are cars (and DontCare regions, vans, ...): their type in any case,
as KITTI's devkit compares types (``strcasecmp``). A label folder another tool wrote with ``car``
rows gives the evaluation, kitti-eval and training the same cars as one with ``Car`` rows."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import kitti_copy
from wirescene.io.kitti import KittiDataset, read_labels, write_labels

FRAME = "000010"  # 8 Car, 1 Pedestrian and 4 DontCare rows


def lower_types(label_dir: Path) -> None:
    """Write every row's type of the label files in ``label_dir`` in lower case (``car``, ``dontcare``)."""
    for path in label_dir.glob("*.txt"):
        rows = [line.split(maxsplit=1) for line in path.read_text().splitlines() if line.strip()]
        path.write_text("".join(f"{kind.lower()} {rest}\n" for kind, rest in rows))


@pytest.fixture
def roots(tmp_path):
    """``(original, lowered)``: copies of the test frame, the second with its types in lower case."""
    original = kitti_copy(tmp_path / "original", [FRAME])
    lowered = kitti_copy(tmp_path / "lowered", [FRAME])
    lower_types(lowered / "training" / "label_2")
    assert "car 0.00 0 1.95" in (lowered / "training" / "label_2" / f"{FRAME}.txt").read_text()
    return original, lowered


def _cli(*args):
    from click.testing import CliRunner

    from wirescene.cli.main import main

    return CliRunner().invoke(main, [str(a) for a in args])


def test_every_pick_of_a_type_goes_through_the_one_rule():
    """No module compares a row's type itself (``o.type == "Car"``, ``o.type in CAR_TYPES``,
    ``of_type("Car")``): each pick goes through ``is_type`` or ``FrameLabels.of_type``, with
    ``CAR_TYPES`` for the cars."""
    import wirescene

    pattern = re.compile(r'\.type\s*(==|!=)\s*"[A-Z]|\.type\s+(not\s+)?in\b|of_type\("Car"')
    src = Path(wirescene.__file__).parent
    spelt = [f"{path.relative_to(src)}:{n}" for path in sorted(src.rglob("*.py"))
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if pattern.search(line) and not line.lstrip().startswith((">>>", "..."))]
    assert not spelt


def test_lower_case_dontcare_rows_are_kept_apart(roots):
    labels = read_labels(roots[1] / "training" / "label_2" / f"{FRAME}.txt")
    assert (len(labels.objects), len(labels.dontcare)) == (9, 4)
    assert len(labels.of_type("Car")) == 8


def test_evaluation_counts_the_cars_of_lower_case_labels(roots, tmp_path):
    figures = []
    for root in roots:
        out = tmp_path / f"{root.name}.json"
        r = _cli("eval", root, "--variant", "coarse", "--raw-scores", "--frames", FRAME, "--workers", "1",
                 "--draws", "0", "--json", out)
        assert r.exit_code == 0, r.output
        figures.append(json.loads(out.read_text()))
    original, lowered = figures
    assert original["n_gt"] == 8 and original["n_tp"] > 0
    # the paper's tables and KITTI's APs count the same cars (were 0 of 8 against KITTI's 5 moderate cars)
    for key in ("n_gt", "n_tp", "loc_1m", "az_10", "subsets", "counts", "kitti"):
        assert lowered[key] == original[key], key


def test_training_picks_the_cars_of_lower_case_labels(roots):
    from wirescene.core.shape import load_default
    from wirescene.predetect.ap import frame_gt
    from wirescene.predetect.viewpoint_classifier import kitti_examples
    from wirescene.training.kitti_detector import frame_examples, kitti_gt_boxes
    from wirescene.training.parts import kitti_eval_frames
    from wirescene.training.parts_real import kitti_car_wireframes, trainable_car_counts

    mean = load_default().mean

    def picked(root):
        ds = KittiDataset(root)
        labels, camera = ds.labels(FRAME), ds.camera(FRAME)
        gt = frame_gt(labels)
        features, bins = kitti_examples(ds, [FRAME])
        return {
            "detector boxes": kitti_gt_boxes(labels),
            "detector examples": [(e.label_box, e.visible) for e in frame_examples(labels, camera, 1242, 375, 0, mean)],
            "viewpoint examples": (features.shape, bins),
            "real parts": [c.box for c in kitti_car_wireframes(labels, camera, image_size=(1242, 375))],
            "real part counts": trainable_car_counts(ds, [FRAME]),
            "part evaluation": [len(cars) for _, cars in kitti_eval_frames(root, frames=[FRAME])],
            "pre-detection AP": (gt.boxes, gt.ignore, gt.dontcare),
        }

    original, lowered = picked(roots[0]), picked(roots[1])
    assert len(original["detector boxes"]) == 8 and original["real part counts"][FRAME] > 0
    for key, value in original.items():
        np.testing.assert_equal(lowered[key], value, err_msg=key)


def test_kitti_eval_scores_lower_case_labels_and_predictions(roots, tmp_path):
    # kitti-eval's devkit port lowered every type already: this keeps it on the one rule
    results = []
    for root in roots:
        gt_dir = root / "training" / "label_2"
        pred = tmp_path / f"pred_{root.name}"
        pred.mkdir()
        # the ground truth's car rows (picked here, apart from the code under test) as predictions of score 1
        cars = [o for o in read_labels(gt_dir / f"{FRAME}.txt").objects if o.type.lower() == "car"]
        for o in cars:
            o.score = 1.0
        write_labels(pred / f"{FRAME}.txt", cars)
        r = _cli("kitti-eval", gt_dir, pred, "--draws", "0", "--json", tmp_path / f"{root.name}.json")
        assert r.exit_code == 0, r.output
        results.append(json.loads((tmp_path / f"{root.name}.json").read_text()))
    assert results[0]["n_gt"]["car"]["moderate"] == 5 and results[0]["car"]["2d"]["moderate"] > 0
    assert results[1] == results[0]
