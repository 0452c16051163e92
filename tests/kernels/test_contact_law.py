"""The pair force law alone (kernels.hertz_mindlin.force), against closed forms; the law's one
selection point (kernels.contact): its force, energy, constants and stiffness agree.

physics.md sections 2 and 7: Hertz static law F = 0.3472 xi^1.5 for equal grains of d = 1
(E = 1, nu = 0.2), the dashpot clip, and the Mindlin-type tangential spring with Coulomb
plateau and history (slope k_s, plateau mu F_n, elastic slope again on reversal).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gouge_cli.config import build_config
from gouge_cli.kernels import contact, forces, measure
from gouge_cli.kernels.hertz_mindlin import force as hertz_mindlin
from gouge_cli.model.portable import power
from gouge_cli.model.timestep import contact_constants, stability_bound

E, NU = 1.0, 0.2
C_N, C_T = contact_constants(build_config({}))
K_EQUAL = 0.3472  # physics.md: F = 0.3472 xi^1.5 for two grains of d = 1


def call(dx, dz=0.0, dvx=0.0, dvz=0.0, spin_sum=0.0, r_i=0.5, r_j=0.5, m_ij=math.pi / 12.0,
         shear=0.0, dt=0.01, damping=0.0, friction=0.5):
    """(fx_j, fz_j, -F_s, ds, overlap, F_n). spin_sum = a_i w_i + a_j w_j is realised with equal
    spins on the contact-point arms a = R - overlap/2 (which sum to the distance r)."""
    r = math.hypot(dx, dz)
    w = spin_sum / r if r > 0 else 0.0
    r_ij = 2.0 * r_i * r_j / (r_i + r_j)
    fx, fz, ti, tj, ds, xi, fn = hertz_mindlin(dx, dz, dvx, dvz, w, w, r_i, r_j, r_ij, m_ij, shear, dt,
                                               C_N, C_T, damping, friction)
    mfs = ti / (r_i - 0.5 * xi) if xi > 0 else 0.0
    if xi > 0:
        assert tj == pytest.approx(mfs * (r_j - 0.5 * xi), rel=1e-14, abs=1e-300)
    return fx, fz, mfs, ds, xi, fn


def test_contact_constants_match_physics_md():
    assert C_N == pytest.approx(math.sqrt(2.0) * E / (3.0 * (1.0 - NU ** 2)), rel=1e-15)
    assert C_T == pytest.approx(2.0 ** 1.5 * E / ((2.0 - NU) * (1.0 + NU)), rel=1e-15)
    # equal grains, d = 1: R_ij = 0.5; Hertz 4/3 E* sqrt(R*) with E* = E/(2(1-nu^2)), R* = 1/4
    assert C_N * math.sqrt(0.5) == pytest.approx(4.0 / 3.0 * E / (2 * (1 - NU ** 2)) * 0.5, rel=1e-14)
    assert C_N * math.sqrt(0.5) == pytest.approx(K_EQUAL, rel=1e-3)


@pytest.mark.parametrize("overlap", [1e-6, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1])
@pytest.mark.parametrize("angle", [0.0, 0.7, 2.5, -1.9])
def test_hertz_static_equal_grains(overlap, angle):
    r = 1.0 - overlap
    dx, dz = r * math.cos(angle), r * math.sin(angle)
    fx, fz, mfs, ds, xi, fn = call(dx, dz)
    assert xi == pytest.approx(overlap, rel=1e-9)
    assert fn == pytest.approx(K_EQUAL * overlap ** 1.5, rel=1e-3)
    # force on j is repulsive, along n = (x_j - x_i)/r; no tangential force without motion
    assert fx == pytest.approx(fn * math.cos(angle), rel=1e-12, abs=1e-300)
    assert fz == pytest.approx(fn * math.sin(angle), rel=1e-12, abs=1e-300)
    assert mfs == 0.0 and ds == 0.0


@pytest.mark.parametrize("r_i,r_j", [(0.4, 0.6), (0.4, 0.4), (0.6, 0.55), (0.5, 0.41)])
def test_hertz_static_unequal_grains(r_i, r_j):
    """F = 4/3 E* sqrt(R*) xi^1.5 with R* = R_i R_j / (R_i + R_j) (Hertz for spheres)."""
    e_star = E / (2.0 * (1.0 - NU ** 2))
    r_star = r_i * r_j / (r_i + r_j)
    for overlap in (1e-4, 1e-3, 1e-2):
        fn = call(r_i + r_j - overlap, r_i=r_i, r_j=r_j)[5]
        assert fn == pytest.approx(4.0 / 3.0 * e_star * math.sqrt(r_star) * overlap ** 1.5, rel=1e-12)


def test_no_force_when_apart():
    assert call(1.0 + 1e-12) == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert call(0.7, 0.72, shear=0.3) == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # shear forgotten on separation


def test_dashpot_and_clip():
    """F_n = K xi^1.5 - gamma m_ij v_n, clipped at 0 (damping must not pull)."""
    xi, gamma, m = 1e-3, 0.05, math.pi / 12.0
    static = K_EQUAL * xi ** 1.5
    # approaching (v_n = (v_j - v_i).n < 0): more repulsion
    fn = call(1.0 - xi, dvx=-1e-3, damping=gamma)[5]
    assert fn == pytest.approx(C_N * math.sqrt(0.5) * xi ** 1.5 + gamma * m * 1e-3, rel=1e-12)
    assert fn > static
    # separating slowly: less repulsion; fast: clipped to exactly 0, no friction either
    fn = call(1.0 - xi, dvx=1e-4, damping=gamma)[5]
    assert fn == pytest.approx(C_N * math.sqrt(0.5) * xi ** 1.5 - gamma * m * 1e-4, rel=1e-12)
    fx, fz, mfs, ds, ov, fn = call(1.0 - xi, dvx=1.0, dvz=1e-3, damping=gamma)
    assert fn == 0.0 and fx == 0.0 and fz == 0.0 and mfs == 0.0 and ov == pytest.approx(xi)


def _shear_path(xi, velocities, dt=0.01, friction=0.5, spin=False):
    """Hold the pair at overlap xi (n = +x, t = +z) and impose a tangential velocity history;
    feed ds back as the engine does. Returns arrays (ds, -F_s, F_n, F_z on j)."""
    shear = 0.0
    rows = []
    for u in velocities:
        if spin:   # same relative tangential velocity from rotation: v_t = -(R_i w_i + R_j w_j)
            out = call(1.0 - xi, spin_sum=-u, shear=shear, dt=dt, friction=friction)
        else:
            out = call(1.0 - xi, dvz=u, shear=shear, dt=dt, friction=friction)
        shear = out[3]
        rows.append((shear, out[2], out[5], out[1]))
    return np.array(rows).T


@pytest.mark.parametrize("spin", [False, True])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_tangential_law_slope_plateau_reversal(spin, sign):
    """Load to the plateau, reverse, reverse again: each reversal unloads from one plateau with
    the elastic slope k_s and travels 2 mu F_n / k_s to the other (both branches of the clip)."""
    xi, mu, dt, u = 4e-3, 0.5, 0.01, sign * 1e-4
    k_s = 2 ** 1.5 * E / ((2 - NU) * (1 + NU)) * math.sqrt(0.5 * xi)
    f_n = K_EQUAL * xi ** 1.5
    n_slip = mu * f_n / k_s / (abs(u) * dt)   # steps from 0 to the plateau
    legs = [int(2.5 * n_slip), int(4.0 * n_slip), int(4.0 * n_slip)]
    vel = np.concatenate([np.full(legs[0], u), np.full(legs[1], -u), np.full(legs[2], u)])
    ds, mfs, fn, fz = _shear_path(xi, vel, dt=dt, friction=mu, spin=spin)

    assert np.allclose(fn, f_n, rtol=1e-3)
    # friction opposes the relative motion of j: F on j along t = +z is -mfs
    assert np.allclose(fz, -mfs, rtol=1e-14, atol=0)
    # loading: elastic slope k_s (-F_s = k_s ds exactly) until the plateau
    leg = slice(0, legs[0])
    elastic = np.abs(mfs[leg]) < 0.999 * mu * fn[leg]
    assert elastic.sum() == pytest.approx(n_slip, abs=2)
    assert np.polyfit(ds[leg][elastic], mfs[leg][elastic], 1)[0] == pytest.approx(k_s, rel=1e-9)
    assert np.allclose(mfs[leg][elastic], k_s * np.arange(1, elastic.sum() + 1) * u * dt, rtol=1e-9)
    # plateau sign(u) mu F_n, with ds reset so that k_s ds = mu F_n
    plateau = slice(int(1.5 * n_slip), legs[0])
    assert np.allclose(mfs[plateau], sign * mu * f_n, rtol=1e-3)
    assert np.allclose(mfs[plateau], sign * mu * fn[plateau], rtol=1e-14)
    assert np.allclose(ds[plateau], sign * mu * f_n / k_s, rtol=1e-3)
    # reversals
    edges = np.cumsum(legs)
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        to = -sign if k == 0 else sign               # the plateau this leg goes to
        f, d = mfs[a:b], ds[a:b]
        unload = to * f < 0.999 * mu * fn[a:b]
        assert np.all(unload[:int(1.9 * n_slip)])    # starts elastic at once: no dead band
        assert unload.sum() == pytest.approx(2 * n_slip, abs=2)   # travel 2 mu F_n / k_s
        assert np.polyfit(d[unload], f[unload], 1)[0] == pytest.approx(k_s, rel=1e-9)
        assert abs(mfs[a - 1]) == pytest.approx(mu * fn[a - 1], rel=1e-14)     # came off a plateau
        assert f[0] == pytest.approx(mfs[a - 1] + k_s * vel[a] * dt, rel=1e-9)  # k_s ds, ds += v_t dt
        assert np.allclose(f[~unload], to * mu * f_n, rtol=1e-3)


def test_tangential_force_sign_and_torque_convention():
    """t = (-n_z, n_x); v_t = (v_j - v_i).t - (R_i w_i + R_j w_j); returns -F_s = k_s ds."""
    xi, dt = 1e-3, 0.1
    k_s = C_T * math.sqrt(0.5 * xi)
    # n = +z, so t = -x: j moving -x relative to i is v_t > 0
    fx, fz, mfs, ds, _, fn = call(0.0, dz=1.0 - xi, dvx=-1e-5, dt=dt, friction=10.0)
    assert ds == pytest.approx(1e-5 * dt, rel=1e-12)
    assert mfs == pytest.approx(k_s * ds, rel=1e-12)
    assert fx == pytest.approx(mfs, rel=1e-12)          # F_s t = (-k_s ds)(-1, 0)
    assert fz == pytest.approx(fn, rel=1e-12)


def test_the_law_in_force_is_the_registered_one_everywhere():
    """One selection point: the pair pass, the observables and the time step's bound take the law
    from kernels.contact, and a registered law is its module's five functions."""
    from gouge_cli.kernels import hertz_mindlin as module

    law = contact.LAWS["hertz_mindlin"]
    assert contact.LAW is law and tuple(law[1:]) == (module.pair_constants, module.force, module.energy,
                                                      module.constants, module.stiffness)
    assert forces.pair_force is measure.pair_force is contact.pair_force is law.force
    assert measure.pair_energy is law.energy and forces.pair_constants is measure.pair_constants is law.pair_constants
    assert contact_constants(build_config({})) == law.constants(E, NU, 1.0)


