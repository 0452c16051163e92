"""Fluid drag on the grains (thesis Eqs. 12-13): pressure gradient at cell centres, the drag
density -(grad P)/s per cell, gathered onto each grain with the deposit's weights and areas.

The running coupling uses its energy-consistent form (drag_triples, grain_drag_consistent): the
exact adjoint of the deposit that makes the pressure source, so that in the undrained limit the
work of the drag equals minus the change of the fluid's stored energy (module section below).
The gradient form (drag_density, grain_drag) is its definition in the continuum and the tests'
reference.

Drag
----
F_k = -a_k sum_c W_kc (grad P)_c / s_c with the same weights and areas as the
deposit (s unclamped), so sum_k F_k = -sum_c (grad P)_c dx dz exactly (over
cells holding solid); for a grain inside the layer a_k = V_k = pi R_k^2. (grad P)_c is the mean of the two face gradients on each axis, so the
discrete integral of grad P telescopes to the boundary values: with P = 0 on
both planes the total drag is zero to round-off.
"""


import numpy as np
from numba import njit, prange

from . import NUMBA_CACHE
from .layout import CELL_BITS, CR_A00, CR_A01, CR_A10, CR_A11, CR_CELL, CR_DFZ
from .deposit_weights import cell_weights, corner_shares, grain_area
from .lanes import bilinear_pairs
from .pressure import cells, flat, flat_columns


@njit(cache=NUMBA_CACHE, error_model="numpy")
def pressure_gradient(P, dx, dz, p_bot, p_top, gx, gz):
    """Cell-centred grad P [E/d]: the mean of the two face gradients on each axis.

    Periodic in x; the wall faces use P = p_bot, p_top on the planes, half a cell
    away. Exact for a field linear in z; sum_c g dx dz telescopes to the plane
    values: sum_c gz dx dz = dx sum_i (p_top - p_bot), sum_c gx = 0.
    """
    nx, nz = P.shape
    pf, fx, fz = flat(P), flat(gx), flat(gz)
    size, unz, last, one = flat_columns(P)
    zero = np.uint64(0)
    two_dx = 2.0 * dx
    if nx == 1:
        for c in range(zero, size):
            fx[c] = (pf[c] - pf[c]) / two_dx
    else:
        for c in range(zero, unz):             # flat loops; the first and last columns wrap
            fx[c] = (pf[c + unz] - pf[c + last]) / two_dx
        for c in range(unz, last):
            fx[c] = (pf[c + unz] - pf[c - unz]) / two_dx
        for c in range(last, size):
            fx[c] = (pf[c - last] - pf[c - unz]) / two_dx
    for c in range(one, size - one):           # inner rows; the wall rows are redone below
        fz[c] = 0.5 * ((pf[c] - pf[c - one]) / dz + (pf[c + one] - pf[c]) / dz)
    for i in range(nx):
        for j in (0, nz - 1):
            fz[i * nz + j] = _wall_row_gz(P, i, j, dz, p_bot, p_top)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _wall_row_gz(P, i, j, dz, p_bot, p_top):
    """pressure_gradient's gz of cell (i, j) in a wall row (j = 0 or nz - 1)."""
    nz = P.shape[1]
    if j == 0:
        below = (P[i, 0] - p_bot) / (0.5 * dz)
    else:
        below = (P[i, j] - P[i, j - 1]) / dz
    if j == nz - 1:
        above = (p_top - P[i, j]) / (0.5 * dz)
    else:
        above = (P[i, j + 1] - P[i, j]) / dz
    return 0.5 * (below + above)


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _density(gx, gz, s):
    """Drag per unit grain area of one cell, -(gx, gz) / s, or (0, 0) where s <= 0."""
    if s > 0.0:
        inv = -1.0 / s
        return gx * inv, gz * inv
    return 0.0, 0.0


@njit(cache=NUMBA_CACHE, error_model="numpy")
def drag_density(gx, gz, s, fx, fz):
    """Drag per unit grain area f = -grad P / s [E/d] (s = 1 - phi unclamped; 0 where s = 0)."""
    nx, nz = s.shape
    for i in range(nx):
        for j in range(nz):
            fx[i, j], fz[i, j] = _density(gx[i, j], gz[i, j], s[i, j])


