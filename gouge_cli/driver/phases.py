"""The two phases of a run as the driver runs them, each with its callbacks and checkpoints:
compaction (Simulation.compact, latest.h5 on its checks) and loading (Simulation.run with the
guards, series and snapshot writers, slip recorder, dense slip frames and the latest.h5
checkpointer, whose states travel in the checkpoint). Used by `gouge run/resume`, forks and the
accuracy study alike."""

from __future__ import annotations

import json
import signal
import sys
import threading
from contextlib import contextmanager
from pathlib import Path

from ..io import provenance
from ..io.checkpoint import snapshot_of, write_checkpoint
from ..io.layout import RunLayout
from ..io.rundir import ensure_space
from ..io.runfile import RunFile
from ..kernels import layout as L
from ..model.timestep import slip_duration
from .guards import guard_callbacks
from .progress import ProgressReport, SettleReport
from ..errors import ConfigError, PhysicsError
from .schedules import Every
from .simulation import Simulation
from .slips import SlipRecorder


def load_phase(sim: Simulation, writer: RunFile, out_dir: Path, end_time: float, *, live=None,
               quiet=False, label="loading", resume_from=None,
               checkpoints: bool = True, stop_after_slip: bool = False) -> tuple[str, SlipRecorder]:
    """Shear until sim time reaches end_time, firing the output, guard, slip and checkpoint
    callbacks. `resume_from`: the Checkpoint (latest.h5) whose callback states (slip
    recorder with its ring, energy guard) carry on. Returns (status, recorder); raises
    PhysicsError after recording it."""
    config = sim.config
    layout = RunLayout(out_dir) if checkpoints else None
    saved = resume_from.extra if resume_from is not None else {}
    recorder = SlipRecorder(config, sim, writer, layout, saved.get("slip_recorder"),
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

    need = 2.0 * (config.slips.ring + 2) * state_bytes(sim)

    def record(s: Simulation):
        ensure_space(out_dir, need)
        row = s.measure()               # (the guards' row when they ran on this step)
        if scaling is not None:                 # stick scaling: lambda, I (and De) columns
            row.update(scaling.columns(s, row))
        writer.append(row)
        slip = recorder.observe(row)
        if scaling is not None and scaling.after_row(s, row, recorder, writer, guards[0].action, slip):
            return                              # stick scaling: went back to a pre-slip state
        if slip is not None and stop_after_slip:
            stop["now"] = True
        if progress:
            progress.update(s.state.time - t_begin, s.state.step,
                            info=f"tau/sigma {row['tau_over_sigma']:.3f}, slips {recorder.count}")

    def latest(s: Simulation):
        if layout is not None:
            writer.flush()
            rec_state, ring = recorder.full_state()
            extra = {"phase": "loading", "slip_recorder": rec_state, "guards": guards[0].action.state_dict()}
            if scaling is not None:             # stick scaling: its state
                scaling.tally(s)
                extra["stick_scaling"] = scaling.state_dict()
            write_checkpoint(layout.latest, snapshot_of(s, extra, ring))

    def keep(s: Simulation):                    # stick scaling: ring states carry the energy guard's history
        recorder.keep(s, {"guards": guards[0].action.state_dict()})

    # callback order on a step where several are due: guards, slip_frames, series (+ slip detector,
    # progress), snapshots, ring (pre-slip states), checkpoint (latest.h5 with the guards' and the
    # slip recorder's states)
    def build() -> list[Every]:
        """The callbacks; their periods are step counts, so stick scaling rebuilds them when dt changes."""
        recorder.ring_every = recorder.ring_steps(sim)
        return guards + slip_frame_callbacks(sim, writer, recorder) + [
                 Every.t0(sim, config.output.series_interval, record, "series"),
                 Every.t0(sim, config.output.snapshot_interval, writer.snapshot, "snapshots"),
                 Every(recorder.ring_every, recorder.keep if scaling is None else keep, "ring"),
                 Every.t0(sim, config.output.checkpoint_interval, latest, "checkpoint")]
    status = "finished"
    try:
        with deferred_interrupt() as interrupted:
            if sim.state.time < end_time:       # stick scaling changes the step: callbacks rebuilt
                sim.run(end_time - sim.state.time, build if scaling is not None else build(),
                        should_stop=lambda: stop["now"] or interrupted())
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
        scaling.tally(sim)
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
    period = slip_duration(sim.config, sim.wall_mass_per_length)
    writer.set_attr("snapshot_dense_interval", period / frames)

    def dense(s: Simulation):
        if s.state.wall[L.W_VX] >= recorder.lo:
            writer.snapshot(s)

    return [Every.t0(sim, period / frames, dense, "slip_frames")]



@contextmanager
def deferred_interrupt():
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



def state_bytes(sim: Simulation) -> int:
    """Bytes of one checkpointed state (grains, contacts, fluid grid)."""
    fluid = sim.fluid.arrays() if sim.fluid is not None else {}
    return sum(a.nbytes for a in sim.state.arrays().values()) + sum(a.nbytes for a in fluid.values())



def compaction_phase(sim: Simulation, out_dir: Path, live=None, quiet=False,
                     start: tuple[float, int] | None = None):
    """Simulation.compact with checkpoints/latest.h5 written every output.checkpoint_interval of
    compaction (on its 100 t0 checks) and on Ctrl-C, so that `gouge resume` continues a
    compaction too. Progress is shown toward the settling criterion (progress.SettleReport)."""
    config = sim.config
    latest = RunLayout(out_dir).latest
    chunk = sim.steps_for(100.0)
    every = max(1, int(round(config.output.checkpoint_interval / 100.0)))

    need = 2.0 * state_bytes(sim)

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
