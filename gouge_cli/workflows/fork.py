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
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..analysis.pairs import MainEvent
from ..io.layout import RunLayout, branch_name
from ..io import provenance
from ..io.checkpoint import Checkpoint, read_checkpoint
from ..io.records import plain, unit
from ..config import build_config, Config
from ..errors import ConfigError, InputError, NoSpaceError, PhysicsFailure
from ..driver.slips import lead_time
from ..io.runreader import RunReader
from ..io.runwriter import RunFile
from ..io.slipcatalog import SlipEntry, slip_catalog
from ..model.scene import Scene
from ..errors import RunDirError
from ..io.outputs import remove_temps, require_space, temporary
from ..io.rundir import SPACE_MARGIN, check_run_dir, refuse_if_in_progress, restart_command, RunLock
from ..driver.phases import load_phase
from ..driver.simulation import Simulation
from .pairs import branch_status
from .run import stopped_by_os_error


MAX_BRANCH_DURATION = 1e7  # [t0] the longest branch a fork runs (--duration)
FORK_SLIP_FRAMES = 30     # snapshots per predicted slip duration while a fork slips (output.slip_frames)


def branch_config(base: Config, perm: float | None, overrides: dict | None = None) -> Config:
    data = base.to_dict()
    data["numerics"] = dict(data["numerics"], stick_scaling=1.0,     # stick scaling: forks at true inertia
                            device="cpu")                            # forks run on the cpu (a GPU run's too)
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
    first_slip: SlipEntry | None


def fork_entry(run_dir: Path, slip: int) -> SlipEntry:
    """The catalog entry of slip ``slip``; :class:`RunDirError` naming the slips with checkpoints."""
    catalog = slip_catalog(run_dir)
    numbers = [e.number for e in catalog if e.checkpoint]
    if slip not in numbers:
        listed = ", ".join(str(n) for n in numbers) or "none yet"
        raise RunDirError(f"{run_dir} has no checkpoint for slip {slip}; slips with checkpoints: {listed}")
    return next(e for e in catalog if e.number == slip)


SNAPSHOT_BYTES_PER_GRAIN = 130     # a snapshot's grains (7 float64) and about 3 contacts (2 int32, 2 float64)


def branch_bytes(config: Config) -> float:
    """Bytes a branch needs on disk, about: its dense snapshots (output.slip_frames per predicted
    slip duration over up to 6 of them, plus 4 regular ones) and the room the run keeps free for
    its in-memory slip states (driver.phases: the ring and SPACE_MARGIN)."""
    n = config.packing.n_grains
    frames = 6 * config.output.slip_frames + 4
    return frames * SNAPSHOT_BYTES_PER_GRAIN * n + 2.0 * (config.slips.ring + 2) * 200 * n + SPACE_MARGIN


def check_perms(perms) -> None:
    for perm in perms:
        if not (perm is None or (perm > 0 and math.isfinite(perm))):
            raise ConfigError(f"--perm = {perm:g}: the permeability prefactor kappa_c must be a positive number [d^2]")


@dataclass(frozen=True)
class ForkRequest:
    """One fork (`gouge restart` and :func:`gouge_cli.api.restart` both build it), checked when built
    (ConfigError naming the option).

    run_dir    the parent run directory
    slip       the slip whose pre-slip checkpoint the branches start from
    perms      kappa_c [d^2] of the undrained branches (none: the drained branch alone)
    overrides  {dotted key: value} for every branch (config.parse_overrides of the ``--set`` strings)
    duration   [t0] each branch runs from the checkpoint; None: until its first slip ends
    force      run finished branches again
    main       the event pair.json compares: 'first' (the forked slip) or 'largest'
    """

    run_dir: Path
    slip: int
    perms: tuple[float, ...] = ()
    overrides: dict[str, Any] = field(default_factory=dict)
    duration: float | None = None
    force: bool = False
    main: str = "first"

    def __post_init__(self):
        object.__setattr__(self, "run_dir", Path(self.run_dir))
        object.__setattr__(self, "perms", tuple(float(p) for p in self.perms))
        object.__setattr__(self, "overrides", dict(self.overrides or {}))
        check_perms(self.perms)
        if self.duration is not None and not (0 < self.duration <= MAX_BRANCH_DURATION):
            raise ConfigError(f"--duration = {self.duration:g}: give a positive time [t0] of at most "
                              f"{MAX_BRANCH_DURATION:g} (a branch runs one slip's checkpoint through that slip and "
                              "what follows; the study scene's whole loading is 2.5e6 t0)")
        object.__setattr__(self, "main", MainEvent.check(self.main))

    def command(self) -> str:
        """The `gouge restart` line that runs this fork (named when one stops)."""
        return restart_command(self.run_dir, self.slip, list(self.perms), self.overrides, self.duration)


