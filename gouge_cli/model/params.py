"""The kernels' parameter vector of a scene and its thread policy, each decided here once.

``build_params`` fills the float64 vector kernels.layout DT..SORT_EVERY (N_PARAMS) from the
config; ``choose_threads`` / ``choose_sort_every`` are the automatic choices for a scene of
n grains (small scenes run on one thread without re-numbering); ``numba_threads`` runs a block
of kernels on a scene's thread count and restores the caller's. Results are bitwise the same
for any thread count (tests/driver/test_reproducibility.py), so the policy is about speed only.
"""

from __future__ import annotations

from contextlib import contextmanager

import numba
import numpy as np

from ..config import Config
from ..kernels import layout as L
from .timestep import contact_constants

AUTO_PARALLEL_MIN_GRAINS = 2000
AUTO_SORT_EVERY = 20        # rebuilds between re-numberings (~900 steps at the bench scene; LAMMPS: 1000)


def build_params(config: Config, dt: float, width: float, wall_mass: float, n_grains: int,
                 constants: tuple[float, float] | None = None) -> np.ndarray:
    """Kernel parameter vector (N_PARAMS,) for a scene of n_grains grains, width [d], time step
    dt [t0] and top body mass wall_mass = m_b L_x (0: no top wall); `constants` = (c_n, c_t) [E]
    when derived already (model.scene), else timestep.contact_constants. DRIVE and BG_DAMPING are
    the phase's (driver.simulation sets them); THREADS is set by whoever runs the kernels."""
    c_normal, c_tangential = constants if constants is not None else contact_constants(config)
    p = np.zeros(L.N_PARAMS)
    p[L.DT] = dt
    p[L.WIDTH] = width
    p[L.SKIN] = config.numerics.skin
    p[L.C_NORMAL] = c_normal
    p[L.C_TANGENTIAL] = c_tangential
    p[L.DAMPING] = config.material.damping
    p[L.FRICTION] = config.material.friction
    p[L.SIGMA] = config.loading.normal_stress
    p[L.SPRING] = config.loading.spring_constant
    p[L.V_LOAD] = config.loading.velocity
    p[L.WALL_MASS] = wall_mass
    p[L.SORT_EVERY] = choose_sort_every(config.numerics.sort_every, n_grains)
    return p


def choose_threads(requested: int, n_grains: int) -> int:
    """numerics.threads (0: automatic) -> numba threads of a scene of n_grains: the request capped
    at NUMBA_NUM_THREADS; automatic: 1 below AUTO_PARALLEL_MIN_GRAINS grains, else all."""
    available = numba.config.NUMBA_NUM_THREADS
    if requested:
        return min(requested, available)
    return 1 if n_grains < AUTO_PARALLEL_MIN_GRAINS else available


def choose_sort_every(requested: int | None, n_grains: int) -> int:
    """numerics.sort_every (None: automatic) -> list rebuilds between re-numberings (0: never)."""
    if requested is not None:
        return requested
    return AUTO_SORT_EVERY if n_grains >= AUTO_PARALLEL_MIN_GRAINS else 0


@contextmanager
def numba_threads(threads: int):
    """Run the block on `threads` numba threads, then restore the caller's count."""
    previous = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        yield
    finally:
        numba.set_num_threads(previous)
