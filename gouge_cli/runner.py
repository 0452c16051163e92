"""Orchestration of `gouge run` and `gouge resume`: run directory, compaction, loading,
outputs, slip checkpoints, periodic checkpoints and clean stops."""

from __future__ import annotations

import math
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import h5py

from . import provenance
from .checkpoint import CheckpointError, read_checkpoint, snapshot_of, write_checkpoint
from .config import Config, dump_config
from .events import SlipRecorder
from .guards import guard_callbacks
from .kernels.step import W_VX
from .output import RunFile
from .progress import ProgressReport
from .simulation import Every, PhysicsError, Simulation


class RunDirError(ValueError):
    """The run directory cannot be used (exists with results, or is not a run)."""


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


def prepare_run_dir(out_dir: Path, force: bool = False) -> Path:
    out_dir = Path(out_dir)
    if (out_dir / "run.h5").exists() and not force:
        raise RunDirError(f"{out_dir} already holds a run (run.h5); choose another --out, "
                          "another name (--set name=...), or pass --force to overwrite it")
    out_dir.mkdir(parents=True, exist_ok=True)
    for stale in ("checkpoints", "forks", "figures"):     # they belonged to the run being replaced
        if (out_dir / stale).is_dir():
            shutil.rmtree(out_dir / stale)
    return out_dir


def check_run_dir(run_dir: Path) -> Path:
    run_dir = Path(run_dir)
    if not (run_dir / "run.h5").is_file():
        raise RunDirError(f"{run_dir} is not a gouge run directory (no run.h5 in it)")
    return run_dir


def latest_run(runs_root: Path = Path("runs")) -> Path:
    """The most recently modified run directory under runs_root."""
    candidates = [p.parent for p in runs_root.glob("*/run.h5")]
    if not candidates:
        raise RunDirError(f"no runs under {runs_root}/; run `gouge run CONFIG` first or name the run directory")
    return max(candidates, key=lambda p: (p / "run.h5").stat().st_mtime)


def load_phase(sim: Simulation, writer: RunFile, out_dir: Path, end_time: float, *, live=None,
               quiet=False, label="loading", recorder_state: dict | None = None,
               checkpoints: bool = True, stop_after_slip: bool = False) -> tuple[str, SlipRecorder]:
    """Shear until sim time reaches end_time, firing the output, guard, slip and checkpoint
    callbacks. Returns (status, recorder); raises PhysicsError after recording it."""
    config = sim.config
    ck_dir = out_dir / "checkpoints" if checkpoints else None
    recorder = SlipRecorder(config, sim, writer, ck_dir, recorder_state)
    progress = None if quiet else ProgressReport(label, end_time - sim.state.time, sim.state.n, live=live)
    t_begin = sim.state.time
    stop = {"now": False}

    def record(s: Simulation):
        row = s.observe()
        writer.append(row)
        slip = recorder.observe(row)
        if slip is not None and stop_after_slip:
            stop["now"] = True
        if progress:
            progress.update(s.state.time - t_begin, s.state.step,
                            info=f"tau/sigma {row['tau_over_sigma']:.3f}, slips {recorder.count}")

    def latest(s: Simulation):
        if ck_dir is not None:
            writer.flush()
            write_checkpoint(ck_dir / "latest.h5", snapshot_of(s, {"slip_recorder": recorder.state_dict()}))

    callbacks = guard_callbacks(sim) + slip_frame_callbacks(sim, writer, recorder) + [
                 Every(sim.steps_for(config.output.series_interval), record),
                 Every(sim.steps_for(config.output.snapshot_interval), writer.snapshot),
                 Every(recorder.ring_every, recorder.keep),
                 Every(sim.steps_for(config.output.checkpoint_interval), latest)]
    status = "finished"
    try:
        if sim.state.time < end_time:
            sim.run(end_time - sim.state.time, callbacks, should_stop=lambda: stop["now"])
        latest(sim)
    except KeyboardInterrupt:
        status = "interrupted"
        latest(sim)
    except PhysicsError as err:
        writer.close(f"failed: {err}")
        raise
    finally:
        if progress:
            progress.close()
    return status, recorder


def slip_frame_callbacks(sim: Simulation, writer: RunFile, recorder: SlipRecorder) -> list[Every]:
    """Dense snapshots while the top wall slips: output.slip_frames per predicted slip duration
    pi sqrt(m_b/k) (thesis Eq. 3), written whenever v_w >= slips.end_factor V_s; none if 0."""
    frames = sim.config.output.slip_frames
    if not frames or sim.wall_mass_per_length <= 0:
        return []
    period = math.pi * math.sqrt(sim.wall_mass_per_length / sim.config.loading.spring_constant)
    writer.set_attr("snapshot_dense_interval", period / frames)

    def dense(s: Simulation):
        if s.state.wall[W_VX] >= recorder.lo:
            writer.snapshot(s)

    return [Every(sim.steps_for(period / frames), dense)]


