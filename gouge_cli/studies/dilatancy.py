"""Velocity steps in steady sliding: the layer's dilatancy coefficient and the undrained
strengthening it predicts (`gouge dilatancy`, docs/dilatancy.md).

The laboratory measures the dilatancy behind dilatant hardening by stepping the loading velocity
of a sliding gouge layer and recording the change of its steady porosity (Samuelson, Elsworth and
Marone 2009: eps = d(phi) / d(ln V) of 4.7e-5 to 3e-4, independent of normal stress from 0.8 to
20 MPa). Here, for one seed at one normal stress sigma:

1. the scene, with a stiff spring (``stiff`` [E/d], so that the wall slides steadily instead of
   stick-slipping), is compacted and sheared at its loading velocity V_1 for ``run_in`` d of slip;
2. from that one state, for each ratio r in (1, *ratios), the loading velocity steps to r V_1
   (:meth:`Simulation.set_loading_velocity`, the spring force continuous) and the layer slides
   ``slip`` d; the second half of the segment is its steady state: porosity phi_r (series
   ``porosity``), friction tau / sigma (the spring's), the wall speed's mean and coefficient of
   variation, the inertial number I = (r V_1 / H) d sqrt(rho_s / sigma);
3. drained (the dry model): eps_r = (phi_r - phi_1) / ln r, the r = 1 segment being the control;
4. undrained: the same segments, each from the same state with the pore fluid started at P = 0 at
   kappa_c ``perm`` (1e-9 d^2: the diffusion time of the half layer is ~1e6 t0, far beyond a
   segment), give the steady mean pore pressure P_r and friction. The pressure equation's
   undrained limit (docs/physics/fluid.md) predicts from the drained dilation
       P_pred = (phi_1 / (phi_1 + eps_v) - 1) / beta,   eps_v = (phi_r - phi_1) / (1 - phi_1),
   i.e. about -eps ln r / (beta phi), and a strengthening d(tau/sigma) = mu_r (-P_pred) / sigma
   with mu_r the drained friction; measured: (tau/sigma)_undrained - (tau/sigma)_drained at r.

Records (:class:`StepRun`, one per seed and sigma) are appended to ``OUT/dilatancy_runs.json`` as
each finishes, so an interrupted study keeps its finished points and a rerun skips them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ..config import Config, FluidConfig, build_config
from ..errors import ConfigError
from ..io.outputs import temporary
from ..model.fluid import COUPLING_REVISION
from ..analysis.dilatancy import SEGMENT_COLUMNS, StepRun, cells, segment_rows, steady_state, summary_markdown

#: Defaults: the velocity ratios, the spring [E/d], the slip per segment and of the run-in [d], kappa_c [d^2].
RATIOS = (10.0, 100.0)
STIFF = 1.0e-2
SLIP = 40.0
RUN_IN = 25.0
PERM = 1.0e-9
SAMPLES = 600            # series rows per segment


def scene(config: Config, seed: int, sigma: float, stiff: float) -> Config:
    """The study's dry scene: `config` at this seed, normal stress and spring, without fluid, and
    with the top wall's own mass (loading.wall_mass unset: a heavy wall, which the stick-slip
    scenes use to set the slip duration, would ring for many periods after each step)."""
    data = config.to_dict()
    data.pop("fluid", None)
    return build_config(data, {"seed": int(seed), "loading.normal_stress": float(sigma),
                               "loading.spring_constant": float(stiff), "loading.wall_mass": None})


def wet(config: Config, perm: float) -> Config:
    """`config` with the pore fluid at kappa_c `perm` [d^2] (the fluid defaults otherwise)."""
    return build_config(config.to_dict(), {"fluid.permeability": float(perm)})


def run_steps(config: Config, seed: int, sigma: float, *, ratios=RATIOS, perm: float | None = PERM,
              stiff: float = STIFF, slip: float = SLIP, run_in: float = RUN_IN) -> StepRun:
    """One seed at normal stress `sigma` [E] (module docstring); `perm` None: drained only."""
    import time

    from ..driver.phases import guarded_run
    from ..driver.simulation import Simulation

    t_start = time.perf_counter()
    dry = scene(config, seed, sigma, stiff)
    sim = Simulation(dry)
    v1 = dry.loading.velocity
    guarded_run(sim, run_in / v1, interval=run_in / v1 / 100)
    start = sim.state.arrays()
    branches = [(dry, True)] + ([(wet(dry, perm), False)] if perm is not None else [])
    segments = []
    for cfg, drained in branches:
        for ratio in (1.0, *ratios):
            branch = Simulation(cfg, arrays=start)
            branch.set_loading_velocity(ratio * v1)
            duration = slip / (ratio * v1)
            t0 = branch.state.time
            rows = guarded_run(branch, duration, interval=duration / SAMPLES)
            segments.append(steady_state(rows, t0, ratio, drained, sigma))
    fluid = branches[-1][0].fluid or FluidConfig()      # (drained only: beta of the default fluid)
    return StepRun(seed=int(seed), sigma=float(sigma), perm=float(perm) if perm is not None else float("nan"),
                   stiff=float(stiff), segments=tuple(segments), beta=float(fluid.compressibility),
                   wall_seconds=time.perf_counter() - t_start)


# ---- the study: many seeds and stresses, kept as they finish ------------------------------------
@dataclass
class Records:
    """``OUT/dilatancy_runs.json``: the finished StepRuns of one scene (``scene``: the config's
    digest less seed and stress), written atomically after each."""

    path: Path
    scene: str
    runs: list[StepRun] = field(default_factory=list)

    @classmethod
    def open(cls, path: Path, scene_digest: str) -> Records:
        path = Path(path)
        if not path.exists():
            return cls(path, scene_digest)
        data = json.loads(path.read_text())
        if data.get("scene") != scene_digest:
            raise ConfigError(f"{path} holds velocity steps of another scene or settings (digest "
                              f"{data.get('scene')} against {scene_digest}); use another --out")
        return cls(path, scene_digest, [StepRun.from_dict(r) for r in data["runs"]])

    def has(self, seed: int, sigma: float) -> bool:
        return any(r.seed == seed and r.sigma == sigma for r in self.runs)

    def add(self, run: StepRun):
        self.runs = [r for r in self.runs if not (r.seed == run.seed and r.sigma == run.sigma)] + [run]
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with temporary(self.path) as tmp:
            tmp.write_text(json.dumps({"scene": self.scene, "runs": [r.to_dict() for r in self.runs]}, indent=1,
                                      allow_nan=True))


def scene_digest(config: Config, ratios, perm, stiff, slip, run_in) -> str:
    """Hash [hex] of what a StepRun depends on besides seed and sigma."""
    import hashlib

    data = config.to_dict()
    for key in ("seed", "run", "output"):
        data.pop(key, None)
    data["loading"] = {k: v for k, v in data["loading"].items() if k not in ("normal_stress", "spring_constant")}
    data["numerics"] = {k: v for k, v in data["numerics"].items() if k != "threads"}
    data["steps"] = {"ratios": list(map(float, ratios)), "perm": perm, "stiff": stiff, "slip": slip, "run_in": run_in}
    data["coupling"] = COUPLING_REVISION
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _one(args) -> StepRun:
    config, seed, sigma, kw = args
    return run_steps(config, seed, sigma, **kw)


def run_study(config: Config, seeds, sigmas, out: Path, *, workers: int = 1, on_progress=None, tables_only=False,
              **kw) -> list[StepRun]:
    """Every (seed, sigma) not yet in ``out/dilatancy_runs.json``, `workers` processes at a time,
    each kept as it finishes; returns the requested runs (finished ones included). With
    `tables_only` nothing runs: the requested runs already kept."""
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from contextlib import nullcontext

    kw = {"ratios": tuple(kw.get("ratios", RATIOS)), "perm": kw.get("perm", PERM), "stiff": kw.get("stiff", STIFF),
          "slip": kw.get("slip", SLIP), "run_in": kw.get("run_in", RUN_IN)}
    records = Records.open(Path(out) / "dilatancy_runs.json",
                           scene_digest(config, kw["ratios"], kw["perm"], kw["stiff"], kw["slip"], kw["run_in"]))
    todo = [(config, int(s), float(g), kw) for s in seeds for g in sigmas      # seed by seed: every stress
            if not records.has(int(s), float(g))]                            # has a seed early
    say = on_progress or (lambda m: None)
    if tables_only:
        say(f"{len(seeds) * len(sigmas) - len(todo)} of {len(seeds) * len(sigmas)} (seed, sigma) points kept; "
            "none run (--tables)")
        todo = []
    else:
        say(f"{len(todo)} of {len(seeds) * len(sigmas)} (seed, sigma) points to run, {workers} at a time")
    with ProcessPoolExecutor(workers) if workers > 1 and todo else nullcontext() as pool:
        finished = (map(_one, todo) if pool is None
                    else (f.result() for f in as_completed([pool.submit(_one, a) for a in todo])))
        for run in finished:
            records.add(run)
            say(f"seed {run.seed} sigma {run.sigma:g}: done ({run.wall_seconds:.0f} s)")
    wanted = {(int(s), float(g)) for s in seeds for g in sigmas}
    return [r for r in records.runs if (r.seed, r.sigma) in wanted]


def write_outputs(runs: list[StepRun], out: Path) -> list[Path]:
    """segments.csv, summary.md and the figure dilatancy.png under `out`."""
    import csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = segment_rows(runs)
    with open(out / "segments.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(SEGMENT_COLUMNS))
        w.writeheader()
        w.writerows(rows)
    (out / "summary.md").write_text(summary_markdown(runs))
    from ..plots.dilatancy import plot_dilatancy

    paths = [out / "segments.csv", out / "summary.md"]
    paths.append(plot_dilatancy(runs, cells(runs), out / "dilatancy.png"))
    return paths
