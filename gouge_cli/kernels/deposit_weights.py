"""One grain's share of the pressure grid (thesis Appendix E; docs/physics/fluid.md): its in-domain
area (the disc minus the segments beyond the wall planes) and its bilinear weights on the four
cells around its centre. The deposit (deposit.py) and the drag (drag.py) weight with these same
functions, so the drag goes back through the deposit's transpose. Grid conventions: deposit.py.
"""

import math

import numpy as np
from numba import njit

from . import NUMBA_CACHE


NEAR_PLANE = 1e-8      # |h| <= NEAR_PLANE R: a disc centred on a plane (in_domain_area, near_side_area)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def near_side_area(h, radius):
    """Area [d^2] of a disc on its centre's side of a line at signed distance h, for |h| <=
    NEAR_PLANE radius: R (pi R/2 + 2h), the series of R^2 (pi - acos u + u sqrt(1 - u^2)), u = h/R,
    to first order; the next term, R^2 u^3/3, is below 4e-25 R^2, far below round-off. Without
    calls, branches or a division, so that the vector loop of _corners_range takes the wall
    grains (centred on their plane to round-off: |h| ~ 1e-13 R) with in_domain_area's bits."""
    return radius * (0.5 * math.pi * radius + 2.0 * h)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def segment_area(h, radius):
    """Area of a disc beyond a line at signed distance h from its centre.

    h > 0: the centre is on the kept side. Returns 0 for h >= radius and
    pi radius^2 for h <= -radius; R^2 (a - sin a)/2 with a the subtended
    angle, by its series for small a (no cancellation near tangency).
    """
    if h >= radius:
        return 0.0
    if h <= -radius:
        return math.pi * radius * radius
    angle = 2.0 * math.atan2(math.sqrt((radius - h) * (radius + h)), h)
    if angle < 0.1:
        a2 = angle * angle
        angle_minus_sine = angle * a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0 * (1.0 - a2 / 72.0)))
    else:
        angle_minus_sine = angle - math.sin(angle)
    return 0.5 * radius * radius * angle_minus_sine


@njit(cache=NUMBA_CACHE, error_model="numpy")
def in_domain_area(z, radius, z_bot, z_top):
    """Area [d^2] of a disc (centre height z) between the planes z_bot and z_top.

    The area above z_bot minus the area above z_top, each from the small
    segment side so that a nearly tangent plane loses no precision, or for a
    plane through the centre to within NEAR_PLANE R (a wall grain) by near_side_area.
    """
    full = math.pi * radius * radius
    h = z - z_bot
    if abs(h) <= NEAR_PLANE * radius:
        above_bot = near_side_area(h, radius)
    else:
        above_bot = full - segment_area(h, radius) if h >= 0.0 else segment_area(-h, radius)
    h = z_top - z
    if abs(h) <= NEAR_PLANE * radius:
        above_top = near_side_area(-h, radius)
    else:
        above_top = segment_area(h, radius) if h >= 0.0 else full - segment_area(-h, radius)
    area = above_bot - above_top
    if area < 0.0:
        return 0.0
    return area


@njit(cache=NUMBA_CACHE, error_model="numpy")
def grain_area(z, radius, z_bot, z_top):
    """In-domain area [d^2] with a fast path for a grain clear of both planes."""
    if z - z_bot >= radius and z_top - z >= radius:
        return math.pi * radius * radius
    return in_domain_area(z, radius, z_bot, z_top)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def cell_weights(x, z, inv_dx, inv_dz, z_bot, nx, nz):
    """Bilinear (cloud-in-cell) weights of a point; inv_dx = 1/dx, inv_dz = 1/dz.

    Returns (i0, i1, j0, fx, fz, slope_z): the point spreads (1-fx)(1-fz) on
    (i0, j0), fx(1-fz) on (i1, j0), (1-fx) fz on (i0, j0+1) and fx fz on
    (i1, j0+1). Periodic in x; in z a point outside the span of cell centres puts
    all its weight on the nearest boundary cell, where the weights do not vary
    with z: slope_z = d fz / dz is inv_dz inside and 0 there (a non-finite z
    also lands there, so indices stay in range). Requires nz >= 2.
    """
    xi = x * inv_dx - 0.5
    fi = math.floor(xi)
    fx = xi - fi
    i0 = int(fi)
    if i0 < 0 or i0 >= nx:
        i0 = i0 % nx
    i1 = i0 + 1
    if i1 == nx:
        i1 = 0
    zeta = (z - z_bot) * inv_dz - 0.5
    fj = math.floor(zeta)
    if fj >= nz - 1:
        return i0, i1, nz - 2, fx, 1.0, 0.0
    if fj >= 0.0:
        return i0, i1, int(fj), fx, zeta - fj, inv_dz
    return i0, i1, 0, fx, 0.0, 0.0


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def corner_shares(area, i0, i1, j0, fx, fz, nz):
    """Flat indices of the four cells around a point and the area each receives (same weights
    for the deposit and the drag): (c00, c10, c01, c11, a00, a10, a01, a11)."""
    c00 = np.uint64(i0 * nz + j0)
    c10 = np.uint64(i1 * nz + j0)
    a0 = area * (1.0 - fz)
    a1 = area * fz
    return (c00, c10, c00 + np.uint64(1), c10 + np.uint64(1),
            a0 * (1.0 - fx), a0 * fx, a1 * (1.0 - fx), a1 * fx)
