"""Unit tests of the pore-fluid kernels and FluidGrid (gouge_cli/kernels/deposit.py, pressure.py, drag.py, fluid_update.py; gouge_cli/model/fluid.py)."""

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gouge_cli.config import FluidConfig
from needs import skip_unless_two_threads
from gouge_cli.model.fluid import FluidGrid
from gouge_cli.kernels import layout as L
from gouge_cli.kernels import deposit as KD
from gouge_cli.kernels import deposit_weights as KW
from gouge_cli.kernels import drag as KG
from gouge_cli.kernels import fluid_update as KF
from gouge_cli.kernels import pressure as KP


def _deposit(x, z, vx, vz, radius, n, width, z_bot, z_top, w_bot, w_top, s, ux, uz, gx, gz, *rest):
    """kernels.deposit.deposit with its records (layout.Discs, Planes, Deposited) made of plain arrays."""
    planes = L.Planes(float(z_bot), float(z_top), float(w_bot), float(w_top))
    KD.deposit(L.Discs(x, z, vx, vz, radius), n, width, planes, L.Deposited(s, ux, uz, gx, gz), *rest)


def numeric_cap(h, r):
    zz = np.linspace(-r, r, 200001)
    chord = 2.0 * np.sqrt(np.maximum(r * r - zz * zz, 0.0))
    return np.trapezoid(np.where(zz > h, chord, 0.0), zz)


def test_segment_and_in_domain_area():
    r = 0.6
    assert KW.segment_area(r, r) == 0.0
    assert KW.segment_area(-r, r) == pytest.approx(math.pi * r * r)
    assert KW.segment_area(0.0, r) == pytest.approx(0.5 * math.pi * r * r)
    assert KW.segment_area(0.23, r) == pytest.approx(numeric_cap(0.23, r), rel=1e-4)
    assert KW.in_domain_area(5.0, r, 0.0, 10.0) == pytest.approx(math.pi * r * r)
    assert KW.in_domain_area(0.0, r, 0.0, 10.0) == pytest.approx(0.5 * math.pi * r * r)
    assert KW.in_domain_area(10.0 + r, r, 0.0, 10.0) == pytest.approx(0.0, abs=1e-15)
    assert KW.in_domain_area(10.0 + 2 * r, r, 0.0, 10.0) == 0.0
    assert KW.in_domain_area(-0.1, r, 0.0, 10.0) == pytest.approx(numeric_cap(0.1, r), rel=1e-4)


def test_cell_weights_periodic_and_clamped():
    i0, i1, j0, fx, fz, slope = KW.cell_weights(-0.25, 0.0, 1.0, 1.0, 0.0, 4, 3)
    assert (i0, i1) == (3, 0) and fx == pytest.approx(0.25)
    assert (j0, fz, slope) == (0, 0.0, 0.0)
    i0, i1, j0, fx, fz, slope = KW.cell_weights(8.5, 2.9, 1.0, 1.0, 0.0, 4, 3)
    assert (i0, i1, fx) == (0, 1, 0.0)
    assert (j0, fz, slope) == (1, 1.0, 0.0)
    _, _, j0, _, fz, slope = KW.cell_weights(0.5, 1.25, 1.0, 0.5, 0.0, 4, 3)
    assert (j0, fz, slope) == (0, pytest.approx(0.125), 0.5)


def _grains(seed=0, n=130, width=12.0, z_bot=0.5, z_top=10.5):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, width, n)
    z = rng.uniform(z_bot - 0.3, z_top + 0.3, n)
    radius = rng.uniform(0.4, 0.6, n)
    return x, z, radius


