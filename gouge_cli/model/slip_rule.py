"""The slip rule: slip-event detection on top-wall time series (thesis Sections IV-V, Figs. 5-15).

:class:`SlipRule` holds the rule's parameters, built once from a config's ``slips`` section and
V_s (:meth:`SlipRule.from_config`) or from a run file's stored config (:meth:`SlipRule.from_stored`);
the batch detector (:meth:`SlipRule.detect`, :func:`detect_slips`), the streaming detector
(:class:`SlipDetector`, fed by the run's slip recorder), the run file's reader (``RunInfo.slip_rule``)
and the pair definition all take it. It lives in ``model/`` so that driver, io and analysis use it
without importing each other.

All inputs are dimensionless 1-D arrays of length n sampled at one cadence:
``t`` (time), ``x_wall`` (top-wall displacement along the fault), ``v_wall``
(top-wall velocity), ``tau_over_sigma`` (spring force per length / normal
stress) and ``porosity``.

Rule (velocity thresholds are multiples of the loading velocity ``V_s``):

* ``lo = end_factor * V_s`` and ``hi = start_factor * V_s`` (``lo < hi``).
* A *raw event* is a run of consecutive samples with ``v >= lo`` that is
  preceded by a sample with ``v < lo`` (so a series that starts mid-slip
  ignores that first slip), contains at least one sample with ``v >= hi``
  (the trigger) and is followed by a sample with ``v < lo`` (a slip still
  running at the last sample is not reported).
* Onset and end times are the linear interpolations of the ``lo`` crossings
  between the bracketing samples; displacement and porosity are interpolated
  at the same fractions. ``duration = end_time - onset_time``,
  ``slip = x(end_time) - x(onset_time)``, ``mean_velocity = slip / duration``.
* Raw events whose onset comes no later than ``merge_gap`` after the previous
  event's end are merged into it (one slip with several sub-events).
* Merged events with ``duration < min_duration`` or ``slip < min_slip`` are
  dropped.
* ``static_strength``: the largest tau/sigma from the sample after the previous
  detected raw event (dropped ones included; series start for the first) up to
  and including the onset sample; with ``strength_window = W`` instead the
  samples with ``t >= t[onset] - W`` up to the onset sample.
* ``stress_drop = tau/sigma[onset_index] - min(tau/sigma)`` over the samples
  from the onset sample to the first sample after the end (inclusive).
* Sub-events: local velocity maxima inside a slip. Two maxima p1, p2 (both
  ``>= hi``) are separate sub-events when the lowest velocity m between them
  satisfies ``m < subevent_fraction * min(p1, p2)`` or ``m < hi``. Sub-events
  whose peak is below ``min_subevent_fraction * peak_velocity`` are dropped.

:class:`SlipDetector` applies the same rule one sample at a time and gives
exactly the events of :func:`detect_slips` (after :meth:`SlipDetector.flush`). The records (Slip,
SubEvent) and the event both build are in :mod:`gouge_cli.model.slip_events`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from ..config import SlipsConfig
from .slip_events import (OpenEvent, Slip, SubEvent, crossing_fraction, finalize, lerp, merge_events, nanmin2, sub_list,
                          sub_start, sub_step)

__all__ = [
    "SlipRule",
    "SubEvent",
    "Slip",
    "WallSeries",
    "detect_slips",
    "SlipDetector",
    "recurrence_intervals",
]

_NAN = float("nan")


@dataclass
class WallSeries:
    """Top-wall time series of one run; all arrays have shape (n,)."""

    t: np.ndarray
    x_wall: np.ndarray
    v_wall: np.ndarray
    tau_over_sigma: np.ndarray
    porosity: np.ndarray | None = None


_DEFAULTS = SlipsConfig()          # the rule's defaults are those of the config section


@dataclass(frozen=True)
class SlipRule:
    """The slip rule's parameters (module doc): thresholds ``start_factor * V_s`` (trigger) and
    ``end_factor * V_s`` (onset/end level); min_duration, merge_gap, strength_window [t0];
    min_slip [d]; subevent_fraction, min_subevent_fraction [-]. Defaults: ``SlipsConfig``'s."""

    V_s: float
    start_factor: float = _DEFAULTS.start_factor
    end_factor: float = _DEFAULTS.end_factor
    min_duration: float = _DEFAULTS.min_duration
    min_slip: float = _DEFAULTS.min_slip
    merge_gap: float = _DEFAULTS.merge_gap
    strength_window: float | None = None
    subevent_fraction: float = 0.5
    min_subevent_fraction: float = 0.1

    # the parameters a config's slips section sets (stored in every run file's config)
    CONFIG_KEYS = ("start_factor", "end_factor", "min_duration", "min_slip", "merge_gap")

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                object.__setattr__(self, f.name, float(value))
        if not self.V_s > 0:
            raise ValueError(f"V_s must be > 0, got {self.V_s}")
        if not 0 < self.end_factor < self.start_factor:
            raise ValueError(
                f"need 0 < end_factor < start_factor, got {self.end_factor}, {self.start_factor}"
            )

    @classmethod
    def from_config(cls, config) -> "SlipRule":
        """The rule of a run: ``config.slips`` at V_s = ``config.loading.velocity``."""
        s = config.slips
        return cls(config.loading.velocity, **{k: getattr(s, k) for k in cls.CONFIG_KEYS})

    @classmethod
    def from_stored(cls, slips: dict, V_s: float) -> "SlipRule":
        """The rule from a stored config's ``slips`` mapping (an older file may lack keys: defaults)."""
        return cls(V_s, **{k: slips[k] for k in cls.CONFIG_KEYS if k in slips})

    @property
    def lo(self) -> float:
        """Onset/end level [velocity]: end_factor V_s."""
        return self.end_factor * self.V_s

    @property
    def hi(self) -> float:
        """Trigger [velocity]: start_factor V_s."""
        return self.start_factor * self.V_s

    def config_values(self) -> dict:
        """The parameters a config's slips section sets, as a dict (pair definition, reports)."""
        return {k: getattr(self, k) for k in self.CONFIG_KEYS}

    def with_(self, **changes) -> "SlipRule":
        """A copy with some parameters changed (None: kept)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})

    def detect(self, t, v_wall, *, x_wall=None, tau_over_sigma=None, porosity=None) -> list["Slip"]:
        """The slips of a whole series (rule in the module doc); see :func:`detect_slips`."""
        return _detect(self, t, v_wall, x_wall, tau_over_sigma, porosity)

    def detector(self) -> "SlipDetector":
        """A streaming detector of this rule."""
        return SlipDetector(self)

    def state(self) -> dict:
        """Plain-dict form (with the thresholds lo, hi), as the detector's saved state holds it."""
        return dict(asdict(self), lo=self.lo, hi=self.hi)

    @classmethod
    def from_state(cls, p: dict) -> "SlipRule":
        return cls(**{f.name: p[f.name] for f in fields(cls) if f.name in p})


