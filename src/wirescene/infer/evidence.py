"""Sources of per-vertex image evidence for the likelihood (:class:`PartEvidence`).

* :class:`ResponseEvidence` -- the part detectors' response maps (the paper's model);
* :func:`oracle_evidence` -- evidence peaked at the true projected vertices of
  synthetic scenes, an upper bound that separates inference errors from part-detector
  errors.
"""

from __future__ import annotations

import numpy as np

from wirescene.core.boxes import MEAN_CAR_DIMS, iou_2d
from wirescene.core.types import Detections
from wirescene.core.wireframe import N_VERTICES
from wirescene.infer.likelihood import GaussianVertexEvidence
from wirescene.io.wireframes import WireframeGT


class ResponseEvidence:
    """Adapter of :class:`wirescene.parts.detector.PartResponses` (one map per detection box,
    already maximised over detector scale) to the likelihood's evidence interface.

    ``bilinear`` interpolates the maps between grid points (default): with the nearest
    grid point the objective is flat within a grid cell (a stride of up to 4 px), which
    the optimiser cannot resolve below (see benchmarks/bench_inference.py).

    Examples
    --------
    >>> from wirescene.parts.detector import response_maps
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> evidence = ResponseEvidence(response_maps(image, [[20, 20, 44, 34]]))
    >>> uv = np.full((2, 36, 2), [32.0, 27.0])  # two hypotheses of detection 0, every vertex at one pixel
    >>> e = evidence.log_ratio(uv, np.array([0, 0]), np.array([30.0, 30.0]))
    >>> e.shape, e.dtype.name  # log(S_j / S_b) per vertex
    ((2, 36), 'float64')
    """

    def __init__(self, responses, *, bilinear: bool = True):
        self.responses = responses
        self.bilinear = bilinear

    def log_ratio(self, uv, obj, scale):
        return self.responses.log_ratio(uv, obj, bilinear=self.bilinear).astype(float)


def part_evidence(image: np.ndarray, detections: Detections, *, detector=None, bilinear: bool = True,
                  flip: bool = False) -> ResponseEvidence:
    """Response maps of the part detectors inside the detection boxes of ``image`` (with
    ``flip``, averaged with those of each box's mirror image).

    Examples
    --------
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> evidence = part_evidence(image, Detections([[20, 20, 60, 44]], 0.9, 0.0))
    >>> maps = evidence.responses.boxes[0]
    >>> maps.log_ratio.shape, maps.stride  # a grid of the box grown by 10%, 1 px apart; 36 parts
    ((29, 49, 36), 1.0)
    """
    from wirescene.parts.detector import response_maps

    return ResponseEvidence(response_maps(image, detections.boxes, detector=detector, flip=flip), bilinear=bilinear)


#: Peak, floor and width of oracle evidence, on the scale of the shipped part detectors,
#: so that the occluded-part score ``c`` (calibrated with detectors), the box weight and
#: the priors mean the same with oracle evidence. Measured on 6 synthetic scenes (seed 7)
#: with the shipped detectors (``benchmarks/bench_inference.py --evidence-scale``): their
#: log ratio averages 2.56 at the true visible vertices, falls off like a Gaussian of
#: 7% of the projected car length (2.29 at 3%, 1.86 at 5%, 0.73 at 8%), and has median
#: -0.84 at random points of the box. The former scale (1.75, -0.55, 3%) fell off 2.5
#: times faster, so that with ``c`` = 1 a vertex 3% of the car length off its true
#: place was better hidden than seen, and ``full`` hid vertices that detectors would keep.
ORACLE_PEAK = 2.55
ORACLE_FLOOR = -0.85
ORACLE_SIGMA = 0.07


