"""The campaign table: one row per run and per drained/undrained pair, and the phase-diagram cells.

A run's row (:func:`run_row`) and a fork's pair rows (:func:`fork_rows`) are read from run files
(through :mod:`gouge_cli.io.runreader`) once, when the piece finishes, into its results record;
the table is assembled from those records (:func:`gouge_cli.workflows.campaign_tables.table_rows`).
Pairs are classified by :func:`~gouge_cli.analysis.forkpairs.classify_fork` (thesis Sections
4.2-4.3: Type I / II, -C).
Swept values are the resolved (dimensionless) config values; ``permeability`` of a pair row is
the kappa_c [d^2] of its undrained branch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .catalog import catalog_table, read_catalog, summary_statistics
from .forkpairs import classify_fork, PAIR_COLUMNS
from .report import _write_csv
from .study import transient_slips
from ..io.runreader import RunReader

PHASE_COLUMNS = ("x", "y", "n_pairs", "n_unclassified", "n_seeds", "n_complex", "n_type_I", "n_type_II",
                 "frac_complex", "frac_complex_lo", "frac_complex_hi", "frac_type_II", "frac_type_II_lo",
                 "frac_type_II_hi", "de_column", "de_median", "de_min", "de_max")
RUN_STATS = ("stress_drop", "peak_velocity_over_Vs", "duration", "recurrence", "static_strength", "slip")
_NAN = float("nan")


def run_row(run_dir: Path) -> tuple[dict, list[int]]:
    """A run's table row (status, n_slips and, per statistic of :data:`RUN_STATS`, its mean and
    std over the run's slips: velocities over V_s, times [t0], slip [d]) and its transient slips
    (:func:`~gouge_cli.analysis.study.transient_slips`)."""
    with RunReader(run_dir) as reader:
        catalog = read_catalog(reader)
        table = catalog_table(reader, catalog)
        status = reader.info.status
    stats = summary_statistics(table, RUN_STATS)
    row = {"status": status, "n_slips": len(table)}
    for key in RUN_STATS:
        row[f"{key}_mean"], row[f"{key}_std"] = stats[key]["mean"], stats[key]["std"]
    return row, sorted(transient_slips(catalog))


def reload_columns(row: dict, sigma: float, k: float, V: float) -> dict:
    """The loading's own clock for a run row: ``recurrence_reload`` = stress_drop_mean sigma / (k V)
    [t0], the time the spring (k per length [E/d], pulled at V [v0]) takes to give back a mean drop
    at normal stress sigma [E], and ``recurrence_ratio`` = recurrence_mean / that. A layer that
    sticks rigidly between slips has ratio 1; creep and hardening before a slip make it larger.
    With sigma swept, the ratio says whether the recurrence scales with drop x sigma (issue 63)."""
    drop, recurrence = row.get("stress_drop_mean", _NAN), row.get("recurrence_mean", _NAN)
    reload = drop * sigma / (k * V) if k * V > 0 else _NAN
    return {"recurrence_reload": reload, "recurrence_ratio": recurrence / reload if reload > 0 else _NAN}


def fork_rows(fork_dir: Path, permeabilities: list[float]) -> list[dict]:
    """The pair rows (:data:`PAIR_COLUMNS` but ``run``) of one fork's undrained branches at the
    listed permeabilities, classified by :func:`~gouge_cli.analysis.forkpairs.classify_fork`."""
    return [{c: pair.row[c] for c in PAIR_COLUMNS if c != "run"} for pair in classify_fork(fork_dir)
            if _listed(float(pair.permeability), permeabilities)]


@dataclass(frozen=True)
class RowPair:
    """A classified pair rebuilt from its table row (what the campaign figures read, as of a
    ForkPair: ``permeability``, ``regime`` and a ``result`` with type, base_type, complex,
    undrained_event, criteria and the ratios)."""

    row: dict

    @property
    def permeability(self) -> float:
        return float(self.row["permeability"])

    @property
    def regime(self) -> str:
        return self.row["regime"]

    @property
    def result(self):
        from types import SimpleNamespace

        from .pairs import CRITERIA, RATIOS

        fired = set(str(self.row.get("criteria") or "").split(","))
        return SimpleNamespace(type=self.row["type"], base_type=self.row["base_type"],
                               complex=bool(self.row["complex"]), undrained_event=self.row["undrained_event"],
                               criteria={c: c in fired for c in CRITERIA},
                               **{r: float(self.row[r]) for r in RATIOS})


def _listed(perm: float, perms: list[float]) -> bool:
    return any(math.isclose(perm, k, rel_tol=1e-9) for k in perms)


def pairs_by_permeability(pair_rows: list[dict]) -> dict[float, list[RowPair]]:
    """The pair rows grouped by kappa_c [d^2] (never pooled), as :class:`RowPair`."""
    out: dict[float, list[RowPair]] = {}
    for r in pair_rows:
        out.setdefault(float(r["permeability"]), []).append(RowPair(r))
    return out


def _axis_value(row: dict, key: str | None):
    return None if key is None else float(row[key])


def phase_cells(pair_rows: list[dict], x: str, y: str | None) -> list[dict]:
    """Fractions of complex (-C) and of Type II pairs per (x, y) cell (thesis future work A).

    n_pairs counts the classified pairs (a slip in both branches; ties included); n_unclassified
    the pairs where a branch did not slip in its window. Fractions are over n_pairs (NaN when 0),
    each with its seed-level 95 % interval (``_lo``, ``_hi``: :func:`.seedboot.seed_fraction`,
    the seed as the sampling unit, since a seed's pairs share one packing); n_seeds: the seeds
    with a classified pair in the cell (rows without a ``seed`` column count as one seed); the
    intervals are NaN for a single seed, as in the regime map (:func:`.regime.seed_interval`).
    de_median, de_min, de_max: the measured De over the classified pairs (``de_column``:
    :func:`.regime.pair_deborah`, the slip's where the pairs have it), for reading the cell by De."""
    from .regime import pair_deborah, seed_interval

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
            seeds: dict = {}
            for r in classified:
                seeds.setdefault(r.get("seed"), []).append(r)
            c_lo, c_hi = seed_interval(list(seeds.values()), "complex")
            t_lo, t_hi = seed_interval(list(seeds.values()), "type_II")
            de_column, de = pair_deborah(classified)
            cells.append({"x": xv, "y": yv, "n_pairs": n, "n_unclassified": len(inside) - n, "n_seeds": len(seeds),
                          "n_complex": n_c, "n_type_I": n_1, "n_type_II": n_2,
                          "frac_complex": n_c / n if n else _NAN, "frac_complex_lo": c_lo, "frac_complex_hi": c_hi,
                          "frac_type_II": n_2 / n if n else _NAN, "frac_type_II_lo": t_lo, "frac_type_II_hi": t_hi,
                          "de_column": de_column, "de_median": float(np.median(de)) if de else _NAN,
                          "de_min": min(de) if de else _NAN, "de_max": max(de) if de else _NAN})
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
