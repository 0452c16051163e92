"""The run-directory layout: the one module that spells the names of a run directory's files.

::

    RUN/                        RunLayout(RUN)
        config.yaml             .config_file
        run.h5                  .run_file          (io.runfile)
        checkpoints/            .checkpoints
            latest.h5           .latest            (resume)
            slip_NNN.h5         .slip_checkpoint(n) (the state before slip n, for forks)
        forks/                  .forks
            slip_NNN/           .fork(n): ForkLayout
                pair.json       ForkLayout.pair_file
                drained/        ForkLayout.branch(None): a RunLayout of its own (run.h5 ...)
                perm_K/         ForkLayout.branch(K), K in perm_text's format
        analysis/, figures/     .analysis, .figures

A fork branch is a run directory itself (its own run.h5), so ``ForkLayout.branch`` returns a
RunLayout. Everything else in gouge builds these paths through this module.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

RUN_FILE = "run.h5"
CONFIG_FILE = "config.yaml"
CHECKPOINTS = "checkpoints"
LATEST = "latest.h5"
FORKS = "forks"
ANALYSIS = "analysis"
FIGURES = "figures"
PAIR_FILE = "pair.json"
DRAINED = "drained"
_PERM = "perm_"
_SLIP = "slip_"
# what a run directory owns (removed by `gouge run --force`, never anything else)
OWNED = (RUN_FILE, CONFIG_FILE, CHECKPOINTS, FORKS, FIGURES, ANALYSIS)


def perm_text(perm: float) -> str:
    """kappa_c in the one format of branch folders and labels: shortest exact scientific, e.g.
    1e-05, 2.5e-05, 1e-03."""
    return np.format_float_scientific(float(perm), trim="-", exp_digits=2)


def branch_name(perm: float | None) -> str:
    """Branch folder of a fork: ``drained`` or ``perm_<perm_text>`` (e.g. perm_1e-05, perm_1e-03)."""
    return DRAINED if perm is None else f"{_PERM}{perm_text(perm)}"


def branch_perm(path: Path | str) -> float:
    """kappa_c of a ``perm_*`` branch folder (also the older ``perm_0.001`` spelling); inf if unreadable."""
    try:
        return float(Path(path).name[len(_PERM):])
    except ValueError:
        return math.inf


def branch_perm_text(name: str) -> str:
    """The kappa_c of a ``perm_*`` branch folder name as written there (labels)."""
    return name.removeprefix(_PERM)


def branch_flag(name: str) -> str:
    """The `gouge restart` option that recomputes a branch folder: '' (drained) or ' --perm K'."""
    return "" if name == DRAINED else f" --perm {branch_perm_text(name)}"


def slip_name(slip: int) -> str:
    """``slip_NNN``: the stem of slip n's checkpoint and of its fork folder."""
    return f"{_SLIP}{slip:03d}"


