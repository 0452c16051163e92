"""`gouge analyze` and `gouge plot`: thin wrappers over gouge_cli.api (analyze, figures: the report of
gouge_cli.analysis and the figures of gouge_cli.plots, as from Python).

Registered on the main typer app by :func:`register` (called at the end of cli/main.py).
Bad input (not a run, still running, no slips, no such slip) exits with code 2.
"""

from __future__ import annotations

import errno
import json
import math
import shlex
from pathlib import Path
from typing import List, Optional

import typer

from ..io.filedoc import json_safe
from .common import main_event


def _fmt(value, digits: int = 4) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "–"
        return f"{value:.0f}" if 1e4 <= abs(value) < 1e9 else f"{value:.{digits}g}"
    return "" if value is None else str(value)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return text in ("–", "")
    return True


class _Natural:
    """A renderable drawn at its own width whatever the console's (``--wide``: lines may run past
    the terminal's edge, to be read with ``less -S`` or a wide window, but no value is cut)."""

    def __init__(self, renderable, width: int):
        self.renderable, self.width = renderable, width

    def __rich_console__(self, console, options):
        yield from console.render(self.renderable, options.update_width(max(self.width, options.max_width)))


def _table(title: str, columns: list[tuple[str, str]], rows: list[dict], width: int | None = None,
           wide: bool = False, digits: int = 4):
    """A rich table of ``rows``, never truncating a value: when the columns do not fit the console
    (``width``; default the output console's), they are split into several tables, each repeating
    the first (key) column; ``wide``: one table at its full width, past the console's edge if need be;
    ``digits``: significant digits of a float."""
    from rich.console import Group
    from rich.markup import escape
    from rich.table import Table

    from .common import out

    width = width or out.width
    cells = [[_fmt(row.get(key), digits) for key, _ in columns] for row in rows]
    need = [max([len(header)] + [len(c[i]) for c in cells]) + 3 for i, (_, header) in enumerate(columns)]
    chunks, current, used = [], [], need[0] + 4
    for i in range(1, len(columns)):
        if current and used + need[i] > width and not wide:
            chunks.append(current)
            current, used = [], need[0] + 4
        current.append(i)
        used += need[i]
    chunks.append(current)
    tables = []
    for n, chunk in enumerate(chunks):
        part = f" ({n + 1}/{len(chunks)})" if len(chunks) > 1 else ""
        table = Table(title=escape(title + part), title_justify="left")
        for i in [0] + chunk:
            numeric = all(_is_number(c[i]) for c in cells)
            table.add_column(escape(columns[i][1]), justify="right" if numeric else "left", no_wrap=True,
                             min_width=need[i] - 3)
        for c in cells:
            table.add_row(*[escape(c[i]) for i in [0] + chunk])
        tables.append(table)
    if wide:
        return _Natural(tables[0], used + 1)
    return tables[0] if len(tables) == 1 else Group(*tables)


_CATALOG = [("number", "#"), ("onset_time", "onset [t0]"), ("onset_time_ms", "onset [ms]"),
            ("duration", "duration [t0]"), ("duration_us", "duration [µs]"), ("static_strength", "τs/σ"),
            ("stress_drop", "Δτ/σ"), ("stress_drop_MPa", "Δτ [MPa]"), ("peak_velocity_over_Vs", "v_peak/V_s"),
            ("peak_velocity_m_s", "v_peak [m/s]"), ("mean_velocity_over_Vs", "v_mean/V_s"), ("slip", "slip [d]"),
            ("recurrence", "recurrence [t0]"), ("n_subevents", "sub-events"), ("deborah", "De"),
            ("regime", "drainage")]
_FITS = [("number", "#"), ("verdict", "Eq. 3 fit"), ("duration", "duration [t0]"), ("duration_us", "duration [µs]"),
         ("half_period", "fitted T/2 [t0]"), ("predicted_half_period", "π√(m_b/k) [t0]"),
         ("half_period_ratio", "T/2 ÷ π√(m_b/k)"), ("m_eff_over_m_b", "m_eff/m_b"), ("r2", "R²"),
         ("amplitude_over_Vs", "A/V_s"), ("delta_mu", "Δμ (from A)"), ("static_friction", "μ_s"),
         ("mean_dynamic_friction", "mean μ_d"), ("delta_mu_eq7", "μ_s − mean μ_d")]
