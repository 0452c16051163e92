"""The GPU engine on a real device: bits against the CPU, ensembles, throughput (scripts/gpu_check.sh).

    python scripts/gpu_check.py OUT_DIR [--quick]

Writes OUT_DIR/gpu_check.json, one entry per stage as it finishes (a stage that fails records
its error and the next one runs):
* lockstep300: a compacted 300-grain layer (sorting every rebuild) on the GPU and the CPU,
  compared after 1, 1, 98, 900 and 9,000 steps (1e4 in all), every State array bit for bit,
  with the rebuild's bookkeeping on thread 0 (serial) and on the whole block (parallel);
* ensemble: three 300-grain layers as one ensemble equal to each alone;
* bench10k_*: the `gouge bench` 10,000-grain scene (prepared state from runs/bench/cache if
  there, else compacted and pre-sheared here): CPU rates on 2 threads and all cores; B = 1 with
  per-phase cycles (clock64) in both modes; GPU rates for B = 1, 8, 32, 128 layers in both modes
  (device resident, steps/4 steps per launch), B = 1 on 1024 threads, B = 32 timed; the GPU
  state after the timed steps against the CPU's (hash) and the same GPU run twice, both modes;
  one step per launch (host launch overhead).
"""

from __future__ import annotations

import copy
import json
import os
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
OUT.mkdir(parents=True, exist_ok=True)
QUICK = "--quick" in sys.argv
# under numba-cuda's simulator (NUMBA_ENABLE_CUDASIM=1: the rehearsal, every stage at toy size)
SIM = bool(numba.config.ENABLE_CUDASIM)
THREADS, BIG_THREADS = (4, 8) if SIM else (256, 512)
LOCK_SCENE, CHUNKS = ((40, 6.0), (1, 1, 18)) if SIM else ((300, 15.0), (1, 1, 98, 900) if QUICK else (1, 1, 98, 900, 9000))
BENCH_N = 400 if SIM else 10000
LAYERS, TIMED_LAYERS = ((1, 2), 2) if SIM else ((1, 8, 32, 128), 32)
STEPS = 20 if SIM else (500 if QUICK else 2000)
if SIM:
    sys.setswitchinterval(1e-5)     # the simulator's block threads meet at every __syncthreads
RESULTS: dict = {}


ONLY = set(filter(None, os.environ.get("GPU_CHECK_ONLY", "").split(",")))   # run only these stages


def stage(name):
    def wrap(fn):
        if ONLY and name not in ONLY:
            return fn
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
    name = getattr(d, "name", "simulator")
    return {"name": name.decode() if isinstance(name, bytes) else str(name),
            "compute_capability": getattr(d, "compute_capability", None),
            "sms": getattr(d, "MULTIPROCESSOR_COUNT", None), "clock_khz": getattr(d, "CLOCK_RATE", None),
            "numba": numba.__version__, "cpu_threads": numba.config.NUMBA_NUM_THREADS}


@stage("law_probe")
def _law_probe():
    """The contact law alone, GPU against CPU, bit for bit (where do the bits part, if they do)."""
    return gpu_check.law_probe(64 if SIM else 4096)


@stage("lockstep_one_thread")
def _lockstep_one_thread():
    """The lockstep with one thread per block (no thread can race another)."""
    sim = gpu_check.scene(*LOCK_SCENE, seed=2, kick=0.02)
    rows = gpu_check.lockstep(sim, (1, 1, 8), threads=1, parallel=False)
    return {"bitwise": all(not r["diff"] for r in rows), "rows": rows}


@stage("lockstep300")
def _lockstep300():
    sim = gpu_check.scene(*LOCK_SCENE, seed=2, kick=0.02)
    out = {}
    for parallel in (False, True):
        rows = gpu_check.lockstep(copy.deepcopy(sim), CHUNKS, threads=THREADS, parallel=parallel)
        out["parallel" if parallel else "serial"] = {"bitwise": all(not r["diff"] for r in rows), "rows": rows}
    return out


@stage("ptx")
def _ptx():
    """What the compiled kernel's bits depend on, read from its PTX on this machine."""
    import re

    import numba_cuda

    from gouge_cli.kernels.gpu import dry

    out = {"numba_cuda": getattr(numba_cuda, "__version__", "?")}
    for sig, ptx in dry.advance_layers.inspect_asm().items():
        out[str(len(out))] = {"fma.rn.f64": ptx.count("fma.rn.f64"),
                              "float atomics": len(re.findall(r"atom\.[a-z.]*\.f(32|64)", ptx)),
                              "div.rn.f64": ptx.count("div.rn.f64"), "div.approx": ptx.count("div.approx"),
                              "sqrt.rn.f64": ptx.count("sqrt.rn.f64"), "sqrt.approx": ptx.count("sqrt.approx")}
    out["registers"] = str(dry.advance_layers.get_regs_per_thread())
    return out