def _nan_extreme(a: np.ndarray, fn) -> float:
    a = a[~np.isnan(a)]
    return float(fn(a)) if a.size else _NAN


def detect_slips(
    t,
    v_wall,
    V_s: float,
    start_factor: float = SlipRule.start_factor,
    end_factor: float = SlipRule.end_factor,
    min_duration: float = SlipRule.min_duration,
    min_slip: float = SlipRule.min_slip,
    merge_gap: float = SlipRule.merge_gap,
    *,
    x_wall=None,
    tau_over_sigma=None,
    porosity=None,
    strength_window: float | None = None,
    subevent_fraction: float = SlipRule.subevent_fraction,
    min_subevent_fraction: float = SlipRule.min_subevent_fraction,
) -> list[Slip]:
    """Detect slip events in a whole series (rule in the module docstring): the
    :class:`SlipRule` of these parameters applied to the series (:meth:`SlipRule.detect`).

    t, v_wall, x_wall, tau_over_sigma, porosity: arrays of shape (n,).
    V_s: loading velocity; thresholds are ``start_factor * V_s`` (trigger) and
    ``end_factor * V_s`` (onset/end level). min_duration, merge_gap,
    strength_window: time units; min_slip: grain diameters. ``x_wall=None``
    integrates ``v_wall`` (trapezoid, x[0] = 0); missing tau or porosity give NaN
    strengths, stress drops or porosity changes.
    """
    rule = SlipRule(V_s, start_factor, end_factor, min_duration, min_slip, merge_gap, strength_window,
                    subevent_fraction, min_subevent_fraction)
    return _detect(rule, t, v_wall, x_wall, tau_over_sigma, porosity)


