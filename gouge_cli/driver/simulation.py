"""The simulation loop: numba advances whole chunks of steps; callbacks fire between chunks.

    build or restore state -> [compaction until settled] -> loading:
        while step < end:
            advance(steps to the next due callback)      # numba, no Python per step
            for callback in order: if due: callback(sim) # output, guards, detector, progress
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..config import Config
from ..errors import PhysicsError
from ..kernels import layout as L
from ..kernels import measure as M
from ..kernels import step as K
from ..model.packing import build_packing
from . import engines
from .schedules import Every
from ..model.state import State
from ..model.params import numba_threads
from ..model.scene import Scene

_EMPTY = np.zeros(0)


class Simulation:
    """A scene's arrays and the loop that advances them. Dry unless ``config.fluid`` is set."""

    def __init__(self, scene: Scene | Config, arrays: dict | None = None, state: State | None = None,
                 fluid_arrays: dict | None = None):
        """Build the simulation of `scene` (a Config is checked into its Scene here: ConfigError
        naming the key, so no unchecked config runs), its packing from the seed, or around a given
        `state` (e.g. a few free grains in a test); `arrays` restores a checkpoint bit for bit and
        `fluid_arrays` its pressure grid (without them a fluid scene starts at P = 0 from the
        restored packing: a fork from a dry checkpoint)."""
        if not isinstance(scene, Scene):
            scene = Scene(scene, None if state is None else state.n)
        self.scene = scene
        self.config = config = scene.config
        self.dt = scene.dt           # the step in force [t0] (stick scaling changes it; scene.dt is the true one)
        self.inertia_scale = 1.0     # lambda of driver.stick_scaling in force (1: true inertia)
        self.state = state if state is not None else build_packing(config)
        s = self.state
        top_mass = float(s.mass[s.top].sum()) / s.width
        self.wall_mass_per_length = (config.loading.wall_mass or top_mass) if s.top.size else 0.0
        p = scene.params(s.width, self.wall_mass_per_length * s.width, s.n)
        self.params = p
        self.threads = scene.threads     # every kernel of this simulation runs on these (a benchmark may set them)
        self.fluid = None
        self.engine = engines.make(scene.dry_engine)     # what advances the steps (start_fluid: the wet one)
        self.drag = (_EMPTY, _EMPTY)
        self._observables = np.zeros(L.N_OBSERVABLES)
        self._measured: dict | None = None      # measure()'s row while run fires a step's callbacks
        if arrays is not None:
            s.restore(arrays)
        else:
            self._rebuild()
            with numba_threads(self.threads):
                K.compute_forces(s.grains(), s.lists(), s.pairs(), s.wall, p, *self.drag)
        self._apply_phase()
        if self.phase == L.LOADING:
            self.start_fluid(fluid_arrays)

    # ---- fluid -------------------------------------------------------------------------
    def wall_planes(self) -> tuple[float, float]:
        """(z_bottom, z_top): mean z of the bottom- and top-wall grain centres [d]."""
        s = self.state
        return float(s.z[s.bottom].mean()), float(s.wall[L.W_Z])

    def start_fluid(self, fluid_arrays: dict | None = None):
        """Build the pressure grid if the config has a fluid section (never for a dry scene), once:
        the fluid lives through loading, so this is called where loading starts (start_loading,
        or __init__ for a state restored in loading; later calls do nothing). With no saved
        arrays P starts at 0 on the current packing; the grain forces then include its (zero)
        drag from the next step on, and the scene's wet engine advances the steps."""
        if self.config.fluid is None or self.fluid is not None:
            return
        from ..model.fluid import FluidGrid

        s = self.state
        z_bot, z_top = self.wall_planes()
        self.fluid = FluidGrid.from_config(self.config.fluid, s.width, z_bot, z_top, s.n)
        if fluid_arrays:
            self.fluid.restore(fluid_arrays)
        else:
            with numba_threads(self.threads):
                status = self.fluid.init(s.x, s.z, s.vx, s.vz, s.radius, z_bot, z_top)
                if status == 0:           # the top plane's fluid force onto the top body (kernels.fluid_update)
                    from ..kernels.fluid_update import add_top_plane_force
                    add_top_plane_force(self.fluid.record(), s.top, self.fluid.drag_z, status)
            if status != 0:
                raise PhysicsError("the pressure grid could not be initialised (layer thickness <= 0)",
                                   "check the packing", s.time)
        self.drag = (self.fluid.drag_x, self.fluid.drag_z)
        self.engine = engines.make(self.scene.wet_engine)

    @property
    def gpu_fallback(self) -> str:
        """Why numerics.device = gpu does not run this scene's steps now ('' if it does or was not asked)."""
        return self.scene.fallback if self.engine.device != self.scene.device else ""

    # ---- phase -------------------------------------------------------------------------
    @property
    def phase(self) -> int:
        return int(self.state.counters[L.K_PHASE])

    def _apply_phase(self):
        loading = self.phase == L.LOADING
        self.params[L.DRIVE] = 1.0 if loading else 0.0
        self.params[L.BG_DAMPING] = 0.0 if loading else self.config.compaction.damping

    def start_loading(self):
        """End compaction and start the driver clock. The spring is attached in equilibrium
        with the residual grain shear force on the wall (initial stretch s0 = -F_x / (k L_x)),
        so the wall does not jump when it is released along x. The pore fluid (if any) starts
        here, on the compacted packing."""
        s = self.state
        s.counters[L.K_PHASE] = L.LOADING
        s.clock[L.C_ANCHOR] = -s.wall[L.W_FX] / (self.params[L.SPRING] * s.width)
        s.wall[L.W_X] = 0.0
        s.wall[L.W_VX] = 0.0
        s.clock[L.C_DRIVE_TIME] = 0.0
        self._apply_phase()
        self.start_fluid()

    def set_loading_velocity(self, velocity: float):
        """Step the spring's far end to `velocity` [v0] from now on (a velocity step): the anchor
        moves so that the stretch V_s t_load + s0 - x_wall, hence the spring force, is continuous."""
        s, p = self.state, self.params
        if not velocity > 0:
            raise ValueError(f"loading velocity {velocity!r} [v0] must be positive")
        s.clock[L.C_ANCHOR] += (p[L.V_LOAD] - velocity) * s.clock[L.C_DRIVE_TIME]
        p[L.V_LOAD] = velocity

    # ---- stepping ----------------------------------------------------------------------
    def _rebuild(self):
        s = self.state
        self.params[L.THREADS] = self.threads
        with numba_threads(self.threads):
            while not K.rebuild(s.grains(), s.lists(), self.params, s.counters, *self.drag):
                s.grow_pairs(int(s.counters[L.K_NEEDED_CAPACITY]))

    def advance(self, nsteps: int):
        """Advance exactly nsteps steps (the engine in force, on self.threads); grows the pair
        arrays if a rebuild overflows."""
        self.params[L.THREADS] = self.threads
        with numba_threads(self.threads):
            self._advance(int(nsteps))

    def _advance(self, nsteps: int):
        self.engine.advance(self, nsteps)

    def compile_note(self) -> str | None:
        """A line to show before the first step when its kernel is not compiled for this CPU yet
        (a fresh environment: numba compiles it once, then loads it from its cache)."""
        from ..kernels import cached_for_this_cpu

        kernel = self.engine.kernel
        if kernel is None or cached_for_this_cpu(kernel):
            return None
        what, how_long = self.engine.compiling
        return (f"note: compiling {what} for this CPU (once per environment, about {how_long}; later runs load "
                "it from the cache)")

    @property
    def fluid_interval(self) -> int:
        """DEM steps per fluid update: fluid.step / dt rounded, at least 1."""
        return max(1, int(round(self.config.fluid.step / self.dt)))

    def steps_for(self, duration: float) -> int:
        return max(1, int(round(duration / self.dt)))

    def run(self, duration: float | None, callbacks: list[Every] | Callable[[], list[Every]] = (),
            should_stop: Callable[[], bool] = None):
        """Advance by `duration` [t0] (None: until should_stop, e.g. compaction's settling
        criterion; then callbacks must not be empty), firing callbacks when due. Returns steps done.
        `callbacks` may be a function returning the list: the step size may then change inside a
        callback (stick scaling, driver.stick_scaling), the end is counted in time and the list is
        rebuilt after such a change (schedules are step counts).

            end = step + steps_for(duration)        # (no end for duration None)
            while step < end:                       # (changing step: end = step + round((t_end - t) / dt))
                advance(min(next due step of any callback, end) - step)   # numba, kernels.step order:
                    # wall half kick + drift; grains half kick + drift (+ list rebuild);
                    # contact forces; wall force + spring; closing half kicks
                    # (+ a fluid update every fluid_interval steps: deposit, pressure, drag)
                for cb in callbacks (in list order): if cb.due(step): cb.action(self)
                    # (callbacks that measure on the same step share one row: measure();
                    #  after one that changed dt the others wait and the list is rebuilt)
                if should_stop(): break

        The compaction phase's callbacks: driver.compaction; the loading phase's and their order:
        driver.phases.load_phase."""
        s = self.state
        first = s.step
        build = callbacks if callable(callbacks) else None
        if build is not None:
            callbacks = build()
        end = first + self.steps_for(duration) if duration is not None else None
        end_time = s.time + duration if duration is not None and build is not None else None
        while True:
            if end_time is not None:            # the step may change: the end is a time
                left = end_time - s.time
                if left <= 0.5 * self.dt:
                    break
                end = s.step + max(1, int(round(left / self.dt)))
            elif end is not None and s.step >= end:
                break
            target = min([cb.next_step(s.step) for cb in callbacks] + ([end] if end is not None else []))
            dt = self.dt
            self.advance(target - s.step)
            self._measured = {}
            try:
                for cb in callbacks:
                    if cb.due(s.step):
                        cb.action(self)
                        if self.dt != dt:
                            break
            finally:
                self._measured = None
            if build is not None and self.dt != dt:
                callbacks = build()
            if should_stop is not None and should_stop():
                break
        return s.step - first

    # ---- observation -------------------------------------------------------------------
    def spring_stretch(self) -> float:
        """V_s t_load + s0 - x_wall [d] (0 before loading)."""
        s, p = self.state, self.params
        if self.phase != L.LOADING:
            return 0.0
        return float(p[L.V_LOAD] * s.clock[L.C_DRIVE_TIME] + s.clock[L.C_ANCHOR] - s.wall[L.W_X])

    def tau_over_sigma(self) -> float:
        return float(self.params[L.SPRING] * self.spring_stretch() / self.params[L.SIGMA])

    def observe(self) -> dict:
        """Time-series row (dimensionless); see io.runfile.SERIES for names and units."""
        s, p = self.state, self.params
        o = self._observables
        M.observe(s.x, s.z, s.vx, s.vz, s.spin, s.radius, s.mass, s.body, s.force_x, s.force_z,
                  s.start, s.index, s.shear, s.width, p[L.C_NORMAL], p[L.C_TANGENTIAL], o)
        sigma = p[L.SIGMA]
        stretch = self.spring_stretch()
        row = {
            "time": s.clock[L.C_TIME],
            "load_time": s.clock[L.C_DRIVE_TIME],
            "wall_x": s.wall[L.W_X],
            "wall_z": s.wall[L.W_Z],
            "wall_vx": s.wall[L.W_VX],
            "wall_vz": s.wall[L.W_VZ],
            "spring_stretch": stretch,
            "tau_over_sigma": p[L.SPRING] * stretch / sigma,
            "wall_shear_stress": -s.wall[L.W_FX] / s.width,
            "wall_normal_stress": s.wall[L.W_FZ] / s.width,
            "thickness": o[L.THICKNESS],
            "porosity": o[L.POROSITY],
            "kinetic_energy": o[L.KINETIC],
            "coordination": o[L.COORDINATION],
            "max_overlap": o[L.MAX_OVERLAP],
            "nonfinite": o[L.NONFINITE],
            "contact_energy": o[L.CONTACT_ENERGY],
            "worst_pair": (int(o[L.WORST_I]), int(o[L.WORST_J])),
        }
        if self.fluid is not None:
            row.update(self.fluid.observe(s.wall[L.W_VX], s.vx, s.vz))
        return row

    def contacts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, fx, fz): the touching pairs by original grain id and the contact force on i
        (kernels.measure.contact_list), shape (m,) each, for snapshots."""
        s, p = self.state, self.params
        npairs = int(s.start[-1])
        ci = np.empty(npairs, np.int32)
        cj = np.empty(npairs, np.int32)
        cfx = np.empty(npairs)
        cfz = np.empty(npairs)
        m = M.contact_list(s.x, s.z, s.radius, s.start, s.index, s.shear, s.width, p[L.C_NORMAL],
                           p[L.C_TANGENTIAL], p[L.FRICTION], ci, cj, cfx, cfz)
        ci[:m] = s.id[ci[:m]]
        cj[:m] = s.id[cj[:m]]
        return ci[:m], cj[:m], cfx[:m], cfz[:m]

    def measure(self) -> dict:
        """observe(), shared by the callbacks of one step: while run fires a step's callbacks
        (which leave the state alone), the first that measures (guards, the series writer,
        compaction's check) runs the measurement kernel and the later ones get a copy of its
        row. Outside that (or after a callback moved the state to another step) it is observe()."""
        if self._measured is None:
            return self.observe()
        if self._measured.get("step") != self.state.step:
            self._measured = {"step": self.state.step, "row": self.observe()}
        return dict(self._measured["row"])
