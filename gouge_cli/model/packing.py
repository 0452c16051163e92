"""Seeded loose packing between two rough walls (docs/physics/walls.md).

Each wall is one row of grains (diameters from the same distribution) glued to a
rigid body; free grains start on a jittered square lattice with no overlaps and
are then compacted under the normal stress (:func:`gouge_cli.driver.simulation.compact`).

Grain numbering: strip by strip (STRIP d wide columns along x), bottom to top within a strip.
Neighbours then have nearby numbers, so the force pass works in a small window of memory
(faster than row-by-row numbering in wide layers). As the layer shears the
grains are re-numbered the same way (kernels.reorder, numerics.sort_every).
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Config
from ..errors import ConfigError
from ..kernels.reorder import STRIP
from .state import BOTTOM, FREE, TOP, State


def packing_layout(config: Config) -> tuple[float, int, int, int]:
    """(width [d], grains per wall, free grains, lattice columns); ConfigError if the grains
    do not fill at least one row of the width."""
    p = config.packing
    width = p.resolved_width()
    n_wall = max(3, int(round(width / p.wall_spacing)))
    n_free = p.n_grains - 2 * n_wall
    n_columns = int(width // p.initial_spacing)
    if n_free < n_columns or n_columns < 3:
        raise ConfigError(
            f"packing.n_grains = {p.n_grains} leaves {n_free} free grains for a layer {width:g} d wide "
            f"({n_wall} grains per wall); use more grains (at least {2 * n_wall + max(n_columns, 3)}) "
            "or a smaller packing.width"
        )
    return width, n_wall, n_free, n_columns


def build_packing(config: Config) -> State:
    """Loose start of the scene; same config and seed give the same arrays bit for bit."""
    p = config.packing
    rng = np.random.default_rng(config.seed)
    width, n_wall, n_free, n_columns = packing_layout(config)
    n_rows = math.ceil(n_free / n_columns)
    jitter = 0.45 * (p.initial_spacing - p.diameter_max)

    def diameters(count):
        return rng.uniform(p.diameter_min, p.diameter_max, count)

    wall_pitch = width / n_wall
    x_wall = (np.arange(n_wall) + 0.5) * wall_pitch
    d_bottom = diameters(n_wall)
    d_free = diameters(n_free)
    column = np.arange(n_free) % n_columns
    row = np.arange(n_free) // n_columns
    z0 = p.diameter_max + 0.1
    x_free = (column + 0.5) * (width / n_columns) + rng.uniform(-jitter, jitter, n_free)
    z_free = z0 + row * p.initial_spacing + rng.uniform(-jitter, jitter, n_free)
    d_top = diameters(n_wall)
    z_top = z0 + (n_rows - 1) * p.initial_spacing + p.diameter_max + 0.1

    x = np.concatenate([x_wall, x_free, x_wall.copy()]) % width
    z = np.concatenate([np.zeros(n_wall), z_free, np.full(n_wall, z_top)])
    radius = 0.5 * np.concatenate([d_bottom, d_free, d_top])
    body = np.concatenate([np.full(n_wall, BOTTOM), np.full(n_free, FREE), np.full(n_wall, TOP)])
    order = np.lexsort((x, z, np.floor(x / STRIP)))
    x, z, radius, body = x[order], z[order], radius[order], body[order]
    return State(x=x, z=z, radius=radius, body=body, density=config.material.density, width=width)