@njit(cache=NUMBA_CACHE, error_model="numpy")
def drag_density_pairs(gx, gz, s, pairs):
    """drag_density into interleaved pairs: pairs[2c], pairs[2c + 1] = fx, fz of flat cell c
    (float64[2 nx nz]), the layout grain_drag_at gathers from."""
    fx, fz, sf = flat(gx), flat(gz), flat(s)
    for c in range(np.uint64(sf.size)):
        k = np.uint64(2) * c
        pairs[k], pairs[k + np.uint64(1)] = _density(fx[c], fz[c], sf[c])


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _gather(flat_x, flat_z, c00, c10, a00, a10, a01, a11):
    """sum over the four corner cells of area x force density (c01 = c00 + 1, c11 = c10 + 1)."""
    c01 = c00 + np.uint64(1)
    c11 = c10 + np.uint64(1)
    return (a00 * flat_x[c00] + a10 * flat_x[c10] + a01 * flat_x[c01] + a11 * flat_x[c11],
            a00 * flat_z[c00] + a10 * flat_z[c10] + a01 * flat_z[c01] + a11 * flat_z[c11])


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def grain_drag(x, z, radius, n, Lx, z_bot, z_top, fx, fz, drag_x, drag_z):
    """Fluid force on each grain, F_k = a_k sum_c G_kc f_c (thesis Eq. 12).

    f = -grad P / (1 - phi) from drag_density; a_k is the in-domain area (pi R^2
    for a grain inside the layer, unit out-of-plane thickness) and W the deposit
    weights, so F_k = -a_k sum_c G_kc grad P_c / (1 - phi_c).
    drag_x, drag_z : out, float64[>= n] [E d^2].
    """
    nx, nz = fx.shape
    inv_dx = nx / Lx
    inv_dz = nz / (z_top - z_bot)
    flat_x = fx.reshape(nx * nz)
    flat_z = fz.reshape(nx * nz)
    for k in prange(n):
        area = grain_area(z[k], radius[k], z_bot, z_top)
        if area <= 0.0:
            drag_x[k] = 0.0
            drag_z[k] = 0.0
            continue
        i0, i1, j0, wx, wz, _ = cell_weights(x[k], z[k], inv_dx, inv_dz, z_bot, nx, nz)
        c00, c10, c01, c11, a00, a10, a01, a11 = corner_shares(area, i0, i1, j0, wx, wz, nz)
        drag_x[k], drag_z[k] = _gather(flat_x, flat_z, c00, c10, a00, a10, a01, a11)


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def grain_drag_at(corners, n, nz, pairs, drag_x, drag_z):
    """grain_drag with the corner cells and areas the deposit stored (same positions) and the
    density as interleaved pairs (drag_density_pairs): the same values, without recomputing
    areas and weights, x and z in the two lanes of one vector sum (kernels.lanes). Cell c00
    from the bits of the coded row CR_CELL (kernels.layout.CELL_BITS); c10 = c00 + nz, less
    nx nz past the last column. [No float -> int conversion per grain (the cell is read as an
    integer) and an unsigned loop index (no negative-index checks): both were a large share of
    the loop. A parallel loop on one thread too: a plain loop through an inlined per-grain helper
    that takes the arrays is much slower (numba reference-counts them per grain).]"""
    cells = corners[CR_CELL].view(np.int64)
    a00, a10, a01, a11 = corners[CR_A00], corners[CR_A10], corners[CR_A01], corners[CR_A11]
    column = np.uint64(2 * nz)
    end = np.uint64(pairs.size)
    for kk in prange(n):
        k = np.uint64(kk)                   # (unsigned: no negative-index checks)
        cell = cells[k] - CELL_BITS
        if cell < 0:
            drag_x[k] = 0.0
            drag_z[k] = 0.0
            continue
        i00 = np.uint64(cell) * np.uint64(2)
        i10 = i00 + column
        i10 = i10 - end if i10 >= end else i10
        drag_x[k], drag_z[k] = bilinear_pairs(pairs, i00, i10, a00[k], a10[k], a01[k], a11[k])


# ---- the energy-consistent drag ---------------------------------------------------------------
#
# The source (kernels.pressure.undrained_source) changes P_c by dP = (1 + beta P) ds_c,e / (beta s phi),
# ds_c,e = ds_c + dt u_c . grad s_c, from the deposit s_c = sum_k a_k W_kc / (dx dz) and
# u_c = sum_k a_k W_kc v_k / (dx dz s_c). The fluid then stores dE = dx dz sum_c (P_c / s_c) ds_c,e,
# and the force that does exactly minus that work on each grain is
#
#     F_k = -a_k sum_c [ q_c dW_kc/dx_k + W_kc r_c ],   q = P / s,  r = (P / s^2) grad s,
#
# (grad s the deposit's own gradient, mirrored across the wall planes in z). Summed by parts in the
# continuum this is -a_k grad P / s,
# the drag of Eq. 12; on the grid it is its adjoint, so the coupling neither creates nor destroys
# energy at any wavelength the grid holds (the gradient form, with the centred difference of P,
# does not see grid-scale modes the deposit makes, and pumps energy into them when no diffusion
# damps them: the nearly undrained limit). Its total is zero exactly: sum_k a_k dW_kc/dx_k =
# -dx dz grad s_c cancels the r term cell by cell (with P = 0 on the planes, -integral grad P = 0
# too). Through the filter (kernels.filter) q and r go back by S^T.


