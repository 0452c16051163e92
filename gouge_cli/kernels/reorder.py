"""Spatial re-numbering of the grains, so that neighbours keep nearby numbers while the layer shears.

The force pass walks grain rows in number order and reads each neighbour's data; with
neighbours a few numbers apart that data is in cache. Shear mixes the packing's initial
numbering (after one layer width of shear at 10,000 grains the 90th percentile of |j - i|
grows from 29 to 770 and the step slows down), so the grains are re-numbered every
few rebuilds: strips along x (strip_width: STRIP d, narrower in tall layers so that a strip
holds at most about STRIP_GRAINS grains), then rows BIN d high, keeping the current order
inside a bin (a stable counting sort, deterministic). The grain's original number travels
with it in ``id`` so outputs can be written in a fixed order.

Nothing is allocated: the permutation and its inverse live in the rebuild's scratch arrays.
"""

from __future__ import annotations

from numba import njit

from . import NUMBA_CACHE
from .neighbors import bucket_order

STRIP = 16.0            # [d] widest numbering strip, and the packing's initial numbering (fixed: a
                        # checkpoint's grain numbers `id` refer to it)
STRIP_MIN = 2.0         # [d] narrowest
STRIP_GRAINS = 800.0    # grains per strip at most, down to STRIP_MIN: a grain's neighbours in the next
                        # strip stay a cache-sized window of numbers away in tall layers (160,000
                        # grains: 4 d strips)
BIN = 1.0               # [d] height of a row inside a strip


@njit(cache=NUMBA_CACHE)
def strip_width(n, width):
    """[d] numbering strip width for n grains across a layer `width` d wide."""
    return min(STRIP, max(STRIP_MIN, STRIP_GRAINS * width / max(n, 1)))


@njit(cache=NUMBA_CACHE)
def strip_grid(n, width, zmin, zmax, capacity):
    """The re-numbering's bins for n grains between heights zmin and zmax [d]: (strips, strip
    width [d], rows, row height [d]), rows made twice as tall until strips * rows < capacity."""
    strips = max(int(width / strip_width(n, width)), 1)
    height = BIN
    rows = int((zmax - zmin) / height) + 1
    while strips * rows >= capacity:
        height *= 2.0
        rows = int((zmax - zmin) / height) + 1
    return strips, width / strips, rows, height


@njit(cache=NUMBA_CACHE)
def spatial_order(x, z, width, perm, inverse, count):
    """perm (N,) int64: new -> old grain number, by (strip, row), stable; inverse: old -> new.
    count: int64 scratch, len > number of bins (bins grow taller if it is too short)."""
    n = x.shape[0]
    zmin = z[0]
    zmax = z[0]
    for i in range(n):
        zmin = min(zmin, z[i])
        zmax = max(zmax, z[i])
    strips, strip_w, rows, height = strip_grid(n, width, zmin, zmax, count.shape[0])
    for i in range(n):
        s = min(int(x[i] / strip_w), strips - 1)
        inverse[i] = s * rows + min(int((z[i] - zmin) / height), rows - 1)     # (the bin, for now)
    bucket_order(inverse, strips * rows, count, perm)
    for k in range(n):
        inverse[perm[k]] = k


@njit(cache=NUMBA_CACHE)
def permute(values, perm, scratch):
    """values[:] = values[perm] through scratch (same length or longer, same kind)."""
    n = perm.shape[0]
    for k in range(n):
        scratch[k] = values[perm[k]]
    for k in range(n):
        values[k] = scratch[k]


@njit(cache=NUMBA_CACHE)
def renumber_list(inverse, start, index, shear, new_start, new_index, new_shear):
    """The half list in the new numbering (pair (i, j) -> (min, max) of (inverse[i], inverse[j])),
    rows in increasing number, each row's pairs in the order of their old slots; shear travels along."""
    n = inverse.shape[0]
    npairs = start[n]
    for i in range(n + 1):
        new_start[i] = 0
    for i in range(n):
        a = inverse[i]
        for k in range(start[i], start[i + 1]):
            b = inverse[index[k]]
            new_start[min(a, b) + 1] += 1
    for i in range(n):
        new_start[i + 1] += new_start[i]
    for i in range(n):                       # new_start[r] runs to the start of row r + 1, then shifts back
        a = inverse[i]
        for k in range(start[i], start[i + 1]):
            b = inverse[index[k]]
            r = min(a, b)
            at = new_start[r]
            new_index[at] = max(a, b)
            new_shear[at] = shear[k]
            new_start[r] = at + 1
    for r in range(n, 0, -1):
        new_start[r] = new_start[r - 1]
    new_start[0] = 0
    for i in range(n + 1):
        start[i] = new_start[i]
    for k in range(npairs):
        index[k] = new_index[k]
        shear[k] = new_shear[k]
