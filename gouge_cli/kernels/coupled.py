"""The time-step loop with pore fluid: kernels.step plus a Goren pressure update every
`interval` steps. Only scenes with a fluid section import this module."""

from __future__ import annotations

from numba import njit, prange

from . import NUMBA_CACHE
from .atomics import fetch_add
from .layout import (BG_DAMPING, DT, FLUID_FAILED, K_NEED_REBUILD, K_STEP, LIST_OVERFLOW, OK, STATUS_NONFINITE,
                     THREADS, WIDTH, W_VX, W_VZ, W_Z)
from .fluid_update import (BACK_Z, COLLECT, DENSITY, N_STAGES, PREDICT, TAPS, filter_half_widths, fluid_begin,
                           add_top_plane_force, fluid_drag, fluid_solve, grid_stage, pressure_choose, pressure_close, stage_parts)
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
    owed = bool(False)           # (bool(...): one compiled _step, kernels/__init__)
    drifted = bool(False)
    for st in range(nsteps):
        update = (counters[K_STEP] + 1) % interval == 0       # this step ends with a fluid update
        close = st == nsteps - 1
        if not _step((), grains, lists, pair, wall, clock, params, counters, drag_x, drag_z, owed, close, drifted):
            return LIST_OVERFLOW, st
        owed = not close
        drifted = bool(False)
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
            add_top_plane_force(fluid, grains.top, drag_z, status)
        if status != 0:
            if owed and not drifted:
                close_step(grains, wall, params)
            fluid_status[0] = status
            return FLUID_FAILED, st + 1
    return OK, nsteps


# _solve_and_drift's shared counters, at out[tasks + 1 + slot] (after the status and the per-thread
# counts): thread 0 running, the solver chosen, the drag's fields ready, parts that found a pressure
# not finite, and per grid stage (kernels.fluid_update: COLLECT .. INTERLEAVE) a count of parts taken
# and one of parts done
_ALIVE, _CHOSEN, _READY, _NONFINITE = range(4)
_TAKEN = 4
_FINISHED = _TAKEN + N_STAGES
_SLOTS = _FINISHED + N_STAGES
_HEUN, _SOLVED = 1, 2         # out[_CHOSEN]: Heun's stages follow; or the pressure is solved
_GO, _NO_DRAG = 1, 2          # out[_READY]: the drag's fields may be filtered back; or there are none
_PARTS = 2                    # a field's columns in two parts: two threads share the grid


@njit(parallel=True, cache=NUMBA_CACHE)
def _solve_and_drift(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, x_build, z_build,
                     owed, params, width, z_bot, z_top, dt_f, fluid, pending, out):
    """fluid_solve while the threads run step 2 of the next step, the grains' kicks and drift
    (move_range), each grain on its own: the bits of one after the other. Every thread moves its
    own part of the grains (kernels.step.kick_drift's: the ones it holds in cache).

    On two or more threads, threads 0 and 1 share the grid's stages (_stages; kernels.fluid_update:
    the deposit's finish if pending, the filter forward, the pressure's parts, the filter back);
    thread 0 alone runs the serial steps between them (pressure_choose, with the backward Euler
    or sub-stepped solvers, and pressure_close). Each stage is cut into parts (grid_stage), each
    part taken by fetch_add on the stage's counter, so each is done once, by whichever thread
    takes it, in the same serial code: the same bits. Thread 1 takes parts first, then moves its
    grains; thread 0 moves its grains first. A thread waits only for parts another has taken (that
    thread is then running them), and thread 1 waits for the pressure stage only once thread 0
    has signalled that it runs (out[_ALIVE]): the region is correct whichever threads run its
    tasks and in whatever order. On one thread: solve, then move every grain. Returns how many
    grains are now past skin/2; out: int64 scratch (>= threads + 1 + _SLOTS: the lists'
    cell_count), out[0] = the solve's status.
    [Arrays, not the grains/lists records: unpacked from tuples inside this parallel function, the
    two tasks ran slower than one after the other; the fluid record is only passed through.]"""
    n = x.shape[0]
    tasks = max(min(int(params[THREADS]), n), 1)
    base = tasks + 1
    for k in range(_SLOTS):
        out[base + k] = 0
    first = COLLECT if pending else TAPS
    for t in prange(tasks):
        if tasks == 1:                          # (one thread: the grid while the deposit's data is warm)
            out[0] = fluid_solve(width, z_bot, z_top, dt_f, fluid)
        if t == 0 and tasks > 1:
            fetch_add(out, base + _ALIVE, 1)
        if t == 1:
            _stages(out, base, first, int(PREDICT), width, z_bot, z_top, dt_f, fluid, bool(False))
        late = move_range(t * n // tasks, (t + 1) * n // tasks, x, z, vx, vz, spin, force_x, force_z, torque,
                          inv_mass, inv_inertia, body, x_build, z_build, owed, params)
        if t == 0 and tasks > 1:
            out[0] = _grid_on_thread_0(out, base, first, width, z_bot, z_top, dt_f, fluid)
        if t == 1 and fetch_add(out, base + _ALIVE, 0) != 0:       # (thread 0 runs: it sets each flag)
            chosen = _await(out, base + _CHOSEN)
            _stages(out, base, PREDICT if chosen == _HEUN else DENSITY, int(BACK_Z), width, z_bot, z_top, dt_f, fluid,
                    bool(False))
            if _await(out, base + _READY) == _GO:
                _stages(out, base, int(BACK_Z), int(N_STAGES), width, z_bot, z_top, dt_f, fluid, bool(False))
        out[t + 1] = late
    total = 0
    for t in range(tasks):
        total += out[t + 1]
    return total


