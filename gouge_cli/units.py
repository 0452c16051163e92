"""Scales between SI and gouge's dimensionless units (docs/physics/units.md).

Internally d = E = rho_s = 1. A config value may be a plain number (already
dimensionless) or a string with an SI unit, e.g. ``"24 MPa"`` or ``"5e-4 m"``;
:func:`to_dimensionless` converts it using the field's dimension.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Scales:
    """SI value of one dimensionless unit of each quantity."""

    length_m: float = 5e-4          # mean grain diameter d
    stress_pa: float = 8e10         # Young's modulus E
    density_kg_m3: float = 2460.0   # grain density rho_s

    @property
    def velocity_m_s(self) -> float:
        return math.sqrt(self.stress_pa / self.density_kg_m3)

    @property
    def time_s(self) -> float:
        return self.length_m / self.velocity_m_s

    def si(self, dimension: str) -> float:
        """SI size of one unit of `dimension` (a key of DIMENSIONS)."""
        d, e, r, t = self.length_m, self.stress_pa, self.density_kg_m3, self.time_s
        return {
            "dimensionless": 1.0,
            "length": d,
            "stress": e,
            "velocity": d / t,
            "time": t,
            "permeability": d * d,
            "stiffness_per_length": e / d,   # spring force per wall length per length
            "mass_per_length": r * d * d,    # unit out-of-plane thickness d
            "viscosity": e * t,
            "compressibility": 1.0 / e,
            "density": r,
        }[dimension]

    def as_dict(self) -> dict:
        out = asdict(self)
        out.update(velocity_m_s=self.velocity_m_s, time_s=self.time_s)
        return out


# SI unit symbols accepted in config strings, with their factor to the base SI unit
# and the dimension they measure.
_UNITS: dict[str, tuple[float, str]] = {
    "m": (1.0, "length"), "mm": (1e-3, "length"), "um": (1e-6, "length"),
    "Pa": (1.0, "stress"), "kPa": (1e3, "stress"), "MPa": (1e6, "stress"), "GPa": (1e9, "stress"),
    "m/s": (1.0, "velocity"), "mm/s": (1e-3, "velocity"), "um/s": (1e-6, "velocity"),
    "s": (1.0, "time"), "ms": (1e-3, "time"), "us": (1e-6, "time"),
    "m2": (1.0, "permeability"), "m^2": (1.0, "permeability"),
    "Pa/m": (1.0, "stiffness_per_length"), "MPa/m": (1e6, "stiffness_per_length"),
    "kg/m": (1.0, "mass_per_length"),
    "Pa s": (1.0, "viscosity"), "Pa.s": (1.0, "viscosity"),
    "1/Pa": (1.0, "compressibility"), "Pa^-1": (1.0, "compressibility"),
    "kg/m3": (1.0, "density"), "kg/m^3": (1.0, "density"),
}

_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def to_dimensionless(value, dimension: str, scales: Scales) -> float:
    """Number -> itself; "24 MPa" -> 24e6 / E. Raises ValueError naming what is allowed."""
    if isinstance(value, bool):
        raise ValueError("expected a number, got a boolean")
    if isinstance(value, (int, float)):
        return float(value)
    if not isinstance(value, str):
        raise ValueError(f"expected a number or a quantity string, got {type(value).__name__}")
    match = _QUANTITY.match(value)
    if not match:
        raise ValueError(f"cannot read {value!r} as a number with an optional SI unit")
    number, unit = float(match.group(1)), match.group(2)
    if not unit:
        return number
    allowed = sorted(u for u, (_, dim) in _UNITS.items() if dim == dimension)
    if unit not in _UNITS or _UNITS[unit][1] != dimension:
        hint = ", ".join(allowed) if allowed else "none (give a plain dimensionless number)"
        raise ValueError(f"unit {unit!r} does not measure {dimension}; allowed units: {hint}")
    factor, _ = _UNITS[unit]
    return number * factor / scales.si(dimension)


@dataclass(frozen=True)
class ResultUnits:
    """The one unit of each quantity in gouge's results, and its SI size for one run.

    times: t0; wall velocities: V_s (the loading velocity); stresses, strengths and pore
    pressure: sigma (the normal stress, so tau/sigma, P/sigma); slip distance: d; permeability
    (kappa_c): d^2. SI from the run's scales (Table 1: d, E, rho_s) and its V_s and sigma.
    """

    scales: Scales
    V_s: float          # loading velocity [v0]
    sigma: float        # normal stress [E]

    @classmethod
    def of_run(cls, config: dict, V_s: float, sigma: float) -> "ResultUnits":
        """From a run file's config dict (its ``scales`` section, defaults where absent)."""
        s = (config or {}).get("scales") or {}
        base = Scales()
        return cls(Scales(float(s.get("length_m", base.length_m)), float(s.get("stress_pa", base.stress_pa)),
                          float(s.get("density_kg_m3", base.density_kg_m3))), float(V_s), float(sigma))

    @property
    def t0_s(self) -> float:
        return self.scales.time_s

    @property
    def V_s_m_s(self) -> float:
        return self.V_s * self.scales.velocity_m_s

    @property
    def sigma_MPa(self) -> float:
        return self.sigma * self.scales.stress_pa / 1e6

    @property
    def d_m(self) -> float:
        return self.scales.length_m

    def as_dict(self) -> dict:
        """The units and their SI sizes (for summary.json and figure captions)."""
        return {"time": "t0", "t0_s": self.t0_s, "wall_velocity": "V_s", "V_s_m_s": self.V_s_m_s,
                "stress": "sigma", "sigma_MPa": self.sigma_MPa, "slip": "d", "d_m": self.d_m,
                "permeability": "d^2", "d2_m2": self.d_m ** 2}

    def caption(self) -> str:
        """One line for a figure: the SI size of each unit."""
        return (f"units: t0 = {self.t0_s:.3g} s, V_s = {self.V_s_m_s:.3g} m/s, σ = {self.sigma_MPa:.3g} MPa, "
                f"d = {self.d_m * 1e3:.3g} mm")
