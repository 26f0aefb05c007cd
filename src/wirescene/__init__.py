"""wirescene: fine-grained 3D street-scene understanding from a single image.

Geometry convention everywhere inside the package: KITTI rectified camera frame
(x right, y down, z forward), metres, azimuth = KITTI ``rotation_y``.

The public API (see :mod:`wirescene.api`)::

    scene = wirescene.fit(image, calib, boxes=None, variant="full")
    dets = wirescene.detect(image)
    fig = wirescene.draw(image, calib, scene)          # a matplotlib figure of the fit
    reports = wirescene.evaluate(kitti_root, variants=["coarse+gp", "full"])

Importing the package reads no data file; trained artefacts are loaded on first use.
"""

from wirescene.api import detect, draw, evaluate, fit
from wirescene.core.camera import Camera, read_kitti_calib
from wirescene.core.errors import (
    ArgumentError,
    CalibrationWarning,
    HeldOutWarning,
    InputError,
    ShapeError,
    WiresceneError,
)
from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate
from wirescene.core.version import __version__
from wirescene.eval.metrics import EvaluationReport
from wirescene.fitting.options import FitOptions
from wirescene.fitting.variants import VARIANTS
from wirescene.infer.inference import InferenceOptions
from wirescene.lift import LiftingOptions

__all__ = [
    "fit", "detect", "draw", "evaluate", "Camera", "read_kitti_calib", "Detections", "ObjectEstimate", "SceneEstimate",
    "FitOptions", "InferenceOptions", "LiftingOptions", "EvaluationReport", "VARIANTS",
    "ArgumentError", "InputError", "ShapeError", "WiresceneError", "CalibrationWarning", "HeldOutWarning",
    "__version__",
]
