"""Same input, same bits: across code-generation targets, thread counts and seeds.

A run on another machine must reproduce its parent bit for bit. This suite has only one machine,
so it stands in for a second one by re-running the same scenes in fresh processes with numba
compiling for a baseline target (``NUMBA_CPU_NAME=generic``: no AVX, no FMA) and numpy's
SIMD dispatch switched off (``NPY_DISABLE_CPU_FEATURES``: numpy's AVX2 / AVX-512 loops, whose
transcendental functions differ in the last bit), on 1 and 2 threads, and comparing the final
state hashes (gouge_cli.io.provenance.state_hash).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import numpy as np
import pytest

from gouge_cli.io import provenance
from gouge_cli.model import portable

SCENE = {"packing": {"n_grains": 300, "width": 15}, "compaction": {"min_time": 200.0, "max_time": 600.0},
         "loading": {"spring_constant": 2e-4, "velocity": 4e-3}, "numerics": {"sort_every": 1}}

SCRIPT = """
import json, sys
from gouge_cli.config import build_config
from gouge_cli.io.provenance import sim_hash
from gouge_cli.driver.compaction import compact
from gouge_cli.driver.simulation import Simulation
from gouge_cli.kernels.layout import S_EXPLICIT_UPDATES
data = json.loads(sys.argv[1])
threads = int(sys.argv[2])
sim = Simulation(build_config(data))
sim.threads = threads
compact(sim)
sim.start_fluid()
sim.advance(1500)
print(json.dumps({"hash": sim_hash(sim), "mass": sim.state.mass.tobytes().hex()[:64], "dt": sim.dt,
                  "numba_target": __import__("numba").config.CPU_NAME or "host",
                  "fluid": sim.fluid is not None,
                  "explicit_updates": 0.0 if sim.fluid is None else float(sim.fluid.state[S_EXPLICIT_UPDATES])}))
"""


def _numpy_dispatched() -> list[str]:
    """numpy's runtime-dispatched SIMD targets enabled on this CPU (to switch off)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:       # numpy < 2
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]


def _run(scene: dict, threads: int, baseline: bool) -> dict:
    env = dict(os.environ)
    env.pop("NUMBA_CPU_NAME", None)
    env.pop("NPY_DISABLE_CPU_FEATURES", None)
    env["NUMBA_NUM_THREADS"] = "2"
    if baseline:
        env["NUMBA_CPU_NAME"] = "generic"
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(_numpy_dispatched())
    out = subprocess.run([sys.executable, "-c", SCRIPT, json.dumps(scene), str(threads)], env=env,
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("kind", ["dry", "undrained", "undrained-heun"])
def test_same_bits_on_every_code_generation_target_and_thread_count(kind):
    """undrained: kappa_c = 1e-5, where the porous wall cells make the auto solver take backward Euler
    (CG); undrained-heun: kappa_c = 1e-6 at fluid.step 0.25 t0, where it takes the explicit Heun
    step every update."""
    scene = dict(SCENE, seed=2 + int(os.environ.get("GOUGE_TEST_SEED_OFFSET", "0")))
    if kind != "dry":
        scene["fluid"] = {"permeability": 1e-5} if kind == "undrained" else {"permeability": 1e-6, "step": 0.25}
    host1 = _run(scene, 1, baseline=False)
    assert host1["fluid"] == (kind != "dry")
    if kind == "undrained-heun":
        assert host1["explicit_updates"] > 0
    runs = {"host, 2 threads": _run(scene, 2, baseline=False)}
    if platform.machine() in ("x86_64", "AMD64"):
        runs["generic + numpy without SIMD dispatch, 1 thread"] = _run(scene, 1, baseline=True)
        runs["generic + numpy without SIMD dispatch, 2 threads"] = _run(scene, 2, baseline=True)
    for name, other in runs.items():
        assert other["mass"] == host1["mass"] and other["dt"] == host1["dt"], name
        assert other["hash"] == host1["hash"], (name, host1, other)


def test_portable_cube_is_two_correctly_rounded_products():
    """Why gouge_cli.model.portable exists: numpy's x**3 may run SIMD code whose last bit depends on the
    CPU; the cube used for masses is exactly (x*x)*x with two IEEE roundings (the same bits
    everywhere), within 2 ulp of the exact rational cube."""
    from fractions import Fraction
    rng = np.random.default_rng(0)
    x = rng.uniform(0.25, 0.75, 2000)
    cube = portable.cube(x)
    for value, c in zip(x[:200], cube[:200]):
        exact = Fraction(float(value)) ** 3
        assert abs(Fraction(float(c)) - exact) <= 2 * Fraction(float(np.spacing(c)))
        assert c == float(Fraction(float(Fraction(float(value)) ** 2)) * Fraction(float(value)))
    assert portable.power(8.0, 1.0 / 3.0) == pytest.approx(2.0, rel=1e-15)
    assert portable.power(0.0, 1.5) == 0.0


def test_state_hash_sees_every_bit():
    arrays = {"x": np.array([0.1, 0.2]), "counters": np.array([1, 2], np.int64)}
    h = provenance.state_hash(arrays)
    flipped = {"x": np.array([0.1, np.nextafter(0.2, 1.0)]), "counters": arrays["counters"]}
    assert provenance.state_hash(flipped) != h
    assert provenance.state_hash({k: v.copy() for k, v in arrays.items()}) == h
    assert provenance.state_hash(arrays, {"pressure": np.zeros(3)}) != h


def test_bit_risks_name_library_changes_only():
    here = provenance.collect(threads=1)
    assert provenance.bit_risks(here, here) == []
    assert provenance.bit_risks({}, here) == []
    other = json.loads(json.dumps(here))
    other["libraries"]["numpy"] = "1.0.0"
    other["cpu"]["model"] = "another CPU"
    risks = provenance.bit_risks(other, here)
    assert risks == [f"numpy 1.0.0 -> {here['libraries']['numpy']}"]
    assert "numpy 1.0.0" in provenance.risk_line(other, "latest.h5")
