"""The shipped artefacts' training recipes: each step's options (README, "Trained artefacts").

One source for ``wirescene train all`` (:mod:`wirescene.training.pipeline`) and the
defaults of the single-step commands, so that ``wirescene train parts --kitti-root ROOT``
trains what ``train all`` and the shipped ``parts_model.npz`` do. Kept free of imports:
the command line reads it when it starts.
"""

from __future__ import annotations

__all__ = ["RECIPE"]

#: ``{step: {option: value}}``: the options each step's training function is called with
#: beyond its own defaults (``score_calibration`` is the shipped file and takes none).
RECIPE: dict[str, dict] = {
    "parts": {"kind": "ghog_ms", "position": True, "smooth": 0.0625, "calibrate_real": True, "synth_scenes": 100},
    "detector": {"threshold": 0.5},
    "occlusion": {"seed": 2000, "n_scenes": 30},
}