def run_branch(run_dir: Path, slip: int, perm: float | None, duration: float | None = None,
               overrides: dict[str, Any] | None = None, live=None, quiet: bool = False,
               stop_after_slip: bool | None = None, checkpoint=None, command: str | None = None) -> BranchResult:
    """Run one branch (drained: ``perm=None``) of slip ``slip`` into ``RUN/forks/slip_NNN/<branch>``.

    ``duration`` [t0] from the checkpoint; None: 5 x (end - checkpoint time) + 2 leads.
    ``stop_after_slip``: stop when the branch's first slip ends (default: when ``duration`` is None).
    ``command``: the `gouge restart` line that continues this work once stopped (named to a
    second process that finds the branch locked; default: this branch's own).
    Replaces an existing branch's run.h5 only once the new one is closed (:func:`_run_branch`).
    The branch directory is locked while it runs (so branches of one run may run in parallel),
    and the run itself must not be in progress. Dense
    snapshots while the branch slips: output.slip_frames, FORK_SLIP_FRAMES unless overridden.
    ``overrides``: {dotted key: value} (config.parse_overrides).
    ``checkpoint``: the slip's checkpoint read already with these overrides (its arrays are copied
    into the branch's scene, never changed), so that a fork reads it once.
    """
    run_dir = Path(run_dir)
    refuse_if_in_progress(run_dir, f"restart --slip {slip}")
    entry = fork_entry(run_dir, slip)
    ck = checkpoint if checkpoint is not None else read_checkpoint(run_dir / entry.checkpoint, overrides)
    frames = {} if "output.slip_frames" in (overrides or {}) \
        else {"output": {"slip_frames": ck.config.output.slip_frames or FORK_SLIP_FRAMES}}
    scene = Scene(branch_config(ck.config, perm, frames))
    config = scene.config
    name = branch_name(perm)
    duration_given = duration
    if stop_after_slip is None:
        stop_after_slip = duration is None
    if duration is None:
        span = entry.end_time - ck.time
        duration = 5.0 * span + 2.0 * lead_time(ck.config)
    out_dir = RunLayout(run_dir).fork(slip).branch(perm).root
    require_space(run_dir, branch_bytes(config), f"branch {name} of slip {slip}",
                  f"run `gouge restart {run_dir} --slip {slip}` again")     # (run_fork names its command)
    out_dir.mkdir(parents=True, exist_ok=True)
    then = command or restart_command(run_dir, slip, [perm] if perm is not None else [], overrides, duration_given)
    with RunLock(out_dir, f"gouge restart --slip {slip} ({name})", then=then):
        remove_temps(RunLayout(out_dir).run_file)       # of a killed earlier try (locked: none is live)
        return _run_branch(run_dir, slip, entry, ck, scene, name, out_dir, duration, stop_after_slip, live, quiet)


def _run_branch(run_dir: Path, slip: int, entry: SlipEntry, ck: Checkpoint, scene: Scene, name: str, out_dir: Path,
                duration: float, stop_after_slip: bool, live, quiet: bool) -> BranchResult:
    """Drive the branch into a temporary file that becomes ``run.h5`` only once closed (finished,
    interrupted, or failed physically: 'failed: ...', the branch's record); a crash or a full disk
    (the error raised) leaves ``run.h5`` as it was, an earlier finished one whole (io.outputs.temporary)."""
    t0 = time.perf_counter()
    sim = Simulation(scene, arrays=ck.state)
    config = scene.config
    step0 = sim.state.step
    failure = None
    with temporary(RunLayout(out_dir).run_file) as tmp:
        writer = RunFile(tmp, config, sim.dt, extra_attrs={
            "parent_run": os.path.relpath(run_dir, out_dir), "parent_checkpoint": entry.checkpoint,
            "fork_slip": slip, "branch": name, "n_grains": sim.state.n, "width": sim.state.width,
            "wall_mass_per_length": sim.wall_mass_per_length, "load_start_time": ck.time,
            "end_time": ck.time + duration}, threads=sim.threads, safe_close=False)
        try:
            writer.append(sim.observe())
            status, recorder = load_phase(sim, writer, out_dir, ck.time + duration, live=live, quiet=quiet,
                                          label=f"slip {slip} {name}", checkpoints=False,
                                          stop_after_slip=stop_after_slip,
                                          fork_from=replace(ck, fluid={}))     # (a branch's fluid starts at P = 0)
        except PhysicsFailure as err:           # closed 'failed: ...' (load_phase): kept, then raised
            writer.close(f"failed: {err}", provenance.sim_hash(sim))
            failure = err
        except (OSError, RuntimeError) as err:  # e.g. a full disk: closed, then removed by temporary
            raise stopped_by_os_error(writer, err) from None
        else:
            writer.close(status, provenance.sim_hash(sim))
    if failure is not None:
        raise failure
    first = recorder.slips[0] if recorder.slips else None
    return BranchResult(name, out_dir, status, time.perf_counter() - t0, sim.state.step - step0, first)