_PAIRS = [("slip", "slip"), ("branch", "branch"), ("deborah_slip", "De"), ("regime", "drainage"), ("type", "type"),
          ("criteria", "-C criteria"), ("drained_onset", "drained onset [t0]"),
          ("undrained_onset", "undrained onset [t0]"), ("drained_strength", "S_d [τ/σ]"),
          ("undrained_strength", "S_u [τ/σ]"), ("strength_difference", "S_u − S_d"),
          ("peak_velocity_ratio", "v_peak ratio"), ("stress_drop_ratio", "Δτ ratio"),
          ("duration_ratio", "duration ratio"), ("deborah_onset", "De onset"), ("deborah_max", "De max"),
          ("drained_fit_verdict", "drained fit"),
          ("undrained_fit_verdict", "undrained fit")]


def _print_run(out, analysis, written: dict, wide: bool = False):
    from rich.markup import escape

    from ..units import ResultUnits

    info = analysis.info
    units = ResultUnits.of_run(info.config, info.V_s, info.sigma)
    out.print(f"[bold]{escape(str(info.run_dir))}[/]: k = {info.k:g}, V_s = {info.V_s:g} v0, σ = {info.sigma:g} E, "
              f"m_b = {info.m_b:.4g}, predicted slip duration π√(m_b/k) = {info.predicted_half_period:.4g} t0 "
              f"({info.predicted_half_period * units.t0_s:.3g} s){'' if info.has_fluid else ', dry'}", highlight=False)
    out.print(f"units: times in t0 since loading began ({units.caption().removeprefix('units: ')}); wall "
              "velocities in V_s; stresses in σ", highlight=False)
    columns = _CATALOG if info.has_fluid else _CATALOG[:-2]
    shown = [dict(r, onset_time_ms=r["onset_time_s"] * 1e3, duration_us=r["duration_s"] * 1e6) for r in analysis.catalog]
    out.print(_table(f"slips ({len(analysis.catalog)})", columns, shown, wide=wide))
    stats = [{"quantity": k, **v} for k, v in analysis.summary.items() if v["n"]]
    out.print(_table("over all slips of this run", [("quantity", "quantity"), ("mean", "mean"), ("std", "std"),
                                                    ("min", "min"), ("max", "max"), ("n", "n")], stats, wide=wide))
    notch = "notch-filtered" if analysis.notch else "unfiltered"
    fits = [dict(r, duration_us=r["duration_s"] * 1e6) for r in analysis.fits]
    out.print(_table(f"block-slider fits (thesis Eq. 3) and mean μ_d (Eq. 7, {notch})", _FITS, fits, wide=wide))
    for row in analysis.fits:
        if row["reason"]:
            out.print(f"  slip {row['number']}: {escape(row['reason'])}", highlight=False)
    if analysis.pairs:
        out.print(_table("drained / undrained pairs (times since loading began)", _PAIRS, analysis.pair_rows,
                         wide=wide))
        for row in analysis.pair_rows:
            for text in (row["fit_reason"], row["note"]):
                if text:
                    out.print(f"  slip {row['slip']} {escape(row['branch'])}: {escape(text)}", highlight=False)
    for reason in analysis.skipped:
        out.print(f"[yellow]skipped fork:[/] {escape(reason)}", highlight=False)
    out.print("wrote " + ", ".join(escape(str(p)) for k, p in written.items() if k != "h5_skipped"), highlight=False)
    if "h5_skipped" in written:
        out.print(f"note: {escape(written['h5_skipped'])}", highlight=False)


def _print_campaign(out, summary, n_runs: int):
    """One line per permeability (pairs at different permeabilities are never pooled); ``summary``:
    an analysis.forkpairs.Campaign."""
    from ..io.layout import perm_text

    for g in summary.groups:
        c = g.pairs
        counts = ", ".join(f"{k}: {v}" for k, v in c.counts.items() if v)
        regimes = ", ".join(f"{k} {v}" for k, v in g.regimes.items())
        ratio = c.ratios["peak_velocity_ratio"]
        line = (f"[bold]κ_c = {perm_text(g.permeability)} d²[/] ({regimes}; {n_runs} run{'s' if n_runs > 1 else ''}, "
                f"{c.n} pair{'s' if c.n != 1 else ''}): {counts}; Type I {c.n_type_I}, "
                f"Type II {c.n_type_II}, complex {c.n_complex}")
        if ratio.n:
            line += (f"; peak velocity ratio (undrained/drained) mean {ratio.mean:.3g} ± {ratio.std:.2g} "
                     f"over {ratio.n}, {100 * ratio.frac_below_1:.0f}% below 1")
        out.print(line, highlight=False)


