"""Run-time guards: callbacks that stop a run with a PhysicsError naming the cause and the fix.

Each guard is called as ``guard(sim)`` from :class:`gouge_cli.driver.schedules.Every`, between
numba chunks, and raises :class:`gouge_cli.errors.PhysicsError` (cause, fix, time) when
its condition holds. None of them changes the state, so a guarded run is bit for bit the
unguarded one. :class:`Guards` runs all four on one scan of the state;
:func:`guard_callbacks` wraps it in an ``Every`` for a scene.

* :class:`NonFiniteGuard` - a grain coordinate, velocity or spin, the top wall, or (with
  fluid) the pore pressure is NaN/inf.
* :class:`OverlapGuard` - the largest overlap of a neighbour pair, divided by the smaller
  radius, exceeds ``limit`` (default 0.5: a Hertz contact at 0.5 R is far outside the law).
* :class:`KineticEnergyGuard` - energy appears that nothing supplied. Energy balance of the
  whole scene between an earlier check j and now (damping and friction only remove energy):

      K(t) <= B_j(t) = E_j + sigma L (z_j - z(t)) + W(j -> t),
      E_j = K_j + U_contact,j + U_fluid,j + 1/2 k L s_j^2,

  K the kinetic energy (free grains, translation + rotation, plus the top body
  m_b L |v|^2 / 2), U_contact the Hertz energy 0.4 c_n sqrt(R_ij) xi^(5/2) plus the stored
  tangential energy k_s ds^2 / 2 of every contact, U_fluid = sum_cells beta phi P^2 / 2 dx dz
  the compression energy of the pore fluid, s the spring stretch, z the top-wall height
  (the normal load sigma L does work as it falls) and W the load point's work, summed per
  check as k L V_s dt max(|s|) (an upper bound). The guard fires when

      K(t) > margin * max(min_j B_j(t), floor),   margin = 10, floor = 0.01 sigma L D_max,

  over references j kept at every check for the last 10 checks, every 10th for the last
  100, every 100th for the last 1000 and every 1000th for the last 10^4, so a slow
  exponential growth is caught as well as a sudden one. A real slip only converts stored
  energy (K stays below B_j); a numerical instability (a step above the bound, a fluid
  coupling that is not energy-consistent) creates energy and trips the rule. The margin
  absorbs the approximations (W is an upper bound, the tangential energy uses today's k_s).
* :class:`FluidSubstepGuard` - the explicit (FTCS) pressure solver needed more than
  ``limit`` sub-steps in the last fluid update, i.e. the fluid step is more than
  limit * explicit_safety times the FTCS bound (FluidGrid.state[S_DT_MAX]). The kernel
  itself stops (status 1) only above 1e5 sub-steps; this guard stops far earlier, where
  the explicit solver has become pointlessly expensive.

Cost: one call of all four guards is one scan of the grains and pairs, less than one time step;
they run at the series cadence (every output.series_interval t0, about a hundred steps), so they
add about a percent or less to a run.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..kernels import layout as L
from typing import Any

from ..errors import PhysicsError
from ..io.layout import perm_text
from .callbacks import Callback
from .schedules import Every

# what a guard checks: a driver.simulation.Simulation, not imported here (the guards sit below the
# loop and the phases, which import them)
Sim = Any


@dataclass
class Scan:
    """One pass over the state: what every guard needs."""

    time: float
    nonfinite: int
    kinetic: float
    overlap: float
    pair: tuple
    contact_energy: float

    @classmethod
    def of(cls, sim: Sim) -> "Scan":
        """From Simulation.measure (kernels.measure; shared with the series row of the same step),
        plus the top wall's kinetic energy."""
        s = sim.state
        row = sim.measure()
        kinetic = row["kinetic_energy"]
        if s.top.size:
            kinetic += 0.5 * sim.wall_mass_per_length * s.width * (s.wall[L.W_VX] ** 2 + s.wall[L.W_VZ] ** 2) \
                * sim.inertia_scale       # stick scaling: the wall's scaled mass
        return cls(s.time, int(row["nonfinite"]), float(kinetic), float(row["max_overlap"]), row["worst_pair"],
                   float(row["contact_energy"]))


def _suspects(sim: Sim) -> str:
    """Parameters near their own stability limit at this step (preflight), named first."""
    from ..model.preflight import damped_step_bound, min_wall_mass

    cfg, dt = sim.config, float(sim.params[L.DT])
    out = []
    if cfg.material.damping > 0 and dt > 0.5 * damped_step_bound(cfg):
        out.append(f"lower material.damping (now {cfg.material.damping:g} 1/t0; the dashpot is stable up to "
                   f"dt = {damped_step_bound(cfg):.3g} t0)")
    if cfg.loading.wall_mass is not None and cfg.loading.wall_mass < 4.0 * min_wall_mass(cfg, dt):
        out.append(f"raise loading.wall_mass (now {cfg.loading.wall_mass:g}, stable from {min_wall_mass(cfg, dt):.3g} "
                   "rho d^2)")
    if cfg.material.density != 1.0 and cfg.numerics.dt is not None:
        out.append(f"raise material.density (now {cfg.material.density:g}: lighter grains need a smaller numerics.dt)")
    return f"{'; '.join(out)}; or " if out else ""