def run_fork(request: ForkRequest, live=None, quiet=False) -> "ForkSummary":
    """Fork the drained branch and one undrained branch per permeability from slip ``request.slip``,
    reading its checkpoint once.

    Without ``request.force`` only the branches not finished yet are run (new permeabilities added to an
    existing fork, or a branch interrupted, stopped by a full disk or killed); the finished ones are
    kept, and a fork whose requested branches have all finished is refused.
    A branch stopped by Ctrl-C stops the fork (KeyboardInterrupt, naming the command that finishes
    it; no later branch runs); a full disk raises :class:`~gouge_cli.errors.NoSpaceError` naming it.

    Returns a :class:`ForkSummary` (each branch's status, folder, wall time, steps and first slip;
    paths relative to the fork directory)."""
    slip, perms, force = request.slip, list(request.perms), request.force
    run_dir = check_run_dir(request.run_dir)
    refuse_if_in_progress(run_dir, f"restart --slip {slip}")
    entry = fork_entry(run_dir, slip)
    ck = read_checkpoint(run_dir / entry.checkpoint, request.overrides)
    note = provenance.risk_line(ck.provenance, f"the checkpoint of slip {slip}")
    if note:
        print(note, file=sys.stderr, flush=True)
    if ck.config.numerics.device == "gpu" and not quiet:
        print("note: numerics.device = gpu: the fork's branches run on the cpu (branch_config)",
              file=sys.stderr, flush=True)
    fork = RunLayout(run_dir).fork(slip)
    fork_dir = fork.root
    names = [None] + perms
    finished = {p: branch_status(fork.branch(p).root) == "finished" for p in names}
    if all(finished.values()) and not force:
        last = fork.branch(names[-1]).run_file
        raise RunDirError(f"{last} exists (finished); pass --force to run this branch again")
    kept = [] if force else [_finished_branch(fork_dir, p) for p in names if finished[p]]
    branches = names if force else [p for p in names if not finished[p]]
    command = request.command()
    results = []
    for perm in branches:
        stopped = (f"interrupted: branch {branch_name(perm)} of slip {slip} stopped; no pair was classified. "
                   f"Run `{command}` again to finish the fork (no --force needed)")
        try:
            r = run_branch(run_dir, slip, perm, request.duration, request.overrides, live=live, quiet=quiet,
                           checkpoint=ck, command=command)
        except KeyboardInterrupt:       # Ctrl-C outside the step loop (set-up, compilation, closing)
            raise KeyboardInterrupt(stopped) from None
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise
            again = (f"`{command} --force` again: the finished branches it reruns are kept until replaced" if force
                     else f"`{command}` again: the fork's branches are run again (no --force needed)")
            raise NoSpaceError(exc.filename or str(run_dir), f"run {again}", need=getattr(exc, "need", None),
                               detail=getattr(exc, "detail", "")) from None
        if r.status == "interrupted":
            raise KeyboardInterrupt(stopped)
        results.append(r)
    with RunReader(run_dir, allow_running=True) as reader:
        origin = reader.time_offset()
    by_name = {b.name: b for b in kept + results}
    return pair_summary(slip, ck.time - origin, [by_name[branch_name(p)] for p in names], origin,
                        ck.config.loading.velocity, provenance.bit_risks(ck.provenance))


