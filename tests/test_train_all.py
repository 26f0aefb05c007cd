"""Split files, models directories (`--models`, `models=`) and `wirescene train all`.

``tests/data/kitti/ImageSets/{train,val}.txt`` are the lines of KITTI's standard split
files that name the frames of ``tests/data/kitti`` (000010 is in train, 000002 and 001545
in val).
"""

import functools
import hashlib
import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

import wirescene
from conftest import KITTI_ROOT, assert_close, kitti_copy
from wirescene.cli.main import main
from wirescene.core.errors import InputError
from wirescene.core.resources import ARTEFACTS, DATA_DIR, MANIFEST_FILE, file_sha256, resolve_models, shipped_path
from wirescene.io.splits import read_split_file
from wirescene.predetect.bank import SUPPORT_WEIGHT

SPLITS = KITTI_ROOT / "ImageSets"
LABELLED = ["000002", "000010", "001545"]


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_error(result) -> str:
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wirescene: error: "), result.stderr
    return lines[0]


# -- split files -------------------------------------------------------------------------


def test_standard_split_files_read_in_order():
    assert read_split_file(SPLITS / "val.txt", known=LABELLED) == ["000002", "001545"]
    assert read_split_file(SPLITS / "train.txt") == ["000010"]


@pytest.mark.parametrize("text, problem", [
    ("000010\n000002 000010\n", "line 2: '000002 000010' is not a frame id"),
    ("000010\n\n../000002\n", "line 3: '../000002' is not a frame id"),
    ("000010\n000002\n000010\n", "line 3: frame 000010 is listed twice (first on line 1)"),
    ("000010\n424242\n", "line 2: no labelled frame 424242 in"),
    ("\n  \n", "split file lists no frame id"),
])
def test_bad_split_file_names_file_and_line(tmp_path, text, problem):
    path = tmp_path / "split.txt"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_split_file(path, known=LABELLED, what="labelled frame", where=KITTI_ROOT)
    assert str(info.value).startswith(f"{path}: {problem}")


def test_blank_lines_and_spaces_are_ignored(tmp_path):
    path = tmp_path / "split.txt"
    path.write_text("\n 001545 \n\n000002\r\n")
    assert read_split_file(path, known=LABELLED) == ["001545", "000002"]
    with pytest.raises(InputError, match="split file not found"):
        read_split_file(tmp_path / "nope.txt")


def test_eval_split_file_selects_exactly_its_frames(tmp_path):
    pred = tmp_path / "pred"
    r = cli("eval", KITTI_ROOT, "--variant", "coarse", "--split-file", SPLITS / "val.txt", "--particles", 10,
            "--workers", 1, "--predictions", pred)
    assert r.exit_code == 0, r.output
    assert sorted(p.stem for p in (pred / "coarse").glob("*.txt")) == ["000002", "001545"]
    assert sorted(p.stem for p in (pred / ".frames").glob("*.json")) == ["000002", "001545"]
    # the API takes the same file and fits the same frames
    by_file = wirescene.evaluate(KITTI_ROOT, variants="coarse", split_file=SPLITS / "val.txt", particles=10)
    by_list = wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000002", "001545"], particles=10)
    assert json.dumps(by_file["coarse"].metrics, sort_keys=True) == json.dumps(by_list["coarse"].metrics, sort_keys=True)
    assert by_file["coarse"].counts["frames"] == 2
    assert sorted({r.frame_id for r in by_file["coarse"].records}) == ["000002", "001545"]
    with pytest.raises(wirescene.ArgumentError, match="^split_file: "):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000002"], split_file=SPLITS / "val.txt")


def test_split_file_errors_are_one_line(tmp_path):
    bad = tmp_path / "split.txt"
    bad.write_text("000002\n000099\n")
    for command in (["eval", KITTI_ROOT], ["predict", KITTI_ROOT, "--split", "training", "--out", tmp_path / "p"],
                    ["detect", KITTI_ROOT], ["train", "detector", "--kitti-root", KITTI_ROOT, "--out", tmp_path / "b.npz"],
                    ["train", "parts", "--kitti-root", KITTI_ROOT, "--out", tmp_path / "p.npz"],
                    ["train", "all", KITTI_ROOT, "--out", tmp_path / "m"]):
        line = one_line_error(cli(*command, "--split-file", bad))
        assert f"{bad}: line 2: no " in line and "000099" in line, line
    assert not (tmp_path / "p").exists() and not (tmp_path / "m").exists() and not (tmp_path / "b.npz").exists()
    line = one_line_error(cli("eval", KITTI_ROOT, "--frames", "000002", "--split-file", SPLITS / "val.txt"))
    assert "--frames and --split-file" in line


# -- nothing writes into the package -------------------------------------------------------


def _package_state():
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in DATA_DIR.iterdir() if p.is_file()}


@pytest.mark.parametrize("command", [
    ["train", "detector", "--kitti-root", KITTI_ROOT, "--frames", "000010"],
    ["train", "parts", "--kitti-root", KITTI_ROOT, "--frames", "000010"],
    ["train", "occlusion", "--scenes", "1"],
    ["train", "shape"],
    ["train", "scores", "somewhere"],
    ["train", "all", KITTI_ROOT],
])
def test_training_without_out_is_refused_and_leaves_the_package_alone(command):
    before = _package_state()
    r = cli(*command)
    assert "--out" in one_line_error(r)
    assert _package_state() == before


@pytest.mark.parametrize("command", ["all", "viewpoints", "parts", "detector"])
def test_train_commands_take_the_kitti_root_in_either_form(tmp_path, command):
    """`train all ROOT` and `train parts --kitti-root ROOT` are the README's spellings: each command takes both (the
    split file's unknown id, an error naming the root, shows that the root was read), and refuses two roots."""
    split = tmp_path / "split.txt"
    split.write_text("999999\n")
    out = tmp_path / ("models" if command == "all" else "out.npz")
    for form in ([KITTI_ROOT], ["--kitti-root", KITTI_ROOT], [KITTI_ROOT, "--kitti-root", KITTI_ROOT]):
        line = one_line_error(cli("train", command, *form, "--split-file", split, "--out", out))
        assert f"{split}: line 1: no labelled frame 999999" in line, (form, line)  # train viewpoints said "no frame"
    line = one_line_error(cli("train", command, KITTI_ROOT, "--kitti-root", tmp_path, "--out", out))
    assert "KITTI_ROOT" in line and "--kitti-root" in line and "two roots" in line, line
    if command in ("all", "viewpoints"):  # a root they cannot train without
        line = one_line_error(cli("train", command, "--out", out))
        assert "KITTI_ROOT or --kitti-root" in line, line
    assert not out.exists()


