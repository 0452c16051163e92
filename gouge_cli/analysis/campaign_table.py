"""The campaign table: one row per run and per drained/undrained pair, and the phase-diagram cells.

Reads run files only (through :mod:`gouge_cli.io.runfile`); pairs are classified by
:func:`~gouge_cli.analysis.forkpairs.classify_fork` (thesis Sections 4.2-4.3: Type I / II, -C).
Swept values are the resolved (dimensionless) config values; ``permeability`` of a pair row is
the kappa_c [d^2] of its undrained branch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from .catalog import catalog_table, read_catalog, summary_statistics
from .forkpairs import classify_fork, ForkPair, PAIR_COLUMNS
from .report import _write_csv
from .study import transient_slips
from ..io.layout import RunLayout
from ..io.runfile import RunReader

PHASE_COLUMNS = ("x", "y", "n_pairs", "n_unclassified", "n_complex", "n_type_I", "n_type_II", "frac_complex",
                 "frac_type_II")
RUN_STATS = ("stress_drop", "peak_velocity_over_Vs", "duration", "recurrence", "static_strength", "slip")
_NAN = float("nan")


@dataclass
class CampaignPoint:
    """A finished point: its run directory, swept values, forked slips and study permeabilities."""

    name: str
    run_dir: Path
    values: dict
    fork_slips: list[int] = field(default_factory=list)
    permeabilities: list[float] = field(default_factory=list)


def _listed(perm: float, perms: list[float]) -> bool:
    return any(math.isclose(perm, k, rel_tol=1e-9) for k in perms)


def campaign_table(points: list[CampaignPoint]) -> tuple[list[dict], dict[float, list[ForkPair]]]:
    """Rows (``kind`` 'run' or 'pair') and the classified pairs grouped by permeability.

    Run rows: n_slips and, per statistic of :data:`RUN_STATS`, its mean and std over the run's
    slips (velocities over V_s, times [t0], slip [d]). Pair rows: :data:`PAIR_COLUMNS` of
    report.py (type, -C criteria, undrained/drained ratios, De at onset and largest) for each listed
    permeability, and ``transient`` (the slip is transient by analysis.study.transient_slips)."""
    rows, by_perm = [], {}
    for p in points:
        with RunReader(p.run_dir) as reader:
            table = catalog_table(reader, read_catalog(reader))
            status = reader.info.status
            transient = transient_slips(read_catalog(reader))
        stats = summary_statistics(table, RUN_STATS)
        row = {"kind": "run", "point": p.name, **p.values, "status": status, "n_slips": len(table)}
        for key in RUN_STATS:
            row[f"{key}_mean"], row[f"{key}_std"] = stats[key]["mean"], stats[key]["std"]
        rows.append(row)
        for slip in p.fork_slips:
            for pair in classify_fork(RunLayout(p.run_dir).fork(slip).root):
                perm = float(pair.row["permeability"])
                if not _listed(perm, p.permeabilities):
                    continue
                rows.append({"kind": "pair", "point": p.name, **p.values,
                             **{c: pair.row[c] for c in PAIR_COLUMNS if c != "run"},
                             "transient": int(pair.row["slip"]) in transient})
                by_perm.setdefault(perm, []).append(pair)
    return rows, by_perm


def _axis_value(row: dict, key: str | None):
    return None if key is None else float(row[key])


def phase_cells(pair_rows: list[dict], x: str, y: str | None) -> list[dict]:
    """Fractions of complex (-C) and of Type II pairs per (x, y) cell (thesis future work A).

    n_pairs counts the classified pairs (a slip in both branches; ties included); n_unclassified
    the pairs where a branch did not slip in its window. Fractions are over n_pairs (NaN when 0)."""
    xs = sorted({_axis_value(r, x) for r in pair_rows})
    ys = sorted({_axis_value(r, y) for r in pair_rows}) if y else [None]
    cells = []
    for yv in ys:
        for xv in xs:
            inside = [r for r in pair_rows if _axis_value(r, x) == xv and _axis_value(r, y) == yv]
            classified = [r for r in inside if r["base_type"] not in ("none", "failed")]
            n = len(classified)
            n_c = sum(1 for r in classified if r["complex"])
            n_1 = sum(1 for r in classified if r["base_type"] == "I")
            n_2 = sum(1 for r in classified if r["base_type"] == "II")
            cells.append({"x": xv, "y": yv, "n_pairs": n, "n_unclassified": len(inside) - n,
                          "n_complex": n_c, "n_type_I": n_1, "n_type_II": n_2,
                          "frac_complex": n_c / n if n else _NAN, "frac_type_II": n_2 / n if n else _NAN})
    return cells


def write_table(rows: list[dict], first: list[str], path: Path, columns: list[str] | None = None) -> Path:
    """CSV with ``columns`` (default: kind, point, the ``first`` keys, then every other key in
    order of appearance)."""
    if columns is None:
        columns = ["kind", "point"] + list(first)
        for r in rows:
            columns += [k for k in r if k not in columns]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_csv(path, rows, columns)
    return path
