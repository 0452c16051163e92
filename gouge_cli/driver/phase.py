"""A phase of a run (compaction, driver.compaction.compact; loading, driver.phases.load_phase):
its name, its callbacks in firing order and its stop rule, and :meth:`Phase.restore`, the one code
that puts a saved state back:

    restore(sim, ck, writer=None, *, states=True, attached=None):
        sim.state <- ck.state; sim.fluid <- ck.fluid     (where both have one)
        states: for cb in callbacks (the phase's order): cb.load_state_dict(ck.states[cb.name],
                                                                      attached or ck.attached)
        writer: rows, snapshots and slips after ck dropped (RunFile.truncate_after)

Its three users: a resume from latest.h5 (after io.recovery mended and checked the run file), stick
scaling's rollback to a ring state (driver.phases.SeriesWriter, on StickScaling's request) and a
fork's start (``states=False``: a branch starts its own catalog and guards).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

from ..io.checkpoint import Checkpoint
from ..io.runwriter import RunFile
from .callbacks import Callback, schedules
from .schedules import Every
from .simulation import Simulation


def _never() -> bool:
    return False


@dataclass
class Phase:
    """name       'compaction' or 'loading' (a checkpoint header's phase)
    callbacks  in firing order on a shared step, which is also the order their states are put
               back in (stick scaling first: its load_state_dict sets the inertia)
    stop       True once the phase is done (compaction settled, a fork's first slip ended)
    """

    name: str
    callbacks: list[Callback]
    stop: Callable[[], bool] = _never

    def schedules(self, sim: Simulation) -> list[Every] | Callable[[], list[Every]]:
        """The callbacks' schedules for Simulation.run: the list, or the function that rebuilds
        it when a callback may change the step (Callback.changes_step; schedules are step counts)."""
        build = partial(schedules, sim, self.callbacks)
        return build if any(cb.changes_step for cb in self.callbacks) else build()

    def restore(self, sim: Simulation, ck: Checkpoint, writer: RunFile | None = None, *, states: bool = True,
                attached: dict | None = None) -> None:
        """Put `ck` back (module doc): its arrays; with `states`, each callback's own state in the
        phase's order, its attached checkpoints `attached` (default ck.attached); with `writer`,
        the run file cut back to ck (time [t0], step, header.slips)."""
        sim.state.restore(ck.state)
        if sim.fluid is not None and ck.fluid:
            sim.fluid.restore(ck.fluid)
        if states:
            for cb in self.callbacks:
                if cb.name in ck.states:
                    cb.load_state_dict(ck.states[cb.name], ck.attached if attached is None else attached)
        if writer is not None:
            writer.truncate_after(ck.time, ck.step, ck.header.slips)
