"""The time-step loop: velocity Verlet for grains and the top-wall body (physics.md sections 2-3).

One step (``_step``):
  1. top wall: half kick with last step's force, drift; its grains take its velocity
  2. free grains: half kick (v, w) with last step's force; every grain drifts (x periodic)
  3. contact forces at the new positions with the half-step velocities (tangential
     history ds += v_t dt), summed per grain in a fixed order
  4. top wall: grain force + spring k L_x (V_s t + s0 - x) along x, - sigma L_x along z; half kick
  5. free grains: half kick; flag a neighbour rebuild if any grain may pass skin/2 next step
The neighbour list is rebuilt at the start of a step, never in the middle.
Arrays named in ``GRAIN``/``LIST`` order are passed as tuples from :mod:`gouge_cli.state`.
"""

from __future__ import annotations

from numba import njit, prange

from .. import NUMBA_CACHE
from .contact import hertz_mindlin
from .neighbors import build_neighbors, minimum_image

# params: float64 array
DT, WIDTH, SKIN, C_NORMAL, C_TANGENTIAL, DAMPING, FRICTION, SIGMA, SPRING, V_LOAD, \
    WALL_MASS, BG_DAMPING, DRIVE, THREADS = range(14)
N_PARAMS = 14
# wall: float64 array, the top body
W_X, W_Z, W_VX, W_VZ, W_FX, W_FZ = range(6)
N_WALL = 6
# clock: float64 array (C_ANCHOR: spring stretch at the start of loading [d])
C_TIME, C_DRIVE_TIME, C_ANCHOR = range(3)
N_CLOCK = 3
# counters: int64 array
K_STEP, K_REBUILDS, K_PAIRS, K_NEED_REBUILD, K_NEEDED_CAPACITY, K_PHASE = range(6)
N_COUNTERS = 6
# phases (counters[K_PHASE])
COMPACTION, LOADING = 0, 1
# return codes of advance
OK, LIST_OVERFLOW, FLUID_FAILED = 0, 1, 2


@njit(parallel=True, cache=NUMBA_CACHE)
def pair_forces(x, z, vx, vz, spin, radius, mass, start, index, shear,
                pair_fx, pair_fz, pair_ti, pair_tj, params):
    """Per-pair force on j and torques on i and j into pair_*; updates shear history in place."""
    n = x.shape[0]
    dt = params[DT]
    width = params[WIDTH]
    c_n = params[C_NORMAL]
    c_t = params[C_TANGENTIAL]
    damping = params[DAMPING]
    friction = params[FRICTION]
    for i in prange(n):
        xi = x[i]
        zi = z[i]
        vxi = vx[i]
        vzi = vz[i]
        ri = radius[i]
        wi = spin[i]
        mi = mass[i]
        for k in range(start[i], start[i + 1]):
            j = index[k]
            dx = minimum_image(x[j] - xi, width)
            mj = mass[j]
            fx, fz, ti, tj, ds, overlap, fn = hertz_mindlin(
                dx, z[j] - zi, vx[j] - vxi, vz[j] - vzi, wi, spin[j], ri, radius[j],
                mi * mj / (mi + mj), shear[k], dt, c_n, c_t, damping, friction)
            pair_fx[k] = fx
            pair_fz[k] = fz
            pair_ti[k] = ti
            pair_tj[k] = tj
            shear[k] = ds


@njit(parallel=True, cache=NUMBA_CACHE)
def sum_pair_forces(radius, start, tr_start, tr_pair, pair_fx, pair_fz, pair_ti, pair_tj,
                    force_x, force_z, torque, drag_x, drag_z):
    """force = sum over pairs (as i: minus, as j: plus) + drag; fixed order per grain."""
    n = radius.shape[0]
    has_drag = drag_x.shape[0] == n
    for i in prange(n):
        fx = 0.0
        fz = 0.0
        ts = 0.0
        for k in range(start[i], start[i + 1]):
            fx -= pair_fx[k]
            fz -= pair_fz[k]
            ts += pair_ti[k]
        for m in range(tr_start[i], tr_start[i + 1]):
            k = tr_pair[m]
            fx += pair_fx[k]
            fz += pair_fz[k]
            ts += pair_tj[k]
        if has_drag:
            fx += drag_x[i]
            fz += drag_z[i]
        force_x[i] = fx
        force_z[i] = fz
        torque[i] = ts


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
def _wall_kick(wall, clock, params):
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


@njit(parallel=True, cache=NUMBA_CACHE)
def _kick_drift(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, params):
    n = x.shape[0]
    dt = params[DT]
    half = 0.5 * dt
    width = params[WIDTH]
    damp = params[BG_DAMPING]
    for i in prange(n):
        if body[i] == 0:
            vx[i] += half * (force_x[i] * inv_mass[i] - damp * vx[i])
            vz[i] += half * (force_z[i] * inv_mass[i] - damp * vz[i])
            spin[i] += half * (torque[i] * inv_inertia[i] - damp * spin[i])
        xn = x[i] + dt * vx[i]
        if xn >= width:
            xn -= width
        elif xn < 0.0:
            xn += width
        x[i] = xn
        z[i] += dt * vz[i]


