"""CLI pieces: ``wirescene train detector``, ``train viewpoints`` and ``wirescene detect``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from wirescene.cli.options import (
    KITTI_ROOT_FORMS,
    NON_NEGATIVE,
    NON_NEGATIVE_FLOAT,
    POSITIVE_FLOAT,
    FiniteFloat,
    NonEmptyPath,
    calib_option,
    check_output_dir,
    check_output_file,
    check_picture_file,
    drive_map_option,
    field_type,
    keeps_on_resume,
    kitti_dataset,
    kitti_root_params,
    models_option,
    read_drive_map,
    refuse_given,
    say_models,
    say_off_centre_frames,
    select_frames,
    split_file_option,
    split_option,
    workers_count,
    workers_option,
)
from wirescene.core.artefacts import format_tag
from wirescene.core.atomic import atomic_dir, write_text
from wirescene.core.errors import InputError
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, Mount
from wirescene.core.jsonio import dumps, write_json
from wirescene.core.settings import stage_field
from wirescene.core.version import __version__
from wirescene.fitting.options import PredetectOptions
from wirescene.lift import LiftingOptions
from wirescene.predetect.bank import SUPPORT_WEIGHT
from wirescene.training.scale import (
    DEFAULT_CACHE_MB,
    DEFAULT_MAX_NEGATIVES,
    MAX_CACHE_MB,
    MAX_CUT_PASTE,
    MAX_DETECTOR_SCENES,
    MAX_MINING_IMAGES,
    MAX_MINING_ROUNDS,
    MAX_NEGATIVES,
    MAX_PARTIAL,
    MAX_PER_OCTAVE,
    MAX_VAL_SCENES,
    single_thread,
)


@click.command("detector")
@click.option("--out", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="Detector bank .npz to write (the shipped one is src/wirescene/data/detector_bank.npz).")
@kitti_root_params("Train on the labelled real frames of this KITTI root (the shipped bank: all 72 frames of "
                   "shared/data/kitti). Without it: synthetic scenes.",
                   type=NonEmptyPath(file_okay=False, path_type=Path))
@click.option("--frames", default=None, help="With a KITTI root: comma-separated training frame ids (default all).")
@split_file_option
@click.option("--folds", default=None,
              help="With a KITTI root: train only on the frames of these cross-validation folds (e.g. 0,1,3).")
@click.option("--no-calibration", is_flag=True,
              help="With a KITTI root: skip the held-out (leave-one-fold-out) Platt calibration; scores stay margins.")
@click.option("--calibration", default=None,
              help="With a KITTI root: Platt 'a,b,c' mapping margins and the verifier's logits to confidences, from "
                   "held-out detections of the same recipe (printed by benchmarks/bench_predetect.py); default: "
                   "leave-one-fold-out training.")
@click.option("--threshold", type=FiniteFloat(min=0.0, max=1.0), default=0.5, show_default=True,
              help="With a KITTI root and a calibration: default detection threshold (confidence, 0 to 1).")
@drive_map_option()
@click.option("--support-weight", type=NON_NEGATIVE_FLOAT, default=SUPPORT_WEIGHT, show_default=True,
              help="With a KITTI root: margin a cluster of detections gains per e-fold of its votes (0: its best vote "
                   "alone).")
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True, help="Random stream (synthetic: scenes; validation: seed+1).")
@click.option("--scenes", "n_scenes", type=click.IntRange(min=1, max=MAX_DETECTOR_SCENES), default=200, show_default=True,
              help=f"Synthetic training scenes (at most {MAX_DETECTOR_SCENES:,}: some 0.6 s and 4 MB each).")
@click.option("--partial", "n_partial", type=click.IntRange(min=0, max=MAX_PARTIAL), default=3, show_default=True,
              help=f"Partial configurations per viewpoint (plus one full-car configuration; at most {MAX_PARTIAL}, "
                   "as many as the cars' visible vertex sets allow: some 7).")
@click.option("--per-octave", type=click.IntRange(min=1, max=MAX_PER_OCTAVE), default=6, show_default=True,
              help="With a KITTI root: HOG pyramid levels per octave (stored with the bank for detection, whose "
                   "time, like the training's, grows in proportion).")
@click.option("--cut-paste", type=click.IntRange(min=0, max=MAX_CUT_PASTE), default=0, show_default=True,
              help="With a KITTI root: cars of other frames pasted into a composite copy of every training frame.")
@click.option("--mining-rounds", type=click.IntRange(min=0, max=MAX_MINING_ROUNDS), default=None,
              help="Hard-negative mining rounds [synthetic 2, real 3], each describing every mined image again.")
@click.option("--mining-images", type=click.IntRange(min=1, max=MAX_MINING_IMAGES), default=None,
              help=f"The most training images a hard-negative mining round searches [synthetic 80, real: all; at most "
                   f"{MAX_MINING_IMAGES:,}].")
@click.option("--val-scenes", "n_val", type=click.IntRange(min=0, max=MAX_VAL_SCENES), default=20, show_default=True,
              help="Synthetic only: held-out scenes of the threshold.")
@click.option("--C", "C", type=POSITIVE_FLOAT, default=0.01, show_default=True, help="Linear SVM regularisation.")
@click.option("--report", type=NonEmptyPath(dir_okay=False), default=None, help="Write a JSON report here.")
@click.option("--max-negatives", type=click.IntRange(min=1, max=MAX_NEGATIVES), default=DEFAULT_MAX_NEGATIVES,
              show_default=True,
              help=f"With a KITTI root: cap of each configuration's negatives (reservoir, then the hardest; at most "
                   f"{MAX_NEGATIVES:,}: some 4.8 kB each).")
@click.option("--pyramid-cache-mb", type=FiniteFloat(min=0, max=MAX_CACHE_MB), default=DEFAULT_CACHE_MB,
              show_default=True,
              help=f"With a KITTI root: memory for cached grey images and HOG pyramids (beyond it they are recomputed; "
                   f"at most {MAX_CACHE_MB:,}, the step needing some 6 GB besides).")
@workers_option("of the per-image passes (mining, detections; with a KITTI root only)")
def detector(out, kitti_root, frames, split_file, folds, no_calibration, calibration, threshold, drive_mapping,
             support_weight, seed, n_scenes, n_partial, per_octave, cut_paste, mining_rounds, mining_images, n_val, C,
             report, max_negatives, pyramid_cache_mb, workers):
    """Train the part-configuration detector bank (real KITTI frames or synthetic scenes)."""
    check_output_file(out, "--out")
    check_output_file(report, "--report")
    if drive_mapping is not None and (no_calibration or calibration is not None):
        raise click.UsageError("--drive-map groups the held-out calibration's folds: not with --no-calibration or "
                               "--calibration")
    if no_calibration and threshold != 0.5:  # an uncalibrated bank keeps its margins' threshold, 0
        raise click.UsageError("--threshold is a calibrated bank's (a confidence): not with --no-calibration")
    # each option given for the other kind of training is refused, not ignored
    other = ({"--scenes": n_scenes != 200, "--val-scenes": n_val != 20} if kitti_root is not None else
             {"--frames": frames, "--split-file": split_file, "--folds": folds, "--no-calibration": no_calibration,
              "--calibration": calibration is not None, "--threshold": threshold != 0.5,
              "--drive-map": drive_mapping, "--support-weight": support_weight != SUPPORT_WEIGHT,
              "--per-octave": per_octave != 6, "--cut-paste": cut_paste, "--max-negatives":
              max_negatives != DEFAULT_MAX_NEGATIVES, "--pyramid-cache-mb": pyramid_cache_mb != DEFAULT_CACHE_MB,
              "--workers": workers is not None})
    if kitti_root is not None:
        refuse_given(other, why="synthetic training only, not with a KITTI root")
    else:
        refuse_given(other, needs=KITTI_ROOT_FORMS)
    if kitti_root is not None:
        from wirescene.io.kitti import KittiDataset
        from wirescene.training.kitti_detector import check_calibration, frames_in_folds, train_detector_bank_kitti

        try:
            given = None if calibration is None else check_calibration(calibration.split(","), size=3)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--calibration") from None
        ds = KittiDataset(kitti_root)
        ds.require_labels("training")  # before any frame is chosen or image decoded
        ids = select_frames(frames, split_file, ds.require_frames(), where=ds.split_dir)
        fl = _fold_list(folds)
        ids = ds.frame_ids() if ids is None else ids
        if fl is not None:  # narrowed here, so that the warning below is of the frames trained on
            ids = frames_in_folds(ids, fl)
        say_off_centre_frames(ds, ids, images=True)  # a truncated image refused before the training reads it
        drives = read_drive_map(ds, drive_mapping)[0] if not no_calibration and given is None else None
        _, rep = train_detector_bank_kitti(out, kitti_root, frames=ids, seed=seed, C=C,
                                           n_partial=n_partial, calibration_folds=not no_calibration,
                                           calibration=given, threshold=threshold, support_weight=support_weight,
                                           mining_rounds=3 if mining_rounds is None else mining_rounds,
                                           per_octave=per_octave, cut_paste=cut_paste, max_negatives=max_negatives,
                                           mining_images=mining_images, pyramid_cache_mb=pyramid_cache_mb,
                                           workers=workers_count(workers),
                                           drives=drives, progress=click.echo)
    else:
        from wirescene.training.detector import train_detector_bank

        _, rep = train_detector_bank(out, seed=seed, n_scenes=n_scenes, n_partial=n_partial, C=C,
                                     mining_rounds=2 if mining_rounds is None else mining_rounds,
                                     mining_images=80 if mining_images is None else mining_images, n_val=n_val,
                                     progress=click.echo)
    if report:
        write_json(report, rep)


def _fold_list(text: str | None) -> list[int] | None:
    """``--folds`` ("0,1,3") as fold numbers, each one of the N_FOLDS folds."""
    from wirescene.io.folds import N_FOLDS

    if not text:
        return None
    try:
        folds = sorted({int(k) for k in text.split(",") if k.strip()})
    except ValueError:
        raise click.BadParameter(f"{text!r} is not a comma-separated list of fold numbers", param_hint="--folds") from None
    if not folds or not set(folds) <= set(range(N_FOLDS)):
        raise click.BadParameter(f"{text!r}: the folds are 0 to {N_FOLDS - 1}", param_hint="--folds")
    return folds


@click.command("viewpoints")
@kitti_root_params("Labelled KITTI root whose Car labels are cropped.",
                   type=NonEmptyPath(file_okay=False, exists=True, path_type=Path), required=True)
@click.option("--out", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="Classifier to write (the shipped one is src/wirescene/data/viewpoint_classifier.npz).")
@click.option("--frames", default=None, help="Comma-separated training frame ids (default: all).")
@split_file_option
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True, help="Random stream of the jittered copies.")
def viewpoints(kitti_root, out, frames, split_file, seed):
    """Train the crop viewpoint classifier that gives boxes of other detectors a viewpoint."""
    from wirescene.io.kitti import KittiDataset
    from wirescene.predetect.viewpoint_classifier import train_on_kitti

    check_output_file(out, "--out")
    ds = KittiDataset(kitti_root)
    ds.require_labels("training")  # before any frame is chosen or image decoded
    ids = select_frames(frames, split_file, ds.require_frames(), where=ds.split_dir) or ds.frame_ids()
    say_off_centre_frames(ds, ids, images=True)  # as the other train commands: a truncated image refused now
    clf = train_on_kitti(ds, ids, seed=seed)
    clf.save(out)
    click.echo(f"viewpoint classifier: {clf.meta['n']} crops of {len(ids)} frames -> {out}")


@click.command("detect")
@click.argument("kitti_root", type=NonEmptyPath(directory=True, path_type=Path))
@click.option("--frames", default=None, help="Comma-separated frame ids (default: all).")
@split_file_option
@split_option()
@calib_option
@models_option
@click.option("--bank", "bank_path", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="Detector bank .npz (default: --models' or the shipped one).")
@click.option("--viewpoint-classifier", "classifier_path", type=NonEmptyPath(dir_okay=False, path_type=Path),
              default=None, help="Crop viewpoint classifier .npz of the viewpoints --out writes (default: --models' "
                                 "or the shipped one).")
@click.option("--threshold", type=FiniteFloat(), default=None,
              help="Score threshold (default: the bank's, 0.5 for the shipped one; the fit's own pre-detection keeps "
                   "the boxes above 0.3, and --out writes the fit's viewpoints at any threshold).")
@click.option("--out", "out_dir", type=NonEmptyPath(file_okay=False, path_type=Path), default=None,
              help="Write FRAME.json detection files here (readable by --detections of `eval`), each as its frame is "
                   "done, and the run's settings (.detect.json): an empty (or new) directory, or --resume.")
@click.option("--resume/--no-resume", default=False, show_default=True,
              help="Continue an interrupted run in --out (same settings): detect only the frames without a file. "
                   "Its frames must be among those chosen now; the AP is of the frames detected in this run.")
@click.option("--pr-curve", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="PR curve picture, in the format its suffix names (.png, .pdf, .svg; PNG without a suffix).")
@click.option("--json", "json_out", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="Write AP and timing as JSON.")
@click.option("--camera-height", type=field_type(stage_field(LiftingOptions, "camera_height")), default=KITTI_CAMERA_HEIGHT, show_default=True,
              help="The camera's height above the road (m), for the ground and traffic priors learned at KITTI's "
                   "(the fit's --set lifting.camera_height).")
@click.option("--camera-pitch", type=field_type(stage_field(LiftingOptions, "camera_pitch")), default=0.0, show_default=True,
              help="Degrees the camera looks down from the road, which raises the horizon those priors read "
                   "(the fit's --set lifting.camera_pitch).")
@click.option("--estimate-pitch", is_flag=True, default=False,
              help="Read each frame's camera pitch off the boxes found without those priors, about --camera-pitch "
                   "(a camera whose tilt is not known; 1.3x the detection's time; the fit's --estimate-pitch).")
@click.option("--smallest-car", type=field_type(stage_field(PredetectOptions, "smallest_car")), default=0.0,
              show_default=True, help="Smallest car height searched (px; 0: the bank's own, 25 px, and --upsample's "
                                      "enlarged image below it), the image upsampled to reach it; at 25 or more no "
                                      "smaller car is searched in either image (the fit's --smallest-car).")
@click.option("--upsample", type=field_type(stage_field(PredetectOptions, "upsample")),
              default=PredetectOptions().upsample, show_default=True,
              help="Also detect on the image enlarged by this factor, 1 to 3 (Lanczos), at its pyramid levels finer "
                   "than the image's, adding the cars it finds above the fit's threshold 0.3 that the image's boxes "
                   "above it miss: small, far cars (1: the image alone, 2.3x faster; the fit's --upsample).")
def detect(kitti_root, frames, split_file, split, calib, models, bank_path, classifier_path, threshold, out_dir,
           resume, pr_curve, json_out, camera_height, camera_pitch, estimate_pitch, smallest_car, upsample):
    """Run the configuration detector bank on a KITTI-layout directory and report AP.

    The files of --out hold the detections above the threshold with the viewpoints the
    pipeline gives them (the box rule of `fit`); AP and AOS score the bank's own (with
    --upsample, the image's and those the enlarged image adds, each with its bank viewpoint).
    Each frame's file is written as the frame is done: an interrupted run goes on with --resume."""
    import numpy as np

    from wirescene.core.resources import resolve_models
    from wirescene.core.viewpoints import viewpoint_bin
    from wirescene.eval.kitti_metrics import detection_ap_2d
    from wirescene.fitting.models import detector_bank, viewpoint_classifier
    from wirescene.fitting.own_boxes import own_detections
    from wirescene.predetect.ap import evaluate_detections, load_frame_gt, plot_pr, summary

    check_output_dir(out_dir, "--out")
    check_picture_file(pr_curve, "--pr-curve")
    check_output_file(json_out, "--json")
    if classifier_path is not None and out_dir is None:  # refused, not ignored
        raise click.UsageError("--viewpoint-classifier gives the boxes --out writes their viewpoints: it needs --out")
    if resume and out_dir is None:
        raise click.UsageError("--resume continues the files of --out: it needs --out")
    if out_dir is not None:
        keeps_on_resume("the frames --out holds")  # a full disk at frame N: frames 1..N-1 stay
    ds = kitti_dataset(kitti_root, split, calib)
    if pr_curve is not None and not ds.has_labels:  # refused, not left undrawn
        raise click.UsageError(f"--pr-curve draws the AP's precision and recall against the labels: {ds.split_dir} "
                               "has no label_2/")
    found = resolve_models(models)
    bank = detector_bank(found.file("detector_bank", given=bank_path))
    # the viewpoints of the boxes --out writes, read before any frame: a bad file is refused
    classifier = None if out_dir is None else viewpoint_classifier(found.file("viewpoint_classifier",
                                                                              given=classifier_path))
    # once its files are read (a broken one: the error line alone)
    say_models(found, replaced=[name for name, given in (("detector_bank", bank_path),
                                                         ("viewpoint_classifier", classifier_path)) if given])
    ids = select_frames(frames, split_file, ds.require_frames(), where=ds.split_dir, what="frame") or ds.frame_ids()
    thr = bank.threshold if threshold is None else threshold
    record, config, kept = None, None, set()
    if out_dir is not None:  # before the first frame's detection
        config = _detect_config(ds, found, bank_path, classifier_path, threshold=float(thr), smallest_car=smallest_car,
                                upsample=upsample, camera_height=camera_height, camera_pitch=camera_pitch,
                                estimate_pitch=estimate_pitch)
        record, kept = _resumable_out(out_dir, config, ids, resume=resume)
    todo = [f for f in ids if f not in kept]
    # a missing calibration or corrupt image (12 ms each) refused before the first frame, not with frames written
    say_off_centre_frames(ds, todo, images=True, before="the first frame's detection")
    if kept:  # the AP needs every score of a frame; a kept file holds the boxes above the threshold alone
        # every frame kept: no AP (nor --pr-curve) said, not left out unnoticed
        scored = f"the AP is of the {len(todo)} detected now" if todo else "no AP, none detected now"
        ap = f"; {scored} (a kept file holds no score under the threshold)" if ds.has_labels else ""
        click.echo(f"resuming {out_dir}: {len(kept)} of {len(ids)} frames kept from an earlier run, {len(todo)} to "
                   f"detect{ap}")
    told = Mount(camera_height, camera_pitch)
    dets_all, gts, times = [], [], []
    with single_thread():
        for k, fid in enumerate(todo):
            # every score of the image's own and added detections for AP; --out's boxes with the fit's viewpoints
            d, above = own_detections(ds.camera(fid), ds.image(fid), bank=bank, classifier=classifier,
                                      threshold=threshold, fit_viewpoints=True, return_all=True,
                                      viewpoints=out_dir is not None, upsample=upsample, smallest_car=smallest_car,
                                      mount=told, estimate_pitch=estimate_pitch, source=fid, seconds=times)
            if out_dir is not None:
                entries = [{"box": [round(float(v), 2) for v in b], "score": round(float(s), 4),
                            "viewpoint_bin": int(viewpoint_bin(a))} for b, s, a in zip(above.boxes, above.scores,
                                                                                       above.alpha)]
                if k == 0:  # the settings' record with the first frame's file: a run failing before leaves nothing
                    write_text(record, json.dumps(config, indent=1))
                write_text(out_dir / f"{fid}.json", dumps({"detections": entries}))  # whole or not at all
            dets_all.append(d)
            if ds.has_labels:
                gts.append((load_frame_gt(ds.split_dir, fid), ds.labels(fid)))
            click.echo(f"{fid}: {len(above)} detections above {thr:.3f} ({times[-1]:.2f}s)")
    result = {"frames": len(todo), "threshold": thr, "seconds_per_frame": float(np.mean(times)) if times else 0.0}
    if resume:  # "frames": those detected and scored now
        result["frames_kept"] = len(kept)
    if gts:
        res = evaluate_detections(dets_all, [g[0] for g in gts])
        kept_res = evaluate_detections([d.subset(d.scores > thr) for d in dets_all], [g[0] for g in gts])
        kit = detection_ap_2d(dets_all, [g[1] for g in gts])
        result.update(ap=summary(res), at_threshold={"recall": kept_res["max_recall"],
                                                     "precision": float(kept_res["precision"][-1]) if len(kept_res["precision"]) else float("nan")},
                      kitti_2d_ap={d: {"ap": kit["2d"][d], "n_gt": kit["n_gt"][d]} for d in kit["2d"]})
        click.echo("KITTI 2D AP (Car, IoU 0.7, R40, devkit rules): " + ", ".join(
            f"{d} {'-' if ap is None else f'{ap:.1f}'} ({kit['n_gt'][d]} cars)" for d, ap in kit["2d"].items()))
        click.echo(f"AP {100 * res['ap']:.1f}% over {res['n_gt']} cars (IoU 0.5, >50 px, >=20% visible); "
                   f"max recall {res['max_recall']:.2f}; viewpoint bin accuracy of TPs {res['viewpoint_bin_acc']:.2f}, "
                   f"within 45 deg {res['viewpoint_within_45']:.2f}")
        if pr_curve is not None:
            plot_pr({"detector bank": res}, pr_curve,  # the AP printed above, not KITTI's: the title says which
                    title="Car pre-detection: IoU 0.5, cars over 50 px,\nat least 20% visible (not KITTI's AP)")
    if times:  # a resumed run with every frame kept timed none
        click.echo(f"{result['seconds_per_frame']:.2f} s per frame")
    if json_out is not None:
        write_json(json_out, result)