@pytest.mark.parametrize("command", ["all", "viewpoints", "parts", "detector"])
def test_one_root_named_through_a_link_is_one_root(tmp_path, command):
    """KITTI_ROOT and --kitti-root naming one folder, one of them through a symbolic link, are one root (they were
    refused as two): the split file's unknown id, an error naming the root, shows that it was read."""
    link = tmp_path / "link"
    link.symlink_to(KITTI_ROOT, target_is_directory=True)
    split = tmp_path / "split.txt"
    split.write_text("999999\n")
    out = tmp_path / ("models" if command == "all" else "out.npz")
    for form in ([KITTI_ROOT, "--kitti-root", link], [link, "--kitti-root", f"{KITTI_ROOT}/"]):
        line = one_line_error(cli("train", command, *form, "--split-file", split, "--out", out))
        assert f"{split}: line 1: no labelled frame 999999" in line, (form, line)
    assert not out.exists()


@pytest.mark.parametrize("command, usage", [("all", " KITTI_ROOT"), ("viewpoints", " KITTI_ROOT"),
                                            ("parts", " [KITTI_ROOT]"), ("detector", " [KITTI_ROOT]")])
def test_the_usage_line_shows_the_root_required_where_it_is(command, usage):
    """`train all|viewpoints` cannot go without a root (in either form): their usage line showed it optional."""
    r = cli("train", command, "--help")
    assert r.exit_code == 0 and r.output.splitlines()[0].endswith(f"[OPTIONS]{usage}"), r.output.splitlines()[0]


def test_train_parts_and_detector_name_both_forms_of_the_root(tmp_path):
    """Their options of real frames said `needs --kitti-root` / `With --kitti-root` where KITTI_ROOT serves too."""
    forms = "a KITTI root (KITTI_ROOT or --kitti-root)"
    for command, given in (("parts", ["--label-shapes", tmp_path / "s.npz"]), ("parts", ["--frames", "000010"]),
                           ("detector", ["--frames", "000010"]), ("detector", ["--per-octave", "3"])):
        line = one_line_error(cli("train", command, *given, "--out", tmp_path / "o.npz"))
        assert forms in line, line
    for command in ("parts", "detector"):
        text = " ".join(cli("train", command, "--help").output.split())
        assert "With --kitti-root" not in text and "needs --kitti-root" not in text and "With a KITTI root" in text
        assert "The KITTI_ROOT argument gives it too." in text
    assert not (tmp_path / "o.npz").exists()


def test_train_viewpoints_decodes_every_image_before_training(tmp_path, monkeypatch):
    """As the other train commands: a truncated image is refused in one line before any crop is made (it was found
    where the training read it, after the frames before it)."""
    from wirescene.predetect import viewpoint_classifier

    root = kitti_copy(tmp_path / "kitti", ["000002", "000010"])
    image = root / "training" / "image_2" / "000010.png"  # the last frame read
    image.write_bytes(image.read_bytes()[:-2000])

    def no_training(*args, **kwargs):
        raise AssertionError("the training started")

    monkeypatch.setattr(viewpoint_classifier, "kitti_examples", no_training)
    line = one_line_error(cli("train", "viewpoints", root, "--out", tmp_path / "v.npz"))
    assert f"{image}: corrupt or truncated image" in line, line
    assert not (tmp_path / "v.npz").exists()


# the train commands of real frames
TRAIN_ON_ROOT = ["all", "detector", "viewpoints", "parts", "parts --no-calibrate"]


def _train(command, root, tmp_path, *more):
    """`wirescene train COMMAND ROOT --out` a path under ``tmp_path``, and ``more``."""
    name, *options = command.split()
    out = tmp_path / ("models" if name == "all" else f"{name}.npz")
    return cli("train", name, root, "--out", out, *options, *more)


def _no_image_read(monkeypatch):
    """Make any read of an image (its pixels or its header) fail the test."""
    from wirescene.io.kitti import KittiDataset

    def read(self, frame_id):
        raise AssertionError(f"image of {frame_id} read")

    monkeypatch.setattr(KittiDataset, "image", read)
    monkeypatch.setattr(KittiDataset, "image_size", read)


@pytest.mark.parametrize("command", TRAIN_ON_ROOT)
def test_train_commands_refuse_a_split_without_labels_before_reading_an_image(tmp_path, monkeypatch, command):
    """A split without label_2/ (KITTI's testing/ given as the root, or a root whose training/ has none) is refused at
    once in one line naming it: train detector and viewpoints decoded every image first (some 90 s of KITTI's 7,518),
    train parts of one drive said its held-out calibration needed frames of 2 or more folds (with --no-calibrate it
    said the reason after its synthetic scenes, minutes in)."""
    _no_image_read(monkeypatch)
    testing = kitti_copy(tmp_path / "k", ["000010"], subdirs=("image_2", "calib"), split="testing") / "testing"
    unlabelled = kitti_copy(tmp_path / "u", LABELLED, subdirs=("image_2", "calib"))
    for root, split in ((testing, testing), (unlabelled, unlabelled / "training")):
        for frames in ([], ["--frames", "000010"], ["--frames", "424242"]):  # the labels before any frame
            line = one_line_error(_train(command, root, tmp_path, *frames))
            assert line == f"wirescene: error: {split}: training needs label_2/ ground truth", (root, frames, line)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k", "u"]  # nothing written


@pytest.mark.parametrize("command", TRAIN_ON_ROOT)
def test_train_frames_unknown_names_the_labelled_frames_and_their_folder(tmp_path, command):
    """--frames said "no frame X in the dataset" where --split-file says "no labelled frame X in DIR": a frame with an
    image but no label file was "not in the dataset"; now both say which frames count and where they were looked for."""
    root = kitti_copy(tmp_path / "kitti", LABELLED)
    (root / "training" / "label_2" / "000010.txt").unlink()  # its image stays
    for frames, unknown in (("000010", "000010"), ("000002,424242,999999", "424242 (and 1 more)")):
        line = one_line_error(_train(command, root, tmp_path, "--frames", frames))
        assert line == f"wirescene: error: --frames: no labelled frame {unknown} in {root / 'training'}", line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kitti"]


