"""The trained files a user retrains on their own data (crop viewpoint classifier, score
calibration, shape model), each read by the fit from an explicit option, a field of
``FitOptions`` or a models directory: every test changes one file on purpose and checks
that the fit's output, or its resume fingerprint, follows it."""

import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

import wirescene
from conftest import KITTI_ROOT
from wirescene.cli.main import main
from wirescene.core.errors import InputError
from wirescene.core.resources import ARTEFACTS, MANIFEST_FILE, shipped_path
from wirescene.core.shape import ShapeModel, load_default
from wirescene.core.viewpoints import viewpoint_bin
from wirescene.fitting.models import model_files_read, models_fingerprint, options_read
from wirescene.fitting.options import FitOptions, PredetectOptions
from wirescene.lift import LiftingOptions

SPLIT = KITTI_ROOT / "training"
IMAGE, CALIB = SPLIT / "image_2" / "000010.png", SPLIT / "calib" / "000010.txt"
BOXES = [[354.43, 185.52, 549.52, 294.49], [600.0, 170.0, 700.0, 230.0]]  # no viewpoint: the box rule gives theirs
FAST = LiftingOptions(n_particles=5)


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def forced_classifier(path, k: int):
    """The shipped classifier made to put every crop in viewpoint bin ``k``."""
    from wirescene.predetect.viewpoint_classifier import ViewpointClassifier, load_default_classifier

    c = load_default_classifier()
    bias = np.full(8, -50.0)
    bias[k] = 50.0
    ViewpointClassifier(c.mean, c.scale, np.zeros_like(c.weights), bias, dict(c.meta)).save(path)
    return path


def shifted_calibration(path, *, right: float = 0.0, car: float = 0.0):
    """The shipped score calibration with ``right`` added to the coarse confidence's bias and
    ``car`` to the coarse car model's (the verification of our own boxes)."""
    record = json.loads(shipped_path("score_calibration").read_text())
    record["coarse"]["bias"] += right
    record["car"]["coarse"]["bias"] += car
    path.write_text(json.dumps(record))
    return path


def renamed_shape_model(path, *, scale: float = 1.1, components: int | None = None):
    """The shipped shape model ``scale`` times larger, its exemplars renamed ``mine-N`` (and
    only its first ``components``)."""
    m = load_default()
    k = m.n_components if components is None else components
    ShapeModel(m.mean * scale, m.components[:k], m.stds[:k], m.explained_variance_ratio[:k],
               tuple(f"mine-{i}" for i in range(len(m.exemplars))), m.exemplars * scale).save(path)
    return path


def models_dir(path, **files):
    """A models directory put together by hand: ``{artefact: file}`` copied under their names."""
    path.mkdir()
    for name, file in files.items():
        shutil.copy(file, path / shipped_path(name).name)
    return path


def test_a_viewpoint_classifier_of_an_option_or_a_models_directory_gives_boxes_their_viewpoints(tmp_path):
    forced = forced_classifier(tmp_path / "forced.npz", 5)
    shipped = wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", particles=5)
    assert set(viewpoint_bin(shipped.detections.alpha)) != {5}
    own = wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", options=FitOptions(FAST, viewpoint_classifier=str(forced)))
    assert viewpoint_bin(own.detections.alpha).tolist() == [5, 5]
    models = models_dir(tmp_path / "models", viewpoint_classifier=forced)
    assert viewpoint_bin(wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", particles=5, models=models)
                         .detections.alpha).tolist() == [5, 5]
    # an explicit file wins over the directory's
    explicit = FitOptions(FAST, viewpoint_classifier=str(shipped_path("viewpoint_classifier")))
    np.testing.assert_array_equal(wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", options=explicit,
                                                models=models).detections.alpha, shipped.detections.alpha)
    # the command line: --viewpoint-classifier and --models alike, the same labels
    dets = tmp_path / "dets.json"
    dets.write_text(json.dumps([{"box": b} for b in BOXES]))
    common = ["fit", IMAGE, "--calib", CALIB, "--detections", dets, "--variant", "coarse", "--particles", 5]
    fitted = {}
    for name, extra in (("option", ["--viewpoint-classifier", forced]), ("models", ["--models", models])):
        r = cli(*common, *extra, "--out", tmp_path / name)
        assert r.exit_code == 0, r.output + r.stderr
        fitted[name] = [o["alpha"] for o in json.loads((tmp_path / name / "000010.json").read_text())["objects"]]
    assert fitted["option"] == fitted["models"] == [c.alpha for c in own.cars] != [c.alpha for c in shipped.cars]
    # our own detections: `wirescene detect --out` and wirescene.detect write the classifier's viewpoints
    r = cli("detect", KITTI_ROOT, "--frames", "000010", "--out", tmp_path / "found", "--viewpoint-classifier", forced)
    assert r.exit_code == 0, r.output + r.stderr
    written = json.loads((tmp_path / "found" / "000010.json").read_text())["detections"]
    assert written and {d["viewpoint_bin"] for d in written} == {5}
    assert set(viewpoint_bin(wirescene.detect(IMAGE, CALIB, models=models, upsample=1.0).alpha)) == {5}
    # the directory's classifier for `detect --models` too, and the option's over it (one lookup: Models.file);
    # which file is read shows in the image's own boxes (--upsample 1: the classifier of both passes is above)
    bins = {}
    for name, extra in (("shipped", []), ("models", ["--models", models]),
                        ("option", ["--models", models, "--viewpoint-classifier", shipped_path("viewpoint_classifier")])):
        r = cli("detect", KITTI_ROOT, "--frames", "000010", "--upsample", 1, "--out", tmp_path / f"detect-{name}",
                *extra)
        assert r.exit_code == 0, r.output + r.stderr
        written = json.loads((tmp_path / f"detect-{name}" / "000010.json").read_text())["detections"]
        bins[name] = [d["viewpoint_bin"] for d in written]
    assert set(bins["models"]) == {5} != set(bins["shipped"]) and bins["option"] == bins["shipped"]


