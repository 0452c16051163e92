"""`gouge analyze` and `gouge plot`: thin wrappers over gouge_cli.analysis (report, catalog) and gouge_cli.plots.

Registered on the main typer app by :func:`register` (called at the end of cli/main.py).
Bad input (not a run, still running, no slips, no such slip) exits with code 2.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import List, Optional

import typer

from ..io.filedoc import json_safe


def _fmt(value, digits: int = 4) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "–" if not math.isfinite(value) else f"{value:.{digits}g}"
    return "" if value is None else str(value)


def _table(title: str, columns: list[tuple[str, str]], rows: list[dict]):
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for _, header in columns:
        table.add_column(header, justify="right")
    for row in rows:
        table.add_row(*[_fmt(row.get(key)) for key, _ in columns])
    return table


_CATALOG = [("number", "#"), ("onset_since_loading", "onset t/t0 (since loading)"), ("duration", "duration/t0"),
            ("static_strength", "τs/σ"), ("stress_drop", "Δτ/σ"), ("peak_velocity_over_Vs", "vpeak/Vs"),
            ("mean_velocity_over_Vs", "vmean/Vs"), ("slip", "slip/d"), ("recurrence", "recurrence/t0"),
            ("n_subevents", "sub"), ("deborah", "De")]
_FITS = [("number", "#"), ("duration", "duration"), ("half_period", "fit T/2"),
         ("predicted_half_period", "π√(m_b/k)"), ("half_period_ratio", "ratio"),
         ("amplitude_over_Vs", "A/Vs"), ("delta_mu", "Δμ Eq.3"), ("static_friction", "μs"),
         ("mean_dynamic_friction", "μd Eq.7"), ("delta_mu_eq7", "Δμ Eq.7"), ("r2", "R²")]
_PAIRS = [("slip", "slip"), ("branch", "branch"), ("type", "type"), ("criteria", "-C criteria"),
          ("drained_strength", "S_d"), ("undrained_strength", "S_u"), ("strength_difference", "S_u−S_d"),
          ("peak_velocity_ratio", "v ratio"), ("stress_drop_ratio", "Δτ ratio"),
          ("duration_ratio", "T ratio"), ("deborah_mean", "De")]


def _print_run(out, analysis, written: dict):
    from rich.markup import escape

    info = analysis.info
    out.print(f"[bold]{escape(str(info.run_dir))}[/]: k = {info.k:g}, V_s = {info.V_s:g}, σ = {info.sigma:g}, "
              f"m_b = {info.m_b:.4g}, predicted slip duration π√(m_b/k) = {info.predicted_half_period:.4g} t0"
              f"{'' if info.has_fluid else ', dry'}", highlight=False)
    columns = _CATALOG if info.has_fluid else _CATALOG[:-1]
    out.print(_table(f"slips ({len(analysis.catalog)})", columns, analysis.catalog))
    stats = [{"quantity": k, **v} for k, v in analysis.summary.items() if v["n"]]
    out.print(_table("over all slips", [("quantity", "quantity"), ("mean", "mean"), ("std", "std"),
                                        ("min", "min"), ("max", "max"), ("n", "n")], stats))
    notch = "notch-filtered" if analysis.notch else "unfiltered"
    out.print(_table(f"block-slider fits (Eq. 3) and mean μ_d (Eq. 7, {notch})", _FITS, analysis.fits))
    if analysis.pairs:
        out.print(_table("drained / undrained pairs", _PAIRS, analysis.pair_rows))
        for row in analysis.pair_rows:
            if row["note"]:
                out.print(f"  slip {row['slip']} {escape(row['branch'])}: {escape(row['note'])}", highlight=False)
    for reason in analysis.skipped:
        out.print(f"[yellow]skipped fork:[/] {escape(reason)}", highlight=False)
    out.print("wrote " + ", ".join(escape(str(p)) for k, p in written.items() if k != "h5_skipped"), highlight=False)
    if "h5_skipped" in written:
        out.print(f"note: {escape(written['h5_skipped'])}", highlight=False)


def _print_campaign(out, summary: dict, n_runs: int):
    counts = ", ".join(f"{k}: {v}" for k, v in summary["counts"].items() if v)
    ratio = summary["ratios"]["peak_velocity_ratio"]
    line = (f"[bold]campaign[/] ({n_runs} run{'s' if n_runs > 1 else ''}, {summary['n']} pairs): {counts}; "
            f"Type I {summary['n_type_I']}, Type II {summary['n_type_II']}, complex {summary['n_complex']}")
    if ratio["n"]:
        line += (f"; peak velocity ratio mean {ratio['mean']:.3g} ± {ratio['std']:.2g}, "
                 f"{100 * ratio['frac_below_1']:.0f}% below 1")
    out.print(line, highlight=False)


def _main(main: str) -> str:
    """Validate --main (exit 2 naming the option)."""
    if main not in ("first", "largest"):
        from .common import fail

        fail(f"--main = {main!r}: use 'first' (the forked slip) or 'largest'")
    return main


def register(app: typer.Typer) -> None:
    """Add the `analyze` and `plot` commands to ``app``."""

    @app.command()
    def analyze(
        run_dirs: List[Path] = typer.Argument(..., help="one or more run directories"),
        notch: bool = typer.Option(True, "--notch/--no-notch",
                                   help="notch-filter the layer's natural vibration out of μ_d(t)"),
        as_json: bool = typer.Option(False, "--json", help="machine-readable output (NaN as null)"),
        main: str = typer.Option("first", "--main", help="compared event of each branch: first (the forked "
                                 "slip) or largest"),
    ):
        """Slip catalog, block-slider fits, μ_d(t) and drained/undrained pair types.

        Writes RUN/analysis/{catalog,fits,pairs}.csv and summary.json, and /analysis in run.h5.
        """
        from ..analysis.forkpairs import campaign
        from ..analysis.report import analyze_run, write_analysis
        from ..errors import AnalysisError, DamagedFileError
        from ..errors import describe_os_error
        from ..errors import EXIT_BAD_INPUT
        from .common import err, fail, out

        done, failed = [], []
        for run_dir in run_dirs:
            try:
                analysis = analyze_run(run_dir, notch=notch, main=_main(main))
                written = write_analysis(analysis)
            except (AnalysisError, DamagedFileError, OSError) as exc:
                exc = exc if not isinstance(exc, OSError) else describe_os_error(exc, str(run_dir))[0]
                failed.append(str(exc))
                if not as_json:
                    from rich.markup import escape

                    err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False)
                continue
            done.append((analysis, written))
            if not as_json:
                _print_run(out, analysis, written)
        all_pairs = [p for a, _ in done for p in a.pairs]
        summary = campaign(all_pairs) if all_pairs else None
        if as_json:
            print(json.dumps(json_safe({
                "runs": [dict(a.to_dict(), written={k: str(v) for k, v in w.items()}) for a, w in done],
                "campaign": summary,
                "errors": failed,
            })))
        elif summary is not None:
            _print_campaign(out, summary, len({a.info.run_dir for a, _ in done}))
        if failed:
            if as_json:
                raise typer.Exit(EXIT_BAD_INPUT)
            fail(f"{len(failed)} of {len(run_dirs)} run(s) could not be analysed")

    @app.command()
    def plot(
        run_dir: Path = typer.Argument(..., help="run directory"),
        slip: Optional[int] = typer.Option(None, "--slip", help="also draw slip N (and its fork, if any)"),
        out_dir: Optional[Path] = typer.Option(None, "--out", help="figure directory (default RUN/figures)"),
        notch: bool = typer.Option(True, "--notch/--no-notch", help="notch-filter μ_d(t)"),
        main: str = typer.Option("first", "--main", help="compared event of each branch: first or largest"),
    ):
        """PNG figures: run overview, grain snapshot, slip N with its fit, μ_d(t), drained vs undrained."""
        from ..plots import make_figures
        from .common import guarded, out

        files = guarded(make_figures)(run_dir=run_dir, slip=slip, out_dir=out_dir, notch=notch, main=_main(main))
        for path in files:
            out.print(str(path), highlight=False)
