"""Bad input never crashes and never passes silently: every case of the issue's list,
table-driven through the CLI (exit code 2, one line ``wirescene: error: ...``, no output
left behind), and property-based fuzzing of the parsers and the option ranges."""

import json
import re
import shutil
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wirescene.io.kitti
from conftest import KITTI_ROOT, assert_close, kitti_copy
from wirescene.cli.main import main
from wirescene.core.camera import read_kitti_calib
from wirescene.core.errors import InputError
from wirescene.core.resources import DATA_DIR
from wirescene.io.detections import read_detections
from wirescene.io.folds import N_FOLDS, fold_of
from wirescene.io.kitti import KittiDataset, read_image, read_labels

SPLIT = KITTI_ROOT / "training"
FRAME = "000010"
CALIB_TEXT = (SPLIT / "calib" / f"{FRAME}.txt").read_text()
P2_LINE = next(ln for ln in CALIB_TEXT.splitlines() if ln.startswith("P2:"))
CAR = "Car 0.00 0 1.95 354.43 185.52 549.52 294.49 1.43 1.70 3.95 -2.39 1.66 11.80 1.76"


def _with_p2(values: str) -> str:
    return CALIB_TEXT.replace(P2_LINE, f"P2: {values}")


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` x ``height`` (a decompression bomb's shape)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = lambda kind, data: struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))  # noqa: E731
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 16)) + chunk(b"IEND", b"")


def _fit_case(tmp, *, calib=None, dets=None, image=None, extra=()):
    img = tmp / f"{FRAME}.png"
    shutil.copy(SPLIT / "image_2" / f"{FRAME}.png", img)
    if image is not None:
        image(img)
    c = tmp / "calib.txt"
    c.write_text(CALIB_TEXT if calib is None else calib)
    d = tmp / ("dets" + (dets[0] if dets else ".txt"))
    d.write_text(CAR + "\n" if dets is None else dets[1])
    return ["fit", img, "--calib", c, "--detections", d, "--out", tmp / "out", "--variant", "coarse", *extra]


def _frame_root(tmp, label: str):
    """A KITTI root (``tmp/kitti``) of a copy of the test frame whose label file holds ``label``."""
    root = kitti_copy(tmp / "kitti", [FRAME], subdirs=("image_2", "calib"))
    (root / "training" / "label_2").mkdir()
    (root / "training" / "label_2" / f"{FRAME}.txt").write_text(label)
    return root


def _carless_root(tmp):
    """A KITTI root of one frame whose label holds no Car (a DontCare region only)."""
    return _frame_root(tmp, "DontCare -1 -1 -10 1000 160 1040 190 -1 -1 -1 -1000 -1000 -1000 -10\n")


def _eval_case(tmp, *extra):
    return ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", FRAME, "--workers", "1", *extra]


LABEL_ROWS = len((SPLIT / "label_2" / f"{FRAME}.txt").read_text().splitlines())


def _eval_label_case(tmp, row):
    """``eval`` of a copy of the test frame whose label file ends with ``row``; outputs asked
    for, so that any partial output would show."""
    root = _frame_root(tmp, (SPLIT / "label_2" / f"{FRAME}.txt").read_text() + row + "\n")
    return ["eval", root, "--variant", "coarse", "--frames", FRAME, "--workers", "1",
            "--predictions", tmp / "pred", "--json", tmp / "metrics.json", "--report", tmp / "report"]


def _eval_mapping_case(tmp):
    """``eval`` of a copy of the test frame under a root whose devkit mapping (the drives of its
    bootstrap intervals) is malformed: refused before any frame is fitted."""
    args = _eval_label_case(tmp, "")
    label = tmp / "kitti" / "training" / "label_2" / f"{FRAME}.txt"
    label.write_text(label.read_text().rstrip("\n") + "\n")
    _file(tmp, "kitti/mapping/train_mapping.txt", "2011_09_26 2011_09_26_drive_0005_sync 0000000001\n")
    _file(tmp, "kitti/mapping/train_rand.txt", "1,x")
    return args


def _write_16bit(path):
    from PIL import Image

    Image.fromarray((np.arange(375 * 1242).reshape(375, 1242) % 65536).astype(np.uint16)).save(path)


def _float_tiff_case(tmp):
    """``fit`` of the test frame as a float TIFF (PIL mode F) of values fitting neither 0..1 nor 0..255 (the sum of
    two images): it was clipped without a word."""
    from PIL import Image

    args = _fit_case(tmp)
    args[1] = tmp / f"{FRAME}.tif"
    Image.fromarray(np.asarray(Image.open(args[1].with_suffix(".png")).convert("L"), np.float32) * 2).save(args[1])
    return args


def _file(tmp, name, text="x"):
    path = tmp / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _made(folder):
    """``folder``, made."""
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _npy_file(path):
    """An ``.npy`` file (one array, no ``.npz`` archive) at ``path``."""
    np.save(path, np.zeros(3))
    return path


def _bad_deflate_npz(path):
    """An artefact ``.npz`` at ``path`` whose first member's deflated data starts with a block of
    the reserved type (its first byte 0xFF), which zlib refuses to inflate."""
    import zipfile

    from wirescene.core.artefacts import save_npz

    save_npz(path, {"w": np.zeros(3)}, kind="parts-model", version=2)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        info = z.infolist()[0]
    name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26:info.header_offset + 30])
    data[info.header_offset + 30 + name_len + extra_len] = 0xFF
    path.write_bytes(bytes(data))
    return path


def _link(path, target):
    """A symbolic link at ``path`` (its folder made) to ``target``, which need not exist."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.symlink_to(target, target_is_directory=True)
    return path


def _shape_case(tmp, beside):
    """``train shape --out tmp/s.npz`` where a directory takes the place of ``beside``, a file
    the shape model's training writes next to it."""
    (tmp / beside).mkdir()
    return ["train", "shape", "--cad-dir", Path(__file__).parent / "data" / "cad", "--out", tmp / "s.npz",
            "--augment", "0"]


def _truncated_copy(tmp, frames, broken):
    """A KITTI root (``tmp/kitti``) of copies of the test ``frames`` whose image of frame ``broken`` is cut short."""
    root = kitti_copy(tmp / "kitti", frames)
    image = root / "training" / "image_2" / f"{broken}.png"
    image.write_bytes(image.read_bytes()[:3000])
    return root


def _jpeg_split(tmp):
    """A KITTI root (``tmp/kitti``) whose testing split holds the test frame as a JPEG (no .png)."""
    from PIL import Image

    root = kitti_copy(tmp / "kitti", [FRAME], subdirs=("calib",), split="testing")
    (root / "testing" / "image_2").mkdir()
    Image.open(SPLIT / "image_2" / f"{FRAME}.png").convert("RGB").save(root / "testing" / "image_2" / f"{FRAME}.jpg")
    return root


def _frames_folder(tmp, *names):
    """A plain folder (``tmp/frames``) of copies of the test frame's image named ``names`` (``FRAME.png``
    without), as a dashcam's frames: read with one calibration (``--calib``)."""
    folder = tmp / "frames"
    folder.mkdir()
    for name in names or (f"{FRAME}.png",):
        shutil.copy(SPLIT / "image_2" / f"{FRAME}.png", folder / name)
    return folder


def _unlabelled_split(tmp):
    """A KITTI root (``tmp/kitti``) whose training split has images and calibrations but an empty ``label_2/``."""
    root = kitti_copy(tmp / "kitti", [FRAME], subdirs=("image_2", "calib"))
    (root / "training" / "label_2").mkdir()
    return root


def _shape_model_file(tmp, *, components=None, mean=None):
    """A shape model file ``tmp/shape.npz``: the shipped one's first ``components`` components,
    or with ``mean`` for its mean (arrays of another shape)."""
    from wirescene.core.artefacts import save_npz
    from wirescene.core.shape import load_default

    m = load_default()
    k = m.n_components if components is None else components
    save_npz(tmp / "shape.npz", dict(mean=m.mean if mean is None else mean, components=m.components[:k],
                                     stds=m.stds[:k], explained_variance_ratio=m.explained_variance_ratio[:k],
                                     exemplar_names=np.asarray(m.exemplar_names), exemplars=m.exemplars),
             kind="shape-model", version=1)
    return tmp / "shape.npz"


def _classifier_file(tmp, features: int):
    """A viewpoint classifier file ``tmp/v.npz`` of ``features`` features (the crops have 1957)."""
    from wirescene.predetect.viewpoint_classifier import ViewpointClassifier

    ViewpointClassifier(np.zeros(features), np.ones(features), np.zeros((features, 8)), np.zeros(8)).save(tmp / "v.npz")
    return tmp / "v.npz"


def _dets_dir(tmp, files):
    d = tmp / "dets"
    d.mkdir()
    for name, text in files.items():
        (d / name).write_text(text)
    return d


def _predict_resume_case(tmp, record, *, resume=True):
    """``predict`` of the test frame (label boxes, coarse) into ``tmp/pred``, which holds a settings' record
    ``record`` (text, or None: a folder of its name) and no label file."""
    pred = tmp / "pred"
    if record is None:
        (pred / ".predict.json").mkdir(parents=True)
    else:
        _file(tmp, "pred/.predict.json", record)
    return ["predict", KITTI_ROOT, "--split", "training", "--variant", "coarse", "--detections", "gt", "--frames",
            FRAME, "--workers", "1", "--particles", "20", "--out", pred, *(["--resume"] if resume else [])]


def _cars_in_one_fold(tmp, *, occluded=False):
    """A KITTI root of the test frame and of a copy of another frame (of another fold) whose label holds no Car
    (``occluded``: its Cars, all of occlusion level 2, which the part training leaves out)."""
    root = kitti_copy(tmp / "kitti", [FRAME, "001545"])
    label = root / "training" / "label_2" / "001545.txt"
    if occluded:
        rows = [r.split() for r in label.read_text().splitlines()]
        label.write_text("".join(" ".join(r[:2] + ["2"] + r[3:]) + "\n" if r[0] == "Car" else " ".join(r) + "\n"
                                 for r in rows))
        assert "Car" in label.read_text()
    else:
        label.write_text("DontCare -1 -1 -10 1000 160 1040 190 -1 -1 -1 -1000 -1000 -1000 -10\n")
    assert fold_of(FRAME) != fold_of("001545")
    return root


def _grey_root(tmp):
    """A KITTI root (``tmp/kitti``) of one unlabelled frame: a uniform grey image (no car to find) and the test
    frame's calibration."""
    from PIL import Image

    root = kitti_copy(tmp / "kitti", [FRAME], subdirs=("calib",))
    (root / "training" / "image_2").mkdir()
    Image.new("RGB", (1242, 375), (128, 128, 128)).save(root / "training" / "image_2" / f"{FRAME}.png")
    return root


def _bank_without_ground_prior(tmp):
    """The shipped detector bank saved as ``tmp/bank.npz`` without its ground prior."""
    from dataclasses import replace

    from wirescene.predetect.bank import load_default_bank

    bank = load_default_bank()
    return replace(bank, meta={k: v for k, v in bank.meta.items() if k != "ground_prior"}).save(tmp / "bank.npz")


PLY_FACE_PAST_VERTICES = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                          "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n4 0 0\n0 1 1\n"
                          "3 0 1 7\n")

def _broken_link(tmp):
    """``tmp/ln``: a symbolic link to nothing (``tmp/gone``), given where an output folder goes."""
    (tmp / "ln").symlink_to(tmp / "gone")
    return tmp / "ln"


# A COCO result file (a detector's output over a data set): boxes of every image, told by image_id.
COCO_TWO_IMAGES = [{"image_id": 7, "category_id": 3, "bbox": [300, 180, 220, 90], "score": 0.9},
                   {"image_id": 8, "category_id": 3, "bbox": [600, 170, 80, 60], "score": 0.8}]


CASES = {
    # calibration
    "calib NaN P2": (lambda t: _fit_case(t, calib=_with_p2(" ".join(["nan"] * 12))), "not a number|non-finite"),
    "calib all-zero P2": (lambda t: _fit_case(t, calib=_with_p2(" ".join(["0"] * 12))), "P2:"),
    "calib duplicate P2": (lambda t: _fit_case(t, calib=CALIB_TEXT + P2_LINE + "\n"), "P2 is given twice"),
    "calib inf focal": (lambda t: _fit_case(t, calib=_with_p2("inf 0 609 44 0 721 172 0.2 0 0 1 0.003")), "non-finite"),
    "calib huge focal": (lambda t: _fit_case(t, calib=_with_p2("1e308 0 609 44 0 721 172 0.2 0 0 1 0.003")),
                         "implausible focal"),
    "calib negative focal": (lambda t: _fit_case(t, calib=_with_p2("-721 0 609 44 0 721 172 0.2 0 0 1 0.003")),
                             "implausible focal"),
    "calib tiny focal": (lambda t: _fit_case(t, calib=_with_p2("1e-12 0 609 44 0 1e-12 172 0.2 0 0 1 0.003")),
                         "implausible focal"),
    "calib far principal point": (lambda t: _fit_case(t, calib=_with_p2("721 0 90000 44 0 721 172 0.2 0 0 1 0.003")),
                                  "principal point"),
    "calib of 8 numbers": (lambda t: _fit_case(t, calib="721 0 609 0 721 172 0 0\n"), "found 8 numbers"),
    "calib of words": (lambda t: _fit_case(t, calib="fx 721 cx 609\n"), "not a number"),
    "calib K not upper triangular": (lambda t: _fit_case(t, calib="721 0 609 0 721 172 0.5 0 1\n"), "upper triangular"),
    # labels and detections
    "txt x2 < x1": (lambda t: _fit_case(t, dets=(".txt", CAR.replace("354.43 185.52 549.52", "549.52 185.52 354.43"))),
                    "empty or inverted"),
    "box at x2 = 1e30": (lambda t: _fit_case(t, dets=(".txt", CAR.replace("549.52", "1e30"))), "absurdly far"),
    "box outside the image": (lambda t: _fit_case(t, dets=(".json", json.dumps([{"box": [5000, 10, 5100, 60]}]))),
                              "entirely outside"),
    "negative dimensions": (lambda t: _fit_case(t, dets=(".txt", CAR.replace("1.43 1.70 3.95", "-1.43 1.70 3.95"))),
                            "dimensions must be positive"),
    "truncation 5.0": (lambda t: _fit_case(t, dets=(".txt", CAR.replace("Car 0.00", "Car 5.00"))), "truncation"),
    "COCO bbox strings": (lambda t: _fit_case(t, dets=(".json", '[{"bbox": ["a", 1, 2, 3]}]')), "bbox must be"),
    "COCO bbox null": (lambda t: _fit_case(t, dets=(".json", '[{"bbox": null}]')), "bbox must be"),
    "deeply nested JSON": (lambda t: _fit_case(t, dets=(".json", "[" * 100000 + "]" * 100000)), "nested too deeply"),
    "5001-digit number": (lambda t: _fit_case(t, dets=(".json", '[{"box": [' + "9" * 5001 + ", 1, 2, 3]}]")),
                          "not a usable JSON"),
    "score NaN": (lambda t: _fit_case(t, dets=(".json", '[{"box": [300, 180, 520, 300], "score": NaN}]')),
                  "score must be finite"),
    "txt alpha in degrees": (lambda t: _fit_case(t, dets=(".txt", CAR.replace("Car 0.00 0 1.95", "Car 0.00 0 111.7"))),
                             r"alpha must be radians within one turn, got 111\.7 \(degrees\?\)"),
    "JSON alpha in degrees": (lambda t: _fit_case(t, dets=(".json", '[{"box": [300, 180, 520, 300], "alpha": -45}]')),
                              "alpha must be radians within one turn"),
    # images
    "16-bit image is fine": None,  # behaviour test below
    "decompression bomb": (lambda t: _fit_case(t, image=lambda p: p.write_bytes(_png_header(100000, 100000))),
                           "too large"),
    "10 x 10 image, boxes to x = 1241": (
        lambda t: _fit_case(t, image=lambda p: __import__("PIL.Image").Image.new("RGB", (10, 10)).save(p)),
        "principal point|entirely outside|absurdly far|too small"),
    "float TIFF image of 0..510": (_float_tiff_case, rf"^wirescene: error: \S+/{FRAME}\.tif: float values outside both "
                                                     r"0\.\.1 and 0\.\.255 \(dtype float32, \d+\.\.510\) would be clipped"),
    # was "image: image of 8x8 px is too small": the API's argument named, not the file
    "8 x 8 image with its own calibration": (
        lambda t: _fit_case(t, calib="20 0 4 0 20 4 0 0 1\n", dets=(".json", '[{"box": [1, 1, 6, 6]}]'),
                            image=lambda p: __import__("PIL.Image").Image.new("RGB", (8, 8)).save(p)),
        rf"^wirescene: error: \S+/{FRAME}\.png: image of 8x8 px is too small \(at least 16 px a side\)$"),
    # options
    "--particles 0": (lambda t: _fit_case(t, extra=("--particles", "0")), "--particles"),
    "--particles -5": (lambda t: _fit_case(t, extra=("--particles", "-5")), "--particles"),
    "--samples 0": (lambda t: _fit_case(t, extra=("--samples", "0")), "--samples"),
    "eval --seed -1": (lambda t: _eval_case(t, "--seed", "-1"), "--seed"),
    "--box-weight nan": (lambda t: _fit_case(t, extra=("--box-weight", "nan")), "--box-weight"),
    "--iterations -1": (lambda t: _fit_case(t, extra=("--iterations", "-1")), "--iterations"),
    "--workers 0": (lambda t: _eval_case(t, "--workers", "0"), "--workers"),
    "--prune-after -2": (lambda t: _fit_case(t, extra=("--prune-after", "-2")), "--prune-after"),
    "--viewpoint-noise nan": (lambda t: _eval_case(t, "--viewpoint-noise", "nan"), "--viewpoint-noise"),
    "fit without --calib": (lambda t: ["fit", _fit_case(t)[1], "--out", t / "o"], r"--calib: missing \(required\)$"),
    "fit without an image": (lambda t: ["fit", "--calib", "c.txt", "--out", t / "o"], r"IMAGE: missing \(required\)$"),
    "--frames twice": (lambda t: ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", f"{FRAME},{FRAME}"], "listed twice"),
    "--frames unknown": (lambda t: ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", "424242"],
                        r"--frames: no labelled frame 424242 in .*kitti/training$"),  # was "in the dataset"
    "predict of a split without .png images": (
        lambda t: ["predict", _jpeg_split(t), "--out", t / "submission", "--workers", "1"],
        r"testing/image_2: no \.png file \(it holds \.jpg files; KITTI's images are \.png\)$"),
    "detect on a split without .png images": (
        lambda t: ["detect", _jpeg_split(t), "--split", "testing", "--out", t / "dets"],
        r"testing/image_2: no \.png file \(it holds \.jpg files; KITTI's images are \.png\)$"),
    # one calibration for every frame (--calib): refused before any frame, naming the file
    "predict --calib not found": (
        lambda t: ["predict", _frames_folder(t), "--calib", t / "K.txt", "--out", t / "out", "--workers", "1"],
        r"^wirescene: error: \S+/K\.txt: calibration file not found$"),
    "detect --calib of 8 numbers": (
        lambda t: ["detect", _frames_folder(t), "--calib", _file(t, "K.txt", "721 0 609 0 721 172 0 0\n"), "--out",
                   t / "dets"], r"\S+/K\.txt: expected a KITTI calibration .* found 8 numbers$"),
    "pitch --calib of a folder": (
        lambda t: ["pitch", _frames_folder(t), "--calib", t, "--json", t / "pitch.json"],
        r"^wirescene: error: \S+: calibration path is not a file$"),
    "eval --calib without P2": (
        lambda t: ["eval", kitti_copy(t / "kitti", [FRAME], subdirs=("image_2", "label_2")), "--calib",
                   _file(t, "calib.txt", CALIB_TEXT.replace(P2_LINE + "\n", "")), "--variant", "coarse", "--json",
                   t / "m.json", "--predictions", t / "pred"], r"calib\.txt: calibration has no P2 matrix$"),
    "predict --calib of a folder without images": (
        lambda t: ["predict", _file(t, "frames/notes.txt").parent, "--calib", SPLIT / "calib" / f"{FRAME}.txt",
                   "--out", t / "out"], r"frames: no \.png, \.jpg or \.jpeg file \(it holds \.txt files\)$"),
    "predict --calib of a KITTI root without the split": (
        lambda t: ["predict", KITTI_ROOT, "--calib", SPLIT / "calib" / f"{FRAME}.txt", "--out", t / "out"],
        r"kitti: no \.png, \.jpg or \.jpeg file \(it holds only the folders ImageSets, training, no testing/image_2\)$"),
    "predict --calib of a KITTI root with a file, without the split": (
        lambda t: ["predict", _file(kitti_copy(t / "kitti", [FRAME]), "SOURCES.md", "# drives\n").parent, "--calib",
                   SPLIT / "calib" / f"{FRAME}.txt", "--out", t / "out"],
        r"kitti: no \.png, \.jpg or \.jpeg file \(it holds \.md files and the folders training, no testing/image_2\)$"),
    "predict --calib of a frame of two images": (
        lambda t: ["predict", _frames_folder(t, f"{FRAME}.png", f"{FRAME}.jpg"), "--calib",
                   SPLIT / "calib" / f"{FRAME}.txt", "--out", t / "out"],
        rf"frames: frame {FRAME} has two images \({FRAME}\.jpg, {FRAME}\.png\): keep one$"),
    "predict of a folder of frames without --calib": (
        lambda t: ["predict", _frames_folder(t), "--out", t / "out"],
        r"frames: not a KITTI object directory: expected testing/image_2 and testing/calib \(or image_2 and calib\); "
        r"predict, detect, pitch and eval take one calibration for every frame \(--calib FILE\) for a folder of one "
        r"camera's frames$"),
    # the reason first: --frames said "no labelled frame 424242 in .../testing" of a split of images alone
    "eval --frames of a split without label_2": (
        lambda t: ["eval", kitti_copy(t / "kitti", [FRAME], subdirs=("image_2", "calib"), split="testing") / "testing",
                   "--variant", "coarse", "--frames", "424242"], r"testing: evaluation needs label_2/ ground truth$"),
    # the AP's curve needs labels: it was silently not drawn
    "detect --pr-curve of a split without label_2": (
        lambda t: ["detect", kitti_copy(t / "kitti", [FRAME], subdirs=("image_2", "calib"), split="testing") / "testing",
                   "--pr-curve", t / "pr.png"], r"--pr-curve draws the AP's precision and recall against the labels: "
                                                 r".*testing has no label_2/$"),
    "eval of a split without label files": (
        lambda t: ["eval", _unlabelled_split(t), "--variant", "coarse"], r"training/label_2: no \.txt file \(it is empty\)$"),
    # outputs, refused before any fitting
    "--json is a directory": (lambda t: _eval_case(t, "--json", t), "is a directory"),
    "--json under a file": (lambda t: _eval_case(t, "--json", _file(t, "f") / "m.json"), "is a file"),
    "--predictions is a file": (lambda t: _eval_case(t, "--predictions", _file(t, "f")), "is a file"),
    "fit --out is a file": (lambda t: [*_fit_case(t), "--out", _file(t, "o")], "is a file"),
    "fit --out holding a folder of an output's name": (
        lambda t: [*_fit_case(t), "--out", _file(t, f"o/{FRAME}_overlay.png/x").parents[1]],
        rf"o/{FRAME}_overlay\.png: a folder where the fit writes a file$"),
    "demo --out is a file": (lambda t: ["demo", "--out", _file(t, "o")], "is a file"),
    # os.access says yes to root and knows nothing of pseudo file systems: a real try refuses these
    "fit --out under /proc": (lambda t: [*_fit_case(t), "--out", "/proc/wirescene-check/out"],
                              r"--out: /proc/wirescene-check/out: /proc is not writable"),
    "kitti-eval --json under /proc": (lambda t: ["kitti-eval", SPLIT / "label_2", SPLIT / "label_2", "--json",
                                                 "/proc/wirescene-check/k.json"], "--json: .*/proc is not writable"),
    "gt of a frame not in the split": (lambda t: ["gt", KITTI_ROOT, "999999", "--out", t / "gt.png"],
                                       r"^wirescene: error: FRAME: no frame 999999 in .*training \(its image_2 holds "
                                       r"\d+ frames, e.g\. \d{6}\)$"),
    "gt --out is a directory": (lambda t: ["gt", KITTI_ROOT, FRAME, "--out", t], "--out: .* is a directory"),
    "gt --out under a file": (lambda t: ["gt", KITTI_ROOT, FRAME, "--out", _file(t, "f") / "gt.png"], "--out: .*is a file"),
    "gt --out of no picture format": (lambda t: ["gt", KITTI_ROOT, FRAME, "--out", t / "gt.txt"],
                                      r"^wirescene: error: --out: .*gt\.txt: \.txt is not a picture format \(\.png, "),
    "cad show --out under a file": (lambda t: ["cad", "show", "acura-nsx-sz", "--cad-dir", Path(__file__).parent / "data" / "cad",
                                               "--out", _file(t, "f") / "car.png"], "--out: .*is a file"),
    "cad show --out of no picture format": (
        lambda t: ["cad", "show", "acura-nsx-sz", "--cad-dir", Path(__file__).parent / "data" / "cad", "--out",
                   t / "car.json"], r"--out: .*car\.json: \.json is not a picture format"),
    "synth OUT_DIR under /proc": (lambda t: ["synth", "/proc/wirescene-check", "--scenes", "1"],
                                  "OUT_DIR: .*/proc is not writable"),
    # refused before any scene is drawn (they were all drawn, then a traceback: "Not a directory")
    "synth OUT_DIR/training a link to nothing": (
        lambda t: ["synth", _link(t / "s" / "training", t / "unmounted" / "training").parent, "--scenes", "1"],
        r"^wirescene: error: .*/s/training: a symbolic link to .*/unmounted/training, which leads to no folder"),
    "synth --cars-per-scene 5-2": (lambda t: ["synth", t / "s", "--cars-per-scene", "5-2"],
                                   r"^wirescene: error: --cars-per-scene: need 1 <= A <= B <= 1000, got '5-2'$"),
    "detect --threshold nan": (lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--threshold", "nan"],
                               "--threshold: 'nan' is not finite"),
    "detect --camera-pitch 60": (lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--camera-pitch", "60"],
                                 "--camera-pitch: 60 is above the maximum 45"),
    "detect --smallest-car 3": (lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--smallest-car", "3"],
                                r"--smallest-car: 3 is below the minimum 10 \(0: the bank's own\)"),
    "fit --samples 100000": (lambda t: [*_fit_case(t), "--samples", "100000", "--out", t / "o"],
                             r"--samples: 100000 is not in the range 2<=x<=200"),
    "fit --smallest-car 2": (lambda t: [*_fit_case(t), "--smallest-car", "2", "--out", t / "o"],
                             r"--smallest-car: 2 is below the minimum 10 \(0: the bank's own\)"),
    "fit --upsample 0.5": (lambda t: [*_fit_case(t), "--upsample", "0.5", "--out", t / "o"],
                           r"--upsample: 0.5 is below the minimum 1$"),
    "detect --upsample 5": (lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--upsample", "5"],
                            r"--upsample: 5 is above the maximum 3$"),
    "fit --set a plane grid too fine": (
        lambda t: [*_fit_case(t), "--set", "lifting.pitch_step=0.01", "--set", "lifting.roll_step=0.01", "--set",
                   "lifting.roll_range=3", "--out", t / "o"],
        r"^wirescene: error: --set: lifting.pitch_range, lifting.pitch_step, lifting.roll_range, lifting.roll_step give "
        r"601 pitches x 601 rolls = 361,201 ground planes, at most 250,000"),
    "eval --set predetect.smallest_car=5": (
        lambda t: ["eval", KITTI_ROOT, "--variant", "coarse", "--frames", FRAME, "--set", "predetect.smallest_car=5"],
        r"predetect.smallest_car must be 0 \(the bank's own\) or at least 10, got 5.0"),
    # a frame that fails after others were detected: none of their files is left behind
    "detect --out, a later image truncated": (
        lambda t: ["detect", _truncated_copy(t, ["000002", FRAME], FRAME), "--frames", f"000002,{FRAME}",
                   "--out", t / "dets"], rf"image_2/{FRAME}\.png: corrupt or truncated image"),
    "eval devkit mapping malformed": (_eval_mapping_case, r"train_rand\.txt.*entry 2 \('x'\)"),
    # trained files the fit reads: refused naming the file before any frame is read
    "fit --shape-model of another kind": (
        lambda t: _fit_case(t, extra=("--shape-model", DATA_DIR / "viewpoint_classifier.npz")),
        r"viewpoint_classifier\.npz: format 'wirescene-viewpoint-classifier/1', expected 'wirescene-shape-model/1'"),
    "fit --shape-model of arrays of another shape": (
        lambda t: _fit_case(t, extra=("--shape-model", _shape_model_file(t, mean=np.zeros((30, 3))))),
        r"shape\.npz: malformed shape model \(mean of shape \(30, 3\), expected \(36, 3\)\)$"),
    "fit --shape-model of fewer components than searched": (
        lambda t: _fit_case(t, extra=("--shape-model", _shape_model_file(t, components=3), "--variant", "fg")),
        r"shape\.npz: shape model of 3 components, the fine stage searches 5 \(--set inference.n_shape=N"),
    "fit --viewpoint-classifier corrupt": (lambda t: _fit_case(t, extra=("--viewpoint-classifier", _file(t, "v.npz"))),
                                           r"v\.npz: corrupt artefact file"),
    # np.load gives an .npy file's one array, not an archive: was a TypeError's traceback
    "fit --parts-model a single .npy array": (
        lambda t: _fit_case(t, extra=("--parts-model", _npy_file(t / "p.npy"), "--variant", "full")),
        r"p\.npy: corrupt artefact file \(a single \.npy array, not an \.npz archive\)$"),
    # a member whose deflated data does not inflate (zlib.error: was a traceback)
    "fit --parts-model of corrupt compressed data": (
        lambda t: _fit_case(t, extra=("--parts-model", _bad_deflate_npz(t / "p.npz"), "--variant", "full")),
        r"p\.npz: corrupt artefact file \(compressed data that does not inflate\)$"),
    # info reads each file's format tag: its own read of an npz, a zlib.error's traceback
    "info --models of a part model of corrupt compressed data": (
        lambda t: ["info", "--models", _bad_deflate_npz(_made(t / "m") / "parts_model.npz").parent],
        r"parts_model\.npz: corrupt artefact file \(compressed data that does not inflate\)$"),
    "fit --viewpoint-classifier of other features": (
        lambda t: _fit_case(t, extra=("--viewpoint-classifier", _classifier_file(t, 10))),
        r"v\.npz: viewpoint classifier of 10 features, expected 1957$"),
    "fit --score-calibration malformed": (
        lambda t: _fit_case(t, extra=("--score-calibration", _file(t, "s.json", json.dumps(
            {"format": "wirescene-score-calibration/2", "coarse": {}})))), r"s\.json: malformed score calibration"),
    "eval --models with a broken shape model": (
        lambda t: _eval_case(t, "--models", _file(t, "models/shape_model.npz").parent),
        r"models/shape_model\.npz: corrupt artefact file"),
    "detect --viewpoint-classifier without --out": (
        lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--viewpoint-classifier", DATA_DIR / "viewpoint_classifier.npz"],
        "--viewpoint-classifier gives the boxes --out writes their viewpoints: it needs --out"),
    "detect --viewpoint-classifier corrupt": (
        lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--out", t / "dets", "--viewpoint-classifier",
                   _file(t, "v.npz")], r"v\.npz: corrupt artefact file"),
    # detection directories
    "eval detections match no frame": (lambda t: _eval_case(t, "--detections", _dets_dir(t, {"10.csv": "x1,y1,x2,y2\n1,2,3,4\n"})),
                                       "none of the frames"),
    "fit --min-score nan": (lambda t: _fit_case(t, extra=("--min-score", "nan")), "--min-score: 'nan' is not finite"),
    "fit --min-score without --detections": (
        lambda t: _fit_case(t)[:4] + ["--min-score", "0.5", "--out", t / "out"],
        "--min-score needs --detections FILE: our own pre-detection's floor is its detection threshold "
        r"\(--detection-threshold\)$"),
    # refused before any fit (and before the word that the frames are not held out), not at the first fit
    "eval --evidence oracle on KITTI": (lambda t: _eval_case(t, "--variant", "fg", "--evidence", "oracle"),
                                        r"wireframes/.*: oracle evidence needs wireframes/ ground truth"),
    # a coarse variant takes a viewpoint-less box's viewpoint from the evidence: refused at the first fit, after the
    # word that the frames are not held out
    "eval --evidence oracle on KITTI, boxes without a viewpoint": (
        lambda t: _eval_case(t, "--evidence", "oracle", "--detections", _boxes_without_viewpoint(t)),
        r"wireframes/.*: oracle evidence needs wireframes/ ground truth"),
    "eval --min-score with label boxes": (lambda t: _eval_case(t, "--detections", "gt", "--min-score", "0.5"),
                                          r"--min-score needs --detections DIR: label boxes \('gt'\) are all fitted"),
    "predict --min-score with our own boxes": (
        lambda t: ["predict", KITTI_ROOT, "--split", "training", "--frames", FRAME, "--out", t / "pred", "--min-score",
                   "0.5"], r"--min-score needs --detections DIR: our own pre-detection's floor is its detection threshold"),
    "eval detections: two files for one frame": (
        lambda t: _eval_case(t, "--detections", _dets_dir(t, {f"{FRAME}.json": '{"detections": []}',
                                                              f"{FRAME}.txt": ""})),
        rf"dets: frame {FRAME} has 2 detection files \({FRAME}\.json, {FRAME}\.txt\): keep one"),
    "eval detections: one frame's file in two cases": (
        lambda t: _eval_case(t, "--detections", _dets_dir(t, {f"{FRAME}.json": '{"detections": []}',
                                                              f"{FRAME}.JSON": '{"detections": []}'})),
        rf"dets: frame {FRAME} has 2 detection files \({FRAME}\.json, {FRAME}\.JSON\): keep one"),
    # training inputs
    "train parts --label-shapes not an artefact": (
        lambda t: ["train", "parts", "--kitti-root", KITTI_ROOT, "--out", t / "p.npz", "--label-shapes",
                   _file(t, "shapes.npz")], r"shapes\.npz.*corrupt artefact"),
    "train parts with no training data": (lambda t: ["train", "parts", "--out", t / "p.npz", "--synth-scenes", "0"],
                                          "synth_scenes: no training data"),
    "train parts --n-trees 0": (lambda t: ["train", "parts", "--out", t / "p.npz", "--n-trees", "0"], "--n-trees"),
    "train parts --synth-seed 5": (lambda t: ["train", "parts", "--out", t / "p.npz", "--synth-seed", "5"],
                                   "--synth-seed"),
    "train detector --C 0": (lambda t: ["train", "detector", "--out", t / "b.npz", "--C", "0"], "--C: 0 is not above 0"),
    "train detector --per-octave 0": (lambda t: ["train", "detector", "--out", t / "b.npz", "--per-octave", "0"],
                                      "--per-octave"),
    # sizes that grow time or memory without end: a typo's hours refused before any work
    "train detector --per-octave 60": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--per-octave", "60"],
        r"--per-octave: 60 is not in the range 1<=x<=48"),
    "train parts --n-trees 3000": (lambda t: ["train", "parts", "--out", t / "p.npz", "--n-trees", "3000"],
                                   r"--n-trees: 3000 is not in the range 1<=x<=1000"),
    "synth --scenes 1000000": (lambda t: ["synth", t / "s", "--scenes", "1000000"],
                               r"--scenes: 1000000 is not in the range 1<=x<=100000"),
    "fit --particles 250000": (lambda t: _fit_case(t, extra=("--particles", "250000")),
                               r"--particles: 250000 is not in the range 1<=x<=25000"),
    "demo --particles 250000": (lambda t: ["demo", "--out", t / "demo", "--particles", "250000"],
                                r"--particles: 250000 is not in the range 1<=x<=25000"),
    "fit --particles x --samples beyond the memory's cap": (
        lambda t: _fit_case(t, extra=("--particles", "5000", "--samples", "20", "--set", "lifting.pitch_step=0.02")),
        r"^wirescene: error: lifting.n_particles x inference.samples = 3,913 \(one a plane of the grid\) x 20 = "
        r"78,260 hypotheses a car and iteration, at most 50,000"),
    "fit --set an azimuth step too fine": (
        lambda t: _fit_case(t, extra=("--set", "lifting.unknown_viewpoint_step=0.05")),
        r"^wirescene: error: --set: lifting.unknown_viewpoint_step gives 7,200 azimuths a detection, at most 3,600"),
    "fit --set azimuths x planes too many": (
        lambda t: _fit_case(t, extra=("--set", "lifting.pitch_step=0.01", "--set", "lifting.roll_step=0.01", "--set",
                                      "lifting.azimuth_step=0.25")),
        r"--set: lifting.pitch_step, lifting.roll_step, lifting.azimuth_halfwidth, lifting.azimuth_step give 180,901 "
        r"ground planes x 181 azimuths = 32,743,081 cells a detection"),
    # iterations, scenes, rounds, workers: counts whose time (or memory) a typo would multiply, refused at parsing
    "fit --iterations 100000": (lambda t: _fit_case(t, extra=("--variant", "full", "--iterations", "100000")),
                                r"--iterations: 100000 is not in the range 0<=x<=1000"),
    "fit --polish-iterations 100000": (lambda t: _fit_case(t, extra=("--variant", "full", "--polish-iterations",
                                                                     "100000")),
                                       r"--polish-iterations: 100000 is not in the range 0<=x<=1000"),
    "fit --set lifting.iterations=1000": (lambda t: _fit_case(t, extra=("--set", "lifting.iterations=1000")),
                                          r"--set: lifting.iterations must be at most 100, got 1000"),
    # a window past 180 deg would read as a limit where it is none: an angle is never further off
    "fit --viewpoint-window 270": (lambda t: _fit_case(t, extra=("--variant", "full", "--viewpoint-window", "270")),
                                   r"--viewpoint-window: 270 is above the maximum 180$"),
    "eval --set inference.iterations=5000": (lambda t: _eval_case(t, "--variant", "full", "--set",
                                                                  "inference.iterations=5000"),
                                             r"--set: inference.iterations must be at most 1000, got 5000"),
    "eval --workers 10000": (lambda t: _eval_case(t, "--workers", "10000"), r"--workers: 10000 is not in the range 1<=x<="),
    "eval --draws 10000000": (lambda t: _eval_case(t, "--draws", "10000000"),
                              r"--draws: 10000000 is not in the range 0<=x<=100000"),
    "kitti-eval --draws 10000000": (lambda t: ["kitti-eval", SPLIT / "label_2", _dets_dir(t, {f"{FRAME}.txt": CAR + " 0.9\n"}),
                                               "--frames", FRAME, "--draws", "10000000"],
                                    r"--draws: 10000000 is not in the range 0<=x<=100000"),
    "predict --workers 10000": (lambda t: ["predict", KITTI_ROOT, "--split", "training", "--variant", "coarse",
                                           "--detections", "gt", "--out", t / "pred", "--workers", "10000"],
                                r"--workers: 10000 is not in the range 1<=x<="),
    "train detector --scenes 100000": (lambda t: ["train", "detector", "--out", t / "b.npz", "--scenes", "100000"],
                                       r"--scenes: 100000 is not in the range 1<=x<=2000"),
    "train detector --val-scenes 100000": (lambda t: ["train", "detector", "--out", t / "b.npz", "--val-scenes", "100000"],
                                           r"--val-scenes: 100000 is not in the range 0<=x<=2000"),
    "train detector --mining-rounds 300": (lambda t: ["train", "detector", "--out", t / "b.npz", "--mining-rounds", "300"],
                                           r"--mining-rounds: 300 is not in the range 0<=x<=20"),
    "train detector --cut-paste 1000": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--cut-paste", "1000"],
        r"--cut-paste: 1000 is not in the range 0<=x<=50"),
    "train detector --max-negatives 10000000": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--max-negatives", "10000000"],
        r"--max-negatives: 10000000 is not in the range 1<=x<=100000"),
    "train detector --pyramid-cache-mb 1e6": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--pyramid-cache-mb", "1e6"],
        r"--pyramid-cache-mb: 1e\+06 is above the maximum 16000"),
    "train detector --workers 10000": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--workers", "10000"],
        r"--workers: 10000 is not in the range 1<=x<="),
    "train occlusion --scenes 100000": (lambda t: ["train", "occlusion", "--out", t / "o.json", "--scenes", "100000"],
                                        r"--scenes: 100000 is not in the range 1<=x<=3000"),
    "train parts --n-views 10000": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--n-views", "10000", "--kind", "sc", "--no-position"],
        r"--n-views: 10000 is not in the range 0<=x<=360"),
    "train parts --n-aug 1000": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--n-views", "2", "--n-aug", "1000", "--kind", "sc",
                   "--no-position"], r"--n-aug: 1000 is not in the range 1<=x<=20"),
    "train parts --synth-scenes 100000": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--synth-scenes", "100000"],
        r"--synth-scenes: 100000 is not in the range 0<=x<=3000"),
    "train parts --heldout every CAD car": (  # was a held-out accuracy of 0 on a forest trained on no car
        lambda t: ["train", "parts", "--out", t / "p.npz", "--n-views", "2", "--synth-scenes", "0", "--kind", "sc",
                   "--no-position", "--n-trees", "1", "--heldout", "1000"],
        r"heldout: holds out 1,000 of the \d+ CAD cars: at most \d+"),
    "train all --workers 10000": (lambda t: ["train", "all", KITTI_ROOT, "--out", t / "models", "--workers", "10000"],
                                  r"--workers: 10000 is not in the range 1<=x<="),
    "train parts --max-depth 1000": (lambda t: ["train", "parts", "--out", t / "p.npz", "--max-depth", "1000"],
                                     r"--max-depth: 1000 is not in the range 1<=x<=100"),
    "train detector --mining-images 10^6": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--mining-images", "1000000"],
        r"--mining-images: 1000000 is not in the range 1<=x<=100000"),
    "train detector --partial 50": (lambda t: ["train", "detector", "--out", t / "b.npz", "--partial", "50"],
                                    r"--partial: 50 is not in the range 0<=x<=20"),
    "train all --folds 100": (lambda t: ["train", "all", KITTI_ROOT, "--out", t / "models", "--folds", "100"],
                              r"--folds: 100 is not in the range 2<=x<=25"),
    "eval --seed given 101 times": (lambda t: _eval_case(t, *[a for s in range(101) for a in ("--seed", str(s))]),
                                    r"--seed: 101 seeds given, at most 100 \(each evaluates every frame again\)$"),
    "train parts on frames without a car": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--kitti-root", _carless_root(t), "--synth-scenes", "0"],
        "frames: none of the 1 real training frame.s. has a labelled Car"),
    # the held-out forest of the fold of every car learnt from background only: a calibration of no part, and a
    # held-out log loss of NaN (of the fold without cars) in --report
    "train parts --calibrate with the cars of one fold": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--kitti-root", _cars_in_one_fold(t), "--synth-scenes", "0",
                   "--n-trees", "1", "--max-depth", "4", "--calibrate"],
        r"calibrate_real: the held-out calibration needs labelled cars \(25 px high or more, occlusion 1 or less\) in 2 "
        r"or more folds \(drives\); those of the 2 frame\(s\) given lie in one"),
    # the other fold's Cars all too occluded to learn parts from: the same forest of background only
    "train parts --calibrate with the other fold's cars all occluded": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--kitti-root", _cars_in_one_fold(t, occluded=True),
                   "--synth-scenes", "0", "--n-trees", "1", "--max-depth", "4", "--calibrate"],
        r"needs labelled cars \(25 px high or more, occlusion 1 or less\) in 2 or more folds"),
    "train detector on frames without a car": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", _carless_root(t), "--no-calibration"],
        "none of the 1 training frame.s. has a labelled Car"),
    "train detector --folds x": (lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT,
                                            "--folds", "x"], "--folds: 'x' is not a comma-separated list"),
    "train detector --folds 7": (lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT,
                                            "--folds", "7"], "--folds: '7': the folds are 0 to 3"),
    "train detector, no frame in --folds": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--frames", FRAME,
                   "--folds", str((fold_of(FRAME) + 1) % N_FOLDS), "--no-calibration"], "folds: none of the 1 frame.s. given"),
    "train detector on one drive": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--frames", FRAME],
        "form a single group .one drive., so no held-out calibration can be fitted: give one"),
    "train detector of truncated cars only": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", _frame_root(t, CAR.replace(
            "Car 0.00", "Car 0.60") + "\n"), "--no-calibration"], "no detector can be trained: none of the 2 car examples"),
    "train detector --folds of other frames": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", kitti_copy(t / "k", [FRAME], rename={
            FRAME: "005000"}), "--folds", "0,1", "--no-calibration"], "folds: frame 005000 is not one of the shared"),
    "train viewpoints of one bin": (
        lambda t: ["train", "viewpoints", _frame_root(t, CAR + "\n"), "--out", t / "v.npz"],
        "show one viewpoint bin"),
    "train parts --synth-cache under a file": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--synth-cache", _file(t, "f") / "cache"], "is a file"),
    "train all parts.synth_cache under a file": (
        lambda t: ["train", "all", KITTI_ROOT, "--out", t / "m", "--set", f"parts.synth_cache={_file(t, 'f') / 'c'}"],
        "--set parts.synth_cache: .* is a file"),
    "train scores of a run given twice": (
        lambda t: ["train", "scores", t / "run", t / "x" / ".." / "run", "--out", t / "s.json"],
        "evaluation run given twice"),
    "train occlusion --scenes 0": (lambda t: ["train", "occlusion", "--out", t / "c.json", "--scenes", "0"], "--scenes"),
    "train occlusion --parts-model broken": (
        lambda t: ["train", "occlusion", "--out", t / "c.json", "--scenes", "1", "--parts-model", _file(t, "p.npz")],
        r"p\.npz: corrupt artefact file"),
    "train occlusion with a broken part model": (
        lambda t: ["train", "occlusion", "--out", t / "c.json", "--scenes", "1", "--models",
                   _file(t, "models/parts_model.npz").parent], r"models/parts_model\.npz: corrupt artefact file"),
    "train shape, cad_meshes.npz beside --out a directory": (
        lambda t: _shape_case(t, "cad_meshes.npz"), r"--out: .*cad_meshes\.npz is a directory, expected a file path"),
    "train shape --augment 10^10": (
        lambda t: ["train", "shape", "--cad-dir", Path(__file__).parent / "data" / "cad", "--out", t / "s.npz",
                   "--augment", "10000000000"], r"--augment: 10000000000 is not in the range 0<=x<=10000"),
    # a part model smoothed over more than its box (1e300: the fit's Gaussian kernel cannot be made)
    "train parts --smooth 2": (lambda t: ["train", "parts", "--out", t / "p.npz", "--smooth", "2", "--synth-scenes", "0"],
                               "--smooth: 2 is above the maximum 1"),
    "train all parts.smooth=1e300": (
        lambda t: ["train", "all", KITTI_ROOT, "--out", t / "m", "--set", "parts.smooth=1e300", "--frames", "424242"],
        r"--set: parts\.smooth must be at most 1"),
    "train parts --n-views with the box position": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--n-views", "2", "--kind", "sc", "--synth-scenes", "0"],
        r"n_views: CAD edge renderings \(--n-views\) carry no box position"),
    "train parts --kitti-background without --n-views": (
        lambda t: ["train", "parts", "--out", t / "p.npz", "--kitti-background", KITTI_ROOT, "--synth-scenes", "0"],
        "--kitti-background needs --n-views"),
    "train detector --threshold 7": (lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", t / "none",
                                                "--threshold", "7"], "--threshold: 7 is above the maximum 1"),
    "train detector --threshold with --no-calibration": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--frames", FRAME,
                   "--no-calibration", "--threshold", "0.7"], "--threshold is a calibrated bank's"),
    # options of the real frames' training given to the synthetic one, and the other way round: refused, not ignored
    "train detector --calibration without --kitti-root": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--calibration", "4,-2,0.6", "--scenes", "2",
                   "--val-scenes", "0", "--mining-rounds", "0", "--partial", "0"],
        r"--calibration needs a KITTI root \(KITTI_ROOT or --kitti-root\)$"),
    "train detector --scenes with --kitti-root": (
        lambda t: ["train", "detector", "--out", t / "b.npz", "--kitti-root", KITTI_ROOT, "--frames", FRAME,
                   "--scenes", "3"], "--scenes: synthetic training only, not with a KITTI root"),
    # synthetic scenes
    "synth into an empty path": (lambda t: ["synth", "", "--scenes", "1"], "OUT_DIR: empty path"),
    "synth of 10^20 scenes": (lambda t: ["synth", t / "s", "--scenes", "99999999999999999999"], "--scenes"),
    "synth into a non-empty directory": (lambda t: ["synth", _file(t, "training/x").parents[1], "--scenes", "1"],
                                         "already holds scenes"),
    # a settings' record that cannot be read was taken for none and written over (a resumed run with no label file)
    "predict --resume of an unreadable settings record": (
        lambda t: _predict_resume_case(t, "{not json"),
        r"^wirescene: error: \S+/pred/\.predict\.json: unreadable settings record \(JSONDecodeError\): cannot resume "
        r"from it \(remove it to start afresh, or choose another directory\)$"),
    "predict --resume of a settings record not a JSON object": (
        lambda t: _predict_resume_case(t, "[]"),
        r"pred/\.predict\.json: unreadable settings record \(a JSON list, not an object\): cannot resume from it"),
    # was IsADirectoryError's traceback, after the first frame's fit
    "predict where .predict.json is a folder": (
        lambda t: _predict_resume_case(t, None, resume=False),
        r"^wirescene: error: \S+/pred/\.predict\.json: a folder where predict writes its settings' record$"),
    # a record that is JSON but no object: was an AttributeError's traceback
    "train scores of a frame record not a JSON object": (
        lambda t: ["train", "scores", _file(t, f"run/.frames/{FRAME}.json", "[]").parents[1], "--out", t / "s.json"],
        rf"{FRAME}\.json: unreadable frame record \(a JSON list, not an object\)$"),
    # was "unreadable frame record ('variants')": a KeyError's bare key
    "train scores of a frame record without its variants": (
        lambda t: ["train", "scores", _file(t, f"run/.frames/{FRAME}.json", "{}").parents[1], "--out", t / "s.json"],
        rf"{FRAME}\.json: unreadable frame record \(no 'variants' entry\)$"),
    # a PR curve named .txt was a PNG under that name, as gt's and cad show's --out refuse
    "detect --pr-curve of no picture format": (
        lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--pr-curve", t / "pr.txt"],
        r"^wirescene: error: --pr-curve: .*pr\.txt: \.txt is not a picture format \(\.png, "),
    # fit's --gt was read without the image's size, which eval's labels are checked against
    "fit --gt of a box outside the image": (
        lambda t: [*_fit_case(t), "--gt", _file(t, "gt.txt", CAR.replace("354.43 185.52 549.52", "3000 185.52 3100"))],
        r"gt\.txt: line 1: 2D box \(x1 y1 x2 y2 = 3000 185\.52 3100 294\.49\) lies entirely outside the 1242x375 image"),
    # a probability above 1 dropped every car of our own pre-detection
    "fit --min-car-probability 2": (lambda t: _fit_case(t, extra=("--min-car-probability", "2")),
                                    r"--min-car-probability: 2 is above the maximum 1$"),
    # was int()'s "invalid literal for int() with base 10"
    "fit --set of an integer given 2.5": (lambda t: _fit_case(t, extra=("--set", "inference.iterations=2.5")),
                                          r"--set: inference\.iterations: expected an integer, got '2\.5'$"),
    "fit --set of a number given a word": (lambda t: _fit_case(t, extra=("--set", "lifting.camera_height=high")),
                                           r"--set: lifting\.camera_height: expected a number, got 'high'$"),
    # a directory where a file is expected (and the other way round) was "not found"
    "fit --calib a directory": (lambda t: (lambda a: [*a[:3], _file(t, "cdir/x").parent, *a[4:]])(_fit_case(t)),
                                r"cdir: calibration path is not a file$"),
    "fit --detections a directory": (lambda t: (lambda a: [*a[:5], _file(t, "ddir/x").parent, *a[6:]])(_fit_case(t)),
                                     r"ddir: detections path is not a file$"),
    "fit --models a file": (lambda t: _fit_case(t, extra=("--models", _file(t, "models.npz"))),
                            r"models\.npz: models path is not a directory$"),
    "detect of a KITTI root that is a file": (lambda t: ["detect", _file(t, "kitti.zip")],
                                               r"kitti\.zip: KITTI root path is not a directory$"),
    "synth where OUT_DIR/training is a file": (
        lambda t: ["synth", _file(t, "s/training", "mine").parent, "--scenes", "1", "--overwrite"],
        r"^wirescene: error: OUT_DIR: \S+/s/training is a file, not a folder of scenes"),
    # an empty path (an unset variable's --out "$OUT") was the current directory: written into, exit 0 (the test
    # runs these in tmp_path, so that what they write there shows)
    "fit --out empty": (lambda t: [*_fit_case(t), "--out", ""],
                        r"^wirescene: error: --out: empty path \(give a directory, e\.g\. '\.'\)$"),
    "predict --out empty": (lambda t: ["predict", KITTI_ROOT, "--split", "training", "--variant", "coarse",
                                       "--detections", "gt", "--frames", FRAME, "--workers", "1", "--out", ""],
                            r"^wirescene: error: --out: empty path \(give a directory"),
    "detect --out empty": (lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--out", ""],
                           r"^wirescene: error: --out: empty path \(give a directory"),
    "eval --predictions empty": (lambda t: _eval_case(t, "--draws", "0", "--predictions", ""),
                                 r"^wirescene: error: --predictions: empty path \(give a directory"),
    "eval --report empty": (lambda t: _eval_case(t, "--draws", "0", "--report", ""),
                            r"^wirescene: error: --report: empty path \(give a directory"),
    "eval --json empty": (lambda t: _eval_case(t, "--draws", "0", "--json", " "),
                          r"^wirescene: error: --json: empty path \(give a file name\)$"),
    "demo --out empty": (lambda t: ["demo", "--out", "", "--variant", "coarse", "--particles", "5"],
                         r"^wirescene: error: --out: empty path \(give a directory"),
    "cad show --out empty": (lambda t: ["cad", "show", "acura-nsx-sz", "--cad-dir", Path(__file__).parent / "data" / "cad",
                                        "--out", ""], r"^wirescene: error: --out: empty path \(give a file name\)$"),
    "train all --set parts.synth_cache empty": (
        lambda t: ["train", "all", KITTI_ROOT, "--out", t / "m", "--set", "parts.synth_cache=", "--frames", "424242"],
        r"^wirescene: error: --set: parts\.synth_cache must be a path, got ''$"),
    # a number where a path goes was Path(5)'s TypeError, a traceback
    "train all --set parts.synth_cache a number": (
        lambda t: ["train", "all", KITTI_ROOT, "--out", t / "m", "--set", "parts.synth_cache=5", "--frames", "424242"],
        r"^wirescene: error: --set: parts\.synth_cache must be a path, got 5 \(a name of digits or a JSON word: \./5\)$"),
    "train all --set parts.label_shapes empty": (
        lambda t: ["train", "all", KITTI_ROOT, "--out", t / "m", "--set", "parts.label_shapes=", "--frames", "424242"],
        r"^wirescene: error: --set: parts\.label_shapes is not an option of train all \(it is `wirescene train parts "
        r"--label-shapes FILE`'s\)$"),
    "eval of an empty KITTI_ROOT": (lambda t: ["eval", "", "--variant", "coarse"],
                                    r"^wirescene: error: KITTI_ROOT: empty path \(give a directory"),
    # --detections "$DETS" unset: a directory name, not a path type, and read as the current directory
    "eval --detections empty": (lambda t: _eval_case(t, "--draws", "0", "--detections", "", "--allow-missing-detections"),
                                r"^wirescene: error: --detections: empty path \(give a directory"),
    "predict --detections empty": (lambda t: ["predict", KITTI_ROOT, "--split", "training", "--variant", "coarse",
                                              "--detections", " ", "--frames", FRAME, "--workers", "1", "--out",
                                              t / "submission"],
                                   r"^wirescene: error: --detections: empty path \(give a directory"),
    # a corrupt file of --models: its "models from DIR" line came before the error's
    "info --models with a corrupt file": (lambda t: ["info", "--models", _file(t, "models/shape_model.npz").parent],
                                          r"^wirescene: error: \S+/models/shape_model\.npz: corrupt"),
    # numpy's words: "cannot read mesh (IndexError: index 2 is out of bounds for axis 0 with size 2)"
    "cad list of an OBJ face past its vertices": (
        lambda t: ["cad", "list", "--cad-dir", _file(t, "cad/car.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n").parent],
        r"^wirescene: error: \S+/cad/car\.obj: OBJ line 3: vertex reference 3 out of range \(the file has 2 "
        r"vertices\)$"),
    # a latin-1 0x85 (a UTF-8 byte of "Å") is no line end: the face's line is the fourth
    "cad list of an OBJ face past its vertices after a UTF-8 comment": (
        lambda t: ["cad", "list", "--cad-dir", _file(t, "cad/car.obj", "# Ångström car by Åsa\nv 0 0 0\nv 1 0 0\n"
                                                                       "f 1 2 3\n").parent],
        r"car\.obj: OBJ line 4: vertex reference 3 out of range"),
    "cad list of an OBJ face of words": (
        lambda t: ["cad", "list", "--cad-dir", _file(t, "cad/car.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n").parent],
        r"car\.obj: OBJ line 4: non-integer vertex reference 'x'$"),
    # trimesh read vertex 0 (OBJ counts from 1) as the last vertex: another mesh, without a word
    "cad list of an OBJ face of vertex 0": (
        lambda t: ["cad", "list", "--cad-dir", _file(t, "cad/car.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                                                       "f 0 1 2\n").parent],
        r"^wirescene: error: \S+/cad/car\.obj: OBJ line 5: vertex reference 0 \(OBJ counts vertices from 1, or back "
        r"from -1\)$"),
    "pitch with a bank without a ground prior": (
        lambda t: ["pitch", KITTI_ROOT, "--frames", FRAME, "--bank", _bank_without_ground_prior(t), "--json",
                   t / "pitch.json"],
        r"^wirescene: error: \S+/bank\.npz: detector bank without a ground prior to read a pitch with"),
    # the pitch told was printed, and written to --json, as the pitch read (exit 0, a warning aside)
    "pitch of frames without a box": (
        lambda t: ["pitch", _grey_root(t), "--json", t / "pitch.json"],
        r"^wirescene: error: \S+/training/image_2: no box to read the pitch off in the 1 frame read: give frames of "
        r"cars \(--frames, --max-frames\)$"),
    # a COCO result file holds every image's boxes: all of them were fitted to this image
    "fit --detections of a COCO result file of two images": (
        lambda t: _fit_case(t, dets=(".json", json.dumps(COCO_TWO_IMAGES))),
        r"dets\.json: detection 1 is of image_id 8, detection 0 of 7: a detections file holds one image's boxes "
        r"\(split a COCO result file by image_id: wirescene split-coco\)$"),
    # its first box was taken for the header and no box was read: an empty scene, exit 0
    "fit --detections of a CSV without its header": (
        lambda t: _fit_case(t, dets=(".csv", "300,180,520,300\n")),
        r"dets\.csv: CSV header must name x1,y1,x2,y2 \(optional score, viewpoint_bin, alpha\), got "
        r"'300,180,520,300'$"),
    # a car fitted to a box of a fifth of a pixel: 957 m to the left, 178 m ahead
    "fit --detections in normalised coordinates": (
        lambda t: _fit_case(t, dets=(".csv", "x1,y1,x2,y2\n0.24,0.48,0.42,0.8\n")),
        r"dets\.csv: every box is under a pixel \(box 0: x1 y1 x2 y2 = 0\.24 0\.48 0\.42 0\.8\): normalised "
        r"coordinates\? boxes are in pixels$"),
    # millimetres: each car fitted 1650 m below the camera
    "fit --set lifting.camera_height in millimetres": (
        lambda t: _fit_case(t, extra=("--set", "lifting.camera_height=1650")),
        r"--set: lifting\.camera_height must be at most 50, got 1650\.0$"),
    "detect --camera-height in centimetres": (
        lambda t: ["detect", KITTI_ROOT, "--frames", FRAME, "--camera-height", "165"],
        r"--camera-height: 165 is above the maximum 50$"),
    # predictions' angles in degrees scored 0% 3D AP without a word
    "kitti-eval of predictions with rotation_y in degrees": (
        lambda t: ["kitti-eval", SPLIT / "label_2", _dets_dir(t, {f"{FRAME}.txt": CAR.replace(" 1.76", " 100.8 0.9")}),
                   "--frames", FRAME, "--draws", "0"],
        rf"dets/{FRAME}\.txt: line 1: rotation_y must be radians within one turn, got 100\.8 \(degrees\?\)$"),
    # a corrupt translation column was taken as it was: the car's x was -1.4e297 m in the label file, exit 0
    "calib P2 translation 1e300": (
        lambda t: _fit_case(t, calib=_with_p2("721.5 0 609 1e300 0 721.5 172.9 0.2 0 0 1 0.003")),
        r"calib\.txt: P2: camera centre 1\.386e\+297 m from the frame's origin on an axis \(at most 100 m\): a corrupt "
        r"translation column \(P's 4th\), or one in millimetres\?$"),
    # each row kept the last x1: box 0 was x1 y1 x2 y2 = 1 180 520 300, fitted without a word
    "CSV header naming a column twice": (lambda t: _fit_case(t, dets=(".csv", "x1,y1,x2,y2,x1\n300,180,520,300,1\n")),
                                         r"dets\.csv: CSV header names the column 'x1' twice$"),
    # int() dropped the fraction (bin 2) and took true for bin 1
    "JSON viewpoint_bin 2.7": (lambda t: _fit_case(t, dets=(".json", '[{"box": [300, 180, 520, 300], "viewpoint_bin": 2.7}]')),
                               r"detection 0: viewpoint_bin must be an integer 0\.\.7, got '2\.7'$"),
    "JSON viewpoint_bin true": (
        lambda t: _fit_case(t, dets=(".json", '[{"box": [300, 180, 520, 300], "viewpoint_bin": true}]')),
        r"detection 0: viewpoint_bin must be an integer 0\.\.7, got 'True'$"),
    # float(True): a score of 1, as a bool box coordinate is refused
    "JSON score true": (lambda t: _fit_case(t, dets=(".json", '[{"box": [300, 180, 520, 300], "score": true}]')),
                        r"dets\.json: detection 0: score must be a number$"),
    # an output folder that is a symbolic link to nothing passed the checks: FileExistsError's traceback at its
    # mkdir (eval's --report after every fit, predict's --json-dir after its settings' record was written)
    "fit --out a broken symbolic link": (
        lambda t: [*_fit_case(t), "--out", _broken_link(t)],
        r"^wirescene: error: --out: \S+/ln is a broken symbolic link \(to \S+/gone\)$"),
    "fit --out under a broken symbolic link": (
        lambda t: [*_fit_case(t), "--out", _broken_link(t) / "run"],
        r"^wirescene: error: --out: \S+/ln is a broken symbolic link \(to \S+/gone\)$"),
    "eval --report a broken symbolic link": (
        lambda t: _eval_case(t, "--draws", "0", "--report", _broken_link(t)),
        r"^wirescene: error: --report: \S+/ln is a broken symbolic link"),
    "predict --json-dir a broken symbolic link": (
        lambda t: ["predict", KITTI_ROOT, "--split", "training", "--variant", "coarse", "--detections", "gt",
                   "--frames", FRAME, "--workers", "1", "--out", t / "submission", "--json-dir", _broken_link(t)],
        r"^wirescene: error: --json-dir: \S+/ln is a broken symbolic link"),
    # a folder name longer than the file system allows: Path.exists() raised ENAMETOOLONG, a traceback
    "predict --out of a name too long": (
        lambda t: ["predict", KITTI_ROOT, "--split", "training", "--variant", "coarse", "--detections", "gt",
                   "--frames", FRAME, "--workers", "1", "--out", t / ("a" * 300) / "out"],
        r"^wirescene: error: --out: \S+/a{300}/out: File name too long$"),
    "synth into a name too long": (
        lambda t: ["synth", t / ("a" * 300), "--scenes", "1"], r"^wirescene: error: OUT_DIR: \S+/a{300}: File name too long$"),
    "cad list of a PLY face past its vertices": (  # loaded as it is by trimesh, refused later or not at all
        lambda t: ["cad", "list", "--cad-dir", _file(t, "cad/car.ply", PLY_FACE_PAST_VERTICES).parent],
        r"car\.ply: a face refers to vertex 7, the file has 3 vertices \(0 to 2\)$"),
}


@pytest.mark.parametrize("case", [c for c, v in CASES.items() if v is not None])
def test_bad_input_ends_in_one_line_and_exit_code_2(tmp_path, monkeypatch, case):
    make, pattern = CASES[case]
    args = [str(a) for a in make(tmp_path)]
    if "" in [a.strip() for a in args]:  # an empty path is the current directory: what it writes there shows
        monkeypatch.chdir(tmp_path)
    before = {p for p in tmp_path.rglob("*")}
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2, (case, r.output, r.exception)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("wirescene: error: "), r.stderr
    import re

    assert re.search(pattern, lines[0]), lines[0]
    after = {p for p in tmp_path.rglob("*")}
    assert after <= before, f"{case} left {sorted(after - before)}"


def test_every_path_parameter_refuses_an_empty_path():
    """Every path option and argument of every command is a NonEmptyPath: "" (an unset shell variable) is
    refused naming it, not read as the current directory (click's own Path takes it for ".")."""
    import click

    from wirescene.cli.options import NonEmptyPath

    def commands(command, name):
        yield name, command
        for sub, child in getattr(command, "commands", {}).items():
            yield from commands(child, f"{name} {sub}")

    paths = [(name, p) for name, command in commands(main, "wirescene") for p in command.params
             if isinstance(p.type, click.Path)]
    assert len(paths) > 40
    assert [f"{name} {p.name}" for name, p in paths if not isinstance(p.type, NonEmptyPath)] == []


def test_api_refuses_an_empty_path(tmp_path, monkeypatch):
    """evaluate's kitti_root, predictions, models and detections of "" (an unset variable): an ArgumentError naming the
    argument, not the current directory read or written."""
    import wirescene
    from wirescene.core.errors import ArgumentError

    monkeypatch.chdir(tmp_path)
    for name, kwargs in (("kitti_root", dict(kitti_root="")), ("predictions", dict(kitti_root=KITTI_ROOT, predictions="")),
                         ("models", dict(kitti_root=KITTI_ROOT, models=" ")),
                         ("detections", dict(kitti_root=KITTI_ROOT, detections=""))):
        with pytest.raises(ArgumentError, match=rf"^{name}: empty path \(give a directory, e\.g\. '\.'\)$"):
            wirescene.evaluate(**kwargs, variants="coarse", frames=[FRAME], particles=5)
    assert list(tmp_path.iterdir()) == []


# Label rows that cannot be (row appended to the test frame's label file -> the problem named).
BAD_LABEL_ROWS = {
    "car box right of the image": (CAR.replace("354.43 185.52 549.52 294.49", "1300 185.52 1400 294.49"),
                                   r"2D box \(x1 y1 x2 y2 = 1300 185.52 1400 294.49\) lies entirely outside the "
                                   r"1242x375 image"),
    "car box above the image": (CAR.replace("185.52 549.52 294.49", "-90 549.52 -10"), "2D box .* entirely outside"),
    "DontCare box outside the image": ("DontCare -1 -1 -10 1500 160 1560 190 -1 -1 -1 -1000 -1000 -1000 -10",
                                       "2D box .* entirely outside"),
    "x2 = 1e30": (CAR.replace("549.52", "1e30"), r"2D box coordinate 1e\+30 is absurdly far from any image"),
    "x1 = -1e6": (CAR.replace("354.43", "-1e6"), r"2D box coordinate -1e\+06 is absurdly far from any image"),
    "x2 NaN": (CAR.replace("549.52", "nan"), r"column 7 \(x2\) is not finite"),
    "y1 -inf": (CAR.replace("185.52", "-inf"), r"column 6 \(y1\) is not finite"),
    "x2 < x1": (CAR.replace("354.43 185.52 549.52", "549.52 185.52 354.43"), "2D box is empty or inverted"),
    "y2 = y1": (CAR.replace("294.49", "185.52"), "2D box is empty or inverted"),
    # ground truth in degrees: every car's orientation (AOS) wrong without a word
    "alpha in degrees": (CAR.replace("Car 0.00 0 1.95", "Car 0.00 0 111.7"),
                         r"alpha must be radians within one turn, got 111\.7 \(degrees\?\)$"),
}


@pytest.mark.parametrize("case", BAD_LABEL_ROWS)
def test_eval_refuses_label_boxes_that_cannot_be_naming_file_and_row(tmp_path, case):
    row, problem = BAD_LABEL_ROWS[case]
    args = [str(a) for a in _eval_label_case(tmp_path, row)]
    before = set(tmp_path.rglob("*"))
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2, (case, r.output, r.exception)
    # The frame's progress bar (erased on a terminal) may precede the error line.
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("eval: ")]
    assert len(lines) == 1, r.stderr
    assert re.match(rf"wirescene: error: \S+/label_2/{FRAME}\.txt: line {LABEL_ROWS + 1}: {problem}", lines[0]), lines[0]
    assert set(tmp_path.rglob("*")) <= before, f"{case} left {sorted(set(tmp_path.rglob('*')) - before)}"


