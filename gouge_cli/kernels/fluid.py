"""Pore-fluid kernels on the Goren pressure grid (thesis Eqs. 12, 14-20; physics.md section 4).

Pure compute (``error_model="numpy"``: IEEE inf/NaN instead of ZeroDivisionError, so loops
vectorise), no allocation: every array is allocated once by :class:`gouge_cli.model.fluid.FluidGrid`
and passed in. Everything is dimensionless (d = E = rho_s = 1): lengths [d], time [t0],
pressure [E], permeability [d^2], viscosity [E t0], compressibility [1/E].

Grid
----
Cell-centred, ``nx`` cells across the periodic width ``Lx`` and ``nz`` cells
between the wall planes ``z_bot`` and ``z_top``; cell (i, j) has its centre at
``((i + 1/2) dx, z_bot + (j + 1/2) dz)`` with ``dx = Lx / nx`` and
``dz = (z_top - z_bot) / nz``. The grid stretches with the layer: a cell keeps
its index and moves affinely with the two wall planes, so pressure and solid
fraction are attached to cells that follow the affine part of the solid motion.
P = 0 on both wall planes (half a cell from the boundary centres), periodic in x.

Deposit (thesis Appendix E, "solid velocities ... interpolated onto the grid")
----------------------------------------------------------------------------
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
packing slides rigidly through the grid.

Pressure (thesis Eq. 18 with the sign of physics.md)
----------------------------------------------------
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

Drag (thesis Eq. 12)
--------------------
F_k = -a_k sum_c W_kc (grad P)_c / s_c with the same weights and areas as the
deposit (s unclamped), so sum_k F_k = -sum_c (grad P)_c dx dz exactly (over
cells holding solid); for a grain inside the layer a_k = V_k = pi R_k^2. (grad P)_c is the mean of the two face gradients on each axis, so the
discrete integral of grad P telescopes to the boundary values: with P = 0 on
both planes the total drag is zero to round-off.

Array layouts
-------------
params : float64[N_PARAMS]  indices P_* below (see FluidGrid.from_config)
state  : float64[N_STATE]   indices S_* below; S_Z_BOT/S_Z_TOP are the planes at
                            the last update and must be checkpointed with P and s
P, s, s_old, ux, uz, permeability, div_u : float64[nx, nz]
work   : float64[N_WORK, nx, nz]   scratch, indices W_* below
corners : float64[N_CORNERS, N]    per-grain deposit cells and areas (see deposit), reused for the drag
partial : float64[DEPOSIT_GROUPS, nx * nz, N_MOMENTS]   per-group deposit moments (see deposit);
                            allocate it zeroed: between calls it is zero outside the columns flagged
                            in it (M_FLAG)
drag_x, drag_z : float64[N]        force on each grain [E d^2]

Status: STATUS_OK 0; STATUS_SOLVER 1 (CG not converged in max_iter: P is the
last iterate; explicit sub-steps above max_substeps: P = P*, no diffusion; a
non-positive dt_f or layer thickness: nothing done); STATUS_NONFINITE 2 (P not
finite; drag is then set to zero). A status other than 0 should stop the run.
"""

import math

import numpy as np
from numba import njit, prange

from .. import NUMBA_CACHE
from .step import closed_velocity

P_KAPPA_C = 0        # Carman-Kozeny prefactor kappa_c [d^2]
P_BETA = 1           # fluid compressibility beta [1/E]
P_ETA = 2            # fluid viscosity eta [E t0]
P_SOLVER = 3         # SOLVER_IMPLICIT or SOLVER_EXPLICIT
P_SAFETY = 4         # fraction of the FTCS bound per explicit sub-step [-]
P_TOL = 5            # CG relative residual tolerance [-]
P_MAX_ITER = 6       # CG iteration limit
P_PHI_MIN = 7        # porosity clamp, lower (0.05)
P_PHI_MAX = 8        # porosity clamp, upper (0.9)
P_MAX_SUBSTEPS = 9   # explicit sub-step limit per fluid update
N_PARAMS = 10

SOLVER_IMPLICIT = 0
SOLVER_EXPLICIT = 1

S_Z_BOT = 0          # bottom plane at the last update [d]
S_Z_TOP = 1          # top plane at the last update [d]
S_ITERATIONS = 2     # CG iterations of the last update
S_RESIDUAL = 3       # final relative residual of the last CG solve
S_SUBSTEPS = 4       # explicit sub-steps of the last update
S_DT_MAX = 5         # explicit stability bound of the last update [t0]
S_UPDATES = 6        # number of fluid updates since fluid_init
N_STATE = 8