@stage("ensemble")
def _ensemble():
    sims = [gpu_check.scene(*LOCK_SCENE, seed=3 + b, kick=0.01 * (b + 1)) for b in range(3)]
    diffs = gpu_check.ensemble(sims, 20 if SIM else 2000, threads=THREADS)
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


BENCH = {}


@stage("bench10k_cpu")
def _bench10k_cpu():
    t0 = time.perf_counter()
    sim, start = prepare(BENCH_N, 0.89, 0.2, Path("runs/bench/cache"))
    BENCH.update(sim=sim, start=start, steps=STEPS)
    out = {"prepare_seconds": time.perf_counter() - t0, "grains": sim.state.n}
    out["cpu_2_threads"], BENCH["cpu_hash"] = _cpu_rate(sim, start, 2, BENCH["steps"])
    out["cpu_all_threads"], cpu_hash_all = _cpu_rate(sim, start, numba.config.NUMBA_NUM_THREADS, BENCH["steps"])
    out["cpu_hashes_equal"] = BENCH["cpu_hash"] == cpu_hash_all
    out["cpu_threads"] = numba.config.NUMBA_NUM_THREADS
    BENCH["cpu_2_threads"] = out["cpu_2_threads"]
    return out


def _gpu_rate(layers: int, parallel: bool, threads: int = THREADS, timed: bool = False) -> dict:
    sim, start, steps = BENCH["sim"], BENCH["start"], BENCH["steps"]
    sim.state.restore(start)
    row = gpu_check.throughput(sim.state, sim.params, layers, steps, threads=threads, launch_steps=steps // 4,
                               parallel=parallel, timed=timed)
    row["ratio_to_cpu_2_threads"] = row["grain_steps_per_s"] / layers / BENCH["cpu_2_threads"]
    return row


@stage("bench10k_breakdown")
def _breakdown():
    """B = 1, per-phase cycles, the serial phases on thread 0 and on the whole block."""
    return [_gpu_rate(1, parallel, timed=True) for parallel in (False, True)]


@stage("bench10k_gpu")
def _bench10k_gpu():
    rows = RESULTS.setdefault("bench10k_gpu_rows", [])
    runs = [(layers, parallel, THREADS, False) for parallel in (True, False) for layers in LAYERS]
    runs += [(1, True, BIG_THREADS, False), (TIMED_LAYERS, True, THREADS, True)]
    for layers, parallel, threads, timed in runs:
        try:
            rows.append(_gpu_rate(layers, parallel, threads=threads, timed=timed))
        except Exception as exc:          # (too many threads for the kernel's registers, say)
            rows.append({"layers": layers, "parallel": parallel, "threads": threads, "error": repr(exc)[:500]})
        (OUT / "gpu_check.json").write_text(json.dumps(RESULTS, indent=1, default=str))
    return {"rows": len(rows)}


@stage("bench10k_bits")
def _bench10k_bits():
    """The GPU state after `steps` steps against the CPU's, and the same GPU run twice (both modes)."""
    from gouge_cli.model.gpu_layers import Layers

    sim, start, steps = BENCH["sim"], BENCH["start"], BENCH["steps"]
    out = {"cpu_hash": BENCH["cpu_hash"]}
    for parallel in (False, True):
        hashes = []
        for _ in range(2):
            s = copy.deepcopy(sim.state)
            s.restore(start)
            Layers([s], sim.params, THREADS, parallel=parallel).advance(steps)
            hashes.append(gpu_check.provenance_hash(s))
        key = "parallel" if parallel else "serial"
        out[key] = {"gpu_hash": hashes[0], "gpu_equals_cpu": hashes[0] == BENCH["cpu_hash"],
                    "gpu_twice_same": hashes[0] == hashes[1]}
    return out


@stage("one_step_per_launch")
def _one_step():
    sim, start = BENCH["sim"], BENCH["start"]
    sim.state.restore(start)
    return gpu_check.throughput(sim.state, sim.params, 1, 10 if SIM else 200, threads=THREADS, launch_steps=1,
                                parallel=True)


print("done", flush=True)