def test_models_file_is_the_given_file_else_the_directory_s_else_none_for_the_shipped_one(tmp_path):
    """The one lookup of the files a loader reads (the fit's options, ``detect`` of the API and the
    command line): a file given wins, else the directory's own, else None (the loaders' shipped file)."""
    from wirescene.core.resources import SHIPPED, resolve_models

    models = resolve_models(models_dir(tmp_path / "models", viewpoint_classifier=shipped_path("viewpoint_classifier")))
    assert models.file("viewpoint_classifier") == str(models.root / "viewpoint_classifier.npz")
    assert models.file("viewpoint_classifier", given="mine.npz") == "mine.npz"
    assert models.file("detector_bank") is None and SHIPPED.file("viewpoint_classifier") is None
    assert SHIPPED.file("detector_bank", given="bank.npz") == "bank.npz"
    with pytest.raises(KeyError, match="unknown artefact 'bank'"):
        models.file("bank", given="bank.npz")


def test_a_score_calibration_of_an_option_or_a_models_directory_scores_and_verifies_the_cars(tmp_path):
    higher = shifted_calibration(tmp_path / "higher.json", right=3.0)
    shipped = wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", particles=5)
    own = wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", options=FitOptions(FAST, score_calibration=str(higher)))
    assert all(o.score > s.score for o, s in zip(own.cars, shipped.cars))
    # once refused ("cannot be used yet"), a directory's own calibration now replaces the shipped one
    models = models_dir(tmp_path / "models", score_calibration=higher)
    via = wirescene.fit(IMAGE, CALIB, BOXES, variant="coarse", particles=5, models=models)
    assert [c.score for c in via.cars] == [c.score for c in own.cars]
    # the fit's verification of our own boxes reads its car model: one that calls nothing a car keeps no car
    # (our own boxes of the image alone, not enlarged too: the verification reads them all alike)
    nothing = shifted_calibration(tmp_path / "nothing.json", car=-100.0)
    alone = PredetectOptions(upsample=1.0)
    assert wirescene.fit(IMAGE, CALIB, variant="coarse", options=FitOptions(FAST, predetect=alone)).cars
    assert not wirescene.fit(IMAGE, CALIB, variant="coarse",
                             options=FitOptions(FAST, score_calibration=str(nothing), predetect=alone)).cars
    r = cli("fit", IMAGE, "--calib", CALIB, "--variant", "coarse", "--particles", 5, "--upsample", 1,
            "--score-calibration", nothing, "--out", tmp_path / "out")
    assert r.exit_code == 0 and "no car found" in r.stderr, r.output + r.stderr


