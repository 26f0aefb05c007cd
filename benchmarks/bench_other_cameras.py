"""Other cameras than KITTI's: the fit and our own pre-detection on synthetic scenes, plain script.

Users run wirescene on other rigs (other intrinsics, other mounting heights, a camera that
looks down). This renders ``--scenes`` synthetic scenes (``generate_scene(--seed, i,
camera=..., camera_height=..., camera_pitch_deg=...)``) for one ``--setting`` and fits
them from their label boxes (``fit_frame``, ``--particles`` particles, seed 1, viewpoints
from the box rule), once as the fit's defaults assume KITTI's rig (``assumed``) and, for a
setting of another height or pitch, once told the camera's mount (``told``:
``lifting.camera_height``, ``lifting.camera_pitch``: the pitch the setting adds to the rig's
random +-2 deg), once as KITTI's rig with the pitch read off the frame's boxes
(``read``: ``lifting.estimate_pitch``, ``wirescene.detect(estimate_pitch=True)``), and once
told the pitch read off the boxes of all the setting's scenes pooled (``pooled``: as
``wirescene pitch`` reads a rig's, the shipped bank, the setting's camera height told). Reported
per variant: the cars, the median bird's-eye error to the label location and the share
within 1 m. With ``--detect``, our own pre-detection (``wirescene.detect`` at 0.3, in each
mode as above) and its recall at IoU 0.5 of the cars with occlusion <= 1 and truncation < 0.3.

With a pitched camera the label boxes are those of the cars as they stand (their true
rotation, projected and clipped): the generator's KITTI label box is the level box of
``rotation_y``, which a car on a road tilted in the camera's frame does not fill.

Usage:
  python benchmarks/bench_other_cameras.py --setting height-1.3 [--scenes 30] [--seed 11] [--particles 50]
      [--variant coarse+gp --variant fg+gp] [--detect] [--set STAGE.KEY=VALUE ...] [--json out.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import wirescene  # noqa: E402
from wirescene.core.atomic import write_text  # noqa: E402
from wirescene.core.boxes import box_corners, clip_boxes, iou_2d, project_points_to_box  # noqa: E402
from wirescene.core.camera import Camera  # noqa: E402
from wirescene.core.groundplane import KITTI_CAMERA_HEIGHT, Mount  # noqa: E402
from wirescene.core.jsonio import dumps  # noqa: E402
from wirescene.core.types import Detections  # noqa: E402
from wirescene.fitting.models import detector_bank  # noqa: E402
from wirescene.fitting.mount import image_pitch_likelihood, rig_pitch  # noqa: E402
from wirescene.fitting.options import FitOptions  # noqa: E402
from wirescene.fitting.pipeline import fit_frame  # noqa: E402
from wirescene.synth.generate import default_camera, generate_scene  # noqa: E402


def _intrinsics(f: float, cx: float, cy: float, width: int, height: int) -> Camera:
    return Camera(np.array([[f, 0, cx, 0], [0, f, cy, 0], [0, 0, 1, 0]], float), (width, height))


#: ``{setting: (camera or None for KITTI's, camera height m, extra pitch deg)}``.
SETTINGS = {
    "kitti": (None, KITTI_CAMERA_HEIGHT, 0.0),
    "1600x900": (_intrinsics(1266.0, 800.0, 450.0, 1600, 900), KITTI_CAMERA_HEIGHT, 0.0),
    "2048x1024": (_intrinsics(2262.0, 1024.0, 512.0, 2048, 1024), KITTI_CAMERA_HEIGHT, 0.0),
    "principal-offset": (_intrinsics(721.5, 420.0, 240.0, 1242, 375), KITTI_CAMERA_HEIGHT, 0.0),
    "height-1.3": (None, 1.3, 0.0),
    "height-2.0": (None, 2.0, 0.0),
    "pitch-2": (None, KITTI_CAMERA_HEIGHT, 2.0),
    "pitch-4": (None, KITTI_CAMERA_HEIGHT, 4.0),
}


def label_boxes(scene, cars) -> np.ndarray:
    """The cars' boxes as they stand: their 3D boxes at their true rotation, projected and clipped."""
    W, H = scene.camera.image_size
    wires = {c["scene_object_id"]: c for c in scene.wireframes["cars"]}
    out = []
    for o, c in zip(cars, (wires[i] for i in sorted(wires))):
        corners = box_corners(np.asarray(o.dims, float), np.asarray(c["location"], float), np.asarray(c["R"], float))
        out.append(project_points_to_box(scene.camera, corners) if corners[:, 2].min() > 0.1 else o.box)
    return clip_boxes(np.array(out, float).reshape(-1, 4), W, H)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--setting", choices=sorted(SETTINGS), required=True)
    ap.add_argument("--scenes", type=int, default=30)
    ap.add_argument("--seed", type=int, default=11, help="scene stream")
    ap.add_argument("--particles", type=int, default=50)
    ap.add_argument("--variant", dest="variants", action="append", default=None,
                    help="fitted variants (default coarse+gp and fg+gp)")
    ap.add_argument("--detect", action="store_true", help="also our own pre-detection's recall")
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="STAGE.KEY=VALUE",
                    help="a fit option for both modes (e.g. lifting.pitch_range=6)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    camera, height, pitch = SETTINGS[args.setting]
    given = dict(s.split("=", 1) for s in args.settings)
    camera = default_camera() if camera is None else camera
    variants = args.variants or ["coarse+gp", "fg+gp"]
    kitti_rig = (KITTI_CAMERA_HEIGHT, 0.0)
    t0 = time.perf_counter()
    scenes = [generate_scene(args.seed, i, camera=camera, camera_height=height, camera_pitch_deg=pitch)
              for i in range(args.scenes)]
    rig = Mount(height, 0.0)  # the setting's scenes pooled, at the height told, as `wirescene pitch` reads a rig
    pooled = rig_pitch([image_pitch_likelihood(s.camera, s.image, bank=detector_bank(None), told=rig)[0]
                        for s in scenes], told=rig)
    modes = {"assumed": kitti_rig} | ({"told": (height, pitch)} if (height, pitch) != kitti_rig else {}) \
        | {"read": kitti_rig, "pooled": (height, pooled)}
    errors = {(m, v): [] for m in modes for v in variants}
    found = {m: [0, 0] for m in modes}
    for scene in scenes:
        objects = scene.labels.objects
        cars = [o for o in objects if o.type == "Car"]
        if not cars:
            continue
        boxes = label_boxes(scene, objects)[[k for k, o in enumerate(objects) if o.type == "Car"]] if pitch \
            else np.array([o.box for o in cars], float)
        truth = np.array([o.location for o in cars], float)
        for mode, (assumed, assumed_pitch) in modes.items():
            options = FitOptions(seed=1).with_settings({"lifting.n_particles": args.particles, **given,
                                                        "lifting.camera_height": assumed,
                                                        "lifting.camera_pitch": assumed_pitch,
                                                        "lifting.estimate_pitch": mode == "read"})
            fitted = fit_frame(scene.camera, Detections(boxes, 1.0, np.nan, "gt"), variants, image=scene.image,
                               options=options)
            for v in variants:
                fit = np.array([c.location for c in fitted.estimates[v].cars], float)
                errors[mode, v] += list(np.linalg.norm((fit - truth)[:, [0, 2]], axis=1))
            if args.detect:
                easy = np.array([o.box for o in cars if o.occluded <= 1 and o.truncated < 0.3], float).reshape(-1, 4)
                # the fit's enlargement (--set predetect.upsample=1: the image alone, as the README's figures)
                dets = wirescene.detect(scene.image, scene.camera, threshold=0.3, camera_height=assumed,
                                        camera_pitch=assumed_pitch, estimate_pitch=mode == "read",
                                        upsample=options.predetect.upsample)
                hit = (iou_2d(easy[:, None], dets.boxes[None]).max(axis=1) >= 0.5) if len(dets) else np.zeros(len(easy))
                found[mode][0] += int(np.sum(hit))
                found[mode][1] += len(easy)
    out = {"setting": args.setting, "scenes": args.scenes, "seed": args.seed, "camera_height": height,
           "camera_pitch_deg": pitch, "pooled_pitch_deg": pooled, "settings": given,
           "seconds": round(time.perf_counter() - t0)}
    print(f"{args.setting}: {args.scenes} scenes of stream {args.seed}, camera {height:.2f} m high, "
          f"pitched {pitch:+.1f} deg, {camera.image_size[0]} x {camera.image_size[1]}, f = {camera.K[0, 0]:.0f} px; "
          f"the pitch read off all scenes pooled {pooled:+.1f} deg")
    for (mode, v), e in errors.items():
        e = np.asarray(e)
        out[f"{mode} {v}"] = {"cars": len(e), "median_m": round(float(np.median(e)), 3),
                              "within_1m": round(float(np.mean(e < 1.0)) * 100, 1)}
        print(f"  {mode:8s} {v:10s} {len(e):4d} cars  median {np.median(e):5.2f} m  within 1 m {np.mean(e < 1) * 100:5.1f}%")
    if args.detect:
        for mode, (hits, n) in found.items():
            out[f"{mode} recall"] = [hits, n]
            print(f"  {mode:8s} pre-detection recall at 0.3: {hits} / {n} ({hits / max(n, 1) * 100:.0f}%)")
    if args.json:
        write_text(args.json, dumps(out) + "\n")


if __name__ == "__main__":
    main()
