"""Pore-fluid kernels on the Goren pressure grid (thesis Eqs. 12, 14-20; docs/physics/fluid.md).

Pure compute (``error_model="numpy"``: IEEE inf/NaN instead of ZeroDivisionError, so loops
vectorise), no allocation: every array is allocated once by :class:`gouge_cli.model.fluid.FluidGrid`
and passed in. Everything is dimensionless (d = E = rho_s = 1): lengths [d], time [t0],
pressure [E], permeability [d^2], viscosity [E t0], compressibility [1/E].

Grid: :mod:`gouge_cli.kernels.deposit` (cell-centred, stretching with the layer, P = 0 on both
wall planes, periodic in x).

One fluid update = deposit (deposit.py) -> filter (filter.py) -> source and pressure solve (pressure.py, Eqs. 14-20)
-> pressure gradient and grain drag (drag.py, Eqs. 12-13); this module orders them.

Array layouts
-------------
params : float64[N_FLUID_PARAMS]  indices P_* (kernels.layout) (see FluidGrid.from_config)
state  : float64[N_FLUID_STATE]   indices S_* (kernels.layout); S_Z_BOT/S_Z_TOP are the planes at
                            the last update and must be checkpointed with P and s
P, s, s_old, ux, uz, permeability, div_u : float64[nx, nz] (s, ux, uz filtered: kernels.filter)
work   : float64[N_GRID_WORK, nx, nz]   scratch, rows G_* of kernels.layout
corners : float64[N_CORNERS, N]    per-grain deposit cells and areas (see deposit), reused for the drag
partial : float64[DEPOSIT_GROUPS, nx * nz, N_MOMENTS]   per-group deposit moments (see deposit);
                            allocate it zeroed: between calls it is zero outside the columns flagged
                            in it (M_FLAG)
taps_x : float64[nx], bands_z : float64[3, 2 nz - 1, nz]   the filter's operators (kernels.filter), scratch
drag_x, drag_z : float64[N]        force on each grain [E d^2]

Status: STATUS_OK 0; STATUS_SOLVER 1 (CG not converged in max_iter: P is the
last iterate; explicit sub-steps above max_substeps: P = P*, no diffusion; a
non-positive dt_f or layer thickness: nothing done); STATUS_NONFINITE 2 (P not
finite; drag is then set to zero). A status other than 0 should stop the run.
"""

import math

import numpy as np
from numba import njit

from . import NUMBA_CACHE
from .layout import (AUTO_EXPLICIT, CR_Z, S_F_BOT, S_F_TOP, Deposited, Discs, Planes, G_CAPACITY, G_DIAG, G_FQ, G_FX, G_FZ, G_P, G_PREV, G_Q, G_R, G_RHS, G_SX,
                     G_SZ, G_TB, G_TMP, G_TX, G_TZ, G_Z, P_BETA, P_ETA, P_FILTER_WIDTH, P_KAPPA_C, P_MAX_ITER,
                     P_MAX_SUBSTEPS, P_PHI_MAX, P_PHI_MIN, P_SAFETY, P_SOLVER, P_TOL, SOLVER_AUTO, SOLVER_EXPLICIT,
                     STATUS_NONFINITE, STATUS_OK, STATUS_SOLVER, S_DT_MAX, S_EXPLICIT_UPDATES, S_ITERATIONS,
                     S_RESIDUAL, S_SUBSTEPS, S_UPDATES, S_Z_BOT, S_Z_TOP)
from .deposit import collect_columns, deposit, expand_columns
from .drag import drag_triples, grain_drag_consistent, interleave_triples
from .filter import filter_setup, filter_x, filter_z, half_widths, velocities_of_moments, velocity_moments
from .pressure import (bound_of_rates, bound_rates, cells, conjugate_gradient, copy_grid, explicit_diffusion,
                       face_conductances, flat, heun_corrector, heun_predictor, implicit_system, permeability_field,
                       undrained_source, _face_diagonal)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _all_finite(P, i0=0, i1=-1):
    """True if every cell of P on columns i0..i1 (kernels.pressure.cells) is finite (one
    branch-free pass: it vectorises)."""
    pf = flat(P)
    lo, hi = cells(P, i0, i1)
    bad = 0
    for c in range(lo, hi):
        bad += 0 if abs(pf[c]) < math.inf else 1
    return bad == 0