def test_a_shape_model_of_an_option_or_a_models_directory_gives_the_wireframes(tmp_path):
    mine = renamed_shape_model(tmp_path / "mine.npz")
    settings = {"inference.iterations": 2}
    shipped = wirescene.fit(IMAGE, CALIB, BOXES[:1], variant="fg", particles=3, settings=settings)
    own = wirescene.fit(IMAGE, CALIB, BOXES[:1], variant="fg", settings=settings,
                        options=FitOptions(LiftingOptions(n_particles=3), shape_model=str(mine)))
    assert not shipped.cars[0].cad_model.startswith("mine-") and own.cars[0].cad_model.startswith("mine-")
    assert not np.allclose(own.cars[0].vertices, shipped.cars[0].vertices)
    models = models_dir(tmp_path / "models", shape_model=mine)
    dets = tmp_path / "dets.json"
    dets.write_text(json.dumps([{"box": BOXES[0]}]))
    r = cli("fit", IMAGE, "--calib", CALIB, "--detections", dets, "--variant", "fg", "--particles", 3,
            "--iterations", 2, "--models", models, "--out", tmp_path / "out")
    assert r.exit_code == 0, r.output + r.stderr
    assert all(o["exemplar"].startswith("mine-") for o in json.loads((tmp_path / "out" / "000010.json")
                                                                   .read_text())["objects"])
    # a model of fewer components than the fine stage searches: refused naming the file, coarse variants read none
    few = renamed_shape_model(tmp_path / "few.npz", components=3)
    with pytest.raises(InputError, match=r"few\.npz: shape model of 3 components, the fine stage searches 5"):
        wirescene.fit(IMAGE, CALIB, BOXES[:1], variant="fg", options=FitOptions(shape_model=str(few)))
    assert wirescene.fit(IMAGE, CALIB, BOXES[:1], variant="coarse", options=FitOptions(FAST, shape_model=str(few))).cars


def test_the_resume_fingerprint_holds_the_files_the_fit_reads_and_no_other(tmp_path):
    fingerprint = models_fingerprint(FitOptions())
    assert set(fingerprint) == {"parts_model", "detector_bank", "viewpoint_classifier", "score_calibration",
                                "shape_model"}
    # raw scores read no calibration, unless the verification of our own boxes does
    assert "score_calibration" not in models_fingerprint(FitOptions(calibrate_scores=False,
                                                                    predetect=PredetectOptions(min_car_probability=0)))
    assert "score_calibration" in models_fingerprint(FitOptions(calibrate_scores=False))
    assert "score_calibration" not in models_fingerprint(FitOptions(calibrate_scores=False), own=False)
    # coarse variants read neither the part model nor the shape model; true vertices read no part model
    assert set(models_fingerprint(FitOptions(), fine=False, own=False)) == {"detector_bank", "viewpoint_classifier",
                                                                            "score_calibration"}
    assert "parts_model" not in models_fingerprint(FitOptions(), evidence="oracle")
    mine = renamed_shape_model(tmp_path / "mine.npz")
    assert models_fingerprint(FitOptions(shape_model=str(mine)))["shape_model"] != fingerprint["shape_model"]
    calibration = tmp_path / "calibration.json"
    shutil.copy(shipped_path("score_calibration"), calibration)
    pred = tmp_path / "pred"
    common = ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", "000010", "--workers", 1, "--particles", 5,
              "--predictions", pred, "--score-calibration", calibration]
    r = cli(*common, "--models", models_dir(tmp_path / "models", shape_model=mine))
    assert r.exit_code == 0, r.output + r.stderr
    record_path = pred / ".frames" / "000010.json"
    config = json.loads(record_path.read_text())["config"]
    assert set(config["models"]) == {"detector_bank", "viewpoint_classifier", "score_calibration"}
    assert "shape_model" not in config["options"] and config["options"]["score_calibration"] == str(calibration)
    assert "predetect" not in config["options"]  # label boxes: our own pre-detection's options are not read
    # files the coarse run does not read, swapped (named anew, or rewritten in place), or options of a pre-detection
    # it does not run or of the fine stage it does not fit: the record is reused
    renamed_shape_model(mine, scale=1.2)
    for swapped in (["--shape-model", shipped_path("shape_model"), "--parts-model", shipped_path("parts_model")],
                    ["--shape-model", mine], ["--upsample", "1", "--own-box-weight", "10"],
                    ["--set", "inference.flip_evidence=false", "--iterations", 3]):
        r = cli(*common, *swapped, "--resume")
        assert r.exit_code == 0 and "1 of 1 frames already done" in r.stderr, r.output + r.stderr
        assert "refitting" not in r.stderr
    # a file it reads, rewritten in place: refitted
    shifted_calibration(calibration, right=3.0)
    r = cli(*common, "--resume")
    assert r.exit_code == 0 and "written with a different configuration" in r.stderr, r.output + r.stderr
    assert "models.score_calibration" in r.stderr
    r = cli(*common, "--resume")
    assert r.exit_code == 0 and "1 of 1 frames already done" in r.stderr, r.output + r.stderr
    # records of an older wirescene, whose fingerprint held other files (every model file, or fewer than are read
    # now): refitted, not an error
    for older in ({"shape_model": fingerprint["shape_model"]}, {"viewpoint_classifier": None}):
        record = json.loads(record_path.read_text())
        for key, digest in older.items():
            if digest is None:
                del record["config"]["models"][key], record["config"]["options"][key]
            else:
                record["config"]["models"][key] = digest
                record["config"]["options"][key] = None
        record_path.write_text(json.dumps(record))
        r = cli(*common, "--resume")
        assert r.exit_code == 0 and "refitting 1 frame(s)" in r.stderr, r.output + r.stderr
        assert f"models.{next(iter(older))}" in r.stderr and "already done" not in r.stderr


