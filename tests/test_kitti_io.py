"""KITTI label / image / calibration I/O and dataset discovery."""

from __future__ import annotations

import os
import re
import shutil
import stat

import numpy as np
import pytest

from conftest import assert_close, kitti_copy
from wirescene.core.errors import InputError
from wirescene.io import (
    CAR_TYPES,
    KittiDataset,
    Label,
    car_indices,
    read_image,
    read_labels,
    select_cars,
    write_labels,
)

GOOD = "Car 0.00 0 1.95 354.43 185.52 549.52 294.49 1.43 1.70 3.95 -2.39 1.66 11.80 1.76"


def labels_of(kitti_root, frame="000010"):
    return read_labels(kitti_root / "training" / "label_2" / f"{frame}.txt")


def one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_read_labels_known_values(kitti_root):
    frame = labels_of(kitti_root)
    cars = frame.of_type(*CAR_TYPES)
    assert len(cars) == 8  # 8 Car lines in KITTI training/label_2/000010.txt
    assert len(frame.dontcare) == 4
    assert all(o.type != "DontCare" for o in frame.objects)
    assert [o.type for o in frame.objects].count("Pedestrian") == 1
    first = cars[0]
    assert first.type == "Car" and first.occluded == 0 and first.score is None
    assert_close(first.truncated, 0.80)
    assert_close(first.alpha, -2.09)
    assert_close(first.box, [1013.39, 182.46, 1241.00, 374.00])
    assert_close(first.dims, [1.57, 1.65, 3.35])
    assert_close(first.location, [4.43, 1.65, 5.20])
    assert_close(first.rotation_y, -1.42)
    # centroid: bottom centre raised by h/2 (camera y points down)
    assert_close(first.centroid, [4.43, 1.65 - 1.57 / 2, 5.20])
    assert [o.occluded for o in cars] == [0, 0, 0, 2, 0, 2, 1, 1]


def test_select_cars(kitti_root):
    frame = labels_of(kitti_root)
    idx = car_indices(frame)
    assert len(idx) == 8 and frame.objects[2].type == "Pedestrian" and 2 not in idx
    tall = select_cars(frame, min_height=50)
    assert all(c.height_px >= 50 for c in tall) and 0 < len(tall) < 8
    assert len(select_cars(frame, max_occluded=1)) == 6


def test_empty_and_blank_lines(tmp_path):
    p = tmp_path / "empty.txt"
    p.write_text("")
    frame = read_labels(p)
    assert frame.objects == [] and frame.dontcare == []
    p.write_text("\n" + GOOD + "\n\n")
    assert len(read_labels(p).objects) == 1


def test_round_trip_with_score(tmp_path, kitti_root):
    frame = labels_of(kitti_root)
    for i, o in enumerate(frame.objects):
        o.score = 0.5 + i * 1e-3
    frame.objects[0].rotation_y = 0.123456789  # angles keep more than the devkit's 2 decimals
    out = tmp_path / "sub" / "000010.txt"
    write_labels(out, frame)
    back = read_labels(out)
    assert len(out.read_text().splitlines()[0].split()) == 16
    assert len(back.objects) == len(frame.objects) and len(back.dontcare) == 4
    for a, b in zip(frame.objects + frame.dontcare, back.objects + back.dontcare):
        assert a.type == b.type and a.occluded == b.occluded
        assert_close(b.box, a.box, atol=5e-3)
        assert_close(b.location, a.location, atol=1e-6)
        assert_close(b.dims, a.dims, atol=1e-6)
        assert_close(b.rotation_y, a.rotation_y, atol=1e-6)
        assert_close(b.alpha, a.alpha, atol=1e-6)
    assert_close([o.score for o in back.objects], [o.score for o in frame.objects], atol=1e-6)
    assert back.dontcare[0].score == 0.0  # ground truth without score written as 0
    write_labels(out, frame.objects, with_score=False)
    assert all(len(line.split()) == 15 for line in out.read_text().splitlines())
    assert read_labels(out).objects[0].score is None