class RunLayout:
    """The paths of one run directory (module doc)."""

    def __init__(self, root: Path | str):
        self.root = Path(root)

    def __repr__(self):
        return f"RunLayout({str(self.root)!r})"

    @classmethod
    def of_checkpoint(cls, path: Path | str) -> RunLayout:
        """The run directory a checkpoint file (``RUN/checkpoints/NAME.h5``) belongs to."""
        return cls(Path(path).resolve().parent.parent)

    @property
    def run_file(self) -> Path:
        return self.root / RUN_FILE

    @property
    def config_file(self) -> Path:
        return self.root / CONFIG_FILE

    @property
    def checkpoints(self) -> Path:
        return self.root / CHECKPOINTS

    @property
    def latest(self) -> Path:
        return self.checkpoints / LATEST

    def slip_checkpoint(self, slip: int) -> Path:
        return self.checkpoints / f"{slip_name(slip)}.h5"

    def relative(self, path: Path) -> str:
        """`path` relative to the run directory, as the catalog and reports name files."""
        return Path(path).relative_to(self.root).as_posix()

    def slip_checkpoints(self) -> list[Path]:
        """The slip checkpoints present, in slip order."""
        return sorted(self.checkpoints.glob(f"{_SLIP}*.h5"))

    def checkpoint_files(self) -> list[Path]:
        """Every checkpoint file present (latest and slips), sorted by name."""
        return sorted(self.checkpoints.glob("*.h5"))

    @property
    def forks(self) -> Path:
        return self.root / FORKS

    @property
    def analysis(self) -> Path:
        return self.root / ANALYSIS

    @property
    def figures(self) -> Path:
        return self.root / FIGURES

    def fork_branch(self) -> tuple[Path, int, float | None] | None:
        """(parent run dir, slip, kappa_c or None for drained) when this directory is a fork
        branch, RUN/forks/slip_NNN/drained or perm_K, read off its place in the layout; else None."""
        fork = ForkLayout(self.root.parent)
        if fork.root.parent.name != FORKS or fork.slip < 0:
            return None
        if self.root.name == DRAINED:
            return fork.root.parent.parent, fork.slip, None
        perm = branch_perm(self.root) if self.root.name.startswith(_PERM) else math.inf
        return (fork.root.parent.parent, fork.slip, perm) if math.isfinite(perm) else None

    def fork(self, slip: int) -> ForkLayout:
        return ForkLayout(self.forks / slip_name(slip))

    def fork_dirs(self) -> list[Path]:
        """``forks/slip_NNN`` directories present, in slip order."""
        return sorted(p for p in self.forks.glob(f"{_SLIP}*") if p.is_dir()) if self.forks.is_dir() else []

    def branch_dirs(self) -> list[Path]:
        """Every fork branch directory present (``forks/slip_NNN/<branch>``), sorted."""
        return sorted(p for p in self.forks.glob(f"{_SLIP}*/*") if p.is_dir())

    def branch_run_files(self) -> list[Path]:
        """The run files of every fork branch present, sorted."""
        return sorted(self.forks.glob(f"{_SLIP}*/*/{RUN_FILE}"))


class ForkLayout:
    """The paths of one fork, ``RUN/forks/slip_NNN`` (module doc)."""

    def __init__(self, root: Path | str):
        self.root = Path(root)

    def __repr__(self):
        return f"ForkLayout({str(self.root)!r})"

    @property
    def slip(self) -> int:
        """The forked slip's number, from the folder name (-1 if it is not ``slip_NNN``)."""
        try:
            return int(self.root.name.removeprefix(_SLIP))
        except ValueError:
            return -1

    @property
    def pair_file(self) -> Path:
        return self.root / PAIR_FILE

    def branch(self, perm: float | None) -> RunLayout:
        """The branch run directory: drained (perm None) or undrained at kappa_c = perm."""
        return RunLayout(self.root / branch_name(perm))

    def branches(self) -> tuple[Path | None, list[Path]]:
        """(drained run dir or None, undrained ``perm_*`` run dirs sorted by permeability), those
        with a run file only."""
        drained = self.root / DRAINED
        perms = [p for p in self.root.glob(f"{_PERM}*") if (p / RUN_FILE).is_file()]
        return (drained if (drained / RUN_FILE).is_file() else None), sorted(perms, key=branch_perm)

    def branch_run_files(self) -> list[Path]:
        """The run files of this fork's branches present, sorted."""
        return sorted(self.root.glob(f"*/{RUN_FILE}"))

    def undrained_dirs(self) -> list[Path]:
        """Every ``perm_*`` folder present, finished or not, sorted by name."""
        return sorted(p for p in self.root.glob(f"{_PERM}*") if p.is_dir())


def runs_under(runs_root: Path) -> list[Path]:
    """Run directories directly under runs_root (those holding a run file)."""
    return [p.parent for p in Path(runs_root).glob(f"*/{RUN_FILE}")]