W_TX = 0             # conductance of face (i+1/2, j)
W_TZ = 1             # conductance of face (i, j+1/2), j < nz-1
W_TB = 2             # conductance of the Dirichlet wall face of a boundary cell
W_CAPACITY = 3       # beta phi
W_DIAG = 4           # diagonal of C/dt + L
W_RHS = 5            # right-hand side; P* before the solve
W_R = 6              # CG residual
W_Z = 7              # preconditioned residual
W_P = 8              # CG direction
W_Q = 9              # operator times direction; explicit scratch
W_CP = 10            # tridiagonal factor: modified upper coefficient
W_DINV = 11          # tridiagonal factor: inverse pivot
W_GX = 12            # dP/dx at cell centres
W_GZ = 13            # dP/dz at cell centres
W_FX = 14            # drag per unit grain area, -(dP/dx)/s
W_FZ = 15            # drag per unit grain area, -(dP/dz)/s
W_SX = 16            # ds/dx consistent with the deposit
W_SZ = 17            # ds/dz consistent with the deposit
N_WORK = 18

STATUS_OK = 0
STATUS_SOLVER = 1
STATUS_NONFINITE = 2


@njit(cache=NUMBA_CACHE, error_model="numpy")
def segment_area(h, radius):
    """Area of a disc beyond a line at signed distance h from its centre.

    h > 0: the centre is on the kept side. Returns 0 for h >= radius and
    pi radius^2 for h <= -radius; R^2 (a - sin a)/2 with a the subtended
    angle, by its series for small a (no cancellation near tangency).
    """
    if h >= radius:
        return 0.0
    if h <= -radius:
        return math.pi * radius * radius
    angle = 2.0 * math.atan2(math.sqrt((radius - h) * (radius + h)), h)
    if angle < 0.1:
        a2 = angle * angle
        angle_minus_sine = angle * a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0 * (1.0 - a2 / 72.0)))
    else:
        angle_minus_sine = angle - math.sin(angle)
    return 0.5 * radius * radius * angle_minus_sine


@njit(cache=NUMBA_CACHE, error_model="numpy")
def in_domain_area(z, radius, z_bot, z_top):
    """Area [d^2] of a disc (centre height z) between the planes z_bot and z_top.

    The area above z_bot minus the area above z_top, each from the small
    segment side so that a nearly tangent plane loses no precision.
    """
    full = math.pi * radius * radius
    h = z - z_bot
    above_bot = full - segment_area(h, radius) if h >= 0.0 else segment_area(-h, radius)
    h = z_top - z
    above_top = segment_area(h, radius) if h >= 0.0 else full - segment_area(-h, radius)
    area = above_bot - above_top
    if area < 0.0:
        return 0.0
    return area


@njit(cache=NUMBA_CACHE, error_model="numpy")
def grain_area(z, radius, z_bot, z_top):
    """In-domain area [d^2] with a fast path for a grain clear of both planes."""
    if z - z_bot >= radius and z_top - z >= radius:
        return math.pi * radius * radius
    return in_domain_area(z, radius, z_bot, z_top)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def cell_weights(x, z, inv_dx, inv_dz, z_bot, nx, nz):
    """Bilinear (cloud-in-cell) weights of a point; inv_dx = 1/dx, inv_dz = 1/dz.

    Returns (i0, i1, j0, fx, fz, slope_z): the point spreads (1-fx)(1-fz) on
    (i0, j0), fx(1-fz) on (i1, j0), (1-fx) fz on (i0, j0+1) and fx fz on
    (i1, j0+1). Periodic in x; in z a point outside the span of cell centres puts
    all its weight on the nearest boundary cell, where the weights do not vary
    with z: slope_z = d fz / dz is inv_dz inside and 0 there (a non-finite z
    also lands there, so indices stay in range). Requires nz >= 2.
    """
    xi = x * inv_dx - 0.5
    fi = math.floor(xi)
    fx = xi - fi
    i0 = int(fi)
    if i0 < 0 or i0 >= nx:
        i0 = i0 % nx
    i1 = i0 + 1
    if i1 == nx:
        i1 = 0
    zeta = (z - z_bot) * inv_dz - 0.5
    fj = math.floor(zeta)
    if fj >= nz - 1:
        return i0, i1, nz - 2, fx, 1.0, 0.0
    if fj >= 0.0:
        return i0, i1, int(fj), fx, zeta - fj, inv_dz
    return i0, i1, 0, fx, 0.0, 0.0


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def corner_shares(area, i0, i1, j0, fx, fz, nz):
    """Flat indices of the four cells around a point and the area each receives (same weights
    for the deposit and the drag): (c00, c10, c01, c11, a00, a10, a01, a11)."""
    c00 = np.uint64(i0 * nz + j0)
    c10 = np.uint64(i1 * nz + j0)
    a0 = area * (1.0 - fz)
    a1 = area * fz
    return (c00, c10, c00 + np.uint64(1), c10 + np.uint64(1),
            a0 * (1.0 - fx), a0 * fx, a1 * (1.0 - fx), a1 * fx)


