"""Pore pressure on the Goren grid: the undrained source from solid mass conservation (Eqs. 14-17),
the pressure equation (Eq. 18) with Carman-Kozeny permeability (Eq. 20) and its diffusion
solved implicitly (conjugate gradients) or explicitly (FTCS); docs/physics/fluid.md.

Grid: :mod:`gouge_cli.kernels.deposit`; arrays and indices: :mod:`gouge_cli.kernels.layout`.

Pressure
--------
    beta phi dP/dt = -(1 + beta P) div u_s + div[(1 + beta P)(kappa/eta) grad P]

d/dt follows the grid cell (the affine part of the solid motion); the
advection of P by the non-affine velocity u_rel is neglected, as in Goren et al.
Solid mass (Eq. 14) gives div u_s = -(Ds/Dt)/s; on the moving grid
Ds/Dt = (s^{n+1} - s^n)/dt_f + u_rel . grad s (u_rel and grad s at t^{n+1}).
Without diffusion the equation integrates exactly to
(1 + beta P)/(s/(1 - s)) = const along the solid, so the source is applied in
that integrated form over the fluid step,

    1 + beta P* = (1 + beta P^n) [s_e/(1 - s_e)] / [s^n/(1 - s^n)],
    s_e = s^{n+1} + dt_f u_rel . grad s,

(s clamped to [1 - phi_max, 1 - phi_min] here), which makes the undrained
response independent of dt_f and exact for an affine deformation of grains and
planes: 1 + beta P = phi_0 / (phi_0 + eps_v) (= exp(-eps_v/phi) to first order).
A rigid translation gives no source except when a grain crosses a kink of the
bilinear weights: that error is first order in u dt_f / dx.
Diffusion then advances P* by dt_f with the (1 + beta P) factors lagged at P^n
(Picard): capacity C_c = beta phi_c, face conductances
T = (1 + beta P)_face kappa_face / (eta h^2), with the arithmetic mean of
(1 + beta P) and the harmonic mean of kappa (Carman-Kozeny,
kappa = kappa_c phi^3 / (1 - phi)^2, phi clamped to [phi_min, phi_max], docs/physics/fluid.md;
the thesis's printed (1 + 2 phi)^3 is an extraction error). A wall face is half
a cell from the boundary-cell centre: T_b = (1 + beta P_cell / 2) kappa_cell 2 / (eta dz^2).

* implicit (default): backward Euler, (C/dt + L) P^{n+1} = C P*/dt, a symmetric
  positive definite 5-point system solved by conjugate gradients preconditioned
  with exact tridiagonal solves along each z column; stops when
  ||r||_2 <= tol ||rhs||_2 (tol = params[P_TOL], default 1e-10).
* explicit: forward Euler (FTCS) with n_sub = ceil(dt_f / (safety dt_max))
  equal sub-steps, dt_max = 2 / max_c lambda_c, lambda_c the Gershgorin row
  bound of C^-1 L; for uniform D = kappa/(eta beta phi) this is exactly
  1 / (2 D (1/dx^2 + 1/dz^2)).
* auto (the config default): one explicit second-order step (Heun: the forward-Euler
  predictor, then the mean of the two slopes; amplification 1 - x + x^2/2, x = dt_f lambda)
  while dt_f <= AUTO_EXPLICIT dt_max (kernels.layout; 0.25, so x <= 0.5 for every mode),
  backward Euler otherwise. There Heun errs by ~x^3/6 per step against backward Euler's
  ~x^2/2: 0.0185 against 0.060 at the threshold x = 0.5 (exp(-0.5) = 0.6065), 0.0013
  against 0.0146 at x = 0.2. So the explicit step is the more accurate, and it saves the
  conjugate gradients (most of an implicit update's cost). The undrained thesis
  scenes (kappa_c = 1e-5) sit at dt_f ~ 0.05 dt_max; kappa_c >~ 1e-4 goes implicit.
"""