@njit(parallel=True, cache=NUMBA_CACHE)
def _kick_check(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body,
                x_build, z_build, params):
    """Second half kick; returns how many grains might move past skin/2 in the next drift."""
    n = x.shape[0]
    dt = params[DT]
    half = 0.5 * dt
    width = params[WIDTH]
    damp = params[BG_DAMPING]
    reach = 0.5 * params[SKIN]
    reach2 = reach * reach
    late = 0
    for i in prange(n):
        ax = 0.0
        az = 0.0
        if body[i] == 0:
            ax = force_x[i] * inv_mass[i] - damp * vx[i]
            az = force_z[i] * inv_mass[i] - damp * vz[i]
            vx[i] += half * ax
            vz[i] += half * az
            spin[i] += half * (torque[i] * inv_inertia[i] - damp * spin[i])
        dx = minimum_image(x[i] - x_build[i], width) + dt * (vx[i] + half * ax)
        dz = z[i] - z_build[i] + dt * (vz[i] + half * az)
        if dx * dx + dz * dz > reach2:
            late += 1
    return late


@njit(cache=NUMBA_CACHE)
def compute_forces(grains, lists, pair, wall, params, drag_x, drag_z):
    """Contact (+ drag) forces on every grain and on the top wall at the current state."""
    x, z, vx, vz, spin, radius, mass, inv_mass, inv_inertia, body, force_x, force_z, torque, top = grains
    start, index, shear, tr_start, tr_pair, x_build, z_build, new_start, new_index, new_shear = lists
    pair_fx, pair_fz, pair_ti, pair_tj = pair
    pair_forces(x, z, vx, vz, spin, radius, mass, start, index, shear, pair_fx, pair_fz, pair_ti, pair_tj,
                params)
    sum_pair_forces(radius, start, tr_start, tr_pair, pair_fx, pair_fz, pair_ti, pair_tj,
                    force_x, force_z, torque, drag_x, drag_z)
    wall_force(force_x, force_z, top, wall)


@njit(cache=NUMBA_CACHE)
def rebuild(grains, lists, params, counters):
    """Rebuild the neighbour list; False (and K_NEEDED_CAPACITY set) if it does not fit."""
    x, z, vx, vz, spin, radius, mass, inv_mass, inv_inertia, body, force_x, force_z, torque, top = grains
    start, index, shear, tr_start, tr_pair, x_build, z_build, new_start, new_index, new_shear = lists
    npairs = build_neighbors(x, z, radius, body, params[WIDTH], params[SKIN], start, index, shear,
                             new_start, new_index, new_shear, tr_start, tr_pair, x_build, z_build,
                             params[THREADS] <= 1.0)
    if npairs < 0:
        counters[K_NEEDED_CAPACITY] = -npairs
        return False
    counters[K_PAIRS] = npairs
    counters[K_REBUILDS] += 1
    counters[K_NEED_REBUILD] = 0
    return True


@njit(cache=NUMBA_CACHE)
def _step(grains, lists, pair, wall, clock, params, counters, drag_x, drag_z):
    x, z, vx, vz, spin, radius, mass, inv_mass, inv_inertia, body, force_x, force_z, torque, top = grains
    x_build, z_build = lists[5], lists[6]
    dt = params[DT]
    _wall_kick(wall, clock, params)
    wall[W_X] += dt * wall[W_VX]
    wall[W_Z] += dt * wall[W_VZ]
    _set_wall_grain_velocity(vx, vz, spin, top, wall)
    _kick_drift(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body, params)
    clock[C_TIME] += dt
    if params[DRIVE] > 0.0:
        clock[C_DRIVE_TIME] += dt
    compute_forces(grains, lists, pair, wall, params, drag_x, drag_z)
    _wall_kick(wall, clock, params)
    _set_wall_grain_velocity(vx, vz, spin, top, wall)
    late = _kick_check(x, z, vx, vz, spin, force_x, force_z, torque, inv_mass, inv_inertia, body,
                       x_build, z_build, params)
    if late > 0:
        counters[K_NEED_REBUILD] = 1
    counters[K_STEP] += 1


@njit(cache=NUMBA_CACHE)
def advance(grains, lists, pair, wall, clock, params, counters, nsteps, drag_x, drag_z):
    """Run up to nsteps dry steps. Returns (status, steps done); status LIST_OVERFLOW asks the
    caller to enlarge the list arrays to counters[K_NEEDED_CAPACITY] and call again."""
    for s in range(nsteps):
        if counters[K_NEED_REBUILD] != 0:
            if not rebuild(grains, lists, params, counters):
                return LIST_OVERFLOW, s
        _step(grains, lists, pair, wall, clock, params, counters, drag_x, drag_z)
    return OK, nsteps

