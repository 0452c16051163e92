"""``GOUGE_TEST_SEED_OFFSET=N``: every packing the suite builds uses seed + N.

Applied through one wrapper of ``build_packing`` (scene dicts, shipped configs and defaults
alike): in the test process by conftest, and in every Python process the tests start (gouge
subprocesses, study process pools, Dask workers) through :func:`propagate`, so
``GOUGE_TEST_SEED_OFFSET=7 make test`` shows that no test depends on the trajectory of the seed it
happens to use. ``GOUGE_TEST_PACKING_LOG=FILE`` (with an offset) appends, for every packing built,
the test module that built it: the list of modules the seed sweep runs (docs/developer.md).
"""

from __future__ import annotations

import os
from pathlib import Path

OFFSET = int(os.environ.get("GOUGE_TEST_SEED_OFFSET", "0"))


def install() -> None:
    """Shift the seed of every packing built in this process by OFFSET (no-op for 0)."""
    if not OFFSET:
        return
    try:
        from gouge_cli.driver import simulation
        from gouge_cli.model import packing
    except ImportError:
        return

    original = packing.build_packing
    if getattr(original, "seed_offset", None) is not None:
        return

    log = os.environ.get("GOUGE_TEST_PACKING_LOG")

    def shifted(config):
        if log:         # which test module built a packing (the seed sweep's list of modules)
            with open(log, "a") as fh:
                fh.write(os.environ.get("PYTEST_CURRENT_TEST", "?").split("::")[0] + "\n")
        return original(config.model_copy(update={"seed": config.seed + OFFSET}))

    shifted.seed_offset = OFFSET
    packing.build_packing = simulation.build_packing = shifted


def propagate() -> None:
    """Make every Python process started from now on apply the same shift: the folder
    seed_offset_site (a sitecustomize that calls :func:`install`) goes first on PYTHONPATH, so gouge
    subprocesses, the process-pool workers of `gouge study` and Dask workers all pick it up."""
    if OFFSET:
        site = str(Path(__file__).resolve().parent / "seed_offset_site")
        os.environ["PYTHONPATH"] = os.pathsep.join([site] + [p for p in os.environ.get("PYTHONPATH", "").split(
            os.pathsep) if p and p != site])
