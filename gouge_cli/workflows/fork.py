"""`gouge restart`: drained and undrained branches from the packing kept before a slip.

Both branches start from the identical checkpoint (grains, walls, contact history, clock).
The drained branch is the dry model: with unchanged parameters it retraces the original
run bit for bit. Each undrained branch adds the pore fluid with kappa_c = K, starting from
P = 0 on that packing. Outputs: ``RUN/forks/slip_NNN/{drained,perm_K}/run.h5``. The pair
verdict (``pair.json``) is written by :mod:`gouge_cli.workflows.pairs` from these files with the
one pair definition of :mod:`gouge_cli.analysis.pairs`.
"""

from __future__ import annotations

import errno
import math
import os
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ..io import provenance
from ..io.checkpoint import read_checkpoint
from ..config import build_config, Config
from ..errors import ConfigError, NoSpaceError
from ..driver.slips import lead_time
from ..io.runfile import RunFile, slip_catalog
from ..model.preflight import check_config
from ..errors import RunDirError
from ..io.rundir import check_run_dir, refuse_if_in_progress, RunLock
from ..driver.phases import load_phase
from ..driver.simulation import Simulation
from .pairs import branch_status
from .run import stopped_by_os_error


def branch_name(perm: float | None) -> str:
    return "drained" if perm is None else f"perm_{perm:g}"


FORK_SLIP_FRAMES = 30     # snapshots per predicted slip duration while a fork slips (output.slip_frames)


def branch_config(base: Config, perm: float | None, overrides: dict | None = None) -> Config:
    data = base.to_dict()
    data["numerics"] = dict(data["numerics"], stick_scaling=1.0)     # stick scaling: forks at true inertia
    for section, values in (overrides or {}).items():
        data[section] = dict(data[section], **values)
    if perm is None:
        data["fluid"] = None
    else:
        fluid = dict(data.get("fluid") or {})
        fluid["permeability"] = perm
        data["fluid"] = fluid
    return build_config(data)


@dataclass
class BranchResult:
    name: str
    out_dir: Path
    status: str
    wall_seconds: float
    steps: int
    first_slip: dict | None


def fork_entry(run_dir: Path, slip: int) -> dict:
    """The catalog entry of slip ``slip``; :class:`RunDirError` naming the slips with checkpoints."""
    catalog = slip_catalog(run_dir)
    numbers = [int(e["number"]) for e in catalog if e.get("checkpoint")]
    if slip not in numbers:
        listed = ", ".join(str(n) for n in numbers) or "none yet"
        raise RunDirError(f"{run_dir} has no checkpoint for slip {slip}; slips with checkpoints: {listed}")
    return next(e for e in catalog if int(e["number"]) == slip)


def check_perms(perms) -> None:
    for perm in perms:
        if not (perm is None or (perm > 0 and math.isfinite(perm))):
            raise ConfigError(f"--perm = {perm:g}: the permeability prefactor kappa_c must be a positive number [d^2]")


def run_branch(run_dir: Path, slip: int, perm: float | None, duration: float | None = None,
               overrides: list[str] | None = None, live=None, quiet: bool = False,
               stop_after_slip: bool | None = None) -> BranchResult:
    """Run one branch (drained: ``perm=None``) of slip ``slip`` into ``RUN/forks/slip_NNN/<branch>``.

    ``duration`` [t0] from the checkpoint; None: 5 x (end - checkpoint time) + 2 leads.
    ``stop_after_slip``: stop when the branch's first slip ends (default: when ``duration`` is None).
    Overwrites an existing branch directory. The branch directory is locked while it runs (so
    branches of one run may run in parallel), and the run itself must not be in progress. Dense
    snapshots while the branch slips: output.slip_frames, FORK_SLIP_FRAMES unless overridden.
    """
    run_dir = Path(run_dir)
    refuse_if_in_progress(run_dir, f"restart --slip {slip}")
    entry = fork_entry(run_dir, slip)
    ck = read_checkpoint(run_dir / entry["checkpoint"], overrides)
    frames = {} if any(o.split("=")[0].strip() == "output.slip_frames" for o in overrides or []) \
        else {"output": {"slip_frames": ck.config.output.slip_frames or FORK_SLIP_FRAMES}}
    config = branch_config(ck.config, perm, frames)
    check_config(config)
    name = branch_name(perm)
    if stop_after_slip is None:
        stop_after_slip = duration is None
    if duration is None:
        span = float(entry["end_time"]) - ck.time
        duration = 5.0 * span + 2.0 * lead_time(ck.config)
    out_dir = run_dir / "forks" / f"slip_{slip:03d}" / name
    out_dir.mkdir(parents=True, exist_ok=True)
    with RunLock(out_dir, f"gouge restart --slip {slip} ({name})"):
        return _run_branch(run_dir, slip, entry, ck, config, name, out_dir, duration, stop_after_slip, live, quiet)