@njit(cache=NUMBA_CACHE, error_model="numpy")
def drag_triples(P, s, grad_s_x, grad_s_z, q, rx, rz, i0=0, i1=-1):
    """q = P/s [E], r = (P/s^2) grad s [E/d] per cell (0 where s <= 0); all float64[nx, nz]
    (i0, i1: kernels.pressure.cells)."""
    pf, sf, gx, gz, qf, xf, zf = flat(P), flat(s), flat(grad_s_x), flat(grad_s_z), flat(q), flat(rx), flat(rz)
    lo, hi = cells(P, i0, i1)
    for c in range(lo, hi):          # (selects, not branches: the loop vectorises)
        solid = sf[c] > 0.0
        inv = 1.0 / sf[c]
        value = pf[c] * inv
        qf[c] = value if solid else 0.0
        xf[c] = value * inv * gx[c] if solid else 0.0
        zf[c] = value * inv * gz[c] if solid else 0.0


@njit(cache=NUMBA_CACHE, error_model="numpy")
def interleave_triples(q, rx, rz, triples, i0, i1):
    """triples[3c], [3c + 1], [3c + 2] = q, rx, rz of flat cell c (float64[3 nx nz]) on the grid columns
    i0 <= i < i1: a grain's cells (c00, c01) and (c10, c11) are then two runs of six adjacent values."""
    nz = q.shape[1]
    qf, xf, zf = flat(q), flat(rx), flat(rz)
    for c in range(np.uint64(i0 * nz), np.uint64(i1 * nz)):
        k = np.uint64(3) * c
        triples[k] = qf[c]
        triples[k + np.uint64(1)] = xf[c]
        triples[k + np.uint64(2)] = zf[c]


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def grain_drag_consistent(corners, n, nz, inv_dx, triples, drag_x, drag_z):
    """F_k = -a_k sum_c [q_c dW_kc/dx_k + W_kc r_c] [E d^2] with the corner cells, areas and d fz/dz
    the deposit stored (kernels.deposit: dW/dx_k of the bilinear weights is -(1 - fz)/dx, (1 - fz)/dx,
    -fz/dx, fz/dx on the cells 00, 10, 01, 11, and the same in z with d fz/dz, 0 where a grain's
    z-weight is clamped to a boundary row). triples: (q, rx, rz) per cell (drag_triples, then S^T,
    then interleave_triples). Each grain on its own: the same bits on any thread count."""
    cells = corners[CR_CELL].view(np.int64)
    a00s, a10s, a01s, a11s, dfz = corners[CR_A00], corners[CR_A10], corners[CR_A01], corners[CR_A11], corners[CR_DFZ]
    column = np.uint64(3 * nz)
    end = np.uint64(triples.size)
    one, two, three = np.uint64(1), np.uint64(2), np.uint64(3)
    for kk in prange(n):
        k = np.uint64(kk)
        cell = cells[k] - CELL_BITS
        if cell < 0:
            drag_x[k] = 0.0
            drag_z[k] = 0.0
            continue
        i00 = np.uint64(cell) * three
        i10 = i00 + column
        i10 = i10 - end if i10 >= end else i10
        i01 = i00 + three
        i11 = i10 + three
        a00, a10, a01, a11 = a00s[k], a10s[k], a01s[k], a11s[k]
        q00, q10, q01, q11 = triples[i00], triples[i10], triples[i01], triples[i11]
        dqx = ((a00 + a10) * (q10 - q00) + (a01 + a11) * (q11 - q01)) * inv_dx
        dqz = ((a00 + a01) * (q01 - q00) + (a10 + a11) * (q11 - q10)) * dfz[k]
        drag_x[k] = -(dqx + a00 * triples[i00 + one] + a10 * triples[i10 + one] + a01 * triples[i01 + one]
                      + a11 * triples[i11 + one])
        drag_z[k] = -(dqz + a00 * triples[i00 + two] + a10 * triples[i10 + two] + a01 * triples[i01 + two]
                      + a11 * triples[i11 + two])