def restart(request: ForkRequest, live=None, quiet: bool = False) -> "ForkSummary":
    """`gouge restart` and :func:`gouge_cli.api.restart`: :func:`run_fork`, then, with
    permeabilities, the fork's pair.json (its record also the returned summary's ``pair``)."""
    from .pairs import write_pair_json

    fork_dir = RunLayout(request.run_dir).fork(request.slip).root
    try:
        summary = run_fork(request, live=live, quiet=quiet)
    except PhysicsFailure:
        if request.perms:        # the failed branch is reported as failed in pair.json, with its message
            try:
                write_pair_json(fork_dir, request.main)
            except (InputError, OSError):
                pass
        raise
    if request.perms:
        summary = replace(summary, pair=write_pair_json(fork_dir, request.main))
    return summary


def _finished_branch(fork_dir: Path, perm: float | None) -> BranchResult:
    """A finished branch of the fork, kept as it is (status "finished (kept)")."""
    out_dir = fork_dir / branch_name(perm)
    catalog = slip_catalog(out_dir)
    return BranchResult(branch_name(perm), out_dir, "finished (kept)", 0.0, 0, catalog[0] if catalog else None)


@dataclass(frozen=True)
class FirstSlip:
    """A branch's first slip as `gouge restart` reports it (:meth:`of` a catalog entry)."""

    onset_time: float = unit("t0", "onset, since loading began")
    duration: float = unit("t0", "slip duration")
    static_strength: float = unit("sigma", "static strength tau/sigma")
    stress_drop: float = unit("sigma", "stress drop tau/sigma")
    slip: float = unit("d", "slip distance of the top wall")
    peak_velocity_over_Vs: float = unit("V_s", "peak wall velocity")
    mean_velocity_over_Vs: float = unit("V_s", "mean wall velocity over the slip")

    @classmethod
    def of(cls, f: SlipEntry, origin: float, V_s: float) -> "FirstSlip":
        """From the detector's entry (stored clock; ``origin``: the stored clock when loading
        began) and the loading velocity ``V_s`` [v0]."""
        return cls(f.onset_time - origin, f.duration, f.static_strength, f.stress_drop, f.slip,
                   f.peak_velocity / V_s, f.mean_velocity / V_s)


@dataclass(frozen=True)
class BranchSummary:
    """One branch of a fork as `gouge restart` reports it."""

    status: str = unit("-", "finished, finished (kept), interrupted or failed: ...")
    dir: str = unit("-", "the branch's folder, relative to the fork's")
    wall_seconds: float = unit("s", "wall-clock time of the branch (0 when kept)")
    steps: int = unit("-", "time steps run")
    first_slip: FirstSlip | None = unit("-", "its first slip (None: no slip in its window)")


@dataclass(frozen=True, kw_only=True)
class ForkSummary:
    """What :func:`run_fork` returns and `gouge restart` prints (``--json``: :meth:`to_dict`): times
    in t0 since loading began, velocities in V_s, strengths and drops in tau/sigma."""

    run: str = unit("-", "the parent run, relative to the fork's folder", default="../..")
    slip: int = unit("-", "the forked slip")
    time_origin: str = unit("-", "what times count from", default="loading start")
    start_time: float = unit("t0", "the checkpoint's time, since loading began")
    branches: dict = unit("-", "{branch name: BranchSummary}, drained first")
    library_differences_from_parent: list = unit("-", "library versions that differ from the parent's "
                                                 "checkpoint (provenance.bit_risks)", default_factory=list)
    pair: dict | None = unit("-", "pair.json's record (workflows.pairs.write_pair_json), when written",
                             default=None)

    def to_dict(self) -> dict:
        """The JSON form (``pair`` only when there is one)."""
        out = plain(self)
        if self.pair is None:
            del out["pair"]
        return out


def pair_summary(slip: int, start_time: float, results: list[BranchResult], origin: float,
                 V_s: float, risks: list[str]) -> ForkSummary:
    """What `gouge restart` prints: times in t0 since loading began (``origin``: the stored clock then;
    ``start_time``: the checkpoint's), velocities in V_s, strengths and drops in tau/sigma; ``risks``:
    the library differences from the parent's checkpoint."""
    return ForkSummary(slip=slip, start_time=start_time, library_differences_from_parent=risks, branches={
        r.name: BranchSummary(r.status, r.out_dir.name, round(r.wall_seconds, 3), r.steps,
                              FirstSlip.of(r.first_slip, origin, V_s) if r.first_slip else None)
        for r in results})
