"""Shared fixtures for the test suite (kept small on purpose).

``GOUGE_TEST_SEED_OFFSET=N`` shifts the seed of every packing the suite builds (tests/seed_offset.py).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numba
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import seed_offset  # noqa: E402

seed_offset.install()
seed_offset.propagate()


@pytest.fixture
def single_thread():
    """Run numba kernels on one thread (restored afterwards).

    Scenes of a few grains spend almost all their time launching parallel regions; on a
    busy 2-core machine one thread is 10-30x faster and gives the same numbers bit for bit
    (force sums have a fixed order)."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


@pytest.fixture
def free_grains():
    """Factory: a Simulation of free grains (body 0 unless given) with no top wall.

    free_grains(x, z, radius, vx=..., vz=..., spin=..., body=..., width=100, dt=..., **material)
    material keys go to config section ``material`` (damping defaults to 0); background
    (compaction) damping is always 0 so the dynamics are Newtonian."""
    from gouge_cli.config import build_config
    from gouge_cli.driver.simulation import Simulation
    from gouge_cli.model.state import State

    def make(x, z, radius, *, vx=None, vz=None, spin=None, body=None, width=100.0, dt=0.01,
             normal_stress=None, **material):
        material.setdefault("damping", 0.0)
        data = {"numerics": {"dt": dt}, "compaction": {"damping": 0.0}, "material": material}
        if normal_stress is not None:
            data["loading"] = {"normal_stress": normal_stress}
        cfg = build_config(data)
        x = np.asarray(x, float)
        n = x.shape[0]
        st = State(x=x.copy(), z=np.asarray(z, float).copy(), radius=np.asarray(radius, float).copy(),
                   body=np.zeros(n) if body is None else np.asarray(body), density=1.0, width=width)
        for name, value in (("vx", vx), ("vz", vz), ("spin", spin)):
            if value is not None:
                getattr(st, name)[:] = value
        return Simulation(cfg, state=st)

    return make