@pytest.mark.parametrize("command", TRAIN_ON_ROOT)
def test_train_commands_refuse_a_label_without_its_image_before_training(tmp_path, monkeypatch, command):
    """A label file whose frame has no image is refused in one line naming the image, before any step trains (the
    frames of a training are its label files: an image without one is not trained on, as --frames says above)."""
    def no_training(*a, **kw):
        raise AssertionError("the training started")

    for target in ("wirescene.training.pipeline._Run", "wirescene.training.parts.train_part_detector",
                   "wirescene.training.kitti_detector.train_detector_bank_kitti",
                   "wirescene.predetect.viewpoint_classifier.kitti_examples"):
        monkeypatch.setattr(target, no_training)
    root = kitti_copy(tmp_path / "kitti", LABELLED)
    image = root / "training" / "image_2" / "000010.png"
    image.unlink()
    line = one_line_error(_train(command, root, tmp_path))
    assert line == f"wirescene: error: {image}: image file not found", line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kitti"]


# -- models directories -------------------------------------------------------------------


def test_models_directory_rules(tmp_path):
    with pytest.raises(InputError, match="models directory not found"):
        resolve_models(tmp_path / "nope")
    with pytest.raises(InputError, match="not a models directory"):
        resolve_models(tmp_path)
    shutil.copy(shipped_path("occlusion"), tmp_path / "occlusion.json")
    models = resolve_models(tmp_path)  # without a manifest: the files present
    assert models.own == ("occlusion",)
    assert models.path("occlusion") == (tmp_path / "occlusion.json").resolve()
    assert models.path("parts_model") == shipped_path("parts_model")  # what it lacks is shipped
    manifest = {"format": "wirescene-models/1", "complete": False, "artefacts": ["occlusion"],
                "steps": {"parts": {"done": True}}}
    (tmp_path / MANIFEST_FILE).write_text(json.dumps(manifest))
    with pytest.raises(InputError, match=r"training not finished \(steps done: parts\)"):
        resolve_models(tmp_path)
    manifest.update(complete=True, artefacts=["occlusion", "detector_bank"])
    (tmp_path / MANIFEST_FILE).write_text(json.dumps(manifest))
    with pytest.raises(InputError, match="detector_bank.npz is listed in models.json but missing"):
        resolve_models(tmp_path)
    manifest.update(artefacts=[])
    (tmp_path / MANIFEST_FILE).write_text(json.dumps(manifest))
    with pytest.raises(InputError, match="occlusion.json is not listed in models.json"):
        resolve_models(tmp_path)
    manifest.update(artefacts=["occlusion"])
    (tmp_path / MANIFEST_FILE).write_text(json.dumps(manifest))
    assert resolve_models(tmp_path).own == ("occlusion",)
    written = hashlib.sha256((tmp_path / "occlusion.json").read_bytes()).hexdigest()
    manifest["steps"]["occlusion"] = {"done": True, "artefact": "occlusion.json", "sha256": written}
    (tmp_path / MANIFEST_FILE).write_text(json.dumps(manifest))
    assert resolve_models(tmp_path).own == ("occlusion",)
    (tmp_path / "occlusion.json").write_text((tmp_path / "occlusion.json").read_text() + " ")  # replaced by hand
    with pytest.raises(InputError, match="occlusion.json: not the file its training wrote"):
        resolve_models(tmp_path)
    line = one_line_error(cli("eval", KITTI_ROOT, "--frames", "000002", "--models", tmp_path / "nope"))
    assert "models directory not found" in line


def test_models_directory_replaces_c_and_an_explicit_file_wins(tmp_path):
    from wirescene.fitting.models import with_models
    from wirescene.fitting.options import FitOptions
    from wirescene.infer.occluded_score import save_occluded_score

    save_occluded_score(tmp_path / "occlusion.json", {"c": -2.75})
    shutil.copy(shipped_path("parts_model"), tmp_path / "parts_model.npz")
    options = with_models(FitOptions(detector_bank="my_bank.npz"), resolve_models(tmp_path))
    assert options.inference.occluded_score == -2.75
    assert options.parts_model == str((tmp_path / "parts_model.npz").resolve())
    assert options.detector_bank == "my_bank.npz"
    shutil.copy(shipped_path("score_calibration"), tmp_path / "score_calibration.json")
    options = with_models(FitOptions(shape_model="my_shape.npz"), resolve_models(tmp_path))
    assert options.score_calibration == str((tmp_path / "score_calibration.json").resolve())
    assert options.shape_model == "my_shape.npz" and options.viewpoint_classifier is None  # kept; what it lacks: shipped
    (tmp_path / "score_calibration.json").unlink()
    # the CLI's and the API's options go through the same resolver
    from wirescene.api import _options
    from wirescene.cli.main import _fit_options

    for options in (_fit_options(10, 0, models=tmp_path), _options(None, 10, 0, tmp_path)):
        assert options.inference.occluded_score == -2.75 and options.parts_model.endswith("parts_model.npz")
    with pytest.raises(wirescene.ArgumentError, match="^models: "):
        wirescene.fit(KITTI_ROOT / "training" / "image_2" / "000010.png", KITTI_ROOT / "training" / "calib" / "000010.txt",
                      [[354, 185, 549, 294]], models=3)


# -- train all -----------------------------------------------------------------------------

# Seconds, not minutes: tiny forests and banks, no part calibration (its folds: the next test).
TINY = ["--set", "parts.n_trees=3", "--set", "parts.max_depth=8", "--set", "parts.synth_scenes=0",
        "--set", "parts.calibrate_real=0",
        "--set", "detector.n_partial=0", "--set", "detector.mining_rounds=1", "--set", "detector.neg_per_image=10",
        "--set", "detector.min_pos=20", "--set", "detector.min_height=40", "--set", "detector.max_scale=1.0",
        "--set", "detector.per_octave=2", "--set", "occlusion.n_scenes=2", "--set", "occlusion.grid=[-1, 0, 1]"]


