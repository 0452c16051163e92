"""`gouge bench`: grain-steps per second on the sheared layer, side by side with LAMMPS.

The scene mirrors ``shared/bench/lammps`` (width 200 sqrt(N/1e4) d, one rough row of wall
grains at each side, diameters uniform in [0.8, 1.2], E = 1, nu = 0.2, mu = 0.5,
sigma = 3e-4 E, top wall dragged at 1e-3 v0 by a stiff spring, dt and skin as given):
compaction, ~0.3 strain of pre-shear, then only the steady sheared phase is timed.
Every thread count starts from the same pre-sheared state; their final states are
compared bit for bit.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numba
import numpy as np

from .config import build_config
from .simulation import Simulation


@dataclass
class BenchRow:
    code: str
    n_grains: int
    threads: int
    steps: int
    rate_min: float
    rate_median: float
    rate_max: float
    bytes_per_grain: float | None = None
    identical_to_1_thread: bool | None = None


def bench_config(n_grains: int, dt: float, skin: float, permeability: float | None = None):
    fluid = {"permeability": permeability} if permeability else None
    return build_config({
        "fluid": fluid,
        "name": f"bench{n_grains}",
        "packing": {"n_grains": n_grains},
        "loading": {"normal_stress": 3e-4, "spring_constant": 1e-2, "velocity": 1e-3},
        "numerics": {"dt": dt, "skin": skin},
        "compaction": {"min_time": 200.0, "max_time": 4000.0, "wall_velocity_tol": 1.0},
    })


def state_bytes(sim: Simulation) -> int:
    s = sim.state
    return sum(v.nbytes for v in vars(s).values() if isinstance(v, np.ndarray))


def prepare(n_grains: int, dt: float, skin: float) -> tuple[Simulation, dict]:
    """Compacted and pre-sheared scene, and its state arrays for identical restarts."""
    sim = Simulation(bench_config(n_grains, dt, skin))
    sim.compact()
    sim.advance(int(80 * sim.state.width))
    sim.check()
    return sim, sim.state.arrays()


def time_gouge(sim: Simulation, start: dict, threads: int, steps: int, repeats: int) -> tuple[list[float], dict]:
    sim.threads = threads
    sim.state.restore(start)
    sim.advance(10)  # warm-up (compiled already; touches memory)
    rates = []
    final = None
    for _ in range(repeats):
        sim.state.restore(start)
        t0 = time.perf_counter()
        sim.advance(steps)
        rates.append(steps * sim.state.n / (time.perf_counter() - t0))
        final = sim.state.arrays()
    sim.check()
    return rates, final


def lammps_script() -> Path | None:
    candidates = [os.environ.get("GOUGE_LAMMPS_BENCH", ""),
                  Path(__file__).resolve().parents[1] / "shared" / "bench" / "lammps" / "run_lammps.sh",
                  Path(__file__).resolve().parents[2] / "shared" / "bench" / "lammps" / "run_lammps.sh"]
    for c in candidates:
        if c and Path(c).is_file():
            return Path(c)
    return None


def time_lammps(n_grains: int, ranks: int, steps: int, dt: float, skin: float, style: str) -> float | None:
    script = lammps_script()
    if script is None or shutil.which("lmp") is None:
        return None
    if ranks > 1 and shutil.which("mpirun") is None:
        return None
    proc = subprocess.run(["bash", str(script), str(n_grains), str(ranks), str(steps), str(dt), str(skin), style],
                          capture_output=True, text=True, timeout=1800)
    match = re.search(r"grain_steps_per_s=([\d.eE+-]+)", proc.stdout)
    return float(match.group(1)) if match else None


def fluid_share(n_grains: int, start: dict, dt: float, skin: float, permeability: float, threads: int,
                steps: int, repeats: int) -> dict:
    """Undrained (implicit fluid, kappa_c = permeability) vs dry from the same state: rates and the
    fluid share of a step, 1 - rate_undrained / rate_dry."""
    wet = Simulation(bench_config(n_grains, dt, skin, permeability), arrays=start)
    dry = Simulation(bench_config(n_grains, dt, skin), arrays=start)
    wet_start = (wet.state.arrays(), wet.fluid.arrays())
    wet.threads = dry.threads = threads
    rates = {"dry": [], "undrained": []}
    for _ in range(repeats):
        for name, sim in (("dry", dry), ("undrained", wet)):
            sim.state.restore(start)
            if sim.fluid is not None:
                sim.fluid.restore(wet_start[1])
            sim.advance(5)
            t0 = time.perf_counter()
            sim.advance(steps)
            rates[name].append(steps * sim.state.n / (time.perf_counter() - t0))
    dry_rate, wet_rate = float(np.median(rates["dry"])), float(np.median(rates["undrained"]))
    return {"n_grains": n_grains, "threads": threads, "permeability": permeability,
            "fluid_interval_steps": wet.fluid_interval, "grid": list(wet.fluid.pressure.shape),
            "rate_dry": dry_rate, "rate_undrained": wet_rate, "fluid_share": 1.0 - wet_rate / dry_rate}


def run_benchmark(sizes=(10000,), threads=None, steps: int = 5000, repeats: int = 3, dt: float = 0.89,
                  skin: float = 0.2, lammps: bool = True, lammps_styles=("granular", "hh"),
                  permeability: float | None = 1e-5) -> dict:
    all_threads = numba.config.NUMBA_NUM_THREADS
    threads = threads or sorted({1, all_threads})
    rows: list[BenchRow] = []
    fluid = []
    for n in sizes:
        sim, start = prepare(n, dt, skin)
        if permeability:
            for t in threads:
                fluid.append(fluid_share(n, start, dt, skin, permeability, t, steps, repeats))
        per_grain = state_bytes(sim) / sim.state.n
        reference = None
        for t in threads:
            rates, final = time_gouge(sim, start, t, steps, repeats)
            if reference is None:
                reference = final
            identical = all(np.array_equal(reference[k], final[k]) for k in reference)
            rows.append(BenchRow("gouge", sim.state.n, t, steps, min(rates), float(np.median(rates)), max(rates),
                                 per_grain, identical))
        if lammps:
            for style in lammps_styles:
                for t in threads:
                    rate = time_lammps(n, t, steps, dt, skin, style)
                    if rate is not None:
                        rows.append(BenchRow(f"lammps-{style}", n, t, steps, rate, rate, rate))
    return {
        "machine": {"cpus": os.cpu_count(), "numba_threads": all_threads},
        "dt": dt, "skin": skin,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "rows": [asdict(r) for r in rows],
        "fluid": fluid,
    }


def write_results(results: dict, path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=2))