def test_write_is_atomic(tmp_path):
    out = tmp_path / "det.txt"
    out.write_text(GOOD + "\n")
    bad = Label("Car", 0, 0, np.nan, [0, 0, 1, 1], [1, 1, 1], [0, 0, 5], 0.0, 0.9)
    ok = Label("Car", 0, 0, 0.1, [0, 0, 1, 1], [1, 1, 1], [0, 0, 5], 0.0, 0.9)
    with pytest.raises(ValueError):
        write_labels(out, [ok, bad])
    assert out.read_text() == GOOD + "\n"  # old file untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["det.txt"]  # no temp file left


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX's")
def test_an_atomic_write_keeps_a_link_and_writes_into_a_pipe(tmp_path):
    """A link was replaced by a new file (its target left as it was), and a device or a pipe (`--json /dev/stdout`,
    as root: the container's /dev/stdout replaced by a file) by a file beside it: the link's target is written, the
    pipe written into."""
    from wirescene.core.jsonio import write_json

    target = tmp_path / "runs" / "metrics.json"
    target.parent.mkdir()
    target.write_text("old")
    (tmp_path / "latest.json").symlink_to(target)
    write_json(tmp_path / "latest.json", {"ap": float("nan")})
    assert (tmp_path / "latest.json").is_symlink() and target.read_text() == '{\n "ap": null\n}'
    assert sorted(p.name for p in target.parent.iterdir()) == ["metrics.json"]
    (tmp_path / "runs.json").symlink_to(target.parent)  # a link to a folder: refused, not replaced by a file
    with pytest.raises(InputError, match="runs.json: a folder where a file is written$"):
        write_json(tmp_path / "runs.json", [])
    assert (tmp_path / "runs.json").is_symlink()
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # a reader waiting, as a shell's pipe has
    try:
        write_json(fifo, [1, 2])
        assert os.read(reader, 100) == b"[\n 1,\n 2\n]" and fifo.is_fifo()
    finally:
        os.close(reader)


def test_an_oserror_in_an_atomic_write_names_the_file_asked_for_and_keeps_an_errnoless_one(tmp_path):
    """A full disk (no file named, or the temporary one) is told of the file asked for; an OSError without
    an errno (an encoder's message, io.UnsupportedOperation) was "[Errno None] None: 'PATH'", a plain OSError."""
    import errno
    import io

    from wirescene.core.atomic import atomic_path

    out = tmp_path / "a.png"
    with pytest.raises(OSError) as exc:
        with atomic_path(out):
            raise OSError(errno.ENOSPC, "No space left on device")
    assert (exc.value.errno, exc.value.filename) == (errno.ENOSPC, str(out))
    for raised in (OSError("cannot write mode RGBA as JPEG"), io.UnsupportedOperation("not writable")):
        with pytest.raises(type(raised)) as exc:
            with atomic_path(out):
                raise raised
        assert exc.value is raised and str(exc.value) == str(raised)
    assert list(tmp_path.iterdir()) == []


def test_an_oserror_in_a_set_of_files_names_the_file_of_the_set_not_of_its_staging_folder(tmp_path):
    """A report's page or a synthetic scene written into the staging folder of a set when the disk fills was told of
    `.SET.<hex>.tmp/...`, a folder gone by the time the message is read: the file's place in the set is named."""
    import errno

    from wirescene.core.atomic import atomic_dir, replaced_dir

    for staged in (atomic_dir, replaced_dir):
        with pytest.raises(OSError) as exc:
            with staged(tmp_path / "set") as staging:
                (staging / "seed-1").mkdir()
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(staging / "seed-1" / "index.html"))
        assert (exc.value.errno, exc.value.filename) == (errno.ENOSPC, str(tmp_path / "set" / "seed-1" / "index.html"))
        assert list(tmp_path.iterdir()) == []


def test_a_full_disk_met_by_a_write_in_a_set_names_the_set(tmp_path):
    """A full disk met by write() (not open()) names no file: `split-coco` onto a full disk said "wirescene: error: No
    space left on device", naming nothing; the set asked for is named, as atomic_path names its file."""
    import errno

    from wirescene.core.atomic import atomic_dir, replaced_dir

    for staged in (atomic_dir, replaced_dir):
        with pytest.raises(OSError) as exc:
            with staged(tmp_path / "set") as staging:
                (staging / "000001.json").write_text("[]")
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        assert (exc.value.errno, exc.value.filename) == (errno.ENOSPC, str(tmp_path / "set"))
        assert list(tmp_path.iterdir()) == []