def _predict_without_p2_case(tmp):
    """``predict`` of a copy of the test frame whose calibration lacks P2 (found by the frame's fit)."""
    root = kitti_copy(tmp / "kitti", [FRAME], subdirs=("image_2", "calib"))
    (root / "training" / "calib" / f"{FRAME}.txt").write_text(CALIB_TEXT.replace(P2_LINE + "\n", ""))
    return ["predict", root, "--split", "training", "--variant", "coarse", "--detections",
            _dets_dir(tmp, {f"{FRAME}.txt": CAR + "\n"}), "--workers", "1", "--out", tmp / "submission"]


def _later_frame_bad_dets(tmp):
    """A detections directory whose first frame's (000002) file is fine and the test frame's is not."""
    return _dets_dir(tmp, {"000002.json": json.dumps([{"box": [600, 170, 680, 230]}]),
                           f"{FRAME}.json": json.dumps([{"box": [5000, 170, 5100, 230]}])})


def _boxes_without_viewpoint(tmp, alpha=None):
    """A detections directory of a box for 000002 and the test frame, without a viewpoint (as a detection file's
    boxes come; the fit scores it on the image) unless ``alpha``."""
    box = {"box": [600, 170, 680, 230], **({} if alpha is None else {"alpha": alpha})}
    return _dets_dir(tmp, {f"{f}.json": json.dumps([box]) for f in ("000002", FRAME)})


