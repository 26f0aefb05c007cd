"""``wirescene train parts``: train the part detector (see :mod:`wirescene.training.parts`)."""

from __future__ import annotations

from pathlib import Path

import click

from wirescene.cli.options import (
    KITTI_ROOT_FORMS,
    NON_NEGATIVE,
    FiniteFloat,
    NonEmptyPath,
    check_output_dir,
    check_output_file,
    drive_map_option,
    kitti_root_params,
    read_drive_map,
    refuse_given,
    say_off_centre_frames,
    select_frames,
    split_file_option,
)
from wirescene.parts import MAX_SMOOTH
from wirescene.training.recipe import RECIPE
from wirescene.training.scale import MAX_AUG, MAX_DEPTH, MAX_PART_SCENES, MAX_TREES, MAX_VIEWS

#: The shipped model's options are this command's defaults (``train all`` trains the same).
_RECIPE = RECIPE["parts"]


@click.command("parts")
@click.option("--out", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="Model .npz to write (the shipped one is src/wirescene/data/parts_model.npz).")
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True,
              help="Random stream of the patches' sampling and augmentation and of the forest.")
@click.option("--n-views", type=click.IntRange(min=0, max=MAX_VIEWS), default=0, show_default=True,
              help="CAD edge renderings: views per car (2 elevations; 0: none; edge kinds sc/hog and --no-position "
                   "only).")
@click.option("--n-trees", type=click.IntRange(min=1, max=MAX_TREES), default=30, show_default=True,
              help="Trees of the random forest (the part maps of every fit take time in proportion).")
@click.option("--max-depth", type=click.IntRange(min=1, max=MAX_DEPTH), default=13, show_default=True,
              help=f"Depth limit of each tree (at most {MAX_DEPTH}; a tree stops where its patches run out, and the "
                   "part maps of every fit take time in proportion to the deepest).")
@click.option("--kind", type=click.Choice(["sc", "hog", "ghog", "ghog_sc", "ghog_ms", "ghog_msc"]), default=_RECIPE["kind"],
              show_default=True,
              help="Descriptor (ghog: gradient-orientation histograms of the grey image; ghog_ms: two cell sizes; "
                   "ghog_msc: ghog_ms plus colour).")
@kitti_root_params("Labelled KITTI root whose frames add real part and background patches (the shipped model: "
                   "../shared/data/kitti, all 72 frames).", type=NonEmptyPath(file_okay=False, exists=True))
@click.option("--frames", default=None, help="Real training frames: comma-separated ids (default: all).")
@split_file_option
@click.option("--position/--no-position", default=_RECIPE["position"], show_default=True,
              help="Append the point's position relative to the box to the descriptor.")
@click.option("--smooth", type=FiniteFloat(min=0.0, max=MAX_SMOOTH), default=_RECIPE["smooth"], show_default=True,
              help="Default Gaussian smoothing of the response maps (sigma in box heights, at most 1).")
@click.option("--calibrate/--no-calibrate", default=None,
              help="Calibrate log(S_j/S_b) per part on held-out real patches (needs a KITTI root; default: on with "
                   "one, as the shipped model).")
@drive_map_option()
@click.option("--label-shapes", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="With a KITTI root: .npz of the labelled cars' own wireframes (frame id -> (N, 36, 3), object "
                   "frame) in place of the mean shape scaled into each label's box.")
@click.option("--synth-scenes", type=click.IntRange(min=0, max=MAX_PART_SCENES), default=_RECIPE["synth_scenes"],
              show_default=True,
              help=f"Synthetic shaded training scenes (wirescene synth stream --synth-seed; at most {MAX_PART_SCENES:,}: "
                   "some 1.3 s and 4 MB of patches each).")
@click.option("--synth-seed", type=click.IntRange(min=1000), default=1000, show_default=True,
              help="Synthetic scene stream (>= 1000; lower seeds are evaluation scenes).")
@click.option("--synth-cache", type=NonEmptyPath(file_okay=False), default=None,
              help="Directory keeping the synthetic scenes' patches, read back by later trainings with the same "
                   "synthetic options (e.g. one per fold).")
@click.option("--class-weight", type=click.Choice(["balanced", "balanced_subsample", "none"]), default="balanced",
              show_default=True, help="Forest class weights.")
@click.option("--n-aug", type=click.IntRange(min=1, max=MAX_AUG), default=2, show_default=True,
              help="With --n-views: renderings per view (first unaugmented).")