@pytest.mark.parametrize("name", sorted(contact.LAWS))
@pytest.mark.parametrize("r_i,r_j", [(0.5, 0.5), (0.4, 0.6)])
def test_registered_law_force_energy_and_stiffness_agree(name, r_i, r_j):
    """For every registered law: the energy's slope is the static normal force, its tangential
    part k_s ds^2 / 2 with the slope of the tangential force; stiffness finds the overlap of a
    given force and the force's slopes there (what the step's stability bound uses)."""
    law = contact.LAWS[name]
    c_n, c_t = law.constants(E, NU, 1.0)
    r_ij, m_ij = law.pair_constants(r_i, r_j, 1.0, 1.0)

    def normal(xi):
        return law.force(r_i + r_j - xi, 0.0, 0.0, 0.0, 0.0, 0.0, r_i, r_j, r_ij, m_ij, 0.0, 0.0, c_n, c_t, 0.0,
                         0.5)[6]

    def tangential(xi, ds):
        return law.force(r_i + r_j - xi, 0.0, 0.0, 0.0, 0.0, 0.0, r_i, r_j, r_ij, m_ij, ds, 0.0, c_n, c_t, 0.0,
                         10.0)[1]

    for force in (1e-5, 3e-3, 0.1):
        xi, k_n, k_t = law.stiffness(force, r_ij, c_n, c_t, power)
        h = 1e-4 * xi
        assert normal(xi) == pytest.approx(force, rel=1e-10)
        assert (normal(xi + h) - normal(xi - h)) / (2 * h) == pytest.approx(k_n, rel=1e-6)
        u = law.energy
        assert (u(r_ij, xi + h, 0.0, c_n, c_t) - u(r_ij, xi - h, 0.0, c_n, c_t)) / (2 * h) == pytest.approx(
            force, rel=1e-7)
        ds = 1e-3 * xi
        assert -tangential(xi, ds) / ds == pytest.approx(k_t, rel=1e-10)       # elastic: F_s = -k_s ds
        assert u(r_ij, xi, ds, c_n, c_t) - u(r_ij, xi, 0.0, c_n, c_t) == pytest.approx(0.5 * k_t * ds * ds, rel=1e-6)