# Runs that fail after their fits began: the report's pictures already drawn, the settings' record of
# `predict`, appear only with the whole (or with a finished frame), so nothing is left behind.
FAILING_RUNS = {
    # the coarse fit of label boxes never reads the image, the report's overlay does: each image is decoded before
    # the first fit (the frames fitted before it and their records were left behind, refused after every fit)
    "eval --report, image truncated": (
        lambda t: ["eval", _truncated_copy(t, [FRAME], FRAME), "--variant", "coarse", "--frames", FRAME, "--workers",
                   "1", "--draws", "0", "--report", t / "report"], rf"image_2/{FRAME}\.png: corrupt or truncated"),
    "eval --predictions --report, a later image truncated": (
        lambda t: ["eval", _truncated_copy(t, ["000002", FRAME], FRAME), "--variant", "coarse", "--workers", "1",
                   "--draws", "0", "--predictions", t / "pred", "--report", t / "report"],
        rf"image_2/{FRAME}\.png: corrupt or truncated image \(image file is truncated\)$"),
    # predict decodes each image before the first fit where it reads them (its pictures, our own boxes, part evidence)
    "predict --pictures, a later image truncated": (
        lambda t: ["predict", _truncated_copy(t, ["000002", FRAME], FRAME), "--split", "training", "--variant",
                   "coarse", "--detections", "gt", "--workers", "1", "--out", t / "submission", "--pictures",
                   t / "pictures"], rf"image_2/{FRAME}\.png: corrupt or truncated image \(image file is truncated\)$"),
    # boxes without a viewpoint: even the coarse fit reads the image (the bank scores each box's viewpoint there)
    "eval --predictions, boxes without a viewpoint, a later image truncated": (
        lambda t: ["eval", _truncated_copy(t, ["000002", FRAME], FRAME), "--variant", "coarse", "--workers", "1",
                   "--draws", "0", "--detections", _boxes_without_viewpoint(t), "--predictions", t / "pred"],
        rf"image_2/{FRAME}\.png: corrupt or truncated image \(image file is truncated\)$"),
    "predict, boxes without a viewpoint, a later image truncated": (
        lambda t: ["predict", _truncated_copy(t, ["000002", FRAME], FRAME), "--split", "training", "--variant",
                   "coarse", "--detections", _boxes_without_viewpoint(t), "--workers", "1", "--out", t / "submission"],
        rf"image_2/{FRAME}\.png: corrupt or truncated image \(image file is truncated\)$"),
    "predict, calibration without P2": (_predict_without_p2_case, "calibration has no P2"),
    # the training commands decode every training image before any step (train all failed in its parts step)
    "train all, a later training image truncated": (
        lambda t: ["train", "all", _truncated_copy(t, ["000002", FRAME], FRAME), "--out", t / "models"],
        rf"image_2/{FRAME}\.png: corrupt or truncated image \(image file is truncated\)$"),

    # the detection files are read before the first fit, as the calibrations and labels: the first frame's
    # outputs (label files, its record, the settings' record) were left behind
    "eval --predictions, a later frame's detection file malformed": (
        lambda t: ["eval", kitti_copy(t / "kitti", ["000002", FRAME]), "--variant", "coarse", "--workers", "1",
                   "--draws", "0", "--detections", _later_frame_bad_dets(t), "--predictions", t / "pred",
                   "--json", t / "m.json"], rf"dets/{FRAME}\.json: box 0 lies entirely outside the 1242x375 image"),
    "predict, a later frame's detection file malformed": (
        lambda t: ["predict", kitti_copy(t / "kitti", ["000002", FRAME]), "--split", "training", "--variant", "coarse",
                   "--workers", "1", "--detections", _later_frame_bad_dets(t), "--out", t / "submission"],
        rf"dets/{FRAME}\.json: box 0 lies entirely outside the 1242x375 image"),
}


