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

Size (~500 lines): the pair pass (reverse_list .. sum_pass) and the step (kicks, drift,
rebuild, advance) stay in one file for now; the pair pass is the natural next split (forces.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import NUMBA_CACHE
from .layout import (BG_DAMPING, B_DVX, B_DVZ, B_DX, B_DZ, B_WI, B_WJ, C_ANCHOR, C_DRIVE_TIME, C_NORMAL,
                     C_TANGENTIAL, C_TIME, DAMPING, DRIVE, DT, FREE, FRICTION, K_NEEDED_CAPACITY, K_NEED_REBUILD,
                     K_PAIRS, K_REBUILDS, K_STEP, LIST_OVERFLOW, L_BUILT, L_SCRATCH, MID_STEP, OK, PAIR_BUF,
                     PARTS_PER_THREAD, PC_MEFF, PC_REFF, PC_RI, PC_RJ, SIGMA, SKIN, SORT_EVERY, SPRING, THREADS, TOP,
                     V_LOAD, WALL_MASS, WIDTH, W_FX, W_FZ, W_VX, W_VZ, W_X, W_Z)
from .contact import pair_constants, pair_force
from .neighbors import bucket_order, build_neighbors, minimum_image
from .reorder import permute, renumber_list, spatial_order


@njit(cache=NUMBA_CACHE)
def reverse_list(start, index, n, rev_start, rev_slot):
    """The list by second grain: rev_slot[rev_start[g]:rev_start[g + 1]] are the slots k of the
    pairs (i, g), i < g, in increasing k (a stable counting sort of index by value).
    rev_start: (N + 1,) int64; rev_slot: (capacity,) int32."""
    bucket_order(index[:start[n]], n, rev_start, rev_slot)


@njit(cache=NUMBA_CACHE)
def sum_list(start, rev_start, rev_slot, n, half, sum_start, sum_end):
    """The terms of each grain's sums in their one fixed order (_sum_range), as indices e of the
    sum_x, sum_z, sum_t tables (kernels.layout.Pairs; half: their capacity): grain g's are
    sum_end[sum_start[g]:sum_start[g + 1]]: k for the slots k of the pairs (i, g) in increasing k,
    then half + k for the slots of its own row, then 2 half (-0.0) where that makes an odd count
    even. sum_start (N + 1,) int64; sum_end int32 with room for 2 npairs + N entries."""
    m = 0
    for g in range(n):
        sum_start[g] = m
        for r in range(rev_start[g], rev_start[g + 1]):
            sum_end[m] = rev_slot[r]
            m += 1
        for k in range(start[g], start[g + 1]):
            sum_end[m] = half + k
            m += 1
        if (m - sum_start[g]) % 2 != 0:
            sum_end[m] = 2 * half
            m += 1
    sum_start[n] = m


@njit(cache=NUMBA_CACHE)
def list_constants(start, index, radius, mass, const, row):
    """const (N_PAIR_CONST, capacity), rows PC_*: the radii and kernels.contact.pair_constants of
    every listed pair, and row (capacity,) int32: the first grain i of every slot; constant while
    the list and the masses are: set once per change instead of gathered every step."""
    for i in range(radius.shape[0]):
        ri = radius[i]
        mi = mass[i]
        for k in range(start[i], start[i + 1]):
            j = index[k]
            row[k] = i
            const[PC_RI, k] = ri
            const[PC_RJ, k] = radius[j]
            const[PC_REFF, k], const[PC_MEFF, k] = pair_constants(ri, radius[j], mi, mass[j])


@njit(inline="always", cache=NUMBA_CACHE)
def _fill(k0, k1, x, z, vx, vz, spin, row, index, width, buf):
    """Copy the inputs of pair slots k0:k1 into buf[:, k - k0]: one flat loop over the slots, each
    slot's first grain from row (pairs.pair_row). [A loop per list row, as before 2026-12-07, ends
    after a data-dependent 0-6 slots: about one mispredicted branch per row, half this pass's time.]"""
    for k in range(np.uint64(k0), np.uint64(k1)):
        i = np.uint32(row[k])
        j = np.uint32(index[k])
        q = k - np.uint64(k0)
        buf[B_DX, q] = minimum_image(x[j] - x[i], width)
        buf[B_DZ, q] = z[j] - z[i]
        buf[B_DVX, q] = vx[j] - vx[i]
        buf[B_DVZ, q] = vz[j] - vz[i]
        buf[B_WI, q] = spin[i]
        buf[B_WJ, q] = spin[j]


@njit(error_model="numpy", cache=NUMBA_CACHE)
def _laws(m, buf, base, dt, c_n, c_t, damping, friction, shear, const, sum_x, sum_z, sum_t):
    """The contact law (kernels.contact.pair_force) on buf[:, :m] for slots base:base + m (their
    shear history and constants read in place), results to shear and to the terms of the two grains'
    sums [sum_x, sum_z, sum_t at k: fx, fz (force on j), tj; at half + k: -fx, -fz, ti;
    kernels.layout.Pairs] at those slots: a loop without branches or gathers, which LLVM
    vectorises (SIMD lanes do the same IEEE operations as the scalar law: same bits; -f is exact)."""
    half = np.uint64((sum_x.shape[0] - 1) // 2)
    for q in range(m):
        k = np.uint64(base + q)
        fx, fz, ti, tj, ds, overlap, fn = pair_force(
            buf[B_DX, q], buf[B_DZ, q], buf[B_DVX, q], buf[B_DVZ, q], buf[B_WI, q], buf[B_WJ, q],
            const[PC_RI, k], const[PC_RJ, k], const[PC_REFF, k], const[PC_MEFF, k], shear[k], dt, c_n, c_t,
            damping, friction)
        sum_x[k] = fx
        sum_z[k] = fz
        sum_t[k] = tj
        sum_x[half + k] = -fx
        sum_z[half + k] = -fz
        sum_t[half + k] = ti
        shear[k] = ds


@njit(inline="always", cache=NUMBA_CACHE)
def _pair_range(k_lo, k_hi, x, z, vx, vz, spin, row, index, shear, const, sum_x, sum_z, sum_t, buf, width, dt,
                c_n, c_t, damping, friction):
    """The law for list slots k_lo:k_hi, in chunks of PAIR_BUF slots (copy in, SIMD law)."""
    k0 = k_lo
    while k0 < k_hi:
        k1 = min(k0 + PAIR_BUF, k_hi)
        _fill(k0, k1, x, z, vx, vz, spin, row, index, width, buf)
        _laws(k1 - k0, buf, k0, dt, c_n, c_t, damping, friction, shear, const, sum_x, sum_z, sum_t)
        k0 = k1


@njit(inline="always", cache=NUMBA_CACHE)
def _sum_range(g0, g1, start, rev_start, rev_slot, pair_fx, pair_fz, pair_ti, pair_tj, force_x, force_z, torque,
               drag, drag_x, drag_z):
    """Force and torque of grains g0:g1 from the pair results, in the one fixed order: the pairs
    where g is second (+, increasing slot, i.e. increasing i), then its own row (-, in slot
    order), then drag. (The GPU engine's sum, kernels.gpu; the host's pass is _sum_terms, the same
    terms in the same order.)"""
    for g in range(np.uint64(g0), np.uint64(g1)):
        fx = 0.0
        fz = 0.0
        ts = 0.0
        for r in range(rev_start[g], rev_start[g + 1]):
            k = np.uint32(rev_slot[r])
            fx += pair_fx[k]
            fz += pair_fz[k]
            ts += pair_tj[k]
        for k in range(np.uint64(start[g]), np.uint64(start[g + 1])):
            fx -= pair_fx[k]
            fz -= pair_fz[k]
            ts += pair_ti[k]
        if drag:
            fx += drag_x[g]
            fz += drag_z[g]
        force_x[g] = fx
        force_z[g] = fz
        torque[g] = ts


@njit(inline="always", cache=NUMBA_CACHE)
def _sum_terms(g0, g1, sum_start, sum_end, sum_x, sum_z, sum_t, force_x, force_z, torque, drag, drag_x, drag_z):
    """_sum_range's sums: the same terms in the same order (sum_list), without its two loops of
    data-dependent length per grain: one loop, two terms a turn. Same bits: where _sum_range
    subtracts f this adds -f (x + (-f) = x - f exactly), and the padding adds -0.0 (x + (-0.0) = x
    exactly)."""
    for g in range(np.uint64(g0), np.uint64(g1)):
        fx = 0.0
        fz = 0.0
        ts = 0.0
        for c in range(np.uint64(sum_start[g]), np.uint64(sum_start[g + 1]), np.uint64(2)):
            e = np.uint32(sum_end[c])
            f = np.uint32(sum_end[c + np.uint64(1)])
            fx += sum_x[e]
            fz += sum_z[e]
            ts += sum_t[e]
            fx += sum_x[f]
            fz += sum_z[f]
            ts += sum_t[f]
        if drag:
            fx += drag_x[g]
            fz += drag_z[g]
        force_x[g] = fx
        force_z[g] = fz
        torque[g] = ts


@njit(cache=NUMBA_CACHE)
def derive_list(grains, lists, pairs):
    """The arrays the force pass derives from the list and the masses: the reverse list
    (lists.rev_start, rev_slot), the pair constants and rows (pairs.pair_const, pair_row) and the
    sum list (pairs.sum_start, sum_end, and the -0.0 term); marks them current."""
    reverse_list(lists.start, lists.index, grains.x.shape[0], lists.rev_start, lists.rev_slot)
    list_constants(lists.start, lists.index, grains.radius, grains.mass, pairs.pair_const, pairs.pair_row)
    half = (pairs.sum_x.shape[0] - 1) // 2
    pairs.sum_x[2 * half] = -0.0
    pairs.sum_z[2 * half] = -0.0
    pairs.sum_t[2 * half] = -0.0
    sum_list(lists.start, lists.rev_start, lists.rev_slot, grains.x.shape[0], half, pairs.sum_start, pairs.sum_end)
    lists.layout[L_BUILT] = 1


@njit(cache=NUMBA_CACHE)
def force_parts(threads, n, buffers):
    """Parts of each force pass for params[THREADS] = threads: 1 on one thread, else
    PARTS_PER_THREAD per thread, at most n and the number of chunk buffers."""
    t = max(int(threads), 1)
    return min(1 if t == 1 else PARTS_PER_THREAD * t, max(n, 1), buffers)


@njit(cache=NUMBA_CACHE)
def contact_forces(grains, lists, pairs, drag_x, drag_z, params):
    """grains.force_x, force_z, torque (N,) = contact forces of all listed pairs (+ drag_x, drag_z
    (N,) when they have N entries; (0,) for none); lists.shear updated (thesis Eqs. 8-11).
    grains, lists, pairs: kernels.layout.Grains, Lists, Pairs.

    Two passes, each split into nb equal parts, PARTS_PER_THREAD per thread when there are
    several (smaller parts balance the threads better; no part reads what another
    part of the same pass writes): the law of every listed pair (law_pass) into pairs.pair_*,
    then the sum per grain (sum_pass) in the one fixed order of _sum_range. Every pair's result
    and every sum are the same for any nb: same bits on any thread count. The passes are separate
    parallel functions: numba fuses adjacent prange loops of equal range, which would let a part sum
    pairs another part has not yet computed."""
    n = grains.x.shape[0]
    if lists.layout[L_BUILT] < 0:
        derive_list(grains, lists, pairs)
    nb = force_parts(params[THREADS], n, pairs.pair_buf.shape[0])
    law_pass(nb, grains.x, grains.z, grains.vx, grains.vz, grains.spin, lists.start, pairs.pair_row, lists.index,
              lists.shear, pairs.pair_const, pairs.sum_x, pairs.sum_z, pairs.sum_t, pairs.pair_buf, params)
    sum_pass(nb, pairs.sum_start, pairs.sum_end, pairs.sum_x, pairs.sum_z, pairs.sum_t, grains.force_x,
              grains.force_z, grains.torque, drag_x, drag_z)


@njit(inline="always", cache=NUMBA_CACHE)
def law_scalars(params):
    """(dt, width, c_normal, c_tangential, damping, friction): the pair pass's scalars from params
    (the law's last four arguments, kernels.contact)."""
    return params[DT], params[WIDTH], params[C_NORMAL], params[C_TANGENTIAL], params[DAMPING], params[FRICTION]


@njit(parallel=True, error_model="numpy", cache=NUMBA_CACHE)
def law_pass(nb, x, z, vx, vz, spin, start, row, index, shear, const, sum_x, sum_z, sum_t, pair_buf, params):
    """The law of every listed pair, slots in nb equal ranges (_pair_range), chunk buffers
    pair_buf[part] (N_BUF, PAIR_BUF); row: the first grain of each slot (pairs.pair_row). [Arrays,
    not the records: the parallel loops keep the code they were measured with.]"""
    dt, width, c_n, c_t, damping, friction = law_scalars(params)
    npairs = start[x.shape[0]]
    for b in prange(nb):
        _pair_range(b * npairs // nb, (b + 1) * npairs // nb, x, z, vx, vz, spin, row, index, shear, const,
                    sum_x, sum_z, sum_t, pair_buf[b], width, dt, c_n, c_t, damping, friction)


@njit(parallel=True, cache=NUMBA_CACHE)
def sum_pass(nb, sum_start, sum_end, sum_x, sum_z, sum_t, force_x, force_z, torque, drag_x, drag_z):
    """Force and torque of every grain (_sum_terms), grains in nb equal ranges."""
    n = force_x.shape[0]
    has_drag = drag_x.shape[0] == n
    for b in prange(nb):
        _sum_terms(b * n // nb, (b + 1) * n // nb, sum_start, sum_end, sum_x, sum_z, sum_t, force_x, force_z,
                   torque, has_drag, drag_x, drag_z)


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
