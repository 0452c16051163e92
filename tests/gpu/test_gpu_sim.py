"""The GPU dry engine (kernels.gpu, model.gpu_layers) against the CPU kernels, under numba-cuda's
CUDA simulator (no GPU needed).

Each check runs tests/gpu/sim_check.py in a fresh process with NUMBA_ENABLE_CUDASIM=1 (the
simulator must be chosen before numba.cuda is imported, and must not reach this process):
* lockstep: a compacted 40-grain layer at a point where its pair list is about to grow, the GPU
  copy starting with too short a list (it overflows and grows on the device), compared after
  1, 1, 8 and 60 steps,
  then 50 and 80 more after the spring is re-attached: every State array bit for bit,
  through list rebuilds and re-numberings (sort_every 1);
* ensemble: three 30-grain layers (different seeds, velocities, one of them loading) advanced
  as one ensemble equal each layer advanced alone, bit for bit;
* planted: a last-bit change in the GPU's contact law alone makes the lockstep comparison fail;
* parallel / planted_parallel: the lockstep with the rebuild's bookkeeping on the whole block
  (kernels.gpu.parallel) and the per-phase timers on; an unstable block sort must fail it;
* `gouge config` refuses numerics.device: gpu (exit 2) where no device is found, and (validation
  only) `gouge run` on the simulated GPU writes the CPU's run.h5 and checkpoint.
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


@pytest.fixture(scope="module")
def parallel_lockstep():
    return _run("parallel")


def test_block_wide_rebuild_equals_cpu_bits(parallel_lockstep):
    """The rebuild's bookkeeping on the whole block (kernels.gpu.parallel: counting sorts by
    integer atomics, prefix sums) gives the CPU's list, numbering and state bit for bit,
    through overflows, rebuilds and re-numberings, with the per-phase timers on."""
    rows = parallel_lockstep["rows"]
    assert [r["diff"] for r in rows] == [{}] * len(rows)
    assert rows[-1]["rebuilds"] - rows[0]["rebuilds"] >= 5
    assert rows[0]["gpu_launches"] >= 1 and rows[3]["gpu_launches"] > 4      # grew its list on the device
    timed = rows[-1]["cycles"]
    assert min(timed[p] for p in ("move", "renumber", "bin", "offsets", "reverse", "law", "sum", "wall")) > 0


def test_unstable_block_sort_is_caught():
    """The block-wide counting sort made unstable (buckets descending): the lockstep fails."""
    rows = _run("planted_parallel")["rows"]
    assert any(r["diff"] for r in rows)


def test_law_probe_compares_every_output_bit():
    """The probe that finds where GPU arithmetic parts from the CPU's (studies.gpu_check.law_probe):
    under the simulator the law is the CPU's Python, so every output of 200 random touching pairs
    agrees bit for bit, and the probe saw touching pairs (non-zero normal forces)."""
    probe = _run("law")
    assert probe["pairs"] == 200 and probe["differ"] == dict.fromkeys(probe["differ"], 0)
    assert probe["first"] is None and probe["touching"] > 150


def test_ensemble_equals_single_layers():
    layers = _run("ensemble")["layers"]
    assert layers == [{}, {}, {}]


def test_planted_change_in_gpu_law_is_caught():
    rows = _run("planted")["rows"]
    assert any(r["diff"] for r in rows)
    assert "force_x" in rows[0]["diff"] or "vx" in rows[0]["diff"] or "x" in rows[0]["diff"]


TINY_RUN = """\
name: tiny
packing: {n_grains: 40, width: 6}
compaction: {min_time: 100, max_time: 100}
loading: {spring_constant: 2.0e-4, velocity: 4.0e-3}
numerics: {sort_every: 1, dt_safety: 0.5}
run: {duration: 40}
output: {series_interval: 2, checkpoint_interval: 10}
"""

GOUGE = "import sys; sys.setswitchinterval(1e-5); from gouge_cli.cli.main import app; app()"


def _gouge(args: list[str], simulator: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_NUM_THREADS="1", GOUGE_GPU_THREADS="2")
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-c", GOUGE, *args], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=300)


def _datasets(path: Path) -> dict:
    import h5py

    out = {}
    with h5py.File(path, "r") as h5:
        h5.visititems(lambda name, obj: out.__setitem__(name, obj[()].tobytes()) if isinstance(obj, h5py.Dataset)
                      else None)
        out["final_state_hash"] = str(h5.attrs.get("final_state_hash"))
    return out


@pytest.mark.validation
def test_gouge_run_on_gpu_writes_the_cpu_run(tmp_path):
    """`gouge run` with numerics.device: gpu (compaction and loading on the GPU engine): the
    same run.h5 series and final state hash, and the same checkpoint, as on the CPU. (~530
    steps; under the simulator ~40 s on a quiet machine: make validate only.)"""
    config = tmp_path / "tiny.yaml"
    config.write_text(TINY_RUN + f"seed: {SEED}\n")
    runs = {}
    for device, simulator in (("cpu", False), ("gpu", True)):
        out = tmp_path / device
        done = _gouge(["run", str(config), "--out", str(out), "--quiet", "--set", f"numerics.device={device}"],
                      simulator)
        assert done.returncode == 0, done.stderr[-3000:]
        runs[device] = (_datasets(out / "run.h5"), _datasets(out / "checkpoints" / "latest.h5"))
    cpu, gpu = runs["cpu"], runs["gpu"]
    assert len(cpu[0]) > 10 and cpu[0]["final_state_hash"] not in ("None", "")
    assert gpu[0] == cpu[0]
    assert gpu[1] == cpu[1]


def test_device_gpu_refused_without_a_gpu(tmp_path):
    """Where numba-cuda finds no device, numerics.device: gpu is exit 2 naming the key."""
    from numba import cuda

    if cuda.is_available():
        pytest.skip("a CUDA device is present")
    done = _gouge(["config", "--set", "numerics.device=gpu"], simulator=False)
    assert done.returncode == 2
    assert "numerics.device" in done.stderr + done.stdout
