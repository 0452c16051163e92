"""Orchestration of `gouge run` and `gouge resume`: run directory, compaction, loading,
outputs, slip checkpoints, periodic checkpoints and clean stops."""

from __future__ import annotations

import json
import math
import signal
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path


from . import provenance
from .checkpoint import CheckpointError, read_checkpoint, remove_stale_temps, snapshot_of, write_checkpoint
from .config import Config, ConfigError, dump_config, load_config
from .errors import hdf5_os_error
from .events import SlipRecorder
from .guards import guard_callbacks
from .kernels import step as K
from .output import RunFile
from .preflight import check_config
from .progress import ProgressReport, SettleReport
from .rundir import (RunDirError, RunLock, check_run_dir, ensure_space, latest_run, open_run_file,
                     prepare_run_dir)
from .simulation import Every, PhysicsError, Simulation


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


def load_phase(sim: Simulation, writer: RunFile, out_dir: Path, end_time: float, *, live=None,
               quiet=False, label="loading", resume_from=None,
               checkpoints: bool = True, stop_after_slip: bool = False) -> tuple[str, SlipRecorder]:
    """Shear until sim time reaches end_time, firing the output, guard, slip and checkpoint
    callbacks. `resume_from`: the Checkpoint (latest.h5) whose callback states (slip
    recorder with its ring, energy guard) carry on. Returns (status, recorder); raises
    PhysicsError after recording it."""
    config = sim.config
    ck_dir = out_dir / "checkpoints" if checkpoints else None
    saved = resume_from.extra if resume_from is not None else {}
    recorder = SlipRecorder(config, sim, writer, ck_dir, saved.get("slip_recorder"),
                            resume_from.attached if resume_from is not None else None)
    guards = guard_callbacks(sim)
    guards[0].action.load_state_dict(saved.get("guards", {}))
    scaling = None
    if config.numerics.stick_scaling > 1.0:     # stick scaling: the controller (sets the inertia)
        from .stick_scaling import StickScaling
        try:
            scaling = StickScaling(config, sim, saved.get("stick_scaling"), quiet=quiet)
        except ConfigError as err:
            writer.close(f"refused: {err}", provenance.sim_hash(sim))
            raise
    progress = None if quiet else ProgressReport(label, end_time - sim.state.time, sim.state.n, live=live)
    t_begin = sim.state.time
    stop = {"now": False}

    need = 2.0 * (config.slips.ring + 2) * _state_bytes(sim)

    def record(s: Simulation):
        ensure_space(out_dir, need)
        row = s.observe()
        if scaling is not None:                 # stick scaling: lambda, I (and De) columns
            row.update(scaling.columns(s, row))
        writer.append(row)
        slip = recorder.observe(row)
        if scaling is not None and scaling.after_row(s, row, recorder, writer, guards[0].action):
            return                              # stick scaling: went back to a pre-slip state
        if slip is not None and stop_after_slip:
            stop["now"] = True
        if progress:
            progress.update(s.state.time - t_begin, s.state.step,
                            info=f"tau/sigma {row['tau_over_sigma']:.3f}, slips {recorder.count}")

    def latest(s: Simulation):
        if ck_dir is not None:
            writer.flush()
            rec_state, ring = recorder.full_state()
            extra = {"phase": "loading", "slip_recorder": rec_state, "guards": guards[0].action.state_dict()}
            if scaling is not None:             # stick scaling: its state
                extra["stick_scaling"] = scaling.state_dict()
            write_checkpoint(ck_dir / "latest.h5", snapshot_of(s, extra, ring))

    def keep(s: Simulation):                    # stick scaling: ring states carry the energy guard's history
        recorder.keep(s, {"guards": guards[0].action.state_dict()})

    def build() -> list[Every]:
        """The callbacks; their periods are step counts, so stick scaling rebuilds them when dt changes."""
        recorder.ring_every = sim.steps_for(recorder.lead / 4.0)
        return guards + slip_frame_callbacks(sim, writer, recorder) + [
                 Every(sim.steps_for(config.output.series_interval), record),
                 Every(sim.steps_for(config.output.snapshot_interval), writer.snapshot),
                 Every(recorder.ring_every, recorder.keep if scaling is None else keep),
                 Every(sim.steps_for(config.output.checkpoint_interval), latest)]
    status = "finished"
    try:
        with _deferred_interrupt() as interrupted:
            if sim.state.time < end_time and scaling is not None:
                scaling.run(sim, end_time, build, should_stop=lambda: stop["now"] or interrupted())
            elif sim.state.time < end_time:
                sim.run(end_time - sim.state.time, build(), should_stop=lambda: stop["now"] or interrupted())
            if interrupted():
                status = "interrupted"
            latest(sim)
    except KeyboardInterrupt:       # a second Ctrl-C, or one outside the step loop
        status = "interrupted"
        latest(sim)
    except PhysicsError as err:
        writer.close(f"failed: {err}", provenance.sim_hash(sim))
        raise
    finally:
        if progress:
            progress.close()
    if scaling is not None:
        recorder.stick_scaling = scaling        # stick scaling: counts for reports and the ladder
        writer.set_attr("stick_scaling_counts", json.dumps(scaling.state_dict()))
        if not quiet:
            print(scaling.summary(), file=sys.stderr, flush=True)
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
        if s.state.wall[K.W_VX] >= recorder.lo:
            writer.snapshot(s)

    return [Every(sim.steps_for(period / frames), dense)]


