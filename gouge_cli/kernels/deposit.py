"""Grain -> grid deposit of the pore-fluid model: solid fraction s, solid velocity and grad s
(thesis Appendix E, the solid fraction of Eq. 14; docs/physics/fluid.md).

Grid
----
Cell-centred, ``nx`` cells across the periodic width ``Lx`` and ``nz`` cells
between the wall planes ``z_bot`` and ``z_top``; cell (i, j) has its centre at
``((i + 1/2) dx, z_bot + (j + 1/2) dz)`` with ``dx = Lx / nx`` and
``dz = (z_top - z_bot) / nz``. The grid stretches with the layer: a cell keeps
its index and moves affinely with the two wall planes, so pressure and solid
fraction are attached to cells that follow the affine part of the solid motion.
P = 0 on both wall planes (half a cell from the boundary centres), periodic in x.

Deposit
-------
Grain k of radius R_k contributes its *in-domain area* a_k: pi R_k^2 minus the
circular segments lying below ``z_bot`` or above ``z_top`` (a wall grain centred
on its plane counts half). a_k goes to the four nearest cell centres with
bilinear weights W_kc (periodic in x; in z a centre below the first or above the
last cell centre puts all its z-weight on that boundary cell). Then
s_c = sum_k a_k W_kc / (dx dz) and phi_c = 1 - s_c. The solid velocity is the
a W weighted mean grain velocity *relative to the grid*,
u_rel = v_k - w(z_k), w(z) = w_bot + (z - z_bot)/(z_top - z_bot) (w_top - w_bot),
where w_bot, w_top are the plane velocities over the last fluid step. The
gradient of s is taken from the same deposit, grad s_c = -sum_k a_k dW_kc/dx_k
/ (dx dz) (the derivative of s_c with respect to the cell position), not by
differencing s between cells: only this one cancels the change of s when the
packing slides rigidly through the grid. In z it is the derivative of the deposit
extended by its mirror image across each plane: a grain between a plane and the
boundary cell centre (whose clamped weights do not vary with z) adds its x weights
times -2/dz (bottom) or +2/dz (top) to the boundary row (itself and its image), so
that grad_z s holds no jump of s to zero beyond the plane (a jump the source would
carry with the solid's grid-relative velocity: docs/physics/fluid.md, "The wall planes").

Arrays and indices: :mod:`gouge_cli.kernels.layout` (CR_* corner rows, M_* moments). One grain's
in-domain area and cell weights: :mod:`gouge_cli.kernels.deposit_weights` (shared with the drag).
"""

import math

import numpy as np
from numba import njit, prange

from . import NUMBA_CACHE
from .layout import (CELL_BITS, CELL_CODE, CELL_OUTSIDE, CR_A00, CR_A01, CR_A10, CR_A11, CR_CELL, CR_DFZ, CR_U, CR_W, CR_Z,
                     DEPOSIT_GROUPS, M_FLAG, M_G, M_H, M_S, M_U, M_W, N_MOMENTS)
from .deposit_weights import NEAR_PLANE, cell_weights, corner_shares, grain_area, near_side_area
from .lanes import add2, add4, add4_scaled
from .step import closed_velocity


