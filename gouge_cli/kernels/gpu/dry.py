"""The dry step on the GPU: kernels.step.advance for B layers at once, one thread block per layer.

``advance_layers[B, threads](...)`` runs todo[b] steps of layer b in one launch (no host work
between steps). It takes the records of kernels.layout (Grains, Lists) whose fields are
model.state.State's arrays stacked over layers, [B, N] per grain and [B, capacity] per pair slot,
the pair results (pair_fx, pair_fz, pair_ti, pair_tj) likewise; wall, clock, params and counters
are [B, N_WALL] etc.; grains.top is [B, max top grains] with ntop[b] in use.

The step's sequence is the CPU's own: kernels.step._step and run_steps compiled for the device
(gpu.device) with each phase (kernels.step.STEP_PHASES) bound to its block version here
(BLOCK_PHASES), the block's threads sharing the per-grain and per-row loops and __syncthreads
between phases:
  open: open_step (thread 0: the wall and its grains); drift: _move_one of every grain
       (threads stride over grains; any late grain sets counters[K_NEED_REBUILD])
  rebuild: renumber (thread 0, every SORT_EVERY rebuilds), bin_cells (thread 0), rows counted
       by _scan_row per grain, offsets (thread 0), rows written and their history carried per
       grain: the same list, row for row and slot for slot, as kernels.neighbors.build_neighbors
  forces: the law per list row (kernels.contact), then each grain sums its own pairs in
       _sum_range's order (no atomics); reverse list by thread 0 (kernels.forces.reverse_list)
       after a rebuild
  wall: force, spring and kick (thread 0); close: close_step's kick per grain on the last step.
Every function named above is the CPU kernel's own code (gpu.device). With ``parallel`` = 1 the
thread-0 phases of the rebuild (binning, offsets, re-numbering, reverse list) run on the whole
block instead (kernels.gpu.parallel: counting sorts by integer atomics and prefix sums), the same
lists and the same bits; only the wall (its force sum and kick, O(top grains)) stays on thread 0.
With a timers row, thread 0 adds up clock64 cycles per phase (PHASES). Status per layer: OK, or
LIST_OVERFLOW with done[b] whole steps done and counters[K_NEEDED_CAPACITY] set; the host
enlarges the pair arrays and launches again (the step resumes at its rebuild, as on the CPU).
The pair constants are computed per pair and step (kernels.contact.pair_constants, same bits)
instead of stored, so pairs.pair_const is not used here (the host marks it stale).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import cuda

from ..layout import (BG_DAMPING, DT, K_NEEDED_CAPACITY, K_NEED_REBUILD, K_PAIRS, K_REBUILDS, K_STEP, L_BUILT,
                      L_SCRATCH, MID_STEP, SKIN, SORT_EVERY, WIDTH, Grains, Lists)
from ..neighbors import bin_cells
from ..step import STEP_PHASES, _step, open_step, renumber, run_steps
from .device import (d_bucket_order, d_carry_history, d_cell_grid, d_half_kick, d_law_scalars, d_minimum_image,
                     d_move_one, d_pair_constants, d_pair_force, d_permute, d_renumber_list, d_reverse_list, d_scan_row,
                     d_set_wall_grain_velocity, d_spatial_order, d_sum_range, d_wall_force, d_wall_kick, device)
from .parallel import SHARED_FLOATS, SHARED_INTS, clock64, p_bin_cells, p_renumber, p_reverse_list, p_scan

d_open_step = device(open_step, wall_kick=d_wall_kick, _set_wall_grain_velocity=d_set_wall_grain_velocity)
d_renumber = device(renumber, spatial_order=d_spatial_order, renumber_list=d_renumber_list, permute=d_permute)
d_bin_cells = device(bin_cells, bucket_order=d_bucket_order, cell_grid=d_cell_grid)

# who runs a phase (kernels.step's `block`): this thread, the block's size, the rebuild's bookkeeping
# by the whole block (0/1), the layer's timers row, the block's shared scratch (kernels.gpu.parallel)
Block = namedtuple("Block", ("t", "nt", "parallel", "timers", "sh", "shf"))

# layout[L_SCRATCH:] of each layer (the CPU build's per-block counters) carries the build's
# cell grid from thread 0 to the block (thread-0 binning)
_NCX, _NCZ = L_SCRATCH, L_SCRATCH + 1

# per-phase timers (timers[b, phase] in clock64 cycles of layer b's SM, thread 0's view after the
# phase's barrier; slot N_PHASES holds the last reading)
PHASES = ("open", "move", "renumber", "bin", "count_rows", "offsets", "write_rows", "reverse", "law", "sum",
          "wall", "close")
P_OPEN, P_MOVE, P_RENUMBER, P_BIN, P_COUNT, P_OFFSETS, P_WRITE, P_REVERSE, P_LAW, P_SUM, P_WALL, P_CLOSE = \
    range(len(PHASES))
N_PHASES = len(PHASES)


@cuda.jit(device=True)
def _mark(t, timers, phase):
    """Thread 0 charges the cycles since the last mark to `phase` (-1: only note the time);
    nothing when timers is empty (untimed launch)."""
    if t == 0 and timers.shape[0] > 0:
        now = clock64()
        if phase >= 0:
            timers[phase] += now - timers[N_PHASES]
        timers[N_PHASES] = now


@cuda.jit(device=True)
def _build(t, nt, g, li, params, parallel, timers, sh, shf):
    """kernels.neighbors.build_neighbors by the block: the pair count, or -(pairs) if the list
    does not fit (the list is unchanged then). parallel: binning and offsets by the block
    (kernels.gpu.parallel) instead of thread 0."""
    x, z, radius, body = g.x, g.z, g.radius, g.body
    width = params[WIDTH]
    skin = params[SKIN]
    n = x.shape[0]
    index = li[1]                   # (li.index is typed as tuple.index by numba-cuda)
    capacity = index.shape[0]
    layout = li.layout
    if parallel:
        ncx, ncz = p_bin_cells(t, nt, x, z, radius, width, skin, li.cell_of, li.order, li.cell_count, sh, shf)
    else:
        if t == 0:
            layout[_NCX], layout[_NCZ] = d_bin_cells(x, z, radius, width, skin, li.cell_of, li.order, li.cell_count)
        cuda.syncthreads()
        ncx = layout[_NCX]
        ncz = layout[_NCZ]
    _mark(t, timers, P_BIN)
    new_start = li.new_start
    for i in range(t, n, nt):
        new_start[i + 1] = d_scan_row(i, x, z, radius, body, width, skin, li.cell_of, li.cell_count, li.order,
                                      ncx, ncz, li.new_index, 0, 0)
    if t == 0:
        new_start[0] = 0
    cuda.syncthreads()
    _mark(t, timers, P_COUNT)
    if parallel:
        p_scan(t, nt, new_start, 0, n + 1, sh)
    else:
        if t == 0:
            for i in range(n):
                new_start[i + 1] += new_start[i]
        cuda.syncthreads()
    total = new_start[n]
    _mark(t, timers, P_OFFSETS)
    if total > capacity:
        return -total
    for i in range(t, n, nt):
        d_scan_row(i, x, z, radius, body, width, skin, li.cell_of, li.cell_count, li.order, ncx, ncz, li.new_index,
                   new_start[i], capacity)
        d_carry_history(i, new_start[i], new_start[i + 1], li.start, index, li.shear, li.new_index, li.new_shear)
    cuda.syncthreads()
    for k in range(t, total, nt):
        index[k] = li.new_index[k]
        li.shear[k] = li.new_shear[k]
    for i in range(t, n + 1, nt):
        li.start[i] = new_start[i]
    for i in range(t, n, nt):
        li.x_build[i] = x[i]
        li.z_build[i] = z[i]
    cuda.syncthreads()
    _mark(t, timers, P_WRITE)
    return total


@cuda.jit(device=True)
def _pending(block, counters):
    """kernels.step.pending for the block: the flag as every thread read it before any writes it."""
    value = counters[K_NEED_REBUILD]
    cuda.syncthreads()
    return value


@cuda.jit(device=True)
def _suspend(block, counters):
    """kernels.step.suspend by thread 0."""
    if block.t == 0:
        counters[K_NEED_REBUILD] = MID_STEP
    cuda.syncthreads()


@cuda.jit(device=True)
def _open(block, g, wall, clock, params):
    """kernels.step.open_phase by thread 0 (the wall and its grains)."""
    if block.t == 0:
        d_open_step(g, wall, clock, params)
    cuda.syncthreads()
    _mark(block.t, block.timers, P_OPEN)


@cuda.jit(device=True)
def _drift(block, g, li, params, counters, owed):
    """kernels.step.drift_phase: the threads stride over the grains (kernels.step.move_range);
    any late grain sets counters[K_NEED_REBUILD]."""
    t = block.t
    dt = params[DT]
    width = params[WIDTH]
    damp = params[BG_DAMPING]
    reach = 0.5 * params[SKIN]
    reach2 = reach * reach
    for i in range(t, g.x.shape[0], block.nt):
        if d_move_one(i, g.x, g.z, g.vx, g.vz, g.spin, g.force_x, g.force_z, g.torque, g.inv_mass, g.inv_inertia,
                      g.body, li.x_build, li.z_build, owed, dt, width, damp, reach2) > 0:
            counters[K_NEED_REBUILD] = 1
    cuda.syncthreads()
    _mark(t, block.timers, P_MOVE)


@cuda.jit(device=True)
def _rebuild(block, g, li, params, counters, drag_x, drag_z):
    """kernels.step.rebuild_phase by the block; False (K_NEEDED_CAPACITY set) if the list does not
    fit. drag_x, drag_z: empty (the GPU steps are dry)."""
    t, nt, parallel, timers, sh, shf = block
    every = int(params[SORT_EVERY])
    if every > 0 and counters[K_REBUILDS] % every == 0:
        if parallel:
            p_renumber(t, nt, g, li, params[WIDTH], sh, shf)
        else:
            if t == 0:
                d_renumber(g, li, drag_x, drag_z, params[WIDTH])
            cuda.syncthreads()
        _mark(t, timers, P_RENUMBER)
    npairs = _build(t, nt, g, li, params, parallel, timers, sh, shf)
    cuda.syncthreads()
    if t == 0:
        if npairs < 0:
            counters[K_NEEDED_CAPACITY] = -npairs
        else:
            li.layout[L_BUILT] = -1
            counters[K_PAIRS] = npairs
            counters[K_REBUILDS] += 1
            counters[K_NEED_REBUILD] = 0
    cuda.syncthreads()
    return npairs >= 0


@cuda.jit(device=True)
def _forces(block, g, li, pairs, params, drag_x, drag_z):
    """kernels.step.force_phase by the block: the reverse list after a rebuild, the law per list
    row (kernels.contact), then each grain sums its own pairs in _sum_range's order (no atomics).
    pairs: (pair_fx, pair_fz, pair_ti, pair_tj) per slot."""
    t, nt, parallel, timers, sh, shf = block
    pair_fx, pair_fz, pair_ti, pair_tj = pairs
    x, z, vx, vz, spin, radius, mass = g.x, g.z, g.vx, g.vz, g.spin, g.radius, g.mass
    start, index, shear = li.start, li[1], li.shear
    n = x.shape[0]
    built = li.layout[L_BUILT]
    cuda.syncthreads()
    if built < 0:
        if parallel:
            p_reverse_list(t, nt, start, index, n, li.rev_start, li.rev_slot, sh)
        elif t == 0:
            d_reverse_list(start, index, n, li.rev_start, li.rev_slot)
        cuda.syncthreads()
        if t == 0:
            li.layout[L_BUILT] = 1
        cuda.syncthreads()
        _mark(t, timers, P_REVERSE)
    dt, width, c_n, c_t, damping, friction = d_law_scalars(params)
    for i in range(t, n, nt):                   # the law, row by row (kernels.forces._fill, _laws)
        xi = x[i]
        zi = z[i]
        vxi = vx[i]
        vzi = vz[i]
        wi = spin[i]
        ri = radius[i]
        mi = mass[i]
        for k in range(start[i], start[i + 1]):
            j = index[k]
            rj = radius[j]
            r_ij, m_ij = d_pair_constants(ri, rj, mi, mass[j])
            fx, fz, ti, tj, ds, overlap, fn = d_pair_force(
                d_minimum_image(x[j] - xi, width), z[j] - zi, vx[j] - vxi, vz[j] - vzi, wi, spin[j], ri, rj, r_ij,
                m_ij, shear[k], dt, c_n, c_t, damping, friction)
            pair_fx[k] = fx
            pair_fz[k] = fz
            pair_ti[k] = ti
            pair_tj[k] = tj
            shear[k] = ds
    cuda.syncthreads()
    _mark(t, timers, P_LAW)
    for i in range(t, n, nt):                   # each grain gathers its pairs in the CPU's order
        d_sum_range(i, i + 1, start, li.rev_start, li.rev_slot, pair_fx, pair_fz, pair_ti, pair_tj, g.force_x,
                    g.force_z, g.torque, False, drag_x, drag_z)
    cuda.syncthreads()
    _mark(t, timers, P_SUM)


@cuda.jit(device=True)
def _wall(block, g, wall, clock, params, counters):
    """kernels.step.wall_phase by thread 0 (O(top grains))."""
    if block.t == 0:
        d_wall_force(g.force_x, g.force_z, g.top, wall)
        d_wall_kick(wall, clock, params)
        counters[K_STEP] += 1
    cuda.syncthreads()
    _mark(block.t, block.timers, P_WALL)


@cuda.jit(device=True)
def _close(block, g, wall, params):
    """kernels.step.close_phase by the block: the wall's grains take its velocity (thread 0), free
    grains get their second half kick (kernels.step._kick)."""
    t = block.t
    if t == 0:
        d_set_wall_grain_velocity(g.vx, g.vz, g.spin, g.top, wall)
    half = 0.5 * params[DT]
    damp = params[BG_DAMPING]
    for i in range(t, g.x.shape[0], block.nt):
        if g.body[i] == 0:
            g.vx[i] = d_half_kick(g.vx[i], g.force_x[i] * g.inv_mass[i], half, damp)
            g.vz[i] = d_half_kick(g.vz[i], g.force_z[i] * g.inv_mass[i], half, damp)
            g.spin[i] = d_half_kick(g.spin[i], g.torque[i] * g.inv_inertia[i], half, damp)
    cuda.syncthreads()
    _mark(t, block.timers, P_CLOSE)


# the step's sequence is the CPU's own (kernels.step._step, run_steps), its phases bound to the block's
BLOCK_PHASES = {"pending": _pending, "suspend": _suspend, "open_phase": _open, "drift_phase": _drift,
                "rebuild_phase": _rebuild, "force_phase": _forces, "wall_phase": _wall, "close_phase": _close}
if set(BLOCK_PHASES) != set(STEP_PHASES):        # (an unbound phase would run the CPU's under the simulator)
    raise ImportError(f"kernels.gpu.dry binds {sorted(BLOCK_PHASES)}, the step has {sorted(STEP_PHASES)}")
d_step = device(_step, **BLOCK_PHASES)
d_run_steps = device(run_steps, _step=d_step)


@cuda.jit
def advance_layers(grains, lists, pairs, wall, clock, params, counters, ntop, todo, done, status, none, parallel,
                   timers):
    """kernels.step.run_steps of layer blockIdx.x for todo[b] steps (module docstring); done[b]:
    whole steps done, status[b]: OK or LIST_OVERFLOW. grains, lists: kernels.layout.Grains and
    Lists of the layers' arrays stacked (grains.top [B, max top grains], ntop[b] of them in use);
    pairs: (pair_fx, pair_fz, pair_ti, pair_tj) [B, capacity]. none: an empty float64 array (no
    drag). parallel (0/1): the rebuild's bookkeeping by the block (kernels.gpu.parallel), same
    bits; timers: int64 [B, N_PHASES + 1] per-phase cycles added up (timed), or [B, 0] (untimed)."""
    sh = cuda.shared.array(SHARED_INTS, np.int64)
    shf = cuda.shared.array(SHARED_FLOATS, np.float64)
    b = cuda.blockIdx.x
    t = cuda.threadIdx.x
    gs = grains
    g = Grains(gs.x[b], gs.z[b], gs.vx[b], gs.vz[b], gs.spin[b], gs.radius[b], gs.mass[b], gs.inv_mass[b],
               gs.inv_inertia[b], gs.body[b], gs.force_x[b], gs.force_z[b], gs.torque[b], gs.top[b, :ntop[b]],
               gs.id[b])
    ls = lists
    li = Lists(ls.start[b], ls[1][b], ls.shear[b], ls.rev_start[b], ls.rev_slot[b], ls.x_build[b], ls.z_build[b],
               ls.new_start[b], ls.new_index[b], ls.new_shear[b], ls.layout[b], ls.cell_of[b], ls.order[b],
               ls.cell_count[b])                # (ls[1]: .index is typed as tuple.index by numba-cuda)
    timer = timers[b]
    _mark(t, timer, -1)
    block = Block(t, cuda.blockDim.x, parallel, timer, sh, shf)
    outcome, steps = d_run_steps(block, g, li, (pairs[0][b], pairs[1][b], pairs[2][b], pairs[3][b]), wall[b],
                                 clock[b], params[b], counters[b], todo[b], none, none)
    if t == 0:
        status[b] = outcome
        done[b] = steps