@pytest.mark.parametrize("case", FAILING_RUNS)
def test_runs_failing_at_a_frame_leave_no_output(tmp_path, case):
    make, problem = FAILING_RUNS[case]
    args = [str(a) for a in make(tmp_path)]
    before = set(tmp_path.rglob("*"))
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2, (case, r.output, r.exception)
    # the progress bars, and eval's notice of the test frames the shipped models were trained on (not held out)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not re.match(r"(eval|predict): ", ln)
             and not re.match(r"wirescene: \d+ of the \d+ frames evaluated are among ", ln)]
    assert len(lines) == 1 and re.match(rf"wirescene: error: .*{problem}", lines[0]), r.stderr
    assert set(tmp_path.rglob("*")) <= before, f"{case} left {sorted(set(tmp_path.rglob('*')) - before)}"


@pytest.mark.parametrize("command", ["parts", "detector"])
def test_train_parts_and_detector_refuse_a_truncated_image_before_training(tmp_path, monkeypatch, command):
    """They read every training image: a truncated one is refused before the training starts (it was found when the
    training reached it, up to half an hour into the part step on a whole KITTI)."""
    import wirescene.training.kitti_detector
    import wirescene.training.parts

    def trained(*args, **kwargs):
        raise AssertionError("the training started")

    monkeypatch.setattr(wirescene.training.parts, "train_part_detector", trained)
    monkeypatch.setattr(wirescene.training.kitti_detector, "train_detector_bank_kitti", trained)
    root = _truncated_copy(tmp_path, ["000002", FRAME], FRAME)
    r = CliRunner().invoke(main, ["train", command, "--kitti-root", str(root), "--out", str(tmp_path / "m.npz")])
    assert r.exit_code == 2 and r.stderr.strip() == (f"wirescene: error: {root / 'training' / 'image_2'}/{FRAME}.png: "
                                                     "corrupt or truncated image (image file is truncated)"), r.stderr


