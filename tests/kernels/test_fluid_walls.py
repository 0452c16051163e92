"""The undrained source next to the wall planes, with prescribed grain motions (no DEM).

The source is Goren's material change of the solid fraction, s(n+1) - s(n) + dt u_rel . grad s, with
grad s the deposit's derivative with respect to a common displacement of the grains. Next to a
wall plane that derivative holds the plane's jump in s (no solid beyond the plane: the clamped
bilinear weights, then the filter's even mirror images), about s / dz in each boundary row. The
boundary rows move with the planes, so that jump never moves relative to its cells, yet the
source transports it with the solid's grid-relative velocity: wherever the material near a wall
does not follow the grid (dilation not uniform across the layer, a shear band at a wall), the
wall rows get a spurious source. Still material next to a still wall then takes a suction when
the grid stretches, and a gap opening at a wall is mostly not seen as dilation, so that the fluid
mass sum (1 + beta P) phi dV is not conserved although nothing drains. In a 300-grain layer
sheared at 30 x 4e-4 v0 (kappa_c 1e-9) it removes 3.7e-4 E of the 4.4e-4 E mean suction missing
after 163 t0 (the rest: the suction sits in the porous wall rows), with diffusion, clamps and the
unadvected P each below 1 % of it.

These tests state the physics and fail on the current scheme (strict xfail). Removing the jump
from grad s (grad s as the derivative of the mirror-extended deposit: weight slope 2/dz for the
grains between a plane and the first cell centre, odd images in the filter) passes them in a
source-only prototype, but the same term, through the adjoint drag (r = P grad s / s^2), is the
force by which a uniform suction squeezes the layer (|P| L_x on each wall's grains), so the fix
needs that force moved onto the wall (the deposit's adjoint with respect to the planes,
docs/physics/fluid.md) and is a change of the model.
"""

import numpy as np
import pytest

from gouge_cli.config import FluidConfig
from gouge_cli.kernels import layout as L
from gouge_cli.model.fluid import FluidGrid

from test_fluid import BETA

WIDTH, Z_BOT, Z_TOP = 30.0, 1.5, 21.5


def wall_lattice(seed=4):
    """A row of wall grains (R 0.5) centred on each plane, 1 d apart, and free grains on a jittered
    square lattice of 1 d between them (solid fraction 0.7, clear of the planes): no cell is
    clamped (phi in [0.05, 0.9]), so the undrained response is exact cell by cell."""
    rng = np.random.default_rng(seed)
    sites = np.arange(WIDTH) + 0.5
    rows = Z_BOT + 1.0 + np.arange(int(Z_TOP - Z_BOT) - 1)
    X, Z = np.meshgrid(sites, rows, indexing="ij")
    x = np.concatenate([sites, sites, X.ravel() + rng.normal(0, 0.1, X.size)])
    z = np.concatenate([np.full(sites.size, Z_BOT), np.full(sites.size, Z_TOP), Z.ravel() + rng.normal(0, 0.1, X.size)])
    radius = np.concatenate([np.full(2 * sites.size, 0.5), np.full(X.size, np.sqrt(0.7 / np.pi))])
    return x, z, radius
DEFECT = "undrained source transports the wall plane's jump in s with the solid (see module doc)"


def prescribed(kind, lift=0.03, total=100.0, steps=100):
    """Undrained (kappa_c 1e-12) grid under a prescribed motion that lifts the top wall by `lift`.

    kind "band": a middle band (40-60 % of the layer) dilates uniformly, the material below it
    stays still and the material above it, top wall included, rises rigidly; "gap": the top-wall
    grains and the top plane rise off a still packing. Returns the grid and the initial pore
    area sum(phi dV) and fluid mass sum((1 + beta P) phi dV) (P = 0 at the start).
    """
    x, z0, radius = wall_lattice()
    thickness = Z_TOP - Z_BOT
    if kind == "band":
        z1, z2 = Z_BOT + 0.4 * thickness, Z_BOT + 0.6 * thickness
        rise = np.clip(z0 - z1, 0.0, z2 - z1) / (z2 - z1)
    else:
        rise = (np.abs(z0 - Z_TOP) < 0.3).astype(float)
    speed = lift / total
    return moving(x, z0, radius, speed * rise, speed, total, steps)


def moving(x, z0, radius, vz, top_speed, total, steps):
    """(grid, initial pore area): the undrained grid (kappa_c 1e-12) while the grains move at `vz`
    and the top plane at `top_speed` [d/t0] for `total` t0 in `steps` updates."""
    zero = np.zeros_like(x)
    grid = FluidGrid.from_config(FluidConfig(permeability=1e-12), WIDTH, Z_BOT, Z_TOP, x.size)
    assert grid.init(x, z0, zero, vz, radius, Z_BOT, Z_TOP) == L.STATUS_OK
    pore0 = grid.porosity.sum() * grid.dx * grid.dz
    dt = total / steps
    for k in range(1, steps + 1):
        status = grid.update(x, z0 + vz * dt * k, zero, vz, radius, Z_BOT, Z_TOP + top_speed * dt * k, dt)
        assert status == L.STATUS_OK
    return grid, pore0


def fluid_mass_error(grid, pore0):
    """(fluid mass gained) / (pore area gained): 0 for an undrained layer (nothing crosses the walls)."""
    area = grid.dx * grid.dz
    pore = grid.porosity.sum() * area
    fluid = ((1.0 + BETA * grid.pressure) * grid.porosity).sum() * area
    return (fluid - pore0) / (pore - pore0)


def test_still_material_next_to_a_still_wall_keeps_zero_pressure():
    """Band dilation: the two rows next to the still bottom wall hold material that does not move
    at all; their pressure must stay ~0 (3 % of the band's suction asked; measured: 16 %)."""
    grid, _ = prescribed("band")
    rows = grid.pressure.mean(axis=0)
    assert rows.min() < 0.0
    assert np.abs(rows[:2]).max() < 0.03 * np.abs(rows).max()


@pytest.mark.parametrize("kind", ["band", "gap"])
def test_undrained_dilation_conserves_the_fluid_mass(kind):
    """Undrained, nothing crosses the walls: the fluid mass sum((1 + beta P) phi dV) keeps its
    initial value within 5 % of the pore area created. Measured: band +18 % (the still wall rows
    take suction), gap -64 % (the top wall lifting off a still packing: most of the gap not seen)."""
    grid, pore0 = prescribed(kind)
    assert grid.pressure.min() < 0.0
    assert abs(fluid_mass_error(grid, pore0)) < 0.05


def test_uniform_dilation_conserves_the_fluid_mass():
    """The affine control: the whole layer dilates with the grid (no motion relative to it), and
    the fluid mass is conserved to round-off of the exact undrained response (the jump is not
    transported when u_rel = 0)."""
    x, z0, radius = wall_lattice()
    strain, total, steps = 1.5e-3, 100.0, 50
    vz = strain * (z0 - Z_BOT) / total
    grid, pore0 = moving(x, z0, radius, vz, strain * (Z_TOP - Z_BOT) / total, total, steps)
    assert grid.pressure.max() < 0.0
    assert abs(fluid_mass_error(grid, pore0)) < 1e-3
