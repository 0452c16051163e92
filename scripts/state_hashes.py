"""Print the dry and undrained state hashes of the two 300-grain reference scenes
(seed 2, 3,000 loading steps), the bitwise check of any refactoring.

    NUMBA_NUM_THREADS=1 .venv/bin/python scripts/state_hashes.py   (T=2 for two threads)

Expected (1 or 2 threads): dry e9db53e39dbb39ad (since main 3548805), undrained with the implicit solver
79034979a2618553 (since efb21c5; the default solver, auto, takes the implicit step there: the porous cells at the walls
put dt_f above 0.25 x the FTCS bound); undrained with kappa_c = 1e-6, where auto takes the explicit (Heun)
step: see the README.
"""

import os

from gouge_cli.config import build_config
from gouge_cli.io.provenance import sim_hash
from gouge_cli.driver.simulation import Simulation

SCENE = {"packing": {"n_grains": 300, "width": 15}, "compaction": {"min_time": 200.0, "max_time": 600.0},
         "loading": {"spring_constant": 2e-4, "velocity": 4e-3}, "numerics": {"sort_every": 1}, "seed": 2}
KINDS = {"dry": None, "undrained": {"permeability": 1e-5},
         "undrained-implicit": {"permeability": 1e-5, "solver": "implicit"},
         "undrained-heun": {"permeability": 1e-6, "solver": "auto"}}
for kind, fluid in KINDS.items():
    data = dict(SCENE)
    if fluid:
        data["fluid"] = fluid
    sim = Simulation(build_config(data))
    sim.threads = int(os.environ.get("T", "1"))
    sim.compact()
    sim.start_fluid()
    sim.advance(3000)
    explicit = "" if sim.fluid is None else f" ({sim.fluid.state[7]:.0f} of {sim.fluid.state[6]:.0f} updates explicit)"
    print(kind, sim_hash(sim) + explicit)