@pytest.mark.parametrize("variant, detections, check_images, refused", [
    ("coarse", "gt", True, True),  # a report: its gallery draws fitted frames
    ("fg", "gt", False, True),  # the part detectors read every image
    ("coarse", "bank", False, True),  # our own pre-detection too
    ("coarse", "gt", False, False),  # nothing reads the pixels: the image is not decoded, the run as before
    ("coarse", "files", False, True),  # boxes without a viewpoint: the bank scores theirs on the image
    ("coarse", "files with alpha", False, False),  # boxes with their viewpoint: as label boxes
])
def test_eval_refuses_a_corrupt_image_before_any_fit_where_it_is_read(tmp_path, monkeypatch, variant, detections,
                                                                      check_images, refused):
    """A truncated image of a later frame is refused before the first fit where the run reads the images (it was
    found at its frame's fit, or by the report after every fit, the frames fitted before it kept)."""
    import wirescene.eval.runner as runner
    from wirescene.eval.sources import DetectionSource

    fitted = []

    def fit_frames(job, frame_ids, **kwargs):
        fitted.extend(frame_ids)
        raise RuntimeError("fitted")

    monkeypatch.setattr(runner, "fit_frames", fit_frames)
    dataset = KittiDataset(_truncated_copy(tmp_path, ["000002", FRAME], FRAME))
    if detections.startswith("files"):
        detections = str(_boxes_without_viewpoint(tmp_path, alpha=0.5 if "alpha" in detections else None))
    run = dict(frames=["000002", FRAME], source=DetectionSource(detections), check_images=check_images)
    if refused:
        with pytest.raises(InputError, match=rf"image_2/{FRAME}\.png: corrupt or truncated image"):
            runner.evaluate_dataset(dataset, [variant], **run)
        assert fitted == []
    else:
        with pytest.raises(RuntimeError, match="fitted"):
            runner.evaluate_dataset(dataset, [variant], **run)
        assert fitted == ["000002", FRAME]


