"""The time-step loop: velocity Verlet for grains and the top-wall body (docs/physics/walls.md).

One step (``_step``):
  1. top wall: half kick with last step's force, drift; its grains take its velocity
  2. free grains: half kick (v, w) with last step's force; every grain drifts (x periodic);
     if any grain is now farther than skin/2 from where the list was built, rebuild it
  3. contact forces at the new positions with the half-step velocities (tangential
     history ds += v_t dt), summed per grain in a fixed order
  4. top wall: grain force + spring k L_x (V_s t + s0 - x) along x, - sigma L_x along z; half kick
  5. free grains: half kick
Within one ``advance`` the grains' step-5 kick is done in the same pass as the next step's
step-2 kick and drift (same operations in the same order: the bits do not depend on how a
run is cut into advance calls); the state is at a whole step when advance returns. Code that
needs whole-step velocities mid-call takes them from ``closed_velocity`` (the fluid deposit).
The scene's arrays come as records addressed by field name (kernels.layout.Grains, Lists, Pairs,
built by model.state.State); indices of params, wall, clock and counters: kernels.layout.

The sequence is written once: _step and run_steps call the step's phases by name (STEP_PHASES:
open, drift, rebuild, forces, wall, close and the rebuild flag's read and suspension), each with
a first argument `block` saying who runs it. Here block is () and the phases are this module's
(numba threads inside each); kernels.gpu.dry compiles the same two functions for a CUDA thread
block with its own phases bound to those names. advance is the CPU's dry engine, coupled.py adds
the fluid between its steps.

The pair pass (the list's derived arrays, the law and sum passes) is kernels.forces.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import NUMBA_CACHE
from .forces import contact_forces
from .layout import (BG_DAMPING, C_ANCHOR, C_DRIVE_TIME, C_TIME, DRIVE, DT, FREE, K_NEEDED_CAPACITY, K_NEED_REBUILD,
                     K_PAIRS, K_REBUILDS, K_STEP, LIST_OVERFLOW, L_BUILT, L_SCRATCH, MID_STEP, OK, SIGMA, SKIN,
                     SORT_EVERY, SPRING, THREADS, TOP, V_LOAD, WALL_MASS, WIDTH, W_FX, W_FZ, W_VX, W_VZ, W_X, W_Z)
from .neighbors import build_neighbors, minimum_image
from .reorder import permute, renumber_list, spatial_order


@njit(cache=NUMBA_CACHE)
def wall_force(force_x, force_z, top, wall):
    """Sum of grain forces on the top-wall grains, in index order, into wall[W_FX], wall[W_FZ]."""
    fx = 0.0
    fz = 0.0
    for m in range(top.shape[0]):
        fx += force_x[top[m]]
        fz += force_z[top[m]]
    wall[W_FX] = fx
    wall[W_FZ] = fz


@njit(cache=NUMBA_CACHE)
def wall_kick(wall, clock, params):
    """Half kick of the top body: M a = F_grains + (spring, -sigma) L_x; M = m_b L_x."""
    half = 0.5 * params[DT]
    width = params[WIDTH]
    mass = params[WALL_MASS]
    if mass <= 0.0:
        return
    fz = wall[W_FZ] - params[SIGMA] * width - params[BG_DAMPING] * mass * wall[W_VZ]
    wall[W_VZ] += half * fz / mass
    if params[DRIVE] > 0.0:
        stretch = params[V_LOAD] * clock[C_DRIVE_TIME] + clock[C_ANCHOR] - wall[W_X]
        fx = wall[W_FX] + params[SPRING] * width * stretch
        wall[W_VX] += half * fx / mass
    else:
        wall[W_VX] = 0.0


@njit(cache=NUMBA_CACHE)
def _set_wall_grain_velocity(vx, vz, spin, top, wall):
    for m in range(top.shape[0]):
        i = top[m]
        vx[i] = wall[W_VX]
        vz[i] = wall[W_VZ]
        spin[i] = 0.0


@njit(inline="always", cache=NUMBA_CACHE)
def _half_kick(v, a, half, damp):
    """Velocity (or spin) v after half a step of acceleration a with background damping."""
    return v + half * (a - damp * v)


@njit(inline="always", cache=NUMBA_CACHE)
def closed_velocity(body, vx, vz, ax, az, half, damp, wall_vx, wall_vz):
    """(vx, vz) [v0] of a grain once the second half kick it owes is applied: what _kick (free
    grains, acceleration ax, az = force * inv_mass) and _set_wall_grain_velocity (top-wall
    grains, wall velocity) would store, same bits; bottom-wall grains keep theirs. Scalars
    only: a per-grain call with array arguments costs reference counting."""
    if body == FREE:
        return _half_kick(vx, ax, half, damp), _half_kick(vz, az, half, damp)
    if body == TOP:
        return wall_vx, wall_vz
    return vx, vz


@njit(inline="always", cache=NUMBA_CACHE)
def _move_one(i, x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, x_build, z_build,
              double, dt, width, damp, reach2):
    """Half kick of grain i if it is free (two in a row if double: the previous step's second
    and this step's first, same bits as two passes), then its drift, x periodic. Returns 1 if
    it then lies farther than sqrt(reach2) from its position at the last list build. The kick
    is computed for every grain and selected (a wall grain stores its velocity back unchanged):
    a store under a branch needs masked stores to vectorise, which AVX-512 has and AVX2 code
    generation declines."""
    half = 0.5 * dt
    free = body[i] == 0
    u0 = vx[i]
    v0 = vz[i]
    w0 = spin[i]
    ax = force_x[i] * inv_mass[i]
    az = force_z[i] * inv_mass[i]
    aw = torque[i] * inv_inertia[i]
    u = _half_kick(u0, ax, half, damp)
    v = _half_kick(v0, az, half, damp)
    w = _half_kick(w0, aw, half, damp)
    if double:
        u = _half_kick(u, ax, half, damp)
        v = _half_kick(v, az, half, damp)
        w = _half_kick(w, aw, half, damp)
    u = u if free else u0
    v = v if free else v0
    w = w if free else w0
    vx[i] = u
    vz[i] = v
    spin[i] = w
    xn = x[i] + dt * u
    if xn >= width:
        xn -= width
    elif xn < 0.0:
        xn += width
    zn = z[i] + dt * v
    x[i] = xn
    z[i] = zn
    dx = minimum_image(xn - x_build[i], width)
    dz = zn - z_build[i]
    return 1 if dx * dx + dz * dz > reach2 else 0


@njit(inline="always", cache=NUMBA_CACHE)
def move_range(first, last, x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, x_build,
               z_build, double, params):
    """_move_one for grains first:last on this thread; returns how many lie farther than skin/2
    from their build positions. (Unsigned bounds: no negative-index checks in the loop; called
    from parallel functions only: in a plain njit function the inlined array arguments cost
    reference counting per grain, several times slower.)"""
    dt = params[DT]
    width = params[WIDTH]
    damp = params[BG_DAMPING]
    reach = 0.5 * params[SKIN]
    reach2 = reach * reach
    total = 0
    for i in range(np.uint64(first), np.uint64(last)):
        total += _move_one(i, x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body,
                           x_build, z_build, double, dt, width, damp, reach2)
    return total


@njit(parallel=True, cache=NUMBA_CACHE)
def kick_drift(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, x_build, z_build,
                double, params, late):
    """Half kick (two if double) and drift of every grain; returns how many grains lie farther
    than skin/2 from their build positions (the list must be rebuilt before forces).
    Grains in params[THREADS] equal parts (move_range); late: (N,) int64 scratch, one count per
    part."""
    n = x.shape[0]
    nb = min(max(int(params[THREADS]), 1), max(n, 1))
    for b in prange(nb):
        late[b] = move_range(b * n // nb, (b + 1) * n // nb, x, z, vx, vz, spin, force_x, force_z, torque, inv_mass,
                             inv_inertia, body, x_build, z_build, double, params)
    total = 0
    for b in range(nb):
        total += late[b]
    return total


@njit(cache=NUMBA_CACHE)
def open_step(grains, wall, clock, params):
    """Step 1: the top wall's half kick and drift, its grains take its velocity; the clock
    advances by dt."""
    dt = params[DT]
    wall_kick(wall, clock, params)
    wall[W_X] += dt * wall[W_VX]
    wall[W_Z] += dt * wall[W_VZ]
    _set_wall_grain_velocity(grains.vx, grains.vz, grains.spin, grains.top, wall)
    clock[C_TIME] += dt
    if params[DRIVE] > 0.0:
        clock[C_DRIVE_TIME] += dt


@njit(parallel=True, cache=NUMBA_CACHE)
def _kick(vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, params):
    """Second half kick of the free grains (the state is then at a whole step)."""
    half = 0.5 * params[DT]
    damp = params[BG_DAMPING]
    for i in prange(vx.shape[0]):
        if body[i] == 0:
            vx[i] = _half_kick(vx[i], force_x[i] * inv_mass[i], half, damp)
            vz[i] = _half_kick(vz[i], force_z[i] * inv_mass[i], half, damp)
            spin[i] = _half_kick(spin[i], torque[i] * inv_inertia[i], half, damp)


@njit(cache=NUMBA_CACHE)
def compute_forces(grains, lists, pair, wall, params, drag_x, drag_z):
    """Contact (+ drag) forces on every grain and on the top wall at the current state."""
    contact_forces(grains, lists, pair, drag_x, drag_z, params)
    wall_force(grains.force_x, grains.force_z, grains.top, wall)


@njit(cache=NUMBA_CACHE)
def renumber(grains, lists, drag_x, drag_z, width):
    """Re-number the grains by position (kernels.reorder): every per-grain array (and the fluid
    drag, when there is one), the top-wall index list and the half list with its shear history.
    The original numbers travel in ``id``."""
    x, z, vx, vz, spin = grains.x, grains.z, grains.vx, grains.vz, grains.spin
    radius, mass, inv_mass, inv_inertia = grains.radius, grains.mass, grains.inv_mass, grains.inv_inertia
    force_x, force_z, torque = grains.force_x, grains.force_z, grains.torque
    body, top, ident = grains.body, grains.top, grains.id
    # (unpacked, not lists.index: numba-cuda types .index on a tuple as tuple.index; this function
    # also runs on the GPU, kernels.gpu)
    start, index, shear, _, _, _, _, new_start, new_index, new_shear, layout, cell_of, order, cell_count = lists
    n = x.shape[0]
    spatial_order(x, z, width, order, cell_of, cell_count)
    renumber_list(cell_of, start, index, shear, new_start, new_index, new_shear)
    for values in (x, z, vx, vz, spin, radius, mass, inv_mass, inv_inertia, force_x, force_z, torque):
        permute(values, order, new_shear)
    if drag_x.shape[0] == n:
        permute(drag_x, order, new_shear)
        permute(drag_z, order, new_shear)
    permute(body, order, cell_count)
    permute(ident, order, cell_count)
    m = 0
    for i in range(n):
        if body[i] == TOP:
            top[m] = i
            m += 1
    layout[L_BUILT] = -1


@njit(cache=NUMBA_CACHE)
def rebuild(grains, lists, params, counters, drag_x, drag_z):
    """Rebuild the neighbour list, re-numbering the grains first every params[SORT_EVERY]-th
    rebuild; False (and K_NEEDED_CAPACITY set) if the list does not fit."""
    layout = lists.layout
    every = int(params[SORT_EVERY])
    if every > 0 and counters[K_REBUILDS] % every == 0:
        renumber(grains, lists, drag_x, drag_z, params[WIDTH])
    npairs = build_neighbors(grains.x, grains.z, grains.radius, grains.body, params[WIDTH], params[SKIN],
                             lists.start, lists.index, lists.shear, lists.new_start, lists.new_index, lists.new_shear,
                             lists.x_build, lists.z_build, lists.cell_of, lists.order, lists.cell_count,
                             layout[L_SCRATCH:], params[THREADS] <= 1.0)
    if npairs < 0:
        counters[K_NEEDED_CAPACITY] = -npairs
        return False
    layout[L_BUILT] = -1            # reverse list stale; contact_forces rebuilds it
    counters[K_PAIRS] = npairs
    counters[K_REBUILDS] += 1
    counters[K_NEED_REBUILD] = 0
    return True


@njit(cache=NUMBA_CACHE)
def close_step(grains, wall, params):
    """Step 5 on its own: the top wall's grains take its velocity and the free grains get the
    second half kick they owe (the state is then at a whole step)."""
    _set_wall_grain_velocity(grains.vx, grains.vz, grains.spin, grains.top, wall)
    _kick(grains.vx, grains.vz, grains.spin, grains.force_x, grains.force_z, grains.torque, grains.inv_mass,
          grains.inv_inertia, grains.body, params)



# ---- the step's sequence ----------------------------------------------------------------------
# _step and run_steps are the one description of a step's order: the CPU engines call them as they
# are (block = (): the phases below, on this process's numba threads); kernels.gpu.dry compiles the
# same two functions for a CUDA thread block with every name in STEP_PHASES bound to the block's own
# phase (block: the thread, the block's size, its scratch). A phase does its part of the step and
# leaves the state where the next one expects it. (The CPU's phases and run_steps are inlined into
# _step and advance: each would otherwise be one more function numba compiles, about 0.5 s each.)

STEP_PHASES = ("pending", "suspend", "open_phase", "drift_phase", "rebuild_phase", "force_phase", "wall_phase",
               "close_phase")


@njit(inline="always", cache=NUMBA_CACHE)
def pending(block, counters):
    """counters[K_NEED_REBUILD]: 0, 1 (rebuild the list before the forces) or MID_STEP (a step
    left drifted by an overflow: resume at the rebuild)."""
    return counters[K_NEED_REBUILD]


@njit(inline="always", cache=NUMBA_CACHE)
def suspend(block, counters):
    """Leave the step drifted after an overflowing rebuild: the next call resumes at the rebuild."""
    counters[K_NEED_REBUILD] = MID_STEP


@njit(inline="always", cache=NUMBA_CACHE)
def open_phase(block, grains, wall, clock, params):
    """Step 1 (open_step)."""
    open_step(grains, wall, clock, params)


@njit(inline="always", cache=NUMBA_CACHE)
def drift_phase(block, grains, lists, params, counters, owed):
    """Step 2: every grain's half kick (two if owed) and drift (kick_drift); a rebuild is pending
    if one has moved more than skin/2 since the list was built."""
    late = kick_drift(grains.x, grains.z, grains.vx, grains.vz, grains.spin, grains.force_x, grains.force_z,
                      grains.torque, grains.inv_mass, grains.inv_inertia, grains.body, lists.x_build, lists.z_build,
                      owed, params, lists.cell_of)
    if late > 0:
        counters[K_NEED_REBUILD] = 1


@njit(inline="always", cache=NUMBA_CACHE)
def rebuild_phase(block, grains, lists, params, counters, drag_x, drag_z):
    """The list rebuilt (rebuild); False if it does not fit."""
    return rebuild(grains, lists, params, counters, drag_x, drag_z)


@njit(inline="always", cache=NUMBA_CACHE)
def force_phase(block, grains, lists, pairs, params, drag_x, drag_z):
    """Step 3: contact (+ drag) forces on every grain (contact_forces)."""
    contact_forces(grains, lists, pairs, drag_x, drag_z, params)


@njit(inline="always", cache=NUMBA_CACHE)
def wall_phase(block, grains, wall, clock, params, counters):
    """Step 4: the grains' force on the top wall, its spring and its second half kick; the step
    is counted."""
    wall_force(grains.force_x, grains.force_z, grains.top, wall)
    wall_kick(wall, clock, params)
    counters[K_STEP] += 1


@njit(inline="always", cache=NUMBA_CACHE)
def close_phase(block, grains, wall, params):
    """Step 5 (close_step)."""
    close_step(grains, wall, params)


@njit(cache=NUMBA_CACHE)
def _step(block, grains, lists, pairs, wall, clock, params, counters, drag_x, drag_z, owed, close, drifted):
    """One step (module docstring), phase by phase (STEP_PHASES). owed: the grains still owe the
    previous step their second half kick, which is fused into this step's first; close: end with
    the grains' second half kick (the state is then at a whole step), else leave it owed to the
    next step; drifted: steps 1-2 are already done (open_step and _move_one of every grain,
    rebuild flag set). False if the rebuild overflows the list: the step is then left drifted
    (counters[K_NEED_REBUILD] = MID_STEP) and the next call resumes it at the rebuild."""
    if pending(block, counters) != MID_STEP and not drifted:
        open_phase(block, grains, wall, clock, params)
        drift_phase(block, grains, lists, params, counters, owed)
    if pending(block, counters) != 0:
        if not rebuild_phase(block, grains, lists, params, counters, drag_x, drag_z):
            suspend(block, counters)
            return False
    force_phase(block, grains, lists, pairs, params, drag_x, drag_z)
    wall_phase(block, grains, wall, clock, params, counters)
    if close:
        close_phase(block, grains, wall, params)
    return True


@njit(inline="always", cache=NUMBA_CACHE)
def run_steps(block, grains, lists, pairs, wall, clock, params, counters, nsteps, drag_x, drag_z):
    """Up to nsteps dry steps (_step), the grains' half kicks between steps fused. Returns (status,
    whole steps done); status LIST_OVERFLOW asks the caller to enlarge the list arrays to
    counters[K_NEEDED_CAPACITY] and call again (the interrupted step resumes)."""
    for s in range(nsteps):
        if not _step(block, grains, lists, pairs, wall, clock, params, counters, drag_x, drag_z, s > 0,
                     s == nsteps - 1, bool(False)):
            return LIST_OVERFLOW, s
    return OK, nsteps


@njit(cache=NUMBA_CACHE)
def advance(grains, lists, pair, wall, clock, params, counters, nsteps, drag_x, drag_z):
    """run_steps on this process's numba threads: the CPU's dry engine."""
    return run_steps((), grains, lists, pair, wall, clock, params, counters, nsteps, drag_x, drag_z)
