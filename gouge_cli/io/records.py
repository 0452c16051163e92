"""Typed records: frozen dataclasses whose fields carry their unit and meaning (:func:`unit`, as
field metadata), turned into plain dicts for JSON and CSV in one place (:func:`plain`).

Units are the symbols of docs/physics/units.md ('-' for ratios, counts and labels). A field whose
name in the files is no Python name (``"I-C"``) gives it as ``key``. A new quantity of a record
is one field: its dict, JSON and CSV forms and its unit follow from the declaration.
"""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["unit", "keys", "units", "plain"]


def unit(symbol: str, doc: str = "", *, key: str | None = None, default: Any = dataclasses.MISSING,
         default_factory: Any = dataclasses.MISSING) -> Any:
    """A record field with its unit ``symbol``, a line of description and, where the files spell
    it otherwise, its ``key`` there."""
    meta = {"unit": symbol, "doc": doc}
    if key is not None:
        meta["key"] = key
    return dataclasses.field(default=default, default_factory=default_factory, metadata=meta)


def _key(f: dataclasses.Field) -> str:
    return f.metadata.get("key", f.name)


def keys(record) -> tuple[str, ...]:
    """The record class's (or record's) keys in the files, in field order."""
    return tuple(_key(f) for f in dataclasses.fields(record))


def units(record) -> dict[str, str]:
    """{key: unit} of the record class's (or record's) fields ('-' where none is declared)."""
    return {_key(f): f.metadata.get("unit", "-") for f in dataclasses.fields(record)}


def plain(obj):
    """``obj`` as plain Python for JSON and CSV: a record becomes ``{key: value}`` in field order,
    records inside it (and inside dicts, lists and tuples) likewise; everything else as it is."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {_key(f): plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [plain(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(plain(v) for v in obj)
    return obj
