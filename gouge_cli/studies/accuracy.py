"""Accuracy ladders: run one scene at a ladder of numerical settings, time each run and
measure its error against the finest setting; the same for analytic cases with known
solutions, so the order of each scheme is measured (docs/physics/timestep.md and docs/validation.md).

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
* ``grid``: the pressure-grid spacing h = w, w/2, w/4 -> w/8 at the scene's fixed filter width w
  (fluid.filter_width; the convergence of the coupling's numerics);
* ``filter_width``: w = 2, 3, 4 d at h = w/2 (a physical parameter: its sensitivity, no order;
  errors against the scene's own w when it is one of them);
* ``fluid.step`` 2, 1, 0.5, 0.25 -> 0.125 [t0];
* ``fluid.solver`` implicit, explicit and auto at the scene's fluid.step, against the
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
  grid (grid-independent) / its largest reference value;
* ``pressure_field``: RMS over the interval and over fixed probe points (a lattice of spacing
  w/2 in x and in the relative height between the wall planes, the pressure interpolated
  bilinearly from the cell centres) of the pressure difference / the largest reference |P| there.

The observed order is the least-squares slope of log(error) against log(setting) over the
non-reference levels (dt for the dt_safety ladder, the fluid step actually used, the grid
spacing actually used).
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.checkpoint import CheckpointHeader, read_checkpoint
from ..config import build_config, Config
from ..errors import ConfigError
from ..driver.guards import Guards
from ..driver.schedules import Every
from ..kernels import layout as L
from ..driver.compaction import compact
from ..driver.simulation import Simulation
from ..errors import PhysicsError
from ..model.timestep import slip_duration
from ..plots.accuracy import plot_work_precision
from .analytic import AnalyticRow, block_slider_errors, energy_drift, head_on, hertz_reference, terzaghi_error

DT_SAFETY = (0.8, 0.4, 0.2, 0.1, 0.05, 0.025)
GRID_FRACTIONS = (1.0, 0.5, 0.25, 0.125)          # h / w
FILTER_WIDTHS = (2.0, 3.0, 4.0)
FLUID_STEP = (2.0, 1.0, 0.5, 0.25, 0.125)
QUICK_DT_SAFETY = (0.4, 0.2, 0.1)
QUICK_GRID_FRACTIONS = (1.0, 0.5, 0.25)
QUICK_FLUID_STEP = (2.0, 1.0, 0.5)
SCENE_ERRORS = ("wall_x", "wall_vx", "stress_drop", "peak_velocity", "pressure", "pressure_field")
ORDER_LADDERS = ("dt_safety", "grid", "fluid.step")
LADDERS = ("dt_safety", "grid", "filter_width", "fluid.step", "fluid.solver")
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


def slip_end(path: Path, header: CheckpointHeader) -> float | None:
    """End time of the slip a checkpoint was kept for (its header's slip), from the run's catalog
    (RUN/run.h5 next to RUN/checkpoints/), or None."""
    from ..io.layout import RunLayout
    from ..io.slipcatalog import slip_catalog

    run = RunLayout.of_checkpoint(path)
    if header.slip is None or not run.run_file.is_file():
        return None
    for entry in slip_catalog(run.root):
        if entry.number == header.slip:
            return entry.end_time
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
        end = slip_end(path, ck.header)
        onset = ck.header.onset_time
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
    from ..io.layout import RunLayout
    from ..io.runwriter import RunFile
    from ..driver.phases import load_phase

    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    sim = Simulation(config)
    writer = RunFile(RunLayout(work_dir).run_file, config, sim.dt)
    try:
        compact(sim)
        writer.append(sim.observe())
        _, recorder = load_phase(sim, writer, work_dir, sim.state.time + config.run.duration, quiet=quiet,
                                 stop_after_slip=True)
    finally:
        writer.close()
    if recorder.slips and recorder.slips[0].checkpoint:
        return start_from_checkpoint(work_dir / recorder.slips[0].checkpoint, config, interval)
    return start_from_checkpoint(RunLayout(work_dir).latest, config, interval)


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
    fractions = QUICK_GRID_FRACTIONS if quick else GRID_FRACTIONS
    steps = QUICK_FLUID_STEP if quick else FLUID_STEP
    dt = fluid_dt(config, steps[-1])
    base_step = (config.fluid.step if config.fluid is not None else 0.5)
    width = config.fluid.filter_width if config.fluid is not None and config.fluid.filter_width > 0 else 3.0
    common = {"numerics.dt": dt}
    levels += [Level("grid", f"cell_size={f * width:g}", f * width,
                     {**common, "fluid.filter_width": width, "fluid.cell_size": f * width, "fluid.step": base_step},
                     reference=(f == fractions[-1]), keep_fluid=False) for f in fractions]
    levels += [Level("filter_width", f"filter_width={w:g}", w,
                     {**common, "fluid.filter_width": w, "fluid.cell_size": 0.5 * w, "fluid.step": base_step},
                     reference=(w == width), keep_fluid=False) for w in FILTER_WIDTHS]
    levels += [Level("fluid.step", f"fluid.step={v:g}", v, {**common, "fluid.step": v, "fluid.solver": "implicit"},
                     reference=(v == steps[-1])) for v in steps]
    levels += [Level("fluid.solver", f"solver={s}", base_step,
                     {**common, "fluid.step": base_step, "fluid.solver": s}) for s in ("implicit", "explicit", "auto")]
    return levels


def level_config(base: Config, level: Level) -> Config:
    data = base.to_dict()
    if level.ladder != "dt_safety" and data.get("fluid") is None:
        data["fluid"] = dict(fluid_defaults)
    return build_config(data, level.overrides)


def _pressure_rms(sim: Simulation) -> float:
    return float(np.sqrt(np.mean(sim.fluid.pressure ** 2))) if sim.fluid is not None else float("nan")


def probe_points(width: float, length: float, thickness: float) -> np.ndarray:
    """(n, 2) probe points (x [d], relative height in (0, 1)): a lattice of spacing width/2 in x and
    about width/2 in height, inside the layer (the planes, where P = 0, excluded)."""
    step = 0.5 * width
    xs = np.arange(0.5 * step, length, step)
    rows = max(1, int(thickness / step))
    heights = (np.arange(rows) + 0.5) / rows
    return np.array([(x, h) for x in xs for h in heights])


def probe_pressure(sim: Simulation, points: np.ndarray) -> np.ndarray:
    """The pressure [E] at probe points (x, relative height), bilinear from the cell centres
    (periodic in x; P = 0 on the planes, half a cell beyond the first and last centres)."""
    grid = sim.fluid
    nx, nz = grid.nx, grid.nz
    xs = (points[:, 0] / grid.dx - 0.5) % nx
    i0 = np.floor(xs).astype(int)
    fx = xs - i0
    i1 = (i0 + 1) % nx
    # z nodes: the bottom plane (P = 0) at q = 0, the cell centres at q = j + 1/2, the top plane at q = nz
    nodes = np.concatenate([[0.0], np.arange(nz) + 0.5, [float(nz)]])
    padded = np.zeros((nx, nz + 2))
    padded[:, 1:-1] = grid.pressure
    q = np.clip(points[:, 1], 0.0, 1.0) * nz
    j0 = np.clip(np.searchsorted(nodes, q, side="right") - 1, 0, nz)
    fz = (q - nodes[j0]) / (nodes[j0 + 1] - nodes[j0])
    return ((1 - fx) * (1 - fz) * padded[i0, j0] + fx * (1 - fz) * padded[i1, j0]
            + (1 - fx) * fz * padded[i0, j0 + 1] + fx * fz * padded[i1, j0 + 1])


def run_level(start: Start, level: Level, period: float, count: int) -> LevelResult:
    """Run `level` from `start`, sampling every `period` [t0] (a whole number of its steps)
    `count` times: Simulation.run with the callbacks "guards", "sample" every `period` from the
    start's step. The elapsed time is the run's without its callbacks."""
    config = level_config(start.config, level)
    fluid = start.fluid if (level.keep_fluid and start.fluid and config.fluid is not None) else None
    sim = Simulation(config, arrays=start.state, fluid_arrays=fluid)
    guards = Guards()
    per = max(1, int(round(period / sim.dt)))
    series = {k: [] for k in ("time", "wall_x", "wall_vx", "tau_over_sigma", "pressure_rms", "pressure_probe")}
    steps0, status = sim.state.step, "ok"
    in_callbacks = [0.0]
    points = None
    if sim.fluid is not None:
        width = start.config.fluid.filter_width if start.config.fluid is not None else 0.0
        points = probe_points(width if width > 0 else 3.0, sim.state.width, sim.fluid.dz * sim.fluid.nz)

    def sample(s: Simulation):
        for key, value in (("time", s.state.time), ("wall_x", s.state.wall[L.W_X]),
                           ("wall_vx", s.state.wall[L.W_VX]), ("tau_over_sigma", s.tau_over_sigma()),
                           ("pressure_rms", _pressure_rms(s))):
            series[key].append(float(value))
        series["pressure_probe"].append(probe_pressure(s, points) if points is not None else np.zeros(0))

    def timed_out(action):
        def run(s: Simulation):
            t0 = time.perf_counter()
            action(s)
            in_callbacks[0] += time.perf_counter() - t0
        return run

    sample(sim)
    t0 = time.perf_counter()
    try:
        sim.run(count * per * sim.dt, [Every(per, timed_out(guards), "guards", offset=steps0),
                                       Every(per, timed_out(sample), "sample", offset=steps0)])
    except PhysicsError as err:
        status = f"failed: {err}"
    elapsed = time.perf_counter() - t0 - in_callbacks[0]
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
    field_ref, field = ref.get("pressure_probe"), run.get("pressure_probe")
    if field_ref is not None and field is not None and field_ref.shape == field.shape and field_ref.size \
            and np.all(np.isfinite(field)) and np.abs(field_ref).max() > 0:
        out["pressure_field"] = float(np.sqrt(np.mean((field - field_ref) ** 2)) / np.abs(field_ref).max())
    else:
        out["pressure_field"] = float("nan")
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
    """The setting the order is fitted against: dt, the fluid step used, the grid spacing or the width."""
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
    step_ref = step_ref or next((r for r in results if r.level.ladder == "fluid.solver"
                                 and r.level.setting == "solver=implicit"), None)
    for ladder in dict.fromkeys(r.level.ladder for r in results):
        group = [r for r in results if r.level.ladder == ladder]
        ref = step_ref if ladder == "fluid.solver" else next((r for r in group if r.level.reference), None)
        for r in group:
            r.errors = level_errors(r, ref) if ref is not None and r is not ref else {}
    orders, flags = {}, {}
    for ladder in ORDER_LADDERS:
        group = [r for r in results if r.level.ladder == ladder and not r.level.reference]
        if group:
            values = [order_value(r) for r in group]
            errs = {name: [r.errors.get(name, np.nan) for r in group] for name in SCENE_ERRORS}
            orders[ladder] = {name: fit_order(values, errs[name]) for name in SCENE_ERRORS}
            flags[ladder] = {name: order_flag(values, errs[name]) for name in SCENE_ERRORS}
    return {"results": results, "orders": orders, "order_flags": flags}


# ---- analytic cases ---------------------------------------------------------------------


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


def run_accuracy(config: Config | None, out_dir: Path, checkpoint: Path | None = None, quick: bool = False,
                 interval: float | None = None, samples: int = 400, analytic: bool = True, scene: bool = True,
                 fluid: bool = True, on_level=None, ladders: tuple | None = None) -> dict:
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
        if ladders is not None:
            levels = [lv for lv in levels if lv.ladder in ladders]
        scene_result = run_scene_ladders(start, levels, samples, on_level)
    analytic_result = analytic_ladders(quick) if analytic else None
    write_csv(out_dir / "accuracy.csv", scene_result, analytic_result)
    plot_work_precision(out_dir / "accuracy.png", scene_result, analytic_result, SCENE_ERRORS)
    return {"start": start, "scene": scene_result, "analytic": analytic_result}


__all__ = ["Start", "Level", "LevelResult", "scene_ladders", "run_scene_ladders", "run_level", "level_errors",
           "fit_order", "order_flag", "analytic_ladders", "run_accuracy", "prepare_start", "start_from_checkpoint"]


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
