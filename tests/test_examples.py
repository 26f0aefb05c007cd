"""Every docstring example of the package runs and prints what it says (users copy them)."""

import doctest
import importlib
from pathlib import Path

import pytest

import wirescene

PACKAGE = Path(wirescene.__file__).parent


def modules_with_examples() -> list[str]:
    """Dotted names of the package's modules whose source holds a ``>>>`` example."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if ">>> " in path.read_text(encoding="utf-8"):
            parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
            out.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


MODULES = modules_with_examples()


def test_the_search_finds_the_examples():
    # the discovery itself must not pass by finding nothing
    assert {"wirescene.api", "wirescene.core.types", "wirescene.predetect.hog", "wirescene.eval.intervals"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_of_a_module_run(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS, report=True)
    assert result.attempted > 0 and result.failed == 0, f"{name}: {result}"