def test_an_oserror_making_a_temporary_names_the_file_asked_for_and_any_name_is_kept(tmp_path, monkeypatch):
    """A full disk or a refused place when the temporary file (or a set's staging folder) is made was told of
    `.NAME.<hex>.tmp` (in a set: `SET/DIR/.NAME.<hex>.tmp`, a name no set holds); an OSError naming bytes or a file
    descriptor in a set was a TypeError; os.replace's second name (filename2) in the staging folder was dropped."""
    import errno

    import wirescene.core.atomic as atomic

    def refused(directory, *, prefix, suffix):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(directory / f"{prefix}0123456789ab{suffix}"))

    with monkeypatch.context() as patched:
        patched.setattr(atomic, "_new_file", refused)
        with pytest.raises(OSError) as exc:
            atomic.write_text(tmp_path / "a.txt", "x")
        assert (exc.value.errno, exc.value.filename) == (errno.ENOSPC, str(tmp_path / "a.txt"))
        for staged in (atomic.atomic_dir, atomic.replaced_dir):
            with pytest.raises(OSError) as exc:
                with staged(tmp_path / "set") as staging:
                    atomic.write_text(staging / "seed-1" / "index.html", "x")
            assert exc.value.filename == str(tmp_path / "set" / "seed-1" / "index.html")
    with monkeypatch.context() as patched:
        patched.setattr(atomic, "_new_dir", refused)
        with pytest.raises(OSError) as exc:
            with atomic.atomic_dir(tmp_path / "new" / "set"):
                pass
        assert exc.value.filename == str(tmp_path / "new" / "set")
    for name in (b"/somewhere", 5):
        with pytest.raises(OSError) as exc:
            with atomic.atomic_dir(tmp_path / "set"):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), name)
        assert exc.value.filename == name
    with pytest.raises(OSError) as exc:
        with atomic.atomic_dir(tmp_path / "set") as staging:
            raise OSError(errno.EXDEV, os.strerror(errno.EXDEV), "/elsewhere/a", None, str(staging / "a"))
    assert (exc.value.filename, exc.value.filename2) == ("/elsewhere/a", str(tmp_path / "set" / "a"))
    assert list(tmp_path.iterdir()) == []


