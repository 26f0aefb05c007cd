"""The package's version, read from its installed metadata so that it is written once
(``pyproject.toml``). It lives in ``core`` so that any layer may record it without
importing the package root (which loads the API and every layer under it)."""

from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wirescene")
except PackageNotFoundError:  # a source tree on sys.path that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__", "environment", "package_versions"]

#: The installed packages whose versions a run's figures (and pictures: matplotlib) may depend on.
_PACKAGES = ("numpy", "scipy", "scikit-learn", "scikit-image", "pillow", "trimesh", "embreex", "matplotlib")


def package_versions(names) -> dict:
    """``{name: installed version or None}`` of the distributions ``names``.

    Examples
    --------
    >>> import numpy
    >>> package_versions(["numpy", "no-such-distribution"]) == {"numpy": numpy.__version__,
    ...                                                         "no-such-distribution": None}
    True
    """
    out: dict = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


def environment() -> dict:
    """What a run's figures depend on beside the code: the package versions, and the BLAS
    libraries (numpy's and scipy's, which wheels ship apart) with the kernels they chose for
    this CPU (``kernels``: OpenBLAS's core type, e.g. ``Haswell`` or ``SkylakeX``;
    ``OPENBLAS_CORETYPE`` sets it), whatever the caller has imported. Models trained with other
    kernels differ in their last digits (``benchmarks/RESULTS.md``, "The held-out figures on
    a CPU with AVX-512").

    Examples
    --------
    >>> import numpy
    >>> env = environment()
    >>> env["numpy"] == numpy.__version__, sorted(env["blas"][0]) if env["blas"] else []
    (True, ['kernels', 'library', 'version'])
    """
    import numpy  # noqa: F401  (their BLAS must be loaded for threadpoolctl to see them)
    import scipy.linalg  # noqa: F401

    out: dict = {"wirescene": __version__, "python": platform.python_version(), **package_versions(_PACKAGES)}
    try:
        from threadpoolctl import threadpool_info
    except ImportError:  # scikit-learn brings it; without it the kernels are unknown
        out["blas"] = None
    else:
        out["blas"] = [{"library": i.get("internal_api"), "version": i.get("version"), "kernels": i.get("architecture")}
                       for i in threadpool_info() if i.get("user_api") == "blas"]
    return out