def test_grouped_deposit_and_cached_drag():
    """The grouped (parallel) deposit equals the serial pass to round-off and gives the same bits
    for 1 and 2 threads, and stopped after the groups (finish=False) then finished by
    deposit_finish on one thread; the drag from the cached corner cells equals grain_drag bit
    for bit."""
    import numba

    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains(seed=3, n=400)
    z[:3] = z_top + 1.0                         # outside the layer: no deposit, no drag
    rng = np.random.default_rng(4)
    vx, vz = rng.normal(0, 1e-3, x.size), rng.normal(0, 1e-3, x.size)
    serial = [np.empty((5, 4)) for _ in range(5)]
    _deposit(x, z, vx, vz, radius, x.size, width, z_bot, z_top, 1e-4, -2e-4, *serial)
    grouped = []
    corners = np.zeros((L.N_CORNERS, x.size))
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        numba.set_num_threads(threads)
        out = [np.empty((5, 4)) for _ in range(5)]
        partial = np.zeros((L.DEPOSIT_GROUPS, 20, L.N_MOMENTS))
        _deposit(x, z, vx, vz, radius, x.size, width, z_bot, z_top, 1e-4, -2e-4, *out, corners, partial)
        grouped.append(out)
        later = [np.full((5, 4), np.nan) for _ in range(5)]
        _deposit(x, z, vx, vz, radius, x.size, width, z_bot, z_top, 1e-4, -2e-4, *later, corners, partial,
                   None, False, False)
        assert all(np.isnan(a).all() for a in later)          # nothing expanded yet
        KD.deposit_finish(width, z_bot, z_top, L.Deposited(*later), partial)
        grouped.append(later)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    for other in grouped[1:]:
        for a, b in zip(grouped[0], other):
            assert a.tobytes() == b.tobytes()
    for a, b in zip(serial, grouped[0]):
        assert np.allclose(a, b, rtol=1e-13, atol=1e-15 * np.abs(a).max())
    assert np.sum(corners[L.CR_CELL] < 2.0 ** 52) == np.sum([KW.in_domain_area(zk, rk, z_bot, z_top) <= 0
                                             for zk, rk in zip(z, radius)]) > 0
    gx, gz = rng.normal(size=(2, 5, 4))
    s = rng.uniform(-0.2, 1.0, (5, 4))          # some cells without solid: zero density there
    fx, fz = np.empty((2, 5, 4))
    KG.drag_density(gx, gz, s, fx, fz)
    pairs = np.empty(2 * 20)
    KG.drag_density_pairs(gx, gz, s, pairs)     # the same bits, interleaved (x, z) per cell
    assert pairs[0::2].tobytes() == fx.tobytes() and pairs[1::2].tobytes() == fz.tobytes() and np.any(fx == 0)
    expected = np.zeros((2, x.size))
    cached = np.zeros((2, x.size))
    KG.grain_drag(x, z, radius, x.size, width, z_bot, z_top, fx, fz, expected[0], expected[1])
    KG.grain_drag_at(corners, x.size, 4, pairs, cached[0], cached[1])
    assert expected.tobytes() == cached.tobytes() and np.abs(expected).max() > 0
    cells = corners[L.CR_CELL].view(np.int64) - L.CELL_BITS  # the coded cell row: c00 as float and as bits
    inside = cells >= 0
    assert cells[inside].tolist() == (corners[L.CR_CELL][inside] - 2.0 ** 52).astype(np.int64).tolist()
    assert np.any(cells >= 16) and np.all(cells[~inside] == -2) and np.sum(~inside) == 3   # (c10 wraps at 16-19)
    skip_unless_two_threads("the grouped deposit on 2 threads")


def test_grouped_deposit_reuses_its_scratch_and_takes_owed_kicks():
    """partial is reused between calls (only the columns a group touched are cleared): a deposit
    after one from grains elsewhere gives the bits of a fresh scratch. With grain_kick, the
    velocities are the whole-step ones (closing half kick for free grains, the wall velocity
    for top-wall grains, bottom-wall grains as stored): the bits of closing first. The serial
    form (one thread: plain loops) gives the same bits
    as the parallel one, whatever either left in the scratch."""

    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains(seed=5, n=400)
    rng = np.random.default_rng(6)
    vx, vz, fx, fz = rng.normal(0, 1e-3, (4, x.size))
    inv_mass = rng.uniform(1.0, 3.0, x.size)
    body = np.zeros(x.size, np.int8)
    body[:20] = L.TOP
    body[20:40] = L.BOTTOM
    half, damp, wall_v = 0.05, 0.3, (2e-3, -1e-3)

    def run(partial, xs, grain_kick=None, u=vx, w=vz, serial=False):
        out = [np.empty((5, 4)) for _ in range(5)]
        corners = np.zeros((L.N_CORNERS, x.size))
        _deposit(xs, z, u, w, radius, x.size, width, z_bot, z_top, 1e-4, -2e-4, *out, corners, partial,
                        grain_kick, serial)
        return b"".join(a.tobytes() for a in out)

    fresh = run(np.zeros((L.DEPOSIT_GROUPS, 20, L.N_MOMENTS)), x)
    reused = np.zeros((L.DEPOSIT_GROUPS, 20, L.N_MOMENTS))
    elsewhere = np.sort(x)[::-1] + 0.37 * width            # groups in other columns first
    run(reused, elsewhere)
    assert run(reused, x) == fresh
    for first, then in ((True, True), (False, True), (True, False)):
        run(reused, elsewhere, serial=first)
        assert run(reused, x, serial=then) == fresh
    banded = np.sort(x)                                     # groups in bands of columns, as in a run
    assert run(reused, banded, serial=True) == run(np.zeros_like(reused), banded) != fresh
    closed_x, closed_z = vx.copy(), vz.copy()
    free = body == L.FREE
    closed_x[free] = vx[free] + half * (fx[free] * inv_mass[free] - damp * vx[free])
    closed_z[free] = vz[free] + half * (fz[free] * inv_mass[free] - damp * vz[free])
    closed_x[body == L.TOP], closed_z[body == L.TOP] = wall_v
    partial = np.zeros((L.DEPOSIT_GROUPS, 20, L.N_MOMENTS))
    owed = run(partial, x, (True, fx, fz, inv_mass, body, half, damp, *wall_v))
    assert owed == run(partial, x, u=closed_x, w=closed_z) != fresh
    assert run(partial, x, (True, fx, fz, inv_mass, body, half, damp, *wall_v), serial=True) == owed
    assert run(partial, x, (False, fx, fz, inv_mass, body, half, damp, *wall_v)) == fresh