def test_a_coarse_run_s_resume_record_holds_no_option_of_the_fine_stage():
    """The options only the fine variants read (the inference stage's, the weight of our own
    boxes in its objective) are not in a coarse run's record, so that changing one refits no
    frame; those the coarse fit reads are, on our own pre-detections as on other boxes."""
    base = FitOptions(FAST)
    for fine_only in ({"inference.flip_evidence": False}, {"inference.iterations": 3, "inference.occluded_score": 0.1},
                      {"inference.device": "cpu"}, {"predetect.box_weight": 10}):
        changed = base.with_settings(fine_only)
        for own in (True, False):
            assert options_read(changed, fine=False, own=own) == options_read(base, fine=False, own=own), fine_only
        assert options_read(changed) != options_read(base), fine_only  # a fine variant reads it
    # the coarse stage's own options, our own pre-detection's (its threshold, its boxes' verification), the seed and
    # the confidences: still recorded
    for read in ({"lifting.road_prior": 0}, {"lifting.camera_height": 1.5}, {"predetect.threshold": 0.5},
                 {"predetect.min_car_probability": 0}, {"predetect.upsample": 1}):
        assert options_read(base.with_settings(read), fine=False) != options_read(base, fine=False), read
    for changed in (FitOptions(FAST, seed=1), FitOptions(FAST, calibrate_scores=False)):
        assert options_read(changed, fine=False, own=False) != options_read(base, fine=False, own=False)
    assert set(options_read(base, fine=False)) == {"lifting", "predetect", "seed", "calibrate_scores",
                                                   *model_files_read(base, fine=False)}


def test_eval_says_when_the_viewpoint_classifier_read_was_trained_on_the_frames(tmp_path):
    """A file of a `train all` directory is told by its manifest (the file its training wrote, by SHA-256), a copy
    of a shipped file by the shipped models' frames, and a file of the user's own says nothing."""
    from wirescene.core.resources import file_sha256
    from wirescene.eval.held_out import trained_on_frames
    from wirescene.io.kitti import KittiDataset

    models = models_dir(tmp_path / "models", viewpoint_classifier=forced_classifier(tmp_path / "forced.npz", 5))
    step = {"done": True, "artefact": "viewpoint_classifier.npz",
            "sha256": file_sha256(models / "viewpoint_classifier.npz")}
    manifest = {"format": "wirescene-models/1", "complete": True, "artefacts": ["viewpoint_classifier"],
                "data": {"kitti_root": str(SPLIT.resolve()), "frame_ids": ["000010"]}, "steps": {"viewpoints": step}}
    (models / MANIFEST_FILE).write_text(json.dumps(manifest))
    common = ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", "000010", "--workers", 1, "--particles", 5,
              "--raw-scores"]
    # our own boxes with the shipped bank (the directory holds none): the directory's classifier gives their viewpoints
    r = cli(*common, "--models", models, "--detections", "bank")
    assert r.exit_code == 0, r.output + r.stderr
    assert r.stderr.count("trained on") == 2, r.stderr
    assert f"1 of the 1 frames evaluated is among those the viewpoint classifier of {models} was trained on" in \
        r.stderr
    assert "the 72 the shipped detector bank was trained on" in r.stderr
    # label boxes carry their viewpoints: no classifier is read
    r = cli(*common, "--models", models, "--detections", "gt")
    assert r.exit_code == 0 and "trained on" not in r.stderr, r.output + r.stderr
    # the same file outside its directory: nothing known of it
    r = cli(*common, "--viewpoint-classifier", tmp_path / "forced.npz", "--detections", "bank")
    assert r.exit_code == 0 and f"{models}" not in r.stderr, r.output + r.stderr
    # no frames given: every frame of the split
    options = FitOptions(viewpoint_classifier=str(models / "viewpoint_classifier.npz"))
    assert trained_on_frames(KittiDataset(KITTI_ROOT), None, options=options, read=["viewpoint_classifier"]) == [
        f"1 of the 3 frames evaluated is among those the viewpoint classifier of {models} was trained on "
        "(e.g. 000010): its figures are not held out"]
    (models / "viewpoint_classifier.npz").write_bytes(b"x" + (models / "viewpoint_classifier.npz").read_bytes())
    assert trained_on_frames(KittiDataset(KITTI_ROOT), None, options=options, read=["viewpoint_classifier"]) == []


