"""The coarse-graining filter of the pore-fluid coupling: the grid deposit smoothed over a
physical width w, the drag gathered back through the transpose (docs/physics/fluid.md).

The averaging width and the grid are two scales. The grains deposit onto the grid with
bilinear weights W (kernels.deposit), which spread a grain over about one cell; the filter S
then smooths the deposited sums with a Gaussian of standard deviation sigma = w/2 per axis, less
the spread the bilinear weights already give (variance h^2/6 on an axis of spacing h):

    sigma_h^2 = max(w^2/4 - h^2/6, 0),

so that the total spread of a grain's deposit is w/2 whatever the grid, and refining the grid at
fixed w converges to the filtered continuum model. S is separable, S = S_z S_x:

* S_x: periodic, a circulant of taps exp(-(m dx)^2 / (2 sigma_x^2)) for offsets |m| <= 3 sigma_x / dx
  (and at most (nx - 1)/2), normalised to sum 1;
* S_z: between the wall planes, a Gaussian with mirror images in both planes (no solid crosses a
  wall), K[jo, ji] for |jo - ji| <= 3 sigma_z / dz, each column ji normalised to sum 1, stored as
  its diagonals: bands_z[0, mz + d, jo] = K[jo, jo + d] (S_z) and bands_z[1, mz + d, ji] =
  K[ji + d, ji] (S_z^T), so that both products run along contiguous rows.

Both keep every column sum at 1, so S conserves the deposited solid area exactly. The drag goes
back through S^T = S_x S_z^T: with A the raw deposit and f = -(grad P)/s~ the drag density on
s~ = S A / (dx dz), sum_c A_c (S^T f)_c = sum_c (S A)_c f_c = -dx dz sum_c (grad P)_c, so the total
drag is minus the integral of grad P and action equals reaction. A width w = 0 (or sigma_h below
1e-3 cells on both axes) leaves S the identity. Pure compute, serial, a fixed order of sums: the
same bits on any thread count.
"""

import math

import numpy as np
from numba import njit

from . import NUMBA_CACHE

TRUNCATION = 3.0     # the kernel is cut at this many standard deviations (then renormalised)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def filter_sigmas(width, dx, dz):
    """(sigma_x, sigma_z) [d]: the Gaussian smoothing left to the filter on a grid of spacing dx, dz
    for a filter width w (total standard deviation w/2; the bilinear deposit has h^2/6)."""
    target = 0.25 * width * width
    sx2 = target - dx * dx / 6.0
    sz2 = target - dz * dz / 6.0
    return math.sqrt(sx2) if sx2 > 0.0 else 0.0, math.sqrt(sz2) if sz2 > 0.0 else 0.0


