"""Validation of the pore-fluid grid against analytic results (physics.md section 7).

Terzaghi consolidation (order of convergence measured), the undrained response
to an affine compaction, the sign of the source, and the drag identities.
Dimensionless units (d = E = rho_s = 1); beta = 36, eta = 1.43e-7 as in Table 1.
"""

import numpy as np
import pytest

from gouge_cli.config import FluidConfig
from gouge_cli.model.fluid import FluidGrid
from gouge_cli.kernels import layout as L
from gouge_cli.kernels import deposit_weights as KW
from gouge_cli.kernels import drag as KG

BETA = 36.0
ETA = 1.43e-7


def lattice(nx_sites, nz_sites, spacing, z_bot, porosity):
    """Two coincident discs on every site of a square lattice with layers at half offsets.

    Each site carries solid area (1 - porosity) spacing^2 and every disc stays
    clear of the wall planes, so with an integer number of sites per cell the
    bilinear deposit gives the same solid fraction 1 - porosity in every cell.
    """
    xs = (np.arange(nx_sites) + 0.5) * spacing
    zs = z_bot + (np.arange(nz_sites) + 0.5) * spacing
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    x = np.repeat(X.ravel(), 2)
    z = np.repeat(Z.ravel(), 2)
    radius = np.full(x.size, spacing * np.sqrt((1.0 - porosity) / (2.0 * np.pi)))
    return x, z, radius


def terzaghi_mean(T, terms=4000):
    m = np.arange(1, 2 * terms, 2)
    return float(np.sum(8.0 / (m * np.pi) ** 2 * np.exp(-(m * np.pi) ** 2 * T)))


def terzaghi_profile(T, zeta, terms=4000):
    m = np.arange(1, 2 * terms, 2)
    return float(np.sum(4.0 / (m * np.pi) * np.sin(m * np.pi * zeta) * np.exp(-(m * np.pi) ** 2 * T)))


TERZAGHI_T = (0.01, 0.05, 0.1, 0.2, 0.5)
TABLE_MEAN = (0.774, 0.496, 0.302, 0.113, 0.0058)
TABLE_MID = (0.999, 0.772, 0.474, 0.177, 0.0092)