def test_a_manifest_step_naming_no_file_by_a_string_is_left_out_as_resolve_models_leaves_it(tmp_path):
    """A step whose "artefact" is a list or an object: `--models` read the directory (resolve_models skips the step),
    then the held-out line failed with a TypeError (unhashable type) after every check had passed."""
    from wirescene.core.resources import file_sha256, resolve_models, trained_on
    from wirescene.io.kitti import KittiDataset

    models = models_dir(tmp_path / "models", viewpoint_classifier=forced_classifier(tmp_path / "forced.npz", 5))
    file = models / "viewpoint_classifier.npz"
    steps = {"viewpoints": {"done": True, "artefact": file.name, "sha256": file_sha256(file)},
             "notes": {"artefact": ["a"]}, "more": {"artefact": {"b": 1}}}
    manifest = {"format": "wirescene-models/1", "complete": True, "artefacts": ["viewpoint_classifier"],
                "data": {"kitti_root": str(SPLIT.resolve()), "frame_ids": ["000010"]}, "steps": steps}
    (models / MANIFEST_FILE).write_text(json.dumps(manifest))
    assert resolve_models(models).own == ("viewpoint_classifier",)
    image_path = KittiDataset(KITTI_ROOT).image_path
    assert trained_on(file, image_path, ["000002", "000010"], split_dir=SPLIT) == ["000010"]


def test_a_train_all_file_tells_its_frames_by_their_images_in_a_copy_of_the_root_too(tmp_path):
    """The manifest records each training image's SHA-256: the same frames evaluated from a copy of the KITTI root
    elsewhere (they were told by the root's path alone, and said nothing) are told; another image under a training
    frame's id is not; a manifest of an earlier version, without them, is read by the root's path as before."""
    from PIL import Image

    from conftest import kitti_copy
    from wirescene.core.resources import file_sha256, trained_on
    from wirescene.io.kitti import KittiDataset

    models = models_dir(tmp_path / "models", viewpoint_classifier=forced_classifier(tmp_path / "forced.npz", 5))
    file = models / "viewpoint_classifier.npz"
    images = {f: file_sha256(SPLIT / "image_2" / f"{f}.png") for f in ("000010", "001545")}
    manifest = {"format": "wirescene-models/1", "complete": True, "artefacts": ["viewpoint_classifier"],
                "data": {"kitti_root": str(SPLIT.resolve()), "frame_ids": sorted(images), "images_sha256": images},
                "steps": {"viewpoints": {"done": True, "artefact": file.name, "sha256": file_sha256(file)}}}
    (models / MANIFEST_FILE).write_text(json.dumps(manifest))
    copy = KittiDataset(kitti_copy(tmp_path / "copy", ["000002", "000010", "001545"]))
    flipped = copy.image_path("001545")
    Image.open(flipped).transpose(Image.FLIP_LEFT_RIGHT).save(flipped)  # another image under a training frame's id
    assert trained_on(file, copy.image_path, copy.frame_ids(), split_dir=copy.split_dir) == ["000010"]
    del manifest["data"]["images_sha256"]  # an earlier manifest: the root's path and the ids
    (models / MANIFEST_FILE).write_text(json.dumps(manifest))
    assert trained_on(file, copy.image_path, copy.frame_ids(), split_dir=copy.split_dir) == []
    assert trained_on(file, copy.image_path, ["000002", "001545"], split_dir=SPLIT) == ["001545"]


def test_an_image_is_hashed_once_however_many_files_of_a_models_directory_ask(tmp_path):
    """The held-out line tells a `train all` directory's frames once for each of its files the run reads (the part
    model, the bank and the classifier: three), by the images' SHA-256: a split's images stay in file_sha256's cache
    (it held 64, so that each of 3,712 images was read and hashed three times)."""
    from wirescene.core import resources

    images = []
    for i in range(200):
        images.append(tmp_path / f"{i:06d}.png")
        images[-1].write_bytes(i.to_bytes(2, "little"))
    resources._sha256.cache_clear()
    for _ in range(3):
        hashes = [resources.file_sha256(path, what="image") for path in images]
    assert len(set(hashes)) == 200
    assert resources._sha256.cache_info().misses == 200


