"""The reference scenes whose final state hashes pin the simulation's bits ("same bits").

Three 300-grain scenes (15 d wide, seed 2, compaction of 200-600 t0, then 3,000 loading steps at
V = 4e-3 v0 through k = 2e-4 E/d, grains re-numbered at every rebuild): dry; undrained at
kappa_c = 1e-5 d^2, where the porous cells at the walls make the ``auto`` solver take the implicit
(backward Euler) update; undrained at kappa_c = 1e-6 d^2, where ``auto`` takes the explicit
(Heun) update at fluid.step 0.25 t0. The state hash (:func:`gouge_cli.io.provenance.sim_hash`) of each scene's last
state must not depend on the thread count or the CPU; the test suite holds the expected values
(tests/driver/test_golden_hashes.py). A change that is meant to keep the bits is checked with

    python -m gouge_cli.studies.reference [--threads N]

which prints one line per scene: its name, hash, and how many fluid updates were explicit.
"""

from __future__ import annotations

import argparse
import json

from ..config import build_config
from ..driver.compaction import compact
from ..driver.simulation import Simulation
from ..io.provenance import sim_hash
from ..kernels.layout import S_EXPLICIT_UPDATES, S_UPDATES

SCENE = {"packing": {"n_grains": 300, "width": 15}, "compaction": {"min_time": 200.0, "max_time": 600.0},
         "loading": {"spring_constant": 2e-4, "velocity": 4e-3}, "numerics": {"sort_every": 1}, "seed": 2}
FLUIDS = {"dry": None, "undrained": {"permeability": 1e-5},
          "undrained-heun": {"permeability": 1e-6, "step": 0.25}}     # (0.25 t0: every update within Heun's bound)
LOADING_STEPS = 3000


def reference_config(kind: str):
    """The Config of reference scene ``kind`` (a key of :data:`FLUIDS`)."""
    data = dict(SCENE)
    if FLUIDS[kind]:
        data["fluid"] = FLUIDS[kind]
    return build_config(data)


def reference_run(kind: str, threads: int = 1) -> dict:
    """Compact reference scene ``kind``, load it for :data:`LOADING_STEPS` steps on ``threads``
    threads and return {"scene", "hash", "updates", "explicit_updates"} (fluid update counts, 0 dry)."""
    sim = Simulation(reference_config(kind))
    sim.threads = threads
    compact(sim)                 # (ends with start_loading, which starts the fluid)
    sim.advance(LOADING_STEPS)
    updates = explicit = 0
    if sim.fluid is not None:
        updates, explicit = int(sim.fluid.state[S_UPDATES]), int(sim.fluid.state[S_EXPLICIT_UPDATES])
    return {"scene": kind, "hash": sim_hash(sim), "updates": updates, "explicit_updates": explicit}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Final state hashes of the reference scenes.")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", action="store_true", help="one JSON object per scene")
    parser.add_argument("scenes", nargs="*", metavar="SCENE", help=f"any of {', '.join(FLUIDS)} (default: all)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.scenes) - set(FLUIDS))
    if unknown:
        parser.error(f"unknown scene(s) {', '.join(unknown)}; choose from {', '.join(FLUIDS)}")
    for kind in args.scenes or FLUIDS:
        row = reference_run(kind, args.threads)
        print(json.dumps(row) if args.json else
              f"{kind:15s} {row['hash']}  ({row['explicit_updates']} of {row['updates']} fluid updates explicit)",
              flush=True)


if __name__ == "__main__":
    main()