def _detect(rule: SlipRule, t, v_wall, x_wall, tau_over_sigma, porosity) -> list[Slip]:
    lo, hi = rule.lo, rule.hi
    t = np.asarray(t, dtype=float)
    v = np.asarray(v_wall, dtype=float)
    n = t.size
    if v.shape != (n,):
        raise ValueError("t and v_wall must have the same shape (n,)")
    if not np.all(np.isfinite(v)):
        raise ValueError("v_wall must be finite")
    if x_wall is None:
        x = np.zeros(n)
        if n > 1:
            x[1:] = np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))
    else:
        x = np.asarray(x_wall, dtype=float)
    tau = np.full(n, np.nan) if tau_over_sigma is None else np.asarray(tau_over_sigma, dtype=float)
    phi = np.full(n, np.nan) if porosity is None else np.asarray(porosity, dtype=float)
    if x.shape != (n,) or tau.shape != (n,) or phi.shape != (n,):
        raise ValueError("all series must have shape (n,)")

    above = np.concatenate(([False], v >= lo, [False]))
    edges = np.flatnonzero(np.diff(above.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2] - 1
    raws: list[OpenEvent] = []
    window_start = 0
    for a, b in zip(starts, stops):
        if a == 0 or b == n - 1:
            continue
        seg = v[a:b + 1]
        if seg.max() < hi:
            continue
        fa = crossing_fraction(v[a - 1], v[a], lo)
        fb = crossing_fraction(v[b], v[b + 1], lo)
        if rule.strength_window is None:
            strength = _nan_extreme(tau[window_start:a + 1], np.max)
        else:
            j0 = int(np.searchsorted(t, t[a] - rule.strength_window, side="left"))
            strength = _nan_extreme(tau[j0:a + 1], np.max)
        k = int(np.argmax(seg))
        sub = sub_start(int(a), float(t[a]), float(v[a]))
        for j in range(a + 1, b + 1):
            sub_step(sub, j, float(t[j]), float(v[j]), hi, rule.subevent_fraction)
        raws.append(OpenEvent(
            onset_index=int(a), end_index=int(b),
            onset_time=lerp(float(t[a - 1]), float(t[a]), fa),
            onset_x=lerp(float(x[a - 1]), float(x[a]), fa),
            onset_porosity=lerp(float(phi[a - 1]), float(phi[a]), fa),
            end_time=lerp(float(t[b]), float(t[b + 1]), fb),
            end_x=lerp(float(x[b]), float(x[b + 1]), fb),
            end_porosity=lerp(float(phi[b]), float(phi[b + 1]), fb),
            tau_onset=float(tau[a]),
            strength=strength,
            peak_velocity=float(seg[k]), peak_index=int(a + k), peak_time=float(t[a + k]),
            tau_min=_nan_extreme(tau[a:b + 2], np.min),
            subs=sub_list(sub),
            n_merged=1,
        ))
        window_start = b + 1

    merged: list[OpenEvent] = []
    for r in raws:
        if merged and r.onset_time - merged[-1].end_time <= rule.merge_gap:
            prev = merged[-1]
            gap_min = _nan_extreme(tau[prev.end_index + 2:r.onset_index], np.min)
            merged[-1] = merge_events(prev, r, gap_min)
        else:
            merged.append(r)
    return [s for s in (finalize(m, rule) for m in merged) if s is not None]


class SlipDetector:
    """Streaming form of :func:`detect_slips`: feed one sample at a time.

    Built from a :class:`SlipRule` (or, as :func:`detect_slips`, from V_s and the rule's
    parameters). ``update`` returns a :class:`Slip` on the sample at which it is known to be
    finished (the first sample after its end when ``merge_gap == 0``; later
    ones while a merge is still possible), else ``None``. ``flush`` returns the
    event still waiting at the end of a series. ``state_dict()`` / ``from_state_dict()`` save and
    restore the state as plain numbers, lists and dicts (``from_state_dict`` also reads the
    one- and two-letter keys of checkpoints written before the records were typed).
    """

    def __init__(
        self,
        V_s: float | SlipRule,
        start_factor: float = SlipRule.start_factor,
        end_factor: float = SlipRule.end_factor,
        min_duration: float = SlipRule.min_duration,
        min_slip: float = SlipRule.min_slip,
        merge_gap: float = SlipRule.merge_gap,
        *,
        strength_window: float | None = None,
        subevent_fraction: float = SlipRule.subevent_fraction,
        min_subevent_fraction: float = SlipRule.min_subevent_fraction,
    ):
        self.rule = V_s if isinstance(V_s, SlipRule) else SlipRule(
            V_s, start_factor, end_factor, min_duration, min_slip, merge_gap, strength_window,
            subevent_fraction, min_subevent_fraction)
        self.n = 0
        self.armed = False
        self.prev: list[float] | None = None
        self.smax = _NAN
        self.sdeque: list[list[float]] = []
        self.raw: OpenEvent | None = None
        self.pending: OpenEvent | None = None

    def state_dict(self) -> dict:
        """Deep copy of the whole state as plain Python objects."""
        return copy.deepcopy({
            "params": self.rule.state(), "n": self.n, "armed": self.armed,
            "prev": self.prev, "smax": self.smax, "sdeque": self.sdeque,
            "raw": None if self.raw is None else self.raw.state(),
            "pending": None if self.pending is None else self.pending.state(),
        })

    @classmethod
    def from_state_dict(cls, state: dict) -> "SlipDetector":
        det = cls(SlipRule.from_state(state["params"]))
        s = copy.deepcopy(state)
        det.n, det.armed, det.prev = s["n"], s["armed"], s["prev"]
        det.smax, det.sdeque = s["smax"], s["sdeque"]
        det.raw, det.pending = OpenEvent.from_state(s["raw"]), OpenEvent.from_state(s["pending"])
        return det

    def _strength_push(self, t: float, tau: float) -> None:
        if math.isnan(tau):
            return
        if self.rule.strength_window is None:
            if math.isnan(self.smax) or tau > self.smax:
                self.smax = tau
            return
        dq = self.sdeque
        while dq and dq[-1][1] <= tau:
            dq.pop()
        dq.append([t, tau])
        self._strength_prune(t)

    def _strength_prune(self, t: float) -> None:
        dq = self.sdeque
        cut = t - self.rule.strength_window
        while dq and dq[0][0] < cut:
            dq.pop(0)

    def _strength(self, t: float) -> float:
        if self.rule.strength_window is None:
            return self.smax
        self._strength_prune(t)
        return self.sdeque[0][1] if self.sdeque else _NAN

    def update(self, t: float, x: float, v: float, tau_over_sigma: float = _NAN,
               porosity: float = _NAN) -> Slip | None:
        """Add one sample; return a finished slip or ``None``."""
        rule = self.rule
        lo, hi, gap = rule.lo, rule.hi, rule.merge_gap
        t, x, v = float(t), float(x), float(v)
        if not math.isfinite(v):
            raise ValueError("v must be finite")
        tau, phi = float(tau_over_sigma), float(porosity)
        i = self.n
        self.n += 1
        raw = self.raw

        if raw is not None and v < lo:
            t0, x0, v0, _, phi0 = self.prev
            fb = crossing_fraction(v0, v, lo)
            raw.end_index, raw.end_time, raw.end_x = i - 1, lerp(t0, t, fb), lerp(x0, x, fb)
            raw.end_porosity, raw.tau_min = lerp(phi0, phi, fb), nanmin2(raw.tau_min, tau)
            self.raw = None
            if raw.triggered:
                raw.subs, raw.sub = sub_list(raw.sub), None
                if self.pending is not None:
                    self.pending = merge_events(self.pending, raw, self.pending.gap_min)
                else:
                    self.pending = raw
                self.pending.gap_min = _NAN
                self.smax = _NAN
        elif raw is not None:
            raw.triggered = raw.triggered or v >= hi
            if v > raw.peak_velocity:
                raw.peak_velocity, raw.peak_index, raw.peak_time = v, i, t
            raw.tau_min = nanmin2(raw.tau_min, tau)
            sub_step(raw.sub, i, t, v, hi, rule.subevent_fraction)

        self._strength_push(t, tau)

        if self.raw is None and raw is None and self.armed and v >= lo:
            t0, x0, v0, _, phi0 = self.prev
            fa = crossing_fraction(v0, v, lo)
            self.raw = OpenEvent(
                onset_index=i, onset_time=lerp(t0, t, fa), onset_x=lerp(x0, x, fa),
                onset_porosity=lerp(phi0, phi, fa), tau_onset=tau,
                strength=self._strength(t), triggered=v >= hi,
                peak_velocity=v, peak_index=i, peak_time=t, tau_min=tau,
                sub=sub_start(i, t, v), n_merged=1,
            )
        if v < lo:
            self.armed = True
        self.prev = [t, x, v, tau, phi]

        pend = self.pending
        if pend is None:
            return None
        if i > pend.end_index + 1:
            pend.gap_min = nanmin2(pend.gap_min, tau)
        cand = self.raw
        if cand is None:
            ready = t - pend.end_time > gap
        else:
            ready = cand.onset_time - pend.end_time > gap
        if not ready:
            return None
        self.pending = None
        return finalize(pend, rule)

    def flush(self) -> Slip | None:
        """Finish the event waiting at the end of the series (if any)."""
        pend, self.pending = self.pending, None
        return None if pend is None else finalize(pend, self.rule)


def recurrence_intervals(slips: list[Slip]) -> np.ndarray:
    """Onset-to-onset times between consecutive slips, shape (len(slips) - 1,)."""
    on = np.array([s.onset_time for s in slips], dtype=float)
    return np.diff(on)
