"""Orchestration of `gouge run` and `gouge resume`: run directory, compaction, loading,
outputs, slip checkpoints, periodic checkpoints and clean stops."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path


from ..io import provenance
from ..io.checkpoint import read_checkpoint, remove_stale_temps
from ..config import Config, dump_config, load_config
from ..errors import ConfigError, DamagedFileError, hdf5_os_error
from ..kernels import layout as L
from ..io.layout import RunLayout
from ..io.recovery import mend_series_tail, rebuild_openable
from ..io.runwriter import RunFile
from ..io.verify import continued_problems
from ..model.fluid import COUPLING_REVISION, saved_revision
from ..model.scene import Scene
from ..driver.compaction import compaction_phase
from ..driver.phases import load_phase
from ..errors import RunDirError
from ..io.outputs import is_no_space, remove_temps, require_space
from ..io.rundir import SPACE_MARGIN, check_run_dir, open_run_file, prepare_run_dir, restart_command, RunLock
from ..driver.simulation import Simulation
from ..errors import PhysicsError


@dataclass
class RunResult:
    out_dir: Path
    status: str
    steps: int
    wall_seconds: float
    grain_steps_per_second: float
    simulation: Simulation
    slips: list


def default_run_dir(config: Config, runs_root: Path = Path("runs")) -> Path:
    return runs_root / config.name


def _drive(sim: Simulation, writer: RunFile, out_dir: Path, *, live=None, quiet=False, label="loading",
           resume_from=None) -> RunResult:
    """Compaction (if the state is still compacting) then loading to the run's end; closes the
    run file with the final status. `resume_from`: the checkpoint the state came from (put back,
    callback states and run file, by the phase it was written in: driver.phase.Phase.restore)."""
    config = sim.config
    t_start = time.perf_counter()
    n, steps0 = sim.state.n, sim.state.step
    recorder = None
    try:
        if sim.phase == L.COMPACTION:
            settling = compaction_phase(sim, out_dir, live, quiet, resume_from)     # (ends with the fluid started)
            writer.set_attr("compaction_settled", bool(settling.settled))
            if not settling.settled:
                print(f"warning: compaction did not settle within compaction.max_time = "
                      f"{config.compaction.max_time:g} t0 (top wall or grains still moving); loading starts "
                      "anyway. Raise compaction.max_time, or compaction.damping, for a settled start.",
                      file=sys.stderr, flush=True)
            if sim.gpu_fallback:
                print(f"note: {sim.gpu_fallback}", file=sys.stderr, flush=True)
            writer.set_attrs({"load_start_time": sim.state.time, "end_time": sim.state.time + config.run.duration})
            writer.append(sim.observe())
            writer.snapshot(sim)
            resume_from = None
        end_time = float(writer.h5.attrs["end_time"])
        status, recorder = load_phase(sim, writer, out_dir, end_time, live=live, quiet=quiet, label=label,
                                      resume_from=resume_from)
    except KeyboardInterrupt:
        status = "interrupted"
    except PhysicsError as err:
        writer.close(f"failed: {err}", provenance.sim_hash(sim))
        raise
    except (OSError, RuntimeError) as err:      # e.g. the disk is full (rundir.ensure_space): stop cleanly
        raise stopped_by_os_error(writer, err) from None
    writer.close(status, provenance.sim_hash(sim))
    wall = time.perf_counter() - t_start
    steps = sim.state.step - steps0
    return RunResult(out_dir, status, steps, wall, steps * n / max(wall, 1e-9), sim,
                     recorder.slips if recorder else [])


def stopped_by_os_error(writer: RunFile, err: BaseException) -> BaseException:
    """A file operation failed while a run or branch went (e.g. a full disk): close its run file
    with status 'failed: <cause>' (not 'finished', so it is run or resumed again) and return the
    OSError to raise; ``err`` itself when it is no file error."""
    cause = err if isinstance(err, OSError) else hdf5_os_error(err, str(writer.path))
    if cause is None:
        return err
    try:
        writer.close(f"failed: {cause.strerror or cause}", full_disk=is_no_space(cause))      # (ENOSPC or a quota)
    except (OSError, RuntimeError):
        pass
    return cause


def _new_run(scene: Scene | Config, out_dir: Path, live, quiet, label) -> RunResult:
    """Write config.yaml and a fresh run.h5 into out_dir (locked by the caller) and drive it
    (a Config is checked into its Scene first: nothing is written for one that cannot run)."""
    scene = scene if isinstance(scene, Scene) else Scene(scene)
    RunLayout(out_dir).config_file.write_text(dump_config(scene.config))
    sim = Simulation(scene)
    return _drive(sim, _fresh_run_file(sim, out_dir), out_dir, live=live, quiet=quiet, label=label)


def _fresh_run_file(sim: Simulation, out_dir: Path) -> RunFile:
    """A new run.h5 (attributes only), flushed to disk at once."""
    writer = RunFile(RunLayout(out_dir).run_file, sim.config, sim.dt,
                     extra_attrs={"n_grains": sim.state.n, "width": sim.state.width,
                                  "wall_mass_per_length": sim.wall_mass_per_length}, threads=sim.threads)
    writer.flush()
    return writer


def run_scene(config: Config, out_dir: Path, force: bool = False, live: bool | None = None,
              quiet: bool = False, confirm=None) -> RunResult:
    """Compact, then load for config.run.duration, writing out_dir/{config.yaml, run.h5,
    checkpoints/}. The config is checked whole (preflight) and the directory locked before
    anything is written. Ctrl-C stops cleanly (status 'interrupted', outputs flushed).
    ``confirm(note)``: asked before a long run (preflight's note) starts; False refuses it
    (ConfigError) with nothing written."""
    out_dir = Path(out_dir)
    scene = Scene(config)
    pre = scene.preflight
    if pre.note and confirm is not None and not confirm(pre.note):
        raise ConfigError(f"not started (nothing was written): {pre.note.removeprefix('note: ')}")
    for line in (pre.note, pre.warning):
        if line:
            print(line, file=sys.stderr, flush=True)
    require_space(out_dir, start_bytes(config), f"the start of run {config.name}",
                  "run the same `gouge run` again (nothing was written)")
    with prepare_run_dir(out_dir, force):
        return _new_run(scene, out_dir, live, quiet, f"loading {config.name}")


def start_bytes(config: Config) -> float:
    """Bytes a run needs free to start (its first files and the room driver.phases keeps for its
    checkpoints): HDF5 then never meets a full disk while the run can still stop cleanly."""
    return 2.0 * (config.slips.ring + 2) * STATE_BYTES_PER_GRAIN * config.packing.n_grains + SPACE_MARGIN


STATE_BYTES_PER_GRAIN = 110     # driver.phases.state_bytes of a dry state, about (104 measured), plus a fluid grid's share


def resume_run(run_dir: Path, live: bool | None = None, quiet: bool = False) -> RunResult:
    """Continue an interrupted run from checkpoints/latest.h5 (compaction or loading); rows,
    snapshots and catalog entries written after that checkpoint are dropped and produced
    again. A run killed before its first checkpoint starts again from its config.yaml."""
    run_dir = check_run_dir(run_dir)
    layout = RunLayout(run_dir)
    with RunLock(run_dir, "gouge resume"):
        latest = layout.latest
        remove_stale_temps(latest)
        remove_temps(layout.run_file)       # of a close cut short (RunFile._close: a copy renamed when complete)
        if not latest.is_file():
            _refuse_branch(run_dir)
            if not layout.config_file.is_file():
                raise RunDirError(f"{run_dir} has neither checkpoints/latest.h5 nor config.yaml; start it again "
                                  "with `gouge run ... --force`")
            config = load_config(layout.config_file)
            return _new_run(config, run_dir, live, quiet, f"resume {config.name}")
        ck = read_checkpoint(latest)
        require_space(run_dir, start_bytes(ck.config), f"resuming {run_dir}", f"`gouge resume {run_dir}`")
        note = provenance.risk_line(ck.provenance, f"{latest}")
        if note:
            print(note, file=sys.stderr, flush=True)
        if ck.fluid and saved_revision(ck.fluid) != COUPLING_REVISION:
            print(f"note: {latest} was written by coupling revision {saved_revision(ck.fluid)}; the run continues "
                  f"on revision {COUPLING_REVISION} (docs: physics/fluid, 'The wall planes'), so its wet results mix "
                  "the two: run it again from its config for one revision's", file=sys.stderr, flush=True)
        sim = Simulation(ck.config, arrays=ck.state, fluid_arrays=ck.fluid)
        if sim.phase == L.COMPACTION:       # run.h5 holds nothing but its attributes yet: written anew
            writer = _fresh_run_file(sim, run_dir)
        else:
            with open_run_file(layout.run_file) as h5:
                if str(h5.attrs["status"]) == "finished":
                    raise RunDirError(f"{run_dir} already finished; nothing to resume")
            count = ck.header.slips
            mended = mend_series_tail(layout.run_file, ck.header.series_tail)
            if mended:
                print(f"mended the series' last chunk in {len(mended)} column(s) ({', '.join(mended[:3])}"
                      f"{', ...' if len(mended) > 3 else ''}): its checksum was stale after the stop, its rows "
                      f"up to the checkpoint match the checkpoint's record", file=sys.stderr, flush=True)
            if _refuse_damaged(layout.run_file, ck.time, ck.step, count):
                rebuild_openable(layout.run_file, f"`gouge resume {run_dir}`")
                print(f"rebuilt {layout.run_file} without what could not be opened after the checkpoint (a snapshot "
                      "or slip whose write the stop cut short)", file=sys.stderr, flush=True)
            writer = RunFile(layout.run_file, ck.config, sim.dt, mode="a", threads=sim.threads)
            writer.set_attr("status", "running")        # (cut back to the checkpoint by load_phase: Phase.restore)
        return _drive(sim, writer, run_dir, live=live, quiet=quiet, label=f"resume {ck.config.name}",
                      resume_from=ck)


def _refuse_branch(run_dir: Path) -> None:
    """RunDirError naming the `gouge restart` that finishes a fork branch (branches are run again,
    not resumed: they keep no checkpoints, and an interrupted one may have no run.h5 yet)."""
    branch = RunLayout(run_dir.resolve()).fork_branch()
    if branch is None:
        return
    parent, slip, perm = branch
    command = restart_command(parent, slip, [perm] if perm is not None else [])
    raise RunDirError(f"{run_dir} is a fork branch, which is run again rather than resumed: run `{command}` "
                      "(it runs the fork's unfinished branches; no --force needed)")


def _refuse_damaged(path: Path, time: float, step: int, slips: int) -> bool:
    """DamagedFileError naming what is damaged in the part of run.h5 a resume keeps (nothing is
    run); else whether a snapshot or slip after the checkpoint cannot be opened (rebuild_openable)."""
    damaged, dropped = continued_problems(path, time, step, slips)
    if damaged:
        listed = ", ".join(p.object + (f" rows {p.rows[0]}-{p.rows[1]}" if p.rows else "") for p in damaged[:3])
        more = f" and {len(damaged) - 3} more" if len(damaged) > 3 else ""
        raise DamagedFileError(f"{path} holds damaged data before the checkpoint the run would continue from "
                               f"({listed}{more}), so nothing was resumed; `gouge verify {path.parent}` says what "
                               "recomputes it")
    return any(p.unopened for p in dropped)


__all__ = ["RunResult", "default_run_dir", "run_scene", "resume_run", "stopped_by_os_error"]
