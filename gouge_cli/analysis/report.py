"""What `gouge analyze` reports for a run (thesis Sections IV-V): the slip catalog and fits
(analysis.catalog), the drained/undrained fork pairs (analysis.forkpairs) and their summary, written
as RUN/analysis/*.csv, summary.json and /analysis in run.h5 (through io.analysis_tables).

Reads only: ``RUN/run.h5`` (io.runreader.RunReader) and the forks under
``RUN/forks/slip_NNN/{drained,perm_K}/run.h5``. All quantities are dimensionless (length d,
stress E, time t0; docs/physics/units.md). Errors are gouge_cli.errors.AnalysisError (subclasses
name the case); the CLI turns them into exit code 2.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import NoSlipsError
from ..io.filedoc import json_safe
from ..io.outputs import is_no_space, require_space, write_bytes
from ..io.analysis_tables import analysis_bytes, write_analysis_tables
from ..io.runreader import RunInfo, RunReader
from .catalog import CATALOG_COLUMNS, FIT_COLUMNS, catalog_table, fit_table, read_catalog, summary_statistics
from .forkpairs import PAIR_COLUMNS, PAIR_UNITS, ForkPair, campaign, run_pairs

__all__ = ["RunAnalysis", "analyze_run", "write_analysis"]


# --------------------------------------------------------------------------- fits and friction


# --------------------------------------------------------------------------- pairs


# --------------------------------------------------------------------------- whole run


@dataclass
class RunAnalysis:
    """Everything `gouge analyze` computes for one run."""

    info: RunInfo
    catalog: list[dict]           # catalog_table rows
    summary: dict
    fits: list[dict]
    pairs: list[ForkPair]
    skipped: list[str]
    notch: bool

    @property
    def pair_rows(self) -> list[dict]:
        return [p.row for p in self.pairs]

    def fit_summary(self) -> dict:
        return summary_statistics(self.fits, ("half_period", "half_period_ratio", "delta_mu",
                                              "mean_dynamic_friction", "delta_mu_eq7", "r2"))

    def to_dict(self) -> dict:
        from ..units import ResultUnits

        return {
            "run": str(self.info.run_dir.resolve()),
            "time_origin": "loading start",
            "units": ResultUnits.of_run(self.info.config, self.info.V_s, self.info.sigma).as_dict(),
            "parameters": {"k": self.info.k, "V_s": self.info.V_s, "sigma": self.info.sigma,
                           "m_b": self.info.m_b, "predicted_half_period": self.info.predicted_half_period,
                           "has_fluid": self.info.has_fluid, "notch": self.notch},
            "catalog": self.catalog,
            "summary": self.summary,
            "fits": self.fits,
            "fit_summary": self.fit_summary(),
            "pairs": self.pair_rows,
            "campaign": campaign(self.pairs).to_dict() if self.pairs else None,
            "skipped_forks": self.skipped,
        }


def analyze_run(run_dir: Path | str, notch: bool = True, main: str = "first") -> RunAnalysis:
    """Catalog, summary statistics, block-slider fits and fork pairs of one run.

    Raises :class:`NotARunError`, :class:`RunStillRunningError` or :class:`NoSlipsError`.
    """
    with RunReader(run_dir) as reader:
        catalog = read_catalog(reader)
        if not catalog:
            info = reader.info
            raise NoSlipsError(
                f"{info.describe()} has no slips (status {info.status!r}, {info.n_samples} samples): "
                "run it longer (run.duration), load it faster, or lower slips.start_factor")
        rows = catalog_table(reader, catalog)
        fits = fit_table(reader, catalog, notch=notch)
        info = reader.info
    pairs, skipped = run_pairs(info.run_dir, main=main)
    return RunAnalysis(info, rows, summary_statistics(rows), fits, pairs, skipped, notch)


# --------------------------------------------------------------------------- writing


def _write_csv(path: Path, rows: list[dict], columns) -> None:
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=list(columns), extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({c: row.get(c, "") for c in columns})
    write_bytes(path, text.getvalue().encode())


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    return str(obj)


def write_analysis(analysis: RunAnalysis, out_dir: Path | None = None, into_h5: bool = True) -> dict[str, Path]:
    """Write ``RUN/analysis/{catalog,fits[,pairs]}.csv`` and ``summary.json``, and the same
    tables under ``/analysis`` in run.h5 (replaced on each call). Returns the written paths."""
    info = analysis.info
    out_dir = Path(out_dir) if out_dir is not None else info.run_dir / "analysis"
    out_dir.mkdir(parents=True, exist_ok=True)
    written = {}
    _write_csv(out_dir / "catalog.csv", analysis.catalog, CATALOG_COLUMNS)
    written["catalog"] = out_dir / "catalog.csv"
    _write_csv(out_dir / "fits.csv", analysis.fits, FIT_COLUMNS)
    written["fits"] = out_dir / "fits.csv"
    pairs_csv = out_dir / "pairs.csv"
    if analysis.pairs:
        _write_csv(pairs_csv, analysis.pair_rows, PAIR_COLUMNS)
        written["pairs"] = pairs_csv
    elif pairs_csv.exists():
        pairs_csv.unlink()
    summary = {k: v for k, v in analysis.to_dict().items() if k not in ("catalog", "fits", "pairs")}
    write_bytes(out_dir / "summary.json", json.dumps(json_safe(summary), indent=2, default=_json_default,
                                                     allow_nan=False).encode())
    written["summary"] = out_dir / "summary.json"
    if into_h5:
        tables = {"catalog": (analysis.catalog, CATALOG_COLUMNS), "fits": (analysis.fits, FIT_COLUMNS)}
        if analysis.pairs:
            tables["pairs"] = (analysis.pair_rows, PAIR_COLUMNS)
        # run.h5 is written in place: HDF5 must never meet a full disk there (its room allocated first)
        require_space(info.h5_path.parent, analysis_bytes(tables), f"the /analysis tables in {info.h5_path}")
        try:
            write_analysis_tables(info.h5_path, bool(analysis.notch),
                                  json.dumps(json_safe(summary), default=_json_default, allow_nan=False), tables,
                                  {"pairs": PAIR_UNITS})
        except OSError as exc:
            if is_no_space(exc):        # (another writer took the room after the check: nothing written)
                raise
            # the tables are in the CSV files already; run.h5 is left as it is (read-only, or open elsewhere)
            written["h5_skipped"] = (f"/analysis not written into {info.h5_path} "
                                     f"({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__}); "
                                     "the CSV files hold the same tables")
            return written
        written["h5"] = info.h5_path
    return written


# --------------------------------------------------------------------------- plotting support


