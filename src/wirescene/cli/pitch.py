"""CLI piece: ``wirescene pitch``, a rig's camera pitch read off the boxes of many of its frames."""

from __future__ import annotations

from pathlib import Path

import click

from wirescene.cli.options import (
    NON_NEGATIVE,
    NonEmptyPath,
    calib_option,
    check_output_file,
    field_type,
    kitti_dataset,
    models_option,
    say_models,
    say_off_centre_frames,
    select_frames,
    split_file_option,
    split_option,
)
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, Mount
from wirescene.core.jsonio import write_json
from wirescene.core.settings import stage_field
from wirescene.lift import LiftingOptions

#: Frames read by default: the pitch pooled over 20 or 36 held-out KITTI frames is within 0.3 deg
#: of the other frames' in 90% of draws, one frame's within 1.1 (``benchmarks/bench_rig_pitch.py``).
DEFAULT_FRAMES = 40


def spread_sample(ids: list[str], n: int) -> list[str]:
    """``n`` of ``ids`` spread evenly over them, in their order (all of them for ``n`` 0 or
    ``n >= len(ids)``): the frames of a long drive, not its first minute.

    Examples
    --------
    >>> spread_sample([f"{i:06d}" for i in range(10)], 3)
    ['000000', '000004', '000009']
    >>> spread_sample(["a", "b"], 0)
    ['a', 'b']
    """
    if not n or n >= len(ids):
        return list(ids)
    import numpy as np

    return [ids[int(i)] for i in np.round(np.linspace(0, len(ids) - 1, n)).astype(int)]


@click.command("pitch")
@click.argument("kitti_root", type=NonEmptyPath(directory=True, path_type=Path))
@click.option("--frames", default=None, help="Comma-separated frame ids (default: every frame of the split).")
@split_file_option
@split_option()
@calib_option
@click.option("--max-frames", type=NON_NEGATIVE, default=DEFAULT_FRAMES, show_default=True,
              help="Read this many of the frames chosen, spread evenly over them (0: all of them); the pitch pooled "
                   "over 20 KITTI frames is within 0.3 deg of the other 52 frames' in 90% of draws.")
@models_option
@click.option("--bank", "bank_path", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="Detector bank .npz (default: --models' or the shipped one); its ground prior reads the pitch.")
@click.option("--camera-height", type=field_type(stage_field(LiftingOptions, "camera_height")),
              default=KITTI_CAMERA_HEIGHT, show_default=True,
              help="The camera's height above the road (m), told: the pitch is read at it (a camera 1.3 m up read "
                   "at 1.65 m reads some 0.8 deg further down), so measure it (the fit's --set "
                   "lifting.camera_height).")
@click.option("--camera-pitch", type=field_type(stage_field(LiftingOptions, "camera_pitch")), default=0.0,
              show_default=True, help="The pitch (degrees down from the road) the search is centred on, within 15 "
                                      "deg of it.")
@click.option("--json", "json_out", type=NonEmptyPath(dir_okay=False, path_type=Path), default=None,
              help="Write the rig's pitch and each frame's (null where it read no box) as JSON.")