def test_hertz_energy_and_bound_against_closed_forms():
    """Equal grains of d = 1: U = 0.4 K xi^2.5 with K = 0.3472 (the integral of F = K xi^1.5);
    the default scene's bound from k_s = c_t sqrt(R xi), k_n = 1.5 c_n sqrt(R xi) at the chain
    force 10 sigma D_max (docs/physics/timestep.md)."""
    law = contact.LAWS["hertz_mindlin"]
    for xi in (1e-4, 1e-3, 1e-2):
        assert law.energy(0.5, xi, 0.0, C_N, C_T) == pytest.approx(0.4 * K_EQUAL * xi ** 2.5, rel=1e-3)
        assert law.energy(0.5, xi, 0.0, C_N, C_T) == pytest.approx(0.4 * C_N * math.sqrt(0.5) * xi ** 2.5, rel=1e-14)
    cfg = build_config({})
    d_min, sigma = cfg.packing.diameter_min, cfg.loading.normal_stress
    force = 10.0 * sigma * cfg.packing.diameter_max
    xi = (force / (C_N * math.sqrt(0.5 * d_min))) ** (2.0 / 3.0)
    mass = cfg.material.density * math.pi * d_min ** 3 / 6.0
    k_s = C_T * math.sqrt(0.5 * d_min * xi)
    k_n = 1.5 * C_N * math.sqrt(0.5 * d_min * xi)
    bound = stability_bound(cfg)
    assert bound.reference_overlap == pytest.approx(xi, rel=1e-14)
    assert bound.bound == pytest.approx(min(2 * math.sqrt(mass / 7 / k_s), 2 * math.sqrt(mass / 2 / k_n)), rel=1e-14)
