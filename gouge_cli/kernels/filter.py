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
  wall), kernel_z[jo, ji] for |jo - ji| <= 3 sigma_z / dz, each column ji normalised to sum 1.

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
def filter_setup(width, dx, dz, taps_x, kernel_z):
    """Taps of S_x and the band of S_z for the current cell sizes; returns (mx, mz), the half widths
    in cells (0: no smoothing on that axis).

    taps_x : float64[nx] out, taps_x[m] for offsets 0..mx (symmetric), summing to 1 over -mx..mx
    kernel_z : float64[nz, nz] out, column-normalised Gaussian with wall images, zero outside the band
    """
    nx = taps_x.shape[0]
    nz = kernel_z.shape[0]
    sx, sz = filter_sigmas(width, dx, dz)
    mx = 0
    if sx > 1e-3 * dx:
        mx = min(int(math.ceil(TRUNCATION * sx / dx)), (nx - 1) // 2)
    mz = 0
    if sz > 1e-3 * dz:
        mz = min(int(math.ceil(TRUNCATION * sz / dz)), nz - 1)
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
        for ji in range(nz):
            zi = (ji + 0.5) * dz
            total = 0.0
            for jo in range(nz):
                kernel_z[jo, ji] = 0.0
            for jo in range(max(0, ji - mz), min(nz, ji + mz + 1)):
                zo = (jo + 0.5) * dz
                value = 0.0
                for distance in (zo - zi, zo + zi, 2.0 * thickness - zo - zi):
                    if abs(distance) <= reach:
                        u = distance / sz
                        value += math.exp(-0.5 * u * u)
                kernel_z[jo, ji] = value
                total += value
            for jo in range(max(0, ji - mz), min(nz, ji + mz + 1)):
                kernel_z[jo, ji] /= total
    return mx, mz


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _smooth_x(field, tmp, taps_x, mx):
    """tmp = S_x field (periodic circulant; symmetric, so also S_x^T)."""
    nx, nz = field.shape
    for i in range(nx):
        for j in range(nz):
            tmp[i, j] = taps_x[0] * field[i, j]
        for m in range(1, mx + 1):
            right = i + m if i + m < nx else i + m - nx
            left = i - m if i - m >= 0 else i - m + nx
            t = taps_x[m]
            for j in range(nz):
                tmp[i, j] += t * (field[right, j] + field[left, j])


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _smooth_z(source, target, kernel_z, mz, transpose):
    """target = S_z source (kernel_z[jo, ji]), or S_z^T source if transpose."""
    nx, nz = source.shape
    for i in range(nx):
        for jo in range(nz):
            acc = 0.0
            for ji in range(max(0, jo - mz), min(nz, jo + mz + 1)):
                k = kernel_z[ji, jo] if transpose else kernel_z[jo, ji]
                acc += k * source[i, ji]
            target[i, jo] = acc


@njit(cache=NUMBA_CACHE, error_model="numpy")
def apply_filter(field, tmp, taps_x, kernel_z, mx, mz):
    """field = S field in place (S_x, then S_z); tmp: float64[nx, nz] scratch."""
    if mx > 0:
        _smooth_x(field, tmp, taps_x, mx)
    else:
        tmp[:, :] = field
    if mz > 0:
        _smooth_z(tmp, field, kernel_z, mz, False)
    else:
        field[:, :] = tmp


@njit(cache=NUMBA_CACHE, error_model="numpy")
def apply_filter_transpose(field, tmp, taps_x, kernel_z, mx, mz):
    """field = S^T field in place (S_z^T, then S_x); tmp: float64[nx, nz] scratch."""
    if mz > 0:
        _smooth_z(field, tmp, kernel_z, mz, True)
    else:
        tmp[:, :] = field
    if mx > 0:
        _smooth_x(tmp, field, taps_x, mx)
    else:
        field[:, :] = tmp


@njit(cache=NUMBA_CACHE, error_model="numpy")
def filter_deposit(s, ux, uz, grad_s_x, grad_s_z, tmp, taps_x, kernel_z, mx, mz):
    """The deposit's fields filtered in place: s~ = S s, grad s~ = S grad s (the same linear map of
    the same deposit, so still its derivative with respect to the cell position), and the
    velocities as S(s u) / S(s) (0 where S(s) = 0). All float64[nx, nz]."""
    if mx == 0 and mz == 0:
        return
    nx, nz = s.shape
    for i in range(nx):
        for j in range(nz):
            ux[i, j] *= s[i, j]
            uz[i, j] *= s[i, j]
    apply_filter(s, tmp, taps_x, kernel_z, mx, mz)
    apply_filter(ux, tmp, taps_x, kernel_z, mx, mz)
    apply_filter(uz, tmp, taps_x, kernel_z, mx, mz)
    apply_filter(grad_s_x, tmp, taps_x, kernel_z, mx, mz)
    apply_filter(grad_s_z, tmp, taps_x, kernel_z, mx, mz)
    for i in range(nx):
        for j in range(nz):
            if s[i, j] > 0.0:
                inv = 1.0 / s[i, j]
                ux[i, j] *= inv
                uz[i, j] *= inv
            else:
                ux[i, j] = 0.0
                uz[i, j] = 0.0
