"""``RUN/forks/slip_NNN/pair.json``: the pair verdict of one forked slip, from its branch files.

Written after ``gouge restart`` and by ``gouge study`` from the same rows that ``gouge analyze``
writes to pairs.csv (:func:`gouge_cli.analysis.forkpairs.classify_fork`, one pair definition), so the
two cannot disagree.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from ..analysis.forkpairs import classify_fork, fork_branches
from ..errors import AnalysisError, InputError
from ..io.checkpoint import read_checkpoint
from ..io.filedoc import json_safe
from ..io.integrity import check_seal, stored_seal
from ..io.provenance import bit_risks, loads
from ..io.layout import ForkLayout, RunLayout
from ..io.runreader import RunReader

__all__ = ["write_pair_json", "branch_status"]


def branch_status(branch_dir: Path) -> str:
    """Status attribute of ``branch_dir/run.h5`` ('missing' or 'unreadable' when it has none)."""
    h5 = RunLayout(branch_dir).run_file
    if not h5.is_file():
        return "missing"
    try:
        with RunReader(branch_dir, allow_running=True) as r:
            return r.info.status
    except AnalysisError:
        return "unreadable"


def write_pair_json(fork_dir: Path, main: str = "first") -> dict:
    """Classify the fork's pairs and write ``fork_dir/pair.json``; returns what it wrote.

    ``{"slip", "fork_dir", "branches": {name: status}, "definition": {...}, "run", "time_origin",
    "pairs": [pairs.csv row per undrained branch], "library_differences_from_parent": [...]}`` (run:
    the parent run relative to this file's folder, also in each row; times in t0 since loading
    began, as everywhere; library versions that
    differ between the parent's checkpoint and the branches: the drained branch may then not
    retrace the parent bit for bit). Raises :class:`~gouge_cli.errors.AnalysisError` when a
    branch is missing or still running.
    """
    fork = ForkLayout(fork_dir)
    fork_dir = fork.root
    pairs = classify_fork(fork_dir, main)
    drained, undrained = fork_branches(fork_dir)
    branches = {p.name: branch_status(p) for p in [drained, *undrained] if p is not None}
    risks = sorted({r for p in [drained, *undrained] if p is not None for r in branch_bit_risks(p)})
    record = json_safe({
        "slip": pairs[0].slip if pairs else fork.slip,
        "fork_dir": fork_dir.name,
        "branches": branches,
        "definition": pairs[0].result.definition if pairs else None,
        "run": "../..",
        "time_origin": "loading start",
        "pairs": [dict(p.row, run="../..") for p in pairs],
        "library_differences_from_parent": risks,
    })
    fork.pair_file.write_text(json.dumps(record, indent=2, allow_nan=False))
    return record


def branch_bit_risks(branch_dir: Path) -> list[str]:
    """:func:`~gouge_cli.io.provenance.bit_risks` between the parent checkpoint a fork branch
    started from and the provenance the branch was run with, both read through their checksums
    ([] if either file or its provenance is missing; one line saying so if either is damaged,
    nothing compared)."""
    try:
        with h5py.File(RunLayout(branch_dir).run_file, "r") as h5:
            check_seal(h5, stored_seal(h5) is not None)
            mine = loads(h5.attrs.get("provenance"))
            parent = Path(branch_dir) / str(h5.attrs.get("parent_run", "")) / str(h5.attrs.get("parent_checkpoint", ""))
        if not mine or not parent.is_file():
            return []
        theirs = read_checkpoint(parent).provenance
    except (OSError, KeyError):
        return []
    except InputError as err:       # a damaged branch file or parent checkpoint: say so, compare nothing
        return [f"not compared: {str(err).splitlines()[0]}"]
    return bit_risks(theirs, mine)
