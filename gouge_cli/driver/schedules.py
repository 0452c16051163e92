"""When a callback of the loop (Simulation.run) is due: schedules counted in steps since step 0,
so that a restarted or forked run fires its callbacks on the same steps as an uninterrupted one."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass
class Every:
    """Call ``action(sim)`` every ``steps`` steps (step counts since step 0, so restarts line up)."""

    steps: int
    action: Callable

    def next_step(self, step: int) -> int:
        return (step // self.steps + 1) * self.steps

    def due(self, step: int) -> bool:
        return step % self.steps == 0
