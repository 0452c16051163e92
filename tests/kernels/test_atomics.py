"""fetch_add: threads that take chunks of a range through one shared counter each take a different
chunk, and together every chunk once (kernels.coupled claims the deposit's finish that way)."""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from gouge_cli.kernels.atomics import fetch_add
from needs import two_threads


@njit
def _serial(counter):
    return fetch_add(counter, 1, 5), fetch_add(counter, 1, -2), counter[1]


@njit(parallel=True)
def _claim_all(tasks, size, counter, taken):
    """Every task takes single items of [0, size) until none is left, counting what it takes."""
    for t in prange(tasks):
        while True:
            item = fetch_add(counter, 0, 1)
            if item >= size:
                break
            taken[item] += 1
            counter[2 + t] += 1


def test_fetch_add_returns_the_old_value():
    counter = np.array([7, 10, 3], np.int64)
    assert _serial(counter) == (10, 15, 13)
    assert list(counter) == [7, 13, 3]


@two_threads
def test_chunks_are_taken_once_each_by_racing_threads():
    """200 rounds of 20,000 single items taken by 2 threads at once: with a plain (non-atomic)
    add, the threads racing on the counter take some items twice and the per-task counts sum to
    more than the items (a race needs two threads: skipped on one)."""
    threads = 2
    size = 20_000
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        for _ in range(200):
            counter = np.zeros(2 + threads, np.int64)
            taken = np.zeros(size, np.int64)
            _claim_all(threads, size, counter, taken)
            assert (taken == 1).all()
            assert counter[2:].sum() == size
            assert counter[0] == size + threads          # each task's last claim overshoots by one
    finally:
        numba.set_num_threads(before)
