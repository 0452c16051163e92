"""Checks of a whole config that need more than one section: run by `gouge config`, `run` and
`restart` before anything is written, so that a config that cannot run is exit 2 naming the key.

* numerics.dt within the stability bound (timestep.choose_dt);
* the packing fits its width (packing.packing_layout);
* material.damping: the dashpot on the stiffest normal mode (a pair of the smallest grains at
  the reference overlap of timestep, omega = sqrt(k_n / (m_min / 2))) is stable for

      dt <= (2 / omega) (sqrt(1 + zeta^2) - zeta),   zeta = gamma / (2 omega)

  (explicit integration of a damped oscillator; gamma = 0 gives the undamped 2 / omega);
* loading.wall_mass (when set): the top wall, a rigid body of m_b L on its L / wall_spacing
  grains each pressing on about two layer grains of stiffness k_n, is stable for

      dt <= 2 sqrt(m_b wall_spacing / (2 k_n)),  i.e.  m_b >= (dt / 2)^2 2 k_n / wall_spacing;

  a lighter wall blows up within a few steps (a segmentation fault once its grains leave the cell grid);
* numerics.device: gpu needs numba-cuda and a CUDA device (kernels.gpu.availability);
* the run length: (compaction.max_time + run.duration) / dt steps of n_grains grains, estimated at
  RATE grain-steps per second per thread; above MAX_HOURS it is refused, above NOTE_HOURS the
  estimate is returned as a note to print.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..config import Config
from ..errors import ConfigError
from .packing import packing_layout
from .timestep import choose_dt, contact_constants, stability_bound

RATE = 2e7              # grain-steps per second and thread, about (README Speed: 1.5-3.5e7)
NOTE_HOURS = 1.0
MAX_HOURS = 1e5         # eleven years on one thread


@dataclass(frozen=True)
class Preflight:
    dt: float           # the run's step [t0]
    steps: float        # steps of compaction (at most) and loading
    hours: float        # estimated wall time on one thread [h]
    note: str           # "" or the estimate, for runs longer than NOTE_HOURS


def _pair_normal_mode(config: Config) -> tuple[float, float]:
    """(k_n [E d], omega [1/t0]) of two smallest grains at the reference overlap."""
    bound = stability_bound(config)
    c_normal, _ = contact_constants(config)
    d_min = config.packing.diameter_min
    k_n = 1.5 * c_normal * math.sqrt(0.5 * d_min * bound.reference_overlap)
    mass = config.material.density * math.pi * d_min ** 3 / 6.0
    return k_n, math.sqrt(k_n / (0.5 * mass))


def damped_step_bound(config: Config) -> float:
    """Largest stable dt [t0] of the damped normal mode (module doc)."""
    _, omega = _pair_normal_mode(config)
    zeta = config.material.damping / (2.0 * omega)
    return 2.0 / omega * (math.sqrt(1.0 + zeta * zeta) - zeta)


def min_wall_mass(config: Config, dt: float) -> float:
    """Smallest stable loading.wall_mass [rho d^2] at step dt (module doc)."""
    k_n, _ = _pair_normal_mode(config)
    return (0.5 * dt) ** 2 * 2.0 * k_n / config.packing.wall_spacing


def check_config(config: Config, threads: int = 1) -> Preflight:
    """Raise ConfigError naming the key when `config` cannot run; else the step and an estimate."""
    dt = choose_dt(config)
    packing_layout(config)
    limit = damped_step_bound(config)
    if dt > limit:
        raise ConfigError(
            f"material.damping = {config.material.damping:g}: the normal dashpot is unstable at the step "
            f"{dt:.4g} t0 (stable up to {limit:.4g} t0 at this damping); lower material.damping or "
            "numerics.dt_safety / numerics.dt")
    m_b = config.loading.wall_mass
    if m_b is not None and m_b < min_wall_mass(config, dt):
        raise ConfigError(
            f"loading.wall_mass = {m_b:g} rho d^2 is too light for the step {dt:.4g} t0: the top wall would "
            f"oscillate unstably on its grains; use loading.wall_mass >= {min_wall_mass(config, dt):.3g} "
            "(or leave it unset: the mass of its grains), or a smaller numerics.dt")
    if config.numerics.device == "gpu":
        from ..kernels.gpu import availability

        reason = availability()
        if reason:
            raise ConfigError(f"numerics.device = gpu cannot run here: {reason}; use numerics.device: cpu")
    steps = (config.compaction.max_time + config.run.duration) / dt
    hours = steps * config.packing.n_grains / RATE / 3600.0
    per = max(1, threads)
    estimate = (f"{steps:.3g} steps of {config.packing.n_grains} grains: about {hours / per:.3g} h at "
                f"{RATE:.0e} grain-steps/s per thread on {per} thread(s)")
    if hours / per > MAX_HOURS:
        raise ConfigError(f"numerics.dt = {dt:.3g} t0 is too small to finish: {estimate}; raise numerics.dt "
                          "(or numerics.dt_safety), or shorten run.duration / compaction.max_time")
    note = f"note: this run is long, {estimate} (Ctrl-C stops it; `gouge resume` continues)" \
        if hours / per > NOTE_HOURS else ""
    return Preflight(dt, steps, hours, note)
