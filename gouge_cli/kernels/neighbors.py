"""Cell lists and the Verlet half neighbour list, with tangential history carried across rebuilds.

The list is CSR: the neighbours j > i of grain i are ``index[start[i]:start[i+1]]``;
``shear`` (same layout) is the tangential displacement of each pair. The list is the same
for any thread count, so is the order of every force sum (kernels.forces.contact_forces).
"""

from __future__ import annotations

from numba import njit, prange

from . import NUMBA_CACHE
from .layout import LIST_BLOCKS


@njit(inline="always", cache=NUMBA_CACHE)
def minimum_image(dx, width):
    if dx > 0.5 * width:
        return dx - width
    if dx < -0.5 * width:
        return dx + width
    return dx


@njit(inline="always", cache=NUMBA_CACHE)
def _scan_row(i, x, z, radius, body, width, skin, cell_of, count, order, ncx, ncz, out, at, limit):
    """Neighbours j > i of grain i within R_i + R_j + skin: the 3 x 3 cells around i's cell,
    each walked from its highest grain number down to i + 1 (cells hold grains in increasing
    number), written to out[at:limit]. Returns how many (also those beyond limit)."""
    c = cell_of[i]
    cz0 = c // ncx
    cx0 = c - cz0 * ncx
    xi = x[i]
    zi = z[i]
    reach = radius[i] + skin
    bi = body[i]
    half = 0.5 * width
    span = 3 if ncx > 1 else 1
    left = cx0 - 1 if cx0 > 0 else ncx - 1          # periodic neighbours along x, no modulo
    right = cx0 + 1 if cx0 + 1 < ncx else 0
    found = 0
    for cz in range(max(cz0 - 1, 0), min(cz0 + 2, ncz)):
        row = cz * ncx
        for o in range(span):
            cc = row + (cx0 if span == 1 or o == 1 else (left if o == 0 else right))
            lo = count[cc]
            m = count[cc + 1] - 1
            while m >= lo:
                j = order[m]
                if j <= i:
                    break
                m -= 1
                dx = x[j] - xi
                if dx > half:
                    dx -= width
                elif dx < -half:
                    dx += width
                dz = z[j] - zi
                cut = reach + radius[j]
                if dx * dx + dz * dz < cut * cut and not (bi == body[j] and bi != 0):
                    if at + found < limit:
                        out[at + found] = j
                    found += 1
    return found


@njit(inline="always", cache=NUMBA_CACHE)
def bucket_order(key, nbins, count, order):
    """Stable counting sort: order (N,) = grain numbers by key (N,) in [0, nbins); afterwards
    count[b] is the first position of bucket b in order and count[nbins] = N. count: len > nbins."""
    n = key.shape[0]
    for b in range(nbins + 1):
        count[b] = 0
    for i in range(n):
        count[key[i] + 1] += 1
    for b in range(nbins):
        count[b + 1] += count[b]
    for i in range(n):              # count[b] runs up to the start of bucket b + 1, then is shifted back
        b = key[i]
        order[count[b]] = i
        count[b] += 1
    for b in range(nbins, 0, -1):
        count[b] = count[b - 1]
    count[0] = 0


@njit(inline="always", cache=NUMBA_CACHE)
def cell_grid(rmax, zmin, zmax, width, skin, capacity):
    """The list build's cell grid over grains of largest radius rmax [d] between heights zmin and
    zmax [d]: (cell height, cell width, ncx, ncz), cells at least 2 rmax + skin [d], made 1.25 times
    larger until ncx * ncz < capacity."""
    cell = 2.0 * rmax + skin
    while True:
        ncx = int(width / cell)
        if ncx < 3:
            ncx = 1
        ncz = int((zmax - zmin) / cell) + 1
        if ncx * ncz < capacity:
            break
        cell *= 1.25
    return cell, width / ncx, ncx, ncz


