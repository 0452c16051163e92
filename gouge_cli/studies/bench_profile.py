"""`gouge bench`'s profiles: the microseconds of each part of a step and of a fluid update,
numba runtime allocations per step, and the contact pass on sub-systems of one packing
(cost per grain against working-set size)."""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from ..driver.simulation import Simulation
from ..kernels import layout as L
from ..kernels import forces as F
from ..kernels import step as K
from .bench_scene import bench_config

def profile_fluid(n_grains: int, start: dict, dt: float, skin: float, permeability: float, threads: int,
                  calls: int = 30) -> dict:
    """Microseconds of one fluid update's parts on the undrained scene (kernels.fluid_update), best
    of 3 x `calls`: the deposit (with the owed half kick and, on one thread, in plain loops, as in
    the running loop), the grid solve
    (serial on any thread count; P and the fluid state restored before each call) and the drag."""
    from ..kernels import fluid_update as F

    sim = Simulation(bench_config(n_grains, dt, skin, permeability), arrays=start)
    sim.threads = threads
    numba.set_num_threads(threads)
    sim.advance(2 * sim.fluid_interval)
    s, fl = sim.state, sim.fluid.record()
    z_bot, z_top = sim.wall_planes()[0], float(s.wall[L.W_Z])
    dt_f = sim.fluid_interval * sim.dt
    kick = (True, s.force_x, s.force_z, s.inv_mass, s.body, 0.5 * sim.dt, sim.params[L.BG_DAMPING],
            s.wall[L.W_VX], s.wall[L.W_VZ])
    fstate, pressure = fl.state.copy(), fl.pressure.copy()

    def reset():
        fl.state[:] = fstate
        fl.pressure[:] = pressure

    def begin():
        F.fluid_begin(s.x, s.z, s.vx, s.vz, s.radius, s.n, s.width, z_bot, z_top, dt_f, fl, kick, threads <= 1)

    def solve():
        F.fluid_solve(s.width, z_bot, z_top, dt_f, fl)

    out = {"n_grains": n_grains, "threads": threads, "dt": dt, "grid": list(fl.pressure.shape),
           "deposit": best_seconds(begin, calls, 3) * 1e6,          # (reads neither P nor the solver state)
           "solve": best_seconds(solve, calls, 3, reset) * 1e6,
           "drag": best_seconds(lambda: F.fluid_drag(s.n, s.width, fl, *sim.drag, 0), calls, 3) * 1e6,
           "cg_iterations": float(fl.state[L.S_ITERATIONS]),
           "explicit": bool(fl.state[L.S_EXPLICIT_UPDATES] > fstate[L.S_EXPLICIT_UPDATES]),
           "solver": sim.config.fluid.solver}
    out["update"] = out["deposit"] + out["solve"] + out["drag"]
    return out


def allocations_per_step(sim: Simulation, start: dict, threads: int, steps: int = 400) -> float | None:
    """numba runtime allocations per step: advance(steps) and advance(4 steps) from the same
    state allocate the same fixed count per call (array arguments), so the difference / 3
    steps is what the step loop allocates. None if NRT statistics are unavailable."""
    try:
        from numba.core.runtime import nrt
        nrt._nrt.memsys_enable_stats()
    except Exception:   # noqa: BLE001 - internal numba API; report unavailable instead
        return None
    sim.threads = threads
    counts = []
    for n in (steps, 4 * steps):
        sim.state.restore(start)
        before = nrt.rtsys.get_allocation_stats().alloc
        sim.advance(n)
        counts.append(nrt.rtsys.get_allocation_stats().alloc - before)
    return (counts[1] - counts[0]) / (3 * steps)


def best_seconds(fn, calls: int, repeats: int, reset=None) -> float:
    """Seconds per call of fn(): the best over `repeats` of the mean over `calls` calls, timing
    fn alone (reset(), if given, runs untimed before each call)."""
    best = math.inf
    for _ in range(repeats):
        total = 0.0
        for _ in range(calls):
            if reset:
                reset()
            t0 = time.perf_counter()
            fn()
            total += time.perf_counter() - t0
        best = min(best, total / calls)
    return best


