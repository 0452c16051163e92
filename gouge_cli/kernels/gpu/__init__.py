"""The dry DEM step on a CUDA GPU (numba-cuda), for B independent layers at once.

device.py compiles the CPU kernels' own Python functions (the contact law, Eqs. 8-11, the
half kick, the list scan, the counting sorts, the re-numbering) for the CUDA target: the
physics is written once. dry.py is the kernel: one thread block per layer, many steps per
launch, each grain gathering its forces over its own pairs in the CPU's fixed order (no
floating-point atomics), FMA contraction off: the same operations in the same order as
kernels.step.advance, so the same bits. Nothing here is imported by the CPU path.
"""

from __future__ import annotations

import os


def availability() -> str | None:
    """None if a CUDA device (or numba-cuda's simulator, NUMBA_ENABLE_CUDASIM=1) can run the
    GPU engine, else the reason it cannot (no numba-cuda, no driver, no device)."""
    try:
        from numba import cuda
    except ImportError as exc:       # numba without its CUDA target: numba-cuda is not installed
        return f"numba-cuda is not installed ({exc}); pip install 'gouge[gpu]'"
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return None
    try:
        if not cuda.is_available():
            return "no CUDA GPU or driver found (numba.cuda.is_available() is False)"
    except Exception as exc:        # a broken driver install raises instead of answering
        return f"the CUDA driver could not be queried: {exc}"
    return None
