"""Time-step bound from the stiffest contact mode (docs/physics/timestep.md).

The stiffest mode is tangential-rotational: for two discs with sphere inertia
I = m D^2/10 the effective mass at the contact point is m/7. Its stiffness is the
contact law's tangential k_s (kernels.contact.LAW.stiffness; Mindlin's) at the overlap where the
law's normal force equals a reference chain force F_ref = CHAIN_FACTOR * sigma * D_max (force
chains carry about ten times the mean contact force). The bound is the smaller of

    dt_tangential = 2 sqrt((m_min / 7) / k_s(xi_ref)),   dt_normal = 2 sqrt((m_min / 2) / k_n'(xi_ref)),

evaluated for a pair of the smallest grains (the lightest and, per unit force, stiffest).
The default step is ``dt_safety`` times the bound; a configured dt above it is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..config import Config
from ..errors import ConfigError
from ..kernels.contact import LAW
from .portable import cube, power

CHAIN_FACTOR = 10.0


def contact_constants(config: Config) -> tuple[float, float]:
    """(c_normal, c_tangential) of the contact law in force (kernels.contact.LAW.constants; Hertz-Mindlin:
    F_n = c_n sqrt(R xi) xi, k_s = c_t sqrt(R xi), thesis Eqs. 9-10)."""
    m = config.material
    return LAW.constants(m.youngs_modulus, m.poisson_ratio, m.tangential_stiffness_factor)


@dataclass(frozen=True)
class StepBound:
    bound: float          # critical step [t0]
    reference_overlap: float
    mode: str             # which mode sets the bound


def stability_bound(config: Config) -> StepBound:
    c_normal, c_tangential = contact_constants(config)
    d_min = config.packing.diameter_min
    r_pair = 0.5 * d_min  # harmonic mean radius of two smallest grains
    mass = config.material.density * math.pi * cube(d_min) / 6.0
    force = CHAIN_FACTOR * config.loading.normal_stress * config.packing.diameter_max
    overlap, k_n, k_s = LAW.stiffness(force, r_pair, c_normal, c_tangential, power)
    dt_t = 2.0 * math.sqrt(mass / 7.0 / k_s)
    dt_n = 2.0 * math.sqrt(mass / 2.0 / k_n)
    if dt_t <= dt_n:
        return StepBound(dt_t, overlap, "tangential-rotational")
    return StepBound(dt_n, overlap, "normal")


def choose_dt(config: Config) -> float:
    """The run's step: numerics.dt if given (refused above the bound), else dt_safety * bound."""
    b = stability_bound(config)
    dt = config.numerics.dt
    if dt is None:
        return config.numerics.dt_safety * b.bound
    if dt > b.bound:
        raise ConfigError(
            f"numerics.dt = {dt:g} is above the stability bound {b.bound:.4g} t0 "
            f"({b.mode} mode at sigma = {config.loading.normal_stress:g}); use numerics.dt <= {b.bound:.4g} "
            f"or leave it unset (default {config.numerics.dt_safety:g} x bound)"
        )
    return dt


def half_period(m: float, k: float) -> float:
    """Block-slider slip duration (half period) pi sqrt(m / k) (thesis Eq. 3) [t0]; m [rho_s d^2], k [E]."""
    return math.pi * math.sqrt(m / k)


def slip_duration(config: Config, wall_mass_per_length: float) -> float:
    """Predicted slip duration pi sqrt(m_b / k) of a scene (thesis Eq. 3) [t0]."""
    return half_period(wall_mass_per_length, config.loading.spring_constant)
