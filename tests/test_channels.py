"""Colour and gradient-magnitude channel features of the verifier's windows."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_close
from wirescene.core.image import to_grey
from wirescene.predetect.channels import N_CHANNEL_FEATURES, integral_channels, window_channel_features
from wirescene.predetect.refine import GRID, window_boxes
from wirescene.predetect.verifier import fit_verifier, verifier_features, verifier_logits


def test_cell_means_are_the_channels_means_over_each_cell():
    """Inside the image each cell holds its channel's mean over the cell's pixels, each
    channel standardised over the window, then the window's means and log spreads."""
    from skimage.color import rgb2luv

    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (90, 130, 3), dtype=np.uint8)
    box = np.array([[40.0, 30.0, 88.0, 62.0]])  # window (28, 22, 100, 70): 72 x 48 px, cells of 6 x 6
    f = window_channel_features(integral_channels(img), box)
    assert f.shape == (1, N_CHANNEL_FEATURES) and f.dtype == np.float32
    luv = rgb2luv(img)
    ch = np.concatenate([luv, np.hypot(*np.gradient(luv[..., 0]))[..., None]], -1)
    x0, y0, x1, y1 = window_boxes(box)[0].astype(int)
    th, tw = GRID
    cells = ch[y0:y1, x0:x1].reshape(th, (y1 - y0) // th, tw, (x1 - x0) // tw, 4).mean((1, 3))
    mean, spread = cells.mean((0, 1)), cells.std((0, 1)) + 1e-3
    assert_close(f[0, :th * tw * 4], ((cells - mean) / spread).ravel(), atol=1e-4)
    assert_close(f[0, th * tw * 4:], np.concatenate([mean, np.log(spread)]), rtol=1e-5, atol=1e-5)


def test_integral_channels_are_skimage_s_colours_summed_in_order_to_the_bit():
    """The L*u*v* channels are ``skimage.color.rgb2luv``'s to the bit (its gamma read from a
    table of the 256 levels), the gradient magnitude ``np.hypot`` of ``np.gradient``'s, and the
    integral image two ``cumsum``'s, down the columns, then along the rows, whole or in strips
    (the former code, written out; every 8-bit level in every channel)."""
    from skimage.color import rgb2luv

    rng = np.random.default_rng(7)
    img = np.stack([rng.permutation(np.tile(np.arange(256, dtype=np.uint8), 24)).reshape(48, 128)
                    for _ in range(3)], axis=-1)
    img[:4, :4] = [[0, 0, 0], [255, 255, 255], [10, 10, 10], [11, 0, 0]]  # black, white, the gamma's linear part
    luv = rgb2luv(img).astype(np.float64)
    ch = np.concatenate([luv, np.hypot(*np.gradient(luv[..., 0])[::-1])[..., None]], axis=-1)
    expected = np.zeros((49, 129, 4))
    expected[1:, 1:] = ch.cumsum(0).cumsum(1)
    for strip_pixels in (1 << 20, 128 * 7, 1):  # one strip, strips of 7 rows, of one row
        assert integral_channels(img, strip_pixels=strip_pixels).tobytes() == expected.tobytes()


def test_windows_past_the_image_and_empty_inputs():
    ii = integral_channels(np.full((40, 60, 3), 128, np.uint8))
    f = window_channel_features(ii, np.array([[-30.0, -20.0, 10.0, 5.0], [50.0, 30.0, 90.0, 70.0]]))
    assert np.isfinite(f).all() and np.abs(f[:, :GRID[0] * GRID[1] * 4]).max() < 1e-3  # a flat image: no contrast
    assert window_channel_features(ii, np.zeros((0, 4))).shape == (0, N_CHANNEL_FEATURES)
    with pytest.raises(ValueError, match=r"boxes must have shape \(\*, 4\)"):
        window_channel_features(ii, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="integral must be"):
        window_channel_features(ii[..., :3], np.zeros((1, 4)))


def _scene(rng, hue):
    """An image whose object (a textured rectangle) has colour ``hue`` and whose decoy, the
    same texture, the other colour of the same grey: alike to HOG, not to colour."""
    red, green = np.array([0.8, 0.25, 0.25]), np.array([0.25, 0.0, 0.25])
    green[1] = (to_grey(red[None, None]).item() - 0.299 * green[0] - 0.114 * green[2]) / 0.587  # the same luma
    img = np.full((120, 300, 3), 0.3)
    w, h = int(rng.uniform(50, 70)), int(rng.uniform(30, 40))
    x, y = int(rng.uniform(10, 70)), int(rng.uniform(30, 60))
    texture = 0.8 + 0.4 * rng.uniform(size=(h, w, 1))
    obj, decoy = (red, green) if hue == "red" else (green, red)
    img[y:y + h, x:x + w] = np.clip(obj * texture, 0, 1)
    img[y:y + h, x + 150:x + 150 + w] = np.clip(decoy * texture, 0, 1)
    car = np.array([x, y, x + w, y + h], float)
    return (img * 255).round().astype(np.uint8), np.stack([car, car + [150, 0, 150, 0]])


def test_a_verifier_with_channels_tells_colours_apart_that_hog_cannot():
    rng = np.random.default_rng(2)

    def rows(n, *, channels):
        X = []
        for _ in range(n):
            img, boxes = _scene(rng, "red")
            X.append(verifier_features(to_grey(img), boxes, np.zeros((2, 1)),
                                       channels=integral_channels(img) if channels else None))
        return np.concatenate(X), np.tile([1, 0], n)

    for channels, least, most in ((False, 0.0, 0.75), (True, 0.95, 1.0)):
        state = rng.bit_generator.state
        X, y = rows(30, channels=channels)
        Xt, yt = rows(15, channels=channels)
        rng.bit_generator.state = state  # the same scenes for both verifiers
        right = np.mean((verifier_logits(fit_verifier(X, y), Xt) > 0) == yt)
        assert least <= right <= most, (channels, right)