DEPOSIT_GROUPS = 4     # grains deposit in this many fixed groups, summed in group order
# corners rows: flat indices of a grain's cells (i0, j0) and (i1, j0), the areas its four cells
# receive, and d fz / dz (see cell_weights)
C_00, C_10, C_A00, C_A10, C_A01, C_A11, C_DFZ = range(7)
N_CORNERS = 7
# moments a grain adds to the record of its cell c00: its four shares a00, a10, a01, a11, the
# same times vx and times vz - w(z), and the z-slope terms (a00 + a01) dfz, (a10 + a11) dfz
M_S, M_U, M_W, M_G = 0, 4, 8, 12
M_FLAG = 15            # in the first record of a grid column: 1 if the group added to that column
N_MOMENTS = 16         # (14 moments and the flag; padded so that a record is two cache lines)
N_SUMMED = 14


@njit(cache=NUMBA_CACHE, error_model="numpy")
def deposit(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, s, ux, uz_rel, grad_s_x, grad_s_z,
            corners=None, partial=None, grain_kick=None):
    """Solid fraction, its kernel-consistent gradient and the grid-relative solid velocity.

    x, z, vx, vz, radius : float64[>= n] grain centres [d], velocities [v0], radii [d]
    w_bot, w_top : plane velocities [v0] defining the grid velocity w(z)
    s : float64[nx, nz] out, s_c = sum_k a_k W_kc / (dx dz) = 1 - phi [-]
    ux, uz_rel : float64[nx, nz] out, a W weighted mean of vx and of vz - w(z_k)
                 [v0] (0 in cells without solid)
    grad_s_x, grad_s_z : float64[nx, nz] out, -sum_k a_k dW_kc/dx_k / (dx dz)
                 [1/d]: the derivative of s_c with respect to the cell position,
                 so that moving every grain by delta changes s by -delta . grad_s
                 to first order (a rigid translation generates no source).
    corners : float64[N_CORNERS, >= n] out (rows C_*), per grain: flat indices c00, c10 of its
                 corner cells, the areas a00, a10, a01, a11 they receive (c00 = -1 for a
                 grain outside the layer) and d fz/dz; reused by grain_drag_at for the drag.
    partial : float64[DEPOSIT_GROUPS, nx * nz, N_MOMENTS] scratch. With corners and partial,
                 the fast form: a vectorised pass for the cells and areas (_corners_range),
                 then each grain adds 14 moments to the record of its cell c00
                 (_moments_range), in DEPOSIT_GROUPS fixed groups of grains (in parallel)
                 summed in group order, and one pass over the cells collects the four shares
                 (_expand): the same sums regrouped (equal to round-off), the same bits for
                 any thread count. Without partial, the direct serial form, the definition:
                 every grain adds to its four cells (the tests' reference).
    grain_kick : (fast form only) None, or (owed, force_x, force_z, inv_mass, body, half, damp,
                 wall_vx, wall_vz): grain forces, inverse masses and kinds, half a time step,
                 the background damping and the top wall's velocity (kernels.step). If owed,
                 each grain's velocity is taken after the second half kick it still owes
                 (kernels.step.closed_velocity): the same bits as closing the step first,
                 without a pass over the grains.
    """
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
                     corners, partial, grain_kick)


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def _deposit_grouped(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, s, ux, uz_rel, grad_s_x, grad_s_z,
                     corners, partial, grain_kick):
    """deposit's fast form: cells and moments in DEPOSIT_GROUPS fixed groups (in parallel), summed
    in group order into partial[0], collected per cell."""
    nx, nz = s.shape
    size = nx * nz
    for g in prange(DEPOSIT_GROUPS):
        first = g * n // DEPOSIT_GROUPS
        last = (g + 1) * n // DEPOSIT_GROUPS
        _corners_range(x, z, radius, first, last, Lx, z_bot, z_top, nx, nz, corners)
        _moments_range(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, partial[g], corners, nz, grain_kick)
    total = partial[0]
    for i in prange(nx):                 # the groups' columns (a group's grains are nearby), in group order
        head = i * nz
        for g in range(1, DEPOSIT_GROUPS):
            if partial[g, head, M_FLAG] == 0.0:
                continue                 # all +0.0 there, and x + (+0.0) is x (sums are never -0.0)
            total[head, M_FLAG] = 1.0
            for c in range(head, head + nz):
                for m in range(N_SUMMED):
                    total[c, m] += partial[g, c, m]
    solid = s.reshape(size)
    momentum_x = ux.reshape(size)
    momentum_z = uz_rel.reshape(size)
    slope_x = grad_s_x.reshape(size)
    slope_z = grad_s_z.reshape(size)
    _expand(total, nx, nz, nx / Lx, solid, momentum_x, momentum_z, slope_x, slope_z)
    _normalise(nx, nz, Lx, z_bot, z_top, solid, momentum_x, momentum_z, slope_x, slope_z)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _corners_range(x, z, radius, first, last, Lx, z_bot, z_top, nx, nz, corners):
    """corners[:, first:last]: grain_area, cell_weights and corner_shares, the same values.
    A loop without calls or branches (SIMD) for grains clear of both planes with x in
    [dx/2 - Lx, Lx + dx/2) (one periodic wrap at most); it marks the others (d fz/dz = -1),
    which then take the scalar path."""
    inv_dx = nx / Lx
    inv_dz = nz / (z_top - z_bot)
    fnx = float(nx)
    fnz = float(nz)
    c00, c10, a00, a10, a01, a11, dfz = (corners[C_00], corners[C_10], corners[C_A00], corners[C_A10],
                                         corners[C_A01], corners[C_A11], corners[C_DFZ])
    for kk in range(first, last):
        k = np.uint64(kk)
        zk = z[k]
        r = radius[k]
        area = math.pi * r * r
        xi = x[k] * inv_dx - 0.5
        fi = math.floor(xi)
        fx = xi - fi
        fi = fi + fnx if fi < 0.0 else fi
        f1 = fi + 1.0
        f1 = 0.0 if f1 == fnx else f1
        zeta = (zk - z_bot) * inv_dz - 0.5
        fj = math.floor(zeta)
        inside = (fj >= 0.0) & (fj < fnz - 1.0)
        top = fj >= fnz - 1.0
        j0 = fj if inside else (fnz - 2.0 if top else 0.0)
        fz = zeta - fj if inside else (1.0 if top else 0.0)
        a0 = area * (1.0 - fz)
        a1 = area * fz
        c00[k] = fi * fnz + j0
        c10[k] = f1 * fnz + j0
        a00[k] = a0 * (1.0 - fx)
        a10[k] = a0 * fx
        a01[k] = a1 * (1.0 - fx)
        a11[k] = a1 * fx
        odd = (zk - z_bot < r) | (z_top - zk < r) | (fi < 0.0) | (fi >= fnx)
        dfz[k] = -1.0 if odd else (inv_dz if inside else 0.0)
    for k in range(first, last):
        if dfz[k] >= 0.0:
            continue
        area = grain_area(z[k], radius[k], z_bot, z_top)
        if area <= 0.0:
            c00[k] = -1.0
            dfz[k] = 0.0
            continue
        i0, i1, j0, fx, fz, slope = cell_weights(x[k], z[k], inv_dx, inv_dz, z_bot, nx, nz)
        c00[k], c10[k], _, _, a00[k], a10[k], a01[k], a11[k] = corner_shares(area, i0, i1, j0, fx, fz, nz)
        dfz[k] = slope


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _moments_range(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, moments, corners, nz, grain_kick):
    """moments (nx * nz, N_MOMENTS) of grains first:last from their corners, flagging (M_FLAG)
    the grid columns they add to. Zeroes the columns flagged by the previous call first, so
    the rest of moments must be zero on entry (a zeroed allocation keeps it so). grain_kick:
    see deposit (velocities after the owed half kick when its first item is true)."""
    if grain_kick is None:                  # (the arrays after False are not read)
        _moments_loop(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, moments, corners, nz,
                      (False, vx, vz, vx, vx, 0.0, 0.0, 0.0, 0.0))
    else:
        _moments_loop(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, moments, corners, nz, grain_kick)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _moments_loop(z, vx, vz, first, last, z_bot, z_top, w_bot, w_top, moments, corners, nz, grain_kick):
    """_moments_range with a grain_kick tuple."""
    owed, force_x, force_z, inv_mass, body, half, damp, wall_vx, wall_vz = grain_kick
    grid_strain_rate = (w_top - w_bot) / (z_top - z_bot)
    for head in range(0, moments.shape[0], nz):
        if moments[head, M_FLAG] != 0.0:
            for c in range(head, head + nz):
                for m in range(N_MOMENTS):
                    moments[c, m] = 0.0
    flat = moments.reshape(moments.size)
    c00, a00s, a10s, a01s, a11s, dfz = (corners[C_00], corners[C_A00], corners[C_A10], corners[C_A01],
                                         corners[C_A11], corners[C_DFZ])
    inv_nz = 1.0 / nz
    column = np.uint64(nz) * np.uint64(N_MOMENTS)
    for kk in range(first, last):
        k = np.uint64(kk)
        if c00[k] < 0.0:
            continue
        r = np.uint64(c00[k]) * np.uint64(N_MOMENTS)
        a00 = a00s[k]
        a10 = a10s[k]
        a01 = a01s[k]
        a11 = a11s[k]
        if owed:
            u, v = closed_velocity(body[k], vx[k], vz[k], force_x[k] * inv_mass[k], force_z[k] * inv_mass[k],
                                   half, damp, wall_vx, wall_vz)
        else:
            u = vx[k]
            v = vz[k]
        w = v - (w_bot + (z[k] - z_bot) * grid_strain_rate)
        flat[r + M_S] += a00
        flat[r + M_S + 1] += a10
        flat[r + M_S + 2] += a01
        flat[r + M_S + 3] += a11
        flat[r + M_U] += a00 * u
        flat[r + M_U + 1] += a10 * u
        flat[r + M_U + 2] += a01 * u
        flat[r + M_U + 3] += a11 * u
        flat[r + M_W] += a00 * w
        flat[r + M_W + 1] += a10 * w
        flat[r + M_W + 2] += a01 * w
        flat[r + M_W + 3] += a11 * w
        flat[r + M_G] += (a00 + a01) * dfz[k]
        flat[r + M_G + 1] += (a10 + a11) * dfz[k]
        # column of c00 = i nz + j (j < nz): floor((i nz + j) / nz) with 1/nz rounded is still i
        flat[np.uint64(math.floor(c00[k] * inv_nz)) * column + np.uint64(M_FLAG)] = 1.0


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _expand(moments, nx, nz, inv_dx, solid, momentum_x, momentum_z, slope_x, slope_z):
    """Raw sums per cell (as _deposit_range leaves them) from the moment records of the grains
    whose cell c00 is this one (share 00), the one to its left (10), below (01), left-below (11)."""
    for i in range(nx):
        il = i - 1 if i > 0 else nx - 1
        for j in range(nz):
            c = i * nz + j
            own = moments[c]
            left = moments[il * nz + j]
            a = own[M_S] + left[M_S + 1]
            b = own[M_U] + left[M_U + 1]
            e = own[M_W] + left[M_W + 1]
            gx = (own[M_S] + own[M_S + 1]) - (left[M_S] + left[M_S + 1])
            gz = own[M_G] + left[M_G + 1]
            if j > 0:
                below = moments[c - 1]
                corner = moments[il * nz + j - 1]
                a += below[M_S + 2] + corner[M_S + 3]
                b += below[M_U + 2] + corner[M_U + 3]
                e += below[M_W + 2] + corner[M_W + 3]
                gx += (below[M_S + 2] + below[M_S + 3]) - (corner[M_S + 2] + corner[M_S + 3])
                gz -= below[M_G] + corner[M_G + 1]
            solid[c] = a
            momentum_x[c] = b
            momentum_z[c] = e
            slope_x[c] = gx * inv_dx
            slope_z[c] = gz


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
                corners[C_00, k] = -1.0
            continue
        i0, i1, j0, fx, fz, dfz = cell_weights(x[k], z[k], inv_dx, inv_dz, z_bot, nx, nz)
        c00, c10, c01, c11, a00, a10, a01, a11 = corner_shares(area, i0, i1, j0, fx, fz, nz)
        if corners is not None:
            corners[C_00, k] = c00
            corners[C_10, k] = c10
            corners[C_A00, k] = a00
            corners[C_A10, k] = a10
            corners[C_A01, k] = a01
            corners[C_A11, k] = a11
            corners[C_DFZ, k] = dfz
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


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _normalise(nx, nz, Lx, z_bot, z_top, solid, momentum_x, momentum_z, slope_x, slope_z):
    """Raw sums -> s, mean velocities and slopes (see deposit)."""
    inv_area = nx / Lx * nz / (z_top - z_bot)
    for c in range(nx * nz):
        if solid[c] > 0.0:
            momentum_x[c] /= solid[c]
            momentum_z[c] /= solid[c]
        solid[c] *= inv_area
        slope_x[c] *= inv_area
        slope_z[c] *= inv_area


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
    work : float64[N_WORK, nx, nz] scratch (W_R, W_Z, W_P, W_Q, W_CP, W_DINV used)
    Returns (iterations, ||r|| / ||rhs||, converged).
    """
    r = work[W_R]
    zv = work[W_Z]
    p = work[W_P]
    q = work[W_Q]
    cp = work[W_CP]
    dinv = work[W_DINV]
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


@njit(cache=NUMBA_CACHE, error_model="numpy")
def pressure_gradient(P, dx, dz, p_bot, p_top, gx, gz):
    """Cell-centred grad P [E/d]: the mean of the two face gradients on each axis.

    Periodic in x; the wall faces use P = p_bot, p_top on the planes, half a cell
    away. Exact for a field linear in z; sum_c g dx dz telescopes to the plane
    values: sum_c gz dx dz = dx sum_i (p_top - p_bot), sum_c gx = 0.
    """
    nx, nz = P.shape
    for i in range(nx):
        ip = (i + 1) % nx
        im = (i - 1) % nx
        for j in range(nz):
            gx[i, j] = (P[ip, j] - P[im, j]) / (2.0 * dx)
            if j == 0:
                below = (P[i, 0] - p_bot) / (0.5 * dz)
            else:
                below = (P[i, j] - P[i, j - 1]) / dz
            if j == nz - 1:
                above = (p_top - P[i, j]) / (0.5 * dz)
            else:
                above = (P[i, j + 1] - P[i, j]) / dz
            gz[i, j] = 0.5 * (below + above)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def drag_density(gx, gz, s, fx, fz):
    """Drag per unit grain area f = -grad P / s [E/d] (s = 1 - phi unclamped; 0 where s = 0)."""
    nx, nz = s.shape
    for i in range(nx):
        for j in range(nz):
            if s[i, j] > 0.0:
                inv = -1.0 / s[i, j]
                fx[i, j] = gx[i, j] * inv
                fz[i, j] = gz[i, j] * inv
            else:
                fx[i, j] = 0.0
                fz[i, j] = 0.0


@njit(cache=NUMBA_CACHE, error_model="numpy", inline="always")
def _gather(flat_x, flat_z, c00, c10, a00, a10, a01, a11):
    """sum over the four corner cells of area x force density (c01 = c00 + 1, c11 = c10 + 1)."""
    c01 = c00 + np.uint64(1)
    c11 = c10 + np.uint64(1)
    return (a00 * flat_x[c00] + a10 * flat_x[c10] + a01 * flat_x[c01] + a11 * flat_x[c11],
            a00 * flat_z[c00] + a10 * flat_z[c10] + a01 * flat_z[c01] + a11 * flat_z[c11])


@njit(cache=NUMBA_CACHE, error_model="numpy", parallel=True)
def grain_drag(x, z, radius, n, Lx, z_bot, z_top, fx, fz, drag_x, drag_z):
    """Fluid force on each grain, F_k = a_k sum_c W_kc f_c (thesis Eq. 12).

    f = -grad P / (1 - phi) from drag_density; a_k is the in-domain area (pi R^2
    for a grain inside the layer, unit out-of-plane thickness) and W the deposit
    weights, so F_k = -a_k sum_c W_kc grad P_c / (1 - phi_c).
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
def grain_drag_at(corners, n, fx, fz, drag_x, drag_z):
    """grain_drag with the corner cells and areas the deposit stored (same positions): the
    same values, without recomputing areas and weights."""
    nx, nz = fx.shape
    flat_x = fx.reshape(nx * nz)
    flat_z = fz.reshape(nx * nz)
    for k in prange(n):
        if corners[C_00, k] < 0.0:
            drag_x[k] = 0.0
            drag_z[k] = 0.0
            continue
        drag_x[k], drag_z[k] = _gather(flat_x, flat_z, np.uint64(corners[C_00, k]), np.uint64(corners[C_10, k]),
                                       corners[C_A00, k], corners[C_A10, k], corners[C_A01, k], corners[C_A11, k])


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _all_finite(P):
    nx, nz = P.shape
    for i in range(nx):
        for j in range(nz):
            if not math.isfinite(P[i, j]):
                return False
    return True


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _finish_grid(Lx, z_bot, z_top, P, s, uz, work, w_bot, w_top):
    """Absolute uz, finiteness check, gradient and drag density; returns a status."""
    nx, nz = P.shape
    dx = Lx / nx
    dz = (z_top - z_bot) / nz
    for i in range(nx):
        for j in range(nz):
            uz[i, j] += w_bot + (j + 0.5) / nz * (w_top - w_bot)
    if not _all_finite(P):
        return STATUS_NONFINITE
    pressure_gradient(P, dx, dz, 0.0, 0.0, work[W_GX], work[W_GZ])
    drag_density(work[W_GX], work[W_GZ], s, work[W_FX], work[W_FZ])
    return STATUS_OK


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_drag(n, work, corners, drag_x, drag_z, status):
    """Third part of fluid_update: the drag on every grain from the drag density, at the positions
    of the deposit (corners); zero after a non-finite pressure (status STATUS_NONFINITE)."""
    if status == STATUS_NONFINITE:
        for k in range(n):
            drag_x[k] = 0.0
            drag_z[k] = 0.0
        return
    grain_drag_at(corners, n, work[W_FX], work[W_FZ], drag_x, drag_z)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_init(x, z, vx, vz, radius, n, Lx, z_bot, z_top,
               params, state, P, s, s_old, ux, uz, permeability, div_u, work, corners, partial, drag_x, drag_z):
    """Deposit the initial solid fraction and set the drag of the current P.

    Call once before the first fluid_update (and after a restart that does not
    restore s and state). P is left as given (zeros for a fresh run).
    Arguments as fluid_update without dt_f. Returns a status.
    """
    if not (z_top > z_bot):
        return STATUS_SOLVER
    deposit(x, z, vx, vz, radius, n, Lx, z_bot, z_top, 0.0, 0.0, s, ux, uz, work[W_SX], work[W_SZ], corners, partial)
    nx, nz = s.shape
    for i in range(nx):
        for j in range(nz):
            s_old[i, j] = s[i, j]
            div_u[i, j] = 0.0
    permeability_field(s, params[P_KAPPA_C], params[P_PHI_MIN], params[P_PHI_MAX],
                       permeability, work[W_CAPACITY], params[P_BETA])
    state[S_Z_BOT] = z_bot
    state[S_Z_TOP] = z_top
    state[S_ITERATIONS] = 0.0
    state[S_RESIDUAL] = 0.0
    state[S_SUBSTEPS] = 0.0
    state[S_UPDATES] = 0.0
    status = _finish_grid(Lx, z_bot, z_top, P, s, uz, work, 0.0, 0.0)
    fluid_drag(n, work, corners, drag_x, drag_z, status)
    return status


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_update(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f,
                 params, state, P, s, s_old, ux, uz, permeability, div_u, work, corners, partial, drag_x, drag_z,
                 grain_kick=None):
    """Advance the pore pressure by one fluid step and set the drag on every grain.

    x, z, vx, vz, radius : float64[>= n] grain state (x may lie outside [0, Lx))
    n : number of grains;  Lx : periodic width [d]
    z_bot, z_top : wall planes now [d] (mean z of the wall-grain centres)
    dt_f : time since the last fluid update [t0]
    params, state, P, s, s_old, ux, uz, permeability, div_u, work, corners, partial : see module doc
        (FluidGrid.kernel_args() returns them in this order, followed by drag_x, drag_z)
    drag_x, drag_z : out, float64[>= n] fluid force per grain [E d^2], to be added
        to the contact forces until the next update.
    grain_kick : None, or (owed, ...) as in deposit, when the grains may still owe their second
        half kick: the deposit then takes the whole-step velocities without storing them.

    Order: deposit s^{n+1} and u_rel (keeping each grain's corner cells and areas in
    corners); exact undrained source -> P*; Carman-Kozeny permeability from s^{n+1};
    conductances with (1 + beta P^n); implicit or explicit diffusion over dt_f; grad P and
    drag. Returns a status (module doc). In three parts, fluid_begin (reads the grains),
    fluid_solve (the grid only) and fluid_drag, so that a caller can move the grains while
    the grid is solved.
    """
    status = fluid_begin(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, state, s, s_old, ux, uz, work, corners,
                         partial, grain_kick)
    if status != STATUS_OK:
        return status
    status = fluid_solve(Lx, z_bot, z_top, dt_f, params, state, P, s, s_old, ux, uz, permeability, div_u, work)
    fluid_drag(n, work, corners, drag_x, drag_z, status)
    return status


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _plane_velocities(state, z_bot, z_top, dt_f):
    """[v0] velocities of the bottom and top planes since the last update (grid velocity w(z))."""
    return (z_bot - state[S_Z_BOT]) / dt_f, (z_top - state[S_Z_TOP]) / dt_f


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_begin(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, state, s, s_old, ux, uz, work, corners, partial,
                grain_kick):
    """First part of fluid_update (same arguments): s^n kept, deposit s^{n+1} and u_rel, the
    only part that reads the grains' positions and velocities. Returns a status."""
    if not (z_top - z_bot > 0.0 and dt_f > 0.0):
        return STATUS_SOLVER
    nx, nz = s.shape
    w_bot, w_top = _plane_velocities(state, z_bot, z_top, dt_f)
    for i in range(nx):
        for j in range(nz):
            s_old[i, j] = s[i, j]
    deposit(x, z, vx, vz, radius, n, Lx, z_bot, z_top, w_bot, w_top, s, ux, uz, work[W_SX], work[W_SZ], corners, partial,
            grain_kick)
    return STATUS_OK


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_solve(Lx, z_bot, z_top, dt_f, params, state, P, s, s_old, ux, uz, permeability, div_u, work):
    """Second part of fluid_update, on the grid only (serial): source, permeability, diffusion,
    gradient and drag density. Returns a status."""
    nx, nz = P.shape
    dx = Lx / nx
    dz = (z_top - z_bot) / nz
    beta = params[P_BETA]
    w_bot, w_top = _plane_velocities(state, z_bot, z_top, dt_f)
    p_star = work[W_RHS]
    undrained_source(P, s, s_old, ux, uz, work[W_SX], work[W_SZ], dt_f, beta,
                     1.0 - params[P_PHI_MAX], 1.0 - params[P_PHI_MIN], p_star, div_u)
    capacity = work[W_CAPACITY]
    permeability_field(s, params[P_KAPPA_C], params[P_PHI_MIN], params[P_PHI_MAX],
                       permeability, capacity, beta)
    tx = work[W_TX]
    tz = work[W_TZ]
    tb = work[W_TB]
    face_conductances(P, permeability, dx, dz, beta, params[P_ETA], tx, tz, tb)
    dt_max = explicit_bound(capacity, tx, tz, tb)
    state[S_DT_MAX] = dt_max
    status = STATUS_OK
    if params[P_SOLVER] == SOLVER_EXPLICIT:
        substeps = max(1.0, math.ceil(dt_f / (params[P_SAFETY] * dt_max)))
        for i in range(nx):
            for j in range(nz):
                P[i, j] = p_star[i, j]
        state[S_ITERATIONS] = 0.0
        state[S_SUBSTEPS] = substeps
        if not substeps <= params[P_MAX_SUBSTEPS]:
            status = STATUS_SOLVER
        else:
            n_sub = int(substeps)
            explicit_diffusion(P, capacity, tx, tz, tb, dt_f / n_sub, n_sub, work[W_Q])
    else:
        diag = work[W_DIAG]
        for i in range(nx):
            im = (i - 1) % nx
            for j in range(nz):
                c = capacity[i, j] / dt_f
                d = c + tx[i, j] + tx[im, j] + tb[i, j] + tz[i, j]
                if j > 0:
                    d += tz[i, j - 1]
                diag[i, j] = d
                P[i, j] = p_star[i, j]
                p_star[i, j] *= c
        iterations, residual, converged = conjugate_gradient(
            P, p_star, diag, tx, tz, work, params[P_TOL], int(params[P_MAX_ITER]))
        state[S_ITERATIONS] = iterations
        state[S_RESIDUAL] = residual
        state[S_SUBSTEPS] = 1.0
        if not converged:
            status = STATUS_SOLVER
    state[S_Z_BOT] = z_bot
    state[S_Z_TOP] = z_top
    state[S_UPDATES] += 1.0
    finish = _finish_grid(Lx, z_bot, z_top, P, s, uz, work, w_bot, w_top)
    if finish != STATUS_OK:
        return finish
    return status