FORWARD_FIELDS = 5    # the filter's fields: s, s ux, s uz, ds/dx, ds/dz (_forward_field)
DRAG_FIELDS = 3       # the drag's fields filtered back: q, r_x, r_z (work rows G_FQ, G_FX, G_FZ)
# A fluid update's grid work as stages run in this order (grid_stage): the deposit's finish (COLLECT,
# EXPAND), the filter forward (TAPS, MOMENTS, FORWARD_X, FORWARD_Z, VELOCITIES: S = S_z S_x on the
# deposit's fields), the source, permeability and face conductances (SOURCE, FACES), the cells'
# explicit bounds (RATES), then the choice of solver (pressure_choose, serial), Heun's two halves
# (PREDICT, CORRECT: when it is chosen), the drag's fields (DENSITY), the update's close
# (pressure_close, serial), then the filter back (BACK_Z, BACK_X: S^T = S_x S_z^T on the drag's
# fields) and INTERLEAVE
(COLLECT, EXPAND, TAPS, MOMENTS, FORWARD_X, FORWARD_Z, VELOCITIES, SOURCE, FACES, RATES, PREDICT, CORRECT, DENSITY,
 BACK_Z, BACK_X, INTERLEAVE) = range(16)
N_STAGES = 16


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _drag_density(fluid, w_bot, w_top, extrapolate, i0=0, i1=-1):
    """Absolute uz, the drag's fields on the grid (before S^T) on columns i0..i1 (-1: all); returns
    whether P is finite on them (if not, the fields are not used: STATUS_NONFINITE).

    The drag acts until the next update, so it is taken from the pressure extrapolated to the
    middle of that interval, P + (P - P^n)/2 (P^n in work[G_PREV]; extrapolate False, as at
    fluid_init: P itself): a drag held at the value of the interval's start lags the grains by
    half a fluid step, which at high De (no diffusion to damp it) pumps energy into the
    grain-fluid oscillation at a rate ~ omega^2 dt_f / 4; the extrapolation removes that first
    order term. The drag is the deposit's adjoint (kernels.drag.drag_triples: q = P/s,
    r = (P/s^2) grad s), whose fields then go back through the filter's transpose
    (grid stages BACK_Z, BACK_X, INTERLEAVE)."""
    P, s, uz, work = fluid.pressure, fluid.s, fluid.uz, fluid.work
    nx, nz = P.shape
    last = nx if i1 < 0 else i1
    for j in range(nz):                     # (a row's w once: a division per row, not per cell)
        w = w_bot + (j + 0.5) / nz * (w_top - w_bot)
        for i in range(i0, last):
            uz[i, j] += w
    ext = work[G_PREV]
    pf, ef = flat(P), flat(ext)
    lo, hi = cells(P, i0, i1)
    finite = _all_finite(P, i0, i1)
    if extrapolate:
        for c in range(lo, hi):
            ef[c] = 1.5 * pf[c] - 0.5 * ef[c]
    else:
        for c in range(lo, hi):
            ef[c] = pf[c]
    drag_triples(ext, s, work[G_SX], work[G_SZ], work[G_FQ], work[G_FX], work[G_FZ], i0, i1)
    return finite


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _finish_grid(Lx, z_bot, z_top, fluid, w_bot, w_top, extrapolate):
    """_drag_density, then its fields through S^T on this thread; returns a status."""
    if not _drag_density(fluid, w_bot, w_top, extrapolate, int(0), int(-1)):
        return STATUS_NONFINITE
    grid_stages(int(BACK_Z), int(N_STAGES), Lx, z_bot, z_top, 0.0, fluid)
    return STATUS_OK


@njit(cache=NUMBA_CACHE, inline="always")
def _deposited(fluid):
    """The deposit's five fields in the grid's arrays: s, ux, uz and grad s in work rows G_SX, G_SZ
    (grad_z s of the deposit mirrored across the wall planes)."""
    return Deposited(fluid.s, fluid.ux, fluid.uz, fluid.work[G_SX], fluid.work[G_SZ])


