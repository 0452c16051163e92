"""Shared fixtures for the test suite (kept small on purpose).

``GOUGE_TEST_SEED_OFFSET=N`` shifts the seed of every packing the suite builds (tests/seed_offset.py).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numba
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
    """Factory: gouge_cli.studies.analytic.free_grains (a Simulation of free grains, no top wall).

    free_grains(x, z, radius, vx=..., vz=..., spin=..., body=..., width=100, dt=..., **material)"""
    from gouge_cli.studies.analytic import free_grains

    return free_grains


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory):
    """The tiny scene's loading run (tests/slipping.TINY, two or more slips with checkpoints),
    run once per test process (a worker of ``pytest -n``): a factories.SharedRun, never written
    to; a module forks its own ``tiny_run.copy(folder)``."""
    from factories import SharedRun
    from slipping import TINY, slipping_run

    return SharedRun(*slipping_run(TINY, tmp_path_factory.mktemp("tiny_run")))