def test_held_out_folds_are_drives_where_known_and_frames_otherwise(tmp_path):
    from wirescene.io.folds import drive_map
    from wirescene.io.kitti import KittiDataset
    from wirescene.training.parts import real_folds
    from wirescene.training.pipeline import calibration_folds

    # 000002 and 000010 are frames of known drives; a copy under an unknown id is a group of its own
    dataset = KittiDataset(kitti_copy(tmp_path / "kitti", ["000002", "000010", "001545"], rename={"001545": "900001"}))
    folds = calibration_folds(dataset, ["000002", "000010", "900001"], n_folds=2)
    # cars: 000010 8, 900001 6, 000002 1 -> the largest group alone, the other two together
    assert folds == {"000010": 0, "900001": 1, "000002": 1}
    assert calibration_folds(dataset, ["000002", "000010", "900001"], n_folds=4) == \
        {"000010": 0, "900001": 1, "000002": 2}
    assert real_folds(["900001", "000010"], folds).tolist() == [1, 0]  # the parts' calibration takes them
    with pytest.raises(InputError, match="at least two drives"):
        calibration_folds(dataset, ["000010"])
    # the devkit's mapping files of a user's KITTI: 000002 and 000010 recorded on one drive, one group now
    mapping = tmp_path / "kitti" / "devkit" / "mapping"
    mapping.mkdir(parents=True)
    (mapping / "train_mapping.txt").write_text("2011_09_26 2011_09_26_drive_0005_sync 0000000001\n")
    (mapping / "train_rand.txt").write_text(",".join(["1"] * 11))
    drives, where = drive_map(dataset.base_dir)
    assert where == mapping
    assert drive_map(KittiDataset(tmp_path / "kitti" / "training").base_dir)[1] == mapping  # the split given
    assert calibration_folds(dataset, ["000002", "000010", "900001"], n_folds=2, drives=drives) == \
        {"000010": 0, "000002": 0, "900001": 1}


def test_a_bad_drive_map_is_refused_before_training(tmp_path):
    line = one_line_error(cli("train", "all", KITTI_ROOT, "--out", tmp_path / "m", "--drive-map", tmp_path))
    assert "no train_rand.txt here" in line and str(tmp_path) in line
    assert not (tmp_path / "m").exists()
    r = cli("train", "detector", "--out", tmp_path / "b.npz", "--drive-map", tmp_path)
    assert r.exit_code == 2 and "--drive-map needs a KITTI root (KITTI_ROOT or --kitti-root)" in r.stderr
    r = cli("train", "parts", "--out", tmp_path / "p.npz", "--kitti-root", KITTI_ROOT, "--drive-map", tmp_path)
    assert "no train_rand.txt here" in one_line_error(r)  # the calibration is on by default: its folds read the map
    r = cli("train", "parts", "--out", tmp_path / "p.npz", "--kitti-root", KITTI_ROOT, "--drive-map", tmp_path,
            "--no-calibrate")
    assert r.exit_code == 2 and "--drive-map needs a KITTI root (KITTI_ROOT or --kitti-root) and --calibrate" in r.stderr
    for without in (["--no-calibration"], ["--calibration", "9,1,0.4"]):  # no held-out calibration to group
        r = cli("train", "detector", "--out", tmp_path / "b.npz", "--kitti-root", KITTI_ROOT, "--drive-map", tmp_path,
                *without)
        assert r.exit_code == 2 and "not with --no-calibration or --calibration" in r.output + r.stderr
    assert not any(tmp_path.glob("*.npz"))


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """`train all` on two frames of two drives (two held-out folds), with a tiny recipe."""
    base = tmp_path_factory.mktemp("train_all")
    split = base / "split.txt"
    split.write_text("000010\n001545\n")
    out = base / "models"
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY)
    assert r.exit_code == 0, r.output + r.stderr
    return out, split, r


def _mtimes(out):
    return {f: (out / f).stat().st_mtime_ns for f in ARTEFACTS.values() if (out / f).exists()}


def test_train_all_writes_a_manifest_and_loadable_models(trained):
    from wirescene.infer.occluded_score import load_occluded_score
    from wirescene.parts.detector import PartDetector
    from wirescene.predetect.bank import DetectorBank
    from wirescene.predetect.viewpoint_classifier import ViewpointClassifier

    out, split, r = trained
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    assert manifest["format"] == "wirescene-models/1" and manifest["complete"] is True
    assert manifest["wirescene"] == wirescene.__version__
    assert manifest["environment"]["numpy"] == np.__version__  # with the BLAS kernels: they change trained files
    assert "blas" in manifest["environment"]
    assert manifest["artefacts"] == ["parts_model", "detector_bank", "viewpoint_classifier", "occlusion"]
    assert manifest["shipped"] == ["score_calibration"]
    data = manifest["data"]
    assert data["frames"] == 2 and data["frame_ids"] == ["000010", "001545"] and data["cars"] == 14
    # each image's content, by which an evaluation of a copy of the root elsewhere tells the frames trained on
    assert data["images_sha256"] == {f: file_sha256(KITTI_ROOT / "training" / "image_2" / f"{f}.png")
                                     for f in ("000010", "001545")}
    assert data["split_file"] == str(split.resolve())
    assert manifest["calibration_folds"]["fold_of"] == {"000010": 0, "001545": 1}
    assert manifest["calibration_folds"]["frames_with_known_drive"] == 2  # the shared frames' drives
    assert manifest["calibration_folds"]["devkit_mapping"] is None  # tests/data/kitti holds no devkit
    assert list(manifest["steps"]) == ["parts", "detector", "viewpoints", "score_calibration", "occlusion"]
    for step in ("parts", "detector", "viewpoints", "occlusion"):
        record = manifest["steps"][step]
        assert record["done"] and record["seconds"] >= 0 and record["peak_rss_mb"] > 10
        assert record["sha256"] == hashlib.sha256((out / record["artefact"]).read_bytes()).hexdigest()
    assert manifest["steps"]["detector"]["key"]["options"]["threshold"] == 0.5  # the shipped recipe's
    assert manifest["steps"]["parts"]["key"]["options"]["n_trees"] == 3  # --set
    assert manifest["steps"]["detector"]["calibration"]["n_folds"] == 2
    parts = PartDetector.load(out / "parts_model.npz")
    assert parts.kind == "ghog_ms" and parts.position and parts.meta["real_frames"] == "000010,001545"
    bank = DetectorBank.load(out / "detector_bank.npz")
    assert bank.calibration is not None and bank.threshold == 0.5
    assert bank.meta["support_weight"] == SUPPORT_WEIGHT  # the recipe's, set on the finished bank
    assert np.isfinite(load_occluded_score(out / "occlusion.json"))
    classifier = ViewpointClassifier.load(out / "viewpoint_classifier.npz")
    assert classifier.meta["frames"] == ["000010", "001545"] and manifest["steps"]["viewpoints"]["crops"] == 56
    alone = out.parent / "viewpoints_alone.npz"  # the step is the recipe of `train viewpoints`, byte for byte
    assert cli("train", "viewpoints", KITTI_ROOT, "--split-file", split, "--out", alone).exit_code == 0
    assert alone.read_bytes() == (out / "viewpoint_classifier.npz").read_bytes()
    assert resolve_models(out).own == ("parts_model", "detector_bank", "viewpoint_classifier", "occlusion")
    assert "shipped" in r.output and "models written to" in r.output and "2 frames of known drive)" in r.output
    # the run's peak, kept across the resets that measure each step's (which /usr/bin/time sees the last of alone)
    assert manifest["peak_rss_mb"] >= max(record["peak_rss_mb"] for record in manifest["steps"].values()
                                          if "peak_rss_mb" in record)
    assert r.stdout.rstrip().endswith(f"; peak memory {manifest['peak_rss_mb']:.0f} MB"), r.stdout
    assert "\r" not in r.stderr and "\x1b" not in r.stderr  # no progress bar drawn where stderr is no terminal


