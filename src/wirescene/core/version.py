"""The package's version, read from its installed metadata so that it is written once
(``pyproject.toml``). It lives in ``core`` so that any layer may record it without
importing the package root (which loads the API and every layer under it)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wirescene")
except PackageNotFoundError:  # a source tree on sys.path that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