def test_a_set_that_cannot_take_its_place_leaves_the_old_one_whole(tmp_path, monkeypatch):
    from pathlib import Path

    import wirescene.core.atomic as atomic

    (tmp_path / "set").mkdir()
    (tmp_path / "set" / "old.txt").write_text("old")
    real = os.replace

    def failing_from(n):  # os.replace failing from its n-th call on: 1 moves the old set aside, 2 the new one in
        calls = []

        def replace(src, dst):
            calls.append(src)
            if len(calls) >= n:
                raise OSError("device busy")
            return real(src, dst)
        return replace

    # the new set cannot move in, and the old one cannot move back: it is kept where it is, and named
    monkeypatch.setattr(atomic.os, "replace", failing_from(2))
    with pytest.raises(OSError, match="the old one is left in") as info:
        with atomic.replaced_dir(tmp_path / "set") as staging:
            (staging / "new.txt").write_text("new")
    monkeypatch.undo()
    kept = Path(str(info.value).rsplit(" left in ", 1)[1])
    assert (kept / "old.txt").read_text() == "old"
    real(kept, tmp_path / "set")
    kept.parent.rmdir()
    # the new set cannot move in, the old one moves back: as it was, nothing else left
    calls = []

    def fail_second(src, dst):
        calls.append(src)
        if len(calls) == 2:
            raise OSError("device busy")
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", fail_second)
    with pytest.raises(OSError, match="device busy"):
        with atomic.replaced_dir(tmp_path / "set") as staging:
            (staging / "new.txt").write_text("new")
    assert len(calls) == 3 and sorted(p.name for p in (tmp_path / "set").iterdir()) == ["old.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["set"]


def test_a_set_replaced_through_a_link_stays_where_the_link_points(tmp_path):
    from wirescene.core.atomic import replaced_dir

    (tmp_path / "big_disk" / "set").mkdir(parents=True)
    (tmp_path / "big_disk" / "set" / "old.txt").write_text("old")
    (tmp_path / "set").symlink_to(tmp_path / "big_disk" / "set", target_is_directory=True)
    with replaced_dir(tmp_path / "set") as staging:
        (staging / "new.txt").write_text("new")
    assert (tmp_path / "set").is_symlink()
    assert [p.name for p in (tmp_path / "big_disk" / "set").iterdir()] == ["new.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big_disk", "set"]
    assert [p.name for p in (tmp_path / "big_disk").iterdir()] == ["set"]


def test_a_set_replaced_through_a_relative_link_or_a_link_to_nothing(tmp_path):
    """A relative link is followed from its own folder; a link to nothing (a disk not mounted) or a loop of links is
    refused naming it before the block's work (it failed after it: "Not a directory: set -> set"), nothing made."""
    from wirescene.core.atomic import replaced_dir
    from wirescene.core.errors import InputError

    (tmp_path / "disk" / "set").mkdir(parents=True)
    (tmp_path / "links").mkdir()
    (tmp_path / "links" / "set").symlink_to(os.path.join("..", "disk", "set"), target_is_directory=True)
    with replaced_dir(tmp_path / "links" / "set") as staging:
        (staging / "new.txt").write_text("new")
    assert [p.name for p in (tmp_path / "disk" / "set").iterdir()] == ["new.txt"]
    (tmp_path / "links" / "gone").symlink_to(tmp_path / "unmounted" / "set", target_is_directory=True)
    (tmp_path / "links" / "loop").symlink_to("loop")
    before = set(tmp_path.rglob("*"))
    for name, target in (("gone", tmp_path / "unmounted" / "set"), ("loop", "loop")):
        with pytest.raises(InputError, match=f"a symbolic link to {target}, which leads to no folder"):
            with replaced_dir(tmp_path / "links" / name):
                raise AssertionError("the block ran")
    assert set(tmp_path.rglob("*")) == before and (tmp_path / "links" / "gone").is_symlink()


@pytest.mark.skipif(os.name != "posix", reason="file modes and the umask are POSIX's")
def test_written_files_get_the_permissions_of_any_new_file(tmp_path):
    from wirescene.core.atomic import atomic_dir, write_text

    old = os.umask(0o022)
    try:
        write_text(tmp_path / "a.txt", "x")
        with atomic_dir(tmp_path / "report") as staging:
            (staging / "page.html").write_text("x")
        os.umask(0o077)
        write_text(tmp_path / "b.txt", "x")
    finally:
        os.umask(old)
    modes = {p: stat.S_IMODE((tmp_path / p).stat().st_mode) for p in ("a.txt", "report", "report/page.html", "b.txt")}
    assert modes == {"a.txt": 0o644, "report": 0o755, "report/page.html": 0o644, "b.txt": 0o600}


@pytest.mark.parametrize(
    "line, expect",
    [
        ("Car 0.00 0 1.95 354.43 185.52 549.52 294.49 1.43 1.70 3.95 -2.39 1.66 11.80", "line 2: expected 15 columns"),
        (GOOD + " 0.9 7", "got 17"),
        (GOOD.replace("185.52", "abc"), "line 2: column 6 (y1) is not a number: 'abc'"),
        (GOOD.replace(" 0 1.95", " 0.5 1.95"), "line 2: column 3 (occluded) must be an integer"),
        (GOOD.replace("11.80", "nan"), "line 2: column 14 (z) is not finite"),
    ],
)
def test_malformed_lines(tmp_path, line, expect):
    p = tmp_path / "000000.txt"
    p.write_text(GOOD + "\n" + line + "\n")
    with pytest.raises(InputError) as exc:
        read_labels(p)
    msg = one_line(exc)
    assert msg.startswith(f"{p}: ") and expect in msg


def test_missing_label_file(tmp_path):
    with pytest.raises(InputError, match="label file not found") as exc:
        read_labels(tmp_path / "nope.txt")
    assert str(tmp_path / "nope.txt") in one_line(exc)


def test_read_image(kitti_root, tmp_path):
    img = read_image(kitti_root / "training" / "image_2" / "000010.png")
    assert img.shape == (375, 1242, 3) and img.dtype == np.uint8 and img.std() > 10
    data = (kitti_root / "training" / "image_2" / "000010.png").read_bytes()
    truncated = tmp_path / "truncated.png"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="corrupt or truncated image") as exc:
        read_image(truncated)
    assert one_line(exc).startswith(str(truncated))
    text = tmp_path / "text.png"
    text.write_text("hello, I am not an image\n")
    with pytest.raises(InputError, match="not an image file") as exc:
        read_image(text)
    assert one_line(exc).startswith(str(text))
    with pytest.raises(InputError, match="image file not found"):
        read_image(tmp_path / "missing.png")


