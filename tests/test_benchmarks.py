"""The benchmark scripts stay importable as the package's layout changes.

Benchmarks are not run by the test suite (they take minutes to hours), but a script
whose imports no longer resolve is found here rather than by the next person who needs
its figures.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p for p in BENCHMARKS.glob("*.py") if not p.stem.startswith("_"))  # _common.py: helpers


def test_there_are_benchmarks():
    assert len(SCRIPTS) >= 5


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_benchmark_imports(script, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(f"_bench_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)  # every script guards its main with __name__
    finally:
        sys.modules.pop(f"_bench_{script.stem}", None)
    assert callable(getattr(module, "main", None)), f"{script.name} has no main()"


def test_choose_by_fold_never_uses_the_scored_fold(monkeypatch):
    """Each fold's configuration is the best on the other folds, whatever it scores on its own."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from choose_by_fold import choose_leaving_one_out

    # "a" wins overall only through fold 0; on folds 1-3 "b" leads.
    counts = {"a": [50, 10, 10, 10], "b": [0, 12, 12, 12]}
    assert choose_leaving_one_out(counts) == {0: "b", 1: "a", 2: "a", 3: "a"}
    # Ties go to the first configuration given.
    assert choose_leaving_one_out({"off": [1, 1], "on": [1, 1]}) == {0: "off", 1: "off"}


def test_learning_curve_subsets_are_reproducible_shares_of_the_training_frames(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_predetect import training_subset

    frames = [f"{i:06d}" for i in range(24)]
    third = training_subset(frames, 1 / 3, seed=(0, 2))
    assert len(third) == 8 and third <= set(frames)
    assert training_subset(frames, 1 / 3, seed=(0, 2)) == third  # same seed, same frames
    assert training_subset(frames, 1 / 3, seed=(0, 3)) != third  # each fold draws its own
    assert training_subset(frames, 1.0, seed=(0, 2)) == set(frames)
    assert len(training_subset(frames, 0.01, seed=(0, 2))) == 1
