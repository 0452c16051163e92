"""The time-step loop with pore fluid: kernels.step plus a Goren pressure update every
`interval` steps. Only scenes with a fluid section import this module."""

from __future__ import annotations

from numba import njit, prange

from . import NUMBA_CACHE
from .atomics import fetch_add
from .layout import (BG_DAMPING, DT, FLUID_FAILED, K_NEED_REBUILD, K_STEP, LIST_OVERFLOW,
                     OK, THREADS, WIDTH, W_VX, W_VZ, W_Z)
from .fluid_update import fluid_begin, fluid_drag, fluid_finish_deposit, fluid_solve
from .step import _step, close_step, move_range, open_step


@njit(cache=NUMBA_CACHE)
def advance_fluid(grains, lists, pair, wall, clock, params, counters, nsteps, drag_x, drag_z,
                  fluid, interval, z_bottom, fluid_status):
    """As kernels.step.advance, plus a pore-pressure update (kernels.fluid_update.fluid_update) after every
    `interval`-th step (step count multiple of interval) over dt_f = interval * dt; the drag
    it leaves in drag_x/drag_z acts on the grains until the next update. fluid: the grid's
    arrays by name (kernels.layout.FluidArrays, FluidGrid.record()). Returns (FLUID_FAILED, steps) with fluid_status[0]
    set if the fluid update fails (the grains may then be drifted into the next step).

    The step before an update is not closed: the deposit takes the grains' whole-step
    velocities from the half kick they owe. When another step follows in this call, its
    steps 1-2 (wall, kicks and drift: they need neither the pressure nor the drag) run while
    the grid is solved (_solve_and_drift). Both keep the bits of doing one thing after the
    other."""
    x, z, vx, vz, radius = grains.x, grains.z, grains.vx, grains.vz, grains.radius
    force_x, force_z, inv_mass, body = grains.force_x, grains.force_z, grains.inv_mass, grains.body
    n = x.shape[0]
    width = params[WIDTH]
    dt_f = interval * params[DT]
    half = 0.5 * params[DT]
    serial = params[THREADS] <= 1.0          # (the deposit in plain loops)
    owed = False
    drifted = False
    for st in range(nsteps):
        update = (counters[K_STEP] + 1) % interval == 0       # this step ends with a fluid update
        close = st == nsteps - 1
        if not _step(grains, lists, pair, wall, clock, params, counters, drag_x, drag_z, owed, close, drifted):
            return LIST_OVERFLOW, st
        owed = not close
        drifted = False
        if not update:
            continue
        z_top = wall[W_Z]
        overlap = not (close or n < 2)      # the next step's drift runs while the grid is solved
        kick = (owed, force_x, force_z, inv_mass, body, half, params[BG_DAMPING], wall[W_VX], wall[W_VZ])
        status = fluid_begin(x, z, vx, vz, radius, n, width, z_bottom, z_top, dt_f, fluid, kick, serial,
                             serial or not overlap)
        if status == 0:
            if not overlap:
                status = fluid_solve(width, z_bottom, z_top, dt_f, fluid)
            else:
                open_step(grains, wall, clock, params)
                late = _solve_and_drift(x, z, vx, vz, grains.spin, force_x, force_z, grains.torque, inv_mass,
                                        grains.inv_inertia, body, lists.x_build, lists.z_build, owed, params, width,
                                        z_bottom, z_top, dt_f, fluid, not serial, lists.cell_count)
                if late > 0:
                    counters[K_NEED_REBUILD] = 1
                status = lists.cell_count[0]
                drifted = True
            fluid_drag(n, width, fluid, drag_x, drag_z, status)
        if status != 0:
            if owed and not drifted:
                close_step(grains, wall, params)
            fluid_status[0] = status
            return FLUID_FAILED, st + 1
    return OK, nsteps


@njit(parallel=True, cache=NUMBA_CACHE)
def _solve_and_drift(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, x_build, z_build,
                     owed, params, width, z_bot, z_top, dt_f, fluid, pending, out):
    """fluid_solve (serial, grid only) while the threads run step 2 of the next step, the grains'
    kicks and drift (move_range), each grain on its own: the bits of one after the other.
    Every thread moves its own part of the grains (kernels.step.kick_drift's: the ones it holds
    in cache). If pending, the deposit's finish (deposit_finish: collect and expansion) must
    precede the solve: thread 1 takes it (fetch_add on a claim counter)
    before its own part, while thread 0 moves its own; thread 0 then waits for it (or, if no
    other thread claimed it yet, does it itself: no thread ever waits on one that has not
    started) and solves. On one thread: solve, then move every grain. Returns how many
    grains are now past skin/2; out: int64 scratch (>= threads + 3: the lists' cell_count),
    out[0] = fluid_solve's status.
    [Each thread keeps its own grains: having the other threads move thread 0's grains in chunks
    while it finished and solved was slower (those grains sit in the other core's cache). Arrays,
    not the grains/lists records: unpacked from tuples inside this parallel function, the two
    tasks ran slower than one after the other; the fluid record is only passed through.]"""
    n = x.shape[0]
    tasks = max(min(int(params[THREADS]), n), 1)
    claim = tasks + 1
    done = tasks + 2
    out[claim] = 0
    out[done] = 0
    for t in prange(tasks):
        if t != 0 and pending:
            _finish_if_unclaimed(out, claim, done, width, z_bot, z_top, fluid)
        if tasks == 1:                          # (one thread: the grid while the deposit's data is warm)
            out[0] = fluid_solve(width, z_bot, z_top, dt_f, fluid)
        late = move_range(t * n // tasks, (t + 1) * n // tasks, x, z, vx, vz, spin, force_x, force_z, torque,
                          inv_mass, inv_inertia, body, x_build, z_build, owed, params)
        if t == 0 and tasks > 1:
            if pending and not _finish_if_unclaimed(out, claim, done, width, z_bot, z_top, fluid):
                while fetch_add(out, done, 0) == 0:         # (an atomic read: the claimant is running)
                    pass
            out[0] = fluid_solve(width, z_bot, z_top, dt_f, fluid)
        out[t + 1] = late
    total = 0
    for t in range(tasks):
        total += out[t + 1]
    return total


@njit(cache=NUMBA_CACHE, inline="always")
def _finish_if_unclaimed(out, claim, done, width, z_bot, z_top, fluid):
    """The deposit's finish (fluid_finish_deposit) if no thread has claimed it (fetch_add on
    out[claim]), then out[done] set; returns whether this thread did it."""
    if fetch_add(out, claim, 1) != 0:
        return False
    fluid_finish_deposit(width, z_bot, z_top, fluid)
    fetch_add(out, done, 1)
    return True