def run_scene(config: Config, out_dir: Path, force: bool = False, live: bool | None = None,
              quiet: bool = False) -> RunResult:
    """Compact, then load for config.run.duration, writing out_dir/{config.yaml, run.h5,
    checkpoints/}. Ctrl-C stops cleanly (status 'interrupted', outputs flushed)."""
    out_dir = prepare_run_dir(out_dir, force)
    (out_dir / "config.yaml").write_text(dump_config(config))
    t_start = time.perf_counter()
    sim = Simulation(config)
    writer = RunFile(out_dir / "run.h5", config, sim.dt,
                     extra_attrs={"n_grains": sim.state.n, "width": sim.state.width,
                                  "wall_mass_per_length": sim.wall_mass_per_length}, threads=sim.threads)
    n, steps0 = sim.state.n, sim.state.step
    try:
        progress = None if quiet else ProgressReport("compaction", config.compaction.max_time, n, live=live)
        try:
            sim.compact(on_chunk=(lambda s, el: progress.update(el, s.state.step)) if progress else None)
        finally:
            if progress:
                progress.close()
        sim.start_fluid()
        writer.set_attr("compaction_settled", bool(sim.compaction_settled))
        if not sim.compaction_settled:
            print(f"warning: compaction did not settle within compaction.max_time = {config.compaction.max_time:g} t0 "
                  "(top wall or grains still moving); loading starts anyway. Raise compaction.max_time, or "
                  "compaction.damping, for a settled start.", file=sys.stderr, flush=True)
        writer.set_attr("load_start_time", sim.state.time)
        writer.set_attr("end_time", sim.state.time + config.run.duration)
        writer.append(sim.observe())
        writer.snapshot(sim)
        status, recorder = load_phase(sim, writer, out_dir, sim.state.time + config.run.duration,
                                      live=live, quiet=quiet, label=f"loading {config.name}")
    except KeyboardInterrupt:
        status, recorder = "interrupted", None
    except PhysicsError as err:
        writer.close(f"failed: {err}", provenance.sim_hash(sim))
        raise
    writer.close(status, provenance.sim_hash(sim))
    wall = time.perf_counter() - t_start
    steps = sim.state.step - steps0
    return RunResult(out_dir, status, steps, wall, steps * n / max(wall, 1e-9), sim,
                     recorder.slips if recorder else [])


def resume_run(run_dir: Path, live: bool | None = None, quiet: bool = False) -> RunResult:
    """Continue an interrupted run from checkpoints/latest.h5; rows, snapshots and catalog
    entries written after that checkpoint are dropped and produced again."""
    run_dir = check_run_dir(run_dir)
    latest = run_dir / "checkpoints" / "latest.h5"
    if not latest.is_file():
        raise RunDirError(f"{run_dir} has no checkpoints/latest.h5 (it stopped before loading began); "
                          "start it again with `gouge run ... --force`")
    ck = read_checkpoint(latest)
    with h5py.File(run_dir / "run.h5", "r") as h5:
        end_time = float(h5.attrs["end_time"])
        status = str(h5.attrs["status"])
    if status == "finished":
        raise RunDirError(f"{run_dir} already finished; nothing to resume")
    note = provenance.risk_line(ck.provenance, f"{latest}")
    if note:
        print(note, file=sys.stderr, flush=True)
    t_start = time.perf_counter()
    sim = Simulation(ck.config, arrays=ck.state, fluid_arrays=ck.fluid)
    rec_state = ck.extra.get("slip_recorder", {})
    writer = RunFile(run_dir / "run.h5", ck.config, sim.dt, mode="a", threads=sim.threads)
    writer.truncate_after(ck.time, ck.step, int(rec_state.get("count", 0)))
    writer.set_attr("status", "running")
    steps0 = sim.state.step
    try:
        status, recorder = load_phase(sim, writer, run_dir, end_time, live=live, quiet=quiet,
                                      label=f"resume {ck.config.name}", recorder_state=rec_state)
    except KeyboardInterrupt:
        status, recorder = "interrupted", None
    writer.close(status, provenance.sim_hash(sim))
    wall = time.perf_counter() - t_start
    steps = sim.state.step - steps0
    return RunResult(run_dir, status, steps, wall, steps * sim.state.n / max(wall, 1e-9), sim,
                     recorder.slips if recorder else [])


__all__ = ["RunDirError", "RunResult", "run_scene", "resume_run", "load_phase", "latest_run",
           "check_run_dir", "CheckpointError"]