@pytest.mark.parametrize("variant, detections, pictures, refused", [
    ("coarse", "gt", True, True),  # its pictures draw each frame
    ("fg", "gt", False, True),  # the part detectors read every image
    ("coarse", "bank", False, True),  # our own pre-detection too
    ("coarse", "files", False, True),  # boxes without a viewpoint: the bank scores theirs on the image
    ("coarse", "gt", False, False),  # nothing reads the pixels: the image is not decoded
])
def test_predict_refuses_a_corrupt_image_before_any_fit_where_it_is_read(tmp_path, monkeypatch, variant, detections,
                                                                         pictures, refused):
    """predict decodes before the first fit each image that its fits or pictures read, as eval does (boxes without
    a viewpoint were missed: the frames fitted before a truncated image left their label files)."""
    import wirescene.eval.predict as predict
    from wirescene.eval.sources import DetectionSource

    fitted = []

    def fit_frames(job, frame_ids, **kwargs):
        fitted.extend(frame_ids)
        raise RuntimeError("fitted")

    monkeypatch.setattr(predict, "fit_frames", fit_frames)
    dataset = KittiDataset(_truncated_copy(tmp_path, ["000002", FRAME], FRAME))
    source = DetectionSource(str(_boxes_without_viewpoint(tmp_path)) if detections == "files" else detections)
    run = dict(variant=variant, source=source, frames=["000002", FRAME],
               pictures_dir=tmp_path / "pictures" if pictures else None)
    with pytest.raises(InputError if refused else RuntimeError,
                       match=rf"image_2/{FRAME}\.png: corrupt or truncated image" if refused else "fitted"):
        predict.predict_dataset(dataset, tmp_path / "out", **run)
    assert fitted == ([] if refused else ["000002", FRAME])