def run_terzaghi(nz, solver, ratio=0.5, thickness=10.0, p0=1e-6):
    """Frozen uniform packing (phi = 0.15), P = p0 at t = 0, P = 0 on both planes.

    Fluid steps of Delta T = ratio / nz^2 (so dt ~ dz^2 and time and space errors
    both scale as dz^2). Returns {T: (mean P/p0, mid-plane P/p0)}; the mid-plane
    value is the mean of the two central cells (nz even).
    """
    nx = 2
    h = thickness / nz
    z_bot = 1.0
    z_top = z_bot + thickness
    x, z, radius = lattice(nx, nz, h, z_bot, 0.15)
    v = np.zeros_like(x)
    grid = FluidGrid(nx, nz, nx * h, z_bot, z_top, x.size, 1e-5, BETA, ETA, solver=solver)
    assert grid.init(x, z, v, v, radius, z_bot, z_top) == L.STATUS_OK
    np.testing.assert_allclose(grid.porosity, 0.15, rtol=0, atol=1e-12)
    diffusivity = grid.mean_diffusivity()
    grid.pressure[:] = p0
    delta_T = ratio / nz**2
    steps_per_target = {round(T / delta_T): T for T in TERZAGHI_T}
    out = {}
    for step in range(1, max(steps_per_target) + 1):
        status = grid.update(x, z, v, v, radius, z_bot, z_top, delta_T * thickness**2 / diffusivity)
        assert status == L.STATUS_OK
        if step in steps_per_target:
            profile = grid.pressure[0] / p0
            out[steps_per_target[step]] = (profile.mean(), 0.5 * (profile[nz // 2 - 1] + profile[nz // 2]))
    out["explicit_updates"] = grid.state[L.S_EXPLICIT_UPDATES] / grid.state[L.S_UPDATES]
    return out


def test_terzaghi_series_matches_table():
    for T, mean, mid in zip(TERZAGHI_T, TABLE_MEAN, TABLE_MID):
        assert terzaghi_mean(T) == pytest.approx(mean, abs=6e-4)
        assert terzaghi_profile(T, 0.5) == pytest.approx(mid, abs=6e-4)


@pytest.mark.parametrize("solver, ratio", [("implicit", 0.5), ("explicit", 0.5), ("auto", 0.05)])
def test_terzaghi_consolidation(solver, ratio):
    """Fluid steps of 2x the FTCS bound (implicit; explicit sub-steps itself) and, for auto, of 0.2x
    the bound, where it takes the Heun step every update."""
    errors = {}
    results = {}
    for nz in (20, 40, 80):
        results[nz] = run_terzaghi(nz, solver, ratio)
        assert results[nz]["explicit_updates"] == {"implicit": 0.0, "explicit": 1.0, "auto": 1.0}[solver]
        errors[nz] = max(
            max(abs(results[nz][T][0] - terzaghi_mean(T)), abs(results[nz][T][1] - terzaghi_profile(T, 0.5)))
            for T in TERZAGHI_T
        )
    fine = results[80]
    for T, mean, mid in zip(TERZAGHI_T, TABLE_MEAN, TABLE_MID):
        exact_mean = terzaghi_mean(T)
        exact_mid = terzaghi_profile(T, 0.5)
        # within 1 % relative to the analytic value (stricter than 1 % of P0)
        assert fine[T][0] == pytest.approx(exact_mean, rel=0.01)
        assert fine[T][1] == pytest.approx(exact_mid, rel=0.01)
        # and the physics.md table (3 significant figures) within 1 % of P0
        assert fine[T][0] == pytest.approx(mean, abs=0.01)
        assert fine[T][1] == pytest.approx(mid, abs=0.01)
    orders = [np.log2(errors[20] / errors[40]), np.log2(errors[40] / errors[80])]
    assert min(orders) > 1.7, (errors, orders)
    assert max(orders) < 2.5, (errors, orders)


def affine_compaction(strain, n_steps, solver="implicit", permeability=1e-12, total_time=1.0):
    """Scale z of every grain and of both planes by (1 + strain) at a constant rate.

    Lattice at phi = 0.15 (2 sites per cell per axis), 10 x 8 cells of 2 d.
    Returns the grid after n_steps equal fluid steps and the initial porosity.
    """
    spacing = 1.0
    z_bot0, z_top0 = 2.0, 18.0
    x, z0, radius = lattice(20, 16, spacing, z_bot0, 0.15)
    grid = FluidGrid(10, 8, 20.0, z_bot0, z_top0, x.size, permeability, BETA, ETA, solver=solver)
    zero = np.zeros_like(x)
    vz = strain * z0 / total_time
    assert grid.init(x, z0, zero, vz, radius, z_bot0, z_top0) == L.STATUS_OK
    porosity0 = grid.porosity.copy()
    dt = total_time / n_steps
    for step in range(1, n_steps + 1):
        factor = 1.0 + strain * step / n_steps
        status = grid.update(x, z0 * factor, zero, vz, radius, z_bot0 * factor, z_top0 * factor, dt)
        assert status == L.STATUS_OK
    return grid, porosity0


def test_undrained_affine_compaction():
    strain = -1e-3
    results = {k: affine_compaction(strain, k)[0].pressure.copy() for k in (1, 4, 16)}
    grid, porosity0 = affine_compaction(strain, 1)
    np.testing.assert_allclose(porosity0, 0.15, atol=1e-12)
    np.testing.assert_allclose(grid.porosity, 1.0 - 0.85 / (1.0 + strain), atol=1e-12)
    # exact undrained solution of the pressure equation: 1 + beta P = phi0 / (phi0 + eps_v)
    exact = (0.15 / (0.15 + strain) - 1.0) / BETA
    for pressure in results.values():
        np.testing.assert_allclose(pressure, exact, rtol=1e-6)
    # independent of the fluid step: 1, 4 and 16 steps agree (1 % asked; exact here)
    np.testing.assert_allclose(results[4], results[1], rtol=1e-6)
    np.testing.assert_allclose(results[16], results[1], rtol=1e-6)
    # physics.md targets: 1 + beta P = exp(-eps_v/phi) and P = -eps_v/(beta phi) = 1.85e-4
    one_plus = 1.0 + BETA * results[16]
    np.testing.assert_allclose(one_plus, np.exp(-strain / 0.15), rtol=0.01)
    np.testing.assert_allclose(BETA * results[16], np.expm1(-strain / 0.15), rtol=0.01)
    np.testing.assert_allclose(results[16], -strain / (BETA * 0.15), rtol=0.01)
    np.testing.assert_allclose(results[16], 1.85e-4, rtol=0.01)


def test_undrained_explicit_solver_agrees():
    strain = -1e-3
    implicit = affine_compaction(strain, 4)[0].pressure
    explicit = affine_compaction(strain, 4, solver="explicit")[0].pressure
    np.testing.assert_allclose(explicit, implicit, rtol=1e-6)


@pytest.mark.parametrize("solver", ["implicit", "explicit"])
def test_compaction_raises_and_dilation_lowers_pressure(solver):
    # kappa_c = 1e-5 (thesis): D ~ 0.06, the layer drains partly during the step
    compacted, _ = affine_compaction(-1e-3, 4, solver=solver, permeability=1e-5, total_time=50.0)
    dilated, _ = affine_compaction(+1e-3, 4, solver=solver, permeability=1e-5, total_time=50.0)
    assert (compacted.pressure > 0.0).all()
    assert (dilated.pressure < 0.0).all()
    # bounded by the undrained values phi0 / (phi0 + eps_v) - 1 = beta P
    assert 0.0 < compacted.pressure.max() < (0.15 / 0.149 - 1.0) / BETA
    assert 0.0 < -dilated.pressure.min() < (1.0 - 0.15 / 0.151) / BETA
    # drainage: boundary cells hold less pressure than the mid-plane
    assert compacted.pressure[:, 0].max() < compacted.pressure[:, 3].min()


def random_layer(seed=3, width=30.0, z_bot=1.5, z_top=21.5):
    """Wall rows centred on the planes and a random dense set of free grains."""
    rng = np.random.default_rng(seed)
    wall_x = np.arange(0.0, width, 1.0) + 0.5
    n_free = 520
    x = np.concatenate([wall_x, wall_x + 0.25, rng.uniform(-width, 2 * width, n_free)])
    z = np.concatenate([np.full(wall_x.size, z_bot) + rng.normal(0, 0.05, wall_x.size),
                        np.full(wall_x.size, z_top) + rng.normal(0, 0.05, wall_x.size),
                        rng.uniform(z_bot + 0.2, z_top - 0.2, n_free)])
    radius = np.concatenate([np.full(2 * wall_x.size, 0.5), rng.uniform(0.4, 0.6, n_free)])
    return x, z, radius


def test_drag_equals_minus_integral_of_uniform_gradient():
    width, z_bot, z_top = 30.0, 1.5, 21.5
    x, z, radius = random_layer(width=width, z_bot=z_bot, z_top=z_top)
    v = np.zeros_like(x)
    # the gradient form with the deposit's own (unfiltered) solid fraction: the identity below
    grid = FluidGrid.from_config(FluidConfig(filter_width=0, cell_size=2.5), width, z_bot, z_top, x.size)
    assert grid.init(x, z, v, v, radius, z_bot, z_top) == L.STATUS_OK
    assert (grid.solid_fraction > 0).all()
    nx, nz = grid.nx, grid.nz
    dx, dz = grid.dx, grid.dz
    gx = np.empty((nx, nz))
    gz = np.empty((nx, nz))
    slope = 2.5e-5
    z_centres = (np.arange(nz) + 0.5) * dz
    pressure = np.tile(slope * z_centres, (nx, 1))
    KG.pressure_gradient(pressure, dx, dz, 0.0, slope * (z_top - z_bot), gx, gz)
    np.testing.assert_allclose(gz, slope, rtol=1e-12)
    assert np.abs(gx).max() == 0.0
    gx[:] = -0.7 * slope
    drag_x = np.empty(x.size)
    drag_z = np.empty(x.size)
    fx, fz = np.empty_like(gx), np.empty_like(gz)
    KG.drag_density(gx, gz, grid.solid_fraction, fx, fz)
    KG.grain_drag(x, z, radius, x.size, width, z_bot, z_top, fx, fz, drag_x, drag_z)
    area = width * (z_top - z_bot)
    # sum_k a_k sum_c W_kc / s_c = sum_c dx dz: the total drag is -grad P times the domain area
    assert drag_z.sum() == pytest.approx(-slope * area, rel=1e-10)
    assert drag_x.sum() == pytest.approx(0.7 * slope * area, rel=1e-10)
    # the in-domain grain area, divided cell by cell by the solid fraction, is that area
    in_domain = np.array([KW.in_domain_area(zk, rk, z_bot, z_top) for zk, rk in zip(z, radius)])
    assert in_domain.sum() == pytest.approx((grid.solid_fraction * dx * dz).sum(), rel=1e-12)


def test_drag_uniform_porosity_is_volume_over_solid_fraction():
    x, z, radius = lattice(20, 16, 1.0, 2.0, 0.15)
    v = np.zeros_like(x)
    grid = FluidGrid(10, 8, 20.0, 2.0, 18.0, x.size, 1e-5, BETA, ETA)
    grid.init(x, z, v, v, radius, 2.0, 18.0)
    gx = np.zeros((10, 8))
    gz = np.full((10, 8), 3e-6)
    drag_x = np.empty(x.size)
    drag_z = np.empty(x.size)
    fx, fz = np.empty_like(gx), np.empty_like(gz)
    KG.drag_density(gx, gz, grid.solid_fraction, fx, fz)
    KG.grain_drag(x, z, radius, x.size, 20.0, 2.0, 18.0, fx, fz, drag_x, drag_z)
    volume = np.pi * radius**2
    np.testing.assert_allclose(drag_z, -3e-6 * volume / (1.0 - 0.15), rtol=1e-12)
    assert drag_z.sum() == pytest.approx(-3e-6 * volume.sum() / 0.85, rel=1e-10)
    assert drag_z.sum() == pytest.approx(-3e-6 * 20.0 * 16.0, rel=1e-10)
    assert np.abs(drag_x).max() == 0.0


def test_total_drag_of_solved_pressure_is_zero():
    """P = 0 on both planes and periodic x: -integral of grad P = 0, so the fluid's forces sum to zero:
    the grains' drag and the two planes' forces (kernels.fluid_update.plane_forces; the mirrored
    grad s puts the wall rows' squeeze on the planes)."""
    width, z_bot, z_top = 30.0, 1.5, 21.5
    x, z, radius = random_layer(width=width, z_bot=z_bot, z_top=z_top)
    rng = np.random.default_rng(7)
    v = np.zeros_like(x)
    grid = FluidGrid.from_config(FluidConfig(), width, z_bot, z_top, x.size)
    grid.init(x, z, v, v, radius, z_bot, z_top)
    vx = rng.normal(0, 1e-4, x.size)
    vz = rng.normal(0, 1e-4, x.size)
    dt = 10.0
    status = grid.update(x + vx * dt, z + vz * dt, vx, vz, radius, z_bot, z_top, dt)
    assert status == L.STATUS_OK
    assert np.abs(grid.pressure).max() > 0.0
    scale = np.abs(grid.drag_z).sum() + np.abs(grid.drag_x).sum()
    assert scale > 0.0
    assert abs(grid.drag_x.sum()) < 1e-12 * scale
    planes = grid.state[L.S_F_BOT] + grid.state[L.S_F_TOP]
    assert abs(grid.drag_z.sum() + planes) < 1e-12 * scale


def test_uniform_pressure_gives_no_drag():
    width, z_bot, z_top = 30.0, 1.5, 21.5
    x, z, radius = random_layer(width=width, z_bot=z_bot, z_top=z_top)
    v = np.zeros_like(x)
    grid = FluidGrid.from_config(FluidConfig(), width, z_bot, z_top, x.size)
    grid.init(x, z, v, v, radius, z_bot, z_top)
    # an ambient shift, equal on the planes: no gradient, no force on grains or walls
    pressure = np.full((grid.nx, grid.nz), 4e-5)
    gx = np.empty_like(pressure)
    gz = np.empty_like(pressure)
    KG.pressure_gradient(pressure, grid.dx, grid.dz, 4e-5, 4e-5, gx, gz)
    drag_x = np.ones(x.size)
    drag_z = np.ones(x.size)
    fx, fz = np.empty_like(gx), np.empty_like(gz)
    KG.drag_density(gx, gz, grid.solid_fraction, fx, fz)
    KG.grain_drag(x, z, radius, x.size, width, z_bot, z_top, fx, fz, drag_x, drag_z)
    assert np.abs(drag_x).max() == 0.0
    assert np.abs(drag_z).max() == 0.0
    # frozen grains at P = 0: the fluid step leaves P = 0 and no drag
    for _ in range(3):
        assert grid.update(x, z, v, v, radius, z_bot, z_top, 5.0) == L.STATUS_OK
    assert np.abs(grid.pressure).max() == 0.0
    assert np.abs(grid.drag_x).max() == 0.0
    assert np.abs(grid.drag_z).max() == 0.0


def test_rigid_translation_generates_almost_no_pressure():
    """A packing sliding rigidly through the grid has div u_s = 0.

    grad s is the derivative of the deposit itself, so u . grad s cancels the
    change of s except where a grain crosses a kink of the bilinear weights:
    the spurious pressure is first order in U dt_f / dx. (A central difference of
    s on the grid instead leaves ~5 % volumetric strain after 0.2 d.)
    """
    rng = np.random.default_rng(1)
    sites_x, sites_z = np.meshgrid(np.arange(40) + 0.5, np.arange(20) + 0.5, indexing="ij")
    x0 = sites_x.ravel() + rng.normal(0, 0.15, sites_x.size)
    z0 = sites_z.ravel() + rng.normal(0, 0.15, sites_x.size)
    radius = np.full(x0.size, np.sqrt(0.85 / np.pi))
    speed = 1e-3
    vx = np.full(x0.size, speed)
    vz = np.zeros_like(x0)
    strain = {}
    for steps in (100, 400):
        dt = 1.0 / speed / steps
        grid = FluidGrid.from_config(FluidConfig(permeability=1e-12), 40.0, 0.0, 20.0, x0.size)
        grid.init(x0, z0, vx, vz, radius, 0.0, 20.0)
        for k in range(1, steps + 1):
            assert grid.update(x0 + speed * dt * k, z0, vx, vz, radius, 0.0, 20.0, dt) == L.STATUS_OK
        strain[steps] = np.abs(grid.pressure).max() * BETA * 0.15
    assert strain[100] < 5e-3
    assert strain[400] < strain[100] / 2.0