def test_deposit_conserves_area_and_is_periodic():
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    v = np.full(x.size, 2e-3)
    s, ux, uz, gx, gz = (np.empty((5, 4)) for _ in range(5))
    _deposit(x, z, v, -v, radius, x.size, width, z_bot, z_top, 0.0, 0.0, s, ux, uz, gx, gz)
    cell_area = width / 5 * (z_top - z_bot) / 4
    total = sum(KW.in_domain_area(zk, rk, z_bot, z_top) for zk, rk in zip(z, radius))
    assert (s * cell_area).sum() == pytest.approx(total, rel=1e-12)
    np.testing.assert_allclose(ux, 2e-3, rtol=1e-12)
    np.testing.assert_allclose(uz, -2e-3, rtol=1e-12)
    shifted = np.empty_like(s)
    _deposit(x + width, z, v, -v, radius, x.size, width, z_bot, z_top, 0.0, 0.0, shifted, ux, uz, gx, gz)
    np.testing.assert_allclose(shifted, s, rtol=1e-12)


def test_solid_fraction_gradient_is_the_derivative_of_the_deposit():
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    inside = (z > z_bot + 0.6) & (z < z_top - 0.6)
    x, z, radius = x[inside], z[inside], radius[inside]
    v = np.zeros_like(x)
    s, ux, uz, gx, gz = (np.empty((5, 4)) for _ in range(5))
    _deposit(x, z, v, v, radius, x.size, width, z_bot, z_top, 0.0, 0.0, s, ux, uz, gx, gz)
    shift = 1e-7
    for dxk, dzk, slope in ((shift, 0.0, gx), (0.0, shift, gz)):
        s_plus, s_minus = np.empty((5, 4)), np.empty((5, 4))
        scratch = [np.empty((5, 4)) for _ in range(4)]
        _deposit(x + dxk, z + dzk, v, v, radius, x.size, width, z_bot, z_top, 0.0, 0.0, s_plus, *scratch)
        _deposit(x - dxk, z - dzk, v, v, radius, x.size, width, z_bot, z_top, 0.0, 0.0, s_minus, *scratch)
        # moving every grain by +delta is moving the cells by -delta; grad_z s is that of the
        # mirror-extended deposit: a grain between a plane and the boundary centre adds -+2/dz its
        # x weights in the boundary row (its clamped weights do not vary with z)
        derivative = -(s_plus - s_minus) / (2 * shift)
        if dzk:
            dx, dz = width / 5, (z_top - z_bot) / 4
            for xk, zk, rk in zip(x, z, radius):
                zeta = (zk - z_bot) / dz - 0.5
                if 0.0 <= zeta < 3.0:
                    continue
                row, mu = (0, -2.0 / dz) if zeta < 0.0 else (3, 2.0 / dz)
                xi = xk / dx - 0.5
                fx = xi - np.floor(xi)
                i0 = int(np.floor(xi)) % 5
                area = KW.in_domain_area(zk, rk, z_bot, z_top) / (dx * dz)
                derivative[i0, row] += mu * area * (1 - fx)
                derivative[(i0 + 1) % 5, row] += mu * area * fx
        np.testing.assert_allclose(derivative, slope, atol=1e-6)