def test_the_notice_of_a_models_directory_names_the_files_read_that_were_trained_on_the_frames(tmp_path):
    """The line of a `train all` directory names the files of it that the run reads, as the shipped models' line does:
    the part model alone for a fine variant on label boxes, the bank and classifier for our own boxes."""
    from wirescene.core.resources import file_sha256
    from wirescene.eval.held_out import trained_on_frames
    from wirescene.io.kitti import KittiDataset

    models = tmp_path / "models"
    models.mkdir()
    steps = {}
    for step, name in (("parts", "parts_model"), ("detector", "detector_bank"), ("viewpoints", "viewpoint_classifier")):
        (models / ARTEFACTS[name]).write_bytes(name.encode())  # the notice reads the manifest and the hashes alone
        steps[step] = {"done": True, "artefact": ARTEFACTS[name], "sha256": file_sha256(models / ARTEFACTS[name])}
    manifest = {"format": "wirescene-models/1", "complete": True, "data": {"kitti_root": str(SPLIT.resolve()),
                "frame_ids": ["000010", "001545"]}, "steps": steps}
    (models / MANIFEST_FILE).write_text(json.dumps(manifest))
    options = FitOptions(**{name: str(models / ARTEFACTS[name])
                            for name in ("parts_model", "detector_bank", "viewpoint_classifier")})
    dataset = KittiDataset(KITTI_ROOT)

    def said(read):
        return trained_on_frames(dataset, ["000002", "000010"], options=options, read=read)

    assert said(["parts_model", "shape_model"]) == [
        f"1 of the 2 frames evaluated is among those the part model of {models} was trained on (e.g. 000010): its "
        "figures are not held out"]
    assert said(["detector_bank", "viewpoint_classifier"])[0].startswith(
        f"1 of the 2 frames evaluated is among those the detector bank and viewpoint classifier of {models} were "
        "trained on (e.g. 000010)")
    assert f"part model, detector bank and viewpoint classifier of {models} were" in said(
        ["parts_model", "detector_bank", "viewpoint_classifier"])[0]


@pytest.fixture(scope="module")
def standalone_parts(tmp_path_factory):
    """A part model of `train parts --kitti-root`, on frame 000010 alone (a tiny recipe: some 2 s)."""
    path = tmp_path_factory.mktemp("standalone") / "parts.npz"
    r = cli("train", "parts", "--kitti-root", KITTI_ROOT, "--frames", "000010", "--n-trees", 2, "--max-depth", 4,
            "--synth-scenes", 0, "--no-calibrate", "--out", path)
    assert r.exit_code == 0, r.output + r.stderr
    return path


def test_eval_names_the_frames_a_standalone_trained_part_model_was_trained_on(standalone_parts, tmp_path):
    """A file of `train parts --kitti-root` (or `train detector --kitti-root`, `train viewpoints`) has no manifest:
    evaluated on its own training frames it said nothing, and their figures passed for held out. It records its
    frames' images (SHA-256), which the held-out line reads as a manifest's, naming the file; the files trained on the
    same frames evaluated share a line; a frame they were not trained on says nothing."""
    from wirescene.core.resources import file_sha256
    from wirescene.eval.held_out import trained_on_frames
    from wirescene.io.kitti import KittiDataset
    from wirescene.parts.detector import PartDetector

    r = cli("eval", KITTI_ROOT, "--variant", "full", "--frames", "000010", "--particles", 5, "--workers", 1, "--draws",
            0, "--raw-scores", "--parts-model", standalone_parts)
    assert r.exit_code == 0, r.output + r.stderr
    assert r.stderr.count("trained on") == 1 and (
        f"wirescene: 1 of the 1 frames evaluated is among those the part model {standalone_parts} was trained on "
        "(e.g. 000010): its figures are not held out") in r.stderr, r.stderr
    assert PartDetector.load(standalone_parts).trained_images == {"000010": file_sha256(IMAGE)}
    viewpoints = tmp_path / "viewpoints.npz"
    assert cli("train", "viewpoints", KITTI_ROOT, "--frames", "000002,000010", "--out", viewpoints).exit_code == 0
    options = FitOptions(parts_model=str(standalone_parts), viewpoint_classifier=str(viewpoints))
    dataset = KittiDataset(KITTI_ROOT)

    def said(frames):
        return trained_on_frames(dataset, frames, options=options, read=["parts_model", "viewpoint_classifier"])

    assert said(["000010", "001545"]) == [
        f"1 of the 2 frames evaluated is among those the part model {standalone_parts} and viewpoint classifier "
        f"{viewpoints} were trained on (e.g. 000010): its figures are not held out"]
    assert said(["000002", "001545"]) == [
        f"1 of the 2 frames evaluated is among those the viewpoint classifier {viewpoints} was trained on (e.g. "
        "000002): its figures are not held out"]
    assert said(["001545"]) == []


