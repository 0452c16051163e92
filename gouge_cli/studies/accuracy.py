"""Accuracy ladders: run one scene at a ladder of numerical settings, time each run and
measure its error against the finest setting; the same for analytic cases with known
solutions, so the order of each scheme is measured (physics.md sections 5 and 7).

Scene ladders start every level from the same state (a checkpoint written by ``gouge run``
before a slip, or one made here by compacting and loading the scene until its first slip)
and run it for the same interval [t0]. The DEM is chaotic: trajectories that start equal
separate exponentially, so errors are only meaningful over a short interval: by default
at most 2.5 block-slider slip durations before the onset plus the slip itself (~1000 t0 in
small scenes; see start_from_checkpoint). Over much longer
intervals every level differs from the reference by the chaotic spread, not by its
discretisation error.

Ladders (the last value is the reference):

* ``dt_safety`` 0.8, 0.4, 0.2, 0.1, 0.05 -> 0.025 with the scene's fluid settings (halvings:
  every level is sampled at the same times, a whole number of its steps apart);
* ``fluid.cell_size`` 4, 3, 2.5 -> 2 [d];
* ``fluid.step`` 2, 1, 0.5, 0.25 -> 0.125 [t0];
* ``fluid.solver`` explicit and implicit at the scene's fluid.step, against the
  fluid.step reference (implicit).

The fluid ladders run at dt = 0.125 / ceil(0.125 / dt_scene) so that every fluid step is a
whole number of DEM steps, and start from P = 0 on the checkpoint's packing unless the
checkpoint has a pressure grid and the ladder keeps the grid (fluid.step, solver). A dry
scene gets the fluid section ``fluid_defaults`` (kappa_c = 1e-5, the thesis value) for them.

Errors (relative; the reference level has none):

* ``wall_x``, ``wall_vx``: RMS difference over the interval / range of the reference;
* ``stress_drop``: drop of tau/sigma from its largest value before the peak wall velocity to
  its smallest value after it; ``peak_velocity``: largest sampled wall velocity; relative errors;
* ``pressure``: RMS over the interval of the difference of the RMS pore pressure of the
  grid (grid-independent) / its largest reference value.

The observed order is the least-squares slope of log(error) against log(setting) over the
non-reference levels (dt for the dt_safety ladder, the fluid step actually used, the cell
size actually used).
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

from .. import NUMBA_CACHE
from ..io.checkpoint import read_checkpoint
from ..config import Config, ConfigError, build_config
from ..driver.guards import Guards
from ..kernels import layout as L
from ..kernels import step as K
from ..driver.simulation import Simulation
from ..errors import PhysicsError

DT_SAFETY = (0.8, 0.4, 0.2, 0.1, 0.05, 0.025)
CELL_SIZE = (4.0, 3.0, 2.5, 2.0)
FLUID_STEP = (2.0, 1.0, 0.5, 0.25, 0.125)
QUICK_DT_SAFETY = (0.4, 0.2, 0.1)
QUICK_CELL_SIZE = (4.0, 3.0, 2.5)
QUICK_FLUID_STEP = (2.0, 1.0, 0.5)
SCENE_ERRORS = ("wall_x", "wall_vx", "stress_drop", "peak_velocity", "pressure")
fluid_defaults = {"permeability": 1e-5}


# ---- scene ladders ----------------------------------------------------------------------

@dataclass
class Start:
    """The state every level starts from: config, grain arrays, optional pressure grid."""

    config: Config
    state: dict
    fluid: dict
    interval: float
    source: str


@dataclass
class Level:
    ladder: str
    setting: str
    value: float              # the numerical parameter the order is fitted against
    overrides: dict
    reference: bool = False
    keep_fluid: bool = True


@dataclass
class LevelResult:
    level: Level
    status: str
    wall_seconds: float
    steps: int
    dt: float
    series: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)
    measures: dict = field(default_factory=dict)


def slip_duration(config: Config, wall_mass_per_length: float) -> float:
    """Block-slider slip duration pi sqrt(m_b / k) [t0]."""
    return math.pi * math.sqrt(wall_mass_per_length / config.loading.spring_constant)


def slip_end(path: Path, extra: dict) -> float | None:
    """End time of the slip a checkpoint was kept for, from the run's catalog (RUN/run.h5 next
    to RUN/checkpoints/), or None."""
    from ..io.runfile import slip_catalog

    run_dir = Path(path).resolve().parent.parent
    if "slip" not in extra or not (run_dir / "run.h5").is_file():
        return None
    for entry in slip_catalog(run_dir):
        if int(entry["number"]) == int(extra["slip"]):
            return float(entry["end_time"])
    return None


MAX_LEAD_SLIPS = 2.5   # ladders start at most this many slip durations pi sqrt(m_b/k) before the onset


def start_from_checkpoint(path: Path, config: Config | None = None, interval: float | None = None) -> Start:
    """Start from a checkpoint of ``gouge run``; `config` replaces the stored one (same packing).

    A pre-slip checkpoint is kept at the stress peak, which can precede the onset by thousands
    of t0 of slow creep; over such a lead the levels part by the chaotic spread, not by their
    discretisation error. So without an explicit `interval`, the checkpoint is first advanced
    (with `config`) to MAX_LEAD_SLIPS slip durations before the onset. Default interval: from
    there to the end of the slip plus 10 % of that span (catalog of its run), else the lead to
    the onset plus 5 slip durations, else 500 t0."""
    ck = read_checkpoint(path)
    cfg = config or ck.config
    state, fluid, time = ck.state, ck.fluid, ck.time
    if interval is None:
        end = slip_end(path, ck.extra)
        onset = ck.extra.get("onset_time")
        if onset is not None:
            sim = Simulation(cfg, arrays=state, fluid_arrays=fluid or None)
            duration = slip_duration(cfg, sim.wall_mass_per_length)
            lead = float(onset) - time
            if lead > MAX_LEAD_SLIPS * duration:
                sim.advance(int((lead - MAX_LEAD_SLIPS * duration) / sim.dt))
                state = sim.state.arrays()
                fluid = sim.fluid.arrays() if sim.fluid is not None and fluid else fluid
                time = sim.state.time
        if end is not None:
            interval = 1.1 * (end - time)
        elif onset is not None:
            interval = (float(onset) - time) + 5.0 * duration
        else:
            interval = 500.0
    return Start(cfg, state, fluid, float(interval), str(path))


def prepare_start(config: Config, work_dir: Path, interval: float | None = None, quiet: bool = True) -> Start:
    """Compact and load `config` (at most run.duration) until its first slip ends; start from the
    slip checkpoint written before it (work_dir/checkpoints/slip_001.h5), or from the end state
    (checkpoints/latest.h5) if no slip came."""
    from ..io.runfile import RunFile
    from ..driver.phases import load_phase

    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    sim = Simulation(config)
    writer = RunFile(work_dir / "run.h5", config, sim.dt)
    try:
        sim.compact()
        sim.start_fluid()
        writer.append(sim.observe())
        _, recorder = load_phase(sim, writer, work_dir, sim.state.time + config.run.duration, quiet=quiet,
                                 stop_after_slip=True)
    finally:
        writer.close()
    if recorder.slips and recorder.slips[0]["checkpoint"]:
        return start_from_checkpoint(work_dir / recorder.slips[0]["checkpoint"], config, interval)
    return start_from_checkpoint(work_dir / "checkpoints" / "latest.h5", config, interval)


def fluid_dt(config: Config, finest_step: float) -> float:
    """DEM step of the fluid ladders: finest_step / ceil(finest_step / dt of the scene)."""
    from ..model.timestep import choose_dt

    return finest_step / math.ceil(finest_step / choose_dt(config) - 1e-9)


def scene_ladders(config: Config, quick: bool = False, fluid: bool = True) -> list[Level]:
    """The levels of every ladder (module doc); fluid ladders only if `fluid`."""
    dts = QUICK_DT_SAFETY if quick else DT_SAFETY
    levels = [Level("dt_safety", f"dt_safety={v:g}", v, {"numerics.dt_safety": v, "numerics.dt": None},
                    reference=(v == dts[-1])) for v in dts]
    if not fluid:
        return levels
    cells = QUICK_CELL_SIZE if quick else CELL_SIZE
    steps = QUICK_FLUID_STEP if quick else FLUID_STEP
    dt = fluid_dt(config, steps[-1])
    base_step = (config.fluid.step if config.fluid is not None else 0.5)
    common = {"numerics.dt": dt}
    levels += [Level("cell_size", f"cell_size={v:g}", v, {**common, "fluid.cell_size": v, "fluid.step": base_step},
                     reference=(v == cells[-1]), keep_fluid=False) for v in cells]
    levels += [Level("fluid.step", f"fluid.step={v:g}", v, {**common, "fluid.step": v, "fluid.solver": "implicit"},
                     reference=(v == steps[-1])) for v in steps]
    levels += [Level("fluid.solver", f"solver={s}", base_step,
                     {**common, "fluid.step": base_step, "fluid.solver": s}) for s in ("implicit", "explicit")]
    return levels


def level_config(base: Config, level: Level) -> Config:
    data = base.to_dict()
    if level.ladder != "dt_safety" and data.get("fluid") is None:
        data["fluid"] = dict(fluid_defaults)
    return build_config(data, level.overrides)


def _pressure_rms(sim: Simulation) -> float:
    return float(np.sqrt(np.mean(sim.fluid.pressure ** 2))) if sim.fluid is not None else float("nan")


def run_level(start: Start, level: Level, period: float, count: int) -> LevelResult:
    """Run `level` from `start`, sampling every `period` [t0] (a whole number of its steps)
    `count` times."""
    config = level_config(start.config, level)
    fluid = start.fluid if (level.keep_fluid and start.fluid and config.fluid is not None) else None
    sim = Simulation(config, arrays=start.state, fluid_arrays=fluid)
    guards = Guards()
    per = max(1, int(round(period / sim.dt)))
    series = {k: [] for k in ("time", "wall_x", "wall_vx", "tau_over_sigma", "pressure_rms")}
    elapsed, steps0, status = 0.0, sim.state.step, "ok"

    def sample():
        s = sim.state
        for key, value in (("time", s.time), ("wall_x", s.wall[L.W_X]), ("wall_vx", s.wall[L.W_VX]),
                           ("tau_over_sigma", sim.tau_over_sigma()),
                           ("pressure_rms", _pressure_rms(sim))):
            series[key].append(float(value))

    sample()
    try:
        for _ in range(count):
            t0 = time.perf_counter()
            sim.advance(per)
            elapsed += time.perf_counter() - t0
            guards(sim)
            sample()
    except PhysicsError as err:
        status = f"failed: {err}"
    return LevelResult(level, status, elapsed, sim.state.step - steps0, sim.dt,
                       {k: np.array(v) for k, v in series.items()})


def sampling(start: Start, levels: list[Level], samples: int) -> tuple[float, int]:
    """(period, count): a period that is a whole number of steps of the coarsest level (the
    ladders' steps divide each other), about interval / samples, and the samples in the interval."""
    from ..model.timestep import choose_dt

    coarsest = max(choose_dt(level_config(start.config, lv)) for lv in levels)
    period = coarsest * max(1, int(round(start.interval / samples / coarsest)))
    return period, max(2, int(start.interval / period))


def _warm_up(start: Start, levels: list[Level]):
    """Load every kernel the levels use (numba cache) so that the timings exclude it."""
    seen = set()
    for level in levels:
        config = level_config(start.config, level)
        kind = None if config.fluid is None else config.fluid.solver
        if kind not in seen:
            seen.add(kind)
            sim = Simulation(config, arrays=start.state)
            sim.advance(max(2, sim.fluid_interval if config.fluid is not None else 2))
            Guards()(sim)


def slip_measures(series: dict) -> dict:
    """stress_drop and peak_velocity of a sampled interval (module doc)."""
    v = series["wall_vx"]
    tau = series["tau_over_sigma"]
    if v.size == 0 or not np.all(np.isfinite(v)):
        return {"stress_drop": float("nan"), "peak_velocity": float("nan")}
    i = int(np.argmax(v))
    return {"stress_drop": float(tau[:i + 1].max() - tau[i:].min()), "peak_velocity": float(v[i])}


def level_errors(result: LevelResult, reference: LevelResult) -> dict:
    """Relative errors of `result` against `reference` (module doc); NaN where undefined."""
    out = {}
    ref, run = reference.series, result.series
    if result.status != "ok" or run["time"].size != ref["time"].size \
            or not np.allclose(run["time"], ref["time"], rtol=0, atol=1e-6 * (1.0 + abs(ref["time"][-1]))):
        return {name: float("nan") for name in SCENE_ERRORS}
    for name in ("wall_x", "wall_vx"):
        diff = run[name] - ref[name]
        span = np.ptp(ref[name])
        out[name] = float(np.sqrt(np.mean(diff ** 2)) / span) if span > 0 else float("nan")
    mine, theirs = slip_measures(run), slip_measures(ref)
    for name in ("stress_drop", "peak_velocity"):
        out[name] = abs(mine[name] - theirs[name]) / abs(theirs[name]) if theirs[name] else float("nan")
    p_ref = ref["pressure_rms"]
    if np.all(np.isfinite(p_ref)) and np.all(np.isfinite(run["pressure_rms"])) and p_ref.max() > 0:
        diff = run["pressure_rms"] - p_ref
        out["pressure"] = float(np.sqrt(np.mean(diff ** 2)) / p_ref.max())
    else:
        out["pressure"] = float("nan")
    return out


def fit_order(values, errors) -> float:
    """Slope of log(error) vs log(value) over the finite positive errors (NaN if < 2)."""
    pairs = [(v, e) for v, e in zip(values, errors) if v > 0 and e > 0 and math.isfinite(e)]
    if len(pairs) < 2 or len({v for v, _ in pairs}) < 2:
        return float("nan")
    x, y = np.log([p[0] for p in pairs]), np.log([p[1] for p in pairs])
    return float(np.polyfit(x, y, 1)[0])


ORDER_MIN_R2 = 0.8


def order_flag(values, errors, min_r2: float = ORDER_MIN_R2) -> str:
    """Why an observed order (:func:`fit_order`) is meaningless, or "" when it is not.

    Meaningful: at least 2 finite positive errors, each finer setting's error below the next
    coarser one's (errors fall as the setting is refined), and log(error) on a line in
    log(setting) with R^2 >= ``min_r2``.
    """
    pairs = sorted((v, e) for v, e in zip(values, errors) if v > 0 and e > 0 and math.isfinite(e))
    if len(pairs) < 2:
        return "fewer than 2 errors"
    rising = [f"{fine:.3g} -> {coarse:.3g}" for (_, fine), (_, coarse) in zip(pairs, pairs[1:]) if fine >= coarse]
    if rising:
        return "errors do not fall as the setting is refined (" + ", ".join(rising) + ")"
    x, y = np.log([p[0] for p in pairs]), np.log([p[1] for p in pairs])
    if len(pairs) > 2:
        res = y - np.polyval(np.polyfit(x, y, 1), x)
        r2 = 1.0 - float(np.sum(res ** 2)) / float(np.sum((y - y.mean()) ** 2))
        if r2 < min_r2:
            return f"log-log fit R^2 = {r2:.2f} < {min_r2:g}"
    return ""


def order_value(result: LevelResult) -> float:
    """The setting the order is fitted against: dt, the fluid step used, or the cell size."""
    lv = result.level
    if lv.ladder == "dt_safety":
        return result.dt
    if lv.ladder == "fluid.step":
        return max(1, int(round(lv.value / result.dt))) * result.dt
    return lv.value


def run_scene_ladders(start: Start, levels: list[Level], samples: int = 400, on_level=None) -> dict:
    """Run every level, all sampled at the same times (about `samples` over the interval);
    returns {"results": [...], "orders": {ladder: {error: order}}}."""
    period, count = sampling(start, levels, samples)
    _warm_up(start, levels)
    results = []
    for level in levels:
        res = run_level(start, level, period, count)
        res.measures = slip_measures(res.series) if res.status == "ok" else {}
        results.append(res)
        if on_level is not None:
            on_level(res)
    step_ref = next((r for r in results if r.level.ladder == "fluid.step" and r.level.reference), None)
    for ladder in dict.fromkeys(r.level.ladder for r in results):
        group = [r for r in results if r.level.ladder == ladder]
        ref = step_ref if ladder == "fluid.solver" else next((r for r in group if r.level.reference), None)
        for r in group:
            r.errors = level_errors(r, ref) if ref is not None and r is not ref else {}
    orders, flags = {}, {}
    for ladder in ("dt_safety", "cell_size", "fluid.step"):
        group = [r for r in results if r.level.ladder == ladder and not r.level.reference]
        if group:
            values = [order_value(r) for r in group]
            errs = {name: [r.errors.get(name, np.nan) for r in group] for name in SCENE_ERRORS}
            orders[ladder] = {name: fit_order(values, errs[name]) for name in SCENE_ERRORS}
            flags[ladder] = {name: order_flag(values, errs[name]) for name in SCENE_ERRORS}
    return {"results": results, "orders": orders, "order_flags": flags}


# ---- analytic cases ---------------------------------------------------------------------

@dataclass
class AnalyticRow:
    case: str
    parameter: str
    value: float
    wall_seconds: float
    errors: dict


def _free_grains(x, z, radius, vx, dt, width=100.0, body=None, **material):
    """Simulation of free grains without walls (compaction damping 0, given material)."""
    from ..model.state import State

    material.setdefault("damping", 0.0)
    cfg = build_config({"numerics": {"dt": dt}, "compaction": {"damping": 0.0}, "material": material})
    n = len(x)
    st = State(x=np.asarray(x, float).copy(), z=np.asarray(z, float).copy(), radius=np.asarray(radius, float).copy(),
               body=np.zeros(n) if body is None else np.asarray(body), density=1.0, width=width)
    for name, value in vx.items():
        getattr(st, name)[:] = value
    return Simulation(cfg, state=st)


def hertz_reference(v: float) -> tuple[float, float]:
    """(contact time, max overlap) of two d = 1 grains meeting at relative speed v (gamma = 0)."""
    from scipy.special import beta

    from ..model.timestep import contact_constants

    k = contact_constants(build_config({}))[0] * math.sqrt(0.5)
    m_star = math.pi / 12.0
    xi_max = (1.25 * m_star * v * v / k) ** 0.4
    return 0.8 * beta(0.4, 0.5) * xi_max / v, xi_max


def head_on(v: float, steps_per_contact: int) -> tuple[float, float]:
    """(contact time, max overlap) of the engine's head-on collision at dt = t_c / steps."""
    t_c, _ = hertz_reference(v)
    dt = t_c / steps_per_contact
    gap = 3.5 * v * dt
    sim = _free_grains([10.0, 11.0 + gap], [0.0, 0.0], [0.5, 0.5], {"vx": [0.5 * v, -0.5 * v]}, dt)
    st = sim.state
    overlap = [1.0 - (st.x[1] - st.x[0])]
    while not (overlap[-1] < 0.0 and max(overlap) > 0.0) and len(overlap) < 5 * steps_per_contact:
        sim.advance(1)
        overlap.append(1.0 - (st.x[1] - st.x[0]))
    xi = np.array(overlap)
    inside = np.flatnonzero(xi > 0.0)
    a, b = inside[0], inside[-1]
    t_in = (a - 1) + xi[a - 1] / (xi[a - 1] - xi[a])
    t_out = b + xi[b] / (xi[b] - xi[b + 1])
    return (t_out - t_in) * dt, float(xi.max())


def closed_box(seed=3, width=10.0, nx=8, nz=12, spacing=1.25, v_rms=1e-2) -> dict:
    """Free grains between two rows of fixed grains (one body: they never pair), periodic in x,
    random velocities and spins: a closed conservative system (gamma = mu = 0)."""
    rng = np.random.default_rng(seed)
    xs = (np.arange(nx) + 0.5) * width / nx
    gx, gz = np.meshgrid(xs, 1.25 + np.arange(nz) * spacing)
    x_free = gx.ravel() + rng.uniform(-0.02, 0.02, gx.size)
    z_free = gz.ravel()
    r_free = rng.uniform(0.4, 0.6, x_free.size)
    n_wall = int(width)
    x_wall = (np.arange(n_wall) + 0.5) * width / n_wall
    x = np.concatenate([x_wall, x_free, x_wall])
    z = np.concatenate([np.zeros(n_wall), z_free, np.full(n_wall, z_free.max() + 1.25)])
    radius = np.concatenate([np.full(n_wall, 0.5), r_free, np.full(n_wall, 0.5)])
    body = np.concatenate([np.ones(n_wall), np.zeros(x_free.size), np.ones(n_wall)])
    free = body == 0
    velocities = {name: np.where(free, rng.normal(0.0, v_rms, x.size), 0.0) for name in ("vx", "vz", "spin")}
    return dict(x=x, z=z, radius=radius, body=body, velocities=velocities, width=width)


def total_energy(sim: Simulation) -> float:
    """Kinetic + Hertz energy sum 0.4 c_n sqrt(R_ij) xi^2.5 over touching pairs (same-wall excluded)."""
    st = sim.state
    inertia = st.mass * (2.0 * st.radius) ** 2 / 10.0
    kinetic = 0.5 * np.sum(st.mass * (st.vx ** 2 + st.vz ** 2) + inertia * st.spin ** 2)
    i, j = np.triu_indices(st.n, 1)
    dx = st.x[j] - st.x[i]
    dx -= st.width * np.round(dx / st.width)
    xi = st.radius[i] + st.radius[j] - np.hypot(dx, st.z[j] - st.z[i])
    touching = (xi > 0.0) & ~((st.body[i] == st.body[j]) & (st.body[i] > 0))
    r_ij = 2.0 * st.radius[i] * st.radius[j] / (st.radius[i] + st.radius[j])
    return float(kinetic + np.sum(0.4 * sim.params[L.C_NORMAL] * np.sqrt(r_ij[touching]) * xi[touching] ** 2.5))


def energy_drift(dt: float, duration: float = 200.0, sample: float = 0.32) -> tuple[float, float]:
    """(largest |E - E0| / E0, seconds spent stepping) of the closed box (gamma = mu = 0) over
    `duration` [t0]; the energy is evaluated every `sample` t0 (untimed)."""
    box = closed_box()
    sim = _free_grains(box["x"], box["z"], box["radius"], box["velocities"], dt, width=box["width"],
                       body=box["body"], friction=0.0)
    e0 = total_energy(sim)
    worst, seconds = 0.0, 0.0
    per = max(1, int(round(sample / dt)))
    for _ in range(int(round(duration / (per * dt)))):
        t0 = time.perf_counter()
        sim.advance(per)
        seconds += time.perf_counter() - t0
        worst = max(worst, abs(total_energy(sim) - e0))
    return worst / e0, seconds


def terzaghi_error(nz: int, solver: str = "implicit", ratio: float = 0.5, thickness: float = 10.0) -> float:
    """Largest error of mean and mid-plane P/P0 at T = 0.01, 0.05, 0.1, 0.2, 0.5 on a frozen
    uniform packing (phi = 0.15, two discs per lattice site), fluid steps Delta T = ratio / nz^2."""
    from ..model.fluid import FluidGrid

    targets = (0.01, 0.05, 0.1, 0.2, 0.5)
    m = np.arange(1, 8000, 2)

    def mean(T):
        return float(np.sum(8.0 / (m * np.pi) ** 2 * np.exp(-(m * np.pi) ** 2 * T)))

    def mid(T):
        return float(np.sum(4.0 / (m * np.pi) * np.sin(m * np.pi * 0.5) * np.exp(-(m * np.pi) ** 2 * T)))

    nx, h, z_bot = 2, thickness / nz, 1.0
    xs = (np.arange(nx) + 0.5) * h
    zs = z_bot + (np.arange(nz) + 0.5) * h
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    x, z = np.repeat(X.ravel(), 2), np.repeat(Z.ravel(), 2)
    radius = np.full(x.size, h * np.sqrt(0.85 / (2.0 * np.pi)))
    v = np.zeros_like(x)
    grid = FluidGrid(nx, nz, nx * h, z_bot, z_bot + thickness, x.size, 1e-5, 36.0, 1.43e-7, solver=solver)
    grid.init(x, z, v, v, radius, z_bot, z_bot + thickness)
    diffusivity = grid.mean_diffusivity()
    grid.pressure[:] = 1.0e-6
    delta = ratio / nz ** 2
    due = {round(T / delta): T for T in targets}
    worst = 0.0
    for step in range(1, max(due) + 1):
        if grid.update(x, z, v, v, radius, z_bot, z_bot + thickness, delta * thickness ** 2 / diffusivity) != L.STATUS_OK:
            return float("nan")
        if step in due:
            T = due[step]
            profile = grid.pressure[0] / 1.0e-6
            worst = max(worst, abs(profile.mean() - mean(T)),
                        abs(0.5 * (profile[nz // 2 - 1] + profile[nz // 2]) - mid(T)))
    return worst


@njit(cache=NUMBA_CACHE)
def _block_slip(wall, clock, params, mu_s, mu_d, nsteps, out):
    """The top-wall integrator (kernels.step.wall_kick, _step's order) with imposed Coulomb
    friction; out = (t start, t end, x start, x end, peak v) of the first complete slip.
    Returns 1 if a slip completed."""
    dt = params[L.DT]
    length = params[L.WIDTH]
    sigma = params[L.SIGMA]
    sliding = False
    peak = 0.0
    for _ in range(nsteps):
        K.wall_kick(wall, clock, params)
        wall[L.W_X] += dt * wall[L.W_VX]
        clock[L.C_TIME] += dt
        clock[L.C_DRIVE_TIME] += dt
        spring = params[L.SPRING] * length * (params[L.V_LOAD] * clock[L.C_DRIVE_TIME] - wall[L.W_X])
        if sliding and wall[L.W_VX] <= 0.0:
            out[1] = clock[L.C_TIME]
            out[3] = wall[L.W_X]
            out[4] = peak
            return 1
        if not sliding and spring > mu_s * sigma * length:
            sliding = True
            out[0] = clock[L.C_TIME]
            out[2] = wall[L.W_X]
        wall[L.W_FX] = -mu_d * sigma * length if sliding else -spring
        wall[L.W_FZ] = sigma * length
        K.wall_kick(wall, clock, params)
        if sliding:
            peak = max(peak, wall[L.W_VX])
    return 0


def block_slider_errors(dt: float, m=1.0, k=1e-2, sigma=1e-2, mu_s=0.6, mu_d=0.5, v_load=1e-5) -> dict:
    """Relative errors of the first slip's duration, slip and peak velocity against the exact
    solution with loading during the slip (see tests/validation/test_block_slider.py)."""
    from scipy.optimize import brentq

    p = np.zeros(L.N_PARAMS)
    p[L.DT], p[L.WIDTH], p[L.SIGMA], p[L.SPRING], p[L.V_LOAD] = dt, 1.0, sigma, k, v_load
    p[L.WALL_MASS], p[L.DRIVE] = m, 1.0
    wall, clock, out = np.zeros(L.N_WALL), np.zeros(L.N_CLOCK), np.zeros(5)
    t_end = (mu_s * sigma / k) / v_load + 3.0 * math.pi * math.sqrt(m / k)
    if not _block_slip(wall, clock, p, mu_s, mu_d, int(t_end / dt), out):
        return {"duration": float("nan"), "slip": float("nan"), "peak_velocity": float("nan")}
    w, a = math.sqrt(k / m), (mu_s - mu_d) * sigma / k

    def speed(th):
        return w * a * math.sin(th) + v_load * (1.0 - math.cos(th))
    end = brentq(speed, math.pi, 1.5 * math.pi, xtol=1e-15)
    peak_th = brentq(lambda th: w * a * math.cos(th) + v_load * math.sin(th), 0.0, math.pi, xtol=1e-15)
    exact = {"duration": end / w, "slip": a * (1.0 - math.cos(end)) + v_load * (end - math.sin(end)) / w,
             "peak_velocity": speed(peak_th)}
    got = {"duration": out[1] - out[0], "slip": out[3] - out[2], "peak_velocity": out[4]}
    return {key: abs(got[key] - exact[key]) / exact[key] for key in exact}


def _timed(fn, *args):
    t0 = time.perf_counter()
    value = fn(*args)
    return value, time.perf_counter() - t0


def analytic_ladders(quick: bool = False) -> dict:
    """Rows and orders of the analytic cases: head-on collision and energy drift vs dt,
    Terzaghi vs grid spacing (both solvers), block on a spring vs dt."""
    rows = []
    v = 1e-3
    t_c, xi_max = hertz_reference(v)
    head_on(v, 25), energy_drift(0.16, 1.0), block_slider_errors(0.4)          # load kernels: untimed
    for solver in ("implicit", "explicit"):
        terzaghi_error(4, solver)
    for n in ((25, 50, 100) if quick else (25, 50, 100, 200, 400)):
        (tc, xi), sec = _timed(head_on, v, n)
        rows.append(AnalyticRow("head-on collision", "dt", t_c / n, sec,
                                {"contact_time": abs(tc - t_c) / t_c, "max_overlap": abs(xi - xi_max) / xi_max}))
    for dt in ((0.16, 0.08, 0.04) if quick else (0.16, 0.08, 0.04, 0.02)):
        drift, sec = energy_drift(dt, 50.0 if quick else 200.0)
        rows.append(AnalyticRow("energy drift", "dt", dt, sec, {"energy": drift}))
    for solver in ("implicit", "explicit"):
        for nz in ((10, 20, 40) if quick else (10, 20, 40, 80)):
            err, sec = _timed(terzaghi_error, nz, solver)
            rows.append(AnalyticRow(f"Terzaghi ({solver})", "dz", 10.0 / nz, sec, {"pressure": err}))
    for dt in ((0.4, 0.2, 0.1) if quick else (0.4, 0.2, 0.1, 0.05, 0.025)):
        errs, sec = _timed(block_slider_errors, dt)
        rows.append(AnalyticRow("block on a spring", "dt", dt, sec, errs))
    orders, flags = {}, {}
    for case in dict.fromkeys(r.case for r in rows):
        group = [r for r in rows if r.case == case]
        values = [r.value for r in group]
        orders[case] = {name: fit_order(values, [r.errors[name] for r in group]) for name in group[0].errors}
        flags[case] = {name: order_flag(values, [r.errors[name] for r in group]) for name in group[0].errors}
    return {"rows": rows, "orders": orders, "order_flags": flags}


# ---- outputs ----------------------------------------------------------------------------

def write_csv(path: Path, scene: dict | None, analytic: dict | None):
    """One row per level: kind, case/ladder, setting, value, run time, steps, status, errors."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = sorted({*SCENE_ERRORS, *(k for r in (analytic or {}).get("rows", []) for k in r.errors)})
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kind", "case", "setting", "value", "dt", "wall_seconds", "steps", "status", "reference",
                    "stress_drop", "peak_velocity", *[f"error_{n}" for n in names]])
        for r in (scene or {}).get("results", []):
            w.writerow(["scene", r.level.ladder, r.level.setting, f"{order_value(r):.6g}", f"{r.dt:.6g}",
                        f"{r.wall_seconds:.4f}", r.steps, r.status, int(r.level.reference),
                        *[f"{r.measures.get(k, float('nan')):.6g}" for k in ("stress_drop", "peak_velocity")],
                        *[f"{r.errors[n]:.4g}" if n in r.errors else "" for n in names]])
        for r in (analytic or {}).get("rows", []):
            w.writerow(["analytic", r.case, f"{r.parameter}={r.value:.4g}", f"{r.value:.6g}", "",
                        f"{r.wall_seconds:.4f}", "", "ok", 0, "", "",
                        *[f"{r.errors[n]:.4g}" if n in r.errors else "" for n in names]])


def plot_work_precision(path: Path, scene: dict | None, analytic: dict | None):
    """Error vs run time (log-log), one panel per ladder and per analytic case."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator

    panels = []
    for r in (scene or {}).get("results", []):
        if r.level.ladder not in panels:
            panels.append(r.level.ladder)
    cases = list(dict.fromkeys(r.case for r in (analytic or {}).get("rows", [])))
    total = len(panels) + len(cases)
    if total == 0:
        return
    cols = min(3, total)
    rows = math.ceil(total / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4 * rows), squeeze=False)
    flat = list(axes.ravel())
    for ax, ladder in zip(flat, panels):
        group = [r for r in scene["results"] if r.level.ladder == ladder and r.errors]
        for name in SCENE_ERRORS:
            pts = [(r.wall_seconds, r.errors[name], r.level.setting) for r in group
                   if r.errors.get(name, 0) > 0 and math.isfinite(r.errors[name]) and r.wall_seconds > 0]
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=name)
                for p in pts:
                    ax.annotate(p[2].split("=")[-1], (p[0], p[1]), fontsize=7, alpha=0.7)
        ax.set_title(f"scene: {ladder}")
    for ax, case in zip(flat[len(panels):], cases):
        group = [r for r in analytic["rows"] if r.case == case]
        for name in group[0].errors:
            pts = [(r.wall_seconds, r.errors[name], r.value) for r in group
                   if r.errors[name] > 0 and math.isfinite(r.errors[name]) and r.wall_seconds > 0]
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=name)
                for p in pts:
                    ax.annotate(f"{p[2]:.3g}", (p[0], p[1]), fontsize=7, alpha=0.7)
        ax.set_title(f"analytic: {case} ({group[0].parameter})")
    for ax in flat[:total]:
        if not ax.lines:                          # every error exactly 0 (or no timing): nothing to draw
            ax.text(0.5, 0.5, "errors all zero", ha="center", va="center", transform=ax.transAxes)
            continue
        lo, hi = ax.get_xlim()
        if hi < 3.0 * lo:                        # at least one 1, 2 or 5 x 10^k inside: a labelled tick
            centre = math.sqrt(lo * hi)
            ax.set_xlim(centre / 1.8, centre * 1.8)
        ax.xaxis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda value, _: f"{value:.2g}"))
        ax.set_xlabel("run time [s]")
        ax.set_ylabel("relative error")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    for ax in flat[total:]:
        ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_accuracy(config: Config | None, out_dir: Path, checkpoint: Path | None = None, quick: bool = False,
                 interval: float | None = None, samples: int = 400, analytic: bool = True, scene: bool = True,
                 fluid: bool = True, on_level=None) -> dict:
    """Scene ladders (from `checkpoint`, or from the first slip of `config`) and analytic ladders;
    writes out_dir/accuracy.csv and out_dir/accuracy.png. Returns {"start", "scene", "analytic"}."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = scene_result = None
    if scene:
        if checkpoint is not None:
            start = start_from_checkpoint(checkpoint, config, interval)
        elif config is not None:
            start = prepare_start(config, out_dir / "prepare", interval)
        else:
            raise ConfigError("give a config or a checkpoint for the scene ladders")
        try:
            Simulation(start.config, arrays=start.state)
        except ValueError as err:
            raise ConfigError(f"the config does not fit the checkpoint's packing: {err}") from None
        levels = scene_ladders(start.config, quick, fluid)
        scene_result = run_scene_ladders(start, levels, samples, on_level)
    analytic_result = analytic_ladders(quick) if analytic else None
    write_csv(out_dir / "accuracy.csv", scene_result, analytic_result)
    plot_work_precision(out_dir / "accuracy.png", scene_result, analytic_result)
    return {"start": start, "scene": scene_result, "analytic": analytic_result}


__all__ = ["Start", "Level", "LevelResult", "scene_ladders", "run_scene_ladders", "run_level", "level_errors",
           "fit_order", "order_flag", "analytic_ladders", "run_accuracy", "prepare_start", "start_from_checkpoint"]
