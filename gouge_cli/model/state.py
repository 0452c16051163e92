"""All evolving state of a scene as flat numpy arrays (structure of arrays).

Grains are discs in the x-z plane with sphere mass and inertia (docs/physics/units.md).
``body``: 0 free grain, 1 bottom-wall grain (fixed), 2 top-wall grain (moves with the top body).
Everything a restart needs to continue bit for bit is in :meth:`State.arrays` (the
neighbour list too, since it fixes the order of force sums). Every array has one dtype and C
layout however the state was built (kernel_array) and is restored by copying into those arrays,
so one compiled specialisation of each kernel serves runs, restarts, forks and the bench.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ..kernels import layout as L
from .portable import sphere_mass

FREE, BOTTOM, TOP = L.FREE, L.BOTTOM, L.TOP

# fixed properties of a grain, re-ordered with it (kernels.step.renumber)
STATIC = ("radius", "mass", "inv_mass", "inv_inertia", "body")
# (the reverse list, pair constants and cell arrays are derived or scratch, rebuilt on demand)
EVOLVING = ("id", "x", "z", "vx", "vz", "spin", "force_x", "force_z", "torque",
            "start", "index", "shear", "x_build", "z_build", "wall", "clock", "counters")


def kernel_array(values, dtype) -> np.ndarray:
    """`values` as the one array type the kernels are compiled for: `dtype`, C order, aligned and
    writable (numba compiles a kernel again for each new dtype, layout or read-only flag; an
    array that already fits is returned as is)."""
    out = np.ascontiguousarray(values, dtype=dtype)
    return out if out.flags.writeable and out.flags.aligned else out.copy()


@dataclass
class State:
    """Arrays of one scene. Shapes: (N,) per grain, (capacity,) per pair slot."""

    x: np.ndarray
    z: np.ndarray
    radius: np.ndarray
    body: np.ndarray
    density: float
    width: float
    vx: np.ndarray = None
    vz: np.ndarray = None
    spin: np.ndarray = None
    wall: np.ndarray = field(default_factory=lambda: np.zeros(L.N_WALL))
    clock: np.ndarray = field(default_factory=lambda: np.zeros(L.N_CLOCK))
    counters: np.ndarray = field(default_factory=lambda: np.zeros(L.N_COUNTERS, np.int64))

    def __post_init__(self):
        n = self.x.shape[0]
        for name in ("vx", "vz", "spin"):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros(n))
        for name in ("x", "z", "radius", "vx", "vz", "spin"):
            setattr(self, name, kernel_array(getattr(self, name), np.float64))
        self.body = kernel_array(self.body, np.int8)
        self.width, self.density = float(self.width), float(self.density)     # float64 scalars, never int
        self.mass = sphere_mass(self.radius, self.density)
        self.inv_mass = 1.0 / self.mass
        self.inv_inertia = 1.0 / (self.mass * (2.0 * self.radius) ** 2 / 10.0)
        self.force_x = np.zeros(n)
        self.force_z = np.zeros(n)
        self.torque = np.zeros(n)
        self.top = np.flatnonzero(self.body == TOP).astype(np.int64)
        self.id = np.arange(n, dtype=np.int64)      # original grain number (grains are re-numbered in place)
        self.start = np.zeros(n + 1, np.int64)
        self.rev_start = np.zeros(n + 1, np.int64)
        self.new_start = np.zeros(n + 1, np.int64)
        self.layout = np.zeros(L.N_LAYOUT, np.int64)
        self.list_changed()
        self.cell_of = np.zeros(n, np.int64)
        self.order = np.zeros(n, np.int64)
        self.cell_count = np.zeros(2 * n + 64, np.int64)
        self.x_build = self.x.copy()
        self.z_build = self.z.copy()
        # one chunk buffer of the force pass per part: PARTS_PER_THREAD for each thread numba may run
        self.pair_buf = np.zeros((L.PARTS_PER_THREAD * max(numba.config.NUMBA_NUM_THREADS, 1), L.N_BUF, L.PAIR_BUF))
        self._allocate_pairs(4 * n + 64)     # ~2.5 listed pairs per grain in a dense layer; grows if needed
        self.counters[L.K_NEED_REBUILD] = 1
        if self.top.size:
            self.wall[L.W_Z] = self.z[self.top].mean()

    @property
    def n(self) -> int:
        return self.x.shape[0]

    @property
    def bottom(self) -> np.ndarray:
        """Current numbers of the bottom-wall grains."""
        return np.flatnonzero(self.body == BOTTOM)

    def by_id(self, values: np.ndarray) -> np.ndarray:
        """A per-grain array in original grain order (as the packing numbered them)."""
        out = np.empty_like(values)
        out[self.id] = values
        return out

    def _allocate_pairs(self, capacity: int, keep: int = 0):
        old = {name: getattr(self, name, None) for name in ("index", "shear")}
        self.index = np.zeros(capacity, np.int32)
        self.shear = np.zeros(capacity)
        self.rev_slot = np.zeros(capacity, np.int32)
        self.list_changed()
        for name, arr in old.items():
            if arr is not None and keep:
                getattr(self, name)[:keep] = arr[:keep]
        self.new_index = np.zeros(capacity, np.int32)
        self.new_shear = np.zeros(capacity)
        self.pair_fx = np.zeros(capacity)
        self.pair_fz = np.zeros(capacity)
        self.pair_ti = np.zeros(capacity)
        self.pair_tj = np.zeros(capacity)
        self.pair_const = np.zeros((L.N_PAIR_CONST, capacity))
        self.pair_row = np.zeros(capacity, np.int32)
        self.sum_x = np.zeros(2 * capacity + 1)
        self.sum_z = np.zeros(2 * capacity + 1)
        self.sum_t = np.zeros(2 * capacity + 1)
        self.sum_start = np.zeros(self.n + 1, np.int64)
        self.sum_end = np.zeros(2 * capacity + self.n + 2, np.int32)

    def list_changed(self):
        """The list or the masses changed: the arrays derived from them (reverse list, pair
        constants; kernels.layout L_BUILT) are recomputed by the next contact pass."""
        self.layout[L.L_BUILT] = -1

    def grow_pairs(self, needed: int):
        """Enlarge pair arrays to hold `needed` pairs (with 25 % headroom), keeping the list."""
        self._allocate_pairs(int(needed * 1.25) + 64, keep=int(self.start[-1]))

    def grains(self) -> L.Grains:
        """The per-grain arrays as the kernels take them (kernels.layout.Grains)."""
        return L.Grains(*(getattr(self, name) for name in L.Grains._fields))

    def lists(self) -> L.Lists:
        """The neighbour list and its scratch as the kernels take them (kernels.layout.Lists)."""
        return L.Lists(*(getattr(self, name) for name in L.Lists._fields))

    def pairs(self) -> L.Pairs:
        """The force pass's pair buffers as the kernels take them (kernels.layout.Pairs)."""
        return L.Pairs(*(getattr(self, name) for name in L.Pairs._fields))

    @property
    def time(self) -> float:
        return float(self.clock[L.C_TIME])

    @property
    def step(self) -> int:
        return int(self.counters[L.K_STEP])

    def arrays(self) -> dict:
        """Evolving arrays for a checkpoint (pair slots trimmed to the pairs in use)."""
        npairs = int(self.start[-1])
        out = {}
        for name in EVOLVING:
            arr = getattr(self, name)
            out[name] = arr[:npairs].copy() if name in ("index", "shear") else arr.copy()
        return out

    def restore(self, arrays: dict):
        """Load evolving arrays written by :meth:`arrays` (bit-exact), re-ordering the fixed
        grain properties to the saved numbering (checkpoints without ``id``: packing order)."""
        npairs = int(arrays["start"][-1])
        if npairs > self.index.shape[0]:
            self._allocate_pairs(int(npairs * 1.25) + 64)
        ident = np.asarray(arrays["id"]) if "id" in arrays else np.arange(self.n)
        if ident.shape != self.id.shape:
            raise ValueError(f"checkpoint has {ident.shape[0]} grains, scene has {self.n}")
        if not np.array_equal(ident, self.id):
            for name in STATIC:
                values = getattr(self, name)
                values[...] = self.by_id(values)[ident]
            self.id[...] = ident
            self.top[...] = np.flatnonzero(self.body == TOP)
        for name in EVOLVING:
            if name == "id":
                continue
            target = getattr(self, name)
            source = np.asarray(arrays[name])
            if name in ("index", "shear"):
                target[:npairs] = source
            else:
                if target.shape != source.shape:
                    raise ValueError(f"checkpoint array {name!r} has shape {source.shape}, scene has {target.shape}")
                target[...] = source
        self.list_changed()