def test_a_train_all_file_records_its_manifest_s_frames_and_the_held_out_line_says_them_once(trained, tmp_path):
    """Each frame-trained file of `train all` carries the record of its frames' images that a standalone training's
    does, the manifest's own (the bank's held-out calibration's frames are its training frames): evaluated in the
    directory the manifest's line alone says them (not the file's too); the file copied elsewhere, without its
    manifest, says them by its record."""
    from wirescene.core.artefacts import read_trained_images
    from wirescene.eval.held_out import trained_on_frames
    from wirescene.fitting.options import FitOptions
    from wirescene.io.kitti import KittiDataset

    out, _, _ = trained
    images = json.loads((out / MANIFEST_FILE).read_text())["data"]["images_sha256"]
    names = ("parts_model", "detector_bank", "viewpoint_classifier")
    assert all(read_trained_images(out / ARTEFACTS[name]) == images for name in names)
    options = FitOptions(**{name: str(out / ARTEFACTS[name]) for name in names})
    dataset = KittiDataset(KITTI_ROOT)
    assert trained_on_frames(dataset, ["000002", "000010"], options=options, read=names) == [
        f"1 of the 2 frames evaluated is among those the part model, detector bank and viewpoint classifier of {out} "
        "were trained on (e.g. 000010): its figures are not held out"]
    assert trained_on_frames(dataset, ["000002"], options=options, read=names) == []
    alone = shutil.copy(out / "detector_bank.npz", tmp_path / "bank.npz")
    assert trained_on_frames(dataset, ["000002", "001545"], options=FitOptions(detector_bank=str(alone)),
                             read=["detector_bank"]) == [
        f"1 of the 2 frames evaluated is among those the detector bank {alone} was trained on (e.g. 001545): its "
        "figures are not held out"]


def test_a_copy_of_the_root_elsewhere_resumes_the_same_training(trained, tmp_path):
    """The resume key holds the frames' files' content, not the root's path: the same frames in a copy of the root
    (another disk, a bind mount) keep every step, where they retrained all four."""
    out, split, _ = trained
    copy = kitti_copy(tmp_path / "kitti", ["000010", "001545"])
    models = shutil.copytree(out, tmp_path / "models")
    r = cli("train", "all", copy, "--split-file", split, "--out", models, *TINY, "--resume")
    assert r.exit_code == 0 and r.stderr.count("done in an earlier run, kept") == 4, r.output + r.stderr


def test_a_resumed_run_s_peak_memory_is_at_least_that_of_the_steps_it_keeps(trained, tmp_path, monkeypatch):
    """A resumed run that trained no step wrote its own process's peak (reading the frames: some 70 MB) over the
    earlier run's and said it on its last line, below steps kept at hundreds of MB: the run's peak is at least each
    step's."""
    from wirescene.training import pipeline

    out, split, _ = trained
    models = shutil.copytree(out, tmp_path / "models")
    monkeypatch.setattr(pipeline, "_peak_memory_mb", lambda: 1.0)  # this process: far below any step's
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", models, *TINY, "--resume")
    assert r.exit_code == 0 and r.stderr.count("done in an earlier run, kept") == 4, r.output + r.stderr
    manifest = json.loads((models / MANIFEST_FILE).read_text())
    steps = max(record["peak_rss_mb"] for record in manifest["steps"].values() if "peak_rss_mb" in record)
    assert manifest["peak_rss_mb"] == steps > 10, (manifest["peak_rss_mb"], steps)
    assert r.stdout.rstrip().endswith(f"; peak memory {steps:.0f} MB"), r.stdout

def test_train_all_resume_skips_finished_steps(trained):
    out, split, _ = trained
    before = _mtimes(out)
    line = one_line_error(cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY))
    assert "already holds models" in line and "--resume" in line
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY, "--resume")
    assert r.exit_code == 0, r.output + r.stderr
    assert r.stderr.count("done in an earlier run, kept") == 4
    assert r.stdout.count("(kept from an earlier run)") == 4, r.stdout  # the summary's costs are an earlier run's
    assert _mtimes(out) == before
    # options set to their defaults train the same: every step is kept
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY, "--set", "parts.n_jobs=1",
            "--set", "detector.whiten=false", "--set", "viewpoints.seed=0", "--set", "occlusion.flip=false",
            "--resume")
    assert r.exit_code == 0 and r.stderr.count("done in an earlier run, kept") == 4, r.output + r.stderr
    assert _mtimes(out) == before
    # another option of the last step: only that step runs again
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY, "--set", "occlusion.n_scenes=1",
            "--resume")
    assert r.exit_code == 0, r.output + r.stderr
    # what changed is said (hours of training again on a whole KITTI)
    assert "occlusion: the earlier run's record does not match (option n_scenes): training again" in r.stderr
    summary = [line for line in r.stdout.splitlines() if "kept from an earlier run" in line]
    assert [line.split()[0] for line in summary] == ["parts", "detector", "viewpoints"], r.stdout
    after = _mtimes(out)
    assert after["occlusion.json"] != before["occlusion.json"]
    assert {f: t for f, t in after.items() if f != "occlusion.json"} == \
        {f: t for f, t in before.items() if f != "occlusion.json"}
    assert json.loads((out / MANIFEST_FILE).read_text())["steps"]["occlusion"]["key"]["options"]["n_scenes"] == 1
    assert resolve_models(out).own == ("parts_model", "detector_bank", "viewpoint_classifier", "occlusion")
    # a directory of an older `train all`, without the classifier step: it loads, and a resumed run adds the step
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    classifier = (out / "viewpoint_classifier.npz").read_bytes()
    del manifest["steps"]["viewpoints"]
    manifest["artefacts"].remove("viewpoint_classifier")
    (out / MANIFEST_FILE).write_text(json.dumps(manifest))
    (out / "viewpoint_classifier.npz").unlink()
    assert resolve_models(out).own == ("parts_model", "detector_bank", "occlusion")
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY, "--set", "occlusion.n_scenes=1",
            "--resume")
    assert r.exit_code == 0 and r.stderr.count("done in an earlier run, kept") == 3, r.output + r.stderr
    assert (out / "viewpoint_classifier.npz").read_bytes() == classifier
    assert resolve_models(out).own == ("parts_model", "detector_bank", "viewpoint_classifier", "occlusion")