def pitch(kitti_root, frames, split_file, split, calib, max_frames, models, bank_path, camera_height, camera_pitch,
          json_out):
    """Read the camera's pitch off the cars of many frames of one rig (a camera mounted once).

    Each frame's boxes, found by the detector bank without the ground and traffic priors
    (which need the pitch), tell how far above their bottoms the horizon lies; the frames'
    log-likelihoods are summed, so the few boxes of one frame no longer decide it (a KITTI
    frame alone reads KITTI's level rig to 0.75 deg, standard deviation; 20 frames within
    0.3 deg of the other 52 frames' pitch in 90% of draws). The pitch is read at the camera's
    height told (--camera-height: measure it). Tell the fit the height and the pitch printed
    (`--set lifting.camera_height=H --set lifting.camera_pitch=D`, `wirescene detect
    --camera-height H --camera-pitch D`) rather than reading each frame's (`--estimate-pitch`)."""
    import numpy as np

    from wirescene.core.errors import InputError
    from wirescene.core.resources import resolve_models
    from wirescene.fitting.models import detector_bank
    from wirescene.fitting.mount import image_pitch_likelihood, rig_pitch
    from wirescene.predetect.geometry import PITCH_SEARCH

    check_output_file(json_out, "--json")
    ds = kitti_dataset(kitti_root, split, calib)
    found = resolve_models(models)
    bank_file = found.file("detector_bank", given=bank_path)
    bank = detector_bank(bank_file)
    say_models(found, replaced=["detector_bank"] if bank_path else [])
    if not bank.meta.get("ground_prior"):
        raise InputError("detector bank without a ground prior to read a pitch with (banks trained on KITTI frames "
                         "have one)", path=bank_file)
    ids = select_frames(frames, split_file, ds.require_frames(), where=ds.split_dir, what="frame") or ds.frame_ids()
    ids = spread_sample(ids, max_frames)
    say_off_centre_frames(ds, ids)  # before the first frame: a missing calibration is refused here
    told = Mount(camera_height, camera_pitch)
    bound = stage_field(LiftingOptions, "camera_pitch").metadata["maximum"]
    likelihoods, each = [], {}
    for fid in ids:
        likelihood, n = image_pitch_likelihood(ds.camera(fid), ds.image(fid), bank=bank, told=told)
        likelihoods.append(likelihood)
        if likelihood.any():
            each[fid] = {"pitch": round(rig_pitch([likelihood], told=told), 2), "boxes": n}
            click.echo(f"{fid}: {each[fid]['pitch']:.1f} deg ({_count(n, 'box')} found)")
        else:  # boxes cut by the bottom edge are not read: the pitch told would pass for one read
            each[fid] = {"pitch": None, "boxes": n}
            click.echo(f"{fid}: no pitch read ({_count(n, 'box')} found{', cut by the bottom edge' if n else ''})")
    boxes = sum(e["boxes"] for e in each.values())
    read = [e["pitch"] is not None for e in each.values()]
    if not any(read):  # the pitch told is no pitch read: no line (nor --json) may pass it off as one
        each_cut = "cut" if boxes == 1 else "each cut"
        cut = f" ({_count(boxes, 'box')} found, {each_cut} by the image's bottom edge)" if boxes else ""
        raise InputError(f"no box to read the pitch off in the {_count(len(ids), 'frame')} read{cut}: give frames "
                         "of cars (--frames, --max-frames)", path=ds.image_dir)
    rig = round(rig_pitch(likelihoods, told=told), 2)
    alone = [abs(e["pitch"] - rig) for e in each.values() if e["pitch"] is not None]
    spread = (f"; each frame alone: within {np.percentile(alone, 90, method='higher'):.1f} deg of it for 90%"
              if len(alone) > 1 else "")
    over = _count(len(ids), "frame") if all(read) else f"{sum(read)} of {_count(len(ids), 'frame')} read"
    click.echo(f"the rig's pitch over {over} ({_count(boxes, 'box')} found): {rig:.1f} deg "
               f"down from the road, its height told {camera_height:g} m{spread}")
    if abs(rig - camera_pitch) > PITCH_SEARCH - 0.05 or abs(rig) >= bound:  # at the grid's end or the bound
        click.echo(f"wirescene: the pitch read lies at the edge of the search ({PITCH_SEARCH:g} deg about "
                   f"--camera-pitch {camera_pitch:g}, at most {bound:g}): read it again about it (--camera-pitch "
                   f"{rig:.1f})", err=True)
    click.echo(f"fit with --set lifting.camera_height={camera_height:g} --set lifting.camera_pitch={rig:.1f} "
               f"(wirescene detect --camera-height {camera_height:g} --camera-pitch {rig:.1f})")
    if json_out is not None:
        record = {"pitch": rig, "camera_height": camera_height, "told_pitch": camera_pitch, "boxes": boxes,
                  "frames": each}
        write_json(json_out, record)


def _count(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless one: ``1 box``, ``3 boxes``, ``2 frames``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}{'es' if noun.endswith('x') else 's'}"
