"""Provenance: what produced a run file or checkpoint, and whether a continuation may differ.

Every run file and checkpoint stores ``provenance`` (JSON attribute) with the gouge version
and git commit, the command line, the Python and library versions, the C library, the CPU
model and vector features, numba's code-generation target and thread count; run files also
store ``final_state_hash`` (:func:`state_hash` of the last state) when they close.

The state's bits are meant not to depend on the CPU (see :mod:`gouge_cli.model.portable`; tested
across numba/numpy code-generation targets and thread counts). They do depend on the versions
of the libraries that compute it (numpy, numba, llvmlite) and on the C library's ``sin`` /
``atan2`` (fluid deposit), so :func:`bit_risks` names a stored/current difference in those.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

from .. import __version__

# keys whose difference can change the bits of a continued trajectory
BIT_KEYS = ("numpy", "numba", "llvmlite", "libc", "python")
VECTOR_FEATURES = ("sse4_2", "avx", "fma", "avx2", "avx512f", "avx512vl", "avx512dq", "avx512bw", "neon", "sve")


@lru_cache(maxsize=1)
def git_commit() -> str:
    """Commit of the source tree gouge runs from ('+dirty' if it has changes), or 'not a git checkout'."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return "not a git checkout"
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "not a git checkout"
    if not head:
        return "not a git checkout"
    return head + ("+dirty" if dirty else "")


@lru_cache(maxsize=1)
def cpu() -> dict:
    """CPU model, the vector features present (of VECTOR_FEATURES), and numba's target."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            key = key.strip()
            if key in ("model name", "Model") and model in ("", platform.machine(), platform.processor()):
                model = value.strip()
            elif key in ("flags", "Features") and not flags:
                flags = set(value.split())
    except OSError:
        pass
    import llvmlite.binding as ll
    import numba

    return {"model": model, "machine": platform.machine(),
            "vector_features": [f for f in VECTOR_FEATURES if f in flags],
            "vector_width_bits": 512 if "avx512f" in flags else 256 if "avx2" in flags else 128,
            "numba_target": os.environ.get("NUMBA_CPU_NAME") or ll.get_host_cpu_name(),
            "numba_threads_available": int(numba.config.NUMBA_NUM_THREADS)}


@lru_cache(maxsize=1)
def libraries() -> dict:
    """Versions of the interpreter and every library that touches the state or the files."""
    import h5py
    import llvmlite
    import numba
    import scipy

    libc = "-".join(platform.libc_ver()) or "unknown"
    return {"gouge": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "numba": numba.__version__, "llvmlite": llvmlite.__version__, "h5py": h5py.__version__,
            "hdf5": h5py.version.hdf5_version, "scipy": scipy.__version__, "libc": libc}


def collect(threads: int | None = None, command: list[str] | None = None) -> dict:
    """The provenance record of this process (JSON-serialisable)."""
    return {"gouge_version": __version__, "git_commit": git_commit(),
            "command": list(sys.argv if command is None else command),
            "libraries": dict(libraries()), "cpu": dict(cpu()), "threads": threads,
            "numpy_cpu_features": os.environ.get("NPY_ENABLE_CPU_FEATURES", "") or "host"}


def dumps(record: dict) -> str:
    return json.dumps(record, sort_keys=True)


def loads(text) -> dict:
    """Parse a stored provenance attribute; {} for files written before provenance existed."""
    if text is None:
        return {}
    try:
        return json.loads(text)
    except (TypeError, ValueError):
        return {}


def state_digest(groups: dict[str, dict[str, np.ndarray]]) -> str:
    """SHA-256 (hex) over every array's group/name, dtype, shape and bytes, in sorted order
    (the checkpoint checksum)."""
    h = hashlib.sha256()
    for group in sorted(groups):
        for name in sorted(groups[group]):
            arr = np.ascontiguousarray(groups[group][name])
            h.update(f"{group}/{name}:{arr.dtype.str}:{arr.shape}".encode())
            h.update(arr.tobytes())
    return h.hexdigest()


def state_hash(arrays: dict, fluid: dict | None = None) -> str:
    """First 16 hex digits of :func:`state_digest` of a state (and its fluid grid)."""
    return state_digest({"state": arrays, "fluid": fluid or {}})[:16]


def sim_hash(sim) -> str:
    """:func:`state_hash` of a Simulation's current state (grains, walls, lists, fluid grid)."""
    return state_hash(sim.state.arrays(), sim.fluid.arrays() if sim.fluid is not None else None)


def bit_risks(stored: dict, current: dict | None = None) -> list[str]:
    """Differences between a stored provenance and this process that can change the bits of a
    continued trajectory (library versions, C library); [] if none or nothing was stored."""
    if not stored:
        return []
    current = current or collect()
    old, new = stored.get("libraries", {}), current.get("libraries", {})
    return [f"{key} {old[key]} -> {new.get(key)}" for key in BIT_KEYS
            if key in old and old[key] != new.get(key)]


def risk_line(stored: dict, what: str) -> str | None:
    """One line for the user when continuing `what` may not reproduce its bits, else None."""
    risks = bit_risks(stored)
    if not risks:
        return None
    return (f"note: {what} was written with other library versions ({'; '.join(risks)}); the continued "
            "trajectory may differ from an uninterrupted one in the last bits (chaos amplifies them)")
