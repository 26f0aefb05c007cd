"""wirescene: fine-grained 3D street-scene understanding from a single image.

Geometry convention everywhere inside the package: KITTI rectified camera frame
(x right, y down, z forward), metres, azimuth = KITTI ``rotation_y``.
"""

__version__ = "0.1.0"
