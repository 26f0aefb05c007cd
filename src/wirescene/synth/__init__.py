"""Synthetic street scenes with full ground truth (KITTI layout plus per-vertex wireframe
visibility): :mod:`.layout` samples the geometry, :mod:`.generate` renders and writes."""

from wirescene.synth.generate import (
                       OCCLUSION_THRESHOLDS,
                       SyntheticScene,
                       default_camera,
                       generate_dataset,
                       generate_scene,
                       load_car_library,
                       write_scene,
)
from wirescene.synth.layout import SceneLayout, sample_layout

__all__ = ["generate_scene", "generate_dataset", "write_scene", "load_car_library", "default_camera",
           "SyntheticScene", "SceneLayout", "sample_layout", "OCCLUSION_THRESHOLDS"]
