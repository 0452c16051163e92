"""The kernels' parameter vector and the thread policy of a scene (gouge_cli.model.params)."""

from __future__ import annotations

import numba
import pytest

from gouge_cli.config import build_config
from gouge_cli.kernels import layout as L
from gouge_cli.model.params import (AUTO_PARALLEL_MIN_GRAINS, AUTO_SORT_EVERY, build_params, choose_sort_every,
                                    choose_threads, numba_threads)
from gouge_cli.model.timestep import contact_constants


def test_build_params_fills_every_named_entry_from_the_config():
    cfg = build_config({"loading": {"spring_constant": 3e-4, "velocity": 2e-3, "normal_stress": 2e-4},
                        "material": {"friction": 0.4, "damping": 0.05}, "numerics": {"skin": 0.3}})
    p = build_params(cfg, 0.01, 15.0, 7.5, 300)
    assert p.shape == (L.N_PARAMS,)
    assert (p[L.DT], p[L.WIDTH], p[L.SKIN], p[L.WALL_MASS]) == (0.01, 15.0, 0.3, 7.5)
    assert (p[L.C_NORMAL], p[L.C_TANGENTIAL]) == contact_constants(cfg)
    assert (p[L.FRICTION], p[L.DAMPING], p[L.SIGMA], p[L.SPRING], p[L.V_LOAD]) == (0.4, 0.05, 2e-4, 3e-4, 2e-3)
    assert p[L.SORT_EVERY] == 0 and p[L.DRIVE] == 0 and p[L.THREADS] == 0


def test_thread_policy():
    available = numba.config.NUMBA_NUM_THREADS
    assert choose_threads(0, AUTO_PARALLEL_MIN_GRAINS - 1) == 1
    assert choose_threads(0, AUTO_PARALLEL_MIN_GRAINS) == available
    assert choose_threads(1, 10**6) == 1 and choose_threads(available + 5, 10) == available
    assert choose_sort_every(None, AUTO_PARALLEL_MIN_GRAINS) == AUTO_SORT_EVERY
    assert choose_sort_every(None, AUTO_PARALLEL_MIN_GRAINS - 1) == 0 and choose_sort_every(3, 10) == 3


def test_numba_threads_restores_the_callers_count():
    before = numba.get_num_threads()
    with pytest.raises(RuntimeError):
        with numba_threads(1):
            assert numba.get_num_threads() == 1
            raise RuntimeError
    assert numba.get_num_threads() == before
