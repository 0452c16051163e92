"""Velocity-step records and what they measure: the dilatancy coefficient eps = d(phi)/d(ln V)
and the undrained strengthening it predicts (the protocol: gouge_cli.studies.dilatancy).

Per seed and normal stress sigma (:class:`StepRun`), each segment's steady state (:class:`Segment`,
the second half of the segment) at ratio r = V / V_1, drained (the dry model) and undrained:

    eps_r = (phi_r - phi_1) / ln r                                         (drained)
    P_pred = (phi_1 / (phi_1 + eps_v) - 1) / beta,  eps_v = (phi_r - phi_1) / (1 - phi_1)
    predicted strengthening  mu_r (-P_pred) / sigma,  measured  (tau/sigma)_undrained - _drained

(the pressure equation's undrained limit, docs/physics/fluid.md; about -eps ln r / (beta phi)).
Summaries (:func:`cells`) are seed means with Student-t 95 % intervals: the seed is the unit.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..config import FluidConfig
from .seedboot import seed_mean

@dataclass(frozen=True)
class Segment:
    """The steady state (second half) of one segment at ratio r = V / V_1.

    velocity: the wall's mean speed [v0], inertial number I [-], porosity phi [-] and its
    batch-means standard error, friction tau/sigma [-] (the spring's), the wall speed's
    coefficient of variation [-],
    ``stuck``: the wall stopped at least once (stick-slip, not steady sliding), mean pore pressure
    [E] (NaN drained), duration [t0]."""

    ratio: float
    drained: bool
    velocity: float
    inertial: float
    porosity: float
    porosity_se: float
    friction: float
    speed_cv: float
    stuck: bool
    pressure: float
    duration: float


@dataclass(frozen=True)
class StepRun:
    """One seed at one normal stress sigma [E]: its drained and undrained segments."""

    seed: int
    sigma: float
    perm: float
    stiff: float
    segments: tuple[Segment, ...]
    beta: float = FluidConfig().compressibility
    wall_seconds: float = 0.0

    def segment(self, ratio: float, drained: bool) -> Segment | None:
        return next((s for s in self.segments if s.ratio == ratio and s.drained == drained), None)

    def steady(self) -> bool:
        """Every segment slid without stopping."""
        return not any(s.stuck for s in self.segments)

    def eps(self, ratio: float) -> float:
        """Drained dilatancy coefficient (phi_r - phi_1) / ln r [-]."""
        a, b = self.segment(1.0, True), self.segment(ratio, True)
        return (b.porosity - a.porosity) / math.log(ratio) if a and b else float("nan")

    def slope(self, ratio: float) -> float:
        """Drained (phi_r - phi_1) / (I_r - I_1) [-]: b of the dense-flow law phi = phi_c - b I
        (with the sign of a dilation: positive when the faster layer is looser)."""
        a, b = self.segment(1.0, True), self.segment(ratio, True)
        return (b.porosity - a.porosity) / (b.inertial - a.inertial) if a and b else float("nan")

    def predicted_pressure(self, ratio: float) -> float:
        """Undrained pore pressure [E] of the drained dilation (module docstring)."""
        a, b = self.segment(1.0, True), self.segment(ratio, True)
        if not (a and b):
            return float("nan")
        strain = (b.porosity - a.porosity) / (1.0 - a.porosity)
        return (a.porosity / (a.porosity + strain) - 1.0) / self.beta

    def predicted_strengthening(self, ratio: float) -> float:
        """mu_r (-P_pred) / sigma [-]: the rise of tau/sigma the predicted suction gives."""
        b = self.segment(ratio, True)
        return b.friction * -self.predicted_pressure(ratio) / self.sigma if b else float("nan")

    def measured_strengthening(self, ratio: float) -> float:
        """(tau/sigma) undrained - drained at ratio r [-] (NaN without both)."""
        d, u = self.segment(ratio, True), self.segment(ratio, False)
        return u.friction - d.friction if d and u else float("nan")

    def measured_pressure(self, ratio: float) -> float:
        """Steady mean pore pressure of the undrained segment at r, less that of the r = 1 one [E]."""
        u, c = self.segment(ratio, False), self.segment(1.0, False)
        return u.pressure - (c.pressure if c else 0.0) if u else float("nan")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> StepRun:
        # (records written before 2026-12-08 also hold "speed", the same number as "velocity")
        segments = tuple(Segment(**{k: v for k, v in s.items() if k != "speed"}) for s in data["segments"])
        return cls(**{**data, "segments": segments})


def steady_state(rows: list[dict], start_time: float, ratio: float, drained: bool, sigma: float) -> Segment:
    """The Segment of series `rows` (Simulation.measure) after `start_time` [t0]: their second half."""
    t = np.array([r["time"] for r in rows])
    end = t[-1]
    keep = t >= start_time + 0.5 * (end - start_time)
    pick = [r for r, k in zip(rows, keep) if k]
    phi = np.array([r["porosity"] for r in pick])
    speed = np.array([r["wall_vx"] for r in pick])
    thickness = float(np.mean([r["thickness"] for r in pick]))
    batches = [b.mean() for b in np.array_split(phi, 10) if b.size]
    velocity = float(np.mean(speed))
    pressure = float(np.mean([r["pressure_mean"] for r in pick])) if "pressure_mean" in pick[0] else float("nan")
    return Segment(ratio=ratio, drained=drained, velocity=velocity,
                   inertial=velocity / thickness / math.sqrt(sigma),
                   porosity=float(phi.mean()), porosity_se=float(np.std(batches, ddof=1) / math.sqrt(len(batches))),
                   friction=float(np.mean([r["tau_over_sigma"] for r in pick])),
                   speed_cv=float(np.std(speed) / abs(velocity)) if velocity else float("inf"),
                   stuck=bool(np.min(speed) <= 0.0), pressure=pressure, duration=float(end - start_time))


# ---- tables -------------------------------------------------------------------------------------
SEGMENT_COLUMNS = ("seed", "sigma", "ratio", "drained", "velocity", "inertial", "porosity", "porosity_se",
                   "friction", "speed_cv", "stuck", "pressure", "duration")


def segment_rows(runs: list[StepRun]) -> list[dict]:
    """One row per segment (SEGMENT_COLUMNS)."""
    return [{"seed": r.seed, "sigma": r.sigma, **{k: getattr(s, k) for k in SEGMENT_COLUMNS[2:]}}
            for r in runs for s in r.segments]


@dataclass(frozen=True)
class Cell:
    """One (sigma, ratio): seed means with t intervals (the seed is the unit; 95 %)."""

    sigma: float
    ratio: float
    n_seeds: int
    steady: int
    inertial: float
    eps: tuple[float, float, float]
    slope: tuple[float, float, float]
    predicted: tuple[float, float, float]
    measured: tuple[float, float, float]
    pressure_ratio: tuple[float, float, float]


def cells(runs: list[StepRun]) -> list[Cell]:
    """The summary by (sigma, ratio)."""
    out = []
    for sigma in sorted({r.sigma for r in runs}):
        group = [r for r in runs if r.sigma == sigma]
        ratios = sorted({s.ratio for r in group for s in r.segments if s.ratio != 1.0})
        for ratio in ratios:
            seg = [r.segment(ratio, True) for r in group]
            out.append(Cell(sigma=sigma, ratio=ratio, n_seeds=len(group), steady=sum(r.steady() for r in group),
                            inertial=float(np.mean([s.inertial for s in seg if s])),
                            eps=seed_mean([r.eps(ratio) for r in group]),
                            slope=seed_mean([r.slope(ratio) for r in group]),
                            predicted=seed_mean([r.predicted_strengthening(ratio) for r in group]),
                            measured=seed_mean([r.measured_strengthening(ratio) for r in group]),
                            pressure_ratio=seed_mean([r.measured_pressure(ratio) / r.predicted_pressure(ratio)
                                                      for r in group])))
    return out


def _ci(v: tuple[float, float, float], fmt: str) -> str:
    if not math.isfinite(v[0]):
        return "n/a"
    if not math.isfinite(v[1]):
        return format(v[0], fmt)
    return f"{v[0]:{fmt}} [{v[1]:{fmt}}, {v[2]:{fmt}}]"


def summary_markdown(runs: list[StepRun]) -> str:
    """The table of cells (markdown), seed means and 95 % t intervals."""
    lines = ["| sigma [E] | V2/V1 | seeds (steady) | I at V2 | eps = dphi/dlnV | b = dphi/dI "
             "| d(tau/sigma) predicted | d(tau/sigma) measured | P measured / predicted |",
             "|---|---|---|---|---|---|---|---|---|"]
    for c in cells(runs):
        lines.append(f"| {c.sigma:g} | {c.ratio:g} | {c.n_seeds} ({c.steady}) | {c.inertial:.2g} | "
                     f"{_ci(c.eps, '.2e')} | {_ci(c.slope, '.3f')} | {_ci(c.predicted, '.3f')} | "
                     f"{_ci(c.measured, '.3f')} | "
                     f"{_ci(c.pressure_ratio, '.2f')} |")
    return "\n".join(lines) + "\n"