@njit(inline="always", cache=NUMBA_CACHE)
def bin_cells(x, z, radius, width, skin, cell_of, order, count):
    """The cell grid of a list build: cells at least 2 R_max + skin [d] wide (larger if count,
    len > cells, is too short), cell_of (N,) each grain's cell, order/count the grains by cell
    (bucket_order). Returns (ncx, ncz), the cells along x and z."""
    n = x.shape[0]
    rmax = 0.0
    zmin = z[0]
    zmax = z[0]
    for i in range(n):
        rmax = max(rmax, radius[i])
        zmin = min(zmin, z[i])
        zmax = max(zmax, z[i])
    cell, cw, ncx, ncz = cell_grid(rmax, zmin, zmax, width, skin, count.shape[0])
    for i in range(n):
        cx = min(int(x[i] / cw), ncx - 1)
        cz = min(int((z[i] - zmin) / cell), ncz - 1)
        cell_of[i] = cz * ncx + cx
    bucket_order(cell_of, ncx * ncz, count, order)
    return ncx, ncz


@njit(parallel=True, cache=NUMBA_CACHE)
def build_neighbors(x, z, radius, body, width, skin, start, index, shear, new_start, new_index, new_shear,
                    x_build, z_build, cell_of, order, count, scratch, serial):
    """Rebuild the half list for pairs closer than R_i + R_j + skin (`serial`: one thread runs it).

    x, z, radius: (N,) [d]; body: (N,) int8, grains of the same wall (body > 0) never pair.
    Work arrays cell_of, order (N,), count (cells + 1,) and scratch (>= 2 * LIST_BLOCKS + 1,)
    are preallocated: nothing is allocated here (if the layer grows past count's capacity,
    cells are made larger, which is still exact). Rows are found in LIST_BLOCKS blocks, each
    into its own region of new_index, then packed; the list is the same for any thread count.
    Returns the number of pairs, or -(needed capacity) if ``index`` is too short (the list is
    unchanged then). 
    """
    n = x.shape[0]
    capacity = index.shape[0]
    ncx, ncz = bin_cells(x, z, radius, width, skin, cell_of, order, count)
    nb = 1 if serial else LIST_BLOCKS
    region = capacity // nb
    found = scratch[:nb]
    packed = scratch[nb:2 * nb + 1]
    for b in prange(nb):
        at = b * region
        for i in range(b * n // nb, (b + 1) * n // nb):
            new_start[i] = at
            at += _scan_row(i, x, z, radius, body, width, skin, cell_of, count, order, ncx, ncz,
                            new_index, at, (b + 1) * region)
        found[b] = at - b * region
    packed[0] = 0
    worst = 0
    for b in range(nb):
        packed[b + 1] = packed[b] + found[b]
        worst = max(worst, found[b])
    if worst > region:
        return -max(worst * nb, packed[nb])
    npairs = packed[nb]
    for b in prange(nb):
        hi = (b + 1) * n // nb
        for i in range(b * n // nb, hi):
            end = new_start[i + 1] if i + 1 < hi else b * region + found[b]
            _carry_history(i, new_start[i], end, start, index, shear, new_index, new_shear)
    for b in prange(nb):
        shift = packed[b] - b * region
        for k in range(b * region, b * region + found[b]):
            index[k + shift] = new_index[k]
            shear[k + shift] = new_shear[k]
        for i in range(b * n // nb, (b + 1) * n // nb):
            start[i] = new_start[i] + shift
    start[n] = npairs
    for i in range(n):
        x_build[i] = x[i]
        z_build[i] = z[i]
    return npairs


@njit(inline="always", cache=NUMBA_CACHE)
def _carry_history(i, lo, hi, start, index, shear, new_index, new_shear):
    """Tangential history of row i (new slots lo:hi) from the old list; new pairs start at 0."""
    old_lo = start[i]
    old_hi = start[i + 1]
    for k in range(lo, hi):
        j = new_index[k]
        value = 0.0
        for m in range(old_lo, old_hi):
            if index[m] == j:
                value = shear[m]
                break
        new_shear[k] = value
