"""The /analysis tables `gouge analyze` writes into run.h5 (layout: :mod:`gouge_cli.io.runfile`)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import h5py
import numpy as np

from .. import __version__
from .filedoc import document_analysis
from .integrity import checked_dataset, seal_tree
from .outputs import preallocate


def _table_to_group(group: h5py.Group, rows: list[dict], columns) -> None:
    group.attrs["columns"] = json.dumps(list(columns))
    for col in columns:
        values = [r.get(col) for r in rows]
        if all(isinstance(v, (bool, np.bool_)) for v in values) and values:
            checked_dataset(group, col, np.asarray(values, dtype=bool))
        elif all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
                 for v in values):
            checked_dataset(group, col, np.asarray(values, dtype=float))
        else:       # text: chunked (written by this call) without filters, which HDF5 refuses for it
            group.create_dataset(col, data=np.asarray(["" if v is None else str(v) for v in values],
                                                      dtype=h5py.string_dtype()), chunks=True)


def analysis_bytes(tables: dict) -> int:
    """Bytes ``/analysis`` may take in run.h5, over-estimated: 40 columns of 64 bytes a row, and
    1 MB for its attributes, descriptions and seals; `tables` as in write_analysis_tables."""
    return 64 * 40 * sum(len(rows) for rows, _ in tables.values()) + 1_000_000


def write_analysis_tables(h5_path: Path, notch: bool, summary: str, tables: dict,
                          units: dict[str, dict[str, str]] | None = None) -> None:
    """Replace ``/analysis`` in run.h5 (written by `gouge analyze`): attrs created, version, notch,
    summary (JSON); one group per table, `tables` = {name: (rows as dicts, columns)}, one dataset
    per column, its unit from `units` = {name: {column: unit}} (filedoc.ANALYSIS_UNITS for a table
    not in it). Its room (analysis_bytes) is allocated first (io.outputs.preallocate): ENOSPC then,
    with nothing written. Raises OSError if the file cannot be written (read-only, or open elsewhere)."""
    preallocate(h5_path, analysis_bytes(tables))
    with h5py.File(h5_path, "a", rdcc_nbytes=0) as h5:       # (written by each call: RunFile's rule)
        if "analysis" in h5:
            del h5["analysis"]
        grp = h5.create_group("analysis")
        grp.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        grp.attrs["version"] = __version__
        grp.attrs["notch"] = notch
        grp.attrs["summary"] = summary
        for name, (rows, columns) in tables.items():
            _table_to_group(grp.create_group(name), rows, columns)
        document_analysis(grp, units or {})
        seal_tree(grp)
