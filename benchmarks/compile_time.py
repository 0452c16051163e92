"""The kernels' one-off compile: CPU seconds per kernel and specialisations, in a fresh cache.

    .venv/bin/python benchmarks/compile_time.py [--json]

Runs a 200-grain scene dry (compaction + 30 steps) and then wet (kappa_c 1e-5, 30 steps) on one
thread in this process, with numba's cache pointed at a new empty folder (so everything
compiles), and reports the compile CPU time of each kernel exclusive of the kernels it compiles
inside it (numba's compile events; CPU time, so that a busy machine changes it little), the
dry and wet totals, and every kernel compiled more than once with the argument that differs.
--json: one JSON object instead of the table (tests/kernels/test_compile_once.py reads it).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from collections import defaultdict

if __name__ == "__main__":
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="gouge-compile-")     # before numba loads

import numba
from numba.core import event

SCENE = {"packing": {"n_grains": 200, "width": 12}, "numerics": {"dt_safety": 0.3},
         "compaction": {"min_time": 200, "max_time": 400}}


class _Compiles(event.Listener):
    """Exclusive compile CPU time [s] per kernel (nested compiles subtracted from their caller)."""

    def __init__(self):
        self.seconds = defaultdict(float)
        self._open = []

    def on_start(self, e):
        self._open.append([time.process_time(), 0.0])

    def on_end(self, e):
        start, inner = self._open.pop()
        total = time.process_time() - start
        if self._open:
            self._open[-1][1] += total
        f = e.data["dispatcher"].py_func
        self.seconds[f"{f.__module__.rsplit('.', 1)[-1]}.{f.__name__}"] += total - inner


def _repeated() -> dict[str, list[str]]:
    """Kernels of gouge_cli.kernels with several specialisations: {name: the arguments that differ}."""
    import importlib
    import pkgutil

    import gouge_cli.kernels

    out = {}
    for info in pkgutil.iter_modules(gouge_cli.kernels.__path__):
        module = importlib.import_module(f"gouge_cli.kernels.{info.name}")
        for name, obj in vars(module).items():
            if not (isinstance(obj, numba.core.registry.CPUDispatcher) and obj.__module__ == module.__name__):
                continue
            sigs = [list(s) for s in obj.signatures]
            if len(sigs) > 1:
                names = obj.py_func.__code__.co_varnames
                out[f"{info.name}.{name}"] = [
                    f"{names[i]}: " + " / ".join(sorted({str(s[i])[:60] for s in sigs}))
                    for i in range(len(sigs[0])) if len({str(s[i]) for s in sigs}) > 1]
    return out


def measure() -> dict:
    """Compile everything a dry and a wet run need; {dry_seconds, wet_seconds, kernels, repeated}."""
    from gouge_cli.config import build_config
    from gouge_cli.driver.compaction import compact
    from gouge_cli.driver.simulation import Simulation

    listener = _Compiles()
    event.register("numba:compile", listener)
    numba.set_num_threads(1)
    t0 = time.process_time()
    dry = Simulation(build_config(SCENE))
    compact(dry)
    dry.advance(30)
    dry.observe()
    t1 = time.process_time()
    wet = Simulation(build_config({**SCENE, "fluid": {"permeability": 1e-5}}))
    compact(wet)
    wet.start_fluid()
    wet.advance(30)
    wet.observe()
    t2 = time.process_time()
    event.unregister("numba:compile", listener)
    kernels = dict(sorted(listener.seconds.items(), key=lambda kv: -kv[1]))
    return {"dry_seconds": t1 - t0, "wet_seconds": t2 - t1, "kernels": kernels, "repeated": _repeated(),
            "numba_target": numba.core.config.CPU_NAME or "host"}


def main() -> None:
    result = measure()
    if "--json" in sys.argv:
        print(json.dumps(result))
        return
    print(f"compile CPU time: dry run {result['dry_seconds']:.1f} s, wet run adds {result['wet_seconds']:.1f} s "
          f"(numba target {result['numba_target']})")
    for name, seconds in list(result["kernels"].items())[:20]:
        print(f"  {seconds:6.1f} s  {name}")
    for name, args in result["repeated"].items():
        print(f"  compiled more than once: {name} ({'; '.join(args)})")


if __name__ == "__main__":
    main()
