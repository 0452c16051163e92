"""Rigid block on a spring: the top-wall integrator alone (kernels.step.wall_kick) with an
imposed Coulomb friction, physics.md sections 1, 3 and 7.

Per unit wall length: mass m (params WALL_MASS holds the total m L), spring k, normal stress
sigma; all forces are per length times L. The friction force is written into wall[W_FX]
where the grains' force would be: stuck, it balances the spring up to mu_s sigma L;
sliding, it is -mu_d sigma L sign(v). The step is _step's wall part, in _step's order:
half kick, drift, clock, forces, half kick.

Ideal stick-slip (V -> 0): slip duration pi sqrt(m/k), peak velocity dmu sigma / sqrt(k m),
slip 2 dmu sigma / k, recurrence 2 dmu sigma / (k V).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy.optimize import brentq

from gouge_cli.kernels import layout as L

from gouge_cli.kernels import step as K

W_X, W_Z, W_VX, W_VZ, W_FX, W_FZ = L.W_X, L.W_Z, L.W_VX, L.W_VZ, L.W_FX, L.W_FZ
DT, WIDTH, SIGMA, SPRING, V_LOAD = L.DT, L.WIDTH, L.SIGMA, L.SPRING, L.V_LOAD
C_TIME, C_DRIVE_TIME = L.C_TIME, L.C_DRIVE_TIME
wall_kick = K.wall_kick


@njit
def stick_slip(wall, clock, params, mu_s, mu_d, nsteps, events):
    """Run the block; events[e] = (t start, t end, x start, x end, peak v) per slip.
    Returns the number of complete slips."""
    dt = params[DT]
    length = params[WIDTH]
    sigma = params[SIGMA]
    sliding = False
    direction = 0.0
    peak = 0.0
    n = 0
    for _ in range(nsteps):
        wall_kick(wall, clock, params)
        wall[W_X] += dt * wall[W_VX]
        wall[W_Z] += dt * wall[W_VZ]
        clock[C_TIME] += dt
        clock[C_DRIVE_TIME] += dt
        spring = params[SPRING] * length * (params[V_LOAD] * clock[C_DRIVE_TIME] - wall[W_X])
        if sliding and wall[W_VX] * direction <= 0.0:        # velocity reversed: sticks
            sliding = False
            wall[W_VX] = 0.0
            events[n, 1] = clock[C_TIME]
            events[n, 3] = wall[W_X]
            events[n, 4] = peak
            n += 1
            if n == events.shape[0]:
                return n
        if not sliding:
            if abs(spring) <= mu_s * sigma * length:
                wall[W_FX] = -spring
            else:
                sliding = True
                direction = 1.0 if spring > 0.0 else -1.0
                peak = 0.0
                events[n, 0] = clock[C_TIME]
                events[n, 2] = wall[W_X]
        if sliding:
            wall[W_FX] = -mu_d * sigma * length * direction
        wall[W_FZ] = sigma * length        # the normal load is carried: no motion across
        wall_kick(wall, clock, params)
        if sliding:
            peak = max(peak, abs(wall[W_VX]))
    return n


def make_params(dt, length, sigma, k, v_load, m):
    p = np.zeros(L.N_PARAMS)
    p[DT], p[WIDTH], p[SIGMA], p[SPRING], p[V_LOAD] = dt, length, sigma, k, v_load
    p[L.WALL_MASS] = m * length       # total mass m_b L_x
    p[L.DRIVE] = 1.0
    return p


def exact_slip(m, k, sigma, dmu, v_load):
    """Slip of the block including the loading during the slip: in the frame of the load
    point u = x - V t obeys m u'' = -k u - mu_d sigma with u(0) = -mu_s sigma / k, u'(0) = -V;
    x' = w A sin(wt) + V (1 - cos wt), A = dmu sigma / k. Slip ends at x' = 0, wt in (pi, 2pi)."""
    w = math.sqrt(k / m)
    a = dmu * sigma / k

    def speed(th):
        return w * a * math.sin(th) + v_load * (1.0 - math.cos(th))
    end = brentq(speed, math.pi, 1.5 * math.pi, xtol=1e-15)
    peak_th = brentq(lambda th: w * a * math.cos(th) + v_load * math.sin(th), 0.0, math.pi, xtol=1e-15)
    slip = a * (1.0 - math.cos(end)) + v_load * (end - math.sin(end)) / w
    return end / w, slip, speed(peak_th)


@pytest.mark.parametrize("length", [1.0, 10.0, 64.0])
def test_block_slider(length):
    m, k, sigma, mu_s, mu_d, v_load, dt = 1.0, 1e-2, 1e-2, 0.6, 0.5, 1e-5, 0.02
    dmu = mu_s - mu_d
    params = make_params(dt, length, sigma, k, v_load, m)
    wall, clock = np.zeros(L.N_WALL), np.zeros(L.N_CLOCK)
    events = np.zeros((3, 5))
    t_end = (mu_s * sigma + 2.5 * 2 * dmu * sigma) / (k * v_load)     # three slips
    n = stick_slip(wall, clock, params, mu_s, mu_d, int(t_end / dt), events)
    assert n == 3
    duration = events[:, 1] - events[:, 0]
    slip = events[:, 3] - events[:, 2]
    peak = events[:, 4]
    recurrence = np.diff(events[:, 0])
    ideal = dict(duration=math.pi * math.sqrt(m / k), peak=dmu * sigma / math.sqrt(k * m),
                 slip=2 * dmu * sigma / k, recurrence=2 * dmu * sigma / (k * v_load))
    # first slip starts when the spring reaches mu_s sigma
    assert events[0, 0] == pytest.approx(mu_s * sigma / (k * v_load), abs=2 * dt)
    for measured, key in ((duration, "duration"), (peak, "peak"), (slip, "slip"), (recurrence, "recurrence")):
        assert np.allclose(measured, ideal[key], rtol=0.02), (key, measured, ideal[key])
    t_exact, slip_exact, peak_exact = exact_slip(m, k, sigma, dmu, v_load)
    assert np.allclose(duration, t_exact, rtol=0, atol=1.01 * dt)
    assert np.allclose(slip, slip_exact, rtol=2e-4)
    assert np.allclose(peak, peak_exact, rtol=2e-4)
    assert np.allclose(recurrence, slip_exact / v_load, rtol=2e-4)


def test_free_fall_under_normal_stress():
    """No grain force: M z'' = -sigma L, M = m L (exact for a constant force in Verlet)."""
    m, sigma, length, dt = 0.7, 3e-4, 12.0, 0.1
    params = make_params(dt, length, sigma, 1e-3, 0.0, m)
    params[L.DRIVE] = 0.0        # compaction: no spring, no motion along x
    wall, clock = np.zeros(L.N_WALL), np.zeros(L.N_CLOCK)
    wall[W_VX] = 1.0
    for _ in range(1000):
        wall_kick(wall, clock, params)
        wall[W_X] += dt * wall[W_VX]
        wall[W_Z] += dt * wall[W_VZ]
        wall_kick(wall, clock, params)
    t = 1000 * dt
    assert wall[W_Z] == pytest.approx(-0.5 * sigma / m * t * t, rel=1e-12)
    assert wall[W_VZ] == pytest.approx(-sigma / m * t, rel=1e-12)
    assert wall[W_X] == 0.0 and wall[W_VX] == 0.0
