"""The GPU dry engine checked against the CPU kernels: lockstep comparison, ensembles, throughput.

Used by tests/gpu (under numba-cuda's simulator, tiny scenes) and scripts/gpu_check.sh (on a
GPU). ``lockstep`` advances a copy of a scene on the GPU (model.gpu_layers) and the scene itself
on the CPU (kernels.step.advance) chunk by chunk and lists every array that differs after each
chunk; ``ensemble`` runs B copies with different velocities as one ensemble and compares each
with its own single-layer run; ``throughput`` times grain-steps per second.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ..config import build_config
from ..driver import compaction
from ..driver.simulation import Simulation
from ..kernels import layout as L
from ..model.gpu_layers import Layers
from ..model.state import EVOLVING, State

# what a restart needs (State.EVOLVING) and the fixed properties the re-numbering moves
COMPARED = EVOLVING + ("radius", "mass", "inv_mass", "inv_inertia", "body", "top")


def scene(n_grains: int, width: float, seed: int = 1, kick: float = 0.05, sort_every: int = 1,
          compact: bool = True) -> Simulation:
    """A small dry scene, compacted on the CPU (if `compact`) and still in compaction, whose free
    grains get random velocities (normal, `kick` [v0] per component, from `seed`), so that the
    list is rebuilt (and the grains re-numbered every `sort_every` rebuilds) within a few
    hundred steps."""
    sim = Simulation(build_config({"seed": seed, "packing": {"n_grains": n_grains, "width": width},
                                   "numerics": {"sort_every": sort_every},
                                   "compaction": {"min_time": 100.0, "max_time": 400.0},
                                   "loading": {"spring_constant": 2e-4, "velocity": 4e-3}}))
    if compact:
        compaction.compact(sim)
    s = sim.state
    free = s.body == L.FREE
    rng = np.random.default_rng(seed)
    s.vx[free] += rng.normal(0.0, kick, free.sum())
    s.vz[free] += rng.normal(0.0, kick, free.sum())
    return sim


def differences(a: State, b: State, needed: bool = True) -> dict[str, float]:
    """{array: largest |a - b|} of every compared array that is not bit-identical; needed=False
    leaves out counters[K_NEEDED_CAPACITY] (the list size asked for at the last overflow)."""
    out = {}
    npairs = int(a.start[-1])
    for name in COMPARED:
        x = getattr(a, name)
        y = getattr(b, name)
        if name == "counters" and not needed:
            x, y = x.copy(), y.copy()
            x[L.K_NEEDED_CAPACITY] = y[L.K_NEEDED_CAPACITY] = 0
        if name in ("index", "shear"):
            x, y = x[:npairs], y[:npairs]
        if x.shape != y.shape:
            out[name] = float("inf")
        elif x.tobytes() != y.tobytes():
            out[name] = float(np.max(np.abs(x.astype(np.float64) - y.astype(np.float64))))
    return out


def lockstep(sim: Simulation, chunks, threads: int, capacity: int | None = None, parallel: bool | None = None,
             timed: bool = False) -> list[dict]:
    """Advance the scene chunk by chunk on the CPU and a copy of it on the GPU; after each chunk
    a row {step, pairs, rebuilds, gpu_launches (so far), diff} (timed: and cycles, the GPU's
    per-phase clock of that chunk). capacity: start the GPU copy with this few pair slots (at
    least N and its pairs), so that it runs out of list and grows it where the CPU does not
    (counters[K_NEEDED_CAPACITY] is then not compared). parallel, timed: as model.gpu_layers.Layers."""
    gpu = copy.deepcopy(sim.state)
    if capacity is not None:
        npairs = int(gpu.start[-1])
        gpu._allocate_pairs(max(capacity, gpu.n, npairs), keep=npairs)     # (>= N: re-numbering scratch)
    layers = Layers([gpu], sim.params, threads, parallel=parallel, timed=timed)
    rows = []
    for n in chunks:
        layers.params[0] = sim.params            # a phase change on the host reaches the GPU
        layers.advance(int(n))
        sim.advance(int(n))                       # kernels.step.advance, growing the list as needed
        s = sim.state
        rows.append({"step": int(s.step), "pairs": int(s.counters[L.K_PAIRS]), "rebuilds": int(s.counters[L.K_REBUILDS]),
                     "gpu_launches": layers.launches, "diff": differences(s, gpu, capacity is None)})
        if timed:
            rows[-1]["cycles"] = {k: int(v[0]) for k, v in layers.phase_cycles().items()}
    return rows


def ensemble(sims: list[Simulation], nsteps: int, threads: int) -> list[dict[str, float]]:
    """The scenes advanced together as one GPU ensemble and each alone as a GPU single layer;
    per layer, the arrays in which the two differ."""
    together = [copy.deepcopy(s.state) for s in sims]
    Layers(together, [s.params for s in sims], threads).advance(nsteps)
    out = []
    for s, t in zip(sims, together):
        alone = copy.deepcopy(s.state)
        Layers([alone], s.params, threads).advance(nsteps)
        out.append(differences(alone, t))
    return out


def throughput(state: State, params: np.ndarray, layers: int, steps: int, threads: int, launch_steps: int,
               parallel: bool | None = None, timed: bool = False) -> dict:
    """Grain-steps per second of `layers` copies of `state` on the GPU (device resident: one
    upload, timed launches of launch_steps steps, one download), after a warm-up launch; timed:
    also the per-phase share of layer 0's cycles (``phases``, fractions of the timed steps)."""
    copies = [copy.deepcopy(state) for _ in range(layers)]
    ens = Layers(copies, params, threads, parallel=parallel, timed=timed)
    ens.upload()
    ens.run(launch_steps, launch_steps)               # compile and warm up
    from numba import cuda

    cuda.synchronize()
    before = ens.phase_cycles()
    rebuilds = int(ens.d["counters"].copy_to_host()[0, L.K_REBUILDS])
    t0 = time.perf_counter()
    ens.run(steps, launch_steps)
    cuda.synchronize()
    seconds = time.perf_counter() - t0
    cycles = {k: int(v[0] - before[k][0]) for k, v in ens.phase_cycles().items()}
    ens.download()
    out = {"layers": layers, "grains": state.n, "steps": steps, "launch_steps": launch_steps, "threads": threads,
           "parallel": ens.parallel, "seconds": seconds, "grain_steps_per_s": layers * state.n * steps / seconds,
           "rebuilds": int(copies[0].counters[L.K_REBUILDS]) - rebuilds,      # layer 0's, in the timed steps
           "hashes_equal": len({provenance_hash(c) for c in copies}) == 1}
    if timed:
        total = max(sum(cycles.values()), 1)
        out["cycles_per_step"] = total / steps
        out["phases"] = {k: round(v / total, 4) for k, v in cycles.items()}
    return out


