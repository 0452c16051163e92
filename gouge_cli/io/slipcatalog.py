"""A run's slip catalog: :class:`SlipEntry`, the typed record of one slip, and its one reader
(:func:`read_slips`, :func:`slip_catalog`). The writer is RunFile.add_slip (``/slips/NNN``: an
entry's :meth:`SlipEntry.attrs` as attributes, its sub-events as datasets); units of each
attribute are documented in the file itself (gouge_cli.io.filedoc SLIP_ATTRS)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import h5py

from ..model.slip_rule import Slip, SubEvent
from .integrity import SEAL, attr_value, check_seal, read, stored_seal
from .layout import RunLayout
from .rundir import open_run_file

_NAN = float("nan")


@dataclass(frozen=True, kw_only=True)
class SlipEntry(Slip):
    """One slip of a run's catalog: the detector's :class:`~gouge_cli.model.slip_rule.Slip`
    (dimensionless: times [t0], slip [d], velocities [v0], strengths and drops tau/sigma, indices
    series samples) with what the recorder adds: number (from 1), deborah (mean De over the slip
    [-], NaN dry or detected afterwards), checkpoint (the pre-slip checkpoint relative to the run
    directory, "" if none) and checkpoint_time [t0] (NaN if none). Sub-events read from a file have
    index -1 (only their time and velocity are stored). A field an older file lacks reads as NaN
    (floats), -1 (indices) or 1 (n_merged).
    """

    number: int
    deborah: float = _NAN
    checkpoint: str = ""
    checkpoint_time: float = _NAN

    SUBEVENTS = ("subevent_time", "subevent_velocity")     # the datasets holding the sub-events

    @classmethod
    def from_slip(cls, slip: Slip, number: int, **recorded) -> "SlipEntry":
        """The entry of detected `slip` numbered `number`; `recorded`: deborah, checkpoint,
        checkpoint_time (the recorder's)."""
        values = {f.name: getattr(slip, f.name) for f in fields(Slip)}
        values["subevents"] = tuple(slip.subevents)
        return cls(**values, number=number, **recorded)

    @classmethod
    def from_attrs(cls, attrs: dict) -> "SlipEntry":
        """From a /slips/NNN group's decoded attributes and its sub-event lists (other keys ignored)."""
        values = {f.name: attrs[f.name] for f in fields(cls) if f.name in attrs}
        for f in fields(Slip):
            if f.name not in values and f.name != "subevents":
                values[f.name] = -1 if f.name.endswith("_index") else 1 if f.name == "n_merged" else _NAN
        values["subevents"] = tuple(SubEvent(-1, float(t), float(v)) for t, v in
                                    zip(attrs.get("subevent_time", ()), attrs.get("subevent_velocity", ())))
        return cls(**values)

    @property
    def subevent_time(self) -> tuple[float, ...]:
        """(S,) [t0] clock of each sub-event."""
        return tuple(s.time for s in self.subevents)

    @property
    def subevent_velocity(self) -> tuple[float, ...]:
        """(S,) [v0] top-wall velocity at each sub-event."""
        return tuple(s.velocity for s in self.subevents)

    def attrs(self) -> dict:
        """The run file's attributes of this slip: every field but the sub-events, in field order."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "subevents"}

    def to_dict(self) -> dict:
        """Plain-dict form as the run file lists it: attributes by name, then the sub-event lists."""
        attrs = self.attrs()
        return {**{k: attrs[k] for k in sorted(attrs)}, **{k: list(getattr(self, k)) for k in self.SUBEVENTS}}


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