def test_deposit_velocity_is_relative_to_the_stretching_grid():
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    rate = 1e-3
    vz = rate * (z - z_bot)
    s, ux, uz, gx, gz = (np.empty((5, 4)) for _ in range(5))
    _deposit(x, z, 0 * x, vz, radius, x.size, width, z_bot, z_top, 0.0, rate * (z_top - z_bot),
                    s, ux, uz, gx, gz)
    assert np.abs(uz).max() < 1e-15


def _random_system(nx=7, nz=5, seed=1):
    rng = np.random.default_rng(seed)
    beta, eta = 36.0, 1.43e-7
    s = rng.uniform(0.7, 0.9, (nx, nz))
    pressure = rng.normal(0, 1e-3, (nx, nz))
    perm = np.empty((nx, nz))
    capacity = np.empty((nx, nz))
    KP.permeability_field(s, 1e-3, 0.05, 0.9, perm, capacity, beta)
    tx, tz, tb = (np.empty((nx, nz)) for _ in range(3))
    KP.face_conductances(pressure, perm, 2.0, 1.7, beta, eta, tx, tz, tb)
    return pressure, capacity, tx, tz, tb


def _sparse_operator(capacity_over_dt, tx, tz, tb):
    nx, nz = tx.shape
    idx = np.arange(nx * nz).reshape(nx, nz)
    rows, cols, vals = [], [], []
    for i in range(nx):
        for j in range(nz):
            neighbours = [((i + 1) % nx, j, tx[i, j]), ((i - 1) % nx, j, tx[(i - 1) % nx, j])]
            if j < nz - 1:
                neighbours.append((i, j + 1, tz[i, j]))
            if j > 0:
                neighbours.append((i, j - 1, tz[i, j - 1]))
            diag = capacity_over_dt[i, j] + tb[i, j]
            for a, b, t in neighbours:
                diag += t
                rows.append(idx[i, j]); cols.append(idx[a, b]); vals.append(-t)
            rows.append(idx[i, j]); cols.append(idx[i, j]); vals.append(diag)
    return sp.csr_matrix((vals, (rows, cols)), shape=(nx * nz, nx * nz))


def test_conjugate_gradient_matches_sparse_direct_solve():
    pressure, capacity, tx, tz, tb = _random_system()
    nx, nz = pressure.shape
    dt = 50.0
    matrix = _sparse_operator(capacity / dt, tx, tz, tb)
    assert abs(matrix - matrix.T).max() == 0.0
    diag = matrix.diagonal().reshape(nx, nz).copy()
    rhs = capacity / dt * pressure
    solution = pressure.copy()
    work = np.zeros((L.N_GRID_WORK, nx, nz))
    iterations, residual, converged = KP.conjugate_gradient(solution, rhs, diag, tx, tz, work, 1e-12, 500)
    assert converged and residual <= 1e-12 and iterations > 1
    exact = spla.spsolve(matrix.tocsc(), rhs.ravel()).reshape(nx, nz)
    np.testing.assert_allclose(solution, exact, rtol=1e-9, atol=1e-9 * np.abs(exact).max())


def test_explicit_diffusion_matches_implicit_for_small_steps():
    pressure, capacity, tx, tz, tb = _random_system()
    bound = KP.explicit_bound(capacity, tx, tz, tb)
    total = 20 * bound
    explicit = pressure.copy()
    KP.explicit_diffusion(explicit, capacity, tx, tz, tb, total / 4000, 4000, np.empty_like(pressure),
                          np.empty_like(pressure))
    matrix = _sparse_operator(capacity / total * 0, tx, tz, tb).toarray()
    from scipy.linalg import expm

    c_inv = np.diag(1.0 / capacity.ravel())
    exact = (expm(-total * c_inv @ matrix) @ pressure.ravel()).reshape(pressure.shape)
    np.testing.assert_allclose(explicit, exact, atol=1e-3 * np.abs(pressure).max())