def provenance_hash(state: State) -> str:
    from ..io.provenance import state_hash

    return state_hash(state.arrays())


def law_probe(n: int = 4096, seed: int = 1, params: np.ndarray | None = None) -> dict:
    """The contact law and pair constants (kernels.contact) on the GPU, one thread per pair, for n
    random touching pairs, against the CPU kernels' results: per output, how many pairs differ
    in any bit, and the first such pair's inputs (where the GPU's arithmetic departs from the
    CPU's, if it does). params: a scene's params (default: the demo scene's)."""
    from numba import cuda

    from ..kernels.contact import pair_constants, pair_force
    from ..kernels.gpu.device import probe_law

    if params is None:
        params = Simulation(build_config({"packing": {"n_grains": 40, "width": 6}})).params
    rng = np.random.default_rng(seed)
    ri, rj = rng.uniform(0.35, 0.65, n), rng.uniform(0.35, 0.65, n)
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    dist = (ri + rj) * (1.0 - rng.uniform(0.0, 0.02, n))
    inp = np.stack([ri, rj, np.pi * ri ** 2, np.pi * rj ** 2, dist * np.cos(angle), dist * np.sin(angle),
                    rng.normal(0, 1e-3, n), rng.normal(0, 1e-3, n), rng.normal(0, 1e-2, n), rng.normal(0, 1e-2, n),
                    rng.normal(0, 1e-4, n)], axis=1)
    consts = np.array([params[L.DT], params[L.C_NORMAL], params[L.C_TANGENTIAL], params[L.DAMPING],
                       params[L.FRICTION]])

    out = cuda.device_array((n, 9))
    probe_law[(n + 127) // 128, 128](cuda.to_device(inp), cuda.to_device(consts), out)
    gpu = out.copy_to_host()
    cpu = np.empty_like(gpu)
    for k in range(n):
        a = inp[k]
        r_ij, m_ij = pair_constants(a[0], a[1], a[2], a[3])
        cpu[k, :2] = r_ij, m_ij
        cpu[k, 2:] = pair_force(a[4], a[5], a[6], a[7], a[8], a[9], a[0], a[1], r_ij, m_ij, a[10], *consts)
    names = ("r_ij", "m_ij", "fx", "fz", "torque_i", "torque_j", "shear", "overlap", "normal_force")
    differ = gpu.view(np.int64) != cpu.view(np.int64)
    first = int(np.argmax(differ.any(axis=1))) if differ.any() else None
    return {"pairs": n, "touching": int((cpu[:, 8] > 0.0).sum()),
            "differ": {name: int(differ[:, c].sum()) for c, name in enumerate(names)},
            "first": None if first is None else {"inputs": inp[first].tolist(), "gpu": gpu[first].tolist(),
                                                  "cpu": cpu[first].tolist()}}
