"""One calibration for every frame (``KittiDataset(calib=)``, ``--calib`` of ``predict``, ``detect``,
``pitch`` and ``eval``): a folder of frames of one camera reads as KITTI's layout of one calibration
file per frame. The three test frames' calibrations are identical, so every output must be too."""

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from conftest import KITTI_ROOT, assert_close, kitti_copy
from wirescene.cli.main import main
from wirescene.core.errors import ArgumentError, InputError
from wirescene.io.kitti import KittiDataset

SPLIT = KITTI_ROOT / "training"
FRAMES = ["000002", "000010", "001545"]
CALIB = SPLIT / "calib" / "000010.txt"
CAR = "Car 0.00 0 1.95 354.43 185.52 549.52 294.49 1.43 1.70 3.95 -2.39 1.66 11.80 1.76"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def frames_dir(tmp_path):
    """A plain folder of the test frames' images (no image_2/, no calib/)."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for frame in FRAMES:
        shutil.copy(SPLIT / "image_2" / f"{frame}.png", folder)
    return folder


def _projection_file(path, P):
    """``path`` holding the 12 numbers of ``P`` (another form of a calibration than KITTI's file)."""
    path.write_text("\n".join(" ".join(repr(float(v)) for v in row) for row in P) + "\n")
    return path


def test_the_test_frames_share_one_calibration():
    """What the byte-for-byte comparisons below rest on."""
    assert len({(SPLIT / "calib" / f"{f}.txt").read_text() for f in FRAMES}) == 1


def test_a_folder_of_frames_with_one_calibration_reads_as_the_kitti_layout(frames_dir, tmp_path):
    kitti = KittiDataset(KITTI_ROOT)
    ds = KittiDataset(frames_dir, calib=CALIB)
    assert ds.image_dir == ds.split_dir == frames_dir and not ds.has_labels
    assert ds.frame_ids() == ds.require_frames(images=True) == FRAMES
    for f in FRAMES:
        assert np.array_equal(ds.camera(f).P, kitti.camera(f).P)
        assert ds.camera(f).image_size == kitti.camera(f).image_size
        assert np.array_equal(ds.image(f), kitti.image(f))
    assert ds.calib_path(10) == CALIB and ds.check_frames(FRAMES) == []
    # KITTI's layout without calib/: refused alone, read with one calibration (labels and all)
    root = kitti_copy(tmp_path / "kitti", FRAMES, subdirs=("image_2", "label_2"))
    with pytest.raises(InputError, match=r"training: KITTI split has no calib/ directory; predict, detect, pitch and "
                                         r"eval take one calibration for every frame \(--calib FILE\)$"):
        KittiDataset(root)
    labelled = KittiDataset(root, calib=CALIB)
    assert labelled.split_dir == labelled.image_dir.parent == root / "training"
    assert labelled.frame_ids() == FRAMES and len(labelled.labels("000010").of_type("Car")) == 8
    # without a calibration a folder of frames is no KITTI directory, as before
    with pytest.raises(InputError, match=r"frames: not a KITTI object directory: expected training/image_2"):
        KittiDataset(frames_dir)
    # the 9 numbers of K: a camera at the origin, P = K [I | 0]; the run's record names the camera
    K = tmp_path / "K.txt"
    K.write_text(" ".join(repr(float(v)) for v in kitti.camera(10).K.ravel()))
    intrinsics = KittiDataset(frames_dir, calib=K)
    assert_close(intrinsics.camera(10).P, np.hstack([kitti.camera(10).K, np.zeros((3, 1))]))
    assert "calib" not in kitti.record() and ds.record()["calib"] == kitti.camera(10).P.tolist()
    assert intrinsics.record() != ds.record()


def test_jpeg_frames_are_read_and_two_images_of_one_frame_refused(tmp_path):
    """A dashcam's or nuScenes' frames are JPEG, named as they come: the id is the name without its suffix."""
    folder = tmp_path / "cam"
    folder.mkdir()
    rgb = Image.open(SPLIT / "image_2" / "000010.png").convert("RGB")
    rgb.save(folder / "CAM_FRONT_0001.jpg", quality=95)
    rgb.save(folder / "CAM_FRONT_0002.JPEG", quality=95)
    (folder / "notes.txt").write_text("the rig: 1.4 m up\n")
    (folder / "._CAM_FRONT_0001.jpg").write_bytes(b"\x00\x05\x16\x07")  # macOS's AppleDouble file on an exFAT card
    ds = KittiDataset(folder, calib=CALIB)
    assert ds.frame_ids() == ["CAM_FRONT_0001", "CAM_FRONT_0002"]
    assert ds.image_path("CAM_FRONT_0002").name == "CAM_FRONT_0002.JPEG"
    # a worker's copy (pickled with each frame's task) carries no listing of the folder, and finds the same images
    copy = pickle.loads(pickle.dumps(ds))
    assert copy._images is None and ds._images is not None
    assert [copy.image_path(f) for f in ds.frame_ids()] == [ds.image_path(f) for f in ds.frame_ids()]
    assert ds.image("CAM_FRONT_0001").shape == (375, 1242, 3) and ds.camera("CAM_FRONT_0001").image_size == (1242, 375)
    shutil.copy(SPLIT / "image_2" / "000010.png", folder / "CAM_FRONT_0001.png")
    with pytest.raises(InputError, match=r"cam: frame CAM_FRONT_0001 has two images \(CAM_FRONT_0001\.jpg, "
                                         r"CAM_FRONT_0001\.png\): keep one$"):
        KittiDataset(folder, calib=CALIB).frame_ids()
    # KITTI's layout without --calib reads .png alone, as before
    jpeg_split = kitti_copy(tmp_path / "kitti", ["000010"], subdirs=("calib",))
    (jpeg_split / "training" / "image_2").mkdir()
    rgb.save(jpeg_split / "training" / "image_2" / "000010.jpg")
    assert KittiDataset(jpeg_split).image_ids() == []
    assert KittiDataset(jpeg_split, calib=CALIB).image_ids() == ["000010"]


def test_predict_of_a_folder_of_frames_writes_the_kitti_layouts_label_files(frames_dir, tmp_path):
    """Our own pre-detection reads each image: the label files match those of the KITTI layout byte for byte."""
    common = ["--variant", "coarse", "--frames", "000010", "--particles", 20, "--workers", 1,
              "--set", "predetect.upsample=1"]  # the image alone: half the time
    r = run("predict", frames_dir, "--calib", CALIB, "--out", tmp_path / "folder", *common)
    assert r.exit_code == 0, r.output
    r = run("predict", KITTI_ROOT, "--split", "training", "--out", tmp_path / "kitti", *common)
    assert r.exit_code == 0, r.output
    written = (tmp_path / "folder" / "000010.txt").read_bytes()
    assert written and written == (tmp_path / "kitti" / "000010.txt").read_bytes()
    # scored against labels kept elsewhere: no word of a KITTI split mixed up (the folder's name is no split's)
    r = run("kitti-eval", SPLIT / "label_2", tmp_path / "folder", "--frames", "000010", "--draws", 0)
    assert r.exit_code == 0 and "predicted from the images of" not in r.output, r.output


def test_predict_resumed_with_another_calibration_is_refused(frames_dir, tmp_path):
    """The settings' record holds the camera: another one is refused on --resume; the same matrix in another
    file (its 12 numbers) continues the run."""
    dets = tmp_path / "dets"
    dets.mkdir()
    (dets / "000010.txt").write_text(CAR + "\n")
    out = tmp_path / "pred"
    common = ["predict", frames_dir, "--frames", "000010", "--variant", "coarse", "--detections", dets,
              "--particles", 5, "--workers", 1, "--out", out]
    r = run(*common, "--calib", CALIB)
    assert r.exit_code == 0, r.output
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    P = KittiDataset(KITTI_ROOT).camera(10).P
    longer = P.copy()
    longer[:2, :3] *= 1.05  # a longer lens
    r = run(*common, "--calib", _projection_file(tmp_path / "longer.txt", longer), "--resume")
    assert r.exit_code == 2, r.output
    assert r.stderr.strip() == (f"wirescene: error: {out}: label files were written with other settings (calib): "
                                "cannot resume into this directory")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    r = run(*common, "--calib", _projection_file(tmp_path / "P.txt", P), "--resume")
    assert r.exit_code == 0 and "0 frames fitted, 1 kept" in r.output, r.output


def test_eval_with_one_calibration_and_its_records(tmp_path):
    """``eval --calib`` of KITTI's layout without calib/ gives the figures of the per-frame calibrations;
    a frame's record written with another camera is fitted again."""
    root = kitti_copy(tmp_path / "kitti", ["000010"], subdirs=("image_2", "label_2"))
    common = ["--variant", "coarse", "--frames", "000010", "--particles", 20, "--workers", 1, "--draws", 0]
    r = run("eval", root, "--calib", CALIB, *common, "--json", tmp_path / "one.json", "--predictions", tmp_path / "p")
    assert r.exit_code == 0, r.output
    r = run("eval", KITTI_ROOT, *common, "--json", tmp_path / "each.json", "--predictions", tmp_path / "q")
    assert r.exit_code == 0, r.output
    assert json.loads((tmp_path / "one.json").read_text()) == json.loads((tmp_path / "each.json").read_text())
    written = [(tmp_path / run / "coarse" / "000010.txt").read_bytes() for run in ("p", "q")]
    assert written[0] == written[1]
    import wirescene

    api = wirescene.evaluate(root, calib=CALIB, variants="coarse", frames=["000010"], particles=20)  # the same in Python
    records = api["coarse"].to_json_dict()["records"]
    assert records and records == json.loads((tmp_path / "one.json").read_text())["records"]
    K = tmp_path / "K.txt"
    K.write_text(" ".join(repr(float(v)) for v in KittiDataset(KITTI_ROOT).camera(10).K.ravel()))
    r = run("eval", root, "--calib", K, *common, "--predictions", tmp_path / "p", "--resume")
    assert r.exit_code == 0, r.output
    assert "refitting 1 frame(s) whose record cannot be reused" in r.stderr
    assert "written with a different configuration (calib)" in r.stderr, r.stderr


def test_detect_of_a_folder_of_frames_writes_the_kitti_layouts_files(frames_dir, tmp_path):
    r = run("detect", frames_dir, "--calib", CALIB, "--frames", "000010", "--upsample", 1, "--out", tmp_path / "folder")
    assert r.exit_code == 0, r.output
    r = run("detect", KITTI_ROOT, "--frames", "000010", "--upsample", 1, "--out", tmp_path / "kitti")
    assert r.exit_code == 0, r.output
    written = (tmp_path / "folder" / "000010.json").read_bytes()
    assert json.loads(written)["detections"] and written == (tmp_path / "kitti" / "000010.json").read_bytes()


def test_pitch_of_a_folder_of_frames_reads_the_kitti_layouts_pitch(frames_dir, tmp_path):
    r = run("pitch", frames_dir, "--calib", CALIB, "--frames", "000010", "--json", tmp_path / "folder.json")
    assert r.exit_code == 0, r.output
    r = run("pitch", KITTI_ROOT, "--frames", "000010", "--json", tmp_path / "kitti.json")
    assert r.exit_code == 0, r.output
    record = json.loads((tmp_path / "folder.json").read_text())
    assert record["frames"]["000010"]["boxes"] > 0 and record == json.loads((tmp_path / "kitti.json").read_text())


def test_eval_of_a_plain_folder_draws_its_frames_alone(tmp_path):
    """A plain folder's frames are no KITTI drive's, whatever their names: the intervals draw each alone (the
    shipped drive map grouped 000002 and 000010, frames of KITTI's, by their drives)."""
    folder = tmp_path / "cam"
    (folder / "label_2").mkdir(parents=True)
    for f in ("000002", "000010"):
        shutil.copy(SPLIT / "image_2" / f"{f}.png", folder / f"{f}.png")
        shutil.copy(SPLIT / "label_2" / f"{f}.txt", folder / "label_2" / f"{f}.txt")
    r = run("eval", folder, "--calib", CALIB, "--variant", "coarse", "--particles", 10, "--workers", 1,
            "--draws", 20)
    assert r.exit_code == 0, r.output
    assert "0 drives and 2 frames of no known drive" in r.output, r.output


def test_split_given_for_a_plain_folder_is_refused(frames_dir, tmp_path):
    """A plain folder of frames has no split folder: --split given there is refused (it was ignored, the folder's
    own images read whatever it named), at its default it is no error; KITTI's layout read with --calib honours it."""
    dets = tmp_path / "dets"
    dets.mkdir()
    (dets / "000010.txt").write_text(CAR + "\n")
    fit = ["--detections", dets, "--variant", "coarse", "--particles", 5, "--workers", 1]
    commands = {"predict": ["--out", tmp_path / "pred", *fit], "detect": ["--out", tmp_path / "boxes"],
                "pitch": ["--json", tmp_path / "pitch.json"],
                "eval": [*fit, "--json", tmp_path / "m.json", "--predictions", tmp_path / "p"]}
    for command, extra in commands.items():
        for split in ("testing", "training"):  # either given: predict's default is testing, the others' training
            r = run(command, frames_dir, "--calib", CALIB, "--split", split, "--frames", "000010", *extra)
            assert r.exit_code == 2, (command, r.output)
            assert r.stderr.strip() == (f"wirescene: error: {frames_dir}: --split {split} has no meaning for a plain "
                                        f"folder of frames (its own images are read with --calib; no {split}/image_2 "
                                        "here): drop --split"), (command, r.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dets", "frames"]  # nothing written

    def predict(root, *more):
        return run("predict", root, "--calib", CALIB, "--frames", "000010", *fit, *more)

    r = predict(frames_dir, "--out", tmp_path / "folder")  # the default: as before
    assert r.exit_code == 0, r.output
    r = predict(KITTI_ROOT, "--split", "training", "--out", tmp_path / "kitti")
    assert r.exit_code == 0, r.output
    written = (tmp_path / "folder" / "000010.txt").read_bytes()
    assert written and written == (tmp_path / "kitti" / "000010.txt").read_bytes()
    r = predict(KITTI_ROOT, "--split", "testing", "--out", tmp_path / "none")  # the message of before
    assert r.exit_code == 2 and not (tmp_path / "none").exists(), r.output
    assert r.stderr.strip() == (f"wirescene: error: {KITTI_ROOT}: no .png, .jpg or .jpeg file (it holds only the "
                                "folders ImageSets, training, no testing/image_2)")


def test_split_given_in_python_where_it_has_no_meaning_is_refused(frames_dir, tmp_path):
    """KittiDataset(split=) as --split: refused for a plain folder of frames and for a split folder of another name
    (it was ignored, the folder's own images read whatever it named), naming the root; not given, or honoured, no
    error; the split folder's own name (as given, or as its link's target) is no other split."""
    for split in ("testing", "training"):
        with pytest.raises(InputError) as exc:
            KittiDataset(frames_dir, calib=CALIB, split=split)
        assert str(exc.value) == (f"{frames_dir}: split={split!r} has no meaning for a plain folder of frames (its own "
                                  f"images are read with calib; no {split}/image_2 here): drop split")
    with pytest.raises(InputError) as exc:
        KittiDataset(SPLIT, split="testing")
    assert str(exc.value) == (f"{SPLIT}: split='testing' names no folder here: this is itself a split folder (its "
                              "image_2/ is read, no testing/image_2): give the KITTI root above it, or drop split")
    assert KittiDataset(frames_dir, calib=CALIB).frame_ids() == FRAMES  # not given: as before
    for split in (Path("training"), "training/", "training/image_2", 5, "", ".."):  # a split's name, nothing else
        with pytest.raises(ArgumentError, match=r"^split: expected the name of a split folder \(e\.g\. 'training'\)"):
            KittiDataset(KITTI_ROOT, split=split)
    assert KittiDataset(SPLIT, split="training").split_dir == KittiDataset(SPLIT).split_dir == SPLIT
    assert KittiDataset(KITTI_ROOT, split="training", calib=CALIB).image_dir == SPLIT / "image_2"
    link = tmp_path / "val"
    link.symlink_to(SPLIT)
    assert KittiDataset(link, split="val").split_dir == KittiDataset(link, split="training").split_dir == link


def test_split_given_for_a_split_folder_of_another_name_is_refused(tmp_path):
    """KITTI_ROOT/training given as the root reads its own image_2/: a --split naming another split there is refused
    (it was ignored: `--split testing` wrote a submission of the training frames); its own name, or none, is fine."""
    common = ["--variant", "coarse", "--particles", 5, "--workers", 1, "--detections", "gt", "--frames", "000010"]
    r = run("predict", SPLIT, "--split", "testing", "--out", tmp_path / "pred", *common)
    assert r.exit_code == 2 and not (tmp_path / "pred").exists(), r.output
    assert r.stderr.strip() == (f"wirescene: error: {SPLIT}: --split testing names no folder here: this is itself a "
                                "split folder (its image_2/ is read, no testing/image_2): give the KITTI root above "
                                "it, or drop --split")
    r = run("eval", SPLIT, "--split", "testing", "--json", tmp_path / "m.json", *common)
    assert r.exit_code == 2 and "--split testing names no folder here" in r.stderr, r.stderr
    r = run("predict", SPLIT, "--split", "training", "--out", tmp_path / "pred", *common)
    assert r.exit_code == 0, r.output


def test_split_named_by_its_link_is_no_other_split(tmp_path, monkeypatch):
    """ROOT/training a link to a folder of another name (the data kept elsewhere): `--split training` with
    ROOT/training given names it (the link's name), with --dask too (whose dataset reads the link's target), and `.`
    entered through the link (the shell's $PWD); another split is refused there, naming the path given."""
    target = tmp_path / "kitti_object_train"
    target.mkdir()
    for sub in ("image_2", "calib", "label_2"):
        (target / sub).symlink_to(SPLIT / sub)
    (tmp_path / "kitti").mkdir()
    split = tmp_path / "kitti" / "training"
    split.symlink_to(target)
    dask = ["--dask", "127.0.0.1:9"]  # refused at --frames, before any scheduler is reached
    # --frames names what it looks among and where, as --split-file does
    unknown = {"predict": "image", "eval": "labelled frame", "detect": "frame", "pitch": "frame"}
    for command, extra in {"predict": ["--out", tmp_path / "pred"], "eval": [], "detect": [], "pitch": []}.items():
        for more in ([], dask) if command in ("predict", "eval") else ([],):
            r = run(command, split, "--split", "training", "--frames", "nothing", *extra, *more)
            # with --dask the dataset reads the link's target (for workers elsewhere): the folder named is that
            said = f"--frames: no {unknown[command]} nothing in {target.resolve() if more else split}"
            assert r.exit_code == 2 and said in r.stderr, (command, more, r.stderr)
            r = run(command, split, "--split", "testing", "--frames", "nothing", *extra, *more)
            assert r.exit_code == 2, (command, more, r.output)
            assert r.stderr.startswith(f"wirescene: error: {split}: --split testing names no folder here"), r.stderr
    r = run("gt", split, "000010", "--split", "testing", "--out", tmp_path / "gt.png")
    assert r.exit_code == 2 and "--split testing names no folder here" in r.stderr and not list(tmp_path.glob("*.png"))
    monkeypatch.chdir(split)
    monkeypatch.setenv("PWD", str(split))
    r = run("predict", ".", "--split", "training", "--frames", "nothing", "--out", tmp_path / "pred")
    assert r.exit_code == 2 and "--frames: no image nothing in ." in r.stderr, r.stderr
    assert not (tmp_path / "pred").exists()
