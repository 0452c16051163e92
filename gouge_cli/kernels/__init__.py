"""numba kernels only: arrays and scalars in, status codes out; no allocation, no exceptions, no
imports from the rest of gouge. Named indices of every shared array: layout.py. One home per
equation: contact.py (Eqs. 8-11), step.py (velocity Verlet), deposit.py (App. E),
pressure.py (Eqs. 14-20), drag.py (Eqs. 12-13), fluid_update.py (their order), coupled.py
(step + fluid), measure.py (observables), neighbors.py reorder.py (lists, numbering), lanes.py
(vector adds with the scalar bits), probe.py (the bench's machine probe).

One compiled specialisation per kernel: numba types a module constant, ``True``/``False`` and an
omitted default as a literal and compiles a jitted callee again for every literal it is passed
(the coupled step compiled ``_stages`` six times). Jitted call sites therefore pass constants as
``int(STAGE)`` / ``bool(False)`` and give ranges explicitly (``int(0), int(-1)``);
tests/kernels/test_compile_once.py holds every kernel to one specialisation per run kind."""

import hashlib
import os
import sys
from pathlib import Path


def _kernel_digest() -> str:
    """Hash of every kernel source: numba's on-disk cache only tracks the file of each function,
    not the kernels it inlines from other files, so the cache lives in a folder per digest."""
    h = hashlib.sha256()
    for path in sorted(Path(__file__).parent.glob("*.py")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


# numba compiles kernels once per machine and caches them (GOUGE_NUMBA_CACHE=0 turns it off).
NUMBA_CACHE = os.environ.get("GOUGE_NUMBA_CACHE", "1") != "0"
if NUMBA_CACHE and "NUMBA_CACHE_DIR" not in os.environ:
    _cache = str(Path(__file__).parent.parent / "__pycache__" / f"numba-{_kernel_digest()}")
    os.environ["NUMBA_CACHE_DIR"] = _cache
    if "numba" in sys.modules:
        sys.modules["numba"].config.CACHE_DIR = _cache


def cached_for_this_cpu(dispatcher) -> bool:
    """Whether numba's on-disk cache holds `dispatcher` compiled for this CPU's target (an index
    entry with this machine's triple, CPU name and features); False: its first call compiles it.
    True where the cache cannot tell (then nothing is announced)."""
    try:
        index = dispatcher._cache._cache_file._load_index()
        magic = dispatcher.targetctx.codegen().magic_tuple()
    except Exception:        # noqa: BLE001  (numba internals moved: say nothing rather than fail)
        return True
    return any(len(key) > 1 and key[1] == magic for key in index)