@njit(cache=NUMBA_CACHE, inline="always")
def _triples(work):
    """The drag's interleaved (q, r_x, r_z) per cell: work rows G_R..G_P (free after the solve) as one
    flat float64[3 nx nz] (kernels.drag.interleave_triples)."""
    return work[G_R:G_P + 1].reshape(3 * work.shape[1] * work.shape[2])


@njit(cache=NUMBA_CACHE, inline="always")
def _forward_field(fluid, k):
    """The filter's field k: s, ux, uz (the moments s u while filtered), ds/dx, ds/dz."""
    if k == 0:
        return fluid.s
    if k == 1:
        return fluid.ux
    if k == 2:
        return fluid.uz
    return fluid.work[G_SX + k - 3]


@njit(cache=NUMBA_CACHE, error_model="numpy")
def filter_half_widths(Lx, z_bot, z_top, fluid):
    """(mx, mz) of the filter on the current cells (kernels.filter.half_widths; both 0: no filter)."""
    nx, nz = fluid.s.shape
    return half_widths(fluid.params[P_FILTER_WIDTH], Lx / nx, (z_top - z_bot) / nz, nx, nz)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def stage_parts(stage, parts):
    """How many parts grid_stage cuts `stage` into when a field's columns are cut into `parts`."""
    if stage == TAPS:
        return 1
    if stage == FORWARD_X or stage == FORWARD_Z:
        return FORWARD_FIELDS * parts
    if stage == BACK_Z or stage == BACK_X:
        return DRAG_FIELDS * parts
    return parts