def _dt_hint(sim: Sim) -> str:
    n = sim.config.numerics
    knob = f"numerics.dt (now {n.dt:g} t0)" if n.dt is not None else f"numerics.dt_safety (now {n.dt_safety:g})"
    return f"{_suspects(sim)}lower {knob}; the step is {sim.params[L.DT]:.4g} t0"


def _fluid_hint(sim: Sim) -> str:
    if sim.fluid is None:
        return ""
    f = sim.config.fluid
    return (f"; with pore fluid, also lower fluid.step (now {f.step:g} t0, the period of the drag update); "
            f"the coupling stiffens as fluid.permeability (now {perm_text(f.permeability)} d^2) falls and as "
            f"fluid.filter_width (now {f.filter_width:g} d, the averaging width) narrows")


class NonFiniteGuard:
    """Stop on NaN/inf in the grains, the top wall or the pore pressure."""

    def __call__(self, sim: Sim, scan: Scan | None = None):
        s = sim.state
        bad = (scan or Scan.of(sim)).nonfinite
        wall_bad = not all(math.isfinite(v) for v in s.wall[:L.W_VZ + 1])
        pressure_bad = sim.fluid is not None and not bool(np.isfinite(sim.fluid.pressure).all())
        if bad or wall_bad or pressure_bad:
            parts = [f"{bad} grains"] if bad else []
            parts += ["the top wall"] if wall_bad else []
            parts += ["the pore pressure"] if pressure_bad else []
            raise PhysicsError(f"non-finite state ({', '.join(parts)})",
                               f"the integration is unstable: {_dt_hint(sim)}{_fluid_hint(sim)}", s.time)


class OverlapGuard:
    """Stop when a pair overlaps by more than ``limit`` of the smaller radius."""

    def __init__(self, limit: float = 0.5):
        self.limit = float(limit)

    def __call__(self, sim: Sim, scan: Scan | None = None):
        scan = scan or Scan.of(sim)
        if scan.overlap > self.limit:
            i, j = scan.pair
            raise PhysicsError(
                f"runaway overlap: grains {i} and {j} overlap by {scan.overlap:.3g} of the smaller radius "
                f"(limit {self.limit:g})",
                f"{_suspects(sim)}grains are too soft for the load or the step too large: lower "
                f"loading.normal_stress (now {sim.config.loading.normal_stress:g} E) or loading.velocity, or "
                f"{_dt_hint(sim).removeprefix(_suspects(sim))}"
                f"{_fluid_hint(sim)}", scan.time)


def fluid_energy(grid) -> float:
    """Compression energy of the pore fluid, sum beta phi P^2 / 2 dx dz [E d^3] (phi clamped)."""
    if grid is None:
        return 0.0
    beta = grid.params[L.P_BETA]
    return float(0.5 * beta * np.sum(grid._clamped_porosity() * grid.pressure ** 2) * grid.dx * grid.dz)


