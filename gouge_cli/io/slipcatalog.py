"""A run's slip catalog: :class:`SlipEntry`, the typed record of one slip, and its one reader
(:func:`read_slips`, :func:`slip_catalog`). The writer is RunFile.add_slip (``/slips/NNN``: an
entry's :meth:`SlipEntry.attrs` as attributes, its sub-events as datasets); units of each
attribute are documented in the file itself (gouge_cli.io.filedoc SLIP_ATTRS)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import h5py

from ..model.slip_rule import Slip
from .integrity import SEAL, attr_value, check_seal, read, stored_seal
from .layout import RunLayout
from .rundir import open_run_file

_NAN = float("nan")


@dataclass(frozen=True)
class SlipEntry:
    """One slip of a run's catalog (dimensionless units: time t0, length d, velocity v0; indices
    are series samples in the detector's stream; strengths and drops are tau/sigma).

    The model.slip_rule.Slip fields (onset/end/peak index and time [t0], duration [t0], slip [d],
    peak/mean velocity [v0], static_strength, tau_onset, tau_min, stress_drop, porosity_change [-],
    n_merged), then: number (from 1), deborah (mean De over the slip, NaN dry or detected),
    checkpoint (pre-slip checkpoint relative to the run directory, "" if none), checkpoint_time
    [t0] (NaN if none), subevent_time [t0] and subevent_velocity [v0] (S,) of its sub-events.
    A field an older file lacks reads as NaN (floats), -1 (indices), 1 (n_merged) or "".
    """

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
    n_merged: int
    number: int
    deborah: float = _NAN
    checkpoint: str = ""
    checkpoint_time: float = _NAN
    subevent_time: tuple[float, ...] = ()
    subevent_velocity: tuple[float, ...] = ()

    SUBEVENTS = ("subevent_time", "subevent_velocity")     # stored as datasets, not attributes

    def __post_init__(self):
        """Every field as its plain Python type (numpy scalars from a detector unwrapped)."""
        for f in fields(self):
            value = getattr(self, f.name)
            kind = {"int": int, "float": float, "str": str}.get(f.type)
            value = tuple(float(v) for v in value) if f.name in self.SUBEVENTS else kind(value)
            object.__setattr__(self, f.name, value)

    @classmethod
    def from_slip(cls, slip: Slip, number: int, **recorded) -> "SlipEntry":
        """The entry of a detected `slip` numbered `number`; `recorded`: deborah, checkpoint,
        checkpoint_time (the recorder's)."""
        values = {f.name: getattr(slip, f.name) for f in fields(Slip) if f.name != "subevents"}
        return cls(**values, number=number, subevent_time=tuple(float(s.time) for s in slip.subevents),
                   subevent_velocity=tuple(float(s.velocity) for s in slip.subevents), **recorded)

    @classmethod
    def from_attrs(cls, attrs: dict) -> "SlipEntry":
        """From a /slips/NNN group's decoded attributes and sub-event lists (other keys ignored)."""
        values = {}
        for f in fields(cls):
            if f.name in attrs:
                value = attrs[f.name]
                values[f.name] = tuple(value) if f.name in cls.SUBEVENTS else value
            elif f.name in ("onset_index", "end_index", "peak_index"):
                values[f.name] = -1
            elif f.name == "n_merged":
                values[f.name] = 1
            elif f.name not in ("deborah", "checkpoint", "checkpoint_time", *cls.SUBEVENTS):
                values[f.name] = _NAN
        return cls(**values)

    @property
    def n_subevents(self) -> int:
        return len(self.subevent_time)

    @property
    def has_checkpoint(self) -> bool:
        return bool(self.checkpoint)

    def attrs(self) -> dict:
        """The run file's attributes of this slip (every field but the sub-events, in field order)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in self.SUBEVENTS}

    def to_dict(self) -> dict:
        """Plain-dict form as the run file lists it: attributes by name, then the sub-event lists."""
        attrs = self.attrs()
        return {**{k: attrs[k] for k in sorted(attrs)},
                **{k: list(getattr(self, k)) for k in self.SUBEVENTS}}


def read_slips(h5: h5py.File) -> list[SlipEntry] | None:
    """The /slips catalog of an open run file (one entry per slip, in order), its seals checked,
    or None if the run wrote none."""
    if "slips" not in h5:
        return None
    required = stored_seal(h5) is not None
    check_seal(h5["slips"], required)
    out = []
    for name in sorted(h5["slips"]):
        g = h5["slips"][name]
        check_seal(g, required)
        attrs = {k: attr_value(g.attrs, k) for k in g.attrs.keys() if k != SEAL}
        for key in SlipEntry.SUBEVENTS:
            if key in g:
                check_seal(g[key], required)
            attrs[key] = read(g[key]).tolist() if key in g else []
        out.append(SlipEntry.from_attrs(attrs))
    return out


def slip_catalog(run_dir: Path) -> list[SlipEntry]:
    """The run's slip catalog (one entry per slip, in order; [] if none)."""
    with open_run_file(RunLayout(run_dir).run_file) as h5:
        return read_slips(h5) or []


def find_entry(catalog: list[SlipEntry], number: int) -> SlipEntry | None:
    """The entry numbered `number`, None if absent."""
    return next((e for e in catalog if e.number == number), None)
