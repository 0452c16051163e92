"""The two phases of a run as the driver runs them, each with its callbacks and checkpoints:
compaction (driver.compaction: the settling check, progress and latest.h5 on its checks) and loading (Simulation.run with the
guards, series and snapshot writers, slip recorder, dense slip frames and the latest.h5
checkpointer, whose states travel in the checkpoint). Used by `gouge run/resume`, forks and the
accuracy study alike."""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager
from pathlib import Path

from ..io import provenance
from ..io.checkpoint import Checkpoint, CheckpointHeader, snapshot_of, state_bytes, write_checkpoint
from ..io.layout import RunLayout
from ..io.rundir import ensure_space
from ..io.runwriter import RunFile
from ..kernels import layout as L
from ..model.timestep import slip_duration
from .callbacks import Callback, schedules, states
from . import compaction
from .guards import Guards
from .phase import Phase
from .progress import ProgressReport
from ..errors import ConfigError, PhysicsError
from .schedules import Every
from .simulation import Simulation
from .slips import SlipRecorder, ring_attachments
from .stick_scaling import StickScaling, TrueInertia, controller


def load_phase(sim: Simulation, writer: RunFile, out_dir: Path, end_time: float, *, live=None,
               quiet=False, label="loading", resume_from: Checkpoint | None = None,
               fork_from: Checkpoint | None = None, checkpoints: bool = True,
               stop_after_slip: bool = False) -> tuple[str, SlipRecorder]:
    """Shear until sim time reaches end_time, firing the loading phase's callbacks (driver.callbacks),
    in this order on a step where several are due: guards, slip_frames, series (+ slip recorder,
    stick scaling, progress), snapshots, ring (pre-slip states, with the guards' state), checkpoint
    (latest.h5 with every callback's state under its name). `resume_from`: the Checkpoint
    (latest.h5) the run goes on from: Phase.restore puts its state back (stick scaling, guards,
    slip recorder with its ring) and cuts `writer` back to it. `fork_from`: a fork's start (the
    arrays alone, Phase.restore with states=False). Returns (status, recorder); raises
    PhysicsError after recording it."""
    config = sim.config
    layout = RunLayout(out_dir) if checkpoints else None
    guards = Guards()
    recorder = SlipRecorder(config, sim, writer, layout, kept_with=[guards])
    try:
        scaling = controller(config, sim, quiet=quiet)     # stick scaling (sets the inertia) or true inertia
    except ConfigError as err:
        writer.close(f"refused: {err}", provenance.sim_hash(sim))
        raise
    progress = None if quiet else ProgressReport(label, end_time - sim.state.time, sim.state.n, live=live)
    need = 2.0 * (config.slips.ring + 2) * state_bytes(sim)
    series = SeriesWriter(writer, recorder, scaling, progress, out_dir, need, sim.state.time, stop_after_slip)
    callbacks = [scaling, guards, SlipFrames(writer, recorder), series, Snapshots(writer), Ring(recorder)]
    keeper = CheckpointKeeper(writer, layout, callbacks, recorder)
    callbacks += [keeper, recorder]
    phase = series.phase = Phase("loading", callbacks, stop=lambda: series.stopped)
    if resume_from is not None:
        phase.restore(sim, resume_from, writer)
    elif fork_from is not None:
        phase.restore(sim, fork_from, states=False)
    note = None if quiet else sim.compile_note()
    if note:
        print(note, file=sys.stderr, flush=True)

    status = "finished"
    try:
        with deferred_interrupt() as interrupted:
            if end_time - sim.state.time > 0.5 * sim.dt:     # (a run resumed at its end: no step more)
                sim.run(end_time - sim.state.time, phase.schedules(sim),
                        should_stop=lambda: phase.stop() or interrupted())
            if interrupted():
                status = "interrupted"
            keeper.act(sim)
    except KeyboardInterrupt:       # a second Ctrl-C, or one outside the step loop
        status = "interrupted"
        keeper.act(sim)
    except PhysicsError as err:
        writer.close(f"failed: {err}", provenance.sim_hash(sim))
        raise
    finally:
        if progress:
            progress.close()
    scaling.finish(sim, writer)
    return status, recorder


class SeriesWriter(Callback):
    """The series row every output.series_interval: measured, widened by stick scaling's columns,
    appended to the run file, fed to the slip recorder and stick scaling (whose rollback it has
    ``phase`` perform: Phase.restore of the ring state, then after_rewind), shown as progress.
    ``stopped``: a slip ended and the phase was asked to stop after one (stop_after_slip)."""

    name = "series"

    def __init__(self, writer: RunFile, recorder: SlipRecorder, scaling: StickScaling | TrueInertia, progress,
                 out_dir: Path, need: float, t_begin: float, stop_after_slip: bool):
        self.writer, self.recorder, self.scaling = writer, recorder, scaling
        self.progress, self.out_dir, self.need, self.t_begin = progress, out_dir, need, t_begin
        self.stop_after_slip = stop_after_slip
        self.stopped = False
        self.phase: Phase | None = None      # set by load_phase

    def every(self, sim):
        return Every.t0(sim, sim.config.output.series_interval, self.act, self.name)

    def act(self, sim: Simulation):
        ensure_space(self.out_dir, self.need)
        row = sim.measure()             # (the guards' row when they ran on this step)
        row.update(self.scaling.columns(sim, row))      # stick scaling: lambda, I (and De) columns
        self.writer.append(row)
        slip = self.recorder.observe(row)
        rollback = self.scaling.after_row(sim, row, self.recorder, slip)
        if rollback is not None:                # stick scaling: back to true inertia at an onset
            if rollback.to is not None:
                self.phase.restore(sim, rollback.to, self.writer, attached=ring_attachments([rollback.to]))
                self.scaling.after_rewind(sim)
            return
        if slip is not None and self.stop_after_slip:
            self.stopped = True
        if self.progress:
            self.progress.update(sim.state.time - self.t_begin, sim.state.step,
                                 info=f"tau/sigma {row['tau_over_sigma']:.3f}, slips {self.recorder.count}")


