"""Does this machine let two threads run a memory-streaming loop twice as fast as one?

    .venv/bin/python scripts/machine_scaling.py [ROUNDS]

Each round times three loops on 1 and on 2 threads, back to back, and prints the 2/1 speed-up:
  latency-bound compute  one dependent sqrt chain per thread (registers only)
  throughput compute     eight independent multiply-add chains per thread (the FP units)
  L2 stream              kernels.probe.stream_probe over 0.25 MB (125 kB per thread: each in its
                         own core's L2, nothing shared between the threads)
On a machine with two real cores all three are ~2.0x. On the 2-core CI-class virtual machine
(README "Speed") the compute loops stay at ~2.0x while the stream varies from ~1.2x to ~2.0x
between rounds: the second core is slowed only for work that moves data, which is what a DEM
step does. `gouge bench` runs the same probe beside gouge's own repeats.
"""

from __future__ import annotations

import math
import sys
import time

import numba
import numpy as np
from numba import njit, prange

from gouge_cli.kernels.probe import stream_probe


@njit(parallel=True)
def latency_bound(n, out):
    for t in prange(2):
        x = 1.0 + t
        for _ in range(n):
            x = math.sqrt(x + 1.0) * 1.0000001
        out[t] = x


@njit(parallel=True)
def throughput_bound(n, out):
    for t in prange(2):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 1.0 + t
        for _ in range(n):
            a0 = a0 * 0.9999999 + 1e-9
            a1 = a1 * 0.9999998 + 1e-9
            a2 = a2 * 0.9999997 + 1e-9
            a3 = a3 * 0.9999996 + 1e-9
            a4 = a4 * 0.9999995 + 1e-9
            a5 = a5 * 0.9999994 + 1e-9
            a6 = a6 * 0.9999993 + 1e-9
            a7 = a7 * 0.9999992 + 1e-9
        out[t] = a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7


def speedup(fn, *args) -> float:
    """Seconds on 1 thread / seconds on 2 threads, each after one untimed call."""
    seconds = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        fn(*args)
        t0 = time.perf_counter()
        fn(*args)
        seconds.append(time.perf_counter() - t0)
    return seconds[0] / seconds[1]


def main(rounds: int = 20):
    if numba.config.NUMBA_NUM_THREADS < 2:
        sys.exit("needs 2 threads (NUMBA_NUM_THREADS >= 2)")
    out = np.zeros(2)
    a = np.linspace(0.0, 1.0, 15625)
    b = np.zeros_like(a)
    rows = np.array([(speedup(latency_bound, 10_000_000, out), speedup(throughput_bound, 20_000_000, out),
                      speedup(stream_probe, a, b, 2, 6000)) for _ in range(rounds)])
    print("round  latency-bound  throughput  L2 stream   (2 threads / 1 thread)")
    for i, (x, y, z) in enumerate(rows):
        print(f"{i:5d}  {x:13.2f}  {y:10.2f}  {z:9.2f}")
    for name, f in (("median", np.median), ("min", np.min), ("max", np.max)):
        print(f"{name:>6s} " + "  ".join(f"{v:.2f}" for v in f(rows, axis=0)))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
