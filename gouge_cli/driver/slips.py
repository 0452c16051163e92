"""Slips during a run: the streaming detector, and the checkpoint kept from before each slip.

:class:`SlipRecorder` is fed every time-series row. It keeps the last ``slips.ring`` states
in memory, spaced lead/4 apart, taken only while the wall is quiet (v below the end
threshold) and the stress is near its peak since the last slip (within lead_stress/4), so
that a slow pre-slip creep does not push the ring past the stress peak. When the wall
velocity first crosses the trigger threshold, it sets aside the newest kept state that is
at least ``lead`` older than both the stress peak and the last quiet sample: a packing from
before the static strength was reached, so an undrained branch can fail earlier. When the detector
reports the finished slip, that state is written as ``checkpoints/slip_NNN.h5`` and the
slip goes into the run file's catalog (``/slips/NNN``) at once. An event the detector
drops (too small) discards its pending state.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np

from ..io.checkpoint import SLIP_RECORDER, Checkpoint, CheckpointHeader, snapshot_of, write_checkpoint
from ..io.layout import RunLayout
from ..io.slipcatalog import SlipEntry
from ..config import Config
from ..model.slip_rule import Slip, SlipDetector, SlipRule
from .callbacks import Callback, states
from ..kernels.layout import W_VX

RING_PER_LEAD = 4      # pre-slip ring states kept per slips.lead (spaced lead / RING_PER_LEAD)
RING = "ring_"         # attached ring states are ring_000, ring_001, ... (oldest first)


def ring_attachments(ring) -> dict:
    """{ring_NNN: state} of ring states (oldest first), as a checkpoint attaches them and
    SlipRecorder.load_state_dict takes them back."""
    return {f"{RING}{i:03d}": ck for i, ck in enumerate(ring)}


def lead_time(config: Config) -> float:
    """Checkpoint lead before onset [t0]: slips.lead, or lead_stress sigma / (k V_s)."""
    s = config.slips
    if s.lead is not None:
        return s.lead
    rate = config.loading.spring_constant * max(config.loading.velocity, 1e-300)
    return s.lead_stress * config.loading.normal_stress / rate


class SlipRecorder(Callback):
    """Time-series callback: detect slips, persist the pre-slip checkpoint, write the catalog.
    Fed by the series writer (not scheduled itself); its checkpoint state (``state_dict`` and
    ``attachments``: the ring and the pending pre-slip state) is saved under ``name``.
    ``kept_with``: the callbacks whose states each ring state keeps too (the guards': a stick
    scaling rollback puts them back with it)."""

    name = SLIP_RECORDER

    def __init__(self, config: Config, sim, run_file, layout: RunLayout | None, kept_with=()):
        """`layout`: the run directory whose slip checkpoints it writes (None: none written)."""
        self.config = config
        self.run_file = run_file
        self.layout = layout
        self.lead = lead_time(config)
        self.ring_every = self.ring_steps(sim)
        self.ring: deque[Checkpoint] = deque(maxlen=config.slips.ring)
        self.rule = SlipRule.from_config(config)
        self.hi, self.lo = self.rule.hi, self.rule.lo
        self.peak_band = 0.25 * config.slips.lead_stress
        self.slips: list[SlipEntry] = []      # recorded since this process started
        self._start_time = sim.state.time
        self.kept_with = list(kept_with)
        self.load_state_dict({})          # (the initial state)

    def load_state_dict(self, state: dict, attached: dict | None = None):
        """Go on from a saved state (state_dict) and its attached checkpoints (attachments)."""
        self.detector = (SlipDetector.from_state_dict(state["detector"]) if "detector" in state
                         else self.rule.detector())
        self.count = int(state.get("count", 0))
        self.last_quiet = float(state.get("last_quiet", self._start_time))
        self.above = bool(state.get("above", False))
        self.peak_tau = float(state.get("peak_tau", -np.inf))
        self.peak_time = float(state.get("peak_time", self._start_time))
        self.pending: Checkpoint | None = None
        self._deborah: list[float] = [float(v) for v in state.get("deborah", [])]
        ring = [ck for key, ck in sorted((attached or {}).items()) if key.startswith(RING)]
        self.ring.clear()
        self.ring.extend(ring)
        if "pending" in (attached or {}):
            self.pending = attached["pending"]
        elif state.get("pending_in_ring") is not None:
            self.pending = ring[int(state["pending_in_ring"])]

    def ring_state(self) -> dict:
        """The state kept with each ring state: load_state_dict with that ring state alone attached
        (ring_attachments) goes back to the moment it was kept (no pending state, no Deborah
        samples: a stick scaling rollback)."""
        return {"detector": self.detector.state_dict(), "count": self.count,
                "last_quiet": self.last_quiet, "above": self.above,
                "peak_tau": self.peak_tau, "peak_time": self.peak_time}

    def state_dict(self) -> dict:
        """For latest.h5: everything a resume needs to go on exactly as this recorder would (with
        attachments(): the kept ring, the pending pre-slip state; the Deborah samples of a slip
        in progress); the inverse of load_state_dict."""
        state = self.ring_state()
        state["deborah"] = list(self._deborah)
        in_ring = [i for i, ck in enumerate(self.ring) if ck is self.pending]
        state["pending_in_ring"] = in_ring[0] if in_ring else None
        return state

    def attachments(self) -> dict:
        attached = ring_attachments(self.ring)
        if self.pending is not None and not any(ck is self.pending for ck in self.ring):
            attached["pending"] = self.pending
        return attached

    def keep(self, sim, always: bool = False):
        """Ring callback (every lead/4): keep the state if the wall is quiet (v < end threshold),
        so that the ring always reaches back from the last quiet moment before an onset, with
        ring_state() and the states of ``kept_with``; `always`: keep it whatever the wall does
        (stick scaling: the moment scaling resumes)."""
        tau = sim.tau_over_sigma()
        if always or (sim.state.wall[W_VX] < self.lo and tau >= self.peak_tau - self.peak_band):
            kept = {self.name: self.ring_state(), **states(self.kept_with)[0]}
            self.ring.append(snapshot_of(sim, CheckpointHeader(slips=self.count), kept))

    def ring_steps(self, sim) -> int:
        """Steps between ring states at sim's current dt: lead / RING_PER_LEAD."""
        return sim.steps_for(self.lead / RING_PER_LEAD)

    def closed(self) -> bool:
        """Nothing open: no raw or pending detector event and no pending pre-slip state (every
        slip seen is in the catalog or dropped as too small)."""
        return self.detector.raw is None and self.detector.pending is None and self.pending is None

    def forget_peak(self):
        """Stick scaling, when scaling resumes after a stretch that moved: the stress peak starts
        afresh (as after a slip), so that the scaled stretch keeps ring states near its own peak."""
        self.peak_tau = -np.inf

    def choose_pre_slip(self, onset: float = math.inf, not_before: float = -math.inf) -> Checkpoint | None:
        """The pre-slip state of an onset at `onset` [t0] (default: the trigger crossed now): the
        one set aside at the trigger if any, else the newest kept state at least `lead` before
        min(last quiet row, stress peak, onset), else the oldest kept (a shorter lead); none from
        before `not_before` [t0] (stick scaling: where it last resumed), the oldest kept since
        then instead; None if nothing fits."""
        ck = self.pending if self.pending is not None else self._kept_before(min(self.last_quiet, self.peak_time,
                                                                                  onset))
        if ck is not None and ck.time < not_before:
            ck = next((c for c in self.ring if c.time >= not_before), None)
        return ck

    def _kept_before(self, estimate: float) -> Checkpoint | None:
        for ck in reversed(self.ring):
            if ck.time <= estimate - self.lead:
                return ck
        return self.ring[0] if self.ring else None

    def observe(self, row: dict) -> Slip | None:
        """Series callback; returns a slip the moment it is finished."""
        t, v = row["time"], row["wall_vx"]
        if v < self.lo:
            self.last_quiet = t
        if row["tau_over_sigma"] > self.peak_tau and self.pending is None:
            self.peak_tau, self.peak_time = row["tau_over_sigma"], t
        if v >= self.hi and not self.above and self.pending is None:
            self.pending = self.choose_pre_slip()
        self.above = v >= self.hi
        slip = self.detector.update(t, row["wall_x"], v, row["tau_over_sigma"], row["porosity"])
        if "deborah" in row and (self.detector.raw is not None or slip is not None):
            self._deborah.append(row["deborah"])
        elif slip is None and self.detector.pending is None:
            self._deborah.clear()
        if slip is not None:
            self._record(slip)
            self._reset(recorded=True)
        elif self.pending is not None and self.detector.raw is None and self.detector.pending is None \
                and not self.above and v < self.lo:
            self._reset()
        return slip

    def _reset(self, recorded: bool = False):
        """After a slip: forget the pending state and the stress peak; after a recorded slip
        also the kept states (a later slip's checkpoint must not contain this slip)."""
        self.pending = None
        self.peak_tau = -np.inf
        if recorded:
            self.ring.clear()

    def _record(self, slip: Slip):
        self.count += 1
        deborah = float(np.mean(self._deborah)) if self._deborah else float("nan")
        self._deborah.clear()
        checkpoint, checkpoint_time = "", float("nan")
        if self.pending is not None and self.layout is not None:
            path = self.layout.slip_checkpoint(self.count)
            header = replace(self.pending.header, slip=self.count, onset_time=slip.onset_time)
            write_checkpoint(path, replace(self.pending, header=header))
            checkpoint, checkpoint_time = self.layout.relative(path), self.pending.time
        entry = SlipEntry.from_slip(slip, self.count, deborah=deborah, checkpoint=checkpoint,
                                    checkpoint_time=checkpoint_time)
        self.slips.append(entry)
        if self.run_file is not None:
            self.run_file.add_slip(entry)