def profile_step(sim: Simulation, start: dict, threads: int, repeats: int = 50) -> dict:
    """Microseconds per step in each part: contact pass (law pass + sum pass, also timed alone),
    the kick pass (the closing half kick of one step, the first of the next and the drift,
    fused), and the neighbour rebuild with the arrays derived from the list (per rebuild, and
    amortised over the measured steps between rebuilds)."""
    sim.threads = threads
    s, p = sim.state, sim.params.copy()
    p[L.THREADS] = threads
    numba.set_num_threads(threads)
    s.restore(start)
    r0, k0 = int(s.counters[L.K_REBUILDS]), s.step
    sim.advance(2000)
    per_rebuild_steps = (s.step - k0) / max(1, int(s.counters[L.K_REBUILDS]) - r0)
    g, lists, pairs = s.grains(), s.lists(), s.pairs()
    sort_every = int(p[L.SORT_EVERY])
    p[L.SORT_EVERY] = 0        # rebuild alone; the re-numbering is timed on its own below
    shear0 = s.shear.copy()
    v0 = (s.vx.copy(), s.vz.copy(), s.spin.copy(), s.x.copy(), s.z.copy())

    def timed(fn, n=repeats, reset=None):
        return best_seconds(fn, n, 3, reset) * 1e6

    def reset():
        s.shear[:] = shear0
        s.vx[:], s.vz[:], s.spin[:], s.x[:], s.z[:] = v0

    nb = F.force_parts(threads, s.n, pairs.pair_buf.shape[0])
    out = {
        "contact_forces": timed(lambda: K.compute_forces(g, lists, pairs, s.wall, p, *sim.drag), reset=reset),
        "law_pass": timed(lambda: F.law_pass(nb, g.x, g.z, g.vx, g.vz, g.spin, lists.start, pairs.pair_row,
                                             lists.index, lists.shear, pairs.pair_const, pairs.sum_x, pairs.sum_z,
                                             pairs.sum_t, pairs.pair_buf, p), reset=reset),
        "sum_pass": timed(lambda: F.sum_pass(nb, pairs.sum_start, pairs.sum_end, pairs.sum_x, pairs.sum_z,
                                             pairs.sum_t, g.force_x, g.force_z, g.torque, *sim.drag)),
        "kick_drift": timed(lambda: K.kick_drift(g.x, g.z, g.vx, g.vz, g.spin, g.force_x, g.force_z, g.torque,
                                                  g.inv_mass, g.inv_inertia, g.body, lists.x_build, lists.z_build,
                                                  True, p, lists.cell_of), reset=reset),
        "rebuild_each": timed(lambda: (K.rebuild(g, lists, p, s.counters, *sim.drag), F.derive_list(g, lists, pairs)),
                              n=max(3, repeats // 10), reset=reset),
        "steps_per_rebuild": per_rebuild_steps,
        "renumber_each": timed(lambda: K.renumber(g, lists, *sim.drag, p[L.WIDTH]), n=max(3, repeats // 10)),
        "rebuilds_per_renumber": sort_every,
    }
    out["rebuild_per_step"] = out["rebuild_each"] / per_rebuild_steps
    out["renumber_per_step"] = out["renumber_each"] / (per_rebuild_steps * sort_every) if sort_every else 0.0
    sim.threads = threads
    s.restore(start)
    t0 = time.perf_counter()
    sim.advance(500)
    out["whole_step"] = (time.perf_counter() - t0) / 500 * 1e6
    s.restore(start)
    return out


def sub_system(s, m: int) -> tuple[L.Grains, L.Lists, L.Pairs]:
    """Grains 0..m-1 of state s and the listed pairs among them (same order, shear copied), as the
    records kernels.forces.contact_forces takes for one thread (without drag): fields the contact
    pass does not read are empty, every field has the state's dtype (an int64 list array here
    once compiled the kernel a second time); the reverse list and pair constants are derived on
    the first call."""
    rows = np.repeat(np.arange(s.n), np.diff(s.start))
    npairs = int(s.start[-1])
    keep = (rows < m) & (s.index[:npairs] < m)
    start = np.zeros(m + 1, s.start.dtype)
    np.cumsum(np.bincount(rows[keep], minlength=m), out=start[1:])
    per_grain = ("x", "z", "vx", "vz", "spin", "radius", "mass")
    grains = L.Grains(**{name: getattr(s, name)[:m].copy() if name in per_grain else
                         np.zeros(m if name in ("force_x", "force_z", "torque") else 0, getattr(s, name).dtype)
                         for name in L.Grains._fields})
    index = s.index[:npairs][keep].copy()
    lists = L.Lists(**{name: np.zeros(1, getattr(s, name).dtype) for name in L.Lists._fields})._replace(
        start=start, index=index, shear=s.shear[:npairs][keep].copy(), layout=np.full(L.N_LAYOUT, -1, s.layout.dtype),
        rev_start=np.zeros(m + 1, s.rev_start.dtype), rev_slot=np.zeros(index.size, s.rev_slot.dtype))
    pairs = L.Pairs(*(np.zeros(index.size) for _ in range(4)), np.zeros((L.N_PAIR_CONST, index.size)),
                    np.zeros((1, L.N_BUF, L.PAIR_BUF)), np.zeros(index.size, s.pair_row.dtype),
                    *(np.zeros(2 * index.size + 1) for _ in range(3)), np.zeros(m + 1, s.sum_start.dtype),
                    np.zeros(2 * index.size + m + 2, s.sum_end.dtype))
    return grains, lists, pairs


def footprint_profile(sim: Simulation, start: dict, sizes, repeats: int = 5) -> list[dict]:
    """Contact pass on one thread over the first m grains (in list order) of one packing, for each
    m in sizes: the same kind of rows and pairs, working sets of different sizes. Nanoseconds
    per grain (best of `repeats`), pairs per grain and the bytes the pass touches."""
    s = sim.state
    s.restore(start)
    p = sim.params.copy()
    p[L.THREADS] = 1
    numba.set_num_threads(1)
    out = []
    for m in sorted(v for v in sizes if v <= s.n):
        grains, lists, pairs = sub_system(s, m)
        npairs = int(lists.start[-1])
        none = np.zeros(0)
        F.contact_forces(grains, lists, pairs, none, none, p)
        best = best_seconds(lambda: F.contact_forces(grains, lists, pairs, none, none, p), max(3, 200000 // m),
                            repeats)
        touched = sum(a.nbytes for a in (*grains, lists.start, lists.index, lists.shear))   # grains, list, forces
        out.append({"of_n_grains": s.n, "first_grains": m, "pairs_per_grain": npairs / m,
                    "working_set_mb": touched / 2**20, "ns_per_grain": best * 1e9 / m})
    return out
