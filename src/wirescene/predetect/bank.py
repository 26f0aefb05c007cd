"""The detector bank: one linear HOG template per part configuration, applied to one
shared HOG feature pyramid, merged by agglomerative clustering of the predicted
full-object boxes (paper Sec. 3.4).

Single-component linear HOG templates trained as linear SVMs with hard-negative mining
stand in for the paper's single-component DPMs: a single-component DPM is a root filter
plus deformable part filters; the root filter alone is exactly this (Dalal-Triggs)
detector, the configurations are already semi-local, and it trains in minutes on a CPU,
whereas latent-SVM DPM training needs the original MATLAB/C code.

A linear box regression (DPM's bounding-box prediction, :func:`apply_box_regression`)
moves the clusters' boxes onto the labelled boxes' convention. Given the camera, a ground
prior (:mod:`wirescene.predetect.geometry`) weighs each box's height against its position
below the horizon: background windows rarely stand on the road at the size of a car; and a
viewpoint prior (:mod:`wirescene.predetect.viewpoint_prior`) weighs front against back views
by where the car stands in the traffic. A verifier (:mod:`wirescene.predetect.verifier`)
takes a second look at each final box with its surroundings, whose logit adds to the score
with the weight its calibration gave it.

The shipped bank is trained on the real labelled KITTI frames
(:mod:`wirescene.training.kitti_detector`, ``wirescene train detector --kitti-root``) and carries a Platt
calibration, so :func:`detect_cars` returns confidences (probability of a car);
:mod:`.training` trains the older synthetic-scene bank.

The bank is stored without pickle in a versioned ``.npz`` (loadable with numpy alone).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wirescene.core.artefacts import load_npz, save_npz, trained_arrays, trained_images
from wirescene.core.boxes import clip_boxes
from wirescene.core.errors import ArgumentError, InputError
from wirescene.core.groundplane import KITTI_MOUNT, Mount
from wirescene.core.jsonio import dumps
from wirescene.core.resources import DATA_DIR
from wirescene.core.types import Detections
from wirescene.core.validate import MIN_IMAGE_SIDE
from wirescene.core.viewpoints import bin_center
from wirescene.core.wireframe import N_VERTICES
from wirescene.predetect.channels import integral_channels
from wirescene.predetect.configurations import Configuration
from wirescene.predetect.geometry import Horizon, ground_log_ratio, road_horizon
from wirescene.predetect.hog import CELL, N_FEAT, feature_pyramid, pyramid_scales, to_gray
from wirescene.predetect.refine import apply_box_refinement
from wirescene.predetect.verifier import N_VIEW_GROUPS, VIEW_GROUPS, verifier_features, verifier_logits
from wirescene.predetect.viewpoint_prior import choose_viewpoints, lateral_position, viewpoint_log_prior

FORMAT_VERSION = 6
"""2: adds ``calibration`` (Platt ``a, b``; empty when uncalibrated). 3: adds the box
refinement (``refine_mean``, ``refine_scale``, ``refine_weights``; empty when none). 4: adds
the verifier (``verify_mean``, ``verify_scale``, ``verify_weights``, ``verify_gain``; empty
when none). 5: ``verify_weights`` may hold one row per viewpoint group
(:data:`wirescene.predetect.verifier.VIEW_GROUPS`). 6: adds ``verify_channels`` (1: the verifier also
reads the colour channels of :mod:`wirescene.predetect.channels`; older banks: 0)."""
ARTEFACT_KIND = "detector-bank"
DEFAULT_BANK_PATH = DATA_DIR / "detector_bank.npz"
VERIFIER_ARRAYS = ("mean", "scale", "weights", "gain")
#: ``meta["support_weight"]`` of newly trained banks: margin a cluster gains per e-fold of its votes
#: (:func:`merge_activations`), chosen on fold group {0, 1} among 0 / 0.05 / 0.15 / 0.3 / 0.6 (``benchmarks/RESULTS.md``).
SUPPORT_WEIGHT = 0.3


@dataclass
class DetectorBank:
    """A bank of ``T`` linear HOG templates, one per part configuration (module docstring).

    Attributes
    ----------
    configs : list of Configuration
        The part configuration of each template (its viewpoint bin, vertices, template shape
        and full-box offsets).
    weights : list of (th, tw, 31) float32 arrays
        The templates.
    biases : (T,) array
    threshold : float
        Default detection threshold, in the units of the scores :func:`detect_cars` returns.
    meta : dict
        Training settings and the learned priors (``ground_prior``, ``viewpoint_prior``, ...).
    calibration : (2,) array or None
        Platt ``(a, b)``: confidence ``= sigmoid(a * margin + b)``.
    refinement, verifier : dict or None
        The box refinement (:mod:`wirescene.predetect.refine`) and the verifier
        (:mod:`wirescene.predetect.verifier`, with its ``gain``).
    trained_images : dict of str
        ``{frame id: image SHA-256}`` of the real frames it was trained on (empty: none, or a
        file written before the record was; :func:`wirescene.core.artefacts.trained_arrays`).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> len(bank) == len(bank.weights) == len(bank.biases) == len(bank.bins), bank.weights[0].shape[2]
    (True, 31)
    >>> bank.configs[0].name, bank.configs[0].template == bank.weights[0].shape[:2]  # (th, tw) cells
    ('bin0:full', True)
    >>> a, b = bank.calibration  # Platt: confidence = sigmoid(a * margin + b)
    >>> bool(np.isclose(bank.confidence(0.0), 1 / (1 + np.exp(-b))))
    True
    >>> round(float(bank.confidence(bank.margin_of(0.7))), 6)  # margin_of inverts it
    0.7
    """

    configs: list  # [Configuration]
    weights: list  # [(th, tw, 31) float32]
    biases: np.ndarray  # (T,)
    threshold: float = 0.0  # default detection threshold (in the units of the scores detect_cars returns)
    meta: dict = field(default_factory=dict)
    calibration: np.ndarray | None = None  # (2,) Platt (a, b): confidence = sigmoid(a * margin + b)
    refinement: dict | None = None  # image-based box refinement (wirescene.predetect.refine)
    verifier: dict | None = None  # second look at each box (wirescene.predetect.verifier), with its "gain"
    trained_images: dict = field(default_factory=dict)  # {frame id: image SHA-256} of its real training frames

    def __len__(self) -> int:
        return len(self.configs)

    @property
    def needs_channels(self) -> bool:
        """Whether the verifier reads the image's colour channels
        (:func:`wirescene.predetect.channels.integral_channels`) besides its grey image."""
        return self.verifier is not None and bool(self.verifier.get("channels", False))

    @property
    def bins(self) -> np.ndarray:
        return np.array([c.bin for c in self.configs], int)

    def confidence(self, margin) -> np.ndarray:
        """Scores reported for raw cluster margins: calibrated probabilities when the bank
        carries a Platt calibration, else the margins themselves."""
        m = np.asarray(margin, float)
        if self.calibration is None:
            return m
        a, b = (float(v) for v in self.calibration)
        return 1.0 / (1.0 + np.exp(-(a * m + b)))

    def ground_log_ratio(self, boxes, horizon: float | Horizon) -> np.ndarray:
        """``(D,)`` log ratio of the bank's ground prior for ``boxes`` ``(D, 4)`` under the
        horizon row ``horizon`` (:func:`wirescene.predetect.geometry.ground_log_ratio`);
        zeros for a bank without a ground prior."""
        prior = self.meta.get("ground_prior")
        if not prior or not len(boxes):
            return np.zeros(len(boxes))
        return ground_log_ratio(prior, boxes, horizon)

    def margin_of(self, score: float) -> float:
        """Inverse of :meth:`confidence` for one score (a threshold)."""
        if self.calibration is None or not np.isfinite(score):
            return float(score)
        a, b = (float(v) for v in self.calibration)
        p = min(max(float(score), 1e-12), 1 - 1e-12)
        return (np.log(p / (1 - p)) - b) / a

    # ----------------------------------------------------------------- storage
    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        T = len(self.configs)
        verts = -np.ones((T, N_VERTICES), np.int16)
        for i, c in enumerate(self.configs):
            verts[i, : len(c.vertices)] = c.vertices
        arrays = dict(
            bins=np.array([c.bin for c in self.configs], np.int8),
            n_vertices=np.array([len(c.vertices) for c in self.configs], np.int16),
            vertices=verts,
            templates=np.array([c.template for c in self.configs], np.int16).reshape(T, 2),
            offsets=np.array([c.offsets for c in self.configs], np.float32).reshape(T, 4),
            frac=np.array([c.frac for c in self.configs], np.float32).reshape(T, 2),
            coverage=np.array([c.coverage for c in self.configs], np.float32),
            n_examples=np.array([c.n_examples for c in self.configs], np.int32),
            biases=np.asarray(self.biases, np.float32),
            weights=np.concatenate([w.astype(np.float32).ravel() for w in self.weights]) if T else np.zeros(0, np.float32),
            names=np.array([c.name for c in self.configs], dtype=str),
            threshold=np.array(float(self.threshold)),
            # strict JSON (a NaN of the validation summary as null), the bytes of json.dumps' otherwise
            meta_json=np.array(dumps(self.meta, indent=None, sort_keys=True)),
            calibration=np.zeros(0, np.float64) if self.calibration is None else np.asarray(self.calibration, float),
            **{f"refine_{k}": (np.zeros(0, np.float32) if self.refinement is None
                               else np.asarray(self.refinement[k], np.float32)) for k in ("mean", "scale", "weights")},
            **{f"verify_{k}": (np.zeros(0, np.float32) if self.verifier is None
                               else np.asarray(self.verifier[k], np.float32)) for k in VERIFIER_ARRAYS},
            verify_channels=np.array(int(self.needs_channels), np.int8),
            **trained_arrays(self.trained_images),
        )
        return save_npz(path, arrays, kind=ARTEFACT_KIND, version=FORMAT_VERSION)

    @classmethod
    def load(cls, path) -> "DetectorBank":
        path = Path(path)
        # missing / corrupt / foreign: InputError; a bank of format 3 reads as one without a verifier,
        # one of format 4 as one with a single verifier regression, formats 3-5 as ones whose verifier reads no colour
        z = load_npz(path, kind=ARTEFACT_KIND, version=FORMAT_VERSION, older=(3, 4, 5))
        try:
            T = len(z["bins"])
            flat = z["weights"]
            configs, weights, pos = [], [], 0
            for i in range(T):
                th, tw = (int(v) for v in z["templates"][i])
                n = th * tw * N_FEAT
                weights.append(flat[pos:pos + n].reshape(th, tw, N_FEAT).astype(np.float32))
                pos += n
                nv = int(z["n_vertices"][i])
                configs.append(Configuration(int(z["bins"][i]), tuple(int(v) for v in z["vertices"][i, :nv]),
                                             (th, tw), z["offsets"][i].astype(float), z["frac"][i].astype(float),
                                             float(z["coverage"][i]), int(z["n_examples"][i])))
            if pos != len(flat):
                raise InputError("detector bank weights do not match the template shapes", path=path)
            calib = z["calibration"].astype(float)
            if calib.size == 0:
                calib = None  # an uncalibrated bank
            elif calib.shape != (2,):
                raise InputError("detector bank calibration must hold 2 numbers", path=path)
            refinement = {k: z[f"refine_{k}"] for k in ("mean", "scale", "weights")}
            if refinement["weights"].size == 0:
                refinement = None  # a bank without box refinement
            elif not (refinement["weights"].ndim == 2 and refinement["weights"].shape[1] == 4
                      and refinement["mean"].shape == refinement["scale"].shape == (len(refinement["weights"]) - 1,)):
                raise InputError("detector bank refinement arrays do not match", path=path)
            verifier = {k: z.get(f"verify_{k}", np.zeros(0, np.float32)) for k in VERIFIER_ARRAYS}
            if verifier["weights"].size == 0:
                verifier = None  # a bank without verifier
            elif not (verifier["mean"].shape == verifier["scale"].shape == (verifier["weights"].shape[-1] - 1,)
                      and verifier["weights"].shape[:-1] in ((), (N_VIEW_GROUPS,)) and verifier["gain"].shape == ()):
                raise InputError("detector bank verifier arrays do not match", path=path)
            else:
                verifier["channels"] = bool(z.get("verify_channels", np.array(0)))
            return cls(configs, weights, z["biases"].astype(np.float32), float(z["threshold"]),
                       json.loads(str(z["meta_json"])), calib, refinement, verifier,  # older banks: NaN too
                       trained_images(z, path=path))
        except (KeyError, ValueError) as exc:
            raise InputError(f"malformed detector bank ({exc.__class__.__name__}: {exc})", path=path) from None


_DEFAULT: DetectorBank | None = None


def load_default_bank() -> DetectorBank:
    """The bank shipped in ``wirescene/data/detector_bank.npz`` (cached).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> bank is load_default_bank(), 0 < bank.threshold < 1  # cached; its threshold is a probability
    (True, True)
    """
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = DetectorBank.load(DEFAULT_BANK_PATH)
    return _DEFAULT


# --------------------------------------------------------------------------- scoring


@dataclass
class Activations:
    """Raw sliding-window activations of every detector of the bank.

    Examples
    --------
    >>> bank = load_default_bank()
    >>> pyramid = bank_pyramid(bank, np.zeros((64, 96, 3), np.uint8))
    >>> act = score_pyramid(bank, pyramid, threshold=-np.inf, top_k=5, detectors=[0])
    >>> act.det.shape, act.boxes.shape, act.scores.shape, act.level.shape, act.cell.shape
    ((5,), (5, 4), (5,), (5,), (5, 2))
    """

    det: np.ndarray  # (A,) detector index
    boxes: np.ndarray  # (A, 4) configuration boxes in image pixels
    scores: np.ndarray  # (A,)
    level: np.ndarray  # (A,) pyramid level
    cell: np.ndarray  # (A, 2) (row, col) of the window's top-left cell


#: Most template-cell products (floats) :func:`template_responses` holds at once: a level whose chunk of templates
#: would need more is scored in bands of cell rows. 2^25 (128 MB of float32) is above every level of a KITTI frame
#: (at most 772 x 28,830 at scale 2), which is scored whole as before; a 4K frame's scale-2 level needed 1.7 GB.
MAX_PRODUCTS = 1 << 25


def template_responses(bank: DetectorBank, pyramid, *, min_height: float = 30.0, max_height: float = 2000.0,
                       chunk_cols: int = 800, detectors=None, max_products: int = MAX_PRODUCTS):
    """Yield ``(t, level, scale, R)``: the response map ``R`` ``(Hr, Wr)`` (float32, bias
    included; entry ``(r, q)`` scores the window whose top-left cell is ``(r, q)``) of every
    template ``t`` at every pyramid level where the full object it implies is
    ``min_height..max_height`` px high. Per level and chunk of templates ONE matrix product
    of the cell features with all their template cells, then shifted sums: the bias plus
    every cell's product in the cell order, added one after the other in float32 (one
    reduction along the first axis of a copy of the shifted products, which numpy sums row
    after row -- pairwise summation is only along a contiguous axis -- so the same additions
    in the same order as a loop of in-place adds, without a numpy call per cell).

    A level whose products would exceed ``max_products`` floats (:data:`MAX_PRODUCTS`; a
    large image's finest levels) is scored in bands of response rows, each from the cell
    rows its windows cover: the same products and additions per window, the products' memory
    bounded whatever the image's size (the group's maps, at most a chunk of templates', are
    kept until its last band).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> pyramid = bank_pyramid(bank, np.zeros((64, 96, 3), np.uint8))
    >>> t, level, scale, R = next(template_responses(bank, pyramid))  # the first map of all
    >>> (th, tw), (Hc, Wc, _) = bank.configs[t].template, pyramid[level][1].shape
    >>> R.shape == (Hc - th + 1, Wc - tw + 1), R.dtype.name  # a score per window position
    (True, 'float32')
    >>> banded = {(t, li): R for t, li, _, R in template_responses(bank, pyramid, max_products=1)}
    >>> all(R.tobytes() == banded[(t, li)].tobytes() for t, li, _, R in template_responses(bank, pyramid))
    True
    """
    dets = range(len(bank)) if detectors is None else detectors
    buf = np.empty(0, np.float32)  # the products' memory, reused: a fresh one per level cost page faults
    stack = np.empty(0, np.float32)  # a template's shifted products, reused likewise
    for li, (s, F) in enumerate(pyramid):
        Hc, Wc = F.shape[:2]
        active = []
        for t in dets:
            c = bank.configs[t]
            th, tw = c.template
            full_h = th * CELL / s / max(float(c.frac[1]), 1e-3)
            if th <= Hc and tw <= Wc and min_height <= full_h <= max_height:
                active.append(t)
        if not active:
            continue
        i = 0
        while i < len(active):
            group, cols = [], 0
            while i < len(active) and (not group or cols + np.prod(bank.configs[active[i]].template) <= chunk_cols):
                group.append(active[i])
                cols += int(np.prod(bank.configs[active[i]].template))
                i += 1
            W = np.concatenate([bank.weights[t].reshape(-1, N_FEAT) for t in group], 0)  # (M, 31)
            dtype = np.result_type(W, F)
            reach = max(bank.configs[t].template[0] for t in group) - 1  # cell rows a band reads below its last
            # response rows a band: all of them when the level's products fit, else as many as max_products allows
            rows = Hc if len(W) * Hc * Wc <= max_products else max(1, max_products // (len(W) * Wc) - reach)
            maps = {t: (np.empty((Hc - bank.configs[t].template[0] + 1, Wc - bank.configs[t].template[1] + 1),
                                 np.float32) if rows < Hc else None) for t in group}
            for r0 in range(0, Hc - min(bank.configs[t].template[0] for t in group) + 1, rows):
                hb = min(Hc, r0 + rows + reach) - r0  # the band's cell rows
                Fm = F[r0:r0 + hb].reshape(-1, N_FEAT)
                if buf.size < len(W) * len(Fm) or buf.dtype != dtype:
                    buf = P = Pt = None  # (the old products and their views freed first: not both at once)
                    buf = np.empty(len(W) * len(Fm), dtype)
                P = np.matmul(W, Fm.T, out=buf[:len(W) * len(Fm)].reshape(len(W), len(Fm))).reshape(-1, hb, Wc)
                o = 0
                for t in group:
                    th, tw = bank.configs[t].template
                    Hr, Wr = min(Hc - th + 1 - r0, rows), Wc - tw + 1  # this band's response rows
                    Pt, o = P[o:o + th * tw, :Hr + th - 1], o + th * tw
                    if Hr <= 0:
                        continue
                    if P.dtype == np.float32 and Hr * Wr == 1 and maps[t] is not None and Hc - th + 1 > 1:
                        # a band of one window: numpy would sum its contiguous products pairwise, the whole map row
                        # after row
                        stack = _shifted_products(Pt, th, tw, stack)
                        R = np.full((1, 1), bank.biases[t], np.float32)
                        for k in range(th * tw):
                            R += stack[k]
                    elif P.dtype == np.float32:
                        stack = _shifted_products(Pt, th, tw, stack)
                        R = np.add.reduce(stack[:th * tw * Hr * Wr].reshape(th * tw, Hr, Wr), axis=0,
                                          initial=np.float32(bank.biases[t]))
                    else:  # (float64 products, e.g. weights not yet stored: rounded to float32 after every add)
                        R = np.full((Hr, Wr), bank.biases[t], np.float32)
                        for dy in range(th):
                            for dx in range(tw):
                                R += Pt[dy * tw + dx, dy:dy + Hr, dx:dx + Wr]
                    if maps[t] is None:
                        yield t, li, s, R
                    else:
                        maps[t][r0:r0 + Hr] = R
            for t in group:
                if maps[t] is not None:
                    yield t, li, s, maps[t]


def _shifted_products(P: np.ndarray, th: int, tw: int, stack: np.ndarray) -> np.ndarray:
    """Write ``P[dy * tw + dx, dy:dy + Hr, dx:dx + Wr]`` for the ``th x tw`` cells of a
    template, in that order, to the front of ``stack`` (grown if need be; returned): one
    copy from a strided view of the products ``P`` ``(th * tw, Hc, Wc)`` of its cells."""
    n, Hc, Wc = P.shape
    Hr, Wr = Hc - th + 1, Wc - tw + 1
    if stack.size < n * Hr * Wr or stack.dtype != P.dtype:
        stack = np.empty(n * Hr * Wr, P.dtype)
    a, b, c = P.strides
    # element (dy, dx, r, q) of the view: P[dy * tw + dx, dy + r, dx + q]
    shifted = np.lib.stride_tricks.as_strided(P, (th, tw, Hr, Wr), (tw * a + b, a + c, b, c), writeable=False)
    stack[:n * Hr * Wr].reshape(th, tw, Hr, Wr)[...] = shifted
    return stack


def score_pyramid(bank: DetectorBank, pyramid, *, threshold: float = -1.0, top_k: int = 200,
                  min_height: float = 30.0, max_height: float = 2000.0, chunk_cols: int = 800,
                  detectors=None, pad_cells: int = 0, responses: dict | None = None) -> Activations:
    """Apply every template to every pyramid level where the full object it implies is
    ``min_height..max_height`` px high (:func:`template_responses`). Keeps per detector
    and level the ``top_k`` windows scoring above ``threshold``. ``pad_cells`` columns of
    empty cells left and right of every level (:func:`pad_pyramid`) let windows reach past
    the image's sides (cars it truncates) while at least half of each stays inside
    (:func:`half_inside`); their boxes keep image coordinates and ``cell`` the padded grid's.
    ``responses`` (a dict), where given, receives every response map ``R`` as ``{(t, level): R}``
    over the windows inside the unpadded level (entry ``(r, q)``: the window whose top-left
    cell is ``(r, q)``), for the box rule to read
    (:func:`wirescene.predetect.box_viewpoints.box_bin_log_odds`).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> pyramid = bank_pyramid(bank, np.zeros((64, 96, 3), np.uint8))
    >>> act = score_pyramid(bank, pyramid, threshold=-np.inf, top_k=5, detectors=[0])  # template 0's best 5
    >>> act.boxes.shape, bool(np.all(act.det == 0))
    ((5, 4), True)
    """
    out = {k: [] for k in ("det", "boxes", "scores", "level", "cell")}
    pyramid = pad_pyramid(pyramid, pad_cells)
    for t, li, s, R in template_responses(bank, pyramid, min_height=min_height, max_height=max_height,
                                          chunk_cols=chunk_cols, detectors=detectors):
        th, tw = bank.configs[t].template
        Wr = R.shape[1]
        if responses is not None:  # (windows wholly inside: never masked below)
            responses[(t, li)] = R[:, pad_cells:Wr - pad_cells]
        if pad_cells:
            R[:, ~half_inside(np.arange(Wr), tw, R.shape[1] + tw - 1 - 2 * pad_cells, pad_cells)] = -np.inf
        flat = R.ravel()
        idx = np.flatnonzero(flat > threshold)
        if len(idx) > top_k:
            idx = idx[np.argpartition(-flat[idx], top_k - 1)[:top_k]]
        if not len(idx):
            continue
        r, q = np.divmod(idx, Wr)
        boxes = np.stack([(q - pad_cells) * CELL, r * CELL, (q - pad_cells + tw) * CELL, (r + th) * CELL], 1) / s
        out["det"].append(np.full(len(idx), t))
        out["boxes"].append(boxes)
        out["scores"].append(flat[idx].astype(float))
        out["level"].append(np.full(len(idx), li))
        out["cell"].append(np.stack([r, q], 1))
    if not out["det"]:
        return Activations(np.zeros(0, int), np.zeros((0, 4)), np.zeros(0), np.zeros(0, int), np.zeros((0, 2), int))
    return Activations(*(np.concatenate(out[k]) for k in ("det", "boxes", "scores", "level", "cell")))


def pad_pyramid(pyramid, pad_cells: int) -> list:
    """``pyramid`` with ``pad_cells`` columns of empty cells left and right of every level
    (windows past the image's sides; DPM's padding), unchanged for 0.

    Examples
    --------
    >>> levels = [(1.0, np.zeros((16, 24, 31), np.float32))]
    >>> pad_pyramid(levels, 2)[0][1].shape  # two empty cell columns on each side
    (16, 28, 31)
    """
    if not pad_cells:
        return list(pyramid)
    return [(s, np.pad(F, ((0, 0), (pad_cells, pad_cells), (0, 0)))) for s, F in pyramid]


def half_inside(q, tw: int, wc: int, pad_cells: int) -> np.ndarray:
    """Whether windows ``tw`` cells wide whose first column is ``q`` in a level ``wc``
    cells wide padded by ``pad_cells`` keep at least half their columns in the image (a
    window mostly in the padding scores its bias, whatever the image shows).

    Examples
    --------
    >>> half_inside([0, 10, 11], tw=4, wc=10, pad_cells=2)  # window columns -2..1, 8..11 and 9..12 of 0..9
    array([ True,  True, False])
    """
    q = np.asarray(q) - pad_cells
    inside = np.minimum(q + tw, wc) - np.maximum(q, 0)
    return 2 * inside >= tw


def nms(boxes: np.ndarray, scores: np.ndarray, iou: float = 0.5, max_keep: int | None = None) -> np.ndarray:
    """Greedy non-maximum suppression; indices kept, best first.

    Examples
    --------
    >>> boxes = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [20, 0, 30, 10]], float)
    >>> nms(boxes, [0.5, 0.9, 0.7])  # box 0 overlaps the better box 1 at IoU 0.82
    array([1, 2])
    >>> nms(boxes, [0.5, 0.9, 0.7], max_keep=1)
    array([1])
    """
    order = np.argsort(-np.asarray(scores), kind="stable")
    keep = []
    x1, y1, x2, y2 = np.asarray(boxes, float).reshape(-1, 4).T
    area = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    while len(order):
        i = order[0]
        keep.append(i)
        if max_keep is not None and len(keep) >= max_keep:
            break
        rest = order[1:]
        # core.boxes.iou_2d of box i and the rest, operation for operation, the areas computed once
        iw = np.clip(np.minimum(x2[i], x2[rest]) - np.maximum(x1[i], x1[rest]), 0, None)
        ih = np.clip(np.minimum(y2[i], y2[rest]) - np.maximum(y1[i], y1[rest]), 0, None)
        inter = iw * ih
        union = area[i] + area[rest] - inter
        overlap = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
        order = rest[overlap <= iou]
    return np.array(keep, int)


# --------------------------------------------------------------------------- clustering


def _box_dist(a: np.ndarray, b: np.ndarray, rx: float, ry: float, rs: float) -> np.ndarray:
    """Distance in (x, y, scale) between boxes ``a`` and ``b`` ``(..., 4)`` (broadcasting);
    'nearby' means < 1."""
    (cxa, cya, wa, ha, lsa), (cxb, cyb, wb, hb, lsb) = _box_terms(a), _box_terms(b)
    mw, mh = (wa + wb) / 2, (ha + hb) / 2
    d = np.maximum(np.abs(cxa - cxb) / (rx * mw), np.abs(cya - cyb) / (ry * mh))
    return np.maximum(d, np.abs(lsa - lsb) / rs)


def _box_terms(b: np.ndarray):
    """Centre, size and log scale of boxes ``(..., 4)``: what :func:`_box_dist` compares."""
    cx, cy = (b[..., 0] + b[..., 2]) / 2, (b[..., 1] + b[..., 3]) / 2
    w, h = np.maximum(b[..., 2] - b[..., 0], 1e-6), np.maximum(b[..., 3] - b[..., 1], 1e-6)
    return cx, cy, w, h, 0.5 * np.log(w * h)


def cluster_activations(boxes, scores, bins, *, rx: float = 0.4, ry: float = 0.4, rs: float = 0.4,
                        box_weight: float = 0.0):
    """Recursive agglomerative clustering of predicted full-object boxes (paper Sec. 3.4).

    Within each viewpoint bin, repeatedly merge the two nearest clusters while their
    distance in (x, y, scale) is below 1 (centre offsets below ``rx`` / ``ry`` of the mean
    width / height and log-scale difference below ``rs``; the defaults were chosen on
    held-out synthetic scenes, 0.25 gave ~5-10 AP points less). A cluster's box is the average
    of its members' box corners (weighted by ``exp(box_weight * score)``: 0 = plain mean),
    its score the highest member score. Different viewpoints are never merged.

    Returns ``(boxes (C, 4), scores (C,), bins (C,), support (C,))``.

    Examples
    --------
    >>> boxes = [[0, 0, 100, 50], [4, 2, 104, 52], [0, 0, 100, 50]]
    >>> out, scores, bins, support = cluster_activations(boxes, [1.0, 2.0, 0.5], [3, 3, 5])
    >>> out  # the two votes of bin 3 merged into their mean box; bin 5's alone
    array([[  2.,   1., 102.,  51.],
           [  0.,   0., 100.,  50.]])
    >>> scores, bins, support  # a cluster's best vote, its bin, its number of votes
    (array([2. , 0.5]), array([3, 5]), array([2., 1.]))
    """
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    scores = np.asarray(scores, float).reshape(-1)
    bins = np.asarray(bins, int).reshape(-1)
    ob, os_, obin, osup = [], [], [], []
    for b in np.unique(bins):
        sel = np.flatnonzero(bins == b)
        w = np.exp(box_weight * (scores[sel] - scores[sel].max())) if box_weight else np.ones(len(sel))
        sums, cnt, sc = boxes[sel] * w[:, None], np.ones(len(sel)), scores[sel].copy()
        wsum = w.copy()
        mean = boxes[sel].copy()
        alive = np.ones(len(sel), bool)
        D = _box_dist(mean[:, None], mean[None], rx, ry, rs)
        np.fill_diagonal(D, np.inf)
        while len(sel) > 1:
            k = int(np.argmin(D))
            i, j = divmod(k, len(sel))
            if not D[i, j] < 1.0:
                break
            sums[i] += sums[j]
            cnt[i] += cnt[j]
            wsum[i] += wsum[j]
            sc[i] = max(sc[i], sc[j])
            mean[i] = sums[i] / wsum[i]
            alive[j] = False
            D[j, :] = D[:, j] = np.inf
            d = _box_dist(mean[i], mean, rx, ry, rs)  # the merged cluster's row only
            d[~alive] = np.inf
            d[i] = np.inf
            D[i, :] = D[:, i] = d
        ob.append(mean[alive])
        os_.append(sc[alive])
        obin.append(np.full(int(alive.sum()), b))
        osup.append(cnt[alive])
    if not ob:
        return np.zeros((0, 4)), np.zeros(0), np.zeros(0, int), np.zeros(0)
    return np.concatenate(ob), np.concatenate(os_), np.concatenate(obin), np.concatenate(osup)


# --------------------------------------------------------------------------- detection


def detect_cars(image: np.ndarray, *, bank: DetectorBank | None = None, threshold: float | None = None,
                max_scale: float | None = None, per_octave: int | None = None, min_height: float | None = None,
                min_scale: float | None = None, per_detector: int | None = None, cross_view_nms: float | None = 0.3,
                source: str = "bank",
                return_all: bool = False, camera=None, pyramid: list | None = None,
                verify_within: float | None = None, responses: dict | None = None,
                mount: Mount = KITTI_MOUNT) -> Detections:
    """Detect cars in an (H, W, 3) uint8 image with the configuration bank.

    HOG pyramid once -> every template as a linear filter -> NMS per detector (IoU 0.5 on
    configuration boxes, best ``per_detector`` kept) -> predicted full-object boxes ->
    agglomerative clustering per viewpoint -> optional NMS across viewpoints (IoU
    ``cross_view_nms``; None to skip) -> clusters scoring above ``threshold`` (default:
    the bank's). ``alpha`` is the centre of the viewpoint bin of the detector(s).

    Scores are the bank's calibrated confidences (probability of a car, see
    :meth:`DetectorBank.confidence`) when it carries a calibration, else SVM margins;
    ``threshold`` is in the same units. ``max_scale``, ``per_octave`` (pyramid levels per
    octave) and ``min_height`` (smallest full-car height searched, px) default to the values
    the bank was trained with (2.0, 4, 30 for banks that do not say); ``min_scale``: the
    pyramid's coarsest level (:func:`bank_scales`); ``per_detector`` (the
    windows each template keeps after its own suppression) to ``meta["per_detector"]`` (30).

    ``camera`` (a :class:`~wirescene.core.camera.Camera`): when given and the bank carries a
    ground prior (``meta["ground_prior"]``, :mod:`wirescene.predetect.geometry`), every
    detection's score also weighs how well its box's height fits its position below the
    horizon; banks trained on KITTI were calibrated with this term, so pass the camera
    whenever it is known. With a viewpoint prior (``meta["viewpoint_prior"]``) the camera
    also lets each detection's viewpoint weigh where it stands in the traffic
    (:mod:`wirescene.predetect.viewpoint_prior`); both priors were learned at KITTI's camera
    height and level mount, ``mount`` is the camera's
    (:class:`~wirescene.core.groundplane.Mount`; :func:`~wirescene.predetect.geometry.road_horizon`). ``pyramid``: the image's
    :func:`bank_pyramid` if already computed (e.g. to score given boxes' viewpoints on it too).
    ``verify_within``: see :func:`merge_activations` (off by default; ``benchmarks/RESULTS.md``,
    "An early cut before the box refinement and the verifier"). ``responses``: a dict to receive
    the templates' response maps (:func:`score_pyramid`), which the box rule then reads instead
    of computing them again."""
    bank = load_default_bank() if bank is None else bank
    min_height = float(bank.meta.get("min_height", 30.0)) if min_height is None else min_height
    thr = bank.threshold if threshold is None else float(threshold)
    image = np.asarray(image)
    if image.ndim not in (2, 3) or min(image.shape[:2]) < MIN_IMAGE_SIDE:
        raise InputError(f"expected an (H, W, 3) image, got shape {image.shape}")
    H, W = image.shape[:2]
    if pyramid is None:
        pyramid = bank_pyramid(bank, image, max_scale=max_scale, per_octave=per_octave, min_scale=min_scale)
    gray = None if bank.refinement is None and bank.verifier is None else to_gray(image)
    channels = integral_channels(image) if bank.needs_channels else None
    horizon = None if camera is None else road_horizon(camera, mount)
    center_column = None if camera is None else float(np.asarray(camera.K, float)[0, 2])
    return detect_pyramid(bank, pyramid, (W, H), threshold=None if return_all else thr, min_height=min_height,
                          per_detector=per_detector, cross_view_nms=cross_view_nms, source=source, horizon=horizon,
                          center_column=center_column, gray=gray, channels=channels, verify_within=verify_within,
                          responses=responses)


def bank_scales(bank: DetectorBank, width: int, height: int, *, max_scale: float | None = None,
                per_octave: int | None = None, min_scale: float | None = None) -> list[float]:
    """Pyramid scales of a ``width x height`` image at the levels the bank was trained with
    (``meta["max_scale"]``, ``meta["per_octave"]``; 2.0 and 4 for banks that do not say),
    unless ``max_scale`` / ``per_octave`` are given, down to ``min_scale`` (None: to
    :func:`~wirescene.predetect.hog.pyramid_scales`' smallest).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> np.round(bank_scales(bank, 1242, 375, max_scale=2.0, per_octave=4)[:3], 3)  # 2 ** (-k / 4) from 2x
    array([2.   , 1.682, 1.414])
    >>> bank_scales(bank, 1242, 375)[0] == bank.meta["max_scale"]  # the levels the bank was trained with
    True
    >>> np.round(bank_scales(bank, 1242, 375, min_scale=1.5), 3)  # the finest levels only
    array([2.   , 1.782, 1.587])
    """
    max_scale = float(bank.meta.get("max_scale", 2.0)) if max_scale is None else max_scale
    per_octave = int(bank.meta.get("per_octave", 4)) if per_octave is None else per_octave
    lowest = {} if min_scale is None else {"min_scale": float(min_scale)}
    return pyramid_scales(width, height, max_scale=max_scale, per_octave=per_octave, **lowest)


#: The smallest car (px) a search may be asked to reach: 10 px upsamples a KITTI frame 5x (6.6 s, 0.9 GB), 2 px
#: would need 25x and some 40 GB.
MIN_SMALLEST_CAR = 10.0


def smallest_car_search(bank: DetectorBank, smallest_car: float | None) -> tuple[float | None, float | None]:
    """``(min_height, max_scale)`` of :func:`detect_cars` and :func:`bank_pyramid` that search cars
    down to ``smallest_car`` px (None or 0: the bank's own): the same templates on finer levels,
    a car that high fitting the smallest.

    Examples
    --------
    >>> from wirescene.predetect import load_default_bank
    >>> smallest_car_search(load_default_bank(), 12.5)  # the shipped bank: 25 px at 2x
    (12.5, 4.0)
    >>> smallest_car_search(load_default_bank(), 0)
    (None, None)
    """
    if not smallest_car:
        return None, None
    if not np.isfinite(smallest_car) or smallest_car < MIN_SMALLEST_CAR:
        raise ArgumentError("smallest_car", f"expected 0 (the bank's own) or at least {MIN_SMALLEST_CAR:g} px, "
                                            f"got {smallest_car!r}")
    min_height = float(smallest_car)
    return min_height, float(bank.meta.get("max_scale", 2.0)) * float(bank.meta.get("min_height", 30.0)) / min_height


def bank_pyramid(bank: DetectorBank, image: np.ndarray, *, max_scale: float | None = None,
                 per_octave: int | None = None, min_scale: float | None = None) -> list[tuple[float, np.ndarray]]:
    """The HOG :func:`~wirescene.predetect.hog.feature_pyramid` of ``image`` at the bank's
    levels (:func:`bank_scales`, with its ``max_scale`` / ``per_octave`` / ``min_scale``):
    what :func:`detect_cars` computes, to share with the box rule
    (:func:`wirescene.predetect.box_viewpoints.box_bin_log_odds`).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> pyramid = bank_pyramid(bank, np.zeros((64, 96, 3), np.uint8))
    >>> [s for s, _ in pyramid] == bank_scales(bank, 96, 64)
    True
    >>> scale, F = pyramid[0]
    >>> F.shape == (round(64 * scale) // 8, round(96 * scale) // 8, 31)  # 8-px cells of the resized image
    True
    """
    H, W = np.asarray(image).shape[:2]
    return feature_pyramid(image, bank_scales(bank, W, H, max_scale=max_scale, per_octave=per_octave,
                                              min_scale=min_scale))


def cluster_options(bank: DetectorBank) -> dict:
    """Clustering options stored with the bank (``meta["box_weight"]``, old banks: plain
    means; ``meta["cluster_rx" | "cluster_ry" | "cluster_rs"]`` where set, else
    :func:`cluster_activations`' radii).

    Examples
    --------
    >>> bank = DetectorBank([], [], np.zeros(0), meta={"box_weight": 2.0, "cluster_rx": 0.2, "cluster_ry": 0.2})
    >>> cluster_options(bank)
    {'box_weight': 2.0, 'rx': 0.2, 'ry': 0.2}
    >>> cluster_options(DetectorBank([], [], np.zeros(0)))  # an old bank: plain means, the default radii
    {'box_weight': 0.0}
    """
    kw = {"box_weight": float(bank.meta.get("box_weight", 0.0))}
    kw.update({k: float(bank.meta[f"cluster_{k}"]) for k in ("rx", "ry", "rs") if f"cluster_{k}" in bank.meta})
    return kw


def detect_pyramid(bank: DetectorBank, pyramid, image_size, *, threshold: float | None = None,
                   calibrated: bool = True, min_height: float = 30.0, per_detector: int | None = None,
                   cross_view_nms: float | None = 0.3, source: str = "bank",
                   horizon: float | Horizon | None = None, center_column: float | None = None,
                   gray: np.ndarray | None = None, channels: np.ndarray | None = None,
                   verify_within: float | None = None, responses: dict | None = None) -> Detections:
    """:func:`detect_cars` on a precomputed feature pyramid of an image of ``image_size``
    ``(W, H)``; ``threshold`` (None: keep all) in the units of the returned scores
    (``calibrated``: :meth:`DetectorBank.confidence`, else raw margins); ``horizon``: image
    row of the horizon for the ground-plane consistency term (None: none);
    ``center_column``: column of the principal point, for the viewpoint prior (None: none);
    ``gray``: the ``(H, W)`` float grey image, for the bank's box refinement and verifier
    (None: neither); ``channels``: the image's
    :func:`~wirescene.predetect.channels.integral_channels`, for a verifier that reads them
    (:attr:`DetectorBank.needs_channels`). A bank's ``meta["pad_cells"]`` (default 0: banks
    trained with windows inside the image) lets windows reach past the image's sides
    (:func:`score_pyramid`; ``train_bank_on_frames(pad_cells=)``). ``responses``: a dict to
    receive the templates' response maps (:func:`score_pyramid`)."""
    raw_thr = raw_threshold(bank, threshold, calibrated=calibrated)
    clusters = pyramid_clusters(bank, pyramid, image_size, threshold=raw_thr, min_height=min_height,
                                per_detector=per_detector, responses=responses)
    return finish_clusters(clusters, bank, image_size, threshold=raw_thr, calibrated=calibrated,
                           cross_view_nms=cross_view_nms, source=source, horizon=horizon,
                           center_column=center_column, gray=gray, channels=channels, verify_within=verify_within)


def raw_threshold(bank: DetectorBank, threshold: float | None, *, calibrated: bool = True) -> float | None:
    """``threshold`` in margin units (None stays None): :meth:`DetectorBank.margin_of` of a
    calibrated one.

    Examples
    --------
    >>> bank = load_default_bank()
    >>> round(float(bank.confidence(raw_threshold(bank, 0.7))), 6), raw_threshold(bank, 0.7, calibrated=False)
    (0.7, 0.7)
    """
    return None if threshold is None else (bank.margin_of(threshold) if calibrated else float(threshold))


def pyramid_clusters(bank: DetectorBank, pyramid, image_size, *, threshold: float | None = None,
                     min_height: float = 30.0, per_detector: int | None = None,
                     responses: dict | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first half of :func:`detect_pyramid`: the templates' activations on ``pyramid``
    (:func:`score_pyramid`, down to a margin floor below ``threshold``, in margin units) and
    their votes clustered into cars (:func:`vote_clusters`). They depend only on the
    templates and on the bank's clustering options, so a training pass that changes only
    the steps after them can reuse them (:func:`finish_clusters`)."""
    H = image_size[1]
    floor = min(threshold if threshold is not None else -0.5, -0.5) - 0.5
    act = score_pyramid(bank, pyramid, threshold=floor, min_height=min_height, max_height=3.0 * H,
                        pad_cells=int(bank.meta.get("pad_cells", 0)), responses=responses)
    return vote_clusters(act, bank, per_detector=per_detector, cluster_kw=cluster_options(bank))


def merge_activations(act: Activations, bank: DetectorBank, image_size, *, threshold: float | None,
                      per_detector: int | None = None, cross_view_nms: float | None = 0.3, source: str = "bank",
                      cluster_kw: dict | None = None, horizon: float | Horizon | None = None,
                      center_column: float | None = None, gray: np.ndarray | None = None,
                      channels: np.ndarray | None = None, verify_within: float | None = None) -> Detections:
    """Activations -> Detections: NMS per detector, full-box votes, clustering per
    viewpoint (a cluster's score: its best vote, plus ``meta["support_weight"]`` times the log of
    its number of votes where a bank sets it), clip to image, box regression, box refinement from the grey image ``gray``
    (None: none; :mod:`wirescene.predetect.refine`), the verifier's second look at each box
    (with ``gray`` and, where it reads them, ``channels``; :func:`verification_logits` times its
    calibrated gain), ground-plane consistency (``horizon``: the
    image row of the horizon, None to skip; :func:`ground_margin`), optional NMS across
    viewpoints with each kept detection's viewpoint chosen by :func:`traffic_viewpoints`
    (``center_column``: the principal point's column, None to keep the winner's), threshold
    in margin units (None: keep all). ``verify_within`` (margin units; None: off): with a
    threshold, clusters more than this below it before the box refinement and the verifier
    are dropped first, sparing the two HOG crops each costs."""
    clusters = vote_clusters(act, bank, per_detector=per_detector, cluster_kw=cluster_kw)
    return finish_clusters(clusters, bank, image_size, threshold=threshold, calibrated=False,
                           cross_view_nms=cross_view_nms, source=source, horizon=horizon,
                           center_column=center_column, gray=gray, channels=channels, verify_within=verify_within)


def vote_clusters(act: Activations, bank: DetectorBank, *, per_detector: int | None = None,
                  cluster_kw: dict | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(boxes (C, 4), scores (C,), bins (C,))``: the first steps of :func:`merge_activations`
    (NMS per detector, full-box votes, clustering per viewpoint, the vote count)."""
    per_detector = int(bank.meta.get("per_detector", 30)) if per_detector is None else int(per_detector)
    fb, fs, fbin = [], [], []
    for t in np.unique(act.det):
        sel = np.flatnonzero(act.det == t)
        keep = sel[nms(act.boxes[sel], act.scores[sel], 0.5, per_detector)]
        fb.append(bank.configs[t].full_box(act.boxes[keep]))
        fs.append(act.scores[keep])
        fbin.append(np.full(len(keep), bank.configs[t].bin))
    if fb:
        boxes, scores, bins, support = cluster_activations(np.concatenate(fb), np.concatenate(fs),
                                                           np.concatenate(fbin), **(cluster_kw or {}))
        # a cluster many votes agree on: margin units per e-fold of its votes (banks without the key: 0)
        scores = scores + float(bank.meta.get("support_weight", 0.0)) * np.log(support)
    else:
        boxes, scores, bins = np.zeros((0, 4)), np.zeros(0), np.zeros(0, int)
    return boxes, scores, bins


def finish_clusters(clusters, bank: DetectorBank, image_size, *, threshold: float | None,
                    calibrated: bool = False, cross_view_nms: float | None = 0.3, source: str = "bank",
                    horizon: float | Horizon | None = None, center_column: float | None = None,
                    gray: np.ndarray | None = None, channels: np.ndarray | None = None,
                    verify_within: float | None = None) -> Detections:
    """The rest of :func:`merge_activations` on the vote ``clusters`` of
    :func:`vote_clusters` (or :func:`pyramid_clusters`): clip, box regression, refinement,
    verifier, ground term, suppression across viewpoints, ``threshold`` (margin units);
    ``calibrated``: the returned scores are the bank's calibrated confidences (where it
    has a calibration).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> boxes = np.array([[100.0, 150, 220, 220], [105, 152, 225, 222], [400, 160, 460, 200]])
    >>> clusters = boxes, np.array([1.5, 0.5, -3.0]), np.array([2, 6, 0])  # margins, viewpoint bins
    >>> found = finish_clusters(clusters, bank, (1242, 375), threshold=bank.margin_of(0.5), calibrated=True)
    >>> len(found), found.alpha.round(4)  # bin 6's box suppressed, the third too weak; bin 2's centre
    (1, array([1.5708]))
    >>> bool(np.isclose(found.scores[0], bank.confidence(1.5)))  # no image: no verifier nor ground term
    True
    """
    W, H = image_size
    boxes, scores, bins = clusters
    if threshold is not None and verify_within is not None:
        near = scores >= threshold - verify_within
        boxes, scores, bins = boxes[near], scores[near], bins[near]
    if len(boxes):
        boxes = clip_boxes(boxes, W, H)
        if "box_regression" in bank.meta:
            boxes = clip_boxes(apply_box_regression(bank.meta["box_regression"], boxes, bins, (W, H)), W, H)
        if bank.refinement is not None and gray is not None:
            boxes = clip_boxes(apply_box_refinement(bank.refinement, gray, boxes,
                                                    regression_features(boxes, bins, (W, H))), W, H)
        ok = (boxes[:, 2] - boxes[:, 0] >= 2) & (boxes[:, 3] - boxes[:, 1] >= 2)
        boxes, scores, bins = boxes[ok], scores[ok], bins[ok]
        if bank.verifier is not None and gray is not None and float(bank.verifier["gain"]):
            # before the suppression: which of two overlapping boxes survives is most of its gain
            scores = scores + float(bank.verifier["gain"]) * verification_logits(bank, gray, boxes, bins,
                                                                                   channels=channels)
        if horizon is not None:
            scores = scores + ground_margin(bank, boxes, horizon)
    if cross_view_nms is not None and len(boxes):
        keep = nms(boxes, scores, cross_view_nms)
        kept_bins = bins[keep]
        if horizon is not None and center_column is not None:
            kept_bins = traffic_viewpoints(bank, boxes[keep], kept_bins, (boxes, scores, bins), horizon, center_column,
                                           iou=cross_view_nms)
        boxes, scores, bins = boxes[keep], scores[keep], kept_bins
    if threshold is not None:
        sel = scores > threshold
        boxes, scores, bins = boxes[sel], scores[sel], bins[sel]
    order = np.argsort(-scores, kind="stable")
    boxes, scores, bins = boxes[order], scores[order], bins[order]
    if calibrated and bank.calibration is not None:
        scores = bank.confidence(scores)
    return Detections(boxes, scores, bin_center(bins) if len(bins) else np.zeros(0), source)


def verification_logits(bank: DetectorBank, gray: np.ndarray, boxes, bins, *,
                        channels: np.ndarray | None = None) -> np.ndarray:
    """``(D,)`` log-odds of the bank's verifier (:mod:`wirescene.predetect.verifier`) that
    ``boxes`` ``(D, 4)`` of viewpoint ``bins`` ``(D,)`` in the grey ``(H, W)`` float image
    show a car; zeros for a bank without one. A verifier that reads colour
    (:attr:`DetectorBank.needs_channels`) needs the image's ``channels``
    (:func:`~wirescene.predetect.channels.integral_channels`).

    Examples
    --------
    >>> from wirescene.predetect.channels import integral_channels
    >>> image = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    >>> bank = load_default_bank()
    >>> logits = verification_logits(bank, to_gray(image), [[10, 10, 70, 40], [20, 5, 90, 60]], [0, 2],
    ...                              channels=integral_channels(image))  # this bank's verifier reads colour
    >>> logits.shape, bool(np.isfinite(logits).all())
    ((2,), True)
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    if bank.verifier is None or not len(b):
        return np.zeros(len(b))
    if bank.needs_channels and channels is None:
        raise ValueError("this bank's verifier reads the image's colour channels: pass channels=integral_channels(image)")
    H, W = gray.shape
    bins = np.asarray(bins, int).reshape(len(b))
    features = verifier_features(gray, b, regression_features(b, bins, (W, H)),
                                 channels=channels if bank.needs_channels else None)
    return verifier_logits(bank.verifier, features, groups=VIEW_GROUPS[bins % 8])


def ground_margin(bank: DetectorBank, boxes, horizon: float | Horizon) -> np.ndarray:
    """``(D,)`` margin added to detections ``boxes`` by the bank's ground prior: the log
    ratio of :func:`wirescene.predetect.geometry.ground_log_ratio` divided by the Platt slope,
    so that the calibrated confidence is ``sigmoid(a * margin + b + log ratio)``. Zero for
    a bank without a ground prior, and for an uncalibrated one (its scores are SVM margins,
    on no scale a log ratio could be added to).

    Examples
    --------
    >>> boxes = [[500, 180, 600, 230], [500, 100, 600, 150]]  # standing 1.2 box heights below the horizon; above it
    >>> (ground_margin(load_default_bank(), boxes, 170.0) > 0).tolist()
    [True, False]
    """
    if bank.calibration is None:
        return np.zeros(len(boxes))
    return bank.ground_log_ratio(boxes, horizon) / float(bank.calibration[0])


def traffic_viewpoints(bank: DetectorBank, kept, kept_bins, clusters, horizon: float | Horizon, center_column: float, *,
                       iou: float) -> np.ndarray:
    """``(D,)`` viewpoint bins of the detections ``kept`` ``(D, 4)`` that survived the
    cross-view NMS (at IoU ``iou``) of ``clusters`` ``(boxes (C, 4), margins (C,), bins (C,))``:
    :func:`wirescene.predetect.viewpoint_prior.choose_viewpoints` with the bank's viewpoint
    prior at each box's lateral position. ``kept_bins`` (the winners' own bins) unchanged
    for a bank without that prior or without a calibration (margins of different
    viewpoints' templates are only comparable as calibrated log-odds).

    Examples
    --------
    >>> bank = load_default_bank()
    >>> def facing(x1):  # a front view (bin 2) scoring a little above a back view (bin 6) of the same box
    ...     boxes = np.array([[x1, 180, x1 + 100, 230], [x1 + 2, 181, x1 + 101, 231]])
    ...     return traffic_viewpoints(bank, boxes[:1], [2], (boxes, np.array([0.2, 0.0]), np.array([2, 6])), 170.0,
    ...                               600.0, iou=0.3)
    >>> facing(700.0), facing(400.0)  # to the right of the camera traffic shows its back; to the left, fronts
    (array([6]), array([2]))
    """
    log_prior = traffic_log_prior(bank, kept, horizon, center_column) if len(kept) else None
    if log_prior is None:
        return np.asarray(kept_bins, int)
    boxes, margins, bins = clusters
    return choose_viewpoints(kept, boxes, float(bank.calibration[0]) * np.asarray(margins, float), bins, log_prior,
                             iou=iou)


def traffic_log_prior(bank: DetectorBank, boxes, horizon: float | Horizon, center_column: float) -> np.ndarray | None:
    """``(D, 8)`` log P(bin | lateral position) of ``boxes`` ``(D, 4)`` under the bank's
    viewpoint prior (:func:`wirescene.predetect.viewpoint_prior.viewpoint_log_prior`), or None
    for a bank without that prior or without a calibration (its margins are no log-odds the
    prior could be added to).

    Examples
    --------
    >>> prior = traffic_log_prior(load_default_bank(), [[700, 180, 800, 230]], 170.0, 600.0)
    >>> prior.shape, bool(np.isclose(np.exp(prior).sum(), 1.0))  # log P(bin | lateral position)
    ((1, 8), True)
    """
    prior = bank.meta.get("viewpoint_prior")
    if not prior or bank.calibration is None:
        return None
    return viewpoint_log_prior(prior, lateral_position(boxes, horizon, center_column))


# --------------------------------------------------------------------------- box regression

#: Names of the box-regression features (:func:`regression_features`), in order.
REGRESSION_FEATURES = ("1",) + tuple(f"bin{b}" for b in range(8)) + (
    "log_height", "log_aspect", "bottom", "at_left", "at_right")


def regression_features(boxes, bins, image_size) -> np.ndarray:
    """``(D, F)`` features of detection boxes ``(D, 4)`` (clipped to the image) for the
    box regression: a constant, the viewpoint bin (one-hot), log height (over 100 px),
    log aspect ratio, the bottom edge's height in the image, and whether the box touches
    the left or right image border (a truncated car, whose label box is clipped).

    Examples
    --------
    >>> f = regression_features([[0, 100, 50, 200]], [2], (1242, 375))  # 100 px high, at the left side
    >>> f.shape, dict(zip(REGRESSION_FEATURES[9:], f[0, 9:].round(3).tolist()))
    ((1, 14), {'log_height': 0.0, 'log_aspect': -0.693, 'bottom': 0.033, 'at_left': 1.0, 'at_right': 0.0})
    """
    W, H = image_size
    b = np.asarray(boxes, float).reshape(-1, 4)
    w, h = np.maximum(b[:, 2] - b[:, 0], 1.0), np.maximum(b[:, 3] - b[:, 1], 1.0)
    onehot = np.eye(8)[np.asarray(bins, int) % 8]
    return np.column_stack([np.ones(len(b)), onehot, np.log(h / 100.0), np.log(w / h), b[:, 3] / H - 0.5,
                            b[:, 0] <= 1.0, b[:, 2] >= W - 2.0]).astype(float)


def apply_box_regression(regression: dict, boxes, bins, image_size) -> np.ndarray:
    """Boxes ``(D, 4)`` moved by the linear box regression ``regression`` (``weights``
    ``(F, 4)``: each side's offset in units of the box width or height, DPM's bounding-box
    prediction), which maps the bank's cluster boxes -- averaged votes of the placed
    wireframe's box -- onto the labelled 2D boxes.

    Examples
    --------
    >>> weights = np.zeros((len(REGRESSION_FEATURES), 4))
    >>> weights[0] = [0.1, 0.0, -0.1, 0.0]  # the constant: both sides 10% of the width inwards
    >>> apply_box_regression({"weights": weights}, [[100, 100, 200, 150]], [0], (1242, 375))
    array([[110., 100., 190., 150.]])
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    if not len(b):
        return b
    weights = np.asarray(regression["weights"], float)
    t = regression_features(b, bins, image_size) @ weights  # (D, 4)
    w, h = b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]
    return b + t * np.column_stack([w, h, w, h])