def _run_branch(run_dir, slip, entry, ck, config, name, out_dir, duration, stop_after_slip, live, quiet):
    t0 = time.perf_counter()
    sim = Simulation(config, arrays=ck.state)
    writer = RunFile(out_dir / "run.h5", config, sim.dt, extra_attrs={
        "parent_run": os.path.relpath(run_dir, out_dir), "parent_checkpoint": str(entry["checkpoint"]),
        "fork_slip": slip, "branch": name, "n_grains": sim.state.n, "width": sim.state.width,
        "wall_mass_per_length": sim.wall_mass_per_length, "load_start_time": ck.time,
        "end_time": ck.time + duration}, threads=sim.threads)
    step0 = sim.state.step
    try:
        writer.append(sim.observe())
        status, recorder = load_phase(sim, writer, out_dir, ck.time + duration, live=live, quiet=quiet,
                                      label=f"slip {slip} {name}", checkpoints=False,
                                      stop_after_slip=stop_after_slip)
    except (OSError, RuntimeError) as err:      # e.g. a full disk: the branch is left 'failed: ...'
        raise stopped_by_os_error(writer, err) from None
    writer.close(status, provenance.sim_hash(sim))
    first = recorder.slips[0] if recorder.slips else None
    return BranchResult(name, out_dir, status, time.perf_counter() - t0, sim.state.step - step0, first)


def restart_command(run_dir: Path, slip: int, perms: list[float], overrides: list[str] | None = None,
                    duration: float | None = None) -> str:
    """The `gouge restart` command line that runs this fork (named in the messages of a stopped one)."""
    args = ["gouge", "restart", str(run_dir), "--slip", str(slip)]
    for perm in perms:
        args += ["--perm", f"{perm:g}"]
    for o in overrides or []:
        args += ["--set", o]
    if duration is not None:
        args += ["--duration", f"{duration:g}"]
    return shlex.join(args)


def run_fork(run_dir: Path, slip: int, perms: list[float], overrides: list[str] | None = None,
             duration: float | None = None, force: bool = False, live=None, quiet=False) -> dict:
    """Fork the drained branch and one undrained branch per permeability from slip `slip`.

    A fork whose branches all finished is refused without ``force``; one with a branch not
    finished (interrupted, stopped by a full disk, killed) is run again whole, without ``force``.
    A branch stopped by Ctrl-C stops the fork (KeyboardInterrupt, naming the command that finishes
    it; no later branch runs); a full disk raises :class:`~gouge_cli.errors.NoSpaceError` naming it.

    Returns ``{"run", "slip", "start_time", "branches": {name: {status, dir, wall_seconds, steps,
    first_slip}}, "library_differences_from_parent"}`` (first_slip: the detector's record of the
    branch's first slip; paths relative to the fork directory)."""
    run_dir = check_run_dir(run_dir)
    refuse_if_in_progress(run_dir, f"restart --slip {slip}")
    entry = fork_entry(run_dir, slip)
    check_perms(perms)
    ck = read_checkpoint(run_dir / entry["checkpoint"], overrides)
    note = provenance.risk_line(ck.provenance, f"the checkpoint of slip {slip}")
    if note:
        print(note, file=sys.stderr, flush=True)
    fork_dir = run_dir / "forks" / f"slip_{slip:03d}"
    branches = [None] + list(perms)
    done = [fork_dir / branch_name(p) for p in branches if branch_status(fork_dir / branch_name(p)) == "finished"]
    if done and len(done) == len(branches) and not force:
        raise RunDirError(f"{done[0] / 'run.h5'} exists (finished); pass --force to run this fork again")
    command = restart_command(run_dir, slip, perms, overrides, duration)
    results = []
    for perm in branches:
        try:
            r = run_branch(run_dir, slip, perm, duration, overrides, live=live, quiet=quiet)
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise
            raise NoSpaceError(exc.filename or str(run_dir), f"run `{command}` again: the fork's branches are "
                               "run again (no --force needed)") from None
        if r.status == "interrupted":
            raise KeyboardInterrupt(f"interrupted: branch {r.name} of slip {slip} stopped; no pair was classified. "
                                    f"Run `{command}` again to finish the fork (no --force needed)")
        results.append(r)
    summary = pair_summary(run_dir, slip, ck.time, results)
    summary["library_differences_from_parent"] = provenance.bit_risks(ck.provenance)
    return summary


def pair_summary(run_dir: Path, slip: int, start_time: float, results: list[BranchResult]) -> dict:
    keys = ("onset_time", "static_strength", "stress_drop", "peak_velocity", "mean_velocity", "duration", "slip")
    branches = {}
    for r in results:
        branches[r.name] = {"status": r.status, "dir": r.out_dir.name, "wall_seconds": round(r.wall_seconds, 3),
                            "steps": r.steps,
                            "first_slip": {k: r.first_slip[k] for k in keys} if r.first_slip else None}
    return {"run": "../..", "slip": slip, "start_time": start_time, "branches": branches}