#: Where ``detect --out`` keeps its run's settings, beside the frames' files (hidden: no frame's file).
DETECT_RECORD = ".detect.json"
#: The settings of :data:`DETECT_RECORD` a refusal names by their options.
_SAID = {name: "--" + name.replace("_", "-") for name in ("threshold", "smallest_car", "upsample", "camera_height",
                                                         "camera_pitch", "estimate_pitch")}


def _held_detections(out_dir: Path | None) -> list[Path]:
    """The detection files (``FRAME.json``, ``.csv``, ``.txt``) ``out_dir`` holds, by name; a
    hidden file (a settings' record) is no frame's."""
    from wirescene.eval.sources import DETECTION_SUFFIXES

    return sorted(p for p in (out_dir.iterdir() if out_dir is not None and out_dir.is_dir() else ())
                  if p.suffix.lower() in DETECTION_SUFFIXES and not p.name.startswith("."))


def _refuse_held_detections(out_dir: Path | None, *, whose: str = "",
                            advice: str = "choose an empty directory") -> None:
    """A usage error of ``--out`` where ``out_dir`` already holds detection files: an earlier
    run's frames would stay beside this run's, to be read by ``--detections`` as one run's;
    ``whose`` (" of a run ...") and ``advice`` complete the message."""
    held = _held_detections(out_dir)
    if held:
        raise click.BadParameter(f"{out_dir} already holds {len(held)} detection file{'s' * (len(held) != 1)} "
                                 f"(e.g. {held[0].name}){whose}: {advice}", param_hint="--out")


