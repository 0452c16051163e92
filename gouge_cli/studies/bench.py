"""`gouge bench`: grain-steps per second on the sheared layer, side by side with LAMMPS.

The scene is that of the LAMMPS deck in ``benchmarks/lammps`` (width 200 sqrt(N/1e4) d, one rough row of wall
grains at each side, diameters uniform in [0.8, 1.2], E = 1, nu = 0.2, mu = 0.5,
sigma = 3e-4 E, top wall dragged at 1e-3 v0 by a stiff spring, dt and skin as given):
compaction, ~0.3 strain of pre-shear, then only the steady sheared phase is timed.
Every thread count starts from the same pre-sheared state; their final states are
compared bit for bit. Prepared states are cached (runs/bench/cache) per size, dt, skin and
kernel version, since pre-shearing 160,000 grains takes minutes.

Also measured: the cost of each part of a step (profile), numba runtime allocations per
step (NRT statistics: two advances of different length from the same state), the fluid
share of an undrained step, the contact pass on the first m grains of the largest packing
(cost per grain against working-set size, at the same kind of rows and pairs), and the
projected wall time of one loading cycle and of one slip of the thesis Run 24 scene
(docs/physics/units.md, "Scale of real work") at the rates measured here. Where LAMMPS cannot
be timed (no ``lmp``, no deck, a failed run), the results say why under ``lammps``.

One job a module: the scene and its cache (bench_scene.py), the profiles (bench_profile.py),
LAMMPS (bench_lammps.py); this one times the steps and assembles :class:`BenchResult`.
"""

from __future__ import annotations

import json
import os
import resource
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numba
import numpy as np

from ..io import provenance
from ..config import find_config, load_config
from ..kernels import layout as L
from ..kernels.probe import stream_probe
from ..driver.guards import check
from ..driver.simulation import Simulation
from ..model.timestep import choose_dt, slip_duration
from .bench_lammps import LAMMPS_INSTALL, time_lammps
from .bench_profile import allocations_per_step, footprint_profile, profile_fluid, profile_step
from .bench_scene import bench_config, prepare, state_bytes

RUN24_CYCLE = 1.6e7     # [t0] one loading cycle of thesis Run 24 (docs/physics/units.md)


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


@dataclass
class BenchResult:
    """What `gouge bench` measured (rates in grain-steps/s, times in microseconds per call);
    :func:`write_results` writes it as bench.json, :func:`gouge_cli.studies.bench_report.bench_report`
    renders it. The parts' records are the dicts named in :func:`run_benchmark`'s helpers.

    machine            cpus, numba_threads, threads timed, NUMBA_CPU_NAME / _FEATURES
    provenance         io.provenance.collect of the process
    dt, skin           the bench scene's step [t0] and Verlet skin [d]
    peak_rss_mb        the process's peak resident memory [MB]
    rows               one BenchRow per code, size and thread count
    lammps             timed, requested, max_grains, missing (why a row is absent), install
    fluid              fluid_share records (undrained against dry rates)
    fluid_profile_us   profile_fluid records (one fluid update's parts)
    profile_us         profile_step records (one step's parts) with n_grains and threads
    allocations        numba runtime allocations per step, by size and thread count
    footprint          footprint_profile records (contact pass on the first m grains)
    scaling            paired thread scaling and the machine probe's, by size
    run24              run24_projection (None: not projected)
    """

    machine: dict
    provenance: dict
    dt: float
    skin: float
    peak_rss_mb: float
    rows: list[BenchRow]
    lammps: dict
    fluid: list[dict]
    fluid_profile_us: list[dict]
    profile_us: list[dict]
    allocations: list[dict]
    footprint: list[dict]
    scaling: list[dict]
    run24: dict | None

    def to_dict(self) -> dict:
        """The JSON record (bench.json)."""
        return asdict(self)


def numba_features() -> str:
    """The CPU features numba compiles for: "host" (this CPU's: numba's default, also when only
    NUMBA_CPU_NAME is set, so that NUMBA_CPU_NAME=haswell alone still uses an AVX-512 host's
    512-bit instructions), "named CPU's own" (NUMBA_CPU_FEATURES set empty: e.g. haswell's AVX2 +
    FMA, nothing more), else the feature string given."""
    features = numba.config.CPU_FEATURES
    return "host" if features is None else features or "named CPU's own"


