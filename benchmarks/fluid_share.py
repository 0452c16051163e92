"""The undrained fluid share of a step at the thesis step, steadier than the bench's paired share.

    .venv/bin/python benchmarks/fluid_share.py THREADS [REPEATS STEPS COPIES] [SOLVER ...]
    e.g. benchmarks/fluid_share.py 1 30 300 4 implicit auto
    (GOUGE_SHARE_VERBOSE=1 also prints each copy's fastest repeat)

The bench's 10,000-grain sheared layer (runs/bench/cache) at the dt of thesis Run 24 (0.09 t0, a
fluid update every 3 steps, kappa_c 1e-5): one dry Simulation and one undrained per fluid.solver,
each in COPIES separate copies (their own arrays: a copy's memory placement moves its speed by a
few per cent), take turns for REPEATS repeats of STEPS steps from the same state. Per copy the
fastest repeat counts (a shared VM slows a core for seconds at a time: many short repeats find its
quiet stretches); the median over copies is
reported, as us per step, share = 1 - dry / undrained and the cost of one update beyond the dry
steps [us].
"""

import os
import sys
import time

import numpy as np

from gouge_cli.driver.simulation import Simulation
from gouge_cli.studies import bench as B

threads = int(sys.argv[1])
repeats, steps, copies = (int(a) for a in (sys.argv[2:5] + ["30", "300", "4"][len(sys.argv[2:5]):]))
solvers = sys.argv[5:] or ["implicit", "auto"]
_, start = B.prepare(10000, 0.89, 0.2, B.Path("runs/bench/cache"))
dt = B.choose_dt(B.run24_config())
sims = {}
for k in range(copies):
    sims[("dry", k)] = Simulation(B.bench_config(10000, dt, 0.2), arrays=start)
    for solver in solvers:
        sims[(solver, k)] = Simulation(B.bench_config(10000, dt, 0.2, 1e-5, solver), arrays=start)
fluid_start = {key: sim.fluid.arrays() for key, sim in sims.items() if sim.fluid is not None}
for sim in sims.values():
    sim.threads = threads
times = {key: [] for key in sims}
for r in range(repeats + 1):                       # (the first round warms up)
    for key, sim in sims.items():
        sim.state.restore(start)
        if sim.fluid is not None:
            sim.fluid.restore(fluid_start[key])
        sim.advance(6)
        t0 = time.perf_counter()
        sim.advance(steps)
        if r:
            times[key].append((time.perf_counter() - t0) / steps * 1e6)
fastest = {key: min(v) for key, v in times.items()}
if "GOUGE_SHARE_VERBOSE" in os.environ:
    print({f"{k[0]}{k[1]}": round(v, 1) for k, v in fastest.items()})
dry = float(np.median([fastest[("dry", k)] for k in range(copies)]))
print(f"{threads} thread(s), {copies} copies x {repeats} repeats of {steps} steps: dry {dry:.1f} us/step")
for solver in solvers:
    wet = float(np.median([fastest[(solver, k)] for k in range(copies)]))
    interval = sims[(solver, 0)].fluid_interval
    print(f"  {solver:9s} {wet:.1f} us/step, fluid share {100 * (1 - dry / wet):.1f} %, one update "
          f"{(wet - dry) * interval:.0f} us beyond the dry steps (an update every {interval} steps)")
