"""Compaction, a phase like loading: the packing settles under the normal stress alone until the
top wall and grains are still (driver.settling's criterion), then loading starts.

    compact(sim, callbacks, settling, resume_from):
        phase = Phase("compaction", [settling, *callbacks], stop=settling.settled is not None)
        phase.restore(sim, resume_from)      # (a resume: the settling state, i.e. compaction's start)
        Simulation.run(no end, phase.callbacks on the checks, every CHECK_INTERVAL [t0] from that start)
        sim.start_loading()                  # (and the pore fluid, if any)

Its callbacks (driver.callbacks) fire on the checks, in list order after the settling check:
:class:`SettleProgress` (progress toward the criterion), :class:`CompactionCheckpoint`
(checkpoints/latest.h5 every output.checkpoint_interval rounded to whole checks, for `gouge
resume`), or a :class:`~gouge_cli.driver.guards.Guards` (driver.phases.guarded_run). The
compaction's start travels in a checkpoint as the settling callback's state (older checkpoints:
io.checkpoint.split_extra maps their LEGACY_START onto it), so that a compaction resumed from any
step checks, and ends, on the steps where it would have.
"""

from __future__ import annotations

import sys

from pathlib import Path

from ..io.checkpoint import SETTLING, Checkpoint, CheckpointHeader, snapshot_of, state_bytes, write_checkpoint
from ..io.layout import RunLayout
from ..io.rundir import ensure_space
from .callbacks import Callback, states
from .guards import check
from .phase import Phase
from .progress import SettleReport
from .schedules import Every
from .settling import SettleCheck, settle_check
from .simulation import Simulation

CHECK_INTERVAL = 100.0      # [t0] between compaction's checks


class Settling(Callback):
    """Compaction's check every CHECK_INTERVAL [t0] from ``start`` = (time [t0], step) where it began:
    the non-finite and overlap guards (guards.check), the observation row, the settling criterion.

    check    the last SettleCheck (None before the first)
    row      the last check's observation row (Simulation.measure)
    settled  None while compacting; True once settled; False when compaction.max_time passed first
    """

    name = SETTLING

    def __init__(self, sim: Simulation, start: tuple[float, int] | None = None):
        cfg = sim.config.compaction
        self.v_tol = cfg.wall_velocity_tol * sim.config.loading.normal_stress     # [v0]
        self.min_time, self.max_time = cfg.min_time, cfg.max_time
        self.start = start if start is not None else (sim.state.time, sim.state.step)
        self.check: SettleCheck | None = None
        self.row: dict | None = None
        self.settled: bool | None = None

    def every(self, sim: Simulation) -> Every:
        return Every(sim.steps_for(CHECK_INTERVAL), self.act, self.name, offset=self.start[1])

    def checks_done(self, sim: Simulation) -> int:
        """Checks since compaction began, this one included (on a check step)."""
        return (sim.state.step - self.start[1]) // sim.steps_for(CHECK_INTERVAL)

    def act(self, sim: Simulation):
        check(sim)
        row = self.row = sim.measure()
        elapsed = sim.state.time - self.start[0]
        self.check = settle_check(sim.state, row["kinetic_energy"], row["wall_vz"], elapsed, self.v_tol,
                                  self.min_time)
        if self.check.settled:
            self.settled = True
        elif elapsed >= self.max_time:
            self.settled = False

    def state_dict(self) -> dict:
        return {"start": [float(self.start[0]), int(self.start[1])]}

    def load_state_dict(self, state: dict, attached: dict | None = None):
        t0, step0 = state["start"]
        self.start = (float(t0), int(step0))


class SettleProgress(Callback):
    """Progress toward the settling criterion on each check (progress.SettleReport)."""

    name = "progress"

    def __init__(self, settling: Settling, report: SettleReport):
        self.settling, self.report = settling, report

    def act(self, sim: Simulation):
        self.report.update(self.settling.check, sim.state.step)


class CompactionCheckpoint(Callback):
    """checkpoints/latest.h5 (phase 'compaction' and the settling state) on every `checks`-th check,
    after making sure `need` bytes are free in `out_dir`; :meth:`save` on Ctrl-C."""

    name = "checkpoint"

    def __init__(self, settling: Settling, out_dir: Path, checks: int, need: float):
        self.settling, self.out_dir, self.checks, self.need = settling, Path(out_dir), checks, need

    def act(self, sim: Simulation):
        if self.settling.checks_done(sim) % self.checks == 0:
            self.save(sim)

    def save(self, sim: Simulation):
        ensure_space(self.out_dir, self.need)
        saved, _ = states([self.settling])
        write_checkpoint(RunLayout(self.out_dir).latest, snapshot_of(sim, CheckpointHeader("compaction"), saved))


def compact(sim: Simulation, callbacks: list[Callback] = (), settling: Settling | None = None,
            resume_from: Checkpoint | None = None) -> Settling:
    """Settle under the normal stress alone until the top wall and grains are still (or until
    compaction.max_time), then start loading (and the fluid). ``callbacks`` fire on each check after
    ``settling`` (default: a new one from now). `resume_from`: a compaction checkpoint put back
    first (Phase.restore: the state and compaction's start); a compaction resumed on a check step
    runs that check first. Returns the settling callback (its last check, row and outcome)."""
    settling = settling if settling is not None else Settling(sim)
    phase = Phase("compaction", [settling, *callbacks], stop=lambda: settling.settled is not None)
    if resume_from is not None:
        phase.restore(sim, resume_from)
    checks = settling.every(sim)
    if sim.state.step > checks.offset and checks.due(sim.state.step):      # resumed on a check
        for cb in phase.callbacks:
            cb.act(sim)
    if not phase.stop():
        sim.run(None, [Every(checks.steps, cb.act, cb.name, offset=checks.offset) for cb in phase.callbacks],
                should_stop=phase.stop)
    sim.start_loading()
    return settling


def compaction_phase(sim: Simulation, out_dir: Path, live=None, quiet=False, resume_from=None) -> Settling:
    """:func:`compact` with checkpoints/latest.h5 written every output.checkpoint_interval of
    compaction (on its checks) and on Ctrl-C, so that `gouge resume` continues a compaction too
    (`resume_from`: that checkpoint, whose compaction start it goes on from). Progress is shown
    toward the settling criterion (progress.SettleReport)."""
    settling = Settling(sim)
    checks = max(1, int(round(sim.config.output.checkpoint_interval / CHECK_INTERVAL)))
    keeper = CompactionCheckpoint(settling, out_dir, checks, 2.0 * state_bytes(sim))
    note = None if quiet else sim.compile_note()
    if note:
        print(note, file=sys.stderr, flush=True)
    report = None if quiet else SettleReport(sim.config.compaction.max_time, sim.state.n, live=live)
    callbacks = ([SettleProgress(settling, report)] if report else []) + [keeper]
    try:
        return compact(sim, callbacks, settling, resume_from)
    except KeyboardInterrupt:
        keeper.save(sim)
        raise
    finally:
        if report:
            report.close()