def test_a_part_model_records_the_frames_of_its_kitti_background(tmp_path):
    """`train parts --n-views N --kitti-background ROOT` learns background patches of every frame of ROOT: its file
    recorded none of them, and an evaluation on them said nothing of it."""
    from wirescene.eval.held_out import trained_on_frames
    from wirescene.io.kitti import KittiDataset
    from wirescene.parts.detector import PartDetector

    path = tmp_path / "parts.npz"
    r = cli("train", "parts", "--n-views", 2, "--kind", "sc", "--no-position", "--kitti-background", KITTI_ROOT,
            "--n-trees", 2, "--max-depth", 4, "--synth-scenes", 0, "--out", path)
    assert r.exit_code == 0, r.output + r.stderr
    dataset = KittiDataset(KITTI_ROOT)
    assert sorted(PartDetector.load(path).trained_images) == dataset.frame_ids()
    assert trained_on_frames(dataset, ["000010"], options=FitOptions(parts_model=str(path)), read=["parts_model"]) == [
        f"1 of the 1 frames evaluated is among those the part model {path} was trained on (e.g. 000010): its figures "
        "are not held out"]


def test_a_bank_records_the_frames_of_its_held_out_calibration_beyond_its_own(tmp_path, monkeypatch):
    """A bank trained in Python on frame 000010 with a held-out calibration over folds that hold 001545 too (the
    calibration's fold banks learn from it and their detections on it set the confidences): its record holds both
    frames, and survives the file."""
    import wirescene.training.kitti_detector as kitti_detector
    from wirescene.core.resources import images_sha256
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.bank import DetectorBank

    calibrated_on = []

    def calibration(root, folds, **kwargs):  # the leave-one-fold-out trainings (seconds) stood in for
        calibrated_on.append(sorted(folds))
        return kitti_detector.calibration_record([1.0, 0.0], source="stub")

    monkeypatch.setattr(kitti_detector, "heldout_bank_calibration", calibration)
    bank, _ = kitti_detector.train_detector_bank_kitti(
        tmp_path / "bank.npz", KITTI_ROOT, frames=["000010"], calibration_folds={"000010": 0, "001545": 1},
        n_partial=0, mining_rounds=1, neg_per_image=10, min_pos=20, min_height=40, max_scale=1.0, per_octave=2)
    assert calibrated_on == [["000010", "001545"]]
    assert bank.trained_images == images_sha256(KittiDataset(KITTI_ROOT).image_path, ["000010", "001545"])
    assert DetectorBank.load(tmp_path / "bank.npz").trained_images == bank.trained_images


def test_a_frame_trained_file_without_the_record_of_its_frames_loads_and_says_nothing(standalone_parts, tmp_path):
    """Files written before the record (the shipped ones among them) load as they did, with none, and the held-out
    line says nothing of them; a record whose digests do not match its ids is refused naming the file."""
    from wirescene.core.artefacts import TRAINED_FRAMES, TRAINED_IMAGES, load_npz, save_npz
    from wirescene.eval.held_out import trained_on_frames
    from wirescene.io.kitti import KittiDataset
    from wirescene.parts.detector import FORMAT_KIND, FORMAT_VERSION, PartDetector
    from wirescene.predetect.bank import load_default_bank
    from wirescene.predetect.viewpoint_classifier import load_default_classifier

    arrays = load_npz(standalone_parts, kind=FORMAT_KIND, version=FORMAT_VERSION)
    older = {k: v for k, v in arrays.items() if k not in (TRAINED_FRAMES, TRAINED_IMAGES)}
    old = save_npz(tmp_path / "old.npz", older, kind=FORMAT_KIND, version=FORMAT_VERSION)
    model = PartDetector.load(old)
    assert model.trained_images == {} and model.n_trees == PartDetector.load(standalone_parts).n_trees == 2
    options = FitOptions(parts_model=str(old))
    assert trained_on_frames(KittiDataset(KITTI_ROOT), ["000010"], options=options, read=["parts_model"]) == []
    assert load_default_bank().trained_images == {} and load_default_classifier().trained_images == {}
    bad = save_npz(tmp_path / "bad.npz", {**arrays, TRAINED_IMAGES: arrays[TRAINED_IMAGES][:, :16]}, kind=FORMAT_KIND,
                   version=FORMAT_VERSION)
    with pytest.raises(InputError, match=f"^{bad}: malformed record of its training frames"):
        PartDetector.load(bad)