def test_predict_of_label_boxes_reads_no_image_where_its_fit_needs_none(tmp_path):
    """The coarse fit of label boxes reads no pixel: predict's job no longer decodes each image (some 12 ms a frame
    of a 0.1 s fit), so a truncated one that nothing reads is no error (it was, at its frame, the frames fitted before
    it left behind), as eval's run of the same fits."""
    root = _truncated_copy(tmp_path, ["000002", FRAME], FRAME)
    r = CliRunner().invoke(main, ["predict", str(root), "--split", "training", "--variant", "coarse", "--detections",
                                  "gt", "--workers", "1", "--particles", "20", "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, (r.output, r.exception)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".predict.json", "000002.txt", f"{FRAME}.txt"]


def test_file_sha256_names_the_file_and_what_it_is(tmp_path):
    """The hash of a file a run records (a model file of the options, an image or split file of train all's) of a
    folder was IsADirectoryError's traceback; missing, it was an "artefact" whatever it was."""
    from wirescene.core.artefacts import MISSING_ARTEFACT
    from wirescene.core.resources import file_sha256
    from wirescene.fitting.models import models_fingerprint
    from wirescene.fitting.options import FitOptions

    with pytest.raises(InputError, match=rf"^{re.escape(str(tmp_path.resolve()))}: artefact path is not a file$"):
        models_fingerprint(FitOptions(parts_model=str(tmp_path)))
    with pytest.raises(InputError, match=rf"/parts\.npz: {re.escape(MISSING_ARTEFACT)}$"):
        models_fingerprint(FitOptions(parts_model=str(tmp_path / "parts.npz")))
    with pytest.raises(InputError, match=rf"^{re.escape(str(tmp_path.resolve()))}: image path is not a file$"):
        file_sha256(tmp_path, what="image")
    with pytest.raises(InputError, match=r"/nope\.png: image file not found$"):
        file_sha256(tmp_path / "nope.png", what="image")


def test_label_boxes_of_real_frames_are_accepted(tmp_path):
    """Truncated cars touching the border, DontCare regions and other classes are fine;
    so is every label file shipped with the package or the tests."""
    for root in (KITTI_ROOT, Path(wirescene.io.kitti.__file__).parents[1] / "data" / "sample" / "kitti"):
        ds = KittiDataset(root)
        assert all(len(ds.labels(f)) > 0 for f in ds.frame_ids())
    path = tmp_path / "edge.txt"
    path.write_text(CAR.replace("354.43 185.52 549.52 294.49", "0.00 160.00 120.50 374.00") + "\n"
                    + CAR.replace("354.43 185.52 549.52 294.49", "1100.00 150.00 1241.00 300.00") + "\n"
                    + "DontCare -1 -1 -10 1200.00 160.00 1241.00 190.00 -1 -1 -1 -1000 -1000 -1000 -10\n"
                    + "Pedestrian 0.00 0 0.2 700 150 730 240 1.7 0.6 0.8 2.0 1.6 20.0 0.3\n")
    labels = read_labels(path, image_size=(1242, 375))
    assert len(labels.objects) == 3 and len(labels.dontcare) == 1
    with pytest.raises(InputError, match=r"edge\.txt: line 2: .* entirely outside the 1100x300 image"):
        read_labels(path, image_size=(1100, 300))


def test_sixteen_bit_images_are_scaled_not_clipped(tmp_path):
    path = tmp_path / "g16.png"
    _write_16bit(path)
    rgb = read_image(path)
    assert rgb.dtype == np.uint8 and rgb.shape == (375, 1242, 3)
    assert 100 < rgb.mean() < 156 and rgb.min() == 0 and rgb.max() == 255


def test_csv_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "d.csv"
    path.write_bytes("x1,y1,x2,y2,score\n300,180,520,300,0.9\n".encode("utf-8-sig"))
    dets = read_detections(path)
    assert len(dets) == 1 and dets.scores[0] == pytest.approx(0.9)


def test_an_empty_csv_holds_no_box(tmp_path):
    """An empty CSV file (no header either) was "I/O operation on closed file"'s traceback: its header was
    looked for once the file was closed."""
    from wirescene.io.detections import NO_CARS

    (tmp_path / "d.csv").write_text("")
    with pytest.raises(InputError, match=rf"d\.csv: {NO_CARS}$"):
        read_detections(tmp_path / "d.csv")


def test_a_csv_with_unnamed_trailing_columns_is_read(tmp_path):
    """A spreadsheet's trailing commas name two empty columns: no column named twice (it was refused so)."""
    (tmp_path / "d.csv").write_text("x1,y1,x2,y2,score,,\n300,180,520,300,0.9,,\n")
    assert len(read_detections(tmp_path / "d.csv").boxes) == 1


def test_label_calib_and_split_files_with_a_byte_order_mark_are_read_whole(tmp_path):
    from wirescene.io.splits import read_split_file

    split = KITTI_ROOT / "training"
    for kind in ("label_2", "calib"):
        (tmp_path / f"{kind}.txt").write_bytes((split / kind / "000010.txt").read_text().encode("utf-8-sig"))
    labels = wirescene.io.kitti.read_labels(tmp_path / "label_2.txt")
    assert [o.type for o in labels.objects] == [o.type for o in wirescene.io.kitti.read_labels(
        split / "label_2" / "000010.txt").objects]  # the first object was typed "\ufeffCar" and lost as a car
    assert (read_kitti_calib(tmp_path / "calib.txt").P2 == read_kitti_calib(split / "calib" / "000010.txt").P2).all()
    (tmp_path / "split.txt").write_bytes("000010\n".encode("utf-8-sig"))
    assert read_split_file(tmp_path / "split.txt") == ["000010"]


def test_missing_detection_files_are_allowed_only_when_asked(tmp_path):
    d = _dets_dir(tmp_path, {"000002.json": json.dumps([{"box": [600, 170, 680, 230]}])})
    args = ["eval", str(KITTI_ROOT), "--variant", "coarse", "--frames", f"000002,{FRAME}", "--workers", "1",
            "--detections", str(d)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2 and f"1 of 2 frames have no detection file (e.g. no {FRAME}.json" in r.stderr
    r = CliRunner().invoke(main, args + ["--allow-missing-detections"])
    assert r.exit_code == 0, r.output
    assert "1 of 2 frames have no detection file" in r.stderr


def test_detection_files_with_an_upper_case_extension_are_read(tmp_path):
    """A detections directory of ``000010.JSON`` (as Windows tools write it) said the frame had no detection file:
    the extension is matched in any case, as ``read_detections`` reads it."""
    from wirescene.eval.sources import DetectionSource

    d = _dets_dir(tmp_path, {f"{FRAME}.JSON": json.dumps([{"box": [354.4, 185.5, 549.5, 294.5], "score": 0.9}]),
                             "000002.Csv": "x1,y1,x2,y2\n600,170,680,230\n"})
    source = DetectionSource(str(d))
    assert source.missing_frames(["000002", FRAME]) == []
    assert [source.detection_file(f).name for f in ("000002", FRAME)] == ["000002.Csv", f"{FRAME}.JSON"]
    dataset = KittiDataset(KITTI_ROOT)
    assert_close(source.for_frame(dataset, FRAME, None).boxes, [[354.4, 185.5, 549.5, 294.5]], atol=0, rtol=0)
    assert_close(source.for_frame(dataset, "000002", None).boxes, [[600, 170, 680, 230]], atol=0, rtol=0)
    r = CliRunner().invoke(main, ["eval", str(KITTI_ROOT), "--variant", "coarse", "--frames", FRAME, "--workers", "1",
                                  "--detections", str(d)])
    assert r.exit_code == 0, r.output


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process tree inspection via /proc")
def test_worker_processes_die_with_their_parent(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "wirescene.cli.main", "eval", str(KITTI_ROOT), "--variant", "full",
                             "--workers", "2", "--particles", "30"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def children():
        out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(proc.pid)], capture_output=True, text=True).stdout
        return [int(p) for p in out.split()]

    deadline = time.time() + 60
    kids = []
    while time.time() < deadline and len(kids) < 2:
        time.sleep(0.5)
        kids = children()
    assert len(kids) >= 2, "the pool did not start"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(Path(f"/proc/{k}").exists() and _alive(k) for k in kids):
        time.sleep(0.2)
    assert not any(Path(f"/proc/{k}").exists() and _alive(k) for k in kids)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has exited; init reaps it


# --------------------------------------------------------------------------- fuzzing

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _only_input_errors(fn, path):
    """The parser either returns or raises InputError naming the file: nothing else."""
    try:
        return fn(path)
    except InputError as exc:
        assert str(path) in str(exc)
        return None


@FUZZ
@given(st.lists(st.one_of(st.text(max_size=12), st.floats(allow_nan=True, allow_infinity=True).map(repr),
                          st.integers().map(str)), min_size=0, max_size=18))
def test_label_parser_never_crashes(tmp_path, tokens):
    path = tmp_path / "l.txt"
    path.write_text(" ".join(tokens).replace("\x00", "") + "\n", errors="surrogatepass")
    labels = _only_input_errors(read_labels, path)
    if labels is not None:
        for o in labels.objects:
            assert np.all(np.isfinite(o.box)) and o.box[2] > o.box[0] and o.box[3] > o.box[1]


@FUZZ
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=12, max_size=12),
       st.sampled_from(["P2", "P0", "R0_rect"]))