@njit(cache=NUMBA_CACHE, error_model="numpy")
def half_widths(width, dx, dz, nx, nz):
    """(mx, mz): the filter's half widths in cells on an nx x nz grid of spacing dx, dz (0: no
    smoothing on that axis); filter_setup's."""
    sx, sz = filter_sigmas(width, dx, dz)
    mx = 0
    if sx > 1e-3 * dx:
        mx = min(int(math.ceil(TRUNCATION * sx / dx)), (nx - 1) // 2)
    mz = 0
    if sz > 1e-3 * dz:
        mz = min(int(math.ceil(TRUNCATION * sz / dz)), nz - 1)
    return mx, mz


@njit(cache=NUMBA_CACHE, error_model="numpy")
def filter_setup(width, dx, dz, taps_x, bands_z):
    """Taps of S_x and the diagonals of S_z for the current cell sizes; returns (mx, mz), the half
    widths in cells (0: no smoothing on that axis).

    taps_x : float64[nx] out, taps_x[m] for offsets 0..mx (symmetric), summing to 1 over -mx..mx
    bands_z : float64[2 or 3, 2 nz - 1, nz] out, the diagonals of S_z and of S_z^T (module doc); zero
              where a diagonal leaves the grid; [2]: S_z with odd mirror images (the filter of an odd
              field such as grad_z s of the mirror-extended deposit), normalised as the even one
    """
    nx = taps_x.shape[0]
    nz = bands_z.shape[2]
    sx, sz = filter_sigmas(width, dx, dz)
    mx, mz = half_widths(width, dx, dz, nx, nz)
    if mx > 0:
        total = 0.0
        for m in range(mx + 1):
            d = m * dx / sx
            taps_x[m] = math.exp(-0.5 * d * d)
            total += taps_x[m] if m == 0 else 2.0 * taps_x[m]
        for m in range(mx + 1):
            taps_x[m] /= total
    if mz > 0:
        thickness = nz * dz
        reach = TRUNCATION * sz
        for b in range(2 * mz + 1):
            for j in range(nz):
                for h in range(bands_z.shape[0]):
                    bands_z[h, b, j] = 0.0
        for ji in range(nz):
            zi = (ji + 0.5) * dz
            total = 0.0
            for jo in range(max(0, ji - mz), min(nz, ji + mz + 1)):
                zo = (jo + 0.5) * dz
                value = 0.0
                for distance in (zo - zi, zo + zi, 2.0 * thickness - zo - zi):
                    if abs(distance) <= reach:
                        u = distance / sz
                        value += math.exp(-0.5 * u * u)
                bands_z[1, mz + jo - ji, ji] = value          # K[jo, ji], column ji
                total += value
            for jo in range(max(0, ji - mz), min(nz, ji + mz + 1)):
                value = bands_z[1, mz + jo - ji, ji] / total
                bands_z[1, mz + jo - ji, ji] = value
                bands_z[0, mz + ji - jo, jo] = value          # the same entry on the row diagonal
                if bands_z.shape[0] > 2:                      # the odd images (grad_z s), the even norm
                    zo = (jo + 0.5) * dz
                    odd = 0.0
                    for sign, distance in ((1.0, zo - zi), (-1.0, zo + zi), (-1.0, 2.0 * thickness - zo - zi)):
                        if abs(distance) <= reach:
                            u = distance / sz
                            odd += sign * math.exp(-0.5 * u * u)
                    bands_z[2, mz + ji - jo, jo] = odd / total
    return mx, mz


@njit(cache=NUMBA_CACHE, error_model="numpy")
def filter_x(field, target, taps_x, mx, i0, i1):
    """target = S_x field on the columns i0 <= i < i1 (periodic circulant; symmetric, so also S_x^T;
    mx = 0: a copy): t_0 f + t_1 (f_east + f_west) + t_2 (...) + ... per cell, in that order (a
    cell's x neighbours m columns away are m nz apart; the first and last m columns wrap). For
    mx <= 4 the cells whose neighbours do not wrap take every term in one expression, the others
    _x_cell; otherwise one pass per tap (_x_passes). The same bits whichever columns a call takes."""
    nx, nz = field.shape
    f = field.reshape(field.size)
    out = target.reshape(target.size)
    size = np.uint64(f.size)
    lo = np.uint64(i0 * nz)
    hi = np.uint64(i1 * nz)
    if mx == 0:
        for c in range(lo, hi):
            out[c] = f[c]
        return
    if mx > 4:
        _x_passes(f, out, taps_x, mx, nz, lo, hi)
        return
    reach = np.uint64(mx * nz)
    inner_lo = max(lo, reach)
    inner_hi = max(min(hi, size - reach), inner_lo)
    for c in range(lo, min(hi, inner_lo)):
        out[c] = _x_cell(f, taps_x, mx, c, nz, size)
    for c in range(inner_hi, hi):
        out[c] = _x_cell(f, taps_x, mx, c, nz, size)
    t0, t1 = taps_x[0], taps_x[1]
    t2 = taps_x[2] if mx >= 2 else 0.0
    t3 = taps_x[3] if mx >= 3 else 0.0
    t4 = taps_x[4] if mx >= 4 else 0.0
    s1, s2, s3, s4 = np.uint64(nz), np.uint64(2 * nz), np.uint64(3 * nz), np.uint64(4 * nz)
    if mx == 1:
        for c in range(inner_lo, inner_hi):
            out[c] = t0 * f[c] + t1 * (f[c + s1] + f[c - s1])
    elif mx == 2:
        for c in range(inner_lo, inner_hi):
            out[c] = (t0 * f[c] + t1 * (f[c + s1] + f[c - s1])) + t2 * (f[c + s2] + f[c - s2])
    elif mx == 3:
        for c in range(inner_lo, inner_hi):
            out[c] = ((t0 * f[c] + t1 * (f[c + s1] + f[c - s1])) + t2 * (f[c + s2] + f[c - s2])) + \
                t3 * (f[c + s3] + f[c - s3])
    else:
        for c in range(inner_lo, inner_hi):
            out[c] = (((t0 * f[c] + t1 * (f[c + s1] + f[c - s1])) + t2 * (f[c + s2] + f[c - s2])) +
                      t3 * (f[c + s3] + f[c - s3])) + t4 * (f[c + s4] + f[c - s4])


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _x_cell(f, taps_x, mx, c, nz, size):
    """One flat cell c of filter_x (f flat, size cells), its terms in filter_x's order, wrapping."""
    acc = taps_x[0] * f[c]
    for m in range(1, mx + 1):
        shift = np.uint64(m * nz)
        east = c + shift if c + shift < size else c + shift - size
        west = c - shift if c >= shift else c + size - shift
        acc += taps_x[m] * (f[east] + f[west])
    return acc


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _x_passes(f, out, taps_x, mx, nz, lo, hi):
    """filter_x for any mx on flat cells lo <= c < hi: one pass per tap (f, out: flat)."""
    size = np.uint64(f.size)
    t0 = taps_x[0]
    for c in range(lo, hi):
        out[c] = t0 * f[c]
    for m in range(1, mx + 1):
        t = taps_x[m]
        shift = np.uint64(m * nz)
        back = size - shift
        for c in range(lo, min(shift, hi)):                  # (unsigned: no negative-index checks)
            out[c] += t * (f[c + shift] + f[c + back])
        for c in range(max(shift, lo), min(back, hi)):
            out[c] += t * (f[c + shift] + f[c - shift])
        for c in range(max(back, lo), hi):
            out[c] += t * (f[c - back] + f[c - shift])


@njit(cache=NUMBA_CACHE, error_model="numpy")
def filter_z(source, target, bands, mz, i0, i1):
    """target = the band matrix of diagonals bands[mz + d, j] (d = -mz..mz) times source, along z,
    on the columns i0 <= i < i1: target[i, j] = sum_d bands[mz + d, j] source[i, j + d] (S_z with
    bands_z[0], S_z^T with [1]; mz = 0: a copy), summed d = 0, +1, -1, +2, -2, ... per cell (the
    terms with j + d inside the column). For mz <= 4 a column's inner rows take every term in one
    expression (one store per cell; the same sums in the same order), its mz rows at each end
    _z_cell; otherwise one pass per diagonal. Flat unsigned indices (no negative-index checks)."""
    nx, nz = source.shape
    f = source.reshape(source.size)
    out = target.reshape(target.size)
    unz = np.uint64(nz)
    zero = np.uint64(0)
    if mz == 0:
        for c in range(np.uint64(i0) * unz, np.uint64(i1) * unz):
            out[c] = f[c]
        return
    if mz > 4 or nz <= 2 * mz:
        _z_passes(f, out, bands, mz, nz, i0, i1)
        return
    m = np.uint64(mz)
    c0 = bands[mz]
    u1, d1 = bands[mz + 1], bands[mz - 1]
    u2, d2 = bands[mz + 2 if mz >= 2 else mz], bands[mz - 2 if mz >= 2 else mz]
    u3, d3 = bands[mz + 3 if mz >= 3 else mz], bands[mz - 3 if mz >= 3 else mz]
    u4, d4 = bands[mz + 4 if mz >= 4 else mz], bands[mz - 4 if mz >= 4 else mz]
    for i in range(np.uint64(i0), np.uint64(i1)):
        base = i * unz
        for j in range(zero, m):
            out[base + j] = _z_cell(f, bands, mz, base, j, unz)
        for j in range(unz - m, unz):
            out[base + j] = _z_cell(f, bands, mz, base, j, unz)
        one, two, three, four = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)
        if mz == 1:
            for j in range(m, unz - m):
                k = base + j
                out[k] = (c0[j] * f[k] + u1[j] * f[k + one]) + d1[j] * f[k - one]
        elif mz == 2:
            for j in range(m, unz - m):
                k = base + j
                out[k] = (((c0[j] * f[k] + u1[j] * f[k + one]) + d1[j] * f[k - one]) + u2[j] * f[k + two]) + \
                    d2[j] * f[k - two]
        elif mz == 3:
            for j in range(m, unz - m):
                k = base + j
                out[k] = (((((c0[j] * f[k] + u1[j] * f[k + one]) + d1[j] * f[k - one]) + u2[j] * f[k + two]) +
                           d2[j] * f[k - two]) + u3[j] * f[k + three]) + d3[j] * f[k - three]
        else:
            for j in range(m, unz - m):
                k = base + j
                out[k] = (((((((c0[j] * f[k] + u1[j] * f[k + one]) + d1[j] * f[k - one]) + u2[j] * f[k + two]) +
                             d2[j] * f[k - two]) + u3[j] * f[k + three]) + d3[j] * f[k - three]) +
                          u4[j] * f[k + four]) + d4[j] * f[k - four]


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _z_cell(f, bands, mz, base, j, unz):
    """One cell (row j of the column at flat offset base) of filter_z, its terms in filter_z's order."""
    acc = bands[mz][j] * f[base + j]
    for m in range(1, mz + 1):
        d = np.uint64(m)
        if j + d < unz:
            acc += bands[mz + m][j] * f[base + j + d]
        if j >= d:
            acc += bands[mz - m][j] * f[base + j - d]
    return acc


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _z_passes(f, out, bands, mz, nz, i0, i1):
    """filter_z for any mz: one pass per diagonal over each column (f, out: flat)."""
    unz = np.uint64(nz)
    zero = np.uint64(0)
    centre = bands[mz]
    for i in range(np.uint64(i0), np.uint64(i1)):
        base = i * unz
        for j in range(zero, unz):
            out[base + j] = centre[j] * f[base + j]
        for m in range(1, mz + 1):
            d = np.uint64(m)
            up = bands[mz + m]
            down = bands[mz - m]
            for j in range(zero, unz - d):
                out[base + j] += up[j] * f[base + j + d]
            for j in range(d, unz):
                out[base + j] += down[j] * f[base + j - d]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def apply_filter(field, tmp, taps_x, bands_z, mx, mz):
    """field = S field in place (S_x into tmp, then S_z back); tmp: float64[nx, nz] scratch."""
    nx = field.shape[0]
    filter_x(field, tmp, taps_x, mx, 0, nx)
    filter_z(tmp, field, bands_z[0], mz, 0, nx)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def apply_filter_transpose(field, tmp, taps_x, bands_z, mx, mz):
    """field = S^T field in place (S_z^T into tmp, then S_x back); tmp: float64[nx, nz] scratch."""
    nx = field.shape[0]
    filter_z(field, tmp, bands_z[1], mz, 0, nx)
    filter_x(tmp, field, taps_x, mx, 0, nx)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def velocity_moments(s, ux, uz, i0, i1):
    """ux, uz *= s in place on the columns i0 <= i < i1: the moments S filters, so that the filtered
    velocity is S(s u) / S(s) (velocities_of_moments; kernels.fluid_update.filter_begin .. filter_end)."""
    nz = s.shape[1]
    sf, xf, zf = s.reshape(s.size), ux.reshape(ux.size), uz.reshape(uz.size)
    for c in range(np.uint64(i0 * nz), np.uint64(i1 * nz)):
        xf[c] *= sf[c]
        zf[c] *= sf[c]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def velocities_of_moments(s, ux, uz, i0, i1):
    """ux, uz /= s in place on the columns i0 <= i < i1 once s and the moments are filtered (as
    u * (1/s); 0 where s = 0: a select, so that the loop vectorises)."""
    nz = s.shape[1]
    sf, xf, zf = s.reshape(s.size), ux.reshape(ux.size), uz.reshape(uz.size)
    for c in range(np.uint64(i0 * nz), np.uint64(i1 * nz)):
        solid = sf[c] > 0.0
        inv = 1.0 / sf[c]
        xf[c] = xf[c] * inv if solid else 0.0
        zf[c] = zf[c] * inv if solid else 0.0