@njit(cache=NUMBA_CACHE)
def _grid_on_thread_0(out, base, first, width, z_bot, z_top, dt_f, fluid):
    """Thread 0's part of the shared solve (_solve_and_drift); returns the solve's status."""
    _stages(out, base, first, int(PREDICT), width, z_bot, z_top, dt_f, fluid, bool(True))
    heun, status = pressure_choose(dt_f, fluid)
    fetch_add(out, base + _CHOSEN, _HEUN if heun else _SOLVED)
    _stages(out, base, PREDICT if heun else DENSITY, int(BACK_Z), width, z_bot, z_top, dt_f, fluid, bool(True))
    status = pressure_close(z_bot, z_top, fluid, fetch_add(out, base + _NONFINITE, 0) == 0, status)
    if status == STATUS_NONFINITE:
        fetch_add(out, base + _READY, _NO_DRAG)
        return status
    fetch_add(out, base + _READY, _GO)
    _stages(out, base, int(BACK_Z), int(N_STAGES), width, z_bot, z_top, dt_f, fluid, bool(True))
    return status


@njit(cache=NUMBA_CACHE, inline="always")
def _await(out, slot):
    """Spin until out[slot] is set (an atomic read; only for a flag a running thread will set)."""
    value = fetch_add(out, slot, 0)
    while value == 0:
        value = fetch_add(out, slot, 0)
    return value


@njit(cache=NUMBA_CACHE)
def _stages(out, base, first, last, width, z_bot, z_top, dt_f, fluid, wait):
    """Grid stages first <= stage < last, shared: the parts of each (_PARTS per field's columns)
    taken one at a time by fetch_add on the stage's counter until none is left; a stage starts
    once every part of the one before is done (all are then taken: any in progress is another
    running thread's). A part that finds the pressure not finite counts in out[_NONFINITE]. With
    wait, returns only once every part of the last stage is done."""
    mx, mz = filter_half_widths(width, z_bot, z_top, fluid)
    parts = int(_PARTS)
    for stage in range(first, last):
        count = stage_parts(stage, parts)
        if stage != first:
            while fetch_add(out, base + _FINISHED + stage - 1, 0) < stage_parts(stage - 1, parts):
                pass
        k = fetch_add(out, base + _TAKEN + stage, 1)
        while k < count:
            if not grid_stage(stage, k, parts, width, z_bot, z_top, dt_f, fluid, mx, mz):
                fetch_add(out, base + _NONFINITE, 1)
            fetch_add(out, base + _FINISHED + stage, 1)
            k = fetch_add(out, base + _TAKEN + stage, 1)
    while wait and fetch_add(out, base + _FINISHED + last - 1, 0) < stage_parts(last - 1, parts):
        pass
