"""Pool workers that stop when the process that started them dies: no orphans.

A worker of ``gouge study``'s process pool calls :func:`follow_parent` as it starts (the pool's
initializer), with the PID of the process that owns the pool. On Linux the kernel then sends the
worker SIGKILL when that process ends, however it ends (``prctl(PR_SET_PDEATHSIG)``, through
ctypes); everywhere, a daemon thread also checks every POLL seconds that the worker's parent is
still that process (an orphan is adopted by init or a subreaper, so ``os.getppid()`` changes) and
ends the worker otherwise. The branch a killed worker was running is left unfinished and is run
again by the next invocation. (Dask's worker processes, ``gouge campaign``, already end with
their nanny: distributed watches a pipe to the parent.)
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

POLL = 0.5              # seconds between the fallback's checks of the parent
PR_SET_PDEATHSIG = 1    # linux/prctl.h


def _parent_death_signal() -> bool:
    """Ask Linux for SIGKILL when the parent ends; False where that is not available."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent_pid: int, poll: float):
    while os.getppid() == parent_pid:
        time.sleep(poll)
    os._exit(1)


def follow_parent(parent_pid: int, poll: float = POLL) -> None:
    """Make this process end when ``parent_pid`` (its parent) ends (module doc). Exits at once
    when the parent is already gone, or is not ``parent_pid``."""
    _parent_death_signal()
    if os.getppid() != parent_pid:      # it died before the death signal was armed
        os._exit(1)
    threading.Thread(target=_watch, args=(parent_pid, poll), daemon=True, name="gouge-follow-parent").start()


__all__ = ["follow_parent", "POLL"]
