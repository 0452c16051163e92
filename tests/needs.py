"""What a test needs that not every machine gives, as skips with their reason (``pytest -rs``
lists them): two numba threads. ``make test`` runs with NUMBA_NUM_THREADS=2, so these run there;
a run with one thread reports them skipped instead of passing them on one thread."""

from __future__ import annotations

import numba
import pytest

THREADS = numba.config.NUMBA_NUM_THREADS
TWO_THREADS_REASON = (f"needs 2 numba threads, NUMBA_NUM_THREADS={THREADS} here "
                      "(`make test` runs with NUMBA_NUM_THREADS=2)")

two_threads = pytest.mark.skipif(THREADS < 2, reason=TWO_THREADS_REASON)


def skip_unless_two_threads(what: str) -> None:
    """Skip (after a test's one-thread checks) when numba has a single thread: `what` was not checked."""
    if THREADS < 2:
        pytest.skip(f"{what} not checked: {TWO_THREADS_REASON}")
