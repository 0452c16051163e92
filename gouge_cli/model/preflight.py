"""Checks of a whole config that need more than one section: run by model.scene.Scene, which every
Simulation is built from (`gouge config`, `run`, `restart` and a campaign's points build one before
anything is written), so that a config that cannot run is exit 2 naming the key.

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
  estimate is returned as a note to print;
* every interval (output.*_interval, slips.lead, slips.merge_gap, slips.min_duration) is at most
  MAX_STEPS steps of dt, so that its step count is a finite integer (1e308 is refused naming the key);
* numerics.threads above the machine's cores: a warning (the threads would share cores);
* every derived quantity above (contact stiffness, grain mass, reference overlap, step bound,
  dashpot frequency, step, step count, hours) is a finite positive number: an over- or underflow
  (e.g. material.youngs_modulus: 1e308, packing.diameter_min: 1e-300) is refused naming the keys
  of DERIVED_FROM whose own value, put back to its default, makes every quantity finite.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from ..config import Config, build_config
from ..errors import ConfigError
from .packing import packing_layout
from .timestep import choose_dt, contact_constants, stability_bound

RATE = 2e7              # grain-steps per second and thread, about (README Speed: 1.5-3.5e7)
NOTE_HOURS = 1.0
MAX_HOURS = 1e5         # eleven years on one thread
MAX_STEPS = 2 ** 62     # step counts are int64
INTERVALS = ("output.series_interval", "output.snapshot_interval", "output.checkpoint_interval",
             "slips.lead", "slips.merge_gap", "slips.min_duration")
#: Keys the derived quantities of the checks come from (searched for the culprit of a non-finite one).
DERIVED_FROM = ("material.youngs_modulus", "material.poisson_ratio", "material.tangential_stiffness_factor",
                "material.density", "material.damping", "packing.diameter_min", "packing.diameter_max",
                "packing.wall_spacing", "packing.n_grains", "loading.normal_stress", "loading.wall_mass",
                "numerics.dt", "numerics.dt_safety", "compaction.max_time", "run.duration")


class _NonFinite(ArithmeticError):
    """A derived quantity is not a finite positive number (its name is the message)."""


def _finite(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise _NonFinite(f"{name} = {value:g}")
    return value


@dataclass(frozen=True)
class Preflight:
    dt: float           # the run's step [t0]
    steps: float        # steps of compaction (at most) and loading
    hours: float        # estimated wall time on one thread [h]
    note: str           # "" or the estimate, for runs longer than NOTE_HOURS
    warning: str = ""   # "" or what may make the run slow (numerics.threads above the cores)


def _pair_normal_mode(config: Config) -> tuple[float, float]:
    """(k_n [E d], omega [1/t0]) of two smallest grains at the reference overlap."""
    bound = stability_bound(config)
    c_normal, _ = contact_constants(config)
    d_min = config.packing.diameter_min
    k_n = _finite("the normal stiffness k_n", 1.5 * c_normal * math.sqrt(0.5 * d_min * bound.reference_overlap))
    mass = _finite("the smallest grain's mass", config.material.density * math.pi * d_min ** 3 / 6.0)
    return k_n, _finite("the normal frequency omega", math.sqrt(k_n / (0.5 * mass)))


def damped_step_bound(config: Config) -> float:
    """Largest stable dt [t0] of the damped normal mode (module doc)."""
    _, omega = _pair_normal_mode(config)
    zeta = config.material.damping / (2.0 * omega)
    return _finite("the damped step bound", 2.0 / omega * (math.sqrt(1.0 + zeta * zeta) - zeta))


def min_wall_mass(config: Config, dt: float) -> float:
    """Smallest stable loading.wall_mass [rho d^2] at step dt (module doc)."""
    k_n, _ = _pair_normal_mode(config)
    return (0.5 * dt) ** 2 * 2.0 * k_n / config.packing.wall_spacing


def check_config(config: Config, threads: int = 1) -> Preflight:
    """Raise ConfigError naming the key when `config` cannot run; else the step and an estimate."""
    try:
        return _check(config, threads)
    except (ArithmeticError, ValueError) as exc:      # ValueError: math domain error
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(_non_finite(config, exc)) from None


def _derived(config: Config) -> None:
    """The derived quantities of the stability bound, each checked finite and positive."""
    c_normal, c_tangential = contact_constants(config)
    _finite("the Hertz constant c_n", c_normal)
    _finite("the Mindlin constant c_t", c_tangential)
    b = stability_bound(config)
    _finite("the reference overlap", b.reference_overlap)
    _finite("the stability bound on the step", b.bound)


def _non_finite(config: Config, exc: BaseException) -> str:
    """The message for an over- or underflow: the keys whose default value cures it, with their values."""
    defaults = build_config({}).to_dict()
    data = config.to_dict()
    culprits = []
    for key in DERIVED_FROM:
        section, name = key.split(".")
        value = data[section][name]
        if value == defaults[section][name]:
            continue
        trial = {**data, section: {**data[section], name: defaults[section][name]}}
        try:
            _check(build_config(trial), 1)
        except (ArithmeticError, ValueError) as again:
            if not isinstance(again, ConfigError):
                continue
        culprits.append(f"{key} = {value:g}")
    what = str(exc) if isinstance(exc, _NonFinite) else f"a derived quantity ({type(exc).__name__}: {exc})"
    named = " and ".join(culprits) or "one of " + ", ".join(
        f"{k} = {data[k.split('.')[0]][k.split('.')[1]]}" for k in DERIVED_FROM)
    return (f"{named}: {what} is not a finite positive number (over- or underflow); values are dimensionless "
            "(units: scales, see `gouge config --defaults`): give a value within a few orders of magnitude of the "
            "default")


def _check(config: Config, threads: int) -> Preflight:
    _derived(config)
    dt = _finite("the step dt", choose_dt(config))
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
    for key in INTERVALS:
        section, name = key.split(".")
        value = getattr(getattr(config, section), name)
        if value is not None and not value / dt <= MAX_STEPS:
            raise ConfigError(f"{key} = {value:g} t0 is {value / dt:.3g} steps of dt = {dt:.3g} t0, beyond a "
                              f"finite step count (at most {MAX_STEPS * dt:.3g} t0); give a shorter interval")
    steps = _finite("the number of steps", (config.compaction.max_time + config.run.duration) / dt)
    hours = _finite("the estimated run time", steps * config.packing.n_grains / RATE / 3600.0)
    per = max(1, threads)
    estimate = (f"{steps:.3g} steps of {config.packing.n_grains} grains: about {hours / per:.3g} h at "
                f"{RATE:.0e} grain-steps/s per thread on {per} thread(s)")
    if hours / per > MAX_HOURS:
        raise ConfigError(f"numerics.dt = {dt:.3g} t0 is too small to finish: {estimate}; raise numerics.dt "
                          "(or numerics.dt_safety), or shorten run.duration / compaction.max_time")
    note = f"note: this run is long, {estimate} (Ctrl-C stops it; `gouge resume` continues)" \
        if hours / per > NOTE_HOURS else ""
    return Preflight(dt, steps, hours, note, _threads_warning(config.numerics.threads))


def machine_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _threads_warning(requested: int) -> str:
    cores = machine_cores()
    if requested > cores:
        return (f"warning: numerics.threads = {requested} is above this machine's {cores} core(s); at most "
                f"{cores} thread(s) are worth running (set numerics.threads <= {cores}, or 0 for automatic)")
    return ""
