"""The records of the slip rule (:mod:`gouge_cli.model.slip_rule`): a detected :class:`Slip` and its
:class:`SubEvent` s, and the event under construction that both detectors, batch and streaming,
build and finish with the same helpers (so that they give the same slips)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .slip_rule import SlipRule

_NAN = float("nan")


@dataclass(frozen=True)
class SubEvent:
    """One local velocity maximum inside a slip (index: its series sample, -1 where not stored)."""

    index: int
    time: float
    velocity: float


@dataclass(frozen=True)
class Slip:
    """One detected slip event (dimensionless units; indices into the series). A run's catalog
    keeps it as io.slipcatalog.SlipEntry, this record with its number and checkpoint."""

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
class SubTracker:
    """Sub-event tracker of one raw event: the sub-events done ([index, time, velocity] each), the
    current peak, and the lowest velocity since it (None: still rising)."""

    done: list
    peak_index: int
    peak_time: float
    peak_velocity: float
    min_velocity: float | None = None

    # the one- and two-letter keys of checkpoints written before these records were typed
    OLD_KEYS = {"pi": "peak_index", "pt": "peak_time", "pv": "peak_velocity", "mv": "min_velocity"}

    @classmethod
    def from_state(cls, d: dict) -> "SubTracker":
        return cls(**{cls.OLD_KEYS.get(k, k): v for k, v in d.items()})


@dataclass
class OpenEvent:
    """A raw event (lo crossings of one run above lo) or several merged ones, while it is built."""

    onset_index: int
    onset_time: float
    onset_x: float
    onset_porosity: float
    tau_onset: float
    strength: float
    peak_velocity: float
    peak_index: int
    peak_time: float
    tau_min: float
    n_merged: int = 1
    end_index: int = -1
    end_time: float = _NAN
    end_x: float = _NAN
    end_porosity: float = _NAN
    subs: list = field(default_factory=list)
    # streaming detector only: whether v reached hi, the sub-event tracker while the event runs,
    # the lowest tau/sigma in the gap after it (merging)
    triggered: bool = True
    sub: SubTracker | None = None
    gap_min: float = _NAN

    OLD_KEYS = {"a": "onset_index", "b": "end_index", "t_on": "onset_time", "x_on": "onset_x",
                "phi_on": "onset_porosity", "t_end": "end_time", "x_end": "end_x", "phi_end": "end_porosity",
                "tau_on": "tau_onset", "peak_v": "peak_velocity", "peak_i": "peak_index", "peak_t": "peak_time"}

    def state(self) -> dict:
        return asdict(self)

    @classmethod
    def from_state(cls, d: dict | None) -> "OpenEvent | None":
        if d is None:
            return None
        values = {cls.OLD_KEYS.get(k, k): v for k, v in d.items()}
        if values.get("sub") is not None:
            values["sub"] = SubTracker.from_state(values["sub"])
        return cls(**values)


def lerp(y0: float, y1: float, f: float) -> float:
    return y0 + f * (y1 - y0)


def crossing_fraction(v0: float, v1: float, level: float) -> float:
    return (level - v0) / (v1 - v0)


def sub_start(i: int, t: float, v: float) -> SubTracker:
    return SubTracker([], i, t, v, None)


def sub_step(s: SubTracker, i: int, t: float, v: float, hi: float, frac: float) -> None:
    """Advance the sub-event tracker ``s`` by one sample (shared by both detectors)."""
    m = s.min_velocity
    if m is None:
        if v > s.peak_velocity:
            s.peak_index, s.peak_time, s.peak_velocity = i, t, v
        else:
            s.min_velocity = v
        return
    low = min(s.peak_velocity, v)
    if low >= hi and (m < frac * low or m < hi):
        s.done.append([s.peak_index, s.peak_time, s.peak_velocity])
        s.peak_index, s.peak_time, s.peak_velocity, s.min_velocity = i, t, v, None
    elif v > s.peak_velocity:
        s.peak_index, s.peak_time, s.peak_velocity, s.min_velocity = i, t, v, None
    elif v < m:
        s.min_velocity = v


def sub_list(s: SubTracker) -> list[list]:
    return s.done + [[s.peak_index, s.peak_time, s.peak_velocity]]


def nanmin2(a: float, b: float) -> float:
    if math.isnan(a):
        return b
    if math.isnan(b):
        return a
    return a if a <= b else b


def merge_events(p: OpenEvent, r: OpenEvent, gap_min: float) -> OpenEvent:
    """Merge raw event ``r`` into pending event ``p``."""
    out = replace(p)
    if r.peak_velocity > p.peak_velocity:
        out.peak_velocity, out.peak_index, out.peak_time = r.peak_velocity, r.peak_index, r.peak_time
    out.tau_min = nanmin2(nanmin2(p.tau_min, gap_min), r.tau_min)
    out.subs = p.subs + r.subs
    out.end_index, out.end_time, out.end_x, out.end_porosity = r.end_index, r.end_time, r.end_x, r.end_porosity
    out.n_merged = p.n_merged + r.n_merged
    return out


def finalize(acc: OpenEvent, rule: SlipRule) -> Slip | None:
    duration = acc.end_time - acc.onset_time
    slip = acc.end_x - acc.onset_x
    if duration < rule.min_duration or slip < rule.min_slip:
        return None
    keep = rule.min_subevent_fraction * acc.peak_velocity
    subs = [SubEvent(int(i), float(t), float(v)) for i, t, v in acc.subs if v >= keep]
    tau_on = acc.tau_onset
    return Slip(
        onset_index=int(acc.onset_index),
        onset_time=float(acc.onset_time),
        end_index=int(acc.end_index),
        end_time=float(acc.end_time),
        duration=float(duration),
        slip=float(slip),
        peak_velocity=float(acc.peak_velocity),
        peak_index=int(acc.peak_index),
        peak_time=float(acc.peak_time),
        mean_velocity=float(slip / duration) if duration > 0 else _NAN,
        static_strength=float(acc.strength),
        tau_onset=float(tau_on),
        tau_min=float(acc.tau_min),
        stress_drop=float(tau_on - acc.tau_min),
        porosity_change=float(acc.end_porosity - acc.onset_porosity),
        subevents=subs,
        n_merged=int(acc.n_merged),
    )
