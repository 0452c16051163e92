"""The pressure grid's flat (vectorising) loops against the cell-by-cell definitions, bit for bit,
on grids of every small shape (hypothesis): 1 to 6 columns (one column is its own periodic
neighbour; two are each other's on both sides) and 2 to 7 rows (gouge_cli/kernels/pressure.py,
drag.py, fluid_update.py). The references below are plain Python over (i, j) with the terms in
the kernels' documented order, so any regrouping, a wrong wrap or a missed wall row fails."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gouge_cli.kernels import drag as KG
from gouge_cli.kernels import deposit as KD
from gouge_cli.kernels import fluid_update as KF
from gouge_cli.kernels import layout as L
from gouge_cli.kernels import pressure as KP

shapes = st.tuples(st.integers(1, 6), st.integers(2, 7), st.integers(0, 2**31 - 1))


def _deposit(x, z, vx, vz, radius, n, width, z_bot, z_top, w_bot, w_top, s, ux, uz, gx, gz, *rest):
    """kernels.deposit.deposit with its records (layout.Discs, Planes, Deposited) made of plain arrays."""
    planes = L.Planes(float(z_bot), float(z_top), float(w_bot), float(w_top))
    KD.deposit(L.Discs(x, z, vx, vz, radius), n, width, planes, L.Deposited(s, ux, uz, gx, gz), *rest)


def _fields(nx, nz, seed):
    """Positive conductances and capacities, signed pressures, solid fractions in (0.6, 0.95)."""
    rng = np.random.default_rng(seed)
    pos = lambda: rng.uniform(0.2, 3.0, (nx, nz))  # noqa: E731
    return rng, {"P": rng.normal(0.0, 1e-3, (nx, nz)), "perm": rng.uniform(0.0, 2e-5, (nx, nz)),
                 "cap": pos(), "tx": pos(), "tz": pos(), "tb": pos(), "s": rng.uniform(0.6, 0.95, (nx, nz))}


def _same(a, b):
    assert a.shape == b.shape
    assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), np.abs(a - b).max()


def ref_faces(P, k, dx, dz, beta, eta):
    nx, nz = P.shape
    cx, cz = 1.0 / (eta * dx * dx), 1.0 / (eta * dz * dz)
    tx, tz, tb = np.zeros((nx, nz)), np.zeros((nx, nz)), np.zeros((nx, nz))
    harmonic = lambda a, b: 2.0 * a * b / (a + b) if a + b > 0.0 else 0.0  # noqa: E731
    for i in range(nx):
        ip = (i + 1) % nx
        for j in range(nz):
            tx[i, j] = (1.0 + 0.5 * beta * (P[i, j] + P[ip, j])) * harmonic(k[i, j], k[ip, j]) * cx
            if j < nz - 1:
                tz[i, j] = (1.0 + 0.5 * beta * (P[i, j] + P[i, j + 1])) * harmonic(k[i, j], k[i, j + 1]) * cz
        tb[i, 0] += (1.0 + 0.5 * beta * P[i, 0]) * k[i, 0] * 2.0 * cz
        tb[i, nz - 1] += (1.0 + 0.5 * beta * P[i, nz - 1]) * k[i, nz - 1] * 2.0 * cz
    return tx, tz, tb


def ref_operator(p, diag, tx, tz):
    nx, nz = p.shape
    q = np.empty((nx, nz))
    for i in range(nx):
        ip, im = (i + 1) % nx, (i - 1) % nx
        for j in range(nz):
            v = diag[i, j] * p[i, j] - tx[i, j] * p[ip, j] - tx[im, j] * p[im, j]
            if j < nz - 1:
                v -= tz[i, j] * p[i, j + 1]
            if j > 0:
                v -= tz[i, j - 1] * p[i, j - 1]
            q[i, j] = v
    return q


def ref_system(cap, tx, tz, tb, dt_f, p_star):
    nx, nz = cap.shape
    diag, P, rhs = np.empty((nx, nz)), np.empty((nx, nz)), p_star.copy()
    for i in range(nx):
        im = (i - 1) % nx
        for j in range(nz):
            c = cap[i, j] / dt_f
            d = c + tx[i, j] + tx[im, j] + tb[i, j] + tz[i, j]
            if j > 0:
                d += tz[i, j - 1]
            diag[i, j] = d
            P[i, j] = rhs[i, j]
            rhs[i, j] *= c
    return diag, P, rhs


def ref_line_solve(diag, tz, r):
    """Thomas algorithm down each column (the z-line preconditioner's definition)."""
    nx, nz = r.shape
    out, cp, dinv = np.empty((nx, nz)), np.empty((nx, nz)), np.empty((nx, nz))
    for i in range(nx):
        dinv[i, 0] = 1.0 / diag[i, 0]
        cp[i, 0] = -tz[i, 0] * dinv[i, 0]
        out[i, 0] = r[i, 0] * dinv[i, 0]
        for j in range(1, nz):
            dinv[i, j] = 1.0 / (diag[i, j] + tz[i, j - 1] * cp[i, j - 1])
            cp[i, j] = -tz[i, j] * dinv[i, j]
            out[i, j] = (r[i, j] + tz[i, j - 1] * out[i, j - 1]) * dinv[i, j]
        for j in range(nz - 2, -1, -1):
            out[i, j] -= cp[i, j] * out[i, j + 1]
    return out


def ref_gradient(P, dx, dz, p_bot, p_top):
    nx, nz = P.shape
    gx, gz = np.empty((nx, nz)), np.empty((nx, nz))
    for i in range(nx):
        ip, im = (i + 1) % nx, (i - 1) % nx
        for j in range(nz):
            gx[i, j] = (P[ip, j] - P[im, j]) / (2.0 * dx)
            below = (P[i, 0] - p_bot) / (0.5 * dz) if j == 0 else (P[i, j] - P[i, j - 1]) / dz
            above = (p_top - P[i, j]) / (0.5 * dz) if j == nz - 1 else (P[i, j + 1] - P[i, j]) / dz
            gz[i, j] = 0.5 * (below + above)
    return gx, gz


@settings(max_examples=60, deadline=None)
@given(shapes)
def test_faces_system_and_operator_are_the_cell_by_cell_definitions(shape):
    nx, nz, seed = shape
    rng, f = _fields(nx, nz, seed)
    dx, dz, beta, eta = 2.5, 1.7, 36.0, 1.43e-7
    tx, tz, tb = (np.full((nx, nz), np.nan) for _ in range(3))
    KP.face_conductances(f["P"], f["perm"], dx, dz, beta, eta, tx, tz, tb)
    for got, want in zip((tx, tz, tb), ref_faces(f["P"], f["perm"], dx, dz, beta, eta)):
        _same(got, want)
    assert np.all(tz[:, -1] == 0.0)

    tz0 = f["tz"].copy()
    tz0[:, -1] = 0.0                              # (as face_conductances leaves it: the kernels rely on it)
    p_star = rng.normal(0.0, 1e-3, (nx, nz))
    diag, P, rhs = np.empty((nx, nz)), np.empty((nx, nz)), p_star.copy()
    KP.implicit_system(f["cap"], f["tx"], tz0, f["tb"], 0.27, rhs, P, diag)
    for got, want in zip((diag, P, rhs), ref_system(f["cap"], f["tx"], tz0, f["tb"], 0.27, p_star)):
        _same(got, want)

    q = np.empty((nx, nz))
    KP._apply_operator(f["P"], diag, f["tx"], tz0, q)
    _same(q, ref_operator(f["P"], diag, f["tx"], tz0))


@settings(max_examples=60, deadline=None)
@given(shapes)
def test_transposed_line_solves_are_the_thomas_algorithm(shape):
    nx, nz, seed = shape
    rng, f = _fields(nx, nz, seed)
    tz = f["tz"].copy()
    tz[:, -1] = 0.0
    diag = f["cap"] + 2.0 * f["tx"] + f["tb"] + tz + np.roll(tz, 1, axis=1) * (np.arange(nz) > 0)
    r = rng.normal(0.0, 1.0, (nx, nz))
    t = (nz, nx)
    tzt, cp, dinv, line = (np.empty(t) for _ in range(4))
    KP._factor_columns(diag, tz, tzt, cp, dinv)
    out = np.empty((nx, nz))
    KP._solve_columns(r, tzt, cp, dinv, line, out)
    _same(out, ref_line_solve(diag, tz, r))
    # and it is the inverse of each column's tridiagonal block, to round-off
    for i in range(nx):
        block = np.diag(diag[i]) - np.diag(tz[i, :-1], 1) - np.diag(tz[i, :-1], -1)
        np.testing.assert_allclose(block @ out[i], r[i], rtol=1e-12, atol=1e-12 * np.abs(r[i]).max())


@settings(max_examples=60, deadline=None)
@given(shapes)
def test_gradient_density_source_and_finiteness_are_the_cell_by_cell_definitions(shape):
    nx, nz, seed = shape
    rng, f = _fields(nx, nz, seed)
    P, s = f["P"], f["s"]
    gx, gz = np.empty((nx, nz)), np.empty((nx, nz))
    KG.pressure_gradient(P, 2.5, 1.7, 1e-4, -2e-4, gx, gz)
    want_x, want_z = ref_gradient(P, 2.5, 1.7, 1e-4, -2e-4)
    _same(gx, want_x)
    _same(gz, want_z)

    s[0, 0] = 0.0                                  # an empty cell has no drag density
    pairs = np.empty(2 * nx * nz)
    KG.drag_density_pairs(gx, gz, s, pairs)
    want = np.array([[0.0, 0.0] if s[i, j] <= 0.0 else [gx[i, j] * (-1.0 / s[i, j]), gz[i, j] * (-1.0 / s[i, j])]
                     for i in range(nx) for j in range(nz)]).ravel()
    _same(pairs, want)

    s_old, ux, uz, sx, sz = (rng.uniform(0.6, 0.95, (nx, nz)) if k == 0 else rng.normal(0, 1e-2, (nx, nz))
                             for k in range(5))
    p_star, div_u = np.empty((nx, nz)), np.empty((nx, nz))
    KP.undrained_source(P, s, s_old, ux, uz, sx, sz, 0.27, 36.0, 0.1, 0.95, p_star, div_u)
    for i in range(nx):
        for j in range(nz):
            s_end = min(max(s[i, j] + 0.27 * (ux[i, j] * sx[i, j] + uz[i, j] * sz[i, j]), 0.1), 0.95)
            s_start = min(max(s_old[i, j], 0.1), 0.95)
            assert p_star[i, j] == P[i, j] + (1.0 + 36.0 * P[i, j]) * (s_end - s_start) / (
                36.0 * s_start * (1.0 - s_end))
            assert div_u[i, j] == -2.0 * (s_end - s_start) / ((s_end + s_start) * 0.27)

    assert KF._all_finite(P)
    for bad in (math.nan, math.inf, -math.inf):
        broken = P.copy()
        broken[rng.integers(nx), rng.integers(nz)] = bad
        assert not KF._all_finite(broken)


def test_work_rows_hold_the_transposed_line_arrays():
    """The z-line solves use two extra work rows, viewed (nz, nx); every named row is its own and
    within N_GRID_WORK (the drag's extrapolated pressure and the filter's scratch among them: one
    row per field it filters, the last rows)."""
    rows = [value for name, value in vars(L).items() if name.startswith("G_")]
    assert len(set(rows)) == len(rows) and max(rows) == L.G_TMP
    assert L.G_TMP + L.N_FILTER_SCRATCH == L.N_GRID_WORK
    assert L.N_FILTER_SCRATCH >= max(KF.FORWARD_FIELDS, KF.DRAG_FIELDS)
    assert len({L.G_CP, L.G_DINV, L.G_TZT, L.G_LINE, L.G_R, L.G_Z, L.G_P, L.G_Q}) == 8


@settings(max_examples=25, deadline=None)
@given(st.tuples(st.integers(1, 5), st.integers(2, 6), st.integers(0, 2**31 - 1)))
def test_deposit_on_narrow_grids_matches_the_direct_form(shape):
    """The grouped deposit (parallel and serial forms, the same bits) against the direct
    definition, on grids down to one column, where a group's arc of columns wraps onto itself."""
    from gouge_cli.kernels import deposit as KD

    nx, nz, seed = shape
    rng = np.random.default_rng(seed)
    width, z_bot, z_top, n = 3.0 * nx, 0.5, 0.5 + 2.0 * nz, 60
    x = rng.uniform(-0.2 * width, 1.2 * width, n) % width
    z = rng.uniform(z_bot - 0.3, z_top + 0.3, n)
    radius = rng.uniform(0.4, 0.6, n)
    vx, vz = rng.normal(0, 1e-3, (2, n))
    direct = [np.empty((nx, nz)) for _ in range(5)]
    _deposit(x, z, vx, vz, radius, n, width, z_bot, z_top, 1e-4, -2e-4, *direct)
    outs = []
    for serial in (False, True):
        out = [np.empty((nx, nz)) for _ in range(5)]
        _deposit(x, z, vx, vz, radius, n, width, z_bot, z_top, 1e-4, -2e-4, *out,
                   np.zeros((L.N_CORNERS, n)), np.zeros((L.DEPOSIT_GROUPS, nx * nz, L.N_MOMENTS)), None, serial)
        outs.append(out)
    for a, b, want in zip(outs[0], outs[1], direct):
        _same(a, b)
        np.testing.assert_allclose(a, want, rtol=1e-12, atol=1e-14 * max(np.abs(want).max(), 1.0))
