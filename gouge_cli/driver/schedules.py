"""When a callback of the loop (Simulation.run) is due: schedules counted in steps since step 0
(or since a phase's first step, ``offset``), so that a restarted or forked run fires its
callbacks on the same steps as an uninterrupted one."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass
class Every:
    """Call ``action(sim)`` on the steps offset + k * steps, k >= 1 (step counts since step 0, or
    since the step ``offset`` where a phase began, so restarts line up). ``name`` says what the
    callback is (guards, series, snapshots, ...); callbacks due on the same step fire in the
    order of the list given to Simulation.run."""

    steps: int
    action: Callable
    name: str = ""
    offset: int = 0

    @classmethod
    def t0(cls, sim, interval: float, action: Callable, name: str = "", offset: int = 0) -> "Every":
        """Every `interval` [t0] of the scene `sim`, rounded to whole steps (at least 1): the one
        conversion of a schedule in time to steps."""
        return cls(sim.steps_for(interval), action, name, offset)

    def next_step(self, step: int) -> int:
        return self.offset + ((step - self.offset) // self.steps + 1) * self.steps

    def due(self, step: int) -> bool:
        return (step - self.offset) % self.steps == 0
