"""The GPU engine on a real device: bits against the CPU, ensembles, throughput (scripts/gpu_check.sh).

    python scripts/gpu_check.py OUT_DIR [--quick]

Writes OUT_DIR/gpu_check.json, one entry per stage as it finishes (a stage that fails records
its error and the next one runs):
* lockstep300: a compacted 300-grain layer (sorting every rebuild) on the GPU and the CPU,
  compared after 1, 1, 98, 900 and 9,000 steps (1e4 in all), every State array bit for bit;
* ensemble: three 300-grain layers as one ensemble equal to each alone;
* bench10k: the `gouge bench` 10,000-grain scene (prepared state from runs/bench/cache if there,
  else compacted and pre-sheared here): CPU rates on 2 threads and all cores, GPU rates for
  B = 1, 8, 32 layers (device resident, launch_steps steps per launch) and for one step per
  launch (host launch overhead), the GPU state after the timed steps against the CPU's (hash),
  and the same GPU run twice (hash).
"""

from __future__ import annotations

import copy
import json
import sys
import time
import traceback
from pathlib import Path

import numba
import numpy as np

from gouge_cli.driver.simulation import Simulation
from gouge_cli.kernels import layout as L
from gouge_cli.studies import gpu_check
from gouge_cli.studies.bench import bench_config, prepare

OUT = Path(sys.argv[1])
QUICK = "--quick" in sys.argv
RESULTS: dict = {}


def stage(name):
    def wrap(fn):
        t0 = time.perf_counter()
        try:
            RESULTS[name] = fn()
        except Exception:
            RESULTS[name] = {"error": traceback.format_exc()[-3000:]}
        RESULTS[name + "_seconds"] = time.perf_counter() - t0
        (OUT / "gpu_check.json").write_text(json.dumps(RESULTS, indent=1, default=str))
        print(name, json.dumps(RESULTS[name], default=str)[:2000], flush=True)
        return fn
    return wrap


@stage("device")
def _device():
    from numba import cuda

    d = cuda.get_current_device()
    return {"name": d.name.decode() if isinstance(d.name, bytes) else str(d.name),
            "compute_capability": d.compute_capability, "sms": d.MULTIPROCESSOR_COUNT,
            "numba": numba.__version__, "cpu_threads": numba.config.NUMBA_NUM_THREADS}


@stage("lockstep300")
def _lockstep300():
    sim = gpu_check.scene(300, 15.0, seed=2, kick=0.02)
    chunks = (1, 1, 98, 900) if QUICK else (1, 1, 98, 900, 9000)
    rows = gpu_check.lockstep(sim, chunks, threads=256)
    return {"bitwise": all(not r["diff"] for r in rows), "rows": rows}


@stage("ensemble")
def _ensemble():
    sims = [gpu_check.scene(300, 15.0, seed=3 + b, kick=0.01 * (b + 1)) for b in range(3)]
    diffs = gpu_check.ensemble(sims, 2000, threads=256)
    return {"bitwise": diffs == [{}, {}, {}], "diffs": diffs}


def _cpu_rate(sim: Simulation, start: dict, threads: int, steps: int) -> tuple[float, str]:
    sim.threads = threads
    sim.state.restore(start)
    sim.advance(10)
    sim.state.restore(start)
    t0 = time.perf_counter()
    sim.advance(steps)
    rate = steps * sim.state.n / (time.perf_counter() - t0)
    return rate, gpu_check.provenance_hash(sim.state)


@stage("bench10k")
def _bench10k():
    t0 = time.perf_counter()
    sim, start = prepare(10000, 0.89, 0.2, Path("runs/bench/cache"))
    out = {"prepare_seconds": time.perf_counter() - t0, "grains": sim.state.n}
    steps = 500 if QUICK else 2000
    out["cpu_2_threads"], cpu_hash = _cpu_rate(sim, start, 2, steps)
    out["cpu_all_threads"], cpu_hash_all = _cpu_rate(sim, start, numba.config.NUMBA_NUM_THREADS, steps)
    out["cpu_hashes_equal"] = cpu_hash == cpu_hash_all
    sim.state.restore(start)
    gpu = []
    for layers in (1, 8, 32):
        row = gpu_check.throughput(sim.state, sim.params, layers, steps, threads=256, launch_steps=steps // 4)
        gpu.append(row)
    out["gpu"] = gpu
    # one step per launch (host launches and transfers of done/status per step)
    out["gpu_one_step_per_launch"] = gpu_check.throughput(sim.state, sim.params, 1, 200, threads=256, launch_steps=1)
    # the GPU state after `steps` steps against the CPU's, and the same GPU run twice
    hashes = []
    for _ in range(2):
        s = copy.deepcopy(sim.state)
        s.restore(start)
        from gouge_cli.model.gpu_layers import Layers

        Layers([s], sim.params, 256).advance(steps)
        hashes.append(gpu_check.provenance_hash(s))
    out["gpu_hash"] = hashes[0]
    out["cpu_hash"] = cpu_hash
    out["gpu_equals_cpu"] = hashes[0] == cpu_hash
    out["gpu_twice_same"] = hashes[0] == hashes[1]
    out["ratio_gpu_b1_to_cpu_2_threads"] = gpu[0]["grain_steps_per_s"] / out["cpu_2_threads"]
    out["gpu_b32_aggregate"] = gpu[-1]["grain_steps_per_s"]
    return out


print("done", flush=True)
