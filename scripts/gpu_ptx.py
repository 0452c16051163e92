"""Compile the GPU dry kernel (kernels.gpu.dry.advance_layers) to PTX without a GPU, and count
what the bits depend on: FMA instructions (must be 0), floating-point atomics (0; integer atomics
count and claim slots in kernels.gpu.parallel), IEEE div/sqrt, barriers.

    pip install 'gouge[gpu-ptx]'; .venv/bin/python scripts/gpu_ptx.py [cc, default 9.0] [out.ptx]

numba-cuda asks the driver for the compute capability when it compiles device functions; with
no driver here it is given as the argument (a development check: run scripts/gpu_check.sh on a GPU).
"""

import re
import sys
import time
import types as _types

import numba.cuda.compiler as _compiler
import numba.cuda.dispatcher as _dispatcher
import numpy as np
from numba import cuda, typeof, types

CC = tuple(int(v) for v in (sys.argv[1] if len(sys.argv) > 1 else "9.0").split("."))
_device = _types.SimpleNamespace(compute_capability=CC)
_dispatcher.get_current_device = _compiler.get_current_device = lambda: _device

from gouge_cli.config import build_config  # noqa: E402
from gouge_cli.driver.simulation import Simulation  # noqa: E402
from gouge_cli.kernels.gpu import dry  # noqa: E402
from gouge_cli.kernels import layout as L  # noqa: E402
from gouge_cli.model.gpu_layers import GRAIN, LISTS, PAIR_RESULTS, RECORDS, Layers  # noqa: E402

sim = Simulation(build_config({"packing": {"n_grains": 40, "width": 6}}))
layers = Layers([sim.state], sim.params, 64)
arrays = {name: layers._stack(name, sim.state.index.shape[0]) for name in GRAIN + LISTS + RECORDS}
arrays.update(top=np.zeros((1, 1), np.int64), params=layers.params)
records = (L.Grains(*(arrays[f] for f in L.Grains._fields)), L.Lists(*(arrays[f] for f in L.Lists._fields)),
           tuple(arrays[f] for f in PAIR_RESULTS))
# advance_layers(grains, lists, pairs, wall, clock, params, counters, ntop, todo, done, status, none, parallel,
# timers)
signature = (tuple(typeof(r) for r in records) + tuple(typeof(arrays[f]) for f in ("wall", "clock", "params",
                                                                                    "counters"))
             + (types.int64[::1],) * 4 + (types.float64[::1], types.int64, types.int64[:, ::1]))
t0 = time.perf_counter()
ptx, _ = cuda.compile_ptx(dry.advance_layers.py_func, signature, cc=CC)
float_atomics = len(re.findall(r"atom\.[a-z.]*\.f(32|64)", ptx))
print(f"sm_{CC[0]}{CC[1]}: compiled in {time.perf_counter() - t0:.1f} s; fma.rn.f64 {ptx.count('fma.rn.f64')}, "
      f"float atomics {float_atomics}, integer atomics {ptx.count('atom.') - float_atomics}, "
      f"div.rn.f64 {ptx.count('div.rn.f64')}, sqrt.rn.f64 {ptx.count('sqrt.rn.f64')}, "
      f"barriers {ptx.count('bar.sync') + ptx.count('barrier.sync')}")
if len(sys.argv) > 2:
    open(sys.argv[2], "w").write(ptx)
sys.exit(1 if ptx.count("fma.rn.f64") or float_atomics else 0)
