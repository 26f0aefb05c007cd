"""The pre-detection's working memory on a large image: bounded, whatever the image's size (a 4K frame's finest
pyramid level once took 1.7 GB of template products, an 8K frame's colour channels some 4 GB of temporaries;
``benchmarks/RESULTS.md``, "A 4K camera's memory"), with the same numbers as before."""

import tracemalloc

import numpy as np

from wirescene.predetect import load_default_bank
from wirescene.predetect.bank import MAX_PRODUCTS, template_responses
from wirescene.predetect.channels import STRIP_PIXELS, integral_channels
from wirescene.predetect.hog import N_FEAT


def _peak_bytes(fn):
    """``(result, peak bytes numpy and Python allocated while fn() ran)``."""
    tracemalloc.start()
    try:
        result = fn()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_template_responses_hold_at_most_max_products_on_a_large_level():
    """A level of 240,000 cells (a 4K frame's scale-1.6 level): all 32 templates' maps with the templates' products
    bounded by ``MAX_PRODUCTS`` (128 MB), not 800 template cells times the level's cells (770 MB before), and every
    map equal to the bit to the one of the level's rows scored whole."""
    bank = load_default_bank()
    rng = np.random.default_rng(0)
    F = np.abs(rng.normal(0.0, 0.1, (400, 600, N_FEAT))).astype(np.float32)
    pyramid = [(1.0, F)]

    def sizes():
        return {t: R.shape for t, _, _, R in template_responses(bank, pyramid, min_height=0.0, max_height=np.inf)}

    got, peak = _peak_bytes(sizes)
    assert len(got) == len(bank)
    maps = sum(int(np.prod(shape)) * 4 for shape in got.values())  # (each map is yielded whole)
    assert peak < 4 * MAX_PRODUCTS + maps // 8 + (64 << 20), peak / 2**20
    # the bands' maps: the same as a level small enough to be scored whole, cut out of this one
    small = [(1.0, F[:40, :60].copy())]
    whole = {t: R for t, _, _, R in template_responses(bank, small, min_height=0.0, max_height=np.inf)}
    banded = {t: R for t, _, _, R in template_responses(bank, small, min_height=0.0, max_height=np.inf,
                                                        max_products=5000)}
    assert whole.keys() == banded.keys() and all(whole[t].tobytes() == banded[t].tobytes() for t in whole)


def test_integral_channels_convert_a_large_image_in_strips():
    """A 4000 x 1500 image's integral channels: the colour conversion's temporaries bounded by one strip of
    ``STRIP_PIXELS`` pixels (before: some 130 bytes for every pixel of the image at once, 790 MB here)."""
    image = np.random.default_rng(1).integers(0, 255, (1500, 4000, 3), dtype=np.uint8)
    out, peak = _peak_bytes(lambda: integral_channels(image))
    assert out.shape == (1501, 4001, 4)
    assert peak < out.nbytes + 200 * STRIP_PIXELS, (peak - out.nbytes) / 2**20


def test_bands_give_the_whole_maps_to_the_bit_on_levels_a_template_wide():
    """A band of one window on a level exactly a template wide is summed in order, as the
    whole map's rows are: banded maps equal whole ones at any band size."""
    bank = load_default_bank()
    rng = np.random.default_rng(3)
    tw = bank.configs[0].template[1]
    levels = [(1.0, np.abs(rng.normal(0, 0.1, (40, width, N_FEAT))).astype(np.float32)) for width in (tw, tw + 1)]
    whole = {(t, li): R for t, li, _, R in template_responses(bank, levels, min_height=0, max_height=np.inf)}
    assert any(R.shape[1] == 1 for R in whole.values())  # a level a template wide: a map one window wide
    for max_products in (1, 5_000):
        banded = list(template_responses(bank, levels, min_height=0, max_height=np.inf, max_products=max_products))
        assert len(banded) == len(whole)
        assert all(R.tobytes() == whole[(t, li)].tobytes() for t, li, _, R in banded)
