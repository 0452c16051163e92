"""Pore pressure on the Goren grid: the undrained source from solid mass conservation (Eqs. 14-17),
the pressure equation (Eq. 18) with Carman-Kozeny permeability (Eq. 20) and its diffusion
solved implicitly (conjugate gradients) or explicitly (FTCS); physics.md section 4.

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
kappa = kappa_c phi^3 / (1 - phi)^2, phi clamped to [phi_min, phi_max], physics.md;
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
"""

import math

import numpy as np
from numba import njit

from . import NUMBA_CACHE
from .layout import G_CP, G_DINV, G_P, G_Q, G_R, G_Z


@njit(cache=NUMBA_CACHE, error_model="numpy")
def undrained_source(P, s, s_old, ux, uz_rel, grad_s_x, grad_s_z, dt_f, beta, s_min, s_max, p_star, div_u):
    """Pressure after the exact undrained response to the solid-fraction change.

    P : float64[nx, nz] pressure P^n [E];  s, s_old : s^{n+1}, s^n [-]
    ux, uz_rel, grad_s_x, grad_s_z : from deposit at t^{n+1}
    The material change is s_e - s^n with s_e = s^{n+1} + dt_f u_rel . grad s.
    p_star : out, P* = P^n + (1 + beta P^n)(s_e - s^n) / (beta s^n (1 - s_e))  [E]
    div_u : out, solid volumetric strain rate -(s_e - s^n) / (dt_f (s_e + s^n)/2) [1/t0]
    s is clamped to [s_min, s_max] = [1 - phi_max, 1 - phi_min] in both formulas.
    """
    nx, nz = P.shape
    for i in range(nx):
        for j in range(nz):
            s_end = s[i, j] + dt_f * (ux[i, j] * grad_s_x[i, j] + uz_rel[i, j] * grad_s_z[i, j])
            s_start = s_old[i, j]
            s_end = min(max(s_end, s_min), s_max)
            s_start = min(max(s_start, s_min), s_max)
            p_star[i, j] = P[i, j] + (1.0 + beta * P[i, j]) * (s_end - s_start) / (
                beta * s_start * (1.0 - s_end))
            div_u[i, j] = -2.0 * (s_end - s_start) / ((s_end + s_start) * dt_f)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def permeability_field(s, kappa_c, phi_min, phi_max, permeability, capacity, beta):
    """Carman-Kozeny permeability (physics.md; thesis Eq. 20 corrected) and capacity.

    permeability : out, kappa_c phi^3 / (1 - phi)^2 [d^2];  capacity : out, beta phi [1/E]
    with phi = 1 - s clamped to [phi_min, phi_max].
    """
    nx, nz = s.shape
    for i in range(nx):
        for j in range(nz):
            phi = min(max(1.0 - s[i, j], phi_min), phi_max)
            permeability[i, j] = kappa_c * phi * phi * phi / ((1.0 - phi) * (1.0 - phi))
            capacity[i, j] = beta * phi


@njit(cache=NUMBA_CACHE, error_model="numpy")
def face_conductances(P, permeability, dx, dz, beta, eta, tx, tz, tb):
    """Face conductances of div[(1 + beta P)(kappa/eta) grad P] per unit cell area.

    P : lagged pressure P^n [E]. tx[i, j]: face (i+1/2, j), periodic;
    tz[i, j]: face (i, j+1/2) for j < nz-1 (tz[:, nz-1] = 0);
    tb[i, j]: the wall face of a boundary cell, 1 + beta P taken as the mean of
    the cell value and 1 (P = 0 on the plane), distance dz/2; 0 for inner cells.
    Units 1/(E t0).
    """
    nx, nz = P.shape
    cx = 1.0 / (eta * dx * dx)
    cz = 1.0 / (eta * dz * dz)
    for i in range(nx):
        ip = (i + 1) % nx
        for j in range(nz):
            k0 = permeability[i, j]
            k1 = permeability[ip, j]
            khar = 2.0 * k0 * k1 / (k0 + k1) if k0 + k1 > 0.0 else 0.0
            tx[i, j] = (1.0 + 0.5 * beta * (P[i, j] + P[ip, j])) * khar * cx
            if j < nz - 1:
                k1 = permeability[i, j + 1]
                khar = 2.0 * k0 * k1 / (k0 + k1) if k0 + k1 > 0.0 else 0.0
                tz[i, j] = (1.0 + 0.5 * beta * (P[i, j] + P[i, j + 1])) * khar * cz
            else:
                tz[i, j] = 0.0
            tb[i, j] = 0.0
        tb[i, 0] += (1.0 + 0.5 * beta * P[i, 0]) * permeability[i, 0] * 2.0 * cz
        tb[i, nz - 1] += (1.0 + 0.5 * beta * P[i, nz - 1]) * permeability[i, nz - 1] * 2.0 * cz