def oracle_evidence(detections: Detections, gt_boxes: np.ndarray, vertex_gt: WireframeGT, **kwargs) -> GaussianVertexEvidence:
    """Evidence at the true vertices of the ground-truth car best overlapping each
    detection (no evidence at all for a detection overlapping none), on the scale of the
    part detectors (:data:`ORACLE_PEAK`, :data:`ORACLE_FLOOR`, :data:`ORACLE_SIGMA`;
    ``kwargs`` override).

    Examples
    --------
    >>> gt = WireframeGT(vertices_2d=[np.full((36, 2), [40.0, 32.0])], visible=[np.ones(36, bool)],
    ...                  self_occluded=[np.zeros(36, bool)], occluded_parts=[0], ground_plane={})
    >>> dets = Detections([[20, 20, 60, 44], [70, 0, 90, 20]], 0.9, 0.0)  # the second overlaps no car
    >>> evidence = oracle_evidence(dets, np.array([[21, 20, 60, 45]]), gt)
    >>> evidence.log_ratio(np.full((2, 36, 2), [40.0, 32.0]), np.array([0, 1]), np.array([50.0, 50.0]))[:, 0]
    array([ 2.55, -0.85])
    """
    kwargs = {"peak": ORACLE_PEAK, "floor": ORACLE_FLOOR, "sigma_frac": ORACLE_SIGMA} | kwargs
    n = len(detections)
    uv = np.zeros((n, N_VERTICES, 2))
    visible = np.zeros((n, N_VERTICES), bool)
    if len(gt_boxes):
        iou = iou_2d(detections.boxes[:, None, :], np.asarray(gt_boxes)[None, :, :])
        for j in range(n):
            g = int(np.argmax(iou[j]))
            if iou[j, g] > 0.5:
                uv[j] = vertex_gt.vertices_2d[g]
                visible[j] = vertex_gt.visible[g]
    return GaussianVertexEvidence(uv, visible, **kwargs)


def viewpoint_from_evidence(camera, detections: Detections, evidence, shape_model, *, c: float = 0.0,
                            lifting=None) -> Detections:
    """Detections whose unknown viewpoints (NaN ``alpha``, e.g. boxes of an external
    detector) are set to the bin whose mean-shape wireframe, lifted onto the road plane of
    the camera's mount (``lifting``: :class:`~wirescene.lift.LiftingOptions`, default KITTI's
    level rig 1.65 m above the road) at that viewpoint, best explains the part evidence;
    known viewpoints are kept.

    Examples
    --------
    >>> from wirescene.core.camera import Camera
    >>> from wirescene.core.viewpoints import bin_center
    >>> from wirescene.fitting.models import load_shape_model
    >>> from wirescene.infer.likelihood import instantiate_wireframes
    >>> camera = Camera(np.array([[720.0, 0, 600, 0], [0, 720.0, 170, 0], [0, 0, 1, 0]]), (1200, 370))
    >>> x, z, alpha = -2.0, 15.0, bin_center(3)  # a car seen at 135 deg
    >>> car = instantiate_wireframes(camera, load_shape_model(), x=np.array([x]), z=np.array([z]),
    ...                              azimuth=np.array([alpha + np.arctan2(x, z)]), pitch=np.zeros(1),
    ...                              roll=np.zeros(1), shape=np.zeros((1, 5)), height=1.65)
    >>> evidence = GaussianVertexEvidence(car.uv, ~car.self_hidden, sigma_frac=0.07, peak=2.55, floor=-0.85)
    >>> box = [*car.uv[0].min(0), *car.uv[0].max(0)]
    >>> found = viewpoint_from_evidence(camera, Detections([box], 0.9, np.nan), evidence, load_shape_model())
    >>> np.rad2deg(found.alpha).round(1)  # the bin whose wireframe explains the evidence best
    array([135.])
    """
    from wirescene.core.viewpoints import N_BINS, bin_center
    from wirescene.infer.likelihood import instantiate_wireframes, wireframe_likelihood
    from wirescene.lift import LiftingOptions, solve_positions

    unknown = np.flatnonzero(~np.isfinite(detections.alpha))
    if len(unknown) == 0:
        return detections
    boxes = detections.boxes[unknown][:, None, :]  # (U, 1, 4)
    alpha = bin_center(np.arange(N_BINS))[None, :]  # (1, 8)
    dims = np.broadcast_to(MEAN_CAR_DIMS, (len(unknown), N_BINS, 3))
    opts = LiftingOptions() if lifting is None else lifting
    pitch = np.deg2rad(opts.camera_pitch)
    x, z, az, _ = solve_positions(camera, boxes, alpha, pitch, 0.0, dims, height=opts.camera_height,
                                  iterations=opts.iterations)
    batch = instantiate_wireframes(camera, shape_model, x=x, z=z, azimuth=az, pitch=np.full_like(x, pitch),
                                   roll=np.zeros_like(x), shape=np.zeros(x.shape + (1,)), height=opts.camera_height)
    score = wireframe_likelihood(batch, evidence, np.broadcast_to(unknown[:, None], x.shape), c=c)
    out = detections.alpha.copy()
    out[unknown] = bin_center(np.argmax(score, axis=1))
    return Detections(detections.boxes, detections.scores, out, detections.source)