@njit(cache=NUMBA_CACHE, error_model="numpy")
def deposit(discs, n, Lx, planes, fields, corners=None, partial=None, grain_kick=None, serial=False, finish=True):
    """Solid fraction, its kernel-consistent gradient and the grid-relative solid velocity.

    discs : kernels.layout.Discs, float64[>= n] grain centres x, z [d], velocities vx, vz [v0], radii [d]
    n : number of grains;  Lx : periodic width [d]
    planes : kernels.layout.Planes, the wall planes z_bot, z_top [d] and their velocities w_bot,
                 w_top [v0], which define the grid velocity w(z)
    fields : kernels.layout.Deposited, out, float64[nx, nz] each:
                 s, s_c = sum_k a_k G_kc / (dx dz) = 1 - phi [-];
                 ux, uz, a W weighted mean of vx and of vz - w(z_k) [v0] (0 in cells without solid);
                 grad_s_x, grad_s_z, -sum_k a_k dW_kc/dx_k / (dx dz) [1/d]: the derivative of
                 s_c with respect to the cell position, so that moving every grain by delta
                 changes s by -delta . grad_s to first order (a rigid translation generates no
                 source).
    corners : float64[N_CORNERS, >= n] out (rows CR_*), per grain: the flat index c00 of its
                 corner cell (i0, j0) (row CR_CELL, coded: kernels.layout.CELL_CODE; c00 < 0
                 for a grain outside the layer), the areas a00, a10, a01, a11 its four cells
                 receive and d fz/dz, reused by grain_drag_at for the drag, its height (z - z_bot) / (z_top - z_bot)
                 (row CR_Z, for the planes' fluid force); and the velocity it
                 deposits (rows CR_U, CR_W), scratch.
    partial : float64[DEPOSIT_GROUPS, nx * nz, N_MOMENTS] scratch. With corners and partial,
                 the fast form: vectorised passes for the cells and areas (_corners_range)
                 and the velocities (_velocity_range), then each grain adds 14 moments to the
                 record of its cell c00 (_moments_range), in DEPOSIT_GROUPS fixed groups of
                 grains (in parallel), each group into its own partial[g]; the columns two
                 groups or more added to are summed in group order (_collect_column), and one
                 pass over the cells collects the four shares (_expand_column): the same sums
                 regrouped (equal to round-off), the same bits for any thread count. Without
                 partial, the direct serial form, the definition:
                 every grain adds to its four cells (the tests' reference).
    grain_kick : (fast form only) None, or (owed, force_x, force_z, inv_mass, body, half, damp,
                 wall_vx, wall_vz): grain forces, inverse masses and kinds, half a time step,
                 the background damping and the top wall's velocity (kernels.step). If owed,
                 each grain's velocity is taken after the second half kick it still owes
                 (kernels.step.closed_velocity): the same bits as closing the step first,
                 without a pass over the grains.
    serial : (fast form only) for one thread: plain loops; the same sums in the same order.
    finish : (fast form, not serial) False: stop after the groups' moments, leaving the fields to
                 a later deposit_finish (on one thread, while others do something else:
                 kernels.coupled); the same bits.
    """
    x, z, vx, vz, radius = discs
    z_bot, z_top, w_bot, w_top = planes
    s, ux, uz_rel, grad_s_x, grad_s_z = fields
    nx, nz = s.shape
    size = nx * nz
    if partial is None:
        if grain_kick is not None:
            raise ValueError("deposit: grain_kick needs the fast form (corners and partial)")
        _deposit_range(x, z, vx, vz, radius, 0, n, Lx, z_bot, z_top, w_bot, w_top, nx, nz,
                       s.reshape(size), ux.reshape(size), uz_rel.reshape(size), grad_s_x.reshape(size),
                       grad_s_z.reshape(size), corners)
        _normalise(nx, nz, Lx, z_bot, z_top, s.reshape(size), ux.reshape(size), uz_rel.reshape(size),
                   grad_s_x.reshape(size), grad_s_z.reshape(size))
        return
    _deposit_grouped(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, s, ux, uz_rel, grad_s_x, grad_s_z,
                     corners, partial, grain_kick, serial, finish)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def deposit_finish(Lx, z_bot, z_top, fields, partial):
    """The rest of a parallel fast deposit stopped with finish=False, on this thread: the groups'
    records collected column by column in group order (_collect_column) and expanded into the
    fields (kernels.layout.Deposited; arguments as deposit's)."""
    nx = fields.s.shape[0]
    collect_columns(partial, nx, fields.s.shape[1], 0, nx)
    expand_columns(Lx, z_bot, z_top, fields, partial, 0, nx)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def collect_columns(partial, nx, nz, i0, i1):
    """deposit_finish's first half on grid columns i0 <= i < i1 (_collect_column; each column on
    its own). All columns must be collected before any is expanded (a column's expansion reads
    the column to its left)."""
    records = partial.reshape(partial.size)
    for i in range(i0, i1):
        _collect_column(records, i, nx, nz)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def expand_columns(Lx, z_bot, z_top, fields, partial, i0, i1):
    """deposit_finish's second half on grid columns i0 <= i < i1 (_expand_column, each column on
    its own, the same bits whichever columns a call takes)."""
    s, ux, uz_rel, grad_s_x, grad_s_z = fields
    nx, nz = s.shape
    size = nx * nz
    inv_area = nx / Lx * nz / (z_top - z_bot)
    records = partial.reshape(partial.size)
    for i in range(i0, i1):
        _expand_column(records, i, nx, nz, nx / Lx, inv_area, s.reshape(size), ux.reshape(size),
                       uz_rel.reshape(size), grad_s_x.reshape(size), grad_s_z.reshape(size))


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _expand(Lx, z_bot, z_top, s, ux, uz_rel, grad_s_x, grad_s_z, partial, serial):
    """s, ux, uz_rel, grad_s_x, grad_s_z from the collected records (each column's in partial[g],
    g its _source), the columns in a plain loop if serial, else in parallel."""
    nx, nz = s.shape
    size = nx * nz
    solid = s.reshape(size)
    momentum_x = ux.reshape(size)
    momentum_z = uz_rel.reshape(size)
    slope_x = grad_s_x.reshape(size)
    slope_z = grad_s_z.reshape(size)
    inv_area = nx / Lx * nz / (z_top - z_bot)
    records = partial.reshape(partial.size)
    if serial:
        for i in range(nx):
            _expand_column(records, i, nx, nz, nx / Lx, inv_area, solid, momentum_x, momentum_z, slope_x, slope_z)
    else:
        _expand_parallel(records, nx, nz, nx / Lx, inv_area, solid, momentum_x, momentum_z, slope_x, slope_z)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _deposit_grouped(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, s, ux, uz_rel, grad_s_x, grad_s_z,
                     corners, partial, grain_kick, serial, finish):
    """deposit's fast form: cells and moments in DEPOSIT_GROUPS fixed groups, group g into
    partial[g] (in parallel unless serial), the shared columns summed in group order, then
    expanded per cell. The same sums in the same order either way. (One thread also uses a
    buffer per group and adds only the shared columns: a single scratch buffer, each group
    added to partial[0] at once, was no faster.)"""
    nx, nz = s.shape
    if serial:
        for g in range(DEPOSIT_GROUPS):
            _group(g, x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, nx, nz, corners, partial, grain_kick)
    else:
        _groups_parallel(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, nx, nz, corners, partial,
                         grain_kick)
        if not finish:
            return
    _collect(partial, nx, nz, serial)
    _expand(Lx, z_bot, z_top, s, ux, uz_rel, grad_s_x, grad_s_z, partial, serial)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _group(g, x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, nx, nz, corners, partial, grain_kick):
    """Cells, areas, velocities and moments of the grains of group g into partial[g]."""
    first = g * n // DEPOSIT_GROUPS
    last = (g + 1) * n // DEPOSIT_GROUPS
    _corners_range(x, z, radius, first, last, Lx, z_bot, z_top, nx, nz, corners)
    _velocity_range(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, corners, grain_kick)
    _moments_range(first, last, partial[g], corners, nz, nz / (z_top - z_bot))


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _add_column(records, i, g, group, span):
    """records: partial as one flat array, group = nx * nz * N_MOMENTS its group stride, span =
    nz * N_MOMENTS a column's. partial[0] += partial[g] over grid column i if group g flagged it
    (a column's records are contiguous: one vector loop; the flag and padding slots add too and
    stay != 0 / 0). Unflagged: all +0.0 there, and x + (+0.0) is x (sums are never -0.0)."""
    start = np.uint64(i) * span
    source = np.uint64(g) * group + start
    if records[source + np.uint64(M_FLAG)] == 0.0:
        return
    for c in range(np.uint64(0), span):
        records[start + c] += records[source + c]


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _collect(partial, nx, nz, serial):
    """_collect_column for every grid column, in a plain loop if serial, else in parallel."""
    if serial:
        records = partial.reshape(partial.size)
        for i in range(nx):
            _collect_column(records, i, nx, nz)
    else:
        _collect_parallel(partial, nx, nz)


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def _collect_parallel(partial, nx, nz):
    """_collect_column for every grid column, the columns in parallel."""
    records = partial.reshape(partial.size)
    for i in prange(nx):
        _collect_column(records, i, nx, nz)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _collect_column(records, i, nx, nz):
    """partial[0] += partial[g] over grid column i for g = 1, 2, ... in order (the groups that
    flagged it), if two groups or more flagged it; records: partial as one flat array. A column
    only one group flagged is left in that group's records (_source: a group's grains are
    nearby, so most columns are; 0 + x is x, so the sums are the same)."""
    if _flaggers(records, i, nx, nz)[0] < 2:
        return
    span = np.uint64(nz * N_MOMENTS)
    for g in range(1, DEPOSIT_GROUPS):
        _add_column(records, i, g, np.uint64(nx) * span, span)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _source(records, i, nx, nz):
    """The group whose records hold grid column i's totals after _collect_column: the one group
    that flagged it, else 0 (none: zeros; two or more: collected into partial[0]); records:
    partial as one flat array."""
    flagged, group = _flaggers(records, i, nx, nz)
    return group if flagged == 1 else 0


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _flaggers(records, i, nx, nz):
    """(how many groups flagged grid column i, the last of them); records: partial as one flat
    array."""
    flagged = 0
    group = 0
    for g in range(DEPOSIT_GROUPS):
        if records[np.uint64(((g * nx + i) * nz) * N_MOMENTS + M_FLAG)] != 0.0:
            flagged += 1
            group = g
    return flagged, group


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def _groups_parallel(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, nx, nz, corners, partial, grain_kick):
    """_group for every group, the groups in parallel (no two write the same memory)."""
    for g in prange(DEPOSIT_GROUPS):
        _group(g, x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, nx, nz, corners, partial, grain_kick)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _corners_range(x, z, radius, first, last, Lx, z_bot, z_top, nx, nz, corners):
    """corners[:, first:last]: grain_area, cell_weights and corner_shares, the same values.
    A loop without calls or branches (SIMD) for grains with x in [dx/2 - Lx, Lx + dx/2) (one
    periodic wrap at most) that are, for each plane, clear of it or centred on it to within
    NEAR_PLANE R (the wall grains: in_domain_area with near_side_area); it marks the
    others (d fz/dz = -1), which then take the scalar path (grain_area, cell_weights), and
    skips that path when there are none."""
    inv_dx = nx / Lx
    inv_dz = nz / (z_top - z_bot)
    fnx = float(nx)
    fnz = float(nz)
    cell, a00, a10, a01, a11, dfz = (corners[CR_CELL], corners[CR_A00], corners[CR_A10], corners[CR_A01],
                                     corners[CR_A11], corners[CR_DFZ])
    height = corners[CR_Z]
    inv_h = 1.0 / (z_top - z_bot)
    odd_count = 0
    for kk in range(first, last):
        k = np.uint64(kk)
        zk = z[k]
        r = radius[k]
        full = math.pi * r * r
        hb = zk - z_bot
        ht = z_top - zk
        area = (full if hb >= r else near_side_area(hb, r)) - (0.0 if ht >= r else near_side_area(-ht, r))
        xi = x[k] * inv_dx - 0.5
        fi = np.floor(xi)        # (a float: math.floor returns an int, a conversion AVX2 cannot vectorise)
        fx = xi - fi
        fi = fi + fnx if fi < 0.0 else fi
        zeta = hb * inv_dz - 0.5
        fj = np.floor(zeta)
        inside = (fj >= 0.0) & (fj < fnz - 1.0)
        top = fj >= fnz - 1.0
        j0 = fj if inside else (fnz - 2.0 if top else 0.0)
        fz = zeta - fj if inside else (1.0 if top else 0.0)
        a0 = area * (1.0 - fz)
        a1 = area * fz
        cell[k] = (fi * fnz + j0) + CELL_CODE
        a00[k] = a0 * (1.0 - fx)
        a10[k] = a0 * fx
        a01[k] = a1 * (1.0 - fx)
        a11[k] = a1 * fx
        height[k] = hb * inv_h
        cut = ((hb < r) & (abs(hb) > NEAR_PLANE * r)) | ((ht < r) & (abs(ht) > NEAR_PLANE * r))
        odd = cut | (area <= 0.0) | (fi < 0.0) | (fi != fi) | (fi >= fnx)   # (a NaN x is odd)
        dfz[k] = -1.0 if odd else (inv_dz if inside else 0.0)
        odd_count += 1 if odd else 0
    if odd_count == 0:
        return
    for k in range(first, last):
        if dfz[k] >= 0.0:
            continue
        area = grain_area(z[k], radius[k], z_bot, z_top)
        if area <= 0.0:
            cell[k] = CELL_OUTSIDE
            dfz[k] = 0.0
            continue
        i0, i1, j0, fx, fz, slope = cell_weights(x[k], z[k], inv_dx, inv_dz, z_bot, nx, nz)
        c00, _, _, _, a00[k], a10[k], a01[k], a11[k] = corner_shares(area, i0, i1, j0, fx, fz, nz)
        cell[k] = float(c00) + CELL_CODE
        dfz[k] = slope


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _velocity_range(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, corners, grain_kick):
    """corners rows CR_U, CR_W of grains first:last: the velocity each deposits, vx and vz - w(z)
    (grid-relative), after the owed half kick if grain_kick says so (see deposit). A loop
    without stores to shared places: it vectorises, which the scatter that follows cannot."""
    if grain_kick is None:                  # (the arrays after False are not read)
        _velocity_loop(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, corners,
                       (bool(False), vx, vz, vx, vx, 0.0, 0.0, 0.0, 0.0))
    else:
        _velocity_loop(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, corners, grain_kick)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _velocity_loop(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, corners, grain_kick):
    """_velocity_range with a grain_kick tuple."""
    owed, force_x, force_z, inv_mass, body, half, damp, wall_vx, wall_vz = grain_kick
    grid_strain_rate = (w_top - w_bot) / (z_top - z_bot)
    us, ws = corners[CR_U], corners[CR_W]
    if owed:
        for kk in range(first, last):
            k = np.uint64(kk)
            u, v = closed_velocity(body[k], vx[k], vz[k], force_x[k] * inv_mass[k], force_z[k] * inv_mass[k],
                                   half, damp, wall_vx, wall_vz)
            us[k] = u
            ws[k] = v - (w_bot + (z[k] - z_bot) * grid_strain_rate)
    else:
        for kk in range(first, last):
            k = np.uint64(kk)
            us[k] = vx[k]
            ws[k] = vz[k] - (w_bot + (z[k] - z_bot) * grid_strain_rate)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _moments_range(first, last, moments, corners, nz, inv_dz):
    """moments (nx * nz, N_MOMENTS) of grains first:last from their corners and velocities,
    flagging (M_FLAG) the grid columns they may add to (_flag_columns). Zeroes the columns
    flagged by the previous call first, so the rest of moments must be zero on entry (a zeroed
    allocation keeps it so)."""
    flat = moments.reshape(moments.size)
    span = np.uint64(nz * N_MOMENTS)
    for head in range(0, moments.shape[0], nz):
        if moments[head, M_FLAG] != 0.0:
            start = np.uint64(head * N_MOMENTS)
            for c in range(start, start + span):
                flat[c] = 0.0
    a00s, a10s, a01s, a11s, dfz, us, ws = (corners[CR_A00], corners[CR_A10], corners[CR_A01], corners[CR_A11],
                                           corners[CR_DFZ], corners[CR_U], corners[CR_W])
    cells = corners[CR_CELL].view(np.int64)
    for kk in range(first, last):
        k = np.uint64(kk)
        cell = cells[k] - CELL_BITS           # (an integer load: no float -> int conversion)
        if cell < 0:
            continue
        r = np.uint64(cell) * np.uint64(N_MOMENTS)
        a00 = a00s[k]
        a10 = a10s[k]
        a01 = a01s[k]
        a11 = a11s[k]
        add4(flat, r + np.uint64(M_S), a00, a10, a01, a11)           # (4-lane vector adds, same bits)
        add4_scaled(flat, r + np.uint64(M_U), a00, a10, a01, a11, us[k])
        add4_scaled(flat, r + np.uint64(M_W), a00, a10, a01, a11, ws[k])
        add2(flat, r + np.uint64(M_G), (a00 + a01) * dfz[k], (a10 + a11) * dfz[k])
        if dfz[k] == 0.0:                     # between a plane and the boundary centre: the mirror term
            mu = 2.0 * inv_dz if a00 + a10 == 0.0 else -2.0 * inv_dz
            add4_scaled(flat, r + np.uint64(M_H), a00, a10, a01, a11, mu)
    _flag_columns(first, last, corners[CR_CELL], moments, nz)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _flag_columns(first, last, cell, moments, nz):
    """Flag (M_FLAG of a column's first record) an arc of grid columns that holds the column of
    every grain first:last (cell: the corners row CR_CELL): offsets from the first grain's
    column, taken into (-nx/2, nx/2] around it, and their least and greatest. The arc may hold
    columns no grain added to (they stay zero); it is one vector pass (int32 columns, integer
    min and max), cheaper than a flag store per grain."""
    nx = moments.shape[0] // nz
    if last <= first:
        return
    inv_nz = 1.0 / nz
    base = np.int32(max(cell[first] - CELL_CODE, 0.0) * inv_nz)   # c00 = i nz + j: i (1/nz rounded: still i)
    half = np.int32(nx // 2)
    width = np.int32(nx)
    lo = np.int32(0)
    hi = np.int32(0)
    for kk in range(first, last):
        k = np.uint64(kk)
        c00 = cell[k] - CELL_CODE                                      # (exact)
        col = np.int32(c00 * inv_nz) if c00 >= 0.0 else base           # (c00 < 0: outside the layer)
        d = col - base
        d = d - width if d > half else d
        d = d + width if d <= -half else d
        lo = min(lo, d)
        hi = max(hi, d)
    column = nz * N_MOMENTS
    flat = moments.reshape(moments.size)
    for d in range(lo, hi + 1):
        flat[((base + d) % nx) * column + M_FLAG] = 1.0


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def _expand_parallel(records, nx, nz, inv_dx, inv_area, solid, momentum_x, momentum_z, slope_x, slope_z):
    """_expand_column for every grid column, the columns in parallel (each writes its own cells)."""
    for i in prange(nx):
        _expand_column(records, i, nx, nz, inv_dx, inv_area, solid, momentum_x, momentum_z, slope_x, slope_z)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _expand_column(records, i, nx, nz, inv_dx, inv_area, solid, momentum_x, momentum_z, slope_x, slope_z):
    """s, mean velocities and slopes of grid column i (as _deposit_range then _normalise leave them)
    from the moment records of the grains whose cell c00 is this one (share 00), the one to its
    left (10), below (01), left-below (11), each column's in partial[_source] after _collect;
    records: partial as one flat array. [Unsigned offsets (no negative-index checks), the slots
    as uint64 constants (uint64 + int64 is float64 in numba).]"""
    il = i - 1 if i > 0 else nx - 1
    m = np.uint64(N_MOMENTS)
    s0, s1, s2, s3 = np.uint64(M_S), np.uint64(M_S + 1), np.uint64(M_S + 2), np.uint64(M_S + 3)
    u0, u1, u2, u3 = np.uint64(M_U), np.uint64(M_U + 1), np.uint64(M_U + 2), np.uint64(M_U + 3)
    w0, w1, w2, w3 = np.uint64(M_W), np.uint64(M_W + 1), np.uint64(M_W + 2), np.uint64(M_W + 3)
    g0, g1 = np.uint64(M_G), np.uint64(M_G + 1)
    h0, h1, h2, h3 = np.uint64(M_H), np.uint64(M_H + 1), np.uint64(M_H + 2), np.uint64(M_H + 3)
    own = (np.uint64(_source(records, i, nx, nz)) * np.uint64(nx) + np.uint64(i)) * np.uint64(nz) * m
    left = (np.uint64(_source(records, il, nx, nz)) * np.uint64(nx) + np.uint64(il)) * np.uint64(nz) * m
    c = np.uint64(i * nz)
    for j in range(nz):
        a = records[own + s0] + records[left + s1]
        b = records[own + u0] + records[left + u1]
        e = records[own + w0] + records[left + w1]
        gx = (records[own + s0] + records[own + s1]) - (records[left + s0] + records[left + s1])
        gz = records[own + g0] + records[left + g1]
        hz = records[own + h0] + records[left + h1]
        if j > 0:
            below = own - m
            corner = left - m
            a += records[below + s2] + records[corner + s3]
            b += records[below + u2] + records[corner + u3]
            e += records[below + w2] + records[corner + w3]
            gx += (records[below + s2] + records[below + s3]) - (records[corner + s2] + records[corner + s3])
            gz -= records[below + g0] + records[corner + g1]
            hz += records[below + h2] + records[corner + h3]
        solid[c], momentum_x[c], momentum_z[c], slope_x[c], slope_z[c] = _normalised(
            a, b, e, gx * inv_dx, gz + hz, inv_area)
        own += m
        left += m
        c += np.uint64(1)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _deposit_range(x, z, vx, vz, radius, first, last, Lx, z_bot, z_top, w_bot, w_top, nx, nz,
                   solid, momentum_x, momentum_z, slope_x, slope_z, corners):
    """Raw sums of grains first:last into the flat (nx * nz,) grids (zeroed first), each grain
    adding to its four cells (the direct form of the deposit)."""
    thickness = z_top - z_bot
    inv_dx = nx / Lx
    inv_dz = nz / thickness
    grid_strain_rate = (w_top - w_bot) / thickness
    for c in range(nx * nz):
        solid[c] = 0.0
        momentum_x[c] = 0.0
        momentum_z[c] = 0.0
        slope_x[c] = 0.0
        slope_z[c] = 0.0
    for k in range(first, last):
        area = grain_area(z[k], radius[k], z_bot, z_top)
        if area <= 0.0:
            if corners is not None:
                corners[CR_CELL, k] = CELL_OUTSIDE
            continue
        i0, i1, j0, fx, fz, dfz = cell_weights(x[k], z[k], inv_dx, inv_dz, z_bot, nx, nz)
        c00, c10, c01, c11, a00, a10, a01, a11 = corner_shares(area, i0, i1, j0, fx, fz, nz)
        if corners is not None:
            corners[CR_CELL, k] = float(c00) + CELL_CODE
            corners[CR_A00, k] = a00
            corners[CR_A10, k] = a10
            corners[CR_A01, k] = a01
            corners[CR_A11, k] = a11
            corners[CR_DFZ, k] = dfz
            corners[CR_Z, k] = (z[k] - z_bot) / thickness
        a0 = area * (1.0 - fz)
        a1 = area * fz
        vxk = vx[k]
        vzk = vz[k] - (w_bot + (z[k] - z_bot) * grid_strain_rate)
        solid[c00] += a00
        solid[c10] += a10
        solid[c01] += a01
        solid[c11] += a11
        momentum_x[c00] += a00 * vxk
        momentum_x[c10] += a10 * vxk
        momentum_x[c01] += a01 * vxk
        momentum_x[c11] += a11 * vxk
        momentum_z[c00] += a00 * vzk
        momentum_z[c10] += a10 * vzk
        momentum_z[c01] += a01 * vzk
        momentum_z[c11] += a11 * vzk
        gx0 = a0 * inv_dx
        gx1 = a1 * inv_dx
        slope_x[c00] += gx0
        slope_x[c10] -= gx0
        slope_x[c01] += gx1
        slope_x[c11] -= gx1
        gz0 = area * (1.0 - fx) * dfz
        gz1 = area * fx * dfz
        slope_z[c00] += gz0
        slope_z[c01] -= gz0
        slope_z[c10] += gz1
        slope_z[c11] -= gz1
        if dfz == 0.0:            # between a plane and the boundary centre: the grain and its mirror image
            mu = 2.0 * inv_dz if fz == 1.0 else -2.0 * inv_dz
            slope_z[c00] += a00 * mu
            slope_z[c10] += a10 * mu
            slope_z[c01] += a01 * mu
            slope_z[c11] += a11 * mu


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _normalised(solid, momentum_x, momentum_z, slope_x, slope_z, inv_area):
    """One cell's raw sums -> (s, mean vx, mean vz - w, ds/dx, ds/dz) (see deposit)."""
    if solid > 0.0:
        momentum_x /= solid
        momentum_z /= solid
    return solid * inv_area, momentum_x, momentum_z, slope_x * inv_area, slope_z * inv_area


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _normalise(nx, nz, Lx, z_bot, z_top, solid, momentum_x, momentum_z, slope_x, slope_z):
    """Raw sums -> s, mean velocities and slopes (see deposit)."""
    inv_area = nx / Lx * nz / (z_top - z_bot)
    for c in range(nx * nz):
        solid[c], momentum_x[c], momentum_z[c], slope_x[c], slope_z[c] = _normalised(
            solid[c], momentum_x[c], momentum_z[c], slope_x[c], slope_z[c], inv_area)