def test_resume_sees_changed_frames_and_a_failed_one_leaves_the_directory_as_it_was(tmp_path, monkeypatch):
    import wirescene.training.occlusion as occlusion

    root = kitti_copy(tmp_path / "kitti", ["000010", "001545"])
    out = tmp_path / "models"
    args = ["train", "all", root, "--out", out, *TINY, "--workers", "1"]
    assert cli(*args).exit_code == 0
    finished = (out / MANIFEST_FILE).read_bytes()
    mtimes = _mtimes(out)

    @functools.wraps(occlusion.calibrate_occluded_score)  # its options stay those --set checks
    def broken(*a, **k):
        raise RuntimeError("the occlusion step broke")

    with monkeypatch.context() as patch:  # a step that fails after three kept ones
        patch.setattr(occlusion, "calibrate_occluded_score", broken)
        r = cli(*args, "--set", "occlusion.n_scenes=3", "--resume")
    assert isinstance(r.exception, RuntimeError) and r.stderr.count("done in an earlier run, kept") == 3
    assert (out / MANIFEST_FILE).read_bytes() == finished and _mtimes(out) == mtimes
    assert resolve_models(out).own == ("parts_model", "detector_bank", "viewpoint_classifier", "occlusion")
    image = root / "training" / "image_2" / "001545.png"
    image.rename(tmp_path / "away.png")  # a missing image is found before any step, not inside one
    line = one_line_error(cli(*args, "--resume"))
    assert f"{image}: image file not found" in line and (out / MANIFEST_FILE).read_bytes() == finished
    (tmp_path / "away.png").rename(image)
    calib = root / "training" / "calib" / "001545.txt"
    kept = calib.read_bytes()
    calib.write_text("P2: 1 2 3\n")  # malformed: found before any step too
    line = one_line_error(cli(*args, "--resume"))
    assert str(calib) in line and (out / MANIFEST_FILE).read_bytes() == finished
    calib.write_bytes(kept)
    label = root / "training" / "label_2" / "001545.txt"
    rows = label.read_text().splitlines(keepends=True)
    first = next(i for i, ln in enumerate(rows) if ln.startswith("Car"))
    label.write_text("".join(rows[:first] + rows[first + 1:]))  # a car less: every step learns from other data
    r = cli(*args, "--resume")
    assert r.exit_code == 0, r.output + r.stderr
    assert "done in an earlier run, kept" not in r.stderr and r.stderr.count("does not match") == 4
    assert "parts: the earlier run's record does not match (the frames' label, calibration or image files)" in r.stderr
    assert json.loads((out / MANIFEST_FILE).read_text())["data"]["cars"] == 13


def test_the_resume_key_sees_an_image_replaced_by_another_of_the_same_size(tmp_path):
    from PIL import Image

    from wirescene.io.kitti import KittiDataset
    from wirescene.training.pipeline import _check_frames

    root = kitti_copy(tmp_path / "kitti", ["000010"])
    image = root / "training" / "image_2" / "000010.png"
    rgb = np.asarray(Image.open(image).convert("RGB"))
    Image.fromarray(rgb).save(image, compress_level=0)  # stored: its size is the pixels', whatever they show
    before, size = _check_frames(KittiDataset(root), ["000010"]), image.stat().st_size
    Image.fromarray(rgb[:, ::-1].copy()).save(image, compress_level=0)  # the frame mirrored
    assert image.stat().st_size == size
    after = _check_frames(KittiDataset(root), ["000010"])
    assert after[1] == before[1] == 8 and after[0] != before[0]


def test_a_first_step_that_fails_leaves_no_directory(tmp_path, monkeypatch):
    import wirescene.training.parts as parts

    @functools.wraps(parts.train_part_detector)  # its options stay those --set checks
    def broken(*a, **k):
        raise RuntimeError("the parts step broke")

    monkeypatch.setattr(parts, "train_part_detector", broken)
    r = cli("train", "all", KITTI_ROOT, "--out", tmp_path / "new" / "models", *TINY)
    assert isinstance(r.exception, RuntimeError) and not (tmp_path / "new").exists()


def test_train_all_needs_two_groups_and_known_options(tmp_path):
    line = one_line_error(cli("train", "all", KITTI_ROOT, "--frames", "000010", "--out", tmp_path / "m"))
    assert "at least two drives" in line
    # with the part calibration off and the bank's given, no fold is held out: one drive will do
    r = cli("train", "all", KITTI_ROOT, "--frames", "000010", "--out", tmp_path / "one", *TINY, "--set",
            "detector.calibration=[4.0416, -2.3012, 0.6323]")
    assert r.exit_code == 0, r.output + r.stderr
    assert json.loads((tmp_path / "one" / MANIFEST_FILE).read_text())["calibration_folds"]["n_folds"] == 0
    line = one_line_error(cli("train", "all", KITTI_ROOT, "--out", tmp_path / "m", "--set", "parts.nope=1"))
    assert "--set" in line and "no option 'nope'" in line
    assert not (tmp_path / "m").exists()