def test_float_and_32_bit_integer_image_files_are_checked_as_arrays_are(kitti_root, tmp_path):
    """A float TIFF (PIL mode F) of values fitting neither 0..1 nor 0..255 was clipped without a word, a 32-bit
    integer one (mode I) of negative values or values beyond 16 bits likewise: refused as the same array is
    (core.image.range_problem), naming the file. Those that fit are read as the arrays are; mode I within 0..65535
    as the 16-bit image it is (Pillow before 10.3 opens a 16-bit PNG as mode I)."""
    from PIL import Image

    grey = read_image(kitti_root / "training" / "image_2" / "000010.png")[:64, 300:428, 1].copy()  # (64, 128) uint8
    grey[0, :2] = 0, 255  # the whole range

    def tiff(name, values):
        Image.fromarray(values).save(tmp_path / f"{name}.tif")
        return tmp_path / f"{name}.tif"

    unit = grey.astype(np.float32) / 255
    for name, values in (("unit", unit), ("levels", grey.astype(np.float32)), ("overshoot", unit * np.float32(1.001)),
                         ("int16bit", grey.astype(np.int32) * 257)):
        assert (read_image(tiff(name, values))[..., 0] == grey).all(), name
    sixteen = Image.fromarray(grey.astype(np.uint16) * 257)  # I;16, as Pillow 10.3 and later open a 16-bit PNG
    assert (read_image(tiff("int16bit_old", np.asarray(sixteen.convert("I")))) == read_image(tiff("u16", np.asarray(
        sixteen)))).all()
    for name, values, says in (
            ("normalised", unit * 403 - 3, r"float values outside both 0\.\.1 and 0\.\.255 \(dtype float32, -3\.\.400\) "
                                           r"would be clipped: scale to 0\.\.1 or 0\.\.255"),
            ("negative", grey.astype(np.int32) - 1, r"integer values outside 0\.\.65535 \(mode I, -1\.\.254\) "
                                                    r"would be clipped: scale to 0\.\.65535"),
            ("wide", grey.astype(np.int32) * 65793, r"integer values outside 0\.\.65535 \(mode I, 0\.\.16777215\) "
                                                    r"would be clipped: scale to 0\.\.65535"),
            ("nan", np.where(unit > 0.5, np.nan, unit).astype(np.float32), r"image has non-finite values \(\d+ NaN")):
        path = tiff(name, values)
        with pytest.raises(InputError, match=f"^{re.escape(str(path))}: {says}") as exc:
            read_image(path)
        one_line(exc)


def test_a_32_bit_integer_image_file_is_refused_naming_the_range_it_is_read_by(tmp_path):
    """A mode I file is read by 0..65535 (as a 16-bit image), not by an int32 array's 0..255: its refusal said
    "outside 0..255 ... scale others to 0..255", and a file so scaled read black. It names 0..65535, and a file
    scaled so reads."""
    from PIL import Image

    levels = np.tile(np.arange(0, 256, 5, dtype=np.int32), (16, 1))  # (16, 52), 0..255
    path = tmp_path / "wide.tif"
    Image.fromarray(levels * 65793).save(path)  # 0..16777215: 24 bits
    with pytest.raises(InputError, match=r"integer values outside 0\.\.65535 \(mode I, 0\.\.16777215\) would be "
                                         r"clipped: scale to 0\.\.65535") as exc:
        read_image(path)
    one_line(exc)
    Image.fromarray(levels * 257).save(path)  # as the message says: the levels read back
    assert (read_image(path)[..., 0] == levels).all()

