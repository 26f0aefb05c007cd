"""wirescene: fine-grained 3D street-scene understanding from a single image.

Geometry convention everywhere inside the package: KITTI rectified camera frame
(x right, y down, z forward), metres, azimuth = KITTI ``rotation_y``.

The public API (see :mod:`wirescene.api`)::

    scene = wirescene.fit(image, calib, boxes=None, variant="full")
    dets = wirescene.detect(image)
    reports = wirescene.evaluate(kitti_root, variants=["coarse+gp", "full"])

Importing the package reads no data file; trained artefacts are loaded on first use.
"""

__version__ = "0.2.0"

from wirescene.api import detect, evaluate, fit  # noqa: E402
from wirescene.core.camera import Camera, read_kitti_calib  # noqa: E402
from wirescene.core.errors import ArgumentError, InputError, ShapeError, WiresceneError  # noqa: E402
from wirescene.core.types import Detections, ObjectEstimate, SceneEstimate  # noqa: E402
from wirescene.fitting.pipeline import FitOptions  # noqa: E402
from wirescene.fitting.variants import VARIANTS  # noqa: E402

__all__ = [
    "fit", "detect", "evaluate", "Camera", "read_kitti_calib", "Detections", "ObjectEstimate", "SceneEstimate",
    "FitOptions", "VARIANTS", "ArgumentError", "InputError", "ShapeError", "WiresceneError", "__version__",
]