@contextmanager
def _deferred_interrupt():
    """Ctrl-C (SIGINT) sets a flag that the step loop reads between chunks, after every
    callback of the current step has run, so that the checkpoint written on stopping lines up
    with the series (an interrupt inside a callback could lose a row). A second Ctrl-C
    interrupts at once. Yields a function telling whether Ctrl-C was pressed."""
    flag = {"set": False}
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = signal.getsignal(signal.SIGINT)
    previous = signal.default_int_handler if previous is None else previous

    def handler(signum, frame):
        flag["set"] = True
        signal.signal(signal.SIGINT, previous)

    signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: flag["set"]
    finally:
        signal.signal(signal.SIGINT, previous)


def _state_bytes(sim: Simulation) -> int:
    """Bytes of one checkpointed state (grains, contacts, fluid grid)."""
    fluid = sim.fluid.arrays() if sim.fluid is not None else {}
    return sum(a.nbytes for a in sim.state.arrays().values()) + sum(a.nbytes for a in fluid.values())


def compaction_phase(sim: Simulation, out_dir: Path, live=None, quiet=False,
                     start: tuple[float, int] | None = None):
    """Simulation.compact with checkpoints/latest.h5 written every output.checkpoint_interval of
    compaction (on its 100 t0 checks) and on Ctrl-C, so that `gouge resume` continues a
    compaction too. Progress is shown toward the settling criterion (progress.SettleReport)."""
    config = sim.config
    latest = out_dir / "checkpoints" / "latest.h5"
    chunk = sim.steps_for(100.0)
    every = max(1, int(round(config.output.checkpoint_interval / 100.0)))

    need = 2.0 * _state_bytes(sim)

    def save(s: Simulation):
        ensure_space(out_dir, need)
        write_checkpoint(latest, snapshot_of(s, {"phase": "compaction", "compaction_start": list(s.compaction_start)}))

    progress = None if quiet else SettleReport(config.compaction.max_time, sim.state.n, live=live)

    def on_chunk(s: Simulation, elapsed: float):
        if progress:
            progress.update(s.settling, s.state.step)
        if ((s.state.step - s.compaction_start[1]) // chunk) % every == 0:
            save(s)

    try:
        sim.compact(on_chunk=on_chunk, start=start)
    except KeyboardInterrupt:
        if sim.compaction_start is not None:
            save(sim)
        raise
    finally:
        if progress:
            progress.close()


def _drive(sim: Simulation, writer: RunFile, out_dir: Path, *, live=None, quiet=False, label="loading",
           resume_from=None) -> RunResult:
    """Compaction (if the state is still compacting) then loading to the run's end; closes the
    run file with the final status. `resume_from`: the checkpoint the state came from."""
    config = sim.config
    t_start = time.perf_counter()
    n, steps0 = sim.state.n, sim.state.step
    recorder = None
    try:
        if sim.phase == K.COMPACTION:
            start = None
            if resume_from is not None and "compaction_start" in resume_from.extra:
                t0, step0 = resume_from.extra["compaction_start"]
                start = (float(t0), int(step0))
            compaction_phase(sim, out_dir, live, quiet, start)
            sim.start_fluid()
            writer.set_attr("compaction_settled", bool(sim.compaction_settled))
            if not sim.compaction_settled:
                print(f"warning: compaction did not settle within compaction.max_time = "
                      f"{config.compaction.max_time:g} t0 (top wall or grains still moving); loading starts "
                      "anyway. Raise compaction.max_time, or compaction.damping, for a settled start.",
                      file=sys.stderr, flush=True)
            writer.set_attr("load_start_time", sim.state.time)
            writer.set_attr("end_time", sim.state.time + config.run.duration)
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
        cause = hdf5_os_error(err, str(writer.path)) if not isinstance(err, OSError) else err
        if cause is None:
            raise
        try:
            writer.close(f"failed: {cause.strerror or cause}")
        except (OSError, RuntimeError):
            pass
        raise cause from None
    writer.close(status, provenance.sim_hash(sim))
    wall = time.perf_counter() - t_start
    steps = sim.state.step - steps0
    return RunResult(out_dir, status, steps, wall, steps * n / max(wall, 1e-9), sim,
                     recorder.slips if recorder else [])


def _new_run(config: Config, out_dir: Path, live, quiet, label) -> RunResult:
    """Write config.yaml and a fresh run.h5 into out_dir (locked by the caller) and drive it."""
    (out_dir / "config.yaml").write_text(dump_config(config))
    sim = Simulation(config)
    return _drive(sim, _fresh_run_file(sim, out_dir), out_dir, live=live, quiet=quiet, label=label)


def _fresh_run_file(sim: Simulation, out_dir: Path) -> RunFile:
    """A new run.h5 (attributes only), flushed to disk at once."""
    writer = RunFile(out_dir / "run.h5", sim.config, sim.dt,
                     extra_attrs={"n_grains": sim.state.n, "width": sim.state.width,
                                  "wall_mass_per_length": sim.wall_mass_per_length}, threads=sim.threads)
    writer.flush()
    return writer


def run_scene(config: Config, out_dir: Path, force: bool = False, live: bool | None = None,
              quiet: bool = False) -> RunResult:
    """Compact, then load for config.run.duration, writing out_dir/{config.yaml, run.h5,
    checkpoints/}. The config is checked whole (preflight) and the directory locked before
    anything is written. Ctrl-C stops cleanly (status 'interrupted', outputs flushed)."""
    out_dir = Path(out_dir)
    pre = check_config(config, Simulation._choose_threads(config.numerics.threads, config.packing.n_grains))
    if pre.note:
        print(pre.note, file=sys.stderr, flush=True)
    with prepare_run_dir(out_dir, force):
        return _new_run(config, out_dir, live, quiet, f"loading {config.name}")


def resume_run(run_dir: Path, live: bool | None = None, quiet: bool = False) -> RunResult:
    """Continue an interrupted run from checkpoints/latest.h5 (compaction or loading); rows,
    snapshots and catalog entries written after that checkpoint are dropped and produced
    again. A run killed before its first checkpoint starts again from its config.yaml."""
    run_dir = check_run_dir(run_dir)
    with RunLock(run_dir, "gouge resume"):
        latest = run_dir / "checkpoints" / "latest.h5"
        remove_stale_temps(latest)
        if not latest.is_file():
            if not (run_dir / "config.yaml").is_file():
                raise RunDirError(f"{run_dir} has neither checkpoints/latest.h5 nor config.yaml; start it again "
                                  "with `gouge run ... --force`")
            config = load_config(run_dir / "config.yaml")
            return _new_run(config, run_dir, live, quiet, f"resume {config.name}")
        ck = read_checkpoint(latest)
        note = provenance.risk_line(ck.provenance, f"{latest}")
        if note:
            print(note, file=sys.stderr, flush=True)
        sim = Simulation(ck.config, arrays=ck.state, fluid_arrays=ck.fluid)
        if sim.phase == K.COMPACTION:       # run.h5 holds nothing but its attributes yet: written anew
            writer = _fresh_run_file(sim, run_dir)
        else:
            with open_run_file(run_dir / "run.h5") as h5:
                if str(h5.attrs["status"]) == "finished":
                    raise RunDirError(f"{run_dir} already finished; nothing to resume")
            rec_state = ck.extra.get("slip_recorder", {})
            writer = RunFile(run_dir / "run.h5", ck.config, sim.dt, mode="a", threads=sim.threads)
            writer.truncate_after(ck.time, ck.step, int(rec_state.get("count", 0)))
            writer.set_attr("status", "running")
        return _drive(sim, writer, run_dir, live=live, quiet=quiet, label=f"resume {ck.config.name}",
                      resume_from=ck)


__all__ = ["RunDirError", "RunResult", "run_scene", "resume_run", "load_phase", "latest_run",
           "check_run_dir", "CheckpointError", "compaction_phase"]
