"""Slip-event detection on top-wall time series (thesis Sections IV-V, Figs. 5-15).

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
exactly the events of :func:`detect_slips` (after :meth:`SlipDetector.flush`).
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..config import SLIP_END_FACTOR, SLIP_START_FACTOR

__all__ = [
    "SubEvent",
    "Slip",
    "WallSeries",
    "detect_slips",
    "SlipDetector",
    "recurrence_intervals",
]

_NAN = float("nan")


@dataclass
class SubEvent:
    """One local velocity maximum inside a slip."""

    index: int
    time: float
    velocity: float


@dataclass
class Slip:
    """One detected slip event (dimensionless units; indices into the series)."""

    onset_index: int
    onset_time: float
    end_index: int
    end_time: float
    duration: float
    slip: float
    peak_velocity: float
    peak_index: int
    peak_time: float
    mean_velocity: float
    static_strength: float
    tau_onset: float
    tau_min: float
    stress_drop: float
    porosity_change: float
    subevents: list[SubEvent] = field(default_factory=list)
    n_merged: int = 1

    @property
    def n_subevents(self) -> int:
        return len(self.subevents)

    def to_dict(self) -> dict:
        """Plain-dict form (sub-events as a list of dicts)."""
        return asdict(self)


@dataclass
class WallSeries:
    """Top-wall time series of one run; all arrays have shape (n,)."""

    t: np.ndarray
    x_wall: np.ndarray
    v_wall: np.ndarray
    tau_over_sigma: np.ndarray
    porosity: np.ndarray | None = None


def _thresholds(V_s: float, start_factor: float, end_factor: float) -> tuple[float, float]:
    if not V_s > 0:
        raise ValueError(f"V_s must be > 0, got {V_s}")
    if not 0 < end_factor < start_factor:
        raise ValueError(
            f"need 0 < end_factor < start_factor, got {end_factor}, {start_factor}"
        )
    return end_factor * V_s, start_factor * V_s


def _lerp(y0: float, y1: float, f: float) -> float:
    return y0 + f * (y1 - y0)


def _crossing_fraction(v0: float, v1: float, level: float) -> float:
    return (level - v0) / (v1 - v0)


def _sub_start(i: int, t: float, v: float) -> dict:
    return {"done": [], "pi": i, "pt": t, "pv": v, "mv": None}


def _sub_step(s: dict, i: int, t: float, v: float, hi: float, frac: float) -> None:
    """Advance the sub-event tracker ``s`` by one sample (shared by both detectors)."""
    m = s["mv"]
    if m is None:
        if v > s["pv"]:
            s["pi"], s["pt"], s["pv"] = i, t, v
        else:
            s["mv"] = v
        return
    low = min(s["pv"], v)
    if low >= hi and (m < frac * low or m < hi):
        s["done"].append([s["pi"], s["pt"], s["pv"]])
        s["pi"], s["pt"], s["pv"], s["mv"] = i, t, v, None
    elif v > s["pv"]:
        s["pi"], s["pt"], s["pv"], s["mv"] = i, t, v, None
    elif v < m:
        s["mv"] = v


def _sub_list(s: dict) -> list[list]:
    return s["done"] + [[s["pi"], s["pt"], s["pv"]]]


def _nanmin2(a: float, b: float) -> float:
    if math.isnan(a):
        return b
    if math.isnan(b):
        return a
    return a if a <= b else b


def _merge(p: dict, r: dict, gap_min: float) -> dict:
    """Merge raw event ``r`` into pending event ``p``."""
    out = dict(p)
    if r["peak_v"] > p["peak_v"]:
        out["peak_v"], out["peak_i"], out["peak_t"] = r["peak_v"], r["peak_i"], r["peak_t"]
    out["tau_min"] = _nanmin2(_nanmin2(p["tau_min"], gap_min), r["tau_min"])
    out["subs"] = p["subs"] + r["subs"]
    for key in ("b", "t_end", "x_end", "phi_end"):
        out[key] = r[key]
    out["n_merged"] = p["n_merged"] + r["n_merged"]
    return out


def _finalize(acc: dict, params: dict) -> Slip | None:
    duration = acc["t_end"] - acc["t_on"]
    slip = acc["x_end"] - acc["x_on"]
    if duration < params["min_duration"] or slip < params["min_slip"]:
        return None
    keep = params["min_subevent_fraction"] * acc["peak_v"]
    subs = [SubEvent(int(i), float(t), float(v)) for i, t, v in acc["subs"] if v >= keep]
    tau_on = acc["tau_on"]
    return Slip(
        onset_index=int(acc["a"]),
        onset_time=float(acc["t_on"]),
        end_index=int(acc["b"]),
        end_time=float(acc["t_end"]),
        duration=float(duration),
        slip=float(slip),
        peak_velocity=float(acc["peak_v"]),
        peak_index=int(acc["peak_i"]),
        peak_time=float(acc["peak_t"]),
        mean_velocity=float(slip / duration) if duration > 0 else _NAN,
        static_strength=float(acc["strength"]),
        tau_onset=float(tau_on),
        tau_min=float(acc["tau_min"]),
        stress_drop=float(tau_on - acc["tau_min"]),
        porosity_change=float(acc["phi_end"] - acc["phi_on"]),
        subevents=subs,
        n_merged=int(acc["n_merged"]),
    )


def _params(V_s, start_factor, end_factor, min_duration, min_slip, merge_gap,
            strength_window, subevent_fraction, min_subevent_fraction) -> dict:
    lo, hi = _thresholds(V_s, start_factor, end_factor)
    return {
        "V_s": float(V_s), "lo": lo, "hi": hi,
        "start_factor": float(start_factor), "end_factor": float(end_factor),
        "min_duration": float(min_duration), "min_slip": float(min_slip),
        "merge_gap": float(merge_gap),
        "strength_window": None if strength_window is None else float(strength_window),
        "subevent_fraction": float(subevent_fraction),
        "min_subevent_fraction": float(min_subevent_fraction),
    }


def _nan_extreme(a: np.ndarray, fn) -> float:
    a = a[~np.isnan(a)]
    return float(fn(a)) if a.size else _NAN


def detect_slips(
    t,
    v_wall,
    V_s: float,
    start_factor: float = SLIP_START_FACTOR,
    end_factor: float = SLIP_END_FACTOR,
    min_duration: float = 0.0,
    min_slip: float = 0.0,
    merge_gap: float = 0.0,
    *,
    x_wall=None,
    tau_over_sigma=None,
    porosity=None,
    strength_window: float | None = None,
    subevent_fraction: float = 0.5,
    min_subevent_fraction: float = 0.1,
) -> list[Slip]:
    """Detect slip events in a whole series (rule in the module docstring).

    t, v_wall, x_wall, tau_over_sigma, porosity: arrays of shape (n,).
    V_s: loading velocity; thresholds are ``start_factor * V_s`` (trigger) and
    ``end_factor * V_s`` (onset/end level). min_duration, merge_gap,
    strength_window: time units; min_slip: grain diameters. ``x_wall=None``
    integrates ``v_wall`` (trapezoid, x[0] = 0); missing tau or porosity give NaN
    strengths, stress drops or porosity changes.
    """
    p = _params(V_s, start_factor, end_factor, min_duration, min_slip, merge_gap,
                strength_window, subevent_fraction, min_subevent_fraction)
    lo, hi = p["lo"], p["hi"]
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
    raws: list[dict] = []
    window_start = 0
    for a, b in zip(starts, stops):
        if a == 0 or b == n - 1:
            continue
        seg = v[a:b + 1]
        if seg.max() < hi:
            continue
        fa = _crossing_fraction(v[a - 1], v[a], lo)
        fb = _crossing_fraction(v[b], v[b + 1], lo)
        if p["strength_window"] is None:
            strength = _nan_extreme(tau[window_start:a + 1], np.max)
        else:
            j0 = int(np.searchsorted(t, t[a] - p["strength_window"], side="left"))
            strength = _nan_extreme(tau[j0:a + 1], np.max)
        k = int(np.argmax(seg))
        sub = _sub_start(int(a), float(t[a]), float(v[a]))
        for j in range(a + 1, b + 1):
            _sub_step(sub, j, float(t[j]), float(v[j]), hi, p["subevent_fraction"])
        raws.append({
            "a": int(a), "b": int(b),
            "t_on": _lerp(float(t[a - 1]), float(t[a]), fa),
            "x_on": _lerp(float(x[a - 1]), float(x[a]), fa),
            "phi_on": _lerp(float(phi[a - 1]), float(phi[a]), fa),
            "t_end": _lerp(float(t[b]), float(t[b + 1]), fb),
            "x_end": _lerp(float(x[b]), float(x[b + 1]), fb),
            "phi_end": _lerp(float(phi[b]), float(phi[b + 1]), fb),
            "tau_on": float(tau[a]),
            "strength": strength,
            "peak_v": float(seg[k]), "peak_i": int(a + k), "peak_t": float(t[a + k]),
            "tau_min": _nan_extreme(tau[a:b + 2], np.min),
            "subs": _sub_list(sub),
            "n_merged": 1,
        })
        window_start = b + 1

    merged: list[dict] = []
    for r in raws:
        if merged and r["t_on"] - merged[-1]["t_end"] <= p["merge_gap"]:
            prev = merged[-1]
            gap_min = _nan_extreme(tau[prev["b"] + 2:r["a"]], np.min)
            merged[-1] = _merge(prev, r, gap_min)
        else:
            merged.append(r)
    return [s for s in (_finalize(m, p) for m in merged) if s is not None]


class SlipDetector:
    """Streaming form of :func:`detect_slips`: feed one sample at a time.

    ``update`` returns a :class:`Slip` on the sample at which it is known to be
    finished (the first sample after its end when ``merge_gap == 0``; later
    ones while a merge is still possible), else ``None``. ``flush`` returns the
    event still waiting at the end of a series. The state is plain numbers,
    lists and dicts: ``state_dict()`` / ``from_state_dict()`` save and restore it.
    """

    def __init__(
        self,
        V_s: float,
        start_factor: float = SLIP_START_FACTOR,
        end_factor: float = SLIP_END_FACTOR,
        min_duration: float = 0.0,
        min_slip: float = 0.0,
        merge_gap: float = 0.0,
        *,
        strength_window: float | None = None,
        subevent_fraction: float = 0.5,
        min_subevent_fraction: float = 0.1,
    ):
        self.params = _params(V_s, start_factor, end_factor, min_duration, min_slip,
                              merge_gap, strength_window, subevent_fraction,
                              min_subevent_fraction)
        self.n = 0
        self.armed = False
        self.prev: list[float] | None = None
        self.smax = _NAN
        self.sdeque: list[list[float]] = []
        self.raw: dict | None = None
        self.pending: dict | None = None

    def state_dict(self) -> dict:
        """Deep copy of the whole state as plain Python objects."""
        return copy.deepcopy({
            "params": self.params, "n": self.n, "armed": self.armed,
            "prev": self.prev, "smax": self.smax, "sdeque": self.sdeque,
            "raw": self.raw, "pending": self.pending,
        })

    @classmethod
    def from_state_dict(cls, state: dict) -> "SlipDetector":
        p = state["params"]
        det = cls(p["V_s"], p["start_factor"], p["end_factor"], p["min_duration"],
                  p["min_slip"], p["merge_gap"], strength_window=p["strength_window"],
                  subevent_fraction=p["subevent_fraction"],
                  min_subevent_fraction=p["min_subevent_fraction"])
        s = copy.deepcopy(state)
        det.n, det.armed, det.prev = s["n"], s["armed"], s["prev"]
        det.smax, det.sdeque = s["smax"], s["sdeque"]
        det.raw, det.pending = s["raw"], s["pending"]
        return det

    def _strength_push(self, t: float, tau: float) -> None:
        if math.isnan(tau):
            return
        if self.params["strength_window"] is None:
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
        cut = t - self.params["strength_window"]
        while dq and dq[0][0] < cut:
            dq.pop(0)

    def _strength(self, t: float) -> float:
        if self.params["strength_window"] is None:
            return self.smax
        self._strength_prune(t)
        return self.sdeque[0][1] if self.sdeque else _NAN

    def update(self, t: float, x: float, v: float, tau_over_sigma: float = _NAN,
               porosity: float = _NAN) -> Slip | None:
        """Add one sample; return a finished slip or ``None``."""
        p = self.params
        lo, hi, gap = p["lo"], p["hi"], p["merge_gap"]
        t, x, v = float(t), float(x), float(v)
        if not math.isfinite(v):
            raise ValueError("v must be finite")
        tau, phi = float(tau_over_sigma), float(porosity)
        i = self.n
        self.n += 1
        raw = self.raw

        if raw is not None and v < lo:
            t0, x0, v0, _, phi0 = self.prev
            fb = _crossing_fraction(v0, v, lo)
            raw.update(b=i - 1, t_end=_lerp(t0, t, fb), x_end=_lerp(x0, x, fb),
                       phi_end=_lerp(phi0, phi, fb), tau_min=_nanmin2(raw["tau_min"], tau))
            self.raw = None
            if raw["triggered"]:
                raw["subs"] = _sub_list(raw.pop("sub"))
                del raw["triggered"]
                if self.pending is not None:
                    self.pending = _merge(self.pending, raw, self.pending["gap_min"])
                else:
                    self.pending = raw
                self.pending["gap_min"] = _NAN
                self.smax = _NAN
        elif raw is not None:
            raw["triggered"] = raw["triggered"] or v >= hi
            if v > raw["peak_v"]:
                raw["peak_v"], raw["peak_i"], raw["peak_t"] = v, i, t
            raw["tau_min"] = _nanmin2(raw["tau_min"], tau)
            _sub_step(raw["sub"], i, t, v, hi, p["subevent_fraction"])

        self._strength_push(t, tau)

        if self.raw is None and raw is None and self.armed and v >= lo:
            t0, x0, v0, _, phi0 = self.prev
            fa = _crossing_fraction(v0, v, lo)
            self.raw = {
                "a": i, "t_on": _lerp(t0, t, fa), "x_on": _lerp(x0, x, fa),
                "phi_on": _lerp(phi0, phi, fa), "tau_on": tau,
                "strength": self._strength(t), "triggered": v >= hi,
                "peak_v": v, "peak_i": i, "peak_t": t, "tau_min": tau,
                "sub": _sub_start(i, t, v), "n_merged": 1,
            }
        if v < lo:
            self.armed = True
        self.prev = [t, x, v, tau, phi]

        pend = self.pending
        if pend is None:
            return None
        if i > pend["b"] + 1:
            pend["gap_min"] = _nanmin2(pend["gap_min"], tau)
        cand = self.raw
        if cand is None:
            ready = t - pend["t_end"] > gap
        else:
            ready = cand["t_on"] - pend["t_end"] > gap
        if not ready:
            return None
        self.pending = None
        return _finalize(pend, p)

    def flush(self) -> Slip | None:
        """Finish the event waiting at the end of the series (if any)."""
        pend, self.pending = self.pending, None
        return None if pend is None else _finalize(pend, self.params)


def recurrence_intervals(slips: list[Slip]) -> np.ndarray:
    """Onset-to-onset times between consecutive slips, shape (len(slips) - 1,)."""
    on = np.array([s.onset_time for s in slips], dtype=float)
    return np.diff(on)