@pytest.mark.parametrize("setting, problem", [
    ("parts.n_trees=0", "parts.n_trees must be at least 1, got 0"),  # was a traceback of scikit-learn
    ("parts.kind=foo", "parts.kind must be one of sc, hog, ghog"),
    ("detector.C=nan", "detector.C must be a finite number"),  # was a traceback after the whole parts step
    ("occlusion.n_scenes=0", "occlusion.n_scenes must be at least 1"),
    ("detector.threshold=2", "detector.threshold must be at most 1"),  # was a bank that never detects
    ("detector.mining_rounds=-1", "detector.mining_rounds must be at least 0"),
    ("detector.mining_images=0", "detector.mining_images must be at least 1"),
    ("parts.synth_seed=5", "parts.synth_seed must be at least 1000"),  # was a traceback in the parts step
    ("occlusion.grid=abc", "occlusion.grid must be a list of numbers"),  # was one after two steps
    ("parts.n_jobs=0", "parts.n_jobs must not be 0"),
    ("parts.n_trees=3000", "parts.n_trees must be at most 1000, got 3000"),  # was hours of forests, then a slow model
    ("detector.per_octave=60", "detector.per_octave must be at most 48, got 60"),  # was a bank 10x slower, to use too
    ("detector.mining_rounds=300", "detector.mining_rounds must be at most 20, got 300"),  # each some 2.5 h a split
    ("detector.cut_paste=1000", "detector.cut_paste must be at most 50, got 1000"),
    ("detector.max_negatives=10000000", "detector.max_negatives must be at most 100000, got 10000000"),  # 4.8 kB each
    ("detector.pyramid_cache_mb=1000000", "detector.pyramid_cache_mb must be at most 16000, got 1000000"),
    ("parts.synth_scenes=100000", "parts.synth_scenes must be at most 3000, got 100000"),  # 4 MB of patches each
    ("parts.n_views=10000", "parts.n_views must be at most 360, got 10000"),
    ("parts.n_aug=1000", "parts.n_aug must be at most 20, got 1000"),
    ("occlusion.n_scenes=100000", "occlusion.n_scenes must be at most 3000, got 100000"),
    ("parts.max_depth=1000", "parts.max_depth must be at most 100, got 1000"),  # every fit's part maps: a step a level
    ("detector.mining_images=1000000", "detector.mining_images must be at most 100000, got 1000000"),
    ("detector.n_partial=50", "detector.n_partial must be at most 20, got 50"),  # some 7 a viewpoint can be found
])
def test_train_all_checks_the_values_it_is_set_before_any_step(tmp_path, setting, problem):
    from wirescene.training.pipeline import check_options

    line = one_line_error(cli("train", "all", KITTI_ROOT, "--out", tmp_path / "m", "--set", setting))
    assert "--set" in line and problem in line
    assert not (tmp_path / "m").exists()
    documented = {"parts": {"class_weight": "balanced_subsample", "max_real_patches": None, "n_jobs": -1},
                  "detector": {"mining_images": None}, "occlusion": {"grid": [0.5, 0.75]}}
    assert check_options(documented)["parts"]["n_jobs"] == -1  # what the steps document is taken


@pytest.mark.parametrize("n_folds", [1, 0, 26, 10**6, 2.5, True])
def test_train_all_takes_2_to_25_folds_checked_before_any_step(tmp_path, n_folds):
    """The API's ``n_folds`` as ``--folds``, before any work: a fold held out leaves the others' frames to train
    on (1 was refused by the parts step, 2.5 a TypeError), and each fold trains a bank and a part forest again, so
    at most MAX_FOLDS (26 began the training)."""
    from wirescene.training.pipeline import train_all
    from wirescene.training.scale import MAX_FOLDS

    with pytest.raises(ValueError, match=rf"^n_folds must be an integer from 2 to {MAX_FOLDS}, got {n_folds!r}$"):
        train_all(tmp_path / "m", KITTI_ROOT, n_folds=n_folds)
    assert not (tmp_path / "m").exists()


def test_train_parts_defaults_are_the_shipped_recipe(tmp_path):
    from wirescene.cli.parts import parts
    from wirescene.training.pipeline import RECIPE

    recipe = RECIPE["parts"]
    defaults = {p.name: p.default for p in parts.params}
    assert {k: defaults[k] for k in ("kind", "position", "smooth", "synth_scenes")} == \
        {k: recipe[k] for k in ("kind", "position", "smooth", "synth_scenes")}
    assert recipe["calibrate_real"]  # on by default with --kitti-root: one frame holds no second fold out
    out = tmp_path / "p.npz"
    line = one_line_error(cli("train", "parts", "--kitti-root", KITTI_ROOT, "--frames", "000010", "--synth-scenes",
                              "0", "--out", out))
    assert line.startswith("wirescene: error: calibrate_real: ") and "--no-calibrate" in line, line
    line = one_line_error(cli("train", "parts", "--calibrate", "--out", out))
    assert "--calibrate needs a KITTI root (KITTI_ROOT or --kitti-root)" in line, line
    assert not out.exists()


def test_models_replace_the_bank_and_the_resume_fingerprint(trained, tmp_path):
    """The tiny bank detects other boxes than the shipped one, everywhere a bank is
    loaded (API, `detect`, `eval --detections bank`), and eval's resume records tell the
    two runs apart."""
    out, _, _ = trained
    image = KITTI_ROOT / "training" / "image_2" / "000010.png"
    calib = KITTI_ROOT / "training" / "calib" / "000010.txt"
    shipped = wirescene.detect(image, calib)
    own = wirescene.detect(image, calib, models=out)
    assert len(own) != len(shipped) or not np.allclose(own.boxes, shipped.boxes)
    from wirescene.api import as_camera, as_image
    from wirescene.predetect.bank import DetectorBank, detect_cars

    rgb = as_image(image)
    direct = detect_cars(rgb, bank=DetectorBank.load(out / "detector_bank.npz"),
                         camera=as_camera(calib, (rgb.shape[1], rgb.shape[0])))
    np.testing.assert_array_equal(own.boxes[:len(direct)], direct.boxes)  # then the enlarged image's cars, if any
    np.testing.assert_array_equal(wirescene.detect(image, calib, models=out, upsample=1).boxes, direct.boxes)
    r = cli("detect", KITTI_ROOT, "--frames", "000010", "--out", tmp_path / "dets", "--models", out)
    assert r.exit_code == 0 and f"models from {out.resolve()}" in r.stderr
    written = json.loads((tmp_path / "dets" / "000010.json").read_text())["detections"]
    kept = own.subset(own.scores > DetectorBank.load(out / "detector_bank.npz").threshold)
    np.testing.assert_allclose([d["box"] for d in written], kept.boxes, atol=0.01)
    from wirescene.core.viewpoints import viewpoint_bin

    # the files carry the viewpoints the pipeline gives the boxes, as wirescene.detect does
    assert [d["viewpoint_bin"] for d in written] == [int(b) for b in viewpoint_bin(kept.alpha)]
    pred = tmp_path / "pred"
    common = ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", "000010", "--particles", 10, "--workers", 1,
              "--detections", "bank", "--predictions", pred]
    r = cli(*common, "--models", out)
    assert r.exit_code == 0
    assert (f"1 of the 1 frames evaluated is among those the detector bank and viewpoint classifier of {out} were "
            "trained on (e.g. 000010)") in r.stderr
    # label boxes fitted by `coarse` read neither the bank nor the part model: nothing to warn of but the shipped
    # score calibration, which the directory lacks
    r = cli("eval", KITTI_ROOT, "--variant", "coarse", "--frames", "000010", "--workers", 1, "--detections", "gt",
            "--models", out)
    assert r.exit_code == 0 and f"of {out} w" not in r.stderr
    assert "among the 72 the shipped score calibration was trained on (e.g. 000010)" in r.stderr
    record = json.loads((pred / ".frames" / "000010.json").read_text())
    from wirescene.eval.metrics import FrameResult

    fitted = FrameResult.from_dict(record["variants"]["coarse"]["result"]).det_boxes
    # the tiny bank's boxes (those the fit's verification keeps)
    assert len(fitted) and all(np.isclose(own.boxes, box, rtol=1e-7, atol=0).all(axis=1).any() for box in fitted)
    assert record["config"]["models"]["detector_bank"] == hashlib.sha256(
        (out / "detector_bank.npz").read_bytes()).hexdigest()
    # the same bank file, the shipped crop classifier (and part model, which coarse variants do not read): the
    # record is not reused
    r = cli(*common, "--bank", out / "detector_bank.npz", "--resume")
    assert r.exit_code == 0 and "written with a different configuration" in r.stderr
    assert "models.viewpoint_classifier" in r.stderr and "models.detector_bank" not in r.stderr
    assert "parts_model" not in r.stderr
    r = cli(*common, "--bank", out / "detector_bank.npz", "--resume")
    assert r.exit_code == 0 and "1 of 1 frames already done" in r.stderr