@click.option("--heldout", type=NON_NEGATIVE, default=0, show_default=True,
              help="With --n-views: first evaluate with this many CAD models held out.")
@click.option("--compare-hog/--no-compare-hog", default=False, help="With --n-views: also evaluate HOG held-out.")
@click.option("--kitti-background", type=NonEmptyPath(file_okay=False, exists=True), default=None,
              help="With --n-views: labelled KITTI root whose car-free regions add background patches (off by "
                   "default).")
@click.option("--report", type=NonEmptyPath(dir_okay=False), default=None, help="Write a JSON report here.")
def parts(out, seed, n_views, n_trees, max_depth, kind, kitti_root, frames, split_file, position, smooth, calibrate,
          drive_mapping, label_shapes, synth_scenes, synth_seed, synth_cache, class_weight, n_aug, heldout, compare_hog,
          kitti_background, report):
    """Train the 37-class part detector on real KITTI frames, synthetic shaded scenes
    and/or CAD renderings; the defaults are the shipped model's recipe."""
    from wirescene.training.parts import train_part_detector

    if calibrate is None:
        calibrate = bool(_RECIPE["calibrate_real"]) and kitti_root is not None
    elif calibrate and kitti_root is None:
        raise click.UsageError(f"--calibrate needs {KITTI_ROOT_FORMS}: its held-out real patches")

    check_output_file(out, "--out")
    check_output_file(report, "--report")
    check_output_dir(synth_cache, "--synth-cache")
    if kitti_root is None and (frames is not None or split_file is not None):
        raise click.UsageError(f"--frames / --split-file need {KITTI_ROOT_FORMS}")
    if not n_views:  # options of the CAD renderings, else ignored
        refuse_given({"--n-aug": n_aug != 2, "--heldout": heldout, "--compare-hog": compare_hog,
                      "--kitti-background": kitti_background is not None}, needs="--n-views (CAD edge renderings)")
    if kitti_background is not None:  # read after the renderings: checked before them
        from wirescene.core.errors import InputError
        from wirescene.io.kitti import KittiDataset

        background = KittiDataset(kitti_background)
        if not background.has_labels:
            raise InputError("--kitti-background needs label_2/ (the cars its background leaves out)",
                             path=background.split_dir)
        background.require_frames()
    if label_shapes is not None:
        if kitti_root is None:
            raise click.UsageError(f"--label-shapes needs {KITTI_ROOT_FORMS}")
        from wirescene.training.parts_real import load_label_shapes

        label_shapes = load_label_shapes(label_shapes)
    if drive_mapping is not None and not (calibrate and kitti_root is not None):
        raise click.UsageError(f"--drive-map needs {KITTI_ROOT_FORMS} and --calibrate")
    folds = None
    if kitti_root is not None:
        from wirescene.io.kitti import KittiDataset

        ds = KittiDataset(kitti_root)
        ds.require_labels("training")  # the real reason, before any frame, image or calibration fold is looked at
        if frames is not None or split_file is not None:
            frames = select_frames(frames, split_file, ds.frame_ids(), where=ds.split_dir)
        # the real frames' calibrations and images, a truncated one refused before the training reads it
        say_off_centre_frames(ds, ds.frame_ids() if frames is None else frames, images=True)
        if calibrate:
            from wirescene.training.kitti_detector import calibration_folds

            drives, mapping_dir = read_drive_map(ds, drive_mapping)
            if mapping_dir is not None:  # else train_part_detector deals the frames by their known drives alike
                folds = calibration_folds(ds, frames or ds.frame_ids(), drives=drives)

    _, rep = train_part_detector(out, seed=seed, n_views=n_views, n_trees=n_trees, max_depth=max_depth, kind=kind,
                                 n_aug=n_aug, heldout=heldout, synth_scenes=synth_scenes, synth_seed=synth_seed,
                                 class_weight=None if class_weight == "none" else class_weight,
                                 compare_kinds=("hog",) if compare_hog else (),
                                 kitti_background=kitti_background, kitti_root=kitti_root, frames=frames,
                                 position=position, calibrate_real=calibrate, smooth=smooth, synth_cache=synth_cache,
                                 calibration_folds=folds, label_shapes=label_shapes, progress=click.echo)
    if report:
        def public(o):  # the report's keys without the private ones; arrays are write_json's (strict_values)
            return {k: public(v) for k, v in o.items() if not str(k).startswith("_")} if isinstance(o, dict) else o

        from wirescene.core.jsonio import write_json

        write_json(report, public(rep))
    click.echo(f"train accuracy {rep['train_acc']:.3f}")
