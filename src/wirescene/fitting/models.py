"""The trained artefacts a fit uses, as :class:`~wirescene.fitting.pipeline.FitOptions`
carry them: a models directory (:func:`wirescene.core.resources.resolve_models`) applied
to the options, and the content fingerprint of what the options load (part of every
resume record, so that a retrained model is never mistaken for the one a record was
fitted with)."""

from __future__ import annotations

import dataclasses

from wirescene.core.errors import InputError
from wirescene.core.resources import Models, file_sha256, shipped_path
from wirescene.fitting.pipeline import FitOptions

__all__ = ["with_models", "models_fingerprint"]


def with_models(options: FitOptions, models: Models) -> FitOptions:
    """``options`` with the artefacts of ``models``.

    Parameters
    ----------
    options : FitOptions
        A part model or detector bank file set in it (``--parts-model``, ``--bank``) is
        kept: an explicit file wins over the directory's.
    models : Models
        Its part model, detector bank and occluded-part score ``c`` replace the shipped
        ones; what it lacks stays shipped.

    Raises
    ------
    InputError
        If ``models`` holds its own score calibration and ``options`` calibrate the
        scores: the fit cannot load another calibration than the shipped one yet.
    """
    if models.root is None:
        return options
    if "score_calibration" in models.own and options.calibrate_scores:
        raise InputError("a models directory's own score calibration cannot be used yet (the fit reads the "
                         "shipped one): remove the file, or write raw scores", path=models.path("score_calibration"))
    changes = {}
    if "parts_model" in models.own and options.parts_model is None:
        changes["parts_model"] = str(models.path("parts_model"))
    if "detector_bank" in models.own and options.detector_bank is None:
        changes["detector_bank"] = str(models.path("detector_bank"))
    if "occlusion" in models.own:
        from wirescene.infer.occluded_score import load_occluded_score

        c = load_occluded_score(models.path("occlusion"))
        changes["inference"] = dataclasses.replace(options.inference, occluded_score=c)
    return dataclasses.replace(options, **changes)


def models_fingerprint(options: FitOptions) -> dict[str, str]:
    """``{artefact: SHA-256}`` of the files a fit with ``options`` reads: part model,
    detector bank and (when scores are calibrated) score calibration. The occluded-part
    score is a number in the options themselves."""
    out = {
        "parts_model": file_sha256(options.parts_model or shipped_path("parts_model")),
        "detector_bank": file_sha256(options.detector_bank or shipped_path("detector_bank")),
    }
    if options.calibrate_scores:
        out["score_calibration"] = file_sha256(shipped_path("score_calibration"))
    return out
