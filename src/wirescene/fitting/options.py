"""The options of a fit: those of our own pre-detection (:class:`PredetectOptions`) and of every
stage of :func:`~wirescene.fitting.pipeline.fit_frame` (:class:`FitOptions`), with the stages
``--set STAGE.FIELD`` reaches (:data:`STAGES`)."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace
from typing import Mapping

from wirescene.core.errors import ArgumentError
from wirescene.core.settings import option
from wirescene.infer.inference import InferenceOptions
from wirescene.lift import MAX_HYPOTHESES, LiftingOptions
from wirescene.predetect.bank import MIN_SMALLEST_CAR

#: Largest enlargement of ``PredetectOptions.upsample``: 3 makes a KITTI frame 9 times the pixels.
MAX_UPSAMPLE = 3.0


@dataclass(frozen=True)
class PredetectOptions:
    """Options of our own pre-detection as the fit uses it (stage 1), and of how the fit
    treats its boxes: their weight in the fine objective and their verification. How each
    default was chosen: ``benchmarks/RESULTS.md``.

    Examples
    --------
    >>> PredetectOptions()
    PredetectOptions(threshold=0.3, min_car_probability=0.5, box_weight=30.0, smallest_car=0.0, upsample=1.5)
    >>> FitOptions().with_settings({"predetect.threshold": "0.5"}).predetect.threshold
    0.5
    """

    # Below the bank's own 2D operating point (0.5): the fit verifies every box it is given.
    threshold: float = option(0.3, cli="detection-threshold",
                              help="Score threshold of our own pre-detection for the fit (the bank's calibrated "
                                   "probability of a car).")
    # The score calibration's car model on the detection score, the fit's objective and the box height.
    min_car_probability: float = option(0.5, maximum=1.0,
                                        help="Drop the fitted cars of our own pre-detection whose probability "
                                             "of standing on a car is below this (0: keep all).")
    # The bank's boxes miss the car's outline by more than labelled ones: the fine stage leans on them less.
    box_weight: float = option(30.0, cli="own-box-weight",
                               help="Weight of our own pre-detection's boxes in the fine objective (boxes from files "
                                    "or the API take the inference stage's --box-weight).")
    # Off: held out (upsample 1), 16.7 px gave 7 more true positives, 8 fewer cars within 1 m, 1.7x the time (RESULTS).
    smallest_car: float = option(0.0, minimum=MIN_SMALLEST_CAR, zero="the bank's own",
                                 help="Smallest car height (px) our own pre-detection searches, its pyramid "
                                      "upsampled to reach it, the enlarged image's too (--upsample; 0: the bank's "
                                      "own, 25 px, and the enlarged image's below it; at least 10).")
    # Held out on {0, 1}, where it was chosen: `full` 7 more true positives, 8 more within 1 m, 2 more false (RESULTS).
    upsample: float = option(1.5, minimum=1.0, maximum=MAX_UPSAMPLE,
                             help="Also detect our own cars on the image enlarged by this factor, 1 to 3 (Lanczos; "
                                  "up to a 4K frame's pixels), at its pyramid levels finer than the image's, adding "
                                  "the small, far cars the image as it is misses (2.3x the pre-detection's time at "
                                  "1.5; 1: none).")


@dataclass(frozen=True)
class FitOptions:
    """Options of every stage of :func:`~wirescene.fitting.pipeline.fit_frame`, with the run's seed.

    Examples
    --------
    >>> options = FitOptions()
    >>> options.seed, options.calibrate_scores, options.inference.iterations, options.parts_model  # None: shipped
    (0, True, 12, None)
    >>> from dataclasses import replace
    >>> replace(options, seed=3, lifting=replace(options.lifting, n_particles=20)).lifting.n_particles
    20
    """

    lifting: LiftingOptions = field(default_factory=LiftingOptions)
    inference: InferenceOptions = field(default_factory=InferenceOptions)
    predetect: PredetectOptions = field(default_factory=PredetectOptions)
    seed: int = 0
    # Write calibrated confidences (wirescene.fitting.confidence) as the cars' scores;
    # False keeps the pre-detection scores (used to collect the calibration's own data).
    calibrate_scores: bool = True
    # Part detector file (None: the shipped model), e.g. a cross-validation fold's model
    # so that real frames are scored by a model that never saw their drive.
    parts_model: str | None = None
    # Detector bank file for our own pre-detection (None: the shipped bank).
    detector_bank: str | None = None
    # Crop viewpoint classifier file for boxes given without a viewpoint (None: the shipped one).
    viewpoint_classifier: str | None = None
    # Score calibration file of the confidences and of the verification of our own boxes
    # (None: the shipped one), e.g. one of `wirescene train scores` on the user's own runs.
    score_calibration: str | None = None
    # Shape model file of the fine variants' wireframes (None: the shipped one), e.g. one of
    # `wirescene train shape` on other CAD cars.
    shape_model: str | None = None

    def with_settings(self, settings: Mapping[str, object] | None, *, combined: bool = True) -> "FitOptions":
        """These options with ``{"STAGE.FIELD": value}`` changed, ``STAGE`` one of
        :data:`STAGES` (``lifting``, ``inference``, ``predetect``): the mapping ``--set`` and the named
        options of ``eval`` / ``predict`` / ``fit`` and the API's ``settings`` share.
        String values are parsed as the field's type; an unknown stage or field is a
        ``ValueError`` naming what exists, and so are options that break a limit together
        (:meth:`combined_problem`; ``combined=False``: left to the caller).

        Examples
        --------
        >>> FitOptions().with_settings({"inference.box_weight": "50", "lifting.road_prior": 0}).inference.box_weight
        50.0
        """
        from wirescene.core.settings import replace_fields

        by_stage: dict[str, dict[str, object]] = {}
        for name, value in (settings or {}).items():
            stage, dot, key = name.partition(".") if isinstance(name, str) else ("", "", "")
            if not dot or stage not in STAGES:
                raise ValueError(f"{name!r}: settings are STAGE.FIELD, STAGE one of {', '.join(STAGES)}")
            by_stage.setdefault(stage, {})[key] = value
        changed = {stage: replace_fields(getattr(self, stage), values, scope=stage) for stage, values in by_stage.items()}
        out = replace(self, **changed)
        problem = out.combined_problem() if combined else None
        if problem is not None:
            raise ValueError(problem)
        return out

    def combined_problem(self) -> str | None:
        """What the stages' options break together, or None: more scene particles (those the
        plane grid holds) times fine-stage samples than :data:`~wirescene.lift.MAX_HYPOTHESES`,
        whose memory grows with both (some 9 kB a particle, car and sample).

        Examples
        --------
        >>> FitOptions().combined_problem() is None
        True
        >>> FitOptions(lifting=LiftingOptions(n_particles=1000, pitch_step=0.05),
        ...            inference=InferenceOptions(samples=60)).combined_problem()
        'lifting.n_particles x inference.samples = 1,000 x 60 = 60,000 hypotheses a car and iteration, at most 50,000 (memory grows with them): fewer particles or samples'
        """
        lifting, inference = self.lifting, self.inference
        if not all(isinstance(v, numbers.Integral) for v in (lifting.n_particles, inference.samples)):
            return None  # the fields' own checks name what is wrong
        try:
            particles = min(lifting.n_particles, lifting.grid_planes())  # the coarse stage keeps one a plane at most
        except (TypeError, ValueError, ZeroDivisionError, OverflowError):
            return None
        n = particles * inference.samples
        if n <= MAX_HYPOTHESES:
            return None
        planes = " (one a plane of the grid)" if particles < lifting.n_particles else ""
        return (f"lifting.n_particles x inference.samples = {particles:,}{planes} x {inference.samples:,} = {n:,} "
                f"hypotheses a car and iteration, at most {MAX_HYPOTHESES:,} (memory grows with them): fewer "
                "particles or samples")

    def checked(self) -> "FitOptions":
        """These options, once every stage's numbers are checked against their fields'
        kinds and limits (:func:`wirescene.core.settings.check_fields`) and the seed is a
        non-negative integer; an :class:`~wirescene.core.errors.ArgumentError` naming the
        field otherwise (options built directly bypass :meth:`with_settings`' checks).

        Examples
        --------
        >>> FitOptions(lifting=LiftingOptions(n_particles=0)).checked()
        Traceback (most recent call last):
        ...
        wirescene.core.errors.ArgumentError: options: lifting.n_particles must be at least 1, got 0
        """
        from wirescene.core.settings import check_fields

        try:
            for stage in STAGES:
                check_fields(getattr(self, stage), scope=stage)
        except ValueError as exc:
            raise ArgumentError("options", str(exc)) from None
        problem = self.combined_problem()
        if problem is not None:
            raise ArgumentError("options", problem)
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral) or self.seed < 0:
            raise ArgumentError("options", f"seed must be a non-negative integer, got {self.seed!r}")
        return self


#: The stages whose options :meth:`FitOptions.with_settings` reaches, by attribute of :class:`FitOptions`.
STAGES: tuple[str, ...] = ("lifting", "inference", "predetect")
