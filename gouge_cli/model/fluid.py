"""The pore-pressure grid of a wet scene (thesis Eqs. 12, 14-20; docs/physics/fluid.md).

:class:`FluidGrid` owns every array the fluid kernels need, allocated once, and
the parameters from :class:`gouge_cli.config.FluidConfig`. The engine calls, from
Python or from njit code,

    fluid_init(x, z, vx, vz, radius, n, Lx, z_bot, z_top, *grid.kernel_args())
    status = fluid_update(x, z, vx, vz, radius, n, Lx, z_bot, z_top, dt_f, *grid.kernel_args())

with kernel_args() = (record(), drag_x, drag_z),

and adds ``grid.drag_x``, ``grid.drag_z`` to the contact forces. The numerics are
documented in gouge_cli.kernels (deposit, filter, pressure, drag, fluid_update; indices in layout).
Two scales: the filter width w (fluid.filter_width, physics: the width over which grains are
averaged) and the cell size h (fluid.cell_size, numerics: the grid, refined at fixed w until the
answers stop changing). A dry scene never builds this.
"""

from __future__ import annotations

import numpy as np

from ..kernels import layout as L

from ..kernels import fluid_update as KF


def aligned_zeros(shape: tuple, align: int = 64) -> np.ndarray:
    """Zeroed float64 array whose data starts on an `align`-byte boundary (numpy gives 16): the
    deposit's 128-byte moment records then lie on whole cache lines, so no vector add splits
    across two."""
    size = int(np.prod(shape))
    buffer = np.zeros(size + align // 8)
    start = (-buffer.ctypes.data % align) // 8
    return buffer[start:start + size].reshape(shape)


COUPLING_REVISION = 2
"""Revision of the coupling's discretisation, part of every wet result's settings digest (campaign
forks, dilatancy steps), so that results of two revisions never mix under one digest. Bumped when a
change alters wet results: 1, gouge <= 0.2 and the filtered grid; 2, the wall planes' mirrored
gradient of s and the pore pressure's force on the planes (docs/physics/fluid.md)."""


def saved_revision(arrays: dict) -> int:
    """The coupling revision that wrote a checkpoint's fluid arrays (FluidGrid.arrays()): 1 where
    the fluid state lacks the planes' forces (S_F_BOT, S_F_TOP), else COUPLING_REVISION."""
    return 1 if np.shape(arrays["state"])[0] < L.S_F_TOP + 1 else COUPLING_REVISION


SOLVERS = {"implicit": L.SOLVER_IMPLICIT, "explicit": L.SOLVER_EXPLICIT, "auto": L.SOLVER_AUTO}


class FluidGrid:
    """Pressure grid between the wall planes, periodic in x, stretching with the layer.

    Arrays (float64; nx x nz cells, N grains):
      pressure P [nx, nz] pore-pressure perturbation [E]
      solid_fraction s [nx, nz] = 1 - porosity [-]; previous_solid_fraction s^n
      solid_velocity_x, solid_velocity_z [nx, nz] deposited grain velocity [v0]
      permeability [nx, nz] Carman-Kozeny kappa [d^2]
      div_u [nx, nz] solid volumetric strain rate over the last update [1/t0]
      drag_x, drag_z [N] fluid force on each grain [E d^2]
      taps_x [nx], bands_z [3, 2 nz - 1, nz] the filter's operators (kernels.filter), rebuilt each update
      params [N_PARAMS], state [N_STATE], work [N_WORK, nx, nz] (kernel layouts)
    Evolving state to checkpoint (everything else is rebuilt by each update):
    pressure, solid_fraction, state, drag_x, drag_z; see arrays() / restore().
    """

    EVOLVING = ("pressure", "solid_fraction", "state", "drag_x", "drag_z")

    def __init__(self, nx: int, nz: int, Lx: float, z_bot: float, z_top: float, n_grains: int,
                 permeability: float, compressibility: float, viscosity: float,
                 solver: str = "auto", explicit_safety: float = 0.5, tolerance: float = 1e-10,
                 max_iterations: int = 1000, max_substeps: int = 100_000,
                 porosity_min: float = 0.05, porosity_max: float = 0.9, filter_width: float = 0.0):
        if nx < 1 or nz < 2:
            raise ValueError(f"grid needs nx >= 1 and nz >= 2, got nx={nx}, nz={nz}")
        if not z_top > z_bot:
            raise ValueError(f"z_top ({z_top}) must be above z_bot ({z_bot})")
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(map(repr, SOLVERS))}, got {solver!r}")
        self.nx = int(nx)
        self.nz = int(nz)
        self.Lx = float(Lx)
        self.n_grains = int(n_grains)
        self.solver = solver
        params = np.zeros(L.N_FLUID_PARAMS)
        params[L.P_KAPPA_C] = permeability
        params[L.P_BETA] = compressibility
        params[L.P_ETA] = viscosity
        params[L.P_SOLVER] = SOLVERS[solver]
        params[L.P_SAFETY] = explicit_safety
        params[L.P_TOL] = tolerance
        params[L.P_MAX_ITER] = max_iterations
        params[L.P_PHI_MIN] = porosity_min
        params[L.P_PHI_MAX] = porosity_max
        params[L.P_MAX_SUBSTEPS] = max_substeps
        params[L.P_FILTER_WIDTH] = filter_width
        self.params = params
        self.state = np.zeros(L.N_FLUID_STATE)
        self.state[L.S_Z_BOT] = z_bot
        self.state[L.S_Z_TOP] = z_top
        self._allocate_grid(self.nx, self.nz)
        self.corners = np.zeros((L.N_CORNERS, self.n_grains))
        self.drag_x = np.zeros(self.n_grains)
        self.drag_z = np.zeros(self.n_grains)

    def _allocate_grid(self, nx: int, nz: int):
        self.nx, self.nz = nx, nz
        shape = (nx, nz)
        self.pressure = np.zeros(shape)
        self.solid_fraction = np.zeros(shape)
        self.previous_solid_fraction = np.zeros(shape)
        self.solid_velocity_x = np.zeros(shape)
        self.solid_velocity_z = np.zeros(shape)
        self.permeability = np.zeros(shape)
        self.div_u = np.zeros(shape)
        self.work = np.zeros((L.N_GRID_WORK, nx, nz))
        self.partial = aligned_zeros((L.DEPOSIT_GROUPS, nx * nz, L.N_MOMENTS))   # (records on whole cache lines)
        self.taps_x = np.zeros(nx)
        self.bands_z = np.zeros((3, 2 * nz - 1, nz))

    @classmethod
    def from_config(cls, fluid_config, Lx: float, z_bot: float, z_top: float, n_grains: int) -> "FluidGrid":
        """Grid of nx = max(1, round(Lx/h)) by nz = max(2, round((z_top - z_bot)/h)), h the config's
        grid spacing (fluid.cell_size, by default half the filter width)."""
        h = fluid_config.grid_spacing
        nx = max(1, int(round(Lx / h)))
        nz = max(2, int(round((z_top - z_bot) / h)))
        return cls(nx, nz, Lx, z_bot, z_top, n_grains,
                   permeability=fluid_config.permeability,
                   compressibility=fluid_config.compressibility,
                   viscosity=fluid_config.viscosity,
                   solver=fluid_config.solver,
                   explicit_safety=fluid_config.explicit_safety,
                   filter_width=fluid_config.filter_width)

    def record(self) -> L.FluidArrays:
        """The grid's arrays by name, as kernels.coupled.advance_fluid takes them (without drag)."""
        return L.FluidArrays(self.params, self.state, self.pressure, self.solid_fraction, self.previous_solid_fraction,
                             self.solid_velocity_x, self.solid_velocity_z, self.permeability, self.div_u, self.work,
                             self.corners, self.partial, self.taps_x, self.bands_z)

    def kernel_args(self) -> tuple:
        """(record(), drag_x, drag_z), as fluid_init / fluid_update take them."""
        return (self.record(), self.drag_x, self.drag_z)

    def arrays(self) -> dict:
        """Copies of the evolving arrays (EVOLVING) for a checkpoint."""
        return {name: getattr(self, name).copy() for name in self.EVOLVING}

    def restore(self, arrays: dict):
        """Load arrays written by :meth:`arrays` (bit-exact); replaces fluid_init on a restart.

        The grid takes the checkpoint's nx x nz (nz was fixed when the grid was first
        built, so the layer thickness at the restart may round to another count).
        """
        shape = np.shape(arrays["pressure"])
        if len(shape) != 2 or shape[0] < 1 or shape[1] < 2:
            raise ValueError(f"fluid pressure in the checkpoint has shape {shape}; expected (nx >= 1, nz >= 2)")
        if shape != self.pressure.shape:
            self._allocate_grid(int(shape[0]), int(shape[1]))
        for name in self.EVOLVING:
            target = getattr(self, name)
            source = np.asarray(arrays[name])
            if name == "state" and saved_revision(arrays) == 1:     # (no plane forces saved: zero until an update)
                source = np.concatenate([source, target[source.shape[0]:]])
            if source.shape != target.shape:
                raise ValueError(f"fluid array {name!r} in the checkpoint has shape {source.shape}, "
                                 f"the scene needs {target.shape} (a different number of grains?)")
            target[...] = source

    def snapshot_fields(self) -> dict:
        """Fields for an output snapshot: pressure [E] and porosity [-], each [nx, nz]."""
        return {"pressure": self.pressure.copy(), "porosity": self.porosity}

    def observe(self, wall_speed: float, vx: np.ndarray, vz: np.ndarray) -> dict:
        """Time-series values: pressure mean/min/max [E], the Deborah number, and the counts of
        updates so far and of those taken explicitly (fluid.solver auto: where the Heun step was
        within its threshold).

        De = l u0 / D (thesis Eq. 4) with l half the layer thickness (distance to the drained
        walls), u0 = wall_speed, the top wall's speed [v0] (what the thesis's own estimate uses,
        and independent of the grid), D the mean diffusivity; ``deborah_grid`` takes u0 from the
        largest solid speed deposited on the grid instead (a diagnostic: it moves with the grid
        and the filter width). The energy budget: ``fluid_energy``, the elastic energy stored in
        the pore fluid, sum_c dx dz beta phi_c P_c^2 / 2 [E d^3 per unit thickness], and
        ``drag_power``, the work rate of the drag on the grains, sum_k F_k . v_k [E d^3/t0]
        (vx, vz: the grains' velocities [v0]); without drainage the one is minus the integral of
        the other (tests/model/test_fluid_coupling.py).
        """
        speed = float(np.sqrt(self.solid_velocity_x**2 + self.solid_velocity_z**2).max())
        half = 0.5 * self.dz * self.nz
        return {"pressure_mean": self.mean_pressure(), "pressure_min": self.min_pressure(),
                "pressure_max": self.max_pressure(), "deborah": self.deborah(half, abs(wall_speed)),
                "deborah_grid": self.deborah(half, speed),
                "fluid_energy": self.stored_energy(),
                "drag_power": float(np.dot(self.drag_x, vx[:self.n_grains]) + np.dot(self.drag_z, vz[:self.n_grains])),
                "fluid_updates": float(self.state[L.S_UPDATES]),
                "explicit_updates": float(self.state[L.S_EXPLICIT_UPDATES])}

    def failure(self, status: int) -> tuple[str, str]:
        """(cause, fix) for a non-zero status of fluid_update, worded for the user."""
        state = self.state
        if status == L.STATUS_NONFINITE:
            return ("non-finite pore pressure",
                    "the pressure source or the grain state blew up: lower fluid.step or numerics.dt_safety, "
                    "and check the grain state for NaN")
        if status == L.STATUS_SOLVER and self.solver == "explicit":
            return (f"explicit pressure step needs {int(state[L.S_SUBSTEPS])} sub-steps "
                    f"(FTCS bound {state[L.S_DT_MAX]:.3g} t0), above the limit "
                    f"{int(self.params[L.P_MAX_SUBSTEPS])}",
                    "use fluid.solver=implicit, or raise fluid.cell_size")
        if status == L.STATUS_SOLVER:
            return (f"pressure solver did not converge in {int(self.params[L.P_MAX_ITER])} iterations "
                    f"(relative residual {state[L.S_RESIDUAL]:.2g}), or the layer thickness is not positive",
                    "lower fluid.step or raise fluid.cell_size (nearly empty cells make the system stiff)")
        return (f"fluid update returned unknown status {status}", "report this as a bug")

    def init(self, x, z, vx, vz, radius, z_bot: float, z_top: float, n: int | None = None) -> int:
        """Python convenience for KF.fluid_init; returns its status."""
        n = len(x) if n is None else n
        return KF.fluid_init(x, z, vx, vz, radius, n, self.Lx, z_bot, z_top, *self.kernel_args())

    def update(self, x, z, vx, vz, radius, z_bot: float, z_top: float, dt_f: float, n: int | None = None) -> int:
        """Python convenience for KF.fluid_update; returns its status."""
        n = len(x) if n is None else n
        return KF.fluid_update(x, z, vx, vz, radius, n, self.Lx, z_bot, z_top, dt_f, *self.kernel_args())

    @property
    def dx(self) -> float:
        return self.Lx / self.nx

    @property
    def dz(self) -> float:
        """Cell height at the last update [d]."""
        return (self.state[L.S_Z_TOP] - self.state[L.S_Z_BOT]) / self.nz

    @property
    def porosity(self) -> np.ndarray:
        """phi = 1 - s [nx, nz], unclamped."""
        return 1.0 - self.solid_fraction

    def _clamped_porosity(self) -> np.ndarray:
        return np.clip(self.porosity, self.params[L.P_PHI_MIN], self.params[L.P_PHI_MAX])

    def stored_energy(self) -> float:
        """sum_c dx dz beta phi_c P_c^2 / 2 [E d^3 per unit thickness], phi clamped as for kappa."""
        beta = self.params[L.P_BETA]
        return float(0.5 * beta * self.dx * self.dz * np.sum(self._clamped_porosity() * self.pressure ** 2))

    def mean_pressure(self) -> float:
        return float(self.pressure.mean())

    def min_pressure(self) -> float:
        return float(self.pressure.min())

    def max_pressure(self) -> float:
        return float(self.pressure.max())

    def diffusivity(self) -> np.ndarray:
        """D = kappa / (eta beta phi) [d^2/t0] per cell (phi clamped as for kappa)."""
        eta = self.params[L.P_ETA]
        beta = self.params[L.P_BETA]
        return self.permeability / (eta * beta * self._clamped_porosity())

    def mean_diffusivity(self) -> float:
        """D of the mean permeability and mean clamped porosity [d^2/t0]."""
        eta = self.params[L.P_ETA]
        beta = self.params[L.P_BETA]
        return float(self.permeability.mean() / (eta * beta * self._clamped_porosity().mean()))

    def deborah(self, length: float, speed: float) -> float:
        """De = l u0 / D (thesis Eq. 4/19) with the mean diffusivity; De << 1 is drained."""
        return float(length * speed / self.mean_diffusivity())

    def explicit_bound(self, dx: float | None = None, dz: float | None = None) -> float:
        """FTCS limit 1 / (2 D_max (1/dx^2 + 1/dz^2)) [t0] with the largest cell D."""
        dx = self.dx if dx is None else dx
        dz = self.dz if dz is None else dz
        return float(1.0 / (2.0 * self.diffusivity().max() * (1.0 / dx**2 + 1.0 / dz**2)))
