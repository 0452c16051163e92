"""The scene `gouge bench` times: the sheared layer of the LAMMPS deck (:func:`bench_config`),
compacted and pre-sheared once per size, dt, skin and kernel version (:func:`prepare`, cached as
npz since pre-shearing 160,000 grains takes minutes)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from .. import __version__
from ..config import build_config
from ..driver.compaction import compact
from ..driver.guards import check
from ..driver.simulation import Simulation

CACHE = Path("runs/bench/cache")
DRY_SOURCES = ("kernels/step.py", "kernels/neighbors.py", "kernels/contact.py", "kernels/reorder.py", "kernels/layout.py",
               "model/packing.py", "model/params.py", "driver/simulation.py", "model/state.py", "config.py",
               "model/timestep.py", "model/portable.py")     # (and bench_config below)


def bench_config(n_grains: int, dt: float, skin: float, permeability: float | None = None, solver: str = "auto"):
    fluid = {"permeability": permeability, "solver": solver} if permeability else None
    return build_config({
        "fluid": fluid,
        "name": f"bench{n_grains}",
        "packing": {"n_grains": n_grains},
        "loading": {"normal_stress": 3e-4, "spring_constant": 1e-2, "velocity": 1e-3},
        "numerics": {"dt": dt, "skin": skin},
        "compaction": {"min_time": 200.0, "max_time": 4000.0, "wall_velocity_tol": 1.0},
    })


def state_bytes(sim: Simulation) -> int:
    """Bytes of the state's arrays."""
    s = sim.state
    return sum(v.nbytes for v in vars(s).values() if isinstance(v, np.ndarray))


def dry_digest() -> str:
    """Hash of the sources a pre-sheared dry state depends on (the cache key)."""
    h = hashlib.sha256(__version__.encode())
    for name in DRY_SOURCES:
        h.update((Path(__file__).resolve().parents[1] / name).read_bytes())
    return h.hexdigest()[:16]


def prepare(n_grains: int, dt: float, skin: float, cache: Path | None = None) -> tuple[Simulation, dict]:
    """Compacted and pre-sheared scene, and its state arrays for identical restarts; read from
    / written to `cache` (a folder) when given."""
    path = None
    if cache is not None:
        path = Path(cache) / f"prep_{n_grains}_{dt:g}_{skin:g}_{dry_digest()}.npz"
        if path.is_file():
            with np.load(path) as saved:
                arrays = {k: saved[k] for k in saved.files}
            sim = Simulation(bench_config(n_grains, dt, skin), arrays=arrays)
            return sim, sim.state.arrays()
    sim = Simulation(bench_config(n_grains, dt, skin))
    compact(sim)
    sim.advance(int(80 * sim.state.width))
    check(sim)
    start = sim.state.arrays()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **start)
        os.replace(tmp, path)
    return sim, start
