"""B scenes on the GPU as one ensemble: their State arrays stacked [B, ...] on the device and
advanced by kernels.gpu.dry.advance_layers (B = 1: a single layer).

``Layers(states, params).advance(nsteps)`` uploads every State (so host-side changes between
calls, a phase change or stick scaling's masses, always reach the device), runs nsteps steps
of every layer in as few launches as the pair arrays allow, and copies the result back: each
State is then what kernels.step.advance would have made of it, bit for bit. The layers must
have the same number of grains; their parameters (params rows) may differ.
"""

from __future__ import annotations

import os

import numpy as np

from ..kernels import layout as L
from .state import State

# State arrays the kernel reads and writes, per grain (N,), per row offset (N + 1,), per pair slot
# (capacity,), and scratch; grouped by how they are stacked
GRAIN = ("x", "z", "vx", "vz", "spin", "radius", "mass", "inv_mass", "inv_inertia", "body", "force_x", "force_z",
         "torque")
LISTS = ("id", "start", "index", "shear", "rev_start", "rev_slot", "x_build", "z_build", "new_start", "new_index",
         "new_shear", "layout", "cell_of", "order", "cell_count", "pair_fx", "pair_fz", "pair_ti", "pair_tj")
PAIR_SLOTS = ("index", "shear", "rev_slot", "new_index", "new_shear", "pair_fx", "pair_fz", "pair_ti", "pair_tj")
RECORDS = ("wall", "clock", "counters")
PAIR_RESULTS = ("pair_fx", "pair_fz", "pair_ti", "pair_tj")        # the law's results per slot (kernels.gpu.dry)
THREADS = 256       # threads per layer's block on a GPU
SIM_THREADS = 4     # under numba-cuda's simulator (each simulated thread is a Python thread)
PARALLEL = True     # the rebuild's bookkeeping on the whole block (kernels.gpu.parallel): 1.9x at B = 1 (H200)


