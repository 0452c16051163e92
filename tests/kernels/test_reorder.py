"""Spatial re-numbering order (kernels.reorder): strips along x, rows inside a strip, stable."""

import numpy as np

from gouge_cli.kernels.reorder import BIN, STRIP, STRIP_MIN, spatial_order, strip_width


def test_strip_width_keeps_strips_cache_sized():
    assert strip_width(2500, 100.0) == STRIP             # short layers: the widest strip
    assert strip_width(10000, 200.0) == STRIP            # 800 grains per 16 d strip
    assert strip_width(160000, 800.0) == 4.0             # tall layer: 800 grains per strip
    assert strip_width(10**6, 100.0) == STRIP_MIN


def _check_order(x, z, width, strip):
    n = x.size
    perm = np.zeros(n, np.int64)
    inverse = np.zeros(n, np.int64)
    spatial_order(x, z, width, perm, inverse, np.zeros(2 * n + 64, np.int64))
    assert np.array_equal(np.sort(perm), np.arange(n))
    assert np.array_equal(inverse[perm], np.arange(n))
    strips = max(int(width / strip), 1)
    column = np.minimum((x / (width / strips)).astype(np.int64), strips - 1)
    row = ((z - z.min()) / BIN).astype(np.int64)
    expected = np.lexsort((np.arange(n), row, column))      # by strip, row, then old number
    assert np.array_equal(perm, expected)


def test_spatial_order_is_a_stable_sort_by_strip_and_row():
    rng = np.random.default_rng(5)
    short = (40.0, 600)          # 15 grains per d of width: 16 d strips
    tall = (20.0, 8000)          # 400 grains per d of width: 2 d strips
    for width, n in (short, tall):
        x = rng.uniform(0, width, n)
        z = rng.uniform(0, n / width, n)
        _check_order(x, z, width, strip_width(n, width))