def test_train_occlusion_scores_the_part_model_it_is_given(tmp_path):
    broken = tmp_path / "parts.npz"
    broken.write_text("x")
    r = cli("train", "occlusion", "--out", tmp_path / "c.json", "--scenes", 1, "--parts-model", broken)
    assert r.exit_code == 2 and "parts.npz: corrupt artefact file" in r.stderr, r.output + r.stderr
    # the explicit file wins over the directory's
    models = models_dir(tmp_path / "models", parts_model=broken)
    r = cli("train", "occlusion", "--out", tmp_path / "c.json", "--scenes", 1, "--models", models,
            "--parts-model", shipped_path("parts_model"))
    assert r.exit_code == 0, r.output + r.stderr
    assert json.loads((tmp_path / "c.json").read_text())["n_scenes"] == 1


def test_settings_win_over_a_models_directory_and_its_line_names_the_files_given_instead(tmp_path, capsys):
    """An explicit value beats the directory's, for a number (``--set inference.occluded_score``)
    as for a file (``--shape-model``), and the run's line on standard error says which of the
    directory's files were replaced."""
    from wirescene.api import _options
    from wirescene.cli.main import _fit_options
    from wirescene.infer.occluded_score import save_occluded_score

    models = tmp_path / "models"
    models.mkdir()
    save_occluded_score(models / "occlusion.json", {"c": 0.4})
    shutil.copy(shipped_path("shape_model"), models / "shape_model.npz")
    mine = tmp_path / "mine.npz"
    shutil.copy(shipped_path("shape_model"), mine)
    assert _options(None, 5, 0, models=models).inference.occluded_score == 0.4
    assert _options(None, 5, 0, models=models, settings={"inference.occluded_score": 0.1}).inference.occluded_score \
        == 0.1
    options = _fit_options(5, 0, models=models, shape_model=mine, device="numpy",
                           settings=("inference.occluded_score=0.1",))
    assert options.inference.occluded_score == 0.1 and options.shape_model == str(mine.resolve())
    line = capsys.readouterr().err
    assert "given as files: shape_model" in line and f"models from {models.resolve()}: occlusion;" in line


def test_a_broken_part_model_or_bank_is_refused_before_any_frame(tmp_path):
    """A corrupt part model or bank of a models directory is refused in one line before any
    frame is fitted, as the other files are; so is a fine stage searching more shape
    components than the shipped model has."""
    broken = tmp_path / "models"
    broken.mkdir()
    (broken / "parts_model.npz").write_bytes(b"not an npz")
    with pytest.raises(InputError, match="parts_model.npz"):
        wirescene.api._options(None, 5, 0, models=broken, casts_rays=True)
    (broken / "parts_model.npz").unlink()
    (broken / "detector_bank.npz").write_bytes(b"not an npz")
    with pytest.raises(InputError, match="detector_bank.npz"):
        wirescene.api._options(None, 5, 0, models=broken, casts_rays=False)
    with pytest.raises(InputError, match="shape model of 41 components, the fine stage searches 50"):
        wirescene.api._options(None, 5, 0, settings={"inference.n_shape": 50}, casts_rays=True)


def test_the_record_of_the_shipped_models_frames_is_theirs_and_knows_the_real_frames_by_content():
    """`training_frames.json` lists the frames every shipped frame-trained model records (the part model's
    real_frames, the bank's and the classifier's frames), and the real frames the tests copy have its digests."""
    from wirescene.io.kitti import KittiDataset
    from wirescene.io.shipped_frames import among_shipped_training_frames, shipped_training_frames
    from wirescene.parts.detector import PartDetector
    from wirescene.predetect.bank import DetectorBank
    from wirescene.predetect.viewpoint_classifier import load_default_classifier

    record = set(shipped_training_frames())
    assert record == set(PartDetector.load().meta["real_frames"].split(","))
    assert record == set(DetectorBank.load(shipped_path("detector_bank")).meta["frames"])
    assert record == set(load_default_classifier().meta["frames"])
    dataset = KittiDataset(KITTI_ROOT)
    frames = dataset.frame_ids()
    assert among_shipped_training_frames(dataset.image_path, frames) == frames == ["000002", "000010", "001545"]
