"""One scene: a Config checked whole and what is derived from it, each derived once.

``Scene(config)`` runs the preflight checks (:func:`gouge_cli.model.preflight.check_config`:
ConfigError naming the key when the config cannot run), so a scene, and the
:class:`~gouge_cli.driver.simulation.Simulation` built from one, never holds an unchecked config.
It carries the step, the contact constants, the thread count, the resolved device and the
preflight's estimate, and builds the kernels' parameter vector for a packing.
"""

from __future__ import annotations

import numpy as np

from ..config import Config
from .params import build_params, choose_threads
from .preflight import Preflight, check_config
from .timestep import contact_constants


class Scene:
    """A checked config and its derived quantities (read-only by convention).

    config        the Config
    dt            the run's step [t0] (timestep.choose_dt, within every stability bound)
    c_normal      Hertz constant c_n [E]: F_n = c_n sqrt(R xi) xi (thesis Eq. 9)
    c_tangential  Mindlin constant c_t [E]: k_s = c_t sqrt(R xi) (thesis Eq. 10)
    threads       numba threads of every kernel of the scene (params.choose_threads)
    device        "cpu" or "gpu": numerics.device, checked available
    dry_engine    what advances dry steps: "cpu dry" or "gpu dry" (driver.engines)
    wet_engine    what advances steps once the pore fluid runs: "cpu wet" (None for a dry scene;
                  the GPU engine runs dry steps only)
    preflight     the checks' result: steps, hours, the long-run note, the threads warning
    """

    __slots__ = ("config", "dt", "c_normal", "c_tangential", "threads", "device", "dry_engine", "wet_engine",
                 "preflight")

    def __init__(self, config: Config, n_grains: int | None = None):
        """Check `config` whole (ConfigError naming the key) and derive the scene of `n_grains`
        grains (default packing.n_grains; a test's own few grains choose their threads by their count)."""
        self.config = config
        self.threads = choose_threads(config.numerics.threads,
                                      config.packing.n_grains if n_grains is None else n_grains)
        self.preflight: Preflight = check_config(config, self.threads)
        self.dt = self.preflight.dt
        self.c_normal, self.c_tangential = contact_constants(config)
        self.device = config.numerics.device
        self.dry_engine = "gpu dry" if self.device == "gpu" else "cpu dry"
        self.wet_engine = "cpu wet" if self.wet else None

    @property
    def wet(self) -> bool:
        """True if the scene has a pore fluid (fluid section set): loading runs the coupled step."""
        return self.config.fluid is not None

    @property
    def engine(self) -> str:
        """What advances the steps: 'cpu dry', 'cpu wet', 'gpu dry', or 'gpu dry compaction, cpu wet
        loading' (the GPU engine runs dry steps only)."""
        if self.device == "gpu":
            return "gpu dry compaction, cpu wet loading" if self.wet else "gpu dry"
        return "cpu wet" if self.wet else "cpu dry"

    @property
    def fallback(self) -> str:
        """Why numerics.device = gpu does not run the loading steps ('' when it does or was not asked)."""
        if self.device == "gpu" and self.wet:
            return "numerics.device = gpu runs dry steps only: this wet scene loads on the cpu"
        return ""

    def params(self, width: float, wall_mass: float, n_grains: int) -> np.ndarray:
        """The kernels' parameter vector (kernels.layout, N_PARAMS) of a packing `width` [d] wide
        with a top body of mass `wall_mass` = m_b L_x [rho d^2] (0: none) and `n_grains` grains."""
        return build_params(self.config, self.dt, width, wall_mass, n_grains,
                            (self.c_normal, self.c_tangential))

    def __repr__(self) -> str:
        return f"Scene({self.config.name!r}, dt={self.dt:.6g}, threads={self.threads}, engine={self.engine!r})"