class Layers:
    """The ensemble (module docstring). states: B States with equal N; params: B params vectors
    (kernels.layout, N_PARAMS) or one for all; threads: threads per block (None: the environment's
    GOUGE_GPU_THREADS, else THREADS, or SIM_THREADS under the simulator; the bits do not depend on it);
    parallel: the rebuild's bookkeeping by the whole block (kernels.gpu.parallel; None: the
    environment's GOUGE_GPU_PARALLEL, else PARALLEL; same bits either way); timed: add up
    per-phase cycles (``phase_cycles``)."""

    def __init__(self, states: list[State], params, threads: int | None = None, parallel: bool | None = None,
                 timed: bool = False):
        from numba import config, cuda

        if threads is None:
            threads = int(os.environ.get("GOUGE_GPU_THREADS", SIM_THREADS if config.ENABLE_CUDASIM else THREADS))
        if parallel is None:
            parallel = os.environ.get("GOUGE_GPU_PARALLEL", "1" if PARALLEL else "0") == "1"
        self.parallel = bool(parallel)
        self.timed = bool(timed)
        self.cuda = cuda
        self.states = list(states)
        if len({s.n for s in self.states}) != 1:
            raise ValueError("the layers of a GPU ensemble must have the same number of grains")
        self.params = np.array(np.broadcast_to(np.asarray(params, np.float64), (len(self.states), L.N_PARAMS)))
        self.threads = int(threads)
        self.launches = 0

    @property
    def size(self) -> int:
        return len(self.states)

    def _stack(self, name: str, capacity: int) -> np.ndarray:
        rows = [getattr(s, name) for s in self.states]
        if name in PAIR_SLOTS:
            out = np.zeros((self.size, capacity) + rows[0].shape[1:], rows[0].dtype)
            for b, r in enumerate(rows):
                out[b, :r.shape[0]] = r
            return out
        return np.stack(rows)

    def upload(self):
        """Copy every State (and the params) to the device."""
        cuda = self.cuda
        capacity = max(s.index.shape[0] for s in self.states)
        self.capacity = capacity
        self.d = {name: cuda.to_device(self._stack(name, capacity)) for name in GRAIN + LISTS + RECORDS}
        ntop = np.array([s.top.shape[0] for s in self.states], np.int64)
        top = np.zeros((self.size, max(int(ntop.max()), 1)), np.int64)
        for b, s in enumerate(self.states):
            top[b, :ntop[b]] = s.top
        self.d["top"] = cuda.to_device(top)
        self.d["ntop"] = cuda.to_device(ntop)
        self.d["params"] = cuda.to_device(self.params)
        self.d["none"] = cuda.to_device(np.zeros(0))
        from ..kernels.gpu.dry import N_PHASES

        self.d["timers"] = cuda.to_device(np.zeros((self.size, N_PHASES + 1 if self.timed else 0), np.int64))

    def phase_cycles(self) -> dict[str, np.ndarray]:
        """{phase: (B,) clock64 cycles spent in it since the last upload} (timed ensembles;
        kernels.gpu.dry.PHASES)."""
        from ..kernels.gpu.dry import PHASES

        cycles = self.d["timers"].copy_to_host()
        return {name: cycles[:, k] for k, name in enumerate(PHASES)} if self.timed else {}

    def download(self):
        """Copy the device arrays back into the States (pair arrays enlarged where needed); the
        pair constants are marked stale (the GPU does not store them)."""
        for b, s in enumerate(self.states):
            if s.index.shape[0] < self.capacity:
                s._allocate_pairs(self.capacity)
        for name in GRAIN + LISTS + RECORDS:
            host = self.d[name].copy_to_host()
            for b, s in enumerate(self.states):
                target = getattr(s, name)
                target[...] = host[b, :target.shape[0]] if name in PAIR_SLOTS else host[b]
        top = self.d["top"].copy_to_host()
        for b, s in enumerate(self.states):
            s.top[...] = top[b, :s.top.shape[0]]
            s.list_changed()

    def records(self) -> tuple:
        """(Grains, Lists, pair results) of the uploaded device arrays, as advance_layers takes them."""
        d = self.d
        return (L.Grains(*(d[name] for name in L.Grains._fields)), L.Lists(*(d[name] for name in L.Lists._fields)),
                tuple(d[name] for name in PAIR_RESULTS))

    def _launch(self, todo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from ..kernels.gpu.dry import advance_layers

        cuda = self.cuda
        d = self.d
        done = cuda.to_device(np.zeros(self.size, np.int64))
        status = cuda.to_device(np.zeros(self.size, np.int64))
        advance_layers[self.size, self.threads](*self.records(), d["wall"], d["clock"], d["params"], d["counters"],
                                                d["ntop"], cuda.to_device(todo), done, status, d["none"],
                                                int(self.parallel), d["timers"])
        self.launches += 1
        return done.copy_to_host(), status.copy_to_host()

    def run(self, nsteps: int, launch_steps: int | None = None):
        """Advance every layer by nsteps steps on the device, launch_steps at most per launch
        (None: all in one); the arrays stay on the device (download to read them)."""
        left = np.full(self.size, int(nsteps), np.int64)
        while left.any():
            todo = left if launch_steps is None else np.minimum(left, launch_steps)
            done, status = self._launch(todo)
            left -= done
            if (status == L.LIST_OVERFLOW).any():
                self._grow()

    def _grow(self):
        """Enlarge every layer's pair arrays to the largest capacity a layer asked for."""
        counters = self.d["counters"].copy_to_host()
        needed = int(counters[:, L.K_NEEDED_CAPACITY].max())
        self.download()
        for s in self.states:
            if s.index.shape[0] < needed:
                s.grow_pairs(needed)
        self.upload()

    def advance(self, nsteps: int, launch_steps: int | None = None, params=None):
        """upload, run, download: the States advanced by nsteps steps (with `params`, as in
        __init__, when given: the host changes them between calls)."""
        if params is not None:
            self.params[...] = np.broadcast_to(np.asarray(params, np.float64), self.params.shape)
        self.upload()
        self.run(nsteps, launch_steps)
        self.download()