def cpu_mhz() -> float | None:
    """The first "cpu MHz" of /proc/cpuinfo (a virtual machine's nominal clock; a host's current
    one), to turn ns into cycles; None where there is none."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "cpu MHz":
                return float(value)
    except (OSError, ValueError):
        pass
    return None


def time_gouge(sim: Simulation, start: dict, threads: int | list[int], steps: int, repeats: int,
               probe_bytes: int = 0) -> tuple[dict[int, list[float]], dict[int, dict], dict[int, list[float]]]:
    """Grain-steps per second of `steps` steps from `start`, `repeats` times per thread count.
    The thread counts take turns within each repeat (1, 2, 1, 2, ...), so that a slow stretch of
    a shared machine falls on both and the paired ratios (scaling) stay comparable. With
    probe_bytes, each timing is followed by the machine probe (stream_probe over two arrays of
    probe_bytes together) on the same thread count: what the machine allows such a loop at that
    moment. Returns the rates, the final state arrays and the probe's rates [elements/s] per
    thread count (empty without probe_bytes)."""
    counts = [threads] if isinstance(threads, int) else list(threads)
    for t in counts:
        sim.threads = t
        sim.state.restore(start)
        sim.advance(10)  # warm-up (compiled already; touches memory)
    probe = _Probe(probe_bytes) if probe_bytes > 0 else None
    rates = {t: [] for t in counts}
    probe_rates = {t: [] for t in counts} if probe else {}
    final = {}
    for _ in range(repeats):
        for t in counts:
            sim.threads = t
            sim.state.restore(start)
            t0 = time.perf_counter()
            sim.advance(steps)
            rates[t].append(steps * sim.state.n / (time.perf_counter() - t0))
            final[t] = sim.state.arrays()
            if probe:
                probe_rates[t].append(probe.rate(t))
    check(sim)
    return rates, final, probe_rates


class _Probe:
    """kernels.probe.stream_probe over two float64 arrays of `n_bytes` together, in as many fixed
    parts as numba has threads."""

    def __init__(self, n_bytes: int):
        n = max(n_bytes // 16, 1024)
        self.a = np.linspace(0.0, 1.0, n)
        self.b = np.zeros(n)
        self.reps = max(1, int(2e8 // n))
        self.parts = numba.config.NUMBA_NUM_THREADS
        stream_probe(self.a, self.b, self.parts, 1)        # compile / warm

    def rate(self, threads: int) -> float:
        numba.set_num_threads(threads)
        t0 = time.perf_counter()
        stream_probe(self.a, self.b, self.parts, self.reps)
        return self.reps * self.a.size / (time.perf_counter() - t0)


def median_ratio(numerators: list[float], denominators: list[float]) -> float:
    """Median over repeats of numerator / denominator within the same repeat."""
    return float(np.median(np.asarray(numerators) / np.asarray(denominators)))


def paired_scaling(rates: dict[int, list[float]]) -> dict[int, float]:
    """Median over repeats of rate(t) / rate(fewest threads) within the same repeat."""
    base = min(rates)
    return {t: median_ratio(r, rates[base]) for t, r in rates.items() if t != base}


def fluid_share(n_grains: int, start: dict, dt: float, skin: float, permeability: float, threads: int,
                steps: int, repeats: int, solver: str = "auto") -> dict:
    """Undrained (fluid.solver `solver`, kappa_c = permeability) vs dry from the same state: rates and the
    fluid share of a step, 1 - rate_undrained / rate_dry: paired (fluid_share_paired, the median
    over repeats of the share within each repeat, where the two runs are back to back, so that a
    slow stretch of a shared machine falls on both), from the medians of each (fluid_share) and
    from the fastest of each (fluid_share_best); explicit_fraction: the share of the last repeat's
    updates that took the explicit step (kernels.pressure: auto)."""
    wet = Simulation(bench_config(n_grains, dt, skin, permeability, solver), arrays=start)
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
    updates = wet.fluid.state[L.S_UPDATES] - wet_start[1]["state"][L.S_UPDATES]
    explicit = wet.fluid.state[L.S_EXPLICIT_UPDATES] - wet_start[1]["state"][L.S_EXPLICIT_UPDATES]
    return {"n_grains": n_grains, "threads": threads, "permeability": permeability, "dt": dt, "solver": solver,
            "explicit_fraction": float(explicit / updates) if updates > 0 else 0.0,
            "fluid_interval_steps": wet.fluid_interval, "grid": list(wet.fluid.pressure.shape),
            "rate_dry": dry_rate, "rate_undrained": wet_rate, "fluid_share": 1.0 - wet_rate / dry_rate,
            "fluid_share_best": 1.0 - max(rates["undrained"]) / max(rates["dry"]),
            "fluid_share_paired": 1.0 - median_ratio(rates["undrained"], rates["dry"])}


def run24_config():
    return load_config(find_config("thesis_run24_dry"))


def run24_projection(rates: dict) -> dict:
    """Projected wall time of one Run 24 loading cycle (RUN24_CYCLE) and one slip
    (pi sqrt(m_b / k)), from grain-steps/s measured at that scene's size and time step."""
    config = run24_config()
    sim = Simulation(config)
    dt = sim.scene.dt
    slip = slip_duration(config, sim.wall_mass_per_length)
    n = sim.state.n
    out = {"n_grains": n, "dt": dt, "cycle_t0": RUN24_CYCLE, "slip_t0": slip, "by_threads": {}}
    for threads, rate in rates.items():
        out["by_threads"][threads] = {"rate": rate, "cycle_hours": RUN24_CYCLE / dt * n / rate / 3600,
                                      "slip_minutes": slip / dt * n / rate / 60}
    from ..driver.stick_scaling import LADDER_DEFAULT, cycle_steps, true_stretch     # stick scaling: the same cycle

    out["stick_scaling"] = {}
    out["stick_scaling_cap"] = RUN24_CYCLE / true_stretch(config, RUN24_CYCLE, slip)[0]    # lambda -> inf
    for lam in sorted({LADDER_DEFAULT, 16.0, 64.0, 256.0}):
        plain, scaled = cycle_steps(config, lam, RUN24_CYCLE, slip)
        out["stick_scaling"][lam] = {"default": lam == LADDER_DEFAULT, "step_ratio": plain / scaled,
                                     "cycle_hours": {t: v["cycle_hours"] * scaled / plain
                                                     for t, v in out["by_threads"].items()}}
    return out