import math

import numpy as np
from numba import njit

from . import NUMBA_CACHE
from .layout import G_CP, G_DINV, G_LINE, G_P, G_Q, G_R, G_TZT, G_Z


@njit(cache=NUMBA_CACHE, inline="always")
def flat(a):
    """The (nx * nz,) view of a C-contiguous grid array: loops over it vectorise (an inner loop
    over nz ~ 20 cells runs in the scalar remainder of an 8-wide vector loop)."""
    return a.reshape(a.size)


@njit(cache=NUMBA_CACHE, inline="always")
def cells(a, i0, i1):
    """(lo, hi): the flat cells of grid columns i0 <= i < i1 of a (nx, nz) as uint64; i1 < 0: to the
    last column. The functions taking (i0, i1) do those columns' cells only, each cell with the
    same operations whatever the range: a grid shared out by columns has the bits of one pass."""
    nz = np.uint64(a.shape[1])
    last = a.shape[0] if i1 < 0 else i1
    return np.uint64(i0) * nz, np.uint64(last) * nz


@njit(cache=NUMBA_CACHE, inline="always")
def copy_grid(source, target, i0=0, i1=-1):
    """target[:] = source for two grid arrays of one shape (columns i0..i1: cells), one flat loop."""
    sf, tf = flat(source), flat(target)
    lo, hi = cells(source, i0, i1)
    for c in range(lo, hi):
        tf[c] = sf[c]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def undrained_source(P, s, s_old, ux, uz_rel, grad_s_x, grad_s_z, dt_f, beta, s_min, s_max, p_star, div_u, i0=0,
                     i1=-1):
    """Pressure after the exact undrained response to the solid-fraction change.

    P : float64[nx, nz] pressure P^n [E];  s, s_old : s^{n+1}, s^n [-]
    ux, uz_rel, grad_s_x, grad_s_z : from deposit at t^{n+1}
    The material change is s_e - s^n with s_e = s^{n+1} + dt_f u_rel . grad s.
    p_star : out, P* = P^n + (1 + beta P^n)(s_e - s^n) / (beta s^n (1 - s_e))  [E]
    div_u : out, solid volumetric strain rate -(s_e - s^n) / (dt_f (s_e + s^n)/2) [1/t0]
    s is clamped to [s_min, s_max] = [1 - phi_max, 1 - phi_min] in both formulas. (i0, i1: cells.)
    """
    p, sn, so, u, w, gx, gz, out, div = (flat(P), flat(s), flat(s_old), flat(ux), flat(uz_rel), flat(grad_s_x),
                                         flat(grad_s_z), flat(p_star), flat(div_u))
    lo, hi = cells(P, i0, i1)
    for c in range(lo, hi):
        s_end = sn[c] + dt_f * (u[c] * gx[c] + w[c] * gz[c])
        s_start = so[c]
        s_end = min(max(s_end, s_min), s_max)
        s_start = min(max(s_start, s_min), s_max)
        out[c] = p[c] + (1.0 + beta * p[c]) * (s_end - s_start) / (beta * s_start * (1.0 - s_end))
        div[c] = -2.0 * (s_end - s_start) / ((s_end + s_start) * dt_f)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def permeability_field(s, kappa_c, phi_min, phi_max, permeability, capacity, beta, i0=0, i1=-1):
    """Carman-Kozeny permeability (docs/physics/fluid.md; thesis Eq. 20 corrected) and capacity.

    permeability : out, kappa_c phi^3 / (1 - phi)^2 [d^2];  capacity : out, beta phi [1/E]
    with phi = 1 - s clamped to [phi_min, phi_max]. (i0, i1: cells.)
    """
    sf, kf, cf = flat(s), flat(permeability), flat(capacity)
    lo, hi = cells(s, i0, i1)
    for c in range(lo, hi):
        phi = min(max(1.0 - sf[c], phi_min), phi_max)
        kf[c] = kappa_c * phi * phi * phi / ((1.0 - phi) * (1.0 - phi))
        cf[c] = beta * phi


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _face(p0, p1, k0, k1, half_beta, scale):
    """Conductance of the face between two cells: (1 + beta mean P) x harmonic mean of kappa x scale."""
    khar = 2.0 * k0 * k1 / (k0 + k1) if k0 + k1 > 0.0 else 0.0
    return (1.0 + half_beta * (p0 + p1)) * khar * scale