def test_calib_parser_accepts_only_sane_cameras(tmp_path, values, key):
    path = tmp_path / "c.txt"
    path.write_text(CALIB_TEXT.replace(P2_LINE, f"{key}: " + " ".join(repr(v) for v in values)))
    calib = _only_input_errors(read_kitti_calib, path)
    if calib is not None:
        K = calib.P2[:, :3] / calib.P2[2, 2]
        assert np.all(np.isfinite(calib.P2)) and 10 <= K[0, 0] <= 1e5 and 10 <= K[1, 1] <= 1e5


json_values = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True, allow_infinity=True) | st.integers() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(
        st.sampled_from(["box", "bbox", "score", "alpha", "viewpoint_bin", "category", "x1", "y1", "x2", "y2"]),
        inner, max_size=6),
    max_leaves=20,
)


@FUZZ
@given(json_values)
def test_json_detection_reader_never_crashes(tmp_path, data):
    path = tmp_path / "d.json"
    path.write_text(json.dumps(data))
    dets = _only_input_errors(lambda p: read_detections(p, image_size=(1242, 375)), path)
    if dets is not None:
        assert len(dets) > 0 and np.all(np.isfinite(dets.boxes)) and np.all(np.isfinite(dets.scores))


@FUZZ
@given(st.lists(st.lists(st.one_of(st.text(max_size=6), st.floats().map(repr)), min_size=1, max_size=6),
                max_size=5))
def test_csv_detection_reader_never_crashes(tmp_path, rows):
    path = tmp_path / "d.csv"
    path.write_text("x1,y1,x2,y2,score\n" + "\n".join(",".join(r).replace("\x00", "") for r in rows) + "\n")
    dets = _only_input_errors(read_detections, path)
    if dets is not None:
        assert np.all(dets.boxes[:, 2] > dets.boxes[:, 0]) and np.all(dets.boxes[:, 3] > dets.boxes[:, 1])


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(["--particles", "--samples", "--iterations", "--prune-after", "--box-weight", "--seed",
                        "--shape-prior", "--size-prior", "--polish-iterations"]),
       st.one_of(st.integers(-10**6, 0), st.sampled_from(["nan", "inf", "-inf", "x", "", "1e999"])))
def test_fit_options_out_of_range_are_refused_before_any_work(option, value):
    if option in ("--iterations", "--prune-after", "--seed", "--box-weight", "--shape-prior", "--size-prior",
                  "--polish-iterations") and value == 0:
        return  # 0 is a valid value of these
    r = CliRunner().invoke(main, ["fit", "nowhere.png", "--calib", "nowhere.txt", "--out", "nowhere", option, str(value)])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"wirescene: error: {option}"), r.stderr
