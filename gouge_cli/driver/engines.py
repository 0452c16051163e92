"""What advances a simulation's steps: three engines behind one signature.

``engine.advance(sim, nsteps)`` advances sim's state by exactly nsteps steps (numba on the threads
Simulation.advance set), enlarging the pair arrays where a rebuild overflows; a failed fluid
update is a PhysicsError. The engines, each the same sequence of a step (kernels.step._step):

  cpu dry   kernels.step.advance
  cpu wet   kernels.coupled.advance_fluid: the step plus a pore-pressure update every
            fluid_interval steps (from the moment the fluid grid exists)
  gpu dry   model.gpu_layers.Layers: the scene as a one-layer GPU ensemble (the same bits)

The Scene names them once (model.scene.Scene.dry_engine, wet_engine); the Simulation builds its
engine with ``make`` from those names and swaps the dry one for the wet one where the fluid
starts. Nothing else looks at the device or the fluid to decide how to step.
"""

from __future__ import annotations

import numpy as np

from ..errors import PhysicsError
from ..kernels import layout as L
from ..kernels import step as K


class CpuDry:
    """kernels.step.advance, chunk after chunk until nsteps are done (an overflow ends a chunk)."""

    name = "cpu dry"
    device = "cpu"
    compiling = ("the grain step", "20-60 s")       # what compile_note calls it, and how long it takes

    @property
    def kernel(self):
        """The numba dispatcher the engine runs (compile_note asks the cache about it)."""
        return K.advance

    def advance(self, sim, nsteps: int):
        left = int(nsteps)
        while left > 0:
            status, done = self._chunk(sim, left)
            left -= done
            self._after(sim, status)

    def _chunk(self, sim, nsteps: int) -> tuple[int, int]:
        """(status, whole steps done) of one kernel call for up to nsteps steps."""
        s = sim.state
        return K.advance(s.grains(), s.lists(), s.pairs(), s.wall, s.clock, sim.params, s.counters, nsteps,
                         *sim.drag)

    def _after(self, sim, status: int):
        """An overflowing rebuild ended the chunk: enlarge the pair arrays (the step resumes)."""
        if status == L.LIST_OVERFLOW:
            s = sim.state
            s.grow_pairs(int(s.counters[L.K_NEEDED_CAPACITY]))


class CpuWet(CpuDry):
    """kernels.coupled.advance_fluid: the dry step plus the fluid update every sim.fluid_interval
    steps, over sim.fluid's grid."""

    name = "cpu wet"
    compiling = ("the coupled grain-fluid step", "1-3 minutes")

    def __init__(self):
        self.status = np.zeros(1, np.int64)      # why a fluid update failed (kernels.coupled)

    @property
    def kernel(self):
        from ..kernels.coupled import advance_fluid

        return advance_fluid

    def _chunk(self, sim, nsteps: int) -> tuple[int, int]:
        s = sim.state
        fluid = sim.fluid
        return self.kernel(s.grains(), s.lists(), s.pairs(), s.wall, s.clock, sim.params, s.counters, nsteps,
                           fluid.drag_x, fluid.drag_z, fluid.record(), sim.fluid_interval, sim.wall_planes()[0],
                           self.status)

    def _after(self, sim, status: int):
        if status == L.FLUID_FAILED:
            raise PhysicsError(*sim.fluid.failure(int(self.status[0])), sim.state.time)
        super()._after(sim, status)


class GpuDry:
    """The scene as a one-layer GPU ensemble (model.gpu_layers.Layers, made on the first advance):
    uploaded, advanced and downloaded every call (host changes between calls reach the device)."""

    name = "gpu dry"
    device = "gpu"
    kernel = None                   # compiled by numba-cuda at its first launch, not cached on disk

    def __init__(self):
        self.layers = None

    def advance(self, sim, nsteps: int):
        if self.layers is None:
            from ..model.gpu_layers import Layers

            self.layers = Layers([sim.state], sim.params)
        self.layers.advance(int(nsteps), params=sim.params)


ENGINES = {engine.name: engine for engine in (CpuDry, CpuWet, GpuDry)}


def make(name: str):
    """A new engine of the kind the Scene named ('cpu dry', 'cpu wet' or 'gpu dry')."""
    return ENGINES[name]()
