"""`gouge study`: thin wrapper over gouge_cli.workflows.study (registered from cli/main.py)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from .common import guarded, main_event


#: The study table's columns on the terminal (study/table.csv holds every column).
_COLUMNS = [("slip", "slip"), ("transient", "transient"), ("kappa_c", "κ_c [d²]"), ("deborah", "De"),
            ("regime", "drainage"), ("type", "type"), ("undrained_event", "undrained event"), ("S_d", "S_d [τ/σ]"),
            ("S_u", "S_u [τ/σ]"), ("peak_velocity_ratio", "v_peak ratio"), ("stress_drop_ratio", "Δτ ratio"),
            ("duration_ratio", "duration ratio"), ("drained_duration", "drained duration [t0]"),
            ("drained_fit_verdict", "drained Eq. 3 fit"), ("drained_fit_r2", "R²"),
            ("m_eff_over_m_b", "m_eff/m_b")]


def register(app: typer.Typer) -> None:
    """Add the `study` command to ``app``."""

    @app.command()
    @guarded
    def study(
        target: Path = typer.Argument(..., help="a config (the dry loading run is run first) or a run directory"),
        perm: List[float] = typer.Option([], "--perm", help="kappa_c [d^2] of the undrained branches; repeatable"),
        slips: Optional[str] = typer.Option(None, "--slips", help="slips to fork, e.g. 3-12 or 3,5,7 "
                                            "(default: every non-transient slip)"),
        main: str = typer.Option("first", "--main", callback=main_event,
                                 help="compared event of each branch: first or largest"),
        jobs: Optional[int] = typer.Option(None, "--jobs", help="parallel branches (default: all cores)"),
        out_dir: Optional[Path] = typer.Option(None, "--out", help="loading-run directory for a config"),
        set_: List[str] = typer.Option([], "--set", help="config override for the loading run"),
        figures: bool = typer.Option(True, "--figures/--no-figures", help="draw RUN/study/figures"),
        quiet: bool = typer.Option(False, "--quiet"),
        yes: bool = typer.Option(False, "--yes", help="start a loading run estimated above 1 h without asking"),
        wide: bool = typer.Option(False, "--wide", help="one table per section at its full width, past the terminal's edge "
                              "if need be (default: split to fit)"),
    ):
        """Dry loading run, drained + undrained forks of every slip, pair types and the study report."""
        from ..io.layout import perm_text
        from ..analysis.study import summary_lines
        from ..io.records import plain
        from ..errors import StudyInterrupted
        from ..config import parse_overrides
        from ..workflows.study import parse_slips, run_study
        from .analysis_cmds import _table
        from ..errors import EXIT_INTERRUPTED
        from .common import confirm_long, fail, out

        try:
            wanted = parse_slips(slips)
        except ValueError:
            fail(f"--slips {slips!r}: give a range like 3-12 or a list like 3,5,7")
        if not perm:
            fail("give at least one --perm K (kappa_c in d^2, e.g. --perm 1e-5)")
        say = (lambda m: None) if quiet else (lambda m: out.print(m, highlight=False))
        try:
            result = run_study(target, perm, wanted, main=main, jobs=jobs, out=out_dir, overrides=parse_overrides(set_),
                               quiet=quiet, figures=figures, on_progress=say, confirm=confirm_long(yes))
        except StudyInterrupted as e:
            fail(str(e), EXIT_INTERRUPTED)
        out.print(_table(f"study of {result.run_dir} ({len(result.rows)} pairs; full table in study/table.csv)",
                         _COLUMNS, [plain(r) for r in result.rows], wide=wide))
        for g in result.summary:
            side = [{"quantity": a, "this study": b, "thesis": c} for a, b, c in summary_lines(g.summary)]
            regimes = ", ".join(f"{k} {v}" for k, v in g.regimes.items())
            out.print(_table(f"κ_c = {perm_text(g.permeability)} d² ({regimes}): summary (transient slips left "
                             "out) next to the thesis (κ_c = 1e-05)",
                             [("quantity", "quantity"), ("this study", "this study"), ("thesis", "thesis")], side,
                             wide=wide))
        from ..errors import EXIT_SKIPPED
        from .common import err

        for reason in result.damaged:
            err.print(f"skipped fork: {reason}", highlight=False, markup=False)
        out.print(f"ran {len(result.ran)} branches, {len(result.skipped)} done before; wrote "
                  f"{result.run_dir / 'study'}", highlight=False)
        if result.damaged:      # exit 4: done, but forks were left out (listed above)
            err.print(f"summary: {len(result.rows)} pairs in the study; {len(result.damaged)} damaged fork(s) "
                      "skipped (listed above)", highlight=False, markup=False)
            raise typer.Exit(EXIT_SKIPPED)
