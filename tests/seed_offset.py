"""``GOUGE_TEST_SEED_OFFSET=N``: every packing the suite builds uses seed + N.

Applied through one wrapper of ``build_packing`` (scene dicts, shipped configs and defaults
alike): in the test process by conftest, in the gouge processes that tests start through
:func:`gouge_command`, and in Dask workers (a worker preload, :func:`preload_workers`), so ``GOUGE_TEST_SEED_OFFSET=7 make test`` shows that no test depends on
the trajectory of the seed it happens to use.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

OFFSET = int(os.environ.get("GOUGE_TEST_SEED_OFFSET", "0"))


def install() -> None:
    """Shift the seed of every packing built in this process by OFFSET (no-op for 0)."""
    if not OFFSET:
        return
    from gouge_cli import packing, simulation

    original = packing.build_packing
    if getattr(original, "seed_offset", None) is not None:
        return

    def shifted(config):
        return original(config.model_copy(update={"seed": config.seed + OFFSET}))

    shifted.seed_offset = OFFSET
    packing.build_packing = simulation.build_packing = shifted


def gouge_command() -> list[str]:
    """argv prefix that runs the gouge command line in a new process with the same seed offset."""
    here = str(Path(__file__).resolve().parent)
    return [sys.executable, "-c",
            f"import sys; sys.path.insert(0, {here!r}); import seed_offset; seed_offset.install(); "
            "sys.argv[0] = 'gouge'; from gouge_cli.cli.main import app; app()"]


def dask_setup(worker) -> None:
    """Dask worker preload hook (set by conftest when OFFSET != 0): the same shift in workers."""
    install()


def preload_workers() -> None:
    """Make Dask workers started from now on (LocalCluster processes) preload this module."""
    if OFFSET:
        os.environ["DASK_DISTRIBUTED__WORKER__PRELOAD"] = f"[{str(Path(__file__).resolve())!r}]"