@njit(cache=NUMBA_CACHE, error_model="numpy")
def explicit_bound(capacity, tx, tz, tb):
    """Largest stable FTCS step [t0]: 2 / (Gershgorin bound on the eigenvalues of C^-1 L).

    Row c of C^-1 L gives lambda <= (sum of all face conductances + sum of the
    inner ones) / C_c; for uniform D = kappa/(eta beta phi) this is
    4 D (1/dx^2 + 1/dz^2) in every cell (boundary cells included: the wall face,
    half a cell away, conducts twice as much but has no off-diagonal), so the step is exactly
    1 / (2 D (1/dx^2 + 1/dz^2)). Returns inf when there is no diffusion.
    """
    nx, nz = capacity.shape
    lam_max = 0.0
    for i in range(nx):
        im = (i - 1) % nx
        for j in range(nz):
            inner = tx[i, j] + tx[im, j] + tz[i, j]
            if j > 0:
                inner += tz[i, j - 1]
            lam = (2.0 * inner + tb[i, j]) / capacity[i, j]
            if lam > lam_max:
                lam_max = lam
    if lam_max <= 0.0:
        return math.inf
    return 2.0 / lam_max


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _apply_operator(p, diag, tx, tz, q):
    """q = (C/dt + L) p for the 5-point operator (diag holds C/dt + sum of face conductances)."""
    nx, nz = p.shape
    for i in range(nx):
        ip = (i + 1) % nx
        im = (i - 1) % nx
        for j in range(nz):
            v = diag[i, j] * p[i, j] - tx[i, j] * p[ip, j] - tx[im, j] * p[im, j]
            if j < nz - 1:
                v -= tz[i, j] * p[i, j + 1]
            if j > 0:
                v -= tz[i, j - 1] * p[i, j - 1]
            q[i, j] = v


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _factor_columns(diag, tz, cp, dinv):
    """Thomas factorisation of the z-column tridiagonal blocks of the operator."""
    nx, nz = diag.shape
    for i in range(nx):
        dinv[i, 0] = 1.0 / diag[i, 0]
        cp[i, 0] = -tz[i, 0] * dinv[i, 0]
    for j in range(1, nz):
        for i in range(nx):
            dinv[i, j] = 1.0 / (diag[i, j] + tz[i, j - 1] * cp[i, j - 1])
            cp[i, j] = -tz[i, j] * dinv[i, j]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _solve_columns(r, tz, cp, dinv, out):
    """out = B^-1 r with B the z-column tridiagonal part of the operator."""
    nx, nz = r.shape
    for i in range(nx):
        out[i, 0] = r[i, 0] * dinv[i, 0]
    for j in range(1, nz):
        for i in range(nx):
            out[i, j] = (r[i, j] + tz[i, j - 1] * out[i, j - 1]) * dinv[i, j]
    for j in range(nz - 2, -1, -1):
        for i in range(nx):
            out[i, j] -= cp[i, j] * out[i, j + 1]


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
    work : float64[N_GRID_WORK, nx, nz] scratch (G_R, G_Z, G_P, G_Q, G_CP, G_DINV used)
    Returns (iterations, ||r|| / ||rhs||, converged).
    """
    r = work[G_R]
    zv = work[G_Z]
    p = work[G_P]
    q = work[G_Q]
    cp = work[G_CP]
    dinv = work[G_DINV]
    nx, nz = rhs.shape
    rhs_norm = math.sqrt(_dot(rhs, rhs))
    if rhs_norm == 0.0:
        for i in range(nx):
            for j in range(nz):
                solution[i, j] = 0.0
        return 0, 0.0, True
    _factor_columns(diag, tz, cp, dinv)
    _apply_operator(solution, diag, tx, tz, q)
    for i in range(nx):
        for j in range(nz):
            r[i, j] = rhs[i, j] - q[i, j]
    res = math.sqrt(_dot(r, r)) / rhs_norm
    if res <= tol:
        return 0, res, True
    _solve_columns(r, tz, cp, dinv, zv)
    for i in range(nx):
        for j in range(nz):
            p[i, j] = zv[i, j]
    rz = _dot(r, zv)
    for it in range(1, max_iter + 1):
        _apply_operator(p, diag, tx, tz, q)
        alpha = rz / _dot(p, q)
        res = math.sqrt(_step_residual(alpha, p, q, solution, r)) / rhs_norm
        if res <= tol:
            return it, res, True
        _solve_columns(r, tz, cp, dinv, zv)
        rz_new = _dot(r, zv)
        gamma = rz_new / rz
        rz = rz_new
        for i in range(nx):
            for j in range(nz):
                p[i, j] = zv[i, j] + gamma * p[i, j]
    return max_iter, res, False


@njit(cache=NUMBA_CACHE, error_model="numpy")
def explicit_diffusion(P, capacity, tx, tz, tb, dt_sub, n_sub, scratch):
    """n_sub forward-Euler (FTCS) steps of C dP/dt = -L P with P = 0 on the planes."""
    nx, nz = P.shape
    for _ in range(n_sub):
        for i in range(nx):
            ip = (i + 1) % nx
            im = (i - 1) % nx
            for j in range(nz):
                pc = P[i, j]
                flux = tx[i, j] * (P[ip, j] - pc) + tx[im, j] * (P[im, j] - pc) - tb[i, j] * pc
                if j < nz - 1:
                    flux += tz[i, j] * (P[i, j + 1] - pc)
                if j > 0:
                    flux += tz[i, j - 1] * (P[i, j - 1] - pc)
                scratch[i, j] = pc + dt_sub * flux / capacity[i, j]
        for i in range(nx):
            for j in range(nz):
                P[i, j] = scratch[i, j]