def _one_step_errors(ratio, seed):
    """Heun (heun_diffusion, the auto solver's explicit step), backward Euler (CG to 1e-13) and the
    exact exp(-dt C^-1 L) P over one step of dt = ratio x the FTCS bound, on a random system;
    returns the L2 errors of the two schemes and dt lambda_max."""
    from scipy.linalg import expm

    pressure, capacity, tx, tz, tb = _random_system(seed=seed)
    dt = ratio * KP.explicit_bound(capacity, tx, tz, tb)
    heun = pressure.copy()
    KP.heun_diffusion(heun, capacity, tx, tz, tb, dt, *(np.empty_like(pressure) for _ in range(4)))
    backward = pressure.copy()
    rhs = capacity / dt * pressure
    diag = _sparse_operator(capacity / dt, tx, tz, tb).diagonal().reshape(pressure.shape).copy()
    work = np.zeros((L.N_GRID_WORK,) + pressure.shape)
    assert KP.conjugate_gradient(backward, rhs, diag, tx, tz, work, 1e-13, 500)[2]
    c_inv_l = np.diag(1.0 / capacity.ravel()) @ _sparse_operator(0 * capacity, tx, tz, tb).toarray()
    exact = (expm(-dt * c_inv_l) @ pressure.ravel()).reshape(pressure.shape)
    lam = np.linalg.eigvals(c_inv_l).real.max()
    return np.linalg.norm(heun - exact), np.linalg.norm(backward - exact), dt * lam


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_auto_threshold_heun_step_more_accurate_than_backward_euler(seed):
    """The auto solver's explicit step (Heun, dt_f <= AUTO_EXPLICIT x the FTCS bound, so dt lambda
    <= 0.5 for every mode) errs less than backward Euler: per mode ~x^3/6 against ~x^2/2, 0.0185
    against 0.060 at x = 0.5, so within 0.4x at the threshold and 0.1x at a tenth of it (the error
    ratio falls as x). At twice the FTCS bound (x up to 4) Heun is unstable and far worse, so the
    test tells the schemes apart."""
    heun, backward, x = _one_step_errors(L.AUTO_EXPLICIT, seed)
    assert 0.05 < x <= 0.5 + 1e-12
    assert backward > 0 and heun <= 0.4 * backward
    heun, backward, _ = _one_step_errors(L.AUTO_EXPLICIT / 10, seed)
    assert 0 < heun <= 0.1 * backward
    heun, backward, _ = _one_step_errors(2.0, seed)
    assert heun > 3 * backward


def test_auto_solver_picks_explicit_only_within_threshold():
    """fluid_update with solver auto: one Heun step (no CG iteration, S_EXPLICIT_UPDATES counts it)
    where dt_f <= AUTO_EXPLICIT x the FTCS bound, backward Euler (CG iterations, the implicit
    solver's bits) above it; the Heun pressure agrees with the implicit one to the latter's
    time-stepping error."""
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    rng = np.random.default_rng(4)
    vz = rng.normal(0.0, 1e-3, x.size)
    v = np.zeros_like(x)
    for kappa, dt_f, explicit in ((1e-6, 0.25, True), (1e-3, 0.25, False)):
        results = {}
        for solver in ("auto", "implicit"):
            grid = FluidGrid(5, 4, width, z_bot, z_top, x.size, kappa, 36.0, 1.43e-7, solver=solver)
            assert grid.init(x, z, v, v, radius, z_bot, z_top) == L.STATUS_OK
            z1 = z + vz * dt_f
            assert grid.update(x, z1, v, vz, radius, z_bot, z_top, dt_f) == L.STATUS_OK
            results[solver] = grid.pressure.copy()
            if solver == "auto":
                assert (dt_f <= L.AUTO_EXPLICIT * grid.state[L.S_DT_MAX]) == explicit
                assert grid.state[L.S_EXPLICIT_UPDATES] == (1.0 if explicit else 0.0)
                assert (grid.state[L.S_ITERATIONS] == 0) == explicit
        scale = np.abs(results["implicit"]).max()
        assert scale > 0
        if explicit:
            np.testing.assert_allclose(results["auto"], results["implicit"], atol=1e-2 * scale)
        else:
            assert np.array_equal(results["auto"], results["implicit"])


