"""Factories of the test suite: the one tiny scene (:func:`scene`), fork paths through
gouge_cli.io.layout (:func:`fork_at`, :func:`branch_at`) and the tiny loading run shared by the modules
of one test process (:class:`SharedRun`, the ``tiny_run`` fixture of tests/conftest.py: each module
forks its own copy).
"""

from __future__ import annotations

import copy
import shutil
from dataclasses import dataclass
from pathlib import Path

from gouge_cli.io.layout import ForkLayout, RunLayout

#: What every tiny scene shares: 300 grains 15 d wide, loaded through a spring of 2e-4 at 4e-5
#: (stick-slip within tens of thousands of t0), dt_safety 0.3.
BASE = {
    "packing": {"n_grains": 300, "width": 15},
    "loading": {"spring_constant": 2e-4, "velocity": 4e-5},
    "numerics": {"dt_safety": 0.3},
}


def scene(name: str | None = None, seed: int | None = None, **sections) -> dict:
    """The tiny scene (:data:`BASE`) named ``name`` with ``seed``, each keyword a config section:
    a section the base has is updated key by key (``numerics={"threads": 1}`` keeps dt_safety;
    ``None`` drops it), any other is added as given. A fresh dict each call."""
    out = {} if name is None else {"name": name}
    if seed is not None:
        out["seed"] = seed
    out.update(copy.deepcopy(BASE))
    for key, value in sections.items():
        if value is None:
            out.pop(key, None)
        elif key in BASE and isinstance(value, dict):
            out[key] = {**out[key], **copy.deepcopy(value)}
        else:
            out[key] = copy.deepcopy(value)
    return out


def fork_at(run_dir: Path, slip: int) -> ForkLayout:
    """``RUN/forks/slip_NNN`` of slip ``slip`` (``.root``, ``.pair_file``, ``.branch(perm)``)."""
    return RunLayout(run_dir).fork(slip)


def branch_at(run_dir: Path, slip: int, perm: float | None = None) -> RunLayout:
    """The drained branch (``perm`` None) or the kappa_c = ``perm`` branch of slip ``slip``'s fork
    (``.root``, ``.run_file``)."""
    return fork_at(run_dir, slip).branch(perm)


@dataclass(frozen=True)
class SharedRun:
    """A loading run made once per test process (tests/slipping.slipping_run): its config file,
    run directory and the slips kept with checkpoints. Never written to: :meth:`copy` gives a
    module its own run to fork and analyse."""

    config: Path
    out: Path
    numbers: list[int]

    def copy(self, root: Path) -> tuple[Path, Path, list[int]]:
        """(config, run directory, slip numbers) of a copy under ``root`` (the same names)."""
        root = Path(root)
        config, out = root / self.config.name, root / self.out.name
        shutil.copy2(self.config, config)
        shutil.copytree(self.out, out, symlinks=True)
        return config, out, list(self.numbers)
