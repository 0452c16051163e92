"""Machine probe for `gouge bench`: a loop that streams two arrays in fixed parts, one part per
thread, with no data shared between the parts and no barrier inside. Its speed-up on t threads is
what the machine itself allows a memory-streaming loop (the kind of work a step's passes do);
on a virtual machine it can fall well below t while compute-only loops still scale
(studies.bench, README "Speed")."""

from numba import njit, prange

from . import NUMBA_CACHE


@njit(parallel=True, cache=NUMBA_CACHE)
def stream_probe(a, b, parts, reps):
    """reps times b[i] = 0.5 (a[i] + b[i]) for every i, in `parts` fixed contiguous parts run in
    parallel (the same bits on any thread count).

    a, b : float64[n], C-contiguous;  parts, reps : >= 1."""
    n = a.size
    for p in prange(parts):
        lo = p * n // parts
        hi = (p + 1) * n // parts
        for _ in range(reps):
            for i in range(lo, hi):
                b[i] = 0.5 * (a[i] + b[i])