def run_benchmark(sizes=(10000,), threads=None, steps: int = 5000, repeats: int = 3, dt: float = 0.89,
                  skin: float = 0.2, lammps: bool = True, lammps_styles=("granular", "hh"),
                  permeability: float | None = 1e-5, lammps_max: int = 40000, cache: Path | None = None,
                  profile: bool = True, projection: bool = True) -> BenchResult:
    all_threads = numba.config.NUMBA_NUM_THREADS
    threads = sorted({min(max(int(t), 1), all_threads) for t in threads}) if threads else sorted({1, all_threads})
    rows: list[BenchRow] = []
    fluid = []
    profiles = []
    allocations = []
    footprint = []
    fluid_parts = []
    scaling = []
    run24 = None
    lammps_notes: list[dict] = []
    run24_dt = choose_dt(run24_config())
    for n in sizes:
        sim, start = prepare(n, dt, skin, cache)
        n_steps = max(min(steps, 500), steps * 10000 // max(n, 10000))      # about the same time per repeat
        if permeability and (n == 10000 or len(sizes) == 1):
            for step, solvers in ((dt, ("auto",)), (run24_dt, ("auto", "implicit"))):
                for solver in solvers:
                    for t in threads:
                        fluid.append(fluid_share(n, start, step, skin, permeability, t, steps, repeats, solver))
            if profile:
                fluid_parts = [profile_fluid(n, start, run24_dt, skin, permeability, t) for t in threads]
        n_bytes = state_bytes(sim)
        per_grain = n_bytes / sim.state.n
        all_rates, finals, probe_rates = time_gouge(sim, start, threads, n_steps, repeats,
                                                    probe_bytes=n_bytes if len(threads) > 1 else 0)
        reference = finals[threads[0]]
        scaling.append({"n_grains": n, "paired_ratio": paired_scaling(all_rates),
                        "machine_stream_ratio": paired_scaling(probe_rates) if probe_rates else {},
                        "probe_bytes": n_bytes})
        for t in threads:
            rates = all_rates[t]
            identical = all(np.array_equal(reference[k], finals[t][k]) for k in reference)
            rows.append(BenchRow("gouge", sim.state.n, t, n_steps, min(rates), float(np.median(rates)), max(rates),
                                 per_grain, identical))
            allocations.append({"n_grains": n, "threads": t,
                                "per_step": allocations_per_step(sim, start, t)})
            if profile:
                profiles.append({"n_grains": n, "threads": t, **profile_step(sim, start, t)})
        if profile and len(sizes) > 1 and n == max(sizes):
            footprint = footprint_profile(sim, start, sizes)
        if projection and n == 10000:
            at_dt = Simulation(bench_config(n, run24_dt, skin), arrays=start)
            rates, _, _ = time_gouge(at_dt, start, threads, steps, repeats)
            run24 = {t: float(np.median(r)) for t, r in rates.items()}
            run24 = run24_projection(run24)
        if lammps and n <= lammps_max:
            for style in lammps_styles:
                for t in threads:
                    rate, reason = time_lammps(n, t, n_steps, dt, skin, style)
                    if rate is not None:
                        rows.append(BenchRow(f"lammps-{style}", n, t, n_steps, rate, rate, rate))
                    else:
                        lammps_notes.append({"code": f"lammps-{style}", "n_grains": n, "threads": t,
                                             "reason": reason})
    return BenchResult(
        machine={"cpus": os.cpu_count(), "numba_threads": all_threads, "threads": threads,
                 "numba_cpu_name": os.environ.get("NUMBA_CPU_NAME") or "host",
                 "numba_cpu_features": numba_features(), "cpu_mhz": cpu_mhz()},
        provenance=provenance.collect(all_threads),
        dt=dt, skin=skin,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        rows=rows,
        lammps={"timed": lammps and any(r.code.startswith("lammps") for r in rows),
                "requested": lammps, "max_grains": lammps_max, "missing": lammps_notes,
                "install": LAMMPS_INSTALL},
        fluid=fluid,
        fluid_profile_us=fluid_parts,
        profile_us=profiles,
        allocations=allocations,
        footprint=footprint,
        scaling=scaling,
        run24=run24,
    )


def write_results(results: BenchResult, path: Path):
    """bench.json: the result's JSON record."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results.to_dict(), indent=2))
