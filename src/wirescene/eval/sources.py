"""Where each frame's pre-detections come from in an evaluation, and the per-frame
random stream that makes runs independent of scheduling."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wirescene.core.errors import InputError
from wirescene.core.types import Detections
from wirescene.io.detections import detections_from_labels, read_detections
from wirescene.io.kitti import KittiDataset


@dataclass(frozen=True)
class DetectionSource:
    """Where pre-detections come from: ``"gt"`` (label boxes, noisy viewpoint bins),
    ``"bank"`` (our part-configuration detector bank on the raw image) or a directory of
    per-frame detection files (``FRAME.json``, ``.csv`` or ``.txt``)."""

    spec: str = "gt"
    viewpoint_noise_deg: float = 0.0

    def for_frame(self, dataset: KittiDataset, frame_id: str, rng: np.random.Generator) -> Detections:
        if self.spec == "gt":
            return detections_from_labels(dataset.labels(frame_id), viewpoint_noise_deg=self.viewpoint_noise_deg, rng=rng)
        if self.spec == "bank":
            from wirescene.predetect import detect_cars

            return detect_cars(dataset.image(frame_id))
        folder = Path(self.spec)
        if not folder.is_dir():
            raise InputError("detections must be 'gt', 'bank' or a directory of per-frame files", path=folder)
        for ext in (".json", ".csv", ".txt"):
            path = folder / f"{frame_id}{ext}"
            if path.is_file():
                try:
                    return read_detections(path)
                except InputError as exc:
                    if exc.problem == "no car detections in file":
                        return Detections.empty(str(path))
                    raise
        return Detections.empty(str(folder))


def frame_seed(seed: int, frame_id: str) -> np.random.Generator:
    """A generator that depends only on the run seed and the frame, so results do not
    depend on the order (or the process) in which frames are processed."""
    digits = int("".join(ch for ch in frame_id if ch.isdigit()) or 0)
    return np.random.default_rng([seed, digits])