class Snapshots(Callback):
    """A snapshot into the run file every output.snapshot_interval."""

    name = "snapshots"

    def __init__(self, writer: RunFile):
        self.writer = writer

    def every(self, sim):
        return Every.t0(sim, sim.config.output.snapshot_interval, self.act, self.name)

    def act(self, sim):
        self.writer.snapshot(sim)


class SlipFrames(Callback):
    """Dense snapshots while the top wall slips: output.slip_frames per predicted slip duration
    pi sqrt(m_b/k) (thesis Eq. 3), written whenever v_w >= slips.end_factor V_s; none if 0."""

    name = "slip_frames"

    def __init__(self, writer: RunFile, recorder: SlipRecorder):
        self.writer, self.recorder = writer, recorder

    def every(self, sim):
        frames = sim.config.output.slip_frames
        if not frames or sim.wall_mass_per_length <= 0:
            return None
        period = slip_duration(sim.config, sim.wall_mass_per_length)
        self.writer.set_attr("snapshot_dense_interval", period / frames)
        return Every.t0(sim, period / frames, self.act, self.name)

    def act(self, sim):
        if sim.state.wall[L.W_VX] >= self.recorder.lo:
            self.writer.snapshot(sim)


class Ring(Callback):
    """The slip recorder's ring of pre-slip states, every lead / RING_PER_LEAD (SlipRecorder.keep:
    with the states of its kept_with callbacks)."""

    name = "ring"

    def __init__(self, recorder: SlipRecorder):
        self.recorder = recorder

    def every(self, sim):
        self.recorder.ring_every = self.recorder.ring_steps(sim)
        return Every(self.recorder.ring_every, self.act, self.name)

    def act(self, sim):
        self.recorder.keep(sim)


class CheckpointKeeper(Callback):
    """checkpoints/latest.h5 every output.checkpoint_interval and when the phase ends: the state
    with every callback's own state under its name (callbacks.states) and the header (phase
    'loading', the slips recorded, the series tail)."""

    name = "checkpoint"

    def __init__(self, writer: RunFile, layout: RunLayout | None, callbacks: list, recorder: SlipRecorder):
        self.writer, self.layout, self.callbacks, self.recorder = writer, layout, callbacks, recorder

    def every(self, sim):
        return Every.t0(sim, sim.config.output.checkpoint_interval, self.act, self.name)

    def act(self, sim):
        if self.layout is None:
            return
        self.writer.flush()
        for cb in self.callbacks:
            cb.sync(sim)
        saved, attached = states(self.callbacks)
        header = CheckpointHeader("loading", self.recorder.count, self.writer.series_tail())
        write_checkpoint(self.layout.latest, snapshot_of(sim, header, saved, attached))


#: the signals that stop a run cleanly: Ctrl-C, and what schedulers, `timeout` and systemd send
#: (SLURM at a job's wall-time limit) or a closed terminal
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextmanager
def deferred_interrupt():
    """Ctrl-C (SIGINT), SIGTERM or SIGHUP sets a flag that the step loop reads between chunks,
    after every callback of the current step has run, so that the checkpoint written on stopping
    lines up with the series (an interrupt inside a callback could lose a row). A second signal
    acts at once (its previous handler: KeyboardInterrupt under the CLI, cli.common.stop_signals).
    Yields a function telling whether a stop was asked for."""
    flag = {"set": False}
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = {}
    for sig in STOP_SIGNALS:
        old = signal.getsignal(sig)
        previous[sig] = signal.default_int_handler if old is None and sig == signal.SIGINT else old

    def handler(signum, frame):
        flag["set"] = True
        for sig, old in previous.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)

    for sig in STOP_SIGNALS:
        signal.signal(sig, handler)
    try:
        yield lambda: flag["set"]
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)


def guarded_run(sim: Simulation, duration: float, interval: float | None = None, compact: bool = True,
                **limits) -> list[dict]:
    """Compact (if still compacting and `compact`, with the guards on its checks; the fluid starts
    with loading), then load for `duration` [t0] with all guards every `interval` [t0] (default
    output.series_interval); returns the time-series rows (Simulation.measure, shared with the
    guards) taken at the same cadence: Simulation.run with the callbacks "guards", "series".
    Raises PhysicsError."""
    interval = sim.config.output.series_interval if interval is None else interval
    guards = Guards(interval=interval, **limits)
    if compact and sim.phase == L.COMPACTION:
        compaction.compact(sim, [guards])
    rows = Rows(interval)
    rows.rows.append(sim.measure())
    sim.run(duration, schedules(sim, [guards, rows]))
    return rows.rows


class Rows(Callback):
    """The observation row (Simulation.measure) every `interval` [t0], kept in ``rows``."""

    name = "series"

    def __init__(self, interval: float):
        self.interval = interval
        self.rows: list[dict] = []

    def every(self, sim):
        return Every.t0(sim, self.interval, self.act, self.name)

    def act(self, sim):
        self.rows.append(sim.measure())