@njit(cache=NUMBA_CACHE, error_model="numpy")
def face_conductances(P, permeability, dx, dz, beta, eta, tx, tz, tb, i0=0, i1=-1):
    """Face conductances of div[(1 + beta P)(kappa/eta) grad P] per unit cell area.

    P : lagged pressure P^n [E]. tx[i, j]: face (i+1/2, j), periodic;
    tz[i, j]: face (i, j+1/2) for j < nz-1 (tz[:, nz-1] = 0);
    tb[i, j]: the wall face of a boundary cell, 1 + beta P taken as the mean of
    the cell value and 1 (P = 0 on the plane), distance dz/2; 0 for inner cells.
    Units 1/(E t0). Flat loops: the x neighbour of cell c is c + nz (the last column wraps
    to the first); tz is computed across a column's top face too, then set to 0 there.
    (i0, i1: cells; they read P and kappa of the next column and cell.)
    """
    nx, nz = P.shape
    cx = 1.0 / (eta * dx * dx)
    cz = 1.0 / (eta * dz * dz)
    half_beta = 0.5 * beta
    p, k, fx, fz, fb = flat(P), flat(permeability), flat(tx), flat(tz), flat(tb)
    size, unz, inner, one = flat_columns(P)
    lo, hi = cells(P, i0, i1)
    for c in range(lo, min(inner, hi)):
        fx[c] = _face(p[c], p[c + unz], k[c], k[c + unz], half_beta, cx)
    for c in range(max(inner, lo), hi):
        fx[c] = _face(p[c], p[c - inner], k[c], k[c - inner], half_beta, cx)
    for c in range(lo, min(size - one, hi)):
        fz[c] = _face(p[c], p[c + one], k[c], k[c + one], half_beta, cz)
        fb[c] = 0.0
    if hi == size:
        fb[size - one] = 0.0
    for i in range(i0, nx if i1 < 0 else i1):
        top = i * nz + nz - 1
        fz[top] = 0.0
        fb[i * nz] += (1.0 + 0.5 * beta * p[i * nz]) * k[i * nz] * 2.0 * cz
        fb[top] += (1.0 + 0.5 * beta * p[top]) * k[top] * 2.0 * cz


@njit(cache=NUMBA_CACHE, error_model="numpy")
def implicit_system(capacity, tx, tz, tb, dt_f, p_star, P, diag):
    """Backward Euler system (C/dt_f + L) P = C P*/dt_f: diag = C/dt_f + the sum of the cell's
    face conductances (_add_face_sums); P takes P* as the initial guess; p_star is scaled in
    place to the right-hand side C P*/dt_f."""
    cap, rhs, pf, df = flat(capacity), flat(p_star), flat(P), flat(diag)
    for c in range(np.uint64(pf.size)):                # C/dt_f once per cell, kept in diag
        df[c] = cap[c] / dt_f
        pf[c] = rhs[c]
        rhs[c] *= df[c]
    _add_face_sums(tx, tz, tb, diag, int(0), int(-1))


