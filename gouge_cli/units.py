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
        what = f"does not measure {dimension}" if unit in _UNITS else "is not a unit gouge knows"
        raise ValueError(f"unit {unit!r} {what}; allowed units: {hint}")
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
                "stress": pint_unit("sigma"), "sigma_MPa": self.sigma_MPa, "slip": pint_unit("d"), "d_m": self.d_m,
                "permeability": pint_unit("d^2"), "d2_m2": self.d_m ** 2}

    def caption(self) -> str:
        """One line for a figure: the SI size of each unit."""
        return (f"units: t0 = {self.t0_s:.3g} s, V_s = {self.V_s_m_s:.3g} m/s, σ = {self.sigma_MPa:.3g} MPa, "
                f"d = {self.d_m * 1e3:.3g} mm")


# --- unit strings in outputs ---------------------------------------------------------------
# The one table of the non-SI unit symbols gouge writes into run files, analysis tables and the
# Python API's attrs: symbol as written -> (key of its SI size in :func:`unit_sizes`, SI unit, meaning).
# A unit string is a product of symbols with powers ('E d_grain^2', 'rho_s d_grain^2', '1/t0'); '1'
# is dimensionless; a vector with mixed units lists one unit per element ('d_grain, v0, E d_grain^2').
# Every symbol is a name that a plain pint registry refuses rather than misreads (pint reads a bare
# 'd' as a day and 'sigma' as the Stefan-Boltzmann constant).
SCALE_UNITS: dict[str, tuple[str, str, str]] = {
    "d_grain": ("length_m", "m", "mean grain diameter d"),
    "E": ("stress_pa", "Pa", "Young's modulus of the grains"),
    "rho_s": ("density_kg_m3", "kg / m**3", "grain density"),
    "t0": ("time_s", "s", "time unit d / sqrt(E / rho_s)"),
    "v0": ("velocity_m_s", "m / s", "velocity unit d / t0"),
    "V_s": ("V_s", "m / s", "the run's loading velocity"),
    "sigma_n": ("sigma", "Pa", "the run's normal stress sigma"),
    "m_b": ("m_b", "kg / m", "the run's top-wall mass per unit length"),
}
#: the physics notation that gouge's own unit tables use -> the symbol written (pint_unit translates)
NOTATION: dict[str, str] = {"d": "d_grain", "sigma": "sigma_n"}
#: SI symbols that outputs use as they are (pint knows them)
SI_SYMBOLS: tuple[str, ...] = ("1", "m", "s", "kg", "Pa", "MPa")
_BASE = {"m": {"m": 1}, "Pa": {"Pa": 1}, "s": {"s": 1}, "m / s": {"m": 1, "s": -1},
         "kg / m**3": {"kg": 1, "m": -3}, "kg / m": {"kg": 1, "m": -1}}
_NAN = float("nan")
_NOTATION = re.compile(r"\b(" + "|".join(NOTATION) + r")\b")


def pint_unit(unit: str) -> str:
    """A unit as written into outputs: the dimensionless '-' (or '') is pint's '1', per element of a
    list, and the notation's d and sigma are spelled d_grain and sigma_n (:data:`NOTATION`)."""
    parts = [p.strip() for p in str(unit).split(",")]
    return ", ".join("1" if p in ("-", "") else _NOTATION.sub(lambda m: NOTATION[m.group(1)], p) for p in parts)


def unit_factors(unit: str) -> list[tuple[str, float]] | None:
    """(symbol, power) of each factor of one unit string ('E d_grain^3/t0'); None if it is not one such product."""
    unit = pint_unit(unit.strip())
    if "," in unit:
        return None
    factors = []
    for sign, part in ((1, unit.split("/")[0]), *((-1, q) for q in unit.split("/")[1:])):
        for token in part.split():
            name, _, power = token.partition("^")
            try:
                factors.append((name, sign * (float(power) if power else 1.0)))
            except ValueError:
                return None
    return [(n, p) for n, p in factors if n != "1"]


def unit_sizes(scales: "Scales | dict", V_s: float = _NAN, sigma: float = _NAN, m_b: float = _NAN) -> dict[str, float]:
    """SI size of each SCALE_UNITS symbol for one run (``scales``: Scales or a run's ``scales`` dict)."""
    s = scales.as_dict() if isinstance(scales, Scales) else dict(scales)
    return {symbol: {"V_s": V_s * s["velocity_m_s"], "sigma": sigma * s["stress_pa"],
                     "m_b": m_b * s["density_kg_m3"] * s["length_m"] ** 2}.get(key, s.get(key, _NAN))
            for symbol, (key, _, _) in SCALE_UNITS.items()}


def si_of(unit: str, sizes: dict[str, float]) -> tuple[float, str] | None:
    """(factor, SI unit) of a unit made of SCALE_UNITS ('E d^3' -> (.., 'Pa * m**3')); None for any other."""
    factors = unit_factors(unit)
    if factors is None or any(name not in SCALE_UNITS for name, _ in factors):
        return None
    factor, dims = 1.0, {}
    for name, power in factors:
        factor *= sizes[name] ** power
        for base, exponent in _BASE[SCALE_UNITS[name][1]].items():
            dims[base] = dims.get(base, 0) + exponent * power
    up = [f"{b}**{e:g}" if e != 1 else b for b, e in dims.items() if e > 0]
    down = [f"{b}**{-e:g}" if e != -1 else b for b, e in dims.items() if e < 0]
    return factor, (" * ".join(up) or "1") + "".join(f" / {d}" for d in down)


def pint_definitions(scales: "Scales | dict", V_s: float = _NAN, sigma: float = _NAN, m_b: float = _NAN) -> str:
    """pint definition lines of the SCALE_UNITS symbols of one run (unknown sizes left out; docs/physics/units.md)."""
    sizes = unit_sizes(scales, V_s, sigma, m_b)
    lines = ["# gouge's units for one run (gouge_cli.units.SCALE_UNITS; docs/physics/units.md)"]
    for symbol, (_, si, meaning) in SCALE_UNITS.items():
        if math.isfinite(sizes[symbol]):
            lines.append(f"{symbol} = {sizes[symbol]!r} * {si.replace('**', ' ** ')}  # {meaning}")
    return "\n".join(lines) + "\n"


def pint_registry(scales: "Scales | dict", V_s: float = _NAN, sigma: float = _NAN, m_b: float = _NAN):
    """A pint.UnitRegistry that reads every unit string gouge writes (needs pint, which gouge does not require)."""
    try:
        import pint
    except ImportError as err:
        raise ImportError("pint_registry needs pint (pip install pint); pint_definitions() gives the text") from err
    registry = pint.UnitRegistry(force_ndarray_like=True)     # (pint-xarray needs it)
    registry.load_definitions(pint_definitions(scales, V_s, sigma, m_b).splitlines())
    return registry
