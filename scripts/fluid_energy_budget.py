"""Energy budget of tests/model/test_fluid_coupling.py::test_undrained_energy_budget_closes, wall still and
free, fluid.step 0.25 and 0.5 t0, for the seed offsets given (scene seed 3 + offset): max |stored + work|
as a fraction of the stored energy's range. Usage (repo root):
PYTHONPATH=. NUMBA_NUM_THREADS=1 python scripts/fluid_energy_budget.py 0 1 2   (a few minutes)."""
import sys, time
sys.path[:0] = ["tests", "tests/model"]
import numpy as np
from gouge_cli.config import build_config
from gouge_cli.workflows.fork import branch_config
from gouge_cli.kernels.layout import W_VZ
from gouge_cli.driver.compaction import compact
from gouge_cli.driver.simulation import Simulation
from factories import scene

def budget(config, arrays, free, step, updates=480):
    branch = branch_config(config, 1e-12)
    upd = {"step": step}
    branch = branch.model_copy(update={"fluid": branch.fluid.model_copy(update=upd)})
    arrays = dict(arrays, wall=arrays["wall"].copy())
    if not free:
        branch = branch.model_copy(update={"loading": branch.loading.model_copy(update={"wall_mass": 1e7})})
        arrays["wall"][W_VZ] = 0.0
    sim = Simulation(branch, arrays=arrays)
    interval = sim.fluid_interval
    sim.advance(interval - sim.state.step % interval)
    width = sim.state.width
    stored, work, zt = [sim.fluid.stored_energy()], [0.0], [sim.wall_planes()[1]]
    for _ in range(updates):
        fx, fz = sim.fluid.drag_x.copy(), sim.fluid.drag_z.copy()
        x0, z0, id0 = sim.state.x.copy(), sim.state.z.copy(), sim.state.id.copy()
        sim.advance(interval)
        order = np.empty_like(id0); order[sim.state.id] = np.arange(id0.size); now = order[id0]
        dx = sim.state.x[now] - x0; dx -= width * np.round(dx / width)
        dz = sim.state.z[now] - z0
        work.append(work[-1] + float(np.dot(fx, dx) + np.dot(fz, dz)))
        stored.append(sim.fluid.stored_energy()); zt.append(sim.wall_planes()[1])
    stored, work = np.array(stored) - stored[0], np.array(work)
    span = np.ptp(stored)
    return float(np.abs(stored + work).max()) / span, span, float(np.ptp(zt))

for off in [int(a) for a in sys.argv[1:]]:
    t = time.time()
    sim = Simulation(build_config(scene(seed=3 + off)))
    compact(sim); sim.advance(sim.steps_for(3000.0))
    cfg, arr = sim.config, sim.state.arrays()
    for step in (0.25, 0.5):
        for free in (False, True):
            m, span, dzt = budget(cfg, arr, free, step)
            print(f"offset {off} step {step} wall {'free ' if free else 'still'}: mismatch {m:.2%} of range {span:.3e} (top plane moved {dzt:.2e} d) [{time.time()-t:.0f} s]", flush=True)
