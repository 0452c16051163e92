"""The time-step loop with pore fluid: kernels.step plus a Goren pressure update every
`interval` steps. Only scenes with a fluid section import this module."""

from __future__ import annotations

from numba import njit

from .. import NUMBA_CACHE
from .fluid import fluid_update
from .step import BG_DAMPING, DT, FLUID_FAILED, K_STEP, LIST_OVERFLOW, OK, W_VX, W_VZ, W_Z, WIDTH, _step, close_step


@njit(cache=NUMBA_CACHE)
def advance_fluid(grains, lists, pair, wall, clock, params, counters, nsteps, drag_x, drag_z,
                  fluid, interval, z_bottom, fluid_status):
    """As kernels.step.advance, plus a pore-pressure update (kernels.fluid.fluid_update) after every
    `interval`-th step (step count multiple of interval) over dt_f = interval * dt; the drag
    it leaves in drag_x/drag_z acts on the grains until the next update. fluid: the tuple
    FluidGrid.kernel_args() without drag. Returns (FLUID_FAILED, steps) with fluid_status[0]
    set if the fluid update fails. The step before an update is not closed: the deposit takes
    the grains' whole-step velocities from the half kick they owe (the same bits)."""
    x, z, vx, vz, radius, inv_mass, body = grains[0], grains[1], grains[2], grains[3], grains[5], grains[7], grains[9]
    force_x, force_z = grains[10], grains[11]
    fparams, fstate, P, s, s_old, ux, uz, perm, div_u, work, corners, partial = fluid
    n = x.shape[0]
    dt_f = interval * params[DT]
    half = 0.5 * params[DT]
    owed = False
    for st in range(nsteps):
        update = (counters[K_STEP] + 1) % interval == 0       # this step ends with a fluid update
        close = st == nsteps - 1
        if not _step(grains, lists, pair, wall, clock, params, counters, drag_x, drag_z, owed, close):
            return LIST_OVERFLOW, st
        owed = not close
        if update:
            status = fluid_update(x, z, vx, vz, radius, n, params[WIDTH], z_bottom, wall[W_Z], dt_f,
                                  fparams, fstate, P, s, s_old, ux, uz, perm, div_u, work, corners, partial,
                                  drag_x, drag_z, (owed, force_x, force_z, inv_mass, body, half, params[BG_DAMPING],
                                                   wall[W_VX], wall[W_VZ]))
            if status != 0:
                if owed:
                    close_step(grains, wall, params)
                fluid_status[0] = status
                return FLUID_FAILED, st + 1
    return OK, nsteps