def _detect_config(ds, found, bank_path, classifier_path, **settings) -> dict:
    """What decides the boxes of ``detect --out``'s files, as its settings' record holds them:
    the package version, the split (and its one calibration), the detector bank's and crop
    classifier's content (as ``predict`` records them) and ``settings`` (the threshold, the
    search's and the camera's), normalised through JSON to compare equal to a stored one."""
    from wirescene.fitting.models import models_fingerprint
    from wirescene.fitting.options import FitOptions

    files = FitOptions(detector_bank=found.file("detector_bank", given=bank_path),
                       viewpoint_classifier=found.file("viewpoint_classifier", given=classifier_path))
    config = {"format": format_tag("detect-config", 1), "wirescene": __version__, **ds.record(),
              "models": models_fingerprint(files, read=("detector_bank", "viewpoint_classifier")), **settings}
    return json.loads(json.dumps(config, default=str))


def _resumable_out(out_dir: Path, config: dict, ids: list[str], *, resume: bool) -> tuple[Path, set[str]]:
    """``(settings' record, frames kept)`` of ``detect --out out_dir``, refused before any frame:
    without ``resume``, a folder holding detection files (the advice to resume where its record is
    of ``config``); resumed, one holding files of other settings (:data:`DETECT_RECORD` names
    them), of frames outside ``ids``, or no ``FRAME.json`` (another tool's, which ``--detections``
    would read as this run's)."""
    from wirescene.eval.records import resumed_settings, settings_changed, settings_record, stored_config

    record = settings_record(out_dir, DETECT_RECORD, command="detect")
    held = _held_detections(out_dir)
    would = "which --detections would read as this run's"
    if not resume:
        if held:
            try:
                stored = stored_config(record)
            except InputError:  # unreadable: no run to continue, the folder refused all the same
                stored = None
            if stored is None:  # another tool's files, or a run's record lost: nothing to continue
                _refuse_held_detections(out_dir)
            changed = settings_changed(stored, config, record=DETECT_RECORD, said=_SAID)
            if changed is None:
                _refuse_held_detections(out_dir, whose=" of a run of these settings",
                                        advice="use --resume to continue it, or choose an empty directory")
            _refuse_held_detections(out_dir, whose=f" of a run with other settings ({changed})")
        return record, set()
    foreign = [p.name for p in held if p.suffix != ".json"]
    if foreign:
        raise InputError(f"holds detection files detect does not write (e.g. {foreign[0]}), {would}: choose an empty "
                         "directory", path=out_dir)
    resumed_settings(out_dir, held, config, record, ids, what="detection files", would=would, said=_SAID)
    return record, {p.stem for p in held}


