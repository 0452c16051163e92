"""The top-wall integrator alone (step.wall_kick, in _step's order) with imposed Coulomb friction:
a rigid block on a spring (thesis Eq. 3), the reference case of studies.analytic."""

from __future__ import annotations

from numba import njit

from . import NUMBA_CACHE
from .layout import C_DRIVE_TIME, C_TIME, DT, SIGMA, SPRING, V_LOAD, W_FX, W_FZ, W_VX, W_X, WIDTH
from .step import wall_kick


@njit(cache=NUMBA_CACHE)
def block_slip(wall, clock, params, mu_s, mu_d, nsteps, out):
    """The top-wall integrator (kernels.step.wall_kick, _step's order) with imposed Coulomb
    friction; out = (t start, t end, x start, x end, peak v) of the first complete slip.
    Returns 1 if a slip completed."""
    dt = params[DT]
    length = params[WIDTH]
    sigma = params[SIGMA]
    sliding = False
    peak = 0.0
    for _ in range(nsteps):
        wall_kick(wall, clock, params)
        wall[W_X] += dt * wall[W_VX]
        clock[C_TIME] += dt
        clock[C_DRIVE_TIME] += dt
        spring = params[SPRING] * length * (params[V_LOAD] * clock[C_DRIVE_TIME] - wall[W_X])
        if sliding and wall[W_VX] <= 0.0:
            out[1] = clock[C_TIME]
            out[3] = wall[W_X]
            out[4] = peak
            return 1
        if not sliding and spring > mu_s * sigma * length:
            sliding = True
            out[0] = clock[C_TIME]
            out[2] = wall[W_X]
        wall[W_FX] = -mu_d * sigma * length if sliding else -spring
        wall[W_FZ] = sigma * length
        wall_kick(wall, clock, params)
        if sliding:
            peak = max(peak, wall[W_VX])
    return 0