def test_interrupted_train_all_resumes_to_the_same_artefacts(trained, tmp_path, monkeypatch):
    """A run stopped in the detector step (after the parts), resumed (with other
    --workers), writes the parts model and detector bank of the uninterrupted run, array
    for array."""
    import wirescene.training.kitti_detector as kitti_detector
    from wirescene.predetect.bank import DetectorBank

    reference, split, _ = trained
    out = tmp_path / "models"

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(kitti_detector, "train_detector_bank_kitti", interrupted)
        r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY, "--workers", "1")
    assert r.exit_code == 130  # Ctrl-C's code in a shell, and the steps trained said to stay
    assert "wirescene: interrupted; the steps --out holds stay (--resume goes on from them)" in r.stderr
    assert (out / "parts_model.npz").is_file() and not (out / "detector_bank.npz").exists()
    assert json.loads((out / MANIFEST_FILE).read_text())["complete"] is False
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY, "--workers", "2", "--resume")
    assert r.exit_code == 0, r.output + r.stderr
    assert r.stderr.count("done in an earlier run, kept") == 1  # the parts
    for name in ("parts_model.npz", "detector_bank.npz"):
        with np.load(reference / name) as a, np.load(out / name) as b:
            assert sorted(a.files) == sorted(b.files)
            for key in a.files:
                if key != "meta_json":
                    np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}: {key}")
    bank, ref = DetectorBank.load(out / "detector_bank.npz"), DetectorBank.load(reference / "detector_bank.npz")
    strip = ("train_seconds",)
    assert {k: v for k, v in bank.meta.items() if k not in strip} == {k: v for k, v in ref.meta.items() if k not in strip}
    # (the occlusion step, run afresh here, reads only the parts model; the reference's was
    # retrained with other options by the resume test above)


def test_train_all_takes_a_given_calibration_and_refuses_a_bad_one(tmp_path):
    """``--set detector.calibration=[a, b, c]`` skips the fold banks (the shipped recipe's way);
    a malformed one, or a pair without the verifier's weight, is refused before any step trains."""
    from wirescene.predetect.bank import DetectorBank
    from wirescene.predetect.channels import N_CHANNEL_FEATURES

    split = tmp_path / "split.txt"
    split.write_text("000010\n001545\n")
    out = tmp_path / "models"
    r = cli("train", "all", KITTI_ROOT, "--split-file", split, "--out", out, *TINY,
            "--set", "detector.calibration=[2.5, -1.0, 0.5]")
    assert r.exit_code == 0, r.output + r.stderr
    manifest = json.loads((out / "models.json").read_text())
    assert manifest["steps"]["detector"]["calibration"] == {"a": 2.5, "b": -1.0, "c": 0.5, "source": "given"}
    bank = DetectorBank.load(out / "detector_bank.npz")
    assert_close(bank.calibration, [2.5, -1.0])
    assert float(bank.verifier["gain"]) == pytest.approx(0.2)  # c / a: the logit's weight in margin units
    # the verifier reads what the box refinement reads (HOG cells, geometry) and the colour channels
    assert bank.needs_channels and len(bank.verifier["mean"]) == len(bank.refinement["mean"]) + N_CHANNEL_FEATURES
    for bad in ("[1]", "[0, 1, 1]", "[1, nan, 1]", "[2.5, -1.0]", "[1, 1, -1]", "fast"):
        line = one_line_error(cli("train", "all", KITTI_ROOT, "--out", tmp_path / "bad", *TINY,
                                  "--set", f"detector.calibration={bad}"))
        assert "--set" in line and "detector.calibration" in line, (bad, line)
        assert not (tmp_path / "bad").exists()


def test_peak_memory_is_unknown_not_an_import_error_where_the_os_has_no_resource_module(monkeypatch):
    import sys

    from wirescene.training import pipeline

    assert pipeline._peak_memory_mb() > 10
    monkeypatch.setitem(sys.modules, "resource", None)  # as on Windows
    assert pipeline._peak_memory_mb() is None


def test_a_runs_peak_memory_outlives_the_resets_that_measure_each_step():
    """Each step resets the process's peak to measure its own, so that the process's (what /usr/bin/time reports) is
    the last step's alone: the run keeps the peak before every reset."""
    from wirescene.training import pipeline

    peak = pipeline._RunPeak()
    big = np.ones(300 << 17)  # 300 MB, every page written
    del big
    before = pipeline._peak_memory_mb()
    if not peak.reset():
        pytest.skip("no resettable peak here (Linux's /proc/self/clear_refs)")
    assert pipeline._peak_memory_mb() < before - 100  # the process's peak is reset ...
    assert peak.mb >= before and peak.total() >= before  # ... the run's is kept