def test_dataset_from_root_and_split_dir(kitti_root):
    for root in (kitti_root, kitti_root / "training"):
        ds = KittiDataset(root)
        assert ds.has_labels
        assert ds.frame_ids() == ["000002", "000010", "001545"]
        assert ds.image_path(10) == kitti_root / "training" / "image_2" / "000010.png"
        assert len(ds.labels("000010").objects) == 9
    cam = ds.camera("000010")
    assert cam.image_size == (1242, 375)
    P2 = ds.calib("000010").P2
    assert P2.shape == (3, 4)
    assert_close(P2[0], [7.215377e02, 0.0, 6.095593e02, 4.485728e01])
    assert_close(cam.P, P2)
    assert ds.image("000002").shape[:2] == (375, 1242)
    assert ds.car_counts(["000002", "000010", "001545"]) == {"000002": 1, "000010": 8, "001545": 6}
    assert ds.car_counts([10]) == {10: 8}  # keyed as given


def test_an_int_frame_id_is_written_06d_and_a_bool_or_a_negative_one_refused(kitti_root):
    """KittiDataset writes an int id %06d (10 is 000010); a bool (True was frame 000001), a negative int (-10 was
    frame -00010) or a float is no frame id: an ArgumentError naming frame_id."""
    from wirescene.core.errors import ArgumentError

    ds = KittiDataset(kitti_root)
    assert ds.image_path(10) == ds.image_path(np.int64(10)) == ds.image_path("000010")
    for bad, says in ((True, "got bool True"), (-10, "must be non-negative, got -10"), (10.0, "got float 10.0")):
        for read in (ds.image_path, ds.label_path, ds.calib_path):
            with pytest.raises(ArgumentError, match=f"^frame_id: .*{says}"):
                read(bad)


def test_frame_ids_are_read_from_any_iterable_or_one_id():
    """as_frame_ids, the API's reading of ``frames``: a numpy array of str or of ints, a generator or a tuple give
    their ids in order, once each; one id alone (a numpy scalar, or a 0-d array: iterating that was a TypeError)
    is one frame, not its characters; what is no id is an ArgumentError naming frames."""
    from wirescene.core.errors import ArgumentError
    from wirescene.io.kitti import as_frame_ids

    for frames in (np.array(["000010", "000002"]), np.array([10, 2]), (f for f in ("000010", 2, 10)),
                   ("000010", "000002")):
        assert as_frame_ids(frames) == ["000010", "000002"], frames
    for one in ("000010", 10, np.int64(10), np.str_("000010"), np.array(10), np.array("000010")):
        assert as_frame_ids(one) == ["000010"], repr(one)
    # a set's own order changes from one process to the next (str hashing): sorted, as the reports list them

    class Descending(set):  # a set whose order is certain not to be the sorted one
        def __iter__(self):
            return iter(sorted(set.__iter__(self), key=str, reverse=True))

    for frames in (Descending({"000010", "000002", 1545}), frozenset({"001545", "000010", "000002"})):
        assert as_frame_ids(frames) == sorted(as_frame_ids(list(frames))), frames
    for bad in (b"000010", [None], [np.array([10, 2])], 10.0):
        with pytest.raises(ArgumentError, match="^frames: expected a frame id"):
            as_frame_ids(bad)
    assert as_frame_ids([]) == []  # the caller's to allow (an evaluation of no frame), or refuse:
    with pytest.raises(ArgumentError, match="^frames: no frame given$"):
        as_frame_ids(iter([]), some=True)


