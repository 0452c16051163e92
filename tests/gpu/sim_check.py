"""Runs a GPU check under numba-cuda's simulator and prints its result as JSON (run by
test_gpu_sim.py in a fresh process: NUMBA_ENABLE_CUDASIM must be set before numba.cuda is
imported, and only in this process). GOUGE_GPU_DEVICE=1: on the real device instead
(scripts/gpu_check.sh).

    python tests/gpu/sim_check.py lockstep|parallel|ensemble|law|planted|planted_parallel [seed]

parallel: the lockstep comparison with the rebuild's bookkeeping on the whole block
(kernels.gpu.parallel) and the per-phase timers on; planted_parallel: the same with the
block-wide counting sort made unstable (each bucket sorted descending), which must be caught.
"""

from __future__ import annotations

import json
import os
import sys

DEVICE = os.environ.get("GOUGE_GPU_DEVICE") == "1"
if not DEVICE:
    os.environ["NUMBA_ENABLE_CUDASIM"] = "1"
    sys.setswitchinterval(1e-5)     # the simulator's block threads meet at every __syncthreads

from gouge_cli.kernels import layout as L  # noqa: E402
from gouge_cli.studies import gpu_check  # noqa: E402

THREADS = 64 if DEVICE else 3      # threads per block (simulated: fewer than grains, not a divisor of N)


def plant():
    """A last-bit change in the GPU's contact law only (the CPU kernels are untouched)."""
    from numba import cuda

    from gouge_cli.kernels import contact
    from gouge_cli.kernels.gpu import device

    law = contact.pair_force.py_func

    def planted(*args):
        fx, fz, ti, tj, ds, overlap, fn = law(*args)
        return fx * (1.0 + 2.0 ** -52), fz, ti, tj, ds, overlap, fn

    device.d_pair_force = cuda.jit(device=True)(planted)


def plant_parallel():
    """Each bucket of the block-wide counting sort in descending order (not the CPU's stable order)."""
    from numba import cuda

    from gouge_cli.kernels.gpu import parallel

    def descending(values, lo, hi, carry):
        for a in range(lo + 1, hi):
            for b in range(a, lo, -1):
                if values[b - 1] < values[b]:
                    values[b - 1], values[b] = values[b], values[b - 1]
                    carry[b - 1], carry[b] = carry[b], carry[b - 1]

    parallel._sort_segment = cuda.jit(device=True)(descending)


def growing(sim, steps: int, tries: int = 30):
    """`sim` advanced, 50 steps at a time, to a point where its pair list outgrows max(N, its
    present length) within `steps` steps (a GPU copy started with that capacity must then grow
    its list on the device), whatever the packing's seed."""
    import copy

    for _ in range(tries):
        probe = copy.deepcopy(sim)
        capacity = max(probe.state.n, int(probe.state.start[-1]))
        for _ in range(steps):
            probe.advance(1)
            if int(probe.state.start[-1]) > capacity:
                return sim
        sim.advance(50)
    raise SystemExit(f"the pair list did not grow within {steps} steps at any of {tries} starts")


def main(mode: str, seed: int):
    if mode == "planted":
        plant()
    if mode == "planted":
        return {"rows": gpu_check.lockstep(gpu_check.scene(40, 6.0, seed), (1, 2), THREADS)}
    if mode == "planted_parallel":
        plant_parallel()
        return {"rows": gpu_check.lockstep(gpu_check.scene(40, 6.0, seed), (20, 40), THREADS, parallel=True)}
    if mode in ("lockstep", "parallel"):
        par = mode == "parallel"
        sim = growing(gpu_check.scene(40, 6.0, seed), 70)
        rows = gpu_check.lockstep(sim, (1, 1, 8, 60), THREADS, capacity=1, parallel=par, timed=par)
        sim.start_loading()                          # spring and drive on, no background damping
        rows += gpu_check.lockstep(sim, (50, 80), THREADS, parallel=par, timed=par)
        return {"rows": rows, "loading": sim.phase == L.LOADING}
    if mode == "law":
        return gpu_check.law_probe(200, seed)
    if mode == "ensemble":
        sims = [gpu_check.scene(30, 5.0, seed + b, kick=0.03 * (b + 1), compact=False) for b in range(3)]
        sims[2].start_loading()                      # a layer with other parameters (drive on)
        return {"layers": gpu_check.ensemble(sims, 40, THREADS)}
    raise SystemExit(f"unknown mode {mode!r}")


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 1)))
