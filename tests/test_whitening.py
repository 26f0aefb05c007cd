import numpy as np
import pytest
from scipy.ndimage import uniform_filter

from conftest import assert_close
from wirescene.core.errors import ShapeError
from wirescene.training.whitening import background_statistics, whitening_matrix, window_covariance


def _correlated_levels(seed=0):
    """HOG-like levels whose cells are correlated with their neighbours and across channels."""
    rng = np.random.default_rng(seed)
    mix = rng.normal(size=(31, 31)) / 6
    out = []
    for shape in ((60, 90), (40, 70)):
        noise = rng.normal(size=shape + (31,))
        out.append((uniform_filter(noise, size=(3, 3, 1)) @ mix + 0.1).astype(np.float32))
    return out


def _windows(levels, th, tw):
    return np.concatenate([np.stack([F[y:y + th, x:x + tw].ravel() for y in range(F.shape[0] - th + 1)
                                     for x in range(F.shape[1] - tw + 1)]) for F in levels])


def test_window_covariance_is_the_windows_own_covariance():
    levels = _correlated_levels()
    stats = background_statistics(levels, (3, 4))
    X = _windows(levels, 2, 3)
    S = window_covariance(stats, 2, 3)
    # neighbouring cells are correlated (the statistics see it) and the assembled matrix is the sample's
    assert abs(S[0, 31]) > 0.2 * S[0, 0]
    assert_close(S, np.cov(X.T), atol=0.07 * S.diagonal().mean())


def test_whitened_windows_are_decorrelated_at_the_raw_mean_variance():
    levels = _correlated_levels(1)
    stats = background_statistics(levels, (2, 2))
    M = whitening_matrix(stats, 2, 2, ridge=0.0)
    scale = window_covariance(stats, 2, 2).diagonal().mean()
    C = np.cov((_windows(levels, 2, 2) @ M).T)
    assert_close(C / scale, np.eye(len(C)), atol=0.08)


def test_windows_larger_than_the_statistics_and_bad_levels_are_refused():
    stats = background_statistics(_correlated_levels(), (2, 2))
    with pytest.raises(ShapeError, match="exceeds"):
        window_covariance(stats, 3, 2)
    with pytest.raises(ShapeError, match="31"):
        background_statistics([np.zeros((5, 5, 9))], (2, 2))