@njit(cache=NUMBA_CACHE, inline="always")
def flat_columns(a):
    """(size, nz, size - nz, 1) as uint64 for the flat loops over a grid array a (nx, nz): cell
    c's x neighbours are c + nz and c - nz, wrapping through size - nz in the first and last
    columns."""
    size = np.uint64(a.size)
    unz = np.uint64(a.shape[1])
    return size, unz, size - unz, np.uint64(1)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _add_face_sums(tx, tz, tb, diag, i0=0, i1=-1):
    """diag += the sum of each cell's face conductances (the diagonal of L). Flat loops, the tz
    term below a column's first cell being a zero face (tz = 0 on the top row of the previous
    column). (i0, i1: cells.)"""
    fx, fz, fb, df = flat(tx), flat(tz), flat(tb), flat(diag)
    size, unz, last, one = flat_columns(tx)
    lo, hi = cells(tx, i0, i1)
    if lo == 0 and hi > 0:
        df[0] = df[0] + fx[0] + fx[last] + fb[0] + fz[0]
    for c in range(max(one, lo), min(unz, hi)):
        df[c] = df[c] + fx[c] + fx[c + last] + fb[c] + fz[c] + fz[c - one]
    for c in range(max(unz, lo), hi):
        df[c] = df[c] + fx[c] + fx[c - unz] + fb[c] + fz[c] + fz[c - one]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def explicit_bound(capacity, tx, tz, tb, rates=None):
    """Largest stable FTCS step [t0]: 2 / (Gershgorin bound on the eigenvalues of C^-1 L).

    Row c of C^-1 L gives lambda <= (sum of all face conductances + sum of the
    inner ones) / C_c; for uniform D = kappa/(eta beta phi) this is
    4 D (1/dx^2 + 1/dz^2) in every cell (boundary cells included: the wall face,
    half a cell away, conducts twice as much but has no off-diagonal), so the step is exactly
    1 / (2 D (1/dx^2 + 1/dz^2)). Returns inf when there is no diffusion.
    rates : (nx, nz) scratch (allocated if None) for the cells' bounds. Their largest is found as
    the largest int64 of their bit patterns, which orders non-negative doubles as their values
    (an integer reduction vectorises; a float max does not): the exact maximum when any bound
    is positive, and a value <= 0 (so inf) when none is, as a float max would give.
    """
    if rates is None:
        rates = np.empty_like(capacity)
    bound_rates(capacity, tx, tz, tb, rates)
    return bound_of_rates(rates)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def bound_rates(capacity, tx, tz, tb, rates, i0=0, i1=-1):
    """rates (nx, nz) out: each cell's Gershgorin bound of explicit_bound (i0, i1: cells)."""
    fx, fz, fb, cap, rf = flat(tx), flat(tz), flat(tb), flat(capacity), flat(rates)
    size, unz, last, one = flat_columns(capacity)
    lo, hi = cells(capacity, i0, i1)
    if lo == 0 and hi > 0:
        rf[0] = (2.0 * (fx[0] + fx[last] + fz[0]) + fb[0]) / cap[0]
    for c in range(max(one, lo), min(unz, hi)):      # (flat, as _add_face_sums)
        rf[c] = (2.0 * (fx[c] + fx[c + last] + fz[c] + fz[c - one]) + fb[c]) / cap[c]
    for c in range(max(unz, lo), hi):
        rf[c] = (2.0 * (fx[c] + fx[c - unz] + fz[c] + fz[c - one]) + fb[c]) / cap[c]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def bound_of_rates(rates):
    """explicit_bound from the cells' bounds (bound_rates; rates[0, 0] is overwritten)."""
    rf = flat(rates)
    bits = rf.view(np.int64)
    top = bits[0]
    for c in range(np.uint64(1), np.uint64(rf.size)):
        top = max(top, bits[c])
    bits[0] = top
    lam_max = rf[0]
    if lam_max <= 0.0:
        return math.inf
    return 2.0 / lam_max


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _row(d, p, tx_east, p_east, tx_west, p_west, tz_up, p_up, tz_down, p_down):
    """One row of the operator, in the order of the terms. Scalars only: numba may reference-count
    the arrays of an inlined helper at every call of a plain loop (kernels.drag.grain_drag_at)."""
    return (d * p - tx_east * p_east - tx_west * p_west) - tz_up * p_up - tz_down * p_down


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _apply_operator(p, diag, tx, tz, q, i0=0, i1=-1):
    """q = (C/dt + L) p for the 5-point operator (diag holds C/dt + sum of face conductances).
    Flat loops (the middle columns vectorise): the x neighbours of cell c are c + nz and c - nz
    (wrapping in the first and last columns); the z terms use tz = 0 across the walls (c + 1 and
    c - 1 then lie in the next or previous column: their product is a zero and the difference
    keeps the value). The first and last cells, whose z neighbour would fall outside the
    arrays, take a zero term. (i0, i1: cells; they read p of the neighbouring columns.)"""
    nx, nz = p.shape
    pf, df, fx, fz, qf = flat(p), flat(diag), flat(tx), flat(tz), flat(q)
    size, unz, last, one = flat_columns(p)   # (size >= 2: nz >= 2; last = 0 if nx = 1)
    end = size - one
    lo, hi = cells(p, i0, i1)
    if hi <= lo:
        return
    east = unz if nx > 1 else np.uint64(0)
    if lo == 0:
        qf[0] = _row(df[0], pf[0], fx[0], pf[east], fx[last], pf[last], fz[0], pf[1], 0.0, 0.0)
    if nx == 1:                           # one column: it is its own x neighbour
        for c in range(one, end):
            qf[c] = _row(df[c], pf[c], fx[c], pf[c], fx[c], pf[c], fz[c], pf[c + one], fz[c - one], pf[c - one])
    else:
        for c in range(max(one, lo), min(unz, hi)):
            w = c + last
            qf[c] = _row(df[c], pf[c], fx[c], pf[c + unz], fx[w], pf[w], fz[c], pf[c + one], fz[c - one], pf[c - one])
        for c in range(max(unz, lo), min(last, hi)):
            w = c - unz
            qf[c] = _row(df[c], pf[c], fx[c], pf[c + unz], fx[w], pf[w], fz[c], pf[c + one], fz[c - one], pf[c - one])
        for c in range(max(last, lo), min(end, hi)):
            w = c - unz
            e = c - last
            qf[c] = _row(df[c], pf[c], fx[c], pf[e], fx[w], pf[w], fz[c], pf[c + one], fz[c - one], pf[c - one])
    if hi == size:
        w = end - unz if nx > 1 else end
        e = end - last
        qf[end] = _row(df[end], pf[end], fx[end], pf[e], fx[w], pf[w], 0.0, 0.0, fz[end - one], pf[end - one])


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _transpose(a, out):
    """out (m, n) = a (n, m) transposed, writing out in order; both C-contiguous."""
    n, m = a.shape
    af, of = flat(a), flat(out)
    un, um = np.uint64(n), np.uint64(m)
    for j in range(np.uint64(0), um):
        for i in range(np.uint64(0), un):
            of[j * un + i] = af[i * um + j]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _factor_columns(diag, tz, tzt, cp, dinv):
    """Thomas factorisation of the z-column tridiagonal blocks of the operator, transposed:
    tzt, cp, dinv are (nz, nx), so that the solves run along x, all columns at once (a vector
    loop per row; rows as separate views, so the compiler sees the row before as another
    array) with each column's own recurrence in z."""
    nx, nz = diag.shape
    _transpose(tz, tzt)
    _transpose(diag, dinv)
    d, c, t = dinv[0], cp[0], tzt[0]
    for i in range(nx):
        d[i] = 1.0 / d[i]
        c[i] = -t[i] * d[i]
    for j in range(1, nz):
        d, c, t, below_t, below_c = dinv[j], cp[j], tzt[j], tzt[j - 1], cp[j - 1]
        for i in range(nx):
            d[i] = 1.0 / (d[i] + below_t[i] * below_c[i])
            c[i] = -t[i] * d[i]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _solve_columns(r, tzt, cp, dinv, line, out):
    """out = B^-1 r with B the z-column tridiagonal part of the operator (factors from
    _factor_columns), through line (nz, nx): r transposed, solved in place row by row (vector
    loops), transposed back."""
    nx, nz = r.shape
    _transpose(r, line)
    row, d = line[0], dinv[0]
    for i in range(nx):
        row[i] = row[i] * d[i]
    for j in range(1, nz):
        row, below, t, d = line[j], line[j - 1], tzt[j - 1], dinv[j]
        for i in range(nx):
            row[i] = (row[i] + t[i] * below[i]) * d[i]
    for j in range(nz - 2, -1, -1):
        row, above, c = line[j], line[j + 1], cp[j]
        for i in range(nx):
            row[i] -= c[i] * above[i]
    _transpose(line, out)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _dot(a, b):
    """sum a * b over all cells, in four interleaved partial sums (fixed order: the same bits
    every time; four independent additions in flight instead of one chain)."""
    fa = a.reshape(a.size)
    fb = b.reshape(b.size)
    n4 = fa.size - fa.size % 4
    s0 = s1 = s2 = s3 = 0.0
    for c in range(0, n4, 4):
        k = np.uint64(c)
        s0 += fa[k] * fb[k]
        s1 += fa[k + 1] * fb[k + 1]
        s2 += fa[k + 2] * fb[k + 2]
        s3 += fa[k + 3] * fb[k + 3]
    for c in range(n4, fa.size):
        s0 += fa[c] * fb[c]
    return (s0 + s1) + (s2 + s3)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _step_residual(alpha, p, q, solution, r):
    """solution += alpha p, r -= alpha q; returns r . r (summed as _dot)."""
    fp = p.reshape(p.size)
    fq = q.reshape(q.size)
    fx = solution.reshape(solution.size)
    fr = r.reshape(r.size)
    for c in range(fr.size):
        k = np.uint64(c)
        fx[k] += alpha * fp[k]
        fr[k] -= alpha * fq[k]
    return _dot(r, r)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def conjugate_gradient(solution, rhs, diag, tx, tz, work, tol, max_iter):
    """Solve (C/dt + L) solution = rhs by z-line preconditioned conjugate gradients.

    solution : float64[nx, nz] in: initial guess, out: solution
    work : float64[N_GRID_WORK, nx, nz] scratch (G_R, G_Z, G_P, G_Q, G_CP, G_DINV, G_TZT, G_LINE used)
    Returns (iterations, ||r|| / ||rhs||, converged).
    """
    r = work[G_R]
    zv = work[G_Z]
    p = work[G_P]
    q = work[G_Q]
    nx, nz = rhs.shape
    transposed = (nz, nx)
    cp = work[G_CP].reshape(transposed)
    dinv = work[G_DINV].reshape(transposed)
    tzt = work[G_TZT].reshape(transposed)
    line = work[G_LINE].reshape(transposed)
    rhs_norm = math.sqrt(_dot(rhs, rhs))
    if rhs_norm == 0.0:
        solution[:] = 0.0
        return 0, 0.0, True
    _factor_columns(diag, tz, tzt, cp, dinv)
    _apply_operator(solution, diag, tx, tz, q, int(0), int(-1))
    rf, bf, qf = flat(r), flat(rhs), flat(q)
    for c in range(np.uint64(rf.size)):
        rf[c] = bf[c] - qf[c]
    res = math.sqrt(_dot(r, r)) / rhs_norm
    if res <= tol:
        return 0, res, True
    _solve_columns(r, tzt, cp, dinv, line, zv)
    pf, zf = flat(p), flat(zv)
    for c in range(np.uint64(pf.size)):
        pf[c] = zf[c]
    rz = _dot(r, zv)
    for it in range(1, max_iter + 1):
        _apply_operator(p, diag, tx, tz, q, int(0), int(-1))
        alpha = rz / _dot(p, q)
        res = math.sqrt(_step_residual(alpha, p, q, solution, r)) / rhs_norm
        if res <= tol:
            return it, res, True
        _solve_columns(r, tzt, cp, dinv, line, zv)
        rz_new = _dot(r, zv)
        gamma = rz_new / rz
        rz = rz_new
        for c in range(np.uint64(pf.size)):
            pf[c] = zf[c] + gamma * pf[c]
    return max_iter, res, False


