"""Cell lists and the Verlet half neighbour list, with tangential history carried across rebuilds.

The list is CSR: the neighbours j > i of grain i are ``index[start[i]:start[i+1]]``;
``shear`` (same layout) is the tangential displacement of each pair. The transposed
list ``tr_pair[tr_start[j]:tr_start[j+1]]`` holds, in increasing i, the pair slots in
which j is the second grain, so forces can be summed per grain in a fixed order
(bitwise identical for any thread count).
"""

from __future__ import annotations

from numba import njit, prange

from .. import NUMBA_CACHE


@njit(inline="always", cache=NUMBA_CACHE)
def minimum_image(dx, width):
    if dx > 0.5 * width:
        return dx - width
    if dx < -0.5 * width:
        return dx + width
    return dx


@njit(cache=NUMBA_CACHE)
def _scan_row(i, x, z, radius, body, width, skin, cell_of, count, order, ncx, ncz, out, at, write, limit):
    """Neighbours j > i of grain i within R_i + R_j + skin: the 3 x 3 cells around i's cell,
    each walked from its highest grain number down to i + 1 (cells hold grains in increasing
    number). Written to out[at:limit] when `write`. Returns how many (also those beyond limit)."""
    c = cell_of[i]
    cz0 = c // ncx
    cx0 = c - cz0 * ncx
    xi = x[i]
    zi = z[i]
    ri = radius[i]
    bi = body[i]
    found = 0
    span = 3 if ncx > 1 else 1
    for cz in range(max(cz0 - 1, 0), min(cz0 + 2, ncz)):
        for o in range(span):
            cx = (cx0 + o - 1) % ncx if ncx > 1 else 0
            cc = cz * ncx + cx
            for m in range(count[cc + 1] - 1, count[cc] - 1, -1):
                j = order[m]
                if j <= i:
                    break
                if bi == body[j] and bi != 0:
                    continue
                dx = minimum_image(x[j] - xi, width)
                dz = z[j] - zi
                cut = ri + radius[j] + skin
                if dx * dx + dz * dz < cut * cut:
                    if write and at + found < limit:
                        out[at + found] = j
                    found += 1
    return found


@njit(parallel=True, cache=NUMBA_CACHE)
def build_neighbors(x, z, radius, body, width, skin, start, index, shear, new_start, new_index, new_shear,
                    x_build, z_build, cell_of, order, count, serial):
    """Rebuild the half list for pairs closer than R_i + R_j + skin (`serial`: one thread runs it).

    x, z, radius: (N,) [d]; body: (N,) int8, grains of the same wall (body > 0) never pair.
    Work arrays cell_of, order (N,) and count (cells + 1,) are preallocated: nothing is
    allocated here (if the layer grows past count's capacity, cells are made larger, which is
    still exact). Returns the number of pairs, or -(needed capacity) if ``index`` is too short
    (the list is unchanged then). The transposed list is marked stale (see :func:`transpose`).
    """
    n = x.shape[0]
    capacity = index.shape[0]
    rmax = 0.0
    zmin = z[0]
    zmax = z[0]
    for i in range(n):
        rmax = max(rmax, radius[i])
        zmin = min(zmin, z[i])
        zmax = max(zmax, z[i])
    cell = 2.0 * rmax + skin
    while True:
        ncx = int(width / cell)
        if ncx < 3:
            ncx = 1
        ncz = int((zmax - zmin) / cell) + 1
        if ncx * ncz < count.shape[0]:
            break
        cell *= 1.25
    cw = width / ncx
    ncell = ncx * ncz
    for c in range(ncell + 1):
        count[c] = 0
    for i in range(n):
        cx = min(int(x[i] / cw), ncx - 1)
        cz = min(int((z[i] - zmin) / cell), ncz - 1)
        c = cz * ncx + cx
        cell_of[i] = c
        count[c + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    for i in range(n):              # count[c] runs up to the start of cell c + 1, then is reset
        c = cell_of[i]
        order[count[c]] = i
        count[c] += 1
    for c in range(ncell, 0, -1):
        count[c] = count[c - 1]
    count[0] = 0

    # One thread: one pass. Several: count per grain, prefix sum, then write in parallel. The
    # order within a row is the cell scan order either way, so the list is the same.
    if serial:
        npairs = 0
        for i in range(n):
            new_start[i] = npairs
            npairs += _scan_row(i, x, z, radius, body, width, skin, cell_of, count, order, ncx, ncz,
                                new_index, npairs, True, capacity)
        new_start[n] = npairs
        if npairs > capacity:
            return -npairs
    else:
        for i in prange(n):
            new_start[i + 1] = _scan_row(i, x, z, radius, body, width, skin, cell_of, count, order, ncx, ncz,
                                         new_index, 0, False, 0)
        new_start[0] = 0
        for i in range(n):
            new_start[i + 1] += new_start[i]
        npairs = new_start[n]
        if npairs > capacity:
            return -npairs
        for i in prange(n):
            _scan_row(i, x, z, radius, body, width, skin, cell_of, count, order, ncx, ncz,
                      new_index, new_start[i], True, capacity)
    if serial:
        _carry_history(0, n, start, index, shear, new_start, new_index, new_shear)
    else:
        for b in prange(16):
            _carry_history(b * n // 16, (b + 1) * n // 16, start, index, shear, new_start, new_index, new_shear)
    for i in range(n + 1):
        start[i] = new_start[i]
    for k in range(npairs):
        index[k] = new_index[k]
        shear[k] = new_shear[k]
    for i in range(n):
        x_build[i] = x[i]
        z_build[i] = z[i]
    return npairs


@njit(cache=NUMBA_CACHE)
def _carry_history(lo, hi, start, index, shear, new_start, new_index, new_shear):
    """Tangential history of rows lo:hi into the new list (pairs new to the list start at 0)."""
    for i in range(lo, hi):
        old_lo = start[i]
        old_hi = start[i + 1]
        for k in range(new_start[i], new_start[i + 1]):
            j = new_index[k]
            value = 0.0
            for m in range(old_lo, old_hi):
                if index[m] == j:
                    value = shear[m]
                    break
            new_shear[k] = value


@njit(cache=NUMBA_CACHE)
def transpose(start, index, tr_start, tr_pair, n):
    """Transposed list: tr_pair[tr_start[j]:tr_start[j+1]] are the slots where j is second, in
    increasing i. Derived from the list; tr_start[n] != start[n] marks it stale."""
    npairs = start[n]
    for j in range(n + 1):
        tr_start[j] = 0
    for k in range(npairs):
        tr_start[index[k] + 1] += 1
    for j in range(n):
        tr_start[j + 1] += tr_start[j]
    for i in range(n):
        for k in range(start[i], start[i + 1]):
            j = index[k]
            tr_pair[tr_start[j]] = k
            tr_start[j] += 1
    for j in range(n, 0, -1):
        tr_start[j] = tr_start[j - 1]
    tr_start[0] = 0