def test_explicit_bound_is_the_exact_largest_cell_bound():
    """The largest cell bound, found through the integer order of the bits, is the float maximum
    exactly: with every bound positive, with some negative (1 + beta P < 0 on a face), and with
    none positive (no diffusion: inf)."""
    nx, nz = 7, 5
    rng = np.random.default_rng(12)
    capacity = rng.uniform(0.5, 2.0, (nx, nz))
    tx, tz, tb = rng.uniform(0.0, 1e3, (3, nx, nz))
    tz[:, -1] = 0.0

    def bounds():
        rates = np.empty(nx * nz)
        for c in range(nx * nz):
            i, j = divmod(c, nz)
            faces = tx[i, j] + tx[i - 1, j] + tz[i, j] + (tz[i, j - 1] if j > 0 else 0.0)
            rates[c] = (2.0 * faces + tb[i, j]) / capacity[i, j]
        return rates

    for case in ("positive", "mixed", "none"):
        if case == "mixed":
            tb[2, 0] = -1e6
            tb[4, 4] = -3e5
        if case == "none":
            tx[:], tz[:], tb[:] = 0.0, 0.0, -1.0
        rates = bounds()
        scratch = np.empty((nx, nz))
        got = KP.explicit_bound(capacity, tx, tz, tb, scratch)
        assert got == (2.0 / rates.max() if rates.max() > 0 else math.inf), case
        assert KP.explicit_bound(capacity, tx, tz, tb) == got
        if case == "mixed":
            assert rates.min() < 0 < rates.max()


def test_explicit_bound_equals_ftcs_formula_for_uniform_diffusivity():
    nx, nz, dx, dz = 6, 5, 2.0, 1.5
    beta, eta, kappa_c, phi = 36.0, 1.43e-7, 1e-5, 0.15
    s = np.full((nx, nz), 1 - phi)
    perm, capacity = np.empty((nx, nz)), np.empty((nx, nz))
    KP.permeability_field(s, kappa_c, 0.05, 0.9, perm, capacity, beta)
    tx, tz, tb = (np.empty((nx, nz)) for _ in range(3))
    KP.face_conductances(np.zeros((nx, nz)), perm, dx, dz, beta, eta, tx, tz, tb)
    diffusivity = kappa_c * phi**3 / (1 - phi) ** 2 / (eta * beta * phi)
    assert diffusivity == pytest.approx(0.0605, rel=1e-3)
    formula = 1.0 / (2.0 * diffusivity * (1 / dx**2 + 1 / dz**2))
    assert KP.explicit_bound(capacity, tx, tz, tb) == pytest.approx(formula, rel=1e-12)
    grid = FluidGrid(nx, nz, nx * dx, 0.0, nz * dz, 1, kappa_c, beta, eta)
    grid.permeability[:] = perm
    grid.solid_fraction[:] = 1 - phi
    assert grid.explicit_bound() == pytest.approx(formula, rel=1e-12)
    assert grid.deborah(10.0, 1e-3) == pytest.approx(10.0 * 1e-3 / diffusivity, rel=1e-12)


def test_from_config_and_kernel_args():
    grid = FluidGrid.from_config(FluidConfig(cell_size=2.5), 200.0, 1.0, 51.0, 10_000)
    assert (grid.nx, grid.nz) == (80, 20)
    assert grid.pressure.shape == (80, 20) and grid.drag_x.shape == (10_000,)
    assert grid.params[L.P_KAPPA_C] == 1e-5
    assert grid.params[L.P_SOLVER] == L.SOLVER_AUTO
    assert grid.params[L.P_FILTER_WIDTH] == FluidConfig().filter_width
    assert len(grid.kernel_args()) == 3 and len(grid.record()) == len(L.FluidArrays._fields)
    default = FluidGrid.from_config(FluidConfig(filter_width=4.0), 200.0, 1.0, 51.0, 10)   # h = w / 2
    assert (default.nx, default.nz) == (100, 25)
    assert default.taps_x.shape == (100,) and default.bands_z.shape == (3, 49, 25)
    thin = FluidGrid.from_config(FluidConfig(cell_size=20.0, filter_width=20.0), 5.0, 0.0, 3.0, 4)
    assert (thin.nx, thin.nz) == (1, 2)
    explicit = FluidGrid.from_config(FluidConfig(solver="explicit"), 20.0, 0.0, 10.0, 4)
    assert explicit.params[L.P_SOLVER] == L.SOLVER_EXPLICIT
    for g in (grid, thin):                      # the moment records start on cache lines, zeroed
        assert g.partial.ctypes.data % 64 == 0 and g.partial.flags.c_contiguous and not g.partial.any()
        assert g.partial.shape == (L.DEPOSIT_GROUPS, g.nx * g.nz, L.N_MOMENTS)


