"""The compile note (issue 60): a run whose kernel numba has not compiled for this CPU says so
before its first step; one whose kernel is in the cache says nothing."""

from __future__ import annotations

import os
import subprocess
import sys

from gouge_cli.config import build_config
from gouge_cli.driver.simulation import Simulation

SCENE = {"name": "note", "seed": 1, "packing": {"n_grains": 200, "width": 12}, "run": {"duration": 10}}


def test_note_with_an_empty_cache(tmp_path):
    code = ("from gouge_cli.config import build_config\n"
            "from gouge_cli.driver.simulation import Simulation\n"
            f"print(Simulation(build_config({SCENE!r})).compile_note())\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "empty"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.startswith("note: compiling the grain step for this CPU")


def test_no_note_once_compiled():
    sim = Simulation(build_config(SCENE))
    sim.advance(1)                         # compiled (or loaded) and in the cache now
    assert sim.compile_note() is None