def test_dataset_without_labels_and_bad_roots(kitti_root, tmp_path):
    split = kitti_copy(tmp_path, ["000002", "000010", "001545"], subdirs=("image_2", "calib"), split="testing") / "testing"
    ds = KittiDataset(tmp_path, split="testing")
    assert not ds.has_labels and ds.frame_ids() == ["000002", "000010", "001545"]
    with pytest.raises(InputError, match="no label_2"):
        ds.labels("000002")
    with pytest.raises(InputError, match="not found"):
        KittiDataset(tmp_path / "nothing")
    with pytest.raises(InputError, match="not a KITTI object directory") as exc:
        KittiDataset(tmp_path)  # no training/ here
    assert one_line(exc).startswith(str(tmp_path))
    # the other split's folder named (predict's default split, testing, of a root of training frames alone)
    assert one_line(exc).endswith("; it holds testing/image_2: --split testing")
    shutil.rmtree(split / "calib")
    with pytest.raises(InputError, match="no calib/ directory"):
        KittiDataset(split)


def test_alpha_minus_ten_is_an_unknown_viewpoint(tmp_path):
    """KITTI's alpha -10 ("not estimated", as a 2D-only detector writes it) is no viewpoint,
    in a KITTI detection file, in JSON and in CSV, with or without viewpoint noise."""
    from wirescene.core.viewpoints import bin_center, viewpoint_bin
    from wirescene.io.detections import detections_from_labels, read_detections

    txt = tmp_path / "000010.txt"
    txt.write_text(GOOD.replace(" 1.95 ", " -10 ") + " 0.9\n" + GOOD + " 0.8\n"
                   + GOOD.replace(" 1.95 ", " -10.00 ") + " 0.7\n")
    dets = read_detections(txt)
    assert np.isnan(dets.alpha[[0, 2]]).all() and dets.alpha[1] == pytest.approx(bin_center(viewpoint_bin(1.95)))
    noisy = detections_from_labels(read_labels(txt), viewpoint_noise_deg=30, rng=np.random.default_rng(1))
    assert np.isnan(noisy.alpha[[0, 2]]).all() and np.isfinite(noisy.alpha[1])
    js = tmp_path / "d.json"
    js.write_text('[{"box": [300, 180, 520, 300], "alpha": -10}, {"box": [600, 170, 680, 230], "alpha": -3.0}]')
    csv = tmp_path / "d.csv"
    csv.write_text("x1,y1,x2,y2,alpha\n300,180,520,300,-10\n600,170,680,230,-3.0\n")
    for path in (js, csv):
        alpha = read_detections(path).alpha
        assert np.isnan(alpha[0]) and alpha[1] == pytest.approx(bin_center(viewpoint_bin(-3.0))), path.name


def test_wireframe_ground_truth_that_cannot_be_read_is_an_input_error(tmp_path):
    from wirescene.io.wireframes import read_wireframe_gt

    folder = tmp_path / "000003.json"
    folder.mkdir()  # a directory where the file should be
    with pytest.raises(InputError, match="cannot read the wireframe ground truth") as info:
        read_wireframe_gt(folder)
    assert str(folder) in str(info.value)


def test_a_score_floor_keeps_the_boxes_at_or_above_it_and_checks_every_box_first(tmp_path):
    """read_detections(min_score=): boxes scoring the floor or more stay, a box without a score scores 1, none
    left is NO_CARS; a box outside the image is refused even where the floor would drop it (a file of another
    image), and named by its place in the file."""
    import json

    from wirescene.io.detections import NO_CARS, read_detections

    path = tmp_path / "dets.json"
    path.write_text(json.dumps([{"box": [10, 10, 50, 40], "score": 0.2}, {"box": [60, 10, 90, 40], "score": 0.5},
                                {"box": [100, 10, 140, 40]}]))
    assert read_detections(path, min_score=0.5).scores.tolist() == [0.5, 1.0]
    with pytest.raises(InputError, match=NO_CARS):
        read_detections(path, min_score=1.5)
    path.write_text(json.dumps([{"box": [10, 10, 50, 40], "score": 0.9}, {"box": [5000, 10, 5100, 40], "score": 0.1}]))
    with pytest.raises(InputError, match="box 1 lies entirely outside the 1242x375 image"):
        read_detections(path, min_score=0.5, image_size=(1242, 375))