@njit(cache=NUMBA_CACHE, error_model="numpy")
def grid_stage(stage, index, parts, Lx, z_bot, z_top, dt_f, fluid, mx, mz):
    """Part `index` (< stage_parts(stage, parts)) of a grid stage; (mx, mz): filter_half_widths.
    Returns False if the part found a pressure that is not finite (DENSITY), else True.

    COLLECT, EXPAND: the deposit's finish (kernels.deposit: collect_columns, expand_columns);
    TAPS: the filter's taps (kernels.filter.filter_setup); MOMENTS: u -> s u; FORWARD_X: S_x of
    deposit field k (_forward_field: s, s ux, s uz, ds/dx, ds/dz) into scratch row G_TMP + k;
    FORWARD_Z: S_z of that row back into the field; VELOCITIES: s u -> u = S(s u) / S(s);
    BACK_Z: S_z^T of drag field k (G_FQ + k: q, r_x, r_z) into G_TMP + k; BACK_X: S_x of that row
    back into the field; INTERLEAVE: the triples grain_drag_consistent reads (_triples); SOURCE,
    FACES, RATES, PREDICT, CORRECT, DENSITY: pressure_stage's parts (kernels.pressure). A
    field's columns are cut into `parts` parts (k = index // parts). Each stage needs the one
    before it complete on every column; within a stage the parts are independent and each cell's
    sums run in one order, so any thread may take any part (the same bits). The filtered s and
    grad s are S s and S grad s (grad_z s through S_z with odd images, bands_z[2]): the same linear
    map of the same deposit, so still its derivative with respect to the cell position, that of
    the deposit mirror-extended across the planes (kernels.deposit). With no filter (mx = mz = 0) the filter's stages do nothing."""
    work = fluid.work
    nx = work.shape[1]
    part = index % parts
    i0 = part * nx // parts
    i1 = (part + 1) * nx // parts
    if stage == COLLECT:
        collect_columns(fluid.partial, nx, work.shape[2], i0, i1)
    elif stage == EXPAND:
        expand_columns(Lx, z_bot, z_top, _deposited(fluid), fluid.partial, i0, i1)
    elif stage == INTERLEAVE:
        interleave_triples(work[G_FQ], work[G_FX], work[G_FZ], _triples(work), i0, i1)
    elif stage >= SOURCE and stage <= DENSITY:
        return _pressure_part(stage, Lx, z_bot, z_top, dt_f, fluid, i0, i1)
    elif mx > 0 or mz > 0:
        _filter_part(stage, index // parts, fluid, Lx, z_bot, z_top, mx, mz, i0, i1)
    return True


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _filter_part(stage, k, fluid, Lx, z_bot, z_top, mx, mz, i0, i1):
    """grid_stage's filter stages on field k, columns i0..i1."""
    work = fluid.work
    nx = work.shape[1]
    tmp = work[G_TMP + k]
    if stage == TAPS:
        filter_setup(fluid.params[P_FILTER_WIDTH], Lx / nx, (z_top - z_bot) / work.shape[2], fluid.taps_x,
                     fluid.bands_z)
    elif stage == MOMENTS:
        velocity_moments(fluid.s, fluid.ux, fluid.uz, i0, i1)
    elif stage == FORWARD_X:
        filter_x(_forward_field(fluid, k), tmp, fluid.taps_x, mx, i0, i1)
    elif stage == FORWARD_Z:
        filter_z(tmp, _forward_field(fluid, k), fluid.bands_z[2 if k == 4 else 0], mz, i0, i1)
    elif stage == VELOCITIES:
        velocities_of_moments(fluid.s, fluid.ux, fluid.uz, i0, i1)
    elif stage == BACK_Z:
        filter_z(work[G_FQ + k], tmp, fluid.bands_z[1], mz, i0, i1)
    else:
        filter_x(tmp, work[G_FQ + k], fluid.taps_x, mx, i0, i1)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _pressure_part(stage, Lx, z_bot, z_top, dt_f, fluid, i0, i1):
    """grid_stage's pressure stages on columns i0..i1 (pressure_stage: the order and the arrays)."""
    params, state, P, s, work = fluid.params, fluid.state, fluid.pressure, fluid.s, fluid.work
    nx, nz = P.shape
    beta = params[P_BETA]
    capacity, tx, tz, tb, diag = work[G_CAPACITY], work[G_TX], work[G_TZ], work[G_TB], work[G_DIAG]
    if stage == SOURCE:
        copy_grid(P, work[G_PREV], i0, i1)
        undrained_source(P, s, fluid.s_old, fluid.ux, fluid.uz, work[G_SX], work[G_SZ], dt_f, beta,
                         1.0 - params[P_PHI_MAX], 1.0 - params[P_PHI_MIN], work[G_RHS], fluid.div_u, i0, i1)
        permeability_field(s, params[P_KAPPA_C], params[P_PHI_MIN], params[P_PHI_MAX], fluid.permeability, capacity,
                           beta, i0, i1)
    elif stage == FACES:
        face_conductances(P, fluid.permeability, Lx / nx, (z_top - z_bot) / nz, beta, params[P_ETA], tx, tz, tb,
                          i0, i1)
    elif stage == RATES:
        bound_rates(capacity, tx, tz, tb, work[G_R], i0, i1)
        _face_diagonal(tx, tz, tb, diag, i0, i1)
    elif stage == PREDICT:
        heun_predictor(P, capacity, tx, tz, dt_f, diag, work[G_Q], work[G_P], i0, i1)
    elif stage == CORRECT:
        heun_corrector(P, capacity, tx, tz, dt_f, diag, work[G_Q], work[G_P], work[G_Z], i0, i1)
    else:
        w_bot, w_top = _plane_velocities(state, z_bot, z_top, dt_f)
        return _drag_density(fluid, w_bot, w_top, bool(True), i0, i1)
    return True


@njit(cache=NUMBA_CACHE, error_model="numpy")
def grid_stages(first, last, Lx, z_bot, z_top, dt_f, fluid):
    """Grid stages first <= stage < last on this thread (grid_stage, whole columns); returns
    False if the pressure is not finite (DENSITY)."""
    mx, mz = filter_half_widths(Lx, z_bot, z_top, fluid)
    finite = True
    whole = int(1)
    for stage in range(first, last):
        for index in range(stage_parts(stage, whole)):
            finite &= grid_stage(stage, index, whole, Lx, z_bot, z_top, dt_f, fluid, mx, mz)
    return finite


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_drag(n, Lx, fluid, drag_x, drag_z, status):
    """Third part of fluid_update: the drag on every grain (kernels.drag.grain_drag_consistent) at
    the positions of the deposit (fluid.corners); zero after a non-finite pressure (status
    STATUS_NONFINITE)."""
    if status == STATUS_NONFINITE:
        for k in range(n):
            drag_x[k] = 0.0
            drag_z[k] = 0.0
        return
    work = fluid.work
    grain_drag_consistent(fluid.corners, n, work.shape[2], work.shape[1] / Lx, _triples(work), drag_x, drag_z)
    fluid.state[S_F_BOT], fluid.state[S_F_TOP] = plane_forces(n, Lx, fluid, drag_z)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def plane_forces(n, Lx, fluid, drag_z):
    """(F_bot, F_top) [E d]: the fluid's z force on the two wall planes, minus the derivative of the
    power the pressure source stores with respect to each plane's velocity (the deposit's adjoint
    with respect to the planes, as the drag is with respect to the grains; docs/physics/fluid.md):

        F_top = dx dz / H sum_c P'_c - sum_k F_k,z h_k,   F_bot = -dx dz / H sum_c P'_c - sum_k F_k,z (1 - h_k)

    with P' the drag's (extrapolated) pressure over cells holding solid, F_k,z the grains' drag and
    h_k = (z_k - z_bot) / H their height in the layer at the deposit (corners row CR_Z). The first
    term is the cells' height growing with H (s = A / (dx dz)), the second the grid's stretching
    under the grains (their weights and grid-relative velocity). A uniform suction -|P| pulls the
    top plane down and the bottom one up by |P| L_x; F_bot + F_top + sum_k F_k,z = 0 (action and
    reaction). The in-domain areas of the grains a plane cuts are left out of both this and the
    drag: a top-wall grain moves with its plane, so its area does not change. Call after the drag."""
    ext, s = fluid.work[G_PREV], fluid.s
    nx, nz = s.shape
    total = 0.0
    for i in range(nx):
        for j in range(nz):
            if s[i, j] > 0.0:
                total += ext[i, j]
    cells_term = total * (Lx / nx) / nz
    heights = fluid.corners[CR_Z]
    lever = 0.0
    drag = 0.0
    for k in range(n):
        if drag_z[k] != 0.0:                 # (a grain outside the layer has no drag)
            lever += drag_z[k] * heights[k]
            drag += drag_z[k]
    return -cells_term - (drag - lever), cells_term - lever


@njit(cache=NUMBA_CACHE, error_model="numpy")
def add_top_plane_force(fluid, top, drag_z, status):
    """Share the top plane's fluid force (state S_F_TOP, plane_forces) equally among the top-wall grains'
    drag_z, so that kernels.step.wall_force takes it into the top body's force (the wet engine's
    path; those grains move with the body, so their drag work is the plane's)."""
    if status != STATUS_OK or top.shape[0] == 0:
        return
    share = fluid.state[S_F_TOP] / top.shape[0]
    for m in range(top.shape[0]):
        drag_z[top[m]] += share


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_init(x, z, vx, vz, radius, n, Lx, z_bot, z_top, fluid, drag_x, drag_z):
    """Deposit and filter the initial solid fraction and set the drag of the current P.

    Call once before the first fluid_update (and after a restart that does not
    restore s and state). P is left as given (zeros for a fresh run).
    Arguments as fluid_update without dt_f. Returns a status.
    """
    if not (z_top > z_bot):
        return STATUS_SOLVER
    params, state, s, s_old, div_u, work = fluid.params, fluid.state, fluid.s, fluid.s_old, fluid.div_u, fluid.work
    deposit(Discs(x, z, vx, vz, radius), n, Lx, Planes(z_bot, z_top, 0.0, 0.0), _deposited(fluid), fluid.corners,
            fluid.partial)
    grid_stages(int(TAPS), int(SOURCE), Lx, z_bot, z_top, 0.0, fluid)
    nx, nz = s.shape
    for i in range(nx):
        for j in range(nz):
            s_old[i, j] = s[i, j]
            div_u[i, j] = 0.0
    permeability_field(s, params[P_KAPPA_C], params[P_PHI_MIN], params[P_PHI_MAX],
                       fluid.permeability, work[G_CAPACITY], params[P_BETA], int(0), int(-1))
    state[S_Z_BOT] = z_bot
    state[S_Z_TOP] = z_top
    state[S_ITERATIONS] = 0.0
    state[S_RESIDUAL] = 0.0
    state[S_SUBSTEPS] = 0.0
    state[S_UPDATES] = 0.0
    state[S_EXPLICIT_UPDATES] = 0.0
    status = _finish_grid(Lx, z_bot, z_top, fluid, 0.0, 0.0, bool(False))
    fluid_drag(n, Lx, fluid, drag_x, drag_z, status)
    return status


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_update(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, fluid, drag_x, drag_z, grain_kick=None):
    """Advance the pore pressure by one fluid step and set the drag on every grain.

    x, z, vx, vz, radius : float64[>= n] grain state (x may lie outside [0, Lx))
    n : number of grains;  Lx : periodic width [d]
    z_bot, z_top : wall planes now [d] (mean z of the wall-grain centres)
    dt_f : time since the last fluid update [t0]
    fluid : the grid's arrays (kernels.layout.FluidArrays, FluidGrid.record(); shapes: module doc)
    drag_x, drag_z : out, float64[>= n] fluid force per grain [E d^2], to be added
        to the contact forces until the next update.
    grain_kick : None, or (owed, ...) as in deposit, when the grains may still owe their second
        half kick: the deposit then takes the whole-step velocities without storing them.

    Order: deposit s^{n+1} and u_rel (keeping each grain's corner cells and areas in
    corners) and filter them over the width w (kernels.filter); exact undrained source -> P*;
    Carman-Kozeny permeability from s^{n+1};
    conductances with (1 + beta P^n); implicit or explicit diffusion over dt_f (auto: one
    explicit (Heun) step while dt_f <= AUTO_EXPLICIT times the FTCS bound, kernels.pressure);
    grad P (extrapolated to the middle of the next interval) and the drag through the filter's
    transpose. Returns a status (module doc). In three parts, fluid_begin (reads the grains),
    fluid_solve (the grid only) and fluid_drag, so that a caller can move the grains while
    the grid is solved.
    """
    status = fluid_begin(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, fluid, grain_kick)
    if status != STATUS_OK:
        return status
    status = fluid_solve(Lx, z_bot, z_top, dt_f, fluid)
    fluid_drag(n, Lx, fluid, drag_x, drag_z, status)
    return status


@njit(cache=NUMBA_CACHE, error_model="numpy")
def _plane_velocities(state, z_bot, z_top, dt_f):
    """[v0] velocities of the bottom and top planes since the last update (grid velocity w(z))."""
    return (z_bot - state[S_Z_BOT]) / dt_f, (z_top - state[S_Z_TOP]) / dt_f


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_begin(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, fluid, grain_kick, serial=False, finish=True):
    """First part of fluid_update (same arguments): s^n kept, deposit s^{n+1} and u_rel, the
    only part that reads the grains' positions and velocities; serial: plain loops (one thread).
    finish False (not serial): the deposit stops after the grains' moments; fluid_finish_deposit
    must then run before fluid_solve. Returns a status."""
    if not (z_top - z_bot > 0.0 and dt_f > 0.0):
        return STATUS_SOLVER
    w_bot, w_top = _plane_velocities(fluid.state, z_bot, z_top, dt_f)
    copy_grid(fluid.s, fluid.s_old)
    deposit(Discs(x, z, vx, vz, radius), n, Lx, Planes(z_bot, z_top, w_bot, w_top), _deposited(fluid),
            fluid.corners, fluid.partial, grain_kick, serial, finish)
    return STATUS_OK


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_finish_deposit(Lx, z_bot, z_top, fluid):
    """The deposit's last part after fluid_begin(finish=False), on this thread (grid only)."""
    grid_stages(int(COLLECT), int(TAPS), Lx, z_bot, z_top, 0.0, fluid)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def fluid_solve(Lx, z_bot, z_top, dt_f, fluid):
    """Second part of fluid_update, on the grid only, on this thread: filter, source, permeability,
    diffusion, gradient and drag density. fluid: kernels.layout.FluidArrays. Returns a status.
    (kernels.coupled runs the same parts with the filter's fields shared between two threads.)"""
    grid_stages(int(TAPS), int(SOURCE), Lx, z_bot, z_top, 0.0, fluid)
    status = pressure_stage(Lx, z_bot, z_top, dt_f, fluid)
    if status == STATUS_NONFINITE:
        return status
    grid_stages(int(BACK_Z), int(N_STAGES), Lx, z_bot, z_top, dt_f, fluid)
    return status


@njit(cache=NUMBA_CACHE, error_model="numpy")
def pressure_stage(Lx, z_bot, z_top, dt_f, fluid):
    """The part of fluid_solve between the filter and the drag's S^T, on this thread: source and
    permeability, face conductances (with 1 + beta P^n), the explicit bound, diffusion over dt_f,
    then the drag's fields (_drag_density). Returns a status: STATUS_NONFINITE leaves the drag
    fields unused (fluid_drag then zeroes the drag). As grid stages SOURCE .. DENSITY around the
    serial pressure_choose and pressure_close, which kernels.coupled shares between two threads."""
    grid_stages(int(SOURCE), int(PREDICT), Lx, z_bot, z_top, dt_f, fluid)
    heun, status = pressure_choose(dt_f, fluid)
    finite = grid_stages(PREDICT if heun else DENSITY, int(BACK_Z), Lx, z_bot, z_top, dt_f, fluid)
    return pressure_close(z_bot, z_top, fluid, finite, status)


@njit(cache=NUMBA_CACHE, error_model="numpy")
def pressure_choose(dt_f, fluid):
    """After RATES: the explicit bound (state S_DT_MAX) and the solver for dt_f: Heun (auto, while
    dt_f <= AUTO_EXPLICIT x the bound: returns heun True, P = P*, and grid stages PREDICT and
    CORRECT must follow), or here, on this thread, the explicit sub-steps or backward Euler
    (kernels.pressure). Returns (heun, status)."""
    params, state, P, work = fluid.params, fluid.state, fluid.pressure, fluid.work
    capacity, tx, tz, tb = work[G_CAPACITY], work[G_TX], work[G_TZ], work[G_TB]
    p_star = work[G_RHS]
    dt_max = bound_of_rates(work[G_R])
    state[S_DT_MAX] = dt_max
    status = STATUS_OK
    solver = params[P_SOLVER]
    heun = solver == SOLVER_AUTO and dt_f <= AUTO_EXPLICIT * dt_max
    if heun or solver == SOLVER_EXPLICIT:
        substeps = 1.0 if heun else max(1.0, math.ceil(dt_f / (params[P_SAFETY] * dt_max)))
        copy_grid(p_star, P)
        state[S_ITERATIONS] = 0.0
        state[S_RESIDUAL] = 0.0
        state[S_SUBSTEPS] = substeps
        if not substeps <= params[P_MAX_SUBSTEPS]:
            return False, STATUS_SOLVER
        if not heun:
            n_sub = int(substeps)
            explicit_diffusion(P, capacity, tx, tz, tb, dt_f / n_sub, n_sub, work[G_DIAG], work[G_Q])
        state[S_EXPLICIT_UPDATES] += 1.0
        return heun, status
    diag = work[G_DIAG]
    implicit_system(capacity, tx, tz, tb, dt_f, p_star, P, diag)
    iterations, residual, converged = conjugate_gradient(
        P, p_star, diag, tx, tz, work, params[P_TOL], int(params[P_MAX_ITER]))
    state[S_ITERATIONS] = iterations
    state[S_RESIDUAL] = residual
    state[S_SUBSTEPS] = 1.0
    if not converged:
        status = STATUS_SOLVER
    return False, status


@njit(cache=NUMBA_CACHE, error_model="numpy")
def pressure_close(z_bot, z_top, fluid, finite, status):
    """After DENSITY: the planes of this update and the update count in the state; returns the
    update's status (STATUS_NONFINITE if the pressure is not finite)."""
    state = fluid.state
    state[S_Z_BOT] = z_bot
    state[S_Z_TOP] = z_top
    state[S_UPDATES] += 1.0
    return status if finite else STATUS_NONFINITE