@njit(cache=NUMBA_CACHE, error_model="numpy")
def heun_diffusion(P, capacity, tx, tz, tb, dt, diag, slope, predictor, slope_2):
    """One Heun (explicit trapezoidal, second-order) step of C dP/dt = -L P with P = 0 on the
    planes: P~ = P - dt (L P) / C, then P <- P - dt/2 (L P + L P~) / C. diag (out): the sum of
    each cell's face conductances; slope, predictor, slope_2 (nx, nz): scratch. Flat loops, in
    three parts that a caller may also run on column ranges (heun_predictor after _face_diagonal
    on every column, heun_corrector after heun_predictor on every column)."""
    _face_diagonal(tx, tz, tb, diag, int(0), int(-1))
    heun_predictor(P, capacity, tx, tz, dt, diag, slope, predictor, int(0), int(-1))
    heun_corrector(P, capacity, tx, tz, dt, diag, slope, predictor, slope_2, int(0), int(-1))


@njit(cache=NUMBA_CACHE, error_model="numpy")
def heun_predictor(P, capacity, tx, tz, dt, diag, slope, predictor, i0=0, i1=-1):
    """Heun's first half: slope = L P, predictor = P - dt slope / C (i0, i1: cells)."""
    _apply_operator(P, diag, tx, tz, slope, i0, i1)
    _forward_euler(P, slope, capacity, dt, predictor, i0, i1)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def heun_corrector(P, capacity, tx, tz, dt, diag, slope, predictor, slope_2, i0=0, i1=-1):
    """Heun's second half: slope_2 = L predictor, P -= dt/2 (slope + slope_2) / C (i0, i1: cells)."""
    _apply_operator(predictor, diag, tx, tz, slope_2, i0, i1)
    pf, q1, q2, cap = flat(P), flat(slope), flat(slope_2), flat(capacity)
    half = 0.5 * dt
    lo, hi = cells(P, i0, i1)
    for c in range(lo, hi):
        pf[c] -= half * (q1[c] + q2[c]) / cap[c]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def explicit_diffusion(P, capacity, tx, tz, tb, dt_sub, n_sub, diag, scratch):
    """n_sub forward-Euler (FTCS) steps of C dP/dt = -L P with P = 0 on the planes:
    P <- P - dt_sub (L P) / C, L P by _apply_operator with diag (out) = the sum of each cell's
    face conductances; scratch (nx, nz) holds L P. Flat loops."""
    _face_diagonal(tx, tz, tb, diag, int(0), int(-1))
    for _ in range(n_sub):
        _apply_operator(P, diag, tx, tz, scratch, int(0), int(-1))
        _forward_euler(P, scratch, capacity, dt_sub, P, int(0), int(-1))


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _face_diagonal(tx, tz, tb, diag, i0=0, i1=-1):
    """diag = the sum of each cell's face conductances (the diagonal of L alone; i0, i1: cells)."""
    df = flat(diag)
    lo, hi = cells(diag, i0, i1)
    for c in range(lo, hi):
        df[c] = 0.0
    _add_face_sums(tx, tz, tb, diag, i0, i1)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _forward_euler(P, slope, capacity, dt, out, i0=0, i1=-1):
    """out = P - dt slope / C (slope = L P); out may be P itself (i0, i1: cells)."""
    pf, qf, cap, of = flat(P), flat(slope), flat(capacity), flat(out)
    lo, hi = cells(P, i0, i1)
    for c in range(lo, hi):
        of[c] = pf[c] - dt * qf[c] / cap[c]
