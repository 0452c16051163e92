"""The GPU dry engine (kernels.gpu, model.gpu_layers) against the CPU kernels, under numba-cuda's
CUDA simulator (no GPU needed).

Each check runs tests/gpu/sim_check.py in a fresh process with NUMBA_ENABLE_CUDASIM=1 (the
simulator must be chosen before numba.cuda is imported, and must not reach this process):
* lockstep: a compacted 40-grain layer under loading, the GPU copy starting with too short a
  pair list (it overflows and grows on the device), compared after 1, 1, 8 and 60 steps,
  then 50 and 80 more after the spring is re-attached: every State array bit for bit,
  through list rebuilds and re-numberings (sort_every 1);
* ensemble: three 30-grain layers (different seeds, velocities, one of them loading) advanced
  as one ensemble equal each layer advanced alone, bit for bit;
* planted: a last-bit change in the GPU's contact law alone makes the lockstep comparison fail.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba.cuda", reason="numba-cuda is not installed (pip install 'gouge[gpu]')")

SCRIPT = Path(__file__).with_name("sim_check.py")
ROOT = Path(__file__).resolve().parents[2]
SEED = 1 + int(os.environ.get("GOUGE_TEST_SEED_OFFSET", "0"))


def _run(mode: str) -> dict:
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", NUMBA_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    out = subprocess.run([sys.executable, str(SCRIPT), mode, str(SEED)], capture_output=True, text=True, env=env,
                         cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def lockstep():
    return _run("lockstep")


def test_gpu_steps_equal_cpu_bits(lockstep):
    rows = lockstep["rows"]
    assert [r["diff"] for r in rows] == [{}] * len(rows)
    assert lockstep["loading"]
    assert rows[-1]["rebuilds"] - rows[0]["rebuilds"] >= 5      # the list was rebuilt (and re-numbered)
    assert rows[-1]["pairs"] > 40                                # a dense layer: more pairs than grains


def test_gpu_list_overflow_grows_on_device(lockstep):
    first = lockstep["rows"][:4]
    assert first[-1]["gpu_launches"] > len(first)               # a launch stopped at an overflow and resumed
    assert all(r["diff"] == {} for r in first)


def test_ensemble_equals_single_layers():
    layers = _run("ensemble")["layers"]
    assert layers == [{}, {}, {}]


def test_planted_change_in_gpu_law_is_caught():
    rows = _run("planted")["rows"]
    assert any(r["diff"] for r in rows)
    assert "force_x" in rows[0]["diff"] or "vx" in rows[0]["diff"] or "x" in rows[0]["diff"]
