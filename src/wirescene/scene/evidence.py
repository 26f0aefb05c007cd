"""Sources of per-vertex image evidence for the likelihood (:class:`PartEvidence`).

* :class:`ResponseEvidence` -- the part detectors' response maps (the paper's model);
* :func:`oracle_evidence` -- evidence peaked at the true projected vertices of
  synthetic scenes, an upper bound that separates inference errors from part-detector
  errors.
"""

from __future__ import annotations

import numpy as np

from ..boxes import iou_2d
from ..datasets.wireframes import WireframeGT
from .hypotheses import Detections
from .likelihood import GaussianVertexEvidence


class ResponseEvidence:
    """Adapter of :class:`wirescene.parts.PartResponses` (one map per detection box,
    already maximised over detector scale) to the likelihood's evidence interface."""

    def __init__(self, responses):
        self.responses = responses

    def log_ratio(self, uv, obj, scale):
        return self.responses.log_ratio(uv, obj).astype(float)


def part_evidence(image: np.ndarray, detections: Detections, *, detector=None) -> ResponseEvidence:
    """Response maps of the part detectors inside the detection boxes of ``image``."""
    from ..parts import response_maps

    return ResponseEvidence(response_maps(image, detections.boxes, detector=detector))


def oracle_evidence(detections: Detections, gt_boxes: np.ndarray, vertex_gt: WireframeGT, **kwargs) -> GaussianVertexEvidence:
    """Evidence at the true vertices of the ground-truth car best overlapping each
    detection (no evidence at all for a detection overlapping none)."""
    n = len(detections)
    uv = np.zeros((n, 36, 2))
    visible = np.zeros((n, 36), bool)
    if len(gt_boxes):
        iou = iou_2d(detections.boxes[:, None, :], np.asarray(gt_boxes)[None, :, :])
        for j in range(n):
            g = int(np.argmax(iou[j]))
            if iou[j, g] > 0.5:
                uv[j] = vertex_gt.vertices_2d[g]
                visible[j] = vertex_gt.visible[g]
    return GaussianVertexEvidence(uv, visible, **kwargs)
