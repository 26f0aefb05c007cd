"""CAD car exemplars: AC3D reading, canonicalisation to the object frame, road-car
selection, automatic 36-vertex landmarking and shape-model training."""

from wirescene.cad.ac3d import AC3DMesh, read_ac3d
from wirescene.cad.landmarks import annotate, auto_landmarks, load_corrections
from wirescene.cad.mesh import (
    CarMesh,
    canonicalize,
    default_cad_dir,
    list_cad_files,
    load_car,
    read_mesh,
    road_car_check,
)

__all__ = [
    "AC3DMesh", "read_ac3d", "CarMesh", "canonicalize", "default_cad_dir", "list_cad_files",
    "load_car", "read_mesh", "road_car_check", "annotate", "auto_landmarks", "load_corrections",
]