class KineticEnergyGuard:
    """Stop when kinetic energy exceeds what the scene stored and the loading supplied (module doc)."""

    LEVELS = 4      # reference spacings 1, 10, 100, 1000 checks
    KEEP = 10       # references per level

    def __init__(self, margin: float = 10.0, floor: float = 0.01):
        self.margin = float(margin)
        self.floor = float(floor)
        self.checks = 0
        self.work = 0.0             # load-point work bound W since the first check
        self.last = None            # (time, |stretch|) of the previous check
        self.references = [deque(maxlen=self.KEEP) for _ in range(self.LEVELS)]

    def state_dict(self) -> dict:
        """The energy history (JSON-able; floats round-trip exactly), for latest.h5."""
        return {"checks": self.checks, "work": self.work, "last": list(self.last) if self.last else None,
                "references": [[list(r) for r in level] for level in self.references]}

    def load_state_dict(self, state: dict):
        self.checks = int(state["checks"])
        self.work = float(state["work"])
        self.last = tuple(state["last"]) if state["last"] is not None else None
        for level, saved in zip(self.references, state["references"]):
            level.clear()
            level.extend(tuple(r) for r in saved)

    @staticmethod
    def _load(sim: Sim) -> tuple[float, float, float]:
        """(|spring stretch| [d], top-wall height [d], spring energy [E d^3]); zeros without a wall."""
        s, p = sim.state, sim.params
        if not s.top.size:
            return 0.0, 0.0, 0.0
        stretch = sim.spring_stretch()
        return abs(float(stretch)), float(s.wall[L.W_Z]), 0.5 * p[L.SPRING] * s.width * float(stretch) ** 2

    def budget(self, sim: Sim, wall_z: float) -> float:
        """min_j B_j(t) over the kept references (inf before the first)."""
        sigma_l = sim.params[L.SIGMA] * sim.state.width if sim.state.top.size else 0.0
        best = math.inf
        for level in self.references:
            for stored, z_ref, work_ref in level:
                best = min(best, stored + sigma_l * (z_ref - wall_z) + (self.work - work_ref))
        return best

    def __call__(self, sim: Sim, scan: Scan | None = None):
        scan = scan or Scan.of(sim)
        s, p = sim.state, sim.params
        stretch, wall_z, spring = self._load(sim)
        if not math.isfinite(scan.kinetic):
            raise PhysicsError("non-finite kinetic energy",
                               f"the integration is unstable: {_dt_hint(sim)}{_fluid_hint(sim)}", scan.time)
        if self.last is not None and p[L.DRIVE] > 0 and s.top.size:
            self.work += p[L.SPRING] * s.width * p[L.V_LOAD] * (scan.time - self.last[0]) * max(stretch, self.last[1])
        self.last = (scan.time, stretch)
        floor = self.floor * p[L.SIGMA] * s.width * 2.0 * float(s.radius.max()) if s.top.size else 0.0
        budget = self.budget(sim, wall_z)
        if scan.kinetic > self.margin * max(budget, floor):
            raise PhysicsError(
                f"kinetic-energy blow-up: {scan.kinetic:.3g} E d^3, more than {self.margin:g} x the "
                f"{max(budget, floor):.3g} E d^3 that the contacts, the pore fluid, the spring and the normal "
                "load could have supplied (energy is being created)",
                f"the integration is unstable: {_dt_hint(sim)}{_fluid_hint(sim)}", scan.time)
        stored = scan.kinetic + scan.contact_energy + fluid_energy(sim.fluid) + spring
        for level, refs in enumerate(self.references):
            if self.checks % (10 ** level) == 0:
                refs.append((stored, wall_z, self.work))
        self.checks += 1


class FluidSubstepGuard:
    """Stop when the explicit pressure solver needs more than ``limit`` sub-steps per update."""

    def __init__(self, limit: int = 10_000):
        self.limit = int(limit)

    def __call__(self, sim: Sim, scan: Scan | None = None):
        grid = sim.fluid
        if grid is None or grid.solver != "explicit" or grid.state[L.S_UPDATES] < 1:
            return
        substeps = int(grid.state[L.S_SUBSTEPS])
        if substeps > self.limit:
            bound = float(grid.state[L.S_DT_MAX])
            step = sim.fluid_interval * sim.dt
            raise PhysicsError(
                f"explicit pressure step above its bound: the fluid step {step:.4g} t0 is {step / bound:.3g} x the "
                f"FTCS bound {bound:.3g} t0 and needs {substeps} sub-steps per update (limit {self.limit})",
                "use fluid.solver=implicit (unconditionally stable), or raise fluid.cell_size "
                f"(now {sim.config.fluid.grid_spacing:g} d); the diffusivity grows with fluid.permeability "
                f"(now {perm_text(sim.config.fluid.permeability)} d^2)", sim.state.time)


class Guards(Callback):
    """All four guards on one scan of the state, cheapest first; a callback every
    output.series_interval (or ``interval`` [t0]) whose state is the energy guard's history."""

    name = "guards"

    def __init__(self, overlap_limit: float = 0.5, substep_limit: int = 10_000, margin: float = 10.0,
                 interval: float | None = None):
        self.interval = interval
        self.nonfinite = NonFiniteGuard()
        self.energy = KineticEnergyGuard(margin)
        self.overlap = OverlapGuard(overlap_limit)
        self.fluid = FluidSubstepGuard(substep_limit)

    def __call__(self, sim: Sim):
        scan = Scan.of(sim)
        for guard in (self.nonfinite, self.energy, self.overlap, self.fluid):
            guard(sim, scan)

    act = __call__

    def every(self, sim: Sim) -> Every:
        interval = sim.config.output.series_interval if self.interval is None else self.interval
        return Every.t0(sim, interval, self, self.name)

    def state_dict(self) -> dict:
        """What a resume needs (only the energy guard keeps a history)."""
        return {"energy": self.energy.state_dict()}

    def load_state_dict(self, state: dict, attached: dict | None = None):
        if "energy" in state:
            self.energy.load_state_dict(state["energy"])


def guard_callbacks(sim: Sim, interval: float | None = None, **limits) -> list[Every]:
    """[Every(steps, Guards(**limits))] at `interval` [t0] (default: output.series_interval)."""
    return [Guards(interval=interval, **limits).every(sim)]


def check(sim: Sim):
    """Stop with a PhysicsError on NaN/inf or a runaway overlap (the non-finite and overlap
    guards, run once; compaction's check, the benchmark)."""
    scan = Scan.of(sim)
    NonFiniteGuard()(sim, scan)
    OverlapGuard()(sim, scan)