def test_status_codes():
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    v = np.zeros_like(x)
    grid = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-3, 36.0, 1.43e-7, solver="explicit", max_substeps=2)
    assert grid.init(x, z, v, v, radius, z_bot, z_top) == L.STATUS_OK
    grid.pressure[:] = 1e-5
    assert grid.update(x, z, v, v, radius, z_bot, z_top, 1e4) == L.STATUS_SOLVER
    assert grid.state[L.S_SUBSTEPS] > 2
    assert grid.update(x, z, v, v, radius, z_bot, z_top, -1.0) == L.STATUS_SOLVER
    bad = v.copy()
    bad[3] = np.nan
    grid = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-3, 36.0, 1.43e-7)
    grid.init(x, z, v, v, radius, z_bot, z_top)
    assert grid.update(x, z, bad, v, radius, z_bot, z_top, 1.0) == L.STATUS_NONFINITE
    assert np.abs(grid.drag_x).max() == 0.0
    for position, expected in ((np.nan, L.STATUS_NONFINITE), (np.inf, L.STATUS_OK),
                               (-np.inf, L.STATUS_OK)):
        lost = z.copy()
        lost[5] = position
        grid = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-3, 36.0, 1.43e-7)
        grid.init(x, z, v, v, radius, z_bot, z_top)
        # a grain at infinite distance has no area in the layer and is ignored
        assert grid.update(lost, lost, v, v, radius, z_bot, z_top, 1.0) == expected


def test_fluid_update_callable_from_njit():
    from numba import njit

    @njit
    def loop(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, steps, *args):
        status = KF.fluid_init(x, z, vx, vz, radius, n, Lx, z_bot, z_top, *args)
        for _ in range(steps):
            status = max(status, KF.fluid_update(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, *args))
        return status

    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    v = np.zeros_like(x)
    grid = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-5, 36.0, 1.43e-7)
    assert loop(x, z, v, v, radius, x.size, width, z_bot, z_top, 1.0, 3, *grid.kernel_args()) == 0
    assert grid.state[L.S_UPDATES] == 3


def test_restart_from_checkpoint_arrays_is_bit_for_bit():
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    rng = np.random.default_rng(5)
    vx, vz = rng.normal(0, 1e-3, x.size), rng.normal(0, 1e-3, x.size)

    def step(grid, k):
        top = z_top - 1e-3 * k
        return grid.update(x + vx * k, z + vz * k, vx, vz, radius, z_bot, top, 1.0)

    straight = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-4, 36.0, 1.43e-7)
    straight.init(x, z, vx, vz, radius, z_bot, z_top)
    for k in range(1, 4):
        step(straight, k)
    saved = straight.arrays()
    for k in range(4, 7):
        step(straight, k)
    restarted = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-4, 36.0, 1.43e-7)
    restarted.restore(saved)
    for k in range(4, 7):
        step(restarted, k)
    for name, array in straight.arrays().items():
        np.testing.assert_array_equal(restarted.arrays()[name], array)
    assert np.abs(straight.pressure).max() > 0.0
    other_count = FluidGrid(6, 5, width, z_bot, z_top, x.size, 1e-4, 36.0, 1.43e-7)
    other_count.restore(saved)
    assert other_count.pressure.shape == (5, 4) and other_count.work.shape[1:] == (5, 4)
    with pytest.raises(ValueError, match="grains"):
        FluidGrid(5, 4, width, z_bot, z_top, x.size + 1, 1e-4, 36.0, 1.43e-7).restore(saved)


def test_observe_snapshot_and_failure_messages():
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains()
    vx = np.full(x.size, 2e-3)
    grid = FluidGrid(5, 4, width, z_bot, z_top, x.size, 1e-5, 36.0, 1.43e-7)
    grid.init(x, z, vx, 0 * vx, radius, z_bot, z_top)
    row = grid.observe(-7e-4, vx, 0 * vx)
    assert set(row) == {"pressure_mean", "pressure_min", "pressure_max", "deborah", "deborah_grid", "fluid_energy",
                        "drag_power", "fluid_updates", "explicit_updates"}
    assert row["drag_power"] == pytest.approx(float(np.dot(grid.drag_x, vx)), rel=1e-12)
    assert row["fluid_updates"] == row["explicit_updates"] == 0.0
    assert row["deborah"] == pytest.approx(5.0 * 7e-4 / grid.mean_diffusivity())       # the wall's speed
    assert row["deborah_grid"] == pytest.approx(5.0 * 2e-3 / grid.mean_diffusivity())  # the grid's largest
    fields = grid.snapshot_fields()
    assert fields["pressure"].shape == fields["porosity"].shape == (5, 4)
    for status in (1, 2, 7):
        cause, fix = grid.failure(status)
        assert cause and fix


