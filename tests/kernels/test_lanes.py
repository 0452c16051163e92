"""The vector read-modify-writes of kernels.lanes give the bits of the scalar statements they replace."""

import numpy as np
from numba import njit

from gouge_cli.kernels.lanes import add2, add4, add4_scaled


@njit
def _vector(out, rows, values, scales):
    for k in range(rows.size):
        r = np.uint64(rows[k] * 16)
        x = values[k]
        add4(out, r, x[0], x[1], x[2], x[3])
        add4_scaled(out, r + np.uint64(4), x[0], x[1], x[2], x[3], scales[k])
        add2(out, r + np.uint64(8), x[4], x[5])


@njit
def _scalar(out, rows, values, scales):
    for k in range(rows.size):
        r = rows[k] * 16
        x = values[k]
        for m in range(4):
            out[r + m] += x[m]
        for m in range(4):
            out[r + 4 + m] += x[m] * scales[k]
        out[r + 8] += x[4]
        out[r + 9] += x[5]


def test_lanes_match_scalar_adds_bit_for_bit():
    rng = np.random.default_rng(11)
    n = 4000
    rows = rng.integers(0, 50, n)                    # repeated rows: sums of many terms, order matters
    values = rng.standard_normal((n, 6)) * 10.0 ** rng.integers(-12, 12, (n, 6))
    values[::97] = -0.0
    scales = rng.standard_normal(n) * 10.0 ** rng.integers(-8, 8, n)
    out_v = np.zeros(50 * 16)
    out_s = np.zeros(50 * 16)
    _vector(out_v, rows, values, scales)
    _scalar(out_s, rows, values, scales)
    assert np.array_equal(out_v.view(np.int64), out_s.view(np.int64))
    assert np.all(out_v.reshape(50, 16)[:, 10:] == 0.0)        # lanes beyond each write untouched
