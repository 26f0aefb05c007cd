"""Dataset readers and writers (KITTI object benchmark)."""

from wirescene.io.kitti import (
    CAR_TYPES,
    FrameLabels,
    KittiDataset,
    Label,
    car_indices,
    format_label,
    image_size,
    read_image,
    read_labels,
    select_cars,
    write_labels,
)

__all__ = [
    "CAR_TYPES",
    "FrameLabels",
    "KittiDataset",
    "Label",
    "car_indices",
    "format_label",
    "image_size",
    "read_image",
    "read_labels",
    "select_cars",
    "write_labels",
]
