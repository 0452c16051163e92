"""The Hertz-Mindlin contact law for one pair of discs (thesis Eqs. 8-11, docs/physics/contacts.md):
its force, stored energy, constants and stiffness (registered in kernels.contact, which every
caller goes through).

Convention: n points from grain i to grain j, t = (-n_z, n_x). The pair record
holds the force ON j (the force on i is its negative) and the torque on each grain.

Lever arms [choice, departs from the thesis; docs/physics/contacts.md]: the tangential force acts at the contact
point, a_i = R_i - xi/2 from centre i and a_j = R_j - xi/2 from centre j, so a_i + a_j = r
and the pair's torques balance the moment of its forces: angular momentum is conserved
exactly (with arms R_i, R_j each contact would inject a net torque xi F_s). The same arms
enter the slip velocity v_t, so the tangential spring does no net work. The difference to
the thesis's R_i, R_j is O(xi / R) (about 1 % at sigma = 3e-4).
"""

from __future__ import annotations

import math

from numba import njit

from . import NUMBA_CACHE


@njit(inline="always", cache=NUMBA_CACHE)
def pair_constants(r_i, r_j, m_i, m_j):
    """(R_ij, m_ij): effective radius 2 R_i R_j / (R_i + R_j) [d] (thesis Eq. 9) and reduced mass
    m_i m_j / (m_i + m_j) [rho d^3] of a pair; the one expression for both (same bits wherever
    they are computed)."""
    return 2.0 * r_i * r_j / (r_i + r_j), m_i * m_j / (m_i + m_j)


@njit(inline="always", cache=NUMBA_CACHE)
def force(dx, dz, dvx, dvz, spin_i, spin_j, r_i, r_j, r_ij, m_ij, shear, dt, c_normal, c_tangential, damping,
          friction):
    """Contact force of a touching pair.

    dx, dz: x_j - x_i (minimum image) [d]; dvx, dvz: v_j - v_i [v0];
    spin_i, spin_j: angular velocities [1/t0]; r_ij, m_ij: effective radius [d] and reduced
    mass [rho d^3] (pair_constants);
    shear: tangential displacement ds before this step [d];
    c_normal = sqrt(2) E / (3 (1 - nu^2)), c_tangential = 2^1.5 E / ((2 - nu)(1 + nu)) * factor.
    Returns (fx_j, fz_j, torque_i, torque_j, new_shear, overlap, normal_force); all zero
    when not touching. torque = a (-F_s) with a = R - overlap/2 (thesis Eq. 11).
    """
    r2 = dx * dx + dz * dz
    rsum = r_i + r_j
    if r2 >= rsum * rsum:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    r = math.sqrt(r2)
    nx = dx / r
    nz = dz / r
    overlap = rsum - r
    arm_i = r_i - 0.5 * overlap
    arm_j = r_j - 0.5 * overlap
    root = math.sqrt(r_ij * overlap)
    v_n = dvx * nx + dvz * nz
    v_t = -dvx * nz + dvz * nx - (arm_i * spin_i + arm_j * spin_j)
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
    return f_n * nx - f_s * nz, f_n * nz + f_s * nx, -f_s * arm_i, -f_s * arm_j, ds, overlap, f_n


@njit(inline="always", cache=NUMBA_CACHE)
def energy(r_ij, overlap, shear, c_normal, c_tangential):
    """Elastic energy stored in a touching pair [E d^3]: the Hertz spring's integral
    0.4 c_n sqrt(R_ij xi) xi^2 plus the tangential spring's k_s ds^2 / 2 at today's k_s."""
    root = math.sqrt(r_ij * overlap)
    return 0.4 * c_normal * root * overlap * overlap + 0.5 * c_tangential * root * shear ** 2


def constants(youngs_modulus, poisson_ratio, tangential_factor):
    """(c_normal, c_tangential) [E]: F_n = c_n sqrt(R xi) xi (thesis Eq. 9), k_s = c_t sqrt(R xi)
    (Eq. 10) times tangential_factor (material.tangential_stiffness_factor). Host side: plain
    Python, correctly rounded operations only."""
    nu = poisson_ratio
    c_normal = math.sqrt(2.0) * youngs_modulus / (3.0 * (1.0 - nu * nu))
    c_tangential = 2.0 * math.sqrt(2.0) * youngs_modulus / ((2.0 - nu) * (1.0 + nu)) * tangential_factor
    return c_normal, c_tangential


def stiffness(normal_force, r_ij, c_normal, c_tangential, power):
    """(overlap [d], k_normal, k_tangential [E d]) of a pair of effective radius r_ij [d] pressed
    together by a normal force [E d^2]: xi = (F / (c_n sqrt(R)))^(2/3), k_n = dF_n/dxi =
    1.5 c_n sqrt(R xi), k_s = c_t sqrt(R xi), for the step's stability bound (model.timestep).
    power(x, e): x**e with the same bits on every machine (model.portable.power)."""
    overlap = power(normal_force / (c_normal * math.sqrt(r_ij)), 2.0 / 3.0)
    k_tangential = c_tangential * math.sqrt(r_ij * overlap)
    k_normal = 1.5 * c_normal * math.sqrt(r_ij * overlap)
    return overlap, k_normal, k_tangential