@click.command("split-coco")
@click.argument("results", type=NonEmptyPath(dir_okay=False, path_type=Path))
@click.option("--images", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="The COCO annotation file the detector ran on: its images' id and file_name, whose stem is the "
                   "frame id (training/image_2/000010.png: 000010).")
@click.option("--out", "out_dir", type=NonEmptyPath(file_okay=False, path_type=Path), required=True,
              help="An empty (or new) directory for the FRAME.json files.")
def split_coco(results, images, out_dir):
    """Split a COCO result file of a whole data set (mmdetection's or detectron2's bbox results: one list, each box
    naming its image_id) into one FRAME.json a frame, for --detections DIR of eval, predict and fit. Every image of
    --images gets its file (an image without a box: [], a frame without cars); the entries are kept as they are
    (their class, score and any alpha; a category_id alone also gets its name from the categories of --images, where
    they list it: a detector trained on KITTI numbers its cars 1), checked as --detections reads them."""
    from wirescene.io.detections import is_car, split_coco_results

    check_output_dir(out_dir, "--out")
    _refuse_held_detections(out_dir)
    by_frame = split_coco_results(results, images)  # every entry checked before any file is written
    # one set or not at all (a full disk); a detect run's record, left where its files were removed, goes: it would
    # vouch for these files as that run's to its --resume
    with atomic_dir(out_dir, stale=(DETECT_RECORD,)) as staging:
        for frame, entries in by_frame.items():
            # compact: no reader needs the indent, which made the files 3x slower to write (json's Python encoder)
            (staging / f"{frame}.json").write_text(dumps(entries, indent=None))
    boxes = sum(len(entries) for entries in by_frame.values())
    # the cars said: a detector numbering its classes otherwise (KITTI's Car 1, Cyclist 3) shows here, not in a run
    cars = sum(is_car(entry) for entries in by_frame.values() for entry in entries)
    empty = sum(not entries for entries in by_frame.values())
    click.echo(f"{boxes} detection{'s' * (boxes != 1)} ({cars} car{'s' * (cars != 1)}: 'car' or COCO's category_id 3) "
               f"of {len(by_frame)} frame{'s' * (len(by_frame) != 1)} written to {out_dir} ({empty} "
               f"frame{'s' * (empty != 1)} without one)")
