"""The callback model of the loop: every run-time piece (guards, slip recorder, ring of pre-slip
states, series writer, snapshots, checkpoint keeper, stick scaling) is an object with

* ``name``: what it is, and the key of its state in a checkpoint's ``extra``;
* ``every(sim)``: its schedule, an :class:`~gouge_cli.driver.schedules.Every` on ``act`` (None: it
  is not scheduled, e.g. stick scaling, which acts from the series writer); rebuilt when the step
  changes (stick scaling), since schedules are step counts;
* ``act(sim)``: what it does when due;
* ``state_dict()`` / ``load_state_dict(state, attached)``: its state (None: nothing to save), and
  ``attachments()``: checkpoints to attach to the one written (the slip recorder's ring);
* ``changes_step``: True if ``act`` may change the step (stick scaling: schedules are rebuilt).

:func:`states` collects the states by name for a checkpoint, and
:meth:`gouge_cli.driver.phase.Phase.restore` alone gives each callback its own back, so no module
reads another's state by key. A phase (driver.phase.Phase) lists its callbacks in firing order.
"""

from __future__ import annotations

from .schedules import Every


class Callback:
    """Base of a run-time piece (module doc); the defaults: not scheduled, stateless."""

    name: str = ""
    changes_step: bool = False

    def every(self, sim) -> Every | None:
        return None

    def act(self, sim) -> None:
        pass

    def sync(self, sim) -> None:
        """Bring the state up to date before it is saved (default: nothing to do)."""

    def state_dict(self) -> dict | None:
        return None

    def load_state_dict(self, state: dict, attached: dict | None = None) -> None:
        pass

    def attachments(self) -> dict:
        return {}


def schedules(sim, callbacks) -> list[Every]:
    """The Every of each scheduled callback, in list order (the firing order on a shared step)."""
    return [e for cb in callbacks if (e := cb.every(sim)) is not None]


def states(callbacks) -> tuple[dict, dict]:
    """({name: state}, attached checkpoints) of the callbacks that keep a state."""
    saved, attached = {}, {}
    for cb in callbacks:
        state = cb.state_dict()
        if state is not None:
            saved[cb.name] = state
            attached.update(cb.attachments())
    return saved, attached