def test_near_plane_area_matches_the_closed_form():
    """A disc centred on a plane to within NEAR_PLANE R (a wall grain) gets R (pi R/2 + 2h) on its
    centre's side: against R^2 (pi - acos u + u sqrt(1 - u^2)) (no cancellation there, so the closed
    form is good to ~1 ulp) within 3 ulp of R^2 pi/2, for either plane; across the threshold the
    near form and the closed one (atan2, sin) agree as closely."""
    r, z_bot, z_top = 0.47, 0.5, 10.5
    ulp = np.spacing(0.5 * math.pi * r * r)

    def side(u):                   # the closed form
        return r * r * (math.pi - math.acos(u) + u * math.sqrt(1.0 - u * u))

    for u in (0.0, 1e-14, -6e-14, 3e-10, -2.5e-9, 1e-8, -1e-8):
        z = z_bot + u * r
        assert abs(KW.in_domain_area(z, r, z_bot, z_top) - side((z - z_bot) / r)) <= 3 * ulp, u
        z = z_top - u * r
        assert abs(KW.in_domain_area(z, r, z_bot, z_top) - side((z_top - z) / r)) <= 3 * ulp, u
    limit = KW.NEAR_PLANE * r
    beyond = np.nextafter(limit, 1.0)
    assert abs(limit) <= KW.NEAR_PLANE * r < abs(beyond)
    near, closed = KW.in_domain_area(z_bot + limit, r, z_bot, z_top), KW.in_domain_area(z_bot + beyond, r, z_bot, z_top)
    assert abs(near - closed) <= 3 * ulp


def test_wall_grains_take_the_vector_path_with_the_bits_of_grain_area():
    """Grains centred on a plane to within NEAR_PLANE R (the wall grains) and grains cutting a plane
    elsewhere: the corners (cells, areas, slopes) of the fast deposit equal grain_area,
    cell_weights and corner_shares bit for bit, so the drag from them equals grain_drag's bits."""
    width, z_bot, z_top = 12.0, 0.5, 10.5
    x, z, radius = _grains(seed=7, n=300)
    z[:40] = z_bot + radius[:40] * np.linspace(-1e-8, 1e-8, 40)     # on the bottom plane (+-NEAR_PLANE R)
    z[40:60] = z_top + radius[40:60] * np.r_[np.linspace(-1e-8, 1e-8, 10), np.linspace(-0.5, 0.5, 10)]
    z[60:70] = z_bot + np.linspace(-0.3, 0.3, 10)                      # cutting it off-centre: scalar path
    v = np.zeros_like(x)
    corners = np.zeros((L.N_CORNERS, x.size))
    out = [np.empty((5, 4)) for _ in range(5)]
    _deposit(x, z, v, v, radius, x.size, width, z_bot, z_top, 0.0, 0.0, *out, corners,
               np.zeros((L.DEPOSIT_GROUPS, 20, L.N_MOMENTS)), None, True)
    for k in range(70):
        area = KW.grain_area(z[k], radius[k], z_bot, z_top)
        i0, i1, j0, fx, fz, slope = KW.cell_weights(x[k], z[k], 5 / width, 4 / (z_top - z_bot), z_bot, 5, 4)
        c00, c10, _, _, *shares = KW.corner_shares(area, i0, i1, j0, fx, fz, 4)
        assert list(corners[[L.CR_A00, L.CR_A10, L.CR_A01, L.CR_A11, L.CR_DFZ], k]) == [*shares, slope], k
        assert corners[L.CR_CELL].view(np.int64)[k] - L.CELL_BITS == c00 and c10 == (c00 + 4) % 20, k
    u = (z[0] - z_bot) / radius[0]                                 # -1e-8: a little less than half inside
    assert KW.grain_area(z[0], radius[0], z_bot, z_top) == pytest.approx(radius[0] ** 2 * (0.5 * math.pi + 2 * u),
                                                                        rel=1e-15)
    pairs = np.random.default_rng(9).normal(size=2 * 20)
    expected, cached = np.zeros((2, x.size)), np.zeros((2, x.size))
    KG.grain_drag(x, z, radius, x.size, width, z_bot, z_top, pairs[0::2].reshape(5, 4).copy(),
                  pairs[1::2].reshape(5, 4).copy(), expected[0], expected[1])
    KG.grain_drag_at(corners, x.size, 4, pairs, cached[0], cached[1])
    assert expected.tobytes() == cached.tobytes()
