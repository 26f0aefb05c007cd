"""Figures of one evaluation over several seeds (``wirescene.eval.seeds``)."""

import pytest

from conftest import assert_close
from wirescene.eval.seeds import FIGURES, format_over_seeds, over_seeds, seed_figures


def _kitti(ap3d: float) -> dict:
    block = {m: {"easy": 0.0, "moderate": ap3d if m == "3d" else 50.0, "hard": 0.0} for m in ("2d", "aos", "bev", "3d")}
    return {"car": block, "iou_0.5": {"car": block}}


def test_each_seeds_figures_and_their_mean_and_range():
    metrics = {1: {"n_tp": 10, "loc_1m": 50.0, "loc_1_5m": 60.0, "median_az3d": float("nan")},
               2: {"n_tp": 12, "loc_1m": 40.0, "loc_1_5m": 70.0, "median_az3d": 3.0}}
    per_seed = {s: seed_figures({"full": m}, {"full": _kitti(10.0 * s)}) for s, m in metrics.items()}
    assert set(per_seed[1]["full"]) == {c for c, _, _ in FIGURES}
    summary = over_seeds(per_seed)["full"]
    assert_close([summary["TP"][k] for k in ("mean", "min", "max")], [11.0, 10.0, 12.0])
    assert_close([summary["3d@.7"][k] for k in ("mean", "min", "max")], [15.0, 10.0, 20.0])
    # a figure a seed cannot give (NaN: no true positive to take a median of) is left out of the summary
    assert summary["med az"]["values"] == [None, 3.0] and summary["med az"]["mean"] == 3.0
    text = format_over_seeds(over_seeds(per_seed), [1, 2])
    assert text.splitlines()[0].startswith("Over 2 seeds (1, 2)") and "10-12" in text and "40.0-50.0" in text


def test_seeds_must_have_evaluated_the_same_variants():
    with pytest.raises(ValueError, match="seed 2 evaluated variants"):
        over_seeds({1: {"full": {"TP": 1.0}}, 2: {"fg+gp": {"TP": 1.0}}})
    with pytest.raises(ValueError, match="no seeds"):
        over_seeds({})