def register(app: typer.Typer) -> None:
    """Add the `analyze` and `plot` commands to ``app``."""

    @app.command()
    def analyze(
        run_dirs: List[Path] = typer.Argument(..., help="one or more run directories"),
        notch: bool = typer.Option(True, "--notch/--no-notch",
                                   help="notch-filter the layer's natural vibration out of μ_d(t)"),
        as_json: bool = typer.Option(False, "--json", help="machine-readable output (NaN as null)"),
        main: str = typer.Option("first", "--main", callback=main_event, help="compared event of each branch: "
                                 "first (the forked slip) or largest"),
        wide: bool = typer.Option(False, "--wide", help="one table per section at its full width, past the terminal's edge if "
                              "need be (default: split to fit)"),
    ):
        """Slip catalog, block-slider fits, μ_d(t) and drained/undrained pair types.

        Writes RUN/analysis/{catalog,fits,pairs}.csv and summary.json, and /analysis in run.h5.
        """
        from ..analysis.forkpairs import campaign
        from ..analysis.report import write_analysis
        from ..api import analyze as analyze_run
        from ..errors import AnalysisError, DamagedFileError
        from ..errors import describe_os_error
        from ..errors import EXIT_BAD_INPUT, EXIT_PHYSICS, EXIT_SKIPPED, NoSpaceError
        from .common import err, fail, out

        done, failed, full = [], [], False
        for run_dir in run_dirs:
            try:
                analysis = analyze_run(run_dir, notch=notch, main=main, write=False)
                written = write_analysis(analysis)
            except (AnalysisError, DamagedFileError, OSError) as exc:
                if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
                    full = True
                    if not getattr(exc, "next_step", None):
                        exc = NoSpaceError(exc.filename or str(run_dir), "run `" + shlex.join(
                            ["gouge", "analyze", *map(str, run_dirs)]) + "` again (with the same options)",
                                           getattr(exc, "need", None), getattr(exc, "detail", ""))
                exc = exc if not isinstance(exc, OSError) else describe_os_error(exc, str(run_dir))[0]
                failed.append(str(exc))
                if not as_json:
                    from rich.markup import escape

                    err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False)
                continue
            done.append((analysis, written))
            if not as_json:
                _print_run(out, analysis, written, wide)
        all_pairs = [p for a, _ in done for p in a.pairs]
        summary = campaign(all_pairs) if all_pairs else None
        if as_json:
            print(json.dumps(json_safe({
                "runs": [dict(a.to_dict(), written={k: str(v) for k, v in w.items()}) for a, w in done],
                "campaign": summary.to_dict() if summary is not None else None,
                "errors": failed,
            })))
        elif summary is not None:
            _print_campaign(out, summary, len({a.info.run_dir for a, _ in done}))
        skipped = sum(1 for a, _ in done for r in a.skipped if getattr(r, "damaged", True))
        if failed:
            if as_json:
                raise typer.Exit(EXIT_PHYSICS if full else EXIT_BAD_INPUT)
            if len(failed) == 1 and len(run_dirs) == 1 and not skipped:    # one message, already printed
                raise typer.Exit(EXIT_PHYSICS if full else EXIT_BAD_INPUT)
            fail(f"{len(failed)} of {len(run_dirs)} run(s) could not be analysed"
                 + (f"; {skipped} damaged fork(s) skipped (listed above)" if skipped else ""),
                 EXIT_PHYSICS if full else EXIT_BAD_INPUT)
        if skipped:         # exit 4: done, but incomplete (a script can tell)
            if not as_json:
                err.print(f"summary: {len(done)} run(s) analysed; {skipped} damaged fork(s) skipped (listed above: "
                          "their pairs are not in the tables)", highlight=False)
            raise typer.Exit(EXIT_SKIPPED)

    @app.command()
    def plot(
        run_dir: Path = typer.Argument(..., help="run directory"),
        slip: Optional[int] = typer.Option(None, "--slip", help="also draw slip N (and its fork, if any)"),
        out_dir: Optional[Path] = typer.Option(None, "--out", help="figure directory (default RUN/figures)"),
        notch: bool = typer.Option(True, "--notch/--no-notch", help="notch-filter μ_d(t)"),
        main: str = typer.Option("first", "--main", callback=main_event,
                                 help="compared event of each branch: first or largest"),
    ):
        """PNG figures: run overview, last grain snapshot, pair types per permeability; with --slip N the
        slip and its Eq. 3 fit, μ_d(t), and for its fork the drained branch against every permeability.
        Lists each file with what it shows."""
        from ..api import figures
        from ..plots.make import describe_figure
        from .common import guarded, out

        files = guarded(figures)(run_dir=run_dir, slip=slip, out_dir=out_dir, notch=notch, main=main)
        for path in files:
            out.print(f"{path}\n    {describe_figure(path)}", highlight=False)
