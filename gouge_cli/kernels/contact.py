"""Hertz-Mindlin contact law for one pair of discs (thesis Eqs. 8-11, physics.md section 2).

Convention: n points from grain i to grain j, t = (-n_z, n_x). The pair record
holds the force ON j (the force on i is its negative) and ``-F_s``; the torque on
each grain of the pair is ``radius * (-F_s)``.
"""

from __future__ import annotations

import math

from numba import njit

from .. import NUMBA_CACHE


@njit(inline="always", cache=NUMBA_CACHE)
def hertz_mindlin(dx, dz, dvx, dvz, spin_sum, r_i, r_j, m_ij, shear, dt,
                  c_normal, c_tangential, damping, friction):
    """Contact force of a touching pair.

    dx, dz: x_j - x_i (minimum image) [d]; dvx, dvz: v_j - v_i [v0];
    spin_sum: R_i w_i + R_j w_j [v0]; m_ij: reduced mass [rho d^3];
    shear: tangential displacement ds before this step [d];
    c_normal = sqrt(2) E / (3 (1 - nu^2)), c_tangential = 2^1.5 E / ((2 - nu)(1 + nu)) * factor.
    Returns (fx_j, fz_j, minus_fs, new_shear, overlap, normal_force); overlap <= 0: no contact.
    """
    r2 = dx * dx + dz * dz
    rsum = r_i + r_j
    if r2 >= rsum * rsum:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    r = math.sqrt(r2)
    nx = dx / r
    nz = dz / r
    overlap = rsum - r
    r_ij = 2.0 * r_i * r_j / rsum
    root = math.sqrt(r_ij * overlap)
    v_n = dvx * nx + dvz * nz
    v_t = -dvx * nz + dvz * nx - spin_sum
    f_n = c_normal * root * overlap - damping * m_ij * v_n
    if f_n < 0.0:
        f_n = 0.0
    k_s = c_tangential * root
    ds = shear + v_t * dt
    f_s = -k_s * ds
    limit = friction * f_n
    if f_s > limit:
        f_s = limit
        ds = -f_s / k_s
    elif f_s < -limit:
        f_s = -limit
        ds = -f_s / k_s
    return f_n * nx - f_s * nz, f_n * nz + f_s * nx, -f_s, ds, overlap, f_n
